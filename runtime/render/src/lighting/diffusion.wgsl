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
// α and β of the current iteration.
@group(0) @binding(4) var<storage, read> coef: array<f32>;

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
    if (i >= p.voxels) {
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
    if (i >= p.voxels) {
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

// The coarser level's right-hand side (at out): each coarse voxel sums its active children's
// residuals (at a).
@compute @workgroup_size(64)
fn restriction(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let ci = index(wg, t);
    if (ci >= p.coarse_voxels) {
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
    if (i >= p.voxels || stencil[p.first_row + i].diag <= 0.0) {
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
    if (i < p.voxels) {
        v[p.out + i] = 0.0;
    }
}

// Per workgroup, Σ a_i b_i over its voxels, into partial[out + workgroup].
@compute @workgroup_size(64)
fn dots(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    var s = 0.0;
    if (i < p.voxels) {
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
    if (i >= p.voxels) {
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
    if (i >= p.voxels) {
        return;
    }
    v[p.out + i] = v[p.a + i] + coef[1] * v[p.out + i];
}
