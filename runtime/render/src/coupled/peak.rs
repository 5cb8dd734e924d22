//! The forward peak's blur of the beam's single scattering (step 4 of the [module docs](super)).
//!
//! The δ-split keeps the forward peak's share f of each extinction in the beam as if it were
//! unscattered, and the gather sees the light through β_ext(1 − αf) as well. What the peak
//! scatters still travels on, but each such scattering turns it by the peak's width: for the
//! 10 µm droplets' diffraction lobe ~1° (half width 0.68°), enough to wash out the glory's
//! rings, 0.5° apart. The truth shows it (the glory's first ring +6.7 % over its minimum, sky
//! off +9.2 %); the beam scattered by the exact Ams_1 did not (+10.3 %, +13.8 %).
//!
//! So the sun's single scattering is taken with the phase function blurred by the peak
//! scatterings along the way in (the beam) and out (the eye's ray). Per field and channel the
//! peak is fitted by a Gaussian in θ of the Ams_1 table's half width θ_h at half its forward
//! maximum, q(θ) ∝ e^{−θ²/σ²}, σ² = θ_h²/ln 2 (small angles), whose Legendre moments are
//! π_l = e^{−l(l+1)σ²/4} (the heat kernel on the sphere). After k peak scatterings the light
//! is blurred by q^{∗k}, moments π_l^k (Funk–Hecke); with the peak's optical depth D along
//! the path the count is Poisson (Max et al. 2004 Eq. 8's count, of the peak alone), and the
//! mixture's moments are Σ_k e^{−D} D^k/k! π_l^k = e^{−D(1 − π_l)}. The blurred phase function
//! (Legendre moments χ_l of p):
//!
//!   p^{(D)}(θ) = e^{−D} p(θ) + Σ_l (2l + 1)/4π χ_l (e^{−D(1 − π_l)} − e^{−D}) P_l(cos θ),
//!
//! exact p at D = 0 and the unblurred share e^{−D} kept in the samples, so the sum's
//! truncation at the table's resolution (l ≤ 1.2 · 180°/Δθ) rings nowhere; every term keeps
//! ∫p dΩ (the l = 0 term's e^{−D(1 − π_0)} = 1). D adds along the way in and out
//! (e^{−D₁(1−π)} e^{−D₂(1−π)}), tabulated at D_j = j/4, j < 41, linear between, the last row
//! beyond (for the cloud D = 10 is τ ≈ 27 along the beam, which has kept e^{−(1 − αf)τ} ≈
//! e^{−12} of the sun there).
//!
//! D is the optical depth of the peak's scattering, ∫ β_sca s ds, s the share of the
//! scattering the Gaussian holds: its integral (p(0) − p(3θ_h)) π σ² over ∫ p dΩ (above the
//! phase function three half widths out), at most the split's f. For the 10 µm droplets s =
//! 0.37 (a large droplet's Airy central lobe holds 0.42 of its scattering), against δ-M's
//! f = χ_5 ≈ 0.56, which holds the scattering within ~12° (measured: D at χ_5 over-blurred
//! the rings by ~13 %). A peak narrower than two of the table's samples (rain, 0.11°; ice,
//! 0.12°) is not resolved by them and is not blurred (s = 0): a blur narrower than the table's
//! step does not show; nor is a lobe wider than 10°.
//!
//! **The cone.** The Gaussian holds the diffraction lobe, not all of δ-M's f: the samples
//! from three half widths out to where the samples from θ = 0 hold f (for the 10 µm droplets
//! 2°–11.5°, a share c = 0.14 of the scattering) are scattered by the split as unscattered
//! too, and turn the light by several degrees — enough to soften the fogbow's 4° bow (the
//! truth's contrast +31.9 %; blurred by the Gaussian alone +36.4 %). Their normalized samples
//! are a second kernel, moments π^c_l, counted like the peak at the depth rD, r = c/s, so the
//! two blurs together have moments e^{−D(1 − π_l)} e^{−rD(1 − π^c_l)}. But the cone blurs
//! only p's backward part w(θ) p, w a smoothstep from 0 at 90° to 1 at 120°
//! ([`CONE_RAMP_DEG`]); the forward part (1 − w) p is blurred by the Gaussian alone:
//!
//!   p^{(D)} = e^{−D} (1 − w) p + e^{−(1 + r)D} w p
//!           + Σ_l (2l + 1)/4π [χ^f_l (e^{−D(1 − π_l)} − e^{−D})
//!                             + χ^b_l (e^{−D(1 − π_l)} e^{−rD(1 − π^c_l)} − e^{−(1 + r)D})] P_l,
//!
//! χ^f_l, χ^b_l the moments of the two parts. Why not the whole of p: the blur assumes the
//! light a turn takes out of a line is given back from the lines beside it; where the forward
//! lobe is seen (the views towards the sun) a ball's limb has no lines beside it, and blurring
//! all of p brightened the soft ball's forward views at τ 8 / 32 from +2.3 / +4.5 % to +7.8 /
//! +20.4 % against the truth, the excess at the limb nearest the sun. Beyond 90° p is smooth
//! on the cone's scale but for the bows and glories whose softening the blur is for, and the
//! forward views do not see it. Measured (docs/models/coupled.md): the fogbow +32.9 % against the
//! truth's +31.9 %, the glory's rings +6.6 % against +6.7 %, every soft-ball case within
//! 0.4 point of the Gaussian's alone.
//!
//! Tried and not kept: the peak as the phase function itself over the forward cone that holds
//! f (11.7° for the cloud), in place of the Gaussian, blurred at D = ∫ β_sca f ds — the fogbow
//! came right (+32.8 %) but the cone's light spread from the forward lobe brightened the views
//! towards the sun (the soft ball's forward view at τ 8 / 32 / 64: +8.1 / +20.9 / +30.8 %
//! against the Gaussian's +2.4 / +4.7 / +6.9 %).

use std::f64::consts::PI;

use rayon::prelude::*;

use runtime::FieldTable;

/// The step of the tabulated peak depths D_j = j · DEPTH_STEP.
pub const DEPTH_STEP: f64 = 0.25;
/// How many peak depths are tabulated (D = 0 … 10).
pub const DEPTHS: usize = 41;

/// One field's blur: its peak's fit and the blurred phase function per depth.
#[derive(Debug, Clone)]
pub struct FieldBlur {
    /// The forward lobe's half width at half maximum per channel (degrees); 0 where the
    /// table does not resolve it.
    pub half_width_deg: [f64; 3],
    /// The share s of the scattering the peak holds per channel; 0 where not resolved.
    pub share: [f64; 3],
    /// The cone's share of the scattering per channel (the samples past the peak that hold
    /// the rest of the split's f); 0 where not blurred.
    pub cone_share: [f64; 3],
    /// p^{(D_j)}(θ_k) at `[(j · 3 + c) · K + k]` (1/sr).
    table: Vec<f64>,
}

/// Every field's [`FieldBlur`] on the tables' angle grid.
#[derive(Debug, Clone)]
pub struct PeakBlur {
    /// Per field, in the tables' order.
    pub fields: Vec<FieldBlur>,
    /// K, the samples θ_k = k Δθ per row.
    pub angle_count: usize,
    /// Δθ (degrees).
    pub theta_step_deg: f64,
}

impl PeakBlur {
    /// The blur of each field of `fields` (Ams_1 on `theta_step_deg`), the share at most
    /// `split[f]`, the δ-split's forward peak f of field f.
    pub fn of(fields: &[&FieldTable], theta_step_deg: f64, split: &[[f64; 3]]) -> Self {
        let angle_count = fields.first().map_or(0, |f| f.image.angle_count());
        let fields = fields
            .iter()
            .zip(split)
            .map(|(field, &cap)| FieldBlur::of(field, theta_step_deg, cap, CONE_RAMP_DEG))
            .collect();
        Self {
            fields,
            angle_count,
            theta_step_deg,
        }
    }

    /// Whether any field's peak is blurred (its share above 0 in some channel).
    pub fn blurs(&self) -> bool {
        self.fields.iter().any(|b| b.share.iter().any(|&s| s > 0.0))
    }

    /// The peak's scattering coefficient per unit of `rho` (green), Σ ρ_f σ_sca,f s_f: its
    /// product with a path length is the peak depth D.
    pub fn coefficient(&self, fields: &[&FieldTable], rho: &[f64]) -> f64 {
        fields
            .iter()
            .zip(&self.fields)
            .zip(rho)
            .filter(|&(_, &r)| r > 0.0)
            .map(|((field, blur), &r)| r * field.sigma_sca_m2[1] * blur.share[1])
            .sum()
    }

    /// p^{(D)}(θ) of the mixture at densities `rho` (weighted as [`runtime::sample::mix`]),
    /// linear in θ and D.
    pub fn phase(
        &self,
        fields: &[&FieldTable],
        rho: &[f64],
        depth: f64,
        cos_theta: f64,
    ) -> [f64; 3] {
        let k_len = self.angle_count;
        let (k0, t) = runtime::sample::column(self.theta_step_deg, k_len, cos_theta);
        let v = (depth.max(0.0) / DEPTH_STEP).min((DEPTHS - 1) as f64);
        let j0 = (v.floor() as usize).min(DEPTHS - 2);
        let s = v - j0 as f64;
        runtime::sample::scattering_weighted(fields, rho, 0.0, |f| {
            let blur = &self.fields[f];
            std::array::from_fn(|c| {
                let at = |j: usize| {
                    let row = &blur.table[(j * 3 + c) * k_len..];
                    row[k0] * (1.0 - t) + row[k0 + 1] * t
                };
                at(j0) * (1.0 - s) + at(j0 + 1) * s
            })
        })
    }

    /// Per field of `fields` whose peak is blurred (green): its name, the peak's half width
    /// (degrees), its share of the scattering and the cone's.
    pub fn report(&self, fields: &[&FieldTable]) -> Vec<(String, f64, f64, f64)> {
        fields
            .iter()
            .zip(&self.fields)
            .filter(|(_, b)| b.share[1] > 0.0)
            .map(|(f, b)| {
                (
                    f.name.clone(),
                    b.half_width_deg[1],
                    b.share[1],
                    b.cone_share[1],
                )
            })
            .collect()
    }

    /// The tables as the GPU gather reads them, `[((f · DEPTHS + j) · 3 + c) · K + k]`.
    pub fn rows(&self) -> Vec<f32> {
        self.fields
            .iter()
            .flat_map(|b| b.table.iter().map(|&v| v as f32))
            .collect()
    }
}

/// δ-M's forward cone past the peak: per channel, the samples from three half widths out to
/// where the samples from θ = 0 hold the share `cap` of the scattering, their share of it and
/// their kernel's Legendre moments π^c_l to `degree` (channels without a peak blur, `share`
/// 0, have none); `step` is the samples' spacing in θ (radians).
fn cone(
    p: &[Vec<f64>; 3],
    weight: &[f64],
    mu: &[f64],
    (share, total, half_width): (&[f64; 3], &[f64; 3], &[Option<f64>; 3]),
    (cap, step): ([f64; 3], f64),
    degree: usize,
) -> ([f64; 3], Vec<[f64; 3]>) {
    let k_len = mu.len();
    let mut cone_share = [0.0; 3];
    let mut cone_moments = vec![[0.0; 3]; degree + 1];
    for c in 0..3 {
        if share[c] <= 0.0 {
            continue;
        }
        let first = (3.0 * half_width[c].unwrap_or(0.0) / step).ceil() as usize;
        let mut held = 0.0;
        let mut window = Vec::new();
        for k in 0..k_len {
            let w = 2.0 * PI * weight[k] * p[c][k];
            if held >= cap[c] * total[c] {
                break;
            }
            held += w;
            if k >= first {
                window.push((k, w));
            }
        }
        let mass: f64 = window.iter().map(|&(_, w)| w).sum();
        if mass <= 0.0 {
            continue;
        }
        cone_share[c] = mass / total[c];
        for &(k, w) in &window {
            legendre(mu[k], degree, |l, pl| cone_moments[l][c] += w / mass * pl);
        }
    }
    (cone_share, cone_moments)
}

/// The moments c_l = 2π ∫ p P_l sin θ dθ to `degree` of p's forward part (1 − w) p and backward
/// part w p (w the `ramp`), per channel, by the trapezoid `weight`s in θ at the samples' `mu`.
fn part_moments(
    p: &[Vec<f64>; 3],
    weight: &[f64],
    mu: &[f64],
    ramp: &[f64],
    degree: usize,
) -> Vec<[[f64; 3]; 2]> {
    let k_len = mu.len();
    (0..k_len)
        .into_par_iter()
        .fold(
            || vec![[[0.0; 3]; 2]; degree + 1],
            |mut acc, k| {
                legendre(mu[k], degree, |l, pl| {
                    for c in 0..3 {
                        let v = 2.0 * PI * weight[k] * p[c][k] * pl;
                        acc[l][0][c] += (1.0 - ramp[k]) * v;
                        acc[l][1][c] += ramp[k] * v;
                    }
                });
                acc
            },
        )
        .reduce(
            || vec![[[0.0; 3]; 2]; degree + 1],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    for (xs, ys) in x.iter_mut().zip(y) {
                        for c in 0..3 {
                            xs[c] += ys[c];
                        }
                    }
                }
                a
            },
        )
}

impl FieldBlur {
    /// `ramp_deg`: where the cone's blur comes in ([`CONE_RAMP_DEG`]; (0, 0) blurs all of p).
    fn of(field: &FieldTable, theta_step_deg: f64, cap: [f64; 3], ramp_deg: (f64, f64)) -> Self {
        let k_len = field.image.angle_count();
        let ams = &field.image.ams;
        let p: [Vec<f64>; 3] =
            std::array::from_fn(|c| (0..k_len).map(|k| ams[[c, 0, k]]).collect());
        let step = theta_step_deg.to_radians();
        let half_width = p.each_ref().map(|p| half_width(p, step));
        let degree = (1.2 * PI / step).round() as usize;
        let mu: Vec<f64> = (0..k_len).map(|k| (k as f64 * step).cos()).collect();
        // The trapezoid's weights in θ, sin θ dθ (2π of dΩ left out of both sums).
        let weight: Vec<f64> = (0..k_len)
            .map(|k| {
                let end = if k == 0 || k == k_len - 1 { 0.5 } else { 1.0 };
                end * (k as f64 * step).sin() * step
            })
            .collect();
        let mut share = [0.0; 3];
        let mut sigma2 = [0.0; 3];
        let mut total = [0.0; 3];
        for c in 0..3 {
            let Some(h) = half_width[c] else { continue };
            total[c] = p[c].iter().zip(&weight).map(|(v, w)| v * w).sum::<f64>() * 2.0 * PI;
            let s2 = h * h / std::f64::consts::LN_2;
            let edge = sample_at(&p[c], 3.0 * h / step);
            sigma2[c] = s2;
            share[c] = ((p[c][0] - edge) * PI * s2 / total[c]).clamp(0.0, cap[c].max(0.0));
        }
        let blurred = share.iter().any(|&s| s > 0.0);
        // The cone: the samples from three half widths out to where the samples from θ = 0
        // hold the split's f, its share of the scattering and its kernel's moments π^c_l.
        let (from, to) = (ramp_deg.0.to_radians(), ramp_deg.1.to_radians());
        let (cone_share, cone_moments) = if blurred {
            cone(
                &p,
                &weight,
                &mu,
                (&share, &total, &half_width),
                (cap, step),
                degree,
            )
        } else {
            ([0.0; 3], Vec::new())
        };
        // p's forward part (1 − w) p and backward part w p, w the ramp from `from` to `to`:
        // only the backward part is blurred by the cone (the module docs say why).
        let ramp: Vec<f64> = (0..k_len)
            .map(|k| {
                let x =
                    ((k as f64 * step - from) / (to - from).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
                x * x * (3.0 - 2.0 * x)
            })
            .collect();
        // The moments c_l = 2π ∫ p P_l sin θ dθ of each part, per channel ([forward, backward]).
        let moments = if blurred {
            part_moments(&p, &weight, &mu, &ramp, degree)
        } else {
            Vec::new()
        };
        // The cone's depth per unit of the peak's, D_c = r D.
        let ratio: [f64; 3] = std::array::from_fn(|c| {
            if share[c] > 0.0 {
                cone_share[c] / share[c]
            } else {
                0.0
            }
        });
        // a[l][j][c] = (2l + 1)/4π (c_l^fwd (G − e^{−D}) + c_l^back (G C − e^{−D(1 + r)})),
        // G = e^{−D(1 − π_l)} the peak's blur, C = e^{−rD(1 − π^c_l)} the cone's.
        let coefficient = |l: usize, j: usize, c: usize| {
            if share[c] <= 0.0 {
                return 0.0;
            }
            let d = j as f64 * DEPTH_STEP;
            let pi_l = (-((l * (l + 1)) as f64) * sigma2[c] / 4.0).exp();
            let g = (-d * (1.0 - pi_l)).exp();
            let cone = (-ratio[c] * d * (1.0 - cone_moments[l][c])).exp();
            let [fwd, back] = moments[l];
            (2 * l + 1) as f64 / (4.0 * PI)
                * (fwd[c] * (g - (-d).exp()) + back[c] * (g * cone - (-d * (1.0 + ratio[c])).exp()))
        };
        let a: Vec<f64> = if blurred {
            (0..=degree)
                .flat_map(|l| (0..DEPTHS).flat_map(move |j| (0..3).map(move |c| (l, j, c))))
                .map(|(l, j, c)| coefficient(l, j, c))
                .collect()
        } else {
            Vec::new()
        };
        // Each sample's column of the table: e^{−D_j} p + Σ_l a[l][j][c] P_l(μ_k).
        let columns: Vec<Vec<f64>> = (0..k_len)
            .into_par_iter()
            .map(|k| {
                let mut col: Vec<f64> = (0..DEPTHS * 3)
                    .map(|jc| {
                        let (j, c) = (jc / 3, jc % 3);
                        if share[c] <= 0.0 {
                            return p[c][k];
                        }
                        let d = j as f64 * DEPTH_STEP;
                        (-d).exp() * (1.0 - ramp[k]) * p[c][k]
                            + (-d * (1.0 + ratio[c])).exp() * ramp[k] * p[c][k]
                    })
                    .collect();
                if blurred {
                    legendre(mu[k], degree, |l, pl| {
                        let row = &a[l * DEPTHS * 3..(l + 1) * DEPTHS * 3];
                        for (v, &x) in col.iter_mut().zip(row) {
                            *v += x * pl;
                        }
                    });
                }
                col
            })
            .collect();
        let mut table = vec![0.0; DEPTHS * 3 * k_len];
        for (k, col) in columns.iter().enumerate() {
            for (jc, &v) in col.iter().enumerate() {
                table[jc * k_len + k] = v;
            }
        }
        Self {
            half_width_deg: half_width.map(|h| h.map_or(0.0, f64::to_degrees)),
            share,
            cone_share,
            table,
        }
    }

    /// p^{(D_j)}(θ_k) of channel `c`, the K samples of depth row `j`.
    pub fn row(&self, j: usize, c: usize) -> &[f64] {
        let k_len = self.table.len() / (DEPTHS * 3);
        &self.table[(j * 3 + c) * k_len..(j * 3 + c + 1) * k_len]
    }
}

/// The forward lobe's half width at half its maximum p(0) (radians), linear between the
/// samples `step` apart; `None` where p does not fall to half within [`MAX_PEAK_DEG`] (a broad
/// lobe, which the transport's degree resolves, or none) or falls within two samples (a peak
/// the samples do not resolve).
fn half_width(p: &[f64], step: f64) -> Option<f64> {
    if p.len() < 2 || p[0] <= 0.0 {
        return None;
    }
    let half = 0.5 * p[0];
    let k = p.iter().position(|&v| v <= half)?;
    let h = (k as f64 - (half - p[k]) / (p[k - 1] - p[k])) * step;
    (h >= 2.0 * step && h <= MAX_PEAK_DEG.to_radians()).then_some(h)
}

/// The widest forward lobe taken for a peak (degrees): the transport's degree-4 phase function
/// p′ holds lobes of a few tens of degrees; a peak is what it cannot hold.
const MAX_PEAK_DEG: f64 = 10.0;

/// The scattering angles (degrees) over which the cone's blur comes in: none of p below the
/// first, all of it beyond the second, a smoothstep between (the module docs say why).
pub const CONE_RAMP_DEG: (f64, f64) = (90.0, 120.0);

/// p at the fractional sample index `u`, linear between samples.
fn sample_at(p: &[f64], u: f64) -> f64 {
    let k0 = (u.floor() as usize).min(p.len() - 2);
    let t = (u - k0 as f64).min(1.0);
    p[k0] * (1.0 - t) + p[k0 + 1] * t
}

/// Calls `each(l, P_l(μ))` for l = 0 … `degree` (the upward recurrence, stable for |μ| ≤ 1).
pub(super) fn legendre(mu: f64, degree: usize, mut each: impl FnMut(usize, f64)) {
    let (mut prev, mut cur) = (1.0, mu);
    each(0, 1.0);
    if degree >= 1 {
        each(1, mu);
    }
    for l in 1..degree {
        let next = ((2 * l + 1) as f64 * mu * cur - l as f64 * prev) / (l + 1) as f64;
        (prev, cur) = (cur, next);
        each(l + 1, cur);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A field whose Ams_1 is `p(θ)` (θ in radians) in every channel on a 0.18° grid.
    pub(crate) fn field(p: impl Fn(f64) -> f64) -> FieldTable {
        let step = 0.18;
        let k_len = 1001;
        let ams = ndarray::Array3::from_shape_fn((3, 1, k_len), |(_, _, k)| {
            p((k as f64 * step).to_radians())
        });
        FieldTable {
            name: "peak".into(),
            kind: format::FieldKind::Cloud,
            image: format::FieldImage {
                field: "peak".into(),
                theta_step_deg: step,
                ams,
                forward_fraction: ndarray::Array2::from_elem((3, 1), 0.9),
                extra_layers: Vec::new(),
            },
            sigma_sca_m2: [1.0; 3],
            sigma_ext_m2: [1.0; 3],
            albedo: [1.0; 3],
            single: None,
            poisson: None,
            transport_factor: None,
            biri: None,
        }
    }

    /// The small-angle Gaussian of variance `v` (rad²) normalized over the sphere, e^{−θ²/v}/πv.
    fn gaussian(v: f64, theta: f64) -> f64 {
        (-theta * theta / v).exp() / (PI * v)
    }

    /// ∫ f dΩ over the samples by the trapezoid in θ.
    fn integral(f: &[f64]) -> f64 {
        let step = 0.18f64.to_radians();
        let n = f.len();
        (0..n)
            .map(|k| {
                let end = if k == 0 || k == n - 1 { 0.5 } else { 1.0 };
                2.0 * PI * end * f[k] * (k as f64 * step).sin() * step
            })
            .sum()
    }

    #[test]
    fn a_gaussian_peak_is_blurred_as_a_poisson_count_of_its_own_convolutions() {
        // Half the scattering in a Gaussian peak of variance σ² = (1°)², half isotropic.
        let s2 = 1f64.to_radians().powi(2);
        let p = |t: f64| 0.5 * gaussian(s2, t) + 0.5 / (4.0 * PI);
        let f = field(p);
        let blur = PeakBlur::of(&[&f], 0.18, &[[0.6; 3]]);
        let b = &blur.fields[0];
        let h = s2.sqrt() * std::f64::consts::LN_2.sqrt();
        let fit = b.half_width_deg[1].to_radians().powi(2) / std::f64::consts::LN_2;
        // The fit: half width and share of the peak.
        assert!(
            (b.half_width_deg[1] / h.to_degrees() - 1.0).abs() < 0.01,
            "{b:?}"
        );
        assert!(
            (b.share[1] / 0.5 - 1.0).abs() < 0.02,
            "share {}",
            b.share[1]
        );
        let mut worst = 0.0f64;
        for j in [0, 2, 8, 40] {
            let depth = j as f64 * DEPTH_STEP;
            let row = b.row(j, 1);
            // After k peak scatterings the peak's light has variance σ² + k σ²_fit, k Poisson
            // about D: the blur's prediction in closed form, without the Legendre sum.
            let expect = |t: f64| {
                let mut weight = (-depth).exp();
                let mut sum = 0.0;
                for k in 0..80 {
                    sum += weight * gaussian(s2 + k as f64 * fit, t);
                    weight *= depth / (k + 1) as f64;
                }
                0.5 * sum + 0.5 / (4.0 * PI)
            };
            for (k, &v) in row.iter().enumerate().take(40) {
                let t = (k as f64 * 0.18).to_radians();
                worst = worst.max((v / expect(t) - 1.0).abs());
            }
            // The blur keeps ∫ p dΩ, but for the Legendre sum's quadrature (measured: at most
            // 8.0·10⁻⁴, at D = 2).
            let energy = integral(row) / integral(b.row(0, 1)) - 1.0;
            assert!(energy.abs() < 1e-3, "D = {depth}: energy {energy:e}");
        }
        // Measured: 6.2·10⁻³, the peak at D = 2 (the moments' trapezoid over 0.18° samples).
        assert!(worst < 7e-3, "worst relative difference {worst:e}");
    }

    #[test]
    fn the_cone_blurs_the_backward_part_alone_as_its_kernel_convolved_on_the_sphere() {
        // A 1° peak (0.4), a 6° cone (0.4), a 5° ring at 140° (0.05) and the rest isotropic;
        // the split's f 0.75 ends the cone's window inside the 6° lobe.
        let (s2, cone2) = (1f64.to_radians().powi(2), 6f64.to_radians().powi(2));
        let (at, wide) = (140f64.to_radians(), 5f64.to_radians());
        let ring =
            |t: f64| (-((t - at) / wide).powi(2)).exp() / (2.0 * PI * at.sin() * wide * PI.sqrt());
        let p = |t: f64| {
            0.4 * gaussian(s2, t) + 0.4 * gaussian(cone2, t) + 0.05 * ring(t) + 0.15 / (4.0 * PI)
        };
        let f = field(p);
        let cap = [0.75; 3];
        let ramped = FieldBlur::of(&f, 0.18, cap, CONE_RAMP_DEG);
        let none = FieldBlur::of(&f, 0.18, cap, (360.0, 360.0));
        assert_eq!(none.cone_share, ramped.cone_share);
        let (share, cone) = (ramped.share[1], ramped.cone_share[1]);
        assert!(share > 0.3 && cone > 0.2, "shares {share} {cone}");
        let step = 0.18f64.to_radians();
        // The cone's window and kernel as the blur takes them: from three half widths out to
        // where the samples hold f (trapezoid weights in θ).
        let first = (3.0 * ramped.half_width_deg[1] / 0.18).ceil() as usize;
        let samples: Vec<f64> = (0..1001).map(|k| p(k as f64 * step)).collect();
        let weight = |k: usize| {
            let end = if k == 0 { 0.5 } else { 1.0 };
            2.0 * PI * end * samples[k] * (k as f64 * step).sin() * step
        };
        let total: f64 = (0..1001)
            .map(|k| weight(k) * if k == 1000 { 0.5 } else { 1.0 })
            .sum();
        let mut held = 0.0;
        let mut kernel = Vec::new();
        for k in 0..1001 {
            if held >= cap[1] * total {
                break;
            }
            held += weight(k);
            if k >= first {
                kernel.push((k as f64 * step, weight(k)));
            }
        }
        let mass: f64 = kernel.iter().map(|&(_, w)| w).sum();
        assert!((mass / total / cone - 1.0).abs() < 1e-12);
        // The backward part w p and its convolution with the kernel on the sphere, by
        // quadrature over each kernel ring's azimuth: (K ∗ q)(θ) = Σ_k w_k ⟨q(θ′)⟩_φ.
        let (from, to) = (CONE_RAMP_DEG.0.to_radians(), CONE_RAMP_DEG.1.to_radians());
        let back = |t: f64| {
            let x = ((t - from) / (to - from)).clamp(0.0, 1.0);
            x * x * (3.0 - 2.0 * x) * p(t)
        };
        let convolved = |t: f64| -> f64 {
            let n = 720;
            kernel
                .iter()
                .map(|&(a, w)| {
                    let ring: f64 = (0..n)
                        .map(|i| {
                            let phi = (i as f64 + 0.5) * 2.0 * PI / n as f64;
                            let c = t.cos() * a.cos() + t.sin() * a.sin() * phi.cos();
                            back(c.clamp(-1.0, 1.0).acos())
                        })
                        .sum::<f64>();
                    w / mass * ring / n as f64
                })
                .sum()
        };
        // At the first depth, D = ¼ (the cone's rD = ¼ cone/share), the cone's part is to
        // first order rD (K ∗ q − q); the peak's blur of the 5° ring, second order, is O(D σ²).
        let r_d = DEPTH_STEP * cone / share;
        let (with, without) = (ramped.row(1, 1), none.row(1, 1));
        let mut worst = 0.0f64;
        let mut largest = 0.0f64;
        for k in (0..1001).step_by(5) {
            let t = k as f64 * step;
            let change = with[k] - without[k];
            if t < from - 25f64.to_radians() {
                // Below the ramp, past the cone's reach: no change but the sum's rounding.
                // Measured: at most 2.8·10⁻⁹ of p.
                assert!(
                    change.abs() < 5e-9 * p(t),
                    "θ {:.1}°: {change:e}",
                    t.to_degrees()
                );
                continue;
            }
            let expect = r_d * (convolved(t) - back(t));
            largest = largest.max(expect.abs());
            worst = worst.max((change - expect).abs());
        }
        assert!(largest > 0.0);
        // Measured: 0.068 of the largest change at rD = 0.17, the second order's (rD)²/2 terms.
        assert!(
            worst < 0.08 * largest,
            "worst {worst:e} of the largest change {largest:e}"
        );
        // The blur keeps ∫ p dΩ at every depth.
        for j in [0, 4, 20, 40] {
            let energy = integral(ramped.row(j, 1)) / integral(ramped.row(0, 1)) - 1.0;
            assert!(
                energy.abs() < 1e-3,
                "D = {}: energy {energy:e}",
                j as f64 * DEPTH_STEP
            );
        }
    }

    #[test]
    fn a_peak_the_samples_do_not_resolve_is_not_blurred_nor_a_broad_lobe() {
        // Rain's: half width 0.1°, within the first 0.18° sample; and a 30° lobe.
        for s2 in [0.12f64.to_radians().powi(2), 36f64.to_radians().powi(2)] {
            let f = field(|t| 0.5 * gaussian(s2, t) + 0.5 / (4.0 * PI));
            let blur = PeakBlur::of(&[&f], 0.18, &[[0.6; 3]]);
            let b = &blur.fields[0];
            assert_eq!(b.share, [0.0; 3]);
            assert_eq!(b.row(DEPTHS - 1, 1), b.row(0, 1));
            assert_eq!(blur.coefficient(&[&f], &[1.0]), 0.0);
        }
    }

    #[test]
    fn the_share_is_at_most_the_splits_peak() {
        let s2 = 1f64.to_radians().powi(2);
        let f = field(|t| 0.5 * gaussian(s2, t) + 0.5 / (4.0 * PI));
        let blur = PeakBlur::of(&[&f], 0.18, &[[0.3; 3]]);
        assert_eq!(blur.fields[0].share, [0.3; 3]);
        assert_eq!(blur.coefficient(&[&f], &[2.0]), 0.6);
    }
}
