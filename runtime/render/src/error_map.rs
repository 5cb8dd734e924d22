//! How right an image is: a model's frame measured against the path-traced truth of the same
//! scene (`photometeor compare-render TRUTH.exr MODEL.exr`).
//!
//! # The statistics
//! Over the pixels where the volume matters — 1 − T_vol > 1 % in the truth's A channel (the
//! same ray march of β_ext in both models) — with luminance Y = 0.2126 R + 0.7152 G +
//! 0.0722 B (Rec. 709) and the truth's standard error of it σ_Y (its `stderr.Y`, from the
//! samples' own luminance; for a truth written before it, (Σ_c w_c² σ_c²)^{1/2}, which
//! treats the channels as independent and so understates σ_Y where one path carries them
//! all):
//! - the pixel's difference d = Y_model − Y_truth counts as 0 when |d| ≤ 3 σ_Y (it cannot be
//!   told from the truth's own noise), else as d;
//! - relative error e = |d| / Y_truth: its mean, median and 95th percentile are reported;
//! - bias = Σ d / Σ Y_truth (signed; the share of light the model gains or loses overall,
//!   all masked pixels, without the 3σ rule);
//! - `resolved` = the share of masked pixels whose |d| ≤ 3σ_Y;
//! - the noise-debiased rms error ((mean d² − mean σ_Y²)⁺)^{1/2} / mean Y_truth over all
//!   masked pixels: d² overstates the model's own error by the truth's variance σ_Y² on
//!   average, which it subtracts, so that a noisy truth neither hides an error (as the 3σ rule
//!   does, which counts every pixel within 18 % of a truth at 6 % noise as exact) nor adds
//!   its own noise to it.
//!
//! The error map (PNG) shows d / Y_truth per pixel: red where the model is too bright, blue
//! where too dark (full colour at ±50 %), grey where |d| ≤ 3σ, black outside the mask.

use std::path::Path;

use serde::Serialize;

use crate::image::Image;

/// An EXR frame as `photometeor render` writes it: R, G, B, A and any further channels.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The image (A is the transparency).
    pub image: Image,
    /// stderr.R/G/B when present (the truth's).
    pub std_error: Option<Vec<[f32; 3]>>,
    /// stderr.Y when present: the standard error of the luminance from the samples' own
    /// (the truth's since it writes it; the channels of a path are correlated).
    pub luma_error: Option<Vec<f32>>,
}

/// Why a frame could not be read or compared.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct CompareError(pub String);

/// Reads a frame written by `photometeor render`.
pub fn read_frame(path: &Path) -> Result<Frame, CompareError> {
    let fail = |m: String| CompareError(format!("{}: {m}", path.display()));
    let bytes =
        format::read_regular_file(path, 1 << 30).map_err(|(op, e)| fail(format!("{op}: {e}")))?;
    let (channels, w, h) = format::exr::decode_channels(&bytes)
        .map_err(|e| fail(format!("not a readable OpenEXR file: {e}")))?;
    let get = |name: &str| -> Option<Vec<f32>> {
        channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.clone())
    };
    let need = |v: Option<Vec<f32>>, name: &str| {
        v.ok_or_else(|| fail(format!("no channel {name} (R, G, B, A expected)")))
    };
    let (r, g, b, a) = (
        need(get("R"), "R")?,
        need(get("G"), "G")?,
        need(get("B"), "B")?,
        need(get("A"), "A")?,
    );
    let std_error = match (get("stderr.R"), get("stderr.G"), get("stderr.B")) {
        (Some(er), Some(eg), Some(eb)) => Some((0..w * h).map(|i| [er[i], eg[i], eb[i]]).collect()),
        _ => None,
    };
    Ok(Frame {
        image: Image {
            width: w,
            height: h,
            rgb: (0..w * h).map(|i| [r[i], g[i], b[i]]).collect(),
            transparency: a,
        },
        std_error,
        luma_error: get("stderr.Y"),
    })
}

/// Which pixels are measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pixels {
    /// Where the volume matters, 1 − T_vol > 1 % (the default).
    #[default]
    Volume,
    /// Every pixel the truth lights: the air too (haze, shafts, sky) and the ground.
    All,
}

/// The measured error of a model's frame against the truth (module docs).
#[derive(Debug, Clone, Serialize)]
pub struct ErrorReport {
    /// Pixels in the mask (1 − T_vol > 1 %, or all lit ones with [`Pixels::All`]).
    pub pixels: usize,
    /// Mean relative error of luminance over the mask (differences within 3σ count as 0).
    pub mean_rel_error: f64,
    /// Median of the same (robust where the truth is nearly black: a relative error there can
    /// be huge and dominate the mean).
    pub median_rel_error: f64,
    /// 95th percentile of the same.
    pub p95_rel_error: f64,
    /// Σ (Y_model − Y_truth) / Σ Y_truth over the mask.
    pub bias: f64,
    /// Share of masked pixels whose difference is within 3σ of the truth's noise.
    pub resolved: f64,
    /// Median relative standard error of the truth's luminance over the mask.
    pub truth_noise: f64,
    /// ((mean d² − mean σ_Y²)⁺)^{1/2} / mean Y_truth over the mask (module docs).
    pub debiased_rms: f64,
}

/// Rec. 709 luminance weights of R, G, B.
pub const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Compares `model` against `truth` (same size; `truth` must carry stderr channels), and
/// returns the report and the signed relative difference per pixel (`None` outside the mask,
/// `Some(0)` within 3σ).
pub fn compare(
    truth: &Frame,
    model: &Frame,
    pixels: Pixels,
) -> Result<(ErrorReport, Vec<Option<f64>>), CompareError> {
    let (t, m) = (&truth.image, &model.image);
    if (t.width, t.height) != (m.width, m.height) {
        return Err(CompareError(format!(
            "the frames differ in size: truth {}×{}, model {}×{}",
            t.width, t.height, m.width, m.height
        )));
    }
    let err = truth.std_error.as_ref().ok_or_else(|| {
        CompareError(
            "the truth frame has no stderr.R/G/B channels: render it with --model truth".into(),
        )
    })?;
    let y = |p: [f32; 3]| (0..3).map(|c| LUMA[c] * p[c] as f64).sum::<f64>();
    let mut rel = Vec::new();
    let mut noise = Vec::new();
    let (mut sum_d, mut sum_t, mut resolved) = (0.0, 0.0, 0usize);
    let (mut sum_d2, mut sum_var) = (0.0, 0.0);
    let mut map = vec![None; t.rgb.len()];
    for i in 0..t.rgb.len() {
        if pixels == Pixels::Volume && 1.0 - t.transparency[i] as f64 <= 0.01 {
            continue;
        }
        let (yt, ym) = (y(t.rgb[i]), y(m.rgb[i]));
        if yt.is_nan() || yt <= 0.0 {
            continue;
        }
        // σ_Y from the samples' luminance where the truth wrote it; else from the channels'
        // as if they were independent (older truths: an understatement where they are not).
        let sigma = truth.luma_error.as_ref().map_or_else(
            || {
                (0..3)
                    .map(|c| (LUMA[c] * err[i][c] as f64).powi(2))
                    .sum::<f64>()
                    .sqrt()
            },
            |e| f64::from(e[i]),
        );
        let d = ym - yt;
        sum_d += d;
        sum_t += yt;
        sum_d2 += d * d;
        sum_var += sigma * sigma;
        noise.push(sigma / yt);
        let e = if d.abs() <= 3.0 * sigma {
            resolved += 1;
            0.0
        } else {
            d / yt
        };
        rel.push(e.abs());
        map[i] = Some(e);
    }
    if rel.is_empty() {
        return Err(CompareError(match pixels {
            Pixels::Volume => {
                "no pixel of the truth has 1 − T_vol > 1 %: the volume covers nothing to compare"
                    .into()
            }
            Pixels::All => "no pixel of the truth is lit: nothing to compare".into(),
        }));
    }
    let n = rel.len();
    let mean = rel.iter().sum::<f64>() / n as f64;
    rel.sort_by(f64::total_cmp);
    noise.sort_by(f64::total_cmp);
    Ok((
        ErrorReport {
            pixels: n,
            mean_rel_error: mean,
            median_rel_error: rel[n / 2],
            p95_rel_error: rel[((n - 1) as f64 * 0.95).round() as usize],
            bias: sum_d / sum_t,
            resolved: resolved as f64 / n as f64,
            truth_noise: noise[n / 2],
            debiased_rms: ((sum_d2 - sum_var).max(0.0) / n as f64).sqrt() / (sum_t / n as f64),
        },
        map,
    ))
}

/// The error map as an 8-bit RGB image (module docs).
pub fn error_map_rgb8(map: &[Option<f64>]) -> Vec<u8> {
    map.iter()
        .flat_map(|e| match *e {
            None => [0u8, 0, 0],
            Some(0.0) => [128, 128, 128],
            Some(e) => {
                let a = (e.abs() / 0.5).min(1.0);
                let hi = 128.0 + 127.0 * a;
                let lo = 128.0 * (1.0 - a);
                if e > 0.0 {
                    [hi as u8, lo as u8, lo as u8]
                } else {
                    [lo as u8, lo as u8, hi as u8]
                }
            }
        })
        .collect()
}

/// Writes the error map as a PNG.
pub fn write_error_map(
    path: &Path,
    map: &[Option<f64>],
    width: usize,
    height: usize,
) -> Result<(), crate::image::WriteError> {
    crate::image::write_png_rgb8(path, width, height, &error_map_rgb8(map))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4-pixel frame of grey luminance `y` per pixel, transparency `t`, stderr `se`.
    fn frame(y: [f32; 4], t: [f32; 4], se: Option<f32>) -> Frame {
        Frame {
            image: Image {
                width: 2,
                height: 2,
                rgb: y.iter().map(|&v| [v; 3]).collect(),
                transparency: t.to_vec(),
            },
            std_error: se.map(|s| vec![[s; 3]; 4]),
            luma_error: None,
        }
    }

    #[test]
    fn errors_count_beyond_the_truth_noise_over_the_chosen_pixels() {
        // Pixels 0–2 are volume (T 0.5), pixel 3 is clear sky (T 1).
        let truth = frame([1.0, 2.0, 4.0, 8.0], [0.5, 0.5, 0.5, 1.0], Some(0.01));
        // +50 %, within noise (+0.02 < 3σ = 0.03), −25 %, and +100 % on the sky.
        let model = frame([1.5, 2.02, 3.0, 16.0], [0.5; 4], None);
        let (r, map) = compare(&truth, &model, Pixels::Volume).unwrap();
        assert_eq!(r.pixels, 3);
        assert!(
            (r.mean_rel_error - (0.5 + 0.0 + 0.25) / 3.0).abs() < 1e-6,
            "{r:?}"
        );
        assert!((r.median_rel_error - 0.25).abs() < 1e-6);
        assert!((r.p95_rel_error - 0.5).abs() < 1e-6);
        assert!((r.bias - (0.5 + 0.02 - 1.0) / 7.0).abs() < 1e-6);
        assert!((r.resolved - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(map[1], Some(0.0));
        assert_eq!(map[3], None);
        let (r, map) = compare(&truth, &model, Pixels::All).unwrap();
        assert_eq!(r.pixels, 4);
        assert!((r.bias - (0.5 + 0.02 - 1.0 + 8.0) / 15.0).abs() < 1e-6);
        assert!(map[3].is_some_and(|e| (e - 1.0).abs() < 1e-6));
        // Refusals: no stderr in the truth, frames of different sizes, nothing in the mask.
        assert!(compare(&model, &truth, Pixels::Volume).is_err());
        let mut small = model.clone();
        small.image.width = 1;
        assert!(compare(&truth, &small, Pixels::Volume).is_err());
        let clear = frame([1.0; 4], [1.0; 4], Some(0.01));
        let e = compare(&clear, &model, Pixels::Volume).unwrap_err().0;
        assert!(e.contains("1 − T_vol > 1 %"), "{e}");
    }

    /// A truth with Gaussian noise of 6 % per channel (its stated σ) against a model 5 % too
    /// bright in half its pixels and 5 % too dark in the rest: the 3σ rule counts nearly every
    /// pixel as exact, the plain rms of d adds the truth's noise, and the debiased rms reads
    /// the model's 5 %; against the noiseless answer itself it reads 0 (within its sampling
    /// error at 40 000 pixels).
    #[test]
    fn a_noisy_truth_neither_hides_nor_adds_to_the_debiased_rms() {
        let n = 40_000;
        let mut rng = crate::rng::SplitMix64::new(7);
        let mut gauss = || {
            let (u, v) = (rng.uniform().max(1e-300), rng.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let exact: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64 * 0.1).collect();
        // Each channel its own draw, as the truth's channels are (σ_Y from them).
        let noisy: Vec<[f32; 3]> = exact
            .iter()
            .map(|&y| std::array::from_fn(|_| (y * (1.0 + 0.06 * gauss())) as f32))
            .collect();
        let frame_of = |rgb: Vec<[f32; 3]>, se: Option<Vec<[f32; 3]>>| Frame {
            image: Image {
                width: n,
                height: 1,
                rgb,
                transparency: vec![0.5; n],
            },
            std_error: se,
            luma_error: None,
        };
        let truth = frame_of(
            noisy,
            Some(exact.iter().map(|&y| [(0.06 * y) as f32; 3]).collect()),
        );
        let off = frame_of(
            exact
                .iter()
                .enumerate()
                .map(|(i, &y)| [(y * if i % 2 == 0 { 1.05 } else { 0.95 }) as f32; 3])
                .collect(),
            None,
        );
        let right = frame_of(exact.iter().map(|&y| [y as f32; 3]).collect(), None);
        let (r, _) = compare(&truth, &off, Pixels::Volume).unwrap();
        let (r0, _) = compare(&truth, &right, Pixels::Volume).unwrap();
        eprintln!(
            "5 % off: debiased rms {:.4}, resolved {:.3}; exact: debiased rms {:.4}",
            r.debiased_rms, r.resolved, r0.debiased_rms
        );
        // The 3σ rule (σ_Y 4.5 % of Y from three channels at 6 %) calls 97 % of the pixels
        // exact, and the median error 0.
        assert!(r.resolved > 0.95 && r.median_rel_error == 0.0, "{r:?}");
        // Relative to the mean luminance: the model's rms is 5 % of √(mean y²)/mean y.
        let mean = exact.iter().sum::<f64>() / n as f64;
        let want = 0.05 * (exact.iter().map(|y| y * y).sum::<f64>() / n as f64).sqrt() / mean;
        eprintln!("want {want:.4}");
        // Sampling error of the debiased variance at n pixels, σ_Y² √(2/n): about 2·10⁻⁴ on
        // the 5 % and a floor of σ_Y (2/n)^{1/4} ≈ 3.4·10⁻³ where the model is exact.
        assert!(
            (r.debiased_rms - want).abs() < 1e-3,
            "{} vs {want}",
            r.debiased_rms
        );
        assert!(r0.debiased_rms < 3.5e-3, "{}", r0.debiased_rms);
    }
}
