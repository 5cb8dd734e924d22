//! Henyey–Greenstein lobes as a field's given phase function (`kind = "hg"`): the lobe an
//! engine uses (one term, or two) baked through the same tables as the droplets and crystals, so
//! that the two can be rendered side by side (docs/physics.md, "Given phase functions").
//!
//! p_HG(μ; g) = (1 − g²) / (4π (1 + g² − 2gμ)^{3/2}) per sr (Henyey & Greenstein 1941, Eq. 4,
//! normalized to 1 over the sphere); its Legendre coefficients are χ_l = g^l, so its n-fold
//! self-convolution has χ_l = g^{ln}. A two-term lobe is w p_HG(g) + (1 − w) p_HG(g2). Each
//! value may be given per channel (R, G, B) where the scene samples one wavelength per channel
//! (`rgb3`).
//!
//! The bins are exact: the average of p_HG over μ ∈ [μ_lo, μ_hi] is, from the antiderivative
//! (1 − g²)/(4πg) (1 + g² − 2gμ)^{−1/2},
//!
//! p̄ = (1 − g²) / (2π √a √b (√a + √b)),  a = 1 + g² − 2gμ_hi, b = 1 + g² − 2gμ_lo,
//!
//! written without the 1/g that cancels (so g = 0 gives 1/4π), and with a = (1 − g)² + 2g(1 − μ)
//! from 1 − μ = 2 sin²(θ/2), which keeps the forward bins of g → 1 accurate.

use serde::{Deserialize, Serialize};

use crate::grid::ThetaGrid;
use crate::phase::{GivenOrigin, Origin, PhaseFunction};

/// A one- or two-term Henyey–Greenstein lobe: `weight` p_HG(`g`) + (1 − `weight`) p_HG(`g2`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HgLobe {
    /// The first lobe's asymmetry parameter, (−1, 1).
    pub g: f64,
    /// The second lobe's asymmetry parameter, (−1, 1) (unused when `weight` is 1).
    pub g2: f64,
    /// The first lobe's share, (0, 1]; 1 for a one-term lobe.
    pub weight: f64,
}

/// A `kind = "hg"` field: its lobe and its optics per channel (R, G, B; the same three where
/// the scene gave one value for all).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HgField {
    /// The phase function per channel.
    pub lobes: [HgLobe; 3],
    /// Extinction cross-section per particle (m²) per channel.
    pub extinction_m2: [f64; 3],
}

impl HgLobe {
    /// A one-term lobe.
    pub fn one(g: f64) -> Self {
        Self {
            g,
            g2: 0.0,
            weight: 1.0,
        }
    }

    /// ⟨cos θ⟩ = w g + (1 − w) g2.
    pub fn asymmetry(&self) -> f64 {
        self.weight * self.g + (1.0 - self.weight) * self.g2
    }

    /// The Legendre coefficient χ_l = w g^l + (1 − w) g2^l (χ_0 = 1).
    pub fn legendre(&self, l: i32) -> f64 {
        self.weight * self.g.powi(l) + (1.0 - self.weight) * self.g2.powi(l)
    }

    /// p (1/sr) at scattering-angle cosine `mu`.
    pub fn value(&self, mu: f64) -> f64 {
        let one = |g: f64| {
            (1.0 - g * g) / (4.0 * std::f64::consts::PI * (1.0 + g * g - 2.0 * g * mu).powf(1.5))
        };
        self.weight * one(self.g) + (1.0 - self.weight) * one(self.g2)
    }

    /// The average of p (1/sr) over each bin of `grid`, exact to rounding.
    pub fn bins(&self, grid: &ThetaGrid) -> Vec<f64> {
        // 1 − μ at each edge, from 2 sin²(θ/2): no cancellation near the forward pole.
        let v: Vec<f64> = grid
            .edge_theta_rad()
            .iter()
            .map(|t| 2.0 * (0.5 * t).sin().powi(2))
            .collect();
        let average = |g: f64, k: usize| {
            let a = (1.0 - g).powi(2) + 2.0 * g * v[k];
            let b = (1.0 - g).powi(2) + 2.0 * g * v[k + 1];
            let (ra, rb) = (a.sqrt(), b.sqrt());
            (1.0 - g * g) / (2.0 * std::f64::consts::PI * ra * rb * (ra + rb))
        };
        (0..grid.len())
            .map(|k| {
                let first = self.weight * average(self.g, k);
                if self.weight < 1.0 {
                    first + (1.0 - self.weight) * average(self.g2, k)
                } else {
                    first
                }
            })
            .collect()
    }
}

impl HgField {
    /// The field's optics of `channel` (0, 1, 2: R, G, B) at `wavelength_nm` on `grid`; the lobe
    /// scatters all it removes (albedo 1: a field's given albedo replaces it, as any field's).
    pub fn phase(&self, channel: usize, wavelength_nm: f64, grid: ThetaGrid) -> PhaseFunction {
        let lobe = self.lobes[channel];
        PhaseFunction::given(
            wavelength_nm,
            self.extinction_m2[channel],
            (lobe.asymmetry(), lobe.bins(&grid), grid),
            Origin::Given(GivenOrigin { hg: lobe }),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Σ_k p̄_k Ω_k = 1 and the bins' ⟨cos θ⟩ is g, for lobes up to g = 0.99 and backward ones.
    #[test]
    fn bins_are_normalized_and_keep_the_asymmetry() {
        for step in [0.18, 1.0] {
            let grid = ThetaGrid::new(step).unwrap();
            let omega = grid.bin_solid_angles();
            let widths = grid.bin_mu_widths();
            for lobe in [
                HgLobe::one(0.0),
                HgLobe::one(0.85),
                HgLobe::one(0.99),
                HgLobe::one(-0.6),
                HgLobe {
                    g: 0.9,
                    g2: -0.3,
                    weight: 0.8,
                },
            ] {
                let bins = lobe.bins(&grid);
                let total: f64 = bins.iter().zip(&omega).map(|(p, o)| p * o).sum();
                assert!(
                    (total - 1.0).abs() < 1e-12,
                    "{lobe:?} Δθ {step}: Σ = {total}"
                );
                // ⟨μ⟩ by each bin's mean μ (its energy-weighted cosine differs by O(Δθ²)).
                let mut mu_hi = 1.0;
                let mut mean = 0.0;
                for (p, (o, w)) in bins.iter().zip(omega.iter().zip(&widths)) {
                    mean += p * o * (mu_hi - 0.5 * w);
                    mu_hi -= w;
                }
                let tol = if step < 0.5 { 1e-4 } else { 2e-3 };
                assert!(
                    (mean - lobe.asymmetry()).abs() < tol,
                    "{lobe:?} Δθ {step}: ⟨μ⟩ {mean} vs g {}",
                    lobe.asymmetry()
                );
            }
        }
    }

    /// Away from the forward peak a bin's average is the point value at its centre to O(Δθ²).
    #[test]
    fn bins_approach_the_point_values() {
        let grid = ThetaGrid::new(0.18).unwrap();
        let lobe = HgLobe::one(0.85);
        let bins = lobe.bins(&grid);
        for k in [50, 200, 500, 999] {
            let mu = grid.theta_deg(k).to_radians().cos();
            let rel = bins[k] / lobe.value(mu) - 1.0;
            assert!(rel.abs() < 1e-4, "θ {}°: {rel:e}", grid.theta_deg(k));
        }
    }
}
