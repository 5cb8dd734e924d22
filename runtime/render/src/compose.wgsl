// The pixel around a volume's light, shared by riley's composite and max's gather (included
// after slicing.wgsl; the including shader's `rp` also has eye (xyz), sun (xyz towards the sun,
// w = cos of the disk radius), irradiance (rgb; w = the disk's solid angle) and grid_min.w (the
// ground's albedo)). The CPU reference is render::shading::compose.

// The air's light beyond single scattering (render::skylight::SkyLight): per (level, direction,
// mode) an rgb radiance per unit irradiance; levels uniform in u = e^{−y/H}, directions
// μ = ±((j + ½)/SKY_MU)² of the light's travel, down then up.
@group(1) @binding(15) var<storage, read> sky_light: array<vec4<f32>>;
const SKY_LEVELS: u32 = 64u;
const SKY_MU: u32 = 64u;

// The multiply-scattered light reaching height y along the view ray d from its whole length
// (render::skylight::SkyLight::radiance).
fn sky_light_radiance(y: f32, d: vec3<f32>) -> vec3<f32> {
    let u = exp(-rp.sky_beta.w * max(y, 0.0)) * f32(SKY_LEVELS);
    let k0 = min(u32(floor(u)), SKY_LEVELS - 1u);
    let fk = clamp(u - f32(k0), 0.0, 1.0);
    let mu = -d.y;
    let a = clamp(sqrt(abs(mu)) * f32(SKY_MU) - 0.5, 0.0, f32(SKY_MU - 1u));
    let j0 = min(u32(floor(a)), SKY_MU - 2u);
    let fj = a - f32(j0);
    let base = select(SKY_MU, 0u, mu < 0.0);
    let dh = vec2<f32>(d.x, d.z);
    let sh = vec2<f32>(rp.sun.x, rp.sun.z);
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

// The multiply-scattered light the first k metres of the view ray gather (k < 0: all of it).
fn sky_light_inscatter(y: f32, d: vec3<f32>, k: f32) -> vec3<f32> {
    let near = sky_light_radiance(y, d);
    if (k < 0.0) {
        return near;
    }
    if (k == 0.0) {
        return vec3<f32>(0.0);
    }
    return near - air_transparency(y, d.y, k) * sky_light_radiance(y + k * d.y, d);
}

// The air in front of and behind the volume (Eqs. 11–15 and the light they leave out), the sun
// disk and the Lambertian ground, lit by `lit` (the sunlight the volume leaves at the ground
// point), around the volume's radiance `l_vol` along d; the disk seen through the volume's
// transparency `t_vol`, the smooth background through `t_smooth` (render::shading::compose).
fn compose(d: vec3<f32>, l_vol: vec3<f32>, t_vol: vec3<f32>, t_smooth: vec3<f32>,
           lit: vec3<f32>) -> vec3<f32> {
    let y = rp.eye.y;
    let l_y = rp.sun.y;
    let span = box_span(rp.eye.xyz, d);
    var k_mid = select(0.0, 0.5 * (span.x + span.y), span.y >= 0.0);
    let k_end = ground_distance(d);
    if (k_end >= 0.0) {
        k_mid = min(k_mid, k_end);
    }
    let cos_sun = dot(d, rp.sun.xyz);
    var front = inscatter(y, d.y, k_mid, cos_sun, l_y);
    var all_sky = inscatter(y, d.y, k_end, cos_sun, l_y);
    if (k_end != 0.0) {
        front = front + sky_light_inscatter(y, d, k_mid);
        all_sky = all_sky + sky_light_radiance(y, d);
    }
    let t_mid = air_transparency(y, d.y, k_mid);
    let i_s = rp.irradiance.rgb;
    var v = i_s * (front + t_smooth * (all_sky - front)) + t_mid * l_vol;
    if (k_end < 0.0 && cos_sun >= rp.sun.w) {
        v = v + t_vol * i_s * air_transparency(y, d.y, -1.0) / rp.irradiance.w;
    }
    if (rp.grid_min.w > 0.0 && k_end > 0.0) {
        v = v + t_smooth * i_s * (rp.grid_min.w / 3.14159265358979 * l_y) * sunlight(0.0, l_y) * lit
            * air_transparency(y, d.y, k_end);
    }
    return v;
}
