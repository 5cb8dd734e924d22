//! Refractive indices m = n + iκ of liquid water and ice (docs/physics.md §3).
//!
//! - Water, real part: IAPWS R9-97 (Harvey et al. 1998, J. Phys. Chem. Ref. Data 27, 761),
//!   a function of wavelength, temperature and density; the density at 1 atm comes from the
//!   IAPWS-95 table in `mie/data/water/density_1atm.csv` (linear in T). Valid 200–1100 nm and
//!   −12…99 °C (the density table; IAPWS R9-97 itself holds from 261.15 K).
//! - Water, imaginary part: Segelstein 1981 (`mie/data/refractive_index/water_segelstein1981.csv`).
//! - Ice: Warren & Brandt 2008 at −7 °C (`mie/data/refractive_index/ice_warren_brandt2008.csv`),
//!   both parts.
//!
//! # Interpolation
//! Between tabulated wavelengths n is linear in λ and κ is linear in ln κ versus ln λ (κ spans
//! many decades). Outside a table's range, or the IAPWS validity, the functions return an
//! error naming the range; nothing is extrapolated or clamped.

use std::sync::OnceLock;

use num_complex::Complex64;

use crate::error::MieError;

const SEGELSTEIN_CSV: &str = include_str!("../data/refractive_index/water_segelstein1981.csv");
const WARREN_BRANDT_CSV: &str = include_str!("../data/refractive_index/ice_warren_brandt2008.csv");
const DENSITY_CSV: &str = include_str!("../data/water/density_1atm.csv");

/// Water IAPWS R9-97 validity in wavelength (nm).
pub const WATER_WAVELENGTH_NM: (f64, f64) = (200.0, 1100.0);

/// A particle material with a tabulated refractive index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Material {
    /// Liquid water: IAPWS R9-97 n (200–1100 nm, −12…99 °C), Segelstein 1981 κ.
    Water,
    /// Ice Ih at −7 °C: Warren & Brandt 2008.
    Ice,
}

impl Material {
    /// m = n + iκ at `wavelength_nm` (vacuum). `temperature_c` applies to water only.
    pub fn refractive_index(
        self,
        wavelength_nm: f64,
        temperature_c: f64,
    ) -> Result<Complex64, MieError> {
        match self {
            Material::Water => water_refractive_index(wavelength_nm, temperature_c),
            Material::Ice => ice_refractive_index(wavelength_nm),
        }
    }

    /// Lower-case name, "water" or "ice".
    pub fn name(self) -> &'static str {
        match self {
            Material::Water => "water",
            Material::Ice => "ice",
        }
    }
}

/// Liquid water: IAPWS R9-97 real part at 1 atm and `temperature_c`, Segelstein κ.
pub fn water_refractive_index(
    wavelength_nm: f64,
    temperature_c: f64,
) -> Result<Complex64, MieError> {
    let (lo, hi) = WATER_WAVELENGTH_NM;
    if !(wavelength_nm.is_finite() && (lo..=hi).contains(&wavelength_nm)) {
        return Err(MieError::WavelengthOutOfTable {
            material: "water (IAPWS R9-97)",
            wavelength_nm,
            min_nm: lo,
            max_nm: hi,
        });
    }
    let rho = water_density_kg_m3(temperature_c)?;
    let n = iapws_r9_97(wavelength_nm, temperature_c + 273.15, rho);
    let kappa = segelstein().kappa(wavelength_nm, "water (Segelstein 1981)")?;
    Ok(Complex64::new(n, kappa))
}

/// Ice Ih at −7 °C, Warren & Brandt 2008.
pub fn ice_refractive_index(wavelength_nm: f64) -> Result<Complex64, MieError> {
    let table = warren_brandt();
    let what = "ice (Warren & Brandt 2008)";
    Ok(Complex64::new(
        table.n(wavelength_nm, what)?,
        table.kappa(wavelength_nm, what)?,
    ))
}

/// IAPWS R9-97: (n²−1)/(n²+2) = ρ̄ [a0 + a1 ρ̄ + a2 T̄ + a3 λ̄² T̄ + a4/λ̄² + a5/(λ̄²−λ̄_UV²)
/// + a6/(λ̄²−λ̄_IR²) + a7 ρ̄²], T̄ = T/273.15 K, ρ̄ = ρ/1000 kg m⁻³, λ̄ = λ/0.589 µm.
pub fn iapws_r9_97(wavelength_nm: f64, temperature_k: f64, density_kg_m3: f64) -> f64 {
    const A: [f64; 8] = [
        0.244257733,
        9.74634476e-3,
        -3.73234996e-3,
        2.68678472e-4,
        1.58920570e-3,
        2.45934259e-3,
        0.900704920,
        -1.66626219e-2,
    ];
    const LAMBDA_UV: f64 = 0.2292020;
    const LAMBDA_IR: f64 = 5.432937;
    let t = temperature_k / 273.15;
    let rho = density_kg_m3 / 1000.0;
    let l2 = (wavelength_nm / 589.0).powi(2);
    let rhs = rho
        * (A[0]
            + A[1] * rho
            + A[2] * t
            + A[3] * l2 * t
            + A[4] / l2
            + A[5] / (l2 - LAMBDA_UV * LAMBDA_UV)
            + A[6] / (l2 - LAMBDA_IR * LAMBDA_IR)
            + A[7] * rho * rho);
    // n² = (1 + 2 rhs)/(1 − rhs)
    ((1.0 + 2.0 * rhs) / (1.0 - rhs)).sqrt()
}

/// Density of liquid water at 1 atm (IAPWS-95 table), linear in temperature.
pub fn water_density_kg_m3(temperature_c: f64) -> Result<f64, MieError> {
    let table = density_table();
    let (t0, t1) = (table[0].0, table[table.len() - 1].0);
    if !(temperature_c.is_finite() && (t0..=t1).contains(&temperature_c)) {
        return Err(MieError::OutOfRange {
            name: "water temperature (°C)",
            value: temperature_c,
            range: "[-12, 99] (liquid at 1 atm, IAPWS R9-97 validity)",
        });
    }
    let i = table
        .partition_point(|&(t, _)| t <= temperature_c)
        .clamp(1, table.len() - 1);
    let (ta, ra) = table[i - 1];
    let (tb, rb) = table[i];
    Ok(ra + (rb - ra) * (temperature_c - ta) / (tb - ta))
}

/// A (λ, n, κ) table with λ ascending.
struct IndexTable {
    wavelength_nm: Vec<f64>,
    n: Vec<f64>,
    kappa: Vec<f64>,
}

impl IndexTable {
    fn parse(csv: &str) -> Self {
        let mut t = IndexTable {
            wavelength_nm: Vec::new(),
            n: Vec::new(),
            kappa: Vec::new(),
        };
        for line in csv.lines().filter(|l| !l.starts_with('#')).skip(1) {
            let mut f = line
                .split(',')
                .map(|v| v.trim().parse::<f64>().expect("numeric table"));
            t.wavelength_nm.push(f.next().expect("wavelength column"));
            t.n.push(f.next().expect("n column"));
            t.kappa.push(f.next().expect("k column"));
        }
        t
    }

    /// Index i with λ_i ≤ λ ≤ λ_{i+1}, or the range error.
    fn bracket(
        &self,
        wavelength_nm: f64,
        material: &'static str,
    ) -> Result<(usize, f64), MieError> {
        let (lo, hi) = (
            self.wavelength_nm[0],
            self.wavelength_nm[self.wavelength_nm.len() - 1],
        );
        if !(wavelength_nm.is_finite() && (lo..=hi).contains(&wavelength_nm)) {
            return Err(MieError::WavelengthOutOfTable {
                material,
                wavelength_nm,
                min_nm: lo,
                max_nm: hi,
            });
        }
        let i = self
            .wavelength_nm
            .partition_point(|&w| w <= wavelength_nm)
            .clamp(1, self.wavelength_nm.len() - 1)
            - 1;
        Ok((i, wavelength_nm))
    }

    fn n(&self, wavelength_nm: f64, material: &'static str) -> Result<f64, MieError> {
        let (i, w) = self.bracket(wavelength_nm, material)?;
        let (wa, wb) = (self.wavelength_nm[i], self.wavelength_nm[i + 1]);
        Ok(self.n[i] + (self.n[i + 1] - self.n[i]) * (w - wa) / (wb - wa))
    }

    fn kappa(&self, wavelength_nm: f64, material: &'static str) -> Result<f64, MieError> {
        let (i, w) = self.bracket(wavelength_nm, material)?;
        let (wa, wb) = (self.wavelength_nm[i], self.wavelength_nm[i + 1]);
        let (ka, kb) = (self.kappa[i], self.kappa[i + 1]);
        if ka <= 0.0 || kb <= 0.0 {
            return Ok(ka + (kb - ka) * (w - wa) / (wb - wa));
        }
        let s = (w.ln() - wa.ln()) / (wb.ln() - wa.ln());
        Ok((ka.ln() + (kb.ln() - ka.ln()) * s).exp())
    }
}

fn segelstein() -> &'static IndexTable {
    static TABLE: OnceLock<IndexTable> = OnceLock::new();
    TABLE.get_or_init(|| IndexTable::parse(SEGELSTEIN_CSV))
}

fn warren_brandt() -> &'static IndexTable {
    static TABLE: OnceLock<IndexTable> = OnceLock::new();
    TABLE.get_or_init(|| IndexTable::parse(WARREN_BRANDT_CSV))
}

/// (t_C, ρ) rows of the density table.
fn density_table() -> &'static [(f64, f64)] {
    static TABLE: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    TABLE.get_or_init(|| {
        DENSITY_CSV
            .lines()
            .filter(|l| !l.starts_with('#'))
            .skip(1)
            .map(|line| {
                let v: Vec<f64> = line
                    .split(',')
                    .map(|f| f.trim().parse().expect("numeric density table"))
                    .collect();
                (v[1], v[2])
            })
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iapws_check_values() {
        // IAPWS R9-97 Table 3 check values (docs/physics.md §3).
        for (t, rho, lambda_um, n) in [
            (298.15, 997.047435, 0.5893, 1.33285819),
            (298.15, 997.047435, 0.2265, 1.39277824),
            (773.15, 30.4758534, 0.5893, 1.00949307),
        ] {
            let ours = iapws_r9_97(lambda_um * 1000.0, t, rho);
            assert!(
                (ours - n).abs() < 5e-9,
                "{t} K, {lambda_um} µm: {ours} vs {n}"
            );
        }
    }

    #[test]
    fn water_at_20c_matches_physics_table() {
        // docs/physics.md §3: n (IAPWS, 20 °C) to 4 decimals and Segelstein κ to 3 digits.
        let rows = [
            (400.0, 1.3436, 1.58e-9),
            (450.0, 1.3396, 8.07e-10),
            (500.0, 1.3368, 9.23e-10),
            (550.0, 1.3347, 2.46e-9),
            (600.0, 1.3330, 9.69e-9),
            (650.0, 1.3317, 1.67e-8),
            (700.0, 1.3305, 3.37e-8),
        ];
        for (lambda, n, kappa) in rows {
            let m = water_refractive_index(lambda, 20.0).unwrap();
            assert!((m.re - n).abs() <= 0.6e-4, "{lambda} nm: n = {}", m.re);
            assert!(
                (m.im - kappa).abs() / kappa < 0.03,
                "{lambda} nm: κ = {}",
                m.im
            );
        }
    }

    #[test]
    fn warren_brandt_table_points() {
        let rows = [
            (400.0, 1.3194, 2.365e-11),
            (450.0, 1.3157, 9.239e-11),
            (500.0, 1.3130, 5.889e-10),
            (550.0, 1.3110, 2.289e-09),
            (600.0, 1.3094, 5.730e-09),
            (650.0, 1.3080, 1.430e-08),
            (700.0, 1.3069, 2.900e-08),
        ];
        for (lambda, n, kappa) in rows {
            let m = ice_refractive_index(lambda).unwrap();
            assert_eq!(m.re, n, "{lambda} nm");
            assert!(
                (m.im - kappa).abs() / kappa < 1e-12,
                "{lambda} nm: κ = {}",
                m.im
            );
        }
    }

    #[test]
    fn out_of_range_is_an_error_naming_the_range() {
        let e = water_refractive_index(1500.0, 20.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("1500") && e.contains("[200, 1100]"), "{e}");
        let e = water_refractive_index(550.0, 150.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("150") && e.contains("[-12, 99]"), "{e}");
        assert!(ice_refractive_index(10.0).is_err());
    }
}
