//! The crystal tracer's sampling levers, one by one: for ice (column AR 2, 100 µm) and snow
//! (AR 1, 2 mm, δ = 0.7) at 550 nm, the rms over bins θ ≥ 1° of each bin's relative standard
//! error (from the spread between independent chunks) at several ray counts, and the time; for
//! snow also the facet tilts split 2, 4 and 8 ways.
//! `cargo run --release -p photometeor-mie --example crystal_levers`

use std::time::Instant;

use mie::ThetaGrid;
use mie::crystal::{CrystalField, Rays, Sampling, crystal_phase};

fn main() {
    let grid = ThetaGrid::new(0.18).unwrap();
    let fields = [
        (
            "ice",
            CrystalField {
                aspect_ratio: 2.0,
                max_dimension_um: 100.0,
                sigma_g: 1.5,
                roughness: 0.0,
            },
        ),
        (
            "snow",
            CrystalField {
                aspect_ratio: 1.0,
                max_dimension_um: 2000.0,
                sigma_g: 1.5,
                roughness: 0.7,
            },
        ),
    ];
    let counts: Vec<u64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().unwrap())
        .collect();
    let counts = if counts.is_empty() {
        vec![131_072, 524_288]
    } else {
        counts
    };
    println!("field  rays      sampling  symmetric  splits  rms rel SE (θ≥1°)  max rel SE  time s");
    for (name, field) in fields {
        for &count in &counts {
            // Tilt splitting only acts on distorted crystals.
            let splits: &[u32] = if field.roughness > 0.0 {
                &[1, 2, 4, 8]
            } else {
                &[1]
            };
            let levers = [
                (Sampling::Random, false),
                (Sampling::Random, true),
                (Sampling::Sobol, false),
                (Sampling::Sobol, true),
            ]
            .into_iter()
            .map(|(sampling, symmetric)| (sampling, symmetric, 1))
            .chain(splits[1..].iter().map(|&k| (Sampling::Random, false, k)));
            for (sampling, symmetric, tilt_splits) in levers {
                let t = Instant::now();
                let rays = Rays {
                    sampling,
                    symmetric,
                    tilt_splits,
                    ..Rays::random(count, 7)
                };
                let p = crystal_phase(&field, 550.0, grid, rays).unwrap();
                let secs = t.elapsed().as_secs_f64();
                let se = &p.crystal().unwrap().bins_std_error;
                let rel: Vec<f64> = (0..grid.len())
                    .filter(|&k| grid.theta_deg(k) >= 1.0)
                    .map(|k| se[k] / p.bins[k])
                    .collect();
                let rms = (rel.iter().map(|r| r * r).sum::<f64>() / rel.len() as f64).sqrt();
                let max = rel.iter().copied().fold(0.0, f64::max);
                let band = |lo: f64, hi: f64| {
                    let r: Vec<f64> = (0..grid.len())
                        .filter(|&k| (lo..hi).contains(&grid.theta_deg(k)))
                        .map(|k| (se[k] / p.bins[k]).powi(2))
                        .collect();
                    100.0 * (r.iter().sum::<f64>() / r.len() as f64).sqrt()
                };
                println!(
                    "{name:5}  {count:8}  {sampling:8?}  {symmetric:9}  {tilt_splits:6}  {:17.3} %  {:9.2} %  {secs:6.2}   bands 1-10 {:.2} 10-90 {:.2} 90-170 {:.2} 170-179 {:.2} 179-180 {:.2}",
                    100.0 * rms,
                    100.0 * max,
                    band(1.0, 10.0),
                    band(10.0, 90.0),
                    band(90.0, 170.0),
                    band(170.0, 179.0),
                    band(179.0, 180.1)
                );
            }
        }
    }
}
