//! The `coupled` model's per-sun recipe ([module docs](super) steps 1–3b) over the grid
//! lighting layer ([`crate::lighting`]): the beam's medium from the fields' peaks, then the
//! beam, the skylight, the diffusion per channel and the transport, each pass where
//! `per_sun` lets it run ([`crate::lighting::run`]), and the energy budget of the result.
//! The split and its sources are docs/physics.md §7.9 (δ-scaling, Joseph, Wiscombe & Weinman
//! 1976; δ-M, Wiscombe 1977), the diffusion §7.8 (Max et al. 2004 Eqs. 4–7), the transport
//! §7.10.

use std::f64::consts::PI;
use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use runtime::{FieldTable, Tables};

use super::peak::PeakBlur;
use super::{Diffuse, Settings, Source, Split};
use crate::lighting::beam::{BeamMedium, BeamState, Depth, PeakFrom, beam_sweep};
use crate::lighting::diffusion::{self, Problem};
use crate::lighting::lattice::{MIN_DIFFUSION_VOXEL_DEPTH, Voxels, voxel_size, voxels};
use crate::lighting::resident::{MomentsOnGpu, Resident};
use crate::lighting::sky::{self, Sky, sky_light};
use crate::lighting::sun::{ShadowMap, reduced_sun, transmittance_to_sun};
use crate::lighting::{OnGpu, Place, run, transport};
use crate::relight::Stepped;
use crate::shading::check_fields;
use crate::{checks::FrameError, frame::Frame, volume::DensityGrid, volume::MAX_FIELDS};

use super::moments::*;

/// What the lighting of a `coupled` frame spent and found.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CoupledReport {
    /// Seconds for the buffer sweep, the sources and the reduced skylight (steps 1, 2).
    pub buffer_s: f64,
    /// Seconds for the three diffusion solves and the flux (step 3).
    pub diffusion_s: f64,
    /// Whether the diffusion was not solved: the transport started from a previous sun's
    /// moments, and the diffusion's only use with the transport is its start.
    pub diffusion_skipped: bool,
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
    /// Whether it started from a previous lighting's moments (another sun on the same grid)
    /// rather than the diffusion's P1 radiance.
    pub transport_warm: bool,
    /// Where its sweeps ran.
    pub transport_on: String,
    /// What its iteration on the GPU submitted and read back (all zero on the CPU).
    pub transport_traffic: crate::lighting::resident::Traffic,
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
    /// The transport's moments where its iteration ran on the GPU: the adapter's buffer of
    /// them, which a GPU gather on the same device reads in place. They are the relight's
    /// buffer, not a copy: a lighting of a step ([`Relight::current`]) holds them there only
    /// (its `sh` empty: [`Lighting::moments`] reads them back), as they stand when it is
    /// drawn, which a later step moves on; the converged lighting holds them in `sh` too,
    /// and they no longer change.
    pub sh_on_gpu: Option<MomentsOnGpu>,
    /// Shared by every lighting one relight draws (its steps' and its result): all of them but
    /// [`Lighting::sh`] and [`Lighting::sh_on_gpu`] is the same, so a GPU gather keeps the rest
    /// on the GPU from one step's lighting to the next. A lighting changed otherwise must take a
    /// new one.
    pub relight: Arc<()>,
}

impl Lighting {
    /// Whether it holds the transport's moments (in [`Lighting::sh`] or on the GPU).
    pub fn has_transport(&self) -> bool {
        !self.sh.is_empty() || self.sh_on_gpu.is_some()
    }

    /// The transport's moments: [`Lighting::sh`], or where a relight's step left them on the
    /// GPU only, read back from there (as they stand).
    pub fn moments(&self) -> Result<std::borrow::Cow<'_, [Harmonics]>, FrameError> {
        use std::borrow::Cow;
        match &self.sh_on_gpu {
            Some(on_gpu) if self.sh.is_empty() => on_gpu
                .read()
                .map(Cow::Owned)
                .map_err(|e| FrameError(format!("the transport's moments on the GPU: {e}"))),
            _ => Ok(Cow::Borrowed(&self.sh)),
        }
    }

    /// Checks that `frame` has the grid and sun this lighting was computed for.
    pub fn check_frame(&self, frame: &Frame) -> Result<(), FrameError> {
        crate::lighting::check_lit_for("coupled", (self.dims, self.sun_dir), frame)
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
    check_depth(tables, frame, settings)?;
    if let Some(f) = tables.fields.iter().find(|f| f.transport_factor.is_none()) {
        return Err(FrameError(format!(
            "field {:?}'s bake has no transport factor (written before it existed): bake it \
             again",
            f.name
        )));
    }
    Ok(())
}

/// Refuses a scene deeper than the transport converges on within the default iteration cap,
/// naming its depths and the limit: deeper than [`super::MAX_OPTICAL_DEPTH`], or with a product
/// of that depth and its densest transport voxel's optical depth above
/// [`super::MAX_DEPTH_PRODUCT`] (the coarser the grid, the shallower the scene it converges on;
/// docs/models/coupled.md, "Optical depth"). A raised cap or the diffusion alone takes it on.
pub(crate) fn check_depth(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
) -> Result<(), FrameError> {
    let default_cap = Settings::default().max_transport_iterations;
    if settings.diffuse != Diffuse::Transport || settings.max_transport_iterations > default_cap {
        return Ok(());
    }
    let tau = crate::volume::optical_depth(tables, &frame.grid);
    let voxel = transport_voxel_depth(tables, &frame.grid, settings.coarsening(frame.grid.dims));
    let advice = format!(
        "(docs/models/coupled.md, \"Optical depth\"): use --model max or riley, raise \
         max_transport_iterations above {default_cap}, or set diffuse = \"diffusion\""
    );
    if tau > super::MAX_OPTICAL_DEPTH {
        return Err(FrameError(format!(
            "the scene's optical depth is {tau:.0} at its deepest point (green, the least of its \
             three axis lines), more than the {} the transport converges at {advice}",
            super::MAX_OPTICAL_DEPTH
        )));
    }
    if tau * voxel > super::MAX_DEPTH_PRODUCT {
        return Err(FrameError(format!(
            "the scene's optical depth is {tau:.0} at its deepest point (green, the least of its \
             three axis lines) and {voxel:.1} across its densest transport voxel: their product \
             {:.0} is more than the {} the transport converges at on this grid; a finer \
             grid_resolution lowers the voxel's depth {advice}",
            tau * voxel,
            super::MAX_DEPTH_PRODUCT
        )));
    }
    Ok(())
}

/// The optical depth (green) across the densest voxel of the transport's grid: the largest
/// β_ext of `grid` times its longest voxel edge, `coarsening` voxels to a transport voxel (an
/// upper bound where blocks average denser and thinner voxels).
pub(crate) fn transport_voxel_depth(tables: &Tables, grid: &DensityGrid, coarsening: usize) -> f64 {
    let densest = grid
        .data
        .iter()
        .map(crate::volume::green_extinction(tables))
        .fold(0.0, f64::max);
    let edge = voxel_size(grid).into_iter().fold(0.0, f64::max);
    densest * edge * coarsening.max(1) as f64
}

/// Steps 1–3 of the [module docs](super).
pub fn light(tables: &Tables, frame: &Frame, settings: &Settings) -> Result<Lighting, FrameError> {
    light_with(tables, frame, settings, &())
}

/// Each voxel's [`BeamMedium`].
pub(super) fn beam_medium(
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

/// [`light`], telling `progress` as each step starts.
pub fn light_with(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn crate::model::Progress,
) -> Result<Lighting, FrameError> {
    light_on(tables, frame, settings, progress, None)
}

/// [`light_with`], the transport's sweeps and the diffusion solves on `on` when given.
pub fn light_on(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn crate::model::Progress,
    on: Option<OnGpu>,
) -> Result<Lighting, FrameError> {
    light_from(tables, frame, settings, progress, (on, None))
}

/// [`light_on`], the transport's source iteration starting from `previous`'s moments where
/// it is a lighting of the same grid (another sun: a sun that moves little changes the diffuse
/// light little) instead of the diffusion's P1 radiance; the same converged light either
/// way, to the transport's tolerance. A [`Relight`] run to its end in one call.
pub fn light_from(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
    progress: &dyn crate::model::Progress,
    (on, previous): (Option<OnGpu>, Option<&Lighting>),
) -> Result<Lighting, FrameError> {
    let mut relight = Relight::new(tables, frame, settings, previous)?;
    relight.advance(tables, (on, progress), None)?;
    Ok(relight.finish().expect("advanced to its end"))
}

/// The spherical-harmonic moments of the radiance at one voxel, per channel.
type Harmonics = [f64; transport::PER_VOXEL];

/// What the transport's medium is formed from: the fields, their voxels' optics, and their
/// Legendre moments and forward peaks.
type Optics<'a> = (
    &'a [&'a FieldTable],
    &'a Voxels,
    (&'a [Moments], &'a [[f64; 3]]),
);

/// The diffusion's result: I_0 per channel and I_1 = 3J per channel and axis, per voxel.
type Diffused = (Vec<[f64; 3]>, Vec<[f64; 9]>);

/// A sun's lighting computed in steps, so that a caller with frames to draw can stop between
/// them ([`Relight::advance`] with a budget) and draw meanwhile from [`Relight::current`]:
/// 1. the beam and the skylight (steps 1, 2 of the [module docs](super));
/// 2. the diffusion (step 3; not solved where the transport starts from the previous sun's
///    moments), then the transport's medium, its acceleration and its start;
/// 3. each of the transport's source iterations (step 3b), one a step; on the GPU, in a call
///    with a budget, a round in parts sized to what is left of it ([`Resident::part`]: each
///    a step, at least one of the sweeps' dispatches or one iteration of the acceleration's
///    solves), the lighting meanwhile the last whole round's.
///
/// From the end of step 2 on, [`Relight::current`] is a whole lighting (the diffusion's with
/// the transport's start, then each iteration's moments). The steps do the same arithmetic
/// however the calls divide them (the same lighting but for the solvers' parallel sums, which
/// may associate differently from run to run). The transport's iteration on the GPU (where
/// `on` lets it run) is prepared on its first step and kept there between steps
/// ([`crate::lighting::resident`]): the medium, the acceleration's hierarchies and the moments
/// go up once a relight, and each call reads the moments back once, at its end.
pub struct Relight {
    frame: Frame,
    settings: Settings,
    /// The previous sun's moments (on the transport's grid) to start from.
    warm: Option<Vec<Harmonics>>,
    stage: Stage,
    report: CoupledReport,
    /// Steps taken.
    steps: usize,
}

/// Where a [`Relight`] stands.
enum Stage {
    Start,
    /// The beam and the skylight are lit.
    Lit(Box<Lit>),
    /// The lighting without the transport's moments, and the transport's iteration.
    Transporting(Box<(Lighting, Transporting)>),
    Done(Box<Lighting>),
    /// A step failed; the relight cannot go on.
    Failed,
}

/// What step 1 leaves for the diffusion and the transport.
struct Lit {
    v: Voxels,
    chis: Vec<Moments>,
    peak: Vec<[f64; 3]>,
    blur: Option<PeakBlur>,
    state: Vec<BeamState>,
    sunlight: Vec<[f64; 3]>,
    sky: Sky,
    active: Vec<bool>,
}

/// The transport's source iteration between steps: its grid, medium, acceleration and moments.
struct Transporting {
    /// The transport's blocks, where it runs on a coarser grid than the frame's.
    coarse: Option<transport::Coarse>,
    medium: transport::Medium,
    /// The acceleration's operators and their multigrid hierarchies, one per channel, built
    /// once; only their sources change per round.
    operators: Vec<Arc<diffusion::Operator>>,
    dirs: Vec<DVec3>,
    groups: Vec<transport::Group>,
    moments: Vec<Harmonics>,
    report: transport::Report,
    /// Whether it started from a previous sun's moments.
    warm: bool,
    /// Where its last sweeps ran.
    on: String,
    /// The iteration kept on the GPU between steps, once a step ran there.
    resident: Option<Resident>,
    /// Seconds spent on it so far.
    seconds: f64,
}

impl Relight {
    /// A relight of `frame`'s sun with `settings`, checked (nothing is computed yet), its
    /// transport to start from `previous`'s moments where it lit a grid of these dims.
    pub fn new(
        tables: &Tables,
        frame: &Frame,
        settings: &Settings,
        previous: Option<&Lighting>,
    ) -> Result<Self, FrameError> {
        check(tables, frame, settings)?;
        let warm = match previous.filter(|p| p.dims == frame.grid.dims && p.has_transport()) {
            Some(p) => Some(p.moments()?.into_owned()),
            None => None,
        };
        Ok(Self {
            frame: frame.clone(),
            settings: *settings,
            warm,
            stage: Stage::Start,
            report: CoupledReport::default(),
            steps: 0,
        })
    }

    /// Steps taken so far.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The transport's rounds (source iterations) ended so far, from the step that made the
    /// lighting whole on (`None` before): [`Relight::current`] changes only when this does.
    pub fn rounds(&self) -> Option<usize> {
        match &self.stage {
            Stage::Transporting(t) => Some(t.1.report.changes.len()),
            Stage::Done(lighting) => Some(lighting.report.transport_iterations),
            _ => None,
        }
    }

    /// Whether the lighting has converged ([`Relight::finish`] hands it over).
    pub fn done(&self) -> bool {
        matches!(self.stage, Stage::Done(_))
    }

    /// The frame it lights.
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// The settings it lights with.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Runs steps until the lighting is done or, with a `budget`, until the call has spent it
    /// (checked after each step, so a call runs at least one step, and a step may outlast the
    /// budget); the passes on `on` where the settings let them run, telling `progress`.
    /// Whether the lighting is done. After an error the relight is spent.
    pub fn advance(
        &mut self,
        tables: &Tables,
        (on, progress): (Option<OnGpu>, &dyn crate::model::Progress),
        budget: Option<std::time::Duration>,
    ) -> Result<bool, FrameError> {
        // A periodic grid's sweeps wrap and repeat, which only the CPU passes do.
        let on = on.filter(|_| !self.frame.grid.periodic);
        let deadline = budget.map(|b| Instant::now() + b);
        let spent = || deadline.is_some_and(|d| Instant::now() >= d);
        while !self.done() {
            let stage = std::mem::replace(&mut self.stage, Stage::Failed);
            self.stage = match stage {
                Stage::Start => {
                    progress.update(0, 3, "light buffer and skylight");
                    self.steps += 1;
                    Stage::Lit(Box::new(self.light(tables, on)?))
                }
                Stage::Lit(lit) => {
                    progress.update(1, 3, "diffusion solve");
                    self.steps += 1;
                    self.diffuse(tables, *lit, on)?
                }
                Stage::Transporting(t) => {
                    let (base, mut run) = *t;
                    progress.update(2, 3, "discrete-ordinates transport");
                    if self.transport(&mut run, on, deadline)? {
                        Stage::Done(Box::new(self.assemble(base, run)))
                    } else {
                        Stage::Transporting(Box::new((base, run)))
                    }
                }
                Stage::Done(_) => unreachable!("the loop stops when done"),
                Stage::Failed => {
                    return Err(FrameError("the relight failed in an earlier step".into()));
                }
            };
            if spent() {
                break;
            }
        }
        if self.done() {
            progress.update(3, 3, "lighting done");
        }
        Ok(self.done())
    }

    /// The lighting as it stands: the converged one when done, else from the end of step 2
    /// on the diffusion's with the transport's moments so far (a copy); `None` before.
    pub fn current(&self) -> Option<Lighting> {
        match &self.stage {
            Stage::Done(lighting) => Some((**lighting).clone()),
            Stage::Transporting(t) => {
                let (base, run) = &**t;
                let mut lighting = base.clone();
                // On the GPU the moments stay there until the relight converges
                // (`Lighting::moments` reads them back where a caller needs them).
                match &run.resident {
                    Some(resident) => lighting.sh_on_gpu = Some(resident.moments_on_gpu()),
                    None => lighting.sh = run.moments.clone(),
                }
                lighting.report.transport_iterations = run.report.changes.len();
                Some(lighting)
            }
            _ => None,
        }
    }

    /// The converged lighting; `None` before it is done.
    pub fn finish(mut self) -> Option<Lighting> {
        self.take()
    }

    /// The converged lighting, taken out (the relight is spent); `None` before it is done.
    fn take(&mut self) -> Option<Lighting> {
        match std::mem::replace(&mut self.stage, Stage::Failed) {
            Stage::Done(lighting) => Some(*lighting),
            other => {
                self.stage = other;
                None
            }
        }
    }

    /// One frame's steps ([`crate::relight`]): [`Relight::advance`] for `budget`, then on
    /// until the lighting is whole (a new sun's first frame); the converged lighting, or the
    /// lighting as it stands and the steps taken.
    pub fn step_for(
        &mut self,
        tables: &Tables,
        (on, progress): (Option<OnGpu>, &dyn crate::model::Progress),
        budget: std::time::Duration,
    ) -> Result<Stepped<Lighting>, FrameError> {
        let mut done = self.advance(tables, (on, progress), Some(budget))?;
        while !done && !matches!(self.stage, Stage::Transporting(_)) {
            done = self.advance(tables, (on, progress), Some(std::time::Duration::ZERO))?;
        }
        Ok(match self.take() {
            Some(lighting) => Stepped::Done(lighting),
            None => Stepped::Partial(self.current().expect("whole"), self.steps),
        })
    }

    /// Step 1: the beam's medium from the fields' peaks, the beam, and the skylight.
    fn light(&mut self, tables: &Tables, on: Option<OnGpu>) -> Result<Lit, FrameError> {
        let (frame, settings) = (&self.frame, &self.settings);
        let fields: Vec<&FieldTable> = tables.fields.iter().collect();
        let grid = &frame.grid;
        let sun_dir = frame.sun.direction();
        let start = Instant::now();
        let v = voxels(&fields, grid);
        let chis: Vec<Moments> = fields
            .iter()
            .map(|f| legendre_moments(f, tables.theta_step_deg))
            .collect();
        let peak = peaks(&fields, &chis, settings);
        // The peak's blur with δ-M's split (the transport's), whose gather it was measured
        // with; the diffusion alone keeps the exact Ams_1.
        let blurred = delta_scaled(settings) && settings.diffuse == Diffuse::Transport;
        // None where no field's peak is blurred (rain, ice): Ams_1 as it is, without the tables.
        let blur = blurred
            .then(|| PeakBlur::of(&fields, tables.theta_step_deg, &peak))
            .filter(PeakBlur::blurs);
        let medium = (&peak[..], blur.as_ref());
        let (state, beam_on) = beam(&fields, grid, &v, medium, -sun_dir, (settings, on))?;
        self.report.beam_on = beam_on;
        if let Some(blur) = &blur {
            self.report.peaks = blur.report(&fields);
        }
        // E S_atm per voxel: the sun's irradiance at each voxel's height, before the volume.
        let sunlight = reduced_sun(frame, &vec![[0.0; 3]; v.ext.len()]);
        // The ground lit as the composite lights it (through the δ-scaled extinction).
        let scaled = delta_scaled(settings).then_some(peak.as_slice());
        let lit = sky_light(frame, |g| {
            transmittance_to_sun(&fields, grid, g, sun_dir, scaled)
        });
        let (sky, sky_on) = sky::sweep_on((on, settings.per_sun), grid, &v.ext, &lit)?;
        self.report.sky_on = sky_on;
        self.report.buffer_s = start.elapsed().as_secs_f64();
        let h = voxel_size(grid);
        let h_voxel = (h[0] * h[1] * h[2]).cbrt();
        let active = v
            .ext
            .iter()
            .map(|e| e[1] * h_voxel >= MIN_DIFFUSION_VOXEL_DEPTH)
            .collect();
        Ok(Lit {
            v,
            chis,
            peak,
            blur,
            state,
            sunlight,
            sky,
            active,
        })
    }

    /// Step 2: the diffusion (none where the transport starts from the previous sun's
    /// moments), and the lighting without the transport's moments; with the transport, its
    /// medium, acceleration and start.
    fn diffuse(
        &mut self,
        tables: &Tables,
        lit: Lit,
        on: Option<OnGpu>,
    ) -> Result<Stage, FrameError> {
        let (frame, settings) = (&self.frame, &self.settings);
        let fields: Vec<&FieldTable> = tables.fields.iter().collect();
        let grid = &frame.grid;
        let sun_dir = frame.sun.direction();
        let l = -sun_dir;
        let start = Instant::now();
        let buffer = BufferLight {
            state: &lit.state,
            sunlight: &lit.sunlight,
        };
        // With the transport, the diffusion's I_0 and I_1 are its start alone (the gathers
        // read the transport's moments): a start from the last sun's moments needs no solve.
        let fits = |w: &Vec<Harmonics>| w.len() == transport_voxels(grid, settings);
        let skip = settings.diffuse == Diffuse::Transport && self.warm.as_ref().is_some_and(fits);
        let (i0, p1) = if skip {
            let n = lit.v.ext.len();
            for c in 0..3 {
                self.report.budget.add_beam(c, grid, &buffer, l);
            }
            self.report.diffusion_skipped = true;
            (vec![[0.0; 3]; n], vec![[0.0; 9]; n])
        } else {
            diffuse(
                grid,
                (&lit.v, &lit.active),
                (&buffer, &lit.sky),
                l,
                (settings, on),
                &mut self.report,
            )?
        };
        self.report.diffusion_s = start.elapsed().as_secs_f64();
        let shadow = ShadowMap::of(&fields, frame, delta_scaled(settings).then_some(&lit.peak));
        let run = (settings.diffuse == Diffuse::Transport).then(|| {
            let sources = Sources {
                sunlight: &lit.sunlight,
                state: &lit.state,
                sky: &lit.sky,
                active: &lit.active,
            };
            let optics = (&fields[..], &lit.v, (&lit.chis[..], &lit.peak[..]));
            transporting(
                grid,
                optics,
                &sources,
                l,
                (&i0, &p1),
                self.warm.take(),
                settings,
            )
        });
        let base = Lighting {
            buffer: lit
                .state
                .iter()
                .map(|s| [s.intensity[0], s.intensity[1], s.intensity[2], s.depth])
                .collect(),
            i0,
            p1,
            sh: Vec::new(),
            sh_grid: box_of(grid),
            chis: lit.chis,
            active: lit.active,
            g: asymmetries(&fields),
            peak: lit.peak,
            blur: lit.blur,
            sky_mean: lit.sky.mean,
            dims: grid.dims,
            sun_dir,
            shadow,
            report: self.report.clone(),
            sh_on_gpu: None,
            relight: Arc::new(()),
        };
        Ok(match run {
            None => Stage::Done(Box::new(base)),
            Some(run) => {
                let mut base = base;
                base.sh_grid = run
                    .coarse
                    .as_ref()
                    .map_or_else(|| box_of(grid), |c| box_of(&c.grid));
                Stage::Transporting(Box::new((base, run)))
            }
        })
    }

    /// Step 3b's source iterations, one a step, until `spent` (at least one) or converged;
    /// whether it has converged. Fails, naming the change, the tolerance and the cap, when it
    /// does not converge within `max_transport_iterations`.
    fn transport(
        &mut self,
        run: &mut Transporting,
        on: Option<OnGpu>,
        deadline: Option<Instant>,
    ) -> Result<bool, FrameError> {
        let start = Instant::now();
        let spent = || deadline.is_some_and(|d| Instant::now() >= d);
        self.keep_on_gpu(run, on)?;
        let settings = &self.settings;
        let grid = run.coarse.as_ref().map_or(&self.frame.grid, |c| &c.grid);
        let Transporting {
            medium,
            operators,
            dirs,
            groups,
            moments,
            report,
            resident,
            ..
        } = run;
        let weight = 4.0 * PI / dirs.len() as f64;
        let mut failed = None;
        let converged = loop {
            let change = match resident.as_mut() {
                Some(resident) => {
                    // With a deadline, a round in parts sized to it (each a step).
                    let units = deadline.map_or(usize::MAX, |d| resident.units_before(d));
                    let part = resident
                        .part(units)
                        .map_err(|e| FrameError(format!("the transport on the GPU: {e}")))?;
                    let Some(change) = part else {
                        // Without a deadline the part was a round's further chunk, no step.
                        self.steps += usize::from(deadline.is_some());
                        if spent() {
                            break false;
                        }
                        continue;
                    };
                    report.changes.push(change);
                    change
                }
                None => {
                    let round = |m: &[Harmonics]| {
                        Ok::<_, FrameError>(transport::sweep_round(grid, medium, m, groups, weight))
                    };
                    let accelerate = |old: &[Harmonics], new: &mut [Harmonics]| {
                        if let Err(e) = accelerate(medium, operators, (old, new), settings) {
                            failed = Some(e);
                        }
                    };
                    transport::iterate(moments, report, round, accelerate)?
                }
            };
            self.steps += 1;
            if let Some(e) = failed.take() {
                return Err(FrameError(format!("the transport's acceleration: {e}")));
            }
            if !change.is_finite() {
                return Err(FrameError(format!(
                    "the transport broke down: the mean radiance's change is {change} after {} \
                     iterations (the medium or its sources are not finite in floating point at \
                     these optical depths; more iterations would not help)",
                    report.changes.len()
                )));
            }
            if change < settings.transport_tolerance {
                break true;
            }
            if report.changes.len() >= settings.max_transport_iterations {
                return Err(FrameError(format!(
                    "the transport did not converge: the mean radiance still changed by \
                     {change:.3e} (relative) in iteration {} (max_transport_iterations), \
                     transport_tolerance {}; raise max_transport_iterations or loosen \
                     transport_tolerance",
                    settings.max_transport_iterations,
                    crate::checks::Shown(settings.transport_tolerance)
                )));
            }
            if spent() {
                break false;
            }
        };
        // The converged moments (for the lighting, its report and the next sun's start): read
        // back once. A step's lighting before that reads them on the GPU.
        if let Some(resident) = resident.as_mut().filter(|_| converged) {
            *moments = resident
                .moments()
                .map_err(|e| FrameError(format!("the transport on the GPU: {e}")))?;
        }
        run.seconds += start.elapsed().as_secs_f64();
        Ok(converged)
    }

    /// Puts `run`'s iteration on the GPU on its first step there, where `on` is given: the
    /// sweeps' buffers, the acceleration's hierarchies and the moments uploaded once, kept
    /// between steps. Where the adapter refuses, `auto` runs the iteration on the CPU (saying
    /// why) and `gpu` fails naming the refusal.
    fn keep_on_gpu(&self, run: &mut Transporting, on: Option<OnGpu>) -> Result<(), FrameError> {
        let Some(on) = on.filter(|_| run.resident.is_none()) else {
            return Ok(());
        };
        let grid = run.coarse.as_ref().map_or(&self.frame.grid, |c| &c.grid);
        let kept = on
            .transport()
            .prepare(on.gpu, grid, &run.medium, &run.dirs)
            .and_then(|sweeps| {
                Resident::new(
                    (on.gpu, on.resident(), on.solver()),
                    sweeps,
                    (&run.medium, &run.operators),
                    &run.moments,
                    (
                        ACCELERATION_TOLERANCE,
                        self.settings.max_diffusion_iterations,
                    ),
                )
            });
        match kept {
            Ok(resident) => {
                run.on = resident.describe();
                run.resident = Some(resident);
            }
            Err(e) if self.settings.per_sun == Place::Gpu => {
                return Err(FrameError(format!("the transport on the GPU: {e}")));
            }
            Err(refused) => run.on = format!("the CPU ({refused})"),
        }
        Ok(())
    }

    /// The converged lighting: `base` with `run`'s moments, its report and energy balance.
    fn assemble(&mut self, mut base: Lighting, run: Transporting) -> Lighting {
        let grid = run.coarse.as_ref().map_or(&self.frame.grid, |c| &c.grid);
        let r = &mut self.report;
        r.transport_traffic = run
            .resident
            .as_ref()
            .map_or_else(Default::default, Resident::traffic);
        r.transport_on = run.on;
        r.transport_warm = run.warm;
        r.transport_balance = transport::balance(grid, &run.medium, &run.moments);
        r.transport_iterations = run.report.changes.len();
        r.transport_dims = grid.dims;
        r.transport_change = run.report.changes.last().copied().unwrap_or(0.0);
        r.transport_s = run.seconds;
        base.sh = run.moments;
        base.sh_on_gpu = run.resident.as_ref().map(Resident::moments_on_gpu);
        base.report = r.clone();
        base
    }
}

/// The transport's blocks of voxels along each axis with `settings` on `grid` (1: it runs on
/// the grid's voxels).
fn transport_factor(grid: &DensityGrid, settings: &Settings) -> usize {
    let factor = settings.coarsening(grid.dims);
    // A periodic grid's blocks must tile its period: else the transport runs on its voxels.
    let tiles = |a: usize| !grid.wraps(a) || grid.dims[a].is_multiple_of(factor);
    if (0..3).all(tiles) { factor } else { 1 }
}

/// The transport grid's voxels with `settings` on `grid`.
fn transport_voxels(grid: &DensityGrid, settings: &Settings) -> usize {
    let factor = transport_factor(grid, settings);
    transport::Coarse::dims(grid.dims, factor).iter().product()
}

/// The transport's iteration over `optics` (the fields, their voxels, moments and peaks) from
/// `sources`, ready to run: the δ-M-scaled medium (f = χ_{L+1} per field), the sunlit source
/// Q(ω) = q p′(ω·l) with q the diffusion's Q_0 from the beam, the skylit source as the
/// diffusion has it, on the grid's blocks with `transport_coarsening`, starting from `warm`
/// (a previous sun's moments on that grid) or else the diffusion's P1 radiance (I_0, I_1).
fn transporting(
    grid: &DensityGrid,
    (fields, v, (chis, peak)): Optics,
    sources: &Sources,
    l: DVec3,
    (i0, p1): (&[[f64; 3]], &[[f64; 9]]),
    warm: Option<Vec<Harmonics>>,
    settings: &Settings,
) -> Transporting {
    let start = Instant::now();
    let n = v.ext.len();
    let medium = transport_medium(fields, grid, v, sources, (chis, peak), l);
    let p1_start = p1_moments(i0, p1);
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
    let factor = transport_factor(grid, settings);
    // On a coarser grid when asked: the medium, the sources and the start averaged over
    // blocks of voxels; the moments stay there (the gathers interpolate them).
    let coarse = (factor > 1).then(|| transport::Coarse::new(grid, factor));
    let (medium, p1_start, kappa_tr, kappa_a) = match &coarse {
        None => (medium, p1_start, kappa_tr, kappa_a),
        Some(c) => (
            c.medium(&medium),
            c.average(&p1_start),
            c.average(&kappa_tr),
            c.average(&kappa_a),
        ),
    };
    let on_grid = coarse.as_ref().map_or(grid, |c| &c.grid);
    let (n, h) = (medium.ext.len(), voxel_size(on_grid));
    // A previous sun's moments on this transport grid, in place of the diffusion's start.
    let warm = warm.filter(|w| w.len() == p1_start.len());
    let operators = (0..3)
        .map(|c| {
            Arc::new(diffusion::Operator::of(&Problem {
                dims: on_grid.dims,
                periodic: on_grid.periodic,
                h,
                kappa_tr: kappa_tr.iter().map(|k| k[c]).collect(),
                kappa_a: kappa_a.iter().map(|k| k[c]).collect(),
                q0: vec![0.0; n],
                q1: vec![[0.0; 3]; n],
            }))
        })
        .collect();
    let dirs = crate::lighting::lattice::fibonacci_directions(settings.directions);
    let groups = transport::groups(on_grid, &dirs);
    Transporting {
        warm: warm.is_some(),
        moments: warm.unwrap_or(p1_start),
        coarse,
        medium,
        operators,
        dirs,
        groups,
        report: transport::Report::default(),
        on: "the CPU".into(),
        resident: None,
        seconds: start.elapsed().as_secs_f64(),
    }
}

/// The transport's acceleration (diffusion synthetic acceleration, Alcouffe 1977): the
/// diffusion of a round's change `new − old` of the mean radiance, scattered (the error's
/// source), added to `new`'s φ_00 per channel, solved by `operators` on the CPU
/// ([`crate::lighting::resident`] does it on the GPU). (Correcting φ_1 by its flux as well
/// diverged.)
fn accelerate(
    medium: &transport::Medium,
    operators: &[Arc<diffusion::Operator>],
    (old, new): (&[Harmonics], &mut [Harmonics]),
    settings: &Settings,
) -> Result<(), String> {
    let root = (4.0 * PI).sqrt();
    let mut q0 = vec![0.0; old.len()];
    for (c, operator) in operators.iter().enumerate() {
        let o = c * transport::HARMONICS;
        for (i, q) in q0.iter_mut().enumerate() {
            *q = medium.sca[i][c] * (new[i][o] - old[i][o]) / root;
        }
        let (tolerance, cap) = (ACCELERATION_TOLERANCE, settings.max_diffusion_iterations);
        let s = operator
            .solve_isotropic(&q0, tolerance, cap)
            .map_err(|e| e.to_string())?;
        new.par_iter_mut()
            .zip(&s.i0)
            .for_each(|(m, d)| m[o] += root * d);
    }
    Ok(())
}

/// Step 1 and the loss of step 2: the beam through `v`'s medium with the forward `peak`s (and
/// their `blur`) travelling along `l`, on the GPU when `on` is given and `settings.per_sun`
/// lets it (but for the hemisphere split, whose F_n the sweep looks up as it goes); and where
/// it ran.
pub(super) fn beam(
    fields: &[&FieldTable],
    grid: &DensityGrid,
    v: &Voxels,
    (peak, blur): (&[[f64; 3]], Option<&PeakBlur>),
    l: DVec3,
    (settings, on): (&Settings, Option<OnGpu>),
) -> Result<(Vec<BeamState>, String), FrameError> {
    let medium = beam_medium(fields, grid, v, settings, (peak, blur));
    let rule = (
        if (settings.source, settings.split) == (Source::Buffer, Split::Hemisphere) {
            PeakFrom::Tables
        } else {
            PeakFrom::Medium
        },
        if settings.split == Split::Hemisphere {
            Depth::Scatterings
        } else {
            Depth::Peak
        },
    );
    run(
        on.filter(|_| settings.split != Split::Hemisphere),
        settings.per_sun,
        "the beam",
        |on| Ok(on.beam().sweep(on.gpu, grid, &medium, l)?),
        || Ok(beam_sweep(fields, grid, &medium, l, rule)),
    )
}

/// Step 3: the diffusion per channel over the `active` voxels of `v`, its sources the beam's
/// loss (`buffer`, light travelling along `l`) and the skylight `sky`, solved where
/// `settings.per_sun` and `on` say; I_0 per channel and the P1 term I_1 = 3J per channel and
/// axis. Fills the report's solve figures and energy budget.
pub(super) fn diffuse(
    grid: &DensityGrid,
    (v, active): (&Voxels, &[bool]),
    (buffer, sky): (&BufferLight, &Sky),
    l: DVec3,
    (settings, on): (&Settings, Option<OnGpu>),
    report: &mut CoupledReport,
) -> Result<Diffused, FrameError> {
    let h = voxel_size(grid);
    let (state, sunlight) = (buffer.state, buffer.sunlight);
    let n = v.ext.len();
    let mut i0 = vec![[0.0f64; 3]; n];
    let mut p1 = vec![[0.0f64; 9]; n];
    for c in 0..3 {
        let problem = Problem {
            dims: grid.dims,
            periodic: grid.periodic,
            h,
            kappa_tr: (0..n)
                .map(|i| if active[i] { v.transport[i][c] } else { 0.0 })
                .collect(),
            kappa_a: (0..n)
                .map(|i| (v.ext[i][c] - v.sca[i][c]).max(0.0))
                .collect(),
            q0: (0..n)
                .map(|i| {
                    sunlight[i][c] * state[i].dropped[c] / (4.0 * PI) + v.sca[i][c] * sky.mean[i][c]
                })
                .collect(),
            q1: (0..n)
                .map(|i| {
                    let sun = l * (sunlight[i][c] * state[i].forward[c] / (4.0 * PI));
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
        let (s, solved_on) = run(
            on,
            settings.per_sun,
            &format!("channel {channel}"),
            |on| Ok(on.solver().solve_problem(on.gpu, &problem, limits)?),
            || {
                diffusion::solve(&problem, limits.0, limits.1)
                    .map_err(|e| FrameError(format!("channel {channel}: {e}")))
            },
        )?;
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
        report.budget.add(c, grid, (&problem, &s.i0), buffer, l);
    }
    Ok((i0, p1))
}

impl Budget {
    /// Channel `c`'s budget from its problem and solution, the buffer's `state` and the
    /// `sunlight` E S_atm per voxel (light travelling along `l`).
    fn add(
        &mut self,
        c: usize,
        grid: &DensityGrid,
        (p, i0): (&Problem, &[f64]),
        light: &BufferLight,
        l: DVec3,
    ) {
        self.add_beam(c, grid, light, l);
        let solve = diffusion::balance(p, i0);
        let share = |x: f64| x / self.incident[c].max(f64::MIN_POSITIVE);
        self.diffusion_source[c] = share(4.0 * PI * solve.source);
        self.diffusion_out[c] = share(4.0 * PI * solve.out);
        self.diffusion_absorbed[c] = share(4.0 * PI * solve.absorbed);
    }

    /// Channel `c`'s budget of the buffer alone on `grid` (the diffusion's shares untouched).
    fn add_beam(&mut self, c: usize, grid: &DensityGrid, light: &BufferLight, l: DVec3) {
        let (h, dims, periodic) = (voxel_size(grid), grid.dims, grid.periodic);
        let volume = h[0] * h[1] * h[2];
        let [nx, ny, _] = dims;
        // A periodic grid's x and z faces are no faces: its voxels there are neighbours.
        let faces = |a: usize| !(periodic && a != 1);
        let (mut incident, mut out, mut dropped, mut lost) = (0.0, 0.0, 0.0, 0.0);
        for (i, s) in light.state.iter().enumerate() {
            let e = light.sunlight[i][c];
            dropped += e * s.dropped[c] * volume;
            lost += e * s.loss[c] * volume;
            // The beam through the box's faces.
            let cc = [i % nx, (i / nx) % ny, i / (nx * ny)];
            for (a, ha) in h.iter().enumerate() {
                for (sign, on_face) in [(-1.0, cc[a] == 0), (1.0, cc[a] + 1 == dims[a])] {
                    let cos = sign * l[a];
                    if !on_face || !faces(a) {
                        continue;
                    } else if cos < 0.0 {
                        incident += e * -cos * volume / ha;
                    } else {
                        out += e * s.intensity[c] * cos * volume / ha;
                    }
                }
            }
        }
        let share = |x: f64| x / incident.max(f64::MIN_POSITIVE);
        self.incident[c] = incident;
        self.buffer_out[c] = share(out);
        self.dropped[c] = share(dropped);
        self.buffer_absorbed[c] = share(lost - dropped);
    }
}

/// The buffer's state and the sunlight E S_atm per voxel, which [`Budget::add`] reads.
pub(super) struct BufferLight<'a> {
    state: &'a [BeamState],
    sunlight: &'a [[f64; 3]],
}

/// Whether the gather treats a forward peak as unscattered (the δ-Eddington split).
pub(crate) fn delta_scaled(settings: &Settings) -> bool {
    (settings.source, settings.split) == (Source::Buffer, Split::DeltaEddington)
}

/// The relative residual of the transport's acceleration solves: the correction only needs to
/// be roughly right, the next sweep corrects it (dense_cumulus at 128³: six rounds and the
/// same image to four digits at 10⁻² as at 10⁻⁴, the acceleration 0.5 s a round instead of
/// 0.95 s).
pub(super) const ACCELERATION_TOLERANCE: f64 = 1e-2;

/// What feeds the transport: E S_atm per voxel, the buffer's state, the reduced skylight, and
/// the diffusion's active voxels.
pub(super) struct Sources<'a> {
    sunlight: &'a [[f64; 3]],
    state: &'a [BeamState],
    sky: &'a crate::lighting::sky::Sky,
    active: &'a [bool],
}

/// The δ-M-scaled medium the transport solves (docs/physics.md §7.10): per voxel σ′_t =
/// β_ext − f β_sca and σ′_s = (1 − f) β_sca, p′'s moments, the sunlit source (the beam's
/// dropped loss) and the skylit one, for light travelling along `l`.
pub(super) fn transport_medium(
    fields: &[&FieldTable],
    grid: &crate::volume::DensityGrid,
    v: &Voxels,
    sources: &Sources,
    (chis, peak): (&[Moments], &[[f64; 3]]),
    l: DVec3,
) -> transport::Medium {
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
                    sources.sunlight[i][c] * sources.state[i].dropped[c] / (4.0 * PI)
                }),
                std::array::from_fn(|c| {
                    let q1 = sources.sky.flux[i][c] * v.g_sca[i][c];
                    [sca[c] * sources.sky.mean[i][c], q1.x, q1.y, q1.z]
                }),
            )
        })
        .collect();
    transport::Medium {
        ext: optics.iter().map(|o| o.0).collect(),
        sca: optics.iter().map(|o| o.1).collect(),
        chi: optics.iter().map(|o| o.2).collect(),
        sun: optics.iter().map(|o| o.3).collect(),
        l,
        sky: optics.iter().map(|o| o.4).collect(),
    }
}

/// The spherical-harmonic moments of the P1 radiance I_0 + I_1·ω per voxel, the transport's
/// start: φ_00 = √(4π) I_0 and φ_1m = Y_1 (4π/3) I_1 (m = −1, 0, 1: y, z, x).
pub(super) fn p1_moments(i0: &[[f64; 3]], p1: &[[f64; 9]]) -> Vec<[f64; transport::PER_VOXEL]> {
    let root = (4.0 * PI).sqrt();
    let c1 = 0.488_602_511_902_919_9 * 4.0 * PI / 3.0;
    (0..i0.len())
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
        .collect()
}

/// `grid`'s box and dims without its densities.
pub(super) fn box_of(grid: &DensityGrid) -> DensityGrid {
    DensityGrid {
        min_m: grid.min_m,
        max_m: grid.max_m,
        dims: grid.dims,
        data: Vec::new(),
        periodic: grid.periodic,
    }
}
