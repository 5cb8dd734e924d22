//! Published values: Wiscombe's MIEV0 test cases, Bohren & Huffman's example, the Rayleigh
//! limit, the large-sphere limit and the optical theorem.

use mie::reference::amplitudes_direct;
use mie::{FoldedAngles, Sphere, amplitudes};
use num_complex::Complex64;

const WISCOMBE: &str = include_str!("../../data/reference/wiscombe_miev0.csv");
const MPMATH: &str = include_str!("../../data/reference/mpmath_small_spheres.csv");

/// Rows of a reference CSV (comment lines and the header skipped).
fn rows(csv: &str) -> impl Iterator<Item = Vec<f64>> + '_ {
    csv.lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').map(|f| f.trim().parse().unwrap()).collect())
}

/// The 50-digit value for (x, m), when the mpmath reference has it: [qext, qsca, g, qback].
fn exact(x: f64, m: Complex64) -> Option<Vec<f64>> {
    rows(MPMATH)
        .find(|v| v[0] == x && v[1] == m.re && v[2] == m.im)
        .map(|v| v[3..].to_vec())
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn wiscombe_miev0_cases() {
    let mut checked = 0;
    for v in rows(WISCOMBE) {
        let (case, x, m) = (v[0], v[1], Complex64::new(v[2], v[3]));
        let e = Sphere::new(m, x).unwrap().coefficients().efficiencies();
        let truth = exact(x, m);
        for (q, (name, ours, published)) in [
            ("Q_ext", e.q_ext, v[4]),
            ("Q_sca", e.q_sca, v[5]),
            ("g·Q_sca", e.g * e.q_sca, v[6]),
        ]
        .into_iter()
        .enumerate()
        {
            // The published values carry 7 significant digits (tolerance 6e-7). For the small
            // spheres (cases 5, 6, 12, 13) the 50-digit computation shows the printed figure
            // itself off by up to 1.5e-6 (Wiscombe's small-particle expansion at x|m| ≈ 0.1);
            // there the tolerance widens by exactly that measured error.
            let own_error = truth.as_ref().map_or(0.0, |t| {
                let exact = if q == 2 { t[2] * t[1] } else { t[q] };
                rel(published, exact)
            });
            assert!(
                rel(ours, published) < 6e-7 + own_error,
                "case {case} (x = {x}, m = {m}): {name} = {ours:e}, published {published:e}"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 15);
}

#[test]
fn small_spheres_match_50_digit_values() {
    // Worst disagreements measured: Q_ext, Q_sca 1e-9, g 1.2e-7 (m = 10+10i, x = 0.03),
    // Q_back 1.8e-6 (m = 1.0001, x = 0.1, small-particle path).
    let mut checked = 0;
    for v in rows(MPMATH) {
        let (x, m) = (v[0], Complex64::new(v[1], v[2]));
        let e = Sphere::new(m, x).unwrap().coefficients().efficiencies();
        for (name, ours, truth, tol) in [
            ("Q_ext", e.q_ext, v[3], 2e-9),
            ("Q_sca", e.q_sca, v[4], 2e-9),
            ("g", e.g, v[5], 2e-7),
            ("Q_back", e.q_back, v[6], 2.5e-6),
        ] {
            assert!(
                rel(ours, truth) < tol,
                "x = {x}, m = {m}: {name} = {ours:e}, 50-digit {truth:e}"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 60);
}

#[test]
fn bohren_huffman_example_sphere() {
    // B&H appendix A: m = 1.55, r = 0.525 µm, λ = 0.6328 µm → x = 5.213.
    let x = 2.0 * std::f64::consts::PI * 0.525 / 0.6328;
    let e = Sphere::new(Complex64::new(1.55, 0.0), x)
        .unwrap()
        .coefficients()
        .efficiencies();
    // B&H print Q_sca = 3.10543 and Q_back = 2.92534 (BHMIE output, p. 482).
    assert!(rel(e.q_sca, 3.10543) < 2e-6, "Q_sca = {}", e.q_sca);
    assert!(rel(e.q_ext, 3.10543) < 2e-6, "Q_ext = {}", e.q_ext);
    assert!(rel(e.q_back, 2.92534) < 2e-6, "Q_back = {}", e.q_back);
}

#[test]
fn rayleigh_limit() {
    for &(re, im) in &[(1.33, 0.0), (1.5, 0.1), (3.0, 2.0)] {
        let m = Complex64::new(re, im);
        let x = 1e-4;
        let c = Sphere::new(m, x).unwrap().coefficients();
        let e = c.efficiencies();
        let alpha = (m * m - 1.0) / (m * m + 2.0);
        // Q_sca → (8/3) x⁴ |α|², Q_abs → 4 x Im α (B&H Eqs. 5.8, 5.11)
        let q_sca = 8.0 / 3.0 * x.powi(4) * alpha.norm_sqr();
        assert!(
            rel(e.q_sca, q_sca) < 1e-6,
            "m = {m}: {} vs {q_sca}",
            e.q_sca
        );
        if im > 0.0 {
            assert!(rel(e.q_abs, 4.0 * x * alpha.im) < 1e-6);
        }
        // p → 3/(16π)(1 + μ²)
        let mu = [1.0, 0.5, 0.0, -0.3, -1.0];
        let (s1, s2) = amplitudes(&c, &FoldedAngles::new(&mu));
        for (k, &m) in mu.iter().enumerate() {
            let p = mie::phase_from_amplitudes(s1[k], s2[k], x, e.q_sca);
            let expected = 3.0 / (16.0 * std::f64::consts::PI) * (1.0 + m * m);
            assert!(rel(p, expected) < 1e-6, "μ = {m}: {p} vs {expected}");
        }
    }
}

#[test]
fn large_spheres_extinguish_twice_their_area() {
    for &x in &[1e4, 1e5, 2e5] {
        let e = Sphere::new(Complex64::new(1.333, 1e-8), x)
            .unwrap()
            .coefficients()
            .efficiencies();
        // Q_ext = 2 + O(x^{-2/3}) (van de Hulst).
        assert!(
            (e.q_ext - 2.0).abs() < 4.0 * x.powf(-2.0 / 3.0),
            "x = {x}: {}",
            e.q_ext
        );
    }
}

#[test]
fn optical_theorem_and_fast_kernel_matches_direct_sum() {
    for &(re, im, x) in &[
        (1.333, 1e-8, 0.3),
        (1.333, 1e-8, 37.0),
        (1.5, 1.0, 250.0),
        (0.75, 0.0, 1000.0),
        (1.333, 1e-8, 4000.0),
        (2.5, 0.5, 60.0),
    ] {
        let c = Sphere::new(Complex64::new(re, im), x)
            .unwrap()
            .coefficients();
        let e = c.efficiencies();
        let theta: Vec<f64> = (0..=180)
            .map(|d| d as f64 * 1.0)
            .chain([0.18, 179.82])
            .collect();
        let mu: Vec<f64> = theta.iter().map(|t| t.to_radians().cos()).collect();
        let (s1, s2) = amplitudes(&c, &FoldedAngles::new(&mu));
        // Re S(0) = x² Q_ext / 4
        assert!(rel(s1[0].re, x * x * e.q_ext / 4.0) < 1e-10, "x = {x}");
        assert!((s1[0] - s2[0]).norm() < 1e-9 * s1[0].norm());
        for (k, &m) in mu.iter().enumerate() {
            let (d1, d2) = amplitudes_direct(&c, m);
            let scale = s1[0].norm();
            assert!(
                (s1[k] - d1).norm() < 1e-12 * scale + 1e-9 * d1.norm(),
                "x = {x}, θ = {}: {} vs {}",
                theta[k],
                s1[k],
                d1
            );
            assert!((s2[k] - d2).norm() < 1e-12 * scale + 1e-9 * d2.norm());
        }
        // Q_back = 4 |S1(180°)|² / x²
        assert!(
            rel(4.0 * s1[180].norm_sqr() / (x * x), e.q_back) < 1e-8,
            "x = {x}"
        );
    }
}
