//! The `max` model's final gather on wgpu (`gather.wgsl`): one compute invocation per pixel
//! marches the ray through the grid as [`super::cpu::gather`] does, in f32, reading the
//! per-voxel [`Lighting`] the CPU computed (steps 1–4: the reduced sun and sky, the diffusion
//! solve, the clear-air propagation). That lighting depends on the sun, the sky and the cloud,
//! not on the camera: a camera that moves needs only this gather again, which is where a GPU
//! pays (module docs of [`super`]; `photometeor bench render --model max` times both).
//!
//! Bind group 0: the tables ([`GpuTables`]: `ams_mix` for Ams_1, `poisson` for the Poisson
//! mixtures). Bind group 1: the params uniform, the densities, the lighting (a
//! [`LightVoxel`] per voxel: T_sun and the solve mask, I_0, the skylight), the image (rgb,
//! T_vol) and the largest edge depth (an atomic).

use std::time::Instant;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, read_back};

use super::Settings;
use super::cpu::{Lighting, check};
use crate::gpu::{
    FieldsAndSky, GatherView, Grid, RenderError, Sky, Timings, View, a3, bind, build,
    fields_and_sky, filled, gather_source, gather_view, sky_light_buffer, storage, timed_frame,
};
use crate::lighting::lattice::voxel_length;
use crate::{checks::FrameError, frame::Frame, image::Image, volume::MAX_FIELDS};

runtime::uniform! {
    /// `LightVoxel` of `gather.wgsl`: a voxel's [`Lighting`] in f32.
    pub struct LightVoxel as "LightVoxel" {
        /// The reduced sunlight T_sun per channel.
        pub sun: [f32; 3],
        /// 1 if in the diffusion solve, else 0.
        pub in_solve: f32,
        /// The diffusion's I_0 per channel.
        pub i0: [f32; 3],
        /// Padding.
        pub pad0: f32,
        /// The skylight's mean per channel.
        pub sky: [f32; 3],
        /// Padding.
        pub pad1: f32,
    }
}

runtime::uniform! {
    /// `MaxParams` of `gather.wgsl`.
    pub struct MaxParams as "MaxParams" {
        /// The camera.
        pub view: View,
        /// The grid and the ground.
        pub grid: Grid,
        /// Width, height.
        pub sizes: [u32; 2],
        /// The march's step (m).
        pub march_step: f32,
        /// Padding.
        pub pad_step: f32,
        /// The edge treatment's voxel length (h_x h_y h_z)^{1/3} (m).
        pub voxel_length: f32,
        /// The edge treatment's threshold T (a voxel's optical depth).
        pub edge_threshold: f32,
        /// Padding.
        pub pad0: f32,
        /// Padding.
        pub pad1: f32,
        /// Per field, σ_ext per channel (m²).
        pub sigma_ext: [[f32; 4]; MAX_FIELDS],
        /// The sun and the air.
        pub sky: Sky,
    }
}

/// The gather's WGSL ([`crate::gpu::gather_source`] puts the shared parts before it).
pub const GATHER_WGSL: &str = include_str!("gather.wgsl");

/// The gather's pipeline, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    /// The per-sun passes' pipelines, compiled on first use.
    per_sun: crate::lighting::Pipelines,
}

/// The model's whole shader module, as the renderer compiles it.
pub fn source() -> String {
    gather_source(GATHER_WGSL)
}

impl Renderer {
    /// Compiles `gather.wgsl` after the tables' and the slicing renderers' WGSL, `tables`'
    /// layout as bind group 0.
    pub fn new(gpu: &Gpu, tables: &GpuTables) -> Self {
        // Bindings: params, densities and lighting (read-only), image, largest edge depth.
        let (layout, pipelines) = build(
            gpu,
            tables,
            "photometeor max gather",
            source(),
            (5, true),
            &[1, 2],
            &["gather"],
        );
        let [pipeline] = <[_; 1]>::try_from(pipelines).expect("one pipeline");
        Self {
            layout,
            pipeline,
            per_sun: crate::lighting::Pipelines::default(),
        }
    }

    /// The per-sun passes on `gpu` (the adapter this renderer was built for), each compiled
    /// on its first use.
    pub fn per_sun<'a>(&'a self, gpu: &'a Gpu) -> crate::lighting::OnGpu<'a> {
        self.per_sun.on(gpu)
    }

    /// Steps 5–6 of the model for `frame` from `lighting` ([`super::cpu::light`] of a frame
    /// with the same grid and sun), as [`super::cpu::gather`]: the image and the largest edge
    /// depth the rays reached (checked against the bake's Poisson table, as the CPU does).
    pub fn gather(
        &self,
        gpu: &Gpu,
        tables: &Tables,
        gpu_tables: &GpuTables,
        frame: &Frame,
        settings: &Settings,
        lighting: &Lighting,
    ) -> Result<(Image, Timings, f64), RenderError> {
        let depth_max = check(tables, frame, settings)?;
        lighting.check_frame(frame)?;
        let device = &gpu.device;
        let start = Instant::now();
        let (w, h) = (frame.width, frame.height);
        let grid = &frame.grid;
        let voxels = grid.data.len();
        let GatherView { view, step } =
            gather_view(device, frame, std::mem::size_of::<LightVoxel>() as u64)?;
        let FieldsAndSky { sigma_ext, sky } = fields_and_sky(tables, frame);
        let params = MaxParams {
            view,
            grid: Grid::of(frame, tables.fields.len()),
            sizes: [w as u32, h as u32],
            march_step: step as f32,
            pad_step: 0.0,
            voxel_length: voxel_length(grid) as f32,
            edge_threshold: settings.threshold as f32,
            pad0: 0.0,
            pad1: 0.0,
            sigma_ext,
            sky,
        };
        let rows: Vec<LightVoxel> = (0..voxels)
            .map(|i| LightVoxel {
                sun: a3(lighting.t_sun[i]),
                in_solve: f32::from(u8::from(lighting.active[i])),
                i0: a3(lighting.i0[i]),
                pad0: 0.0,
                sky: a3(lighting.sky_mean[i]),
                pad1: 0.0,
            })
            .collect();
        let params = filled(
            device,
            "photometeor max params",
            bytemuck::bytes_of(&params),
            wgpu::BufferUsages::UNIFORM,
        );
        let density = filled(
            device,
            "photometeor max densities",
            bytemuck::cast_slice(&grid.data),
            wgpu::BufferUsages::STORAGE,
        );
        let lighting_buffer = filled(
            device,
            "photometeor max lighting",
            bytemuck::cast_slice(&rows),
            wgpu::BufferUsages::STORAGE,
        );
        let image = storage(device, "photometeor max image", 16 * (w * h) as u64, true);
        let largest = filled(
            device,
            "photometeor max largest edge depth",
            &[0u8; 16],
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let bind_group = bind(
            device,
            &self.layout,
            "photometeor max gather bindings",
            &[&params, &density, &lighting_buffer, &image, &largest],
            Some(&sky_light_buffer(
                device,
                frame,
                Some(lighting.shadow.gpu_rows()),
            )),
        );
        let (image, timings) = timed_frame(
            gpu,
            start,
            |pass| {
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &gpu_tables.bind_group, &[]);
                pass.set_bind_group(1, &bind_group, &[]);
                pass.dispatch_workgroups(w.div_ceil(8) as u32, h.div_ceil(8) as u32, 1);
            },
            &image,
            (w, h),
        )?;
        let largest = read_back(gpu, &largest, 16)?[0][0] as f64;
        if largest > depth_max {
            return Err(FrameError(format!(
                "an edge segment reached optical depth {largest:.3}, beyond the bake's Poisson \
                 table (poisson_max_depth = {depth_max}): bake with a larger [scene] \
                 poisson_max_depth or lower [render.max] threshold"
            ))
            .into());
        }
        Ok((image, timings, largest))
    }
}
