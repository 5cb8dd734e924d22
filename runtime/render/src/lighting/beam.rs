//! The sun's beam through the grid (the reduced sunlight with what it loses to scattering), the
//! first per-sun pass of the grid models: an upwind sweep along the sun's direction of travel
//! ([`super::lattice::sweep`]) that keeps, across each step of optical depth τ, the share
//! e^{−τ(1 − αf)} of the beam (the continuum update: of the light a step removes, the forward
//! peak's share αf stays in the beam; docs/physics.md §7.9) and splits what it loses into
//! the diffuse light's sources: the part scattered out of the peak, α(1 − f)/(1 − αf) of the
//! loss (isotropic source of the diffusion and the transport), and its forward part
//! α(g − f)/(1 − αf) (their first-moment source; δ-M scaling, Wiscombe 1977). The GPU twin is
//! [`super::beam_gpu`].

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use runtime::{FieldTable, sample};

use super::lattice::sweep;
use crate::volume::{DensityGrid, MAX_FIELDS};

/// What the beam's sweep needs of a voxel: β_ext and β_sca, the split's forward peak f (but
/// for the hemisphere split, whose F_n depends on the scatterings the beam kept), the
/// asymmetry g, and the share of β_sca (green) whose scatterings the forward peak's blur
/// counts (0 without a blur).
#[derive(Debug, Clone, Copy)]
pub struct BeamMedium {
    /// β_ext per channel (1/m).
    pub ext: [f64; 3],
    /// β_sca per channel (1/m).
    pub sca: [f64; 3],
    /// The split's forward peak f per channel (0 for the hemisphere split and without the
    /// buffer's source).
    pub f: [f64; 3],
    /// The asymmetry parameter g per channel.
    pub g: [f64; 3],
    /// The share of β_sca (green) whose scatterings the peak's blur counts.
    pub share: f64,
}

/// The beam at a voxel centre, per unit solar irradiance: what the sweep carries from one
/// layer to the next and what the diffuse light's passes read.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct BeamState {
    /// I: the beam's intensity per channel (1 outside the box).
    pub intensity: [f64; 3],
    /// The depth the forward peak's blur reads: the scatterings the beam kept, n (the
    /// hemisphere split, Riley et al. 2004 §4.2), or the peak's optical depth D (the δ-split).
    pub depth: f64,
    /// β_ext at the voxel (1/m), the next step's trapezoid.
    pub ext: [f64; 3],
    /// β_sca at the voxel (1/m), the next step's trapezoid.
    pub sca: [f64; 3],
    /// The loss scattered out of the peak, α(1 − f)/(1 − αf) of the loss, per metre: the
    /// diffuse light's isotropic source.
    pub dropped: [f64; 3],
    /// Its forward part, α(g − f)/(1 − αf) of the loss, per metre: the diffuse light's
    /// first-moment source.
    pub forward: [f64; 3],
    /// The whole loss per metre.
    pub loss: [f64; 3],
}

/// f64 values in a [`BeamState`], the lattice sweep's state per voxel.
const STATE: usize = std::mem::size_of::<BeamState>() / 8;

/// Where the sweep takes the forward peak f the beam keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeakFrom {
    /// Each voxel's [`BeamMedium::f`].
    Medium,
    /// F_n of the fields' tables at the scatterings the beam kept so far, n + 1 + τ (Riley
    /// et al. 2004 §4.2's forward hemisphere).
    Tables,
}

/// What the beam's [`BeamState::depth`] counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Depth {
    /// The peak's optical depth D: [`BeamMedium::share`] of β_sca along the path.
    Peak,
    /// The scatterings the beam kept, n: the albedo times the optical depth along the path.
    Scatterings,
}

/// Outside the box: the sunlight unscattered (I = 1, n = D = 0) in clear air.
fn outside() -> BeamState {
    BeamState {
        intensity: [1.0; 3],
        ..BeamState::default()
    }
}

/// The beam swept along `l`, the direction of travel, through `medium` on `grid`, its peak
/// taken as `rule` says (the tables `fields` read only by [`PeakFrom::Tables`]).
pub fn beam_sweep(
    fields: &[&FieldTable],
    grid: &DensityGrid,
    medium: &[BeamMedium],
    l: DVec3,
    rule: (PeakFrom, Depth),
) -> Vec<BeamState> {
    let swept = sweep::<STATE>(grid, l, bytemuck::cast(outside()), |i, back, ds| {
        let b: BeamState = bytemuck::cast(back);
        bytemuck::cast(step(fields, grid, (&medium[i], i), &b, ds, rule))
    });
    swept.into_iter().map(bytemuck::cast).collect()
}

/// The beam at voxel `i` of `medium` from `b`, the beam one layer back, a step `ds` metres
/// behind (trapezoid of β_ext and β_sca; clear air beyond the box's faces).
fn step(
    fields: &[&FieldTable],
    grid: &DensityGrid,
    (m, i): (&BeamMedium, usize),
    b: &BeamState,
    ds: f64,
    (peak, depth): (PeakFrom, Depth),
) -> BeamState {
    let ext: [f64; 3] = std::array::from_fn(|c| 0.5 * (b.ext[c] + m.ext[c]));
    let sca: [f64; 3] = std::array::from_fn(|c| 0.5 * (b.sca[c] + m.sca[c]));
    let tau: [f64; 3] = ext.map(|e| e * ds);
    let f = match peak {
        PeakFrom::Tables => {
            let rho: [f64; MAX_FIELDS] = std::array::from_fn(|f| f64::from(grid.data[i][f]));
            sample::forward_fraction_mix(fields, &rho, b.depth + 1.0 + tau[1])
        }
        PeakFrom::Medium => m.f,
    };
    let mut out = BeamState {
        depth: b.depth,
        ext: m.ext,
        sca: m.sca,
        ..BeamState::default()
    };
    if ext[1] > 0.0 {
        out.depth += match depth {
            Depth::Scatterings => sca[1] / ext[1] * tau[1],
            Depth::Peak => sca[1] * ds * m.share,
        };
    }
    for c in 0..3 {
        let albedo = if ext[c] > 0.0 { sca[c] / ext[c] } else { 0.0 };
        let lost = 1.0 - albedo * f[c];
        let kept = b.intensity[c] * (-tau[c] * lost).exp();
        out.intensity[c] = kept;
        if lost > 1e-12 && ds > 0.0 {
            let loss = (b.intensity[c] - kept) / ds;
            out.dropped[c] = loss * albedo * (1.0 - f[c]) / lost;
            out.forward[c] = loss * albedo * (m.g[c] - f[c]) / lost;
            out.loss[c] = loss;
        }
    }
    out
}
