//! `Tables::open` on a real bake, the CPU sampling functions, and corrupt, truncated and
//! mismatched files, each of which must fail naming the file and the check.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use format::{read_field_exr, write_field_exr};
use runtime::Tables;
use runtime::sample::{ams, forward_fraction, mix};

mod common;

/// The cloud-and-rain scene, baked once for the whole file.
fn baked() -> &'static Path {
    static BAKE: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &BAKE
        .get_or_init(|| common::bake(&common::cloud_and_rain("runtime-test", 4)))
        .1
}

/// A fresh copy of that bake (its files, not the cache) in its own temporary directory.
fn bake() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tables");
    fs::create_dir(&dir).unwrap();
    for entry in fs::read_dir(baked()).unwrap() {
        let path = entry.unwrap().path();
        if path.is_file() {
            fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
        }
    }
    (tmp, dir)
}

fn error_of(dir: &Path) -> String {
    match Tables::open(dir) {
        Ok(_) => panic!("{} opened", dir.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn opens_a_bake_and_selects_fields() {
    let (_tmp, dir) = bake();
    let all = Tables::open(&dir).unwrap();
    let names: Vec<&str> = all.fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["cloud", "rain"]);
    assert_eq!(all.angle_count, 1001);
    let rain = Tables::open_fields(&dir, Some(&["rain"])).unwrap();
    assert_eq!(rain.fields.len(), 1);
    assert_eq!(rain.fields[0].n_max(), 4);
    let e = Tables::open_fields(&dir, Some(&["hail"]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("manifest.json") && e.contains("\"hail\"") && e.contains("\"rain\""),
        "{e}"
    );
}

#[test]
fn sampling_is_linear_in_angle_and_order() {
    let (_tmp, dir) = bake();
    let t = Tables::open(&dir).unwrap();
    let rain = t.field("rain").unwrap();
    let step = t.theta_step_deg;
    let cos = |deg: f64| deg.to_radians().cos();
    for c in 0..3 {
        for k in [0usize, 1, 500, 767, 1000] {
            let theta = k as f64 * step;
            let at = ams(rain, step, 2.0, cos(theta))[c];
            assert!(
                (at - rain.image.ams[[c, 1, k]]).abs()
                    <= 1e-9 * rain.image.ams[[c, 1, k]].abs().max(1e-12)
            );
        }
        let k = 767;
        let mid = ams(rain, step, 1.0, cos((k as f64 + 0.5) * step))[c];
        let want = 0.5 * (rain.image.ams[[c, 0, k]] + rain.image.ams[[c, 0, k + 1]]);
        assert!((mid - want).abs() < 1e-6 * want, "{mid} vs {want}");
        let half_order = ams(rain, step, 1.5, cos(k as f64 * step))[c];
        let want = 0.5 * (rain.image.ams[[c, 0, k]] + rain.image.ams[[c, 1, k]]);
        assert!((half_order - want).abs() < 1e-9 * want);
        let f = forward_fraction(rain, 2.25)[c];
        let want =
            0.75 * rain.image.forward_fraction[[c, 1]] + 0.25 * rain.image.forward_fraction[[c, 2]];
        assert!((f - want).abs() < 1e-12);
    }
    // Beyond N the last row; below 1 the first.
    assert_eq!(ams(rain, step, 40.0, 0.3), ams(rain, step, 4.0, 0.3));
    assert_eq!(ams(rain, step, 0.2, 0.3), ams(rain, step, 1.0, 0.3));
    // Sampled finely, the interpolated phase function still integrates to 1 over the sphere
    // (trapezoid in θ on 20 000 points; the forward peak of rain sits inside bin 0).
    let cloud = t.field("cloud").unwrap();
    let m = 20_000;
    let h = std::f64::consts::PI / m as f64;
    let integral: f64 = (0..=m)
        .map(|i| {
            let th = i as f64 * h;
            let w = if i == 0 || i == m { 0.5 } else { 1.0 };
            w * ams(cloud, step, 3.0, th.cos())[1] * th.sin()
        })
        .sum::<f64>()
        * 2.0
        * std::f64::consts::PI
        * h;
    assert!((integral - 1.0).abs() < 0.01, "∫ = {integral}");
    // The spatial mix: one field alone is that field; no particles scatter nothing.
    let one = mix(&[rain, cloud], &[2.0, 0.0], step, 1.0, 0.1);
    assert_eq!(one, ams(rain, step, 1.0, 0.1));
    assert_eq!(mix(&[rain, cloud], &[0.0, 0.0], step, 1.0, 0.1), [0.0; 3]);
    let both = mix(&[rain, cloud], &[1.0, 1.0], step, 1.0, 0.1);
    let (a, b) = (ams(rain, step, 1.0, 0.1), ams(cloud, step, 1.0, 0.1));
    for c in 0..3 {
        let w = rain.sigma_sca_m2[c] / (rain.sigma_sca_m2[c] + cloud.sigma_sca_m2[c]);
        assert!((both[c] - (w * a[c] + (1.0 - w) * b[c])).abs() < 1e-9 * both[c]);
    }
}

/// Records field `index`'s current EXR size and CRC-32 in the manifest.
fn restamp(dir: &Path, index: usize) {
    let file = dir.join(format!(
        "{}.exr",
        format::read_manifest(dir).unwrap().fields[index].name
    ));
    let bytes = fs::read(file).unwrap();
    edit_manifest(dir, |v| {
        v["fields"][index]["bytes"] = (bytes.len() as u64).into();
        v["fields"][index]["crc32"] = format::crc32_hex(&bytes).into();
    });
}

/// Edits `manifest.json` as JSON.
fn edit_manifest(dir: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("manifest.json");
    let mut v: serde_json::Value = serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
    f(&mut v);
    fs::write(&path, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
}

#[test]
fn corrupt_truncated_and_mismatched_files_name_the_file_and_the_check() {
    type Corrupt = fn(&Path);
    let cases: [(&str, Corrupt, &str, &str); 11] = [
        (
            "truncated EXR",
            |d| {
                let b = fs::read(d.join("rain.exr")).unwrap();
                fs::write(d.join("rain.exr"), &b[..b.len() / 2]).unwrap();
            },
            "rain.exr",
            "not a complete OpenEXR file",
        ),
        (
            "not an EXR",
            |d| fs::write(d.join("rain.exr"), b"photometeor").unwrap(),
            "rain.exr",
            "not a complete OpenEXR file",
        ),
        (
            "missing EXR",
            |d| fs::remove_file(d.join("rain.exr")).unwrap(),
            "rain.exr",
            "reading",
        ),
        (
            "unknown schema",
            |d| edit_manifest(d, |v| v["schema"] = 3.into()),
            "manifest.json",
            "schema 3",
        ),
        (
            "manifest not JSON",
            |d| fs::write(d.join("manifest.json"), b"{ \"schema\": 2,").unwrap(),
            "manifest.json",
            "EOF",
        ),
        (
            "F_i differ between EXR and manifest",
            |d| {
                edit_manifest(d, |v| {
                    let f = &mut v["fields"][1]["forward_fraction"]["G"][0];
                    *f = (f.as_f64().unwrap() - 1e-4).into();
                })
            },
            "rain.exr",
            "F_1.G",
        ),
        (
            "another field's table",
            |d| {
                fs::copy(d.join("cloud.exr"), d.join("rain.exr")).unwrap();
            },
            "rain.exr",
            "field attribute \"cloud\"",
        ),
        (
            "a row not normalized",
            |d| {
                let mut image = read_field_exr(d.join("rain.exr")).unwrap();
                for v in image.ams.slice_mut(ndarray::s![2, 3, ..]) {
                    *v *= 1.001;
                }
                write_field_exr(d.join("rain.exr"), &image).unwrap();
                // A consistent but wrong bake: the manifest vouches for the new file.
                restamp(d, 1);
            },
            "rain.exr",
            "Ams_4.B integrates to",
        ),
        (
            "the same field's table from another bake",
            |d| {
                let mut image = read_field_exr(d.join("rain.exr")).unwrap();
                image.ams[[0, 0, 500]] *= 1.5;
                write_field_exr(d.join("rain.exr"), &image).unwrap();
            },
            "rain.exr",
            "not the one this bake wrote",
        ),
        (
            "an interrupted bake's pending commit",
            |d| fs::create_dir(d.join(".commit")).unwrap(),
            "manifest.json",
            "interrupted",
        ),
        (
            "an albedo out of range",
            |d| edit_manifest(d, |v| v["fields"][0]["albedo"]["R"] = 7.0.into()),
            "manifest.json",
            "albedo.R = 7",
        ),
    ];
    for (what, corrupt, file, needle) in cases {
        let (_tmp, dir) = bake();
        corrupt(&dir);
        let e = error_of(&dir);
        println!("{what}: {e}");
        assert!(
            e.contains(&dir.join(file).display().to_string()),
            "{what}: {e:?} does not name {file}"
        );
        assert!(e.contains(needle), "{what}: {e:?} does not say {needle:?}");
    }
}
