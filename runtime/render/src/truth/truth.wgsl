// The path-traced truth on the GPU (render::truth::gpu): the estimator of render::truth, written
// for one invocation per pixel, f32, after slicing.wgsl (grid sampling, camera rays, box span,
// the air's path factor). Every step names the CPU function it mirrors; the module docs of
// render::truth give the equations and their sources.

// The tracker's four scalars (a record of its own: as separate fields of Params, lavapipe's
// paths ran 5.7× slower on the cumulus at dawn).
struct Track {
    majorant: f32,           // 1/m
    guide_share: f32,        // the guide share ε
    inv_haze_height: f32,    // the haze's 1/H (1/m)
    transparency_step: f32,  // T_vol's step (m)
}

struct Counts {
    bands: u32,
    carried: u32,            // wavelengths carried per path
    max_scatterings: u32,
    lights: u32,
}

struct TableSizes {
    theta_bins: u32,
    haze_field: u32,         // 0xffffffff: none
    air_on: u32,             // 1: the air scatters
    blocks: u32,             // the phase sampling's blocks
}

struct Stream {
    seed_low: u32,           // the seed's low word
    seed_high: u32,          // its high word
    splitting: u32,          // 1: splitting on
    pad: u32,
}

struct Stepping {
    theta_step: f32,         // the θ bins' step (rad)
    loop_budget: f32,        // loop steps per dispatch
    pad0: f32,
    pad1: f32,
}

struct Tile {
    first: u32,              // the tile's first pixel
    pixels: u32,             // its pixel count
    pad0: u32,
    pad1: u32,
}

struct Params {
    view: View,
    sizes: vec2<u32>,        // width, height
    first_sample: u32,       // the first sample of this pass
    samples: u32,            // the samples in this pass
    grid: Grid,
    sigma_ext: array<vec4<f32>, 4>, // per field, m² per channel (the transparency uses green)
    sky: Sky,                // (beta unused here)
    background: vec3<f32>,   // radiance of what paths leave into
    pad0: f32,
    track: Track,
    counts: Counts,
    tables: TableSizes,
    stream: Stream,
    stepping: Stepping,
    tile: Tile,
}

@group(0) @binding(0) var<uniform> rp: Params;
@group(0) @binding(1) var<storage, read> density: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> bands: array<Band>;
// Per (band, field), PHASE_STRIDE floats: the bins' p_k (1/sr), each bin's CDF within its block
// (the block's last is 1), each block's CDF over the smooth part (the last is 1).
@group(0) @binding(3) var<storage, read> phase: array<f32>;
// Per bin: 1 − cos θ at its forward edge, its width in cos θ.
@group(0) @binding(4) var<storage, read> bin_mu: array<vec2<f32>>;
@group(0) @binding(5) var<storage, read> lights: array<Light>;
// Per pixel two rows: Σ L and Σ L² over this pass's samples (rgb).
@group(0) @binding(6) var<storage, read_write> sums: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> transparency_out: array<f32>;
// Per dispatch, at a dynamic offset: whether it begins a sample (else it continues the paths
// under way) and whether it counts the paths still under way after it.
struct Step {
    begin: u32,
    count: u32,
    pad0: u32,
    pad1: u32,
}
@group(0) @binding(8) var<uniform> stp: Step;
// Paths cut short by the adapter (see `step`), and paths still under way.
@group(0) @binding(9) var<storage, read_write> counters: array<atomic<u32>, 2>;
// Each tile slot's path between dispatches (`save`, `load`).
@group(0) @binding(10) var<storage, read_write> saved: array<SavedPath>;

// A point or spot light (Tracer's lights).
struct Light {
    position: vec4<f32>,     // its position (m); w: 1 for a spot, 0 for a point light
    intensity: vec4<f32>,    // its intensity per channel, 0
    axis: vec4<f32>,         // a spot's axis; w: the cosine of its half-angle (−2 for a point)
}

// One wavelength band's optics (Tracer's bands).
struct Band {
    air: vec4<f32>,          // β_air at sea level, haze N₀σ_ext, haze N₀σ_sca, the CDF of q
    to_rgb: vec4<f32>,       // w_c/q per channel, 0
    fields: array<vec4<f32>, MAX_FIELDS>, // per field: σ_ext, albedo, forward δ, 0
}

// A path's point, direction and carried wavelengths: the one under way (SavedPath's head) or
// a branch a split left waiting on its stack (`push`, `pop`).
struct SavedBranch {
    f: vec4<f32>,            // the carried wavelengths' f_m (Carried)
    r: vec4<f32>,            // their r_m
    position: vec4<f32>,     // p xyz, 0
    direction: vec4<f32>,    // d xyz, 0
    band: vec4<u32>,         // the carried wavelengths' bands
    counts: vec4<u32>,       // wavelengths carried, bounce; the head's stack top and alive
}

// A tile slot's path between dispatches (`save`, `load`).
struct SavedPath {
    head: SavedBranch,
    sum: vec4<f32>,          // the radiance gathered so far rgb, 0
    stream: vec4<u32>,       // the random stream: key0, key1, counter; the sample k
    stack: array<SavedBranch, STACK>,
}

// The photon pipeline (photons walking forward, `photon_event`) or the camera's: a pipeline
// constant, so that each pipeline holds only its own code (a run-time flag made lavapipe's
// camera paths 10× slower).
override photon_mode: bool = false;
// The grid repeats in x and z (DensityGrid::periodic): a constant of the pipeline, so that a
// bounded grid's loops are those they were.
override periodic: bool = false;

const BLOCK: u32 = 32u;
const MAX_FIELDS: u32 = 4u;
const PI: f32 = 3.14159265358979;
const INF: f32 = 3.0e38;
const ROULETTE_WEIGHT: f32 = 1e-3;
const SPLIT_WEIGHT: f32 = 2.0;
const MAX_SPLIT: u32 = 16u;
const STACK: u32 = 8u;
const EVENT_STEPS: u32 = 64u;

// ---- random numbers: counter-based, two 32-bit keys per (seed, pixel, sample) ----

var<private> key0: u32;
var<private> key1: u32;
var<private> counter: u32;
// Loop steps (free-path and transmittance steps, events) taken in this dispatch.
var<private> work: u32;

// A 32-bit integer hash (xor-shift-multiply rounds, Wellons' "lowbias32" constants).
fn hash(v: u32) -> u32 {
    var x = v;
    x = x ^ (x >> 16u);
    x = x * 0x7feb352du;
    x = x ^ (x >> 15u);
    x = x * 0x846ca68bu;
    x = x ^ (x >> 16u);
    return x;
}

fn stream(pixel: u32, smp: u32) {
    let s = hash(hash(rp.stream.seed_low) ^ rp.stream.seed_high);
    key0 = hash(s ^ hash(pixel + 0x9e3779b9u) ^ hash(smp * 0x85ebca6bu + 1u));
    key1 = hash(key0 ^ hash(smp + 0x27d4eb2fu) ^ pixel * 0xc2b2ae35u);
    counter = 0u;
}

// Uniform in [0, 1), 24 bits.
fn rand() -> f32 {
    counter = counter + 1u;
    let x = hash(hash(counter ^ key0) + key1);
    return f32(x >> 8u) * (1.0 / 16777216.0);
}

// Every component finite, judged by its exponent bits (a driver may fold x != x away).
fn finite3(v: vec3<f32>) -> bool {
    let e = bitcast<vec3<u32>>(v) & vec3<u32>(0x7f800000u);
    return all(e != vec3<u32>(0x7f800000u));
}

// Exponential of rate 1.
fn exp_rand() -> f32 {
    return -log(1.0 - rand());
}

// ---- the carried wavelengths (render::truth::Carried) ----

struct Carried {
    n: u32,
    band: vec4<u32>,
    f: vec4<f32>,
    r: vec4<f32>,
}

fn mask(c: Carried) -> vec4<f32> {
    return select(vec4<f32>(0.0), vec4<f32>(1.0), vec4<u32>(0u, 1u, 2u, 3u) < vec4<u32>(c.n));
}

// W_m = f_m / Σ_k p_k (the balance heuristic).
fn weights(c: Carried) -> vec4<f32> {
    let s = dot(c.r, mask(c));
    if (s <= 0.0) {
        return vec4<f32>(0.0);
    }
    return c.f * mask(c) / s;
}

// Divides every f_m and p_m by their mean p: the weights W_m = f_m / Σ_k p_k do not change,
// but the ratios p_m/p_0, products over thousands of collisions in a dense cloud, stay inside
// f32's range (e^{±88}; the CPU's f64 has e^{±709}).
fn renormalize(c: ptr<function, Carried>) {
    let s = dot((*c).r, mask(*c)) / f32((*c).n);
    if (s > 0.0 && s < INF) {
        (*c).f = (*c).f / s;
        (*c).r = (*c).r / s;
    }
}

fn field_optics(b: u32, field: u32) -> vec4<f32> {
    return bands[b].fields[field];
}

// The wavelengths of one path (Tracer::carry): the m-th at u + m/n (mod 1) in the bands' CDF.
fn carry(n: u32) -> Carried {
    let u = rand();
    var c: Carried;
    c.n = n;
    c.f = vec4<f32>(1.0);
    c.r = vec4<f32>(1.0);
    for (var m = 0u; m < n; m = m + 1u) {
        var um = u + f32(m) / f32(n);
        if (um >= 1.0) {
            um = um - 1.0;
        }
        var j = 0u;
        while (j + 1u < rp.counts.bands && bands[j].air.w <= um) {
            j = j + 1u;
        }
        c.band[m] = j;
    }
    return c;
}

// ---- the phase functions (render::truth::phase::PhaseSampler) ----

fn phase_base(b: u32, field: u32) -> u32 {
    let bins = rp.tables.theta_bins;
    return (b * 4u + field) * (2u * bins + rp.tables.blocks);
}

fn phase_value(b: u32, field: u32, k: u32) -> f32 {
    return phase[phase_base(b, field) + k];
}

// The bin of the angle between unit d and w.
fn phase_bin(d: vec3<f32>, w: vec3<f32>) -> u32 {
    let theta = atan2(length(cross(d, w)), dot(d, w));
    return min(u32(round(theta / rp.stepping.theta_step)), rp.tables.theta_bins - 1u);
}

// A bin of the smooth part drawn by its probability (u picks the block, v the bin in it: each
// level's CDF is relative, so a bin of probability 10⁻⁸ is drawn as often as it should be in
// f32), then (1 − cos θ, sin θ) uniform in cos θ inside the bin (w).
fn phase_sample_smooth(b: u32, field: u32, u: f32, v: f32, w: f32) -> vec2<f32> {
    let bins = rp.tables.theta_bins;
    let blocks = rp.tables.blocks;
    let base = phase_base(b, field);
    var lo = 0u;
    var hi = blocks - 1u;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (phase[base + 2u * bins + mid] > u) {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    var k0 = lo * BLOCK;
    var k1 = min(k0 + BLOCK, bins) - 1u;
    while (k0 < k1) {
        let mid = (k0 + k1) / 2u;
        if (phase[base + bins + mid] > v) {
            k1 = mid;
        } else {
            k0 = mid + 1u;
        }
    }
    let mu = bin_mu[k0];
    let omm = clamp(mu.x + w * mu.y, 0.0, 2.0);
    return vec2<f32>(omm, sqrt(max(omm * (2.0 - omm), 0.0)));
}

// Rayleigh phase function (1/sr) and the inversion of its CDF (phase::rayleigh,
// phase::sample_rayleigh).
fn rayleigh(c: f32) -> f32 {
    return 3.0 / (16.0 * PI) * (1.0 + c * c);
}

fn sample_rayleigh(u: f32) -> f32 {
    let q = 4.0 * u - 2.0;
    let r = sqrt(q * q + 1.0);
    let a = q + r;
    let b = q - r;
    return clamp(sign(a) * pow(abs(a), 1.0 / 3.0) + sign(b) * pow(abs(b), 1.0 / 3.0), -1.0, 1.0);
}

fn basis1(d: vec3<f32>) -> vec3<f32> {
    let helper = select(vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), abs(d.x) < 0.9);
    return normalize(helper - dot(helper, d) * d);
}

// The direction at angle θ (as 1 − cos θ, sin θ) from d at azimuth 2π u (phase::rotate).
fn rotate(d: vec3<f32>, omm: f32, s: f32, u: f32) -> vec3<f32> {
    let e1 = basis1(d);
    let e2 = cross(d, e1);
    let phi = 2.0 * PI * u;
    return normalize((1.0 - omm) * d + s * (cos(phi) * e1 + sin(phi) * e2));
}

// ---- air and haze: exponential species ----

fn log1p(x: f32) -> f32 {
    if (abs(x) < 1e-4) {
        return x * (1.0 - x * (0.5 - x / 3.0));
    }
    return log(1.0 + x);
}

// Distance to the next collision with β(y) = β₀ e^{−γ y} (truth::sample_exponential), or INF.
fn sample_exponential(beta0: f32, gamma: f32, p: vec3<f32>, d: vec3<f32>) -> f32 {
    if (beta0 <= 0.0) {
        return INF;
    }
    let target_tau = exp_rand() / (beta0 * exp(-gamma * p.y));
    let k = gamma * d.y;
    if (abs(k) < 1e-12) {
        return target_tau;
    }
    let x = target_tau * k;
    if (x >= 1.0) {
        return INF;
    }
    return -log1p(-x) / k;
}

// Optical depth per unit β_sl from p along d over s (INF allowed): Tracer::air_path.
fn exp_path(gamma: f32, p: vec3<f32>, d: vec3<f32>, s: f32) -> f32 {
    let k = select(s, -1.0, s >= INF);
    return exp(-gamma * p.y) * path_factor_for(gamma, d.y, k) / gamma;
}

fn air_path(p: vec3<f32>, d: vec3<f32>, s: f32) -> f32 {
    if (rp.tables.air_on == 0u) {
        return 0.0;
    }
    return exp_path(rp.sky.inv_scale_height, p, d, s);
}

fn haze_path(p: vec3<f32>, d: vec3<f32>, s: f32) -> f32 {
    if (rp.tables.haze_field == 0xffffffffu) {
        return 0.0;
    }
    return exp_path(rp.track.inv_haze_height, p, d, s);
}

// Tracer::air_ratios.
fn air_ratios(c: ptr<function, Carried>, p: vec3<f32>, d: vec3<f32>, s: f32, collided: bool) {
    if ((*c).n == 1u || rp.tables.air_on == 0u) {
        return;
    }
    let path = air_path(p, d, s);
    let b0 = bands[(*c).band[0]].air.x;
    for (var m = 1u; m < (*c).n; m = m + 1u) {
        let bm = bands[(*c).band[m]].air.x;
        var k = exp(-(bm - b0) * path);
        if (collided) {
            k = k * bm / b0;
        }
        (*c).f[m] = (*c).f[m] * k;
        (*c).r[m] = (*c).r[m] * k;
    }
}

// Tracer::haze_ratios.
fn haze_ratios(c: ptr<function, Carried>, p: vec3<f32>, d: vec3<f32>, s: f32, collided: bool) {
    if (rp.tables.haze_field == 0xffffffffu) {
        return;
    }
    let path = haze_path(p, d, s);
    let b0 = bands[(*c).band[0]].air.y;
    for (var m = 0u; m < (*c).n; m = m + 1u) {
        let row = bands[(*c).band[m]].air;
        let k = exp(-(row.y - b0) * path);
        if (collided) {
            (*c).f[m] = (*c).f[m] * k * row.z / b0;
            (*c).r[m] = (*c).r[m] * k * row.y / b0;
        } else if (m > 0u) {
            (*c).f[m] = (*c).f[m] * k;
            (*c).r[m] = (*c).r[m] * k;
        }
    }
}

// ---- the volumes ----

// σ_ext of each field (columns) for each carried wavelength (rows; past n the hero's), so that
// the extinctions at densities ρ are one product, M ρ, without loops: llvmpipe counts every loop
// iteration of an invocation against its limit (module docs of truth::gpu).
fn sigma_matrix(c: Carried) -> mat4x4<f32> {
    let b0 = c.band[0];
    let b1 = select(b0, c.band[1], c.n > 1u);
    let b2 = select(b0, c.band[2], c.n > 2u);
    let b3 = select(b0, c.band[3], c.n > 3u);
    return mat4x4<f32>(
        vec4<f32>(field_optics(b0, 0u).x, field_optics(b1, 0u).x, field_optics(b2, 0u).x, field_optics(b3, 0u).x),
        vec4<f32>(field_optics(b0, 1u).x, field_optics(b1, 1u).x, field_optics(b2, 1u).x, field_optics(b3, 1u).x),
        vec4<f32>(field_optics(b0, 2u).x, field_optics(b1, 2u).x, field_optics(b2, 2u).x, field_optics(b3, 2u).x),
        vec4<f32>(field_optics(b0, 3u).x, field_optics(b1, 3u).x, field_optics(b2, 3u).x, field_optics(b3, 3u).x),
    );
}

// Extinction at densities rho for each carried wavelength (Tracer::extinctions).
fn extinctions(c: Carried, rho: vec4<f32>) -> vec4<f32> {
    var e = vec4<f32>(0.0);
    for (var m = 0u; m < c.n; m = m + 1u) {
        for (var f = 0u; f < rp.grid.fields; f = f + 1u) {
            e[m] = e[m] + rho[f] * field_optics(c.band[m], f).x;
        }
    }
    return e;
}

struct Hit {
    hit: bool,
    t: f32,
    rho: vec4<f32>,
}

// Where o + t d crosses the grid, t ≥ 0, or (−1, −1) (box_span); a periodic grid
// between its bottom and top only, at most 1000 periods of it
// (DensityGrid::bounds, DensityGrid::longest_path_m).
fn grid_span(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    if (!periodic) {
        return box_span(o, d);
    }
    var t0 = 0.0;
    var t1 = 3.0e38;
    if (d.y == 0.0) {
        if (o.y < rp.grid.min.y || o.y > rp.grid.max.y) {
            return vec2<f32>(-1.0);
        }
    } else {
        let lo = (rp.grid.min.y - o.y) / d.y;
        let hi = (rp.grid.max.y - o.y) / d.y;
        t0 = max(0.0, min(lo, hi));
        t1 = max(lo, hi);
    }
    let size = rp.grid.max - rp.grid.min;
    t1 = min(t1, t0 + 1000.0 * max(size.x, size.z));
    return select(vec2<f32>(-1.0), vec2<f32>(t0, t1), t0 < t1);
}

// Trilinear densities at p (densities); on a periodic grid x and z wrap, the last voxel's
// upper neighbour being the first (DensityGrid::taps).
fn grid_densities(p: vec3<f32>) -> vec4<f32> {
    if (!periodic) {
        return densities(p);
    }
    if (p.y < rp.grid.min.y || p.y > rp.grid.max.y) {
        return vec4<f32>(0.0);
    }
    let n = rp.grid.dims;
    let nf = vec3<f32>(n);
    let u = (p - rp.grid.min) / (rp.grid.max - rp.grid.min) * nf - 0.5;
    let ux = u.x - floor(u.x / nf.x) * nf.x;
    let uz = u.z - floor(u.z / nf.z) * nf.z;
    let uy = clamp(u.y, 0.0, nf.y - 1.0);
    let x0 = min(u32(floor(ux)), n.x - 1u);
    let z0 = min(u32(floor(uz)), n.z - 1u);
    let y0 = u32(min(i32(floor(uy)), max(i32(n.y) - 2, 0)));
    let x1 = (x0 + 1u) % n.x;
    let z1 = (z0 + 1u) % n.z;
    let y1 = y0 + u32(n.y > 1u);
    let t = vec3<f32>(ux - f32(x0), select(0.0, uy - f32(y0), n.y > 1u), uz - f32(z0));
    let c00 = mix(voxel(x0, y0, z0), voxel(x1, y0, z0), t.x);
    let c10 = mix(voxel(x0, y1, z0), voxel(x1, y1, z0), t.x);
    let c01 = mix(voxel(x0, y0, z1), voxel(x1, y0, z1), t.x);
    let c11 = mix(voxel(x0, y1, z1), voxel(x1, y1, z1), t.x);
    return mix(mix(c00, c10, t.y), mix(c01, c11, t.y), t.z);
}

// Delta tracking up to limit, decided by the hero (Tracer::track).
fn track(c: ptr<function, Carried>, p: vec3<f32>, d: vec3<f32>, limit: f32) -> Hit {
    var out: Hit;
    out.hit = false;
    let span = grid_span(p, d);
    if (span.y < 0.0) {
        return out;
    }
    let end = min(span.y, limit);
    let mu = rp.track.majorant;
    let sig = sigma_matrix(*c);
    var t = span.x;
    loop {
        work = work + 1u;
        t = t + exp_rand() / mu;
        if (t >= end) {
            return out;
        }
        let rho = grid_densities(p + t * d);
        let e = sig * rho;
        if (rand() * mu < e[0]) {
            out.hit = true;
            out.t = t;
            out.rho = rho;
            return out;
        }
        // Every other wavelength's density by its share of null collisions over the hero's
        // (the hero's own factor is 1; past n nothing is read).
        let k = (mu - e) / (mu - e[0]);
        (*c).f = (*c).f * k;
        (*c).r = (*c).r * k;
    }
    return out;
}

// Ratio tracking with Russian roulette below 1/20 (Tracer::volume_transmittance).
fn volume_transmittance(c: Carried, p: vec3<f32>, d: vec3<f32>, limit: f32) -> vec4<f32> {
    var tr = vec4<f32>(1.0);
    let span = grid_span(p, d);
    if (span.y < 0.0) {
        return tr;
    }
    let end = min(span.y, limit);
    let mu = rp.track.majorant;
    let sig = sigma_matrix(c);
    var t = span.x;
    loop {
        work = work + 1u;
        t = t + exp_rand() / mu;
        if (t >= end) {
            return tr;
        }
        let e = sig * grid_densities(p + t * d);
        tr = tr * (1.0 - e / mu);
        let tm = tr * mask(c);
        if (max(max(tm.x, tm.y), max(tm.z, tm.w)) < 0.05) {
            if (rand() < 0.5) {
                return vec4<f32>(0.0);
            }
            tr = tr * 2.0;
        }
    }
    return tr;
}

// ---- direct light (Tracer::direct) ----

// What a vertex scatters towards `dir` per carried wavelength: kind 0 a volume vertex of
// `field` (the tabulated phase function), 1 the air, 2 a Lambertian surface of normal n and
// albedo a.
struct Vertex {
    kind: u32,
    field: u32,
    d: vec3<f32>,
    n: vec3<f32>,
    a: f32,
}

fn vertex_weight(c: Carried, v: Vertex, dir: vec3<f32>) -> vec4<f32> {
    if (v.kind == 0u) {
        let k = phase_bin(v.d, dir);
        var w = vec4<f32>(0.0);
        for (var m = 0u; m < c.n; m = m + 1u) {
            w[m] = phase_value(c.band[m], v.field, k);
        }
        return w;
    }
    if (v.kind == 1u) {
        return vec4<f32>(rayleigh(dot(v.d, dir)));
    }
    return vec4<f32>(v.a / PI * max(dot(dir, v.n), 0.0));
}

// One source seen from p along dir over limit: Σ_m coef_m · weight_m · T_m · source.
fn add_source(c: Carried, v: Vertex, p: vec3<f32>, dir: vec3<f32>, limit: f32, source: vec3<f32>,
              coef_w: vec4<f32>) -> vec3<f32> {
    let w = vertex_weight(c, v, dir) * mask(c);
    if (all(w <= vec4<f32>(0.0))) {
        return vec3<f32>(0.0);
    }
    let tv = volume_transmittance(c, p, dir, limit);
    let air = air_path(p, dir, limit);
    let hz = haze_path(p, dir, limit);
    var sum = vec3<f32>(0.0);
    for (var m = 0u; m < c.n; m = m + 1u) {
        let row = bands[c.band[m]].air;
        let t = w[m] * tv[m] * exp(-row.x * air - row.y * hz);
        sum = sum + coef_w[m] * bands[c.band[m]].to_rgb.xyz * t * source;
    }
    return sum;
}

fn direct(c: Carried, v: Vertex, p: vec3<f32>, coef_w: vec4<f32>) -> vec3<f32> {
    var sum = add_source(c, v, p, rp.sky.sun, INF, rp.sky.irradiance, coef_w);
    for (var i = 0u; i < rp.counts.lights; i = i + 1u) {
        let light = lights[i];
        let to = light.position.xyz - p;
        let r2 = dot(to, to);
        if (r2 == 0.0) {
            continue;
        }
        let r = sqrt(r2);
        let dir = to / r;
        if (light.position.w > 0.5 && dot(-dir, light.axis.xyz) < light.axis.w) {
            continue;
        }
        sum = sum + add_source(c, v, p, dir, r, light.intensity.xyz / r2, coef_w);
    }
    return sum;
}

// ---- free paths (Tracer::next_event) ----

const EV_VOLUME: u32 = 0u;
const EV_AIR: u32 = 1u;
const EV_SURFACE: u32 = 2u;
const EV_ESCAPE: u32 = 3u;

struct Event {
    kind: u32,
    field: u32,
    p: vec3<f32>,
}

fn next_event(c: ptr<function, Carried>, p0: vec3<f32>, d: vec3<f32>) -> Event {
    var ev: Event;
    ev.p = p0;
    ev.field = 0u;
    let t_ground = select(INF, max(p0.y / -d.y, 0.0), d.y < 0.0);
    let hero = bands[(*c).band[0]].air;
    let t_air = select(INF, sample_exponential(hero.x, rp.sky.inv_scale_height, p0, d), rp.tables.air_on != 0u);
    let t_haze = select(INF, sample_exponential(hero.y, rp.track.inv_haze_height, p0, d),
        rp.tables.haze_field != 0xffffffffu);
    let hit = track(c, p0, d, min(t_ground, min(t_air, t_haze)));
    if (hit.hit) {
        air_ratios(c, p0, d, hit.t, false);
        haze_ratios(c, p0, d, hit.t, false);
        ev.p = p0 + hit.t * d;
        let e = extinctions(*c, hit.rho);
        let nf = rp.grid.fields;
        var total = vec4<f32>(0.0);
        for (var m = 0u; m < (*c).n; m = m + 1u) {
            for (var f = 0u; f < nf; f = f + 1u) {
                let o = field_optics((*c).band[m], f);
                total[m] = total[m] + hit.rho[f] * o.x * o.y;
            }
        }
        var field = nf - 1u;
        if (total[0] > 0.0) {
            var pick = rand() * total[0];
            for (var f = 0u; f < nf; f = f + 1u) {
                let o = field_optics((*c).band[0], f);
                let s = hit.rho[f] * o.x * o.y;
                if (pick < s) {
                    field = f;
                    break;
                }
                pick = pick - s;
            }
        } else {
            field = min(u32(rand() * f32(nf)), nf - 1u);
        }
        var p0c = 0.0;
        for (var m = 0u; m < (*c).n; m = m + 1u) {
            let o = field_optics((*c).band[m], field);
            let s = hit.rho[field] * o.x * o.y;
            let choice = select(1.0 / f32(nf), s / total[m], total[m] > 0.0);
            if (m == 0u) {
                p0c = e[0] * choice;
            }
            (*c).f[m] = (*c).f[m] * s / p0c;
            (*c).r[m] = (*c).r[m] * e[m] * choice / p0c;
        }
        ev.kind = EV_VOLUME;
        ev.field = field;
    } else if (t_haze < min(t_ground, t_air)) {
        air_ratios(c, p0, d, t_haze, false);
        haze_ratios(c, p0, d, t_haze, true);
        ev.p = p0 + t_haze * d;
        ev.kind = EV_VOLUME;
        ev.field = rp.tables.haze_field;
    } else if (t_air < t_ground) {
        air_ratios(c, p0, d, t_air, true);
        haze_ratios(c, p0, d, t_air, false);
        ev.p = p0 + t_air * d;
        ev.kind = EV_AIR;
    } else if (t_ground < INF) {
        air_ratios(c, p0, d, t_ground, false);
        haze_ratios(c, p0, d, t_ground, false);
        ev.p = p0 + t_ground * d;
        ev.p.y = 0.0;
        ev.kind = EV_SURFACE;
    } else {
        air_ratios(c, p0, d, INF, false);
        haze_ratios(c, p0, d, INF, false);
        ev.kind = EV_ESCAPE;
    }
    return ev;
}

// The continuation at a volume vertex (Tracer::continue_volume): with probability ε from the
// smooth part about the sun, else about d (the δ included), weighted by p/q.
fn continue_volume(c: ptr<function, Carried>, field: u32, d: vec3<f32>, eps: f32) -> vec3<f32> {
    let b0 = (*c).band[0];
    let delta0 = field_optics(b0, field).z;
    var next: vec3<f32>;
    if (eps > 0.0 && rand() < eps) {
        let s = phase_sample_smooth(b0, field, rand(), rand(), rand());
        next = rotate(rp.sky.sun, s.x, s.y, rand());
    } else {
        let u = rand();
        if (u < delta0) {
            // The forward δ: p_m = (1 − ε) f_m, f_m = f_m.
            for (var m = 0u; m < (*c).n; m = m + 1u) {
                let ratio = field_optics((*c).band[m], field).z / delta0;
                (*c).f[m] = (*c).f[m] * ratio / (1.0 - eps);
                (*c).r[m] = (*c).r[m] * ratio;
            }
            return d;
        }
        let s = phase_sample_smooth(b0, field, min((u - delta0) / (1.0 - delta0), 0.99999994),
            rand(), rand());
        next = rotate(d, s.x, s.y, rand());
    }
    if (eps == 0.0 && (*c).n == 1u) {
        return next;
    }
    let kd = phase_bin(d, next);
    let ks = select(0u, phase_bin(rp.sky.sun, next), eps > 0.0);
    var q0 = 0.0;
    var pm = vec4<f32>(0.0);
    var qm = vec4<f32>(0.0);
    for (var m = 0u; m < (*c).n; m = m + 1u) {
        let b = (*c).band[m];
        let p = phase_value(b, field, kd);
        var q = p;
        if (eps > 0.0) {
            q = (1.0 - eps) * p + eps * phase_value(b, field, ks) / (1.0 - field_optics(b, field).z);
        }
        pm[m] = p;
        qm[m] = q;
    }
    q0 = qm[0];
    if (q0 <= 0.0) {
        (*c).f = vec4<f32>(0.0);
        return next;
    }
    (*c).f = (*c).f * pm / q0;
    (*c).r = (*c).r * qm / q0;
    return next;
}

// The continuation at an air or ground vertex (Tracer::continue_guided): with probability ε
// from the smooth lobe about the sun of a field drawn uniformly, else Rayleigh about d (air) or
// the cosine about the normal n (ground, albedo a), weighted by value/q.
fn continue_guided(c: ptr<function, Carried>, ground: bool, d: vec3<f32>, n: vec3<f32>, a: f32,
                   eps: f32) -> vec3<f32> {
    let fields = rp.grid.fields;
    var next: vec3<f32>;
    if (eps > 0.0 && rand() < eps) {
        let field = min(u32(rand() * f32(fields)), fields - 1u);
        let s = phase_sample_smooth((*c).band[0], field, rand(), rand(), rand());
        next = rotate(rp.sky.sun, s.x, s.y, rand());
    } else if (ground) {
        let r = sqrt(rand());
        let phi = 2.0 * PI * rand();
        let e1 = basis1(n);
        let e2 = cross(n, e1);
        next = normalize(r * cos(phi) * e1 + r * sin(phi) * e2 + sqrt(max(1.0 - r * r, 0.0)) * n);
    } else {
        let mu = sample_rayleigh(rand());
        next = rotate(d, 1.0 - mu, sqrt(max(1.0 - mu * mu, 0.0)), rand());
    }
    // The own density and the value (phase function, or BRDF × cosine) towards `next`.
    var pdf = rayleigh(dot(d, next));
    var value = pdf;
    if (ground) {
        pdf = max(dot(next, n), 0.0) / PI;
        value = a * pdf;
    }
    if (eps == 0.0) {
        (*c).f = (*c).f * select(0.0, value / pdf, pdf > 0.0);
        return next;
    }
    let ks = phase_bin(rp.sky.sun, next);
    var q = vec4<f32>(0.0);
    for (var m = 0u; m < (*c).n; m = m + 1u) {
        let b = (*c).band[m];
        var guide = 0.0;
        for (var f = 0u; f < fields; f = f + 1u) {
            guide = guide + phase_value(b, f, ks) / (1.0 - field_optics(b, f).z);
        }
        q[m] = (1.0 - eps) * pdf + eps * guide / f32(fields);
    }
    if (q[0] <= 0.0) {
        (*c).f = vec4<f32>(0.0);
        return next;
    }
    (*c).f = (*c).f * value / q[0];
    (*c).r = (*c).r * q / q[0];
    return next;
}

// The weight window (Tracer::weight_window): roulette below ROULETTE_WEIGHT, with `room` > 0
// a split into k ≤ room + 1 branches above SPLIT_WEIGHT. The branches, 0 when the path ends.
fn weight_window(c: ptr<function, Carried>, room: u32) -> u32 {
    let w = weights(*c);
    let largest = f32((*c).n) * max(max(w.x, w.y), max(w.z, w.w));
    var kept = largest;
    if (kept < ROULETTE_WEIGHT) {
        if (rand() * ROULETTE_WEIGHT >= kept) {
            return 0u;
        }
        kept = ROULETTE_WEIGHT;
    }
    var k = 1u;
    if (rp.stream.splitting != 0u && kept > SPLIT_WEIGHT) {
        k = min(min(u32(ceil(kept)), MAX_SPLIT), room + 1u);
    }
    if (kept != largest) {
        (*c).f = (*c).f * (kept / largest);
    }
    (*c).f = (*c).f / f32(k);
    return k;
}

// ---- a camera path (Tracer::radiance), resumable ----

// A path under way: its branch (wavelengths, position, direction, scatterings), the branches
// split off and waiting (the top `top` entries of its slot's stack), whether it is still under
// way, and the radiance it has gathered.
struct Path {
    c: Carried,
    p: vec3<f32>,
    d: vec3<f32>,
    bounce: u32,
    top: u32,
    alive: u32,
    sum: vec3<f32>,
    // The sample within the pass.
    k: u32,
}

// Sample k of the pass at `pixel`: its random stream and its camera ray (in photon mode, a
// photon of one wavelength from the eye along `forward`).
fn begin_sample(pixel: u32, k: u32) -> Path {
    var path: Path;
    stream(pixel, rp.first_sample + k);
    path.p = rp.view.eye;
    if (photon_mode) {
        path.c = carry(1u);
        path.d = rp.view.forward;
    } else {
        path.c = carry(rp.counts.carried);
        path.p = camera_origin(pixel % rp.sizes.x, pixel / rp.sizes.x);
        path.d = camera_direction(pixel % rp.sizes.x, pixel / rp.sizes.x);
    }
    path.bounce = 0u;
    path.top = 0u;
    path.alive = 1u;
    path.sum = vec3<f32>(0.0);
    path.k = k;
    return path;
}

// A path's carried wavelengths `c`, point `p`, direction `d` and `bounce` as a saved branch,
// `top` and `alive` in its counts' last two lanes.
fn branch_of(c: Carried, p: vec3<f32>, d: vec3<f32>, bounce: u32, top: u32, alive: u32)
    -> SavedBranch {
    return SavedBranch(c.f, c.r, vec4<f32>(p, 0.0), vec4<f32>(d, 0.0), c.band,
                       vec4<u32>(c.n, bounce, top, alive));
}

// `b` back into `path` (its `c`, `p`, `d`, `bounce`).
fn restore(b: SavedBranch, path: ptr<function, Path>) {
    (*path).c.f = b.f;
    (*path).c.r = b.r;
    (*path).p = b.position.xyz;
    (*path).d = b.direction.xyz;
    (*path).c.band = b.band;
    (*path).c.n = b.counts.x;
    (*path).bounce = b.counts.y;
}

fn push(slot: u32, e: u32, c: Carried, p: vec3<f32>, d: vec3<f32>, bounce: u32) {
    saved[slot].stack[e] = branch_of(c, p, d, bounce, 0u, 0u);
}

fn pop(slot: u32, path: ptr<function, Path>) {
    (*path).top = (*path).top - 1u;
    restore(saved[slot].stack[(*path).top], path);
}

fn save(slot: u32, path: Path) {
    saved[slot].head = branch_of(path.c, path.p, path.d, path.bounce, path.top, path.alive);
    saved[slot].sum = vec4<f32>(path.sum, 0.0);
    saved[slot].stream = vec4<u32>(key0, key1, counter, path.k);
}

fn load(slot: u32) -> Path {
    var path: Path;
    let head = saved[slot].head;
    restore(head, &path);
    path.top = head.counts.z;
    path.alive = head.counts.w;
    path.sum = saved[slot].sum.xyz;
    let k = saved[slot].stream;
    key0 = k.x;
    key1 = k.y;
    counter = k.z;
    path.k = k.w;
    return path;
}

// One free path of a photon walking forward (Tracer::photon: plain phase sampling, no splitting)
// and what happens at its end; true when it ends, its weight then in `sum`: x if it left
// upwards, y if downwards off the beam's direction (the slabs' R and diffuse T).
fn photon_event(path: ptr<function, Path>) -> bool {
    (*path).sum = vec3<f32>(0.0);
    if ((*path).bounce >= rp.counts.max_scatterings) {
        return true;
    }
    var c = (*path).c;
    let d = (*path).d;
    let ev = next_event(&c, (*path).p, d);
    (*path).p = ev.p;
    if (ev.kind == EV_ESCAPE || ev.kind == EV_SURFACE) {
        let w = c.f[0];
        if (d.y > 0.0) {
            (*path).sum = vec3<f32>(w, 0.0, 0.0);
        } else if (any(d != rp.view.forward)) {
            (*path).sum = vec3<f32>(0.0, w, 0.0);
        }
        return true;
    }
    if (ev.kind == EV_VOLUME) {
        (*path).d = continue_volume(&c, ev.field, d, 0.0);
    } else {
        let mu = sample_rayleigh(rand());
        (*path).d = rotate(d, 1.0 - mu, sqrt(max(1.0 - mu * mu, 0.0)), rand());
    }
    (*path).bounce = (*path).bounce + 1u;
    let k = weight_window(&c, 0u);
    (*path).c = c;
    return k == 0u;
}

// One free path of the current branch and what happens at its end (the loop body of
// Tracer::radiance); true when the branch ends.
fn event(slot: u32, path: ptr<function, Path>) -> bool {
    if (photon_mode) {
        return photon_event(path);
    }
    let max_scatterings = rp.counts.max_scatterings;
    if ((*path).bounce >= max_scatterings) {
        return true;
    }
    var c = (*path).c;
    let d = (*path).d;
    let ev = next_event(&c, (*path).p, d);
    renormalize(&c);
    let p = ev.p;
    (*path).p = p;
    let w = weights(c);
    var v: Vertex;
    v.kind = ev.kind;
    v.field = ev.field;
    v.d = d;
    v.n = vec3<f32>(0.0, 1.0, 0.0);
    v.a = rp.grid.ground_albedo;
    if (ev.kind == EV_ESCAPE) {
        let disk = (*path).bounce == 0u && dot(d, rp.sky.sun) >= rp.sky.cos_disk;
        let l = rp.background + select(vec3<f32>(0.0), rp.sky.irradiance / rp.sky.disk_sr, disk);
        var add = vec3<f32>(0.0);
        for (var m = 0u; m < c.n; m = m + 1u) {
            add = add + w[m] * bands[c.band[m]].to_rgb.xyz * l;
        }
        (*path).sum = (*path).sum + add;
        return true;
    }
    if (ev.kind == EV_SURFACE && v.a == 0.0) {
        return true;
    }
    (*path).sum = (*path).sum + direct(c, v, p, w);
    var next: vec3<f32>;
    if (ev.kind == EV_VOLUME) {
        next = continue_volume(&c, ev.field, d, rp.track.guide_share);
    } else {
        next = continue_guided(&c, ev.kind == EV_SURFACE, d, v.n, v.a, rp.track.guide_share);
    }
    (*path).d = next;
    (*path).bounce = (*path).bounce + 1u;
    (*path).c = c;
    if ((*path).bounce >= max_scatterings) {
        return true;
    }
    let k = weight_window(&c, STACK - 1u - (*path).top);
    (*path).c = c;
    if (k == 0u) {
        return true;
    }
    for (var i = 1u; i < k; i = i + 1u) {
        push(slot, (*path).top, c, p, next, (*path).bounce);
        (*path).top = (*path).top + 1u;
    }
    return false;
}

// Advances one pixel's path of the current sample by at most about `rp.stepping.loop_budget` loop steps:
// a dispatch stops between events once it has taken that many, and the next one goes on from
// the saved state. Bounded work per dispatch keeps every invocation inside llvmpipe's loop
// limit and every dispatch short on a desktop GPU (whose driver resets a device busy for
// seconds); the path is the same whichever dispatch takes which part of it.
@compute @workgroup_size(64)
fn step(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.tile.pixels) {
        return;
    }
    let slot = id.x;
    let pixel = rp.tile.first + slot;
    var path: Path;
    if (stp.begin == 1u) {
        path = begin_sample(pixel, 0u);
    } else {
        path = load(slot);
    }
    if (path.alive == 1u) {
        work = 0u;
        let budget = u32(rp.stepping.loop_budget);
        loop {
            if (work >= budget) {
                break;
            }
            // An event's own loops (the carried wavelengths, the fields, the phase CDFs'
            // binary searches, the lights) count as EVENT_STEPS.
            work = work + EVENT_STEPS;
            if (event(slot, &path)) {
                if (path.top > 0u) {
                    pop(slot, &path);
                    continue;
                }
                // The sample is done: its radiance into the pass's sums, then the next one.
                // A sample that is not finite (about one path in 10⁸ in f32 on an H200, where
                // the f64 CPU truth has none) counts as 0 and is counted in the w of Σ L.
                let bad = !(finite3(path.sum) && finite3(path.sum * path.sum));
                let l = select(path.sum, vec3<f32>(0.0), bad);
                let dropped = select(0.0, 1.0, bad);
                // Σ L² per channel and, in w, Σ Y² of the sample's Rec. 709 luminance.
                let y = dot(l, vec3<f32>(0.2126, 0.7152, 0.0722));
                if (path.k == 0u) {
                    sums[2u * pixel] = vec4<f32>(l, dropped);
                    sums[2u * pixel + 1u] = vec4<f32>(l * l, y * y);
                } else {
                    sums[2u * pixel] = sums[2u * pixel] + vec4<f32>(l, dropped);
                    sums[2u * pixel + 1u] = sums[2u * pixel + 1u] + vec4<f32>(l * l, y * y);
                }
                if (path.k + 1u < rp.samples) {
                    path = begin_sample(pixel, path.k + 1u);
                } else {
                    path.alive = 0u;
                    break;
                }
            }
        }
        save(slot, path);
    }
    // A probe loop of two iterations (its bound from the uniform, so that it is not unrolled):
    // llvmpipe ends every loop of an invocation once the invocation has run 65535 loop
    // iterations in all, silently cutting a path short; then this loop runs fewer times, and
    // the pass reports the cut path.
    var probe = 0u;
    for (var i = 0u; i < min(rp.tables.theta_bins, 2u); i = i + 1u) {
        probe = probe + 1u;
    }
    if (probe != min(rp.tables.theta_bins, 2u)) {
        atomicAdd(&counters[0], 1u);
    }
    if (stp.count == 1u && path.alive == 1u) {
        atomicAdd(&counters[1], 1u);
    }
}

// The volumes' transparency along each pixel's ray by a fine march of green β_ext
// (Tracer::transparency): quarter-voxel midpoint steps.
@compute @workgroup_size(8, 8)
fn transparency(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= rp.sizes.x || id.y >= rp.sizes.y) {
        return;
    }
    let pixel = id.x + rp.sizes.x * id.y;
    let o = camera_origin(id.x, id.y);
    let d = camera_direction(id.x, id.y);
    let span = grid_span(o, d);
    if (span.y < 0.0) {
        transparency_out[pixel] = 1.0;
        return;
    }
    let steps = u32(clamp(ceil((span.y - span.x) / rp.track.transparency_step), 1.0, 65536.0));
    let dt = (span.y - span.x) / f32(steps);
    var tau = 0.0;
    for (var i = 0u; i < steps; i = i + 1u) {
        let rho = grid_densities(o + (span.x + (f32(i) + 0.5) * dt) * d);
        for (var f = 0u; f < rp.grid.fields; f = f + 1u) {
            tau = tau + rho[f] * rp.sigma_ext[f].g * dt;
        }
    }
    transparency_out[pixel] = exp(-tau);
}
