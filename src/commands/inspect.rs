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
    // Every field's EXR is read and checked against its entry, not only the manifest.
    let bake = format::BakeDir::open(&a.dir)?;
    for entry in &bake.manifest.fields {
        bake.read_field(entry)?;
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
        println!(
            "  {:<10} {:<5} {:<14} N = {:<4} g = {:.4}/{:.4}/{:.4}  σ_ext = {:.3e} m²  F_1 = {:.4}  F_N = {:.4}  n_iso(1e-6) = {:?}",
            f.name,
            f.kind,
            f.file,
            f.n_max,
            f.g.r,
            f.g.g,
            f.g.b,
            f.sigma_ext_m2.g,
            f.forward_fraction.g[0],
            f.forward_fraction.g[f.n_max - 1],
            f.n_isotropic.g.get("1e-6").copied().flatten()
        );
        // The sampling behind the tables and its noise: rays for ice and snow, sizes for drops.
        let (what, key) = match f.quality["crystal_rays"].as_u64() {
            Some(rays) => (format!("{rays:.2e} rays traced"), "crystal_noise"),
            None => (
                format!(
                    "{} sizes per wavelength",
                    match &f.quality["sizes"] {
                        serde_json::Value::Null => &f.quality["knobs"]["sizes"],
                        n => n,
                    }
                ),
                "size_noise",
            ),
        };
        if let Some([r, g, b]) = rgb(&f.quality[key]) {
            println!(
                "  {:<10} {what}; noise of Ams_1 (rms relative standard error, θ ≥ 1°) R {:.2} %, G {:.2} %, B {:.2} %",
                "",
                100.0 * r,
                100.0 * g,
                100.0 * b
            );
        }
    }
    Ok(())
}

/// An {R, G, B} object of numbers, if that is what `v` is.
fn rgb(v: &serde_json::Value) -> Option<[f64; 3]> {
    Some([v["R"].as_f64()?, v["G"].as_f64()?, v["B"].as_f64()?])
}
