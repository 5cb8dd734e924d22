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
        let mut ways: Vec<[f32; 4]> = Vec::with_capacity(3 * lit.len());
        let mut steps: Vec<u8> = Vec::new();
        let mut layers: Vec<(usize, usize)> = Vec::new();
        let mut largest_state = 0usize;
        for ((a, forward), order) in sky_orders(grid, lit) {
            let first = ways.len() / 3;
            for w in &order {
                ways.push([w.shift.0 as f32, w.shift.1 as f32, w.ds as f32, 0.0]);
                ways.push(f(w.weight));
                ways.push(f(w.s.to_array()));
            }
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let count = order.len();
            largest_state = largest_state.max(2 * dims[b] * dims[c] * count * 2);
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
        let sky_bytes = (64 * voxels) as u64;
        let state_bytes = (16 * largest_state) as u64;
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
        for (i, v) in back.chunks_exact(4).enumerate() {
            sky.mean[i] = std::array::from_fn(|c| f64::from(v[0][c]));
            sky.flux[i] = std::array::from_fn(|c| {
                DVec3::new(
                    f64::from(v[1 + c][0]),
                    f64::from(v[1 + c][1]),
                    f64::from(v[1 + c][2]),
                )
            });
        }
        Ok(sky)
    }
}
