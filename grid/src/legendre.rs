//! Exact bin integrals of P_l over the grid's bins, W_lk = ∫_bin k P_l(μ) dμ: the one source of
//! the Legendre moments of binned tables, for the bake (`photometeor-tables`: the bins ↔ χ_l
//! transforms) and the renderers (`photometeor-render`: the moments the δ-M split scatters by).
//!
//! # Method
//! With G_l(μ) = ∫_μ^1 P_l(μ') dμ' the bin integral is W_lk = G_l(μ_edge(k+1)) − G_l(μ_edge(k)).
//! Integrating Bonnet's recurrence gives (Abramowitz & Stegun 8.5.3 / 22.8.5)
//!
//!   (2l + 1) P_l = P'_{l+1} − P'_{l−1}        ⇒ G_l = (P_{l−1} − P_{l+1})/(2l + 1),
//!   (1 − μ²) P'_l = l (P_{l−1} − μ P_l) = l(l + 1)/(2l + 1) (P_{l−1} − P_{l+1}),
//!
//! so for l ≥ 1
//!
//!   G_l(μ) = sin²θ · P'_l(μ) / (l(l + 1)),
//!
//! which is evaluated at the K + 1 edges only; G_0 = 1 − μ gives W_0k = Δμ_k, taken from
//! [`crate::ThetaGrid::bin_mu_widths`]. P_l and P'_l advance one degree at a time across the edges
//! ([`BinIntegrals`]), so the memory is O(K) whatever l_max is; cost O(K · l_max). Only the
//! forward-half edges (θ ≤ π/2) run the recurrence; the mirror edge takes
//! G_l(−μ) = (−1)^{l+1} G_l(μ), so the table is exactly (anti)symmetric.
//!
//! # Numerical hazards
//! - The recurrence runs on v = 1 − μ = 2 sin²(θ/2), never on a rounded μ, in Reinsch's
//!   difference form (`photometeor-tables`' `legendre::reference::legendre_p_all_versine`). The plain form loses
//!   ~l^{3/2} ulp near the poles and its rounded edge cosine shifts P_l by P'_l·1e-16; measured
//!   against the per-bin oracle the plain form was off by 6.6e-13 of Δμ_k at l ≤ 200 (bin 3),
//!   this form by 8e-14 (all of it from the interior-bin difference below).
//! - No cancellation near the poles (`photometeor-tables`' `legendre` module docs); G_l is exactly 0
//!   at μ = ±1, so Σ_k W_lk telescopes to 2δ_l0 up to the rounding of K terms.
//! - Interior bins at low l subtract neighbouring G_l values of size ~sin θ·Δθ… sin²θ, losing up
//!   to log10(1/Δθ) ≈ 2.5 digits relative to W_lk at Δθ = 0.18° (measured ≤ 1e-13 of Δμ_k, see
//!   the tests). The absolute error stays ~1e-16, which is what χ_l and the bin averages see.
//! - For l Δθ ≫ 1, P_l oscillates many times within one bin and W_lk is small (~Δμ_k/(lΔθ)); it
//!   is still computed to absolute rounding, with no special case.

use crate::ThetaGrid;

/// Streams W_lk = ∫_bin k P_l(μ) dμ for l = 0, 1, 2, … over all K bins of a grid, one degree
/// at a time, in O(K) memory.
///
/// ```
/// use grid::{ThetaGrid, legendre::BinIntegrals};
/// let grid = ThetaGrid::new(1.0).unwrap();
/// let mut w = BinIntegrals::new(&grid);
/// assert_eq!(w.degree(), 0);
/// let total: f64 = w.values().iter().sum(); // ∫_{-1}^{1} P_0 dμ = 2
/// assert!((total - 2.0).abs() < 1e-14);
/// w.advance(); // l = 1
/// assert!(w.values().iter().sum::<f64>().abs() < 1e-14);
/// ```
#[derive(Debug, Clone)]
pub struct BinIntegrals {
    l: usize,
    /// Number of bins K.
    n_bins: usize,
    /// v_e = 1 − cos θ_e = 2 sin²(θ_e/2) at the forward-half edges θ_e ≤ π/2.
    v: Vec<f64>,
    /// sin²θ_e = v_e (2 − v_e) at the forward-half edges.
    sin2: Vec<f64>,
    /// P_l(μ_e), forward half.
    p_l: Vec<f64>,
    /// D_l = P_l − P_{l−1} (Reinsch's difference), forward half.
    d_l: Vec<f64>,
    /// P'_l(μ_e), forward half.
    dp_l: Vec<f64>,
    /// G_l(μ_e) = ∫_{μ_e}^1 P_l at all K + 1 edges.
    g_l: Vec<f64>,
    /// W_lk, k = 0..K.
    w_l: Vec<f64>,
}

impl BinIntegrals {
    /// Starts at l = 0 (W_0k = Δμ_k).
    pub fn new(grid: &ThetaGrid) -> Self {
        let theta = grid.edge_theta_rad();
        // Edges e and K − e are mirror images; the first ⌈(K + 1)/2⌉ have θ ≤ π/2.
        let n_half = theta.len().div_ceil(2);
        let v: Vec<f64> = theta[..n_half]
            .iter()
            .map(|t| 2.0 * (0.5 * t).sin().powi(2))
            .collect();
        let sin2 = v.iter().map(|v| v * (2.0 - v)).collect();
        Self {
            l: 0,
            n_bins: grid.len(),
            p_l: vec![1.0; n_half],
            d_l: vec![1.0; n_half],
            dp_l: vec![0.0; n_half],
            g_l: vec![0.0; theta.len()],
            w_l: grid.bin_mu_widths(),
            v,
            sin2,
        }
    }

    /// The current degree l.
    pub fn degree(&self) -> usize {
        self.l
    }

    /// W_lk = ∫_bin k P_l(μ) dμ for the current l, k = 0..K (forward bin first).
    pub fn values(&self) -> &[f64] {
        &self.w_l
    }

    /// Moves to degree l + 1.
    pub fn advance(&mut self) {
        let l = self.l as f64;
        // Bonnet's recurrence in Reinsch's difference form (μ = 1 − v, D_l = P_l − P_{l−1}):
        //   D_{l+1} = (l D_l − (2l + 1) v P_l) / (l + 1),  P_{l+1} = P_l + D_{l+1};
        // derivative P'_{l+1} = (l + 1) P_l + μ P'_l = (l + 1) P_l + P'_l − v P'_l.
        let a = (2.0 * l + 1.0) / (l + 1.0);
        let b = l / (l + 1.0);
        for e in 0..self.v.len() {
            let v = self.v[e];
            let p_l = self.p_l[e];
            let dp_l = self.dp_l[e];
            let d_next = b * self.d_l[e] - a * v * p_l;
            self.d_l[e] = d_next;
            self.p_l[e] = p_l + d_next;
            self.dp_l[e] = (l + 1.0) * p_l + (dp_l - v * dp_l);
        }
        self.l += 1;
        // G_l = sin²θ P'_l / (l(l + 1)) on the forward half; on the mirror edge
        // P'_l(−μ) = (−1)^{l+1} P'_l(μ), so G_l(−μ) = (−1)^{l+1} G_l(μ).
        let l_new = self.l as f64;
        let inv = 1.0 / (l_new * (l_new + 1.0));
        let sign = if self.l % 2 == 1 { 1.0 } else { -1.0 };
        let n_edges = self.g_l.len();
        for e in 0..self.v.len() {
            let g = self.sin2[e] * self.dp_l[e] * inv;
            self.g_l[n_edges - 1 - e] = sign * g;
            self.g_l[e] = g;
        }
        for k in 0..self.n_bins {
            self.w_l[k] = self.g_l[k + 1] - self.g_l[k];
        }
    }
}

/// All W_lk for l = 0..=l_max, stored as `w[l][k]`.
///
/// Memory is (l_max + 1)·K·8 bytes (160 MB at K = 1001, l_max = 20 000); prefer
/// [`BinIntegrals`] or the transforms below, which stream, unless the table is reused many times.
pub fn bin_integrals(grid: &ThetaGrid, l_max: usize) -> Vec<Vec<f64>> {
    let mut w = BinIntegrals::new(grid);
    let mut out = Vec::with_capacity(l_max + 1);
    for l in 0..=l_max {
        if l > 0 {
            w.advance();
        }
        out.push(w.values().to_vec());
    }
    out
}
