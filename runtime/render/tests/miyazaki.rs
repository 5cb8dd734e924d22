//! Miyazaki, Dobashi & Nishita's shadow-view slices (`render::miyazaki`), CPU reference:
//! - an optically thin uniform box gives single scattering with Ams_1 + k_multi (Eq. 1 with
//!   g_view = g_sun = 1), and with Cornette–Shanks's function for the paper's phase option;
//! - the ground under a slab of cloud of known optical depth is darker by e^{−τ/sin e} than
//!   the lit ground beside it (the shadow surface, Eq. 10);
//! - bad scene keys are refused, naming the key, the value and the range.

use std::path::Path;

use glam::DVec3;
use render::geometry::box_span;
use render::miyazaki::cpu::{asymmetry, cornette_shanks, render};
use render::miyazaki::{Miyazaki, SvsPhase, setup};
use render::{Frame, RenderScene};
use runtime::{Tables, sample};

#[path = "../../tests/common/mod.rs"]
mod common;
#[path = "support/uniform_box.rs"]
mod support;

fn fields() -> String {
    common::cloud_and_rain("miyazaki", 4)
}

/// A scene of one grid volume of constant density over `[min, max]`, written beside the bake.
fn uniform_box(
    tmp: &Path,
    density: f64,
    min: [f64; 3],
    max: [f64; 3],
    extra: &str,
) -> (RenderScene, String) {
    let grid_file = tmp.join("ones.f32");
    let ones: Vec<u8> = (0..64).flat_map(|_| 1f32.to_le_bytes()).collect();
    std::fs::write(&grid_file, ones).unwrap();
    let text = format!(
        r#"{}
{extra}

[[volume]]
field = "cloud"
shape = "grid"
number_density_per_m3 = {density}
file = "ones.f32"
dims = [4, 4, 4]
min_m = {min:?}
max_m = {max:?}
"#,
        fields()
    );
    (RenderScene::parse(&text, "test", tmp).unwrap(), text)
}

fn pixel_ray(frame: &Frame, i: usize, j: usize) -> DVec3 {
    let axes = frame.camera.axes().unwrap();
    let tan = frame.camera.tan_half_fov();
    render::camera::pixel_ray(axes, tan, (i, j), (frame.width, frame.height))
}

#[test]
fn thin_uniform_box_gives_single_scattering_with_k_multi() {
    let (tmp, dir) = common::bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let cloud = tables.field("cloud").unwrap();
    // τ = 1e-3 across the 1 km box in green.
    let density = 1e-6 / cloud.sigma_ext_m2[1];
    let g = asymmetry(cloud, tables.theta_step_deg);
    let mut worst: f64 = 0.0;
    for (k_multi, phase, name) in [
        (0.0, SvsPhase::Tables, "tables"),
        (0.05, SvsPhase::Tables, "tables"),
        (0.02, SvsPhase::CornetteShanks, "cornette_shanks"),
    ] {
        let extra = format!(
            "[render]\nwidth = 32\nheight = 32\n[render.miyazaki]\nslices = 256\n\
             light_resolution = 32\na = 1.5\nk_multi = {k_multi}\nphase = \"{name}\"\n\n\
             [camera]\nposition_m = [0, 1500, 0]\nlook_at_m = [0, 1500, 5000]\nfov_deg = 20\n\n\
             [sun]\nelevation_deg = 30\nazimuth_deg = 160\n\n[sky]\nenabled = false\n\n\
             [ground]\nalbedo = 0.0"
        );
        let (scene, _) = uniform_box(
            tmp.path(),
            density,
            [-500.0, 1000.0, 4500.0],
            [500.0, 2000.0, 5500.0],
            &extra,
        );
        let svs = scene.settings::<Miyazaki>().unwrap();
        assert_eq!(svs.phase, phase);
        let frame = scene.frame(&tables).unwrap();
        let s = setup(&frame, &svs).unwrap();
        let image = render(&tables, &frame, &svs).unwrap();
        let mut checked = 0;
        for j in 0..frame.height {
            for i in 0..frame.width {
                let d = pixel_ray(&frame, i, j);
                let Some((t0, t1)) = box_span(frame.grid.min_m, frame.grid.max_m, s.eye, d) else {
                    continue;
                };
                let chord = t1 - t0;
                if chord < 500.0 {
                    continue;
                }
                let cos = d.dot(s.to_sun);
                let p1 = match phase {
                    SvsPhase::Tables => sample::ams(cloud, tables.theta_step_deg, 1.0, cos),
                    SvsPhase::CornetteShanks => std::array::from_fn(|c| cornette_shanks(g[c], cos)),
                };
                // One slab of the slicing resolves the chord; the light's and the eye's losses
                // (τ ≤ 1e-3) move the rest by well under 5e-3.
                let tol = s.step / s.normal.dot(d).abs() / chord + 5e-3;
                for c in 0..3 {
                    let want = (p1[c] + k_multi)
                        * cloud.albedo[c]
                        * (1.0 - (-density * cloud.sigma_ext_m2[c] * chord).exp());
                    let got = image.rgb[i + frame.width * j][c] as f64;
                    let rel = ((got - want) / want).abs();
                    worst = worst.max(rel);
                    assert!(
                        rel < tol,
                        "{name} k_multi {k_multi}, pixel ({i}, {j}) channel {c}: {got} vs \
                         single scattering {want} (tolerance {tol})"
                    );
                }
                checked += 1;
            }
        }
        assert!(checked > 200, "only {checked} pixels crossed the box");
    }
    eprintln!("worst relative difference from single scattering {worst:.2e}");
}

#[test]
fn cornette_shanks_is_normalized_and_has_its_asymmetry() {
    for &g in &[0.0, 0.5, 0.85] {
        let n = 200_000;
        let (mut m0, mut m1) = (0.0, 0.0);
        for i in 0..n {
            let mu = -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
            let p = cornette_shanks(g, mu) * 2.0 * std::f64::consts::PI * 2.0 / n as f64;
            m0 += p;
            m1 += p * mu;
        }
        // ∫ P dΩ = 1; Cornette & Shanks's mean cosine is 3g(4 + g²)/(5(2 + g²)).
        let want_g = 3.0 * g * (4.0 + g * g) / (5.0 * (2.0 + g * g));
        assert!((m0 - 1.0).abs() < 1e-6, "g {g}: ∫P dΩ = {m0}");
        assert!(
            (m1 - want_g).abs() < 1e-6,
            "g {g}: ⟨cos⟩ = {m1} vs {want_g}"
        );
    }
}

#[test]
fn the_ground_under_a_cloud_slab_is_darker_by_its_transmittance() {
    let (tmp, dir) = common::bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let cloud = tables.field("cloud").unwrap();
    // A slab 200 m thick of vertical optical depth 1 (green) at 1000–1200 m; the sun 60° up
    // at azimuth 0, so the shadow falls 635 m towards −z of the slab; the camera under the
    // slab looks down at the ground where both lit and shadowed ground are in view.
    let thickness = 200.0;
    let density = 1.0 / (cloud.sigma_ext_m2[1] * thickness);
    let extra = "[render]\nwidth = 48\nheight = 36\n[render.miyazaki]\nslices = 2048\n\
                 light_resolution = 128\n\n\
                 [camera]\nposition_m = [0, 500, -2000]\nlook_at_m = [0, 0, 2500]\nfov_deg = 50\n\n\
                 [sun]\nelevation_deg = 60\nazimuth_deg = 0\n\n[sky]\nenabled = false\n\n\
                 [ground]\nalbedo = 0.5";
    let (scene, _) = uniform_box(
        tmp.path(),
        density,
        [-3000.0, 1000.0, 0.0],
        [3000.0, 1200.0, 4000.0],
        extra,
    );
    let frame = scene.frame(&tables).unwrap();
    let svs = scene.settings::<Miyazaki>().unwrap();
    let s = setup(&frame, &svs).unwrap();
    let image = render(&tables, &frame, &svs).unwrap();
    let l_y = s.to_sun.y;
    let lit = 0.5 / std::f64::consts::PI * l_y;
    let (mut shadowed, mut sunlit, mut worst) = (0, 0, 0.0f64);
    for j in 0..frame.height {
        for i in 0..frame.width {
            let d = pixel_ray(&frame, i, j);
            if d.y >= 0.0 {
                continue;
            }
            let ground = s.eye + (s.eye.y / -d.y) * d;
            // The ground point's sun ray through the slab's box: its path and its distance
            // from the box's side faces (shadow edges are blurred over a texel).
            let (path, margin) =
                match box_span(frame.grid.min_m, frame.grid.max_m, ground, s.to_sun) {
                    Some((t0, t1)) => {
                        let p = ground + 0.5 * (t0 + t1) * s.to_sun;
                        let m = (p.x - frame.grid.min_m.x)
                            .min(frame.grid.max_m.x - p.x)
                            .min(p.z - frame.grid.min_m.z)
                            .min(frame.grid.max_m.z - p.z);
                        (t1 - t0, m)
                    }
                    None => (0.0, f64::INFINITY),
                };
            let texel = s.shadow_texel[0].max(s.shadow_texel[1]);
            let got = image.rgb[i + frame.width * j];
            // Lit: the sun rays from the point and from points two texels off it in every
            // direction of the shadow surface all miss the box.
            let clear = [(0.0, 0.0), (2.0, 0.0), (-2.0, 0.0), (0.0, 2.0), (0.0, -2.0)]
                .iter()
                .all(|&(a, b)| {
                    let q = ground + a * texel * s.shadow_u + b * texel * s.shadow_w;
                    box_span(frame.grid.min_m, frame.grid.max_m, q, s.to_sun).is_none()
                });
            if clear {
                for c in 0..3 {
                    assert!(
                        ((got[c] as f64) - lit).abs() < 1e-6 * lit,
                        "lit ground ({i}, {j}) channel {c}: {} vs {lit}",
                        got[c]
                    );
                }
                sunlit += 1;
            } else if margin > 3.0 * texel && (path - thickness / l_y).abs() < 1e-6 {
                for c in 0..3 {
                    let ext = density * cloud.sigma_ext_m2[c];
                    let want = lit * (-ext * path).exp();
                    // The shadow surface samples the sun's path at the slices: one slab Δs.
                    let tol = ext * s.sun_step;
                    let err = ((got[c] as f64) / want).ln().abs();
                    worst = worst.max(err / tol);
                    assert!(
                        err < tol,
                        "shadowed ground ({i}, {j}) channel {c}: {} vs {want} \
                         (|ln ratio| {err:.2e}, tolerance {tol:.2e})",
                        got[c]
                    );
                }
                shadowed += 1;
            }
        }
    }
    assert!(
        shadowed > 100 && sunlit > 50,
        "{shadowed} shadowed, {sunlit} lit pixels"
    );
    eprintln!(
        "{shadowed} shadowed and {sunlit} lit ground pixels; worst shadow error {worst:.2} of one \
         slab's optical depth"
    );
}

#[test]
fn single_scattering_in_a_haze_layer_is_exact() {
    // Eq. 1's atmosphere term alone: a horizontal ray at 500 m through an exponential haze
    // (H = 1 km, β_ext ≈ 1e-4 /m there), the sun 30° up at 90° to the ray: per channel
    // ω P(90°) e^{−τ_sun}, P the haze's Ams_1.
    let (tmp, dir) = common::bake(&common::scene(
        "haze",
        4,
        &format!("{}{}", common::CLOUD, common::HAZE),
    ));
    let tables = Tables::open(&dir).unwrap();
    let haze = tables.field("haze").unwrap();
    let n0 = 1e-4 / (haze.sigma_ext_m2[1] * (-0.5f64).exp());
    let scene = RenderScene::parse(&common::haze_scene(n0), "haze", tmp.path()).unwrap();
    let frame = scene.frame(&tables).unwrap();
    let svs = scene.settings::<Miyazaki>().unwrap();
    let s = setup(&frame, &svs).unwrap();
    let image = render(&tables, &frame, &svs).unwrap();
    let mut worst: f64 = 0.0;
    for (p, rgb) in image.rgb.iter().enumerate() {
        let d = pixel_ray(&frame, p % frame.width, p / frame.width);
        let cos = d.dot(s.to_sun);
        let phase = sample::ams(haze, tables.theta_step_deg, 1.0, cos);
        for c in 0..3 {
            let want = common::haze_single_scattering(
                haze.albedo[c],
                phase[c],
                n0 * haze.sigma_ext_m2[c],
                1000.0,
                500.0,
                s.to_sun.y,
            );
            let rel = (rgb[c] as f64 - want) / want;
            worst = worst.max(rel.abs());
            // The midpoint rule at 0.02 of an optical depth per step, and f32 output:
            // measured worst 1.5e-4.
            assert!(
                rel.abs() < 3e-4,
                "pixel {p} channel {c}: {} vs {want} ({rel:+.2e})",
                rgb[c]
            );
        }
    }
    eprintln!("worst relative difference {worst:.2e}");
}

#[test]
fn a_shadow_in_the_haze_removes_its_single_scattering() {
    // A light shaft's complement: an opaque block beside a horizontal view ray, the sun at 30°
    // from the side, so the block's shadow crosses the ray 3–4 km ahead. The render with the
    // block and the one with a vanishing block differ, pixel by pixel, by the haze's single
    // scattering along the shadowed stretch of the ray, I ∫ N σ_sca P(α) g_sun_atm T_view dt,
    // integrated here by the midpoint rule at 1 m with the shadow from the box's geometry.
    let (tmp, dir) = common::bake(&common::scene(
        "shaft",
        4,
        &format!("{}{}", common::CLOUD, common::HAZE),
    ));
    let tables = Tables::open(&dir).unwrap();
    let cloud = tables.field("cloud").unwrap();
    let haze = tables.field("haze").unwrap();
    let n0 = 1e-4 / haze.sigma_ext_m2[1];
    let (min, max) = ([1100.0, 1000.0, 3000.0], [2000.0, 1400.0, 4000.0]);
    let extra = |_: ()| {
        format!(
            "[render]\nwidth = 16\nheight = 8\n[render.miyazaki]\nslices = 512\n\
             light_resolution = 256\n\n\
             [camera]\nposition_m = [0, 300, 0]\nlook_at_m = [0, 300, 1000]\nfov_deg = 4\n\n\
             [sun]\nelevation_deg = 30\nazimuth_deg = 90\n\n[sky]\nenabled = false\n\n\
             [ground]\nalbedo = 0.0\n\n\
             [haze]\nfield = \"haze\"\nnumber_density_per_m3 = {n0}\nscale_height_m = 1500"
        )
    };
    // τ ≈ 400 through the block along the sun; 1e-12 of it for the reference.
    let opaque = 1.0 / cloud.sigma_ext_m2[1];
    let mut images = Vec::new();
    let mut frames = Vec::new();
    for density in [opaque, opaque * 1e-12] {
        let (scene, _) = uniform_box(tmp.path(), density, min, max, &extra(()));
        let frame = scene.frame(&tables).unwrap();
        let svs = scene.settings::<Miyazaki>().unwrap();
        images.push(render(&tables, &frame, &svs).unwrap());
        frames.push((frame, svs));
    }
    let (frame, svs) = &frames[0];
    let s = setup(frame, svs).unwrap();
    let (lo, hi) = (glam::DVec3::from_array(min), glam::DVec3::from_array(max));
    let h = 1500.0;
    let mut worst: f64 = 0.0;
    for p in 0..frame.width * frame.height {
        let d = pixel_ray(frame, p % frame.width, p / frame.width);
        let phase = sample::ams(haze, tables.theta_step_deg, 1.0, d.dot(s.to_sun));
        for c in 0..3 {
            let ext0 = n0 * haze.sigma_ext_m2[c];
            let sca0 = n0 * haze.sigma_sca_m2[c];
            let mut want = 0.0;
            let dt = 1.0;
            for i in 0..5000 {
                let t = (i as f64 + 0.5) * dt;
                let q = s.eye + t * d;
                if box_span(lo, hi, q, s.to_sun).is_none() {
                    continue;
                }
                let n = (-q.y / h).exp();
                let sun = (-ext0 * h * n / s.to_sun.y).exp();
                // Transmittance from the eye along the (nearly horizontal) ray.
                let depth = if d.y.abs() < 1e-12 {
                    (-s.eye.y / h).exp() * t
                } else {
                    h * ((-s.eye.y / h).exp() - (-q.y / h).exp()) / d.y
                };
                want += sca0 * n * phase[c] * sun * (-ext0 * depth).exp() * dt;
            }
            let got = (images[1].rgb[p][c] - images[0].rgb[p][c]) as f64;
            let rel = (got - want) / want;
            worst = worst.max(rel.abs());
            // The shadow's edges, resolved to a texel or a slice: measured worst 2.2e-3.
            assert!(
                rel.abs() < 3e-3,
                "pixel {p} channel {c}: the shadow removed {got:.4e}, single scattering in it \
                 {want:.4e} ({rel:+.2e})"
            );
        }
    }
    eprintln!("worst relative difference {worst:.2e}");
}

#[test]
fn gpu_render_matches_the_cpu_reference() {
    let Some(gpu) = common::gpu() else { return };
    // A cumulus and a rain shaft over a grey ground, in Rayleigh air and haze, the sun behind
    // the camera (front to back) and ahead of it (back to front), both phase functions, a = 1
    // and 2, k_multi 0.05; both orders also seen by an orthographic camera 6 km wide.
    let (tmp, dir) = common::bake(&common::scene(
        "svs-gpu",
        4,
        &format!("{}{}{}", common::CLOUD, common::RAIN, common::HAZE),
    ));
    let tables = Tables::open(&dir).unwrap();
    let uploaded =
        runtime::gpu::GpuTables::upload(&gpu, &tables, runtime::gpu::TexelFormat::F32).unwrap();
    let renderer = render::miyazaki::gpu::Renderer::new(&gpu, &uploaded);
    let (pinhole, ortho) = (
        "fov_deg = 50",
        "projection = \"orthographic\"\nwidth_m = 6000",
    );
    for (elevation, azimuth, a, phase, projection) in [
        (20.0, 200.0, 1.0, "tables", pinhole),
        (30.0, 10.0, 2.0, "tables", pinhole),
        (30.0, 10.0, 1.5, "cornette_shanks", pinhole),
        (20.0, 200.0, 1.0, "tables", ortho),
        (30.0, 10.0, 2.0, "tables", ortho),
    ] {
        let text = format!(
            r#"{}
[render]
width = 64
height = 48
grid_resolution = 40

[render.miyazaki]
slices = 64
light_resolution = 64
a = {a}
k_multi = 0.05
phase = "{phase}"

[camera]
position_m = [0, 300, 0]
look_at_m = [0, 1500, 6000]
{projection}

[sun]
elevation_deg = {elevation}
azimuth_deg = {azimuth}

[ground]
albedo = 0.3

[haze]
field = "haze"
number_density_per_m3 = 2e9
scale_height_m = 1200

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
            common::scene(
                "svs-gpu",
                4,
                &format!("{}{}{}", common::CLOUD, common::RAIN, common::HAZE)
            )
        );
        let scene = RenderScene::parse(&text, "test", tmp.path()).unwrap();
        let frame = scene.frame(&tables).unwrap();
        let svs = scene.settings::<Miyazaki>().unwrap();
        let reference = render(&tables, &frame, &svs).unwrap();
        let (image, t) = renderer
            .render(&gpu, &tables, &uploaded, &frame, &svs)
            .unwrap();
        // f32 against f64 on lavapipe: worst 1e-6·|c| + 1e-7 of the image's scale; the margin
        // is for GPUs whose exp and pow are a few ulp off.
        let worst = common::assert_gpu_matches_cpu(
            (&image.rgb, &image.transparency),
            (&reference.rgb, &reference.transparency),
            (1e-4, 1e-5, 1e-5),
            &format!("sun {elevation}°/{azimuth}° a {a} {phase} {projection}"),
        );
        eprintln!(
            "sun {elevation}°/{azimuth}° a {a} {phase} {projection:?}: worst |GPU − CPU| = {worst:.3} of the \
             tolerance, frame {:.1} ms",
            t.frame * 1e3
        );
    }
}

/// An orthographic camera (`projection = "orthographic"`): each pixel is the radiance along
/// the view direction from its own point of the image plane, the one-pixel perspective image
/// from there (the slices and the shadow surface depend on the view direction and the sun
/// alone), here with the air, its shadowed part and the ground taking part.
#[test]
fn an_orthographic_pixel_is_the_ray_from_its_point_of_the_image_plane() {
    let (_tmp, dir) = common::bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let (text, base) = common::soft_ball(&fields());
    let text = text.replace("enabled = false", "enabled = true");
    let scene = RenderScene::parse(&text, "ball", &base).unwrap();
    let mut frame = scene.frame(&tables).unwrap();
    frame.ground_albedo = 0.3;
    (frame.width, frame.height) = (6, 4);
    let mut settings = scene.settings::<Miyazaki>().unwrap();
    (settings.slices, settings.light_resolution) = (64, 64);
    let (worst, spread) = support::orthographic_against_single_rays(&frame, |f| {
        render(&tables, f, &settings).unwrap()
    });
    eprintln!("orthographic vs single rays: worst {worst:.1e}, the image's spread {spread:.2}");
    // Measured 0 (bit for bit); the bound allows the one-pixel camera's direction, look_at −
    // position normalized, to differ from the view direction in its last bits.
    assert!(worst < 1e-6, "worst relative difference {worst:.2e}");
    assert!(spread > 0.1, "the image is almost uniform ({spread:.3})");
}

#[test]
fn bad_keys_are_refused_naming_the_key_value_and_range() {
    let base = format!(
        "{}\n[camera]\nposition_m = [0, 100, 0]\nlook_at_m = [0, 100, 10]\n\n\
         [sun]\nelevation_deg = 30\nazimuth_deg = 0\n\n\
         [[volume]]\nfield = \"cloud\"\nshape = \"cumulus\"\nnumber_density_per_m3 = 1e6\n\
         center_m = [0, 500, 2000]\nradius_m = 300\nheight_m = 300\n",
        fields()
    );
    for (keys, needle) in [
        (
            "[render.miyazaki]\na = -1",
            "[render.miyazaki] a = -1 is outside the allowed range (0, 2]",
        ),
        (
            "[render.miyazaki]\na = 2.5",
            "[render.miyazaki] a = 2.5 is outside the allowed range (0, 2]",
        ),
        (
            "[render.miyazaki]\nk_multi = -0.1",
            "[render.miyazaki] k_multi = -0.1 is outside the allowed range [0, 1e6] (1/sr)",
        ),
        (
            "[render.miyazaki]\nphase = \"hg\"",
            "unknown variant `hg`, expected `tables` or `cornette_shanks`",
        ),
        (
            "[render.miyazaki]\nxi = 0.1",
            "[render.miyazaki] xi: --model miyazaki has no such setting",
        ),
        (
            "[render]\nsvs_a = 1.5",
            "[render] svs_a: each model's settings live in its own table: write a = 1.5 under \
             [render.miyazaki]",
        ),
        (
            "[ground]\nalbedo = 1.5",
            "albedo = 1.5 is outside the allowed range [0, 1]",
        ),
        (
            "[haze]\nfield = \"cloud\"\nnumber_density_per_m3 = 1e8\nscale_height_m = 0",
            "[haze] scale_height_m = 0 is outside the allowed range [1, 1e6] (m)",
        ),
        (
            "[haze]\nfield = \"cloud\"\nnumber_density_per_m3 = -1\nscale_height_m = 1000",
            "[haze] number_density_per_m3 = -1 must be finite and > 0",
        ),
    ] {
        let text = format!("{base}\n{keys}\n");
        let e = RenderScene::parse(&text, "test", Path::new("."))
            .expect_err(keys)
            .to_string();
        assert!(e.contains(needle), "{keys}: {e}");
    }
    // A good scene passes the models' checks, a ground albedo included.
    let text = format!("{base}\n[ground]\nalbedo = 0.3\n");
    let scene = RenderScene::parse(&text, "test", Path::new(".")).unwrap();
    scene.check_for("miyazaki").unwrap();
    scene.check_for("riley").unwrap();
    // Riley's model has Rayleigh air only: a haze layer is refused, naming it.
    let text = format!(
        "{base}\n[haze]\nfield = \"cloud\"\nnumber_density_per_m3 = 1e8\nscale_height_m = 1000\n"
    );
    let scene = RenderScene::parse(&text, "test", Path::new(".")).unwrap();
    scene.check_for("miyazaki").unwrap();
    scene.check_for("truth").unwrap();
    let e = scene.check_for("riley").unwrap_err().0;
    assert!(e.contains("[haze] layer (field \"cloud\")"), "{e}");
}
