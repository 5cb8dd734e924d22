//! `photometeor render` with inputs that are valid TOML but would abort, hang, run without end,
//! write over what is not its own or give a wrong image: each refused before anything is baked
//! or written (exit 2, the value named), or, where only the tables can tell, before any path
//! is traced.

mod common;
#[path = "common/exr_planes.rs"]
mod exr_planes;

use std::fs;
use std::os::unix::fs::FileTypeExt;
use std::path::Path;
use std::process::{Command, Output};

use common::{photometeor, workdir};

/// A small cloud scene for every model but biri: its [scene], [[field]], [render], [camera],
/// [sun] and one cumulus; `extra` replaces the marker line `#EXTRA` (more tables or keys).
fn scene(extra: &str) -> String {
    r#"[scene]
name = "bounds"
spectral = "rgb3"
n_max = 4
quality = "draft"

[[field]]
name = "cloud"
kind = "cloud"
distribution = { kind = "gamma", r_eff_um = 8, v_eff = 0.1 }

[render]
width = 8
height = 6
grid_resolution = 16

[camera]
position_m = [0, 500, -3000]
look_at_m = [0, 500, 0]

[sun]
elevation_deg = 30
azimuth_deg = 40

#EXTRA

[[volume]]
field = "cloud"
shape = "cumulus"
number_density_per_m3 = 1e7
center_m = [0, 500, 0]
radius_m = 300
height_m = 300
"#
    .replace("#EXTRA", extra)
}

/// `render scene.toml --tables tables --out out.exr <args>` in `dir`, with `--model riley`
/// where `args` name no model (these bounds are the scene's and the models', not auto's).
fn render(dir: &Path, args: &[&str]) -> Output {
    let mut all = vec![
        "render",
        "scene.toml",
        "--tables",
        "tables",
        "--out",
        "out.exr",
    ];
    if !args.contains(&"--model") {
        all.extend(["--model", "riley"]);
    }
    all.extend_from_slice(args);
    photometeor(&all, dir)
}

/// Runs `render scene.toml --tables tables <args>` in `dir` with `text` as the scene: exit 2
/// naming `needle`, nothing baked (no `tables/`), no image written.
fn refused_before_the_bake(dir: &Path, text: &str, args: &[&str], needle: &str) {
    let _ = fs::remove_dir_all(dir.join("tables"));
    fs::write(dir.join("scene.toml"), text).unwrap();
    let o = render(dir, &[&["--quiet"], args].concat());
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
    assert!(e.contains(needle), "{args:?}: {needle:?} not in {e}");
    assert!(
        !dir.join("tables").exists(),
        "{args:?}: baked before refusing"
    );
    assert!(!dir.join("out.exr").exists(), "{args:?}: wrote an image");
}

#[test]
fn values_out_of_range_are_refused_before_the_bake_for_every_model() {
    let dir = workdir("bounds-values");
    let base = scene("");
    let cases: &[(String, &[&str], &str)] = &[
        (
            base.replace("azimuth_deg = 40", "azimuth_deg = nan"),
            &["--model", "truth"],
            "[sun] azimuth_deg = NaN must be a finite angle",
        ),
        (
            base.replace(
                "position_m = [0, 500, -3000]",
                "position_m = [0, inf, -3000]",
            ),
            &["--cpu"],
            "[camera] position_m = [0.0, inf, -3000.0] must be finite",
        ),
        (
            base.replace(
                "azimuth_deg = 40",
                "azimuth_deg = 40\nirradiance = [1e308, 1, 1]",
            ),
            &[],
            "outside the allowed range [0, 1e30]",
        ),
        (
            scene(
                "[haze]\nfield = \"cloud\"\nnumber_density_per_m3 = 1e6\nscale_height_m = 1e-300",
            ),
            &["--model", "miyazaki"],
            "[haze] scale_height_m = 1e-300 is outside the allowed range [1, 1e6]",
        ),
        (
            scene("[render.riley]\nxi = 1e308"),
            &["--cpu"],
            "[render.riley] xi = 1e308 is outside the allowed range [0, 1e6]",
        ),
        (
            scene("[render.max]\ndiffusion_tolerance = 1e-300"),
            &["--model", "max"],
            "diffusion_tolerance = 1e-300 is outside the allowed range [1e-12, 0.1]",
        ),
        (
            base.clone(),
            &["--model", "truth", "--noise=-1"],
            "noise = -1",
        ),
        (
            base.clone(),
            &["--model", "truth", "--max-scatterings", "2000000"],
            "max_scatterings = 2000000",
        ),
        (
            base.clone(),
            &["--model", "max", "--slices", "64"],
            "--slices: --model max has no setting slices",
        ),
        (base.clone(), &["--exposure", "nan"], "--exposure NaN"),
    ];
    for (text, args, needle) in cases {
        refused_before_the_bake(&dir, text, args, needle);
    }
}

#[test]
fn a_frame_larger_than_the_memory_allowed_is_refused_naming_the_setting() {
    let dir = workdir("bounds-memory");
    // 8192² pixels of riley's buffers (112 B each) are 7 GiB: over a 1 GiB bound.
    refused_before_the_bake(
        &dir,
        &scene(""),
        &[
            "--cpu",
            "--width",
            "8192",
            "--height",
            "8192",
            "--max-memory",
            "1",
        ],
        "lower [render] width and height",
    );
    // max's lighting at grid_resolution 512 (about 500 B a voxel).
    refused_before_the_bake(
        &dir,
        &scene("").replace("grid_resolution = 16", "grid_resolution = 512"),
        &["--model", "max", "--cpu", "--max-memory", "1"],
        "lower [render] grid_resolution",
    );
    // The default frame fits the same bound.
    fs::write(dir.join("scene.toml"), scene("")).unwrap();
    let o = render(&dir, &["--quiet", "--cpu", "--max-memory", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn scene_files_that_are_not_regular_files_are_refused() {
    let dir = workdir("bounds-files");
    let grid = |file: &str| {
        scene("").replace(
            "shape = \"cumulus\"",
            &format!(
                "shape = \"grid\"\nfile = \"{file}\"\ndims = [4, 4, 4]\nmin_m = [-300, 200, \
                 -300]\nmax_m = [300, 800, 300]"
            ),
        )
    };
    let _ = fs::remove_file(dir.join("zero.f32"));
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.f32")).unwrap();
    refused_before_the_bake(&dir, &grid("zero.f32"), &["--cpu"], "not a regular file");
    let fifo = dir.join("pipe.f32");
    let _ = fs::remove_file(&fifo);
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success(), "mkfifo");
    // Read without a bound, a FIFO would block this forever.
    refused_before_the_bake(&dir, &grid("pipe.f32"), &["--cpu"], "not a regular file");
    // More values than a grid file may hold, refused before reading.
    refused_before_the_bake(
        &dir,
        &grid("zero.f32").replace("dims = [4, 4, 4]", "dims = [4096, 4096, 64]"),
        &["--cpu"],
        "more than the 268435456 a grid file may hold",
    );
    let mesh = format!(
        "{}\n[[medium]]\nfield = \"cloud\"\nnumber_density_per_m3 = 1e6\n\n[[light]]\n\
         position_m = [0, 500, -500]\nintensity = [1, 1, 1]\n\n[[occluder]]\nshape = \"mesh\"\n\
         file = \"zero.f32\"\n",
        scene("")
    );
    refused_before_the_bake(&dir, &mesh, &["--model", "truth"], "not a regular file");
}

#[test]
fn a_truth_of_one_sample_per_pixel_is_refused_before_the_bake() {
    // One sample per pixel gives no spread to estimate the standard error from: the truth
    // would carry stderr = inf in every pixel, and compare-render would count every
    // difference as within its noise.
    let dir = workdir("bounds-spp");
    for (text, args) in [
        (scene(""), &["--model", "truth", "--spp", "1"][..]),
        (scene("[render.truth]\nspp = 1"), &["--model", "truth"][..]),
    ] {
        refused_before_the_bake(&dir, &text, args, "spp = 1: the standard error");
    }
}

#[test]
fn size_profiles_at_a_sweeps_last_value_render() {
    // The profile at the last value of a log and of a linear sweep of 6 … 14 (it panicked in
    // choose_members, index out of bounds); the frame is finite.
    let dir = workdir("bounds-profile-ends");
    for (spacing, count) in [("log", 4), ("linear", 5)] {
        let text = scene("").replace(
            "distribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }",
            &format!(
                "distribution = {{ kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }}\n\
                 sweep = {{ key = \"r_eff_um\", from = 6, to = 14, count = {count}, \
                 spacing = \"{spacing}\" }}"
            ),
        ) + "r_eff_um = { base = 14, top = 14 }\n";
        fs::write(dir.join("scene.toml"), &text).unwrap();
        let _ = fs::remove_file(dir.join("out.exr"));
        let o = render(&dir, &["--cpu", "--quiet"]);
        assert!(
            o.status.success(),
            "{spacing}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let (_, _, [r, g, b, _]) = exr_planes::read_rgba(&dir.join("out.exr"));
        assert!(r.iter().chain(&g).chain(&b).all(|v| v.is_finite()));
        fs::remove_file(dir.join("out.exr")).unwrap();
        // A volume naming a member past the sweep's end is refused naming that member.
        let missing = text
            .replace("field = \"cloud\"\nshape", "field = \"cloud@07\"\nshape")
            .replace("r_eff_um = { base = 14, top = 14 }\n", "");
        refused_before_the_bake(
            &dir,
            &missing,
            &["--cpu"],
            &format!(
                "a [[volume]] uses field \"cloud@07\", which the sweep \"cloud\" does not \
                 have: its members are cloud@00 … cloud@0{} ({count} values of r_eff_um)",
                count - 1
            ),
        );
    }
}

#[test]
fn hopeless_optical_depths_are_refused_before_any_path() {
    let dir = workdir("bounds-depth");
    let dense = scene("").replace(
        "number_density_per_m3 = 1e7",
        "number_density_per_m3 = 1e25",
    );
    fs::write(dir.join("scene.toml"), &dense).unwrap();
    let o = render(&dir, &["--model", "truth", "--quiet"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("a point of the [[volume]] grid of field \"cloud\" has optical depth")
            && e.contains("more than the 1000"),
        "{e}"
    );
    assert!(!dir.join("out.exr").exists());
}

/// Media that overlap add up: two [[medium]] tables over one box, each 60 % of the bound through
/// its shortest side (each was checked alone, and passed), are refused together.
#[test]
fn overlapping_media_are_refused_by_their_summed_optical_depth() {
    let dir = workdir("bounds-media");
    let medium = |n: f64, x0: f64| {
        format!(
            "[[medium]]\nfield = \"cloud\"\nnumber_density_per_m3 = {n:e}\n\
             min_m = [{x0}, 400, -50]\nmax_m = [{}, 500, 50]\n",
            x0 + 100.0
        )
    };
    // One medium far past the bound tells its optical depth per particle: τ/n.
    let probe = 1e20;
    fs::write(dir.join("scene.toml"), scene(&medium(probe, -50.0))).unwrap();
    let o = render(&dir, &["--model", "truth", "--quiet"]);
    let e = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(2), "{e}");
    let tau: f64 = e
        .split("has optical depth ")
        .nth(1)
        .and_then(|s| s.split(',').next())
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or_else(|| panic!("{e}"));
    let n = 600.0 / (tau / probe);
    let two = scene(&format!("{}\n{}", medium(n, -50.0), medium(n, -50.0)));
    fs::write(dir.join("scene.toml"), two).unwrap();
    let o = render(&dir, &["--model", "truth", "--quiet", "--spp", "2"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("with the 1 [[medium]] tables overlapping it has optical depth 1.")
            && e.contains("more than the 1000"),
        "{e}"
    );
    assert!(!dir.join("out.exr").exists());
}

#[test]
fn render_outputs_never_replace_a_device_a_directory_or_the_bake() {
    let dir = workdir("bounds-outputs");
    fs::write(dir.join("scene.toml"), scene("")).unwrap();
    let render = |args: &[&str]| {
        let mut all = vec![
            "render",
            "scene.toml",
            "--model",
            "riley",
            "--cpu",
            "--tables",
            "tables",
            "--quiet",
        ];
        all.extend_from_slice(args);
        photometeor(&all, &dir)
    };
    let o = render(&["--out", "out.exr"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let manifest = fs::read(dir.join("tables/manifest.json")).unwrap();
    for (args, needle) in [
        (["--out", "tables/manifest.json"], "tables"),
        (["--out", "tables/cloud.exr"], "tables"),
        (["--out", "scene.toml"], "scene.toml"),
        (["--out", "tables"], "a directory"),
    ] {
        let o = render(&args);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(needle), "{args:?}: {e}");
    }
    assert_eq!(
        fs::read(dir.join("tables/manifest.json")).unwrap(),
        manifest
    );
    // A character device (as root, made with mknod: the numbers of /dev/null).
    let dev = dir.join("device");
    let _ = fs::remove_file(&dev);
    if Command::new("mknod")
        .arg(&dev)
        .args(["c", "1", "3"])
        .status()
        .is_ok_and(|s| s.success())
    {
        let o = render(&["--out", "out.exr", "--png", "device"]);
        assert_eq!(o.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&o.stderr).contains("a character device"));
        assert!(fs::metadata(&dev).unwrap().file_type().is_char_device());
    } else {
        eprintln!("mknod not permitted here: the device case is not run");
    }
}

#[test]
fn render_outputs_never_replace_a_file_the_scene_reads() {
    let dir = workdir("bounds-inputs");
    // A grid volume and an OBJ occluder, each a file the scene names; links to each and a
    // path through `..`. Every output onto one of them is refused before the bake, naming it.
    let values: Vec<u8> = (0..64)
        .flat_map(|i| (0.5 + i as f32 / 64.0).to_le_bytes())
        .collect();
    fs::write(dir.join("density.f32"), &values).unwrap();
    let obj = "v -50 0 -50\nv 50 0 -50\nv 0 80 50\nv 0 0 60\nf 1 2 3\nf 1 2 4\nf 2 3 4\nf 1 3 4\n";
    fs::write(dir.join("rock.obj"), obj).unwrap();
    fs::create_dir_all(dir.join("sub")).unwrap();
    for (link, target) in [
        ("grid_link.exr", "density.f32"),
        ("obj_link.png", "rock.obj"),
    ] {
        let _ = fs::remove_file(dir.join(link));
        std::os::unix::fs::symlink(dir.join(target), dir.join(link)).unwrap();
    }
    let text = format!(
        "{}\n[[light]]\nposition_m = [0, 500, -500]\nintensity = [1, 1, 1]\n\n[[occluder]]\n\
         shape = \"mesh\"\nfile = \"rock.obj\"\noffset_m = [0, 0, 600]\n",
        scene("").replace(
            "shape = \"cumulus\"",
            "shape = \"grid\"\nfile = \"density.f32\"\ndims = [4, 4, 4]\nmin_m = [-300, 200, \
             -300]\nmax_m = [300, 800, 300]",
        )
    );
    let truth = ["--model", "truth", "--spp", "2"];
    for (out, png, needle) in [
        ("density.f32", None, "is density.f32"),
        ("out.exr", Some("density.f32"), "is density.f32"),
        ("rock.obj", None, "is rock.obj"),
        ("out.exr", Some("rock.obj"), "is rock.obj"),
        ("grid_link.exr", None, "is density.f32"),
        ("out.exr", Some("obj_link.png"), "is rock.obj"),
        ("sub/../density.f32", None, "is density.f32"),
    ] {
        let mut args = vec!["--out", out];
        if let Some(png) = png {
            args.extend(["--png", png]);
        }
        args.extend(truth);
        let _ = fs::remove_dir_all(dir.join("tables"));
        fs::write(dir.join("scene.toml"), &text).unwrap();
        let mut all = vec!["render", "scene.toml", "--tables", "tables", "--quiet"];
        if !args.contains(&"--model") {
            all.extend(["--model", "riley"]);
        }
        all.extend(&args);
        let o = photometeor(&all, &dir);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(needle), "{args:?}: {needle:?} not in {e}");
        assert!(
            !dir.join("tables").exists(),
            "{args:?}: baked before refusing"
        );
        assert!(!dir.join("out.exr").exists(), "{args:?}: wrote an image");
    }
    assert_eq!(fs::read(dir.join("density.f32")).unwrap(), values);
    assert_eq!(fs::read_to_string(dir.join("rock.obj")).unwrap(), obj);
    assert!(
        fs::symlink_metadata(dir.join("grid_link.exr"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
}

#[test]
fn a_render_that_finds_its_tables_being_baked_waits_and_uses_them() {
    let dir = workdir("bounds-lock");
    fs::write(dir.join("scene.toml"), scene("")).unwrap();
    let render = || {
        Command::new(env!("CARGO_BIN_EXE_photometeor"))
            .args([
                "render",
                "scene.toml",
                "--model",
                "riley",
                "--tables",
                "tables",
                "--out",
                "out.exr",
                "--cpu",
            ])
            .current_dir(&dir)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    // A first render bakes the tables; then this process holds the bake's lock as a bake in
    // progress would.
    assert!(render().wait().unwrap().success());
    let manifest = fs::read(dir.join("tables/manifest.json")).unwrap();
    let exr = fs::read(dir.join("tables/cloud.exr")).unwrap();
    let lock = format::BakeLock::acquire(&dir.join("tables")).unwrap();
    let child = render();
    std::thread::sleep(std::time::Duration::from_secs(2));
    let mut child = child;
    assert!(
        child.try_wait().unwrap().is_none(),
        "the render did not wait for the bake's lock"
    );
    drop(lock);
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let pid = std::process::id().to_string();
    assert!(
        stderr.contains(&format!("waiting for process {pid}, which is baking")),
        "{stderr}"
    );
    // It used the tables it waited for: the bake is as it was.
    assert_eq!(
        fs::read(dir.join("tables/manifest.json")).unwrap(),
        manifest
    );
    assert_eq!(fs::read(dir.join("tables/cloud.exr")).unwrap(), exr);
    assert!(dir.join("out.exr").is_file());
}

#[test]
fn the_truth_stops_at_its_time_bound() {
    let dir = workdir("bounds-seconds");
    fs::write(dir.join("scene.toml"), scene("")).unwrap();
    // 10⁶ samples per pixel would take minutes; one second of tracing takes what it can.
    let o = render(
        &dir,
        &[
            "--model",
            "truth",
            "--spp",
            "1000000",
            "--set",
            "max_seconds=1",
        ],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    let spp: usize = e
        .split(" spp,")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no spp in {e}"));
    assert!((1..1_000_000).contains(&spp), "{spp} spp: {e}");
    assert!(dir.join("out.exr").is_file());
}
