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
    COMPOSE_WGSL, Dispatch, RenderError, Timings, bind, build, check_sizes, field_and_sky_rows,
    filled, run_slices, slice_uniforms, storage, v4,
};
use crate::{Frame, Image, SUN_DIAMETER_DEG};

/// The renderer's WGSL (after [`runtime::gpu::WGSL`], [`crate::gpu::SLICING_WGSL`] and
/// [`COMPOSE_WGSL`]).
pub const RENDER_WGSL: &str = include_str!("render.wgsl");

/// Pipelines and layouts, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    clear: wgpu::ComputePipeline,
    eye: wgpu::ComputePipeline,
    light: wgpu::ComputePipeline,
    composite: wgpu::ComputePipeline,
}

impl Renderer {
    /// Compiles [`RENDER_WGSL`] after [`runtime::gpu::WGSL`] and builds the pipelines, with `tables`' layout
    /// as bind group 0.
    pub fn new(gpu: &Gpu, tables: &GpuTables) -> Self {
        let (layout, p) = build(
            gpu,
            tables,
            "photometeor render",
            &format!("{COMPOSE_WGSL}\n{RENDER_WGSL}"),
            6,
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

        let mut params: Vec<[f32; 4]> = Vec::new();
        let sun_dir = frame.sun.direction();
        let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
        params.push(v4(setup.eye, if setup.front_to_back { 1.0 } else { 0.0 }));
        params.push(v4(setup.forward, setup.tan_half_fov_y));
        params.push(v4(setup.right, setup.aspect));
        params.push(v4(setup.up, settings.xi));
        params.push(v4(setup.light, setup.slice_step));
        let continuum = match settings.light_update {
            crate::LightUpdate::Continuum => 1.0,
            crate::LightUpdate::Riley2004 => 0.0,
        };
        params.push(v4(setup.half, continuum));
        params.push(v4(setup.light_u, setup.light_origin[0]));
        params.push(v4(setup.light_w, setup.light_origin[1]));
        params.push([
            setup.light_texel[0] as f32,
            setup.light_texel[1] as f32,
            sun_dir[1] as f32,
            0.0,
        ]);
        params.push(v4(frame.grid.min_m, frame.ground_albedo));
        params.push(v4(frame.grid.max_m, 0.0));
        let [nx, ny, nz] = frame.grid.dims;
        let uints = |v: [u32; 4]| v.map(f32::from_bits);
        params.push(uints([
            nx as u32,
            ny as u32,
            nz as u32,
            tables.fields.len() as u32,
        ]));
        params.push(uints([w as u32, h as u32, res as u32, 0]));
        params.extend(field_and_sky_rows(tables, frame, sun_dir, cos_disk));
        let params = filled(
            device,
            "photometeor render params",
            bytemuck::cast_slice(&params),
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
