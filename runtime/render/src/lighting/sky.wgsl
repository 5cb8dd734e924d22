// One layer of the reduced skylight's sweeps (render::lattice::sky_sweeps) on the GPU, in f32:
// one invocation per voxel of the layer, looping over the directions of one sweep order (those
// that travel most along the same axis and sign). Per direction the optical depth one layer back
// is interpolated (lattice::upwind; clear air beyond the box: zero), the step's trapezoid of
// β_ext added (lattice::sun_depths), and the direction's radiance, attenuated, added to the
// voxel's mean skylight and flux (lattice::Sky::add).

struct Params {
    dims: vec4<u32>,         // nx, ny, nz, 0
}

@group(0) @binding(0) var<uniform> params: Params;
// Binding 1: the dispatch's `Step` (upwind.wgsl).
// β_ext per voxel (rgb).
@group(0) @binding(2) var<storage, read> ext: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> ways: array<SkyWay>;
// One per (half, layer voxel, direction of the order), read one layer on by upwind.wgsl's
// upwind_state.
@group(0) @binding(4) var<storage, read_write> state: array<LayerState>;
@group(0) @binding(5) var<storage, read_write> sky: array<SkyVoxel>;

// One direction of the sky (lattice::sky_sweeps' order).
struct SkyWay {
    way: vec4<f32>,          // the point one layer back (shift u, shift v), the step ds (m), 0
    radiance: vec4<f32>,     // the sky's radiance × 1/SKY_DIRECTIONS rgb, 0
    towards: vec4<f32>,      // s, the unit direction towards the sky, 0
}

// A voxel's skylight (lattice::Sky), summed over the sweeps.
struct SkyVoxel {
    mean: vec4<f32>,         // the mean skylight rgb, 0
    flux: array<vec4<f32>, 3>, // its flux vector (x, y, z, 0), one per channel
}

// One direction's optical depth at a voxel of the layer just swept.
struct LayerState {
    tau: vec4<f32>,          // the optical depth back to the sky rgb, 0
    ext: vec4<f32>,          // the voxel's β_ext rgb, 0
}

// sum + w · s, field by field (upwind.wgsl's bilinear sum).
fn weighted_add(sum: LayerState, w: f32, s: LayerState) -> LayerState {
    return LayerState(sum.tau + w * s.tau, sum.ext + w * s.ext);
}

@compute @workgroup_size(64)
fn sweep(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = layer_size();
    let nb = size.x;
    let nc = size.y;
    if (id.x >= nb * nc) {
        return;
    }
    let ub = id.x % nb;
    let vc = id.x / nb;
    let first_layer = stp.group.x == 1u;
    let first = stp.group.y;
    let count = stp.group.z;
    let behind = stp.group.w;
    let i = voxel_at(ub, vc);
    let here = ext[i].xyz;
    var mean = vec3<f32>(0.0);
    var flux = array<vec3<f32>, 3>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var j = 0u; j < count; j = j + 1u) {
        let d = first + j;
        let o = ways[d].way;
        var back_tau = vec3<f32>(0.0);
        var back_ext = vec3<f32>(0.0);
        if (!first_layer) {
            let up = upwind(ub, vc, o.xy, nb, nc);
            if (up.kept > 0.0) {
                let back = upwind_state(up, behind, j, nb, nc, count);
                back_tau = up.kept * back.tau.xyz;
                back_ext = up.kept * back.ext.xyz;
            }
        }
        let tau = back_tau + 0.5 * o.z * (here + back_ext);
        state[state_slot(1u - behind, ub, vc, j, nb, nc, count)] =
            LayerState(vec4<f32>(tau, 0.0), vec4<f32>(here, 0.0));
        let light = ways[d].radiance.xyz * exp(-min(tau, vec3<f32>(700.0)));
        let towards = ways[d].towards.xyz;
        mean = mean + light;
        for (var ch = 0u; ch < 3u; ch = ch + 1u) {
            flux[ch] = flux[ch] - light[ch] * towards;
        }
    }
    sky[i].mean = sky[i].mean + vec4<f32>(mean, 0.0);
    for (var ch = 0u; ch < 3u; ch = ch + 1u) {
        sky[i].flux[ch] = sky[i].flux[ch] + vec4<f32>(flux[ch], 0.0);
    }
}
