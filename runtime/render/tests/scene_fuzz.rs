//! Property tests of the scene parsers — the render scene (`RenderScene::parse`, then each
//! model's `check_for` and `memory`) and the bake scene (`bake::Scene::parse_in`) — on mutated
//! copies of every example scene in `data/scenes/` and the soft-ball fixture: a value set to an
//! extreme, a wrong type or a path of a device, a line removed, duplicated or swapped with
//! another, bytes flipped, the text truncated. Each case must end in `Ok` or an error naming
//! what is wrong — no panic, no abort — and no single allocation may exceed the stated bound:
//! 64 bytes per byte of scene text plus 4 per byte of the largest file beside it (a grid file is
//! read as f32 and kept as f64 values), plus the dense copy of the seed's own OpenVDB grids (16
//! bytes a voxel), plus 1 MiB.
//!
//! CI runs `PHOTOMETEOR_FUZZ_CASES` cases per parser (default 256, about a second); the long
//! run and its result are in docs/accuracy.md ("Scenes under mutation"). Failing cases proptest
//! finds are kept in `tests/data/scene-fuzz-regressions.txt` and replayed first.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::TestRunner;
use render::RenderScene;
use render::registry::MODEL_NAMES;

#[path = "../../../tests/common/fuzz.rs"]
mod fuzz;
use fuzz::largest_allocation;

fn runner() -> TestRunner {
    fuzz::runner("tests/data/scene-fuzz-regressions.txt")
}

/// An example scene: its text and the directory its files are named from.
struct Seed {
    name: String,
    text: String,
    base: PathBuf,
    /// The largest file in `base` and its subdirectories one deep (bytes).
    largest_file: u64,
    /// The dense copy of the OpenVDB grids the unmutated scene reads (16 B a voxel of each
    /// one's active box): a compressed file holds far more voxels than bytes.
    vdb_dense: u64,
}

fn seeds() -> Vec<Seed> {
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenes");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&scenes)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.push(scenes.join("fixtures/soft_ball.toml"));
    paths.sort();
    paths
        .into_iter()
        .map(|p| {
            let base = p.parent().unwrap().to_path_buf();
            let text = std::fs::read_to_string(&p).unwrap();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            let vdb_dense = RenderScene::parse(&text, &name, &base)
                .map(|scene| {
                    scene
                        .volumes
                        .iter()
                        .map(|v| match &v.shape {
                            render::volume::Shape::Vdb { values, .. } => values.bytes(),
                            _ => 0,
                        })
                        .sum()
                })
                .unwrap_or(0);
            Seed {
                name,
                text,
                largest_file: largest_file(&base),
                vdb_dense,
                base,
            }
        })
        .collect()
}

fn largest_file(dir: &Path) -> u64 {
    let mut largest = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            for e in std::fs::read_dir(&p).unwrap() {
                largest = largest.max(e.unwrap().metadata().unwrap().len());
            }
        } else {
            largest = largest.max(p.metadata().unwrap().len());
        }
    }
    largest
}

/// Values a mutation puts in place of a key's value: extremes, non-finite numbers, wrong types,
/// huge counts and paths of devices and of nothing.
const VALUES: &[&str] = &[
    "1e308",
    "-1e308",
    "-1",
    "0",
    "0.5",
    "nan",
    "inf",
    "-inf",
    "5e-324",
    "1e-300",
    "2147483647",
    "9223372036854775807",
    "-9223372036854775808",
    "100000000",
    "8192",
    "512",
    "\"x\"",
    "\"\"",
    "\"/dev/zero\"",
    "\"/dev/null\"",
    "\"/\"",
    "\"../../../../../../etc/passwd\"",
    "true",
    "[]",
    "{}",
    "[1e308, 1e308, 1e308]",
    "[nan, 0, 0]",
    "[0, 0, 0]",
    "[-1, -1, -1]",
    "[1, 2]",
    "[100000, 100000, 100000]",
    "[\"a\", 1, 2]",
];

/// One change to a scene's text.
#[derive(Debug, Clone)]
enum Mutation {
    /// The value of the i-th `key = value` line (modulo their count) replaced.
    Value(usize, &'static str),
    /// A line removed.
    Remove(usize),
    /// A line written twice.
    Duplicate(usize),
    /// Two lines' values swapped.
    Swap(usize, usize),
    /// One byte's bits flipped by a mask.
    Flip(usize, u8),
    /// The text cut at a byte.
    Truncate(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), prop::sample::select(VALUES)).prop_map(|(i, v)| Mutation::Value(i, v)),
        1 => any::<usize>().prop_map(Mutation::Remove),
        1 => any::<usize>().prop_map(Mutation::Duplicate),
        1 => (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::Swap(a, b)),
        1 => (any::<usize>(), 1u8..).prop_map(|(i, m)| Mutation::Flip(i, m)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
    ]
}

/// `text` with `m` applied.
fn apply(text: &str, m: &Mutation) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let assignments: Vec<usize> = (0..lines.len())
        .filter(|&i| {
            let l = lines[i].trim_start();
            !l.starts_with('#') && l.contains(" = ")
        })
        .collect();
    let value_of = |l: &str| l.split_once(" = ").map(|(_, v)| v.to_string());
    match *m {
        Mutation::Value(i, v) if !assignments.is_empty() => {
            let at = assignments[i % assignments.len()];
            let key = lines[at].split_once(" = ").unwrap().0.to_string();
            lines[at] = format!("{key} = {v}");
        }
        Mutation::Remove(i) if !lines.is_empty() => {
            lines.remove(i % lines.len());
        }
        Mutation::Duplicate(i) if !lines.is_empty() => {
            let at = i % lines.len();
            lines.insert(at, lines[at].clone());
        }
        Mutation::Swap(a, b) if !assignments.is_empty() => {
            let (a, b) = (
                assignments[a % assignments.len()],
                assignments[b % assignments.len()],
            );
            let (va, vb) = (value_of(&lines[a]).unwrap(), value_of(&lines[b]).unwrap());
            let key = |l: &str| l.split_once(" = ").unwrap().0.to_string();
            lines[a] = format!("{} = {vb}", key(&lines[a]));
            lines[b] = format!("{} = {va}", key(&lines[b]));
        }
        Mutation::Flip(i, mask) if !text.is_empty() => {
            let mut bytes = text.as_bytes().to_vec();
            let at = i % bytes.len();
            bytes[at] ^= mask;
            return String::from_utf8_lossy(&bytes).into_owned();
        }
        Mutation::Truncate(i) if !text.is_empty() => {
            let bytes = text.as_bytes();
            return String::from_utf8_lossy(&bytes[..i % bytes.len()]).into_owned();
        }
        _ => {}
    }
    lines.join("\n") + "\n"
}

/// What the mutated scenes did, for the long run's record.
#[derive(Default)]
struct Tally {
    cases: u64,
    parsed: u64,
    accepted_by_a_model: u64,
    largest_allocation: usize,
    slowest: Duration,
}

impl Tally {
    fn print(&self, what: &str) {
        let accepted = if what.starts_with("render") {
            format!(
                ", {} accepted by at least one model",
                self.accepted_by_a_model
            )
        } else {
            String::new()
        };
        eprintln!(
            "{what}: {} cases, {} parsed{accepted}, largest allocation {} B, slowest case \
             {:.3} s",
            self.cases,
            self.parsed,
            self.largest_allocation,
            self.slowest.as_secs_f64()
        );
    }
}

/// The render scene parser and every model's checks and memory estimate on one mutated scene;
/// whether it parsed and whether any model accepted it.
fn render_case(text: &str, seed: &Seed) -> (bool, bool) {
    let Ok(scene) = RenderScene::parse(text, &seed.name, &seed.base) else {
        return (false, false);
    };
    let mut accepted = false;
    for &model in MODEL_NAMES {
        if let Ok(settings) = scene.check_for(model) {
            accepted = true;
            let bytes: u64 = scene.memory(&settings).iter().map(|n| n.bytes).sum();
            assert!(bytes > 0, "{model}: a frame estimated at 0 bytes");
            let _ = scene.check_memory(&settings, 1 << 30);
        }
    }
    (true, accepted)
}

/// Runs `case` on mutated copies of every seed scene (the text, the seed; it returns whether
/// the scene parsed and whether a model accepted it), each within `bound(text length, seed)`
/// bytes per allocation; the tally of the run.
fn fuzz(
    case: impl Fn(&str, &Seed) -> (bool, bool),
    bound: impl Fn(usize, &Seed) -> usize,
) -> Tally {
    let seeds = seeds();
    let tally = RefCell::new(Tally::default());
    runner()
        .run(
            &(0..seeds.len(), prop::collection::vec(mutation(), 1..4)),
            |(s, mutations)| {
                let seed = &seeds[s];
                let text = mutations
                    .iter()
                    .fold(seed.text.clone(), |t, m| apply(&t, m));
                let bound = bound(text.len(), seed);
                let start = Instant::now();
                let mut outcome = (false, false);
                let largest = largest_allocation(|| outcome = case(&text, seed));
                let mut tally = tally.borrow_mut();
                tally.cases += 1;
                tally.parsed += u64::from(outcome.0);
                tally.accepted_by_a_model += u64::from(outcome.1);
                tally.largest_allocation = tally.largest_allocation.max(largest);
                tally.slowest = tally.slowest.max(start.elapsed());
                prop_assert!(
                    largest <= bound,
                    "{}: an allocation of {largest} B, over the bound {bound} B",
                    seed.name
                );
                Ok(())
            },
        )
        .unwrap();
    tally.into_inner()
}

#[test]
fn the_render_scene_parser_survives_mutated_scenes() {
    let tally = fuzz(render_case, |len, seed| {
        64 * len + 4 * seed.largest_file as usize + seed.vdb_dense as usize + (1 << 20)
    });
    tally.print("render scenes");
    // The mutations are not all fatal: some scenes still parse and render.
    if tally.cases >= 256 {
        assert!(tally.accepted_by_a_model > 0);
    }
}

#[test]
fn the_bake_scene_parser_survives_mutated_scenes() {
    let case = |text: &str, seed: &Seed| {
        // A field's `file` (a tabulated field's table) is read beside the scene.
        let Ok(scene) = bake::Scene::parse_in(text, &seed.name, Some(&seed.base)) else {
            return (false, false);
        };
        // A plan of every preset: knobs for the scene's spectral mode.
        for q in [
            bake::Quality::Draft,
            bake::Quality::Standard,
            bake::Quality::Reference,
        ] {
            let _ = bake::BakePlan::for_preset(scene.clone(), "t".into(), q);
        }
        (true, false)
    };
    // The text, and a table file read and parsed (its bytes, then a few floats a byte).
    let tally = fuzz(case, |len, seed| {
        64 * len + 8 * seed.largest_file as usize + (1 << 20)
    });
    tally.print("bake scenes");
    if tally.cases >= 256 {
        assert!(tally.parsed > 0);
    }
}
