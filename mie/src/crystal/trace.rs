//! Monte Carlo geometric-optics ray tracing through one randomly oriented prism (module docs of
//! [`crate::crystal`] give the model).
//!
//! # Sampling
//! A ray is a point of the unit cube: dimensions 0–1 its incident direction, 2 whether the
//! direction is kept (with probability A(d)/A_max, so directions come in proportion to the
//! projected area A(d)), 3–6 its entry point (a face in proportion to its projected area, a
//! point uniform on it: uniform over the silhouette, as a point uniform on a disc across the
//! prism that hits would be, without the misses; 0.87 of the directions are kept for a column
//! of AR 2 where 0.47 of the disc's points hit), then the tilts of the facets (distorted
//! crystals). The points
//! come from [`Sampling::Random`] (independent pseudo-random numbers: plain Monte Carlo, error
//! ∝ N^{−1/2}) or [`Sampling::Sobol`] (randomized quasi-Monte Carlo: each chunk of rays an
//! independently Owen-scrambled Sobol' sequence, Burley 2020, so the chunks stay independent,
//! unbiased estimates and their spread still gives the standard errors). A direction not kept
//! takes the next point. With `symmetric` the directions cover
//! only the prism's fundamental domain, 1/24 of the sphere (z ≥ 0 and azimuth 0–30° between a
//! vertex and a face normal: the prism's 24 symmetries, D6h, map it onto the whole sphere, and
//! the facet tilts are drawn symmetrically), which gives the same distribution of scattering
//! angles and lets the quasi-random points fill a smaller domain.
//!
//! # Tilt splitting
//! A distorted crystal's rays differ most by the tilts of the facets they cross, and a plain
//! path draws one tilt per facet. With `tilt_splits` K > 1, where a ray meets a facet whose tilt
//! is not yet drawn (its entry facet, or a facet it first tries to leave by), K tilts are drawn
//! and the light that leaves the crystal there is scored for each, 1/K of it apiece (the
//! external reflection at entry, the transmitted part inside). The ray then carries on through
//! one of the K, chosen in proportion to the weight it carries on (transmittance at entry,
//! reflectance inside), which becomes the facet's tilt for the rest of the path, with the mean
//! of those weights. The expectation is the plain path's (the choice's probability cancels the
//! weight it carries), a ray's energy is kept exactly as in a plain path, and the angular
//! distribution of the leaving light is sampled K times for about the cost of K − 1 Fresnel
//! evaluations. Pristine crystals have no tilts and ignore K; with K = 1 the trace is the plain
//! one, bit for bit. Measured (`mie/examples/crystal_levers.rs`, snow AR 1, 2 mm, δ 0.7,
//! 2.1 M rays, one run): the rms relative standard error over θ ≥ 1° 3.73 % in 3.9 s with one
//! tilt, 2.60 % (5.1 s) with K = 2, 1.77 % (8.3 s) with 4, 1.35 % (13.2 s) with 8: variance per
//! unit of time 1.6×, 2.1× and 2.3× the plain path's.
//!
//! # Roulette
//! A path's weight falls by the reflectance at every partial reflection, and the light it
//! still carries after a few is small, yet each interaction costs as much as the first. Below
//! the roulette weight w_r a path goes on with probability w/w_r, weighing w_r, or stops: the
//! expectation is unchanged (no light is lost, where a cut-off dropped what it stopped), and the
//! trace spends its time on the paths that carry light. Measured (the fields of
//! `mie/examples/crystal_levers.rs`, 550 nm, 10⁶ rays, one seed, runs alternated; rms relative
//! standard error² × time over θ ≥ 1°, against the cut-off at 10⁻⁴ the tracer had): w_r = 0.01
//! 0.78–0.84 (ice column AR 2) / 0.82–0.94 (rough snow, tilts split 4 ways), 0.03 0.74–0.79 /
//! 0.78–0.82, 0.1 0.62–0.66 / 0.71–0.77, 0.3 0.58–0.63 / 0.71–0.73, and analog tracing (w_r =
//! 1: every path weighs 1) 0.91–1.01 / 1.19–1.30. 0.1 is kept: noise per ray +1.7 % (ice) and
//! +2.6 % (snow), time −37 % and −31 %; 0.3 gains little more for +7 % and +10 % noise per ray.
//! The energy the roulette adds and takes is tallied ([`TraceResult::roulette`]), so the
//! bookkeeping still closes exactly.

use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::{RngCore, SeedableRng};
use rayon::prelude::*;

use glam::DVec3;

use super::geometry::{Prism, basis, turn};
use crate::grid::ThetaGrid;

/// Rays per chunk by default: each chunk has its own random stream, and chunks are summed in
/// order, so the result does not depend on the thread count.
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
    /// Russian roulette (module docs, "Roulette"): a path whose weight w falls below this goes
    /// on with probability w / this, weighing this, or stops. 0 = never.
    pub roulette_weight: f64,
    /// How the rays' directions, entry points and tilts are drawn (module docs).
    pub sampling: Sampling,
    /// Directions only in the prism's fundamental domain (module docs).
    pub symmetric: bool,
    /// Tilts weighed where a ray meets a facet whose tilt is not yet drawn (distorted crystals;
    /// module docs, "Tilt splitting"), 1 to [`MAX_TILT_SPLITS`]. 1 = the plain path.
    pub tilt_splits: u32,
    /// Rays per chunk ([`Trace::CHUNK_RAYS`] by default): the unit of the random streams and of
    /// the spread the standard errors come from, so also the fewest rays a trace with standard
    /// errors (two chunks) can take.
    pub chunk_rays: u64,
}

/// How a trace draws its rays (module docs, "Sampling").
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sampling {
    /// Independent pseudo-random numbers (xoshiro256++ per chunk).
    Random,
    /// An Owen-scrambled Sobol' sequence per chunk (randomized quasi-Monte Carlo).
    Sobol,
}

impl TraceSettings {
    /// Settings with at most 1000 interactions per path and Russian roulette below weight 0.1,
    /// plain Monte Carlo over the whole sphere of directions.
    pub fn new(rays: u64, seed: u64, roughness: f64) -> Self {
        Self {
            rays,
            seed,
            roughness,
            max_interactions: 1000,
            roulette_weight: ROULETTE_WEIGHT,
            sampling: Sampling::Random,
            symmetric: false,
            tilt_splits: 1,
            chunk_rays: CHUNK_RAYS,
        }
    }

    /// These settings with chunks of `chunk_rays` rays (at least 1).
    pub fn chunked(self, chunk_rays: u64) -> Self {
        Self {
            chunk_rays: chunk_rays.max(1),
            ..self
        }
    }

    /// These settings with `sampling` and, if `symmetric`, directions in the fundamental domain.
    pub fn sampled(self, sampling: Sampling, symmetric: bool) -> Self {
        Self {
            sampling,
            symmetric,
            ..self
        }
    }

    /// These settings with `tilt_splits` tilts per facet a path first meets.
    pub fn split(self, tilt_splits: u32) -> Self {
        Self {
            tilt_splits,
            ..self
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
    /// Energy of paths stopped by `max_interactions`.
    pub lost: f64,
    /// Energy the roulette added (survivors raised to the roulette weight) less what it took
    /// (paths it stopped): zero in expectation, so that bins + delta + absorbed + lost =
    /// 1 + this, exactly.
    pub roulette: f64,
    /// Asymmetry parameter of the scattered geometric-optics light (delta included, cos θ = 1).
    pub g: f64,
    /// Standard error of g, from the spread between chunks (NaN with one chunk).
    pub g_std_error: f64,
    /// Rays that hit the crystal.
    pub rays_hit: u64,
    /// Directions drawn in all, those not kept (module docs, "Sampling") included.
    pub rays_cast: u64,
    /// Mean projected area from the fraction of directions kept: A_max hits / cast (same unit²
    /// as the prism).
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
    /// cos θ of the inner bin edges, falling: bin k holds cos θ in (edge[k], edge[k − 1]].
    edges: std::sync::Arc<Vec<f64>>,
    bins: Vec<f64>,
    delta: f64,
    external: f64,
    absorbed: f64,
    lost: f64,
    roulette: f64,
    cos_sum: f64,
    hits: u64,
    cast: u64,
}

impl Tally {
    fn new(edges: std::sync::Arc<Vec<f64>>) -> Self {
        Self {
            bins: vec![0.0; edges.len() + 1],
            edges,
            delta: 0.0,
            external: 0.0,
            absorbed: 0.0,
            lost: 0.0,
            roulette: 0.0,
            cos_sum: 0.0,
            hits: 0,
            cast: 0,
        }
    }
}

/// Sobol' points one scramble holds (sobol_burley's limit); past it a chunk takes the next
/// scramble.
const SOBOL_POINTS: u32 = 1 << 16;

/// The numbers a chunk's rays are made of (module docs, "Sampling").
struct Rng {
    random: Xoshiro256PlusPlus,
    sobol: Option<SobolPoint>,
}

/// The current point of a chunk's scrambled Sobol' sequence and the next dimension to read.
struct SobolPoint {
    chunk_seed: u64,
    scramble: u32,
    next_index: u64,
    index: u32,
    dim: u32,
}

impl Rng {
    fn new(sampling: Sampling, chunk_seed: u64) -> Self {
        let sobol = (sampling == Sampling::Sobol).then_some(SobolPoint {
            chunk_seed,
            scramble: 0,
            next_index: 0,
            index: 0,
            dim: 0,
        });
        Self {
            random: Xoshiro256PlusPlus::seed_from_u64(chunk_seed),
            sobol,
        }
    }

    /// Starts the next point: a new ray, or a new try after a miss.
    fn next_point(&mut self) {
        if let Some(p) = &mut self.sobol {
            let segment = p.next_index / SOBOL_POINTS as u64;
            // Each segment of 2^16 points its own scramble, derived from the chunk's seed.
            let mixed = p.chunk_seed ^ segment.wrapping_mul(0xD1B5_4A32_D192_ED03);
            p.scramble = (mixed ^ (mixed >> 32)) as u32;
            p.index = (p.next_index % SOBOL_POINTS as u64) as u32;
            p.next_index += 1;
            p.dim = 0;
        }
    }

    /// Uniform in [0, 1): the point's next dimension, or the next pseudo-random number.
    fn uniform(&mut self) -> f64 {
        match &mut self.sobol {
            Some(p) if p.dim < sobol_burley::NUM_DIMENSIONS => {
                let u = sobol_burley::sample(p.index, p.dim, p.scramble) as f64;
                p.dim += 1;
                u
            }
            // A point's dimensions beyond the Sobol' table (only many tilt splits reach them)
            // are pseudo-random.
            _ => (self.random.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64),
        }
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
    // r_s = a/b and r_p = c/e over one division.
    let (a, b) = (eta * cos_i - cos_t, eta * cos_i + cos_t);
    let (c, e) = (cos_i - eta * cos_t, cos_i + eta * cos_t);
    let inv = 1.0 / (b * e);
    let (rs, rp) = (a * e * inv, c * b * inv);
    (0.5 * (rs * rs + rp * rp), cos_t)
}

/// The facet normals of one distorted crystal: each face's outward normal tilted by an angle
/// uniform in [0, δ·90°] about a uniform azimuth (the true normals when δ = 0), each drawn when
/// the ray first meets its facet (a ray meets about half of them).
struct Facets<'a> {
    normals: [DVec3; 8],
    /// Two unit vectors across each true normal (`geometry::basis`), for drawing tilts.
    tangents: &'a [(DVec3, DVec3); 8],
    drawn: u8,
    roughness: f64,
}

impl<'a> Facets<'a> {
    fn new(prism: &Prism, tangents: &'a [(DVec3, DVec3); 8], roughness: f64) -> Self {
        Self {
            normals: prism.faces.map(|f| f.normal),
            tangents,
            drawn: if roughness > 0.0 { 0 } else { u8::MAX },
            roughness,
        }
    }

    /// Whether facet `f`'s tilt is still to be drawn.
    fn undrawn(&self, f: usize) -> bool {
        self.drawn & (1 << f) == 0
    }

    /// How many tilts of facet `f` a ray meeting it now weighs: `tilt_splits` (at most
    /// [`MAX_TILT_SPLITS`]) where its tilt is still to be drawn, else its one.
    fn splits(&self, f: usize, tilt_splits: u32) -> usize {
        if self.undrawn(f) {
            tilt_splits.clamp(1, MAX_TILT_SPLITS) as usize
        } else {
            1
        }
    }

    /// One of the `k` tilts of facet `f` a ray weighs: with one, the facet's own tilt (drawn
    /// and kept if it is the first); with more, a fresh draw, kept by [`Facets::keep`].
    fn tilt(&mut self, f: usize, k: usize, rng: &mut Rng) -> DVec3 {
        if k > 1 {
            return self.draw(f, rng);
        }
        if self.undrawn(f) {
            self.drawn |= 1 << f;
            self.normals[f] = self.draw(f, rng);
        }
        self.normals[f]
    }

    /// Facet `f`'s tilt from here on: tilt `j` of those weighed.
    fn keep(&mut self, f: usize, tilts: &[Tilt], j: usize) -> Tilt {
        self.drawn |= 1 << f;
        self.normals[f] = tilts[j].normal;
        tilts[j]
    }

    /// A fresh tilt of undrawn facet `f` (its true normal tilted).
    fn draw(&self, f: usize, rng: &mut Rng) -> DVec3 {
        let n = self.normals[f];
        let (e1, e2) = self.tangents[f];
        // A tilt uniform in [0, δ·90°] (δ/4 of a turn) about a uniform azimuth.
        let (c, s) = turn(0.25 * self.roughness * rng.uniform());
        let (cp, sp) = turn(rng.uniform());
        c * n + s * cp * e1 + s * sp * e2
    }
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
    let mut t = Trace::new(prism.clone(), n_re, alpha, grid, settings);
    t.run_to(settings.rays.div_ceil(settings.chunk_rays).max(1));
    t.result()
}

/// A trace that can be carried on: chunks of rays, each its own stream, added in order, so a
/// caller can trace until a statistic of the [`Trace::result`] is reached and the result is the
/// same for any thread count.
pub struct Trace {
    prism: Prism,
    n_re: f64,
    alpha: f64,
    grid: ThetaGrid,
    settings: TraceSettings,
    edges: std::sync::Arc<Vec<f64>>,
    tallies: Vec<Tally>,
}

impl Trace {
    /// A trace with no rays yet; `settings.rays` bounds the rays of the last chunk only (chunks
    /// beyond it are whole).
    pub fn new(
        prism: Prism,
        n_re: f64,
        alpha: f64,
        grid: ThetaGrid,
        settings: TraceSettings,
    ) -> Self {
        Self {
            prism,
            n_re,
            alpha,
            grid,
            settings,
            edges: std::sync::Arc::new(inner_edge_cosines(grid)),
            tallies: Vec::new(),
        }
    }

    /// Rays per chunk by default ([`TraceSettings::chunk_rays`]).
    pub const CHUNK_RAYS: u64 = CHUNK_RAYS;

    /// Rays per chunk of this trace.
    pub fn chunk_rays(&self) -> u64 {
        self.settings.chunk_rays
    }

    /// Chunks traced so far.
    pub fn chunks(&self) -> u64 {
        self.tallies.len() as u64
    }

    /// Traces chunks up to `chunks` in all (in parallel; chunk c its own stream).
    pub fn run_to(&mut self, chunks: u64) {
        let (prism, n_re, alpha, settings) = (&self.prism, self.n_re, self.alpha, self.settings);
        let edges = &self.edges;
        let max_area = prism.max_projected_area();
        let tangents = prism.faces.map(|f| basis(f.normal));
        let more: Vec<Tally> = (self.chunks()..chunks)
            .into_par_iter()
            .map(|c| {
                let chunk = settings.chunk_rays;
                let left = settings.rays.saturating_sub(c * chunk);
                let rays = if left == 0 { chunk } else { chunk.min(left) };
                let seed = settings
                    .seed
                    .wrapping_add((c + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                let mut rng = Rng::new(settings.sampling, seed);
                let mut tally = Tally::new(edges.clone());
                for _ in 0..rays {
                    trace_one(
                        prism, max_area, &tangents, n_re, alpha, settings, &mut rng, &mut tally,
                    );
                }
                tally
            })
            .collect();
        self.tallies.extend(more);
    }

    /// The tallies so far, summed in chunk order, with standard errors from the spread between
    /// chunks.
    pub fn result(&self) -> TraceResult {
        summarize(&self.prism, self.grid, &self.tallies)
    }
}

fn summarize(prism: &Prism, grid: ThetaGrid, tallies: &[Tally]) -> TraceResult {
    let k_len = grid.len();
    let step = grid.step_deg();
    let hits: u64 = tallies.iter().map(|t| t.hits).sum();
    let cast: u64 = tallies.iter().map(|t| t.cast).sum();
    let total = hits as f64;
    let mut bin_energy = vec![0.0; k_len];
    let mut sum = Tally::new(std::sync::Arc::new(Vec::new()));
    for t in tallies {
        for (a, b) in bin_energy.iter_mut().zip(&t.bins) {
            *a += b;
        }
        sum.delta += t.delta;
        sum.external += t.external;
        sum.absorbed += t.absorbed;
        sum.lost += t.lost;
        sum.roulette += t.roulette;
        sum.cos_sum += t.cos_sum;
    }
    bin_energy.iter_mut().for_each(|b| *b /= total);
    let scattered = bin_energy.iter().sum::<f64>() + sum.delta / total;
    let g = sum.cos_sum / total / scattered;
    // Standard errors from the chunk-to-chunk spread, chunks weighted by their rays: the
    // estimate is a ratio of totals, μ = Σ_c S_c / Σ_c n_c, whose variance is
    // m/(m − 1) Σ_c (S_c − n_c μ)² / (Σ_c n_c)² (S_c a chunk's total, n_c its rays that hit).
    // For equal chunks it is the spread of the chunks' means over √m; a short chunk (the last
    // of a round that is not a whole number of chunks) counts by its rays, where the unweighted
    // spread let its few rays' noisy mean inflate the error (a draft bake's ice 2.8-3.6 % for
    // a true 2.1 %).
    let (bin_energy_std_error, g_std_error) = if tallies.len() > 1 {
        let m = tallies.len() as f64;
        let se = |f: &dyn Fn(&Tally) -> f64, mean: f64| -> f64 {
            let spread: f64 = tallies
                .iter()
                .map(|t| (f(t) - t.hits as f64 * mean).powi(2))
                .sum();
            (m / (m - 1.0) * spread).sqrt() / total
        };
        let bins_se = (0..k_len)
            .map(|k| se(&|t: &Tally| t.bins[k], bin_energy[k]))
            .collect();
        let g_se = se(&|t: &Tally| t.cos_sum, sum.cos_sum / total) / scattered;
        (bins_se, g_se)
    } else {
        (vec![f64::NAN; k_len], f64::NAN)
    };
    TraceResult {
        theta_step_deg: step,
        bin_energy,
        bin_energy_std_error,
        delta: sum.delta / total,
        external_reflection: sum.external / total,
        absorbed: sum.absorbed / total,
        lost: sum.lost / total,
        roulette: sum.roulette / total,
        g,
        g_std_error,
        rays_hit: hits,
        rays_cast: cast,
        projected_area: prism.max_projected_area() * hits as f64 / cast as f64,
    }
}

/// cos θ of the K − 1 inner bin edges (k + ½)Δθ, falling with k.
fn inner_edge_cosines(grid: ThetaGrid) -> Vec<f64> {
    grid.edge_theta_rad()[1..grid.len()]
        .iter()
        .map(|t| t.cos())
        .collect()
}

/// Bin of the table grid holding cos θ = `c`: the number of inner edges whose cosine is ≥ c
/// (bin k is (k − ½)Δθ ≤ θ < (k + ½)Δθ), found from a first guess by the angle (a polynomial
/// acos good to 10⁻⁴ rad) and settled by comparing c with the edges' cosines: exact, without a
/// libm acos per exit.
fn bin_of(c: f64, edges: &[f64]) -> usize {
    // Bins per radian, a multiplication (the guess is settled exactly below).
    let per_rad = edges.len() as f64 * std::f64::consts::FRAC_1_PI;
    let mut k = ((fast_acos(c) * per_rad + 0.5) as usize).min(edges.len());
    while k > 0 && edges[k - 1] < c {
        k -= 1;
    }
    while k < edges.len() && edges[k] >= c {
        k += 1;
    }
    k
}

/// acos(x) to about 7·10⁻⁵ rad (Abramowitz & Stegun 4.4.45): a first guess only.
fn fast_acos(x: f64) -> f64 {
    let a = x.abs().min(1.0);
    let r =
        (1.0 - a).sqrt() * (1.570_728_8 + a * (-0.212_114_4 + a * (0.074_261_0 - 0.018_729_3 * a)));
    if x < 0.0 { std::f64::consts::PI - r } else { r }
}

fn emit(tally: &mut Tally, d_in: DVec3, d_out: DVec3, w: f64) {
    let c = d_in.dot(d_out).clamp(-1.0, 1.0);
    tally.cos_sum += w * c;
    if c > 1.0 - 1e-12 {
        tally.delta += w;
    } else {
        let k = bin_of(c, &tally.edges);
        tally.bins[k] += w;
    }
}

fn trace_one(
    prism: &Prism,
    max_area: f64,
    tangents: &[(DVec3, DVec3); 8],
    n_re: f64,
    alpha: f64,
    s: TraceSettings,
    rng: &mut Rng,
    tally: &mut Tally,
) {
    // A direction uniform on the sphere, kept with probability A(d)/A_max (so directions come
    // in proportion to the projected area, as orientation averaging weights them), and an entry
    // point uniform over the silhouette (Prism::entry_point): the distribution of a point
    // uniform on a disc across the prism, kept where it hits, without the misses.
    let (d_in, mut p, face) = loop {
        rng.next_point();
        let (z, turns) = if s.symmetric {
            // z ≥ 0, azimuth between a vertex (0°) and a face normal (30°).
            (rng.uniform(), rng.uniform() / 12.0)
        } else {
            (1.0 - 2.0 * rng.uniform(), rng.uniform())
        };
        let rho = (1.0 - z * z).max(0.0).sqrt();
        let (cos_phi, sin_phi) = turn(turns);
        let d = DVec3::new(rho * cos_phi, rho * sin_phi, z);
        tally.cast += 1;
        let (areas, total) = prism.entry_areas(d);
        if rng.uniform() * max_area >= total {
            continue;
        }
        let (u_face, u, v, w) = (rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform());
        let (p, f) = prism.entry_point(&areas, total, u_face, u, v, w);
        break (d, p, f);
    };
    tally.hits += 1;
    let mut facets = Facets::new(prism, tangents, s.roughness);
    // The share 1/K of each of K split tilts, once per ray rather than a division per exit.
    let split_share = 1.0 / s.tilt_splits.clamp(1, MAX_TILT_SPLITS) as f64;
    let share_of = |k: usize| if k == 1 { 1.0 } else { split_share };

    // External interaction. With K tilts of a distorted entry facet (module docs, "Tilt
    // splitting") each one's reflection is scored, 1/K of it, and the ray enters through one of
    // them chosen in proportion to its transmittance, carrying their mean.
    let eta_in = 1.0 / n_re;
    let mut tilts = [Tilt::default(); MAX_TILT_SPLITS as usize];
    let k = facets.splits(face, s.tilt_splits);
    let share = share_of(k);
    for tilt in &mut tilts[..k] {
        tilt.normal = facets.tilt(face, k, rng);
        tilt.m = entry_normal(tilt.normal, prism.faces[face].normal, d_in);
        tilt.cos_i = -d_in.dot(tilt.m);
        (tilt.refl, tilt.cos_t) = fresnel(tilt.cos_i, eta_in);
        let reflected = d_in + 2.0 * tilt.cos_i * tilt.m;
        emit(tally, d_in, reflected, tilt.refl * share);
        tally.external += tilt.refl * share;
    }
    let (j, mut w) = choose(&tilts[..k], |t| 1.0 - t.refl, rng);
    let Tilt {
        m, cos_i, cos_t, ..
    } = facets.keep(face, &tilts[..k], j);
    let mut d = (eta_in * d_in + (eta_in * cos_i - cos_t) * m).normalize();

    // Internal path: at each face the transmitted part leaves, the reflected part goes on. A
    // facet met for the first time may be split as at entry: each tilt's transmitted part is
    // scored, 1/K of it, and the path reflects about one chosen in proportion to its
    // reflectance, carrying their mean.
    let eta_out = n_re;
    for _ in 0..s.max_interactions {
        let (t, f) = prism.exit(p, d);
        p += t * d;
        if alpha > 0.0 {
            // e^{−x} by its series where x is small (ice in the visible: x ~ 10⁻⁶; the
            // remainder x⁴/24 < 4·10⁻¹⁴ below 10⁻³), else exp.
            let x = alpha * t;
            let kept = w * if x < 1e-3 {
                1.0 - x * (1.0 - x * (0.5 - x * (1.0 / 6.0)))
            } else {
                (-x).exp()
            };
            tally.absorbed += w - kept;
            w = kept;
        }
        let k = facets.splits(f, s.tilt_splits);
        let share = share_of(k);
        for tilt in &mut tilts[..k] {
            tilt.normal = facets.tilt(f, k, rng);
            (tilt.m, tilt.cos_i, (tilt.refl, tilt.cos_t)) =
                leave(d, tilt.normal, prism.faces[f].normal, eta_out);
            if tilt.refl < 1.0 {
                let out = eta_out * d + (eta_out * tilt.cos_i - tilt.cos_t) * tilt.m;
                emit(tally, d_in, out, w * (1.0 - tilt.refl) * share);
            }
        }
        let (j, kept) = choose(&tilts[..k], |t| t.refl, rng);
        let Tilt { m, cos_i, .. } = facets.keep(f, &tilts[..k], j);
        w *= kept;
        // A reflection keeps |d| (a Householder map), and the refracted and reflected
        // directions scored are unit vectors by construction: no renormalizing (the drift is
        // rounding's, ~1e-16 per interaction).
        d += 2.0 * cos_i * m;
        if w < s.roulette_weight {
            if rng.uniform() * s.roulette_weight < w {
                tally.roulette += s.roulette_weight - w;
                w = s.roulette_weight;
            } else {
                tally.roulette -= w;
                return;
            }
        }
    }
    tally.lost += w;
}

/// The default roulette weight ([`TraceSettings::roulette_weight`], module docs "Roulette").
pub const ROULETTE_WEIGHT: f64 = 0.1;

/// Most tilts a facet is split into; `tilt_splits` above it count as this.
pub const MAX_TILT_SPLITS: u32 = 16;

/// One tilt of a facet where a ray meets it: the tilted outward normal, the normal the ray
/// turns about, cos of incidence, reflectance and cos of refraction.
#[derive(Debug, Clone, Copy, Default)]
struct Tilt {
    normal: DVec3,
    m: DVec3,
    cos_i: f64,
    refl: f64,
    cos_t: f64,
}

/// One of `tilts` chosen in proportion to `weight` (the first, drawing nothing, if there is
/// only one), and the weights' mean.
fn choose(tilts: &[Tilt], weight: impl Fn(&Tilt) -> f64, rng: &mut Rng) -> (usize, f64) {
    if tilts.len() == 1 {
        return (0, weight(&tilts[0]));
    }
    let total: f64 = tilts.iter().map(&weight).sum();
    let mut u = rng.uniform() * total;
    let mut last = 0;
    for (j, t) in tilts.iter().enumerate() {
        let w = weight(t);
        if w > 0.0 {
            last = j;
            if u < w {
                break;
            }
            u -= w;
        }
    }
    (last, total / tilts.len() as f64)
}

/// An inside ray `d` at a facet with outward normal `tilted` (true normal `true_normal`), index
/// ratio `eta_out` = n: the normal it turns about (inward), cos of incidence, and (R, cos_t).
/// Turned against the ray, a tilted surface facing back at the ray cannot be crossed: total
/// reflection about the true normal, which keeps the ray inside.
fn leave(d: DVec3, tilted: DVec3, true_normal: DVec3, eta_out: f64) -> (DVec3, f64, (f64, f64)) {
    if d.dot(tilted) > 0.0 {
        let cos_i = d.dot(tilted);
        (-tilted, cos_i, fresnel(cos_i, eta_out))
    } else {
        let m = -true_normal;
        (m, -d.dot(m), (1.0, 0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_from_edge_cosines_equal_bins_from_the_angle() {
        for step in [0.18, 0.25, 1.0, 30.0] {
            let grid = ThetaGrid::new(step).unwrap();
            let edges = inner_edge_cosines(grid);
            let by_angle = |c: f64| {
                let theta = c.acos().to_degrees();
                ((theta / step + 0.5).floor() as usize).min(grid.len() - 1)
            };
            let mut rng = Rng::new(Sampling::Random, 5);
            for _ in 0..200_000 {
                let c = 1.0 - 2.0 * rng.uniform();
                assert_eq!(bin_of(c, &edges), by_angle(c), "step {step}, cos θ {c}");
            }
            for (k, &e) in edges.iter().enumerate() {
                // On an edge the bin above it (θ = (k + ½)Δθ belongs to bin k + 1).
                assert_eq!(bin_of(e, &edges), k + 1, "step {step}, edge {k}");
                assert_eq!(
                    bin_of(e.next_up(), &edges),
                    k,
                    "step {step}, above edge {k}"
                );
            }
            assert_eq!(bin_of(1.0, &edges), 0);
            assert_eq!(bin_of(-1.0, &edges), grid.len() - 1);
        }
    }
}
