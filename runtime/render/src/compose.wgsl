// The pixel around a volume's light, shared by riley's composite and max's gather (included
// after slicing.wgsl; the including shader's `rp` also has eye (xyz), sun (xyz towards the sun,
// w = cos of the disk radius), irradiance (rgb; w = the disk's solid angle) and grid_min.w (the
// ground's albedo)). The CPU reference is render::shading::compose.

// The air in front of and behind the volume (Eqs. 11–15), the sun disk and the Lambertian
// ground, lit by `lit` (the sunlight the volume leaves at the ground point), around the volume's
// radiance `l_vol` and transparency `t_vol` along d.
fn compose(d: vec3<f32>, l_vol: vec3<f32>, t_vol: vec3<f32>, lit: vec3<f32>) -> vec3<f32> {
    let y = rp.eye.y;
    let l_y = rp.sun.y;
    let span = box_span(rp.eye.xyz, d);
    var k_mid = select(0.0, 0.5 * (span.x + span.y), span.y >= 0.0);
    let k_end = ground_distance(d);
    if (k_end >= 0.0) {
        k_mid = min(k_mid, k_end);
    }
    let cos_sun = dot(d, rp.sun.xyz);
    let front = inscatter(y, d.y, k_mid, cos_sun, l_y);
    let all_sky = inscatter(y, d.y, k_end, cos_sun, l_y);
    let t_mid = air_transparency(y, d.y, k_mid);
    let i_s = rp.irradiance.rgb;
    var v = i_s * (front + t_vol * (all_sky - front)) + t_mid * l_vol;
    if (k_end < 0.0 && cos_sun >= rp.sun.w) {
        v = v + t_vol * i_s * air_transparency(y, d.y, -1.0) / rp.irradiance.w;
    }
    if (rp.grid_min.w > 0.0 && k_end > 0.0) {
        v = v + t_vol * i_s * (rp.grid_min.w / 3.14159265358979 * l_y) * sunlight(0.0, l_y) * lit
            * air_transparency(y, d.y, k_end);
    }
    return v;
}
