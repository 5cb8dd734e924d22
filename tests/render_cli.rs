//! `photometeor render` end to end: the rainbow scene of data/scenes rendered on the GPU
//! (lavapipe in CI), the bow's radius about the antisolar point measured from the written EXR
//! and compared with the primary peak of the table the render used; and bad scenes refused
//! with the value and its range, nothing written.

use std::path::{Path, PathBuf};

use render::RenderScene;
use runtime::Tables;

mod common;
#[path = "common/exr_planes.rs"]
mod exr_planes;

use common::{photometeor, workdir};
use exr_planes::read_rgba;

fn scene_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/scenes")
        .join(name)
}

fn gpu_required() -> bool {
    std::env::var("REQUIRE_GPU").as_deref() == Ok("1")
}

#[test]
fn rainbow_radius_in_the_render_matches_the_tables_primary_peak_red_outside() {
    let cwd = workdir("render-rainbow");
    let scene = scene_path("rainbow.toml");
    let args = [
        "render",
        scene.to_str().unwrap(),
        "--model",
        "riley",
        "--quality",
        "draft",
        "--tables",
        "tables",
        "--out",
        "rainbow.exr",
        "--png",
        "rainbow.png",
        "--width",
        "400",
        "--height",
        "400",
        "--slices",
        "128",
    ];
    let out = photometeor(&args, &cwd);
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() && stderr.contains("no GPU adapter") && !gpu_required() {
        eprintln!("skipped, no adapter:\n{stderr}");
        return;
    }
    assert!(out.status.success(), "render failed:\n{stderr}");
    assert!(cwd.join("rainbow.png").exists());
    // Its stderr is a pipe, not a terminal: the bake's progress comes as plain lines.
    assert!(
        stderr.contains("  rain: baking (") && stderr.contains("  rain: done in "),
        "no bake progress lines on a non-terminal stderr:\n{stderr}"
    );

    // The table's primary bow: the largest Ams_1 between 130° and 145°, per channel.
    let tables = Tables::open(cwd.join("tables")).unwrap();
    let rain = tables.field("rain").unwrap();
    let step = tables.theta_step_deg;
    let table_radius: Vec<f64> = (0..3)
        .map(|c| {
            let row = rain.image.row(c, 0).to_vec();
            let k = (130.0 / step) as usize..=(145.0 / step) as usize;
            let peak = k.max_by(|&a, &b| row[a].total_cmp(&row[b])).unwrap();
            180.0 - peak as f64 * step
        })
        .collect();

    // The image: each pixel's angle ψ from the antisolar point (the direction the sunlight
    // travels), radiance averaged in 0.1° rings over pixels that see the rain.
    let (w, h, planes) = read_rgba(&cwd.join("rainbow.exr"));
    assert_eq!((w, h), (400, 400));
    let render = RenderScene::from_file(&scene).unwrap();
    let mut frame = render.frame(&tables).unwrap();
    frame.width = w;
    frame.height = h;
    let settings = render::riley::Settings::default();
    let setup = render::riley::Setup::new(&frame, &settings).unwrap();
    let bin = 0.1;
    let (lo, hi) = (36.0, 48.0);
    let nbins = ((hi - lo) / bin) as usize;
    let mut sums = vec![[0.0f64; 3]; nbins];
    let mut counts = vec![0usize; nbins];
    for j in 0..h {
        for i in 0..w {
            let p = i + w * j;
            if planes[3][p] > 0.95 {
                continue;
            }
            let (_, d) = setup.pixel(i, j, w, h);
            let psi = d.dot(setup.light).clamp(-1.0, 1.0).acos().to_degrees();
            if psi < lo || psi >= hi {
                continue;
            }
            let b = ((psi - lo) / bin) as usize;
            counts[b] += 1;
            for c in 0..3 {
                sums[b][c] += planes[c][p] as f64;
            }
        }
    }
    assert!(
        counts.iter().all(|&n| n > 20),
        "rings too sparse: {counts:?}"
    );
    let image_radius: Vec<f64> = (0..3)
        .map(|c| {
            // The rings' mean less the straight line through the two end rings: the bow is a
            // peak on the sky's smooth gradient (the sky light makes the green and blue sky
            // brighter towards 36° than the bow is above it).
            let raw: Vec<f64> = (0..nbins).map(|b| sums[b][c] / counts[b] as f64).collect();
            let (first, last) = (raw[0], raw[nbins - 1]);
            let mean: Vec<f64> = (0..nbins)
                .map(|b| raw[b] - first - (last - first) * b as f64 / (nbins - 1) as f64)
                .collect();
            let b = (1..nbins - 1)
                .max_by(|&a, &b| mean[a].total_cmp(&mean[b]))
                .unwrap();
            // Parabola through the peak bin and its neighbours.
            let (y0, y1, y2) = (mean[b - 1], mean[b], mean[b + 1]);
            let shift = 0.5 * (y0 - y2) / (y0 - 2.0 * y1 + y2);
            lo + (b as f64 + 0.5 + shift) * bin
        })
        .collect();
    eprintln!("bow radius: image {image_radius:?}, table {table_radius:?} (R, G, B, degrees)");
    for c in 0..3 {
        assert!(
            (image_radius[c] - table_radius[c]).abs() < 0.5,
            "channel {c}: image {:.2}°, table {:.2}°",
            image_radius[c],
            table_radius[c]
        );
    }
    assert!(
        image_radius[0] > image_radius[2],
        "red ({:.2}°) must lie outside blue ({:.2}°)",
        image_radius[0],
        image_radius[2]
    );
}

#[test]
fn bad_render_scenes_name_the_value_and_its_range_and_write_nothing() {
    let cwd = workdir("render-bad");
    let base = std::fs::read_to_string(scene_path("rainbow.toml")).unwrap();
    let args = [
        "render",
        "bad.toml",
        "--model",
        "riley",
        "--quality",
        "draft",
        "--tables",
        "tables",
        "--out",
        "bad.exr",
        "--cpu",
        "--width",
        "8",
        "--height",
        "8",
    ];
    let cases = [
        (
            "elevation_deg = 12",
            "elevation_deg = -5",
            "elevation_deg = -5",
        ),
        ("shape = \"rain_shaft\"", "shape = \"torus\"", "\"torus\""),
        (
            "number_density_per_m3 = 80",
            "number_density_per_m3 = -1",
            "number_density_per_m3 = -1",
        ),
        ("fov_deg = 75", "fov_deg = 180", "fov_deg = 180"),
        ("field = \"rain\"", "field = \"hail\"", "\"hail\""),
    ];
    for (from, to, named) in cases {
        assert!(base.contains(from), "{from}");
        let scene = cwd.join("bad.toml");
        std::fs::write(&scene, base.replace(from, to)).unwrap();
        let out = photometeor(&args, &cwd);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{to}: accepted");
        assert!(
            stderr.contains(named),
            "{to}: message does not name it:\n{stderr}"
        );
        assert!(!cwd.join("bad.exr").exists(), "{to}: an image was written");
    }
    // A swept field: refused where no volume uses it, and where a volume names the sweep
    // itself (not one member), with the sweep's line, before anything is baked.
    let base = format!("{}\n", base.trim_end());
    let swept = "\n[[field]]\nname = \"cloud\"\nkind = \"cloud\"\n\
                 distribution = { kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }\n\
                 sweep = { key = \"r_eff_um\", from = 4, to = 32 }\n";
    let line = base.lines().count() + 6;
    std::fs::write(cwd.join("bad.toml"), format!("{base}{swept}")).unwrap();
    assert_refused_before_any_work(
        &args,
        &cwd,
        &format!(
            "line {line}: [[field]] \"cloud\" sweeps r_eff_um from 4 to 32 and no [[volume]] uses it"
        ),
    );
    let named = base.replace("field = \"rain\"", "field = \"cloud\"");
    std::fs::write(cwd.join("bad.toml"), format!("{named}{swept}")).unwrap();
    assert_refused_before_any_work(
        &args,
        &cwd,
        "[[volume]] 1 (field \"cloud\"): \"cloud\" sweeps r_eff_um from 4 to 32; give the \
         volume a size per voxel, `r_eff_um = { base = …, top = … }`",
    );
    // A size profile: outside the sweep's values, on a field that is not swept, of a key the
    // field does not sweep, or with a size ≤ 0.
    let profiled = |profile: &str, field: &str| {
        base.replace(
            "field = \"rain\"",
            &format!("field = \"{field}\"\n{profile}"),
        )
    };
    let cases = [
        (
            profiled("r_eff_um = { base = 3, top = 12 }", "cloud"),
            "r_eff_um = { base = 3, top = 12 } lies outside the sweep's values [4, 32]",
        ),
        (
            profiled("r_eff_um = { base = 6, top = 12 }", "rain"),
            "r_eff_um = { base, top } needs a swept field",
        ),
        (
            profiled("median_radius_um = { base = 6, top = 12 }", "cloud"),
            "the profile follows median_radius_um and \"cloud\" sweeps r_eff_um",
        ),
        (
            profiled("r_eff_um = { base = 0, top = 12 }", "cloud"),
            "base must be finite and > 0",
        ),
    ];
    for (scene, named) in cases {
        std::fs::write(cwd.join("bad.toml"), format!("{scene}{swept}")).unwrap();
        assert_refused_before_any_work(&args, &cwd, named);
    }
}

/// A volume whose size profile holds one member's value everywhere renders as a volume of that
/// member: the per-voxel mixing of the sweep puts all of its particles in that member.
#[test]
fn a_size_profile_at_one_members_value_renders_as_that_member() {
    let cwd = workdir("render-profile");
    let base = std::fs::read_to_string(scene_path("rainbow.toml")).unwrap();
    let swept = "\n[[field]]\nname = \"cloud\"\nkind = \"cloud\"\n\
                 distribution = { kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }\n\
                 sweep = { key = \"r_eff_um\", from = 4, to = 16, count = 3 }\n";
    let render = |name: &str, volume: &str| {
        let scene = format!(
            "{}\n{swept}",
            base.trim_end()
                .replace("field = \"rain\"", volume)
                .replace("number_density_per_m3 = 80", "number_density_per_m3 = 2e7")
        );
        std::fs::write(cwd.join(format!("{name}.toml")), scene).unwrap();
        let (toml, exr) = (format!("{name}.toml"), format!("{name}.exr"));
        let args = [
            "render",
            &toml,
            "--model",
            "riley",
            "--quality",
            "draft",
            "--tables",
            "tables",
            "--out",
            &exr,
            "--cpu",
            "--width",
            "32",
            "--height",
            "24",
            "--slices",
            "32",
        ];
        let out = photometeor(&args, &cwd);
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(out.status.success(), "{name}:\n{stderr}");
        (read_rgba(&cwd.join(exr)).2, stderr)
    };
    // Members 4, 8 and 16 µm: a profile of 8 µm at base and top is all cloud@01.
    let (member, _) = render("member", "field = \"cloud@01\"");
    let (profile, said) = render(
        "profile",
        "field = \"cloud\"\nr_eff_um = { base = 8, top = 8 }",
    );
    assert!(
        said.contains("cloud: a size per voxel from 2 of its members, r_eff_um = 8.000, 16.000"),
        "{said}"
    );
    let (growing, said) = render(
        "growing",
        "field = \"cloud\"\nr_eff_um = { base = 4, top = 16 }",
    );
    assert!(said.contains("from 3 of its members"), "{said}");
    let (a, b) = (member[..3].concat(), profile[..3].concat());
    let peak = a.iter().fold(0f32, |m, v| m.max(v.abs()));
    let apart = |b: &[f32]| a.iter().zip(b).fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    let (same, other) = (apart(&b), apart(&growing[..3].concat()));
    eprintln!("peak {peak}, profile at the member {same}, growing profile {other}");
    assert!(peak > 0.0 && same <= 1e-5 * peak, "{same} of peak {peak}");
    // The growing cloud is another cloud (the test can tell them apart).
    assert!(other > 0.05 * peak, "{other} of peak {peak}");
}

#[test]
fn render_without_tables_bakes_under_the_cache_directory_with_a_safe_name() {
    let cwd = workdir("render-cache-dir");
    let cache = cwd.join("xdg-cache");
    // A scene whose name would climb out of any directory it named.
    let text = std::fs::read_to_string(scene_path("rainbow.toml"))
        .unwrap()
        .replacen("name = \"rainbow\"", "name = \"x/../../victim\"", 1);
    assert!(
        text.contains("x/../../victim"),
        "the scene's name line moved"
    );
    std::fs::write(cwd.join("scene.toml"), text).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_photometeor"))
        .args([
            "render",
            "scene.toml",
            "--model",
            "riley",
            "--quality",
            "draft",
            "--out",
            "out.exr",
            "--cpu",
            "--width",
            "8",
            "--height",
            "8",
            "--slices",
            "8",
            "--quiet",
        ])
        .current_dir(&cwd)
        .env("XDG_CACHE_HOME", &cache)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Nothing but the scene, the image and the cache root appeared in the working directory.
    let mut entries: Vec<String> = std::fs::read_dir(&cwd)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    entries.sort();
    assert_eq!(entries, ["out.exr", "scene.toml", "xdg-cache"]);
    let tables_root = cache.join("photometeor").join("tables");
    let dirs: Vec<PathBuf> = std::fs::read_dir(&tables_root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    let name = dirs[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with("x_______victim-"), "{name}");
    assert!(Tables::open(&dirs[0]).unwrap().field("rain").is_some());
}

/// Runs `args` in `cwd` and asserts that it fails naming `named`, with no bake (`tables`) and
/// no image (`bad.exr`) left behind.
fn assert_refused_before_any_work(args: &[&str], cwd: &Path, named: &str) {
    let out = photometeor(args, cwd);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{named}: accepted");
    assert!(stderr.contains(named), "{named}: not named:\n{stderr}");
    assert!(
        !cwd.join("tables").exists(),
        "{named}: baked before refusing"
    );
    assert!(
        !cwd.join("bad.exr").exists(),
        "{named}: an image was written"
    );
}

#[test]
fn scenes_the_path_tracer_cannot_handle_are_refused_before_any_bake() {
    let cwd = workdir("render-truth-bad");
    let base = std::fs::read_to_string(scene_path("rainbow.toml")).unwrap();
    std::fs::write(cwd.join("zeros.f32"), [0u8; 4 * 8]).unwrap();
    let grid = base.replace(
        "shape = \"rain_shaft\"",
        "shape = \"grid\"\nfile = \"zeros.f32\"\ndims = [2, 2, 2]\nmin_m = [-100, 0, 5000]\nmax_m = [100, 200, 5200]",
    );
    let cases: [(String, &[&str], &str); 3] = [
        (
            format!("{base}\n[[light]]\nposition_m = [0, -3, 100]\nintensity = [1, 1, 1]\n"),
            &[],
            "[0.0, -3.0, 100.0]",
        ),
        (base.clone(), &["--spp", "0"], "spp = 0"),
        (grid, &[], "every one of its 8 values is 0"),
    ];
    for (text, extra, named) in cases {
        std::fs::write(cwd.join("bad.toml"), text).unwrap();
        let mut args = vec![
            "render",
            "bad.toml",
            "--model",
            "truth",
            "--quality",
            "draft",
            "--tables",
            "tables",
            "--out",
            "bad.exr",
            "--width",
            "8",
            "--height",
            "8",
        ];
        args.extend_from_slice(extra);
        assert_refused_before_any_work(&args, &cwd, named);
    }
}

#[test]
fn miyazaki_keys_out_of_range_are_refused_before_any_bake() {
    let cwd = workdir("render-miyazaki-bad");
    let base = std::fs::read_to_string(scene_path("shafts.toml")).unwrap();
    let cases = [
        (
            base.replace("a = 1.5", "a = -0.5"),
            "[render.miyazaki] a = -0.5 is outside the allowed range (0, 2]",
        ),
        (
            base.replace("a = 1.5", "a = 2.5"),
            "[render.miyazaki] a = 2.5 is outside the allowed range (0, 2]",
        ),
        (
            base.replace("a = 1.5", "a = 1.5\nxi = 0.1"),
            "[render.miyazaki] xi: --model miyazaki has no such setting",
        ),
        (
            base.replace("scale_height_m = 1500", "scale_height_m = 0"),
            "[haze] scale_height_m = 0 is outside the allowed range [1, 1e6] (m)",
        ),
        (
            base.replace("albedo = 0.1", "albedo = 1.2"),
            "[ground] albedo = 1.2 is outside the allowed range [0, 1]",
        ),
    ];
    for (text, named) in cases {
        std::fs::write(cwd.join("bad.toml"), text).unwrap();
        let args = [
            "render",
            "bad.toml",
            "--model",
            "miyazaki",
            "--cpu",
            "--quality",
            "draft",
            "--tables",
            "tables",
            "--out",
            "bad.exr",
            "--width",
            "8",
            "--height",
            "8",
        ];
        assert_refused_before_any_work(&args, &cwd, named);
    }
    // Riley's model refuses the haze layer, naming it, before any bake.
    std::fs::write(cwd.join("bad.toml"), &base).unwrap();
    let out = photometeor(
        &[
            "render", "bad.toml", "--model", "riley", "--cpu", "--tables", "tables", "--out",
            "bad.exr",
        ],
        &cwd,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("[haze] layer"),
        "{stderr}"
    );
    assert!(!cwd.join("tables").exists());
}

#[test]
fn max_keys_out_of_range_are_refused_before_any_bake() {
    let cwd = workdir("render-max-bad");
    let base = std::fs::read_to_string(scene_path("cumulus_dawn.toml")).unwrap();
    let with = |key: &str| format!("{base}\n[render.max]\n{key}\n");
    let cases = [
        (
            with("threshold = 0"),
            "[render.max] threshold = 0 is outside the allowed range (0, ∞)",
        ),
        (
            with("threshold = -2"),
            "[render.max] threshold = -2 is outside the allowed range (0, ∞)",
        ),
        (
            with("diffusion_tolerance = 0.5"),
            "[render.max] diffusion_tolerance = 0.5 is outside the allowed range [1e-12, 0.1]",
        ),
        (
            with("max_diffusion_iterations = 0"),
            "[render.max] max_diffusion_iterations = 0 is outside the allowed range [1, 100000]",
        ),
        (
            base.replace("[render]\n", "[render]\nmax_threshold = 2\n"),
            "[render] max_threshold: each model's settings live in its own table: write \
             threshold = 2 under [render.max]",
        ),
        (
            base.replace("n_max = 26", "n_max = 26\npoisson_max_depth = 0"),
            "poisson_max_depth = 0 is outside the allowed range (0.001, 1000]",
        ),
        (
            std::fs::read_to_string(scene_path("shafts.toml")).unwrap(),
            "--model max draws Rayleigh air only",
        ),
    ];
    for (text, named) in cases {
        std::fs::write(cwd.join("bad.toml"), text).unwrap();
        let args = [
            "render",
            "bad.toml",
            "--model",
            "max",
            "--quality",
            "draft",
            "--tables",
            "tables",
            "--out",
            "bad.exr",
            "--width",
            "8",
            "--height",
            "8",
        ];
        assert_refused_before_any_work(&args, &cwd, named);
    }
}

#[test]
fn the_beams_scene_renders_with_both_kernels_and_other_models_refuse_it() {
    let cwd = workdir("render-biri");
    let scene = scene_path("beams.toml");
    let scene = scene.to_str().unwrap();
    for model in ["riley", "miyazaki", "max"] {
        assert_refused_before_any_work(
            &[
                "render", scene, "--model", model, "--cpu", "--out", "bad.exr", "--tables",
                "tables",
            ],
            &cwd,
            "only --model biri and --model truth draw",
        );
    }
    let mut images = Vec::new();
    for kernel in ["exact", "polynomial"] {
        let out = format!("{kernel}.exr");
        let run = photometeor(
            &[
                "render",
                scene,
                "--model",
                "biri",
                "--biri-kernel",
                kernel,
                "--quality",
                "draft",
                "--width",
                "40",
                "--height",
                "30",
                "--out",
                &out,
                "--tables",
                "tables",
            ],
            &cwd,
        );
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(stderr.contains(&format!("{kernel} kernel")), "{stderr}");
        let (w, h, rgba) = read_rgba(&cwd.join(&out));
        assert_eq!((w, h), (40, 30));
        images.push(rgba);
    }
    // The exact image is positive and lit; the quartic differs from it.
    assert!(images[0][1].iter().all(|&v| v > 0.0));
    assert!(
        images[0][1]
            .iter()
            .zip(&images[1][1])
            .any(|(a, b)| (a - b).abs() > 0.1 * a)
    );
}

#[test]
fn settings_of_another_model_are_refused_before_any_bake() {
    let cwd = workdir("render-foreign-settings");
    std::fs::copy(scene_path("cumulus_dawn.toml"), cwd.join("scene.toml")).unwrap();
    let cases: [(&str, &[&str], &str); 4] = [
        (
            "max",
            &["--slices", "64"],
            "--slices: --model max has no setting slices",
        ),
        (
            "riley",
            &["--spp", "4"],
            "--spp: --model riley has no setting spp",
        ),
        (
            "truth",
            &["--set", "k_multi=0.3"],
            "--set k_multi=0.3: --model truth has no setting k_multi",
        ),
        (
            "miyazaki",
            &["--set", "k_multi=-1"],
            "[render.miyazaki] k_multi = -1 is outside the allowed range [0, 1e6]",
        ),
    ];
    for (model, extra, named) in cases {
        let mut args = vec![
            "render",
            "scene.toml",
            "--model",
            model,
            "--cpu",
            "--quality",
            "draft",
            "--tables",
            "tables",
            "--out",
            "bad.exr",
        ];
        args.extend_from_slice(extra);
        assert_refused_before_any_work(&args, &cwd, named);
    }
}

/// `--model auto` (the default): riley for a thin cloud, coupled for a dense one (the sweep's
/// measured errors at their optical depths), each said with the depth; lamps in a medium go
/// to the one model that draws them; `--set` with auto is refused before any bake.
#[test]
fn auto_chooses_by_the_scenes_optical_depth_and_says_why() {
    let cwd = workdir("render-auto");
    let scene = |density: &str| {
        format!(
            "[scene]\nname = \"auto\"\nspectral = \"rgb3\"\nn_max = 4\nquality = \"draft\"\n\n\
             [[field]]\nname = \"cloud\"\nkind = \"cloud\"\n\
             distribution = {{ kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }}\n\n\
             [render]\nwidth = 8\nheight = 6\ngrid_resolution = 12\n\n\
             [camera]\nposition_m = [0, 500, -3000]\nlook_at_m = [0, 500, 0]\n\n\
             [sun]\nelevation_deg = 30\nazimuth_deg = 40\n\n\
             [[volume]]\nfield = \"cloud\"\nshape = \"cumulus\"\n\
             number_density_per_m3 = {density}\ncenter_m = [0, 500, 0]\nradius_m = 300\n\
             height_m = 300\n"
        )
    };
    let run = |text: &str, extra: &[&str]| {
        std::fs::write(cwd.join("auto.toml"), text).unwrap();
        let mut args = vec![
            "render",
            "auto.toml",
            "--cpu",
            "--tables",
            "tables",
            "--out",
            "auto.exr",
        ];
        args.extend_from_slice(extra);
        let out = photometeor(&args, &cwd);
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    // At 2e9 (τ ≈ 160) on 12 voxels coupled's transport would not converge (docs/models/
    // coupled.md, "Optical depth"): it is left out, and the line says so.
    for (density, chosen) in [("1e4", "riley"), ("1e8", "coupled"), ("2e9", "max")] {
        let (code, e) = run(&scene(density), &[]);
        assert_eq!(code, Some(0), "{e}");
        let line = e
            .lines()
            .find(|l| l.starts_with("--model auto: "))
            .unwrap_or_else(|| panic!("no choice said:\n{e}"));
        assert!(
            line.starts_with(&format!("--model auto: {chosen} — optical depth ")),
            "density {density}: {line}"
        );
        assert!(line.contains("docs/coupled/sweep.md"), "{line}");
        assert_eq!(
            line.contains("; coupled not taken: the scene's optical depth is "),
            density == "2e9",
            "{line}"
        );
    }
    // Lamps in a medium: only biri draws them.
    let beams = scene_path("beams.toml");
    let out = photometeor(
        &[
            "render",
            beams.to_str().unwrap(),
            "--cpu",
            "--tables",
            "beams-tables",
            "--out",
            "beams.exr",
            "--width",
            "8",
            "--height",
            "6",
            "--quality",
            "draft",
        ],
        &cwd,
    );
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{e}");
    assert!(
        e.contains("--model auto: biri — the only kind of model"),
        "{e}"
    );
    // An orthographic camera, which every model draws: chosen by the depth as for a pinhole
    // (coupled at this one).
    let ortho = scene("1e8").replace(
        "look_at_m = [0, 500, 0]\n",
        "look_at_m = [0, 500, 0]\nprojection = \"orthographic\"\nwidth_m = 1000\n",
    );
    let (code, e) = run(&ortho, &[]);
    assert_eq!(code, Some(0), "{e}");
    assert!(e.contains("--model auto: coupled — optical depth"), "{e}");
    // A periodic volume: coupled and the truth draw it, and auto chooses by the depth among
    // them (coupled at this one).
    let (code, e) = run(&format!("{}periodic = true\n", scene("1e8")), &[]);
    assert_eq!(code, Some(0), "{e}");
    assert!(e.contains("--model auto: coupled — optical depth"), "{e}");
    std::fs::remove_dir_all(cwd.join("tables")).unwrap();
    let (code, e) = run(&scene("1e8"), &["--set", "slices=8"]);
    assert_eq!(code, Some(2), "{e}");
    assert!(
        e.contains("--set slices=8: --model auto chooses its model after the bake"),
        "{e}"
    );
    assert!(!cwd.join("tables").exists(), "baked before refusing");
}
