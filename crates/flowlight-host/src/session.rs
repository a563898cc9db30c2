//! One render from a config file: load the scene, build the intersector, load and create the
//! integrator plugin, render, write the outputs.

use crate::film::Frame;
use crate::intersector::{build_intersector, Intersector};
use crate::output::{write_exr, write_png_preview, ExrMetadata, ImageLayer};
use crate::plugin::{find_plugin, search_dirs, IntegratorInstance, PluginLibrary};
use crate::render::{render, Progress, RenderOptions, RenderOutcome};
use flowlight_core::camera::Camera;
use flowlight_core::material::Texture;
use flowlight_scene::config::{load_config, RenderConfig, SampleBudget};
use flowlight_scene::{load_gltf, Scene};
use flowlight_sdk::abi::SceneView;
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Command-line settings that take precedence over the config file.
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    pub spp: Option<u32>,
    pub time: Option<f64>,
    pub threads: Option<usize>,
    pub out: Option<PathBuf>,
    pub seed: Option<u64>,
    /// Extra or replaced integrator parameters.
    pub params: Vec<(String, toml::Value)>,
}

/// Everything loaded for a render. Field order matters: the integrator instance is dropped
/// before the scene data its view points into.
pub struct Session {
    pub instance: IntegratorInstance,
    pub intersector: Box<dyn Intersector>,
    pub build_time: Duration,
    pub load_time: Duration,
    pub config: RenderConfig,
    pub options: RenderOptions,
    pub exr_path: Option<PathBuf>,
    pub png_path: Option<PathBuf>,
    pub camera: Camera,
    _textures: Vec<Texture>,
    pub scene: Scene,
}

impl Session {
    /// Loads `config_path` and everything it names. Errors are one line naming the file,
    /// field or plugin at fault.
    pub fn prepare(config_path: &Path, ov: &Overrides) -> Result<Session, String> {
        let config = load_config(config_path).map_err(|e| e.to_string())?;
        Session::from_config(config, ov)
    }

    pub fn from_config(mut config: RenderConfig, ov: &Overrides) -> Result<Session, String> {
        for (k, v) in &ov.params {
            match config
                .integrator_params
                .iter_mut()
                .find(|(name, _)| name == k)
            {
                Some(entry) => entry.1 = v.clone(),
                None => config.integrator_params.push((k.clone(), v.clone())),
            }
        }
        let t0 = Instant::now();
        let scene =
            load_gltf(&config.scene, &config.material_overrides).map_err(|e| e.to_string())?;
        let load_time = t0.elapsed();
        let camera = config.camera(&scene).map_err(|e| e.to_string())?;
        let (intersector, build_time) = build_intersector(config.intersector, &scene)
            .map_err(|e| format!("{}: {e}", config.path.display()))?;

        let dirs = search_dirs(&config.plugin_search_paths);
        let plugin_path =
            find_plugin(&config.integrator_plugin, &dirs).map_err(|e| e.to_string())?;
        let plugin = Arc::new(PluginLibrary::load(&plugin_path).map_err(|e| e.to_string())?);

        let textures = scene.texture_views();
        let (bounds_min, bounds_max) = scene.bounds().unwrap_or((Vec3::ZERO, Vec3::ZERO));
        let view = SceneView {
            camera,
            materials: scene.materials.as_ptr(),
            material_count: scene.materials.len(),
            textures: textures.as_ptr(),
            texture_count: textures.len(),
            emitters: scene.emitters.as_ptr(),
            emitter_count: scene.emitters.len(),
            emitter_power_cdf: scene.emitter_power_cdf.as_ptr(),
            bounds_min,
            bounds_max,
        };
        // SAFETY: the view points into `scene` and `textures`, which the session owns and
        // drops after the instance (field order); their heap buffers never move.
        let instance =
            unsafe { IntegratorInstance::create(plugin, &config.integrator_params, view) }
                .map_err(|e| format!("{}: {e}", config.path.display()))?;

        // The command line replaces the config's budget: --time, else --spp, else the file's.
        let (spp, time) = match (ov.time, ov.spp, config.budget) {
            (Some(t), _, _) => (0, Some(t)),
            (None, Some(n), _) => (n, None),
            (None, None, SampleBudget::Spp(n)) => (n, None),
            (None, None, SampleBudget::Time(t)) => (0, Some(t)),
        };
        let options = RenderOptions {
            width: camera.width,
            height: camera.height,
            spp,
            time: time.map(Duration::from_secs_f64),
            threads: ov.threads.unwrap_or(config.threads),
            tile_size: config.tile_size,
            seed: ov.seed.unwrap_or(config.seed),
        };
        let exr_path = Some(ov.out.clone().unwrap_or_else(|| config.output_exr.clone()));
        let png_path = config.output_png.clone();
        Ok(Session {
            instance,
            intersector,
            build_time,
            load_time,
            options,
            exr_path,
            png_path,
            camera,
            _textures: textures,
            scene,
            config,
        })
    }

    /// Renders until the budget is spent or `stop` is set.
    pub fn render(
        &self,
        stop: &AtomicBool,
        progress: &(dyn Fn(&Progress) + Sync),
    ) -> Result<RenderOutcome, String> {
        render(
            &self.instance,
            &self.scene,
            self.intersector.as_ref(),
            &self.options,
            stop,
            progress,
        )
    }

    /// Writes the EXR (main image plus lighting layers) and the PNG preview, each atomically.
    pub fn write_outputs(
        &self,
        frame: &Frame,
        outcome_stats: &crate::RenderStats,
    ) -> Result<Vec<PathBuf>, String> {
        let mut written = Vec::new();
        let (w, h) = (frame.width as usize, frame.height as usize);
        let image = frame.image();
        if let Some(path) = &self.exr_path {
            let layers: Vec<Vec<flowlight_core::Rgb>> = (0..frame.layer_count as usize)
                .map(|k| frame.layer(k))
                .collect();
            let mut exr_layers = vec![ImageLayer {
                name: String::new(),
                pixels: &image,
            }];
            for (k, l) in layers.iter().enumerate() {
                exr_layers.push(ImageLayer {
                    name: format!("layer{k}"),
                    pixels: l,
                });
            }
            let meta = self.metadata(outcome_stats);
            write_exr(path, w, h, &exr_layers, &meta).map_err(|e| e.to_string())?;
            written.push(path.clone());
        }
        if let Some(path) = &self.png_path {
            write_png_preview(path, w, h, &image, 0.0).map_err(|e| e.to_string())?;
            written.push(path.clone());
        }
        Ok(written)
    }

    fn metadata(&self, stats: &crate::RenderStats) -> ExrMetadata {
        let params: Vec<String> = self
            .config
            .integrator_params
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        let spp = if stats.interrupted || self.options.time.is_some() {
            format!(
                "{:.2} (mean)",
                stats.pixel_samples as f64 / (self.camera.width as f64 * self.camera.height as f64)
            )
        } else {
            self.options.spp.to_string()
        };
        ExrMetadata {
            entries: vec![
                (
                    "software".into(),
                    format!("flowlight {}", env!("CARGO_PKG_VERSION")),
                ),
                (
                    "flowlight.integrator".into(),
                    self.instance.plugin().name.clone(),
                ),
                ("flowlight.params".into(), params.join(" ")),
                ("flowlight.spp".into(), spp),
                ("flowlight.seed".into(), self.options.seed.to_string()),
                (
                    "flowlight.intersector".into(),
                    self.intersector.name().into(),
                ),
                (
                    "flowlight.biased".into(),
                    (self.instance.info.biased != 0).to_string(),
                ),
                (
                    "flowlight.interrupted".into(),
                    stats.interrupted.to_string(),
                ),
            ],
        }
    }
}
