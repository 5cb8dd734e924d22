// One layer of the discrete-ordinates transport's sweeps (render::lighting::transport::sweep_round)
// on the GPU, in f32: one workgroup per voxel of the layer, its invocations the directions of
// one group (the directions that travel most along the same axis and sign). Each voxel's
// emission harmonics are formed once in workgroup memory (transport::emission), each direction
// steps its radiance from the layer behind (lattice::upwind, transport::advance), and the
// workgroup projects the radiances onto the harmonics and adds them to the round's moments.

struct Params {
    dims: vec4<u32>,         // nx, ny, nz, moments' stride per voxel (floats)
    weight: vec4<f32>,       // x = the quadrature weight 4π/N
    y_sun: array<vec4<f32>, 7>, // Y_k(l) for the sun's direction of travel l, k < 25
}

@group(0) @binding(0) var<uniform> params: Params;
// Binding 1: the dispatch's `Step` (upwind.wgsl).
@group(0) @binding(2) var<storage, read> medium: array<TransportVoxel>;
@group(0) @binding(3) var<storage, read> moments: array<f32>;
@group(0) @binding(4) var<storage, read_write> next: array<f32>;
@group(0) @binding(5) var<storage, read> ordinates: array<Ordinate>;
// One per (layer voxel, direction of the group), in two halves (the layer behind, this one):
// lattice's upwind state of sweep_round.
@group(0) @binding(6) var<storage, read_write> state: array<LayerState>;

// A voxel's medium for the transport (transport::Medium, in f32).
struct TransportVoxel {
    ext: vec4<f32>,          // σ′_t rgb, 0
    sca: vec4<f32>,          // σ′_s rgb, 0
    chi: array<vec4<f32>, 3>, // p′'s moments χ′_0…3, one vector per channel
    chi4: vec4<f32>,         // χ′_4 per channel (rgb), 0
    sun: vec4<f32>,          // the sunlit source q rgb, 0
    sky: array<vec4<f32>, 3>, // the skylit source (q0, q1 x, y, z), one vector per channel
}

// One direction of the quadrature.
struct Ordinate {
    y: array<vec4<f32>, 7>,  // Y_k(ω), k < 25, zero past k = 24
    way: vec4<f32>,          // the point one layer back (shift u, shift v), the step ds (m), 0
}
const HARMONICS: u32 = 25u;
// Invocations per workgroup: 96 directions make about 16 per sweep order (on lavapipe a round
// at 32 directions took 1.84 s with 16, 2.73 s with 64, most of them idle).
const WG: u32 = 16u;
const MAX_GROUP: u32 = 512u;
const PI: f32 = 3.14159265358979;

// The emission harmonics per channel (transport::emission).
var<workgroup> emission: array<f32, 75>;
// weight × I per channel and direction.
var<workgroup> weighted: array<f32, 1536>;

fn degree(k: u32) -> u32 {
    if (k == 0u) { return 0u; }
    if (k < 4u) { return 1u; }
    if (k < 9u) { return 2u; }
    if (k < 16u) { return 3u; }
    return 4u;
}

fn chi(i: u32, c: u32, l: u32) -> f32 {
    if (l < 4u) {
        return medium[i].chi[c][l];
    }
    return medium[i].chi4[c];
}

fn y_of(d: u32, k: u32) -> f32 {
    return ordinates[d].y[k / 4u][k % 4u];
}

// One direction's radiance at a voxel of the layer just swept, what the next layer reads.
struct LayerState {
    radiance: vec4<f32>,     // I rgb, 0
    ext: vec4<f32>,          // the voxel's σ′_t rgb, 0
    source: vec4<f32>,       // the voxel's source S in this direction rgb, 0
}

// sum + w · s, field by field (upwind.wgsl's bilinear sum).
fn weighted_add(sum: LayerState, w: f32, s: LayerState) -> LayerState {
    return LayerState(sum.radiance + w * s.radiance, sum.ext + w * s.ext,
                      sum.source + w * s.source);
}

// transport::advance. In f32, 1 − q and q − e lose their digits for a thin step (1 − q ≈ τ/2
// against an ulp of 6·10⁻⁸, times A = S/σ′, large where σ′ is small): below τ = 0.1 the step
// is the same expression expanded in τ, (A + B)(q − e) = (S + S_back) ds (q − e)/τ and
// A((1 − q) − (q − e)), their series to τ³ and τ⁴ (the next terms ≤ 3·10⁻⁶ of them there).
fn advance(i_back: f32, ds: f32, tau: f32, e: f32, s_here: f32, ext_here: f32, s_back: f32) -> f32 {
    let mean_ext = tau / ds;
    if (tau >= 0.1) {
        let total = (s_here + s_back) / mean_ext;
        let a = s_here / max(ext_here, mean_ext);
        let q = (1.0 - e) / tau;
        return i_back * e + a * (1.0 - q) + (total - a) * (q - e);
    }
    let both = (s_here + s_back) * ds * (0.5 + tau * (-1.0 / 3.0 + tau * (0.125 - tau / 30.0)));
    var thick = 0.0;
    if (tau > 0.0) {
        thick = s_here / max(ext_here, mean_ext) * tau * tau
            * (1.0 / 6.0 + tau * (-1.0 / 12.0 + tau / 40.0));
    }
    return i_back * e + both + thick;
}

@compute @workgroup_size(16)
fn sweep(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let size = layer_size();
    let nb = size.x;
    let nc = size.y;
    let ub = wg.x;
    let vc = wg.y;
    let first_layer = stp.group.x == 1u;
    let first = stp.group.y;
    let count = stp.group.z;
    let behind = stp.group.w;
    let i = voxel_at(ub, vc);
    var ext = medium[i].ext.xyz;
    let stride_m = params.dims.w;
    // The emission harmonics, one per invocation (transport::emission).
    for (var n = t; n < 75u; n = n + WG) {
        let ch = n / HARMONICS;
        let kk = n % HARMONICS;
        let sca = medium[i].sca[ch];
        let sun = medium[i].sun[ch];
        let y_sun = params.y_sun[kk / 4u][kk % 4u];
        var s = chi(i, ch, degree(kk)) * (sca * moments[i * stride_m + n] + 4.0 * PI * sun * y_sun);
        let sky = medium[i].sky[ch];
        let y1 = 0.4886025119029199;
        if (kk == 0u) {
            s = s + sqrt(4.0 * PI) * sky.x;
        } else if (kk == 1u) {
            s = s + 3.0 * sky.z / y1;
        } else if (kk == 2u) {
            s = s + 3.0 * sky.w / y1;
        } else if (kk == 3u) {
            s = s + 3.0 * sky.y / y1;
        }
        emission[n] = s;
    }
    workgroupBarrier();
    let weight = params.weight.x;
    for (var j = t; j < count; j = j + WG) {
        let d = first + j;
        var s_here = vec3<f32>(0.0);
        for (var kk = 0u; kk < HARMONICS; kk = kk + 1u) {
            let y = y_of(d, kk);
            s_here = s_here + y * vec3<f32>(emission[kk], emission[HARMONICS + kk],
                                            emission[2u * HARMONICS + kk]);
        }
        let o = ordinates[d].way;
        let ds = o.z;
        // The state one layer back (lattice::upwind; clear air outside: zero).
        var back_i = vec3<f32>(0.0);
        var back_ext = vec3<f32>(0.0);
        var back_s = vec3<f32>(0.0);
        if (!first_layer) {
            let up = upwind(ub, vc, o.xy, nb, nc);
            if (up.kept > 0.0) {
                let back = upwind_state(up, behind, j, nb, nc, count);
                back_i = up.kept * back.radiance.xyz;
                back_ext = up.kept * back.ext.xyz;
                back_s = up.kept * back.source.xyz;
            }
        }
        var radiance = vec3<f32>(0.0);
        for (var ch = 0u; ch < 3u; ch = ch + 1u) {
            let mean_ext = 0.5 * (ext[ch] + back_ext[ch]);
            let tau = mean_ext * ds;
            let e = exp(-min(tau, 700.0));
            radiance[ch] = advance(back_i[ch], ds, tau, e, s_here[ch], ext[ch], back_s[ch]);
        }
        state[state_slot(1u - behind, ub, vc, j, nb, nc, count)] = LayerState(
            vec4<f32>(radiance, 0.0),
            vec4<f32>(ext, 0.0),
            vec4<f32>(s_here, 0.0),
        );
        for (var ch = 0u; ch < 3u; ch = ch + 1u) {
            weighted[ch * MAX_GROUP + j] = weight * radiance[ch];
        }
    }
    workgroupBarrier();
    // Σ_d weight I_d Y_k(ω_d) per channel, added to the round's moments.
    for (var n = t; n < 75u; n = n + WG) {
        let ch = n / HARMONICS;
        let kk = n % HARMONICS;
        var sum = 0.0;
        for (var j = 0u; j < count; j = j + 1u) {
            sum = sum + weighted[ch * MAX_GROUP + j] * y_of(first + j, kk);
        }
        next[i * stride_m + n] = next[i * stride_m + n] + sum;
    }
}
