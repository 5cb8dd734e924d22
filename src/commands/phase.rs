//! `photometeor phase`: a size distribution's σ_ext, albedo, g and bin-averaged phase
//! function per wavelength.

use anyhow::{Result, bail};
use clap::Args as ClapArgs;
use mie::{BulkRequest, NodeCounts, SizeDistribution, ThetaGrid, bulk_phase};
use serde_json::json;

use super::mie::angles_from;
use crate::cli::{MaterialArg, parse_list};

#[derive(Debug, ClapArgs)]
pub struct PhaseArgs {
    /// Particle material.
    #[arg(long, value_enum, default_value = "water")]
    material: MaterialArg,
    /// Lognormal median radius r_g in µm (with --sigma-g).
    #[arg(long, allow_hyphen_values = true, requires = "sigma_g")]
    lognormal_median_um: Option<f64>,
    /// Lognormal geometric standard deviation σ_g, in (1, 5].
    #[arg(long, allow_hyphen_values = true)]
    sigma_g: Option<f64>,
    /// Effective radius in µm (with --v-eff): gamma distribution, or lognormal with --lognormal.
    #[arg(long, allow_hyphen_values = true, requires = "v_eff")]
    r_eff_um: Option<f64>,
    /// Effective variance (with --r-eff-um).
    #[arg(long, allow_hyphen_values = true)]
    v_eff: Option<f64>,
    /// Use a lognormal (instead of gamma) for --r-eff-um/--v-eff.
    #[arg(long)]
    lognormal: bool,
    /// Marshall–Palmer raindrop spectrum for this rain rate in mm/h, [0.1, 500].
    #[arg(long, allow_hyphen_values = true)]
    marshall_palmer_mm_h: Option<f64>,
    /// Vacuum wavelengths in nm, comma-separated (water: 200–1100 nm).
    #[arg(long, allow_hyphen_values = true, required = true)]
    wavelengths_nm: String,
    /// Fixed number of sizes (nodes in ln r), [1, 100000]; default: adaptive to --tolerance.
    #[arg(long)]
    sizes: Option<usize>,
    /// Fixed Gauss nodes per angular panel, [1, 64] (with --sizes; default 4).
    #[arg(long)]
    nodes_per_panel: Option<usize>,
    /// Adaptive refinement stops when one doubling changes the bins (rms, θ ≥ 1°), σ_ext or g
    /// by less than this.
    #[arg(long, default_value_t = 0.01)]
    tolerance: f64,
    /// Angle step of the output bins in degrees (must divide 180).
    #[arg(long, default_value_t = ThetaGrid::DEFAULT_STEP_DEG)]
    angles_step_deg: f64,
    /// Water temperature in °C.
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true)]
    temperature_c: f64,
    /// Also report p̄ at these angles (degrees, comma-separated, in [0, 180]) as point values.
    #[arg(long, allow_hyphen_values = true)]
    angles_deg: Option<String>,
    /// Mass fraction of the distribution left outside the truncated size range.
    #[arg(long, default_value_t = 1e-3)]
    tail_mass: f64,
    /// Print JSON instead of a summary.
    #[arg(long)]
    json: bool,
}

/// Chooses the size distribution from the mutually exclusive flag groups.
fn distribution_from(a: &PhaseArgs) -> Result<SizeDistribution> {
    let options = mie::DistributionOptions {
        lognormal_median_um: a.lognormal_median_um,
        sigma_g: a.sigma_g,
        r_eff_um: a.r_eff_um,
        v_eff: a.v_eff,
        lognormal: a.lognormal,
        marshall_palmer_mm_h: a.marshall_palmer_mm_h,
    };
    let flag = |name: &str| format!("--{}", name.replace('_', "-"));
    Ok(options.choose(flag, None)?.expect("no other group"))
}

/// Largest --sizes: 25× the reference preset's 4096, far past where one doubling still changes
/// a bin (and about 1 GB of coefficients at x = 2e5).
const MAX_SIZES: usize = 100_000;
/// Largest --nodes-per-panel: where the adaptive refinement gives up.
const MAX_NODES_PER_PANEL: usize = 64;

/// Runs `photometeor phase`.
pub fn run(a: PhaseArgs) -> Result<()> {
    let wavelengths_nm = parse_list("wavelength (nm)", &a.wavelengths_nm, "[200, 1100] nm")?;
    let distribution = distribution_from(&a)?;
    let nodes = match (a.sizes, a.nodes_per_panel) {
        (Some(sizes), nodes) => {
            if !(1..=MAX_SIZES).contains(&sizes) {
                bail!("--sizes {sizes} is outside the allowed range [1, {MAX_SIZES}]");
            }
            let nodes_per_panel = nodes.unwrap_or(4);
            if !(1..=MAX_NODES_PER_PANEL).contains(&nodes_per_panel) {
                bail!(
                    "--nodes-per-panel {nodes_per_panel} is outside the allowed range [1, {MAX_NODES_PER_PANEL}]"
                );
            }
            NodeCounts::Fixed {
                sizes,
                nodes_per_panel,
            }
        }
        (None, Some(_)) => bail!("--nodes-per-panel needs --sizes (fixed node counts)"),
        (None, None) => {
            if !(a.tolerance > 0.0 && a.tolerance < 1.0) {
                bail!(
                    "--tolerance {} is outside the allowed range (0, 1)",
                    a.tolerance
                );
            }
            NodeCounts::Adaptive {
                tolerance: a.tolerance,
                max_sizes: 1 << 14,
            }
        }
    };
    let (point_angles_deg, point_cosines) = match &a.angles_deg {
        Some(text) => angles_from(Some(text.clone()), None)?,
        None => (Vec::new(), Vec::new()),
    };
    let request = BulkRequest {
        material: a.material.into(),
        temperature_c: a.temperature_c,
        distribution,
        wavelengths_nm,
        grid: ThetaGrid::new(a.angles_step_deg)?,
        nodes,
        tail_mass: a.tail_mass,
        point_cosines,
    };
    let result = bulk_phase(&request)?;
    if a.json {
        let out = json!({
            "material": request.material,
            "temperature_c": request.temperature_c,
            "distribution": request.distribution,
            "theta_step_deg": request.grid.step_deg(),
            "angles_deg": request.grid.thetas_deg(),
            "point_angles_deg": point_angles_deg,
            "node_counts": request.nodes,
            "tail_mass": request.tail_mass,
            "wavelengths": result,
        });
        println!("{}", serde_json::to_string(&out)?);
    } else {
        println!(
            "{} {}, {} bins of {}°",
            request.material.name(),
            request.distribution.describe(),
            request.grid.len(),
            request.grid.step_deg()
        );
        println!(
            "{:>8} {:>22} {:>13} {:>10} {:>9} {:>6} {:>6} {:>11}",
            "λ (nm)", "m", "σ_ext (m²)", "albedo", "g", "sizes", "nodes", "energy-1"
        );
        for r in &result {
            println!(
                "{:>8} {:>22} {:>13.6e} {:>10.8} {:>9.6} {:>6} {:>6} {:>11.2e}",
                r.wavelength_nm,
                format!("{:.5}+{:.3e}i", r.m_re, r.m_im),
                r.sigma_ext_m2,
                r.albedo,
                r.g,
                r.mie().map_or(0, |m| m.sizes),
                r.mie().map_or(0, |m| m.nodes_per_panel),
                r.mie().map_or(f64::NAN, |m| m.energy_closure)
            );
        }
        if !point_angles_deg.is_empty() {
            println!("p̄ (1/sr) at the requested angles:");
            for (k, theta) in point_angles_deg.iter().enumerate() {
                let values: Vec<String> = result
                    .iter()
                    .map(|r| format!("{:>14.6e}", r.points[k]))
                    .collect();
                println!("{theta:>10.4}° {}", values.join(" "));
            }
        }
    }
    Ok(())
}
