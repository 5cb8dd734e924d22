//! `photometeor render`: bake what a scene's volumes use, then render it with a model
//! (`render::model`) on the GPU, or with the model's CPU reference.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use bake::{BakePlan, Quality, Scene};
use clap::Args as ClapArgs;
use render::{Frame, Job, ModelSettings, On, RenderScene, Rendered};
use runtime::Tables;
use runtime::gpu::Gpu;

use crate::progress::Bars;

/// The scene `photometeor render` uses when none is given: the rainbow in a rain shaft.
pub const DEFAULT_RENDER_SCENE: &str = include_str!("../../data/scenes/rainbow.toml");

#[derive(Debug, ClapArgs)]
pub struct RenderArgs {
    /// Scene file (TOML: [scene], [[field]], [render] with a [render.<model>] table per model,
    /// [camera], [sun], [sky], [[volume]]; see data/scenes/). Default: the embedded rainbow
    /// scene (data/scenes/rainbow.toml).
    scene: Option<PathBuf>,
    /// HDR output: OpenEXR with R, G, B = linear radiance per unit solar irradiance outside
    /// the atmosphere (1/sr) and A = the volumes' transparency.
    #[arg(long)]
    out: PathBuf,
    /// Also write a tone-mapped sRGB PNG.
    #[arg(long)]
    png: Option<PathBuf>,
    /// Image width in pixels, 1–8192 (overrides [render] width).
    #[arg(long)]
    width: Option<usize>,
    /// Image height in pixels, 1–8192 (overrides [render] height).
    #[arg(long)]
    height: Option<usize>,
    /// The render model (each reads its settings from the scene's [render.<model>] table);
    /// `auto` chooses, after the bake, the fastest model whose median error against the truth,
    /// measured on the optical-depth sweep at the scene's optical depth, is within 10 %
    /// (docs/coupled/sweep.md), and says which and why.
    #[arg(long, default_value = AUTO, value_parser = model_parser())]
    model: String,
    /// A setting of the model, `KEY=VALUE` in TOML (e.g. `k_multi=0.3`, `phase="tables"`),
    /// over the scene's [render.<model>]; repeatable. A key the model does not have is refused.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Half-angle (riley) or shadow-view (miyazaki) slices through the volumes, 1–4096: the
    /// model's `slices`.
    #[arg(long)]
    slices: Option<usize>,
    /// Light-buffer (riley) or shadow-surface (miyazaki) texels per side, 2–4096: the model's
    /// `light_resolution`.
    #[arg(long)]
    light_resolution: Option<usize>,
    /// riley: the light buffer's update per slab, `continuum` (I ← I e^{−τ(1 − αF)}, the
    /// default: converges as slices are added) or `riley2004` (Eq. 25 as printed).
    #[arg(long, value_parser = ["continuum", "riley2004"])]
    light_update: Option<String>,
    /// biri: the kernel's integral, `exact` (the bake's primitive C(τ_h, θ), interpolated) or
    /// `polynomial` (the paper's degree-4 fit, Eq. 2).
    #[arg(long, value_parser = ["exact", "polynomial"])]
    biri_kernel: Option<String>,
    /// truth: samples (paths) per pixel, [1, 1048576].
    #[arg(long)]
    spp: Option<usize>,
    /// truth: stop early once the median relative standard error of the volume's pixels
    /// (green) is at or below this, e.g. 0.01 for 1 %; 0: run all samples.
    #[arg(long)]
    noise: Option<f64>,
    /// truth: seed of the random streams; the image is the same for a seed whatever the
    /// thread count (CPU) or adapter (GPU, up to float rounding); the GPU's and the CPU's
    /// images of one seed differ sample by sample and agree within their noise.
    #[arg(long)]
    seed: Option<u64>,
    /// truth: wavelengths each path carries, 1–4 (hero-wavelength sampling: the first decides
    /// the path, all of them score it, combined by the balance heuristic); 0, the default,
    /// carries all three of an rgb3 bake and 4 of a spectral one. 1 is one wavelength per path.
    #[arg(long)]
    wavelengths_per_path: Option<usize>,
    /// truth: scatterings after which a path ends, 1–1000000; 1 is exact single scattering
    /// (what biri and miyazaki's k_multi = 0 model); 0: the default bound (1000000).
    #[arg(long)]
    max_scatterings: Option<usize>,
    /// PNG exposure (multiplies radiance before 1 − e^{−x}); default: the scene's, or automatic.
    #[arg(long)]
    exposure: Option<f64>,
    /// Bake directory for the scene's tables (the fields its volumes use are baked or taken
    /// from the cache in DIR/.cache; other fields a bake there has are kept). Default: a
    /// directory per scene under the user's cache directory ($XDG_CACHE_HOME/photometeor or
    /// ~/.cache/photometeor).
    #[arg(long)]
    tables: Option<PathBuf>,
    /// Accuracy preset of the bake, overriding the scene's.
    #[arg(long, value_parser = ["draft", "standard", "reference"])]
    quality: Option<String>,
    /// Render with the CPU reference instead of the GPU (slow; no adapter needed).
    #[arg(long)]
    cpu: bool,
    /// The most memory the frame may take, GiB; a frame whose estimate exceeds it is refused
    /// before anything is baked, naming the setting to lower. Default: the memory available
    /// (/proc/meminfo's MemAvailable).
    #[arg(long, value_name = "GIB")]
    max_memory: Option<f64>,
    /// No progress output.
    #[arg(long)]
    quiet: bool,
}

/// `--model`'s values, each with its model's one-line description for `--help`.
pub fn model_parser() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        std::iter::once(clap::builder::PossibleValue::new(AUTO).help(
            "the model the scene needs: the fastest within 10 % of the truth at its optical depth",
        ))
        .chain(
            render::registry::model_descriptions()
                .into_iter()
                .map(|(name, about)| clap::builder::PossibleValue::new(name).help(about)),
        ),
    )
}

impl RenderArgs {
    /// The model settings the flags give: (flag, key, value), `--set` included.
    fn overrides(&self) -> Result<Vec<(String, String, toml::Value)>> {
        let int = |v: usize| toml::Value::Integer(v as i64);
        let mut out: Vec<(String, String, toml::Value)> = Vec::new();
        let mut flag = |name: &str, key: &str, v: Option<toml::Value>| {
            if let Some(v) = v {
                out.push((format!("--{name}"), key.to_string(), v));
            }
        };
        flag("slices", "slices", self.slices.map(int));
        flag(
            "light-resolution",
            "light_resolution",
            self.light_resolution.map(int),
        );
        let text = |v: &Option<String>| v.clone().map(toml::Value::String);
        flag("light-update", "light_update", text(&self.light_update));
        flag("biri-kernel", "kernel", text(&self.biri_kernel));
        flag("spp", "spp", self.spp.map(int));
        flag("noise", "noise", self.noise.map(toml::Value::Float));
        flag(
            "seed",
            "seed",
            self.seed.map(|v| toml::Value::Integer(v as i64)),
        );
        let carried = self.wavelengths_per_path.map(int);
        flag("wavelengths-per-path", "wavelengths_per_path", carried);
        flag(
            "max-scatterings",
            "max_scatterings",
            self.max_scatterings.map(int),
        );
        for kv in &self.set {
            let (key, value) = parse_setting(kv)?;
            out.push((format!("--set {kv}"), key, value));
        }
        Ok(out)
    }
}

/// `KEY=VALUE` with VALUE in TOML (a bare word is taken as a string).
pub fn parse_setting(kv: &str) -> Result<(String, toml::Value)> {
    let (key, value) = kv
        .split_once('=')
        .ok_or_else(|| anyhow!("--set {kv:?}: expected KEY=VALUE, e.g. k_multi=0.3"))?;
    let key = key.trim().to_string();
    let value = value.trim();
    let parsed = toml::from_str::<toml::Table>(&format!("v = {value}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value.to_string()));
    Ok((key, parsed))
}

/// The GPU, or an error that says how to get one (or to render with --cpu).
pub fn gpu() -> anyhow::Result<Gpu> {
    Gpu::new().context(
        "no GPU adapter: install a driver (on Debian, mesa-vulkan-drivers gives lavapipe, a \
         software Vulkan) or render with --cpu",
    )
}

/// What a render needs once the scene is read and its tables baked.
pub struct Prepared {
    /// The scene's render part.
    pub scene: RenderScene,
    /// The model with its settings, checked against the scene.
    pub model: ModelSettings,
    /// The checked tables, field i = grid channel i.
    pub tables: Tables,
    /// The bake that made them (the scene's fields its volumes use, the directory, the
    /// preset): what the viewer re-bakes when a field's microphysics changes.
    #[cfg_attr(not(feature = "view"), allow(dead_code))]
    pub plan: BakePlan,
    /// The frame, where it was built to choose the model (`--model auto`).
    pub frame: Option<Frame>,
    /// What `--model auto` chose and why.
    #[cfg_attr(not(feature = "view"), allow(dead_code))]
    pub choice: Option<render::auto::Choice>,
    /// The files the scene reads beside itself ([`scene_inputs`]): what the viewer watches.
    #[cfg_attr(not(feature = "view"), allow(dead_code))]
    pub inputs: Vec<PathBuf>,
}

/// Refuses a scene whose volumes use a field no [[field]] makes (naming a member past a sweep's
/// end as such), or that sweeps a field no volume uses (`render` bakes only what it shows).
fn check_used_fields(scene: &Scene, used: &[String], text: &str, origin: &str) -> Result<()> {
    // A field no [[field]] makes is named first, before what the sweeps lack: a member past a
    // sweep's end (`cloud@07` of four) is such a field.
    for name in used {
        if !scene.fields.iter().any(|f| &f.name == name) {
            let sweep = name
                .split_once('@')
                .and_then(|(base, _)| scene.sweeps.iter().find(|s| s.name == base));
            if let Some(sweep) = sweep {
                let members = sweep.members();
                bail!(
                    "{origin}: a [[volume]] uses field {name:?}, which the sweep {:?} does not \
                     have: its members are {} … {} ({} values of {})",
                    sweep.name,
                    members[0],
                    members[members.len() - 1],
                    members.len(),
                    sweep.key
                );
            }
            let have: Vec<&str> = scene.fields.iter().map(|f| f.name.as_str()).collect();
            bail!(
                "{origin}: a [[volume]] uses field {name:?}; the scene's [[field]]s are {}",
                super::bake::list_in_words(&have)
            );
        }
    }
    for sweep in &scene.sweeps {
        let members = sweep.members();
        let (first, last) = (sweep.values[0], sweep.values[sweep.values.len() - 1]);
        let origin = match sweep_line(text, &sweep.name) {
            Some(line) => format!("{origin}: line {line}"),
            None => origin.to_string(),
        };
        if !members.iter().any(|m| used.contains(m)) {
            bail!(
                "{origin}: [[field]] {:?} sweeps {} from {first} to {last} and no [[volume]] \
                 uses it or one of its members: `render` bakes only what the scene shows; \
                 bake the sweep with `photometeor bake`",
                sweep.name,
                sweep.key
            );
        }
    }
    Ok(())
}

/// Reads the scene, checks the model and its settings (`overrides`: flag, key, value) against
/// it, bakes the fields its volumes use, loads and checks them. `adjust` overrides the scene's
/// shared render settings; everything is checked before the bake.
pub fn prepare(
    model: &str,
    overrides: &[(String, String, toml::Value)],
    scene_path: Option<&std::path::Path>,
    tables_dir: Option<PathBuf>,
    quality: Option<&str>,
    quiet: bool,
    outputs: &[&std::path::Path],
    max_memory_gib: Option<f64>,
    adjust: impl FnOnce(&mut RenderScene),
) -> Result<Prepared> {
    let (text, origin, base) = match scene_path {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| format!("reading scene {}", p.display()))?,
            p.display().to_string(),
            p.parent().map(PathBuf::from).unwrap_or_default(),
        ),
        None => (
            DEFAULT_RENDER_SCENE.to_string(),
            "default render scene".to_string(),
            PathBuf::from("."),
        ),
    };
    let mut scene = Scene::parse_in(&text, &origin, Some(&base))?;
    let mut render = RenderScene::parse(&text, &origin, &base)?;
    adjust(&mut render);
    let limit = memory_limit(max_memory_gib)?;
    if model == TRUTH {
        at_file_resolution(&mut render, limit, quiet);
    }
    let candidates = if model == AUTO {
        if let Some((flag, _, _)) = overrides.first() {
            bail!(
                "{flag}: --model auto chooses its model after the bake; name the model \
                 (--model {}) to set its keys",
                render::registry::interactive_models().join(" | ")
            );
        }
        auto_candidates(&render, limit, &origin)?
    } else {
        vec![checked_model(
            model, overrides, &render, limit, &origin, &text,
        )?]
    };
    if !quiet {
        describe_vdb_volumes(&render, &candidates);
    }
    let entries: Vec<format::SweepEntry> = scene.sweeps.iter().map(|s| s.entry()).collect();
    render
        .choose_members(&entries)
        .map_err(|e| at_line(&origin, &text, &e))?;
    let used = render.fields();
    let sized = render
        .volumes
        .iter()
        .find_map(|v| v.size.as_ref().and_then(|p| p.members.as_ref()));
    if let Some(members) = sized.filter(|_| !quiet) {
        let v = &members.values;
        let step = (v[v.len() - 1] / v[0]).powf(1.0 / (v.len() - 1) as f64);
        eprintln!(
            "{}: a size per voxel from {} of its members, {} = {} (×{step:.2} apart)",
            members.name,
            v.len(),
            members.key,
            v.iter()
                .map(|x| format!("{x:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    check_used_fields(&scene, &used, &text, &origin)?;
    // Model only what the scene requires.
    scene.fields.retain(|f| used.contains(&f.name));
    // A sweep of which the volumes use only some members is baked as those fields alone.
    scene
        .sweeps
        .retain(|s| s.members().iter().all(|m| used.contains(m)));
    let quality = match quality {
        Some(q) => Quality::parse(q).context("quality preset")?,
        None => scene.quality,
    };
    let dir = match tables_dir {
        Some(d) => d,
        None => default_tables_dir(&scene.name)?,
    };
    // The outputs may not replace a device, a directory, the scene, a file it reads (a grid,
    // an OBJ) or anything of the bake; links and `..` are resolved before comparing.
    let inputs = scene_inputs(&text, &base, &render);
    let protected: Vec<&std::path::Path> = std::iter::once(dir.as_path())
        .chain(scene_path)
        .chain(inputs.iter().map(PathBuf::as_path))
        .collect();
    for out in outputs {
        format::check_output(out, &protected)?;
    }
    let mut plan = BakePlan::for_preset(scene, dir.clone(), quality);
    // A render bakes only what its volumes use and never removes another field's tables.
    plan.prune = false;
    bake_waiting(&plan, &Bars::new(quiet), quiet)?;
    let names: Vec<&str> = used.iter().map(String::as_str).collect();
    let tables = Tables::open_fields(&dir, Some(&names))?;
    let (model, frame, choice) = if model == AUTO {
        let (model, frame, choice) = auto_choice(candidates, &render, &tables, quiet)?;
        (model, Some(frame), Some(choice))
    } else {
        (
            candidates.into_iter().next().expect("one model"),
            None,
            None,
        )
    };
    Ok(Prepared {
        scene: render,
        model,
        tables,
        plan,
        frame,
        choice,
        inputs,
    })
}

/// The truth samples grid files at their own resolution: `[render] grid_resolution` raised to
/// [`render::volume::file_resolution`] (at most [`render::scene::MAX_GRID_RESOLUTION`]) where the frame still
/// fits in `limit` bytes; where it does not, the scene's resolution stays and a line says so.
fn at_file_resolution(render: &mut RenderScene, limit: u64, quiet: bool) {
    let Some(own) = render::volume::file_resolution(&render.volumes) else {
        return;
    };
    let wanted = own.min(render::scene::MAX_GRID_RESOLUTION);
    if wanted <= render.grid_resolution {
        return;
    }
    let mut raised = render.clone();
    raised.grid_resolution = wanted;
    let fits = raised
        .check_for(TRUTH)
        .and_then(|m| raised.check_memory(&m, limit));
    let from = render.grid_resolution;
    match fits {
        Ok(()) => {
            render.grid_resolution = wanted;
            if !quiet {
                eprintln!(
                    "truth: grid_resolution {from} → {wanted}, the grid files' own voxels{}",
                    if wanted < own {
                        format!(
                            " (they need {own}; {} is the most)",
                            render::scene::MAX_GRID_RESOLUTION
                        )
                    } else {
                        String::new()
                    }
                );
            }
        }
        Err(e) if !quiet => eprintln!(
            "truth: grid_resolution stays {from}, coarser than the grid files' own {wanted}: {e}"
        ),
        Err(_) => {}
    }
}

/// Prints, before work, what each `shape = "vdb"` volume holds (active voxels, boxes, dense
/// size) and the frame's memory estimate for each of `models`.
fn describe_vdb_volumes(render: &RenderScene, models: &[ModelSettings]) {
    let size = |b: u64| match b {
        0..0x10_0000 => format!("{:.1} KiB", b as f64 / 1024.0),
        0x10_0000..0x4000_0000 => format!("{:.1} MiB", b as f64 / f64::from(1u32 << 20)),
        _ => format!("{:.2} GiB", b as f64 / f64::from(1u32 << 30)),
    };
    let mut any = false;
    for v in &render.volumes {
        let render::volume::Shape::Vdb {
            file,
            grid,
            summary: s,
            values,
        } = &v.shape
        else {
            continue;
        };
        any = true;
        let [nx, ny, nz] = values.dims;
        let corner = |[x, y, z]: [f64; 3]| format!("[{x:.1}, {y:.1}, {z:.1}]");
        let [hx, hy, hz] = render::lighting::lattice::voxel_size(values);
        eprintln!(
            "vdb {} grid {grid:?}: {} active voxels ({} leaves, {} tiles; {}{}), index box {:?}–{:?}; \
             dense {nx} × {ny} × {nz} voxels of {hx:.3} × {hy:.3} × {hz:.3} m over {}–{} m, {}",
            file.display(),
            s.active_voxels,
            s.leaves,
            s.tiles,
            s.compression,
            if s.half { ", half floats" } else { "" },
            s.index_min,
            s.index_max,
            corner(values.min_m.to_array()),
            corner(values.max_m.to_array()),
            size(values.bytes()),
        );
        if s.background != 0.0 {
            eprintln!(
                "vdb {}: background {} fills the box where the tree stores nothing; outside the \
                 box the density is 0",
                file.display(),
                s.background
            );
        }
    }
    if any {
        for m in models {
            let total = render::model::Need::total(&render.memory(m));
            eprintln!(
                "--model {}: about {} for this frame (grid_resolution {})",
                m.name(),
                size(total),
                render.grid_resolution
            );
        }
    }
}

/// `--model auto`'s model among `candidates` ([`auto_candidates`]) for the scene's frame on
/// `tables`: the truth where it is the only one, else by [`render::auto::choose`]; says which
/// and why unless `quiet`.
fn auto_choice(
    candidates: Vec<ModelSettings>,
    render: &RenderScene,
    tables: &Tables,
    quiet: bool,
) -> Result<(ModelSettings, Frame, render::auto::Choice)> {
    let frame = render.frame(tables)?;
    let tau = render::auto::optical_depth(tables, &frame.grid);
    if candidates.len() == 1 && candidates[0].name() == TRUTH {
        // The first interactive model's refusal says what only the truth draws.
        let refusal = render::registry::interactive_models()
            .iter()
            .find_map(|m| render.check_for(m).err().map(|e| format!("{m}: {e}")));
        let why = format!(
            "the only model that draws this scene ({})",
            refusal
                .as_deref()
                .unwrap_or("the others do not fit in memory")
        );
        if !quiet {
            eprintln!("--model auto: {TRUTH} — {why}");
        }
        let choice = render::auto::Choice {
            model: TRUTH,
            tau,
            why,
        };
        let model = candidates.into_iter().next().expect("the truth");
        return Ok((model, frame, choice));
    }
    // A model that refuses this grid's depths below its depth limit (coupled's transport
    // on a coarse grid) does not take part, and the line says why; one beyond its limit
    // stays for `choose`, which leaves it out and names the limit.
    let mut able = Vec::new();
    let mut refused = Vec::new();
    for m in candidates.iter().map(ModelSettings::name) {
        let beyond = tau > render::registry::depth_limit(m).unwrap_or(f64::INFINITY);
        match render::registry::depth_refusal(m, tables, &frame).filter(|_| !beyond) {
            Some(e) => refused.push((m, e)),
            None => able.push(m),
        }
    }
    let mut choice = render::auto::choose(&able, tau, &render::auto::measured())
        .expect("auto_candidates is never empty");
    for (m, e) in refused {
        let e = e.split(" (docs/").next().unwrap_or(&e);
        choice.why += &format!("; {m} not taken: {e}");
    }
    if !quiet {
        eprintln!("--model auto: {} — {}", choice.model, choice.why);
    }
    let chosen = candidates
        .into_iter()
        .find(|m| m.name() == choice.model)
        .expect("chosen among the candidates");
    Ok((chosen, frame, choice))
}

/// `--model`'s value that lets the scene choose ([`render::auto`]).
pub const AUTO: &str = "auto";

/// Model `model` with the scene's settings and `overrides` (flag, key, value), checked against
/// the scene and the memory limit before anything is baked.
fn checked_model(
    model: &str,
    overrides: &[(String, String, toml::Value)],
    render: &RenderScene,
    limit: u64,
    origin: &str,
    text: &str,
) -> Result<ModelSettings> {
    for (flag, key, _) in overrides {
        if !RenderScene::model_has(model, key) {
            let keys = render::registry::model_keys()
                .into_iter()
                .find(|(m, _)| *m == model)
                .map(|(_, k)| k.join(", "))
                .unwrap_or_default();
            bail!("{flag}: --model {model} has no setting {key} (its settings: {keys})");
        }
    }
    let pairs: Vec<(String, toml::Value)> = overrides
        .iter()
        .map(|(_, k, v)| (k.clone(), v.clone()))
        .collect();
    let settings = render
        .model(model, &pairs)
        .map_err(|e| anyhow!("{origin}: {e}"))?;
    render
        .check(&settings)
        .map_err(|e| at_line(origin, text, &e.to_string()))?;
    // The truth's standard error is estimated from the spread of its samples: one sample
    // per pixel has none (it would be written as infinite), so at least 2 are asked for.
    if let ModelSettings::Truth(t) = &settings
        && t.spp < 2
    {
        bail!(
            "{origin}: --model truth with spp = {}: the standard error each pixel carries needs \
             at least 2 samples per pixel; set spp to 2 or more",
            t.spp
        );
    }
    render
        .check_memory(&settings, limit)
        .map_err(|e| anyhow!("{origin}: {e}"))?;
    Ok(settings)
}

/// The interactive models that can render the scene within the memory limit (`--model
/// auto` chooses among them after the bake); none is an error naming each one's reason.
fn auto_candidates(render: &RenderScene, limit: u64, origin: &str) -> Result<Vec<ModelSettings>> {
    let mut able = Vec::new();
    let mut reasons = Vec::new();
    for name in render::registry::interactive_models() {
        let checked = render
            .check_for(name)
            .and_then(|m| render.check_memory(&m, limit).map(|()| m));
        match checked {
            Ok(m) => able.push(m),
            Err(e) => reasons.push(format!("{name}: {e}")),
        }
    }
    if able.is_empty() {
        // What only the reference draws (an orthographic camera, a periodic volume): the truth.
        let truth = render
            .check_for(TRUTH)
            .and_then(|m| render.check_memory(&m, limit).map(|()| m));
        match truth {
            Ok(m) => return Ok(vec![m]),
            Err(e) => reasons.push(format!("{TRUTH}: {e}")),
        }
        bail!(
            "{origin}: --model auto: no model renders this scene —\n  {}",
            reasons.join("\n  ")
        );
    }
    Ok(able)
}

/// The reference model, which `--model auto` takes where no interactive model draws the scene.
const TRUTH: &str = "truth";

/// The files a render scene reads beside itself: each grid volume's `file` and each mesh
/// occluder's OBJ `file`, resolved against `base` (the scene file's directory) as the scene's
/// parser resolves them.
pub fn scene_inputs(text: &str, base: &std::path::Path, scene: &RenderScene) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = scene
        .volumes
        .iter()
        .filter_map(|v| match &v.shape {
            render::volume::Shape::Grid { file, .. } | render::volume::Shape::Vdb { file, .. } => {
                Some(file.clone())
            }
            _ => None,
        })
        .collect();
    // A mesh keeps its triangles, not its file's name: the names are read from the text.
    if let Ok(table) = toml::from_str::<toml::Table>(text)
        && let Some(toml::Value::Array(occluders)) = table.get("occluder")
    {
        files.extend(
            occluders
                .iter()
                .filter_map(|o| o.get("file").and_then(toml::Value::as_str))
                .map(|f| base.join(f)),
        );
    }
    files
}

/// The 1-based line of `sweep =` in the `[[field]]` named `name`.
fn sweep_line(text: &str, name: &str) -> Option<usize> {
    let lines: Vec<&str> = text.lines().collect();
    let quoted = format!("\"{name}\"");
    let named = lines.iter().position(|l| {
        let t = l.trim_start();
        t.starts_with("name") && t.contains(&quoted)
    })?;
    let start = (0..=named)
        .rev()
        .find(|&i| lines[i].trim_start().starts_with('['))
        .unwrap_or(0);
    let end = (named + 1..lines.len())
        .find(|&i| lines[i].trim_start().starts_with('['))
        .unwrap_or(lines.len());
    (start..end)
        .find(|&i| lines[i].trim_start().starts_with("sweep"))
        .map(|i| i + 1)
}

/// A scene error found after parsing, placed on its key's line where one line sets that key.
pub fn at_line(origin: &str, text: &str, message: &str) -> anyhow::Error {
    match render::scene::key_line(text, message) {
        Some(line) => anyhow!("{origin}: line {line}: {message}"),
        None => anyhow!("{origin}: {message}"),
    }
}

/// Bakes `plan`; where another process is baking the same directory (a second render of the
/// scene), waits for it, saying so, and then takes what it wrote from the cache.
pub fn bake_waiting(
    plan: &BakePlan,
    progress: &dyn bake::progress::Progress,
    quiet: bool,
) -> Result<()> {
    loop {
        format::BakeLock::wait_until_free(&plan.out_dir, |holder| {
            if !quiet {
                eprintln!(
                    "waiting for process {holder}, which is baking {}; its tables will be used",
                    plan.out_dir.display()
                );
            }
        })?;
        // The lock can be taken again between the wait and the bake's own lock (a third
        // process); wait again then.
        match bake::run(plan, progress) {
            Err(bake::BakeError::Commit(format::CommitError::Locked { .. })) => continue,
            r => return r.map(|_| ()).map_err(Into::into),
        }
    }
}

/// The memory a frame may take (bytes): `--max-memory` GiB, else the memory available now
/// (Linux's MemAvailable), else no bound.
pub fn memory_limit(max_memory_gib: Option<f64>) -> Result<u64> {
    if let Some(g) = max_memory_gib {
        if !(g.is_finite() && g > 0.0) {
            bail!("--max-memory {g} must be a number of GiB > 0");
        }
        return Ok((g * f64::from(1u32 << 30)) as u64);
    }
    let available = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        m.lines()
            .find(|l| l.starts_with("MemAvailable:"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kib| kib.parse::<u64>().ok())
    });
    Ok(available.map_or(u64::MAX, |kib| kib * 1024))
}

/// Runs `photometeor render`.
pub fn run(a: RenderArgs) -> Result<()> {
    if let Some(e) = a.exposure
        && !(e.is_finite() && e > 0.0)
    {
        bail!(
            "--exposure {e} must be finite and > 0 (it multiplies the radiance before 1 − e^(−x))"
        );
    }
    let overrides = a.overrides()?;
    let p = prepare(
        &a.model,
        &overrides,
        a.scene.as_deref(),
        a.tables.clone(),
        a.quality.as_deref(),
        a.quiet,
        &std::iter::once(a.out.as_path())
            .chain(a.png.as_deref())
            .collect::<Vec<_>>(),
        a.max_memory,
        |r| {
            r.width = a.width.unwrap_or(r.width);
            r.height = a.height.unwrap_or(r.height);
        },
    )?;
    let started = Instant::now();
    let frame: Frame = match p.frame {
        Some(f) => f,
        None => p.scene.frame(&p.tables)?,
    };
    if !a.quiet && !p.scene.volumes.is_empty() {
        eprintln!(
            "grid {} × {} × {} built in {:.2} s",
            frame.grid.dims[0],
            frame.grid.dims[1],
            frame.grid.dims[2],
            started.elapsed().as_secs_f64()
        );
    }
    let bar = crate::progress::RenderBar::new(a.quiet);
    let job = Job {
        tables: &p.tables,
        frame: &frame,
        progress: &bar,
        lighting: None,
    };
    let rendered = if a.cpu || !p.model.has_gpu() {
        p.model.render(&job, On::Cpu)?
    } else {
        let gpu = gpu()?;
        let prepared = p.model.prepare(&gpu, &p.tables)?;
        if !a.quiet {
            eprintln!(
                "tables uploaded to {} in {:.1} ms",
                gpu.describe(),
                prepared.tables().upload_seconds * 1e3
            );
        }
        p.model.render(&job, On::Gpu(&gpu, &prepared))?
    };
    bar.finish();
    if !a.quiet {
        eprintln!("{}", rendered.summary);
    }
    write_outputs(&a, &p.scene, &rendered)
}

/// Writes the frame's EXR (with its extra channels) and, if asked, its PNG; a frame with a
/// non-finite pixel writes nothing.
fn write_outputs(a: &RenderArgs, scene: &RenderScene, rendered: &Rendered) -> Result<()> {
    let image = &rendered.image;
    if image.rgb.iter().flatten().any(|v| !v.is_finite()) {
        bail!("the render produced a non-finite pixel; nothing written");
    }
    // A truth stopped (by max_seconds) before a pixel had 2 samples has no standard error there.
    for (name, values) in &rendered.extra {
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            bail!(
                "the render's {name} is {} at pixel ({}, {}) (a truth stopped before every \
                 pixel had 2 samples: raise max_seconds or lower the size); nothing written",
                values[i],
                i % image.width.max(1),
                i / image.width.max(1)
            );
        }
    }
    image.write_exr_with(&a.out, rendered.extra.clone())?;
    if let Some(png) = &a.png {
        let exposure = a
            .exposure
            .or(scene.exposure)
            .unwrap_or_else(|| image.auto_exposure());
        image.write_png(png, exposure)?;
    }
    Ok(())
}

/// `path` as a person reads it without this machine's layout: relative to the working
/// directory where it lies below it, else with the home directory as `~`, else as it is (the
/// viewer's panel shows the tables' folder so).
#[cfg_attr(not(feature = "view"), allow(dead_code))]
pub fn shown_path(path: &std::path::Path) -> String {
    if let Some(rest) = std::env::current_dir().ok().and_then(|cwd| {
        path.strip_prefix(cwd)
            .ok()
            .map(std::path::Path::to_path_buf)
    }) {
        return rest.display().to_string();
    }
    if let Some(rest) = std::env::var_os("HOME")
        .filter(|h| !h.is_empty())
        .and_then(|h| path.strip_prefix(h).ok().map(std::path::Path::to_path_buf))
    {
        return format!("~/{}", rest.display());
    }
    path.display().to_string()
}

/// The bake directory of a scene when `--tables` is not given: under the user's cache directory
/// (`$XDG_CACHE_HOME/photometeor/tables`, else `~/.cache/photometeor/tables`, else the system's
/// temporary directory), named by the scene's name reduced to `[A-Za-z0-9_-]` plus a hash of the
/// full name, so that no name can leave that directory or collide with another.
pub fn default_tables_dir(scene_name: &str) -> Result<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|v| !v.is_empty())
                .map(|h| PathBuf::from(h).join(".cache"))
        })
        .unwrap_or_else(std::env::temp_dir);
    let safe: String = scene_name
        .chars()
        .take(64)
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    // FNV-1a of the full name: stable across runs and platforms.
    let hash = scene_name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    let dir = base
        .join("photometeor")
        .join("tables")
        .join(format!("{safe}-{:08x}", hash as u32));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::shown_path;

    #[test]
    fn paths_are_shown_from_the_working_directory_or_home() {
        let cwd = std::env::current_dir().unwrap();
        assert_eq!(
            shown_path(&cwd.join("tables").join("glory")),
            "tables/glory"
        );
        // Neither below the working directory nor the home directory: as it is.
        let elsewhere = std::path::Path::new("/photometeor-nowhere/tables");
        assert_eq!(shown_path(elsewhere), "/photometeor-nowhere/tables");
        if let Some(home) = std::env::var_os("HOME").filter(|h| !h.is_empty())
            && !cwd.starts_with(&home)
        {
            let cache = std::path::Path::new(&home).join(".cache/photometeor/tables/x");
            assert_eq!(shown_path(&cache), "~/.cache/photometeor/tables/x");
        }
    }
}
