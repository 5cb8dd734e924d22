//! Shared helpers for the integration tests: a seeded LCG and exact bin averages of analytic
//! phase functions.

#![allow(dead_code)]

use std::f64::consts::PI;
use tables::legendre::ThetaGrid;

/// Knuth's MMIX 64-bit LCG; `uniform` takes the top 53 bits.
pub struct Lcg(u64);

impl Lcg {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [−1, 1).
    pub fn symmetric(&mut self) -> f64 {
        2.0 * self.uniform() - 1.0
    }
}

/// Edge cosines of bin k: (μ_lo, μ_hi).
pub fn bin_mu_range(mu_edges: &[f64], k: usize) -> (f64, f64) {
    (mu_edges[k + 1], mu_edges[k])
}

/// Exact bin averages over solid angle of p(μ), given its antiderivative in μ, A(μ) with
/// A' = p: v_k = (A(μ_hi) − A(μ_lo)) / Δμ_k.
pub fn bin_averages_of(grid: &ThetaGrid, antiderivative: impl Fn(f64) -> f64) -> Vec<f64> {
    let (mu, _) = grid.edge_mu_sin2();
    let d_mu = grid.bin_mu_widths();
    (0..grid.len())
        .map(|k| {
            let (lo, hi) = bin_mu_range(&mu, k);
            (antiderivative(hi) - antiderivative(lo)) / d_mu[k]
        })
        .collect()
}

/// Exact bin averages of Henyey–Greenstein,
/// p = (1 − g²) / (4π (1 + g² − 2gμ)^{3/2}), ∫ p dμ = (1 − g²) / (4π g √(1 + g² − 2gμ)).
pub fn henyey_greenstein_bins(grid: &ThetaGrid, g: f64) -> Vec<f64> {
    bin_averages_of(grid, |mu| {
        (1.0 - g * g) / (4.0 * PI * g * (1.0 + g * g - 2.0 * g * mu).sqrt())
    })
}

/// Exact bin averages of Rayleigh, p = 3/(16π) (1 + μ²), ∫ p dμ = 3/(16π) (μ + μ³/3).
pub fn rayleigh_bins(grid: &ThetaGrid) -> Vec<f64> {
    bin_averages_of(grid, |mu| 3.0 / (16.0 * PI) * (mu + mu * mu * mu / 3.0))
}

/// max_i |x_i − y_i|.
pub fn max_abs_diff(x: &[f64], y: &[f64]) -> f64 {
    x.iter()
        .zip(y)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

/// max_i |x_i|.
pub fn max_abs(x: &[f64]) -> f64 {
    x.iter().map(|a| a.abs()).fold(0.0, f64::max)
}

/// The rows of an (N, K) table as nested vectors.
pub fn nested(a: &ndarray::Array2<f64>) -> Vec<Vec<f64>> {
    a.outer_iter().map(|r| r.to_vec()).collect()
}
