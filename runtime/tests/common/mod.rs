//! Shared by the runtime's integration tests: a fresh bake in a temporary directory.

use std::path::PathBuf;

use tables::bake::{BakePlan, run};
use tables::scene::Scene;

/// Bakes the scene `text` into `<tmp>/tables`; keep the `TempDir` alive while using the path.
pub fn bake(text: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tables");
    let scene = Scene::parse(text, "test").unwrap();
    let quality = scene.quality;
    run(&BakePlan {
        scene,
        out_dir: dir.clone(),
        quality,
        knobs: quality.knobs(),
        quiet: true,
    })
    .unwrap();
    (tmp, dir)
}

/// A headless device, or None with a notice; with `REQUIRE_GPU=1` a missing adapter fails.
#[allow(dead_code)]
pub fn gpu() -> Option<runtime::gpu::Gpu> {
    match runtime::gpu::Gpu::new() {
        Ok(g) => {
            eprintln!("adapter: {}", g.describe());
            Some(g)
        }
        Err(e) if std::env::var("REQUIRE_GPU").as_deref() == Ok("1") => {
            panic!("REQUIRE_GPU=1 but {e}")
        }
        Err(e) => {
            eprintln!("skipped, {e}");
            None
        }
    }
}
