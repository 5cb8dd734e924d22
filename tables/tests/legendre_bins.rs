//! Exact bin integrals and the bins ↔ χ_l transforms, tested through invariants and analytic
//! phase functions (isotropic, Rayleigh, Henyey–Greenstein). Measured errors are printed
//! (`--nocapture`) and the tolerances sit just above them.

mod common;

use common::{Lcg, henyey_greenstein_bins, max_abs, max_abs_diff, rayleigh_bins};
use std::f64::consts::PI;
use tables::legendre::reference::{bin_integrals_by_quadrature, gauss_legendre};
use tables::legendre::{
    BinIntegrals, ThetaGrid, bin_averages_from_coefficients, coefficients_from_bin_rows,
    coefficients_from_bins,
};

fn grid_018() -> ThetaGrid {
    ThetaGrid::new(0.18).unwrap()
}

#[test]
fn bin_integrals_match_per_bin_gauss_quadrature() {
    // Oracle: Gauss–Legendre on each bin, exact for P_l with 2·nodes − 1 ≥ l.
    // Error measured relative to Δμ_k (|W_lk| ≤ Δμ_k; W_lk itself crosses zero).
    let grid = grid_018();
    let theta = grid.edge_theta_rad();
    let d_mu = grid.bin_mu_widths();
    let check = |l_max: usize, bins: &[usize]| {
        let (x, w) = gauss_legendre(l_max / 2 + 2);
        let mut stream = BinIntegrals::new(&grid);
        // Backward bins by symmetry from their forward mirror (exact edges): W_lk = (−1)^l W_lk'.
        let n_bins = grid.len();
        let oracle: Vec<Vec<f64>> = bins
            .iter()
            .map(|&k| {
                let (k_fwd, flip) = if 2 * k + 1 > n_bins {
                    (n_bins - 1 - k, true)
                } else {
                    (k, false)
                };
                let mut o =
                    bin_integrals_by_quadrature(theta[k_fwd], theta[k_fwd + 1], l_max, &x, &w);
                if flip {
                    o.iter_mut().skip(1).step_by(2).for_each(|v| *v = -*v);
                }
                o
            })
            .collect();
        let mut worst = 0.0f64;
        for l in 0..=l_max {
            if l > 0 {
                stream.advance();
            }
            for (i, &k) in bins.iter().enumerate() {
                let err = (stream.values()[k] - oracle[i][l]).abs() / d_mu[k];
                worst = worst.max(err);
            }
        }
        worst
    };
    // Every bin, l ≤ 200.
    let all: Vec<usize> = (0..grid.len()).collect();
    let worst_low = check(200, &all);
    // Poles and a sample of interior bins, l ≤ 3000 (l Δθ up to 9.4: many oscillations a bin).
    let some = [0, 1, 2, 3, 50, 250, 499, 500, 501, 777, 997, 998, 999, 1000];
    let worst_high = check(3000, &some);
    println!(
        "bin integrals vs per-bin Gauss: l ≤ 200 all bins {worst_low:.2e}, l ≤ 3000 {worst_high:.2e} (of Δμ_k)"
    );
    // Measured 8.0e-14 and 7.8e-14 (interior bins at low l: neighbouring G_l differ by ~Δμ_k
    // while G_l ~ sin²θ; the difference costs log10(sin θ/Δθ) ≲ 2.5 digits).
    assert!(worst_low < 1e-13, "{worst_low:e}");
    assert!(worst_high < 1e-13, "{worst_high:e}");
}

#[test]
fn stable_antiderivative_beats_the_textbook_difference_at_the_poles() {
    // W_l0 = ∫_{μ_1}^{1} P_l = (P_{l−1}(μ_1) − P_{l+1}(μ_1))/(2l + 1) is the textbook form; at
    // 1 − μ_1 = 1.2e-6 it cancels. The stable form sin²θ P'_l/(l(l + 1)) does not.
    let grid = grid_018();
    let (mu, _) = grid.edge_mu_sin2();
    let theta = grid.edge_theta_rad();
    let (x, w) = gauss_legendre(12);
    let oracle = bin_integrals_by_quadrature(theta[0], theta[1], 20, &x, &w);
    let p = tables::legendre::reference::legendre_p_all(21, mu[1]);
    let mut stream = BinIntegrals::new(&grid);
    let (mut worst_stable, mut worst_textbook) = (0.0f64, 0.0f64);
    for l in 1..=20 {
        stream.advance();
        let textbook = (p[l - 1] - p[l + 1]) / (2 * l + 1) as f64;
        worst_stable = worst_stable.max((stream.values()[0] / oracle[l] - 1.0).abs());
        worst_textbook = worst_textbook.max((textbook / oracle[l] - 1.0).abs());
    }
    println!(
        "forward bin, l ≤ 20: stable {worst_stable:.1e}, textbook {worst_textbook:.1e} relative"
    );
    // Measured 2.2e-16 and 7.7e-11.
    assert!(worst_stable < 1e-15, "{worst_stable:e}");
    assert!(worst_textbook > 1e3 * worst_stable);
}

#[test]
fn bin_integrals_sum_to_the_full_integral() {
    // Σ_k ∫_bin P_l = ∫_{-1}^{1} P_l = 2 δ_l0, for l ≤ 20 000 on the 0.18° grid.
    let grid = grid_018();
    let mut stream = BinIntegrals::new(&grid);
    let mut worst = 0.0f64;
    for l in 0..=20_000 {
        if l > 0 {
            stream.advance();
        }
        let total: f64 = stream.values().iter().sum();
        let want = if l == 0 { 2.0 } else { 0.0 };
        worst = worst.max((total - want).abs());
    }
    println!("|Σ_k W_lk − 2δ_l0| ≤ {worst:.2e} for l ≤ 20000");
    // Measured 6.7e-16.
    assert!(worst < 1e-15, "{worst:e}");
}

#[test]
fn normalized_bins_give_chi_0_equal_one() {
    let grid = grid_018();
    let omega = grid.bin_solid_angles();
    let mut rng = Lcg::new(7);
    let mut bins: Vec<f64> = (0..grid.len()).map(|_| rng.uniform()).collect();
    let energy: f64 = bins.iter().zip(&omega).map(|(v, o)| v * o).sum();
    bins.iter_mut().for_each(|v| *v /= energy);
    let chi = coefficients_from_bins(&bins, &grid, 10).unwrap();
    println!(
        "random normalized bins: |χ_0 − 1| = {:.1e}",
        (chi[0] - 1.0).abs()
    );
    // Measured 1.6e-15: Σ v_k Ω_k and 2π Σ v_k Δμ_k round differently over 1001 terms.
    assert!((chi[0] - 1.0).abs() < 3e-15, "{}", chi[0]);
}

#[test]
fn isotropic_has_only_chi_0() {
    let grid = grid_018();
    let bins = vec![1.0 / (4.0 * PI); grid.len()];
    let chi = coefficients_from_bins(&bins, &grid, 20_000).unwrap();
    let worst = max_abs(&chi[1..]);
    println!(
        "isotropic: |χ_0 − 1| = {:.1e}, max_l≥1 |χ_l| = {worst:.1e}",
        (chi[0] - 1.0).abs()
    );
    // Measured 4.4e-16 and 1.6e-17.
    assert!((chi[0] - 1.0).abs() < 5e-16);
    assert!(worst < 5e-16, "{worst:e}");
}

#[test]
fn rayleigh_has_chi_2_one_tenth() {
    // p = 3/(16π)(1 + μ²) = (1/4π)(P_0 + (5/10) P_2): χ_0 = 1, χ_2 = 1/10, all else 0. The bins
    // hold the exact bin averages; the piecewise-constant function they define differs from p by
    // O(Δθ²) within bins, which is what χ_2 − 1/10 and χ_{l≥3} measure.
    let grid = grid_018();
    let bins = rayleigh_bins(&grid);
    let chi = coefficients_from_bins(&bins, &grid, 1000).unwrap();
    let odd = (1..=1000)
        .step_by(2)
        .map(|l| chi[l].abs())
        .fold(0.0, f64::max);
    let even_high = (4..=1000)
        .step_by(2)
        .map(|l| chi[l].abs())
        .fold(0.0, f64::max);
    println!(
        "Rayleigh 0.18°: χ_0 − 1 = {:.1e}, max odd |χ_l| = {odd:.1e}, χ_2 − 0.1 = {:.2e}, max_{{l≥4}} |χ_l| = {even_high:.1e}",
        chi[0] - 1.0,
        chi[2] - 0.1
    );
    // Measured: −1.1e-16, 5.8e-18 (odd χ_l vanish by the grid's exact symmetry), −4.93e-7
    // (second order in Δθ, see the ratio below), 6.1e-13.
    assert!((chi[0] - 1.0).abs() < 5e-16);
    assert!(odd < 1e-16, "{odd:e}");
    assert!((chi[2] - 0.1).abs() < 5e-7, "{}", chi[2]);
    assert!(even_high < 1e-12, "{even_high:e}");
    // Halving Δθ quarters the bin-averaging error: second order.
    let fine = ThetaGrid::new(0.09).unwrap();
    let chi_fine = coefficients_from_bins(&rayleigh_bins(&fine), &fine, 2).unwrap();
    let ratio = (chi[2] - 0.1) / (chi_fine[2] - 0.1);
    println!("Rayleigh χ_2 error ratio 0.18° / 0.09° = {ratio:.4}");
    assert!((ratio - 4.0).abs() < 0.01, "{ratio}");
}

#[test]
fn henyey_greenstein_bins_give_g_to_the_l() {
    // Bin-averaged HG, g = 0.85, 0.18° grid: χ_l ≈ g^l while l Δθ ≪ 1. Replacing p by its bin
    // averages changes χ_l at second order in Δθ; beyond l ~ 1/Δθ the steps' own spectrum
    // (peaks at l ≈ 2πm/Δθ = 2000m) dominates.
    let g: f64 = 0.85;
    let grid = grid_018();
    let bins = henyey_greenstein_bins(&grid, g);
    let chi = coefficients_from_bins(&bins, &grid, 20_000).unwrap();
    let err = |l: usize| (chi[l] - g.powi(l as i32)).abs();
    let worst_to = |l_top: usize| (0..=l_top).map(err).fold(0.0, f64::max);
    let first_rel_above = |eps: f64| {
        (1..=20_000)
            .find(|&l| err(l) > eps * g.powi(l as i32))
            .unwrap_or(usize::MAX)
    };
    let (l_1e3, l_1e2) = (first_rel_above(1e-3), first_rel_above(1e-2));
    println!(
        "HG g = 0.85 at 0.18°: |χ_0 − 1| = {:.1e}, |χ_1 − g| = {:.2e}, max|χ_l − g^l| l ≤ 100: {:.2e}, l ≤ 20000: {:.2e}; |χ_l/g^l − 1| first > 1e-3 at l = {l_1e3}, > 1e-2 at l = {l_1e2}",
        err(0),
        err(1),
        worst_to(100),
        worst_to(20_000),
    );
    // Measured: 1.1e-15, 1.40e-6, 1.82e-5, 1.19e-4 (at the l ≈ 2000 peak of the steps), l = 35, 99.
    assert!(err(0) < 2e-15);
    assert!(err(1) < 1.5e-6, "{:e}", err(1));
    assert!(worst_to(100) < 1.9e-5);
    assert!(worst_to(20_000) < 1.3e-4);
    assert!(l_1e3 >= 35 && l_1e2 >= 99, "{l_1e3} {l_1e2}");
    // Second order: halving Δθ quarters χ_1 − g.
    let fine = ThetaGrid::new(0.09).unwrap();
    let chi_fine = coefficients_from_bins(&henyey_greenstein_bins(&fine, g), &fine, 1).unwrap();
    let ratio = err(1) / (chi_fine[1] - g).abs();
    println!("HG χ_1 − g ratio 0.18° / 0.09° = {ratio:.4}");
    assert!((ratio - 4.0).abs() < 0.01, "{ratio}");
}

#[test]
fn bins_to_chi_to_bins_round_trip() {
    // Truncating at l_max projects the piecewise-constant function onto degree ≤ l_max; its
    // Gibbs tails around each bin edge leave O(jump / (l_max Δθ)) in the bin averages, so the
    // round trip converges like 1/l_max — provided l_max avoids the spectral peaks of the steps
    // at l ≈ 2πm/Δθ (2000m at 0.18°): a peak cut in half leaves its oscillation in the bins,
    // worst in the half-width end bin at 180°. Best: l_max Δθ an odd multiple of π.
    let g = 0.85;
    let grid = grid_018();
    let bins = henyey_greenstein_bins(&grid, g);
    let chi_all = coefficients_from_bins(&bins, &grid, 21_000).unwrap();
    let rel = |l_max: usize| {
        let back = bin_averages_from_coefficients(&chi_all, &grid, l_max).unwrap();
        bins.iter()
            .zip(&back)
            .map(|(v, b)| ((b - v) / v).abs())
            .fold(0.0, f64::max)
    };
    let (e5, e11, e21, e_peak) = (rel(5_000), rel(11_000), rel(21_000), rel(4_000));
    println!(
        "HG round trip max rel error: l_max 5000 {e5:.2e}, 11000 {e11:.2e}, 21000 {e21:.2e}; at the l = 4000 peak {e_peak:.2e}"
    );
    // Measured: 5.01e-5, 2.31e-5, 1.21e-5 (∝ 1/l_max); 0.158 at a peak.
    assert!(e21 < 1.3e-5, "{e21:e}");
    assert!((e5 / e21 - 21.0 / 5.0).abs() < 0.2, "{e5:e} {e21:e}");
    assert!(e_peak > 0.1, "{e_peak:e}");
    // Random bins (jumps as large as the values) round-trip to O(1/(l_max Δθ)).
    let mut rng = Lcg::new(11);
    let random: Vec<f64> = (0..grid.len()).map(|_| 0.5 + rng.uniform()).collect();
    let chi = coefficients_from_bins(&random, &grid, 21_000).unwrap();
    let back = bin_averages_from_coefficients(&chi, &grid, 21_000).unwrap();
    let worst = max_abs_diff(&random, &back) / max_abs(&random);
    println!("random bins round trip at l_max = 21000: {worst:.2e} of max");
    // Measured 5.78e-3.
    assert!(worst < 6e-3, "{worst:e}");
}

#[test]
fn funk_hecke_convolutions() {
    let grid = grid_018();
    let l_max = 4000;
    // Isotropic ∗ anything (normalized) = isotropic: χ_l = δ_l0 · χ_l^other.
    let hg = henyey_greenstein_bins(&grid, 0.85);
    let chi_hg = coefficients_from_bins(&hg, &grid, l_max).unwrap();
    let chi_iso: Vec<f64> = (0..=l_max)
        .map(|l| if l == 0 { 1.0 } else { 0.0 })
        .collect();
    let chi_conv: Vec<f64> = chi_iso.iter().zip(&chi_hg).map(|(a, b)| a * b).collect();
    let bins = bin_averages_from_coefficients(&chi_conv, &grid, l_max).unwrap();
    let worst = bins
        .iter()
        .map(|v| (4.0 * PI * v - 1.0).abs())
        .fold(0.0, f64::max);
    println!("isotropic ∗ HG: max |4π v_k − 1| = {worst:.1e}");
    // Measured 1.3e-15.
    assert!(worst < 2e-15, "{worst:e}");
    // HG(g1) ∗ HG(g2) = HG(g1 g2) since χ_l = g^l: a real convolution, through bins both ways.
    let rows = [
        henyey_greenstein_bins(&grid, 0.5),
        henyey_greenstein_bins(&grid, 0.6),
    ];
    let chi = coefficients_from_bin_rows(&[&rows[0], &rows[1]], &grid, l_max).unwrap();
    let chi_prod: Vec<f64> = chi[0].iter().zip(&chi[1]).map(|(a, b)| a * b).collect();
    let conv = bin_averages_from_coefficients(&chi_prod, &grid, l_max).unwrap();
    let want = henyey_greenstein_bins(&grid, 0.3);
    let worst = conv
        .iter()
        .zip(&want)
        .map(|(c, w)| ((c - w) / w).abs())
        .fold(0.0, f64::max);
    println!("HG(0.5) ∗ HG(0.6) vs HG(0.3): max rel {worst:.1e}");
    // Measured 6.0e-6 (bin averaging of the two inputs, second order in Δθ).
    assert!(worst < 6.5e-6, "{worst:e}");
}
