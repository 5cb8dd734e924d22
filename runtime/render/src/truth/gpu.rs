//! The path-traced truth on wgpu: the estimator of [`super`] (its module docs give the
//! transport, the equations and their sources: delta tracking, hero wavelengths with the
//! balance heuristic, next-event estimation; docs/truth.md and docs/physics.md §9) in
//! `truth.wgsl`, in f32, progressive. Each pass
//! takes a batch of samples per pixel; the host adds the pass's Σ L and Σ L² into f64 sums, so
//! the mean, the per-pixel standard error and the stopping rules (`spp`, `noise`,
//! `max_seconds`) are the CPU truth's.
//!
//! **Resumable paths.** One invocation per pixel of a tile (at most [`TILE_PIXELS`]) follows its
//! pixel's samples one after the other, but stops between events after about
//! [`STEPS_PER_DISPATCH`] loop steps and saves its path (the branch, the split branches waiting
//! on its stack, the random stream's counter, the radiance so far) for the next dispatch; the
//! host dispatches until no path of the tile is under way. So no dispatch runs for long (a
//! desktop driver resets a device busy for seconds), and no invocation passes llvmpipe's limit
//! of 65535 loop iterations, after which lavapipe silently ends every loop of the invocation
//! (found here: a path traced after 60 000 dummy loop iterations in the same invocation kept
//! 15 % of its light, after 70 000 none; tracing whole paths in one invocation made the soft
//! ball at τ = 100 30 % dark). A probe loop at the end of each invocation still detects such a
//! cut, and the render fails naming it. Where the image is cut between dispatches does not
//! change it: the same seed gives the same image.
//!
//! What differs from the CPU truth, and why it is the same estimator:
//! - **Random numbers** are counter-based: each (seed, pixel, sample) gets two 32-bit keys
//!   from an integer hash, and the i-th number of the stream hashes the counter with them. An
//!   image depends on the seed alone, on any adapter, up to float rounding; it is not the CPU
//!   truth's image for the same seed (SplitMix64 there): the two agree within their noise.
//! - **Phase sampling** draws a block of 32 θ bins by the blocks' CDF, then a bin by the
//!   block's own CDF, then cos θ uniformly inside it: the same distribution as the CPU's one
//!   inverse CDF, with each level's CDF relative so that f32 keeps a rare backscatter bin's
//!   probability (a single f32 CDF over 1001 bins resolves only 6·10⁻⁸ of probability near 1).
//! - **Splitting** keeps its branches on a stack of [`STACK`] per pixel (in the path state): a
//!   split makes k = ⌈n·W⌉ branches as on the CPU, but at most as many as the stack has room
//!   for. Any k ≥ 1
//!   chosen from the path's past keeps the estimator unbiased (each branch carries 1/k of the
//!   weight); a full stack only gives up some variance reduction.
//! - **f32**: the ratios p_m/p_0 of the carried wavelengths are products over every collision;
//!   after each free path f and p are divided by the mean p (the weights do not change), so that
//!   they stay inside f32's range in clouds of optical depth 100 (`renormalize` in the shader).
//! - **Not yet on the GPU**: `[[occluder]]` and `[[medium]]` (the lamp scenes of `--model
//!   biri`). A frame with them is traced by the CPU truth, and its summary says so.

use std::time::Instant;

use glam::DVec3;
use runtime::Tables;
use runtime::gpu::{Gpu, read_back};

use super::{Passes, Settings, Tracer, TruthImage};
use crate::checks::FrameError;
use crate::frame::Frame;
use crate::gpu::{
    Grid, RenderError, SLICING_WGSL, Sky, View, a3, a4, check_sizes, entry, filled, storage,
    submit_pass, v3, v4,
};
use crate::model::Progress;
use crate::volume::{DensityGrid, MAX_FIELDS};

/// The estimator's WGSL (after [`SLICING_WGSL`]).
pub const TRUTH_WGSL: &str = include_str!("truth.wgsl");

/// Branches one pixel's path keeps waiting (module docs, "Splitting"); `STACK` in `truth.wgsl`.
pub const STACK: usize = 8;

/// θ bins per block of the two-level phase sampling; `BLOCK` in `truth.wgsl`.
const BLOCK: usize = 32;

runtime::uniform! {
    /// `Light` of `truth.wgsl`: a point or spot light.
    pub struct Light as "Light" {
        /// Its position (m); w: 1 for a spot, 0 for a point light.
        pub position: [f32; 4],
        /// Its intensity per channel, 0.
        pub intensity: [f32; 4],
        /// A spot's axis; w: the cosine of its half-angle (−2 for a point light).
        pub axis: [f32; 4],
    }
}

runtime::uniform! {
    /// `Band` of `truth.wgsl`: one wavelength band's optics.
    pub struct Band as "Band" {
        /// β_air at sea level (1/m), the haze's N₀σ_ext and N₀σ_sca (1/m), the band's CDF of q.
        pub air: [f32; 4],
        /// The band's w_c/q per channel, 0.
        pub to_rgb: [f32; 4],
        /// Per field: σ_ext (m²), the albedo, the forward δ's weight, 0.
        pub fields: [[f32; 4]; MAX_FIELDS],
    }
}

runtime::uniform! {
    /// `SavedBranch` of `truth.wgsl`: a path's point, direction and carried wavelengths (the
    /// one under way, or a branch a split left waiting on its stack).
    pub struct SavedBranch as "SavedBranch" {
        /// The carried wavelengths' f_m.
        pub f: [f32; 4],
        /// Their r_m.
        pub r: [f32; 4],
        /// The position (m), 0.
        pub position: [f32; 4],
        /// The direction, 0.
        pub direction: [f32; 4],
        /// The carried wavelengths' bands.
        pub band: [u32; 4],
        /// Wavelengths carried, the bounce; the path under way's stack top and whether it is
        /// alive (a waiting branch's 0, 0).
        pub counts: [u32; 4],
    }
}

runtime::uniform! {
    /// `SavedPath` of `truth.wgsl`: a tile slot's path between dispatches (GPU memory only;
    /// its size sizes the buffer).
    pub struct SavedPath as "SavedPath" {
        /// The path under way.
        pub head: SavedBranch,
        /// The radiance gathered so far per channel, 0.
        pub sum: [f32; 4],
        /// The random stream's two keys and counter, the sample within the pass.
        pub stream: [u32; 4],
        /// The branches waiting.
        pub stack: [SavedBranch; STACK],
    }
}

/// Pixels whose paths are under way at once (their state: a [`SavedPath`], 896 bytes each).
const TILE_PIXELS: usize = 1 << 16;

/// Loop steps one invocation takes per dispatch before it saves its path for the next: each
/// free-path or transmittance step counts 1 and each event 64 (`EVENT_STEPS`, its own small
/// loops), so that an invocation stays well inside llvmpipe's 65535 loop iterations.
const STEPS_PER_DISPATCH: usize = 8000;

/// Dispatches per submission (the host then reads how many paths are still under way).
const DISPATCHES_PER_SUBMIT: usize = 8;

/// A pass that took longer than this (s) is not followed by a larger one (a desktop driver
/// may reset a device whose dispatch runs for seconds).
const PASS_SECONDS: f64 = 0.5;

/// The whole shader module.
pub fn source() -> String {
    format!("{SLICING_WGSL}\n{TRUTH_WGSL}")
}

runtime::uniform! {
    /// `Track` of `truth.wgsl`: the tracker's scalars (a record of their own: as separate
    /// fields of [`TruthParams`], lavapipe's paths ran 5.7× slower on the cumulus at dawn).
    pub struct Track as "Track" {
        /// The majorant (1/m).
        pub majorant: f32,
        /// The guide share ε.
        pub guide_share: f32,
        /// The haze's 1/H (1/m).
        pub inv_haze_height: f32,
        /// T_vol's step (m).
        pub transparency_step: f32,
    }
}

runtime::uniform! {
    /// `Counts` of `truth.wgsl`.
    pub struct Counts as "Counts" {
        /// Bands.
        pub bands: u32,
        /// Wavelengths carried per path.
        pub carried: u32,
        /// Max scatterings.
        pub max_scatterings: u32,
        /// Lights.
        pub lights: u32,
    }
}

runtime::uniform! {
    /// `TableSizes` of `truth.wgsl`.
    pub struct TableSizes as "TableSizes" {
        /// θ bins.
        pub theta_bins: u32,
        /// The haze's field (u32::MAX: none).
        pub haze_field: u32,
        /// 1: the air scatters.
        pub air_on: u32,
        /// The phase sampling's blocks.
        pub blocks: u32,
    }
}

runtime::uniform! {
    /// `Stream` of `truth.wgsl`: the random streams.
    pub struct Stream as "Stream" {
        /// The seed's low word.
        pub seed_low: u32,
        /// Its high word.
        pub seed_high: u32,
        /// 1: splitting on.
        pub splitting: u32,
        /// Padding.
        pub pad: u32,
    }
}

runtime::uniform! {
    /// `Stepping` of `truth.wgsl`.
    pub struct Stepping as "Stepping" {
        /// The θ bins' step (rad).
        pub theta_step: f32,
        /// Loop steps per dispatch.
        pub loop_budget: f32,
        /// Padding.
        pub pad0: f32,
        /// Padding.
        pub pad1: f32,
    }
}

runtime::uniform! {
    /// `Tile` of `truth.wgsl`: the pixels of one dispatch.
    pub struct Tile as "Tile" {
        /// The first pixel.
        pub first: u32,
        /// The pixel count.
        pub pixels: u32,
        /// Padding.
        pub pad0: u32,
        /// Padding.
        pub pad1: u32,
    }
}

runtime::uniform! {
    /// `Params` of `truth.wgsl`.
    pub struct TruthParams as "Params" {
        /// The camera (photons: their source as the eye, their direction as forward).
        pub view: View,
        /// Width, height.
        pub sizes: [u32; 2],
        /// The pass's first sample.
        pub first_sample: u32,
        /// The pass's samples.
        pub samples: u32,
        /// The grid and the ground.
        pub grid: Grid,
        /// σ_ext per field (m², per channel; the transparency uses green).
        pub sigma_ext: [[f32; 4]; MAX_FIELDS],
        /// The sun and the air (its β unused here).
        pub sky: Sky,
        /// The radiance of what paths leave into.
        pub background: [f32; 3],
        /// Padding.
        pub pad0: f32,
        /// The tracker's scalars.
        pub track: Track,
        /// The counts of bands, wavelengths, scatterings and lights.
        pub counts: Counts,
        /// The tables' sizes and switches.
        pub tables: TableSizes,
        /// The random streams.
        pub stream: Stream,
        /// The θ step and the loop budget.
        pub stepping: Stepping,
        /// The tile of this dispatch.
        pub tile: Tile,
    }
}

runtime::uniform! {
    /// `Step` of `truth.wgsl`: one per dispatch, at a dynamic offset.
    pub struct StepParams as "Step" {
        /// 1: the dispatch begins a sample.
        pub begin: u32,
        /// 1: it counts the paths still under way after it.
        pub count: u32,
        /// Padding.
        pub pad0: u32,
        /// Padding.
        pub pad1: u32,
    }
}

/// The pipelines, built once: those of bounded grids at once, those of periodic ones
/// (`periodic` true in the shader, a constant so that a bounded grid's loops carry no trace
/// of it: as a uniform's branch it made them 5× slower on lavapipe) when first needed.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    module: wgpu::ShaderModule,
    pipeline_layout: wgpu::PipelineLayout,
    bounded: Pipelines,
    periodic: std::sync::OnceLock<Pipelines>,
}

/// The passes' pipelines for one value of the shader's `periodic`.
struct Pipelines {
    step: wgpu::ComputePipeline,
    photon: wgpu::ComputePipeline,
    transparency: wgpu::ComputePipeline,
}

impl Pipelines {
    fn new(
        device: &wgpu::Device,
        module: &wgpu::ShaderModule,
        layout: &wgpu::PipelineLayout,
        periodic: bool,
    ) -> Self {
        let pipeline = |name: &str, photon: bool| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: Some(layout),
                module,
                entry_point: Some(name),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &[
                        ("photon_mode", f64::from(u8::from(photon))),
                        ("periodic", f64::from(u8::from(periodic))),
                    ],
                    ..Default::default()
                },
                cache: None,
            })
        };
        Self {
            step: pipeline("step", false),
            photon: pipeline("step", true),
            transparency: pipeline("transparency", false),
        }
    }
}

impl Renderer {
    /// Compiles `truth.wgsl` and builds its two pipelines (`trace`, `transparency`).
    pub fn new(gpu: &Gpu) -> Self {
        let device = &gpu.device;
        use wgpu::BufferBindingType::{Storage, Uniform};
        let entries: Vec<_> = (0..11)
            .map(|b| match b {
                0 => entry(0, Uniform, false),
                8 => entry(8, Uniform, true),
                6 | 7 | 9 | 10 => entry(b, Storage { read_only: false }, false),
                b => entry(b, Storage { read_only: true }, false),
            })
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("photometeor truth layout"),
            entries: &entries,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("photometeor truth"),
            source: wgpu::ShaderSource::Wgsl(source().into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("photometeor truth pipeline layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        Self {
            bounded: Pipelines::new(device, &module, &pipeline_layout, false),
            periodic: std::sync::OnceLock::new(),
            layout,
            module,
            pipeline_layout,
        }
    }

    /// The pipelines for a grid that repeats (`periodic`) or not.
    fn pipelines(&self, gpu: &Gpu, periodic: bool) -> &Pipelines {
        if periodic {
            self.periodic.get_or_init(|| {
                Pipelines::new(&gpu.device, &self.module, &self.pipeline_layout, true)
            })
        } else {
            &self.bounded
        }
    }
}

/// Why a frame cannot be traced on the GPU yet (module docs), or `None`.
pub fn unsupported(frame: &Frame) -> Option<&'static str> {
    if !frame.occluders.is_empty() {
        Some("[[occluder]]")
    } else if !frame.media.is_empty() {
        Some("[[medium]]")
    } else {
        None
    }
}

/// The tracer's optics as the shader's buffers: per band its [`Band`], per (band, field) the
/// phase function's values and two-level CDF, per bin its (1 − cos θ, width).
struct Optics {
    bands: Vec<Band>,
    phase: Vec<f32>,
    bin_mu: Vec<[f32; 2]>,
    bins: usize,
    blocks: usize,
}

fn optics(tracer: &Tracer) -> Optics {
    let first = &tracer.bands[0].fields[0].phase;
    let bins = first.len();
    let blocks = bins.div_ceil(BLOCK);
    let bin_mu: Vec<[f32; 2]> = (0..bins)
        .map(|k| {
            let (lo, width) = first.bin_mu(k);
            [lo as f32, width as f32]
        })
        .collect();
    let mut bands = Vec::with_capacity(tracer.bands.len());
    let stride = 2 * bins + blocks;
    let mut phase = vec![0f32; tracer.bands.len() * MAX_FIELDS * stride];
    for (j, b) in tracer.bands.iter().enumerate() {
        let mut band = Band {
            air: [
                b.beta_air_sl as f32,
                b.haze_ext_sl as f32,
                b.haze_sca_sl as f32,
                tracer.band_cdf[j] as f32,
            ],
            to_rgb: a4(b.to_rgb, 0.0),
            fields: [[0.0; 4]; MAX_FIELDS],
        };
        for (f, o) in b.fields.iter().enumerate().take(MAX_FIELDS) {
            band.fields[f] = [
                o.sigma_ext as f32,
                o.albedo as f32,
                o.phase.delta() as f32,
                0.0,
            ];
            let out = &mut phase[(j * MAX_FIELDS + f) * stride..][..stride];
            // Each bin's probability in the smooth part, p_k Ω_k.
            let prob: Vec<f64> = (0..bins).map(|k| o.phase.probability(k)).collect();
            let total: f64 = prob.iter().sum();
            let mut acc_blocks = 0.0;
            for (block, chunk) in prob.chunks(BLOCK).enumerate() {
                let in_block: f64 = chunk.iter().sum();
                let mut acc = 0.0;
                for (i, p) in chunk.iter().enumerate() {
                    acc += p;
                    let k = block * BLOCK + i;
                    out[bins + k] = if in_block > 0.0 {
                        (acc / in_block) as f32
                    } else {
                        1.0
                    };
                }
                out[bins + block * BLOCK + chunk.len() - 1] = 1.0;
                acc_blocks += in_block;
                out[2 * bins + block] = if total > 0.0 {
                    (acc_blocks / total) as f32
                } else {
                    1.0
                };
            }
            out[2 * bins + blocks - 1] = 1.0;
            for (k, v) in out[..bins].iter_mut().enumerate() {
                *v = o.phase.value(k) as f32;
            }
        }
        bands.push(band);
    }
    Optics {
        bands,
        phase,
        bin_mu,
        bins,
        blocks,
    }
}

/// Traces `frame` on the GPU (module docs): the same result type, checks and stopping rules
/// as [`super::render`].
pub fn render(
    renderer: &Renderer,
    gpu: &Gpu,
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn Progress,
) -> Result<TruthImage, RenderError> {
    super::check(frame, settings)?;
    let tracer = Tracer::new(tables, frame, settings)?;
    render_with(renderer, gpu, &tracer, frame, settings, progress)
}

/// [`render`] with a tracer made (and perhaps changed, as the white-furnace test does) by the
/// caller from the same frame.
pub fn render_with(
    renderer: &Renderer,
    gpu: &Gpu,
    tracer: &Tracer,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn Progress,
) -> Result<TruthImage, RenderError> {
    trace(renderer, gpu, tracer, frame, settings, progress, None)
}

/// Photons walking forward from `origin` along `beam` (as [`Tracer::photon`]: one wavelength,
/// plain phase sampling, no splitting), `settings.spp` per cell of a 64 × 64 grid of streams:
/// the mean weight leaving upwards and leaving downwards off the beam's direction (a slab's R
/// and diffuse T per unit incident flux along the beam), each with its standard error.
pub fn photon_fluxes(
    renderer: &Renderer,
    gpu: &Gpu,
    tracer: &Tracer,
    frame: &Frame,
    (origin, beam): (DVec3, DVec3),
    settings: &Settings,
) -> Result<[(f64, f64); 2], RenderError> {
    let mut frame = frame.clone();
    (frame.width, frame.height) = (64, 64);
    let image = trace(
        renderer,
        gpu,
        tracer,
        &frame,
        settings,
        &(),
        Some((origin, beam)),
    )?;
    let n = image.image.rgb.len() as f64;
    Ok(std::array::from_fn(|c| {
        let mean = image.image.rgb.iter().map(|p| f64::from(p[c])).sum::<f64>() / n;
        let var: f64 = image
            .std_error
            .iter()
            .map(|e| f64::from(e[c]).powi(2))
            .sum();
        (mean, var.sqrt() / n)
    }))
}

/// The uniform of the passes: the camera (or with `photon` = (origin, direction) the photons'
/// source), the grid, the sun, the sky and the counts of `tracer`, the optics' sizes `o`.
fn params(
    tracer: &Tracer,
    frame: &Frame,
    settings: &Settings,
    o: &Optics,
    photon: Option<(DVec3, DVec3)>,
) -> Result<TruthParams, RenderError> {
    let (w, h) = (frame.width, frame.height);
    let grid = &frame.grid;
    let axes = frame
        .camera
        .axes()
        .ok_or_else(|| FrameError("camera look_at_m equals position_m".into()))?;
    let voxel = (0..3)
        .map(|a| (grid.max_m[a] - grid.min_m[a]) / grid.dims[a] as f64)
        .fold(f64::INFINITY, f64::min);
    let mut view = View::of(frame, axes);
    if let Some((origin, beam)) = photon {
        (view.eye, view.forward) = (v3(origin), v3(beam));
    }
    Ok(TruthParams {
        view,
        sizes: [w as u32, h as u32],
        first_sample: 0,
        samples: 0,
        grid: Grid::of(frame, tracer.n_fields),
        sigma_ext: std::array::from_fn(|f| [0.0, tracer.sigma_ext_g[f] as f32, 0.0, 0.0]),
        sky: Sky::of(frame),
        background: a3(tracer.background),
        pad0: 0.0,
        track: Track {
            majorant: tracer.majorant as f32,
            guide_share: tracer.guide as f32,
            inv_haze_height: tracer.haze.map_or(0.0, |h| h.1) as f32,
            transparency_step: (0.25 * voxel) as f32,
        },
        counts: Counts {
            bands: tracer.bands.len() as u32,
            carried: tracer.wavelengths_per_path.clamp(1, super::MAX_CARRIED) as u32,
            max_scatterings: tracer.max_scatterings.min(u32::MAX as usize) as u32,
            lights: tracer.lights.len() as u32,
        },
        tables: TableSizes {
            theta_bins: o.bins as u32,
            haze_field: tracer.haze.map_or(u32::MAX, |h| h.0 as u32),
            air_on: u32::from(tracer.air_on),
            blocks: o.blocks as u32,
        },
        stream: Stream {
            seed_low: settings.seed as u32,
            seed_high: (settings.seed >> 32) as u32,
            splitting: 1,
            pad: 0,
        },
        stepping: Stepping {
            theta_step: tracer.bands[0].fields[0].phase.step() as f32,
            loop_budget: STEPS_PER_DISPATCH as f32,
            pad0: 0.0,
            pad1: 0.0,
        },
        tile: Tile::default(),
    })
}

/// The tracer's lights as the shader's [`Light`]s.
fn lights(tracer: &Tracer) -> Vec<Light> {
    tracer
        .lights
        .iter()
        .map(|l| {
            let (axis, cos) = l
                .spot
                .map_or((DVec3::Y, -2.0), |(a, half)| (a, half.to_radians().cos()));
            Light {
                position: v4(l.position_m, if l.spot.is_some() { 1.0 } else { 0.0 }),
                intensity: a4(l.intensity, 0.0),
                axis: v4(axis, cos),
            }
        })
        .collect()
}

/// The passes' buffers, bound.
struct Bound {
    /// The uniform ([`TruthParams`]), rewritten per tile.
    params: wgpu::Buffer,
    /// Per pixel the sums of the samples and of their squares.
    sums: wgpu::Buffer,
    /// Per pixel T_vol.
    transparency: wgpu::Buffer,
    /// The paths cut short and the paths still under way.
    counters: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// The bytes between the four [`StepParams`] (the dispatches' dynamic offsets).
    step_stride: usize,
    /// The grid repeats in x and z: the periodic pipelines.
    periodic: bool,
}

/// The passes' buffers for `params`, the `tracer`'s optics `o`, the `grid` and `pixels`
/// pixels, bound to the renderer's layout.
fn bind(
    renderer: &Renderer,
    device: &wgpu::Device,
    params: &TruthParams,
    (tracer, o): (&Tracer, &Optics),
    grid: &DensityGrid,
    pixels: u64,
) -> Bound {
    // A binding holds at least one record: a scene without lights binds one zero light (the
    // shader reads rp.counts.w of them, none).
    let mut lights = lights(tracer);
    if lights.is_empty() {
        lights.push(Light::default());
    }
    let usage = wgpu::BufferUsages::STORAGE;
    let params_buffer = filled(
        device,
        "truth params",
        bytemuck::bytes_of(params),
        wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    );
    let density = filled(
        device,
        "truth densities",
        bytemuck::cast_slice(&grid.data),
        usage,
    );
    let bands = filled(device, "truth bands", bytemuck::cast_slice(&o.bands), usage);
    let phase = filled(device, "truth phase", bytemuck::cast_slice(&o.phase), usage);
    let bin_mu = filled(device, "truth bins", bytemuck::cast_slice(&o.bin_mu), usage);
    let lights = filled(device, "truth lights", bytemuck::cast_slice(&lights), usage);
    let sums = storage(device, "truth sums", 32 * pixels, true);
    let transparency = storage(device, "truth transparency", 4 * pixels.max(4), true);
    // The four kinds of dispatch (begin or continue, count or not), read at a dynamic offset.
    let step_stride = device.limits().min_uniform_buffer_offset_alignment.max(16) as usize;
    let mut step_bytes = vec![0u8; 4 * step_stride];
    for (i, (begin, count)) in [(1, 0), (0, 0), (0, 1), (1, 1)].into_iter().enumerate() {
        let u = StepParams {
            begin,
            count,
            ..Default::default()
        };
        step_bytes[i * step_stride..][..16].copy_from_slice(bytemuck::bytes_of(&u));
    }
    let steps = filled(
        device,
        "truth steps",
        &step_bytes,
        wgpu::BufferUsages::UNIFORM,
    );
    let counters = filled(
        device,
        "truth counters",
        &[0; 16],
        usage | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
    );
    let tile = TILE_PIXELS.min(pixels as usize);
    let saved = storage(
        device,
        "truth path state",
        (std::mem::size_of::<SavedPath>() * tile) as u64,
        false,
    );
    let buffers = [
        &params_buffer,
        &density,
        &bands,
        &phase,
        &bin_mu,
        &lights,
        &sums,
        &transparency,
        &steps,
        &counters,
        &saved,
    ];
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("photometeor truth bindings"),
        layout: &renderer.layout,
        entries: &buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: if i == 8 {
                    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: b,
                        offset: 0,
                        size: wgpu::BufferSize::new(16),
                    })
                } else {
                    b.as_entire_binding()
                },
            })
            .collect::<Vec<_>>(),
    });
    Bound {
        params: params_buffer,
        sums,
        transparency,
        counters,
        bind_group,
        step_stride,
        periodic: grid.periodic,
    }
}

impl Bound {
    /// The transparency pass: one dispatch over the image of `w` × `h` pixels.
    fn transparency_pass(&self, gpu: &Gpu, renderer: &Renderer, (w, h): (usize, usize)) {
        submit_pass(gpu, "photometeor truth transparency", |pass| {
            pass.set_pipeline(&renderer.pipelines(gpu, self.periodic).transparency);
            pass.set_bind_group(0, &self.bind_group, &[0]);
            pass.dispatch_workgroups(w.div_ceil(8) as u32, h.div_ceil(8) as u32, 1);
        });
    }

    /// DISPATCHES_PER_SUBMIT steps of the paths (the photons' with `photon`) of a tile of
    /// `len` pixels, the first beginning a sample if `begin`, the last counting the paths
    /// still under way.
    fn steps(&self, gpu: &Gpu, renderer: &Renderer, photon: bool, (len, begin): (usize, bool)) {
        submit_pass(gpu, "photometeor truth steps", |pass| {
            let pipelines = renderer.pipelines(gpu, self.periodic);
            pass.set_pipeline(if photon {
                &pipelines.photon
            } else {
                &pipelines.step
            });
            for i in 0..DISPATCHES_PER_SUBMIT {
                let last = i + 1 == DISPATCHES_PER_SUBMIT;
                let kind = match (begin && i == 0, last) {
                    (true, false) => 0,
                    (false, false) => 1,
                    (false, true) => 2,
                    (true, true) => 3,
                };
                pass.set_bind_group(0, &self.bind_group, &[(kind * self.step_stride) as u32]);
                pass.dispatch_workgroups(len.div_ceil(64) as u32, 1, 1);
            }
        });
    }
}

/// The passes: camera paths through `frame`'s pixels, or with `photon` = (origin, direction)
/// photons walking forward, one stream per pixel.
fn trace(
    renderer: &Renderer,
    gpu: &Gpu,
    tracer: &Tracer,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn Progress,
    photon: Option<(DVec3, DVec3)>,
) -> Result<TruthImage, RenderError> {
    if let Some(what) = unsupported(frame) {
        return Err(FrameError(format!(
            "the GPU truth does not trace {what} yet: render with --cpu"
        ))
        .into());
    }
    let device = &gpu.device;
    let (w, h) = (frame.width, frame.height);
    let pixels = (w * h) as u64;
    let grid = &frame.grid;
    check_sizes(
        device,
        &[
            ("density grid bytes", 16 * grid.data.len() as u64),
            ("per-pixel sums bytes", 32 * pixels),
            (
                "path state bytes",
                (std::mem::size_of::<SavedPath>() * TILE_PIXELS.min(pixels as usize)) as u64,
            ),
        ],
    )?;
    let o = optics(tracer);
    let mut params = params(tracer, frame, settings, &o, photon)?;
    let bound = bind(renderer, device, &params, (tracer, &o), grid, pixels);
    bound.transparency_pass(gpu, renderer, (w, h));
    let t_vol: Vec<f64> = read_back(gpu, &bound.transparency, 4 * pixels.max(4))?
        .into_iter()
        .flatten()
        .take(pixels as usize)
        .map(f64::from)
        .collect();

    let mut passes = Passes::new(settings, w, t_vol, progress);
    let mut last = (0usize, 0.0f64);
    // As the CPU truth's passes, but none larger than the last once a pass takes PASS_SECONDS.
    while let Some(batch) = passes.next_batch((last.1 > PASS_SECONDS).then_some(last.0)) {
        let done = passes.done;
        let pass_start = Instant::now();
        for first in (0..pixels as usize).step_by(TILE_PIXELS) {
            let len = TILE_PIXELS.min(pixels as usize - first);
            params.tile = Tile {
                first: first as u32,
                pixels: len as u32,
                ..Tile::default()
            };
            params.first_sample = done as u32;
            params.samples = batch as u32;
            gpu.queue
                .write_buffer(&bound.params, 0, bytemuck::bytes_of(&params));
            let mut begin = true;
            loop {
                gpu.queue.write_buffer(&bound.counters, 4, &[0; 4]);
                bound.steps(gpu, renderer, photon.is_some(), (len, begin));
                begin = false;
                let c = read_back(gpu, &bound.counters, 16)?[0];
                let cut_paths = c[0].to_bits();
                if cut_paths > 0 {
                    return Err(FrameError(format!(
                        "the GPU adapter ({}) cut {cut_paths} paths short: it ends a shader's \
                         loops after a fixed number of iterations (llvmpipe: 65535); render \
                         with --cpu",
                        gpu.describe()
                    ))
                    .into());
                }
                if c[1].to_bits() == 0 {
                    break;
                }
            }
        }
        let rows = read_back(gpu, &bound.sums, 32 * pixels)?;
        last = (batch, pass_start.elapsed().as_secs_f64());
        for (p, a) in passes.acc.iter_mut().enumerate() {
            let (s, q) = (rows[2 * p], rows[2 * p + 1]);
            for c in 0..3 {
                a.0[c] += f64::from(s[c]);
                a.1[c] += f64::from(q[c]);
            }
            a.2 += f64::from(q[3]);
            passes.dropped += s[3] as u64;
        }
        if passes.end_pass(batch) {
            break;
        }
    }
    Ok(passes.image())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sizes the host lays buffers out by are the shader's.
    #[test]
    fn the_host_and_the_shader_agree_on_the_layout() {
        for (name, value) in [
            ("STACK", STACK),
            ("BLOCK", BLOCK),
            ("MAX_FIELDS", MAX_FIELDS),
        ] {
            let line = format!("const {name}: u32 = {value}u;");
            assert!(TRUTH_WGSL.contains(&line), "truth.wgsl lacks {line:?}");
        }
    }
}
