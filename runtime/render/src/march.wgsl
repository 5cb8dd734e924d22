// The grid gathers' shared steps (`max` and `coupled`), after slicing.wgsl and compose.wgsl;
// their params give the march's step in eye.w and the unit vector towards the sun in sun.xyz.

fn scattering_of(rho: vec4<f32>) -> vec3<f32> {
    var s = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid_dims.w; i = i + 1u) {
        s = s + rho[i] * ams_field_info[i].yzw;
    }
    return s;
}

// The sunlight the volume leaves at p (outside the box: the ground) along the sun, by a march
// of half-voxel steps.
fn transmittance_to_sun(p: vec3<f32>) -> vec3<f32> {
    let span = box_span(p, rp.sun.xyz);
    if (span.y < 0.0) {
        return vec3<f32>(1.0);
    }
    let n = max(u32(ceil((span.y - span.x) / rp.eye.w)), 1u);
    let dt = (span.y - span.x) / f32(n);
    var tau = vec3<f32>(0.0);
    for (var k = 0u; k < n; k = k + 1u) {
        tau = tau + extinction(densities(p + (span.x + (f32(k) + 0.5) * dt) * rp.sun.xyz)) * dt;
    }
    return exp(-tau);
}
