//! `photometeor bench relight`: coupled's relight in steps after a sun move (what the viewer
//! does between frames, `runtime/render/src/relight.rs`), started cold (from the diffusion) and
//! warm (from the last sun's lighting): after each step from the second, the time so far and
//! the error of the image drawn from the lighting as it stands, against the converged image
//! and, where given, against the truth of the moved view. The per-sun passes on the CPU (all
//! cores), or with `--gpu` where coupled's `per_sun` puts them; the gathers on the CPU.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use render::coupled::light::Lighting;
use render::coupled::{Settings, gather, light};
use render::error_map::{self, LUMA, Pixels};
use render::lighting::OnGpu;
use render::lighting::resident::Traffic;
use render::{Image, ModelSettings};
use runtime::Tables;
use serde_json::json;

use super::render::{parse_setting, prepare};

#[derive(Debug, Args)]
pub struct RelightBench {
    /// Scene file (TOML with [render], [camera], [sun], [[volume]]); default: the embedded
    /// rainbow scene.
    scene: Option<PathBuf>,
    /// Bake preset for the tables.
    #[arg(long, default_value = "draft")]
    quality: String,
    /// Bake directory (default: the scene's under the user's cache directory, as `render`).
    #[arg(long)]
    tables: Option<PathBuf>,
    /// Sun moves in azimuth from the scene's sun (degrees, each in (0, 180]), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,5,30")]
    moves: Vec<f64>,
    /// Image width and height (pixels, 1–4096; default: the scene's).
    #[arg(long)]
    size: Option<usize>,
    /// A setting of coupled, `KEY=VALUE` in TOML (e.g. preset=realtime); repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Truth frames (`render --model truth --out`) of the moved views, one per move in order,
    /// the same size: each step's image is measured against them too.
    #[arg(long, value_delimiter = ',')]
    truths: Vec<PathBuf>,
    /// Run the per-sun passes on this machine's GPU adapter where coupled's `per_sun` lets
    /// them (`auto`: a real GPU, not lavapipe), as the viewer does; the gathers stay on the CPU.
    #[arg(long)]
    gpu: bool,
    /// Each call's budget (milliseconds, 0–10000; 0: one step a call, the smallest): on the
    /// GPU a round of the transport goes in parts sized to it, as in the viewer's
    /// `--step-budget-ms`. Only the steps that end a round (or the start) are drawn.
    #[arg(long, default_value_t = 0.0)]
    step_budget_ms: f64,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// One step's image measured: its step, the relight's seconds so far, the rms relative
/// difference of its luminance from the converged image's, and its error against the truth
/// (bias, noise-debiased rms) where one was given.
struct Measured {
    step: usize,
    seconds: f64,
    to_converged: f64,
    truth: Option<(f64, f64)>,
}

pub fn run(b: RelightBench) -> Result<()> {
    for &m in &b.moves {
        if !(m > 0.0 && m <= 180.0) {
            bail!("--moves {m} is outside (0, 180] (degrees of azimuth)");
        }
    }
    if let Some(s) = b.size
        && !(1..=4096).contains(&s)
    {
        bail!("--size {s} is outside 1–4096 pixels");
    }
    if !(0.0..=10_000.0).contains(&b.step_budget_ms) {
        bail!(
            "--step-budget-ms {} is outside 0–10000 (milliseconds a call)",
            b.step_budget_ms
        );
    }
    let budget = Some(Duration::from_secs_f64(b.step_budget_ms / 1000.0));
    if !b.truths.is_empty() && b.truths.len() != b.moves.len() {
        bail!(
            "--truths names {} frames for {} --moves: one per move, in order",
            b.truths.len(),
            b.moves.len()
        );
    }
    let truths = b
        .truths
        .iter()
        .map(|p| error_map::read_frame(p).with_context(|| format!("--truths {}", p.display())))
        .collect::<Result<Vec<_>>>()?;
    let overrides = b
        .set
        .iter()
        .map(|kv| parse_setting(kv).map(|(k, v)| (format!("--set {kv}"), k, v)))
        .collect::<Result<Vec<_>>>()?;
    let p = prepare(
        "coupled",
        &overrides,
        b.scene.as_deref(),
        b.tables.clone(),
        Some(&b.quality),
        true,
        &[],
        None,
        |r| {
            if let Some(s) = b.size {
                (r.width, r.height) = (s, s);
            }
        },
    )?;
    let ModelSettings::Coupled(settings) = p.model else {
        bail!("bench relight times coupled only");
    };
    let frame = p.scene.frame(&p.tables)?;
    let tables = &p.tables;
    let gpu = if b.gpu {
        Some(super::render::gpu()?)
    } else {
        None
    };
    let pipelines = render::lighting::Pipelines::default();
    let on = || {
        gpu.as_ref()
            .filter(|g| settings.per_sun.on_gpu(g))
            .map(|g| pipelines.on(g))
    };
    let last = light::light_on(tables, &frame, &settings, &(), on())?;
    let mut swept_on = last.report.transport_on.clone();
    let mut runs = Vec::new();
    for (k, &moved) in b.moves.iter().enumerate() {
        let mut to = frame.clone();
        to.sun.azimuth_deg += moved;
        for (start, previous) in [("cold", None), ("warm", Some(&last))] {
            let (run, on_what) = relight(
                (tables, &to, &settings, previous),
                (on(), budget),
                truths.get(k),
                (moved, start),
            )?;
            if let Some(on_what) = on_what {
                swept_on = on_what;
            }
            runs.push(run);
        }
    }
    let device = gpu.as_ref().map(|g| g.describe());
    report(&b, (&settings, device, &swept_on), &frame, &runs)
}

/// One sun move's relight from `previous` (or cold), a call at a time with `budget`, each
/// step that shows a new lighting drawn and measured (against `truth` where given); also
/// where the transport's sweeps ran.
fn relight(
    (tables, to, settings, previous): (&Tables, &render::Frame, &Settings, Option<&Lighting>),
    (on, budget): (Option<OnGpu<'_>>, Option<Duration>),
    truth: Option<&error_map::Frame>,
    (moved, start): (f64, &'static str),
) -> Result<(Run, Option<String>)> {
    let mut relight = light::Relight::new(tables, to, settings, previous)?;
    let (mut seconds, mut images) = (0.0, Vec::new());
    let (mut traffic, mut rounds, mut swept_on) = (Default::default(), None, None);
    // The calls once the lighting was whole (the transport's), and the longest.
    let (mut calls, mut longest) = (0, 0.0f64);
    loop {
        let t = Instant::now();
        let whole = relight.rounds().is_some();
        let done = relight.advance(tables, (on, &()), budget)?;
        let call = t.elapsed().as_secs_f64();
        seconds += call;
        if whole {
            calls += 1;
            longest = longest.max(call);
        }
        // A step mid-round shows the lighting of the step that ended the last round.
        let new_round = rounds != relight.rounds();
        rounds = relight.rounds();
        if let Some(lighting) = relight.current().filter(|_| new_round) {
            if done {
                swept_on = Some(lighting.report.transport_on.clone());
                traffic = lighting.report.transport_traffic;
            }
            let image = gather::gather(tables, to, settings, &lighting)?;
            images.push((relight.steps(), seconds, image));
        }
        if done {
            break;
        }
    }
    let converged = &images.last().expect("a step drew").2;
    let steps = images
        .iter()
        .map(|(step, seconds, image)| {
            Ok(Measured {
                step: *step,
                seconds: *seconds,
                to_converged: rms_difference(image, converged),
                truth: truth.map(|t| against_truth(t, image)).transpose()?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let run = Run {
        moved,
        start,
        steps,
        traffic,
        calls,
        longest,
    };
    Ok((run, swept_on))
}

/// The error of `image` against the truth `t`: bias and noise-debiased rms over the volume.
fn against_truth(t: &error_map::Frame, image: &Image) -> Result<(f64, f64)> {
    let model = error_map::Frame {
        image: image.clone(),
        std_error: None,
        luma_error: None,
    };
    let (r, _) = error_map::compare(t, &model, Pixels::Volume)?;
    Ok((r.bias, r.debiased_rms))
}

/// The rms difference of `a`'s and `b`'s luminance over the pixels `b`'s volume covers
/// (1 − T_vol > 1 %), relative to `b`'s mean luminance there.
fn rms_difference(a: &Image, b: &Image) -> f64 {
    let luma = |p: &[f32; 3]| (0..3).map(|c| LUMA[c] * f64::from(p[c])).sum::<f64>();
    let (mut d, mut y, mut n) = (0.0, 0.0, 0usize);
    for i in 0..b.rgb.len() {
        if 1.0 - f64::from(b.transparency[i]) > 0.01 {
            let (ya, yb) = (luma(&a.rgb[i]), luma(&b.rgb[i]));
            d += (ya - yb).powi(2);
            y += yb;
            n += 1;
        }
    }
    if n == 0 || y <= 0.0 {
        return 0.0;
    }
    (d / n as f64).sqrt() / (y / n as f64)
}

/// A sun move measured.
struct Run {
    /// The move (degrees of azimuth).
    moved: f64,
    /// "cold" or "warm".
    start: &'static str,
    /// Each drawn step.
    steps: Vec<Measured>,
    /// What the transport's iteration on the GPU submitted and read back (zero on the CPU).
    traffic: Traffic,
    /// The calls once the lighting was whole (the transport's steps), and the longest (s).
    calls: usize,
    longest: f64,
}

/// Prints the runs (JSON with --json): the settings, the adapter (with --gpu) and where the
/// transport's sweeps ran.
fn report(
    b: &RelightBench,
    (settings, adapter, swept_on): (&render::coupled::Settings, Option<String>, &str),
    frame: &render::Frame,
    runs: &[Run],
) -> Result<()> {
    if b.json {
        let out = json!({
            "scene": b.scene.as_ref().map(|p| p.display().to_string()),
            "grid": frame.grid.dims,
            "image": [frame.width, frame.height],
            "settings": settings,
            "adapter": adapter,
            "transport_swept_on": swept_on,
            "threads": rayon::current_num_threads(),
            "step_budget_ms": b.step_budget_ms,
            "runs": runs.iter().map(|r| json!({
                "moved_deg": r.moved,
                "start": r.start,
                "transport_traffic": r.traffic,
                "transport_calls": r.calls,
                "longest_transport_call_s": r.longest,
                "steps": r.steps.iter().map(|m| json!({
                    "step": m.step,
                    "seconds": m.seconds,
                    "rms_to_converged": m.to_converged,
                    "truth_bias": m.truth.map(|t| t.0),
                    "truth_debiased_rms": m.truth.map(|t| t.1),
                })).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "coupled's relight in steps of {} ms ({} threads; the transport swept on {swept_on}), \
         grid {:?}, image {}×{}, preset {}",
        b.step_budget_ms,
        rayon::current_num_threads(),
        frame.grid.dims,
        frame.width,
        frame.height,
        settings.preset.name()
    );
    for r in runs {
        println!("sun moved {}°, {} start:", r.moved, r.start);
        let t = r.traffic;
        if t.rounds > 0 {
            println!(
                "  the transport on the GPU: {} rounds, {} submissions, {} dispatches, {} \
                 readbacks of {} bytes in all",
                t.rounds, t.submits, t.dispatches, t.readbacks, t.bytes_read
            );
        }
        println!(
            "  {} calls once the lighting was whole, the longest {:.1} ms",
            r.calls,
            r.longest * 1e3
        );
        for m in &r.steps {
            let truth = m.truth.map_or(String::new(), |(bias, rms)| {
                format!(
                    "; against the truth: bias {:+.2} %, debiased rms {:.2} %",
                    bias * 100.0,
                    rms * 100.0
                )
            });
            println!(
                "  step {:2} at {:7.3} s: rms to the converged image {:.2e}{truth}",
                m.step, m.seconds, m.to_converged
            );
        }
    }
    Ok(())
}
