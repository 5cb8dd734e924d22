//! The reference renderer: the model of [`super`] in plain Rust, f64, one pixel and one
//! light texel at a time (rayon across them). Slow; the GPU path is tested against it.

use rayon::prelude::*;

use glam::DVec3;

use runtime::sample;
use runtime::{FieldTable, Tables};

use super::Setup;
use crate::{Frame, FrameError, Image, LightUpdate, MAX_FIELDS, SUN_DIAMETER_DEG};

/// Light-buffer texel: intensity per channel (fraction of the sunlight at that height) and the
/// expected scatter count n.
#[derive(Clone, Copy)]
struct Light {
    intensity: [f64; 3],
    n: f64,
}

/// Extinction and scattering coefficients (1/m) per channel at densities ρ.
pub fn coefficients(fields: &[&FieldTable], rho: &[f64; MAX_FIELDS]) -> ([f64; 3], [f64; 3]) {
    let mut ext = [0.0; 3];
    let mut sca = [0.0; 3];
    for (f, &r) in fields.iter().zip(rho) {
        for c in 0..3 {
            ext[c] += r * f.sigma_ext_m2[c];
            sca[c] += r * f.sigma_sca_m2[c];
        }
    }
    (ext, sca)
}

/// Checks that the tables can serve the frame's grid.
pub fn check_fields(tables: &Tables, frame: &Frame) -> Result<(), FrameError> {
    if tables.fields.is_empty() || tables.fields.len() > MAX_FIELDS {
        return Err(FrameError(format!(
            "a render takes 1 to {MAX_FIELDS} fields, the tables hold {}",
            tables.fields.len()
        )));
    }
    let used = frame.grid.max_density();
    for f in tables.fields.len()..MAX_FIELDS {
        if used[f] > 0.0 {
            return Err(FrameError(format!(
                "the density grid has field channel {f}, the tables hold {} fields",
                tables.fields.len()
            )));
        }
    }
    Ok(())
}

/// Distances along the ray where it enters and leaves the box, if it does (t ≥ 0).
pub fn box_span(grid_min: DVec3, grid_max: DVec3, origin: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        let inv = 1.0 / d[a];
        let (mut lo, mut hi) = (
            (grid_min[a] - origin[a]) * inv,
            (grid_max[a] - origin[a]) * inv,
        );
        if lo > hi {
            std::mem::swap(&mut lo, &mut hi);
        }
        if lo.is_nan() || hi.is_nan() {
            // d[a] = 0 on the box's plane: inside that slab or not.
            if origin[a] < grid_min[a] || origin[a] > grid_max[a] {
                return None;
            }
            continue;
        }
        t0 = t0.max(lo);
        t1 = t1.min(hi);
    }
    (t0 < t1).then_some((t0, t1))
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

/// The four texels (indices into a res × res buffer, x fastest) and weights of a bilinear
/// lookup at continuous coordinates `uv` (texel centres at integers), clamped to the edge
/// texels.
pub(crate) fn bilinear_taps(res: usize, uv: [f64; 2]) -> [(usize, f64); 4] {
    let clamp = |v: f64| v.clamp(0.0, (res - 1) as f64);
    let (u, v) = (clamp(uv[0]), clamp(uv[1]));
    let (a0, b0) = (
        (u.floor() as usize).min(res - 2),
        (v.floor() as usize).min(res - 2),
    );
    let (s, t) = (u - a0 as f64, v - b0 as f64);
    let at = |a: usize, b: usize| a + res * b;
    [
        (at(a0, b0), (1.0 - s) * (1.0 - t)),
        (at(a0 + 1, b0), s * (1.0 - t)),
        (at(a0, b0 + 1), (1.0 - s) * t),
        (at(a0 + 1, b0 + 1), s * t),
    ]
}

/// Whether `uv` lies over a res × res buffer's footprint (within half a texel of its edge
/// texels); outside it no volume is in the way.
pub(crate) fn over_footprint(res: usize, uv: [f64; 2]) -> bool {
    let edge = (res - 1) as f64 + 0.5;
    uv.iter().all(|&v| (-0.5..=edge).contains(&v))
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

/// Renders `frame` with the fields of `tables` (field i = grid channel i).
pub fn render(tables: &Tables, frame: &Frame) -> Result<Image, FrameError> {
    let setup = frame.setup()?;
    check_fields(tables, frame)?;
    let fields: Vec<&FieldTable> = tables.fields.iter().collect();
    let (w, h) = (frame.width, frame.height);
    let res = frame.light_resolution;
    let l_y = frame.sun.direction()[1];
    let cos_light = |d: DVec3| -setup.light.dot(d);
    let rays: Vec<DVec3> = (0..w * h).map(|p| setup.ray(p % w, p / w, w, h)).collect();

    let mut light = vec![
        Light {
            intensity: [1.0; 3],
            n: 0.0,
        };
        res * res
    ];
    // Per pixel: radiance and transparency of the volume, per channel.
    let mut eye = vec![([0.0f64; 3], [1.0f64; 3]); w * h];
    let h_dot_l = setup.half.dot(setup.light);
    let h_dot_e = setup.half.dot(setup.eye);
    // Δ_l, the light's path through one slab.
    let light_thickness = setup.slice_step / h_dot_l;

    for k in 0..frame.slices {
        let c = setup.slice_start + k as f64 * setup.slice_step;
        eye.par_iter_mut().zip(&rays).for_each(|(px, &d)| {
            let hd = setup.half.dot(d);
            if hd.abs() < 1e-9 {
                return;
            }
            let t = (c - h_dot_e) / hd;
            if t <= 0.0 {
                return;
            }
            let p = setup.eye + t * d;
            let rho = frame.grid.sample(p);
            let (ext, sca) = coefficients(&fields, &rho);
            if ext.iter().all(|&e| e <= 0.0) {
                return;
            }
            let mut lit = bilinear(&light, res, setup.light_coords(p));
            if frame.light_update == LightUpdate::Continuum {
                // The light at the slab's middle: the buffer holds it at the slab's entry.
                cross_slab(
                    &mut lit,
                    &fields,
                    &ext,
                    &sca,
                    &rho,
                    light_thickness / 2.0,
                    frame.light_update,
                );
            }
            let sun = frame.atmosphere.sunlight(p[1], l_y);
            let phase = sample::mix(
                &fields,
                &rho,
                tables.theta_step_deg,
                lit.n + 1.0,
                cos_light(d),
            );
            let thickness = setup.slice_step / hd.abs();
            for ch in 0..3 {
                if ext[ch] <= 0.0 {
                    continue;
                }
                let slab = (-ext[ch] * thickness).exp();
                let scattered = lit.intensity[ch]
                    * sun[ch]
                    * frame.sun.irradiance[ch]
                    * (phase[ch] + frame.xi)
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
        });
        let thickness = light_thickness;
        light.par_iter_mut().enumerate().for_each(|(i, texel)| {
            let p = setup.light_point(i % res, i / res, c);
            let rho = frame.grid.sample(p);
            let (ext, sca) = coefficients(&fields, &rho);
            if ext.iter().all(|&e| e <= 0.0) {
                return;
            }
            cross_slab(
                texel,
                &fields,
                &ext,
                &sca,
                &rho,
                thickness,
                frame.light_update,
            );
        });
    }

    let pixels: Vec<([f32; 3], f32)> = eye
        .par_iter()
        .zip(&rays)
        .map(|(&(l_vol, t_vol), &d)| {
            // The ground is lit through the final light buffer (1 outside its footprint,
            // where no volume is).
            let ground_lit = |p: DVec3| {
                let uv = setup.light_coords(p);
                if over_footprint(res, uv) {
                    bilinear(&light, res, uv).intensity
                } else {
                    [1.0; 3]
                }
            };
            (
                compose(frame, setup.eye, d, l_vol, t_vol, ground_lit),
                t_vol[1] as f32,
            )
        })
        .collect();
    Ok(Image {
        width: w,
        height: h,
        rgb: pixels.iter().map(|p| p.0).collect(),
        transparency: pixels.iter().map(|p| p.1).collect(),
    })
}

/// A pixel's radiance from its ray `d` from `eye`, the volume's radiance `l_vol` (at the box's
/// middle, before the air in front) and transparency `t_vol` per channel: the air in front of
/// and behind the box (Eqs. 11–15), the sun's disk and a Lambertian ground lit through the air
/// (Eq. 12) and through the volume as `ground_lit` says (the fraction of sunlight left at a
/// ground point). Every slicing model composes its pixels this way.
pub(crate) fn compose(
    frame: &Frame,
    eye: DVec3,
    d: DVec3,
    l_vol: [f64; 3],
    t_vol: [f64; 3],
    ground_lit: impl Fn(DVec3) -> [f64; 3],
) -> [f32; 3] {
    let atm = &frame.atmosphere;
    let sun_dir = frame.sun.direction();
    let l_y = sun_dir[1];
    let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
    let disk_sr = std::f64::consts::TAU * (1.0 - cos_disk);
    let y = eye[1];
    let k_mid = box_span(frame.grid.min_m, frame.grid.max_m, eye, d)
        .map_or(0.0, |(t0, t1)| 0.5 * (t0 + t1));
    let k_end = if d[1] < 0.0 && y > 0.0 {
        y / -d[1]
    } else if d[1] < 0.0 {
        0.0
    } else {
        f64::INFINITY
    };
    let k_mid = k_mid.min(k_end);
    let cos_sun = d.dot(sun_dir);
    let front = atm.inscatter(y, d[1], k_mid, l_y, cos_sun);
    let all = atm.inscatter(y, d[1], k_end, l_y, cos_sun);
    let t_mid = atm.transparency(y, d[1], k_mid);
    let on_disk = k_end.is_infinite() && cos_sun >= cos_disk;
    let t_all = atm.transparency(y, d[1], k_end);
    let ground: [f64; 3] = if frame.ground_albedo > 0.0 && k_end.is_finite() && k_end > 0.0 {
        let lit = ground_lit(eye + k_end * d);
        let sun0 = atm.sunlight(0.0, l_y);
        std::array::from_fn(|c| {
            frame.ground_albedo / std::f64::consts::PI * l_y * sun0[c] * lit[c] * t_all[c]
        })
    } else {
        [0.0; 3]
    };
    std::array::from_fn(|c| {
        let i_s = frame.sun.irradiance[c];
        let mut v = i_s * (front[c] + t_vol[c] * (all[c] - front[c])) + t_mid[c] * l_vol[c];
        if on_disk {
            v += t_vol[c] * i_s * t_all[c] / disk_sr;
        }
        v += t_vol[c] * i_s * ground[c];
        v as f32
    })
}
