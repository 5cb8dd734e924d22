//! Spectral → RGB: which wavelengths a bake computes and how much each one
//! contributes to the linear sRGB channels R, G and B.
//!
//! # Spectral mode
//! `count` wavelengths at the midpoints of equal intervals of [min, max] (31 over 400–700 nm by
//! default: 404.8, 414.5, … nm). Wavelength j stands for its whole interval; the first and last
//! intervals also take the colour-matching tails below `min` and above `max` (to 360 and
//! 830 nm), whose light is scattered much like the end wavelengths'.
//!
//! Channel c's weight of wavelength j is the integral, over j's interval at the 1 nm spacing of
//! the CIE table, of
//!
//!   E(λ) · max(0, r̄_c(λ)),   r̄_c = row c of M_709 · (x̄, ȳ, z̄),
//!
//! with E the ASTM G173-03 extraterrestrial solar spectrum (sunlight before any atmosphere: the
//! renderer's sky model attenuates it), x̄ȳz̄ the CIE 1931 2° observer, and M_709 the XYZ →
//! linear sRGB/Rec.709 (D65 white) matrix of IEC 61966-2-1. Weights are normalized to sum to
//! 1 per channel: the tables are per-channel distributions, the colour of the sun is the
//! renderer's.
//!
//! # The negative lobes
//! Spectral colours lie outside the sRGB gamut, so each r̄_c is negative somewhere (r̄_R most,
//! around 440–540 nm). A channel table is a mixture of per-wavelength phase functions with these
//! weights; a negative weight would make it negative at angles where one wavelength's rainbow
//! or corona ring sits and another's does not. The lobes are therefore dropped, each channel
//! becoming a non-negative band-pass, and the dropped share ∫E·max(0, −r̄_c) / ∫E·max(0, r̄_c)
//! is reported with the weights ([`ChannelWeights::negative_lobe_fraction`]) and in the
//! manifest's channel definitions.
//!
//! # Mode `rgb3`
//! Riley et al. 2004's three wavelengths, 650, 515 and 440 nm for R, G, B, each channel its own
//! wavelength with weight 1.

use std::sync::OnceLock;

use thiserror::Error;

const CMF_CSV: &str = include_str!("../data/color/cie1931_2deg_cmf.csv");
const SOLAR_CSV: &str = include_str!("../data/color/solar_astm_g173_extraterrestrial.csv");
const D65_CSV: &str = include_str!("../data/color/cie_d65.csv");

/// XYZ → linear sRGB (Rec.709 primaries, D65 white), IEC 61966-2-1:1999 Eq. (F.7)
/// (the standard's four-decimal matrix).
pub const XYZ_TO_LINEAR_SRGB: [[f64; 3]; 3] = [
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
];

/// Riley et al. 2004's wavelengths for R, G, B (nm).
pub const RGB3_WAVELENGTHS_NM: [f64; 3] = [650.0, 515.0, 440.0];

/// Wavelength range of the colour-matching table (nm); spectral modes must lie inside it.
pub const CMF_RANGE_NM: (f64, f64) = (360.0, 830.0);

/// Which wavelengths a bake samples (serialized as `{"mode": "rgb3"}` or
/// `{"mode": "spectral", "count": …, "min_nm": …, "max_nm": …}`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "mode", rename_all = "lowercase")]
pub enum SpectralMode {
    /// Riley et al. 2004's three wavelengths, 650/515/440 nm, one per channel.
    Rgb3,
    /// `count` interval midpoints over [min_nm, max_nm], mixed to RGB with CIE × solar weights.
    Spectral {
        /// Number of wavelengths, [3, 1000].
        count: usize,
        /// Lower end of the range (nm), ≥ 360.
        min_nm: f64,
        /// Upper end of the range (nm), ≤ 830.
        max_nm: f64,
    },
}

/// A spectral mode that cannot be turned into channel weights.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SpectralError {
    /// The wavelength count is outside [3, 1000].
    #[error("wavelength count {0} is out of range: need 3 ≤ count ≤ 1000")]
    Count(usize),
    /// The range is not within the CIE table [360, 830] nm with min < max.
    #[error(
        "wavelength range [{min}, {max}] nm is invalid: need {} ≤ min < max ≤ {} nm",
        CMF_RANGE_NM.0,
        CMF_RANGE_NM.1
    )]
    Range {
        /// Lower end given, nm.
        min: f64,
        /// Upper end given, nm.
        max: f64,
    },
    /// A channel gets no positive weight from the sampled wavelengths.
    #[error(
        "channel {channel} has no positive weight over [{min}, {max}] nm with {count} wavelengths"
    )]
    EmptyChannel {
        /// The channel: "R", "G" or "B".
        channel: &'static str,
        /// Lower end of the range, nm.
        min: f64,
        /// Upper end of the range, nm.
        max: f64,
        /// Number of wavelengths.
        count: usize,
    },
}

/// The wavelengths of a bake and each channel's normalized weights over them.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelWeights {
    /// The spectral mode these weights were built for.
    pub mode: SpectralMode,
    /// The wavelengths to compute (nm).
    pub wavelengths_nm: Vec<f64>,
    /// weights[c][j] ≥ 0, Σ_j weights[c][j] = 1: channel c's share of wavelength j.
    pub weights: [Vec<f64>; 3],
    /// Per channel, the dropped negative lobe relative to the kept positive part (0 for rgb3).
    pub negative_lobe_fraction: [f64; 3],
}

impl ChannelWeights {
    /// Wavelengths and normalized channel weights of `mode`, or why they cannot be built.
    pub fn new(mode: &SpectralMode) -> Result<Self, SpectralError> {
        match *mode {
            SpectralMode::Rgb3 => Ok(Self {
                mode: *mode,
                wavelengths_nm: RGB3_WAVELENGTHS_NM.to_vec(),
                weights: [
                    vec![1.0, 0.0, 0.0],
                    vec![0.0, 1.0, 0.0],
                    vec![0.0, 0.0, 1.0],
                ],
                negative_lobe_fraction: [0.0; 3],
            }),
            SpectralMode::Spectral {
                count,
                min_nm,
                max_nm,
            } => spectral_weights(count, min_nm, max_nm),
        }
    }
}

/// The embedded colour tables, parsed once.
struct Tables {
    /// (λ, x̄, ȳ, z̄) at 1 nm, 360–830 nm.
    cmf: Vec<[f64; 4]>,
    /// (λ, E) of the ASTM G173 extraterrestrial column.
    solar: Vec<(f64, f64)>,
    /// (λ, S) of D65 at 5 nm.
    d65: Vec<(f64, f64)>,
}

fn tables() -> &'static Tables {
    static TABLES: OnceLock<Tables> = OnceLock::new();
    TABLES.get_or_init(|| {
        let cmf = parse_csv(CMF_CSV, 4)
            .into_iter()
            .map(|r| [r[0], r[1], r[2], r[3]])
            .collect();
        let solar = parse_csv(SOLAR_CSV, 2)
            .into_iter()
            .map(|r| (r[0], r[1]))
            .collect();
        let d65 = parse_csv(D65_CSV, 2)
            .into_iter()
            .map(|r| (r[0], r[1]))
            .collect();
        Tables { cmf, solar, d65 }
    })
}

/// Numeric rows of an embedded CSV (comment lines `#` and the header skipped), first `columns`
/// columns. The files are part of the build, so a malformed one is a bug: it panics.
fn parse_csv(text: &str, columns: usize) -> Vec<Vec<f64>> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .skip(1)
        .map(|l| {
            l.split(',')
                .take(columns)
                .map(|s| {
                    s.trim()
                        .parse::<f64>()
                        .unwrap_or_else(|_| panic!("embedded colour table: bad number in {l:?}"))
                })
                .collect()
        })
        .collect()
}

/// Linear interpolation in a table sorted by its first coordinate.
fn interpolate(table: &[(f64, f64)], x: f64) -> f64 {
    let i = table.partition_point(|&(t, _)| t <= x);
    if i == 0 {
        return table[0].1;
    }
    if i == table.len() {
        return table[table.len() - 1].1;
    }
    let (x0, y0) = table[i - 1];
    let (x1, y1) = table[i];
    y0 + (y1 - y0) * (x - x0) / (x1 - x0)
}

/// r̄_c(λ) = row c of M_709 · (x̄, ȳ, z̄).
fn srgb_matching(xyz: [f64; 3]) -> [f64; 3] {
    XYZ_TO_LINEAR_SRGB.map(|row| row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2])
}

fn spectral_weights(count: usize, min: f64, max: f64) -> Result<ChannelWeights, SpectralError> {
    if !(3..=1000).contains(&count) {
        return Err(SpectralError::Count(count));
    }
    if !(min.is_finite() && max.is_finite() && CMF_RANGE_NM.0 <= min && min < max)
        || max > CMF_RANGE_NM.1
    {
        return Err(SpectralError::Range { min, max });
    }
    let t = tables();
    let step = (max - min) / count as f64;
    let wavelengths_nm: Vec<f64> = (0..count).map(|j| min + (j as f64 + 0.5) * step).collect();
    let mut weights = [vec![0.0; count], vec![0.0; count], vec![0.0; count]];
    let mut negative = [0.0; 3];
    for &[lambda, x, y, z] in &t.cmf {
        // Interval of wavelength j; the ends take the tails. A 1 nm sample on an interval
        // boundary is split evenly between the two intervals.
        let pos = ((lambda - min) / step).clamp(0.0, count as f64);
        let (j_lo, j_hi) = if pos.fract() == 0.0 && pos > 0.0 && pos < count as f64 {
            (pos as usize - 1, pos as usize)
        } else {
            let j = (pos.floor() as usize).min(count - 1);
            (j, j)
        };
        let e = interpolate(&t.solar, lambda);
        for (c, r) in srgb_matching([x, y, z]).into_iter().enumerate() {
            let w = e * r;
            if w > 0.0 {
                weights[c][j_lo] += 0.5 * w;
                weights[c][j_hi] += 0.5 * w;
            } else {
                negative[c] -= w;
            }
        }
    }
    let mut negative_lobe_fraction = [0.0; 3];
    for c in 0..3 {
        let total: f64 = weights[c].iter().sum();
        if total <= 0.0 {
            return Err(SpectralError::EmptyChannel {
                channel: ["R", "G", "B"][c],
                min,
                max,
                count,
            });
        }
        weights[c].iter_mut().for_each(|w| *w /= total);
        negative_lobe_fraction[c] = negative[c] / total;
    }
    Ok(ChannelWeights {
        mode: SpectralMode::Spectral {
            count,
            min_nm: min,
            max_nm: max,
        },
        wavelengths_nm,
        weights,
        negative_lobe_fraction,
    })
}

/// Linear sRGB of a spectrum S(λ) under the CIE 1931 observer, Σ over the 1 nm table (no
/// clipping): the colorimetric check of the data files and the matrix (D65 → R = G = B).
pub fn linear_srgb_of(spectrum: impl Fn(f64) -> f64) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for &[lambda, x, y, z] in &tables().cmf {
        let s = spectrum(lambda);
        xyz[0] += s * x;
        xyz[1] += s * y;
        xyz[2] += s * z;
    }
    srgb_matching(xyz)
}

/// The CIE D65 relative spectral power at λ (nm), linearly interpolated from the 5 nm table.
pub fn d65(lambda_nm: f64) -> f64 {
    interpolate(&tables().d65, lambda_nm)
}

/// The ASTM G173-03 extraterrestrial solar irradiance at λ (W m⁻² nm⁻¹), interpolated.
pub fn solar_extraterrestrial(lambda_nm: f64) -> f64 {
    interpolate(&tables().solar, lambda_nm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn d65_is_white_in_linear_srgb() {
        let rgb = linear_srgb_of(d65);
        let mean = (rgb[0] + rgb[1] + rgb[2]) / 3.0;
        for c in rgb {
            // The four-decimal matrix and 5 nm interpolated D65 give white to a few 1e-4.
            assert!((c / mean - 1.0).abs() < 2e-3, "{rgb:?}");
        }
    }

    #[test]
    fn spectral_weights_are_normalized_band_passes() {
        let w = ChannelWeights::new(&SpectralMode::Spectral {
            count: 31,
            min_nm: 400.0,
            max_nm: 700.0,
        })
        .unwrap();
        assert_eq!(w.wavelengths_nm.len(), 31);
        assert!((w.wavelengths_nm[0] - 404.83870967741933).abs() < 1e-9);
        let centroid = |c: usize| -> f64 {
            w.weights[c]
                .iter()
                .zip(&w.wavelengths_nm)
                .map(|(a, l)| a * l)
                .sum()
        };
        for c in 0..3 {
            let sum: f64 = w.weights[c].iter().sum();
            assert!((sum - 1.0).abs() < 1e-12);
            assert!(w.weights[c].iter().all(|&x| x >= 0.0));
        }
        // Red above green above blue, near the sRGB primaries' dominant wavelengths.
        let (r, g, b) = (centroid(0), centroid(1), centroid(2));
        assert!(r > 590.0 && r < 640.0, "R centroid {r}");
        assert!(g > 510.0 && g < 560.0, "G centroid {g}");
        assert!(b > 430.0 && b < 480.0, "B centroid {b}");
        // r̄ has the big negative lobe.
        assert!(w.negative_lobe_fraction[0] > w.negative_lobe_fraction[2]);
    }

    #[test]
    fn bad_modes_name_the_range() {
        let e = ChannelWeights::new(&SpectralMode::Spectral {
            count: 31,
            min_nm: 300.0,
            max_nm: 700.0,
        })
        .unwrap_err();
        assert!(e.to_string().contains("360"), "{e}");
        let e = ChannelWeights::new(&SpectralMode::Spectral {
            count: 2,
            min_nm: 400.0,
            max_nm: 700.0,
        })
        .unwrap_err();
        assert!(e.to_string().contains("3 ≤ count"), "{e}");
    }
}
