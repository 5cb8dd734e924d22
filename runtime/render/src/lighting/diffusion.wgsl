// The diffusion solve on the GPU (render::diffusion_gpu): conjugate gradients preconditioned by
// the multigrid V-cycle of render::diffusion, in f32, every kernel one of the CPU solver's loops.
// Each level's 7-point operator is one row per voxel (diag, w+x, w+y, w+z: A_ii = diag,
// A_{i,i+e_a} = −w_a); the vectors of every level live in one buffer at offsets the dispatch's
// parameters give.

struct Dispatch {
    dims: vec4<u32>,   // this level's nx, ny, nz; w = the colour of a smoothing sweep
    cdims: vec4<u32>,  // the coarser level's nx, ny, nz; w = its voxel count
    offs: vec4<u32>,   // this level's first row of `stencil`, the coarser level's, voxels here
    sel: vec4<u32>,    // vector offsets in `v`: a, b, out, and the z vector of the coarser level
}

@group(0) @binding(0) var<uniform> p: Dispatch;
@group(0) @binding(1) var<storage, read> stencil: array<vec4<f32>>;
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
    let d = p.dims.xyz;
    var stride = vec3<u32>(1u, d.x, d.x * d.y);
    var s = 0.0;
    for (var a = 0u; a < 3u; a = a + 1u) {
        let st = stride[a];
        if (c[a] + 1u < d[a]) {
            s = s + stencil[o + i][1u + a] * v[x + i + st];
        }
        if (c[a] > 0u) {
            s = s + stencil[o + i - st][1u + a] * v[x + i - st];
        }
    }
    return s;
}

// One red-black Gauss–Seidel sweep of colour p.dims.w: z_i = (b_i + Σ w_ij z_j)/A_ii
// (Stencil::sweep), z at sel.out, b at sel.a.
@compute @workgroup_size(64)
fn gauss_seidel(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.offs.z) {
        return;
    }
    let c = coords(i, p.dims.xyz);
    let diag = stencil[p.offs.x + i].x;
    if ((c.x + c.y + c.z) % 2u != p.dims.w || diag <= 0.0) {
        return;
    }
    v[p.sel.z + i] = (v[p.sel.x + i] + neighbours(p.offs.x, i, c, p.sel.z)) / diag;
}

// out = a − A b (the V-cycle's residual; with a = b = out unused, A b alone when sel.w = 1).
@compute @workgroup_size(64)
fn residual(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.offs.z) {
        return;
    }
    let diag = stencil[p.offs.x + i].x;
    var ax = 0.0;
    if (diag > 0.0) {
        ax = diag * v[p.sel.y + i] - neighbours(p.offs.x, i, coords(i, p.dims.xyz), p.sel.y);
    }
    if (p.sel.w == 1u) {
        v[p.sel.z + i] = ax;
    } else {
        v[p.sel.z + i] = select(0.0, v[p.sel.x + i] - ax, diag > 0.0);
    }
}

// The coarser level's right-hand side (at sel.z): each coarse voxel sums its active children's
// residuals (at sel.x).
@compute @workgroup_size(64)
fn restriction(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let ci = index(wg, t);
    if (ci >= p.cdims.w) {
        return;
    }
    let d = p.dims.xyz;
    let c = coords(ci, p.cdims.xyz);
    var sum = 0.0;
    for (var fz = 2u * c.z; fz < min(2u * c.z + 2u, d.z); fz = fz + 1u) {
        for (var fy = 2u * c.y; fy < min(2u * c.y + 2u, d.y); fy = fy + 1u) {
            for (var fx = 2u * c.x; fx < min(2u * c.x + 2u, d.x); fx = fx + 1u) {
                let i = fx + d.x * (fy + d.y * fz);
                if (stencil[p.offs.x + i].x > 0.0) {
                    sum = sum + v[p.sel.x + i];
                }
            }
        }
    }
    v[p.sel.z + ci] = sum;
}

// z (at sel.z) += the coarser level's correction (at sel.w) at each active voxel.
@compute @workgroup_size(64)
fn prolong(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.offs.z || stencil[p.offs.x + i].x <= 0.0) {
        return;
    }
    let c = coords(i, p.dims.xyz) / 2u;
    let cd = p.cdims.xyz;
    v[p.sel.z + i] = v[p.sel.z + i] + v[p.sel.w + c.x + cd.x * (c.y + cd.y * c.z)];
}

// out (at sel.z) = 0.
@compute @workgroup_size(64)
fn zero(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i < p.offs.z) {
        v[p.sel.z + i] = 0.0;
    }
}

// Per workgroup, Σ a_i b_i over its voxels, into partial[sel.z + workgroup].
@compute @workgroup_size(64)
fn dots(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    var s = 0.0;
    if (i < p.offs.z) {
        s = v[p.sel.x + i] * v[p.sel.y + i];
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
        partial[p.sel.z + wg.y * ROW + wg.x] = sums[0];
    }
}

// x (sel.x) += α d (sel.y); r (sel.z) −= α A d (sel.w).
@compute @workgroup_size(64)
fn update_xr(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.offs.z) {
        return;
    }
    let alpha = coef[0];
    v[p.sel.x + i] = v[p.sel.x + i] + alpha * v[p.sel.y + i];
    v[p.sel.z + i] = v[p.sel.z + i] - alpha * v[p.sel.w + i];
}

// d (sel.z) = z (sel.x) + β d.
@compute @workgroup_size(64)
fn update_d(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i >= p.offs.z) {
        return;
    }
    v[p.sel.z + i] = v[p.sel.x + i] + coef[1] * v[p.sel.z + i];
}
