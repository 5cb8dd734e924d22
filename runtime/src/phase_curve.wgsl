// photometeor export --format bevy: sampling a chromatic phase curve.
//
// The texture is N x 1 Rgba32Float; column i holds Ams_n at cos θ = -1 + 2i/(N - 1) (θ = 180°
// first, θ = 0° last) per channel R, G, B in 1/sr, A = 1; θ is the scattering angle, cos θ =
// dot(direction the light travelled, direction it leaves in). The curve is read linearly in
// cos θ between columns, which is how its values were resampled (each the average of the
// bake's row over its cell, so the curve integrates to 1 over the sphere). textureLoad and
// an explicit lerp need no filterable-float feature (a linear sampler on Rgba32Float needs
// FLOAT32_FILTERABLE) and hit the columns exactly.
fn phase_curve(curve: texture_2d<f32>, cos_theta: f32) -> vec3<f32> {
    let n = textureDimensions(curve).x;
    let u = clamp((cos_theta + 1.0) * 0.5, 0.0, 1.0) * f32(n - 1u);
    let i = min(u32(floor(u)), n - 2u);
    let t = u - f32(i);
    let a = textureLoad(curve, vec2<u32>(i, 0u), 0).rgb;
    let b = textureLoad(curve, vec2<u32>(i + 1u, 0u), 0).rgb;
    return mix(a, b, t);
}
