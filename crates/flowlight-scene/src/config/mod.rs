//! The TOML render configuration.
//!
//! Every relative path in the file (`scene`, `[output]`, `[plugins] search_paths`) is relative
//! to the folder of the config file, not to the current directory; [`load_config`] resolves
//! them to absolute paths. Unknown keys are errors everywhere except among the integrator's
//! parameters, which belong to the plugin and are kept in file order.
//!
//! ```toml
//! scene = "cornell-box.gltf"
//! [render]
//! width = 512
//! height = 512
//! spp = 64            # or time = 30.0 (seconds); not both; default spp = 16
//! seed = 1
//! threads = 0         # 0 = all cores
//! tile_size = 32
//! intersector = "bvh" # "bvh" | "embree" | "auto" (default "auto")
//! build_quality = "medium"  # Embree BVH quality: "low" | "medium" | "high" (large scenes)
//! robust = true       # Embree robust mode (rays on shared edges do not slip through)
//! accumulation = "auto"   # "blasting" | "buffering" | "caching" | "auto" (docs/config.md)
//! precision = "exact"     # frame sums: "exact" (fixed point) | "f32" (a quarter the memory)
//! accumulation_cache_mib = 16.0   # Caching: all threads' micro-tile caches together
//! flange = 16         # Blasting: pixels around a unit's tile, or "screen" (default: the integrator's)
//! multiscatter = false  # GGX multiple-scattering energy compensation (docs/config.md)
//! [camera]            # optional (see "Cameras" below)
//! name = "Camera"     # or index = 0: which glTF camera (default: the first camera node)
//! position = [0.278, 0.273, -0.8]
//! look_at = [0.278, 0.273, 0.0]   # or forward = [...]
//! up = [0.0, 1.0, 0.0]
//! fov_y = 39.3        # degrees, perspective
//! projection = "perspective"      # or "orthographic", with ortho_height = 2.0 (world units)
//! [integrator]
//! plugin = "mcpt"
//! variant = "entangled"           # every other key is a plugin parameter
//! [output]
//! exr = "cornell-box.exr"         # default: <config file stem>.exr
//! png = "cornell-box.png"         # optional sRGB preview
//! aovs = ["albedo", "normal"]     # extra EXR layers (docs/config.md, "AOVs")
//! aov_spp = 16                    # camera samples per pixel of the AOV pass
//! [plugins]
//! search_paths = ["../my-plugins"]
//! [environment]       # optional light from infinitely far away (docs/config.md)
//! color = [0.8, 0.9, 1.0]         # constant radiance, or map = "sky.exr" / "sky.hdr"
//! strength = 1.0                  # multiplies either
//! rotation_degrees = 0.0          # turns the map about +Y
//! [textures]
//! missing = "error"   # or "warn": drop a texture whose image file cannot be read
//! [materials.white]
//! diffuse = "oren-nayar"          # or "lambert"
//! sigma_degrees = 20.0
//! ```
//!
//! The file is read in [`parse`](mod@self::parse) (serde's raw tables, then every value
//! checked with a one-line error naming the key); [`cameras`] builds the render's camera from
//! the config and the scene.

use crate::error::ConfigError;
use crate::load_options::{LoadOptions, MissingTextures};
use crate::material::MaterialOverride;
use std::collections::BTreeMap;
use std::path::PathBuf;

pub mod aovs;
pub mod cameras;
pub mod lens;
pub mod parse;

pub use aovs::{Aov, DEFAULT_AOV_SPP};

pub use cameras::{
    auto_camera_direction, CameraOverride, AUTO_AZIMUTH_DEGREES, AUTO_ELEVATION_DEGREES,
    DEFAULT_FOV_Y_DEGREES,
};
pub use parse::{load_config, parse_config};

/// Which ray intersector the host should use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Intersector {
    Bvh,
    Embree,
    Auto,
}

/// `render.accumulation`: how work units feed the frame (the host's `accumulation` module).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Accumulation {
    /// The host chooses from what the integrator asks for.
    Auto,
    Blasting,
    Buffering,
    Caching,
}

/// `render.precision`: the frame's number format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FramePrecision {
    /// Fixed-point sums, bitwise reproducible.
    Exact,
    /// f32 frame fed by f64 partial sums.
    F32,
}

/// Default of `render.accumulation_cache_mib`.
pub const DEFAULT_CACHE_MIB: f64 = 16.0;

/// How long to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SampleBudget {
    /// Samples per pixel.
    Spp(u32),
    /// Seconds of rendering.
    Time(f64),
}
/// The optional `[environment]` table: a constant sky or an equirectangular map.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentConfig {
    /// Constant radiance (linear RGB), when given.
    pub color: Option<[f32; 3]>,
    /// Lat-long map (`.exr` or `.hdr`, +Y up), absolute, when given.
    pub map: Option<PathBuf>,
    pub strength: f32,
    pub rotation_degrees: f32,
}

/// A validated render configuration with absolute paths.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderConfig {
    /// The config file itself.
    pub path: PathBuf,
    /// Its folder, against which relative paths were resolved.
    pub base_dir: PathBuf,
    pub scene: PathBuf,
    pub width: u32,
    pub height: u32,
    pub budget: SampleBudget,
    pub seed: u64,
    /// Worker threads; 0 = all cores.
    pub threads: usize,
    pub tile_size: u32,
    pub intersector: Intersector,
    /// Embree build quality: "low", "medium" (default) or "high".
    pub build_quality: String,
    /// Embree robust mode (default on).
    pub robust: bool,
    pub accumulation: Accumulation,
    pub precision: FramePrecision,
    /// Caching: MiB of all threads' micro-tile caches together.
    pub accumulation_cache_mib: f64,
    /// Blasting: flange of each unit's buffer in pixels (`u32::MAX` for `"screen"`); `None`
    /// the integrator's.
    pub flange: Option<u32>,
    pub camera_override: Option<CameraOverride>,
    pub integrator_plugin: String,
    /// The integrator's parameters (every key of `[integrator]` but `plugin`), in file order.
    pub integrator_params: Vec<(String, toml::Value)>,
    pub output_exr: PathBuf,
    pub output_png: Option<PathBuf>,
    /// `[output] aovs`: the AOV layers to write, each once, in [`Aov::ALL`] order.
    pub aovs: Vec<Aov>,
    /// `[output] aov_spp`: camera samples per pixel of the AOV pass.
    pub aov_spp: u32,
    pub plugin_search_paths: Vec<PathBuf>,
    pub material_overrides: BTreeMap<String, MaterialOverride>,
    /// `[environment]`, when the file has one.
    pub environment: Option<EnvironmentConfig>,
    /// `[textures] missing`: what a texture whose image file cannot be read does.
    pub missing_textures: MissingTextures,
    /// `[render] multiscatter`: GGX multiple-scattering energy compensation (default off).
    pub multiscatter: bool,
}
/// Parses `render.accumulation`.
pub fn parse_accumulation(s: &str) -> Result<Accumulation, String> {
    Ok(match s {
        "auto" => Accumulation::Auto,
        "blasting" => Accumulation::Blasting,
        "buffering" => Accumulation::Buffering,
        "caching" => Accumulation::Caching,
        other => {
            return Err(format!(
                "\"{other}\" is not one of \"auto\", \"blasting\", \"buffering\", \"caching\""
            ))
        }
    })
}

/// Parses `render.precision`.
pub fn parse_precision(s: &str) -> Result<FramePrecision, String> {
    match s {
        "exact" => Ok(FramePrecision::Exact),
        "f32" => Ok(FramePrecision::F32),
        other => Err(format!("\"{other}\" is not one of \"exact\", \"f32\"")),
    }
}

/// Parses `render.accumulation_cache_mib`: a positive, finite number of MiB.
pub fn parse_cache_mib(v: f64) -> Result<f64, String> {
    if !(v > 0.0 && v.is_finite()) {
        Err(format!("must be a positive number of MiB, got {v}"))
    } else if v > 1.0e9 {
        Err(format!(
            "{v} MiB is beyond the limit of 1e9 MiB (about 1 PiB); the caches need only a few MiB per thread"
        ))
    } else {
        Ok(v)
    }
}

/// Parses `render.flange`: a number of pixels, or `"screen"` (the whole film).
pub fn parse_flange(v: &toml::Value) -> Result<u32, String> {
    match v {
        toml::Value::String(s) if s == "screen" => Ok(u32::MAX),
        toml::Value::Integer(n) if (0..=u32::MAX as i64).contains(n) => Ok(*n as u32),
        other => Err(format!(
            "must be a number of pixels (≥ 0) or \"screen\", got {other}"
        )),
    }
}

impl RenderConfig {
    /// Applies `--set render.KEY=VALUE` for the accumulation keys (`accumulation`,
    /// `precision`, `accumulation_cache_mib`, `flange`); `Ok(false)` for any other key.
    pub fn set_render_key(&mut self, key: &str, value: &toml::Value) -> Result<bool, ConfigError> {
        let invalid = |reason: String| ConfigError::Invalid {
            file: self.path.clone(),
            key: format!("render.{key}"),
            reason,
        };
        let text = || {
            value
                .as_str()
                .map(str::to_owned)
                .unwrap_or_else(|| value.to_string())
        };
        match key {
            "accumulation" => self.accumulation = parse_accumulation(&text()).map_err(invalid)?,
            "precision" => self.precision = parse_precision(&text()).map_err(invalid)?,
            "accumulation_cache_mib" => {
                let v = value
                    .as_float()
                    .or_else(|| value.as_integer().map(|i| i as f64))
                    .ok_or_else(|| invalid(format!("must be a number, got {value}")))?;
                self.accumulation_cache_mib = parse_cache_mib(v).map_err(invalid)?;
            }
            "flange" => self.flange = Some(parse_flange(value).map_err(invalid)?),
            _ => return Ok(false),
        }
        Ok(true)
    }
}
impl RenderConfig {
    /// What the config says about loading the scene ([`crate::load_gltf_with`]).
    pub fn load_options(&self) -> LoadOptions<'_> {
        LoadOptions {
            overrides: &self.material_overrides,
            missing_textures: self.missing_textures,
            multiscatter: self.multiscatter,
        }
    }

    /// The integrator parameter `key`, if the config sets it.
    pub fn integrator_param(&self, key: &str) -> Option<&toml::Value> {
        self.integrator_params
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v)
    }

    /// Samples per pixel, when the budget is a sample count.
    pub fn spp(&self) -> Option<u32> {
        match self.budget {
            SampleBudget::Spp(s) => Some(s),
            SampleBudget::Time(_) => None,
        }
    }
}
