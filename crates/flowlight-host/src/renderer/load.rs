//! Loading what a renderer renders with, step by step as [`Renderer::from_config`](super::Renderer::from_config) runs them:
//! the command line's `--set`s, the intersector, the mutation list, the view of the scene the
//! plugins read, the mutation plugins and the render options.

use super::Overrides;
use crate::accumulation::{Precision, Style};
use crate::error::HostError;
use crate::intersector::{build_intersector_with, Intersector};
use crate::plugin::{
    find_plugin, normalised_weights, MutationInstance, PluginError, PluginLibrary,
};
use crate::render::RenderOptions;
use flowlight_core::camera::Camera;
use flowlight_core::material::Texture;
use flowlight_scene::config::{Accumulation, FramePrecision, RenderConfig, SampleBudget};
use flowlight_scene::Scene;
use flowlight_sdk::abi::SceneView;
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

/// A plugin named by a relative file path is relative to the config's folder, like every
/// other path in the config; a bare name is looked up on the search path.
pub(super) fn relative_to(name: &str, base: &Path) -> String {
    let looks_like_path =
        name.contains(std::path::MAIN_SEPARATOR) || name.ends_with(std::env::consts::DLL_SUFFIX);
    if looks_like_path && Path::new(name).is_relative() {
        base.join(name).display().to_string()
    } else {
        name.to_string()
    }
}

/// One warning per Embree variable of the ray benchmark that is set (`is_set`) while a render
/// of `config` runs: the benchmark has no config and reads `FLOWLIGHT_EMBREE_ROBUST` and
/// `FLOWLIGHT_EMBREE_QUALITY`, a render takes `[render] robust` and `build_quality` from its
/// config only. Said aloud because a render timed with one of them set measures the config's
/// mode, not the variable's (earlier measurements of the robust mode's cost were void so).
pub(super) fn ignored_embree_variables(
    is_set: impl Fn(&str) -> bool,
    config: &Path,
) -> Vec<String> {
    [
        ("FLOWLIGHT_EMBREE_ROBUST", "robust"),
        ("FLOWLIGHT_EMBREE_QUALITY", "build_quality"),
    ]
    .into_iter()
    .filter(|(var, _)| is_set(var))
    .map(|(var, key)| {
        format!(
            "{var} is read by the ray benchmark and tests, not by renders: set [render] {key} in {}",
            config.display()
        )
    })
    .collect()
}

/// The host's precision for the config's `render.precision`.
pub(super) fn frame_precision(config: &RenderConfig) -> Precision {
    match config.precision {
        FramePrecision::Exact => Precision::Exact,
        FramePrecision::F32 => Precision::F32,
    }
}

/// A plugin's error while preparing a `Renderer`, said of the config (and of the config
/// key that named the plugin, if given).
pub(super) fn plugin_error(
    config: &RenderConfig,
    field: Option<String>,
    error: PluginError,
) -> HostError {
    HostError::Plugin {
        file: Some(config.path.clone()),
        field,
        error: Box::new(error),
    }
}

/// The image of `config` would not fit in memory.
pub(super) fn memory_error(config: &RenderConfig, msg: String) -> HostError {
    HostError::Memory {
        file: Some(config.path.clone()),
        msg,
    }
}

/// Applies the command line's `--set KEY=VALUE`s: `render.*` keys to the render settings
/// that may be set so, every other key to the integrator's parameters (replaced or added).
pub(super) fn apply_set_overrides(
    config: &mut RenderConfig,
    params: &[(String, toml::Value)],
) -> Result<(), HostError> {
    for (k, v) in params {
        // `--set render.accumulation=caching` and its siblings set the render's keys.
        if let Some(key) = k.strip_prefix("render.") {
            if config.set_render_key(key, v)? {
                continue;
            }
            return Err(HostError::NotSettable {
                file: config.path.clone(),
                key: k.clone(),
            });
        }
        match config
            .integrator_params
            .iter_mut()
            .find(|(name, _)| name == k)
        {
            Some(entry) => entry.1 = v.clone(),
            None => config.integrator_params.push((k.clone(), v.clone())),
        }
    }
    Ok(())
}

/// The config's intersector over `scene` and its build time, Embree with the config's robust
/// mode and build quality (the benchmark's variables are named when set, and ignored).
pub(super) fn build_intersector(
    config: &RenderConfig,
    scene: &Scene,
) -> Result<(Box<dyn Intersector>, Duration), HostError> {
    for warning in ignored_embree_variables(|v| std::env::var_os(v).is_some(), &config.path) {
        tracing::warn!("{warning}");
    }
    let options = flowlight_embree::SceneOptions {
        robust: config.robust,
        quality: flowlight_embree::BuildQuality::parse(&config.build_quality).map_err(|msg| {
            HostError::Field {
                file: config.path.clone(),
                field: "render.build_quality".into(),
                msg,
            }
        })?,
        packets: flowlight_embree::Packets::from_env().map_err(HostError::Variable)?,
        ..Default::default()
    };
    let intersector_error = |msg| HostError::Intersector {
        file: config.path.clone(),
        msg,
    };
    // The pure-Rust BVH builds on the host's worker pool, not on rayon's global one.
    let pool = crate::render::worker_pool(config.threads).map_err(intersector_error)?;
    pool.install(|| build_intersector_with(config.intersector, scene, options))
        .map_err(intersector_error)
}

/// The integrator's mutation list, taken out of its parameters: the name of the parameter
/// the integrator declares as a mutation list, and its entries, whose weights are checked
/// here, before any mutation plugin loads.
///
/// A config without the list gets the default the integrator's spec declares, if any
/// ([`PluginLibrary::mutation_list_default`]); the flag says so.
pub(super) fn mutation_list(
    plugin: &PluginLibrary,
    config: &mut RenderConfig,
) -> Result<(Option<String>, Vec<MutationEntry>, bool), HostError> {
    let list_name = plugin
        .mutation_list_param()
        .map_err(|error| plugin_error(config, None, error))?;
    let given = |list: &str| config.integrator_params.iter().any(|(k, _)| k == list);
    let default = match &list_name {
        Some(list) if !given(list) => plugin.mutation_list_default(),
        _ => None,
    };
    let defaulted = default.is_some();
    let mut mutation_entries = match (&list_name, default) {
        (Some(list), Some(text)) => {
            // The plugin's declared default, read as the config's list would be.
            let mut params =
                default_list_params(list, &text).map_err(|msg| HostError::Mutations {
                    file: config.path.clone(),
                    msg: format!("the default of plugin '{}': {msg}", plugin.name),
                })?;
            take_mutations(&mut params, list, &config.path)?
        }
        (Some(list), None) => take_mutations(&mut config.integrator_params, list, &config.path)?,
        (None, _) => Vec::new(),
    };
    // The one normalisation of the list's weights: each entry's weight becomes its
    // selection probability, which its instance is created with.
    let weights: Vec<(&str, f64)> = mutation_entries
        .iter()
        .map(|e| (e.plugin.as_str(), e.weight))
        .collect();
    let probabilities = normalised_weights(list_name.as_deref().unwrap_or("mutations"), &weights)
        .map_err(|msg| HostError::Mutations {
        file: config.path.clone(),
        msg,
    })?;
    for (entry, probability) in mutation_entries.iter_mut().zip(probabilities) {
        entry.weight = probability;
    }
    Ok((list_name, mutation_entries, defaulted))
}

/// The declared default list `text` (a TOML array of inline tables) as the one parameter
/// `list`, for [`take_mutations`].
fn default_list_params(list: &str, text: &str) -> Result<Vec<(String, toml::Value)>, String> {
    let table: toml::Table = format!("{list} = {text}")
        .parse()
        .map_err(|e: toml::de::Error| {
            format!("default mutation list is not TOML: {}", e.message())
        })?;
    Ok(table.into_iter().collect())
}

/// The view of the scene the plugins read: pointers into `scene`, `textures` and
/// `light_cdf`, which must outlive every plugin instance made over it. Without a light the
/// environment is left out, as the power CDF is empty.
pub fn scene_view(
    scene: &Scene,
    camera: Camera,
    textures: &[Texture],
    env_view: flowlight_core::light::Environment,
    light_cdf: &[f32],
) -> SceneView {
    let (bounds_min, bounds_max) = scene.bounds().unwrap_or((Vec3::ZERO, Vec3::ZERO));
    SceneView {
        camera,
        materials: scene.materials.as_ptr(),
        material_count: scene.materials.len(),
        textures: textures.as_ptr(),
        texture_count: textures.len(),
        emitters: scene.emitters.as_ptr(),
        emitter_count: scene.emitters.len(),
        punctual_lights: scene.punctual_lights.as_ptr(),
        punctual_count: scene.punctual_lights.len(),
        environment: if light_cdf.is_empty() {
            flowlight_core::light::Environment::none()
        } else {
            env_view
        },
        light_power_cdf: light_cdf.as_ptr(),
        bounds_min,
        bounds_max,
        mesh: flowlight_sdk::scene::mesh_tables(&scene.mesh()),
    }
}

/// Loads and creates the mutation plugins of `entries` over `view`, adding their files to
/// `plugin_files`.
pub(super) fn create_mutations(
    config: &RenderConfig,
    dirs: &[PathBuf],
    list_name: Option<&str>,
    entries: &[MutationEntry],
    view: &SceneView,
    plugin_files: &mut Vec<PathBuf>,
) -> Result<Vec<MutationInstance>, HostError> {
    let mut mutations = Vec::new();
    for entry in entries {
        let path =
            find_plugin(&relative_to(&entry.plugin, &config.base_dir), dirs).map_err(|error| {
                let field = format!("integrator.{}", list_name.unwrap_or_default());
                plugin_error(config, Some(field), error)
            })?;
        plugin_files.push(path.clone());
        let lib = Arc::new(PluginLibrary::load(&path)?);
        // SAFETY: as for the integrator: the view points into data the renderer owns and
        // drops after every instance.
        let m = unsafe { MutationInstance::create(lib, &entry.params, entry.weight, view) }
            .map_err(|error| plugin_error(config, None, error))?;
        mutations.push(m);
    }
    Ok(mutations)
}

/// The render options of `config` at the camera's resolution; the command line replaces the
/// config's budget (`--time`, else `--spp`, else the file's), threads and seed.
pub(super) fn render_options(
    config: &RenderConfig,
    camera: &Camera,
    ov: &Overrides,
) -> RenderOptions {
    let (spp, time) = match (ov.time, ov.spp, config.budget) {
        (Some(t), _, _) => (0, Some(t)),
        (None, Some(n), _) => (n, None),
        (None, None, SampleBudget::Spp(n)) => (n, None),
        (None, None, SampleBudget::Time(t)) => (0, Some(t)),
    };
    RenderOptions {
        width: camera.width,
        height: camera.height,
        spp,
        sample_begin: 0,
        time: time.map(Duration::from_secs_f64),
        threads: ov.threads.unwrap_or(config.threads),
        tile_size: config.tile_size,
        seed: ov.seed.unwrap_or(config.seed),
        accumulation: match config.accumulation {
            Accumulation::Auto => None,
            Accumulation::Blasting => Some(Style::Blasting),
            Accumulation::Buffering => Some(Style::Buffering),
            Accumulation::Caching => Some(Style::Caching),
        },
        precision: frame_precision(config),
        cache_bytes: (config.accumulation_cache_mib * 1048576.0) as u64,
        flange: config.flange,
        preview_flush: None,
    }
}

/// One `[[integrator.mutations]]` entry.
pub(super) struct MutationEntry {
    pub(super) plugin: String,
    pub(super) weight: f64,
    pub(super) params: Vec<(String, toml::Value)>,
}

/// Removes the mutation list `list` (the integrator's [`ParamKind::MutationList`]
/// parameter, e.g. `mutations`) from the integrator's parameters and reads each entry: a
/// `plugin` name, a numeric `weight` (default 1; its value is checked with the list's other
/// weights by [`normalised_weights`]), the rest are the plugin's parameters.
///
/// [`ParamKind::MutationList`]: flowlight_sdk::ParamKind::MutationList
pub(super) fn take_mutations(
    params: &mut Vec<(String, toml::Value)>,
    list: &str,
    config: &Path,
) -> Result<Vec<MutationEntry>, HostError> {
    let Some(pos) = params.iter().position(|(k, _)| k == list) else {
        return Ok(Vec::new());
    };
    let (_, value) = params.remove(pos);
    let in_list = |msg: String| HostError::Mutations {
        file: config.to_path_buf(),
        msg,
    };
    let at = |i: usize, msg: &str| in_list(format!("integrator.{list}[{i}]: {msg}"));
    let toml::Value::Array(items) = value else {
        return Err(in_list(format!(
            "integrator.{list} must be an array of tables ([[integrator.{list}]])"
        )));
    };
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.into_iter().enumerate() {
        let toml::Value::Table(table) = item else {
            return Err(at(i, "must be a table with a `plugin` key"));
        };
        let mut plugin = None;
        let mut weight = 1.0;
        let mut rest = Vec::new();
        for (k, v) in table {
            match k.as_str() {
                "plugin" => {
                    plugin = Some(
                        v.as_str()
                            .ok_or_else(|| at(i, "`plugin` must be a string"))?
                            .to_string(),
                    )
                }
                "weight" => {
                    weight = v
                        .as_float()
                        .or_else(|| v.as_integer().map(|n| n as f64))
                        .ok_or_else(|| at(i, "`weight` must be a number"))?;
                }
                _ => rest.push((k, v)),
            }
        }
        let plugin = plugin.ok_or_else(|| at(i, "missing `plugin`"))?;
        out.push(MutationEntry {
            plugin,
            weight,
            params: rest,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A declared default list reads as the config's would: entries, their parameters and
    /// the default weight 1; text that is not a TOML array of tables is a one-line error.
    #[test]
    fn a_declared_default_list_reads_as_a_config_list() {
        let text = "[{ plugin = \"drill\", width = \"narrow\" }, { plugin = \"blow\" }]";
        let mut params = default_list_params("mutations", text).unwrap();
        let list = take_mutations(&mut params, "mutations", Path::new("c.toml")).unwrap();
        assert!(params.is_empty());
        assert_eq!(list.len(), 2);
        assert_eq!((list[0].plugin.as_str(), list[0].weight), ("drill", 1.0));
        assert_eq!(list[0].params[0].0, "width");
        assert_eq!(list[1].plugin, "blow");
        let e = default_list_params("mutations", "[{ plugin = ").unwrap_err();
        assert!(
            e.starts_with("default mutation list is not TOML") && !e.contains('\n'),
            "{e}"
        );
    }

    #[test]
    fn embree_variables_set_for_a_render_are_named_with_the_config_key() {
        let cfg = Path::new("scenes/cornell-box/cornell-box.toml");
        assert!(ignored_embree_variables(|_| false, cfg).is_empty());
        let both = ignored_embree_variables(|_| true, cfg);
        assert_eq!(both.len(), 2, "{both:?}");
        assert!(
            both[0].starts_with("FLOWLIGHT_EMBREE_ROBUST ")
                && both[0].contains("[render] robust in scenes/cornell-box/cornell-box.toml"),
            "{both:?}"
        );
        assert!(
            both[1].starts_with("FLOWLIGHT_EMBREE_QUALITY ")
                && both[1].contains("[render] build_quality in"),
            "{both:?}"
        );
        let one = ignored_embree_variables(|v| v == "FLOWLIGHT_EMBREE_QUALITY", cfg);
        assert_eq!(one.len(), 1);
        assert!(one[0].starts_with("FLOWLIGHT_EMBREE_QUALITY "));
    }
}
