//! Per-sun work kept between the frames of a moving camera. `max` and `coupled` light the grid
//! once per sun (their lighting depends on the sun, the grid, the sky, the ground, the scene's
//! objects and the settings, never on the camera or the image size) and then gather a view from
//! it. A caller that renders many views of one lighting (the viewer) hands the models a
//! [`LightingCache`] through [`crate::model::Job::lighting`]; a view that changes only the camera then
//! costs the gather alone. `render` and `bench render` hand none: every frame is lit anew.
//!
//! A cache made with a step budget ([`LightingCache::stepped`], the viewer's) lights a new sun
//! in steps instead ([`LightingCache::get_or_step`]; `coupled`'s [`crate::coupled::light::Relight`]):
//! each frame runs the relight's steps for about the budget and is drawn from the lighting as
//! it stands, until it converges. What a frame shows meanwhile is the new sun's lighting from
//! its first frame on (never the last sun's, never black): the first frame after a sun change
//! runs the steps that make a whole lighting (the beam, the skylight, the diffusion and the
//! transport's start) whatever the budget, each later frame the transport's next iterations.

use std::any::Any;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::frame::Frame;

/// The last lighting a model computed, with what it was computed from (module docs).
#[derive(Default)]
pub struct LightingCache {
    last: Mutex<Option<Entry>>,
    /// The lighting work a frame may do where a relight goes in steps (module docs).
    step_budget: Option<Duration>,
    /// A relight in steps that has not converged, with what it lights.
    pending: Mutex<Option<Pending>>,
}

struct Pending {
    frame: Frame,
    settings: Box<dyn Any + Send + Sync>,
    relight: Box<dyn Any + Send>,
}

/// A relight's state after a frame's steps (module docs).
pub enum Stepped<L> {
    /// Converged: the lighting.
    Done(L),
    /// Not yet: the lighting as it stands, and the steps taken.
    Partial(L, usize),
}

/// Where a stepped frame's lighting came from ([`LightingCache::get_or_step`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lit {
    /// The kept lighting: it lit the frame alike.
    Kept,
    /// A relight that converged in this frame's steps.
    Converged,
    /// A relight that has not converged: the lighting after this many steps.
    Partial(usize),
}

struct Entry {
    /// The frame it was lit for (its camera and size play no part).
    frame: Frame,
    /// The model's settings (their type tells the models apart).
    settings: Box<dyn Any + Send + Sync>,
    lighting: Arc<dyn Any + Send + Sync>,
}

/// Whether `stored` (a model's settings, boxed) is `settings` (their type tells the models
/// apart).
fn same_settings<S: PartialEq + 'static>(stored: &(dyn Any + Send + Sync), settings: &S) -> bool {
    stored.downcast_ref::<S>() == Some(settings)
}

impl Entry {
    /// Its lighting, where it lit `frame` alike with `settings`.
    fn kept<S: PartialEq + 'static, L: Send + Sync + 'static>(
        &self,
        frame: &Frame,
        settings: &S,
    ) -> Option<Arc<L>> {
        let alike = same_settings(&*self.settings, settings) && same_lighting(&self.frame, frame);
        alike.then(|| self.lighting.clone().downcast::<L>().ok())?
    }

    /// Whether its lighting is a start for `frame`'s with `settings`: the same settings on the
    /// same grid (another sun, sky or ground).
    fn starts<S: PartialEq + 'static>(&self, frame: &Frame, settings: &S) -> bool {
        same_settings(&*self.settings, settings) && self.frame.grid == frame.grid
    }
}

/// Whether `a` and `b` light the grid alike: everything but the camera and the image size.
fn same_lighting(a: &Frame, b: &Frame) -> bool {
    a.sun == b.sun
        && a.atmosphere == b.atmosphere
        && a.ground_albedo == b.ground_albedo
        && a.haze == b.haze
        && a.lights == b.lights
        && a.media == b.media
        && a.occluders == b.occluders
        && a.grid == b.grid
}

impl LightingCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty cache whose relights go in steps of about `budget` a frame (module docs).
    pub fn stepped(budget: Duration) -> Self {
        Self {
            step_budget: Some(budget),
            ..Self::default()
        }
    }

    /// The lighting work a frame may do, where relights go in steps.
    pub fn step_budget(&self) -> Option<Duration> {
        self.step_budget
    }

    /// Whether a relight in steps is under way (the next frame of the same view takes it
    /// further).
    pub fn converging(&self) -> bool {
        self.pending.lock().expect("not poisoned").is_some()
    }

    /// The lighting of `frame` with `settings` where relights go in steps: the kept one when it
    /// lit the frame alike; else the pending relight of this frame and settings (or a new one,
    /// `start(previous)`, `previous` as in [`LightingCache::get_or_light`]) taken one frame's
    /// `step`s further, its lighting as it stands, and kept in the last one's place once it has
    /// converged.
    pub(crate) fn get_or_step<S, L, R, E>(
        &self,
        frame: &Frame,
        settings: &S,
        start: impl FnOnce(Option<&L>) -> Result<R, E>,
        step: impl FnOnce(&mut R) -> Result<Stepped<L>, E>,
    ) -> Result<(Arc<L>, Lit), E>
    where
        S: PartialEq + Clone + Send + Sync + 'static,
        L: Send + Sync + 'static,
        R: Send + 'static,
    {
        let mut last = self.last.lock().expect("not poisoned");
        if let Some(lighting) = last.as_ref().and_then(|e| e.kept(frame, settings)) {
            return Ok((lighting, Lit::Kept));
        }
        let mut pending = self.pending.lock().expect("not poisoned");
        let ours = pending.as_ref().is_some_and(|p| {
            same_settings(&*p.settings, settings)
                && same_lighting(&p.frame, frame)
                && p.relight.is::<R>()
        });
        if !ours {
            // Another sun (or settings): the relight under way is dropped for a new one.
            *pending = None;
            let previous = last
                .as_ref()
                .filter(|e| e.starts(frame, settings))
                .and_then(|e| e.lighting.clone().downcast::<L>().ok());
            *pending = Some(Pending {
                frame: frame.clone(),
                settings: Box::new(settings.clone()),
                relight: Box::new(start(previous.as_deref())?),
            });
        }
        let relight = pending
            .as_mut()
            .and_then(|p| p.relight.downcast_mut::<R>())
            .expect("a relight of this type was set above");
        let stepped = step(relight);
        match stepped {
            Err(e) => {
                *pending = None;
                Err(e)
            }
            Ok(Stepped::Partial(lighting, steps)) => Ok((Arc::new(lighting), Lit::Partial(steps))),
            Ok(Stepped::Done(lighting)) => {
                let p = pending.take().expect("set above");
                let lighting = Arc::new(lighting);
                *last = Some(Entry {
                    frame: p.frame,
                    settings: Box::new(settings.clone()),
                    lighting: lighting.clone(),
                });
                Ok((lighting, Lit::Converged))
            }
        }
    }

    /// The lighting of `frame` with `settings`: the kept one when both light alike (and
    /// `true`), else `light(previous)`'s, kept in its place (and `false`). `previous` is the
    /// kept lighting where it was computed with the same settings on the same grid (another
    /// sun, sky or ground): a start for a lighting that iterates (held beside the new one
    /// while it is computed).
    pub(crate) fn get_or_light<S, L, E>(
        &self,
        frame: &Frame,
        settings: &S,
        light: impl FnOnce(Option<&L>) -> Result<L, E>,
    ) -> Result<(Arc<L>, bool), E>
    where
        S: PartialEq + Clone + Send + Sync + 'static,
        L: Send + Sync + 'static,
    {
        let mut last = self.last.lock().expect("not poisoned");
        if let Some(lighting) = last.as_ref().and_then(|e| e.kept(frame, settings)) {
            return Ok((lighting, true));
        }
        let previous = last
            .take()
            .filter(|e| e.starts(frame, settings))
            .and_then(|e| e.lighting.downcast::<L>().ok());
        let lighting = Arc::new(light(previous.as_deref())?);
        drop(previous);
        *last = Some(Entry {
            frame: frame.clone(),
            settings: Box::new(settings.clone()),
            lighting: lighting.clone(),
        });
        Ok((lighting, false))
    }
}

/// The lighting of `frame` with `settings` from `cache` where one is given (module docs), else
/// `light()`'s; and whether it was reused.
pub(crate) fn lit<S, L, E>(
    cache: Option<&LightingCache>,
    frame: &Frame,
    settings: &S,
    light: impl FnOnce(Option<&L>) -> Result<L, E>,
) -> Result<(Arc<L>, bool), E>
where
    S: PartialEq + Clone + Send + Sync + 'static,
    L: Send + Sync + 'static,
{
    match cache {
        Some(cache) => cache.get_or_light(frame, settings, light),
        None => Ok((Arc::new(light(None)?), false)),
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::{camera::Camera, camera::Sun, sky::Atmosphere, volume::DensityGrid};

    fn frame() -> Frame {
        Frame {
            camera: Camera {
                position_m: DVec3::new(0.0, 1.0, -10.0),
                look_at_m: DVec3::ZERO,
                fov_deg: 40.0,
                projection: Default::default(),
            },
            sun: Sun {
                elevation_deg: 30.0,
                azimuth_deg: 0.0,
                irradiance: [1.0; 3],
            },
            atmosphere: Atmosphere::default(),
            width: 8,
            height: 6,
            grid: DensityGrid::empty(),
            haze: None,
            ground_albedo: 0.1,
            lights: Vec::new(),
            media: Vec::new(),
            occluders: Vec::new(),
        }
    }

    /// Lights `frame` through `cache`, counting the calls that computed.
    fn light(cache: &LightingCache, frame: &Frame, settings: u32, calls: &mut u32) -> bool {
        let (lighting, reused) = cache
            .get_or_light(frame, &settings, |_| {
                *calls += 1;
                Ok::<_, ()>(frame.sun.elevation_deg)
            })
            .unwrap();
        assert_eq!(*lighting, frame.sun.elevation_deg);
        reused
    }

    /// What `light` is handed as its start: the last lighting where the settings and the
    /// grid are the same (another sun), none where either changed.
    #[test]
    fn a_new_sun_on_the_same_grid_starts_from_the_last_lighting() {
        let cache = LightingCache::new();
        let start = |f: &Frame, settings: u32| {
            let mut seen = None;
            cache
                .get_or_light(f, &settings, |previous: Option<&f64>| {
                    seen = Some(previous.copied());
                    Ok::<_, ()>(f.sun.elevation_deg)
                })
                .unwrap();
            seen.expect("lit anew")
        };
        let mut f = frame();
        assert_eq!(start(&f, 1), None);
        f.sun.elevation_deg = 31.0;
        assert_eq!(start(&f, 1), Some(30.0));
        f.sun.elevation_deg = 32.0;
        f.grid.data[0][0] = 1.0;
        assert_eq!(start(&f, 1), None);
        f.sun.elevation_deg = 33.0;
        assert_eq!(start(&f, 2), None);
        f.sun.elevation_deg = 34.0;
        assert_eq!(start(&f, 2), Some(33.0));
    }

    #[test]
    fn the_lighting_is_kept_while_only_the_camera_and_the_size_change() {
        let cache = LightingCache::new();
        let mut calls = 0;
        let mut f = frame();
        assert!(!light(&cache, &f, 1, &mut calls));
        f.camera.position_m.x += 3.0;
        f.camera.fov_deg = 60.0;
        (f.width, f.height) = (64, 48);
        assert!(light(&cache, &f, 1, &mut calls));
        assert_eq!(calls, 1);
        // The sun, the settings, the grid and the ground each light anew.
        f.sun.elevation_deg = 31.0;
        assert!(!light(&cache, &f, 1, &mut calls));
        assert!(!light(&cache, &f, 2, &mut calls));
        f.grid.data[0][0] = 1.0;
        assert!(!light(&cache, &f, 2, &mut calls));
        f.ground_albedo = 0.2;
        assert!(!light(&cache, &f, 2, &mut calls));
        assert_eq!(calls, 5);
        // Settings of another type (another model) never take this lighting.
        let (_, reused) = cache
            .get_or_light(&f, &2u64, |_| Ok::<_, ()>(0.0f64))
            .unwrap();
        assert!(!reused);
    }

    /// A relight in steps through a stepped cache: each frame of the same sun takes the
    /// pending relight one call further and shows it as it stands; once converged it is kept
    /// (the next frame reuses it); a new sun mid-relight drops the pending relight and starts
    /// from the last converged lighting. Here a "relight" counts to 3 from its start.
    #[test]
    fn a_stepped_relight_shows_each_frame_its_lighting_so_far_until_it_converges() {
        let cache = LightingCache::stepped(Duration::from_millis(1));
        let frame_of = |elevation: f64| {
            let mut f = frame();
            f.sun.elevation_deg = elevation;
            f
        };
        // The relight's state: (where it started, steps); its lighting: start + steps.
        let step = |f: &Frame| {
            cache.get_or_step(
                f,
                &1u32,
                |previous: Option<&f64>| Ok::<_, ()>((previous.copied().unwrap_or(0.0), 0)),
                |r: &mut (f64, usize)| {
                    r.1 += 1;
                    let lighting = r.0 + r.1 as f64;
                    Ok(if r.1 == 3 {
                        Stepped::Done(lighting)
                    } else {
                        Stepped::Partial(lighting, r.1)
                    })
                },
            )
        };
        let shown = |f: &Frame| {
            let (lighting, lit) = step(f).unwrap();
            (*lighting, lit)
        };
        let (a, b) = (frame_of(30.0), frame_of(31.0));
        assert_eq!(shown(&a), (1.0, Lit::Partial(1)));
        assert!(cache.converging());
        assert_eq!(shown(&a), (2.0, Lit::Partial(2)));
        assert_eq!(shown(&a), (3.0, Lit::Converged));
        assert!(!cache.converging());
        assert_eq!(shown(&a), (3.0, Lit::Kept));
        // Another sun starts from the converged lighting (3); moved again mid-relight, the
        // pending relight is dropped and the new one starts from that same lighting.
        assert_eq!(shown(&b), (4.0, Lit::Partial(1)));
        let c = frame_of(32.0);
        assert_eq!(shown(&c), (4.0, Lit::Partial(1)));
        assert_eq!(shown(&c), (5.0, Lit::Partial(2)));
        // A failed step drops the relight: the next frame starts anew.
        let failed = cache.get_or_step(
            &c,
            &1u32,
            |_: Option<&f64>| Ok::<(f64, usize), ()>((0.0, 0)),
            |_: &mut (f64, usize)| Err::<Stepped<f64>, ()>(()),
        );
        assert!(failed.is_err() && !cache.converging());
        assert_eq!(shown(&c), (4.0, Lit::Partial(1)));
    }
}
