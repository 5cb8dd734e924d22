//! The reference renderer of [`super`]: plain Rust, f64, one pixel and one shadow texel at a
//! time (rayon across them).

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use grid::ThetaGrid;
use runtime::{FieldTable, Tables, sample};

use super::{SvsPhase, SvsSettings, SvsSetup};
use crate::riley::cpu::{check_fields, coefficients};
use crate::sky::rayleigh_phase;
use crate::{Frame, FrameError, Image, MAX_FIELDS, SUN_DIAMETER_DEG};

/// Quadrature points for the shadowed air outside the slices (module docs of [`super`]).
const SHADOWED_AIR_POINTS: usize = 64;

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
    let edge = (res - 1) as f64;
    if uv.iter().any(|&v| !(-0.5..=edge + 0.5).contains(&v)) {
        return [1.0; 3];
    }
    let (u, v) = (uv[0].clamp(0.0, edge), uv[1].clamp(0.0, edge));
    let (a0, b0) = (
        (u.floor() as usize).min(res - 2),
        (v.floor() as usize).min(res - 2),
    );
    let (s, t) = (u - a0 as f64, v - b0 as f64);
    let at = |a: usize, b: usize| buffer[a + res * b];
    let w = [(1.0 - s) * (1.0 - t), s * (1.0 - t), (1.0 - s) * t, s * t];
    let l = [
        at(a0, b0),
        at(a0 + 1, b0),
        at(a0, b0 + 1),
        at(a0 + 1, b0 + 1),
    ];
    std::array::from_fn(|c| (0..4).map(|i| w[i] * l[i][c]).sum())
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

/// Renders `frame` by shadow-view slicing with the fields of `tables` (field i = grid
/// channel i).
pub fn render(tables: &Tables, frame: &Frame, settings: &SvsSettings) -> Result<Image, FrameError> {
    let s = super::setup(frame, settings)?;
    check_fields(tables, frame)?;
    let fields: Vec<&FieldTable> = tables.fields.iter().collect();
    let (w, h) = (frame.width, frame.height);
    let res = frame.light_resolution;
    let atm = &frame.atmosphere;
    let air_on = atm.beta_sea_level_per_m.iter().any(|&b| b > 0.0);
    let l_y = s.to_sun.y;
    let irradiance = frame.sun.irradiance;
    let rays: Vec<DVec3> = (0..w * h)
        .map(|p| crate::camera::pixel_ray(s.axes, s.tan_half_fov_y, (p % w, p / w), (w, h)))
        .collect();
    let g: Vec<[f64; 3]> = fields
        .iter()
        .map(|f| asymmetry(f, tables.theta_step_deg))
        .collect();
    // The Mie scattering texture (§4.1): per pixel and field, (P_f(α) + k_multi) σ_sca,f per
    // channel, and the Rayleigh phase; α is constant along a pixel's ray.
    let mie: Vec<([[f64; 3]; MAX_FIELDS], f64)> = rays
        .par_iter()
        .map(|&d| {
            let cos = d.dot(s.to_sun);
            let mut out = [[0.0; 3]; MAX_FIELDS];
            for (i, f) in fields.iter().enumerate() {
                let p = match settings.phase {
                    SvsPhase::Tables => sample::ams(f, tables.theta_step_deg, 1.0, cos),
                    SvsPhase::CornetteShanks => {
                        std::array::from_fn(|c| cornette_shanks(g[i][c], cos))
                    }
                };
                out[i] = std::array::from_fn(|c| (p[c] + settings.k_multi) * f.sigma_sca_m2[c]);
            }
            (out, rayleigh_phase(cos))
        })
        .collect();

    // The shadow surface g_sun_cl, and per pixel: S, α* (air and cloud), the cloud's own
    // transparency.
    let mut shadow = vec![[1.0f64; 3]; res * res];
    let mut eye = vec![([0.0f64; 3], [1.0f64; 3], [1.0f64; 3]); w * h];
    let n_dot_e = s.normal.dot(s.eye);
    let y_eye = s.eye.y;
    let t_ground = |d: DVec3| {
        if d.y < 0.0 {
            (y_eye / -d.y).max(0.0)
        } else {
            f64::INFINITY
        }
    };
    for k in 0..frame.slices {
        let c = s.plane(k);
        // Eq. 10 first (§4.1): the slice's cloud into the shadow surface.
        shadow.par_iter_mut().enumerate().for_each(|(i, texel)| {
            let p = s.shadow_point(i % res, i / res, c);
            let rho = frame.grid.sample(p);
            let (ext, _) = coefficients(&fields, &rho);
            for ch in 0..3 {
                texel[ch] *= (-ext[ch] * s.sun_step).exp();
            }
        });
        // Then the screen: Eqs. 8 and 9, blended as §4.3.
        eye.par_iter_mut()
            .zip(&rays)
            .zip(&mie)
            .for_each(|((px, &d), (beta, p_air))| {
                let nd = s.normal.dot(d);
                if nd.abs() < 1e-9 {
                    return;
                }
                let t = (c - n_dot_e) / nd;
                if t <= 0.0 || t > t_ground(d) {
                    return;
                }
                let p = s.eye + t * d;
                let rho = frame.grid.sample(p);
                let (ext, _) = coefficients(&fields, &rho);
                let air: [f64; 3] = if air_on {
                    std::array::from_fn(|ch| {
                        atm.beta_sea_level_per_m[ch] * (-p.y / atm.scale_height_m).exp()
                    })
                } else {
                    [0.0; 3]
                };
                if ext.iter().chain(&air).all(|&e| e <= 0.0) {
                    return;
                }
                let dt = s.step / nd.abs();
                let g_cl = shadow_at(&shadow, res, s.shadow_coords(p));
                let g_atm = if air_on {
                    atm.sunlight(p.y, l_y)
                } else {
                    [1.0; 3]
                };
                let (sum, alpha_star, t_cl) = px;
                for ch in 0..3 {
                    let mut b = air[ch] * p_air;
                    for (f, r) in rho.iter().enumerate().take(fields.len()) {
                        b += r * beta[f][ch];
                    }
                    // Eq. 8 (× I_sun), Eq. 9.
                    let contribution = irradiance[ch] * dt * b * g_atm[ch] * g_cl[ch];
                    let slab = (-(ext[ch] + air[ch]) * dt).exp();
                    if s.back_to_front {
                        sum[ch] = contribution + slab * sum[ch];
                    } else {
                        sum[ch] += alpha_star[ch] * contribution;
                    }
                    alpha_star[ch] *= slab;
                    t_cl[ch] *= (-ext[ch] * dt).exp();
                }
            });
    }

    // Composite: the air before and after the slices, the ground, the sun disk.
    let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
    let disk_sr = std::f64::consts::TAU * (1.0 - cos_disk);
    let sun_ground = atm.sunlight(0.0, l_y);
    let pixels: Vec<([f32; 3], f32)> = eye
        .par_iter()
        .zip(&rays)
        .zip(&mie)
        .map(|((&(sum, _, t_cl), &d), &(_, p_air))| {
            let t_end = t_ground(d);
            // The slices' range along the ray, clipped to [0, t_end].
            let nd = s.normal.dot(d);
            let (ta, tb) = if nd.abs() < 1e-12 {
                let inside = (s.range.0..=s.range.1).contains(&n_dot_e);
                if inside { (0.0, t_end) } else { (0.0, 0.0) }
            } else {
                let (x, y) = ((s.range.0 - n_dot_e) / nd, (s.range.1 - n_dot_e) / nd);
                (x.min(y).clamp(0.0, t_end), x.max(y).clamp(0.0, t_end))
            };
            let cos_sun = d.dot(s.to_sun);
            // In-scattering by the air over [t0, t1], per unit irradiance: Eq. 14 where the
            // segment is on the sun's side of the slices, less the final shadow's deficit on
            // the far side.
            let air_segment = |t0: f64, t1: f64| -> [f64; 3] {
                if !air_on || t1 <= t0 {
                    return [0.0; 3];
                }
                let a = atm.inscatter(y_eye, d.y, t1, l_y, cos_sun);
                let b = atm.inscatter(y_eye, d.y, t0, l_y, cos_sun);
                let mut out: [f64; 3] = std::array::from_fn(|c| a[c] - b[c]);
                let probe = s.eye + (t0 + 1e-6 * (t1 - t0).min(1.0)) * d;
                if s.sunward_of_slices(probe) {
                    return out;
                }
                let (lo, hi) = prism_span(&s, res, s.eye, d, t0, t1.min(t0 + SHADOWED_AIR_MAX_M));
                if hi <= lo {
                    return out;
                }
                let dt = (hi - lo) / SHADOWED_AIR_POINTS as f64;
                for i in 0..SHADOWED_AIR_POINTS {
                    let t = lo + (i as f64 + 0.5) * dt;
                    let p = s.eye + t * d;
                    let g_cl = shadow_at(&shadow, res, s.shadow_coords(p));
                    let sun = atm.sunlight(p.y, l_y);
                    let tr = atm.transparency(y_eye, d.y, t);
                    for c in 0..3 {
                        let beta = atm.beta_sea_level_per_m[c] * (-p.y / atm.scale_height_m).exp();
                        out[c] -= beta * p_air * sun[c] * tr[c] * (1.0 - g_cl[c]) * dt;
                    }
                }
                out
            };
            let front = air_segment(0.0, ta);
            let back = air_segment(tb, t_end);
            let t_front = atm.transparency(y_eye, d.y, ta);
            let t_all = atm.transparency(y_eye, d.y, t_end);
            // What lies beyond: the ground, lit through the final shadow surface, or the sun.
            let end: [f64; 3] = if t_end.is_finite() {
                let ground = s.eye + t_end * d;
                let g_cl = shadow_at(&shadow, res, s.shadow_coords(ground));
                std::array::from_fn(|c| {
                    settings.ground_albedo / PI * l_y * sun_ground[c] * g_cl[c] * t_all[c]
                })
            } else if cos_sun >= cos_disk {
                std::array::from_fn(|c| t_all[c] / disk_sr)
            } else {
                [0.0; 3]
            };
            let rgb = std::array::from_fn(|c| {
                let i_s = irradiance[c];
                let v = i_s * front[c] + t_front[c] * sum[c] + t_cl[c] * i_s * (back[c] + end[c]);
                v as f32
            });
            (rgb, t_cl[1] as f32)
        })
        .collect();
    Ok(Image {
        width: w,
        height: h,
        rgb: pixels.iter().map(|p| p.0).collect(),
        transparency: pixels.iter().map(|p| p.1).collect(),
    })
}
