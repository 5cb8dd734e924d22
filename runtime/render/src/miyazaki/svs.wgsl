// Miyazaki, Dobashi & Nishita's shadow-view slices (render::miyazaki docs): per slice
// the shadow surface first (Eq. 10), then the screen (Eqs. 8, 9, blended as §4.3), then the
// composite with the air outside the slices, the ground and the sun disk. Included after
// tables.wgsl (bind group 0) and slicing.wgsl. The CPU reference is
// render::miyazaki::cpu; this follows it step for step.

// The shadow-view slices.
struct Slices {
    to_sun: vec3<f32>,       // unit vector towards the sun
    spacing: f32,            // Δ (m)
    normal: vec3<f32>,       // the slices' unit normal
    sun_path: f32,           // Δs, the sun's path per slice (m)
    plane_min: f32,          // the lower plane value of the slices' range (m)
    plane_max: f32,          // the upper plane value (m)
    back_to_front: u32,      // 1: slices back to front, 0: front to back
    pad: u32,
}

struct Shading {
    k_multi: f32,            // 1/sr
    cornette_shanks: u32,    // 1: the Cornette–Shanks phase function
    haze_field: u32,         // the haze's field + 1 (0: none)
    pad: u32,
}

// The haze layer (Miyazaki et al.'s aerosol).
struct Haze {
    ext: vec3<f32>,          // N_0 σ_ext per channel (1/m)
    inv_height: f32,         // 1/H_haze (1/m)
    sca: vec3<f32>,          // N_0 σ_sca per channel (1/m)
    pad: f32,
}

struct SvsParams {
    view: View,
    slices: Slices,
    shadow: TexturePlane,    // the shadow surface
    shading: Shading,
    grid: Grid,
    sizes: vec4<u32>,        // width, height, shadow resolution, 0
    sigma_ext: array<vec4<f32>, 4>,  // per field, m² per channel
    g: array<vec4<f32>, 4>,          // per field, Cornette–Shanks asymmetry per channel
    sky: Sky,
    haze: Haze,
}

struct SliceParams {
    plane: f32,
    index: u32,
    pad0: u32,
    pad1: u32,
}

@group(1) @binding(0) var<uniform> rp: SvsParams;
@group(1) @binding(1) var<storage, read> density: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read_write> shadow: array<vec4<f32>>;   // g_sun_cl rgb
@group(1) @binding(3) var<storage, read_write> eye_buffer: array<vec4<f32>>; // S, α*, T_cl
@group(1) @binding(4) var<storage, read_write> image: array<vec4<f32>>;      // rgb, T_vol
@group(1) @binding(5) var<uniform> slice: SliceParams;
// Per pixel (the paper's Mie scattering texture): (P_f(α) + k_multi) σ_sca,f per field, then
// the haze's N_0 σ_sca P(α) (rgb) with the Rayleigh phase in w.
@group(1) @binding(6) var<storage, read_write> pixel_tex: array<vec4<f32>>;

const PI: f32 = 3.14159265358979;
const HAZY_AIR_STEP_TAU: f32 = 0.02;
const HAZY_AIR_MAX_STEP_M: f32 = 2000.0;
const SHADOWED_AIR_POINTS: u32 = 64u;
const SHADOWED_AIR_MAX_M: f32 = 200000.0;

fn haze_on() -> bool {
    return rp.shading.haze_field > 0u;
}

fn cornette_shanks(g: vec3<f32>, c: f32) -> vec3<f32> {
    return 1.5 * (1.0 - g * g) / (2.0 + g * g) * (1.0 + c * c)
        / pow(1.0 + g * g - 2.0 * g * c, vec3<f32>(1.5)) / (4.0 * PI);
}

fn phase_of(field: u32, c: f32) -> vec3<f32> {
    if (rp.shading.cornette_shanks != 0u) {
        return cornette_shanks(rp.g[field].rgb, c);
    }
    return ams(field, 1.0, c);
}

// Rayleigh β and the haze's N/N_0 at height y.
fn air_at(y: f32) -> vec4<f32> {
    let r = rp.sky.beta * exp(-y * rp.sky.inv_scale_height);
    let n = select(0.0, exp(-rp.haze.inv_height * y), haze_on());
    return vec4<f32>(r, n);
}

// Sunlight reaching height y through the air and the haze.
fn sun_through_air(y: f32) -> vec3<f32> {
    var s = sunlight(y, rp.slices.to_sun.y);
    if (haze_on()) {
        s = s * exp(-rp.haze.ext * (exp(-rp.haze.inv_height * y) / rp.haze.inv_height / rp.slices.to_sun.y));
    }
    return s;
}

// Transmittance of the air and the haze from the eye at height y along p_y over k (< 0: ∞).
fn air_haze_transparency(y: f32, p_y: f32, k: f32) -> vec3<f32> {
    var t = air_transparency(y, p_y, k);
    if (haze_on()) {
        let depth = exp(-rp.haze.inv_height * y) * path_factor_for(rp.haze.inv_height, p_y, k) / rp.haze.inv_height;
        t = t * exp(-rp.haze.ext * depth);
    }
    return t;
}

fn shadow_coords(p: vec3<f32>) -> vec2<f32> {
    return vec2<f32>(
        (dot(rp.shadow.u, p) - rp.shadow.u_origin) / rp.shadow.texel.x - 0.5,
        (dot(rp.shadow.w, p) - rp.shadow.w_origin) / rp.shadow.texel.y - 0.5);
}

// Bilinear in the shadow surface; 1 outside its footprint.
fn shadow_at(p: vec3<f32>) -> vec3<f32> {
    let res = rp.sizes.z;
    let edge = f32(res - 1u);
    let uv = shadow_coords(p);
    if (uv.x < -0.5 || uv.x > edge + 0.5 || uv.y < -0.5 || uv.y > edge + 0.5) {
        return vec3<f32>(1.0);
    }
    let u = clamp(uv.x, 0.0, edge);
    let v = clamp(uv.y, 0.0, edge);
    let a0 = min(u32(floor(u)), res - 2u);
    let b0 = min(u32(floor(v)), res - 2u);
    let s = u - f32(a0);
    let t = v - f32(b0);
    let l00 = shadow[a0 + res * b0].rgb;
    let l10 = shadow[a0 + 1u + res * b0].rgb;
    let l01 = shadow[a0 + res * (b0 + 1u)].rgb;
    let l11 = shadow[a0 + 1u + res * (b0 + 1u)].rgb;
    return mix(mix(l00, l10, s), mix(l01, l11, s), t);
}

fn sunward_of_slices(p: vec3<f32>) -> bool {
    let c = dot(rp.slices.normal, p);
    if (dot(rp.slices.normal, rp.slices.to_sun) > 0.0) {
        return c >= rp.slices.plane_max;
    }
    return c <= rp.slices.plane_min;
}

@compute @workgroup_size(8, 8)
fn clear(@builtin(global_invocation_id) id: vec3<u32>) {
    let res = rp.sizes.z;
    if (id.x < res && id.y < res) {
        shadow[id.x + res * id.y] = vec4<f32>(1.0);
    }
    if (id.x < rp.sizes.x && id.y < rp.sizes.y) {
        let i = id.x + rp.sizes.x * id.y;
        eye_buffer[3u * i] = vec4<f32>(0.0);
        eye_buffer[3u * i + 1u] = vec4<f32>(1.0);
        eye_buffer[3u * i + 2u] = vec4<f32>(1.0);
        // The Mie scattering texture.
        let c = dot(camera_direction(id.x, id.y), rp.slices.to_sun);
        let haze = i32(rp.shading.haze_field) - 1;
        for (var f = 0u; f < 4u; f = f + 1u) {
            var b = vec3<f32>(0.0);
            if (f < rp.grid.fields && i32(f) != haze) {
                b = (phase_of(f, c) + rp.shading.k_multi) * ams_field_info[f].yzw;
            }
            pixel_tex[5u * i + f] = vec4<f32>(b, 0.0);
        }
        var hb = vec3<f32>(0.0);
        if (haze_on()) {
            hb = phase_of(u32(haze), c) * rp.haze.sca;
        }
        pixel_tex[5u * i + 4u] = vec4<f32>(hb, 3.0 / (16.0 * PI) * (1.0 + c * c));
    }
}

@compute @workgroup_size(8, 8)
fn shadow_slice(@builtin(global_invocation_id) id: vec3<u32>) {
    let res = rp.sizes.z;
    if (id.x >= res || id.y >= res) {
        return;
    }
    let q = rp.shadow.u * (rp.shadow.u_origin + (f32(id.x) + 0.5) * rp.shadow.texel.x)
        + rp.shadow.w * (rp.shadow.w_origin + (f32(id.y) + 0.5) * rp.shadow.texel.y);
    let p = q + (slice.plane - dot(rp.slices.normal, q)) / dot(rp.slices.normal, rp.slices.to_sun)
        * rp.slices.to_sun;
    let ext = extinction(densities(p));
    let i = id.x + res * id.y;
    shadow[i] = vec4<f32>(shadow[i].rgb * exp(-ext * rp.slices.sun_path), 1.0);
}

@compute @workgroup_size(8, 8)
fn eye_slice(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.sizes.x || id.y >= rp.sizes.y) {
        return;
    }
    let o = camera_origin(id.x, id.y);
    let d = camera_direction(id.x, id.y);
    let nd = dot(rp.slices.normal, d);
    if (abs(nd) < 1e-9) {
        return;
    }
    let t = (slice.plane - dot(rp.slices.normal, o)) / nd;
    let tg = ground_distance(o, d);
    if (t <= 0.0 || (tg >= 0.0 && t > tg)) {
        return;
    }
    let p = o + t * d;
    let rho = densities(p);
    let ext = extinction(rho);
    let air = air_at(p.y);
    let air_ext = air.rgb + air.w * rp.haze.ext;
    if (all(ext <= vec3<f32>(0.0)) && all(air_ext <= vec3<f32>(0.0))) {
        return;
    }
    let i = id.x + rp.sizes.x * id.y;
    let dt = rp.slices.spacing / abs(nd);
    let g_cl = shadow_at(p);
    let g_atm = sun_through_air(p.y);
    let tex_haze = pixel_tex[5u * i + 4u];
    var b = air.rgb * tex_haze.w + air.w * tex_haze.rgb;
    for (var f = 0u; f < rp.grid.fields; f = f + 1u) {
        b = b + rho[f] * pixel_tex[5u * i + f].rgb;
    }
    let contribution = rp.sky.irradiance * dt * b * g_atm * g_cl;   // Eq. 8 × I_sun
    let slab = exp(-(ext + air_ext) * dt);                           // Eq. 9
    var sum = eye_buffer[3u * i].rgb;
    let alpha_star = eye_buffer[3u * i + 1u].rgb;
    if (rp.slices.back_to_front != 0u) {
        sum = contribution + slab * sum;
    } else {
        sum = sum + alpha_star * contribution;
    }
    eye_buffer[3u * i] = vec4<f32>(sum, 0.0);
    eye_buffer[3u * i + 1u] = vec4<f32>(alpha_star * slab, 0.0);
    eye_buffer[3u * i + 2u] = vec4<f32>(eye_buffer[3u * i + 2u].rgb * exp(-ext * dt), 0.0);
}

// Where the ray from o along d lies over the shadow surface's footprint, within [t0, t1].
fn prism_span(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> vec2<f32> {
    var lo = t0;
    var hi = t1;
    let res = f32(rp.sizes.z);
    for (var k = 0; k < 2; k = k + 1) {
        var axis = rp.shadow.u;
        var origin = rp.shadow.u_origin;
        var texel = rp.shadow.texel.x;
        if (k == 1) {
            axis = rp.shadow.w;
            origin = rp.shadow.w_origin;
            texel = rp.shadow.texel.y;
        }
        let a = origin;
        let b = origin + texel * res;
        let p = dot(axis, o);
        let v = dot(axis, d);
        if (abs(v) < 1e-15) {
            if (p < a || p > b) {
                return vec2<f32>(t0, t0);
            }
            continue;
        }
        let x = (a - p) / v;
        let y = (b - p) / v;
        lo = max(lo, min(x, y));
        hi = min(hi, max(x, y));
    }
    return vec2<f32>(lo, max(hi, lo));
}

// In-scattering by the air along the ray from o along d over [t0, t1] (t1 < 0: ∞) per unit
// irradiance (cpu::render's air_segment).
fn air_segment(o: vec3<f32>, d: vec3<f32>, t0: f32, t1_in: f32, tex: vec4<f32>) -> vec3<f32> {
    let air_on = any(rp.sky.beta > vec3<f32>(0.0)) || haze_on();
    let infinite = t1_in < 0.0;
    if (!air_on || (!infinite && t1_in <= t0)) {
        return vec3<f32>(0.0);
    }
    let y = o.y;
    let cos_sun = dot(d, rp.slices.to_sun);
    // The segment lies on one side of the slices: ask at a point well inside it.
    let probe_t = select(0.5 * (t0 + t1_in), t0 + max(t0, 1.0), infinite);
    let probe = o + probe_t * d;
    let sunward = sunward_of_slices(probe);
    var out = vec3<f32>(0.0);
    var lo = t0;
    var hi = t1_in;
    var shadow_only = false;
    if (haze_on()) {
        hi = select(t1_in, t0 + SHADOWED_AIR_MAX_M, infinite);
    } else {
        let k0 = t0;
        out = inscatter(y, d.y, t1_in, cos_sun, rp.slices.to_sun.y) - inscatter(y, d.y, k0, cos_sun, rp.slices.to_sun.y);
        if (sunward) {
            return out;
        }
        var cap = t0 + SHADOWED_AIR_MAX_M;
        if (!infinite) {
            cap = min(t1_in, cap);
        }
        let s = prism_span(o, d, t0, cap);
        lo = s.x;
        hi = s.y;
        shadow_only = true;
    }
    if (hi <= lo) {
        return out;
    }
    let uniform_step = (hi - lo) / f32(SHADOWED_AIR_POINTS);
    let prism = prism_span(o, d, lo, hi);
    let prism_step = max(min(rp.shadow.texel.x, rp.shadow.texel.y), (prism.y - prism.x) / 256.0);
    var t = lo;
    for (var n = 0u; n < 100000u; n = n + 1u) {
        if ((shadow_only && n >= SHADOWED_AIR_POINTS) || (!shadow_only && t >= hi)) {
            break;
        }
        if (shadow_only) {
            t = lo + f32(n) * uniform_step; // counted, not accumulated: exactly the midpoints
        }
        let ahead = air_at(y + (t + 0.5 * uniform_step) * d.y);
        var dt = uniform_step;
        if (!shadow_only) {
            let e = ahead.rgb + ahead.w * rp.haze.ext;
            let ext = max(e.r, max(e.g, e.b));
            dt = min(min(HAZY_AIR_STEP_TAU / max(ext, 1e-30), HAZY_AIR_MAX_STEP_M), hi - t);
            // Over the shadow's prism the steps resolve its edges (cpu::render).
            if (!sunward) {
                if (t < prism.x) {
                    dt = min(dt, prism.x - t);
                } else if (t < prism.y) {
                    dt = min(dt, prism_step);
                }
            }
        }
        let tm = t + 0.5 * dt;
        t = t + dt;
        let p = o + tm * d;
        var g_cl = vec3<f32>(1.0);
        if (!sunward) {
            g_cl = shadow_at(p);
        }
        let sun = sun_through_air(p.y);
        let tr = air_haze_transparency(y, d.y, tm);
        let a = air_at(p.y);
        let b = a.rgb * tex.w + a.w * tex.rgb;
        var lit = g_cl;
        if (shadow_only) {
            lit = -(1.0 - g_cl);
        }
        out = out + b * sun * tr * lit * dt;
        if (!shadow_only && all(tr < vec3<f32>(1e-7))) {
            break;
        }
    }
    return out;
}

@compute @workgroup_size(8, 8)
fn composite(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.sizes.x || id.y >= rp.sizes.y) {
        return;
    }
    let i = id.x + rp.sizes.x * id.y;
    let o = camera_origin(id.x, id.y);
    let d = camera_direction(id.x, id.y);
    let sum = eye_buffer[3u * i].rgb;
    let t_cl = eye_buffer[3u * i + 2u].rgb;
    let tex = pixel_tex[5u * i + 4u];
    let t_end = ground_distance(o, d); // < 0: ∞
    let n_dot_o = dot(rp.slices.normal, o);
    let nd = dot(rp.slices.normal, d);
    let big = 3.0e38;
    let end = select(t_end, big, t_end < 0.0);
    var ta = 0.0;
    var tb = 0.0;
    if (abs(nd) < 1e-12) {
        if (n_dot_o >= rp.slices.plane_min && n_dot_o <= rp.slices.plane_max) {
            tb = end;
        }
    } else {
        let x = (rp.slices.plane_min - n_dot_o) / nd;
        let y = (rp.slices.plane_max - n_dot_o) / nd;
        ta = clamp(min(x, y), 0.0, end);
        tb = clamp(max(x, y), 0.0, end);
    }
    let front = air_segment(o, d, 0.0, ta, tex);
    // tb = end = ∞ leaves nothing behind the slices.
    var back = vec3<f32>(0.0);
    if (tb < end) {
        back = air_segment(o, d, tb, t_end, tex);
    }
    let t_front = air_haze_transparency(o.y, d.y, ta);
    let t_all = air_haze_transparency(o.y, d.y, t_end);
    var beyond = vec3<f32>(0.0);
    if (t_end >= 0.0) {
        let g_cl = shadow_at(o + t_end * d);
        beyond = rp.grid.ground_albedo / PI * rp.slices.to_sun.y * sun_through_air(0.0) * g_cl * t_all;
    } else if (dot(d, rp.slices.to_sun) >= rp.sky.cos_disk) {
        beyond = t_all / rp.sky.disk_sr;
    }
    let i_s = rp.sky.irradiance;
    let v = i_s * front + t_front * sum + t_cl * i_s * (back + beyond);
    image[i] = vec4<f32>(v, t_cl.g);
}
