//! The reference renderer: the model of [`super`] in plain Rust, f64, one pixel and one
//! light texel at a time (rayon across them). Slow; the GPU path is tested against it.

use rayon::prelude::*;

use glam::DVec3;

use runtime::sample;
use runtime::{FieldTable, Tables};

use super::{Settings, Setup};
use crate::shading::{bilinear_taps, check_fields, coefficients, compose, over_footprint};
use crate::skylight::SkyLight;
use crate::{
    checks::FrameError, frame::Frame, image::Image, riley::LightUpdate, volume::MAX_FIELDS,
};

/// Light-buffer texel: intensity per channel (fraction of the sunlight at that height) and the
/// expected scatter count n.
#[derive(Clone, Copy)]
struct Light {
    intensity: [f64; 3],
    n: f64,
}

impl Setup {
    /// The point where the light texel (a, b)'s ray meets slice plane value `c`.
    pub fn light_point(&self, a: usize, b: usize, c: f64) -> DVec3 {
        let q = (self.light_origin[0] + (a as f64 + 0.5) * self.light_texel[0]) * self.light_u
            + (self.light_origin[1] + (b as f64 + 0.5) * self.light_texel[1]) * self.light_w;
        let t = (c - self.half.dot(q)) / self.half.dot(self.light);
        q + t * self.light
    }

    /// Continuous light-buffer coordinates of `p` (texel centres at integers).
    pub fn light_coords(&self, p: DVec3) -> [f64; 2] {
        [
            (self.light_u.dot(p) - self.light_origin[0]) / self.light_texel[0] - 0.5,
            (self.light_w.dot(p) - self.light_origin[1]) / self.light_texel[1] - 0.5,
        ]
    }
}

fn bilinear(buffer: &[Light], res: usize, uv: [f64; 2]) -> Light {
    let mut out = Light {
        intensity: [0.0; 3],
        n: 0.0,
    };
    for (i, w) in bilinear_taps(res, uv) {
        for c in 0..3 {
            out.intensity[c] += w * buffer[i].intensity[c];
        }
        out.n += w * buffer[i].n;
    }
    out
}

/// Carries a light-buffer value across optical path `length` (m) at a point with extinction
/// `ext`, scattering `sca` and densities `rho` (Eqs. 21, 25 or the continuum update; n ← n +
/// α τ in green).
fn cross_slab(
    texel: &mut Light,
    fields: &[&FieldTable],
    ext: &[f64; 3],
    sca: &[f64; 3],
    rho: &[f64; MAX_FIELDS],
    length: f64,
    update: LightUpdate,
) {
    let tau: [f64; 3] = ext.map(|e| e * length);
    let f = sample::forward_fraction_mix(fields, rho, texel.n + 1.0 + tau[1]);
    for ch in 0..3 {
        if ext[ch] > 0.0 {
            texel.intensity[ch] *= update.keep(tau[ch], sca[ch] / ext[ch], f[ch]);
        }
    }
    if ext[1] > 0.0 {
        texel.n += sca[1] / ext[1] * tau[1];
    }
}

/// What every step of a frame reads: the frame, its settings and geometry, the fields.
struct Slicer<'a> {
    tables: &'a Tables,
    frame: &'a Frame,
    settings: &'a Settings,
    setup: Setup,
    fields: Vec<&'a FieldTable>,
    /// Δ_l, the light's path through one slab.
    light_thickness: f64,
    /// The sun direction's y component.
    l_y: f64,
    /// The air's light beyond single scattering.
    sky: SkyLight,
}

/// A pixel's volume radiance L and transparency T per channel, accumulated over the slices.
type EyeTexel = ([f64; 3], [f64; 3]);

impl Slicer<'_> {
    /// Step 1 of the module docs (Eq. 26): the slab of slice plane `c` along the pixel's ray
    /// from `o` along `d`, lit by the light buffer, added to the pixel's (L, T).
    fn eye_slab(&self, px: &mut EyeTexel, (o, d): (DVec3, DVec3), c: f64, light: &[Light]) {
        let (setup, settings) = (&self.setup, self.settings);
        let hd = setup.half.dot(d);
        if hd.abs() < 1e-9 {
            return;
        }
        let t = (c - setup.half.dot(o)) / hd;
        if t <= 0.0 {
            return;
        }
        let p = o + t * d;
        let rho = self.frame.grid.sample(p);
        let (ext, sca) = coefficients(&self.fields, &rho);
        if ext.iter().all(|&e| e <= 0.0) {
            return;
        }
        let mut lit = bilinear(light, settings.light_resolution, setup.light_coords(p));
        if settings.light_update == LightUpdate::Continuum {
            // The light at the slab's middle: the buffer holds it at the slab's entry.
            cross_slab(
                &mut lit,
                &self.fields,
                &ext,
                &sca,
                &rho,
                self.light_thickness / 2.0,
                settings.light_update,
            );
        }
        let sun = self.frame.atmosphere.sunlight(p[1], self.l_y);
        let phase = sample::mix(
            &self.fields,
            &rho,
            self.tables.theta_step_deg,
            lit.n + 1.0,
            -setup.light.dot(d),
        );
        let thickness = setup.slice_step / hd.abs();
        for ch in 0..3 {
            if ext[ch] <= 0.0 {
                continue;
            }
            let slab = (-ext[ch] * thickness).exp();
            let scattered = lit.intensity[ch]
                * sun[ch]
                * self.frame.sun.irradiance[ch]
                * (phase[ch] + settings.xi)
                * (sca[ch] / ext[ch])
                * (1.0 - slab);
            let (l, tr) = (&mut px.0[ch], &mut px.1[ch]);
            if setup.front_to_back {
                *l += *tr * scattered;
            } else {
                *l = scattered + slab * *l;
            }
            *tr *= slab;
        }
    }

    /// Step 2 (Eqs. 21, 25): light texel `i` carried across slice plane `c`.
    fn light_slab(&self, texel: &mut Light, i: usize, c: f64) {
        let res = self.settings.light_resolution;
        let p = self.setup.light_point(i % res, i / res, c);
        let rho = self.frame.grid.sample(p);
        let (ext, sca) = coefficients(&self.fields, &rho);
        if ext.iter().all(|&e| e <= 0.0) {
            return;
        }
        cross_slab(
            texel,
            &self.fields,
            &ext,
            &sca,
            &rho,
            self.light_thickness,
            self.settings.light_update,
        );
    }

    /// The pixel of the ray from `o` along `d` composed around its volume light: the ground is
    /// lit through the final light buffer (1 outside its footprint, where no volume is).
    fn pixel(
        &self,
        (l_vol, t_vol): EyeTexel,
        (o, d): (DVec3, DVec3),
        light: &[Light],
    ) -> ([f32; 3], f32) {
        let res = self.settings.light_resolution;
        let ground_lit = |p: DVec3| {
            let uv = self.setup.light_coords(p);
            if over_footprint(res, uv) {
                bilinear(light, res, uv).intensity
            } else {
                [1.0; 3]
            }
        };
        (
            compose(
                self.frame,
                &self.sky,
                o,
                d,
                l_vol,
                (t_vol, t_vol),
                ground_lit,
            ),
            t_vol[1] as f32,
        )
    }
}

/// Renders `frame` with the fields of `tables` (field i = grid channel i).
pub fn render(tables: &Tables, frame: &Frame, settings: &Settings) -> Result<Image, FrameError> {
    let setup = Setup::new(frame, settings)?;
    check_fields(tables, frame)?;
    let slicer = Slicer {
        tables,
        frame,
        settings,
        fields: tables.fields.iter().collect(),
        light_thickness: setup.slice_step / setup.half.dot(setup.light),
        l_y: frame.sun.direction()[1],
        sky: SkyLight::of(frame),
        setup,
    };
    let (w, h) = (frame.width, frame.height);
    let res = settings.light_resolution;
    let rays: Vec<(DVec3, DVec3)> = (0..w * h)
        .map(|p| setup.pixel(p % w, p / w, w, h))
        .collect();
    let mut light = vec![
        Light {
            intensity: [1.0; 3],
            n: 0.0,
        };
        res * res
    ];
    let mut eye: Vec<EyeTexel> = vec![([0.0; 3], [1.0; 3]); w * h];
    for k in 0..settings.slices {
        let c = setup.slice_start + k as f64 * setup.slice_step;
        eye.par_iter_mut()
            .zip(&rays)
            .for_each(|(px, &d)| slicer.eye_slab(px, d, c, &light));
        light
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, texel)| slicer.light_slab(texel, i, c));
    }
    let pixels: Vec<([f32; 3], f32)> = eye
        .par_iter()
        .zip(&rays)
        .map(|(&px, &d)| slicer.pixel(px, d, &light))
        .collect();
    Ok(Image::from_pixels(w, h, &pixels))
}
