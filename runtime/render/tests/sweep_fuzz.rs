//! Property test of swept fields and size profiles, from the scene text to the shares a voxel
//! mixes: a `[[field]]` sweeping `r_eff_um` or `radius_um` (log or linear; `from`, `to` and
//! `count` at and past their limits, down to values that round to one another) and a volume
//! with a size profile `{ base, top }` at the sweep's ends, on its values, a rounding step
//! beside them, inside, outside, equal or reversed. Each case is refused by a parser or
//! `choose_members` with an error (or by the checks a bake makes before any work), or accepted: then the sweep's values are finite and
//! strictly increasing (what a manifest holds), the members chosen are 2 to 4 of them around
//! the profile, and every height of the volume gets two member indices with finite shares ≥ 0
//! that are not both 0. No panic.
//!
//! CI runs `PHOTOMETEOR_FUZZ_CASES` cases (default 256, well under a second); the long run and
//! its result are in docs/accuracy.md ("Scenes under mutation"). Failing cases are kept in
//! `tests/data/sweep-fuzz-regressions.txt` and replayed first.

use std::cell::RefCell;
use std::path::Path;

use proptest::prelude::*;
use render::RenderScene;

// The shared runner (its allocation counter is not used here).
#[path = "../../../tests/common/fuzz.rs"]
#[allow(dead_code)]
mod fuzz;

/// How one end of the profile is placed against the sweep's values.
#[derive(Debug, Clone, Copy)]
enum Place {
    /// On value k (k taken modulo the count).
    On(usize),
    /// Value k times (1 + ε) for ε in ±1e-15, ±1e-12, ±1e-9, ±1e-6.
    Beside(usize, i8),
    /// At fraction t of the way from `from` to `to`.
    Inside(f64),
    /// A factor outside [from, to]: below from or above to.
    Outside(bool, f64),
}

fn place() -> impl Strategy<Value = Place> {
    prop_oneof![
        (0usize..70).prop_map(Place::On),
        (0usize..70, -4i8..=4).prop_map(|(k, e)| Place::Beside(k, e)),
        (0.0f64..=1.0).prop_map(Place::Inside),
        (any::<bool>(), 1.0f64..1e3).prop_map(|(b, f)| Place::Outside(b, f)),
    ]
}

/// A sweep's ends: `from` and `to` as numbers a user might write, including ones that collapse.
fn ends() -> impl Strategy<Value = (f64, f64)> {
    let from = prop_oneof![
        Just(6.0),
        Just(1.0),
        Just(0.0),
        Just(1e-300),
        Just(1e-6),
        Just(1e300),
        0.01f64..100.0,
    ];
    let ratio = prop_oneof![
        Just(1.0 + 1e-15),
        Just(1.0 + 4e-16),
        Just(1.0 + 1e-9),
        Just(1.0001),
        Just(14.0 / 6.0),
        Just(1e6),
        Just(1.0),
        Just(0.5),
        1.0f64..50.0,
    ];
    (from, ratio).prop_map(|(f, r)| (f, f * r))
}

#[derive(Debug, Clone)]
struct Case {
    key_is_radius: bool,
    linear: bool,
    from: f64,
    to: f64,
    count: Option<usize>,
    base: Place,
    top: Place,
}

fn case() -> impl Strategy<Value = Case> {
    (
        any::<bool>(),
        any::<bool>(),
        ends(),
        prop_oneof![Just(None), (0usize..=66).prop_map(Some)],
        place(),
        place(),
    )
        .prop_map(
            |(key_is_radius, linear, (from, to), count, base, top)| Case {
                key_is_radius,
                linear,
                from,
                to,
                count,
                base,
                top,
            },
        )
}

/// The values the sweep would have (the bake's formula, for placing the profile; the test
/// reads the parsed sweep's own values for its checks).
fn nominal(c: &Case) -> Vec<f64> {
    let n = c.count.unwrap_or(4).clamp(2, 64);
    (0..n)
        .map(|k| {
            let t = k as f64 / (n - 1) as f64;
            if c.linear || c.from <= 0.0 {
                c.from + t * (c.to - c.from)
            } else {
                (c.from.ln() + t * (c.to / c.from).ln()).exp()
            }
        })
        .collect()
}

fn at(p: Place, v: &[f64], c: &Case) -> f64 {
    match p {
        Place::On(k) => v[k % v.len()],
        Place::Beside(k, e) => {
            let eps = [1e-15, 1e-12, 1e-9, 1e-6][(e.unsigned_abs() as usize).clamp(1, 4) - 1];
            v[k % v.len()] * (1.0 + eps * f64::from(e.signum()))
        }
        Place::Inside(t) => c.from + t * (c.to - c.from),
        Place::Outside(below, f) => {
            if below {
                c.from / f
            } else {
                c.to * f
            }
        }
    }
}

/// TOML for a number, as a user would write it (`inf`/`nan` where not finite).
fn toml_number(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else {
        format!("{x:e}")
    }
}

fn scene_text(c: &Case) -> String {
    let v = nominal(c);
    let (key, distribution) = if c.key_is_radius {
        ("radius_um", "{ kind = \"monodisperse\", radius_um = 10 }")
    } else {
        (
            "r_eff_um",
            "{ kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }",
        )
    };
    let count = c
        .count
        .map(|n| format!(", count = {n}"))
        .unwrap_or_default();
    let spacing = if c.linear { "linear" } else { "log" };
    format!(
        "[scene]\nname = \"sweep-fuzz\"\nspectral = \"rgb3\"\nn_max = 4\nquality = \"draft\"\n\n\
         [[field]]\nname = \"cloud\"\nkind = \"cloud\"\ndistribution = {distribution}\n\
         sweep = {{ key = \"{key}\", from = {}, to = {}{count}, spacing = \"{spacing}\" }}\n\n\
         [render]\nwidth = 8\nheight = 6\ngrid_resolution = 8\n\n\
         [camera]\nposition_m = [0, 500, -3000]\nlook_at_m = [0, 500, 0]\n\n\
         [sun]\nelevation_deg = 30\nazimuth_deg = 40\n\n\
         [[volume]]\nfield = \"cloud\"\nshape = \"cumulus\"\nnumber_density_per_m3 = 1e7\n\
         center_m = [0, 500, 0]\nradius_m = 300\nheight_m = 300\n\
         {key} = {{ base = {}, top = {} }}\n",
        toml_number(c.from),
        toml_number(c.to),
        toml_number(at(c.base, &v, c)),
        toml_number(at(c.top, &v, c)),
    )
}

#[derive(Default, Debug)]
struct Tally {
    cases: u64,
    bake_refused: u64,
    render_refused: u64,
    members_refused: u64,
    accepted: u64,
}

/// One case: refused somewhere with an error, or accepted with sound members and shares.
fn check(text: &str, tally: &mut Tally) -> Result<(), TestCaseError> {
    tally.cases += 1;
    let Ok(scene) = bake::Scene::parse(text, "case") else {
        tally.bake_refused += 1;
        return Ok(());
    };
    let entries: Vec<format::SweepEntry> = scene.sweeps.iter().map(|s| s.entry()).collect();
    // What a bake refuses before any work (a size parameter outside the solver's range at a
    // wavelength): a render bakes before it uses the members, so such a scene goes no further.
    let plan = bake::BakePlan::for_preset(scene.clone(), "never-written".into(), scene.quality);
    if bake::bake::check_before_work(&plan).is_err() {
        tally.bake_refused += 1;
        return Ok(());
    }
    for e in &entries {
        prop_assert!(
            e.values.len() >= 2
                && e.values.iter().all(|v| v.is_finite())
                && e.values.windows(2).all(|w| w[0] < w[1]),
            "the parser accepted a sweep the manifest refuses: {:?}",
            e.values
        );
        prop_assert_eq!(e.values.len(), e.fields.len());
    }
    let Ok(mut render) = RenderScene::parse(text, "case", Path::new(".")) else {
        tally.render_refused += 1;
        return Ok(());
    };
    if render.choose_members(&entries).is_err() {
        tally.members_refused += 1;
        return Ok(());
    }
    tally.accepted += 1;
    let sweep = &entries[0];
    for v in &render.volumes {
        let p = v.size.as_ref().expect("the volume has its profile");
        let m = p.members.as_ref().expect("members chosen");
        prop_assert!((2..=4).contains(&m.values.len()), "{:?}", m.values);
        prop_assert!(m.values.windows(2).all(|w| w[0] < w[1]));
        prop_assert!(m.values.iter().all(|x| sweep.values.contains(x)));
        let (lo, hi) = p.range();
        let (first, last) = (m.values[0], m.values[m.values.len() - 1]);
        prop_assert!(
            lo >= first * (1.0 - 1e-9) || first == sweep.values[0],
            "profile {lo} below the members from {first}"
        );
        prop_assert!(
            hi <= last * (1.0 + 1e-9) || last == sweep.values[sweep.values.len() - 1],
            "profile {hi} above the members to {last}"
        );
        // σ_ext ∝ r² (large drops), positive and finite where the values are.
        let sigma: Vec<f64> = m.values.iter().map(|r| (r * r).max(1e-300)).collect();
        let (b0, b1) = v.bounds();
        for i in 0..=16 {
            let y = b0.y + (b1.y - b0.y) * f64::from(i) / 16.0;
            let size = p.at(y, b0.y, b1.y);
            let s = m.shares(size, &sigma);
            for (k, share) in s {
                prop_assert!(k < m.values.len());
                prop_assert!(share.is_finite() && share >= 0.0, "size {size}: {s:?}");
            }
            prop_assert!(s[0].1 + s[1].1 > 0.0, "size {size}: {s:?}");
        }
    }
    Ok(())
}

#[test]
fn sweeps_and_size_profiles_are_accepted_soundly_or_refused() {
    let tally = RefCell::new(Tally::default());
    fuzz::runner("tests/data/sweep-fuzz-regressions.txt")
        .run(&case(), |c| check(&scene_text(&c), &mut tally.borrow_mut()))
        .unwrap();
    let t = tally.into_inner();
    eprintln!(
        "sweeps and profiles: {} cases: {} refused by the bake's parser, {} by the render's, \
         {} by choose_members, {} accepted",
        t.cases, t.bake_refused, t.render_refused, t.members_refused, t.accepted
    );
    // The generator reaches every outcome.
    if t.cases >= 256 {
        assert!(
            t.accepted > 0 && t.bake_refused > 0 && t.members_refused > 0,
            "{t:?}"
        );
    }
}
