//! `photometeor inspect`: the summary of a bake directory.

use anyhow::Result;
use clap::Args as ClapArgs;

#[derive(Debug, ClapArgs)]
pub struct InspectArgs {
    /// A bake directory (holding manifest.json).
    dir: std::path::PathBuf,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(a: InspectArgs) -> Result<()> {
    // Every file the manifest names is read and checked: each field's EXR and its side tables,
    // against their contracts, the manifest and each other.
    let bake = format::BakeDir::open(&a.dir)?;
    for entry in &bake.manifest.fields {
        bake.read_field_files(entry)?;
    }
    let manifest = bake.manifest;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&manifest)?);
        return Ok(());
    }
    println!(
        "{}: schema {}, {} {}, Δθ = {}°, {} angles",
        a.dir.display(),
        manifest.schema,
        manifest.tool,
        manifest.tool_version,
        manifest.theta_step_deg,
        manifest.angle_count
    );
    for f in &manifest.fields {
        let n_iso = match f.n_isotropic.g.get("1e-6").copied().flatten() {
            Some(n) => n.to_string(),
            None => "not reached".to_string(),
        };
        println!(
            "  {:<10} {:<5} {:<14} N = {:<4} g = {:.4}/{:.4}/{:.4}  σ_ext = {:.3e} m²  F_1 = {:.4}  F_N = {:.4}  n_iso(1e-6) = {n_iso}",
            f.name,
            f.kind.name(),
            f.file,
            f.n_max,
            f.g.r,
            f.g.g,
            f.g.b,
            f.sigma_ext_m2.g,
            f.forward_fraction.g[0],
            f.forward_fraction.g[f.n_max - 1],
        );
        // The sampling behind the tables and its noise: rays for ice and snow, sizes for drops.
        if let (Some(what), Some(noise)) = (f.quality.sampling(), f.quality.noise()) {
            println!(
                "  {:<10} {what}; noise of Ams_1 (rms relative standard error, θ ≥ 1°) R {:.2} %, G {:.2} %, B {:.2} %",
                "",
                100.0 * noise.r,
                100.0 * noise.g,
                100.0 * noise.b
            );
        }
    }
    for s in &manifest.sweeps {
        let first = |v: &[f64]| v.first().copied().unwrap_or(f64::NAN);
        let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
        println!(
            "  sweep {}: {} from {} to {}, {} values ({} spacing), fields {} … {}",
            s.name,
            s.key,
            first(&s.values),
            last(&s.values),
            s.values.len(),
            s.spacing,
            s.fields.first().map_or("", String::as_str),
            s.fields.last().map_or("", String::as_str),
        );
    }
    Ok(())
}
