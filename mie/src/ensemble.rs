//! Size-averaged ("bulk") optics of a sphere population at one or more wavelengths.
//!
//! For each wavelength λ and quadrature node r_i (number fraction w_i):
//!   σ_ext = Σ w_i Q_ext,i π r_i²,  σ_sca likewise,  albedo = σ_sca/σ_ext,
//!   g = Σ w_i σ_sca,i g_i / σ_sca,
//!   p̄(θ) = Σ w_i σ_sca,i p_i(θ) / σ_sca = Σ w_i (|S1|²+|S2|²)_i / (2 k² σ_sca),  k = 2π/λ
//! (intensities are averaged, not normalized phase functions; docs/physics.md §2 and §6).
//! The result is one [`PhaseFunction`] per wavelength: bin averages on a [`ThetaGrid`], integrated
//! inside each bin with Gauss nodes (see [`crate::grid`]).
//!
//! # Node counts
//! Two counts set the cost: sizes (nodes in ln r) and Gauss nodes per angular panel. With
//! [`NodeCounts::Adaptive`] the size count doubles, then the nodes per panel double, until one
//! doubling changes the result by less than the tolerance (rms relative change of the bins at
//! θ ≥ 1°, and relative change of σ_ext and g); [`NodeCounts::Fixed`] runs one pass for timing.
//! Bins near the forward direction (θ < 60/x_min rad, where diffraction rings of single sizes are
//! still coherent) are cut into panels of width ≤ π/x_max so the diffraction peak is resolved.

use num_complex::Complex64;
use rayon::prelude::*;

use crate::amplitude::{FoldedAngles, SphereTerms, weighted_intensity, weighted_intensity_halves};
use crate::distribution::{SizeDistribution, SizeQuadrature};
use crate::error::MieError;
use crate::grid::{BinQuadrature, ThetaGrid, bin_quadrature};
use crate::phase::{MieOrigin, Origin, PhaseFunction};
use crate::refractive::Material;
use crate::sphere::Sphere;

/// How many quadrature nodes to use.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NodeCounts {
    /// Refine until one doubling changes the result by less than `tolerance`.
    Adaptive {
        /// Relative change per doubling accepted (rms of bins at θ ≥ 1°; σ_ext; g).
        tolerance: f64,
        /// Most size nodes allowed before the refinement gives up with `NotConverged`.
        max_sizes: usize,
    },
    /// Exactly these counts.
    Fixed {
        /// Size nodes in ln r.
        sizes: usize,
        /// Gauss nodes per angular panel.
        nodes_per_panel: usize,
    },
}

/// What to compute.
#[derive(Debug, Clone, PartialEq)]
pub struct BulkRequest {
    /// Particle material.
    pub material: Material,
    /// Temperature, °C (water only: −12…99; ignored for ice).
    pub temperature_c: f64,
    /// Size distribution of the spheres.
    pub distribution: SizeDistribution,
    /// Vacuum wavelengths λ, nm (not empty).
    pub wavelengths_nm: Vec<f64>,
    /// Angular bins of the output phase functions.
    pub grid: ThetaGrid,
    /// Size and angular quadrature node counts.
    pub nodes: NodeCounts,
    /// Mass fraction left outside the truncated size range.
    pub tail_mass: f64,
    /// Cosines at which point values of p̄ are wanted besides the bins (may be empty).
    pub point_cosines: Vec<f64>,
}

/// Computes the bulk optics for every requested wavelength (in the given order).
pub fn bulk_phase(request: &BulkRequest) -> Result<Vec<PhaseFunction>, MieError> {
    if request.wavelengths_nm.is_empty() {
        return Err(MieError::Empty("wavelength list"));
    }
    let distribution = request.distribution.validated()?;
    if !(request.tail_mass > 0.0 && request.tail_mass < 0.5) {
        return Err(MieError::OutOfRange {
            name: "tail mass fraction",
            value: request.tail_mass,
            range: "(0, 0.5)",
        });
    }
    let indices: Vec<Complex64> = request
        .wavelengths_nm
        .iter()
        .map(|&l| request.material.refractive_index(l, request.temperature_c))
        .collect::<Result<_, _>>()?;
    request
        .wavelengths_nm
        .iter()
        .zip(indices)
        .map(|(&lambda, m)| {
            let one = |sizes: usize, nodes: usize| {
                let q = distribution.quadrature(sizes, request.tail_mass);
                bulk_at(m, lambda, &q, request.grid, nodes, &request.point_cosines)
            };
            match request.nodes {
                NodeCounts::Fixed {
                    sizes,
                    nodes_per_panel,
                } => one(sizes, nodes_per_panel),
                NodeCounts::Adaptive {
                    tolerance,
                    max_sizes,
                } => adaptive(&one, &distribution, tolerance, max_sizes),
            }
        })
        .collect()
}

/// Doubles sizes, then nodes per panel, until a doubling changes the result by < tolerance.
fn adaptive(
    one: &dyn Fn(usize, usize) -> Result<PhaseFunction, MieError>,
    distribution: &SizeDistribution,
    tolerance: f64,
    max_sizes: usize,
) -> Result<PhaseFunction, MieError> {
    let mono = matches!(distribution, SizeDistribution::Monodisperse { .. });
    let (mut sizes, mut nodes) = (if mono { 1 } else { 32 }, 2);
    let mut current = one(sizes, nodes)?;
    if !mono {
        loop {
            let next = one(2 * sizes, nodes)?;
            let change = relative_change(&current, &next);
            sizes *= 2;
            current = with_last_change(next, change);
            if change < tolerance {
                break;
            }
            if 2 * sizes > max_sizes {
                return Err(MieError::NotConverged {
                    what: "size quadrature",
                    tolerance,
                    last_change: change,
                });
            }
        }
    }
    loop {
        let next = one(sizes, 2 * nodes)?;
        let change = relative_change(&current, &next);
        nodes *= 2;
        current = with_last_change(next, change.max(last_change(&current)));
        if change < tolerance {
            return Ok(current);
        }
        if nodes >= 64 {
            return Err(MieError::NotConverged {
                what: "angular quadrature inside bins",
                tolerance,
                last_change: change,
            });
        }
    }
}

fn last_change(p: &PhaseFunction) -> f64 {
    p.mie().map_or(0.0, |m| m.last_change)
}

fn with_last_change(mut p: PhaseFunction, change: f64) -> PhaseFunction {
    if let Origin::Mie(m) = &mut p.origin {
        m.last_change = change;
    }
    p
}

/// rms relative change of bins at θ ≥ 1°, or of σ_ext and g, whichever is largest.
pub fn relative_change(a: &PhaseFunction, b: &PhaseFunction) -> f64 {
    let first = (1.0 / a.grid.step_deg()).ceil() as usize;
    let (mut sum, mut count) = (0.0, 0usize);
    for k in first.min(a.bins.len())..a.bins.len() {
        let r = (b.bins[k] - a.bins[k]) / b.bins[k].abs().max(f64::MIN_POSITIVE);
        sum += r * r;
        count += 1;
    }
    let rms = if count > 0 {
        (sum / count as f64).sqrt()
    } else {
        0.0
    };
    rms.max(((b.sigma_ext_m2 - a.sigma_ext_m2) / b.sigma_ext_m2).abs())
        .max((b.g - a.g).abs())
}

/// The size-averaged phase function p̄ (1/sr) of spheres of index `m` at vacuum wavelength
/// `wavelength_nm` over the size nodes `sizes`, at the (folded) angles `angles` only — no bins:
/// p̄ = Σ_i w_i (|S1|² + |S2|²)_i / (2 k² σ_sca), σ_sca = Σ_i w_i Q_sca,i π r_i², k = 2π/λ.
pub fn mean_phase_at(
    m: Complex64,
    wavelength_nm: f64,
    sizes: &SizeQuadrature,
    angles: &FoldedAngles,
) -> Result<Vec<f64>, MieError> {
    let k = 2.0 * std::f64::consts::PI / (wavelength_nm / 1000.0);
    let per_size: Vec<(SphereTerms, f64)> = sizes
        .radius_um
        .par_iter()
        .map(|&r| -> Result<_, MieError> {
            let c = Sphere::new(m, k * r)?.coefficients();
            let q_sca = c.efficiencies().q_sca;
            Ok((SphereTerms::new(&c), q_sca * std::f64::consts::PI * r * r))
        })
        .collect::<Result<_, _>>()?;
    let sigma_sca: f64 = per_size
        .iter()
        .zip(&sizes.weight)
        .map(|((_, s), w)| s * w)
        .sum();
    let terms: Vec<SphereTerms> = per_size.into_iter().map(|(t, _)| t).collect();
    let intensity = weighted_intensity(&terms, &sizes.weight, angles);
    Ok(intensity
        .iter()
        .map(|i| i / (2.0 * k * k * sigma_sca))
        .collect())
}

/// Sizes whose Mie coefficients are held at once by [`bulk_at`] (64 raindrops at x ≈ 2e4 hold
/// ~50 MB).
const SIZE_CHUNK: usize = 64;

/// One pass at fixed node counts.
pub fn bulk_at(
    m: Complex64,
    wavelength_nm: f64,
    sizes: &SizeQuadrature,
    grid: ThetaGrid,
    nodes_per_panel: usize,
    point_cosines: &[f64],
) -> Result<PhaseFunction, MieError> {
    bulk_with_spread(
        m,
        wavelength_nm,
        sizes,
        grid,
        nodes_per_panel,
        point_cosines,
    )
    .map(|(p, _)| p)
}

/// [`bulk_at`] and the standard error of each bin from the size sampling, estimated from the
/// two interleaved half-sets of the nodes (even and odd indices, each a lattice of half the
/// step): with A and B the halves' phase functions and p = α A + (1 − α) B their combination
/// (α the even half's share of σ_sca), SE = |A − B| √((α² + (1 − α)²)/2), the spread of two
/// estimates taken as independent. The phase function is the same sum as [`bulk_at`]'s, the
/// sizes' terms accumulated in two halves.
pub fn bulk_with_spread(
    m: Complex64,
    wavelength_nm: f64,
    sizes: &SizeQuadrature,
    grid: ThetaGrid,
    nodes_per_panel: usize,
    point_cosines: &[f64],
) -> Result<(PhaseFunction, Vec<f64>), MieError> {
    let wavelength_um = wavelength_nm / 1000.0;
    let k = 2.0 * std::f64::consts::PI / wavelength_um;
    let spheres: Vec<Sphere> = sizes
        .radius_um
        .iter()
        .map(|&r| Sphere::new(m, k * r))
        .collect::<Result<_, _>>()?;
    let quadrature = forward_resolving_quadrature(&spheres, &grid, nodes_per_panel);
    let sums = SizeSums::over(&spheres, sizes, &quadrature, point_cosines);
    let scale = 1.0 / (2.0 * k * k * sums.sigma_sca);
    let node_phase: Vec<f64> = sums.halves[0]
        .iter()
        .zip(&sums.halves[1])
        .map(|(a, b)| (a + b) * scale)
        .collect();
    let bins = quadrature.average(&node_phase);
    let std_error = half_spread(&sums, &quadrature, k, bins.len());
    let points: Vec<f64> = sums.point_intensity.iter().map(|i| i * scale).collect();
    const UM2_TO_M2: f64 = 1e-12;
    let mut phase = PhaseFunction {
        wavelength_nm,
        m_re: m.re,
        m_im: m.im,
        sigma_ext_m2: sums.sigma_ext * UM2_TO_M2,
        sigma_sca_m2: sums.sigma_sca * UM2_TO_M2,
        albedo: sums.sigma_sca / sums.sigma_ext,
        g: sums.g_sca / sums.sigma_sca,
        grid,
        bins,
        forward_delta_fraction: 0.0,
        points,
        origin: Origin::Mie(MieOrigin {
            energy_closure: 0.0,
            sizes: sizes.radius_um.len(),
            nodes_per_panel,
            last_change: 0.0,
        }),
    };
    let closure = phase.integral() - 1.0;
    if let Origin::Mie(m) = &mut phase.origin {
        m.energy_closure = closure;
    }
    Ok((phase, std_error))
}

/// The Gauss nodes inside the bins for these spheres: bins near the forward and backward
/// directions (within 60/x_min rad, where single sizes' diffraction rings are still coherent)
/// cut into panels of width ≤ π/x_max, the others one panel each (module docs).
fn forward_resolving_quadrature(
    spheres: &[Sphere],
    grid: &ThetaGrid,
    nodes_per_panel: usize,
) -> BinQuadrature {
    let x_min = spheres.iter().map(|s| s.x()).fold(f64::INFINITY, f64::min);
    let x_max = spheres.iter().map(|s| s.x()).fold(0.0, f64::max);
    let step_rad = grid.step_deg().to_radians();
    let forward_panels = (step_rad * x_max / std::f64::consts::PI).ceil().max(1.0) as usize;
    let forward_limit_deg = (60.0 / x_min).to_degrees();
    bin_quadrature(grid, nodes_per_panel, |kbin| {
        let (lo, _) = grid.bin_edges_deg(kbin);
        if lo < forward_limit_deg || 180.0 - grid.bin_edges_deg(kbin).1 < forward_limit_deg {
            forward_panels
        } else {
            1
        }
    })
}

/// The weighted sums over the sizes that [`bulk_with_spread`] needs (cross-sections in µm²).
struct SizeSums {
    /// Σ w σ_ext.
    sigma_ext: f64,
    /// Σ w σ_sca.
    sigma_sca: f64,
    /// Σ w σ_sca g.
    g_sca: f64,
    /// Per half (even, odd node index): Σ w I at each angular node.
    halves: [Vec<f64>; 2],
    /// Per half: Σ w σ_sca.
    half_sca: [f64; 2],
    /// Σ w I at each point angle.
    point_intensity: Vec<f64>,
}

impl SizeSums {
    /// The sums over `spheres` (radii and weights `sizes`) at the quadrature's nodes and the
    /// point cosines. Sizes go in fixed chunks, so memory stays bounded (a chunk's
    /// coefficients, not all sizes') and the summation order does not depend on the thread
    /// count.
    fn over(
        spheres: &[Sphere],
        sizes: &SizeQuadrature,
        quadrature: &BinQuadrature,
        point_cosines: &[f64],
    ) -> Self {
        let node_angles = FoldedAngles::new(&quadrature.mu);
        let point_angles = FoldedAngles::new(point_cosines);
        let mut sums = Self {
            sigma_ext: 0.0,
            sigma_sca: 0.0,
            g_sca: 0.0,
            halves: [
                vec![0.0; quadrature.mu.len()],
                vec![0.0; quadrature.mu.len()],
            ],
            half_sca: [0.0; 2],
            point_intensity: vec![0.0; point_cosines.len()],
        };
        for (chunk, (radii, weights)) in spheres.chunks(SIZE_CHUNK).zip(
            sizes
                .radius_um
                .chunks(SIZE_CHUNK)
                .zip(sizes.weight.chunks(SIZE_CHUNK)),
        ) {
            // Coefficients and efficiencies per size, in parallel; order is preserved.
            let per_size: Vec<(SphereTerms, f64, f64, f64)> = chunk
                .par_iter()
                .zip(radii.par_iter())
                .map(|(s, &r)| {
                    let c = s.coefficients();
                    let e = c.efficiencies();
                    let area = std::f64::consts::PI * r * r;
                    (SphereTerms::new(&c), e.q_ext * area, e.q_sca * area, e.g)
                })
                .collect();
            for (i, ((_, ext, sca, g), w)) in per_size.iter().zip(weights).enumerate() {
                sums.sigma_ext += w * ext;
                sums.sigma_sca += w * sca;
                sums.g_sca += w * sca * g;
                sums.half_sca[i % 2] += w * sca;
            }
            let terms: Vec<SphereTerms> = per_size.into_iter().map(|(t, ..)| t).collect();
            if !point_cosines.is_empty() {
                for (acc, v) in sums.point_intensity.iter_mut().zip(weighted_intensity(
                    &terms,
                    weights,
                    &point_angles,
                )) {
                    *acc += v;
                }
            }
            // SIZE_CHUNK is even, so a size's parity within its chunk is its parity overall.
            for (acc, half) in
                sums.halves
                    .iter_mut()
                    .zip(weighted_intensity_halves(&terms, weights, &node_angles))
            {
                for (a, v) in acc.iter_mut().zip(half) {
                    *a += v;
                }
            }
        }
        sums
    }
}

/// The standard error of each of the `bin_count` bins from the spread of the two halves' own
/// phase functions (each half's terms over its σ_sca; [`bulk_with_spread`]).
fn half_spread(sums: &SizeSums, quadrature: &BinQuadrature, k: f64, bin_count: usize) -> Vec<f64> {
    let half_bins: Vec<Vec<f64>> = (0..2)
        .map(|h| {
            if sums.half_sca[h] > 0.0 {
                let s = 1.0 / (2.0 * k * k * sums.half_sca[h]);
                quadrature.average(&sums.halves[h].iter().map(|i| i * s).collect::<Vec<_>>())
            } else {
                vec![f64::NAN; bin_count]
            }
        })
        .collect();
    let alpha = sums.half_sca[0] / sums.sigma_sca;
    let factor = ((alpha * alpha + (1.0 - alpha) * (1.0 - alpha)) / 2.0).sqrt();
    half_bins[0]
        .iter()
        .zip(&half_bins[1])
        .map(|(a, b)| (a - b).abs() * factor)
        .collect()
}
