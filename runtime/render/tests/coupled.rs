//! The `coupled` model: its budget balances (a white furnace: every bit of sunlight that enters
//! leaves or is absorbed), its thin limit is single scattering, its GPU gather is its CPU
//! reference in f32, a dense ball agrees with a stored truth image within the measured error,
//! and bad settings and a solve that does not converge are refused.

use std::path::Path;

use render::coupled::{Diffuse, Emergent, Settings, Split, gather, light};
use render::lighting::beam::{BeamState, Depth, PeakFrom, beam_sweep};
use render::{Frame, RenderScene};
use runtime::Tables;

#[path = "../../tests/common/mod.rs"]
mod common;
#[path = "support/slabs.rs"]
mod slabs;
#[path = "support/uniform_box.rs"]
mod support;

use common::bake;

fn fields() -> String {
    common::scene("coupled", 8, common::CLOUD)
}

fn uniform_box(tables: &Tables, dir: &Path, tau: f64, elevation: f64) -> Frame {
    support::uniform_box(tables, dir, &fields(), tau, false, elevation)
}

/// The soft-ball fixture of cloud, `tau` through its centre, the sun 20° up at `azimuth`,
/// 32³ voxels, 24² pixels, no sky, a black ground (the sweep's case, smaller).
fn ball(tables: &Tables, tau: f64, azimuth: f64) -> Frame {
    ball_on(tables, tau, azimuth, 32)
}

/// [`ball`] on `grid`³ voxels.
fn ball_on(tables: &Tables, tau: f64, azimuth: f64, grid: usize) -> Frame {
    let (text, base) = common::soft_ball(&fields());
    let mut scene = RenderScene::parse(&text, "ball", &base).unwrap();
    scene.volumes[0].number_density_per_m3 =
        tau / (0.666 * 1000.0 * tables.field("cloud").unwrap().sigma_ext_m2[1]);
    (scene.width, scene.height, scene.grid_resolution) = (24, 24, grid);
    scene.sun.azimuth_deg = azimuth;
    scene.frame(tables).unwrap()
}

/// With the sun straight down on a uniform box of cloud (albedo 1 − 10⁻⁶ … 1), the sunlight
/// that enters leaves in the beam, is absorbed from it, or feeds the diffusion (exactly: the
/// sweep's steps telescope), and the diffusion sends out or absorbs all of its source (to the
/// solver's tolerance): reflected + transmitted + absorbed = incident.
#[test]
fn the_budget_balances_in_a_white_furnace() {
    let (tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    for tau in [2.0, 16.0] {
        let frame = uniform_box(&tables, tmp.path(), tau, 90.0);
        let settings = Settings {
            diffusion_tolerance: 1e-9,
            max_diffusion_iterations: 2000,
            diffuse: Diffuse::Diffusion,
            ..Settings::default()
        };
        let lighting = light::light(&tables, &frame, &settings).unwrap();
        let b = &lighting.report.budget;
        for c in 0..3 {
            let beam = b.buffer_out[c] + b.buffer_absorbed[c] + b.dropped[c];
            let diffusion = b.diffusion_out[c] + b.diffusion_absorbed[c];
            let total = b.buffer_out[c] + b.buffer_absorbed[c] + diffusion;
            eprintln!(
                "τ {tau} channel {c}: beam out {:.4}, absorbed {:.2e}, dropped {:.4}; diffusion \
                 source {:.4}, out {:.4}, absorbed {:.2e}; out + absorbed − incident {:.2e}",
                b.buffer_out[c],
                b.buffer_absorbed[c],
                b.dropped[c],
                b.diffusion_source[c],
                b.diffusion_out[c],
                b.diffusion_absorbed[c],
                total - 1.0
            );
            assert!(b.dropped[c] > 0.1, "τ {tau}: little light dropped");
            // The beam's partition is exact up to rounding (measured ≤ 3e-16).
            assert!(
                (beam - 1.0).abs() < 1e-12,
                "τ {tau} channel {c}: beam {beam}"
            );
            // The sky is off: the diffusion's source is the dropped sunlight.
            assert!((b.diffusion_source[c] - b.dropped[c]).abs() < 1e-12);
            // The solve's balance at a relative residual of 1e-9 (measured ≤ 2e-9).
            assert!(
                (diffusion - b.diffusion_source[c]).abs() < 1e-7 * b.diffusion_source[c],
                "τ {tau} channel {c}: the diffusion sends out and absorbs {diffusion}, its \
                 source is {}",
                b.diffusion_source[c]
            );
        }
    }
}

/// The sunlit ground lights the volume from below: with no sky and a nearly empty ball (τ
/// 10⁻⁵, so nothing shadows the ground), a Lambertian ground of albedo a under the sun at
/// elevation e adds a sin e E/(2π) to every voxel's mean skylight (1/4π of the lower
/// hemisphere's 2π sr of radiance a E sin e/π), and nothing with a black ground.
#[test]
fn the_ground_lights_the_volume_from_below() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let mut frame = ball(&tables, 1e-5, 90.0);
    let settings = Settings::default();
    let black = light::light(&tables, &frame, &settings).unwrap();
    frame.ground_albedo = 0.3;
    let lit = light::light(&tables, &frame, &settings).unwrap();
    let sine = 20f64.to_radians().sin();
    let mut worst: f64 = 0.0;
    for (b, l) in black.sky_mean.iter().zip(&lit.sky_mean) {
        for c in 0..3 {
            let want = 0.3 * sine * frame.sun.irradiance[c] / (2.0 * std::f64::consts::PI);
            assert_eq!(b[c], 0.0);
            worst = worst.max(((l[c] - b[c]) - want).abs() / want);
        }
    }
    eprintln!("ground light: worst relative difference {worst:.2e}");
    assert!(worst < GROUND_LIGHT, "{worst:e}");
}

/// The ground's light's worst relative error, just above the measured 6.0·10⁻⁶ (the ball's
/// own τ 10⁻⁵ attenuates it).
const GROUND_LIGHT: f64 = 1e-5;

/// A Gaussian blob of cloud, e^{−r²/2s²} with s = 0.12 of its 1 km box (clear air at the
/// faces: e^{−8.7} there), `tau` through its centre, the sun 20° up at the side, on `grid`³
/// voxels (from a 96³ file written into `dir`), no sky, a black ground.
fn blob(tables: &Tables, dir: &Path, tau: f64, grid: usize) -> Frame {
    let (n, s) = (96usize, 0.12f64);
    // The same file for every optical depth: written by the first call.
    let file = dir.join("blob.f32");
    if !file.exists() {
        let mut bytes = Vec::with_capacity(4 * n * n * n);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let r2: f64 = [i, j, k]
                        .iter()
                        .map(|&x| ((x as f64 + 0.5) / n as f64 - 0.5).powi(2))
                        .sum();
                    bytes.extend_from_slice(&((-r2 / (2.0 * s * s)).exp() as f32).to_le_bytes());
                }
            }
        }
        std::fs::write(&file, bytes).unwrap();
    }
    // Through the centre ∫ e^{−x²/2s²} dx = s √(2π) of the box.
    let cloud = tables.field("cloud").unwrap();
    let density = tau / (1000.0 * s * (2.0 * std::f64::consts::PI).sqrt()) / cloud.sigma_ext_m2[1];
    let text = support::box_scene(
        &fields(),
        ("blob.f32", n, density),
        (8, grid),
        (20.0, 90.0),
        false,
    );
    RenderScene::parse(&text, "blob", dir)
        .unwrap()
        .frame(tables)
        .unwrap()
}

/// The transport's light is conserved: in a blob of cloud whose box's faces are clear air (its
/// albedo 1 − 10⁻⁶ … 1), what leaves the box of the outermost voxel centres plus what is
/// absorbed in it equals what the sources in it (the dropped sunlight) emit, to the
/// discretization's error, at τ 2 and 16 on 32³ voxels.
#[test]
fn the_transport_conserves_energy() {
    let (tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    for (tau, tolerance) in [(2.0, TRANSPORT_BALANCE.0), (16.0, TRANSPORT_BALANCE.1)] {
        let frame = blob(&tables, tmp.path(), tau, 32);
        let settings = Settings {
            transport_tolerance: 1e-5,
            max_transport_iterations: 100,
            ..Settings::default()
        };
        let lighting = light::light(&tables, &frame, &settings).unwrap();
        let r = &lighting.report;
        for (c, b) in r.transport_balance.iter().enumerate() {
            let error = (b.out + b.absorbed - b.source) / b.source;
            eprintln!(
                "τ {tau} channel {c}: source {:.4e}, out {:.4e}, absorbed {:.2e}: out + \
                 absorbed − source {error:+.2e} of the source ({} rounds to {:.1e})",
                b.source, b.out, b.absorbed, r.transport_iterations, r.transport_change
            );
            assert!(b.source > 0.0 && b.out > 0.0);
            assert!(error.abs() < tolerance, "τ {tau} channel {c}: {error:e}");
        }
    }
}

/// The transport's |imbalance| at τ 2 and 16, just above the measured −4.94·10⁻³ and
/// −6.09·10⁻³ (every channel; converged to a change of 10⁻⁵): the sweeps' discretization,
/// falling with the voxel size (green, τ 2: −1.25 / −0.50 / −0.21 % at 16³ / 32³ / 64³).
/// Read on the grid's faces with their whole areas, as until 2026-12-05, the flux half a voxel
/// inside was counted over more than the whole sphere (+2.96 % at 32³; the soft ball +1.7 %).
const TRANSPORT_BALANCE: (f64, f64) = (0.0052, 0.0064);

/// Worst relative difference of a `coupled` render of the uniform box of optical depth `tau`
/// from single scattering, over the pixels whose chord is ≥ 500 m.
fn thin_box_error(tables: &Tables, dir: &Path, tau: f64, settings: &Settings) -> (f64, usize) {
    let frame = uniform_box(tables, dir, tau, 30.0);
    let lighting = light::light(tables, &frame, settings).unwrap();
    let image = gather::gather(tables, &frame, settings, &lighting).unwrap();
    support::single_scatter_error(tables, &frame, &image)
}

/// As the box thins, the image tends to single scattering of the sun with the exact phase
/// function, every candidate: the beam's δ-scaling and the diffusion's light are O(τ), so the
/// difference falls a hundredfold from τ = 10⁻³ to 10⁻⁵.
#[test]
fn a_thin_box_gives_single_scattering() {
    let (tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let diffusion = Settings {
        diffuse: Diffuse::Diffusion,
        ..Settings::default()
    };
    let candidates = [
        ("δ-M, transport", Settings::default()),
        ("δ-Eddington, P1", diffusion),
        (
            "hemisphere",
            Settings {
                split: Split::Hemisphere,
                ..diffusion
            },
        ),
        (
            "isotropic",
            Settings {
                emergent: Emergent::Isotropic,
                ..diffusion
            },
        ),
    ];
    for (what, settings) in candidates {
        let (e3, checked) = thin_box_error(&tables, tmp.path(), 1e-3, &settings);
        let (e5, _) = thin_box_error(&tables, tmp.path(), 1e-5, &settings);
        eprintln!(
            "{what}: {checked} pixels, worst relative difference from single scattering \
             {e3:.2e} at τ = 1e-3, {e5:.2e} at τ = 1e-5"
        );
        assert!(checked > 200, "only {checked} pixels crossed the box");
        // Measured 3.5e-6 (δ-Eddington, isotropic) and 5.1e-6 (hemisphere).
        assert!(e5 < 6e-6, "{what}: {e5:e}");
        assert!(e3 > 50.0 * e5, "{what}: {e3:e} vs {e5:e}");
    }
}

/// The GPU tests' scene: the τ 30 soft ball side-lit over a ground of albedo 0.3, the sky on.
fn lit_ball(tables: &Tables) -> Frame {
    let mut frame = ball(tables, 30.0, 70.0);
    frame.ground_albedo = 0.3;
    frame.atmosphere = render::Atmosphere::default();
    frame
}

/// The gather on the GPU (`coupled::gpu`, f32, lavapipe in CI) equals the CPU reference's from
/// the same lighting: a τ 30 soft ball side-lit over a lit ground with the sky on, for the
/// transport (its moments), the diffusion alone and the hemisphere split (Riley's n and
/// Ams_{n+1}), from two cameras and an orthographic one; with the transport, the sun's single scattering blurred by the
/// cloud's forward peak (`coupled::peak`) in and out.
#[test]
fn the_gpu_gather_equals_the_cpu_reference() {
    let Some(gpu) = common::gpu() else { return };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let mut frame = lit_ball(&tables);
    // Lifted 400 m off the ground, so that the composite's air below it is in its shadow
    // (shading::air_shadow) and the sky light takes part.
    frame.grid.min_m.y += 400.0;
    frame.grid.max_m.y += 400.0;
    let on_gpu = GatherOnGpu::new(&gpu, &tables);
    let diffusion = Settings {
        diffuse: Diffuse::Diffusion,
        ..Settings::default()
    };
    let hemisphere = Settings {
        split: Split::Hemisphere,
        ..diffusion
    };
    // The transport's 75 moments per voxel, fewer directions to keep the test short; and on
    // 2³ blocks, its moments on a 16³ grid inside the frame's 32³.
    let transport = Settings {
        directions: 32,
        ..Settings::default()
    };
    let blocks = Settings {
        transport_coarsening: 2,
        ..transport
    };
    for settings in [transport, blocks, diffusion, hemisphere] {
        // Each lighting's buffers stay on the GPU for its second camera.
        let lighting = std::sync::Arc::new(light::light(&tables, &frame, &settings).unwrap());
        let on = lighting.report.transport_dims;
        assert_eq!(
            on,
            match settings.transport_coarsening {
                2 => [16; 3],
                _ if settings.diffuse == Diffuse::Transport => [32; 3],
                _ => on,
            }
        );
        // The blur takes part with the transport: the cloud's peak is resolved by the draft
        // bake's 0.18° samples, and the cone beyond it holds part of the split's f.
        let blurred = lighting
            .report
            .peaks
            .iter()
            .any(|&(_, _, share, cone)| share > 0.1 && cone > 0.05);
        assert_eq!(
            blurred,
            settings.diffuse == Diffuse::Transport,
            "{:?}",
            lighting.report.peaks
        );
        for (camera, projection) in support::cameras() {
            frame.camera.position_m = glam::DVec3::from_array(camera);
            frame.camera.projection = projection;
            let gather = (&tables, &frame, &settings);
            let (worst, t) = on_gpu.matches_cpu(gather, &lighting, "coupled gather");
            eprintln!(
                "{:?} {:?} transport grid {on:?} camera {camera:?} {projection:?}: worst |GPU − CPU| \
                 {worst:.2} of the tolerance; gather {:.1} ms on the GPU, upload {:.1} ms",
                settings.diffuse,
                settings.split,
                1e3 * t.frame,
                1e3 * t.upload
            );
        }
    }
}

/// A lighting whose transport ran on the GPU carries its moments' buffer, and the GPU gather on
/// that device reads them there: the image is the one gathered from the moments read back
/// (bit for bit: the same f32 values), and it does not change when the read-back moments are
/// zeroed, which changes the image of a lighting without the buffer.
#[test]
fn the_gpu_gather_reads_the_transports_moments_in_place() {
    let Some(gpu) = common::gpu() else { return };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = lit_ball(&tables);
    let on_gpu = GatherOnGpu::new(&gpu, &tables);
    let pipelines = render::lighting::Pipelines::default();
    let settings = Settings {
        directions: 32,
        transport_coarsening: 2,
        per_sun: render::lighting::Place::Gpu,
        ..Settings::default()
    };
    let lit = light::light_on(&tables, &frame, &settings, &(), Some(pipelines.on(&gpu))).unwrap();
    assert!(lit.sh_on_gpu.is_some());
    let draw = |lighting: light::Lighting| {
        let lighting = std::sync::Arc::new(lighting);
        let (image, _) = (on_gpu.renderer)
            .gather(
                &gpu,
                &tables,
                &on_gpu.uploaded,
                &frame,
                &settings,
                &lighting,
            )
            .unwrap();
        image
    };
    let zeroed = |mut l: light::Lighting| {
        l.sh.iter_mut().for_each(|m| m.fill(0.0));
        l
    };
    let uploaded_sh = light::Lighting {
        sh_on_gpu: None,
        ..lit.clone()
    };
    let in_place = draw(lit.clone());
    assert_eq!(in_place.rgb, draw(uploaded_sh.clone()).rgb);
    assert_eq!(in_place.rgb, draw(zeroed(lit)).rgb);
    assert_ne!(in_place.rgb, draw(zeroed(uploaded_sh)).rgb);
}

/// Each step of a relight on the GPU drawn by the GPU gather (the lighting's other buffers kept
/// from the step before, the moments read in place) equals the CPU gather of that step's
/// lighting (its moments read back for it), as one lighting's does
/// (`the_gpu_gather_equals_the_cpu_reference`); the relight itself reads its moments back once,
/// when it converges.
#[test]
fn the_gpu_gather_draws_each_step_of_a_relight() {
    let Some(gpu) = common::gpu() else { return };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = ball_on(&tables, 8.0, 90.0, 16);
    let on_gpu = GatherOnGpu::new(&gpu, &tables);
    let pipelines = render::lighting::Pipelines::default();
    let settings = Settings {
        directions: 32,
        transport_tolerance: 1e-3,
        per_sun: render::lighting::Place::Gpu,
        ..Settings::default()
    };
    let mut relight = light::Relight::new(&tables, &frame, &settings, None).unwrap();
    let (mut drawn, mut rounds) = (0, None);
    loop {
        let on = Some(pipelines.on(&gpu));
        let done = relight
            .advance(&tables, (on, &()), Some(std::time::Duration::ZERO))
            .unwrap();
        // A step mid-round shows the lighting drawn at the round's start again.
        let new_round = rounds != relight.rounds();
        rounds = relight.rounds();
        if let Some(lighting) = relight.current().filter(|_| new_round) {
            // From the first iteration on (step 3), the moments are on the GPU, and only there
            // until the relight has converged.
            assert_eq!(lighting.sh_on_gpu.is_some(), relight.steps() >= 3);
            assert_eq!(lighting.sh.is_empty(), relight.steps() >= 3 && !done);
            if done {
                // Read back once, at the end, though each call ran one step: the other
                // readbacks are the solves' flags and the change's sums.
                let t = lighting.report.transport_traffic;
                let moments = moments_bytes(&lighting.report);
                assert!(
                    t.bytes_read <= moments + 256 * (t.readbacks - 1) as u64,
                    "{t:?}"
                );
            }
            let lighting = std::sync::Arc::new(lighting);
            let gather = (&tables, &frame, &settings);
            let (worst, _) = on_gpu.matches_cpu(gather, &lighting, "coupled gather of a step");
            eprintln!(
                "step {}: worst |GPU − CPU| {worst:.2} of the tolerance",
                relight.steps()
            );
            drawn += 1;
        }
        if done {
            break;
        }
    }
    assert!(drawn >= 3, "{drawn} steps drawn");
}

/// An orthographic camera (`projection = "orthographic"`): each pixel of the CPU gather is the
/// radiance along the view direction from its own point of the image plane, the one-pixel
/// perspective image from there (the GPU's equals the CPU's in the test above).
#[test]
fn an_orthographic_pixel_is_the_ray_from_its_point_of_the_image_plane() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let mut frame = lit_ball(&tables);
    (frame.width, frame.height) = (6, 4);
    let settings = Settings {
        directions: 32,
        ..Settings::default()
    };
    let lighting = light::light(&tables, &frame, &settings).unwrap();
    let (worst, spread) = support::orthographic_against_single_rays(&frame, |f| {
        gather::gather(&tables, f, &settings, &lighting).unwrap()
    });
    eprintln!("orthographic vs single rays: worst {worst:.1e}, the image's spread {spread:.2}");
    // Measured 0 (bit for bit); the bound allows the one-pixel camera's direction, look_at −
    // position normalized, to differ from the view direction in its last bits.
    assert!(worst < 1e-6, "worst relative difference {worst:.2e}");
    assert!(spread > 0.1, "the image is almost uniform ({spread:.3})");
}

/// The per-sun passes on the GPU (the transport's sweeps, `lighting::transport_gpu`, the skylight's,
/// `lighting::sky_gpu`, and the diffusion solves, `diffusion_gpu`; f32, lavapipe in CI) give the
/// CPU reference's lighting:
/// the τ 30 soft ball side-lit over a lit ground with the sky on, 32 directions on a 16³
/// transport grid (to keep the test short on lavapipe), every source iteration's round swept
/// and accelerated on the GPU (the convergence test on the CPU, f64, as in the reference).
#[test]
fn the_gpu_lighting_equals_the_cpu_reference() {
    let Some(gpu) = common::gpu() else { return };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = lit_ball(&tables);
    let pipelines = render::lighting::Pipelines::default();
    let settings = Settings {
        directions: 32,
        transport_coarsening: 2,
        ..Settings::default()
    };
    let cpu_light = light::light(&tables, &frame, &settings).unwrap();
    let on = pipelines.on(&gpu);
    let gpu_light = light::light_on(&tables, &frame, &settings, &(), Some(on)).unwrap();
    assert_eq!(
        cpu_light.report.transport_iterations,
        gpu_light.report.transport_iterations
    );
    // The worst difference per channel, as a share of that channel's largest mean radiance:
    // the diffusion's I_0 and I_1 (of I_0), the transport's moments (of φ_00).
    let h = render::lighting::transport::HARMONICS;
    let (mut diffusion, mut transport): (f64, f64) = (0.0, 0.0);
    for c in 0..3 {
        let scale = cpu_light.i0.iter().fold(0.0f64, |a, v| a.max(v[c].abs()));
        for (a, b) in cpu_light.i0.iter().zip(&gpu_light.i0) {
            diffusion = diffusion.max((a[c] - b[c]).abs() / scale);
        }
        for (a, b) in cpu_light.p1.iter().zip(&gpu_light.p1) {
            for k in 3 * c..3 * c + 3 {
                diffusion = diffusion.max((a[k] - b[k]).abs() / scale);
            }
        }
        let scale = cpu_light
            .sh
            .iter()
            .fold(0.0f64, |a, m| a.max(m[c * h].abs()));
        for (a, b) in cpu_light.sh.iter().zip(&gpu_light.sh) {
            for k in c * h..(c + 1) * h {
                transport = transport.max((a[k] - b[k]).abs() / scale);
            }
        }
    }
    assert_eq!(gpu_light.report.sky_on, gpu.describe());
    let scale = cpu_light
        .sky_mean
        .iter()
        .flatten()
        .fold(0.0f64, |a, v| a.max(*v));
    let sky_worst = cpu_light
        .sky_mean
        .iter()
        .flatten()
        .zip(gpu_light.sky_mean.iter().flatten())
        .fold(0.0f64, |a, (x, y)| a.max((x - y).abs() / scale));
    eprintln!("skylight: worst |GPU − CPU| {sky_worst:.2e} of the largest mean");
    assert!(sky_worst < GPU_SKY_TOLERANCE, "{sky_worst:e}");
    let r = (&gpu_light.report, &cpu_light.report);
    eprintln!(
        "diffusion: CG iterations {:?} (CPU {:?}), worst |GPU − CPU| {diffusion:.2e}, {:.2} s \
         (CPU {:.2} s); transport: {} iterations (CPU {}), worst {transport:.2e}, {:.2} s on {} \
         (CPU {:.2} s); the transport on the GPU sent and read back {:?}",
        r.0.iterations,
        r.1.iterations,
        r.0.diffusion_s,
        r.1.diffusion_s,
        r.0.transport_iterations,
        r.1.transport_iterations,
        r.0.transport_s,
        r.0.transport_on,
        r.1.transport_s,
        r.0.transport_traffic,
    );
    assert!(diffusion < GPU_LIGHTING_TOLERANCE.0, "{diffusion}");
    assert!(transport < GPU_LIGHTING_TOLERANCE.1, "{transport}");
    // The iteration stayed on the GPU: two submissions and two readbacks a round (one more of
    // each where a solve outlasts its first chunk; measured: 10 and 11 for 5 rounds, the moments
    // read back once at the end), and of the moments' bytes only that last readback.
    let t = r.0.transport_traffic;
    assert_eq!(t.rounds, r.0.transport_iterations);
    assert!(
        t.submits <= 3 * t.rounds && t.readbacks <= 3 * t.rounds + 1,
        "{t:?}"
    );
    let moments = moments_bytes(r.0);
    assert!(
        t.bytes_read < moments + 1024 * t.rounds as u64,
        "{t:?}, moments {moments} B"
    );
}

/// The bytes of a lighting's transport moments on the GPU (f32, whole rows of four a voxel).
fn moments_bytes(report: &light::CoupledReport) -> u64 {
    let voxels: usize = report.transport_dims.iter().product();
    (4 * render::lighting::transport::PER_VOXEL.div_ceil(4) * 4 * voxels) as u64
}

/// The coupled model's GPU gather on an adapter, with the tables uploaded there.
struct GatherOnGpu<'a> {
    gpu: &'a runtime::gpu::Gpu,
    uploaded: runtime::gpu::GpuTables,
    renderer: render::coupled::gpu::Renderer,
}

impl<'a> GatherOnGpu<'a> {
    fn new(gpu: &'a runtime::gpu::Gpu, tables: &Tables) -> Self {
        let uploaded =
            runtime::gpu::GpuTables::upload(gpu, tables, runtime::gpu::TexelFormat::F32).unwrap();
        let renderer = render::coupled::gpu::Renderer::new(gpu, &uploaded);
        Self {
            gpu,
            uploaded,
            renderer,
        }
    }

    /// Gathers `lighting` on the GPU and on the CPU and asserts they agree within the f32
    /// tolerance (measured on lavapipe: within 1.10 × (10⁻⁵ |CPU| + 10⁻⁶ of the 99th
    /// percentile), T within the max gather's 6·10⁻⁶, f32 against f64): the worst difference
    /// as a share of the tolerance, and the GPU's timings.
    fn matches_cpu(
        &self,
        (tables, frame, settings): (&Tables, &Frame, &Settings),
        lighting: &std::sync::Arc<light::Lighting>,
        what: &str,
    ) -> (f64, render::gpu::Timings) {
        let cpu_image = gather::gather(tables, frame, settings, lighting).unwrap();
        let (gpu_image, t) = self
            .renderer
            .gather(self.gpu, tables, &self.uploaded, frame, settings, lighting)
            .unwrap();
        let worst = common::assert_gpu_matches_cpu(
            (&gpu_image.rgb, &gpu_image.transparency),
            (&cpu_image.rgb, &cpu_image.transparency),
            (1.2e-5, 1.2e-6, 6e-6),
            what,
        );
        (worst, t)
    }
}

/// The worst differences above, the diffusion's and the transport's (measured on lavapipe:
/// 4.24·10⁻⁵ and 1.30·10⁻⁶, the transport's iteration kept on the GPU and its acceleration
/// solved there to the CPU's relative residual of 10⁻²; 2.55·10⁻⁵ when the GPU solved it to
/// 10⁻³ and the CPU's to 10⁻²). Each diffusion solve stops anywhere within its tolerance
/// (relative residual 10⁻⁶), so the two lightings differ by that. The GPU beam's losses (f32,
/// 10⁻⁷ of a voxel's own) reach the diffusion's flux I_1 through 1/κ_tr where the ball is thin
/// — there |I_1| is up to 20× the largest I_0 (the gather limits it to I_0) — hence the
/// diffusion's larger figure: solved to 10⁻⁹ it stays 4.35·10⁻⁵ with the GPU beam, 2.34·10⁻⁶
/// with the CPU's.
const GPU_LIGHTING_TOLERANCE: (f64, f64) = (4.5e-5, 1.5e-6);

/// The GPU sweep tests' grid: 9 × 5 × 7 voxels of 40 × 20 × 40 m (every axis leads some
/// directions), empty (the tests give β per voxel, from 2.5·10⁻⁸ to 1 per metre by [`wobble`]).
fn uneven_grid() -> render::DensityGrid {
    let dims = [9, 5, 7];
    render::DensityGrid {
        min_m: glam::DVec3::new(-100.0, 0.0, 50.0),
        max_m: glam::DVec3::new(260.0, 100.0, 330.0),
        dims,
        data: vec![[0.0; render::MAX_FIELDS]; dims[0] * dims[1] * dims[2]],
        periodic: false,
    }
}

/// A lumpy value in [0, 1] per voxel `i` and quantity `k`.
fn wobble(i: usize, k: usize) -> f64 {
    0.5 + 0.5 * ((i * 7 + k * 13) as f64 * 0.61).sin()
}

/// The beam's sweep on the GPU (`lighting::beam_gpu`) gives `lighting::beam::beam_sweep`'s beam,
/// peak depth and losses in f32: a lumpy medium on an uneven grid, τ per voxel from 10⁻⁶ to
/// 40, the split's f, g and the peak's share varying per voxel, the sun travelling most along
/// each axis in turn, both ways.
#[test]
fn the_gpu_beam_equals_the_cpu_sweep() {
    let Some(gpu) = common::gpu() else { return };
    let grid = uneven_grid();
    let n = grid.data.len();
    let medium: Vec<render::lighting::beam::BeamMedium> = (0..n)
        .map(|i| {
            let ext: [f64; 3] = std::array::from_fn(|c| 10f64.powf(-7.6 + 7.6 * wobble(i, c)));
            let f: [f64; 3] = std::array::from_fn(|c| 0.3 + 0.4 * wobble(i, c + 3));
            render::lighting::beam::BeamMedium {
                ext,
                sca: std::array::from_fn(|c| ext[c] * (0.9 + 0.1 * wobble(i, c + 6))),
                f,
                g: std::array::from_fn(|c| f[c] + (0.95 - f[c]) * wobble(i, c + 9)),
                share: 0.5 * wobble(i, 12),
            }
        })
        .collect();
    let sweeper = render::lighting::beam_gpu::BeamSweeper::new(&gpu);
    let mut worst: [f64; 3] = [0.0; 3];
    for l in [
        glam::DVec3::new(0.8, -0.5, 0.3),
        glam::DVec3::new(-0.3, 0.9, -0.2),
        glam::DVec3::new(0.4, -0.3, -0.85),
    ] {
        let l = l.normalize();
        let want = beam_sweep(&[], &grid, &medium, l, (PeakFrom::Medium, Depth::Peak));
        let got = sweeper.sweep(&gpu, &grid, &medium, l).unwrap();
        // Each quantity against its largest value: the beam (of the sunlight, 1), the peak
        // depth D, and the losses per metre.
        let beam = |s: &BeamState| s.intensity.to_vec();
        let depth = |s: &BeamState| vec![s.depth];
        let losses = |s: &BeamState| [s.dropped, s.forward, s.loss].concat();
        let parts: [&Quantity; 3] = [&beam, &depth, &losses];
        for (p, part) in parts.iter().enumerate() {
            let top = want
                .iter()
                .flat_map(part)
                .fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(top > 0.0, "part {p} is zero everywhere");
            for (w, g) in want.iter().zip(&got) {
                for (a, b) in part(w).iter().zip(part(g)) {
                    worst[p] = worst[p].max((b - a).abs() / top);
                }
            }
        }
    }
    eprintln!(
        "GPU beam: worst beam {:.2e}, peak depth {:.2e}, losses {:.2e} of their largest",
        worst[0], worst[1], worst[2]
    );
    assert!(worst.iter().all(|&w| w < GPU_BEAM_TOLERANCE), "{worst:?}");
}

/// One quantity of the beam's state, as the numbers compared.
type Quantity = dyn Fn(&BeamState) -> Vec<f64>;

/// The GPU beam's worst difference from the CPU's, of the largest value of each quantity,
/// just above the measured (lavapipe, f32): beam 8.44·10⁻⁷, peak depth 7.95·10⁻⁷, losses
/// 5.91·10⁻⁷ (8.66, 9.03 and 6.19·10⁻⁷ with the point one layer back as index + shift in f32).
const GPU_BEAM_TOLERANCE: f64 = 9e-7;

/// The skylight's sweeps on the GPU (`lighting::sky_gpu`) give `lighting::sky::sky_sweeps`' mean
/// skylight and flux in f32: a lumpy medium on an uneven grid (every axis leads some
/// directions), τ per voxel from 10⁻⁶ to 40 (the light past the thick voxels e^{−40}), each
/// of the 32 directions with its own radiance.
#[test]
fn the_gpu_skylight_equals_the_cpu_sweeps() {
    let Some(gpu) = common::gpu() else { return };
    let grid = uneven_grid();
    let n = grid.data.len();
    let ext: Vec<[f64; 3]> = (0..n)
        .map(|i| std::array::from_fn(|c| 10f64.powf(-7.6 + 7.6 * wobble(i, c))))
        .collect();
    let lit: Vec<(glam::DVec3, [f64; 3])> = render::lighting::sky::sky_directions()
        .into_iter()
        .enumerate()
        .map(|(d, s)| (s, std::array::from_fn(|c| 1.0 + wobble(d, c))))
        .collect();
    let want = render::lighting::sky::sky_sweeps(&grid, &ext, &lit);
    let got = render::lighting::sky_gpu::SkySweeper::new(&gpu)
        .sweep(&gpu, &grid, &ext, &lit)
        .unwrap();
    let scale = want.mean.iter().flatten().fold(0.0f64, |a, v| a.max(*v));
    let (mut mean, mut flux): (f64, f64) = (0.0, 0.0);
    for i in 0..n {
        for c in 0..3 {
            mean = mean.max((got.mean[i][c] - want.mean[i][c]).abs() / scale);
            flux = flux.max((got.flux[i][c] - want.flux[i][c]).abs().max_element() / scale);
        }
    }
    eprintln!(
        "GPU skylight: worst mean {mean:.2e}, flux {flux:.2e} of the largest mean {scale:.3}"
    );
    assert!(scale > 0.1, "the sky reaches the voxels: {scale}");
    assert!(mean.max(flux) < GPU_SKY_TOLERANCE, "{mean:e} {flux:e}");
}

/// The GPU skylight's worst difference from the CPU's, of the largest mean skylight, just
/// above the measured (lavapipe, f32): 2.56·10⁻⁷ on the lumpy grid, 1.67·10⁻⁷ in the lit ball
/// (4.85·10⁻⁷ and 3.67·10⁻⁷ with the point one layer back formed as index + shift in f32).
const GPU_SKY_TOLERANCE: f64 = 3e-7;

/// The diffusion solve on the GPU (`diffusion_gpu`: f32 conjugate gradients and V-cycles
/// inside an f64 refinement) reaches the CPU reference's solution: a ball of varying κ_tr
/// (optical depths 0.3–30 per voxel) with absorption, an isotropic and a directed source, on a
/// 40 × 33 × 27 grid (five levels).
#[test]
fn the_gpu_diffusion_solve_equals_the_cpu_reference() {
    let Some(gpu) = common::gpu() else { return };
    let dims = [40usize, 33, 27];
    let n = dims.iter().product();
    let (mut kappa_tr, mut kappa_a) = (vec![0.0; n], vec![0.0; n]);
    let (mut q0, mut q1) = (vec![0.0; n], vec![[0.0; 3]; n]);
    for i in 0..n {
        let c = [
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        ];
        let u: [f64; 3] = std::array::from_fn(|a| (c[a] as f64 + 0.5) / dims[a] as f64 - 0.5);
        let r2 = u.iter().map(|v| v * v).sum::<f64>();
        if r2 < 0.2 {
            let k = 0.3 + 30.0 * (1.0 - r2 / 0.2) * (1.0 + 0.5 * (7.0 * u[0]).sin());
            kappa_tr[i] = k;
            kappa_a[i] = 1e-3 * k;
            q0[i] = 1.0 + u[1];
            q1[i] = [0.2 * k * u[2], 0.1, -0.3];
        }
    }
    let problem = render::lighting::diffusion::Problem {
        dims,
        periodic: false,
        h: [1.0, 1.2, 0.9],
        kappa_tr,
        kappa_a,
        q0,
        q1,
    };
    let solver = render::lighting::diffusion_gpu::Solver::new(&gpu);
    let cpu_s = render::lighting::diffusion::solve(&problem, 1e-6, 500).unwrap();
    let gpu_s = solver.solve_problem(&gpu, &problem, (1e-6, 500)).unwrap();
    let worst = worst_share(&cpu_s.i0, &gpu_s.i0);
    eprintln!(
        "diffusion: {} unknowns, {} levels; CPU {} iterations to {:.1e} in {:.3} s, GPU {} to \
         {:.1e} in {:.3} s; worst |GPU − CPU| {worst:.2e} of the largest I_0",
        cpu_s.unknowns,
        gpu_s.levels,
        cpu_s.iterations,
        cpu_s.residual,
        cpu_s.seconds,
        gpu_s.iterations,
        gpu_s.residual,
        gpu_s.seconds
    );
    assert!(gpu_s.residual < 1e-6, "{}", gpu_s.residual);
    assert!(worst < GPU_DIFFUSION_TOLERANCE, "{worst}");
    // The extremes: a grid one voxel thick (a single level, the coarsest's smoothing alone)
    // and one without unknowns.
    let line = render::lighting::diffusion::Problem {
        dims: [1, 1, 9],
        periodic: false,
        h: [1.0; 3],
        kappa_tr: vec![2.0; 9],
        kappa_a: vec![0.1; 9],
        q0: vec![1.0; 9],
        q1: vec![[0.0, 0.0, 0.5]; 9],
    };
    let cpu_s = render::lighting::diffusion::solve(&line, 1e-6, 500).unwrap();
    let gpu_s = solver.solve_problem(&gpu, &line, (1e-6, 500)).unwrap();
    let worst = worst_share(&cpu_s.i0, &gpu_s.i0);
    eprintln!("a line of voxels: worst |GPU − CPU| {worst:.2e} of the largest I_0");
    assert!(worst < GPU_DIFFUSION_TOLERANCE, "a line of voxels: {worst}");
    let empty = render::lighting::diffusion::Problem {
        kappa_tr: vec![0.0; 9],
        ..line
    };
    let s = solver.solve_problem(&gpu, &empty, (1e-6, 500)).unwrap();
    assert!(s.i0.iter().all(|&v| v == 0.0) && s.iterations == 0 && s.unknowns == 0);
}

/// The largest |a − b| over the largest |a|.
fn worst_share(a: &[f64], b: &[f64]) -> f64 {
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs() / scale))
}

/// The GPU solve's worst difference above (measured on lavapipe: 1.82·10⁻⁷ on the ball,
/// 1.79·10⁻⁷ on the line; both solutions within a relative residual of 10⁻⁶ of the system's).
const GPU_DIFFUSION_TOLERANCE: f64 = 2.2e-7;

/// One round of the transport's sweeps on the GPU equals the CPU's (`transport::sweep_once`)
/// on grids at the extremes of their shape — one voxel thick along each axis in turn, and a
/// long thin one — with a medium from clear to optically thick per voxel (τ 10⁻⁴ … 30), every
/// source on, from moments that are not a solution.
#[test]
fn one_round_of_gpu_sweeps_equals_the_cpu_round_on_thin_grids() {
    use render::lighting::transport::{DEGREE, Medium, PER_VOXEL, sweep_once};
    let Some(gpu) = common::gpu() else { return };
    let sweeper = render::lighting::transport_gpu::Sweeper::new(&gpu);
    let dirs = render::lighting::lattice::fibonacci_directions(48);
    let mut worst: f64 = 0.0;
    for dims in [[1usize, 5, 7], [6, 1, 4], [3, 5, 1], [2, 2, 40]] {
        let n: usize = dims.iter().product();
        let grid = render::DensityGrid {
            min_m: glam::DVec3::ZERO,
            max_m: glam::DVec3::new(1.0, 1.3, 0.8) * 10.0,
            dims,
            data: vec![[0.0; render::MAX_FIELDS]; n],
            periodic: false,
        };
        // A deterministic spread of values per voxel.
        let v = |i: usize, k: usize| ((i * 7 + k * 13) % 17) as f64 / 17.0;
        let medium = Medium {
            ext: (0..n)
                .map(|i| [0, 1, 2].map(|c| 1e-5 * 10f64.powf(6.5 * v(i, c))))
                .collect(),
            sca: vec![[0.0; 3]; n],
            chi: (0..n)
                .map(|i| {
                    [0, 1, 2].map(|c| {
                        std::array::from_fn(|l| if l == 0 { 1.0 } else { 0.8 * v(i, c + l) - 0.2 })
                    })
                })
                .collect::<Vec<[[f64; DEGREE + 1]; 3]>>(),
            sun: (0..n)
                .map(|i| [0, 1, 2].map(|c| 0.01 * v(i, c + 3)))
                .collect(),
            l: glam::DVec3::new(0.3, -0.8, 0.52).normalize(),
            sky: (0..n)
                .map(|i| [0, 1, 2].map(|c| [0.01 * v(i, c), 0.002, -0.001, 0.003]))
                .collect(),
        };
        let medium = Medium {
            sca: medium.ext.iter().map(|e| e.map(|x| 0.9 * x)).collect(),
            ..medium
        };
        let m: Vec<[f64; PER_VOXEL]> = (0..n)
            .map(|i| std::array::from_fn(|k| 0.1 * v(i, k) - 0.02))
            .collect();
        let cpu_round = sweep_once(&grid, &medium, &m, &dirs);
        let sweeps = sweeper.prepare(&gpu, &grid, &medium, &dirs).unwrap();
        let gpu_round = sweeps.round(&m).unwrap();
        worst = worst.max(worst_share(
            cpu_round.as_flattened(),
            gpu_round.as_flattened(),
        ));
    }
    eprintln!("one round on thin grids: worst |GPU − CPU| {worst:.2e} of the largest moment");
    assert!(worst < GPU_ROUND_TOLERANCE, "{worst}");
}

/// The round's worst difference above (measured on lavapipe: 4.15·10⁻⁷; 2.63·10⁻⁶ with the
/// point one layer back formed as index + shift in f32, 3.94·10⁻⁵ while the f32 step took its
/// series only below τ = 10⁻²).
const GPU_ROUND_TOLERANCE: f64 = 5e-7;

/// The stored truth of the dense case: the soft ball at τ 32, the sun 48° from the view.
const DENSE_TRUTH: &str = "tests/data/coupled_dense_truth.exr";

/// The dense case: 24² pixels, the model's CPU reference.
fn dense(tables: &Tables) -> Frame {
    ball(tables, 32.0, 45.0)
}

/// Writes the stored truth of [`dense`] (run once; `cargo test -p photometeor-render --test
/// coupled -- --ignored store_the_dense_truth`): the path tracer to 1 % noise, 65 536 spp at
/// most, with the same draft bake the tests make.
#[test]
#[ignore]
fn store_the_dense_truth() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = dense(&tables);
    let settings = render::truth::Settings {
        spp: 65_536,
        target_noise: 0.01,
        ..render::truth::Settings::default()
    };
    let truth = render::truth::render(&tables, &frame, &settings, &()).unwrap();
    eprintln!(
        "truth: {} spp, noise {:.2} %, {:.0} s",
        truth.spp,
        truth.noise * 100.0,
        truth.seconds
    );
    let mut extra: Vec<(String, Vec<f32>)> = (0..3)
        .map(|c| {
            (
                format!("stderr.{}", ["R", "G", "B"][c]),
                truth.std_error.iter().map(|e| e[c]).collect(),
            )
        })
        .collect();
    extra.push(("stderr.Y".into(), truth.luma_error.clone()));
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(DENSE_TRUTH);
    truth.image.write_exr_with(&path, extra).unwrap();
}

/// A dense ball (τ 32) against its stored truth: the bias and the median per-pixel error
/// within what was measured when the model was chosen (docs/coupled), for the transport (the
/// default) and the diffusion alone.
#[test]
fn a_dense_ball_agrees_with_its_stored_truth() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = dense(&tables);
    let truth =
        render::error_map::read_frame(&Path::new(env!("CARGO_MANIFEST_DIR")).join(DENSE_TRUTH))
            .unwrap();
    let diffusion = Settings {
        diffuse: Diffuse::Diffusion,
        ..Settings::default()
    };
    let coarse = Settings {
        transport_coarsening: 2,
        ..Settings::default()
    };
    for (settings, (bias, median)) in [
        (Settings::default(), TRANSPORT_DENSE),
        (coarse, COARSE_DENSE),
        (diffusion, DIFFUSION_DENSE),
    ] {
        let lighting = light::light(&tables, &frame, &settings).unwrap();
        let image = gather::gather(&tables, &frame, &settings, &lighting).unwrap();
        let model = render::error_map::Frame {
            image,
            std_error: None,
            luma_error: None,
        };
        let (report, _) =
            render::error_map::compare(&truth, &model, render::error_map::Pixels::Volume).unwrap();
        eprintln!(
            "{:?} (coarsening {}): dense ball against its stored truth: bias {:+.1} %, median \
             {:.1} %, p95 {:.1} %, truth noise {:.1} % ({} transport iterations on {:?}, last \
             change {:.1e})",
            settings.diffuse,
            settings.transport_coarsening,
            100.0 * report.bias,
            100.0 * report.median_rel_error,
            100.0 * report.p95_rel_error,
            100.0 * report.truth_noise,
            lighting.report.transport_iterations,
            lighting.report.transport_dims,
            lighting.report.transport_change,
        );
        assert!(report.pixels > 200);
        assert!(
            report.bias.abs() < bias,
            "{:?}: bias {}",
            settings.diffuse,
            report.bias
        );
        assert!(report.median_rel_error < median, "{:?}", settings.diffuse);
    }
}

/// The dense case's |bias| and median error with the transport are below these, just above
/// the measured −0.18 % and 4.91 % (−0.1 % and 5.4 % before the phase function's moments were
/// read from the tables' bins, 5.3 % before the forward peak's blur; the model is
/// deterministic and the truth stored, so they do not scatter; a change to the model that
/// moves them must say so here).
const TRANSPORT_DENSE: (f64, f64) = (0.003, 0.050);
/// The same with `transport_coarsening = 2` (the transport on the 16³ blocks of the 32³
/// grid, the gather looking its moments up there): measured −1.06 % and 5.95 % (−1.0 % and
/// 6.1 % before the moments from the bins, −1.5 % and 6.7 % with the moments interpolated to
/// the 32³ grid first, −1.6 % before the forward peak's blur).
const COARSE_DENSE: (f64, f64) = (0.012, 0.061);
/// The same with `diffuse = "diffusion"`: measured −13.1 % and 11.6 %.
const DIFFUSION_DENSE: (f64, f64) = (0.14, 0.125);

/// Settings out of range and a solve that cannot converge within its cap are refused, naming
/// the key, the value and the range (or the residual and the cap), before any image.
#[test]
fn bad_settings_and_a_solve_over_its_cap_are_refused() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = ball(&tables, 30.0, 45.0);
    for (settings, want) in [
        (
            Settings {
                diffusion_tolerance: 0.5,
                ..Settings::default()
            },
            "diffusion_tolerance = 0.5 is outside the allowed range [1e-12, 0.1]",
        ),
        (
            Settings {
                max_diffusion_iterations: 0,
                ..Settings::default()
            },
            "max_diffusion_iterations = 0 is outside the allowed range [1, 100000]",
        ),
        (
            Settings {
                max_diffusion_iterations: 1,
                diffusion_tolerance: 1e-12,
                ..Settings::default()
            },
            "did not converge",
        ),
        (
            Settings {
                directions: 8,
                ..Settings::default()
            },
            "directions = 8 is outside the allowed range [16, 1024]",
        ),
        (
            Settings {
                transport_tolerance: 0.0,
                ..Settings::default()
            },
            "transport_tolerance = 0 is outside the allowed range [1e-6, 0.5]",
        ),
        (
            Settings {
                max_transport_iterations: 0,
                ..Settings::default()
            },
            "max_transport_iterations = 0 is outside the allowed range [1, 1000]",
        ),
        (
            Settings {
                split: Split::Hemisphere,
                ..Settings::default()
            },
            "diffuse = \"transport\" needs the default source",
        ),
        (
            Settings {
                transport_coarsening: 3,
                ..Settings::default()
            },
            "transport_coarsening = 3 is not one of 1, 2, 4",
        ),
        (
            Settings {
                directions: 16,
                max_transport_iterations: 1,
                transport_tolerance: 1e-6,
                ..Settings::default()
            },
            "the transport did not converge",
        ),
    ] {
        let e = light::light(&tables, &frame, &settings).unwrap_err().0;
        assert!(e.contains(want), "{e}");
    }
}

/// Counts the progress a render tells.
#[derive(Default)]
struct Told(std::sync::atomic::AtomicUsize);

impl render::model::Progress for Told {
    fn update(&self, _done: u64, _total: u64, _message: &str) {
        self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
}

/// `per_view = "gpu"` refuses, before the lighting starts, a grid whose lighting would exceed
/// the adapter's storage-binding limit, naming the buffer, its size and the limit (`auto` would
/// gather such a view on the CPU). Checked where the limit is within a 160³ grid's reach
/// (lavapipe's 128 MiB in CI); an adapter with more says so and checks nothing.
#[test]
fn per_view_gpu_refuses_a_lighting_past_the_adapters_limit_before_any_work() {
    let Some(gpu) = common::gpu() else { return };
    let limit = gpu.device.limits().max_storage_buffer_binding_size;
    // The lighting's 80 bytes a voxel past the limit: the smallest cube that does it.
    let side = (1..=160).find(|&n| 80 * (n as u64).pow(3) > limit);
    let Some(side) = side else {
        eprintln!("the adapter binds {limit} bytes: no grid up to 160³ exceeds it");
        return;
    };
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let (text, base) = common::soft_ball(&fields());
    let mut scene = RenderScene::parse(&text, "ball", &base).unwrap();
    (scene.width, scene.height, scene.grid_resolution) = (8, 8, side);
    let frame = scene.frame(&tables).unwrap();
    let settings = render::ModelSettings::Coupled(Settings {
        per_view: render::lighting::Place::Gpu,
        ..Settings::default()
    });
    let prepared = settings.prepare(&gpu, &tables).unwrap();
    let told = Told::default();
    let job = render::Job {
        tables: &tables,
        frame: &frame,
        progress: &told,
        lighting: None,
    };
    let started = std::time::Instant::now();
    let err = settings
        .render(&job, render::On::Gpu(&gpu, &prepared))
        .expect_err("refused")
        .to_string();
    eprintln!(
        "{side}³ grid: refused in {:.3} s: {err}",
        started.elapsed().as_secs_f64()
    );
    assert!(
        err.contains("per_view = \"gpu\"")
            && err.contains("the lighting's")
            && err.contains(&format!(
                "storage-binding limit of {:.1} MiB",
                limit as f64 / 1048576.0
            )),
        "{err}"
    );
    assert_eq!(told.0.load(std::sync::atomic::Ordering::Relaxed), 0);
}

/// A setting out of range is named once with its table: `[render.coupled] directions = 8 …`
/// (the model's check and the parser each put the table's name before it, which read
/// "[render.coupled] [render.coupled] directions").
#[test]
fn a_bad_setting_names_its_table_once() {
    let table: toml::Table = toml::from_str("directions = 8").unwrap();
    let e = render::ModelSettings::parse("coupled", &table)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("[render.coupled] directions = 8 is outside the allowed range"),
        "{e}"
    );
    assert_eq!(e.matches("[render.coupled]").count(), 1, "{e}");
}

/// The memory estimate counts the transport on the grid it runs on: the automatic coarsening
/// (blocks of 4 at 256 along the longest side) or the set one, not every voxel of the grid.
#[test]
fn the_memory_estimate_counts_the_transport_on_its_coarsened_grid() {
    let dims = [256, 140, 256];
    let transport = |coarsening: i64| {
        let mut table = toml::Table::new();
        table.insert(
            "transport_coarsening".into(),
            toml::Value::Integer(coarsening),
        );
        let model = render::ModelSettings::parse("coupled", &table).unwrap();
        model
            .memory(1, dims)
            .into_iter()
            .find(|n| n.what.contains("discrete-ordinates transport"))
            .expect("the transport's part")
            .bytes
    };
    let per_voxel = render::coupled::TRANSPORT_MEMORY_PER_VOXEL;
    assert_eq!(transport(1), 256 * 140 * 256 * per_voxel);
    assert_eq!(transport(2), 128 * 70 * 128 * per_voxel);
    assert_eq!(transport(0), 64 * 35 * 64 * per_voxel);
    assert_eq!(transport(4), transport(0));
}

/// A scene deeper than the transport converges at within its default iteration cap is refused
/// before the lighting, naming its optical depth and the limit; the diffusion alone still
/// lights it. On a coarse grid the limit is lower (the product of the scene's and the densest
/// voxel's optical depths): the ball at τ 200 on 16³ voxels (product ≈ 3 750) is refused, and
/// with the check lifted (the cap raised by one) its transport indeed diverges, while τ 160
/// (≈ 2 400) is taken and converges.
#[test]
fn a_scene_deeper_than_the_transport_converges_at_is_refused_before_the_lighting() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let limit = render::coupled::MAX_OPTICAL_DEPTH;
    let frame = ball(&tables, 1.5 * limit, 90.0);
    let e = match light::light(&tables, &frame, &Settings::default()) {
        Ok(_) => panic!("lit a ball of optical depth {}", 1.5 * limit),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("the scene's optical depth is ")
            && e.contains(&format!("more than the {limit}")),
        "{e}"
    );
    let diffusion = Settings {
        diffuse: Diffuse::Diffusion,
        ..Settings::default()
    };
    assert!(light::light(&tables, &frame, &diffusion).is_ok());

    let coarse = ball_on(&tables, 200.0, 90.0, 16);
    let e = match light::light(&tables, &coarse, &Settings::default()) {
        Ok(_) => panic!("lit a ball of optical depth 200 on 16³ voxels"),
        Err(e) => e.to_string(),
    };
    let product = render::coupled::MAX_DEPTH_PRODUCT;
    assert!(
        e.contains("across its densest transport voxel: their product")
            && e.contains(&format!("more than the {product}")),
        "{e}"
    );
    let lifted = Settings {
        max_transport_iterations: Settings::default().max_transport_iterations + 1,
        ..Settings::default()
    };
    match light::light(&tables, &coarse, &lifted) {
        Ok(_) => panic!("the transport converged at a product the check refuses"),
        Err(e) => assert!(e.to_string().contains("did not converge"), "{e}"),
    }
    let taken = ball_on(&tables, 160.0, 90.0, 16);
    assert!(light::light(&tables, &taken, &Settings::default()).is_ok());
}

/// A periodic volume (`periodic = true`): DISORT's g = 0.85 slab at τ 4 (ω 1 and 0.99; a
/// scene's `kind = "hg"` field, baked), 1 m thick, as a box 1 m wide of 16³ voxels repeating
/// without end, seen by an orthographic camera along each of DISORT's radiances (reflected at
/// μ 1 and μ 0.8/φ 90°, transmitted likewise): every pixel is the infinite slab's radiance.
/// The sun at 30° travels most along z, so its beam's sweep, like half the transport's
/// directions, wraps and repeats until it settles.
#[test]
fn a_periodic_slab_is_disorts_infinite_slab() {
    let mut worst: f64 = 0.0;
    for omega in [1.0, 0.99] {
        let lobe = format!(
            "\n[[field]]\nname = \"cloud\"\nkind = \"hg\"\ng = 0.85\nextinction_m2 = 1\n\
             albedo = {omega}\n"
        );
        let (_tmp, dir) = bake(&common::scene("periodic", 4, &lobe));
        let tables = Tables::open(&dir).unwrap();
        let case = slabs::disort_case("hg085", 4.0, omega);
        for r in slabs::disort_radiances(&case) {
            let out = slabs::outgoing(r.mu, r.phi, r.up);
            let mut frame = slabs::orthographic_slab(4.0, out, (3, 2));
            slabs::periodic_slab(&mut frame, 1.0);
            frame.grid.dims = [16, 16, 16];
            frame.grid.data = vec![[4.0, 0.0, 0.0, 0.0]; 16 * 16 * 16];
            let settings = Settings::default();
            let lighting = light::light(&tables, &frame, &settings).unwrap();
            let image = gather::gather(&tables, &frame, &settings, &lighting).unwrap();
            let first = image.rgb[0][1];
            for (p, l) in image.rgb.iter().enumerate() {
                let l = f64::from(l[1]);
                let error = (l - r.want) / r.want;
                worst = worst.max(error.abs());
                assert!(
                    (l - f64::from(first)).abs() <= 1e-6 * l.abs(),
                    "ω {omega} {} μ {} φ {}: pixel {p} {l} differs from pixel 0's {first}",
                    r.list,
                    r.mu,
                    r.phi
                );
                if p == 0 {
                    eprintln!(
                        "ω {omega} {} μ {} φ {}: {l:.5} vs DISORT {:.5} ({:+.2} %)",
                        r.list,
                        r.mu,
                        r.phi,
                        r.want,
                        error * 100.0
                    );
                }
            }
        }
    }
    eprintln!("worst {:.2} %", worst * 100.0);
    assert!(worst < 0.03, "worst {:.2} %", worst * 100.0);
}

/// A new sun started from the last sun's moments (`light_from` with the last lighting, what a
/// viewer's relight does through its lighting cache): the transport converges to the cold
/// start's light, for a sun moved by 1°, 5° and 30° in azimuth around the soft ball at τ 8
/// (16³ voxels); at the default tolerance a move of 1° or 5° takes fewer iterations. The warm
/// start solves no diffusion (its only use with the transport is the cold start): the image
/// drawn from it is the cold start's to the transport's tolerance (1.1–1.8·10⁻⁴ rms at 10⁻⁴),
/// the diffusion's field plays no part in it, and the beam's part of the energy budget is the
/// same.
#[test]
fn a_warm_start_from_the_last_sun_converges_to_the_cold_start() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let tight = Settings {
        transport_tolerance: 1e-4,
        ..Settings::default()
    };
    for settings in [Settings::default(), tight] {
        let last = light::light(&tables, &ball_on(&tables, 8.0, 90.0, 16), &settings).unwrap();
        for moved in [1.0, 5.0, 30.0] {
            let frame = ball_on(&tables, 8.0, 90.0 + moved, 16);
            let cold = light::light(&tables, &frame, &settings).unwrap();
            let warm =
                light::light_from(&tables, &frame, &settings, &(), (None, Some(&last))).unwrap();
            assert!(warm.report.transport_warm && !cold.report.transport_warm);
            assert!(warm.report.diffusion_skipped && !cold.report.diffusion_skipped);
            let (w, c) = (&warm.report.budget, &cold.report.budget);
            assert_eq!(
                (w.incident, w.buffer_out, w.buffer_absorbed, w.dropped),
                (c.incident, c.buffer_out, c.buffer_absorbed, c.dropped)
            );
            // The mean radiance's moment φ_00 per channel, rms over the grid.
            let difference = mean_radiance_error(&warm, &cold);
            let draw = |l: &light::Lighting| gather::gather(&tables, &frame, &settings, l).unwrap();
            let drawn = draw(&warm);
            let image = image_difference(&drawn, &draw(&cold));
            // The diffusion's field plays no part in the image beside the transport's moments.
            let mut diffused = warm.clone();
            (diffused.i0, diffused.p1) = (cold.i0.clone(), cold.p1.clone());
            assert!(draw(&diffused).rgb == drawn.rgb);
            eprintln!(
                "tolerance {:.0e}, sun moved {moved}°: iterations cold {}, warm {}; warm − \
                 cold {difference:.1e} (rms, relative), image {image:.1e}",
                settings.transport_tolerance,
                cold.report.transport_iterations,
                warm.report.transport_iterations
            );
            if settings.transport_tolerance < 1e-3 {
                assert!(difference < 1e-4, "moved {moved}°: {difference:e}");
                assert!(image < 2e-4, "moved {moved}°: image {image:e}");
            } else if moved < 10.0 {
                let (w, c) = (
                    warm.report.transport_iterations,
                    cold.report.transport_iterations,
                );
                assert!(w < c, "moved {moved}°: {w} iterations warm, {c} cold");
            }
        }
    }
}

/// A relight in steps (`Relight::advance` with a budget of zero: one step a call, what a viewer
/// does between frames) reaches the lighting one call reaches, on the CPU and on the GPU (whose
/// iteration stays there between the steps, each round cut into parts of one dispatch or one
/// solver iteration), to rounding (the solvers' parallel sums: 3.6·10⁻¹⁵ measured with the
/// other tests running beside it, 0 alone); from its second step on, each step's lighting is a
/// whole one that the gather draws (mid-round, the last whole round's), and its mean radiance
/// moves towards the converged one's (soft ball at τ 8, 16³ voxels, at a tolerance of 10⁻⁴).
#[test]
fn k_amortized_steps_equal_one_full_relight() {
    let (_tmp, dir) = bake(&fields());
    let tables = Tables::open(&dir).unwrap();
    let frame = ball_on(&tables, 8.0, 90.0, 16);
    let settings = Settings {
        transport_tolerance: 1e-4,
        ..Settings::default()
    };
    let gpu = common::gpu();
    let pipelines = render::lighting::Pipelines::default();
    let gpu_settings = Settings {
        directions: 32,
        per_sun: render::lighting::Place::Gpu,
        ..settings
    };
    let mut places = vec![(None, settings)];
    if let Some(gpu) = &gpu {
        places.push((Some(gpu), gpu_settings));
    }
    for (gpu, settings) in places {
        let on = || gpu.map(|g| pipelines.on(g));
        let full = light::light_on(&tables, &frame, &settings, &(), on()).unwrap();
        let mut relight = light::Relight::new(&tables, &frame, &settings, None).unwrap();
        let mut errors = Vec::new();
        // Each round's moments, and the steps that showed them again mid-round.
        let (mut last, mut mid_round): (Option<(usize, Vec<_>)>, _) = (None, 0);
        let zero = Some(std::time::Duration::ZERO);
        while !relight.advance(&tables, (on(), &()), zero).unwrap() {
            if last
                .as_ref()
                .is_some_and(|(r, _)| Some(*r) == relight.rounds())
            {
                mid_round += 1;
                if mid_round % 16 == 1 {
                    // What a frame shows mid-round: the last whole round's lighting (before the
                    // first round, the start as the GPU holds it, in f32).
                    let shown = relight.current().unwrap();
                    let f32s = |m: &[[f64; 75]]| -> Vec<f32> {
                        m.iter().flatten().map(|&v| v as f32).collect()
                    };
                    let before = f32s(&last.as_ref().unwrap().1);
                    assert!(
                        f32s(&shown.moments().unwrap()) == before,
                        "mid-round moments"
                    );
                }
                continue;
            }
            let shown = relight.current();
            assert_eq!(
                shown.is_some(),
                relight.steps() >= 2,
                "step {}",
                relight.steps()
            );
            if let Some(shown) = shown {
                // What a frame shows meanwhile: a whole lighting the gather draws.
                let image = gather::gather(&tables, &frame, &settings, &shown).unwrap();
                assert!(image.rgb.iter().flatten().all(|v| v.is_finite()));
                errors.push(mean_radiance_error(&shown, &full));
                let round = relight.rounds().expect("a whole lighting");
                last = Some((round, shown.moments().unwrap().into_owned()));
            }
        }
        let steps = relight.steps();
        let stepped = relight.finish().unwrap();
        let iterations = full.report.transport_iterations;
        let shown: Vec<String> = errors.iter().map(|e| format!("{e:.1e}")).collect();
        eprintln!(
            "{}: {steps} steps ({iterations} iterations, {mid_round} steps mid-round); the mean \
             radiance's error after each round: {}",
            if gpu.is_some() { "GPU" } else { "CPU" },
            shown.join(", ")
        );
        // On the CPU a step is a round; on the GPU the rounds go in parts.
        assert_eq!(steps, 2 + iterations + mid_round);
        assert_eq!(mid_round > 0, gpu.is_some());
        assert_eq!(stepped.report.transport_iterations, iterations);
        // The same arithmetic; only the solvers' parallel sums may associate differently from
        // one run to the next (rayon splits them as threads steal work).
        let worst = [
            largest_difference(&stepped.buffer, &full.buffer),
            largest_difference(&stepped.i0, &full.i0),
            largest_difference(&stepped.p1, &full.p1),
            largest_difference(&stepped.sh, &full.sh),
        ];
        let shown: Vec<String> = worst.iter().map(|w| format!("{w:.1e}")).collect();
        eprintln!(
            "stepped against one call, largest difference of the buffer, I_0, I_1 and the \
             moments: {}",
            shown.join(", ")
        );
        assert!(worst.iter().all(|w| *w <= 1e-12), "{worst:?}");
        assert!(errors.last().unwrap() < &errors[0], "{errors:?}");
    }
}

/// The rms difference of `a`'s and `b`'s pixels over the channels, relative to `b`'s rms.
fn image_difference(a: &render::Image, b: &render::Image) -> f64 {
    let (mut d, mut t) = (0.0, 0.0);
    for (x, y) in a.rgb.iter().flatten().zip(b.rgb.iter().flatten()) {
        d += f64::from(x - y).powi(2);
        t += f64::from(*y).powi(2);
    }
    (d / t.max(f64::MIN_POSITIVE)).sqrt()
}

/// The largest difference of `a`'s and `b`'s values, relative to `b`'s largest magnitude.
fn largest_difference<const N: usize>(a: &[[f64; N]], b: &[[f64; N]]) -> f64 {
    assert_eq!(a.len(), b.len());
    let (d, scale) = render::lighting::lattice::largest_difference(a, b);
    d / scale.max(f64::MIN_POSITIVE)
}

/// The rms difference of `a`'s and `b`'s mean radiance φ_00 over the grid and channels,
/// relative to `b`'s.
fn mean_radiance_error(a: &light::Lighting, b: &light::Lighting) -> f64 {
    let (a, b) = (a.moments().unwrap(), b.moments().unwrap());
    let (mut d, mut t) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b.iter()) {
        for c in 0..3 {
            let o = c * render::lighting::transport::HARMONICS;
            d += (x[o] - y[o]).powi(2);
            t += y[o] * y[o];
        }
    }
    (d / t).sqrt()
}
