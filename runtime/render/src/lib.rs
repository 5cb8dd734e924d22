//! The renderers fed by photometeor's tables: one module per render model over shared parts.
//!
//! # The shape of a model
//! A model is a folder `src/<model>/` with a unit type implementing [`Model`]
//! ([`model`]'s docs): its `NAME` (`--model <name>` and the scene table `[render.<name>]`), its
//! `Settings` (a serde struct read from that table; keys it does not have are refused naming
//! the model and the key), `check` (its settings' ranges) and `check_frame` (what it needs of a
//! scene and refuses in it, before anything is baked), its CPU reference (`cpu.rs`) and its GPU
//! renderer (`gpu.rs` with its WGSL beside it). Adding one is its folder plus one line in the
//! `models!` list of [`registry`]; the scene parser, `photometeor render`, `photometeor bench
//! render` and the viewer dispatch through [`ModelSettings`], so nothing else changes. A model
//! that lights a grid once per sun (`max`, `coupled`) is a recipe over the [`lighting`] layer:
//! which passes run, in which order, with which sources. A model imports the shared modules
//! only, never another model, and the shared modules import no model but through the registry
//! (tests/layout.rs holds both, and that the modules' imports form no circle).
//!
//! The models:
//! - [`riley`]: Riley et al. 2004's half-angle slicing with a light buffer and an eye buffer,
//!   the multiple-scattering tables Ams_n and F_n for the angular spread of sunlight (the
//!   default).
//! - [`miyazaki`]: Miyazaki, Dobashi & Nishita's shadow-view slices — single scattering with a
//!   constant k_multi, a shadow surface for the clouds' shadows on the ground and in the air.
//! - [`max`]: Max, Schussman, Miyazaki, Iwasaki & Nishita 2004 — a diffusion solve in the dense
//!   core, Poisson-weighted multiple anisotropic scattering from the bake's M(D, θ) at the
//!   edges (the per-sun passes on the GPU or the CPU, the final gather on the GPU).
//! - [`coupled`]: the sunlight's forward peak kept in a beam (δ-M), the light it loses carried
//!   by discrete-ordinates transport accelerated by a diffusion solve, gathered with the exact
//!   phase function.
//! - [`biri`]: Biri, Arquès & Michelin 2006 — single scattering of point and spot lights in
//!   homogeneous media in closed form per ray, volumetric shadows from the occluders'
//!   silhouette planes.
//! - [`truth`]: an unbiased spectral Monte Carlo path tracer of the full radiative transfer on
//!   the same scene, the reference every fast model is measured against.
//!
//! # The shared parts
//! - [`auto`]: `--model auto`, the model a scene needs, from its optical depth and the
//!   models' measured errors on the optical-depth sweep.
//! - [`scene`]: the scene file's render tables → [`RenderScene`] (shared keys, objects, one
//!   checked settings table per model) → [`Frame`] ([`frame`]: the view, the density grid, the
//!   objects) for a set of tables; [`checks`]: the error every check returns.
//! - [`objects`]: lights, media and their regions, occluders; [`geometry`]: meshes (OBJ),
//!   spheres, ray tests; [`volume`]: density volumes rasterized into one grid.
//! - [`camera`], [`sky`] (Riley's analytic sky, Eqs. 9–15), [`skylight`] (the sky's light on
//!   the ground and the air), [`shading`] (per-sample coefficients, sun-side buffer lookups,
//!   the pixel composed around a volume's light), [`image`] (EXR and PNG out), [`error_map`]
//!   (a frame against the truth).
//! - [`lighting`]: the grid lighting of the per-sun models — the lattice and its upwind
//!   sweeps, the beam, the skylight, the sunlight, the diffusion solve and the
//!   discrete-ordinates transport, each pass a CPU reference with its GPU twin, run by one
//!   runner that chooses the place; [`relight`] keeps a sun's lighting between views.
//! - [`gpu`]: the plumbing every GPU renderer uses (pipelines, buffers, slice uniforms, a
//!   timed frame and its readback); each WGSL uniform is mirrored by a Pod struct declared
//!   with `runtime::uniform!`, whose layout a test checks against the shader's.
//!
//! Units: radiance per unit solar irradiance outside the atmosphere (1/sr) per channel; lengths
//! in metres, y up, sea level at y = 0.

#![warn(missing_docs)]

pub mod auto;
pub mod biri;
pub mod camera;
pub mod checks;
pub mod coupled;
pub mod error_map;
pub mod frame;
pub mod geometry;
pub mod gpu;
pub mod image;
pub mod lighting;
pub mod max;
pub mod miyazaki;
pub mod model;
pub mod objects;
pub mod registry;
pub mod relight;
pub mod riley;
pub mod rng;
pub mod scene;
pub mod shading;
pub mod sky;
pub mod skylight;
pub mod truth;
pub mod volume;

pub use camera::SUN_DIAMETER_DEG;
pub use camera::{Camera, Sun};
pub use checks::FrameError;
pub use frame::{Frame, Haze};
pub use geometry::basis;
pub use image::Image;
pub use model::{Job, Model, Rendered};
pub use registry::{ModelSettings, On};
pub use riley::LightUpdate;
pub use scene::RenderScene;
pub use sky::Atmosphere;
pub use volume::DensityGrid;
pub use volume::MAX_FIELDS;
