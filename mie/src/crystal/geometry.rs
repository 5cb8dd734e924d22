//! Hexagonal prisms as convex polyhedra: eight planes, their areas, and ray intersection.

use glam::DVec3;

/// (cos 2πu, sin 2πu) for u ∈ [0, 1] without libm: u is reduced to the nearest quarter turn k/4
/// (an exact rotation of the result) and the remainder α ∈ [−π/4, π/4] goes through the Taylor
/// series of sin to α¹⁵ and of cos to α¹⁶ (truncation < 1e-16; measured worst 7.2e-16 against
/// libm, test). The tracer draws one azimuth per ray and two angles per facet tilt, where
/// libm's sincos was 8–17 % of a bake's tracing time.
pub fn turn(u: f64) -> (f64, f64) {
    // Taylor coefficients (−1)^k/(2k + 1)! of sin α/α and (−1)^k/(2k)! of cos α in α², folded
    // at compile time so that Horner's rule takes multiplications only (the quotients
    // a2/6, a2/20, … were a chain of dependent divisions).
    const SIN: [f64; 8] = [
        1.0,
        -1.0 / 6.0,
        1.0 / 120.0,
        -1.0 / 5040.0,
        1.0 / 362_880.0,
        -1.0 / 39_916_800.0,
        1.0 / 6_227_020_800.0,
        -1.0 / 1_307_674_368_000.0,
    ];
    const COS: [f64; 9] = [
        1.0,
        -1.0 / 2.0,
        1.0 / 24.0,
        -1.0 / 720.0,
        1.0 / 40_320.0,
        -1.0 / 3_628_800.0,
        1.0 / 479_001_600.0,
        -1.0 / 87_178_291_200.0,
        1.0 / 20_922_789_888_000.0,
    ];
    let t = 4.0 * u;
    let k = t.round();
    let a = (t - k) * std::f64::consts::FRAC_PI_2;
    let a2 = a * a;
    // Estrin's scheme in z = α²: pairs, then pairs of pairs, so the products run side by
    // side (four dependent steps where Horner's rule takes eight; the tilts of rough crystals
    // call this twice each and it was a fifth of their trace).
    let (z, z2) = (a2, a2 * a2);
    let z4 = z2 * z2;
    let s = a
        * ((SIN[0] + SIN[1] * z + (SIN[2] + SIN[3] * z) * z2)
            + (SIN[4] + SIN[5] * z + (SIN[6] + SIN[7] * z) * z2) * z4);
    let c = (COS[0] + COS[1] * z + (COS[2] + COS[3] * z) * z2)
        + (COS[4] + COS[5] * z + (COS[6] + COS[7] * z) * z2) * z4
        + COS[8] * (z4 * z4);
    match (k as i64).rem_euclid(4) {
        0 => (c, s),
        1 => (-s, c),
        2 => (-c, -s),
        _ => (s, -c),
    }
}

/// Two unit vectors completing `d` (unit) to an orthonormal basis.
pub fn basis(d: DVec3) -> (DVec3, DVec3) {
    let helper = if d.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = (helper + -helper.dot(d) * d).normalize();
    (e1, d.cross(e1))
}

/// One face: the plane n·p = offset with outward unit normal n.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Face {
    /// Outward unit normal n.
    pub normal: DVec3,
    /// Plane offset: distance of the face from the centre along n.
    pub offset: f64,
    /// Face area (square of the prism's length unit).
    pub area: f64,
}

/// A hexagonal prism centred at the origin, c-axis along z: hexagon side a, length L.
/// Aspect ratio AR = L/(2a) (van Diedenhoven et al. 2014's convention): AR < 1 plates,
/// AR > 1 columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Prism {
    /// Hexagon side a (unit of `max_dimension`, µm in [`crate::crystal`]).
    pub side: f64,
    /// Prism length L along the c-axis (unit of `side`).
    pub length: f64,
    /// The six prism faces (outward normals at azimuths 30° + 60°·i, so face i + 3 is
    /// opposite face i), then the basal faces +z and −z: [`Prism::exit`] relies on this order.
    pub faces: [Face; 8],
}

impl Prism {
    /// A prism of aspect ratio `aspect_ratio` whose largest dimension max(2a, L) is `max_dimension`.
    pub fn new(aspect_ratio: f64, max_dimension: f64) -> Self {
        let side = if aspect_ratio >= 1.0 {
            max_dimension / (2.0 * aspect_ratio)
        } else {
            max_dimension / 2.0
        };
        let length = 2.0 * side * aspect_ratio;
        let apothem = side * 3f64.sqrt() / 2.0;
        let mut faces = [Face {
            normal: DVec3::ZERO,
            offset: 0.0,
            area: 0.0,
        }; 8];
        for (i, face) in faces.iter_mut().take(6).enumerate() {
            let phi = (30.0 + 60.0 * i as f64).to_radians();
            *face = Face {
                normal: DVec3::new(phi.cos(), phi.sin(), 0.0),
                offset: apothem,
                area: side * length,
            };
        }
        let basal = 1.5 * 3f64.sqrt() * side * side;
        faces[6] = Face {
            normal: DVec3::Z,
            offset: length / 2.0,
            area: basal,
        };
        faces[7] = Face {
            normal: DVec3::NEG_Z,
            offset: length / 2.0,
            area: basal,
        };
        Self {
            side,
            length,
            faces,
        }
    }

    /// Total surface area S.
    pub fn surface_area(&self) -> f64 {
        self.faces.iter().map(|f| f.area).sum()
    }

    /// Projected area seen along unit direction d: ½ Σ A_f |n_f·d| (exact for a convex body).
    pub fn projected_area(&self, d: DVec3) -> f64 {
        0.5 * self
            .faces
            .iter()
            .map(|f| f.area * f.normal.dot(d).abs())
            .sum::<f64>()
    }

    /// The largest projected area over all directions. Opposite faces project alike, so
    /// A(d) = Σ_p A_p |n_p·d| over the four pairs p (three of side faces, one basal), the
    /// support function of the zonotope Σ_p A_p [−n_p, n_p], whose maximum over unit d is its
    /// longest vertex: max over signs ε of |Σ_p ε_p A_p n_p|.
    pub fn max_projected_area(&self) -> f64 {
        let pairs = [0, 1, 2, 6].map(|f| self.faces[f].area * self.faces[f].normal);
        (0..16u32)
            .map(|signs| {
                pairs
                    .iter()
                    .enumerate()
                    .map(|(i, v)| if signs & (1 << i) == 0 { *v } else { -*v })
                    .sum::<DVec3>()
                    .length()
            })
            .fold(0.0, f64::max)
    }

    /// Projected areas A_f max(0, −n_f·d) of the faces a ray along unit `d` can enter by (the
    /// others 0), and their sum A(d).
    pub fn entry_areas(&self, d: DVec3) -> ([f64; 8], f64) {
        let mut areas = [0.0; 8];
        let mut total = 0.0;
        for (a, f) in areas.iter_mut().zip(&self.faces) {
            *a = (-f.area * f.normal.dot(d)).max(0.0);
            total += *a;
        }
        (areas, total)
    }

    /// An entry point uniform over the prism's silhouette along `d`: face f chosen in
    /// proportion to `areas` (from [`Self::entry_areas`], summing to `total`) by `u_face`, then
    /// a point uniform on it from `u`, `v` (and `w`, which of a hexagon's six triangles).
    /// The faces facing the ray project onto the plane across it without overlap and tile the
    /// silhouette, each by a linear map of constant Jacobian |n_f·d|, so the point is uniform
    /// over the silhouette: what a point uniform on a disc across the prism, kept if it hits,
    /// gives, without the misses. Returns (point, face).
    pub fn entry_point(
        &self,
        areas: &[f64; 8],
        total: f64,
        u_face: f64,
        u: f64,
        v: f64,
        w: f64,
    ) -> (DVec3, usize) {
        let mut x = u_face * total;
        let mut face = 0;
        for (f, &a) in areas.iter().enumerate() {
            if a > 0.0 {
                face = f;
                if x < a {
                    break;
                }
                x -= a;
            }
        }
        let n = self.faces[face].normal;
        let centre = self.faces[face].offset * n;
        let point = if face < 6 {
            // A side face: side a across (along n × z), length L along z.
            let across = DVec3::new(-n.y, n.x, 0.0);
            centre + (u - 0.5) * self.side * across + (v - 0.5) * self.length * DVec3::Z
        } else {
            // A basal hexagon: one of its six triangles (centre and two neighbouring vertices at
            // azimuths 60°·j, 60°·(j + 1)), then a point uniform in it.
            const HALF_ROOT3: f64 = 0.866_025_403_784_438_6;
            const VERTICES: [(f64, f64); 7] = [
                (1.0, 0.0),
                (0.5, HALF_ROOT3),
                (-0.5, HALF_ROOT3),
                (-1.0, 0.0),
                (-0.5, -HALF_ROOT3),
                (0.5, -HALF_ROOT3),
                (1.0, 0.0),
            ];
            let j = ((w * 6.0) as usize).min(5);
            let vertex = |i: usize| self.side * DVec3::new(VERTICES[i].0, VERTICES[i].1, 0.0);
            let (a, b) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            centre + a * vertex(j) + b * vertex(j + 1)
        };
        (point, face)
    }

    /// Radius of the smallest sphere about the centre that holds the prism.
    pub fn bounding_radius(&self) -> f64 {
        (self.side * self.side + 0.25 * self.length * self.length).sqrt()
    }

    /// Entry of a ray p + t d from outside: (t, face index), or None if it misses.
    pub fn enter(&self, p: DVec3, d: DVec3) -> Option<(f64, usize)> {
        let mut t_in = f64::NEG_INFINITY;
        let mut t_out = f64::INFINITY;
        let mut face_in = usize::MAX;
        for (i, f) in self.faces.iter().enumerate() {
            let nd = f.normal.dot(d);
            let gap = f.offset - f.normal.dot(p);
            if nd < 0.0 {
                let t = gap / nd;
                if t > t_in {
                    t_in = t;
                    face_in = i;
                }
            } else if nd > 0.0 {
                t_out = t_out.min(gap / nd);
            } else if gap < 0.0 {
                return None; // parallel to the face and outside it
            }
        }
        (face_in != usize::MAX && t_in < t_out && t_in > 0.0).then_some((t_in, face_in))
    }

    /// Exit of a ray p + t d from inside: (t ≥ 0, face index). The nearest face ahead is found
    /// by comparing the fractions gap/(n·d) crosswise (both denominators positive), with one
    /// division at the end. Opposite faces share a normal up to sign, so the ray is ahead of
    /// one face of each pair (side faces j and j + 3, basal 6 and 7): three dot products in the
    /// hexagon's plane and the z component settle all eight, the faces' order being
    /// [`Prism::new`]'s.
    pub fn exit(&self, p: DVec3, d: DVec3) -> (f64, usize) {
        // The best face so far as its fraction num/den; 1/0 stands for "none yet".
        let (mut num, mut den, mut face) = (1.0, 0.0, 0);
        let mut consider = |along: f64, across: f64, offset: f64, ahead: usize, behind: usize| {
            // The pair's face the ray heads for: n·d > 0, gap offset − n·p.
            let (nd, gap, f) = if along > 0.0 {
                (along, offset - across, ahead)
            } else {
                (-along, offset + across, behind)
            };
            if nd > 0.0 && gap.max(0.0) * den < num * nd {
                (num, den, face) = (gap.max(0.0), nd, f);
            }
        };
        for j in 0..3 {
            let n = self.faces[j].normal;
            consider(
                n.x * d.x + n.y * d.y,
                n.x * p.x + n.y * p.y,
                self.faces[j].offset,
                j,
                j + 3,
            );
        }
        consider(d.z, p.z, self.faces[6].offset, 6, 7);
        if den > 0.0 {
            (num / den, face)
        } else {
            (f64::INFINITY, 0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_xoshiro::Xoshiro256PlusPlus;
    use rand_xoshiro::rand_core::{RngCore, SeedableRng};

    /// [`turn`] against libm over a million angles and at the quarter turns (measured worst
    /// 7.2e-16).
    #[test]
    fn turn_matches_libm() {
        let mut worst: f64 = 0.0;
        for i in 0..=1_000_000 {
            let u = i as f64 / 1e6;
            let (c, s) = turn(u);
            let (sl, cl) = (2.0 * std::f64::consts::PI * u).sin_cos();
            worst = worst.max((c - cl).abs()).max((s - sl).abs());
        }
        println!("worst {worst:.1e}");
        assert!(worst < 1e-15, "{worst:e}");
        assert_eq!(turn(0.0), (1.0, 0.0));
        assert_eq!(turn(0.25), (-0.0, 1.0));
    }

    /// Entry points lie on the face they name, on its outer side of every other face's plane
    /// (inside the prism's surface), and the faces come in proportion to their projected
    /// areas.
    #[test]
    fn entry_points_lie_on_the_silhouette() {
        for aspect_ratio in [0.3, 1.0, 2.0] {
            let prism = Prism::new(aspect_ratio, 10.0);
            let d = DVec3::new(0.3, -0.5, 0.81).normalize();
            let (areas, total) = prism.entry_areas(d);
            let mut counts = [0usize; 8];
            let n = 200_000;
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
            let mut uniform = || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
            for _ in 0..n {
                let (u0, u, v, w) = (uniform(), uniform(), uniform(), uniform());
                let (p, f) = prism.entry_point(&areas, total, u0, u, v, w);
                counts[f] += 1;
                let face = prism.faces[f];
                assert!((face.normal.dot(p) - face.offset).abs() < 1e-9);
                for other in &prism.faces {
                    assert!(other.normal.dot(p) <= other.offset + 1e-9);
                }
                assert!(
                    face.normal.dot(d) < 0.0,
                    "entered through a face turned away"
                );
            }
            for f in 0..8 {
                let want = areas[f] / total;
                let got = counts[f] as f64 / n as f64;
                let sigma = (want * (1.0 - want) / n as f64).sqrt();
                assert!(
                    (got - want).abs() <= 5.0 * sigma + 1e-12,
                    "face {f}: {got} vs {want}"
                );
            }
        }
    }

    /// [`Prism::exit`]'s pairwise search finds the face a search over all eight planes finds
    /// (the nearest plane ahead), from points inside towards random directions.
    #[test]
    fn exit_is_the_nearest_plane_ahead() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let mut uniform = || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        for aspect_ratio in [0.2, 1.0, 3.0] {
            let prism = Prism::new(aspect_ratio, 10.0);
            for _ in 0..100_000 {
                let d = DVec3::new(
                    2.0 * uniform() - 1.0,
                    2.0 * uniform() - 1.0,
                    2.0 * uniform() - 1.0,
                )
                .normalize();
                // A point inside: shrink a point of the bounding box until every plane holds it.
                let r = prism.bounding_radius();
                let mut p = r * DVec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
                while prism.faces.iter().any(|f| f.normal.dot(p) > f.offset) {
                    p *= 0.5;
                }
                let (t, face) = prism.exit(p, d);
                let (want_t, want_face) = prism
                    .faces
                    .iter()
                    .enumerate()
                    .filter(|(_, f)| f.normal.dot(d) > 0.0)
                    .map(|(i, f)| ((f.offset - f.normal.dot(p)) / f.normal.dot(d), i))
                    .fold((f64::INFINITY, 0), |a, b| if b.0 < a.0 { b } else { a });
                assert!((t - want_t).abs() <= 1e-12 * r, "{t} vs {want_t}");
                let exit = p + t * d;
                let on = prism.faces[face];
                assert!(
                    face == want_face || (on.normal.dot(exit) - on.offset).abs() < 1e-9 * r,
                    "face {face} vs {want_face}"
                );
            }
        }
    }

    /// The largest projected area bounds A(d) over many directions and is reached by one.
    #[test]
    fn max_projected_area_bounds_every_direction() {
        for aspect_ratio in [0.2, 1.0, 3.0] {
            let prism = Prism::new(aspect_ratio, 10.0);
            let max = prism.max_projected_area();
            let mut seen: f64 = 0.0;
            for i in 0..400 {
                for j in 0..400 {
                    let z = -1.0 + 2.0 * (i as f64 + 0.5) / 400.0;
                    let (c, s) = turn((j as f64 + 0.5) / 400.0);
                    let r = (1.0 - z * z).sqrt();
                    let a = prism.projected_area(DVec3::new(r * c, r * s, z));
                    assert!(a <= max * (1.0 + 1e-12));
                    seen = seen.max(a);
                }
            }
            assert!(seen > 0.999 * max, "AR {aspect_ratio}: {seen} of {max}");
        }
    }
}
