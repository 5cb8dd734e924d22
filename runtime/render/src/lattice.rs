//! Light on the voxel grid, shared by the models that light a grid once per sun and gather
//! per view (`max`, `coupled`): the voxels' optics, upwind sweeps along a direction of travel,
//! the reduced sunlight and skylight at voxel centres, and trilinear lookups of the results.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use runtime::FieldTable;

use crate::geometry::box_span;
use crate::shading::coefficients;
use crate::skylight::SkyLight;
use crate::{DensityGrid, Frame};

/// Voxels of smaller optical depth β_ext h (green) are left out of the diffusion solve.
pub const MIN_DIFFUSION_VOXEL_DEPTH: f64 = 1e-4;

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
/// a grazing angle was lit only through its side).
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
    let mut state = vec![[0.0f64; N]; grid.data.len()];
    let layers = layer_order(dims[a], way.forward);
    for (step, &k) in layers.iter().enumerate() {
        let prev = (step > 0).then(|| layers[step - 1]);
        let back_of = |layer: usize, u: f64, v: f64| -> [f64; N] {
            upwind(
                |ub, vc| &state[layer * stride[a] + ub * stride[b] + vc * stride[c]],
                (dims[b], dims[c]),
                (u, v),
                outside,
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
/// from clear air), and beyond the edges it is `outside`. The upwind sweeps' lookup one layer
/// back ([`sweep`] and the transport's).
#[inline(always)]
pub(crate) fn upwind<'a, const N: usize>(
    at: impl Fn(usize, usize) -> &'a [f64; N],
    (nb, nc): (usize, usize),
    (u, v): (f64, f64),
    outside: [f64; N],
) -> [f64; N] {
    // The share of `outside` at coordinate u of an axis of n centres (0 between the centres,
    // rising linearly to 1 at the faces half a voxel beyond them).
    let face_share = |u: f64, n: f64| ((-u).max(u - (n - 1.0)) / 0.5).clamp(0.0, 1.0);
    let kept = (1.0 - face_share(u, nb as f64)) * (1.0 - face_share(v, nc as f64));
    if kept <= 0.0 {
        return outside;
    }
    let (u, v) = (u.clamp(0.0, (nb - 1) as f64), v.clamp(0.0, (nc - 1) as f64));
    let (u0, v0) = (u.floor() as usize, v.floor() as usize);
    let (u1, v1) = ((u0 + 1).min(nb - 1), (v0 + 1).min(nc - 1));
    let (s, t) = (u - u0 as f64, v - v0 as f64);
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

/// Cells of a [`ShadowMap`] per axis at most.
pub const MAX_SHADOW_CELLS: usize = 1024;

/// The sunlight the volume leaves on the plane of the grid's bottom, and so at every point
/// below it (the line from such a point to the sun meets nothing before that plane): the
/// ground's and the air's light below the grid ([`crate::shading::air_shadow`]), one march to
/// the sun per cell instead of per pixel and point. Cells of the grid's horizontal voxel size
/// (at most [`MAX_SHADOW_CELLS`] a side) over where the shadow can fall: the footprint swept
/// back along the sun's horizontal direction by the grid's height; bilinear between cell
/// centres, 1 outside.
#[derive(Debug, Clone)]
pub struct ShadowMap {
    /// The region's corner (x, z) (m).
    origin: [f64; 2],
    /// A cell's size (x, z) (m).
    cell: [f64; 2],
    /// Cells along x and z (≥ 2 each).
    dims: [usize; 2],
    /// The plane's height, the grid's bottom (m).
    bottom: f64,
    /// Unit vector towards the sun.
    sun: DVec3,
    /// Per cell (x fastest), the fraction left per channel.
    values: Vec<[f64; 3]>,
}

impl ShadowMap {
    /// The map of `grid` with the sun towards `sun` (above the horizon), each cell's value
    /// `left(q)` at its centre q on the plane.
    pub fn new(grid: &DensityGrid, sun: DVec3, left: impl Fn(DVec3) -> [f64; 3] + Sync) -> Self {
        let (lo, hi) = (grid.min_m, grid.max_m);
        // From the plane the line to the sun crosses the grid's height over t ≤ height/l_y,
        // moving sun_h t: the footprint swept back by that.
        let reach = (hi.y - lo.y) / sun.y.max(1e-6);
        let shift = [sun.x * reach, sun.z * reach];
        let x = [lo.x - shift[0].max(0.0), hi.x - shift[0].min(0.0)];
        let z = [lo.z - shift[1].max(0.0), hi.z - shift[1].min(0.0)];
        let voxel = voxel_size(grid);
        let count = |extent: f64, h: f64| ((extent / h).ceil() as usize).clamp(2, MAX_SHADOW_CELLS);
        let dims = [count(x[1] - x[0], voxel[0]), count(z[1] - z[0], voxel[2])];
        let cell = [
            (x[1] - x[0]) / dims[0] as f64,
            (z[1] - z[0]) / dims[1] as f64,
        ];
        let values = (0..dims[0] * dims[1])
            .into_par_iter()
            .map(|i| {
                let (a, b) = (i % dims[0], i / dims[0]);
                left(DVec3::new(
                    x[0] + (a as f64 + 0.5) * cell[0],
                    lo.y,
                    z[0] + (b as f64 + 0.5) * cell[1],
                ))
            })
            .collect();
        Self {
            origin: [x[0], z[0]],
            cell,
            dims,
            bottom: lo.y,
            sun,
            values,
        }
    }

    /// The map of `frame`'s grid and sun through the extinction of `fields`, less each field's
    /// forward peak share with `peaks` ([`transmittance_to_sun`]).
    pub fn of(fields: &[&FieldTable], frame: &Frame, peaks: Option<&[[f64; 3]]>) -> Self {
        let sun = frame.sun.direction();
        Self::new(&frame.grid, sun, |q| {
            transmittance_to_sun(fields, &frame.grid, q, sun, peaks)
        })
    }

    /// The fraction of sunlight left at `p` (at or below the grid's bottom).
    pub fn at(&self, p: DVec3) -> [f64; 3] {
        let q = p + ((self.bottom - p.y) / self.sun.y) * self.sun;
        let u = (q.x - self.origin[0]) / self.cell[0] - 0.5;
        let w = (q.z - self.origin[1]) / self.cell[1] - 0.5;
        let [nx, nz] = self.dims;
        if u < -0.5 || w < -0.5 || u > nx as f64 - 0.5 || w > nz as f64 - 0.5 {
            return [1.0; 3];
        }
        let (i, j) = (
            (u.floor().max(0.0) as usize).min(nx - 2),
            (w.floor().max(0.0) as usize).min(nz - 2),
        );
        let (s, t) = (
            (u - i as f64).clamp(0.0, 1.0),
            (w - j as f64).clamp(0.0, 1.0),
        );
        let v = |a: usize, b: usize| self.values[a + nx * b];
        std::array::from_fn(|c| {
            (v(i, j)[c] * (1.0 - s) + v(i + 1, j)[c] * s) * (1.0 - t)
                + (v(i, j + 1)[c] * (1.0 - s) + v(i + 1, j + 1)[c] * s) * t
        })
    }

    /// The map as the shaders read it after the sky light's table (compose.wgsl's
    /// `shadow_map_at`): (x₀, z₀, cell x, cell z), (n_x, n_z, bottom, 0), the cells (rgb, 0).
    pub fn gpu_rows(&self) -> Vec<[f32; 4]> {
        let mut rows = vec![
            [
                self.origin[0] as f32,
                self.origin[1] as f32,
                self.cell[0] as f32,
                self.cell[1] as f32,
            ],
            [
                self.dims[0] as f32,
                self.dims[1] as f32,
                self.bottom as f32,
                0.0,
            ],
        ];
        rows.extend(
            self.values
                .iter()
                .map(|v| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0]),
        );
        rows
    }
}

/// The fraction of the sunlight the volume leaves at `p` along the sun direction `sun`, by a
/// ray march of half-voxel steps (for points outside the box: the ground and the air below
/// it). With `peaks` (each field's forward peak f per channel, δ-scaling's) the extinction is
/// β_ext − Σ_k ρ_k σ_sca,k f_k: the forward peak's light still reaches `p`, as in a δ-scaled
/// beam.
pub fn transmittance_to_sun(
    fields: &[&FieldTable],
    grid: &DensityGrid,
    p: DVec3,
    sun: DVec3,
    peaks: Option<&[[f64; 3]]>,
) -> [f64; 3] {
    let Some((t0, t1)) = box_span(grid.min_m, grid.max_m, p, sun) else {
        return [1.0; 3];
    };
    let step = 0.5
        * voxel_size(grid)
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
    let n = (((t1 - t0) / step).ceil() as usize).max(1);
    let dt = (t1 - t0) / n as f64;
    let mut tau = [0.0; 3];
    for i in 0..n {
        let rho = grid.sample(p + (t0 + (i as f64 + 0.5) * dt) * sun);
        let (mut ext, _) = coefficients(fields, &rho);
        if let Some(peaks) = peaks {
            for (k, (f, r)) in fields.iter().zip(rho).enumerate() {
                for c in 0..3 {
                    ext[c] -= r * f.sigma_sca_m2[c] * peaks[k][c];
                }
            }
        }
        for c in 0..3 {
            tau[c] += ext[c] * dt;
        }
    }
    tau.map(|t| (-t).exp())
}

/// Directions of the skylight: a Fibonacci set of equal solid angles 4π/[`SKY_DIRECTIONS`].
pub const SKY_DIRECTIONS: usize = 32;

/// The reduced skylight per voxel and channel: its mean radiance over
/// the sphere (1/4π)∫ L_sky T dω and its flux over 4π, (1/4π)∫ L_sky T ω dω (ω the direction
/// of travel).
pub struct Sky {
    /// (1/4π)∫ L_sky T dω per voxel and channel.
    pub mean: Vec<[f64; 3]>,
    /// (1/4π)∫ L_sky T ω dω per voxel and channel (ω the direction of travel).
    pub flux: Vec<[DVec3; 3]>,
}

/// The [`SKY_DIRECTIONS`] directions (towards the sky, y up), a Fibonacci set.
pub fn sky_directions() -> Vec<DVec3> {
    fibonacci_directions(SKY_DIRECTIONS)
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

impl Sky {
    /// No skylight at `n` voxels.
    pub fn zero(n: usize) -> Self {
        Self {
            mean: vec![[0.0; 3]; n],
            flux: vec![[DVec3::ZERO; 3]; n],
        }
    }

    /// Adds `radiance` per voxel arriving from direction `s` (travelling along −s) over the
    /// solid angle 4π/[`SKY_DIRECTIONS`].
    pub fn add(&mut self, s: DVec3, radiance: impl Fn(usize) -> [f64; 3] + Sync) {
        let omega = 4.0 * PI / SKY_DIRECTIONS as f64;
        self.mean
            .par_iter_mut()
            .zip(self.flux.par_iter_mut())
            .enumerate()
            .for_each(|(j, (mean, flux))| {
                let r = radiance(j);
                for c in 0..3 {
                    let w = r[c] * omega / (4.0 * PI);
                    mean[c] += w;
                    flux[c] -= w * s;
                }
            });
    }
}

/// The reduced skylight per voxel: the sky model's radiance from [`SKY_DIRECTIONS`] directions
/// ([`sky_light`]), each attenuated through the grid ([`sky_sweeps`]).
pub fn reduced_sky(frame: &Frame, ext: &[[f64; 3]], ground_lit: impl Fn(DVec3) -> [f64; 3]) -> Sky {
    sky_sweeps(&frame.grid, ext, &sky_light(frame, ground_lit))
}

/// The sky's radiance arriving at the box from each of the [`SKY_DIRECTIONS`] directions s
/// (towards the sky) that carries light, per channel: above the horizon the air's, below it
/// the air's and the sunlit ground's (Lambertian, `[ground] albedo`, lit through the volume as
/// `ground_lit` says, as [`crate::shading::compose`] shades it), both as seen from the middle
/// of the box.
pub fn sky_light(frame: &Frame, ground_lit: impl Fn(DVec3) -> [f64; 3]) -> Vec<(DVec3, [f64; 3])> {
    let grid = &frame.grid;
    let sun = frame.sun.direction();
    // The sky's radiance as seen from the middle of the box (Eqs. 11–15).
    let middle = 0.5 * (grid.min_m + grid.max_m);
    let y = middle.y;
    let atm = &frame.atmosphere;
    let multiple = SkyLight::of(frame);
    let mut lit = Vec::new();
    for s in sky_directions() {
        let k_end = if s.y < 0.0 { y / -s.y } else { f64::INFINITY };
        let mut l = atm.inscatter(y, s.y, k_end, sun.y, s.dot(sun));
        // The air's light beyond single scattering (and the sky-lit ground).
        let ms = multiple.radiance(y, s, sun);
        for c in 0..3 {
            l[c] += ms[c];
        }
        let ground: [f64; 3] = if frame.ground_albedo > 0.0 && k_end.is_finite() && sun.y > 0.0 {
            let g = crate::shading::ground_radiance(frame, ground_lit(middle + k_end * s));
            let t = atm.transparency(y, s.y, k_end);
            std::array::from_fn(|c| g[c] * t[c])
        } else {
            [0.0; 3]
        };
        let radiance: [f64; 3] =
            std::array::from_fn(|c| frame.sun.irradiance[c] * (l[c] + ground[c]));
        if radiance.iter().any(|&v| v > 0.0) {
            lit.push((s, radiance));
        }
    }
    lit
}

/// One direction of the skylight's sweeps ([`sky_orders`]).
pub(crate) struct SkyWay {
    /// The direction towards the sky.
    pub(crate) s: DVec3,
    /// Its radiance times its solid angle's share of the sphere, 1/[`SKY_DIRECTIONS`].
    pub(crate) weight: [f64; 3],
    /// The step between two layers (m).
    pub(crate) ds: f64,
    /// The point one layer back along the layer's axes b, c (voxel units).
    pub(crate) shift: (f64, f64),
}

/// The sweep orders of `lit` ([`sky_sweeps`]): per order its axis a (along which the
/// directions travel most, as [`sweep`] chooses it; the layers' axes are (a + 1) % 3 and
/// (a + 2) % 3), whether they travel towards +a, and its directions.
pub(crate) fn sky_orders(
    grid: &DensityGrid,
    lit: &[(DVec3, [f64; 3])],
) -> Vec<((usize, bool), Vec<SkyWay>)> {
    let omega = 4.0 * PI / SKY_DIRECTIONS as f64;
    let mut orders: Vec<((usize, bool), Vec<SkyWay>)> = Vec::new();
    for &(s, radiance) in lit {
        let along = Way::along(grid, -s);
        let way = SkyWay {
            s,
            weight: radiance.map(|r| r * omega / (4.0 * PI)),
            ds: along.ds,
            shift: along.shift,
        };
        let key = (along.axis, along.forward);
        match orders.iter_mut().find(|(k, _)| *k == key) {
            Some((_, ways)) => ways.push(way),
            None => orders.push((key, vec![way])),
        }
    }
    orders
}

/// The skylight arriving from each `(s, radiance)` of `lit` (towards the sky, radiance per
/// channel beyond the box), attenuated through the grid: per direction what [`sun_depths`]
/// along −s and [`Sky::add`] give, in one sweep per layer order. The directions that travel
/// most along the same axis and sign share the sweep, so each voxel's β_ext is read once per
/// sweep, and only two layers of each direction's state (τ and β_ext one layer back) are kept
/// instead of a grid per direction (at 128³ the 32 sweeps one after the other took 3.3 s of
/// the coupled model's 3.6 s of beam and sky on 2 cores).
pub fn sky_sweeps(grid: &DensityGrid, ext: &[[f64; 3]], lit: &[(DVec3, [f64; 3])]) -> Sky {
    let mut sky = Sky::zero(ext.len());
    let dims = grid.dims;
    let stride = [1, dims[0], dims[0] * dims[1]];
    for ((a, forward), ways) in &sky_orders(grid, lit) {
        let a = *a;
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        let (nb, nc) = (dims[b], dims[c]);
        let count = ways.len();
        // Per voxel of a layer, per direction: τ (rgb), then β_ext (rgb) for the trapezoid.
        let mut prev = vec![[0.0f64; 6]; nb * nc * count];
        let mut cur = prev.clone();
        let layers = layer_order(dims[a], *forward);
        for (step, &k) in layers.iter().enumerate() {
            let light: Vec<([f64; 3], [DVec3; 3])> = cur
                .par_chunks_mut(count)
                .enumerate()
                .map(|(m, states)| {
                    let (ub, vc) = (m % nb, m / nb);
                    let i = k * stride[a] + ub * stride[b] + vc * stride[c];
                    let here = ext[i];
                    let (mut mean, mut flux) = ([0.0; 3], [DVec3::ZERO; 3]);
                    for (d, (state, way)) in states.iter_mut().zip(ways).enumerate() {
                        let back = if step == 0 {
                            [0.0; 6]
                        } else {
                            upwind(
                                |u, v| &prev[(u + v * nb) * count + d],
                                (nb, nc),
                                (ub as f64 + way.shift.0, vc as f64 + way.shift.1),
                                [0.0; 6],
                            )
                        };
                        *state = std::array::from_fn(|n| match n {
                            0..=2 => back[n] + 0.5 * way.ds * (here[n] + back[n + 3]),
                            _ => here[n - 3],
                        });
                        for ch in 0..3 {
                            let w = way.weight[ch] * (-state[ch]).exp();
                            mean[ch] += w;
                            flux[ch] -= w * way.s;
                        }
                    }
                    (mean, flux)
                })
                .collect();
            for (m, (mean, flux)) in light.into_iter().enumerate() {
                let (ub, vc) = (m % nb, m / nb);
                let i = k * stride[a] + ub * stride[b] + vc * stride[c];
                for ch in 0..3 {
                    sky.mean[i][ch] += mean[ch];
                    sky.flux[i][ch] += flux[ch];
                }
            }
            std::mem::swap(&mut prev, &mut cur);
        }
    }
    sky
}

/// E T_sun S_atm per voxel: the reduced sunlight's irradiance, from the sun's optical depth
/// `tau_sun` to each voxel centre.
pub fn reduced_sun(frame: &Frame, tau_sun: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let grid = &frame.grid;
    let (h, dims, l_y) = (voxel_size(grid), grid.dims, frame.sun.direction()[1]);
    let centre = |i: usize| {
        let c = [
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        ];
        DVec3::from_array(std::array::from_fn(|a| {
            grid.min_m[a] + (c[a] as f64 + 0.5) * h[a]
        }))
    };
    (0..tau_sun.len())
        .into_par_iter()
        .map(|i| {
            let s_atm = frame.atmosphere.sunlight(centre(i).y, l_y);
            std::array::from_fn(|c| frame.sun.irradiance[c] * s_atm[c] * (-tau_sun[i][c]).exp())
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
            data: vec![[0.0; crate::MAX_FIELDS]; dims.iter().product()],
        }
    }

    /// A smooth, deterministic value in [0, 1] per index `i` and key `k` (a lumpy field).
    pub(crate) fn wobble(i: usize, k: usize) -> f64 {
        0.5 + 0.5 * ((i * 7 + k * 13) as f64 * 0.61).sin()
    }
}

#[cfg(test)]
mod tests {
    use super::fixture::{uneven_grid, wobble};
    use super::*;

    /// The grouped sweeps give per direction what a sweep of its own and [`Sky::add`] give: a
    /// lumpy medium on an uneven grid, every direction of the sky set with its own radiance.
    #[test]
    fn the_grouped_sky_sweeps_equal_a_sweep_per_direction() {
        let grid = uneven_grid();
        let n = grid.data.len();
        let ext: Vec<[f64; 3]> = (0..n)
            .map(|i| std::array::from_fn(|c| 3.0 * wobble(i, c) + 0.2))
            .collect();
        let lit: Vec<(DVec3, [f64; 3])> = sky_directions()
            .into_iter()
            .enumerate()
            .map(|(d, s)| (s, std::array::from_fn(|c| 1.0 + wobble(d, c))))
            .collect();
        let mut want = Sky::zero(n);
        for &(s, radiance) in &lit {
            let tau = sun_depths(&grid, &ext, -s);
            want.add(s, |j| {
                std::array::from_fn(|c| radiance[c] * (-tau[j][c]).exp())
            });
        }
        let got = sky_sweeps(&grid, &ext, &lit);
        let (mut worst, mut scale) = (0.0f64, 0.0f64);
        for i in 0..n {
            for c in 0..3 {
                scale = scale.max(want.mean[i][c]);
                worst = worst.max((got.mean[i][c] - want.mean[i][c]).abs());
                worst = worst.max((got.flux[i][c] - want.flux[i][c]).abs().max_element());
            }
        }
        eprintln!("sky sweeps: worst difference {worst:.2e} of {scale:.3}");
        // Only the order of the sums differs.
        assert!(scale > 0.1, "the sky reaches the voxels: {scale}");
        assert!(
            worst < 1e-14 * scale,
            "worst difference {worst:e} of {scale}"
        );
    }
}
