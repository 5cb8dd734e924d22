//! A bake measured against a reference bake of the same scene: relative errors of Ams_1 and of
//! every row over bins θ ≥ a minimum angle, and the largest F_i difference, per field and channel.

use std::path::Path;

use format::BakeDir;
use serde::Serialize;

use crate::error::BakeError;

/// Error of one field and channel of a bake against a reference bake.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelError {
    /// The field.
    pub field: String,
    /// `R`, `G` or `B`.
    pub channel: &'static str,
    /// rms over bins θ ≥ min angle of |v − v_ref| / v_ref, row Ams_1.
    pub rms_rel_ams1: f64,
    /// max over the same bins.
    pub max_rel_ams1: f64,
    /// The same over every row.
    pub rms_rel_all: f64,
    /// max over every row.
    pub max_rel_all: f64,
    /// max_i |F_i − F_i,ref|.
    pub max_abs_forward_fraction: f64,
}

/// Every field and channel of a comparison.
#[derive(Debug, Clone, Serialize)]
pub struct CompareReport {
    /// Smallest scattering angle of the statistics (degrees).
    pub min_angle_deg: f64,
    /// One entry per field and channel.
    pub fields: Vec<ChannelError>,
}

/// Compares every field of `dir` with the same field of `reference` (same grid and N).
pub fn compare(
    dir: &Path,
    reference: &Path,
    min_angle_deg: f64,
) -> Result<CompareReport, BakeError> {
    if !(0.0..=180.0).contains(&min_angle_deg) {
        return Err(BakeError::OutOfRange {
            name: "--min-angle-deg",
            value: min_angle_deg,
            range: "[0, 180]",
        });
    }
    let ours_dir = BakeDir::open(dir)?;
    let theirs_dir = BakeDir::open(reference)?;
    let (ours, theirs) = (&ours_dir.manifest, &theirs_dir.manifest);
    if ours.theta_step_deg != theirs.theta_step_deg || ours.angle_count != theirs.angle_count {
        return Err(BakeError::Incompatible(format!(
            "the bakes use different grids: Δθ = {}° ({} angles) against {}° ({} angles)",
            ours.theta_step_deg, ours.angle_count, theirs.theta_step_deg, theirs.angle_count
        )));
    }
    let k0 = (min_angle_deg / ours.theta_step_deg).ceil() as usize;
    let mut fields = Vec::new();
    for f in &ours.fields {
        let Some(r) = theirs.fields.iter().find(|r| r.name == f.name) else {
            return Err(BakeError::Incompatible(format!(
                "field {:?} is not in the reference bake {}",
                f.name,
                reference.display()
            )));
        };
        let a = ours_dir.read_field(f)?;
        let b = theirs_dir.read_field(r)?;
        if a.n_max() != b.n_max() {
            return Err(BakeError::Incompatible(format!(
                "field {:?}: N = {} against the reference's {}",
                f.name,
                a.n_max(),
                b.n_max()
            )));
        }
        for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
            let rel = |row: usize| -> Vec<f64> {
                a.row(c, row)
                    .iter()
                    .skip(k0)
                    .zip(b.row(c, row).iter().skip(k0))
                    .map(|(x, y)| ((x - y) / y).abs())
                    .collect()
            };
            let stats = |v: &[f64]| {
                let rms = (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt();
                (rms, v.iter().copied().fold(0.0, f64::max))
            };
            let (rms1, max1) = stats(&rel(0));
            let all: Vec<f64> = (0..a.n_max()).flat_map(rel).collect();
            let (rms_all, max_all) = stats(&all);
            let df = a
                .forward_fractions(c)
                .iter()
                .zip(b.forward_fractions(c))
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            fields.push(ChannelError {
                field: f.name.clone(),
                channel: name,
                rms_rel_ams1: rms1,
                max_rel_ams1: max1,
                rms_rel_all: rms_all,
                max_rel_all: max_all,
                max_abs_forward_fraction: df,
            });
        }
    }
    Ok(CompareReport {
        min_angle_deg,
        fields,
    })
}
