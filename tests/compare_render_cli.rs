//! `photometeor compare-render` on frames no comparison can be made from: a non-finite or
//! negative pixel or standard error in either frame (a truth of one sample per pixel writes an
//! infinite stderr) is refused, exit 2, naming the file, the pixel, the channel and the value.

mod common;

use std::path::Path;

use common::{photometeor, workdir};
use render::Image;

const W: usize = 3;
const H: usize = 2;

/// A 3×2 frame of radiance `rgb` (the volume everywhere, A = 0.5), with `stderr` if given.
fn write(path: &Path, rgb: [f32; 3], stderr: Option<f32>, edit: impl FnOnce(&mut Frame)) {
    let mut f = Frame {
        rgb: vec![rgb; W * H],
        a: vec![0.5; W * H],
        stderr: stderr.map(|e| vec![[e; 3]; W * H]),
    };
    edit(&mut f);
    let image = Image {
        width: W,
        height: H,
        rgb: f.rgb,
        transparency: f.a,
    };
    let extra = f
        .stderr
        .map(|e| {
            (0..3)
                .map(|c| {
                    (
                        format!("stderr.{}", ["R", "G", "B"][c]),
                        e.iter().map(|p| p[c]).collect(),
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    image.write_exr_with(path, extra).unwrap();
}

/// What a case does, how it writes its frame, and the refusal it must give.
type Case = (&'static str, Box<dyn Fn(&Path)>, &'static str);

struct Frame {
    rgb: Vec<[f32; 3]>,
    a: Vec<f32>,
    stderr: Option<Vec<[f32; 3]>>,
}

#[test]
fn frames_with_non_finite_or_negative_values_are_refused_naming_the_first() {
    let dir = workdir("compare-render-values");
    write(&dir.join("truth.exr"), [0.2, 0.2, 0.2], Some(0.01), |_| {});
    write(&dir.join("model.exr"), [0.1, 0.1, 0.1], None, |_| {});
    // The good pair compares: 50 % too dark.
    let o = photometeor(
        &["compare-render", "truth.exr", "model.exr", "--json"],
        &dir,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        (report["bias"].as_f64().unwrap() + 0.5).abs() < 1e-6,
        "{report}"
    );

    let cases: Vec<Case> = vec![
        (
            "a truth of 1 spp: stderr inf everywhere",
            Box::new(|p| write(p, [0.2; 3], Some(f32::INFINITY), |_| {})),
            "truth.exr: pixel (0, 0) channel stderr.R = inf",
        ),
        (
            "a negative stderr",
            Box::new(|p| {
                write(p, [0.2; 3], Some(0.01), |f| {
                    f.stderr.as_mut().unwrap()[4][2] = -0.5
                })
            }),
            "truth.exr: pixel (1, 1) channel stderr.B = -0.5",
        ),
        (
            "a NaN stderr",
            Box::new(|p| {
                write(p, [0.2; 3], Some(0.01), |f| {
                    f.stderr.as_mut().unwrap()[2][1] = f32::NAN
                })
            }),
            "truth.exr: pixel (2, 0) channel stderr.G = NaN",
        ),
        (
            "a NaN truth pixel",
            Box::new(|p| write(p, [0.2; 3], Some(0.01), |f| f.rgb[5][0] = f32::NAN)),
            "truth.exr: pixel (2, 1) channel R = NaN",
        ),
        (
            "a negative truth pixel",
            Box::new(|p| write(p, [0.2; 3], Some(0.01), |f| f.rgb[1][1] = -1e-3)),
            "truth.exr: pixel (1, 0) channel G = -0.001",
        ),
    ];
    for (what, make, needle) in &cases {
        make(&dir.join("truth.exr"));
        refused(&dir, what, needle);
    }
    write(&dir.join("truth.exr"), [0.2, 0.2, 0.2], Some(0.01), |_| {});
    let model_cases: Vec<Case> = vec![
        (
            "an infinite model pixel",
            Box::new(|p| write(p, [0.1; 3], None, |f| f.rgb[3][2] = f32::INFINITY)),
            "model.exr: pixel (0, 1) channel B = inf",
        ),
        (
            "a NaN model pixel",
            Box::new(|p| write(p, [0.1; 3], None, |f| f.rgb[0][0] = f32::NAN)),
            "model.exr: pixel (0, 0) channel R = NaN",
        ),
        (
            "a negative model pixel",
            Box::new(|p| write(p, [0.1; 3], None, |f| f.rgb[2][1] = -0.25)),
            "model.exr: pixel (2, 0) channel G = -0.25",
        ),
        (
            "a model transparency of NaN",
            Box::new(|p| write(p, [0.1; 3], None, |f| f.a[1] = f32::NAN)),
            "model.exr: pixel (1, 0) channel A = NaN",
        ),
        (
            "a model frame with a negative stderr",
            Box::new(|p| {
                write(p, [0.1; 3], Some(0.01), |f| {
                    f.stderr.as_mut().unwrap()[0][0] = -1.0
                })
            }),
            "model.exr: pixel (0, 0) channel stderr.R = -1",
        ),
    ];
    for (what, make, needle) in &model_cases {
        make(&dir.join("model.exr"));
        refused(&dir, what, needle);
    }
}

/// `compare-render truth.exr model.exr --map map.png` in `dir`: exit 2, `needle` in the error,
/// no map written.
fn refused(dir: &Path, what: &str, needle: &str) {
    let o = photometeor(
        &[
            "compare-render",
            "truth.exr",
            "model.exr",
            "--map",
            "map.png",
        ],
        dir,
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: {e}");
    assert!(e.contains(needle), "{what}: {needle:?} not in {e}");
    assert!(!dir.join("map.png").exists(), "{what}: a map was written");
}
