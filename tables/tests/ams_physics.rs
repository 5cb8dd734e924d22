//! Ams_n of real drop populations (phase functions from the Mie crate): every row conserves
//! energy and does not ring, Ams_1 is the single-scattering phase function, and the rainbow,
//! glory and corona are present in Ams_1 and fade with n while F_n falls toward 1/2.

use mie::{BulkRequest, Material, NodeCounts, SizeDistribution, bulk_phase};
use tables::ams::{AmsSeries, AmsSettings, AmsTable, ams_table};
use tables::legendre::ThetaGrid;

mod common;

use common::nested;

fn phase_bins(distribution: SizeDistribution, sizes: usize) -> Vec<f64> {
    let request = BulkRequest {
        material: Material::Water,
        temperature_c: 20.0,
        distribution,
        wavelengths_nm: vec![550.0],
        grid: ThetaGrid::new(0.18).unwrap(),
        nodes: NodeCounts::Fixed {
            sizes,
            nodes_per_panel: 4,
        },
        tail_mass: 1e-3,
        point_cosines: Vec::new(),
    };
    bulk_phase(&request).unwrap().remove(0).bins
}

fn index(theta_deg: f64) -> usize {
    (theta_deg / 0.18).round() as usize
}

fn max_in(row: &[f64], a: f64, b: f64) -> f64 {
    row[index(a)..=index(b)]
        .iter()
        .cloned()
        .fold(f64::MIN, f64::max)
}

fn min_in(row: &[f64], a: f64, b: f64) -> f64 {
    row[index(a)..=index(b)]
        .iter()
        .cloned()
        .fold(f64::MAX, f64::min)
}

/// A contrast ratio fades: it falls strictly while the feature stands out by more than 1 %, and
/// once within 1 % of flat (ratio 1, where the residual slope of a nearly isotropic row
/// decides the sign) it stays there.
fn assert_fades(what: &str, c: &[f64]) {
    let mut flat = false;
    for n in 1..c.len() {
        if flat {
            assert!(
                (c[n] - 1.0).abs() < 0.01,
                "{what} reappears at n = {}: {}",
                n + 1,
                c[n]
            );
        } else {
            assert!(
                c[n] < c[n - 1],
                "{what} rises at n = {}: {:?}",
                n + 1,
                &c[..=n]
            );
        }
        flat |= (c[n] - 1.0).abs() < 0.01;
    }
    assert!(flat, "{what} never fades: {c:?}");
}

fn check_invariants(name: &str, grid: &ThetaGrid, bins: &[f64], t: &AmsTable) {
    let omega = grid.bin_solid_angles();
    let energy_in: f64 = bins.iter().zip(&omega).map(|(v, o)| v * o).sum();
    for (i, row) in nested(&t.rows).iter().enumerate() {
        let e: f64 = row.iter().zip(&omega).map(|(v, o)| v * o).sum();
        assert!((e - 1.0).abs() < 1e-6, "{name} n = {}: energy {e}", i + 1);
        let max = row.iter().cloned().fold(0.0, f64::max);
        let min = row.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(
            min >= -1e-6 * max,
            "{name} n = {}: min {min:e}, max {max:e}",
            i + 1
        );
    }
    // Ams_1 is the (renormalized) single-scattering bin average, for θ ≥ 1°.
    for k in index(1.0)..bins.len() {
        let expected = bins[k] / energy_in;
        assert!(
            (nested(&t.rows)[0][k] - expected).abs() <= 1e-3 * expected,
            "{name} bin {k}: {} vs {expected}",
            nested(&t.rows)[0][k]
        );
    }
    for w in t.forward_fraction.windows(2) {
        assert!(
            w[1] < w[0] && w[1] > 0.5,
            "{name}: F not falling toward 1/2: {w:?}"
        );
    }
}

#[test]
fn rain_rainbow_fades_with_scattering_order() {
    let grid = ThetaGrid::new(0.18).unwrap();
    let bins = phase_bins(
        SizeDistribution::Lognormal {
            median_radius_um: 500.0,
            sigma_g: 1.4,
        },
        400,
    );
    let t = ams_table(&grid, &bins, AmsSettings::default());
    check_invariants("rain", &grid, &bins, &t);
    eprintln!(
        "rain: forward peak fraction {:.4}, F_1 {:.4}, F_26 {:.4}, l_max {}",
        t.forward_peak_fraction, t.forward_fraction[0], t.forward_fraction[25], t.l_max
    );
    // Primary bow (Descartes 138.17° at 550 nm) over Alexander's dark band.
    let contrast = |row: &[f64]| max_in(row, 137.0, 141.0) / min_in(row, 130.5, 136.0);
    let c: Vec<f64> = nested(&t.rows).iter().map(|r| contrast(r)).collect();
    eprintln!(
        "rainbow contrast n = 1, 2, 4, 26: {:.3} {:.3} {:.3} {:.3}",
        c[0], c[1], c[3], c[25]
    );
    assert!(c[0] > 1.5, "no primary rainbow in Ams_1: contrast {}", c[0]);
    assert_fades("rainbow contrast", &c);

    // Riley et al. claim rain is isotropic within 1e-6 by n = 26; report what the table says.
    let series = AmsSeries::new(&grid, &bins, AmsSettings::default().reconstruction);
    let n_iso: Vec<Option<usize>> = [1e-2, 1e-4, 1e-6]
        .iter()
        .map(|&eps| series.isotropic_order(eps, 100_000))
        .collect();
    eprintln!(
        "rain n_iso(1e-2, 1e-4, 1e-6) = {n_iso:?}; max|4πAms_26 − 1| = {:.3e}",
        series.anisotropy(26)
    );
    let n_iso: Vec<usize> = n_iso
        .into_iter()
        .map(|n| n.expect("isotropic by n = 1e5"))
        .collect();
    assert!(n_iso[0] < n_iso[1] && n_iso[1] < n_iso[2]);
    // The bisection's premise: the deviation only falls around the answer.
    for (eps, &n) in [1e-2, 1e-4, 1e-6].iter().zip(&n_iso) {
        assert!(series.anisotropy(n) < *eps && series.anisotropy(n - 1) >= *eps);
    }
}

#[test]
fn cloud_glory_and_corona_fade_with_scattering_order() {
    let grid = ThetaGrid::new(0.18).unwrap();
    let bins = phase_bins(
        SizeDistribution::Gamma {
            r_eff_um: 10.0,
            v_eff: 0.02,
        },
        512,
    );
    let t = ams_table(&grid, &bins, AmsSettings::default());
    check_invariants("cloud", &grid, &bins, &t);
    // Glory: back-scatter enhancement over the minimum at 165–176°.
    let glory = |row: &[f64]| row[row.len() - 1] / min_in(row, 165.0, 176.0);
    // Corona: Ams_1's first dark ring (x sin θ = 3.83 → ≈ 1.9° for r = 10 µm at 550 nm) and the
    // bright ring after it (x sin θ = 5.14 → ≈ 2.6°), located in Ams_1; contrast = bright/dark
    // at those two angles in every row.
    let first = &nested(&t.rows)[0];
    let dark = (index(1.0)..index(4.0))
        .find(|&k| first[k] < first[k - 1] && first[k] < first[k + 1])
        .expect("a first dark corona ring in Ams_1");
    let bright = (dark..index(5.0))
        .find(|&k| first[k] > first[k - 1] && first[k] > first[k + 1])
        .expect("a bright corona ring in Ams_1");
    eprintln!(
        "corona rings in Ams_1: dark {:.2}°, bright {:.2}°",
        dark as f64 * 0.18,
        bright as f64 * 0.18
    );
    // Ring depth: bright/dark − 1 where the row still has a local minimum and maximum within
    // ±2 bins of those angles, else 0 (the ring is gone).
    let corona = |row: &[f64]| {
        let local_min = (dark - 2..=dark + 2).find(|&k| row[k] < row[k - 1] && row[k] < row[k + 1]);
        let local_max =
            (bright - 2..=bright + 2).find(|&k| row[k] > row[k - 1] && row[k] > row[k + 1]);
        match (local_min, local_max) {
            (Some(a), Some(b)) if b > a => row[b] / row[a] - 1.0,
            _ => 0.0,
        }
    };
    let g: Vec<f64> = nested(&t.rows).iter().map(|r| glory(r)).collect();
    let c: Vec<f64> = nested(&t.rows).iter().map(|r| corona(r)).collect();
    eprintln!("glory n = 1, 2, 26: {:.3} {:.3} {:.3}", g[0], g[1], g[25]);
    eprintln!("corona n = 1, 2, 26: {:.3} {:.3} {:.3}", c[0], c[1], c[25]);
    assert!(g[0] > 1.5, "no glory in Ams_1: {}", g[0]);
    assert!(c[0] > 0.05, "no corona ring in Ams_1: depth {}", c[0]);
    assert_fades("glory contrast", &g);
    for n in 1..nested(&t.rows).len() {
        assert!(c[n] <= c[n - 1], "corona depth rises at n = {}", n + 1);
    }
}
