// What the GPU sweeps share — the transport's, the skylight's and the beam's (put before
// sweep.wgsl, sky.wgsl and beam.wgsl by lighting::transport_gpu::with_upwind): their per-dispatch
// `Step`, and the lookup one layer
// back (render::lattice::upwind): for the point `shift` (voxel units) from the centre (ub, vc)
// of a layer of nb × nc voxel centres, the four centres around it and their bilinear
// weights, and the share `kept` of the layer's state there — 1 between the centres, falling
// linearly to 0 over the half voxel beyond the outermost ones (the rest is clear air's light:
// zero); the weights are zero where nothing is kept.
// Per dispatch of each sweep (a dynamic offset into its steps, transport_gpu::push_step): the
// layer's axis a and across-axes b, c, its index k; whether it is the sweep order's first
// layer, the order's first direction and its count, and which half of the state buffer holds
// the layer behind.
struct Step {
    axes: vec4<u32>,         // a, b, c, k
    group: vec4<u32>,        // first layer (1/0), first direction, count, half behind
}

@group(0) @binding(1) var<uniform> stp: Step;

// The step's layer: its size nb × nc along the across-axes b, c (of the including shader's
// `params.dims`).
fn layer_size() -> vec2<u32> {
    var dims = params.dims;
    return vec2<u32>(dims[stp.axes.y], dims[stp.axes.z]);
}

// The grid index of the layer's voxel (ub, vc) (x fastest).
fn voxel_at(ub: u32, vc: u32) -> u32 {
    var dims = params.dims;
    var stride = vec3<u32>(1u, dims.x, dims.x * dims.y);
    return stp.axes.w * stride[stp.axes.x] + ub * stride[stp.axes.y] + vc * stride[stp.axes.z];
}

struct Upwind {
    kept: f32,
    u: array<u32, 4>,
    v: array<u32, 4>,
    w: array<f32, 4>,
}

fn upwind(ub: u32, vc: u32, shift: vec2<f32>, nb: u32, nc: u32) -> Upwind {
    let fb = f32(nb);
    let fc = f32(nc);
    let u = f32(ub) + shift.x;
    let v = f32(vc) + shift.y;
    let share_u = clamp(max(-u, u - (fb - 1.0)) / 0.5, 0.0, 1.0);
    let share_v = clamp(max(-v, v - (fc - 1.0)) / 0.5, 0.0, 1.0);
    let kept = (1.0 - share_u) * (1.0 - share_v);
    // The centres and weights from the voxel's index and the shift's whole and fractional
    // parts apart: f32(ub) + shift rounds the position to 2^-24 of the index (2·10⁻⁶ of a voxel
    // at 32), which where β changes fast across a layer moved the beam's losses by 10⁻⁵.
    let cu = corner(i32(ub), shift.x, nb);
    let cv = corner(i32(vc), shift.y, nc);
    let s = cu.y;
    let t = cv.y;
    let u0 = u32(cu.x);
    let v0 = u32(cv.x);
    let u1 = min(u0 + 1u, nb - 1u);
    let v1 = min(v0 + 1u, nc - 1u);
    var w = array<f32, 4>((1.0 - s) * (1.0 - t), s * (1.0 - t), (1.0 - s) * t, s * t);
    if (kept <= 0.0) {
        w = array<f32, 4>(0.0, 0.0, 0.0, 0.0);
    }
    return Upwind(max(kept, 0.0), array<u32, 4>(u0, u1, u0, u1), array<u32, 4>(v0, v0, v1, v1), w);
}

// The centre below index + shift, clamped to 0 … n − 1, and the weight of the one above it
// (zero where clamped): lattice::upwind's floor of the clamped position.
fn corner(index: i32, shift: f32, n: u32) -> vec2<f32> {
    let whole = floor(shift);
    let at = index + i32(whole);
    if (at < 0) {
        return vec2<f32>(0.0, 0.0);
    }
    if (at >= i32(n) - 1) {
        return vec2<f32>(f32(n - 1u), 0.0);
    }
    return vec2<f32>(f32(at), shift - whole);
}

// The slot of direction `j` (of `count`) at layer voxel (u, v) in half `h` of the including
// shader's `state` array of its `LayerState` records.
fn state_slot(h: u32, u: u32, v: u32, j: u32, nb: u32, nc: u32, count: u32) -> u32 {
    return (h * nb * nc + u + v * nb) * count + j;
}

// The state one layer back at `up`, for direction slot `j` of the layer in half `h`: the
// bilinear sum over the four centres (each field by the including shader's `weighted_add`),
// not yet scaled by `up.kept`.
fn upwind_state(up: Upwind, h: u32, j: u32, nb: u32, nc: u32, count: u32) -> LayerState {
    var at = up;
    var sum = LayerState();
    for (var q = 0u; q < 4u; q = q + 1u) {
        sum = weighted_add(sum, at.w[q], state[state_slot(h, at.u[q], at.v[q], j, nb, nc, count)]);
    }
    return sum;
}
