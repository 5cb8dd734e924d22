//! Biri, Arquès & Michelin 2006, "Real Time Rendering of Atmospheric Scattering and Volumetric
//! Shadows": single scattering of point and spot lights in homogeneous media, in constant time
//! per ray from the angular form of the in-scattering integral (§4.1, Eq. 2), with volumetric
//! shadows as sums of differences Γ(F) − Γ(E) over shadow planes (§4.2, §5.1.4–5.1.5) and a
//! constant ambient term for multiple scattering (§3), several bounded media blended (§5.2).
//!
//! The kernel comes from the bake (`<field>.biri.exr`, `tables::biri`): for any field's Ams_1,
//! either the exact primitive C(τ_h, θ) (`--biri-kernel exact`, the default) or the paper's
//! quartic c_0..c_4 (`polynomial`), fitted by least squares where the paper's annex gives
//! Taylor coefficients for four analytic phase functions only.
//!
//! # Where this departs from the paper
//! - The stencil passes (§5.1.5) are replaced by their per-pixel equivalent (the CPU
//!   reference, [`cpu`], and the GPU's compute shader, [`gpu`], alike): the
//!   list of the view ray's crossings with the silhouette planes, sorted by distance, the
//!   shadow count summed from its value at the eye ([`geometry`]'s module docs). This
//!   handles the camera in shadow (the paper's "slightly different strategy") and shadows in
//!   shadows (§5.1.4) without a special case, and needs no meshing of the shadow planes:
//!   Γ is evaluated exactly at each crossing instead of interpolated between plane vertices.
//! - Spot lights have a hard cone (the truth path tracer's); the cone's two crossings bound
//!   the lit part of the ray like shadow planes, where the paper integrates I_s(θ + β).
//! - Bounded media (§4.2) are axis-aligned boxes that do not overlap. For a light inside its
//!   medium the bounded form is exact: the eye's attenuation starts at the ray's entry x_A,
//!   a constant factor e^{k_t x_A}. For a light outside, the paper replaces the light path's
//!   length inside the medium by a constant R; here the constant is the length of the light
//!   path *outside* the medium, r_0, taken at the middle of each lit piece of the ray, so the
//!   kernel stays the table's: e^{−k_t (r − r_0)} = e^{k_t r_0} e^{−k_t r}.
//! - Surfaces are Lambertian (§5.1.2, L = ρ I cos θ_p e^{−k_t r_p}/(π r_p²)), the ground at
//!   y = 0 among them; hard shadows on them by a shadow ray.

pub mod cpu;
pub mod gpu;

use std::time::Instant;

use serde::{Deserialize, Serialize};

use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::gpu::RenderError;
use crate::model::{Device, Job, Model, Need, Pass, RenderResult, Rendered, image_need};
use crate::objects;
use crate::{checks::FrameError, frame::Frame};

/// Which form of the kernel's integral Γ uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// The exact primitive C(τ_h, θ) from the bake's table, interpolated.
    #[default]
    Exact,
    /// The paper's degree-4 polynomial (Eq. 2) with the bake's least-squares coefficients.
    Polynomial,
}

impl Kernel {
    /// The scene/CLI name: `exact` or `polynomial`.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "exact" => Some(Self::Exact),
            "polynomial" => Some(Self::Polynomial),
            _ => None,
        }
    }

    /// The name [`Kernel::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            Self::Exact => "exact",
            Self::Polynomial => "polynomial",
        }
    }
}

/// The model's settings, `[render.biri]`; its media, occluders and lights are the frame's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// The form of the kernel's integral (`--biri-kernel`).
    pub kernel: Kernel,
}

/// `--model biri`.
pub struct Biri;

impl Model for Biri {
    const NAME: &'static str = "biri";
    const ABOUT: &'static str = "Biri, Arquès & Michelin 2006: single scattering of [[light]]s \
        in homogeneous [[medium]]s in closed form, volumetric shadows of [[occluder]]s from \
        their silhouette planes";
    // 32-bit texels: the exact kernel adds Ams_1 bin values to the primitive.
    const TEXELS: TexelFormat = TexelFormat::F32;
    const GPU: bool = true;
    type Settings = Settings;
    type Renderer = gpu::Renderer;

    fn check(_: &Settings) -> Result<(), FrameError> {
        Ok(())
    }

    fn check_frame(_: &Settings, frame: &Frame) -> Result<(), FrameError> {
        check_scene(frame)?;
        let mut view = frame.clone();
        view.sun.elevation_deg = 90.0; // biri has no sun
        view.check_view()
    }

    fn memory(_: &Settings, pixels: u64, _dims: [usize; 3]) -> Vec<Need> {
        // Per pixel: the surface hit (32 B), the medium's light and crossings (40), the image:
        // measured 89 B.
        vec![image_need("the per-pixel stages and image", pixels, 96)]
    }

    fn renderer(gpu: &Gpu, tables: &GpuTables) -> Option<gpu::Renderer> {
        Some(gpu::Renderer::new(gpu, tables))
    }

    fn render_cpu(s: &Settings, job: &Job) -> Result<Rendered, RenderError> {
        let start = Instant::now();
        let (image, report) = cpu::render(job.tables, job.frame, s)?;
        let all = start.elapsed().as_secs_f64();
        let share = |s: f64| 100.0 * s / all.max(1e-12);
        let summary = format!(
            "analytic single scattering (CPU reference, {} threads, {} kernel): {}×{}, {} \
             light(s), {} shadow planes, {:.2} crossings per ray and light: {all:.3} s \
             (silhouettes {:.1} %, surfaces {:.1} %, medium and shadow planes {:.1} %)",
            rayon::current_num_threads(),
            s.kernel.name(),
            image.width,
            image.height,
            job.frame.lights.len(),
            report.shadow_planes,
            report.crossings_per_ray,
            share(report.silhouettes_s),
            share(report.surfaces_s),
            share(report.medium_s)
        );
        let pass = |name, seconds| Pass { name, seconds };
        Ok(Rendered {
            summary,
            image,
            extra: Vec::new(),
            figures: vec![
                ("shadow planes", report.shadow_planes as f64),
                ("crossings per ray and light", report.crossings_per_ray),
            ],
            passes: vec![
                pass("silhouettes", report.silhouettes_s),
                pass("surfaces", report.surfaces_s),
                pass("medium and shadow planes", report.medium_s),
            ],
        })
    }

    fn render_gpu(s: &Settings, job: &Job, on: Device<gpu::Renderer>) -> RenderResult {
        let (renderer, gpu, tables) = (on.renderer, on.gpu, on.tables);
        let (image, t) = renderer.render(gpu, job.tables, tables, job.frame, s)?;
        // Biri's upload includes the silhouettes, computed on the CPU.
        let summary = format!(
            "analytic single scattering ({}, {} kernel): {}×{}, {} light(s): silhouettes and {}",
            gpu.describe(),
            s.kernel.name(),
            image.width,
            image.height,
            job.frame.lights.len(),
            t.describe()
        );
        Ok(Rendered::plain(image, Pass::of_gpu(&t), summary))
    }

    /// Stage 2 alone (the surfaces, shaded and attenuated, no medium): the paper's Table 1
    /// splits the frame into stages this way.
    fn bench_parts(
        s: &Settings,
        job: &Job,
        on: Device<gpu::Renderer>,
    ) -> Result<Vec<Pass>, RenderError> {
        let (renderer, gpu, tables) = (on.renderer, on.gpu, on.tables);
        let (_, t) = renderer.render_stages(gpu, job.tables, tables, job.frame, s, true)?;
        Ok(vec![Pass {
            name: "stage 2 alone",
            seconds: t.frame,
        }])
    }
}

/// What the model needs of a scene and refuses in it: no density volumes, haze or sunlight (it
/// draws point and spot lights in homogeneous media), at least one medium and one light, media
/// that do not overlap, no light inside an occluder.
pub fn check_scene(frame: &Frame) -> Result<(), FrameError> {
    let bad = |s: String| Err(FrameError(s));
    if frame.grid != crate::volume::DensityGrid::empty() {
        return bad(
            "the scene has [[volume]] tables; --model biri draws homogeneous [[medium]] tables \
             only (render volumes with riley, miyazaki, max, coupled or truth)"
                .into(),
        );
    }
    if let Some(h) = &frame.haze {
        return bad(format!(
            "the scene has a [haze] layer (field {:?}); --model biri draws homogeneous \
             [[medium]] tables only",
            h.name
        ));
    }
    if frame.sun.irradiance.iter().any(|&v| v > 0.0) {
        return bad(format!(
            "[sun] irradiance = {:?}: --model biri draws point and spot lights only; set it to \
             [0, 0, 0] or leave out [sun]",
            frame.sun.irradiance
        ));
    }
    if frame.media.is_empty() {
        return bad(
            "--model biri needs at least one [[medium]] table (a homogeneous medium: field, \
             number_density_per_m3, and min_m/max_m for a box)"
                .into(),
        );
    }
    if frame.lights.is_empty() {
        return bad("--model biri needs at least one [[light]]: nothing lights the medium".into());
    }
    objects::check_media(&frame.media)?;
    objects::check_lights(&frame.lights, &frame.occluders)
}
