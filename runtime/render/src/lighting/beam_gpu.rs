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

runtime::uniform! {
    /// `MediumVoxel` of `beam.wgsl`: a voxel's [`BeamMedium`] in f32.
    pub struct MediumVoxel as "MediumVoxel" {
        /// β_ext per channel (1/m), 0.
        pub ext: [f32; 4],
        /// β_sca per channel (1/m), 0.
        pub sca: [f32; 4],
        /// The split's forward peak f per channel, the peak's share of β_sca (green).
        pub peak: [f32; 4],
        /// The asymmetry parameter g per channel, 0.
        pub g: [f32; 4],
    }
}

runtime::uniform! {
    /// `BeamVoxel` of `beam.wgsl`: the beam at a voxel and its losses per metre of the step,
    /// the GPU's part of a [`BeamState`].
    pub struct BeamVoxel as "BeamVoxel" {
        /// I per channel, the peak's depth D.
        pub beam: [f32; 4],
        /// The diffuse light's isotropic source per channel ([`BeamState::dropped`]), 0.
        pub isotropic: [f32; 4],
        /// Its first-moment source per channel ([`BeamState::forward`]), 0.
        pub forward: [f32; 4],
        /// The whole loss per channel ([`BeamState::loss`]), 0.
        pub loss: [f32; 4],
    }
}

runtime::uniform! {
    /// `LayerState` of `beam.wgsl`: the beam at a voxel of the layer just swept, what the
    /// next layer reads (GPU memory only; its size sizes the buffer).
    pub struct BeamLayerState as "LayerState" {
        /// The beam I per channel, 0.
        pub intensity: [f32; 4],
        /// The voxel's β_ext per channel, 0.
        pub ext: [f32; 4],
        /// The voxel's β_sca per channel, 0.
        pub sca: [f32; 4],
        /// The peak's depth D, 0, 0, 0.
        pub depth: [f32; 4],
    }
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
        let beam_bytes = (std::mem::size_of::<BeamVoxel>() * voxels) as u64;
        let state_bytes = (2 * std::mem::size_of::<BeamLayerState>() * dims[b] * dims[c]) as u64;
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
        let rows: Vec<MediumVoxel> = medium
            .iter()
            .map(|m| MediumVoxel {
                ext: f(m.ext, 0.0),
                sca: f(m.sca, 0.0),
                peak: f(m.f, m.share),
                g: f(m.g, 0.0),
            })
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
        let voxels: &[BeamVoxel] = bytemuck::cast_slice(&back);
        Ok(voxels
            .iter()
            .zip(medium)
            .map(|(v, m)| {
                let rgb = |row: [f32; 4]| std::array::from_fn(|ch| f64::from(row[ch]));
                BeamState {
                    intensity: rgb(v.beam),
                    depth: f64::from(v.beam[3]),
                    ext: m.ext,
                    sca: m.sca,
                    dropped: rgb(v.isotropic),
                    forward: rgb(v.forward),
                    loss: rgb(v.loss),
                }
            })
            .collect())
    }
}
