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

/// A water haze field (kind haze, the default lognormal).
#[allow(dead_code)]
pub const HAZE: &str = r#"
[[field]]
name = "haze"
kind = "haze"
"#;

/// A scene of cloud and haze seen along a horizontal ray at 500 m through a haze layer of
/// N_0 = `n0` and H = 1000 m, the sun 30° up at the side (azimuth 90°), sky off; the only
/// cloud is far on the side away from the sun, out of view and off every sun ray.
#[allow(dead_code)]
pub fn haze_scene(n0: f64) -> String {
    format!(
        r#"{}
[render]
width = 4
height = 4
slices = 64
light_resolution = 16

[camera]
position_m = [0, 500, 0]
look_at_m = [0, 500, 1000]
fov_deg = 0.01

[sun]
elevation_deg = 30
azimuth_deg = 90

[sky]
enabled = false

[haze]
field = "haze"
number_density_per_m3 = {n0}
scale_height_m = 1000

[[volume]]
field = "cloud"
shape = "cumulus"
number_density_per_m3 = 1e6
center_m = [-20000, 1000, 0]
radius_m = 300
height_m = 300
"#,
        scene("haze", 4, &format!("{CLOUD}{HAZE}"))
    )
}

/// Single scattering along a horizontal ray at height y through an exponential haze of
/// N(y) σ_ext = `beta_ext` there, scale height `h`, with the sun at vertical component `l_y`:
/// ω P(α) e^{−β_ext(0) h e^{−y/h} / l_y} (the ray is infinite, so ∫ β_sca e^{−β_ext t} dt = ω).
#[allow(dead_code)]
pub fn haze_single_scattering(
    omega: f64,
    phase: f64,
    beta_ext_sl: f64,
    h: f64,
    y: f64,
    l_y: f64,
) -> f64 {
    omega * phase * (-beta_ext_sl * h * (-y / h).exp() / l_y).exp()
}
