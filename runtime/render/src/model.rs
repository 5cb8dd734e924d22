//! The render models behind one type.
//!
//! A model is a module with a unit type implementing [`Model`]: its name (`--model` and the
//! scene's `[render.<name>]` table), its settings (a serde struct read from that table, keys
//! it does not know refused), its checks (made before anything is baked), its CPU reference
//! and its GPU renderer. The registry ([`crate::registry`]) names every model and writes the
//! [`ModelSettings`](crate::registry::ModelSettings) enum the scene parser, `render`, `bench
//! render` and the viewer dispatch through; this module names none, so adding a model is its
//! module plus one line there.
//!
//! ```text
//! scene file ──▶ RenderScene (shared: camera, sun, sky, volumes, lights, media, occluders)
//!                  └─ [render.<name>] ──▶ ModelSettings::parse ──▶ <Model>::Settings, checked
//! tables + scene ──▶ Frame ──▶ ModelSettings::render(Job, On::Cpu | On::Gpu) ──▶ Rendered
//! ```

use std::fmt::Debug;

use serde::Serialize;
use serde::de::DeserializeOwned;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::checks::FrameError;
use crate::frame::Frame;
use crate::gpu::RenderError;
use crate::image::Image;

/// Progress of long work (the path tracer's passes, the diffusion's sweeps), reported from the
/// library to whoever runs it; the library decides nothing about terminals or verbosity.
pub trait Progress: Sync {
    /// `done` of `total` steps; `message` says what the step is or what it reached (e.g.
    /// "noise 2.1 %").
    fn update(&self, done: u64, total: u64, message: &str);

    /// Whether a progressive model (the truth) should hand its frame so far to
    /// [`Progress::running`] after each pass; making it costs a pass over the pixels.
    fn wants_running(&self) -> bool {
        false
    }

    /// A progressive model's frame so far, after each pass: the mean `image` and the
    /// `std_error` per pixel and channel of the `spp` samples per pixel taken, and its median
    /// relative noise (`photometeor view` shows it while it converges).
    fn running(&self, _image: &Image, _std_error: &[[f32; 3]], _spp: usize, _noise: f64) {}

    /// Whether a progressive model should end its frame after the pass under way; the samples
    /// taken so far are the frame.
    fn stop(&self) -> bool {
        false
    }
}

impl Progress for () {
    fn update(&self, _: u64, _: u64, _: &str) {}
}

/// What one frame is rendered from.
#[derive(Clone, Copy)]
pub struct Job<'a> {
    /// The checked tables; field i is the grid's channel i.
    pub tables: &'a Tables,
    /// The view, the grid and the scene's objects.
    pub frame: &'a Frame,
    /// Told as long work advances.
    pub progress: &'a dyn Progress,
    /// Where the per-sun lighting of `max` and `coupled` is kept between the frames of a moving
    /// camera ([`crate::relight`]); `None` lights every frame anew.
    pub lighting: Option<&'a crate::relight::LightingCache>,
}

/// One named part of a frame's work and its wall time (s).
#[derive(Debug, Clone, PartialEq)]
pub struct Pass {
    /// What it is ("upload", "frame", "diffusion", …).
    pub name: &'static str,
    /// Seconds.
    pub seconds: f64,
}

impl Pass {
    /// A GPU frame's three timed parts: "upload", "frame" and "readback".
    pub fn of_gpu(t: &crate::gpu::Timings) -> Vec<Self> {
        vec![
            Self {
                name: "upload",
                seconds: t.upload,
            },
            Self {
                name: "frame",
                seconds: t.frame,
            },
            Self {
                name: "readback",
                seconds: t.readback,
            },
        ]
    }
}

/// A rendered frame and what it cost.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Radiance and the volume's transparency per pixel.
    pub image: Image,
    /// Further EXR channels (the path tracer's stderr.R/G/B), name and one value per pixel.
    pub extra: Vec<(String, Vec<f32>)>,
    /// The frame's parts and their wall times, in order.
    pub passes: Vec<Pass>,
    /// Other figures the model measured, by name (the truth's "noise" and "paths per
    /// second", the diffusion's "CG iterations", …).
    pub figures: Vec<(&'static str, f64)>,
    /// One line for the user: what ran, where, and its figures.
    pub summary: String,
}

impl Rendered {
    /// A frame without further channels or figures: `image`, its `passes` and the line
    /// `summary`.
    pub fn plain(image: Image, passes: Vec<Pass>, summary: String) -> Self {
        Self {
            image,
            extra: Vec::new(),
            passes,
            figures: Vec::new(),
            summary,
        }
    }

    /// A CPU frame of one pass, "frame", that took `seconds`.
    pub fn cpu_frame(image: Image, seconds: f64, summary: String) -> Self {
        Self::plain(
            image,
            vec![Pass {
                name: "frame",
                seconds,
            }],
            summary,
        )
    }

    /// Marks a frame whose per-sun lighting was kept from an earlier frame
    /// ([`crate::relight`]): its lighting passes took no time, its figure "lighting reused" is 1
    /// and its summary says so.
    pub fn reused_lighting(&mut self) {
        self.figures.push(("lighting reused", 1.0));
        self.summary = format!(
            "lighting reused from the previous frame (same sun, grid, sky and settings); {}",
            self.summary
        );
    }

    /// Marks a frame drawn from a relight that has not converged, `steps` steps in
    /// ([`crate::relight`]): the figure "relight steps" and the summary say so; the next
    /// frame of the same view takes it further.
    pub fn converging(&mut self, steps: usize) {
        self.figures.push(("relight steps", steps as f64));
        self.summary = format!(
            "lighting converging: {steps} steps of the relight so far (the next frame takes it \
             further); {}",
            self.summary
        );
    }

    /// Whether the frame was drawn from a relight that has not converged.
    pub fn is_converging(&self) -> bool {
        self.figures
            .iter()
            .any(|(name, _)| *name == "relight steps")
    }

    /// The wall time of pass `name`, if the model reported it.
    pub fn seconds(&self, name: &str) -> Option<f64> {
        self.passes
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.seconds)
    }
}

/// A part of a frame's memory: what it is, its bytes, and the setting that sets its size.
#[derive(Debug, Clone, PartialEq)]
pub struct Need {
    /// What it holds ("the eye buffer", …).
    pub what: &'static str,
    /// Bytes.
    pub bytes: u64,
    /// The setting to lower to make it smaller ("[render] width and height", …).
    pub setting: String,
}

impl Need {
    /// The bytes of `needs` together.
    pub fn total(needs: &[Need]) -> u64 {
        needs.iter().map(|n| n.bytes).sum()
    }
}

/// The per-pixel buffers of a frame: `bytes_per_pixel` times the pixels.
pub fn image_need(what: &'static str, pixels: u64, bytes_per_pixel: u64) -> Need {
    Need {
        what,
        bytes: pixels * bytes_per_pixel,
        setting: "[render] width and height (--width, --height)".into(),
    }
}

/// A model's frame or why it could not be rendered.
pub type RenderResult = Result<Rendered, RenderError>;

/// The GPU side of a render: the adapter, the model's renderer built for it and the tables
/// uploaded there.
pub struct Device<'a, R> {
    /// The model's GPU renderer.
    pub renderer: &'a R,
    /// The adapter.
    pub gpu: &'a Gpu,
    /// The tables as uploaded for the model.
    pub tables: &'a GpuTables,
}

impl<R> Clone for Device<'_, R> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<R> Copy for Device<'_, R> {}

/// What a render model provides (module docs).
pub trait Model {
    /// The `--model` name and the scene table `[render.<NAME>]`.
    const NAME: &'static str;
    /// One line for `--help`: the paper and what the model draws.
    const ABOUT: &'static str;
    /// The texel format its GPU renderer wants the tables in.
    const TEXELS: TexelFormat;
    /// Whether it has a GPU renderer ([`Model::renderer`] gives one).
    const GPU: bool;
    /// Whether it is the reference the others are measured against (the path tracer), which
    /// the viewer shows beside a model rather than as one.
    const REFERENCE: bool = false;
    /// Whether it draws a periodic volume (the registry refuses one by name, before anything
    /// is baked, for a model that does not).
    const PERIODIC: bool = false;
    /// Its settings: `[render.<NAME>]`, every key optional (defaults in `Default`).
    type Settings: Default + Clone + PartialEq + Debug + Serialize + DeserializeOwned + Send + Sync;
    /// Its GPU renderer: pipelines and layouts built once for a device and a table upload.
    type Renderer;

    /// The settings alone, each key against its allowed range.
    fn check(settings: &Self::Settings) -> Result<(), FrameError>;
    /// What the model needs of the frame and refuses in it, before anything is baked: the
    /// frame's grid may be a placeholder over the volumes' bounds without particles.
    fn check_frame(settings: &Self::Settings, frame: &Frame) -> Result<(), FrameError>;
    /// The memory a frame of `pixels` pixels over a grid of `dims` voxels takes beyond the
    /// grid itself, by part (the CPU reference's, which exceeds the GPU renderer's host side).
    fn memory(settings: &Self::Settings, pixels: u64, dims: [usize; 3]) -> Vec<Need>;
    /// The GPU renderer, or `None` when the model runs on the CPU only ([`Model::GPU`]).
    fn renderer(gpu: &Gpu, tables: &GpuTables) -> Option<Self::Renderer>;
    /// The CPU reference.
    fn render_cpu(settings: &Self::Settings, job: &Job) -> Result<Rendered, RenderError>;
    /// The frame on the GPU `on` names: its renderer and the tables uploaded as
    /// [`Model::TEXELS`].
    fn render_gpu(s: &Self::Settings, job: &Job, on: Device<Self::Renderer>) -> RenderResult;
    /// Parts of a GPU frame a benchmark times on their own beside the frame (Biri's stage 2
    /// without the medium); none by default.
    fn bench_parts(
        _s: &Self::Settings,
        _job: &Job,
        _on: Device<Self::Renderer>,
    ) -> Result<Vec<Pass>, RenderError> {
        Ok(Vec::new())
    }
}

/// The voxels of a grid of `dims`.
pub fn voxels(dims: [usize; 3]) -> u64 {
    dims.iter().map(|&d| d as u64).product()
}
