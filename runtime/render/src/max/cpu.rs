//! The `max` model on the CPU (rayon): reduced sunlight, diffusion solve and final gather as
//! the [module docs](super) describe them.

use std::f64::consts::PI;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use runtime::{FieldTable, Tables, sample};

use super::Settings;
use crate::geometry::box_span;
use crate::lighting::diffusion::{self, Problem};
use crate::lighting::lattice::{
    MIN_DIFFUSION_VOXEL_DEPTH, Voxels, sun_depths, sweep, trilinear, voxel_length, voxel_size,
    voxels,
};
use crate::lighting::sky::{self, Sky, sky_directions, sky_light};
use crate::lighting::sun::{ShadowMap, reduced_sun, transmittance_to_sun};
use crate::lighting::{OnGpu, run};
use crate::shading::{check_fields, coefficients, compose};
use crate::skylight::SkyLight;
use crate::{
    checks::FrameError, frame::Frame, image::Image, volume::DensityGrid, volume::MAX_FIELDS,
};

/// What a `max` render spent and found.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct MaxReport {
    /// Seconds for the reduced sunlight and the sources (steps 1, 2).
    pub propagation_s: f64,
    /// Seconds for the three diffusion solves (step 3).
    pub diffusion_s: f64,
    /// Seconds for the final gather and composition (steps 4, 5).
    pub gather_s: f64,
    /// Seconds for §3's clear-air propagation and the solve after it.
    pub clear_air_s: f64,
    /// The mean radiance (green) that reached a cloud voxel across clear air from other
    /// parts (0 without the propagation).
    pub clear_air_mean: f64,
    /// Conjugate-gradient iterations per channel (over every solve).
    pub iterations: [usize; 3],
    /// Relative residual reached per channel.
    pub residual: [f64; 3],
    /// Unknowns of the diffusion system (voxels with β_ext > 0).
    pub unknowns: usize,
    /// Multigrid levels.
    pub levels: usize,
    /// The largest optical depth an edge segment reached (any channel).
    pub largest_edge_depth: f64,
    /// Where the per-sun passes ran: the reduced sunlight's sweep, the skylight's sweeps and
    /// the diffusion solves ("the CPU", or the adapter; "the CPU (why)" where the GPU refused).
    pub on: [String; 3],
}

/// Clear air shorter than this many sweep steps does not separate two parts of a cloud: the
/// sweep's bilinear interpolation smears a part's own outgoing light one step into empty
/// space beside its silhouette, which would otherwise come back as light "from another part".
pub const MIN_CLEAR_AIR_STEPS: f64 = 2.0;

/// §3's clear-air propagation for one direction of travel `l`: the radiance arriving at every
/// voxel along `l` that left another part of the cloud and crossed clear air on the way. In a
/// full voxel the light emitted so far by the current part (E, from `emission` per unit
/// optical depth) grows and the light from other parts (A) is attenuated; in an empty voxel
/// E becomes pending light P, which joins A when the ray enters a part again after at least
/// [`MIN_CLEAR_AIR_STEPS`] of clear air (and is dropped otherwise). So a part's own light never
/// counts as its incident light (its diffusion carries that).
fn clear_air_light(
    grid: &DensityGrid,
    ext: &[[f64; 3]],
    full: &[bool],
    emission: impl Fn(usize) -> [f64; 3] + Sync,
    l: DVec3,
) -> Vec<[f64; 3]> {
    // State: A (0..3), P (3..6), E (6..9), the clear-air length so far (9).
    let state = sweep::<10>(grid, l, [0.0; 10], |i, b, ds| {
        let mut out = [0.0; 10];
        if full[i] {
            let crossed = b[9] >= MIN_CLEAR_AIR_STEPS * ds;
            let em = emission(i);
            for c in 0..3 {
                let keep = (-ext[i][c] * ds).exp();
                let a = b[c] + if crossed { b[3 + c] } else { 0.0 };
                out[c] = a * keep;
                out[6 + c] = b[6 + c] * keep + (1.0 - keep) * em[c];
            }
        } else {
            for c in 0..3 {
                out[c] = b[c];
                out[3 + c] = b[3 + c] + b[6 + c];
            }
            out[9] = b[9] + ds;
        }
        out
    });
    state.iter().map(|s| [s[0], s[1], s[2]]).collect()
}

/// G(D) = e^{−D(1−α)} − e^{−D}: the fraction of the light a segment of optical depth D
/// scatters at least once (all orders i ≥ 1, each weighted α^i).
fn scattered(d: f64, albedo: f64) -> f64 {
    if d <= 0.0 {
        return 0.0;
    }
    (-d).exp() * (d * albedo).exp_m1()
}

/// What the final gather reads per voxel: everything of a frame that depends on the sun, the sky,
/// the grid and the tables but not on the camera (steps 1–4 of the [module docs](super)), so a
/// moving camera needs only the gather again ([`gather`], or `super::gpu` on a GPU).
#[derive(Debug, Clone)]
pub struct Lighting {
    /// T_sun per voxel and channel: the sunlight the volume leaves there (step 1).
    pub t_sun: Vec<[f64; 3]>,
    /// I_0 per voxel and channel: the diffusion solution (step 3, after step 4).
    pub i0: Vec<[f64; 3]>,
    /// Whether a voxel took part in the solve; I_0 is interpolated over these only.
    pub active: Vec<bool>,
    /// The reduced skylight's mean radiance per voxel and channel, with the light that crossed
    /// clear air (step 4).
    pub sky_mean: Vec<[f64; 3]>,
    /// The grid's dimensions and the sun's direction this lighting was computed for.
    pub dims: [usize; 3],
    /// Unit vector towards the sun.
    pub sun_dir: DVec3,
    /// The sunlight left below the grid (the ground's and the air's light; the GPU gather
    /// reads it too).
    pub shadow: ShadowMap,
    /// The time, iterations and residuals of steps 1–4.
    pub report: MaxReport,
}

impl Lighting {
    /// Checks that `frame` has the grid and sun this lighting was computed for.
    pub fn check_frame(&self, frame: &Frame) -> Result<(), FrameError> {
        crate::lighting::check_lit_for("max", (self.dims, self.sun_dir), frame)
    }
}

/// Renders `frame` with the `max` model ([`light`], then [`gather`]); the report splits the
/// time by stage.
pub fn render(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
) -> Result<(Image, MaxReport), FrameError> {
    let lighting = light(tables, frame, settings)?;
    gather(tables, frame, settings, &lighting)
}

/// Checks what a `max` frame needs of `tables` and `frame`, and returns the Poisson tables'
/// largest depth.
pub(crate) fn check(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
) -> Result<f64, FrameError> {
    frame.check_view()?;
    settings.check()?;
    check_fields(tables, frame)?;
    if frame.haze.is_some() {
        return Err(FrameError(
            "--model max does not model the [haze] layer; use --model miyazaki or truth".into(),
        ));
    }
    for f in &tables.fields {
        if f.poisson.is_none() || f.transport_factor.is_none() {
            return Err(FrameError(format!(
                "field {:?}'s bake has no Poisson table or transport factor (written before \
                 they existed): bake it again",
                f.name
            )));
        }
    }
    Ok(tables
        .fields
        .iter()
        .filter_map(|f| f.poisson.as_ref())
        .map(|p| *p.depths.last().expect("checked"))
        .fold(f64::INFINITY, f64::min))
}

/// Steps 1–4 of the [module docs](super): reduced sun and sky, the diffusion solve and §3's
/// clear-air propagation.
pub fn light(tables: &Tables, frame: &Frame, settings: &Settings) -> Result<Lighting, FrameError> {
    light_with(tables, frame, settings, &())
}

/// [`light`], telling `progress` as each step starts.
pub fn light_with(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn crate::model::Progress,
) -> Result<Lighting, FrameError> {
    light_on(tables, frame, settings, progress, None)
}

/// [`light_with`], the per-sun passes on `on` when given (where `settings.per_sun` lets the
/// adapter run them; [`crate::lighting::run`]).
pub fn light_on(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn crate::model::Progress,
    on: Option<OnGpu>,
) -> Result<Lighting, FrameError> {
    check(tables, frame, settings)?;
    let fields: Vec<&FieldTable> = tables.fields.iter().collect();
    let grid = &frame.grid;
    let h = voxel_size(grid);
    let sun_dir = frame.sun.direction();
    let mut report = MaxReport::default();

    // 1, 2: reduced sunlight and first-scattered sources.
    let steps = 2 + settings.clear_air_iterations as u64;
    progress.update(0, steps, "reduced sunlight and skylight");
    let start = Instant::now();
    let v = voxels(&fields, grid);
    let (tau_sun, sun_on) = run(
        on,
        settings.per_sun,
        "the reduced sunlight",
        |on| Ok(on.sky().depths(on.gpu, grid, &v.ext, -sun_dir)?),
        || Ok(sun_depths(grid, &v.ext, -sun_dir)),
    )?;
    let reduced = reduced_sun(frame, &tau_sun);
    let lit = sky_light(frame, |g| {
        transmittance_to_sun(&fields, grid, g, sun_dir, None)
    });
    let (mut sky, sky_on) = sky::sweep_on((on, settings.per_sun), grid, &v.ext, &lit)?;
    report.propagation_s = start.elapsed().as_secs_f64();

    // 3: diffusion per channel.
    progress.update(1, steps, "diffusion solve");
    let start = Instant::now();
    let h_voxel = (h[0] * h[1] * h[2]).cbrt();
    // Voxels thinner than MIN_DIFFUSION_VOXEL_DEPTH take no part in the solve: a grid's
    // interpolated fringe holds densities down to 1e-19 of the core's, whose D = 1/(3κ_tr)
    // would couple them 10¹⁶ times more strongly than the core and stall any iterative solver.
    let active: Vec<bool> = v
        .ext
        .iter()
        .map(|e| e[1] * h_voxel >= MIN_DIFFUSION_VOXEL_DEPTH)
        .collect();
    let sources = Sources {
        v: &v,
        active: &active,
        reduced: &reduced,
        light: -sun_dir,
        dims: grid.dims,
        h,
        settings,
    };
    let mut i0 = sources.solve(&sky, on, &mut report)?;
    report.diffusion_s = start.elapsed().as_secs_f64();

    // §3: the clouds' own light carried across clear air into other parts, then solved again.
    let start = Instant::now();
    for k in 0..settings.clear_air_iterations {
        progress.update(2 + k as u64, steps, "clear-air propagation and solve");
        let (across, mean) = sources.across_clear_air(tables, frame, &i0, &sky);
        for (j, (m, f)) in across.mean.iter().zip(&across.flux).enumerate() {
            for c in 0..3 {
                sky.mean[j][c] += m[c];
                sky.flux[j][c] += f[c];
            }
        }
        report.clear_air_mean = mean;
        i0 = sources.solve(&sky, on, &mut report)?;
    }
    report.clear_air_s = start.elapsed().as_secs_f64();
    (report.on[0], report.on[1]) = (sun_on, sky_on);
    progress.update(steps, steps, "lighting done");
    Ok(Lighting {
        t_sun: tau_sun.iter().map(|t| t.map(|x| (-x).exp())).collect(),
        i0,
        active,
        sky_mean: sky.mean,
        dims: grid.dims,
        sun_dir,
        shadow: ShadowMap::of(&fields, frame, None),
        report,
    })
}

/// What the diffusion solves read: the voxels' optics, which take part, the reduced sun.
struct Sources<'a> {
    v: &'a Voxels,
    active: &'a [bool],
    reduced: &'a [[f64; 3]],
    /// The sunlight's direction of travel.
    light: DVec3,
    dims: [usize; 3],
    h: [f64; 3],
    settings: &'a Settings,
}

impl Sources<'_> {
    /// Step 3: one solve per channel with the reduced sun and the incident light `sky`
    /// (skylight, and after §3's propagation the clouds' light across clear air).
    fn solve(
        &self,
        sky: &Sky,
        on: Option<OnGpu>,
        report: &mut MaxReport,
    ) -> Result<Vec<[f64; 3]>, FrameError> {
        let v = self.v;
        let mut i0 = vec![[0.0f64; 3]; v.ext.len()];
        for c in 0..3 {
            let problem = Problem {
                dims: self.dims,
                // max refuses a periodic volume (Model::PERIODIC).
                periodic: false,
                h: self.h,
                kappa_tr: v
                    .transport
                    .iter()
                    .zip(self.active)
                    .map(|(t, &on)| if on { t[c] } else { 0.0 })
                    .collect(),
                kappa_a: v
                    .ext
                    .iter()
                    .zip(&v.sca)
                    .map(|(e, s)| (e[c] - s[c]).max(0.0))
                    .collect(),
                q0: (0..v.sca.len())
                    .map(|i| v.sca[i][c] * (self.reduced[i][c] / (4.0 * PI) + sky.mean[i][c]))
                    .collect(),
                q1: (0..v.sca.len())
                    .map(|i| {
                        let flux = self.light * self.reduced[i][c] / (4.0 * PI) + sky.flux[i][c];
                        (flux * v.g_sca[i][c]).to_array()
                    })
                    .collect(),
            };
            let limits = (self.settings.tolerance, self.settings.max_iterations);
            let channel = ["R", "G", "B"][c];
            let (s, solved_on) = run(
                on,
                self.settings.per_sun,
                &format!("channel {channel}"),
                |on| Ok(on.solver().solve_problem(on.gpu, &problem, limits)?),
                || {
                    diffusion::solve(&problem, limits.0, limits.1)
                        .map_err(|e| FrameError(format!("channel {channel}: {e}")))
                },
            )?;
            report.on[2] = solved_on;
            report.iterations[c] += s.iterations;
            report.residual[c] = s.residual;
            report.unknowns = s.unknowns;
            report.levels = s.levels;
            for (out, v) in i0.iter_mut().zip(&s.i0) {
                out[c] = *v;
            }
        }
        Ok(i0)
    }

    /// §3: the light each cloud voxel sends along every sky direction (α (I_0 + S) and the
    /// reduced sun scattered that way) carried across clear air into other parts, as an
    /// incident [`Sky`], and its mean radiance (green) over the cloud's voxels.
    fn across_clear_air(
        &self,
        tables: &Tables,
        frame: &Frame,
        i0: &[[f64; 3]],
        sky: &Sky,
    ) -> (Sky, f64) {
        let (v, grid) = (self.v, &frame.grid);
        let fields: Vec<&FieldTable> = tables.fields.iter().collect();
        let full: Vec<bool> = v.ext.iter().map(|e| e[1] > 0.0).collect();
        let mut across = Sky::zero(v.ext.len());
        for s_dir in sky_directions() {
            // What a voxel sends along −s_dir per unit optical depth: α (I_0 + S) and the
            // reduced sun scattered into −s_dir.
            let rho_of = |i: usize| -> [f64; MAX_FIELDS] {
                std::array::from_fn(|f| f64::from(grid.data[i][f]))
            };
            let cos = self.light.dot(-s_dir);
            let emission = |i: usize| -> [f64; 3] {
                let rho = rho_of(i);
                let p1 = sample::mix(&fields, &rho, tables.theta_step_deg, 1.0, cos);
                std::array::from_fn(|c| {
                    let a = if v.ext[i][c] > 0.0 {
                        v.sca[i][c] / v.ext[i][c]
                    } else {
                        0.0
                    };
                    a * (i0[i][c].max(0.0) + sky.mean[i][c] + p1[c] * self.reduced[i][c])
                })
            };
            let l = clear_air_light(grid, &v.ext, &full, emission, -s_dir);
            across.add(s_dir, |j| l[j]);
        }
        let mean = across
            .mean
            .iter()
            .zip(&full)
            .filter(|(_, f)| **f)
            .map(|(m, _)| m[1])
            .sum::<f64>()
            / full.iter().filter(|f| **f).count().max(1) as f64;
        (across, mean)
    }
}

/// Steps 5–6 of the [module docs](super): the final gather along every pixel's ray and the
/// composition, from `lighting` ([`light`] of a frame with the same grid and sun).
pub fn gather(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    lighting: &Lighting,
) -> Result<(Image, MaxReport), FrameError> {
    let depth_max = check(tables, frame, settings)?;
    lighting.check_frame(frame)?;
    let grid = &frame.grid;
    let h = voxel_size(grid);
    let g = Gather {
        tables,
        frame,
        settings,
        lighting,
        fields: tables.fields.iter().collect(),
        h_voxel: voxel_length(grid),
        step: 0.5 * h.iter().copied().fold(f64::INFINITY, f64::min),
        sun_dir: frame.sun.direction(),
        sky: SkyLight::of(frame),
    };
    let mut report = lighting.report.clone();
    let start = Instant::now();
    let axes = frame.camera.axes().expect("checked by check_view");
    let (w, hgt) = (frame.width, frame.height);
    let gathered: Vec<([f32; 3], f32, f64)> = (0..w * hgt)
        .into_par_iter()
        .map(|px| {
            let (origin, d) = frame.camera.pixel(axes, (px % w, px / w), (w, hgt));
            g.pixel(origin, d)
        })
        .collect();
    report.largest_edge_depth = gathered.iter().map(|g| g.2).fold(0.0, f64::max);
    if report.largest_edge_depth > depth_max {
        return Err(FrameError(format!(
            "an edge segment reached optical depth {:.3}, beyond the bake's Poisson table \
             (poisson_max_depth = {depth_max}): bake with a larger [scene] poisson_max_depth or \
             lower [render.max] threshold",
            report.largest_edge_depth
        )));
    }
    report.gather_s = start.elapsed().as_secs_f64();
    let pixels: Vec<([f32; 3], f32)> = gathered.iter().map(|g| (g.0, g.1)).collect();
    Ok((Image::from_pixels(w, hgt, &pixels), report))
}

/// What the final gather reads.
struct Gather<'a> {
    tables: &'a Tables,
    frame: &'a Frame,
    settings: &'a Settings,
    lighting: &'a Lighting,
    fields: Vec<&'a FieldTable>,
    /// The voxel length (h_x h_y h_z)^{1/3} (m).
    h_voxel: f64,
    /// The march's step, half the smallest voxel side (m).
    step: f64,
    /// Unit vector towards the sun.
    sun_dir: DVec3,
    /// The air's light beyond single scattering.
    sky: SkyLight,
}

/// A ray's march so far: the volume's radiance and transparency, the current edge segment's
/// optical depth, per channel, and the largest edge depth reached.
struct March {
    l_vol: [f64; 3],
    tr: [f64; 3],
    edge: [f64; 3],
    largest: f64,
}

impl Gather<'_> {
    /// Steps 5–6 for the ray `d` from `eye` (the eye, or an orthographic image's point): the
    /// pixel, its T_vol and the largest edge depth.
    fn pixel(&self, eye: DVec3, d: DVec3) -> ([f32; 3], f32, f64) {
        let (frame, grid) = (self.frame, &self.frame.grid);
        let mut m = March {
            l_vol: [0.0; 3],
            tr: [1.0; 3],
            edge: [0.0; 3],
            largest: 0.0,
        };
        if let Some((t0, t1)) = box_span(grid.min_m, grid.max_m, eye, d) {
            let t0 = t0.max(0.0);
            let n = (((t1 - t0) / self.step).ceil() as usize).max(1);
            let dt = (t1 - t0) / n as f64;
            for k in 0..n {
                let p = eye + (t0 + (k as f64 + 0.5) * dt) * d;
                self.step_at(&mut m, p, d, dt);
                if m.tr.iter().all(|&t| t < 1e-9) {
                    break;
                }
            }
        }
        let ground_lit = |g: DVec3| self.lighting.shadow.at(g);
        let rgb = compose(frame, &self.sky, eye, d, m.l_vol, (m.tr, m.tr), ground_lit);
        (rgb, m.tr[1] as f32, m.largest)
    }

    /// One step of length `dt` at `p` along `d`: its share in the dense treatment (diffusion
    /// plus exact single scattering of the sun) and in the edge treatment (the segment's
    /// increment, seen from its entry), module docs step 5.
    fn step_at(&self, m: &mut March, p: DVec3, d: DVec3, dt: f64) {
        let (frame, grid, lighting) = (self.frame, &self.frame.grid, self.lighting);
        let theta_step = self.tables.theta_step_deg;
        let cos_theta = self.sun_dir.dot(d);
        let rho: [f64; MAX_FIELDS] = grid.sample(p);
        let (ext, sca) = coefficients(&self.fields, &rho);
        if ext.iter().all(|&e| e <= 0.0) {
            return;
        }
        let w_edge = self.settings.edge_share(ext[1] * self.h_voxel);
        let s_atm = frame.atmosphere.sunlight(p.y, self.sun_dir[1]);
        let ts = trilinear(grid, &lighting.t_sun, None, p);
        let sun: [f64; 3] = std::array::from_fn(|c| frame.sun.irradiance[c] * s_atm[c] * ts[c]);
        // Diffuse light: the diffusion solution and the reduced skylight, isotropic.
        let i0_here = trilinear(grid, &lighting.i0, Some(&lighting.active), p);
        let sky_here = trilinear(grid, &lighting.sky_mean, None, p);
        // (P1's I_0 can dip below zero where the first-scattered light's flux term dominates,
        // in optically thin voxels: no radiance is negative.)
        let diffuse: [f64; 3] = std::array::from_fn(|c| i0_here[c].max(0.0) + sky_here[c]);
        let p1 = sample::mix(&self.fields, &rho, theta_step, 1.0, cos_theta);
        let before: [f64; 3] = std::array::from_fn(|c| m.edge[c] * w_edge);
        let after: [f64; 3] = std::array::from_fn(|c| before[c] + w_edge * ext[c] * dt);
        let (m_before, m_after) = if w_edge > 0.0 {
            (
                sample::poisson_mix(&self.fields, &rho, theta_step, before, cos_theta),
                sample::poisson_mix(&self.fields, &rho, theta_step, after, cos_theta),
            )
        } else {
            ([0.0; 3], [0.0; 3])
        };
        for c in 0..3 {
            if ext[c] <= 0.0 {
                continue;
            }
            let albedo = sca[c] / ext[c];
            let dtau = ext[c] * dt;
            let slab = (-dtau).exp();
            // Dense share: diffusion plus exact single scattering of the sun.
            let dense = (1.0 - w_edge) * (1.0 - slab) * albedo * (diffuse[c] + p1[c] * sun[c]);
            // Edge share: the segment's increment, seen from its entry.
            let (g0, g1) = (scattered(before[c], albedo), scattered(after[c], albedo));
            let edge_light = (g1 * m_after[c] - g0 * m_before[c]) * sun[c] + (g1 - g0) * diffuse[c];
            let entry = m.tr[c] * before[c].exp();
            m.l_vol[c] += m.tr[c] * dense + entry * edge_light;
            m.tr[c] *= slab;
            m.edge[c] = after[c];
            m.largest = m.largest.max(after[c]);
        }
    }
}
