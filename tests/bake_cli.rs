//! `photometeor bake` end to end: the no-argument bake of the embedded default scene read by the
//! OpenEXR reference library, its invariants and optical features, `inspect` and `compare`, and
//! malformed scenes that must leave the output directory untouched.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use format::{FieldImage, Manifest, read_field_exr, read_manifest};

mod common;

use common::{photometeor, workdir};

struct DefaultBake {
    out: PathBuf,
    stdout: String,
    stderr: String,
    manifest: Manifest,
}

/// `photometeor bake` with no arguments, run once in a fresh directory.
fn default_bake() -> &'static DefaultBake {
    static BAKE: OnceLock<DefaultBake> = OnceLock::new();
    BAKE.get_or_init(|| {
        let cwd = workdir("default-bake");
        let out = photometeor(&["bake"], &cwd);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "photometeor bake failed:\n{stderr}");
        let dir = cwd.join("photometeor-tables");
        let manifest = read_manifest(&dir).unwrap();
        DefaultBake {
            out: dir,
            stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
            stderr,
            manifest,
        }
    })
}

fn image(name: &str) -> FieldImage {
    read_field_exr(default_bake().out.join(format!("{name}.exr"))).unwrap()
}

#[test]
fn no_argument_bake_writes_all_four_fields() {
    let bake = default_bake();
    let names: Vec<&str> = bake
        .manifest
        .fields
        .iter()
        .map(|f| f.name.as_str())
        .collect();
    assert_eq!(names, ["cloud", "rain", "ice", "snow"], "{}", bake.stderr);
    for f in &bake.manifest.fields {
        assert!(bake.out.join(&f.file).is_file());
        assert_eq!(f.n_max, 26);
        assert_eq!(f.quality.preset, "standard");
        assert_eq!(f.content_hash.len(), 64);
        for c in f.n_isotropic.as_array() {
            let n: Vec<u32> = ["1e-2", "1e-4", "1e-6"]
                .iter()
                .map(|eps| c[*eps].unwrap_or_else(|| panic!("{}: n_iso({eps}) missing", f.name)))
                .collect();
            assert!(n[0] <= n[1] && n[1] <= n[2], "{}: {n:?}", f.name);
        }
    }
    assert_eq!(bake.manifest.angle_count, 1001);
    // Snow: featureless and g within VD14's range for strongly distorted crystals.
    let snow = &bake.manifest.fields[3];
    for g in [snow.g.r, snow.g.g, snow.g.b] {
        assert!((0.70..=0.80).contains(&g), "snow g {g}");
    }
}

#[test]
fn openexr_reference_library_reads_the_default_bake_and_its_invariants_hold() {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/check_bake_openexr.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(&default_bake().out)
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e})"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.starts_with("OK"),
        "{}\n{stdout}\n{}\n(needs `python3 -m pip install OpenEXR numpy`)",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn forward_fractions_fall_monotonically_toward_one_half() {
    for f in &default_bake().manifest.fields {
        for (c, values) in f.forward_fraction.as_array().into_iter().enumerate() {
            assert!(
                values.iter().all(|&v| v > 0.5),
                "{} {c}: {values:?}",
                f.name
            );
            for w in values.windows(2) {
                assert!(w[1] < w[0], "{} {c}: F_i must fall: {values:?}", f.name);
            }
            let (first, last) = (values[0] - 0.5, values[values.len() - 1] - 0.5);
            assert!(
                last < 0.1 * first,
                "{} {c}: F_N − ½ = {last}, F_1 − ½ = {first}",
                f.name
            );
        }
    }
}

/// Index range of θ ∈ [a°, b°] on the 0.18° grid.
fn bins(a: f64, b: f64) -> std::ops::RangeInclusive<usize> {
    (a / 0.18).ceil() as usize..=(b / 0.18).floor() as usize
}

fn max_in(row: &[f64], r: std::ops::RangeInclusive<usize>) -> (usize, f64) {
    r.map(|k| (k, row[k]))
        .fold((0, f64::NEG_INFINITY), |m, x| if x.1 > m.1 { x } else { m })
}

/// Rows Ams_1..Ams_N of channel c.
fn rows_of(image: &FieldImage, c: usize) -> Vec<Vec<f64>> {
    (0..image.n_max())
        .map(|r| image.row(c, r).to_vec())
        .collect()
}

fn min_in(row: &[f64], r: std::ops::RangeInclusive<usize>) -> f64 {
    r.map(|k| row[k]).fold(f64::INFINITY, f64::min)
}

#[test]
fn rain_rainbow_is_red_outside_and_fades_with_order() {
    let rain = image("rain");
    let mut peak_bin = [0; 3];
    for c in 0..3 {
        // Primary bow: maximum at θ ≈ 138° (42° from the antisolar point); Alexander's dark
        // band lies between it and the secondary bow (≈ 129°).
        let rows = rows_of(&rain, c);
        let contrast: Vec<f64> = rows
            .iter()
            .map(|row| max_in(row, bins(136.0, 142.0)).1 / min_in(row, bins(130.0, 135.0)))
            .collect();
        let (k, _) = max_in(&rows[0], bins(136.0, 142.0));
        peak_bin[c] = k;
        let theta = k as f64 * 0.18;
        assert!(
            (137.0..=140.0).contains(&theta),
            "channel {c}: primary bow at {theta}°"
        );
        assert!(contrast[0] > 10.0, "channel {c}: bow contrast {contrast:?}");
        for w in contrast[..8].windows(2) {
            assert!(w[1] < w[0], "channel {c}: bow must fade: {contrast:?}");
        }
        assert!(
            contrast[25] < 1.01,
            "channel {c}: bow gone by n = 26: {contrast:?}"
        );
    }
    // Red is deviated least: smaller scattering angle, larger radius about the antisolar point.
    assert!(
        peak_bin[0] < peak_bin[1] && peak_bin[1] < peak_bin[2],
        "{peak_bin:?}"
    );
}

#[test]
fn ice_has_22_and_46_degree_halos_red_inside() {
    let ice = image("ice");
    for (lo, hi) in [(20.5, 24.0), (44.0, 49.0)] {
        let mut peaks = [0; 3];
        for (c, peak) in peaks.iter_mut().enumerate() {
            let row = &rows_of(&ice, c)[0];
            let (k, v) = max_in(row, bins(lo, hi));
            assert!(
                v > row[k - 1] && v > row[k + 1],
                "channel {c}: no local maximum in {lo}–{hi}°"
            );
            // Stands well above the light 1° inside it (the halo's dark inner side).
            assert!(
                v > 2.0 * row[k - 6],
                "channel {c}: halo at {}° too weak",
                k as f64 * 0.18
            );
            *peak = k;
        }
        assert!(
            peaks[0] < peaks[2],
            "{lo}–{hi}°: red {} not inside blue {}",
            peaks[0],
            peaks[2]
        );
    }
}

#[test]
fn cloud_glory_is_present_and_fades_with_order() {
    let cloud = image("cloud");
    for c in 0..3 {
        let contrast: Vec<f64> = rows_of(&cloud, c)
            .iter()
            .map(|row| row[1000] / min_in(row, bins(170.0, 178.0)))
            .collect();
        assert!(
            contrast[0] > 2.0,
            "channel {c}: glory contrast {contrast:?}"
        );
        for w in contrast[..8].windows(2) {
            assert!(w[1] < w[0], "channel {c}: glory must fade: {contrast:?}");
        }
    }
}

#[test]
fn inspect_and_compare_read_the_bake() {
    let dir = default_bake().out.to_str().unwrap().to_string();
    let out = photometeor(&["inspect", &dir], Path::new("."));
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("cloud") && text.contains("rain") && text.contains("1001 angles"),
        "{text}"
    );
    // Ice and snow, traced to the standard preset's noise target, say how far they went.
    assert_eq!(
        text.matches("rays traced; noise of Ams_1").count(),
        2,
        "{text}"
    );
    assert_eq!(
        text.matches("sizes per wavelength; noise of Ams_1").count(),
        2,
        "{text}"
    );
    for f in &default_bake().manifest.fields {
        let noise = &f.quality.crystal_noise;
        if !f.kind.is_drops() {
            for (c, n) in ["R", "G", "B"]
                .iter()
                .zip(noise.as_ref().unwrap().as_array())
            {
                assert!(*n > 0.0 && *n <= 0.009, "{} {c}: noise {n}", f.name);
            }
        } else {
            assert!(noise.is_none(), "{}: {noise:?}", f.name);
            // Drops: the size sampling's noise, at the standard preset under its 1 %.
            let size_noise = f.quality.size_noise.as_ref().unwrap();
            for (c, n) in ["R", "G", "B"].iter().zip(size_noise.as_array()) {
                assert!(*n > 0.0 && *n < 0.01, "{} {c}: size noise {n}", f.name);
            }
        }
    }
    let out = photometeor(&["inspect", &dir, "--json"], Path::new("."));
    let parsed: Manifest = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(parsed, default_bake().manifest);
    let out = photometeor(&["compare", &dir, &dir, "--json"], Path::new("."));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for f in v["fields"].as_array().unwrap() {
        assert_eq!(f["rms_rel_ams1"], 0.0);
        assert_eq!(f["max_abs_forward_fraction"], 0.0);
    }
}

#[test]
fn validate_passes_on_the_default_bake() {
    let dir = default_bake().out.to_str().unwrap().to_string();
    let out = photometeor(&["validate", &dir, "--json"], Path::new("."));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let checks = v["checks"].as_array().unwrap();
    let passed = |field: &str, name: &str| {
        checks
            .iter()
            .filter(|c| c["field"] == field && c["name"] == name && c["status"] == "pass")
            .count()
    };
    // Every phenomenon the default scene must show is judged, per channel, and passes.
    assert_eq!(passed("rain", "primary rainbow"), 3);
    assert_eq!(passed("rain", "secondary rainbow"), 3);
    assert_eq!(passed("rain", "Alexander's dark band contrast"), 3);
    assert_eq!(passed("cloud", "glory enhancement"), 3);
    assert_eq!(passed("ice", "22° halo"), 3);
    assert_eq!(passed("ice", "46° halo"), 3);
    assert_eq!(passed("snow", "featureless 10–60° (no halo)"), 3);
}

#[test]
fn plot_draws_every_picture_of_the_default_bake_as_png_and_svg() {
    let dir = default_bake().out.to_str().unwrap().to_string();
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("plots");
    let _ = fs::remove_dir_all(&out);
    let run = photometeor(
        &[
            "plot",
            &dir,
            "--out",
            out.to_str().unwrap(),
            "--reference",
            &dir,
        ],
        Path::new("."),
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let mut names = vec!["forward_fraction".to_string()];
    for (field, zooms) in [
        ("cloud", &["corona", "glory", "fogbow"][..]),
        ("rain", &["rainbows"][..]),
        ("ice", &["halos"][..]),
        ("snow", &["no_halos"][..]),
    ] {
        names.push(format!("{field}_phase"));
        names.push(format!("{field}_ams_family"));
        names.extend(zooms.iter().map(|z| format!("{field}_zoom_{z}")));
        let strip = fs::read(out.join(format!("{field}_colours.png"))).unwrap();
        assert_eq!(&strip[1..4], b"PNG", "{field} colour strip");
    }
    for name in names {
        let png = fs::read(out.join(format!("{name}.png"))).unwrap();
        assert_eq!(&png[1..4], b"PNG", "{name}.png");
        assert!(png.len() > 10_000, "{name}.png is {} bytes", png.len());
        let svg = fs::read_to_string(out.join(format!("{name}.svg"))).unwrap();
        assert!(
            svg.contains("<svg") && svg.contains("<polyline"),
            "{name}.svg"
        );
    }
}

/// A quick trade on a small scene: every variant is baked, timed and compared; errors fall as
/// sizes rise, and the presets' rows are there.
#[test]
fn tradeoff_measures_each_knob_against_a_reference() {
    let root = workdir("tradeoff");
    let scene = root.join("scene.toml");
    fs::write(
        &scene,
        "[scene]\nname = \"t\"\nspectral = \"rgb3\"\nn_max = 4\n\n[[field]]\nname = \"cloud\"\nkind = \"cloud\"\ndistribution = { kind = \"gamma\", r_eff_um = 4, v_eff = 0.02 }\n",
    )
    .unwrap();
    let out_dir = root.join("work");
    let run = photometeor(
        &[
            "tradeoff",
            scene.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
            "--quick",
        ],
        Path::new("."),
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_slice(&fs::read(out_dir.join("tradeoff.json")).unwrap()).unwrap();
    let rows = v["rows"].as_array().unwrap();
    let row = |knob: &str, value: &str| {
        rows.iter()
            .find(|r| r["knob"] == knob && r["value"] == value)
            .unwrap_or_else(|| panic!("no row {knob} = {value}: {rows:?}"))
    };
    let err = |r: &serde_json::Value| r["rms_rel_ams1"].as_f64().unwrap();
    let (draft, standard) = (row("preset", "draft"), row("preset", "standard"));
    assert!(err(standard) < err(draft), "{draft} {standard}");
    assert!(err(row("sizes per λ", "100")) > err(standard));
    for r in rows {
        assert!(r["seconds"].as_f64().unwrap() > 0.0);
        assert!(r["max_peak_shift_deg"].as_f64().unwrap() < 0.2, "{r}");
    }
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(text.starts_with("| fields | knob |"), "{text}");
    let plots = root.join("plots");
    let run = photometeor(
        &[
            "plot",
            "--tradeoff",
            out_dir.join("tradeoff.json").to_str().unwrap(),
            "--out",
            plots.to_str().unwrap(),
        ],
        Path::new("."),
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(plots.join("tradeoff_pareto.png").exists());
    assert!(plots.join("tradeoff_pareto.svg").exists());

    // A scene of given phase functions only has nothing to trade: refused before any work.
    let lobe = root.join("lobe.toml");
    fs::write(
        &lobe,
        "[scene]\nname = \"lobe\"\nspectral = \"rgb3\"\n\n[[field]]\nname = \"l\"\nkind = \"hg\"\n\
         g = 0.8\nextinction_m2 = 1e-12\n",
    )
    .unwrap();
    let lobe_out = root.join("lobe-work");
    let run = photometeor(
        &[
            "tradeoff",
            lobe.to_str().unwrap(),
            "--out",
            lobe_out.to_str().unwrap(),
        ],
        Path::new("."),
    );
    let e = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        e.contains("nothing to trade: its fields are given phase functions"),
        "{e}"
    );
    assert!(!lobe_out.exists(), "wrote before refusing");
}

/// The bake's summary is words, not a debug list: what it computed, where the tables are and
/// the next command; an unchanged re-bake says its fields came from the cache.
#[test]
fn the_bake_says_in_words_what_it_did_and_what_to_run_next() {
    let out = &default_bake().stdout;
    for line in [
        "baked default into photometeor-tables in ",
        ": computed cloud, rain, ice and snow; peak memory ",
        "The tables are in photometeor-tables: manifest.json and one <field>.exr per field",
        "Next: photometeor validate photometeor-tables",
        "  or: photometeor render --out rainbow.exr --png rainbow.png",
    ] {
        assert!(out.contains(line), "no {line:?} in:\n{out}");
    }
    assert!(
        !out.contains('[') && !out.contains('"'),
        "a debug list in:\n{out}"
    );

    let root = workdir("bake-in-words");
    fs::write(root.join("scene.toml"), GOOD).unwrap();
    let bake = || photometeor(&["bake", "scene.toml", "--out", "t"], &root);
    assert!(bake().status.success());
    let again = bake();
    let again = String::from_utf8_lossy(&again.stdout);
    assert!(again.contains("baked t into t in "), "{again}");
    assert!(
        again.contains(": rain from the cache; peak memory "),
        "{again}"
    );
}

const SPHERES: &str = "[scene]\nname = \"v\"\nspectral = \"rgb3\"\nn_max = 4\nquality = \"draft\"\n\n[[field]]\nname = \"cloud\"\nkind = \"cloud\"\ndistribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.02 }\n\n[[field]]\nname = \"rain\"\nkind = \"rain\"\nMATERIAL\ndistribution = { kind = \"lognormal\", median_radius_um = 500, sigma_g = 1.4 }\n";

/// Bakes SPHERES with the rain drops made of `material` into `name` under the test's tmp dir.
fn bake_spheres(name: &str, material: &str) -> PathBuf {
    let root = workdir(name);
    let scene = root.join("scene.toml");
    fs::write(
        &scene,
        SPHERES.replace("MATERIAL", &format!("material = \"{material}\"")),
    )
    .unwrap();
    let out_dir = root.join("tables");
    let out = photometeor(
        &[
            "bake",
            scene.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
            "--quiet",
        ],
        Path::new("."),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out_dir
}

/// A narrow cloud shows its corona ring where Fraunhofer theory puts it; ice spheres validate
/// against the ice index; and a rain table computed with the ice index but labelled water (the
/// manifest of a water bake) fails, naming the rainbow checks.
#[test]
fn validate_judges_the_corona_and_fails_on_a_table_with_the_wrong_index() {
    let water = bake_spheres("validate-water", "water");
    let ice = bake_spheres("validate-ice", "ice");
    for dir in [&water, &ice] {
        let out = photometeor(&["validate", dir.to_str().unwrap()], Path::new("."));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{text}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            text.lines()
                .filter(|l| l.contains("first corona ring") && l.contains(" pass "))
                .count(),
            3,
            "{text}"
        );
    }
    // Water's manifest, ice's rain table. Copied alone, every reader refuses it (its F_i and
    // checksum are not the manifest's); so the manifest is made to vouch for it (size, CRC-32 and F_i of the
    // ice table, microphysics still water), as a bake with the wrong index would have written.
    fs::copy(ice.join("rain.exr"), water.join("rain.exr")).unwrap();
    let out = photometeor(&["validate", water.to_str().unwrap()], Path::new("."));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("rain.exr") && stderr.contains("manifest.json"),
        "{stderr}"
    );
    let ice_rain = read_manifest(&ice).unwrap().fields[1].clone();
    let mut m = read_manifest(&water).unwrap();
    assert_eq!(
        (m.fields[1].name.as_str(), ice_rain.name.as_str()),
        ("rain", "rain")
    );
    m.fields[1].bytes = ice_rain.bytes;
    m.fields[1].crc32 = ice_rain.crc32;
    m.fields[1].forward_fraction = ice_rain.forward_fraction;
    fs::write(water.join("manifest.json"), m.to_json_bytes()).unwrap();
    let out = photometeor(&["validate", water.to_str().unwrap()], Path::new("."));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    for c in ["R", "G", "B"] {
        assert!(
            stderr.contains(&format!("rain {c} primary rainbow")),
            "{stderr}"
        );
    }
    assert!(
        !stderr.contains("cloud"),
        "the cloud table is right: {stderr}"
    );
}

const GOOD: &str = "[scene]\nname = \"t\"\nspectral = \"rgb3\"\nquality = \"draft\"\n\n[[field]]\nname = \"rain\"\nkind = \"rain\"\ndistribution = { kind = \"lognormal\", median_radius_um = 500, sigma_g = 1.4 }\n";

fn listing(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            let bytes = if e.path().is_file() {
                fs::read(e.path()).unwrap()
            } else {
                Vec::new()
            };
            (e.file_name().to_string_lossy().into_owned(), bytes)
        })
        .collect();
    v.sort();
    v
}

#[test]
fn malformed_scenes_name_key_and_line_and_leave_the_output_untouched() {
    let cases = [
        // (scene, words the message must hold)
        (
            GOOD.replace("quality = \"draft\"", "quality = \"draft\"\ncolour = 3"),
            vec!["line 5", "colour"],
        ),
        (
            GOOD.replace("median_radius_um = 500", "median_radius_um = -500"),
            vec!["line 9", "-500"],
        ),
        (
            GOOD.replace("quality = \"draft\"", "quality = \"draft\"\nn_max = 0"),
            vec!["line 5", "n_max = 0"],
        ),
        (
            GOOD.replace(
                "quality = \"draft\"",
                "quality = \"draft\"\ntheta_step_deg = 0.7",
            ),
            vec!["line 5", "theta_step_deg = 0.7", "divide 180"],
        ),
        (
            // A table beside the scene (not in the working folder) with a negative value.
            format!(
                "{GOOD}\n[[field]]\nname = \"t\"\nkind = \"tabulated\"\nfile = \"bad.csv\"\n\
                 extinction_m2 = 1e-12\n"
            ),
            vec!["line 14", "file bad.csv line 3: p = -1", "finite and ≥ 0"],
        ),
    ];
    for (scene, words) in cases {
        let tmp = tempfile::tempdir().unwrap();
        let out_dir = tmp.path().join("tables");
        fs::create_dir(&out_dir).unwrap();
        fs::write(out_dir.join("manifest.json"), b"{\"previous\": true}").unwrap();
        fs::write(out_dir.join("rain.exr"), b"previous table").unwrap();
        let before = listing(&out_dir);
        fs::create_dir(tmp.path().join("scenes")).unwrap();
        let scene_path = tmp.path().join("scenes").join("scene.toml");
        fs::write(&scene_path, &scene).unwrap();
        fs::write(
            tmp.path().join("scenes").join("bad.csv"),
            "theta_deg,p\n0,1\n90,-1\n180,1\n",
        )
        .unwrap();
        let out = photometeor(
            &[
                "bake",
                scene_path.to_str().unwrap(),
                "--out",
                out_dir.to_str().unwrap(),
            ],
            tmp.path(),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{scene}");
        assert_eq!(stderr.trim().lines().count(), 1, "one line: {stderr}");
        for w in words {
            assert!(stderr.contains(w), "{w:?} missing in: {stderr}");
        }
        assert_eq!(listing(&out_dir), before, "output changed for:\n{scene}");
    }
}
