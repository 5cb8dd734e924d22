//! Hexagonal prisms as convex polyhedra: eight planes, their areas, and ray intersection.

/// A 3-vector.
pub type Vec3 = [f64; 3];

pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn add_scaled(a: Vec3, s: f64, b: Vec3) -> Vec3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

pub fn scale(s: f64, a: Vec3) -> Vec3 {
    [s * a[0], s * a[1], s * a[2]]
}

pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn normalize(a: Vec3) -> Vec3 {
    scale(1.0 / dot(a, a).sqrt(), a)
}

/// Two unit vectors completing `d` (unit) to an orthonormal basis.
pub fn basis(d: Vec3) -> (Vec3, Vec3) {
    let helper = if d[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let e1 = normalize(add_scaled(helper, -dot(helper, d), d));
    (e1, cross(d, e1))
}

/// One face: the plane n·p = offset with outward unit normal n.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Face {
    pub normal: Vec3,
    pub offset: f64,
    pub area: f64,
}

/// A hexagonal prism centred at the origin, c-axis along z: hexagon side a, length L.
/// Aspect ratio AR = L/(2a) (van Diedenhoven et al. 2014's convention): AR < 1 plates,
/// AR > 1 columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Prism {
    pub side: f64,
    pub length: f64,
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
            normal: [0.0; 3],
            offset: 0.0,
            area: 0.0,
        }; 8];
        for (i, face) in faces.iter_mut().take(6).enumerate() {
            let phi = (30.0 + 60.0 * i as f64).to_radians();
            *face = Face {
                normal: [phi.cos(), phi.sin(), 0.0],
                offset: apothem,
                area: side * length,
            };
        }
        let basal = 1.5 * 3f64.sqrt() * side * side;
        faces[6] = Face {
            normal: [0.0, 0.0, 1.0],
            offset: length / 2.0,
            area: basal,
        };
        faces[7] = Face {
            normal: [0.0, 0.0, -1.0],
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
    pub fn projected_area(&self, d: Vec3) -> f64 {
        0.5 * self
            .faces
            .iter()
            .map(|f| f.area * dot(f.normal, d).abs())
            .sum::<f64>()
    }

    /// Radius of the smallest sphere about the centre that holds the prism.
    pub fn bounding_radius(&self) -> f64 {
        (self.side * self.side + 0.25 * self.length * self.length).sqrt()
    }

    /// Entry of a ray p + t d from outside: (t, face index), or None if it misses.
    pub fn enter(&self, p: Vec3, d: Vec3) -> Option<(f64, usize)> {
        let mut t_in = f64::NEG_INFINITY;
        let mut t_out = f64::INFINITY;
        let mut face_in = usize::MAX;
        for (i, f) in self.faces.iter().enumerate() {
            let nd = dot(f.normal, d);
            let gap = f.offset - dot(f.normal, p);
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
    pub fn exit(&self, p: Vec3, d: Vec3) -> (f64, usize) {
        let mut best = (f64::INFINITY, 0);
        for (i, f) in self.faces.iter().enumerate() {
            let nd = dot(f.normal, d);
            if nd > 0.0 {
                let t = ((f.offset - dot(f.normal, p)) / nd).max(0.0);
                if t < best.0 {
                    best = (t, i);
                }
            }
        }
        best
    }
}
