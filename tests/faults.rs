//! Fault injection on the bake directory: a writer killed at every step of its commit, a failure
//! before the commit point, dead writers' leftovers, a second writer while one holds the lock,
//! concurrent bakes of different scenes, and every reader on a swapped or edited bake. What
//! must hold: nothing the previous bake wrote is lost before the commit point, a reader never
//! accepts a mix, and the next bake finishes or cleans what a dead one left.
//!
//! A kill is simulated by stopping the protocol between two of its steps through the library
//! (`Staging::commit_point_only` and manual renames), which is exactly the state a SIGKILL there
//! leaves on disk; the full disk is not simulated (it needs a mount this suite cannot rely on).

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

use bake::{BakePlan, Scene, Silent};
use format::{BakeDir, BakeLock, Staging};

mod common;
#[path = "common/tmpfs.rs"]
mod tmpfs;

use common::{photometeor, workdir};

fn scene(name: &str, fields: &[&str]) -> String {
    let mut text = format!(
        "[scene]\nname = \"{name}\"\nspectral = \"rgb3\"\nn_max = 4\nquality = \"draft\"\n"
    );
    for f in fields {
        text.push_str(match *f {
            "cloud" => "[[field]]\nname = \"cloud\"\nkind = \"cloud\"\ndistribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }\n",
            "rain" => "[[field]]\nname = \"rain\"\nkind = \"rain\"\ndistribution = { kind = \"lognormal\", median_radius_um = 300, sigma_g = 1.3 }\n",
            other => panic!("no field {other}"),
        });
    }
    text
}

fn bake_into(text: &str, dir: &Path) -> Result<bake::BakeReport, bake::BakeError> {
    let scene = Scene::parse(text, "test scene").unwrap();
    let quality = scene.quality;
    bake::run(
        &BakePlan::for_preset(scene, dir.to_path_buf(), quality),
        &Silent,
    )
}

/// Every visible file of `dir` (not the lock, cache or commit machinery) with its bytes.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = fs::read_dir(dir)
        .unwrap()
        .flatten()
        .filter(|e| e.path().is_file())
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                fs::read(e.path()).unwrap(),
            )
        })
        .filter(|(n, _)| n != ".lock")
        .collect();
    files.sort();
    files
}

/// Opens the bake and reads every field through its manifest: a consistent generation.
fn consistent(dir: &Path) -> Vec<String> {
    let bake = BakeDir::open(dir).unwrap();
    for entry in &bake.manifest.fields {
        bake.read_field(entry)
            .unwrap_or_else(|e| panic!("{}: {e}", entry.name));
    }
    runtime::Tables::open(dir).unwrap();
    bake.manifest
        .fields
        .iter()
        .map(|f| f.name.clone())
        .collect()
}

/// Stages a second generation of `dir` (each field's F_i unchanged, one texel changed by a
/// part in 10⁶, within every normalization check; the single-scattering files as they were),
/// with a manifest that vouches for it.
fn stage_next_generation(lock: &BakeLock) -> Staging<'_> {
    let dir = lock.dir();
    let old = BakeDir::open(dir).unwrap();
    let mut manifest = old.manifest.clone();
    let mut stage = Staging::begin(lock).unwrap();
    for entry in &mut manifest.fields {
        let mut image = old.read_field(entry).unwrap();
        image.ams[[0, 0, 300]] *= 1.0 + 1e-6;
        let bytes = format::exr::field_exr_bytes(&image).unwrap();
        entry.bytes = bytes.len() as u64;
        entry.crc32 = format::crc32_hex(&bytes);
        stage.write(&entry.file, &bytes).unwrap();
        for extra in [&entry.single_scattering, &entry.poisson, &entry.biri_kernel]
            .into_iter()
            .flatten()
        {
            let same = fs::read(dir.join(&extra.file)).unwrap();
            stage.write(&extra.file, &same).unwrap();
        }
    }
    stage
        .write(format::MANIFEST_FILE, &manifest.to_json_bytes())
        .unwrap();
    stage
}

/// A copy of the directory tree `from` at `to`.
fn copy_tree(from: &Path, to: &Path) {
    fs::create_dir_all(to).unwrap();
    for entry in fs::read_dir(from).unwrap().flatten() {
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_tree(&entry.path(), &target);
        } else {
            fs::copy(entry.path(), target).unwrap();
        }
    }
}

#[test]
fn a_writer_killed_at_any_step_of_its_commit_never_shows_a_mix() {
    let work = workdir("faults-kill");
    let dir = work.join("tables");
    bake_into(&scene("a", &["cloud", "rain"]), &dir).unwrap();
    let before = snapshot(&dir);
    // cloud.exr, cloud.biri.exr, cloud.poisson.exr, cloud.single.exr, manifest.json, and
    // rain's four
    let files = before.len();

    // Killed while staging (before the commit point): the previous bake is untouched, and
    // the next writer removes the stage.
    {
        let lock = BakeLock::acquire(&dir).unwrap();
        let stage = stage_next_generation(&lock);
        std::mem::forget(stage); // a kill: no destructor runs
    }
    assert_eq!(snapshot(&dir), before);
    assert_eq!(consistent(&dir), ["cloud", "rain"]);
    assert!(
        fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().starts_with(".stage-"))
    );

    // Killed after the commit point, after k of the roll-forward's renames (manifest last),
    // each from a copy of a whole bake taken before the kill above.
    let whole = work.join("tables-whole");
    bake_into(&scene("a", &["cloud", "rain"]), &whole).unwrap();
    for k in 0..files {
        let dir = work.join(format!("tables-{k}"));
        copy_tree(&whole, &dir);
        let staged_manifest;
        {
            let lock = BakeLock::acquire(&dir).unwrap();
            let stage = stage_next_generation(&lock);
            stage.commit_point_only().unwrap();
            let commit = dir.join(".commit");
            staged_manifest = fs::read(commit.join("manifest.json")).unwrap();
            let mut names: Vec<String> = fs::read_dir(&commit)
                .unwrap()
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n != "manifest.json")
                .collect();
            names.sort();
            names.push("manifest.json".into());
            for name in &names[..k] {
                fs::rename(commit.join(name), dir.join(name)).unwrap();
            }
        }
        // Every reader refuses the directory, naming the pending commit.
        let e = format::read_manifest(&dir).unwrap_err().to_string();
        assert!(
            e.contains("interrupted") && e.contains(".commit"),
            "k = {k}: {e}"
        );
        assert!(runtime::Tables::open(&dir).is_err(), "k = {k}");
        let out = photometeor(&["inspect", dir.to_str().unwrap()], &work);
        assert!(!out.status.success(), "k = {k}: inspect accepted");
        assert!(String::from_utf8_lossy(&out.stderr).contains(".commit"));
        // The next writer finishes the commit first: the new generation, whole.
        let lock = BakeLock::acquire(&dir).unwrap();
        assert_eq!(lock.clean_stale().unwrap(), [".commit"]);
        drop(lock);
        assert_eq!(
            fs::read(dir.join("manifest.json")).unwrap(),
            staged_manifest
        );
        assert_eq!(consistent(&dir), ["cloud", "rain"], "k = {k}");
    }
}

#[test]
fn failures_before_any_work_or_while_computing_leave_the_previous_bake_as_it_was() {
    let work = workdir("faults-before");
    let dir = work.join("tables");
    bake_into(&scene("a", &["cloud", "rain"]), &dir).unwrap();
    let before = snapshot(&dir);

    // A field whose sizes leave the solver's range (x up to 2e5: 20 mm drops at 515 nm):
    // refused before anything is computed.
    let huge = scene("a", &["cloud"]).replace(
        "{ kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }",
        "{ kind = \"monodisperse\", radius_um = 20000 }",
    );
    let e = bake_into(&huge, &dir).unwrap_err().to_string();
    assert!(
        e.contains("field \"cloud\"") && e.contains("[1e-6, 2e5]"),
        "{e}"
    );
    assert_eq!(snapshot(&dir), before);

    // An output directory that cannot exist (its parent is a file): refused before computing.
    let file = work.join("a-file");
    fs::write(&file, b"x").unwrap();
    let started = std::time::Instant::now();
    let e = bake_into(&scene("a", &["rain"]), &file.join("tables"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("a-file") && e.contains("not a directory"), "{e}");
    assert!(started.elapsed().as_secs_f64() < 1.0, "it computed first");
}

#[test]
fn leftovers_of_dead_bakes_are_removed_by_the_next_one() {
    let work = workdir("faults-leftovers");
    let dir = work.join("tables");
    bake_into(&scene("a", &["rain"]), &dir).unwrap();
    fs::write(dir.join(".rain.exr.tmp-999999-0"), b"half a file").unwrap();
    fs::create_dir(dir.join(".stage-999999")).unwrap();
    fs::write(dir.join(".stage-999999").join("rain.exr"), b"staged").unwrap();
    let report = bake_into(&scene("a", &["rain"]), &dir).unwrap();
    let mut cleaned = report.cleaned.clone();
    cleaned.sort();
    assert_eq!(cleaned, [".rain.exr.tmp-999999-0", ".stage-999999"]);
    assert!(!dir.join(".rain.exr.tmp-999999-0").exists());
    assert!(!dir.join(".stage-999999").exists());
    assert_eq!(consistent(&dir), ["rain"]);
}

#[test]
fn a_second_writer_is_refused_naming_the_holder() {
    let work = workdir("faults-lock");
    let dir = work.join("tables");
    bake_into(&scene("a", &["rain"]), &dir).unwrap();
    let before = snapshot(&dir);
    let held = BakeLock::acquire(&dir).unwrap();
    let e = bake_into(&scene("b", &["cloud"]), &dir)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(&format!("is being baked by process {}", std::process::id())),
        "{e}"
    );
    assert_eq!(snapshot(&dir), before);
    drop(held);
    bake_into(&scene("b", &["cloud"]), &dir).unwrap();
    assert_eq!(consistent(&dir), ["cloud"]);
}

#[test]
fn concurrent_bakes_of_different_scenes_leave_one_whole_bake() {
    let work = workdir("faults-concurrent");
    fs::write(work.join("a.toml"), scene("a", &["cloud"])).unwrap();
    fs::write(work.join("b.toml"), scene("b", &["rain"])).unwrap();
    for trial in 0..3 {
        let dir: PathBuf = work.join(format!("tables-{trial}"));
        let spawn = |s: &str| {
            Command::new(env!("CARGO_BIN_EXE_photometeor"))
                .args(["bake", s, "--out", dir.to_str().unwrap(), "--quiet"])
                .current_dir(&work)
                .spawn()
                .unwrap()
        };
        let (a, b) = (spawn("a.toml"), spawn("b.toml"));
        let outcomes = [a.wait_with_output().unwrap(), b.wait_with_output().unwrap()];
        let mut succeeded = 0;
        for out in &outcomes {
            if out.status.success() {
                succeeded += 1;
            } else {
                let stderr = String::from_utf8_lossy(&out.stderr);
                assert!(stderr.contains("is being baked by process"), "{stderr}");
            }
        }
        assert!(succeeded >= 1, "trial {trial}: neither bake succeeded");
        let fields = consistent(&dir);
        assert!(
            fields == ["cloud"] || fields == ["rain"],
            "trial {trial}: {fields:?}"
        );
        println!("trial {trial}: {succeeded} succeeded, bake holds {fields:?}");
    }
}

#[test]
fn every_reader_refuses_a_swapped_table_and_an_edited_manifest() {
    let work = workdir("faults-readers");
    let dir = work.join("tables");
    bake_into(&scene("a", &["cloud", "rain"]), &dir).unwrap();
    let d = dir.to_str().unwrap();
    let readers: [&[&str]; 4] = [
        &["inspect", d],
        &["validate", d],
        &["compare", d, d],
        &["plot", d, "--out", "plots"],
    ];
    // The cloud's table copied over the rain's.
    let rain = fs::read(dir.join("rain.exr")).unwrap();
    fs::copy(dir.join("cloud.exr"), dir.join("rain.exr")).unwrap();
    for args in readers {
        let out = photometeor(args, &work);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} accepted a swapped table");
        assert!(stderr.contains("rain.exr"), "{args:?}: {stderr}");
    }
    fs::write(dir.join("rain.exr"), rain).unwrap();
    // A manifest whose entry names another file, and one with an impossible albedo.
    let manifest = fs::read_to_string(dir.join("manifest.json")).unwrap();
    type Edit = fn(&mut serde_json::Value);
    let edits: [(Edit, &str); 2] = [
        (|v| v["fields"][1]["file"] = "notes.txt".into(), "notes.txt"),
        (
            |v| v["fields"][0]["albedo"]["R"] = 7.0.into(),
            "albedo.R = 7",
        ),
    ];
    for (edit, needle) in edits {
        let mut v: serde_json::Value = serde_json::from_str(&manifest).unwrap();
        edit(&mut v);
        fs::write(
            dir.join("manifest.json"),
            serde_json::to_vec_pretty(&v).unwrap(),
        )
        .unwrap();
        for args in readers {
            let out = photometeor(args, &work);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(!out.status.success(), "{args:?} accepted {needle}");
            assert!(stderr.contains(needle), "{args:?}: {stderr}");
        }
        assert!(runtime::Tables::open(&dir).is_err());
    }
    fs::write(dir.join("manifest.json"), manifest).unwrap();
    assert_eq!(consistent(&dir), ["cloud", "rain"]);
}

#[test]
fn readers_refuse_fifos_devices_and_oversized_files_without_blocking() {
    let work = workdir("faults-special-files");
    let dir = work.join("tables");
    bake_into(&scene("a", &["rain"]), &dir).unwrap();
    let started = std::time::Instant::now();
    // The EXR replaced by a link to /dev/zero: refused, not read until memory runs out.
    fs::remove_file(dir.join("rain.exr")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.join("rain.exr")).unwrap();
    let e = runtime::Tables::open(&dir).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    // The manifest replaced by a FIFO: refused, not waited on forever.
    fs::remove_file(dir.join("manifest.json")).unwrap();
    let made = Command::new("mkfifo")
        .arg(dir.join("manifest.json"))
        .status()
        .unwrap();
    assert!(made.success(), "mkfifo failed");
    let e = format::read_manifest(&dir).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    assert!(started.elapsed().as_secs_f64() < 5.0, "a reader blocked");
    // And the next bake replaces both with a whole generation.
    fs::remove_file(dir.join("manifest.json")).unwrap();
    fs::remove_file(dir.join("rain.exr")).unwrap();
    bake_into(&scene("a", &["rain"]), &dir).unwrap();
    assert_eq!(consistent(&dir), ["rain"]);
}

#[test]
fn a_full_disk_leaves_the_previous_bake_as_it_was() {
    let work = workdir("faults-full-disk");
    let dir = work.join("tables");
    fs::create_dir_all(&dir).unwrap();
    // A 4 MiB tmpfs: room for a one-field bake of 4 orders (2.4 MB with its Poisson and Biri
    // tables and cache record), not for two fields of 60 (8.3 MB).
    let Some(_unmount) = tmpfs::mount_tmpfs(&dir, "4m") else {
        return;
    };
    bake_into(&scene("a", &["rain"]), &dir).unwrap();
    let before = snapshot(&dir);
    let big = scene("b", &["cloud", "rain"]).replace("n_max = 4", "n_max = 60");
    let e = bake_into(&big, &dir).unwrap_err().to_string();
    println!("full disk: {e}");
    assert!(
        e.contains("No space left") || e.contains("space"),
        "not a full-disk error: {e}"
    );
    assert_eq!(snapshot(&dir), before);
    assert_eq!(consistent(&dir), ["rain"]);
}

/// Flips bit 27 of the data window's x max in `file` (an EXR of `dir`): a header that declares
/// 2^27 more columns than the file holds.
fn flip_data_window_bit(file: &Path) {
    let mut bytes = fs::read(file).unwrap();
    let window = b"dataWindow\0box2i\0";
    let at = bytes
        .windows(window.len())
        .position(|w| w == window)
        .unwrap()
        + window.len()
        + 4;
    bytes[at + 8 + 3] ^= 0x08;
    fs::write(file, bytes).unwrap();
}

/// Runs the binary with its address space limited to 1 GiB, as on a machine without the
/// memory a corrupt header asks for: an allocation sized from the header aborts there.
fn photometeor_in_1_gib(args: &[&str], cwd: &Path) -> std::process::Output {
    Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_photometeor"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

#[test]
fn every_reader_refuses_a_side_table_whose_header_declares_more_than_the_file_holds() {
    let work = workdir("faults-side-table-header");
    let dir = work.join("tables");
    bake_into(&scene("a", &["cloud", "rain"]), &dir).unwrap();
    let d = dir.to_str().unwrap();
    for file in ["cloud.single.exr", "rain.poisson.exr", "cloud.biri.exr"] {
        let path = dir.join(file);
        let good = fs::read(&path).unwrap();
        flip_data_window_bit(&path);
        for args in [
            &["export", d, "--format", "npy", "--out", "export"][..],
            &["inspect", d],
            &["validate", d],
        ] {
            let out = photometeor_in_1_gib(args, &work);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{args:?} on {file}: {stderr}");
            assert!(
                stderr.contains(file) && stderr.contains("the header declares a 134218729 × "),
                "{args:?} on {file}: {stderr}"
            );
        }
        let e = runtime::Tables::open(&dir).unwrap_err().to_string();
        assert!(e.contains(file), "{e}");
        fs::write(&path, good).unwrap();
    }
    assert!(!work.join("export").exists());
    assert_eq!(consistent(&dir), ["cloud", "rain"]);
}

#[test]
fn impossible_manifest_values_are_refused_by_every_reader() {
    let work = workdir("faults-manifest-values");
    let dir = work.join("tables");
    bake_into(&scene("a", &["cloud", "rain"]), &dir).unwrap();
    let d = dir.to_str().unwrap();
    let manifest = fs::read_to_string(dir.join("manifest.json")).unwrap();
    type Edit = fn(&mut serde_json::Value);
    let edits: [(Edit, &str); 5] = [
        (
            |v| v["fields"][0]["sigma_ext_m2"]["G"] = 1e308.into(),
            "sigma_ext_m2.G = 1e308 is outside [1e-30, 1] m²",
        ),
        (
            |v| v["fields"][1]["microphysics"]["temperature_c"] = "warm".into(),
            "temperature_c",
        ),
        (
            |v| v["fields"][1]["microphysics"]["temperature_c"] = 150.0.into(),
            "microphysics.temperature_c = 150 is outside [-12, 99] °C",
        ),
        (
            |v| {
                let zeros = serde_json::json!([0.0, 0.0, 0.0, 0.0]);
                v["fields"][1]["forward_peak_fraction"]["G"] = zeros;
            },
            "forward_peak_fraction.G[0] = 0 in manifest.json, but the table's forward peaks give 0.4",
        ),
        (
            |v| v["fields"][0]["kind"] = "hail".into(),
            "unknown variant `hail`",
        ),
    ];
    for (edit, needle) in edits {
        let mut v: serde_json::Value = serde_json::from_str(&manifest).unwrap();
        edit(&mut v);
        fs::write(
            dir.join("manifest.json"),
            serde_json::to_vec_pretty(&v).unwrap(),
        )
        .unwrap();
        for args in [
            &["inspect", d][..],
            &["validate", d],
            &["export", d, "--format", "mitsuba", "--out", "export"],
        ] {
            let out = photometeor(args, &work);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{args:?} accepted {needle}");
            assert!(stderr.contains(needle), "{args:?}: {stderr}");
        }
        assert!(!work.join("export").exists());
    }
    fs::write(dir.join("manifest.json"), manifest).unwrap();
    assert_eq!(consistent(&dir), ["cloud", "rain"]);
}
