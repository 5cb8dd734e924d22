//! The transport's source iteration kept on the GPU: the sweeps' moments, the acceleration's
//! diffusion solves and the convergence test's sums stay in GPU buffers from round to round
//! and from one step of a relight to the next. A round is two submissions and two readbacks
//! of a few hundred bytes (the solves' flags, the change's partial sums); the moments come back
//! when the caller asks for them ([`Resident::moments`]: once at the end of a relight's call,
//! not once a round). Before, a round sent the moments up and read them back (2 × 304 bytes a
//! voxel) and each conjugate-gradient iteration of each channel's acceleration waited for three
//! readbacks of its scalars.
//!
//! A round (as [`super::transport::iterate`] with coupled's acceleration, in f32):
//! 1. the sweeps from the moments into `next` ([`super::transport_gpu`]);
//! 2. per channel, the acceleration's right-hand side h³ σ′_s Δφ_00 / √(4π) formed in the
//!    diffusion solver's own vectors (`resident.wgsl`'s `source`) and the solve of the round's
//!    error by conjugate gradients driven on the GPU ([`super::diffusion_gpu`]'s `scalars`: a
//!    chunk of iterations recorded, each doing nothing once the solve has finished), its flags
//!    read back, another chunk where one has not finished;
//! 3. the correction √(4π) e added to the new φ_00 (`correct`), the relative change of the
//!    green φ_00 summed per workgroup (`change`), the new moments copied over the old, and the
//!    sums read back.
//!
//! A round can also go in parts ([`Resident::part`]), each submitted and waited for: runs of
//! the sweeps' dispatches, then runs of the solves' iterations, a channel after another, sized
//! by the caller (a relight's step with a budget, [`Resident::units_before`]). The parts record
//! the same dispatches in the same order, so the moments do not depend on where a round is
//! cut; the moments the gather reads stay the last whole round's until the part that ends it.
//!
//! Where it departs from the CPU's iteration: the moments are f32 throughout, as the GPU
//! sweeps' were, and the acceleration's conjugate gradients run in f32 to its relative
//! residual of 10⁻² (coupled's `ACCELERATION_TOLERANCE`) without the f64 refinement that the
//! diffusion's own solve (10⁻⁶) needs.

use std::sync::Arc;
use std::time::Instant;

use runtime::gpu::{Gpu, Readback};

use super::diffusion::Operator;
use super::diffusion_gpu::{COEF_BYTES, Flags, Uploaded, groups, more_iterations};
use super::transport::{HARMONICS, Medium, PER_VOXEL};
use super::transport_gpu::{STRIDE, Sweeps};
use crate::gpu::{RenderError, bind, entry, filled};

/// The glue's WGSL.
pub const RESIDENT_WGSL: &str = include_str!("resident.wgsl");

/// Iterations of an acceleration's solve recorded in a round's first submission: the first
/// round's [`FIRST_CHUNK`], each later one's what the last round's solve of that channel took
/// and [`SLACK`] more (the iterations recorded after a solve finishes do nothing, but each
/// still launches its invocations; a solve not finished gets half as many again). A solve takes
/// 18–22 at the acceleration's relative residual of 10⁻² on dense_cumulus (realtime,
/// 64 × 35 × 64 voxels), about as many from round to round.
pub const FIRST_CHUNK: usize = 8;
/// See [`FIRST_CHUNK`].
pub const SLACK: usize = 1;

/// What a [`Resident`] iteration has submitted and read back.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Traffic {
    /// Rounds (source iterations).
    pub rounds: usize,
    /// Command buffers submitted.
    pub submits: usize,
    /// Dispatches recorded.
    pub dispatches: usize,
    /// Readbacks (each waits for the GPU).
    pub readbacks: usize,
    /// Bytes read back.
    pub bytes_read: u64,
}

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

/// The transport's moments on the GPU that computed them, in the layout the gathers read
/// (`STRIDE` floats a voxel, as the sweeps write them): the adapter and the buffer.
#[derive(Clone)]
pub struct MomentsOnGpu {
    /// The adapter the buffer lives on.
    pub gpu: Gpu,
    /// The moments.
    pub buffer: wgpu::Buffer,
}

impl std::fmt::Debug for MomentsOnGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MomentsOnGpu")
            .field("gpu", &self.gpu.describe())
            .field("bytes", &self.buffer.size())
            .finish()
    }
}

impl MomentsOnGpu {
    /// The moments read back, as they stand.
    pub fn read(&self) -> Result<Vec<[f64; PER_VOXEL]>, RenderError> {
        let voxels = self.buffer.size() as usize / (4 * STRIDE);
        super::transport_gpu::read_moments(&self.gpu, &self.buffer, voxels)
    }
}

/// Where a round stands between its parts ([`Resident::part`]).
enum Phase {
    /// The sweeps' dispatches before `next` have run.
    Sweeping { next: usize },
    /// The sweeps have run; the acceleration's solves: per channel the iterations recorded
    /// (none: not begun), and the channels whose solves have not finished.
    Solving {
        recorded: [usize; 3],
        pending: Vec<usize>,
    },
}

/// Seconds a unit of a part took, the last time one was timed (0: never).
#[derive(Default)]
struct Pace {
    /// One of the sweeps' dispatches.
    sweeps: f64,
    /// One iteration of one channel's solve.
    solves: f64,
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
    /// Each channel's solve's scalars, copied out together.
    flags: wgpu::Buffer,
    readback: Readback,
    traffic: Traffic,
    /// Per channel, the iterations to record in a round's first submission ([`FIRST_CHUNK`]).
    expected: [usize; 3],
    groups: (u32, u32),
    /// The acceleration's solves' relative residual and iteration cap.
    limits: (f64, usize),
    /// Where the round under way stands (`None`: between rounds).
    phase: Option<Phase>,
    /// The time a unit of each part took ([`Resident::units_before`]).
    pace: Pace,
    _keep: Vec<wgpu::Buffer>,
}

impl Resident {
    /// The iteration of `medium` on `sweeps`' grid from `start`, with `operators` (one per
    /// channel) accelerating it, each solve to `limits` (relative residual, iterations): the
    /// start uploaded once. Refused where the adapter cannot hold an operator's hierarchy.
    pub fn new(
        (gpu, kernels, solver): (&Gpu, &Kernels, &super::diffusion_gpu::Solver),
        sweeps: Sweeps,
        (medium, operators): (&Medium, &[Arc<Operator>]),
        start: &[[f64; PER_VOXEL]],
        limits: (f64, usize),
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
            let label = "photometeor resident bindings";
            bindings.push(bind(device, &kernels.layout, label, &buffers, None));
            keep.push(params);
        }
        keep.push(idle);
        sweeps.write_moments(start);
        for solve in solves.iter().flatten() {
            solve.set_limits(limits);
        }
        let flags = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor resident solves' scalars"),
            size: 3 * COEF_BYTES,
            usage: U::COPY_DST | U::COPY_SRC,
            mapped_at_creation: false,
        });
        Ok(Self {
            gpu: gpu.clone(),
            readback: Readback::new(gpu, partial.size().max(flags.size())),
            flags,
            traffic: Traffic::default(),
            expected: [FIRST_CHUNK; 3],
            sweeps,
            solves,
            source: kernels.source.clone(),
            correct: kernels.correct.clone(),
            change: kernels.change.clone(),
            bindings,
            partial,
            groups,
            limits,
            phase: None,
            pace: Pace::default(),
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
    /// converge within the cap. A round begun in parts ([`Resident::part`]) is finished.
    ///
    /// Two submissions in the common case: the sweeps, each channel's right-hand side and
    /// the first iterations of its solve ([`FIRST_CHUNK`]), driven on the GPU, then the solves'
    /// scalars read back (a channel not yet finished gets another chunk); then the
    /// corrections, the change's sums and the moments' copy, and the sums read back.
    pub fn iterate(&mut self) -> Result<f64, String> {
        loop {
            if let Some(change) = self.part(usize::MAX)? {
                return Ok(change);
            }
        }
    }

    /// Runs the next part of the round, of at most `units` units of work (at least one): a
    /// unit is one of the sweeps' dispatches (a layer of a group of directions) or one
    /// iteration of the acceleration's unfinished solves, and a part of fewer than
    /// `usize::MAX` units does work of one kind; the part is submitted and waited for.
    /// The change (as [`Resident::iterate`]) where the part ends the round, else `None`.
    /// The parts of a round record the same dispatches in the same order as one call of
    /// [`Resident::iterate`]; the iterations recorded after a solve has finished do nothing,
    /// so however a round is cut, its moments are the same. Meanwhile the moments read by the
    /// gather ([`Resident::moments_on_gpu`]) are the last whole round's.
    pub fn part(&mut self, units: usize) -> Result<Option<f64>, String> {
        let start = Instant::now();
        let mut left = units.max(1);
        let mut encoder = self.encoder();
        let mut phase = self.phase.take().unwrap_or(Phase::Sweeping { next: 0 });
        let mut swept = 0;
        if let Phase::Sweeping { next } = phase {
            let total = self.sweeps.dispatches();
            let end = total.min(next.saturating_add(left));
            self.sweeps.record_range(&mut encoder, next..end);
            swept = end - next;
            self.traffic.dispatches += swept;
            // A bounded part is of one kind: its units are timed as one.
            left = if units == usize::MAX || swept == 0 {
                left - swept
            } else {
                0
            };
            phase = if end < total {
                Phase::Sweeping { next: end }
            } else {
                Phase::Solving {
                    recorded: [0; 3],
                    pending: self.channels(),
                }
            };
        }
        let Phase::Solving {
            mut recorded,
            pending,
        } = phase
        else {
            self.submit(encoder);
            self.wait()?;
            self.pace.sweeps = start.elapsed().as_secs_f64() / swept as f64;
            self.phase = Some(phase);
            return Ok(None);
        };
        if pending.is_empty() {
            return self.close(encoder).map(Some);
        }
        if left == 0 {
            self.submit(encoder);
            self.wait()?;
            self.pace.sweeps = start.elapsed().as_secs_f64() / swept as f64;
            self.phase = Some(Phase::Solving { recorded, pending });
            return Ok(None);
        }
        let (tolerance, cap) = self.limits;
        if let Some(&c) = pending.iter().find(|&&c| recorded[c] > cap) {
            return Err(format!(
                "channel {}'s acceleration on the GPU did not finish within {} iterations \
                 (max_diffusion_iterations {cap})",
                ["R", "G", "B"][c],
                recorded[c]
            ));
        }
        // Each unfinished channel in turn, while units are left: its first iterations (after
        // its right-hand side and start) or half as many again as it has had.
        let mut chunk = [0; 3];
        for &c in &pending {
            let more = if recorded[c] == 0 {
                self.expected[c].clamp(1, cap.max(1))
            } else {
                more_iterations(recorded[c])
            };
            chunk[c] = more.min(left);
            left -= chunk[c];
        }
        let begin = recorded.map(|n| n == 0);
        self.solve_chunk(&mut encoder, &pending, begin, chunk);
        for &c in &pending {
            recorded[c] += chunk[c];
        }
        self.submit(encoder);
        let flags = self.read_flags()?;
        if swept == 0 {
            let iterations: usize = chunk.iter().sum();
            self.pace.solves = start.elapsed().as_secs_f64() / iterations as f64;
        }
        let all = self.channels();
        // (A channel that had no iterations in this part holds its last round's flags.)
        let pending: Vec<usize> = pending
            .into_iter()
            .filter(|&c| chunk[c] == 0 || !flags[c].done)
            .collect();
        if !pending.is_empty() {
            self.phase = Some(Phase::Solving { recorded, pending });
            return Ok(None);
        }
        for &c in &all {
            let Flags {
                taken, converged, ..
            } = flags[c];
            // The next round's solve takes about as many.
            self.expected[c] = taken + SLACK;
            if !converged {
                return Err(format!(
                    "channel {}'s acceleration did not reach its relative residual of \
                     {tolerance} in {taken} iterations (max_diffusion_iterations {cap})",
                    ["R", "G", "B"][c]
                ));
            }
        }
        self.close(self.encoder()).map(Some)
    }

    /// The units of work ([`Resident::part`]) the next part can do before `deadline`, from
    /// the time the last parts of its kind took: at least one; one where none has been timed.
    pub fn units_before(&self, deadline: Instant) -> usize {
        let pace = match &self.phase {
            Some(Phase::Solving { pending, .. }) => self.pace.solves * pending.len() as f64,
            _ => self.pace.sweeps,
        };
        let left = deadline
            .saturating_duration_since(Instant::now())
            .as_secs_f64();
        if pace > 0.0 {
            ((left / pace) as usize).max(1)
        } else {
            1
        }
    }

    /// Whether a round has begun and not ended (its sweeps' new moments are not yet the
    /// moments).
    pub fn mid_round(&self) -> bool {
        self.phase.is_some()
    }

    /// The end of a round, recorded after `encoder`'s work: the corrections, the change's
    /// sums and the moments' copy, submitted; the change read back.
    fn close(&mut self, mut encoder: wgpu::CommandEncoder) -> Result<f64, String> {
        let all = self.channels();
        for &c in &all {
            self.glue(&mut encoder, &self.correct, c);
        }
        // The convergence test's channel: green.
        self.glue(&mut encoder, &self.change, 1);
        self.traffic.dispatches += all.len() + 1;
        encoder.copy_buffer_to_buffer(&self.sweeps.next, 0, &self.sweeps.moments, 0, None);
        self.submit(encoder);
        let partial = self.partial.clone();
        let rows = self.read(&partial)?;
        let floats: &[f32] = bytemuck::cast_slice(&rows);
        let (mut d, mut t) = (0.0, 0.0);
        for pair in floats.chunks_exact(2) {
            d += f64::from(pair[0]);
            t += f64::from(pair[1]);
        }
        self.traffic.rounds += 1;
        Ok((d / t.max(f64::MIN_POSITIVE)).sqrt())
    }

    /// The channels whose acceleration has unknowns (a solve).
    fn channels(&self) -> Vec<usize> {
        (0..3).filter(|&c| self.solves[c].is_some()).collect()
    }

    /// Waits for the work submitted.
    fn wait(&self) -> Result<(), String> {
        self.gpu
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| e.to_string())
    }

    /// Records, for each of `channels` given any, `iterations[c]` iterations of its
    /// acceleration's solve (where `start[c]`: its right-hand side and its start first), then
    /// copies its scalars out.
    fn solve_chunk(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        channels: &[usize],
        start: [bool; 3],
        iterations: [usize; 3],
    ) {
        let channels: Vec<usize> = channels
            .iter()
            .copied()
            .filter(|&c| iterations[c] > 0)
            .collect();
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("photometeor resident acceleration"),
                timestamp_writes: None,
            });
            for &c in &channels {
                let solve = self.solves[c].as_ref().expect("a channel with a solve");
                let start = start[c];
                if start {
                    pass.set_pipeline(&self.source);
                    pass.set_bind_group(0, &self.bindings[c], &[]);
                    pass.dispatch_workgroups(self.groups.0, self.groups.1, 1);
                    self.traffic.dispatches += 1;
                }
                self.traffic.dispatches += solve.record_iterations(&mut pass, start, iterations[c]);
            }
        }
        for &c in &channels {
            let solve = self.solves[c].as_ref().expect("a channel with a solve");
            let at = c as u64 * COEF_BYTES;
            encoder.copy_buffer_to_buffer(solve.scalars(), 0, &self.flags, at, COEF_BYTES);
        }
    }

    fn submit(&mut self, encoder: wgpu::CommandEncoder) {
        self.gpu.queue.submit([encoder.finish()]);
        self.traffic.submits += 1;
    }

    /// `buffer` read back whole.
    fn read(&mut self, buffer: &wgpu::Buffer) -> Result<Vec<[f32; 4]>, String> {
        let size = buffer.size();
        self.traffic.readbacks += 1;
        self.traffic.bytes_read += size;
        self.readback
            .read(&self.gpu, buffer, 0, size)
            .map_err(|e| e.to_string())
    }

    /// Per channel, its solve's state.
    fn read_flags(&mut self) -> Result<[Flags; 3], String> {
        let flags = self.flags.clone();
        let rows = self.read(&flags)?;
        let floats: &[f32] = bytemuck::cast_slice(&rows);
        let per = (COEF_BYTES / 4) as usize;
        Ok(std::array::from_fn(|c| Flags::of(&floats[c * per..])))
    }

    /// What it has sent and read back so far.
    pub fn traffic(&self) -> Traffic {
        self.traffic
    }

    /// The moments' buffer on the GPU and its device (the gather reads it in place).
    pub fn moments_on_gpu(&self) -> MomentsOnGpu {
        MomentsOnGpu {
            gpu: self.gpu.clone(),
            buffer: self.sweeps.moments.clone(),
        }
    }

    /// The moments as they stand (read back).
    pub fn moments(&mut self) -> Result<Vec<[f64; PER_VOXEL]>, RenderError> {
        self.traffic.readbacks += 1;
        self.traffic.bytes_read += self.sweeps.moments.size();
        self.sweeps.read(&self.sweeps.moments)
    }
}
