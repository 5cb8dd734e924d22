//! `photometeor view`: the scene in a window, live. The sun, the camera, the model and its
//! settings, the exposure and the volumes' density move; the image answers with its frame time,
//! and, given a truth frame, with its error against it.
//!
//! ```text
//! window (eframe: winit + wgpu surface, egui controls)   ── Request (latest wins) ──▶ worker
//!   app.rs: state, panels, orbit/fly camera, A/B, script  ◀── Shown (image, passes) ──  thread
//!   rebake.rs: a field's microphysics changed ─▶ bake in the background ─▶ new tables ─▶ ┘
//! ```
//!
//! The worker (`worker.rs`) owns the render device, the tables and the prepared model
//! renderers; it renders with the same `ModelSettings::render` as `photometeor render` and
//! hands back the image, which the window tone-maps exactly as `render`'s PNG and draws at an
//! integer zoom. Rendering off the window's thread keeps the controls live where a frame is
//! slow (lavapipe); requests that arrive while a frame renders are merged, the newest kept.
//!
//! Built with the `view` feature only (`cargo run --release --features view -- view`), so the
//! bake and render commands build without a windowing stack.

mod app;
mod rebake;
mod script;
mod worker;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;

use crate::commands::render::{AUTO, gpu, parse_setting, prepare};

/// The render models the window can switch between: those with a GPU renderer but the
/// reference (the registry's list).
pub fn models() -> Vec<&'static str> {
    render::registry::interactive_models()
}

#[derive(Debug, ClapArgs)]
pub struct ViewArgs {
    /// Scene file (as for `render`; the file is watched: an edit is applied when it is valid
    /// and shown as an error, the last good scene kept, when it is not). Default: the embedded
    /// rainbow scene.
    scene: Option<PathBuf>,
    /// The model shown first (switchable in the window): one with a GPU renderer, or `auto`
    /// (as for `render`: the fastest within 10 % of the truth at the scene's optical depth,
    /// docs/coupled/sweep.md).
    #[arg(long, default_value = AUTO, value_parser = clap::builder::PossibleValuesParser::new(
        std::iter::once(AUTO).chain(models())
    ))]
    model: String,
    /// A setting of the first model, `KEY=VALUE` in TOML, over the scene's [render.<model>];
    /// repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Image width in pixels, 1–8192 (overrides [render] width); the window shows it at the
    /// largest integer zoom that fits.
    #[arg(long)]
    width: Option<usize>,
    /// Image height in pixels, 1–8192 (overrides [render] height).
    #[arg(long)]
    height: Option<usize>,
    /// Exposure of the display (multiplies radiance before 1 − e^{−x}, as `render`'s PNG);
    /// default: the scene's, else automatic from the first frame.
    #[arg(long)]
    exposure: Option<f64>,
    /// A truth frame of the scene's view (`render --model truth --out FILE`, same size) for the
    /// A/B: the window shows the model, the truth or the error map, with the error figures.
    #[arg(long, value_name = "EXR")]
    truth: Option<PathBuf>,
    /// Bake directory (as for `render`; default: the scene's under the user's cache).
    #[arg(long)]
    tables: Option<PathBuf>,
    /// Accuracy preset of the bake, overriding the scene's.
    #[arg(long, value_parser = ["draft", "standard", "reference"])]
    quality: Option<String>,
    /// Write what the window shows to FILE (PNG) once the view is rendered, then exit; also
    /// FILE with `.exr` (the view's radiance, as `render --out` writes it) and `.json` (where
    /// the image sits in the window, the view, the model, the frame times). With --script, the
    /// shot is taken after the last step.
    #[arg(long, value_name = "FILE")]
    screenshot: Option<PathBuf>,
    /// With --screenshot: frames rendered of the final view before the shot, 1–10000; the
    /// frame time written is their mean.
    #[arg(long, default_value_t = 1)]
    frames: usize,
    /// A TOML file of steps run in order, each once the previous one's frame is shown:
    /// `[[step]]` with any of sun_elevation_deg, sun_azimuth_deg (degrees), orbit_deg =
    /// [yaw, pitch] (degrees, about the look-at point), dolly (factor on the distance), model,
    /// set = { key = value }, density_scale, exposure, screenshot = "FILE.png", wait_s (seconds
    /// the window then waits, still watching the scene file), field_size = { FIELD = size }
    /// (the field's size parameter, re-baked before the step's frame).
    #[arg(long, value_name = "TOML")]
    script: Option<PathBuf>,
    /// Milliseconds of per-sun lighting work a frame may do, (0, 60000]: after a sun change
    /// `coupled` lights in steps (the first frame runs those to a whole lighting: the beam,
    /// the skylight, the diffusion; each later frame its transport's next source iterations),
    /// each frame drawn from the lighting as it stands until it converges. A step is not
    /// split, so a frame runs at least one (docs/viewer.md). `max` lights a sun whole.
    #[arg(long, value_name = "MS", default_value_t = 30.0)]
    step_budget_ms: f64,
    /// No progress output on stderr.
    #[arg(long)]
    quiet: bool,
}

/// The longest `--step-budget-ms` taken (a minute of lighting work a frame).
const MAX_STEP_BUDGET_MS: f64 = 60_000.0;

/// `--step-budget-ms` as a duration, or why it is refused.
fn step_budget(ms: f64) -> Result<std::time::Duration> {
    if !(ms > 0.0 && ms <= MAX_STEP_BUDGET_MS) {
        bail!(
            "--step-budget-ms {ms} is outside (0, {MAX_STEP_BUDGET_MS}] (milliseconds of \
             per-sun lighting work a frame may do)"
        );
    }
    Ok(std::time::Duration::from_secs_f64(ms / 1000.0))
}

/// Runs `photometeor view`: everything is checked and baked before the window opens.
pub fn run(a: ViewArgs) -> Result<()> {
    if !(1..=10_000).contains(&a.frames) {
        bail!("--frames {} must be in 1–10000", a.frames);
    }
    if let Some(e) = a.exposure
        && !(e.is_finite() && e > 0.0)
    {
        bail!("--exposure {e} must be finite and > 0");
    }
    let budget = step_budget(a.step_budget_ms)?;
    let steps = match &a.script {
        Some(path) => script::read(path)?,
        None => Vec::new(),
    };
    if cfg!(target_os = "linux")
        && ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"]
            .iter()
            .all(|v| std::env::var_os(v).is_none_or(|s| s.is_empty()))
    {
        bail!(
            "photometeor view needs a display: neither DISPLAY (X11) nor WAYLAND_DISPLAY is set \
             (headless, run it under xvfb-run)"
        );
    }
    let overrides = a
        .set
        .iter()
        .map(|kv| parse_setting(kv).map(|(k, v)| (format!("--set {kv}"), k, v)))
        .collect::<Result<Vec<_>>>()?;
    let mut outputs: Vec<PathBuf> = Vec::new();
    if let Some(shot) = &a.screenshot {
        outputs.extend(app::shot_files(shot));
    }
    for step in &steps {
        if let Some(shot) = &step.screenshot {
            outputs.extend(app::shot_files(shot));
        }
    }
    let output_refs: Vec<&std::path::Path> = outputs.iter().map(PathBuf::as_path).collect();
    // No adapter is said before anything is baked.
    let gpu = gpu()?;
    let p = prepare(
        &a.model,
        &overrides,
        a.scene.as_deref(),
        a.tables.clone(),
        a.quality.as_deref(),
        a.quiet,
        &output_refs,
        None,
        |r| {
            r.width = a.width.unwrap_or(r.width);
            r.height = a.height.unwrap_or(r.height);
        },
    )?;
    for step in &steps {
        step.check(&p.scene)?;
    }
    let truth = match &a.truth {
        Some(path) => Some(
            render::error_map::read_frame(path)
                .with_context(|| format!("--truth {}", path.display()))?,
        ),
        None => None,
    };
    let adapter = gpu.describe();
    let worker = worker::Worker::start(gpu, p.scene.clone(), p.tables, budget)?;
    let options = app::Options {
        scene_path: a.scene.clone(),
        first_model: p.model,
        exposure: a.exposure,
        truth,
        screenshot: a.screenshot.clone(),
        frames: a.frames,
        steps,
        adapter,
        chosen: p.choice.map(|c| format!("{}, {}", c.model, c.why)),
        size: (a.width, a.height),
        inputs: p.inputs,
    };
    app::open(options, p.scene, p.plan, worker)
}
