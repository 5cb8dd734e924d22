//! Riley et al. 2004 §4.1: single-scattering sky and aerial perspective over a flat earth with
//! an exponential atmosphere, in closed form (Eqs. 9–15). Heights y are metres above sea level.
//!
//! Eq. 15 as printed omits the factor exp(−β_eye/(γ p_y)) of the eye transparency (Eq. 11 at
//! u = 1); [`inscatter`] integrates Eq. 14 exactly and is checked against quadrature of Eq. 14
//! in the tests. Written with u = e^{−γ p_y K}:
//!
//! L = I_s P_air · l_y · e^{E₂} · (e^{q (p_y − l_y)} − 1)/(p_y − l_y),
//! q = (β_eye/γ)(1 − u)/(p_y l_y), E₂ = −β_eye/(γ l_y),
//!
//! which stays finite as p_y → l_y (the limit is q) and as p_y → 0 ((1 − u)/p_y → γK).

use std::f64::consts::PI;

/// Sea-level Rayleigh scattering coefficients at 680, 550, 440 nm (Riley et al. 2004 Table 3).
pub const BETA_SEA_LEVEL_PER_M: [f64; 3] = [5.8e-6, 1.35e-5, 3.31e-5];
/// Scale height 1/γ (Riley et al. 2004 §4.1.1).
pub const SCALE_HEIGHT_M: f64 = 8000.0;

/// The atmosphere of the analytic sky model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Atmosphere {
    /// β_sl per channel (1/m); all zero switches the sky and aerial perspective off.
    pub beta_sea_level_per_m: [f64; 3],
    /// 1/γ (m).
    pub scale_height_m: f64,
}

impl Default for Atmosphere {
    fn default() -> Self {
        Self {
            beta_sea_level_per_m: BETA_SEA_LEVEL_PER_M,
            scale_height_m: SCALE_HEIGHT_M,
        }
    }
}

/// Rayleigh phase function (Eq. 1), 1/sr.
pub fn rayleigh_phase(cos_theta: f64) -> f64 {
    3.0 / (16.0 * PI) * (1.0 + cos_theta * cos_theta)
}

/// (1 − e^{−γ p K})/p, finite for p → 0 (→ γK) and for K = ∞ with p > 0 (→ 1/p).
pub(crate) fn one_minus_u_over_p(gamma: f64, p_y: f64, k: f64) -> f64 {
    let x = gamma * p_y * k;
    if x.abs() < 1e-8 {
        gamma * k
    } else if k.is_infinite() {
        if p_y > 0.0 { 1.0 / p_y } else { f64::INFINITY }
    } else {
        -(-x).exp_m1() / p_y
    }
}

impl Atmosphere {
    fn gamma(&self) -> f64 {
        1.0 / self.scale_height_m
    }

    /// Transparency from height `y` along direction component `p_y` over distance `k`
    /// (Eq. 11), per channel.
    pub fn transparency(&self, y: f64, p_y: f64, k: f64) -> [f64; 3] {
        let g = self.gamma();
        let path = one_minus_u_over_p(g, p_y, k);
        std::array::from_fn(|c| {
            let beta_eye = self.beta_sea_level_per_m[c] * (-g * y).exp();
            if beta_eye == 0.0 {
                1.0
            } else {
                (-beta_eye / g * path).exp()
            }
        })
    }

    /// Sunlight reaching height `y` with the sun at `l_y` = sin(elevation) > 0 (Eq. 12), as a
    /// fraction of the light outside the atmosphere.
    pub fn sunlight(&self, y: f64, l_y: f64) -> [f64; 3] {
        let g = self.gamma();
        std::array::from_fn(|c| (-self.beta_sea_level_per_m[c] / (g * l_y) * (-g * y).exp()).exp())
    }

    /// Light scattered towards an eye at height `y` looking along a ray with vertical
    /// component `p_y`, from the first `k` metres of the ray (Eq. 14 integrated; module docs),
    /// per unit solar irradiance and channel. `cos_sun` is the cosine of the angle between the
    /// ray and the direction towards the sun; `l_y` > 0 the sun's vertical component.
    pub fn inscatter(&self, y: f64, p_y: f64, k: f64, l_y: f64, cos_sun: f64) -> [f64; 3] {
        let g = self.gamma();
        let phase = rayleigh_phase(cos_sun);
        let path = one_minus_u_over_p(g, p_y, k);
        std::array::from_fn(|c| {
            let beta_eye = self.beta_sea_level_per_m[c] * (-g * y).exp();
            if beta_eye == 0.0 || k <= 0.0 {
                return 0.0;
            }
            let q = beta_eye / g * path / l_y;
            let e2 = -beta_eye / (g * l_y);
            let eps = p_y - l_y;
            let factor = if (q * eps).abs() < 1e-9 {
                q
            } else {
                (q * eps).exp_m1() / eps
            };
            phase * l_y * e2.exp() * factor
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eq. 14 by the midpoint rule in K (the integrand is smooth).
    fn quadrature(atm: &Atmosphere, y: f64, p_y: f64, k: f64, l_y: f64, cos: f64) -> [f64; 3] {
        let steps = 200_000;
        let dk = k / steps as f64;
        let mut sum = [0.0; 3];
        for i in 0..steps {
            let kk = (i as f64 + 0.5) * dk;
            let t_eye = atm.transparency(y, p_y, kk);
            let y_s = y + p_y * kk;
            let sun = atm.sunlight(y_s, l_y);
            let g = 1.0 / atm.scale_height_m;
            for c in 0..3 {
                let beta = atm.beta_sea_level_per_m[c] * (-g * y_s).exp();
                sum[c] += t_eye[c] * beta * sun[c] * dk;
            }
        }
        sum.map(|s| s * rayleigh_phase(cos))
    }

    #[test]
    fn closed_form_matches_quadrature_of_eq_14() {
        let atm = Atmosphere::default();
        // Up, down, horizontal, and along the sun's own elevation (p_y = l_y).
        for &(y, p_y, k, l_y) in &[
            (100.0, 0.3, 40_000.0, 0.5),
            (3000.0, -0.1, 20_000.0, 0.2),
            (0.0, 0.0, 50_000.0, 0.05),
            (500.0, 0.2, 30_000.0, 0.2),
            (9000.0, -0.5, 15_000.0, 0.9),
        ] {
            let exact = atm.inscatter(y, p_y, k, l_y, 0.3);
            let numeric = quadrature(&atm, y, p_y, k, l_y, 0.3);
            for c in 0..3 {
                let rel = (exact[c] - numeric[c]).abs() / numeric[c];
                assert!(
                    rel < 1e-6,
                    "y {y} p {p_y} K {k} l {l_y} ch {c}: {exact:?} vs {numeric:?}"
                );
            }
        }
    }

    #[test]
    fn transparency_and_sunlight_limits() {
        let atm = Atmosphere::default();
        // Horizontal at sea level: T = exp(−β K).
        let t = atm.transparency(0.0, 0.0, 10_000.0);
        for c in 0..3 {
            let want = (-BETA_SEA_LEVEL_PER_M[c] * 10_000.0).exp();
            assert!((t[c] - want).abs() < 1e-12, "{t:?}");
        }
        // Straight up to infinity: T = exp(−β/γ), the sunlight at the zenith.
        let up = atm.transparency(0.0, 1.0, f64::INFINITY);
        let sun = atm.sunlight(0.0, 1.0);
        for c in 0..3 {
            assert!((up[c] - sun[c]).abs() < 1e-12);
        }
        // Blue is dimmed more than red at dawn.
        let dawn = atm.sunlight(0.0, 0.07);
        assert!(dawn[2] < 0.1 * dawn[0], "{dawn:?}");
    }
}
