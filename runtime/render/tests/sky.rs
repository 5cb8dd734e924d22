//! The fast models' sky (`render::sky`, single scattering in closed form, and
//! `render::skylight`, the light it leaves out) against the path-traced truth's air, which
//! scatters any number of times: clear air over a Lambertian ground, no volume, looking up,
//! along the horizon and down at the ground.

use glam::DVec3;
use render::skylight::SkyLight;
use render::truth::{Settings, Tracer};
use render::{Atmosphere, Frame};

#[path = "support/slabs.rs"]
mod slabs;

use slabs::{hg_bins, radiance_along, slab_frame, tables_of};

/// Clear air (the default atmosphere) over a ground of albedo `albedo`, the sun at
/// `elevation` degrees; the slab's droplets are negligible.
fn clear_air(albedo: f64, elevation: f64) -> Frame {
    // The tracer refuses a grid of zeros: a slab of τ 10⁻⁹ just above the ground.
    let mut frame = slab_frame(1e-9);
    frame.atmosphere = Atmosphere::default();
    frame.ground_albedo = albedo;
    frame.sun.elevation_deg = elevation;
    frame
}

/// The truth's radiance per channel along view ray `d` from `eye`: mean and standard error of
/// `n` paths.
fn truth(tracer: &Tracer, eye: DVec3, d: DVec3, n: usize) -> [(f64, f64); 3] {
    radiance_along(tracer, eye, d, n, 7)
}

/// The fast models' radiance along `d` from height `y` (what `shading::compose` gives a pixel
/// without volume): single scattering and the sunlit ground (Eqs. 11–15), plus, with `sky`,
/// the multiply-scattered light.
fn model(frame: &Frame, sky: Option<&SkyLight>, y: f64, d: DVec3) -> [f64; 3] {
    let atm = &frame.atmosphere;
    let sun = frame.sun.direction();
    let k_end = if d.y < 0.0 { y / -d.y } else { f64::INFINITY };
    let single = atm.inscatter(y, d.y, k_end, sun.y, d.dot(sun));
    let multiple = sky.map_or([0.0; 3], |s| s.radiance(y, d, sun));
    let ground: [f64; 3] = if k_end.is_finite() {
        let (lit, t) = (atm.sunlight(0.0, sun.y), atm.transparency(y, d.y, k_end));
        std::array::from_fn(|c| frame.ground_albedo / std::f64::consts::PI * sun.y * lit[c] * t[c])
    } else {
        [0.0; 3]
    };
    std::array::from_fn(|c| single[c] + multiple[c] + ground[c])
}

#[test]
fn the_sky_light_matches_the_truths_air() {
    let tables = tables_of(&hg_bins(&grid::ThetaGrid::new(1.0).unwrap(), 0.5), 1.0, 1.0);
    // A view (elevation above the horizon, azimuth from the sun's) per row.
    let views = [
        (90.0, 0.0),
        (30.0, 0.0),
        (10.0, 180.0),
        (3.0, 90.0),
        (45.0, 135.0),
        (-20.0, 60.0),
    ];
    let mut worst = 0.0f64;
    for &(albedo, elevation) in &[(0.1, 20.0), (0.6, 50.0), (0.0, 6.0)] {
        let frame = clear_air(albedo, elevation);
        let tracer = Tracer::new(&tables, &frame, &Settings::default()).unwrap();
        let start = std::time::Instant::now();
        let sky = SkyLight::of(&frame);
        println!(
            "albedo {albedo} sun {elevation}°: the table in {:.1} ms, {} orders",
            start.elapsed().as_secs_f64() * 1e3,
            sky.orders
        );
        let sun = frame.sun.direction();
        let eye = DVec3::new(0.0, 300.0, 0.0);
        for &(e, a) in &views {
            // Azimuth measured from the sun's horizontal direction.
            let (e, a) = (f64::to_radians(e), f64::to_radians(a));
            let sh = DVec3::new(sun.x, 0.0, sun.z).normalize();
            let side = DVec3::Y.cross(sh);
            let d = (e.cos() * (a.cos() * sh + a.sin() * side) + e.sin() * DVec3::Y).normalize();
            let t = truth(&tracer, eye, d, 40_000);
            let with = model(&frame, Some(&sky), eye.y, d);
            let without = model(&frame, None, eye.y, d);
            for c in 0..3 {
                let (mean, se) = t[c];
                let z = (with[c] - mean) / se;
                println!(
                    "albedo {albedo} sun {elevation:>2}° view ({:>5.1}°, {:>5.1}°) ch {c}: truth \
                     {mean:.4e} ± {:.2} %, single scattering {:+6.1} %, with the sky light \
                     {:+6.2} % ({z:+.1}σ)",
                    e.to_degrees(),
                    a.to_degrees(),
                    100.0 * se / mean,
                    100.0 * (without[c] / mean - 1.0),
                    100.0 * (with[c] / mean - 1.0),
                );
                worst = worst.max(z.abs());
            }
        }
    }
    println!("largest |z| {worst:.2}");
    assert!(worst < 4.0, "the sky light is off the truth by {worst:.2}σ");
}

/// The same through a model's whole composite: Riley's CPU reference renders clear air (its
/// grid a negligible slab 1 m up) over a grey ground, looking along the horizon across the
/// sun's side; every pixel against the truth's radiance along the pixel's ray.
#[test]
fn the_composite_sky_matches_the_truth() {
    let tables = tables_of(&hg_bins(&grid::ThetaGrid::new(1.0).unwrap(), 0.5), 1.0, 1.0);
    let mut frame = clear_air(0.3, 25.0);
    frame.camera.position_m = DVec3::new(0.0, 200.0, 0.0);
    frame.camera.look_at_m = DVec3::new(1000.0, 250.0, -300.0);
    frame.camera.fov_deg = 60.0;
    (frame.width, frame.height) = (8, 6);
    let settings = render::riley::Settings::default();
    let image = render::riley::cpu::render(&tables, &frame, &settings).unwrap();
    let setup = render::riley::Setup::new(&frame, &settings).unwrap();
    let tracer = Tracer::new(&tables, &frame, &Settings::default()).unwrap();
    let (w, h) = (frame.width, frame.height);
    let mut worst = 0.0f64;
    for j in 0..h {
        for i in 0..w {
            let (o, d) = setup.pixel(i, j, w, h);
            let t = truth(&tracer, o, d, 20_000);
            let pixel = image.rgb[i + w * j];
            for c in 0..3 {
                let z = (pixel[c] as f64 - t[c].0) / t[c].1;
                worst = worst.max(z.abs());
                if c == 1 {
                    println!(
                        "pixel ({i}, {j}) d_y {:+.3}: truth {:.4e} ± {:.1} %, composite {:+.2} %",
                        d.y,
                        t[c].0,
                        100.0 * t[c].1 / t[c].0,
                        100.0 * (pixel[c] as f64 / t[c].0 - 1.0)
                    );
                }
            }
        }
    }
    println!("largest |z| {worst:.2}");
    assert!(
        worst < 4.0,
        "the composite's sky is off the truth by {worst:.2}σ"
    );
}
