//! Reading a `kind = "tabulated"` field's file: p(θ) as CSV or NumPy `.npy`, θ in degrees in
//! the first column, then one column for every wavelength, or one per channel or per
//! wavelength of the scene. Every refusal names the file and the line (CSV) or row (`.npy`).
//!
//! CSV: one row per line, cells separated by commas (or, on a line without commas, by spaces
//! or tabs); blank lines and lines starting with `#` are skipped, and a first line whose first
//! cell is not a number is a header. `.npy`: a 2-D array of float64 or float32, C order, one
//! row per angle.

use std::path::Path;

use mie::tabulated::TabulatedField;

/// The most rows a table may have (a 0.001° table from 0 to 180° has 180 001).
pub const MAX_ROWS: usize = 200_001;

/// The largest table file read (bytes): a FIFO, a device such as `/dev/zero` or a larger file
/// is refused before it is read.
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// A table read from its file: the angles, the columns after θ, and where each row sits in
/// the file ("line 7", "row 7") for messages.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// θ (degrees), as written.
    pub theta_deg: Vec<f64>,
    /// The columns after θ.
    pub columns: Vec<Vec<f64>>,
    /// Where row i sits in the file.
    pub places: Vec<String>,
}

impl Table {
    /// Reads `path` (named `shown` in messages): `.npy` by its extension, CSV otherwise; only
    /// a regular file of at most [`MAX_FILE_BYTES`].
    pub fn read(path: &Path, shown: &str) -> Result<Self, String> {
        let is_npy = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
        let bytes = format::read_regular_file(path, MAX_FILE_BYTES)
            .map_err(|(op, e)| format!("file {shown}: cannot be read ({op}: {e})"))?;
        let table = if is_npy {
            Self::npy(&bytes, shown)?
        } else {
            let text = String::from_utf8(bytes)
                .map_err(|e| format!("file {shown}: cannot be read as text: {e}"))?;
            Self::csv(&text, shown)?
        };
        if table.theta_deg.len() > MAX_ROWS {
            return Err(format!(
                "file {shown}: {} rows, more than the {MAX_ROWS} a table may have",
                table.theta_deg.len()
            ));
        }
        Ok(table)
    }

    /// The table as a field's phase function (with `extinction_m2` per channel), checked:
    /// θ from 0 to 180° increasing, values finite and ≥ 0, each column non-zero.
    pub fn field(self, shown: &str, extinction_m2: [f64; 3]) -> Result<TabulatedField, String> {
        let places = self.places;
        let field = TabulatedField {
            file: shown.to_string(),
            theta_deg: self.theta_deg,
            columns: self.columns,
            extinction_m2,
        };
        field.check().map_err(|e| match e.row {
            Some(row) => format!("file {shown} {}: {}", places[row], e.message),
            None => format!("file {shown}: {}", e.message),
        })?;
        Ok(field)
    }

    /// Parses CSV text.
    pub fn csv(text: &str, shown: &str) -> Result<Self, String> {
        let mut table = Self {
            theta_deg: Vec::new(),
            columns: Vec::new(),
            places: Vec::new(),
        };
        let mut width = None;
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let cells: Vec<&str> = if line.contains(',') {
                line.split(',').map(str::trim).collect()
            } else {
                line.split_whitespace().collect()
            };
            let place = format!("line {}", i + 1);
            if width.is_none() && cells[0].parse::<f64>().is_err() {
                // A header: its cells are names, not values.
                width = Some(cells.len());
                continue;
            }
            let n = *width.get_or_insert(cells.len());
            if n < 2 {
                return Err(format!(
                    "file {shown} {place}: one cell; a row is θ (degrees) and one value of p \
                     at least"
                ));
            }
            if cells.len() != n {
                return Err(format!(
                    "file {shown} {place}: {} cells where the table has {n}",
                    cells.len()
                ));
            }
            let mut values = Vec::with_capacity(n);
            for cell in &cells {
                values.push(
                    cell.parse::<f64>()
                        .map_err(|_| format!("file {shown} {place}: {cell:?} is not a number"))?,
                );
            }
            table.push(&values, place);
        }
        if table.theta_deg.is_empty() {
            return Err(format!("file {shown}: no rows of values"));
        }
        Ok(table)
    }

    /// Parses a `.npy` array of float64 or float32, one row per angle.
    fn npy(bytes: &[u8], shown: &str) -> Result<Self, String> {
        use ndarray_npy::ReadNpyExt;
        let array = match ndarray::Array2::<f64>::read_npy(bytes) {
            Ok(a) => a,
            Err(first) => match ndarray::Array2::<f32>::read_npy(bytes) {
                Ok(a) => a.mapv(f64::from),
                Err(_) => {
                    return Err(format!(
                        "file {shown}: not a 2-D .npy array of float64 or float32 (one row per \
                         angle: θ in degrees, then p): {first}"
                    ));
                }
            },
        };
        if array.ncols() < 2 {
            return Err(format!(
                "file {shown}: {} column; a row is θ (degrees) and one value of p at least",
                array.ncols()
            ));
        }
        let mut table = Self {
            theta_deg: Vec::new(),
            columns: Vec::new(),
            places: Vec::new(),
        };
        for (i, row) in array.rows().into_iter().enumerate() {
            table.push(&row.to_vec(), format!("row {}", i + 1));
        }
        if table.theta_deg.is_empty() {
            return Err(format!("file {shown}: no rows"));
        }
        Ok(table)
    }

    fn push(&mut self, values: &[f64], place: String) {
        if self.columns.is_empty() {
            self.columns = vec![Vec::new(); values.len() - 1];
        }
        self.theta_deg.push(values[0]);
        for (column, v) in self.columns.iter_mut().zip(&values[1..]) {
            column.push(*v);
        }
        self.places.push(place);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_takes_a_header_comments_and_either_separator() {
        let t = Table::csv(
            "# p\ntheta,R,G,B\n0, 1,2,3\n\n90,4,5,6\n180,7,8,9\n",
            "t.csv",
        )
        .unwrap();
        assert_eq!(t.theta_deg, [0.0, 90.0, 180.0]);
        assert_eq!(
            t.columns,
            [
                vec![1.0, 4.0, 7.0],
                vec![2.0, 5.0, 8.0],
                vec![3.0, 6.0, 9.0]
            ]
        );
        assert_eq!(t.places, ["line 3", "line 5", "line 6"]);
        let t = Table::csv("0 1\n180\t2\n", "t").unwrap();
        assert_eq!(t.columns, [vec![1.0, 2.0]]);
    }

    #[test]
    fn csv_refusals_name_the_file_and_line() {
        for (text, want) in [
            (
                "0,1\n90,x\n180,1\n",
                "file t.csv line 2: \"x\" is not a number",
            ),
            (
                "0,1\n90,1,2\n180,1\n",
                "file t.csv line 2: 3 cells where the table has 2",
            ),
            ("0\n180\n", "file t.csv line 1: one cell"),
            ("# nothing\n", "file t.csv: no rows of values"),
        ] {
            let e = Table::csv(text, "t.csv").unwrap_err();
            assert!(e.contains(want), "{text:?}: {e}");
        }
        let e = Table::csv("0,1\n90,-2\n180,1\n", "t.csv")
            .unwrap()
            .field("t.csv", [1.0; 3])
            .unwrap_err();
        assert!(e.starts_with("file t.csv line 2: p = -2"), "{e}");
        let e = Table::csv("0,1\n90,inf\n180,1\n", "t.csv")
            .unwrap()
            .field("t.csv", [1.0; 3])
            .unwrap_err();
        assert!(e.starts_with("file t.csv line 2: p = inf"), "{e}");
    }

    /// A device or a FIFO is refused before a byte is read (`/dev/zero` would never end).
    #[test]
    fn only_regular_files_are_read() {
        for path in ["/dev/zero", "/"] {
            let e = Table::read(Path::new(path), path).unwrap_err();
            assert!(e.contains("not a regular file"), "{path}: {e}");
        }
    }

    #[test]
    fn npy_reads_float32_and_float64_rows_and_refuses_other_arrays() {
        use ndarray_npy::WriteNpyExt;
        let dir = tempfile::tempdir().unwrap();
        let rows = ndarray::arr2(&[[0.0, 2.0], [90.0, 1.0], [180.0, 1.0]]);
        let f64_path = dir.path().join("p64.npy");
        rows.write_npy(std::fs::File::create(&f64_path).unwrap())
            .unwrap();
        let f32_path = dir.path().join("p32.NPY");
        rows.mapv(|v| v as f32)
            .write_npy(std::fs::File::create(&f32_path).unwrap())
            .unwrap();
        for path in [&f64_path, &f32_path] {
            let t = Table::read(path, "p.npy").unwrap();
            assert_eq!(t.theta_deg, [0.0, 90.0, 180.0]);
            assert_eq!(t.columns, [vec![2.0, 1.0, 1.0]]);
            assert_eq!(t.places[2], "row 3");
        }
        let flat = dir.path().join("flat.npy");
        ndarray::arr1(&[0.0, 1.0])
            .write_npy(std::fs::File::create(&flat).unwrap())
            .unwrap();
        let e = Table::read(&flat, "flat.npy").unwrap_err();
        assert!(e.starts_with("file flat.npy: not a 2-D .npy array"), "{e}");
        let narrow = dir.path().join("narrow.npy");
        ndarray::arr2(&[[0.0], [180.0]])
            .write_npy(std::fs::File::create(&narrow).unwrap())
            .unwrap();
        let e = Table::read(&narrow, "narrow.npy").unwrap_err();
        assert!(e.starts_with("file narrow.npy: 1 column"), "{e}");
    }
}
