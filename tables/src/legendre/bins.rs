//! The bins ↔ χ_l transforms, built on the exact bin integrals of P_l ([`BinIntegrals`], in
//! `photometeor-grid`, which the renderers' moments use too).
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
//! [`ThetaGrid::bin_mu_widths`]. P_l and P'_l advance one degree at a time across the edges
//! ([`BinIntegrals`]), so the memory is O(K) whatever l_max is; cost O(K · l_max). Only the
//! forward-half edges (θ ≤ π/2) run the recurrence; the mirror edge takes
//! G_l(−μ) = (−1)^{l+1} G_l(μ), so the table is exactly (anti)symmetric.
//!
//! # Numerical hazards
//! - The recurrence runs on v = 1 − μ = 2 sin²(θ/2), never on a rounded μ, in Reinsch's
//!   difference form (see [`super::reference::legendre_p_all_versine`]). The plain form loses
//!   ~l^{3/2} ulp near the poles and its rounded edge cosine shifts P_l by P'_l·1e-16; measured
//!   against the per-bin oracle the plain form was off by 6.6e-13 of Δμ_k at l ≤ 200 (bin 3),
//!   this form by 8e-14 (all of it from the interior-bin difference below).
//! - No cancellation near the poles (see the module doc of [`crate::legendre`]); G_l is exactly 0
//!   at μ = ±1, so Σ_k W_lk telescopes to 2δ_l0 up to the rounding of K terms.
//! - Interior bins at low l subtract neighbouring G_l values of size ~sin θ·Δθ… sin²θ, losing up
//!   to log10(1/Δθ) ≈ 2.5 digits relative to W_lk at Δθ = 0.18° (measured ≤ 1e-13 of Δμ_k, see
//!   the tests). The absolute error stays ~1e-16, which is what χ_l and the bin averages see.
//! - For l Δθ ≫ 1, P_l oscillates many times within one bin and W_lk is small (~Δμ_k/(lΔθ)); it
//!   is still computed to absolute rounding, with no special case.

use super::LegendreError;
use grid::ThetaGrid;
pub use grid::legendre::{BinIntegrals, bin_integrals};

/// χ_l, l = 0..=l_max, of the function that equals `bins[k]` on bin k (piecewise constant in
/// μ): χ_l = 2π Σ_k bins[k] W_lk, exact up to rounding. χ_0 = Σ_k bins[k] Ω_k is 1 for a
/// normalized bin vector; it is returned as computed, not forced to 1.
pub fn coefficients_from_bins(
    bins: &[f64],
    grid: &ThetaGrid,
    l_max: usize,
) -> Result<Vec<f64>, LegendreError> {
    let mut rows = coefficients_from_bin_rows(&[bins], grid, l_max)?;
    Ok(rows.pop().expect("one row in, one row out"))
}

/// [`coefficients_from_bins`] for several bin vectors (e.g. wavelengths) sharing one pass of
/// the recurrence: returns `chi[row][l]`.
pub fn coefficients_from_bin_rows(
    rows: &[&[f64]],
    grid: &ThetaGrid,
    l_max: usize,
) -> Result<Vec<Vec<f64>>, LegendreError> {
    for (row, bins) in rows.iter().enumerate() {
        if bins.len() != grid.len() {
            return Err(LegendreError::BinCount {
                row,
                got: bins.len(),
                expected: grid.len(),
            });
        }
    }
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut chi = vec![vec![0.0; l_max + 1]; rows.len()];
    let mut w = BinIntegrals::new(grid);
    for l in 0..=l_max {
        if l > 0 {
            w.advance();
        }
        let w_l = w.values();
        for (chi_row, bins) in chi.iter_mut().zip(rows) {
            // χ_l = 2π Σ_k v_k ∫_bin P_l dμ.
            chi_row[l] = two_pi * dot(bins, w_l);
        }
    }
    Ok(chi)
}

/// Bin averages over the solid angle of each bin of f(μ) = Σ_{l ≤ l_max} (2l + 1)/(4π) χ_l P_l(μ),
/// using the exact bin integrals:
///
///   v_k = (1/Ω_k) 2π ∫_bin f dμ = Σ_l (2l + 1) χ_l W_lk / (4π Δμ_k).
///
/// `chi` must hold at least l_max + 1 values; those above l_max are ignored.
pub fn bin_averages_from_coefficients(
    chi: &[f64],
    grid: &ThetaGrid,
    l_max: usize,
) -> Result<Vec<f64>, LegendreError> {
    if chi.len() < l_max + 1 {
        return Err(LegendreError::CoefficientCount {
            got: chi.len(),
            expected: l_max + 1,
        });
    }
    let mut acc = vec![0.0; grid.len()];
    let mut w = BinIntegrals::new(grid);
    let d_mu = w.values().to_vec();
    for l in 0..=l_max {
        if l > 0 {
            w.advance();
        }
        let weight = (2 * l + 1) as f64 * chi[l];
        if weight == 0.0 {
            continue;
        }
        for (a, w_lk) in acc.iter_mut().zip(w.values()) {
            *a += weight * w_lk;
        }
    }
    let inv_4pi = 1.0 / (4.0 * std::f64::consts::PI);
    Ok(acc
        .iter()
        .zip(&d_mu)
        .map(|(a, d)| a * inv_4pi / d)
        .collect())
}

/// Σ x_k y_k with four interleaved partial sums (vectorizes; pairwise-like rounding).
fn dot(x: &[f64], y: &[f64]) -> f64 {
    let mut s = [0.0f64; 4];
    let chunks = x.len() / 4;
    for c in 0..chunks {
        for i in 0..4 {
            s[i] += x[4 * c + i] * y[4 * c + i];
        }
    }
    let mut tail = 0.0;
    for i in 4 * chunks..x.len() {
        tail += x[i] * y[i];
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stream_and_table_agree() {
        let grid = ThetaGrid::new(3.0).unwrap();
        let table = bin_integrals(&grid, 50);
        let mut w = BinIntegrals::new(&grid);
        for (l, row) in table.iter().enumerate() {
            assert_eq!(w.degree(), l);
            assert_eq!(w.values(), row.as_slice());
            w.advance();
        }
    }

    #[test]
    fn shape_errors_name_the_bad_value() {
        let grid = ThetaGrid::new(1.0).unwrap();
        let err = coefficients_from_bins(&[1.0; 10], &grid, 4).unwrap_err();
        assert_eq!(
            err,
            LegendreError::BinCount {
                row: 0,
                got: 10,
                expected: 181
            }
        );
        let err = bin_averages_from_coefficients(&[1.0; 3], &grid, 4).unwrap_err();
        assert!(err.to_string().contains("l_max + 1 = 5"), "{err}");
    }
}
