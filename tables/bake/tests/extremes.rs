//! The bake at the edges of what it accepts: monodisperse and very broad
//! distributions, 500 scattering orders, Δθ = 0.01° and 1°, wavelengths at the ends of the
//! colour tables, crystals of extreme aspect ratio, and inputs that must be refused with their
//! range. Each accepted case must give finite tables whose every row integrates to 1 over the
//! sphere, is non-negative (to the Legendre series' ripple), and whose F_i lie in [0, 1] and come
//! no further from ½ with n. Each test prints its measured worst deviation.

use format::read_field_exr;
use mie::ThetaGrid;

mod common;

use common::{forward_fractions, plan, rows_of, run};

/// Worst |∫ row dΩ − 1|, worst negative value relative to the row's maximum, over every row
/// and channel of every field; F_i checked in [0, 1] and |F_i − ½| non-increasing.
struct Worst {
    energy: f64,
    negative: f64,
}

fn bake_and_check(what: &str, text: &str) -> Worst {
    bake_checked(what, text).0
}

/// [`bake_and_check`], keeping the bake's directory.
fn bake_checked(what: &str, text: &str) -> (Worst, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let plan = plan(text, dir.path()).unwrap();
    run(&plan).unwrap_or_else(|e| panic!("{what}: {e:#}"));
    let grid = ThetaGrid::new(plan.scene.theta_step_deg).unwrap();
    let omega = grid.bin_solid_angles();
    let mut worst = Worst {
        energy: 0.0,
        negative: 0.0,
    };
    for field in &plan.scene.fields {
        let image = read_field_exr(dir.path().join(format!("{}.exr", field.name))).unwrap();
        assert_eq!(image.n_max(), plan.scene.n_max);
        assert_eq!(image.angle_count(), grid.len());
        for c in 0..3 {
            for (r, row) in rows_of(&image)[c].iter().enumerate() {
                assert!(row.iter().all(|v| v.is_finite()), "{what}: non-finite row");
                let e: f64 = row.iter().zip(&omega).map(|(v, o)| v * o).sum();
                let max = row.iter().cloned().fold(0.0, f64::max);
                let min = row.iter().cloned().fold(f64::INFINITY, f64::min);
                worst.energy = worst.energy.max((e - 1.0).abs());
                worst.negative = worst.negative.max(-min / max);
                // 32-bit floats in the EXR: 1e-5 is their summation noise over 18001 bins.
                assert!(
                    (e - 1.0).abs() < 1e-5,
                    "{what} {} c{c} n = {}: ∫ = {e}",
                    field.name,
                    r + 1
                );
                assert!(
                    min >= -1e-4 * max,
                    "{what} {} c{c} n = {}: min {min:e} max {max:e}",
                    field.name,
                    r + 1
                );
            }
            let f = &forward_fractions(&image, c);
            for w in f.windows(2) {
                assert!(
                    (w[1] - 0.5).abs() <= (w[0] - 0.5).abs() + 1e-12,
                    "{what}: F moves away from ½: {w:?}"
                );
            }
            assert!(
                f.iter().all(|&v| (0.0..=1.0).contains(&v)),
                "{what}: F outside [0, 1]: {:?}",
                &f[..4.min(f.len())]
            );
        }
    }
    println!(
        "{what}: worst |∫ Ams_n dΩ − 1| = {:.2e}, worst negative/max = {:.2e}",
        worst.energy, worst.negative
    );
    (worst, dir)
}

fn scene(header: &str, fields: &str) -> String {
    format!("[scene]\nname = \"x\"\nquality = \"draft\"\n{header}\n{fields}")
}

const CLOUD: &str = "[[field]]\nname = \"c\"\nkind = \"cloud\"\ndistribution = { kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }\n";

#[test]
fn monodisperse_and_very_broad_distributions() {
    let fields = "[[field]]\nname = \"mono\"\nkind = \"cloud\"\ndistribution = { kind = \"monodisperse\", radius_um = 10 }\n\n\
                  [[field]]\nname = \"broad\"\nkind = \"rain\"\ndistribution = { kind = \"lognormal\", median_radius_um = 10, sigma_g = 3.0 }\n\n\
                  [[field]]\nname = \"tiny\"\nkind = \"cloud\"\ndistribution = { kind = \"monodisperse\", radius_um = 0.001 }\n\n\
                  [[field]]\nname = \"mp\"\nkind = \"rain\"\ndistribution = { kind = \"marshall_palmer\", rain_rate_mm_h = 100 }\n";
    bake_and_check(
        "monodisperse 10 µm, 1 nm; lognormal σ_g = 3; Marshall–Palmer 100 mm/h",
        &scene("spectral = \"rgb3\"\nn_max = 8", fields),
    );
}

/// Small, strongly absorbing, high-index spheres (m = 3 + 10i, r_eff 0.03 µm) scatter more
/// backward than forward: F_1 ≈ 0.38 and g < 0, F_n − ½ alternating in sign toward 0. The
/// manifest refused such a bake after computing it (F_1 outside [½, 1]); it is physical.
#[test]
fn small_strongly_absorbing_high_index_spheres_lean_backward() {
    let fields = "[[field]]\nname = \"metal\"\nkind = \"cloud\"\nrefractive_index = [3.0, 10.0]\n\
                  distribution = { kind = \"gamma\", r_eff_um = 0.03, v_eff = 0.1 }\n";
    let text = scene("spectral = \"rgb3\"\nn_max = 8", fields);
    let (_, dir) = bake_checked("m = 3 + 10i, r_eff 0.03 µm", &text);
    let image = read_field_exr(dir.path().join("metal.exr")).unwrap();
    for c in 0..3 {
        let f = forward_fractions(&image, c);
        println!("channel {c}: F_1..F_4 = {:?}", &f[..4]);
        assert!(f[0] < 0.45, "channel {c}: F_1 = {}", f[0]);
        assert!(f[1] > 0.5, "channel {c}: F_2 = {}", f[1]);
    }
}

#[test]
fn five_hundred_scattering_orders() {
    let w = bake_and_check("N = 500", &scene("spectral = \"rgb3\"\nn_max = 500", CLOUD));
    assert!(w.energy < 1e-5);
}

#[test]
fn angle_steps_of_a_hundredth_and_of_one_degree() {
    for step in [0.01, 1.0] {
        bake_and_check(
            &format!("Δθ = {step}°"),
            &scene(
                &format!("spectral = \"rgb3\"\nn_max = 4\ntheta_step_deg = {step}"),
                CLOUD,
            ),
        );
    }
}

#[test]
fn wavelengths_at_the_ends_of_the_colour_tables() {
    bake_and_check(
        "360–830 nm, 5 wavelengths",
        &scene(
            "spectral = \"spectral\"\nwavelengths = 5\nwavelength_min_nm = 360\nwavelength_max_nm = 830\nn_max = 4",
            CLOUD,
        ),
    );
}

#[test]
fn crystals_of_extreme_aspect_ratio_and_full_distortion() {
    let fields = "[[field]]\nname = \"plate\"\nkind = \"ice\"\naspect_ratio = 0.02\nmax_dimension_um = 50\n\n\
                  [[field]]\nname = \"needle\"\nkind = \"ice\"\naspect_ratio = 50\nmax_dimension_um = 500\n\n\
                  [[field]]\nname = \"rough\"\nkind = \"snow\"\nroughness = 1.0\n";
    bake_and_check(
        "crystals AR 0.02 and 50, δ = 1",
        &scene("spectral = \"rgb3\"\nn_max = 4", fields),
    );
}

/// Inputs outside the accepted ranges are refused with a message naming the value and the
/// range, and nothing is written.
#[test]
fn out_of_range_inputs_are_refused_with_the_range() {
    let cases = [
        (
            "spectral = \"spectral\"\nwavelength_min_nm = 300",
            CLOUD.to_string(),
            "[360, 830]",
        ),
        ("theta_step_deg = 0.007", CLOUD.to_string(), "180"),
        ("n_max = 0", CLOUD.to_string(), "n_max"),
        (
            "",
            CLOUD.replace(
                "{ kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }",
                "{ kind = \"marshall_palmer\", rain_rate_mm_h = 0 }",
            ),
            "rain",
        ),
        (
            "",
            CLOUD.replace(
                "{ kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }",
                "{ kind = \"monodisperse\", radius_um = 0 }",
            ),
            "radius",
        ),
        (
            "",
            CLOUD.replace("kind = \"cloud\"", "kind = \"cloud\"\ntemperature_c = -40"),
            "[-12, 99]",
        ),
        (
            "",
            "[[field]]\nname = \"i\"\nkind = \"ice\"\nroughness = 1.5\n".to_string(),
            "roughness",
        ),
        // So broad that its mass reaches 2 cm drops, beyond x = 2e5: named with the field, the
        // wavelength (the first the bake meets, the sizes' pilot's), the radii and the range.
        (
            "spectral = \"rgb3\"",
            CLOUD.replace(
                "{ kind = \"gamma\", r_eff_um = 10, v_eff = 0.1 }",
                "{ kind = \"lognormal\", median_radius_um = 100, sigma_g = 3 }",
            ),
            "field \"c\" at 440 nm, radius",
        ),
    ];
    for (header, fields, needle) in cases {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let err = match plan(&scene(header, &fields), &out).and_then(|p| run(&p).map(|_| ())) {
            Ok(()) => panic!("accepted: {header} {fields}"),
            Err(e) => format!("{e:#}"),
        };
        println!("refused: {err}");
        assert!(err.contains(needle), "{err:?} does not name {needle:?}");
        assert!(!out.exists(), "{err}: output written");
    }
}
