//! A phase function given as a table (`kind = "tabulated"`): p(θ) at the user's angles, one
//! column per channel or per wavelength, baked through the same tables as the droplets, the
//! crystals and the Henyey–Greenstein lobes (docs/physics.md, "Given phase functions").
//!
//! **The interpolation is ours and stated**: p is linear in θ between the table's nodes (which
//! may be spaced as the user likes, from 0° to 180°). Everything after follows from that one
//! function exactly, in closed form:
//!
//! - its integral over the sphere, 2π ∫₀^π p(θ) sin θ dθ, which is the normalization *found*
//!   (reported; the user's table need not be normalized, we divide by it);
//! - each bin's average over its solid angle, ∫ p dΩ / Ω, so Ams_1 equals the normalized table
//!   to rounding;
//! - g = 2π ∫ p cos θ sin θ dθ.
//!
//! On a segment [u, v] of width h and midpoint m where p = p_u + (p_v − p_u)(θ − u)/h,
//! ∫ sin θ dθ = 2 sin m sin(h/2) and ∫ (θ − u) sin θ dθ = 2 cos m (sin(h/2) − (h/2) cos(h/2))
//! plus h sin m sin(h/2), both free of cancellation (the bracket by its series for small h);
//! and ∫ p cos θ sin θ dθ = ¼ ∫_{2u}^{2v} p(φ/2) sin φ dφ is the same form on doubled angles.

use serde::{Deserialize, Serialize};

use crate::grid::ThetaGrid;
use crate::phase::{Origin, PhaseFunction, TableOrigin};

/// A `kind = "tabulated"` field: the user's table and the field's cross-section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TabulatedField {
    /// The file the table came from, as the scene names it (for the manifest and messages).
    pub file: String,
    /// The table's angles (degrees), increasing strictly from 0 to 180.
    pub theta_deg: Vec<f64>,
    /// p(θ) at those angles, as given (any scale), one column per channel (1 for all, or R, G,
    /// B) or per wavelength of the scene.
    pub columns: Vec<Vec<f64>>,
    /// Extinction cross-section per particle (m²) per channel.
    pub extinction_m2: [f64; 3],
}

/// Why a table cannot be a phase function: the row (0-based, in the table's order) and why.
#[derive(Debug, Clone, PartialEq)]
pub struct TableError {
    /// The row at fault, if one is.
    pub row: Option<usize>,
    /// What is wrong, in words.
    pub message: String,
}

impl TabulatedField {
    /// Checks the table: at least two rows, θ strictly increasing from exactly 0 to exactly
    /// 180, every value finite and ≥ 0, and every column with a positive integral.
    pub fn check(&self) -> Result<(), TableError> {
        let at = |row: usize, message: String| {
            Err(TableError {
                row: Some(row),
                message,
            })
        };
        let t = &self.theta_deg;
        if t.len() < 2 {
            return Err(TableError {
                row: None,
                message: format!("{} rows: a table needs two at least (0° and 180°)", t.len()),
            });
        }
        if t[0] != 0.0 {
            return at(0, format!("θ = {}°: the table must start at 0°", t[0]));
        }
        for (i, pair) in t.windows(2).enumerate() {
            if pair[1].is_nan() || pair[1] <= pair[0] {
                return at(
                    i + 1,
                    format!(
                        "θ = {}° after {}°: the angles must increase strictly",
                        pair[1], pair[0]
                    ),
                );
            }
        }
        let last = t[t.len() - 1];
        if last != 180.0 {
            return at(
                t.len() - 1,
                format!("θ = {last}°: the table must end at 180°"),
            );
        }
        for (c, column) in self.columns.iter().enumerate() {
            if column.len() != t.len() {
                return Err(TableError {
                    row: None,
                    message: format!(
                        "column {} has {} values for {} angles",
                        c + 1,
                        column.len(),
                        t.len()
                    ),
                });
            }
            if let Some((i, p)) = column
                .iter()
                .enumerate()
                .find(|(_, p)| !(p.is_finite() && **p >= 0.0))
            {
                return at(
                    i,
                    format!(
                        "p = {p} in column {} (θ = {}°): values must be finite and ≥ 0",
                        c + 1,
                        t[i]
                    ),
                );
            }
            if self.sphere_integral(c) <= 0.0 {
                return Err(TableError {
                    row: None,
                    message: format!("column {} is zero everywhere", c + 1),
                });
            }
        }
        Ok(())
    }

    /// 2π ∫₀^π p(θ) sin θ dθ of column `column` as given: the normalization found (1 for a
    /// table already per sr and normalized; 4π for one normalized to 4π).
    pub fn sphere_integral(&self, column: usize) -> f64 {
        2.0 * std::f64::consts::PI * self.integral(column, 0.0, std::f64::consts::PI, 1.0)
    }

    /// The average over each bin of `grid` of column `column`, normalized (1/sr): exact for
    /// the linear interpolant.
    pub fn bins(&self, column: usize, grid: &ThetaGrid) -> Vec<f64> {
        let edges = grid.edge_theta_rad();
        let total = self.integral(column, 0.0, std::f64::consts::PI, 1.0);
        edges
            .windows(2)
            .map(|e| {
                let (a, b) = (e[0], e[1]);
                // ∫ sin θ dθ over the bin, as 2 sin m sin(h/2).
                let sine = 2.0 * (0.5 * (a + b)).sin() * (0.5 * (b - a)).sin();
                self.integral(column, a, b, 1.0) / (sine * total) / (2.0 * std::f64::consts::PI)
            })
            .collect()
    }

    /// g = ⟨cos θ⟩ of column `column`, exact for the linear interpolant.
    pub fn asymmetry(&self, column: usize) -> f64 {
        let pi = std::f64::consts::PI;
        // ∫ p cos θ sin θ dθ = ¼ ∫_{0}^{2π} p(φ/2) sin φ dφ.
        0.25 * self.integral(column, 0.0, pi, 2.0) / self.integral(column, 0.0, pi, 1.0)
    }

    /// The column the scene's wavelength `j` reads: the one column, else its own (the scene
    /// checks that a table with several has one per wavelength; in rgb3, one per channel).
    pub fn column_of(&self, j: usize) -> usize {
        if self.columns.len() == 1 { 0 } else { j }
    }

    /// The field's optics from column `column` at `wavelength_nm` on `grid`, with the
    /// cross-section of `channel` (albedo 1: a given albedo replaces it, as any field's).
    pub fn phase(
        &self,
        column: usize,
        channel: usize,
        wavelength_nm: f64,
        grid: ThetaGrid,
    ) -> PhaseFunction {
        PhaseFunction::given(
            wavelength_nm,
            self.extinction_m2[channel],
            (self.asymmetry(column), self.bins(column, &grid), grid),
            Origin::Table(TableOrigin {
                file: self.file.clone(),
                column: column + 1,
                rows: self.theta_deg.len(),
                sphere_integral: self.sphere_integral(column),
            }),
        )
    }

    /// ∫_{ka}^{kb} p(φ/k) sin φ dφ for the linear interpolant p of column `column`, over
    /// [a, b] ⊂ [0, π] (radians): ∫ p sin θ dθ for k = 1, 4 ∫ p cos θ sin θ dθ for k = 2.
    fn integral(&self, column: usize, a: f64, b: f64, k: f64) -> f64 {
        let to_rad = std::f64::consts::PI / 180.0;
        let (t, p) = (&self.theta_deg, &self.columns[column]);
        let at = |i: usize, x: f64| {
            let (u, v) = (t[i] * to_rad, t[i + 1] * to_rad);
            p[i] + (p[i + 1] - p[i]) * ((x - u) / (v - u))
        };
        // The first segment that reaches past a.
        let first = t.partition_point(|&x| x * to_rad <= a).saturating_sub(1);
        let mut sum = 0.0;
        for i in first..t.len() - 1 {
            let (u, v) = (t[i] * to_rad, t[i + 1] * to_rad);
            if u >= b {
                break;
            }
            let (lo, hi) = (u.max(a), v.min(b));
            if hi <= lo {
                continue;
            }
            sum += linear_sine(k * lo, k * hi, at(i, lo), at(i, hi));
        }
        sum
    }
}

/// ∫_u^v q(φ) sin φ dφ for q linear from `qu` at u to `qv` at v.
fn linear_sine(u: f64, v: f64, qu: f64, qv: f64) -> f64 {
    let (m, half) = (0.5 * (u + v), 0.5 * (v - u));
    let s0 = 2.0 * m.sin() * half.sin();
    let s1 = 2.0 * m.cos() * sin_minus_x_cos(half) + 2.0 * half * m.sin() * half.sin();
    qu * s0 + (qv - qu) / (v - u) * s1
}

/// sin x − x cos x, by its series below 0.01 (where the difference cancels): x³/3 − x⁵/30.
fn sin_minus_x_cos(x: f64) -> f64 {
    if x.abs() < 1e-2 {
        let x2 = x * x;
        x * x2 * (1.0 / 3.0 - x2 / 30.0 + x2 * x2 / 840.0)
    } else {
        x.sin() - x * x.cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hg::HgLobe;

    fn table_of(f: impl Fn(f64) -> f64, n: usize) -> TabulatedField {
        let theta_deg: Vec<f64> = (0..=n).map(|i| 180.0 * i as f64 / n as f64).collect();
        let column = theta_deg.iter().map(|t| f(t.to_radians().cos())).collect();
        TabulatedField {
            file: "test".into(),
            theta_deg,
            columns: vec![column],
            extinction_m2: [1.0; 3],
        }
    }

    /// A table linear in θ is its own interpolant: its integral and g in closed form, and
    /// its bins normalized to Σ p̄ Ω = 1.
    #[test]
    fn a_linear_table_integrates_exactly() {
        let t = TabulatedField {
            file: "t".into(),
            theta_deg: vec![0.0, 180.0],
            columns: vec![vec![2.0, 0.0]],
            extinction_m2: [1.0; 3],
        };
        // 2π ∫ 2(1 − θ/π) sin θ dθ = 4π (∫ sin θ dθ − ∫ θ sin θ dθ / π) = 4π (2 − 1).
        let want = 4.0 * std::f64::consts::PI;
        assert!((t.sphere_integral(0) / want - 1.0).abs() < 1e-14);
        let grid = ThetaGrid::new(0.18).unwrap();
        let total: f64 = t
            .bins(0, &grid)
            .iter()
            .zip(grid.bin_solid_angles())
            .map(|(p, o)| p * o)
            .sum();
        assert!((total - 1.0).abs() < 1e-12, "Σ p̄ Ω = {total}");
        // ∫ (1 − θ/π) cos θ sin θ dθ = −½ ∫ θ/π sin 2θ dθ = 1/4, over ∫ (1 − θ/π) sin θ dθ
        // = 1: g = 1/4.
        assert!(
            (t.asymmetry(0) - 0.25).abs() < 1e-14,
            "g {}",
            t.asymmetry(0)
        );
    }

    /// A fine table of an HG lobe reproduces its exact bins and g to the interpolation's
    /// second-order error, and the bins of any table are normalized.
    #[test]
    fn a_fine_hg_table_reproduces_the_lobe() {
        let lobe = HgLobe::one(0.7);
        let t = table_of(|mu| 4.0 * std::f64::consts::PI * lobe.value(mu), 36_000);
        assert!((t.sphere_integral(0) / (4.0 * std::f64::consts::PI) - 1.0).abs() < 1e-8);
        let grid = ThetaGrid::new(0.18).unwrap();
        let (got, want) = (t.bins(0, &grid), lobe.bins(&grid));
        let worst = got
            .iter()
            .zip(&want)
            .map(|(g, w)| (g / w - 1.0).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "worst relative bin error {worst}");
        assert!((t.asymmetry(0) - 0.7).abs() < 1e-8, "g {}", t.asymmetry(0));
    }

    #[test]
    fn bad_tables_are_refused_with_their_row() {
        let good = table_of(|_| 1.0, 4);
        assert!(good.check().is_ok());
        let mut t = good.clone();
        t.theta_deg[2] = t.theta_deg[1];
        assert_eq!(t.check().unwrap_err().row, Some(2));
        let mut t = good.clone();
        t.columns[0][3] = -1.0;
        assert_eq!(t.check().unwrap_err().row, Some(3));
        let mut t = good.clone();
        t.columns[0][1] = f64::NAN;
        assert_eq!(t.check().unwrap_err().row, Some(1));
        let mut t = good.clone();
        *t.theta_deg.last_mut().unwrap() = 170.0;
        assert!(t.check().unwrap_err().message.contains("end at 180"));
        let mut t = good;
        t.columns[0] = vec![0.0; 5];
        assert!(t.check().unwrap_err().message.contains("zero everywhere"));
    }
}
