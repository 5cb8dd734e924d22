//! What every model computes per sample, on the CPU: extinction and scattering at a point's
//! densities, the tables checked against the grid, a sun-side buffer's bilinear lookup (Riley's
//! light buffer, Miyazaki's shadow surface), and the pixel composed around a volume's light
//! (the air in front of and behind the volume, the sun's disk, the ground).

use glam::DVec3;

use runtime::{FieldTable, Tables};

use crate::geometry::box_span;
use crate::skylight::SkyLight;
use crate::{camera::SUN_DIAMETER_DEG, checks::FrameError, frame::Frame, volume::MAX_FIELDS};

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

/// A pixel's radiance from its ray `d` from `eye`, the volume's radiance `l_vol` (at the box's
/// middle, before the air in front) and transparency `t_vol` per channel: the air in front of
/// and behind the box (Eqs. 11–15), the sun's disk and a Lambertian ground lit through the air
/// (Eq. 12) and through the volume as `ground_lit` says (the fraction of sunlight left at a
/// point below the grid: the ground, and the air there, [`air_shadow`]), and the air's light
/// beyond single scattering from `sky` in front and behind
/// (the ground lit by the sky included; [`crate::skylight`]). The sun's disk is seen through
/// the volume's transparency `t_vol`, the smooth background (air and ground behind) through
/// `t_smooth` — the same, except for a model whose volume light leaves a forward peak in the
/// beam (coupled's δ-scaled extinction: what the peak scatters out of a smooth background, it
/// scatters in from next to it). Every slicing model composes its pixels this way.
pub(crate) fn compose(
    frame: &Frame,
    sky: &SkyLight,
    eye: DVec3,
    d: DVec3,
    l_vol: [f64; 3],
    (t_vol, t_smooth): ([f64; 3], [f64; 3]),
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
    let mut front = atm.inscatter(y, d[1], k_mid, l_y, cos_sun);
    let mut all = atm.inscatter(y, d[1], k_end, l_y, cos_sun);
    if k_end > 0.0 {
        // The whole ray's multiply-scattered light ends at the ground or in space alike; the
        // volume's shadow on the air below it takes from the singly scattered.
        let (a, f) = sky.inscatter(y, d, k_mid, sun_dir);
        let (sf, sa) = air_shadow(frame, eye, d, (k_mid, k_end), &ground_lit);
        for c in 0..3 {
            front[c] += f[c] - sf[c];
            all[c] += a[c] - sa[c];
        }
    }
    let t_mid = atm.transparency(y, d[1], k_mid);
    let on_disk = k_end.is_infinite() && cos_sun >= cos_disk;
    let t_all = atm.transparency(y, d[1], k_end);
    let ground: [f64; 3] = if frame.ground_albedo > 0.0 && k_end.is_finite() && k_end > 0.0 {
        let g = ground_radiance(frame, ground_lit(eye + k_end * d));
        std::array::from_fn(|c| g[c] * t_all[c])
    } else {
        [0.0; 3]
    };
    std::array::from_fn(|c| {
        let i_s = frame.sun.irradiance[c];
        let mut v = i_s * (front[c] + t_smooth[c] * (all[c] - front[c])) + t_mid[c] * l_vol[c];
        if on_disk {
            v += t_vol[c] * i_s * t_all[c] / disk_sr;
        }
        v += t_smooth[c] * i_s * ground[c];
        v as f32
    })
}

/// Samples of the volume's shadow on the air along a ray ([`air_shadow`]).
pub const AIR_SHADOW_STEPS: usize = 32;

/// The air's single scattering (Eq. 14) that the volume's shadow takes from view ray `d` from
/// `eye`, in its first `k_mid` metres and in all of it up to `k_end`, per unit solar irradiance
/// and channel: ∫ T_air(s) β(y_s) S_atm(y_s) P_air (1 − lit(p_s)) ds by the midpoint rule in
/// [`AIR_SHADOW_STEPS`] steps, over the part of the ray below the grid's bottom and within
/// reach of its shadow (horizontally within the footprint's half diagonal plus bottom/tan e of
/// its centre). `lit` is the fraction of sunlight the volume leaves at a point, as for the
/// ground: below the grid every model knows it (Riley's final light buffer, the grid models'
/// [`crate::lighting::sun::ShadowMap`]); beside and inside the grid the air is left unshadowed.
pub(crate) fn air_shadow(
    frame: &Frame,
    eye: DVec3,
    d: DVec3,
    (k_mid, k_end): (f64, f64),
    lit: &impl Fn(DVec3) -> [f64; 3],
) -> ([f64; 3], [f64; 3]) {
    let (mut front, mut all) = ([0.0; 3], [0.0; 3]);
    let atm = &frame.atmosphere;
    let (grid, sun) = (&frame.grid, frame.sun.direction());
    let bottom = grid.min_m.y;
    if atm.beta_sea_level_per_m.iter().all(|&b| b <= 0.0) || bottom <= 0.0 || sun.y <= 0.0 {
        return (front, all);
    }
    // Below the bottom: s ≥ (eye.y − bottom)/(−d_y) looking down from above it, s ≤ (bottom −
    // eye.y)/d_y looking up from below it.
    let (mut s0, mut s1) = (0.0, k_end);
    if eye.y > bottom {
        if d.y >= 0.0 {
            return (front, all);
        }
        s0 = (eye.y - bottom) / -d.y;
    } else if d.y > 0.0 {
        s1 = s1.min((bottom - eye.y) / d.y);
    }
    // Within reach of the shadow: |eye_h + s d_h − c_h| ≤ R.
    let c = 0.5 * (grid.min_m + grid.max_m);
    let half = 0.5 * (grid.max_m - grid.min_m);
    let reach = half.x.hypot(half.z) + bottom * (1.0 - sun.y * sun.y).sqrt() / sun.y;
    let (o, dh) = (
        DVec3::new(eye.x - c.x, 0.0, eye.z - c.z),
        DVec3::new(d.x, 0.0, d.z),
    );
    let (a, b, q) = (
        dh.length_squared(),
        o.dot(dh),
        o.length_squared() - reach * reach,
    );
    if a > 1e-12 {
        let disc = b * b - a * q;
        if disc <= 0.0 {
            return (front, all);
        }
        let r = disc.sqrt();
        s0 = s0.max((-b - r) / a);
        s1 = s1.min((-b + r) / a);
    } else if q > 0.0 {
        return (front, all);
    }
    if s1.is_infinite() || s1 <= s0 {
        return (front, all);
    }
    let phase = crate::sky::rayleigh_phase(d.dot(sun));
    let gamma = 1.0 / atm.scale_height_m;
    let ds = (s1 - s0) / AIR_SHADOW_STEPS as f64;
    for i in 0..AIR_SHADOW_STEPS {
        let s = s0 + (i as f64 + 0.5) * ds;
        let p = eye + s * d;
        let left = lit(p);
        if left.iter().all(|&v| v >= 1.0) {
            continue;
        }
        let (t, sunlight) = (atm.transparency(eye.y, d.y, s), atm.sunlight(p.y, sun.y));
        for ch in 0..3 {
            let beta = atm.beta_sea_level_per_m[ch] * (-gamma * p.y).exp();
            let loss = t[ch] * beta * sunlight[ch] * phase * (1.0 - left[ch]) * ds;
            all[ch] += loss;
            if s < k_mid {
                front[ch] += loss;
            }
        }
    }
    (front, all)
}

/// The Lambertian ground's radiance per unit solar irradiance, per channel (Eq. 12):
/// albedo/π × sin(elevation) × the sunlight reaching the ground through the air, × `lit`, the
/// fraction the volume leaves there.
pub(crate) fn ground_radiance(frame: &Frame, lit: [f64; 3]) -> [f64; 3] {
    let l_y = frame.sun.direction()[1];
    let sun0 = frame.atmosphere.sunlight(0.0, l_y);
    std::array::from_fn(|c| frame.ground_albedo / std::f64::consts::PI * l_y * sun0[c] * lit[c])
}

/// The largest constant a model may add to a phase function (Riley's ξ, Miyazaki's k_multi),
/// 1/sr: the largest forward bin of any table is ~10⁶/sr, and the useful values measured are
/// below 1.
pub const MAX_PHASE_TERM: f64 = 1e6;

/// The slicing models' settings: `slices` in [1, 4096], `light_resolution` (the sun-side
/// buffer's texels per side, `buffer` names it) in [2, 4096].
pub fn check_slicing(
    slices: usize,
    light_resolution: usize,
    buffer: &str,
) -> Result<(), FrameError> {
    if !(1..=4096).contains(&slices) {
        return Err(FrameError(format!(
            "slices = {slices} is outside the allowed range [1, 4096]"
        )));
    }
    if !(2..=4096).contains(&light_resolution) {
        return Err(FrameError(format!(
            "light_resolution = {light_resolution} is outside the allowed range [2, 4096] (the \
             {buffer}'s texels per side)"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{camera::Camera, camera::Sun, sky::Atmosphere, volume::DensityGrid};

    /// Clear air under a wide grid whose bottom is 5 km up, the sun 40° up.
    fn frame() -> Frame {
        let mut grid = DensityGrid::empty();
        grid.min_m = DVec3::new(-2e4, 5000.0, -2e4);
        grid.max_m = DVec3::new(2e4, 6000.0, 2e4);
        Frame {
            camera: Camera {
                position_m: DVec3::new(0.0, 100.0, 0.0),
                look_at_m: DVec3::new(0.0, 100.0, 1.0),
                fov_deg: 40.0,
                projection: Default::default(),
            },
            sun: Sun {
                elevation_deg: 40.0,
                azimuth_deg: 30.0,
                irradiance: [1.0; 3],
            },
            atmosphere: Atmosphere::default(),
            width: 8,
            height: 6,
            grid,
            haze: None,
            ground_albedo: 0.1,
            lights: Vec::new(),
            media: Vec::new(),
            occluders: Vec::new(),
        }
    }

    #[test]
    fn the_air_shadow_is_the_skys_single_scattering_it_darkens() {
        let frame = frame();
        let (atm, sun) = (&frame.atmosphere, frame.sun.direction());
        let eye = DVec3::new(0.0, 100.0, 0.0);
        let d = DVec3::new(0.2, 0.5, 0.8).normalize();
        // The ray leaves the air below the grid at s1; a black volume takes all its light there.
        let s1 = (5000.0 - eye.y) / d.y;
        let (front, all) = air_shadow(&frame, eye, d, (0.5 * s1, f64::INFINITY), &|_| [0.0; 3]);
        let cos = d.dot(sun);
        let want_all = atm.inscatter(eye.y, d.y, s1, sun.y, cos);
        let want_front = atm.inscatter(eye.y, d.y, 0.5 * s1, sun.y, cos);
        for c in 0..3 {
            let (ea, ef) = (all[c] / want_all[c] - 1.0, front[c] / want_front[c] - 1.0);
            println!("channel {c}: whole {ea:+.2e}, front half {ef:+.2e}");
            // The midpoint rule in 32 (16) steps of a smooth integrand: 1.9·10⁻⁵ measured.
            assert!(ea.abs() < 3e-5 && ef.abs() < 3e-5, "{all:?} {want_all:?}");
        }
        // A volume letting all the light through, or a grid on the ground, shadows nothing.
        let none = air_shadow(&frame, eye, d, (0.5 * s1, f64::INFINITY), &|_| [1.0; 3]);
        assert_eq!(none, ([0.0; 3], [0.0; 3]));
        let mut low = frame.clone();
        low.grid.min_m.y = 0.0;
        let none = air_shadow(&low, eye, d, (0.5 * s1, f64::INFINITY), &|_| [0.0; 3]);
        assert_eq!(none, ([0.0; 3], [0.0; 3]));
        // Looking down from above the grid's bottom, only the part below it is shadowed.
        let high = DVec3::new(0.0, 8000.0, 0.0);
        let down = DVec3::new(0.1, -0.6, 0.5).normalize();
        let k_end = high.y / -down.y;
        let (_, all) = air_shadow(&frame, high, down, (0.0, k_end), &|_| [0.0; 3]);
        let s0 = (high.y - 5000.0) / -down.y;
        let cos = down.dot(sun);
        let t0 = atm.transparency(high.y, down.y, s0);
        let from_bottom = atm.inscatter(5000.0, down.y, k_end - s0, sun.y, cos);
        for c in 0..3 {
            let e = all[c] / (t0[c] * from_bottom[c]) - 1.0;
            println!("channel {c}: from above {e:+.2e}");
            assert!(e.abs() < 3e-5, "{all:?}");
        }
    }
}
