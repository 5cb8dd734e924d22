//! The `max` model (Max et al. 2004): its thin limit is single scattering whichever treatment
//! (dense or edge) a voxel gets, its image is continuous across the threshold T, and it
//! refuses what it cannot do before any work.

use std::path::Path;

use render::max::{Settings, cpu};
use render::{Frame, RenderScene};
use runtime::Tables;

#[path = "../../tests/common/mod.rs"]
mod common;
#[path = "support/uniform_box.rs"]
mod support;

use common::bake;

fn fields() -> String {
    common::scene("max", 8, common::CLOUD)
}

fn uniform_box(tables: &Tables, dir: &Path, tau: f64, sky: bool) -> Frame {
    support::uniform_box(tables, dir, &fields(), tau, sky, 30.0)
}

/// The soft-ball fixture of cloud, `tau` through its centre, side-lit (sun 20° up, 70° round),
/// rasterized to 32³ voxels, 40² pixels, with the sky and a grey ground.
fn ball(tables: &Tables, tau: f64) -> Frame {
    let (text, base) = common::soft_ball(&fields());
    let mut scene = RenderScene::parse(&text, "ball", &base).unwrap();
    scene.volumes[0].number_density_per_m3 =
        tau / (0.666 * 1000.0 * tables.field("cloud").unwrap().sigma_ext_m2[1]);
    (scene.width, scene.height, scene.grid_resolution) = (40, 40, 32);
    scene.sun.azimuth_deg = 70.0;
    scene.atmosphere = render::Atmosphere::default();
    scene.ground_albedo = render::scene::DEFAULT_GROUND_ALBEDO;
    scene.frame(tables).unwrap()
}

/// Worst relative difference of a `max` render of the uniform box of optical depth `tau`
/// from single scattering, over the pixels whose chord is ≥ 500 m, at threshold T.
fn thin_box_error(tables: &Tables, dir: &Path, tau: f64, threshold: f64) -> (f64, usize) {
    let frame = uniform_box(tables, dir, tau, false);
    let settings = Settings {
        threshold,
        ..Settings::default()
    };
    let (image, _) = cpu::render(tables, &frame, &settings).unwrap();
    support::single_scatter_error(tables, &frame, &image)
}

#[test]
fn a_thin_box_gives_single_scattering_in_both_treatments() {
    let (tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    // A voxel of these boxes has optical depth ≤ 3e-5 at this grid: T = 1e-7 puts it all in
    // the dense treatment, T = 1 all in the edge treatment. Both are single scattering of the
    // sun; the voxels are thinner than MIN_DIFFUSION_VOXEL_DEPTH, so the diffusion adds
    // nothing, and what is left is O(τ): the sunlight's attenuation inside the box, which the
    // reference leaves out.
    for (threshold, what) in [(1e-7, "dense"), (1.0, "edge")] {
        let (e3, checked) = thin_box_error(&tables, tmp.path(), 1e-3, threshold);
        let (e5, _) = thin_box_error(&tables, tmp.path(), 1e-5, threshold);
        eprintln!(
            "{what} treatment (T = {threshold}), {checked} pixels: worst relative difference \
             from single scattering {e3:.2e} at τ = 1e-3, {e5:.2e} at τ = 1e-5"
        );
        assert!(checked > 200, "only {checked} pixels crossed the box");
        // Measured 6.2e-6 (dense) and 5.2e-6 (edge), a hundredth of the τ = 1e-3 values.
        assert!(e5 < 8e-6, "{what}: {e5:e}");
        assert!(e3 > 50.0 * e5, "{what}: {e3:e} vs {e5:e}");
    }
}

#[test]
fn the_image_is_continuous_across_the_threshold() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = ball(&tables, 30.0);
    let render_at = |threshold: f64| {
        let settings = Settings {
            threshold,
            ..Settings::default()
        };
        cpu::render(&tables, &frame, &settings).unwrap().0
    };
    let total = |image: &render::Image| -> f64 { image.rgb.iter().map(|p| f64::from(p[1])).sum() };
    let worst_change = |a: &render::Image, b: &render::Image| {
        let scale = a.rgb.iter().map(|p| p[1]).fold(0.0f32, f32::max) as f64;
        a.rgb
            .iter()
            .zip(&b.rgb)
            .map(|(x, y)| (f64::from(x[1]) - f64::from(y[1])).abs() / scale)
            .fold(0.0, f64::max)
    };
    // Voxels of the ball run from optical depth 0 to ~1.5: T = 0.5 splits them.
    let base = render_at(0.5);
    let near = render_at(0.5 * (1.0 + 1e-3));
    let far = render_at(1.0);
    let (small, large) = (worst_change(&base, &near), worst_change(&base, &far));
    eprintln!(
        "T 0.5 → 0.5005: worst pixel change {small:.2e} of the brightest; T 0.5 → 1: {large:.2e}; \
         totals {:.4} / {:.4} / {:.4}",
        total(&base),
        total(&near),
        total(&far)
    );
    // A change of T by 1e-3 moves no pixel by more than a small multiple of 1e-3 (a jump at a
    // segment's start or end would move some by ~the edge light itself), while a change of T by
    // 2× does move them: the check can fail.
    assert!(small < 1e-3, "{small:e}"); // measured 6.0e-4 (the soft-ball fixture at 32³)
    assert!(large > 20.0 * small, "{large:e} vs {small:e}");
}

#[test]
fn bad_settings_and_short_tables_are_refused() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = ball(&tables, 30.0);
    for (settings, key) in [
        (
            Settings {
                threshold: 0.0,
                ..Settings::default()
            },
            "threshold = 0",
        ),
        (
            Settings {
                threshold: -1.0,
                ..Settings::default()
            },
            "threshold = -1",
        ),
        (
            Settings {
                tolerance: 0.0,
                ..Settings::default()
            },
            "diffusion_tolerance = 0",
        ),
        (
            Settings {
                max_iterations: 1,
                tolerance: 1e-9,
                ..Settings::default()
            },
            "did not converge",
        ),
    ] {
        let e = cpu::render(&tables, &frame, &settings)
            .unwrap_err()
            .to_string();
        assert!(e.contains(key), "{key}: {e}");
    }
    // A threshold above every voxel's optical depth puts the whole ball in edge segments of
    // optical depth ~30 per ray: beyond a table baked to D = 5.
    let (_tmp5, dir5) = bake(&fields().replace("n_max = 8", "n_max = 8\npoisson_max_depth = 5"));
    let short = Tables::open(&dir5).unwrap();
    let settings = Settings {
        threshold: 100.0,
        ..Settings::default()
    };
    let e = cpu::render(&short, &frame, &settings)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("beyond the bake's Poisson table") && e.contains("poisson_max_depth = 5"),
        "{e}"
    );
}

/// Two 4-voxel-wide blocks of cloud (or only the first), 8 voxels of clear air between them,
/// in a 16 × 8 × 8 grid, side-lit along the row.
fn blocks(tables: &Tables, dir: &Path, both: bool, clear_air: usize) -> Frame {
    let mut bytes = Vec::new();
    for _z in 0..8 {
        for _y in 0..8 {
            for x in 0..16 {
                let full = x < 4 || (both && x >= 12);
                bytes.extend_from_slice(&(if full { 1f32 } else { 0f32 }).to_le_bytes());
            }
        }
    }
    std::fs::write(dir.join("blocks.f32"), bytes).unwrap();
    let density = 5.0 / 250.0 / tables.field("cloud").unwrap().sigma_ext_m2[1];
    let text = format!(
        r#"{}
[render]
width = 24
height = 12
grid_resolution = 16

[render.max]
clear_air_iterations = {clear_air}

[camera]
position_m = [0, 500, -4000]
look_at_m = [0, 500, 500]
fov_deg = 20

[sun]
elevation_deg = 10
azimuth_deg = 270

[sky]
enabled = false

[ground]
albedo = 0.0

[[volume]]
field = "cloud"
shape = "grid"
file = "blocks.f32"
dims = [16, 8, 8]
min_m = [-1000, 0, 0]
max_m = [1000, 1000, 1000]
number_density_per_m3 = {density}
"#,
        fields()
    );
    RenderScene::parse(&text, "blocks", dir)
        .unwrap()
        .frame(tables)
        .unwrap()
}

#[test]
fn light_crosses_clear_air_between_parts_and_never_comes_back_to_its_own() {
    let (tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let run = |both: bool, clear_air: usize| {
        let frame = blocks(&tables, tmp.path(), both, clear_air);
        let settings = Settings {
            clear_air_iterations: clear_air,
            ..Settings::default()
        };
        cpu::render(&tables, &frame, &settings).unwrap()
    };
    // One block alone: none of its light returns to it across clear air.
    let (_, alone) = run(false, 1);
    assert_eq!(alone.clear_air_mean, 0.0);
    // Two blocks: the sun (azimuth 270°) is on the −x side, so the first block is lit and
    // its light crosses the gap into the second, which brightens.
    let (without, _) = run(true, 0);
    let (with, report) = run(true, 1);
    let total = |image: &render::Image| -> f64 { image.rgb.iter().map(|p| f64::from(p[1])).sum() };
    eprintln!(
        "two blocks: mean light across clear air {:.3e}; total {:.4} → {:.4} with one iteration",
        report.clear_air_mean,
        total(&without),
        total(&with)
    );
    assert!(report.clear_air_mean > 0.0);
    assert!(total(&with) > total(&without));
}

/// The final gather on the GPU (`max::gpu`, f32, lavapipe in CI) equals the CPU reference's from
/// the same lighting: a τ 30 soft ball side-lit over a lit ground with the sky on (the edge and
/// dense treatments, the Poisson lookups, Ams_1, the composition and the ground's march to the
/// sun all take part), and the same lighting serves a second camera and an orthographic one.
#[test]
fn the_gpu_gather_equals_the_cpu_reference() {
    let Some(gpu) = common::gpu() else { return };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let mut frame = ball(&tables, 30.0);
    frame.ground_albedo = 0.3;
    // Lifted 400 m off the ground, so that the composite's air below it is in its shadow
    // (shading::air_shadow).
    frame.grid.min_m.y += 400.0;
    frame.grid.max_m.y += 400.0;
    let settings = Settings::default();
    let lighting = cpu::light(&tables, &frame, &settings).unwrap();
    let uploaded =
        runtime::gpu::GpuTables::upload(&gpu, &tables, runtime::gpu::TexelFormat::F32).unwrap();
    let renderer = render::max::gpu::Renderer::new(&gpu, &uploaded);
    for (camera, projection) in support::cameras() {
        frame.camera.position_m = glam::DVec3::from_array(camera);
        frame.camera.projection = projection;
        let (cpu_image, report) = cpu::gather(&tables, &frame, &settings, &lighting).unwrap();
        let (gpu_image, t, largest) = renderer
            .gather(&gpu, &tables, &uploaded, &frame, &settings, &lighting)
            .unwrap();
        let worst_t = gpu_image
            .transparency
            .iter()
            .zip(&cpu_image.transparency)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        let worst = common::assert_gpu_matches_cpu(
            (&gpu_image.rgb, &gpu_image.transparency),
            (&cpu_image.rgb, &cpu_image.transparency),
            // Measured on lavapipe: within 0.95 × (10⁻⁵ |CPU| + 10⁻⁶ of the 99th percentile),
            // T within 4.8·10⁻⁶ (f32 against f64).
            (1.2e-5, 1.2e-6, 6e-6),
            "max gather",
        );
        let depth = (largest - report.largest_edge_depth).abs() / report.largest_edge_depth;
        eprintln!(
            "camera {camera:?} {projection:?}: worst |GPU − CPU| {worst:.2} of the tolerance, |ΔT| \
             {worst_t:.1e}; largest edge depth {largest:.4} vs {:.4}; gather {:.1} ms on the \
             GPU, {:.1} ms on the CPU",
            report.largest_edge_depth,
            1e3 * t.frame,
            1e3 * report.gather_s
        );
        assert!(
            depth < 1e-4,
            "largest edge depth {largest} vs {}",
            report.largest_edge_depth
        );
    }
}

/// An orthographic camera (`projection = "orthographic"`): each pixel of the CPU gather is the
/// radiance along the view direction from its own point of the image plane, the one-pixel
/// perspective image from there (the GPU's equals the CPU's in the test above).
#[test]
fn an_orthographic_pixel_is_the_ray_from_its_point_of_the_image_plane() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let mut frame = ball(&tables, 30.0);
    frame.ground_albedo = 0.3;
    (frame.width, frame.height) = (6, 4);
    let settings = Settings::default();
    let lighting = cpu::light(&tables, &frame, &settings).unwrap();
    let (worst, spread) = support::orthographic_against_single_rays(&frame, |f| {
        cpu::gather(&tables, f, &settings, &lighting).unwrap().0
    });
    eprintln!("orthographic vs single rays: worst {worst:.1e}, the image's spread {spread:.2}");
    // Measured 0 (bit for bit); the bound allows the one-pixel camera's direction, look_at −
    // position normalized, to differ from the view direction in its last bits.
    assert!(worst < 1e-6, "worst relative difference {worst:.2e}");
    assert!(spread > 0.1, "the image is almost uniform ({spread:.3})");
}

/// Max's per-sun passes on the GPU (`per_sun = "gpu"`: the reduced sunlight as one direction of
/// the skylight's sweeps, the skylight's sweeps and every diffusion solve, f32,
/// lavapipe in CI) light a τ 30 soft ball as the CPU reference does (f64): T_sun, the skylight's
/// mean and the diffusion's I_0, each against its largest value.
#[test]
fn the_gpu_lighting_equals_the_cpu_reference() {
    let Some(gpu) = common::gpu() else { return };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = ball(&tables, 30.0);
    let settings = Settings {
        per_sun: render::lighting::Place::Gpu,
        ..Settings::default()
    };
    let cpu_light = cpu::light(&tables, &frame, &settings).unwrap();
    let pipelines = render::lighting::Pipelines::default();
    let gpu_light =
        cpu::light_on(&tables, &frame, &settings, &(), Some(pipelines.on(&gpu))).unwrap();
    assert!(
        gpu_light
            .report
            .on
            .iter()
            .all(|o| !o.starts_with("the CPU")),
        "{:?}",
        gpu_light.report.on
    );
    let worst = |a: &[[f64; 3]], b: &[[f64; 3]]| {
        let top = b.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(top > 0.0);
        a.iter()
            .flatten()
            .zip(b.iter().flatten())
            .map(|(x, y)| (x - y).abs() / top)
            .fold(0.0f64, f64::max)
    };
    let t_sun = worst(&gpu_light.t_sun, &cpu_light.t_sun);
    let sky = worst(&gpu_light.sky_mean, &cpu_light.sky_mean);
    let i0 = worst(&gpu_light.i0, &cpu_light.i0);
    eprintln!(
        "max lighting on the GPU: worst T_sun {t_sun:.2e}, skylight {sky:.2e}, I_0 {i0:.2e} of \
         their largest; on {:?}",
        gpu_light.report.on
    );
    assert!(
        t_sun < GPU_LIGHTING_TOLERANCE.0
            && sky < GPU_LIGHTING_TOLERANCE.1
            && i0 < GPU_LIGHTING_TOLERANCE.2,
        "T_sun {t_sun:e}, sky {sky:e}, I_0 {i0:e}"
    );
}

/// The GPU lighting's worst differences from the CPU's (T_sun, skylight, I_0), of each one's
/// largest value, just above the measured (lavapipe; f32 sweeps, an f32 solve inside an f64
/// refinement): 4.24·10⁻⁷, 2.09·10⁻⁷, 9.45·10⁻⁷.
const GPU_LIGHTING_TOLERANCE: (f64, f64, f64) = (5e-7, 2.5e-7, 1.1e-6);

/// The soft ball of optical depth `tau` lifted 400 m (repeating in x and z if `periodic`):
/// its shadow map against the march to the sun it replaces at `points`, the march's green
/// sunlight left at each and the map's largest and mean difference over the channels.
fn shadow_map_against_march(
    tau: f64,
    periodic: bool,
    points: &[glam::DVec3],
) -> (Vec<f64>, f64, f64) {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let mut frame = ball(&tables, tau);
    frame.grid.min_m.y += 400.0;
    frame.grid.max_m.y += 400.0;
    frame.grid.periodic = periodic;
    let fields: Vec<_> = tables.fields.iter().collect();
    let sun = frame.sun.direction();
    let march = |p: glam::DVec3| {
        render::lighting::sun::transmittance_to_sun(&fields, &frame.grid, p, sun, None)
    };
    let map = render::lighting::sun::ShadowMap::new(&frame.grid, sun, march);
    let (mut left, mut worst, mut sum) = (Vec::new(), 0.0f64, 0.0);
    for &p in points {
        let (a, b) = (map.at(p), march(p));
        left.push(b[1]);
        for c in 0..3 {
            worst = worst.max((a[c] - b[c]).abs());
            sum += (a[c] - b[c]).abs();
        }
    }
    (left, worst, sum / (3 * points.len()) as f64)
}

/// Points on a 40 × 40 lattice from (x0, z0) with steps (dx, dz), at the heights `ys`.
fn lattice_points((x0, z0): (f64, f64), (dx, dz): (f64, f64), ys: &[f64]) -> Vec<glam::DVec3> {
    let mut points = Vec::new();
    for i in 0..40 {
        for j in 0..40 {
            for &y in ys {
                points.push(glam::DVec3::new(x0 + dx * i as f64, y, z0 + dz * j as f64));
            }
        }
    }
    points
}

/// The shadow map below the grid (the ground's and the air's light) against the march to the
/// sun it replaces, at points on the ground and in the air below a ball lifted 400 m: equal
/// within the bilinear interpolation between cells of a voxel's size, and 1 outside the shadow.
#[test]
fn the_shadow_map_is_the_march_to_the_sun() {
    let points = lattice_points((-3000.0, -2000.0), (150.0, 150.0), &[0.0, 200.0, 399.0]);
    let (left, worst, mean) = shadow_map_against_march(30.0, false, &points);
    let shadowed = left.iter().filter(|&&l| l < 0.99).count();
    println!(
        "{shadowed} of {} points shadowed; |map − march| worst {worst:.3}, mean {mean:.2e}",
        points.len()
    );
    assert!(shadowed > 200, "the test's points miss the shadow");
    // Measured: worst 0.076 (a soft edge between two cells), mean 4.0·10⁻⁴.
    assert!(worst < 0.08 && mean < 5e-4, "{worst} {mean}");
}

/// A periodic grid's shadow map (coupled's, which draws periodic volumes) repeats with the
/// box: at points on the ground and in the air below the ball's layer over six periods, it is
/// the march to the sun through the repeating layer within the same interpolation.
#[test]
fn a_periodic_shadow_map_is_the_march_through_the_repeating_layer() {
    // Thin (τ 1 through a ball's centre): the sun's slanted path crosses several balls.
    let points = lattice_points((-3000.0, -3000.0), (151.0, 149.0), &[0.0, 399.0]);
    let (left, worst, mean) = shadow_map_against_march(1.0, true, &points);
    let (dark, lit) = left
        .iter()
        .fold((1.0f64, 0.0f64), |(d, l), &v| (d.min(v), l.max(v)));
    println!("sunlight left {dark:.3} … {lit:.3}; |map − march| worst {worst:.3}, mean {mean:.2e}");
    // Measured: the sunlight left 0.237 … 0.511; worst 0.006, mean 6.7·10⁻⁴ (every point
    // under the layer, none in the clear).
    assert!(lit - dark > 0.2, "the points see one shade: {dark} … {lit}");
    assert!(worst < 0.01 && mean < 8e-4, "{worst} {mean}");
}
