//! Sampling and evaluating the tabulated phase functions exactly as baked, the Rayleigh phase
//! function of the air, and the small pieces of direction algebra the path tracer needs.

use std::f64::consts::PI;

use glam::DVec3;
use grid::ThetaGrid;

/// A tabulated phase function as a sampler: bin k holds the constant value p_k (1/sr) over
/// θ ∈ [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°], plus an exact forward δ of energy f.
///
/// Sampling is the inverse CDF over bins in solid angle (probability p_k Ω_k), then uniform in
/// cos θ inside the bin, and the δ as its own event of probability f: the distribution it
/// draws from is the table itself, not an approximation of it. The bins are renormalized so
/// that Σ_k p_k Ω_k = 1 − f exactly in f64 (the stored texels are 32-bit floats).
#[derive(Debug, Clone)]
pub struct PhaseSampler {
    step_rad: f64,
    /// p_k (1/sr), renormalized.
    values: Vec<f64>,
    /// Cumulative probability up to the end of bin k (the δ first): cdf[k] = f + Σ_{i ≤ k} p_i Ω_i.
    cdf: Vec<f64>,
    /// 1 − cos θ at the forward edge of bin k.
    one_minus_mu_lo: Vec<f64>,
    /// Width of bin k in cos θ.
    mu_width: Vec<f64>,
    /// Energy of the forward δ.
    delta: f64,
}

impl PhaseSampler {
    /// A sampler of `bins` (1/sr, on `grid`) with forward δ fraction `delta` ∈ [0, 1).
    pub fn new(grid: &ThetaGrid, bins: &[f64], delta: f64) -> Self {
        let widths = grid.bin_mu_widths();
        let omega = grid.bin_solid_angles();
        let total: f64 = bins.iter().zip(&omega).map(|(p, o)| p * o).sum();
        let scale = if total > 0.0 {
            (1.0 - delta) / total
        } else {
            0.0
        };
        let values: Vec<f64> = bins.iter().map(|p| p * scale).collect();
        let mut cdf = Vec::with_capacity(bins.len());
        let mut acc = delta;
        for (p, o) in values.iter().zip(&omega) {
            acc += p * o;
            cdf.push(acc);
        }
        let mut one_minus_mu_lo = Vec::with_capacity(bins.len());
        let mut s = 0.0;
        for w in &widths {
            one_minus_mu_lo.push(s);
            s += w;
        }
        Self {
            step_rad: grid.step_deg().to_radians(),
            values,
            cdf,
            one_minus_mu_lo,
            mu_width: widths,
            delta,
        }
    }

    /// The phase function (1/sr) between the direction of travel `d` and the outgoing `w`
    /// (unit vectors), without the δ (which only the forward direction itself sees).
    pub fn eval(&self, d: DVec3, w: DVec3) -> f64 {
        self.values[self.bin(d, w)]
    }

    /// The bin the angle between unit vectors `d` and `w` falls into (the same for every
    /// sampler on the same θ grid).
    pub fn bin(&self, d: DVec3, w: DVec3) -> usize {
        let theta = d.cross(w).length().atan2(d.dot(w));
        ((theta / self.step_rad).round() as usize).min(self.values.len() - 1)
    }

    /// The value (1/sr) of bin `k`.
    pub fn value(&self, k: usize) -> f64 {
        self.values[k]
    }

    /// The forward δ's energy.
    pub fn delta(&self) -> f64 {
        self.delta
    }

    /// The number of θ bins.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether there are no bins (never, for a table).
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The θ step (rad).
    pub fn step(&self) -> f64 {
        self.step_rad
    }

    /// Bin `k`'s 1 − cos θ at its forward edge and its width in cos θ.
    pub fn bin_mu(&self, k: usize) -> (f64, f64) {
        (self.one_minus_mu_lo[k], self.mu_width[k])
    }

    /// The probability p_k Ω_k of drawing bin `k`.
    pub fn probability(&self, k: usize) -> f64 {
        self.cdf[k] - if k == 0 { self.delta } else { self.cdf[k - 1] }
    }

    /// A scattering angle: `(1 − cos θ, sin θ)`, or `None` for the forward δ; `u` ∈ [0, 1)².
    pub fn sample(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        if u < self.delta {
            return None;
        }
        let u = u * self.cdf[self.cdf.len() - 1].max(self.delta);
        let k = self
            .cdf
            .partition_point(|&c| c <= u)
            .min(self.cdf.len() - 1);
        let one_minus_mu = (self.one_minus_mu_lo[k] + v * self.mu_width[k]).clamp(0.0, 2.0);
        let sin = (one_minus_mu * (2.0 - one_minus_mu)).max(0.0).sqrt();
        Some((one_minus_mu, sin))
    }
}

impl PhaseSampler {
    /// A scattering angle from the smooth part alone (the bins, without the δ), whose density
    /// in solid angle is [`PhaseSampler::eval`] / (1 − δ); `u` ∈ [0, 1)².
    pub fn sample_smooth(&self, u: f64, v: f64) -> (f64, f64) {
        let u = self.delta + u * (1.0 - self.delta);
        self.sample(u.min(1.0 - f64::EPSILON), v)
            .expect("u ≥ δ samples the bins")
    }
}

/// Rayleigh phase function 3/(16π)·(1 + cos²θ) (1/sr).
pub fn rayleigh(cos: f64) -> f64 {
    3.0 / (16.0 * PI) * (1.0 + cos * cos)
}

/// cos θ drawn from the Rayleigh phase function by inverting its CDF:
/// μ³ + 3μ = 2q with q = 4u − 2 (Cardano: μ = ∛(q + √(q² + 1)) + ∛(q − √(q² + 1))).
pub fn sample_rayleigh(u: f64) -> f64 {
    let q = 4.0 * u - 2.0;
    let r = (q * q + 1.0).sqrt();
    ((q + r).cbrt() + (q - r).cbrt()).clamp(-1.0, 1.0)
}

/// The direction at angle θ (given as 1 − cos θ and sin θ) from `d`, at azimuth 2π·`u`.
pub fn rotate(d: DVec3, one_minus_mu: f64, sin: f64, u: f64) -> DVec3 {
    let (e1, e2) = crate::geometry::basis(d);
    let phi = 2.0 * PI * u;
    ((1.0 - one_minus_mu) * d + sin * (phi.cos() * e1 + phi.sin() * e2)).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampler_reproduces_its_bins() {
        // A made-up phase function with a steep forward peak on a coarse grid.
        let grid = ThetaGrid::new(10.0).unwrap();
        let bins: Vec<f64> = (0..grid.len())
            .map(|k| 1.0 + 50.0 * (-(k as f64)).exp())
            .collect();
        let s = PhaseSampler::new(&grid, &bins, 0.2);
        let omega = grid.bin_solid_angles();
        let n = 400_000;
        let mut counts = vec![0usize; grid.len()];
        let mut deltas = 0;
        let mut rng = crate::truth::Rng::stream(7, 0, 0);
        for _ in 0..n {
            match s.sample(rng.uniform(), rng.uniform()) {
                None => deltas += 1,
                Some((omm, _)) => {
                    let theta = (1.0 - omm).clamp(-1.0, 1.0).acos().to_degrees();
                    counts[((theta / 10.0).round() as usize).min(grid.len() - 1)] += 1;
                }
            }
        }
        let f = deltas as f64 / n as f64;
        assert!((f - 0.2).abs() < 4.0 * (0.2 * 0.8 / n as f64).sqrt(), "{f}");
        for k in 0..grid.len() {
            let p = s.values[k] * omega[k];
            let got = counts[k] as f64 / n as f64;
            let sigma = (p * (1.0 - p) / n as f64).sqrt();
            assert!((got - p).abs() < 4.5 * sigma, "bin {k}: {got} vs {p}");
        }
    }

    #[test]
    fn rayleigh_inversion_matches_the_cdf() {
        for i in 0..=100 {
            let u = i as f64 / 100.0;
            let mu = sample_rayleigh(u);
            let cdf = 0.375 * (mu + mu * mu * mu / 3.0) + 0.5;
            assert!((cdf - u).abs() < 1e-12, "{u}: {mu} gives {cdf}");
        }
    }

    #[test]
    fn rotation_keeps_the_angle() {
        let d = DVec3::new(0.3, -0.8, 0.52).normalize();
        for &(t, u) in &[(0.001f64, 0.1), (1.0, 0.7), (3.0, 0.3)] {
            let w = rotate(d, 1.0 - t.cos(), t.sin(), u);
            assert!((d.dot(w) - t.cos()).abs() < 1e-12);
            assert!((w.length() - 1.0).abs() < 1e-12);
        }
    }
}
