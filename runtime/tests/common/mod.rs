//! Shared by the runtime's and the renderers' integration tests: a fresh bake in a temporary
//! directory, and a GPU that must exist when `REQUIRE_GPU=1`.

use std::path::PathBuf;

use bake::{BakePlan, Scene, Silent, run};

/// A cloud field: gamma distribution, r_eff 10 µm.
#[allow(dead_code)]
pub const CLOUD: &str = r#"
[[field]]
name = "cloud"
kind = "cloud"
distribution = { kind = "gamma", r_eff_um = 10, v_eff = 0.1 }
"#;

/// A rain field: lognormal, median radius 0.5 mm.
#[allow(dead_code)]
pub const RAIN: &str = r#"
[[field]]
name = "rain"
kind = "rain"
distribution = { kind = "lognormal", median_radius_um = 500, sigma_g = 1.4 }
"#;

/// A draft rgb3 scene with N orders and the given `[[field]]` tables.
#[allow(dead_code)]
pub fn scene(name: &str, n_max: usize, fields: &str) -> String {
    format!(
        "[scene]\nname = \"{name}\"\nspectral = \"rgb3\"\nn_max = {n_max}\nquality = \"draft\"\n{fields}"
    )
}

/// [`scene`] of [`CLOUD`] and [`RAIN`].
#[allow(dead_code)]
pub fn cloud_and_rain(name: &str, n_max: usize) -> String {
    scene(name, n_max, &format!("{CLOUD}{RAIN}"))
}

/// Bakes the scene `text` into `<tmp>/tables`; keep the `TempDir` alive while using the path.
pub fn bake(text: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tables");
    let scene = Scene::parse(text, "test").unwrap();
    let quality = scene.quality;
    run(&BakePlan::for_preset(scene, dir.clone(), quality), &Silent).unwrap();
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
