//! The translated sampling functions (`runtime::shaders`): the files checked in under
//! `shaders/` are what `photometeor shaders` writes today, and each one passes a real
//! validator: glslangValidator (GLSL 450 and ES 310) and spirv-val (SPIR-V), from Debian's
//! glslang-tools and spirv-tools, which the README's test command installs. HLSL and MSL have
//! no validator there: naga's own round trip checks the module they come from (WGSL → IR →
//! WGSL → IR, validated both times), and their text must carry the entry point and bindings.

use std::path::{Path, PathBuf};
use std::process::Command;

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
