// The diffusion solve on the GPU (render::diffusion_gpu): conjugate gradients preconditioned by
// the multigrid V-cycle of render::diffusion, in f32, every kernel one of the CPU solver's loops.
// Each level's 7-point operator is one row per voxel (diag, w+x, w+y, w+z: A_ii = diag,
// A_{i,i+e_a} = −w_a); the vectors of every level live in one buffer at offsets the dispatch's
// parameters give.

struct Dispatch {
    dims: vec3<u32>,          // this level's nx, ny, nz
    colour: u32,              // a smoothing sweep's colour: (x + y + z) mod 2
    coarse_dims: vec3<u32>,   // the coarser level's nx, ny, nz (this level's without one)
    coarse_voxels: u32,       // its voxel count
    first_row: u32,           // this level's first row of `stencil`
    coarse_first_row: u32,    // the coarser level's
    voxels: u32,              // this level's voxel count
    product_only: u32,        // residual: 1 writes A b alone
    a: u32,                   // the kernel's vector operands, offsets in `v`: a, b, out and a
    b: u32,                   // fourth, c (the coarser level's z in prolong, A d in update_xr)
    out: u32,
    c: u32,
}

// A voxel's row of its level's 7-point operator: A_ii and the couplings w_a to the next voxel
// along each axis a (A_{i,i+e_a} = −w_a).
struct Stencil {
    diag: f32,
    coupling: array<f32, 3>,
}

@group(0) @binding(0) var<uniform> p: Dispatch;
@group(0) @binding(1) var<storage, read> stencil: array<Stencil>;
@group(0) @binding(2) var<storage, read_write> v: array<f32>;
@group(0) @binding(3) var<storage, read_write> partial: array<f32>;
// The iteration's scalars: α, β, then what the GPU-driven iteration (`scalars`) keeps: 1 once
// it has finished (every kernel then returns at once), r·z, r_0·r_0, the iterations taken,
// 1 where it converged, the relative residual to reach, the iteration cap.
@group(0) @binding(4) var<storage, read_write> coef: array<f32>;
const ALPHA: u32 = 0u;
const BETA: u32 = 1u;
const DONE: u32 = 2u;
const RZ: u32 = 3u;
const RR0: u32 = 4u;
const TAKEN: u32 = 5u;
const CONVERGED: u32 = 6u;
const TOLERANCE: u32 = 7u;
const CAP: u32 = 8u;

fn finished() -> bool {
    return coef[DONE] != 0.0;
}

const WG: u32 = 64u;
// Workgroups along x of a dispatch (the rest along y).
const ROW: u32 = 1024u;

var<workgroup> sums: array<f32, 64>;

fn index(wg: vec3<u32>, t: u32) -> u32 {
    return (wg.y * ROW + wg.x) * WG + t;
}

fn coords(i: u32, d: vec3<u32>) -> vec3<u32> {
    return vec3<u32>(i % d.x, (i / d.x) % d.y, i / (d.x * d.y));
}

// Σ_j w_ij x_j over the six neighbours of voxel i (at coordinates c) of the level starting at
// stencil row `o`, x at offset `x` of `v` (Stencil::row_dot without the diagonal, negated).
fn neighbours(o: u32, i: u32, c: vec3<u32>, x: u32) -> f32 {
    let d = p.dims;
    var stride = vec3<u32>(1u, d.x, d.x * d.y);
    var s = 0.0;
    for (var a = 0u; a < 3u; a = a + 1u) {
        let st = stride[a];
        if (c[a] + 1u < d[a]) {
            s = s + stencil[o + i].coupling[a] * v[x + i + st];
        }
        if (c[a] > 0u) {
            s = s + stencil[o + i - st].coupling[a] * v[x + i - st];
        }
    }
    return s;
}

// One red-black Gauss–Seidel sweep of colour p.colour: z_i = (b_i + Σ w_ij z_j)/A_ii
// (Stencil::sweep), z at out, b at a.
@compute @workgroup_size(64)
fn gauss_seidel(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.voxels || finished()) {
        return;
    }
    let c = coords(i, p.dims);
    let diag = stencil[p.first_row + i].diag;
    if ((c.x + c.y + c.z) % 2u != p.colour || diag <= 0.0) {
        return;
    }
    v[p.out + i] = (v[p.a + i] + neighbours(p.first_row, i, c, p.out)) / diag;
}

// out = a − A b (the V-cycle's residual; A b alone at out when product_only = 1).
@compute @workgroup_size(64)
fn residual(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.voxels || finished()) {
        return;
    }
    let diag = stencil[p.first_row + i].diag;
    var ax = 0.0;
    if (diag > 0.0) {
        ax = diag * v[p.b + i] - neighbours(p.first_row, i, coords(i, p.dims), p.b);
    }
    if (p.product_only == 1u) {
        v[p.out + i] = ax;
    } else {
        v[p.out + i] = select(0.0, v[p.a + i] - ax, diag > 0.0);
    }
}

// The coarsest level of a V-cycle solved in one workgroup (one invocation per voxel, at most
// WG of them): z = 0, then COARSEST_SWEEPS times the sweeps of colour 0, 1, 1, 0 as
// gauss_seidel does them, z at out, b at a; the storage barrier between two colours stands for
// the dispatches the finer levels take per colour. The same arithmetic as those dispatches.
const COARSEST_SWEEPS: u32 = 32u;
var<workgroup> stop: f32;
@compute @workgroup_size(64)
fn coarsest(@builtin(local_invocation_index) t: u32) {
    if (t == 0u) {
        stop = coef[DONE];
    }
    if (workgroupUniformLoad(&stop) != 0.0) {
        return;
    }
    let mine = t < p.voxels;
    var c = vec3<u32>(0u, 0u, 0u);
    var diag = 0.0;
    if (mine) {
        c = coords(t, p.dims);
        diag = stencil[p.first_row + t].diag;
        v[p.out + t] = 0.0;
    }
    storageBarrier();
    let order = array<u32, 4>(0u, 1u, 1u, 0u);
    for (var s = 0u; s < COARSEST_SWEEPS; s = s + 1u) {
        for (var k = 0u; k < 4u; k = k + 1u) {
            if (mine && diag > 0.0 && (c.x + c.y + c.z) % 2u == order[k]) {
                v[p.out + t] = (v[p.a + t] + neighbours(p.first_row, t, c, p.out)) / diag;
            }
            storageBarrier();
        }
    }
}

// The coarser level's right-hand side (at out): each coarse voxel sums its active children's
// residuals (at a).
@compute @workgroup_size(64)
fn restriction(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let ci = index(wg, t);
    if (ci >= p.coarse_voxels || finished()) {
        return;
    }
    let d = p.dims;
    let c = coords(ci, p.coarse_dims);
    var sum = 0.0;
    for (var fz = 2u * c.z; fz < min(2u * c.z + 2u, d.z); fz = fz + 1u) {
        for (var fy = 2u * c.y; fy < min(2u * c.y + 2u, d.y); fy = fy + 1u) {
            for (var fx = 2u * c.x; fx < min(2u * c.x + 2u, d.x); fx = fx + 1u) {
                let i = fx + d.x * (fy + d.y * fz);
                if (stencil[p.first_row + i].diag > 0.0) {
                    sum = sum + v[p.a + i];
                }
            }
        }
    }
    v[p.out + ci] = sum;
}

// z (at out) += the coarser level's correction (at c) at each active voxel.
@compute @workgroup_size(64)
fn prolong(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.voxels || finished() || stencil[p.first_row + i].diag <= 0.0) {
        return;
    }
    let c = coords(i, p.dims) / 2u;
    let cd = p.coarse_dims;
    v[p.out + i] = v[p.out + i] + v[p.c + c.x + cd.x * (c.y + cd.y * c.z)];
}

// out = 0.
@compute @workgroup_size(64)
fn zero(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i < p.voxels && !finished()) {
        v[p.out + i] = 0.0;
    }
}

// Per workgroup, Σ a_i b_i over its voxels, into partial[out + workgroup].
@compute @workgroup_size(64)
fn dots(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    var s = 0.0;
    if (i < p.voxels && !finished()) {
        s = v[p.a + i] * v[p.b + i];
    }
    sums[t] = s;
    workgroupBarrier();
    for (var half = WG / 2u; half > 0u; half = half / 2u) {
        if (t < half) {
            sums[t] = sums[t] + sums[t + half];
        }
        workgroupBarrier();
    }
    if (t == 0u) {
        partial[p.out + wg.y * ROW + wg.x] = sums[0];
    }
}

// x (at a) += α d (at b); r (at out) −= α A d (at c).
@compute @workgroup_size(64)
fn update_xr(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.voxels || finished()) {
        return;
    }
    let alpha = coef[0];
    v[p.a + i] = v[p.a + i] + alpha * v[p.b + i];
    v[p.out + i] = v[p.out + i] - alpha * v[p.c + i];
}

// d (at out) = z (at a) + β d.
@compute @workgroup_size(64)
fn update_d(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.voxels || finished()) {
        return;
    }
    v[p.out + i] = v[p.a + i] + coef[1] * v[p.out + i];
}

// The sums of the two slots of partial sums (p.voxels each: slot 0 at 0, slot 1 after it).
var<workgroup> pairs: array<vec2<f32>, 64>;

// The conjugate gradients' control on the GPU (diffusion_gpu's GPU-driven iteration), one
// workgroup: from the partial sums, step p.colour of the iteration the CPU's loop takes
// (Uploaded::inner): 0 resets it (β = 0, nothing finished or taken); 1 starts it (r·z, r·r
// of the first V-cycle; a zero r is solved, one not finite is not); 2 forms α = r·z / d·Ad
// (d·Ad ≤ 0 stops it) and counts the iteration; 3 tests the residual ‖r‖ ≤ tolerance ‖r_0‖
// and the cap; 4 forms β = r·z_new / r·z. Once finished, steps 2–4 and every other kernel
// do nothing.
@compute @workgroup_size(64)
fn scalars(@builtin(local_invocation_index) t: u32) {
    var s = vec2<f32>(0.0, 0.0);
    for (var k = t; k < p.voxels; k = k + WG) {
        s = s + vec2<f32>(partial[k], partial[p.voxels + k]);
    }
    pairs[t] = s;
    workgroupBarrier();
    for (var half = WG / 2u; half > 0u; half = half / 2u) {
        if (t < half) {
            pairs[t] = pairs[t] + pairs[t + half];
        }
        workgroupBarrier();
    }
    if (t != 0u) {
        return;
    }
    let sums = pairs[0];
    switch p.colour {
        case 0u: {
            coef[BETA] = 0.0;
            coef[DONE] = 0.0;
            coef[TAKEN] = 0.0;
            coef[CONVERGED] = 0.0;
        }
        case 1u: {
            coef[RZ] = sums.x;
            coef[RR0] = sums.y;
            // r_0 = 0 is solved by e = 0; a norm that is not finite (or a cap of 0) is not.
            if (sums.y == 0.0) {
                coef[CONVERGED] = 1.0;
                coef[DONE] = 1.0;
            } else if (!(sums.y > 0.0 && sums.y < 3.0e38) || coef[CAP] < 1.0) {
                coef[DONE] = 1.0;
            }
        }
        case 2u: {
            if (finished()) {
                return;
            }
            if (!(sums.x > 0.0)) {
                coef[DONE] = 1.0;
                return;
            }
            coef[ALPHA] = coef[RZ] / sums.x;
            coef[TAKEN] = coef[TAKEN] + 1.0;
        }
        case 3u: {
            if (finished()) {
                return;
            }
            if (sqrt(sums.y) <= coef[TOLERANCE] * sqrt(coef[RR0])) {
                coef[CONVERGED] = 1.0;
                coef[DONE] = 1.0;
            } else if (coef[TAKEN] >= coef[CAP]) {
                coef[DONE] = 1.0;
            }
        }
        default: {
            if (finished()) {
                return;
            }
            coef[BETA] = sums.x / coef[RZ];
            coef[RZ] = sums.x;
        }
    }
}
