//! Loads, checks and uploads a bake, and reports the time of each step and a sampling check:
//! `cargo run --release -p photometeor-runtime --example upload -- [DIR]` (default
//! `photometeor-tables`).

use std::time::Instant;

use runtime::Tables;
use runtime::gpu::{Gpu, GpuTables, Query, TexelFormat, evaluate};
use runtime::sample::ams;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "photometeor-tables".into());
    let t0 = Instant::now();
    let tables = Tables::open(&dir)?;
    let load = t0.elapsed().as_secs_f64();
    let gpu = Gpu::new()?;
    let uploaded = GpuTables::upload(&gpu, &tables, TexelFormat::Auto)?;
    let texels: usize = tables.fields.len() * uploaded.n_stride * tables.angle_count;
    println!(
        "{dir}: {} fields, {} × {} texels each; load + check {:.0} ms; upload {:.1} ms ({:?}, {:.1} MiB) on {}",
        tables.fields.len(),
        uploaded.n_stride,
        tables.angle_count,
        1e3 * load,
        1e3 * uploaded.upload_seconds,
        uploaded.format,
        (texels
            * if uploaded.format == wgpu::TextureFormat::Rgba16Float {
                8
            } else {
                16
            }) as f64
            / (1 << 20) as f64,
        gpu.describe()
    );
    // One query per field and a few angles: GPU against the CPU reference.
    let cases: Vec<(u32, f32, f32)> = (0..tables.fields.len() as u32)
        .flat_map(|field| {
            [1.0f32, 2.5, 26.0].into_iter().flat_map(move |n| {
                [0.5f64, 22.0, 138.0, 179.0]
                    .map(move |deg| (field, n, deg.to_radians().cos() as f32))
            })
        })
        .collect();
    let queries: Vec<Query> = cases
        .iter()
        .map(|&(field, n, cos_theta)| Query::ams(field, n, cos_theta))
        .collect();
    let got = evaluate(&gpu, &uploaded, &queries)?;
    let worst = cases
        .iter()
        .zip(&got)
        .map(|(&(field, n, cos_theta), g)| {
            let f = &tables.fields[field as usize];
            let want = ams(f, tables.theta_step_deg, n as f64, cos_theta as f64);
            (0..3)
                .map(|c| ((g[c] as f64 - want[c]) / want[c]).abs())
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max);
    println!(
        "{} sample queries, worst relative difference GPU vs CPU {worst:.1e}",
        queries.len()
    );
    Ok(())
}
