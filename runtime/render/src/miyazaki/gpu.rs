//! The shadow-view slices on wgpu compute shaders (`svs.wgsl` after the tables' WGSL and the
//! slicing renderers' shared pieces): one `clear` (which also fills the per-pixel Mie
//! scattering texture), then per slice a `shadow_slice` and an `eye_slice` dispatch (the
//! shadow surface first, §4.1), then `composite`. Bind group 1: params uniform, densities,
//! shadow surface (g_sun_cl rgb), eye buffer (S, α*, T_cl per pixel), image (rgb, T_vol),
//! slice uniform (dynamic offset), pixel texture.

use std::time::Instant;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables};

use super::{Settings, SvsPhase};
use crate::gpu::{
    Dispatch, RenderError, Timings, a4, bind, build, check_sizes, filled, run_slices,
    slice_uniforms, slicing_source, storage, v4,
};
use crate::{camera::SUN_DIAMETER_DEG, frame::Frame, image::Image, volume::MAX_FIELDS};

runtime::uniform! {
    /// `SvsParams` of `svs.wgsl` (its comments say what each w holds).
    pub struct SvsParams as "SvsParams" {
        /// Eye (m); w = 1 back to front, 0 front to back.
        pub eye: [f32; 4],
        /// View direction; w = tan(fov_y / 2).
        pub forward: [f32; 4],
        /// Right axis; w = aspect.
        pub right: [f32; 4],
        /// Up axis; w = k_multi (1/sr).
        pub up: [f32; 4],
        /// Unit vector towards the sun; w = slice spacing Δ (m).
        pub to_sun: [f32; 4],
        /// The slices' unit normal; w = Δs, the sun's path per slice (m).
        pub normal: [f32; 4],
        /// Shadow-surface axis u; w = its origin along u.
        pub shadow_u: [f32; 4],
        /// Shadow-surface axis w; w = its origin along w.
        pub shadow_w: [f32; 4],
        /// Texel size u, w (m); z = ground albedo; w = 1: Cornette–Shanks.
        pub shadow_texel: [f32; 4],
        /// Grid box's lower corner; w = lower plane value of the slices' range.
        pub grid_min: [f32; 4],
        /// Grid box's upper corner; w = upper plane value.
        pub grid_max: [f32; 4],
        /// nx, ny, nz, field count.
        pub grid_dims: [u32; 4],
        /// Width, height, shadow resolution, haze field + 1 (0: none).
        pub sizes: [u32; 4],
        /// Per field, σ_ext per channel (m²).
        pub sigma_ext: [[f32; 4]; MAX_FIELDS],
        /// Per field, the Cornette–Shanks asymmetry per channel.
        pub g: [[f32; 4]; MAX_FIELDS],
        /// Rayleigh β_sl per channel (1/m); w = 1/H.
        pub sky_beta: [f32; 4],
        /// Haze N_0 σ_ext per channel (1/m); w = 1/H_haze.
        pub haze: [f32; 4],
        /// Haze N_0 σ_sca per channel (1/m); w = cos of the disk radius.
        pub haze_sca: [f32; 4],
        /// Irradiance per channel; w = disk solid angle (sr).
        pub irradiance: [f32; 4],
    }
}

/// The model's WGSL (after `runtime::gpu::WGSL` and `crate::gpu::SLICING_WGSL`).
pub const SVS_WGSL: &str = include_str!("svs.wgsl");

/// Pipelines and layouts, built once.
pub struct Renderer {
    layout: wgpu::BindGroupLayout,
    clear: wgpu::ComputePipeline,
    shadow: wgpu::ComputePipeline,
    eye: wgpu::ComputePipeline,
    composite: wgpu::ComputePipeline,
}

/// The model's uniform for `frame` with the slicing geometry `s`.
fn params(tables: &Tables, frame: &Frame, settings: &Settings, s: &super::SvsSetup) -> SvsParams {
    let (w, h, res) = (frame.width, frame.height, settings.light_resolution);
    let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
    let (forward, right, up) = s.axes;
    let haze = frame.haze.as_ref().map(|h| (&tables.fields[h.field], h));
    let [nx, ny, nz] = frame.grid.dims;
    let per_field = |f: &dyn Fn(&runtime::FieldTable) -> [f64; 3]| -> [[f32; 4]; MAX_FIELDS] {
        std::array::from_fn(|i| tables.fields.get(i).map_or([0.0; 4], |t| a4(f(t), 0.0)))
    };
    SvsParams {
        eye: v4(s.eye, if s.back_to_front { 1.0 } else { 0.0 }),
        forward: v4(forward, s.tan_half_fov_y),
        right: v4(right, w as f64 / h as f64),
        up: v4(up, settings.k_multi),
        to_sun: v4(s.to_sun, s.step),
        normal: v4(s.normal, s.sun_step),
        shadow_u: v4(s.shadow_u, s.shadow_origin[0]),
        shadow_w: v4(s.shadow_w, s.shadow_origin[1]),
        shadow_texel: [
            s.shadow_texel[0] as f32,
            s.shadow_texel[1] as f32,
            frame.ground_albedo as f32,
            if settings.phase == SvsPhase::CornetteShanks {
                1.0
            } else {
                0.0
            },
        ],
        grid_min: v4(frame.grid.min_m, s.range.0),
        grid_max: v4(frame.grid.max_m, s.range.1),
        grid_dims: [nx as u32, ny as u32, nz as u32, tables.fields.len() as u32],
        sizes: [
            w as u32,
            h as u32,
            res as u32,
            frame.haze.as_ref().map_or(0, |h| h.field as u32 + 1),
        ],
        sigma_ext: per_field(&|f| f.sigma_ext_m2),
        g: per_field(&|f| super::cpu::asymmetry(f, tables.theta_step_deg)),
        sky_beta: a4(
            frame.atmosphere.beta_sea_level_per_m,
            1.0 / frame.atmosphere.scale_height_m,
        ),
        haze: haze.map_or([0.0; 4], |(f, h)| {
            a4(
                f.sigma_ext_m2.map(|e| e * h.number_density_per_m3),
                1.0 / h.scale_height_m,
            )
        }),
        haze_sca: a4(
            haze.map_or([0.0; 3], |(f, h)| {
                f.sigma_sca_m2.map(|e| e * h.number_density_per_m3)
            }),
            cos_disk,
        ),
        irradiance: a4(
            frame.sun.irradiance,
            std::f64::consts::TAU * (1.0 - cos_disk),
        ),
    }
}

/// The model's whole shader module, as the renderer compiles it.
pub fn source() -> String {
    slicing_source(SVS_WGSL)
}

impl Renderer {
    /// Compiles the shaders and builds the pipelines, with `tables`' layout as bind group 0.
    pub fn new(gpu: &Gpu, tables: &GpuTables) -> Self {
        let (layout, p) = build(
            gpu,
            tables,
            "photometeor svs",
            source(),
            (7, false),
            &[1],
            &["clear", "shadow_slice", "eye_slice", "composite"],
        );
        let [clear, shadow, eye, composite] = <[_; 4]>::try_from(p).expect("four pipelines");
        Self {
            clear,
            shadow,
            eye,
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
        settings: &Settings,
    ) -> Result<(Image, Timings), RenderError> {
        let s = super::setup(frame, settings)?;
        crate::shading::check_fields(tables, frame)?;
        let device = &gpu.device;
        let start = Instant::now();
        let (w, h, res) = (frame.width, frame.height, settings.light_resolution);
        check_sizes(
            device,
            &[
                ("density grid bytes", 16 * frame.grid.data.len() as u64),
                ("eye buffer bytes", 48 * (w * h) as u64),
                ("pixel texture bytes", 80 * (w * h) as u64),
                ("shadow surface bytes", 16 * (res * res) as u64),
            ],
        )?;
        let params = params(tables, frame, settings, &s);
        let params = filled(
            device,
            "photometeor svs params",
            bytemuck::bytes_of(&params),
            wgpu::BufferUsages::UNIFORM,
        );
        let density = filled(
            device,
            "photometeor svs densities",
            bytemuck::cast_slice(&frame.grid.data),
            wgpu::BufferUsages::STORAGE,
        );
        let shadow = storage(
            device,
            "photometeor shadow surface",
            16 * (res * res) as u64,
            false,
        );
        let eye_buffer = storage(
            device,
            "photometeor svs eye buffer",
            48 * (w * h) as u64,
            false,
        );
        let pixel_tex = storage(
            device,
            "photometeor svs pixel texture",
            80 * (w * h) as u64,
            false,
        );
        let image = storage(device, "photometeor svs image", 16 * (w * h) as u64, true);
        let planes: Vec<f64> = (0..settings.slices).map(|k| s.plane(k)).collect();
        let (slice_buffer, stride) = slice_uniforms(device, &planes);
        let bind_group = bind(
            device,
            &self.layout,
            "photometeor svs bindings",
            &[
                &params,
                &density,
                &shadow,
                &eye_buffer,
                &image,
                &slice_buffer,
                &pixel_tex,
            ],
            None,
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
                    Dispatch(&self.shadow, (res, res)),
                    Dispatch(&self.eye, (w, h)),
                ],
                Dispatch(&self.composite, (w, h)),
            ),
            &image,
            (w, h),
        )?)
    }
}
