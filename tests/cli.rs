//! End-to-end checks of the `photometeor mie` and `photometeor phase` commands.

// Table-driven end-to-end tests read best whole: the 120-line bound on functions
// (clippy.toml) holds for library and binary code.
#![allow(clippy::too_many_lines)]

use std::process::{Command, Output};

use serde_json::Value;

fn photometeor(args: &[&str], threads: Option<usize>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_photometeor"));
    cmd.args(args);
    if let Some(t) = threads {
        cmd.env("RAYON_NUM_THREADS", t.to_string());
    }
    cmd.output().expect("running photometeor")
}

fn json_of(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON object on stdout")
}

#[test]
fn mie_json_has_the_documented_keys_and_obeys_the_optical_theorem() {
    let v = json_of(&photometeor(
        &[
            "mie",
            "--m",
            "1.333+1e-8i",
            "--x",
            "1000",
            "--angles-deg",
            "0,0.18,90,180",
            "--json",
        ],
        None,
    ));
    for key in [
        "m_re",
        "m_im",
        "x",
        "n_terms",
        "qext",
        "qsca",
        "qabs",
        "qback",
        "g",
        "angles_deg",
        "phase",
        "s1",
        "s2",
    ] {
        assert!(v.get(key).is_some(), "missing key {key}");
    }
    assert_eq!(v["m_im"].as_f64(), Some(1e-8));
    assert_eq!(v["phase"].as_array().unwrap().len(), 4);
    let x = v["x"].as_f64().unwrap();
    let s1_0 = v["s1"][0][0].as_f64().unwrap();
    let qext = v["qext"].as_f64().unwrap();
    assert!((s1_0 - x * x * qext / 4.0).abs() < 1e-10 * s1_0);
    // Q_back = 4|S1(180°)|²/x²
    let (re, im) = (
        v["s1"][3][0].as_f64().unwrap(),
        v["s1"][3][1].as_f64().unwrap(),
    );
    let qback = v["qback"].as_f64().unwrap();
    assert!((4.0 * (re * re + im * im) / (x * x) - qback).abs() < 1e-9 * qback);
}

#[test]
fn mie_by_material_and_full_grid() {
    let v = json_of(&photometeor(
        &[
            "mie",
            "--material",
            "water",
            "--radius-um",
            "10",
            "--wavelength-nm",
            "550",
            "--angles-step-deg",
            "0.18",
            "--json",
        ],
        None,
    ));
    assert_eq!(v["angles_deg"].as_array().unwrap().len(), 1001);
    let x = v["x"].as_f64().unwrap();
    assert!((x - 2.0 * std::f64::consts::PI * 10.0 / 0.55).abs() < 1e-9);
    // IAPWS 20 °C at 550 nm is 1.3347 (docs/physics.md §3)
    assert!((v["m_re"].as_f64().unwrap() - 1.3347).abs() < 1e-4);
}

#[test]
fn bad_input_exits_nonzero_with_one_line_naming_value_and_range() {
    for (args, needles) in [
        (
            vec!["mie", "--m", "1.33-0.1i", "--x", "10"],
            vec!["-0.1", "κ ≥ 0"],
        ),
        (
            vec!["mie", "--m", "1.33", "--x", "0"],
            vec!["x = 0", "[1e-6, 2e5]"],
        ),
        (
            vec!["mie", "--m", "1.33", "--x", "-3"],
            vec!["x = -3", "[1e-6, 2e5]"],
        ),
        (
            vec!["mie", "--m", "1.3.3+i", "--x", "10"],
            vec!["1.3.3+i", "n + iκ"],
        ),
        (
            vec!["mie", "--m", "1.33", "--x", "10", "--angles-deg", "0,181"],
            vec!["181", "[0, 180]"],
        ),
        (
            vec!["mie", "--m", "1.33", "--x", "10", "--angles-deg", "-1"],
            vec!["-1", "[0, 180]"],
        ),
        (
            vec![
                "phase",
                "--lognormal-median-um",
                "10",
                "--sigma-g",
                "1.4",
                "--wavelengths-nm",
                "",
            ],
            vec!["wavelength", "empty", "[200, 1100]"],
        ),
        (
            vec![
                "phase",
                "--lognormal-median-um",
                "10",
                "--sigma-g",
                "0.8",
                "--wavelengths-nm",
                "550",
            ],
            vec!["0.8", "(1, 5]"],
        ),
        (
            vec![
                "phase",
                "--r-eff-um",
                "10",
                "--v-eff",
                "0.1",
                "--wavelengths-nm",
                "1500",
            ],
            vec!["1500", "[200, 1100]"],
        ),
        (
            vec!["bench", "relight", "--moves", "1,0"],
            vec!["--moves 0", "(0, 180]"],
        ),
        (
            vec!["bench", "relight", "--moves=-5"],
            vec!["--moves -5", "(0, 180]"],
        ),
        (
            vec!["bench", "relight", "--size", "0"],
            vec!["--size 0", "1–4096"],
        ),
        (
            vec!["bench", "relight", "--step-budget-ms", "NaN"],
            vec!["--step-budget-ms NaN", "0–10000"],
        ),
        (
            vec!["bench", "relight", "--moves", "1,5", "--truths", "a.exr"],
            vec!["1 frames for 2 --moves"],
        ),
        (
            vec!["bench", "render", "--sizes", "1920x0"],
            vec!["1920x0", "1–8192"],
        ),
    ] {
        let out = photometeor(&args, None);
        assert!(!out.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {err:?} lacks {n:?}");
        }
    }
}

#[test]
fn phase_bins_conserve_energy_and_are_bit_identical_for_any_thread_count() {
    let args = [
        "phase",
        "--material",
        "water",
        "--r-eff-um",
        "10",
        "--v-eff",
        "0.1",
        "--wavelengths-nm",
        "650,550,450",
        "--sizes",
        "64",
        "--json",
    ];
    let one = photometeor(&args, Some(1));
    let two = photometeor(&args, Some(2));
    assert_eq!(
        one.stdout, two.stdout,
        "output differs between 1 and 2 threads"
    );
    let v = json_of(&one);
    let step = v["theta_step_deg"].as_f64().unwrap();
    assert_eq!(step, 0.18);
    let rows = v["wavelengths"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    for r in rows {
        let bins: Vec<f64> = r["bins"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b.as_f64().unwrap())
            .collect();
        assert_eq!(bins.len(), 1001);
        // Σ_k v_k Ω_k, Ω_k the bin solid angles
        let energy: f64 = bins
            .iter()
            .enumerate()
            .map(|(k, b)| {
                let lo = (k as f64 * step - step / 2.0).max(0.0).to_radians();
                let hi = (k as f64 * step + step / 2.0).min(180.0).to_radians();
                b * 2.0 * std::f64::consts::PI * (lo.cos() - hi.cos())
            })
            .sum();
        assert!((energy - 1.0).abs() < 1e-8, "energy {energy}");
        let g = r["g"].as_f64().unwrap();
        assert!(g > 0.8 && g < 0.9, "g = {g}");
        let albedo = r["albedo"].as_f64().unwrap();
        assert!(albedo > 0.9999 && albedo <= 1.0);
    }
}

#[test]
fn bin_averages_integrate_inside_bins_not_point_samples() {
    // A single sphere whose phase function varies inside the 1° bins: the bin average must
    // equal a fine quadrature of p over the bin, which differs from the value at the centre.
    let phase = json_of(&photometeor(
        &[
            "phase",
            "--material",
            "water",
            "--r-eff-um",
            "20",
            "--v-eff",
            "0.02",
            "--wavelengths-nm",
            "550",
            "--sizes",
            "16",
            "--nodes-per-panel",
            "12",
            "--angles-step-deg",
            "1",
            "--json",
        ],
        None,
    ));
    let coarse = json_of(&photometeor(
        &[
            "phase",
            "--material",
            "water",
            "--r-eff-um",
            "20",
            "--v-eff",
            "0.02",
            "--wavelengths-nm",
            "550",
            "--sizes",
            "16",
            "--nodes-per-panel",
            "6",
            "--angles-step-deg",
            "1",
            "--json",
        ],
        None,
    ));
    let fine: Vec<f64> = phase["wavelengths"][0]["bins"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b.as_f64().unwrap())
        .collect();
    let six: Vec<f64> = coarse["wavelengths"][0]["bins"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b.as_f64().unwrap())
        .collect();
    // Bin 0 ([0°, 0.5°]) holds most of the diffraction lobe (first zero at 0.96°): its average
    // lies well below the peak value p(0) that a point sample would report.
    let p0 = json_of(&photometeor(
        &[
            "mie",
            "--material",
            "water",
            "--radius-um",
            "20",
            "--wavelength-nm",
            "550",
            "--angles-deg",
            "0",
            "--json",
        ],
        None,
    ))["phase"][0]
        .as_f64()
        .unwrap();
    assert!(fine[0] < 0.8 * p0, "bin 0 = {} vs p(0) = {p0}", fine[0]);
    // 6 and 12 Gauss nodes per bin agree (measured 5.4e-6; 3 nodes are 2 % off, as the
    // ripple period π/x ≈ 0.8° is shorter than a bin): the bins are converged integrals.
    let worst = fine
        .iter()
        .zip(&six)
        .map(|(a, b)| ((a - b) / a).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "worst {worst}");
}

#[test]
fn phase_point_values_agree_with_bins_where_the_function_is_smooth() {
    let v = json_of(&photometeor(
        &[
            "phase",
            "--r-eff-um",
            "10",
            "--v-eff",
            "0.1",
            "--wavelengths-nm",
            "550",
            "--sizes",
            "64",
            "--angles-deg",
            "9.9,59.94,140.04",
            "--json",
        ],
        None,
    ));
    assert_eq!(v["point_angles_deg"].as_array().unwrap().len(), 3);
    let row = &v["wavelengths"][0];
    // Grid angles θ_k = k·0.18° for k = 55, 333, 778.
    for (i, theta) in [9.9f64, 59.94, 140.04].iter().enumerate() {
        let point = row["points"][i].as_f64().unwrap();
        let k = (theta / 0.18).round() as usize;
        let bin = row["bins"][k].as_f64().unwrap();
        // A 0.18° bin average of a smooth cloud phase function is its centre value to O(Δθ²).
        assert!(
            ((point - bin) / bin).abs() < 2e-3,
            "θ = {theta}: {point} vs {bin}"
        );
    }
}

/// True when every number in `v` is finite (serde_json writes NaN and ±∞ as null).
fn all_finite(v: &Value) -> bool {
    match v {
        Value::Null => false,
        Value::Number(n) => n.as_f64().is_some_and(f64::is_finite),
        Value::Array(a) => a.iter().all(all_finite),
        Value::Object(o) => o.iter().all(|(k, v)| {
            // Keys that are null by design: n_iso not reached.
            k == "1e-6" || k == "1e-4" || k == "1e-2" || all_finite(v)
        }),
        _ => true,
    }
}

#[test]
fn the_ends_of_every_range_answer_finitely_or_refuse_in_one_line() {
    let x_ends = [
        "1e-300",
        "1e-60",
        "9.9e-7",
        "1e-6",
        "1.0000001e-6",
        "1",
        "199999.9",
        "2e5",
        "2.0000001e5",
        "NaN",
        "inf",
        "-0",
    ];
    let mut cases: Vec<Vec<String>> = Vec::new();
    let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    for x in x_ends {
        cases.push(own(&[
            "mie",
            "--m",
            "1.333+1e-8i",
            "--x",
            x,
            "--angles-deg",
            "0,90,180",
            "--json",
        ]));
    }
    for m in [
        "0.4",
        "0.5",
        "10",
        "10.1",
        "1.33+10i",
        "1.33+10.1i",
        "1",
        "1+0i",
        "NaN",
        "inf",
    ] {
        cases.push(own(&[
            "mie",
            "--m",
            m,
            "--x",
            "10",
            "--angles-deg",
            "0,180",
            "--json",
        ]));
    }
    for step in ["0.005", "0.01", "30", "36", "0", "-1", "NaN"] {
        cases.push(own(&[
            "mie",
            "--m",
            "1.33",
            "--x",
            "1",
            "--angles-step-deg",
            step,
            "--json",
        ]));
    }
    for (median, sizes, nodes) in [
        ("1e-60", "8", "2"),
        ("1e-300", "8", "2"),
        ("1e-3", "8", "2"),
        ("10", "0", "2"),
        ("10", "100001", "2"),
        ("10", "18446744073709551615", "2"),
        ("10", "8", "0"),
        ("10", "8", "65"),
        ("10", "8", "1000000000"),
    ] {
        cases.push(own(&[
            "phase",
            "--lognormal-median-um",
            median,
            "--sigma-g",
            "1.2",
            "--wavelengths-nm",
            "550",
            "--sizes",
            sizes,
            "--nodes-per-panel",
            nodes,
            "--angles-step-deg",
            "1",
            "--json",
        ]));
    }
    for sigma in ["1", "1.0000001", "5", "5.1", "NaN"] {
        cases.push(own(&[
            "phase",
            "--lognormal-median-um",
            "5",
            "--sigma-g",
            sigma,
            "--wavelengths-nm",
            "550",
            "--sizes",
            "8",
            "--angles-step-deg",
            "1",
            "--json",
        ]));
    }
    for jobs in ["0", "257", "100000"] {
        cases.push(own(&[
            "bake",
            "--jobs",
            jobs,
            "--out",
            "never-written",
            "--quiet",
        ]));
    }
    let mut answered = 0;
    for args in &cases {
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = photometeor(&argv, Some(1));
        let stderr = String::from_utf8_lossy(&out.stderr);
        match out.status.code() {
            Some(0) => {
                let v: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
                assert!(all_finite(&v), "{argv:?}: a non-finite number in {v}");
                answered += 1;
            }
            Some(2) => {
                // One line of ours, or clap's refusal of a malformed argument (its usage
                // follows); either way it starts with "error:" and names no panic.
                assert!(stderr.starts_with("error:"), "{argv:?}: {stderr}");
                assert!(!stderr.contains("panicked"), "{argv:?}: {stderr}");
                if !stderr.contains("Usage:") {
                    assert_eq!(stderr.trim().lines().count(), 1, "{argv:?}: {stderr}");
                }
            }
            other => panic!("{argv:?}: exit {other:?} (a panic or abort):\n{stderr}"),
        }
    }
    assert!(!std::path::Path::new("never-written").exists());
    println!(
        "{} cases: {answered} answered, {} refused",
        cases.len(),
        cases.len() - answered
    );
}
