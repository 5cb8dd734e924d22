// Pieces the grid models' shaders use (render::riley, render::miyazaki, the gathers of
// render::max and render::coupled, and the truth), included after tables.wgsl and before each.
// The including shader declares `rp` with at least: view (a View, view.wgsl), sizes (x =
// width, y = height), grid (a Grid), sigma_ext (array<vec4<f32>, 4>, m² per channel per field)
// and sky (a Sky), and the density buffer `density` (array<vec4<f32>>, one channel per field).

fn inside_box(p: vec3<f32>) -> bool {
    return all(p >= rp.grid.min) && all(p <= rp.grid.max);
}

fn voxel(x: u32, y: u32, z: u32) -> vec4<f32> {
    return density[x + rp.grid.dims.x * (y + rp.grid.dims.y * z)];
}

// The trilinear taps at p inside the box, voxel centres, clamped to the edge voxels: the lower
// corner voxel `lo`, the step `s` to the upper one per axis (0 on an axis of one voxel) and the
// upper corner's weight `t` per axis.
struct Taps {
    lo: vec3<u32>,
    s: vec3<u32>,
    t: vec3<f32>,
}

fn taps(p: vec3<f32>) -> Taps {
    return taps_in(p, rp.grid.min, rp.grid.max, rp.grid.dims);
}

// `taps` on a grid of `n` voxels over the box from `lo` to `hi`.
fn taps_in(p: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>, n: vec3<u32>) -> Taps {
    let dims = vec3<f32>(n);
    let u = clamp((p - lo) / (hi - lo) * dims - 0.5, vec3<f32>(0.0), dims - 1.0);
    let top = max(vec3<i32>(n) - 2, vec3<i32>(0));
    let first = vec3<u32>(min(vec3<i32>(floor(u)), top));
    let t = select(vec3<f32>(0.0), u - vec3<f32>(first), n > vec3<u32>(1u));
    let s = vec3<u32>(n > vec3<u32>(1u));
    return Taps(first, s, t);
}

// Trilinear densities at p, voxel centres, clamped to the edge voxels; zero outside the box.
fn densities(p: vec3<f32>) -> vec4<f32> {
    if (!inside_box(p)) {
        return vec4<f32>(0.0);
    }
    let tap = taps(p);
    let lo = tap.lo;
    let s = tap.s;
    let t = tap.t;
    let c00 = mix(voxel(lo.x, lo.y, lo.z), voxel(lo.x + s.x, lo.y, lo.z), t.x);
    let c10 = mix(voxel(lo.x, lo.y + s.y, lo.z), voxel(lo.x + s.x, lo.y + s.y, lo.z), t.x);
    let c01 = mix(voxel(lo.x, lo.y, lo.z + s.z), voxel(lo.x + s.x, lo.y, lo.z + s.z), t.x);
    let c11 = mix(voxel(lo.x, lo.y + s.y, lo.z + s.z), voxel(lo.x + s.x, lo.y + s.y, lo.z + s.z), t.x);
    return mix(mix(c00, c10, t.y), mix(c01, c11, t.y), t.z);
}

fn extinction(rho: vec4<f32>) -> vec3<f32> {
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < rp.grid.fields; i = i + 1u) {
        e = e + rho[i] * rp.sigma_ext[i].rgb;
    }
    return e;
}

// The distance K along d from the ray's origin o to the ground; K < 0 stands for ∞ (the ray
// leaves the atmosphere without meeting the ground); 0 from an origin at or below the ground.
fn ground_distance(o: vec3<f32>, d: vec3<f32>) -> f32 {
    if (d.y < 0.0) {
        return select(0.0, o.y / -d.y, o.y > 0.0);
    }
    return -1.0;
}

// The unit ray from the eye through pixel (i, j) of a perspective camera (camera::pixel_ray).
fn pixel_ray(i: u32, j: u32) -> vec3<f32> {
    let sx = (2.0 * (f32(i) + 0.5) / f32(rp.sizes.x) - 1.0) * rp.view.tan_half_fov * rp.view.aspect;
    let sy = (1.0 - 2.0 * (f32(j) + 0.5) / f32(rp.sizes.y)) * rp.view.tan_half_fov;
    return normalize(rp.view.forward + sx * rp.view.right + sy * rp.view.up);
}

// Pixel (i, j)'s camera ray (Camera::pixel): from the eye through the pixel, or for an
// orthographic camera (view.ortho_half_height > 0, m) along `forward` from the pixel's
// point of the image plane. Without branches: a branch on the camera in the truth's
// begin_sample made lavapipe's paths 5–10× slower.
fn camera_origin(i: u32, j: u32) -> vec3<f32> {
    let sx = (2.0 * (f32(i) + 0.5) / f32(rp.sizes.x) - 1.0) * rp.view.aspect;
    let sy = 1.0 - 2.0 * (f32(j) + 0.5) / f32(rp.sizes.y);
    return rp.view.eye + rp.view.ortho_half_height * (sx * rp.view.right + sy * rp.view.up);
}

fn camera_direction(i: u32, j: u32) -> vec3<f32> {
    return select(pixel_ray(i, j), rp.view.forward, rp.view.ortho_half_height > 0.0);
}


// e^x − 1 without cancellation for small x.
fn expm1(x: f32) -> f32 {
    if (abs(x) < 1e-2) {
        return x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x / 24.0)));
    }
    return exp(x) - 1.0;
}

// Sunlight left at height y with the sun at vertical component l_y (Eq. 12).
fn sunlight(y: f32, l_y: f32) -> vec3<f32> {
    let g = rp.sky.inv_scale_height;
    return exp(-rp.sky.beta / (g * l_y) * exp(-g * y));
}

// (1 − e^{−γ p K})/p for the air's γ; K < 0 means ∞.
fn path_factor(p_y: f32, k: f32) -> f32 {
    return path_factor_for(rp.sky.inv_scale_height, p_y, k);
}

// (1 − e^{−g p K})/p for an exponential of 1/scale height g; K < 0 means ∞.
fn path_factor_for(g: f32, p_y: f32, k: f32) -> f32 {
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
    let g = rp.sky.inv_scale_height;
    let beta_eye = rp.sky.beta * exp(-g * y);
    return exp(-beta_eye / g * path_factor(p_y, k));
}

// Sky light from the first K metres of the ray (render::sky::Atmosphere::inscatter).
fn inscatter(y: f32, p_y: f32, k: f32, cos_sun: f32, l_y: f32) -> vec3<f32> {
    if (k == 0.0) {
        return vec3<f32>(0.0);
    }
    let g = rp.sky.inv_scale_height;
    let phase = 3.0 / (16.0 * 3.14159265358979) * (1.0 + cos_sun * cos_sun);
    let beta_eye = rp.sky.beta * exp(-g * y);
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

// Where the ray enters and leaves the box (t ≥ 0), or (−1, −1).
fn box_span(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    var t0 = 0.0;
    var t1 = 3.0e38;
    for (var a = 0; a < 3; a = a + 1) {
        if (d[a] == 0.0) {
            if (o[a] < rp.grid.min[a] || o[a] > rp.grid.max[a]) {
                return vec2<f32>(-1.0);
            }
            continue;
        }
        let inv = 1.0 / d[a];
        let lo = (rp.grid.min[a] - o[a]) * inv;
        let hi = (rp.grid.max[a] - o[a]) * inv;
        t0 = max(t0, min(lo, hi));
        t1 = min(t1, max(lo, hi));
    }
    return select(vec2<f32>(-1.0), vec2<f32>(t0, t1), t0 < t1);
}

