//! The CPU reference of Biri et al. 2006 (module docs of [`super`]): per pixel, the surface
//! the ray meets (§5.1.2), then for each light the lit pieces of the ray from the silhouette
//! planes' crossings (§4.2, §5.1.4–5.1.5), each piece's medium contribution Γ(F) − Γ(E) in
//! closed form (Eq. 2, from the bake's kernel), and the ambient fog (§3). All cores.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use runtime::{Tables, sample};

use super::{Kernel, Settings};
use crate::geometry::{ShadowPlane, Sphere, nappe_roots};
use crate::objects::{Light, Medium, Occluder, OccluderShape, Region};
use crate::{checks::FrameError, frame::Frame, image::Image};

/// The light's distance h from a ray is taken as at least this (m): Eq. 2's 1/h is singular
/// for a ray through the light, whose radiance is the light's own.
pub const MIN_LIGHT_DISTANCE_M: f64 = 1e-3;

/// One medium's optics per channel.
#[derive(Debug, Clone)]
struct Optics {
    region: Region,
    beta_ext: [f64; 3],
    beta_sca: [f64; 3],
    ambient: [f64; 3],
    field: usize,
}

/// A light with its shadow planes: per occluder, the silhouette of a mesh (§5.1.1) or the
/// sphere whose tangent cone it casts.
struct Prepared {
    light: Light,
    planes: Vec<ShadowPlane>,
    spheres: Vec<Sphere>,
    /// The shadow state at the eye: the same for every pixel of a pinhole camera.
    at_eye: ShadowState,
}

/// How far along an orthographic pixel's ray its shadow state is found (m): 0.1 mm, as the
/// GPU's (f32) surface offset.
pub const ORTHOGRAPHIC_START_M: f64 = 1e-4;

/// Where a ray starts, towards one light: its shadow count (the triangles and spheres between
/// it and the light) and per sphere whether it blocks the light.
struct ShadowState {
    count: i32,
    sphere_blocks: Vec<bool>,
}

impl ShadowState {
    /// The state at `o` towards a light at `s` among `occluders` (`spheres`, theirs).
    fn at(occluders: &[Occluder], spheres: &[Sphere], o: DVec3, s: DVec3) -> Self {
        ShadowState {
            count: occluders.iter().map(|oc| oc.blockers(o, s) as i32).sum(),
            sphere_blocks: spheres.iter().map(|sp| sp.blocks(o, s)).collect(),
        }
    }
}

/// What a render measured, per stage (the paper's Table 1 on the CPU).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BiriReport {
    /// Stage 1: silhouettes of every occluder from every light (s).
    pub silhouettes_s: f64,
    /// Stage 2: surfaces, shaded and attenuated, with hard shadows (s).
    pub surfaces_s: f64,
    /// Stages 3–5: the medium contribution of each ray's lit pieces, from the sorted
    /// crossings with the shadow planes, and the ambient fog (s).
    pub medium_s: f64,
    /// Silhouette edges (shadow planes) over all lights.
    pub shadow_planes: usize,
    /// Mean number of shadow-plane crossings per ray and light.
    pub crossings_per_ray: f64,
}

/// Renders `frame` (its `[[medium]]`, `[[occluder]]`, `[[light]]`, camera and ground) with
/// the kernel `settings.kernel`. Fails before any work when a medium's field has no kernel
/// table in the bake.
pub fn render(
    tables: &Tables,
    frame: &Frame,
    settings: &Settings,
) -> Result<(Image, BiriReport), FrameError> {
    super::check_scene(frame)?;
    let media = optics(tables, &frame.media)?;
    let grid =
        grid::ThetaGrid::new(tables.theta_step_deg).map_err(|e| FrameError(e.to_string()))?;
    let axes = frame
        .camera
        .axes()
        .ok_or_else(|| FrameError("camera look_at_m equals position_m".into()))?;
    let (w, h) = (frame.width, frame.height);
    let o = frame.camera.position_m;
    let ray = |p: usize| frame.camera.pixel(axes, (p % w, p / w), (w, h));
    let mut report = BiriReport::default();

    let t = Instant::now();
    let prepared: Vec<Prepared> = frame
        .lights
        .iter()
        .map(|l| {
            let mut planes = Vec::new();
            let mut spheres = Vec::new();
            for oc in &frame.occluders {
                match &oc.shape {
                    OccluderShape::Mesh(m) => planes.extend(m.silhouette(l.position_m)),
                    OccluderShape::Sphere(s) => spheres.push(*s),
                }
            }
            Prepared {
                light: *l,
                at_eye: ShadowState::at(&frame.occluders, &spheres, o, l.position_m),
                planes,
                spheres,
            }
        })
        .collect();
    report.silhouettes_s = t.elapsed().as_secs_f64();
    report.shadow_planes = prepared.iter().map(|p| p.planes.len()).sum();

    let ctx = Context {
        tables,
        grid: &grid,
        kernel: settings.kernel,
        occluders: &frame.occluders,
        orthographic: frame.camera.ortho_half_height_m((w, h)).is_some(),
        media: &media,
        ground_albedo: frame.ground_albedo,
    };
    // Stage 2: the surface each ray meets, shaded and attenuated.
    let t = Instant::now();
    let surfaces: Vec<(f64, [f64; 3])> = (0..w * h)
        .into_par_iter()
        .map(|p| {
            let (o, d) = ray(p);
            ctx.surface(o, d, &prepared)
        })
        .collect();
    report.surfaces_s = t.elapsed().as_secs_f64();
    // Stages 3–5: the medium's contribution over each ray's lit pieces.
    let t = Instant::now();
    let medium: Vec<([f64; 3], f64, usize)> = (0..w * h)
        .into_par_iter()
        .map(|p| {
            let (o, d) = ray(p);
            ctx.medium(o, d, surfaces[p].0, &prepared)
        })
        .collect();
    report.medium_s = t.elapsed().as_secs_f64();
    let crossings: usize = medium.iter().map(|m| m.2).sum();
    report.crossings_per_ray = crossings as f64 / (w * h * prepared.len()).max(1) as f64;
    let rgb = surfaces
        .iter()
        .zip(&medium)
        .map(|((_, s), (m, _, _))| std::array::from_fn(|c| (s[c] + m[c]) as f32))
        .collect();
    let transparency = medium.iter().map(|m| m.1 as f32).collect();
    Ok((
        Image {
            width: w,
            height: h,
            rgb,
            transparency,
        },
        report,
    ))
}

fn optics(tables: &Tables, media: &[Medium]) -> Result<Vec<Optics>, FrameError> {
    media
        .iter()
        .map(|m| {
            let field = crate::objects::field_index(tables, &m.field)?;
            let f = &tables.fields[field];
            if f.biri.is_none() {
                return Err(FrameError(format!(
                    "field {:?} of the bake in {} has no Biri kernel table ({}.biri.exr, \
                     written since schema 1 of it): bake it again",
                    f.name,
                    tables.dir.display(),
                    f.name
                )));
            }
            let n = m.number_density_per_m3;
            Ok(Optics {
                region: m.region,
                beta_ext: f.sigma_ext_m2.map(|s| n * s),
                beta_sca: f.sigma_sca_m2.map(|s| n * s),
                ambient: m.ambient,
                field,
            })
        })
        .collect()
}

struct Context<'a> {
    tables: &'a Tables,
    grid: &'a grid::ThetaGrid,
    kernel: Kernel,
    occluders: &'a [Occluder],
    /// Each pixel's ray starts at its own point (its shadow state found there), not the eye.
    orthographic: bool,
    media: &'a [Optics],
    ground_albedo: f64,
}

impl Context<'_> {
    /// Optical depth per channel of the media along p + x u, x ∈ [0, len], leaving out
    /// medium `skip`.
    fn depth(&self, p: DVec3, u: DVec3, len: f64, skip: Option<usize>) -> [f64; 3] {
        let mut tau = [0.0; 3];
        for (i, m) in self.media.iter().enumerate() {
            if Some(i) == skip {
                continue;
            }
            if let Some((a, b)) = m.region.span(p, u, len) {
                for c in 0..3 {
                    tau[c] += m.beta_ext[c] * (b - a);
                }
            }
        }
        tau
    }

    /// Whether the segment p → q passes no occluder.
    fn visible(&self, p: DVec3, q: DVec3) -> bool {
        self.occluders.iter().all(|o| o.blockers(p, q) == 0)
    }

    /// The first surface along o + x d: its distance (∞ for none) and its radiance at the eye
    /// (§5.1.2, attenuated by the media in between).
    fn surface(&self, o: DVec3, d: DVec3, lights: &[Prepared]) -> (f64, [f64; 3]) {
        let mut best: Option<(f64, DVec3, f64)> = None;
        if d.y < 0.0 {
            best = Some((-o.y / d.y, DVec3::Y, self.ground_albedo));
        }
        for oc in self.occluders {
            if let Some((x, n)) = oc.hit(o, d, best.map_or(f64::INFINITY, |b| b.0)) {
                best = Some((x, n, oc.albedo));
            }
        }
        let Some((x, n, albedo)) = best else {
            return (f64::INFINITY, [0.0; 3]);
        };
        let p = o + x * d;
        let mut l = [0.0; 3];
        for pl in lights {
            let light = &pl.light;
            let to = light.position_m - p;
            let r = to.length();
            let u = to / r;
            let cos = n.dot(u);
            if cos <= 0.0 || !in_spot(light, -u) {
                continue;
            }
            if !self.visible(p + n * 1e-6 * (1.0 + r), light.position_m) {
                continue;
            }
            let tau = self.depth(light.position_m, -u, r, None);
            for c in 0..3 {
                l[c] += albedo * light.intensity[c] * cos / (std::f64::consts::PI * r * r)
                    * (-tau[c]).exp();
            }
        }
        let tau = self.depth(o, d, x, None);
        (x, std::array::from_fn(|c| l[c] * (-tau[c]).exp()))
    }

    /// The medium's radiance along o + x d, x ∈ [0, x_end]: each light's lit pieces' Γ
    /// differences and the ambient fog; with the media's transparency along the ray and the
    /// number of shadow-plane crossings it made.
    fn medium(
        &self,
        o: DVec3,
        d: DVec3,
        x_end: f64,
        lights: &[Prepared],
    ) -> ([f64; 3], f64, usize) {
        let mut out = [0.0; 3];
        let mut crossings = 0;
        // Each medium's span of the ray and the other media's optical depth before it.
        let spans: Vec<Option<(f64, f64, [f64; 3])>> = (0..self.media.len())
            .map(|m| {
                let (a, b) = self.media[m].region.span(o, d, x_end)?;
                Some((a, b, self.depth(o, d, a, Some(m))))
            })
            .collect();
        for pl in lights {
            let (lit, n) = self.lit_pieces(pl, o, d, x_end);
            crossings += n;
            for (m, span) in spans.iter().enumerate() {
                let Some((a, b, front)) = *span else { continue };
                for &(x0, x1) in &lit {
                    let (x0, x1) = (x0.max(a), x1.min(b));
                    if x0 < x1 {
                        let g = self.gamma(m, &pl.light, o, d, a, (x0, x1), front);
                        for c in 0..3 {
                            out[c] += g[c];
                        }
                    }
                }
            }
        }
        let mut tau_all = [0.0; 3];
        for (m, span) in self.media.iter().zip(&spans) {
            // The media in front of this one's span (they do not overlap it).
            let Some((a, b, front)) = *span else { continue };
            for c in 0..3 {
                let own = m.beta_ext[c] * (b - a);
                out[c] += m.ambient[c] * (-front[c]).exp() * -(-own).exp_m1();
                tau_all[c] += own;
            }
        }
        (out, (-tau_all[1]).exp(), crossings)
    }

    /// The lit pieces of o + x d, x ∈ [0, x_end], for one light: outside every shadow (the
    /// sorted crossings with the silhouette planes and spheres' cones, summed from the count
    /// at the ray's start) and inside a spot's cone; with the number of crossings.
    fn lit_pieces(
        &self,
        pl: &Prepared,
        o: DVec3,
        d: DVec3,
        x_end: f64,
    ) -> (Vec<(f64, f64)>, usize) {
        let s = pl.light.position_m;
        let mut events: Vec<(f64, i32)> = Vec::new();
        // An orthographic ray's state is found at `from` along it, where it has left any
        // shadow surface its start lies on (a pixel's point on a shadow cone's edge would
        // otherwise count as lit with no crossing to follow); the events before it are in it.
        let own;
        let (start, from) = if self.orthographic {
            own = ShadowState::at(self.occluders, &pl.spheres, o + ORTHOGRAPHIC_START_M * d, s);
            (&own, ORTHOGRAPHIC_START_M)
        } else {
            (&pl.at_eye, 0.0)
        };
        let ahead = |x: f64| x > from && x < x_end;
        let mut count = start.count;
        for plane in &pl.planes {
            if let Some((x, w)) = plane.crossing(s, o, d)
                && ahead(x)
            {
                events.push((x, w));
            }
        }
        let mut roots = Vec::new();
        for (sphere, &blocks) in pl.spheres.iter().zip(&start.sphere_blocks) {
            roots.clear();
            sphere.shadow_crossings(s, o, d, &mut roots);
            let mut on = blocks;
            for &x in roots.iter().filter(|&&x| ahead(x)) {
                on = !on;
                events.push((x, if on { 1 } else { -1 }));
            }
        }
        if let Some((axis, half_deg)) = pl.light.spot {
            let cos = half_deg.to_radians().cos();
            let mut inside = in_spot(&pl.light, o + from * d - s);
            count += (!inside) as i32;
            let toggles: Vec<f64> = if cos.abs() < 1e-12 {
                let (wa, da) = ((o - s).dot(axis), d.dot(axis));
                let x = -wa / da;
                if da != 0.0 && x > 0.0 {
                    vec![x]
                } else {
                    vec![]
                }
            } else {
                nappe_roots(s, axis, cos * cos, o, d, cos.signum())
            };
            for x in toggles.into_iter().filter(|&x| ahead(x)) {
                inside = !inside;
                events.push((x, if inside { -1 } else { 1 }));
            }
        }
        events.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut pieces = Vec::new();
        let mut start = (count <= 0).then_some(0.0);
        for &(x, delta) in &events {
            count += delta;
            match (start, count <= 0) {
                (Some(x0), false) => {
                    pieces.push((x0, x));
                    start = None;
                }
                (None, true) => start = Some(x),
                _ => {}
            }
        }
        if let Some(x0) = start {
            pieces.push((x0, x_end));
        }
        (pieces, events.len())
    }

    /// Γ(x1) − Γ(x0) of medium `m` for one light over a lit piece (Eq. 2 and the bounded
    /// form of §4.2; module docs of [`super`]): `entry` is where the ray enters the medium
    /// and `front` the optical depth of the other media before it.
    fn gamma(
        &self,
        m: usize,
        light: &Light,
        o: DVec3,
        d: DVec3,
        entry: f64,
        (x0, x1): (f64, f64),
        front: [f64; 3],
    ) -> [f64; 3] {
        let med = &self.media[m];
        let field = &self.tables.fields[med.field];
        let s = light.position_m;
        let t = (s - o).dot(d);
        let h = (s - (o + t * d)).length().max(MIN_LIGHT_DISTANCE_M);
        let (th0, th1) = (((x0 - t) / h).atan(), ((x1 - t) / h).atan());
        // The light path outside the medium (0 for a light inside it), and through the other
        // media, at the piece's middle.
        let mid = o + 0.5 * (x0 + x1) * d;
        let to = mid - s;
        let r = to.length();
        let u = to / r;
        let r0 = if med.region.contains(s) {
            0.0
        } else {
            med.region.span(s, u, r).map_or(r, |(a, _)| a)
        };
        let others = self.depth(s, u, r, Some(m));
        let depths = field
            .biri
            .as_ref()
            .map_or(0.0, |b| *b.depths.last().unwrap_or(&0.0));
        std::array::from_fn(|c| {
            let beta = med.beta_ext[c];
            let tau_h = beta * h;
            if tau_h > depths {
                return 0.0; // e^{−β(x + r)} ≤ e^{−τ_h} < e^{−100}
            }
            let delta = match self.kernel {
                Kernel::Exact => {
                    sample::biri_primitive_difference(field, self.grid, c, tau_h, (th0, th1))
                        .unwrap_or(0.0)
                }
                Kernel::Polynomial => {
                    let k = sample::biri_polynomial(field, c, tau_h).unwrap_or([0.0; 5]);
                    (0..5)
                        .map(|j| {
                            let p = (j + 1) as i32;
                            k[j] * (th1.powi(p) - th0.powi(p)) / p as f64
                        })
                        .sum()
                }
            };
            if delta == 0.0 {
                return 0.0;
            }
            let exponent = (-beta * (t - entry - r0) - front[c] - others[c]).min(700.0);
            med.beta_sca[c] / h * light.intensity[c] * exponent.exp() * delta
        })
    }
}

/// Whether direction `u` from the light (any length) is inside its spot cone (always for a
/// point light).
fn in_spot(light: &Light, u: DVec3) -> bool {
    match light.spot {
        None => true,
        Some((axis, half_deg)) => u.dot(axis) >= half_deg.to_radians().cos() * u.length(),
    }
}
