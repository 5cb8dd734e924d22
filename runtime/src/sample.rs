//! The sampling functions a renderer uses, on the CPU: the reference the WGSL module is to be
//! tested against, so the definitions here are the specification.
//!
//! - [`ams`]`(field, n, cos θ)`: θ = acos(cos θ) on the table grid θ_k = k·Δθ, linear between
//!   the two neighbouring samples; n ≥ 1 fractional, linear between Ams_⌊n⌋ and Ams_⌊n⌋+1.
//!   Beyond N the table's last row is used: Ams_n tends to the isotropic 1/(4π) as n grows, and
//!   a bake's N is chosen (`max_optical_depth`) so that the scene never needs more; orders
//!   n < 1 are single scattering, Ams_1.
//! - [`forward_fraction`]`(field, n)`: F_n, linear in fractional n, with the same ends.
//! - [`mix`]: several fields in one place (Riley et al. 2004 Eq. 6), each weighted by its
//!   number density times its scattering cross-section, per channel; [`forward_fraction_mix`]
//!   the same for F_n.

use crate::load::FieldTable;

/// Row r and weight of row r + 1 for a fractional order n.
fn order(field: &FieldTable, n: f64) -> (usize, usize, f64) {
    let n = if n.is_finite() { n } else { 1.0 };
    let top = field.n_max() as f64;
    let n = n.clamp(1.0, top);
    let lo = n.floor();
    let r0 = lo as usize - 1;
    let r1 = (r0 + 1).min(field.n_max() - 1);
    (r0, r1, n - lo)
}

/// The sample k0 below θ = acos(cos θ) on a grid of `k_len` samples θ_k = k·Δθ and the
/// weight t of sample k0 + 1 (linear in θ; the last interval beyond the grid).
pub fn column(theta_step_deg: f64, k_len: usize, cos_theta: f64) -> (usize, f64) {
    let theta = cos_theta.clamp(-1.0, 1.0).acos().to_degrees();
    let u = (theta / theta_step_deg).min((k_len - 1) as f64);
    let k0 = (u.floor() as usize).min(k_len - 2);
    (k0, u - k0 as f64)
}

/// Ams_n(θ) per channel R, G, B (1/sr), linear in θ and in n.
pub fn ams(field: &FieldTable, theta_step_deg: f64, n: f64, cos_theta: f64) -> [f64; 3] {
    let ams = &field.image.ams;
    let (k0, t) = column(theta_step_deg, field.image.angle_count(), cos_theta);
    let (r0, r1, s) = order(field, n);
    std::array::from_fn(|c| {
        let at = |r: usize| ams[[c, r, k0]] * (1.0 - t) + ams[[c, r, k0 + 1]] * t;
        at(r0) * (1.0 - s) + at(r1) * s
    })
}

/// F_n per channel, linear in fractional n.
pub fn forward_fraction(field: &FieldTable, n: f64) -> [f64; 3] {
    let (r0, r1, s) = order(field, n);
    std::array::from_fn(|c| {
        let f = &field.image.forward_fraction;
        f[[c, r0]] * (1.0 - s) + f[[c, r1]] * s
    })
}

/// Σ_i ρ_i σ_sca,i v_i / Σ_i ρ_i σ_sca,i per channel over the fields present (ρ_i > 0), with
/// v_i = `value(i)`; `empty` where nothing scatters. The one place a per-field quantity is mixed
/// as the phase functions are (Riley et al. 2004 Eq. 6's weights): every model's mixture goes
/// through it.
pub fn scattering_weighted(
    fields: &[&FieldTable],
    densities: &[f64],
    empty: f64,
    value: impl Fn(usize) -> [f64; 3],
) -> [f64; 3] {
    let mut num = [0.0; 3];
    let mut den = [0.0; 3];
    for (i, (f, &rho)) in fields.iter().zip(densities).enumerate() {
        if rho <= 0.0 {
            continue;
        }
        let v = value(i);
        for c in 0..3 {
            let w = rho * f.sigma_sca_m2[c];
            num[c] += w * v[c];
            den[c] += w;
        }
    }
    std::array::from_fn(|c| if den[c] > 0.0 { num[c] / den[c] } else { empty })
}

/// [`scattering_weighted`] with `value` given the field itself.
fn weighted(
    fields: &[&FieldTable],
    densities: &[f64],
    empty: f64,
    value: impl Fn(&FieldTable) -> [f64; 3],
) -> [f64; 3] {
    scattering_weighted(fields, densities, empty, |i| value(fields[i]))
}

/// Phase function of a mixture of fields at one place: Σ_i ρ_i σ_sca,i P_i / Σ_i ρ_i σ_sca,i
/// per channel, with ρ_i the number density of field i (any common unit) and P_i its
/// `ams(…, n, cos θ)`. All densities zero gives zero (nothing scatters there), never NaN.
pub fn mix(
    fields: &[&FieldTable],
    densities: &[f64],
    theta_step_deg: f64,
    n: f64,
    cos_theta: f64,
) -> [f64; 3] {
    weighted(fields, densities, 0.0, |f| {
        ams(f, theta_step_deg, n, cos_theta)
    })
}

/// Ams_n(θ) of a swept field at `value` (the key's unit): the two members around it
/// (`members[k]` the field of `sweep.values[k]`) with the number shares of
/// [`format::SweepEntry::shares`] (green σ_ext), mixed as [`mix`] mixes fields in one place.
/// The exact reference of WGSL's `ams_sweep`.
pub fn ams_sweep(
    members: &[&FieldTable],
    sweep: &format::SweepEntry,
    theta_step_deg: f64,
    value: f64,
    n: f64,
    cos_theta: f64,
) -> [f64; 3] {
    let (fields, shares) = sweep_shares(members, sweep, value);
    mix(&fields, &shares, theta_step_deg, n, cos_theta)
}

/// F_n of a swept field at `value`, weighted like [`ams_sweep`].
pub fn forward_fraction_sweep(
    members: &[&FieldTable],
    sweep: &format::SweepEntry,
    value: f64,
    n: f64,
) -> [f64; 3] {
    let (fields, shares) = sweep_shares(members, sweep, value);
    forward_fraction_mix(&fields, &shares, n)
}

fn sweep_shares<'a>(
    members: &[&'a FieldTable],
    sweep: &format::SweepEntry,
    value: f64,
) -> ([&'a FieldTable; 2], [f64; 2]) {
    let sigma: Vec<f64> = members.iter().map(|f| f.sigma_ext_m2[1]).collect();
    let [(a, wa), (b, wb)] = sweep.shares(value, &sigma);
    ([members[a], members[b]], [wa, wb])
}

/// F_n of a mixture, weighted like [`mix`]; 1 where nothing scatters (no light is lost there).
pub fn forward_fraction_mix(fields: &[&FieldTable], densities: &[f64], n: f64) -> [f64; 3] {
    weighted(fields, densities, 1.0, |f| forward_fraction(f, n))
}

/// M(D, θ) per channel (1/sr) from a field's Poisson-mixture table (`format::poisson`), each
/// channel at its own optical depth `depth[c]`: linear in θ as [`ams`], linear in ln D between
/// the table's depths; below the first depth D_1, linear in D from M(0) = Ams_1 to the first
/// row (M − Ams_1 is O(D)); beyond the last depth the last row (a caller checks that its
/// depths stay in range). `None` if the bake has no Poisson table.
pub fn poisson(
    field: &FieldTable,
    theta_step_deg: f64,
    depth: [f64; 3],
    cos_theta: f64,
) -> Option<[f64; 3]> {
    let table = field.poisson.as_ref()?;
    let rows = &table.rows;
    let (k0, t) = column(theta_step_deg, rows.dim().2, cos_theta);
    let depths = &table.depths;
    Some(std::array::from_fn(|c| {
        let d = depth[c];
        let j = depths.partition_point(|&x| x <= d);
        let at = |r: usize| rows[[c, r, k0]] * (1.0 - t) + rows[[c, r, k0 + 1]] * t;
        if j == 0 {
            let ams1 = &field.image.ams;
            let single = ams1[[c, 0, k0]] * (1.0 - t) + ams1[[c, 0, k0 + 1]] * t;
            let s = (d / depths[0]).max(0.0);
            return single * (1.0 - s) + at(0) * s;
        }
        let (j0, j1, s) = if j >= depths.len() {
            (depths.len() - 1, depths.len() - 1, 0.0)
        } else {
            let (a, b) = (depths[j - 1].ln(), depths[j].ln());
            (j - 1, j, (d.ln() - a) / (b - a))
        };
        at(j0) * (1.0 - s) + at(j1) * s
    }))
}

/// [`poisson`] of a mixture of fields, weighted like [`mix`] (fields without a table count as
/// zero).
pub fn poisson_mix(
    fields: &[&FieldTable],
    densities: &[f64],
    theta_step_deg: f64,
    depth: [f64; 3],
    cos_theta: f64,
) -> [f64; 3] {
    weighted(fields, densities, 0.0, |f| {
        poisson(f, theta_step_deg, depth, cos_theta).unwrap_or([0.0; 3])
    })
}

/// Biri et al.'s kernel primitive C(τ_h, θ) of channel `c` (`format::biri`; θ ∈ [−π/2, π/2]
/// the angle at the light from the ray's foot point, radians). The table holds C at the bin
/// centres θ_k; within bin k the phase function is the constant Ams_1 bin value p_k (the
/// tables' own definition), so C(θ) = C(θ_k) + p_k ∫_{θ_k}^{θ} e^{−τ_h g}, the integral by
/// the midpoint rule over less than half a bin: exact to the bins, where a line between
/// centres would miss the kink at each bin edge (up to ~3·10⁻³ of a ray's light where the
/// ray's end sees a fog's forward lobe). C(θ_k) is quadratic in ln τ_h between the depths
/// (`grid::depth_weights`). `None` if the bake has no kernel table.
pub fn biri_primitive(
    field: &FieldTable,
    grid: &grid::ThetaGrid,
    c: usize,
    tau_h: f64,
    theta: f64,
) -> Option<f64> {
    let t = field.biri.as_ref()?;
    let weights = grid::depth_weights(&t.depths, tau_h);
    Some(primitive_with(field, t, grid, c, &weights, tau_h, theta))
}

/// C(τ_h, θ_1) − C(τ_h, θ_0), as [`biri_primitive`] with the depth weights found once: a lit
/// piece of a ray. `None` if the bake has no kernel table.
pub fn biri_primitive_difference(
    field: &FieldTable,
    grid: &grid::ThetaGrid,
    c: usize,
    tau_h: f64,
    (theta0, theta1): (f64, f64),
) -> Option<f64> {
    let t = field.biri.as_ref()?;
    let weights = grid::depth_weights(&t.depths, tau_h);
    let at = |theta| primitive_with(field, t, grid, c, &weights, tau_h, theta);
    Some(at(theta1) - at(theta0))
}

fn primitive_with(
    field: &FieldTable,
    t: &format::BiriTable,
    grid: &grid::ThetaGrid,
    c: usize,
    weights: &[(usize, f64); 3],
    tau_h: f64,
    theta: f64,
) -> f64 {
    use std::f64::consts::FRAC_PI_2;
    let step = grid.step_deg().to_radians();
    let theta = theta.clamp(-FRAC_PI_2, FRAC_PI_2);
    let k = (((theta + FRAC_PI_2) / step).round() as usize).min(grid.len() - 1);
    let centre = k as f64 * step - FRAC_PI_2;
    let at_centre: f64 = weights
        .iter()
        .map(|&(j, w)| w * t.primitive[[c, j, k]])
        .sum();
    // e^{−τ_h g} at the middle of [θ_k, θ] (g = tan(θ/2 + π/4) → ∞ at π/2).
    let g = (0.25 * (theta + centre) + std::f64::consts::FRAC_PI_4).tan();
    let e = if tau_h == 0.0 {
        1.0
    } else if g.is_finite() {
        (-tau_h.min(*t.depths.last().expect("depths")) * g).exp()
    } else {
        0.0
    };
    at_centre + field.image.ams[[c, 0, k]] * e * (theta - centre)
}

/// The paper's quartic coefficients c_0..c_4 (Biri et al. 2006 Eq. 2, θ in radians) of channel
/// `c` at τ_h, interpolated in τ_h as [`biri_primitive`]. `None` if the bake has no kernel
/// table.
pub fn biri_polynomial(field: &FieldTable, c: usize, tau_h: f64) -> Option<[f64; 5]> {
    let t = field.biri.as_ref()?;
    let rows = &t.polynomial[c];
    let mut out = [0.0; 5];
    for (j, w) in grid::depth_weights(&t.depths, tau_h) {
        for (i, o) in out.iter_mut().enumerate() {
            *o += w * rows[5 * j + i];
        }
    }
    Some(out)
}
