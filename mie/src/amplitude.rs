//! Scattering amplitudes S1(θ), S2(θ) of one or many spheres at many angles.
//!
//! # Method
//! S1 = Σ c_n (a_n π_n + b_n τ_n), S2 = Σ c_n (a_n τ_n + b_n π_n), c_n = (2n+1)/(n(n+1))
//! (B&H Eq. 4.74), with π_n by its upward recurrence and τ_n = nμπ_n − (n+1)π_{n−1} (Eq. 4.47).
//! The kernel runs the recurrence for a block of 8 angles at once and keeps the four complex
//! partial sums Σ c a π, Σ c b τ, Σ c b π, Σ c a τ in vector registers (8 fused multiply-adds
//! per order and angle). π_n, τ_n depend on the angle and the order only: a batch of spheres
//! shares one run of the recurrence, a tile of orders at a time (`batch_sums`). The π/τ form
//! is kept on purpose: regrouping the sums over π alone saves three operations per term but
//! makes two sums of size ~x³ cancel to S(0) ~ x², which costs four digits at x = 1e5.
//!
//! # Symmetry
//! π_n(−μ) = (−1)^{n−1} π_n(μ), τ_n(−μ) = (−1)^n τ_n(μ) (docs/physics.md §2). Each partial sum is split
//! into odd-n and even-n parts evaluated at ν = |μ|, which gives θ and 180° − θ from one pass:
//!   Σ π_n(±ν) K_n = O ± E,   Σ τ_n(±ν) K_n = ±O + E.
//!
//! # Determinism
//! Work is split into fixed chunks of angles that do not depend on the thread count; every
//! output element is summed in the same order whatever the number of threads.

use std::collections::HashMap;

use num_complex::Complex64;
use rayon::prelude::*;

use crate::sphere::{MieCoefficients, Neumaier};

mod fused;

/// Angles per work item; fixed so that results do not depend on the thread count.
const ROW_CHUNK: usize = 64;

/// cos θ of a scattering angle in degrees, folded so that angles mirrored about 90° give
/// cosines of exactly opposite sign: θ > 90° uses −cos(180° − θ), and 90° gives 0 exactly (not
/// 6e-17). [`FoldedAngles`] then evaluates each ± pair once.
pub fn exact_cosine_deg(theta_deg: f64) -> f64 {
    if theta_deg == 90.0 {
        0.0
    } else if theta_deg > 90.0 {
        -(180.0 - theta_deg).to_radians().cos()
    } else {
        theta_deg.to_radians().cos()
    }
}

/// Requested cosines folded onto ν = |μ| so that each ± pair is evaluated once.
#[derive(Debug, Clone)]
pub struct FoldedAngles {
    /// Distinct ν = |μ| ≥ 0.
    nu: Vec<f64>,
    /// For each requested μ: (index into `nu`, whether μ < 0).
    map: Vec<(usize, bool)>,
}

impl FoldedAngles {
    /// Folds the cosines `mu`. Pairs are shared only where −μ equals μ' exactly, so build
    /// them with [`exact_cosine_deg`] or [`crate::ThetaGrid::cosines`].
    pub fn new(mu: &[f64]) -> Self {
        let mut index: HashMap<u64, usize> = HashMap::new();
        let mut nu = Vec::new();
        let map = mu
            .iter()
            .map(|&m| {
                let key = m.abs();
                let slot = *index.entry(key.to_bits()).or_insert_with(|| {
                    nu.push(key);
                    nu.len() - 1
                });
                (slot, m < 0.0 || (m == 0.0 && m.is_sign_negative()))
            })
            .collect();
        Self { nu, map }
    }

    /// Number of requested angles.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// True when no angle was requested.
    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }

    /// Number of distinct folded angles actually evaluated.
    pub fn folded_len(&self) -> usize {
        self.nu.len()
    }
}

/// The coefficients c_n a_n and c_n b_n (re, im each) of one sphere, n = 1..N.
#[derive(Debug, Clone)]
pub struct SphereTerms {
    rows: Vec<[f64; 4]>,
}

impl SphereTerms {
    /// Scales a_n, b_n of `coefficients` by c_n = (2n+1)/(n(n+1)).
    pub fn new(coefficients: &MieCoefficients) -> Self {
        let rows = coefficients
            .a
            .iter()
            .zip(&coefficients.b)
            .enumerate()
            .map(|(i, (a, b))| {
                let n = (i + 1) as f64;
                let c = (2.0 * n + 1.0) / (n * (n + 1.0));
                [c * a.re, c * a.im, c * b.re, c * b.im]
            })
            .collect();
        Self { rows }
    }

    /// Number of orders n.
    pub fn n_terms(&self) -> usize {
        self.rows.len()
    }
}

/// S1 and S2 at ν and at −ν for one sphere and one folded angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmplitudePair {
    /// S1 at μ = +ν (θ ≤ 90°).
    pub s1_plus: Complex64,
    /// S2 at μ = +ν (θ ≤ 90°).
    pub s2_plus: Complex64,
    /// S1 at μ = −ν (180° − θ).
    pub s1_minus: Complex64,
    /// S2 at μ = −ν (180° − θ).
    pub s2_minus: Complex64,
}

/// S1, S2 of one sphere at the requested cosines.
pub fn amplitudes(
    coefficients: &MieCoefficients,
    angles: &FoldedAngles,
) -> (Vec<Complex64>, Vec<Complex64>) {
    let terms = [SphereTerms::new(coefficients)];
    let folded: Vec<AmplitudePair> = for_each_pair(
        &terms,
        &angles.nu,
        Vec::with_capacity,
        |acc, _row, _sphere, pair| acc.push(pair),
    )
    .into_iter()
    .flatten()
    .collect();
    angles
        .map
        .iter()
        .map(|&(slot, negative)| {
            let p = folded[slot];
            if negative {
                (p.s1_minus, p.s2_minus)
            } else {
                (p.s1_plus, p.s2_plus)
            }
        })
        .unzip()
}

/// Σ_s w_s (|S1|² + |S2|²)_s at the requested cosines, for a batch of spheres.
pub fn weighted_intensity(
    spheres: &[SphereTerms],
    weights: &[f64],
    angles: &FoldedAngles,
) -> Vec<f64> {
    let [all] = interleaved_intensity(spheres, weights, angles);
    all
}

/// [`weighted_intensity`] of the even-indexed spheres and of the odd-indexed ones, from one batch.
pub fn weighted_intensity_halves(
    spheres: &[SphereTerms],
    weights: &[f64],
    angles: &FoldedAngles,
) -> [Vec<f64>; 2] {
    interleaved_intensity(spheres, weights, angles)
}

/// [`weighted_intensity`] of `G` interleaved groups of the spheres (sphere s in group s mod G)
/// from one batch: the groups share the recurrence (`batch_sums`), and each group's sums are
/// added in its spheres' order, as separate calls would.
fn interleaved_intensity<const G: usize>(
    spheres: &[SphereTerms],
    weights: &[f64],
    angles: &FoldedAngles,
) -> [Vec<f64>; G] {
    assert_eq!(spheres.len(), weights.len());
    // Per folded angle and group: [+ν, −ν].
    let folded: Vec<[[f64; 2]; G]> = for_each_pair(
        spheres,
        &angles.nu,
        |rows| vec![[[0.0; 2]; G]; rows],
        |acc, row, sphere, p| {
            let (w, group) = (weights[sphere], &mut acc[row][sphere % G]);
            group[0] += w * (p.s1_plus.norm_sqr() + p.s2_plus.norm_sqr());
            group[1] += w * (p.s1_minus.norm_sqr() + p.s2_minus.norm_sqr());
        },
    )
    .into_iter()
    .flatten()
    .collect();
    std::array::from_fn(|g| {
        angles
            .map
            .iter()
            .map(|&(slot, negative)| folded[slot][g][usize::from(negative)])
            .collect()
    })
}

/// Evaluates every sphere at every folded angle ν and hands each (row, sphere, amplitudes) to
/// `visit`, in a fixed order per chunk of `ROW_CHUNK` angles. Returns one accumulator per chunk.
/// Spheres are visited in their given order for each row.
pub fn for_each_pair<T, I, V>(spheres: &[SphereTerms], nu: &[f64], init: I, visit: V) -> Vec<T>
where
    T: Send,
    I: Fn(usize) -> T + Sync,
    V: Fn(&mut T, usize, usize, AmplitudePair) + Sync,
{
    let n_max = spheres.iter().map(SphereTerms::n_terms).max().unwrap_or(0);
    // θ = 0° and 180° exactly (ν = 1) have closed forms; see `exact_forward_backward`.
    let exact: Vec<AmplitudePair> = if nu.contains(&1.0) {
        spheres.iter().map(exact_forward_backward).collect()
    } else {
        Vec::new()
    };
    let recurrence = recurrence_table(n_max);
    nu.par_chunks(ROW_CHUNK)
        .map(|rows| {
            let mut acc = init(rows.len());
            let blocks: Vec<[f64; LANES]> = rows
                .chunks(LANES)
                .map(|c| {
                    let mut b = [0.0; LANES];
                    b[..c.len()].copy_from_slice(c);
                    b
                })
                .collect();
            for (s, sums) in sphere_sums(&blocks, spheres, &recurrence, true)
                .iter()
                .enumerate()
            {
                for j in 0..rows.len() {
                    if rows[j] == 1.0 {
                        visit(&mut acc, j, s, exact[s]);
                        continue;
                    }
                    let (b, l) = (j / LANES, j % LANES);
                    let odd: [f64; 8] = std::array::from_fn(|q| sums[b].odd[q][l]);
                    let even: [f64; 8] = std::array::from_fn(|q| sums[b].even[q][l]);
                    visit(&mut acc, j, s, combine(&odd, &even));
                }
            }
            acc
        })
        .collect()
}

/// S1, S2 at θ = 0° and 180° from π_n(±1) = (±1)^{n−1} n(n+1)/2, τ_n(±1) = (±1)^n n(n+1)/2:
///   S1(0°) = S2(0°) = Σ (2n+1)/2 (a_n + b_n),  S1(180°) = −S2(180°) = Σ (−1)^{n−1} (2n+1)/2 (a_n − b_n),
/// summed with Neumaier compensation: the back-scatter sum cancels strongly (docs/physics.md §2), and
/// the recurrence at μ = ±1 accumulates 2e-9 relative error by x = 2e5.
fn exact_forward_backward(sphere: &SphereTerms) -> AmplitudePair {
    let mut fwd = [Neumaier::default(); 2];
    let mut back = [Neumaier::default(); 2];
    for (i, &[ca_re, ca_im, cb_re, cb_im]) in sphere.rows.iter().enumerate() {
        let n = (i + 1) as f64;
        let half = n * (n + 1.0) / 2.0; // π_n(1) = τ_n(1)
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 }; // (−1)^{n−1}
        fwd[0].add(half * (ca_re + cb_re));
        fwd[1].add(half * (ca_im + cb_im));
        back[0].add(sign * half * (ca_re - cb_re));
        back[1].add(sign * half * (ca_im - cb_im));
    }
    let s_fwd = Complex64::new(fwd[0].sum(), fwd[1].sum());
    let s_back = Complex64::new(back[0].sum(), back[1].sum());
    AmplitudePair {
        s1_plus: s_fwd,
        s2_plus: s_fwd,
        s1_minus: s_back,
        s2_minus: -s_back,
    }
}

/// Angles evaluated together in one SIMD-friendly block.
const LANES: usize = 8;

/// [r1, r2, n, n+1] per order n (index n): π_n = r1 μ π_{n−1} − r2 π_{n−2} with
/// r1 = (2n−1)/(n−1), r2 = n/(n−1) (r1, r2 unused for n < 2), and τ_n = n μ π_n − (n+1) π_{n−1}.
fn recurrence_table(n_max: usize) -> Vec<[f64; 4]> {
    (0..=n_max.max(1))
        .map(|n| {
            let nf = n as f64;
            if n < 2 {
                [0.0, 0.0, nf, nf + 1.0]
            } else {
                [(2.0 * nf - 1.0) / (nf - 1.0), nf / (nf - 1.0), nf, nf + 1.0]
            }
        })
        .collect()
}

/// Odd-n and even-n sums of π_n K_n[q] for each lane of one block of angles.
#[derive(Clone, Copy)]
struct BlockSums {
    odd: [[f64; LANES]; 8],
    even: [[f64; LANES]; 8],
}

impl BlockSums {
    const ZERO: Self = Self {
        odd: [[0.0; LANES]; 8],
        even: [[0.0; LANES]; 8],
    };
}

/// π_n and τ_n at one block of angles, for one order n.
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
struct PiTau {
    pi: [f64; LANES],
    tau: [f64; LANES],
}

/// Orders per tile. A tile's π_n, τ_n at every block of a chunk of angles (8 blocks × 512
/// orders × 128 B = 512 KiB) are computed once and stay in L2 while every sphere of the batch
/// adds its terms; each sphere's coefficients for the tile (16 KiB) stay in L1 while every
/// block consumes them. `bench mie`'s rain, 3 λ × 100 sizes: 0.51 s at 32 orders, 0.44 s at
/// 128, 0.42 s at 512, 0.46 s at 1024, 0.76 s at 2048 (0.57 s before the batch shared them).
const ORDER_TILE: usize = 512;

/// The odd-n and even-n sums of every sphere (outer) at every block of angles (inner).
///
/// The recurrence depends on the angle and the order, not on the sphere: it runs once per tile
/// of orders for all spheres, which then only add their eight terms per order (the recurrence
/// was 6 of the 14 vector operations per order and sphere when each sphere ran its own). Per
/// sphere and block the operations and their order are those of one sphere alone.
///
/// `simd`: take the AVX-512 kernel where the CPU has it (always, except in the test that holds
/// the two kernels to the same bits).
fn batch_sums(
    blocks: &[[f64; LANES]],
    spheres: &[SphereTerms],
    recurrence: &[[f64; 4]],
    simd: bool,
) -> Vec<Vec<BlockSums>> {
    let avx512 = use_avx512(simd);
    let n_max = spheres.iter().map(SphereTerms::n_terms).max().unwrap_or(0);
    let mut sums = vec![vec![BlockSums::ZERO; blocks.len()]; spheres.len()];
    // π_{n−1}, π_{n−2} per block; before n = 1: π_0 = 0 and a virtual π_{−1} = 0.
    let mut previous = vec![([0.0; LANES], [0.0; LANES]); blocks.len()];
    let mut table = vec![PiTau::default(); ORDER_TILE * blocks.len()];
    let mut n0 = 1;
    while n0 <= n_max {
        let n1 = (n0 + ORDER_TILE).min(n_max + 1);
        for ((mu, prev), tile) in blocks
            .iter()
            .zip(previous.iter_mut())
            .zip(table.chunks_mut(ORDER_TILE))
        {
            let tile = &mut tile[..n1 - n0];
            #[cfg(target_arch = "x86_64")]
            if avx512 {
                // SAFETY: the CPU supports AVX-512F (`use_avx512`).
                #[allow(unsafe_code)]
                unsafe {
                    avx512::pi_tau(mu, prev, n0, tile, recurrence)
                };
                continue;
            }
            pi_tau(mu, prev, n0, tile, recurrence);
        }
        for (sphere, sums) in spheres.iter().zip(sums.iter_mut()) {
            let end = n1.min(sphere.rows.len() + 1);
            if end <= n0 {
                continue;
            }
            let terms = &sphere.rows[n0 - 1..end - 1];
            for (tile, block) in table.chunks(ORDER_TILE).zip(sums.iter_mut()) {
                let tile = &tile[..end - n0];
                #[cfg(target_arch = "x86_64")]
                if avx512 {
                    // SAFETY: the CPU supports AVX-512F (`use_avx512`).
                    #[allow(unsafe_code)]
                    unsafe {
                        avx512::accumulate(block, n0, tile, terms)
                    };
                    continue;
                }
                accumulate(block, n0, tile, terms);
            }
        }
        n0 = n1;
    }
    sums
}

/// Whether the AVX-512 kernels run: the CPU has AVX-512F (checked at run time) and `simd` asks
/// for them (always, except in the test that holds them to the portable kernels' bits).
fn use_avx512(simd: bool) -> bool {
    #[cfg(target_arch = "x86_64")]
    return simd && std::arch::is_x86_feature_detected!("avx512f");
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = simd;
        false
    }
}

/// The sums of every sphere at every block: a lone sphere by the fused kernel
/// (`fused::block_sums`), a batch by [`batch_sums`].
fn sphere_sums(
    blocks: &[[f64; LANES]],
    spheres: &[SphereTerms],
    recurrence: &[[f64; 4]],
    simd: bool,
) -> Vec<Vec<BlockSums>> {
    match spheres {
        [one] => vec![fused::block_sums(blocks, &one.rows, recurrence, simd)],
        _ => batch_sums(blocks, spheres, recurrence, simd),
    }
}

/// π_n (upward recurrence, B&H Eq. 4.47) and τ_n = n μ π_n − (n+1) π_{n−1} of one block for
/// the orders n0 .. n0 + tile.len(), carrying (π_{n−1}, π_{n−2}) in `previous`.
fn pi_tau(
    mu: &[f64; LANES],
    previous: &mut ([f64; LANES], [f64; LANES]),
    n0: usize,
    tile: &mut [PiTau],
    recurrence: &[[f64; 4]],
) {
    let (mut p1, mut p2) = *previous;
    for (n, out) in (n0..).zip(tile.iter_mut()) {
        let [r1, r2, nf, n1f] = recurrence[n];
        let pi: [f64; LANES] = if n == 1 {
            [1.0; LANES]
        } else {
            // π_n = (r1 μ) π_{n−1} + (−r2 π_{n−2})
            std::array::from_fn(|l| (r1 * mu[l]).mul_add(p1[l], -r2 * p2[l]))
        };
        // τ_n = (n μ) π_n + (−(n+1) π_{n−1})
        let tau = std::array::from_fn(|l| (nf * mu[l]).mul_add(pi[l], -n1f * p1[l]));
        *out = PiTau { pi, tau };
        p2 = p1;
        p1 = pi;
    }
    *previous = (p1, p2);
}

/// Hands `add` the orders n0 .. n0 + len in turn (by their index i from n0), each with the
/// odd-n or the even-n sums: in (odd, even) pairs, so both stay in registers without a branch
/// per order. Every kernel walks its orders this way.
#[inline(always)]
fn by_parity<S>(
    n0: usize,
    len: usize,
    odd: &mut S,
    even: &mut S,
    mut add: impl FnMut(&mut S, usize),
) {
    let mut i = 0;
    if len > 0 && n0.is_multiple_of(2) {
        add(even, 0);
        i = 1;
    }
    while i + 1 < len {
        add(odd, i);
        add(even, i + 1);
        i += 2;
    }
    if i < len {
        add(odd, i);
    }
}

/// Adds the terms of orders n0 .. n0 + tile.len() of one sphere to one block's sums.
///
/// The hot loop: eight fused multiply-adds per order and lane into the odd-n or even-n sums,
/// orders in (odd, even) pairs with the sums held in locals so they live in vector registers.
#[inline]
fn accumulate(sums: &mut BlockSums, n0: usize, tile: &[PiTau], terms: &[[f64; 4]]) {
    #[inline(always)]
    fn add(sums: &mut [[f64; LANES]; 8], t: &PiTau, k: &[f64; 4]) {
        let [ca_re, ca_im, cb_re, cb_im] = *k;
        let pairs = [
            (&t.pi, ca_re),
            (&t.pi, ca_im),
            (&t.tau, cb_re),
            (&t.tau, cb_im),
            (&t.pi, cb_re),
            (&t.pi, cb_im),
            (&t.tau, ca_re),
            (&t.tau, ca_im),
        ];
        for (q, (v, k)) in pairs.into_iter().enumerate() {
            for l in 0..LANES {
                sums[q][l] = v[l].mul_add(k, sums[q][l]);
            }
        }
    }
    let mut odd = sums.odd;
    let mut even = sums.even;
    let terms = &terms[..tile.len()];
    by_parity(n0, tile.len(), &mut odd, &mut even, |sums, i| {
        add(sums, &tile[i], &terms[i])
    });
    sums.odd = odd;
    sums.even = even;
}

/// [`accumulate`] and [`pi_tau`] in explicit 512-bit operations, for the reason the fused
/// kernel's notes give (`fused`: the compiler's 256-bit choice, 2.1× slower there); the same
/// operations in the same order as the portable versions, so they agree bit for bit.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx512 {
    use std::arch::x86_64::{
        __m512d, _mm512_fmadd_pd, _mm512_loadu_pd, _mm512_mul_pd, _mm512_set1_pd, _mm512_storeu_pd,
    };

    use super::{BlockSums, LANES, PiTau};

    const _: () = assert!(LANES == 8, "the AVX-512 kernel holds 8 lanes per register");

    /// [`super::pi_tau`] in 512-bit operations, the same ones in the same order.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn pi_tau(
        mu: &[f64; LANES],
        previous: &mut ([f64; LANES], [f64; LANES]),
        n0: usize,
        tile: &mut [PiTau],
        recurrence: &[[f64; 4]],
    ) {
        // SAFETY (all loads and stores below): every pointer comes from a [f64; 8] array.
        let load = |a: &[f64; LANES]| unsafe { _mm512_loadu_pd(a.as_ptr()) };
        let store =
            |a: &mut [f64; LANES], v: __m512d| unsafe { _mm512_storeu_pd(a.as_mut_ptr(), v) };
        let mu = load(mu);
        let (mut p1, mut p2) = (load(&previous.0), load(&previous.1));
        for (n, out) in (n0..).zip(tile.iter_mut()) {
            let [r1, r2, nf, n1f] = recurrence[n];
            let pi = if n == 1 {
                _mm512_set1_pd(1.0)
            } else {
                // π_n = (r1 μ) π_{n−1} + (−r2 π_{n−2})
                let r1_mu = _mm512_mul_pd(_mm512_set1_pd(r1), mu);
                let r2_p2 = _mm512_mul_pd(_mm512_set1_pd(-r2), p2);
                _mm512_fmadd_pd(r1_mu, p1, r2_p2)
            };
            // τ_n = (n μ) π_n + (−(n+1) π_{n−1})
            let n_mu = _mm512_mul_pd(_mm512_set1_pd(nf), mu);
            let n1_p1 = _mm512_mul_pd(_mm512_set1_pd(-n1f), p1);
            store(&mut out.pi, pi);
            store(&mut out.tau, _mm512_fmadd_pd(n_mu, pi, n1_p1));
            p2 = p1;
            p1 = pi;
        }
        store(&mut previous.0, p1);
        store(&mut previous.1, p2);
    }

    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn accumulate(
        sums: &mut BlockSums,
        n0: usize,
        tile: &[PiTau],
        terms: &[[f64; 4]],
    ) {
        // SAFETY (all loads and stores below): every pointer comes from a [f64; 8] array.
        let load = |a: &[f64; LANES]| unsafe { _mm512_loadu_pd(a.as_ptr()) };
        let mut odd: [__m512d; 8] = std::array::from_fn(|q| load(&sums.odd[q]));
        let mut even: [__m512d; 8] = std::array::from_fn(|q| load(&sums.even[q]));
        #[inline(always)]
        fn add(sums: &mut [__m512d; 8], t: &PiTau, k: &[f64; 4]) {
            // SAFETY: only called from `accumulate`, which has AVX-512F enabled; the loads
            // read [f64; 8] arrays.
            unsafe {
                let pi = _mm512_loadu_pd(t.pi.as_ptr());
                let tau = _mm512_loadu_pd(t.tau.as_ptr());
                let ca_re = _mm512_set1_pd(k[0]);
                let ca_im = _mm512_set1_pd(k[1]);
                let cb_re = _mm512_set1_pd(k[2]);
                let cb_im = _mm512_set1_pd(k[3]);
                sums[0] = _mm512_fmadd_pd(pi, ca_re, sums[0]);
                sums[1] = _mm512_fmadd_pd(pi, ca_im, sums[1]);
                sums[2] = _mm512_fmadd_pd(tau, cb_re, sums[2]);
                sums[3] = _mm512_fmadd_pd(tau, cb_im, sums[3]);
                sums[4] = _mm512_fmadd_pd(pi, cb_re, sums[4]);
                sums[5] = _mm512_fmadd_pd(pi, cb_im, sums[5]);
                sums[6] = _mm512_fmadd_pd(tau, ca_re, sums[6]);
                sums[7] = _mm512_fmadd_pd(tau, ca_im, sums[7]);
            }
        }
        let terms = &terms[..tile.len()];
        super::by_parity(n0, tile.len(), &mut odd, &mut even, |sums, i| {
            add(sums, &tile[i], &terms[i])
        });
        let store =
            |a: &mut [f64; LANES], v: __m512d| unsafe { _mm512_storeu_pd(a.as_mut_ptr(), v) };
        for q in 0..8 {
            store(&mut sums.odd[q], odd[q]);
            store(&mut sums.even[q], even[q]);
        }
    }
}

/// Assembles S1, S2 at ±ν from the odd-n and even-n parts of the partial sums
/// [Σ c a π, Σ c b τ, Σ c b π, Σ c a τ] (re, im each; module docs).
fn combine(odd: &[f64], even: &[f64]) -> AmplitudePair {
    let part = |q: usize| {
        (
            Complex64::new(odd[q], odd[q + 1]),
            Complex64::new(even[q], even[q + 1]),
        )
    };
    let (ap_o, ap_e) = part(0); // Σ c a π
    let (bt_o, bt_e) = part(2); // Σ c b τ
    let (bp_o, bp_e) = part(4); // Σ c b π
    let (at_o, at_e) = part(6); // Σ c a τ
    AmplitudePair {
        s1_plus: (ap_o + ap_e) + (bt_o + bt_e),
        s2_plus: (bp_o + bp_e) + (at_o + at_e),
        // π flips sign for even n, τ for odd n.
        s1_minus: (ap_o - ap_e) + (bt_e - bt_o),
        s2_minus: (bp_o - bp_e) + (at_e - at_o),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sphere::Sphere;

    fn sums_bits(sums: &[Vec<BlockSums>]) -> Vec<u64> {
        sums.iter()
            .flatten()
            .flat_map(|b| b.odd.iter().chain(&b.even).flatten().map(|v| v.to_bits()))
            .collect()
    }

    /// A sphere's sums do not depend on the batch it is computed in (the orders of the shared
    /// recurrence's tiles and of the terms are a lone sphere's, whose fused kernel runs the
    /// same operations), and the AVX-512 kernels give the portable ones' bits. The sizes span several tiles of orders and end mid-tile.
    #[test]
    fn batched_sums_equal_each_sphere_alone_and_both_kernels_agree() {
        let m = Complex64::new(1.33, 1e-8);
        let spheres: Vec<SphereTerms> = [3.0, 700.0, 40.0, 1500.0]
            .iter()
            .map(|&x| SphereTerms::new(&Sphere::new(m, x).unwrap().coefficients()))
            .collect();
        assert!(spheres[3].n_terms() > 2 * ORDER_TILE);
        let nu: Vec<f64> = (0..13).map(|i| (i as f64 * 0.077).cos()).collect();
        let blocks: Vec<[f64; LANES]> = nu
            .chunks(LANES)
            .map(|c| std::array::from_fn(|l| c.get(l).copied().unwrap_or(0.0)))
            .collect();
        let n_max = spheres.iter().map(SphereTerms::n_terms).max().unwrap();
        let recurrence = recurrence_table(n_max);
        let batch = batch_sums(&blocks, &spheres, &recurrence, true);
        // Each alone: the fused kernel (sphere_sums with one sphere).
        let alone = |simd: bool| -> Vec<Vec<BlockSums>> {
            spheres
                .iter()
                .map(|s| sphere_sums(&blocks, std::slice::from_ref(s), &recurrence, simd).remove(0))
                .collect()
        };
        assert_eq!(sums_bits(&batch), sums_bits(&alone(true)));
        assert_eq!(sums_bits(&batch), sums_bits(&alone(false)));
        let portable = batch_sums(&blocks, &spheres, &recurrence, false);
        assert_eq!(sums_bits(&batch), sums_bits(&portable));
        // Not all zero: the comparison compares something.
        assert!(sums_bits(&batch).iter().filter(|&&b| b != 0).count() > 500);
    }
}
