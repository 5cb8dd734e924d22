//! `DIR/<field>.biri.exr`: the point-light in-scattering kernel of Biri, Arquès & Michelin 2006
//! (§4.1) for the field's single-scattering phase function (its Ams_1 per channel):
//! K(τ_h, θ) = e^{−τ_h (sin θ + 1)/cos θ} p(θ + π/2), with τ_h = β_ext h the optical depth
//! from the light to the view ray and θ the angle along the ray (`tables::biri`).
//!
//! # The contract
//! - The layout every side table shares ([`crate::side`]: one scanline ZIP part, its header, the
//!   order of reading); here three 32-bit float channels `R`, `G`, `B`.
//! - Data window (0, 0)–(K − 1, J − 1): column k ↔ θ_k = k·Δθ − 90° (the field's angle grid,
//!   shifted: θ + 90° is the scattering angle), row j ↔ τ_h,j, ascending from 0. Values: the
//!   exact primitive C(τ_h, θ_k) = ∫_{−90°}^{θ_k} K dθ' (θ' in radians, p in 1/sr),
//!   non-decreasing along each row. A renderer takes Γ(P) − Γ(Q) ∝ C(τ_h, θ_P) − C(τ_h, θ_Q),
//!   linear between columns and between rows.
//! - Header attributes:
//!
//!   | name                          | EXR type | value                                          |
//!   |-------------------------------|----------|------------------------------------------------|
//!   | `photometeor/schema`          | `int`    | [`BIRI_SCHEMA_VERSION`] (1)                    |
//!   | `photometeor/field`           | `string` | the field's name, UTF-8                        |
//!   | `photometeor/theta_step_deg`  | `double` | Δθ in degrees                                  |
//!   | `photometeor/depths`          | `string` | τ_h,1..τ_h,J                                   |
//!   | `photometeor/poly_R`, `_G`, `_B` | `string` | the paper's c_0..c_4 per τ_h (θ in radians), row-major J × 5 |
//!   | `photometeor/poly_error_R`, `_G`, `_B` | `string` | per τ_h: max_θ ∣C_poly − C∣ / C(90°), the quartic's error |
//!
//!   Lists are encoded as F_i in the field's EXR (`crate::exr`, "Encoding of F_i").
//! - The manifest entry's `biri_kernel` names this file with its size and CRC-32.

use std::path::Path;

use grid::ThetaGrid;
use ndarray::{Array2, Array3, ArrayView2};

use crate::exr::IoError;
use crate::poisson::stack_planes;
use crate::side::{self, SideTable};

/// Version of this layout in `photometeor/schema`; a reader rejects any other.
pub const BIRI_SCHEMA_VERSION: i32 = 1;

/// The file name of field `name`'s kernel EXR inside the bake directory.
pub fn biri_file_name(name: &str) -> String {
    format!("{name}.biri.exr")
}

/// Names of the header attributes.
pub mod attr {
    /// `string`: the τ_h values, named as in the Poisson file.
    pub use crate::poisson::attr::DEPTHS;
    /// `photometeor/schema` (`int`: [`super::BIRI_SCHEMA_VERSION`]), `/field` (`string`) and
    /// `/theta_step_deg` (`double`: Δθ in degrees), as in every side table.
    pub use crate::side::attr::{FIELD, SCHEMA, THETA_STEP_DEG};
    /// `string`: polynomial coefficients per channel.
    pub const POLY: [&str; 3] = [
        "photometeor/poly_R",
        "photometeor/poly_G",
        "photometeor/poly_B",
    ];
    /// `string`: the polynomial's error per channel.
    pub const POLY_ERROR: [&str; 3] = [
        "photometeor/poly_error_R",
        "photometeor/poly_error_G",
        "photometeor/poly_error_B",
    ];
}

/// One field's kernel tables (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct BiriTable {
    /// The field's name.
    pub field: String,
    /// Δθ in degrees.
    pub theta_step_deg: f64,
    /// τ_h, ascending, finite, ≥ 0.
    pub depths: Vec<f64>,
    /// `primitive[[c, j, k]]` = C(τ_j, θ_k) for channel c.
    pub primitive: Array3<f64>,
    /// Per channel, J × 5 row-major: c_0..c_4 at τ_j.
    pub polynomial: [Vec<f64>; 3],
    /// Per channel and τ_j: the quartic primitive's error relative to C(90°).
    pub polynomial_error: [Vec<f64>; 3],
}

impl BiriTable {
    /// Every check the writer makes before encoding.
    pub fn check(&self) -> Result<(), String> {
        let grid = ThetaGrid::new(self.theta_step_deg).map_err(|e| e.to_string())?;
        let j = self.depths.len();
        if j == 0 {
            return Err("no depths".into());
        }
        if self.depths.windows(2).any(|p| p[0] >= p[1])
            || self.depths.iter().any(|d| !(d.is_finite() && *d >= 0.0))
        {
            return Err(format!(
                "depths {:?} must be finite, ≥ 0 and ascending",
                self.depths
            ));
        }
        if self.primitive.dim() != (3, j, grid.len()) {
            return Err(format!(
                "primitive is {:?}, expected 3 × J × K = 3 × {j} × {}",
                self.primitive.dim(),
                grid.len()
            ));
        }
        for c in 0..3 {
            if self.polynomial[c].len() != 5 * j || self.polynomial_error[c].len() != j {
                return Err(format!(
                    "channel {c}: {} coefficients and {} errors, expected 5 × {j} and {j}",
                    self.polynomial[c].len(),
                    self.polynomial_error[c].len()
                ));
            }
            if let Some(v) = self.polynomial[c]
                .iter()
                .chain(&self.polynomial_error[c])
                .find(|v| !v.is_finite())
            {
                return Err(format!("channel {c}: a coefficient or error is {v}"));
            }
            for r in 0..j {
                let row = self.primitive.slice(ndarray::s![c, r, ..]);
                if let Some(k) = (0..row.len()).find(|&k| {
                    let v = row[k] as f32;
                    !(v.is_finite() && v >= 0.0) || (k > 0 && v < row[k - 1] as f32)
                }) {
                    return Err(format!(
                        "channel {c}, τ_h = {}, column {k}: {} is not a finite, non-decreasing \
                         primitive",
                        self.depths[r], row[k]
                    ));
                }
            }
        }
        Ok(())
    }
}

impl SideTable for BiriTable {
    const WHAT: &'static str = "Biri kernel table";
    const SCHEMA_VERSION: i32 = BIRI_SCHEMA_VERSION;
    const CHANNELS: &'static [&'static str] = &["R", "G", "B"];
    const LISTS: &'static [&'static str] = &[
        attr::DEPTHS,
        attr::POLY[0],
        attr::POLY[1],
        attr::POLY[2],
        attr::POLY_ERROR[0],
        attr::POLY_ERROR[1],
        attr::POLY_ERROR[2],
    ];

    fn file_name(field: &str) -> String {
        biri_file_name(field)
    }

    fn field(&self) -> &str {
        &self.field
    }

    fn theta_step_deg(&self) -> f64 {
        self.theta_step_deg
    }

    fn lists(&self) -> Vec<&[f64]> {
        let mut lists: Vec<&[f64]> = vec![&self.depths];
        lists.extend(self.polynomial.iter().map(Vec::as_slice));
        lists.extend(self.polynomial_error.iter().map(Vec::as_slice));
        lists
    }

    fn planes(&self) -> Vec<ArrayView2<'_, f64>> {
        self.primitive.outer_iter().collect()
    }

    fn from_parts(
        field: String,
        theta_step_deg: f64,
        lists: Vec<Vec<f64>>,
        planes: Vec<Array2<f64>>,
    ) -> Self {
        let [depths, p_r, p_g, p_b, e_r, e_g, e_b] =
            <[Vec<f64>; 7]>::try_from(lists).expect("one list per name in LISTS");
        Self {
            field,
            theta_step_deg,
            depths,
            primitive: stack_planes(&planes),
            polynomial: [p_r, p_g, p_b],
            polynomial_error: [e_r, e_g, e_b],
        }
    }

    fn check(&self) -> Result<(), String> {
        BiriTable::check(self)
    }
}

/// The bytes of `t`'s EXR (deterministic: the header's attributes sorted by name).
pub fn biri_exr_bytes(t: &BiriTable) -> Result<Vec<u8>, IoError> {
    side::encode(t)
}

/// Decodes and checks the bytes of a kernel EXR; `path` names it in errors.
pub fn decode_biri_exr(bytes: &[u8], path: &Path) -> Result<BiriTable, IoError> {
    side::decode(bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> BiriTable {
        let grid = ThetaGrid::new(30.0).unwrap();
        let k = grid.len();
        BiriTable {
            field: "fog".into(),
            theta_step_deg: 30.0,
            depths: vec![0.0, 1.0],
            primitive: Array3::from_shape_fn((3, 2, k), |(c, j, kk)| {
                (kk as f64 + 0.5 * c as f64) / (1.0 + j as f64)
            }),
            polynomial: std::array::from_fn(|c| (0..10).map(|i| (i + c) as f64 * 0.1).collect()),
            polynomial_error: std::array::from_fn(|_| vec![0.01, 0.2]),
        }
    }

    #[test]
    fn round_trip_is_exact_and_deterministic() {
        let t = example();
        let bytes = biri_exr_bytes(&t).unwrap();
        assert_eq!(bytes, biri_exr_bytes(&t).unwrap());
        let back = decode_biri_exr(&bytes, Path::new("fog.biri.exr")).unwrap();
        assert_eq!(back.depths, t.depths);
        assert_eq!(back.polynomial, t.polynomial);
        assert_eq!(back.polynomial_error, t.polynomial_error);
        for (a, b) in back.primitive.iter().zip(&t.primitive) {
            assert_eq!(*a, f64::from(*b as f32));
        }
    }

    #[test]
    fn bad_tables_are_refused_before_encoding() {
        let mut t = example();
        t.primitive[[1, 0, 3]] = 0.0; // decreasing
        let e = biri_exr_bytes(&t).unwrap_err().to_string();
        assert!(e.contains("channel 1, τ_h = 0, column 3"), "{e}");
        let mut t = example();
        t.polynomial[2].pop();
        let e = biri_exr_bytes(&t).unwrap_err().to_string();
        assert!(e.contains("channel 2: 9 coefficients"), "{e}");
        let mut t = example();
        t.depths = vec![1.0, 0.0];
        assert!(biri_exr_bytes(&t).is_err());
    }
}
