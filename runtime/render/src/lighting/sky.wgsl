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
// Per direction three rows: (shift u, shift v, ds, 0), (radiance × 1/SKY_DIRECTIONS rgb, 0),
// (s, the direction towards the sky, 0).
@group(0) @binding(3) var<storage, read> ways: array<vec4<f32>>;
// Per (half, layer voxel, direction of the order) two rows: τ (rgb), β_ext (rgb).
@group(0) @binding(4) var<storage, read_write> state: array<vec4<f32>>;
// Per voxel four rows: the mean skylight (rgb), its flux per channel (R, G, B: xyz).
@group(0) @binding(5) var<storage, read_write> sky: array<vec4<f32>>;

// The state's rows per direction (upwind.wgsl's state_index).
const STATE_ROWS: u32 = 2u;

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
        let o = ways[3u * d];
        var back_tau = vec3<f32>(0.0);
        var back_ext = vec3<f32>(0.0);
        if (!first_layer) {
            let up = upwind(ub, vc, o.xy, nb, nc);
            if (up.kept > 0.0) {
                back_tau = up.kept * upwind_row(up, behind, j, nb, nc, count, 0u);
                back_ext = up.kept * upwind_row(up, behind, j, nb, nc, count, 1u);
            }
        }
        let tau = back_tau + 0.5 * o.z * (here + back_ext);
        let at = state_index(1u - behind, ub, vc, j, nb, nc, count);
        state[at] = vec4<f32>(tau, 0.0);
        state[at + 1u] = vec4<f32>(here, 0.0);
        let light = ways[3u * d + 1u].xyz * exp(-min(tau, vec3<f32>(700.0)));
        let towards = ways[3u * d + 2u].xyz;
        mean = mean + light;
        for (var ch = 0u; ch < 3u; ch = ch + 1u) {
            flux[ch] = flux[ch] - light[ch] * towards;
        }
    }
    sky[4u * i] = sky[4u * i] + vec4<f32>(mean, 0.0);
    for (var ch = 0u; ch < 3u; ch = ch + 1u) {
        sky[4u * i + 1u + ch] = sky[4u * i + 1u + ch] + vec4<f32>(flux[ch], 0.0);
    }
}
