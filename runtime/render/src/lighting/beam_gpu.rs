//! The beam's sweep ([`super::beam::beam_sweep`] with the peak from the medium and the peak's
//! depth D, [`super::beam::PeakFrom::Medium`] and [`super::beam::Depth::Peak`]) on wgpu
//! (`beam.wgsl`): one dispatch per layer along the sun's direction of travel, one invocation
//! per voxel of the layer, in f32. The medium per voxel (β_ext, β_sca,
//! the split's f, g and the peak's share) comes from the CPU, the beam and its losses go back
//! to it in the CPU sweep's layout.

use glam::DVec3;

use runtime::gpu::{Gpu, read_back};

use super::beam::{BeamMedium, BeamState};
use super::transport_gpu::{
    bind_with_steps, buffers_fit, dispatch_steps, layer_fits, push_step, sweep_pipeline,
    with_upwind,
};
use crate::gpu::{RenderError, filled, storage};
use crate::volume::DensityGrid;

/// The sweep's WGSL, without the shared upwind lookup ([`source`] puts it before).
pub const BEAM_WGSL: &str = include_str!("beam.wgsl");

/// The sweep's whole shader module.
pub fn source() -> String {
    with_upwind(BEAM_WGSL)
}

/// Invocations per workgroup (`beam.wgsl`).
const WG: usize = 64;

runtime::uniform! {
    /// `Params` of `beam.wgsl`.
    pub struct BeamParams as "Params" {
        /// nx, ny, nz, 0.
        pub dims: [u32; 4],
        /// The point one layer back (voxel units along the layer's two axes), the step's length
        /// (metres), 0.
        pub way: [f32; 4],
    }
}

/// The beam sweep's pipeline, built once per adapter.
pub struct BeamSweeper {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl BeamSweeper {
    /// Compiles `beam.wgsl`.
    pub fn new(gpu: &Gpu) -> Self {
        let (layout, pipeline) = sweep_pipeline(
            gpu,
            "photometeor beam sweep",
            source(),
            &[true, false, false],
        );
        Self { layout, pipeline }
    }

    /// The beam travelling along `l` through `medium` on `grid`, as
    /// [`super::beam::beam_sweep`] gives it (in f32). Refused, naming the value, where a layer
    /// exceeds the adapter's workgroups or a buffer its storage-binding limit.
    pub fn sweep(
        &self,
        gpu: &Gpu,
        grid: &DensityGrid,
        medium: &[BeamMedium],
        l: DVec3,
    ) -> Result<Vec<BeamState>, RenderError> {
        let (device, queue) = (&gpu.device, &gpu.queue);
        let dims = grid.dims;
        let voxels = medium.len();
        let way = super::lattice::Way::along(grid, l);
        let (a, b, c) = (way.axis, (way.axis + 1) % 3, (way.axis + 2) % 3);
        let groups = (dims[b] * dims[c]).div_ceil(WG);
        layer_fits(gpu, "the beam's GPU sweep", groups, dims)?;
        let beam_bytes = (64 * voxels) as u64;
        let state_bytes = (2 * 64 * dims[b] * dims[c]) as u64;
        buffers_fit(
            gpu,
            "the beam's",
            dims,
            &[
                ("medium and beam", beam_bytes),
                ("layer state", state_bytes),
            ],
            "lower [render] grid_resolution",
        )?;
        let mut steps: Vec<u8> = Vec::new();
        let run = super::lattice::layer_order(dims[a], way.forward);
        for (s, &k) in run.iter().enumerate() {
            let words = [a, b, c, k, usize::from(s == 0), 0, 1, s % 2];
            push_step(&mut steps, words.map(|w| w as u32));
        }
        let f = |v: [f64; 3], w: f64| [v[0] as f32, v[1] as f32, v[2] as f32, w as f32];
        let rows: Vec<[f32; 4]> = medium
            .iter()
            .flat_map(|m| [f(m.ext, 0.0), f(m.sca, 0.0), f(m.f, m.share), f(m.g, 0.0)])
            .collect();
        let params = BeamParams {
            dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, 0],
            way: [way.shift.0 as f32, way.shift.1 as f32, way.ds as f32, 0.0],
        };
        use wgpu::BufferUsages as U;
        let params = filled(
            device,
            "photometeor beam params",
            bytemuck::bytes_of(&params),
            U::UNIFORM,
        );
        let steps = filled(device, "photometeor beam steps", &steps, U::UNIFORM);
        let medium_buffer = filled(
            device,
            "photometeor beam medium",
            bytemuck::cast_slice(&rows),
            U::STORAGE,
        );
        let state = storage(device, "photometeor beam state", state_bytes, false);
        let beam = storage(device, "photometeor beam", beam_bytes, true);
        let bind_group = bind_with_steps(
            device,
            &self.layout,
            "photometeor beam bindings",
            &steps,
            &[&params, &medium_buffer, &state, &beam],
        );
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("photometeor beam sweep"),
        });
        dispatch_steps(
            &mut encoder,
            "photometeor beam sweep",
            &self.pipeline,
            &bind_group,
            &vec![(groups, 1); run.len()],
        );
        queue.submit([encoder.finish()]);
        let back = read_back(gpu, &beam, beam_bytes).map_err(RenderError::from)?;
        Ok(back
            .chunks_exact(4)
            .zip(medium)
            .map(|(v, m)| {
                let row = |k: usize| std::array::from_fn(|ch| f64::from(v[k][ch]));
                BeamState {
                    intensity: row(0),
                    depth: f64::from(v[0][3]),
                    ext: m.ext,
                    sca: m.sca,
                    dropped: row(1),
                    forward: row(2),
                    loss: row(3),
                }
            })
            .collect())
    }
}
