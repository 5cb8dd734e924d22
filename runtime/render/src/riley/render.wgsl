// photometeor's renderer (runtime::render docs): half-angle slicing with a light buffer and an
// eye buffer, Riley et al. 2004 Eqs. 6, 21/22, 25, 26 and the analytic sky (Eqs. 11–15).
// Included after tables.wgsl (bind group 0), slicing.wgsl and compose.wgsl. The CPU reference is
// render::riley::cpu.

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
    let scattered = lit.rgb * sunlight(p.y, rp.light_texel.z) * rp.irradiance.rgb * (phase + rp.up.w) * albedo
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
    // render::LightUpdate::keep.
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

// The fraction of sunlight the volume leaves at a point past it: the final light buffer, 1
// outside its footprint (the ground's and the air's below the grid, compose.wgsl).
fn sun_left(g: vec3<f32>) -> vec3<f32> {
    let res = f32(rp.sizes.z);
    let u = (dot(rp.light_u.xyz, g) - rp.light_u.w) / rp.light_texel.x - 0.5;
    let w = (dot(rp.light_w.xyz, g) - rp.light_w.w) / rp.light_texel.y - 0.5;
    if (u >= -0.5 && u <= res - 0.5 && w >= -0.5 && w <= res - 0.5) {
        return light_at(g).rgb;
    }
    return vec3<f32>(1.0);
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
    // The ground lit through the final light buffer (1 outside it).
    var lit = vec3<f32>(1.0);
    let k_end = ground_distance(d);
    if (rp.grid_min.w > 0.0 && k_end > 0.0) {
        lit = sun_left(rp.eye.xyz + k_end * d);
    }
    let v = compose(d, l_vol, t_vol, t_vol, lit);
    image[i] = vec4<f32>(v, t_vol.g);
}
