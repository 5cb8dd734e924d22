//! The renderer: the GPU path against the CPU reference (both compositing orders, two fields
//! mixed, sky and aerial perspective on), and the CPU reference against single scattering in an
//! optically thin uniform box, where Riley et al. 2004 Eq. 26 must reduce to
//! I_s · Ams_1(θ) · α · (1 − e^{−β·chord}).

use std::path::Path;

use render::geometry::box_span;
use render::riley::cpu;
use render::riley::gpu::Renderer;
use render::riley::{Riley, Settings, Setup};
use render::{Frame, LightUpdate, RenderScene};
use runtime::Tables;
use runtime::gpu::{GpuTables, TexelFormat};
use runtime::sample;

#[path = "../../tests/common/mod.rs"]
mod common;
#[path = "support/uniform_box.rs"]
mod support;

use common::{bake, gpu};

fn fields() -> String {
    common::cloud_and_rain("render", 8)
}

/// A cumulus of cloud beside a shaft of rain, 6 km ahead, with the sun where asked.
fn two_field_frame(tables: &Tables, elevation: f64, azimuth: f64) -> (Frame, Settings) {
    let text = format!(
        r#"{}
[render]
width = 72
height = 54
grid_resolution = 48

[render.riley]
slices = 64
light_resolution = 64
xi = 0.01

[camera]
position_m = [0, 300, 0]
look_at_m = [0, 1500, 6000]
fov_deg = 50

[sun]
elevation_deg = {elevation}
azimuth_deg = {azimuth}

[ground]
albedo = 0.3

[[volume]]
field = "cloud"
shape = "cumulus"
number_density_per_m3 = 3e6
center_m = [-800, 1500, 6000]
radius_m = 1200
height_m = 1400

[[volume]]
field = "rain"
shape = "rain_shaft"
number_density_per_m3 = 300
center_m = [800, 0, 6000]
radius_m = 1000
top_m = 2000
"#,
        fields()
    );
    let scene = RenderScene::parse(&text, "test", Path::new(".")).unwrap();
    (
        scene.frame(tables).unwrap(),
        scene.settings::<Riley>().unwrap(),
    )
}

#[test]
fn gpu_render_matches_the_cpu_reference_in_both_compositing_orders() {
    let Some(gpu) = gpu() else { return };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let uploaded = GpuTables::upload(&gpu, &tables, TexelFormat::F32).unwrap();
    let renderer = Renderer::new(&gpu, &uploaded);
    // Sun behind the camera (front to back), then ahead of it (back to front); each order
    // also seen by an orthographic camera 6 km wide.
    let ortho = render::camera::Projection::Orthographic { width_m: 6000.0 };
    let pinhole = render::camera::Projection::Perspective;
    for (elevation, azimuth, front_to_back, update, projection) in [
        (20.0, 200.0, true, LightUpdate::Continuum, pinhole),
        (30.0, 10.0, false, LightUpdate::Continuum, pinhole),
        (30.0, 10.0, false, LightUpdate::Riley2004, pinhole),
        (20.0, 200.0, true, LightUpdate::Continuum, ortho),
        (30.0, 10.0, false, LightUpdate::Continuum, ortho),
    ] {
        let (mut frame, mut settings) = two_field_frame(&tables, elevation, azimuth);
        frame.camera.projection = projection;
        settings.light_update = update;
        let setup = Setup::new(&frame, &settings).unwrap();
        assert_eq!(setup.front_to_back, front_to_back);
        let reference = cpu::render(&tables, &frame, &settings).unwrap();
        let (image, t) = renderer
            .render(&gpu, &tables, &uploaded, &frame, &settings)
            .unwrap();
        // f32 on the GPU against f64: rounding in ~100 slices of exp/pow, the asin polynomial
        // (1 ulp) and f32 coordinates of metre-scale points (a few 1e-5 of a texel) stay far
        // below 1e-3 of a pixel plus 1e-4 of the image's scale.
        let worst = common::assert_gpu_matches_cpu(
            (&image.rgb, &image.transparency),
            (&reference.rgb, &reference.transparency),
            (1e-3, 1e-4, 1e-4),
            &format!("sun {elevation}°/{azimuth}°, {projection:?}"),
        );
        eprintln!(
            "sun {elevation}°/{azimuth}°, {update:?}, {projection:?}: worst |GPU − CPU| = {worst:.3} of the tolerance, frame {:.1} ms",
            t.frame * 1e3
        );
    }
}

#[test]
fn thin_uniform_box_gives_single_scattering() {
    let (tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let cloud = tables.field("cloud").unwrap();
    // τ = 1e-3 across the 1 km box in green.
    let density = 1e-6 / cloud.sigma_ext_m2[1];
    let grid_file = tmp.path().join("ones.f32");
    let ones: Vec<u8> = (0..64).flat_map(|_| 1f32.to_le_bytes()).collect();
    std::fs::write(&grid_file, ones).unwrap();
    let text = format!(
        r#"{}
[render]
width = 32
height = 32

[render.riley]
slices = 256
light_resolution = 32

[camera]
position_m = [0, 1500, 0]
look_at_m = [0, 1500, 5000]
fov_deg = 20

[sun]
elevation_deg = 30
azimuth_deg = 160

[sky]
enabled = false

[ground]
albedo = 0.0

[[volume]]
field = "cloud"
shape = "grid"
number_density_per_m3 = {density}
file = "ones.f32"
dims = [4, 4, 4]
min_m = [-500, 1000, 4500]
max_m = [500, 2000, 5500]
"#,
        fields()
    );
    let scene = RenderScene::parse(&text, "thin", tmp.path()).unwrap();
    let frame = scene.frame(&tables).unwrap();
    let settings = scene.settings::<Riley>().unwrap();
    let setup = Setup::new(&frame, &settings).unwrap();
    let image = cpu::render(&tables, &frame, &settings).unwrap();
    let mut checked = 0;
    let mut worst = 0f64;
    for j in 0..frame.height {
        for i in 0..frame.width {
            let (o, d) = setup.pixel(i, j, frame.width, frame.height);
            let Some((t0, t1)) = box_span(frame.grid.min_m, frame.grid.max_m, o, d) else {
                continue;
            };
            let chord = t1 - t0;
            if chord < 500.0 {
                continue;
            }
            let p1 = sample::ams(cloud, tables.theta_step_deg, 1.0, -setup.light.dot(d));
            // One slab of the slicing is the resolution of the chord; n ≤ 1e-3 and the light's
            // loss ≤ 1e-3 move the rest by well under 5e-3.
            let tol = setup.slice_step / setup.half.dot(d).abs() / chord + 5e-3;
            for c in 0..3 {
                let want = p1[c]
                    * cloud.albedo[c]
                    * (1.0 - (-density * cloud.sigma_ext_m2[c] * chord).exp());
                let got = image.rgb[i + frame.width * j][c] as f64;
                worst = worst.max(((got - want) / want).abs());
                assert!(
                    ((got - want) / want).abs() < tol,
                    "pixel ({i}, {j}) channel {c}: {got} vs single scattering {want} (tolerance {tol})"
                );
            }
            checked += 1;
        }
    }
    assert!(checked > 200, "only {checked} pixels crossed the box");
    eprintln!("{checked} pixels: worst relative difference from single scattering {worst:.2e}");
}

/// The soft-ball fixture of cloud, of optical depth `tau` through its centre in green,
/// side-lit by a low sun (5° up: Riley's hardest case for the light buffer), 64² pixels.
fn side_lit_ball(
    tables: &Tables,
    tau: f64,
    slices: usize,
    update: LightUpdate,
) -> (Frame, Settings) {
    let (text, base) = common::soft_ball(&fields());
    let mut scene = RenderScene::parse(&text, "ball", &base).unwrap();
    // ∫ sqrt(1 − |x|) over the diameter of the unit box's ball: 2·(2/3) of the box side / 2.
    scene.volumes[0].number_density_per_m3 =
        tau / (0.666 * 1000.0 * tables.field("cloud").unwrap().sigma_ext_m2[1]);
    scene.sun.elevation_deg = 5.0;
    let settings = Settings {
        slices,
        light_resolution: 64,
        light_update: update,
        ..Settings::default()
    };
    (scene.frame(tables).unwrap(), settings)
}

#[test]
fn the_soft_ball_fixture_is_its_formula() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, base) = common::soft_ball("");
    common::write_soft_ball(&tmp.path().join("ball.f32"), 48);
    assert!(
        std::fs::read(tmp.path().join("ball.f32")).unwrap()
            == std::fs::read(base.join("soft_ball_48.f32")).unwrap(),
        "data/scenes/fixtures/soft_ball_48.f32 is not √(1 − r) on 48³ voxels"
    );
}

/// An orthographic camera (`projection = "orthographic"`): each pixel is the radiance along
/// the view direction from its own point of the image plane, the one-pixel perspective image
/// from there (the slices and the light buffer depend on the view direction and the sun
/// alone).
#[test]
fn an_orthographic_pixel_is_the_ray_from_its_point_of_the_image_plane() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let (mut frame, settings) = side_lit_ball(&tables, 8.0, 64, LightUpdate::Continuum);
    (frame.width, frame.height) = (6, 4);
    let (worst, spread) = support::orthographic_against_single_rays(&frame, |f| {
        cpu::render(&tables, f, &settings).unwrap()
    });
    eprintln!("orthographic vs single rays: worst {worst:.1e}, the image's spread {spread:.2}");
    // Measured 0 (bit for bit); the bound allows the one-pixel camera's direction, look_at −
    // position normalized, to differ from the view direction in its last bits.
    assert!(worst < 1e-6, "worst relative difference {worst:.2e}");
    assert!(spread > 0.1, "the image is almost uniform ({spread:.3})");
}

#[test]
fn the_light_buffer_converges_as_slices_are_added() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let total = |tau: f64, slices: usize, update: LightUpdate| -> f64 {
        let (frame, settings) = side_lit_ball(&tables, tau, slices, update);
        let image = cpu::render(&tables, &frame, &settings).unwrap();
        image.rgb.iter().map(|p| p[1] as f64).sum()
    };
    for tau in [8.0, 32.0] {
        let coarse = total(tau, 256, LightUpdate::Continuum);
        let fine = total(tau, 1024, LightUpdate::Continuum);
        let change = fine / coarse - 1.0;
        let paper = total(tau, 1024, LightUpdate::Riley2004)
            / total(tau, 256, LightUpdate::Riley2004)
            - 1.0;
        eprintln!(
            "τ {tau}: 256 → 1024 slices, continuum {:+.2} %, Eq. 25 as printed {:+.2} %",
            change * 100.0,
            paper * 100.0
        );
        assert!(change.abs() < 0.01, "τ {tau}: the total moved {change:+.4}");
    }
}
