//! `DIR/<field>.single.exr`: the field's single-scattering optics per wavelength, as the bake
//! computed them before mixing to R, G, B — what a spectral path tracer (`render --model
//! truth`) samples so that light keeps its wavelength through every scattering.
//!
//! # The contract
//! - The layout every side table shares ([`crate::side`]: one scanline ZIP part, its header, the
//!   order of reading); here one 32-bit float channel `Y`.
//! - Data window (0, 0)–(K − 1, W − 1): column k ↔ θ_k = k·Δθ as in the field's tables (the bin
//!   average of p over [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°], `grid::ThetaGrid`), row j ↔
//!   wavelength j, in the order of the manifest's channel weights (ascending for `spectral`;
//!   650, 515, 440 nm for `rgb3`). Values: the single-scattering phase function, 1/sr, normalized
//!   so that Σ_k p_k Ω_k = 1 − f_j, where f_j is the wavelength's forward delta fraction (the
//!   energy of an exact δ in the forward direction, stored apart).
//! - Header attributes:
//!
//!   | name                                     | EXR type | value                                 |
//!   |------------------------------------------|----------|---------------------------------------|
//!   | `photometeor/schema`                     | `int`    | [`SINGLE_SCHEMA_VERSION`] (1)         |
//!   | `photometeor/field`                      | `string` | the field's name, UTF-8               |
//!   | `photometeor/theta_step_deg`             | `double` | Δθ in degrees                         |
//!   | `photometeor/wavelengths_nm`             | `string` | λ_1..λ_W (nm)                         |
//!   | `photometeor/sigma_ext_m2`               | `string` | σ_ext per particle per wavelength, m² |
//!   | `photometeor/albedo`                     | `string` | single-scattering albedo per λ        |
//!   | `photometeor/forward_delta_fraction`     | `string` | f_j per λ, in [0, 1)                  |
//!
//!   Lists are encoded as F_i in the field's EXR (`crate::exr`, "Encoding of F_i"): shortest
//!   round-trip decimals separated by `,`, so a reader recovers the f64 values bit for bit.
//! - How the wavelengths make R, G and B is the manifest's `channels` (weights per channel and
//!   wavelength); the manifest entry's `single_scattering` names this file with its size and
//!   CRC-32.
//!
//! The texels are 32-bit floats, so a sampler normalizes each row's CDF itself: its phase
//! function is the stored one to within f32 rounding (relative 6·10⁻⁸).

use std::path::Path;

use grid::ThetaGrid;
use ndarray::{Array2, ArrayView2};

use crate::exr::IoError;
use crate::side::{self, SideTable};

/// Version of this layout in `photometeor/schema`; a reader rejects any other.
pub const SINGLE_SCHEMA_VERSION: i32 = 1;

/// The file name of field `name`'s single-scattering EXR inside the bake directory.
pub fn single_file_name(name: &str) -> String {
    format!("{name}.single.exr")
}

/// Names of the header attributes.
pub mod attr {
    /// `photometeor/schema` (`int`: [`super::SINGLE_SCHEMA_VERSION`]), `/field` (`string`) and
    /// `/theta_step_deg` (`double`: Δθ in degrees), as in every side table.
    pub use crate::side::attr::{FIELD, SCHEMA, THETA_STEP_DEG};
    /// `string`: the wavelengths (nm).
    pub const WAVELENGTHS_NM: &str = "photometeor/wavelengths_nm";
    /// `string`: σ_ext (m²) per wavelength.
    pub const SIGMA_EXT_M2: &str = "photometeor/sigma_ext_m2";
    /// `string`: single-scattering albedo per wavelength.
    pub const ALBEDO: &str = "photometeor/albedo";
    /// `string`: forward delta fraction per wavelength.
    pub const FORWARD_DELTA: &str = "photometeor/forward_delta_fraction";
}

/// One field's single-scattering optics per wavelength (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct SingleScatter {
    /// The field's name.
    pub field: String,
    /// Δθ in degrees.
    pub theta_step_deg: f64,
    /// λ_1..λ_W (nm), in the order of the manifest's channel weights.
    pub wavelengths_nm: Vec<f64>,
    /// Phase-function bins, shape (W, K), 1/sr: `bins[[j, k]]` at wavelength j and θ_k.
    pub bins: Array2<f64>,
    /// Energy of the exact forward δ per wavelength, [0, 1).
    pub forward_delta_fraction: Vec<f64>,
    /// Extinction cross-section per particle per wavelength (m²), > 0.
    pub sigma_ext_m2: Vec<f64>,
    /// Single-scattering albedo per wavelength, [0, 1].
    pub albedo: Vec<f64>,
}

impl SingleScatter {
    /// Every check the writer makes before encoding: the grid, shapes, ranges, finite values.
    pub fn check(&self) -> Result<(), String> {
        let grid = ThetaGrid::new(self.theta_step_deg).map_err(|e| e.to_string())?;
        let w = self.wavelengths_nm.len();
        if w == 0 {
            return Err("no wavelengths".into());
        }
        if self.bins.dim() != (w, grid.len()) {
            return Err(format!(
                "bins are {:?}, expected W × K = {w} × {}",
                self.bins.dim(),
                grid.len()
            ));
        }
        for (what, v) in [
            ("forward_delta_fraction", &self.forward_delta_fraction),
            ("sigma_ext_m2", &self.sigma_ext_m2),
            ("albedo", &self.albedo),
        ] {
            if v.len() != w {
                return Err(format!("{what} has {} values, expected W = {w}", v.len()));
            }
        }
        let mut sorted = self.wavelengths_nm.clone();
        sorted.sort_by(f64::total_cmp);
        if sorted.windows(2).any(|p| p[0] == p[1])
            || sorted.iter().any(|l| !(l.is_finite() && *l > 0.0))
        {
            return Err(format!(
                "wavelengths {:?} must be positive and distinct",
                self.wavelengths_nm
            ));
        }
        for j in 0..w {
            let (s, a, f) = (
                self.sigma_ext_m2[j],
                self.albedo[j],
                self.forward_delta_fraction[j],
            );
            if !(s.is_finite() && s > 0.0 && (0.0..=1.0).contains(&a) && (0.0..1.0).contains(&f)) {
                return Err(format!(
                    "wavelength {} nm: σ_ext = {s} m² (> 0), albedo = {a} ([0, 1]), forward \
                     delta = {f} ([0, 1)) out of range",
                    self.wavelengths_nm[j]
                ));
            }
        }
        if let Some(((j, k), v)) = self
            .bins
            .indexed_iter()
            .find(|(_, v)| !((**v as f32).is_finite() && **v >= 0.0))
        {
            return Err(format!(
                "bin ({j}, {k}) is {v}, expected a finite value ≥ 0"
            ));
        }
        Ok(())
    }
}

impl SideTable for SingleScatter {
    const WHAT: &'static str = "single-scattering table";
    const SCHEMA_VERSION: i32 = SINGLE_SCHEMA_VERSION;
    const CHANNELS: &'static [&'static str] = &["Y"];
    const LISTS: &'static [&'static str] = &[
        attr::WAVELENGTHS_NM,
        attr::SIGMA_EXT_M2,
        attr::ALBEDO,
        attr::FORWARD_DELTA,
    ];

    fn file_name(field: &str) -> String {
        single_file_name(field)
    }

    fn field(&self) -> &str {
        &self.field
    }

    fn theta_step_deg(&self) -> f64 {
        self.theta_step_deg
    }

    fn lists(&self) -> Vec<&[f64]> {
        vec![
            &self.wavelengths_nm,
            &self.sigma_ext_m2,
            &self.albedo,
            &self.forward_delta_fraction,
        ]
    }

    fn planes(&self) -> Vec<ArrayView2<'_, f64>> {
        vec![self.bins.view()]
    }

    fn from_parts(
        field: String,
        theta_step_deg: f64,
        lists: Vec<Vec<f64>>,
        planes: Vec<Array2<f64>>,
    ) -> Self {
        let [wavelengths_nm, sigma_ext_m2, albedo, forward_delta_fraction] =
            <[Vec<f64>; 4]>::try_from(lists).expect("one list per name in LISTS");
        let [bins] = <[Array2<f64>; 1]>::try_from(planes).expect("one plane per channel");
        Self {
            field,
            theta_step_deg,
            wavelengths_nm,
            bins,
            forward_delta_fraction,
            sigma_ext_m2,
            albedo,
        }
    }

    fn check(&self) -> Result<(), String> {
        SingleScatter::check(self)
    }
}

/// The bytes of `s`'s EXR (deterministic: the header's attributes sorted by name).
pub fn single_exr_bytes(s: &SingleScatter) -> Result<Vec<u8>, IoError> {
    side::encode(s)
}

/// Decodes and checks the bytes of a single-scattering EXR; `path` names it in errors.
pub fn decode_single_exr(bytes: &[u8], path: &Path) -> Result<SingleScatter, IoError> {
    side::decode(bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> SingleScatter {
        let grid = ThetaGrid::new(30.0).unwrap();
        let omega = grid.bin_solid_angles();
        let iso = 1.0 / omega.iter().sum::<f64>();
        SingleScatter {
            field: "cloud".into(),
            theta_step_deg: 30.0,
            wavelengths_nm: vec![440.0, 515.0, 650.0],
            bins: Array2::from_elem((3, grid.len()), iso),
            forward_delta_fraction: vec![0.0, 0.1, 0.2],
            sigma_ext_m2: vec![1e-10, 1.1e-10, 1.2e-10],
            albedo: vec![1.0, 0.999, 0.5],
        }
    }

    #[test]
    fn round_trip_is_exact_and_deterministic() {
        let s = example();
        let bytes = single_exr_bytes(&s).unwrap();
        assert_eq!(bytes, single_exr_bytes(&s).unwrap());
        let back = decode_single_exr(&bytes, Path::new("cloud.single.exr")).unwrap();
        // f64 lists bit for bit; bins through f32.
        assert_eq!(back.sigma_ext_m2, s.sigma_ext_m2);
        assert_eq!(back.albedo, s.albedo);
        assert_eq!(back.forward_delta_fraction, s.forward_delta_fraction);
        assert_eq!(back.wavelengths_nm, s.wavelengths_nm);
        for (a, b) in back.bins.iter().zip(&s.bins) {
            assert_eq!(*a, f64::from(*b as f32));
        }
    }

    #[test]
    fn bad_tables_are_refused_before_encoding() {
        let mut s = example();
        s.albedo[2] = 1.5;
        let e = single_exr_bytes(&s).unwrap_err().to_string();
        assert!(e.contains("albedo = 1.5") && e.contains("650"), "{e}");
        let mut s = example();
        s.bins[[1, 2]] = f64::NAN;
        let e = single_exr_bytes(&s).unwrap_err().to_string();
        assert!(e.contains("bin (1, 2)"), "{e}");
        let mut s = example();
        s.wavelengths_nm = vec![515.0, 440.0, 515.0];
        assert!(single_exr_bytes(&s).is_err());
    }
}
