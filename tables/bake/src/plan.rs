//! The plan of a bake: plain data decided before any work starts (scene, output directory,
//! preset and the node counts it stands for).

use std::path::PathBuf;

use serde::Serialize;

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
    /// Heat-kernel blur of the j ≥ 2 Ams terms, in bins.
    pub blur_bins: f64,
    /// Geometric-optics rays per wavelength for ice and snow.
    pub rays: u64,
}

impl Quality {
    /// The node counts of this preset.
    pub fn knobs(self) -> Knobs {
        let (sizes, nodes_per_panel, rays) = match self {
            Quality::Draft => (32, 2, 40_000),
            Quality::Standard => (400, 2, 600_000),
            Quality::Reference => (4096, 2, 6_000_000),
        };
        Knobs {
            sizes,
            nodes_per_panel,
            tail_mass: 1e-3,
            blur_bins: 0.5,
            rays,
        }
    }
}

impl Knobs {
    /// The size nodes wavelength j of `j_len` uses: joint sampling of size and wavelength, each
    /// wavelength's nodes shifted by (j + ½)/J of a step in ln r, so a channel that mixes J
    /// wavelengths sees J·sizes distinct radii.
    pub fn size_quadrature(
        &self,
        distribution: &mie::SizeDistribution,
        j: usize,
        j_len: usize,
    ) -> mie::SizeQuadrature {
        let shift = (j as f64 + 0.5) / j_len as f64;
        distribution.quadrature_shifted(self.sizes, self.tail_mass, shift)
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
    /// A bake at `quality`'s preset knobs.
    pub fn for_preset(scene: Scene, out_dir: PathBuf, quality: Quality) -> Self {
        Self {
            scene,
            out_dir,
            quality,
            knobs: quality.knobs(),
            prune: true,
        }
    }
}
