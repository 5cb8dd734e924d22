//! Density volumes: procedural cumulus, cirrus sheet and rain shaft, and raw f32 grids from a
//! file, rasterized into one grid of number densities (particles/m³), one channel per field.
//! Everything is seeded and deterministic.

use std::path::{Path, PathBuf};

use glam::DVec3;

/// Up to this many fields take part in one render (one RGBA texel per voxel).
pub const MAX_FIELDS: usize = 4;

/// Number densities on a regular grid; voxel (x, y, z) is centred at
/// min + (i + ½)·(max − min)/dims and holds one value per field (channel = field index in the
/// renderer's [`crate::Tables`]). Outside the box the density is zero.
#[derive(Debug, Clone, PartialEq)]
pub struct DensityGrid {
    /// Lower corner of the box (m).
    pub min_m: DVec3,
    /// Upper corner of the box (m).
    pub max_m: DVec3,
    /// Voxels along x, y, z.
    pub dims: [usize; 3],
    /// x fastest, then y, then z.
    pub data: Vec<[f32; MAX_FIELDS]>,
    /// The box repeats without end in x and z (a `periodic = true` volume): a point outside
    /// it in x or z samples the box at its remainder, and the voxels at opposite faces are
    /// neighbours.
    pub periodic: bool,
}

/// On an axis of `n` centres that repeats (the last centre's next is the first), the centre
/// at or below coordinate `u` (in centre units), the one after it and the second's weight in
/// a linear interpolation: the lookups of a periodic grid ([`DensityGrid::taps`], the sweeps'
/// one layer back, the shadow map).
pub(crate) fn wrapped_corners(u: f64, n: usize) -> (usize, usize, f64) {
    let u = u.rem_euclid(n as f64);
    let lo = (u.floor() as usize).min(n - 1);
    (lo, (lo + 1) % n, u - lo as f64)
}

impl DensityGrid {
    /// The bytes its voxels take (16 a voxel: one f32 per field).
    pub fn bytes(&self) -> u64 {
        std::mem::size_of_val(self.data.as_slice()) as u64
    }

    /// How deep inside field `f` a point of the grid can lie (particles/m²; with σ_ext, an
    /// optical depth): at each voxel with particles, the least ∫ ρ dl over the three
    /// axis-parallel grid lines through it (a path escapes along the thinnest), the largest
    /// over the voxels. A thin wide layer is as thin as its thickness.
    pub fn deepest_point(&self, f: usize) -> f64 {
        self.deepest_weighted(|rho| f64::from(rho[f]))
    }

    /// [`DensityGrid::deepest_point`] of the fields together, each voxel's density
    /// `weight(ρ per field)` (with each field's σ_ext, the optical depth of them all).
    pub fn deepest_weighted(&self, weight: impl Fn(&[f32; MAX_FIELDS]) -> f64) -> f64 {
        let [nx, ny, nz] = self.dims;
        let h: [f64; 3] =
            std::array::from_fn(|a| (self.max_m[a] - self.min_m[a]) / self.dims[a] as f64);
        let at = |x: usize, y: usize, z: usize| weight(&self.data[x + nx * (y + ny * z)]);
        // The column sums along x (per y, z), y (per x, z) and z (per x, y).
        let mut along = [vec![0.0; ny * nz], vec![0.0; nx * nz], vec![0.0; nx * ny]];
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let rho = at(x, y, z);
                    along[0][y + ny * z] += rho * h[0];
                    along[1][x + nx * z] += rho * h[1];
                    along[2][x + nx * y] += rho * h[2];
                }
            }
        }
        let mut deepest: f64 = 0.0;
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    if at(x, y, z) > 0.0 {
                        let least = along[0][y + ny * z]
                            .min(along[1][x + nx * z])
                            .min(along[2][x + nx * y]);
                        deepest = deepest.max(least);
                    }
                }
            }
        }
        deepest
    }

    /// A grid of no particles, one voxel of a millimetre at the origin: the grid of a scene
    /// without `[[volume]]` tables (media only).
    pub fn empty() -> Self {
        Self {
            min_m: DVec3::ZERO,
            max_m: DVec3::splat(1e-3),
            dims: [1, 1, 1],
            data: vec![[0.0; MAX_FIELDS]],
            periodic: false,
        }
    }

    /// The box's eight corners (m); bit 0, 1, 2 of the index picks max over min in x, y, z.
    pub fn corners(&self) -> [DVec3; 8] {
        std::array::from_fn(|i| {
            DVec3::new(
                if i & 1 == 0 {
                    self.min_m[0]
                } else {
                    self.max_m[0]
                },
                if i & 2 == 0 {
                    self.min_m[1]
                } else {
                    self.max_m[1]
                },
                if i & 4 == 0 {
                    self.min_m[2]
                } else {
                    self.max_m[2]
                },
            )
        })
    }

    /// The range of axis·x over the box's corners: its extent along `axis`.
    pub fn span_along(&self, axis: DVec3) -> (f64, f64) {
        self.corners()
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &c| {
                let v = axis.dot(c);
                (lo.min(v), hi.max(v))
            })
    }

    /// Whether `p` lies in the closed box [min_m, max_m] (for a periodic grid, between its
    /// bottom and top).
    pub fn contains(&self, p: DVec3) -> bool {
        (0..3).all(|a| self.wraps(a) || (p[a] >= self.min_m[a] && p[a] <= self.max_m[a]))
    }

    /// The region the grid's particles fill: its box, unbounded in x and z when periodic.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        if self.periodic {
            let inf = f64::INFINITY;
            (
                DVec3::new(-inf, self.min_m.y, -inf),
                DVec3::new(inf, self.max_m.y, inf),
            )
        } else {
            (self.min_m, self.max_m)
        }
    }

    /// The longest path the tracers follow through the grid: a periodic layer's 1000 periods
    /// (a path along it crosses that many copies of the box before it is ended), else without
    /// bound.
    pub fn longest_path_m(&self) -> f64 {
        if self.periodic {
            let period = (self.max_m - self.min_m).x.max((self.max_m - self.min_m).z);
            1000.0 * period
        } else {
            f64::INFINITY
        }
    }

    /// Whether axis `a` repeats (x and z of a periodic grid).
    pub fn wraps(&self, a: usize) -> bool {
        self.periodic && a != 1
    }

    /// Trilinear density at `p` (voxel centres, clamped to the edge voxels inside the box;
    /// wrapped across the faces of a periodic grid's axes).
    pub fn sample(&self, p: DVec3) -> [f64; MAX_FIELDS] {
        let mut out = [0.0; MAX_FIELDS];
        for (i, w) in self.taps(p).into_iter().flatten().flatten() {
            for f in 0..MAX_FIELDS {
                out[f] += w * self.data[i][f] as f64;
            }
        }
        out
    }

    /// The voxels (indices into `data`, x fastest) and weights of a trilinear lookup at `p`
    /// (voxel centres, clamped to the edge voxels inside the box; on a periodic grid's x and z
    /// the voxel centres repeat, so the last voxel's upper neighbour is the first), or `None`
    /// outside the box. Zero-weight corners are left out (`None` entries).
    pub fn taps(&self, p: DVec3) -> Option<[Option<(usize, f64)>; 8]> {
        if !self.contains(p) {
            return None;
        }
        // Per axis: the lower voxel, the upper one and the upper one's weight.
        let mut corner_voxels = [[0usize; 2]; 3];
        let mut t = [0f64; 3];
        for a in 0..3 {
            let n = self.dims[a];
            let u = (p[a] - self.min_m[a]) / (self.max_m[a] - self.min_m[a]) * n as f64 - 0.5;
            if self.wraps(a) {
                let (lo, hi, w) = wrapped_corners(u, n);
                corner_voxels[a] = [lo, hi];
                t[a] = w;
            } else {
                let u = u.clamp(0.0, (n - 1) as f64);
                let lo = (u.floor() as usize).min(n.saturating_sub(2));
                corner_voxels[a] = [lo, lo + usize::from(n > 1)];
                t[a] = if n > 1 { u - lo as f64 } else { 0.0 };
            }
        }
        let [nx, ny, _] = self.dims;
        Some(std::array::from_fn(|corner| {
            let d = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
            let w: f64 = (0..3)
                .map(|a| if d[a] == 1 { t[a] } else { 1.0 - t[a] })
                .product();
            let at = |a: usize| corner_voxels[a][d[a]];
            (w != 0.0).then(|| (at(0) + nx * (at(1) + ny * at(2)), w))
        }))
    }

    /// Largest density per field.
    pub fn max_density(&self) -> [f64; MAX_FIELDS] {
        let mut m = [0.0f64; MAX_FIELDS];
        for v in &self.data {
            for f in 0..MAX_FIELDS {
                m[f] = m[f].max(v[f] as f64);
            }
        }
        m
    }
}

/// The scene's optical depth as `--model auto` and coupled's depth check measure it: the
/// deepest point's least axis-line optical depth ([`DensityGrid::deepest_weighted`]), the
/// fields' green extinction together.
pub fn optical_depth(tables: &runtime::Tables, grid: &DensityGrid) -> f64 {
    grid.deepest_weighted(green_extinction(tables))
}

/// β_ext (green, 1/m) at a voxel's densities, the fields of `tables` together.
pub fn green_extinction(tables: &runtime::Tables) -> impl Fn(&[f32; MAX_FIELDS]) -> f64 {
    let sigma: Vec<f64> = tables.fields.iter().map(|f| f.sigma_ext_m2[1]).collect();
    move |rho| sigma.iter().zip(rho).map(|(s, &r)| s * f64::from(r)).sum()
}

/// The shape of one volume, in metres (y up).
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A heap of seeded blobs with a flat base at centre_y − height/2, fbm-noised edges.
    Cumulus {
        /// Centre of the bounding box (m).
        center_m: DVec3,
        /// Horizontal half-width of the bounding box (m).
        radius_m: f64,
        /// Height from base to top (m).
        height_m: f64,
    },
    /// A thin horizontal sheet with streaky fbm texture.
    Cirrus {
        /// Centre of the sheet (m).
        center_m: DVec3,
        /// Side of the square sheet (m).
        size_m: f64,
        /// Vertical thickness (m).
        thickness_m: f64,
    },
    /// A vertical cylinder of rain from `bottom_m` to `top_m`, soft at its rim and top.
    RainShaft {
        /// The axis's position (m); only x and z are used.
        center_m: DVec3,
        /// Cylinder radius (m).
        radius_m: f64,
        /// Height of the base (m); below `top_m`.
        bottom_m: f64,
        /// Height of the top (m).
        top_m: f64,
    },
    /// Raw little-endian f32 values, x fastest, filling [min_m, max_m]; multiplied by the
    /// volume's number density.
    Grid {
        /// The raw f32 file (resolved against the scene file's directory).
        file: PathBuf,
        /// Values along x, y, z, each in [1, 4096].
        dims: [usize; 3],
        /// Lower corner of the box (m).
        min_m: DVec3,
        /// Upper corner of the box (m); above `min_m` on every axis.
        max_m: DVec3,
        /// The file's values, read when the scene is parsed (so a bad or empty file is refused
        /// before anything is baked): channel 0 of a grid over [min_m, max_m].
        values: DensityGrid,
    },
    /// A scalar grid of an OpenVDB file (`shape = "vdb"`): the box of its active voxels, each
    /// voxel the file's value (the background where the tree holds none), placed by the file's
    /// own transform, then `scale_m` and `offset_m`; multiplied by the volume's number density.
    Vdb {
        /// The `.vdb` file (resolved against the scene file's directory).
        file: PathBuf,
        /// The grid's name in the file (`density` unless the scene names another).
        grid: String,
        /// What the file holds, as the OpenVDB library reports it, for the lines printed
        /// before work.
        summary: VdbSummary,
        /// The grid's values over its active voxels' box (channel 0), read when the scene is
        /// parsed.
        values: DensityGrid,
    },
}

/// An OpenVDB grid as the library describes it: what `render` and `view` print before work.
#[derive(Debug, Clone, PartialEq)]
pub struct VdbSummary {
    /// Voxels the tree marks active (tiles count each voxel they cover).
    pub active_voxels: u64,
    /// The active voxels' bounding box in index space, inclusive.
    pub index_min: [i32; 3],
    /// Upper corner of the index box, inclusive.
    pub index_max: [i32; 3],
    /// The value the tree holds where it stores none.
    pub background: f32,
    /// Stored as 16-bit floats.
    pub half: bool,
    /// The codec of the file's grid ("blosc + active mask", "zip", "none", …).
    pub compression: String,
    /// Leaf nodes and tiles in the tree.
    pub leaves: usize,
    /// Tiles that are active or differ from the background.
    pub tiles: usize,
}

/// One volume of one field.
#[derive(Debug, Clone, PartialEq)]
pub struct Volume {
    /// Name of the scene's `[[field]]` (a field of the tables) this volume holds; with a
    /// [`SizeProfile`], the name of a swept field.
    pub field: String,
    /// Peak number density (particles/m³); β_ext = density · σ_ext (Riley Eq. 2).
    pub number_density_per_m3: f64,
    /// Where the volume lies and how its density falls off.
    pub shape: Shape,
    /// Seed of the blobs and noise of the procedural shapes (default 1).
    pub seed: u64,
    /// A particle size that changes with height, sampled per voxel from a swept field.
    pub size: Option<SizeProfile>,
}

/// The keys a volume's size profile may follow: droplet radii, which grow by the adiabatic law.
pub const PROFILE_KEYS: [&str; 3] = ["r_eff_um", "median_radius_um", "radius_um"];

/// A droplet size that grows with height inside a volume (`r_eff_um = { base = 6, top = 14 }`):
/// the adiabatic law, r³ linear in the height above the volume's base (the liquid water of a
/// rising parcel grows linearly with height at a constant droplet number, so r ∝ h^{1/3} above a
/// base of zero size; docs/physics.md §11), from `base` at the bottom of the volume's box to
/// `top` at its top. The renderers mix, per voxel, the two members of the swept field around
/// that size with the shares of [`format::SweepEntry::shares`].
#[derive(Debug, Clone, PartialEq)]
pub struct SizeProfile {
    /// The swept key, one of [`PROFILE_KEYS`]; the volume's field must sweep it.
    pub key: String,
    /// The size at the volume's base (the key's unit), finite and > 0.
    pub base: f64,
    /// The size at the volume's top, finite and > 0.
    pub top: f64,
    /// The members the renderer mixes (a sweep over some of the swept field's values), set
    /// when the scene is prepared against its sweep ([`choose_members`]).
    pub members: Option<format::SweepEntry>,
}

impl SizeProfile {
    /// The size at height `y` (m) in a volume whose box spans heights [y0, y1]: r³ linear in
    /// height, clamped to the box.
    pub fn at(&self, y: f64, y0: f64, y1: f64) -> f64 {
        let s = ((y - y0) / (y1 - y0)).clamp(0.0, 1.0);
        let (b, t) = (self.base.powi(3), self.top.powi(3));
        (b + (t - b) * s).cbrt()
    }

    /// The least and largest size in the volume.
    pub fn range(&self) -> (f64, f64) {
        (self.base.min(self.top), self.base.max(self.top))
    }
}

/// The members of `sweep` a renderer holding `budget` fields mixes for sizes in [lo, hi]: the
/// members from the last at or below `lo` to the first at or above `hi`, all of them if they
/// fit, else `budget` of them spread evenly over that run of indices (both ends kept), so the
/// interpolation spans a coarser step. `None` where `budget` < 2 or the sweep has fewer than 2
/// members.
pub fn choose_members(
    sweep: &format::SweepEntry,
    lo: f64,
    hi: f64,
    budget: usize,
) -> Option<format::SweepEntry> {
    let v = &sweep.values;
    if budget < 2 || v.len() < 2 || sweep.fields.len() != v.len() {
        return None;
    }
    let last = v.len() - 1;
    // A size at (or, within rounding, above) the last value takes the last two members; one
    // at or below the first, the first two.
    let first = v.iter().rposition(|&x| x <= lo).unwrap_or(0).min(last - 1);
    let end = v
        .iter()
        .position(|&x| x >= hi)
        .unwrap_or(last)
        .clamp(first + 1, last);
    let run = end - first;
    let picks: Vec<usize> = if run < budget {
        (first..=end).collect()
    } else {
        (0..budget)
            .map(|i| first + (i * run + (budget - 1) / 2) / (budget - 1))
            .collect()
    };
    Some(format::SweepEntry {
        name: sweep.name.clone(),
        key: sweep.key.clone(),
        spacing: sweep.spacing.clone(),
        values: picks.iter().map(|&k| v[k]).collect(),
        fields: picks.iter().map(|&k| sweep.fields[k].clone()).collect(),
    })
}

impl Volume {
    /// Axis-aligned bounding box (min, max) of the shape (m).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        match &self.shape {
            Shape::Cumulus {
                center_m: c,
                radius_m: r,
                height_m: h,
            } => (
                DVec3::new(c[0] - r, c[1] - h / 2.0, c[2] - r),
                DVec3::new(c[0] + r, c[1] + h / 2.0, c[2] + r),
            ),
            Shape::Cirrus {
                center_m: c,
                size_m: s,
                thickness_m: t,
            } => (
                DVec3::new(c[0] - s / 2.0, c[1] - t / 2.0, c[2] - s / 2.0),
                DVec3::new(c[0] + s / 2.0, c[1] + t / 2.0, c[2] + s / 2.0),
            ),
            Shape::RainShaft {
                center_m: c,
                radius_m: r,
                bottom_m: b,
                top_m: t,
            } => (
                DVec3::new(c[0] - r, *b, c[2] - r),
                DVec3::new(c[0] + r, *t, c[2] + r),
            ),
            Shape::Grid { min_m, max_m, .. } => (*min_m, *max_m),
            Shape::Vdb { values, .. } => (values.min_m, values.max_m),
        }
    }
}

/// A volume's density function, relative to its peak (0…1).
enum Density {
    Cumulus {
        blobs: Vec<(DVec3, f64)>,
        base: f64,
        height: f64,
        noise_scale: f64,
        seed: u64,
    },
    Cirrus {
        center: DVec3,
        size: f64,
        thickness: f64,
        seed: u64,
    },
    RainShaft {
        center: DVec3,
        radius: f64,
        bottom: f64,
        top: f64,
        seed: u64,
    },
    Grid(DensityGrid),
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

use crate::rng::SplitMix64 as Rng;

/// Hash of a lattice point to [0, 1).
fn lattice(seed: u64, x: i64, y: i64, z: i64) -> f64 {
    let mut h = seed ^ 0x2545_F491_4F6C_DD1D;
    for v in [x, y, z] {
        h = (h ^ v as u64).wrapping_mul(0x100_0000_01B3);
        h ^= h >> 29;
    }
    Rng::new(h).uniform()
}

/// Value noise with smooth interpolation, in [0, 1].
fn value_noise(seed: u64, p: DVec3) -> f64 {
    let c = p.map(f64::floor);
    let f = [p[0] - c[0], p[1] - c[1], p[2] - c[2]].map(|t| t * t * (3.0 - 2.0 * t));
    let (x, y, z) = (c[0] as i64, c[1] as i64, c[2] as i64);
    let mut sum = 0.0;
    for corner in 0..8 {
        let (dx, dy, dz) = (corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
        let w = (if dx == 1 { f[0] } else { 1.0 - f[0] })
            * (if dy == 1 { f[1] } else { 1.0 - f[1] })
            * (if dz == 1 { f[2] } else { 1.0 - f[2] });
        sum += w * lattice(seed, x + dx, y + dy, z + dz);
    }
    sum
}

/// Four octaves of value noise, in [0, 1].
fn fbm(seed: u64, p: DVec3) -> f64 {
    let (mut sum, mut amp, mut norm, mut freq) = (0.0, 0.5, 0.0, 1.0);
    for octave in 0..4 {
        sum += amp * value_noise(seed.wrapping_add(octave), p.map(|v| v * freq));
        norm += amp;
        amp *= 0.5;
        freq *= 2.03;
    }
    sum / norm
}

impl Density {
    fn new(v: &Volume) -> Result<Self, String> {
        Ok(match &v.shape {
            &Shape::Cumulus {
                center_m: c,
                radius_m: r,
                height_m: h,
            } => {
                // A central tower and seeded side turrets, all inside the bounds.
                let mut rng = Rng::new(v.seed);
                let base = c[1] - h / 2.0;
                let mut blobs = vec![(
                    DVec3::new(c[0], base + 0.45 * h, c[2]),
                    0.5 * h.min(2.0 * r),
                )];
                for _ in 0..14 {
                    let a = rng.uniform() * std::f64::consts::TAU;
                    let size = (0.25 + 0.2 * rng.uniform()) * r.min(h);
                    let d = rng.uniform().sqrt() * (r - size).max(0.0) * 0.9;
                    let y = (base + size * (0.6 + 0.8 * rng.uniform())).min(c[1] + h / 2.0 - size);
                    blobs.push((DVec3::new(c[0] + d * a.cos(), y, c[2] + d * a.sin()), size));
                }
                Density::Cumulus {
                    blobs,
                    base,
                    height: h,
                    noise_scale: 0.2 * r.min(h),
                    seed: v.seed,
                }
            }
            &Shape::Cirrus {
                center_m,
                size_m,
                thickness_m,
            } => Density::Cirrus {
                center: center_m,
                size: size_m,
                thickness: thickness_m,
                seed: v.seed,
            },
            &Shape::RainShaft {
                center_m,
                radius_m,
                bottom_m,
                top_m,
            } => Density::RainShaft {
                center: center_m,
                radius: radius_m,
                bottom: bottom_m,
                top: top_m,
                seed: v.seed,
            },
            Shape::Grid { values, .. } | Shape::Vdb { values, .. } => Density::Grid(values.clone()),
        })
    }

    fn at(&self, p: DVec3) -> f64 {
        match self {
            Density::Cumulus {
                blobs,
                base,
                height,
                noise_scale,
                seed,
            } => {
                let inside = blobs
                    .iter()
                    .map(|&(c, r)| {
                        let d = p - c;
                        1.0 - d.dot(d).sqrt() / r
                    })
                    .fold(f64::NEG_INFINITY, f64::max);
                let n = fbm(*seed, p.map(|v| v / noise_scale)) - 0.5;
                let shaped = inside + 0.45 * n;
                smoothstep(0.0, 0.2, shaped) * smoothstep(*base, base + 0.04 * height, p[1])
            }
            Density::Cirrus {
                center,
                size,
                thickness,
                seed,
            } => {
                let dy = (p[1] - center[1]) / (thickness / 2.0);
                let profile = (1.0 - dy * dy).max(0.0);
                let (x, z) = ((p[0] - center[0]) / size, (p[2] - center[2]) / size);
                // Streaks: the noise stretched along a diagonal, fading at the edges.
                let (s, t) = (0.7 * x + 0.7 * z, -0.7 * x + 0.7 * z);
                let streak = fbm(*seed, DVec3::new(s * 2.0, t * 10.0, p[1] / thickness));
                let edge = smoothstep(0.5, 0.35, x.abs().max(z.abs()));
                profile * edge * smoothstep(0.3, 0.7, streak)
            }
            Density::RainShaft {
                center,
                radius,
                bottom,
                top,
                seed,
            } => {
                let r = ((p[0] - center[0]).powi(2) + (p[2] - center[2]).powi(2)).sqrt();
                let radial = smoothstep(*radius, 0.55 * radius, r);
                let fade_top = smoothstep(*top, top - 0.2 * (top - bottom), p[1]);
                let texture = 0.75 + 0.5 * (fbm(*seed, p.map(|v| v / (0.4 * radius))) - 0.5);
                radial * fade_top * texture
            }
            Density::Grid(g) => g.sample(p)[0],
        }
    }
}

/// Reads a grid volume's raw f32 file: `dims` values (each axis in [1, 4096]), finite and ≥ 0,
/// not all zero (a grid without particles renders nothing).
pub fn read_grid(
    file: &Path,
    dims: [usize; 3],
    min_m: DVec3,
    max_m: DVec3,
) -> Result<DensityGrid, String> {
    if dims.iter().any(|&d| d == 0 || d > 4096) {
        return Err(format!(
            "grid {}: dims {dims:?} must each lie in [1, 4096]",
            file.display()
        ));
    }
    let count = dims.iter().product::<usize>();
    if count > MAX_GRID_VALUES {
        return Err(format!(
            "grid {}: dims {dims:?} hold {count} values, more than the {MAX_GRID_VALUES} a grid \
             file may hold (a renderer resamples it to [render] grid_resolution voxels along the \
             longest side anyway)",
            file.display()
        ));
    }
    // Only a regular file, and no more than the dims need: a FIFO or /dev/zero is refused
    // before anything is read.
    let bytes = format::read_regular_file(file, 4 * count as u64)
        .map_err(|(op, e)| format!("grid {}: {op}: {e}", file.display()))?;
    if bytes.len() != 4 * count {
        return Err(format!(
            "grid {}: {} bytes, but dims {dims:?} need {} (little-endian f32, x fastest)",
            file.display(),
            bytes.len(),
            4 * count
        ));
    }
    let values = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]));
    let data = densities(values, dims, |[x, y, z]| {
        format!(
            "index {} (x {x}, y {y}, z {z})",
            x + dims[0] * (y + dims[1] * z)
        )
    })
    .map_err(|e| format!("grid {}: {e}", file.display()))?;
    Ok(DensityGrid {
        min_m,
        max_m,
        dims,
        data,
        periodic: false,
    })
}

/// The largest `.vdb` file a scene may read (4 GiB): a grid of [`MAX_GRID_VALUES`] floats
/// stored uncompressed, with its tree.
pub const MAX_VDB_BYTES: u64 = 4 << 30;

/// The densities of a grid file's `values` (x fastest over `dims`) as channel 0 of a
/// [`DensityGrid`]'s voxels: each finite and ≥ 0 (else the first that is not, placed by
/// `place` of its (x, y, z)), not all zero (a grid without particles renders nothing).
fn densities(
    values: impl ExactSizeIterator<Item = f32>,
    dims: [usize; 3],
    place: impl Fn([usize; 3]) -> String,
) -> Result<Vec<[f32; MAX_FIELDS]>, String> {
    let mut data = Vec::with_capacity(values.len());
    for (i, v) in values.enumerate() {
        if !(v.is_finite() && v >= 0.0) {
            let xyz = [i % dims[0], i / dims[0] % dims[1], i / (dims[0] * dims[1])];
            return Err(format!(
                "value {v} at {} is not a finite density ≥ 0",
                place(xyz)
            ));
        }
        data.push([v, 0.0, 0.0, 0.0]);
    }
    if data.iter().all(|v| v[0] == 0.0) {
        return Err(format!(
            "every one of its {} values is 0: the volume holds no particles",
            data.len()
        ));
    }
    Ok(data)
}

/// Reads grid `grid` of OpenVDB file `file` (crate `vdb`): its values over the box of its
/// active voxels, finite and ≥ 0, not all zero, at most [`MAX_GRID_VALUES`] of them; the box
/// placed at `offset_m + scale_m · (the file's world box)`. Every error names the file.
pub fn read_vdb(
    file: &Path,
    grid: &str,
    scale_m: f64,
    offset_m: DVec3,
) -> Result<(VdbSummary, DensityGrid), String> {
    let at = |e: String| format!("vdb {}: {e}", file.display());
    let bytes = format::read_regular_file(file, MAX_VDB_BYTES)
        .map_err(|(op, e)| at(format!("{op}: {e}")))?;
    let g = vdb::Archive::parse(&bytes)
        .and_then(|a| a.read(grid, MAX_GRID_VALUES as u64))
        .map_err(|e| at(e.to_string()))?;
    let data = densities(g.values.iter().copied(), g.dims, |xyz| {
        let [i, j, k] = std::array::from_fn(|a| i64::from(g.index_min[a]) + xyz[a] as i64);
        format!("voxel ({i}, {j}, {k})")
    })
    .map_err(|e| at(format!("grid {grid:?}: {e}")))?;
    let place = |x: [f64; 3]| offset_m + scale_m * DVec3::from_array(x);
    let summary = VdbSummary {
        active_voxels: g.active_voxels,
        index_min: g.index_min,
        index_max: g.index_max,
        background: g.background,
        half: g.half,
        compression: g.compression.clone(),
        leaves: g.leaves,
        tiles: g.tiles,
    };
    let values = DensityGrid {
        min_m: place(g.world_min()),
        max_m: place(g.world_max()),
        dims: g.dims,
        data,
        periodic: false,
    };
    Ok((summary, values))
}

/// A volume that cannot be rasterized: the grid file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct VolumeError(pub String);

/// The most values a grid file may hold (2²⁸: a 1 GiB file, 645³ voxels).
pub const MAX_GRID_VALUES: usize = 1 << 28;

/// Voxels along x, y, z of the grid [`rasterize`] makes of `volumes`: `resolution` along the
/// joint box's longest side, the others in proportion (at least 2).
pub fn grid_dims(volumes: &[Volume], resolution: usize) -> [usize; 3] {
    let (lo, hi) = joint_bounds(volumes);
    let extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let longest = extent.iter().cloned().fold(0.0, f64::max);
    // The ratio first: resolution × e alone can overflow to ∞ for a huge box.
    extent
        .map(|e| ((resolution as f64 * (e / longest)).round() as usize).clamp(2, resolution.max(2)))
}

/// The `resolution` of [`grid_dims`] at which the render grid's voxels are no larger than the
/// smallest voxel of any file the volumes read (`grid` and `vdb` shapes): the resolution at
/// which a grid made of one file alone is that file's own voxels, sampled at their centres.
/// `None` where no volume reads a file.
pub fn file_resolution(volumes: &[Volume]) -> Option<usize> {
    let smallest = volumes
        .iter()
        .filter_map(|v| match &v.shape {
            Shape::Grid { values, .. } | Shape::Vdb { values, .. } => Some(values),
            _ => None,
        })
        .flat_map(|g| (0..3).map(|a| (g.max_m[a] - g.min_m[a]) / g.dims[a] as f64))
        .reduce(f64::min)?;
    let (lo, hi) = joint_bounds(volumes);
    let longest = (hi - lo).max_element();
    // A hair below the ratio, so a file's own box and dims give its own count back.
    Some((longest / smallest * (1.0 - 1e-9)).ceil().max(2.0) as usize)
}

/// The box holding every volume.
pub fn joint_bounds(volumes: &[Volume]) -> (DVec3, DVec3) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for v in volumes {
        let (a, b) = v.bounds();
        for i in 0..3 {
            lo[i] = lo[i].min(a[i]);
            hi[i] = hi[i].max(b[i]);
        }
    }
    (DVec3::from_array(lo), DVec3::from_array(hi))
}

/// Where one volume's particles go in the grid: one channel, or the members of a sweep by the
/// size at each height.
enum Channels<'a> {
    One(usize),
    Sized {
        profile: &'a SizeProfile,
        sweep: &'a format::SweepEntry,
        channels: Vec<usize>,
        sigma_ext: Vec<f64>,
        heights: (f64, f64),
    },
}

impl<'a> Channels<'a> {
    /// Where `v`'s particles go; `field` maps a field name to its channel and σ_ext (green).
    fn of(v: &'a Volume, field: &impl Fn(&str) -> (usize, f64)) -> Result<Self, String> {
        let Some(profile) = &v.size else {
            return Ok(Channels::One(field(&v.field).0));
        };
        let sweep = profile.members.as_ref().ok_or_else(|| {
            format!(
                "the volume of {:?} has a {} profile and no members chosen for it",
                v.field, profile.key
            )
        })?;
        let (channels, sigma_ext) = sweep.fields.iter().map(|m| field(m)).unzip();
        let (a, b) = v.bounds();
        Ok(Channels::Sized {
            profile,
            sweep,
            channels,
            sigma_ext,
            heights: (a[1], b[1]),
        })
    }

    /// Adds `n` particles/m³ at height `y` to `cell`.
    fn add(&self, cell: &mut [f32; MAX_FIELDS], n: f64, y: f64) {
        match self {
            Channels::One(f) => cell[*f] += n as f32,
            Channels::Sized {
                profile,
                sweep,
                channels,
                sigma_ext,
                heights,
            } => {
                let size = profile.at(y, heights.0, heights.1);
                for (k, share) in sweep.shares(size, sigma_ext) {
                    cell[channels[k]] += (n * share) as f32;
                }
            }
        }
    }
}

/// Rasterizes `volumes` into one grid over their joint bounds, `resolution` voxels along the
/// longest side; `field` maps a field name to its channel and its extinction cross-section
/// (m², green), which sets a sized volume's member shares.
pub fn rasterize(
    volumes: &[Volume],
    resolution: usize,
    field: impl Fn(&str) -> (usize, f64),
) -> Result<DensityGrid, VolumeError> {
    if volumes.is_empty() {
        return Err(VolumeError("the scene has no [[volume]]".into()));
    }
    let (lo, hi) = joint_bounds(volumes);
    let extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let dims = grid_dims(volumes, resolution);
    let densities: Vec<(Channels, f64, Density)> = volumes
        .iter()
        .map(|v| {
            let c = Channels::of(v, &field)?;
            Ok((c, v.number_density_per_m3, Density::new(v)?))
        })
        .collect::<Result<_, String>>()
        .map_err(VolumeError)?;
    let [nx, ny, nz] = dims;
    let mut data = vec![[0f32; MAX_FIELDS]; nx * ny * nz];
    use rayon::prelude::*;
    data.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(z, slab)| {
            for y in 0..ny {
                for x in 0..nx {
                    let p = DVec3::new(
                        lo[0] + (x as f64 + 0.5) * extent[0] / nx as f64,
                        lo[1] + (y as f64 + 0.5) * extent[1] / ny as f64,
                        lo[2] + (z as f64 + 0.5) * extent[2] / nz as f64,
                    );
                    let cell = &mut slab[x + nx * y];
                    for (channels, scale, d) in &densities {
                        channels.add(cell, scale * d.at(p), p[1]);
                    }
                }
            }
        });
    Ok(DensityGrid {
        min_m: lo,
        max_m: hi,
        dims,
        data,
        periodic: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A periodic grid repeats in x and z: the same density a period away, the faces' voxels
    /// neighbours (halfway between the last voxel's centre and the next period's first, their
    /// mean), and y bounded as before.
    #[test]
    fn a_periodic_grid_wraps_in_x_and_z_only() {
        let mut data = vec![[0f32; MAX_FIELDS]; 4 * 2 * 3];
        for (i, v) in data.iter_mut().enumerate() {
            v[0] = i as f32;
        }
        let grid = DensityGrid {
            min_m: DVec3::new(0.0, 0.0, 0.0),
            max_m: DVec3::new(4.0, 2.0, 3.0),
            dims: [4, 2, 3],
            data,
            periodic: true,
        };
        let p = DVec3::new(1.3, 0.7, 2.2);
        for shift in [DVec3::new(4.0, 0.0, 0.0), DVec3::new(-8.0, 0.0, 3.0)] {
            let (a, b) = (grid.sample(p)[0], grid.sample(p + shift)[0]);
            assert!((a - b).abs() < 1e-12, "{a} vs {b} a period away");
        }
        // x = 4 (the face) lies halfway between voxel 3's centre (3.5) and voxel 0's next one
        // (4.5); at y = 0.5, z = 0.5 (voxel centres) the mean of voxels 3 and 0 of that row.
        let face = grid.sample(DVec3::new(4.0, 0.5, 0.5))[0];
        assert!((face - 1.5).abs() < 1e-12, "{face}");
        assert_eq!(
            grid.sample(DVec3::new(1.0, 2.5, 1.0))[0],
            0.0,
            "above the layer"
        );
        assert!(grid.contains(DVec3::new(-100.0, 1.0, 1e6)));
        assert_eq!(grid.bounds().0.x, f64::NEG_INFINITY);
    }

    fn shaft(seed: u64) -> Volume {
        Volume {
            field: "rain".into(),
            number_density_per_m3: 100.0,
            shape: Shape::RainShaft {
                center_m: DVec3::new(0.0, 0.0, 5000.0),
                radius_m: 1000.0,
                bottom_m: 0.0,
                top_m: 2000.0,
            },
            seed,
            size: None,
        }
    }

    fn cumulus() -> Volume {
        Volume {
            field: "cloud".into(),
            number_density_per_m3: 1e7,
            shape: Shape::Cumulus {
                center_m: DVec3::new(0.0, 2000.0, 5000.0),
                radius_m: 1500.0,
                height_m: 1500.0,
            },
            seed: 2,
            size: None,
        }
    }

    #[test]
    fn rasterizing_is_deterministic_and_follows_the_seed() {
        let index = |f: &str| (usize::from(f == "cloud"), 1.0);
        let a = rasterize(&[shaft(1), cumulus()], 40, index).unwrap();
        let b = rasterize(&[shaft(1), cumulus()], 40, index).unwrap();
        let c = rasterize(&[shaft(9), cumulus()], 40, index).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
        // Joint bounds; both channels filled, peaks at most the volumes' densities.
        assert_eq!(a.min_m, DVec3::new(-1500.0, 0.0, 3500.0));
        assert_eq!(a.max_m, DVec3::new(1500.0, 2750.0, 6500.0));
        let peak = a.max_density();
        assert!(peak[0] > 50.0 && peak[0] <= 100.0 * 1.0001, "{peak:?}");
        assert!(peak[1] > 5e6 && peak[1] <= 1e7 * 1.0001, "{peak:?}");
        assert_eq!((peak[2], peak[3]), (0.0, 0.0));
        // Nothing outside the box.
        assert_eq!(a.sample(DVec3::new(0.0, 3000.0, 5000.0)), [0.0; MAX_FIELDS]);
    }

    fn sweep(values: &[f64]) -> format::SweepEntry {
        format::SweepEntry {
            name: "cloud".into(),
            key: "r_eff_um".into(),
            spacing: "log".into(),
            values: values.to_vec(),
            fields: (0..values.len()).map(|k| format!("cloud@{k:02}")).collect(),
        }
    }

    #[test]
    fn the_adiabatic_profile_grows_as_the_cube_root_of_height() {
        let p = SizeProfile {
            key: "r_eff_um".into(),
            base: 6.0,
            top: 14.0,
            members: None,
        };
        assert_eq!(p.at(1000.0, 1000.0, 2000.0), 6.0);
        assert!((p.at(2000.0, 1000.0, 2000.0) - 14.0).abs() < 1e-12);
        // Halfway up, r³ is the mean of the ends' cubes; below and above, the ends.
        let mid = p.at(1500.0, 1000.0, 2000.0);
        assert!((mid.powi(3) - (6f64.powi(3) + 14f64.powi(3)) / 2.0).abs() < 1e-9);
        assert_eq!(p.at(0.0, 1000.0, 2000.0), 6.0);
        assert!((p.at(9e9, 1000.0, 2000.0) - 14.0).abs() < 1e-12);
        assert_eq!(p.range(), (6.0, 14.0));
    }

    #[test]
    fn members_are_chosen_around_the_profile_within_the_budget() {
        let values: Vec<f64> = (0..16).map(|k| 4.0 * 2f64.powf(k as f64 / 5.0)).collect();
        let s = sweep(&values);
        // 6 … 14 µm: from the last value ≤ 6 (k = 2, 5.28) to the first ≥ 14 (k = 10, 16).
        let all = choose_members(&s, 6.0, 14.0, 16).unwrap();
        assert_eq!(all.values, values[2..=10].to_vec());
        assert_eq!(all.fields.first().unwrap(), "cloud@02");
        // Four channels: both ends kept, evenly spread in index.
        let four = choose_members(&s, 6.0, 14.0, 4).unwrap();
        assert_eq!(
            four.fields,
            ["cloud@02", "cloud@05", "cloud@07", "cloud@10"]
        );
        // A single size still takes two members; a value on a member takes it and the next.
        let one = choose_members(&s, values[3], values[3], 4).unwrap();
        assert_eq!(one.fields, ["cloud@03", "cloud@04"]);
        assert!(choose_members(&s, 6.0, 14.0, 1).is_none());
    }

    #[test]
    fn a_profile_at_the_sweeps_ends_takes_the_two_members_there() {
        // 6 … 14 in four members (log) and 6 … 14 in five (linear): a profile at the last value
        // (or just above it, within the scene check's 1e-9), at the first, or spanning all.
        for values in [vec![6.0, 7.9, 10.6, 14.0], vec![6.0, 8.0, 10.0, 12.0, 14.0]] {
            let s = sweep(&values);
            let n = values.len();
            let top = values[n - 1];
            for (lo, hi, want) in [
                (top, top, [n - 2, n - 1]),
                (top * (1.0 + 1e-9), top * (1.0 + 1e-9), [n - 2, n - 1]),
                (values[0], values[0], [0, 1]),
                (values[0] * (1.0 - 1e-9), values[0], [0, 1]),
            ] {
                for budget in [2, 3, 4] {
                    let m = choose_members(&s, lo, hi, budget).unwrap();
                    assert_eq!(m.values, [values[want[0]], values[want[1]]], "{lo} {hi}");
                }
            }
            for budget in 2..=6 {
                let m = choose_members(&s, values[0], top, budget).unwrap();
                assert_eq!(m.values.len(), budget.min(n));
                assert_eq!(
                    (m.values[0], m.values[m.values.len() - 1]),
                    (values[0], top)
                );
                assert!(m.values.windows(2).all(|w| w[0] < w[1]), "{:?}", m.values);
            }
        }
    }

    #[test]
    fn a_sized_volume_puts_each_voxel_between_the_two_members_around_its_size() {
        let mut v = cumulus();
        let values = [6.0, 8.0, 10.0, 14.0];
        let sigma = [1.0, 1.8, 2.7, 5.3];
        v.size = Some(SizeProfile {
            key: "r_eff_um".into(),
            base: 6.0,
            top: 14.0,
            members: Some(sweep(&values)),
        });
        let field = |name: &str| {
            let k: usize = name[6..].parse().unwrap();
            (k, sigma[k])
        };
        let g = rasterize(std::slice::from_ref(&v), 24, field).unwrap();
        let plain = rasterize(&[cumulus()], 24, |_| (0, 1.0)).unwrap();
        let [nx, ny, _] = g.dims;
        let (y0, y1) = (g.min_m[1], g.max_m[1]);
        let mut checked = 0;
        for (i, (cell, n)) in g.data.iter().zip(&plain.data).enumerate() {
            let n = f64::from(n[0]);
            if n <= 0.0 {
                assert_eq!(*cell, [0.0; MAX_FIELDS]);
                continue;
            }
            let y =
                y0 + ((i / nx) % ny) as f64 * (y1 - y0) / ny as f64 + (y1 - y0) / ny as f64 / 2.0;
            let size = v.size.as_ref().unwrap().at(y, y0, y1);
            // At most two neighbouring members hold particles, and the voxel's extinction is
            // σ interpolated log-linearly in size between them.
            let used: Vec<usize> = (0..MAX_FIELDS).filter(|&k| cell[k] > 0.0).collect();
            assert!(
                used.len() <= 2 && used.windows(2).all(|w| w[1] == w[0] + 1),
                "{cell:?}"
            );
            let k = values.partition_point(|&x| x <= size).clamp(1, 3) - 1;
            let t = (size / values[k]).ln() / (values[k + 1] / values[k]).ln();
            let want = n * sigma[k].powf(1.0 - t) * sigma[k + 1].powf(t);
            let have: f64 = (0..4).map(|k| f64::from(cell[k]) * sigma[k]).sum();
            assert!(
                (have / want - 1.0).abs() < 1e-5,
                "{have} vs {want} at size {size}"
            );
            checked += 1;
        }
        assert!(checked > 1000, "{checked}");
        // Nothing was prepared: the profile without members is an error, not a silent default.
        v.size.as_mut().unwrap().members = None;
        let e = rasterize(&[v], 24, field).unwrap_err();
        assert!(e.0.contains("no members chosen"), "{}", e.0);
    }

    #[test]
    fn grid_files_are_checked_and_sampled_trilinearly() {
        let dir = std::env::temp_dir().join(format!("photometeor-grid-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("g.f32");
        // 2 × 1 × 1 voxels: 0 and 4; the midpoint between the voxel centres samples 2.
        let bytes: Vec<u8> = [0f32, 4.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(&file, &bytes).unwrap();
        let g = read_grid(&file, [2, 1, 1], DVec3::ZERO, DVec3::new(2.0, 1.0, 1.0)).unwrap();
        assert!((g.sample(DVec3::new(1.0, 0.5, 0.5))[0] - 2.0).abs() < 1e-12);
        assert!((g.sample(DVec3::new(0.25, 0.5, 0.5))[0] - 0.0).abs() < 1e-12);
        let short = read_grid(&file, [3, 1, 1], DVec3::ZERO, DVec3::ONE).unwrap_err();
        assert!(
            short.contains("8 bytes") && short.contains("need 12"),
            "{short}"
        );
        let bad: Vec<u8> = [1f32, -2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(&file, &bad).unwrap();
        let negative = read_grid(&file, [2, 1, 1], DVec3::ZERO, DVec3::ONE).unwrap_err();
        assert!(
            negative.contains("-2") && negative.contains("index 1"),
            "{negative}"
        );
        std::fs::write(&file, [0u8; 8]).unwrap();
        let empty = read_grid(&file, [2, 1, 1], DVec3::ZERO, DVec3::ONE).unwrap_err();
        assert!(empty.contains("every one of its 2 values is 0"), "{empty}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
