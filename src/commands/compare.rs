//! `photometeor compare`: a bake measured against a reference bake of the same scene.

use anyhow::Result;
use clap::Args as ClapArgs;

#[derive(Debug, ClapArgs)]
pub struct CompareArgs {
    /// The bake to judge.
    dir: std::path::PathBuf,
    /// The bake taken as truth (e.g. a `--quality reference` bake of the same scene). A
    /// member of its sweeps that the bake lacks is judged against the bake's sweep of that
    /// field interpolated at its value (bake the midpoints to measure the interpolation).
    reference: std::path::PathBuf,
    /// Smallest scattering angle of the error statistics, in degrees (the forward bins hold
    /// the unresolved diffraction peak).
    #[arg(long, default_value_t = 1.0)]
    min_angle_deg: f64,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(a: CompareArgs) -> Result<()> {
    let report = bake::compare::compare(&a.dir, &a.reference, a.min_angle_deg)?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} against {} (θ ≥ {}°):",
        a.dir.display(),
        a.reference.display(),
        a.min_angle_deg
    );
    println!(
        "  {:<10} {:>2}  {:>12} {:>12} {:>12} {:>12} {:>10}",
        "field", "ch", "rms Ams_1", "max Ams_1", "rms all n", "max all n", "max |ΔF_i|"
    );
    for f in &report.fields {
        println!(
            "  {:<10} {:>2}  {:>12.3e} {:>12.3e} {:>12.3e} {:>12.3e} {:>10.2e}",
            f.field,
            f.channel,
            f.rms_rel_ams1,
            f.max_rel_ams1,
            f.rms_rel_all,
            f.max_rel_all,
            f.max_abs_forward_fraction
        );
        if let (Some((sweep, key, value)), "B") = (&f.interpolated, f.channel) {
            println!(
                "  {:<10}     interpolated from {}'s sweep {sweep} at {key} = {value:.4} \
                 (σ_ext {:.2e}, g {:.1e} apart)",
                "",
                a.dir.display(),
                f.rel_sigma_ext,
                f.abs_g
            );
        }
    }
    Ok(())
}
