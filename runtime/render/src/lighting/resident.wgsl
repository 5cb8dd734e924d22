// The transport's source iteration kept on the GPU (render::lighting::resident): between a
// round's sweeps (sweep.wgsl, the new moments in `next`) and one channel's diffusion solve
// (diffusion.wgsl, its vectors in `v`), the acceleration's source from the round's change of
// the mean radiance, the correction added back, and the change's sums for the convergence test
// (transport::iterate and coupled::light's accelerate, in f32).

struct Glue {
    voxels: u32,   // the transport grid's voxels
    stride: u32,   // floats per voxel of the moments
    offset: u32,   // this channel's φ_00 within a voxel's moments (25 c)
    channel: u32,  // c
    rhs: u32,      // the diffusion's right-hand side r, its offset in v (floats)
    solution: u32, // its solution e, its offset in v
    root: f32,     // √(4π)
    pad: u32,
}

@group(0) @binding(0) var<uniform> g: Glue;
// Per voxel and channel: h³ σ′_s / √(4π) where the voxel is one of the diffusion's unknowns,
// else 0 (diffusion::Operator::isotropic of the scattered change).
@group(0) @binding(1) var<storage, read> weight: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> moments: array<f32>;
@group(0) @binding(3) var<storage, read_write> next: array<f32>;
@group(0) @binding(4) var<storage, read_write> v: array<f32>;
// Per workgroup of `change`: Σ (Δφ_00)², Σ φ_00² of channel g.channel.
@group(0) @binding(5) var<storage, read_write> partial: array<f32>;

const WG: u32 = 64u;
// Workgroups along x of a dispatch (the rest along y), as diffusion.wgsl.
const ROW: u32 = 1024u;

var<workgroup> sums: array<vec2<f32>, 64>;

fn index(wg: vec3<u32>, t: u32) -> u32 {
    return (wg.y * ROW + wg.x) * WG + t;
}

// r_i = h³ σ′_s,i (φ_00,new − φ_00,old)_i / √(4π): the diffusion of the round's error.
@compute @workgroup_size(64)
fn source(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i < g.voxels) {
        let k = i * g.stride + g.offset;
        v[g.rhs + i] = weight[i][g.channel] * (next[k] - moments[k]);
    }
}

// φ_00,new += √(4π) e_i.
@compute @workgroup_size(64)
fn correct(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    if (i < g.voxels) {
        let k = i * g.stride + g.offset;
        next[k] = next[k] + g.root * v[g.solution + i];
    }
}

// Per workgroup, Σ (φ_00,new − φ_00,old)² and Σ φ_00,new² over its voxels.
@compute @workgroup_size(64)
fn change(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = index(wg, t);
    var s = vec2<f32>(0.0, 0.0);
    if (i < g.voxels) {
        let k = i * g.stride + g.offset;
        let d = next[k] - moments[k];
        s = vec2<f32>(d * d, next[k] * next[k]);
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
        let w = wg.y * ROW + wg.x;
        partial[2u * w] = sums[0].x;
        partial[2u * w + 1u] = sums[0].y;
    }
}
