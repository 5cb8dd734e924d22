//! Ams_n against the exact n-fold convolution of a cloud's phase function
//! (data/reference/ams_exact_cloud.csv, made by data/reference/generate_ams_exact.py from
//! miepython: the Legendre coefficients of the continuous P by quadrature, so Ams_n = Σ_l
//! (2l+1)/(4π) χ_l^n P_l exactly, averaged over each bin). The table is given only the bin
//! averages of P, as a bake is; what it makes of the j ≥ 2 terms — the slope of the
//! diffraction lobe, the glory, the fogbow — is what this measures (docs/accuracy.md, "Presets
//! that keep their promise").

use std::path::Path;

use tables::ams::{AmsSeries, Reconstruction};
use tables::legendre::ThetaGrid;

/// θ_k and the columns n = 1, 2, 3, 4, 6, 8, 12, 16, 26 of the reference.
fn reference() -> (Vec<f64>, Vec<(usize, Vec<f64>)>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/reference/ams_exact_cloud.csv");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let orders = [1, 2, 3, 4, 6, 8, 12, 16, 26];
    let mut theta = Vec::new();
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); orders.len()];
    for line in text.lines().filter(|l| !l.starts_with('#')) {
        let values: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!(values.len(), orders.len() + 1, "{line}");
        theta.push(values[0]);
        for (c, v) in columns.iter_mut().zip(&values[1..]) {
            c.push(*v);
        }
    }
    (theta, orders.into_iter().zip(columns).collect())
}

/// The worst relative error of rows n ≥ 2 over θ ≥ 1° for `reconstruction`, printed per order,
/// and the smallest value of any row (any θ).
fn errors(reconstruction: Reconstruction) -> (f64, f64) {
    let grid = ThetaGrid::new(0.18).unwrap();
    let (theta, columns) = reference();
    assert_eq!(theta.len(), grid.len());
    let series = AmsSeries::new(&grid, &columns[0].1, reconstruction);
    let orders: Vec<usize> = columns.iter().map(|(n, _)| *n).collect();
    let rows = series.rows(&orders);
    let (mut worst_all, mut lowest) = (0.0f64, f64::INFINITY);
    for (r, (n, exact)) in columns.iter().enumerate() {
        let row = rows.row(r);
        let (mut worst, mut forward) = ((0.0f64, 0.0), 0.0f64);
        for k in 0..grid.len() {
            lowest = lowest.min(row[k]);
            let err = (row[k] / exact[k] - 1.0).abs();
            if theta[k] < 1.0 {
                forward = forward.max(err);
            } else if err > worst.0 {
                worst = (err, theta[k]);
            }
        }
        eprintln!(
            "{reconstruction:?} Ams_{n}: worst relative error {:.4} % at {:.2}° (θ ≥ 1°), {:.4} % \
             below 1°",
            100.0 * worst.0,
            worst.1,
            100.0 * forward
        );
        if *n >= 2 {
            worst_all = worst_all.max(worst.0);
        }
    }
    (worst_all, lowest)
}

/// The spline reconstruction (the default) keeps every order within 0.5 % of the exact
/// convolution beyond 1° (the presets' target; measured 0.005 %, Ams_2 at 1.44°, so the assertion
/// sits just above that) and every value ≥ 0; the earlier half-bin heat-kernel blur is measured
/// beside it (what it cost: Ams_2 4.0 % high at 1.80°, the bias the preset study found).
#[test]
fn higher_orders_equal_the_exact_convolution_beyond_one_degree() {
    let (blurred, _) = errors(Reconstruction::HeatKernel { blur_bins: 0.5 });
    let (quarter, _) = errors(Reconstruction::HeatKernel { blur_bins: 0.25 });
    let (spline, lowest) = errors(Reconstruction::Spline);
    eprintln!(
        "worst over n ≥ 2: spline {:.3} %; steps blurred by half a bin {:.3} %, by a quarter {:.3} %",
        100.0 * spline,
        100.0 * blurred,
        100.0 * quarter
    );
    assert!(lowest >= 0.0, "a negative value: {lowest}");
    assert!(spline < 1e-4, "worst {:.4} %", 100.0 * spline);
}
