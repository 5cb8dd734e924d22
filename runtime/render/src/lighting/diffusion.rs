//! The diffusion equation of Max et al. 2004 §2 on the voxel grid, by finite volumes, solved by
//! conjugate gradients preconditioned with a geometric multigrid V-cycle.
//!
//! # The equation
//! With the diffuse radiance I_d(x, ω) ≈ I_0(x) + I_1(x)·ω (Eq. 3), κ_t the extinction, κ_a the
//! absorption and κ_tr = κ_t (1 − α g) the transport coefficient (§2), integrating the transfer
//! equation over the sphere, and over the sphere times ω, gives (our derivation, after Ishimaru
//! 1978 §9; the paper's Eq. 4 in flux form)
//!
//!   ∇·J = Q_0 − κ_a I_0,   J = Q_1/κ_tr − D ∇I_0,   D = 1/(3 κ_tr),
//!
//! J being the diffuse flux over 4π, Q_0 the first-scattered external light averaged over the
//! sphere (Eq. 5) and Q_1 its ω-weighted average (Eq. 6). Eliminating J gives Eq. 4,
//! ∇·(D∇I_0) − κ_a I_0 = −Q_0 + ∇·(Q_1/κ_tr).
//!
//! # The boundary (Eq. 7)
//! At a face towards an empty voxel no diffuse light flows inwards: ∫_{ω·n<0} I_d |ω·n| dω = 0
//! with n the outward normal. For the linear I_d that is I_1·n = (3/2) I_0, so the outward flux
//! there is J·n = I_0/2 at the face (Marshak's condition, the paper's Eq. 7 solved for the flux).
//! With the face value extrapolated from the cell, I_f = I_i + (h/2) ∂I/∂n, and J·n = Q_1·n/κ_tr
//! − D ∂I/∂n, the boundary face carries I_i D/(2D + h/2) + (Q_1·n/κ_tr) h/(4D + h) out.
//!
//! # The discretization
//! One unknown per voxel with κ_t > 0. Per voxel i of sides h_x, h_y, h_z and volume V, the
//! fluxes out of its six faces (of area V/h_a) balance its sources: at a face shared with voxel
//! j, D_f (I_i − I_j)/h_a + (Q_1/κ_tr)_f·n with D_f from the mean κ_tr of the two voxels (the
//! paper averages their densities) and (Q_1/κ_tr)_f the mean of the two; at a face to an empty
//! voxel, the boundary flux above; the sum equals V (Q_0 − κ_a I_i). The matrix is symmetric and positive definite (an M-matrix
//! when κ_a ≥ 0).
//!
//! # The solver
//! Conjugate gradients with a multigrid V-cycle as preconditioner. The hierarchy halves the
//! grid per level (the octree of the paper, which used Hypre): a coarse voxel is active when
//! any of its ≤ 8 children is, the coarse operator is the Galerkin product Pᵀ A P with P the
//! piecewise-constant prolongation (which keeps the 7-point stencil), smoothing is red-black
//! Gauss–Seidel (red then black before the coarse correction, black then red after, so the
//! V-cycle is a symmetric preconditioner). Iterations stop at a relative residual ‖b − A x‖/‖b‖
//! below the tolerance, or fail at the iteration cap, naming both.

use std::time::Instant;

/// The linear system of one channel on a grid of `dims` voxels of size `h` (see module docs).
#[derive(Debug, Clone)]
pub struct Problem {
    /// Voxels per axis, x fastest.
    pub dims: [usize; 3],
    /// Voxel size per axis (m).
    pub h: [f64; 3],
    /// κ_tr per voxel (1/m); 0 marks an empty voxel (no unknown).
    pub kappa_tr: Vec<f64>,
    /// κ_a per voxel (1/m), ≥ 0.
    pub kappa_a: Vec<f64>,
    /// Q_0 per voxel (radiance per metre).
    pub q0: Vec<f64>,
    /// Q_1 per voxel (a vector, radiance per metre).
    pub q1: Vec<[f64; 3]>,
    /// x and z repeat (a periodic grid): the voxels at opposite faces are neighbours.
    pub periodic: bool,
}

/// What lies beyond a voxel's face along one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Beyond {
    /// Voxel j (across the box's faces on a repeating axis).
    Voxel(usize),
    /// The box's face.
    Face,
    /// The voxel itself: one voxel across a repeating axis, whose faces carry no net flux.
    Itself,
}

/// Beyond the face of voxel `i` (coordinates `c`) on side `sign` (±1) of axis `a` of a grid of
/// `dims` whose axes `wrap` or not.
#[inline(always)]
pub(crate) fn beyond(
    dims: [usize; 3],
    wrap: [bool; 3],
    i: usize,
    c: [usize; 3],
    a: usize,
    sign: f64,
) -> Beyond {
    let n = dims[a];
    let stride = [1, dims[0], dims[0] * dims[1]][a];
    if sign > 0.0 {
        if c[a] + 1 < n {
            return Beyond::Voxel(i + stride);
        }
    } else if c[a] > 0 {
        return Beyond::Voxel(i - stride);
    }
    match (wrap[a], n) {
        (false, _) => Beyond::Face,
        (true, 1) => Beyond::Itself,
        (true, _) if sign > 0.0 => Beyond::Voxel(i - (n - 1) * stride),
        (true, _) => Beyond::Voxel(i + (n - 1) * stride),
    }
}

/// A converged solution and what it cost.
#[derive(Debug, Clone)]
pub struct Solution {
    /// I_0 per voxel (0 in empty voxels).
    pub i0: Vec<f64>,
    /// Conjugate-gradient iterations taken.
    pub iterations: usize,
    /// The relative residual reached.
    pub residual: f64,
    /// Levels of the multigrid hierarchy.
    pub levels: usize,
    /// Active voxels (unknowns).
    pub unknowns: usize,
    /// Wall-clock seconds of the setup and solve.
    pub seconds: f64,
}

impl Solution {
    /// The solution of a system without unknowns or sources: zero everywhere.
    pub(crate) fn zero(n: usize, unknowns: usize, start: Instant) -> Self {
        Self {
            i0: vec![0.0; n],
            iterations: 0,
            residual: 0.0,
            levels: 0,
            unknowns,
            seconds: start.elapsed().as_secs_f64(),
        }
    }
}

/// A solve that did not reach its tolerance: within the iteration cap, or because its residual
/// stopped being a number (then no cap would help, and the message says so).
#[derive(Debug, thiserror::Error)]
pub struct NotConverged {
    /// Residual reached (NaN or infinite where the arithmetic broke down).
    pub residual: f64,
    /// Iterations taken (the cap, or the iteration where the residual went non-finite).
    pub iterations: usize,
    /// The tolerance asked for.
    pub tolerance: f64,
}

impl std::fmt::Display for NotConverged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (residual, iterations, tolerance) = (self.residual, self.iterations, self.tolerance);
        if residual.is_finite() {
            write!(
                f,
                "the diffusion solve did not converge: relative residual {residual:.3e} after \
                 {iterations} iterations (the cap), tolerance {tolerance:.1e}; raise \
                 max_diffusion_iterations or loosen diffusion_tolerance"
            )
        } else {
            write!(
                f,
                "the diffusion solve broke down: its relative residual is {residual} after \
                 {iterations} iterations (the operator or its sources are not finite in \
                 floating point at these optical depths; more iterations would not help)"
            )
        }
    }
}

/// A 7-point symmetric operator: A_ii = diag, A_{i,i+e_a} = −w[a][i].
#[derive(Debug, Clone)]
pub(crate) struct Stencil {
    pub(crate) dims: [usize; 3],
    /// Which axes repeat (a periodic grid's x and z): the last voxel's +neighbour is the first.
    pub(crate) wrap: [bool; 3],
    pub(crate) diag: Vec<f64>,
    /// Couplings to the +x, +y, +z neighbours (≥ 0), 0 where either side is inactive (or no
    /// neighbour is).
    pub(crate) w: [Vec<f64>; 3],
}

impl Stencil {
    fn len(&self) -> usize {
        self.diag.len()
    }

    fn coords(&self, i: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [i % nx, (i / nx) % ny, i / (nx * ny)]
    }

    /// (A x)_i, with the neighbours' couplings.
    fn row_dot(&self, x: &[f64], i: usize, c: [usize; 3]) -> f64 {
        let mut s = self.diag[i] * x[i];
        for a in 0..3 {
            if let Beyond::Voxel(j) = beyond(self.dims, self.wrap, i, c, a, 1.0) {
                s -= self.w[a][i] * x[j];
            }
            if let Beyond::Voxel(j) = beyond(self.dims, self.wrap, i, c, a, -1.0) {
                s -= self.w[a][j] * x[j];
            }
        }
        s
    }

    pub(crate) fn apply(&self, x: &[f64], out: &mut [f64]) {
        use rayon::prelude::*;
        out.par_iter_mut().enumerate().for_each(|(i, o)| {
            *o = if self.diag[i] > 0.0 {
                self.row_dot(x, i, self.coords(i))
            } else {
                0.0
            };
        });
    }

    /// One Gauss–Seidel sweep over the voxels of colour `colour` ((x + y + z) mod 2). A voxel's
    /// neighbours are all of the other colour, so the colour's new values depend only on the
    /// other colour's: they are computed from `x` in parallel (plane by plane) into `scratch`,
    /// then written back, the same arithmetic as a serial sweep.
    fn sweep(&self, x: &mut [f64], b: &[f64], colour: usize, scratch: &mut [f64]) {
        use rayon::prelude::*;
        let [nx, ny, _] = self.dims;
        let plane = nx * ny;
        let each = |z: usize, f: &mut dyn FnMut(usize, usize)| {
            for y in 0..ny {
                let start = (colour + y + z) % 2;
                for xx in (start..nx).step_by(2) {
                    let i = xx + nx * (y + ny * z);
                    if self.diag[i] > 0.0 {
                        f(i, xx + nx * y);
                    }
                }
            }
        };
        let read: &[f64] = x;
        scratch
            .par_chunks_mut(plane)
            .enumerate()
            .for_each(|(z, out)| {
                each(z, &mut |i, j| {
                    let d = self.diag[i];
                    let c = [j % nx, j / nx, z];
                    let off = self.row_dot(read, i, c) - d * read[i];
                    out[j] = (b[i] - off) / d;
                });
            });
        x.par_chunks_mut(plane)
            .zip(scratch.par_chunks(plane))
            .enumerate()
            .for_each(|(z, (out, new))| each(z, &mut |_, j| out[j] = new[j]));
    }

    /// The Galerkin coarse operator Pᵀ A P for piecewise-constant P over 2×2×2 blocks (on a
    /// repeating axis of odd length the last block holds one voxel, whose +neighbour is the
    /// first block's).
    fn coarsen(&self) -> Stencil {
        let cd = self.dims.map(|n| n.div_ceil(2));
        let cn = cd[0] * cd[1] * cd[2];
        let mut diag = vec![0.0; cn];
        let mut w = [vec![0.0; cn], vec![0.0; cn], vec![0.0; cn]];
        let at = |c: [usize; 3]| c[0] + cd[0] * (c[1] + cd[1] * c[2]);
        for i in 0..self.len() {
            if self.diag[i] <= 0.0 {
                continue;
            }
            let c = self.coords(i);
            let ci = at(c.map(|v| v / 2));
            diag[ci] += self.diag[i];
            for a in 0..3 {
                let wij = self.w[a][i];
                if wij == 0.0 {
                    continue;
                }
                // The +neighbour's block: the next one, or across a repeating axis the first.
                let next = (c[a] + 1) % self.dims[a] / 2;
                if next == c[a] / 2 {
                    // Both in the same coarse voxel: −w twice (A_ij and A_ji) on its diagonal.
                    diag[ci] -= 2.0 * wij;
                } else {
                    w[a][ci] += wij;
                }
            }
        }
        Stencil {
            dims: cd,
            wrap: self.wrap,
            diag,
            w,
        }
    }
}

/// The operator and right-hand side of `p` (module docs, "The discretization").
pub(crate) fn assemble(p: &Problem) -> (Stencil, Vec<f64>) {
    let [nx, ny, nz] = p.dims;
    let n = nx * ny * nz;
    let h = p.h;
    let volume = h[0] * h[1] * h[2];
    let mut diag = vec![0.0; n];
    let mut w = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    let mut b = vec![0.0; n];
    let wrap = [p.periodic, false, p.periodic];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let i = x + nx * (y + ny * z);
                let k = p.kappa_tr[i];
                if k <= 0.0 {
                    continue;
                }
                let d_i = 1.0 / (3.0 * k);
                let c = [x, y, z];
                diag[i] += volume * p.kappa_a[i];
                b[i] += volume * p.q0[i];
                for a in 0..3 {
                    let (area, ha) = (volume / h[a], h[a]);
                    for (side, sign) in [(0usize, -1.0f64), (1, 1.0)] {
                        let neighbour = match beyond(p.dims, wrap, i, c, a, sign) {
                            Beyond::Voxel(j) => Some(j),
                            Beyond::Face => None,
                            Beyond::Itself => continue,
                        }
                        .filter(|&j| p.kappa_tr[j] > 0.0);
                        // Q_1·n/κ_tr on this face, n the outward normal (sign along axis a).
                        match neighbour {
                            Some(j) => {
                                let kf = 0.5 * (k + p.kappa_tr[j]);
                                let d_f = 1.0 / (3.0 * kf);
                                diag[i] += area * d_f / ha;
                                if side == 1 {
                                    w[a][i] = area * d_f / ha;
                                }
                                let qn = 0.5 * (p.q1[i][a] / k + p.q1[j][a] / p.kappa_tr[j]);
                                b[i] -= area * sign * qn;
                            }
                            None => {
                                diag[i] += area * d_i / (2.0 * d_i + 0.5 * ha);
                                let qn = sign * p.q1[i][a] / k;
                                b[i] -= area * qn * ha / (4.0 * d_i + ha);
                            }
                        }
                    }
                }
            }
        }
    }
    (
        Stencil {
            dims: p.dims,
            wrap,
            diag,
            w,
        },
        b,
    )
}

/// Checks a model's solver settings `[render.<model>] diffusion_tolerance` and
/// `max_diffusion_iterations`, naming the key, its value and the allowed range.
pub fn check_settings(
    tolerance: f64,
    max_iterations: usize,
) -> Result<(), crate::checks::FrameError> {
    if !(1e-12..=0.1).contains(&tolerance) {
        return Err(crate::checks::FrameError(format!(
            "diffusion_tolerance = {} is outside the allowed range [1e-12, 0.1] (relative \
             residual; f64 arithmetic cannot reach less)",
            crate::checks::Shown(tolerance)
        )));
    }
    if !(1..=100_000).contains(&max_iterations) {
        return Err(crate::checks::FrameError(format!(
            "max_diffusion_iterations = {max_iterations} is outside the allowed range [1, 100000]"
        )));
    }
    Ok(())
}

/// The diffuse flux J (over 4π, per channel's problem) at every voxel of `p` from its
/// solution `i0`: along each axis the mean of the fluxes through the voxel's two faces, each as
/// the discretization has it (module docs: D_f (I_i − I_j)/h_a + (Q_1/κ_tr)_f between two
/// voxels, Marshak's I_i D/(2D + h/2) + (Q_1·n/κ_tr) h/(4D + h) out of a face to an empty
/// voxel). So the flux out of a voxel's faces is what its balance says, and the P1 radiance
/// I_0 + 3 J·ω follows the solve. Zero at empty voxels.
pub fn flux(p: &Problem, i0: &[f64]) -> Vec<[f64; 3]> {
    use rayon::prelude::*;
    (0..i0.len())
        .into_par_iter()
        .map(|i| {
            if p.kappa_tr[i] <= 0.0 {
                return [0.0; 3];
            }
            std::array::from_fn(|a| {
                -0.5 * face_out(p, i0, i, a, -1.0) + 0.5 * face_out(p, i0, i, a, 1.0)
            })
        })
        .collect()
}

/// The flux out of voxel `i`'s face on side `sign` (±1) of axis `a`, along that face's outward
/// normal, as the discretization has it (module docs), and whether that face borders an empty
/// voxel or the box (the boundary).
fn face(p: &Problem, i0: &[f64], i: usize, a: usize, sign: f64) -> (f64, bool) {
    let [nx, ny, _] = p.dims;
    let c = [i % nx, (i / nx) % ny, i / (nx * ny)];
    let k = p.kappa_tr[i];
    let ha = p.h[a];
    let wrap = [p.periodic, false, p.periodic];
    let neighbour = match beyond(p.dims, wrap, i, c, a, sign) {
        Beyond::Voxel(j) => Some(j),
        Beyond::Face => None,
        Beyond::Itself => return (0.0, false),
    }
    .filter(|&j| p.kappa_tr[j] > 0.0);
    match neighbour {
        Some(j) => {
            let d_f = 1.0 / (1.5 * (k + p.kappa_tr[j]));
            let qn = 0.5 * (p.q1[i][a] / k + p.q1[j][a] / p.kappa_tr[j]);
            (d_f * (i0[i] - i0[j]) / ha + sign * qn, false)
        }
        None => {
            let d_i = 1.0 / (3.0 * k);
            let out = i0[i] * d_i / (2.0 * d_i + 0.5 * ha)
                + sign * p.q1[i][a] / k * ha / (4.0 * d_i + ha);
            (out, true)
        }
    }
}

/// [`face`]'s flux alone.
fn face_out(p: &Problem, i0: &[f64], i: usize, a: usize, sign: f64) -> f64 {
    face(p, i0, i, a, sign).0
}

/// The balance of a solution `i0` of `p` over its voxels: ∫Q_0 dV, the flux out through the
/// boundary faces ∮J·n dA, and ∫κ_a I_0 dV (per 4π; equal sources and sinks at convergence).
#[derive(Debug, Clone, Copy, Default)]
pub struct Balance {
    /// ∫Q_0 dV.
    pub source: f64,
    /// ∮J·n dA over the faces to empty voxels and the box.
    pub out: f64,
    /// ∫κ_a I_0 dV.
    pub absorbed: f64,
}

/// [`Balance`] of `i0`, a solution of `p`.
pub fn balance(p: &Problem, i0: &[f64]) -> Balance {
    let volume = p.h[0] * p.h[1] * p.h[2];
    let mut b = Balance::default();
    for i in 0..i0.len() {
        b.source += p.q0[i] * volume;
        if p.kappa_tr[i] <= 0.0 {
            continue;
        }
        b.absorbed += p.kappa_a[i] * i0[i] * volume;
        for a in 0..3 {
            for sign in [-1.0, 1.0] {
                if let (out, true) = face(p, i0, i, a, sign) {
                    b.out += out * volume / p.h[a];
                }
            }
        }
    }
    b
}

/// The multigrid hierarchy: level 0 is the fine operator.
struct Hierarchy {
    levels: Vec<Stencil>,
}

/// Sweeps of each colour, in the order 0, 1, 1, 0, that solve the coarsest level of a V-cycle.
pub(crate) const COARSEST_SWEEPS: usize = 32;

/// Coarsening stops below this many voxels; the coarsest level is smoothed to convergence.
const COARSEST_VOXELS: usize = 64;

impl Hierarchy {
    fn new(fine: Stencil) -> Self {
        let mut levels = vec![fine];
        loop {
            let last = levels.last().expect("one level");
            if last.len() <= COARSEST_VOXELS || last.dims.iter().all(|&n| n <= 2) {
                break;
            }
            let next = last.coarsen();
            levels.push(next);
        }
        Self { levels }
    }

    /// z ≈ A⁻¹ r by one V-cycle from z = 0 (symmetric: see module docs).
    fn vcycle(&self, level: usize, r: &[f64], z: &mut [f64]) {
        use rayon::prelude::*;
        let a = &self.levels[level];
        z.par_iter_mut().for_each(|v| *v = 0.0);
        let mut scratch = vec![0.0; a.len()];
        if level + 1 == self.levels.len() {
            for _ in 0..COARSEST_SWEEPS {
                a.sweep(z, r, 0, &mut scratch);
                a.sweep(z, r, 1, &mut scratch);
                a.sweep(z, r, 1, &mut scratch);
                a.sweep(z, r, 0, &mut scratch);
            }
            return;
        }
        a.sweep(z, r, 0, &mut scratch);
        a.sweep(z, r, 1, &mut scratch);
        let mut res = scratch;
        a.apply(z, &mut res);
        res.par_iter_mut().zip(r).for_each(|(q, &rv)| *q = rv - *q);
        // Restriction: each coarse voxel sums its (up to 8) active fine voxels, in the order
        // of the fine index.
        let coarse = &self.levels[level + 1];
        let cd = coarse.dims;
        let [nx, ny, nz] = a.dims;
        let mut rc = vec![0.0; coarse.len()];
        rc.par_iter_mut().enumerate().for_each(|(ci, out)| {
            let c = [ci % cd[0], (ci / cd[0]) % cd[1], ci / (cd[0] * cd[1])];
            let mut sum = 0.0;
            for fz in 2 * c[2]..(2 * c[2] + 2).min(nz) {
                for fy in 2 * c[1]..(2 * c[1] + 2).min(ny) {
                    for fx in 2 * c[0]..(2 * c[0] + 2).min(nx) {
                        let i = fx + nx * (fy + ny * fz);
                        if a.diag[i] > 0.0 {
                            sum += res[i];
                        }
                    }
                }
            }
            *out = sum;
        });
        let mut zc = vec![0.0; coarse.len()];
        self.vcycle(level + 1, &rc, &mut zc);
        z.par_iter_mut().enumerate().for_each(|(i, zi)| {
            if a.diag[i] > 0.0 {
                let c = a.coords(i).map(|v| v / 2);
                *zi += zc[c[0] + cd[0] * (c[1] + cd[1] * c[2])];
            }
        });
        let mut scratch = res;
        a.sweep(z, r, 1, &mut scratch);
        a.sweep(z, r, 0, &mut scratch);
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    use rayon::prelude::*;
    a.par_iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solves `p` to relative residual `tolerance` within `max_iterations` conjugate-gradient
/// iterations (module docs, "The solver").
pub fn solve(p: &Problem, tolerance: f64, max_iterations: usize) -> Result<Solution, NotConverged> {
    let start = Instant::now();
    let (a, b) = assemble(p);
    let mut s = Operator::new(a).solve(&b, tolerance, max_iterations)?;
    s.seconds = start.elapsed().as_secs_f64();
    Ok(s)
}

/// A problem's operator and its multigrid hierarchy, assembled once for several sources
/// (the transport's acceleration solves the same operator every round).
pub struct Operator {
    mg: Option<Hierarchy>,
    diag: Vec<f64>,
    volume: f64,
}

impl Operator {
    /// The operator of `p` (its sources, which must have one value per voxel, are not used).
    pub fn of(p: &Problem) -> Self {
        let mut op = Self::new(assemble(p).0);
        op.volume = p.h.iter().product();
        op
    }

    pub(crate) fn new(a: Stencil) -> Self {
        let unknowns = a.diag.iter().filter(|&&d| d > 0.0).count();
        let diag = a.diag.clone();
        Self {
            mg: (unknowns > 0).then(|| Hierarchy::new(a)),
            diag,
            volume: 0.0,
        }
    }

    /// Solves for an isotropic source `q0` per voxel (Q_1 = 0), as [`solve`].
    pub fn solve_isotropic(
        &self,
        q0: &[f64],
        tolerance: f64,
        max_iterations: usize,
    ) -> Result<Solution, NotConverged> {
        self.solve(&self.isotropic(q0), tolerance, max_iterations)
    }

    /// The right-hand side of an isotropic source `q0` per voxel.
    pub fn isotropic(&self, q0: &[f64]) -> Vec<f64> {
        q0.iter()
            .zip(&self.diag)
            .map(|(q, d)| if *d > 0.0 { self.volume * q } else { 0.0 })
            .collect()
    }

    /// The multigrid hierarchy's operators, finest first (none without unknowns).
    pub(crate) fn levels(&self) -> &[Stencil] {
        self.mg.as_ref().map_or(&[], |m| &m.levels)
    }

    /// Conjugate gradients preconditioned by one V-cycle, for the right-hand side `b`.
    fn solve(
        &self,
        b: &[f64],
        tolerance: f64,
        max_iterations: usize,
    ) -> Result<Solution, NotConverged> {
        use rayon::prelude::*;
        let start = Instant::now();
        let unknowns = self.diag.iter().filter(|&&d| d > 0.0).count();
        let n = self.diag.len();
        let b_norm = dot(b, b).sqrt();
        // A source that is not a number would read as none below (NaN > 0 is false).
        if !b_norm.is_finite() {
            return Err(NotConverged {
                residual: b_norm,
                iterations: 0,
                tolerance,
            });
        }
        let Some(mg) = self.mg.as_ref().filter(|_| b_norm > 0.0) else {
            return Ok(Solution::zero(n, unknowns, start));
        };
        let mut x = vec![0.0; n];
        let a = &mg.levels[0];
        let mut r = b.to_vec();
        let mut z = vec![0.0; n];
        mg.vcycle(0, &r, &mut z);
        let mut d = z.clone();
        let mut rz = dot(&r, &z);
        let mut ad = vec![0.0; n];
        let mut residual = 1.0;
        for it in 1..=max_iterations {
            a.apply(&d, &mut ad);
            let alpha = rz / dot(&d, &ad);
            x.par_iter_mut()
                .zip(r.par_iter_mut())
                .zip(d.par_iter().zip(&ad))
                .for_each(|((xi, ri), (di, adi))| {
                    *xi += alpha * di;
                    *ri -= alpha * adi;
                });
            residual = dot(&r, &r).sqrt() / b_norm;
            if !residual.is_finite() {
                return Err(NotConverged {
                    residual,
                    iterations: it,
                    tolerance,
                });
            }
            if residual < tolerance {
                return Ok(Solution {
                    i0: x,
                    iterations: it,
                    residual,
                    levels: mg.levels.len(),
                    unknowns,
                    seconds: start.elapsed().as_secs_f64(),
                });
            }
            mg.vcycle(0, &r, &mut z);
            let rz_new = dot(&r, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            d.par_iter_mut()
                .zip(&z)
                .for_each(|(di, zi)| *di = zi + beta * *di);
        }
        Err(NotConverged {
            residual,
            iterations: max_iterations,
            tolerance,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniform cube [−1, 1]³ filling a grid of n³ voxels, with a uniform isotropic source.
    fn cube(n: usize, kappa_tr: f64, kappa_a: f64, q0: f64) -> Problem {
        let cells = n * n * n;
        Problem {
            dims: [n; 3],
            periodic: false,
            h: [2.0 / n as f64; 3],
            kappa_tr: vec![kappa_tr; cells],
            kappa_a: vec![kappa_a; cells],
            q0: vec![q0; cells],
            q1: vec![[0.0; 3]; cells],
        }
    }

    /// The cube's exact solution at `x` by separation of variables: with the boundary
    /// condition −D I' = I/2 at ±1 the modes are cos(k x) with k tan k = 1/(2D), and
    /// I = (Q_0/D) Σ A_l A_m A_n φ_l φ_m φ_n / (k_l² + k_m² + k_n² + κ_a/D), A the modes'
    /// projections of 1.
    fn cube_exact(kappa_tr: f64, kappa_a: f64, q0: f64, points: &[[f64; 3]]) -> Vec<f64> {
        let d = 1.0 / (3.0 * kappa_tr);
        let beta = 1.0 / (2.0 * d);
        let modes: Vec<(f64, f64)> = (0..400)
            .map(|m| {
                // The root of k tan k = β in (mπ, mπ + π/2), by bisection.
                let (mut lo, mut hi) = (
                    m as f64 * std::f64::consts::PI + 1e-12,
                    m as f64 * std::f64::consts::PI + std::f64::consts::FRAC_PI_2 - 1e-12,
                );
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if mid * mid.tan() < beta {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                let k = 0.5 * (lo + hi);
                // ⟨1, cos kx⟩ / ⟨cos kx, cos kx⟩ over [−1, 1].
                (k, (2.0 * k.sin() / k) / (1.0 + (2.0 * k).sin() / (2.0 * k)))
            })
            .collect();
        points
            .iter()
            .map(|x| {
                let phi: Vec<[f64; 3]> = modes
                    .iter()
                    .map(|(k, a)| std::array::from_fn(|ax| a * (k * x[ax]).cos()))
                    .collect();
                let mut sum = 0.0;
                for (l, (kl, _)) in modes.iter().enumerate() {
                    for (m, (km, _)) in modes.iter().enumerate() {
                        for (n, (kn, _)) in modes.iter().enumerate() {
                            let denominator = kl * kl + km * km + kn * kn + kappa_a / d;
                            sum += phi[l][0] * phi[m][1] * phi[n][2] / denominator;
                        }
                    }
                }
                q0 / d * sum
            })
            .collect()
    }

    /// Worst relative errors of the solve of the cube at n³ against the series, over voxel
    /// centres on the diagonal and on an axis: (inside, in the boundary layer of voxels), and
    /// the iterations.
    fn cube_error(n: usize, kappa_tr: f64, kappa_a: f64) -> (f64, f64, usize) {
        let p = cube(n, kappa_tr, kappa_a, 1.0);
        let s = solve(&p, 1e-10, 200).unwrap();
        let centre = |i: usize| -1.0 + (i as f64 + 0.5) * p.h[0];
        let (mut at, mut points, mut boundary) = (Vec::new(), Vec::new(), Vec::new());
        for i in (0..n).step_by((n / 8).max(1)).chain([n - 1]) {
            let edge = i == 0 || i == n - 1;
            at.push(i + n * (i + n * i));
            points.push([centre(i); 3]);
            at.push(i + n * (n / 2 + n * (n / 2)));
            points.push([centre(i), centre(n / 2), centre(n / 2)]);
            boundary.extend([edge, edge]);
        }
        let exact = cube_exact(kappa_tr, kappa_a, 1.0, &points);
        let (mut inside, mut layer) = (0.0f64, 0.0f64);
        for ((&i, e), &b) in at.iter().zip(&exact).zip(&boundary) {
            let err = ((s.i0[i] - e) / e).abs();
            if b {
                layer = layer.max(err);
            } else {
                inside = inside.max(err);
            }
        }
        (inside, layer, s.iterations)
    }

    #[test]
    fn a_cube_matches_its_analytic_solution_to_second_order() {
        for (kappa_tr, kappa_a) in [(20.0, 0.0), (10.0, 2.0)] {
            let (e16, b16, it16) = cube_error(16, kappa_tr, kappa_a);
            let (e32, b32, it32) = cube_error(32, kappa_tr, kappa_a);
            eprintln!(
                "cube κ_tr {kappa_tr}, κ_a {kappa_a}: worst relative error inside {e16:.2e} at \
                 16³ ({it16} iterations), {e32:.2e} at 32³ ({it32} iterations); in the boundary \
                 voxels {b16:.2e} → {b32:.2e}"
            );
            // Inside, finite volumes are second order: the error falls ~4× per halving of h.
            assert!(e16 / e32 > 3.5, "{e16:e} → {e32:e}");
            assert!(e32 < 8e-3, "{e32:e}");
            // The boundary voxels extrapolate to their faces, first order (worst at corners).
            assert!(b32 < 0.65 * b16, "{b16:e} → {b32:e}");
        }
    }

    /// A uniform sphere of radius 0.9 in [−1, 1]³ at n³ voxels (staircase boundary).
    fn sphere(n: usize, kappa_tr: f64, kappa_a: f64, q0: f64) -> Problem {
        let mut p = cube(n, kappa_tr, kappa_a, q0);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let c = [x, y, z].map(|v| -1.0 + (v as f64 + 0.5) * p.h[0]);
                    if c.iter().map(|v| v * v).sum::<f64>() >= 0.81 {
                        let i = x + n * (y + n * z);
                        p.kappa_tr[i] = 0.0;
                        p.q0[i] = 0.0;
                    }
                }
            }
        }
        p
    }

    /// A source that is not a number breaks the solve down at once, and the error says so
    /// rather than asking for more iterations.
    #[test]
    fn a_residual_that_is_not_a_number_is_a_breakdown_not_a_cap() {
        let mut p = sphere(8, 30.0, 0.5, 1.0);
        let i = p.kappa_tr.iter().position(|&k| k > 0.0).unwrap();
        p.q0[i] = f64::NAN;
        let e = solve(&p, 1e-6, 500).unwrap_err();
        assert!(!e.residual.is_finite() && e.iterations < 500, "{e:?}");
        let message = e.to_string();
        assert!(message.contains("broke down"), "{message}");
        assert!(!message.contains("raise"), "{message}");
    }

    #[test]
    fn the_residual_is_what_it_reports_and_the_cap_is_enforced() {
        let mut p = sphere(24, 30.0, 0.5, 1.0);
        // A directional source too, so the Q_1 terms enter.
        for (q, k) in p.q1.iter_mut().zip(&p.kappa_tr) {
            if *k > 0.0 {
                *q = [0.0, -0.8, 0.0];
            }
        }
        let s = solve(&p, 1e-9, 200).unwrap();
        let (a, b) = assemble(&p);
        let mut ax = vec![0.0; a.len()];
        a.apply(&s.i0, &mut ax);
        let r: f64 = ax
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt();
        let bn: f64 = b.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(r / bn < 1e-9, "{}", r / bn);
        assert!(s.i0.iter().all(|v| *v >= 0.0 && v.is_finite()));
        let e = solve(&p, 1e-12, 2).unwrap_err();
        assert_eq!(e.iterations, 2);
        assert!(e.to_string().contains("after 2 iterations"), "{e}");
    }

    /// A periodic grid (x and z repeat): a layered problem is its one-column solution at every
    /// voxel of a layer (the column's x and z faces are the voxel's own, `Beyond::Itself`),
    /// and a source moved by one voxel across the faces moves the solution with it. Odd and
    /// even sizes, so that the coarse levels' last blocks hold one voxel.
    #[test]
    fn a_periodic_problem_wraps_across_its_faces() {
        let layered = |dims: [usize; 3]| {
            let n = dims[0] * dims[1] * dims[2];
            let y = |i: usize| (i / dims[0]) % dims[1];
            Problem {
                dims,
                periodic: true,
                h: [0.3, 0.2, 0.25],
                kappa_tr: (0..n).map(|i| 1.0 + 0.5 * y(i) as f64).collect(),
                kappa_a: vec![0.05; n],
                q0: (0..n).map(|i| if y(i) == 2 { 1.0 } else { 0.1 }).collect(),
                q1: (0..n).map(|i| [0.0, 0.2 * y(i) as f64, 0.0]).collect(),
            }
        };
        let column = solve(&layered([1, 9, 1]), 1e-12, 500).unwrap();
        for dims in [[5, 9, 6], [8, 9, 3]] {
            let s = solve(&layered(dims), 1e-12, 500).unwrap();
            let worst = (0..s.i0.len())
                .map(|i| (s.i0[i] / column.i0[(i / dims[0]) % dims[1]] - 1.0).abs())
                .fold(0.0f64, f64::max);
            eprintln!("{dims:?}: worst relative difference from the column {worst:.1e}");
            assert!(worst < 1e-11, "{dims:?}: {worst:e}");
        }
        // A point source at (0, 3, 0), and at (5, 3, 4): the second solution is the first
        // moved by −1 in x and z, across the faces.
        let dims = [6, 7, 5];
        let at = |x: usize, y: usize, z: usize| x + dims[0] * (y + dims[1] * z);
        let point = |x: usize, z: usize| {
            let mut p = layered(dims);
            p.q0 = vec![0.0; p.q0.len()];
            p.q1 = vec![[0.0; 3]; p.q0.len()];
            p.q0[at(x, 3, z)] = 1.0;
            solve(&p, 1e-12, 500).unwrap().i0
        };
        let (a, b) = (point(0, 0), point(5, 4));
        let mut worst: f64 = 0.0;
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let moved = a[at((x + 1) % dims[0], y, (z + 1) % dims[2])];
                    worst = worst.max((b[at(x, y, z)] - moved).abs() / a[at(0, 3, 0)]);
                }
            }
        }
        eprintln!("a source moved across the faces: worst difference {worst:.1e}");
        assert!(worst < 1e-11, "{worst:e}");
    }
}
