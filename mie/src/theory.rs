//! Closed-form single-particle results that need no Mie sum: the size parameter, the rainbow
//! angles of geometric optics with Airy's finite-size shift, and the prism minimum deviation of
//! the halos. The solver's output is checked against these (docs/physics.md §4).

use std::f64::consts::PI;

/// Size parameter x = 2πr/λ of a sphere of radius `radius_um` (µm) at vacuum wavelength
/// `wavelength_nm` (nm), in a medium of index 1.
pub fn size_parameter(radius_um: f64, wavelength_nm: f64) -> f64 {
    2.0 * PI * radius_um * 1000.0 / wavelength_nm
}

/// Scattering angle (degrees) of the order-k rainbow ray (k internal reflections) for real
/// index `n`, and the Airy shift (degrees, toward the lit side) of the intensity maximum for
/// size parameter `x`.
///
/// Descartes' minimum deviation: cos i = √((n² − 1)/(k(k + 2))), sin r = sin i / n,
/// D = 180°k + 2i − 2(k + 1)r. The maximum of Airy's integral
/// Ai(−z)² lies at z = 1.0188, so the maximum sits 1.0188 (D''/2)^{1/3} x^{−2/3} rad from the
/// geometric angle, with D'' = d²D/db² in the impact parameter b = sin i (docs/physics.md §4).
pub fn rainbow_theory(n: f64, k: u32, x: f64) -> (f64, f64) {
    let kf = k as f64;
    let cos_i = ((n * n - 1.0) / (kf * (kf + 2.0))).sqrt();
    let b = (1.0 - cos_i * cos_i).sqrt();
    let i = b.asin();
    let r = (b / n).asin();
    let d = (180.0 * kf + (2.0 * i - 2.0 * (kf + 1.0) * r).to_degrees()).rem_euclid(360.0);
    let theta = if d <= 180.0 { d } else { 360.0 - d };
    let d2 = 2.0 * b / (1.0 - b * b).powf(1.5) - 2.0 * (kf + 1.0) * b / (n * n - b * b).powf(1.5);
    let shift = 1.0188 * (0.5 * d2.abs()).cbrt() * x.powf(-2.0 / 3.0);
    (theta, shift.to_degrees())
}

/// Prism minimum deviation D = 2 asin(n sin(A/2)) − A (degrees) for apex angle `apex_deg`:
/// 60° gives the 22° halo, 90° the 46° halo (docs/physics.md §4).
pub fn minimum_deviation_deg(n: f64, apex_deg: f64) -> f64 {
    let a = apex_deg.to_radians();
    (2.0 * (n * (a / 2.0).sin()).asin() - a).to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primary_and_secondary_bows_of_water() {
        // n = 1.333: the primary bow at 137.92° (42.08° from the antisolar point), the
        // secondary at 129.11° (50.89°), computed independently from Snell's law.
        let (p, _) = rainbow_theory(1.333, 1, 1e4);
        let (s, _) = rainbow_theory(1.333, 2, 1e4);
        assert!((p - 137.922).abs() < 1e-3, "{p}");
        assert!((s - 129.109).abs() < 1e-3, "{s}");
    }

    #[test]
    fn halo_angles_of_ice() {
        let d22 = minimum_deviation_deg(1.31, 60.0);
        let d46 = minimum_deviation_deg(1.31, 90.0);
        assert!((d22 - 21.8393).abs() < 1e-3, "{d22}");
        assert!((d46 - 45.7334).abs() < 1e-3, "{d46}");
    }

    #[test]
    fn size_parameter_of_a_10_um_drop() {
        let x = size_parameter(10.0, 550.0);
        assert!((x - 114.2397).abs() < 1e-3, "{x}");
    }

    #[test]
    fn rainbow_angles_match_the_tabulated_values() {
        // docs/physics.md §4, water IAPWS 20 °C at 550 nm: n = 1.3347, 138.17° and 128.67°.
        let (t1, _) = rainbow_theory(1.3347, 1, 1e6);
        let (t2, _) = rainbow_theory(1.3347, 2, 1e6);
        assert!((t1 - 138.17).abs() < 0.02, "{t1}");
        assert!((t2 - 128.67).abs() < 0.02, "{t2}");
    }

    #[test]
    fn airy_shift_scales_as_x_to_minus_two_thirds() {
        let (_, a) = rainbow_theory(1.3347, 1, 1000.0);
        let (_, b) = rainbow_theory(1.3347, 1, 8000.0);
        assert!((a / b - 4.0).abs() < 1e-9, "{a} {b}");
        // r = 500 µm at 550 nm (x ≈ 5712): about 0.3° beyond Descartes' angle.
        let (_, s) = rainbow_theory(1.3347, 1, 5712.0);
        assert!(s > 0.25 && s < 0.35, "{s}");
    }

    #[test]
    fn halo_minimum_deviation_matches_the_tabulated_values() {
        // docs/physics.md §4 at 550 nm: 21.915° and 45.949° (n_ice = 1.3110).
        let n = crate::Material::Ice
            .refractive_index(550.0, -20.0)
            .unwrap()
            .re;
        assert!((minimum_deviation_deg(n, 60.0) - 21.915).abs() < 0.01);
        assert!((minimum_deviation_deg(n, 90.0) - 45.949).abs() < 0.01);
    }
}
