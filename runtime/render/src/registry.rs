//! The registry of render models: the one list that names every model ([`models!`]'s
//! invocation at the end), and the [`ModelSettings`] and [`Prepared`] enums it writes, which the
//! scene parser, `photometeor render`, `bench render` and the viewer dispatch through. Adding a
//! model is its module plus one line in that list; nothing else in the crate names a model.

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, TexelFormat};

use crate::frame::Frame;

use crate::checks::FrameError;
use crate::gpu::RenderError;
use crate::model::{Device, Job, Model, Need, Pass, Rendered};

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

        /// The models a viewer switches between: those with a GPU renderer, but the
        /// reference (which it shows beside them), in the order of `--help`.
        pub fn interactive_models() -> Vec<&'static str> {
            let mut names = Vec::new();
            $(
                if <$model as Model>::GPU && !<$model as Model>::REFERENCE {
                    names.push(<$model as Model>::NAME);
                }
            )*
            names
        }

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

            /// The memory a frame of `pixels` pixels over a grid of `dims` voxels takes beyond
            /// the grid.
            pub fn memory(&self, pixels: u64, dims: [usize; 3]) -> Vec<Need> {
                match self {
                    $(Self::$variant(s) => <$model as Model>::memory(s, pixels, dims),)*
                }
            }

            /// What the model needs of `frame` and refuses in it (before anything is baked):
            /// a periodic volume unless it draws one, then its own checks.
            pub fn check_frame(&self, frame: &Frame) -> Result<(), FrameError> {
                match self {
                    $(Self::$variant(s) => {
                        if !<$model as Model>::PERIODIC {
                            frame.bounded_only(<$model as Model>::NAME)?;
                        }
                        <$model as Model>::check_frame(s, frame)
                    })*
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
                            <$model as Model>::render_gpu(s, job, Device { renderer: r, gpu, tables: t })
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
                            <$model as Model>::bench_parts(s, job, Device { renderer: r, gpu, tables: t })
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

/// The deepest optical depth (a scene's deepest point, as [`crate::auto`] measures it) a model
/// takes with its default settings, where it has a limit.
pub fn depth_limit(model: &str) -> Option<f64> {
    match model {
        "coupled" => Some(crate::coupled::MAX_OPTICAL_DEPTH),
        "truth" => Some(crate::truth::MAX_OPTICAL_DEPTH),
        _ => None,
    }
}

/// Why a model with its default settings refuses the depths of `frame`'s grid beyond
/// [`depth_limit`] (coupled's transport on a coarse grid), or None.
pub fn depth_refusal(model: &str, tables: &Tables, frame: &Frame) -> Option<String> {
    match model {
        "coupled" => crate::coupled::light::check_depth(tables, frame, &Default::default())
            .err()
            .map(|e| e.to_string()),
        _ => None,
    }
}
