//! Hexagonal prisms as convex polyhedra: eight planes, their areas, and ray intersection.

use glam::DVec3;

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
    /// The six prism faces, then the basal faces +z and −z.
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

    /// Exit of a ray p + t d from inside: (t ≥ 0, face index).
    pub fn exit(&self, p: DVec3, d: DVec3) -> (f64, usize) {
        let mut best = (f64::INFINITY, 0);
        for (i, f) in self.faces.iter().enumerate() {
            let nd = f.normal.dot(d);
            if nd > 0.0 {
                let t = ((f.offset - f.normal.dot(p)) / nd).max(0.0);
                if t < best.0 {
                    best = (t, i);
                }
            }
        }
        best
    }
}
