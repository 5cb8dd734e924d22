//! The crate's shape, checked on any machine (no GPU): every WGSL uniform has a Rust mirror
//! of the same size and field offsets (naga's layout of the shader each renderer compiles),
//! and no model's module names another model.

use runtime::uniform::{Uniform, check_uniform};

fn check<T: Uniform>(source: &str) {
    if let Err(e) = check_uniform::<T>(source) {
        panic!("{e}");
    }
}

#[test]
fn every_uniform_mirrors_its_wgsl_struct() {
    check::<runtime::gpu::AmsParams>(runtime::gpu::WGSL);
    check::<render::riley::gpu::RenderParams>(&render::riley::gpu::source());
    check::<render::gpu::SliceParams>(&render::riley::gpu::source());
    check::<render::miyazaki::gpu::SvsParams>(&render::miyazaki::gpu::source());
    check::<render::gpu::SliceParams>(&render::miyazaki::gpu::source());
    check::<render::max::gpu::MaxParams>(&render::max::gpu::source());
    check::<render::coupled::gpu::CoupledParams>(&render::coupled::gpu::source());
    check::<render::coupled::sweep_gpu::SweepParams>(&render::coupled::sweep_gpu::source());
    check::<render::coupled::sky_gpu::SkyParams>(&render::coupled::sky_gpu::source());
    check::<render::coupled::beam_gpu::BeamParams>(&render::coupled::beam_gpu::source());
    check::<render::biri::gpu::BiriParams>(&render::biri::gpu::source());
    check::<render::truth::gpu::TruthParams>(&render::truth::gpu::source());
    check::<render::truth::gpu::StepParams>(&render::truth::gpu::source());
}

#[test]
fn a_mirror_that_differs_from_its_wgsl_is_caught() {
    // The check itself: a field missing, moved or added on one side, named.
    runtime::uniform! {
        /// AmsParams with its padding dropped.
        pub struct Short as "AmsParams" {
            /// K.
            pub angle_count: u32,
            /// N.
            pub n_stride: u32,
            /// Fields.
            pub field_count: u32,
            /// 1/Δθ, where WGSL has pad0.
            pub inv_step_rad: f32,
        }
    }
    let e = check_uniform::<Short>(runtime::gpu::WGSL).unwrap_err();
    assert!(
        e.contains("field 3 is inv_step_rad at byte 12 in Rust, pad0"),
        "{e}"
    );
    let wider = runtime::gpu::WGSL.replace("    pad3: f32,\n", "    pad3: f32,\n    extra: f32,\n");
    let e = check_uniform::<runtime::gpu::AmsParams>(&wider).unwrap_err();
    assert!(e.contains("8 fields in Rust, 9 in WGSL"), "{e}");
}

/// The model modules: each may use the shared modules, never another model.
const MODELS: &[&str] = &["riley", "miyazaki", "max", "coupled", "biri", "truth"];

#[test]
fn no_model_names_another_model() {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut found = Vec::new();
    for model in MODELS {
        for entry in std::fs::read_dir(src.join(model)).unwrap() {
            let path = entry.unwrap().path();
            let text = std::fs::read_to_string(&path).unwrap();
            for (n, line) in text.lines().enumerate() {
                for other in MODELS.iter().filter(|m| *m != model) {
                    if line.contains(&format!("{other}::")) {
                        found.push(format!("{}:{}: {line}", path.display(), n + 1));
                    }
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "a model names another:\n{}",
        found.join("\n")
    );
    // Every model module is in the list above and in the models! list.
    for entry in std::fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            assert!(MODELS.contains(&name.as_str()), "{name} is not listed");
            assert!(
                render::model::MODEL_NAMES.contains(&name.as_str()),
                "{name}"
            );
        }
    }
}
