//! The translated sampling functions (`runtime::shaders`): the files checked in under
//! `shaders/` are what `photometeor shaders` writes today, and each one passes a real
//! validator: glslangValidator (GLSL 450 and ES 310) and spirv-val (SPIR-V), from Debian's
//! glslang-tools and spirv-tools, which the README's test command installs. HLSL and MSL have
//! no validator there: naga's own round trip checks the module they come from (WGSL → IR →
//! WGSL → IR, validated both times), and their text must carry the entry point and bindings.

// Table-driven end-to-end tests read best whole: the 120-line bound on functions
// (clippy.toml) holds for library and binary code.
#![allow(clippy::too_many_lines)]

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

fn repo_shaders() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shaders")
}

#[test]
fn the_checked_in_shaders_are_what_the_translator_writes() {
    let outputs = runtime::shaders::translate().unwrap();
    assert_eq!(outputs.len(), 6);
    for o in &outputs {
        let path = repo_shaders().join(o.name);
        let on_disk = std::fs::read(&path).unwrap_or_default();
        assert!(
            on_disk == o.bytes,
            "{} drifted from the WGSL source: run `photometeor shaders --out shaders` and commit",
            path.display()
        );
    }
}

fn validator(tool: &str, args: &[&str], package: &str) {
    let out = Command::new(tool).args(args).output().unwrap_or_else(|e| {
        panic!("{tool} not found ({e}): install Debian's {package} (the README's test command)")
    });
    assert!(
        out.status.success(),
        "{tool} {args:?}:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn every_output_passes_a_validator() {
    let dir = tempfile::tempdir().unwrap();
    for o in runtime::shaders::translate().unwrap() {
        std::fs::write(dir.path().join(o.name), &o.bytes).unwrap();
    }
    let at = |name: &str| dir.path().join(name).display().to_string();
    for glsl in ["photometeor.comp.glsl", "photometeor.es310.comp.glsl"] {
        validator(
            "glslangValidator",
            &["-S", "comp", &at(glsl)],
            "glslang-tools",
        );
    }
    validator("spirv-val", &[&at("photometeor.spv")], "spirv-tools");
    // naga's round trip of the module HLSL and MSL are written from.
    let (module, info) = runtime::shaders::module(&runtime::shaders::source()).unwrap();
    let wgsl =
        naga::back::wgsl::write_string(&module, &info, naga::back::wgsl::WriterFlags::empty())
            .unwrap();
    runtime::shaders::module(&wgsl).unwrap();
    let hlsl = std::fs::read_to_string(at("photometeor.hlsl")).unwrap();
    for want in [
        "void evaluate_queries(",
        "register(t0)",
        "register(b3)",
        "register(t4)",
        "register(t5)",
        "register(u1, space1)",
    ] {
        assert!(hlsl.contains(want), "HLSL lacks {want:?}");
    }
    let msl = std::fs::read_to_string(at("photometeor.metal")).unwrap();
    for want in [
        "kernel void evaluate_queries(",
        "ams_table [[texture(0)]]",
        "model_table [[texture(1)]]",
        "model_depths [[buffer(3)]]",
        "results [[buffer(5)]]",
        "_buffer_sizes [[buffer(6)]]",
    ] {
        assert!(msl.contains(want), "MSL lacks {want:?}");
    }
    // The five functions survive into every text output (under naga's names).
    for name in [
        "photometeor.hlsl",
        "photometeor.comp.glsl",
        "photometeor.metal",
    ] {
        let text = std::fs::read_to_string(at(name)).unwrap();
        for f in [
            "ams(",
            "forward_fraction(",
            "ams_mix(",
            "poisson(",
            "biri_primitive(",
        ] {
            assert!(text.contains(f), "{name} lacks {f}");
        }
    }
}

/// The checked-in GLSL 450 (`shaders/photometeor.comp.glsl`, what Godot- or OpenGL-based
/// engines include), compiled by an OpenGL driver (Mesa's llvmpipe, headless through EGL, via
/// the `moderngl` package; runtime/tests/run_glsl.py) and run on the tables `GpuTables`
/// uploads, against the CPU sampler on a few thousand queries of each lookup: the same inputs
/// as the WGSL on wgpu (tests/gpu.rs, f32 against f64). Ams_n relative to the value (floored at
/// 10⁻⁷ of the largest Ams_1), the Poisson mixtures likewise (floor 10⁻⁶ of the largest M),
/// Biri's primitive relative to its whole integral C(τ_h, 90°), each with its own tolerance.
#[test]
fn the_glsl_runs_in_opengl_and_matches_the_cpu_sampler() {
    use format::export::npy_f64_bytes;
    use runtime::sample::{ams, biri_primitive, forward_fraction, poisson};
    let (_tmp, dir) = common::bake(&common::cloud_and_rain("glsl", 6));
    let tables = runtime::Tables::open(&dir).unwrap();
    let k_len = tables.angle_count;
    let n_stride = tables.fields.iter().map(|f| f.n_max()).max().unwrap();
    let layers = tables.fields.len();
    // The layouts of GpuTables::upload (runtime/src/gpu.rs).
    let mut texture = Vec::new();
    let mut ff = Vec::new();
    let mut info = Vec::new();
    for f in &tables.fields {
        for r in 0..n_stride {
            let row = r.min(f.n_max() - 1);
            for k in 0..k_len {
                let a = &f.image.ams;
                texture.extend([a[[0, row, k]], a[[1, row, k]], a[[2, row, k]], 0.0]);
            }
            ff.extend((0..3).map(|c| f.image.forward_fraction[[c, row]]));
            ff.push(0.0);
        }
        info.push(f.n_max() as f64);
        info.extend(f.sigma_sca_m2);
    }
    let params = [
        k_len as f64,
        n_stride as f64,
        layers as f64,
        1.0 / tables.theta_step_deg.to_radians(),
    ];
    let models = runtime::gpu::model_arrays(&tables);
    let grid = grid::ThetaGrid::new(tables.theta_step_deg).unwrap();
    let (mut queries, mut expected) = (Vec::new(), Vec::new());
    let (mut denominator, mut tolerance) = (Vec::new(), Vec::new());
    // Measured worst on llvmpipe OpenGL: Ams_n 1.6·10⁻⁵, M 5.0·10⁻⁶, C 1.0·10⁻⁶ of the whole.
    let (ams_tol, poisson_tol, biri_tol) = (3e-5, 1e-5, 2e-6);
    for (field, f) in tables.fields.iter().enumerate() {
        let field = field as f64;
        let top = f.image.row(1, 0).iter().copied().fold(0.0, f64::max);
        for n in [0.5f32, 1.0, 1.5, 2.75, 6.0, 9.0] {
            for i in 0..=400 {
                let cos = (i as f64 * 0.45).to_radians().cos() as f32 as f64;
                queries.extend([field, n as f64, cos, 0.0, 0.0, 0.0, 0.0, 0.0]);
                let a = ams(f, tables.theta_step_deg, n as f64, cos);
                expected.extend([a[0], a[1], a[2], forward_fraction(f, n as f64)[1]]);
                denominator.extend(a.map(|v| v.abs() + 1e-7 * top));
                tolerance.push(ams_tol);
            }
        }
        let top_m = f
            .poisson
            .as_ref()
            .unwrap()
            .rows
            .iter()
            .copied()
            .fold(0.0, f64::max);
        for depth in [4e-4f32, 0.0137, 2.0, 29.0, 45.0] {
            for i in 0..=200 {
                let cos = (i as f64 * 0.9).to_radians().cos() as f32 as f64;
                let d = depth as f64;
                queries.extend([field, d, cos, 1.0, 0.0, 0.0, 0.0, 0.0]);
                let m = poisson(f, tables.theta_step_deg, [d; 3], cos).unwrap();
                expected.extend([m[0], m[1], m[2], 0.0]);
                denominator.extend(m.map(|v| v.abs() + 1e-6 * top_m));
                tolerance.push(poisson_tol);
            }
        }
        for tau_h in [0.0f32, 0.031, 1.7, 55.0, 140.0] {
            let whole: [f64; 3] = std::array::from_fn(|c| {
                biri_primitive(f, &grid, c, tau_h as f64, std::f64::consts::FRAC_PI_2).unwrap()
            });
            for i in 0..=200 {
                let theta = (-90.0 + 0.9 * i as f64).to_radians() as f32 as f64;
                queries.extend([field, tau_h as f64, theta, 2.0, 0.0, 0.0, 0.0, 0.0]);
                let c: [f64; 3] = std::array::from_fn(|c| {
                    biri_primitive(f, &grid, c, tau_h as f64, theta).unwrap()
                });
                expected.extend([c[0], c[1], c[2], 0.0]);
                denominator.extend(whole);
                tolerance.push(biri_tol);
            }
        }
    }
    let q = tolerance.len();
    let inputs = tempfile::tempdir().unwrap();
    for (name, shape, data) in [
        ("texture", vec![layers, n_stride, k_len, 4], &texture),
        ("forward_fraction", vec![layers * n_stride, 4], &ff),
        ("field_info", vec![layers, 4], &info),
        ("params", vec![4], &params.to_vec()),
        (
            "model_texture",
            vec![layers, models.rows, k_len, 4],
            &models.texels.iter().map(|&v| v as f64).collect(),
        ),
        (
            "model_depths",
            vec![models.depths.len()],
            &models.depths.iter().map(|&v| v as f64).collect(),
        ),
        ("queries", vec![q, 8], &queries),
        ("expected", vec![q, 4], &expected),
        ("denominator", vec![q, 3], &denominator),
        ("tolerance", vec![q], &tolerance),
    ] {
        std::fs::write(
            inputs.path().join(format!("{name}.npy")),
            npy_f64_bytes(&shape, data),
        )
        .unwrap();
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/run_glsl.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(repo_shaders().join("photometeor.comp.glsl"))
        .arg(inputs.path())
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e})"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}");
    assert!(
        out.status.success() && stdout.contains("\nOK: "),
        "{}\n{stdout}\n{}\n(needs `python3 -m pip install moderngl numpy` and Debian's libegl1 \
         libgl1-mesa-dri)",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}
