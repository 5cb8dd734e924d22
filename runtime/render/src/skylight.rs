//! The air's light beyond single scattering: what the analytic sky of [`crate::sky`] (Riley et
//! al. 2004 Eqs. 11–15: sunlight scattered once by the air, and the ground lit by the sun)
//! leaves out — light scattered two or more times by the air, and the ground lit by the sky —
//! solved once per frame for the same flat, exponential Rayleigh atmosphere over the same
//! Lambertian ground, and tabulated by height, direction and azimuth from the sun.
//!
//! # The problem
//! With u = e^{−y/H}, the air's optical depth from the top down to height y is τ = τ* u
//! (τ* = β_sl H per channel) and its single-scattering albedo is 1, so the atmosphere is a
//! homogeneous plane-parallel slab in τ: 0 at the top, τ* at the ground (albedo A). The sun's
//! beam (per unit irradiance, travelling along μ_s = −l_y) gives the first-order source
//! J₁ = e^{−τ/l_y} p(Θ) and the ground's first reflection A l_y e^{−τ*/l_y}/π — exactly the
//! terms the analytic sky has. Everything else is the diffuse field's own scattering and
//! reflection. The Rayleigh phase function (Eq. 1) has three azimuthal Fourier modes
//! (Chandrasekhar 1960, §18; Liou 2002, §6.2): with s = (1 − μ²)^{1/2},
//!
//! p(Θ) = Σ_{m=0}^{2} (2 − δ_{m0}) P_m(μ, μ′) cos m(φ − φ′),
//! P₀ = (3/16π)(1 + μ²μ′² + s²s′²/2), P₁ = (3/16π) μμ′ss′, P₂ = (3/16π) s²s′²/4,
//!
//! so the radiance is Σ_m I_m(τ, μ) cos mφ (φ from the sun's azimuth; μ the cosine of the
//! direction the light travels, from the vertical), the source of mode m is
//! J_m(μ) = 2π ∫ P_m(μ, μ′) I_m(μ′) dμ′, and the ground (Lambertian) reflects mode 0 only.
//!
//! # The solution
//! Successive orders of scattering on `NODES` Gauss–Legendre directions per hemisphere and
//! `LEVELS` layers uniform in τ, each layer crossed exactly for a source linear in τ (the
//! formal solution, I_out = I_in e^{−x} + J_out(1 − (1 − e^{−x})/x) + J_in((1 − e^{−x})/x −
//! e^{−x}), x = Δτ/|μ|), until an order adds less than 10⁻¹⁰ of the total (τ* ≤ 0.3 in the
//! visible: each order is a few times weaker than the last). The table then holds, at every
//! level and on `MU_STEPS` output directions per hemisphere (μ = ±((j + ½)/MU_STEPS)², dense
//! at the horizon where the radiance turns fastest), the formal solution of the source of
//! orders ≥ 2 alone — J = 2π ∫ P_m I_{≥1} dμ′ at the output μ from the converged nodal field
//! (the source-function integration of Chandrasekhar 1960, §45) — with the ground reflecting
//! the diffuse light that reaches it. That is the radiance the analytic sky misses, exactly in
//! the plane-parallel geometry both share (the path-traced truth's air is the same).
//!
//! # Along a ray
//! The air is horizontally uniform, so the light the first K metres of a ray gather is
//! I(y, d) − T(y, d, K) I(y + K d_y, d): [`SkyLight::inscatter`] gives the multiply-scattered
//! share of Eq. 14's integral for the composite's front and back segments, and
//! [`SkyLight::radiance`] the whole ray's (to space or to the ground) for the skylight on the
//! volume. Neither sees the volume's shadow on the air or on the ground (nor does Eq. 14).

use std::f64::consts::PI;

use std::sync::Mutex;

use glam::DVec3;
use rayon::prelude::*;

use crate::frame::Frame;
use crate::sky::Atmosphere;

/// Layers of the table, uniform in u = e^{−y/H} (so in τ, for every channel).
pub const LEVELS: usize = 64;
/// Output directions per hemisphere, μ = ((j + ½)/MU_STEPS)².
pub const MU_STEPS: usize = 64;
/// Gauss–Legendre directions per hemisphere of the solve.
const NODES: usize = 16;
/// Azimuthal modes of the Rayleigh phase function.
pub const MODES: usize = 3;
/// An order adding less than this share of the total ends the solve.
const ORDER_TOLERANCE: f64 = 1e-10;
/// Orders at most (the visible's τ* ≤ 0.3 needs about ten; a safety bound).
const MAX_ORDERS: usize = 500;

/// The air's multiply-scattered light and the sky-lit ground, per unit solar irradiance,
/// tabulated by height, direction and azimuthal mode (module docs).
#[derive(Debug, Clone)]
pub struct SkyLight {
    /// 1/H (1/m).
    gamma: f64,
    /// The atmosphere (for the transparency of [`SkyLight::inscatter`]).
    atmosphere: Atmosphere,
    /// [(level · 2 MU_STEPS + direction) · MODES + mode] → radiance per channel; level k at
    /// u = k/LEVELS (k = LEVELS the ground), direction j < MU_STEPS travelling down (μ < 0),
    /// the rest up, each hemisphere from the horizon outwards.
    table: Vec<[f64; 3]>,
    /// Orders of scattering the solve took (per channel, the largest).
    pub orders: usize,
}

/// P_m(μ, μ′) of the module docs, 1/sr.
pub(crate) fn rayleigh_mode(m: usize, mu: f64, mu2: f64) -> f64 {
    let k = 3.0 / (16.0 * PI);
    let (s2, s2p) = ((1.0 - mu * mu).max(0.0), (1.0 - mu2 * mu2).max(0.0));
    match m {
        0 => k * (1.0 + mu * mu * mu2 * mu2 + 0.5 * s2 * s2p),
        1 => k * mu * mu2 * (s2 * s2p).sqrt(),
        _ => k * 0.25 * s2 * s2p,
    }
}

/// The output direction cosines μ_j (the direction the light travels), down then up.
fn output_mu(j: usize) -> f64 {
    let h = j % MU_STEPS;
    let mu = ((h as f64 + 0.5) / MU_STEPS as f64).powi(2);
    if j < MU_STEPS { -mu } else { mu }
}

/// Crossing a layer of optical thickness x along the light: I_in e^{−x} plus a source
/// linear from `j_in` (where the light enters) to `j_out`.
fn cross(i_in: f64, x: f64, j_in: f64, j_out: f64) -> f64 {
    let e = (-x).exp();
    // (1 − e^{−x})/x, finite as x → 0.
    let f = if x < 1e-6 {
        1.0 - 0.5 * x
    } else {
        -(-x).exp_m1() / x
    };
    i_in * e + j_out * (1.0 - f) + j_in * (f - e)
}

/// The formal solution of mode m's field at every level along direction `mu` (travelling),
/// for a source `j(level)` and, for light travelling up, the ground's radiance `ground`.
fn formal(mu: f64, dtau: f64, j: impl Fn(usize) -> f64, ground: f64) -> Vec<f64> {
    let mut out = vec![0.0; LEVELS + 1];
    let x = dtau / mu.abs();
    if mu < 0.0 {
        // Down from the top (no light enters from space).
        for k in 1..=LEVELS {
            out[k] = cross(out[k - 1], x, j(k - 1), j(k));
        }
    } else {
        out[LEVELS] = ground;
        for k in (0..LEVELS).rev() {
            out[k] = cross(out[k + 1], x, j(k + 1), j(k));
        }
    }
    out
}

/// One channel's solution.
struct Channel {
    /// [level · 2 MU_STEPS + output direction][mode].
    table: Vec<[f64; MODES]>,
    /// Orders of scattering summed.
    orders: usize,
    /// The whole diffuse field's upward flux at the top and downward flux at the ground (per
    /// unit irradiance; the direct beam's own l_y e^{−τ*/l_y} not included): the energy check
    /// of the tests.
    #[cfg_attr(not(test), allow(dead_code))]
    flux_up_top: f64,
    #[cfg_attr(not(test), allow(dead_code))]
    flux_down_ground: f64,
}

/// One channel's table (module docs).
fn solve_channel(tau_star: f64, l_y: f64, albedo: f64) -> Channel {
    let rows = LEVELS + 1;
    let dirs = 2 * MU_STEPS;
    if tau_star <= 0.0 {
        return Channel {
            table: vec![[0.0; MODES]; rows * dirs],
            orders: 0,
            flux_up_top: 0.0,
            flux_down_ground: 0.0,
        };
    }
    let dtau = tau_star / LEVELS as f64;
    let tau = |k: usize| k as f64 * dtau;
    // Gauss–Legendre on (0, 1): the weights sum to 1.
    let (x, w) = grid::quadrature::gauss_legendre_on(NODES, 0.0, 1.0);
    // Node directions (travelling): down (−x) then up (+x), each with weight w.
    let mu: Vec<f64> = x.iter().map(|&v| -v).chain(x.iter().copied()).collect();
    let weight: Vec<f64> = w.iter().chain(w.iter()).copied().collect();
    let n = mu.len();
    // The field per mode: [mode][node][level].
    let field = |source: &dyn Fn(usize, usize, usize) -> f64, ground: f64| {
        (0..MODES)
            .map(|m| {
                (0..n)
                    .map(|i| {
                        let g = if m == 0 { ground } else { 0.0 };
                        formal(mu[i], dtau, |k| source(m, i, k), g)
                    })
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    // The diffuse light's downward flux at the ground, 2π Σ w μ I₀.
    let flux_down = |f: &[Vec<Vec<f64>>]| {
        (0..NODES)
            .map(|i| 2.0 * PI * weight[i] * x[i] * f[0][i][LEVELS])
            .sum::<f64>()
    };
    // Mode factors of the scattering integral and of the beam (module docs).
    let sun_mu = -l_y;
    let first = |m: usize, i: usize, k: usize| {
        let c = if m == 0 { 1.0 } else { 2.0 };
        (-tau(k) / l_y).exp() * c * rayleigh_mode(m, mu[i], sun_mu)
    };
    let ground_first = albedo / PI * l_y * (-tau_star / l_y).exp();
    let mut order = field(&first, ground_first);
    let mut total = order.clone();
    let mut orders = 1;
    loop {
        let prev = &order;
        let scatter = |m: usize, i: usize, k: usize| {
            2.0 * PI
                * (0..n)
                    .map(|j| weight[j] * rayleigh_mode(m, mu[i], mu[j]) * prev[m][j][k])
                    .sum::<f64>()
        };
        let next = field(&scatter, albedo / PI * flux_down(prev));
        orders += 1;
        let (mut added, mut sum) = (0.0f64, 0.0f64);
        for m in 0..MODES {
            for i in 0..n {
                for k in 0..rows {
                    total[m][i][k] += next[m][i][k];
                    added = added.max(next[m][i][k].abs());
                    sum = sum.max(total[m][i][k].abs());
                }
            }
        }
        order = next;
        if added <= ORDER_TOLERANCE * sum || orders >= MAX_ORDERS {
            break;
        }
    }
    // Orders ≥ 2 on the output directions: the source of the whole diffuse field (orders ≥ 1
    // scattered once more) and the ground's reflection of its downward flux.
    let ground_ms = albedo / PI * flux_down(&total);
    let mut table = vec![[0.0; MODES]; rows * dirs];
    for d in 0..dirs {
        let mu_out = output_mu(d);
        for m in 0..MODES {
            let source = |k: usize| {
                2.0 * PI
                    * (0..n)
                        .map(|j| weight[j] * rayleigh_mode(m, mu_out, mu[j]) * total[m][j][k])
                        .sum::<f64>()
            };
            let g = if m == 0 { ground_ms } else { 0.0 };
            for (k, v) in formal(mu_out, dtau, source, g).into_iter().enumerate() {
                table[k * dirs + d][m] = v;
            }
        }
    }
    let flux_up_top = (0..NODES)
        .map(|i| 2.0 * PI * weight[i] * x[i] * total[0][NODES + i][0])
        .sum::<f64>();
    Channel {
        table,
        orders,
        flux_up_top,
        flux_down_ground: flux_down(&total),
    }
}

impl SkyLight {
    /// The table for `atmosphere` with the sun at vertical component `l_y` ∈ (0, 1] over a
    /// ground of Lambertian `albedo` ∈ [0, 1]. Zero where the atmosphere is off.
    pub fn new(atmosphere: &Atmosphere, l_y: f64, albedo: f64) -> Self {
        let h = atmosphere.scale_height_m;
        let channels: Vec<_> = (0..3)
            .into_par_iter()
            .map(|c| solve_channel(atmosphere.beta_sea_level_per_m[c] * h, l_y, albedo))
            .collect();
        let cells = channels[0].table.len();
        let table = (0..cells * MODES)
            .map(|i| std::array::from_fn(|c| channels[c].table[i / MODES][i % MODES]))
            .collect();
        Self {
            gamma: 1.0 / h,
            atmosphere: *atmosphere,
            table,
            orders: channels.iter().map(|c| c.orders).max().unwrap_or(0),
        }
    }

    /// The table of `frame`'s atmosphere, sun and ground. The last one made is kept: a moving
    /// camera (the viewer, the GPU models' every frame) reuses it until the sun, the ground or
    /// the air change (30–60 ms to solve on 2 cores).
    pub fn of(frame: &Frame) -> Self {
        static LAST: Mutex<Option<([u64; 6], SkyLight)>> = Mutex::new(None);
        let (atm, l_y) = (&frame.atmosphere, frame.sun.direction().y);
        let b = atm.beta_sea_level_per_m;
        let key = [
            b[0],
            b[1],
            b[2],
            atm.scale_height_m,
            l_y,
            frame.ground_albedo,
        ]
        .map(f64::to_bits);
        let mut last = LAST.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((k, sky)) = last.as_ref()
            && *k == key
        {
            return sky.clone();
        }
        let sky = Self::new(atm, l_y, frame.ground_albedo);
        *last = Some((key, sky.clone()));
        sky
    }

    /// The table as the shaders read it: one vec4 (rgb, 0) per (level, direction, mode), in
    /// the order of the module docs.
    pub fn gpu_table(&self) -> Vec<[f32; 4]> {
        self.table
            .iter()
            .map(|v| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0])
            .collect()
    }

    /// The missing radiance reaching height `y` along a view ray `d` (unit; the light travels
    /// along −d) from the whole ray, to space or to the ground, per unit solar irradiance;
    /// `sun` is the unit direction towards the sun.
    pub fn radiance(&self, y: f64, d: DVec3, sun: DVec3) -> [f64; 3] {
        if self.table.is_empty() {
            return [0.0; 3];
        }
        // Level: u = e^{−y/H} ∈ (0, 1], k = u · LEVELS.
        let u = (-self.gamma * y.max(0.0)).exp() * LEVELS as f64;
        let k0 = (u.floor() as usize).min(LEVELS - 1);
        let fk = (u - k0 as f64).clamp(0.0, 1.0);
        // Direction: the light travels along μ = −d_y; within its hemisphere j + ½ =
        // √|μ| · MU_STEPS, clamped to the outermost entries.
        let mu = -d.y;
        let a = (mu.abs().sqrt() * MU_STEPS as f64 - 0.5).clamp(0.0, (MU_STEPS - 1) as f64);
        let j0 = (a.floor() as usize).min(MU_STEPS - 2);
        let fj = a - j0 as f64;
        let base = if mu < 0.0 { 0 } else { MU_STEPS };
        // Azimuth from the sun's, in the horizontal plane (both views agree: the light's
        // direction and the sun's beam are both reversed).
        let (dh, sh) = (DVec3::new(d.x, 0.0, d.z), DVec3::new(sun.x, 0.0, sun.z));
        let norm = dh.length() * sh.length();
        let cos_phi = if norm > 1e-12 { dh.dot(sh) / norm } else { 1.0 };
        let cos_m = [1.0, cos_phi, 2.0 * cos_phi * cos_phi - 1.0];
        let dirs = 2 * MU_STEPS;
        let mut out = [0.0; 3];
        for (dk, wk) in [(0, 1.0 - fk), (1, fk)] {
            for (dj, wj) in [(0, 1.0 - fj), (1, fj)] {
                let cell = ((k0 + dk) * dirs + base + j0 + dj) * MODES;
                for (m, cm) in cos_m.iter().enumerate() {
                    let v = self.table[cell + m];
                    for c in 0..3 {
                        out[c] += wk * wj * cm * v[c];
                    }
                }
            }
        }
        out
    }

    /// The missing light a view ray `d` from height `y` gathers over its whole length
    /// ([`SkyLight::radiance`]) and over its first `k` metres (module docs), in that order.
    pub fn inscatter(&self, y: f64, d: DVec3, k: f64, sun: DVec3) -> ([f64; 3], [f64; 3]) {
        let whole = self.radiance(y, d, sun);
        let first = if k.is_infinite() {
            whole
        } else if k <= 0.0 {
            [0.0; 3]
        } else {
            let far = self.radiance(y + k * d.y, d, sun);
            let t = self.atmosphere.transparency(y, d.y, k);
            std::array::from_fn(|c| whole[c] - t[c] * far[c])
        };
        (whole, first)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conservative_atmosphere_keeps_the_sunlight() {
        // Albedo 1 everywhere: all the sunlight on the top leaves it again, l_y per unit
        // irradiance; over a black ground what reaches the ground (direct and diffuse) plus
        // what leaves the top is l_y.
        for &(tau, l_y) in &[(0.265, 0.34), (0.05, 0.9), (0.3, 0.07)] {
            let white = solve_channel(tau, l_y, 1.0);
            let out = white.flux_up_top / l_y - 1.0;
            let black = solve_channel(tau, l_y, 0.0);
            let direct = l_y * (-tau / l_y).exp();
            let kept = (black.flux_up_top + black.flux_down_ground + direct) / l_y - 1.0;
            println!(
                "τ* {tau} l_y {l_y}: white ground {out:+.2e}, black ground {kept:+.2e}, \
                      {} / {} orders",
                white.orders, black.orders
            );
            // The linear source across a layer: at dawn (Δτ/l_y = 0.07) 2.9·10⁻⁴.
            assert!(out.abs() < 4e-4 && kept.abs() < 4e-4, "{out} {kept}");
        }
    }

    #[test]
    fn modes_sum_to_the_phase_function() {
        // Σ (2 − δ) P_m cos mφ = p(Θ) with cos Θ = μμ′ + ss′ cos φ.
        for &(mu, mu2, phi) in &[(0.3, -0.7, 0.4), (-0.9, -0.2, 2.5), (0.05, 0.99, 3.1)] {
            let (s, s2) = ((1.0f64 - mu * mu).sqrt(), (1.0f64 - mu2 * mu2).sqrt());
            let cos = mu * mu2 + s * s2 * f64::cos(phi);
            let sum: f64 = (0..MODES)
                .map(|m| {
                    let c = if m == 0 { 1.0 } else { 2.0 };
                    c * rayleigh_mode(m, mu, mu2) * (m as f64 * phi).cos()
                })
                .sum();
            let want = crate::sky::rayleigh_phase(cos);
            assert!((sum - want).abs() < 1e-14, "{sum} vs {want}");
        }
    }
}
