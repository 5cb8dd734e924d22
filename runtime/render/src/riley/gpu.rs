//! The renderer on wgpu compute shaders (`render.wgsl` after the tables' WGSL): one `clear`,
//! then per slice an `eye_slice` and a `light_slice` dispatch (each dispatch sees the previous
//! one's writes), then `composite`. The slice plane comes from a uniform array read with a
//! dynamic offset. Bind group 1 (labelled, its layout built once per [`Renderer`]):
//! params uniform, densities (`array<vec4<f32>>`, one channel per field), light buffer
//! (I rgb, n), eye buffer (L, T pairs), image (rgb, T_vol), slice uniform.

use std::time::Instant;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables};

use crate::gpu::{
    COMPOSE_WGSL, Dispatch, FieldsAndSky, Grid, RenderError, Sky, TexturePlane, Timings, View,
    bind, build, check_sizes, fields_and_sky, filled, run_slices, sky_light_buffer, slice_uniforms,
    slicing_source, storage, v3,
};
use crate::{frame::Frame, image::Image, volume::MAX_FIELDS};

/// The renderer's WGSL (after [`runtime::gpu::WGSL`], [`crate::gpu::SLICING_WGSL`] and
/// [`COMPOSE_WGSL`]).
pub const RENDER_WGSL: &str = include_str!("render.wgsl");

runtime::uniform! {
    /// `Slices` of `render.wgsl`: the half-angle slices and how light crosses them.
    pub struct Slices as "Slices" {
        /// The sunlight's direction of travel.
        pub light: [f32; 3],
        /// The slice spacing Δ (m).
        pub spacing: f32,
        /// The half-angle vector.
        pub half_vector: [f32; 3],
        /// 1: the continuum light update, 0: Eq. 25 as printed.
        pub continuum: u32,
        /// ξ (1/sr).
        pub xi: f32,
        /// 1: slices front to back, 0: back to front.
        pub front_to_back: u32,
        /// Padding.
        pub pad0: u32,
        /// Padding.
        pub pad1: u32,
    }
}

runtime::uniform! {
    /// `RenderParams` of `render.wgsl`.
    pub struct RenderParams as "RenderParams" {
        /// The camera.
        pub view: View,
        /// The half-angle slices.
        pub slices: Slices,
        /// The light buffer.
        pub light_buffer: TexturePlane,
        /// The grid and the ground.
        pub grid: Grid,
        /// Width, height, light resolution, 0.
        pub sizes: [u32; 4],
        /// Per field, σ_ext per channel (m²).
        pub sigma_ext: [[f32; 4]; MAX_FIELDS],
        /// The sun and the air.
        pub sky: Sky,
    }
}

/// Pipelines and layouts, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    clear: wgpu::ComputePipeline,
    eye: wgpu::ComputePipeline,
    light: wgpu::ComputePipeline,
    composite: wgpu::ComputePipeline,
}

/// The model's whole shader module, as the renderer compiles it.
pub fn source() -> String {
    slicing_source(&format!("{COMPOSE_WGSL}\n{RENDER_WGSL}"))
}

impl Renderer {
    /// Compiles [`RENDER_WGSL`] after [`runtime::gpu::WGSL`] and builds the pipelines, with `tables`' layout
    /// as bind group 0.
    pub fn new(gpu: &Gpu, tables: &GpuTables) -> Self {
        let (layout, p) = build(
            gpu,
            tables,
            "photometeor render",
            source(),
            (6, true),
            &[1],
            &["clear", "eye_slice", "light_slice", "composite"],
        );
        let [clear, eye, light, composite] = <[_; 4]>::try_from(p).expect("four pipelines");
        Self {
            clear,
            eye,
            light,
            composite,
            layout,
        }
    }

    /// Renders `frame` with `tables` (on the GPU as `gpu_tables`; field i = grid channel i).
    pub fn render(
        &self,
        gpu: &Gpu,
        tables: &Tables,
        gpu_tables: &GpuTables,
        frame: &Frame,
        settings: &super::Settings,
    ) -> Result<(Image, Timings), RenderError> {
        let setup = super::Setup::new(frame, settings)?;
        crate::shading::check_fields(tables, frame)?;
        let device = &gpu.device;
        let start = Instant::now();
        let (w, h, res) = (frame.width, frame.height, settings.light_resolution);
        let voxels = frame.grid.data.len();
        check_sizes(
            device,
            &[
                ("density grid bytes", 16 * voxels as u64),
                ("eye buffer bytes", 32 * (w * h) as u64),
                ("light buffer bytes", 16 * (res * res) as u64),
            ],
        )?;

        let FieldsAndSky { sigma_ext, sky } = fields_and_sky(tables, frame);
        let continuum = match settings.light_update {
            super::LightUpdate::Continuum => 1,
            super::LightUpdate::Riley2004 => 0,
        };
        let params = RenderParams {
            view: View::of(frame, (setup.forward, setup.right, setup.up)),
            slices: Slices {
                light: v3(setup.light),
                spacing: setup.slice_step as f32,
                half_vector: v3(setup.half),
                continuum,
                xi: settings.xi as f32,
                front_to_back: u32::from(setup.front_to_back),
                pad0: 0,
                pad1: 0,
            },
            light_buffer: TexturePlane::new(
                (setup.light_u, setup.light_w),
                setup.light_origin,
                setup.light_texel,
            ),
            grid: Grid::of(frame, tables.fields.len()),
            sizes: [w as u32, h as u32, res as u32, 0],
            sigma_ext,
            sky,
        };
        let params = filled(
            device,
            "photometeor render params",
            bytemuck::bytes_of(&params),
            wgpu::BufferUsages::UNIFORM,
        );
        let density = filled(
            device,
            "photometeor densities",
            bytemuck::cast_slice(&frame.grid.data),
            wgpu::BufferUsages::STORAGE,
        );
        let light_buffer = storage(
            device,
            "photometeor light buffer",
            16 * (res * res) as u64,
            false,
        );
        let eye_buffer = storage(device, "photometeor eye buffer", 32 * (w * h) as u64, false);
        let image = storage(device, "photometeor image", 16 * (w * h) as u64, true);
        let planes: Vec<f64> = (0..settings.slices)
            .map(|k| setup.slice_start + k as f64 * setup.slice_step)
            .collect();
        let (slice_buffer, stride) = slice_uniforms(device, &planes);
        let bind_group = bind(
            device,
            &self.layout,
            "photometeor render bindings",
            &[
                &params,
                &density,
                &light_buffer,
                &eye_buffer,
                &image,
                &slice_buffer,
            ],
            Some(&sky_light_buffer(device, frame, None)),
        );
        Ok(run_slices(
            gpu,
            gpu_tables,
            &bind_group,
            start,
            (settings.slices, stride),
            (
                Dispatch(&self.clear, (w.max(res), h.max(res))),
                &[
                    Dispatch(&self.eye, (w, h)),
                    Dispatch(&self.light, (res, res)),
                ],
                Dispatch(&self.composite, (w, h)),
            ),
            &image,
            (w, h),
        )?)
    }
}
