//! The skylight on the grid: the sky's radiance (and the ground's, lit by the sun through the
//! volume) from [`SKY_DIRECTIONS`] directions, attenuated to each voxel centre by upwind sweeps
//! grouped by leading axis, reduced to its mean radiance and flux per voxel. The GPU twin of
//! [`sky_sweeps`] is [`super::sky_gpu`].

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use super::lattice::{Passes, Way, fibonacci_directions, layer_order, upwind};
use crate::frame::Frame;
use crate::skylight::SkyLight;
use crate::volume::DensityGrid;
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

/// [`sky_sweeps`] where `place` and `on` put it ([`super::run`]: on the GPU, [`super::sky_gpu`],
/// or the CPU); the skylight and where it ran.
pub(crate) fn sweep_on(
    (on, place): (Option<super::OnGpu>, super::Place),
    grid: &DensityGrid,
    ext: &[[f64; 3]],
    lit: &[(DVec3, [f64; 3])],
) -> Result<(Sky, String), crate::checks::FrameError> {
    super::run(
        on,
        place,
        "the skylight",
        |on| Ok(on.sky().sweep(on.gpu, grid, ext, lit)?),
        || Ok(sky_sweeps(grid, ext, lit)),
    )
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
        let wrap = (grid.wraps(b), grid.wraps(c));
        let mut passes = Passes::over(grid, a);
        for pass in 0.. {
            let before = (pass > 0).then(|| prev.clone());
            for (step, &k) in layers.iter().enumerate() {
                let light = sky_layer(
                    (grid, ext, ways),
                    (a, k, step > 0 || pass > 0),
                    (&prev, &mut cur),
                    wrap,
                );
                if passes.counts() {
                    for (m, (mean, flux)) in light.into_iter().enumerate() {
                        let (ub, vc) = (m % nb, m / nb);
                        let i = k * stride[a] + ub * stride[b] + vc * stride[c];
                        for ch in 0..3 {
                            sky.mean[i][ch] += mean[ch];
                            sky.flux[i][ch] += flux[ch];
                        }
                    }
                }
                std::mem::swap(&mut prev, &mut cur);
            }
            if passes.done_after(pass, before.as_deref(), &prev) {
                break;
            }
        }
    }
    sky
}

/// One layer `k` across axis `a` of the skylight's sweeps ([`sky_sweeps`]) for the
/// directions `ways`: each direction's state (τ, then β_ext) into `cur` from the layer behind
/// in `prev` (clear air unless `behind`), and per voxel the mean radiance and flux it adds.
fn sky_layer(
    (grid, ext, ways): (&DensityGrid, &[[f64; 3]], &[SkyWay]),
    (a, k, behind): (usize, usize, bool),
    (prev, cur): (&[[f64; 6]], &mut [[f64; 6]]),
    wrap: (bool, bool),
) -> Vec<([f64; 3], [DVec3; 3])> {
    let dims = grid.dims;
    let stride = [1, dims[0], dims[0] * dims[1]];
    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
    let (nb, count) = (dims[b], ways.len());
    cur.par_chunks_mut(count)
        .enumerate()
        .map(|(m, states)| {
            let (ub, vc) = (m % nb, m / nb);
            let i = k * stride[a] + ub * stride[b] + vc * stride[c];
            let here = ext[i];
            let (mut mean, mut flux) = ([0.0; 3], [DVec3::ZERO; 3]);
            for (d, (state, way)) in states.iter_mut().zip(ways).enumerate() {
                let back = if behind {
                    upwind(
                        |u, v| &prev[(u + v * nb) * count + d],
                        (nb, dims[c]),
                        (ub as f64 + way.shift.0, vc as f64 + way.shift.1),
                        [0.0; 6],
                        wrap,
                    )
                } else {
                    [0.0; 6]
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
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::lattice::fixture::{uneven_grid, wobble};
    use crate::lighting::lattice::sun_depths;

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
