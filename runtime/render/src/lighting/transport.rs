//! The diffuse light by discrete ordinates: the δ-M-scaled transfer equation solved on the voxel
//! grid along a set of directions, by upwind sweeps ([`crate::lighting::lattice::sweep`]) and source
//! iteration from the diffusion's P1 radiance (the module docs of [`super`] say where it sits).
//!
//! Per voxel and channel the radiance over the sphere is kept as its real spherical-harmonic
//! moments φ_lm = ∫ I Y_lm dω up to degree [`DEGREE`], which is all the scattering needs of it
//! when p′ is expanded to that degree (the δ-M truncation, Wiscombe 1977): by the addition
//! theorem, (1/4π)∫ p′(ω·ω′) I(ω′) dω′ = Σ_l χ′_l Σ_m Y_lm(ω) φ_lm. The equations, the
//! acceleration (diffusion synthetic acceleration, Alcouffe 1977) and the conservation check
//! are docs/physics.md §7.10's.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::lighting::lattice::Passes;
use crate::volume::DensityGrid;

/// The highest spherical-harmonic degree kept.
pub const DEGREE: usize = 4;
/// Spherical harmonics up to [`DEGREE`]: (L + 1)².
pub const HARMONICS: usize = (DEGREE + 1) * (DEGREE + 1);
/// Moments per voxel: [`HARMONICS`] per channel.
pub const PER_VOXEL: usize = 3 * HARMONICS;

/// The real, orthonormal spherical harmonics Y_lm(ω) for l ≤ 4, ordered l by l and m from −l
/// to l (Sloan 2008, "Stupid spherical harmonics tricks", Appendix A2; x, y, z the unit
/// vector's components with z the polar axis).
pub fn harmonics(w: DVec3) -> [f64; HARMONICS] {
    let (x, y, z) = (w.x, w.y, w.z);
    let (x2, y2, z2) = (x * x, y * y, z * z);
    [
        0.282_094_791_773_878_1,
        0.488_602_511_902_919_9 * y,
        0.488_602_511_902_919_9 * z,
        0.488_602_511_902_919_9 * x,
        1.092_548_430_592_079_2 * x * y,
        1.092_548_430_592_079_2 * y * z,
        0.315_391_565_252_52 * (3.0 * z2 - 1.0),
        1.092_548_430_592_079_2 * x * z,
        0.546_274_215_296_039_6 * (x2 - y2),
        0.590_043_589_926_643_5 * y * (3.0 * x2 - y2),
        2.890_611_442_640_554 * x * y * z,
        0.457_045_799_464_465_8 * y * (5.0 * z2 - 1.0),
        0.373_176_332_590_115_4 * z * (5.0 * z2 - 3.0),
        0.457_045_799_464_465_8 * x * (5.0 * z2 - 1.0),
        1.445_305_721_320_277 * z * (x2 - y2),
        0.590_043_589_926_643_5 * x * (x2 - 3.0 * y2),
        2.503_342_941_796_704_5 * x * y * (x2 - y2),
        1.770_130_769_779_930_5 * y * z * (3.0 * x2 - y2),
        0.946_174_695_757_560_1 * x * y * (7.0 * z2 - 1.0),
        0.669_046_543_557_289_2 * y * z * (7.0 * z2 - 3.0),
        0.105_785_546_915_204_2 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0),
        0.669_046_543_557_289_2 * x * z * (7.0 * z2 - 3.0),
        0.473_087_347_878_78 * (x2 - y2) * (7.0 * z2 - 1.0),
        1.770_130_769_779_930_5 * x * z * (x2 - 3.0 * y2),
        0.625_835_735_449_176_1 * (x2 * (x2 - 3.0 * y2) - y2 * (3.0 * x2 - y2)),
    ]
}

/// The δ-M-scaled medium and the diffuse light's fixed sources, per voxel and channel.
pub struct Medium {
    /// σ′_t = β_ext (1 − αf) (1/m).
    pub ext: Vec<[f64; 3]>,
    /// σ′_s = β_sca (1 − f) (1/m).
    pub sca: Vec<[f64; 3]>,
    /// p′'s Legendre moments χ′_0 … χ′_L (χ′_0 = 1).
    pub chi: Vec<[[f64; DEGREE + 1]; 3]>,
    /// The sunlit source's strength q (radiance per metre): Q(ω) = q p′(ω·l).
    pub sun: Vec<[f64; 3]>,
    /// The sun's direction of travel l.
    pub l: DVec3,
    /// The skylit source as P1: Q(ω) = q0 + 3 q1·ω (q0, then q1 x, y, z, per channel).
    pub sky: Vec<[[f64; 4]; 3]>,
}

/// What [`solve`] did: the relative change of φ_00 (green, over the grid) per iteration.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// ‖Δφ_00‖/‖φ_00‖ after each iteration.
    pub changes: Vec<f64>,
}

/// (1/4π)∫ p′ I dω′ towards `y` (the harmonics of ω) from moments `m` with p′'s `chi`.
pub fn scattered(m: &[f64], chi: &[f64; DEGREE + 1], y: &[f64; HARMONICS]) -> f64 {
    (0..HARMONICS).map(|k| chi[DEGREES[k]] * y[k] * m[k]).sum()
}

/// One direction of the transport's set: its harmonics and its step between layers.
pub(crate) struct Ordinate {
    /// Y_lm(ω), padded with zeros to [`PADDED`].
    pub(crate) y: [f64; PADDED],
    /// The point one layer back, in voxel units along the layer's two axes.
    pub(crate) shift: (f64, f64),
    /// The path length between two layers (m).
    pub(crate) ds: f64,
}

/// Directions that share a sweep order: the axis each travels along most, and its sign.
pub(crate) struct Group {
    pub(crate) axis: usize,
    pub(crate) forward: bool,
    pub(crate) ordinates: Vec<Ordinate>,
}

/// Directions stepped side by side in the sweeps' inner loop (one AVX-512 register of f64).
const LANES: usize = 8;

/// The harmonics per channel padded to whole vector registers, so that sums over them
/// vectorize.
const PADDED: usize = 32;

/// e^−τ for τ ≥ 0 in every lane, branch-free so that it vectorizes: τ log₂e split into an
/// integer n and a remainder, e^−r by its Taylor series to degree 12 on |r| ≤ ln2/2, times
/// 2^−n from the exponent bits (within 3.3·10⁻¹⁶ of the library's, relative); 0 past τ = 700.
fn exp_neg(tau: [f64; LANES]) -> [f64; LANES] {
    const LN2_HI: f64 = 0.693_147_180_369_123_8;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    std::array::from_fn(|d| {
        let x = -tau[d].min(700.0);
        let n = (x * std::f64::consts::LOG2_E + 0.5).floor();
        let r = (x - n * LN2_HI) - n * LN2_LO;
        let mut p = 1.0 / 479_001_600.0;
        for k in (0..12).rev() {
            p = p * r + 1.0 / FACTORIALS[k];
        }
        // 2^n from the exponent bits: n + 1023 sits in the low mantissa bits of
        // n + 1023 + 2⁵², and the shift moves it into the exponent (a cast would not vectorize).
        let scale = f64::from_bits((n + (1023.0 + 4_503_599_627_370_496.0)).to_bits() << 52);
        if tau[d] > 700.0 { 0.0 } else { p * scale }
    })
}

/// k! for k = 0 … 11.
const FACTORIALS: [f64; 12] = [
    1.0,
    1.0,
    2.0,
    6.0,
    24.0,
    120.0,
    720.0,
    5040.0,
    40_320.0,
    362_880.0,
    3_628_800.0,
    39_916_800.0,
];

/// The two axes across a layer normal to `axis`, the one whose voxels lie closer in memory
/// first (x before y before z), so that a layer's voxels are visited in memory order.
pub(crate) fn layer_axes(axis: usize) -> (usize, usize) {
    match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// `dirs` grouped by the axis they travel along most and its sign (the six sweep orders).
pub(crate) fn groups(grid: &DensityGrid, dirs: &[DVec3]) -> Vec<Group> {
    let h = crate::lighting::lattice::voxel_size(grid);
    let mut groups: Vec<Group> = Vec::new();
    for &w in dirs {
        let a = (0..3)
            .max_by(|&i, &j| w[i].abs().total_cmp(&w[j].abs()))
            .expect("three axes");
        let (b, c) = layer_axes(a);
        let ds = h[a] / w[a].abs();
        let y = harmonics(w);
        let ordinate = Ordinate {
            y: std::array::from_fn(|k| if k < HARMONICS { y[k] } else { 0.0 }),
            shift: (-ds * w[b] / h[b], -ds * w[c] / h[c]),
            ds,
        };
        let forward = w[a] > 0.0;
        match groups
            .iter_mut()
            .find(|g| g.axis == a && g.forward == forward)
        {
            Some(g) => g.ordinates.push(ordinate),
            None => groups.push(Group {
                axis: a,
                forward,
                ordinates: vec![ordinate],
            }),
        }
    }
    groups
}

/// The emission per voxel and channel as harmonics, S(ω) = Σ_k s_k Y_k(ω): the scattered
/// light σ′_s χ′_l φ_lm (the addition theorem), the sunlit source q p′(ω·l) = 4π q Σ χ′_l
/// Y_lm(l) Y_lm(ω), and the skylit q0 + 3 q1·ω (Y_00 = 1/√(4π), Y_1m = Y_1 (y, z, x)).
fn emission(
    medium: &Medium,
    i: usize,
    m: &[f64; PER_VOXEL],
    y_sun: &[f64; HARMONICS],
) -> [[f64; PADDED]; 3] {
    const Y1: f64 = 0.488_602_511_902_919_9;
    let mut s = [[0.0; PADDED]; 3];
    for (c, s) in s.iter_mut().enumerate() {
        let (chi, sca, sun) = (&medium.chi[i][c], medium.sca[i][c], medium.sun[i][c]);
        let o = c * HARMONICS;
        for k in 0..HARMONICS {
            s[k] = chi[DEGREES[k]] * (sca * m[o + k] + 4.0 * PI * sun * y_sun[k]);
        }
        let sky = medium.sky[i][c];
        s[0] += (4.0 * PI).sqrt() * sky[0];
        s[1] += 3.0 * sky[2] / Y1;
        s[2] += 3.0 * sky[3] / Y1;
        s[3] += 3.0 * sky[1] / Y1;
    }
    s
}

/// The degree l of each harmonic k.
const DEGREES: [usize; HARMONICS] = [
    0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4,
];

/// One step of the transfer equation from radiance `i_back` over optical depth `tau` (with
/// e = e^−τ) and path length `ds`, the emission S (radiance per metre) linear between its
/// value at the step's start, `s_back`, and at its end, `here` = (S, σ′_t) there, and σ′_t
/// the mean σ̄ = τ/ds over the step:
/// I = I_back e + A (1 − q) + B (q − e), q = (1 − e)/τ, with A + B = (S_here + S_back)/σ̄, so
/// that a thin step adds the trapezoid of S (what the balance needs), and A = S_here/σ′_here
/// where the medium thickens along the step, so that a thick step ends at the local
/// equilibrium S/σ′_t. (With A = S_here/σ̄ throughout, a step from clear air into a voxel of
/// large optical depth ended at 2 S/σ′_t, and coarse grids glowed; with the source function
/// S/σ′_t linear in τ at both ends, a thin step's emission departed from the trapezoid by
/// ds/4 (σ_here − σ_back)(J_back − J_here), a gain in a sunlit cloud, and a voxel where the
/// beam's loss was not matched by its own σ′_t blew up.)
#[inline(always)]
fn advance(
    i_back: f64,
    ds: f64,
    (tau, e): (f64, f64),
    (s_here, ext_here): (f64, f64),
    s_back: f64,
) -> f64 {
    if tau > 1e-6 {
        let mean_ext = tau / ds;
        let total = (s_here + s_back) / mean_ext;
        let a = s_here / ext_here.max(mean_ext);
        let q = (1.0 - e) / tau;
        i_back * e + a * (1.0 - q) + (total - a) * (q - e)
    } else {
        i_back * (1.0 - tau) + 0.5 * ds * (s_here + s_back)
    }
}

/// Σ_k a_k b_k over [`PADDED`] harmonics, in [`LANES`] partial sums. Not inlined: inlined
/// into the loop over directions, the compiler vectorized that loop instead, with gathers.
#[inline(never)]
fn dot(a: &[f64; PADDED], b: &[f64; PADDED]) -> f64 {
    let mut lanes = [0.0; LANES];
    for (a, b) in a.chunks_exact(LANES).zip(b.chunks_exact(LANES)) {
        for d in 0..LANES {
            lanes[d] += a[d] * b[d];
        }
    }
    ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3]))
        + ((lanes[4] + lanes[5]) + (lanes[6] + lanes[7]))
}

/// Σ_d v_d Y(ω_d) over `ordinates`, the sums kept in registers (not inlined, as [`dot`]).
#[inline(never)]
fn project(v: &[f64], ordinates: &[Ordinate]) -> [f64; PADDED] {
    let mut sums = [0.0; PADDED];
    for (v, o) in v.iter().zip(ordinates) {
        for (sum, y) in sums.iter_mut().zip(&o.y) {
            *sum += v * y;
        }
    }
    sums
}

/// Layers of a sweep held before they are added to the round's moments: added one at a
/// time, a layer across x touches one voxel in each row of the grid (a page apart at 128³),
/// and the additions waited on memory; a block of layers adds a run of neighbours per row.
const LAYER_BLOCK: usize = 8;

/// Adds `block` (the entries of layers `ks` across `axis`, each layer's in [`layer_axes`]
/// order, one after the other) to `into`, in parallel.
fn add_layers(
    dims: [usize; 3],
    axis: usize,
    ks: &[usize],
    block: &[[f64; PER_VOXEL]],
    into: &mut [[f64; PER_VOXEL]],
) {
    let add = |to: &mut [f64; PER_VOXEL], from: &[f64; PER_VOXEL]| {
        for (t, f) in to.iter_mut().zip(from) {
            *t += f;
        }
    };
    let (nx, ny) = (dims[0], dims[1]);
    let size = block.len() / ks.len();
    match axis {
        // Layers x = k, ordered y then z: row m (along x) holds voxel m of each layer.
        0 => into.par_chunks_mut(nx).enumerate().for_each(|(m, row)| {
            for (j, &k) in ks.iter().enumerate() {
                add(&mut row[k], &block[j * size + m]);
            }
        }),
        // Layers y = k, ordered x then z: in slab z, the row y = k.
        1 => into
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(z, slab)| {
                for (j, &k) in ks.iter().enumerate() {
                    let from = &block[j * size + z * nx..j * size + (z + 1) * nx];
                    for (to, from) in slab[k * nx..(k + 1) * nx].iter_mut().zip(from) {
                        add(to, from);
                    }
                }
            }),
        // Layers z = k, ordered x then y: the slabs themselves.
        _ => {
            for (j, &k) in ks.iter().enumerate() {
                into[k * size..(k + 1) * size]
                    .par_iter_mut()
                    .zip(block[j * size..(j + 1) * size].par_iter())
                    .for_each(|(to, from)| add(to, from));
            }
        }
    }
}

/// One round of sweeps: every direction of `groups` with the emission from moments `m`,
/// returning the new moments (equal weights `weight`). The directions of a group share the
/// layer order, so each voxel's emission harmonics are formed once per group, and only two
/// layers of each direction's state are kept. Per direction the state one layer back is
/// [`crate::lighting::lattice::upwind`]'s (clear air outside: zero), and the step is [`advance`]'s.
pub(crate) fn sweep_round(
    grid: &DensityGrid,
    medium: &Medium,
    m: &[[f64; PER_VOXEL]],
    groups: &[Group],
    weight: f64,
) -> Vec<[f64; PER_VOXEL]> {
    let dims = grid.dims;
    let round = Round {
        grid,
        medium,
        m,
        y_sun: harmonics(medium.l),
        weight,
    };
    let mut next = vec![[0.0f64; PER_VOXEL]; m.len()];
    for group in groups {
        let a = group.axis;
        let (b, c) = layer_axes(a);
        let (nb, nc) = (dims[b], dims[c]);
        let count = group.ordinates.len();
        // Per voxel of a layer, per direction: I, σ′_t and S per channel.
        let mut prev = vec![[0.0f64; 9]; nb * nc * count];
        let mut cur = prev.clone();
        // The moments of the last layers, not yet added to `next`.
        let mut block = vec![[0.0f64; PER_VOXEL]; nb * nc * LAYER_BLOCK];
        let mut held: Vec<usize> = Vec::with_capacity(LAYER_BLOCK);
        let layers = crate::lighting::lattice::layer_order(dims[a], group.forward);
        let mut passes = Passes::over(grid, a);
        for pass in 0.. {
            let before = (pass > 0).then(|| prev.clone());
            for (step, &k) in layers.iter().enumerate() {
                let slot = held.len() * nb * nc;
                let acc = &mut block[slot..slot + nb * nc];
                round.layer(group, (k, step > 0 || pass > 0), (&prev, &mut cur), acc);
                if passes.counts() {
                    held.push(k);
                    if held.len() == LAYER_BLOCK || step + 1 == layers.len() {
                        add_layers(dims, a, &held, &block[..held.len() * nb * nc], &mut next);
                        held.clear();
                    }
                }
                std::mem::swap(&mut prev, &mut cur);
            }
            if passes.done_after(pass, before.as_deref(), &prev) {
                break;
            }
        }
    }
    next
}

/// What every layer of a round of sweeps reads: the grid, the medium and the moments `m`
/// whose emission it sweeps, the harmonics towards the sun, the directions' weight.
struct Round<'a> {
    grid: &'a DensityGrid,
    medium: &'a Medium,
    m: &'a [[f64; PER_VOXEL]],
    y_sun: [f64; HARMONICS],
    weight: f64,
}

impl Round<'_> {
    /// Layer `k` across `group`'s axis: each direction's state into `cur` from the layer behind
    /// in `prev` (clear air unless `behind`), and per voxel of the layer its directions'
    /// Σ_d weight I_d Y_k(ω_d) per channel into `acc`.
    fn layer(
        &self,
        group: &Group,
        (k, behind): (usize, bool),
        (prev, cur): (&[[f64; 9]], &mut [[f64; 9]]),
        acc: &mut [[f64; PER_VOXEL]],
    ) {
        let (medium, dims, weight) = (self.medium, self.grid.dims, self.weight);
        let stride = [1, dims[0], dims[0] * dims[1]];
        let a = group.axis;
        let (b, c) = layer_axes(a);
        let (nb, nc) = (dims[b], dims[c]);
        let count = group.ordinates.len();
        let wrap = (self.grid.wraps(b), self.grid.wraps(c));
        let back_of = |d: usize, u: f64, v: f64| -> [f64; 9] {
            let at = |ub: usize, vc: usize| &prev[(ub + vc * nb) * count + d];
            crate::lighting::lattice::upwind(at, (nb, nc), (u, v), [0.0; 9], wrap)
        };
        cur.par_chunks_mut(count)
            .zip(acc.par_iter_mut())
            .enumerate()
            .for_each_init(
                // weight I_d per channel, then direction.
                || vec![0.0f64; 3 * count],
                |weighted, (mi, (states, acc))| {
                    let (ub, vc) = (mi % nb, mi / nb);
                    let i = k * stride[a] + ub * stride[b] + vc * stride[c];
                    let s = emission(medium, i, &self.m[i], &self.y_sun);
                    let ext = medium.ext[i];

                    for (j, chunk) in group.ordinates.chunks(LANES).enumerate() {
                        let first = j * LANES;
                        let mut back = [[0.0f64; 9]; LANES];
                        let mut ds = [1.0f64; LANES];
                        // The emission towards each direction, S(ω_d) = Σ_k s_k Y_k(ω_d).
                        let mut s_here = [[0.0f64; LANES]; 3];
                        for (d, o) in chunk.iter().enumerate() {
                            if behind {
                                back[d] = back_of(
                                    first + d,
                                    ub as f64 + o.shift.0,
                                    vc as f64 + o.shift.1,
                                );
                            }
                            ds[d] = o.ds;
                            for ch in 0..3 {
                                s_here[ch][d] = dot(&s[ch], &o.y);
                            }
                        }
                        let mut radiance = [[0.0f64; LANES]; 3];
                        for ch in 0..3 {
                            let mean_ext: [f64; LANES] =
                                std::array::from_fn(|d| 0.5 * (ext[ch] + back[d][3 + ch]));
                            let tau: [f64; LANES] = std::array::from_fn(|d| mean_ext[d] * ds[d]);
                            let e = exp_neg(tau);
                            radiance[ch] = std::array::from_fn(|d| {
                                advance(
                                    back[d][ch],
                                    ds[d],
                                    (tau[d], e[d]),
                                    (s_here[ch][d], ext[ch]),
                                    back[d][6 + ch],
                                )
                            });
                        }
                        for (d, state) in states[first..first + chunk.len()].iter_mut().enumerate()
                        {
                            *state = [
                                radiance[0][d],
                                radiance[1][d],
                                radiance[2][d],
                                ext[0],
                                ext[1],
                                ext[2],
                                s_here[0][d],
                                s_here[1][d],
                                s_here[2][d],
                            ];
                            for (ch, r) in radiance.iter().enumerate() {
                                weighted[ch * count + first + d] = weight * r[d];
                            }
                        }
                    }
                    // Σ_d weight I_d Y_k(ω_d) per channel.
                    for (ch, w) in weighted.chunks_exact(count).enumerate() {
                        let sums = project(w, &group.ordinates);
                        acc[ch * HARMONICS..(ch + 1) * HARMONICS]
                            .copy_from_slice(&sums[..HARMONICS]);
                    }
                },
            );
    }
}

/// One round of sweeps over every direction of `dirs` with the emission from moments `m`: the
/// new moments, unaccelerated (what [`solve`] does per iteration before the acceleration).
pub fn sweep_once(
    grid: &DensityGrid,
    medium: &Medium,
    m: &[[f64; PER_VOXEL]],
    dirs: &[DVec3],
) -> Vec<[f64; PER_VOXEL]> {
    sweep_round(
        grid,
        medium,
        m,
        &groups(grid, dirs),
        4.0 * PI / dirs.len() as f64,
    )
}

/// Source iteration from `start` (moments per voxel, [`PER_VOXEL`]): each round sweeps every
/// direction of `dirs` with the source σ′_s (p′ ∗ I) + Q from the previous round's moments,
/// gathers the new moments (equal weights 4π/N), and lets `accelerate` correct them from the
/// old (diffusion synthetic acceleration); it stops when a round changes φ_00 by less than
/// `tolerance` (relative, rms, green) or after `max_iterations` rounds.
pub fn solve(
    grid: &DensityGrid,
    medium: &Medium,
    start: Vec<[f64; PER_VOXEL]>,
    dirs: &[DVec3],
    limits: (f64, usize),
    accelerate: impl FnMut(&[[f64; PER_VOXEL]], &mut [[f64; PER_VOXEL]]),
) -> (Vec<[f64; PER_VOXEL]>, Report) {
    let weight = 4.0 * PI / dirs.len() as f64;
    let groups = groups(grid, dirs);
    let round = |m: &[[f64; PER_VOXEL]]| {
        Ok::<_, std::convert::Infallible>(sweep_round(grid, medium, m, &groups, weight))
    };
    match solve_with(start, limits, round, accelerate) {
        Ok(solved) => solved,
        Err(never) => match never {},
    }
}

/// [`solve`]'s iteration with the sweeps of a round done by `round` (the CPU's
/// [`sweep_round`], or the GPU's [`super::transport_gpu::Sweeps::round`]), which may fail.
/// (A relight on the GPU keeps the whole iteration there: [`super::resident`].)
pub fn solve_with<E>(
    start: Vec<[f64; PER_VOXEL]>,
    (tolerance, max_iterations): (f64, usize),
    mut round: impl FnMut(&[[f64; PER_VOXEL]]) -> Result<Vec<[f64; PER_VOXEL]>, E>,
    mut accelerate: impl FnMut(&[[f64; PER_VOXEL]], &mut [[f64; PER_VOXEL]]),
) -> Result<(Vec<[f64; PER_VOXEL]>, Report), E> {
    let mut m = start;
    let mut report = Report::default();
    for _ in 0..max_iterations {
        if iterate(&mut m, &mut report, &mut round, &mut accelerate)? < tolerance {
            break;
        }
    }
    Ok((m, report))
}

/// One round of [`solve_with`]'s source iteration: `m` replaced by the accelerated round from
/// it, its relative change of φ_00 (rms, green) pushed to `report` and returned.
pub fn iterate<E>(
    m: &mut Vec<[f64; PER_VOXEL]>,
    report: &mut Report,
    round: impl FnOnce(&[[f64; PER_VOXEL]]) -> Result<Vec<[f64; PER_VOXEL]>, E>,
    accelerate: impl FnOnce(&[[f64; PER_VOXEL]], &mut [[f64; PER_VOXEL]]),
) -> Result<f64, E> {
    let mut next = round(m)?;
    accelerate(m, &mut next);
    let (mut d, mut t) = (0.0, 0.0);
    for (a, b) in next.iter().zip(m.iter()) {
        d += (a[HARMONICS] - b[HARMONICS]).powi(2);
        t += a[HARMONICS] * a[HARMONICS];
    }
    let change = (d / t.max(f64::MIN_POSITIVE)).sqrt();
    report.changes.push(change);
    *m = next;
    Ok(change)
}

/// A coarser grid for the transport: blocks of `factor`³ voxels of a fine grid (the last
/// blocks along an axis reaching past the fine box, where the medium is empty), with the
/// restriction of per-voxel quantities to it and the interpolation of its results back.
pub struct Coarse {
    /// The coarse grid (its densities unused, zero).
    pub grid: DensityGrid,
    factor: usize,
    fine: [usize; 3],
}

impl Coarse {
    /// The blocks of `factor`³ voxels of `fine`.
    pub fn new(fine: &DensityGrid, factor: usize) -> Self {
        let dims = Self::dims(fine.dims, factor);
        let h = crate::lighting::lattice::voxel_size(fine);
        let extent = DVec3::from_array(std::array::from_fn(|a| (dims[a] * factor) as f64 * h[a]));
        Self {
            grid: DensityGrid {
                min_m: fine.min_m,
                max_m: fine.min_m + extent,
                dims,
                data: vec![[0.0; crate::volume::MAX_FIELDS]; dims[0] * dims[1] * dims[2]],
                // Its blocks tile a periodic grid's period (the caller's choice of factor).
                periodic: fine.periodic,
            },
            factor,
            fine: fine.dims,
        }
    }

    /// The blocks of `factor`³ voxels along each axis of a grid of `fine` voxels (the last
    /// may reach past the grid).
    pub fn dims(fine: [usize; 3], factor: usize) -> [usize; 3] {
        fine.map(|d| d.div_ceil(factor))
    }

    /// The mean of `values` (per fine voxel) over each block, voxels past the fine box
    /// counting as zero.
    pub fn average<const N: usize>(&self, values: &[[f64; N]]) -> Vec<[f64; N]> {
        let [nx, ny, _] = self.grid.dims;
        let f = self.factor;
        let share = 1.0 / (f * f * f) as f64;
        let mut out = vec![[0.0; N]; self.grid.data.len()];
        out.par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(cz, slab)| {
                for z in cz * f..((cz + 1) * f).min(self.fine[2]) {
                    for y in 0..self.fine[1] {
                        let row = &mut slab[(y / f) * nx..(y / f + 1) * nx];
                        let first = (z * self.fine[1] + y) * self.fine[0];
                        for (x, v) in values[first..first + self.fine[0]].iter().enumerate() {
                            let o = &mut row[x / f];
                            for n in 0..N {
                                o[n] += share * v[n];
                            }
                        }
                    }
                }
            });
        out
    }

    /// `medium` averaged over each block: σ′_t, σ′_s and the sources by their means, p′'s
    /// moments weighted by σ′_s (what the block scatters).
    pub fn medium(&self, medium: &Medium) -> Medium {
        let flat_chi: Vec<[f64; 3 * (DEGREE + 1)]> = medium
            .chi
            .iter()
            .zip(&medium.sca)
            .map(|(chi, sca)| {
                std::array::from_fn(|k| {
                    sca[k / (DEGREE + 1)] * chi[k / (DEGREE + 1)][k % (DEGREE + 1)]
                })
            })
            .collect();
        let flat_sky: Vec<[f64; 12]> = medium
            .sky
            .iter()
            .map(|sky| std::array::from_fn(|k| sky[k / 4][k % 4]))
            .collect();
        let sca = self.average(&medium.sca);
        let chi = self
            .average(&flat_chi)
            .iter()
            .zip(&sca)
            .map(|(weighted, sca)| {
                std::array::from_fn(|c| {
                    std::array::from_fn(|l| {
                        if sca[c] > 0.0 {
                            weighted[c * (DEGREE + 1) + l] / sca[c]
                        } else if l == 0 {
                            1.0
                        } else {
                            0.0
                        }
                    })
                })
            })
            .collect();
        Medium {
            ext: self.average(&medium.ext),
            sca,
            chi,
            sun: self.average(&medium.sun),
            l: medium.l,
            sky: self
                .average(&flat_sky)
                .iter()
                .map(|s| std::array::from_fn(|c| std::array::from_fn(|k| s[c * 4 + k])))
                .collect(),
        }
    }
}

/// The diffuse light's energy balance per channel (per unit irradiance, m² · radiance · sr)
/// over the box of the outermost voxel centres: what the sources inside it emit, ∫∫Q dω dV;
/// what leaves through its faces, ∮F·n dA with the net flux F = ∫I ω dω = φ_1/Y_1 read at
/// the centres on them; what is absorbed inside it, ∫σ_a ∫I dω dV. Both integrals by the
/// trapezoid over the centres (a centre on a face of that box weighs ½ per axis it lies on
/// the face of, in volume and in area), so the surface is closed: read on the grid's own faces
/// with their whole areas instead, the flux half a voxel inside was counted over more than the
/// whole sphere around the light (a point source in a box of n voxels: 6 · 4 arcsin(1/(1 +
/// (1 − 1/n)²)) against 4π, +7.2 % at n = 16). Scattering moves light between directions only
/// (p′ is normalized), so a converged solution has source = out + absorbed up to the sweeps'
/// discretization.
#[derive(Debug, Clone, Copy, Default)]
pub struct Balance {
    /// ∫∫Q dω dV.
    pub source: f64,
    /// ∮F·n dA.
    pub out: f64,
    /// ∫σ_a ∫I dω dV.
    pub absorbed: f64,
}

/// [`Balance`] of `moments` (per voxel, [`PER_VOXEL`]) in `medium` on `grid`, per channel.
pub fn balance(grid: &DensityGrid, medium: &Medium, moments: &[[f64; PER_VOXEL]]) -> [Balance; 3] {
    let dims = grid.dims;
    let h: [f64; 3] = std::array::from_fn(|a| (grid.max_m[a] - grid.min_m[a]) / dims[a] as f64);
    let volume = h[0] * h[1] * h[2];
    let y1 = 0.488_602_511_902_919_9;
    let root = (4.0 * PI).sqrt();
    let mut out = [Balance::default(); 3];
    for (i, m) in moments.iter().enumerate() {
        let cell = [
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        ];
        // The trapezoid's weight along each axis: ½ on the outermost centres (a periodic
        // grid's x and z have none: its voxels there are neighbours, and no light leaves).
        let edge = |a: usize| !grid.wraps(a) && (cell[a] == 0 || cell[a] + 1 == dims[a]);
        let along: [f64; 3] =
            std::array::from_fn(|a| if dims[a] > 1 && edge(a) { 0.5 } else { 1.0 });
        let weight = along[0] * along[1] * along[2];
        for (c, b) in out.iter_mut().enumerate() {
            let o = c * HARMONICS;
            let sky = medium.sky[i][c];
            b.source += 4.0 * PI * (medium.sun[i][c] + sky[0]) * volume * weight;
            b.absorbed += (medium.ext[i][c] - medium.sca[i][c]) * root * m[o] * volume * weight;
            // Net flux per axis: φ_1m is (y, z, x) for m = −1, 0, 1.
            let flux = [m[o + 3] / y1, m[o + 1] / y1, m[o + 2] / y1];
            for a in 0..3 {
                // The face's area element at this centre: the trapezoid over the other axes.
                let area = volume / h[a] * weight / along[a];
                if grid.wraps(a) {
                    continue;
                }
                if cell[a] == 0 {
                    b.out -= flux[a] * area;
                }
                if cell[a] + 1 == dims[a] {
                    b.out += flux[a] * area;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Legendre polynomials P_0 … P_L at μ.
    fn legendre(mu: f64) -> [f64; DEGREE + 1] {
        let mut p = [0.0; DEGREE + 1];
        p[0] = 1.0;
        if DEGREE > 0 {
            p[1] = mu;
        }
        for l in 1..DEGREE {
            p[l + 1] = ((2 * l + 1) as f64 * mu * p[l] - l as f64 * p[l - 1]) / (l + 1) as f64;
        }
        p
    }

    /// One round as a sweep per direction (`crate::lighting::lattice::sweep`), the emission summed in
    /// its own terms: what [`sweep_round`] must equal.
    fn round_by_direction(
        grid: &DensityGrid,
        medium: &Medium,
        m: &[[f64; PER_VOXEL]],
        dirs: &[DVec3],
    ) -> Vec<[f64; PER_VOXEL]> {
        let weight = 4.0 * PI / dirs.len() as f64;
        let mut next = vec![[0.0f64; PER_VOXEL]; m.len()];
        for &w in dirs {
            let y = harmonics(w);
            let p_sun = legendre(w.dot(medium.l));
            let state = crate::lighting::lattice::sweep::<9>(grid, w, [0.0; 9], |i, back, ds| {
                let mut out = [0.0; 9];
                for c in 0..3 {
                    let ext = medium.ext[i][c];
                    let chi = &medium.chi[i][c];
                    let phase_sun: f64 = (0..=DEGREE)
                        .map(|l| (2 * l + 1) as f64 * chi[l] * p_sun[l])
                        .sum();
                    let sky = medium.sky[i][c];
                    let s_here = medium.sca[i][c] * scattered(&m[i][c * HARMONICS..], chi, &y)
                        + medium.sun[i][c] * phase_sun
                        + sky[0]
                        + 3.0 * (sky[1] * w.x + sky[2] * w.y + sky[3] * w.z);
                    let tau = 0.5 * (ext + back[3 + c]) * ds;
                    out[c] = advance(back[c], ds, (tau, (-tau).exp()), (s_here, ext), back[6 + c]);
                    out[3 + c] = ext;
                    out[6 + c] = s_here;
                }
                out
            });
            for (n, s) in next.iter_mut().zip(&state) {
                for c in 0..3 {
                    for k in 0..HARMONICS {
                        n[c * HARMONICS + k] += weight * s[c] * y[k];
                    }
                }
            }
        }
        next
    }

    #[test]
    fn a_round_of_grouped_sweeps_equals_a_sweep_per_direction() {
        // A lumpy medium on an uneven grid (every axis leads some directions), lit by the sun
        // and the sky, with moments that are not those of any one radiance.
        let grid = crate::lighting::lattice::fixture::uneven_grid();
        let n = grid.data.len();
        let wobble = crate::lighting::lattice::fixture::wobble;
        let medium = Medium {
            ext: (0..n)
                .map(|i| std::array::from_fn(|c| 3.0 * wobble(i, c) + 0.2))
                .collect(),
            sca: (0..n)
                .map(|i| std::array::from_fn(|c| 2.0 * wobble(i, c) + 0.1))
                .collect(),
            chi: (0..n)
                .map(|i| {
                    std::array::from_fn(|c| {
                        std::array::from_fn(|l| {
                            if l == 0 {
                                1.0
                            } else {
                                0.8 * wobble(i, c + l) / l as f64
                            }
                        })
                    })
                })
                .collect(),
            sun: (0..n)
                .map(|i| std::array::from_fn(|c| wobble(i, c + 5)))
                .collect(),
            l: DVec3::new(0.3, -0.4, -0.87).normalize(),
            sky: (0..n)
                .map(|i| {
                    std::array::from_fn(|c| std::array::from_fn(|k| 0.1 * wobble(i, c + k + 9)))
                })
                .collect(),
        };
        let m: Vec<[f64; PER_VOXEL]> = (0..n)
            .map(|i| {
                std::array::from_fn(|k| wobble(i, k + 20) / (1 + DEGREES[k % HARMONICS]) as f64)
            })
            .collect();
        let dirs = crate::lighting::lattice::fibonacci_directions(40);
        let want = round_by_direction(&grid, &medium, &m, &dirs);
        let got = sweep_round(&grid, &medium, &m, &groups(&grid, &dirs), 4.0 * PI / 40.0);
        let (worst, scale) = crate::lighting::lattice::largest_difference(&got, &want);
        assert!(scale > 1.0, "the round carries light: {scale}");
        assert!(
            worst < 1e-12 * scale,
            "worst difference {worst:e} of {scale}"
        );
    }

    #[test]
    fn a_coarse_grid_keeps_the_totals_and_its_lookup_is_exact_for_linear_fields() {
        // 7 × 6 × 5 voxels in blocks of 2: the last blocks along x and z reach past the box.
        let fine = DensityGrid {
            min_m: DVec3::new(-1.0, 0.0, 2.0),
            max_m: DVec3::new(0.4, 1.2, 3.0),
            dims: [7, 6, 5],
            data: vec![[0.0; crate::volume::MAX_FIELDS]; 210],
            periodic: false,
        };
        let coarse = Coarse::new(&fine, 2);
        assert_eq!(coarse.grid.dims, [4, 3, 3]);
        assert!((coarse.grid.max_m - DVec3::new(0.6, 1.2, 3.2)).length() < 1e-12);
        let values: Vec<[f64; 2]> = (0..210).map(|i| [i as f64, (i % 7) as f64 * 0.5]).collect();
        // Totals: the sum over the fine voxels equals the coarse sum times the block's count.
        let averaged = coarse.average(&values);
        for n in 0..2 {
            let fine_sum: f64 = values.iter().map(|v| v[n]).sum();
            let coarse_sum: f64 = averaged.iter().map(|v| 8.0 * v[n]).sum();
            assert!(
                (fine_sum - coarse_sum).abs() < 1e-9 * fine_sum,
                "{fine_sum} vs {coarse_sum}"
            );
        }
        // A field linear in position, given at the coarse centres, comes back exactly at the
        // fine centres between them as the gathers look it up there (lattice::trilinear on
        // the coarse grid, exact for it).
        let h = 0.2; // the fine voxel along every axis
        let linear = |x: f64, y: f64, z: f64| 1.0 + 2.0 * x - 3.0 * y + 0.5 * z;
        let at_coarse: Vec<[f64; 1]> = (0..36)
            .map(|i| {
                let (x, y, z) = (i % 4, (i / 4) % 3, i / 12);
                [linear(
                    (x as f64 + 0.5) * 2.0 * h,
                    (y as f64 + 0.5) * 2.0 * h,
                    (z as f64 + 0.5) * 2.0 * h,
                )]
            })
            .collect();
        let mut inside = 0;
        for i in 0..210 {
            let (x, y, z) = (i % 7, (i / 7) % 6, i / 42);
            let centre = |k: usize| (k as f64 + 0.5) * h;
            let p = fine.min_m + DVec3::new(centre(x), centre(y), centre(z));
            let v = crate::lighting::lattice::trilinear(&coarse.grid, &at_coarse, None, p);
            let u = |k: usize, n: usize| {
                (k as f64 + 0.5) / 2.0 - 0.5 >= 0.0
                    && (k as f64 + 0.5) / 2.0 - 0.5 <= (n - 1) as f64
            };
            if u(x, 4) && u(y, 3) && u(z, 3) {
                let want = linear(
                    (x as f64 + 0.5) * h,
                    (y as f64 + 0.5) * h,
                    (z as f64 + 0.5) * h,
                );
                assert!((v[0] - want).abs() < 1e-12, "voxel {i}: {} vs {want}", v[0]);
                inside += 1;
            }
        }
        assert!(inside > 40, "{inside}");
    }

    #[test]
    fn the_vectorized_exponential_agrees_with_the_library_s() {
        let mut worst: f64 = 0.0;
        for i in 0..=70_000 {
            let tau: [f64; LANES] = std::array::from_fn(|d| (i * LANES + d) as f64 * 1.25e-3);
            for (d, e) in exp_neg(tau).iter().enumerate() {
                if tau[d] <= 700.0 {
                    worst = worst.max((e / (-tau[d]).exp() - 1.0).abs());
                } else {
                    assert_eq!(*e, 0.0);
                }
            }
        }
        eprintln!("exp_neg: worst relative error {worst:e}");
        assert!(worst < EXP_TOLERANCE, "worst relative error {worst:e}");
    }

    /// [`exp_neg`]'s worst relative error over τ ∈ [0, 700] (steps of 1/800), just above the
    /// measured 3.3·10⁻¹⁶ against the library's e^−τ.
    const EXP_TOLERANCE: f64 = 4e-16;

    #[test]
    fn the_harmonics_are_orthonormal() {
        let dirs = crate::lighting::lattice::fibonacci_directions(20_000);
        let w = 4.0 * PI / dirs.len() as f64;
        let mut gram = [[0.0; HARMONICS]; HARMONICS];
        for d in &dirs {
            let y = harmonics(*d);
            for a in 0..HARMONICS {
                for b in 0..HARMONICS {
                    gram[a][b] += w * y[a] * y[b];
                }
            }
        }
        for a in 0..HARMONICS {
            for b in 0..HARMONICS {
                let want = if a == b { 1.0 } else { 0.0 };
                assert!(
                    (gram[a][b] - want).abs() < 1e-3,
                    "∫Y_{a} Y_{b} = {} (want {want})",
                    gram[a][b]
                );
            }
        }
    }

    #[test]
    fn the_addition_theorem_holds() {
        // Σ_m Y_lm(a) Y_lm(b) = (2l + 1)/(4π) P_l(a·b).
        let (a, b) = (
            DVec3::new(0.3, -0.5, 0.81).normalize(),
            DVec3::new(-0.7, 0.2, 0.4).normalize(),
        );
        let (ya, yb) = (harmonics(a), harmonics(b));
        let p = legendre(a.dot(b));
        for l in 0..=DEGREE {
            let sum: f64 = (l * l..(l + 1) * (l + 1)).map(|k| ya[k] * yb[k]).sum();
            let want = (2 * l + 1) as f64 / (4.0 * PI) * p[l];
            assert!((sum - want).abs() < 1e-12, "l {l}: {sum} vs {want}");
        }
    }
}
