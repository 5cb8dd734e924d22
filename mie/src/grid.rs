//! The uniform scattering-angle grid of the tables, and quadrature inside its bins.
//!
//! # Convention
//! θ_k = k·Δθ, k = 0..K−1 with K = 180°/Δθ + 1 (Δθ must divide 180°). Bin k covers
//! [θ_k − Δθ/2, θ_k + Δθ/2] ∩ [0°, 180°]; a bin value is the average of p over the bin's
//! solid angle Ω_k = 2π (cos θ_lo − cos θ_hi).
//!
//! # Exact symmetry
//! Nodes of bins past 90° are the mirror images (μ → −μ, bit for bit) of nodes before 90°, so
//! the Mie kernel evaluates each ± pair once.

use crate::error::MieError;
use crate::quadrature::gauss_legendre_on;

/// A uniform grid of scattering angles with Δθ dividing 180°.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AngleGrid {
    step_deg: f64,
    count: usize,
}

impl AngleGrid {
    /// The table default: Δθ = 0.18°, 1001 samples.
    pub const DEFAULT_STEP_DEG: f64 = 0.18;

    /// A grid of step `step_deg`; 180/step must be an integer (within 1e-9) and step in [0.001°, 30°].
    pub fn new(step_deg: f64) -> Result<Self, MieError> {
        if !(step_deg.is_finite() && (0.001..=30.0).contains(&step_deg)) {
            return Err(MieError::OutOfRange {
                name: "angle step Δθ (degrees)",
                value: step_deg,
                range: "[0.001, 30] and dividing 180",
            });
        }
        let intervals = 180.0 / step_deg;
        let rounded = intervals.round();
        if (intervals - rounded).abs() > 1e-9 * rounded {
            return Err(MieError::OutOfRange {
                name: "angle step Δθ (degrees)",
                value: step_deg,
                range: "a divisor of 180 (e.g. 0.18, 0.25, 1)",
            });
        }
        Ok(Self {
            step_deg: 180.0 / rounded,
            count: rounded as usize + 1,
        })
    }

    pub fn step_deg(&self) -> f64 {
        self.step_deg
    }

    /// Number of samples K.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    /// θ_k in degrees.
    pub fn theta_deg(&self, k: usize) -> f64 {
        k as f64 * self.step_deg
    }

    /// All θ_k in degrees.
    pub fn thetas_deg(&self) -> Vec<f64> {
        (0..self.count).map(|k| self.theta_deg(k)).collect()
    }

    /// cos θ_k with cos θ_{K−1−k} = −cos θ_k exactly.
    pub fn cosines(&self) -> Vec<f64> {
        let last = self.count - 1;
        (0..self.count)
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
        let half = 0.5 * self.step_deg;
        let lo = (self.theta_deg(k) - half).max(0.0);
        let hi = if k + 1 == self.count {
            180.0
        } else {
            self.theta_deg(k) + half
        };
        (lo, hi)
    }

    /// Solid angle Ω_k of bin k (sr).
    pub fn bin_solid_angle(&self, k: usize) -> f64 {
        let (lo, hi) = self.bin_edges_deg(k);
        2.0 * std::f64::consts::PI * (lo.to_radians().cos() - hi.to_radians().cos())
    }

    /// Quadrature nodes for bin averages (see [`BinQuadrature`]).
    ///
    /// Each bin is cut into `panels(k)` equal panels in θ with `nodes_per_panel` Gauss nodes
    /// each; weights include sin θ and are normalized so they sum to 1 inside each bin.
    pub fn bin_quadrature(
        &self,
        nodes_per_panel: usize,
        panels: impl Fn(usize) -> usize,
    ) -> BinQuadrature {
        let last = self.count - 1;
        let mut mu = Vec::new();
        let mut weight = Vec::new();
        let mut bin_start = vec![0usize; self.count + 1];
        // Nodes of bins k ≤ last/2; bins past 90° reuse them mirrored.
        let mut left: Vec<(Vec<f64>, Vec<f64>)> = Vec::with_capacity(self.count / 2 + 1);
        for k in 0..self.count {
            let mirror = last - k;
            let (m, w) = if k < mirror {
                let (lo, hi) = self.bin_edges_deg(k);
                let nodes = panel_nodes(lo, hi, panels(k), nodes_per_panel);
                left.push(nodes.clone());
                nodes
            } else if k == mirror {
                // Middle bin straddles 90°: integrate [θ_lo, 90°] and mirror it.
                let (lo, _) = self.bin_edges_deg(k);
                let (m_half, w_half) = panel_nodes(lo, 90.0, panels(k), nodes_per_panel);
                let mut m = m_half.clone();
                let mut w = w_half.clone();
                m.extend(m_half.iter().map(|v| -v));
                w.extend(w_half);
                (m, w)
            } else {
                let (m, w) = &left[mirror];
                (m.iter().map(|v| -v).collect(), w.clone())
            };
            let total: f64 = w.iter().sum();
            mu.extend(m);
            weight.extend(w.iter().map(|v| v / total));
            bin_start[k + 1] = mu.len();
        }
        BinQuadrature {
            mu,
            weight,
            bin_start,
        }
    }
}

/// Gauss nodes in θ over `panels` equal panels of [lo, hi] (degrees): returns (cos θ, w sin θ).
fn panel_nodes(lo: f64, hi: f64, panels: usize, per_panel: usize) -> (Vec<f64>, Vec<f64>) {
    let panels = panels.max(1);
    let width = (hi - lo) / panels as f64;
    let mut mu = Vec::with_capacity(panels * per_panel);
    let mut w = Vec::with_capacity(panels * per_panel);
    for p in 0..panels {
        let a = (lo + p as f64 * width).to_radians();
        let b = (lo + (p + 1) as f64 * width).to_radians();
        let (t, v) = gauss_legendre_on(per_panel, a, b);
        for (t, v) in t.into_iter().zip(v) {
            mu.push(t.cos());
            w.push(v * t.sin());
        }
    }
    (mu, w)
}

/// Nodes and per-bin normalized weights: bin k averages over nodes
/// `bin_start[k]..bin_start[k+1]`.
#[derive(Debug, Clone)]
pub struct BinQuadrature {
    pub mu: Vec<f64>,
    pub weight: Vec<f64>,
    pub bin_start: Vec<usize>,
}

impl BinQuadrature {
    /// Bin averages of values given at the nodes.
    pub fn average(&self, values: &[f64]) -> Vec<f64> {
        self.bin_start
            .windows(2)
            .map(|r| {
                (r[0]..r[1])
                    .map(|i| self.weight[i] * values[i])
                    .sum::<f64>()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_grid_has_1001_samples_and_exact_mirror() {
        let grid = AngleGrid::new(0.18).unwrap();
        assert_eq!(grid.len(), 1001);
        let mu = grid.cosines();
        for k in 0..grid.len() {
            assert_eq!(mu[k], -mu[grid.len() - 1 - k]);
        }
        let total: f64 = (0..grid.len()).map(|k| grid.bin_solid_angle(k)).sum();
        assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn rejects_steps_that_do_not_divide_180() {
        assert!(AngleGrid::new(0.7).is_err());
        assert!(AngleGrid::new(0.0).is_err());
        assert!(AngleGrid::new(1.0).is_ok());
        assert!(AngleGrid::new(0.01).is_ok());
    }

    #[test]
    fn bin_quadrature_averages_cos_theta_exactly() {
        // The bin average of μ is (μ_lo + μ_hi)/2 in μ-measure; Gauss in θ with sin θ weight
        // must reproduce it.
        let grid = AngleGrid::new(1.0).unwrap();
        let q = grid.bin_quadrature(4, |_| 1);
        let avg = q.average(&q.mu);
        for k in 0..grid.len() {
            let (lo, hi) = grid.bin_edges_deg(k);
            let exact = 0.5 * (lo.to_radians().cos() + hi.to_radians().cos());
            assert!(
                (avg[k] - exact).abs() < 1e-13,
                "bin {k}: {} vs {exact}",
                avg[k]
            );
        }
    }
}
