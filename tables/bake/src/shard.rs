//! Sharded bakes for a cluster's batch scheduler (Slurm job arrays, Kubernetes Indexed Jobs,
//! HTCondor, GNU parallel): shard K of N computes a deterministic share of the scene's work
//! units into its own directory, and [`check_shards`] gathers N such directories for a merge
//! that bakes from their records, byte-identical to the bake without shards.
//!
//! A work unit is one field (its wavelengths are computed together: the drops' sizes per
//! wavelength come from one pilot, the crystals are traced in rounds until their worst channel's
//! noise is at the target, both decided across the wavelengths). The units are dealt to the
//! shards largest first, each to the shard with the least estimated work so far
//! ([`estimated_seconds`]; ties to the lower index), which every shard computes alike from the
//! scene, so no shard needs to hear from another.
//!
//! A shard directory holds its fields' cache records (`.cache/<hash>.bin`, as any bake's) and
//! [`SHARD_FILE`], which names the scene (its text and the SHA-256 of it), the preset, the seed,
//! the program and its compute version, the shard, and each of its fields with its content
//! hash.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::cache::COMPUTE_VERSION;
use crate::error::BakeError;
use crate::plan::BakePlan;
use crate::progress::Progress;
use crate::scene::{Field, Quality};

/// The file a shard directory describes itself in.
pub const SHARD_FILE: &str = "shard.json";

/// Most shards a bake is split into.
pub const MAX_SHARDS: usize = 4096;

/// Layout of [`SHARD_FILE`].
const SHARD_FORMAT: u32 = 1;

/// Shard `index` of `count`, 1-based as schedulers' array indices are written on a command
/// line (`--shard 3/8`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// K, in 1..=N.
    pub index: usize,
    /// N, in 1..=[`MAX_SHARDS`].
    pub count: usize,
}

impl Shard {
    /// Parses `K/N`, naming the value and the allowed range when it is not one.
    pub fn parse(text: &str) -> Result<Self, String> {
        let bad = || {
            format!(
                "--shard {text:?}: expected K/N with 1 ≤ K ≤ N ≤ {MAX_SHARDS}, e.g. 3/8 (a \
                 scheduler's 0-based index is K − 1: --shard $((SLURM_ARRAY_TASK_ID + 1))/N)"
            )
        };
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let k: usize = k.trim().parse().map_err(|_| bad())?;
        let n: usize = n.trim().parse().map_err(|_| bad())?;
        if !(1..=MAX_SHARDS).contains(&n) || !(1..=n).contains(&k) {
            return Err(bad());
        }
        Ok(Self { index: k, count: n })
    }
}

/// One field of a shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardField {
    /// The field's name.
    pub name: String,
    /// Its content hash: the cache key of its record.
    pub content_hash: String,
    /// The estimate it was dealt by (s).
    pub estimated_seconds: f64,
    /// Wall time it took here (s; 0 when this directory's cache already held it).
    pub seconds: f64,
}

/// [`SHARD_FILE`]'s contents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// Layout version.
    pub format: u32,
    /// The program and its compute version ([`program`]).
    pub program: String,
    /// The scene's name.
    pub scene_name: String,
    /// The scene file's text, as the shard read it.
    pub scene_text: String,
    /// SHA-256 of `scene_text`, hex.
    pub scene_sha256: String,
    /// The folder (absolute) a field's `file` is relative to: the scene file's; none for the
    /// embedded scene.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_dir: Option<PathBuf>,
    /// The preset.
    pub quality: Quality,
    /// The seed of the size nodes and the crystal streams.
    pub seed: u64,
    /// Which shard this is.
    pub shard: Shard,
    /// Every field of the scene, in order: what the shards together must hold.
    pub scene_fields: Vec<String>,
    /// This shard's fields.
    pub fields: Vec<ShardField>,
    /// Wall time of the shard (s).
    pub seconds: f64,
}

/// The program and the version of everything that changes a baked number.
pub fn program() -> String {
    format!(
        "photometeor-bake {} (compute version {COMPUTE_VERSION})",
        env!("CARGO_PKG_VERSION")
    )
}

/// SHA-256 of `text`, hex.
pub fn sha256_hex(text: &str) -> String {
    Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The estimated wall time of `field` on 2 cores (s): what the shards are balanced by. Drops
/// cost ∝ wavelengths × sizes × the size parameter x = 2πr/λ at 550 nm (a Mie series has ~x
/// terms), crystals ∝ wavelengths × rays, both scaled by the preset's node counts and set
/// from one standard bake of the default scene's fields, each alone, here (2026-12-04: cloud
/// 0.59 s, rain 6.2 s, ice 7.7 s, snow 7.5 s). Only the balance depends on it, never a number
/// of the bake.
pub fn estimated_seconds(plan: &BakePlan, field: &Field) -> f64 {
    let wavelengths = match plan.scene.spectral {
        tables::spectral::SpectralMode::Rgb3 => 3.0,
        tables::spectral::SpectralMode::Spectral { count, .. } => count as f64,
    };
    let standard = Quality::Standard.knobs();
    match (&field.distribution, &field.crystal) {
        (Some(d), _) => {
            let r_eff = d.quadrature(64, 1e-6).effective_radius_um();
            let x = 2.0 * std::f64::consts::PI * r_eff / 0.55;
            let sizes = plan.knobs.sizes as f64 / standard.sizes as f64;
            // Rain (x ≈ 5700, 31 λ) 6.2 s at standard; the cloud (x ≈ 114) 0.59 s.
            wavelengths * sizes * (0.0035 + 3.3e-5 * x)
        }
        (None, Some(_)) => {
            let rays = plan.knobs.rays as f64 / standard.rays as f64;
            wavelengths * rays * 0.25
        }
        (None, None) => 0.0,
    }
}

/// The shard (0-based) of each field of `plan`, in scene order (module docs).
pub fn assign(plan: &BakePlan, shards: usize) -> Vec<usize> {
    let cost: Vec<f64> = plan
        .scene
        .fields
        .iter()
        .map(|f| estimated_seconds(plan, f))
        .collect();
    let mut order: Vec<usize> = (0..cost.len()).collect();
    // Largest first; equal estimates in scene order.
    order.sort_by(|&a, &b| cost[b].total_cmp(&cost[a]).then(a.cmp(&b)));
    let mut load = vec![0.0f64; shards.max(1)];
    let mut shard_of = vec![0; cost.len()];
    for i in order {
        let least = (0..load.len())
            .min_by(|&a, &b| load[a].total_cmp(&load[b]).then(a.cmp(&b)))
            .expect("at least one shard");
        load[least] += cost[i];
        shard_of[i] = least;
    }
    shard_of
}

/// Computes shard `shard` of `plan` into `plan.out_dir` (its fields' cache records, then
/// [`SHARD_FILE`]); `scene_text` is the scene as read, `scene_dir` the folder its files are
/// relative to. A shard with no field (more shards than fields) writes only its [`SHARD_FILE`].
pub fn run_shard(
    plan: &BakePlan,
    scene_text: &str,
    scene_dir: Option<&Path>,
    shard: Shard,
    progress: &dyn Progress,
) -> Result<ShardRecord, BakeError> {
    let start = Instant::now();
    crate::bake::preflight(
        plan,
        &tables::spectral::ChannelWeights::new(&plan.scene.spectral)?,
    )?;
    let shard_of = assign(plan, shard.count);
    let mut fields = Vec::new();
    for (field, &s) in plan.scene.fields.iter().zip(&shard_of) {
        if s + 1 != shard.index {
            continue;
        }
        let started = Instant::now();
        let (hash, computed) = crate::bake::compute_record(plan, field, progress)?;
        fields.push(ShardField {
            name: field.name.clone(),
            content_hash: hash,
            estimated_seconds: estimated_seconds(plan, field),
            seconds: if computed {
                started.elapsed().as_secs_f64()
            } else {
                0.0
            },
        });
    }
    let record = ShardRecord {
        format: SHARD_FORMAT,
        program: program(),
        scene_name: plan.scene.name.clone(),
        scene_text: scene_text.to_string(),
        scene_sha256: sha256_hex(scene_text),
        scene_dir: scene_dir.map(Path::to_path_buf),
        quality: plan.quality,
        seed: plan.knobs.seed,
        shard,
        scene_fields: plan.scene.fields.iter().map(|f| f.name.clone()).collect(),
        fields,
        seconds: start.elapsed().as_secs_f64(),
    };
    // A shard that was dealt no field has made no directory yet (its fields' records would
    // have): a scheduler's array with more tasks than fields gives it a fresh --out.
    std::fs::create_dir_all(&plan.out_dir).map_err(|source| BakeError::Io {
        path: plan.out_dir.clone(),
        op: "creating the shard directory",
        source,
    })?;
    let path = plan.out_dir.join(SHARD_FILE);
    let json = serde_json::to_vec_pretty(&record).expect("a shard record serializes");
    format::write_file_atomically(&path, &json).map_err(|(op, source)| BakeError::Io {
        path,
        op,
        source,
    })?;
    Ok(record)
}

/// What a merge bakes from: the scene and how it was baked, and each field's record (the shard
/// directory holding it and its content hash).
#[derive(Debug, Clone)]
pub struct Merge {
    /// The scene's text.
    pub scene_text: String,
    /// The folder its fields' files are relative to.
    pub scene_dir: Option<PathBuf>,
    /// The preset.
    pub quality: Quality,
    /// The seed.
    pub seed: u64,
    /// Per field of the scene, in order: (its shard directory, its content hash).
    pub records: Vec<(PathBuf, String)>,
}

/// Reads the shard directories `dirs` and checks that they are the N shards of one scene
/// baked by this program (same scene text, preset, seed and compute version), each shard once,
/// and that together they hold every field exactly once with a usable record; the refusal
/// names the missing, repeated or foreign shard, or the field.
pub fn check_shards(dirs: &[PathBuf]) -> Result<Merge, BakeError> {
    let refuse = |m: String| Err(BakeError::Shards(m));
    if dirs.is_empty() {
        return refuse("no shard directory given".into());
    }
    let mut shards: Vec<(PathBuf, ShardRecord)> = Vec::new();
    for dir in dirs {
        shards.push((dir.clone(), read_shard(dir)?));
    }
    let (first_dir, first) = &shards[0];
    for (dir, s) in &shards {
        let differs = |what: &str| {
            BakeError::Shards(format!(
                "{} is not a shard of the same bake as {}: its {what} differs",
                dir.display(),
                first_dir.display()
            ))
        };
        if !(1..=MAX_SHARDS).contains(&s.shard.count)
            || !(1..=s.shard.count).contains(&s.shard.index)
        {
            return Err(BakeError::Shards(format!(
                "{} claims shard {}/{}: a shard is K/N with 1 ≤ K ≤ N ≤ {MAX_SHARDS}",
                dir.display(),
                s.shard.index,
                s.shard.count
            )));
        }
        if s.program != program() {
            return Err(BakeError::Shards(format!(
                "{} was made by {}, not by this {}: bake every shard with one version",
                dir.display(),
                s.program,
                program()
            )));
        }
        if s.scene_sha256 != first.scene_sha256 || s.scene_sha256 != sha256_hex(&s.scene_text) {
            return Err(differs("scene"));
        }
        if (s.quality, s.seed) != (first.quality, first.seed) {
            return Err(differs("preset or seed"));
        }
        if s.shard.count != first.shard.count {
            return Err(differs("shard count"));
        }
    }
    let n = first.shard.count;
    for k in 1..=n {
        let holders: Vec<&PathBuf> = shards
            .iter()
            .filter(|(_, s)| s.shard.index == k)
            .map(|(d, _)| d)
            .collect();
        match holders.as_slice() {
            [] => {
                return refuse(format!(
                    "shard {k}/{n} is missing: give all {n} shard directories"
                ));
            }
            [_] => {}
            [a, b, ..] => {
                return refuse(format!(
                    "shard {k}/{n} is given twice: {} and {}",
                    a.display(),
                    b.display()
                ));
            }
        }
    }
    let mut records = Vec::new();
    for name in &first.scene_fields {
        let holders: Vec<(&PathBuf, &ShardField)> = shards
            .iter()
            .flat_map(|(d, s)| {
                s.fields
                    .iter()
                    .filter(|f| &f.name == name)
                    .map(move |f| (d, f))
            })
            .collect();
        let [(dir, field)] = holders.as_slice() else {
            return refuse(format!(
                "field {name:?} is in {} shards, not exactly one",
                holders.len()
            ));
        };
        if !crate::bake::has_record(dir, &field.content_hash) {
            return refuse(format!(
                "{}: the record of field {name:?} ({}) is missing or damaged",
                dir.display(),
                field.content_hash
            ));
        }
        records.push(((*dir).clone(), field.content_hash.clone()));
    }
    Ok(Merge {
        scene_text: first.scene_text.clone(),
        scene_dir: first.scene_dir.clone(),
        quality: first.quality,
        seed: first.seed,
        records,
    })
}

/// Reads `dir`'s [`SHARD_FILE`].
fn read_shard(dir: &Path) -> Result<ShardRecord, BakeError> {
    let path = dir.join(SHARD_FILE);
    let bytes = format::read_regular_file(&path, 1 << 26).map_err(|(op, source)| {
        BakeError::Shards(format!(
            "{} is not a shard directory ({op} {SHARD_FILE}: {source}); make one with \
             `photometeor bake SCENE --shard K/N --out DIR`",
            dir.display()
        ))
    })?;
    let record: ShardRecord = serde_json::from_slice(&bytes).map_err(|e| {
        BakeError::Shards(format!(
            "{}: not a shard record of this version: {e}",
            path.display()
        ))
    })?;
    if record.format != SHARD_FORMAT {
        return Err(BakeError::Shards(format!(
            "{}: shard layout {}, this program reads {SHARD_FORMAT}",
            path.display(),
            record.format
        )));
    }
    Ok(record)
}
