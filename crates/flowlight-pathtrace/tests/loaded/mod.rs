//! Real scenes loaded and intersected by the host's code, for the tests that call the
//! bidirectional library directly (flowlight-host does not depend on this crate, so there
//! is no cycle).

use flowlight_host::intersector::{build_intersector, Intersector};
use flowlight_host::renderer::scene_view;
use flowlight_scene::config::load_config;
use flowlight_scene::lights::{light_power_cdf, load_environment, EnvironmentData};
use flowlight_scene::load_gltf;
use flowlight_sdk::abi::SceneView;
use std::path::Path;

/// A scene loaded as the host loads it, without an integrator plugin: what the view points
/// into is owned here and outlives every [`flowlight_sdk::Scene`] made from `view`.
pub struct LoadedScene {
    pub view: SceneView,
    pub intersector: Box<dyn Intersector>,
    pub scene: flowlight_scene::Scene,
    _textures: Vec<flowlight_core::material::Texture>,
    _environment: EnvironmentData,
    _light_cdf: Vec<f32>,
    /// The config's `path_depth`, if it sets one (not every test binary reads it).
    #[allow(dead_code)]
    pub path_depth: Option<i64>,
}

/// Loads the scene of config `relative` (to the repository root).
pub fn load(relative: &str) -> LoadedScene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(relative);
    let config = load_config(&path).unwrap_or_else(|e| panic!("{relative}: {e}"));
    let scene = load_gltf(&config.scene, &config.material_overrides)
        .unwrap_or_else(|e| panic!("{relative}: {e}"));
    let camera = config
        .camera(&scene)
        .unwrap_or_else(|e| panic!("{relative}: {e}"));
    let (intersector, _) =
        build_intersector(config.intersector, &scene).unwrap_or_else(|e| panic!("{relative}: {e}"));
    let textures = scene.texture_views();
    let environment = match &config.environment {
        Some(e) => load_environment(&config.path, e).unwrap_or_else(|e| panic!("{relative}: {e}")),
        None => EnvironmentData::default(),
    };
    let env_view = environment.view();
    let light_cdf = light_power_cdf(&scene, &env_view);
    let view = scene_view(&scene, camera, &textures, env_view, &light_cdf);
    let path_depth = config
        .integrator_params
        .iter()
        .find(|(name, _)| name == "path_depth")
        .and_then(|(_, v)| v.as_integer());
    LoadedScene {
        view,
        intersector,
        scene,
        _textures: textures,
        _environment: environment,
        _light_cdf: light_cdf,
        path_depth,
    }
}
