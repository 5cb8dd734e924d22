//! The translated sampling functions (`runtime::shaders`): the files checked in under
//! `shaders/` are what `photometeor shaders` writes today, and each one passes a real
//! validator: glslangValidator (GLSL 450 and ES 310) and spirv-val (SPIR-V), from Debian's
//! glslang-tools and spirv-tools, which the README's test command installs. HLSL and MSL have
//! no validator there: naga's own round trip checks the module they come from (WGSL → IR →
//! WGSL → IR, validated both times), and their text must carry the entry point and bindings.

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
        "register(u1, space1)",
    ] {
        assert!(hlsl.contains(want), "HLSL lacks {want:?}");
    }
    let msl = std::fs::read_to_string(at("photometeor.metal")).unwrap();
    for want in [
        "kernel void evaluate_queries(",
        "ams_table [[texture(0)]]",
        "results [[buffer(4)]]",
        "_buffer_sizes [[buffer(5)]]",
    ] {
        assert!(msl.contains(want), "MSL lacks {want:?}");
    }
    // The three functions survive into every text output (under naga's names).
    for name in [
        "photometeor.hlsl",
        "photometeor.comp.glsl",
        "photometeor.metal",
    ] {
        let text = std::fs::read_to_string(at(name)).unwrap();
        for f in ["ams(", "forward_fraction(", "ams_mix("] {
            assert!(text.contains(f), "{name} lacks {f}");
        }
    }
}

/// The checked-in GLSL 450 (`shaders/photometeor.comp.glsl`, what Godot- or OpenGL-based
/// engines include), compiled by an OpenGL driver (Mesa's llvmpipe, headless through EGL, via
/// the `moderngl` package; runtime/tests/run_glsl.py) and run on the tables `GpuTables`
/// uploads, against the CPU sampler on a few thousand queries: the same inputs as the WGSL on
/// wgpu (tests/gpu.rs, f32 against f64); measured worst 1.6·10⁻⁵ relative.
#[test]
fn the_glsl_runs_in_opengl_and_matches_the_cpu_sampler() {
    use format::export::npy_f64_bytes;
    use runtime::sample::{ams, forward_fraction};
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
    let (mut queries, mut expected, mut scale) = (Vec::new(), Vec::new(), Vec::new());
    for (field, f) in tables.fields.iter().enumerate() {
        let top = f.image.row(1, 0).iter().copied().fold(0.0, f64::max);
        for n in [0.5f32, 1.0, 1.5, 2.75, 6.0, 9.0] {
            for i in 0..=400 {
                let cos = (i as f64 * 0.45).to_radians().cos() as f32;
                queries.extend([field as f64, n as f64, cos as f64, 0.0]);
                let a = ams(f, tables.theta_step_deg, n as f64, cos as f64);
                expected.extend([a[0], a[1], a[2], forward_fraction(f, n as f64)[1]]);
                scale.push(top);
            }
        }
    }
    let q = scale.len();
    let inputs = tempfile::tempdir().unwrap();
    for (name, shape, data) in [
        ("texture", vec![layers, n_stride, k_len, 4], &texture),
        ("forward_fraction", vec![layers * n_stride, 4], &ff),
        ("field_info", vec![layers, 4], &info),
        ("params", vec![4], &params.to_vec()),
        ("queries", vec![q, 4], &queries),
        ("expected", vec![q, 4], &expected),
        ("scale", vec![q], &scale),
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
        .arg("3e-5")
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e})"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}");
    assert!(
        out.status.success() && stdout.starts_with("OK"),
        "{}\n{stdout}\n{}\n(needs `python3 -m pip install moderngl numpy` and Debian's libegl1 \
         libgl1-mesa-dri)",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}
