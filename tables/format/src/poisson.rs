//! `DIR/<field>.poisson.exr`: the field's Poisson mixtures of all scattering orders,
//! M(D, θ) = Σ_{i≥1} q_i(D) Ams_i(θ) / (1 − q_0(D)) with q_i(D) = e^{−D} D^i / i! (Max et al.
//! 2004, Eqs. 8, 9): the phase function of the light that a segment of optical depth D scatters
//! at least once, which the `max` model applies to the light incident on a cloud's tenuous
//! edges.
//!
//! # The contract
//! - The layout every side table shares ([`crate::side`]: one scanline ZIP part, its header, the
//!   order of reading); here three 32-bit float channels `R`, `G`, `B`.
//! - Data window (0, 0)–(K − 1, J − 1): column k ↔ θ_k = k·Δθ as in the field's tables (bin
//!   averages, `grid::ThetaGrid`), row j ↔ optical depth D_j, ascending. Values in 1/sr; every
//!   row's energy Σ_k M_k Ω_k is 1. D is each channel's own optical depth (β_ext of that
//!   channel times the length), and the rows mix wavelengths as the field's Ams_n rows do.
//! - Header attributes:
//!
//!   | name                       | EXR type | value                                 |
//!   |----------------------------|----------|---------------------------------------|
//!   | `photometeor/schema`       | `int`    | [`POISSON_SCHEMA_VERSION`] (1)        |
//!   | `photometeor/field`        | `string` | the field's name, UTF-8               |
//!   | `photometeor/theta_step_deg` | `double` | Δθ in degrees                       |
//!   | `photometeor/depths`       | `string` | D_1..D_J, ascending, > 0              |
//!
//!   The list is encoded as F_i in the field's EXR (`crate::exr`, "Encoding of F_i").
//! - The manifest entry's `poisson` names this file with its size and CRC-32, and its
//!   `transport_factor` holds σ_tr/σ_t = 1 − α g per channel (the diffusion equation's transport
//!   cross-section over the extinction cross-section).
//!
//! Between the rows a reader interpolates linearly in ln D; below D_1 the row tends to Ams_1
//! (M(0) = Ams_1), and a reader must not extrapolate beyond D_J.

use std::path::Path;

use grid::ThetaGrid;
use ndarray::{Array2, Array3, ArrayView2, Axis};

use crate::exr::IoError;
use crate::side::{self, SideTable};

/// Version of this layout in `photometeor/schema`; a reader rejects any other.
pub const POISSON_SCHEMA_VERSION: i32 = 1;

/// The file name of field `name`'s Poisson-mixture EXR inside the bake directory.
pub fn poisson_file_name(name: &str) -> String {
    format!("{name}.poisson.exr")
}

/// Names of the header attributes.
pub mod attr {
    /// `photometeor/schema` (`int`: [`super::POISSON_SCHEMA_VERSION`]), `/field` (`string`) and
    /// `/theta_step_deg` (`double`: Δθ in degrees), as in every side table.
    pub use crate::side::attr::{FIELD, SCHEMA, THETA_STEP_DEG};
    /// `string`: the optical depths D_j.
    pub const DEPTHS: &str = "photometeor/depths";
}

/// One field's Poisson mixtures (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct PoissonTable {
    /// The field's name.
    pub field: String,
    /// Δθ in degrees.
    pub theta_step_deg: f64,
    /// D_1..D_J, ascending, finite, > 0.
    pub depths: Vec<f64>,
    /// `rows[[c, j, k]]`: channel c (R, G, B), depth D_j, bin θ_k; 1/sr.
    pub rows: Array3<f64>,
}

impl PoissonTable {
    /// Every check the writer makes before encoding: the grid, shapes, depths, finite values,
    /// and each row's energy within 10⁻⁴ of 1 (f32 texels hold it to ~10⁻⁶).
    pub fn check(&self) -> Result<(), String> {
        let grid = ThetaGrid::new(self.theta_step_deg).map_err(|e| e.to_string())?;
        let j = self.depths.len();
        if j == 0 {
            return Err("no depths".into());
        }
        if self.depths.windows(2).any(|p| p[0] >= p[1])
            || self.depths.iter().any(|d| !(d.is_finite() && *d > 0.0))
        {
            return Err(format!(
                "depths {:?} must be finite, > 0 and ascending",
                self.depths
            ));
        }
        if self.rows.dim() != (3, j, grid.len()) {
            return Err(format!(
                "rows are {:?}, expected 3 × J × K = 3 × {j} × {}",
                self.rows.dim(),
                grid.len()
            ));
        }
        if let Some(((c, r, k), v)) = self
            .rows
            .indexed_iter()
            .find(|(_, v)| !((**v as f32).is_finite() && **v >= 0.0))
        {
            return Err(format!(
                "channel {c}, depth {r}, bin {k} is {v}, expected a finite value ≥ 0"
            ));
        }
        let omega = grid.bin_solid_angles();
        for c in 0..3 {
            for r in 0..j {
                let e: f64 = (0..grid.len())
                    .map(|k| f64::from(self.rows[[c, r, k]] as f32) * omega[k])
                    .sum();
                if (e - 1.0).abs() > 1e-4 {
                    return Err(format!(
                        "channel {c}, D = {}: energy {e}, expected 1 within 1e-4",
                        self.depths[r]
                    ));
                }
            }
        }
        Ok(())
    }
}

impl SideTable for PoissonTable {
    const WHAT: &'static str = "Poisson table";
    const SCHEMA_VERSION: i32 = POISSON_SCHEMA_VERSION;
    const CHANNELS: &'static [&'static str] = &["R", "G", "B"];
    const LISTS: &'static [&'static str] = &[attr::DEPTHS];

    fn file_name(field: &str) -> String {
        poisson_file_name(field)
    }

    fn field(&self) -> &str {
        &self.field
    }

    fn theta_step_deg(&self) -> f64 {
        self.theta_step_deg
    }

    fn lists(&self) -> Vec<&[f64]> {
        vec![&self.depths]
    }

    fn planes(&self) -> Vec<ArrayView2<'_, f64>> {
        self.rows.outer_iter().collect()
    }

    fn from_parts(
        field: String,
        theta_step_deg: f64,
        lists: Vec<Vec<f64>>,
        planes: Vec<Array2<f64>>,
    ) -> Self {
        let [depths] = <[Vec<f64>; 1]>::try_from(lists).expect("one list per name in LISTS");
        Self {
            field,
            theta_step_deg,
            depths,
            rows: stack_planes(&planes),
        }
    }

    fn check(&self) -> Result<(), String> {
        PoissonTable::check(self)
    }
}

/// Planes of one shape as (plane, row, column).
pub(crate) fn stack_planes(planes: &[Array2<f64>]) -> Array3<f64> {
    let views: Vec<ArrayView2<f64>> = planes.iter().map(|p| p.view()).collect();
    ndarray::stack(Axis(0), &views).expect("the planes of one file have one shape")
}

/// The bytes of `t`'s EXR (deterministic: the header's attributes sorted by name).
pub fn poisson_exr_bytes(t: &PoissonTable) -> Result<Vec<u8>, IoError> {
    side::encode(t)
}

/// Decodes and checks the bytes of a Poisson-mixture EXR; `path` names it in errors.
pub fn decode_poisson_exr(bytes: &[u8], path: &Path) -> Result<PoissonTable, IoError> {
    side::decode(bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> PoissonTable {
        let grid = ThetaGrid::new(30.0).unwrap();
        let omega = grid.bin_solid_angles();
        let iso = 1.0 / omega.iter().sum::<f64>();
        let mut rows = Array3::from_elem((3, 2, grid.len()), iso);
        // A row with some shape: twice the level in bin 0, renormalized.
        rows[[1, 0, 0]] = 2.0 * iso;
        let e: f64 = (0..grid.len()).map(|k| rows[[1, 0, k]] * omega[k]).sum();
        for k in 0..grid.len() {
            rows[[1, 0, k]] /= e;
        }
        PoissonTable {
            field: "cloud".into(),
            theta_step_deg: 30.0,
            depths: vec![0.01, 30.0],
            rows,
        }
    }

    #[test]
    fn round_trip_is_exact_and_deterministic() {
        let t = example();
        let bytes = poisson_exr_bytes(&t).unwrap();
        assert_eq!(bytes, poisson_exr_bytes(&t).unwrap());
        let back = decode_poisson_exr(&bytes, Path::new("cloud.poisson.exr")).unwrap();
        assert_eq!(back.depths, t.depths);
        for (a, b) in back.rows.iter().zip(&t.rows) {
            assert_eq!(*a, f64::from(*b as f32));
        }
    }

    #[test]
    fn bad_tables_are_refused_before_encoding() {
        let mut t = example();
        t.depths = vec![30.0, 0.01];
        let e = poisson_exr_bytes(&t).unwrap_err().to_string();
        assert!(e.contains("ascending"), "{e}");
        let mut t = example();
        t.rows[[2, 1, 3]] = f64::NAN;
        let e = poisson_exr_bytes(&t).unwrap_err().to_string();
        assert!(e.contains("channel 2, depth 1, bin 3"), "{e}");
        let mut t = example();
        t.rows[[0, 1, 0]] *= 3.0;
        let e = poisson_exr_bytes(&t).unwrap_err().to_string();
        assert!(e.contains("energy"), "{e}");
    }
}
