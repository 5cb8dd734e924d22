//! `photometeor bake`: scene → plan → per-field phase functions (Mie) → RGB → Ams_n, F_n →
//! EXR + manifest, with a content-addressed cache so an unchanged field is not recomputed.
//!
//! The plan ([`BakePlan`]) is plain data made from the validated scene and the command-line
//! options; nothing touches the output directory until the plan exists.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::ams::{AmsMixture, AmsSeries};
use crate::exr_io::{FieldImage, write_field_exr};
use crate::grid::ThetaGrid;
use crate::manifest::{FieldEntry, Manifest, PerChannel, write_manifest};
use crate::spectral::{ChannelWeights, SpectralMode};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use mie::AngleGrid;
use mie::crystal::crystal_phase;
use mie::ensemble::bulk_at;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::scene::{Field, Quality, Scene, Spectral};

/// Version of everything that changes a baked number; part of every cache key.
const COMPUTE_VERSION: u32 = 5;
/// n_iso is searched up to this order.
const N_ISO_CAP: usize = 100_000;
/// The ε of the n_iso report.
const N_ISO_EPSILONS: [f64; 3] = [1e-2, 1e-4, 1e-6];

/// Node counts a preset stands for (chosen from the measured trade, docs/accuracy.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Knobs {
    /// Sizes per wavelength (nodes in ln r; shifted per wavelength for joint sampling).
    pub sizes: usize,
    /// Gauss nodes per angular panel inside each bin.
    pub nodes_per_panel: usize,
    /// Mass fraction left outside the truncated size range.
    pub tail_mass: f64,
    /// Heat-kernel blur of the j ≥ 2 Ams terms, in bins.
    pub blur_bins: f64,
    /// Geometric-optics rays per wavelength for ice and snow.
    pub rays: u64,
}

impl Quality {
    pub fn knobs(self) -> Knobs {
        let (sizes, nodes_per_panel, rays) = match self {
            Quality::Draft => (32, 2, 40_000),
            Quality::Standard => (400, 2, 600_000),
            Quality::Reference => (4096, 2, 6_000_000),
        };
        Knobs {
            sizes,
            nodes_per_panel,
            tail_mass: 1e-3,
            blur_bins: 0.5,
            rays,
        }
    }
}

impl Knobs {
    /// The size nodes wavelength j of `j_len` uses: joint sampling of size and wavelength, each
    /// wavelength's nodes shifted by (j + ½)/J of a step in ln r, so a channel that mixes J
    /// wavelengths sees J·sizes distinct radii.
    pub fn size_quadrature(
        &self,
        distribution: &mie::SizeDistribution,
        j: usize,
        j_len: usize,
    ) -> mie::distribution::SizeQuadrature {
        let shift = (j as f64 + 0.5) / j_len as f64;
        distribution.quadrature_shifted(self.sizes, self.tail_mass, shift)
    }
}

/// Everything a bake does, decided before any work starts.
#[derive(Debug, Clone)]
pub struct BakePlan {
    pub scene: Scene,
    pub out_dir: PathBuf,
    pub quality: Quality,
    pub knobs: Knobs,
    pub quiet: bool,
}

impl BakePlan {
    /// A bake at `quality`'s preset knobs; progress bars are off when `quiet` or in CI (the
    /// `CI` environment variable set).
    pub fn for_preset(scene: Scene, out_dir: PathBuf, quality: Quality, quiet: bool) -> Self {
        Self {
            scene,
            out_dir,
            quality,
            knobs: quality.knobs(),
            quiet: quiet || std::env::var_os("CI").is_some(),
        }
    }
}

/// What one field's bake produced; also the cache record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldResult {
    pub rows: [Vec<Vec<f64>>; 3],
    pub forward_fraction: [Vec<f64>; 3],
    pub forward_peak_fraction: [Vec<f64>; 3],
    pub g: [f64; 3],
    pub sigma_ext_m2: [f64; 3],
    pub albedo: [f64; 3],
    pub n_isotropic: [[Option<u32>; 3]; 3],
    pub l_max: usize,
    pub seconds: f64,
}

/// Summary printed after a bake.
#[derive(Debug, Clone, Serialize)]
pub struct BakeReport {
    pub scene: String,
    pub out_dir: PathBuf,
    pub quality: Quality,
    pub computed: Vec<String>,
    pub cached: Vec<String>,
    pub seconds: f64,
    /// Peak resident memory of this process (Linux `VmHWM`), MiB.
    pub peak_rss_mib: Option<f64>,
}

/// Peak resident set size of this process in MiB, where the OS reports it (Linux).
pub fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn spectral_mode(s: &Spectral) -> SpectralMode {
    match *s {
        Spectral::Rgb3 => SpectralMode::Rgb3,
        Spectral::Spectral {
            count,
            min_nm,
            max_nm,
        } => SpectralMode::Spectral {
            count,
            min_nm,
            max_nm,
        },
    }
}

/// Hash of every input that affects the field's result.
pub fn content_hash(plan: &BakePlan, field: &Field) -> String {
    let key = serde_json::json!({
        "compute_version": COMPUTE_VERSION,
        "field": field,
        "spectral": plan.scene.spectral,
        "theta_step_deg": plan.scene.theta_step_deg,
        "n_max": plan.scene.n_max,
        "knobs": plan.knobs,
    });
    let digest = Sha256::digest(key.to_string().as_bytes());
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// Runs a plan. Fields whose inputs are unchanged are read from the cache.
pub fn run(plan: &BakePlan) -> Result<BakeReport> {
    let start = Instant::now();
    let weights = ChannelWeights::new(&spectral_mode(&plan.scene.spectral))
        .context("building the RGB channel weights")?;
    let grid = ThetaGrid::new(plan.scene.theta_step_deg)?;
    let mut report = BakeReport {
        scene: plan.scene.name.clone(),
        out_dir: plan.out_dir.clone(),
        quality: plan.quality,
        computed: Vec::new(),
        cached: Vec::new(),
        seconds: 0.0,
        peak_rss_mib: None,
    };
    // Compute (or read from the cache) every field first; only then touch the tables, so a
    // failing field leaves the previous bake as it was.
    let mut done = Vec::new();
    let mut fresh = Vec::new();
    for field in &plan.scene.fields {
        let hash = content_hash(plan, field);
        let cache_file = plan.out_dir.join(".cache").join(format!("{hash}.bin"));
        let result = match read_cache(&cache_file) {
            Some(r) => {
                report.cached.push(field.name.clone());
                r
            }
            None => {
                let r = compute_field(plan, field, &weights, &grid)?;
                report.computed.push(field.name.clone());
                fresh.push((done.len(), cache_file));
                r
            }
        };
        done.push((field, hash, result));
    }
    std::fs::create_dir_all(plan.out_dir.join(".cache"))
        .with_context(|| format!("creating {}", plan.out_dir.display()))?;
    for (i, cache_file) in &fresh {
        write_cache(cache_file, &done[*i].2)?;
    }
    let previous = crate::manifest::read_manifest(&plan.out_dir).ok();
    let mut entries = Vec::new();
    for (field, hash, result) in done {
        let file = format!("{}.exr", field.name);
        write_field_exr(
            plan.out_dir.join(&file),
            &FieldImage {
                field: field.name.clone(),
                theta_step_deg: plan.scene.theta_step_deg,
                rows: result.rows.clone(),
                forward_fraction: result.forward_fraction.clone(),
                extra_layers: Vec::new(),
            },
        )
        .with_context(|| format!("writing {file}"))?;
        entries.push(field_entry(plan, field, &result, file, hash));
    }
    let manifest = Manifest {
        schema: crate::manifest::MANIFEST_SCHEMA_VERSION,
        tool: "photometeor".into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        theta_step_deg: plan.scene.theta_step_deg,
        angle_count: grid.len(),
        channels: weights.channel_definitions(),
        fields: entries,
    };
    write_manifest(&plan.out_dir, &manifest).context("writing manifest.json")?;
    // Tables of fields the scene no longer has would be read as current: remove them.
    if let Some(previous) = previous {
        for old in previous.fields {
            let stale = !manifest.fields.iter().any(|f| f.file == old.file);
            let plain_name = Path::new(&old.file).file_name() == Some(old.file.as_ref());
            if stale && plain_name {
                let _ = std::fs::remove_file(plan.out_dir.join(&old.file));
            }
        }
    }
    report.seconds = start.elapsed().as_secs_f64();
    report.peak_rss_mib = peak_rss_mib();
    Ok(report)
}

fn field_entry(
    plan: &BakePlan,
    field: &Field,
    r: &FieldResult,
    file: String,
    hash: String,
) -> FieldEntry {
    let n_iso = |c: usize| {
        N_ISO_EPSILONS
            .iter()
            .zip(crate::manifest::N_ISOTROPIC_EPSILONS)
            .enumerate()
            .map(|(e, (_, key))| (key.to_string(), r.n_isotropic[e][c]))
            .collect()
    };
    FieldEntry {
        name: field.name.clone(),
        file,
        kind: format!("{:?}", field.kind).to_lowercase(),
        n_max: plan.scene.n_max,
        forward_fraction: PerChannel::from_array(r.forward_fraction.clone()),
        forward_peak_fraction: PerChannel::from_array(r.forward_peak_fraction.clone()),
        g: PerChannel::from_array(r.g),
        sigma_ext_m2: PerChannel::from_array(r.sigma_ext_m2),
        albedo: PerChannel::from_array(r.albedo),
        n_isotropic: PerChannel::from_array([n_iso(0), n_iso(1), n_iso(2)]),
        microphysics: serde_json::to_value(field).unwrap_or_default(),
        quality: serde_json::json!({ "preset": plan.quality, "knobs": plan.knobs, "legendre_l_max": r.l_max }),
        content_hash: hash,
    }
}

fn read_cache(path: &Path) -> Option<FieldResult> {
    let bytes = std::fs::read(path).ok()?;
    let (r, _): (FieldResult, usize) =
        bincode::serde::decode_from_slice(&bytes, bincode::config::standard()).ok()?;
    Some(r)
}

fn write_cache(path: &Path, r: &FieldResult) -> Result<()> {
    let bytes = bincode::serde::encode_to_vec(r, bincode::config::standard())
        .context("encoding the cache record")?;
    crate::exr_io::write_file_atomically(path, &bytes)
        .map_err(|(what, e)| anyhow::anyhow!("writing cache {}: {what}: {e}", path.display()))
}

/// Phase functions per wavelength → RGB → Ams_n per channel.
pub fn compute_field(
    plan: &BakePlan,
    field: &Field,
    weights: &ChannelWeights,
    grid: &ThetaGrid,
) -> Result<FieldResult> {
    let start = Instant::now();
    let angle_grid = AngleGrid::new(plan.scene.theta_step_deg)?;
    let knobs = plan.knobs;
    let lambdas = &weights.wavelengths_nm;
    let progress = if plan.quiet {
        ProgressBar::hidden()
    } else {
        let p = ProgressBar::with_draw_target(
            Some(lambdas.len() as u64 + 3),
            ProgressDrawTarget::stderr(),
        );
        p.set_style(
            ProgressStyle::with_template("{prefix:>8} [{bar:30}] {pos}/{len} {msg} ({elapsed})")
                .expect("valid template")
                .progress_chars("=> "),
        );
        p.set_prefix(field.name.clone());
        p
    };
    let j_len = lambdas.len();
    let mut per_wavelength = Vec::with_capacity(j_len);
    match (field.distribution, field.crystal) {
        (Some(distribution), _) => {
            progress.set_message("Mie per wavelength");
            for (j, &lambda) in lambdas.iter().enumerate() {
                let m = field
                    .material
                    .refractive_index(lambda, field.temperature_c)?;
                let q = knobs.size_quadrature(&distribution, j, j_len);
                let nodes = nodes_per_bin(&distribution, lambda, knobs, angle_grid.step_deg());
                let b = bulk_at(m, lambda, &q, angle_grid, nodes, &[])
                    .with_context(|| {
                        format!(
                            "field {:?} at {lambda} nm (radii {:.3}–{:.0} µm after truncating {:e} of the mass)",
                            field.name,
                            q.radius_um.first().copied().unwrap_or(f64::NAN),
                            q.radius_um.last().copied().unwrap_or(f64::NAN),
                            knobs.tail_mass
                        )
                    })?;
                per_wavelength.push(Spectrum {
                    bins: b.bins,
                    sigma_ext_m2: b.sigma_ext_m2,
                    sigma_sca_m2: b.sigma_sca_m2,
                    g: b.g,
                });
                progress.inc(1);
            }
        }
        (None, Some(crystal)) => {
            progress.set_message("ray tracing per wavelength");
            let rays = ray_allocation(weights, knobs.rays);
            for (j, &lambda) in lambdas.iter().enumerate() {
                // Each wavelength its own random stream: a channel averages J independent traces.
                let seed = CRYSTAL_SEED ^ (j as u64);
                let p = crystal_phase(&crystal, lambda, angle_grid, rays[j], seed)?;
                per_wavelength.push(Spectrum {
                    bins: p.bins,
                    sigma_ext_m2: p.sigma_ext_m2,
                    sigma_sca_m2: p.sigma_sca_m2,
                    g: p.g,
                });
                progress.inc(1);
            }
        }
        (None, None) => bail!("field {:?} has neither sizes nor crystals", field.name),
    }
    // Channel c mixes wavelength j with a_cj = w_cj σ_sca,j / Σ_j w_cj σ_sca,j (the scattered
    // light's spectrum); every row is Σ_j a_cj Ams_n[P_j], light keeping its wavelength.
    progress.set_message("Legendre series per wavelength");
    let series: Vec<AmsSeries> = per_wavelength
        .par_iter()
        .map(|b| AmsSeries::new(grid, &b.bins, knobs.blur_bins))
        .collect();
    progress.set_message("RGB and Ams_n");
    let orders: Vec<usize> = (1..=plan.scene.n_max).collect();
    let channels: Vec<ChannelResult> = (0..3)
        .into_par_iter()
        .map(|c| {
            let r = channel_tables(&weights.weights[c], &per_wavelength, &series, &orders);
            progress.inc(1);
            r
        })
        .collect();
    let mut result = FieldResult {
        rows: Default::default(),
        forward_fraction: Default::default(),
        forward_peak_fraction: Default::default(),
        g: [0.0; 3],
        sigma_ext_m2: [0.0; 3],
        albedo: [0.0; 3],
        n_isotropic: [[None; 3]; 3],
        l_max: 0,
        seconds: 0.0,
    };
    for (c, ch) in channels.into_iter().enumerate() {
        result.rows[c] = ch.rows;
        result.forward_fraction[c] = ch.forward_fraction;
        result.forward_peak_fraction[c] = ch.forward_peak_fraction;
        result.g[c] = ch.g;
        result.sigma_ext_m2[c] = ch.sigma_ext_m2;
        result.albedo[c] = ch.albedo;
        for e in 0..N_ISO_EPSILONS.len() {
            result.n_isotropic[e][c] = ch.n_isotropic[e];
        }
        result.l_max = ch.l_max;
    }
    progress.finish_with_message("done");
    result.seconds = start.elapsed().as_secs_f64();
    Ok(result)
}

/// Gauss nodes per bin. A distribution averages the ripple of each size (period ≈ π/x in θ)
/// away, so the preset's node count serves; a single size keeps its ripple, and a bin of
/// Δθ holds x·Δθ/π ripples, which 3 nodes per ripple resolve (a 1000 µm drop at 450 nm: 14
/// ripples per 0.18° bin; bin averages then agree with miepython's to 1e-7, mie/tests/mieplot.rs).
fn nodes_per_bin(d: &mie::SizeDistribution, lambda_nm: f64, knobs: Knobs, step_deg: f64) -> usize {
    match *d {
        mie::SizeDistribution::Monodisperse { radius_um } => {
            let x = 2.0 * std::f64::consts::PI * radius_um * 1000.0 / lambda_nm;
            let ripples = x * step_deg.to_radians() / std::f64::consts::PI;
            knobs
                .nodes_per_panel
                .max((3.0 * ripples).ceil() as usize + 2)
        }
        _ => knobs.nodes_per_panel,
    }
}

/// One wavelength's phase-function value, from either producer.
struct Spectrum {
    bins: Vec<f64>,
    sigma_ext_m2: f64,
    sigma_sca_m2: f64,
    g: f64,
}

/// Rays per wavelength for crystals: `per_wavelength` × J in all, shared in proportion to the
/// largest weight any channel gives the wavelength (at least a tenth of the mean each). A
/// channel's noise is Σ_j a_j² / n_j, smallest for n_j ∝ a_j: wavelengths a channel leans on get
/// the rays, those at the spectrum's ends (weights ~10⁻³) few.
pub fn ray_allocation(weights: &ChannelWeights, per_wavelength: u64) -> Vec<u64> {
    let j_len = weights.wavelengths_nm.len();
    let floor = per_wavelength / 10;
    let total = per_wavelength * j_len as u64;
    let importance: Vec<f64> = (0..j_len)
        .map(|j| (0..3).map(|c| weights.weights[c][j]).fold(0.0, f64::max))
        .collect();
    let sum: f64 = importance.iter().sum();
    let spare = total.saturating_sub(floor * j_len as u64) as f64;
    importance
        .iter()
        .map(|m| floor + (spare * m / sum).round() as u64)
        .collect()
}

/// Seed of the crystal traces (wavelength j uses CRYSTAL_SEED ^ j).
const CRYSTAL_SEED: u64 = 0x7068_6f74_6f6d_6574;

/// One channel's tables.
struct ChannelResult {
    rows: Vec<Vec<f64>>,
    forward_fraction: Vec<f64>,
    forward_peak_fraction: Vec<f64>,
    g: f64,
    sigma_ext_m2: f64,
    albedo: f64,
    n_isotropic: [Option<u32>; 3],
    l_max: usize,
}

/// Channel with weights `w` over the wavelengths: a_j = w_j σ_sca,j / Σ w σ_sca, and every row
/// Σ_j a_j Ams_n[P_j] (light keeps its wavelength while it scatters).
fn channel_tables(
    w: &[f64],
    per_wavelength: &[Spectrum],
    series: &[AmsSeries],
    orders: &[usize],
) -> ChannelResult {
    let sca: f64 = w
        .iter()
        .zip(per_wavelength)
        .map(|(w, b)| w * b.sigma_sca_m2)
        .sum();
    let ext: f64 = w
        .iter()
        .zip(per_wavelength)
        .map(|(w, b)| w * b.sigma_ext_m2)
        .sum();
    let mut parts = Vec::new();
    let mut g = 0.0;
    for ((wj, b), s) in w.iter().zip(per_wavelength).zip(series) {
        if *wj > 0.0 {
            let a = wj * b.sigma_sca_m2 / sca;
            g += a * b.g;
            parts.push((a, s.clone()));
        }
    }
    let mixture = AmsMixture::new(parts);
    let mut n_isotropic = [None; 3];
    for (slot, &eps) in n_isotropic.iter_mut().zip(&N_ISO_EPSILONS) {
        *slot = mixture.isotropic_order(eps, N_ISO_CAP).map(|n| n as u32);
    }
    ChannelResult {
        rows: mixture.rows(orders),
        forward_fraction: orders
            .iter()
            .map(|&n| mixture.forward_fraction(n))
            .collect(),
        forward_peak_fraction: orders
            .iter()
            .map(|&n| mixture.forward_peak_fraction(n))
            .collect(),
        g,
        sigma_ext_m2: ext,
        albedo: sca / ext,
        n_isotropic,
        l_max: mixture.l_max(),
    }
}

/// Error of one field and channel of a bake against a reference bake.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelError {
    pub field: String,
    pub channel: &'static str,
    /// rms over bins θ ≥ min angle of |v − v_ref| / v_ref, row Ams_1.
    pub rms_rel_ams1: f64,
    pub max_rel_ams1: f64,
    /// The same over every row.
    pub rms_rel_all: f64,
    pub max_rel_all: f64,
    /// max_i |F_i − F_i,ref|.
    pub max_abs_forward_fraction: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct CompareReport {
    pub min_angle_deg: f64,
    pub fields: Vec<ChannelError>,
}

/// Compares every field of `dir` with the same field of `reference` (same grid and N).
pub fn compare(dir: &Path, reference: &Path, min_angle_deg: f64) -> Result<CompareReport> {
    use crate::exr_io::read_field_exr;
    let ours = crate::manifest::read_manifest(dir)?;
    let theirs = crate::manifest::read_manifest(reference)?;
    if ours.theta_step_deg != theirs.theta_step_deg || ours.angle_count != theirs.angle_count {
        bail!(
            "the bakes use different grids: Δθ = {}° ({} angles) against {}° ({} angles)",
            ours.theta_step_deg,
            ours.angle_count,
            theirs.theta_step_deg,
            theirs.angle_count
        );
    }
    if !(0.0..=180.0).contains(&min_angle_deg) {
        bail!("--min-angle-deg {min_angle_deg} is outside the allowed range [0, 180]");
    }
    let k0 = (min_angle_deg / ours.theta_step_deg).ceil() as usize;
    let mut fields = Vec::new();
    for f in &ours.fields {
        let Some(r) = theirs.fields.iter().find(|r| r.name == f.name) else {
            bail!(
                "field {:?} is not in the reference bake {}",
                f.name,
                reference.display()
            );
        };
        let a = read_field_exr(dir.join(&f.file))?;
        let b = read_field_exr(reference.join(&r.file))?;
        if a.n_max() != b.n_max() {
            bail!(
                "field {:?}: N = {} against the reference's {}",
                f.name,
                a.n_max(),
                b.n_max()
            );
        }
        for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
            let rel = |row: usize| -> Vec<f64> {
                a.rows[c][row][k0..]
                    .iter()
                    .zip(&b.rows[c][row][k0..])
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
            let df = a.forward_fraction[c]
                .iter()
                .zip(&b.forward_fraction[c])
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
