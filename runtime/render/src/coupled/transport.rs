//! The diffuse light by discrete ordinates: the δ-M-scaled transfer equation solved on the voxel
//! grid along a set of directions, by upwind sweeps ([`crate::lattice::sweep`]) and source
//! iteration from the diffusion's P1 radiance (the module docs of [`super`] say where it sits).
//!
//! Per voxel and channel the radiance over the sphere is kept as its real spherical-harmonic
//! moments φ_lm = ∫ I Y_lm dω up to degree [`DEGREE`], which is all the scattering needs of it
//! when p′ is expanded to that degree (the δ-M truncation, Wiscombe 1977): by the addition
//! theorem, (1/4π)∫ p′(ω·ω′) I(ω′) dω′ = Σ_l χ′_l Σ_m Y_lm(ω) φ_lm.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::DensityGrid;
use crate::lattice::sweep;

/// The highest spherical-harmonic degree kept.
pub const DEGREE: usize = 4;
/// Spherical harmonics up to [`DEGREE`]: (L + 1)².
pub const HARMONICS: usize = (DEGREE + 1) * (DEGREE + 1);
/// Moments per voxel: [`HARMONICS`] per channel.
pub const PER_VOXEL: usize = 3 * HARMONICS;

/// The real, orthonormal spherical harmonics Y_lm(ω) for l ≤ 4, ordered l by l and m from −l
/// to l (Sloan 2008, "Stupid spherical harmonics tricks", Appendix A2; x, y, z the unit
/// vector's components with z the polar axis).
pub fn harmonics(w: DVec3) -> [f64; HARMONICS] {
    let (x, y, z) = (w.x, w.y, w.z);
    let (x2, y2, z2) = (x * x, y * y, z * z);
    [
        0.282_094_791_773_878_1,
        0.488_602_511_902_919_9 * y,
        0.488_602_511_902_919_9 * z,
        0.488_602_511_902_919_9 * x,
        1.092_548_430_592_079_2 * x * y,
        1.092_548_430_592_079_2 * y * z,
        0.315_391_565_252_52 * (3.0 * z2 - 1.0),
        1.092_548_430_592_079_2 * x * z,
        0.546_274_215_296_039_6 * (x2 - y2),
        0.590_043_589_926_643_5 * y * (3.0 * x2 - y2),
        2.890_611_442_640_554 * x * y * z,
        0.457_045_799_464_465_8 * y * (5.0 * z2 - 1.0),
        0.373_176_332_590_115_4 * z * (5.0 * z2 - 3.0),
        0.457_045_799_464_465_8 * x * (5.0 * z2 - 1.0),
        1.445_305_721_320_277 * z * (x2 - y2),
        0.590_043_589_926_643_5 * x * (x2 - 3.0 * y2),
        2.503_342_941_796_704_5 * x * y * (x2 - y2),
        1.770_130_769_779_930_5 * y * z * (3.0 * x2 - y2),
        0.946_174_695_757_560_1 * x * y * (7.0 * z2 - 1.0),
        0.669_046_543_557_289_2 * y * z * (7.0 * z2 - 3.0),
        0.105_785_546_915_204_2 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0),
        0.669_046_543_557_289_2 * x * z * (7.0 * z2 - 3.0),
        0.473_087_347_878_78 * (x2 - y2) * (7.0 * z2 - 1.0),
        1.770_130_769_779_930_5 * x * z * (x2 - 3.0 * y2),
        0.625_835_735_449_176_1 * (x2 * (x2 - 3.0 * y2) - y2 * (3.0 * x2 - y2)),
    ]
}

/// The degree l of harmonic k.
pub fn degree_of(k: usize) -> usize {
    (k as f64).sqrt() as usize
}

/// Legendre polynomials P_0 … P_L at μ.
pub fn legendre(mu: f64) -> [f64; DEGREE + 1] {
    let mut p = [0.0; DEGREE + 1];
    p[0] = 1.0;
    if DEGREE > 0 {
        p[1] = mu;
    }
    for l in 1..DEGREE {
        p[l + 1] = ((2 * l + 1) as f64 * mu * p[l] - l as f64 * p[l - 1]) / (l + 1) as f64;
    }
    p
}

/// The δ-M-scaled medium and the diffuse light's fixed sources, per voxel and channel.
pub struct Medium {
    /// σ′_t = β_ext (1 − αf) (1/m).
    pub ext: Vec<[f64; 3]>,
    /// σ′_s = β_sca (1 − f) (1/m).
    pub sca: Vec<[f64; 3]>,
    /// p′'s Legendre moments χ′_0 … χ′_L (χ′_0 = 1).
    pub chi: Vec<[[f64; DEGREE + 1]; 3]>,
    /// The sunlit source's strength q (radiance per metre): Q(ω) = q p′(ω·l).
    pub sun: Vec<[f64; 3]>,
    /// The sun's direction of travel l.
    pub l: DVec3,
    /// The skylit source as P1: Q(ω) = q0 + 3 q1·ω (q0, then q1 x, y, z, per channel).
    pub sky: Vec<[[f64; 4]; 3]>,
}

/// What [`solve`] did: the relative change of φ_00 (green, over the grid) per iteration.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// ‖Δφ_00‖/‖φ_00‖ after each iteration.
    pub changes: Vec<f64>,
}

/// (1/4π)∫ p′ I dω′ towards `y` (the harmonics of ω) from moments `m` with p′'s `chi`.
pub fn scattered(m: &[f64], chi: &[f64; DEGREE + 1], y: &[f64; HARMONICS]) -> f64 {
    (0..HARMONICS)
        .map(|k| chi[degree_of(k)] * y[k] * m[k])
        .sum()
}

/// Source iteration from `start` (moments per voxel, [`PER_VOXEL`]): each round sweeps every
/// direction of `dirs` with the source σ′_s (p′ ∗ I) + Q from the previous round's moments,
/// gathers the new moments (equal weights 4π/N), and lets `accelerate` correct them from the
/// old (diffusion synthetic acceleration); it stops when a round changes φ_00 by less than
/// `tolerance` (relative, rms, green) or after `max_iterations` rounds.
pub fn solve(
    grid: &DensityGrid,
    medium: &Medium,
    start: Vec<[f64; PER_VOXEL]>,
    dirs: &[DVec3],
    (tolerance, max_iterations): (f64, usize),
    mut accelerate: impl FnMut(&[[f64; PER_VOXEL]], &mut [[f64; PER_VOXEL]]),
) -> (Vec<[f64; PER_VOXEL]>, Report) {
    let n = medium.ext.len();
    let weight = 4.0 * PI / dirs.len() as f64;
    let mut m = start;
    let mut report = Report::default();
    for _ in 0..max_iterations {
        let mut next = vec![[0.0f64; PER_VOXEL]; n];
        for &w in dirs {
            let y = harmonics(w);
            let p_sun = legendre(w.dot(medium.l));
            // State: I, σ′_t and the emission S (radiance per metre) per channel. Over a step,
            // σ′_t is the mean of its ends and S linear between them.
            let state = sweep::<9>(grid, w, [0.0; 9], |i, back, ds| {
                let mut out = [0.0; 9];
                for c in 0..3 {
                    let ext = medium.ext[i][c];
                    let chi = &medium.chi[i][c];
                    let moments = &m[i][c * HARMONICS..(c + 1) * HARMONICS];
                    let phase_sun: f64 = (0..=DEGREE)
                        .map(|l| (2 * l + 1) as f64 * chi[l] * p_sun[l])
                        .sum();
                    let sky = medium.sky[i][c];
                    let s_here = medium.sca[i][c] * scattered(moments, chi, &y)
                        + medium.sun[i][c] * phase_sun
                        + sky[0]
                        + 3.0 * (sky[1] * w.x + sky[2] * w.y + sky[3] * w.z);
                    let mean_ext = 0.5 * (ext + back[3 + c]);
                    let tau = mean_ext * ds;
                    let (i_back, s_back) = (back[c], back[6 + c]);
                    out[c] = if tau > 1e-6 {
                        let e = (-tau).exp();
                        let k = (1.0 - e) / tau;
                        i_back * e + (s_here * (1.0 - k) + s_back * (k - e)) / mean_ext
                    } else {
                        i_back * (1.0 - tau) + 0.5 * ds * (s_here + s_back)
                    };
                    out[3 + c] = ext;
                    out[6 + c] = s_here;
                }
                out
            });
            next.par_iter_mut()
                .zip(state.par_iter())
                .for_each(|(m, s)| {
                    for c in 0..3 {
                        let v = weight * s[c];
                        for k in 0..HARMONICS {
                            m[c * HARMONICS + k] += v * y[k];
                        }
                    }
                });
        }
        accelerate(&m, &mut next);
        let (mut d, mut t) = (0.0, 0.0);
        for (a, b) in next.iter().zip(&m) {
            d += (a[HARMONICS] - b[HARMONICS]).powi(2);
            t += a[HARMONICS] * a[HARMONICS];
        }
        let change = (d / t.max(f64::MIN_POSITIVE)).sqrt();
        report.changes.push(change);
        m = next;
        if change < tolerance {
            break;
        }
    }
    (m, report)
}

/// The diffuse light's energy balance per channel (per unit irradiance, m² · radiance · sr):
/// what the sources emit, ∫∫Q dω dV; what leaves through the box's faces, ∮F·n dA with the net
/// flux F = ∫I ω dω = φ_1/Y_1 read at the outermost voxel centres; what is absorbed,
/// ∫σ_a ∫I dω dV. Scattering moves light between directions only (p′ is normalized), so a
/// converged solution has source = out + absorbed up to the discretization (the face read half
/// a voxel inside, the sweeps' interpolation).
#[derive(Debug, Clone, Copy, Default)]
pub struct Balance {
    /// ∫∫Q dω dV.
    pub source: f64,
    /// ∮F·n dA.
    pub out: f64,
    /// ∫σ_a ∫I dω dV.
    pub absorbed: f64,
}

/// [`Balance`] of `moments` (per voxel, [`PER_VOXEL`]) in `medium` on `grid`, per channel.
pub fn balance(grid: &DensityGrid, medium: &Medium, moments: &[[f64; PER_VOXEL]]) -> [Balance; 3] {
    let dims = grid.dims;
    let h: [f64; 3] = std::array::from_fn(|a| (grid.max_m[a] - grid.min_m[a]) / dims[a] as f64);
    let volume = h[0] * h[1] * h[2];
    let y1 = 0.488_602_511_902_919_9;
    let root = (4.0 * PI).sqrt();
    let mut out = [Balance::default(); 3];
    for (i, m) in moments.iter().enumerate() {
        let cell = [
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        ];
        for (c, b) in out.iter_mut().enumerate() {
            let o = c * HARMONICS;
            let sky = medium.sky[i][c];
            b.source += 4.0 * PI * (medium.sun[i][c] + sky[0]) * volume;
            b.absorbed += (medium.ext[i][c] - medium.sca[i][c]) * root * m[o] * volume;
            // Net flux per axis: φ_1m is (y, z, x) for m = −1, 0, 1.
            let flux = [m[o + 3] / y1, m[o + 1] / y1, m[o + 2] / y1];
            for a in 0..3 {
                let area = volume / h[a];
                if cell[a] == 0 {
                    b.out -= flux[a] * area;
                }
                if cell[a] + 1 == dims[a] {
                    b.out += flux[a] * area;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_harmonics_are_orthonormal() {
        let dirs = crate::lattice::fibonacci_directions(20_000);
        let w = 4.0 * PI / dirs.len() as f64;
        let mut gram = [[0.0; HARMONICS]; HARMONICS];
        for d in &dirs {
            let y = harmonics(*d);
            for a in 0..HARMONICS {
                for b in 0..HARMONICS {
                    gram[a][b] += w * y[a] * y[b];
                }
            }
        }
        for a in 0..HARMONICS {
            for b in 0..HARMONICS {
                let want = if a == b { 1.0 } else { 0.0 };
                assert!(
                    (gram[a][b] - want).abs() < 1e-3,
                    "∫Y_{a} Y_{b} = {} (want {want})",
                    gram[a][b]
                );
            }
        }
    }

    #[test]
    fn the_addition_theorem_holds() {
        // Σ_m Y_lm(a) Y_lm(b) = (2l + 1)/(4π) P_l(a·b).
        let (a, b) = (
            DVec3::new(0.3, -0.5, 0.81).normalize(),
            DVec3::new(-0.7, 0.2, 0.4).normalize(),
        );
        let (ya, yb) = (harmonics(a), harmonics(b));
        let p = legendre(a.dot(b));
        for l in 0..=DEGREE {
            let sum: f64 = (l * l..(l + 1) * (l + 1)).map(|k| ya[k] * yb[k]).sum();
            let want = (2 * l + 1) as f64 / (4.0 * PI) * p[l];
            assert!((sum - want).abs() < 1e-12, "l {l}: {sum} vs {want}");
        }
    }
}
