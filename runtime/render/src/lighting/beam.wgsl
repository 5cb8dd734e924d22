// One layer of the beam's sweep (lighting::beam::beam_sweep, step 1 of the coupled model and the loss of
// step 2) on the GPU, in f32: one invocation per voxel of the layer. The state one layer back
// along the sun's direction is interpolated (lattice::upwind; beyond the box the sunlight
// unscattered in clear air: I = 1, D = 0), the step's trapezoid of β_ext and β_sca taken, the
// continuum update kept e^{−τ(1 − αf)} of the light, and what the beam loses split into the
// diffuse light's sources.

struct Params {
    dims: vec4<u32>,         // nx, ny, nz, 0
    way: vec4<f32>,          // shift u, shift v one layer back (voxel units), ds (metres), 0
}

// The medium at a voxel (lighting::beam::BeamMedium in f32; beam_gpu::MediumVoxel).
struct MediumVoxel {
    ext: vec4<f32>,          // β_ext rgb (1/m), 0
    sca: vec4<f32>,          // β_sca rgb (1/m), 0
    peak: vec4<f32>,         // the split's forward peak f rgb, the peak's share of β_sca (green)
    g: vec4<f32>,            // the asymmetry parameter g rgb, 0
}

// The beam at a voxel and what it loses, each per metre of the step (beam_gpu::BeamVoxel).
struct BeamVoxel {
    beam: vec4<f32>,         // I rgb, the peak's depth D
    isotropic: vec4<f32>,    // the diffuse light's isotropic source rgb, 0
    forward: vec4<f32>,      // its first-moment (forward) source rgb, 0
    loss: vec4<f32>,         // the beam's whole loss rgb, 0
}

@group(0) @binding(0) var<uniform> params: Params;
// Binding 1: the dispatch's `Step` (upwind.wgsl).
@group(0) @binding(2) var<storage, read> medium: array<MediumVoxel>;
// One per (half, layer voxel), read one layer on by upwind.wgsl's upwind_state.
@group(0) @binding(3) var<storage, read_write> state: array<LayerState>;
@group(0) @binding(4) var<storage, read_write> beam: array<BeamVoxel>;

// The beam at a voxel of the layer just swept, what the next layer reads of it.
struct LayerState {
    intensity: vec4<f32>,    // the beam I rgb, 0
    ext: vec4<f32>,          // the voxel's β_ext rgb, 0
    sca: vec4<f32>,          // the voxel's β_sca rgb, 0
    depth: vec4<f32>,        // the peak's depth D, 0, 0, 0
}

// sum + w · s, field by field (upwind.wgsl's bilinear sum).
fn weighted_add(sum: LayerState, w: f32, s: LayerState) -> LayerState {
    return LayerState(sum.intensity + w * s.intensity, sum.ext + w * s.ext,
                      sum.sca + w * s.sca, sum.depth + w * s.depth);
}

// 1 − e^{−x} without the cancellation of small x.
fn one_minus_exp(x: f32) -> f32 {
    if (x < 1e-3) {
        return x * (1.0 - x * (0.5 - x / 6.0));
    }
    return 1.0 - exp(-min(x, 700.0));
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
    let behind = stp.group.w;
    let i = voxel_at(ub, vc);
    let here = medium[i];
    let ext_h = here.ext.xyz;
    let sca_h = here.sca.xyz;
    let f = here.peak.xyz;
    let share = here.peak.w;
    let g = here.g.xyz;
    // One layer back: clear air's sunlight outside the box, blended over the last half voxel.
    var start = vec3<f32>(1.0);
    var back_ext = vec3<f32>(0.0);
    var back_sca = vec3<f32>(0.0);
    var n0 = 0.0;
    if (stp.group.x == 0u) {
        let up = upwind(ub, vc, params.way.xy, nb, nc);
        let back = upwind_state(up, behind, 0u, nb, nc, 1u);
        start = up.kept * back.intensity.xyz + vec3<f32>(1.0 - up.kept);
        back_ext = up.kept * back.ext.xyz;
        back_sca = up.kept * back.sca.xyz;
        n0 = up.kept * back.depth.x;
    }
    let ds = params.way.z;
    let ext = 0.5 * (back_ext + ext_h);
    let sca = 0.5 * (back_sca + sca_h);
    let tau = ext * ds;
    var n = n0;
    if (ext.y > 0.0) {
        n = n + sca.y * ds * share;
    }
    var kept = vec3<f32>(0.0);
    var source = vec3<f32>(0.0);
    var forward = vec3<f32>(0.0);
    var loss = vec3<f32>(0.0);
    for (var ch = 0u; ch < 3u; ch = ch + 1u) {
        var albedo = 0.0;
        if (ext[ch] > 0.0) {
            albedo = sca[ch] / ext[ch];
        }
        let lost = 1.0 - albedo * f[ch];
        let gone = start[ch] * one_minus_exp(tau[ch] * lost);
        kept[ch] = start[ch] - gone;
        if (lost > 1e-12 && ds > 0.0) {
            loss[ch] = gone / ds;
            source[ch] = loss[ch] * albedo * (1.0 - f[ch]) / lost;
            forward[ch] = loss[ch] * albedo * (g[ch] - f[ch]) / lost;
        }
    }
    state[state_slot(1u - behind, ub, vc, 0u, nb, nc, 1u)] = LayerState(
        vec4<f32>(kept, 0.0),
        vec4<f32>(ext_h, 0.0),
        vec4<f32>(sca_h, 0.0),
        vec4<f32>(n, 0.0, 0.0, 0.0),
    );
    beam[i] = BeamVoxel(
        vec4<f32>(kept, n),
        vec4<f32>(source, 0.0),
        vec4<f32>(forward, 0.0),
        vec4<f32>(loss, 0.0),
    );
}
