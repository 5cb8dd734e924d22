//! The uniform scattering-angle grid every photometeor table is sampled on.
//!
//! One type, [`ThetaGrid`], serves the solver (`photometeor-mie` integrates its phase functions
//! inside these bins), the tables (`photometeor-tables` maps bin averages to Legendre
//! coefficients), the file format and the runtime (which check a bake's width against it).
//! Beside it, the numerics every crate above shares, each computed once: [`legendre`], the
//! exact integrals of P_l over the bins (the Legendre moments of a binned table, for the bake
//! and the renderers alike), and [`quadrature`], Gauss–Legendre rules.
//!
//! # Convention
//! θ_k = k·Δθ, k = 0..K−1 with K = 180°/Δθ + 1 (Δθ must divide 180°). Bin k covers
//! [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°]; a bin value is the average over the bin's solid angle
//! Ω_k = 2π Δμ_k (docs/physics.md §1).
//!
//! # Angle order
//! k = 0 is forward (θ = 0, μ = 1), k = K − 1 is backward (θ = 180°, μ = −1). The K + 1 bin
//! edges are θ = 0, Δθ/2, 3Δθ/2, …, 180° − Δθ/2, 180°; bin k lies between edge k and edge k + 1,
//! so in μ it is [μ_edge(k + 1), μ_edge(k)].
//!
//! # Numerical hazards
//! - Edge cosines near μ = −1 computed as cos θ from a rounded θ near π lose relative accuracy
//!   in 1 + μ and sin θ. The edges are mirror images (edge K − e = π − edge e), so only the
//!   forward half is computed and the backward half is copied with the sign of μ flipped: the
//!   grid is exactly symmetric and sin²θ is equally accurate at both poles.
//! - Bin widths in μ are formed without subtracting cosines: an interior bin has
//!   Δμ_k = 2 sin θ_k sin(Δθ/2), an end bin 1 − cos(Δθ/2) = 2 sin²(Δθ/4). The difference
//!   cos a − cos b would lose up to log10(1/Δθ) ≈ 2.5 digits at 0.18°.
//! - Sample cosines are exactly mirror-symmetric (cos θ_{K−1−k} = −cos θ_k bit for bit), so a
//!   kernel that is even or odd in μ can evaluate each ± pair once.

#![warn(missing_docs)]

pub mod legendre;
pub mod quadrature;

use thiserror::Error;

/// A number as an error message shows it: plainly between 1e-4 and 1e7 (and 0, ±inf, NaN),
/// else in exponent form, so that 1e-300 reads as `1e-300` and not as 300 digits. Shared by
/// every crate's range errors (the solver's, the bake's, the renderers').
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shown(pub f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if !x.is_finite() || x == 0.0 || (1e-4..1e7).contains(&x.abs()) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}

/// A step that is not a valid grid step.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GridError {
    /// Δθ outside the supported range or not a divisor of 180°.
    #[error("angle step Δθ = {step_deg}° is outside the allowed range: {range}")]
    BadStep {
        /// The offending step in degrees.
        step_deg: f64,
        /// The allowed range, in words.
        range: &'static str,
    },
}

/// A uniform grid of scattering angles with Δθ dividing 180°; K = 180°/Δθ + 1 samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThetaGrid {
    /// Number of steps N = 180°/Δθ; K = N + 1.
    n_steps: usize,
}

impl ThetaGrid {
    /// The table default: Δθ = 0.18°, 1001 samples.
    pub const DEFAULT_STEP_DEG: f64 = 0.18;
    /// The smallest supported step (18001 samples).
    pub const MIN_STEP_DEG: f64 = 0.01;
    /// The largest supported step (7 samples).
    pub const MAX_STEP_DEG: f64 = 30.0;
    /// The allowed range of Δθ, in words, for error messages.
    pub const STEP_RANGE: &str = "[0.01, 30] degrees and dividing 180 (e.g. 0.18, 0.25, 1)";

    /// A grid of step `step_deg`: 180/Δθ must be an integer (within 1e-9) and Δθ in
    /// [[`Self::MIN_STEP_DEG`], [`Self::MAX_STEP_DEG`]].
    pub fn new(step_deg: f64) -> Result<Self, GridError> {
        let bad = GridError::BadStep {
            step_deg,
            range: Self::STEP_RANGE,
        };
        if !(step_deg.is_finite() && (Self::MIN_STEP_DEG..=Self::MAX_STEP_DEG).contains(&step_deg))
        {
            return Err(bad);
        }
        let intervals = 180.0 / step_deg;
        let rounded = intervals.round();
        if (intervals - rounded).abs() > 1e-9 * rounded {
            return Err(bad);
        }
        Ok(Self {
            n_steps: rounded as usize,
        })
    }

    /// Number of samples (bins) K = N + 1.
    pub fn len(&self) -> usize {
        self.n_steps + 1
    }

    /// Always false: a grid has at least seven bins.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Δθ in degrees.
    pub fn step_deg(&self) -> f64 {
        180.0 / self.n_steps as f64
    }

    /// θ_k = k·Δθ in degrees.
    pub fn theta_deg(&self, k: usize) -> f64 {
        k as f64 * self.step_deg()
    }

    /// All θ_k in degrees.
    pub fn thetas_deg(&self) -> Vec<f64> {
        (0..self.len()).map(|k| self.theta_deg(k)).collect()
    }

    /// cos θ_k with cos θ_{K−1−k} = −cos θ_k exactly.
    pub fn cosines(&self) -> Vec<f64> {
        let last = self.len() - 1;
        (0..self.len())
            .map(|k| {
                let mirror = last - k;
                if k == mirror {
                    0.0 // θ = 90°: cos is exactly zero, not 6e-17
                } else if k < mirror {
                    self.theta_deg(k).to_radians().cos()
                } else {
                    -self.theta_deg(mirror).to_radians().cos()
                }
            })
            .collect()
    }

    /// Bin edges [θ_lo, θ_hi] of bin k in degrees, clipped to [0, 180].
    pub fn bin_edges_deg(&self, k: usize) -> (f64, f64) {
        let half = 0.5 * self.step_deg();
        let lo = (self.theta_deg(k) - half).max(0.0);
        let hi = if k + 1 == self.len() {
            180.0
        } else {
            self.theta_deg(k) + half
        };
        (lo, hi)
    }

    /// θ of the K + 1 bin edges in radians: 0, Δθ/2, 3Δθ/2, …, π − Δθ/2, π.
    pub fn edge_theta_rad(&self) -> Vec<f64> {
        let n = self.n_steps as f64;
        let k = self.len();
        (0..=k)
            .map(|e| match e {
                0 => 0.0,
                e if e == k => std::f64::consts::PI,
                e => (2 * e - 1) as f64 * std::f64::consts::PI / (2.0 * n),
            })
            .collect()
    }

    /// Edge cosines μ_e and sin²θ_e, e = 0..=K, exactly mirror-symmetric
    /// (μ_{K−e} = −μ_e, sin²θ_{K−e} = sin²θ_e). μ_e is cos θ_e rounded to f64; see
    /// [`Self::edge_mu_split`] for the rounding error.
    pub fn edge_mu_sin2(&self) -> (Vec<f64>, Vec<f64>) {
        let (mu, _, sin2) = self.edge_mu_split();
        (mu, sin2)
    }

    /// Edge cosines split as cos θ_e = μ_e + δ_e (μ_e the f64 nearest 1 − 2 sin²(θ_e/2), δ_e
    /// its rounding error, |δ_e| ≤ 1.1e-16), and sin²θ_e, e = 0..=K, mirror-symmetric.
    ///
    /// Near the poles one ulp of μ is a large relative error in 1 − μ (1e-10 at the first edge of
    /// a 0.18° grid) and moves P_l(μ) by P'_l(μ)·1.1e-16, up to l²·6e-17. Carrying δ_e lets a
    /// recurrence add the first-order correction δ·P_l and stay consistent with the exact sin²θ.
    pub fn edge_mu_split(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let theta = self.edge_theta_rad();
        let n_edges = theta.len();
        let mut mu = vec![0.0; n_edges];
        let mut delta = vec![0.0; n_edges];
        let mut sin2 = vec![0.0; n_edges];
        for e in 0..n_edges.div_ceil(2) {
            let mirror = n_edges - 1 - e;
            // θ ≤ π/2 here. v = 1 − cos θ = 2 sin²(θ/2) to relative rounding.
            let v = 2.0 * (0.5 * theta[e]).sin().powi(2);
            // TwoSum (Knuth): μ = fl(1 − v), δ = (1 − v) − μ exactly. Beyond 60° (v > 1/2) v's
            // own rounding (~2 ulps via sin²) exceeds cos θ's, so take cos θ there, δ unknown (0).
            let (m, d) = if v <= 0.5 {
                let m = 1.0 - v;
                let bb = m - 1.0;
                (m, (1.0 - (m - bb)) + (-v - bb))
            } else {
                (theta[e].cos(), 0.0)
            };
            // sin²θ = (1 − μ)(1 + μ) = v (2 − v), no cancellation.
            let s2 = v * (2.0 - v);
            mu[e] = m;
            delta[e] = d;
            sin2[e] = s2;
            mu[mirror] = -m;
            delta[mirror] = -d;
            sin2[mirror] = s2;
        }
        // Edge 0 is θ = 0 exactly (μ = 1, δ = 0, sin² = 0); edge K is θ = π exactly.
        (mu, delta, sin2)
    }

    /// Bin widths in μ, Δμ_k = ∫_bin dμ (the solid angle is Ω_k = 2π Δμ_k); Σ_k Δμ_k = 2.
    pub fn bin_mu_widths(&self) -> Vec<f64> {
        let n = self.n_steps as f64;
        let half_step = std::f64::consts::PI / (2.0 * n);
        let k_len = self.len();
        let mut d_mu = vec![0.0; k_len];
        // End bins [0, Δθ/2]: 1 − cos(Δθ/2) = 2 sin²(Δθ/4).
        let end = 2.0 * (0.5 * half_step).sin().powi(2);
        d_mu[0] = end;
        d_mu[k_len - 1] = end;
        // Interior bins [θ_k − Δθ/2, θ_k + Δθ/2]: cos a − cos b = 2 sin θ_k sin(Δθ/2),
        // with sin θ_k taken from the nearer pole so that both halves are equally accurate.
        let s_half = half_step.sin();
        for k in 1..k_len - 1 {
            let k_near = k.min(self.n_steps - k);
            let theta_k = k_near as f64 * std::f64::consts::PI / n;
            d_mu[k] = 2.0 * theta_k.sin() * s_half;
        }
        d_mu
    }

    /// Bin solid angles Ω_k = 2π Δμ_k in sr; Σ_k Ω_k = 4π.
    pub fn bin_solid_angles(&self) -> Vec<f64> {
        self.bin_mu_widths()
            .into_iter()
            .map(|d| 2.0 * std::f64::consts::PI * d)
            .collect()
    }
}

/// Interpolation weights in an optical depth τ over a table's ascending `depths` (`depths[0]
/// = 0`, then positive values spaced evenly in ln τ): quadratic in ln τ through the three
/// nearest positive depths; linear in τ between the rows at 0 and `depths[1]`; τ beyond the
/// last depth is clamped to it. Shared by every table over (τ, θ) (Biri's kernel: the bake's
/// check and the renderers' lookup) so both read it the same way. Returns three
/// (row, weight) pairs whose weights sum to 1.
pub fn depth_weights(depths: &[f64], tau: f64) -> [(usize, f64); 3] {
    assert!(
        depths.len() >= 4 && depths[0] == 0.0,
        "0 and ≥ 3 positive depths"
    );
    let tau = tau.clamp(0.0, depths[depths.len() - 1]);
    if tau <= depths[1] {
        let s = tau / depths[1];
        return [(0, 1.0 - s), (1, s), (2, 0.0)];
    }
    let j = depths
        .partition_point(|&x| x <= tau)
        .clamp(2, depths.len() - 1);
    let (a, b, c) = if j + 1 < depths.len() {
        (j - 1, j, j + 1)
    } else {
        (j - 2, j - 1, j)
    };
    let x = tau.ln();
    let (xa, xb, xc) = (depths[a].ln(), depths[b].ln(), depths[c].ln());
    [
        (a, (x - xb) * (x - xc) / ((xa - xb) * (xa - xc))),
        (b, (x - xa) * (x - xc) / ((xb - xa) * (xb - xc))),
        (c, (x - xa) * (x - xb) / ((xc - xa) * (xc - xb))),
    ]
}

/// The column k₀ and weight t of a kernel angle θ ∈ [−π/2, π/2] on a table whose columns are
/// the scattering angles θ + π/2 of a `grid` (θ_k = k·Δθ − π/2): the value there is
/// (1 − t)·v[k₀] + t·v[k₀ + 1].
pub fn kernel_column(grid: &ThetaGrid, theta: f64) -> (usize, f64) {
    let step = grid.step_deg().to_radians();
    let u = ((theta + std::f64::consts::FRAC_PI_2) / step).clamp(0.0, (grid.len() - 1) as f64);
    let k0 = (u.floor() as usize).min(grid.len() - 2);
    (k0, u - k0 as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_grid_has_1001_samples_and_exact_mirror() {
        let grid = ThetaGrid::new(0.18).unwrap();
        assert_eq!(grid.len(), 1001);
        let mu = grid.cosines();
        for k in 0..grid.len() {
            assert_eq!(mu[k], -mu[grid.len() - 1 - k]);
        }
        let total: f64 = grid.bin_solid_angles().iter().sum();
        assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn steps_that_do_not_divide_180_are_rejected() {
        assert!(ThetaGrid::new(0.18).is_ok());
        assert_eq!(ThetaGrid::new(0.18).unwrap().len(), 1001);
        assert_eq!(ThetaGrid::new(1.0).unwrap().len(), 181);
        assert_eq!(ThetaGrid::new(0.01).unwrap().len(), 18001);
        assert_eq!(ThetaGrid::new(30.0).unwrap().len(), 7);
        for bad in [0.0, -1.0, 0.7, 0.005, 36.0, 200.0, f64::NAN, f64::INFINITY] {
            assert!(ThetaGrid::new(bad).is_err(), "{bad}");
        }
        let msg = ThetaGrid::new(0.7).unwrap_err().to_string();
        assert!(msg.contains("0.7"), "{msg}");
    }

    #[test]
    fn edges_are_symmetric_and_widths_sum_to_two() {
        let grid = ThetaGrid::new(0.18).unwrap();
        let (mu, sin2) = grid.edge_mu_sin2();
        assert_eq!(mu.len(), grid.len() + 1);
        assert_eq!((mu[0], mu[grid.len()]), (1.0, -1.0));
        assert_eq!((sin2[0], sin2[grid.len()]), (0.0, 0.0));
        let (_, delta, _) = grid.edge_mu_split();
        assert!(delta.iter().all(|d| d.abs() <= 1.2e-16));
        assert_eq!(mu, grid.edge_mu_split().0);
        for e in 0..mu.len() {
            assert_eq!(mu[e], -mu[mu.len() - 1 - e]);
        }
        let d_mu = grid.bin_mu_widths();
        for k in 0..grid.len() {
            // Same widths as the cosine differences, which carry ~2e-16 per edge (rounded θ
            // near π/2, rounded 1 − μ near the poles: a
            // relative error of 1e-10 at the forward bin, 1.2e-6 wide).
            let rounded = mu[k] - mu[k + 1];
            assert!(
                (d_mu[k] - rounded).abs() <= 4e-16,
                "{k}: {:e}",
                d_mu[k] - rounded
            );
        }
        let total: f64 = d_mu.iter().sum();
        assert!((total - 2.0).abs() < 1e-14, "{total}");
    }
}
