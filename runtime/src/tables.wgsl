// photometeor tables on the GPU: sampling functions a renderer includes (bind group 0).
//
// Layout (runtime::gpu docs): `ams_table` is a 2-D texture array, width K (θ_k = k·Δθ), height
// N (row r = Ams_{r+1}), one layer per field; RGBA with A unused. Fields with fewer rows than
// the largest N repeat their last row. Texels are read with textureLoad and interpolated here,
// so no filterable-float feature is needed. `ams_forward_fraction[field * n_stride + n − 1]`
// holds F_n (RGB), `ams_field_info[field]` holds (N, σ_sca R, G, B).

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

// Ams_n(θ) of `field` (1/sr per channel), linear in θ and in fractional n.
fn ams(field: u32, n: f32, cos_theta: f32) -> vec3<f32> {
    let theta = ams_angle(cos_theta);
    let last = f32(ams_params.angle_count - 1u);
    let u = min(theta * ams_params.inv_step_rad, last);
    let k0 = min(u32(floor(u)), ams_params.angle_count - 2u);
    let t = u - f32(k0);
    let o = ams_order(field, n);
    return mix(ams_row(field, u32(o.x), k0, t), ams_row(field, u32(o.y), k0, t), o.z);
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
