//! Quadrature inside the bins of the table grid ([`ThetaGrid`], re-exported from
//! `photometeor-grid`).
//!
//! # Exact symmetry
//! Nodes of bins past 90° are the mirror images (μ → −μ, bit for bit) of nodes before 90°, so
//! the Mie kernel evaluates each ± pair once.

pub use grid::{GridError, ThetaGrid};

use crate::quadrature::gauss_legendre_on;

/// Quadrature nodes for bin averages on `grid` (see [`BinQuadrature`]).
///
/// Each bin is cut into `panels(k)` equal panels in θ with `nodes_per_panel` Gauss nodes
/// each; weights include sin θ and are normalized so they sum to 1 inside each bin.
pub fn bin_quadrature(
    grid: &ThetaGrid,
    nodes_per_panel: usize,
    panels: impl Fn(usize) -> usize,
) -> BinQuadrature {
    let last = grid.len() - 1;
    let mut mu = Vec::new();
    let mut weight = Vec::new();
    let mut bin_start = vec![0usize; grid.len() + 1];
    // Nodes of bins k ≤ last/2; bins past 90° reuse them mirrored.
    let mut left: Vec<(Vec<f64>, Vec<f64>)> = Vec::with_capacity(grid.len() / 2 + 1);
    for k in 0..grid.len() {
        let mirror = last - k;
        let (m, w) = if k < mirror {
            let (lo, hi) = grid.bin_edges_deg(k);
            let nodes = panel_nodes(lo, hi, panels(k), nodes_per_panel);
            left.push(nodes.clone());
            nodes
        } else if k == mirror {
            // Middle bin straddles 90°: integrate [θ_lo, 90°] and mirror it.
            let (lo, _) = grid.bin_edges_deg(k);
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
    /// Node cosines μ = cos θ, bin by bin.
    pub mu: Vec<f64>,
    /// Node weights (sin θ included), summing to 1 within each bin.
    pub weight: Vec<f64>,
    /// Index of each bin's first node; len() = bins + 1, last = total nodes.
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
    fn bin_quadrature_averages_cos_theta_exactly() {
        // The bin average of μ is (μ_lo + μ_hi)/2 in μ-measure; Gauss in θ with sin θ weight
        // must reproduce it.
        let grid = ThetaGrid::new(1.0).unwrap();
        let q = bin_quadrature(&grid, 4, |_| 1);
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
