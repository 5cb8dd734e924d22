//! Every scene key the parsers accept is documented, and every key the reference listings
//! document is accepted. The accepted keys of each table are read from the parsers themselves:
//! a probe key put into that table of a full scene is refused with the list of the keys it
//! takes (serde's "expected one of …", or [render]'s own list; each model's keys from
//! `render::registry::model_keys`). "Documented" means the key appears as `key =` or `` `key` ``
//! in README.md, docs/**/*.md or the render scene's reference listing (the module docs of
//! runtime/render/src/scene/mod.rs); the listings checked the other way are the scene example
//! of docs/scenes.md and that module's.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// A scene with every table, each opened by a line the probe follows.
const FULL: &str = r#"[scene]
name = "keys"
spectral = "rgb3"
n_max = 4
quality = "draft"
#scene

[[field]]
name = "cloud"
kind = "cloud"
distribution = { kind = "gamma", r_eff_um = 8, v_eff = 0.1 }
sweep = { key = "r_eff_um", from = 6, to = 14, count = 2 }
#field

[[field]]
name = "fog"
kind = "cloud"
distribution = { kind = "gamma", r_eff_um = 8, v_eff = 0.1 }

[render]
width = 8
height = 6
#render

[camera]
position_m = [0, 500, -3000]
look_at_m = [0, 500, 0]
#camera

[sun]
elevation_deg = 30
azimuth_deg = 40
#sun

[sky]
enabled = true
#sky

[ground]
albedo = 0.1
#ground

[haze]
field = "fog"
number_density_per_m3 = 2e8
scale_height_m = 1200
#haze

[[light]]
position_m = [0, 50, 0]
intensity = [1, 1, 1]
#light

[[medium]]
field = "fog"
number_density_per_m3 = 1e6
#medium

[[occluder]]
shape = "sphere"
center_m = [0, 2, 900]
radius_m = 1
#occluder

[[volume]]
field = "cloud"
shape = "cumulus"
number_density_per_m3 = 1e7
center_m = [0, 500, 0]
radius_m = 300
height_m = 300
r_eff_um = { base = 6, top = 14 }
#volume
"#;

/// The backticked names after "expected one of" (or the one after "expected"), or the
/// parenthesised list of [render].
fn listed(error: &str) -> BTreeSet<String> {
    if let Some(rest) = error.split("expected one of").nth(1) {
        return rest
            .split('`')
            .skip(1)
            .step_by(2)
            .map(String::from)
            .collect();
    }
    if let Some(rest) = error.split("expected `").nth(1) {
        // A table of one key.
        return BTreeSet::from([rest.split('`').next().unwrap().to_string()]);
    }
    if let Some(rest) = error.split("is not a key of [render] (").nth(1) {
        return rest
            .split(')')
            .next()
            .unwrap()
            .split(", ")
            .map(String::from)
            .collect();
    }
    panic!("no list of keys in {error:?}");
}

/// Each table's accepted keys, from the parsers' refusals of a probe key.
fn accepted() -> BTreeMap<String, BTreeSet<String>> {
    let mut tables = BTreeMap::new();
    for table in [
        "scene", "field", "render", "camera", "sun", "sky", "ground", "haze", "light", "medium",
        "occluder", "volume",
    ] {
        let text = FULL.replace(&format!("#{table}\n"), "zz_probe = 1\n");
        let error = match (table, bake::Scene::parse(&text, "probe")) {
            ("scene" | "field", Err(e)) => e.to_string(),
            (_, _) => match render::RenderScene::parse(&text, "probe", Path::new(".")) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("[{table}] zz_probe accepted"),
            },
        };
        assert!(error.contains("zz_probe"), "[{table}]: {error}");
        tables.insert(table.to_string(), listed(&error));
    }
    // The inline tables: a sweep and a size profile.
    for (table, from, to) in [
        ("sweep", "count = 2 }", "count = 2, zz_probe = 1 }"),
        ("profile", "top = 14 }", "top = 14, zz_probe = 1 }"),
    ] {
        let text = FULL.replace(from, to);
        let error = match bake::Scene::parse(&text, "probe") {
            Err(e) => e.to_string(),
            Ok(_) => match render::RenderScene::parse(&text, "probe", Path::new(".")) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("{table}: zz_probe accepted"),
            },
        };
        assert!(error.contains("zz_probe"), "{table}: {error}");
        tables.insert(table.to_string(), listed(&error));
    }
    for (model, keys) in render::registry::model_keys() {
        tables.insert(format!("render.{model}"), keys.into_iter().collect());
    }
    tables
}

fn markdown(dir: &Path, into: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            markdown(&p, into);
        } else if p.extension().is_some_and(|x| x == "md") {
            into.push(p);
        }
    }
}

/// The render scene's reference listing: the TOML block of scene.rs's module docs.
fn render_listing() -> String {
    let source =
        std::fs::read_to_string(Path::new(ROOT).join("runtime/render/src/scene/mod.rs")).unwrap();
    source
        .lines()
        .take_while(|l| l.starts_with("//!"))
        .map(|l| l.trim_start_matches("//!").trim_start_matches(' '))
        .collect::<Vec<_>>()
        .join("\n")
}

fn docs() -> String {
    let mut files = vec![Path::new(ROOT).join("README.md")];
    markdown(&Path::new(ROOT).join("docs"), &mut files);
    let mut all: String = files
        .iter()
        .map(|f| std::fs::read_to_string(f).unwrap())
        .collect::<Vec<_>>()
        .join("\n");
    all.push_str(&render_listing());
    all
}

fn documented(docs: &str, key: &str) -> bool {
    let word = |i: usize| {
        let before = docs[..i].chars().next_back();
        !before.is_some_and(|c| c.is_alphanumeric() || c == '_')
    };
    docs.match_indices(&format!("`{key}`")).next().is_some()
        || docs.match_indices(key).any(|(i, _)| {
            word(i)
                && docs[i + key.len()..]
                    .trim_start_matches(' ')
                    .starts_with('=')
        })
}

#[test]
fn every_accepted_scene_key_is_documented() {
    let docs = docs();
    let mut missing = Vec::new();
    for (table, keys) in accepted() {
        for key in keys {
            if !documented(&docs, &key) {
                missing.push(format!("[{table}] {key}"));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "accepted but documented nowhere: {missing:?}"
    );
}

/// (table, key) of each `key =` line of a TOML listing, under its latest `[table]` header.
fn listing_keys(toml: &str) -> Vec<(String, String)> {
    let mut table = String::new();
    let mut keys = Vec::new();
    for line in toml.lines() {
        let line = line.split('#').next().unwrap().trim();
        if line.starts_with('[') {
            table = line.trim_matches(|c| c == '[' || c == ']').to_string();
        } else if let Some((key, _)) = line.split_once('=')
            && !table.is_empty()
        {
            keys.push((table.clone(), key.trim().to_string()));
        }
    }
    keys
}

#[test]
fn every_key_of_the_reference_listings_is_accepted() {
    let accepted = accepted();
    let page = std::fs::read_to_string(Path::new(ROOT).join("docs/scenes.md")).unwrap();
    // docs/scenes.md's scene example: the first TOML block after "## Scenes".
    let scenes = page.split("\n## Scenes").nth(1).expect("a Scenes section");
    let example = scenes
        .split("```toml")
        .nth(1)
        .unwrap()
        .split("```")
        .next()
        .unwrap();
    let listing = render_listing();
    let render = listing
        .split("```toml")
        .nth(1)
        .unwrap()
        .split("```")
        .next()
        .unwrap();
    let mut refused = Vec::new();
    let mut checked = 0;
    for (table, key) in listing_keys(example)
        .into_iter()
        .chain(listing_keys(render))
    {
        checked += 1;
        let known = accepted
            .get(&table)
            .unwrap_or_else(|| panic!("no table [{table}]"));
        if !known.contains(&key) {
            refused.push(format!("[{table}] {key}"));
        }
    }
    assert!(checked > 80, "only {checked} keys found in the listings");
    assert!(refused.is_empty(), "documented but refused: {refused:?}");
}
