// photometeor tables on the GPU: sampling functions a renderer includes (bind group 0).
//
// Layout (runtime::gpu docs): `ams_table` is a 2-D texture array, width K (θ_k = k·Δθ), height
// N (row r = Ams_{r+1}), one layer per field; RGBA with A unused. Fields with fewer rows than
// the largest N repeat their last row. Texels are read with textureLoad and interpolated here,
// so no filterable-float feature is needed. `ams_forward_fraction[field * n_stride + n − 1]`
// holds F_n (RGB), `ams_field_info[field]` holds (N, σ_sca R, G, B).
//
// The render models' lookups: `model_table`, width K, one layer per field, holds in rows
// 0..J_P the Poisson mixtures M(D_j, θ_k) (Max et al. 2004 Eqs. 8-9; format::poisson) and in
// rows J_P..J_P + J_B Biri et al.'s kernel primitive C(τ_j, θ_k − 90°) (Biri et al. 2006
// Eq. 2; format::biri), RGB. `model_depths[4 field .. 4 field + 3]` = (J_P, J_B, index of the
// first Poisson depth, index of the first Biri depth) of each field as floats (0, 0 for a
// field without the tables), the depths themselves after the field_count headers.

struct AmsParams {
    angle_count: u32,
    n_stride: u32,
    field_count: u32,
    pad0: u32,
    inv_step_rad: f32,
    pad1: f32,
    pad2: f32,
    pad3: f32,
}

@group(0) @binding(0) var ams_table: texture_2d_array<f32>;
@group(0) @binding(1) var<storage, read> ams_forward_fraction: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> ams_field_info: array<vec4<f32>>;
@group(0) @binding(3) var<uniform> ams_params: AmsParams;
@group(0) @binding(4) var model_table: texture_2d_array<f32>;
@group(0) @binding(5) var<storage, read> model_depths: array<f32>;

// Rows r0, r1 and the weight of r1 for fractional order n (clamped to [1, N]).
fn ams_order(field: u32, n: f32) -> vec3<f32> {
    let top = ams_field_info[field].x;
    let nn = clamp(n, 1.0, top);
    let lo = floor(nn);
    let r0 = u32(lo) - 1u;
    let r1 = min(r0 + 1u, u32(top) - 1u);
    return vec3<f32>(f32(r0), f32(r1), nn - lo);
}

fn ams_row(field: u32, row: u32, k0: u32, t: f32) -> vec3<f32> {
    let a = textureLoad(ams_table, vec2<i32>(i32(k0), i32(row)), i32(field), 0).rgb;
    let b = textureLoad(ams_table, vec2<i32>(i32(k0 + 1u), i32(row)), i32(field), 0).rgb;
    return mix(a, b, t);
}

// asin(x) for |x| ≤ 0.5 by a minimax polynomial in x² (Cephes asinf coefficients, S. L.
// Moshier), about 1 ulp: the built-in acos/asin of some drivers are allowed errors of
// thousands of ulp (Vulkan's precision rules), which move θ by a tenth of a bin.
fn ams_asin_small(x: f32) -> f32 {
    let z = x * x;
    let p = (((4.2163199048e-2 * z + 2.4181311049e-2) * z + 4.5470025998e-2) * z
        + 7.4953002686e-2) * z + 1.6666752422e-1;
    return x + x * z * p;
}

// θ = acos(cos θ) from ams_asin_small only: near 0° and 180° through 2 asin(√((1 ∓ c)/2)),
// where 1 ∓ c is exact in f32, so θ keeps its relative precision at the poles.
fn ams_angle(cos_theta: f32) -> f32 {
    let c = clamp(cos_theta, -1.0, 1.0);
    let half_pi = 1.5707963267948966;
    if (c > 0.5) {
        return 2.0 * ams_asin_small(sqrt(0.5 * (1.0 - c)));
    }
    if (c < -0.5) {
        return 2.0 * half_pi - 2.0 * ams_asin_small(sqrt(0.5 * (1.0 + c)));
    }
    return half_pi - ams_asin_small(c);
}

// The column k0 below θ = acos(cos θ) and the weight t of column k0 + 1.
struct AmsColumn {
    k0: u32,
    t: f32,
}

fn ams_column(cos_theta: f32) -> AmsColumn {
    let theta = ams_angle(cos_theta);
    let last = f32(ams_params.angle_count - 1u);
    let u = min(theta * ams_params.inv_step_rad, last);
    let k0 = min(u32(floor(u)), ams_params.angle_count - 2u);
    return AmsColumn(k0, u - f32(k0));
}

// Ams_n(θ) of `field` (1/sr per channel), linear in θ and in fractional n.
fn ams(field: u32, n: f32, cos_theta: f32) -> vec3<f32> {
    let col = ams_column(cos_theta);
    let o = ams_order(field, n);
    return mix(ams_row(field, u32(o.x), col.k0, col.t), ams_row(field, u32(o.y), col.k0, col.t), o.z);
}

// F_n of `field` per channel, linear in fractional n.
fn forward_fraction(field: u32, n: f32) -> vec3<f32> {
    let o = ams_order(field, n);
    let base = field * ams_params.n_stride;
    let a = ams_forward_fraction[base + u32(o.x)].rgb;
    let b = ams_forward_fraction[base + u32(o.y)].rgb;
    return mix(a, b, o.z);
}

// Phase function of the first four fields mixed at one place (Riley et al. 2004 Eq. 6):
// Σ ρ_i σ_sca,i P_i / Σ ρ_i σ_sca,i per channel; zero where nothing scatters.
fn ams_mix(densities: vec4<f32>, n: f32, cos_theta: f32) -> vec3<f32> {
    var num = vec3<f32>(0.0);
    var den = vec3<f32>(0.0);
    for (var i = 0u; i < min(ams_params.field_count, 4u); i = i + 1u) {
        let rho = densities[i];
        if (rho > 0.0) {
            let w = rho * ams_field_info[i].yzw;
            num = num + w * ams(i, n, cos_theta);
            den = den + w;
        }
    }
    return select(vec3<f32>(0.0), num / den, den > vec3<f32>(0.0));
}

// A swept field (the manifest's `sweeps`: one member field per value) whose `count` members
// are the consecutive layers first … first + count − 1, their values equally spaced in
// at(value) = ln value (log spacing) or value (linear): at_first = at(v_0), at_step =
// at(v_1) − at(v_0). The member layer below `at_value` (clamped to the sweep) and the weight t
// of the next, linear in at(value) (format::SweepEntry::shares).
struct SweepPoint {
    layer: u32,
    t: f32,
}

fn sweep_point(first: u32, count: u32, at_first: f32, at_step: f32, at_value: f32) -> SweepPoint {
    let u = clamp((at_value - at_first) / at_step, 0.0, f32(count - 1u));
    let k = min(u32(floor(u)), count - 2u);
    return SweepPoint(first + k, u - f32(k));
}

// The two members' weights per channel in a mixture (Riley et al. 2004 Eq. 6) with the number
// shares of format::SweepEntry::shares: (1 − t) σ_sca,c/σ_sca,G of the lower member and
// t σ_sca,c/σ_sca,G of the upper, normalized. The shares divide by the green σ_ext, which the
// shader does not hold; σ_sca in its place differs by the members' albedo, 1 − ω < 10⁻⁴ for
// water and ice in the visible (runtime::sample::ams_sweep is the exact reference).
fn sweep_weights(s: SweepPoint) -> array<vec3<f32>, 2> {
    let a = ams_field_info[s.layer];
    let b = ams_field_info[s.layer + 1u];
    let w0 = (1.0 - s.t) * a.yzw / a.z;
    let w1 = s.t * b.yzw / b.z;
    let total = w0 + w1;
    return array<vec3<f32>, 2>(w0 / total, w1 / total);
}

// Ams_n(θ) of a swept field at `at_value` (ln of the size for a log sweep): the members around
// it mixed as one place mixes fields.
fn ams_sweep(first: u32, count: u32, at_first: f32, at_step: f32, at_value: f32, n: f32,
        cos_theta: f32) -> vec3<f32> {
    let s = sweep_point(first, count, at_first, at_step, at_value);
    let w = sweep_weights(s);
    return w[0] * ams(s.layer, n, cos_theta) + w[1] * ams(s.layer + 1u, n, cos_theta);
}

// F_n of a swept field at `at_value`, weighted like ams_sweep.
fn forward_fraction_sweep(first: u32, count: u32, at_first: f32, at_step: f32, at_value: f32,
        n: f32) -> vec3<f32> {
    let s = sweep_point(first, count, at_first, at_step, at_value);
    let w = sweep_weights(s);
    return w[0] * forward_fraction(s.layer, n) + w[1] * forward_fraction(s.layer + 1u, n);
}

// (J_P, J_B, first Poisson depth, first Biri depth) of `field` (see the layout above).
fn model_header(field: u32) -> vec4<u32> {
    let b = 4u * field;
    return vec4<u32>(
        u32(model_depths[b]),
        u32(model_depths[b + 1u]),
        u32(model_depths[b + 2u]),
        u32(model_depths[b + 3u]),
    );
}

fn model_row(field: u32, row: u32, k0: u32, t: f32) -> vec3<f32> {
    let a = textureLoad(model_table, vec2<i32>(i32(k0), i32(row)), i32(field), 0).rgb;
    let b = textureLoad(model_table, vec2<i32>(i32(k0 + 1u), i32(row)), i32(field), 0).rgb;
    return mix(a, b, t);
}

// The number of depths first..first + count that are ≤ d (a binary search).
fn model_depths_below(first: u32, count: u32, d: f32) -> u32 {
    var lo = 0u;
    var hi = count;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (model_depths[first + mid] <= d) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// Max et al.'s Poisson mixture M(D, θ) = Σ_{i≥1} q_i(D) Ams_i(θ) / (1 − q_0(D)) of `field`
// (1/sr), each channel at its own optical depth `depth_rgb` (Max et al. 2004 Eqs. 8-9): linear in
// θ as `ams`, linear in ln D between the table's depths; below the first depth D_1 linear in D
// from M(0) = Ams_1 to the first row; beyond the last depth the last row. Zero for a field
// without the table. Specification: runtime::sample::poisson.
fn poisson(field: u32, depth_rgb: vec3<f32>, cos_theta: f32) -> vec3<f32> {
    let h = model_header(field);
    if (h.x == 0u) {
        return vec3<f32>(0.0);
    }
    let col = ams_column(cos_theta);
    var out = vec3<f32>(0.0);
    for (var c = 0u; c < 3u; c = c + 1u) {
        let d = depth_rgb[c];
        let j = model_depths_below(h.z, h.x, d);
        if (j == 0u) {
            let single = ams_row(field, 0u, col.k0, col.t)[c];
            let s = max(d / model_depths[h.z], 0.0);
            out[c] = mix(single, model_row(field, 0u, col.k0, col.t)[c], s);
        } else if (j >= h.x) {
            out[c] = model_row(field, h.x - 1u, col.k0, col.t)[c];
        } else {
            let a = log(model_depths[h.z + j - 1u]);
            let b = log(model_depths[h.z + j]);
            let s = (log(d) - a) / (b - a);
            let lo = model_row(field, j - 1u, col.k0, col.t)[c];
            out[c] = mix(lo, model_row(field, j, col.k0, col.t)[c], s);
        }
    }
    return out;
}

// Three rows of the Biri depths and their quadratic-in-ln τ weights (grid::depth_weights):
// linear in τ from 0 to the first positive depth, then the Lagrange parabola in ln τ through
// the depth at or below τ and its two neighbours (the last three at the end).
struct BiriWeights {
    j: vec3<u32>,
    w: vec3<f32>,
}

fn biri_depth_weights(field: u32, tau_in: f32) -> BiriWeights {
    let h = model_header(field);
    let n = h.y;
    let first = h.w;
    let tau = clamp(tau_in, 0.0, model_depths[first + n - 1u]);
    let d1 = model_depths[first + 1u];
    if (tau <= d1) {
        let s = tau / d1;
        return BiriWeights(vec3<u32>(0u, 1u, 2u), vec3<f32>(1.0 - s, s, 0.0));
    }
    let j = clamp(model_depths_below(first, n, tau), 2u, n - 1u);
    var abc = vec3<u32>(j - 1u, j, j + 1u);
    if (j + 1u >= n) {
        abc = vec3<u32>(j - 2u, j - 1u, j);
    }
    let x = log(tau);
    let xa = log(model_depths[first + abc.x]);
    let xb = log(model_depths[first + abc.y]);
    let xc = log(model_depths[first + abc.z]);
    return BiriWeights(abc, vec3<f32>(
        (x - xb) * (x - xc) / ((xa - xb) * (xa - xc)),
        (x - xa) * (x - xc) / ((xb - xa) * (xb - xc)),
        (x - xa) * (x - xb) / ((xc - xa) * (xc - xb)),
    ));
}

// Biri et al.'s kernel primitive C(τ_h, θ) of `field`, each channel at its own optical depth
// `tau_h` from the light to the ray (Biri et al. 2006 Eq. 2; θ ∈ [−π/2, π/2] the angle at the
// light from the ray's foot point, radians): the table's C at the bin centre θ_k (quadratic in
// ln τ_h between the depths), plus the Ams_1 bin value times ∫ from θ_k to θ of e^{−τ_h g} by
// the midpoint rule, g = tan(θ/2 + π/4): exact to the bins. Zero for a field without the
// table. Specification: runtime::sample::biri_primitive. A lit piece of a ray from θ_0 to θ_1
// receives C(θ_1) − C(θ_0) (times σ_sca and the light's intensity over the distance h).
fn biri_primitive(field: u32, tau_h: vec3<f32>, theta_in: f32) -> vec3<f32> {
    let h = model_header(field);
    if (h.y == 0u) {
        return vec3<f32>(0.0);
    }
    let half_pi = 1.5707963267948966;
    let step = 1.0 / ams_params.inv_step_rad;
    let theta = clamp(theta_in, -half_pi, half_pi);
    let k = min(u32(round((theta + half_pi) * ams_params.inv_step_rad)), ams_params.angle_count - 1u);
    let centre = f32(k) * step - half_pi;
    let p = textureLoad(ams_table, vec2<i32>(i32(k), 0), i32(field), 0).rgb;
    // g at the middle of [θ_k, θ]: tan φ, φ ∈ [π/4, π/2]. At φ = π/2 (θ = θ_k = π/2) the
    // kernel is 0; f32 π/2 lies above the true one, where some drivers' tan turns negative
    // and e^{−τ g} would overflow into ∞ · 0.
    let phi = 0.25 * (theta + centre) + 0.7853981633974483;
    let g = tan(phi);
    let last = model_depths[h.w + h.y - 1u];
    var out = vec3<f32>(0.0);
    for (var c = 0u; c < 3u; c = c + 1u) {
        let w = biri_depth_weights(field, tau_h[c]);
        var at = 0.0;
        for (var i = 0u; i < 3u; i = i + 1u) {
            let row = h.x + w.j[i];
            at = at + w.w[i] * textureLoad(model_table, vec2<i32>(i32(k), i32(row)), i32(field), 0)[c];
        }
        var e = 1.0;
        if (tau_h[c] > 0.0) {
            e = select(0.0, exp(-min(tau_h[c], last) * g), g >= 0.0 && phi < half_pi);
        }
        out[c] = at + p[c] * e * (theta - centre);
    }
    return out;
}
