//! `bake --shard K/N` and `merge`: a scene with a swept field (and the default scene) baked as
//! N = 1, 3 and 4 shard processes and merged is byte-identical to the bake without shards; a
//! missing, repeated or foreign shard is refused, naming it, and nothing is written.

use std::collections::BTreeMap;
use std::path::Path;

mod common;

use common::{photometeor, workdir};

/// Every published file of a bake directory (not its cache or lock), by name.
fn published(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_file())
        .map(|e| e.file_name().into_string().unwrap())
        .filter(|n| !n.starts_with('.'))
        .map(|n| (n.clone(), std::fs::read(dir.join(&n)).unwrap()))
        .collect()
}

fn ok(args: &[&str], cwd: &Path) -> String {
    let out = photometeor(args, cwd);
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{args:?}:\n{stderr}");
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// Bakes the default scene's N shards as N processes into `{prefix}{n}-{k}`.
fn shards(cwd: &Path, prefix: &str, n: usize, extra: &[&str]) -> Vec<String> {
    (1..=n)
        .map(|k| {
            let dir = format!("{prefix}{n}-{k}");
            let shard = format!("{k}/{n}");
            let mut args = vec!["bake", "--quality", "draft", "--quiet"];
            args.extend(extra);
            args.extend(["--shard", &shard, "--out", &dir]);
            ok(&args, cwd);
            dir
        })
        .collect()
}

/// Cloud droplets swept over r_eff (three members), rain and ice.
const SWEEP: &str = "[scene]\nname = \"sweep\"\nspectral = \"rgb3\"\nquality = \"draft\"\n\n\
    [[field]]\nname = \"cloud\"\nkind = \"cloud\"\n\
    distribution = { kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }\n\
    sweep = { key = \"r_eff_um\", from = 5, to = 20, count = 3 }\n\n\
    [[field]]\nname = \"rain\"\nkind = \"rain\"\n\
    distribution = { kind = \"lognormal\", median_radius_um = 500, sigma_g = 1.4 }\n\n\
    [[field]]\nname = \"ice\"\nkind = \"ice\"\n";

#[test]
fn sharded_and_merged_bakes_of_a_sweep_are_byte_identical_to_the_bake_without_shards() {
    let cwd = workdir("shard-identical");
    std::fs::write(cwd.join("sweep.toml"), SWEEP).unwrap();
    ok(
        &[
            "bake",
            "sweep.toml",
            "--quality",
            "draft",
            "--quiet",
            "--out",
            "full",
        ],
        &cwd,
    );
    let full = published(&cwd.join("full"));
    assert!(
        full.contains_key("manifest.json") && full.len() == 21,
        "{:?}",
        full.keys()
    );
    let manifest: serde_json::Value = serde_json::from_slice(&full["manifest.json"]).unwrap();
    assert_eq!(
        manifest["sweeps"][0]["fields"],
        serde_json::json!(["cloud@00", "cloud@01", "cloud@02"])
    );
    for n in [1, 3, 4] {
        let dirs = shards(&cwd, "s", n, &["sweep.toml"]);
        // Every field in exactly one shard, each shard with work where there are enough fields.
        let mut seen = Vec::new();
        for d in &dirs {
            let record: serde_json::Value =
                serde_json::from_slice(&std::fs::read(cwd.join(d).join("shard.json")).unwrap())
                    .unwrap();
            let fields = record["fields"].as_array().unwrap();
            assert!(!fields.is_empty(), "{d} got no field of 5");
            seen.extend(
                fields
                    .iter()
                    .map(|f| f["name"].as_str().unwrap().to_string()),
            );
        }
        seen.sort();
        assert_eq!(
            seen,
            ["cloud@00", "cloud@01", "cloud@02", "ice", "rain"],
            "N = {n}"
        );
        // Given in another order than their indices.
        let mut args = vec!["merge", "--quiet"];
        args.extend(dirs.iter().rev().map(String::as_str));
        let out = format!("m{n}");
        args.extend(["--out", &out]);
        ok(&args, &cwd);
        let merged = published(&cwd.join(&out));
        assert_eq!(
            merged.keys().collect::<Vec<_>>(),
            full.keys().collect::<Vec<_>>()
        );
        for (name, bytes) in &full {
            assert!(
                merged[name] == *bytes,
                "N = {n}: {name} differs from the bake without shards"
            );
        }
    }
}

#[test]
fn a_missing_repeated_or_foreign_shard_is_refused_by_name_and_nothing_is_written() {
    let cwd = workdir("shard-refused");
    let dirs = shards(&cwd, "s", 3, &[]);
    // Another bake (another seed): its shard 3/3 is not one of these.
    let other = shards(&cwd, "seed1-", 3, &["--seed", "1"]);
    std::fs::rename(cwd.join(&other[2]), cwd.join("foreign")).unwrap();
    let cases: [(Vec<&str>, &str); 4] = [
        (vec![&dirs[0], &dirs[1]], "shard 3/3 is missing"),
        (
            vec![&dirs[0], &dirs[1], &dirs[1], &dirs[2]],
            "shard 2/3 is given twice",
        ),
        (
            vec![&dirs[0], &dirs[1], "foreign"],
            "foreign is not a shard of the same bake",
        ),
        (
            vec![&dirs[0], &dirs[1], "nowhere"],
            "nowhere is not a shard directory",
        ),
    ];
    for (given, wanted) in cases {
        let mut args = vec!["merge"];
        args.extend(given);
        args.extend(["--out", "merged"]);
        let out = photometeor(&args, &cwd);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(wanted), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(!cwd.join("merged").exists(), "{args:?} wrote the output");
    }
    // A damaged record is named too.
    let cache = cwd.join(&dirs[2]).join(".cache");
    for entry in std::fs::read_dir(&cache).unwrap() {
        let path = entry.unwrap().path();
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        std::fs::write(&path, bytes).unwrap();
    }
    let mut args = vec!["merge"];
    args.extend(dirs.iter().map(String::as_str));
    args.extend(["--out", "merged"]);
    let out = photometeor(&args, &cwd);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("is missing or damaged"), "{stderr}");
    assert!(!cwd.join("merged").exists());
    // And a bad --shard before any work.
    for bad in ["0/3", "4/3", "3", "a/b", "1/0"] {
        let out = photometeor(&["bake", "--shard", bad, "--out", "x"], &cwd);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{bad}: {stderr}");
        assert!(stderr.contains("expected K/N"), "{bad}: {stderr}");
        assert!(!cwd.join("x").exists());
    }
}

/// One small field: the array has more tasks than fields.
const ONE: &str = "[scene]\nname = \"one\"\nspectral = \"rgb3\"\nn_max = 2\nquality = \"draft\"\n\n\
    [[field]]\nname = \"cloud\"\nkind = \"cloud\"\n\
    distribution = { kind = \"gamma\", r_eff_um = 8, v_eff = 0.1 }\n";

#[test]
fn shards_without_a_field_bake_into_fresh_directories_and_a_claim_past_n_is_refused() {
    let cwd = workdir("shard-empty");
    std::fs::write(cwd.join("one.toml"), ONE).unwrap();
    ok(&["bake", "one.toml", "--quiet", "--out", "full"], &cwd);
    // Three shards of one field, each into a directory that does not exist yet (two levels).
    let dirs: Vec<String> = (1..=3).map(|k| format!("fresh/s{k}")).collect();
    for (k, dir) in dirs.iter().enumerate() {
        let shard = format!("{}/3", k + 1);
        ok(
            &[
                "bake", "one.toml", "--quiet", "--shard", &shard, "--out", dir,
            ],
            &cwd,
        );
    }
    let mut args = vec!["merge"];
    args.extend(dirs.iter().map(String::as_str));
    args.extend(["--out", "merged"]);
    ok(&args, &cwd);
    assert_eq!(published(&cwd.join("merged")), published(&cwd.join("full")));
    // A shard record claiming 4/3 (written by hand, or by another tool) is refused by merge,
    // naming it, whatever the others are.
    let record = cwd.join(&dirs[2]).join("shard.json");
    let text = std::fs::read_to_string(&record).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["shard"]["index"] = serde_json::json!(4);
    std::fs::create_dir_all(cwd.join("forged")).unwrap();
    std::fs::write(
        cwd.join("forged/shard.json"),
        serde_json::to_vec_pretty(&json).unwrap(),
    )
    .unwrap();
    let mut args = vec!["merge"];
    args.extend(dirs.iter().map(String::as_str));
    args.extend(["forged", "--out", "merged2"]);
    let out = photometeor(&args, &cwd);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("forged claims shard 4/3"), "{stderr}");
    assert!(!cwd.join("merged2").exists());
    // And on the command line: K past N.
    let out = photometeor(&["bake", "one.toml", "--shard", "5/4", "--out", "y"], &cwd);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("expected K/N with 1 ≤ K ≤ N"));
    assert!(!cwd.join("y").exists());
}
