//! The plan of a bake: plain data decided before any work starts (scene, output directory,
//! preset and the node counts it stands for).

use std::path::PathBuf;

use serde::Serialize;

use tables::spectral::{ChannelWeights, SpectralMode};

use crate::scene::{Quality, Scene};

/// Node counts a preset stands for (chosen from the measured trade, docs/accuracy.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Knobs {
    /// Sizes per wavelength (nodes in ln r; shifted per wavelength for joint sampling).
    pub sizes: usize,
    /// Gauss nodes per angular panel inside each bin.
    pub nodes_per_panel: usize,
    /// Mass fraction left outside the truncated size range.
    pub tail_mass: f64,
    /// What Q is between its bins in the j ≥ 2 Ams terms (`tables::ams` module docs).
    pub reconstruction: tables::ams::Reconstruction,
    /// Geometric-optics rays per wavelength for ice and snow: the first round (shared among the
    /// wavelengths as [`crate::bake::ray_allocation`] does), carried on until `crystal_noise`.
    pub rays: u64,
    /// The rms relative standard error over θ ≥ 1° (rough crystals: 1°–179°,
    /// `mie::crystal::noise_skips_pole`) the crystal tables' channels are traced to
    /// (each wavelength j to crystal_noise / √m_j, m_j its largest channel weight, so that a
    /// channel's Σ_j a_j² s_j² stays below crystal_noise²); 0: `rays` alone.
    pub crystal_noise: f64,
    /// The rms relative standard error over θ ≥ 1° of Ams_1 the drops' channels are sized for
    /// (`crate::bake::drop_sizes`: a pilot wavelength at a quarter of `sizes` predicts the
    /// count, at most 4 × `sizes`); 0: `sizes` alone.
    pub size_noise: f64,
    /// Seed of the crystal tracer's random streams and of the drops' size nodes (0 for the
    /// presets): bakes with different seeds are independent estimates, whose difference
    /// measures their noise.
    pub seed: u64,
    /// How the crystal tracer draws its rays: pseudo-random (the presets) or scrambled Sobol'
    /// (`mie::crystal::trace` docs; measured by `photometeor tradeoff`).
    pub ray_sampling: mie::crystal::Sampling,
    /// Whether the tracer's directions cover only the prism's fundamental domain.
    pub ray_symmetric: bool,
    /// Tilts scored per facet a path first meets in distorted crystals (snow): each the
    /// transmitted part's own estimate, at a fraction of a path's cost (`mie::crystal::trace`
    /// docs, "Tilt splitting"; 4 measured best, docs/accuracy.md).
    pub tilt_splits: u32,
    /// Rays per chunk of the crystal tracer (`mie::crystal::Rays::chunk_rays`): each
    /// wavelength takes two chunks at least, which at 31 wavelengths and 16 384 rays was a
    /// draft's floor (1 M rays of snow for a 4 % target that 0.4 M reach), and each round
    /// rounds every wavelength up to whole chunks. Draft at 4 096 / 2 048 / 1 024 rays: snow
    /// traced 475 k / 395 k / 366 k rays (self-estimate 3.8 / 4.1 / 4.3 % for 4.5 % asked, user
    /// CPU 2.3 / 1.8–1.9 / 1.7–1.8 s), ice 2.22 / 2.18 / 2.15 M; seed pairs of snow (1°–179°)
    /// 4.00 / 4.26 / 4.77 %: 2 048 kept.
    pub chunk_rays: u64,
}

/// The spectral mode the presets' per-wavelength counts are stated for: the default scene's 31
/// wavelengths over 400–700 nm.
pub const PRESET_SPECTRUM: SpectralMode = SpectralMode::Spectral {
    count: 31,
    min_nm: 400.0,
    max_nm: 700.0,
};

/// The worst channel's sampling noise, as the variance factor max_c Σ_j a_cj² / n_j, of a mode
/// whose wavelength j gets `share(weights, j)` samples per unit of a knob (a_cj the channel
/// weights; each wavelength an independent estimate).
pub(crate) fn channel_noise(
    weights: &ChannelWeights,
    share: impl Fn(&ChannelWeights, usize) -> f64,
) -> f64 {
    (0..3)
        .map(|c| {
            weights.weights[c]
                .iter()
                .enumerate()
                .filter(|(_, a)| **a > 0.0)
                .map(|(j, a)| a * a / share(weights, j))
                .sum::<f64>()
        })
        .fold(0.0, f64::max)
}

/// Drops: every wavelength the same number of sizes.
fn size_share(_: &ChannelWeights, _: usize) -> f64 {
    1.0
}

impl Quality {
    /// The node counts of this preset for a scene of `spectrum`: those of [`Quality::knobs`]
    /// (stated for [`PRESET_SPECTRUM`]) with the sizes scaled so that the worst channel's
    /// sampling noise is the same whatever the spectral mode. A channel of `rgb3` is one
    /// wavelength, where a channel of the 31-wavelength mode averages the independent estimates
    /// of about ten, so `rgb3` takes about eight times the sizes per wavelength (and less time
    /// for its three wavelengths than the 31 take). Crystals need no scaling: their noise
    /// target is per channel already.
    pub fn knobs_for(self, spectrum: &SpectralMode) -> Knobs {
        let base = self.knobs();
        let (Ok(reference), Ok(scene)) = (
            ChannelWeights::new(&PRESET_SPECTRUM),
            ChannelWeights::new(spectrum),
        ) else {
            return base;
        };
        let scale = |share: fn(&ChannelWeights, usize) -> f64, count: f64| {
            let factor = channel_noise(&scene, share) / channel_noise(&reference, share);
            (count * factor).ceil().max(1.0)
        };
        Knobs {
            sizes: scale(size_share, base.sizes as f64) as usize,
            ..base
        }
    }

    /// The node counts of this preset for [`PRESET_SPECTRUM`].
    pub fn knobs(self) -> Knobs {
        // Crystals: a first round of rays, then traced on to the noise target (docs/accuracy.md).
        // Drops: sized for their noise target from a pilot (docs/accuracy.md); the reference's
        // sizes fixed.
        let (sizes, nodes_per_panel, rays, crystal_noise, size_noise, chunk_rays) = match self {
            Quality::Draft => (32, 2, 8_192, 0.045, 0.035, 2_048),
            Quality::Standard => (400, 2, 131_072, 0.009, 0.008, 16_384),
            Quality::Reference => (4096, 2, 524_288, 0.0035, 0.0, 16_384),
        };
        Knobs {
            sizes,
            nodes_per_panel,
            tail_mass: 1e-3,
            reconstruction: tables::ams::Reconstruction::Spline,
            rays,
            crystal_noise,
            size_noise,
            seed: 0,
            ray_sampling: mie::crystal::Sampling::Random,
            ray_symmetric: false,
            tilt_splits: 4,
            chunk_rays,
        }
    }
}

impl Knobs {
    /// The size nodes wavelength j of `j_len` uses: equal steps of the cross-section-weighted
    /// distribution (`SizeDistribution::quadrature_by_area`; docs/accuracy.md "Mie sizes"),
    /// each wavelength's nodes shifted by (j + ½)/J of a step (plus the seed's fraction). The shift itself buys nothing
    /// measurable (docs/accuracy.md, "Mie sizes": the wavelengths' size parameters differ at
    /// the same radii already); the seed's offset rides on it.
    pub fn size_quadrature(
        &self,
        distribution: &mie::SizeDistribution,
        j: usize,
        j_len: usize,
    ) -> mie::SizeQuadrature {
        // Another seed moves every wavelength's nodes by a golden-ratio fraction of a step: an
        // independent set of radii (seed 0: the presets' own).
        let golden = 0.618_033_988_749_894_9 * self.seed as f64;
        let shift = ((j as f64 + 0.5) / j_len as f64 + golden).fract();
        distribution.quadrature_by_area(self.sizes, self.tail_mass, shift)
    }
}

/// Everything a bake does, decided before any work starts.
#[derive(Debug, Clone)]
pub struct BakePlan {
    /// The validated scene.
    pub scene: Scene,
    /// The bake directory (created if missing).
    pub out_dir: PathBuf,
    /// The preset the knobs came from (recorded in the manifest).
    pub quality: Quality,
    /// The node counts.
    pub knobs: Knobs,
    /// Whether fields a previous bake in `out_dir` has and this scene lacks are removed (true:
    /// `photometeor bake`, the directory holds exactly the scene), or kept in the manifest and
    /// on disk (false: `photometeor render`, which bakes only the fields its volumes use).
    pub prune: bool,
}

impl BakePlan {
    /// A bake at `quality`'s preset knobs for the scene's spectral mode
    /// ([`Quality::knobs_for`]).
    pub fn for_preset(scene: Scene, out_dir: PathBuf, quality: Quality) -> Self {
        let knobs = quality.knobs_for(&scene.spectral);
        Self {
            scene,
            out_dir,
            quality,
            knobs,
            prune: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knobs_scale_with_the_wavelengths_a_channel_mixes() {
        for q in [Quality::Draft, Quality::Standard, Quality::Reference] {
            assert_eq!(q.knobs_for(&PRESET_SPECTRUM), q.knobs(), "{q:?}");
        }
        let reference = ChannelWeights::new(&PRESET_SPECTRUM).unwrap();
        for mode in [
            SpectralMode::Rgb3,
            SpectralMode::Spectral {
                count: 8,
                min_nm: 400.0,
                max_nm: 700.0,
            },
            SpectralMode::Spectral {
                count: 61,
                min_nm: 400.0,
                max_nm: 700.0,
            },
        ] {
            let weights = ChannelWeights::new(&mode).unwrap();
            let (base, k) = (
                Quality::Standard.knobs(),
                Quality::Standard.knobs_for(&mode),
            );
            // The worst channel's noise variance per size equal to the preset's own.
            let drops = channel_noise(&weights, size_share) / k.sizes as f64;
            let want = channel_noise(&reference, size_share) / base.sizes as f64;
            eprintln!(
                "{mode:?}: {} sizes per wavelength (preset {})",
                k.sizes, base.sizes
            );
            assert!(drops <= want && drops > want * (1.0 - 1.0 / k.sizes as f64));
            // Crystals: the noise target is per channel already.
            assert_eq!((k.rays, k.crystal_noise), (base.rays, base.crystal_noise));
        }
        // rgb3: one wavelength per channel, so many more nodes per wavelength.
        assert!(Quality::Standard.knobs_for(&SpectralMode::Rgb3).sizes > 4 * 400);
    }
}
