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

use crate::objects::{Medium, Occluder, Region};

/// Which form of the kernel's integral Γ uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
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

/// The `--model biri` part of a scene.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BiriSettings {
    /// `[render] biri_kernel` / `--biri-kernel`.
    pub kernel: Kernel,
    /// `[[medium]]` tables.
    pub media: Vec<Medium>,
    /// `[[occluder]]` tables.
    pub occluders: Vec<Occluder>,
}

/// A setting the model cannot use, named with its allowed range.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SettingsError(pub String);

impl BiriSettings {
    /// The checks made before anything is baked: media that overlap or more than one medium
    /// with one everywhere, and lights inside an occluder or a medium box's edge cases.
    pub fn check(&self, lights: &[crate::objects::Light]) -> Result<(), SettingsError> {
        let bad = |s: String| Err(SettingsError(s));
        if self.media.is_empty() {
            return bad(
                "--model biri needs at least one [[medium]] table (a homogeneous medium: \
                 field, number_density_per_m3, and min_m/max_m for a box)"
                    .into(),
            );
        }
        if lights.is_empty() {
            return bad(
                "--model biri needs at least one [[light]]: nothing lights the medium".into(),
            );
        }
        let everywhere = self
            .media
            .iter()
            .position(|m| m.region == Region::Everywhere);
        if let Some(i) = everywhere
            && self.media.len() > 1
        {
            return bad(format!(
                "[[medium]] {} fills the whole scene, so it cannot share it with {} other \
                 medium/media (give each a box, min_m and max_m, that do not overlap)",
                i + 1,
                self.media.len() - 1
            ));
        }
        for (i, a) in self.media.iter().enumerate() {
            for (j, b) in self.media.iter().enumerate().skip(i + 1) {
                if let (
                    Region::Box {
                        min_m: a0,
                        max_m: a1,
                    },
                    Region::Box {
                        min_m: b0,
                        max_m: b1,
                    },
                ) = (a.region, b.region)
                    && a0.cmplt(b1).all()
                    && b0.cmplt(a1).all()
                {
                    return bad(format!(
                        "[[medium]] {} and [[medium]] {} overlap: the media of one scene must \
                         not (each ray's attenuation is one medium's at a time)",
                        i + 1,
                        j + 1
                    ));
                }
            }
        }
        self.check_lights(lights)
    }

    /// Refuses a light inside an occluder (for every model that draws occluders).
    pub fn check_lights(&self, lights: &[crate::objects::Light]) -> Result<(), SettingsError> {
        for (i, l) in lights.iter().enumerate() {
            for (k, o) in self.occluders.iter().enumerate() {
                if o.contains(l.position_m) {
                    return Err(SettingsError(format!(
                        "[[light]] {}: position_m = {:?} is inside [[occluder]] {}: its light \
                         could never leave it",
                        i + 1,
                        l.position_m.to_array(),
                        k + 1
                    )));
                }
            }
        }
        Ok(())
    }
}
