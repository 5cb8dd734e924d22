//! A bake's checkpoints and a shared bake directory: each field's cache record is written as
//! the field finishes, so a bake killed later starts again from the fields it finished; a bake
//! into a directory another bake is publishing into waits for it, saying so, and a bake that
//! replaces another scene's tables says which.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{photometeor, workdir};

const HEAD: &str =
    "[scene]\nname = \"NAME\"\nspectral = \"rgb3\"\nn_max = 4\nquality = \"draft\"\n\n";
const CLOUD: &str = "[[field]]\nname = \"cloud\"\nkind = \"cloud\"\n\
    distribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }\n\n";
const RAIN: &str = "[[field]]\nname = \"rain\"\nkind = \"rain\"\n\
    distribution = { kind = \"lognormal\", median_radius_um = 1000, sigma_g = 1.4 }\n\n";

/// The cache records (not temporaries) in `dir/.cache`.
fn records(dir: &Path) -> usize {
    std::fs::read_dir(dir.join(".cache"))
        .map(|d| {
            d.flatten()
                .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
                .count()
        })
        .unwrap_or(0)
}

fn json_bake(cwd: &Path, scene: &str, out: &str) -> serde_json::Value {
    let o = photometeor(&["bake", scene, "--out", out, "--json"], cwd);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn a_killed_bake_resumes_from_the_fields_it_finished() {
    let cwd = workdir("checkpoint-kill");
    std::fs::write(
        cwd.join("s.toml"),
        format!("{}{CLOUD}{RAIN}", HEAD.replace("NAME", "k")),
    )
    .unwrap();
    let out = cwd.join("tables");
    let mut child = Command::new(env!("CARGO_BIN_EXE_photometeor"))
        .args(["bake", "s.toml", "--out", "tables", "--quiet"])
        .current_dir(&cwd)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The cloud takes well under a second, the rain (1 mm drops) several: kill the bake as soon as the
    // cloud's record is there, while the rain is computing.
    let started = Instant::now();
    while records(&out) == 0 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the bake ended with no cache record seen before its end"
        );
        assert!(started.elapsed() < Duration::from_secs(120));
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let seen_after = started.elapsed().as_secs_f64();
    assert!(
        !out.join("manifest.json").exists(),
        "the bake published before its first record was seen ({seen_after:.2} s)"
    );
    assert_eq!(records(&out), 1);
    let report = json_bake(&cwd, "s.toml", "tables");
    assert_eq!(report["cached"], serde_json::json!(["cloud"]), "{report}");
    assert_eq!(report["computed"], serde_json::json!(["rain"]), "{report}");
    // The record came while the rain was computing: well before the rain alone takes (a bake
    // that wrote its records only once every field was done showed the first after the rain).
    let rain_seconds = report["seconds"].as_f64().unwrap();
    assert!(
        seen_after < 0.5 * rain_seconds,
        "the first record appeared {seen_after:.2} s in; the rain alone takes {rain_seconds:.2} s"
    );
    eprintln!(
        "killed {seen_after:.2} s in, after the cloud's record; the rerun took the cloud from \
         it and computed the rain in {rain_seconds:.2} s"
    );
}

#[test]
fn a_bake_of_another_scene_waits_for_the_first_and_says_it_replaces_its_tables() {
    let cwd = workdir("checkpoint-two-scenes");
    std::fs::write(
        cwd.join("a.toml"),
        format!("{}{CLOUD}", HEAD.replace("NAME", "a")),
    )
    .unwrap();
    let rain_b = RAIN.replace("median_radius_um = 1000", "median_radius_um = 100");
    std::fs::write(
        cwd.join("b.toml"),
        format!("{}{rain_b}", HEAD.replace("NAME", "b")),
    )
    .unwrap();
    let a = json_bake(&cwd, "a.toml", "tables");
    assert_eq!(a["replaced"], serde_json::json!([]), "{a}");
    // This process holds the directory's lock as a bake publishing would: b waits, saying so.
    let lock = format::BakeLock::acquire(&cwd.join("tables")).unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_photometeor"))
        .args(["bake", "b.toml", "--out", "tables", "--json"])
        .current_dir(&cwd)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(2));
    let mut child = child;
    assert!(
        child.try_wait().unwrap().is_none(),
        "b did not wait for the lock"
    );
    drop(lock);
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let pid = std::process::id();
    assert!(
        stderr.contains(&format!(
            "waiting for process {pid}, which is baking into tables"
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains("tables: this bake of b replaced the tables it held of fields [\"cloud\"]"),
        "{stderr}"
    );
    let b: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(b["replaced"], serde_json::json!(["cloud"]), "{b}");
    assert!(!cwd.join("tables/cloud.exr").exists() && cwd.join("tables/rain.exr").exists());
}
