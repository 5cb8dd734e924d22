// Biri, Arquès & Michelin 2006 on the GPU: one invocation per pixel does what the CPU
// reference (cpu.rs) does per ray — the first surface (§5.1.2), then for each light the lit
// pieces of the ray from its sorted crossings with the silhouette planes (the stencil count,
// §5.1.4–5.1.5), the spheres' tangent cones and the spot cone, each piece's Γ(F) − Γ(E) from
// the bake's kernel (Eq. 2: exact primitive or quartic), and the ambient fog (§3). f32
// throughout; the buffers' layouts are written by gpu.rs. Compiled after the tables' WGSL
// (runtime::gpu::WGSL, bind group 0), whose `biri_primitive` is the exact kernel; this
// model's own resources are bind group 1.

struct Params {
    view: View,
    ground_albedo: f32,
    depth_max: f32,          // the kernel table's last depth
    polynomial_kernel: u32,  // 1: the polynomial kernel, 0: the exact one
    surfaces_only: u32,      // 1: the surfaces only (stage 2)
    width: u32,
    height: u32,
    lights: u32,
    media: u32,
    spheres: u32,
    meshes: u32,
    pad0: u32,
    pad1: u32,
}

@group(1) @binding(0) var<uniform> P: Params;
// Per light 4 vec4: position (xyz, shadow count at the eye), intensity (rgb, spot: 1/0),
// spot axis (xyz, cos half-angle), (first plane, plane count, sphere-blocked bits, 0) as bits.
@group(1) @binding(1) var<storage, read> lights: array<vec4<f32>>;
// Per shadow plane 3 vec4: a (xyz, weight), b (xyz, 0), normal (xyz, 0).
@group(1) @binding(2) var<storage, read> planes: array<vec4<f32>>;
// Per sphere 1 vec4: centre, radius; albedo in spheres_albedo.
@group(1) @binding(3) var<storage, read> spheres: array<vec4<f32>>;
// Per mesh 2 vec4: lo (xyz, first triangle bits), hi (xyz, triangle count bits); albedo in
// the w of its first triangle's first vertex row.
@group(1) @binding(4) var<storage, read> meshes: array<vec4<f32>>;
// Per triangle 3 vec4: a (xyz, albedo), b, c.
@group(1) @binding(5) var<storage, read> tris: array<vec4<f32>>;
// Per medium 5 vec4: lo (xyz, 1 box / 0 everywhere), hi (xyz, field bits), β_ext (rgb),
// β_sca (rgb), ambient (rgb).
@group(1) @binding(6) var<storage, read> media: array<vec4<f32>>;
// The quartic's coefficients (Eq. 2) of field f of the tables, at its Biri depths: from index
// polynomials[f], for channel c and depth j the five c_0..c_4 at (c J + j) 5.
@group(1) @binding(7) var<storage, read> polynomials: array<f32>;
@group(1) @binding(8) var<storage, read_write> image: array<vec4<f32>>;

const EPS: f32 = 1e-4;
const MAX_EVENTS: u32 = 64u;

fn box_span(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> vec2<f32> {
    // Entry and exit distances; entry > exit when missed.
    var a = -1e30;
    var b = 1e30;
    for (var k = 0; k < 3; k++) {
        if (abs(d[k]) < 1e-30) {
            if (o[k] < lo[k] || o[k] > hi[k]) { return vec2<f32>(1.0, -1.0); }
        } else {
            let t0 = (lo[k] - o[k]) / d[k];
            let t1 = (hi[k] - o[k]) / d[k];
            a = max(a, min(t0, t1));
            b = min(b, max(t0, t1));
        }
    }
    return vec2<f32>(a, b);
}

fn ray_triangle(o: vec3<f32>, d: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> f32 {
    let e1 = b - a;
    let e2 = c - a;
    let p = cross(d, e2);
    let det = dot(e1, p);
    if (abs(det) < 1e-20) { return -1.0; }
    let inv = 1.0 / det;
    let t = o - a;
    let u = dot(t, p) * inv;
    if (u < 0.0 || u > 1.0) { return -1.0; }
    let q = cross(t, e1);
    let v = dot(d, q) * inv;
    if (v < 0.0 || u + v > 1.0) { return -1.0; }
    return dot(e2, q) * inv;
}

fn ray_sphere(o: vec3<f32>, d: vec3<f32>, s: vec4<f32>) -> vec2<f32> {
    let w = o - s.xyz;
    let b = dot(w, d);
    let disc = b * b - (dot(w, w) - s.w * s.w);
    if (disc < 0.0) { return vec2<f32>(1.0, -1.0); }
    let q = sqrt(disc);
    return vec2<f32>(-b - q, -b + q);
}

struct Hit { x: f32, n: vec3<f32>, albedo: f32 }

// The first surface along o + x d: the ground, a sphere, a mesh triangle.
fn surface(o: vec3<f32>, d: vec3<f32>) -> Hit {
    var h = Hit(1e30, vec3<f32>(0.0, 1.0, 0.0), 0.0);
    if (d.y < 0.0) { h = Hit(-o.y / d.y, vec3<f32>(0.0, 1.0, 0.0), P.ground_albedo); }
    for (var i = 0u; i < P.spheres; i++) {
        let s = spheres[2u * i];
        let r = ray_sphere(o, d, s);
        var x = r.x;
        if (x <= EPS) { x = r.y; }
        if (r.x <= r.y && x > EPS && x < h.x) {
            var n = (o + x * d - s.xyz) / s.w;
            if (dot(n, d) > 0.0) { n = -n; }
            h = Hit(x, n, spheres[2u * i + 1u].x);
        }
    }
    for (var m = 0u; m < P.meshes; m++) {
        let lo = meshes[2u * m];
        let hi = meshes[2u * m + 1u];
        let span = box_span(o, d, lo.xyz, hi.xyz);
        if (span.x > span.y || span.y < 0.0 || span.x > h.x) { continue; }
        let first = bitcast<u32>(lo.w);
        let count = bitcast<u32>(hi.w);
        for (var t = first; t < first + count; t++) {
            let a = tris[3u * t];
            let b = tris[3u * t + 1u].xyz;
            let c = tris[3u * t + 2u].xyz;
            let x = ray_triangle(o, d, a.xyz, b, c);
            if (x > EPS && x < h.x) {
                var n = normalize(cross(b - a.xyz, c - a.xyz));
                if (dot(n, d) > 0.0) { n = -n; }
                h = Hit(x, n, a.w);
            }
        }
    }
    return h;
}

// Whether the segment p → q passes no occluder.
fn visible(p: vec3<f32>, q: vec3<f32>) -> bool {
    let dv = q - p;
    let len = length(dv);
    let d = dv / len;
    for (var i = 0u; i < P.spheres; i++) {
        let r = ray_sphere(p, d, spheres[2u * i]);
        if (r.x <= r.y && r.y > EPS && r.x < len - EPS) { return false; }
    }
    for (var m = 0u; m < P.meshes; m++) {
        let lo = meshes[2u * m];
        let hi = meshes[2u * m + 1u];
        let span = box_span(p, d, lo.xyz, hi.xyz);
        if (span.x > span.y || span.y < 0.0 || span.x > len) { continue; }
        let first = bitcast<u32>(lo.w);
        let count = bitcast<u32>(hi.w);
        for (var t = first; t < first + count; t++) {
            let x = ray_triangle(p, d, tris[3u * t].xyz, tris[3u * t + 1u].xyz, tris[3u * t + 2u].xyz);
            if (x > EPS && x < len - EPS) { return false; }
        }
    }
    return true;
}

// The shadow state at p towards a light at q (cpu.rs's ShadowState): the count of triangles
// and spheres the segment p → q crosses, and the spheres that block it as bits. (The loops of
// `visible` with a count. One function for both, stopping at the first crossing when asked,
// timed 285–340 ms on lavapipe's beams frame at 256² against 287–297 ms for these two, each
// binary run three times alternately: not kept.)
fn shadow_state(p: vec3<f32>, q: vec3<f32>) -> vec2<u32> {
    let dv = q - p;
    let len = length(dv);
    let d = dv / len;
    var count = 0u;
    var bits = 0u;
    for (var i = 0u; i < P.spheres; i++) {
        let r = ray_sphere(p, d, spheres[2u * i]);
        if (r.x <= r.y && r.y > EPS && r.x < len - EPS) {
            count++;
            bits |= 1u << i;
        }
    }
    for (var m = 0u; m < P.meshes; m++) {
        let lo = meshes[2u * m];
        let hi = meshes[2u * m + 1u];
        let span = box_span(p, d, lo.xyz, hi.xyz);
        if (span.x > span.y || span.y < 0.0 || span.x > len) { continue; }
        let first = bitcast<u32>(lo.w);
        let n = bitcast<u32>(hi.w);
        for (var t = first; t < first + n; t++) {
            let x = ray_triangle(p, d, tris[3u * t].xyz, tris[3u * t + 1u].xyz, tris[3u * t + 2u].xyz);
            if (x > EPS && x < len - EPS) { count++; }
        }
    }
    return vec2<u32>(count, bits);
}

fn medium_span(i: u32, o: vec3<f32>, d: vec3<f32>, x_max: f32) -> vec2<f32> {
    let lo = media[5u * i];
    let hi = media[5u * i + 1u];
    if (lo.w == 0.0) { return vec2<f32>(0.0, x_max); }
    let s = box_span(o, d, lo.xyz, hi.xyz);
    return vec2<f32>(max(s.x, 0.0), min(s.y, x_max));
}

fn medium_contains(i: u32, p: vec3<f32>) -> bool {
    let lo = media[5u * i];
    let hi = media[5u * i + 1u];
    return lo.w == 0.0 || (all(p >= lo.xyz) && all(p <= hi.xyz));
}

// Optical depth per channel along p + x u, x ∈ [0, len], without medium `skip`.
fn depth(p: vec3<f32>, u: vec3<f32>, len: f32, skip: u32) -> vec3<f32> {
    var tau = vec3<f32>(0.0);
    for (var i = 0u; i < P.media; i++) {
        if (i == skip) { continue; }
        let s = medium_span(i, p, u, len);
        if (s.x < s.y) { tau += media[5u * i + 2u].xyz * (s.y - s.x); }
    }
    return tau;
}

fn in_spot(l: u32, u: vec3<f32>) -> bool {
    if (lights[4u * l + 1u].w == 0.0) { return true; }
    let axis = lights[4u * l + 2u];
    return dot(u, axis.xyz) >= axis.w * length(u);
}

// The roots x > 0 of ((X − S)·a)² = c²|X − S|² on X = o + x d on the nappe of sign `nappe`.
fn nappe_roots(s: vec3<f32>, a: vec3<f32>, cos2: f32, o: vec3<f32>, d: vec3<f32>, nappe: f32) -> vec2<f32> {
    let w = o - s;
    let da = dot(d, a);
    let wa = dot(w, a);
    let qa = da * da - cos2;
    let qb = 2.0 * (da * wa - cos2 * dot(d, w));
    let qc = wa * wa - cos2 * dot(w, w);
    var r = vec2<f32>(-1.0, -1.0);
    if (abs(qa) < 1e-7) {
        if (qb != 0.0) { r.x = -qc / qb; }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if (disc < 0.0) { return r; }
        let q = -0.5 * (qb + select(-1.0, 1.0, qb >= 0.0) * sqrt(disc));
        if (q != 0.0) { r = vec2<f32>(q / qa, qc / q); }
    }
    if (r.x > r.y) { r = r.yx; }
    if (!(r.x > 0.0 && dot(w + r.x * d, a) * nappe > 0.0)) { r.x = -1.0; }
    if (!(r.y > 0.0 && dot(w + r.y * d, a) * nappe > 0.0)) { r.y = -1.0; }
    return r;
}

// ∫_{θ0}^{θ1} of the quartic (Eq. 2) of channel c at τ, its coefficients quadratic in ln τ
// between the depths as the exact primitive's (biri_depth_weights).
fn polynomial(field: u32, c: u32, tau: f32, t0: f32, t1: f32) -> f32 {
    let j_len = model_header(field).y;
    let off = u32(polynomials[field]) + 5u * c * j_len;
    let w = biri_depth_weights(field, tau);
    var sum = 0.0;
    var p0 = t0;
    var p1 = t1;
    for (var i = 0u; i < 5u; i++) {
        var ci = 0.0;
        for (var r = 0; r < 3; r++) { ci += w.w[r] * polynomials[off + 5u * w.j[r] + i]; }
        sum += ci * (p1 - p0) / f32(i + 1u);
        p0 *= t0;
        p1 *= t1;
    }
    return sum;
}

// Γ(x1) − Γ(x0) of medium m for light l over a lit piece (cpu.rs, gamma).
fn gamma(m: u32, l: u32, o: vec3<f32>, d: vec3<f32>, entry: f32, x0: f32, x1: f32, front: vec3<f32>) -> vec3<f32> {
    let s = lights[4u * l].xyz;
    let t = dot(s - o, d);
    let h = max(length(s - (o + t * d)), 1e-3);
    let th0 = atan((x0 - t) / h);
    let th1 = atan((x1 - t) / h);
    let mid = o + 0.5 * (x0 + x1) * d;
    let to = mid - s;
    let r = length(to);
    let u = to / r;
    var r0 = 0.0;
    if (!medium_contains(m, s)) {
        let sp = medium_span(m, s, u, r);
        r0 = select(r, sp.x, sp.x < sp.y);
    }
    let others = depth(s, u, r, m);
    let field = bitcast<u32>(media[5u * m + 1u].w);
    let beta = media[5u * m + 2u].xyz;
    let sca = media[5u * m + 3u].xyz;
    let intensity = lights[4u * l + 1u].xyz;
    let taus = beta * h;
    var deltas = vec3<f32>(0.0);
    if (P.polynomial_kernel == 0u) {
        deltas = biri_primitive(field, taus, th1) - biri_primitive(field, taus, th0);
    } else {
        for (var c = 0u; c < 3u; c++) { deltas[c] = polynomial(field, c, taus[c], th0, th1); }
    }
    var out = vec3<f32>(0.0);
    for (var c = 0u; c < 3u; c++) {
        if (taus[c] > P.depth_max) { continue; }
        let delta = deltas[c];
        if (delta == 0.0) { continue; }
        let ex = min(-beta[c] * (t - entry - r0) - front[c] - others[c], 80.0);
        out[c] = sca[c] / h * intensity[c] * exp(ex) * delta;
    }
    return out;
}

@compute @workgroup_size(8, 8)
fn render(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = P.width;
    let hgt = P.height;
    if (id.x >= w || id.y >= hgt) { return; }
    // The pixel's ray (Camera::pixel): from the eye through the pixel, or for an orthographic
    // camera along the view direction from the pixel's point of the image plane.
    let u = 2.0 * (f32(id.x) + 0.5) / f32(w) - 1.0;
    let v = 1.0 - 2.0 * (f32(id.y) + 0.5) / f32(hgt);
    let sx = u * P.view.tan_half_fov * P.view.aspect;
    let sy = v * P.view.tan_half_fov;
    let ortho = P.view.ortho_half_height > 0.0;
    let d = select(normalize(P.view.forward + sx * P.view.right + sy * P.view.up), P.view.forward, ortho);
    let o = P.view.eye + P.view.ortho_half_height * (u * P.view.aspect * P.view.right + v * P.view.up);

    // Stage 2: the surface, shaded and attenuated.
    let hit = surface(o, d);
    var rgb = vec3<f32>(0.0);
    if (hit.x < 1e29) {
        let p = o + hit.x * d;
        var lsum = vec3<f32>(0.0);
        for (var l = 0u; l < P.lights; l++) {
            let s = lights[4u * l].xyz;
            let to = s - p;
            let r = length(to);
            let u = to / r;
            let cosine = dot(hit.n, u);
            if (cosine <= 0.0 || !in_spot(l, -u)) { continue; }
            if (!visible(p + hit.n * 1e-4 * (1.0 + r), s)) { continue; }
            let tau = depth(s, -u, r, 0xffffffffu);
            lsum += hit.albedo * lights[4u * l + 1u].xyz * cosine / (3.141592653589793 * r * r) * exp(-tau);
        }
        rgb = lsum * exp(-depth(o, d, hit.x, 0xffffffffu));
    }
    let x_end = hit.x;
    if (P.surfaces_only == 1u) {
        image[id.y * w + id.x] = vec4<f32>(rgb, 1.0);
        return;
    }

    // Stages 3–5: each light's lit pieces and their Γ differences.
    var events: array<vec2<f32>, MAX_EVENTS>;
    for (var l = 0u; l < P.lights; l++) {
        let s = lights[4u * l].xyz;
        var count = i32(lights[4u * l].w);
        let rec = lights[4u * l + 3u];
        let first = bitcast<u32>(rec.x);
        let n_planes = bitcast<u32>(rec.y);
        var blocked = bitcast<u32>(rec.z);
        // An orthographic ray's own state, found EPS along it (cpu.rs's ORTHOGRAPHIC_START_M).
        let x_from = select(0.0, EPS, ortho);
        if (ortho) {
            let state = shadow_state(o + x_from * d, s);
            count = i32(state.x);
            blocked = state.y;
        }
        var n = 0u;
        for (var i = first; i < first + n_planes; i++) {
            let a = planes[3u * i];
            let b = planes[3u * i + 1u].xyz;
            let nm = planes[3u * i + 2u].xyz;
            let dn = dot(d, nm);
            if (dn == 0.0) { continue; }
            let x = dot(s - o, nm) / dn;
            if (x <= x_from || x >= x_end) { continue; }
            let q = o + x * d - s;
            let uu = dot(a.xyz - s, a.xyz - s);
            let uv = dot(a.xyz - s, b - s);
            let vv = dot(b - s, b - s);
            let pu = dot(q, a.xyz - s);
            let pv = dot(q, b - s);
            let det = uu * vv - uv * uv;
            if (det <= 0.0) { continue; }
            let al = (pu * vv - pv * uv) / det;
            let be = (pv * uu - pu * uv) / det;
            if (al >= 0.0 && be >= 0.0 && al + be >= 1.0 && n < MAX_EVENTS) {
                events[n] = vec2<f32>(x, select(-a.w, a.w, dn > 0.0));
                n++;
            }
        }
        for (var i = 0u; i < P.spheres; i++) {
            let sp = spheres[2u * i];
            let axis_v = sp.xyz - s;
            let dist = length(axis_v);
            if (dist <= sp.w) { continue; }
            let axis = axis_v / dist;
            let cos2 = 1.0 - (sp.w / dist) * (sp.w / dist);
            let roots = nappe_roots(s, axis, cos2, o, d, 1.0);
            var on = ((blocked >> i) & 1u) == 1u;
            for (var k = 0; k < 2; k++) {
                let x = roots[k];
                if (x > x_from && x < x_end && dot(o + x * d - s, axis) > dist * cos2 && n < MAX_EVENTS) {
                    on = !on;
                    events[n] = vec2<f32>(x, select(-1.0, 1.0, on));
                    n++;
                }
            }
        }
        if (lights[4u * l + 1u].w != 0.0) {
            let ax = lights[4u * l + 2u];
            var inside = in_spot(l, o + x_from * d - s);
            if (!inside) { count += 1; }
            var roots = vec2<f32>(-1.0, -1.0);
            if (abs(ax.w) < 1e-6) {
                let da = dot(d, ax.xyz);
                if (da != 0.0) { roots.x = -dot(o - s, ax.xyz) / da; }
            } else {
                roots = nappe_roots(s, ax.xyz, ax.w * ax.w, o, d, sign(ax.w));
            }
            for (var k = 0; k < 2; k++) {
                let x = roots[k];
                if (x > x_from && x < x_end && n < MAX_EVENTS) {
                    inside = !inside;
                    events[n] = vec2<f32>(x, select(1.0, -1.0, inside));
                    n++;
                }
            }
        }
        // Insertion sort by distance.
        for (var i = 1u; i < n; i++) {
            let e = events[i];
            var j = i;
            while (j > 0u && events[j - 1u].x > e.x) {
                events[j] = events[j - 1u];
                j--;
            }
            events[j] = e;
        }
        var start = -1.0;
        if (count <= 0) { start = 0.0; }
        for (var i = 0u; i <= n; i++) {
            var x = x_end;
            var closing = true;
            if (i < n) {
                x = events[i].x;
                count += i32(events[i].y);
                closing = count > 0 && start >= 0.0;
            }
            if (closing && start >= 0.0) {
                // A lit piece [start, x]: each medium's part of it.
                for (var m = 0u; m < P.media; m++) {
                    let span = medium_span(m, o, d, x_end);
                    let x0 = max(start, span.x);
                    let x1 = min(x, span.y);
                    if (x0 < x1) {
                        let front = depth(o, d, span.x, m);
                        rgb += gamma(m, l, o, d, span.x, x0, x1, front);
                    }
                }
                start = -1.0;
            } else if (i < n && count <= 0 && start < 0.0) {
                start = x;
            }
        }
    }
    // The ambient fog, and the media's transparency.
    var tau_all = vec3<f32>(0.0);
    for (var m = 0u; m < P.media; m++) {
        let span = medium_span(m, o, d, x_end);
        if (span.x < span.y) {
            let front = depth(o, d, span.x, 0xffffffffu);
            let own = media[5u * m + 2u].xyz * (span.y - span.x);
            rgb += media[5u * m + 4u].xyz * exp(-front) * (1.0 - exp(-own));
            tau_all += own;
        }
    }
    image[id.y * w + id.x] = vec4<f32>(rgb, exp(-tau_all.y));
}
