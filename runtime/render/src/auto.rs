//! `--model auto`: the model a scene needs, chosen from the scene's optical depth and the
//! models' errors against the path-traced truth as measured on the optical-depth sweep
//! (`docs/coupled/sweep.json`, written by `docs/coupled/sweep.py`; embedded here, so that the
//! choice follows the measurements when they are re-run, and names no model itself).
//!
//! The rule: the scene's optical depth τ is that of its deepest point, the least optical depth
//! (green channel) of the three axis lines through it, all fields together
//! ([`crate::volume::DensityGrid::deepest_weighted`]): for the sweep's soft ball, τ through
//! its centre, the sweep's own measure. Each measured model's error at τ is its median
//! |bias| against the truth over the sweep's cases from the sweep depth below the smallest one
//! at or above τ up to that one (all sun azimuths, cloud and rain, and the held-out clouds
//! between them; one held-out case alone chose max for a τ 8 cloud). The
//! median, not the worst: one thin rain truth of the sweep is a heavy-tailed realization
//! (`docs/coupled/sweep.py` says why) that puts coupled 13 % and riley 17 % off at τ 0.5, and a worst
//! case would let that one draw choose for every thin scene. The choice is the cheapest model
//! (median frame time of the sweep) whose error there is within [`ACCEPTED_BIAS`]; where none
//! is, the one with the least error. Only the models that can
//! render the scene at all (the `able` list: those whose checks pass before the bake) take
//! part; a scene only an unmeasured model renders (lamps in a medium: `biri`) gets that one.

use serde::Deserialize;

/// The median |bias| against the truth a model may have at a scene's depth to be chosen.
pub const ACCEPTED_BIAS: f64 = 0.10;

/// A depth of the sweep proper has a case per sun azimuth (four) for each of cloud and rain;
/// the held-out clouds add single cases between them.
const SWEEP_DEPTH_CASES: usize = 4;

/// The sweep's measurements, as `docs/coupled/sweep.py` writes them.
const SWEEP: &str = include_str!("../../../docs/coupled/sweep.json");

/// Where the measurements are described (the table the choice cites).
pub const SOURCE: &str = "docs/coupled/sweep.md";

#[derive(Deserialize)]
struct Sweep {
    results: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    tau: f64,
    #[serde(flatten)]
    models: std::collections::BTreeMap<String, serde_json::Value>,
}

/// One model's measured figures on the sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// The model's name (`--model`).
    pub model: String,
    /// (optical depth, bias) of each case, bias = (model − truth) / truth of the image sums.
    pub cases: Vec<(f64, f64)>,
    /// The median frame time over the cases (s, one machine: a ranking, not a budget).
    pub seconds: f64,
}

/// The models the sweep measured, by name, with their cases (variants such as `coupled-48`,
/// which are settings rather than models, are kept under their own names; callers match the
/// names they can render).
pub fn measured() -> Vec<Measured> {
    let sweep: Sweep = serde_json::from_str(SWEEP).expect("docs/coupled/sweep.json is valid");
    let mut out: Vec<Measured> = Vec::new();
    let mut times: Vec<Vec<f64>> = Vec::new();
    for case in &sweep.results {
        for (name, v) in &case.models {
            let (Some(bias), Some(seconds)) = (
                v.get("bias").and_then(serde_json::Value::as_f64),
                v.get("seconds").and_then(serde_json::Value::as_f64),
            ) else {
                continue;
            };
            let i = match out.iter().position(|m| &m.model == name) {
                Some(i) => i,
                None => {
                    out.push(Measured {
                        model: name.clone(),
                        cases: Vec::new(),
                        seconds: 0.0,
                    });
                    times.push(Vec::new());
                    out.len() - 1
                }
            };
            out[i].cases.push((case.tau, bias));
            times[i].push(seconds);
        }
    }
    for (m, mut t) in out.iter_mut().zip(times) {
        t.sort_by(f64::total_cmp);
        m.seconds = t[t.len() / 2];
    }
    out
}

impl Measured {
    /// The depths of the sweep proper: those measured at every sun azimuth (at least
    /// [`SWEEP_DEPTH_CASES`] cases), not the held-out clouds' single cases between them.
    fn sweep_depths(&self) -> Vec<f64> {
        let mut depths: Vec<f64> = self.cases.iter().map(|c| c.0).collect();
        depths.sort_by(f64::total_cmp);
        depths.dedup();
        let count = |d: f64| self.cases.iter().filter(|c| c.0 == d).count();
        let main: Vec<f64> = depths
            .iter()
            .copied()
            .filter(|&d| count(d) >= SWEEP_DEPTH_CASES)
            .collect();
        if main.is_empty() { depths } else { main }
    }

    /// The depths a scene of optical depth `tau` is judged between: from the sweep depth
    /// below the smallest one at or above `tau` (exclusive; 0 at the first) up to that one (the
    /// deepest where `tau` is beyond them all), so the held-out cases count with the sweep
    /// depth above them.
    fn bracket(&self, tau: f64) -> (f64, f64) {
        let depths = self.sweep_depths();
        let upper = depths
            .iter()
            .position(|&d| d >= tau)
            .unwrap_or(depths.len() - 1);
        let lower = if upper == 0 { 0.0 } else { depths[upper - 1] };
        (lower, depths[upper])
    }

    /// The median |bias| over the cases the depth `tau` is judged by, and their count.
    pub fn error_at(&self, tau: f64) -> (f64, usize) {
        let (lower, upper) = self.bracket(tau);
        let mut errors: Vec<f64> = self
            .cases
            .iter()
            .filter(|c| c.0 > lower && c.0 <= upper)
            .map(|c| c.1.abs())
            .collect();
        errors.sort_by(f64::total_cmp);
        let n = errors.len();
        let median = if n % 2 == 1 {
            errors[n / 2]
        } else {
            0.5 * (errors[n / 2 - 1] + errors[n / 2])
        };
        (median, n)
    }
}

/// What `--model auto` chose and why, in words.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// The model chosen.
    pub model: &'static str,
    /// The scene's optical depth the choice was made at.
    pub tau: f64,
    /// One line: the depth, the chosen model's measured error there and the faster ones'.
    pub why: String,
}

pub use crate::volume::optical_depth;

/// Chooses among `able` (the models that render the scene, in `--help` order) for a scene of
/// optical depth `tau` by the module's rule, from `measured` (normally [`measured`]); a model
/// whose [`crate::registry::depth_limit`] the scene exceeds does not take part.
pub fn choose(able: &[&'static str], tau: f64, measured: &[Measured]) -> Option<Choice> {
    let too_deep: Vec<String> = able
        .iter()
        .filter_map(|&name| {
            crate::registry::depth_limit(name)
                .filter(|&limit| tau > limit)
                .map(|limit| format!("{name} takes τ ≤ {limit}"))
        })
        .collect();
    let able: Vec<&'static str> = able
        .iter()
        .copied()
        .filter(|&name| crate::registry::depth_limit(name).is_none_or(|limit| tau <= limit))
        .collect();
    let mut judged: Vec<(&'static str, &Measured, (f64, usize))> = able
        .iter()
        .filter_map(|&name| {
            measured
                .iter()
                .find(|m| m.model == name)
                .map(|m| (name, m, m.error_at(tau)))
        })
        .collect();
    if judged.is_empty() {
        let &model = able.first()?;
        return Some(Choice {
            model,
            tau,
            why: format!(
                "the only kind of model that renders this scene (no model the sweep measured \
                 does; {SOURCE})"
            ),
        });
    }
    judged.sort_by(|a, b| a.1.seconds.total_cmp(&b.1.seconds));
    let pick = judged
        .iter()
        .position(|j| j.2.0 <= ACCEPTED_BIAS)
        .unwrap_or_else(|| {
            (0..judged.len())
                .min_by(|&a, &b| judged[a].2.0.total_cmp(&judged[b].2.0))
                .expect("not empty")
        });
    let (model, m, (error, cases)) = judged[pick];
    let percent = |e: f64| format!("{:.1} %", e * 100.0);
    let mut why = format!(
        "optical depth {tau:.3} at the scene's deepest point; measured against the truth at \
         τ {} to {} ({cases} cases), {model}'s median |bias| is {}",
        m.bracket(tau).0,
        m.bracket(tau).1,
        percent(error)
    );
    let faster: Vec<String> = judged[..pick]
        .iter()
        .map(|(name, _, e)| format!("{name}'s {}", percent(e.0)))
        .collect();
    if faster.is_empty() {
        why += &format!(", the fastest within {}", percent(ACCEPTED_BIAS));
    } else {
        why += &format!(
            " (the faster {} over {})",
            faster.join(", "),
            percent(ACCEPTED_BIAS)
        );
    }
    if !too_deep.is_empty() {
        why += &format!("; {}", too_deep.join(", "));
    }
    why += &format!(" ({SOURCE})");
    Some(Choice { model, tau, why })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(name: &str, seconds: f64, cases: &[(f64, f64)]) -> Measured {
        Measured {
            model: name.into(),
            cases: cases.to_vec(),
            seconds,
        }
    }

    #[test]
    fn the_cheapest_model_within_the_bound_at_the_scenes_depth_is_chosen() {
        let m = [
            model("fast", 0.1, &[(0.1, 0.01), (1.0, -0.3), (8.0, -0.6)]),
            model("right", 4.0, &[(0.1, 0.002), (1.0, 0.02), (8.0, 0.05)]),
        ];
        assert_eq!(m[0].error_at(0.5), (0.3, 1));
        let able = ["fast", "right"];
        assert_eq!(choose(&able, 0.05, &m).unwrap().model, "fast");
        assert_eq!(choose(&able, 0.1, &m).unwrap().model, "fast");
        // Just past 0.1 the scene is judged at 1.0, where the fast model misses by 30 %.
        let c = choose(&able, 0.2, &m).unwrap();
        assert_eq!(c.model, "right");
        assert!(c.why.contains("fast's 30.0 %"), "{}", c.why);
        // Beyond every measured depth: judged at the deepest.
        assert_eq!(choose(&able, 500.0, &m).unwrap().model, "right");
        // A model that cannot render the scene is not chosen however right.
        assert_eq!(choose(&["fast"], 8.0, &m).unwrap().model, "fast");
        // None measured: the first able one.
        let c = choose(&["lamps"], 1.0, &m).unwrap();
        assert_eq!(c.model, "lamps");
        assert!(choose(&[], 1.0, &m).is_none());
    }

    #[test]
    fn held_out_cases_count_with_the_sweep_depth_above_them() {
        let mut cases: Vec<(f64, f64)> = Vec::new();
        for az in 0..4 {
            cases.push((1.0, 0.01 * f64::from(az)));
            cases.push((8.0, 0.5));
        }
        cases.push((4.0, 0.02));
        let m = model("m", 1.0, &cases);
        assert_eq!(m.bracket(0.3), (0.0, 1.0));
        assert_eq!(m.bracket(2.0), (1.0, 8.0));
        assert_eq!(m.bracket(50.0), (1.0, 8.0));
        // (1, 8]: the four at 8 and the one held out at 4; median of [0.02, 0.5 × 4].
        assert_eq!(m.error_at(5.0), (0.5, 5));
        assert_eq!(m.error_at(1.0), (0.015, 4));
    }

    #[test]
    fn where_no_model_is_within_the_bound_the_least_wrong_is_chosen() {
        let m = [
            model("a", 0.1, &[(1.0, -0.5)]),
            model("b", 1.0, &[(1.0, 0.2)]),
            model("c", 9.0, &[(1.0, 0.3)]),
        ];
        assert_eq!(choose(&["a", "b", "c"], 1.0, &m).unwrap().model, "b");
    }

    #[test]
    fn the_embedded_sweep_has_the_interactive_models_it_is_read_for() {
        let m = measured();
        let names = crate::registry::interactive_models();
        let found: Vec<&Measured> = m
            .iter()
            .filter(|x| names.contains(&x.model.as_str()))
            .collect();
        assert!(
            found.len() >= 2,
            "{:?}",
            m.iter().map(|x| &x.model).collect::<Vec<_>>()
        );
        for x in found {
            assert!(x.cases.len() >= 20, "{}: {} cases", x.model, x.cases.len());
            assert!(x.seconds > 0.0 && x.seconds.is_finite());
        }
        // What the sweep says today, as the docs put it: riley where the cloud is thin,
        // coupled where it is dense.
        let able = ["riley", "max", "coupled"];
        assert_eq!(choose(&able, 0.5, &m).unwrap().model, "riley");
        assert_eq!(choose(&able, 8.2, &m).unwrap().model, "coupled");
        assert_eq!(choose(&able, 200.0, &m).unwrap().model, "coupled");
        // Beyond the depth coupled converges at, the least wrong of the others.
        let deeper = crate::registry::depth_limit("coupled").unwrap() * 1.5;
        assert_ne!(choose(&able, deeper, &m).unwrap().model, "coupled");
    }
}
