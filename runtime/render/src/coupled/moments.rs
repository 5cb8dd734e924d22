//! The phase function's moments the `coupled` model splits and scatters by: the Legendre
//! moments χ_l of the tables' Ams_1 integrated exactly over each bin, δ-M's forward peak
//! f = χ_{L+1} (or f = g² with the diffusion alone), and the δ-M-reduced moments χ′_l of a
//! mixture of fields (docs/physics.md §7.10).

use runtime::FieldTable;

use super::{Diffuse, Settings};
use crate::lighting::lattice::asymmetry;
use crate::lighting::transport;

/// A per-field quantity `value(f)` of the mixture at densities `rho`, per channel, weighted by
/// scattering as the phase functions are ([`runtime::sample::scattering_weighted`]; 0 where
/// nothing scatters).
pub(super) fn mixed(
    fields: &[&FieldTable],
    rho: &[f64],
    value: impl Fn(usize) -> [f64; 3],
) -> [f64; 3] {
    runtime::sample::scattering_weighted(fields, rho, 0.0, value)
}

/// Each field's asymmetry parameter g per channel.
pub(super) fn asymmetries(fields: &[&FieldTable]) -> Vec<[f64; 3]> {
    fields.iter().map(|f| asymmetry(f)).collect()
}

/// Each field's forward peak f per channel, the share of its scattering the split treats as
/// unscattered: δ-M's χ_{L+1} (Wiscombe 1977; `chis`, the fields' Legendre moments) with the
/// transport, δ-Eddington's g² (Joseph, Wiscombe & Weinman 1976) with the diffusion alone.
pub(super) fn peaks(
    fields: &[&FieldTable],
    chis: &[Moments],
    settings: &Settings,
) -> Vec<[f64; 3]> {
    if settings.diffuse == Diffuse::Transport {
        return chis.iter().map(|m| m[transport::DEGREE + 1]).collect();
    }
    asymmetries(fields)
        .into_iter()
        .map(|g| g.map(|g| g * g))
        .collect()
}

/// A field's Legendre moments χ_0 … χ_{L+1} per channel, ∫ p P_l dΩ / ∫ p dΩ, with each of
/// Ams_1's samples the phase function's mean over its bin θ_k ± Δθ/2 (as the tables are baked
/// and the truth's sampler reads them), integrated exactly over the bin:
/// W_lk = ∫_bin k P_l dμ ([`grid::legendre::BinIntegrals`], the integrals the bake's transforms
/// use). A forward peak the bins do not resolve is the
/// first sample's mass, its bin's solid angle π(Δθ/2)² times the sample: integrating the
/// samples linearly interpolated instead gave it 4/3 of that (rain's δ 0.54 of the
/// scattering against the bins' 0.47, and δ-M's f = χ_5 0.63 against 0.57).
pub(crate) fn legendre_moments(field: &FieldTable, theta_step_deg: f64) -> Moments {
    const TOP: usize = transport::DEGREE + 2;
    let grid = grid::ThetaGrid::new(theta_step_deg).expect("tables' Δθ was checked at load");
    let bins = grid.len().min(field.image.angle_count());
    // W_lk = ∫_bin k P_l dμ, one degree at a time (grid::legendre, as the bake's transforms).
    let mut w = grid::legendre::BinIntegrals::new(&grid);
    let mut sums = [[0.0; 3]; TOP];
    for (l, s) in sums.iter_mut().enumerate() {
        if l > 0 {
            w.advance();
        }
        for (k, wk) in w.values()[..bins].iter().enumerate() {
            for c in 0..3 {
                s[c] += field.image.ams[[c, 0, k]] * wk;
            }
        }
    }
    let total = sums[0];
    sums.map(|s| std::array::from_fn(|c| s[c] / total[c]))
}

/// The δ-M-reduced phase function's moments χ′_l = Σ β_sca(χ_l − f)/Σ β_sca(1 − f) of the
/// mixture at densities `rho`, per channel.
pub(super) fn reduced_moments(
    fields: &[&FieldTable],
    rho: &[f64],
    chis: &[Moments],
    peaks: &[[f64; 3]],
) -> [[f64; transport::DEGREE + 1]; 3] {
    let den = mixed(fields, rho, |k| peaks[k].map(|f| 1.0 - f));
    let mut out = [[0.0; transport::DEGREE + 1]; 3];
    for l in 0..=transport::DEGREE {
        let num = mixed(fields, rho, |k| {
            std::array::from_fn(|c| chis[k][l][c] - peaks[k][c])
        });
        for c in 0..3 {
            out[c][l] = if den[c] > 0.0 { num[c] / den[c] } else { 0.0 };
        }
    }
    out
}

/// A field's Legendre moments χ_0 … χ_{L+1} per channel.
pub(super) type Moments = [[f64; 3]; transport::DEGREE + 2];

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;

    #[test]
    fn a_peak_in_the_first_bin_holds_its_bins_share_of_the_moments() {
        // Half the scattering in a forward δ the 0.18° bins do not resolve (the first bin's
        // mean), half isotropic: χ_l = 1/2 for every l ≥ 1, as the truth's bins read it. The
        // samples linearly interpolated gave the δ 4/3 of its bin's mass (χ_l = 4/7).
        let first_bin = 2.0 * PI * (1.0 - 0.09f64.to_radians().cos());
        let field = super::super::peak::tests::field(|t| {
            if t == 0.0 {
                0.5 / first_bin
            } else {
                0.5 / (4.0 * PI)
            }
        });
        let chi = legendre_moments(&field, 0.18);
        for (l, c) in chi.iter().enumerate() {
            let expect = if l == 0 { 1.0 } else { 0.5 };
            // Measured: 4.8·10⁻⁶ at l = 5 (P_l over the first bin, and the isotropic half's share
            // of it).
            assert!((c[1] - expect).abs() < 1e-5, "χ_{l} = {}", c[1]);
        }
    }
}
