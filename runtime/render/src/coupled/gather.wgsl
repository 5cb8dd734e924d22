// The coupled model's gather (step 4 of render::coupled's docs) on the GPU: one invocation per
// pixel does what render::coupled::gather::gather does per ray, in f32, from the per-voxel
// lighting the CPU computed (the beam, the diffusion's I_0 and I_1, the reduced skylight),
// then composes the pixel with the air, the sun disk and the ground. Included after
// tables.wgsl (bind group 0: Ams_n by `ams_mix`), slicing.wgsl (grid sampling, camera rays,
// the sky), compose.wgsl and march.wgsl.

struct CoupledParams {
    view: View,
    grid: Grid,
    sizes: vec2<u32>,        // width, height
    march_step: f32,         // the march's step (m)
    pad_step: f32,
    sh_max: vec3<f32>,       // the transport grid's upper corner (its lower is grid_min's)
    pad0: f32,
    sh_dims: vec3<u32>,      // its voxels along x, y, z
    pad1: u32,
    // The switches, 1 where on, else 0:
    delta_split: u32,        // the δ-split (f = g², δ-scaled gather)
    p1_radiance: u32,        // the P1 radiance (else I_0 alone)
    transport_moments: u32,  // the transport's moments
    peak_blur: u32,          // the sun's single scattering blurred by the forward peak (coupled::peak)
    sigma_ext: array<vec4<f32>, 4>,  // per field, m² per channel
    asymmetry: array<vec4<f32>, 4>,  // per field, g per channel
    peak: array<vec4<f32>, 4>,       // per field, the forward peak f per channel; w = the
                                     // blur's peak share s (green; coupled::peak)
    chi: array<array<vec4<f32>, 4>, 5>,  // per Legendre degree l ≤ 4 and field, χ_l per channel
    sky: Sky,
}

@group(1) @binding(0) var<uniform> rp: CoupledParams;
@group(1) @binding(1) var<storage, read> density: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> lighting: array<LightVoxel>;
@group(1) @binding(3) var<storage, read_write> image: array<vec4<f32>>;  // rgb, T_vol (green)
// With the δ-split, the phase functions blurred by the forward peak (render::coupled::peak):
// p^(D_j)(θ_k) at ((field · PEAK_DEPTHS + j) · 3 + channel) · K + k, D_j = j · PEAK_DEPTH_STEP
// (both constants put before this file by coupled::gpu::source).
@group(1) @binding(4) var<storage, read> blurred: array<f32>;
// With the transport, a voxel's 75 spherical-harmonic moments φ_lm (25 per channel, R then G
// then B), four a row so that the gather loads them four at a time.
struct Moments {
    rows: array<vec4<f32>, 19>,
}
// Per voxel of the transport's grid (sh_dims, the frame's grid or its blocks).
@group(1) @binding(5) var<storage, read> moments: array<Moments>;

// Row `row` of the transport's moments at p, trilinear between its grid's voxel centres,
// clamped to the edge voxels (as slicing.wgsl's `taps` on the frame's grid); zero outside the
// frame's box.
fn moments_at(p: vec3<f32>, row: u32) -> vec4<f32> {
    if (!inside_box(p)) {
        return vec4<f32>(0.0);
    }
    let tap = taps_in(p, rp.grid.min, rp.sh_max, rp.sh_dims);
    var sum = vec4<f32>(0.0);
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        let d = vec3<u32>(corner & 1u, (corner >> 1u) & 1u, (corner >> 2u) & 1u);
        let w3 = select(1.0 - tap.t, tap.t, d == vec3<u32>(1u));
        let at = tap.lo + d * tap.s;
        let i = at.x + rp.sh_dims.x * (at.y + rp.sh_dims.y * at.z);
        sum = sum + w3.x * w3.y * w3.z * moments[i].rows[row];
    }
    return sum;
}

// p^(D)(θ) of the mixture, linear in θ and D (render::coupled::peak::PeakBlur::phase).
fn peak_blurred(rho: vec4<f32>, depth: f32, cos_theta: f32) -> vec3<f32> {
    let col = ams_column(cos_theta);
    let k_len = ams_params.angle_count;
    let v = min(max(depth, 0.0) / PEAK_DEPTH_STEP, f32(PEAK_DEPTHS - 1u));
    let j0 = min(u32(floor(v)), PEAK_DEPTHS - 2u);
    let s = v - f32(j0);
    var num = vec3<f32>(0.0);
    var den = vec3<f32>(0.0);
    for (var i = 0u; i < min(rp.grid.fields, 4u); i = i + 1u) {
        if (rho[i] > 0.0) {
            var p = vec3<f32>(0.0);
            for (var c = 0u; c < 3u; c = c + 1u) {
                let r0 = ((i * PEAK_DEPTHS + j0) * 3u + c) * k_len + col.k0;
                let r1 = r0 + 3u * k_len;
                let a = mix(blurred[r0], blurred[r0 + 1u], col.t);
                let b = mix(blurred[r1], blurred[r1 + 1u], col.t);
                p[c] = mix(a, b, s);
            }
            let w = rho[i] * ams_field_info[i].yzw;
            num = num + w * p;
            den = den + w;
        }
    }
    return select(vec3<f32>(0.0), num / den, den > vec3<f32>(0.0));
}

// The forward peak's scattering coefficient Σ ρ σ_sca s (green; 1/m).
fn peak_coefficient(rho: vec4<f32>) -> f32 {
    var sum = 0.0;
    for (var i = 0u; i < min(rp.grid.fields, 4u); i = i + 1u) {
        sum = sum + max(rho[i], 0.0) * ams_field_info[i].z * rp.peak[i].w;
    }
    return sum;
}

// A voxel's lighting (render::coupled's Lighting, in f32), read by march.wgsl's lighting_at.
struct LightVoxel {
    beam: vec3<f32>,         // the beam I per channel
    peak_depth: f32,         // the peak's depth n
    i0: vec3<f32>,           // the diffusion's I_0 per channel
    in_solve: f32,           // 1 if in the diffusion solve, else 0
    channel: array<Channel, 3>,
}

// One channel's diffusion flux I_1 and skylight mean.
struct Channel {
    i1: vec3<f32>,
    sky_mean: f32,
}

fn channel_add(sum: Channel, w: f32, v: Channel) -> Channel {
    return Channel(sum.i1 + w * v.i1, sum.sky_mean + w * v.sky_mean);
}

// sum + w · v, field by field.
fn weighted_add(sum: LightVoxel, w: f32, v: LightVoxel) -> LightVoxel {
    return LightVoxel(sum.beam + w * v.beam, sum.peak_depth + w * v.peak_depth,
        sum.i0 + w * v.i0, sum.in_solve + w * v.in_solve, array<Channel, 3>(
        channel_add(sum.channel[0], w, v.channel[0]), channel_add(sum.channel[1], w, v.channel[1]),
        channel_add(sum.channel[2], w, v.channel[2])));
}

// v / t, field by field.
fn divided(v: LightVoxel, t: f32) -> LightVoxel {
    var out = v;
    out.beam = v.beam / t;
    out.peak_depth = v.peak_depth / t;
    out.i0 = v.i0 / t;
    out.in_solve = v.in_solve / t;
    for (var c = 0u; c < 3u; c = c + 1u) {
        out.channel[c] = Channel(v.channel[c].i1 / t, v.channel[c].sky_mean / t);
    }
    return out;
}

// Whether the voxel is in the diffusion solve.
fn in_solve(v: LightVoxel) -> bool {
    return v.in_solve != 0.0;
}

// The real, orthonormal spherical harmonics to degree 4 (render::lighting::transport::harmonics).
fn harmonics(w: vec3<f32>) -> array<f32, 25> {
    let x = w.x;
    let y = w.y;
    let z = w.z;
    let x2 = x * x;
    let y2 = y * y;
    let z2 = z * z;
    return array<f32, 25>(
        0.28209479,
        0.48860251 * y, 0.48860251 * z, 0.48860251 * x,
        1.09254843 * x * y, 1.09254843 * y * z, 0.31539157 * (3.0 * z2 - 1.0),
        1.09254843 * x * z, 0.54627422 * (x2 - y2),
        0.59004359 * y * (3.0 * x2 - y2), 2.89061144 * x * y * z,
        0.45704580 * y * (5.0 * z2 - 1.0), 0.37317633 * z * (5.0 * z2 - 3.0),
        0.45704580 * x * (5.0 * z2 - 1.0), 1.44530572 * z * (x2 - y2),
        0.59004359 * x * (x2 - 3.0 * y2),
        2.50334294 * x * y * (x2 - y2), 1.77013077 * y * z * (3.0 * x2 - y2),
        0.94617470 * x * y * (7.0 * z2 - 1.0), 0.66904654 * y * z * (7.0 * z2 - 3.0),
        0.10578555 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0), 0.66904654 * x * z * (7.0 * z2 - 3.0),
        0.47308735 * (x2 - y2) * (7.0 * z2 - 1.0), 1.77013077 * x * z * (x2 - 3.0 * y2),
        0.62583574 * (x2 * (x2 - 3.0 * y2) - y2 * (3.0 * x2 - y2)),
    );
}

// A per-field quantity `values` of the mixture, weighted by ρ σ_sca
// (render::coupled::light::mixed).
fn mixed(rho: vec4<f32>, values: array<vec4<f32>, 4>) -> vec3<f32> {
    var num = vec3<f32>(0.0);
    var den = vec3<f32>(0.0);
    for (var i = 0u; i < min(rp.grid.fields, 4u); i = i + 1u) {
        if (rho[i] > 0.0) {
            let w = rho[i] * ams_field_info[i].yzw;
            num = num + w * values[i].rgb;
            den = den + w;
        }
    }
    return select(vec3<f32>(0.0), num / den, den > vec3<f32>(0.0));
}

@compute @workgroup_size(8, 8)
fn gather(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.sizes.x || id.y >= rp.sizes.y) {
        return;
    }
    let eye = camera_origin(id.x, id.y);
    let d = camera_direction(id.x, id.y);
    let cos_theta = dot(rp.sky.sun, d);
    let toward_eye = -d;
    let transport = rp.transport_moments == 1u;
    let y = harmonics(toward_eye);
    var l_vol = vec3<f32>(0.0);
    var tr = vec3<f32>(1.0);
    var seen = vec3<f32>(1.0);
    // The forward peak's optical depth from the eye (coupled::peak).
    var depth_out = 0.0;
    let span = box_span(eye, d);
    if (span.y >= 0.0) {
        let n = max(u32(ceil((span.y - span.x) / rp.march_step)), 1u);
        let dt = (span.y - span.x) / f32(n);
        for (var k = 0u; k < n; k = k + 1u) {
            let p = eye + (span.x + (f32(k) + 0.5) * dt) * d;
            let rho = densities(p);
            let ext = extinction(rho);
            if (all(ext <= vec3<f32>(0.0))) {
                continue;
            }
            let sca = scattering_of(rho);
            let light = lighting_at(p);
            let beam = light.all.beam;
            let n = light.all.peak_depth;
            let i0 = light.solved.i0;
            let channel = light.solved.channel;
            let sky = vec3<f32>(light.all.channel[0].sky_mean, light.all.channel[1].sky_mean,
                light.all.channel[2].sky_mean);
            let sun = rp.sky.irradiance * sunlight(p.y, rp.sky.sun.y) * beam;
            // The beam scattered by Ams_1 blurred by the peak's scatterings in (n) and out to
            // the middle of this step (δ-M's split), or by Ams_{n+1} (0 with δ-Eddington's).
            var phase: vec3<f32>;
            if (rp.peak_blur == 1u) {
                let peak = peak_coefficient(rho) * dt;
                phase = peak_blurred(rho, n + depth_out + 0.5 * peak, cos_theta);
                depth_out = depth_out + peak;
            } else {
                phase = ams_mix(rho, n + 1.0, cos_theta);
            }
            let g = mixed(rho, rp.asymmetry);
            let f = select(vec3<f32>(0.0), mixed(rho, rp.peak), rp.delta_split == 1u);
            // The transport's diffuse light towards the eye, Σ_l χ′_l Σ_m Y_lm φ_lm per channel
            // (render::lighting::transport::scattered), χ′_l = (χ_l − f)/(1 − f) of the mixture.
            var toward = vec3<f32>(0.0);
            if (transport) {
                var chi: array<vec3<f32>, 5>;
                for (var l = 0u; l < 5u; l = l + 1u) {
                    chi[l] = (mixed(rho, rp.chi[l]) - f) / max(1.0 - f, vec3<f32>(1e-6));
                }
                for (var r = 0u; r < 19u; r = r + 1u) {
                    let m = moments_at(p, r);
                    for (var j = 0u; j < 4u; j = j + 1u) {
                        let q = 4u * r + j;
                        if (q >= 75u) {
                            break;
                        }
                        let c = q / 25u;
                        let k = q % 25u;
                        let l = u32(sqrt(f32(k) + 0.5));
                        toward[c] = toward[c] + chi[l][c] * y[k] * m[j];
                    }
                }
            }
            for (var c = 0u; c < 3u; c = c + 1u) {
                if (ext[c] <= 0.0) {
                    continue;
                }
                let albedo = sca[c] / ext[c];
                // The P1 radiance, |I_1| ≤ I_0 so that it is nowhere negative.
                var flux = channel[c].i1;
                let limit = max(i0[c], 0.0);
                let len = length(flux);
                if (len > limit) {
                    flux = flux * (limit / len);
                }
                let along = select(0.0, (g[c] - f[c]) * dot(flux, toward_eye), rp.p1_radiance == 1u);
                let diffuse = select(max((1.0 - f[c]) * i0[c] + along, 0.0),
                    max((1.0 - f[c]) * toward[c], 0.0), transport);
                let light = albedo * (phase[c] * sun[c] + diffuse + (1.0 - f[c]) * sky[c]);
                let kept = 1.0 - albedo * f[c];
                let scaled = ext[c] * kept * dt;
                if (scaled > 0.0) {
                    let slab = exp(-scaled);
                    l_vol[c] = l_vol[c] + seen[c] * (1.0 - slab) * light / kept;
                    seen[c] = seen[c] * slab;
                }
                tr[c] = tr[c] * exp(-ext[c] * dt);
            }
            if (all(seen < vec3<f32>(1e-9))) {
                break;
            }
        }
    }

    // Composition (render::shading::compose), the ground lit through the volume.
    var ground = vec3<f32>(1.0);
    let k_end = ground_distance(eye, d);
    if (rp.grid.ground_albedo > 0.0 && k_end > 0.0) {
        ground = sun_left(eye + k_end * d);
    }
    let v = compose(eye, d, l_vol, tr, seen, ground);
    image[id.x + rp.sizes.x * id.y] = vec4<f32>(v, tr.g);
}
