//! A scene loaded once for many renders: the glTF scene, its camera, the intersector built
//! over it (Embree's BVH or the pure-Rust one), its textures, environment map and the light
//! power CDF. A [`Renderer`](super::Renderer) made from a [`LoadedScene`] shares all of it
//! (reference-counted) and creates only its integrator and mutations, so a sweep of
//! integrator parameters (`--set`) pays the load and the build once. The command line loads
//! one scene for one render; the Python package keeps one for many.

use super::load::build_intersector;
use crate::error::HostError;
use crate::intersector::Intersector;
use flowlight_core::camera::Camera;
use flowlight_core::material::Texture;
use flowlight_scene::config::RenderConfig;
use flowlight_scene::lights::{light_power_cdf, light_presence, load_environment, EnvironmentData};
use flowlight_scene::{load_gltf_with, Scene};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How many scenes this process has loaded ([`LoadedScene::load`] calls that succeeded):
/// a count the Python package reports so that a sweep can show it loaded once.
static LOADS: AtomicU64 = AtomicU64::new(0);

/// The number of scenes this process has loaded so far.
pub fn loads_so_far() -> u64 {
    LOADS.load(Ordering::Relaxed)
}

/// What the plugins' scene view points into besides the scene: the texture views, the
/// environment map with its sampling tables, and the power CDF over all lights. Owned
/// behind an `Arc` by the loaded scene and by every renderer made from it, so it outlives
/// each plugin instance created over the view.
pub(super) struct ViewData {
    pub(super) textures: Vec<Texture>,
    pub(super) environment: EnvironmentData,
    pub(super) light_cdf: Vec<f32>,
}

/// A config's scene, loaded and built once; [`Renderer::from_loaded`](super::Renderer::from_loaded)
/// makes renderers over it.
pub struct LoadedScene {
    /// The config as read (with the loading call's `--set`s), before any render's own.
    pub config: RenderConfig,
    pub scene: Arc<Scene>,
    pub camera: Camera,
    pub intersector: Arc<dyn Intersector>,
    /// Reading the glTF scene.
    pub load_time: Duration,
    /// Building the intersector.
    pub build_time: Duration,
    /// This load's number in the process (1 for the first; [`loads_so_far`]).
    pub load_id: u64,
    pub(super) data: Arc<ViewData>,
}

impl LoadedScene {
    /// Loads the scene of `config`, builds its intersector and reads its environment.
    /// Errors are one line naming the file or field at fault.
    pub fn load(config: RenderConfig) -> Result<LoadedScene, HostError> {
        let t0 = Instant::now();
        let scene = load_gltf_with(&config.scene, &config.load_options())?;
        let load_time = t0.elapsed();
        let camera = config.camera(&scene)?;
        tracing::debug!(?camera, "camera");
        let (intersector, build_time) = build_intersector(&config, &scene)?;
        let textures = scene.texture_views();
        let environment = match &config.environment {
            Some(e) => load_environment(&config.path, e)?,
            None => EnvironmentData::default(),
        };
        let env_view = environment.view();
        let presence = light_presence(&scene, &env_view).map_err(|msg| HostError::Lights {
            file: config.path.clone(),
            msg,
        })?;
        if let Some(why) = presence.warning() {
            tracing::warn!("{}: {why}", config.path.display());
        }
        let light_cdf = light_power_cdf(&scene, &env_view);
        let load_id = LOADS.fetch_add(1, Ordering::Relaxed) + 1;
        Ok(LoadedScene {
            config,
            scene: Arc::new(scene),
            camera,
            intersector: Arc::from(intersector),
            load_time,
            build_time,
            load_id,
            data: Arc::new(ViewData {
                textures,
                environment,
                light_cdf,
            }),
        })
    }
}
