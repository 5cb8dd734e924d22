//! What the truth refuses before it traces: settings out of range, and optical depths beyond
//! [`super::MAX_OPTICAL_DEPTH`] through any medium of the scene, overlapping ones together.

use super::*;

/// Refuses a scene the tracer cannot finish, naming the part: one where a point lies deeper
/// than [`MAX_OPTICAL_DEPTH`] at some wavelength, measured as the least optical depth of the
/// axis lines through it (a grid's voxel: its three grid lines; a medium's box: its shortest
/// side; the haze: its vertical column). A path from there scatters ~τ² times to escape; a thin
/// wide layer is as thin as its thickness.
pub(super) fn check_optical_depth(
    tables: &Tables,
    frame: &Frame,
    media: &[(crate::objects::Region, f64, usize)],
    bands: &[Band],
) -> Result<(), FrameError> {
    let worst_sigma = |f: usize| {
        bands
            .iter()
            .map(|b| b.fields[f].sigma_ext)
            .fold(0.0, f64::max)
    };
    let mut worst: (f64, String) = (0.0, String::new());
    let mut consider = |tau: f64, what: String| {
        if tau > worst.0 || tau.is_nan() {
            worst = (tau, what);
        }
    };
    let mut in_grid = Vec::new();
    for (f, field) in tables.fields.iter().enumerate() {
        let tau = frame.grid.deepest_point(f) * worst_sigma(f);
        if tau > 0.0 || tau.is_nan() {
            in_grid.push(field.name.as_str());
        }
        consider(
            tau,
            format!("a point of the [[volume]] grid of field {:?}", field.name),
        );
    }
    // Fields that share the grid's voxels add up.
    if in_grid.len() > 1 {
        let n = tables.fields.len();
        consider(
            frame
                .grid
                .deepest_weighted(|rho| (0..n).map(|f| f64::from(rho[f]) * worst_sigma(f)).sum()),
            format!(
                "a point of the [[volume]] grid, its fields {} together",
                in_grid.join(" and ")
            ),
        );
    }
    for (i, &(region, _, _)) in media.iter().enumerate() {
        // Media that overlap this one add up in the overlap (counted over this one's whole
        // shortest side: an upper bound).
        let overlapping: Vec<usize> = (0..media.len())
            .filter(|&j| overlap(region, media[j].0))
            .collect();
        let beta: f64 = overlapping
            .iter()
            .map(|&j| media[j].1 * worst_sigma(media[j].2))
            .sum();
        let length = match region {
            crate::objects::Region::Box { min_m, max_m } => (max_m - min_m).min_element(),
            // Everywhere: across the scene's contents, the camera and its lights.
            crate::objects::Region::Everywhere => {
                let mut lo = frame.camera.position_m;
                let mut hi = lo;
                for l in &frame.lights {
                    lo = lo.min(l.position_m);
                    hi = hi.max(l.position_m);
                }
                for o in &frame.occluders {
                    let (a, b) = o.bounds();
                    lo = lo.min(a);
                    hi = hi.max(b);
                }
                (hi - lo).max_element().max(1.0)
            }
        };
        let others = match overlapping.len() {
            1 => String::new(),
            k => format!(" with the {} [[medium]] tables overlapping it", k - 1),
        };
        consider(
            beta * length,
            format!(
                "[[medium]] {} across its shortest side, {length:e} m{others}",
                i + 1
            ),
        );
    }
    if let Some(h) = &frame.haze {
        consider(
            h.number_density_per_m3 * worst_sigma(h.field) * h.scale_height_m,
            format!("the [haze] layer's vertical column (field {:?})", h.name),
        );
    }
    // NaN (a NaN density or cross-section) is refused too.
    if worst.0.is_nan() || worst.0 > MAX_OPTICAL_DEPTH {
        return bad(format!(
            "{} has optical depth {:.3e}, more than the {MAX_OPTICAL_DEPTH} the path tracer takes \
             on (a path through it would scatter ~τ² times): lower its number density",
            worst.1, worst.0
        ));
    }
    Ok(())
}

/// Whether two media regions share any volume (everywhere shares with all).
fn overlap(a: crate::objects::Region, b: crate::objects::Region) -> bool {
    use crate::objects::Region::{Box, Everywhere};
    match (a, b) {
        (Everywhere, _) | (_, Everywhere) => true,
        (
            Box {
                min_m: a0,
                max_m: a1,
            },
            Box {
                min_m: b0,
                max_m: b1,
            },
        ) => (a0.cmplt(b1) & b0.cmplt(a1)).all(),
    }
}

/// Checks what the truth needs of a frame and its settings, naming the value and its range.
pub fn check(frame: &Frame, settings: &Settings) -> Result<(), FrameError> {
    frame.check_view()?;
    check_settings(settings)?;
    for (i, l) in frame.lights.iter().enumerate() {
        if l.position_m.y.is_nan() || l.position_m.y <= 0.0 || !l.position_m.is_finite() {
            return bad(format!(
                "[[light]] {}: position_m = {:?} is at or below the ground (y = 0), inside an \
                 occluder: its light could never reach the scene; y > 0 required",
                i + 1,
                l.position_m.to_array()
            ));
        }
    }
    Ok(())
}

/// The settings alone, each against its allowed range.
pub(super) fn check_settings(settings: &Settings) -> Result<(), FrameError> {
    if !(SPP_RANGE.0..=SPP_RANGE.1).contains(&settings.spp) {
        return bad(format!(
            "spp = {} is outside the allowed range [{}, {}] samples per pixel",
            settings.spp, SPP_RANGE.0, SPP_RANGE.1
        ));
    }
    if !(settings.target_noise.is_finite() && (0.0..1.0).contains(&settings.target_noise)) {
        return bad(format!(
            "noise = {} is outside the allowed range [0, 1) (relative standard error)",
            crate::checks::Shown(settings.target_noise)
        ));
    }
    if settings.wavelengths_per_path > MAX_CARRIED {
        return bad(format!(
            "wavelengths_per_path = {} is outside the allowed range [1, {MAX_CARRIED}] (0: the \
             default)",
            settings.wavelengths_per_path
        ));
    }
    if !(settings.max_seconds.is_finite() && (0.0..=1e7).contains(&settings.max_seconds)) {
        return bad(format!(
            "max_seconds = {} is outside the allowed range [0, 1e7] (0: no time bound)",
            crate::checks::Shown(settings.max_seconds)
        ));
    }
    if settings.max_scatterings > MAX_BOUNCES {
        return bad(format!(
            "max_scatterings = {} is outside the allowed range [1, {MAX_BOUNCES}] (0: the \
             default)",
            settings.max_scatterings
        ));
    }
    Ok(())
}
