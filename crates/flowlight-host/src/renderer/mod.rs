//! One render from a config file: load the scene, build the intersector, load and create the
//! integrator plugin, render, write the outputs.

use crate::accumulation::{Frame, Precision};
use crate::error::{HostError, PartRefusal};
use crate::intersector::Intersector;
use crate::output::{ExrMetadata, PngPreview};
use crate::plugin::{find_plugin, search_dirs, IntegratorInstance, PluginLibrary};
use crate::render::{render, Progress, RenderOptions, RenderOutcome};
use flowlight_core::camera::Camera;
use flowlight_scene::config::{load_config, RenderConfig};
use flowlight_scene::Scene;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

mod extras;
mod load;
mod loaded;

pub use extras::ExtraLayers;

/// Public for code that runs a plugin library's functions in-process over a loaded scene
/// (the bidirectional library's allocation test) without loading a plugin.
pub use load::scene_view;
use load::{
    apply_set_overrides, create_mutations, frame_precision, memory_error, mutation_list,
    plugin_error, relative_to, render_options,
};
pub use loaded::{loads_so_far, LoadedScene};

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
pub struct Renderer {
    pub instance: IntegratorInstance,
    /// Shared with the [`LoadedScene`] the renderer was made from.
    pub intersector: Arc<dyn Intersector>,
    pub build_time: Duration,
    pub load_time: Duration,
    pub config: RenderConfig,
    pub options: RenderOptions,
    pub exr_path: Option<PathBuf>,
    pub png_path: Option<PathBuf>,
    pub camera: Camera,
    /// The textures, environment map and light CDF the view points into.
    _data: Arc<loaded::ViewData>,
    pub scene: Arc<Scene>,
    /// The plugin libraries loaded (integrator first), for the output checks.
    plugin_files: Vec<PathBuf>,
    /// The resolved config as hashed for a part ([`crate::parts::config_text`]).
    config_text: String,
    /// The share of the samples this renderer renders, with the config hash
    /// ([`Renderer::set_part`]); `None` for a whole render.
    pub part: Option<(crate::parts::PartSpec, u64)>,
}
/// `p` in a form two names of one file share: canonical where the file (or its folder)
/// exists, else absolute.
fn comparable_path(p: &Path) -> PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    if let (Some(dir), Some(name)) = (p.parent(), p.file_name()) {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        if let Ok(d) = dir.canonicalize() {
            return d.join(name);
        }
    }
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}
impl Renderer {
    /// Loads `config_path` and everything it names. Errors are one line naming the file,
    /// field or plugin at fault.
    pub fn prepare(config_path: &Path, ov: &Overrides) -> Result<Renderer, HostError> {
        let config = load_config(config_path)?;
        Renderer::from_config(config, ov)
    }

    /// [`Renderer::prepare`] for a config already read: `ov` applied, the scene loaded, the
    /// intersector built, the integrator (and its mutations) created over the scene's view.
    pub fn from_config(mut config: RenderConfig, ov: &Overrides) -> Result<Renderer, HostError> {
        apply_set_overrides(&mut config, &ov.params)?;
        output_paths(&config, ov.out.as_deref())?;
        // Refuse an image that cannot fit before anything big is loaded (layers are known
        // once the integrator exists; checked again then).
        crate::render::check_memory(config.width, config.height, 0, frame_precision(&config), 0)
            .map_err(|msg| memory_error(&config, msg))?;
        let loaded = LoadedScene::load(config)?;
        Renderer::from_loaded(&loaded, ov)
    }

    /// A renderer over a scene already loaded and built: `ov` applied to a copy of its
    /// config, the integrator (and its mutations) loaded and created over the scene's view.
    /// The scene, intersector and view data are shared with `loaded`, not copied.
    pub fn from_loaded(loaded: &LoadedScene, ov: &Overrides) -> Result<Renderer, HostError> {
        let mut config = loaded.config.clone();
        apply_set_overrides(&mut config, &ov.params)?;
        let (exr_path, png_path) = output_paths(&config, ov.out.as_deref())?;
        let precision = frame_precision(&config);
        crate::render::check_memory(config.width, config.height, 0, precision, 0)
            .map_err(|msg| memory_error(&config, msg))?;
        let camera = loaded.camera;
        let dirs = search_dirs(&config.plugin_search_paths);
        let plugin_path = find_plugin(
            &relative_to(&config.integrator_plugin, &config.base_dir),
            &dirs,
        )
        .map_err(|error| plugin_error(&config, Some("integrator.plugin".into()), error))?;
        let plugin = Arc::new(PluginLibrary::load(&plugin_path)?);

        // Hashed with the mutations still among the parameters.
        let config_text = crate::parts::config_text(&config, &camera, &config.integrator_params);
        let (list_name, mutation_entries, defaulted) = mutation_list(&plugin, &mut config)?;
        let data = loaded.data.clone();
        let env_view = data.environment.view();
        let view = scene_view(
            &loaded.scene,
            camera,
            &data.textures,
            env_view,
            &data.light_cdf,
        );
        let mut plugin_files = vec![plugin_path.clone()];
        let mutations = create_mutations(
            &config,
            &dirs,
            list_name.as_deref(),
            &mutation_entries,
            &view,
            &mut plugin_files,
        )?;
        // SAFETY: the view points into the loaded scene and its view data, which the
        // renderer holds (reference-counted) and drops after the instance (field order);
        // their heap buffers never move.
        let instance = unsafe {
            IntegratorInstance::create(
                plugin,
                &config.integrator_params,
                mutations,
                defaulted,
                view,
            )
        }
        .map_err(|error| plugin_error(&config, None, error))?;
        crate::render::check_memory(
            config.width,
            config.height,
            instance.info.layer_count,
            precision,
            0,
        )
        .map_err(|msg| memory_error(&config, msg))?;
        let options = render_options(&config, &camera, ov);
        let renderer = Renderer {
            instance,
            intersector: loaded.intersector.clone(),
            build_time: loaded.build_time,
            load_time: loaded.load_time,
            options,
            exr_path,
            png_path,
            camera,
            _data: data,
            scene: loaded.scene.clone(),
            config,
            plugin_files,
            config_text,
            part: None,
        };
        Ok(renderer)
    }

    /// Renders only `spec`'s samples [begin, end) of the `spec.total` the config asks for (a
    /// part of a distributed render: [`crate::parts`]); the EXR then records the range, the
    /// config hash and the exact sums. Refused under a time budget (a part needs a fixed
    /// number of samples).
    pub fn set_part(&mut self, spec: crate::parts::PartSpec) -> Result<(), HostError> {
        self.check_part_budget()?;
        let hash = crate::parts::config_hash(&self.config_text, &self.config)
            .map_err(HostError::PartFile)?;
        self.options.sample_begin = spec.begin;
        self.options.spp = spec.end - spec.begin;
        self.part = Some((spec, hash));
        Ok(())
    }

    /// Whether this render can be split into parts: it needs a sample budget and exact
    /// precision. Checked before the part is parsed, so that a time budget is named as the
    /// cause rather than read as a render of 0 samples.
    pub fn check_part_budget(&self) -> Result<(), HostError> {
        let refuse = |refusal| HostError::Part {
            file: self.config.path.clone(),
            refusal,
        };
        if self.options.time.is_some() {
            return Err(refuse(PartRefusal::TimeBudget));
        }
        if self.options.precision != Precision::Exact {
            return Err(refuse(PartRefusal::NotExact));
        }
        Ok(())
    }

    /// The files the render will write, each with the extension its format needs: the EXR,
    /// its `.stats.json` and the PNG preview.
    pub fn output_paths(&self) -> Vec<(&'static str, &'static str, PathBuf)> {
        let mut out = Vec::new();
        if let Some(p) = &self.exr_path {
            out.push(("the EXR output", "exr", p.clone()));
            out.push((
                "the statistics file",
                "json",
                p.with_extension("stats.json"),
            ));
        }
        if let Some(p) = &self.png_path {
            out.push(("the PNG preview", "png", p.clone()));
        }
        out
    }

    /// Checks the outputs before anything is rendered: none may be one of the inputs (the
    /// config, the scene, a plugin) or another output, and each one's folder must accept a
    /// new file. The CLI calls it before rendering, after the outputs are final; renderers
    /// that write nothing (benchmarks, tests) need not.
    pub fn check_outputs(&self) -> Result<(), HostError> {
        let file = &self.config.path;
        let mut inputs: Vec<(&str, PathBuf)> = vec![
            ("the config", self.config.path.clone()),
            ("the scene", self.config.scene.clone()),
        ];
        inputs.extend(self.plugin_files.iter().map(|p| ("a plugin", p.clone())));
        if let Some(map) = self.config.environment.as_ref().and_then(|e| e.map.clone()) {
            inputs.push(("the environment map", map));
        }
        inputs.extend(self.scene.files.iter().map(|p| ("a scene file", p.clone())));
        let outputs = self.output_paths();
        for (i, (what, wanted, out)) in outputs.iter().enumerate() {
            let key = comparable_path(out);
            if let Some((input, _)) = inputs.iter().find(|(_, p)| comparable_path(p) == key) {
                return Err(HostError::OutputIsInput {
                    file: file.clone(),
                    what,
                    output: out.clone(),
                    input,
                });
            }
            if let Some((other, _, _)) = outputs[..i]
                .iter()
                .find(|(_, _, p)| comparable_path(p) == key)
            {
                return Err(HostError::SameOutput {
                    file: file.clone(),
                    what,
                    other,
                    output: out.clone(),
                });
            }
            crate::output::check_writable(out).map_err(|error| HostError::Output {
                file: Some(file.clone()),
                what: Some(what),
                error,
            })?;
            let ext = out.extension().map(|e| e.to_ascii_lowercase());
            if ext.as_deref() != Some(std::ffi::OsStr::new(wanted)) {
                return Err(HostError::WrongExtension {
                    file: file.clone(),
                    what,
                    output: out.clone(),
                    wanted,
                });
            }
        }
        Ok(())
    }

    /// Renders until the budget is spent or `stop` is set.
    pub fn render(
        &self,
        stop: &AtomicBool,
        progress: &(dyn Fn(&Progress) + Sync),
    ) -> Result<RenderOutcome, HostError> {
        render(
            &self.instance,
            &self.scene,
            self.intersector.as_ref(),
            &self.options,
            stop,
            progress,
        )
        .map_err(HostError::Render)
    }

    /// Writes the EXR (main image plus lighting layers) and the PNG preview, each atomically.
    /// Callers write only a render that succeeded or was interrupted (then
    /// `flowlight.interrupted = true` marks the EXR), never one a plugin failed. The frame is
    /// taken apart as its framebuffers are encoded, so writing a 1080p image with 8 layers
    /// needs one framebuffer's channels beyond the frame, not a second image.
    pub fn write_outputs(
        &self,
        frame: Frame,
        outcome_stats: &crate::RenderStats,
    ) -> Result<Vec<PathBuf>, HostError> {
        self.write_outputs_with(frame, outcome_stats, ExtraLayers::default())
    }

    /// [`Renderer::write_outputs`] with the AOV and denoised layers of `extra` after the
    /// beauty's (a part's EXR, which `flowlight merge` joins by its exact sums, takes none);
    /// the PNG preview is made from the denoised layer when there is one.
    pub fn write_outputs_with(
        &self,
        mut frame: Frame,
        outcome_stats: &crate::RenderStats,
        extra: ExtraLayers,
    ) -> Result<Vec<PathBuf>, HostError> {
        let mut written = Vec::new();
        let (w, h) = (frame.width as usize, frame.height as usize);
        // The preview keeps 8-bit pixels (3 bytes a pixel), made from the EXR's main channels
        // when the frame is taken apart for the EXR, so no float copy of the image is made.
        let mut preview = None;
        if let Some(path) = &self.exr_path {
            let mut meta = self.metadata(outcome_stats);
            let stats_json = self.stats_json(outcome_stats);
            if let Some((spec, hash)) = &self.part {
                meta.entries
                    .extend(crate::parts::part_entries(spec, *hash, &frame));
                if let Some(json) = &stats_json {
                    // The merge refuses a statistics file that is not this one.
                    meta.entries.push((
                        crate::parts::KEY_STATS_CHECKSUM.into(),
                        format!(
                            "{:016x}",
                            crate::parts::fnv1a(crate::parts::FNV_OFFSET, json.as_bytes())
                        ),
                    ));
                }
                crate::parts::write_part_exr(path, &frame, &meta).map_err(HostError::PartFile)?;
            } else {
                let mut layers: Vec<_> = (0..=frame.layer_count as usize)
                    .map(|k| crate::output::PlanarLayer {
                        name: if k == 0 {
                            String::new()
                        } else {
                            format!("layer{}", k - 1)
                        },
                        channels: frame.take_channels(k),
                    })
                    .collect();
                if let Some(aovs) = extra.aovs {
                    meta.entries
                        .push(("flowlight.aov_spp".into(), aovs.spp.to_string()));
                    // What `material_id` indexes, as a TOML array of the materials' names.
                    let names = toml::Value::Array(
                        self.scene
                            .material_names
                            .iter()
                            .map(|n| n.as_str().into())
                            .collect(),
                    );
                    meta.entries
                        .push(("flowlight.aov_materials".into(), names.to_string()));
                    layers.extend(aovs.into_planar());
                }
                if let Some(denoiser) = extra.denoiser {
                    meta.entries.push(("flowlight.denoiser".into(), denoiser));
                }
                if let Some(denoised) = extra.denoised {
                    layers.push(crate::output::PlanarLayer {
                        name: crate::denoise::LAYER.into(),
                        channels: denoised,
                    });
                }
                if let Some(png) = &self.png_path {
                    let shown = layers
                        .iter()
                        .find(|l| l.name == crate::denoise::LAYER)
                        .unwrap_or(&layers[0]);
                    preview = Some(PngPreview::from_planar(png, w, h, &shown.channels, 0.0)?);
                }
                crate::output::write_exr_planar(path, w, h, layers, &[], &meta)?;
            }
            written.push(path.clone());
            if let Some(json) = stats_json {
                let json_path = path.with_extension("stats.json");
                crate::output::write_atomically(&json_path, |tmp| {
                    std::fs::write(tmp, &json).map_err(|e| crate::output::OutputError::Io {
                        path: json_path.clone(),
                        source: e,
                    })
                })?;
                written.push(json_path);
            }
        }
        if let Some(path) = &self.png_path {
            let preview = match preview {
                Some(p) => p,
                // No EXR, or a part's (which keeps the frame): from the resolved image.
                None => PngPreview::new(path, w, h, &frame.image(), 0.0)?,
            };
            preview.write(path)?;
            written.push(path.clone());
        }
        Ok(written)
    }

    /// The `.stats.json` text of a render with integrator statistics (with the counters'
    /// merge kinds for a part).
    fn stats_json(&self, outcome_stats: &crate::RenderStats) -> Option<String> {
        if outcome_stats.integrator.is_empty() {
            return None;
        }
        let json = stats_json(&self.instance.plugin().name, outcome_stats);
        if self.part.is_none() {
            return Some(json);
        }
        let kinds = crate::parts::counter_kinds(self.instance.stat_specs());
        Some(crate::parts::stats_json_with_kinds(&json, &kinds))
    }

    /// The EXR header entries of a render with `stats` (integrator, parameters, spp, seed,
    /// inputs, interruption).
    pub fn metadata(&self, stats: &crate::RenderStats) -> ExrMetadata {
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
        let mut entries = vec![
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
            // Inputs a later command must not overwrite (`flowlight merge`).
            (
                "flowlight.config".into(),
                comparable_path(&self.config.path).display().to_string(),
            ),
            (
                "flowlight.scene".into(),
                comparable_path(&self.config.scene).display().to_string(),
            ),
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
            (
                "flowlight.partial_pass".into(),
                stats
                    .partial_pass
                    .map_or("0".to_string(), |p| p.fraction().to_string()),
            ),
        ];
        entries.extend(crate::param_docs::metadata_entries(&self.instance));
        ExrMetadata { entries }
    }
}

/// The EXR and PNG paths of a render: the config's, or with `--out FILE` the EXR at FILE and
/// the PNG preview (when the config asks for one) beside it as FILE with the extension
/// `.png`, so that `--out` never overwrites the config's own preview.
pub fn output_paths(
    config: &RenderConfig,
    out: Option<&Path>,
) -> Result<(Option<PathBuf>, Option<PathBuf>), HostError> {
    let Some(out) = out else {
        return Ok((Some(config.output_exr.clone()), config.output_png.clone()));
    };
    if out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        return Err(HostError::OutNotExr {
            out: out.to_path_buf(),
        });
    }
    let png = config
        .output_png
        .as_ref()
        .map(|_| out.with_extension("png"));
    Ok((Some(out.to_path_buf()), png))
}
/// The render's counters as JSON: host statistics and the integrator's own (e.g. ERPT's
/// quality norms), written next to the image.
pub fn stats_json(integrator: &str, s: &crate::RenderStats) -> String {
    let num = |v: f64| {
        if v.is_finite() {
            format!("{v}")
        } else {
            "null".into()
        }
    };
    let mut out = String::from("{\n");
    out += &format!("  \"integrator\": \"{integrator}\",\n");
    out += &format!("  \"wall_seconds\": {},\n", num(s.wall.as_secs_f64()));
    out += &format!("  \"pixel_samples\": {},\n", s.pixel_samples);
    out += &format!(
        "  \"closest_rays\": {},\n  \"shadow_rays\": {},\n",
        s.closest_rays, s.shadow_rays
    );
    out += &format!("  \"invalid_deposits\": {},\n", s.invalid_deposits);
    out += &format!("  \"interrupted\": {},\n", s.interrupted);
    out += &format!("  \"full_passes\": {},\n", s.full_passes);
    out += &format!(
        "  \"partial_pass\": {},\n",
        s.partial_pass.map_or(0.0, |p| p.fraction())
    );
    out += "  \"counters\": {";
    for (i, (k, v)) in s.integrator.iter().enumerate() {
        let key: String = k
            .chars()
            .flat_map(|c| {
                if c == '"' || c == '\\' {
                    vec!['\\', c]
                } else {
                    vec![c]
                }
            })
            .collect();
        out += &format!(
            "{}\n    \"{key}\": {}",
            if i == 0 { "" } else { "," },
            num(*v)
        );
    }
    out += "\n  }\n}\n";
    out
}
