//! `shape = "vdb"` volumes through `photometeor render`, against the OpenVDB library itself:
//! every file `runtime/vdb/tests/write_cases.py` writes with Debian's python3-openvdb (dense,
//! sparse with tiles and a background, half floats, a scaled and translated transform; blosc,
//! zip, active-mask-only and no codec) renders pixel for pixel as the library's own values
//! given as a raw f32 grid over the same box, and the lines printed before work carry the
//! library's active voxel count and index box. Bad files are refused before the bake, naming
//! the file and the reason, with nothing written.

mod common;
#[path = "common/exr_planes.rs"]
mod exr_planes;
#[path = "common/openvdb.rs"]
mod openvdb;

use std::fs;
use std::path::Path;

use common::{photometeor, workdir};
use openvdb::write_cases;

/// A small scene of one cloud volume; `volume` is the `[[volume]]` table's shape keys.
fn scene(volume: &str) -> String {
    format!(
        r#"[scene]
name = "vdb"
spectral = "rgb3"
n_max = 4
quality = "draft"

[[field]]
name = "cloud"
kind = "cloud"
distribution = {{ kind = "gamma", r_eff_um = 8, v_eff = 0.1 }}

[render]
width = 12
height = 8
grid_resolution = 24

[render.riley]
slices = 32
light_resolution = 64

[camera]
position_m = [300, 300, -4000]
look_at_m = [300, 300, 300]

[sun]
elevation_deg = 30
azimuth_deg = 40

[[volume]]
field = "cloud"
number_density_per_m3 = 1e6
{volume}
"#
    )
}

/// Renders `text` in `dir` to `out` with `args`; panics with stderr on failure.
fn render(dir: &Path, text: &str, out: &str, args: &[&str]) -> String {
    fs::write(dir.join("scene.toml"), text).unwrap();
    let o = photometeor(
        &[
            &["render", "scene.toml", "--tables", "tables", "--out", out],
            args,
        ]
        .concat(),
        dir,
    );
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{out}: {e}");
    e
}

fn ints(v: &serde_json::Value) -> [i64; 3] {
    std::array::from_fn(|a| v[a].as_i64().unwrap())
}

fn floats(v: &serde_json::Value) -> [f64; 3] {
    std::array::from_fn(|a| v[a].as_f64().unwrap())
}

/// Each case rendered from its VDB and from the library's values as a raw grid over the box
/// the library's transform gives: the same pixels, bit for bit, for a grid model and (on the
/// smallest cases, at the files' own resolution) the truth.
#[test]
fn every_library_file_renders_as_its_values_given_raw() {
    let dir = workdir("vdb-cases");
    let json = write_cases(&dir);
    let cases = json["cases"].as_object().unwrap();
    assert!(cases.len() >= 10, "{} cases", cases.len());
    for (name, c) in cases {
        let (lo, hi) = (ints(&c["index_min"]), ints(&c["index_max"]));
        let (size, origin) = (floats(&c["voxel_size"]), floats(&c["origin_m"]));
        // The box of the active voxels: their centres at origin + size · ijk, ± half a voxel.
        let min: [f64; 3] = std::array::from_fn(|a| origin[a] + size[a] * (lo[a] as f64 - 0.5));
        let max: [f64; 3] = std::array::from_fn(|a| origin[a] + size[a] * (hi[a] as f64 + 0.5));
        let dims: [i64; 3] = std::array::from_fn(|a| hi[a] - lo[a] + 1);
        let vdb = scene(&format!(
            "shape = \"vdb\"\nfile = \"{}\"",
            c["file"].as_str().unwrap()
        ));
        let raw = scene(&format!(
            "shape = \"grid\"\nfile = \"{}\"\ndims = {dims:?}\nmin_m = {min:?}\nmax_m = {max:?}",
            c["raw"].as_str().unwrap()
        ));
        let small = dims.iter().product::<i64>() < 10_000;
        let models: &[&str] = if small {
            &["riley", "truth"]
        } else {
            &["riley"]
        };
        for model in models {
            let args = ["--model", model, "--cpu"];
            let said = render(&dir, &vdb, "vdb.exr", &args);
            render(&dir, &raw, "raw.exr", &args);
            let count = c["active_voxels"].as_u64().unwrap();
            let boxed = format!("{count} active voxels");
            assert!(said.contains(&boxed), "{name}: {boxed:?} not in {said}");
            let index = format!("index box {lo:?}–{hi:?}");
            assert!(said.contains(&index), "{name}: {index:?} not in {said}");
            let (a, b) = (
                exr_planes::read_rgba(&dir.join("vdb.exr")),
                exr_planes::read_rgba(&dir.join("raw.exr")),
            );
            assert!(
                a.2.iter().flatten().any(|&v| v > 0.0),
                "{name} {model}: a black image"
            );
            let same =
                a.2.iter()
                    .zip(&b.2)
                    .all(|(p, q)| p.iter().zip(q).all(|(x, y)| x.to_bits() == y.to_bits()));
            assert!(same, "{name} {model}: the VDB and the raw grid differ");
        }
    }
}

/// Runs `render` of `text` in `dir`: exit 2 naming `needles`, nothing baked, nothing written.
fn refused(dir: &Path, text: &str, args: &[&str], needles: &[&str]) {
    let _ = fs::remove_dir_all(dir.join("tables"));
    fs::write(dir.join("scene.toml"), text).unwrap();
    let o = photometeor(
        &[
            &[
                "render",
                "scene.toml",
                "--tables",
                "tables",
                "--out",
                "out.exr",
                "--quiet",
            ],
            args,
        ]
        .concat(),
        dir,
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{needles:?}: {e}");
    for needle in needles {
        assert!(e.contains(needle), "{needle:?} not in {e}");
    }
    assert!(
        !dir.join("tables").exists(),
        "{needles:?}: baked before refusing"
    );
    assert!(!dir.join("out.exr").exists(), "{needles:?}: wrote an image");
}

/// `bytes` with the first run of three little-endian f64 equal to `from` set to `to`.
fn patch_vec3(bytes: &[u8], from: f64, to: f64) -> Vec<u8> {
    let needle: Vec<u8> = [from; 3].iter().flat_map(|v| v.to_le_bytes()).collect();
    let at = bytes
        .windows(24)
        .position(|w| w == needle.as_slice())
        .expect("the transform's vector in the file");
    let mut out = bytes.to_vec();
    for a in 0..3 {
        out[at + 8 * a..at + 8 * a + 8].copy_from_slice(&to.to_le_bytes());
    }
    out
}

#[test]
fn bad_files_are_refused_before_the_bake_naming_file_and_reason() {
    let dir = workdir("vdb-bad");
    write_cases(&dir);
    let vdb =
        |file: &str, extra: &str| scene(&format!("shape = \"vdb\"\nfile = \"{file}\"\n{extra}"));
    let dense = fs::read(dir.join("dense.vdb")).unwrap();
    fs::write(dir.join("truncated.vdb"), &dense[..dense.len() / 2]).unwrap();
    // The UniformScaleMap's voxel size (25 m) set to 0.
    fs::write(dir.join("flat.vdb"), patch_vec3(&dense, 25.0, 0.0)).unwrap();
    let cases: &[(String, &[&str], &[&str])] = &[
        (
            vdb("dense.f32", ""),
            &[],
            &["vdb dense.f32", "not an OpenVDB file"],
        ),
        (
            vdb("truncated.vdb", ""),
            &[],
            &["vdb truncated.vdb", "past the file's end"],
        ),
        (
            vdb("two_grids.vdb", "grid = \"smoke\""),
            &[],
            &[
                "vdb two_grids.vdb",
                "\"smoke\"",
                "\"density\", \"temperature\"",
            ],
        ),
        (vdb("vector.vdb", ""), &[], &["vdb vector.vdb", "vec3s"]),
        (
            vdb("level_set.vdb", ""),
            &[],
            &["vdb level_set.vdb", "level set"],
        ),
        (
            vdb("frustum.vdb", ""),
            &[],
            &["vdb frustum.vdb", "NonlinearFrustumMap"],
        ),
        (
            vdb("negative.vdb", ""),
            &[],
            &[
                "vdb negative.vdb",
                "value -1 at voxel (10, 2, 15) is not a finite density ≥ 0",
            ],
        ),
        (
            vdb("nan.vdb", ""),
            &["--model", "truth"],
            &["vdb nan.vdb", "value NaN at voxel (10, 2, 15)"],
        ),
        (vdb("flat.vdb", ""), &[], &["vdb flat.vdb", "scale"]),
        (
            vdb("far.vdb", ""),
            &[],
            &["vdb far.vdb", "4001 × 4001 × 4001 = 64048012001 voxels"],
        ),
        // A dense copy that fits the reader's bound but not the memory allowed.
        (
            vdb("sparse.vdb", ""),
            &["--max-memory", "0.05"],
            &["the grid files", "GiB allowed"],
        ),
        (vdb("missing.vdb", ""), &[], &["vdb missing.vdb"]),
        (
            vdb("dense.vdb", "dims = [19, 11, 15]"),
            &[],
            &["dims is not a key of shape \"vdb\""],
        ),
        (
            vdb("dense.vdb", "scale_m = 0"),
            &[],
            &["scale_m = 0 must be finite and > 0"],
        ),
    ];
    for (text, args, needles) in cases {
        let args: Vec<&str> = if args.contains(&"--model") {
            args.to_vec()
        } else {
            [&["--model", "riley"], *args].concat()
        };
        refused(&dir, text, &args, needles);
    }
}

/// `scale_m` and `offset_m` place the file's box: the printed box moves and scales with them.
#[test]
fn scale_and_offset_place_the_files_box() {
    let dir = workdir("vdb-place");
    write_cases(&dir);
    let text =
        scene("shape = \"vdb\"\nfile = \"transformed.vdb\"\nscale_m = 2\noffset_m = [1, 2, 3]");
    let said = render(&dir, &text, "out.exr", &["--model", "riley", "--cpu"]);
    // The library's box: index [8, 0, 10]–[26, 10, 24], voxels 10 × 20 × 30 m from (100, −50,
    // 7); its lower corner (175, −60, 292) and upper (365, 160, 742), doubled and offset.
    let placed =
        "voxels of 20.000 × 40.000 × 60.000 m over [351.0, -118.0, 587.0]–[731.0, 322.0, 1487.0] m";
    assert!(said.contains(placed), "{placed:?} not in {said}");
}
