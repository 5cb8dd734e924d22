//! `photometeor bake`: a scene's multiple-scattering tables into a bake directory.

use anyhow::{Context, Result, bail};
use bake::{BakePlan, Quality, Scene};
use clap::Args as ClapArgs;

use crate::progress::Bars;

#[derive(Debug, ClapArgs)]
pub struct BakeArgs {
    /// Scene file (TOML); default: the embedded default scene (cloud, rain, ice, snow).
    scene: Option<std::path::PathBuf>,
    /// Output directory (created if missing).
    #[arg(long, default_value = "photometeor-tables")]
    out: std::path::PathBuf,
    /// Accuracy preset, overriding the scene's: the rms error of Ams_1 (θ ≥ 1°, worst channel)
    /// is ≤ 5 % at draft and ≤ 1 % at standard for every kind and spectral mode (drops sized
    /// until their estimated noise is 3.5 % or 0.8 %, ice and snow traced until theirs is 4 % or
    /// 0.9 %); rough crystals (snow) over 1°–179°, their backscatter spike within 1° of 180°
    /// being carried by few rays; docs/scenes.md, "Presets, measured", has the table, that
    /// spike's error and the times.
    #[arg(long, value_parser = ["draft", "standard", "reference"])]
    quality: Option<String>,
    /// Worker threads, [1, 256] (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// No progress bars or summary.
    #[arg(long)]
    quiet: bool,
    /// Print the summary as JSON (fields computed and cached, seconds, peak memory).
    #[arg(long)]
    json: bool,
    /// Seed of the crystal tracer's random streams and of the drops' size nodes, an integer ≥ 0
    /// (default 0, the presets'). Two bakes with different seeds are independent estimates:
    /// their difference measures the sampling noise (the Monte Carlo noise of ice and snow, the
    /// Mie ripple's of drops).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Compute shard K of N (1 ≤ K ≤ N ≤ 4096) into --out: a deterministic share of the
    /// scene's fields, dealt by estimated cost, as records and `shard.json`; `photometeor merge`
    /// of the N shard directories writes the bake, byte-identical to one without shards. For a
    /// Slurm array: --shard $((SLURM_ARRAY_TASK_ID + 1))/$SLURM_ARRAY_TASK_COUNT.
    #[arg(long, value_name = "K/N", value_parser = bake::shard::Shard::parse)]
    shard: Option<bake::shard::Shard>,
}

/// Most worker threads a bake starts.
const MAX_JOBS: usize = 256;

/// Runs `photometeor bake`.
pub fn run(a: BakeArgs) -> Result<()> {
    // The text is kept: a shard records the scene it baked.
    let (text, origin) = match &a.scene {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| format!("reading scene {}", p.display()))?,
            p.display().to_string(),
        ),
        None => (
            bake::scene::DEFAULT_SCENE.to_string(),
            "default scene".into(),
        ),
    };
    // A field's `file` is relative to the scene's folder, which a shard records (absolute)
    // for the merge.
    let scene_dir = a.scene.as_deref().map(scene_folder).transpose()?;
    let scene = Scene::parse_in(&text, &origin, scene_dir.as_deref())?;
    let quality = match a.quality.as_deref() {
        Some(q) => Quality::parse(q).context("quality preset")?,
        None => scene.quality,
    };
    if let Some(jobs) = a.jobs
        && !(1..=MAX_JOBS).contains(&jobs)
    {
        bail!("--jobs {jobs} is outside the allowed range [1, {MAX_JOBS}]");
    }
    let mut plan = BakePlan::for_preset(scene, a.out.clone(), quality);
    plan.knobs.seed = a.seed;
    let progress = Bars::new(a.quiet);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.jobs.unwrap_or(0))
        .build()
        .context("building the thread pool")?;
    if let Some(shard) = a.shard {
        let record = pool.install(|| {
            bake::shard::run_shard(&plan, &text, scene_dir.as_deref(), shard, &progress)
        })?;
        if a.json {
            // The record (shard.json's content) and the process's peak memory.
            let mut json = serde_json::to_value(&record)?;
            json["peak_rss_mib"] = serde_json::json!(bake::bake::peak_rss_mib());
            println!("{json}");
        } else if !a.quiet {
            let names: Vec<&str> = record.fields.iter().map(|f| f.name.as_str()).collect();
            println!(
                "shard {}/{} of {} into {} in {:.1} s: {}",
                shard.index,
                shard.count,
                plan.scene.name,
                plan.out_dir.display(),
                record.seconds,
                fields_in_words(&names)
            );
        }
        return Ok(());
    }
    // Another bake publishing into the same directory: wait for it, saying so (its tables are
    // then replaced by this scene's, which is said too).
    let report = loop {
        format::BakeLock::wait_until_free(&plan.out_dir, |holder| {
            eprintln!(
                "waiting for process {holder}, which is baking into {}",
                plan.out_dir.display()
            );
        })?;
        match pool.install(|| bake::run(&plan, &progress)) {
            Err(bake::BakeError::Commit(format::CommitError::Locked { holder, .. })) => {
                eprintln!(
                    "{} was locked by process {holder} as this bake finished; waiting to \
                     publish",
                    plan.out_dir.display()
                );
            }
            r => break r?,
        }
    };
    if !report.replaced.is_empty() {
        eprintln!(
            "{}: this bake of {} replaced the tables it held of fields {:?} (another scene's, \
             or fields this scene no longer has); they are removed",
            plan.out_dir.display(),
            plan.scene.name,
            report.replaced
        );
    }
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else if !a.quiet {
        let computed: Vec<&str> = report.computed.iter().map(String::as_str).collect();
        let cached: Vec<&str> = report.cached.iter().map(String::as_str).collect();
        let fields = match (computed.is_empty(), cached.is_empty()) {
            (true, true) => "no field".to_string(),
            (false, true) => format!("computed {}", list_in_words(&computed)),
            (true, false) => format!("{} from the cache", list_in_words(&cached)),
            (false, false) => format!(
                "computed {}; {} from the cache",
                list_in_words(&computed),
                list_in_words(&cached)
            ),
        };
        let out = plan.out_dir.display();
        println!(
            "baked {} into {out} in {:.1} s: {fields}; peak memory {}",
            plan.scene.name,
            report.seconds,
            report
                .peak_rss_mib
                .map_or("not known".to_string(), |m| format!("{m:.0} MiB"))
        );
        println!(
            "The tables are in {out}: manifest.json and one <field>.exr per field (beside each, \
             the .single, .poisson and .biri side tables the render models read)."
        );
        say_normalizations(&plan.scene);
        println!("Next: photometeor validate {out}   (checks each field against theory)");
        println!(
            "  or: photometeor render --out rainbow.exr --png rainbow.png   (the rainbow scene)"
        );
    }
    Ok(())
}

/// One line per `tabulated` field: its table's integral over the sphere as read (per column),
/// the normalization the bake divided out.
fn say_normalizations(scene: &Scene) {
    for f in &scene.fields {
        let Some(t) = &f.tabulated else { continue };
        let found: Vec<String> = (0..t.columns.len())
            .map(|c| format!("{:.6}", t.sphere_integral(c)))
            .collect();
        println!(
            "Field {}: the table {} integrates to {} over the sphere ({} column(s) as read); \
             divided by that, it is normalized to 1.",
            f.name,
            t.file,
            found.join(", "),
            t.columns.len()
        );
    }
}

/// The folder (absolute) of the scene file at `path`; a bare file name's is the working one.
fn scene_folder(path: &std::path::Path) -> Result<std::path::PathBuf> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    std::path::absolute(dir).with_context(|| format!("the folder of scene {}", path.display()))
}

/// Names as words: `a`, `a and b`, `a, b and c`; `no field` for none.
pub(crate) fn list_in_words(names: &[&str]) -> String {
    match names {
        [] => "no field".to_string(),
        [one] => (*one).to_string(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    }
}

/// `field cloud`, `fields cloud and rain`, `no field`.
pub(crate) fn fields_in_words(names: &[&str]) -> String {
    match names.len() {
        0 => "no field".to_string(),
        1 => format!("field {}", names[0]),
        _ => format!("fields {}", list_in_words(names)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_read_as_words() {
        assert_eq!(list_in_words(&[]), "no field");
        assert_eq!(list_in_words(&["cloud"]), "cloud");
        assert_eq!(list_in_words(&["cloud", "rain"]), "cloud and rain");
        assert_eq!(
            list_in_words(&["cloud", "rain", "ice", "snow"]),
            "cloud, rain, ice and snow"
        );
        assert_eq!(fields_in_words(&["ice"]), "field ice");
        assert_eq!(fields_in_words(&["ice", "snow"]), "fields ice and snow");
    }
}
