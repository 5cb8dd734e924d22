//! The WGSL sampling functions on a real adapter against their CPU reference
//! (`runtime::sample`). Without an adapter the tests pass with a notice, unless
//! `REQUIRE_GPU=1`, when they fail (CI installs Mesa's lavapipe, a software Vulkan driver).

use std::path::PathBuf;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, Query, TexelFormat, evaluate};
use runtime::sample::{ams, forward_fraction};

mod common;

use common::{CLOUD, RAIN, gpu};

fn bake(fields: &str) -> (tempfile::TempDir, PathBuf) {
    common::bake(&common::scene("gpu", 6, fields))
}

/// Queries over every field, fractional and out-of-range orders, and angles from exactly 0° to
/// exactly 180°; the CPU reference is evaluated at the same f32 inputs.
fn compare(gpu: &Gpu, tables: &Tables, uploaded: &GpuTables, rel_tol: f64) -> f64 {
    eprintln!(
        "upload {:.1} ms, {:?}",
        1e3 * uploaded.upload_seconds,
        uploaded.format
    );
    let mut queries = Vec::new();
    for field in 0..tables.fields.len() as u32 {
        for n in [0.5f32, 1.0, 1.5, 2.75, 6.0, 9.0] {
            for i in 0..=400 {
                let theta = (i as f64 * 0.45).to_radians();
                queries.push(Query {
                    field,
                    n,
                    cos_theta: theta.cos() as f32,
                });
            }
        }
    }
    let got = evaluate(gpu, uploaded, &queries).unwrap();
    let mut worst: f64 = 0.0;
    let mut worst_at = String::new();
    for (q, g) in queries.iter().zip(&got) {
        let f = &tables.fields[q.field as usize];
        let want = ams(f, tables.theta_step_deg, q.n as f64, q.cos_theta as f64);
        let scale = f.image.row(1, 0).iter().copied().fold(0.0, f64::max);
        for c in 0..3 {
            let err = (g[c] as f64 - want[c]).abs() / (want[c].abs() + 1e-7 * scale);
            if err > worst {
                worst = err;
                worst_at = format!(
                    "field {} n {} θ {:.3}°: channel {c}: GPU {} vs CPU {}",
                    f.name,
                    q.n,
                    (q.cos_theta as f64).acos().to_degrees(),
                    g[c],
                    want[c]
                );
            }
        }
        let ff = forward_fraction(f, q.n as f64)[1];
        assert!((g[3] as f64 - ff).abs() < 1e-6, "F: {} vs {ff}", g[3]);
    }
    eprintln!(
        "{} queries, worst relative difference {worst:.1e} ({worst_at})",
        queries.len()
    );
    assert!(worst < rel_tol, "{worst_at}");
    worst
}

#[test]
fn wgsl_sampling_matches_the_cpu_reference_in_f32() {
    let Some(gpu) = gpu() else { return };
    let (_tmp, dir) = bake(&format!("{CLOUD}\n{RAIN}"));
    let tables = Tables::open(&dir).unwrap();
    // 32-bit texels and f32 arithmetic (acos, interpolation) against f64.
    let uploaded = GpuTables::upload(&gpu, &tables, TexelFormat::F32).unwrap();
    compare(&gpu, &tables, &uploaded, 1e-4);
}

#[test]
fn half_floats_where_the_values_fit() {
    let Some(gpu) = gpu() else { return };
    let (_tmp, dir) = bake(CLOUD);
    let tables = Tables::open(&dir).unwrap();
    assert!(runtime::gpu::fits_half(&tables));
    let uploaded = GpuTables::upload(&gpu, &tables, TexelFormat::Auto).unwrap();
    assert_eq!(uploaded.format, wgpu::TextureFormat::Rgba16Float);
    // Half floats keep 11 significant bits: 2⁻¹¹ ≈ 4.9e-4 relative per texel.
    compare(&gpu, &tables, &uploaded, 1e-3);
}
