//! The `max` model's final gather on wgpu (`gather.wgsl`): one compute invocation per pixel
//! marches the ray through the grid as [`super::cpu::gather`] does, in f32, reading the
//! per-voxel [`Lighting`] the CPU computed (steps 1–4: the reduced sun and sky, the diffusion
//! solve, the clear-air propagation). That lighting depends on the sun, the sky and the cloud,
//! not on the camera: a camera that moves needs only this gather again, which is where a GPU
//! pays (module docs of [`super`]; `photometeor bench render --model max` times both).
//!
//! Bind group 0: the tables ([`GpuTables`]: `ams_mix` for Ams_1, `poisson` for the Poisson
//! mixtures). Bind group 1: the params uniform, the densities, the lighting (three rows per
//! voxel: T_sun and the solve mask, I_0, the skylight), the image (rgb, T_vol) and the largest
//! edge depth (an atomic).

use std::time::Instant;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, read_back};

use super::Settings;
use super::cpu::{Lighting, check, voxel_length};
use crate::gpu::{
    COMPOSE_WGSL, RenderError, Timings, bind, build, check_sizes, field_and_sky_rows, filled,
    storage, timed_frame, v4,
};
use crate::{Frame, FrameError, Image, SUN_DIAMETER_DEG};

/// The gather's WGSL (after [`runtime::gpu::WGSL`], the slicing renderers' WGSL and [`COMPOSE_WGSL`]).
pub const GATHER_WGSL: &str = include_str!("gather.wgsl");

/// The gather's pipeline, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
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
            &format!("{COMPOSE_WGSL}\n{GATHER_WGSL}"),
            5,
            &[1, 2],
            &["gather"],
        );
        let [pipeline] = <[_; 1]>::try_from(pipelines).expect("one pipeline");
        Self { layout, pipeline }
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
        check_sizes(
            device,
            &[
                ("density grid bytes", 16 * voxels as u64),
                ("lighting bytes", 48 * voxels as u64),
                ("image bytes", 16 * (w * h) as u64),
            ],
        )?;
        let (forward, right, up) = frame
            .camera
            .axes()
            .ok_or_else(|| FrameError("camera look_at_m equals position_m".into()))?;
        let size: [f64; 3] =
            std::array::from_fn(|a| (grid.max_m[a] - grid.min_m[a]) / grid.dims[a] as f64);
        let step = 0.5 * size.iter().copied().fold(f64::INFINITY, f64::min);
        let sun_dir = frame.sun.direction();
        let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
        let uints = |v: [u32; 4]| v.map(f32::from_bits);
        let mut params: Vec<[f32; 4]> = vec![
            v4(frame.camera.position_m, step),
            v4(forward, (frame.camera.fov_deg.to_radians() / 2.0).tan()),
            v4(right, w as f64 / h as f64),
            v4(up, voxel_length(grid)),
            v4(grid.min_m, frame.ground_albedo),
            v4(grid.max_m, settings.threshold),
            uints([
                grid.dims[0] as u32,
                grid.dims[1] as u32,
                grid.dims[2] as u32,
                tables.fields.len() as u32,
            ]),
            uints([w as u32, h as u32, 0, 0]),
        ];
        params.extend(field_and_sky_rows(tables, frame, sun_dir, cos_disk));
        let rgb = |v: &[f64; 3], w: f32| [v[0] as f32, v[1] as f32, v[2] as f32, w];
        let mut rows: Vec<[f32; 4]> = Vec::with_capacity(3 * voxels);
        for i in 0..voxels {
            rows.push(rgb(
                &lighting.t_sun[i],
                f32::from(u8::from(lighting.active[i])),
            ));
            rows.push(rgb(&lighting.i0[i], 0.0));
            rows.push(rgb(&lighting.sky_mean[i], 0.0));
        }
        let params = filled(
            device,
            "photometeor max params",
            bytemuck::cast_slice(&params),
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
