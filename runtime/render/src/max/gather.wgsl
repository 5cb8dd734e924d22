// Max et al. 2004's final gather (§4) on the GPU: one invocation per pixel does what
// render::max::cpu::gather does per ray, in f32, from the per-voxel lighting the CPU
// computed (T_sun, the diffusion solution I_0 and the reduced skylight: steps 1–4 of the
// module docs), then composes the pixel with the air, the sun disk and the ground. Included
// after tables.wgsl (bind group 0: Ams_1 by `ams_mix`, the Poisson mixtures by `poisson`),
// slicing.wgsl (grid sampling, camera rays, the sky), riley's compose.wgsl and march.wgsl.

struct MaxParams {
    view: View,
    grid: Grid,
    sizes: vec2<u32>,        // width, height
    march_step: f32,         // the march's step (m)
    pad_step: f32,
    // The edge treatment (MaxSettings::edge_share):
    voxel_length: f32,       // (h_x h_y h_z)^{1/3} (m)
    edge_threshold: f32,     // the threshold T (a voxel's optical depth)
    pad0: f32,
    pad1: f32,
    sigma_ext: array<vec4<f32>, 4>,  // per field, m² per channel
    sky: Sky,
}

@group(1) @binding(0) var<uniform> rp: MaxParams;
@group(1) @binding(1) var<storage, read> density: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> lighting: array<LightVoxel>;
@group(1) @binding(3) var<storage, read_write> image: array<vec4<f32>>;  // rgb, T_vol (green)
// The largest optical depth an edge segment reached, as the bits of a non-negative f32 (whose
// order is the u32 order).
@group(1) @binding(4) var<storage, read_write> largest_edge: atomic<u32>;

// A voxel's lighting (render::max's Lighting, in f32), read by march.wgsl's lighting_at.
struct LightVoxel {
    sun: vec3<f32>,          // the reduced sunlight T_sun per channel
    in_solve: f32,           // 1 if in the diffusion solve, else 0
    i0: vec3<f32>,           // the diffusion's I_0 per channel
    pad0: f32,
    sky: vec3<f32>,          // the skylight's mean per channel
    pad1: f32,
}

// sum + w · v, field by field.
fn weighted_add(sum: LightVoxel, w: f32, v: LightVoxel) -> LightVoxel {
    return LightVoxel(sum.sun + w * v.sun, sum.in_solve + w * v.in_solve, sum.i0 + w * v.i0, 0.0,
        sum.sky + w * v.sky, 0.0);
}

// v / t, field by field.
fn divided(v: LightVoxel, t: f32) -> LightVoxel {
    return LightVoxel(v.sun / t, v.in_solve / t, v.i0 / t, 0.0, v.sky / t, 0.0);
}

// Whether the voxel is in the diffusion solve.
fn in_solve(v: LightVoxel) -> bool {
    return v.in_solve != 0.0;
}

// M(D, θ) of the mixture, weighted by ρ σ_sca like Eq. 6 (runtime::sample::poisson_mix).
fn poisson_mix(rho: vec4<f32>, depth: vec3<f32>, cos_theta: f32) -> vec3<f32> {
    var num = vec3<f32>(0.0);
    var den = vec3<f32>(0.0);
    for (var i = 0u; i < min(rp.grid.fields, 4u); i = i + 1u) {
        if (rho[i] > 0.0) {
            let w = rho[i] * ams_field_info[i].yzw;
            num = num + w * poisson(i, depth, cos_theta);
            den = den + w;
        }
    }
    return select(vec3<f32>(0.0), num / den, den > vec3<f32>(0.0));
}

// e^{−D}(e^{Dα} − 1): the light a segment of optical depth D scatters at albedo α.
fn scattered(d: f32, albedo: f32) -> f32 {
    if (d <= 0.0) {
        return 0.0;
    }
    return exp(-d) * expm1(d * albedo);
}

// The share of a voxel of optical depth τ the edge treatment takes (MaxSettings::edge_share).
fn edge_share(tau_voxel: f32) -> f32 {
    return clamp(1.5 - tau_voxel / rp.edge_threshold, 0.0, 1.0);
}

@compute @workgroup_size(8, 8)
fn gather(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.sizes.x || id.y >= rp.sizes.y) {
        return;
    }
    let eye = camera_origin(id.x, id.y);
    let d = camera_direction(id.x, id.y);
    let l_y = rp.sky.sun.y;
    let cos_theta = dot(rp.sky.sun, d);
    var l_vol = vec3<f32>(0.0);
    var tr = vec3<f32>(1.0);
    var largest = 0.0;
    let span = box_span(eye, d);
    if (span.y >= 0.0) {
        let n = max(u32(ceil((span.y - span.x) / rp.march_step)), 1u);
        let dt = (span.y - span.x) / f32(n);
        var edge = vec3<f32>(0.0);
        for (var k = 0u; k < n; k = k + 1u) {
            let p = eye + (span.x + (f32(k) + 0.5) * dt) * d;
            let rho = densities(p);
            let ext = extinction(rho);
            if (all(ext <= vec3<f32>(0.0))) {
                continue;
            }
            let sca = scattering_of(rho);
            let w_edge = edge_share(ext.g * rp.voxel_length);
            let light = lighting_at(p);
            let sun = rp.sky.irradiance * sunlight(p.y, l_y) * light.all.sun;
            // Diffuse light: the diffusion solution (never below zero) and the skylight.
            let diffuse = max(light.solved.i0, vec3<f32>(0.0)) + light.all.sky;
            let p1 = ams_mix(rho, 1.0, cos_theta);
            let before = edge * w_edge;
            let after = before + w_edge * ext * dt;
            var m_before = vec3<f32>(0.0);
            var m_after = vec3<f32>(0.0);
            if (w_edge > 0.0) {
                m_before = poisson_mix(rho, before, cos_theta);
                m_after = poisson_mix(rho, after, cos_theta);
            }
            for (var c = 0u; c < 3u; c = c + 1u) {
                if (ext[c] <= 0.0) {
                    continue;
                }
                let albedo = sca[c] / ext[c];
                let slab = exp(-ext[c] * dt);
                // Dense share: diffusion plus exact single scattering of the sun.
                let dense = (1.0 - w_edge) * (1.0 - slab) * albedo * (diffuse[c] + p1[c] * sun[c]);
                // Edge share: the segment's increment, seen from its entry.
                let g0 = scattered(before[c], albedo);
                let g1 = scattered(after[c], albedo);
                let edge_light = (g1 * m_after[c] - g0 * m_before[c]) * sun[c] + (g1 - g0) * diffuse[c];
                l_vol[c] = l_vol[c] + tr[c] * dense + tr[c] * exp(before[c]) * edge_light;
                tr[c] = tr[c] * slab;
                edge[c] = after[c];
                largest = max(largest, after[c]);
            }
            if (all(tr < vec3<f32>(1e-9))) {
                break;
            }
        }
    }
    atomicMax(&largest_edge, bitcast<u32>(largest));

    // Composition (render::shading::compose), the ground lit through the volume.
    var lit = vec3<f32>(1.0);
    let k_end = ground_distance(eye, d);
    if (rp.grid.ground_albedo > 0.0 && k_end > 0.0) {
        lit = sun_left(eye + k_end * d);
    }
    let v = compose(eye, d, l_vol, tr, tr, lit);
    image[id.x + rp.sizes.x * id.y] = vec4<f32>(v, tr.g);
}
