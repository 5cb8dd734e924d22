//! The uniform box of cloud the grid models' tests light (`max.rs`, `coupled.rs`), how far a
//! render of it is from single scattering, and the cameras their GPU = CPU gathers are seen
//! from.

use std::path::Path;

use render::geometry::box_span;
use render::{Frame, Image, RenderScene};
use runtime::Tables;
use runtime::sample;

/// A uniform 4³ box of the field "cloud" of `fields`' scene, 1 km wide, 5 km ahead, of optical
/// depth `tau` across (green), the sun at `elevation` degrees, 32² pixels, 32³ voxels.
#[allow(dead_code)]
pub fn uniform_box(
    tables: &Tables,
    dir: &Path,
    fields: &str,
    tau: f64,
    sky: bool,
    elevation: f64,
) -> Frame {
    let cloud = tables.field("cloud").unwrap();
    let density = tau / 1000.0 / cloud.sigma_ext_m2[1];
    let ones: Vec<u8> = (0..64).flat_map(|_| 1f32.to_le_bytes()).collect();
    std::fs::write(dir.join("ones.f32"), ones).unwrap();
    let text = box_scene(
        fields,
        ("ones.f32", 4, density),
        (32, 32),
        (elevation, 160.0),
        sky,
    );
    RenderScene::parse(&text, "box", dir)
        .unwrap()
        .frame(tables)
        .unwrap()
}

/// The scene text of a 1 km box of the field "cloud" of `fields`, 5 km ahead of a camera with a
/// 20° view: its density file `file` of n³ values times `density` (per m³), `size`² pixels on
/// `grid`³ voxels, the sun at (`elevation`, `azimuth`) degrees, a black ground.
#[allow(dead_code)]
pub fn box_scene(
    fields: &str,
    (file, n, density): (&str, usize, f64),
    (size, grid): (usize, usize),
    (elevation, azimuth): (f64, f64),
    sky: bool,
) -> String {
    format!(
        r#"{fields}
[render]
width = {size}
height = {size}
grid_resolution = {grid}

[camera]
position_m = [0, 1500, 0]
look_at_m = [0, 1500, 5000]
fov_deg = 20

[sun]
elevation_deg = {elevation}
azimuth_deg = {azimuth}

[sky]
enabled = {sky}

[ground]
albedo = 0.0

[[volume]]
field = "cloud"
shape = "grid"
number_density_per_m3 = {density}
file = "{file}"
dims = [{n}, {n}, {n}]
min_m = [-500, 1000, 4500]
max_m = [500, 2000, 5500]
"#
    )
}

/// Worst relative difference of `image` (a render of `frame`, a [`uniform_box`]) from single
/// scattering of the sun with the exact phase function, over the pixels whose chord is
/// ≥ 500 m, and how many pixels that is.
#[allow(dead_code)]
pub fn single_scatter_error(tables: &Tables, frame: &Frame, image: &Image) -> (f64, usize) {
    let cloud = tables.field("cloud").unwrap();
    let eye = frame.camera.position_m;
    let (forward, right, up) = frame.camera.axes().unwrap();
    let tan_half = frame.camera.tan_half_fov();
    let light = -frame.sun.direction();
    let (mut checked, mut worst) = (0, 0f64);
    for j in 0..frame.height {
        for i in 0..frame.width {
            let d = render::camera::pixel_ray(
                (forward, right, up),
                tan_half,
                (i, j),
                (frame.width, frame.height),
            );
            let Some((t0, t1)) = box_span(frame.grid.min_m, frame.grid.max_m, eye, d) else {
                continue;
            };
            let chord = t1 - t0;
            if chord < 500.0 {
                continue;
            }
            let p1 = sample::ams(cloud, tables.theta_step_deg, 1.0, -light.dot(d));
            for c in 0..3 {
                // The rasterized grid's optical depth along the chord, by fine quadrature.
                let steps = 2000;
                let tau = (0..steps)
                    .map(|s| {
                        let t = t0 + (s as f64 + 0.5) / steps as f64 * chord;
                        frame.grid.sample(eye + t * d)[0]
                    })
                    .sum::<f64>()
                    * cloud.sigma_ext_m2[c]
                    * chord
                    / steps as f64;
                let want = p1[c] * cloud.albedo[c] * (1.0 - (-tau).exp());
                let got = f64::from(image.rgb[i + frame.width * j][c]);
                worst = worst.max(((got - want) / want).abs());
            }
            checked += 1;
        }
    }
    (worst, checked)
}

/// The soft ball's cameras for a gather's GPU = CPU check: its own, one from the side, and an
/// orthographic one (each pixel its own origin) 1.4 km wide at its own place.
#[allow(dead_code)]
pub fn cameras() -> [([f64; 3], render::camera::Projection); 3] {
    use render::camera::Projection;
    [
        ([0.0, 500.0, -2500.0], Projection::Perspective),
        ([-1800.0, 300.0, -1500.0], Projection::Perspective),
        (
            [0.0, 500.0, -2500.0],
            Projection::Orthographic { width_m: 1400.0 },
        ),
    ]
}

/// The largest relative difference between each pixel of `frame` seen by an orthographic
/// camera 1.4 km wide (`gather` renders a frame) and a one-pixel perspective image from that
/// pixel's point of the image plane looking along the view direction: each orthographic pixel
/// is the radiance along one direction at one place. Also the largest relative spread of the
/// orthographic image's green (so a camera that ignored each pixel's origin would show).
#[allow(dead_code)]
pub fn orthographic_against_single_rays(
    frame: &Frame,
    gather: impl Fn(&Frame) -> Image,
) -> (f64, f64) {
    use render::camera::{Camera, Projection};
    let mut ortho = frame.clone();
    ortho.camera.projection = Projection::Orthographic { width_m: 1400.0 };
    let (w, h) = (ortho.width, ortho.height);
    let image = gather(&ortho);
    let axes = ortho.camera.axes().unwrap();
    let mut worst: f64 = 0.0;
    for j in 0..h {
        for i in 0..w {
            let (origin, d) = ortho.camera.pixel(axes, (i, j), (w, h));
            assert_eq!(d, axes.0, "one direction for every pixel");
            let mut one = ortho.clone();
            one.camera = Camera {
                position_m: origin,
                look_at_m: origin + d,
                fov_deg: 30.0,
                projection: Projection::Perspective,
            };
            (one.width, one.height) = (1, 1);
            let ray = gather(&one);
            for c in 0..3 {
                let (a, b) = (image.rgb[i + w * j][c] as f64, ray.rgb[0][c] as f64);
                worst = worst.max((a - b).abs() / b.abs().max(1e-30));
            }
        }
    }
    let green: Vec<f64> = image.rgb.iter().map(|p| p[1] as f64).collect();
    let (lo, hi) = green.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &g| {
        (lo.min(g), hi.max(g))
    });
    (worst, (hi - lo) / hi)
}
