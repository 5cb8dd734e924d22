//! The reference renderer of [`super`]: plain Rust, f64, one pixel and one shadow texel at a
//! time (rayon across them).

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use grid::ThetaGrid;
use runtime::{FieldTable, Tables, sample};

use super::{Settings, SvsPhase, SvsSetup};
use crate::shading::{bilinear_taps, check_fields, coefficients, over_footprint};
use crate::sky::rayleigh_phase;
use crate::{
    camera::SUN_DIAMETER_DEG, checks::FrameError, frame::Frame, image::Image, volume::MAX_FIELDS,
};

/// Quadrature points for the shadowed air outside the slices (module docs of [`super`]).
const SHADOWED_AIR_POINTS: usize = 64;

/// Midpoint steps for hazy air outside the slices: this optical depth of the densest channel,
/// at most [`HAZY_AIR_MAX_STEP_M`].
const HAZY_AIR_STEP_TAU: f64 = 0.02;

/// The longest midpoint step for hazy air (m).
const HAZY_AIR_MAX_STEP_M: f64 = 2000.0;

/// The longest stretch of a view ray integrated for shadowed air beyond the slices (m).
const SHADOWED_AIR_MAX_M: f64 = 200_000.0;

/// Cornette & Shanks's phase function (Miyazaki Eq. 3) per steradian: the printed
/// 3(1 − g²)/(2(2 + g²)) · (1 + μ²)/(1 + g² − 2gμ)^{3/2} integrates to 4π over the sphere.
pub fn cornette_shanks(g: f64, cos: f64) -> f64 {
    1.5 * (1.0 - g * g) / (2.0 + g * g) * (1.0 + cos * cos)
        / (1.0 + g * g - 2.0 * g * cos).powf(1.5)
        / (4.0 * PI)
}

/// Asymmetry g = ∫ P cos θ dΩ of a field's Ams_1 per channel (bin values at bin centres).
pub fn asymmetry(field: &FieldTable, theta_step_deg: f64) -> [f64; 3] {
    let grid = ThetaGrid::new(theta_step_deg).expect("tables' Δθ was checked at load");
    let omega = grid.bin_solid_angles();
    let cos: Vec<f64> = grid
        .thetas_deg()
        .iter()
        .map(|t| t.to_radians().cos())
        .collect();
    std::array::from_fn(|c| {
        let row = field.image.row(c, 0);
        let (mut m0, mut m1) = (0.0, 0.0);
        for k in 0..omega.len().min(row.len()) {
            m0 += row[k] * omega[k];
            m1 += row[k] * omega[k] * cos[k];
        }
        if m0 > 0.0 { m1 / m0 } else { 0.0 }
    })
}

/// Bilinear lookup in the shadow surface; 1 (no cloud) outside its footprint.
fn shadow_at(buffer: &[[f64; 3]], res: usize, uv: [f64; 2]) -> [f64; 3] {
    if !over_footprint(res, uv) {
        return [1.0; 3];
    }
    let taps = bilinear_taps(res, uv);
    std::array::from_fn(|c| taps.iter().map(|&(i, w)| w * buffer[i][c]).sum())
}

/// The ray parameters where `origin + t d` lies over the shadow surface's footprint (the
/// prism the box's shadow can fill), within [t0, t1].
fn prism_span(s: &SvsSetup, res: usize, origin: DVec3, d: DVec3, t0: f64, t1: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (t0, t1);
    for (axis, o, texel) in [
        (s.shadow_u, s.shadow_origin[0], s.shadow_texel[0]),
        (s.shadow_w, s.shadow_origin[1], s.shadow_texel[1]),
    ] {
        let (a, b) = (o, o + texel * res as f64);
        let (p, v) = (axis.dot(origin), axis.dot(d));
        if v.abs() < 1e-15 {
            if p < a || p > b {
                return (t0, t0);
            }
            continue;
        }
        let (mut x, mut y) = ((a - p) / v, (b - p) / v);
        if x > y {
            std::mem::swap(&mut x, &mut y);
        }
        lo = lo.max(x);
        hi = hi.min(y);
    }
    (lo, hi.max(lo))
}

/// The air: Rayleigh (the sky model's β_sl, H) and the haze layer, each an exponential in
/// height, for the extinction, the sunlight reaching a height (Eq. 12 for each) and the
/// transmittance along a ray.
struct Air<'a> {
    atm: &'a crate::sky::Atmosphere,
    /// N_0 σ_ext per channel (1/m at y = 0) and 1/H of the haze; zero without one.
    haze_ext: [f64; 3],
    haze_gamma: f64,
    l_y: f64,
}

impl Air<'_> {
    fn on(&self) -> bool {
        self.atm.beta_sea_level_per_m.iter().any(|&b| b > 0.0) || self.haze_on()
    }

    fn haze_on(&self) -> bool {
        self.haze_ext.iter().any(|&b| b > 0.0)
    }

    /// Rayleigh β and the haze's N(y)/N_0 at height y.
    fn at(&self, y: f64) -> ([f64; 3], f64) {
        let r = std::array::from_fn(|c| {
            self.atm.beta_sea_level_per_m[c] * (-y / self.atm.scale_height_m).exp()
        });
        (
            r,
            if self.haze_on() {
                (-self.haze_gamma * y).exp()
            } else {
                0.0
            },
        )
    }

    /// Sunlight reaching height y through both (Eq. 12, and its haze analogue).
    fn sunlight(&self, y: f64) -> [f64; 3] {
        let mut s = self.atm.sunlight(y, self.l_y);
        if self.haze_on() {
            let depth = (-self.haze_gamma * y).exp() / self.haze_gamma / self.l_y;
            for c in 0..3 {
                s[c] *= (-self.haze_ext[c] * depth).exp();
            }
        }
        s
    }

    /// Transmittance from the eye at height `y` along `d_y` over `t` (Eq. 11 for each).
    fn transparency(&self, y: f64, d_y: f64, t: f64) -> [f64; 3] {
        let mut tr = self.atm.transparency(y, d_y, t);
        if self.haze_on() {
            let depth = (-self.haze_gamma * y).exp()
                * crate::sky::one_minus_u_over_p(self.haze_gamma, d_y, t)
                / self.haze_gamma;
            for c in 0..3 {
                tr[c] *= (-self.haze_ext[c] * depth).exp();
            }
        }
        tr
    }
}

/// The Mie scattering texture (§4.1) of one pixel: per field (P_f(α) + k_multi) σ_sca,f per
/// channel, the Rayleigh phase, and the haze's N_0 σ_sca P(α); α is constant along the ray.
type Texture = ([[f64; 3]; MAX_FIELDS], f64, [f64; 3]);

/// A pixel's S (the scattered light), α* (air and cloud transparency) and the cloud's own
/// transparency, per channel.
type EyeTexel = ([f64; 3], [f64; 3], [f64; 3]);

/// What every step of a frame reads.
struct Svs<'a> {
    tables: &'a Tables,
    frame: &'a Frame,
    settings: &'a Settings,
    s: SvsSetup,
    fields: Vec<&'a FieldTable>,
    /// Each field's Cornette–Shanks asymmetry per channel.
    g: Vec<[f64; 3]>,
    air: Air<'a>,
    air_on: bool,
    /// The haze layer's field and layer, if any, and its asymmetry.
    haze: Option<(FieldTable, &'a crate::frame::Haze)>,
    haze_g: Option<[f64; 3]>,
}

impl Svs<'_> {
    fn res(&self) -> usize {
        self.settings.light_resolution
    }

    /// Where the ray from `o` along `d` meets the ground (∞ if it does not).
    fn t_ground(&self, (o, d): (DVec3, DVec3)) -> f64 {
        if d.y < 0.0 {
            (o.y / -d.y).max(0.0)
        } else {
            f64::INFINITY
        }
    }

    /// A field's phase function at cos α: its Ams_1, or Cornette–Shanks with asymmetry `g`.
    fn phase(&self, f: &FieldTable, g: [f64; 3], cos: f64) -> [f64; 3] {
        match self.settings.phase {
            SvsPhase::Tables => sample::ams(f, self.tables.theta_step_deg, 1.0, cos),
            SvsPhase::CornetteShanks => std::array::from_fn(|c| cornette_shanks(g[c], cos)),
        }
    }

    /// The pixel's [`Texture`] for ray `d`: the haze's β_atm is N_0 σ_sca P(α), no k_multi
    /// (Eq. 1); the haze layer lives in the air, not the grid.
    fn texture(&self, d: DVec3) -> Texture {
        let cos = d.dot(self.s.to_sun);
        let haze_field = self.frame.haze.as_ref().map(|h| h.field);
        let mut out = [[0.0; 3]; MAX_FIELDS];
        for (i, f) in self.fields.iter().enumerate() {
            if Some(i) == haze_field {
                continue;
            }
            let p = self.phase(f, self.g[i], cos);
            out[i] = std::array::from_fn(|c| (p[c] + self.settings.k_multi) * f.sigma_sca_m2[c]);
        }
        let haze_beta = match &self.haze {
            None => [0.0; 3],
            Some((f, h)) => {
                let g = self.haze_g.expect("with the haze");
                let p = match self.settings.phase {
                    SvsPhase::Tables => sample::ams(f, self.tables.theta_step_deg, 1.0, cos),
                    SvsPhase::CornetteShanks => std::array::from_fn(|c| cornette_shanks(g[c], cos)),
                };
                std::array::from_fn(|c| p[c] * f.sigma_sca_m2[c] * h.number_density_per_m3)
            }
        };
        (out, rayleigh_phase(cos), haze_beta)
    }

    /// Eq. 10, first of each slice (§4.1): slice plane `c`'s cloud into shadow texel `i`.
    fn shadow_slab(&self, texel: &mut [f64; 3], i: usize, c: f64) {
        let res = self.res();
        let p = self.s.shadow_point(i % res, i / res, c);
        let rho = self.frame.grid.sample(p);
        let (ext, _) = coefficients(&self.fields, &rho);
        for ch in 0..3 {
            texel[ch] *= (-ext[ch] * self.s.sun_step).exp();
        }
    }

    /// Then the screen: Eqs. 8 and 9 at slice plane `c` along the ray from `o` along `d`,
    /// blended as §4.3.
    fn eye_slab(
        &self,
        px: &mut EyeTexel,
        (o, d): (DVec3, DVec3),
        tex: &Texture,
        c: f64,
        shadow: &[[f64; 3]],
    ) {
        let (s, air) = (&self.s, &self.air);
        let (beta, p_air, haze_b) = tex;
        let nd = s.normal.dot(d);
        if nd.abs() < 1e-9 {
            return;
        }
        let t = (c - s.normal.dot(o)) / nd;
        if t <= 0.0 || t > self.t_ground((o, d)) {
            return;
        }
        let p = o + t * d;
        let rho = self.frame.grid.sample(p);
        let (ext, _) = coefficients(&self.fields, &rho);
        let (rayleigh, n_haze) = if self.air_on {
            air.at(p.y)
        } else {
            ([0.0; 3], 0.0)
        };
        let air_ext: [f64; 3] = std::array::from_fn(|ch| rayleigh[ch] + n_haze * air.haze_ext[ch]);
        if ext.iter().chain(&air_ext).all(|&e| e <= 0.0) {
            return;
        }
        let dt = s.step / nd.abs();
        let g_cl = shadow_at(shadow, self.res(), s.shadow_coords(p));
        let g_atm = if self.air_on {
            air.sunlight(p.y)
        } else {
            [1.0; 3]
        };
        let (sum, alpha_star, t_cl) = px;
        for ch in 0..3 {
            let mut b = rayleigh[ch] * p_air + n_haze * haze_b[ch];
            for (f, r) in rho.iter().enumerate().take(self.fields.len()) {
                b += r * beta[f][ch];
            }
            // Eq. 8 (× I_sun), Eq. 9.
            let contribution = self.frame.sun.irradiance[ch] * dt * b * g_atm[ch] * g_cl[ch];
            let slab = (-(ext[ch] + air_ext[ch]) * dt).exp();
            if s.back_to_front {
                sum[ch] = contribution + slab * sum[ch];
            } else {
                sum[ch] += alpha_star[ch] * contribution;
            }
            alpha_star[ch] *= slab;
            t_cl[ch] *= (-ext[ch] * dt).exp();
        }
    }

    /// In-scattering by the air along the ray from `o` along `d` over [t0, t1], per unit
    /// irradiance: Eq. 14 where
    /// the segment is on the sun's side of the slices, less the final shadow's deficit on the
    /// far side; with haze, both species by the midpoint rule (module docs of [`super`]).
    fn air_segment(
        &self,
        (o, d): (DVec3, DVec3),
        tex: &Texture,
        (t0, t1): (f64, f64),
        shadow: &[[f64; 3]],
    ) -> [f64; 3] {
        if !self.air_on || t1 <= t0 {
            return [0.0; 3];
        }
        let s = &self.s;
        // The segment lies on one side of the slices: ask at a point well inside it (a point
        // at its start would sit on the boundary plane in f32).
        let probe_t = if t1.is_finite() {
            0.5 * (t0 + t1)
        } else {
            t0 + t0.max(1.0)
        };
        let sunward = s.sunward_of_slices(o + probe_t * d);
        // Without haze: Eq. 14 in closed form, less the final shadow's deficit on the far side
        // (inside the shadow prism). With haze: both species by the midpoint rule along the
        // whole segment.
        let mut out = [0.0; 3];
        let (lo, hi, shadow_only) = if self.air.haze_on() {
            let cap = if t1.is_finite() {
                t1
            } else {
                t0 + SHADOWED_AIR_MAX_M
            };
            (t0, cap, false)
        } else {
            let (atm, l_y, cos_sun) = (self.air.atm, self.air.l_y, d.dot(s.to_sun));
            let a = atm.inscatter(o.y, d.y, t1, l_y, cos_sun);
            let b = atm.inscatter(o.y, d.y, t0, l_y, cos_sun);
            out = std::array::from_fn(|c| a[c] - b[c]);
            if sunward {
                return out;
            }
            let (lo, hi) = prism_span(s, self.res(), o, d, t0, t1.min(t0 + SHADOWED_AIR_MAX_M));
            (lo, hi, true)
        };
        if hi > lo {
            self.air_midpoints(
                (o, d),
                tex,
                (lo, hi),
                shadow_only,
                sunward,
                shadow,
                &mut out,
            );
        }
        out
    }

    /// The midpoint rule of [`Self::air_segment`] over [lo, hi], added to `out`: the shadow
    /// deficit at 64 midpoints over the prism (`shadow_only`), or the hazy air at midpoints
    /// 0.02 of an optical depth (or 2 km) apart until the transmittance from the eye is below
    /// 1e-7.
    fn air_midpoints(
        &self,
        (o, d): (DVec3, DVec3),
        (_, p_air, haze_b): &Texture,
        (lo, hi): (f64, f64),
        shadow_only: bool,
        sunward: bool,
        shadow: &[[f64; 3]],
        out: &mut [f64; 3],
    ) {
        let (s, air, res) = (&self.s, &self.air, self.res());
        let (mut t, uniform) = (lo, (hi - lo) / SHADOWED_AIR_POINTS as f64);
        let prism = prism_span(s, res, o, d, lo, hi);
        let prism_step = s.shadow_texel[0]
            .min(s.shadow_texel[1])
            .max((prism.1 - prism.0) / 256.0);
        let mut n = 0;
        while (shadow_only && n < SHADOWED_AIR_POINTS) || (!shadow_only && t < hi) {
            let (rayleigh, n_haze) = air.at(o.y + (t + 0.5 * uniform) * d.y);
            let dt = if shadow_only {
                // Counted, not accumulated: exactly the 64 midpoints.
                t = lo + n as f64 * uniform;
                uniform
            } else {
                let ext = (0..3)
                    .map(|c| rayleigh[c] + n_haze * air.haze_ext[c])
                    .fold(0.0, f64::max);
                let mut dt = (HAZY_AIR_STEP_TAU / ext.max(1e-300))
                    .min(HAZY_AIR_MAX_STEP_M)
                    .min(hi - t);
                // Over the shadow's prism the steps resolve its edges: a shadow texel, or
                // 1/256 of the prism's stretch if that is longer; and a step ends where the
                // prism begins.
                if !sunward {
                    if t < prism.0 {
                        dt = dt.min(prism.0 - t);
                    } else if t < prism.1 {
                        dt = dt.min(prism_step);
                    }
                }
                dt
            };
            let tm = t + 0.5 * dt;
            t += dt;
            n += 1;
            let p = o + tm * d;
            let g_cl = if sunward {
                [1.0; 3]
            } else {
                shadow_at(shadow, res, s.shadow_coords(p))
            };
            let sun = air.sunlight(p.y);
            let tr = air.transparency(o.y, d.y, tm);
            let (rayleigh, n_haze) = air.at(p.y);
            for c in 0..3 {
                let b = rayleigh[c] * p_air + n_haze * haze_b[c];
                let lit = if shadow_only {
                    -(1.0 - g_cl[c])
                } else {
                    g_cl[c]
                };
                out[c] += b * sun[c] * tr[c] * lit * dt;
            }
            if !shadow_only && tr.iter().all(|&v| v < 1e-7) {
                break;
            }
        }
    }

    /// Composite of the ray from `o` along `d`: the air before and after the slices, the
    /// ground lit through the final shadow surface, or the sun's disk.
    fn pixel(
        &self,
        (sum, _, t_cl): EyeTexel,
        (o, d): (DVec3, DVec3),
        tex: &Texture,
        shadow: &[[f64; 3]],
    ) -> ([f32; 3], f32) {
        let (s, air) = (&self.s, &self.air);
        let t_end = self.t_ground((o, d));
        // The slices' range along the ray, clipped to [0, t_end].
        let (nd, n_dot_o) = (s.normal.dot(d), s.normal.dot(o));
        let (ta, tb) = if nd.abs() < 1e-12 {
            let inside = (s.range.0..=s.range.1).contains(&n_dot_o);
            if inside { (0.0, t_end) } else { (0.0, 0.0) }
        } else {
            let (x, y) = ((s.range.0 - n_dot_o) / nd, (s.range.1 - n_dot_o) / nd);
            (x.min(y).clamp(0.0, t_end), x.max(y).clamp(0.0, t_end))
        };
        let front = self.air_segment((o, d), tex, (0.0, ta), shadow);
        let back = self.air_segment((o, d), tex, (tb, t_end), shadow);
        let t_front = air.transparency(o.y, d.y, ta);
        let t_all = air.transparency(o.y, d.y, t_end);
        let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
        let disk_sr = std::f64::consts::TAU * (1.0 - cos_disk);
        // What lies beyond: the ground, lit through the final shadow surface, or the sun.
        let end: [f64; 3] = if t_end.is_finite() {
            let ground = o + t_end * d;
            let g_cl = shadow_at(shadow, self.res(), s.shadow_coords(ground));
            let sun_ground = air.sunlight(0.0);
            std::array::from_fn(|c| {
                self.frame.ground_albedo / PI * air.l_y * sun_ground[c] * g_cl[c] * t_all[c]
            })
        } else if d.dot(s.to_sun) >= cos_disk {
            std::array::from_fn(|c| t_all[c] / disk_sr)
        } else {
            [0.0; 3]
        };
        let irradiance = self.frame.sun.irradiance;
        let rgb = std::array::from_fn(|c| {
            let i_s = irradiance[c];
            let v = i_s * front[c] + t_front[c] * sum[c] + t_cl[c] * i_s * (back[c] + end[c]);
            v as f32
        });
        (rgb, t_cl[1] as f32)
    }
}

/// Renders `frame` by shadow-view slicing with the fields of `tables` (field i = grid
/// channel i).
pub fn render(tables: &Tables, frame: &Frame, settings: &Settings) -> Result<Image, FrameError> {
    let s = super::setup(frame, settings)?;
    check_fields(tables, frame)?;
    let fields: Vec<&FieldTable> = tables.fields.iter().collect();
    let haze = frame
        .haze
        .as_ref()
        .map(|h| (tables.fields[h.field].clone(), h));
    let air = Air {
        atm: &frame.atmosphere,
        haze_ext: haze.as_ref().map_or([0.0; 3], |(f, h)| {
            f.sigma_ext_m2.map(|e| e * h.number_density_per_m3)
        }),
        haze_gamma: haze.as_ref().map_or(0.0, |(_, h)| 1.0 / h.scale_height_m),
        l_y: s.to_sun.y,
    };
    let svs = Svs {
        tables,
        frame,
        settings,
        g: fields
            .iter()
            .map(|f| asymmetry(f, tables.theta_step_deg))
            .collect(),
        fields,
        air_on: air.on(),
        air,
        haze_g: haze
            .as_ref()
            .map(|(f, _)| asymmetry(f, tables.theta_step_deg)),
        haze,
        s,
    };
    let (w, h) = (frame.width, frame.height);
    let res = settings.light_resolution;
    let rays: Vec<(DVec3, DVec3)> = (0..w * h).map(|p| s.pixel(p % w, p / w, w, h)).collect();
    let mie: Vec<Texture> = rays.par_iter().map(|&(_, d)| svs.texture(d)).collect();
    let mut shadow = vec![[1.0f64; 3]; res * res];
    let mut eye: Vec<EyeTexel> = vec![([0.0; 3], [1.0; 3], [1.0; 3]); w * h];
    for k in 0..settings.slices {
        let c = s.plane(k);
        shadow
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, texel)| svs.shadow_slab(texel, i, c));
        eye.par_iter_mut()
            .zip(&rays)
            .zip(&mie)
            .for_each(|((px, &ray), tex)| svs.eye_slab(px, ray, tex, c, &shadow));
    }
    let pixels: Vec<([f32; 3], f32)> = eye
        .par_iter()
        .zip(&rays)
        .zip(&mie)
        .map(|((&px, &ray), tex)| svs.pixel(px, ray, tex, &shadow))
        .collect();
    Ok(Image::from_pixels(w, h, &pixels))
}
