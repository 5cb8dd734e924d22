//! `photometeor bake`: scene → plan → per-field phase functions (Mie or the crystal tracer) →
//! RGB → Ams_n, F_n → EXR + manifest, with a content-addressed [`crate::cache`] so an unchanged
//! field is not recomputed.
//!
//! The plan ([`BakePlan`]) is plain data made from the validated scene and the caller's options;
//! nothing touches the output directory until every field is computed.

use std::path::{Path, PathBuf};
use std::time::Instant;

use format::exr::field_exr_bytes;
use format::{
    BakeLock, FieldEntry, FieldImage, Manifest, PerChannel, PoissonTable, SingleScatter, Staging,
};
use grid::ThetaGrid;
use mie::PhaseFunction;
use mie::crystal::CrystalTracer;
use mie::ensemble::bulk_with_spread;
use ndarray::{Array2, Array3, s};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tables::ams::{AmsMixture, AmsSeries};
use tables::spectral::{ChannelWeights, SpectralMode};

use crate::cache::{self, Lookup, content_hash};
use crate::error::BakeError;
use crate::plan::{BakePlan, Knobs};
use crate::progress::Progress;
use crate::scene::{Field, Quality};

/// n_iso is searched up to this order.
const N_ISO_CAP: usize = 100_000;
/// The ε of the n_iso report, in the order of [`format::manifest::N_ISOTROPIC_EPSILONS`].
const N_ISO_EPSILONS: [f64; 3] = [1e-2, 1e-4, 1e-6];

/// The per-channel numbers of a field the manifest carries beside its EXR.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldSummary {
    /// Per channel and row: the energy of Ams_n held by the exact forward delta.
    pub forward_peak_fraction: [Vec<f64>; 3],
    /// g = ⟨cos θ⟩ per channel.
    pub g: [f64; 3],
    /// σ_ext per particle (m²) per channel.
    pub sigma_ext_m2: [f64; 3],
    /// Single-scattering albedo per channel.
    pub albedo: [f64; 3],
    /// `n_isotropic[e][c]`: n_iso(ε_e) of channel c.
    pub n_isotropic: [[Option<u32>; 3]; 3],
    /// Highest Legendre degree used.
    pub l_max: usize,
    /// Seconds the field took to compute.
    pub seconds: f64,
    /// Ice and snow: how far their Monte Carlo went (None for drops).
    #[serde(default)]
    pub crystal_sampling: Option<CrystalSampling>,
    /// Drops: the sizes per wavelength they were computed with, the mean over the wavelengths
    /// ([`drop_sizes`]).
    #[serde(default)]
    pub sizes: Option<usize>,
    /// Drops: per channel, the rms relative standard error of Ams_1 over the bins θ ≥ 1° from
    /// the finite set of sizes, estimated from the spread between the two interleaved halves
    /// of each wavelength's size nodes (`mie::ensemble::bulk_with_spread`).
    #[serde(default)]
    pub size_noise: Option<[f64; 3]>,
}

/// How many rays a crystal field's tables rest on and the noise they were traced to.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CrystalSampling {
    /// Rays that hit a crystal, all wavelengths together.
    pub rays: u64,
    /// Per channel, the rms relative standard error of Ams_1 over the bins θ ≥ 1° (rough
    /// crystals ≤ 179° too: `mie::crystal::noise_skips_pole`), estimated from the
    /// spread between independent chunks of rays (the quantity the presets' noise targets stop
    /// at).
    pub noise: [f64; 3],
}

/// One field's bake: its RGB tables and their summary.
#[derive(Debug, Clone, PartialEq)]
pub struct BakedField {
    /// Ams_1..Ams_N and F_1..F_N per channel, as written to the field's EXR.
    pub image: FieldImage,
    /// The numbers the manifest carries.
    pub summary: FieldSummary,
    /// The single-scattering optics per wavelength, as written to `<name>.single.exr`.
    pub single: SingleScatter,
    /// The Poisson mixtures M(D, θ) per channel, as written to `<name>.poisson.exr`.
    pub poisson: PoissonTable,
}

/// The cache record of a field: the tables flattened, and the summary.
#[derive(Serialize, Deserialize)]
struct Record {
    n_max: usize,
    angle_count: usize,
    ams: Vec<f64>,
    forward_fraction: Vec<f64>,
    summary: FieldSummary,
    wavelengths_nm: Vec<f64>,
    single_bins: Vec<f64>,
    forward_delta_fraction: Vec<f64>,
    sigma_ext_m2: Vec<f64>,
    albedo: Vec<f64>,
    poisson_depths: Vec<f64>,
    /// As f32, the precision of the EXR they are written to (the bytes are the same).
    poisson_rows: Vec<f32>,
}

impl Record {
    fn of(field: &BakedField) -> Self {
        Self {
            n_max: field.image.n_max(),
            angle_count: field.image.angle_count(),
            ams: field.image.ams.iter().copied().collect(),
            forward_fraction: field.image.forward_fraction.iter().copied().collect(),
            summary: field.summary.clone(),
            wavelengths_nm: field.single.wavelengths_nm.clone(),
            single_bins: field.single.bins.iter().copied().collect(),
            forward_delta_fraction: field.single.forward_delta_fraction.clone(),
            sigma_ext_m2: field.single.sigma_ext_m2.clone(),
            albedo: field.single.albedo.clone(),
            poisson_depths: field.poisson.depths.clone(),
            poisson_rows: field.poisson.rows.iter().map(|&v| v as f32).collect(),
        }
    }

    fn into_field(self, name: &str, theta_step_deg: f64) -> Option<BakedField> {
        let ams = Array3::from_shape_vec((3, self.n_max, self.angle_count), self.ams).ok()?;
        let forward_fraction =
            Array2::from_shape_vec((3, self.n_max), self.forward_fraction).ok()?;
        let bins = Array2::from_shape_vec(
            (self.wavelengths_nm.len(), self.angle_count),
            self.single_bins,
        )
        .ok()?;
        let poisson_rows = Array3::from_shape_vec(
            (3, self.poisson_depths.len(), self.angle_count),
            self.poisson_rows.into_iter().map(f64::from).collect(),
        )
        .ok()?;
        Some(BakedField {
            poisson: PoissonTable {
                field: name.to_string(),
                theta_step_deg,
                depths: self.poisson_depths,
                rows: poisson_rows,
            },
            single: SingleScatter {
                field: name.to_string(),
                theta_step_deg,
                wavelengths_nm: self.wavelengths_nm,
                bins,
                forward_delta_fraction: self.forward_delta_fraction,
                sigma_ext_m2: self.sigma_ext_m2,
                albedo: self.albedo,
            },
            image: FieldImage {
                field: name.to_string(),
                theta_step_deg,
                ams,
                forward_fraction,
                extra_layers: Vec::new(),
            },
            summary: self.summary,
        })
    }
}

/// Summary of a bake.
#[derive(Debug, Clone, Serialize)]
pub struct BakeReport {
    /// The scene's name.
    pub scene: String,
    /// The bake directory.
    pub out_dir: PathBuf,
    /// The preset.
    pub quality: Quality,
    /// Fields computed in this run.
    pub computed: Vec<String>,
    /// Fields read from the cache.
    pub cached: Vec<String>,
    /// Cache records that could not be used (file and why); their fields were recomputed.
    pub rejected_cache: Vec<String>,
    /// Leftovers of interrupted bakes finished or removed before this one (see
    /// `photometeor_format::commit`).
    pub cleaned: Vec<String>,
    /// Fields of the bake the directory held before that this one replaced and removed (a
    /// bake of another scene into the same directory, or of this scene without them).
    pub replaced: Vec<String>,
    /// Wall-clock seconds.
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

/// Runs a plan. Fields whose inputs are unchanged are read from the cache.
pub fn run(plan: &BakePlan, progress: &dyn Progress) -> Result<BakeReport, BakeError> {
    let start = Instant::now();
    let weights = ChannelWeights::new(&plan.scene.spectral)?;
    let grid = ThetaGrid::new(plan.scene.theta_step_deg)?;
    let mut report = BakeReport::empty(plan);
    // Every check that needs no solver, before any work: the output directory can be written,
    // and every field's refractive index and size parameters are in range at every wavelength.
    preflight(plan, &weights)?;
    // Compute (or read from the cache) every field first; only then touch the tables, so a
    // failing field leaves the previous bake as it was.
    let lookups = look_up_cache(plan, &mut report.rejected_cache);
    let (computed, encoded) = compute_and_encode(plan, &lookups, &weights, &grid, progress)?;
    let done = take_results(lookups, computed, &mut report);
    // Only now are the tables touched (beyond the cache records each field wrote as it
    // finished), under the directory's lock: a pending commit of an interrupted bake is
    // finished and dead writers' leftovers removed (format::commit).
    let lock = BakeLock::acquire(&plan.out_dir)?;
    report.cleaned = lock.clean_stale()?;
    // The previous bake, and which of its fields this one keeps.
    let previous = format::read_manifest(&plan.out_dir).ok();
    let channels = channel_definitions(&weights);
    let kept = kept_fields(plan, previous.as_ref(), &channels)?;
    let sweeps = sweep_entries(plan, previous.as_ref(), &kept);
    let manifest = publish(
        plan,
        &lock,
        done,
        encoded,
        (kept, sweeps),
        channels,
        grid.len(),
    )?;
    report.replaced = remove_stale_tables(plan, previous, &manifest);
    drop(lock);
    report.seconds = start.elapsed().as_secs_f64();
    report.peak_rss_mib = peak_rss_mib();
    Ok(report)
}

impl BakeReport {
    /// The report of `plan` before anything is done.
    fn empty(plan: &BakePlan) -> Self {
        Self {
            scene: plan.scene.name.clone(),
            out_dir: plan.out_dir.clone(),
            quality: plan.quality,
            computed: Vec::new(),
            cached: Vec::new(),
            rejected_cache: Vec::new(),
            cleaned: Vec::new(),
            replaced: Vec::new(),
            seconds: 0.0,
            peak_rss_mib: None,
        }
    }
}

/// A field of the scene, its content hash and cache record, and the bake the record holds if it
/// could be used.
struct CacheLookup<'a> {
    field: &'a Field,
    hash: String,
    cache_file: PathBuf,
    cached: Option<BakedField>,
}

/// Each field's cache record, in scene order; a record that could not be used is listed in
/// `rejected` (file and why) and its field computed again.
fn look_up_cache<'a>(plan: &'a BakePlan, rejected: &mut Vec<String>) -> Vec<CacheLookup<'a>> {
    let mut lookups = Vec::new();
    for field in &plan.scene.fields {
        let hash = content_hash(plan, field);
        let cache_file = cache::record_path(&plan.out_dir, &hash);
        let cached = match cache::read::<Record>(&cache_file, &hash) {
            Lookup::Hit(r) => r.into_field(&field.name, plan.scene.theta_step_deg),
            Lookup::Missing => None,
            Lookup::Rejected(why) => {
                rejected.push(format!("{}: {why}", cache_file.display()));
                None
            }
        };
        lookups.push(CacheLookup {
            field,
            hash,
            cache_file,
            cached,
        });
    }
    lookups
}

/// A field's four EXRs, encoded.
struct Encoded {
    table: Vec<u8>,
    single: Vec<u8>,
    poisson: Vec<u8>,
    biri: Vec<u8>,
}

/// The EXRs of one field's bake ([`Encoded`]).
fn encode(result: &BakedField) -> Result<Encoded, BakeError> {
    Ok(Encoded {
        table: field_exr_bytes(&result.image)?,
        single: format::single_exr_bytes(&result.single)?,
        poisson: format::poisson_exr_bytes(&result.poisson)?,
        // Biri's point-light kernel from Ams_1 per channel (cheap: not cached).
        biri: format::biri_exr_bytes(&biri_kernel(&result.image))?,
    })
}

/// Computes the fields the cache did not hold and encodes every field's EXRs, in scene order:
/// the computed bakes (None where cached) and each field's EXRs. The fields run side by side
/// (each field's numbers do not depend on what runs beside it), and each field's EXRs are
/// encoded as soon as it is done, beside the fields still computing (their deflate and Biri's
/// kernel fit had been a serial tail of every bake); they are written, in scene order, once
/// every field is done.
fn compute_and_encode(
    plan: &BakePlan,
    lookups: &[CacheLookup],
    weights: &ChannelWeights,
    grid: &ThetaGrid,
    progress: &dyn Progress,
) -> Result<(Vec<Option<BakedField>>, Vec<Encoded>), BakeError> {
    let computed: Vec<Result<(Option<BakedField>, Encoded), BakeError>> = lookups
        .par_iter()
        .map(|lookup| {
            let computed = match &lookup.cached {
                Some(_) => None,
                None => {
                    let result = compute_field(plan, lookup.field, weights, grid, progress)?;
                    // The field's cache record at once (a checkpoint: a bake killed later
                    // starts again from the fields it finished). Records are content-addressed
                    // and written atomically, so no lock is needed (a shard writes its own the
                    // same way); the tables are published under the lock below.
                    create_cache_dir(plan)?;
                    cache::write(&lookup.cache_file, &lookup.hash, &Record::of(&result))?;
                    Some(result)
                }
            };
            let result = computed.as_ref().or(lookup.cached.as_ref());
            let encoded = encode(result.expect("a field cached or computed"))?;
            Ok((computed, encoded))
        })
        .collect();
    // The first failing field in scene order, whatever finished first.
    Ok(computed
        .into_iter()
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .unzip())
}

/// A field's bake, cached or computed (its cache record written as it finished).
struct Done<'a> {
    field: &'a Field,
    hash: String,
    result: BakedField,
}

/// Each field's bake from the cache or from this run, in scene order, listing each field in
/// `report` as cached or computed.
fn take_results<'a>(
    lookups: Vec<CacheLookup<'a>>,
    computed: Vec<Option<BakedField>>,
    report: &mut BakeReport,
) -> Vec<Done<'a>> {
    let mut done = Vec::new();
    for (lookup, computed) in lookups.into_iter().zip(computed) {
        let CacheLookup {
            field,
            hash,
            cached,
            ..
        } = lookup;
        let result = match (cached, computed) {
            (Some(r), _) => {
                report.cached.push(field.name.clone());
                r
            }
            (None, Some(r)) => {
                report.computed.push(field.name.clone());
                r
            }
            (None, None) => unreachable!("a field neither cached nor computed"),
        };
        done.push(Done {
            field,
            hash,
            result,
        });
    }
    done
}

/// The fields of the `previous` bake in the directory that this one keeps: with `plan.prune`
/// none; else those of other names, if the previous bake is on the same grid and channels (an
/// error if it is not and has such fields, which this bake would orphan).
fn kept_fields(
    plan: &BakePlan,
    previous: Option<&Manifest>,
    channels: &format::Channels,
) -> Result<Vec<FieldEntry>, BakeError> {
    let mut kept: Vec<FieldEntry> = Vec::new();
    if !plan.prune
        && let Some(previous) = previous
    {
        // Keep the other fields of a compatible previous bake (same grid and channels).
        let compatible =
            previous.theta_step_deg == plan.scene.theta_step_deg && previous.channels == *channels;
        // A member of an earlier sweep of a field this scene has (swept or not) is ours too:
        // the sweep may have shrunk.
        let stem = |name: &str| name.split('@').next().unwrap_or_default().to_string();
        let ours = |old: &FieldEntry| {
            plan.scene.fields.iter().any(|f| {
                f.name == old.name
                    || format!("{}.exr", f.name) == old.file
                    || stem(&f.name) == stem(&old.name)
            })
        };
        let others: Vec<&FieldEntry> = previous.fields.iter().filter(|o| !ours(o)).collect();
        if !others.is_empty() && !compatible {
            return Err(BakeError::Incompatible(format!(
                "{} holds a bake on another grid or spectrum with fields {:?}, which this bake \
                 would orphan; bake into another directory",
                plan.out_dir.display(),
                others.iter().map(|o| o.name.as_str()).collect::<Vec<_>>()
            )));
        }
        kept = others.into_iter().cloned().collect();
    }
    Ok(kept)
}

/// The manifest's sweeps: the scene's, and those of the previous bake whose members are all
/// kept.
fn sweep_entries(
    plan: &BakePlan,
    previous: Option<&Manifest>,
    kept: &[FieldEntry],
) -> Vec<format::SweepEntry> {
    let mut sweeps: Vec<format::SweepEntry> = plan
        .scene
        .sweeps
        .iter()
        .map(crate::scene::Sweep::entry)
        .collect();
    for old in previous.map_or(&[][..], |p| &p.sweeps) {
        let all_kept = old.fields.iter().all(|m| kept.iter().any(|k| &k.name == m));
        if all_kept && !sweeps.iter().any(|s| s.name == old.name) {
            sweeps.push(old.clone());
        }
    }
    sweeps
}

/// Computes `field` (unless `plan.out_dir`'s cache holds it) and writes its cache record there,
/// publishing nothing: a shard's work ([`crate::shard`]). Returns the field's content hash and
/// whether it was computed.
pub(crate) fn compute_record(
    plan: &BakePlan,
    field: &Field,
    progress: &dyn Progress,
) -> Result<(String, bool), BakeError> {
    let hash = content_hash(plan, field);
    let cache_file = cache::record_path(&plan.out_dir, &hash);
    if let Lookup::Hit(_) = cache::read::<Record>(&cache_file, &hash) {
        return Ok((hash, false));
    }
    let weights = ChannelWeights::new(&plan.scene.spectral)?;
    let grid = ThetaGrid::new(plan.scene.theta_step_deg)?;
    let result = compute_field(plan, field, &weights, &grid, progress)?;
    create_cache_dir(plan)?;
    cache::write(&cache_file, &hash, &Record::of(&result))?;
    Ok((hash, true))
}

/// Creates `plan.out_dir`'s cache directory.
fn create_cache_dir(plan: &BakePlan) -> Result<(), BakeError> {
    let cache_dir = plan.out_dir.join(".cache");
    std::fs::create_dir_all(&cache_dir).map_err(|source| BakeError::Io {
        path: cache_dir,
        op: "creating",
        source,
    })
}

/// Whether `dir`'s cache holds a usable record of `hash`.
pub(crate) fn has_record(dir: &Path, hash: &str) -> bool {
    matches!(
        cache::read::<Record>(&cache::record_path(dir, hash), hash),
        Lookup::Hit(_)
    )
}

/// Stages the whole generation (every field's EXRs, the `kept` fields' entries and the
/// manifest), then publishes it in one rename (format::commit); the manifest published.
fn publish(
    plan: &BakePlan,
    lock: &BakeLock,
    done: Vec<Done>,
    encoded: Vec<Encoded>,
    (kept, sweeps): (Vec<FieldEntry>, Vec<format::SweepEntry>),
    channels: format::Channels,
    angle_count: usize,
) -> Result<Manifest, BakeError> {
    let mut stage = Staging::begin(lock)?;
    let mut entries = Vec::new();
    for (d, bytes) in done.into_iter().zip(encoded) {
        entries.push(stage_field(&mut stage, plan, d, &bytes)?);
    }
    entries.extend(kept);
    let manifest = Manifest {
        schema: format::manifest::MANIFEST_SCHEMA_VERSION,
        tool: "photometeor".into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        theta_step_deg: plan.scene.theta_step_deg,
        angle_count,
        channels,
        fields: entries,
        sweeps,
    };
    manifest
        .check()
        .map_err(|e| BakeError::Incompatible(format!("the new manifest: {}", e.what)))?;
    stage.write(format::MANIFEST_FILE, &manifest.to_json_bytes())?;
    stage.commit()?;
    Ok(manifest)
}

/// Stages one field's four EXRs; its manifest entry.
fn stage_field(
    stage: &mut Staging,
    plan: &BakePlan,
    d: Done,
    bytes: &Encoded,
) -> Result<FieldEntry, BakeError> {
    let file = format!("{}.exr", d.field.name);
    stage.write(&file, &bytes.table)?;
    let single_file = format::single_file_name(&d.field.name);
    stage.write(&single_file, &bytes.single)?;
    let poisson_file = format::poisson_file_name(&d.field.name);
    stage.write(&poisson_file, &bytes.poisson)?;
    let mut entry = field_entry(plan, d.field, &d.result, file, d.hash, &bytes.table);
    entry.single_scattering = Some(file_ref(single_file, &bytes.single));
    entry.poisson = Some(file_ref(poisson_file, &bytes.poisson));
    let biri_file = format::biri_file_name(&d.field.name);
    stage.write(&biri_file, &bytes.biri)?;
    entry.biri_kernel = Some(file_ref(biri_file, &bytes.biri));
    Ok(entry)
}

/// The manifest's reference to a file of these bytes.
fn file_ref(file: String, bytes: &[u8]) -> format::manifest::FileRef {
    format::manifest::FileRef {
        file,
        bytes: bytes.len() as u64,
        crc32: format::crc32_hex(bytes),
    }
}

/// Removes the tables of the `previous` bake's fields that `manifest` no longer has (they would
/// be read as current); returns the names of those fields.
fn remove_stale_tables(
    plan: &BakePlan,
    previous: Option<Manifest>,
    manifest: &Manifest,
) -> Vec<String> {
    let mut removed = Vec::new();
    if let Some(previous) = previous {
        for old in previous.fields {
            let stale = !manifest.fields.iter().any(|f| f.file == old.file);
            if stale {
                if !manifest.fields.iter().any(|f| f.name == old.name) {
                    removed.push(old.name.clone());
                }
                let _ = std::fs::remove_file(plan.out_dir.join(&old.file));
                let extras = [&old.single_scattering, &old.poisson, &old.biri_kernel];
                for extra in extras.into_iter().flatten() {
                    let _ = std::fs::remove_file(plan.out_dir.join(&extra.file));
                }
            }
        }
    }
    removed
}

/// The solver's refusal of `field`'s inputs, with where it happened (`context`).
fn mie_error(field: &Field, context: String) -> impl FnOnce(mie::MieError) -> BakeError {
    let name = field.name.clone();
    move |source| BakeError::Mie {
        field: name,
        context,
        source,
    }
}

/// [`preflight`] with the scene's own channel weights: what [`run`] refuses before computing
/// anything, for a caller that has only the plan.
pub fn check_before_work(plan: &BakePlan) -> Result<(), BakeError> {
    preflight(plan, &ChannelWeights::new(&plan.scene.spectral)?)
}

/// The checks [`run`] makes before computing anything (see there).
pub fn preflight(plan: &BakePlan, weights: &ChannelWeights) -> Result<(), BakeError> {
    check_writable(&plan.out_dir)?;
    let lambdas = &weights.wavelengths_nm;
    let j_len = lambdas.len();
    for field in &plan.scene.fields {
        let mie_error = |context: String| mie_error(field, context);
        for (j, &lambda) in lambdas.iter().enumerate() {
            let m = field
                .refractive_index(lambda)
                .map_err(mie_error(format!(" at {lambda} nm")))?;
            if let Some(d) = &field.distribution {
                // The radii this wavelength's quadrature uses, with the solver's own x = k r.
                let q = plan.knobs.size_quadrature(d, j, j_len);
                let k = 2.0 * std::f64::consts::PI / (lambda / 1000.0);
                for &r in [q.radius_um.first(), q.radius_um.last()].iter().flatten() {
                    mie::Sphere::new(m, k * r).map_err(mie_error(format!(
                        " at {lambda} nm, radius {} µm (the quadrature's range after truncating {:e} of the mass)",
                        mie::error::Shown(*r),
                        plan.knobs.tail_mass
                    )))?;
                }
            }
        }
    }
    Ok(())
}

/// Fails early when `dir` (or, if it does not exist yet, its nearest existing ancestor) is not a
/// directory this process can create files in.
fn check_writable(dir: &Path) -> Result<(), BakeError> {
    let io = |path: &Path, source: std::io::Error| BakeError::Io {
        path: path.to_path_buf(),
        op: "checking that the output directory can be written",
        source,
    };
    let mut probe_dir = dir;
    while !probe_dir.exists() {
        match probe_dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => probe_dir = p,
            _ => {
                probe_dir = Path::new(".");
                break;
            }
        }
    }
    if !probe_dir.is_dir() {
        return Err(io(
            probe_dir,
            std::io::Error::other("exists and is not a directory"),
        ));
    }
    let probe = probe_dir.join(format!(".photometeor-probe-{}", std::process::id()));
    std::fs::File::create(&probe).map_err(|e| io(probe_dir, e))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

fn field_entry(
    plan: &BakePlan,
    field: &Field,
    r: &BakedField,
    file: String,
    hash: String,
    bytes: &[u8],
) -> FieldEntry {
    let s = &r.summary;
    let n_iso = |c: usize| {
        format::manifest::N_ISOTROPIC_EPSILONS
            .iter()
            .enumerate()
            .map(|(e, key)| (key.to_string(), s.n_isotropic[e][c]))
            .collect()
    };
    let forward_fraction: [Vec<f64>; 3] =
        std::array::from_fn(|c| r.image.forward_fractions(c).to_vec());
    FieldEntry {
        name: field.name.clone(),
        file,
        bytes: bytes.len() as u64,
        crc32: format::crc32_hex(bytes),
        kind: field.kind,
        n_max: plan.scene.n_max,
        forward_fraction: PerChannel::from_array(forward_fraction),
        forward_peak_fraction: PerChannel::from_array(s.forward_peak_fraction.clone()),
        g: PerChannel::from_array(s.g),
        sigma_ext_m2: PerChannel::from_array(s.sigma_ext_m2),
        albedo: PerChannel::from_array(s.albedo),
        n_isotropic: PerChannel::from_array([n_iso(0), n_iso(1), n_iso(2)]),
        microphysics: format::Microphysics {
            crystal: field
                .crystal
                .map(|c| serde_json::to_value(c).expect("a crystal serializes")),
            distribution: field
                .distribution
                .map(|d| serde_json::to_value(d).expect("a distribution serializes")),
            kind: field.kind,
            material: match field.material {
                mie::refractive::Material::Water => format::Material::Water,
                mie::refractive::Material::Ice => format::Material::Ice,
            },
            name: field.name.clone(),
            refractive_index: field.refractive_index,
            albedo: field.albedo.map(format::ChannelValues::of),
            hg: field
                .hg
                .map(|h| serde_json::to_value(h).expect("a lobe serializes")),
            // The table as read, and the normalization found per column (its integral over
            // the sphere, which the bins are divided by).
            tabulated: field.tabulated.as_ref().map(|t| {
                let mut v = serde_json::to_value(t).expect("a table serializes");
                v["sphere_integral"] = (0..t.columns.len())
                    .map(|c| t.sphere_integral(c))
                    .collect::<Vec<f64>>()
                    .into();
                v
            }),
            temperature_c: field.temperature_c,
        },
        quality: format::QualityRecord {
            crystal_noise: s
                .crystal_sampling
                .as_ref()
                .map(|c| PerChannel::from_array(c.noise)),
            crystal_rays: s.crystal_sampling.as_ref().map(|c| c.rays),
            knobs: serde_json::to_value(plan.knobs).expect("the knobs serialize"),
            legendre_l_max: s.l_max,
            preset: match plan.quality {
                Quality::Draft => "draft",
                Quality::Standard => "standard",
                Quality::Reference => "reference",
            }
            .into(),
            size_noise: s.size_noise.map(PerChannel::from_array),
            sizes: s.sizes,
        },
        content_hash: hash,
        single_scattering: None,
        poisson: None,
        // σ_tr/σ_t = 1 − α g (Max et al. 2004 §2, after Ishimaru 1978).
        transport_factor: Some(PerChannel::from_array(std::array::from_fn(|c| {
            1.0 - s.albedo[c] * s.g[c]
        }))),
        biri_kernel: None,
    }
}

/// The manifest's `channels` of `weights`: the colour space, the observer and illuminant the
/// weights come from (`tables::spectral`), the wavelengths and each channel's weights.
pub fn channel_definitions(weights: &ChannelWeights) -> format::Channels {
    format::Channels {
        illuminant: "ASTM G173-03 extraterrestrial solar spectrum".into(),
        mixing: "channel phase function = Σ_j w_cj σ_sca,j P_j / Σ_j w_cj σ_sca,j; Ams_n mixed the same way per wavelength".into(),
        mode: match weights.mode {
            SpectralMode::Rgb3 => format::SpectralSampling::Rgb3,
            SpectralMode::Spectral {
                count,
                min_nm,
                max_nm,
            } => format::SpectralSampling::Spectral {
                count,
                min_nm,
                max_nm,
            },
        },
        names: ["R", "G", "B"].map(String::from).to_vec(),
        negative_lobe_fraction: PerChannel::from_array(weights.negative_lobe_fraction),
        observer: "CIE 1931 2° colour-matching functions".into(),
        space: "linear sRGB / Rec.709 primaries, D65 white (IEC 61966-2-1)".into(),
        unit: "1/sr; each channel's row integrates to 1 over the sphere".into(),
        wavelengths_nm: weights.wavelengths_nm.clone(),
        weights: PerChannel::from_array(weights.weights.clone()),
    }
}

/// Biri et al.'s point-light kernel tables (`tables::biri`) of a field's Ams_1 per channel.
pub fn biri_kernel(image: &FieldImage) -> format::BiriTable {
    let grid = ThetaGrid::new(image.theta_step_deg).expect("a bake's own grid");
    let rows: Vec<Vec<f64>> = (0..3).map(|c| image.row(c, 0).to_vec()).collect();
    let rows: Vec<&[f64]> = rows.iter().map(|r| &r[..]).collect();
    let tables = tables::biri::kernel_tables(&grid, &rows);
    let depths = tables[0].depths.clone();
    format::BiriTable {
        field: image.field.clone(),
        theta_step_deg: image.theta_step_deg,
        primitive: Array3::from_shape_fn((3, depths.len(), grid.len()), |(c, j, k)| {
            tables[c].primitive[[j, k]]
        }),
        polynomial: std::array::from_fn(|c| tables[c].polynomial.iter().copied().collect()),
        polynomial_error: std::array::from_fn(|c| tables[c].polynomial_error.clone()),
        depths,
    }
}

/// A field's phase functions, one per wavelength in order.
pub struct Phases {
    /// The phase functions.
    pub phases: Vec<PhaseFunction>,
    /// Drops: the standard error of each bin from the size sampling (empty for crystals,
    /// whose phase functions carry their own).
    pub size_errors: Vec<Vec<f64>>,
    /// Drops: the mean sizes per wavelength ([`drop_sizes`]).
    pub sizes: Option<usize>,
}

/// The phase function of `field` at every wavelength of `weights` ([`Phases`]).
pub fn phase_functions(
    plan: &BakePlan,
    field: &Field,
    weights: &ChannelWeights,
    grid: ThetaGrid,
    advance: &dyn Fn(),
) -> Result<Phases, BakeError> {
    let knobs = plan.knobs;
    let lambdas = &weights.wavelengths_nm;
    let j_len = lambdas.len();
    let mie_error = |context: String| mie_error(field, context);
    let mut per_wavelength = Vec::with_capacity(j_len);
    let mut size_errors = Vec::new();
    let mut sizes = None;
    match (field.distribution, field.crystal) {
        (Some(distribution), _) => {
            let counts = drop_sizes(plan, field, &distribution, weights, grid)?;
            sizes = Some(counts.iter().sum::<usize>().div_ceil(j_len.max(1)));
            for (j, &lambda) in lambdas.iter().enumerate() {
                let knobs = Knobs {
                    sizes: counts[j],
                    ..knobs
                };
                let m = field
                    .refractive_index(lambda)
                    .map_err(mie_error(format!(" at {lambda} nm")))?;
                let q = knobs.size_quadrature(&distribution, j, j_len);
                let nodes = nodes_per_bin(&distribution, lambda, knobs, grid.step_deg());
                let context = format!(
                    " at {lambda} nm (radii {:.3}–{:.0} µm after truncating {:e} of the mass)",
                    q.radius_um.first().copied().unwrap_or(f64::NAN),
                    q.radius_um.last().copied().unwrap_or(f64::NAN),
                    knobs.tail_mass
                );
                let (phase, spread) = bulk_with_spread(m, lambda, &q, grid, nodes, &[])
                    .map_err(mie_error(context))?;
                per_wavelength.push(phase);
                size_errors.push(spread);
                advance();
            }
        }
        (None, Some(crystal)) => {
            let rays = ray_allocation(weights, knobs.rays);
            let skip_pole = mie::crystal::noise_skips_pole(crystal.roughness);
            let mut tracers = Vec::with_capacity(j_len);
            for (j, &lambda) in lambdas.iter().enumerate() {
                // Each wavelength its own random stream: a channel averages J independent traces;
                // another knob seed gives other streams (independent bakes).
                let seed = crystal_stream(knobs.seed, j);
                let rays = mie::crystal::Rays {
                    count: rays[j],
                    target: None,
                    max_count: rays[j].max(knobs.rays) * MAX_RAY_ROUNDS,
                    seed,
                    sampling: knobs.ray_sampling,
                    symmetric: knobs.ray_symmetric,
                    tilt_splits: knobs.tilt_splits,
                    chunk_rays: knobs.chunk_rays,
                };
                tracers.push(
                    CrystalTracer::new(&crystal, lambda, grid, rays)
                        .map_err(mie_error(format!(" at {lambda} nm")))?,
                );
                advance();
            }
            // Every wavelength carried on together, the first round's shares kept
            // (ray_allocation), until the worst channel's noise is at the
            // target: noise ∝ 1/√rays gives the rays still needed, 3 % over and at most 4× the
            // rays so far a round.
            let shares: Vec<f64> = {
                let total: u64 = rays.iter().sum();
                rays.iter().map(|&r| r as f64 / total as f64).collect()
            };
            let target = knobs.crystal_noise;
            // The wavelengths are traced side by side (`run_side_by_side`): one wavelength's
            // few chunks a round would leave a core idle at its end.
            if target > 0.0 {
                // Two chunks at least per wavelength: one chunk has no spread to give a standard
                // error, and a wavelength without one would count as noiseless.
                run_side_by_side(&mut tracers, |_, _| 2);
            }
            let phases_of =
                |tracers: &[CrystalTracer]| tracers.par_iter().map(|t| t.phase()).collect();
            let mut phases: Vec<PhaseFunction> = phases_of(&tracers);
            loop {
                let noise = channel_noise(&phases, weights, grid, skip_pole);
                if target <= 0.0 || noise <= target {
                    break;
                }
                let now: u64 = tracers.iter().map(|t| t.chunks()).sum();
                let need = (now as f64 * (1.03 * (noise / target).powi(2)).min(4.0)).ceil();
                let mut traced =
                    run_side_by_side(&mut tracers, |_, j| (need * shares[j]).ceil() as u64);
                if !traced {
                    // The shares' rounding left every wavelength where it was: one more chunk
                    // each (or all at their limit).
                    traced = run_side_by_side(&mut tracers, |t, _| t.chunks() + 1);
                }
                if !traced {
                    break;
                }
                phases = phases_of(&tracers);
            }
            per_wavelength = phases;
        }
        (None, None) => per_wavelength = given_phases(plan, field, lambdas, grid, advance)?,
    }
    // A given albedo replaces the particles' own: σ_sca = α σ_ext at every wavelength, the
    // phase function and σ_ext as computed (so the channels' mixing weights, their albedo and
    // the side tables all follow from it).
    if let Some(albedo) = field.albedo {
        for (j, p) in per_wavelength.iter_mut().enumerate() {
            let a = albedo[given_channel(plan, j)];
            p.sigma_sca_m2 = a * p.sigma_ext_m2;
            p.albedo = a;
        }
    }
    Ok(Phases {
        phases: per_wavelength,
        size_errors,
        sizes,
    })
}

/// The channel whose given values (a field's [R, G, B] albedo, lobe or cross-section) the
/// scene's wavelength `j` takes: per-channel values come only with rgb3 (the scene's check),
/// where wavelength j is channel j; otherwise the three channels' values are one.
fn given_channel(plan: &BakePlan, j: usize) -> usize {
    if plan.scene.spectral == tables::spectral::SpectralMode::Rgb3 {
        j
    } else {
        0
    }
}

/// A given phase function's optics at each of `lambdas`: an `hg` field's closed-form bins
/// (`mie::hg`) or a `tabulated` field's exact bins of its linear interpolant
/// (`mie::tabulated`), with the values of [`given_channel`].
fn given_phases(
    plan: &BakePlan,
    field: &Field,
    lambdas: &[f64],
    grid: ThetaGrid,
    advance: &dyn Fn(),
) -> Result<Vec<PhaseFunction>, BakeError> {
    let channel = |j: usize| given_channel(plan, j);
    let phase = |j: usize, lambda: f64| match (&field.hg, &field.tabulated) {
        (Some(hg), _) => Ok(hg.phase(channel(j), lambda, grid)),
        (None, Some(table)) => Ok(table.phase(table.column_of(j), channel(j), lambda, grid)),
        (None, None) => Err(BakeError::Incompatible(format!(
            "field {:?} has neither sizes nor crystals nor a lobe nor a table",
            field.name
        ))),
    };
    lambdas
        .iter()
        .enumerate()
        .map(|(j, &lambda)| {
            let p = phase(j, lambda);
            advance();
            p
        })
        .collect()
}

/// Carries every wavelength's tracer on to `chunks(tracer, j)` chunks, the wavelengths side by
/// side (each tracer's tallies are fixed by its own chunks' seeds, whatever runs when); whether
/// any traced.
fn run_side_by_side(
    tracers: &mut [CrystalTracer],
    chunks: impl Fn(&CrystalTracer, usize) -> u64 + Sync,
) -> bool {
    tracers
        .par_iter_mut()
        .enumerate()
        .map(|(j, t)| {
            let to = chunks(t, j);
            t.run_to(to)
        })
        .reduce(|| false, |a, b| a || b)
}

/// The sizes [`drop_sizes`] takes over the count its prediction gives (√1.15: 7 % less noise).
const SIZE_MARGIN: f64 = 1.15;

/// Fewest sizes a wavelength of a sized drop field gets (its two halves give its noise). At 8
/// the default rain at draft took 9 per wavelength (mean) for 3.05 % where 3.5 % was asked.
const MIN_SIZES: usize = 6;

/// The sizes each wavelength of a drop field is computed with: the knobs' own, or with a
/// `size_noise` target (and a distribution, not one size) the counts that bring the worst
/// channel's noise there, predicted by a pilot. The pilot is the wavelength channels lean on
/// most, at a quarter of the knobs' sizes; its rms relative standard error s over θ ≥ 1° (from
/// its two interleaved half-sets, `mie::ensemble::bulk_with_spread`) is taken for every
/// wavelength at equal sizes, so wavelength j with n_j sizes has variance s² N_pilot / n_j and
/// channel c (weights a_cj, Σ_j a_cj = 1) s² N_pilot Σ_j a_cj² / n_j. The n_j follow
/// [`sample_shares`], a size at wavelength λ costing ∝ 1/λ (the terms of the Mie series ∝ x),
/// scaled by [`SIZE_MARGIN`] over the total that puts the worst channel at the target. The
/// noise falls a little faster than N^−1/2 (rain N^−0.53, the cloud N^−0.6 to −0.75,
/// docs/accuracy.md "Mie sizes"), but a channel's other wavelengths may be noisier than the
/// pilot (the default scene's rain at standard without the margin: 0.70 / 0.69 / 0.81 %
/// (R/G/B) for a target of 0.8 %). Each count lies in [[`MIN_SIZES`], 4 × the knobs' sizes].
pub fn drop_sizes(
    plan: &BakePlan,
    field: &Field,
    distribution: &mie::SizeDistribution,
    weights: &ChannelWeights,
    grid: ThetaGrid,
) -> Result<Vec<usize>, BakeError> {
    let knobs = plan.knobs;
    let target = knobs.size_noise;
    let lambdas = &weights.wavelengths_nm;
    let j_len = lambdas.len();
    if target <= 0.0 || matches!(distribution, mie::SizeDistribution::Monodisperse { .. }) {
        return Ok(vec![knobs.sizes; j_len]);
    }
    let importance = |j: usize| (0..3).map(|c| weights.weights[c][j]).fold(0.0, f64::max);
    let pilot = (0..j_len)
        .max_by(|&a, &b| importance(a).total_cmp(&importance(b)))
        .unwrap_or(0);
    let lambda = lambdas[pilot];
    let pilot_knobs = Knobs {
        sizes: (knobs.sizes / 4).max(16),
        ..knobs
    };
    let m = field
        .refractive_index(lambda)
        .map_err(mie_error(field, format!(" at {lambda} nm")))?;
    let q = pilot_knobs.size_quadrature(distribution, pilot, j_len);
    let nodes = nodes_per_bin(distribution, lambda, knobs, grid.step_deg());
    let (phase, spread) = bulk_with_spread(m, lambda, &q, grid, nodes, &[]).map_err(mie_error(
        field,
        format!(" at {lambda} nm (the size count's pilot)"),
    ))?;
    let s = mie::crystal::relative_noise(grid, &phase.bins, &spread, false);
    let cost: Vec<f64> = lambdas.iter().map(|l| 1.0 / l).collect();
    let shares = sample_shares(weights, &cost);
    // The worst channel's Σ_j a_cj² / share_j: its variance is s² N_pilot that over the total.
    let mix = crate::plan::channel_noise(weights, |_, j| shares[j]);
    let total = SIZE_MARGIN * pilot_knobs.sizes as f64 * s * s * mix / (target * target);
    let most = 4 * knobs.sizes.max(16);
    Ok(shares
        .iter()
        .map(|n| ((total * n).ceil() as usize).clamp(MIN_SIZES, most))
        .collect())
}

/// Phase functions per wavelength → RGB → Ams_n per channel.
pub fn compute_field(
    plan: &BakePlan,
    field: &Field,
    weights: &ChannelWeights,
    grid: &ThetaGrid,
    progress: &dyn Progress,
) -> Result<BakedField, BakeError> {
    let start = Instant::now();
    let lambdas = &weights.wavelengths_nm;
    let bar = progress.field(&field.name, lambdas.len() as u64 + 3);
    bar.message(if field.crystal.is_some() {
        "ray tracing per wavelength"
    } else if field.hg.is_some() {
        "Henyey–Greenstein lobe per wavelength"
    } else if field.tabulated.is_some() {
        "the table per wavelength"
    } else {
        "Mie per wavelength"
    });
    let phases = phase_functions(plan, field, weights, *grid, &|| bar.advance())?;
    let per_wavelength = &phases.phases;
    // Channel c mixes wavelength j with a_cj = w_cj σ_sca,j / Σ_j w_cj σ_sca,j (the scattered
    // light's spectrum); every row is Σ_j a_cj Ams_n[P_j], light keeping its wavelength.
    bar.message("Legendre series per wavelength");
    let series = legendre_series(per_wavelength, grid, plan.knobs.reconstruction);
    bar.message("RGB and Ams_n");
    let orders: Vec<usize> = (1..=plan.scene.n_max).collect();
    let depths = plan.scene.poisson_depths();
    let channels: Vec<ChannelResult> = (0..3)
        .into_par_iter()
        .map(|c| {
            let r = channel_tables(
                &weights.weights[c],
                per_wavelength,
                &series,
                &orders,
                &depths,
            );
            bar.advance();
            r
        })
        .collect::<Result<_, _>>()
        .map_err(|source| BakeError::Mixture {
            field: field.name.clone(),
            source,
        })?;
    let mut summary = sampling_summary(field, &phases, weights, *grid);
    let tables = ChannelArrays::gather(
        channels,
        &mut summary,
        orders.len(),
        depths.len(),
        grid.len(),
    );
    bar.finish();
    summary.seconds = start.elapsed().as_secs_f64();
    let theta_step_deg = plan.scene.theta_step_deg;
    Ok(BakedField {
        single: single_scatter(field, theta_step_deg, lambdas, per_wavelength, grid.len()),
        poisson: PoissonTable {
            field: field.name.clone(),
            theta_step_deg,
            depths,
            rows: tables.poisson_rows,
        },
        image: FieldImage {
            field: field.name.clone(),
            theta_step_deg,
            ams: tables.ams,
            forward_fraction: tables.forward_fraction,
            extra_layers: Vec::new(),
        },
        summary,
    })
}

/// The Legendre series of every wavelength's phase function, one pass over the degrees per
/// thread, its wavelengths sharing the bin integrals.
fn legendre_series(
    per_wavelength: &[PhaseFunction],
    grid: &ThetaGrid,
    reconstruction: tables::ams::Reconstruction,
) -> Vec<AmsSeries> {
    let per_thread = per_wavelength
        .len()
        .div_ceil(rayon::current_num_threads())
        .max(1);
    per_wavelength
        .par_chunks(per_thread)
        .map(|chunk| {
            let bins: Vec<&[f64]> = chunk.iter().map(|p| &p.bins[..]).collect();
            AmsSeries::many(grid, &bins, reconstruction)
        })
        .collect::<Vec<_>>()
        .concat()
}

/// A field's summary before its channels are filled in: how far its sampling went (the
/// crystals' rays and noise, the drops' sizes and size noise).
fn sampling_summary(
    field: &Field,
    phases: &Phases,
    weights: &ChannelWeights,
    grid: ThetaGrid,
) -> FieldSummary {
    let per_wavelength = &phases.phases;
    FieldSummary {
        forward_peak_fraction: Default::default(),
        g: [0.0; 3],
        sigma_ext_m2: [0.0; 3],
        albedo: [0.0; 3],
        n_isotropic: [[None; 3]; 3],
        l_max: 0,
        seconds: 0.0,
        crystal_sampling: field.crystal.map(|crystal| CrystalSampling {
            rays: per_wavelength
                .iter()
                .filter_map(|p| p.crystal().map(|o| o.trace.rays))
                .sum(),
            noise: channel_noises(
                per_wavelength,
                weights,
                grid,
                mie::crystal::noise_skips_pole(crystal.roughness),
            ),
        }),
        sizes: phases.sizes,
        size_noise: field.distribution.map(|_| {
            let errors: Vec<&[f64]> = phases.size_errors.iter().map(|e| &e[..]).collect();
            mixed_noises(per_wavelength, &errors, weights, grid, false)
        }),
    }
}

/// The three channels' tables side by side, as the field's EXRs hold them.
struct ChannelArrays {
    /// Ams_n, (channel, row, angle).
    ams: Array3<f64>,
    /// The Poisson mixtures, (channel, depth, angle).
    poisson_rows: Array3<f64>,
    /// F_n, (channel, row).
    forward_fraction: Array2<f64>,
}

impl ChannelArrays {
    /// Stacks the `channels` (n rows, `depth_count` Poisson depths and `angle_count` angles
    /// each), and puts their numbers into `summary`.
    fn gather(
        channels: Vec<ChannelResult>,
        summary: &mut FieldSummary,
        n: usize,
        depth_count: usize,
        angle_count: usize,
    ) -> Self {
        let k = angle_count;
        let mut ams = Array3::zeros((3, n, k));
        let mut poisson_rows = Array3::zeros((3, depth_count, k));
        let mut forward_fraction = Array2::zeros((3, n));
        for (c, ch) in channels.into_iter().enumerate() {
            ams.slice_mut(s![c, .., ..]).assign(&ch.rows);
            poisson_rows.slice_mut(s![c, .., ..]).assign(&ch.poisson);
            for (r, f) in ch.forward_fraction.iter().enumerate() {
                forward_fraction[[c, r]] = *f;
            }
            summary.forward_peak_fraction[c] = ch.forward_peak_fraction;
            summary.g[c] = ch.g;
            summary.sigma_ext_m2[c] = ch.sigma_ext_m2;
            summary.albedo[c] = ch.albedo;
            for e in 0..N_ISO_EPSILONS.len() {
                summary.n_isotropic[e][c] = ch.n_isotropic[e];
            }
            summary.l_max = ch.l_max;
        }
        Self {
            ams,
            poisson_rows,
            forward_fraction,
        }
    }
}

/// The single-scattering optics per wavelength, as written to `<name>.single.exr`.
fn single_scatter(
    field: &Field,
    theta_step_deg: f64,
    lambdas: &[f64],
    per_wavelength: &[PhaseFunction],
    angle_count: usize,
) -> SingleScatter {
    SingleScatter {
        field: field.name.clone(),
        theta_step_deg,
        wavelengths_nm: lambdas.to_vec(),
        bins: Array2::from_shape_fn((per_wavelength.len(), angle_count), |(j, k)| {
            per_wavelength[j].bins[k]
        }),
        forward_delta_fraction: per_wavelength
            .iter()
            .map(|p| p.forward_delta_fraction)
            .collect(),
        sigma_ext_m2: per_wavelength.iter().map(|p| p.sigma_ext_m2).collect(),
        albedo: per_wavelength.iter().map(|p| p.albedo).collect(),
    }
}

/// Gauss nodes per bin. A distribution averages the ripple of each size (period ≈ π/x in θ)
/// away, so the preset's node count serves; a single size keeps its ripple, and a bin of
/// Δθ holds x·Δθ/π ripples, which 3 nodes per ripple resolve (a 1000 µm drop at 450 nm: 14
/// ripples per 0.18° bin; bin averages then agree with miepython's to 1e-7, mie/tests/mieplot.rs).
fn nodes_per_bin(d: &mie::SizeDistribution, lambda_nm: f64, knobs: Knobs, step_deg: f64) -> usize {
    match *d {
        mie::SizeDistribution::Monodisperse { radius_um } => {
            let x = mie::size_parameter(radius_um, lambda_nm);
            let ripples = x * step_deg.to_radians() / std::f64::consts::PI;
            knobs
                .nodes_per_panel
                .max((3.0 * ripples).ceil() as usize + 2)
        }
        _ => knobs.nodes_per_panel,
    }
}

/// Rays per wavelength for crystals: `per_wavelength` × J in all, shared by [`sample_shares`]
/// (at least a tenth of the mean each).
pub fn ray_allocation(weights: &ChannelWeights, per_wavelength: u64) -> Vec<u64> {
    let j_len = weights.wavelengths_nm.len();
    let floor = per_wavelength / 10;
    let total = per_wavelength * j_len as u64;
    let spare = total.saturating_sub(floor * j_len as u64) as f64;
    sample_shares(weights, &vec![1.0; j_len])
        .iter()
        .map(|share| floor + (spare * share).round() as u64)
        .collect()
}

/// Each wavelength's share n_j (Σ_j n_j = 1) of a field's independent samples (rays, sizes)
/// that makes the worst channel's noise smallest for the cost: channel c's variance is
/// ∝ Σ_j a_cj²/n_j (a_cj its weights, each wavelength an independent estimate whose variance
/// falls as 1/n_j), a sample at wavelength j costs `cost[j]`, and the shares minimize
/// max_c Σ_j a_cj²/n_j · Σ_j cost_j n_j. For given channel multipliers μ_c (on the simplex) the
/// minimizer is n_j ∝ √(Σ_c μ_c a_cj² / cost_j) (Lagrange); the μ are searched on a grid of
/// step 1/60. For the default scene's 31 wavelengths the worst channel's variance at equal
/// cost is 0.63 of equal shares' (the earlier rays ∝ the largest weight: 0.67).
pub fn sample_shares(weights: &ChannelWeights, cost: &[f64]) -> Vec<f64> {
    const STEPS: usize = 60;
    let j_len = weights.wavelengths_nm.len();
    let a = &weights.weights;
    let shares_for = |mu: [f64; 3]| -> Vec<f64> {
        let n: Vec<f64> = (0..j_len)
            .map(|j| ((0..3).map(|c| mu[c] * a[c][j] * a[c][j]).sum::<f64>() / cost[j]).sqrt())
            .collect();
        let total: f64 = n.iter().sum();
        n.iter().map(|x| x / total).collect()
    };
    let objective = |n: &[f64]| -> f64 {
        let variance = crate::plan::channel_noise(weights, |_, j| n[j]);
        variance * n.iter().zip(cost).map(|(n, c)| n * c).sum::<f64>()
    };
    let mut best = (f64::INFINITY, vec![1.0 / j_len as f64; j_len]);
    for i in 0..=STEPS {
        for k in 0..=STEPS - i {
            let mu = [
                i as f64 / STEPS as f64,
                k as f64 / STEPS as f64,
                (STEPS - i - k) as f64 / STEPS as f64,
            ];
            let n = shares_for(mu);
            if n.iter().any(|x| !x.is_finite()) {
                continue;
            }
            let v = objective(&n);
            if v < best.0 {
                best = (v, n);
            }
        }
    }
    best.1
}

/// A noise target's trace stops at this many times its first round's rays (or the preset's
/// rays per wavelength) whatever its noise: a bound on the time of a field whose noise the
/// estimate cannot bring down. (At 64 the default scene's rgb3 ice and snow stopped at the
/// bound, 1.4 % and 1.5 % from the reference at standard instead of 0.9 %.)
const MAX_RAY_ROUNDS: u64 = 1024;

/// The worst channel's sampling noise of crystal phase functions per wavelength: per channel c
/// the rms over the bins θ ≥ 1° of √(Σ_j a_cj² SE_jk²) / Σ_j a_cj P_jk, with the bake's mixing
/// weights a_cj ∝ w_cj σ_sca,j and SE_jk each bin's standard error (a bin nothing reached
/// counts as 100 %).
fn channel_noise(
    phases: &[PhaseFunction],
    weights: &ChannelWeights,
    grid: ThetaGrid,
    skip_pole: bool,
) -> f64 {
    channel_noises(phases, weights, grid, skip_pole)
        .into_iter()
        .fold(0.0, f64::max)
}

/// [`channel_noise`] of each channel, crystal phase functions' own standard errors.
fn channel_noises(
    phases: &[PhaseFunction],
    weights: &ChannelWeights,
    grid: ThetaGrid,
    skip_pole: bool,
) -> [f64; 3] {
    let errors: Vec<&[f64]> = phases
        .iter()
        .map(|p| p.crystal().map_or(&[][..], |o| &o.bins_std_error[..]))
        .collect();
    mixed_noises(phases, &errors, weights, grid, skip_pole)
}

/// Per channel, the rms over θ ≥ 1° (and ≤ 179° if `skip_pole`:
/// `mie::crystal::noise_skips_pole`) of the mixed bins' relative standard error, from each
/// wavelength's bins' standard errors `errors` (NaN or missing: 100 %).
fn mixed_noises(
    phases: &[PhaseFunction],
    errors: &[&[f64]],
    weights: &ChannelWeights,
    grid: ThetaGrid,
    skip_pole: bool,
) -> [f64; 3] {
    std::array::from_fn(|c| {
        let raw: Vec<f64> = phases
            .iter()
            .zip(&weights.weights[c])
            .map(|(p, w)| w * p.sigma_sca_m2)
            .collect();
        let total: f64 = raw.iter().sum();
        let a: Vec<f64> = raw.iter().map(|x| x / total).collect();
        let mut bins = vec![0.0; grid.len()];
        let mut variance = vec![0.0; grid.len()];
        for ((p, se), &a) in phases.iter().zip(errors).zip(&a) {
            for k in 0..grid.len() {
                bins[k] += a * p.bins[k];
                // A trace of one chunk has no spread (NaN): its bins count as 100 %.
                let e = se.get(k).copied().unwrap_or(f64::NAN);
                variance[k] += a
                    * a
                    * if e.is_finite() {
                        e * e
                    } else {
                        p.bins[k].powi(2)
                    };
            }
        }
        let std_error: Vec<f64> = variance.iter().map(|v| v.sqrt()).collect();
        mie::crystal::relative_noise(grid, &bins, &std_error, skip_pole)
    })
}

/// Seed of the crystal traces (wavelength j uses CRYSTAL_SEED ^ j with the knobs' seed 0).
const CRYSTAL_SEED: u64 = 0x7068_6f74_6f6d_6574;

/// The random stream wavelength j of a crystal field traces with the knobs' `seed`:
/// CRYSTAL_SEED ^ seed·φ ^ j (φ = 0x9E37_79B9_7F4A_7C15). The product spreads the seeds over
/// all 64 bits, so no two (seed, wavelength) pairs share a stream and two seeds' difference
/// measures the noise (with seed ^ j, seed 1's first wavelength would be seed 2's fourth).
pub fn crystal_stream(seed: u64, j: usize) -> u64 {
    CRYSTAL_SEED ^ seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ j as u64
}

/// One channel's tables.
struct ChannelResult {
    rows: Array2<f64>,
    poisson: Array2<f64>,
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
    per_wavelength: &[PhaseFunction],
    series: &[AmsSeries],
    orders: &[usize],
    depths: &[f64],
) -> Result<ChannelResult, tables::TablesError> {
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
    let mixture = AmsMixture::new(parts)?;
    let (rows, poisson) = mixture.rows_and_poisson(orders, depths);
    let mut n_isotropic = [None; 3];
    for (slot, n) in n_isotropic.iter_mut().zip(mixture.isotropic_orders(
        &N_ISO_EPSILONS,
        N_ISO_CAP,
        orders,
        &rows,
    )) {
        *slot = n.map(|n| n as u32);
    }
    Ok(ChannelResult {
        rows,
        poisson,
        forward_fraction: mixture.forward_fractions(orders),
        forward_peak_fraction: orders
            .iter()
            .map(|&n| mixture.forward_peak_fraction(n))
            .collect(),
        g,
        sigma_ext_m2: ext,
        albedo: sca / ext,
        n_isotropic,
        l_max: mixture.l_max(),
    })
}
