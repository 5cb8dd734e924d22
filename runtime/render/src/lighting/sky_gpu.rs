//! The reduced skylight's sweeps ([`super::sky::sky_sweeps`]) on wgpu (`sky.wgsl`), one of
//! the per-sun passes a GPU render runs there with `per_sun = "auto"` on a real adapter or
//! `"gpu"`: one dispatch per layer of each sweep order (the directions that travel most along
//! one axis and sign), one invocation per voxel of the layer looping over the order's
//! directions, in f32; the lit directions ([`super::sky::sky_light`]) come from the CPU and
//! the mean skylight and its flux per voxel go back to it.

use glam::DVec3;

use runtime::gpu::{Gpu, read_back};

use super::sky::{Sky, sky_orders};
use super::transport_gpu::{
    bind_with_steps, buffers_fit, dispatch_steps, layer_fits, push_step, sweep_pipeline,
    with_upwind,
};
use crate::gpu::{RenderError, filled, storage};
use crate::volume::DensityGrid;

/// The sweeps' WGSL, without the shared upwind lookup ([`source`] puts it before).
pub const SKY_WGSL: &str = include_str!("sky.wgsl");

/// The sweeps' whole shader module.
pub fn source() -> String {
    with_upwind(SKY_WGSL)
}

/// Invocations per workgroup (`sky.wgsl`).
const WG: usize = 64;

runtime::uniform! {
    /// `Params` of `sky.wgsl`.
    pub struct SkyParams as "Params" {
        /// nx, ny, nz, 0.
        pub dims: [u32; 4],
    }
}

runtime::uniform! {
    /// `SkyWay` of `sky.wgsl`: one direction of a sweep order.
    pub struct SkyWay as "SkyWay" {
        /// The point one layer back (shift u, shift v, voxel units), the step ds (m), 0.
        pub way: [f32; 4],
        /// The sky's radiance × 1/SKY_DIRECTIONS per channel, 0.
        pub radiance: [f32; 4],
        /// s, the unit direction towards the sky, 0.
        pub towards: [f32; 4],
    }
}

runtime::uniform! {
    /// `SkyVoxel` of `sky.wgsl`: a voxel's [`Sky`], summed over the sweeps.
    pub struct SkyVoxel as "SkyVoxel" {
        /// The mean skylight per channel, 0.
        pub mean: [f32; 4],
        /// Its flux vector (x, y, z, 0), one per channel.
        pub flux: [[f32; 4]; 3],
    }
}

runtime::uniform! {
    /// `LayerState` of `sky.wgsl`: one direction's optical depth at a voxel of the layer just
    /// swept, what the next layer reads (GPU memory only; its size sizes the buffer).
    pub struct SkyLayerState as "LayerState" {
        /// The optical depth back to the sky per channel, 0.
        pub tau: [f32; 4],
        /// The voxel's β_ext per channel, 0.
        pub ext: [f32; 4],
    }
}

/// The skylight sweeps' pipeline, built once per adapter.
pub struct SkySweeper {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl SkySweeper {
    /// The GPU twin of [`super::lattice::sun_depths`]: the optical depth towards the light at
    /// every voxel centre for light travelling along `l`, as one direction of the skylight's
    /// sweeps (which attenuate each direction exactly as `sun_depths` does, interpolating τ
    /// one layer back), its radiance chosen so that its mean is e^{−τ}; τ = −ln of that (f32:
    /// past τ ≈ 87 the light is 0 and τ infinite).
    pub fn depths(
        &self,
        gpu: &Gpu,
        grid: &DensityGrid,
        ext: &[[f64; 3]],
        l: DVec3,
    ) -> Result<Vec<[f64; 3]>, RenderError> {
        let radiance = [super::sky::SKY_DIRECTIONS as f64; 3];
        let sky = self.sweep(gpu, grid, ext, &[(-l, radiance)])?;
        Ok(sky.mean.iter().map(|t| t.map(|t| -t.ln())).collect())
    }

    /// Compiles `sky.wgsl`.
    pub fn new(gpu: &Gpu) -> Self {
        let (layout, pipeline) = sweep_pipeline(
            gpu,
            "photometeor sky sweep",
            source(),
            &[true, true, false, false],
        );
        Self { layout, pipeline }
    }

    /// The skylight of `lit` (towards the sky, radiance per channel beyond the box) through
    /// the grid of β_ext `ext`, as [`super::sky::sky_sweeps`] gives it (in f32). Refused,
    /// naming the value, where a layer exceeds the adapter's workgroups or a buffer its
    /// storage-binding limit.
    pub fn sweep(
        &self,
        gpu: &Gpu,
        grid: &DensityGrid,
        ext: &[[f64; 3]],
        lit: &[(DVec3, [f64; 3])],
    ) -> Result<Sky, RenderError> {
        let (device, queue) = (&gpu.device, &gpu.queue);
        let dims = grid.dims;
        let voxels = ext.len();
        let f = |v: [f64; 3]| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0];
        let mut ways: Vec<SkyWay> = Vec::with_capacity(lit.len());
        let mut steps: Vec<u8> = Vec::new();
        let mut layers: Vec<(usize, usize)> = Vec::new();
        let mut largest_state = 0usize;
        for ((a, forward), order) in sky_orders(grid, lit) {
            let first = ways.len();
            ways.extend(order.iter().map(|w| SkyWay {
                way: [w.shift.0 as f32, w.shift.1 as f32, w.ds as f32, 0.0],
                radiance: f(w.weight),
                towards: f(w.s.to_array()),
            }));
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let count = order.len();
            largest_state = largest_state.max(2 * dims[b] * dims[c] * count);
            let run = super::lattice::layer_order(dims[a], forward);
            for (s, &k) in run.iter().enumerate() {
                let words = [a, b, c, k, usize::from(s == 0), first, count, s % 2];
                push_step(&mut steps, words.map(|w| w as u32));
                layers.push(((dims[b] * dims[c]).div_ceil(WG), 1));
            }
        }
        let mut sky = Sky::zero(voxels);
        if layers.is_empty() {
            return Ok(sky);
        }
        for &(n, _) in &layers {
            layer_fits(gpu, "the skylight's GPU sweeps", n, dims)?;
        }
        let sky_bytes = (std::mem::size_of::<SkyVoxel>() * voxels) as u64;
        let state_bytes = (std::mem::size_of::<SkyLayerState>() * largest_state) as u64;
        buffers_fit(
            gpu,
            "the skylight's",
            dims,
            &[("light", sky_bytes), ("layer state", state_bytes)],
            "lower [render] grid_resolution",
        )?;
        let rows: Vec<[f32; 4]> = ext.iter().map(|&e| f(e)).collect();
        let params = SkyParams {
            dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, 0],
        };
        use wgpu::BufferUsages as U;
        let params = filled(
            device,
            "photometeor sky params",
            bytemuck::bytes_of(&params),
            U::UNIFORM,
        );
        let steps = filled(device, "photometeor sky steps", &steps, U::UNIFORM);
        let ext_buffer = filled(
            device,
            "photometeor sky extinction",
            bytemuck::cast_slice(&rows),
            U::STORAGE,
        );
        let ways = filled(
            device,
            "photometeor sky directions",
            bytemuck::cast_slice(&ways),
            U::STORAGE,
        );
        let state = storage(device, "photometeor sky state", state_bytes, false);
        let light = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("photometeor sky light"),
            size: sky_bytes,
            usage: U::STORAGE | U::COPY_SRC | U::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = bind_with_steps(
            device,
            &self.layout,
            "photometeor sky bindings",
            &steps,
            &[&params, &ext_buffer, &ways, &state, &light],
        );
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("photometeor sky sweeps"),
        });
        encoder.clear_buffer(&light, 0, None);
        dispatch_steps(
            &mut encoder,
            "photometeor sky sweeps",
            &self.pipeline,
            &bind_group,
            &layers,
        );
        queue.submit([encoder.finish()]);
        let back = read_back(gpu, &light, sky_bytes).map_err(RenderError::from)?;
        let voxels: &[SkyVoxel] = bytemuck::cast_slice(&back);
        for (i, v) in voxels.iter().enumerate() {
            sky.mean[i] = std::array::from_fn(|c| f64::from(v.mean[c]));
            sky.flux[i] = std::array::from_fn(|c| {
                let [x, y, z, _] = v.flux[c].map(f64::from);
                DVec3::new(x, y, z)
            });
        }
        Ok(sky)
    }
}
