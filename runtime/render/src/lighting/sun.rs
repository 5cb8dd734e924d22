//! The sunlight on the grid: the reduced sunlight E T_sun S_atm at voxel centres, the
//! volume's transmittance towards the sun from any point, and the shadow map the volume casts
//! below the grid (CPU only: one march per cell).

use glam::DVec3;
use rayon::prelude::*;

use runtime::FieldTable;

use super::lattice::voxel_size;
use crate::frame::Frame;
use crate::geometry::box_span;
use crate::shading::coefficients;
use crate::volume::DensityGrid;
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
    /// The grid repeats in x and z: the cells are its voxels' columns, repeating likewise.
    periodic: bool,
}

impl ShadowMap {
    /// The map of `grid` with the sun towards `sun` (above the horizon), each cell's value
    /// `left(q)` at its centre q on the plane.
    pub fn new(grid: &DensityGrid, sun: DVec3, left: impl Fn(DVec3) -> [f64; 3] + Sync) -> Self {
        let (lo, hi) = (grid.min_m, grid.max_m);
        // From the plane the line to the sun crosses the grid's height over t ≤ height/l_y,
        // moving sun_h t: the footprint swept back by that (a periodic grid's shadow repeats
        // with its box: one period).
        let reach = (hi.y - lo.y) / sun.y.max(1e-6);
        let shift = if grid.periodic {
            [0.0; 2]
        } else {
            [sun.x * reach, sun.z * reach]
        };
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
            periodic: grid.periodic,
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
        // The lower cell, the upper one and the upper one's weight along an axis of n cells.
        let (corners_u, corners_w) = if self.periodic {
            use crate::volume::wrapped_corners;
            (wrapped_corners(u, nx), wrapped_corners(w, nz))
        } else {
            if u < -0.5 || w < -0.5 || u > nx as f64 - 0.5 || w > nz as f64 - 0.5 {
                return [1.0; 3];
            }
            let clamped = |u: f64, n: usize| {
                let lo = (u.floor().max(0.0) as usize).min(n - 2);
                (lo, lo + 1, (u - lo as f64).clamp(0.0, 1.0))
            };
            (clamped(u, nx), clamped(w, nz))
        };
        let ((i0, i1, s), (j0, j1, t)) = (corners_u, corners_w);
        let v = |a: usize, b: usize| self.values[a + nx * b];
        std::array::from_fn(|c| {
            (v(i0, j0)[c] * (1.0 - s) + v(i1, j0)[c] * s) * (1.0 - t)
                + (v(i0, j1)[c] * (1.0 - s) + v(i1, j1)[c] * s) * t
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
    let (lo, hi) = grid.bounds();
    let Some((t0, t1)) = box_span(lo, hi, p, sun) else {
        return [1.0; 3];
    };
    let t1 = t1.min(t0 + grid.longest_path_m());
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
