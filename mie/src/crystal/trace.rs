//! Monte Carlo geometric-optics ray tracing through one randomly oriented prism (module docs of
//! [`crate::crystal`] give the model).

use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::{RngCore, SeedableRng};
use rayon::prelude::*;

use glam::DVec3;

use super::geometry::{Prism, basis};
use crate::grid::ThetaGrid;

/// Rays per chunk: each chunk has its own random stream, and chunks are summed in order, so the
/// result does not depend on the thread count.
const CHUNK_RAYS: u64 = 1 << 14;

/// How to trace.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TraceSettings {
    /// Rays that hit the crystal (misses are drawn again and counted for the projected area).
    pub rays: u64,
    /// Seed of the random streams; chunk c uses its own stream derived from it.
    pub seed: u64,
    /// Macke's distortion δ ∈ [0, 1]: every ray meets its own distorted crystal, each facet
    /// normal tilted by an angle uniform in [0, δ·90°] about a uniform azimuth. 0 = pristine.
    pub roughness: f64,
    /// A path stops after this many interactions; its weight is reported as lost.
    pub max_interactions: u32,
    /// A path stops when its weight falls below this; its weight is reported as lost.
    pub min_weight: f64,
}

impl TraceSettings {
    /// Settings with at most 1000 interactions per path and a weight cut-off of 1e-7.
    pub fn new(rays: u64, seed: u64, roughness: f64) -> Self {
        Self {
            rays,
            seed,
            roughness,
            max_interactions: 1000,
            min_weight: 1e-7,
        }
    }
}

/// Energy bookkeeping and the angular distribution of the geometric-optics part.
/// Fractions are of the energy of the rays that hit the crystal.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TraceResult {
    /// Bin width of the θ grid, degrees.
    pub theta_step_deg: f64,
    /// Energy fraction scattered into bin k (delta transmission excluded).
    pub bin_energy: Vec<f64>,
    /// Standard error of each bin_energy, from the spread between chunks.
    pub bin_energy_std_error: Vec<f64>,
    /// Energy leaving exactly forward (through parallel faces): never inside a bin.
    pub delta: f64,
    /// Energy reflected at the first (external) interaction.
    pub external_reflection: f64,
    /// Energy absorbed inside the crystal.
    pub absorbed: f64,
    /// Energy of paths stopped by `max_interactions` or `min_weight`.
    pub lost: f64,
    /// Asymmetry parameter of the scattered geometric-optics light (delta included, cos θ = 1).
    pub g: f64,
    /// Standard error of g, from the spread between chunks (NaN with one chunk).
    pub g_std_error: f64,
    /// Rays that hit the crystal.
    pub rays_hit: u64,
    /// Rays cast in all, misses included.
    pub rays_cast: u64,
    /// Mean projected area from the hit fraction: π R² hits / cast (same unit² as the prism).
    pub projected_area: f64,
}

impl TraceResult {
    /// Energy scattered in all (bins + delta).
    pub fn scattered(&self) -> f64 {
        self.bin_energy.iter().sum::<f64>() + self.delta
    }
}

#[derive(Clone)]
struct Tally {
    bins: Vec<f64>,
    delta: f64,
    external: f64,
    absorbed: f64,
    lost: f64,
    cos_sum: f64,
    hits: u64,
    cast: u64,
}

impl Tally {
    fn new(k: usize) -> Self {
        Self {
            bins: vec![0.0; k],
            delta: 0.0,
            external: 0.0,
            absorbed: 0.0,
            lost: 0.0,
            cos_sum: 0.0,
            hits: 0,
            cast: 0,
        }
    }
}

struct Rng(Xoshiro256PlusPlus);

impl Rng {
    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.0.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// Unpolarized Fresnel reflectance for cos of incidence `cos_i`, relative index η = n1/n2;
/// 1 for total internal reflection. Returns (R, cos_t).
fn fresnel(cos_i: f64, eta: f64) -> (f64, f64) {
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return (1.0, 0.0);
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    (0.5 * (rs * rs + rp * rp), cos_t)
}

/// The facet normals of one distorted crystal: each face's outward normal tilted by an angle
/// uniform in [0, δ·90°] about a uniform azimuth (the true normals when δ = 0).
fn distorted_normals(rng: &mut Rng, prism: &Prism, roughness: f64) -> [DVec3; 8] {
    let mut normals = prism.faces.map(|f| f.normal);
    if roughness > 0.0 {
        for n in normals.iter_mut() {
            let (e1, e2) = basis(*n);
            let tilt = roughness * std::f64::consts::FRAC_PI_2 * rng.uniform();
            let phi = 2.0 * std::f64::consts::PI * rng.uniform();
            let (s, c) = tilt.sin_cos();
            *n = c * *n + s * phi.cos() * e1 + s * phi.sin() * e2;
        }
    }
    normals
}

/// The normal an entering ray meets at a facet (outward normal `tilted`, true normal
/// `true_normal`): the tilted one, or the true one where the ray would meet the tilted facet
/// from behind.
fn entry_normal(tilted: DVec3, true_normal: DVec3, d: DVec3) -> DVec3 {
    if d.dot(tilted) < 0.0 {
        tilted
    } else {
        true_normal
    }
}

/// Traces `settings.rays` rays through `prism` (refractive index `n_re`, absorption coefficient
/// `alpha` per unit length of the prism's unit) in random orientation, tallying on `grid`.
pub fn trace(
    prism: &Prism,
    n_re: f64,
    alpha: f64,
    grid: ThetaGrid,
    settings: TraceSettings,
) -> TraceResult {
    let k_len = grid.len();
    let step = grid.step_deg();
    let chunks = settings.rays.div_ceil(CHUNK_RAYS).max(1);
    let tallies: Vec<Tally> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let rays = CHUNK_RAYS.min(settings.rays - c * CHUNK_RAYS);
            let seed = settings
                .seed
                .wrapping_add((c + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let mut rng = Rng(Xoshiro256PlusPlus::seed_from_u64(seed));
            let mut tally = Tally::new(k_len);
            for _ in 0..rays {
                trace_one(prism, n_re, alpha, step, settings, &mut rng, &mut tally);
            }
            tally
        })
        .collect();

    let hits: u64 = tallies.iter().map(|t| t.hits).sum();
    let cast: u64 = tallies.iter().map(|t| t.cast).sum();
    let total = hits as f64;
    let mut bin_energy = vec![0.0; k_len];
    let mut sum = Tally::new(0);
    for t in &tallies {
        for (a, b) in bin_energy.iter_mut().zip(&t.bins) {
            *a += b;
        }
        sum.delta += t.delta;
        sum.external += t.external;
        sum.absorbed += t.absorbed;
        sum.lost += t.lost;
        sum.cos_sum += t.cos_sum;
    }
    bin_energy.iter_mut().for_each(|b| *b /= total);
    let scattered = bin_energy.iter().sum::<f64>() + sum.delta / total;
    let g = sum.cos_sum / total / scattered;
    // Standard errors from the chunk-to-chunk spread of per-ray means (chunks weighted by rays).
    let (bin_energy_std_error, g_std_error) = if tallies.len() > 1 {
        let m = tallies.len() as f64;
        let per_chunk = |t: &Tally, f: &dyn Fn(&Tally) -> f64| f(t) / t.hits.max(1) as f64;
        let se = |f: &dyn Fn(&Tally) -> f64, mean: f64| -> f64 {
            let var: f64 = tallies
                .iter()
                .map(|t| (per_chunk(t, f) - mean).powi(2))
                .sum::<f64>()
                / (m - 1.0);
            (var / m).sqrt()
        };
        let bins_se = (0..k_len)
            .map(|k| se(&|t: &Tally| t.bins[k], bin_energy[k]))
            .collect();
        let g_se = se(&|t: &Tally| t.cos_sum, sum.cos_sum / total) / scattered;
        (bins_se, g_se)
    } else {
        (vec![f64::NAN; k_len], f64::NAN)
    };
    let r = prism.bounding_radius();
    TraceResult {
        theta_step_deg: step,
        bin_energy,
        bin_energy_std_error,
        delta: sum.delta / total,
        external_reflection: sum.external / total,
        absorbed: sum.absorbed / total,
        lost: sum.lost / total,
        g,
        g_std_error,
        rays_hit: hits,
        rays_cast: cast,
        projected_area: std::f64::consts::PI * r * r * hits as f64 / cast as f64,
    }
}

/// Bin of the table grid holding scattering angle θ (degrees).
fn bin_of(theta_deg: f64, step: f64, k_len: usize) -> usize {
    ((theta_deg / step + 0.5).floor() as usize).min(k_len - 1)
}

fn emit(tally: &mut Tally, d_in: DVec3, d_out: DVec3, w: f64, step: f64) {
    let c = d_in.dot(d_out).clamp(-1.0, 1.0);
    tally.cos_sum += w * c;
    if c > 1.0 - 1e-12 {
        tally.delta += w;
    } else {
        let k_len = tally.bins.len();
        tally.bins[bin_of(c.acos().to_degrees(), step, k_len)] += w;
    }
}

fn trace_one(
    prism: &Prism,
    n_re: f64,
    alpha: f64,
    step: f64,
    s: TraceSettings,
    rng: &mut Rng,
    tally: &mut Tally,
) {
    // A direction uniform on the sphere and an entry point uniform on the disc of radius R
    // across it: orientation averaging with projected-area weighting.
    let radius = prism.bounding_radius();
    let (d_in, mut p, face) = loop {
        let z = 1.0 - 2.0 * rng.uniform();
        let phi = 2.0 * std::f64::consts::PI * rng.uniform();
        let rho = (1.0 - z * z).max(0.0).sqrt();
        let d = DVec3::new(rho * phi.cos(), rho * phi.sin(), z);
        let (e1, e2) = basis(d);
        let r = radius * rng.uniform().sqrt();
        let psi = 2.0 * std::f64::consts::PI * rng.uniform();
        let start = -2.0 * radius * d + r * psi.cos() * e1 + r * psi.sin() * e2;
        tally.cast += 1;
        if let Some((t, f)) = prism.enter(start, d) {
            break (d, start + t * d, f);
        }
    };
    tally.hits += 1;
    let normals = distorted_normals(rng, prism, s.roughness);

    // External interaction.
    let eta_in = 1.0 / n_re;
    let m = entry_normal(normals[face], prism.faces[face].normal, d_in);
    let cos_i = -d_in.dot(m);
    let (refl, cos_t) = fresnel(cos_i, eta_in);
    let reflected = d_in + 2.0 * cos_i * m;
    emit(tally, d_in, reflected.normalize(), refl, step);
    tally.external += refl;
    let mut w = 1.0 - refl;
    let mut d = (eta_in * d_in + (eta_in * cos_i - cos_t) * m).normalize();

    // Internal path: at each face the transmitted part leaves, the reflected part goes on.
    let eta_out = n_re;
    for _ in 0..s.max_interactions {
        let (t, f) = prism.exit(p, d);
        p += t * d;
        if alpha > 0.0 {
            let kept = w * (-alpha * t).exp();
            tally.absorbed += w - kept;
            w = kept;
        }
        // Turned against the ray. A tilted surface facing back at the ray cannot be crossed:
        // total reflection about the true normal, which keeps the ray inside.
        let (m, cos_i, (refl, cos_t)) = if d.dot(normals[f]) > 0.0 {
            let cos_i = d.dot(normals[f]);
            (-normals[f], cos_i, fresnel(cos_i, eta_out))
        } else {
            let m = -prism.faces[f].normal;
            (m, -d.dot(m), (1.0, 0.0))
        };
        if refl < 1.0 {
            let out = (eta_out * d + (eta_out * cos_i - cos_t) * m).normalize();
            emit(tally, d_in, out, w * (1.0 - refl), step);
        }
        w *= refl;
        d = (d + 2.0 * cos_i * m).normalize();
        if w < s.min_weight {
            tally.lost += w;
            return;
        }
    }
    tally.lost += w;
}
