//! The grid lighting every per-sun model uses (`max`, `coupled`): light on a voxel grid,
//! computed once per sun and read by a per-view gather. Each pass is a CPU reference and,
//! beside it, its GPU twin (wgpu, f32), checked against each other by the crate's tests:
//!
//! | pass | CPU reference | GPU twin |
//! |---|---|---|
//! | the grid: optics per voxel, upwind sweeps, lookups | [`lattice`] | `upwind.wgsl` (shared by the sweeps below) |
//! | the sun's beam and what it loses | [`beam`] | [`beam_gpu`] |
//! | the reduced skylight | [`sky`] | [`sky_gpu`] |
//! | the reduced sunlight and the volume's shadow map | [`sun`] | (CPU only) |
//! | the diffusion solve, multigrid-preconditioned | [`diffusion`] | [`diffusion_gpu`] |
//! | the discrete-ordinates transport | [`transport`] | [`transport_gpu`]; its iteration kept on the GPU between rounds and steps: [`resident`] |
//!
//! A model's recipe runs each pass through [`run`], which chooses the place: [`Place`]
//! `auto` (the GPU on a real adapter, the CPU on one that emulates a GPU on the CPU), `gpu` or
//! `cpu`; where the adapter refuses a pass (its limits), `auto` falls back to the CPU and says
//! why, `gpu` fails naming the refusal. The pipelines of every pass are compiled once per
//! adapter, on first use ([`Pipelines`]).
//!
//! The maths of each pass, with its sources, is in docs/physics.md: the reduced sunlight and
//! the diffusion §7.8 (Max et al. 2004), the beam's δ-split §7.9, the discrete-ordinates
//! transport §7.10.

pub mod beam;
pub mod beam_gpu;
pub mod diffusion;
pub mod diffusion_gpu;
pub mod lattice;
pub mod resident;
pub mod sky;
pub mod sky_gpu;
pub mod sun;
pub mod transport;
pub mod transport_gpu;

use serde::{Deserialize, Serialize};

use runtime::gpu::Gpu;

use crate::checks::FrameError;
use crate::gpu::RenderError;

/// Where a GPU render runs a pass; a CPU render runs every pass on the CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Place {
    /// On the GPU when the adapter is one, on the CPU when it emulates one on the CPU
    /// (lavapipe, where the per-sun passes took 6–7× and the gather 3× the CPU reference's
    /// time, docs/log.md).
    #[default]
    Auto,
    /// On the GPU, whatever the adapter.
    Gpu,
    /// On the CPU.
    Cpu,
}

impl Place {
    /// Whether a GPU render runs the pass on `gpu`.
    pub fn on_gpu(self, gpu: &Gpu) -> bool {
        match self {
            Place::Auto => gpu.adapter.get_info().device_type != wgpu::DeviceType::Cpu,
            Place::Gpu => true,
            Place::Cpu => false,
        }
    }
}

/// The per-sun passes' pipelines for one adapter, each compiled on first use: a renderer
/// whose per-sun passes stay on the CPU (`auto` on lavapipe) never compiles them.
#[derive(Default)]
pub struct Pipelines {
    transport: std::sync::OnceLock<transport_gpu::Sweeper>,
    sky: std::sync::OnceLock<sky_gpu::SkySweeper>,
    beam: std::sync::OnceLock<beam_gpu::BeamSweeper>,
    solver: std::sync::OnceLock<diffusion_gpu::Solver>,
    resident: std::sync::OnceLock<resident::Kernels>,
}

impl Pipelines {
    /// The passes on `gpu`, the adapter these pipelines are (to be) compiled for.
    pub fn on<'a>(&'a self, gpu: &'a Gpu) -> OnGpu<'a> {
        OnGpu {
            gpu,
            pipelines: self,
        }
    }
}

/// An adapter and the per-sun passes' pipelines for it.
#[derive(Clone, Copy)]
pub struct OnGpu<'a> {
    /// The adapter.
    pub gpu: &'a Gpu,
    pipelines: &'a Pipelines,
}

impl<'a> OnGpu<'a> {
    /// The transport's sweeps ([`transport_gpu`]).
    pub fn transport(&self) -> &'a transport_gpu::Sweeper {
        self.pipelines
            .transport
            .get_or_init(|| transport_gpu::Sweeper::new(self.gpu))
    }

    /// The skylight's sweeps ([`sky_gpu`]).
    pub fn sky(&self) -> &'a sky_gpu::SkySweeper {
        self.pipelines
            .sky
            .get_or_init(|| sky_gpu::SkySweeper::new(self.gpu))
    }

    /// The beam's sweep ([`beam_gpu`]).
    pub fn beam(&self) -> &'a beam_gpu::BeamSweeper {
        self.pipelines
            .beam
            .get_or_init(|| beam_gpu::BeamSweeper::new(self.gpu))
    }

    /// The kernels that keep the transport's iteration on the GPU ([`resident`]).
    pub fn resident(&self) -> &'a resident::Kernels {
        self.pipelines
            .resident
            .get_or_init(|| resident::Kernels::new(self.gpu))
    }

    /// The diffusion solver ([`diffusion_gpu`]).
    pub fn solver(&self) -> &'a diffusion_gpu::Solver {
        self.pipelines
            .solver
            .get_or_init(|| diffusion_gpu::Solver::new(self.gpu))
    }
}

/// Why a pass did not run on the GPU.
#[derive(Debug)]
pub enum Refused {
    /// The adapter cannot run it (its limits) or failed: `auto` falls back to the CPU.
    Gpu(RenderError),
    /// The pass ran and failed (e.g. did not converge): the CPU would fail the same way.
    Failed(String),
}

impl From<RenderError> for Refused {
    fn from(e: RenderError) -> Self {
        Self::Gpu(e)
    }
}

impl From<diffusion_gpu::SolveError> for Refused {
    fn from(e: diffusion_gpu::SolveError) -> Self {
        match e {
            diffusion_gpu::SolveError::Gpu(e) => Self::Gpu(e.into()),
            failed @ diffusion_gpu::SolveError::NotConverged(_) => Self::Failed(failed.to_string()),
        }
    }
}

/// A per-sun pass (`what`) and where it ran, in words: on `on`'s GPU when given, else on the
/// CPU; where the adapter refuses it, `auto` falls back to the CPU, saying why, and `gpu` fails
/// naming the refusal.
pub fn run<T>(
    on: Option<OnGpu>,
    place: Place,
    what: &str,
    gpu: impl FnOnce(OnGpu) -> Result<T, Refused>,
    cpu: impl FnOnce() -> Result<T, FrameError>,
) -> Result<(T, String), FrameError> {
    match on.map(|on| (on.gpu.describe(), gpu(on))) {
        None => Ok((cpu()?, "the CPU".to_string())),
        Some((adapter, Ok(done))) => Ok((done, adapter)),
        Some((_, Err(Refused::Gpu(e)))) if place == Place::Auto => {
            Ok((cpu()?, format!("the CPU ({e})")))
        }
        Some((_, Err(Refused::Gpu(e)))) => Err(FrameError(format!("{what} on the GPU: {e}"))),
        Some((_, Err(Refused::Failed(e)))) => Err(FrameError(format!("{what} on the GPU: {e}"))),
    }
}

/// Refuses `frame` unless it has the grid dimensions and the sun a `model`'s lighting was
/// computed for (`lit_for`): a view may reuse a lighting only then.
pub fn check_lit_for(
    model: &str,
    (dims, sun_dir): ([usize; 3], glam::DVec3),
    frame: &crate::frame::Frame,
) -> Result<(), FrameError> {
    if frame.grid.dims != dims || frame.sun.direction() != sun_dir {
        return Err(FrameError(format!(
            "the {model} lighting was computed for a {dims:?} grid and the sun towards \
             {sun_dir:?}; this frame has {:?} and {:?}: light it again",
            frame.grid.dims,
            frame.sun.direction()
        )));
    }
    Ok(())
}
