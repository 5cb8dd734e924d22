//! Where a command writes what its user names (`compare-render --map`, `export --out`,
//! `plot --out`, `shaders --out`): never over a device, a FIFO, a directory, a link to one, or
//! the files the command reads; a failed write (a full disk) is an error that leaves nothing
//! behind. Each refusal exits 2 naming the path, with the target as it was.

mod common;
#[path = "common/tmpfs.rs"]
mod tmpfs;

use std::fs;
use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{photometeor, workdir};

const SCENE: &str = "[scene]\nname = \"o\"\nspectral = \"rgb3\"\nn_max = 2\nquality = \"draft\"\n\n[[field]]\nname = \"cloud\"\nkind = \"cloud\"\ndistribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }\n";

fn bake(root: &Path) -> PathBuf {
    fs::write(root.join("scene.toml"), SCENE).unwrap();
    let out = root.join("tables");
    let o = photometeor(
        &[
            "bake",
            "scene.toml",
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ],
        root,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

/// Runs `args` in `root`: exit 2 with `needle` in the one-line error.
fn refused(root: &Path, args: &[&str], needle: &str) {
    let o = photometeor(args, root);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
    assert!(e.contains(needle), "{args:?}: {e}");
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut all = Vec::new();
    for e in fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            all.extend(snapshot(&p));
        } else {
            all.push((p.clone(), fs::read(&p).unwrap()));
        }
    }
    all.sort();
    all
}

#[test]
fn outputs_refuse_devices_directories_links_and_the_files_read() {
    let root = workdir("outputs_refused");
    let tables = bake(&root);
    let before = snapshot(&tables);
    // Two frames that are never read: the map is checked first.
    fs::write(root.join("truth.exr"), "not read").unwrap();
    fs::write(root.join("model.exr"), "not read").unwrap();
    fs::create_dir(root.join("a_directory")).unwrap();
    std::os::unix::fs::symlink("/dev/null", root.join("null_link")).unwrap();
    let map = |target: &str| -> Vec<String> {
        ["compare-render", "truth.exr", "model.exr", "--map", target]
            .map(String::from)
            .to_vec()
    };
    let cases: Vec<(Vec<String>, &str)> = vec![
        (map("a_directory"), "is a directory, not a regular file"),
        (
            map("null_link"),
            "is a character device, not a regular file",
        ),
        (map("truth.exr"), "is truth.exr"),
        (
            ["plot", "tables", "--out", "tables"]
                .map(String::from)
                .to_vec(),
            "is tables",
        ),
        (
            ["plot", "tables", "--out", "tables/plots"]
                .map(String::from)
                .to_vec(),
            "lies inside tables",
        ),
        (
            ["export", "tables", "--format", "csv", "--out", "tables/x"]
                .map(String::from)
                .to_vec(),
            "lies inside tables",
        ),
        (
            ["export", "tables", "--format", "csv", "--out", "."]
                .map(String::from)
                .to_vec(),
            "holds tables",
        ),
        (
            ["shaders", "--out", "null_link"].map(String::from).to_vec(),
            "is a character device, not a directory",
        ),
    ];
    for (args, needle) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&root, &args, needle);
    }
    assert_eq!(snapshot(&tables), before, "the bake changed");
    assert_eq!(fs::read(root.join("truth.exr")).unwrap(), b"not read");
    assert!(
        fs::read_dir(root.join("a_directory"))
            .unwrap()
            .next()
            .is_none()
    );
    assert!(
        fs::symlink_metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );
    // A character device with /dev/full's numbers, where this machine lets us make one.
    let device = root.join("full_device");
    match Command::new("mknod")
        .arg(&device)
        .args(["c", "1", "7"])
        .output()
    {
        Ok(o) if o.status.success() => {
            refused(
                &root,
                &map("full_device")
                    .iter()
                    .map(String::as_str)
                    .collect::<Vec<_>>(),
                "is a character device, not a regular file",
            );
            refused(
                &root,
                &[
                    "export",
                    "tables",
                    "--format",
                    "csv",
                    "--out",
                    "full_device",
                ],
                "is a character device, not a directory",
            );
            let meta = fs::symlink_metadata(&device).unwrap();
            assert!(meta.file_type().is_char_device(), "the device was replaced");
        }
        other => eprintln!("skipped the mknod case: cannot make a device node here ({other:?})"),
    }
}

#[test]
fn a_full_disk_is_an_error_that_leaves_nothing_behind() {
    let root = workdir("outputs_full_disk");
    let dir = root.join("small");
    fs::create_dir_all(&dir).unwrap();
    // A 16 KiB tmpfs: too small for the translated shaders (≈ 100 KB).
    let Some(_unmount) = tmpfs::mount_tmpfs(&dir, "16k") else {
        return;
    };
    refused(
        &root,
        &["shaders", "--out", "small"],
        "No space left on device",
    );
    let left: Vec<String> = fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
}
