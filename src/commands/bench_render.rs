//! `photometeor bench render`: the frame time of any render models, interleaved in one run so
//! that a change in the machine's load hits every model alike, at a base setting and with the
//! image size, slice count or grid varied one at a time; each model's passes and figures as it
//! reports them (`render::Rendered`), and optionally its CPU reference beside it.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use render::model::Pass;
use render::registry::MODEL_NAMES;
use render::{Job, ModelSettings, On, RenderScene, Rendered};
use serde_json::json;

use super::render::{gpu, parse_setting, prepare};

#[derive(Debug, Args)]
pub struct RenderBench {
    /// Scene file (TOML with [render], [camera], [sun], [[volume]]); default: the embedded
    /// rainbow scene.
    scene: Option<PathBuf>,
    /// Bake preset for the tables (frame time does not depend on it).
    #[arg(long, default_value = "draft")]
    quality: String,
    /// Bake directory (default: a directory per scene under the user's cache directory, as
    /// `photometeor render`).
    #[arg(long)]
    tables: Option<PathBuf>,
    /// Models to time, comma-separated, interleaved in one run (e.g. `riley,miyazaki,max`).
    #[arg(long, value_delimiter = ',', default_value = "riley")]
    model: Vec<String>,
    /// Base setting: width = height (pixels).
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// Base slice count of the models that slice (default: each model's setting in the scene).
    #[arg(long)]
    slices: Option<usize>,
    /// Image sizes to time at the base setting, comma-separated: N (N × N pixels) or WxH
    /// (e.g. 1920x1080), each side 1–8192.
    #[arg(long, value_delimiter = ',')]
    sizes: Vec<String>,
    /// Slice counts to time at the base setting (models that slice), comma-separated.
    #[arg(long, value_delimiter = ',')]
    slice_counts: Vec<usize>,
    /// Grid resolutions (voxels along the volumes' box's longest side) to time, comma-separated
    /// (default: the scene's).
    #[arg(long, value_delimiter = ',')]
    grids: Vec<usize>,
    /// truth: samples per pixel of the timed frame.
    #[arg(long, default_value_t = 64)]
    spp: usize,
    /// A model setting `KEY=VALUE` (TOML) for every model that has the key; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Frames per setting and model; the best of each pass is reported.
    #[arg(long, default_value_t = 2)]
    repeat: usize,
    /// Also time the CPU reference of each model that has a GPU renderer.
    #[arg(long)]
    cpu: bool,
    /// Also time a camera move of the models that keep their per-sun lighting (max,
    /// coupled): frames of the same view that reuse the lighting, as the viewer renders them
    /// (best of --repeat, after one lit frame).
    #[arg(long)]
    camera_moves: bool,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// `--sizes`' N or WxH as (width, height), each side 1–8192.
fn parse_size(text: &str) -> Result<(usize, usize), String> {
    let side = |t: &str| {
        t.trim()
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=8192).contains(n))
            .ok_or_else(|| format!("{text:?}: expected N or WxH, each side 1–8192 pixels"))
    };
    match text.split_once(['x', 'X']) {
        Some((w, h)) => Ok((side(w)?, side(h)?)),
        None => side(text).map(|n| (n, n)),
    }
}

/// One setting to time: image size, slices (for the models that slice) and grid resolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Setting {
    /// Width and height (pixels).
    size: (usize, usize),
    slices: Option<usize>,
    grid: Option<usize>,
}

/// The settings in order: the base, then slices, sizes and grids varied one at a time; or why
/// a size is refused.
fn settings(b: &RenderBench) -> Result<Vec<Setting>> {
    let base = Setting {
        size: (b.size, b.size),
        slices: b.slices,
        grid: None,
    };
    let mut out = vec![base];
    out.extend(b.slice_counts.iter().map(|&s| Setting {
        slices: Some(s),
        ..base
    }));
    for text in &b.sizes {
        let size = parse_size(text).map_err(|e| anyhow::anyhow!("--sizes {e}"))?;
        out.push(Setting { size, ..base });
    }
    out.extend(b.grids.iter().map(|&g| Setting {
        grid: Some(g),
        ..base
    }));
    let mut seen = std::collections::HashSet::new();
    out.retain(|s| seen.insert(*s));
    Ok(out)
}

/// Model `name`'s settings for `setting`: the scene's, the `--set` keys it has, `spp`, slices.
fn model_at(
    scene: &RenderScene,
    name: &str,
    b: &RenderBench,
    setting: Setting,
) -> Result<ModelSettings> {
    let mut overrides = Vec::new();
    for kv in &b.set {
        let (key, value) = parse_setting(kv)?;
        if RenderScene::model_has(name, &key) {
            overrides.push((key, value));
        }
    }
    if RenderScene::model_has(name, "spp") {
        overrides.push(("spp".into(), toml::Value::Integer(b.spp as i64)));
    }
    if let (Some(s), true) = (setting.slices, RenderScene::model_has(name, "slices")) {
        overrides.push(("slices".into(), toml::Value::Integer(s as i64)));
    }
    Ok(scene.model(name, &overrides)?)
}

/// The best (smallest) time of each pass over the frames of one setting.
fn best_passes(best: &mut Vec<Pass>, passes: &[Pass]) {
    for p in passes {
        match best.iter_mut().find(|q| q.name == p.name) {
            Some(q) => q.seconds = q.seconds.min(p.seconds),
            None => best.push(p.clone()),
        }
    }
}

/// The frame's cost as one number: its "frame" pass if it has one, else all passes.
fn cost(passes: &[Pass]) -> f64 {
    passes
        .iter()
        .find(|p| p.name == "frame")
        .map_or_else(|| passes.iter().map(|p| p.seconds).sum(), |p| p.seconds)
}

/// One model's row of the report: its frame at `setting` on `device` over a grid of `dims`,
/// the best of its passes, its cost over the first setting's (`base`), the CPU reference's
/// time and the camera move's, and the figures of its last frame `r`.
fn row(
    m: &ModelSettings,
    r: &Rendered,
    (setting, dims, device): (Setting, [usize; 3], &str),
    (best, base, cpu_s, move_s): (&[Pass], f64, Option<f64>, Option<f64>),
) -> serde_json::Value {
    json!({
        "model": m.name(),
        "width": setting.size.0, "height": setting.size.1,
        "slices": m.to_table().get("slices").and_then(|v| v.as_integer()),
        "grid": dims,
        "device": device,
        "passes": best.iter().map(|p| json!({"name": p.name, "seconds": p.seconds})).collect::<Vec<_>>(),
        "cost_s": cost(best),
        "cost_over_base": cost(best) / base,
        "figures": r.figures.iter().map(|(k, v)| json!({"name": k, "value": v})).collect::<Vec<_>>(),
        "cpu_reference_s": cpu_s,
        "camera_move_s": move_s,
    })
}

pub fn run(b: RenderBench) -> Result<()> {
    for m in &b.model {
        if !MODEL_NAMES.contains(&m.as_str()) {
            bail!("--model {m:?} is not one of {}", MODEL_NAMES.join(", "));
        }
    }
    // The sizes are checked before anything is baked.
    let all = settings(&b)?;
    let p = prepare(
        &b.model[0],
        &[],
        b.scene.as_deref(),
        b.tables.clone(),
        Some(&b.quality),
        true,
        &[],
        None,
        |_| {},
    )?;
    let models: Vec<ModelSettings> = b
        .model
        .iter()
        .map(|m| model_at(&p.scene, m, &b, all[0]))
        .collect::<Result<_>>()?;
    for m in &models {
        p.scene.check(m)?;
    }
    let device = if models.iter().any(|m| m.has_gpu()) {
        Some(gpu()?)
    } else {
        None
    };
    let prepared = match &device {
        Some(g) => models
            .iter()
            .map(|m| m.prepare(g, &p.tables).map(Some))
            .collect::<Result<Vec<_>, _>>()?,
        None => models.iter().map(|_| None).collect(),
    };
    let mut rows = Vec::new();
    let mut base_cost = vec![f64::NAN; models.len()];
    for (k, &setting) in all.iter().enumerate() {
        let mut scene = p.scene.clone();
        scene.grid_resolution = setting.grid.unwrap_or(scene.grid_resolution);
        let mut frame = scene.frame(&p.tables)?;
        (frame.width, frame.height) = setting.size;
        let job = Job {
            tables: &p.tables,
            frame: &frame,
            progress: &(),
            lighting: None,
        };
        let at: Vec<ModelSettings> = b
            .model
            .iter()
            .map(|m| model_at(&scene, m, &b, setting))
            .collect::<Result<_>>()?;
        let on = |i: usize| match (&device, &prepared[i]) {
            (Some(g), Some(pr)) if at[i].has_gpu() => On::Gpu(g, pr),
            _ => On::Cpu,
        };
        if k == 0 {
            // One frame first: a driver may compile a pipeline at its first dispatch.
            for (i, m) in at.iter().enumerate() {
                m.render(&job, on(i))?;
            }
        }
        let mut best: Vec<Vec<Pass>> = vec![Vec::new(); at.len()];
        let mut last: Vec<Option<Rendered>> = vec![None; at.len()];
        for _ in 0..b.repeat.max(1) {
            for (i, m) in at.iter().enumerate() {
                let r = m.render(&job, on(i))?;
                best_passes(&mut best[i], &r.passes);
                if let (Some(g), Some(pr)) = (&device, &prepared[i]) {
                    best_passes(&mut best[i], &m.bench_parts(&job, g, pr)?);
                }
                last[i] = Some(r);
            }
        }
        for (i, m) in at.iter().enumerate() {
            let move_s = if b.camera_moves {
                camera_move(m, &frame, &p.tables, || on(i), b.repeat.max(1))?
            } else {
                None
            };
            let cpu_s = if b.cpu && m.has_gpu() {
                let r = m.render(&job, On::Cpu)?;
                Some(r.passes.iter().map(|p| p.seconds).sum::<f64>())
            } else {
                None
            };
            if k == 0 {
                base_cost[i] = cost(&best[i]);
            }
            let r = last[i].as_ref().expect("one frame");
            let device_name = match (&device, m.has_gpu()) {
                (Some(g), true) => g.describe(),
                _ => format!("CPU, {} threads", rayon::current_num_threads()),
            };
            let timed = (best[i].as_slice(), base_cost[i], cpu_s, move_s);
            rows.push(row(m, r, (setting, frame.grid.dims, &device_name), timed));
        }
    }
    let report = json!({
        "adapter": device.as_ref().map(|g| g.describe()),
        "threads": rayon::current_num_threads(),
        "repeat": b.repeat.max(1),
        "frames": rows,
    });
    if b.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

/// The best of `repeat` frames of `frame`'s view that reuse `m`'s lighting (a camera move in
/// the viewer), after one frame that lights it; `None` for a model that lights every frame.
fn camera_move<'a>(
    m: &ModelSettings,
    frame: &render::Frame,
    tables: &runtime::Tables,
    on: impl Fn() -> On<'a>,
    repeat: usize,
) -> Result<Option<f64>> {
    let cache = render::relight::LightingCache::new();
    let job = Job {
        tables,
        frame,
        progress: &(),
        lighting: Some(&cache),
    };
    m.render(&job, on())?;
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let started = std::time::Instant::now();
        let r = m.render(&job, on())?;
        if !r
            .figures
            .iter()
            .any(|&(k, v)| k == "lighting reused" && v == 1.0)
        {
            return Ok(None);
        }
        best = best.min(started.elapsed().as_secs_f64());
    }
    Ok(Some(best))
}

/// One line per model and setting: size, slices, grid, the cost against the base setting,
/// every pass and figure.
fn print_table(report: &serde_json::Value) {
    println!(
        "{} ({} threads), best of {}, models interleaved",
        report["adapter"].as_str().unwrap_or("no GPU"),
        report["threads"],
        report["repeat"]
    );
    let rows = report["frames"].as_array().cloned().unwrap_or_default();
    for r in &rows {
        let slices = r["slices"]
            .as_i64()
            .map_or(String::new(), |s| format!(", {s} slices"));
        let list = |key: &str, value: &str, show: &dyn Fn(f64) -> String| -> Vec<String> {
            r[key]
                .as_array()
                .map(|a| {
                    a.iter()
                        .map(|p| {
                            let v = p[value].as_f64().unwrap_or(f64::NAN);
                            format!("{} {}", p["name"].as_str().unwrap_or("?"), show(v))
                        })
                        .collect()
                })
                .unwrap_or_default()
        };
        let passes = list("passes", "seconds", &|v| format!("{:.1} ms", v * 1e3));
        let figures = list("figures", "value", &|v| format!("{v:.4}"));
        let cpu = r["cpu_reference_s"].as_f64().map_or(String::new(), |s| {
            format!("; CPU reference {:.1} ms", s * 1e3)
        });
        let cpu = match r["camera_move_s"].as_f64() {
            Some(s) => format!("{cpu}; camera move {:.1} ms", s * 1e3),
            None => cpu,
        };
        println!(
            "{:>9} {:>9} grid {}{slices}: {:.1} ms (× base {:.2}) [{}]{}{cpu}",
            r["model"].as_str().unwrap_or("?"),
            format!("{}×{}", r["width"], r["height"]),
            r["grid"],
            r["cost_s"].as_f64().unwrap_or(f64::NAN) * 1e3,
            r["cost_over_base"].as_f64().unwrap_or(f64::NAN),
            passes.join(", "),
            if figures.is_empty() {
                String::new()
            } else {
                format!(" {}", figures.join(", "))
            }
        );
    }
}
