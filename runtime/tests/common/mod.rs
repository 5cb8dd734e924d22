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
/// The preset's knobs as stated for 31 wavelengths (`Quality::knobs`), not scaled up for rgb3:
/// these tests need tables, not the preset's accuracy.
pub fn bake(text: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tables");
    let scene = Scene::parse(text, "test").unwrap();
    let quality = scene.quality;
    let mut plan = BakePlan::for_preset(scene, dir.clone(), quality);
    plan.knobs = quality.knobs();
    // Crystals: the preset's first round of rays only, not traced on to its noise target;
    // drops: the preset's sizes, not sized by a pilot for its noise target.
    plan.knobs.crystal_noise = 0.0;
    plan.knobs.size_noise = 0.0;
    run(&plan, &Silent).unwrap();
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

[render.miyazaki]
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

[ground]
albedo = 0.0

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

/// Asserts that a GPU frame (`gpu`: rgb and T_vol per pixel) equals its CPU reference `cpu`
/// per pixel and channel within `rel`·|cpu| + `of_scale`·(the reference's 99th percentile, so
/// that a sun disk in view cannot set it), and T_vol within `t_tol`, and that the volumes
/// cover more than 100 pixels. `what` names the case in failures. Returns the worst
/// |GPU − CPU| as a share of the tolerance.
#[allow(dead_code)]
pub fn assert_gpu_matches_cpu(
    gpu: (&[[f32; 3]], &[f32]),
    cpu: (&[[f32; 3]], &[f32]),
    (rel, of_scale, t_tol): (f64, f64, f64),
    what: &str,
) -> f64 {
    let mut values: Vec<f64> = cpu.0.iter().flatten().map(|&v| v as f64).collect();
    values.sort_by(f64::total_cmp);
    let scale = values[values.len() * 99 / 100];
    let mut worst = 0f64;
    for (p, (g, c)) in gpu.0.iter().zip(cpu.0).enumerate() {
        for ch in 0..3 {
            let (g, c) = (g[ch] as f64, c[ch] as f64);
            let tol = rel * c.abs() + of_scale * scale;
            worst = worst.max((g - c).abs() / tol);
            assert!(
                (g - c).abs() <= tol,
                "{what}, pixel {p} channel {ch}: GPU {g}, CPU {c}"
            );
        }
        let (ta, tb) = (gpu.1[p] as f64, cpu.1[p] as f64);
        assert!((ta - tb).abs() < t_tol, "{what}, pixel {p}: T {ta} vs {tb}");
    }
    let seen = cpu.1.iter().filter(|&&t| t < 0.5).count();
    assert!(seen > 100, "{what}: the volumes cover only {seen} pixels");
    worst
}

/// The soft-ball fixture scene (`data/scenes/fixtures/soft_ball.toml`: its render tables, the
/// grid file beside it) after `fields` (a scene's [scene] and [[field]] tables), and the folder
/// its grid file is relative to.
#[allow(dead_code)]
pub fn soft_ball(fields: &str) -> (String, std::path::PathBuf) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/scenes/fixtures")
        .canonicalize()
        .or_else(|_| {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../data/scenes/fixtures")
                .canonicalize()
        })
        .expect("data/scenes/fixtures");
    let text = std::fs::read_to_string(dir.join("soft_ball.toml")).unwrap();
    (format!("{fields}\n{text}"), dir)
}

/// Writes an n³ little-endian f32 density file of a soft ball, √(1 − r) over the unit ball of
/// the grid's box, as `soft_ball_48.f32` holds it for n = 48.
#[allow(dead_code)]
pub fn write_soft_ball(path: &std::path::Path, n: usize) {
    let mut bytes = Vec::with_capacity(4 * n * n * n);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let c = |i: usize| (i as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                let r = (c(x).powi(2) + c(y).powi(2) + c(z).powi(2)).sqrt();
                bytes.extend_from_slice(&((1.0 - r).max(0.0).sqrt() as f32).to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}
