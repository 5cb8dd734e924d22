//! Occluders and media boundaries for Biri et al. 2006: triangle meshes (boxes, OBJ files),
//! spheres, their intersections with rays, and the shadow planes of a point light (§5.1.1)
//! as the crossings a view ray makes with them.
//!
//! # Shadow planes as a crossing list
//! For a light S and any triangle t, let F_t = {S + s(Y − S) : Y ∈ t, s > 1} be the region t
//! shadows. The number n(X) of triangles crossed by the segment X → S is the number of F_t
//! containing X, and X is in shadow iff n(X) > 0. Along a view ray, n changes only where the
//! ray crosses a triangle (never before its first surface hit, where the ray ends) or a
//! *shadow plane*: the infinite quad {S + s(Y − S) : Y ∈ edge, s ≥ 1} of an edge. Crossing an
//! edge's plane enters F_t of each adjacent triangle t lying on the side it moves to: the
//! change is sign(ω·m) Σ_t sign(m·(w_t − S)), m the plane's normal and w_t the triangle's
//! third vertex. For an edge between two triangles on opposite sides of its plane the sum is
//! 0; it is ±2 exactly where the mesh folds back, the silhouette (§5.1.1's edges "common to a
//! front-facing triangle regarding the light position and one back facing it"). So the
//! per-pixel list of silhouette-plane crossings, sorted by distance and summed from n(O) at
//! the eye, is the paper's stencil count (§5.1.5: front faces increment, back faces
//! decrement), without its camera-in-shadow special case, and it holds for any triangle soup,
//! closed or not. A sphere's silhouette is a circle: its shadow plane is the cone from S
//! tangent to it, beyond the circle's plane.

use glam::DVec3;
use std::path::Path;

/// The largest OBJ file a scene may name (bytes).
pub const MAX_OBJ_BYTES: u64 = 256 << 20;

/// Rays closer than this to a surface (m) do not hit it again (self-intersection).
pub const SURFACE_EPSILON_M: f64 = 1e-6;

/// A triangle mesh with its edge adjacency.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Vertex positions (m).
    pub vertices: Vec<DVec3>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[usize; 3]>,
    /// Each distinct edge (lower index first) with the triangles that share it.
    pub edges: Vec<Edge>,
    /// Axis-aligned bounds.
    pub bounds: (DVec3, DVec3),
    /// A bounding-volume hierarchy over the triangles (`triangles` is in its leaf order).
    bvh: Vec<Node>,
}

/// A BVH node: its box, and either a leaf's range of triangles or two children (the next
/// node and `right`).
#[derive(Debug, Clone, PartialEq)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first triangle and count; inner: count 0.
    first: usize,
    count: usize,
    right: usize,
}

/// Triangles per BVH leaf at most.
const LEAF: usize = 4;

fn triangle_bounds(v: &[DVec3], t: &[usize; 3]) -> (DVec3, DVec3) {
    let [a, b, c] = t.map(|i| v[i]);
    (a.min(b).min(c), a.max(b).max(c))
}

/// Builds the BVH of `tris` (reordered in place) by median splits along the widest axis of
/// the centroids; returns the root's index in `nodes`.
fn build(v: &[DVec3], tris: &mut [[usize; 3]], offset: usize, nodes: &mut Vec<Node>) -> usize {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let (mut clo, mut chi) = (lo, hi);
    for t in tris.iter() {
        let (a, b) = triangle_bounds(v, t);
        lo = lo.min(a);
        hi = hi.max(b);
        let c = 0.5 * (a + b);
        clo = clo.min(c);
        chi = chi.max(c);
    }
    let index = nodes.len();
    nodes.push(Node {
        lo,
        hi,
        first: offset,
        count: tris.len(),
        right: 0,
    });
    if tris.len() > LEAF {
        let ext = chi - clo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = tris.len() / 2;
        let key = |t: &[usize; 3]| {
            let (a, b) = triangle_bounds(v, t);
            a[axis] + b[axis]
        };
        tris.select_nth_unstable_by(mid, |a, b| key(a).total_cmp(&key(b)));
        let (left, right) = tris.split_at_mut(mid);
        build(v, left, offset, nodes);
        let r = build(v, right, offset + mid, nodes);
        nodes[index].count = 0;
        nodes[index].right = r;
    }
    index
}

/// An edge of a [`Mesh`] and the triangles on it: with each, the vertex opposite the edge.
#[derive(Debug, Clone, PartialEq)]
pub struct Edge {
    /// Its two vertices.
    pub v: [usize; 2],
    /// The vertices opposite the edge in the triangles that share it.
    pub opposite: Vec<usize>,
}

impl Mesh {
    /// A mesh from vertices and triangles (indices checked by the caller); degenerate
    /// triangles (zero area) are dropped.
    pub fn new(vertices: Vec<DVec3>, triangles: Vec<[usize; 3]>) -> Self {
        let triangles: Vec<[usize; 3]> = triangles
            .into_iter()
            .filter(|t| {
                let [a, b, c] = t.map(|i| vertices[i]);
                (b - a).cross(c - a).length_squared() > 0.0
            })
            .collect();
        let mut map: std::collections::BTreeMap<(usize, usize), Vec<usize>> = Default::default();
        for t in &triangles {
            for e in 0..3 {
                let (a, b, w) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
                map.entry((a.min(b), a.max(b))).or_default().push(w);
            }
        }
        let edges = map
            .into_iter()
            .map(|((a, b), opposite)| Edge {
                v: [a, b],
                opposite,
            })
            .collect();
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for v in &vertices {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        let mut triangles = triangles;
        let mut bvh = Vec::new();
        if !triangles.is_empty() {
            build(&vertices, &mut triangles, 0, &mut bvh);
        }
        Self {
            vertices,
            triangles,
            edges,
            bounds: (lo, hi),
            bvh,
        }
    }

    /// Calls `visit` with each triangle whose leaf box the ray o + x d, x ∈ [0, limit], meets;
    /// `visit` may shorten the limit (to the nearest hit so far).
    fn traverse(&self, o: DVec3, d: DVec3, x_max: f64, mut visit: impl FnMut(usize, &mut f64)) {
        let mut limit = x_max;
        let mut stack = Vec::with_capacity(32);
        if !self.bvh.is_empty() {
            stack.push(0);
        }
        while let Some(i) = stack.pop() {
            let n = &self.bvh[i];
            if !ray_box(o, d, n.lo, n.hi).is_some_and(|(a, b)| b >= 0.0 && a <= limit) {
                continue;
            }
            if n.count > 0 {
                for t in n.first..n.first + n.count {
                    visit(t, &mut limit);
                }
            } else {
                stack.push(n.right);
                stack.push(i + 1);
            }
        }
    }

    /// The closed 12-triangle mesh of the box [min, max], outward-wound.
    pub fn cuboid(min: DVec3, max: DVec3) -> Self {
        let v: Vec<DVec3> = (0..8)
            .map(|i| {
                DVec3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                )
            })
            .collect();
        let quads = [
            [0, 2, 3, 1], // z = min
            [4, 5, 7, 6], // z = max
            [0, 1, 5, 4], // y = min
            [2, 6, 7, 3], // y = max
            [0, 4, 6, 2], // x = min
            [1, 3, 7, 5], // x = max
        ];
        let tris = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Self::new(v, tris)
    }

    /// The nearest hit of the ray o + x d with x in (ε, `x_max`): distance and unit normal
    /// facing the ray.
    pub fn hit(&self, o: DVec3, d: DVec3, x_max: f64) -> Option<(f64, DVec3)> {
        let mut best: Option<(f64, DVec3)> = None;
        self.traverse(o, d, x_max, |t, limit| {
            let [a, b, c] = self.triangles[t].map(|i| self.vertices[i]);
            if let Some(x) = ray_triangle(o, d, a, b, c)
                && x > SURFACE_EPSILON_M
                && x < *limit
            {
                let n = (b - a).cross(c - a).normalize();
                best = Some((x, if n.dot(d) > 0.0 { -n } else { n }));
                *limit = x;
            }
        });
        best
    }

    /// Triangles crossed by the open segment from `p` to `q`.
    pub fn crossings(&self, p: DVec3, q: DVec3) -> usize {
        let d = q - p;
        let len = d.length();
        if len == 0.0 {
            return 0;
        }
        let d = d / len;
        let mut count = 0;
        self.traverse(p, d, len, |t, _| {
            let [a, b, c] = self.triangles[t].map(|i| self.vertices[i]);
            if ray_triangle(p, d, a, b, c)
                .is_some_and(|x| x > SURFACE_EPSILON_M && x < len - SURFACE_EPSILON_M)
            {
                count += 1;
            }
        });
        count
    }

    /// Whether `p` is inside the mesh: an odd number of crossings along a fixed skew ray
    /// (meaningful for a closed mesh).
    pub fn contains(&self, p: DVec3) -> bool {
        let far = p + DVec3::new(0.577_2, 0.411_3, 0.759_8).normalize()
            * (1.0 + 4.0 * (self.bounds.1 - self.bounds.0).length() + (p - self.bounds.0).length());
        self.crossings(p, far) % 2 == 1
    }

    /// The silhouette of the mesh from a light at `s`: each edge whose shadow plane changes
    /// the shadow count (module docs), with that change's weight Σ_t sign(m·(w_t − S)).
    pub fn silhouette(&self, s: DVec3) -> Vec<ShadowPlane> {
        self.edges
            .iter()
            .filter_map(|e| {
                let (a, b) = (self.vertices[e.v[0]], self.vertices[e.v[1]]);
                let m = (a - s).cross(b - s);
                let weight: i32 = e
                    .opposite
                    .iter()
                    .map(|&w| {
                        let side = m.dot(self.vertices[w] - s);
                        if side > 0.0 {
                            1
                        } else if side < 0.0 {
                            -1
                        } else {
                            0
                        }
                    })
                    .sum();
                (weight != 0 && m.length_squared() > 0.0).then_some(ShadowPlane {
                    a,
                    b,
                    normal: m,
                    weight,
                })
            })
            .collect()
    }
}

/// The infinite quad of a silhouette edge [a, b] away from the light (§5.1.1) and how much
/// crossing it along +normal changes the shadow count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowPlane {
    /// The edge's first vertex.
    pub a: DVec3,
    /// The edge's second vertex.
    pub b: DVec3,
    /// (a − S) × (b − S).
    pub normal: DVec3,
    /// The count's change when crossing towards +normal.
    pub weight: i32,
}

impl ShadowPlane {
    /// Where the ray o + x d crosses the quad, and the count's change there.
    pub fn crossing(&self, s: DVec3, o: DVec3, d: DVec3) -> Option<(f64, i32)> {
        let dn = d.dot(self.normal);
        if dn == 0.0 {
            return None;
        }
        let x = (s - o).dot(self.normal) / dn;
        if x <= 0.0 {
            return None;
        }
        // X − S = α (a − S) + β (b − S) on the plane: inside the quad iff α, β ≥ 0 and
        // α + β ≥ 1 (beyond the edge, away from the light).
        let p = o + x * d - s;
        let (u, v) = (self.a - s, self.b - s);
        let (uu, uv, vv) = (u.dot(u), u.dot(v), v.dot(v));
        let (pu, pv) = (p.dot(u), p.dot(v));
        let det = uu * vv - uv * uv;
        if det <= 0.0 {
            return None;
        }
        let alpha = (pu * vv - pv * uv) / det;
        let beta = (pv * uu - pu * uv) / det;
        (alpha >= 0.0 && beta >= 0.0 && alpha + beta >= 1.0)
            .then_some((x, if dn > 0.0 { self.weight } else { -self.weight }))
    }
}

/// A sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Centre (m).
    pub center: DVec3,
    /// Radius (m), > 0.
    pub radius: f64,
}

impl Sphere {
    /// The nearest hit in (ε, `x_max`): distance and unit normal facing the ray.
    pub fn hit(&self, o: DVec3, d: DVec3, x_max: f64) -> Option<(f64, DVec3)> {
        let (x0, x1) = ray_sphere(o, d, self.center, self.radius)?;
        let x = if x0 > SURFACE_EPSILON_M { x0 } else { x1 };
        if !(x > SURFACE_EPSILON_M && x < x_max) {
            return None;
        }
        let n = (o + x * d - self.center) / self.radius;
        Some((x, if n.dot(d) > 0.0 { -n } else { n }))
    }

    /// Whether the open segment p → q meets the sphere.
    pub fn blocks(&self, p: DVec3, q: DVec3) -> bool {
        let d = q - p;
        let len = d.length();
        if len == 0.0 {
            return false;
        }
        ray_sphere(p, d / len, self.center, self.radius)
            .is_some_and(|(x0, x1)| x1 > SURFACE_EPSILON_M && x0 < len - SURFACE_EPSILON_M)
    }

    /// The crossings of the ray o + x d (x > 0) with the sphere's shadow cone from a light at
    /// `s` outside it (module docs): each toggles whether the ray is in the sphere's shadow.
    pub fn shadow_crossings(&self, s: DVec3, o: DVec3, d: DVec3, out: &mut Vec<f64>) {
        let axis = self.center - s;
        let dist = axis.length();
        if dist <= self.radius {
            return;
        }
        let axis = axis / dist;
        let cos2 = 1.0 - (self.radius / dist).powi(2);
        // The silhouette circle's plane: (X − S)·axis = dist·cos²α.
        let cut = dist * cos2;
        for x in nappe_roots(s, axis, cos2, o, d, 1.0) {
            if (o + x * d - s).dot(axis) > cut {
                out.push(x);
            }
        }
    }
}

/// The roots x > 0 of ((X − S)·a)² = c²|X − S|² on X = o + x d on the nappe where
/// (X − S)·a has the sign of `nappe`.
pub fn nappe_roots(s: DVec3, a: DVec3, cos2: f64, o: DVec3, d: DVec3, nappe: f64) -> Vec<f64> {
    let w = o - s;
    let (da, wa) = (d.dot(a), w.dot(a));
    let qa = da * da - cos2;
    let qb = 2.0 * (da * wa - cos2 * d.dot(w));
    let qc = wa * wa - cos2 * w.dot(w);
    let mut roots = Vec::with_capacity(2);
    if qa.abs() < 1e-14 {
        if qb != 0.0 {
            roots.push(-qc / qb);
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            return roots;
        }
        let sq = disc.sqrt();
        let q = -0.5 * (qb + qb.signum() * sq);
        if q != 0.0 {
            roots.push(q / qa);
            roots.push(qc / q);
        } else {
            roots.push(0.0);
        }
    }
    roots.retain(|&x| x > 0.0 && x.is_finite() && (w + x * d).dot(a) * nappe > 0.0);
    roots.sort_by(f64::total_cmp);
    roots
}

/// Entry and exit distances of the line o + x d through the box [lo, hi], if it meets it.
pub fn ray_box(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let (mut a, mut b) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        if d[k] == 0.0 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return None;
            }
        } else {
            let (t0, t1) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
            a = a.max(t0.min(t1));
            b = b.min(t0.max(t1));
        }
    }
    (a <= b).then_some((a, b))
}

/// The two distances of the line o + x d through the sphere, ascending.
pub fn ray_sphere(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<(f64, f64)> {
    let w = o - c;
    let b = w.dot(d);
    let disc = b * b - (w.dot(w) - r * r);
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    Some((-b - sq, -b + sq))
}

/// Möller–Trumbore: the distance along the ray o + x d to triangle (a, b, c).
pub fn ray_triangle(o: DVec3, d: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<f64> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-18 * e1.length_squared().max(e2.length_squared()) {
        return None;
    }
    let inv = 1.0 / det;
    let t = o - a;
    let u = t.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = t.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) * inv)
}

/// Reads a Wavefront OBJ file's vertices (`v`) and faces (`f`, polygons fanned into
/// triangles; `v`, `v/vt`, `v//vn`, `v/vt/vn` and negative indices); other statements are
/// ignored. Errors name the file and line.
pub fn read_obj(path: &Path) -> Result<Mesh, String> {
    // Only a regular file of at most MAX_OBJ_BYTES: a FIFO or /dev/zero is refused before
    // anything is read.
    let bytes = format::read_regular_file(path, MAX_OBJ_BYTES)
        .map_err(|(op, e)| format!("{}: {op}: {e}", path.display()))?;
    let text =
        String::from_utf8(bytes).map_err(|e| format!("{}: not UTF-8 text: {e}", path.display()))?;
    parse_obj(&text, &path.display().to_string())
}

/// [`read_obj`] of the text of a file named `origin`: `v` and `f` lines (polygons fanned into
/// triangles, negative indices relative); other lines ignored.
///
/// Written here rather than with `tobj` because an occluder needs only positions and faces,
/// and a refusal must name the file, line and value of a bad number or index — `tobj`'s
/// `LoadError` is a fieldless enum (`PositionParseError`, `FaceVertexOutOfBounds`, …) that
/// carries none of them.
pub fn parse_obj(text: &str, origin: &str) -> Result<Mesh, String> {
    let mut vertices = Vec::new();
    let mut faces: Vec<(usize, Vec<i64>)> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let at = |m: String| format!("{origin}:{}: {m}", i + 1);
        let line = line.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let xyz: Vec<f64> = words
                    .by_ref()
                    .take(3)
                    .map(|w| {
                        w.parse::<f64>()
                            .map_err(|_| at(format!("vertex coordinate {w:?} is not a number")))
                    })
                    .collect::<Result<_, _>>()?;
                if xyz.len() < 3 || xyz.iter().any(|v| !v.is_finite()) {
                    return Err(at(format!(
                        "a vertex needs three finite coordinates: {line:?}"
                    )));
                }
                vertices.push(DVec3::new(xyz[0], xyz[1], xyz[2]));
            }
            Some("f") => {
                let idx: Vec<i64> = words
                    .map(|w| {
                        w.split('/')
                            .next()
                            .and_then(|v| v.parse::<i64>().ok())
                            .filter(|&v| v != 0)
                            .ok_or_else(|| at(format!("face vertex {w:?} is not a vertex index")))
                    })
                    .collect::<Result<_, _>>()?;
                if idx.len() < 3 {
                    return Err(at(format!("a face needs at least 3 vertices: {line:?}")));
                }
                faces.push((i + 1, idx));
            }
            _ => {}
        }
    }
    let mut triangles = Vec::new();
    let n = vertices.len() as i64;
    for (line, idx) in faces {
        let resolve = |v: i64| {
            // Indices are 1-based; negative ones count back from the vertices so far (here:
            // from all of them, the common case of vertices before faces).
            let k = if v > 0 { v - 1 } else { n + v };
            if (0..n).contains(&k) {
                Ok(k as usize)
            } else {
                Err(format!(
                    "{origin}:{line}: face vertex index {v} is outside 1…{n} (the file has {n} \
                     vertices)"
                ))
            }
        };
        let v: Vec<usize> = idx.into_iter().map(resolve).collect::<Result<_, _>>()?;
        for k in 1..v.len() - 1 {
            triangles.push([v[0], v[k], v[k + 1]]);
        }
    }
    if triangles.is_empty() {
        return Err(format!("{origin}: no faces (f lines): nothing to occlude"));
    }
    Ok(Mesh::new(vertices, triangles))
}

/// Distances along the ray where it enters and leaves the box, if it does (t ≥ 0): the part of
/// [`ray_box`]'s line ahead of the origin.
pub fn box_span(grid_min: DVec3, grid_max: DVec3, origin: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let (a, b) = ray_box(origin, d, grid_min, grid_max)?;
    let a = a.max(0.0);
    (a < b).then_some((a, b))
}

/// Two unit vectors completing the unit vector `d` to an orthonormal basis (d, e1, e2).
pub fn basis(d: DVec3) -> (DVec3, DVec3) {
    let helper = if d.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = (helper - helper.dot(d) * d).normalize();
    (e1, d.cross(e1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cuboid_is_closed_and_its_silhouette_from_a_corner_light_has_six_edges() {
        let m = Mesh::cuboid(DVec3::ZERO, DVec3::ONE);
        assert_eq!(m.triangles.len(), 12);
        assert!(m.edges.iter().all(|e| e.opposite.len() == 2));
        // Seen from beyond a corner, a cube's outline is a hexagon.
        let s = DVec3::splat(3.0);
        let sil = m.silhouette(s);
        assert_eq!(sil.len(), 6, "{sil:?}");
        assert!(sil.iter().all(|p| p.weight.abs() == 2));
        assert!(m.contains(DVec3::splat(0.5)) && !m.contains(DVec3::splat(1.5)));
    }

    /// Along many rays, the shadow state from the crossings equals a shadow ray's at every
    /// sample point outside the occluder.
    #[test]
    fn crossings_match_shadow_rays() {
        let sphere = Sphere {
            center: DVec3::new(1.4, 2.2, 3.5),
            radius: 0.7,
        };
        let mesh = Mesh::cuboid(DVec3::new(-1.5, 0.0, 2.0), DVec3::new(-0.7, 6.0, 2.8));
        let mut rng = 12345u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut mismatches = Vec::new();
        for case in 0..400 {
            let s = DVec3::new(next() * 8.0 - 4.0, next() * 6.0, next() * 16.0 - 6.0);
            let o = DVec3::new(next() * 8.0 - 4.0, next() * 4.0, -6.0 + next() * 4.0);
            let d = (DVec3::new(next() * 2.0 - 1.0, next() * 2.0 - 1.0, 1.0)).normalize();
            if (s - sphere.center).length() <= sphere.radius || mesh.contains(s) {
                continue;
            }
            let mut roots = Vec::new();
            sphere.shadow_crossings(s, o, d, &mut roots);
            let planes = mesh.silhouette(s);
            let mut events: Vec<(f64, i32)> =
                planes.iter().filter_map(|p| p.crossing(s, o, d)).collect();
            events.sort_by(|a, b| a.0.total_cmp(&b.0));
            let end = [
                sphere.hit(o, d, f64::INFINITY),
                mesh.hit(o, d, f64::INFINITY),
            ]
            .iter()
            .flatten()
            .map(|h| h.0)
            .fold(30.0, f64::min);
            for k in 0..300 {
                let x = (k as f64 + 0.5) / 300.0 * end;
                let p = o + x * d;
                let on = sphere.blocks(o, s) ^ (roots.iter().filter(|&&r| r < x).count() % 2 == 1);
                let count = mesh.crossings(o, s) as i32
                    + events.iter().filter(|e| e.0 < x).map(|e| e.1).sum::<i32>();
                let near = roots
                    .iter()
                    .chain(events.iter().map(|e| &e.0))
                    .any(|r| (r - x).abs() < 1e-6);
                if !near && (on != sphere.blocks(p, s) || (count > 0) != (mesh.crossings(p, s) > 0))
                {
                    mismatches.push((
                        case,
                        x,
                        on,
                        sphere.blocks(p, s),
                        count,
                        mesh.crossings(p, s),
                    ));
                    break;
                }
            }
        }
        assert!(
            mismatches.is_empty(),
            "{} rays: {:?}",
            mismatches.len(),
            &mismatches[..mismatches.len().min(5)]
        );
    }

    #[test]
    fn obj_errors_name_file_and_line() {
        let e = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "a.obj").unwrap_err();
        assert!(
            e.starts_with("a.obj:4:") && e.contains("outside 1…3"),
            "{e}"
        );
        let e = parse_obj("v 0 0 zero\n", "b.obj").unwrap_err();
        assert!(e.starts_with("b.obj:1:") && e.contains("\"zero\""), "{e}");
        let e = parse_obj("v 0 0 0\nf 1 1\n", "c.obj").unwrap_err();
        assert!(e.starts_with("c.obj:2:") && e.contains("at least 3"), "{e}");
        let e = parse_obj("v 0 0 0\n", "d.obj").unwrap_err();
        assert!(e.contains("no faces"), "{e}");
        let m = parse_obj(
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2//2 -2 -1\n",
            "q.obj",
        )
        .unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }
}
