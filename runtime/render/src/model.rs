//! The render models behind one type.
//!
//! A model is a module with a unit type implementing [`Model`]: its name (`--model` and the
//! scene's `[render.<name>]` table), its settings (a serde struct read from that table, keys
//! it does not know refused), its checks (made before anything is baked), its CPU reference
//! and its GPU renderer. [`ModelSettings`] is the enum front the scene parser, `render`,
//! `bench render` and the viewer dispatch through; it is written by the [`models!`] list at
//! the end of this file, so adding a model is its module plus one line there.
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

use crate::gpu::RenderError;
use crate::{Frame, FrameError, Image};

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

    /// A progressive model's frame so far, after each pass: the mean and the standard error
    /// per pixel of the samples taken (`photometeor view` shows it while it converges).
    fn running(&self, _frame: &crate::truth::TruthImage) {}

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

/// The per-pixel buffers of a frame: `bytes_per_pixel` times the pixels.
pub fn image_need(what: &'static str, pixels: u64, bytes_per_pixel: u64) -> Need {
    Need {
        what,
        bytes: pixels * bytes_per_pixel,
        setting: "[render] width and height (--width, --height)".into(),
    }
}

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
    /// Its settings: `[render.<NAME>]`, every key optional (defaults in `Default`).
    type Settings: Default + Clone + PartialEq + Debug + Serialize + DeserializeOwned + Send + Sync;
    /// Its GPU renderer: pipelines and layouts built once for a device and a table upload.
    type Renderer;

    /// The settings alone, each key against its allowed range.
    fn check(settings: &Self::Settings) -> Result<(), FrameError>;
    /// What the model needs of the frame and refuses in it, before anything is baked: the
    /// frame's grid may be a placeholder over the volumes' bounds without particles.
    fn check_frame(settings: &Self::Settings, frame: &Frame) -> Result<(), FrameError>;
    /// The memory a frame of `pixels` pixels over a grid of `voxels` voxels takes beyond the
    /// grid itself, by part (the CPU reference's, which exceeds the GPU renderer's host side).
    fn memory(settings: &Self::Settings, pixels: u64, voxels: u64) -> Vec<Need>;
    /// The GPU renderer, or `None` when the model runs on the CPU only ([`Model::GPU`]).
    fn renderer(gpu: &Gpu, tables: &GpuTables) -> Option<Self::Renderer>;
    /// The CPU reference.
    fn render_cpu(settings: &Self::Settings, job: &Job) -> Result<Rendered, RenderError>;
    /// The frame on the GPU with `renderer` and the tables uploaded as [`Model::TEXELS`].
    fn render_gpu(
        renderer: &Self::Renderer,
        settings: &Self::Settings,
        job: &Job,
        gpu: &Gpu,
        tables: &GpuTables,
    ) -> Result<Rendered, RenderError>;
    /// Parts of a GPU frame a benchmark times on their own beside the frame (Biri's stage 2
    /// without the medium); none by default.
    fn bench_parts(
        _renderer: &Self::Renderer,
        _settings: &Self::Settings,
        _job: &Job,
        _gpu: &Gpu,
        _tables: &GpuTables,
    ) -> Result<Vec<Pass>, RenderError> {
        Ok(Vec::new())
    }
}

/// Where a frame is rendered.
pub enum On<'a> {
    /// The CPU reference.
    Cpu,
    /// The GPU, with a model's prepared renderer (or the CPU when the model has none).
    Gpu(&'a Gpu, &'a Prepared),
}

/// A model's settings that cannot be used: the model, the key and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ModelError(pub String);

/// Reads `[render.<model>]` (an empty table when absent) into the model's settings and checks
/// them, naming the model and the key (and the model a misplaced key belongs to).
pub(crate) fn parse_settings<M: Model>(table: &toml::Table) -> Result<M::Settings, ModelError> {
    let known = keys_of::<M>();
    if let Some(key) = table.keys().find(|k| !known.contains(k)) {
        let owners: Vec<&str> = model_keys()
            .into_iter()
            .filter(|(_, keys)| keys.contains(key))
            .map(|(name, _)| name)
            .collect();
        let hint = if owners.is_empty() {
            String::new()
        } else {
            format!("; it is a key of --model {}", owners.join(", "))
        };
        return Err(ModelError(format!(
            "[render.{}] {key}: --model {} has no such setting (its keys: {}){hint}",
            M::NAME,
            M::NAME,
            known.join(", ")
        )));
    }
    let settings: M::Settings =
        toml::Value::Table(table.clone())
            .try_into()
            .map_err(|e: toml::de::Error| {
                ModelError(format!("[render.{}]: {}", M::NAME, e.message().trim_end()))
            })?;
    M::check(&settings).map_err(|e| ModelError(format!("[render.{}] {}", M::NAME, e.0)))?;
    Ok(settings)
}

/// The keys of `M`'s settings, from their serialized defaults.
fn keys_of<M: Model>() -> Vec<String> {
    match toml::Value::try_from(M::Settings::default()) {
        Ok(toml::Value::Table(t)) => t.keys().cloned().collect(),
        _ => Vec::new(),
    }
}

/// Declares the models: the [`ModelSettings`] and [`Prepared`] enums and their dispatch.
macro_rules! models {
    ($($variant:ident => $model:path),* $(,)?) => {
        /// A render model and its settings.
        #[derive(Debug, Clone, PartialEq)]
        pub enum ModelSettings {
            $(
                #[doc = concat!("`--model ", stringify!($variant), "`.")]
                $variant(<$model as Model>::Settings),
            )*
        }

        /// A model's GPU side for one device and table set (built once, reused per frame).
        pub enum Prepared {
            $(
                #[doc = concat!("`--model ", stringify!($variant), "`.")]
                $variant(GpuTables, Option<<$model as Model>::Renderer>),
            )*
        }

        /// Every model's name, in the order of `--help`.
        pub const MODEL_NAMES: &[&str] = &[$(<$model as Model>::NAME),*];

        /// Each model's name and one-line description.
        pub fn model_descriptions() -> Vec<(&'static str, &'static str)> {
            vec![$((<$model as Model>::NAME, <$model as Model>::ABOUT)),*]
        }

        /// The keys each model's `[render.<name>]` table takes.
        pub fn model_keys() -> Vec<(&'static str, Vec<String>)> {
            vec![$((<$model as Model>::NAME, keys_of::<$model>())),*]
        }

        impl ModelSettings {
            /// Model `name` with its `[render.<name>]` table, checked.
            pub fn parse(name: &str, table: &toml::Table) -> Result<Self, ModelError> {
                $(
                    if name == <$model as Model>::NAME {
                        return Ok(Self::$variant(parse_settings::<$model>(table)?));
                    }
                )*
                Err(ModelError(format!(
                    "--model {name:?} is not one of {}",
                    MODEL_NAMES.join(", ")
                )))
            }

            /// The model's name.
            pub fn name(&self) -> &'static str {
                match self {
                    $(Self::$variant(_) => <$model as Model>::NAME,)*
                }
            }

            /// The texel format the model's GPU renderer wants.
            pub fn texels(&self) -> TexelFormat {
                match self {
                    $(Self::$variant(_) => <$model as Model>::TEXELS,)*
                }
            }

            /// The settings as their `[render.<name>]` table (every key, defaults included).
            pub fn to_table(&self) -> toml::Table {
                let value = match self {
                    $(Self::$variant(s) => toml::Value::try_from(s),)*
                };
                match value {
                    Ok(toml::Value::Table(t)) => t,
                    _ => toml::Table::new(),
                }
            }

            /// The memory a frame of `pixels` pixels over `voxels` voxels takes beyond the grid.
            pub fn memory(&self, pixels: u64, voxels: u64) -> Vec<Need> {
                match self {
                    $(Self::$variant(s) => <$model as Model>::memory(s, pixels, voxels),)*
                }
            }

            /// What the model needs of `frame` and refuses in it (before anything is baked).
            pub fn check_frame(&self, frame: &Frame) -> Result<(), FrameError> {
                match self {
                    $(Self::$variant(s) => <$model as Model>::check_frame(s, frame),)*
                }
            }

            /// Uploads `tables` in the model's texel format and builds its GPU renderer.
            pub fn prepare(&self, gpu: &Gpu, tables: &Tables) -> Result<Prepared, RenderError> {
                let uploaded = GpuTables::upload(gpu, tables, self.texels())?;
                Ok(match self {
                    $(Self::$variant(_) => {
                        let r = <$model as Model>::renderer(gpu, &uploaded);
                        Prepared::$variant(uploaded, r)
                    })*
                })
            }

            /// Renders `job` on the CPU reference or on the GPU. A model without a GPU
            /// renderer runs on the CPU either way.
            pub fn render(&self, job: &Job, on: On) -> Result<Rendered, RenderError> {
                match (self, on) {
                    $(
                        (Self::$variant(s), On::Gpu(gpu, Prepared::$variant(t, Some(r)))) => {
                            <$model as Model>::render_gpu(r, s, job, gpu, t)
                        }
                        (Self::$variant(s), _) => <$model as Model>::render_cpu(s, job),
                    )*
                }
            }

            /// Whether the model has a GPU renderer (`render` without `--cpu` uses it).
            pub fn has_gpu(&self) -> bool {
                match self {
                    $(Self::$variant(_) => <$model as Model>::GPU,)*
                }
            }

            /// The parts of a GPU frame the model times on their own ([`Model::bench_parts`]).
            pub fn bench_parts(
                &self,
                job: &Job,
                gpu: &Gpu,
                prepared: &Prepared,
            ) -> Result<Vec<Pass>, RenderError> {
                match (self, prepared) {
                    $(
                        (Self::$variant(s), Prepared::$variant(t, Some(r))) => {
                            <$model as Model>::bench_parts(r, s, job, gpu, t)
                        }
                    )*
                    _ => Ok(Vec::new()),
                }
            }
        }

        impl Prepared {
            /// The tables as uploaded.
            pub fn tables(&self) -> &GpuTables {
                match self {
                    $(Self::$variant(t, _) => t,)*
                }
            }
        }
    };
}

models! {
    Riley => crate::riley::Riley,
    Miyazaki => crate::miyazaki::Miyazaki,
    Max => crate::max::Max,
    Coupled => crate::coupled::Coupled,
    Biri => crate::biri::Biri,
    Truth => crate::truth::Truth,
}

impl Default for ModelSettings {
    fn default() -> Self {
        Self::Riley(Default::default())
    }
}
