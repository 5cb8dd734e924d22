//! One module per subcommand: its arguments and the code that runs it.

pub mod bake;
pub mod bench;
pub mod bench_relight;
pub mod bench_render;
pub mod compare;
pub mod compare_render;
pub mod export;
pub mod inspect;
pub mod merge;
pub mod mie;
pub mod phase;
pub mod plot;
pub mod render;
pub mod shaders;
pub mod tradeoff;
pub mod validate;
#[cfg(feature = "view")]
pub mod view;
