// photometeor's renderer (runtime::render docs): half-angle slicing with a light buffer and an
// eye buffer, Riley et al. 2004 Eqs. 6, 21/22, 25, 26 and the analytic sky (Eqs. 11–15).
// Included after tables.wgsl (bind group 0), slicing.wgsl and compose.wgsl. The CPU reference is
// render::riley::cpu.

// The half-angle slices and how light crosses them.
struct Slices {
    light: vec3<f32>,        // the sunlight's direction of travel
    spacing: f32,            // Δ (m)
    half_vector: vec3<f32>,
    continuum: u32,          // 1: the continuum light update, 0: Eq. 25 as printed
    xi: f32,                 // ξ (1/sr)
    front_to_back: u32,      // 1: slices front to back, 0: back to front
    pad0: u32,
    pad1: u32,
}

struct RenderParams {
    view: View,
    slices: Slices,
    light_buffer: TexturePlane,
    grid: Grid,
    sizes: vec4<u32>,        // width, height, light resolution, 0
    sigma_ext: array<vec4<f32>, 4>,  // per field, m² per channel
    sky: Sky,
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
    for (var i = 0u; i < rp.grid.fields; i = i + 1u) {
        s = s + rho[i] * ams_field_info[i].yzw;
    }
    return s;
}

// F_n of the mixture, weighted by ρ σ_sca like Eq. 6.
fn forward_fraction_mix(rho: vec4<f32>, n: f32) -> vec3<f32> {
    var num = vec3<f32>(0.0);
    var den = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid.fields; i = i + 1u) {
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
    let u = clamp((dot(rp.light_buffer.u, p) - rp.light_buffer.u_origin) / rp.light_buffer.texel.x - 0.5, 0.0, top);
    let v = clamp((dot(rp.light_buffer.w, p) - rp.light_buffer.w_origin) / rp.light_buffer.texel.y - 0.5, 0.0, top);
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
    let o = camera_origin(id.x, id.y);
    let d = camera_direction(id.x, id.y);
    let hd = dot(rp.slices.half_vector, d);
    if (abs(hd) < 1e-9) {
        return;
    }
    let t = (slice.plane - dot(rp.slices.half_vector, o)) / hd;
    if (t <= 0.0) {
        return;
    }
    let p = o + t * d;
    let rho = densities(p);
    let ext = extinction(rho);
    if (all(ext <= vec3<f32>(0.0))) {
        return;
    }
    let sca = scattering(rho);
    let albedo = select(vec3<f32>(0.0), sca / ext, ext > vec3<f32>(0.0));
    var lit = light_at(p);
    if (rp.slices.continuum != 0u) {
        // The light at the slab's middle (cpu::cross_slab over half the light's path).
        let tau_h = ext * (0.5 * rp.slices.spacing / dot(rp.slices.half_vector, rp.slices.light));
        let f_h = forward_fraction_mix(rho, lit.w + 1.0 + tau_h.g);
        let kept = select(vec3<f32>(1.0), exp(-tau_h * (1.0 - albedo * f_h)), ext > vec3<f32>(0.0));
        var n_h = lit.w;
        if (ext.g > 0.0) {
            n_h = n_h + albedo.g * tau_h.g;
        }
        lit = vec4<f32>(lit.rgb * kept, n_h);
    }
    let phase = ams_mix(rho, lit.w + 1.0, -dot(rp.slices.light, d));
    let thickness = rp.slices.spacing / abs(hd);
    let slab = exp(-ext * thickness);
    let scattered = lit.rgb * sunlight(p.y, rp.sky.sun.y) * rp.sky.irradiance * (phase + rp.slices.xi) * albedo
        * (1.0 - slab);
    let i = id.x + rp.sizes.x * id.y;
    let l = eye_buffer[2u * i].rgb;
    let tr = eye_buffer[2u * i + 1u].rgb;
    if (rp.slices.front_to_back != 0u) {
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
    let q = rp.light_buffer.u * (rp.light_buffer.u_origin + (f32(id.x) + 0.5) * rp.light_buffer.texel.x)
        + rp.light_buffer.w * (rp.light_buffer.w_origin + (f32(id.y) + 0.5) * rp.light_buffer.texel.y);
    let h_dot_l = dot(rp.slices.half_vector, rp.slices.light);
    let t = (slice.plane - dot(rp.slices.half_vector, q)) / h_dot_l;
    let p = q + t * rp.slices.light;
    let rho = densities(p);
    let ext = extinction(rho);
    if (all(ext <= vec3<f32>(0.0))) {
        return;
    }
    let sca = scattering(rho);
    let tau = ext * (rp.slices.spacing / h_dot_l);
    let texel = light_buffer[id.x + res * id.y];
    let f = forward_fraction_mix(rho, texel.w + 1.0 + tau.g);
    let albedo = select(vec3<f32>(0.0), sca / ext, ext > vec3<f32>(0.0));
    // render::LightUpdate::keep.
    var kept: vec3<f32>;
    if (rp.slices.continuum != 0u) {
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
    let u = (dot(rp.light_buffer.u, g) - rp.light_buffer.u_origin) / rp.light_buffer.texel.x - 0.5;
    let w = (dot(rp.light_buffer.w, g) - rp.light_buffer.w_origin) / rp.light_buffer.texel.y - 0.5;
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
    let o = camera_origin(id.x, id.y);
    let d = camera_direction(id.x, id.y);
    let l_vol = eye_buffer[2u * i].rgb;
    let t_vol = eye_buffer[2u * i + 1u].rgb;
    // The ground lit through the final light buffer (1 outside it).
    var lit = vec3<f32>(1.0);
    let k_end = ground_distance(o, d);
    if (rp.grid.ground_albedo > 0.0 && k_end > 0.0) {
        lit = sun_left(o + k_end * d);
    }
    let v = compose(o, d, l_vol, t_vol, t_vol, lit);
    image[i] = vec4<f32>(v, t_vol.g);
}
