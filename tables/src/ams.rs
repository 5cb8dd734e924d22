//! Ams_n, the distribution of light after n scattering events, and the forward fractions F_n
//! (Riley et al. 2004 §4.2, Eqs. 21–23), from the bin averages of one phase function.
//!
//! # Method
//! Ams_n = δ ∗ P ∗ … ∗ P (n times) is, by Funk–Hecke, the zonal function with Legendre
//! coefficients χ_l^n. A raindrop's diffraction peak (~0.006° wide) or an ice crystal's delta
//! transmission cannot be expanded at 0.18°, so the energy of bin 0 above the level of bin 1 is
//! split off as an exact forward delta of weight f:
//!
//!   P = f δ + (1 − f) Q,   Q = the remaining bins, normalized (piecewise constant in μ),
//!   Ams_n = Σ_j C(n, j) f^{n−j} (1 − f)^j Q^{∗j}.
//!
//! The j = 0 term (f^n δ) goes into bin 0 exactly and the j = 1 term is Q's bins exactly, so
//! Ams_1 reproduces the input bins to rounding. The j ≥ 2 terms are convolutions of the
//! piecewise-constant Q, which are continuous; they are summed as one Legendre series whose
//! coefficient for degree l is
//!
//!   c_{n,l} = (f + (1 − f) χ_l)^n − f^n − n f^{n−1} (1 − f) χ_l,   χ_l = χ_l(Q),
//!
//! and whose bin averages use the exact bin integrals W_lk of P_l ([`BinIntegrals`]), so every
//! row is a true bin average of its series. Because Σ_k W_lk = 2δ_l0, each row's energy
//! Σ_k Ams_n,k Ω_k is 1 to rounding whatever the truncation degree L.
//!
//! # Resolution: what Q is between the bin averages
//! Q is known only as bin averages; the j ≥ 2 terms need a function. Read as a piecewise-constant
//! function (the steps) its Legendre spectrum does not decay: the steps put peaks near
//! l = 2π m/Δθ (every 2000 degrees at 0.18°), so no truncation of the j ≥ 2 series is safe; and
//! below those peaks the steps are the true Q smoothed twice by a bin (averaging, then holding),
//! a factor sinc²(u/2) on χ_l, u = (l + ½)Δθ, 8 % at u = 1.
//!
//! [`Reconstruction::Spline`] (the default) takes instead the cubic spline in θ with knots at the
//! bin centres whose bin averages are the given ones (histopolation). On a uniform grid both are
//! linear, shift-invariant maps of the same averages, so their spectra differ by a factor: with
//! the spline's box average at the knots, S(u) = (115 + 76 cos u + cos 2u)/192 (the centred
//! degree-4 B-spline at −2..2),
//!
//!   χ_l(spline) = χ_l(steps) · sinc³(u/2) / S(u),
//!
//! which is 1 − O(u⁶) at low degrees (the spline reproduces cubics: 0.45 % low at u = 1.6, l = 500
//! at 0.18°) and vanishes at the steps' peaks u = 2π m, where sinc(u/2) = 0. On the sphere, whose
//! bins are uniform in θ, the factor holds for lθ ≫ 1, i.e. away from the poles' first bins. The
//! spline is smooth (C²), so its spectrum falls as l⁻⁴; the series is cut by a flat taper
//! e^{−(u/2π)⁸} (10⁻⁵ at u = 1.6, e^{−1} at the first peak) where the taper falls below 10⁻¹⁷,
//! u = 2π·39.1^{1/8} ≈ 3.16π: l_max = ⌈3.16π/Δθ⌉, 3162 at 0.18° (it was cut at 4π, 4000, where
//! the taper is e^{−256}: a fifth of every pass over the degrees added nothing). A spline can
//! overshoot next to a jump of the bins (a halo's edge), so it is not positive by construction;
//! the tests check the rows stay ≥ 0.
//!
//! [`Reconstruction::HeatKernel`] is the earlier method, kept to measure against: the steps
//! blurred by the spherical heat kernel, χ_l → χ_l exp(−l(l+1) s²/2) (s = half a bin by
//! default), a positive convolution that cannot ring, cut where the factor is below 1e-17
//! (l ≈ 8.7/s, 5600 at 0.18°). It smooths the j ≥ 2 terms by the blur on top of the steps': on a
//! cloud's diffraction lobe Ams_2 comes out 2–4 % high at 1.6–2.5° (tests/ams_exact.rs).
//!
//! The j = 0, 1 terms use neither: they are the bins themselves.
//!
//! # Forward fractions
//! F_n = ∫_{μ>0} Ams_n dΩ (Eq. 23) from the same split: f^n + n f^{n−1}(1 − f) F(Q) +
//! Σ_l (2l+1)/2 c_{n,l} ∫_0^1 P_l dμ, with ∫_0^1 P_l dμ = P'_l(0)/(l(l+1)) for l ≥ 1.
//!
//! # Poisson mixtures
//! Max et al. 2004 (Eqs. 8, 9) weight the light scattered i times along a segment of optical
//! depth D by the Poisson probability q_i = e^{−D} D^i / i!. The mixture of all orders,
//!
//!   M(D) = Σ_{i≥1} q_i Ams_i / (1 − q_0),
//!
//! is summed here in closed form rather than order by order: with x_l = f + (1 − f) χ_l the
//! coefficient of Ams_i is x_l^i, and Σ_{i≥1} q_i x^i = e^{−D}(e^{Dx} − 1). Split as above,
//! the δ carries (e^{−D(1−f)} − e^{−D}) / (1 − q_0), Q carries e^{−D(1−f)} D(1 − f) / (1 − q_0)
//! exactly, and degree l of the j ≥ 2 terms is e^{−D(1−f)} (e^u − 1 − u) / (1 − q_0) with
//! u = D(1 − f) χ_l. Every order is included, so there is no Poisson tail to cut; each row's
//! energy is 1 as for Ams_n, and as D → 0 the row tends to Ams_1.

use grid::ThetaGrid;
use mie::PhaseFunction;
use ndarray::Array2;

use crate::TablesError;
use crate::legendre::bins::BinIntegrals;

/// What the j ≥ 2 terms take Q to be between its bin averages (module docs, "Resolution").
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Reconstruction {
    /// The cubic spline in θ whose bin averages are Q's (histopolation).
    Spline,
    /// The bins as steps, blurred by the heat kernel of width `blur_bins` bins.
    HeatKernel {
        /// The Gaussian blur s as a fraction of Δθ (the earlier default 0.5).
        blur_bins: f64,
    },
}

impl Reconstruction {
    /// The factor χ_l(Q) is multiplied by at degree l on a grid of step `step_rad`, and the
    /// degree beyond which every factor is 0 to double precision.
    fn factors(self, step_rad: f64) -> (impl Fn(usize) -> f64, usize) {
        use std::f64::consts::PI;
        let l_max = match self {
            // e^{−(u/2π)⁸} < 1e-17 ⇔ u > 2π·39.1^{1/8} (and sinc³/S ≤ 1.24 beyond)
            Reconstruction::Spline => (2.0 * PI * 39.1f64.powf(0.125) / step_rad).ceil() as usize,
            // exp(−l(l+1)s²/2) < 1e-17 ⇔ l(l+1) > 2·39.1/s²
            Reconstruction::HeatKernel { blur_bins } => {
                ((78.2f64).sqrt() / (blur_bins * step_rad)).ceil() as usize
            }
        };
        let factor = move |l: usize| match self {
            // χ_0 = 1 exactly: every row's energy rests on it.
            Reconstruction::Spline if l == 0 => 1.0,
            Reconstruction::Spline => {
                let u = (l as f64 + 0.5) * step_rad;
                let sinc = if u == 0.0 {
                    1.0
                } else {
                    (0.5 * u).sin() / (0.5 * u)
                };
                let s = (115.0 + 76.0 * u.cos() + (2.0 * u).cos()) / 192.0;
                sinc.powi(3) / s * (-(u / (2.0 * PI)).powi(8)).exp()
            }
            Reconstruction::HeatKernel { blur_bins } => {
                let s = blur_bins * step_rad;
                let lf = l as f64;
                (-0.5 * lf * (lf + 1.0) * s * s).exp()
            }
        };
        (factor, l_max)
    }
}

/// Settings of the Ams_n computation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmsSettings {
    /// Number of scattering orders N (rows Ams_1..Ams_N).
    pub n_max: usize,
    /// What Q is between its bins in the j ≥ 2 terms (default: the spline).
    pub reconstruction: Reconstruction,
}

impl Default for AmsSettings {
    fn default() -> Self {
        Self {
            n_max: 26,
            reconstruction: Reconstruction::Spline,
        }
    }
}

/// Ams_1..Ams_N of one phase function as bin averages (1/sr), with the forward fractions (a
/// single channel; a bake's RGB tables are `photometeor_format::FieldImage`).
#[derive(Debug, Clone, PartialEq)]
pub struct AmsTable {
    /// `rows[[n − 1, k]]` = bin average of Ams_n over bin k; shape (N, K).
    pub rows: Array2<f64>,
    /// F_1..F_N.
    pub forward_fraction: Vec<f64>,
    /// f: the energy fraction of the single-scattering forward delta (bin 0 above bin 1).
    pub forward_peak_fraction: f64,
    /// Σ_k v_k Ω_k − 1 of the input before it was renormalized.
    pub input_energy_error: f64,
    /// Legendre degree at which the series stops (every reconstruction factor 0 beyond).
    pub l_max: usize,
}

/// The split P = f δ + (1 − f) Q of one phase function and the Legendre coefficients of Q's
/// reconstruction: everything needed to evaluate any row Ams_n (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct AmsSeries {
    grid: ThetaGrid,
    /// Weight of the forward delta.
    f: f64,
    /// Q's bin averages (normalized).
    q: Vec<f64>,
    /// χ_l of Q's reconstruction, l = 0..=l_max.
    chi: Vec<f64>,
    /// max_{l' ≥ l} |χ_l'|: bounds what the series beyond l can still add.
    chi_tail: Vec<f64>,
    input_energy_error: f64,
}

impl AmsSeries {
    /// Splits a [`PhaseFunction`]'s bins and expands Q (see [`Self::new`]).
    pub fn from_phase(phase: &PhaseFunction, reconstruction: Reconstruction) -> Self {
        Self::new(&phase.grid, &phase.bins, reconstruction)
    }

    /// Splits the bin averages `bins` (1/sr) on `grid` and expands Q's reconstruction.
    pub fn new(grid: &ThetaGrid, bins: &[f64], reconstruction: Reconstruction) -> Self {
        Self::many(grid, &[bins], reconstruction)
            .pop()
            .expect("one series per phase function")
    }

    /// [`Self::new`] for several phase functions on one grid, in one pass over the degrees
    /// (the bin integrals W_lk, the costly part, shared).
    pub fn many(grid: &ThetaGrid, bins: &[&[f64]], reconstruction: Reconstruction) -> Vec<Self> {
        let omega = grid.bin_solid_angles();
        let split: Vec<(f64, Vec<f64>, f64)> = bins
            .iter()
            .map(|bins| {
                assert_eq!(bins.len(), grid.len(), "one value per bin");
                let energy: f64 = bins.iter().zip(&omega).map(|(v, o)| v * o).sum();
                let v: Vec<f64> = bins.iter().map(|b| b / energy).collect();
                // Split the forward delta: energy of bin 0 above the level of bin 1.
                let f = if v.len() > 1 && v[0] > v[1] {
                    (v[0] - v[1]) * omega[0]
                } else {
                    0.0
                };
                let mut q = v;
                if f > 0.0 {
                    q[0] = q[1];
                }
                for x in q.iter_mut() {
                    *x /= 1.0 - f;
                }
                (f, q, energy)
            })
            .collect();
        // χ_l of the steps, 2π Σ_k q_k W_lk, times the reconstruction's factor (module docs).
        let (factor, l_max) = reconstruction.factors(grid.step_deg().to_radians());
        // Q (wavelengths × bins) against blocks of BLOCK degrees' bin integrals (degrees ×
        // bins): one matrix product per block instead of a dot product per wavelength and
        // degree.
        const BLOCK: usize = 32;
        let k_len = grid.len();
        let q_all = Array2::from_shape_fn((split.len(), k_len), |(j, k)| split[j].1[k]);
        let mut w_block = Array2::<f64>::zeros((BLOCK, k_len));
        let mut products = Array2::<f64>::zeros((split.len(), BLOCK));
        let mut chis: Vec<Vec<f64>> = vec![Vec::with_capacity(l_max + 1); split.len()];
        let mut w = BinIntegrals::new(grid);
        for start in (0..=l_max).step_by(BLOCK) {
            let count = BLOCK.min(l_max + 1 - start);
            for (i, l) in (start..start + count).enumerate() {
                if l > 0 {
                    w.advance();
                }
                w_block
                    .row_mut(i)
                    .assign(&ndarray::ArrayView1::from(w.values()));
            }
            ndarray::linalg::general_mat_mul(
                1.0,
                &q_all,
                &w_block.slice(ndarray::s![..count, ..]).t(),
                0.0,
                &mut products.slice_mut(ndarray::s![.., ..count]),
            );
            for (i, l) in (start..start + count).enumerate() {
                let factor_l = factor(l);
                for (j, chi) in chis.iter_mut().enumerate() {
                    chi.push(2.0 * std::f64::consts::PI * products[[j, i]] * factor_l);
                }
            }
        }
        split
            .into_iter()
            .zip(chis)
            .map(|((f, q, energy), chi)| {
                let mut chi_tail = chi.iter().map(|c| c.abs()).collect::<Vec<_>>();
                for l in (0..chi_tail.len().saturating_sub(1)).rev() {
                    chi_tail[l] = chi_tail[l].max(chi_tail[l + 1]);
                }
                Self {
                    grid: *grid,
                    f,
                    q,
                    chi,
                    chi_tail,
                    input_energy_error: energy - 1.0,
                }
            })
            .collect()
    }

    /// Weight f of the single-scattering forward delta.
    pub fn forward_peak_fraction(&self) -> f64 {
        self.f
    }

    /// Highest Legendre degree of the series.
    pub fn l_max(&self) -> usize {
        self.chi.len() - 1
    }

    /// The theta grid the series lives on.
    pub fn grid(&self) -> &ThetaGrid {
        &self.grid
    }

    /// Bin averages of Ams_n for each n in `orders` (n ≥ 1), in one pass over l: shape
    /// (orders, K).
    pub fn rows(&self, orders: &[usize]) -> Array2<f64> {
        mixture_rows(&[(1.0, self)], orders)
    }

    /// F_n = ∫_{μ>0} Ams_n dΩ from the coefficients (module docs).
    pub fn forward_fraction(&self, n: usize) -> f64 {
        mixture_forward_fractions(&[(1.0, self)], &[n])[0]
    }

    /// Bin averages of the Poisson mixture M(D) = Σ_{i≥1} q_i(D) Ams_i / (1 − q_0(D)) for
    /// each optical depth D in `depths` (finite, > 0): shape (depths, K) (module docs,
    /// "Poisson mixtures").
    pub fn poisson_rows(&self, depths: &[f64]) -> Array2<f64> {
        poisson_rows(&[(1.0, self)], depths)
    }

    /// max_k |4π Ams_n(θ_k) − 1|: how far row n is from isotropic.
    pub fn anisotropy(&self, n: usize) -> f64 {
        anisotropy(&[(1.0, self)], n)
    }

    /// n_iso(ε): the smallest n ≤ n_cap with max_k |4π Ams_n − 1| < ε, by bisection on n
    /// (the deviation falls monotonically for the phase functions met here), or None.
    pub fn isotropic_order(&self, epsilon: f64, n_cap: usize) -> Option<usize> {
        isotropic_orders(&[(1.0, self)], &[epsilon], n_cap, Default::default())[0]
    }
}

/// Ams_n of light that keeps its wavelength while it scatters: Σ_j a_j Ams_n[P_j] with
/// Σ_j a_j = 1, a_j ≥ 0. This is how an RGB channel mixes its wavelengths (each wavelength's
/// light scatters n times with its own phase function), not (Σ_j a_j P_j)^{∗n}. The mixing is
/// done in coefficient space: one Legendre series per row whatever the number of wavelengths.
#[derive(Debug, Clone, PartialEq)]
pub struct AmsMixture {
    parts: Vec<(f64, AmsSeries)>,
}

impl AmsMixture {
    /// `parts` = (weight, series) on one grid; weights finite and ≥ 0 with a positive sum,
    /// normalized here to sum to 1.
    pub fn new(parts: Vec<(f64, AmsSeries)>) -> Result<Self, TablesError> {
        let Some((_, first)) = parts.first() else {
            return Err(TablesError::EmptyMixture);
        };
        let grid = first.grid;
        for (index, (a, s)) in parts.iter().enumerate() {
            if !(a.is_finite() && *a >= 0.0) {
                return Err(TablesError::MixtureWeight { index, weight: *a });
            }
            if s.grid != grid {
                return Err(TablesError::GridMismatch {
                    index,
                    step_deg: s.grid.step_deg(),
                    expected_deg: grid.step_deg(),
                });
            }
        }
        let total: f64 = parts.iter().map(|(a, _)| a).sum();
        if !(total > 0.0 && total.is_finite()) {
            return Err(TablesError::MixtureWeight {
                index: 0,
                weight: total,
            });
        }
        Ok(Self {
            parts: parts.into_iter().map(|(a, s)| (a / total, s)).collect(),
        })
    }

    fn refs(&self) -> Vec<(f64, &AmsSeries)> {
        self.parts.iter().map(|(a, s)| (*a, s)).collect()
    }

    /// Bin averages of Ams_n for each n in `orders` (n ≥ 1): shape (orders, K).
    pub fn rows(&self, orders: &[usize]) -> Array2<f64> {
        mixture_rows(&self.refs(), orders)
    }

    /// F_n = Σ_j a_j F_n[P_j].
    pub fn forward_fraction(&self, n: usize) -> f64 {
        mixture_forward_fractions(&self.refs(), &[n])[0]
    }

    /// F_n for each n in `orders`, in one pass over the degrees.
    pub fn forward_fractions(&self, orders: &[usize]) -> Vec<f64> {
        mixture_forward_fractions(&self.refs(), orders)
    }

    /// [`Self::rows`] and [`Self::poisson_rows`] in one pass over the degrees.
    pub fn rows_and_poisson(&self, orders: &[usize], depths: &[f64]) -> (Array2<f64>, Array2<f64>) {
        assert!(
            depths.iter().all(|d| d.is_finite() && *d > 0.0),
            "Poisson depths must be finite and > 0: {depths:?}"
        );
        let kinds: Vec<Row> = orders
            .iter()
            .map(|&n| Row::Order(n))
            .chain(depths.iter().map(|&d| Row::Poisson(d)))
            .collect();
        let all = series_rows(&self.refs(), &kinds);
        (
            all.slice(ndarray::s![..orders.len(), ..]).to_owned(),
            all.slice(ndarray::s![orders.len().., ..]).to_owned(),
        )
    }

    /// Σ_j a_j M(D)[P_j], as [`AmsSeries::poisson_rows`]: each wavelength's light scatters
    /// with its own phase function, as in [`Self::rows`].
    pub fn poisson_rows(&self, depths: &[f64]) -> Array2<f64> {
        poisson_rows(&self.refs(), depths)
    }

    /// Energy of row n held by the exact forward delta: Σ_j a_j f_j^n.
    pub fn forward_peak_fraction(&self, n: usize) -> f64 {
        self.parts.iter().map(|(a, s)| a * s.f.powi(n as i32)).sum()
    }

    /// Highest Legendre degree among the parts.
    pub fn l_max(&self) -> usize {
        self.parts.iter().map(|(_, s)| s.l_max()).max().unwrap_or(0)
    }

    /// max_k |4π Ams_n(θ_k) − 1|.
    pub fn anisotropy(&self, n: usize) -> f64 {
        anisotropy(&self.refs(), n)
    }

    /// n_iso(ε), as [`AmsSeries::isotropic_order`].
    pub fn isotropic_order(&self, epsilon: f64, n_cap: usize) -> Option<usize> {
        isotropic_orders(&self.refs(), &[epsilon], n_cap, Default::default())[0]
    }

    /// n_iso(ε) for each of `epsilons`, searched together (cheaper than one by one), starting
    /// from `rows` of this mixture already computed for `orders` ([`Self::rows`]).
    pub fn isotropic_orders(
        &self,
        epsilons: &[f64],
        n_cap: usize,
        orders: &[usize],
        rows: &Array2<f64>,
    ) -> Vec<Option<usize>> {
        let known = orders
            .iter()
            .zip(rows.outer_iter())
            .map(|(&n, row)| (n, deviation(row)))
            .collect();
        isotropic_orders(&self.refs(), epsilons, n_cap, known)
    }
}

/// What one row of [`mixture_rows`] is: Ams_n, or the Poisson mixture of all orders at
/// optical depth D (module docs, "Poisson mixtures").
#[derive(Debug, Clone, Copy)]
enum Row {
    Order(usize),
    Poisson(f64),
}

impl Row {
    /// The weights of the δ (j = 0) and of Q (j = 1) terms for a part whose forward δ is f.
    fn exact_weights(self, f: f64) -> (f64, f64) {
        match self {
            Row::Order(n) => (
                f.powi(n as i32),
                n as f64 * f.powi(n as i32 - 1) * (1.0 - f),
            ),
            Row::Poisson(d) => {
                let (e, norm) = ((-d * (1.0 - f)).exp(), -(-d).exp_m1());
                // (e^{−D(1−f)} − e^{−D}) / (1 − e^{−D}), without cancellation as D → 0.
                let delta = e * -(-d * f).exp_m1() / norm;
                (delta, e * d * (1.0 - f) / norm)
            }
        }
    }

    /// The j ≥ 2 coefficient of this row at χ_l = `chi` for part `j`: orders up to
    /// [`RECURRENCE_ORDERS`] from `orders` ([`PartOrders`], filled at this degree), higher
    /// orders and Poisson rows from this row's [`RowFactors`] for the part.
    fn higher(self, orders: &PartOrders, j: usize, factors: RowFactors, chi: f64) -> f64 {
        match self {
            Row::Order(n) if n <= orders.n_top => orders.get(n, j),
            _ => factors.coefficient(chi),
        }
    }

    fn top_order(self) -> usize {
        match self {
            Row::Order(n) => n,
            Row::Poisson(_) => 0,
        }
    }
}

/// Rows of Σ_j a_j Ams_n[P_j] (or of the Poisson mixtures): the j ≥ 2 coefficients are mixed
/// per degree l and summed as one series; the exact single-scattering and delta terms are
/// added per part.
fn mixture_rows(parts: &[(f64, &AmsSeries)], orders: &[usize]) -> Array2<f64> {
    let rows: Vec<Row> = orders.iter().map(|&n| Row::Order(n)).collect();
    series_rows(parts, &rows)
}

fn poisson_rows(parts: &[(f64, &AmsSeries)], depths: &[f64]) -> Array2<f64> {
    assert!(
        depths.iter().all(|d| d.is_finite() && *d > 0.0),
        "Poisson depths must be finite and > 0: {depths:?}"
    );
    let rows: Vec<Row> = depths.iter().map(|&d| Row::Poisson(d)).collect();
    series_rows(parts, &rows)
}

fn series_rows(parts: &[(f64, &AmsSeries)], kinds: &[Row]) -> Array2<f64> {
    let grid = &parts[0].1.grid;
    let k_len = grid.len();
    let omega0 = grid.bin_solid_angles()[0];
    let inv_d_mu: Vec<f64> = grid.bin_mu_widths().iter().map(|d| 1.0 / d).collect();
    let l_max = parts.iter().map(|(_, s)| s.l_max()).max().unwrap_or(0);
    let n_top = kinds
        .iter()
        .map(|r| r.top_order())
        .max()
        .unwrap_or(0)
        .min(RECURRENCE_ORDERS);
    // Per part, each row's factors constant in l.
    let factors: Vec<Vec<RowFactors>> = parts
        .iter()
        .map(|(_, s)| kinds.iter().map(|&r| RowFactors::new(r, s.f)).collect())
        .collect();
    let fs: Vec<f64> = parts.iter().map(|(_, s)| s.f).collect();
    let mut orders = PartOrders::new(&fs, n_top);
    let mut chis = vec![0.0; parts.len()];
    let mut rows = Array2::<f64>::zeros((kinds.len(), k_len));
    let mut w = BinIntegrals::new(grid);
    let mut coefficients = vec![0.0; kinds.len()];
    // The degrees' terms are rank-one updates rows += c_l ⊗ (w_l/Δμ); BLOCK of them at a time
    // are one matrix product (C: rows × degrees, W: degrees × bins), which streams the rows
    // through the cache once per block instead of once per degree.
    const BLOCK: usize = 32;
    let mut c_block = Array2::<f64>::zeros((kinds.len(), BLOCK));
    let mut w_block = Array2::<f64>::zeros((BLOCK, k_len));
    let mut filled = 0;
    let flush = |rows: &mut Array2<f64>, c: &Array2<f64>, w: &Array2<f64>, filled: usize| {
        if filled > 0 {
            ndarray::linalg::general_mat_mul(
                1.0,
                &c.slice(ndarray::s![.., ..filled]),
                &w.slice(ndarray::s![..filled, ..]),
                1.0,
                rows,
            );
        }
    };
    // Σ_{l' ≥ l} (2l'+1)/(4π) |c_{n,l'}| |bin average of P_l'| ≤ B_l (L+1)²/(4π), with
    // B_l = Σ_j a_j c_n(f_j, max_{l' ≥ l} |χ_l'|) (c_n grows with |χ|, and so does the
    // Poisson coefficient): below 1e-17 nothing beyond l can change a row (values ~ 1/(4π)),
    // so the sum stops there. High orders, whose χ_l^n vanish early, cost a fraction of a
    // full pass.
    let tail_scale = ((l_max + 1) as f64).powi(2) / (4.0 * std::f64::consts::PI);
    for l in 0..=l_max {
        if l % 32 == 0 && l > 0 {
            for (m, (_, s)) in chis.iter_mut().zip(parts) {
                *m = s.chi_tail.get(l).copied().unwrap_or(0.0);
            }
            orders.at(&chis);
            let mut bound = 0.0;
            for (j, ((a, _), row_factors)) in parts.iter().zip(&factors).enumerate() {
                bound += kinds
                    .iter()
                    .zip(row_factors)
                    .map(|(&r, &p)| a * r.higher(&orders, j, p, chis[j]))
                    .fold(0.0, f64::max);
            }
            if bound * tail_scale < 1e-17 {
                break;
            }
        }
        if l > 0 {
            w.advance();
        }
        let weight = (2.0 * l as f64 + 1.0) / (4.0 * std::f64::consts::PI);
        coefficients.iter_mut().for_each(|c| *c = 0.0);
        // A part whose series ends below l adds nothing (its χ_l taken as 0, whose
        // coefficients are 0 for every row).
        for (chi, (_, s)) in chis.iter_mut().zip(parts) {
            *chi = s.chi.get(l).copied().unwrap_or(0.0);
        }
        orders.at(&chis);
        for (j, ((a, s), row_factors)) in parts.iter().zip(&factors).enumerate() {
            if l >= s.chi.len() {
                continue;
            }
            for ((c, &r), &p) in coefficients.iter_mut().zip(kinds).zip(row_factors) {
                *c += a * r.higher(&orders, j, p, chis[j]);
            }
        }
        if coefficients.iter().all(|&c| c == 0.0) {
            continue;
        }
        for (x, (wl, inv)) in w_block
            .row_mut(filled)
            .iter_mut()
            .zip(w.values().iter().zip(&inv_d_mu))
        {
            *x = weight * wl * inv;
        }
        c_block
            .column_mut(filled)
            .iter_mut()
            .zip(&coefficients)
            .for_each(|(x, c)| *x = *c);
        filled += 1;
        if filled == BLOCK {
            flush(&mut rows, &c_block, &w_block, filled);
            filled = 0;
        }
    }
    flush(&mut rows, &c_block, &w_block, filled);
    for (mut row, &kind) in rows.outer_iter_mut().zip(kinds) {
        for (a, s) in parts {
            // j = 1: Q exactly (n f^{n−1}(1 − f) for Ams_n); j = 0: the δ in bin 0.
            let (delta, single) = kind.exact_weights(s.f);
            for (r, qk) in row.iter_mut().zip(&s.q) {
                *r += a * single * qk;
            }
            row[0] += a * delta / omega0;
        }
    }
    rows
}

/// The factors of a row's j ≥ 2 coefficient that do not depend on l, for one part whose
/// forward δ is f: a Poisson row's e^{−D(1−f)} / (1 − e^{−D}) and D (1 − f) (module docs,
/// "Poisson mixtures"); an order above [`RECURRENCE_ORDERS`]'s f^n and n f^{n−1}
/// ([`high_order_coefficient`]); nothing for the orders the recurrence gives.
#[derive(Debug, Clone, Copy)]
enum RowFactors {
    Recurrence,
    Poisson {
        scale: f64,
        depth: f64,
    },
    High {
        f: f64,
        n: i32,
        f_n: f64,
        n_f_n1: f64,
    },
}

impl RowFactors {
    fn new(row: Row, f: f64) -> Self {
        match row {
            Row::Poisson(d) => Self::Poisson {
                scale: (-d * (1.0 - f)).exp() / -(-d).exp_m1(),
                depth: d * (1.0 - f),
            },
            Row::Order(n) if n > RECURRENCE_ORDERS => Self::High {
                f,
                n: n as i32,
                f_n: f.powi(n as i32),
                n_f_n1: n as f64 * f.powi(n as i32 - 1),
            },
            Row::Order(_) => Self::Recurrence,
        }
    }

    /// The j ≥ 2 coefficient at χ: for a Poisson row e^{−D(1−f)} (e^u − 1 − u) / (1 − e^{−D}),
    /// u = D (1 − f) χ; for a high order [`high_order_coefficient`]'s closed form.
    fn coefficient(self, chi: f64) -> f64 {
        match self {
            Self::Poisson { scale, depth } => {
                let u = depth * chi;
                // e^u − 1 − u, with its series where expm1 would cancel.
                let tail = if u.abs() < 1e-3 {
                    0.5 * u * u * (1.0 + u / 3.0 * (1.0 + u / 4.0))
                } else {
                    u.exp_m1() - u
                };
                scale * tail
            }
            Self::High { f, n, f_n, n_f_n1 } => closed_form(f, chi, n, f_n, n_f_n1),
            Self::Recurrence => unreachable!("orders up to RECURRENCE_ORDERS come from PartOrders"),
        }
    }
}

/// c_{n,l} = (f + (1−f)χ)^n − f^n − n f^{n−1}(1−f)χ, the j ≥ 2 part of the binomial
/// expansion, of every part at one degree l, n = 0..=n_top (0 below n = 2), by the recurrence
///
///   c_2 = a²,  c_{n+1} = x c_n + n f^{n−1} a²   (a = (1 − f)χ, x = f + a),
///
/// which follows from x^{n+1} = x·x^n; every term is of the size of the result (|x| ≤ 1), so
/// nothing cancels against the j < 2 terms, and all orders cost O(n) together. The parts run
/// side by side (the table is order-major, so each step is one vector operation across them).
struct PartOrders {
    n_top: usize,
    fs: Vec<f64>,
    table: Vec<f64>,
    x: Vec<f64>,
    a2: Vec<f64>,
    f_pow: Vec<f64>,
}

impl PartOrders {
    fn new(fs: &[f64], n_top: usize) -> Self {
        let p = fs.len();
        Self {
            n_top,
            fs: fs.to_vec(),
            table: vec![0.0; (n_top + 1) * p],
            x: vec![0.0; p],
            a2: vec![0.0; p],
            f_pow: vec![0.0; p],
        }
    }

    /// Fills the table at χ_l = `chis[j]` for part j.
    fn at(&mut self, chis: &[f64]) {
        let p = self.fs.len();
        if self.n_top < 2 {
            return; // c_0 = c_1 = 0, as the table holds
        }
        for j in 0..p {
            let a = (1.0 - self.fs[j]) * chis[j];
            self.x[j] = self.fs[j] + a;
            self.a2[j] = a * a;
            self.f_pow[j] = self.fs[j];
        }
        self.table[2 * p..3 * p].copy_from_slice(&self.a2);
        for n in 2..self.n_top {
            let (done, next) = self.table.split_at_mut((n + 1) * p);
            let current = &done[n * p..];
            let next = &mut next[..p];
            let nf = n as f64;
            for j in 0..p {
                next[j] = self.x[j] * current[j] + nf * self.f_pow[j] * self.a2[j];
                self.f_pow[j] *= self.fs[j];
            }
        }
    }

    fn get(&self, n: usize, j: usize) -> f64 {
        self.table[n * self.fs.len() + j]
    }
}

fn mixture_forward_fractions(parts: &[(f64, &AmsSeries)], orders: &[usize]) -> Vec<f64> {
    let n_top = orders
        .iter()
        .copied()
        .max()
        .unwrap_or(0)
        .min(RECURRENCE_ORDERS);
    let mut total = vec![0.0; orders.len()];
    // The parts share a grid and a reconstruction: one table of P'_l(0) for all.
    let l_max = parts.iter().map(|(_, s)| s.l_max()).max().unwrap_or(0);
    let p_prime_0 = legendre_derivatives_at_zero(l_max);
    for (a, s) in parts {
        let f = s.f;
        let forward_q = forward_hemisphere(&s.grid, &s.q);
        // The δ and Q terms, then l = 0 (∫_0^1 P_0 = 1, weight 1/2) and l ≥ 1 of the series.
        let mut fwd: Vec<f64> = orders
            .iter()
            .map(|&n| {
                let single = n as f64 * f.powi(n as i32 - 1) * (1.0 - f);
                f.powi(n as i32) + single * forward_q
            })
            .collect();
        let mut c = PartOrders::new(&[f], n_top);
        let coefficient = |c: &PartOrders, chi: f64, n: usize| {
            if n <= c.n_top {
                c.get(n, 0)
            } else {
                high_order_coefficient(f, chi, n)
            }
        };
        c.at(&[s.chi[0]]);
        for (x, &n) in fwd.iter_mut().zip(orders) {
            *x += 0.5 * coefficient(&c, s.chi[0], n);
        }
        for l in 1..s.chi.len() {
            // P'_l(0) = 0 for even l: those degrees add nothing.
            if p_prime_0[l] == 0.0 {
                continue;
            }
            c.at(&[s.chi[l]]);
            let half_integral = p_prime_0[l] / (l as f64 * (l as f64 + 1.0));
            let weight = (2.0 * l as f64 + 1.0) / 2.0;
            for (x, &n) in fwd.iter_mut().zip(orders) {
                *x += weight * coefficient(&c, s.chi[l], n) * half_integral;
            }
        }
        for (t, x) in total.iter_mut().zip(&fwd) {
            *t += a * x;
        }
    }
    total
}

fn anisotropy(parts: &[(f64, &AmsSeries)], n: usize) -> f64 {
    deviation(mixture_rows(parts, &[n]).row(0))
}

/// max_k |4π v_k − 1| of a row of bin averages: how far it is from isotropic.
fn deviation(row: ndarray::ArrayView1<f64>) -> f64 {
    row.iter()
        .map(|v| (4.0 * std::f64::consts::PI * v - 1.0).abs())
        .fold(0.0, f64::max)
}

/// n_iso(ε) for each of `epsilons`: the smallest n ≤ n_cap with max_k |4π Ams_n − 1| < ε, or
/// None, assuming (as a bisection would) that the deviation falls monotonically in n.
/// `known` holds deviations already measured (the rows a bake computes anyway). The orders are
/// searched together, a handful per pass over the degrees, where a pass costs about as much as
/// its rows (the bin integrals and the coefficients' recurrence are shared): for large n the
/// deviation falls geometrically, as the largest |f + (1 − f)χ_l|^n, so each ε's order is
/// predicted from the two nearest orders known to fail (or, inside a bracket, from its ends)
/// and the pass takes orders around the prediction, some spread over the bracket and n_cap.
/// The default scene's channels take one or two passes of about a dozen rows where a
/// bisection took about 54 single-row passes.
fn isotropic_orders(
    parts: &[(f64, &AmsSeries)],
    epsilons: &[f64],
    n_cap: usize,
    mut known: std::collections::BTreeMap<usize, f64>,
) -> Vec<Option<usize>> {
    known.retain(|&n, _| n >= 1 && n <= n_cap);
    loop {
        let mut wanted: Vec<usize> = Vec::new();
        let mut answers = Vec::new();
        for &eps in epsilons {
            let hi = known.iter().find(|(_, d)| **d < eps).map(|(n, _)| *n);
            let below = hi.unwrap_or(n_cap + 1);
            let lo = known
                .range(..below)
                .rev()
                .find(|(_, d)| **d >= eps)
                .map(|(n, d)| (*n, *d));
            let lo_n = lo.map_or(0, |(n, _)| n);
            if let Some(hi) = hi
                && hi - lo_n <= 1
            {
                answers.push(Some(hi));
                continue;
            }
            if hi.is_none() && lo_n == n_cap {
                answers.push(None);
                continue;
            }
            answers.push(None);
            let top = hi.unwrap_or(n_cap);
            // The geometric rate from the bracket's ends, else from the two orders below lo.
            let rate = match (lo, hi) {
                (Some((a, da)), Some(b)) => {
                    let db = known[&b];
                    (db / da).powf(1.0 / (b - a) as f64)
                }
                (Some((a, da)), None) => known
                    .range(..a)
                    .next_back()
                    .map_or(0.5, |(&m, &dm)| (da / dm).powf(1.0 / (a - m) as f64)),
                (None, _) => 0.5,
            };
            let guess = match lo {
                Some((a, da)) if rate > 0.0 && rate < 1.0 && da > 0.0 => {
                    a as f64 + ((eps / da).ln() / rate.ln()).max(0.0)
                }
                _ => (lo_n + top) as f64 / 2.0,
            };
            let inside = |n: f64| (n.round() as usize).clamp(lo_n + 1, top);
            let centre = inside(guess.ceil());
            for k in 0..PREDICTED_ROWS {
                wanted.push(inside(
                    centre as f64 + k as f64 - (PREDICTED_ROWS / 2) as f64,
                ));
            }
            // A few orders spread over the bracket, geometrically where it is wide, and the
            // cap, in case the prediction misses.
            for i in 1..=SPREAD_ROWS {
                let t = i as f64 / (SPREAD_ROWS + 1) as f64;
                let (a, b) = ((lo_n + 1) as f64, top as f64);
                wanted.push(inside(a * (b / a).powf(t)));
            }
            wanted.push(top);
        }
        wanted.sort_unstable();
        wanted.dedup();
        wanted.retain(|n| !known.contains_key(n));
        if wanted.is_empty() {
            return answers;
        }
        let rows = mixture_rows(parts, &wanted);
        for (&n, row) in wanted.iter().zip(rows.outer_iter()) {
            known.insert(n, deviation(row));
        }
    }
}

/// Orders an [`isotropic_orders`] pass takes around each ε's predicted order, and spread over
/// its bracket.
const PREDICTED_ROWS: usize = 5;
const SPREAD_ROWS: usize = 4;

/// f^0..=f^n (only up to degree 64 are used by the direct sum).
#[cfg(test)]
fn powers_of(f: f64, n: usize) -> Vec<f64> {
    let top = n.min(64);
    let mut p = Vec::with_capacity(top + 1);
    let mut x = 1.0;
    for _ in 0..=top {
        p.push(x);
        x *= f;
    }
    p
}

/// Computes Ams_n and F_n for n = 1..N from bin averages `bins` (1/sr) on `grid`.
pub fn ams_table(grid: &ThetaGrid, bins: &[f64], settings: AmsSettings) -> AmsTable {
    let series = AmsSeries::new(grid, bins, settings.reconstruction);
    let orders: Vec<usize> = (1..=settings.n_max).collect();
    AmsTable {
        rows: series.rows(&orders),
        forward_fraction: mixture_forward_fractions(&[(1.0, &series)], &orders),
        forward_peak_fraction: series.f,
        input_energy_error: series.input_energy_error,
        l_max: series.l_max(),
    }
}

/// Orders whose coefficients [`PartOrders`] gives; beyond them
/// [`high_order_coefficient`] (a bisection for n_iso asks for single orders in the
/// thousands, which the recurrence would reach in O(n) per degree).
const RECURRENCE_ORDERS: usize = 64;

/// c_{n,l} for n > [`RECURRENCE_ORDERS`] in closed form: the subtracted terms are ≤ n f^{n−1}
/// with f^64 ≲ 1e-7 even for ice, so it loses at most ~1e-16 · n f^{n−1} absolute.
fn high_order_coefficient(f: f64, chi: f64, n: usize) -> f64 {
    closed_form(
        f,
        chi,
        n as i32,
        f.powi(n as i32),
        n as f64 * f.powi(n as i32 - 1),
    )
}

/// [`high_order_coefficient`] given f^n and n f^{n−1} (which do not depend on χ).
fn closed_form(f: f64, chi: f64, n: i32, f_n: f64, n_f_n1: f64) -> f64 {
    let a = (1.0 - f) * chi;
    if f == 0.0 {
        return a.powi(n);
    }
    (f + a).powi(n) - f_n - n_f_n1 * a
}

/// c_{n,l} = (f + (1−f)χ)^n − f^n − n f^{n−1}(1−f)χ: the j ≥ 2 part of the binomial expansion.
/// `f_pow` holds f^0..f^min(n, 64). The direct sum, O(n) per order: the tests' check of
/// [`PartOrders`].
#[cfg(test)]
fn higher_order_coefficient(f: f64, f_pow: &[f64], chi: f64, n: usize) -> f64 {
    if n < 2 {
        return 0.0;
    }
    let a = (1.0 - f) * chi;
    if f == 0.0 {
        return a.powi(n as i32);
    }
    if n > 64 {
        // The subtracted terms are ≤ n f^{n−1} with f^64 ≲ 1e-7 even for ice, so the closed
        // form loses at most ~1e-16 · n f^{n−1} absolute.
        return (f + a).powi(n as i32) - f.powi(n as i32) - n as f64 * f.powi(n as i32 - 1) * a;
    }
    // Σ_{j=2}^{n} C(n,j) f^{n−j} a^j, summed directly (no cancellation against the j < 2 terms).
    let mut sum = 0.0;
    let mut binom = n as f64 * (n as f64 - 1.0) / 2.0; // C(n, 2)
    let mut a_pow = a * a;
    for j in 2..=n {
        sum += binom * f_pow[n - j] * a_pow;
        binom *= (n - j) as f64 / (j + 1) as f64;
        a_pow *= a;
    }
    sum
}

/// ∫_{μ>0} of a piecewise-constant bin function (1/sr): 2π Σ q_k Δμ_k over the forward
/// hemisphere, the bin straddling 90° counted by its μ ≥ 0 part.
fn forward_hemisphere(grid: &ThetaGrid, q: &[f64]) -> f64 {
    let edges = grid.edge_theta_rad();
    let half = std::f64::consts::FRAC_PI_2;
    let mut sum = 0.0;
    for k in 0..q.len() {
        let (a, b) = (edges[k], edges[k + 1]);
        if b <= half {
            sum += q[k] * (a.cos() - b.cos());
        } else if a < half {
            sum += q[k] * a.cos();
        }
    }
    2.0 * std::f64::consts::PI * sum
}

/// P'_l(0) for l = 0..=l_max, from P'_l(0) = l P_{l−1}(0) and P_l(0) by Bonnet's recurrence.
fn legendre_derivatives_at_zero(l_max: usize) -> Vec<f64> {
    let mut p = vec![0.0; l_max + 2];
    p[0] = 1.0;
    for l in 1..=l_max {
        // (l+1) P_{l+1}(0) = −l P_{l−1}(0)
        p[l + 1] = -(l as f64) * p[l - 1] / (l as f64 + 1.0);
    }
    (0..=l_max)
        .map(|l| if l == 0 { 0.0 } else { l as f64 * p[l - 1] })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recurrence gives the binomial sum Σ_{j≥2} C(n,j) f^{n−j} a^j to rounding for
    /// every order up to 200 (measured worst 6.6e-15 of the largest term), across forward deltas from none to an ice crystal's and χ of
    /// either sign down to 1e-9 (where the closed form would cancel).
    #[test]
    fn coefficient_recurrence_matches_the_binomial_sum() {
        let mut worst: f64 = 0.0;
        for f in [0.0, 0.1, 0.5, 0.9, 0.999] {
            for chi in [-0.95, -0.3, -1e-9, 1e-9, 1e-4, 0.5, 0.99, 0.999_999] {
                let mut orders = PartOrders::new(&[f], 200);
                orders.at(&[chi]);
                let out: Vec<f64> = (0..=200).map(|n| orders.get(n, 0)).collect();
                let f_pow = powers_of(f, 200);
                for n in 0..=200 {
                    // The bake's earlier direct sum up to n = 64 (a closed form above, which
                    // cancels), the sum term by term beyond.
                    let direct = if n <= 64 {
                        higher_order_coefficient(f, &f_pow, chi, n)
                    } else {
                        let a = (1.0 - f) * chi;
                        let mut binom = n as f64 * (n as f64 - 1.0) / 2.0;
                        let mut sum = 0.0;
                        for j in 2..=n {
                            sum += binom * f.powi((n - j) as i32) * a.powi(j as i32);
                            binom *= (n - j) as f64 / (j + 1) as f64;
                        }
                        sum
                    };
                    // Relative to the largest term of the sum, |a|² (f + |a|)^{n−2} C(n, 2).
                    let a = ((1.0 - f) * chi).abs();
                    let scale = a * a * (f + a).powi(n as i32 - 2) * (n * n) as f64;
                    let e = if scale > 0.0 {
                        (out[n] - direct).abs() / scale
                    } else {
                        (out[n] - direct).abs()
                    };
                    worst = worst.max(e);
                    assert!(
                        e < 1e-14,
                        "f {f}, χ {chi}, n {n}: {} against {direct}",
                        out[n]
                    );
                }
            }
        }
        println!("worst relative difference {worst:.1e}");
    }

    /// Henyey–Greenstein bin averages on a grid, by fine midpoint integration in μ.
    fn hg_bins(grid: &ThetaGrid, g: f64) -> Vec<f64> {
        let edges = grid.edge_theta_rad();
        (0..grid.len())
            .map(|k| {
                let (a, b) = (edges[k].cos(), edges[k + 1].cos());
                // ∫ p dμ in closed form: p = (1−g²)/(4π (1+g²−2gμ)^{3/2})
                let prim = |mu: f64| {
                    (1.0 - g * g)
                        / (4.0 * std::f64::consts::PI * g * (1.0 + g * g - 2.0 * g * mu).sqrt())
                };
                (prim(a) - prim(b)) / (a - b)
            })
            .collect()
    }

    #[test]
    fn mixtures_refuse_bad_weights_and_grids() {
        let grid = ThetaGrid::new(1.0).unwrap();
        let s = AmsSeries::new(&grid, &hg_bins(&grid, 0.5), Reconstruction::Spline);
        assert_eq!(
            AmsMixture::new(Vec::new()).unwrap_err(),
            TablesError::EmptyMixture
        );
        for bad in [-1e-300, f64::NAN, f64::INFINITY] {
            let e = AmsMixture::new(vec![(1.0, s.clone()), (bad, s.clone())]).unwrap_err();
            assert!(
                matches!(e, TablesError::MixtureWeight { index: 1, .. }),
                "{e:?}"
            );
        }
        let e = AmsMixture::new(vec![(0.0, s.clone())]).unwrap_err();
        assert!(e.to_string().contains("positive sum"), "{e}");
        let other = ThetaGrid::new(2.0).unwrap();
        let t = AmsSeries::new(&other, &hg_bins(&other, 0.5), Reconstruction::Spline);
        let e = AmsMixture::new(vec![(1.0, s.clone()), (1.0, t)]).unwrap_err();
        assert!(
            matches!(e, TablesError::GridMismatch { index: 1, .. }),
            "{e:?}"
        );
        assert!(AmsMixture::new(vec![(0.0, s.clone()), (2.0, s)]).is_ok());
    }

    #[test]
    fn rows_conserve_energy_do_not_ring_and_tend_to_isotropy() {
        let grid = ThetaGrid::new(0.18).unwrap();
        let bins = hg_bins(&grid, 0.85);
        let t = ams_table(&grid, &bins, AmsSettings::default());
        let omega = grid.bin_solid_angles();
        for (i, row) in t.rows.outer_iter().enumerate() {
            let e: f64 = row.iter().zip(&omega).map(|(v, o)| v * o).sum();
            assert!((e - 1.0).abs() < 1e-9, "n = {}: energy {e}", i + 1);
            let max = row.iter().cloned().fold(0.0, f64::max);
            let min = row.iter().cloned().fold(f64::INFINITY, f64::min);
            assert!(min > -1e-6 * max, "n = {}: min {min}, max {max}", i + 1);
        }
        // Ams_1 is the input.
        for (a, b) in t.rows.row(0).iter().zip(&bins) {
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-3));
        }
        // F_n falls toward 1/2; Ams_26 is close to isotropic for g = 0.85 only at 1e-1 level.
        for w in t.forward_fraction.windows(2) {
            assert!(w[1] < w[0]);
        }
        assert!(t.forward_fraction.last().unwrap() > &0.5);
    }

    #[test]
    fn funk_hecke_for_henyey_greenstein() {
        // HG convolved with itself n times is HG with g^n... only in coefficient space:
        // χ_l^(n) = g^{nl}. Check the bin average of Ams_2 against bins of HG(g²)?
        // Not exact (HG ∗ HG ≠ HG(g²)); instead check g_n = χ_1^n through the first moment.
        let grid = ThetaGrid::new(0.18).unwrap();
        let g = 0.7;
        let bins = hg_bins(&grid, g);
        let t = ams_table(&grid, &bins, AmsSettings::default());
        let edges = grid.edge_theta_rad();
        for (i, row) in t.rows.outer_iter().enumerate().take(6) {
            // ⟨μ⟩ = 2π Σ v_k ∫_bin μ dμ
            let mean: f64 = row
                .iter()
                .enumerate()
                .map(|(k, v)| {
                    let (a, b) = (edges[k].cos(), edges[k + 1].cos());
                    v * std::f64::consts::PI * (a * a - b * b)
                })
                .sum();
            let expected = bins_g(&grid, &bins).powi(i as i32 + 1);
            // The spline reconstruction's χ_1 is the bins' to O(Δθ⁶); measured deviation
            // ≤ 1.4e-6 at n = 2 … 6 (exact at n = 1; the half-bin heat-kernel blur, which
            // lowers χ_1 by 1 − e^{−s²} = 2.5e-6 per factor, gave 3.3e-6).
            eprintln!(
                "n = {}: ⟨μ⟩ {mean} vs g^n {expected}: {:.2e}",
                i + 1,
                mean - expected
            );
            assert!(
                (mean - expected).abs() < 2e-6,
                "n = {}: {mean} vs {expected}",
                i + 1
            );
        }
    }

    fn bins_g(grid: &ThetaGrid, bins: &[f64]) -> f64 {
        let edges = grid.edge_theta_rad();
        bins.iter()
            .enumerate()
            .map(|(k, v)| {
                let (a, b) = (edges[k].cos(), edges[k + 1].cos());
                v * std::f64::consts::PI * (a * a - b * b)
            })
            .sum()
    }

    #[test]
    fn henyey_greenstein_rows_match_the_exact_series() {
        // HG has χ_l = g^l, so Ams_n has χ_l = g^{nl}: its exact bin averages follow from the
        // series with the exact bin integrals. Ours start from HG's bins instead.
        let grid = ThetaGrid::new(0.18).unwrap();
        let g: f64 = 0.85;
        let bins = hg_bins(&grid, g);
        let t = ams_table(&grid, &bins, AmsSettings::default());
        let d_mu = grid.bin_mu_widths();
        let first = (1.0 / grid.step_deg()).ceil() as usize;
        for n in [2usize, 4, 8, 26] {
            let mut exact = vec![0.0; grid.len()];
            let mut w = BinIntegrals::new(&grid);
            let gn = g.powi(n as i32);
            let mut l: i32 = 0;
            while gn.powi(l) > 1e-18 {
                if l > 0 {
                    w.advance();
                }
                let c = (2.0 * l as f64 + 1.0) / (4.0 * std::f64::consts::PI) * gn.powi(l);
                for (e, (wl, dm)) in exact.iter_mut().zip(w.values().iter().zip(&d_mu)) {
                    *e += c * wl / dm;
                }
                l += 1;
            }
            let worst = t.rows.row(n - 1).as_slice().unwrap()[first..]
                .iter()
                .zip(&exact[first..])
                .map(|(a, b)| ((a - b) / b).abs())
                .fold(0.0, f64::max);
            eprintln!("HG g = 0.85, n = {n}: worst relative error for θ ≥ 1°: {worst:.2e}");
            // Measured 4.0e-6 (n = 2) falling to 2.4e-7 (n = 26) with the spline (the half-bin
            // heat-kernel blur gave 2.3e-4 to 4.8e-6): the bin-0 split near the peak and the
            // spline's O(u⁶) near the grid's resolution.
            assert!(worst < 5e-6, "n = {n}: {worst:e}");
        }
    }

    #[test]
    fn large_orders_become_isotropic() {
        let grid = ThetaGrid::new(1.0).unwrap();
        let bins = hg_bins(&grid, 0.85);
        let t = ams_table(
            &grid,
            &bins,
            AmsSettings {
                n_max: 200,
                ..AmsSettings::default()
            },
        );
        let dev = |n: usize| {
            t.rows
                .row(n - 1)
                .iter()
                .map(|v| (4.0 * std::f64::consts::PI * v - 1.0).abs())
                .fold(0.0, f64::max)
        };
        assert!(dev(200) < 1e-12, "{}", dev(200));
        assert!(dev(50) < dev(20) && dev(20) < dev(5));
        assert!((t.forward_fraction[199] - 0.5).abs() < 1e-12);
    }

    /// The multi-order search finds what a bisection over single orders finds, for one
    /// series and for a mixture with a forward δ, at orders below and above
    /// [`RECURRENCE_ORDERS`], and None where the cap is not isotropic enough.
    #[test]
    fn isotropic_orders_equal_a_bisection() {
        let bisection = |parts: &[(f64, &AmsSeries)], eps: f64, cap: usize| {
            if anisotropy(parts, cap) >= eps {
                return None;
            }
            let (mut lo, mut hi) = (0usize, cap);
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if anisotropy(parts, mid) < eps {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            Some(hi)
        };
        let grid = ThetaGrid::new(0.5).unwrap();
        let mut peaked = hg_bins(&grid, 0.8);
        peaked[0] *= 40.0;
        let (a, b, c) = (
            AmsSeries::new(&grid, &hg_bins(&grid, 0.95), Reconstruction::Spline),
            AmsSeries::new(&grid, &peaked, Reconstruction::Spline),
            AmsSeries::new(&grid, &hg_bins(&grid, 0.6), Reconstruction::Spline),
        );
        let epsilons = [1e-2, 1e-4, 1e-6, 1e-9];
        for (parts, cap) in [
            (vec![(1.0, &a)], 100_000),
            (vec![(1.0, &c)], 100_000),
            (vec![(0.3, &a), (0.7, &b)], 100_000),
            (vec![(0.3, &a), (0.7, &b)], 150),
        ] {
            let want: Vec<Option<usize>> = epsilons
                .iter()
                .map(|&e| bisection(&parts, e, cap))
                .collect();
            let got = isotropic_orders(&parts, &epsilons, cap, Default::default());
            eprintln!("cap {cap}: {got:?}");
            assert_eq!(got, want, "cap {cap}");
            // Starting from the first 26 orders' rows, as a bake does.
            let orders: Vec<usize> = (1..=26).collect();
            let known = orders
                .iter()
                .zip(mixture_rows(&parts, &orders).outer_iter())
                .map(|(&n, row)| (n, deviation(row)))
                .collect();
            assert_eq!(isotropic_orders(&parts, &epsilons, cap, known), want);
        }
    }

    #[test]
    fn forward_fractions_match_the_bins() {
        let grid = ThetaGrid::new(0.18).unwrap();
        let mut bins = hg_bins(&grid, 0.9);
        // A sharp forward peak in bin 0, as rain has.
        let omega = grid.bin_solid_angles();
        bins[0] += 0.4 / omega[0];
        let t = ams_table(&grid, &bins, AmsSettings::default());
        assert!(t.forward_peak_fraction > 0.25);
        let edges = grid.edge_theta_rad();
        for (i, row) in t.rows.outer_iter().enumerate() {
            let from_bins = forward_hemisphere(&grid, row.as_slice().unwrap());
            let _ = &edges;
            // The coefficients integrate the series over the μ > 0 half of the bin at 90°;
            // the bins can only take half its average: measured ≤ 4.2e-7 (the table contract asks 1e-4).
            assert!(
                (from_bins - t.forward_fraction[i]).abs() < 5e-7,
                "n = {}: {from_bins} vs {}",
                i + 1,
                t.forward_fraction[i]
            );
            let e: f64 = row.iter().zip(&omega).map(|(v, o)| v * o).sum();
            assert!((e - 1.0).abs() < 1e-9);
        }
    }

    /// q_i(D) = e^{−D} D^i / i! for i = 0..=i_max.
    fn poisson_weights(d: f64, i_max: usize) -> Vec<f64> {
        let mut q = vec![(-d).exp()];
        for i in 1..=i_max {
            q.push(q[i - 1] * d / i as f64);
        }
        q
    }

    #[test]
    fn poisson_rows_equal_the_sum_over_orders() {
        // The closed form against Σ_i q_i Ams_i / (1 − q_0) summed row by row until the
        // Poisson tail is below 1e-14, for a phase function with a forward δ as rain has.
        let grid = ThetaGrid::new(0.18).unwrap();
        let mut bins = hg_bins(&grid, 0.9);
        bins[0] += 0.3 / grid.bin_solid_angles()[0];
        let series = AmsSeries::new(&grid, &bins, Reconstruction::Spline);
        assert!(series.forward_peak_fraction() > 0.2);
        let omega = grid.bin_solid_angles();
        let depths = [1e-6, 0.1, 2.0, 10.0, 30.0];
        let closed = series.poisson_rows(&depths);
        for (row, &d) in closed.outer_iter().zip(&depths) {
            let mut i_max = 1;
            while 1.0 - poisson_weights(d, i_max).iter().sum::<f64>() > 1e-14 {
                i_max += 1;
            }
            let q = poisson_weights(d, i_max);
            let orders: Vec<usize> = (1..=i_max).collect();
            let ams = series.rows(&orders);
            let norm = 1.0 - q[0];
            let mut worst: f64 = 0.0;
            for k in 0..grid.len() {
                let sum: f64 = (1..=i_max).map(|i| q[i] * ams[[i - 1, k]]).sum::<f64>() / norm;
                worst = worst.max(((row[k] - sum) / sum).abs());
            }
            let energy: f64 = row.iter().zip(&omega).map(|(v, o)| v * o).sum();
            eprintln!(
                "D = {d}: {i_max} orders, worst relative difference {worst:.2e}, energy − 1 = \
                 {:.1e}",
                energy - 1.0
            );
            // Measured ≤ 1.6e-11 (D = 1e-6, where 1 − q_0 ≈ D) and |energy − 1| ≤ 6e-14.
            assert!(worst < 5e-11, "D = {d}: {worst:e}");
            assert!((energy - 1.0).abs() < 2e-13, "D = {d}: {energy}");
        }
        // D → 0: only single scattering is left.
        let ams1 = series.rows(&[1]);
        let worst = closed
            .row(0)
            .iter()
            .zip(ams1.row(0))
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        eprintln!("D = 1e-6 against Ams_1: {worst:.2e}");
        assert!(worst < 1e-6, "D = 1e-6 against Ams_1: {worst:e}"); // measured 5.4e-7
    }

    #[test]
    fn henyey_greenstein_poisson_rows_match_the_analytic_sum() {
        // Ams_i of HG(g) is HG(g^i) exactly, so M(D) = Σ q_i HG(g^i)/(1 − q_0) in closed form:
        // an independent check of the series and its blur.
        let grid = ThetaGrid::new(0.18).unwrap();
        let g: f64 = 0.85;
        let series = AmsSeries::new(&grid, &hg_bins(&grid, g), Reconstruction::Spline);
        let first = (1.0 / grid.step_deg()).ceil() as usize;
        let depths = [0.5, 5.0, 30.0];
        let rows = series.poisson_rows(&depths);
        for (row, &d) in rows.outer_iter().zip(&depths) {
            let q = poisson_weights(d, 400);
            let mut want = vec![0.0; grid.len()];
            for (i, qi) in q.iter().enumerate().skip(1) {
                let gi = g.powi(i as i32);
                let b = if gi > 1e-5 {
                    hg_bins(&grid, gi)
                } else {
                    vec![0.25 / std::f64::consts::PI; grid.len()]
                };
                for (w, v) in want.iter_mut().zip(&b) {
                    *w += qi * v / (1.0 - q[0]);
                }
            }
            let worst = row.as_slice().unwrap()[first..]
                .iter()
                .zip(&want[first..])
                .map(|(a, b)| ((a - b) / b).abs())
                .fold(0.0, f64::max);
            eprintln!("HG g = 0.85, D = {d}: worst relative error for θ ≥ 1°: {worst:.2e}");
            // Measured ≤ 2.6e-6 (D = 5), as for the rows Ams_n (the half-bin heat-kernel blur
            // gave 1.0e-4).
            assert!(worst < 3e-6, "D = {d}: {worst:e}");
        }
    }
}
