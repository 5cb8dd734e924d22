//! The path-traced truth on wgpu: the estimator of [`super`] (its module docs give the
//! transport, the equations and their sources) in `truth.wgsl`, one invocation per pixel, in
//! f32, progressive. Each pass traces a batch of samples per pixel; the host adds the pass's
//! Σ L and Σ L² into f64 sums, so the mean, the per-pixel standard error and the stopping rules
//! (`spp`, `noise`, `max_seconds`) are the CPU truth's.
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
//! - **Splitting** keeps its branches on a stack of [`STACK`] per invocation: a split makes
//!   k = ⌈n·W⌉ branches as on the CPU, but at most as many as the stack has room for. Any k ≥ 1
//!   chosen from the path's past keeps the estimator unbiased (each branch carries 1/k of the
//!   weight); a full stack only gives up some variance reduction.
//! - **f32**: the ratios p_m/p_0 of the carried wavelengths are products over every collision;
//!   after each free path f and p are divided by the mean p (the weights do not change), so that
//!   they stay inside f32's range in clouds of optical depth 100 (`renormalize` in the shader).
//! - **Software adapters**: llvmpipe (lavapipe) ends every loop of a shader invocation once
//!   the invocation has run 65535 loop iterations in all, so a long path (hundreds of
//!   scatterings in a cloud of optical depth 100) is silently cut short: measured on the soft
//!   ball at τ = 100, 30 % dark; a probe loop at the end of each invocation detects the cut and
//!   the pass fails, naming it. `render --model truth` runs the CPU truth on a software adapter
//!   (faster there too); the tests call this module on lavapipe with scenes inside the limit.
//! - **Not yet on the GPU**: `[[occluder]]` and `[[medium]]` (the lamp scenes of `--model
//!   biri`). A frame with them is traced by the CPU truth, and its summary says so.

use std::time::Instant;

use glam::DVec3;
use runtime::Tables;
use runtime::gpu::{Gpu, read_back};

use super::{Settings, Tracer, TruthImage, noise_of, std_error};
use crate::gpu::{
    RenderError, SLICING_WGSL, a4, check_sizes, entry, filled, slice_uniforms, storage, v4,
};
use crate::model::Progress;
use crate::{Frame, FrameError, Image, MAX_FIELDS};

/// The estimator's WGSL (after [`SLICING_WGSL`]).
pub const TRUTH_WGSL: &str = include_str!("truth.wgsl");

/// Branches one invocation keeps (module docs, "Splitting"); `STACK` in `truth.wgsl`.
pub const STACK: usize = 64;

/// θ bins per block of the two-level phase sampling; `BLOCK` in `truth.wgsl`.
const BLOCK: usize = 32;

/// Rows of vec4<f32> per wavelength band; `BAND_ROWS` in `truth.wgsl`.
const BAND_ROWS: usize = 2 + MAX_FIELDS;

/// Most samples per pixel in one pass (one dispatch each).
const MAX_BATCH: usize = 64;

/// A pass that took longer than this (s) is not followed by a larger one (a desktop driver
/// may reset a device whose dispatch runs for seconds).
const PASS_SECONDS: f64 = 0.5;

/// The whole shader module.
pub fn source() -> String {
    format!("{SLICING_WGSL}\n{TRUTH_WGSL}")
}

runtime::uniform! {
    /// `Params` of `truth.wgsl` (its comments say what each component holds).
    pub struct TruthParams as "Params" {
        /// View direction; w = tan(fov_y / 2).
        pub forward: [f32; 4],
        /// Right axis; w = aspect.
        pub right: [f32; 4],
        /// Up axis.
        pub up: [f32; 4],
        /// Width, height, first sample of the pass, samples in the pass.
        pub sizes: [u32; 4],
        /// Eye (m).
        pub eye: [f32; 4],
        /// The grid's box (m).
        pub grid_min: [f32; 4],
        /// The grid's box (m).
        pub grid_max: [f32; 4],
        /// Voxels per axis; w = fields.
        pub grid_dims: [u32; 4],
        /// σ_ext per field (m², per channel).
        pub sigma_ext: [[f32; 4]; MAX_FIELDS],
        /// w = the air's 1/H.
        pub sky_beta: [f32; 4],
        /// Towards the sun; w = cos of the disk's radius.
        pub sun: [f32; 4],
        /// Sun irradiance; w = the disk's solid angle.
        pub irradiance: [f32; 4],
        /// Background radiance; w = ground albedo.
        pub background: [f32; 4],
        /// Majorant, guide share, haze 1/H, transparency step.
        pub track: [f32; 4],
        /// Bands, carried wavelengths, max scatterings, lights.
        pub counts: [u32; 4],
        /// θ bins, haze field (u32::MAX: none), air on, blocks.
        pub counts2: [u32; 4],
        /// Seed low and high words, splitting on.
        pub seed: [u32; 4],
        /// θ step (rad).
        pub theta: [f32; 4],
    }
}

/// The pipelines, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    trace: wgpu::ComputePipeline,
    transparency: wgpu::ComputePipeline,
}

impl Renderer {
    /// Compiles `truth.wgsl` and builds its two pipelines (`trace`, `transparency`).
    pub fn new(gpu: &Gpu) -> Self {
        let device = &gpu.device;
        use wgpu::BufferBindingType::{Storage, Uniform};
        let entries: Vec<_> = (0..10)
            .map(|b| match b {
                0 => entry(0, Uniform, false),
                8 => entry(8, Uniform, true),
                6 | 7 | 9 => entry(b, Storage { read_only: false }, false),
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
        let pipeline = |name: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(name),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        Self {
            trace: pipeline("trace"),
            transparency: pipeline("transparency"),
            layout,
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

/// The tracer's optics as the shader's buffers: per band its rows, per (band, field) the
/// phase function's values and two-level CDF, per bin its (1 − cos θ, width).
struct Optics {
    bands: Vec<[f32; 4]>,
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
    let mut rows = Vec::new();
    let stride = 2 * bins + blocks;
    let mut phase = vec![0f32; tracer.bands.len() * MAX_FIELDS * stride];
    for (j, b) in tracer.bands.iter().enumerate() {
        rows.push([
            b.beta_air_sl as f32,
            b.haze_ext_sl as f32,
            b.haze_sca_sl as f32,
            tracer.band_cdf[j] as f32,
        ]);
        rows.push(a4(b.to_rgb, 0.0));
        for f in 0..MAX_FIELDS {
            let Some(o) = b.fields.get(f) else {
                rows.push([0.0; 4]);
                continue;
            };
            rows.push([
                o.sigma_ext as f32,
                o.albedo as f32,
                o.phase.delta() as f32,
                0.0,
            ]);
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
    }
    debug_assert_eq!(rows.len(), BAND_ROWS * tracer.bands.len());
    Optics {
        bands: rows,
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
        ],
    )?;
    let o = optics(tracer);
    let (forward, right, up) = frame
        .camera
        .axes()
        .ok_or_else(|| FrameError("camera look_at_m equals position_m".into()))?;
    let voxel = (0..3)
        .map(|a| (grid.max_m[a] - grid.min_m[a]) / grid.dims[a] as f64)
        .fold(f64::INFINITY, f64::min);
    let mut params = TruthParams {
        forward: v4(forward, frame.camera.tan_half_fov()),
        right: v4(right, w as f64 / h as f64),
        up: v4(up, 0.0),
        sizes: [w as u32, h as u32, 0, 0],
        eye: v4(frame.camera.position_m, 0.0),
        grid_min: v4(grid.min_m, 0.0),
        grid_max: v4(grid.max_m, 0.0),
        grid_dims: [
            grid.dims[0] as u32,
            grid.dims[1] as u32,
            grid.dims[2] as u32,
            tracer.n_fields as u32,
        ],
        sigma_ext: std::array::from_fn(|f| [0.0, tracer.sigma_ext_g[f] as f32, 0.0, 0.0]),
        sky_beta: [0.0, 0.0, 0.0, tracer.gamma as f32],
        sun: v4(tracer.sun, tracer.cos_disk),
        irradiance: a4(tracer.sun_irradiance, tracer.disk_sr),
        background: a4(tracer.background, tracer.ground_albedo),
        track: [
            tracer.majorant as f32,
            tracer.guide as f32,
            tracer.haze.map_or(0.0, |h| h.1) as f32,
            (0.25 * voxel) as f32,
        ],
        counts: [
            tracer.bands.len() as u32,
            tracer.wavelengths_per_path.clamp(1, super::MAX_CARRIED) as u32,
            tracer.max_scatterings.min(u32::MAX as usize) as u32,
            tracer.lights.len() as u32,
        ],
        counts2: [
            o.bins as u32,
            tracer.haze.map_or(u32::MAX, |h| h.0 as u32),
            u32::from(tracer.air_on),
            o.blocks as u32,
        ],
        seed: [settings.seed as u32, (settings.seed >> 32) as u32, 1, 0],
        theta: [tracer.bands[0].fields[0].phase.step() as f32, 0.0, 0.0, 0.0],
    };
    let light_rows: Vec<[f32; 4]> = tracer
        .lights
        .iter()
        .flat_map(|l| {
            let (axis, cos) = l
                .spot
                .map_or((DVec3::Y, -2.0), |(a, half)| (a, half.to_radians().cos()));
            [
                v4(l.position_m, if l.spot.is_some() { 1.0 } else { 0.0 }),
                a4(l.intensity, 0.0),
                v4(axis, cos),
            ]
        })
        .collect();

    let usage = wgpu::BufferUsages::STORAGE;
    let nonempty = |b: &[u8]| -> Vec<u8> {
        if b.is_empty() {
            vec![0; 16]
        } else {
            b.to_vec()
        }
    };
    let params_buffer = filled(
        device,
        "truth params",
        bytemuck::bytes_of(&params),
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
    let lights = filled(
        device,
        "truth lights",
        &nonempty(bytemuck::cast_slice(&light_rows)),
        usage,
    );
    let sums = storage(device, "truth sums", 32 * pixels, true);
    let transparency = storage(device, "truth transparency", 4 * pixels.max(4), true);
    // One uniform per sample of a pass (its index), read at a dynamic offset.
    let (samples, stride) = slice_uniforms(device, &[0.0; MAX_BATCH]);
    let cut = filled(
        device,
        "truth cut paths",
        &[0; 16],
        usage | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
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
        &samples,
        &cut,
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
    // `count` dispatches of `pipeline`, the k-th with sample uniform k, in one compute pass
    // (wgpu orders their storage writes).
    let dispatch = |pipeline: &wgpu::ComputePipeline, count: usize| {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("photometeor truth pass"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("photometeor truth pass"),
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            for k in 0..count {
                pass.set_bind_group(0, &bind_group, &[(k * stride) as u32]);
                pass.dispatch_workgroups(w.div_ceil(8) as u32, h.div_ceil(8) as u32, 1);
            }
        }
        gpu.queue.submit([encoder.finish()]);
    };

    dispatch(&renderer.transparency, 1);
    let t_vol: Vec<f64> = read_back(gpu, &transparency, 4 * pixels.max(4))?
        .into_iter()
        .flatten()
        .take(pixels as usize)
        .map(f64::from)
        .collect();

    let mut acc = vec![([0.0f64; 3], [0.0f64; 3]); pixels as usize];
    let start = Instant::now();
    let mut done = 0usize;
    let mut noise = f64::INFINITY;
    let mut last = (0usize, 0.0f64);
    while done < settings.spp {
        // Passes of 1, 1, 2, 4, … samples (at most 64), as the CPU truth's, but none larger
        // than the last once a pass takes PASS_SECONDS.
        let mut batch = done.clamp(1, MAX_BATCH).min(settings.spp - done);
        if last.1 > PASS_SECONDS {
            batch = batch.min(last.0.max(1));
        }
        params.sizes[2] = done as u32;
        params.sizes[3] = batch as u32;
        gpu.queue
            .write_buffer(&params_buffer, 0, bytemuck::bytes_of(&params));
        gpu.queue.write_buffer(&cut, 0, &[0; 16]);
        let pass_start = Instant::now();
        dispatch(&renderer.trace, batch);
        let rows = read_back(gpu, &sums, 32 * pixels)?;
        let cut_paths = read_back(gpu, &cut, 16)?[0][0].to_bits();
        if cut_paths > 0 {
            return Err(FrameError(format!(
                "the GPU adapter ({}) cut {cut_paths} paths short: it ends a shader's loops after \
                 a fixed number of iterations (llvmpipe: 65535), fewer than a path through this \
                 scene takes; render with --cpu",
                gpu.describe()
            ))
            .into());
        }
        last = (batch, pass_start.elapsed().as_secs_f64());
        for (p, a) in acc.iter_mut().enumerate() {
            let (s, q) = (rows[2 * p], rows[2 * p + 1]);
            for c in 0..3 {
                a.0[c] += f64::from(s[c]);
                a.1[c] += f64::from(q[c]);
            }
        }
        done += batch;
        noise = noise_of(&acc, done, &t_vol);
        progress.update(
            done as u64,
            settings.spp as u64,
            &format!("noise {:.2} %", noise * 100.0),
        );
        if settings.target_noise > 0.0 && noise <= settings.target_noise {
            break;
        }
        if settings.max_seconds > 0.0 && start.elapsed().as_secs_f64() >= settings.max_seconds {
            break;
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let n = done as f64;
    Ok(TruthImage {
        image: Image {
            width: w,
            height: h,
            rgb: acc.iter().map(|(s, _)| s.map(|v| (v / n) as f32)).collect(),
            transparency: t_vol.iter().map(|&t| t as f32).collect(),
        },
        std_error: acc
            .iter()
            .map(|(s, q)| std::array::from_fn(|c| std_error(s[c], q[c], n) as f32))
            .collect(),
        spp: done,
        noise,
        seconds,
        paths_per_second: pixels as f64 * n / seconds.max(1e-9),
    })
}
