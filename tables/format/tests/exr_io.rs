//! The EXR contract and the manifest: round trips, attributes, byte-identical
//! output, atomic writes, the reader's checks, and an independent read of our EXR by the
//! OpenEXR reference library (`tests/exr_openexr.py`).

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

use exr::meta::MetaData;
use exr::meta::attribute::{AttributeValue, Text};
use exr::prelude::{
    AnyChannel, AnyChannels, Blocks, Compression, Encoding, FlatSamples, Image, Layer,
    LayerAttributes, LineOrder, SmallVec, Vec2, WritableImage, f16,
};
use format::exr::{
    ContractError, FieldImage, IoError, RGB_CHANNELS, attr, format_f64_list, parse_f64_list,
    read_field_exr, write_field_exr,
};
use format::manifest::{
    FieldEntry, MANIFEST_FILE, Manifest, ManifestError, PerChannel, read_manifest, write_manifest,
};
use format::sections::{Channels, Material, Microphysics, QualityRecord, SpectralSampling};
use ndarray::{Array2, Axis};
use serde_json::json;

/// K = 11 angles (Δθ = 18°), N = 3 rows.
const K: usize = 11;
const N: usize = 3;
const STEP: f64 = 18.0;

/// A small image whose values are not representable in f32 (so rounding is exercised), with
/// one extra layer.
fn sample(field: &str) -> FieldImage {
    let rows = |c: usize| -> Vec<Vec<f64>> {
        (0..N)
            .map(|r| {
                (0..K)
                    .map(|k| {
                        let x = (c * 100 + r * 10 + k) as f64;
                        (1.0 + 0.1 * x).ln() / (4.0 * std::f64::consts::PI) + 1e-9 * x
                    })
                    .collect()
            })
            .collect()
    };
    let mut image = FieldImage::from_rows(
        field,
        STEP,
        &[rows(0), rows(1), rows(2)],
        &[
            vec![0.1 + 0.2, 0.9731234567890123, 0.5],
            vec![1.0 / 3.0, 2.0 / 3.0, 5e-324],
            vec![0.99, 1e-300, 0.500000000000001],
        ],
    )
    .unwrap();
    let extra = rows(3);
    image.extra_layers = vec![(
        "lambda_550.Y".to_string(),
        Array2::from_shape_fn((N, K), |(r, k)| extra[r][k]),
    )];
    image
}

/// `image` with every texel rounded to f32, as a reader sees it.
fn rounded(image: &FieldImage) -> FieldImage {
    let round = |v: &f64| f64::from(*v as f32);
    FieldImage {
        ams: image.ams.map(round),
        extra_layers: image
            .extra_layers
            .iter()
            .map(|(n, rows)| (n.clone(), rows.map(round)))
            .collect(),
        ..image.clone()
    }
}

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn round_trip_equals_input_rounded_to_f32() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rain.exr");
    let image = sample("rain");
    write_field_exr(&path, &image).unwrap();
    let back = read_field_exr(&path).unwrap();
    assert_eq!(back, rounded(&image));
    assert_eq!(back.n_max(), N);
    assert_eq!(back.angle_count(), K);
    // F_i travels as text: bit-exact in f64, not rounded to f32.
    for c in 0..3 {
        for (a, b) in back
            .forward_fraction
            .row(c)
            .iter()
            .zip(image.forward_fraction.row(c))
        {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }
    // Only the file itself is left in the directory.
    assert_eq!(dir_entries(dir.path()), ["rain.exr"]);
}

#[test]
fn round_trip_without_extra_layers_and_non_ascii_field_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.exr");
    let image = FieldImage {
        field: "Wolke ünter δ".to_string(),
        extra_layers: Vec::new(),
        ..sample("x")
    };
    write_field_exr(&path, &image).unwrap();
    assert_eq!(read_field_exr(&path).unwrap(), rounded(&image));
}

#[test]
fn header_has_the_contract_layout_and_attributes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cloud.exr");
    write_field_exr(&path, &sample("cloud")).unwrap();
    let meta = MetaData::read_from_file(&path, true).unwrap();
    assert_eq!(meta.headers.len(), 1, "single part");
    let h = &meta.headers[0];
    assert!(!h.deep);
    assert!(matches!(h.blocks, exr::meta::BlockDescription::ScanLines));
    assert_eq!(h.layer_size, Vec2(K, N));
    assert_eq!(h.own_attributes.layer_position, Vec2(0, 0));
    let names: Vec<String> = h.channels.list.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["B", "G", "R", "lambda_550.Y"]);
    assert!(
        h.channels
            .list
            .iter()
            .all(|c| c.sample_type == exr::meta::attribute::SampleType::F32)
    );
    let get = |name: &str| {
        h.own_attributes
            .other
            .get(&Text::from(name))
            .unwrap_or_else(|| panic!("attribute {name} missing"))
            .clone()
    };
    assert_eq!(get(attr::SCHEMA), AttributeValue::I32(1));
    assert_eq!(get(attr::FIELD), AttributeValue::Text(Text::from("cloud")));
    assert_eq!(get(attr::THETA_STEP_DEG), AttributeValue::F64(STEP));
    assert_eq!(get(attr::N_MAX), AttributeValue::I32(N as i32));
    assert_eq!(
        get(attr::FORWARD_FRACTION[1]),
        AttributeValue::Text(Text::from("0.3333333333333333,0.6666666666666666,5e-324"))
    );
}

#[test]
fn same_image_gives_byte_identical_files() {
    let dir = tempfile::tempdir().unwrap();
    let image = sample("rain");
    // The exr crate keeps custom attributes in a randomly seeded HashMap; several writes
    // make an unsorted header all but certain to show up.
    let first = dir.path().join("a.exr");
    write_field_exr(&first, &image).unwrap();
    let reference = fs::read(&first).unwrap();
    for i in 0..8 {
        let p = dir.path().join(format!("b{i}.exr"));
        write_field_exr(&p, &image).unwrap();
        assert_eq!(fs::read(&p).unwrap(), reference, "write {i} differs");
    }
}

#[test]
fn f64_list_text_is_shortest_round_trip() {
    let values = [
        0.1 + 0.2,
        1e-300,
        5e-324,
        1.0,
        0.5,
        123456789.125,
        f64::MIN_POSITIVE,
    ];
    let text = format_f64_list(&values);
    assert!(!text.contains(' '));
    let back = parse_f64_list(&text).unwrap();
    assert_eq!(back.len(), values.len());
    for (a, b) in back.iter().zip(&values) {
        assert_eq!(a.to_bits(), b.to_bits());
    }
    assert_eq!(format_f64_list(&[0.25, 1.0, 1e-300]), "0.25,1.0,1e-300");
    assert!(parse_f64_list("0.5,,1").is_err());
    assert!(parse_f64_list("0.5,NaN").is_err());
    assert!(parse_f64_list("").unwrap().is_empty());
}

#[test]
fn non_finite_values_are_refused_naming_field_row_and_column_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rain.exr");
    // An older, valid file must survive a failed write untouched.
    write_field_exr(&path, &sample("rain")).unwrap();
    let before = fs::read(&path).unwrap();
    for (bad, channel, label) in [
        (f64::NAN, 1, "G"),
        (f64::INFINITY, 2, "B"),
        (1e39, 0, "R"), // finite in f64, infinite in f32
    ] {
        let mut image = sample("rain");
        image.ams[[channel, 2, 7]] = bad;
        let err = write_field_exr(&path, &image).unwrap_err();
        match &err {
            IoError::NonFinite {
                field,
                channel: c,
                row,
                column,
                ..
            } => {
                assert_eq!(
                    (field.as_str(), c.as_str(), *row, *column),
                    ("rain", label, 2, 7)
                );
            }
            other => panic!("expected NonFinite, got {other:?}"),
        }
        let msg = err.to_string();
        assert!(
            msg.contains("\"rain\"") && msg.contains("row 2") && msg.contains("column 7"),
            "{msg}"
        );
    }
    let mut image = sample("rain");
    image.extra_layers[0].1[[0, 0]] = f64::NEG_INFINITY;
    assert!(matches!(
        write_field_exr(&path, &image),
        Err(IoError::NonFinite { ref channel, .. }) if channel == "lambda_550.Y"
    ));
    assert_eq!(fs::read(&path).unwrap(), before);
    assert_eq!(dir_entries(dir.path()), ["rain.exr"]);

    // Into an empty directory: nothing at all appears.
    let empty = tempfile::tempdir().unwrap();
    let mut image = sample("rain");
    image.forward_fraction[[0, 1]] = f64::NAN;
    assert!(matches!(
        write_field_exr(empty.path().join("rain.exr"), &image),
        Err(IoError::InvalidImage { .. })
    ));
    assert!(dir_entries(empty.path()).is_empty());
}

#[test]
fn malformed_images_are_refused_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.exr");
    let expect = |image: FieldImage, needle: &str| {
        let err = write_field_exr(&path, &image).unwrap_err();
        assert!(matches!(err, IoError::InvalidImage { .. }), "{err:?}");
        assert!(err.to_string().contains(needle), "{err} lacks {needle:?}");
    };
    expect(
        FieldImage {
            theta_step_deg: 7.0,
            ..sample("x")
        },
        "theta_step_deg",
    );
    expect(
        FieldImage {
            theta_step_deg: 20.0, // divides 180°, but K would be 10
            ..sample("x")
        },
        "expected K",
    );
    let image = sample("x");
    let mut rows: [Vec<Vec<f64>>; 3] =
        std::array::from_fn(|c| (0..N).map(|r| image.row(c, r).to_vec()).collect());
    let ff: [Vec<f64>; 3] = std::array::from_fn(|c| image.forward_fractions(c).to_vec());
    rows[2].pop();
    let err = FieldImage::from_rows("x", STEP, &rows, &ff).unwrap_err();
    assert!(err.to_string().contains("channel B has 2 rows"), "{err}");
    rows[2].push(rows[1][1].clone());
    rows[0][1].pop();
    let err = FieldImage::from_rows("x", STEP, &rows, &ff).unwrap_err();
    assert!(
        err.to_string().contains("channel R row 1 has 10 columns"),
        "{err}"
    );
    let mut image = sample("x");
    image.forward_fraction = Array2::zeros((3, N + 1));
    expect(image, "forward_fraction has shape 3 × 4");
    let mut image = sample("x");
    image.extra_layers[0].0 = "G".into();
    expect(image, "colour channels");
    let mut image = sample("x");
    image.extra_layers.push(image.extra_layers[0].clone());
    expect(image, "given twice");
    let mut image = sample("x");
    image.extra_layers[0].0 = "has space".into();
    expect(image, "printable ASCII");
    let mut image = sample("x");
    image.ams = ndarray::Array3::zeros((3, 0, K));
    image.forward_fraction = Array2::zeros((3, 0));
    expect(image, "N = n_max must be at least 1");
    assert!(dir_entries(dir.path()).is_empty());
}

#[test]
fn failed_rename_removes_the_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    // The destination is a non-empty directory: every step up to the rename succeeds, the
    // rename fails, and the temporary file must go.
    let path = dir.path().join("rain.exr");
    fs::create_dir(&path).unwrap();
    fs::write(path.join("keep"), b"x").unwrap();
    let err = write_field_exr(&path, &sample("rain")).unwrap_err();
    assert!(
        matches!(err, IoError::Io { op, .. } if op.contains("renaming")),
        "{err:?}"
    );
    assert_eq!(dir_entries(dir.path()), ["rain.exr"]);
    assert_eq!(dir_entries(&path), ["keep"]);
}

#[test]
fn missing_directory_is_an_io_error_naming_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no/such/dir/rain.exr");
    let err = write_field_exr(&path, &sample("rain")).unwrap_err();
    assert!(matches!(err, IoError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("no/such/dir/rain.exr"), "{err}");
    let err = read_field_exr(&path).unwrap_err();
    assert!(matches!(err, IoError::Io { .. }), "{err:?}");
}

// ---- the reader's checks, on files made directly with the exr crate ----

/// The attributes of a valid file for `sample`'s shape.
fn good_attributes() -> Vec<(&'static str, AttributeValue)> {
    let text = |s: &str| AttributeValue::Text(Text::from(s));
    vec![
        (attr::SCHEMA, AttributeValue::I32(1)),
        (attr::FIELD, text("hand")),
        (attr::THETA_STEP_DEG, AttributeValue::F64(STEP)),
        (attr::N_MAX, AttributeValue::I32(N as i32)),
        (attr::FORWARD_FRACTION[0], text("0.9,0.7,0.6")),
        (attr::FORWARD_FRACTION[1], text("0.9,0.7,0.6")),
        (attr::FORWARD_FRACTION[2], text("0.9,0.7,0.6")),
    ]
}

/// Writes an EXR by hand: `channels` as (name, samples), size (width, height).
fn write_raw(
    path: &Path,
    size: (usize, usize),
    channels: Vec<(&str, FlatSamples)>,
    attributes: Vec<(&str, AttributeValue)>,
    blocks: Blocks,
) {
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (name, samples) in channels {
        list.push(AnyChannel::new(name, samples));
    }
    let mut attrs = LayerAttributes::default();
    for (name, value) in attributes {
        attrs.other.insert(Text::from(name), value);
    }
    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        Vec2(size.0, size.1),
        attrs,
        encoding,
        AnyChannels::sort(list),
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

fn f32s(n: usize) -> FlatSamples {
    FlatSamples::F32((0..n).map(|i| i as f32 * 0.01).collect())
}

fn rgb(n: usize) -> Vec<(&'static str, FlatSamples)> {
    RGB_CHANNELS.iter().map(|c| (*c, f32s(n))).collect()
}

fn contract_error(path: &Path) -> ContractError {
    match read_field_exr(path) {
        Err(IoError::Contract { path: p, check }) => {
            assert_eq!(p, path);
            check
        }
        other => panic!("expected a contract error, got {other:?}"),
    }
}

#[test]
fn hand_made_valid_file_reads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ok.exr");
    write_raw(
        &path,
        (K, N),
        rgb(K * N),
        good_attributes(),
        Blocks::ScanLines,
    );
    let image = read_field_exr(&path).unwrap();
    assert_eq!(image.field, "hand");
    assert_eq!(image.ams[[1, 2, 3]], f64::from((2 * K + 3) as f32 * 0.01));
    assert!(image.extra_layers.is_empty());
}

#[test]
fn reader_names_the_failed_check() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.exr");
    let scan = || Blocks::ScanLines;

    // Wrong channel set.
    let two: Vec<_> = rgb(K * N).into_iter().take(2).collect();
    write_raw(&path, (K, N), two, good_attributes(), scan());
    let e = contract_error(&path);
    assert!(
        matches!(&e, ContractError::Channels { found } if found == &["G", "R"]),
        "{e:?}"
    );
    let msg = read_field_exr(&path).unwrap_err().to_string();
    assert!(
        msg.contains("bad.exr") && msg.contains("wrong channel set"),
        "{msg}"
    );

    // Half floats.
    let mut channels = rgb(K * N);
    channels[0].1 = FlatSamples::F16(vec![f16::from_f32(0.5); K * N]);
    write_raw(&path, (K, N), channels, good_attributes(), scan());
    assert!(
        matches!(contract_error(&path), ContractError::SampleType { channel, .. } if channel == "R")
    );

    // Wrong width (K must be 180°/Δθ + 1) and wrong height (N = n_max).
    for (w, h) in [(K - 1, N), (K, N + 1)] {
        write_raw(&path, (w, h), rgb(w * h), good_attributes(), scan());
        let e = contract_error(&path);
        assert!(matches!(e, ContractError::Size(_)), "{e:?}");
        assert!(e.to_string().contains(&format!("{w} × {h}")), "{e}");
    }

    // Tiled.
    write_raw(
        &path,
        (K, N),
        rgb(K * N),
        good_attributes(),
        Blocks::Tiles(Vec2(4, 4)),
    );
    assert!(matches!(contract_error(&path), ContractError::Layout(s) if s == "tiled"));

    // Each attribute missing in turn.
    for skip in 0..good_attributes().len() {
        let mut attrs = good_attributes();
        let (name, _) = attrs.remove(skip);
        write_raw(&path, (K, N), rgb(K * N), attrs, scan());
        assert_eq!(contract_error(&path), ContractError::MissingAttribute(name));
        let msg = read_field_exr(&path).unwrap_err().to_string();
        assert!(msg.contains(&format!("missing attribute {name}")), "{msg}");
    }

    // Bad attribute values.
    let bad_cases: Vec<(&str, AttributeValue)> = vec![
        (attr::SCHEMA, AttributeValue::I32(2)),
        (attr::SCHEMA, AttributeValue::Text(Text::from("1"))),
        (attr::THETA_STEP_DEG, AttributeValue::F32(18.0)),
        (attr::THETA_STEP_DEG, AttributeValue::F64(7.0)),
        (attr::N_MAX, AttributeValue::I32(0)),
        (
            attr::FORWARD_FRACTION[2],
            AttributeValue::Text(Text::from("0.9,0.7")),
        ),
        (
            attr::FORWARD_FRACTION[0],
            AttributeValue::Text(Text::from("0.9,x,0.6")),
        ),
        (attr::FIELD, AttributeValue::I32(3)),
    ];
    for (name, value) in bad_cases {
        let mut attrs = good_attributes();
        attrs.iter_mut().find(|(n, _)| *n == name).unwrap().1 = value;
        write_raw(&path, (K, N), rgb(K * N), attrs, scan());
        let e = contract_error(&path);
        assert!(
            matches!(&e, ContractError::BadAttribute { name: n, .. } if *n == name),
            "{name}: {e:?}"
        );
    }

    // A NaN texel.
    let mut channels = rgb(K * N);
    channels[2].1 = FlatSamples::F32({
        let mut v = vec![0.5f32; K * N];
        v[K + 4] = f32::NAN;
        v
    });
    write_raw(&path, (K, N), channels, good_attributes(), scan());
    assert!(matches!(
        contract_error(&path),
        ContractError::NonFinite { channel, row: 1, column: 4, .. } if channel == "B"
    ));
}

#[test]
fn truncated_or_foreign_files_are_unreadable() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.exr");
    write_field_exr(&good, &sample("rain")).unwrap();
    let bytes = fs::read(&good).unwrap();
    let cut = dir.path().join("cut.exr");
    // Every length: inside the magic, the header, the offset table and the pixel chunks.
    for len in 0..bytes.len() {
        fs::write(&cut, &bytes[..len]).unwrap();
        let err = read_field_exr(&cut).expect_err(&format!("{len} of {} bytes read", bytes.len()));
        assert!(
            matches!(err, IoError::Unreadable { .. }),
            "cut at {len}: {err:?}"
        );
        assert!(err.to_string().contains("cut.exr"), "{err}");
    }
    let text = dir.path().join("text.exr");
    fs::write(&text, b"not an exr file at all").unwrap();
    assert!(matches!(
        read_field_exr(&text),
        Err(IoError::Unreadable { .. })
    ));
}

// ---- the manifest ----

fn sample_manifest() -> Manifest {
    let per = |v: f64| PerChannel::from_array([v, v * 1.01, v * 1.02]);
    let eps = |a: Option<u32>, b: Option<u32>, c: Option<u32>| {
        BTreeMap::from([
            ("1e-2".to_string(), a),
            ("1e-4".to_string(), b),
            ("1e-6".to_string(), c),
        ])
    };
    let field = |name: &str, kind: &str| FieldEntry {
        name: name.to_string(),
        file: format!("{name}.exr"),
        bytes: 1234,
        crc32: "0123abcd".to_string(),
        kind: kind.parse().expect("a field kind"),
        n_max: 3,
        forward_fraction: PerChannel::from_array([
            vec![0.97, 0.9, 0.8],
            vec![0.96, 0.89, 0.79],
            vec![0.7 + 0.2, 0.88, 0.78],
        ]),
        forward_peak_fraction: PerChannel::from_array(std::array::from_fn(|_| {
            vec![0.4, 0.16, 0.064]
        })),
        g: per(0.87),
        sigma_ext_m2: per(1.6e-6),
        albedo: per(0.98),
        n_isotropic: PerChannel::from_array([
            eps(Some(9), Some(17), None),
            eps(Some(9), Some(18), None),
            eps(Some(10), None, None),
        ]),
        microphysics: Microphysics {
            crystal: None,
            distribution: Some(json!({"kind": "marshall-palmer", "rain_rate_mm_h": 5.0})),
            kind: kind.parse().expect("a field kind"),
            material: Material::Water,
            name: name.to_string(),
            refractive_index: None,
            albedo: None,
            hg: None,
            tabulated: None,
            temperature_c: 10.0,
        },
        quality: QualityRecord {
            crystal_noise: None,
            crystal_rays: None,
            knobs: json!({"sizes": 40}),
            legendre_l_max: 4000,
            preset: "draft".into(),
            size_noise: Some(PerChannel::from_array([0.01, 0.02, 0.03])),
            sizes: Some(40),
        },
        content_hash: "0123456789abcdef".to_string(),
        single_scattering: None,
        poisson: None,
        transport_factor: None,
        biri_kernel: None,
    };
    Manifest {
        schema: 2,
        tool: "photometeor".to_string(),
        tool_version: "0.1.0".to_string(),
        theta_step_deg: STEP,
        angle_count: K,
        channels: Channels {
            illuminant: "none".into(),
            mixing: "one wavelength per channel".into(),
            mode: SpectralSampling::Rgb3,
            names: ["R", "G", "B"].map(String::from).to_vec(),
            negative_lobe_fraction: PerChannel::from_array([0.0; 3]),
            observer: "none".into(),
            space: "linear sRGB".into(),
            unit: "1/sr".into(),
            wavelengths_nm: vec![650.0, 515.0, 440.0],
            weights: PerChannel::from_array([
                vec![1.0, 0.0, 0.0],
                vec![0.0, 1.0, 0.0],
                vec![0.0, 0.0, 1.0],
            ]),
        },
        // Not alphabetical: the scene's order must be kept.
        fields: vec![field("rain", "rain"), field("cloud", "cloud")],
        sweeps: Vec::new(),
    }
}

#[test]
fn manifest_round_trips_byte_identically() {
    let dir = tempfile::tempdir().unwrap();
    let m = sample_manifest();
    write_manifest(dir.path(), &m).unwrap();
    let first = fs::read(dir.path().join(MANIFEST_FILE)).unwrap();
    let back = read_manifest(dir.path()).unwrap();
    assert_eq!(back, m);
    write_manifest(dir.path(), &back).unwrap();
    assert_eq!(fs::read(dir.path().join(MANIFEST_FILE)).unwrap(), first);
    assert_eq!(dir_entries(dir.path()), [MANIFEST_FILE]);

    let text = String::from_utf8(first).unwrap();
    assert!(text.ends_with("}\n"));
    // Field order is the scene's; keys are the documented ones.
    assert!(text.find("\"rain\"").unwrap() < text.find("\"cloud\"").unwrap());
    for key in [
        "\"schema\": 2",
        "\"crc32\": \"0123abcd\"",
        "\"tool_version\"",
        "\"theta_step_deg\": 18.0",
        "\"angle_count\": 11",
        "\"forward_peak_fraction\"",
        "\"sigma_ext_m2\"",
        "\"albedo\"",
        "\"1e-6\": null",
        "\"content_hash\": \"0123456789abcdef\"",
        "0.8999999999999999",
    ] {
        assert!(text.contains(key), "manifest lacks {key}:\n{text}");
    }
}

#[test]
fn manifest_schema_and_consistency_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(MANIFEST_FILE);
    let good = sample_manifest();
    write_manifest(dir.path(), &good).unwrap();
    let written = fs::read(&path).unwrap();

    // Another schema fails as a schema error, before any missing key.
    fs::write(&path, br#"{"schema": 1, "whatever": true}"#).unwrap();
    let err = read_manifest(dir.path()).unwrap_err();
    assert!(
        matches!(err, ManifestError::Schema { ref found, .. } if found == "1"),
        "{err:?}"
    );
    assert!(err.to_string().contains("manifest.json"), "{err}");
    fs::write(&path, br#"{"fields": []}"#).unwrap();
    assert!(matches!(
        read_manifest(dir.path()),
        Err(ManifestError::Schema { ref found, .. }) if found == "missing"
    ));
    // Broken JSON / wrong structure keep line and column.
    fs::write(&path, "{\n  \"schema\": 2,\n  \"tool\": 5\n}").unwrap();
    let err = read_manifest(dir.path()).unwrap_err();
    assert!(matches!(err, ManifestError::Json { .. }), "{err:?}");
    assert!(err.to_string().contains("line 3"), "{err}");

    // Inconsistent manifests are refused on write, and the old file stays.
    fs::write(&path, &written).unwrap();
    let mut bad = good.clone();
    bad.fields[1].forward_fraction.g.pop();
    let err = write_manifest(dir.path(), &bad).unwrap_err();
    assert!(
        err.to_string().contains("forward_fraction.G has 2 values"),
        "{err}"
    );
    let mut bad = good.clone();
    bad.fields[0].g.b = f64::NAN;
    assert!(write_manifest(dir.path(), &bad).is_err());
    let mut bad = good.clone();
    bad.angle_count = 10;
    assert!(write_manifest(dir.path(), &bad).is_err());
    let mut bad = good.clone();
    bad.fields[1].name = "rain".into();
    assert!(write_manifest(dir.path(), &bad).is_err());
    let mut bad = good.clone();
    bad.fields[0].file = "../rain.exr".into();
    assert!(write_manifest(dir.path(), &bad).is_err());
    let mut bad = good.clone();
    bad.fields[0].content_hash = "ABC".into();
    assert!(write_manifest(dir.path(), &bad).is_err());
    let mut bad = good.clone();
    bad.fields[0].n_isotropic.r.insert("1e-3".into(), Some(4));
    assert!(write_manifest(dir.path(), &bad).is_err());
    // Physics and file names: each refused naming the value.
    type Edit = fn(&mut FieldEntry);
    let cases: [(Edit, &str); 10] = [
        (|f| f.albedo.g = 7.0, "albedo.G = 7"),
        (|f| f.g.r = -5.0, "g.R = -5"),
        (
            |f| f.sigma_ext_m2.b = -1e-6,
            "sigma_ext_m2.B = -1e-6 is outside [1e-30, 1] m²",
        ),
        (|f| f.forward_fraction.r[0] = 1.5, "F_1 = 1.5"),
        (
            |f| f.forward_fraction.r[0] = -0.1,
            "F_1 = -0.1 is outside [0, 1]",
        ),
        (
            |f| f.forward_fraction.r[2] = 0.95,
            "F_3 = 0.95 is further from ½ than F_2",
        ),
        (
            |f| f.forward_peak_fraction.g[1] = 2.0,
            "forward_peak_fraction.G[1] = 2",
        ),
        (
            |f| f.file = "notes.txt".into(),
            "\"notes.txt\" is not the bake's own name",
        ),
        (
            |f| f.file = MANIFEST_FILE.into(),
            "\"manifest.json\" is not the bake's own name",
        ),
        (|f| f.crc32 = "XYZ".into(), "crc32 \"XYZ\""),
    ];
    for (edit, needle) in cases {
        let mut bad = good.clone();
        edit(&mut bad.fields[0]);
        let err = write_manifest(dir.path(), &bad).unwrap_err().to_string();
        assert!(err.contains(needle), "{err} lacks {needle:?}");
        // And on read: a hand-edited manifest is refused the same way.
        fs::write(&path, bad.to_json_bytes()).unwrap();
        let err = read_manifest(dir.path()).unwrap_err().to_string();
        assert!(err.contains(needle), "{err} lacks {needle:?}");
        fs::write(&path, &written).unwrap();
    }
    assert_eq!(fs::read(&path).unwrap(), written);
    assert_eq!(dir_entries(dir.path()), [MANIFEST_FILE]);
    // Physical and accepted: a field leaning backward (small strongly absorbing high-index
    // spheres: F_1 < ½, rising toward ½) and one with g < 0 (F_n − ½ alternating in sign).
    for fractions in [[0.38, 0.45, 0.49], [0.3, 0.6, 0.45]] {
        let mut backward = good.clone();
        let f = &mut backward.fields[0];
        f.forward_fraction = PerChannel::from_array([0, 1, 2].map(|_| fractions.to_vec()));
        f.forward_peak_fraction = PerChannel::from_array([0, 1, 2].map(|_| vec![0.0; 3]));
        write_manifest(dir.path(), &backward).unwrap();
        assert_eq!(read_manifest(dir.path()).unwrap(), backward);
    }
    fs::write(&path, &written).unwrap();

    // A missing directory is an I/O error naming the path.
    let err = write_manifest(dir.path().join("nope"), &good).unwrap_err();
    assert!(matches!(err, ManifestError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("nope"), "{err}");
}

// ---- the OpenEXR reference library reads our file ----

/// Rows of a (N, K) array as nested vectors.
fn nested(rows: ndarray::ArrayView2<f64>) -> Vec<Vec<f64>> {
    rows.outer_iter().map(|row| row.to_vec()).collect()
}

/// What the Python check compares against: the values as written (rounded to f32).
fn expected_json(image: &FieldImage) -> serde_json::Value {
    let r = rounded(image);
    let channels: serde_json::Map<String, serde_json::Value> = RGB_CHANNELS
        .iter()
        .enumerate()
        .map(|(c, name)| {
            (
                name.to_string(),
                json!(nested(r.ams.index_axis(Axis(0), c))),
            )
        })
        .chain(
            r.extra_layers
                .iter()
                .map(|(n, rows)| (n.clone(), json!(nested(rows.view())))),
        )
        .collect();
    json!({
        "field": r.field,
        "theta_step_deg": r.theta_step_deg,
        "n_max": r.n_max(),
        "angle_count": r.angle_count(),
        "schema": 1,
        "channels": channels,
        "forward_fraction": {
            "R": r.forward_fractions(0).to_vec(),
            "G": r.forward_fractions(1).to_vec(),
            "B": r.forward_fractions(2).to_vec(),
        },
    })
}

const PIP_HINT: &str = "install the OpenEXR reference library for Python with \
                        `python3 -m pip install OpenEXR numpy`";

#[test]
fn openexr_reference_library_reads_our_file() {
    let dir = tempfile::tempdir().unwrap();
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/exr_openexr.py");
    for (name, image) in [
        ("rain", sample("rain")),
        (
            "plain",
            FieldImage {
                extra_layers: Vec::new(),
                ..sample("plain")
            },
        ),
    ] {
        let exr_path = dir.path().join(format!("{name}.exr"));
        let json_path = dir.path().join(format!("{name}.json"));
        write_field_exr(&exr_path, &image).unwrap();
        fs::write(&json_path, expected_json(&image).to_string()).unwrap();
        let out = Command::new("python3")
            .arg(&script)
            .arg(&exr_path)
            .arg(&json_path)
            .output()
            .unwrap_or_else(|e| panic!("cannot run python3 ({e}); {PIP_HINT}"));
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "{} failed ({}):\n{stdout}\n{stderr}\nIf OpenEXR or numpy is missing: {PIP_HINT}",
            script.display(),
            out.status
        );
        assert!(stdout.contains("OK"), "{stdout}");
    }
}
