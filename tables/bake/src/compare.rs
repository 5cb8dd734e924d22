//! A bake measured against a reference bake of the same scene: relative errors of Ams_1 and of
//! every row over bins θ ≥ a minimum angle, and the largest F_i difference, per field and channel.
//! A member of a reference sweep that the bake lacks, at a value the bake's sweep of the same
//! field and key spans, is measured against the bake's sweep interpolated there (its two
//! neighbouring members mixed as a renderer mixes them, with [`format::SweepEntry::shares`]):
//! with a reference baked at the midpoints, the interpolation error.

use std::path::Path;

use format::{BakeDir, FieldImage};
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
    /// rms of |v − v_ref| / v_ref over the same bins, per row n = 1…N.
    pub rms_rel_by_order: Vec<f64>,
    /// |σ_ext − σ_ext,ref| / σ_ext,ref.
    pub rel_sigma_ext: f64,
    /// |g − g_ref|.
    pub abs_g: f64,
    /// For an interpolated field: the sweep, key and value it was interpolated at.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interpolated: Option<(String, String, f64)>,
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
    // Plain fields by name; a sweep's members by value (their names number the values).
    let member = |m: &format::Manifest, name: &str| {
        m.sweeps.iter().any(|s| s.fields.iter().any(|f| f == name))
    };
    for f in ours.fields.iter().filter(|f| !member(ours, &f.name)) {
        let Some(r) = theirs
            .fields
            .iter()
            .find(|r| r.name == f.name && !member(theirs, &r.name))
        else {
            return Err(BakeError::Incompatible(format!(
                "field {:?} is not in the reference bake {}",
                f.name,
                reference.display()
            )));
        };
        let a = Judged::read(&ours_dir, f)?;
        let b = Judged::read(&theirs_dir, r)?;
        fields.extend(errors(&f.name, &a, &b, k0, None)?);
    }
    let same = |a: &format::SweepEntry, b: &format::SweepEntry| a.name == b.name && a.key == b.key;
    for os in &ours.sweeps {
        if !theirs.sweeps.iter().any(|rs| same(os, rs)) {
            return Err(BakeError::Incompatible(format!(
                "sweep {:?} of {} is not in the reference bake {}",
                os.name,
                os.key,
                reference.display()
            )));
        }
    }
    fn entry<'m>(m: &'m format::Manifest, name: &str) -> &'m format::FieldEntry {
        m.fields
            .iter()
            .find(|f| f.name == name)
            .expect("a checked manifest's sweep names its fields")
    }
    for rs in &theirs.sweeps {
        let Some(os) = ours.sweeps.iter().find(|os| same(os, rs)) else {
            return Err(BakeError::Incompatible(format!(
                "sweep {:?} of {} is not in {}",
                rs.name,
                rs.key,
                dir.display()
            )));
        };
        // Each of our members read once, whichever midpoints it serves.
        let members: Vec<&format::FieldEntry> = os.fields.iter().map(|m| entry(ours, m)).collect();
        let images = members
            .iter()
            .map(|e| ours_dir.read_field(e))
            .collect::<Result<Vec<_>, _>>()?;
        let sigma: Vec<f64> = members.iter().map(|e| e.sigma_ext_m2.g).collect();
        let (lo, hi) = (os.values[0], os.values[os.values.len() - 1]);
        for (name, &value) in rs.fields.iter().zip(&rs.values) {
            let b = Judged::read(&theirs_dir, entry(theirs, name))?;
            let label = format!("{} {} = {value:.4}", rs.name, rs.key);
            if let Some(k) = os
                .values
                .iter()
                .position(|v| (v - value).abs() <= 1e-9 * value.abs())
            {
                let a = Judged::mix(&[(members[k], &images[k], 1.0)])?;
                fields.extend(errors(&label, &a, &b, k0, None)?);
                continue;
            }
            if !(lo..=hi).contains(&value) {
                return Err(BakeError::Incompatible(format!(
                    "field {name:?}: {} = {value} lies outside {}'s sweep [{lo}, {hi}]",
                    rs.key,
                    dir.display()
                )));
            }
            let [(i, wi), (j, wj)] = os.shares(value, &sigma);
            let a = Judged::mix(&[(members[i], &images[i], wi), (members[j], &images[j], wj)])?;
            let how = Some((rs.name.clone(), rs.key.clone(), value));
            fields.extend(errors(&label, &a, &b, k0, how)?);
        }
    }
    Ok(CompareReport {
        min_angle_deg,
        fields,
    })
}

/// A field's tables as compared: one field's, or two members of a sweep mixed with number
/// shares (each row weighted by share × σ_sca per channel, as `runtime::sample::mix`).
struct Judged {
    /// Ams_n per channel and row, θ_k.
    rows: Vec<Vec<Vec<f64>>>,
    /// F_n per channel and row.
    forward: Vec<Vec<f64>>,
    sigma_ext: [f64; 3],
    g: [f64; 3],
}

impl Judged {
    /// One field of `dir`, read.
    fn read(dir: &BakeDir, entry: &format::FieldEntry) -> Result<Self, BakeError> {
        let image = dir.read_field(entry)?;
        Self::mix(&[(entry, &image, 1.0)])
    }

    /// Fields already read, mixed with number shares.
    fn mix(parts: &[(&format::FieldEntry, &FieldImage, f64)]) -> Result<Self, BakeError> {
        let images: Vec<&FieldImage> = parts.iter().map(|(_, i, _)| *i).collect();
        let n = images[0].n_max();
        if images.iter().any(|i| i.n_max() != n) {
            return Err(BakeError::Incompatible(format!(
                "the members {:?} differ in N",
                parts
                    .iter()
                    .map(|(e, _, _)| e.name.as_str())
                    .collect::<Vec<_>>()
            )));
        }
        let per = |e: &format::FieldEntry| {
            let s = e.sigma_ext_m2.as_array().map(|v| *v);
            let a = e.albedo.as_array().map(|v| *v);
            (
                s,
                [s[0] * a[0], s[1] * a[1], s[2] * a[2]],
                e.g.as_array().map(|v| *v),
            )
        };
        let mut judged = Judged {
            rows: vec![vec![vec![0.0; images[0].angle_count()]; n]; 3],
            forward: vec![vec![0.0; n]; 3],
            sigma_ext: [0.0; 3],
            g: [0.0; 3],
        };
        for c in 0..3 {
            let total: f64 = parts.iter().map(|(e, _, w)| w * per(e).1[c]).sum();
            for &(e, image, w) in parts {
                let (ext, sca, g) = per(e);
                let share = if total > 0.0 { w * sca[c] / total } else { w };
                judged.sigma_ext[c] += w * ext[c];
                judged.g[c] += share * g[c];
                for r in 0..n {
                    for (out, v) in judged.rows[c][r].iter_mut().zip(image.row(c, r)) {
                        *out += share * *v;
                    }
                    judged.forward[c][r] += share * image.forward_fractions(c)[r];
                }
            }
        }
        Ok(judged)
    }
}

/// The errors of `a` against the reference `b`, per channel, over bins k ≥ `k0`.
fn errors(
    name: &str,
    a: &Judged,
    b: &Judged,
    k0: usize,
    interpolated: Option<(String, String, f64)>,
) -> Result<Vec<ChannelError>, BakeError> {
    let n = a.rows[0].len();
    if n != b.rows[0].len() {
        return Err(BakeError::Incompatible(format!(
            "field {name:?}: N = {n} against the reference's {}",
            b.rows[0].len()
        )));
    }
    let stats = |v: &[f64]| {
        let rms = (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
        (rms, v.iter().copied().fold(0.0, f64::max))
    };
    Ok(["R", "G", "B"]
        .into_iter()
        .enumerate()
        .map(|(c, channel)| {
            let rel = |row: usize| -> Vec<f64> {
                a.rows[c][row]
                    .iter()
                    .skip(k0)
                    .zip(b.rows[c][row].iter().skip(k0))
                    .map(|(x, y)| ((x - y) / y).abs())
                    .collect()
            };
            let by_row: Vec<Vec<f64>> = (0..n).map(rel).collect();
            let (rms1, max1) = stats(&by_row[0]);
            let all: Vec<f64> = by_row.iter().flatten().copied().collect();
            let (rms_all, max_all) = stats(&all);
            let df = a.forward[c]
                .iter()
                .zip(&b.forward[c])
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            ChannelError {
                field: name.to_string(),
                channel,
                rms_rel_ams1: rms1,
                max_rel_ams1: max1,
                rms_rel_all: rms_all,
                max_rel_all: max_all,
                max_abs_forward_fraction: df,
                rms_rel_by_order: by_row.iter().map(|v| stats(v).0).collect(),
                rel_sigma_ext: ((a.sigma_ext[c] - b.sigma_ext[c]) / b.sigma_ext[c]).abs(),
                abs_g: (a.g[c] - b.g[c]).abs(),
                interpolated: interpolated.clone(),
            }
        })
        .collect())
}
