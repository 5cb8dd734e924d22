//! Scattering amplitudes S1(θ), S2(θ) of one or many spheres at many angles.
//!
//! # Method
//! With c_n = (2n+1)/(n(n+1)) and τ_n = nμπ_n − (n+1)π_{n−1} (B&H Eq. 4.47), the amplitude sums
//!   S1 = Σ c_n (a_n π_n + b_n τ_n),  S2 = Σ c_n (a_n τ_n + b_n π_n)
//! regroup into sums over π_n alone:
//!   S1 = Σ π_n A_n + μ Σ π_n B_n,  A_n = c_n a_n − c_{n+1}(n+2) b_{n+1},  B_n = n c_n b_n,
//!   S2 = Σ π_n C_n + μ Σ π_n E_n,  C_n = c_n b_n − c_{n+1}(n+2) a_{n+1},  E_n = n c_n a_n.
//! π_n depends only on (n, μ), not on the sphere, so for a batch of spheres the four sums are one
//! matrix product Π·K: Π[angle, n] = π_n(μ), K[n, 8s + q] = the eight real parts of A, B, C, E of
//! sphere s. The product runs through a blocked GEMM (ndarray → matrixmultiply, which picks
//! AVX2/FMA kernels at run time), chunked over n so Π never exists whole.
//!
//! # Symmetry
//! π_n(−μ) = (−1)^{n−1} π_n(μ) (physics.md §2). Splitting each sum into odd-n and even-n parts,
//! evaluated at ν = |μ|, gives both angles θ and 180° − θ from one pass:
//!   Σ π_n(+ν) K_n = O + E,  Σ π_n(−ν) K_n = O − E.
//!
//! # Determinism
//! Work is split into fixed chunks of angles that do not depend on the thread count; every
//! output element is summed in the same order whatever the number of threads.

use std::collections::HashMap;

use ndarray::{ArrayView2, ArrayViewMut2, ShapeBuilder, linalg::general_mat_mul, s};
use num_complex::Complex64;
use rayon::prelude::*;

use crate::sphere::MieCoefficients;

/// Angles per work item; fixed so that results do not depend on the thread count.
const ROW_CHUNK: usize = 64;
/// Orders n per GEMM step (half odd, half even).
const N_CHUNK: usize = 256;

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
    /// symmetric grids with [`crate::grid::symmetric_cosines`].
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

/// The real coefficient rows K_n = [A, B, C, E] (re, im each) of one sphere, n = 1..N.
#[derive(Debug, Clone)]
pub struct SphereTerms {
    rows: Vec<[f64; 8]>,
}

impl SphereTerms {
    /// Regroups a_n, b_n into the π-only coefficients A_n, B_n, C_n, E_n (module docs).
    pub fn new(coefficients: &MieCoefficients) -> Self {
        let n_terms = coefficients.n_terms();
        let (a, b) = (&coefficients.a, &coefficients.b);
        let c = |n: f64| (2.0 * n + 1.0) / (n * (n + 1.0));
        let rows = (0..n_terms)
            .map(|i| {
                let n = (i + 1) as f64;
                let zero = Complex64::new(0.0, 0.0);
                let (a_next, b_next) = if i + 1 < n_terms {
                    (a[i + 1], b[i + 1])
                } else {
                    (zero, zero)
                };
                let shift = c(n + 1.0) * (n + 2.0);
                let a_n = c(n) * a[i] - b_next * shift;
                let b_n = b[i] * (n * c(n));
                let c_n = c(n) * b[i] - a_next * shift;
                let e_n = a[i] * (n * c(n));
                [
                    a_n.re, a_n.im, b_n.re, b_n.im, c_n.re, c_n.im, e_n.re, e_n.im,
                ]
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
    pub s1_plus: Complex64,
    pub s2_plus: Complex64,
    pub s1_minus: Complex64,
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
        |rows| Vec::with_capacity(rows),
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
    assert_eq!(spheres.len(), weights.len());
    let folded: Vec<[f64; 2]> = for_each_pair(
        spheres,
        &angles.nu,
        |rows| vec![[0.0; 2]; rows],
        |acc, row, sphere, p| {
            let w = weights[sphere];
            acc[row][0] += w * (p.s1_plus.norm_sqr() + p.s2_plus.norm_sqr());
            acc[row][1] += w * (p.s1_minus.norm_sqr() + p.s2_minus.norm_sqr());
        },
    )
    .into_iter()
    .flatten()
    .collect();
    angles
        .map
        .iter()
        .map(|&(slot, negative)| folded[slot][usize::from(negative)])
        .collect()
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
    // Longest series first, so the spheres still active at order n are a prefix.
    let mut order: Vec<usize> = (0..spheres.len()).collect();
    order.sort_by_key(|&s| std::cmp::Reverse(spheres[s].n_terms()));
    let n_terms_sorted: Vec<usize> = order.iter().map(|&s| spheres[s].n_terms()).collect();
    // slots[s]: position of sphere s in the sorted order.
    let mut slots = vec![0usize; spheres.len()];
    for (k, &s) in order.iter().enumerate() {
        slots[s] = k;
    }

    nu.par_chunks(ROW_CHUNK)
        .map(|rows| {
            let sums = odd_even_sums(spheres, &order, &n_terms_sorted, rows);
            let mut acc = init(rows.len());
            let width = 8 * spheres.len();
            for (j, &v) in rows.iter().enumerate() {
                // Visit in the caller's sphere order so accumulation order is fixed.
                for s in 0..spheres.len() {
                    let k = slots[s];
                    let odd = &sums.odd[j * width + 8 * k..j * width + 8 * k + 8];
                    let even = &sums.even[j * width + 8 * k..j * width + 8 * k + 8];
                    visit(&mut acc, j, s, combine(odd, even, v));
                }
            }
            acc
        })
        .collect()
}

/// Row-major (rows × 8·spheres) odd-n and even-n sums for one chunk of angles.
struct OddEvenSums {
    odd: Vec<f64>,
    even: Vec<f64>,
}

fn odd_even_sums(
    spheres: &[SphereTerms],
    order: &[usize],
    n_terms_sorted: &[usize],
    rows: &[f64],
) -> OddEvenSums {
    let j_len = rows.len();
    let width = 8 * spheres.len();
    let half = N_CHUNK / 2;
    let n_max = n_terms_sorted.first().copied().unwrap_or(0);

    let mut odd = vec![0.0; j_len * width];
    let mut even = vec![0.0; j_len * width];
    // Π blocks, column-major: element (j, k) at j + j_len·k.
    let mut pi_odd = vec![0.0; j_len * half];
    let mut pi_even = vec![0.0; j_len * half];
    let mut k_odd = vec![0.0; half * width];
    let mut k_even = vec![0.0; half * width];
    // π_{n−2}, π_{n−1} per angle; π_0 = 0, and π_1 = 1 follows from the recurrence below.
    let mut pi_prev2 = vec![0.0; j_len];
    let mut pi_prev = vec![0.0; j_len];

    let mut n0 = 1;
    while n0 <= n_max {
        let active = n_terms_sorted.iter().take_while(|&&n| n >= n0).count();
        // Π for n = n0 .. n0 + N_CHUNK − 1 (n0 is odd).
        for step in 0..N_CHUNK {
            let n = n0 + step;
            let dst = if step % 2 == 0 {
                &mut pi_odd[(step / 2) * j_len..(step / 2 + 1) * j_len]
            } else {
                &mut pi_even[(step / 2) * j_len..(step / 2 + 1) * j_len]
            };
            if n == 1 {
                dst.fill(1.0);
            } else {
                // π_n = ((2n−1)/(n−1)) μ π_{n−1} − (n/(n−1)) π_{n−2}
                let nf = n as f64;
                let r1 = (2.0 * nf - 1.0) / (nf - 1.0);
                let r2 = nf / (nf - 1.0);
                for j in 0..j_len {
                    dst[j] = r1 * rows[j] * pi_prev[j] - r2 * pi_prev2[j];
                }
            }
            pi_prev2.copy_from_slice(&pi_prev);
            pi_prev.copy_from_slice(dst);
        }
        // K rows for the active spheres; orders past a sphere's N_stop are zero.
        let w_active = 8 * active;
        for step in 0..N_CHUNK {
            let n = n0 + step;
            let kk = step / 2;
            let dst = if step % 2 == 0 {
                &mut k_odd
            } else {
                &mut k_even
            };
            let row = &mut dst[kk * w_active..(kk + 1) * w_active];
            for (k, &s) in order[..active].iter().enumerate() {
                let cell = &mut row[8 * k..8 * k + 8];
                match spheres[s].rows.get(n - 1) {
                    Some(values) => cell.copy_from_slice(values),
                    None => cell.fill(0.0),
                }
            }
        }
        for (pi, k, out) in [(&pi_odd, &k_odd, &mut odd), (&pi_even, &k_even, &mut even)] {
            let a = ArrayView2::from_shape((j_len, half).f(), &pi[..]).expect("Π block shape");
            let b = ArrayView2::from_shape((half, w_active), &k[..half * w_active])
                .expect("K block shape");
            let mut c =
                ArrayViewMut2::from_shape((j_len, width), &mut out[..]).expect("sum block shape");
            let mut c = c.slice_mut(s![.., ..w_active]);
            general_mat_mul(1.0, &a, &b, 1.0, &mut c);
        }
        n0 += N_CHUNK;
    }
    OddEvenSums { odd, even }
}

/// Assembles S1, S2 at ±ν from the odd-n and even-n parts of the four sums (module docs).
fn combine(odd: &[f64], even: &[f64], nu: f64) -> AmplitudePair {
    let part = |q: usize| {
        (
            Complex64::new(odd[q], odd[q + 1]),
            Complex64::new(even[q], even[q + 1]),
        )
    };
    let (a_o, a_e) = part(0);
    let (b_o, b_e) = part(2);
    let (c_o, c_e) = part(4);
    let (e_o, e_e) = part(6);
    AmplitudePair {
        s1_plus: (a_o + a_e) + (b_o + b_e) * nu,
        s2_plus: (c_o + c_e) + (e_o + e_e) * nu,
        s1_minus: (a_o - a_e) + (b_e - b_o) * nu,
        s2_minus: (c_o - c_e) + (e_e - e_o) * nu,
    }
}
