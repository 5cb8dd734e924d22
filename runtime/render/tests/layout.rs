//! The crate's shape, checked on any machine (no GPU): every WGSL uniform and named per-voxel
//! record has a Rust mirror of the same size and field offsets (naga's layout of the shader each
//! renderer compiles), no model's module names another model, no shared module names a model
//! but the registry, and the modules' imports form no circle.

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
    check::<render::gpu::View>(&render::riley::gpu::source());
    check::<render::gpu::Grid>(&render::riley::gpu::source());
    check::<render::gpu::Sky>(&render::riley::gpu::source());
    check::<render::gpu::TexturePlane>(&render::riley::gpu::source());
    check::<render::riley::gpu::Slices>(&render::riley::gpu::source());
    check::<render::miyazaki::gpu::Slices>(&render::miyazaki::gpu::source());
    check::<render::miyazaki::gpu::Shading>(&render::miyazaki::gpu::source());
    check::<render::miyazaki::gpu::Haze>(&render::miyazaki::gpu::source());
    check::<render::miyazaki::gpu::SvsParams>(&render::miyazaki::gpu::source());
    check::<render::gpu::SliceParams>(&render::miyazaki::gpu::source());
    check::<render::max::gpu::MaxParams>(&render::max::gpu::source());
    check::<render::coupled::gpu::CoupledParams>(&render::coupled::gpu::source());
    check::<render::coupled::gpu::LightVoxel>(&render::coupled::gpu::source());
    check::<render::coupled::gpu::Channel>(&render::coupled::gpu::source());
    check::<render::coupled::gpu::Moments>(&render::coupled::gpu::source());
    check::<render::max::gpu::LightVoxel>(&render::max::gpu::source());
    check::<render::lighting::transport_gpu::SweepParams>(
        &render::lighting::transport_gpu::source(),
    );
    check::<render::lighting::sky_gpu::SkyParams>(&render::lighting::sky_gpu::source());
    check::<render::lighting::beam_gpu::BeamParams>(&render::lighting::beam_gpu::source());
    check::<render::lighting::beam_gpu::MediumVoxel>(&render::lighting::beam_gpu::source());
    check::<render::lighting::beam_gpu::BeamVoxel>(&render::lighting::beam_gpu::source());
    check::<render::lighting::beam_gpu::BeamLayerState>(&render::lighting::beam_gpu::source());
    check::<render::lighting::sky_gpu::SkyWay>(&render::lighting::sky_gpu::source());
    check::<render::lighting::sky_gpu::SkyVoxel>(&render::lighting::sky_gpu::source());
    check::<render::lighting::sky_gpu::SkyLayerState>(&render::lighting::sky_gpu::source());
    check::<render::lighting::transport_gpu::TransportVoxel>(
        &render::lighting::transport_gpu::source(),
    );
    check::<render::lighting::transport_gpu::Ordinate>(&render::lighting::transport_gpu::source());
    check::<render::lighting::transport_gpu::TransportLayerState>(
        &render::lighting::transport_gpu::source(),
    );
    check::<render::lighting::diffusion_gpu::Dispatch>(
        render::lighting::diffusion_gpu::DIFFUSION_WGSL,
    );
    check::<render::lighting::diffusion_gpu::StencilRow>(
        render::lighting::diffusion_gpu::DIFFUSION_WGSL,
    );
    check::<render::lighting::resident::Glue>(render::lighting::resident::RESIDENT_WGSL);
    check::<render::biri::gpu::BiriParams>(&render::biri::gpu::source());
    check::<render::truth::gpu::TruthParams>(&render::truth::gpu::source());
    check::<render::truth::gpu::StepParams>(&render::truth::gpu::source());
    check::<render::truth::gpu::Track>(&render::truth::gpu::source());
    check::<render::truth::gpu::Counts>(&render::truth::gpu::source());
    check::<render::truth::gpu::TableSizes>(&render::truth::gpu::source());
    check::<render::truth::gpu::Stream>(&render::truth::gpu::source());
    check::<render::truth::gpu::Stepping>(&render::truth::gpu::source());
    check::<render::truth::gpu::Tile>(&render::truth::gpu::source());
    check::<render::truth::gpu::Band>(&render::truth::gpu::source());
    check::<render::truth::gpu::Light>(&render::truth::gpu::source());
    check::<render::truth::gpu::SavedBranch>(&render::truth::gpu::source());
    check::<render::truth::gpu::SavedPath>(&render::truth::gpu::source());
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
    // Every model module is in the list above and in the models! list; the other folders are
    // shared layers.
    for entry in std::fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if SHARED_FOLDERS.contains(&name.as_str()) {
                continue;
            }
            assert!(MODELS.contains(&name.as_str()), "{name} is not listed");
            assert!(
                render::registry::MODEL_NAMES.contains(&name.as_str()),
                "{name}"
            );
        }
    }
}

/// Folders of `src/` that are shared layers, not models.
const SHARED_FOLDERS: &[&str] = &["lighting", "scene"];

/// Each module of `src/` by its path (`coupled::light`; the crate root is ""), with its source
/// before its tests and without comments.
fn modules() -> Vec<(String, String)> {
    fn walk(dir: &std::path::Path, prefix: &[String], out: &mut Vec<(String, String)>) {
        let mut entries: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        entries.sort();
        for path in entries {
            let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                let mut inner = prefix.to_vec();
                inner.push(stem);
                walk(&path, &inner, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let mut name = prefix.to_vec();
                if stem != "mod" && stem != "lib" {
                    name.push(stem);
                }
                let text = std::fs::read_to_string(&path).unwrap();
                let code = text.split("#[cfg(test)]").next().unwrap_or("");
                let code: Vec<&str> = code
                    .lines()
                    .map(|l| l.split("//").next().unwrap())
                    .collect();
                out.push((name.join("::"), code.join("\n")));
            }
        }
    }
    let mut out = Vec::new();
    walk(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src"),
        &[],
        &mut out,
    );
    out
}

/// The modules `code` (module `from`) imports: each `crate::a::b::…` or `super::…` path,
/// resolved to the longest module of `names` it starts with (an item re-exported by the crate
/// root counts as the root).
fn imports(from: &str, code: &str, names: &[String]) -> std::collections::BTreeSet<String> {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let mut found = std::collections::BTreeSet::new();
    let mut resolve = |path: Vec<&str>| {
        for k in (0..=path.len()).rev() {
            let candidate = path[..k].join("::");
            if names.contains(&candidate) {
                if candidate != from {
                    found.insert(candidate);
                }
                return;
            }
        }
    };
    // The crate root's re-exports (`pub use riley::LightUpdate;`) import from their modules.
    if from.is_empty() {
        for line in code
            .lines()
            .filter_map(|l| l.trim().strip_prefix("pub use "))
        {
            resolve(line.split(['{', ';']).next().unwrap().split("::").collect());
        }
    }
    let parent: Vec<&str> = from.split("::").filter(|s| !s.is_empty()).collect();
    for (prefix, base) in [
        ("crate::", Vec::new()),
        ("super::", parent[..parent.len().saturating_sub(1)].to_vec()),
    ] {
        let mut rest = code;
        while let Some(at) = rest.find(prefix) {
            let before = rest[..at].chars().next_back();
            rest = &rest[at + prefix.len()..];
            if before.is_some_and(ident) {
                continue;
            }
            // The path, and inside `{…}` each of its top-level branches' first segment.
            let path: Vec<&str> = rest
                .split(|c: char| !(ident(c) || c == ':'))
                .next()
                .unwrap()
                .split("::")
                .filter(|s| !s.is_empty())
                .collect();
            let mut full = base.clone();
            full.extend(&path);
            if rest[path.join("::").len()..]
                .trim_start_matches(':')
                .starts_with('{')
            {
                let group = &rest[rest.find('{').unwrap() + 1..];
                let (mut depth, mut end) = (1, 0);
                for (i, c) in group.char_indices() {
                    depth += match c {
                        '{' => 1,
                        '}' => -1,
                        _ => 0,
                    };
                    if depth == 0 {
                        end = i;
                        break;
                    }
                }
                let mut depth = 0;
                let mut start = 0;
                let inner = &group[..end];
                for (i, c) in inner.char_indices().chain([(inner.len(), ',')]) {
                    match c {
                        '{' => depth += 1,
                        '}' => depth -= 1,
                        ',' if depth == 0 => {
                            let branch: Vec<&str> = inner[start..i]
                                .split(|c: char| !(ident(c) || c == ':'))
                                .find(|s| !s.is_empty())
                                .unwrap_or("")
                                .split("::")
                                .filter(|s| !s.is_empty())
                                .collect();
                            // A trailing comma leaves an empty last branch: no import.
                            if !branch.is_empty() {
                                let mut p = full.clone();
                                p.extend(branch);
                                resolve(p);
                            }
                            start = i + 1;
                        }
                        _ => {}
                    }
                }
            } else {
                resolve(full);
            }
        }
    }
    found
}

#[test]
fn the_modules_imports_form_no_circle() {
    let modules = modules();
    let names: Vec<String> = modules.iter().map(|(n, _)| n.clone()).collect();
    let graph: Vec<(String, std::collections::BTreeSet<String>)> = modules
        .iter()
        .map(|(name, code)| (name.clone(), imports(name, code, &names)))
        .collect();
    let edges = |m: &str| &graph.iter().find(|(n, _)| n == m).unwrap().1;
    // A depth-first search; a module met again while still on the path closes a circle.
    fn visit<'a>(
        m: &'a str,
        edges: &dyn Fn(&str) -> &'a std::collections::BTreeSet<String>,
        path: &mut Vec<&'a str>,
        done: &mut std::collections::BTreeSet<&'a str>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| *p == m) {
            let mut circle: Vec<String> = path[at..].iter().map(|s| s.to_string()).collect();
            circle.push(m.to_string());
            return Some(circle);
        }
        if !done.insert(m) {
            return None;
        }
        path.push(m);
        for next in edges(m) {
            if let Some(c) = visit(next, edges, path, done) {
                return Some(c);
            }
        }
        path.pop();
        None
    }
    let mut done = std::collections::BTreeSet::new();
    for name in &names {
        let circle = visit(name, &edges, &mut Vec::new(), &mut done);
        let show = |m: &String| {
            if m.is_empty() {
                "lib".to_string()
            } else {
                m.clone()
            }
        };
        assert!(
            circle.is_none(),
            "an import circle: {}",
            circle
                .unwrap()
                .iter()
                .map(show)
                .collect::<Vec<_>>()
                .join(" → ")
        );
    }
    // The check itself: it sees a model's import of the shared `model` module, and would see
    // one back.
    assert!(edges("riley").contains("model"), "{:?}", edges("riley"));
    let back = imports("model", "use crate::riley::Riley;", &names);
    assert!(back.contains("riley"), "{back:?}");
    // A group's trailing comma imports nothing more (rustfmt writes one in a long group).
    let group = imports(
        "gpu",
        "use crate::{\n    camera::Sun, frame::Frame,\n};",
        &names,
    );
    assert_eq!(group.into_iter().collect::<Vec<_>>(), ["camera", "frame"]);
}

#[test]
fn no_shared_module_names_a_model_but_the_registry() {
    let mut found = Vec::new();
    for (name, code) in modules() {
        let top = name.split("::").next().unwrap_or("");
        if MODELS.contains(&top) || name == "registry" || name.is_empty() {
            continue;
        }
        for model in MODELS {
            if code.contains(&format!("crate::{model}::"))
                || code.contains(&format!("crate::{model};"))
            {
                found.push(format!("{name} names {model}"));
            }
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}

/// The scene file's keys as the scene module's docs show them: per `[render.<model>]` table,
/// the keys of its lines up to the next table.
fn documented_model_keys() -> Vec<(String, Vec<String>)> {
    let docs: Vec<&str> = include_str!("../src/scene/mod.rs")
        .lines()
        .filter_map(|l| l.strip_prefix("//!"))
        .map(str::trim)
        .collect();
    let mut tables: Vec<(String, Vec<String>)> = Vec::new();
    for line in docs {
        if let Some(name) = line.strip_prefix("[render.") {
            let name = name.split(']').next().unwrap().to_string();
            tables.push((name, Vec::new()));
        } else if line.starts_with('[') {
            tables.push((String::new(), Vec::new()));
        } else if let (Some((_, keys)), Some((key, _))) =
            (tables.last_mut(), line.split_once(" = "))
        {
            keys.push(key.trim().to_string());
        }
    }
    tables.retain(|(name, _)| !name.is_empty());
    tables
}

#[test]
fn every_key_a_model_takes_is_in_the_scene_docs_and_no_other() {
    let documented = documented_model_keys();
    let mut wrong = Vec::new();
    for (model, keys) in render::registry::model_keys() {
        let Some((_, shown)) = documented.iter().find(|(name, _)| name == model) else {
            wrong.push(format!("[render.{model}] is not in the scene docs"));
            continue;
        };
        for key in &keys {
            if !shown.contains(key) {
                wrong.push(format!("[render.{model}] {key} is not in the scene docs"));
            }
        }
        for key in shown {
            if !keys.contains(key) {
                wrong.push(format!(
                    "[render.{model}] {key} is in the scene docs, not a key"
                ));
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // The check itself: the docs list coupled's transport keys.
    let coupled = &documented.iter().find(|(n, _)| n == "coupled").unwrap().1;
    assert!(
        coupled.contains(&"transport_coarsening".to_string()),
        "{coupled:?}"
    );
}
