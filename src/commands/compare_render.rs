//! `photometeor compare-render`: a model's frame measured against the path-traced truth.

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args as ClapArgs;
use render::error_map::{Frame, Pixels, compare, error_map_rgb8, read_frame};

#[derive(Debug, ClapArgs)]
pub struct CompareRenderArgs {
    /// The truth: an EXR from `render --model truth` (with stderr.R/G/B).
    truth: PathBuf,
    /// The model's EXR of the same scene and size (e.g. `render --model riley`).
    model: PathBuf,
    /// Write the error map here (PNG): red too bright, blue too dark (full at ±50 %), grey
    /// within 3σ of the truth's noise, black where the volume does not matter.
    #[arg(long)]
    map: Option<PathBuf>,
    /// Which pixels to measure: `volume` (1 − T_vol > 1 %, the default) or `all` (every pixel
    /// the truth lights: also the air, such as haze and its light shafts, and the ground).
    #[arg(long, default_value = "volume", value_parser = ["volume", "all"])]
    pixels: String,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(a: CompareRenderArgs) -> Result<()> {
    // The map never replaces a device, a directory or either frame it compares.
    let inputs = [a.truth.as_path(), a.model.as_path()];
    if let Some(path) = &a.map {
        format::check_output(path, &inputs)?;
    }
    let truth = read_frame(&a.truth)?;
    let model = read_frame(&a.model)?;
    check_frame(&a.truth, &truth)?;
    check_frame(&a.model, &model)?;
    let pixels = if a.pixels == "all" {
        Pixels::All
    } else {
        Pixels::Volume
    };
    let (report, map) = compare(&truth, &model, pixels)?;
    if let Some(path) = &a.map {
        let (w, h) = (truth.image.width as u32, truth.image.height as u32);
        let png = crate::commands::plot::png_rgb8(w, h, &error_map_rgb8(&map))?;
        format::write_output(path, &png, &inputs)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} against the truth {} over {} pixels {} (luminance; differences within 3σ of the \
         truth's noise count as 0):",
        a.model.display(),
        a.truth.display(),
        report.pixels,
        match pixels {
            Pixels::Volume => "with 1 − T_vol > 1 %",
            Pixels::All => "(all lit)",
        }
    );
    println!(
        "  mean relative error {:.2} %, median {:.2} %, 95th percentile {:.2} %, bias {:+.2} %",
        report.mean_rel_error * 100.0,
        report.median_rel_error * 100.0,
        report.p95_rel_error * 100.0,
        report.bias * 100.0
    );
    println!(
        "  {:.1} % of the pixels agree within 3σ; the truth's median noise is {:.2} %",
        report.resolved * 100.0,
        report.truth_noise * 100.0
    );
    println!(
        "  noise-debiased rms error {:.2} % (of the mean luminance; the truth's noise taken \
         out rather than counted as exact)",
        report.debiased_rms * 100.0
    );
    Ok(())
}

/// Refuses a frame no comparison can be made from, naming its first bad pixel (x, y from the
/// top left), channel and value: a non-finite or negative R, G or B; an A outside [0, 1]; a
/// non-finite or negative stderr (a truth of one sample per pixel has none to give: its
/// stderr is infinite, and every difference would count as within its noise).
fn check_frame(path: &std::path::Path, frame: &Frame) -> Result<()> {
    let w = frame.image.width.max(1);
    let at = |i: usize| (i % w, i / w);
    for (i, p) in frame.image.rgb.iter().enumerate() {
        for (c, v) in ["R", "G", "B"].iter().zip(p) {
            if !(v.is_finite() && *v >= 0.0) {
                let (x, y) = at(i);
                bail!(
                    "{}: pixel ({x}, {y}) channel {c} = {v}: a radiance must be finite and ≥ 0",
                    path.display()
                );
            }
        }
    }
    for (i, v) in frame.image.transparency.iter().enumerate() {
        if !(0.0..=1.0).contains(v) {
            let (x, y) = at(i);
            bail!(
                "{}: pixel ({x}, {y}) channel A = {v}: a transparency lies in [0, 1]",
                path.display()
            );
        }
    }
    for (i, e) in frame.std_error.iter().flatten().enumerate() {
        for (c, v) in ["stderr.R", "stderr.G", "stderr.B"].iter().zip(e) {
            if !(v.is_finite() && *v >= 0.0) {
                let (x, y) = at(i);
                bail!(
                    "{}: pixel ({x}, {y}) channel {c} = {v}: a standard error must be finite and \
                     ≥ 0 (a truth of 1 sample per pixel has none: render it with --spp 2 or \
                     more)",
                    path.display()
                );
            }
        }
    }
    Ok(())
}
