//! The transport's source iteration kept on the GPU: the sweeps' moments, the acceleration's
//! diffusion solves and the convergence test's sums stay in GPU buffers from round to round,
//! and a round sends nothing up and reads back only the solves' scalars and the change's
//! partial sums. The moments come back when the caller asks for them ([`Resident::moments`]:
//! once at the end of a relight's call, not once a round).
//!
//! A round (as [`super::transport::iterate`] with coupled's acceleration, in f32):
//! 1. the sweeps from the moments into `next` ([`super::transport_gpu`]);
//! 2. per channel, the acceleration's right-hand side h³ σ′_s Δφ_00 / √(4π) formed in the
//!    diffusion solver's own vectors (`resident.wgsl`'s `source`), the solve of the round's
//!    error by conjugate gradients on the GPU ([`super::diffusion_gpu`], f32 to
//!    [`super::diffusion_gpu::INNER_TOLERANCE`]), and the correction √(4π) e added to the new
//!    φ_00 (`correct`);
//! 3. the relative change of the green φ_00 summed per workgroup (`change`), and the new
//!    moments copied over the old.
//!
//! Where it departs from the CPU's iteration: the acceleration's solve stops at the inner
//! solve's relative residual of 10⁻³ (f32) without the f64 refinement around it, which the
//! acceleration's tolerance (10⁻², coupled's `ACCELERATION_TOLERANCE`) never needed: one
//! inner solve already meets it. The moments are f32 throughout, as the GPU sweeps' were.

use std::sync::Arc;

use runtime::gpu::{Gpu, Readback};

use super::diffusion::Operator;
use super::diffusion_gpu::Uploaded;
use super::transport::{HARMONICS, Medium, PER_VOXEL};
use super::transport_gpu::{STRIDE, Sweeps};
use crate::gpu::{RenderError, entry, filled};

/// The glue's WGSL.
pub const RESIDENT_WGSL: &str = include_str!("resident.wgsl");

/// Invocations per workgroup and workgroups along x of a dispatch (`resident.wgsl`).
const WG: usize = 64;
const ROW: usize = 1024;

runtime::uniform! {
    /// `Glue` of `resident.wgsl`: one channel's offsets.
    pub struct Glue as "Glue" {
        /// The transport grid's voxels.
        pub voxels: u32,
        /// Floats per voxel of the moments.
        pub stride: u32,
        /// The channel's φ_00 within a voxel's moments.
        pub offset: u32,
        /// The channel.
        pub channel: u32,
        /// The diffusion's right-hand side, its offset in its vectors (floats).
        pub rhs: u32,
        /// Its solution's offset.
        pub solution: u32,
        /// √(4π).
        pub root: f32,
        /// Padding.
        pub pad: u32,
    }
}

/// The glue's pipelines, compiled once per adapter.
pub struct Kernels {
    layout: wgpu::BindGroupLayout,
    source: wgpu::ComputePipeline,
    correct: wgpu::ComputePipeline,
    change: wgpu::ComputePipeline,
}

impl Kernels {
    /// Compiles `resident.wgsl`.
    pub fn new(gpu: &Gpu) -> Self {
        use wgpu::BufferBindingType::{Storage, Uniform};
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("photometeor resident transport layout"),
                entries: &[
                    entry(0, Uniform, false),
                    entry(1, Storage { read_only: true }, false),
                    entry(2, Storage { read_only: false }, false),
                    entry(3, Storage { read_only: false }, false),
                    entry(4, Storage { read_only: false }, false),
                    entry(5, Storage { read_only: false }, false),
                ],
            });
        let [source, correct, change] = <[_; 3]>::try_from(crate::gpu::compute_pipelines(
            &gpu.device,
            "photometeor resident transport",
            RESIDENT_WGSL.into(),
            &[&layout],
            &["source", "correct", "change"],
        ))
        .expect("three pipelines");
        Self {
            layout,
            source,
            correct,
            change,
        }
    }
}

/// Workgroups for `n` invocations (x up to [`ROW`], the rest along y).
fn groups(n: usize) -> (u32, u32) {
    let wgs = n.div_ceil(WG).max(1);
    (wgs.min(ROW) as u32, wgs.div_ceil(ROW) as u32)
}

/// One transport solve's state on the GPU between its rounds (and a relight's steps).
pub struct Resident {
    gpu: Gpu,
    sweeps: Sweeps,
    /// Per channel, the acceleration's operator on the GPU (None: no unknowns, no correction).
    solves: Vec<Option<Uploaded>>,
    source: wgpu::ComputePipeline,
    correct: wgpu::ComputePipeline,
    change: wgpu::ComputePipeline,
    /// Per channel, the glue's bindings (the moments, that channel's solver vectors).
    bindings: Vec<wgpu::BindGroup>,
    partial: wgpu::Buffer,
    readback: Readback,
    groups: (u32, u32),
    /// The inner solves' iteration cap.
    cap: usize,
    _keep: Vec<wgpu::Buffer>,
}

impl Resident {
    /// The iteration of `medium` on `sweeps`' grid from `start`, with `operators` (one per
    /// channel) accelerating it, each solve capped at `cap` iterations: the start uploaded
    /// once. Refused where the adapter cannot hold an operator's hierarchy.
    pub fn new(
        (gpu, kernels, solver): (&Gpu, &Kernels, &super::diffusion_gpu::Solver),
        sweeps: Sweeps,
        (medium, operators): (&Medium, &[Arc<Operator>]),
        start: &[[f64; PER_VOXEL]],
        cap: usize,
    ) -> Result<Self, RenderError> {
        let device = &gpu.device;
        let n = sweeps.voxels();
        let root = (4.0 * std::f64::consts::PI).sqrt();
        let solves = operators
            .iter()
            .map(|op| {
                let up = solver.upload(gpu, Arc::clone(op))?;
                match up.size() {
                    0 => Ok(None),
                    size if size == n => Ok(Some(up)),
                    size => Err(RenderError::Frame(crate::checks::FrameError(format!(
                        "the acceleration's operator has {size} unknowns on a grid of {n} voxels"
                    )))),
                }
            })
            .collect::<Result<Vec<_>, RenderError>>()?;
        // h³ σ′_s / √(4π) where a voxel is an unknown (Operator::isotropic), per channel.
        let per_channel: Vec<Vec<f64>> = operators
            .iter()
            .enumerate()
            .map(|(c, op)| {
                let sca: Vec<f64> = medium.sca.iter().map(|s| s[c] / root).collect();
                op.isotropic(&sca)
            })
            .collect();
        let weights: Vec<[f32; 4]> = (0..n)
            .map(|i| std::array::from_fn(|c| per_channel.get(c).map_or(0.0, |w| w[i] as f32)))
            .collect();
        use wgpu::BufferUsages as U;
        let weight = filled(
            device,
            "photometeor resident weights",
            bytemuck::cast_slice(&weights),
            U::STORAGE,
        );
        let groups = groups(n);
        let partials = groups.0 as usize * groups.1 as usize;
        let partial = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor resident partial sums"),
            size: (8 * partials).div_ceil(16) as u64 * 16,
            usage: U::STORAGE | U::COPY_SRC,
            mapped_at_creation: false,
        });
        // What a channel without unknowns binds in place of its solver's vectors.
        let idle = crate::gpu::storage(device, "photometeor resident idle", 16, false);
        let mut keep = vec![weight];
        let mut bindings = Vec::new();
        for c in 0..3 {
            let solve = solves.get(c).and_then(Option::as_ref);
            let vectors = solve.map_or(&idle, Uploaded::vectors);
            let glue = Glue {
                voxels: n as u32,
                stride: STRIDE as u32,
                offset: (c * HARMONICS) as u32,
                channel: c as u32,
                rhs: solve.map_or(0, Uploaded::rhs),
                solution: solve.map_or(0, Uploaded::solution),
                root: root as f32,
                pad: 0,
            };
            let params = filled(
                device,
                "photometeor resident glue",
                bytemuck::bytes_of(&glue),
                U::UNIFORM,
            );
            let buffers = [
                &params,
                &keep[0],
                &sweeps.moments,
                &sweeps.next,
                vectors,
                &partial,
            ];
            bindings.push(
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("photometeor resident bindings"),
                    layout: &kernels.layout,
                    entries: &buffers
                        .iter()
                        .enumerate()
                        .map(|(b, buffer)| wgpu::BindGroupEntry {
                            binding: b as u32,
                            resource: buffer.as_entire_binding(),
                        })
                        .collect::<Vec<_>>(),
                }),
            );
            keep.push(params);
        }
        keep.push(idle);
        sweeps.write_moments(start);
        Ok(Self {
            gpu: gpu.clone(),
            readback: Readback::new(gpu, partial.size()),
            sweeps,
            solves,
            source: kernels.source.clone(),
            correct: kernels.correct.clone(),
            change: kernels.change.clone(),
            bindings,
            partial,
            groups,
            cap,
            _keep: keep,
        })
    }

    /// The adapter it runs on.
    pub fn describe(&self) -> String {
        self.gpu.describe()
    }

    /// Records `pipeline` over every voxel with channel `c`'s bindings.
    fn glue(&self, encoder: &mut wgpu::CommandEncoder, pipeline: &wgpu::ComputePipeline, c: usize) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("photometeor resident glue"),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.bindings[c], &[]);
        pass.dispatch_workgroups(self.groups.0, self.groups.1, 1);
    }

    fn encoder(&self) -> wgpu::CommandEncoder {
        self.gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("photometeor resident transport"),
            })
    }

    /// One accelerated round: the new moments replace the old on the GPU; the relative change
    /// of the green φ_00 (rms) is returned. Fails where an acceleration's solve does not
    /// converge within the cap.
    pub fn iterate(&mut self) -> Result<f64, String> {
        let queue = &self.gpu.queue;
        let mut encoder = self.encoder();
        self.sweeps.record(&mut encoder);
        for (c, solve) in self.solves.iter().enumerate() {
            if solve.is_some() {
                self.glue(&mut encoder, &self.source, c);
            }
        }
        queue.submit([encoder.finish()]);
        for (c, solve) in self.solves.iter().enumerate() {
            let Some(solve) = solve else { continue };
            let (taken, converged) = solve.inner_on_gpu(self.cap).map_err(|e| e.to_string())?;
            if !converged {
                return Err(format!(
                    "channel {}'s solve did not reach its relative residual of {} in {taken} \
                     iterations (max_diffusion_iterations {})",
                    ["R", "G", "B"][c],
                    super::diffusion_gpu::INNER_TOLERANCE,
                    self.cap
                ));
            }
        }
        let mut encoder = self.encoder();
        for (c, solve) in self.solves.iter().enumerate() {
            if solve.is_some() {
                self.glue(&mut encoder, &self.correct, c);
            }
        }
        // The convergence test's channel: green.
        self.glue(&mut encoder, &self.change, 1);
        encoder.copy_buffer_to_buffer(&self.sweeps.next, 0, &self.sweeps.moments, 0, None);
        queue.submit([encoder.finish()]);
        let rows = self
            .readback
            .read(&self.gpu, &self.partial, 0, self.partial.size())
            .map_err(|e| e.to_string())?;
        let floats: &[f32] = bytemuck::cast_slice(&rows);
        let (mut d, mut t) = (0.0, 0.0);
        for pair in floats.chunks_exact(2) {
            d += f64::from(pair[0]);
            t += f64::from(pair[1]);
        }
        Ok((d / t.max(f64::MIN_POSITIVE)).sqrt())
    }

    /// The moments as they stand (read back).
    pub fn moments(&self) -> Result<Vec<[f64; PER_VOXEL]>, RenderError> {
        self.sweeps.read(&self.sweeps.moments)
    }
}
