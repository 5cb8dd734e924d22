//! The command line: the subcommands (each in its own file under `commands/`) and the parsing
//! helpers they share.

use anyhow::{Result, bail};
use clap::{Parser, Subcommand};
use mie::Material;
use num_complex::Complex64;

use crate::commands::{
    bake, bench, compare, compare_render, export, inspect, merge, mie as mie_cmd, phase, plot,
    render, shaders, tradeoff, validate,
};

/// Phase functions of cloud droplets, raindrops, ice and snow, and the multiple-scattering
/// tables real-time renderers need.
///
/// Conventions: θ is the scattering angle in degrees (0 = forward); refractive index
/// m = n + iκ with κ ≥ 0 absorbing; size parameter x = 2πr/λ; phase functions in 1/sr,
/// normalized so ∫ p dΩ = 1; radii in µm, wavelengths in nm (vacuum), cross-sections in m².
#[derive(Debug, Parser)]
#[command(name = "photometeor", version, about, long_about)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

impl Args {
    /// Runs the chosen subcommand.
    pub fn run(self) -> Result<()> {
        match self.command {
            Command::Mie(a) => mie_cmd::run(a),
            Command::Phase(a) => phase::run(a),
            Command::Bench(a) => bench::run(a),
            Command::Render(a) => render::run(a),
            Command::CompareRender(a) => compare_render::run(a),
            Command::Bake(a) => bake::run(a),
            Command::Merge(a) => merge::run(a),
            Command::Inspect(a) => inspect::run(a),
            Command::Compare(a) => compare::run(a),
            Command::Validate(a) => validate::run(a),
            Command::Tradeoff(a) => tradeoff::run(a),
            Command::Plot(a) => plot::run(a),
            Command::Shaders(a) => shaders::run(a),
            Command::Export(a) => export::run(a),
            #[cfg(feature = "view")]
            Command::View(a) => crate::commands::view::run(a),
            #[cfg(not(feature = "view"))]
            Command::View(_) => bail!(
                "this photometeor was built without the viewer (the `view` feature, which adds \
                 winit and egui): cargo run --release --features view -- view [SCENE]"
            ),
        }
    }
}

#[derive(Debug, Subcommand)]
enum Command {
    /// One sphere: efficiencies, S1, S2 and the normalized phase function.
    Mie(mie_cmd::MieArgs),
    /// A size distribution of water or ice spheres: σ_ext, albedo, g and the phase function
    /// averaged inside the bins of a uniform θ grid, per wavelength.
    Phase(phase::PhaseArgs),
    /// Bake a scene's multiple-scattering tables: per field `<field>.exr` (rows Ams_1..Ams_N,
    /// columns θ_k = k·Δθ, channels R, G, B in 1/sr) and three side tables the render models
    /// read (`.single.exr`, single scattering per wavelength for the path tracer; `.poisson.exr`,
    /// Max et al.'s Poisson mixtures; `.biri.exr`, Biri et al.'s kernel), and manifest.json
    /// naming every file with its size and CRC-32. Unchanged fields come from the cache in
    /// DIR/.cache.
    Bake(bake::BakeArgs),
    /// Merge the shard directories of `bake SCENE --shard K/N --out DIR_K` (K = 1…N) into one
    /// bake directory: refused, nothing written, unless they are the N shards of one scene and
    /// one program version with every field once; the bake is byte-identical to one without
    /// shards.
    Merge(merge::MergeArgs),
    /// Summarize a bake directory (fields, sizes, F_i, n_iso, g, σ_ext, albedo).
    Inspect(inspect::InspectArgs),
    /// Compare two bakes of the same scene: rms and max relative error of Ams_1 and of all
    /// rows (bins θ ≥ --min-angle-deg), and the largest F_i difference, per field and channel.
    Compare(compare::CompareArgs),
    /// Check a bake against theory from the fields' own refractive index and sizes: rainbow
    /// angles (Descartes + Airy shift), Alexander's dark band, supernumeraries, glory, first
    /// corona ring (Fraunhofer), 22°/46° halos (prism minimum deviation), snow without halos.
    /// Angles in degrees (scattering angle, 0 = forward). Exits 1 when a check fails.
    Validate(validate::ValidateArgs),
    /// Draw a bake (PNG and SVG): Ams_1 per channel on a log scale (phase function, 1/sr,
    /// against scattering angle in degrees) with an optional reference bake overlaid, zooms on
    /// rainbows/glory/corona/halos, the Ams_n family, F_n against n, sRGB colour strips for
    /// n = 1, 2, 4, 8; and the Pareto front of a `tradeoff` run.
    Plot(plot::PlotArgs),
    /// Measure the speed/accuracy trade: vary each bake knob alone from `standard`, bake and
    /// time each variant, compare it with a reference-quality bake (relative errors of Ams_n
    /// for θ ≥ 1°, |ΔF_i|, peak-angle shifts in degrees) and write a table and tradeoff.json.
    Tradeoff(tradeoff::TradeoffArgs),
    /// Render a scene headless (Riley et al. 2004 §4–5): bake the fields its volumes use, then
    /// slice the volumes with a light buffer and an eye buffer on the GPU (wgpu; --cpu for the
    /// reference renderer), with the analytic sky and aerial perspective. Writes an HDR EXR
    /// (radiance per unit solar irradiance, 1/sr) and optionally a tone-mapped PNG.
    Render(render::RenderArgs),
    /// Measure a model's frame against the path-traced truth of the same scene (`render --model
    /// truth`): mean and 95th-percentile relative error of luminance and the bias, over the
    /// pixels where the volume matters (1 − T_vol > 1 %), ignoring differences within 3σ of
    /// the truth's noise; optionally an error-map PNG.
    CompareRender(compare_render::CompareRenderArgs),
    /// Time photometeor's Mie workloads (and miepython's, side by side, when available).
    Bench(bench::BenchArgs),
    /// Write the GPU sampling functions (ams, forward_fraction, ams_mix; the render models'
    /// poisson and biri_primitive) in every engine's language: WGSL, HLSL (SM 5.1), GLSL 450
    /// and ES 310, MSL 2.0 and SPIR-V, translated by naga from the one WGSL source, each with a
    /// header stating its bindings. θ in radians inside the shaders, optical depths unitless.
    Shaders(shaders::ShadersArgs),
    /// Write a bake's Ams_n rows in the formats other programs load: Bevy's chromatic phase
    /// texture (KTX2 and EXR, N × 1 Rgba32Float linear in cos θ), Mitsuba 3's tabphase, NumPy
    /// arrays or CSV. Resampling to a grid in cos θ conserves each row's energy; the command
    /// reports the light it moves to a wrong θ bin and the forward peak's height kept, and by
    /// default takes the fewest samples that keep the moved light under --max-loss.
    Export(export::ExportArgs),
    /// The scene in a window, live (built with `--features view`): move the sun (degrees) and
    /// the camera, switch models and their settings, change the density and a field's size
    /// (re-baked in the background), see the frame time, and the error against a truth frame.
    #[cfg(feature = "view")]
    View(crate::commands::view::ViewArgs),
    /// The scene in a window, live: this build has no viewer; build with `--features view`.
    #[cfg(not(feature = "view"))]
    View(NoViewer),
}

/// `view`'s arguments in a build without the viewer: taken and refused with how to build it.
#[cfg(not(feature = "view"))]
#[derive(Debug, clap::Args)]
pub struct NoViewer {
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
    _args: Vec<String>,
}

/// A particle material on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum MaterialArg {
    /// Liquid water.
    Water,
    /// Ice Ih.
    Ice,
}

impl From<MaterialArg> for Material {
    fn from(m: MaterialArg) -> Self {
        match m {
            MaterialArg::Water => Material::Water,
            MaterialArg::Ice => Material::Ice,
        }
    }
}

/// Parses "1.333+1e-8i", "1.5-0.1j", "1.33": real part, then an optional signed imaginary part.
pub fn parse_complex(text: &str) -> Result<Complex64> {
    let t = text.trim();
    let bad = || {
        anyhow::anyhow!(
            "refractive index m = {text:?} is not a complex number like 1.333+1e-8i (n + iκ, κ ≥ 0)"
        )
    };
    let body = t.strip_suffix(['i', 'j']);
    let Some(body) = body else {
        return t
            .parse::<f64>()
            .map(|re| Complex64::new(re, 0.0))
            .map_err(|_| bad());
    };
    // The sign that starts the imaginary part: the last + or − not at the start and not
    // directly after an exponent marker.
    let bytes = body.as_bytes();
    let split = (1..bytes.len())
        .rev()
        .find(|&i| (bytes[i] == b'+' || bytes[i] == b'-') && !matches!(bytes[i - 1], b'e' | b'E'))
        .ok_or_else(bad)?;
    let re: f64 = body[..split].parse().map_err(|_| bad())?;
    let im_text = &body[split..];
    let im: f64 = if im_text == "+" || im_text == "-" {
        format!("{im_text}1").parse().map_err(|_| bad())?
    } else {
        im_text.parse().map_err(|_| bad())?
    };
    Ok(Complex64::new(re, im))
}

/// Parses a comma-separated list of numbers; `what` names the list in errors.
pub fn parse_list(what: &str, text: &str, allowed: &str) -> Result<Vec<f64>> {
    let items: Vec<&str> = text
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .collect();
    if items.is_empty() {
        bail!("{what} list is empty; give at least one value in {allowed}");
    }
    items
        .iter()
        .map(|t| {
            t.parse::<f64>().map_err(|_| {
                anyhow::anyhow!("{what} {t:?} is not a number; allowed range {allowed}")
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_complex_indices() {
        assert_eq!(
            parse_complex("1.333+1e-8i").unwrap(),
            Complex64::new(1.333, 1e-8)
        );
        assert_eq!(
            parse_complex("1.5-0.1j").unwrap(),
            Complex64::new(1.5, -0.1)
        );
        assert_eq!(parse_complex("1.33").unwrap(), Complex64::new(1.33, 0.0));
        assert_eq!(
            parse_complex("1e0+1E-3i").unwrap(),
            Complex64::new(1.0, 1e-3)
        );
        assert!(parse_complex("1.3+xi").is_err());
        assert!(parse_complex("abc").is_err());
    }
}
