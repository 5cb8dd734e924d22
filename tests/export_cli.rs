//! `photometeor export`: every format written from one small bake, read back by independent
//! readers (the `ktx2` crate here; NumPy, OpenEXR and Mitsuba 3 in tests/check_export.py), its
//! reported cost recomputed, and bad arguments refused before anything is written.

// Table-driven end-to-end tests read best whole: the 120-line bound on functions
// (clippy.toml) holds for library and binary code.
#![allow(clippy::too_many_lines)]

mod common;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use common::{photometeor, workdir};
use runtime::Tables;
use runtime::export::{cost, resample};

const SCENE: &str = "[scene]\nname = \"x\"\nspectral = \"rgb3\"\nn_max = 4\nquality = \"draft\"\n\n[[field]]\nname = \"cloud\"\nkind = \"cloud\"\ndistribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }\n\n[[field]]\nname = \"rain\"\nkind = \"rain\"\ndistribution = { kind = \"lognormal\", median_radius_um = 500, sigma_g = 1.4 }\n";

/// One small bake (cloud and rain, rgb3, 4 orders) shared by the tests.
fn bake() -> &'static PathBuf {
    static BAKE: OnceLock<PathBuf> = OnceLock::new();
    BAKE.get_or_init(|| {
        let root = workdir("export_bake");
        let scene = root.join("scene.toml");
        fs::write(&scene, SCENE).unwrap();
        let out = root.join("tables");
        let o = photometeor(
            &[
                "bake",
                scene.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--quiet",
            ],
            Path::new("."),
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out
    })
}

fn export(args: &[&str]) -> std::process::Output {
    let mut all = vec!["export", bake().to_str().unwrap()];
    all.extend_from_slice(args);
    photometeor(&all, Path::new("."))
}

fn ok(o: &std::process::Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(dir.join("export.json")).unwrap()).unwrap()
}

fn row(t: &Tables, field: &str, c: usize, n: usize) -> Vec<f64> {
    let f = t.field(field).unwrap();
    (0..t.angle_count)
        .map(|k| f.image.ams[[c, n - 1, k]])
        .collect()
}

#[test]
fn bevy_ktx2_reads_back_with_the_ktx2_crate_and_the_reported_cost_is_the_cost() {
    let out = workdir("export_bevy").join("bevy");
    let text = ok(&export(&[
        "--format",
        "bevy",
        "--out",
        out.to_str().unwrap(),
        "--orders",
        "1,4",
        "--samples",
        "2049",
        "--forward-peak",
        "keep",
    ]));
    let t = Tables::open(bake()).unwrap();
    let r = report(&out);
    for field in ["cloud", "rain"] {
        let n = r["fields"][field]["samples"].as_u64().unwrap() as usize;
        for order in [1usize, 4] {
            let bytes = fs::read(out.join(format!("{field}.ams{order}.ktx2"))).unwrap();
            let k = ktx2::Reader::new(&bytes[..]).expect("a valid KTX2 file");
            let h = k.header();
            assert_eq!(h.format, Some(ktx2::Format::R32G32B32A32_SFLOAT));
            assert_eq!((h.pixel_width as usize, h.pixel_height), (n, 1));
            assert_eq!((h.level_count, h.face_count, h.layer_count), (1, 1, 0));
            assert!(h.supercompression_scheme.is_none());
            assert_eq!(k.color_model(), Some(ktx2::ColorModel::RGBSDA));
            assert_eq!(k.transfer_function(), Some(ktx2::TransferFunction::Linear));
            assert_eq!(k.color_primaries(), Some(ktx2::ColorPrimaries::BT709));
            let samples = &k.basic_dfd().unwrap().sample_information;
            assert_eq!(samples.len(), 4);
            for s in samples {
                assert_eq!(s.bit_length.get(), 32);
                assert!(
                    s.channel_type_qualifiers
                        .contains(ktx2::dfd::ChannelTypeQualifiers::FLOAT)
                );
            }
            assert!(k.writer().unwrap().starts_with("photometeor"));
            let data = k.levels().next().unwrap().data;
            assert_eq!(data.len(), 16 * n);
            let texel = |i: usize, c: usize| {
                let o = 16 * i + 4 * c;
                f32::from_le_bytes(data[o..o + 4].try_into().unwrap())
            };
            for c in 0..3 {
                let ours = row(&t, field, c, order);
                let want = resample(&ours, t.theta_step_deg, n);
                for i in 0..n {
                    assert_eq!(texel(i, c), want[i] as f32, "{field} {order} {c} {i}");
                }
                assert_eq!(texel(0, 3), 1.0);
                // The reported cost is the cost of what was written.
                let got = cost(&ours, t.theta_step_deg, &want);
                let rep = &r["fields"][field]["orders"][order.to_string()]["channels"]
                    [["R", "G", "B"][c]];
                assert_eq!(rep["moved"].as_f64().unwrap(), got.moved);
                assert!(got.energy_change.abs() < 1e-9, "{got:?}");
            }
        }
    }
    assert!(
        text.contains("moved") && text.contains("forward peak kept"),
        "{text}"
    );
}

#[test]
fn the_default_sample_count_keeps_the_moved_light_under_max_loss_where_the_limit_allows() {
    let out = workdir("export_choose").join("m");
    let text = ok(&export(&[
        "--format",
        "mitsuba",
        "--out",
        out.to_str().unwrap(),
        "--fields",
        "cloud",
        "--max-loss",
        "0.05",
        "--forward-peak",
        "keep",
    ]));
    let r = report(&out);
    let n = r["fields"]["cloud"]["samples"].as_u64().unwrap() as usize;
    let worst = ["R", "G", "B"]
        .iter()
        .map(|c| {
            r["fields"]["cloud"]["orders"]["1"]["channels"][c]["moved"]
                .as_f64()
                .unwrap()
        })
        .fold(0.0, f64::max);
    assert!(worst <= 0.05 && n < (1 << 18) + 1, "{n} {worst}\n{text}");
    // Half the samples would not do.
    let t = Tables::open(bake()).unwrap();
    let half = (n - 1) / 2 + 1;
    let worse = (0..3)
        .map(|c| {
            let r = row(&t, "cloud", c, 1);
            cost(&r, t.theta_step_deg, &resample(&r, t.theta_step_deg, half)).moved
        })
        .fold(0.0, f64::max);
    assert!(worse > 0.05, "{half}: {worse}");
    // Rain's forward peak (inside the first 0.09°) is what a grid in cos θ cannot hold: it
    // is reported above the bound, and --forward-peak strip takes it out with the scaled
    // optics to use.
    let rain = workdir("export_rain").join("m");
    let text = ok(&export(&[
        "--format",
        "mitsuba",
        "--out",
        rain.to_str().unwrap(),
        "--fields",
        "rain",
        "--samples",
        "4097",
        "--forward-peak",
        "keep",
    ]));
    assert!(text.contains("above --max-loss"), "{text}");
    let strip = workdir("export_strip").join("m");
    ok(&export(&[
        "--format",
        "mitsuba",
        "--out",
        strip.to_str().unwrap(),
        "--fields",
        "rain",
        "--samples",
        "4097",
        "--forward-peak",
        "strip",
    ]));
    let (keep, strip) = (report(&rain), report(&strip));
    let ch = |r: &serde_json::Value, k: &str| {
        r["fields"]["rain"]["orders"]["1"]["channels"]["G"][k].clone()
    };
    let f = ch(&strip, "forward_peak_stripped").as_f64().unwrap();
    assert!(f > 0.3 && f < 0.6, "{f}");
    assert!(ch(&strip, "moved").as_f64().unwrap() < 0.2 * ch(&keep, "moved").as_f64().unwrap());
    let t = Tables::open(bake()).unwrap();
    let rf = t.field("rain").unwrap();
    let scaled = ch(&strip, "scaled_sigma_ext_m2").as_f64().unwrap();
    assert!((scaled - rf.sigma_ext_m2[1] * (1.0 - rf.albedo[1] * f)).abs() < 1e-12 * scaled);
}

#[test]
fn numpy_openexr_and_mitsuba_read_the_exports() {
    let root = workdir("export_consumers");
    let dirs: Vec<PathBuf> = ["npy", "mitsuba", "bevy"]
        .iter()
        .map(|f| root.join(f))
        .collect();
    ok(&export(&[
        "--format",
        "npy",
        "--out",
        dirs[0].to_str().unwrap(),
        "--orders",
        "1,2",
    ]));
    for (i, format) in [(1, "mitsuba"), (2, "bevy")] {
        ok(&export(&[
            "--format",
            format,
            "--out",
            dirs[i].to_str().unwrap(),
            "--orders",
            "1,2",
            "--samples",
            "4097",
            "--forward-peak",
            "keep",
        ]));
    }
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/check_export.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(bake())
        .args(&dirs)
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 ({e})"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}");
    assert!(
        out.status.success() && stdout.starts_with("OK"),
        "{}\n{stdout}\n{}\n(needs `python3 -m pip install OpenEXR numpy mitsuba`)",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    // CSV: a header and one line per θ bin, the first column θ.
    let csv_dir = root.join("csv");
    ok(&export(&[
        "--format",
        "csv",
        "--out",
        csv_dir.to_str().unwrap(),
    ]));
    let csv = fs::read_to_string(csv_dir.join("cloud.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "theta_deg,ams1_R,ams1_G,ams1_B");
    let t = Tables::open(bake()).unwrap();
    assert_eq!(lines.len(), 1 + t.angle_count);
    let last: Vec<f64> = lines[t.angle_count]
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(last[0], 180.0);
    assert_eq!(last[2], row(&t, "cloud", 1, 1)[t.angle_count - 1]);
}

#[test]
fn bad_arguments_are_refused_naming_the_value_and_nothing_is_written() {
    let root = workdir("export_refusals");
    let out = root.join("x");
    let cases: &[(&[&str], &str)] = &[
        (
            &["--format", "bevy", "--max-loss", "0"],
            "--max-loss 0 is outside (0, 1)",
        ),
        (
            &["--format", "bevy", "--orders", "0"],
            "n = 0 is outside [1, 4]",
        ),
        (
            &["--format", "bevy", "--orders", "5"],
            "n = 5 is outside [1, 4]",
        ),
        (
            &["--format", "bevy", "--fields", "fog"],
            "no field or sweep \"fog\"",
        ),
        (
            &["--format", "bevy", "--samples", "9000"],
            "--samples 9000 is outside [2, 8192]",
        ),
        (
            &["--format", "npy", "--samples", "100"],
            "--samples applies to bevy and mitsuba",
        ),
        (
            &[
                "--format",
                "bevy",
                "--fields",
                "rain",
                "--forward-peak",
                "keep",
            ],
            "--max-loss 0.01 cannot be met for field \"rain\" within 8192 values, the bevy limit",
        ),
    ];
    for (args, want) in cases {
        let mut all = args.to_vec();
        all.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let o = export(&all);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(want), "{args:?}: {e}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // A directory that is not a bake, and a format that does not exist.
    let not_bake = root.join("empty");
    fs::create_dir_all(&not_bake).unwrap();
    for (args, want) in [
        (
            vec!["export", not_bake.to_str().unwrap(), "--format", "csv"],
            "manifest.json",
        ),
        (
            vec!["export", bake().to_str().unwrap(), "--format", "fbx"],
            "invalid value 'fbx'",
        ),
    ] {
        let mut args = args;
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let o = photometeor(&args, Path::new("."));
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(want), "{args:?}: {e}");
        assert!(!out.exists());
    }
    // A directory that is not an earlier export is not replaced.
    fs::create_dir_all(&out).unwrap();
    fs::write(out.join("mine.txt"), "keep").unwrap();
    let o = export(&["--format", "csv", "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("non-empty directory"));
    assert_eq!(fs::read_to_string(out.join("mine.txt")).unwrap(), "keep");
    // An earlier export is.
    let again = root.join("again");
    ok(&export(&[
        "--format",
        "csv",
        "--out",
        again.to_str().unwrap(),
    ]));
    ok(&export(&[
        "--format",
        "npy",
        "--out",
        again.to_str().unwrap(),
    ]));
    assert!(again.join("cloud.ams.npy").exists() && !again.join("cloud.csv").exists());
    let leftovers: Vec<_> = fs::read_dir(&root)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// The Bevy export sampled on a GPU (lavapipe in CI) by the WGSL function it ships
/// (`phase_curve.wgsl`), the texture uploaded from the KTX2 file's own level data, against the
/// CPU reading of the same curve (`runtime::export::reconstruct`) and, as a figure, against
/// the bake's own sampler.
#[test]
fn the_bevy_texture_sampled_by_its_wgsl_on_a_gpu_matches_the_cpu() {
    let gpu = match runtime::gpu::Gpu::new() {
        Ok(g) => g,
        Err(e) if std::env::var("REQUIRE_GPU").as_deref() == Ok("1") => {
            panic!("REQUIRE_GPU=1 but {e}")
        }
        Err(e) => {
            eprintln!("skipped, {e}");
            return;
        }
    };
    eprintln!("adapter: {}", gpu.describe());
    let out = workdir("export_gpu").join("bevy");
    ok(&export(&[
        "--format",
        "bevy",
        "--out",
        out.to_str().unwrap(),
        "--fields",
        "cloud",
        "--samples",
        "8192",
        "--forward-peak",
        "keep",
    ]));
    let snippet = fs::read_to_string(out.join("phase_curve.wgsl")).unwrap();
    let bytes = fs::read(out.join("cloud.ams1.ktx2")).unwrap();
    let k = ktx2::Reader::new(&bytes[..]).unwrap();
    let n = k.header().pixel_width;
    let data = k.levels().next().unwrap().data;
    let device = &gpu.device;
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("phase curve"),
        size: wgpu::Extent3d {
            width: n,
            height: 1,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    gpu.queue.write_texture(
        texture.as_image_copy(),
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(16 * n),
            rows_per_image: Some(1),
        },
        wgpu::Extent3d {
            width: n,
            height: 1,
            depth_or_array_layers: 1,
        },
    );
    // Angles from exactly 0° to 180°, dense near the forward peak.
    let cosines: Vec<f32> = (0..=4000)
        .map(|i| {
            let theta = 180.0 * (i as f64 / 4000.0).powi(2);
            theta.to_radians().cos() as f32
        })
        .collect();
    let source = format!(
        "{snippet}
@group(0) @binding(0) var curve: texture_2d<f32>;
@group(0) @binding(1) var<storage, read> cosines: array<f32>;
@group(0) @binding(2) var<storage, read_write> results: array<vec4<f32>>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {{
    if id.x >= arrayLength(&cosines) {{ return; }}
    results[id.x] = vec4<f32>(phase_curve(curve, cosines[id.x]), 1.0);
}}
"
    );
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("phase curve"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("phase curve"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    use wgpu::util::DeviceExt;
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("cosines"),
        contents: &cosines
            .iter()
            .flat_map(|c| c.to_le_bytes())
            .collect::<Vec<u8>>(),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = 16 * cosines.len() as u64;
    let results = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("results"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let view = texture.create_view(&Default::default());
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("phase curve"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(&view),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: results.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(cosines.len().div_ceil(64) as u32, 1, 1);
    }
    gpu.queue.submit([encoder.finish()]);
    let got = runtime::gpu::read_back(&gpu, &results, size).unwrap();
    let t = Tables::open(bake()).unwrap();
    let field = t.field("cloud").unwrap();
    let (mut worst, mut worst_table) = (0.0f64, 0.0f64);
    for c in 0..3 {
        let ours = row(&t, "cloud", c, 1);
        let values: Vec<f64> = resample(&ours, t.theta_step_deg, n as usize)
            .iter()
            .map(|&v| v as f32 as f64)
            .collect();
        let top = values.iter().copied().fold(0.0, f64::max);
        for (i, &mu) in cosines.iter().enumerate() {
            let want = runtime::export::reconstruct(&values, mu as f64);
            // The shader finds the column in f32: u = (μ + 1)/2 (n − 1) is off by up to
            // ~n 2⁻²⁴ columns, which moves the value by that share of the column's step.
            let u = ((mu as f64 + 1.0) / 2.0 * (n - 1) as f64).min((n - 2) as f64);
            let step = (values[u as usize + 1] - values[u as usize]).abs();
            let position = 4.0 * n as f64 * 2f64.powi(-24) * step;
            let err = ((got[i][c] as f64 - want).abs() - position).max(0.0) / (want + 1e-7 * top);
            worst = worst.max(err);
            let table = runtime::sample::ams(field, t.theta_step_deg, 1.0, mu as f64)[c];
            worst_table = worst_table.max((want - table).abs() / table);
        }
    }
    eprintln!(
        "{} texels, {} angles: GPU vs CPU curve {worst:.1e} beyond the f32 column position; the curve against the bake's sampler \
         up to {:.1} % (the resampling, reported as `moved`)",
        n,
        cosines.len(),
        worst_table * 100.0
    );
    assert!(worst < 2e-7, "{worst}");
}

#[test]
fn hg_lobes_are_fitted_with_what_they_lose() {
    let out = workdir("export_hg").join("hg");
    let text = ok(&export(&["--format", "hg", "--out", out.to_str().unwrap()]));
    let r = report(&out);
    let t = Tables::open(bake()).unwrap();
    for field in ["cloud", "rain"] {
        assert!(out.join(format!("{field}.lobes.png")).exists());
        for (c, ch) in ["R", "G", "B"].iter().enumerate() {
            let e = &r["fields"][field]["orders"]["1"]["channels"][ch];
            let moved = |k: &str| e[k]["moved"].as_f64().unwrap();
            // The table's own g, and two fits that each do at least as well as the one before.
            let g = runtime::export::asymmetry(&row(&t, field, c, 1), t.theta_step_deg);
            assert_eq!(e["hg_at_g"]["g1"].as_f64().unwrap(), g);
            assert!(
                moved("hg") <= moved("hg_at_g") && moved("dual_hg") <= moved("hg"),
                "{e}"
            );
            assert!(moved("dual_hg") > 0.0 && moved("hg_at_g") < 1.0);
        }
    }
    // HG has no rainbow: a lobe keeps little of the bow's height.
    let bow = r["fields"]["rain"]["orders"]["1"]["channels"]["G"]["hg"]["features"]
        ["primary rainbow"]["kept"]
        .as_f64()
        .unwrap();
    assert!(bow < 0.5, "{bow}");
    assert!(text.contains("best dual HG"), "{text}");
}

/// What inspect, validate, compare and export print is written for people: no Rust debug
/// formatting of options or structs (`Some(102)`, "ring at None°").
#[test]
fn user_output_has_no_debug_formatting() {
    let d = bake().to_str().unwrap();
    let root = workdir("export_words");
    let mut runs: Vec<Vec<String>> = [
        vec!["inspect", d],
        vec!["validate", d],
        vec!["compare", d, d],
    ]
    .into_iter()
    .map(|a| a.into_iter().map(String::from).collect())
    .collect();
    for format in ["bevy", "mitsuba", "npy", "csv", "hg"] {
        let out = root.join(format);
        runs.push(
            [
                "export",
                d,
                "--format",
                format,
                "--out",
                out.to_str().unwrap(),
            ]
            .map(String::from)
            .to_vec(),
        );
    }
    for args in runs {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = photometeor(&args, Path::new("."));
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(!text.is_empty(), "{args:?} printed nothing");
        for debug in ["Some(", "None"] {
            assert!(!text.contains(debug), "{args:?} prints {debug:?}:\n{text}");
        }
    }
}

/// With its defaults, export succeeds for every format, choosing per field the forward-peak
/// treatment and sample count that meet --max-loss, and says which it chose; a stripped peak's
/// Mitsuba medium carries the δ-scaled optics.
#[test]
fn every_format_succeeds_with_its_defaults_and_reports_its_choice() {
    let root = workdir("export_defaults");
    for format in ["bevy", "mitsuba", "npy", "csv", "hg"] {
        let out = root.join(format);
        let text = ok(&export(&[
            "--format",
            format,
            "--out",
            out.to_str().unwrap(),
        ]));
        let r = report(&out);
        assert_eq!(r["forward_peak"], "auto", "{format}");
        for field in ["cloud", "rain"] {
            let f = &r["fields"][field];
            if format == "hg" {
                continue;
            }
            let treatment = f["forward_peak"].as_str().unwrap();
            let samples = f["samples"].as_u64().unwrap();
            assert!(
                text.contains(&format!("forward peak {treatment}"))
                    || format == "npy"
                    || format == "csv",
                "{format}: {text}"
            );
            if format == "bevy" || format == "mitsuba" {
                let moved = ["R", "G", "B"]
                    .iter()
                    .map(|c| f["orders"]["1"]["channels"][c]["moved"].as_f64().unwrap())
                    .fold(0.0, f64::max);
                // Met, or written with its loss reported.
                let line = text
                    .lines()
                    .find(|l| l.starts_with(field) && l.contains("Ams_1 "))
                    .unwrap();
                assert!(
                    moved <= 0.01 || line.contains("above --max-loss"),
                    "{format} {field}: {treatment} {samples}: {moved}\n{text}"
                );
            } else {
                assert_eq!(treatment, "keep", "{format} {field}");
            }
        }
    }
    // The rain's peak cannot be held by a grid in cos θ: it is stripped, and the medium takes
    // the scaled optics the report gives.
    let r = report(&root.join("mitsuba"));
    assert_eq!(r["fields"]["rain"]["forward_peak"], "strip");
    let g = &r["fields"]["rain"]["orders"]["1"]["channels"]["G"];
    let xml = fs::read_to_string(root.join("mitsuba/rain.xml")).unwrap();
    let sigma_t = format!("{:.6e}", g["scaled_sigma_ext_m2"].as_f64().unwrap());
    let albedo = format!("{:.6}", g["scaled_albedo"].as_f64().unwrap());
    assert!(
        xml.contains(&sigma_t) && xml.contains(&albedo),
        "{sigma_t} {albedo}\n{xml}"
    );
}

/// A swept field exports as one axis: `--fields cloud` (the sweep's name) takes its members,
/// npy stacks their arrays in the order of their values into `cloud.ams.npy` (values × orders ×
/// R, G, B × θ) beside `cloud.values.npy`, and export.json names the axis with what a shader's
/// `ams_sweep` takes.
#[test]
fn a_sweep_exports_as_one_axis() {
    let root = workdir("export_sweep");
    let scene = root.join("scene.toml");
    fs::write(
        &scene,
        SCENE.replace(
            "r_eff_um = 8, v_eff = 0.1 }",
            "r_eff_um = 8, v_eff = 0.1 }\nsweep = { key = \"r_eff_um\", from = 4, to = 16, count = 3 }",
        ),
    )
    .unwrap();
    let tables = root.join("tables");
    let (s, t) = (scene.to_str().unwrap(), tables.to_str().unwrap());
    ok(&photometeor(
        &["bake", s, "--out", t, "--quiet"],
        Path::new("."),
    ));
    let out = root.join("npy");
    let args = [
        "export", t, "--format", "npy", "--fields", "cloud", "--orders", "1,3",
    ];
    let printed = ok(&photometeor(
        &[&args[..], &["--out", out.to_str().unwrap()]].concat(),
        Path::new("."),
    ));
    assert!(
        printed.contains("cloud: sweep over r_eff_um (3 values) as one axis"),
        "{printed}"
    );
    let data = |name: &str| {
        let bytes = fs::read(out.join(name)).unwrap();
        let header = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        (
            String::from_utf8_lossy(&bytes[10..10 + header]).into_owned(),
            bytes[10 + header..].to_vec(),
        )
    };
    let (header, stacked) = data("cloud.ams.npy");
    let k = Tables::open(&tables).unwrap().angle_count;
    assert!(header.contains(&format!("(3, 2, 3, {k})")), "{header}");
    let members: Vec<u8> = (0..3)
        .flat_map(|m| data(&format!("cloud@{m:02}.ams.npy")).1)
        .collect();
    assert_eq!(stacked, members);
    assert!(
        !out.join("rain.ams.npy").exists(),
        "--fields cloud exported rain"
    );
    let r = report(&out);
    let sweep = &r["sweeps"]["cloud"];
    assert_eq!(
        sweep["members"],
        serde_json::json!(["cloud@00", "cloud@01", "cloud@02"])
    );
    let values: Vec<f64> = serde_json::from_value(sweep["values"].clone()).unwrap();
    assert!((values[0] - 4.0).abs() < 1e-12 && (values[2] - 16.0).abs() < 1e-12);
    assert!(
        (sweep["at_step"].as_f64().unwrap() - 2f64.ln()).abs() < 1e-12,
        "{sweep}"
    );
    let (values_header, _) = data("cloud.values.npy");
    assert!(values_header.contains("(3,)"), "{values_header}");
    // An unknown name is refused with the fields and sweeps the bake has.
    let bad = photometeor(
        &[
            "export",
            t,
            "--format",
            "npy",
            "--fields",
            "fog",
            "--out",
            root.join("bad").to_str().unwrap(),
        ],
        Path::new("."),
    );
    let e = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && e.contains("cloud@02, rain, cloud"),
        "{e}"
    );
}
