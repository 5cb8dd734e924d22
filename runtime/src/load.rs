//! Loading and checking a bake directory.
//!
//! # Checks (each failure names the file and the check)
//! - the directory has no pending commit of an interrupted bake; `manifest.json`: schema
//!   version, grid (K = 180°/Δθ + 1), per-field shapes, file names, physical ranges (albedo,
//!   g, σ_ext, F_i) (by `format::BakeDir::open`);
//! - each selected field's EXR: a complete OpenEXR file following the contract, then against
//!   its manifest entry: the field name attribute, Δθ, N and K, F_1..F_N equal to the
//!   manifest's per channel, and the file's size and CRC-32 (by `format::BakeDir::read_field`);
//! - every row Ams_n, per channel, integrates to 1 over the sphere within [`NORMALIZATION_TOLERANCE`]
//!   (the texels are 32-bit floats) and has no value below −10⁻⁶ of its maximum.
//!
//! F_n in [½, 1] and not rising with n is a check of the manifest, whose F_n the EXR's equal.

use std::path::{Path, PathBuf};

use format::{BakeDir, BiriTable, FieldImage, FieldKind, PoissonTable, SingleScatter};
use grid::ThetaGrid;
use ndarray::Axis;
use thiserror::Error;

/// |∫ Ams_n dΩ − 1| allowed: 32-bit texels summed over ≤ 18001 bins stay below 10⁻⁵.
pub const NORMALIZATION_TOLERANCE: f64 = 1e-5;

/// A bake directory that cannot be used, naming the file and the failed check.
#[derive(Debug, Error)]
#[error("{}: {check}", file.display())]
pub struct LoadError {
    /// The file that failed (manifest.json or a field's EXR).
    pub file: PathBuf,
    /// What was checked and what was found.
    pub check: String,
}

/// One field's tables, as loaded and checked: its RGB tables and the optics a renderer mixes
/// them with.
#[derive(Debug, Clone)]
pub struct FieldTable {
    /// The field's name in the scene.
    pub name: String,
    /// What the field is made of.
    pub kind: FieldKind,
    /// Ams_n (`image.ams[[c, n − 1, k]]`, channel c ∈ {R, G, B}, θ_k = k·Δθ, 1/sr) and F_n
    /// (`image.forward_fraction[[c, n − 1]]`).
    pub image: FieldImage,
    /// Mean scattering cross-section per particle, per channel (m²): σ_ext · albedo, the
    /// weight of this field in a spatial mix.
    pub sigma_sca_m2: [f64; 3],
    /// Mean extinction cross-section per particle, per channel (m²): number density times
    /// this is β_ext (Riley et al. 2004 Eq. 2).
    pub sigma_ext_m2: [f64; 3],
    /// Single-scattering albedo per channel.
    pub albedo: [f64; 3],
    /// The field's single-scattering optics per wavelength (`<name>.single.exr`), which a
    /// spectral path tracer samples; `None` for bakes written before it existed.
    pub single: Option<SingleScatter>,
    /// The field's Poisson mixtures M(D, θ) per channel (`<name>.poisson.exr`), which the
    /// `max` model applies at a cloud's edges; `None` for bakes written before it existed.
    pub poisson: Option<PoissonTable>,
    /// σ_tr/σ_t = 1 − α g per channel (the diffusion equation's transport cross-section over
    /// the extinction); `None` for bakes written before it existed.
    pub transport_factor: Option<[f64; 3]>,
    /// Biri et al.'s point-light kernel of the field's Ams_1 (`<name>.biri.exr`); `None` for
    /// bakes written before it existed.
    pub biri: Option<BiriTable>,
}

impl FieldTable {
    /// N, the number of rows Ams_1..Ams_N.
    pub fn n_max(&self) -> usize {
        self.image.n_max()
    }
}

/// A checked bake: the grid and the selected fields, in the manifest's order.
#[derive(Debug, Clone)]
pub struct Tables {
    /// The bake directory.
    pub dir: PathBuf,
    /// Δθ in degrees.
    pub theta_step_deg: f64,
    /// K, samples per row.
    pub angle_count: usize,
    /// The selected fields.
    pub fields: Vec<FieldTable>,
    /// The bake's wavelengths (nm) and each channel's weights over them (`weights[c][j]`),
    /// from the manifest's `channels` (always present since the manifest's `channels` are
    /// typed; an `Option` for the renderers that match on it).
    pub spectrum: Option<Spectrum>,
    /// The manifest's swept fields whose members are all among the selected fields.
    pub sweeps: Vec<format::SweepEntry>,
}

/// How a bake's wavelengths make its R, G, B channels (the manifest's `channels`).
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrum {
    /// λ_1..λ_W (nm), in the order of the single-scattering tables' rows.
    pub wavelengths_nm: Vec<f64>,
    /// weights[c][j] ≥ 0, Σ_j weights[c][j] = 1.
    pub weights: [Vec<f64>; 3],
}

impl Spectrum {
    /// The wavelengths and weights of a manifest's `channels` (checked by the manifest's
    /// reader: one weight ≥ 0 per wavelength, each channel's summing to 1).
    pub fn from_channels(channels: &format::Channels) -> Self {
        Self {
            wavelengths_nm: channels.wavelengths_nm.clone(),
            weights: channels.weights.as_array().map(Clone::clone),
        }
    }
}

impl Tables {
    /// Loads and checks every field of the bake in `dir`.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, LoadError> {
        Self::open_fields(dir, None)
    }

    /// Loads and checks only the fields a scene uses (`None`: all). A name the bake does not
    /// have is an error listing those it has.
    pub fn open_fields(dir: impl AsRef<Path>, names: Option<&[&str]>) -> Result<Self, LoadError> {
        let dir = dir.as_ref();
        let manifest_file = dir.join(format::MANIFEST_FILE);
        let bake = BakeDir::open(dir).map_err(|e| LoadError {
            file: manifest_file.clone(),
            check: strip_path(&e.to_string(), &manifest_file),
        })?;
        let manifest = &bake.manifest;
        if let Some(names) = names {
            for n in names {
                if !manifest.fields.iter().any(|f| f.name == *n) {
                    let have: Vec<&str> = manifest.fields.iter().map(|f| f.name.as_str()).collect();
                    return Err(LoadError {
                        file: manifest_file,
                        check: format!("the scene uses field {n:?}, the bake has {have:?}"),
                    });
                }
            }
        }
        let spectrum = Some(Spectrum::from_channels(&manifest.channels));
        let grid = ThetaGrid::new(manifest.theta_step_deg).expect("checked by read_manifest");
        let omega = grid.bin_solid_angles();
        let mut fields = Vec::new();
        for entry in &manifest.fields {
            if names.is_some_and(|n| !n.contains(&entry.name.as_str())) {
                continue;
            }
            let file = dir.join(&entry.file);
            let fail = |check: String| LoadError {
                file: file.clone(),
                check,
            };
            // Every file of the field: the contracts, the manifest cross-checks (name, Δθ, K,
            // N, F_i, the single table's wavelengths, optics and forward peaks) and each file's
            // size + CRC-32, an error naming the file that failed.
            let files = bake.read_field_files(entry).map_err(|e| {
                let failed = e.path().map_or_else(|| file.clone(), Path::to_path_buf);
                LoadError {
                    check: strip_path(&e.to_string(), &failed),
                    file: failed,
                }
            })?;
            let image = files.image;
            // F_i's range and order are the manifest's checks, and read_field has compared the
            // EXR's F_i with the manifest's bit for bit: only the rows remain to be checked.
            for (c, ch) in ["R", "G", "B"].into_iter().enumerate() {
                for (r, row) in image.ams.index_axis(Axis(0), c).outer_iter().enumerate() {
                    let integral: f64 = row.iter().zip(&omega).map(|(v, o)| v * o).sum();
                    if (integral - 1.0).abs() > NORMALIZATION_TOLERANCE {
                        return Err(fail(format!(
                            "Ams_{}.{ch} integrates to {integral} over the sphere, expected 1 ± {NORMALIZATION_TOLERANCE}",
                            r + 1
                        )));
                    }
                    let max = row.iter().copied().fold(0.0, f64::max);
                    if let Some(k) = row.iter().position(|&v| v < -1e-6 * max) {
                        return Err(fail(format!(
                            "Ams_{}.{ch} at θ = {}° is {}, a phase function cannot be negative",
                            r + 1,
                            k as f64 * manifest.theta_step_deg,
                            row[k]
                        )));
                    }
                }
            }
            let ext = entry.sigma_ext_m2.as_array().map(|&v| v);
            let alb = entry.albedo.as_array().map(|&v| v);
            fields.push(FieldTable {
                name: entry.name.clone(),
                kind: entry.kind,
                image,
                sigma_sca_m2: [ext[0] * alb[0], ext[1] * alb[1], ext[2] * alb[2]],
                sigma_ext_m2: ext,
                albedo: alb,
                single: files.single,
                poisson: files.poisson,
                biri: files.biri,
                transport_factor: entry
                    .transport_factor
                    .as_ref()
                    .map(|t| t.as_array().map(|&v| v)),
            });
        }
        let sweeps = manifest
            .sweeps
            .iter()
            .filter(|s| s.fields.iter().all(|m| fields.iter().any(|f| &f.name == m)))
            .cloned()
            .collect();
        Ok(Self {
            dir: dir.to_path_buf(),
            theta_step_deg: manifest.theta_step_deg,
            angle_count: manifest.angle_count,
            fields,
            spectrum,
            sweeps,
        })
    }

    /// The field called `name`.
    pub fn field(&self, name: &str) -> Option<&FieldTable> {
        self.fields.iter().find(|f| f.name == name)
    }
}

/// The error text without its leading "path: " (the [`LoadError`] names the file itself).
fn strip_path(text: &str, path: &Path) -> String {
    let prefix = format!("{}: ", path.display());
    text.strip_prefix(&prefix).unwrap_or(text).to_string()
}
