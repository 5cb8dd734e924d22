//! Per-sun work kept between the frames of a moving camera. `max` and `coupled` light the grid
//! once per sun (their lighting depends on the sun, the grid, the sky, the ground, the scene's
//! objects and the settings, never on the camera or the image size) and then gather a view from
//! it. A caller that renders many views of one lighting (the viewer) hands the models a
//! [`LightingCache`] through [`crate::model::Job::lighting`]; a view that changes only the camera then
//! costs the gather alone. `render` and `bench render` hand none: every frame is lit anew.

use std::any::Any;
use std::sync::{Arc, Mutex};

use crate::frame::Frame;

/// The last lighting a model computed, with what it was computed from (module docs).
#[derive(Default)]
pub struct LightingCache {
    last: Mutex<Option<Entry>>,
}

struct Entry {
    /// The frame it was lit for (its camera and size play no part).
    frame: Frame,
    /// The model's settings (their type tells the models apart).
    settings: Box<dyn Any + Send + Sync>,
    lighting: Arc<dyn Any + Send + Sync>,
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
        let same_settings = |e: &Entry| e.settings.downcast_ref::<S>() == Some(settings);
        if let Some(e) = last.as_ref()
            && same_settings(e)
            && same_lighting(&e.frame, frame)
            && let Ok(lighting) = e.lighting.clone().downcast::<L>()
        {
            return Ok((lighting, true));
        }
        let previous = last
            .take()
            .filter(|e| same_settings(e) && e.frame.grid == frame.grid)
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
}
