//! A bake's rows on the grid engines load, and what moving them there costs.
//!
//! **The target grid**: `n` values v_i at μ_i = −1 + i·h, h = 2/(n − 1), from θ = 180° (i = 0)
//! to θ = 0° (i = n − 1), which the consumer reads back as the function linear in μ between
//! them: Mitsuba 3's `tabphase` does exactly that, and a texture's linear filter does it
//! between texel centres (Bevy's chromatic phase texture: column i ↔ μ_i, sampled at
//! u = (i + ½)/n).
//!
//! **Our rows** are bin averages p_k over θ ∈ [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°] in solid
//! angle, i.e. constant in μ inside a bin, with the forward peak's energy in bin 0.
//!
//! **Resampling** ([`resample`]): v_i is the row's average over the cell
//! [μ_i − h/2, μ_i + h/2] ∩ [−1, 1], from the row's exact cumulative energy. The trapezoid
//! integral 2π h (v_0/2 + v_1 + … + v_{n−2} + v_{n−1}/2) of the linear reconstruction is then
//! the row's energy exactly (1): each row's energy is conserved, and a consumer that normalises
//! the table by that integral (Mitsuba does) changes nothing.
//!
//! **The cost** ([`cost`]): the reconstruction averaged over our bins against our bins,
//! - `moved` = ½ Σ_k Ω_k |p̂_k − p_k|: the share of the scattered light that leaves in a wrong
//!   bin (0 to 1; the total-variation distance at the table's resolution);
//! - `peak_kept` = v_{n−1}/p_0: how much of the forward peak's height is left.
//!
//! A grid linear in μ starves the forward peak: a cell at μ = 1 spans θ up to
//! ≈ √(2h) rad, 1.8° at n = 4097, against a 10 µm droplet's ~2° diffraction lobe and a
//! raindrop's 0.006° peak (all of it inside our bin 0). [`samples_for`] finds the smallest
//! n = 2^k + 1 that keeps `moved` under a bound. Where the forward peak is what a grid cannot
//! hold, [`strip_forward_peak`] takes its excess over bin 1 out of the row (δ-scaling, Joseph,
//! Wiscombe & Weinman 1976): the light scattered into it travels on as if unscattered, so the
//! medium's extinction becomes σ_ext (1 − α f) and its albedo α (1 − f)/(1 − α f).

use std::f64::consts::PI;

/// A WGSL function that samples an exported curve texture as the module docs define it
/// (`photometeor export --format bevy` writes it beside the textures as `phase_curve.wgsl`).
pub const PHASE_CURVE_WGSL: &str = include_str!("phase_curve.wgsl");

/// θ-bin edges of bin k of a K-column row at step Δθ (degrees), clipped to [0°, 180°].
fn bin_edges_deg(k: usize, k_len: usize, step: f64) -> (f64, f64) {
    let lo = if k == 0 { 0.0 } else { (k as f64 - 0.5) * step };
    let hi = if k + 1 == k_len {
        180.0
    } else {
        (k as f64 + 0.5) * step
    };
    (lo, hi)
}

/// The μ range [cos θ_hi, cos θ_lo] of bin k.
fn bin_mu(k: usize, k_len: usize, step: f64) -> (f64, f64) {
    let (lo, hi) = bin_edges_deg(k, k_len, step);
    // The ends exactly: cos 180° = −1 and cos 0° = 1.
    let c = |deg: f64| {
        if deg == 0.0 {
            1.0
        } else if deg == 180.0 {
            -1.0
        } else {
            deg.to_radians().cos()
        }
    };
    (c(hi), c(lo))
}

/// Solid angle of bin k (sr).
pub fn bin_solid_angle(k: usize, k_len: usize, step: f64) -> f64 {
    let (a, b) = bin_mu(k, k_len, step);
    2.0 * PI * (b - a)
}

/// A row's cumulative energy E(μ) = 2π ∫_{−1}^{μ} p dμ', exact for bin averages.
struct Cumulative {
    /// Bin edges in μ, ascending, from −1 to 1.
    mu: Vec<f64>,
    /// E at each edge.
    e: Vec<f64>,
}

impl Cumulative {
    fn new(row: &[f64], step: f64) -> Self {
        let k_len = row.len();
        let mut mu = vec![-1.0];
        let mut e = vec![0.0];
        for k in (0..k_len).rev() {
            let (a, b) = bin_mu(k, k_len, step);
            debug_assert!((a - mu.last().unwrap()).abs() < 1e-12);
            mu.push(b);
            e.push(e.last().unwrap() + 2.0 * PI * row[k] * (b - a));
        }
        Self { mu, e }
    }

    fn at(&self, x: f64) -> f64 {
        let x = x.clamp(-1.0, 1.0);
        let i = self.mu.partition_point(|&m| m <= x);
        if i == 0 {
            return 0.0;
        }
        if i >= self.mu.len() {
            return *self.e.last().unwrap();
        }
        let (m0, m1) = (self.mu[i - 1], self.mu[i]);
        let t = if m1 > m0 { (x - m0) / (m1 - m0) } else { 0.0 };
        self.e[i - 1] + t * (self.e[i] - self.e[i - 1])
    }
}

/// μ_i of the target grid of `n` values.
pub fn grid_mu(i: usize, n: usize) -> f64 {
    if i + 1 == n {
        1.0
    } else {
        -1.0 + 2.0 * i as f64 / (n - 1) as f64
    }
}

/// The row (bin averages at step Δθ = `step` degrees) on the grid of `n` ≥ 2 values linear in
/// μ from −1 to 1, each the row's average over its cell (module docs): 1/sr.
pub fn resample(row: &[f64], step: f64, n: usize) -> Vec<f64> {
    assert!(n >= 2, "a grid in cos θ needs at least 2 values");
    let cum = Cumulative::new(row, step);
    let h = 2.0 / (n - 1) as f64;
    (0..n)
        .map(|i| {
            let m = grid_mu(i, n);
            let (a, b) = ((m - h / 2.0).max(-1.0), (m + h / 2.0).min(1.0));
            (cum.at(b) - cum.at(a)) / (2.0 * PI * (b - a))
        })
        .collect()
}

/// The consumer's function (linear in μ between `values`, module docs) at μ.
pub fn reconstruct(values: &[f64], mu: f64) -> f64 {
    let n = values.len();
    let u = ((mu.clamp(-1.0, 1.0) + 1.0) / 2.0 * (n - 1) as f64).min((n - 1) as f64);
    let i = (u.floor() as usize).min(n - 2);
    let t = u - i as f64;
    values[i] * (1.0 - t) + values[i + 1] * t
}

/// The reconstruction's average over each of our K bins at step Δθ (degrees).
pub fn reconstruct_bins(values: &[f64], step: f64, k_len: usize) -> Vec<f64> {
    let n = values.len();
    let h = 2.0 / (n - 1) as f64;
    // G(μ) = ∫_{−1}^{μ} f: trapezoids up to node i, then the part of cell i.
    let mut node = vec![0.0; n];
    for i in 1..n {
        node[i] = node[i - 1] + h * (values[i - 1] + values[i]) / 2.0;
    }
    let g = |mu: f64| {
        let u = ((mu.clamp(-1.0, 1.0) + 1.0) / h).min((n - 1) as f64);
        let i = (u.floor() as usize).min(n - 2);
        let t = u - i as f64;
        node[i] + h * (values[i] * t + (values[i + 1] - values[i]) * t * t / 2.0)
    };
    (0..k_len)
        .map(|k| {
            let (a, b) = bin_mu(k, k_len, step);
            (g(b) - g(a)) / (b - a)
        })
        .collect()
}

/// What a resampling costs one row (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cost {
    /// ½ Σ_k Ω_k |p̂_k − p_k|: the share of the light scattered into a wrong bin.
    pub moved: f64,
    /// v_{n−1}/p_0: the share of the forward peak's height that is left.
    pub peak_kept: f64,
    /// 2π h (v_0/2 + … + v_{n−1}/2) − 2π Σ_k p_k Δμ_k: the energy the resampling changed
    /// (zero to rounding).
    pub energy_change: f64,
}

/// The cost of `values` (a resampling of `row`, step Δθ degrees), module docs.
pub fn cost(row: &[f64], step: f64, values: &[f64]) -> Cost {
    let k_len = row.len();
    let moved = moved(row, &reconstruct_bins(values, step, k_len), step);
    let n = values.len();
    let h = 2.0 / (n - 1) as f64;
    let trapezoid = 2.0 * PI * h * (values.iter().sum::<f64>() - 0.5 * (values[0] + values[n - 1]));
    let energy: f64 = (0..k_len)
        .map(|k| bin_solid_angle(k, k_len, step) * row[k])
        .sum();
    Cost {
        moved,
        peak_kept: values[n - 1] / row[0],
        energy_change: trapezoid - energy,
    }
}

/// The forward peak's excess over bin 1, f = (p_0 − p_1)⁺ Ω_0, taken out of `row` and the
/// rest renormalised by 1/(1 − f) (δ-scaling, module docs): the new row and f.
pub fn strip_forward_peak(row: &[f64], step: f64) -> (Vec<f64>, f64) {
    let k_len = row.len();
    let f = ((row[0] - row[1]).max(0.0) * bin_solid_angle(0, k_len, step)).min(1.0 - 1e-12);
    let mut out = row.to_vec();
    out[0] = out[0].min(row[1]);
    for v in &mut out {
        *v /= 1.0 - f;
    }
    (out, f)
}

/// The smallest n = 2^k + 1 (k ≥ 5) up to `max_samples` whose worst `moved` over `rows` is at
/// most `max_loss`, with that worst cost; `max_samples` and its worst cost if none is.
pub fn samples_for(rows: &[&[f64]], step: f64, max_loss: f64, max_samples: usize) -> (usize, Cost) {
    let worst = |n: usize| {
        rows.iter()
            .map(|r| cost(r, step, &resample(r, step, n)))
            .fold(None::<Cost>, |w, c| match w {
                Some(w) if w.moved >= c.moved => Some(w),
                _ => Some(c),
            })
            .expect("at least one row")
    };
    let mut k = 5;
    loop {
        let n = (1usize << k) + 1;
        if n >= max_samples {
            return (max_samples, worst(max_samples));
        }
        let c = worst(n);
        if c.moved <= max_loss {
            return (n, c);
        }
        k += 1;
    }
}

/// Henyey–Greenstein's phase function p(μ) = (1 − g²)/(4π (1 + g² − 2gμ)^{3/2}) (g > 0
/// forward) as bin averages on a K-column grid at step Δθ (degrees), exact: its integral over
/// solid angle from μ = −1 is (1 − g²)/(2g) [(1 + g² − 2gμ)^{−1/2} − (1 + g)^{−1}].
pub fn hg_bins(g: f64, step: f64, k_len: usize) -> Vec<f64> {
    let e = |mu: f64| {
        if g.abs() < 1e-9 {
            (mu + 1.0) / 2.0
        } else {
            (1.0 - g * g) / (2.0 * g)
                * (1.0 / (1.0 + g * g - 2.0 * g * mu).sqrt() - 1.0 / (1.0 + g))
        }
    };
    (0..k_len)
        .map(|k| {
            let (a, b) = bin_mu(k, k_len, step);
            (e(b) - e(a)) / (2.0 * PI * (b - a))
        })
        .collect()
}

/// The asymmetry parameter g = ∫ p μ dΩ of a row of bin averages, each bin taken as constant
/// in μ (its energy times its mean μ): HG g = 0.7 binned at 0.18° gives 0.7 − 1.2·10⁻⁶.
pub fn asymmetry(row: &[f64], step: f64) -> f64 {
    let k_len = row.len();
    (0..k_len)
        .map(|k| {
            let (a, b) = bin_mu(k, k_len, step);
            2.0 * PI * row[k] * (b - a) * (a + b) / 2.0
        })
        .sum()
}

/// ½ Σ_k Ω_k |m_k − p_k|: the share of the light `model` scatters into a wrong bin of `row`.
pub fn moved(row: &[f64], model: &[f64], step: f64) -> f64 {
    let k_len = row.len();
    0.5 * (0..k_len)
        .map(|k| bin_solid_angle(k, k_len, step) * (model[k] - row[k]).abs())
        .sum::<f64>()
}

/// √(mean ((m_k − p_k)/p_k)²) over the bins with θ_k ≥ `from_deg`.
pub fn rms_relative(row: &[f64], model: &[f64], step: f64, from_deg: f64) -> f64 {
    let ks: Vec<usize> = (0..row.len())
        .filter(|&k| k as f64 * step >= from_deg && row[k] > 0.0)
        .collect();
    (ks.iter()
        .map(|&k| ((model[k] - row[k]) / row[k]).powi(2))
        .sum::<f64>()
        / ks.len().max(1) as f64)
        .sqrt()
}

/// A mixture of two Henyey–Greenstein lobes, w HG(g1) + (1 − w) HG(g2) (one lobe when w = 1):
/// what Unreal's, Unity HDRP's and Godot's volumetric fog expose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lobes {
    /// The first lobe's asymmetry.
    pub g1: f64,
    /// The second lobe's asymmetry.
    pub g2: f64,
    /// The first lobe's weight.
    pub w: f64,
    /// [`moved`] of the lobes against the row they were fitted to.
    pub moved: f64,
}

impl Lobes {
    /// The lobes' bin averages.
    pub fn bins(&self, step: f64, k_len: usize) -> Vec<f64> {
        let a = hg_bins(self.g1, step, k_len);
        if self.w >= 1.0 {
            return a;
        }
        let b = hg_bins(self.g2, step, k_len);
        a.iter()
            .zip(&b)
            .map(|(x, y)| self.w * x + (1.0 - self.w) * y)
            .collect()
    }
}

/// The single Henyey–Greenstein lobe with the least [`moved`] against `row` (a scan of g
/// over [−0.995, 0.9995], refined by golden sections).
pub fn fit_hg(row: &[f64], step: f64) -> Lobes {
    let k_len = row.len();
    let cost = |g: f64| moved(row, &hg_bins(g, step, k_len), step);
    let (lo, hi) = (-0.995, 0.9995);
    let m = 200;
    let at = |i: usize| lo + (hi - lo) * i as f64 / m as f64;
    let best = (0..=m)
        .map(|i| (i, cost(at(i))))
        .fold((0, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b })
        .0;
    let (mut a, mut b) = (at(best.saturating_sub(1)), at((best + 1).min(m)));
    let r = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..60 {
        let (c, d) = (b - r * (b - a), a + r * (b - a));
        if cost(c) < cost(d) {
            b = d;
        } else {
            a = c;
        }
    }
    let g = (a + b) / 2.0;
    Lobes {
        g1: g,
        g2: 0.0,
        w: 1.0,
        moved: cost(g),
    }
}

/// The two Henyey–Greenstein lobes with the least [`moved`] against `row`: a coarse grid of
/// (g1 ∈ [0, 0.9995], g2 ∈ [−0.995, 0.9], w ∈ [0, 1]), then a pattern search, started also
/// from the best single lobe so that two lobes never fit worse than one.
pub fn fit_dual_hg(row: &[f64], step: f64) -> Lobes {
    let k_len = row.len();
    let single = fit_hg(row, step);
    let cost = |p: [f64; 3]| {
        let l = Lobes {
            g1: p[0],
            g2: p[1],
            w: p[2],
            moved: 0.0,
        };
        moved(row, &l.bins(step, k_len), step)
    };
    let clamp = |p: [f64; 3]| {
        [
            p[0].clamp(0.0, 0.9995),
            p[1].clamp(-0.995, 0.9),
            p[2].clamp(0.0, 1.0),
        ]
    };
    let mut best = ([single.g1, 0.0, 1.0], single.moved);
    for i in 0..=20 {
        let g1 = 0.9995 * (i as f64 / 20.0).sqrt();
        for j in 0..=12 {
            let g2 = -0.995 + 1.895 * j as f64 / 12.0;
            for l in 1..=10 {
                let p = [g1, g2, l as f64 / 10.0];
                let c = cost(p);
                if c < best.1 {
                    best = (p, c);
                }
            }
        }
    }
    let mut h = [0.05, 0.08, 0.05];
    let mut rounds = 0;
    while h.iter().any(|&s| s > 1e-6) && rounds < 2000 {
        rounds += 1;
        let mut improved = false;
        for i in 0..3 {
            for sign in [1.0, -1.0] {
                let mut p = best.0;
                p[i] += sign * h[i];
                let p = clamp(p);
                let c = cost(p);
                if c < best.1 {
                    best = (p, c);
                    improved = true;
                }
            }
        }
        if !improved {
            h = h.map(|s| s / 2.0);
        }
    }
    let [g1, g2, w] = best.0;
    Lobes {
        g1,
        g2,
        w,
        moved: best.1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hg_row(g: f64, step: f64) -> Vec<f64> {
        hg_bins(g, step, (180.0 / step).round() as usize + 1)
    }

    #[test]
    fn resampling_conserves_every_rows_energy() {
        for g in [0.3, 0.85, 0.99] {
            let row = hg_row(g, 0.18);
            for n in [2, 33, 1025, 16385] {
                let c = cost(&row, 0.18, &resample(&row, 0.18, n));
                assert!(
                    c.energy_change.abs() < 1e-12,
                    "g {g} n {n}: {:e}",
                    c.energy_change
                );
            }
        }
    }

    #[test]
    fn the_cost_falls_with_samples_and_vanishes_for_smooth_rows() {
        let row = hg_row(0.3, 0.18);
        let mut last = f64::INFINITY;
        for n in [9, 33, 129, 513] {
            let c = cost(&row, 0.18, &resample(&row, 0.18, n));
            assert!(c.moved < last, "n {n}: {}", c.moved);
            last = c.moved;
        }
        assert!(last < 1e-4, "{last}");
        // A narrow lobe needs far more: g = 0.99 is ~8° wide.
        let narrow = hg_row(0.99, 0.18);
        let (n, c) = samples_for(&[&narrow], 0.18, 0.01, 1 << 22);
        assert!(c.moved <= 0.01 && n > 1000, "{n} {c:?}");
        let c_half = cost(&narrow, 0.18, &resample(&narrow, 0.18, (n - 1) / 2 + 1));
        assert!(c_half.moved > 0.01, "{c_half:?}");
    }

    #[test]
    fn the_reconstruction_of_a_fine_grid_is_the_row() {
        // A row already linear in μ comes back exactly.
        let k_len = 1001;
        let row: Vec<f64> = (0..k_len)
            .map(|k| {
                let (a, b) = bin_mu(k, k_len, 0.18);
                (1.0 + 0.5 * (a + b) / 2.0) / (4.0 * PI)
            })
            .collect();
        let v = resample(&row, 0.18, 4097);
        assert!((reconstruct(&v, 0.0) - 1.0 / (4.0 * PI)).abs() < 1e-6);
        let c = cost(&row, 0.18, &v);
        assert!(c.moved < 1e-5, "{c:?}");
    }

    #[test]
    fn lobes_fitted_to_lobes_come_back() {
        let step = 0.18;
        let row = hg_row(0.7, step);
        let one = fit_hg(&row, step);
        assert!((one.g1 - 0.7).abs() < 1e-6 && one.moved < 1e-6, "{one:?}");
        // The bins' g (each bin's energy at its mean μ) differs from HG's own by the binning:
        // −1.15·10⁻⁶ at 0.18°.
        assert!((asymmetry(&row, step) - 0.7).abs() < 1.5e-6);
        let k_len = row.len();
        let two = Lobes {
            g1: 0.9,
            g2: -0.3,
            w: 0.8,
            moved: 0.0,
        }
        .bins(step, k_len);
        let fit = fit_dual_hg(&two, step);
        assert!(fit.moved < 1e-4, "{fit:?}");
        assert!(
            (fit.g1 - 0.9).abs() < 1e-3 && (fit.g2 + 0.3).abs() < 1e-2,
            "{fit:?}"
        );
        // Two lobes never fit worse than one.
        assert!(fit_dual_hg(&row, step).moved <= one.moved);
        assert!(fit_hg(&two, step).moved > 0.01);
    }

    #[test]
    fn stripping_the_forward_peak_keeps_the_energy() {
        let mut row = hg_row(0.85, 0.18);
        let omega0 = bin_solid_angle(0, row.len(), 0.18);
        row[0] += 0.4 / omega0;
        for v in &mut row {
            *v /= 1.4;
        }
        let (s, f) = strip_forward_peak(&row, 0.18);
        let energy: f64 = (0..s.len())
            .map(|k| bin_solid_angle(k, s.len(), 0.18) * s[k])
            .sum();
        assert!((energy - 1.0).abs() < 1e-12);
        assert!((f - (0.4 + 0.0) / 1.4).abs() < 0.01, "{f}");
    }
}
