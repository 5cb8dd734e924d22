//! The voxel grid every per-sun pass lights: the voxels' optics, upwind sweeps along a
//! direction of travel (the layer order every sweep follows, on the CPU or the GPU), trilinear
//! lookups of the results, and sets of directions of equal solid angle. A sweep takes the
//! state one layer back, bilinear in the layer behind (clear air beyond the box's faces), and
//! the trapezoid of β_ext over the step: the short characteristics of docs/physics.md §7.8
//! (Max et al. 2004's reduced light) and §7.10 (the transport's sweeps).

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use runtime::FieldTable;

use crate::volume::DensityGrid;

/// Voxels of smaller optical depth β_ext h (green) are left out of the diffusion solve.
pub const MIN_DIFFUSION_VOXEL_DEPTH: f64 = 1e-4;

/// The most passes a sweep makes over the layers of a periodic grid's repeating axis: 1000
/// periods, as far as the truth follows a path along a periodic layer
/// ([`DensityGrid::longest_path_m`]).
pub const WRAP_PASSES: usize = 1000;

/// A sweep over a repeating axis has settled when a pass changed its last layer's state by
/// at most this share of the state's largest value there: well inside the transport's own
/// tolerance (docs/log.md, "Periodic volumes in coupled").
pub const WRAP_TOLERANCE: f64 = 1e-6;

/// The passes of an upwind sweep along axis `a` of `grid`: one where the axis ends at the
/// box's faces; on a periodic grid's repeating axis, where the layer before the first is the
/// last, passes until the last layer has settled ([`settled`]), each starting from the last
/// layer's state of the pass before (the first from clear air), at most [`WRAP_PASSES`].
pub(crate) fn passes(grid: &DensityGrid, a: usize) -> usize {
    if grid.wraps(a) { WRAP_PASSES } else { 1 }
}

/// The passes of a sweep that adds each layer to its result as it goes ([`passes`]): across a
/// repeating axis the passes until the last layer settles add nothing, then one more adds.
pub(crate) struct Passes {
    counts: bool,
    cap: usize,
}

impl Passes {
    /// The passes of a sweep along axis `a` of `grid`.
    pub(crate) fn over(grid: &DensityGrid, a: usize) -> Self {
        Self {
            counts: !grid.wraps(a),
            cap: passes(grid, a),
        }
    }

    /// Whether this pass adds to the result.
    pub(crate) fn counts(&self) -> bool {
        self.counts
    }

    /// After pass `pass`, whose last layer was `before` it (none before the first) and is
    /// `after`: whether the sweep is done (the pass counted); else whether the next counts.
    pub(crate) fn done_after<const N: usize>(
        &mut self,
        pass: usize,
        before: Option<&[[f64; N]]>,
        after: &[[f64; N]],
    ) -> bool {
        if self.counts {
            return true;
        }
        self.counts = pass + 1 == self.cap || before.is_some_and(|old| settled(old, after));
        false
    }
}

/// Whether a repeating sweep's last layer has settled: its states `new` after a pass against
/// `old` before it ([`WRAP_TOLERANCE`]).
pub(crate) fn settled<const N: usize>(old: &[[f64; N]], new: &[[f64; N]]) -> bool {
    let (change, scale) = largest_difference(old, new);
    change <= WRAP_TOLERANCE * scale
}

/// The largest |a − b| over the values of `a` and `b`, and the largest |b|: the scale to judge
/// that difference by.
pub fn largest_difference<const N: usize>(a: &[[f64; N]], b: &[[f64; N]]) -> (f64, f64) {
    let scale = b.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let difference = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    (difference, scale)
}

/// Per-voxel optics of the grid, per channel.
pub struct Voxels {
    /// β_ext (1/m).
    pub ext: Vec<[f64; 3]>,
    /// β_sca (1/m).
    pub sca: Vec<[f64; 3]>,
    /// κ_tr = Σ_f β_ext,f (σ_tr/σ_t)_f.
    pub transport: Vec<[f64; 3]>,
    /// Σ_f β_sca,f g_f: the forward part of the first-scattered source.
    pub g_sca: Vec<[f64; 3]>,
}

/// A field's asymmetry parameter g per channel, from its transport factor 1 − αg (0 where it
/// does not scatter).
pub fn asymmetry(field: &FieldTable) -> [f64; 3] {
    let tf = field.transport_factor.expect("checked by render");
    std::array::from_fn(|c| {
        if field.albedo[c] > 0.0 {
            (1.0 - tf[c]) / field.albedo[c]
        } else {
            0.0
        }
    })
}

/// The optics of every voxel of `grid` with `fields` (field i = grid channel i).
pub fn voxels(fields: &[&FieldTable], grid: &DensityGrid) -> Voxels {
    let n = grid.data.len();
    let mut v = Voxels {
        ext: vec![[0.0; 3]; n],
        sca: vec![[0.0; 3]; n],
        transport: vec![[0.0; 3]; n],
        g_sca: vec![[0.0; 3]; n],
    };
    let g: Vec<[f64; 3]> = fields.iter().map(|f| asymmetry(f)).collect();
    v.ext
        .par_iter_mut()
        .zip(v.sca.par_iter_mut())
        .zip(v.transport.par_iter_mut().zip(v.g_sca.par_iter_mut()))
        .zip(grid.data.par_iter())
        .for_each(|(((ext, sca), (transport, g_sca)), rho)| {
            for (f, field) in fields.iter().enumerate() {
                let r = f64::from(rho[f]);
                if r <= 0.0 {
                    continue;
                }
                let tf = field.transport_factor.expect("checked by render");
                for c in 0..3 {
                    let e = r * field.sigma_ext_m2[c];
                    let s = r * field.sigma_sca_m2[c];
                    ext[c] += e;
                    sca[c] += s;
                    transport[c] += e * tf[c];
                    g_sca[c] += s * g[f][c];
                }
            }
        });
    v
}

/// Voxel sizes per axis (m).
pub fn voxel_size(grid: &DensityGrid) -> [f64; 3] {
    std::array::from_fn(|a| (grid.max_m[a] - grid.min_m[a]) / grid.dims[a] as f64)
}

/// A state of N numbers per voxel centre, computed layer by layer along the direction of
/// travel `l` (an upwind sweep): each voxel's state is `update(i, back, ds)` from the state
/// `back` at the point one layer back along −l, `ds` the path length between the two. `back`
/// is bilinear in that layer between its voxel centres; between the outermost centres and the
/// box's faces it blends linearly to `outside` at the face (the light arriving from clear
/// air), and beyond the faces it is `outside`. So light enters through every face the sun
/// sees, also where the sun is so low that the point one layer back stays within half a voxel
/// of the face it crossed (before, that point took the edge voxels' state, and a slab lit at
/// a grazing angle was lit only through its side). On a periodic grid the layer's repeating
/// axes wrap, and a sweep across a repeating axis makes [`passes`] over it.
pub fn sweep<const N: usize>(
    grid: &DensityGrid,
    l: DVec3,
    outside: [f64; N],
    update: impl Fn(usize, [f64; N], f64) -> [f64; N] + Sync,
) -> Vec<[f64; N]> {
    let dims = grid.dims;
    let way = Way::along(grid, l);
    let (a, ds, (shift_b, shift_c)) = (way.axis, way.ds, way.shift);
    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
    let stride = [1, dims[0], dims[0] * dims[1]];
    let wrap = (grid.wraps(b), grid.wraps(c));
    let mut state = vec![[0.0f64; N]; grid.data.len()];
    let layers = layer_order(dims[a], way.forward);
    let last = layers[layers.len() - 1];
    let layer_of = |state: &[[f64; N]], k: usize| -> Vec<[f64; N]> {
        (0..dims[b] * dims[c])
            .map(|m| state[k * stride[a] + (m % dims[b]) * stride[b] + (m / dims[b]) * stride[c]])
            .collect()
    };
    for pass in 0..passes(grid, a) {
        let before = (pass > 0).then(|| layer_of(&state, last));
        for (step, &k) in layers.iter().enumerate() {
            let prev = if step > 0 {
                Some(layers[step - 1])
            } else {
                (pass > 0).then_some(last)
            };
            let back_of = |layer: usize, u: f64, v: f64| -> [f64; N] {
                upwind(
                    |ub, vc| &state[layer * stride[a] + ub * stride[b] + vc * stride[c]],
                    (dims[b], dims[c]),
                    (u, v),
                    outside,
                    wrap,
                )
            };
            let layer: Vec<(usize, [f64; N])> = (0..dims[b] * dims[c])
                .into_par_iter()
                .map(|m| {
                    let (ub, vc) = (m % dims[b], m / dims[b]);
                    let i = k * stride[a] + ub * stride[b] + vc * stride[c];
                    let back = prev.map_or(outside, |p| {
                        back_of(p, ub as f64 + shift_b, vc as f64 + shift_c)
                    });
                    (i, update(i, back, ds))
                })
                .collect();
            for (i, v) in layer {
                state[i] = v;
            }
        }
        if before.is_some_and(|old| settled(&old, &layer_of(&state, last))) {
            break;
        }
    }
    state
}

/// How an upwind sweep along the direction of travel `l` crosses the grid: layer by layer
/// along the axis it travels most along (towards +axis when `forward`), the step `ds` (m)
/// between two layers, and the point one layer back along the layer's axes (axis + 1) % 3,
/// (axis + 2) % 3, in voxel units.
pub(crate) struct Way {
    pub(crate) axis: usize,
    pub(crate) forward: bool,
    pub(crate) ds: f64,
    pub(crate) shift: (f64, f64),
}

impl Way {
    pub(crate) fn along(grid: &DensityGrid, l: DVec3) -> Self {
        let h = voxel_size(grid);
        let a = (0..3)
            .max_by(|&i, &j| l[i].abs().total_cmp(&l[j].abs()))
            .expect("three axes");
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        let ds = h[a] / l[a].abs();
        Self {
            axis: a,
            forward: l[a] > 0.0,
            ds,
            shift: (-ds * l[b] / h[b], -ds * l[c] / h[c]),
        }
    }
}

/// The layers 0 … n − 1 of an upwind sweep in the order it visits them: ascending when its
/// direction travels towards +axis (`forward`), else descending.
pub(crate) fn layer_order(n: usize, forward: bool) -> Vec<usize> {
    if forward {
        (0..n).collect()
    } else {
        (0..n).rev().collect()
    }
}

/// The state at the point (u, v) of a layer of nb × nc centres (in voxel units), `at(ub, vc)`
/// each centre's: bilinear between the centres; between the outermost centres and the
/// layer's edges half a voxel beyond them it blends linearly to `outside` (the light arriving
/// from clear air), and beyond the edges it is `outside`. Along an axis that `wrap`s (a
/// periodic grid's x or z) the centres repeat instead: the last centre's next is the first.
/// The upwind sweeps' lookup one layer back ([`sweep`] and the transport's).
#[inline(always)]
pub(crate) fn upwind<'a, const N: usize>(
    at: impl Fn(usize, usize) -> &'a [f64; N],
    (nb, nc): (usize, usize),
    (u, v): (f64, f64),
    outside: [f64; N],
    wrap: (bool, bool),
) -> [f64; N] {
    // The share of `outside` at coordinate u of an axis of n centres (0 between the centres,
    // rising linearly to 1 at the faces half a voxel beyond them; 0 on a repeating axis).
    let face_share = |u: f64, n: f64, wraps: bool| {
        if wraps {
            0.0
        } else {
            ((-u).max(u - (n - 1.0)) / 0.5).clamp(0.0, 1.0)
        }
    };
    let kept = (1.0 - face_share(u, nb as f64, wrap.0)) * (1.0 - face_share(v, nc as f64, wrap.1));
    if kept <= 0.0 {
        return outside;
    }
    // The lower centre, the upper one and the upper one's weight along an axis of n centres.
    let corners = |u: f64, n: usize, wraps: bool| {
        if wraps {
            crate::volume::wrapped_corners(u, n)
        } else {
            let u = u.clamp(0.0, (n - 1) as f64);
            let lo = u.floor() as usize;
            (lo, (lo + 1).min(n - 1), u - lo as f64)
        }
    };
    let ((u0, u1, s), (v0, v1, t)) = (corners(u, nb, wrap.0), corners(v, nc, wrap.1));
    let (p00, p10, p01, p11) = (at(u0, v0), at(u1, v0), at(u0, v1), at(u1, v1));
    std::array::from_fn(|n| {
        let inside = (1.0 - s) * (1.0 - t) * p00[n]
            + s * (1.0 - t) * p10[n]
            + (1.0 - s) * t * p01[n]
            + s * t * p11[n];
        kept * inside + (1.0 - kept) * outside[n]
    })
}

/// Optical depth towards the light at every voxel centre, per channel:
/// the depth one layer back plus the trapezoid of β_ext over the step (from the box's face, or
/// clear air, half a voxel back for the first).
pub fn sun_depths(grid: &DensityGrid, ext: &[[f64; 3]], l: DVec3) -> Vec<[f64; 3]> {
    // State: τ per channel, then β_ext per channel (for the trapezoid); clear air outside.
    let state = sweep::<6>(grid, l, [0.0; 6], |i, back, ds| {
        let here = ext[i];
        std::array::from_fn(|n| match n {
            0..=2 => back[n] + 0.5 * ds * (here[n] + back[n + 3]),
            _ => here[n - 3],
        })
    });
    state.iter().map(|s| [s[0], s[1], s[2]]).collect()
}

/// Trilinear interpolation of per-voxel `values` at `p` (voxel centres; clamped at the box's
/// edge voxels), over the voxels `active` says (all if `None`), renormalized over them; zero
/// outside the box or where no active voxel contributes.
pub fn trilinear<const N: usize>(
    grid: &DensityGrid,
    values: &[[f64; N]],
    active: Option<&[bool]>,
    p: DVec3,
) -> [f64; N] {
    let Some(taps) = grid.taps(p) else {
        return [0.0; N];
    };
    let mut out = [0.0; N];
    let mut total = 0.0;
    for (i, w) in taps.into_iter().flatten() {
        if active.is_some_and(|m| !m[i]) {
            continue;
        }
        total += w;
        for c in 0..N {
            out[c] += w * values[i][c];
        }
    }
    if active.is_some() && total > 0.0 {
        out.iter_mut().for_each(|v| *v /= total);
    }
    out
}

/// `count` directions of equal solid angle 4π/count, a Fibonacci set (y the polar axis).
pub fn fibonacci_directions(count: usize) -> Vec<DVec3> {
    let golden = PI * (3.0 - 5f64.sqrt());
    (0..count)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / count as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), z, r * phi.sin())
        })
        .collect()
}

/// The size of a voxel as one length, (h_x h_y h_z)^{1/3} (m).
pub fn voxel_length(grid: &DensityGrid) -> f64 {
    let h = voxel_size(grid);
    (h[0] * h[1] * h[2]).cbrt()
}

/// What the sweeps' tests light: an uneven grid and a lumpy medium on it.
#[cfg(test)]
pub(crate) mod fixture {
    use super::*;

    /// 7 × 5 × 6 voxels of uneven size, so that every axis leads some directions.
    pub(crate) fn uneven_grid() -> DensityGrid {
        let dims = [7, 5, 6];
        DensityGrid {
            min_m: DVec3::new(-1.0, -0.5, 0.0),
            max_m: DVec3::new(1.4, 0.7, 1.1),
            dims,
            data: vec![[0.0; crate::volume::MAX_FIELDS]; dims.iter().product()],
            periodic: false,
        }
    }

    /// A smooth, deterministic value in [0, 1] per index `i` and key `k` (a lumpy field).
    pub(crate) fn wobble(i: usize, k: usize) -> f64 {
        0.5 + 0.5 * ((i * 7 + k * 13) as f64 * 0.61).sin()
    }
}

#[cfg(test)]
mod tests {
    use super::fixture::uneven_grid;
    use super::*;

    /// A periodic grid of uniform β is lit as the same grid repeated without end: its optical
    /// depth towards the sun at every voxel centre equals that deep inside a bounded grid of 16
    /// × 16 periods (far from the faces the sun enters by), for suns that travel most along x
    /// or z (the sweep across a repeating axis, in passes; measured 8.2·10⁻⁷, within the
    /// passes' tolerance) and along y.
    #[test]
    fn a_periodic_grid_is_lit_as_its_repeated_box() {
        let mut grid = uneven_grid();
        grid.periodic = true;
        let beta = 3.0;
        let [nx, ny, nz] = grid.dims;
        let k = 16;
        let mut wide = uneven_grid();
        wide.dims = [k * nx, ny, k * nz];
        wide.data = vec![[0.0; crate::volume::MAX_FIELDS]; k * k * nx * ny * nz];
        wide.max_m.x = wide.min_m.x + k as f64 * (grid.max_m.x - grid.min_m.x);
        wide.max_m.z = wide.min_m.z + k as f64 * (grid.max_m.z - grid.min_m.z);
        for (elevation, azimuth) in [(20.0f64, 210.0f64), (25.0, 250.0), (70.0, 190.0)] {
            // Light travelling towards +x and +z: it enters the wide grid at its low faces,
            // and its far corner (high x and z) is deep inside it.
            let (e, a) = (elevation.to_radians(), azimuth.to_radians());
            let l = -DVec3::new(e.cos() * a.sin(), e.sin(), e.cos() * a.cos());
            let tau = sun_depths(&grid, &vec![[beta; 3]; grid.data.len()], l);
            let deep = sun_depths(&wide, &vec![[beta; 3]; wide.data.len()], l);
            let mut worst: f64 = 0.0;
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let got = tau[x + nx * (y + ny * z)][1];
                        let (wx, wz) = (k * nx - 1, k * nz - 1);
                        let want = deep[wx + k * nx * (y + ny * wz)][1];
                        worst = worst.max((got - want).abs() / want);
                    }
                }
            }
            eprintln!("sun {elevation}°/{azimuth}°: worst relative difference {worst:.1e}");
            assert!(worst < 1e-6, "sun {elevation}°/{azimuth}°: {worst:e}");
        }
    }
}
