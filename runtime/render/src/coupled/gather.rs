//! The `coupled` model's gather on the CPU (rayon, f64; [module docs](super) step 4): along
//! every pixel's ray through the δ-scaled extinction, the beam scattered by the exact (blurred)
//! phase function and the diffuse light by p′, composed with the sky and the ground.

use glam::DVec3;
use rayon::prelude::*;

use runtime::{FieldTable, Tables, sample};

use super::{Emergent, Settings};
use crate::geometry::box_span;
use crate::lighting::lattice::{trilinear, voxel_size};
use crate::lighting::transport;
use crate::shading::{coefficients, compose};
use crate::skylight::SkyLight;
use crate::{checks::FrameError, frame::Frame, image::Image, volume::MAX_FIELDS};

use super::light::*;
use super::moments::*;

/// Step 4 of the [module docs](super): the gather along every pixel's ray and the
/// composition, from `lighting` ([`light`] of a frame with the same grid and sun).
pub fn gather(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    lighting: &Lighting,
) -> Result<Image, FrameError> {
    check(tables, frame, settings)?;
    lighting.check_frame(frame)?;
    // The transport's moments (a relight's step on the GPU leaves them there: read back here).
    let moments = lighting.moments()?;
    let fields: Vec<&FieldTable> = tables.fields.iter().collect();
    let grid = &frame.grid;
    let step = 0.5
        * voxel_size(grid)
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
    let axes = frame.camera.axes().expect("checked by check_view");
    let (w, hgt) = (frame.width, frame.height);
    let sky = SkyLight::of(frame);
    let pixels: Vec<([f32; 3], f32)> = (0..w * hgt)
        .into_par_iter()
        .map(|px| {
            // The pixel's ray: from the eye, or an orthographic image's point (`eye`).
            let (eye, d) = frame.camera.pixel(axes, (px % w, px / w), (w, hgt));
            // The harmonics towards the eye, which the transport's light is scattered into.
            let harmonics = (!moments.is_empty()).then(|| transport::harmonics(-d));
            let towards = harmonics.as_ref().map(|y| (y, &moments[..]));
            let (mut l_vol, mut tr, mut seen) = ([0.0f64; 3], [1.0f64; 3], [1.0f64; 3]);
            // The forward peak's optical depth from the eye ([`super::peak`]).
            let mut depth_out = 0.0;
            // A periodic grid's layer unbounded in x and z, followed for 1000 periods at most.
            let (lo, hi) = grid.bounds();
            if let Some((t0, t1)) = box_span(lo, hi, eye, d) {
                let t0 = t0.max(0.0);
                let t1 = t1.min(t0 + grid.longest_path_m());
                let n = (((t1 - t0) / step).ceil() as usize).max(1);
                let dt = (t1 - t0) / n as f64;
                for k in 0..n {
                    let p = eye + (t0 + (k as f64 + 0.5) * dt) * d;
                    let ray = (d, towards, (depth_out, dt));
                    let light = in_scattered(tables, &fields, frame, lighting, settings, p, ray);
                    let Some(step) = light else { continue };
                    depth_out += step.peak * dt;
                    for c in 0..3 {
                        // The light is seen through the δ-scaled extinction β_ext(1 − αf)
                        // (what the forward peak scatters still travels towards the eye), and
                        // so is the smooth background (the air and the ground behind: what the
                        // peak scatters out of the ray it scatters in from next to it); the
                        // sun's disk and T_vol through the true one.
                        let scaled = step.ext[c] * step.kept[c] * dt;
                        let true_slab = (-step.ext[c] * dt).exp();
                        if scaled > 0.0 {
                            let slab = (-scaled).exp();
                            l_vol[c] += seen[c] * (1.0 - slab) * step.light[c] / step.kept[c];
                            seen[c] *= slab;
                        }
                        tr[c] *= true_slab;
                    }
                    if seen.iter().all(|&t| t < 1e-9) {
                        break;
                    }
                }
            }
            let ground_lit = |g: DVec3| lighting.shadow.at(g);
            (
                compose(frame, &sky, eye, d, l_vol, (tr, seen), ground_lit),
                tr[1] as f32,
            )
        })
        .collect();
    Ok(Image::from_pixels(w, hgt, &pixels))
}

/// The harmonics towards the eye and the transport's moments, with the transport.
type Towards<'a> = Option<(
    &'a [f64; transport::HARMONICS],
    &'a [[f64; transport::PER_VOXEL]],
)>;

/// What one point of a pixel's ray sends towards the eye.
pub(super) struct Step {
    /// β_ext (1/m).
    ext: [f64; 3],
    /// 1 − αf: the share of the extinction that is not the forward peak f.
    kept: [f64; 3],
    /// The light a unit of (true) optical depth sends towards the eye: α times the buffer's
    /// light scattered by the phase function, the diffusion's P1 radiance scattered by the
    /// phase function less its forward peak, and the skylight's mean likewise.
    light: [f64; 3],
    /// The forward peak's scattering coefficient (1/m, green; [`super::peak`]).
    peak: f64,
}

/// At `p` on the ray `d` from the eye, the [`Step`] (module docs step 4); `None` where nothing
/// scatters.
pub(super) fn in_scattered(
    tables: &Tables,
    fields: &[&FieldTable],
    frame: &Frame,
    lighting: &Lighting,
    settings: &Settings,
    p: DVec3,
    (d, towards, (depth_out, dt)): (DVec3, Towards, (f64, f64)),
) -> Option<Step> {
    let grid = &frame.grid;
    let rho: [f64; MAX_FIELDS] = grid.sample(p);
    let (ext, sca) = coefficients(fields, &rho);
    if ext.iter().all(|&e| e <= 0.0) {
        return None;
    }
    let sun_dir = lighting.sun_dir;
    let p1_on = settings.emergent == Emergent::P1;
    let buffer = trilinear(grid, &lighting.buffer, None, p);
    let s_atm = frame.atmosphere.sunlight(p.y, sun_dir.y);
    // The beam scattered by Ams_1 blurred by the peak's scatterings on the way in and out to
    // the middle of this step (δ-M's split), or by Ams_{n+1} (n = 0 but with the hemisphere
    // split), and the peak's scattering coefficient here.
    let (phase, peak_coefficient) = match &lighting.blur {
        Some(blur) => {
            let k = blur.coefficient(fields, &rho);
            let depth = buffer[3] + depth_out + 0.5 * k * dt;
            (blur.phase(fields, &rho, depth, sun_dir.dot(d)), k)
        }
        None => {
            let n = buffer[3] + 1.0;
            let phase = sample::mix(fields, &rho, tables.theta_step_deg, n, sun_dir.dot(d));
            (phase, 0.0)
        }
    };
    let g = mixed(fields, &rho, |f| lighting.g[f]);
    let peak = if delta_scaled(settings) {
        mixed(fields, &rho, |f| lighting.peak[f])
    } else {
        [0.0; 3]
    };
    let i0 = trilinear(grid, &lighting.i0, Some(&lighting.active), p);
    let i1 = trilinear(grid, &lighting.p1, Some(&lighting.active), p);
    let sky = trilinear(grid, &lighting.sky_mean, None, p);
    // The transport's radiance moments and p′'s moments here, with the harmonics towards the
    // eye (`towards`, once per ray).
    let sh = towards.map(|(y, moments)| {
        (
            trilinear(&lighting.sh_grid, moments, None, p),
            y,
            reduced_moments(fields, &rho, &lighting.chis, &lighting.peak),
        )
    });
    let toward_eye = -d;
    let mut step = Step {
        ext,
        kept: [1.0; 3],
        light: [0.0; 3],
        peak: peak_coefficient,
    };
    for c in 0..3 {
        if ext[c] <= 0.0 {
            continue;
        }
        let albedo = sca[c] / ext[c];
        let f = peak[c];
        step.kept[c] = 1.0 - albedo * f;
        let sun = frame.sun.irradiance[c] * s_atm[c] * buffer[c];
        // The P1 radiance I_0 + I_1·ω is nowhere negative when |I_1| ≤ I_0; the closure's
        // Q_1/κ_tr term alone is O(1) where the medium is thin (I_0 is O(τ) there), which would
        // make the diffusion's light first order in τ and the thin limit not single scattering.
        let mut i1 = DVec3::new(i1[3 * c], i1[3 * c + 1], i1[3 * c + 2]);
        let limit = i0[c].max(0.0);
        if i1.length() > limit {
            i1 *= limit / i1.length();
        }
        let along = if p1_on {
            (g[c] - f) * i1.dot(toward_eye)
        } else {
            0.0
        };
        let diffuse = match &sh {
            Some((m, y, chi)) => ((1.0 - f)
                * transport::scattered(&m[c * transport::HARMONICS..], &chi[c], y))
            .max(0.0),
            None => ((1.0 - f) * i0[c] + along).max(0.0),
        };
        step.light[c] = albedo * (phase[c] * sun + diffuse + (1.0 - f) * sky[c]);
    }
    Some(step)
}
