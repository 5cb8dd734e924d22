//! `photometeor render`: bake what a scene's volumes use, then render it (Riley et al. 2004
//! §4–5) on the GPU, or with the CPU reference.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use bake::{BakePlan, Quality, Scene};
use clap::Args as ClapArgs;
use render::riley::cpu;
use render::riley::gpu::Renderer;
use render::{Frame, RenderScene};
use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::progress::Bars;

/// The scene `photometeor render` uses when none is given: the rainbow in a rain shaft.
pub const DEFAULT_RENDER_SCENE: &str = include_str!("../../data/scenes/rainbow.toml");

#[derive(Debug, ClapArgs)]
pub struct RenderArgs {
    /// Scene file (TOML: [scene], [[field]], [render], [camera], [sun], [sky], [[volume]]; see
    /// data/scenes/). Default: the embedded rainbow scene (data/scenes/rainbow.toml).
    scene: Option<PathBuf>,
    /// HDR output: OpenEXR with R, G, B = linear radiance per unit solar irradiance outside
    /// the atmosphere (1/sr) and A = the volumes' transparency.
    #[arg(long)]
    out: PathBuf,
    /// Also write a tone-mapped sRGB PNG.
    #[arg(long)]
    png: Option<PathBuf>,
    /// Image width in pixels (overrides [render] width).
    #[arg(long)]
    width: Option<usize>,
    /// Image height in pixels (overrides [render] height).
    #[arg(long)]
    height: Option<usize>,
    /// Half-angle slices through the volumes (overrides [render] slices).
    #[arg(long)]
    slices: Option<usize>,
    /// Light-buffer texels per side (overrides [render] light_resolution).
    #[arg(long)]
    light_resolution: Option<usize>,
    /// --model riley: the light buffer's update per slab, `continuum` (I ← I e^{−τ(1 − αF)}, the
    /// default: converges as slices are added) or `riley2004` (Eq. 25 as printed); overrides
    /// [render] light_update.
    #[arg(long, value_parser = ["continuum", "riley2004"])]
    light_update: Option<String>,
    /// PNG exposure (multiplies radiance before 1 − e^{−x}); default: the scene's, or automatic.
    #[arg(long)]
    exposure: Option<f64>,
    /// Bake directory for the scene's tables (the fields its volumes use are baked or taken
    /// from the cache in DIR/.cache; other fields a bake there has are kept). Default: a
    /// directory per scene under the user's cache directory ($XDG_CACHE_HOME/photometeor or
    /// ~/.cache/photometeor).
    #[arg(long)]
    tables: Option<PathBuf>,
    /// The render model: `riley` (Riley et al. 2004's half-angle slicing with light and eye
    /// buffers, the multiple-scattering tables for the angular spread of sunlight) or `truth`
    /// (an unbiased spectral Monte Carlo path tracer of the same scene on the CPU, all cores;
    /// its EXR adds stderr.R/G/B, each pixel's standard error; docs/truth.md) or `miyazaki`
    /// (Miyazaki, Dobashi & Nishita's shadow-view slices: single scattering plus a constant
    /// k_multi, shadows on the ground and in the air, an aerosol [haze] layer) or `max` (Max et
    /// al. 2004: a diffusion solve in the dense core, Poisson-weighted multiple anisotropic
    /// scattering from the bake's M(D, θ) at the tenuous edges; the lighting on the CPU, all
    /// cores, the final gather on the GPU or --cpu; [render] max_threshold,
    /// diffusion_tolerance, max_diffusion_iterations) or `biri` (Biri, Arquès &
    /// Michelin 2006: single scattering of [[light]]s in homogeneous [[medium]]s in closed
    /// form, volumetric shadows of [[occluder]]s from their silhouette planes; GPU, or --cpu).
    #[arg(long, default_value = "riley", value_parser = ["riley", "truth", "miyazaki", "max", "biri"])]
    model: String,
    /// --model biri: the kernel's integral, `exact` (the bake's primitive C(τ_h, θ),
    /// interpolated) or `polynomial` (the paper's degree-4 fit, Eq. 2); overrides [render]
    /// biri_kernel.
    #[arg(long, value_parser = ["exact", "polynomial"])]
    biri_kernel: Option<String>,
    /// --model truth: samples (paths) per pixel, [1, 1048576] (overrides [render] spp).
    #[arg(long)]
    spp: Option<usize>,
    /// --model truth: stop early once the median relative standard error of the volume's
    /// pixels (green) is at or below this, e.g. 0.01 for 1 %; 0: run all samples.
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    /// --model truth: seed of the random streams (overrides [render] seed); the image is the
    /// same for a seed whatever the thread count.
    #[arg(long)]
    seed: Option<u64>,
    /// --model truth: wavelengths each path carries, 1–4 (hero-wavelength sampling: the
    /// first decides the path, all of them score it, combined by the balance heuristic); the
    /// default, 0, carries all three of an rgb3 bake and 4 of a spectral one. 1 is one
    /// wavelength per path, the simple baseline.
    #[arg(long, default_value_t = 0)]
    wavelengths_per_path: usize,
    /// --model truth: scatterings after which a path ends, 1–1000000; 1 is exact single
    /// scattering (what --model biri and miyazaki's k_multi = 0 model); 0: the default bound
    /// (1000000, far beyond any table order).
    #[arg(long, default_value_t = 0)]
    max_scatterings: usize,
    /// Accuracy preset of the bake, overriding the scene's.
    #[arg(long, value_parser = ["draft", "standard", "reference"])]
    quality: Option<String>,
    /// Render with the CPU reference instead of the GPU (slow; no adapter needed).
    #[arg(long)]
    cpu: bool,
    /// No progress output.
    #[arg(long)]
    quiet: bool,
}

/// The GPU, or an error that says how to get one (or to render with --cpu).
fn gpu() -> anyhow::Result<Gpu> {
    Gpu::new().context(
        "no GPU adapter: install a driver (on Debian, mesa-vulkan-drivers gives lavapipe, a \
         software Vulkan) or render with --cpu",
    )
}

/// Reads the scene, bakes the fields its volumes use, loads and checks them, builds the frame.
/// `adjust` overrides the scene's render settings; the result is checked before the bake.
pub fn prepare(
    model: &str,
    scene_path: Option<&std::path::Path>,
    tables_dir: Option<PathBuf>,
    quality: Option<&str>,
    quiet: bool,
    adjust: impl FnOnce(&mut RenderScene),
) -> Result<(RenderScene, Tables)> {
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
    let mut scene = Scene::parse(&text, &origin)?;
    let mut render = RenderScene::parse(&text, &origin, &base)?;
    adjust(&mut render);
    render
        .check_for(model)
        .map_err(|e| anyhow!("{origin}: {e}"))?;
    let used = render.fields();
    for name in &used {
        if !scene.fields.iter().any(|f| &f.name == name) {
            let have: Vec<&str> = scene.fields.iter().map(|f| f.name.as_str()).collect();
            bail!(
                "{origin}: a [[volume]] uses field {name:?}; the scene's [[field]]s are {have:?}"
            );
        }
    }
    // Model only what the scene requires.
    scene.fields.retain(|f| used.contains(&f.name));
    let quality = match quality {
        Some(q) => Quality::parse(q).context("quality preset")?,
        None => scene.quality,
    };
    let dir = match tables_dir {
        Some(d) => d,
        None => default_tables_dir(&scene.name)?,
    };
    let mut plan = BakePlan::for_preset(scene, dir.clone(), quality);
    // A render bakes only what its volumes use and never removes another field's tables.
    plan.prune = false;
    bake::run(&plan, &Bars::new(quiet))?;
    let names: Vec<&str> = used.iter().map(String::as_str).collect();
    let tables = Tables::open_fields(&dir, Some(&names))?;
    Ok((render, tables))
}

/// Runs `photometeor render`.
pub fn run(a: RenderArgs) -> Result<()> {
    if a.wavelengths_per_path > render::truth::MAX_CARRIED {
        bail!(
            "--wavelengths-per-path {} is outside the allowed range [1, {}] (0: the default)",
            a.wavelengths_per_path,
            render::truth::MAX_CARRIED
        );
    }
    let (render, tables) = prepare(
        &a.model,
        a.scene.as_deref(),
        a.tables.clone(),
        a.quality.as_deref(),
        a.quiet,
        |r| {
            r.width = a.width.unwrap_or(r.width);
            r.height = a.height.unwrap_or(r.height);
            r.slices = a.slices.unwrap_or(r.slices);
            r.light_resolution = a.light_resolution.unwrap_or(r.light_resolution);
            r.spp = a.spp.unwrap_or(r.spp);
            if let Some(u) = a
                .light_update
                .as_deref()
                .and_then(render::LightUpdate::parse)
            {
                r.light_update = u;
            }
            r.seed = a.seed.unwrap_or(r.seed);
            if let Some(k) = a
                .biri_kernel
                .as_deref()
                .and_then(render::biri::Kernel::parse)
            {
                r.biri.kernel = k;
            }
        },
    )?;
    if a.model == "truth" {
        return run_truth(&a, &render, &tables);
    }
    if a.model == "biri" && !a.cpu {
        let gpu = gpu()?;
        // 32-bit texels: the exact kernel adds Ams_1 bin values to the primitive.
        let gpu_tables = GpuTables::upload(&gpu, &tables, TexelFormat::F32)?;
        let renderer = render::biri::gpu::Renderer::new(&gpu, &gpu_tables);
        let (image, t) = renderer.render(&gpu, &tables, &gpu_tables, &render)?;
        if !a.quiet {
            eprintln!(
                "analytic single scattering ({}, {} kernel): {}×{}, {} light(s): silhouettes \
                 and upload {:.1} ms, frame {:.1} ms, readback {:.1} ms",
                gpu.describe(),
                render.biri.kernel.name(),
                image.width,
                image.height,
                render.lights.len(),
                t.upload * 1e3,
                t.frame * 1e3,
                t.readback * 1e3
            );
        }
        return write_outputs(&a, &render, &image, Vec::new());
    }
    if a.model == "biri" {
        let t = Instant::now();
        let (image, report) = render::biri::cpu::render(&tables, &render)?;
        if !a.quiet {
            let all = t.elapsed().as_secs_f64();
            let share = |s: f64| 100.0 * s / all.max(1e-12);
            eprintln!(
                "analytic single scattering (CPU reference, {} threads, {} kernel): {}×{}, {} \
                 light(s), {} shadow planes, {:.2} crossings per ray and light: {all:.3} s \
                 (silhouettes {:.1} %, surfaces {:.1} %, medium and shadow planes {:.1} %)",
                rayon::current_num_threads(),
                render.biri.kernel.name(),
                image.width,
                image.height,
                render.lights.len(),
                report.shadow_planes,
                report.crossings_per_ray,
                share(report.silhouettes_s),
                share(report.surfaces_s),
                share(report.medium_s)
            );
        }
        return write_outputs(&a, &render, &image, Vec::new());
    }
    let started = Instant::now();
    let frame: Frame = render.frame(&tables)?;
    let raster = started.elapsed().as_secs_f64();
    if a.model == "max" {
        // Steps 1–4 on the CPU; the gather on the GPU unless --cpu (the per-view part).
        let lighting = render::max::cpu::light(&tables, &frame, &render.max)?;
        let (image, report, on) = if a.cpu {
            let (image, report) =
                render::max::cpu::gather(&tables, &frame, &render.max, &lighting)?;
            (image, report, "CPU".to_string())
        } else {
            let gpu = gpu()?;
            let gpu_tables = GpuTables::upload(&gpu, &tables, TexelFormat::F32)?;
            let renderer = render::max::gpu::Renderer::new(&gpu, &gpu_tables);
            let (image, t, largest) =
                renderer.gather(&gpu, &tables, &gpu_tables, &frame, &render.max, &lighting)?;
            let mut report = lighting.report.clone();
            report.gather_s = t.upload + t.frame + t.readback;
            report.largest_edge_depth = largest;
            (image, report, gpu.describe())
        };
        if !a.quiet {
            eprintln!(
                "diffusion + Poisson edges (lighting on the CPU, {} threads; gather on {on}): \
                 {}×{}, grid {:?}: reduced sunlight \
                 {:.2} s, diffusion {:.2} s ({} unknowns, {} levels, {:?} CG iterations to \
                 residuals {:.1e}/{:.1e}/{:.1e}), clear-air propagation and second solve {:.2} s \
                 (mean light across clear air {:.2e}), final gather {:.2} s; largest edge depth \
                 {:.2} (grid built in {raster:.2} s)",
                rayon::current_num_threads(),
                frame.width,
                frame.height,
                frame.grid.dims,
                report.propagation_s,
                report.diffusion_s,
                report.unknowns,
                report.levels,
                report.iterations,
                report.residual[0],
                report.residual[1],
                report.residual[2],
                report.clear_air_s,
                report.clear_air_mean,
                report.gather_s,
                report.largest_edge_depth
            );
        }
        return write_outputs(&a, &render, &image, Vec::new());
    }
    if a.model == "miyazaki" {
        let t = Instant::now();
        let (image, on) = if a.cpu {
            let image = render::miyazaki::cpu::render(&tables, &frame, &render.svs)?;
            (image, "CPU reference".to_string())
        } else {
            let gpu = gpu()?;
            let gpu_tables = GpuTables::upload(&gpu, &tables, TexelFormat::Auto)?;
            let renderer = render::miyazaki::gpu::Renderer::new(&gpu, &gpu_tables);
            let (image, times) =
                renderer.render(&gpu, &tables, &gpu_tables, &frame, &render.svs)?;
            let on = format!(
                "{}, frame {:.1} ms (upload {:.1} ms, readback {:.1} ms)",
                gpu.describe(),
                times.frame * 1e3,
                times.upload * 1e3,
                times.readback * 1e3
            );
            (image, on)
        };
        if !a.quiet {
            eprintln!(
                "shadow-view slices ({on}): {}×{}, {} slices, a = {}, k_multi = {} /sr, shadow \
                 surface {}²: {:.2} s in all (grid {:?} built in {raster:.2} s)",
                frame.width,
                frame.height,
                frame.slices,
                render.svs.a,
                render.svs.k_multi,
                frame.light_resolution,
                t.elapsed().as_secs_f64(),
                frame.grid.dims
            );
        }
        return write_outputs(&a, &render, &image, Vec::new());
    }
    let image = if a.cpu {
        let t = Instant::now();
        let image = cpu::render(&tables, &frame)?;
        if !a.quiet {
            eprintln!(
                "CPU reference: {}×{}, {} slices, light buffer {}²: {:.2} s (grid {:?} built in {raster:.2} s)",
                frame.width,
                frame.height,
                frame.slices,
                frame.light_resolution,
                t.elapsed().as_secs_f64(),
                frame.grid.dims
            );
        }
        image
    } else {
        let gpu = gpu()?;
        let gpu_tables = GpuTables::upload(&gpu, &tables, TexelFormat::Auto)?;
        let renderer = Renderer::new(&gpu, &gpu_tables);
        let (image, t) = renderer.render(&gpu, &tables, &gpu_tables, &frame)?;
        if !a.quiet {
            eprintln!(
                "{}: {}×{}, {} slices, light buffer {}²: tables upload {:.1} ms, grid {:?} built \
                 {raster:.2} s and uploaded {:.1} ms, frame {:.1} ms, readback {:.1} ms",
                gpu.describe(),
                frame.width,
                frame.height,
                frame.slices,
                frame.light_resolution,
                gpu_tables.upload_seconds * 1e3,
                frame.grid.dims,
                t.upload * 1e3,
                t.frame * 1e3,
                t.readback * 1e3
            );
        }
        image
    };
    write_outputs(&a, &render, &image, Vec::new())
}

/// Writes the frame's EXR (with `extra` channels) and, if asked, its PNG; a frame with a
/// non-finite pixel writes nothing.
fn write_outputs(
    a: &RenderArgs,
    render: &RenderScene,
    image: &render::Image,
    extra: Vec<(String, Vec<f32>)>,
) -> Result<()> {
    if image.rgb.iter().flatten().any(|v| !v.is_finite()) {
        bail!("the render produced a non-finite pixel; nothing written");
    }
    image.write_exr_with(&a.out, extra)?;
    if let Some(png) = &a.png {
        let exposure = a
            .exposure
            .or(render.exposure)
            .unwrap_or_else(|| image.auto_exposure());
        image.write_png(png, exposure)?;
    }
    Ok(())
}

/// `render --model truth`: path-trace, then write the EXR (with stderr.R/G/B) and the PNG.
fn run_truth(a: &RenderArgs, render: &RenderScene, tables: &Tables) -> Result<()> {
    let frame: Frame = render.frame(tables)?;
    let mut settings = render.truth_settings();
    settings.target_noise = a.noise;
    settings.wavelengths_per_path = a.wavelengths_per_path;
    settings.max_scatterings = a.max_scatterings;
    let bar = crate::progress::SampleBar::new(a.quiet, settings.spp as u64);
    let truth = render::truth::render(tables, &frame, &settings, &bar)?;
    bar.finish();
    if !a.quiet {
        eprintln!(
            "path-traced truth: {}×{}, {} spp, noise {:.2} % (median relative standard error, green, volume pixels), {:.1} s, {:.3} M paths/s on {} threads",
            frame.width,
            frame.height,
            truth.spp,
            truth.noise * 100.0,
            truth.seconds,
            truth.paths_per_second / 1e6,
            rayon::current_num_threads()
        );
    }
    let extra = (0..3)
        .map(|c| {
            (
                format!("stderr.{}", ["R", "G", "B"][c]),
                truth.std_error.iter().map(|e| e[c]).collect(),
            )
        })
        .collect();
    write_outputs(a, render, &truth.image, extra)
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
