//! What every model computes per sample, on the CPU: extinction and scattering at a point's
//! densities, the tables checked against the grid, a sun-side buffer's bilinear lookup (Riley's
//! light buffer, Miyazaki's shadow surface), and the pixel composed around a volume's light
//! (the air in front of and behind the volume, the sun's disk, the ground).

use glam::DVec3;

use runtime::{FieldTable, Tables};

use crate::geometry::box_span;
use crate::skylight::SkyLight;
use crate::{Frame, FrameError, MAX_FIELDS, SUN_DIAMETER_DEG};

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
/// ground point), and the air's light beyond single scattering from `sky` in front and behind
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
        // The whole ray's multiply-scattered light ends at the ground or in space alike.
        let (f, a) = (
            sky.inscatter(y, d, k_mid, sun_dir),
            sky.radiance(y, d, sun_dir),
        );
        for c in 0..3 {
            front[c] += f[c];
            all[c] += a[c];
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
