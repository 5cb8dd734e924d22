//! The `coupled` model on the CPU (rayon): the buffer sweep, the diffusion solve and the
//! gather as the [module docs](super) describe them.

use std::f64::consts::PI;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use runtime::{FieldTable, Tables, sample};

use super::peak::PeakBlur;
use super::{Diffuse, Emergent, Place, Settings, Source, Split, transport};
use crate::diffusion::{self, Problem};
use crate::diffusion_gpu::SolveError;
use crate::geometry::box_span;
use crate::lattice::{
    MIN_DIFFUSION_VOXEL_DEPTH, ShadowMap, Voxels, asymmetry, reduced_sun, sky_light, sky_sweeps,
    sweep, transmittance_to_sun, trilinear, voxel_size, voxels,
};
use crate::shading::{check_fields, coefficients, compose};
use crate::skylight::SkyLight;
use crate::{DensityGrid, Frame, FrameError, Image, MAX_FIELDS};

/// What the lighting of a `coupled` frame spent and found.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CoupledReport {
    /// Seconds for the buffer sweep, the sources and the reduced skylight (steps 1, 2).
    pub buffer_s: f64,
    /// Seconds for the three diffusion solves and the flux (step 3).
    pub diffusion_s: f64,
    /// Where the three diffusion solves ran.
    pub diffusion_on: String,
    /// Where the reduced skylight's sweeps ran.
    pub sky_on: String,
    /// Where the beam's sweep ran.
    pub beam_on: String,
    /// Seconds for the discrete-ordinates transport (0 with `diffuse = "diffusion"`).
    pub transport_s: f64,
    /// Its source iterations.
    pub transport_iterations: usize,
    /// Where its sweeps ran.
    pub transport_on: String,
    /// The transport's grid (the render's, or coarser by `transport_coarsening`).
    pub transport_dims: [usize; 3],
    /// The relative change of the mean radiance in its last iteration.
    pub transport_change: f64,
    /// The transport's energy balance per channel (its sources, what leaves the box, what
    /// is absorbed; [`transport::balance`]).
    #[serde(skip)]
    pub transport_balance: [transport::Balance; 3],
    /// Conjugate-gradient iterations per channel.
    pub iterations: [usize; 3],
    /// Relative residual reached per channel.
    pub residual: [f64; 3],
    /// Unknowns of the diffusion system.
    pub unknowns: usize,
    /// Multigrid levels.
    pub levels: usize,
    /// The forward peak's fit per field that the beam's single scattering is blurred by
    /// ([`super::peak`]; green): its name, half width (degrees), share of the scattering, and
    /// the share of the cone beyond it that blurs the backward half.
    pub peaks: Vec<(String, f64, f64, f64)>,
    /// Where the sunlight went, per channel, as fractions of what entered the box: kept in
    /// the buffer to its exit, absorbed from it, and handed to the diffusion as its source.
    pub budget: Budget,
}

/// The sunlight's budget over the box, per channel: the power entering the box from the sun
/// (per unit irradiance: the box's cross-section towards the sun, m², times S_atm) and, as
/// fractions of it, where the buffer put it and what the diffusion did with its source.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Budget {
    /// Power entering through the faces the sun sees.
    pub incident: [f64; 3],
    /// The buffer's light leaving through the other faces (read at the voxel centres next to
    /// them, so exact for a sun along a grid axis, within half a voxel's loss otherwise).
    pub buffer_out: [f64; 3],
    /// Absorbed from the buffer.
    pub buffer_absorbed: [f64; 3],
    /// Scattered out of the buffer into the diffusion (its sunlit source).
    pub dropped: [f64; 3],
    /// The diffusion's whole source (the dropped sunlight and the skylight), 4π∫Q_0 dV.
    pub diffusion_source: [f64; 3],
    /// Out of the diffusion through its boundary faces, 4π∮J·n dA.
    pub diffusion_out: [f64; 3],
    /// Absorbed in the diffusion, 4π∫κ_a I_0 dV.
    pub diffusion_absorbed: [f64; 3],
}

/// Everything of a frame that depends on the sun, the sky, the grid and the tables but not on
/// the camera (steps 1–3 of the [module docs](super)); [`gather`] renders a view from it.
#[derive(Debug, Clone)]
pub struct Lighting {
    /// The buffer per voxel: I per channel and, with the hemisphere split, Riley's n, with the
    /// δ-split the forward peak's optical depth D from the box's face ([`super::peak`]).
    pub buffer: Vec<[f64; 4]>,
    /// I_0 per voxel and channel.
    pub i0: Vec<[f64; 3]>,
    /// I_1 = 3J per voxel (x, y, z per channel): the P1 radiance's first moment, so the
    /// diffusion's radiance towards ω is I_0 + I_1·ω.
    pub p1: Vec<[f64; 9]>,
    /// The diffuse radiance's spherical-harmonic moments per voxel of `sh_grid` when the
    /// discrete-ordinates transport computed them ([`transport`]); empty otherwise.
    pub sh: Vec<[f64; transport::PER_VOXEL]>,
    /// The grid the transport ran on, whose voxel centres the moments are at: the frame's, or
    /// its blocks with `transport_coarsening` (only its box and dims; its data is empty). The
    /// gathers interpolate the moments there, so a lighting at 128³ on 64³ blocks holds them
    /// for 64³ voxels (150 MiB in f64; 600 MiB at every voxel of the 128³ grid).
    pub sh_grid: DensityGrid,
    /// Each field's Legendre moments χ_0 … χ_{L+1} per channel.
    pub chis: Vec<[[f64; 3]; transport::DEGREE + 2]>,
    /// Whether a voxel took part in the solve.
    pub active: Vec<bool>,
    /// Each field's asymmetry parameter g per channel.
    pub g: Vec<[f64; 3]>,
    /// Each field's forward peak f per channel (the δ-split's unscattered share).
    pub peak: Vec<[f64; 3]>,
    /// The blur of the beam's single scattering by the forward peak, with δ-M's split (the
    /// transport's).
    pub blur: Option<PeakBlur>,
    /// The reduced skylight's mean radiance per voxel and channel.
    pub sky_mean: Vec<[f64; 3]>,
    /// The grid's dimensions this lighting was computed for.
    pub dims: [usize; 3],
    /// Unit vector towards the sun it was computed for.
    pub sun_dir: DVec3,
    /// The sunlight left below the grid (the ground's and the air's light), through the
    /// δ-scaled extinction as the beam is: what the forward peak scatters still reaches them;
    /// the GPU gather reads it too.
    pub shadow: ShadowMap,
    /// Times, iterations, residuals and the energy budget.
    pub report: CoupledReport,
}

impl Lighting {
    /// Checks that `frame` has the grid and sun this lighting was computed for.
    pub fn check_frame(&self, frame: &Frame) -> Result<(), FrameError> {
        if frame.grid.dims != self.dims || frame.sun.direction() != self.sun_dir {
            return Err(FrameError(format!(
                "the coupled lighting was computed for a {:?} grid and the sun towards {:?}; \
                 this frame has {:?} and {:?}: light it again",
                self.dims,
                self.sun_dir,
                frame.grid.dims,
                frame.sun.direction()
            )));
        }
        Ok(())
    }
}

/// Checks what a `coupled` frame needs of `tables` and `frame`.
pub(crate) fn check(tables: &Tables, frame: &Frame, settings: &Settings) -> Result<(), FrameError> {
    frame.check_view()?;
    settings.check()?;
    check_fields(tables, frame)?;
    if frame.haze.is_some() {
        return Err(FrameError(
            "--model coupled does not model the [haze] layer; use --model miyazaki or truth".into(),
        ));
    }
    if let Some(f) = tables.fields.iter().find(|f| f.transport_factor.is_none()) {
        return Err(FrameError(format!(
            "field {:?}'s bake has no transport factor (written before it existed): bake it \
             again",
            f.name
        )));
    }
    Ok(())
}

/// Steps 1–3 of the [module docs](super).
pub fn light(tables: &Tables, frame: &Frame, settings: &Settings) -> Result<Lighting, FrameError> {
    light_with(tables, frame, settings, &())
}

/// The buffer's state per voxel: I (0..3), n or D (3), β_ext (4..7) and β_sca (7..10) for the next
/// step's trapezoid, the dropped (scattered out of the beam) loss per unit length (10..13) and
/// its forward part α(g − f)/(1 − αf) per unit length (13..16), and the whole loss per unit
/// length (16..19), all per unit irradiance.
pub const BEAM_STATE: usize = 19;
const STATE: usize = BEAM_STATE;

/// What the beam's sweep needs of a voxel: β_ext and β_sca, the split's forward peak f (but
/// for the hemisphere split, whose F_n depends on the scatterings the beam kept), the
/// asymmetry g, and the share of β_sca (green) whose scatterings the forward peak's blur
/// counts (0 without a blur).
#[derive(Debug, Clone, Copy)]
pub struct BeamMedium {
    /// β_ext per channel (1/m).
    pub ext: [f64; 3],
    /// β_sca per channel (1/m).
    pub sca: [f64; 3],
    /// The split's forward peak f per channel (0 for the hemisphere split and without the
    /// buffer's source).
    pub f: [f64; 3],
    /// The asymmetry parameter g per channel.
    pub g: [f64; 3],
    /// The share of β_sca (green) whose scatterings the peak's blur counts.
    pub share: f64,
}

/// Each voxel's [`BeamMedium`].
fn beam_medium(
    fields: &[&FieldTable],
    grid: &DensityGrid,
    v: &Voxels,
    settings: &Settings,
    (peaks, blur): (&[[f64; 3]], Option<&PeakBlur>),
) -> Vec<BeamMedium> {
    (0..grid.data.len())
        .into_par_iter()
        .map(|i| {
            let (ext, sca) = (v.ext[i], v.sca[i]);
            let rho: [f64; MAX_FIELDS] = std::array::from_fn(|f| f64::from(grid.data[i][f]));
            let g = std::array::from_fn(|c| {
                if sca[c] > 0.0 {
                    v.g_sca[i][c] / sca[c]
                } else {
                    0.0
                }
            });
            let f = match (settings.source, settings.split) {
                (Source::Buffer, Split::DeltaEddington) => mixed(fields, &rho, |f| peaks[f]),
                _ => [0.0; 3],
            };
            // In the δ-split the beam's light is Ams_1's, blurred by the peak's scatterings,
            // whose optical depth D the sweep counts (the peak's share of the scattering).
            let share = match blur {
                Some(blur) if settings.split != Split::Hemisphere && sca[1] > 0.0 => {
                    blur.coefficient(fields, &rho) / sca[1]
                }
                _ => 0.0,
            };
            BeamMedium {
                ext,
                sca,
                f,
                g,
                share,
            }
        })
        .collect()
}

/// Step 1 and the loss of step 2: the buffer swept along `l`, the direction of travel,
/// through `medium`.
pub fn beam_sweep(
    fields: &[&FieldTable],
    grid: &DensityGrid,
    medium: &[BeamMedium],
    l: DVec3,
    settings: &Settings,
) -> Vec<[f64; STATE]> {
    // Outside the box: the sunlight unscattered (I = 1, n = 0) in clear air.
    let mut outside = [0.0; STATE];
    outside[..3].copy_from_slice(&[1.0; 3]);
    let hemisphere = (settings.source, settings.split) == (Source::Buffer, Split::Hemisphere);
    sweep::<STATE>(grid, l, outside, |i, b, ds| {
        let m = &medium[i];
        // From the point one layer back (trapezoid; clear air beyond the box's faces).
        let (start, n0, path) = ([b[0], b[1], b[2]], b[3], ds);
        let ext: [f64; 3] = std::array::from_fn(|c| 0.5 * (b[4 + c] + m.ext[c]));
        let sca: [f64; 3] = std::array::from_fn(|c| 0.5 * (b[7 + c] + m.sca[c]));
        let tau: [f64; 3] = ext.map(|e| e * path);
        let f = if hemisphere {
            let rho: [f64; MAX_FIELDS] = std::array::from_fn(|f| f64::from(grid.data[i][f]));
            sample::forward_fraction_mix(fields, &rho, n0 + 1.0 + tau[1])
        } else {
            m.f
        };
        let mut out = [0.0; STATE];
        out[3] = n0;
        if ext[1] > 0.0 {
            // Riley's n counts the scatterings the beam kept (the hemisphere split); the
            // δ-split counts the peak's optical depth D.
            if settings.split == Split::Hemisphere {
                out[3] += sca[1] / ext[1] * tau[1];
            } else {
                out[3] += sca[1] * path * m.share;
            }
        }
        for c in 0..3 {
            let albedo = if ext[c] > 0.0 { sca[c] / ext[c] } else { 0.0 };
            let lost = 1.0 - albedo * f[c];
            let kept = start[c] * (-tau[c] * lost).exp();
            out[c] = kept;
            out[4 + c] = m.ext[c];
            out[7 + c] = m.sca[c];
            if lost > 1e-12 && ds > 0.0 {
                let loss = (start[c] - kept) / ds;
                out[10 + c] = loss * albedo * (1.0 - f[c]) / lost;
                out[13 + c] = loss * albedo * (m.g[c] - f[c]) / lost;
                out[16 + c] = loss;
            }
        }
        out
    })
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

/// An adapter and the per-sun passes compiled for it: the transport's sweeps
/// ([`super::sweep_gpu`]), the skylight's ([`super::sky_gpu`]) and the diffusion solves
/// ([`crate::diffusion_gpu`]).
#[derive(Clone, Copy)]
pub struct OnGpu<'a> {
    /// The adapter.
    pub gpu: &'a runtime::gpu::Gpu,
    /// The sweeps' pipeline.
    pub sweeper: &'a super::sweep_gpu::Sweeper,
    /// The skylight sweeps' pipeline.
    pub sky: &'a super::sky_gpu::SkySweeper,
    /// The beam sweep's pipeline.
    pub beam: &'a super::beam_gpu::BeamSweeper,
    /// The solver's pipelines.
    pub solver: &'a crate::diffusion_gpu::Solver,
}

/// A per-sun pass (`what`) and where it ran: on `on`'s GPU when given, else on the CPU; where
/// the GPU refuses it (its limits), `auto` falls back to the CPU, saying why, and `gpu` fails
/// naming the refusal.
fn on_gpu_or_cpu<T>(
    on: Option<OnGpu>,
    per_sun: Place,
    what: &str,
    gpu: impl FnOnce(OnGpu) -> Result<T, crate::gpu::RenderError>,
    cpu: impl FnOnce() -> T,
) -> Result<(T, String), FrameError> {
    match on.map(|on| (on.gpu.describe(), gpu(on))) {
        None => Ok((cpu(), "the CPU".to_string())),
        Some((adapter, Ok(done))) => Ok((done, adapter)),
        Some((_, Err(e))) if per_sun == Place::Auto => Ok((cpu(), format!("the CPU ({e})"))),
        Some((_, Err(e))) => Err(FrameError(format!("{what} on the GPU: {e}"))),
    }
}

/// [`light_with`], the transport's sweeps and the diffusion solves on `on` when given.
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
    let l = -sun_dir;
    let mut report = CoupledReport::default();

    progress.update(0, 3, "light buffer and skylight");
    let start = Instant::now();
    let v = voxels(&fields, grid);
    let chis: Vec<Moments> = fields
        .iter()
        .map(|f| legendre_moments(f, tables.theta_step_deg))
        .collect();
    let peak = peaks(&fields, &chis, settings);
    // The peak's blur with δ-M's split (the transport's), whose gather it was measured with;
    // the diffusion alone keeps the exact Ams_1.
    let blurred = delta_scaled(settings) && settings.diffuse == Diffuse::Transport;
    // None where no field's peak is blurred (rain, ice): Ams_1 as it is, without the tables.
    let blur = blurred
        .then(|| PeakBlur::of(&fields, tables.theta_step_deg, &peak))
        .filter(PeakBlur::blurs);
    let medium = beam_medium(&fields, grid, &v, settings, (&peak, blur.as_ref()));
    // The beam on the GPU when asked (but for the hemisphere split, whose F_n the sweep looks
    // up as it goes).
    let (state, beam_on) = on_gpu_or_cpu(
        on.filter(|_| settings.split != Split::Hemisphere),
        settings.per_sun,
        "the beam",
        |on| on.beam.sweep(on.gpu, grid, &medium, l),
        || beam_sweep(&fields, grid, &medium, l, settings),
    )?;
    report.beam_on = beam_on;
    if let Some(blur) = &blur {
        report.peaks = fields
            .iter()
            .zip(&blur.fields)
            .filter(|(_, b)| b.share[1] > 0.0)
            .map(|(f, b)| {
                (
                    f.name.clone(),
                    b.half_width_deg[1],
                    b.share[1],
                    b.cone_share[1],
                )
            })
            .collect();
    }
    // E S_atm per voxel: the sun's irradiance at each voxel's height, before the volume.
    let sunlight = reduced_sun(frame, &vec![[0.0; 3]; v.ext.len()]);
    // The ground lit as the composite lights it (through the δ-scaled extinction).
    let scaled = delta_scaled(settings).then_some(peak.as_slice());
    let lit = sky_light(frame, |g| {
        transmittance_to_sun(&fields, grid, g, sun_dir, scaled)
    });
    let (sky, sky_on) = on_gpu_or_cpu(
        on,
        settings.per_sun,
        "the skylight",
        |on| on.sky.sweep(on.gpu, grid, &v.ext, &lit),
        || sky_sweeps(grid, &v.ext, &lit),
    )?;
    report.sky_on = sky_on;
    report.buffer_s = start.elapsed().as_secs_f64();

    progress.update(1, 3, "diffusion solve");
    let start = Instant::now();
    let h_voxel = (h[0] * h[1] * h[2]).cbrt();
    let active: Vec<bool> = v
        .ext
        .iter()
        .map(|e| e[1] * h_voxel >= MIN_DIFFUSION_VOXEL_DEPTH)
        .collect();
    let n = v.ext.len();
    let mut i0 = vec![[0.0f64; 3]; n];
    let mut p1 = vec![[0.0f64; 9]; n];
    for c in 0..3 {
        let problem = Problem {
            dims: grid.dims,
            h,
            kappa_tr: (0..n)
                .map(|i| if active[i] { v.transport[i][c] } else { 0.0 })
                .collect(),
            kappa_a: (0..n)
                .map(|i| (v.ext[i][c] - v.sca[i][c]).max(0.0))
                .collect(),
            q0: (0..n)
                .map(|i| {
                    sunlight[i][c] * state[i][10 + c] / (4.0 * PI) + v.sca[i][c] * sky.mean[i][c]
                })
                .collect(),
            q1: (0..n)
                .map(|i| {
                    let sun = l * (sunlight[i][c] * state[i][13 + c] / (4.0 * PI));
                    (sun + sky.flux[i][c] * v.g_sca[i][c]).to_array()
                })
                .collect(),
        };
        let limits = (
            settings.diffusion_tolerance,
            settings.max_diffusion_iterations,
        );
        let channel = ["R", "G", "B"][c];
        // On the GPU when asked; `auto` falls back to the CPU where the adapter cannot hold
        // the solve, `gpu` fails naming the limit.
        let on_cpu = || {
            diffusion::solve(&problem, limits.0, limits.1)
                .map_err(|e| FrameError(format!("channel {channel}: {e}")))
        };
        let (s, solved_on) =
            match on.map(|on| diffusion::solve_on(&problem, limits, on.gpu, on.solver)) {
                None => (on_cpu()?, "the CPU".to_string()),
                Some(Ok(s)) => (s, on.map_or(String::new(), |on| on.gpu.describe())),
                Some(Err(SolveError::Gpu(e))) if settings.per_sun == Place::Auto => {
                    (on_cpu()?, format!("the CPU ({e})"))
                }
                Some(Err(e)) => {
                    return Err(FrameError(format!("channel {channel} on the GPU: {e}")));
                }
            };
        report.diffusion_on = solved_on;
        report.iterations[c] = s.iterations;
        report.residual[c] = s.residual;
        report.unknowns = s.unknowns;
        report.levels = s.levels;
        let flux = diffusion::flux(&problem, &s.i0);
        for i in 0..n {
            i0[i][c] = s.i0[i];
            for a in 0..3 {
                p1[i][3 * c + a] = 3.0 * flux[i][a];
            }
        }
        let buffer = BufferLight {
            state: &state,
            sunlight: &sunlight,
        };
        report.budget.add(c, (&problem, &s.i0), &buffer, l);
    }
    report.diffusion_s = start.elapsed().as_secs_f64();
    let mut sh = Vec::new();
    let mut sh_grid = box_of(grid);
    if settings.diffuse == Diffuse::Transport {
        progress.update(2, 3, "discrete-ordinates transport");
        let start = Instant::now();
        let sources = Sources {
            sunlight: &sunlight,
            state: &state,
            sky: &sky,
            active: &active,
        };
        let diffusion = (i0.as_slice(), p1.as_slice());
        let Transported {
            on: swept_on,
            moments,
            report: t,
            balance,
            grid: on_grid,
        } = transport_light(
            &fields,
            grid,
            &v,
            &sources,
            (&chis, &peak),
            l,
            diffusion,
            (settings, on),
        )?;
        sh = moments;
        sh_grid = on_grid;
        report.transport_on = swept_on;
        report.transport_balance = balance;
        report.transport_iterations = t.changes.len();
        report.transport_dims = sh_grid.dims;
        report.transport_change = t.changes.last().copied().unwrap_or(0.0);
        report.transport_s = start.elapsed().as_secs_f64();
    }
    progress.update(3, 3, "lighting done");
    let shadow = ShadowMap::of(&fields, frame, delta_scaled(settings).then_some(&peak));
    Ok(Lighting {
        buffer: state.iter().map(|s| [s[0], s[1], s[2], s[3]]).collect(),
        i0,
        p1,
        sh,
        sh_grid,
        chis,
        active,
        g: asymmetries(&fields),
        peak,
        blur,
        sky_mean: sky.mean,
        dims: grid.dims,
        sun_dir,
        shadow,
        report,
    })
}

impl Budget {
    /// Channel `c`'s budget from its problem and solution, the buffer's `state` and the
    /// `sunlight` E S_atm per voxel (light travelling along `l`).
    fn add(&mut self, c: usize, (p, i0): (&Problem, &[f64]), light: &BufferLight, l: DVec3) {
        let (h, dims) = (p.h, p.dims);
        let volume = h[0] * h[1] * h[2];
        let [nx, ny, _] = dims;
        let (mut incident, mut out, mut dropped, mut lost) = (0.0, 0.0, 0.0, 0.0);
        for (i, s) in light.state.iter().enumerate() {
            let e = light.sunlight[i][c];
            dropped += e * s[10 + c] * volume;
            lost += e * s[16 + c] * volume;
            // The beam through the box's faces.
            let cc = [i % nx, (i / nx) % ny, i / (nx * ny)];
            for (a, ha) in h.iter().enumerate() {
                for (sign, on_face) in [(-1.0, cc[a] == 0), (1.0, cc[a] + 1 == dims[a])] {
                    let cos = sign * l[a];
                    if !on_face {
                        continue;
                    } else if cos < 0.0 {
                        incident += e * -cos * volume / ha;
                    } else {
                        out += e * s[c] * cos * volume / ha;
                    }
                }
            }
        }
        let solve = diffusion::balance(p, i0);
        let share = |x: f64| x / incident.max(f64::MIN_POSITIVE);
        self.incident[c] = incident;
        self.buffer_out[c] = share(out);
        self.dropped[c] = share(dropped);
        self.buffer_absorbed[c] = share(lost - dropped);
        self.diffusion_source[c] = share(4.0 * PI * solve.source);
        self.diffusion_out[c] = share(4.0 * PI * solve.out);
        self.diffusion_absorbed[c] = share(4.0 * PI * solve.absorbed);
    }
}

/// The buffer's state and the sunlight E S_atm per voxel, which [`Budget::add`] reads.
struct BufferLight<'a> {
    state: &'a [[f64; STATE]],
    sunlight: &'a [[f64; 3]],
}

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
    let fields: Vec<&FieldTable> = tables.fields.iter().collect();
    let grid = &frame.grid;
    let step = 0.5
        * voxel_size(grid)
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
    let axes = frame.camera.axes().expect("checked by check_view");
    let tan_half = frame.camera.tan_half_fov();
    let (w, hgt) = (frame.width, frame.height);
    let eye = frame.camera.position_m;
    let sky = SkyLight::of(frame);
    let pixels: Vec<([f32; 3], f32)> = (0..w * hgt)
        .into_par_iter()
        .map(|px| {
            let d = crate::camera::pixel_ray(axes, tan_half, (px % w, px / w), (w, hgt));
            // The harmonics towards the eye, which the transport's light is scattered into.
            let harmonics = (!lighting.sh.is_empty()).then(|| transport::harmonics(-d));
            let towards = harmonics.as_ref();
            let (mut l_vol, mut tr, mut seen) = ([0.0f64; 3], [1.0f64; 3], [1.0f64; 3]);
            // The forward peak's optical depth from the eye ([`super::peak`]).
            let mut depth_out = 0.0;
            if let Some((t0, t1)) = box_span(grid.min_m, grid.max_m, eye, d) {
                let t0 = t0.max(0.0);
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

/// What one point of a pixel's ray sends towards the eye.
struct Step {
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
fn in_scattered(
    tables: &Tables,
    fields: &[&FieldTable],
    frame: &Frame,
    lighting: &Lighting,
    settings: &Settings,
    p: DVec3,
    (d, towards, (depth_out, dt)): (DVec3, Option<&[f64; transport::HARMONICS]>, (f64, f64)),
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
    let sh = towards.map(|y| {
        (
            trilinear(&lighting.sh_grid, &lighting.sh, None, p),
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

/// Whether the gather treats a forward peak as unscattered (the δ-Eddington split).
pub(crate) fn delta_scaled(settings: &Settings) -> bool {
    (settings.source, settings.split) == (Source::Buffer, Split::DeltaEddington)
}

/// A per-field quantity `value(f)` of the mixture at densities `rho`, per channel, weighted by
/// scattering as the phase functions are ([`sample::mix`]).
fn mixed(fields: &[&FieldTable], rho: &[f64], value: impl Fn(usize) -> [f64; 3]) -> [f64; 3] {
    let (mut num, mut den) = ([0.0; 3], [0.0; 3]);
    for (f, (field, &r)) in fields.iter().zip(rho).enumerate() {
        if r <= 0.0 {
            continue;
        }
        let v = value(f);
        for c in 0..3 {
            let w = r * field.sigma_sca_m2[c];
            num[c] += w * v[c];
            den[c] += w;
        }
    }
    std::array::from_fn(|c| if den[c] > 0.0 { num[c] / den[c] } else { 0.0 })
}

/// Each field's asymmetry parameter g per channel.
fn asymmetries(fields: &[&FieldTable]) -> Vec<[f64; 3]> {
    fields.iter().map(|f| asymmetry(f)).collect()
}

/// Each field's forward peak f per channel, the share of its scattering the split treats as
/// unscattered: δ-M's χ_{L+1} (Wiscombe 1977; `chis`, the fields' Legendre moments) with the
/// transport, δ-Eddington's g² (Joseph, Wiscombe & Weinman 1976) with the diffusion alone.
fn peaks(fields: &[&FieldTable], chis: &[Moments], settings: &Settings) -> Vec<[f64; 3]> {
    if settings.diffuse == Diffuse::Transport {
        return chis.iter().map(|m| m[transport::DEGREE + 1]).collect();
    }
    asymmetries(fields)
        .into_iter()
        .map(|g| g.map(|g| g * g))
        .collect()
}

/// A field's Legendre moments χ_0 … χ_{L+1} per channel, ∫ p P_l dΩ / ∫ p dΩ, with each of
/// Ams_1's samples the phase function's mean over its bin θ_k ± Δθ/2 (as the tables are baked
/// and the truth's sampler reads them), integrated exactly over the bin:
/// ∫ P_l dμ = (P_{l+1} − P_{l−1})/(2l + 1). A forward peak the bins do not resolve is the
/// first sample's mass, its bin's solid angle π(Δθ/2)² times the sample: integrating the
/// samples linearly interpolated instead gave it 4/3 of that (rain's δ 0.54 of the
/// scattering against the bins' 0.47, and δ-M's f = χ_5 0.63 against 0.57).
pub(crate) fn legendre_moments(field: &FieldTable, theta_step_deg: f64) -> Moments {
    const TOP: usize = transport::DEGREE + 2;
    let grid = grid::ThetaGrid::new(theta_step_deg).expect("tables' Δθ was checked at load");
    // P_0 … P_{TOP} at μ.
    let legendre = |mu: f64| {
        let mut pl = [0.0; TOP + 1];
        super::peak::legendre(mu, TOP, |l, v| pl[l] = v);
        pl
    };
    let mut sums = [[0.0; 3]; TOP];
    for k in 0..grid.len().min(field.image.angle_count()) {
        let (lo, hi) = grid.bin_edges_deg(k);
        let (a, b) = (lo.to_radians().cos(), hi.to_radians().cos());
        let (pa, pb) = (legendre(a), legendre(b));
        for (l, s) in sums.iter_mut().enumerate() {
            let integral = if l == 0 {
                a - b
            } else {
                ((pa[l + 1] - pa[l - 1]) - (pb[l + 1] - pb[l - 1])) / (2 * l + 1) as f64
            };
            for c in 0..3 {
                s[c] += field.image.ams[[c, 0, k]] * integral;
            }
        }
    }
    let total = sums[0];
    sums.map(|s| std::array::from_fn(|c| s[c] / total[c]))
}

/// The δ-M-reduced phase function's moments χ′_l = Σ β_sca(χ_l − f)/Σ β_sca(1 − f) of the
/// mixture at densities `rho`, per channel.
fn reduced_moments(
    fields: &[&FieldTable],
    rho: &[f64],
    chis: &[Moments],
    peaks: &[[f64; 3]],
) -> [[f64; transport::DEGREE + 1]; 3] {
    let den = mixed(fields, rho, |k| peaks[k].map(|f| 1.0 - f));
    let mut out = [[0.0; transport::DEGREE + 1]; 3];
    for l in 0..=transport::DEGREE {
        let num = mixed(fields, rho, |k| {
            std::array::from_fn(|c| chis[k][l][c] - peaks[k][c])
        });
        for c in 0..3 {
            out[c][l] = if den[c] > 0.0 { num[c] / den[c] } else { 0.0 };
        }
    }
    out
}

/// A field's Legendre moments χ_0 … χ_{L+1} per channel.
type Moments = [[f64; 3]; transport::DEGREE + 2];

/// The relative residual of the transport's acceleration solves: the correction only needs to
/// be roughly right, the next sweep corrects it (dense_cumulus at 128³: six rounds and the
/// same image to four digits at 10⁻² as at 10⁻⁴, the acceleration 0.5 s a round instead of
/// 0.95 s).
const ACCELERATION_TOLERANCE: f64 = 1e-2;

/// What feeds the transport: E S_atm per voxel, the buffer's state, the reduced skylight, and
/// the diffusion's active voxels.
struct Sources<'a> {
    sunlight: &'a [[f64; 3]],
    state: &'a [[f64; STATE]],
    sky: &'a crate::lattice::Sky,
    active: &'a [bool],
}

/// The diffuse light by discrete ordinates ([`transport`]), from the diffusion's `(I_0, I_1)`:
/// the δ-M-scaled medium (f = χ_{L+1} per field, `peaks`), the sunlit source Q(ω) = q p′(ω·l)
/// with q the diffusion's Q_0 from the beam, the skylit source as the diffusion has it, and the
/// source iteration accelerated by a diffusion solve of each round's change of the mean
/// radiance (diffusion synthetic acceleration, Alcouffe 1977). Fails, naming the change, the
/// tolerance and the cap, when it does not converge within `max_transport_iterations`.
#[allow(clippy::too_many_arguments)]
fn transport_light(
    fields: &[&FieldTable],
    grid: &crate::DensityGrid,
    v: &Voxels,
    sources: &Sources,
    (chis, peak): (&[Moments], &[[f64; 3]]),
    l: DVec3,
    (i0, p1): (&[[f64; 3]], &[[f64; 9]]),
    (settings, on): (&Settings, Option<OnGpu>),
) -> Result<Transported, FrameError> {
    let n = v.ext.len();
    // Per voxel: σ′_t, σ′_s, p′'s moments, the sunlit and the skylit source.
    type Optics = (
        [f64; 3],
        [f64; 3],
        [[f64; transport::DEGREE + 1]; 3],
        [f64; 3],
        [[f64; 4]; 3],
    );
    let optics: Vec<Optics> = (0..n)
        .into_par_iter()
        .map(|i| {
            let rho: [f64; MAX_FIELDS] = std::array::from_fn(|f| f64::from(grid.data[i][f]));
            let f = mixed(fields, &rho, |k| peak[k]);
            let (ext, sca) = (v.ext[i], v.sca[i]);
            (
                std::array::from_fn(|c| ext[c] - sca[c] * f[c]),
                std::array::from_fn(|c| sca[c] * (1.0 - f[c])),
                reduced_moments(fields, &rho, chis, peak),
                std::array::from_fn(|c| {
                    sources.sunlight[i][c] * sources.state[i][10 + c] / (4.0 * PI)
                }),
                std::array::from_fn(|c| {
                    let q1 = sources.sky.flux[i][c] * v.g_sca[i][c];
                    [sca[c] * sources.sky.mean[i][c], q1.x, q1.y, q1.z]
                }),
            )
        })
        .collect();
    let medium = transport::Medium {
        ext: optics.iter().map(|o| o.0).collect(),
        sca: optics.iter().map(|o| o.1).collect(),
        chi: optics.iter().map(|o| o.2).collect(),
        sun: optics.iter().map(|o| o.3).collect(),
        l,
        sky: optics.iter().map(|o| o.4).collect(),
    };
    drop(optics);
    // φ_00 = √(4π) I_0 and φ_1m = Y_1 (4π/3) I_1 of the P1 radiance I_0 + I_1·ω (m = −1, 0, 1:
    // y, z, x).
    let root = (4.0 * PI).sqrt();
    let c1 = 0.488_602_511_902_919_9 * 4.0 * PI / 3.0;
    let start: Vec<[f64; transport::PER_VOXEL]> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut m = [0.0; transport::PER_VOXEL];
            for c in 0..3 {
                let o = c * transport::HARMONICS;
                m[o] = root * i0[i][c];
                m[o + 1] = c1 * p1[i][3 * c + 1];
                m[o + 2] = c1 * p1[i][3 * c + 2];
                m[o + 3] = c1 * p1[i][3 * c];
            }
            m
        })
        .collect();
    // On a coarser grid when asked: the medium, the sources and the start averaged over
    // blocks of voxels; the moments stay there (the gathers interpolate them).
    let kappa_tr: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            if sources.active[i] {
                v.transport[i]
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let kappa_a: Vec<[f64; 3]> = (0..n)
        .map(|i| std::array::from_fn(|c| (v.ext[i][c] - v.sca[i][c]).max(0.0)))
        .collect();
    let factor = settings.coarsening(grid.dims);
    let coarse = (factor > 1).then(|| transport::Coarse::new(grid, factor));
    let (grid, medium, start, kappa_tr, kappa_a) = match &coarse {
        None => (grid, medium, start, kappa_tr, kappa_a),
        Some(c) => (
            &c.grid,
            c.medium(&medium),
            c.average(&start),
            c.average(&kappa_tr),
            c.average(&kappa_a),
        ),
    };
    let (n, h) = (medium.ext.len(), voxel_size(grid));
    // The acceleration: the diffusion of each round's change of the mean radiance, scattered
    // (the error's source), added to φ_00. (Correcting φ_1 by its flux as well diverged.)
    let mut failed = None;
    // The acceleration's operators and their multigrid hierarchies, one per channel, built
    // once; only their sources change per round.
    let operators: Vec<diffusion::Operator> = (0..3)
        .map(|c| {
            diffusion::Operator::of(&Problem {
                dims: grid.dims,
                h,
                kappa_tr: kappa_tr.iter().map(|k| k[c]).collect(),
                kappa_a: kappa_a.iter().map(|k| k[c]).collect(),
                q0: vec![0.0; n],
                q1: vec![[0.0; 3]; n],
            })
        })
        .collect();
    // On the GPU, each operator's hierarchy uploaded once (`auto` falls back to the CPU where
    // the adapter cannot hold them).
    let uploaded = match on.map(|on| {
        operators
            .iter()
            .map(|op| on.solver.upload(on.gpu, op))
            .collect::<Result<Vec<_>, _>>()
    }) {
        None => None,
        Some(Ok(uploaded)) => Some(uploaded),
        Some(Err(_)) if settings.per_sun == Place::Auto => None,
        Some(Err(e)) => {
            return Err(FrameError(format!(
                "the transport's acceleration on the GPU: {e}"
            )));
        }
    };
    let mut q0 = vec![0.0; n];
    let accelerate = |old: &[[f64; transport::PER_VOXEL]],
                      new: &mut [[f64; transport::PER_VOXEL]]| {
        for (c, operator) in operators.iter().enumerate() {
            let o = c * transport::HARMONICS;
            for (i, q) in q0.iter_mut().enumerate() {
                *q = medium.sca[i][c] * (new[i][o] - old[i][o]) / root;
            }
            let (tolerance, cap) = (ACCELERATION_TOLERANCE, settings.max_diffusion_iterations);
            let solved = match &uploaded {
                Some(u) => u[c]
                    .solve(&operator.isotropic(&q0), tolerance, cap)
                    .map_err(|e| e.to_string()),
                None => operator
                    .solve_isotropic(&q0, tolerance, cap)
                    .map_err(|e| e.to_string()),
            };
            match solved {
                Ok(s) => new
                    .par_iter_mut()
                    .zip(&s.i0)
                    .for_each(|(m, d)| m[o] += root * d),
                Err(e) => failed = Some(e),
            }
        }
    };
    let dirs = crate::lattice::fibonacci_directions(settings.directions);
    let cap = settings.max_transport_iterations;
    let limits = (settings.transport_tolerance, cap);
    // On the GPU when asked and the adapter can hold the sweeps; `auto` falls back to the CPU
    // (and says why), `gpu` fails naming the limit.
    let sweeps = match on {
        None => None,
        Some(on) => match on.sweeper.prepare(on.gpu, grid, &medium, &dirs) {
            Ok(sweeps) => Some(Ok(sweeps)),
            Err(e) if settings.per_sun == Place::Gpu => {
                return Err(FrameError(e.to_string()));
            }
            Err(e) => Some(Err(e.to_string())),
        },
    };
    let (on, (m, report)) = match sweeps {
        Some(Ok(sweeps)) => (
            sweeps.describe(),
            transport::solve_with(start, limits, |m| sweeps.round(m), accelerate)
                .map_err(|e| FrameError(format!("the transport's sweeps on the GPU: {e}")))?,
        ),
        Some(Err(refused)) => (
            format!("the CPU ({refused})"),
            transport::solve(grid, &medium, start, &dirs, limits, accelerate),
        ),
        None => (
            "the CPU".into(),
            transport::solve(grid, &medium, start, &dirs, limits, accelerate),
        ),
    };
    if let Some(e) = failed {
        return Err(FrameError(format!("the transport's acceleration: {e}")));
    }
    let budget = transport::balance(grid, &medium, &m);
    let change = report.changes.last().copied().unwrap_or(0.0);
    if change >= settings.transport_tolerance {
        return Err(FrameError(format!(
            "the transport did not converge: the mean radiance still changed by {change:.3e} \
             (relative) in iteration {cap} (max_transport_iterations), transport_tolerance \
             {}; raise max_transport_iterations or loosen transport_tolerance",
            crate::Shown(settings.transport_tolerance)
        )));
    }
    Ok(Transported {
        on,
        moments: m,
        report,
        balance: budget,
        grid: box_of(grid),
    })
}

/// `grid`'s box and dims without its densities.
fn box_of(grid: &DensityGrid) -> DensityGrid {
    DensityGrid {
        min_m: grid.min_m,
        max_m: grid.max_m,
        dims: grid.dims,
        data: Vec::new(),
    }
}

/// What [`transport_light`] found: the moments per voxel of the grid it ran on, the
/// iteration's report, the energy balance per channel and that grid (box and dims).
struct Transported {
    /// Where the sweeps ran.
    on: String,
    moments: Vec<[f64; transport::PER_VOXEL]>,
    report: transport::Report,
    balance: [transport::Balance; 3],
    grid: DensityGrid,
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;

    #[test]
    fn a_peak_in_the_first_bin_holds_its_bins_share_of_the_moments() {
        // Half the scattering in a forward δ the 0.18° bins do not resolve (the first bin's
        // mean), half isotropic: χ_l = 1/2 for every l ≥ 1, as the truth's bins read it. The
        // samples linearly interpolated gave the δ 4/3 of its bin's mass (χ_l = 4/7).
        let first_bin = 2.0 * PI * (1.0 - 0.09f64.to_radians().cos());
        let field = super::super::peak::tests::field(|t| {
            if t == 0.0 {
                0.5 / first_bin
            } else {
                0.5 / (4.0 * PI)
            }
        });
        let chi = legendre_moments(&field, 0.18);
        for (l, c) in chi.iter().enumerate() {
            let expect = if l == 0 { 1.0 } else { 0.5 };
            // Measured: 4.8·10⁻⁶ at l = 5 (P_l over the first bin, and the isotropic half's share
            // of it).
            assert!((c[1] - expect).abs() < 1e-5, "χ_{l} = {}", c[1]);
        }
    }
}
