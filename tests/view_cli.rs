//! `photometeor view` in a real window under Xvfb (lavapipe's Vulkan surface): a script moves
//! the sun, switches the model and orbits the camera, and the screenshots are checked; the
//! still view equals `photometeor render` of the same view; an edit of the watched scene into
//! an invalid state is reported with its key and line while the last good scene stays, and so
//! is a bad rewrite of an OpenVDB file the scene reads; no display and a bad script are one
//! line and exit 2.

// Table-driven end-to-end tests read best whole: the 120-line bound on functions
// (clippy.toml) holds for library and binary code.
#![allow(clippy::too_many_lines)]
#![cfg(feature = "view")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
#[path = "common/exr_planes.rs"]
mod exr_planes;
#[path = "common/openvdb.rs"]
mod openvdb;

use common::{photometeor, workdir};
use exr_planes::read_rgba;
use render::error_map::{self, read_frame};

fn gpu_required() -> bool {
    std::env::var("REQUIRE_GPU").as_deref() == Ok("1")
}

fn rainbow() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/rainbow.toml")
}

/// `photometeor view ARGS` under `xvfb-run` in `cwd`, or `None` (skipped) where Xvfb is not
/// installed and no GPU is required.
fn view_command(args: &[&str], cwd: &Path) -> Option<Command> {
    let found = Command::new("xvfb-run")
        .arg("--help")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    if !found {
        assert!(
            !gpu_required(),
            "REQUIRE_GPU=1 but xvfb-run is missing (Debian: xvfb and xauth; scripts/test \
             installs them)"
        );
        eprintln!("skipped: no xvfb-run");
        return None;
    }
    let mut command = Command::new("xvfb-run");
    command
        .args(["-a", "-s", "-screen 0 1024x768x24"])
        .arg(env!("CARGO_BIN_EXE_photometeor"))
        .arg("view")
        .args(args)
        .current_dir(cwd);
    Some(command)
}

/// Whether a failed run only lacked an adapter where none is required (skipped).
fn skipped_without_adapter(out: &Output) -> bool {
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() && stderr.contains("no GPU adapter") && !gpu_required() {
        eprintln!("skipped, no adapter:\n{stderr}");
        return true;
    }
    false
}

/// `view ARGS` under Xvfb in `cwd`, run to its end and asserted to succeed; `None` where it was
/// skipped (no Xvfb, or no adapter where none is required).
fn run_view(args: &[&str], cwd: &Path) -> Option<()> {
    let out = view_command(args, cwd)?.output().unwrap();
    if skipped_without_adapter(&out) {
        return None;
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "view failed:\n{stderr}");
    Some(())
}

/// Waits for `view`'s first shot (`shot` written), for at most 300 s; `false` where it ended
/// skipped for want of an adapter, a panic where it ended otherwise.
fn first_shot(child: &mut std::process::Child, shot: &Path) -> bool {
    let started = Instant::now();
    while !shot.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            let mut stderr = Vec::new();
            if let Some(mut pipe) = child.stderr.take() {
                std::io::Read::read_to_end(&mut pipe, &mut stderr).unwrap();
            }
            let out = Output {
                status,
                stdout: Vec::new(),
                stderr,
            };
            if skipped_without_adapter(&out) {
                return false;
            }
            panic!(
                "view ended ({status}) before its first shot:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "no first shot in 300 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    true
}

/// An 8-bit RGB PNG: width, height, pixels.
fn read_png(path: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let pixels = buf[..info.buffer_size()]
        .chunks(channels)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    (info.width as usize, info.height as usize, pixels)
}

/// The image the window showed: the screenshot cropped to the image's rectangle (its JSON),
/// one window pixel per image pixel at the zoom.
fn shown_image(png: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(png.with_extension("json")).unwrap())
            .unwrap();
    let rect: Vec<usize> = json["image_rect_px"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap().round() as usize)
        .collect();
    let zoom = json["zoom"].as_u64().unwrap() as usize;
    let (w, h) = (rect[2] / zoom, rect[3] / zoom);
    let (ww, _, window) = read_png(png);
    let pixels = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| window[(rect[1] + y * zoom) * ww + rect[0] + x * zoom])
        .collect();
    (w, h, pixels)
}

/// Standard deviation of the pixels' luminance (0–255).
fn spread(pixels: &[[u8; 3]]) -> f64 {
    let y: Vec<f64> = pixels
        .iter()
        .map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64)
        .collect();
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    (y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / y.len() as f64).sqrt()
}

/// Mean |a − b| / mean |b| of the luminance over the pixels where the volume matters in both
/// (1 − A > 1 %).
fn volume_change(a: &[Vec<f32>; 4], b: &[Vec<f32>; 4]) -> f64 {
    let y = |p: &[Vec<f32>; 4], i: usize| {
        0.2126 * p[0][i] as f64 + 0.7152 * p[1][i] as f64 + 0.0722 * p[2][i] as f64
    };
    let mask: Vec<usize> = (0..a[3].len())
        .filter(|&i| a[3][i] < 0.99 && b[3][i] < 0.99)
        .collect();
    assert!(mask.len() > 100, "the rain covers {} pixels", mask.len());
    let diff: f64 = mask.iter().map(|&i| (y(a, i) - y(b, i)).abs()).sum();
    let base: f64 = mask.iter().map(|&i| y(b, i).abs()).sum();
    diff / base
}

#[test]
fn a_scripted_session_moves_the_sun_switches_the_model_orbits_and_its_still_view_equals_render() {
    let cwd = workdir("view-script");
    let scene = rainbow();
    let scene = scene.to_str().unwrap();
    std::fs::write(
        cwd.join("script.toml"),
        "[[step]]\nscreenshot = \"still.png\"\n\n\
         [[step]]\ntruth_spp = 16\ndisplay = \"truth\"\nscreenshot = \"truth.png\"\n\n\
         [[step]]\nsun_elevation_deg = 30\ndisplay = \"model\"\nscreenshot = \"sun.png\"\n\n\
         [[step]]\nmodel = \"miyazaki\"\nscreenshot = \"model.png\"\n\n\
         [[step]]\norbit_deg = [25, 5]\nscreenshot = \"orbit.png\"\n\n\
         [[step]]\nfield_size = { rain = 150 }\nscreenshot = \"size.png\"\n",
    )
    .unwrap();
    let size = ["--width", "64", "--height", "48", "--quality", "draft"];
    let tables = ["--tables", "tables"];
    let mut args = vec![scene];
    args.extend(size);
    args.extend(tables);
    args.extend(["--script", "script.toml", "--screenshot", "end.png"]);
    if run_view(&args, &cwd).is_none() {
        return;
    }

    // Every screenshot shows an image, not a flat colour.
    let shots = ["still", "truth", "sun", "model", "orbit", "size", "end"];
    for name in shots {
        let (w, h, pixels) = shown_image(&cwd.join(format!("{name}.png")));
        assert_eq!((w, h), (64, 48), "{name}");
        let s = spread(&pixels);
        assert!(
            s > 5.0,
            "{name}.png is nearly uniform: luminance spread {s:.2} of 255"
        );
    }

    // The still view is `render`'s frame: the same radiance and, in the window, the same
    // 8-bit pixels as its PNG.
    let mut render_args = vec!["render", scene];
    render_args.extend(size);
    render_args.extend(tables);
    render_args.extend(["--out", "render.exr", "--png", "render.png", "--quiet"]);
    let out = photometeor(&render_args, &cwd);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, _, still) = read_rgba(&cwd.join("still.exr"));
    let (_, _, rendered) = read_rgba(&cwd.join("render.exr"));
    let peak = rendered[1].iter().fold(0f32, |m, v| m.max(v.abs()));
    for c in 0..4 {
        let worst = (0..still[c].len())
            .map(|i| (still[c][i] - rendered[c][i]).abs())
            .fold(0f32, f32::max);
        assert!(
            worst <= 1e-6 * peak.max(1.0),
            "channel {c}: the window's frame differs from render's by {worst:e}"
        );
    }
    let (_, _, shown) = shown_image(&cwd.join("still.png"));
    let (_, _, png) = read_png(&cwd.join("render.png"));
    let worst = shown
        .iter()
        .zip(&png)
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] as i32 - b[c] as i32).abs()))
        .max()
        .unwrap();
    assert!(
        worst <= 1,
        "the window's pixels differ from render's PNG by {worst} of 255"
    );

    // The truth traced from the window is the truth of the view: `render --model truth` with
    // the same samples (and seed) gives the same frame, and the window's error figures are
    // compare-render's.
    let json = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(cwd.join(name)).unwrap()).unwrap()
    };
    let mut truth_args = render_args.clone();
    truth_args.extend(["--model", "truth", "--set", "spp=16"]);
    for (flag, value) in [("--out", "truth-render.exr"), ("--png", "truth-render.png")] {
        let i = truth_args.iter().position(|a| *a == flag).unwrap();
        truth_args[i + 1] = value;
    }
    let out = photometeor(&truth_args, &cwd);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let traced = read_frame(&cwd.join("truth.truth.exr")).unwrap();
    let rendered = read_frame(&cwd.join("truth-render.exr")).unwrap();
    let summary = json("truth.json")["truth"].as_str().unwrap().to_string();
    assert!(summary.contains("16 spp"), "{summary}");
    let sigma = |f: &error_map::Frame, i: usize, c: usize| f.std_error.as_ref().unwrap()[i][c];
    if summary.contains("on the CPU") {
        // The CPU truth is deterministic: the same streams, passes and sums.
        assert_eq!(traced.image.rgb, rendered.image.rgb);
        for i in 0..traced.image.rgb.len() {
            assert_eq!(sigma(&traced, i, 1), sigma(&rendered, i, 1));
        }
    } else {
        // The GPU truth (a real adapter): the window's run and render's, each pixel within
        // 5σ of the other.
        for i in 0..traced.image.rgb.len() {
            let d = (traced.image.rgb[i][1] - rendered.image.rgb[i][1]).abs();
            let s = sigma(&traced, i, 1).hypot(sigma(&rendered, i, 1));
            assert!(d <= 5.0 * s, "pixel {i}: {d} apart, σ {s}");
        }
    }
    let window_report = &json("truth.json")["error_against_truth"];
    assert!(
        window_report["pixels"].as_u64().unwrap() > 100,
        "{window_report}"
    );
    let out = photometeor(
        &["compare-render", "truth.truth.exr", "truth.exr", "--json"],
        &cwd,
    );
    assert!(out.status.success());
    let cli_report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(*window_report, cli_report);
    // The truth on display is not the model's image.
    let (_, _, model_shown) = shown_image(&cwd.join("still.png"));
    let (_, _, truth_shown) = shown_image(&cwd.join("truth.png"));
    assert_ne!(model_shown, truth_shown, "display = truth showed the model");

    // Moving the sun moves the bow: the rain's pixels change.
    let (_, _, sun) = read_rgba(&cwd.join("sun.exr"));
    let moved = volume_change(&sun, &still);
    assert!(
        moved > 0.05,
        "the sun moved 18° and the rain changed by {moved:.3}"
    );
    // The model switch and the orbit change the image and are recorded.
    let (_, _, model) = read_rgba(&cwd.join("model.exr"));
    assert!(volume_change(&model, &sun) > 0.01);
    assert_eq!(json("sun.json")["sun"]["elevation_deg"], 30.0);
    assert_eq!(json("model.json")["model"], "miyazaki");
    assert_ne!(
        json("orbit.json")["camera"]["position_m"],
        json("model.json")["camera"]["position_m"]
    );
    let (_, _, orbited) = shown_image(&cwd.join("orbit.png"));
    let (_, _, before) = shown_image(&cwd.join("model.png"));
    assert_ne!(
        orbited, before,
        "the orbit did not change the window's image"
    );
    // Smaller drops, re-baked in the background and swapped in: the bows change.
    let (_, _, orbit) = read_rgba(&cwd.join("orbit.exr"));
    let (_, _, size) = read_rgba(&cwd.join("size.exr"));
    let resized = volume_change(&size, &orbit);
    assert!(
        resized > 0.01,
        "the drops shrank 500 → 150 µm and the rain changed by {resized:.4}"
    );
    assert!(json("end.json")["frame_seconds_mean"].as_f64().unwrap() > 0.0);
}

/// An EXR's R, G, B and A planes.
type Planes = [Vec<f32>; 4];

/// What a window shows around an edit of its inputs: `view` with `args` (the scene first) and a
/// script of two shots 4 s apart (`before.png`, `after.png`, with their EXRs) runs in `cwd`;
/// `edit` runs once the first shot is written. Its stderr and the two shots' planes, once it
/// has ended successfully; `None` where it was skipped (no xvfb-run, or no adapter where none
/// is required).
fn around_an_edit(
    cwd: &Path,
    args: &[&str],
    edit: impl FnOnce(),
) -> Option<(String, Planes, Planes)> {
    std::fs::write(
        cwd.join("script.toml"),
        "[[step]]\nscreenshot = \"before.png\"\nwait_s = 4\n\n[[step]]\nscreenshot = \"after.png\"\n",
    )
    .unwrap();
    let mut args = args.to_vec();
    args.extend(["--script", "script.toml", "--screenshot", "end.png"]);
    let mut child = view_command(&args, cwd)?
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    if !first_shot(&mut child, &cwd.join("before.json")) {
        return None;
    }
    edit();
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "view failed:\n{stderr}");
    let (_, _, before) = read_rgba(&cwd.join("before.exr"));
    let (_, _, after) = read_rgba(&cwd.join("after.exr"));
    Some((stderr, before, after))
}

#[test]
fn a_scene_edited_into_an_invalid_state_is_reported_with_its_line_and_the_last_good_one_kept() {
    let cwd = workdir("view-watch");
    let good = std::fs::read_to_string(rainbow()).unwrap();
    std::fs::write(cwd.join("scene.toml"), &good).unwrap();
    let (line, _) = good
        .lines()
        .enumerate()
        .find(|(_, l)| l.trim_start().starts_with("elevation_deg"))
        .expect("the rainbow scene gives the sun's elevation");
    let args = [
        "scene.toml",
        "--width",
        "48",
        "--height",
        "36",
        "--quality",
        "draft",
        "--tables",
        "tables",
    ];
    // Once the first shot is written, break the scene: the sun below its range.
    let broken: String = good
        .lines()
        .enumerate()
        .map(|(i, l)| if i == line { "elevation_deg = 120" } else { l })
        .collect::<Vec<_>>()
        .join("\n");
    let Some((stderr, before, after)) = around_an_edit(&cwd, &args, || {
        std::fs::write(cwd.join("scene.toml"), broken).unwrap();
    }) else {
        return;
    };
    assert!(
        stderr.contains("elevation_deg") && stderr.contains(&format!("line {}", line + 1)),
        "the invalid edit is not reported with its key and line:\n{stderr}"
    );
    assert!(stderr.contains("keeps the last good scene"), "{stderr}");
    assert_eq!(before, after, "the window did not keep the last good scene");
}

/// The viewer opens an OpenVDB cloud (a file the OpenVDB library wrote) and watches the file:
/// rewritten with a negative density, it is refused by name and the last good cloud kept.
#[test]
fn a_vdb_cloud_opens_and_a_bad_rewrite_of_its_file_is_refused_with_the_last_good_kept() {
    let cwd = workdir("view-vdb");
    openvdb::write_cases(&cwd.join("library"));
    std::fs::copy(cwd.join("library/dense.vdb"), cwd.join("cloud.vdb")).unwrap();
    let scene = "[scene]\nname = \"vdb\"\nspectral = \"rgb3\"\nn_max = 4\nquality = \"draft\"\n\n\
                 [[field]]\nname = \"cloud\"\nkind = \"cloud\"\n\
                 distribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }\n\n\
                 [render]\ngrid_resolution = 24\n\n\
                 [camera]\nposition_m = [400, 150, -1500]\nlook_at_m = [400, 150, 400]\n\n\
                 [sun]\nelevation_deg = 30\nazimuth_deg = 40\n\n\
                 [[volume]]\nfield = \"cloud\"\nshape = \"vdb\"\nfile = \"cloud.vdb\"\n\
                 number_density_per_m3 = 1e7\n";
    std::fs::write(cwd.join("scene.toml"), scene).unwrap();
    let args = [
        "scene.toml",
        "--model",
        "riley",
        "--width",
        "48",
        "--height",
        "36",
        "--tables",
        "tables",
    ];
    let Some((stderr, before, after)) = around_an_edit(&cwd, &args, || {
        std::fs::copy(cwd.join("library/negative.vdb"), cwd.join("cloud.vdb")).unwrap();
    }) else {
        return;
    };
    assert!(
        stderr.contains("1983 active voxels"),
        "the cloud's voxels not printed:\n{stderr}"
    );
    assert!(
        stderr.contains("cloud.vdb: grid \"density\": value -1 at voxel (10, 2, 15)")
            && stderr.contains("keeps the last good scene"),
        "the bad rewrite is not refused by name:\n{stderr}"
    );
    assert!(before[0].iter().any(|&v| v > 0.0), "a black first view");
    assert_eq!(before, after, "the window did not keep the last good cloud");
}

#[test]
fn no_display_is_one_line_and_exit_2() {
    let cwd = workdir("view-no-display");
    let out = Command::new(env!("CARGO_BIN_EXE_photometeor"))
        .args([
            "view",
            "--quality",
            "draft",
            "--tables",
            "tables",
            "--width",
            "8",
            "--height",
            "8",
        ])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&cwd)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(errors[0].contains("needs a display"), "{stderr}");
    // Refused before anything was baked.
    assert!(!cwd.join("tables").exists(), "{stderr}");
}

/// coupled in the window relights a moved sun in steps (a budget of 1 ms: a frame per source
/// iteration of its transport), drawing each frame from the lighting so far; the shot waits for
/// the converged frame, which is `render`'s of the same view to the transport's tolerance (the
/// window's relight starts from the last sun's moments, `render`'s from the diffusion's).
#[test]
fn coupled_relights_a_moved_sun_in_steps_and_converges_to_renders_frame() {
    let cwd = workdir("view-coupled-steps");
    let text = std::fs::read_to_string(rainbow())
        .unwrap()
        .replace("grid_resolution = 96", "grid_resolution = 24");
    std::fs::write(cwd.join("scene.toml"), &text).unwrap();
    let moved = text.replace("elevation_deg = 12", "elevation_deg = 20");
    assert_ne!(moved, text);
    std::fs::write(cwd.join("moved.toml"), moved).unwrap();
    std::fs::write(
        cwd.join("script.toml"),
        "[[step]]\nscreenshot = \"first.png\"\n\n\
         [[step]]\nsun_elevation_deg = 20\nscreenshot = \"moved.png\"\n",
    )
    .unwrap();
    let size = ["--width", "48", "--height", "36", "--quality", "draft"];
    let common = ["--tables", "tables", "--model", "coupled"];
    let mut args = vec!["scene.toml"];
    args.extend(size);
    args.extend(common);
    args.extend(["--step-budget-ms", "1", "--script", "script.toml"]);
    args.extend(["--screenshot", "end.png"]);
    if run_view(&args, &cwd).is_none() {
        return;
    }
    let json = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(cwd.join(name)).unwrap()).unwrap()
    };
    // The moved sun's frames: drawn while the lighting converged, the last one converged.
    let j = json("moved.json");
    let frames = j["frames"].as_u64().unwrap();
    let converging = j["converging_frames"].as_u64().unwrap();
    eprintln!("after the sun moved: {frames} frames, {converging} of them converging");
    assert!(converging >= 1 && frames == converging + 1, "{j}");
    for shot in ["first.json", "moved.json", "end.json"] {
        let figures = json(shot)["figures"].to_string();
        assert!(!figures.contains("relight steps"), "{shot}: {figures}");
    }
    let mut render_args = vec!["render", "moved.toml"];
    render_args.extend(size);
    render_args.extend(common);
    render_args.extend(["--out", "render.exr", "--quiet"]);
    let out = photometeor(&render_args, &cwd);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, _, shown) = read_rgba(&cwd.join("moved.exr"));
    let (_, _, rendered) = read_rgba(&cwd.join("render.exr"));
    let peak = rendered[1].iter().fold(0f32, |m, v| m.max(v.abs()));
    let worst = (0..3)
        .flat_map(|c| (0..shown[c].len()).map(move |i| (c, i)))
        .map(|(c, i)| (shown[c][i] - rendered[c][i]).abs() / peak)
        .fold(0f32, f32::max);
    eprintln!("the converged window frame against render's: worst {worst:.2e} of the peak");
    assert!(worst < 5e-5, "worst {worst:e} of the peak");
}

/// A step budget of zero, a negative one, NaN or one past a minute is refused with its range
/// before anything is baked or opened.
#[test]
fn a_step_budget_out_of_range_is_refused_before_any_work() {
    let cwd = workdir("view-step-budget");
    for budget in ["0", "-5", "NaN", "inf", "60001"] {
        let flag = format!("--step-budget-ms={budget}");
        let out = photometeor(&["view", "--tables", "tables", &flag], &cwd);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{budget}: {stderr}");
        assert!(
            stderr.contains("--step-budget-ms") && stderr.contains("outside (0, 60000]"),
            "{budget}: {stderr}"
        );
        assert!(!cwd.join("tables").exists(), "{budget}: {stderr}");
    }
}

#[test]
fn a_bad_script_is_refused_with_its_line_before_anything_opens() {
    let cwd = workdir("view-bad-script");
    std::fs::write(
        cwd.join("a.toml"),
        "[[step]]\nsun_elevation_deg = 30\nsun_elevtion = 4\n",
    )
    .unwrap();
    std::fs::write(cwd.join("b.toml"), "[[step]]\ndolly = -1\n").unwrap();
    for (file, wanted) in [
        ("a.toml", "line 3"),
        ("b.toml", "dolly = -1 is out of range"),
    ] {
        let out = photometeor(&["view", "--script", file], &cwd);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains(wanted), "{file}: {stderr}");
    }
}

/// A script may not resize one member of a swept field: the per-voxel mixing of a size
/// profile relies on the members' sizes being the sweep's values.
#[test]
fn a_script_resizing_a_sweep_member_is_refused() {
    let cwd = workdir("view-sweep-member");
    std::fs::write(
        cwd.join("s.toml"),
        "[[step]]\nfield_size = { \"cloud@01\" = 9 }\n",
    )
    .unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes/growing_cumulus.toml");
    let args = [
        scene.to_str().unwrap(),
        "--quality",
        "draft",
        "--tables",
        "tables",
        "--script",
        "s.toml",
    ];
    let Some(mut command) = view_command(&args, &cwd) else {
        return;
    };
    let out = command.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if skipped_without_adapter(&out) {
        return;
    }
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("field_size names \"cloud@01\", a member of a swept field"),
        "{stderr}"
    );
}
