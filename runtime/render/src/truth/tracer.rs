//! The path tracer of the [module docs](super): the scene's optics per band (fields, air,
//! haze, media), the free paths by delta tracking under a majorant, the scattering by the
//! tables' phase functions and Rayleigh's, next-event estimation towards the sun and the
//! lights, Russian roulette and splitting.

use super::*;

/// The random stream of one sample (`Rng::stream(seed, pixel, sample)`).
pub use crate::rng::SplitMix64 as Rng;

/// One field's optics at one wavelength.
#[derive(Debug, Clone)]
pub(super) struct FieldOptics {
    pub(super) sigma_ext: f64,
    pub(super) albedo: f64,
    pub(super) phase: PhaseSampler,
}

/// Everything that depends on the wavelength.
#[derive(Debug, Clone)]
pub(super) struct Band {
    pub(super) fields: Vec<FieldOptics>,
    pub(super) beta_air_sl: f64,
    /// The haze layer's N_0 σ_ext and σ_sca (1/m at y = 0); zero without one.
    pub(super) haze_ext_sl: f64,
    pub(super) haze_sca_sl: f64,
    /// w_cj / q_j: what one unit of this wavelength's radiance adds to channel c.
    pub(super) to_rgb: [f64; 3],
}

/// Most wavelengths one path carries (module docs, "Spectral").
pub const MAX_CARRIED: usize = 4;

/// The wavelengths one path carries and, per wavelength m, its path's contribution and
/// sampling density relative to the hero's sampling density p_0 (module docs, "Spectral").
#[derive(Debug, Clone, Copy)]
pub(super) struct Carried {
    pub(super) n: usize,
    /// Indices into the tracer's bands; `band[0]` is the hero, which makes every decision.
    pub(super) band: [usize; MAX_CARRIED],
    /// f_m(x)/p_0(x).
    pub(super) f: [f64; MAX_CARRIED],
    /// p_m(x)/p_0(x): how likely wavelength m's own sampling was to make the same path.
    pub(super) r: [f64; MAX_CARRIED],
}

impl Carried {
    /// W_m = f_m / Σ_k p_k (the balance heuristic over the carried wavelengths).
    fn weights(&self) -> [f64; MAX_CARRIED] {
        let s: f64 = self.r[..self.n].iter().sum();
        std::array::from_fn(|m| {
            if m < self.n && s > 0.0 {
                self.f[m] / s
            } else {
                0.0
            }
        })
    }

    /// Multiplies wavelength m's f and p alike (an analog decision).
    fn both(&mut self, m: usize, k: f64) {
        self.f[m] *= k;
        self.r[m] *= k;
    }
}

/// The density an air or ground vertex continues with when it is not guided
/// ([`Tracer::continue_guided`]).
#[derive(Debug, Clone, Copy)]
pub(super) enum Own {
    /// Rayleigh scattering about the path's direction.
    Air(DVec3),
    /// Lambertian reflection about the normal, of albedo a.
    Ground(DVec3, f64),
}

/// What ends a free path.
#[derive(Debug, Clone, Copy)]
pub(super) enum Event {
    /// A real collision in the volumes, scattered by this field.
    Volume(usize),
    /// A collision with the air.
    Air,
    /// A Lambertian surface (the ground at y = 0, or an occluder): its unit normal on the
    /// side the path came from and its albedo.
    Surface(DVec3, f64),
    /// Nothing: the path leaves the scene.
    Escape,
}

/// The weight below which Russian roulette plays (module docs, "Paths").
pub const ROULETTE_WEIGHT: f64 = 1e-3;

/// The weight above which a camera path splits (module docs, "Paths").
pub const SPLIT_WEIGHT: f64 = 2.0;

/// Most branches one split makes.
pub const MAX_SPLIT: usize = 16;

/// Russian roulette once the weight falls below [`ROULETTE_WEIGHT`] w₀: the path survives with
/// probability w/w₀ and carries w₀ on, so no survivor is ever heavier than w₀ (a roulette that
/// raised survivors to weight 1 would turn a path just bent towards the sun's forward peak into a
/// firefly); false when the path ends.
pub(super) fn roulette(weight: &mut f64, rng: &mut Rng) -> bool {
    if *weight < ROULETTE_WEIGHT {
        if rng.uniform() * ROULETTE_WEIGHT >= *weight {
            return false;
        }
        *weight = ROULETTE_WEIGHT;
    }
    true
}

/// Distance to the next collision with an exponential species of β(y) = β_0 e^{−γ y} from `p`
/// along `d` (closed-form inversion of its optical depth), or ∞.
pub(super) fn sample_exponential(beta0: f64, gamma: f64, p: DVec3, d: DVec3, rng: &mut Rng) -> f64 {
    if beta0 == 0.0 {
        return f64::INFINITY;
    }
    let target = rng.exp() / (beta0 * (-gamma * p.y).exp());
    let k = gamma * d.y;
    if k.abs() < 1e-15 {
        return target;
    }
    let x = target * k;
    if x >= 1.0 {
        return f64::INFINITY;
    }
    -(-x).ln_1p() / k
}

/// A scene ready to trace: the grid, the optics per wavelength, the sources.
#[derive(Debug, Clone)]
pub struct Tracer<'a> {
    pub(super) grid: &'a DensityGrid,
    pub(super) n_fields: usize,
    pub(super) bands: Vec<Band>,
    /// Cumulative q_j.
    pub(super) band_cdf: Vec<f64>,
    /// The volumes' majorant over every wavelength, max_j Σ_f max ρ_f σ_ext,f,j.
    pub(super) majorant: f64,
    /// Whether the air scatters.
    pub(super) air_on: bool,
    /// The haze layer: its field (whose phase function it scatters with) and 1/H.
    pub(super) haze: Option<(usize, f64)>,
    pub(super) gamma: f64,
    pub(super) sun: DVec3,
    pub(super) sun_irradiance: [f64; 3],
    pub(super) cos_disk: f64,
    pub(super) disk_sr: f64,
    pub(super) ground_albedo: f64,
    pub(super) lights: Vec<Light>,
    /// Homogeneous media: region, number density, field.
    pub(super) media: Vec<(crate::objects::Region, f64, usize)>,
    pub(super) occluders: Vec<crate::objects::Occluder>,
    /// The box delta tracking covers: the grid's and the media's.
    pub(super) track_min: DVec3,
    pub(super) track_max: DVec3,
    /// Radiance (per channel, the image's unit) of everything a path leaves into: 0 for the
    /// scenes (black space); 1 makes the white-furnace test.
    pub background: [f64; 3],
    /// Scatterings after which a path ends ([`MAX_BOUNCES`] by default); 1 gives exact single
    /// scattering (the tests' analytic limit).
    pub max_scatterings: usize,
    /// Share ε of continuations at volume vertices drawn from the phase function's lobe about
    /// the sun instead of about the path ([`GUIDE_SHARE`]; 0: plain phase sampling).
    pub guide: f64,
    /// Wavelengths each camera path carries, 1…[`MAX_CARRIED`] (default: all of an `rgb3`
    /// bake's three, else 4); 1 is one wavelength per path.
    pub wavelengths_per_path: usize,
    /// Green channel σ_ext per field (for T_vol), from the tables.
    pub(super) sigma_ext_g: [f64; MAX_FIELDS],
}

pub(super) fn bad<T>(s: String) -> Result<T, FrameError> {
    Err(FrameError(s))
}

impl<'a> Tracer<'a> {
    /// Builds the per-wavelength optics of `tables` (which must hold single-scattering tables,
    /// i.e. come from a bake of this version) for the frame's grid, sun and atmosphere.
    pub fn new(tables: &Tables, frame: &'a Frame, settings: &Settings) -> Result<Self, FrameError> {
        crate::shading::check_fields(tables, frame)?;
        let spectrum = tables.spectrum.as_ref().ok_or_else(|| {
            FrameError(format!(
                "{}: the manifest lists no wavelengths and channel weights; rebake",
                tables.dir.display()
            ))
        })?;
        let grid_theta = ThetaGrid::new(tables.theta_step_deg)
            .map_err(|e| FrameError(format!("tables' Δθ: {e}")))?;
        for f in &tables.fields {
            if f.single.is_none() {
                return bad(format!(
                    "field {:?} has no single-scattering table ({}.single.exr): the bake predates \
                     the path tracer; rebake it",
                    f.name, f.name
                ));
            }
        }
        let max = frame.grid.max_density();
        let media = media_of(tables, frame)?;
        if max.iter().all(|&m| m <= 0.0) && media.is_empty() {
            return bad(
                "the density grid holds no particles (every voxel is 0): nothing scatters, \
                 refusing to trace an empty scene"
                    .into(),
            );
        }
        let (bands, band_cdf, majorant) = bands(tables, frame, spectrum, &grid_theta, &media);
        check_optical_depth(tables, frame, &media, &bands)?;
        let cos_disk = (SUN_DIAMETER_DEG / 2.0).to_radians().cos();
        let (track_min, track_max) = tracked_box(frame, &media, &bands);
        let mut sigma_ext_g = [0.0; MAX_FIELDS];
        for (i, f) in tables.fields.iter().enumerate() {
            sigma_ext_g[i] = f.sigma_ext_m2[1];
        }
        Ok(Self {
            grid: &frame.grid,
            n_fields: tables.fields.len(),
            air_on: bands.iter().any(|b| b.beta_air_sl > 0.0),
            haze: frame
                .haze
                .as_ref()
                .map(|h| (h.field, 1.0 / h.scale_height_m)),
            wavelengths_per_path: match settings.wavelengths_per_path {
                0 => bands.len().min(MAX_CARRIED),
                n => n,
            },
            bands,
            band_cdf,
            majorant,
            gamma: 1.0 / frame.atmosphere.scale_height_m,
            sun: frame.sun.direction(),
            sun_irradiance: frame.sun.irradiance,
            cos_disk,
            disk_sr: 2.0 * PI * (1.0 - cos_disk),
            ground_albedo: frame.ground_albedo,
            lights: frame.lights.clone(),
            media,
            occluders: frame.occluders.clone(),
            track_min,
            track_max,
            background: [0.0; 3],
            max_scatterings: match settings.max_scatterings {
                0 => MAX_BOUNCES,
                n => n,
            },
            // Guiding towards the sun helps only where it shines.
            guide: if frame.sun.irradiance.iter().any(|&v| v > 0.0) {
                GUIDE_SHARE
            } else {
                0.0
            },
            sigma_ext_g,
        })
    }

    /// Overrides every field's single-scattering albedo (the white-furnace test sets 1).
    pub fn set_albedo(&mut self, albedo: f64) {
        for b in &mut self.bands {
            for f in &mut b.fields {
                f.albedo = albedo;
            }
            b.haze_sca_sl = b.haze_ext_sl * albedo;
        }
    }

    /// The wavelengths of one path (module docs, "Spectral"): `n` band indices from one
    /// uniform number u, the m-th at u + m/n (mod 1) in the bands' CDF, so each is marginally
    /// drawn with probability q_j; the first is the hero.
    fn carry(&self, n: usize, rng: &mut Rng) -> Carried {
        let u = rng.uniform();
        let mut band = [0; MAX_CARRIED];
        for (m, b) in band.iter_mut().enumerate().take(n) {
            let mut um = u + m as f64 / n as f64;
            if um >= 1.0 {
                um -= 1.0;
            }
            *b = self
                .band_cdf
                .partition_point(|&c| c <= um)
                .min(self.bands.len() - 1);
        }
        Carried {
            n,
            band,
            f: [1.0; MAX_CARRIED],
            r: [1.0; MAX_CARRIED],
        }
    }

    /// The optics of the `m`-th carried wavelength.
    fn band_of(&self, c: &Carried, m: usize) -> &Band {
        &self.bands[c.band[m]]
    }

    /// The number densities at `p`: the grid's, plus a medium's where it is.
    fn density(&self, p: DVec3) -> [f64; MAX_FIELDS] {
        let mut rho = self.grid.sample(p);
        for &(region, n, f) in &self.media {
            if region.contains(p) {
                rho[f] += n;
            }
        }
        rho
    }

    /// The nearest surface along p + t d, t > 0: distance, normal facing the path, albedo,
    /// and whether it is the ground.
    fn surface(&self, p: DVec3, d: DVec3) -> Option<(f64, DVec3, f64, bool)> {
        let mut best =
            (d.y < 0.0).then(|| ((p.y / -d.y).max(0.0), DVec3::Y, self.ground_albedo, true));
        for o in &self.occluders {
            if let Some((t, n)) = o.hit(p, d, best.map_or(f64::INFINITY, |b| b.0)) {
                best = Some((t, n, o.albedo, false));
            }
        }
        best
    }

    /// Whether no occluder lies on p + t d, t ∈ (0, limit).
    fn unoccluded(&self, p: DVec3, d: DVec3, limit: f64) -> bool {
        self.occluders.iter().all(|o| o.hit(p, d, limit).is_none())
    }

    /// Volume extinction at densities `rho` for each carried wavelength.
    fn extinctions(&self, c: &Carried, rho: &[f64; MAX_FIELDS]) -> [f64; MAX_CARRIED] {
        let mut e = [0.0; MAX_CARRIED];
        for (m, e) in e.iter_mut().enumerate().take(c.n) {
            let b = self.band_of(c, m);
            for f in 0..self.n_fields {
                *e += rho[f] * b.fields[f].sigma_ext;
            }
        }
        e
    }

    /// Air optical depth per unit β_sl from `p` along unit `d` over distance `s` (∞ allowed
    /// for d_y > 0): β_sl times this is a wavelength's optical depth.
    fn air_path(&self, p: DVec3, d: DVec3, s: f64) -> f64 {
        (-self.gamma * p.y).exp() * crate::sky::one_minus_u_over_p(self.gamma, d.y, s) / self.gamma
    }

    /// Haze optical depth per unit N_0 σ_ext from `p` along unit `d` over distance `s`.
    fn haze_path(&self, p: DVec3, d: DVec3, s: f64) -> f64 {
        let Some((_, gamma)) = self.haze else {
            return 0.0;
        };
        (-gamma * p.y).exp() * crate::sky::one_minus_u_over_p(gamma, d.y, s) / gamma
    }

    /// Distance to the next air collision from `p` along `d` for the hero, or ∞.
    fn sample_air(&self, b: &Band, p: DVec3, d: DVec3, rng: &mut Rng) -> f64 {
        sample_exponential(b.beta_air_sl, self.gamma, p, d, rng)
    }

    /// Distance to the next haze collision from `p` along `d` for the hero, or ∞.
    fn sample_haze(&self, b: &Band, p: DVec3, d: DVec3, rng: &mut Rng) -> f64 {
        match self.haze {
            Some((_, gamma)) => sample_exponential(b.haze_ext_sl, gamma, p, d, rng),
            None => f64::INFINITY,
        }
    }

    /// The haze's part of a free path of length `s` that ends without a haze collision or in
    /// one: p_m gains N σ_ext,m e^{−τ_m} over the hero's, f_m the same with σ_sca,m (the
    /// albedo weighting).
    fn haze_ratios(&self, c: &mut Carried, p: DVec3, d: DVec3, s: f64, collided: bool) {
        if self.haze.is_none() {
            return;
        }
        let path = self.haze_path(p, d, s);
        let b0 = self.band_of(c, 0).haze_ext_sl;
        for m in 0..c.n {
            let b = self.band_of(c, m);
            let k = (-(b.haze_ext_sl - b0) * path).exp();
            if collided {
                c.f[m] *= k * b.haze_sca_sl / b0;
                c.r[m] *= k * b.haze_ext_sl / b0;
            } else if m > 0 {
                c.both(m, k);
            }
        }
    }

    /// The air's part of a free path of length `s` from `p` along `d` that ends without an
    /// air collision (`collided` false) or in one: every wavelength's density over the hero's
    /// (the air is analog, so f and p change alike).
    fn air_ratios(&self, c: &mut Carried, p: DVec3, d: DVec3, s: f64, collided: bool) {
        if c.n == 1 || !self.air_on {
            return;
        }
        let path = self.air_path(p, d, s);
        let b0 = self.band_of(c, 0).beta_air_sl;
        for m in 1..c.n {
            let bm = self.band_of(c, m).beta_air_sl;
            let mut k = (-(bm - b0) * path).exp();
            if collided {
                k *= bm / b0;
            }
            c.both(m, k);
        }
    }

    /// Where p + t d crosses the tracked box, t ≥ 0; in a periodic layer at most
    /// [`DensityGrid::longest_path_m`] of it (a path along the layer).
    fn tracked_span(&self, p: DVec3, d: DVec3) -> Option<(f64, f64)> {
        let (t0, t1) = box_span(self.track_min, self.track_max, p, d)?;
        Some((t0, t1.min(t0 + self.grid.longest_path_m())))
    }

    /// Delta tracking through the grid up to distance `limit` with the common majorant,
    /// decided by the hero: the distance and densities of the first real collision, if any.
    /// At each null collision every other wavelength's density changes by its share of null
    /// collisions over the hero's, (μ̄ − μ_m)/(μ̄ − μ_0).
    fn track(
        &self,
        c: &mut Carried,
        p: DVec3,
        d: DVec3,
        limit: f64,
        rng: &mut Rng,
    ) -> Option<(f64, [f64; MAX_FIELDS])> {
        let (t0, t1) = self.tracked_span(p, d)?;
        let end = t1.min(limit);
        let mu = self.majorant;
        let mut t = t0;
        loop {
            t += rng.exp() / mu;
            if t >= end {
                return None;
            }
            let rho = self.density(p + t * d);
            let e = self.extinctions(c, &rho);
            if rng.uniform() * mu < e[0] {
                return Some((t, rho));
            }
            for m in 1..c.n {
                c.both(m, (mu - e[m]) / (mu - e[0]));
            }
        }
    }

    /// Transmittance of the volumes from `p` along `d` over `limit` for each carried
    /// wavelength, by ratio tracking on shared tentative points (the majorant is common), with
    /// Russian roulette once the largest falls below 1/20.
    fn volume_transmittance(
        &self,
        c: &Carried,
        p: DVec3,
        d: DVec3,
        limit: f64,
        rng: &mut Rng,
    ) -> [f64; MAX_CARRIED] {
        let mut tr = [1.0; MAX_CARRIED];
        let Some((t0, t1)) = self.tracked_span(p, d) else {
            return tr;
        };
        let end = t1.min(limit);
        let mu = self.majorant;
        let mut t = t0;
        loop {
            t += rng.exp() / mu;
            if t >= end {
                return tr;
            }
            let e = self.extinctions(c, &self.density(p + t * d));
            let mut largest: f64 = 0.0;
            for m in 0..c.n {
                tr[m] *= 1.0 - e[m] / mu;
                largest = largest.max(tr[m]);
            }
            if largest < 0.05 {
                if rng.uniform() < 0.5 {
                    return [0.0; MAX_CARRIED];
                }
                for t in tr.iter_mut() {
                    *t *= 2.0;
                }
            }
        }
    }

    /// Adds the direct light at `p` from every source: for carried wavelength m and channel
    /// ch, `coef[m][ch]` × `weight(ω)[m]` (the phase function or BRDF × cosine) × the
    /// transmittance × the source.
    fn direct(
        &self,
        c: &Carried,
        p: DVec3,
        coef: &[[f64; 3]; MAX_CARRIED],
        weight: impl Fn(DVec3) -> [f64; MAX_CARRIED],
        sum: &mut [f64; 3],
        rng: &mut Rng,
    ) {
        let mut add = |dir: DVec3, limit: f64, source: [f64; 3], rng: &mut Rng| {
            let w = weight(dir);
            if w[..c.n].iter().all(|&w| w <= 0.0) || !self.unoccluded(p, dir, limit) {
                return;
            }
            let tv = self.volume_transmittance(c, p, dir, limit, rng);
            let path = if self.air_on {
                self.air_path(p, dir, limit)
            } else {
                0.0
            };
            let haze = self.haze_path(p, dir, limit);
            for m in 0..c.n {
                let b = self.band_of(c, m);
                let t = w[m] * tv[m] * (-b.beta_air_sl * path - b.haze_ext_sl * haze).exp();
                for ch in 0..3 {
                    sum[ch] += coef[m][ch] * t * source[ch];
                }
            }
        };
        add(self.sun, f64::INFINITY, self.sun_irradiance, rng);
        for light in &self.lights {
            let to = light.position_m - p;
            let r2 = to.length_squared();
            if r2 == 0.0 {
                continue;
            }
            let r = r2.sqrt();
            let dir = to / r;
            if let Some((axis, half_deg)) = light.spot
                && (-dir).dot(axis) < half_deg.to_radians().cos()
            {
                continue;
            }
            add(dir, r, light.intensity.map(|i| i / r2), rng);
        }
    }

    /// Follows the free path from `p` along `d` to what ends it, moving `p` there, and updates
    /// every carried wavelength's f and p for it. At a volume collision the hero chooses the
    /// scattering field by its share of β_sca, and f gains β_sca,f (the albedo weighting).
    fn next_event(&self, c: &mut Carried, p: &mut DVec3, d: DVec3, rng: &mut Rng) -> Event {
        let surface = self.surface(*p, d);
        let t_ground = surface.map_or(f64::INFINITY, |s| s.0);
        let t_air = self.sample_air(self.band_of(c, 0), *p, d, rng);
        let t_haze = self.sample_haze(self.band_of(c, 0), *p, d, rng);
        if let Some((t, rho)) = self.track(c, *p, d, t_ground.min(t_air).min(t_haze), rng) {
            self.air_ratios(c, *p, d, t, false);
            self.haze_ratios(c, *p, d, t, false);
            *p += t * d;
            let e = self.extinctions(c, &rho);
            // Per carried wavelength: β_sca of each field and in all.
            let mut sca = [[0.0; MAX_FIELDS]; MAX_CARRIED];
            let mut total = [0.0; MAX_CARRIED];
            for m in 0..c.n {
                let b = self.band_of(c, m);
                for f in 0..self.n_fields {
                    sca[m][f] = rho[f] * b.fields[f].sigma_ext * b.fields[f].albedo;
                    total[m] += sca[m][f];
                }
            }
            let field = if total[0] > 0.0 {
                let mut pick = rng.uniform() * total[0];
                let mut field = self.n_fields - 1;
                for f in 0..self.n_fields {
                    if pick < sca[0][f] {
                        field = f;
                        break;
                    }
                    pick -= sca[0][f];
                }
                field
            } else {
                (rng.uniform() * self.n_fields as f64) as usize % self.n_fields
            };
            // The probability of choosing `field` at wavelength m (uniform where nothing
            // scatters), and the collision's p_m = μ_m/μ̄ · that, f_m = β_sca,field,m/μ̄.
            let choice = |m: usize| {
                if total[m] > 0.0 {
                    sca[m][field] / total[m]
                } else {
                    1.0 / self.n_fields as f64
                }
            };
            let p0 = e[0] * choice(0);
            for m in 0..c.n {
                c.f[m] *= sca[m][field] / p0;
                c.r[m] *= e[m] * choice(m) / p0;
            }
            Event::Volume(field)
        } else if t_haze < t_ground.min(t_air) {
            self.air_ratios(c, *p, d, t_haze, false);
            self.haze_ratios(c, *p, d, t_haze, true);
            *p += t_haze * d;
            // It scatters with its field's phase function: a volume event of that field.
            Event::Volume(self.haze.expect("sampled").0)
        } else if t_air < t_ground {
            self.air_ratios(c, *p, d, t_air, true);
            self.haze_ratios(c, *p, d, t_air, false);
            *p += t_air * d;
            Event::Air
        } else if t_ground.is_finite() {
            self.air_ratios(c, *p, d, t_ground, false);
            self.haze_ratios(c, *p, d, t_ground, false);
            let (_, normal, albedo, ground) = surface.expect("finite");
            *p += t_ground * d;
            if ground {
                p.y = 0.0;
            } else {
                // Off the occluder, so that the next free path and shadow rays leave it.
                *p += normal * (1e-6 * (1.0 + p.length()));
            }
            Event::Surface(normal, albedo)
        } else {
            self.air_ratios(c, *p, d, f64::INFINITY, false);
            self.haze_ratios(c, *p, d, f64::INFINITY, false);
            Event::Escape
        }
    }

    /// The continuation at a volume vertex of `field`: with probability ε from the smooth
    /// part of the hero's phase function about the sun direction, else from it about `d`
    /// (the forward δ included). The hero's density is q_0 = (1 − ε) p_0(d, ω) + ε p_0(sun,
    /// ω)/(1 − f_0) for a smooth ω (f the forward δ, which only the second branch draws), each
    /// carried wavelength's q_m the same with its own phase function; f_m gains p_m(d, ω).
    /// Unbiased for any ε < 1.
    fn continue_volume(
        &self,
        c: &mut Carried,
        field: usize,
        d: DVec3,
        eps: f64,
        rng: &mut Rng,
    ) -> DVec3 {
        let phase = |m: usize| &self.band_of(c, m).fields[field].phase;
        let ph = phase(0);
        let next = if eps > 0.0 && rng.uniform() < eps {
            let (omm, sin) = ph.sample_smooth(rng.uniform(), rng.uniform());
            rotate(self.sun, omm, sin, rng.uniform())
        } else {
            match ph.sample(rng.uniform(), rng.uniform()) {
                Some((omm, sin)) => rotate(d, omm, sin, rng.uniform()),
                None => {
                    // The forward δ: p_m = (1 − ε) f_m, f_m = f_m.
                    let f0 = ph.delta();
                    let ratios: [f64; MAX_CARRIED] =
                        std::array::from_fn(|m| if m < c.n { phase(m).delta() / f0 } else { 0.0 });
                    for m in 0..c.n {
                        c.f[m] *= ratios[m] / (1.0 - eps);
                        c.r[m] *= ratios[m];
                    }
                    return d;
                }
            }
        };
        if eps == 0.0 && c.n == 1 {
            return next; // f_0 = q_0
        }
        let kd = ph.bin(d, next);
        let ks = if eps > 0.0 { ph.bin(self.sun, next) } else { 0 };
        let q = |ph: &PhaseSampler| {
            let p = ph.value(kd);
            let q = if eps > 0.0 {
                (1.0 - eps) * p + eps * ph.value(ks) / (1.0 - ph.delta())
            } else {
                p
            };
            (p, q)
        };
        let (_, q0) = q(ph);
        if q0 <= 0.0 {
            c.f = [0.0; MAX_CARRIED];
            return next;
        }
        let pq: [(f64, f64); MAX_CARRIED] =
            std::array::from_fn(|m| if m < c.n { q(phase(m)) } else { (0.0, 0.0) });
        for (m, (p, q)) in pq.iter().enumerate().take(c.n) {
            c.f[m] *= p / q0;
            c.r[m] *= q / q0;
        }
        next
    }

    /// The continuation at an air or ground vertex (module docs, "Guided continuations"):
    /// with probability ε from the smooth lobe about the sun of a field drawn uniformly,
    /// else from the vertex's own density (Rayleigh about the path, the cosine about the
    /// ground's normal), weighted by the one-sample MIS ratio value(ω)/q(ω) with q = (1 − ε)
    /// own(ω) + ε (1/F) Σ_f p_f(sun, ω)/(1 − δ_f), each carried wavelength's q_m with its own
    /// phase functions. Unbiased for any ε < 1.
    fn continue_guided(&self, c: &mut Carried, own: Own, eps: f64, rng: &mut Rng) -> DVec3 {
        let next = if eps > 0.0 && rng.uniform() < eps {
            let field = ((rng.uniform() * self.n_fields as f64) as usize).min(self.n_fields - 1);
            let (omm, sin) = self.band_of(c, 0).fields[field]
                .phase
                .sample_smooth(rng.uniform(), rng.uniform());
            rotate(self.sun, omm, sin, rng.uniform())
        } else {
            match own {
                Own::Air(d) => {
                    let mu = sample_rayleigh(rng.uniform());
                    rotate(d, 1.0 - mu, (1.0 - mu * mu).max(0.0).sqrt(), rng.uniform())
                }
                Own::Ground(normal, _) => {
                    let (r, phi) = (rng.uniform().sqrt(), 2.0 * PI * rng.uniform());
                    let (e1, e2) = basis(normal);
                    (r * phi.cos() * e1
                        + r * phi.sin() * e2
                        + (1.0 - r * r).max(0.0).sqrt() * normal)
                        .normalize()
                }
            }
        };
        // The own density and the value (phase function, or BRDF × cosine) towards `next`.
        let (pdf, value) = match own {
            Own::Air(d) => {
                let p = rayleigh(d.dot(next));
                (p, p)
            }
            Own::Ground(normal, a) => {
                let p = next.dot(normal).max(0.0) / PI;
                (p, a * p)
            }
        };
        if eps == 0.0 {
            let ratio = if pdf > 0.0 { value / pdf } else { 0.0 };
            for f in c.f.iter_mut() {
                *f *= ratio;
            }
            return next;
        }
        let ks = self.band_of(c, 0).fields[0].phase.bin(self.sun, next);
        let q: [f64; MAX_CARRIED] = std::array::from_fn(|m| {
            if m >= c.n {
                return 0.0;
            }
            let guide = self.band_of(c, m).fields[..self.n_fields]
                .iter()
                .map(|f| f.phase.value(ks) / (1.0 - f.phase.delta()))
                .sum::<f64>()
                / self.n_fields as f64;
            (1.0 - eps) * pdf + eps * guide
        });
        if q[0] <= 0.0 {
            c.f = [0.0; MAX_CARRIED];
            return next;
        }
        for m in 0..c.n {
            c.f[m] *= value / q[0];
            c.r[m] *= q[m] / q[0];
        }
        next
    }

    /// The weight window on the path's largest effective weight n·W_m (module docs, "Paths"),
    /// computed once: below [`ROULETTE_WEIGHT`] Russian roulette (survivors scaled so that it
    /// becomes that weight); with `split`, above [`SPLIT_WEIGHT`] k = ⌈n·W_m⌉ branches (at most
    /// [`MAX_SPLIT`]) of 1/k of the weight each. The number of branches, 0 when the path ends.
    fn weight_window(c: &mut Carried, rng: &mut Rng, split: bool) -> usize {
        let w = c.weights();
        let largest = c.n as f64 * w[..c.n].iter().fold(0.0f64, |a, &b| a.max(b));
        let mut kept = largest;
        if !roulette(&mut kept, rng) {
            return 0;
        }
        let k = if split && kept > SPLIT_WEIGHT {
            (kept.ceil() as usize).min(MAX_SPLIT)
        } else {
            1
        };
        for f in c.f.iter_mut() {
            if kept != largest {
                *f *= kept / largest;
            }
            if k > 1 {
                *f /= k as f64;
            }
        }
        k
    }

    /// One path's radiance estimate (per channel) arriving at `origin` from direction `-dir`
    /// (the path leaves `origin` along `dir`).
    pub fn radiance(&self, origin: DVec3, dir: DVec3, rng: &mut Rng) -> [f64; 3] {
        let n = self.wavelengths_per_path.clamp(1, MAX_CARRIED);
        let mut sum = [0.0; 3];
        // The branches still to follow (module docs, "Paths": splitting), each with the
        // bounce it resumes at.
        let mut branches = vec![(self.carry(n, rng), origin, dir, 0)];
        while let Some((mut c, mut p, mut d, first)) = branches.pop() {
            for bounce in first..self.max_scatterings {
                let event = self.next_event(&mut c, &mut p, d, rng);
                // What a unit of radiance at wavelength m adds to channel ch: w_ch,m/q_m × W_m.
                let w = c.weights();
                let coef: [[f64; 3]; MAX_CARRIED] = std::array::from_fn(|m| {
                    if m < c.n {
                        let to = self.band_of(&c, m).to_rgb;
                        std::array::from_fn(|ch| to[ch] * w[m])
                    } else {
                        [0.0; 3]
                    }
                });
                match event {
                    Event::Volume(field) => {
                        let ph0 = &self.band_of(&c, 0).fields[field].phase;
                        let weight = |w: DVec3| {
                            let k = ph0.bin(d, w);
                            std::array::from_fn(|m| {
                                if m < c.n {
                                    self.band_of(&c, m).fields[field].phase.value(k)
                                } else {
                                    0.0
                                }
                            })
                        };
                        self.direct(&c, p, &coef, weight, &mut sum, rng);
                    }
                    Event::Air => {
                        let weight = |w: DVec3| [rayleigh(d.dot(w)); MAX_CARRIED];
                        self.direct(&c, p, &coef, weight, &mut sum, rng);
                    }
                    Event::Surface(normal, a) => {
                        if a == 0.0 {
                            break;
                        }
                        let weight = |w: DVec3| [a / PI * w.dot(normal).max(0.0); MAX_CARRIED];
                        self.direct(&c, p, &coef, weight, &mut sum, rng);
                    }
                    Event::Escape => {
                        let disk = bounce == 0 && d.dot(self.sun) >= self.cos_disk;
                        for ch in 0..3 {
                            let l = self.background[ch]
                                + if disk {
                                    self.sun_irradiance[ch] / self.disk_sr
                                } else {
                                    0.0
                                };
                            for row in coef.iter().take(c.n) {
                                sum[ch] += row[ch] * l;
                            }
                        }
                        break;
                    }
                }
                d = match event {
                    Event::Volume(field) => self.continue_volume(&mut c, field, d, self.guide, rng),
                    Event::Surface(normal, a) => {
                        self.continue_guided(&mut c, Own::Ground(normal, a), self.guide, rng)
                    }
                    _ => self.continue_guided(&mut c, Own::Air(d), self.guide, rng),
                };
                if bounce + 1 >= self.max_scatterings {
                    break;
                }
                let k = Self::weight_window(&mut c, rng, true);
                if k == 0 {
                    break;
                }
                for _ in 1..k {
                    branches.push((c, p, d, bounce + 1));
                }
            }
        }
        sum
    }

    /// A photon's random walk forward from `origin` along `dir` through the volumes and the
    /// air: the direction in which it leaves them for good (towards space or the ground, which
    /// is not modelled here) and its weight, or `None` if it was ended by roulette. The same
    /// free paths, phase sampling and albedo as [`Tracer::radiance`] (one wavelength, plain
    /// phase sampling), run the other way: the flux estimator of the slab tests, whose forward
    /// peak a camera-side estimator would hit only rarely.
    pub fn photon(&self, origin: DVec3, dir: DVec3, rng: &mut Rng) -> Option<(DVec3, f64)> {
        let mut c = self.carry(1, rng);
        let (mut p, mut d) = (origin, dir);
        for _ in 0..self.max_scatterings {
            let event = self.next_event(&mut c, &mut p, d, rng);
            d = match event {
                Event::Surface(..) | Event::Escape => return Some((d, c.f[0])),
                Event::Volume(field) => self.continue_volume(&mut c, field, d, 0.0, rng),
                Event::Air => self.continue_guided(&mut c, Own::Air(d), 0.0, rng),
            };
            if Self::weight_window(&mut c, rng, false) == 0 {
                return None;
            }
        }
        None
    }
    /// The volumes' transparency along a ray by a fine ray march of the green channel's β_ext
    /// (quarter-voxel midpoint steps), as the fast models' A channel.
    pub fn transparency(&self, origin: DVec3, dir: DVec3) -> f64 {
        let (lo, hi) = self.grid.bounds();
        let Some((t0, t1)) = box_span(lo, hi, origin, dir) else {
            return 1.0;
        };
        let t1 = t1.min(t0 + self.grid.longest_path_m());
        let voxel = (0..3)
            .map(|a| (self.grid.max_m[a] - self.grid.min_m[a]) / self.grid.dims[a] as f64)
            .fold(f64::INFINITY, f64::min);
        let steps = (((t1 - t0) / (0.25 * voxel)).ceil() as usize).clamp(1, 1 << 16);
        let dt = (t1 - t0) / steps as f64;
        let mut tau = 0.0;
        for i in 0..steps {
            let rho = self
                .grid
                .sample(origin + (t0 + (i as f64 + 0.5) * dt) * dir);
            for f in 0..self.n_fields {
                tau += rho[f] * self.sigma_ext_g[f] * dt;
            }
        }
        (-tau).exp()
    }
}

/// Each medium's region, number density and field index in `tables`.
pub(super) fn media_of(
    tables: &Tables,
    frame: &Frame,
) -> Result<Vec<(crate::objects::Region, f64, usize)>, FrameError> {
    frame
        .media
        .iter()
        .map(|m| {
            let field = crate::objects::field_index(tables, &m.field)?;
            Ok((m.region, m.number_density_per_m3, field))
        })
        .collect()
}

/// The air's β at sea level at wavelength `l` (nm): log-linear in ln λ through `pts`, the
/// channels' (mean wavelength, β_sl) sorted by wavelength; with the air off (or a channel
/// without air) the nearest channel's value.
pub(super) fn beta_air_at(pts: &[(f64, f64)], l: f64) -> f64 {
    if pts.iter().any(|p| p.1 <= 0.0) {
        return pts
            .iter()
            .min_by(|a, b| (a.0 - l).abs().total_cmp(&(b.0 - l).abs()))
            .map_or(0.0, |p| p.1);
    }
    let seg = if l <= pts[1].0 { 0 } else { 1 };
    let (a, b) = (pts[seg], pts[seg + 1]);
    if a.0 == b.0 {
        return a.1;
    }
    let t = (l.ln() - a.0.ln()) / (b.0.ln() - a.0.ln());
    (a.1.ln() + t * (b.1.ln() - a.1.ln())).exp()
}

/// Every wavelength of the bake with a weight: its [`Band`], the CDF of the hero's sampling
/// probabilities q_j, and the majorant over all of them (module docs, "Volumes").
pub(super) fn bands(
    tables: &Tables,
    frame: &Frame,
    spectrum: &runtime::Spectrum,
    grid_theta: &ThetaGrid,
    media: &[(crate::objects::Region, f64, usize)],
) -> (Vec<Band>, Vec<f64>, f64) {
    let max = frame.grid.max_density();
    let overlapping = crate::objects::check_media(&frame.media).is_err();
    let weights = &spectrum.weights;
    let lambdas = &spectrum.wavelengths_nm;
    // β_sl(λ): log-linear in ln λ through the channels' mean wavelengths.
    let mean_lambda: [f64; 3] =
        std::array::from_fn(|c| (0..lambdas.len()).map(|j| weights[c][j] * lambdas[j]).sum());
    let beta = frame.atmosphere.beta_sea_level_per_m;
    let mut pts: Vec<(f64, f64)> = (0..3).map(|c| (mean_lambda[c], beta[c])).collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut bands = Vec::new();
    let mut band_cdf = Vec::new();
    let mut majorant: f64 = 0.0;
    let mut acc = 0.0;
    for (j, &lambda) in lambdas.iter().enumerate() {
        let q = (weights[0][j] + weights[1][j] + weights[2][j]) / 3.0;
        if q <= 0.0 {
            continue;
        }
        let fields: Vec<FieldOptics> = tables
            .fields
            .iter()
            .map(|f| {
                let s = f.single.as_ref().expect("checked by Tracer::new");
                let bins: Vec<f64> = s.bins.row(j).to_vec();
                FieldOptics {
                    sigma_ext: s.sigma_ext_m2[j],
                    albedo: s.albedo[j],
                    phase: PhaseSampler::new(grid_theta, &bins, s.forward_delta_fraction[j]),
                }
            })
            .collect();
        // Where media overlap their densities add (`Tracer::density`), so the sum of their
        // extinctions bounds them; where they do not, the densest one's does.
        let media_ext = media.iter().map(|&(_, n, f)| n * fields[f].sigma_ext);
        let media_max = if overlapping {
            media_ext.sum()
        } else {
            media_ext.fold(0.0, f64::max)
        };
        majorant = (fields
            .iter()
            .zip(&max)
            .map(|(f, m)| f.sigma_ext * m)
            .sum::<f64>()
            + media_max)
            .max(majorant);
        let (haze_ext_sl, haze_sca_sl) = frame.haze.as_ref().map_or((0.0, 0.0), |h| {
            let f = &fields[h.field];
            let ext = h.number_density_per_m3 * f.sigma_ext;
            (ext, ext * f.albedo)
        });
        bands.push(Band {
            fields,
            beta_air_sl: beta_air_at(&pts, lambda),
            haze_ext_sl,
            haze_sca_sl,
            to_rgb: std::array::from_fn(|c| weights[c][j] / q),
        });
        acc += q;
        band_cdf.push(acc);
    }
    for c in band_cdf.iter_mut() {
        *c /= acc;
    }
    (bands, band_cdf, majorant)
}

/// The tracked box: the grid's, the media boxes', and for a medium everywhere all the scene's
/// contents (camera, lights, occluders, grid) and 30 of its free paths more.
pub(super) fn tracked_box(
    frame: &Frame,
    media: &[(crate::objects::Region, f64, usize)],
    bands: &[Band],
) -> (DVec3, DVec3) {
    // A periodic grid is unbounded in x and z.
    let mut track = frame.grid.bounds();
    let grow = |t: &mut (DVec3, DVec3), a: DVec3, b: DVec3| {
        t.0 = t.0.min(a);
        t.1 = t.1.max(b);
    };
    for &(region, _, _) in media {
        if let crate::objects::Region::Box { min_m, max_m } = region {
            grow(&mut track, min_m, max_m);
        }
    }
    if let Some(&(_, n, f)) = media
        .iter()
        .find(|m| m.0 == crate::objects::Region::Everywhere)
    {
        let p = frame.camera.position_m;
        grow(&mut track, p, p);
        for l in &frame.lights {
            grow(&mut track, l.position_m, l.position_m);
        }
        for o in &frame.occluders {
            let (a, b) = o.bounds();
            grow(&mut track, a, b);
        }
        let thinnest = bands
            .iter()
            .map(|b| n * b.fields[f].sigma_ext)
            .fold(f64::INFINITY, f64::min);
        let margin = DVec3::splat(30.0 / thinnest.max(1e-12));
        track = (track.0 - margin, track.1 + margin);
    }
    track
}
