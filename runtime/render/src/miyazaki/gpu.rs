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
    Dispatch, Grid, RenderError, Sky, TexturePlane, Timings, View, a3, a4, bind, build,
    check_sizes, filled, run_slices, slice_uniforms, slicing_source, storage, v3,
};
use crate::{frame::Frame, image::Image, volume::MAX_FIELDS};

runtime::uniform! {
    /// `Slices` of `svs.wgsl`: the shadow-view slices.
    pub struct Slices as "Slices" {
        /// Unit vector towards the sun.
        pub to_sun: [f32; 3],
        /// The slice spacing Δ (m).
        pub spacing: f32,
        /// The slices' unit normal.
        pub normal: [f32; 3],
        /// Δs, the sun's path per slice (m).
        pub sun_path: f32,
        /// The lower plane value of the slices' range (m).
        pub plane_min: f32,
        /// The upper plane value (m).
        pub plane_max: f32,
        /// 1: slices back to front, 0: front to back.
        pub back_to_front: u32,
        /// Padding.
        pub pad: u32,
    }
}

runtime::uniform! {
    /// `Shading` of `svs.wgsl`.
    pub struct Shading as "Shading" {
        /// k_multi (1/sr).
        pub k_multi: f32,
        /// 1: the Cornette–Shanks phase function.
        pub cornette_shanks: u32,
        /// The haze's field + 1 (0: none).
        pub haze_field: u32,
        /// Padding.
        pub pad: u32,
    }
}

runtime::uniform! {
    /// `Haze` of `svs.wgsl`: the haze layer.
    pub struct Haze as "Haze" {
        /// N_0 σ_ext per channel (1/m).
        pub ext: [f32; 3],
        /// 1/H_haze (1/m).
        pub inv_height: f32,
        /// N_0 σ_sca per channel (1/m).
        pub sca: [f32; 3],
        /// Padding.
        pub pad: f32,
    }
}

runtime::uniform! {
    /// `SvsParams` of `svs.wgsl`.
    pub struct SvsParams as "SvsParams" {
        /// The camera.
        pub view: View,
        /// The shadow-view slices.
        pub slices: Slices,
        /// The shadow surface.
        pub shadow: TexturePlane,
        /// k_multi, the phase function, the haze's field.
        pub shading: Shading,
        /// The grid and the ground.
        pub grid: Grid,
        /// Width, height, shadow resolution, 0.
        pub sizes: [u32; 4],
        /// Per field, σ_ext per channel (m²).
        pub sigma_ext: [[f32; 4]; MAX_FIELDS],
        /// Per field, the Cornette–Shanks asymmetry per channel.
        pub g: [[f32; 4]; MAX_FIELDS],
        /// The sun and the air (Rayleigh's β_sl).
        pub sky: Sky,
        /// The haze layer.
        pub haze: Haze,
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
    let haze = frame.haze.as_ref().map(|h| (&tables.fields[h.field], h));
    let per_field = |f: &dyn Fn(&runtime::FieldTable) -> [f64; 3]| -> [[f32; 4]; MAX_FIELDS] {
        std::array::from_fn(|i| tables.fields.get(i).map_or([0.0; 4], |t| a4(f(t), 0.0)))
    };
    SvsParams {
        view: View::of(frame, s.axes),
        slices: Slices {
            to_sun: v3(s.to_sun),
            spacing: s.step as f32,
            normal: v3(s.normal),
            sun_path: s.sun_step as f32,
            plane_min: s.range.0 as f32,
            plane_max: s.range.1 as f32,
            back_to_front: u32::from(s.back_to_front),
            pad: 0,
        },
        shadow: TexturePlane::new((s.shadow_u, s.shadow_w), s.shadow_origin, s.shadow_texel),
        shading: Shading {
            k_multi: settings.k_multi as f32,
            cornette_shanks: u32::from(settings.phase == SvsPhase::CornetteShanks),
            haze_field: frame.haze.as_ref().map_or(0, |h| h.field as u32 + 1),
            pad: 0,
        },
        grid: Grid::of(frame, tables.fields.len()),
        sizes: [w as u32, h as u32, res as u32, 0],
        sigma_ext: per_field(&|f| f.sigma_ext_m2),
        g: per_field(&|f| super::cpu::asymmetry(f, tables.theta_step_deg)),
        sky: Sky::of(frame),
        haze: Haze {
            ext: a3(haze.map_or([0.0; 3], |(f, h)| {
                f.sigma_ext_m2.map(|e| e * h.number_density_per_m3)
            })),
            inv_height: haze.map_or(0.0, |(_, h)| (1.0 / h.scale_height_m) as f32),
            sca: a3(haze.map_or([0.0; 3], |(f, h)| {
                f.sigma_sca_m2.map(|e| e * h.number_density_per_m3)
            })),
            pad: 0.0,
        },
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
