// photometeor's renderer (runtime::render docs): half-angle slicing with a light buffer and an
// eye buffer, Riley et al. 2004 Eqs. 6, 21/22, 25, 26 and the analytic sky (Eqs. 11–15).
// Included after tables.wgsl (bind group 0). The CPU reference is runtime::render::cpu.

struct RenderParams {
    eye: vec4<f32>,          // xyz; w = 1 front to back, 0 back to front
    forward: vec4<f32>,      // xyz; w = tan(fov_y / 2)
    right: vec4<f32>,        // xyz; w = aspect
    up: vec4<f32>,           // xyz; w = ξ (1/sr)
    light: vec4<f32>,        // direction of travel; w = slice spacing Δ (m)
    half_vector: vec4<f32>,  // xyz; w = 1: continuum light update, 0: Eq. 25 as printed
    light_u: vec4<f32>,      // xyz; w = light-buffer origin along u
    light_w: vec4<f32>,      // xyz; w = light-buffer origin along w
    light_texel: vec4<f32>,  // texel size u, w (m); z = sun's y component; w unused
    grid_min: vec4<f32>,     // xyz; w = ground albedo (Lambertian, 0: black)
    grid_max: vec4<f32>,
    grid_dims: vec4<u32>,    // nx, ny, nz, field count
    sizes: vec4<u32>,        // width, height, light resolution, 0
    sigma_ext: array<vec4<f32>, 4>,  // per field, m² per channel
    sky_beta: vec4<f32>,     // β at sea level per channel (1/m); w = γ (1/m)
    sun: vec4<f32>,          // unit vector towards the sun; w = cos(disk radius)
    irradiance: vec4<f32>,   // per channel; w = disk solid angle (sr)
}

struct SliceParams {
    plane: f32,
    index: u32,
    pad0: u32,
    pad1: u32,
}

@group(1) @binding(0) var<uniform> rp: RenderParams;
@group(1) @binding(1) var<storage, read> density: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read_write> light_buffer: array<vec4<f32>>;  // I rgb, n
@group(1) @binding(3) var<storage, read_write> eye_buffer: array<vec4<f32>>;    // L, T pairs
@group(1) @binding(4) var<storage, read_write> image: array<vec4<f32>>;         // rgb, T_vol
@group(1) @binding(5) var<uniform> slice: SliceParams;

fn inside_box(p: vec3<f32>) -> bool {
    return all(p >= rp.grid_min.xyz) && all(p <= rp.grid_max.xyz);
}

fn voxel(x: u32, y: u32, z: u32) -> vec4<f32> {
    return density[x + rp.grid_dims.x * (y + rp.grid_dims.y * z)];
}

// Trilinear densities at p, voxel centres, clamped to the edge voxels; zero outside the box.
fn densities(p: vec3<f32>) -> vec4<f32> {
    if (!inside_box(p)) {
        return vec4<f32>(0.0);
    }
    let dims = vec3<f32>(rp.grid_dims.xyz);
    let u = clamp((p - rp.grid_min.xyz) / (rp.grid_max.xyz - rp.grid_min.xyz) * dims - 0.5,
        vec3<f32>(0.0), dims - 1.0);
    let top = max(vec3<i32>(rp.grid_dims.xyz) - 2, vec3<i32>(0));
    let lo = vec3<u32>(min(vec3<i32>(floor(u)), top));
    let t = select(vec3<f32>(0.0), u - vec3<f32>(lo), rp.grid_dims.xyz > vec3<u32>(1u));
    let s = vec3<u32>(rp.grid_dims.xyz > vec3<u32>(1u));
    let c00 = mix(voxel(lo.x, lo.y, lo.z), voxel(lo.x + s.x, lo.y, lo.z), t.x);
    let c10 = mix(voxel(lo.x, lo.y + s.y, lo.z), voxel(lo.x + s.x, lo.y + s.y, lo.z), t.x);
    let c01 = mix(voxel(lo.x, lo.y, lo.z + s.z), voxel(lo.x + s.x, lo.y, lo.z + s.z), t.x);
    let c11 = mix(voxel(lo.x, lo.y + s.y, lo.z + s.z), voxel(lo.x + s.x, lo.y + s.y, lo.z + s.z), t.x);
    return mix(mix(c00, c10, t.y), mix(c01, c11, t.y), t.z);
}

fn extinction(rho: vec4<f32>) -> vec3<f32> {
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid_dims.w; i = i + 1u) {
        e = e + rho[i] * rp.sigma_ext[i].rgb;
    }
    return e;
}

fn scattering(rho: vec4<f32>) -> vec3<f32> {
    var s = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid_dims.w; i = i + 1u) {
        s = s + rho[i] * ams_field_info[i].yzw;
    }
    return s;
}

// F_n of the mixture, weighted by ρ σ_sca like Eq. 6.
fn forward_fraction_mix(rho: vec4<f32>, n: f32) -> vec3<f32> {
    var num = vec3<f32>(0.0);
    var den = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid_dims.w; i = i + 1u) {
        if (rho[i] > 0.0) {
            let w = rho[i] * ams_field_info[i].yzw;
            num = num + w * forward_fraction(i, n);
            den = den + w;
        }
    }
    return select(vec3<f32>(1.0), num / den, den > vec3<f32>(0.0));
}

fn pixel_ray(i: u32, j: u32) -> vec3<f32> {
    let sx = (2.0 * (f32(i) + 0.5) / f32(rp.sizes.x) - 1.0) * rp.forward.w * rp.right.w;
    let sy = (1.0 - 2.0 * (f32(j) + 0.5) / f32(rp.sizes.y)) * rp.forward.w;
    return normalize(rp.forward.xyz + sx * rp.right.xyz + sy * rp.up.xyz);
}

// e^x − 1 without cancellation for small x.
fn expm1(x: f32) -> f32 {
    if (abs(x) < 1e-2) {
        return x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x / 24.0)));
    }
    return exp(x) - 1.0;
}

// Sunlight left at height y (Eq. 12).
fn sunlight(y: f32) -> vec3<f32> {
    let g = rp.sky_beta.w;
    return exp(-rp.sky_beta.rgb / (g * rp.light_texel.z) * exp(-g * y));
}

// (1 − e^{−γ p K})/p; K < 0 means ∞.
fn path_factor(p_y: f32, k: f32) -> f32 {
    let g = rp.sky_beta.w;
    if (k < 0.0) {
        return select(1e30, 1.0 / p_y, p_y > 0.0);
    }
    let x = g * p_y * k;
    if (abs(x) < 1e-8) {
        return g * k;
    }
    return -expm1(-x) / p_y;
}

fn air_transparency(y: f32, p_y: f32, k: f32) -> vec3<f32> {
    let g = rp.sky_beta.w;
    let beta_eye = rp.sky_beta.rgb * exp(-g * y);
    return exp(-beta_eye / g * path_factor(p_y, k));
}

// Sky light from the first K metres of the ray (runtime::render::sky::Atmosphere::inscatter).
fn inscatter(y: f32, p_y: f32, k: f32, cos_sun: f32) -> vec3<f32> {
    if (k == 0.0) {
        return vec3<f32>(0.0);
    }
    let g = rp.sky_beta.w;
    let l_y = rp.light_texel.z;
    let phase = 3.0 / (16.0 * 3.14159265358979) * (1.0 + cos_sun * cos_sun);
    let beta_eye = rp.sky_beta.rgb * exp(-g * y);
    let q = beta_eye / g * path_factor(p_y, k) / l_y;
    let e2 = -beta_eye / (g * l_y);
    let eps = p_y - l_y;
    var factor: vec3<f32>;
    for (var c = 0; c < 3; c = c + 1) {
        if (abs(q[c] * eps) < 1e-9) {
            factor[c] = q[c];
        } else {
            factor[c] = expm1(q[c] * eps) / eps;
        }
    }
    return phase * l_y * exp(e2) * factor;
}

fn light_at(p: vec3<f32>) -> vec4<f32> {
    let res = rp.sizes.z;
    let top = f32(res - 1u);
    let u = clamp((dot(rp.light_u.xyz, p) - rp.light_u.w) / rp.light_texel.x - 0.5, 0.0, top);
    let v = clamp((dot(rp.light_w.xyz, p) - rp.light_w.w) / rp.light_texel.y - 0.5, 0.0, top);
    let a0 = min(u32(floor(u)), res - 2u);
    let b0 = min(u32(floor(v)), res - 2u);
    let s = u - f32(a0);
    let t = v - f32(b0);
    let l00 = light_buffer[a0 + res * b0];
    let l10 = light_buffer[a0 + 1u + res * b0];
    let l01 = light_buffer[a0 + res * (b0 + 1u)];
    let l11 = light_buffer[a0 + 1u + res * (b0 + 1u)];
    return mix(mix(l00, l10, s), mix(l01, l11, s), t);
}

@compute @workgroup_size(8, 8)
fn clear(@builtin(global_invocation_id) id: vec3<u32>) {
    let res = rp.sizes.z;
    if (id.x < res && id.y < res) {
        light_buffer[id.x + res * id.y] = vec4<f32>(1.0, 1.0, 1.0, 0.0);
    }
    if (id.x < rp.sizes.x && id.y < rp.sizes.y) {
        let i = id.x + rp.sizes.x * id.y;
        eye_buffer[2u * i] = vec4<f32>(0.0);
        eye_buffer[2u * i + 1u] = vec4<f32>(1.0);
    }
}

@compute @workgroup_size(8, 8)
fn eye_slice(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.sizes.x || id.y >= rp.sizes.y) {
        return;
    }
    let d = pixel_ray(id.x, id.y);
    let hd = dot(rp.half_vector.xyz, d);
    if (abs(hd) < 1e-9) {
        return;
    }
    let t = (slice.plane - dot(rp.half_vector.xyz, rp.eye.xyz)) / hd;
    if (t <= 0.0) {
        return;
    }
    let p = rp.eye.xyz + t * d;
    let rho = densities(p);
    let ext = extinction(rho);
    if (all(ext <= vec3<f32>(0.0))) {
        return;
    }
    let sca = scattering(rho);
    let albedo = select(vec3<f32>(0.0), sca / ext, ext > vec3<f32>(0.0));
    var lit = light_at(p);
    if (rp.half_vector.w > 0.5) {
        // The light at the slab's middle (cpu::cross_slab over half the light's path).
        let tau_h = ext * (0.5 * rp.light.w / dot(rp.half_vector.xyz, rp.light.xyz));
        let f_h = forward_fraction_mix(rho, lit.w + 1.0 + tau_h.g);
        let kept = select(vec3<f32>(1.0), exp(-tau_h * (1.0 - albedo * f_h)), ext > vec3<f32>(0.0));
        var n_h = lit.w;
        if (ext.g > 0.0) {
            n_h = n_h + albedo.g * tau_h.g;
        }
        lit = vec4<f32>(lit.rgb * kept, n_h);
    }
    let phase = ams_mix(rho, lit.w + 1.0, -dot(rp.light.xyz, d));
    let thickness = rp.light.w / abs(hd);
    let slab = exp(-ext * thickness);
    let scattered = lit.rgb * sunlight(p.y) * rp.irradiance.rgb * (phase + rp.up.w) * albedo
        * (1.0 - slab);
    let i = id.x + rp.sizes.x * id.y;
    let l = eye_buffer[2u * i].rgb;
    let tr = eye_buffer[2u * i + 1u].rgb;
    if (rp.eye.w > 0.5) {
        eye_buffer[2u * i] = vec4<f32>(l + tr * scattered, 0.0);
    } else {
        eye_buffer[2u * i] = vec4<f32>(scattered + slab * l, 0.0);
    }
    eye_buffer[2u * i + 1u] = vec4<f32>(tr * slab, 0.0);
}

@compute @workgroup_size(8, 8)
fn light_slice(@builtin(global_invocation_id) id: vec3<u32>) {
    let res = rp.sizes.z;
    if (id.x >= res || id.y >= res) {
        return;
    }
    let q = rp.light_u.xyz * (rp.light_u.w + (f32(id.x) + 0.5) * rp.light_texel.x)
        + rp.light_w.xyz * (rp.light_w.w + (f32(id.y) + 0.5) * rp.light_texel.y);
    let h_dot_l = dot(rp.half_vector.xyz, rp.light.xyz);
    let t = (slice.plane - dot(rp.half_vector.xyz, q)) / h_dot_l;
    let p = q + t * rp.light.xyz;
    let rho = densities(p);
    let ext = extinction(rho);
    if (all(ext <= vec3<f32>(0.0))) {
        return;
    }
    let sca = scattering(rho);
    let tau = ext * (rp.light.w / h_dot_l);
    let texel = light_buffer[id.x + res * id.y];
    let f = forward_fraction_mix(rho, texel.w + 1.0 + tau.g);
    let albedo = select(vec3<f32>(0.0), sca / ext, ext > vec3<f32>(0.0));
    // runtime::render::LightUpdate::keep.
    var kept: vec3<f32>;
    if (rp.half_vector.w > 0.5) {
        kept = exp(-tau * (1.0 - albedo * f));
    } else {
        let through = exp(-tau);
        kept = through + (1.0 - through) * pow(max(albedo * f, vec3<f32>(1e-30)), tau);
    }
    let i = texel.rgb;
    let lit = select(i, i * kept, ext > vec3<f32>(0.0));
    var n = texel.w;
    if (ext.g > 0.0) {
        n = n + albedo.g * tau.g;
    }
    light_buffer[id.x + res * id.y] = vec4<f32>(lit, n);
}

// Where the ray enters and leaves the box (t ≥ 0), or (−1, −1).
fn box_span(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    var t0 = 0.0;
    var t1 = 3.0e38;
    for (var a = 0; a < 3; a = a + 1) {
        if (d[a] == 0.0) {
            if (o[a] < rp.grid_min[a] || o[a] > rp.grid_max[a]) {
                return vec2<f32>(-1.0);
            }
            continue;
        }
        let inv = 1.0 / d[a];
        let lo = (rp.grid_min[a] - o[a]) * inv;
        let hi = (rp.grid_max[a] - o[a]) * inv;
        t0 = max(t0, min(lo, hi));
        t1 = min(t1, max(lo, hi));
    }
    return select(vec2<f32>(-1.0), vec2<f32>(t0, t1), t0 < t1);
}

@compute @workgroup_size(8, 8)
fn composite(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.sizes.x || id.y >= rp.sizes.y) {
        return;
    }
    let i = id.x + rp.sizes.x * id.y;
    let d = pixel_ray(id.x, id.y);
    let l_vol = eye_buffer[2u * i].rgb;
    let t_vol = eye_buffer[2u * i + 1u].rgb;
    let y = rp.eye.y;
    let span = box_span(rp.eye.xyz, d);
    var k_mid = select(0.0, 0.5 * (span.x + span.y), span.y >= 0.0);
    // K < 0 stands for ∞ (the ray leaves the atmosphere without meeting the ground).
    var k_end = -1.0;
    if (d.y < 0.0) {
        k_end = select(0.0, y / -d.y, y > 0.0);
        k_mid = min(k_mid, k_end);
    }
    let cos_sun = dot(d, rp.sun.xyz);
    let front = inscatter(y, d.y, k_mid, cos_sun);
    let all_sky = inscatter(y, d.y, k_end, cos_sun);
    let t_mid = air_transparency(y, d.y, k_mid);
    let i_s = rp.irradiance.rgb;
    var v = i_s * (front + t_vol * (all_sky - front)) + t_mid * l_vol;
    if (k_end < 0.0 && cos_sun >= rp.sun.w) {
        v = v + t_vol * i_s * air_transparency(y, d.y, -1.0) / rp.irradiance.w;
    }
    if (rp.grid_min.w > 0.0 && k_end > 0.0) {
        // The ground, lit through the air and the final light buffer (1 outside it).
        let g = rp.eye.xyz + k_end * d;
        let res = f32(rp.sizes.z);
        let u = (dot(rp.light_u.xyz, g) - rp.light_u.w) / rp.light_texel.x - 0.5;
        let w = (dot(rp.light_w.xyz, g) - rp.light_w.w) / rp.light_texel.y - 0.5;
        var lit = vec3<f32>(1.0);
        if (u >= -0.5 && u <= res - 0.5 && w >= -0.5 && w <= res - 0.5) {
            lit = light_at(g).rgb;
        }
        let l_y = rp.light_texel.z;
        v = v + t_vol * i_s * (rp.grid_min.w / 3.14159265358979 * l_y) * sunlight(0.0) * lit
            * air_transparency(y, d.y, k_end);
    }
    image[i] = vec4<f32>(v, t_vol.g);
}
