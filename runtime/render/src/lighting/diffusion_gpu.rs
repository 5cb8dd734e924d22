//! The diffusion solve of [`super::diffusion`] on wgpu (`diffusion.wgsl`): the same operator
//! and multigrid hierarchy (assembled and coarsened on the CPU, uploaded once), conjugate
//! gradients preconditioned by the same V-cycle (red-black Gauss–Seidel, the Galerkin coarse
//! levels, the coarsest smoothed [`super::diffusion::COARSEST_SWEEPS`] times), every vector
//! operation a dispatch.
//!
//! f32 cannot take a relative residual much below 10⁻⁵, and the models ask for 10⁻⁶: the
//! conjugate gradients run in f32 on the GPU to [`INNER_TOLERANCE`] for a correction e of
//! A e = r, and an outer loop on the CPU in f64 adds it, x ← x + e, and forms the true residual
//! r = b − A x (mixed-precision iterative refinement, Wilkinson 1963; Moler 1967), until
//! ‖r‖/‖b‖ is below the tolerance. Each refinement gains about three digits. The iterations
//! reported are the inner ones, the residual the outer f64 one. The V-cycle's coarsest level (at most 64 voxels) is smoothed in one workgroup, one
//! dispatch for its 128 sweeps (`coarsest`: the same arithmetic).
//!
//! The conjugate gradients are driven on the GPU: the scalars of each iteration (r·z, d·Ad, r·r)
//! are summed per workgroup, and `scalars` sums the partial sums in f32, forms α and β, tests
//! the residual and the cap, and flags the iteration finished, after which every kernel returns
//! at once. A chunk of iterations is recorded into one submission and only the flags come back
//! (`Uploaded::drive`; before, each iteration waited for three readbacks of its partial sums,
//! summed on the CPU in f64). The transport's acceleration ([`super::resident`]) records its
//! chunks into the round's own submission; its tolerance (10⁻²) needs no f64 refinement.

use std::sync::Arc;
use std::time::Instant;

use runtime::gpu::{Gpu, GpuError, Readback};

use super::diffusion::{
    COARSEST_SWEEPS, NotConverged, Operator, Problem, Solution, Stencil, assemble,
};
use crate::gpu::entry;

/// Iterations of a GPU-driven solve recorded in its first submission ([`Uploaded::drive`]).
const FIRST_CHUNK: usize = 8;

/// A GPU-driven solve's state, read from its scalars (`diffusion.wgsl`'s `coef`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Flags {
    /// It has finished (converged, stopped at its cap, or broken down).
    pub done: bool,
    /// The iterations taken.
    pub taken: usize,
    /// It reached its relative residual.
    pub converged: bool,
}

impl Flags {
    /// The scalars' indices, as `diffusion.wgsl` names them.
    const DONE: usize = 2;
    const TAKEN: usize = 5;
    const CONVERGED: usize = 6;
    const TOLERANCE: u64 = 7;
    const CAP: u64 = 8;

    /// The state the scalars `coef` hold.
    pub(crate) fn of(coef: &[f32]) -> Self {
        Self {
            done: coef[Self::DONE] != 0.0,
            taken: coef[Self::TAKEN] as usize,
            converged: coef[Self::CONVERGED] != 0.0,
        }
    }
}

/// The iterations to record for a GPU-driven solve not finished after `recorded`: half as
/// many again, at least two.
pub(crate) fn more_iterations(recorded: usize) -> usize {
    (recorded / 2).max(2)
}

/// The bytes of the iteration's scalars (`diffusion.wgsl`'s `coef`: α, β, and the GPU-driven
/// iteration's state).
pub(crate) const COEF_BYTES: u64 = 48;

/// The inner solve's relative residual on the GPU (f32) per refinement.
pub const INNER_TOLERANCE: f64 = 1e-3;

/// The diffusion's WGSL.
pub const DIFFUSION_WGSL: &str = include_str!("diffusion.wgsl");

/// Invocations per workgroup and workgroups along x of a dispatch (`diffusion.wgsl`).
const WG: usize = 64;
const ROW: usize = 1024;
/// Bytes between two dispatches' parameters (wgpu's largest required dynamic-offset alignment).
const ALIGN: u64 = 256;

/// The kernels of `diffusion.wgsl`, in [`KERNELS`]'s order.
#[derive(Debug, Clone, Copy)]
enum Kernel {
    GaussSeidel,
    Residual,
    Restriction,
    Prolong,
    Zero,
    Dots,
    UpdateXr,
    UpdateD,
    Coarsest,
    Scalars,
}

const KERNELS: [&str; 10] = [
    "gauss_seidel",
    "residual",
    "restriction",
    "prolong",
    "zero",
    "dots",
    "update_xr",
    "update_d",
    "coarsest",
    "scalars",
];

/// A solve that failed: it did not converge, or the device did.
#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    /// The iteration cap was reached.
    #[error(transparent)]
    NotConverged(#[from] NotConverged),
    /// The device failed, or the problem exceeds its limits.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// The solver's pipelines, built once per adapter.
pub struct Solver {
    layout: wgpu::BindGroupLayout,
    pipelines: Vec<wgpu::ComputePipeline>,
}

impl Solver {
    /// The bind group of one upload: the dispatches' parameters (bound 64 bytes at a time at
    /// a dynamic offset), the operators' rows, the vectors, the partial sums and α, β.
    fn bind(&self, device: &wgpu::Device, buffers: [&wgpu::Buffer; 5]) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("photometeor diffusion bindings"),
            layout: &self.layout,
            entries: &buffers
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: if i == 0 {
                        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: b,
                            offset: 0,
                            size: wgpu::BufferSize::new(64),
                        })
                    } else {
                        b.as_entire_binding()
                    },
                })
                .collect::<Vec<_>>(),
        })
    }

    /// [`super::diffusion::solve`] on the GPU: the same operator, hierarchy and right-hand
    /// side, the conjugate gradients in f32 inside an f64 refinement (module docs).
    pub fn solve_problem(
        &self,
        gpu: &Gpu,
        p: &Problem,
        (tolerance, max_iterations): (f64, usize),
    ) -> Result<Solution, SolveError> {
        let start = Instant::now();
        let (a, b) = assemble(p);
        let op = Arc::new(Operator::new(a));
        let mut s = self.upload(gpu, op)?.solve(&b, tolerance, max_iterations)?;
        s.seconds = start.elapsed().as_secs_f64();
        Ok(s)
    }

    /// Compiles `diffusion.wgsl`.
    pub fn new(gpu: &Gpu) -> Self {
        use wgpu::BufferBindingType::{Storage, Uniform};
        let device = &gpu.device;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("photometeor diffusion layout"),
            entries: &[
                entry(0, Uniform, true),
                entry(1, Storage { read_only: true }, false),
                entry(2, Storage { read_only: false }, false),
                entry(3, Storage { read_only: false }, false),
                entry(4, Storage { read_only: false }, false),
            ],
        });
        let pipelines = crate::gpu::compute_pipelines(
            device,
            "photometeor diffusion",
            DIFFUSION_WGSL.into(),
            &[&layout],
            &KERNELS,
        );
        Self { layout, pipelines }
    }

    /// `op`'s hierarchy on the GPU, ready for [`Uploaded::solve`].
    pub fn upload(&self, gpu: &Gpu, op: Arc<Operator>) -> Result<Uploaded, GpuError> {
        Uploaded::new(self, gpu, op)
    }
}

/// One dispatch: its kernel, its parameters' slot and its workgroups.
#[derive(Debug, Clone, Copy)]
struct Call {
    kernel: Kernel,
    slot: u32,
    groups: (u32, u32),
}

/// Workgroups for `n` invocations (x up to [`ROW`], the rest along y): the layout of every
/// one-invocation-per-voxel dispatch of `diffusion.wgsl` and `resident.wgsl`.
pub(crate) fn groups(n: usize) -> (u32, u32) {
    let wgs = n.div_ceil(WG).max(1);
    (wgs.min(ROW) as u32, wgs.div_ceil(ROW) as u32)
}

runtime::uniform! {
    /// `Dispatch` of `diffusion.wgsl`: one dispatch's level, its coarser level and the
    /// kernel's vector operands (offsets in the vector buffer).
    pub struct Dispatch as "Dispatch" {
        /// This level's voxels along x, y, z.
        pub dims: [u32; 3],
        /// A smoothing sweep's colour, (x + y + z) mod 2.
        pub colour: u32,
        /// The coarser level's voxels along x, y, z (this level's without one).
        pub coarse_dims: [u32; 3],
        /// Its voxel count.
        pub coarse_voxels: u32,
        /// This level's first row of the operators.
        pub first_row: u32,
        /// The coarser level's.
        pub coarse_first_row: u32,
        /// This level's voxel count.
        pub voxels: u32,
        /// The residual kernel: 1 writes A b alone.
        pub product_only: u32,
        /// Operand a.
        pub a: u32,
        /// Operand b.
        pub b: u32,
        /// The output.
        pub out: u32,
        /// A fourth operand: the coarser level's z (prolong), A d (update_xr).
        pub c: u32,
    }
}

runtime::uniform! {
    /// `Stencil` of `diffusion.wgsl`: a voxel's row of its level's 7-point operator.
    pub struct StencilRow as "Stencil" {
        /// A_ii.
        pub diag: f32,
        /// The coupling w_a to the next voxel along each axis a (A_{i,i+e_a} = −w_a).
        pub coupling: [f32; 3],
    }
}

/// The parameters of every dispatch the solve records.
#[derive(Default)]
struct Plan {
    params: Vec<Dispatch>,
}

impl Plan {
    fn call(&mut self, kernel: Kernel, dispatch: Dispatch, n: usize) -> Call {
        self.params.push(dispatch);
        Call {
            kernel,
            slot: (self.params.len() - 1) as u32,
            groups: groups(n),
        }
    }
}

/// Where a level's vectors live in the vector buffer.
#[derive(Debug, Clone, Copy)]
struct Level {
    dims: [u32; 3],
    n: u32,
    /// First stencil row (= its offset in each per-level array).
    o: u32,
}

/// An operator's hierarchy and the solve's vectors on the GPU. It holds the device and the
/// solver's pipelines (reference-counted handles), so a relight keeps it between its steps.
pub struct Uploaded {
    gpu: Gpu,
    pipelines: Vec<wgpu::ComputePipeline>,
    op: Arc<Operator>,
    bind_group: wgpu::BindGroup,
    v: wgpu::Buffer,
    coef: wgpu::Buffer,
    /// The one mappable buffer the sums and the solution are read through.
    readback: Readback,
    /// Buffers the bind group reads: the dispatches' parameters, the operators, the partial
    /// sums.
    _keep: [wgpu::Buffer; 3],
    /// Offsets in the vector buffer: x, d, Ad, r_0, z_0.
    x: u64,
    r0: u64,
    n0: usize,
    levels: usize,
    first: Vec<Call>,
    apply: Vec<Call>,
    update_xr: Vec<Call>,
    after_vcycle: Vec<Call>,
    update_d: Vec<Call>,
    /// The GPU-driven iteration's control (`scalars`): reset, start, α, the test, β.
    control: [Call; 5],
}

/// The hierarchy's levels (each one's dims, size and first row) and the operators' rows, every
/// level's after the finer one's: (diagonal, the three couplings) per voxel (one row of zeros
/// for a problem without unknowns, so that a buffer can be bound).
fn levels(stencils: &[Stencil]) -> (Vec<Level>, Vec<StencilRow>) {
    let mut levels = Vec::new();
    let mut rows: Vec<StencilRow> = Vec::new();
    for s in stencils {
        levels.push(Level {
            dims: s.dims.map(|d| d as u32),
            n: s.diag.len() as u32,
            o: rows.len() as u32,
        });
        for i in 0..s.diag.len() {
            rows.push(StencilRow {
                diag: s.diag[i] as f32,
                coupling: [s.w[0][i], s.w[1][i], s.w[2][i]].map(|v| v as f32),
            });
        }
    }
    if rows.is_empty() {
        rows.push(StencilRow::default());
    }
    (levels, rows)
}

/// A dispatch's parameters: level `l`, the sweep's colour, the coarser level `c` (`l` without
/// one), and the vector operands `[a, b, out, c]` the kernel reads and writes.
fn words(l: &Level, c: Option<&Level>, colour: u32, sel: [usize; 4]) -> Dispatch {
    let coarse = c.copied().unwrap_or(*l);
    let [a, b, out, c] = sel.map(|v| v as u32);
    Dispatch {
        dims: l.dims,
        colour,
        coarse_dims: coarse.dims,
        coarse_voxels: coarse.n,
        first_row: l.o,
        coarse_first_row: coarse.o,
        voxels: l.n,
        product_only: 0,
        a,
        b,
        out,
        c,
    }
}

/// The V-cycle from level 0 down and back up (diffusion::Hierarchy::vcycle), z_l from r_l,
/// the vectors z, r and the residual at offsets `(z, r, res)` plus each level's first row.
fn vcycle(plan: &mut Plan, levels: &[Level], (z, r, res): (usize, usize, usize)) -> Vec<Call> {
    let mut vcycle = Vec::new();
    for (k, l) in levels.iter().enumerate() {
        let at = |base: usize, l: &Level| base + l.o as usize;
        let n = l.n as usize;
        if k + 1 == levels.len() && n <= WG {
            // The coarsest level in one workgroup (`coarsest`): one dispatch, not 129.
            vcycle.push(plan.call(
                Kernel::Coarsest,
                words(l, None, 0, [at(r, l), 0, at(z, l), 0]),
                n,
            ));
            break;
        }
        vcycle.push(plan.call(Kernel::Zero, words(l, None, 0, [0, 0, at(z, l), 0]), n));
        let gs = |plan: &mut Plan, colour: u32| {
            plan.call(
                Kernel::GaussSeidel,
                words(l, None, colour, [at(r, l), 0, at(z, l), 0]),
                n,
            )
        };
        if k + 1 == levels.len() {
            for _ in 0..COARSEST_SWEEPS {
                for colour in [0, 1, 1, 0] {
                    vcycle.push(gs(plan, colour));
                }
            }
            break;
        }
        vcycle.push(gs(plan, 0));
        vcycle.push(gs(plan, 1));
        let c = &levels[k + 1];
        vcycle.push(plan.call(
            Kernel::Residual,
            words(l, None, 0, [at(r, l), at(z, l), at(res, l), 0]),
            n,
        ));
        vcycle.push(plan.call(
            Kernel::Restriction,
            words(l, Some(c), 0, [at(res, l), 0, at(r, c), 0]),
            c.n as usize,
        ));
    }
    // Back up: prolong and post-smooth each level from the second-coarsest to the finest.
    for k in (0..levels.len().saturating_sub(1)).rev() {
        let (l, c) = (&levels[k], &levels[k + 1]);
        let at = |base: usize, l: &Level| base + l.o as usize;
        let n = l.n as usize;
        vcycle.push(plan.call(
            Kernel::Prolong,
            words(l, Some(c), 0, [0, 0, at(z, l), at(z, c)]),
            n,
        ));
        for colour in [1, 0] {
            vcycle.push(plan.call(
                Kernel::GaussSeidel,
                words(l, None, colour, [at(r, l), 0, at(z, l), 0]),
                n,
            ));
        }
    }
    vcycle
}

impl Uploaded {
    fn new(solver: &Solver, gpu: &Gpu, op: Arc<Operator>) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let stencils: &[Stencil] = op.levels();
        let (levels, rows) = levels(stencils);
        let total = rows.len();
        let n0 = stencils.first().map_or(0, |s| s.diag.len());
        // Vector offsets: z, r, res per level; x, d, Ad of level 0.
        let (z, r, res) = (0usize, total, 2 * total);
        let (x, d, ad) = (3 * total, 3 * total + n0, 3 * total + 2 * n0);
        let floats = 3 * total + 3 * n0.max(1);
        let partials = groups(n0).0 as usize * groups(n0).1 as usize;
        let limit = device.limits().max_storage_buffer_binding_size;
        if (4 * floats) as u64 > limit {
            return Err(GpuError::Limit {
                what: "bytes of the diffusion's vectors (all levels)",
                value: (4 * floats) as u64,
                limit,
            });
        }
        let mut plan = Plan::default();
        let vcycle = vcycle(&mut plan, &levels, (z, r, res));
        let (mut first, mut apply, mut update_xr, mut after_vcycle, mut update_d) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        if let Some(l0) = levels.first() {
            let dots = |plan: &mut Plan, a: usize, b: usize, slot: usize| {
                plan.call(
                    Kernel::Dots,
                    words(l0, None, 0, [a, b, slot * partials, 0]),
                    n0,
                )
            };
            let zero = |plan: &mut Plan, at: usize| {
                plan.call(Kernel::Zero, words(l0, None, 0, [0, 0, at, 0]), n0)
            };
            let ud = plan.call(Kernel::UpdateD, words(l0, None, 0, [z, 0, d, 0]), n0);
            // x = 0, d = 0, z = M r, d = z (β = 0), r·z, r·r.
            first.extend([zero(&mut plan, x), zero(&mut plan, d)]);
            first.extend(vcycle.iter().copied());
            first.push(ud);
            first.push(dots(&mut plan, r, z, 0));
            first.push(dots(&mut plan, r, r, 1));
            let product = Dispatch {
                product_only: 1,
                ..words(l0, None, 0, [0, d, ad, 0])
            };
            apply.push(plan.call(Kernel::Residual, product, n0));
            apply.push(dots(&mut plan, d, ad, 0));
            update_xr.push(plan.call(Kernel::UpdateXr, words(l0, None, 0, [x, d, r, ad]), n0));
            update_xr.push(dots(&mut plan, r, r, 1));
            after_vcycle.extend(vcycle.iter().copied());
            after_vcycle.push(dots(&mut plan, r, z, 0));
            update_d.push(ud);
        }
        // The control reads the two slots of partial sums of a level-0 vector operation.
        let control = [0, 1, 2, 3, 4].map(|step| {
            let words = Dispatch {
                colour: step,
                voxels: partials as u32,
                ..Dispatch::default()
            };
            plan.call(Kernel::Scalars, words, 1)
        });
        use wgpu::BufferUsages as U;
        // A problem without unknowns dispatches nothing, but binds one block.
        if plan.params.is_empty() {
            plan.params.push(Dispatch::default());
        }
        let params: Vec<u8> = plan
            .params
            .iter()
            .flat_map(|w| {
                let mut block = bytemuck::bytes_of(w).to_vec();
                block.resize(ALIGN as usize, 0);
                block
            })
            .collect();
        let filled =
            |label: &str, bytes: &[u8], usage| crate::gpu::filled(device, label, bytes, usage);
        let params = filled("photometeor diffusion dispatches", &params, U::UNIFORM);
        let stencil = filled(
            "photometeor diffusion operators",
            bytemuck::cast_slice(&rows),
            U::STORAGE,
        );
        let v = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor diffusion vectors"),
            size: (4 * floats) as u64,
            usage: U::STORAGE | U::COPY_DST | U::COPY_SRC,
            mapped_at_creation: false,
        });
        let partial = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor diffusion partial sums"),
            size: (4 * (2 * partials).div_ceil(4) * 4) as u64,
            usage: U::STORAGE | U::COPY_SRC,
            mapped_at_creation: false,
        });
        let coef = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor diffusion α β"),
            size: COEF_BYTES,
            usage: U::STORAGE | U::COPY_DST | U::COPY_SRC,
            mapped_at_creation: false,
        });
        let bind_group = solver.bind(device, [&params, &stencil, &v, &partial, &coef]);
        Ok(Self {
            gpu: gpu.clone(),
            pipelines: solver.pipelines.clone(),
            op,
            bind_group,
            v,
            readback: Readback::new(gpu, solution_bytes(n0).max(COEF_BYTES)),
            coef,
            _keep: [params, stencil, partial],
            x: (4 * x) as u64,
            r0: (4 * r) as u64,
            n0,
            levels: levels.len(),
            first,
            apply,
            update_xr,
            after_vcycle,
            update_d,
            control,
        })
    }

    /// Records `calls` into `pass`.
    fn record(&self, pass: &mut wgpu::ComputePass, calls: &[Call]) {
        for c in calls {
            pass.set_pipeline(&self.pipelines[c.kernel as usize]);
            pass.set_bind_group(0, &self.bind_group, &[(u64::from(c.slot) * ALIGN) as u32]);
            pass.dispatch_workgroups(c.groups.0, c.groups.1, 1);
        }
    }

    /// Sets the GPU-driven iteration's relative residual and iteration cap.
    pub(crate) fn set_limits(&self, (tolerance, cap): (f64, usize)) {
        self.set_coef(Flags::TOLERANCE, tolerance);
        self.set_coef(Flags::CAP, cap as f64);
    }

    /// Records the GPU-driven iteration (`diffusion.wgsl`'s `scalars` forms α and β and tests
    /// the residual on the GPU; nothing comes back): with `start`, its start from the
    /// right-hand side at [`Uploaded::rhs`], then `iterations` iterations of preconditioned
    /// conjugate gradients (A d and d·Ad, α, x and r, r·r and the test, the V-cycle and r·z, β,
    /// d), each one doing nothing once the iteration has finished. The dispatches recorded.
    pub(crate) fn record_iterations(
        &self,
        pass: &mut wgpu::ComputePass,
        start: bool,
        iterations: usize,
    ) -> usize {
        let [reset, begin, alpha, test, beta] = self.control;
        let mut recorded = 0;
        let mut record = |calls: &[Call]| {
            self.record(pass, calls);
            recorded += calls.len();
        };
        if start {
            record(&[reset]);
            record(&self.first);
            record(&[begin]);
        }
        for _ in 0..iterations {
            record(&self.apply);
            record(&[alpha]);
            record(&self.update_xr);
            record(&[test]);
            record(&self.after_vcycle);
            record(&[beta]);
            record(&self.update_d);
        }
        recorded
    }

    /// The buffer of the iteration's scalars ([`COEF_BYTES`]): whether it has finished (2),
    /// the iterations taken (5), whether it converged (6).
    pub(crate) fn scalars(&self) -> &wgpu::Buffer {
        &self.coef
    }

    fn set_coef(&self, index: u64, value: f64) {
        self.gpu
            .queue
            .write_buffer(&self.coef, 4 * index, bytemuck::bytes_of(&(value as f32)));
    }

    /// One f32 solve of A e = r to [`INNER_TOLERANCE`] within `cap` iterations, driven on the
    /// GPU ([`Uploaded::drive`]): e and the iterations taken.
    fn inner(&self, r: &[f64], cap: usize) -> Result<(Vec<f64>, usize), GpuError> {
        let data: Vec<f32> = r.iter().map(|&v| v as f32).collect();
        self.gpu
            .queue
            .write_buffer(&self.v, self.r0, bytemuck::cast_slice(&data));
        self.set_limits((INNER_TOLERANCE, cap));
        let (taken, _) = self.drive(cap)?;
        let rows = self
            .readback
            .read(&self.gpu, &self.v, self.x, solution_bytes(self.n0))?;
        let e: &[f32] = bytemuck::cast_slice(&rows);
        Ok((e[..self.n0].iter().map(|&v| f64::from(v)).collect(), taken))
    }

    /// The GPU-driven iteration ([`Uploaded::record_iterations`]) from the right-hand side at
    /// [`Uploaded::rhs`] to its limits ([`Uploaded::set_limits`]), recorded in chunks of
    /// [`FIRST_CHUNK`] iterations and then half as many again until it finishes (its flags read
    /// back after each; at most `cap` iterations): the iterations taken and whether it
    /// converged (a zero right-hand side is solved by e = 0; one whose norm is not finite is
    /// not solved).
    fn drive(&self, cap: usize) -> Result<(usize, bool), GpuError> {
        let (mut recorded, mut chunk, mut start) = (0, FIRST_CHUNK.min(cap.max(1)), true);
        loop {
            let mut encoder =
                self.gpu
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                        label: Some("photometeor diffusion"),
                    });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("photometeor diffusion"),
                    timestamp_writes: None,
                });
                self.record_iterations(&mut pass, start, chunk);
            }
            self.gpu.queue.submit([encoder.finish()]);
            recorded += chunk;
            start = false;
            let rows = self.readback.read(&self.gpu, &self.coef, 0, COEF_BYTES)?;
            let flags = Flags::of(bytemuck::cast_slice(&rows));
            if flags.done || recorded >= cap {
                return Ok((flags.taken, flags.converged));
            }
            chunk = more_iterations(chunk).min(cap - recorded);
        }
    }

    /// The vectors' buffer (f32; every level's z, r, res, then x, d, A d of the finest).
    pub(crate) fn vectors(&self) -> &wgpu::Buffer {
        &self.v
    }

    /// The offset (floats) of the right-hand side r in [`Uploaded::vectors`].
    pub(crate) fn rhs(&self) -> u32 {
        (self.r0 / 4) as u32
    }

    /// The offset (floats) of the solution e in [`Uploaded::vectors`].
    pub(crate) fn solution(&self) -> u32 {
        (self.x / 4) as u32
    }

    /// The unknowns of the finest level (0: the operator has none, nothing to solve).
    pub(crate) fn size(&self) -> usize {
        self.n0
    }

    /// Solves A x = `b` to relative residual `tolerance` within `max_iterations` inner
    /// iterations in all (module docs).
    pub fn solve(
        &self,
        b: &[f64],
        tolerance: f64,
        max_iterations: usize,
    ) -> Result<Solution, SolveError> {
        let start = Instant::now();
        let n = self.n0;
        let unknowns = self
            .op
            .levels()
            .first()
            .map_or(0, |s| s.diag.iter().filter(|&&d| d > 0.0).count());
        let b_norm = b.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !b_norm.is_finite() {
            return Err(NotConverged {
                residual: b_norm,
                iterations: 0,
                tolerance,
            }
            .into());
        }
        let Some(a) = self.op.levels().first().filter(|_| b_norm > 0.0) else {
            return Ok(Solution::zero(b.len(), unknowns, start));
        };
        let mut x = vec![0.0; n];
        let mut r = b.to_vec();
        let mut ax = vec![0.0; n];
        let mut iterations = 0;
        loop {
            let residual = r.iter().map(|v| v * v).sum::<f64>().sqrt() / b_norm;
            if residual < tolerance {
                return Ok(Solution {
                    i0: x,
                    iterations,
                    residual,
                    levels: self.levels,
                    unknowns,
                    seconds: start.elapsed().as_secs_f64(),
                });
            }
            if iterations >= max_iterations || !residual.is_finite() {
                return Err(NotConverged {
                    residual,
                    iterations,
                    tolerance,
                }
                .into());
            }
            let (e, taken) = self.inner(&r, max_iterations - iterations)?;
            iterations += taken.max(1);
            for (xi, ei) in x.iter_mut().zip(&e) {
                *xi += ei;
            }
            a.apply(&x, &mut ax);
            for ((ri, bi), axi) in r.iter_mut().zip(b).zip(&ax) {
                *ri = bi - axi;
            }
        }
    }
}

/// The bytes a level-0 vector of `n0` f32 is read back in (whole RGBA rows).
fn solution_bytes(n0: usize) -> u64 {
    (4 * n0.max(1)).div_ceil(16) as u64 * 16
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `coarsest` sweeps the coarsest level as often as the CPU's V-cycle.
    #[test]
    fn the_shaders_coarsest_sweeps_are_the_cpus() {
        let line = format!("const COARSEST_SWEEPS: u32 = {COARSEST_SWEEPS}u;");
        assert!(
            DIFFUSION_WGSL.contains(&line),
            "diffusion.wgsl lacks `{line}`"
        );
    }
}
