//! Checks a bake against theory it did not come from: the optical phenomena each field must show
//! in its single-scattering row Ams_1, at the angles geometric optics, Airy theory and Fraunhofer
//! diffraction predict from the field's own refractive index and sizes (docs/physics.md §4–5).
//!
//! # What is checked, per field and channel
//! - **Water (or ice) spheres** large enough for ray optics (x_eff ≥ 500 at every wavelength):
//!   the primary and secondary rainbow maxima, Alexander's dark band between them, the colour
//!   order of the bows; supernumerary maxima are counted (reported, not judged).
//! - **Small spheres** (x_eff < 500): the glory (back-scatter enhancement) and the first corona
//!   ring; the rainbow of such drops is a broad fogbow and is not judged.
//! - **Pristine ice crystals** (roughness ≤ 0.2): the 22° and 46° halo maxima and their colour
//!   order (red inside).
//! - **Snow**: no halo-like feature between 10° and 60°.
//!
//! # Expected angles for a channel
//! A channel mixes wavelengths λ_j with the manifest's weights w_j. Each check's theory angle
//! θ(λ) is computed per wavelength; the expected channel value is Σ w_j θ(λ_j), and the tolerance
//! is the spread of θ(λ) over the wavelengths holding the central 80 % of the channel's weight
//! (a mixture's peak lies somewhere in that spread) plus a stated margin. For `rgb3` bakes each
//! channel is one wavelength and the spread is zero: the checks are per wavelength.
//!
//! # Theory
//! - Rainbow of order k (k internal reflections): Descartes' minimum deviation,
//!   cos i = √((n² − 1)/(k(k + 2))), D = 180°k + 2i − 2(k + 1)r; the finite-size (Airy) shift
//!   of the maximum toward the lit side is 1.0188 (D''/2)^{1/3} x^{−2/3} rad, with D'' the
//!   second derivative of the deviation in the impact parameter b = sin i at the rainbow ray
//!   and 1.0188 the first maximum of Ai(−z)². x is 2π r_eff/λ (r_eff = ⟨r³⟩/⟨r²⟩).
//! - Corona: the first bright ring of the Fraunhofer pattern of the size distribution,
//!   Σ_i n_i r_i² x_i² [2J₁(x_i sin θ)/(x_i sin θ)]², summed over the channel's wavelengths.
//! - Halos: prism minimum deviation D = 2 asin(n sin(A/2)) − A, A = 60° and 90°; the histogram
//!   maximum sits 0.05–0.13° outside it (docs/physics.md §4), so 0.09° is added.

use std::path::Path;

use format::{BakeDir, FieldKind};
use mie::theory::{minimum_deviation_deg, rainbow_theory, size_parameter};
use mie::{Material, SizeDistribution};
use serde::Serialize;

use crate::error::BakeError;

type Result<T> = std::result::Result<T, BakeError>;

/// A manifest entry the checks cannot read.
fn manifest_error(what: String) -> BakeError {
    BakeError::Incompatible(format!("manifest.json: {what}"))
}

/// Size parameter above which a sphere field's rainbows are judged (and below which the glory
/// and corona are).
const RAY_OPTICS_MIN_X: f64 = 500.0;
/// Margin added to a rainbow's tolerance: the Airy shift is for one size, not a distribution.
const RAINBOW_MARGIN_DEG: f64 = 0.3;
/// Margin added to a halo's tolerance: bin width and Monte Carlo noise.
const HALO_MARGIN_DEG: f64 = 0.3;
/// Offset of the halo histogram maximum outside the minimum deviation (docs/physics.md §4).
const HALO_PEAK_OFFSET_DEG: f64 = 0.09;

/// Outcome of one check.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// The check passed.
    Pass,
    /// The check failed.
    Fail,
    /// Reported, not judged.
    Info,
}

/// One check of one field and channel.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// Name of the field checked.
    pub field: String,
    /// "R", "G", "B" or "RGB" for checks across channels.
    pub channel: String,
    /// What is checked, e.g. "glory enhancement".
    pub name: String,
    /// Value measured in the bake; None where the feature was not found or nothing is measured.
    pub measured: Option<f64>,
    /// Value theory predicts; None for checks without one.
    pub expected: Option<f64>,
    /// Allowed |measured − expected|; None for checks without one.
    pub tolerance: Option<f64>,
    /// Unit of measured, expected and tolerance: "deg", "ratio" or "".
    pub unit: &'static str,
    /// The outcome.
    pub status: Status,
    /// How the value was measured or judged.
    pub note: String,
}

/// All checks of a bake directory.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The bake directory checked.
    pub dir: String,
    /// Every check, in the order run.
    pub checks: Vec<Check>,
}

impl Report {
    /// The failed checks.
    pub fn failures(&self) -> Vec<&Check> {
        self.checks
            .iter()
            .filter(|c| c.status == Status::Fail)
            .collect()
    }
}

const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// A channel's wavelengths and weights (Σ = 1, zero weights dropped).
#[derive(Debug, Clone)]
struct ChannelBand {
    lambda_nm: Vec<f64>,
    weight: Vec<f64>,
}

impl ChannelBand {
    /// Weighted mean of `f(λ)` and the spread of f over the central 80 % of the weight.
    fn expect(&self, f: impl Fn(f64) -> f64) -> (f64, f64) {
        let values: Vec<f64> = self.lambda_nm.iter().map(|&l| f(l)).collect();
        let mean: f64 = values.iter().zip(&self.weight).map(|(v, w)| v * w).sum();
        let mut cum = 0.0;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (v, w) in values.iter().zip(&self.weight) {
            let before = cum;
            cum += w;
            if cum >= 0.1 && before <= 0.9 {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
        let spread = (hi - mean).abs().max((mean - lo).abs());
        (mean, if spread.is_finite() { spread } else { 0.0 })
    }
}

/// Validates the bake in `dir`.
pub fn validate(dir: &Path) -> Result<Report> {
    let bake = BakeDir::open(dir)?;
    let manifest = &bake.manifest;
    let step = manifest.theta_step_deg;
    let lambdas = &manifest.channels.wavelengths_nm;
    let spectra: Vec<ChannelBand> = manifest
        .channels
        .weights
        .as_array()
        .into_iter()
        .map(|w| {
            // The manifest's checks hold: one weight per wavelength, summing to 1.
            let total: f64 = w.iter().sum();
            let (lambda_nm, weight) = lambdas
                .iter()
                .zip(w)
                .filter(|(_, w)| **w > 0.0)
                .map(|(l, w)| (*l, w / total))
                .unzip();
            ChannelBand { lambda_nm, weight }
        })
        .collect();

    let mut checks = Vec::new();
    for entry in &manifest.fields {
        // Every file of the field, each checked against its contract, the manifest and the
        // others: a corrupt side table fails validation too.
        let image = bake.read_field_files(entry)?.image;
        let ams1: Vec<Vec<f64>> = (0..3).map(|c| image.row(c, 0).to_vec()).collect();
        let rows: Vec<&[f64]> = ams1.iter().map(Vec::as_slice).collect();
        let micro = &entry.microphysics;
        let material = match micro.material {
            format::Material::Water => Material::Water,
            format::Material::Ice => Material::Ice,
        };
        let temperature_c = micro.temperature_c;
        let n_of = |lambda: f64| -> f64 {
            material
                .refractive_index(lambda, temperature_c)
                .map(|m| m.re)
                .unwrap_or(f64::NAN)
        };
        let ctx = FieldContext {
            name: &entry.name,
            step,
            rows: &rows,
            spectra: &spectra,
        };
        match entry.kind {
            FieldKind::Cloud | FieldKind::Rain => {
                let distribution: SizeDistribution =
                    serde_json::from_value(micro.distribution.clone().unwrap_or_default())
                        .map_err(|e| {
                            manifest_error(format!("field {:?}: distribution: {e}", entry.name))
                        })?;
                spheres(&ctx, &n_of, &distribution, &mut checks)?;
            }
            FieldKind::Ice => {
                let roughness = micro
                    .crystal
                    .as_ref()
                    .and_then(|c| c.get("roughness"))
                    .and_then(serde_json::Value::as_f64)
                    .unwrap_or(0.0);
                if roughness <= 0.2 {
                    halos(&ctx, &n_of, &mut checks);
                } else {
                    checks.push(ctx.info(
                        "RGB",
                        "halos",
                        format!("roughness {roughness} > 0.2: halos are not expected"),
                    ));
                }
            }
            FieldKind::Snow | FieldKind::Haze => featureless(&ctx, &mut checks),
            FieldKind::Hg => {
                let hg: mie::hg::HgField =
                    serde_json::from_value(micro.hg.clone().unwrap_or_default())
                        .map_err(|e| manifest_error(format!("field {:?}: hg: {e}", entry.name)))?;
                given_lobe(&ctx, &hg.lobes, &mut checks)?;
            }
            FieldKind::Tabulated => {
                let table: mie::tabulated::TabulatedField = serde_json::from_value(
                    micro.tabulated.clone().unwrap_or_default(),
                )
                .map_err(|e| manifest_error(format!("field {:?}: tabulated: {e}", entry.name)))?;
                given_table(&ctx, &table, &mut checks)?;
            }
        }
    }
    Ok(Report {
        dir: dir.display().to_string(),
        checks,
    })
}

struct FieldContext<'a> {
    name: &'a str,
    step: f64,
    rows: &'a [&'a [f64]],
    spectra: &'a [ChannelBand],
}

impl FieldContext<'_> {
    fn info(&self, channel: &str, name: &str, note: String) -> Check {
        Check {
            field: self.name.to_string(),
            channel: channel.to_string(),
            name: name.to_string(),
            measured: None,
            expected: None,
            tolerance: None,
            unit: "",
            status: Status::Info,
            note,
        }
    }

    fn judged(
        &self,
        channel: usize,
        name: &str,
        measured: Option<f64>,
        expected: f64,
        tolerance: f64,
        unit: &'static str,
        note: String,
    ) -> Check {
        let pass = measured.is_some_and(|m| (m - expected).abs() <= tolerance);
        Check {
            field: self.name.to_string(),
            channel: CHANNELS[channel].to_string(),
            name: name.to_string(),
            measured,
            expected: Some(expected),
            tolerance: Some(tolerance),
            unit,
            status: if pass { Status::Pass } else { Status::Fail },
            note,
        }
    }

    fn bin(&self, theta_deg: f64) -> usize {
        ((theta_deg / self.step).round().max(0.0) as usize).min(self.rows[0].len() - 1)
    }

    fn mean(&self, c: usize, a_deg: f64, b_deg: f64) -> f64 {
        let (a, b) = (self.bin(a_deg.min(b_deg)), self.bin(a_deg.max(b_deg)));
        self.rows[c][a..=b].iter().sum::<f64>() / (b - a + 1) as f64
    }

    /// The highest local maximum in [a, b] degrees, refined by a parabola through its
    /// neighbours; None when the window holds no local maximum.
    fn peak(&self, c: usize, a_deg: f64, b_deg: f64) -> Option<f64> {
        let row = self.rows[c];
        let (a, b) = (self.bin(a_deg).max(1), self.bin(b_deg).min(row.len() - 2));
        let k = (a..=b)
            .filter(|&k| row[k] > row[k - 1] && row[k] >= row[k + 1])
            .max_by(|&i, &j| row[i].total_cmp(&row[j]))?;
        Some(refine(row, k) * self.step)
    }
}

/// Sub-bin position (in bins) of the maximum at `k` by a parabola through k − 1, k, k + 1.
fn refine(row: &[f64], k: usize) -> f64 {
    let (ym, y0, yp) = (row[k - 1], row[k], row[k + 1]);
    let den = ym - 2.0 * y0 + yp;
    let off = if den < 0.0 {
        (0.5 * (ym - yp) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    k as f64 + off
}

/// A sphere field's checks: the rainbows when every wavelength's x_eff reaches
/// [`RAY_OPTICS_MIN_X`], else the glory and the first corona ring per channel.
fn spheres(
    ctx: &FieldContext,
    n_of: &dyn Fn(f64) -> f64,
    d: &SizeDistribution,
    checks: &mut Vec<Check>,
) -> Result<()> {
    let q = d.quadrature(256, 1e-4);
    let r_eff = q.effective_radius_um();
    let x_of = |lambda: f64| size_parameter(r_eff, lambda);
    let x_min = ctx
        .spectra
        .iter()
        .flat_map(|s| s.lambda_nm.iter())
        .map(|&l| x_of(l))
        .fold(f64::INFINITY, f64::min);
    if x_min >= RAY_OPTICS_MIN_X {
        rainbows(ctx, n_of, r_eff, checks);
    } else {
        checks.push(ctx.info(
            "RGB",
            "rainbows",
            format!("x_eff = {x_min:.0} < {RAY_OPTICS_MIN_X}: a fogbow, not judged"),
        ));
        for c in 0..3 {
            glory(ctx, c, checks);
            corona(ctx, c, &q, checks);
        }
    }
    Ok(())
}

/// Each channel's bows (see [`rainbow_channel`]), then the colour order of the primary (red
/// outside) and, where every channel has one, of the secondary (red inside).
fn rainbows(ctx: &FieldContext, n_of: &dyn Fn(f64) -> f64, r_eff: f64, checks: &mut Vec<Check>) {
    let mut primary = [f64::NAN; 3];
    let mut secondary = [f64::NAN; 3];
    for c in 0..3 {
        (primary[c], secondary[c]) = rainbow_channel(ctx, c, n_of, r_eff, checks);
    }
    checks.push(order_check(
        ctx,
        "primary rainbow colour order (red outside: θ_R < θ_B)",
        primary[0] < primary[2],
        primary[2] - primary[0],
    ));
    if secondary.iter().all(|s| s.is_finite()) {
        checks.push(order_check(
            ctx,
            "secondary rainbow colour order (red inside: θ_R > θ_B)",
            secondary[0] > secondary[2],
            secondary[0] - secondary[2],
        ));
    }
}

/// Channel `c`'s primary and secondary rainbow maxima judged against Descartes + the Airy
/// shift (r_eff in µm), and where both are found the dark band between them and the
/// supernumeraries; returns the measured primary and secondary angles in degrees (NaN where
/// not found, or for the secondary where it is not judged).
fn rainbow_channel(
    ctx: &FieldContext,
    c: usize,
    n_of: &dyn Fn(f64) -> f64,
    r_eff: f64,
    checks: &mut Vec<Check>,
) -> (f64, f64) {
    let x_of = |lambda: f64| size_parameter(r_eff, lambda);
    let s = &ctx.spectra[c];
    let (e1, t1) = s.expect(|l| {
        let (t, sh) = rainbow_theory(n_of(l), 1, x_of(l));
        t + sh
    });
    let (e2, t2) = s.expect(|l| {
        let (t, sh) = rainbow_theory(n_of(l), 2, x_of(l));
        t - sh
    });
    let m1 = ctx.peak(c, e1 - 4.0, e1 + 4.0);
    let note = format!("Descartes + Airy shift, r_eff = {r_eff:.1} µm");
    checks.push(ctx.judged(
        c,
        "primary rainbow",
        m1,
        e1,
        t1 + RAINBOW_MARGIN_DEG,
        "deg",
        note.clone(),
    ));
    // Below n ≈ 1.32 (ice spheres) the two bows overlap: no separate secondary and no
    // dark band to judge.
    let primary = m1.unwrap_or(f64::NAN);
    if e2 + 3.0 + t1 + t2 > e1 {
        checks.push(ctx.info(
            CHANNELS[c],
            "secondary rainbow",
            format!("expected at {e2:.2}°, too close to the primary ({e1:.2}°): bows overlap, not judged"),
        ));
        return (primary, f64::NAN);
    }
    let m2 = ctx.peak(c, e2 - 4.0, e2 + 4.0);
    checks.push(ctx.judged(
        c,
        "secondary rainbow",
        m2,
        e2,
        t2 + RAINBOW_MARGIN_DEG,
        "deg",
        note,
    ));
    let (Some(p1), Some(p2)) = (m1, m2) else {
        return (primary, f64::NAN);
    };
    dark_band(ctx, c, p1, p2, checks);
    (primary, p2)
}

/// Alexander's dark band between the primary at `p1` and the secondary at `p2` (degrees),
/// judged by its contrast, and the supernumerary maxima inside the primary, counted.
fn dark_band(ctx: &FieldContext, c: usize, p1: f64, p2: f64, checks: &mut Vec<Check>) {
    // Alexander's dark band: darker than the sky inside the primary and outside the
    // secondary (in scattering angle: above p1, below p2).
    let band = ctx.mean(c, p2 + 1.5, p1 - 1.5);
    let inside = ctx.mean(c, p1 + 1.0, p1 + 6.0);
    let outside = ctx.mean(c, p2 - 6.0, p2 - 1.0);
    let contrast = inside.min(outside) / band;
    checks.push(Check {
        status: if contrast > 1.0 {
            Status::Pass
        } else {
            Status::Fail
        },
        ..ctx.judged(
            c,
            "Alexander's dark band contrast",
            Some(contrast),
            1.0,
            f64::INFINITY,
            "ratio",
            "min(mean 1–6° inside the primary, mean 1–6° outside the secondary) / mean of the band; must exceed 1".into(),
        )
    });
    checks.push(Check {
        measured: Some(supernumeraries(ctx, c, p1) as f64),
        status: Status::Info,
        ..ctx.info(
            CHANNELS[c],
            "supernumerary maxima",
            "local maxima 0.5–6° inside the primary, ≥ 1 % above the minimum before them".into(),
        )
    });
}

/// Channel `c`'s glory: the back-scatter peak (mean over 179.5–180°) over the minimum between
/// 170° and 178° must exceed 1.5.
fn glory(ctx: &FieldContext, c: usize, checks: &mut Vec<Check>) {
    // Glory: the back-scatter peak over the minimum between 170° and 178°.
    let glory = ctx.mean(c, 179.5, 180.0) / min_in(ctx, c, 170.0, 178.0);
    checks.push(Check {
        status: if glory > 1.5 {
            Status::Pass
        } else {
            Status::Fail
        },
        ..ctx.judged(
            c,
            "glory enhancement",
            Some(glory),
            1.5,
            f64::INFINITY,
            "ratio",
            "mean over 179.5–180° / minimum over 170–178°; must exceed 1.5".into(),
        )
    });
}

/// Channel `c`'s first corona ring against the size distribution's Fraunhofer pattern
/// (± 10 %, degrees); reported, not judged, when the ring lies within [`CORONA_MIN_BINS`] bins
/// of 0° or there is none.
fn corona(
    ctx: &FieldContext,
    c: usize,
    q: &mie::distribution::SizeQuadrature,
    checks: &mut Vec<Check>,
) {
    let s = &ctx.spectra[c];
    match corona_ring_deg(q, s) {
        Some(expected) if expected > CORONA_MIN_BINS * ctx.step => {
            let tol = (0.1 * expected).max(1.5 * ctx.step);
            let measured = ctx.peak(c, 0.7 * expected, 1.3 * expected);
            checks.push(ctx.judged(
                c,
                "first corona ring",
                measured,
                expected,
                tol,
                "deg",
                "first bright ring of the distribution's Fraunhofer pattern ± 10 %".into(),
            ));
        }
        Some(ring) => checks.push(ctx.info(
            CHANNELS[c],
            "first corona ring",
            format!(
                "not judged: the Fraunhofer ring at {ring:.3}° lies within {CORONA_MIN_BINS} bins \
                 of 0°, where the table's first bins hold the unresolved diffraction peak"
            ),
        )),
        None => checks.push(ctx.info(
            CHANNELS[c],
            "first corona ring",
            "not judged: the distribution's Fraunhofer pattern has no ring".into(),
        )),
    }
}

/// The nearest to 0° (in bins of Δθ) a corona ring is judged: a cloud sweep over 4–32 µm
/// (v_eff 0.02, Δθ = 0.18°) found every ring beyond 7.1 bins within 10 % and missed rings at
/// 5.4–6.3 bins in the tables' forward bins, where the unresolved diffraction peak is kept.
pub const CORONA_MIN_BINS: f64 = 7.0;

fn min_in(ctx: &FieldContext, c: usize, a: f64, b: f64) -> f64 {
    ctx.rows[c][ctx.bin(a)..=ctx.bin(b)]
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

fn order_check(ctx: &FieldContext, name: &str, ok: bool, difference: f64) -> Check {
    Check {
        field: ctx.name.to_string(),
        channel: "RGB".into(),
        name: name.into(),
        measured: difference.is_finite().then_some(difference),
        expected: None,
        tolerance: None,
        unit: "deg",
        status: if ok { Status::Pass } else { Status::Fail },
        note: "measured: the angle difference whose sign is checked".into(),
    }
}

/// Local maxima 0.5–6° inside the primary bow (θ > p1) that rise ≥ 1 % above the preceding
/// minimum.
fn supernumeraries(ctx: &FieldContext, c: usize, p1: f64) -> usize {
    let row = ctx.rows[c];
    let (a, b) = (ctx.bin(p1 + 0.5), ctx.bin(p1 + 6.0));
    let mut count = 0;
    let mut low = row[a];
    for k in a + 1..b {
        low = low.min(row[k]);
        if row[k] > row[k - 1] && row[k] >= row[k + 1] && row[k] > 1.01 * low {
            count += 1;
            low = row[k];
        }
    }
    count
}

/// First bright ring (degrees) of Σ_λ w_λ Σ_i n_i r_i² x_i² [2J₁(u)/u]², u = x_i sin θ, below
/// 30°: the first local maximum that rises ≥ 1 % above the minimum before it (a broad
/// distribution of large drops has a monotonic pattern whose far tail wobbles by parts in 10⁶,
/// which is no ring).
fn corona_ring_deg(q: &mie::distribution::SizeQuadrature, s: &ChannelBand) -> Option<f64> {
    let pattern = |theta_deg: f64| -> f64 {
        let st = theta_deg.to_radians().sin();
        let mut sum = 0.0;
        for (&l, &wl) in s.lambda_nm.iter().zip(&s.weight) {
            for (&r, &n) in q.radius_um.iter().zip(&q.weight) {
                let x = size_parameter(r, l);
                let u = x * st;
                let a = if u < 1e-8 { 1.0 } else { 2.0 * libm::j1(u) / u };
                sum += wl * n * r * r * x * x * a * a;
            }
        }
        sum
    };
    let h = 0.005;
    let mut prev = pattern(h);
    let mut cur = pattern(2.0 * h);
    let mut falling = cur < prev;
    let mut low = cur.min(prev);
    let mut theta = 2.0 * h;
    while theta < 30.0 {
        let next = pattern(theta + h);
        if cur < prev {
            falling = true;
        }
        low = low.min(cur);
        if falling && cur > prev && cur >= next && cur > 1.01 * low {
            return Some(theta);
        }
        prev = cur;
        cur = next;
        theta += h;
    }
    None
}

fn halos(ctx: &FieldContext, n_of: &dyn Fn(f64) -> f64, checks: &mut Vec<Check>) {
    for (apex, name) in [(60.0, "22° halo"), (90.0, "46° halo")] {
        let mut peaks = [f64::NAN; 3];
        for c in 0..3 {
            let (e, spread) = ctx.spectra[c]
                .expect(|l| minimum_deviation_deg(n_of(l), apex) + HALO_PEAK_OFFSET_DEG);
            let m = ctx.peak(c, e - 2.5, e + 2.5);
            peaks[c] = m.unwrap_or(f64::NAN);
            checks.push(ctx.judged(
                c,
                name,
                m,
                e,
                spread + HALO_MARGIN_DEG,
                "deg",
                format!("prism minimum deviation (apex {apex}°) + {HALO_PEAK_OFFSET_DEG}°"),
            ));
        }
        checks.push(order_check(
            ctx,
            &format!("{name} colour order (red inside: θ_R < θ_B)"),
            peaks[0] < peaks[2],
            peaks[2] - peaks[0],
        ));
    }
}

/// Largest relative excess, between 10° and 60°, of a 5-bin mean over the 41-bin mean around
/// it: a halo makes tens of percent, Monte Carlo noise on a smooth curve about a percent.
pub const FEATURELESS_MAX_EXCESS: f64 = 0.05;

/// The largest relative difference an `hg` field's Ams_1 may have from its lobe's exact bin
/// averages: the EXR's 32-bit floats round to 6e-8.
pub const GIVEN_LOBE_MAX_ERROR: f64 = 1e-7;

/// An `hg` field's Ams_1 against its lobe's closed-form bin averages (`mie::hg`), per channel.
fn given_lobe(
    ctx: &FieldContext,
    lobes: &[mie::hg::HgLobe; 3],
    checks: &mut Vec<Check>,
) -> Result<()> {
    let grid = mie::ThetaGrid::new(ctx.step)
        .map_err(|e| manifest_error(format!("theta_step_deg = {}: {e}", ctx.step)))?;
    for (c, lobe) in lobes.iter().enumerate() {
        let note = format!(
            "largest relative difference from the Henyey–Greenstein lobe's bin averages (g {}, \
             g2 {}, weight {})",
            lobe.g, lobe.g2, lobe.weight
        );
        checks.push(given_check(
            ctx,
            c,
            "Ams_1 is the given lobe",
            &lobe.bins(&grid),
            note,
        ));
    }
    Ok(())
}

/// A `tabulated` field's Ams_1 against its table's exact bin averages (`mie::tabulated`), per
/// channel, where a channel reads one column (a table with one column, or rgb3's one per
/// channel); a spectral table's channels mix many columns and are noted, not judged.
fn given_table(
    ctx: &FieldContext,
    table: &mie::tabulated::TabulatedField,
    checks: &mut Vec<Check>,
) -> Result<()> {
    let grid = mie::ThetaGrid::new(ctx.step)
        .map_err(|e| manifest_error(format!("theta_step_deg = {}: {e}", ctx.step)))?;
    if table.columns.len() != 1 && table.columns.len() != 3 {
        checks.push(ctx.info(
            "RGB",
            "Ams_1 is the given table",
            format!(
                "{} columns, one per wavelength: each channel mixes them by its spectral weights",
                table.columns.len()
            ),
        ));
        return Ok(());
    }
    for c in 0..3 {
        let column = table.column_of(c);
        let note = format!(
            "largest relative difference from the bin averages of {} column {} ({} rows, linear \
             in θ; its integral over the sphere {:.6} was normalized to 1)",
            table.file,
            column + 1,
            table.theta_deg.len(),
            table.sphere_integral(column)
        );
        let want = table.bins(column, &grid);
        checks.push(given_check(ctx, c, "Ams_1 is the given table", &want, note));
    }
    Ok(())
}

/// Channel `c`'s Ams_1 against a given phase function's exact bin averages `want`, judged to
/// [`GIVEN_LOBE_MAX_ERROR`]: the largest |got/want − 1| (a bin a table sets to zero, which has
/// no relative error, by |got| in 1/sr).
fn given_check(ctx: &FieldContext, c: usize, name: &str, want: &[f64], note: String) -> Check {
    let worst = ctx.rows[c]
        .iter()
        .zip(want)
        .map(|(got, want)| {
            if *want > 0.0 {
                (got / want - 1.0).abs()
            } else {
                got.abs()
            }
        })
        .fold(0.0, f64::max);
    ctx.judged(c, name, Some(worst), 0.0, GIVEN_LOBE_MAX_ERROR, "rel", note)
}

fn featureless(ctx: &FieldContext, checks: &mut Vec<Check>) {
    for c in 0..3 {
        let row = ctx.rows[c];
        let (a, b) = (ctx.bin(10.0), ctx.bin(60.0));
        let mean = |k: usize, half: usize| {
            row[k - half..=k + half].iter().sum::<f64>() / (2 * half + 1) as f64
        };
        let excess = (a..=b)
            .map(|k| mean(k, 2) / mean(k, 20) - 1.0)
            .fold(f64::NEG_INFINITY, f64::max);
        checks.push(Check {
            status: if excess < FEATURELESS_MAX_EXCESS {
                Status::Pass
            } else {
                Status::Fail
            },
            ..ctx.judged(
                c,
                "featureless 10–60° (no halo)",
                Some(excess),
                0.0,
                FEATURELESS_MAX_EXCESS,
                "ratio",
                "largest excess of a 0.9° mean over the 7.4° mean around it".into(),
            )
        });
    }
}
