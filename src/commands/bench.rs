//! `photometeor bench`: the Mie workloads timed here and (optionally) in miepython in the same
//! run, so the speed ratio comes from one machine at one moment; crystal rays per second; bake
//! time and re-bake speed-up; render frame times.
//!
//! Mie workloads (docs/physics.md §2 "speed anchors"):
//! - single sphere m = 1.333 + 1e-8i, x = 1e5, S1 and S2 at θ = 0, 0.18°, …, 180° (1001 angles);
//! - rain: lognormal r_g = 500 µm, σ_g = 1.4, 100 radii log-spaced over r_g e^{±3 ln σ_g}
//!   (end points included), λ = 650, 550, 450 nm with the water indices below, the
//!   lognormal-weighted mean of |S1|² + |S2|² at the same 1001 angles, normalized per λ.

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use mie::ensemble::mean_phase_at;
use mie::{FoldedAngles, SizeQuadrature, Sphere, ThetaGrid, amplitudes};
use num_complex::Complex64;
use serde_json::json;

#[derive(Debug, Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchWhat,
}

#[derive(Debug, Subcommand)]
enum BenchWhat {
    /// Single sphere at x = 1e5 and the 3-wavelength rain lognormal, 1001 angles each.
    Mie(MieBench),
    /// Geometric-optics ray tracing of ice prisms: rays per second on 1 thread and on all.
    Crystal(CrystalBench),
    /// Bake a scene (default: the embedded one) at each preset into a fresh directory, then
    /// again unchanged: wall time, re-bake speed-up and peak memory, each bake its own process.
    Bake(BakeBench),
    /// Frame time of `photometeor render` on the GPU adapter (and of the CPU reference), at
    /// one base setting and varying slices and resolution one at a time; table upload time.
    Render(super::bench_render::RenderBench),
    /// coupled's relight in steps after sun moves, cold and warm: each step's time and the
    /// error of its image against the converged one (and against given truths).
    Relight(super::bench_relight::RelightBench),
}

#[derive(Debug, Args)]
struct CrystalBench {
    /// Rays per run.
    #[arg(long, default_value_t = 2_000_000)]
    rays: u64,
    /// Macke distortion δ of the prism (0 = pristine).
    #[arg(long, default_value_t = 0.0)]
    roughness: f64,
    /// Aspect ratio L/(2a) of the prism.
    #[arg(long, default_value_t = 1.0)]
    aspect_ratio: f64,
    /// Tilts weighed per facet a path first meets (distorted prisms only; 4 as the bake's
    /// presets use, 1 = the plain path).
    #[arg(long, default_value_t = 4)]
    tilt_splits: u32,
}

#[derive(Debug, Args)]
struct BakeBench {
    /// Scene file (TOML); default: the embedded default scene.
    scene: Option<PathBuf>,
    /// Presets to time, comma-separated.
    #[arg(long, default_value = "draft,standard")]
    presets: String,
    /// Worker threads per bake (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Keep the bakes in this directory (one subdirectory per preset) instead of a temporary one.
    #[arg(long)]
    keep: Option<PathBuf>,
    /// Also bake the scene as N shards, one process after another (`bake --shard K/N`), and
    /// merge them: each shard's wall time, CPU seconds and peak memory against the bake
    /// without shards, and the merge's time; [2, 64].
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..=64))]
    shards: Option<u32>,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Args)]
struct MieBench {
    /// Repetitions per workload; the best time is reported.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Also run scripts/bench_miepython.py with this Python and print the speed ratios.
    #[arg(long)]
    compare_miepython: bool,
    /// Python interpreter for --compare-miepython.
    #[arg(long, default_value = "python3")]
    python: String,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// Water at 650, 550, 450 nm (IAPWS 20 °C real part, Segelstein κ; docs/physics.md §3).
const RAIN_CASES: [(f64, f64, f64); 3] = [
    (650.0, 1.3317, 1.67e-8),
    (550.0, 1.3347, 2.46e-9),
    (450.0, 1.3396, 8.07e-10),
];

pub fn run(args: BenchArgs) -> Result<()> {
    let b = match args.what {
        BenchWhat::Mie(b) => b,
        BenchWhat::Bake(b) => return bench_bake(b),
        BenchWhat::Crystal(c) => return bench_crystal(c),
        BenchWhat::Render(r) => return super::bench_render::run(r),
        BenchWhat::Relight(r) => return super::bench_relight::run(r),
    };
    let threads = b.threads.unwrap_or_else(rayon::current_num_threads);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("building the thread pool")?;
    let repeat = b.repeat.max(1);
    let (single, rain, rain_phase) = pool.install(|| -> Result<_> {
        let single = best_of(repeat, single_sphere)?;
        let mut phase = Vec::new();
        let rain = best_of(repeat, || {
            phase = rain_lognormal()?;
            Ok(())
        })?;
        Ok((single, rain, phase))
    })?;
    let mut report = json!({
        "tool": "photometeor", "version": env!("CARGO_PKG_VERSION"), "threads": threads,
        "single_x1e5_s": single, "rain_lognormal_s": rain,
    });
    if !b.json {
        println!("photometeor ({threads} threads, best of {repeat}):");
        println!("  single sphere x = 1e5, 1001 angles: {single:.4} s");
        println!("  rain lognormal, 3 λ × 100 sizes, 1001 angles: {rain:.4} s");
    }
    if b.compare_miepython {
        let py = run_miepython(&b.python, repeat)?;
        let py_single = py["single_x1e5_s"]
            .as_f64()
            .context("miepython single time")?;
        let py_rain = py["rain_lognormal_s"]
            .as_f64()
            .context("miepython rain time")?;
        let worst = compare_phase(&rain_phase, &py["rain_phase"])?;
        report["miepython"] = py.clone();
        report["speedup_single"] = json!(py_single / single);
        report["speedup_rain"] = json!(py_rain / rain);
        report["rain_phase_max_rel_diff"] = json!(worst);
        if !b.json {
            println!(
                "miepython {} (numba JIT, after warm-up, 1 thread):",
                py["version"]
            );
            println!(
                "  single sphere: {py_single:.4} s  → photometeor is {:.1}× faster",
                py_single / single
            );
            println!(
                "  rain lognormal: {py_rain:.4} s  → photometeor is {:.1}× faster",
                py_rain / rain
            );
            println!("  same work check: rain phase functions agree to {worst:.2e} (max relative)");
        }
    }
    if b.json {
        println!("{}", serde_json::to_string(&report)?);
    }
    Ok(())
}

fn best_of(repeat: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let start = Instant::now();
        f()?;
        best = best.min(start.elapsed().as_secs_f64());
    }
    Ok(best)
}

fn grid_cosines() -> Vec<f64> {
    ThetaGrid::new(0.18).expect("0.18° divides 180°").cosines()
}

fn single_sphere() -> Result<()> {
    let x = 1e5;
    let c = Sphere::new(Complex64::new(1.333, 1e-8), x)?.coefficients();
    let e = c.efficiencies();
    let (s1, s2) = amplitudes(&c, &FoldedAngles::new(&grid_cosines()));
    let p: f64 = s1
        .iter()
        .zip(&s2)
        .map(|(&a, &b)| mie::phase_from_amplitudes(a, b, x, e.q_sca))
        .sum();
    if !p.is_finite() {
        bail!("non-finite phase function in the single-sphere benchmark");
    }
    Ok(())
}

/// Returns the three normalized phase functions (1/sr) at the 1001 grid angles.
fn rain_lognormal() -> Result<Vec<Vec<f64>>> {
    // The rule scripts/bench_miepython.py uses: 100 radii log-spaced over r_g e^{±3 ln σ_g}.
    let sizes = SizeQuadrature::lognormal_log_spaced(500.0, 1.4, 100, 3.0);
    let angles = FoldedAngles::new(&grid_cosines());
    RAIN_CASES
        .iter()
        .map(|&(lambda_nm, n, kappa)| {
            Ok(mean_phase_at(
                Complex64::new(n, kappa),
                lambda_nm,
                &sizes,
                &angles,
            )?)
        })
        .collect()
}

fn run_miepython(python: &str, repeat: usize) -> Result<serde_json::Value> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scripts/bench_miepython.py");
    let phase_file =
        std::env::temp_dir().join(format!("photometeor-bench-{}.json", std::process::id()));
    let mut cmd = Command::new(python);
    cmd.arg(&script).arg("--phase-out").arg(&phase_file);
    if repeat == 1 {
        cmd.arg("--quick");
    }
    let out = cmd
        .output()
        .with_context(|| format!("running {python} {}", script.display()))?;
    if !out.status.success() {
        bail!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        );
    }
    let mut value: serde_json::Value =
        serde_json::from_slice(&out.stdout).context("parsing miepython benchmark JSON")?;
    let phase: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&phase_file).context("reading miepython rain phase functions")?,
    )?;
    let _ = std::fs::remove_file(&phase_file);
    value["rain_phase"] = phase;
    Ok(value)
}

/// Largest relative difference between our rain phase functions and miepython's.
fn compare_phase(ours: &[Vec<f64>], theirs: &serde_json::Value) -> Result<f64> {
    let rows = theirs
        .get("phase")
        .or_else(|| theirs.get("phases"))
        .unwrap_or(theirs)
        .as_array()
        .context("miepython phase output: expected a list of 3 rows")?;
    let mut worst: f64 = 0.0;
    for (a, b) in ours.iter().zip(rows) {
        let b = b.as_array().context("miepython phase row")?;
        for (x, y) in a.iter().zip(b) {
            let y = y.as_f64().context("miepython phase value")?;
            worst = worst.max((x - y).abs() / y.abs());
        }
    }
    Ok(worst)
}

/// One `photometeor bake … --json` in a child process; its JSON summary.
fn bake_once(
    scene: &Option<PathBuf>,
    out: &std::path::Path,
    preset: &str,
    jobs: Option<usize>,
) -> Result<(f64, serde_json::Value)> {
    bake_process(scene, out, preset, jobs, &[])
}

/// [`bake_once`] with further arguments (`--shard K/N`).
fn bake_process(
    scene: &Option<PathBuf>,
    out: &std::path::Path,
    preset: &str,
    jobs: Option<usize>,
    extra: &[&str],
) -> Result<(f64, serde_json::Value)> {
    let exe = std::env::current_exe().context("locating the photometeor executable")?;
    let mut cmd = Command::new(exe);
    cmd.arg("bake");
    if let Some(s) = scene {
        cmd.arg(s);
    }
    cmd.arg("--out")
        .arg(out)
        .args(["--quality", preset, "--quiet", "--json"])
        .args(extra);
    if let Some(j) = jobs {
        cmd.args(["--jobs", &j.to_string()]);
    }
    let before = MachineTime::now();
    let start = Instant::now();
    let output = cmd.output().context("running photometeor bake")?;
    let wall = start.elapsed().as_secs_f64();
    if !output.status.success() {
        bail!(
            "photometeor bake --quality {preset} failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let mut report: serde_json::Value =
        serde_json::from_slice(&output.stdout).context("reading the bake summary")?;
    if let (Some(a), Some(b)) = (before, MachineTime::now()) {
        report["machine_cpu_s"] = json!(b.busy_s - a.busy_s);
        report["stolen_share"] = json!((b.steal_s - a.steal_s) / (b.total_s - a.total_s));
    }
    Ok((wall, report))
}

/// The machine's CPU time from /proc/stat (Linux; USER_HZ = 100 ticks per second): busy (user,
/// nice, system, irq, softirq), stolen by the hypervisor for other guests, and in all. On a
/// shared virtual machine the wall time of a bake depends on what the host's other guests do;
/// the busy seconds and the stolen share say how much of a run's wall time was ours.
struct MachineTime {
    busy_s: f64,
    steal_s: f64,
    total_s: f64,
}

impl MachineTime {
    fn now() -> Option<Self> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let ticks: Vec<f64> = stat
            .lines()
            .next()?
            .split_whitespace()
            .skip(1)
            .map(|t| t.parse().ok())
            .collect::<Option<_>>()?;
        let at = |i: usize| ticks.get(i).copied().unwrap_or(0.0) / 100.0;
        // user nice system idle iowait irq softirq steal
        Some(Self {
            busy_s: at(0) + at(1) + at(2) + at(5) + at(6),
            steal_s: at(7),
            total_s: (0..8).map(at).sum(),
        })
    }
}

fn bench_bake(b: BakeBench) -> Result<()> {
    let temp;
    let root = match &b.keep {
        Some(dir) => dir.clone(),
        None => {
            temp = tempfile::tempdir().context("creating a temporary directory")?;
            temp.path().to_path_buf()
        }
    };
    let mut rows = Vec::new();
    for preset in b
        .presets
        .split(',')
        .map(str::trim)
        .filter(|p| !p.is_empty())
    {
        if !["draft", "standard", "reference"].contains(&preset) {
            bail!("preset {preset:?} is not one of draft, standard, reference");
        }
        let out = root.join(preset);
        if out.exists() {
            std::fs::remove_dir_all(&out).with_context(|| format!("clearing {}", out.display()))?;
        }
        let (first, report) = bake_once(&b.scene, &out, preset, b.jobs)?;
        let (again, report_again) = bake_once(&b.scene, &out, preset, b.jobs)?;
        let bytes: u64 = std::fs::read_dir(&out)?
            .filter_map(|e| e.ok())
            .filter(|e| e.path().extension().is_some_and(|x| x == "exr"))
            .filter_map(|e| e.metadata().ok().map(|m| m.len()))
            .sum();
        let shards = match b.shards {
            Some(n) => Some(bench_shards(&b, &root, preset, n, first, &report)?),
            None => None,
        };
        rows.push(json!({
            "shards": shards,
            "preset": preset,
            "first_s": first,
            "first_cpu_s": report["machine_cpu_s"],
            "first_stolen_share": report["stolen_share"],
            "rebake_s": again,
            "rebake_speedup": first / again,
            "peak_rss_mib": report["peak_rss_mib"],
            "computed": report["computed"],
            "rebake_cached": report_again["cached"],
            "rebake_computed": report_again["computed"],
            "exr_bytes": bytes,
        }));
    }
    let threads = b.jobs.unwrap_or_else(rayon::current_num_threads);
    if b.json {
        println!("{}", json!({ "threads": threads, "presets": rows }));
        return Ok(());
    }
    println!(
        "bake benchmark ({threads} threads; wall time of each process, the machine's busy CPU \
         seconds during the first bake and the share of its time the host gave other guests):"
    );
    println!(
        "  {:<10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>12} {:>10}",
        "preset", "first s", "CPU s", "stolen", "re-bake s", "speed-up", "peak MiB", "EXR KiB"
    );
    for r in &rows {
        println!(
            "  {:<10} {:>10.2} {:>10.1} {:>9.0}% {:>10.3} {:>10.0} {:>12.0} {:>10.0}",
            r["preset"].as_str().unwrap_or(""),
            r["first_s"].as_f64().unwrap_or(f64::NAN),
            r["first_cpu_s"].as_f64().unwrap_or(f64::NAN),
            100.0 * r["first_stolen_share"].as_f64().unwrap_or(f64::NAN),
            r["rebake_s"].as_f64().unwrap_or(f64::NAN),
            r["rebake_speedup"].as_f64().unwrap_or(f64::NAN),
            r["peak_rss_mib"].as_f64().unwrap_or(f64::NAN),
            r["exr_bytes"].as_u64().unwrap_or(0) as f64 / 1024.0
        );
        if let Some(shards) = r["shards"].as_object() {
            let list = shards["shards"].as_array().cloned().unwrap_or_default();
            for s in &list {
                println!(
                    "    shard {:>2}/{}: {:>8.2} s ({:>5.1} % of the bake without shards, {:.1} CPU s), \
                     peak {:.0} MiB, fields {}",
                    s["k"],
                    list.len(),
                    s["wall_s"].as_f64().unwrap_or(f64::NAN),
                    100.0 * s["share_of_unsharded"].as_f64().unwrap_or(f64::NAN),
                    s["cpu_s"].as_f64().unwrap_or(f64::NAN),
                    s["peak_rss_mib"].as_f64().unwrap_or(f64::NAN),
                    s["fields"]
                );
            }
            println!(
                "    merge: {:.2} s for {} fields ({:.3} s per field); merged = unsharded bytes: {}",
                shards["merge_s"].as_f64().unwrap_or(f64::NAN),
                shards["fields"],
                shards["merge_s_per_field"].as_f64().unwrap_or(f64::NAN),
                shards["byte_identical"]
            );
        }
    }
    Ok(())
}

/// The scene baked as `n` shards, one process after another, then merged: each shard's wall
/// and CPU time and peak memory, the merge's time, and whether the merged files are the bytes
/// of the bake without shards in `root/preset` (its wall time `unsharded_s`).
fn bench_shards(
    b: &BakeBench,
    root: &std::path::Path,
    preset: &str,
    n: u32,
    unsharded_s: f64,
    unsharded: &serde_json::Value,
) -> Result<serde_json::Value> {
    let mut dirs = Vec::new();
    let mut rows = Vec::new();
    for k in 1..=n {
        let dir = root.join(format!("{preset}-shard-{k}-of-{n}"));
        if dir.exists() {
            std::fs::remove_dir_all(&dir).with_context(|| format!("clearing {}", dir.display()))?;
        }
        let shard = format!("{k}/{n}");
        let (wall, report) = bake_process(&b.scene, &dir, preset, b.jobs, &["--shard", &shard])?;
        let record: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.join("shard.json")).context("reading shard.json")?,
        )
        .context("reading shard.json")?;
        let fields: Vec<serde_json::Value> = record["fields"]
            .as_array()
            .map(|f| f.iter().map(|f| f["name"].clone()).collect())
            .unwrap_or_default();
        rows.push(json!({
            "k": k,
            "wall_s": wall,
            "share_of_unsharded": wall / unsharded_s,
            "cpu_s": report["machine_cpu_s"],
            "peak_rss_mib": report["peak_rss_mib"],
            "fields": fields,
        }));
        dirs.push(dir);
    }
    let merged = root.join(format!("{preset}-merged-{n}"));
    if merged.exists() {
        std::fs::remove_dir_all(&merged)
            .with_context(|| format!("clearing {}", merged.display()))?;
    }
    let exe = std::env::current_exe().context("locating the photometeor executable")?;
    let start = Instant::now();
    let output = Command::new(exe)
        .arg("merge")
        .args(&dirs)
        .arg("--out")
        .arg(&merged)
        .arg("--quiet")
        .output()
        .context("running photometeor merge")?;
    let merge_s = start.elapsed().as_secs_f64();
    if !output.status.success() {
        bail!(
            "photometeor merge failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let published = |dir: &std::path::Path| -> Result<Vec<(String, Vec<u8>)>> {
        let mut files = Vec::new();
        for e in std::fs::read_dir(dir)? {
            let e = e?;
            let name = e.file_name().to_string_lossy().to_string();
            if e.file_type()?.is_file() && !name.starts_with('.') {
                files.push((name, std::fs::read(e.path())?));
            }
        }
        files.sort();
        Ok(files)
    };
    let identical = published(&merged)? == published(&root.join(preset))?;
    let fields = unsharded["computed"].as_array().map_or(0, Vec::len)
        + unsharded["cached"].as_array().map_or(0, Vec::len);
    Ok(json!({
        "n": n,
        "shards": rows,
        "merge_s": merge_s,
        "fields": fields,
        "merge_s_per_field": merge_s / fields.max(1) as f64,
        "byte_identical": identical,
    }))
}

fn bench_crystal(c: CrystalBench) -> Result<()> {
    use mie::crystal::{Prism, TraceSettings, trace};
    let prism = Prism::new(c.aspect_ratio, 100.0);
    let grid = ThetaGrid::new(0.18).expect("0.18° divides 180°");
    let n_ice = mie::Material::Ice.refractive_index(550.0, -20.0)?.re;
    let all = rayon::current_num_threads();
    for threads in [1, all] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .context("building the thread pool")?;
        let start = Instant::now();
        let t = pool.install(|| {
            trace(
                &prism,
                n_ice,
                0.0,
                grid,
                TraceSettings::new(c.rays, 1, c.roughness).split(c.tilt_splits),
            )
        });
        let seconds = start.elapsed().as_secs_f64();
        let rate = t.rays_hit as f64 / seconds;
        println!(
            "{threads} thread(s): {} rays in {seconds:.2} s = {:.3} M rays/s ({:.3} M rays/s per thread); g_GO {:.4}, delta {:.3}, lost {:.1e}",
            t.rays_hit,
            rate / 1e6,
            rate / 1e6 / threads as f64,
            t.g,
            t.delta,
            t.lost
        );
    }
    Ok(())
}
