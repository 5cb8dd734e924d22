//! The discrete-ordinates transport's sweeps on wgpu (`sweep.wgsl`): a round of
//! [`super::transport`]'s source iteration — every direction swept upwind through the grid,
//! layer by layer, the radiances projected onto the spherical harmonics — with one dispatch
//! per layer of each group of directions (one workgroup per voxel of the layer, one
//! invocation per direction), in f32. The iteration around it (the diffusion synthetic
//! acceleration, the convergence test) runs on the GPU too, in [`super::resident`], the
//! moments kept there between rounds; [`Sweeps::round`] alone (the tests' check of one round
//! against the CPU's) uploads the moments and reads the new ones back.

use glam::DVec3;

use runtime::gpu::{Gpu, read_back};

use super::transport::{Group, HARMONICS, Medium, PER_VOXEL, groups, harmonics, layer_axes};
use crate::gpu::{RenderError, entry, filled, storage};
use crate::volume::DensityGrid;

/// The sweeps' WGSL, without the shared [`UPWIND_WGSL`] ([`source`] puts it before).
pub const SWEEP_WGSL: &str = include_str!("sweep.wgsl");
/// The upwind lookup one layer back that the transport's and the skylight's sweeps share.
pub const UPWIND_WGSL: &str = include_str!("upwind.wgsl");

/// The sweeps' whole shader module: [`UPWIND_WGSL`], then [`SWEEP_WGSL`].
pub fn source() -> String {
    with_upwind(SWEEP_WGSL)
}

/// `wgsl` after [`UPWIND_WGSL`].
pub(crate) fn with_upwind(wgsl: &str) -> String {
    format!("{UPWIND_WGSL}\n{wgsl}")
}

/// Appends one dispatch's step to `steps`: its eight words, padded to [`STEP_ALIGN`] (the
/// sweeps' `Step` uniform, read at a dynamic offset).
pub(crate) fn push_step(steps: &mut Vec<u8>, words: [u32; 8]) {
    let start = steps.len();
    steps.extend_from_slice(bytemuck::cast_slice(&words));
    steps.resize(start + STEP_ALIGN as usize, 0);
}

/// A sweep's bind group: `buffers[0]` at binding 0, the steps at binding 1 (one 32-byte
/// `Step` at a dynamic offset), `buffers[1..]` at bindings 2, 3, …
pub(crate) fn bind_with_steps(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    label: &str,
    steps: &wgpu::Buffer,
    buffers: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let step = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer: steps,
        offset: 0,
        size: wgpu::BufferSize::new(32),
    });
    let entries: Vec<wgpu::BindGroupEntry> = std::iter::once((1, step))
        .chain(
            buffers
                .iter()
                .zip(std::iter::once(0).chain(2..))
                .map(|(b, binding)| (binding, b.as_entire_binding())),
        )
        .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// Records one compute pass of `pipeline` with one dispatch per step: step s at its dynamic
/// offset, `groups[s]` workgroups (x, y).
pub(crate) fn dispatch_steps(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    groups: &[(usize, usize)],
) {
    let steps = 0..groups.len();
    dispatch_step_range(encoder, label, (pipeline, bind_group), groups, steps);
}

/// [`dispatch_steps`] for the steps in `range` alone.
pub(crate) fn dispatch_step_range(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    (pipeline, bind_group): (&wgpu::ComputePipeline, &wgpu::BindGroup),
    groups: &[(usize, usize)],
    range: std::ops::Range<usize>,
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    pass.set_pipeline(pipeline);
    for s in range {
        let (x, y) = groups[s];
        pass.set_bind_group(0, bind_group, &[(s as u64 * STEP_ALIGN) as u32]);
        pass.dispatch_workgroups(x as u32, y as u32, 1);
    }
}

/// A sweep's bind group layout and pipeline (entry point `sweep` of `source`): its `Params`
/// at binding 0, the steps at binding 1 (dynamic offset), then one storage buffer per entry of
/// `read_only` at bindings 2, 3, … (read-only where true).
pub(crate) fn sweep_pipeline(
    gpu: &Gpu,
    label: &str,
    source: String,
    read_only: &[bool],
) -> (wgpu::BindGroupLayout, wgpu::ComputePipeline) {
    use wgpu::BufferBindingType::{Storage, Uniform};
    let entries: Vec<wgpu::BindGroupLayoutEntry> =
        [entry(0, Uniform, false), entry(1, Uniform, true)]
            .into_iter()
            .chain(
                read_only
                    .iter()
                    .zip(2..)
                    .map(|(&read_only, b)| entry(b, Storage { read_only }, false)),
            )
            .collect();
    let layout = gpu
        .device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(&format!("{label} layout")),
            entries: &entries,
        });
    let [pipeline] = <[_; 1]>::try_from(crate::gpu::compute_pipelines(
        &gpu.device,
        label,
        source,
        &[&layout],
        &["sweep"],
    ))
    .expect("one pipeline");
    (layout, pipeline)
}

/// Refused, naming the sizes, where `whose` layer of `groups` workgroups exceeds the adapter's
/// workgroups per dimension.
pub(crate) fn layer_fits(
    gpu: &Gpu,
    whose: &str,
    groups: usize,
    dims: [usize; 3],
) -> Result<(), RenderError> {
    let most = gpu.device.limits().max_compute_workgroups_per_dimension;
    if groups as u32 > most {
        return Err(gpu_refusal(format!(
            "{whose} needs {groups} workgroups for a layer of the {dims:?} grid, more than {}'s \
             {most} per dimension: lower [render] grid_resolution",
            gpu.describe()
        )));
    }
    Ok(())
}

/// Refused, naming the buffer, its size and the limit, where one of `buffers` (what, bytes)
/// exceeds the adapter's storage-binding limit; `remedy` says what to lower.
pub(crate) fn buffers_fit(
    gpu: &Gpu,
    whose: &str,
    dims: [usize; 3],
    buffers: &[(&str, u64)],
    remedy: &str,
) -> Result<(), RenderError> {
    let limit = gpu.device.limits().max_storage_buffer_binding_size;
    match buffers.iter().find(|&&(_, bytes)| bytes > limit) {
        Some(&(what, bytes)) => Err(gpu_refusal(format!(
            "{whose} {what} take {} MiB on a {dims:?} grid, more than {}'s storage-binding \
             limit of {} MiB: {remedy}",
            bytes >> 20,
            gpu.describe(),
            limit >> 20
        ))),
        None => Ok(()),
    }
}

/// Floats per voxel of the moments on the GPU (75, padded to whole rows of four).
pub(crate) const STRIDE: usize = PER_VOXEL.div_ceil(4) * 4;
/// The most directions one group may hold (`sweep.wgsl`'s MAX_GROUP, its workgroup memory).
pub const MAX_GROUP: usize = 512;
/// Bytes between two dispatches' [`Step`]s in their uniform buffer (wgpu's largest required
/// dynamic-offset alignment).
const STEP_ALIGN: u64 = 256;

runtime::uniform! {
    /// `Params` of `sweep.wgsl`.
    pub struct SweepParams as "Params" {
        /// nx, ny, nz, floats per voxel of the moments.
        pub dims: [u32; 4],
        /// x: the quadrature weight 4π/N.
        pub weight: [f32; 4],
        /// Y_k(l) of the sun's direction of travel, k < 25 (zero past).
        pub y_sun: [[f32; 4]; 7],
    }
}

runtime::uniform! {
    /// `TransportVoxel` of `sweep.wgsl`: a voxel's [`Medium`] in f32.
    pub struct TransportVoxel as "TransportVoxel" {
        /// σ′_t per channel (1/m), 0.
        pub ext: [f32; 4],
        /// σ′_s per channel (1/m), 0.
        pub sca: [f32; 4],
        /// p′'s moments χ′_0…3, one vector per channel.
        pub chi: [[f32; 4]; 3],
        /// χ′_4 per channel, 0.
        pub chi4: [f32; 4],
        /// The sunlit source q per channel, 0.
        pub sun: [f32; 4],
        /// The skylit source (q0, q1 x, y, z), one vector per channel.
        pub sky: [[f32; 4]; 3],
    }
}

runtime::uniform! {
    /// `Ordinate` of `sweep.wgsl`: one direction of the quadrature.
    pub struct Ordinate as "Ordinate" {
        /// Y_k(ω), k < 25, zero past k = 24.
        pub y: [[f32; 4]; 7],
        /// The point one layer back (shift u, shift v, voxel units), the step ds (m), 0.
        pub way: [f32; 4],
    }
}

runtime::uniform! {
    /// `LayerState` of `sweep.wgsl`: one direction's radiance at a voxel of the layer just
    /// swept, what the next layer reads (GPU memory only; its size sizes the buffer).
    pub struct TransportLayerState as "LayerState" {
        /// I per channel, 0.
        pub radiance: [f32; 4],
        /// The voxel's σ′_t per channel, 0.
        pub ext: [f32; 4],
        /// The voxel's source S in this direction per channel, 0.
        pub source: [f32; 4],
    }
}

/// The medium per voxel in f32 (sweep.wgsl's `medium`).
fn medium_voxels(medium: &Medium) -> Vec<TransportVoxel> {
    let f = |v: [f64; 3]| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0];
    (0..medium.ext.len())
        .map(|i| TransportVoxel {
            ext: f(medium.ext[i]),
            sca: f(medium.sca[i]),
            chi: std::array::from_fn(|c| {
                let chi = &medium.chi[i][c];
                [chi[0], chi[1], chi[2], chi[3]].map(|v| v as f32)
            }),
            chi4: f(std::array::from_fn(|c| medium.chi[i][c][4])),
            sun: f(medium.sun[i]),
            sky: std::array::from_fn(|c| medium.sky[i][c].map(|v| v as f32)),
        })
        .collect()
}

/// The ordinates, the steps' words, the layers' sizes (workgroups along x, y) and the
/// largest layer state ([`ordinate_rows`]).
type OrdinateRows = (Vec<Ordinate>, Vec<u8>, Vec<(usize, usize)>, usize);

/// The ordinates, group after group (Y_lm of the direction, then the point one layer back
/// and the step), one step per layer of each group, the layers' sizes, and the largest layer
/// state (in [`TransportLayerState`]s) a group needs.
fn ordinate_rows(groups: &[Group], dims: [usize; 3]) -> OrdinateRows {
    let mut ordinates: Vec<Ordinate> = Vec::new();
    let mut steps: Vec<u8> = Vec::new();
    let mut layers: Vec<(usize, usize)> = Vec::new();
    let mut largest_state = 0usize;
    for g in groups {
        let first = ordinates.len();
        ordinates.extend(g.ordinates.iter().map(|o| Ordinate {
            y: std::array::from_fn(|r| {
                std::array::from_fn(|j| {
                    let k = 4 * r + j;
                    if k < HARMONICS { o.y[k] as f32 } else { 0.0 }
                })
            }),
            way: [o.shift.0 as f32, o.shift.1 as f32, o.ds as f32, 0.0],
        }));
        let (b, c) = layer_axes(g.axis);
        let count = g.ordinates.len();
        largest_state = largest_state.max(2 * dims[b] * dims[c] * count);
        let order = super::lattice::layer_order(dims[g.axis], g.forward);
        for (s, &k) in order.iter().enumerate() {
            let words = [g.axis, b, c, k, usize::from(s == 0), first, count, s % 2];
            push_step(&mut steps, words.map(|w| w as u32));
            layers.push((dims[b], dims[c]));
        }
    }
    (ordinates, steps, layers, largest_state)
}

/// The sweeps' pipeline, built once per adapter.
pub struct Sweeper {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl Sweeper {
    /// Compiles `sweep.wgsl`.
    pub fn new(gpu: &Gpu) -> Self {
        let (layout, pipeline) = sweep_pipeline(
            gpu,
            "photometeor transport sweep",
            source(),
            &[true, true, false, true, false],
        );
        Self { layout, pipeline }
    }

    /// The buffers of one transport solve: `medium` on `grid` with the directions `dirs`.
    /// Refused, naming the value, when a group of directions exceeds [`MAX_GROUP`], a layer
    /// exceeds the adapter's workgroups per dimension, or a buffer its storage-binding limit.
    pub fn prepare(
        &self,
        gpu: &Gpu,
        grid: &DensityGrid,
        medium: &Medium,
        dirs: &[DVec3],
    ) -> Result<Sweeps, RenderError> {
        let device = &gpu.device;
        let limits = device.limits();
        let dims = grid.dims;
        let voxels = medium.ext.len();
        let groups = groups(grid, dirs);
        if let Some(g) = groups.iter().find(|g| g.ordinates.len() > MAX_GROUP) {
            return Err(gpu_refusal(format!(
                "the transport's GPU sweeps hold at most {MAX_GROUP} directions per sweep order; \
                 {} of the {} directions travel mostly along axis {}: lower [render.coupled] \
                 directions",
                g.ordinates.len(),
                dirs.len(),
                g.axis
            )));
        }
        if let Some(&n) = dims
            .iter()
            .find(|&&n| n as u32 > limits.max_compute_workgroups_per_dimension)
        {
            return Err(gpu_refusal(format!(
                "the transport's grid has {n} voxels along an axis, more than the adapter's {} \
                 workgroups per dimension",
                limits.max_compute_workgroups_per_dimension
            )));
        }
        let rows = medium_voxels(medium);
        let (ordinates, steps, layers, largest_state) = ordinate_rows(&groups, dims);
        let moments_bytes = (4 * STRIDE * voxels) as u64;
        let state_bytes =
            (std::mem::size_of::<TransportLayerState>() * largest_state.max(1)) as u64;
        let medium_bytes = std::mem::size_of_val(rows.as_slice()) as u64;
        buffers_fit(
            gpu,
            "the transport's",
            dims,
            &[
                ("moments", moments_bytes),
                ("medium", medium_bytes),
                ("layer state", state_bytes),
            ],
            "raise [render.coupled] transport_coarsening or lower [render] grid_resolution",
        )?;
        let y_sun = harmonics(medium.l);
        let params = SweepParams {
            dims: [
                dims[0] as u32,
                dims[1] as u32,
                dims[2] as u32,
                STRIDE as u32,
            ],
            weight: [
                (4.0 * std::f64::consts::PI / dirs.len() as f64) as f32,
                0.0,
                0.0,
                0.0,
            ],
            y_sun: std::array::from_fn(|r| {
                std::array::from_fn(|j| y_sun.get(4 * r + j).map_or(0.0, |&v| v as f32))
            }),
        };
        use wgpu::BufferUsages as U;
        let params = filled(
            device,
            "photometeor sweep params",
            bytemuck::bytes_of(&params),
            U::UNIFORM,
        );
        let steps = filled(device, "photometeor sweep steps", &steps, U::UNIFORM);
        let medium_buffer = filled(
            device,
            "photometeor sweep medium",
            bytemuck::cast_slice(&rows),
            U::STORAGE,
        );
        let ordinates = filled(
            device,
            "photometeor sweep ordinates",
            bytemuck::cast_slice(&ordinates),
            U::STORAGE,
        );
        let moments = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor sweep moments"),
            size: moments_bytes,
            usage: U::STORAGE | U::COPY_SRC | U::COPY_DST,
            mapped_at_creation: false,
        });
        let next = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor sweep next"),
            size: moments_bytes,
            usage: U::STORAGE | U::COPY_SRC | U::COPY_DST,
            mapped_at_creation: false,
        });
        let state = storage(device, "photometeor sweep state", state_bytes, false);
        let bind_group = bind_with_steps(
            device,
            &self.layout,
            "photometeor sweep bindings",
            &steps,
            &[&params, &medium_buffer, &moments, &next, &ordinates, &state],
        );
        Ok(Sweeps {
            gpu: gpu.clone(),
            pipeline: self.pipeline.clone(),
            bind_group,
            moments,
            next,
            layers,
            voxels,
            _keep: [params, steps, medium_buffer, ordinates, state],
        })
    }
}

/// The first `voxels` voxels' moments of `buffer` (the sweeps' layout, [`STRIDE`] floats a
/// voxel) read back, in f64.
pub(crate) fn read_moments(
    gpu: &Gpu,
    buffer: &wgpu::Buffer,
    voxels: usize,
) -> Result<Vec<[f64; PER_VOXEL]>, RenderError> {
    let rows = read_back(gpu, buffer, (4 * STRIDE * voxels) as u64).map_err(RenderError::from)?;
    let floats: &[f32] = bytemuck::cast_slice(&rows);
    Ok(floats
        .chunks_exact(STRIDE)
        .map(|v| std::array::from_fn(|k| f64::from(v[k])))
        .collect())
}

/// A refusal of the GPU sweeps, naming the value.
fn gpu_refusal(message: String) -> RenderError {
    RenderError::Frame(crate::checks::FrameError(message))
}

/// One transport solve's buffers on the GPU ([`Sweeper::prepare`]); they hold the device
/// (its handles are reference-counted), so a relight keeps them between its steps.
pub struct Sweeps {
    gpu: Gpu,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    /// The round's moments, read by the sweeps (f32, [`STRIDE`] per voxel).
    pub(crate) moments: wgpu::Buffer,
    /// The new moments the sweeps add to.
    pub(crate) next: wgpu::Buffer,
    /// Per dispatch, the layer's extent (its workgroups).
    layers: Vec<(usize, usize)>,
    voxels: usize,
    /// Buffers the bind group reads.
    _keep: [wgpu::Buffer; 5],
}

impl Sweeps {
    /// The adapter the sweeps run on.
    pub fn describe(&self) -> String {
        self.gpu.describe()
    }

    /// The transport grid's voxels.
    pub(crate) fn voxels(&self) -> usize {
        self.voxels
    }

    /// The dispatches of a round.
    pub(crate) fn dispatches(&self) -> usize {
        self.layers.len()
    }

    /// Writes the moments `m` the next round sweeps from (f32).
    pub(crate) fn write_moments(&self, m: &[[f64; PER_VOXEL]]) {
        let mut data = vec![0f32; STRIDE * self.voxels];
        for (to, from) in data.chunks_exact_mut(STRIDE).zip(m) {
            for (t, f) in to.iter_mut().zip(from) {
                *t = *f as f32;
            }
        }
        self.gpu
            .queue
            .write_buffer(&self.moments, 0, bytemuck::cast_slice(&data));
    }

    /// Records one round of sweeps from the moments on the GPU into `encoder`: the new moments
    /// in [`Sweeps::next`].
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        self.record_range(encoder, 0..self.dispatches());
    }

    /// Records the dispatches in `range` of a round's ([`Sweeps::record`] in parts: the same
    /// dispatches in the same order); one starting at 0 clears [`Sweeps::next`] first.
    pub(crate) fn record_range(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        range: std::ops::Range<usize>,
    ) {
        if range.start == 0 {
            encoder.clear_buffer(&self.next, 0, None);
        }
        let kernel = (&self.pipeline, &self.bind_group);
        dispatch_step_range(encoder, "photometeor sweeps", kernel, &self.layers, range);
    }

    /// `buffer`'s moments (the sweeps' layout) in f64.
    pub(crate) fn read(&self, buffer: &wgpu::Buffer) -> Result<Vec<[f64; PER_VOXEL]>, RenderError> {
        read_moments(&self.gpu, buffer, self.voxels)
    }

    /// One round of sweeps from moments `m`: the new moments, as
    /// [`super::transport::sweep_once`] computes them (in f32). The moments go up and the new
    /// ones come back ([`super::resident`] keeps them on the GPU instead).
    pub fn round(&self, m: &[[f64; PER_VOXEL]]) -> Result<Vec<[f64; PER_VOXEL]>, RenderError> {
        self.write_moments(m);
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("photometeor sweeps"),
            });
        self.record(&mut encoder);
        self.gpu.queue.submit([encoder.finish()]);
        self.read(&self.next)
    }
}
