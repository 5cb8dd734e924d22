//! What buys accuracy per size for drops (docs/accuracy.md, "Presets that keep their promise"). For rain (lognormal r_g = 0.5 mm,
//! σ_g = 1.4) and a cloud (gamma r_eff = 10 µm, v_eff = 0.1) at 550 nm, the rms relative error
//! over bins θ ≥ 1° of the size-averaged phase function against a reference of many sizes, for
//! - equal steps in ln r at one shift (a rank-1 lattice in size), 2 Gauss nodes per angular
//!   panel (the bake's nodes before compute version 13);
//! - equal steps of the cross-section-weighted distribution n(r) r² (the bake's nodes now,
//!   `SizeDistribution::quadrature_by_area`);
//! - with `--more`: independent uniform fractions (plain Monte Carlo over sizes), same counts;
//! - with `--more`: the lattice with the angular ripple (period ~π/x in θ) averaged inside each bin by more
//!   Gauss nodes per panel (an interference-aware average: each size's bin value smooth in x).
//!
//! Each error is the rms over four shifts (or streams), so it is the method's, not one draw's;
//! the reference's own error is the rms difference of two references at other shifts over √2.
//! `cargo run --release -p photometeor-mie --example size_levers [--single|--mixed] [--more] [SIZES...]`

use std::time::Instant;

use mie::ensemble::bulk_at;
use mie::{SizeDistribution, SizeQuadrature, ThetaGrid};

const TAIL: f64 = 1e-3;
const REFERENCE_SIZES: usize = 4096;
const REFERENCE_NODES: usize = 8;
const SHIFTS: [f64; 4] = [0.125, 0.375, 0.625, 0.875];

fn phase(q: &SizeQuadrature, grid: ThetaGrid, nodes: usize) -> (Vec<f64>, f64) {
    let t = Instant::now();
    let p = at(550.0, q, grid, nodes);
    (p.bins, t.elapsed().as_secs_f64())
}

fn at(lambda: f64, q: &SizeQuadrature, grid: ThetaGrid, nodes: usize) -> mie::PhaseFunction {
    let m = mie::refractive::water_refractive_index(lambda, 10.0).unwrap();
    bulk_at(m, lambda, q, grid, nodes, &[]).unwrap()
}

/// A channel that mixes 31 wavelengths over 400–700 nm with equal weights (the bake's
/// a_j ∝ σ_sca,j), wavelength j's nodes at `shift(j)` of a step.
fn mixed(
    d: &SizeDistribution,
    sizes: usize,
    grid: ThetaGrid,
    shift: impl Fn(usize) -> f64,
) -> (Vec<f64>, f64) {
    let t = Instant::now();
    let mut bins = vec![0.0; grid.len()];
    let mut total = 0.0;
    for j in 0..31 {
        let p = at(
            400.0 + 10.0 * j as f64,
            &d.quadrature_shifted(sizes, TAIL, shift(j)),
            grid,
            2,
        );
        total += p.sigma_sca_m2;
        for (b, v) in bins.iter_mut().zip(&p.bins) {
            *b += p.sigma_sca_m2 * v;
        }
    }
    bins.iter_mut().for_each(|b| *b /= total);
    (bins, t.elapsed().as_secs_f64())
}

fn rms_rel(grid: ThetaGrid, a: &[f64], b: &[f64]) -> f64 {
    let r: Vec<f64> = (0..grid.len())
        .filter(|&k| grid.theta_deg(k) >= 1.0)
        .map(|k| (a[k] - b[k]) / b[k])
        .collect();
    (r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64).sqrt()
}

/// The rms over [`SHIFTS`] of `run(i)`'s error against `reference`, and its mean time (`run`
/// returns bins and seconds).
fn over_shifts(
    grid: ThetaGrid,
    reference: &[f64],
    run: impl Fn(usize) -> (Vec<f64>, f64),
) -> (f64, f64) {
    let (sq, secs) = (0..SHIFTS.len()).fold((0.0, 0.0), |(sq, secs), i| {
        let (p, t) = run(i);
        (sq + rms_rel(grid, &p, reference).powi(2), secs + t)
    });
    let n = SHIFTS.len() as f64;
    ((sq / n).sqrt(), secs / n)
}

/// A small deterministic generator (SplitMix64) for the Monte Carlo fractions.
fn uniforms(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    (0..n)
        .map(|_| {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

fn main() {
    let grid = ThetaGrid::new(0.18).unwrap();
    let fields = [
        (
            "rain",
            SizeDistribution::Lognormal {
                median_radius_um: 500.0,
                sigma_g: 1.4,
            },
        ),
        (
            "cloud",
            SizeDistribution::Gamma {
                r_eff_um: 10.0,
                v_eff: 0.1,
            },
        ),
    ];
    let args: Vec<String> = std::env::args().skip(1).collect();
    let only =
        |part: &str| !args.iter().any(|a| a.starts_with("--")) || args.iter().any(|a| a == part);
    let counts: Vec<usize> = args
        .iter()
        .filter(|a| !a.starts_with("--"))
        .map(|a| a.parse().unwrap())
        .collect();
    let counts = if counts.is_empty() {
        vec![16, 32, 64, 128, 256]
    } else {
        counts
    };
    println!("field  nodes            sizes  angular nodes  rms rel error (θ≥1°)  s per bake");
    for (name, d) in fields.iter().copied().filter(|_| only("--single")) {
        let reference = |shift: f64| {
            phase(
                &d.quadrature_shifted(REFERENCE_SIZES, TAIL, shift),
                grid,
                REFERENCE_NODES,
            )
        };
        let (ref_a, t_ref) = reference(0.5);
        let (ref_b, _) = reference(0.0);
        let (ref_c, _) = reference(0.25);
        let own = rms_rel(grid, &ref_b, &ref_c) / std::f64::consts::SQRT_2;
        println!(
            "{name:5}  reference        {REFERENCE_SIZES:5}  {REFERENCE_NODES:13}  {:17.3} %  {t_ref:9.2}   (its own: the rms difference of two other shifts / √2)",
            100.0 * own
        );
        let row = |label: &str, sizes: usize, nodes: usize, q: &dyn Fn(usize) -> SizeQuadrature| {
            let (error, secs) = over_shifts(grid, &ref_a, |i| phase(&q(i), grid, nodes));
            println!(
                "{name:5}  {label:15}  {sizes:5}  {nodes:13}  {:17.3} %  {secs:9.3}",
                100.0 * error
            );
        };
        for &n in &counts {
            row("lattice", n, 2, &|i| {
                d.quadrature_shifted(n, TAIL, SHIFTS[i])
            });
            row("area lattice", n, 2, &|i| {
                d.quadrature_by_area(n, TAIL, SHIFTS[i])
            });

            if !args.iter().any(|a| a == "--more") {
                continue;
            }
            row("monte carlo", n, 2, &|i| {
                d.quadrature_at(&uniforms(n, 1 + i as u64), TAIL)
            });
            for nodes in [8, 32] {
                row("lattice", n, nodes, &|i| {
                    d.quadrature_shifted(n, TAIL, SHIFTS[i])
                });
            }
        }
    }

    // The per-wavelength shifts: rain in a channel of 31 wavelengths, every wavelength at the
    // same shift against each at its own (j + ½)/J (the bake's), against a reference of 1024
    // sizes per wavelength at the bake's shifts (31 744 distinct radii).
    if !only("--mixed") {
        return;
    }
    let d = fields[0].1;
    let (reference, t_ref) = mixed(&d, 1024, grid, |j| (j as f64 + 0.5) / 31.0);
    let (other, _) = mixed(&d, 1024, grid, |j| ((j as f64 + 0.5) / 31.0 + 0.5).fract());
    println!(
        "rain, 31 λ  reference  1024 per λ  {:8.3} %  {t_ref:8.2}   (its own: two shifts' rms difference / √2)",
        100.0 * rms_rel(grid, &other, &reference) / std::f64::consts::SQRT_2
    );
    for &n in &counts[..counts.len().min(2)] {
        for (label, per_wavelength) in [("one shift", false), ("shift per λ", true)] {
            let (error, secs) = over_shifts(grid, &reference, |i| {
                mixed(&d, n, grid, |j| {
                    if per_wavelength {
                        ((j as f64 + 0.5) / 31.0 + SHIFTS[i]).fract()
                    } else {
                        SHIFTS[i]
                    }
                })
            });
            println!(
                "rain, 31 λ  {label:11}  {n:5} per λ  {:8.3} %  {secs:8.2}",
                100.0 * error
            );
        }
    }
}
