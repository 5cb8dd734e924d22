//! The sampling functions in every engine's shading language, from the one WGSL source
//! ([`crate::gpu::WGSL`]): translated by naga (the translator inside wgpu, used as a
//! library) to HLSL (shader model 5.1), GLSL 450 and GLSL ES 310, MSL 2.0 and SPIR-V 1.0.
//!
//! GLSL and SPIR-V are written per entry point, so the module carries one, the reference
//! compute kernel `evaluate_queries` (what [`crate::gpu::evaluate`] runs: for each query it
//! writes Ams_n(θ) R, G, B and F_n G, or a Poisson mixture M(D, θ), or Biri's kernel primitive
//! C(τ_h, θ), or a swept field's Ams_n(θ) between its members), and the functions `ams`,
//! `forward_fraction`, `ams_mix`, `poisson`, `biri_primitive`, `ams_sweep` and
//! `forward_fraction_sweep` come with it. Each text file starts with a header stating
//! the bindings it expects (those of `runtime::gpu`'s bind group 0 and the kernel's group 1).

use naga::back::{glsl, hlsl, msl, spv};
use naga::valid::{Capabilities, ModuleInfo, ValidationFlags, Validator};

/// The reference kernel appended to the sampling functions.
pub const QUERY_KERNEL: &str = r#"
@group(1) @binding(0) var<storage, read> queries: array<vec4<f32>>;
@group(1) @binding(1) var<storage, read_write> results: array<vec4<f32>>;

// Each query is two vec4: (field, a, b, kind) and (c, d, e, f). Kind 0: (a, b) = (n, cos θ),
// Ams_n(θ) R, G, B and F_n G; kind 1: (a, b) = (D, cos θ), M(D, θ) R, G, B and 0; kind 2:
// (a, b) = (τ_h, θ in radians), C(τ_h, θ) R, G, B and 0; kind 3: a swept field whose members
// start at layer `field`, (a, b) = (n, cos θ), (c, d, e, f) = (count, at_first, at_step,
// at_value), ams_sweep R, G, B and forward_fraction_sweep G.
@compute @workgroup_size(64)
fn evaluate_queries(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= arrayLength(&queries) / 2u) {
        return;
    }
    let q = queries[2u * i];
    let x = queries[2u * i + 1u];
    let field = u32(q.x);
    switch u32(q.w) {
        case 1u: {
            results[i] = vec4<f32>(poisson(field, vec3<f32>(q.y), q.z), 0.0);
        }
        case 2u: {
            results[i] = vec4<f32>(biri_primitive(field, vec3<f32>(q.y), q.z), 0.0);
        }
        case 3u: {
            let count = u32(x.x);
            results[i] = vec4<f32>(ams_sweep(field, count, x.y, x.z, x.w, q.y, q.z),
                forward_fraction_sweep(field, count, x.y, x.z, x.w, q.y).g);
        }
        default: {
            results[i] = vec4<f32>(ams(field, q.y, q.z), forward_fraction(field, q.y).g);
        }
    }
}
"#;

/// The entry point of [`QUERY_KERNEL`].
pub const ENTRY_POINT: &str = "evaluate_queries";

/// The bindings every output expects, as its header says.
pub const BINDINGS: &str = "\
Bindings, as WGSL group/binding. HLSL: register(t|b|u<binding>, space<group>). SPIR-V:
DescriptorSet = group, Binding = binding. GLSL: layout(binding = i), i = 0..7 in the order
below. MSL: [[texture(0)]] ams_table, [[texture(1)]] model_table, [[buffer(0..5)]] the other
six in this order, [[buffer(6)]] the array sizes naga adds (uint per runtime-sized buffer).
  group 0 binding 0  ams_table             2-D float texture array, K x N texels, one layer per
                                           field; texel (k, r) = Ams_{r+1}(k * step) R, G, B (1/sr)
  group 0 binding 1  ams_forward_fraction  storage buffer of vec4: [field * n_stride + n - 1] = F_n
  group 0 binding 2  ams_field_info        storage buffer of vec4: [field] = (N, sigma_sca R, G, B)
  group 0 binding 3  ams_params            uniform: angle_count, n_stride, field_count, pad,
                                           inv_step_rad (1/rad), 3 pads
  group 0 binding 4  model_table           2-D float texture array, K x (J_P + J_B) texels, one
                                           layer per field; rows 0..J_P: M(D_j, k * step), rows
                                           J_P..: Biri's C(tau_j, k * step - 90 deg), R, G, B
  group 0 binding 5  model_depths          storage buffer of float: [4 field + 0..3] = (J_P, J_B,
                                           first Poisson depth, first Biri depth), then depths
  group 1 binding 0  queries               storage buffer of vec4, two per query: (field, a, b,
                                           kind), (c, d, e, f) (the kernel's comment)
  group 1 binding 1  results               storage buffer of vec4 (kind 0: Ams R, G, B, F_n G;
                                           kind 1: M R, G, B, 0; kind 2: C R, G, B, 0; kind 3:
                                           swept Ams R, G, B, F_n G)
Functions: ams(field, n, cos_theta) -> rgb, forward_fraction(field, n) -> rgb,
ams_mix(densities, n, cos_theta) -> rgb (Riley et al. 2004 Eq. 6), poisson(field, depth_rgb,
cos_theta) -> rgb (Max et al. 2004 Eqs. 8-9), biri_primitive(field, tau_h_rgb, theta_rad) -> rgb
(Biri et al. 2006 Eq. 2), ams_sweep(first, count, at_first, at_step, at_value, n, cos_theta)
-> rgb and forward_fraction_sweep(…, n) -> rgb (a swept field between its members).
Specification: runtime/src/sample.rs. Generated by `photometeor
shaders` from runtime/src/tables.wgsl; do not edit.";

/// Why a translation failed (naga's message).
#[derive(Debug, thiserror::Error)]
#[error("{stage}: {message}")]
pub struct ShaderError {
    /// Parsing, validation, or the backend.
    pub stage: &'static str,
    /// naga's error.
    pub message: String,
}

fn err(stage: &'static str) -> impl Fn(String) -> ShaderError {
    move |message| ShaderError { stage, message }
}

/// The WGSL the outputs are translated from: the sampling functions and the kernel.
pub fn source() -> String {
    format!("{}\n{QUERY_KERNEL}", crate::gpu::WGSL)
}

/// Parses and validates `wgsl`.
pub fn module(wgsl: &str) -> Result<(naga::Module, ModuleInfo), ShaderError> {
    let module = naga::front::wgsl::parse_str(wgsl)
        .map_err(|e| err("WGSL parse")(e.emit_to_string(wgsl)))?;
    let info = Validator::new(ValidationFlags::all(), Capabilities::empty())
        .validate(&module)
        .map_err(|e| err("validation")(e.emit_to_string(wgsl)))?;
    Ok((module, info))
}

/// One output file: its name and bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Output {
    /// File name, e.g. `photometeor.hlsl`.
    pub name: &'static str,
    /// Its contents.
    pub bytes: Vec<u8>,
}

fn header(comment: &str, language: &str) -> String {
    let mut out = format!("{comment} photometeor sampling functions, {language}.\n");
    for line in BINDINGS.lines() {
        out += &format!("{comment} {line}\n");
    }
    out + "\n"
}

/// The resources in the order of [`BINDINGS`].
const RESOURCES: [(u32, u32); 8] = [
    (0, 0),
    (0, 1),
    (0, 2),
    (0, 3),
    (0, 4),
    (0, 5),
    (1, 0),
    (1, 1),
];

/// The two textures of [`RESOURCES`] (`ams_table`, `model_table`), in order.
const TEXTURES: [(u32, u32); 2] = [(0, 0), (0, 4)];

/// The one writable resource of [`RESOURCES`] (`results`).
const WRITABLE: (u32, u32) = (1, 1);

/// MSL slots: the textures [[texture(0, 1)]], the other resources [[buffer(0..5)]] in the order
/// of [`RESOURCES`], and the array sizes naga adds [[buffer(6)]].
fn msl_targets() -> (Vec<(naga::ResourceBinding, msl::BindTarget)>, u8) {
    let mut buffers = 0u8;
    let targets = RESOURCES
        .iter()
        .map(|&(g, b)| {
            let target = match TEXTURES.iter().position(|&t| t == (g, b)) {
                Some(t) => msl::BindTarget {
                    texture: Some(t as u8),
                    ..Default::default()
                },
                None => {
                    buffers += 1;
                    msl::BindTarget {
                        buffer: Some(buffers - 1),
                        mutable: (g, b) == WRITABLE,
                        ..Default::default()
                    }
                }
            };
            (binding(g, b), target)
        })
        .collect();
    (targets, buffers)
}

fn binding(group: u32, binding: u32) -> naga::ResourceBinding {
    naga::ResourceBinding { group, binding }
}

fn glsl_out(
    module: &naga::Module,
    info: &ModuleInfo,
    version: glsl::Version,
) -> Result<String, ShaderError> {
    let options = glsl::Options {
        version,
        writer_flags: glsl::WriterFlags::empty(),
        binding_map: RESOURCES
            .iter()
            .enumerate()
            .map(|(i, &(g, b))| (binding(g, b), i as u8))
            .collect(),
        ..Default::default()
    };
    let pipeline = glsl::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: ENTRY_POINT.into(),
        multiview: None,
    };
    let mut text = String::new();
    glsl::Writer::new(
        &mut text,
        module,
        info,
        &options,
        &pipeline,
        naga::proc::BoundsCheckPolicies::default(),
    )
    .and_then(|mut w| w.write())
    .map_err(|e| err("GLSL")(e.to_string()))?;
    Ok(text)
}

/// Every output, deterministic: HLSL, GLSL 450, GLSL ES 310, MSL and SPIR-V.
pub fn translate() -> Result<Vec<Output>, ShaderError> {
    let wgsl = source();
    let (module, info) = module(&wgsl)?;
    let mut hlsl_text = String::new();
    let hlsl_options = hlsl::Options::default(); // shader model 5.1
    hlsl::Writer::new(
        &mut hlsl_text,
        &hlsl_options,
        &hlsl::PipelineOptions { entry_point: None },
    )
    .write(&module, &info, None)
    .map_err(|e| err("HLSL")(e.to_string()))?;
    let glsl_450 = glsl_out(&module, &info, glsl::Version::Desktop(450))?;
    let glsl_es = glsl_out(&module, &info, glsl::Version::new_gles(310))?;
    let (targets, sizes_buffer) = msl_targets();
    let (msl_text, _) = msl::write_string(
        &module,
        &info,
        &msl::Options {
            lang_version: (2, 0),
            per_entry_point_map: [(
                ENTRY_POINT.to_string(),
                msl::EntryPointResources {
                    resources: targets.into_iter().collect(),
                    sizes_buffer: Some(sizes_buffer),
                    ..Default::default()
                },
            )]
            .into_iter()
            .collect(),
            fake_missing_bindings: false,
            ..Default::default()
        },
        &msl::PipelineOptions::default(),
    )
    .map_err(|e| err("MSL")(e.to_string()))?;
    let words = spv::write_vec(
        &module,
        &info,
        &spv::Options {
            lang_version: (1, 0),
            // Explicit: naga's default adds the debug names (OpName) only in builds with debug
            // assertions, so a release `photometeor shaders` wrote other bytes than the tests.
            flags: spv::WriterFlags::ADJUST_COORDINATE_SPACE
                | spv::WriterFlags::LABEL_VARYINGS
                | spv::WriterFlags::CLAMP_FRAG_DEPTH
                | spv::WriterFlags::DEBUG,
            ..Default::default()
        },
        Some(&spv::PipelineOptions {
            shader_stage: naga::ShaderStage::Compute,
            entry_point: ENTRY_POINT.into(),
        }),
    )
    .map_err(|e| err("SPIR-V")(e.to_string()))?;
    let text = |name, comment, language, body: String| Output {
        name,
        bytes: format!("{}{body}", header(comment, language)).into_bytes(),
    };
    Ok(vec![
        text("photometeor.wgsl", "//", "WGSL (the source)", wgsl),
        text(
            "photometeor.hlsl",
            "//",
            "HLSL shader model 5.1 (compute: evaluate_queries)",
            hlsl_text,
        ),
        // GLSL's #version must be its first line: the header follows it.
        glsl_file("photometeor.comp.glsl", "GLSL 450", glsl_450),
        glsl_file("photometeor.es310.comp.glsl", "GLSL ES 3.10", glsl_es),
        text("photometeor.metal", "//", "MSL 2.0", msl_text),
        Output {
            name: "photometeor.spv",
            bytes: words.iter().flat_map(|w| w.to_le_bytes()).collect(),
        },
    ])
}

fn glsl_file(name: &'static str, language: &str, text: String) -> Output {
    let (version, rest) = text.split_once('\n').unwrap_or((&text, ""));
    Output {
        name,
        bytes: format!("{version}\n{}{rest}", header("//", language)).into_bytes(),
    }
}
