// The pixel around a volume's light, shared by riley's composite and the gathers of max and
// coupled (included after slicing.wgsl; the including shader's `rp` also has sky (a Sky,
// view.wgsl) and grid.ground_albedo). Each function takes the view ray's origin: the eye, or an
// orthographic pixel's point of the image plane. The CPU reference is render::shading::compose.

// The air's light beyond single scattering (render::skylight::SkyLight): per (level, direction,
// mode) an rgb radiance per unit irradiance; levels uniform in u = e^{−y/H}, directions
// μ = ±((j + ½)/SKY_MU)² of the light's travel, down then up.
@group(1) @binding(15) var<storage, read> sky_light: array<vec4<f32>>;
const SKY_LEVELS: u32 = 64u;
const SKY_MU: u32 = 64u;

// The multiply-scattered light reaching height y along the view ray d from its whole length
// (render::skylight::SkyLight::radiance).
fn sky_light_radiance(y: f32, d: vec3<f32>) -> vec3<f32> {
    let u = exp(-rp.sky.inv_scale_height * max(y, 0.0)) * f32(SKY_LEVELS);
    let k0 = min(u32(floor(u)), SKY_LEVELS - 1u);
    let fk = clamp(u - f32(k0), 0.0, 1.0);
    let mu = -d.y;
    let a = clamp(sqrt(abs(mu)) * f32(SKY_MU) - 0.5, 0.0, f32(SKY_MU - 1u));
    let j0 = min(u32(floor(a)), SKY_MU - 2u);
    let fj = a - f32(j0);
    let base = select(SKY_MU, 0u, mu < 0.0);
    let dh = vec2<f32>(d.x, d.z);
    let sh = vec2<f32>(rp.sky.sun.x, rp.sky.sun.z);
    let norm = length(dh) * length(sh);
    let cos_phi = select(1.0, dot(dh, sh) / norm, norm > 1e-6);
    let cm = vec3<f32>(1.0, cos_phi, 2.0 * cos_phi * cos_phi - 1.0);
    var out = vec3<f32>(0.0);
    for (var dk = 0u; dk < 2u; dk = dk + 1u) {
        for (var dj = 0u; dj < 2u; dj = dj + 1u) {
            let w = select(1.0 - fk, fk, dk == 1u) * select(1.0 - fj, fj, dj == 1u);
            let cell = ((k0 + dk) * 2u * SKY_MU + base + j0 + dj) * 3u;
            out = out + w * (cm.x * sky_light[cell].rgb + cm.y * sky_light[cell + 1u].rgb
                + cm.z * sky_light[cell + 2u].rgb);
        }
    }
    return out;
}

// Where the grid models' shadow map starts in sky_light: after the table's (SKY_LEVELS + 1)
// levels × 2 SKY_MU directions × 3 modes.
const SHADOW_MAP: u32 = (SKY_LEVELS + 1u) * 2u * SKY_MU * 3u;

// The sunlight the volume leaves at p (at or below the grid's bottom) from the shadow map
// after the sky light's table (render::lattice::ShadowMap::at); 1 without a map.
fn shadow_map_at(p: vec3<f32>) -> vec3<f32> {
    let h0 = sky_light[SHADOW_MAP];
    let h1 = sky_light[SHADOW_MAP + 1u];
    let nx = u32(h1.x);
    let nz = u32(h1.y);
    if (nx < 2u || nz < 2u) {
        return vec3<f32>(1.0);
    }
    let q = p + ((h1.z - p.y) / rp.sky.sun.y) * rp.sky.sun;
    let u = (q.x - h0.x) / h0.z - 0.5;
    let w = (q.z - h0.y) / h0.w - 0.5;
    if (u < -0.5 || w < -0.5 || u > f32(nx) - 0.5 || w > f32(nz) - 0.5) {
        return vec3<f32>(1.0);
    }
    let i = min(u32(max(floor(u), 0.0)), nx - 2u);
    let j = min(u32(max(floor(w), 0.0)), nz - 2u);
    let s = clamp(u - f32(i), 0.0, 1.0);
    let t = clamp(w - f32(j), 0.0, 1.0);
    let base = SHADOW_MAP + 2u;
    let v00 = sky_light[base + i + nx * j].rgb;
    let v10 = sky_light[base + i + 1u + nx * j].rgb;
    let v01 = sky_light[base + i + nx * (j + 1u)].rgb;
    let v11 = sky_light[base + i + 1u + nx * (j + 1u)].rgb;
    return mix(mix(v00, v10, s), mix(v01, v11, s), t);
}

// The multiply-scattered light of the view ray's first k metres, given `whole`, the whole
// ray's (sky_light_radiance(y, d)) (render::skylight::SkyLight::inscatter).
fn sky_light_first(y: f32, d: vec3<f32>, k: f32, whole: vec3<f32>) -> vec3<f32> {
    if (k < 0.0) {
        return whole;
    }
    if (k == 0.0) {
        return vec3<f32>(0.0);
    }
    return whole - air_transparency(y, d.y, k) * sky_light_radiance(y + k * d.y, d);
}

// Samples of the volume's shadow on the air along a ray (render::shading::AIR_SHADOW_STEPS).
const AIR_SHADOW_STEPS: u32 = 32u;

struct AirShadow {
    front: vec3<f32>,
    all: vec3<f32>,
}

// The air's single scattering the volume's shadow takes from the view ray from `origin` along
// d in its first k_mid metres and in all of it up to k_end (< 0: ∞), over the part of the ray
// below the grid and within reach of its shadow, lit by the including shader's sun_left(p) (the fraction of
// sunlight the volume leaves there) (render::shading::air_shadow).
fn air_shadow(origin: vec3<f32>, d: vec3<f32>, k_mid: f32, k_end: f32) -> AirShadow {
    var out = AirShadow(vec3<f32>(0.0), vec3<f32>(0.0));
    let bottom = rp.grid.min.y;
    let sun = rp.sky.sun;
    if (all(rp.sky.beta <= vec3<f32>(0.0)) || bottom <= 0.0 || sun.y <= 0.0) {
        return out;
    }
    let eye = origin;
    var s0 = 0.0;
    var s1 = select(k_end, 1e30, k_end < 0.0);
    if (eye.y > bottom) {
        if (d.y >= 0.0) {
            return out;
        }
        s0 = (eye.y - bottom) / -d.y;
    } else if (d.y > 0.0) {
        s1 = min(s1, (bottom - eye.y) / d.y);
    }
    let c = 0.5 * (rp.grid.min + rp.grid.max);
    let half = 0.5 * (rp.grid.max - rp.grid.min);
    let reach = length(half.xz) + bottom * sqrt(max(1.0 - sun.y * sun.y, 0.0)) / sun.y;
    let o = vec2<f32>(eye.x - c.x, eye.z - c.z);
    let dh = vec2<f32>(d.x, d.z);
    let a = dot(dh, dh);
    let b = dot(o, dh);
    let q = dot(o, o) - reach * reach;
    if (a > 1e-12) {
        let disc = b * b - a * q;
        if (disc <= 0.0) {
            return out;
        }
        let r = sqrt(disc);
        s0 = max(s0, (-b - r) / a);
        s1 = min(s1, (-b + r) / a);
    } else if (q > 0.0) {
        return out;
    }
    if (s1 >= 1e29 || s1 <= s0) {
        return out;
    }
    let cos_sun = dot(d, sun);
    let phase = 3.0 / (16.0 * 3.14159265358979) * (1.0 + cos_sun * cos_sun);
    let g = rp.sky.inv_scale_height;
    let ds = (s1 - s0) / f32(AIR_SHADOW_STEPS);
    for (var i = 0u; i < AIR_SHADOW_STEPS; i = i + 1u) {
        let s = s0 + (f32(i) + 0.5) * ds;
        let p = eye + s * d;
        let left = sun_left(p);
        if (all(left >= vec3<f32>(1.0))) {
            continue;
        }
        let loss = air_transparency(eye.y, d.y, s) * rp.sky.beta * exp(-g * p.y)
            * sunlight(p.y, sun.y) * phase * (vec3<f32>(1.0) - left) * ds;
        out.all = out.all + loss;
        if (s < k_mid) {
            out.front = out.front + loss;
        }
    }
    return out;
}

// The air in front of and behind the volume (Eqs. 11–15 and the light they leave out), the sun
// disk and the Lambertian ground, lit by `lit` (the sunlight the volume leaves at the ground
// point), around the volume's radiance `l_vol` along the ray from o along d; the disk seen
// through the volume's transparency `t_vol`, the smooth background through `t_smooth`
// (render::shading::compose).
fn compose(o: vec3<f32>, d: vec3<f32>, l_vol: vec3<f32>, t_vol: vec3<f32>, t_smooth: vec3<f32>,
           lit: vec3<f32>) -> vec3<f32> {
    let y = o.y;
    let l_y = rp.sky.sun.y;
    let span = box_span(o, d);
    var k_mid = select(0.0, 0.5 * (span.x + span.y), span.y >= 0.0);
    let k_end = ground_distance(o, d);
    if (k_end >= 0.0) {
        k_mid = min(k_mid, k_end);
    }
    let cos_sun = dot(d, rp.sky.sun);
    var front = inscatter(y, d.y, k_mid, cos_sun, l_y);
    var all_sky = inscatter(y, d.y, k_end, cos_sun, l_y);
    if (k_end != 0.0) {
        let shadow = air_shadow(o, d, k_mid, k_end);
        let whole = sky_light_radiance(y, d);
        front = front + sky_light_first(y, d, k_mid, whole) - shadow.front;
        all_sky = all_sky + whole - shadow.all;
    }
    let t_mid = air_transparency(y, d.y, k_mid);
    let i_s = rp.sky.irradiance;
    var v = i_s * (front + t_smooth * (all_sky - front)) + t_mid * l_vol;
    if (k_end < 0.0 && cos_sun >= rp.sky.cos_disk) {
        v = v + t_vol * i_s * air_transparency(y, d.y, -1.0) / rp.sky.disk_sr;
    }
    if (rp.grid.ground_albedo > 0.0 && k_end > 0.0) {
        v = v + t_smooth * i_s * (rp.grid.ground_albedo / 3.14159265358979 * l_y) * sunlight(0.0, l_y) * lit
            * air_transparency(y, d.y, k_end);
    }
    return v;
}
