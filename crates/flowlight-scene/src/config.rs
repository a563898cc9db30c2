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
//! [plugins]
//! search_paths = ["../my-plugins"]
//! [environment]       # optional light from infinitely far away (docs/config.md)
//! color = [0.8, 0.9, 1.0]         # constant radiance, or map = "sky.exr" / "sky.hdr"
//! strength = 1.0                  # multiplies either
//! rotation_degrees = 0.0          # turns the map about +Y
//! [materials.white]
//! diffuse = "oren-nayar"          # or "lambert"
//! sigma_degrees = 20.0
//! ```
//!
//! # Cameras
//!
//! [`RenderConfig::camera`] builds the render's camera in this order:
//!
//! 1. **A glTF camera**: `[camera] name` selects the first camera node, in traversal order,
//!    whose camera or node has that name; `[camera] index = N` the first node that places
//!    `cameras[N]` (the glTF camera index, not the node order); neither: the first camera
//!    node. A name or index that matches nothing is an error listing the scene's cameras. The
//!    other `[camera]` keys replace parts of it (position, direction, up, projection, field of
//!    view or orthographic height).
//! 2. **The config's camera**, when the file has none: `position` and `look_at` (or
//!    `forward`) are required, `up` defaults to +Y, `fov_y` to 40°; an orthographic one needs
//!    `ortho_height`.
//! 3. **An automatic camera**, when neither places one: it looks at the centre c of the
//!    scene's bounding box from the direction
//!    d = (sin 30° cos 20°, sin 20°, cos 30° cos 20°) — front (+Z, glTF's front), right (+X)
//!    and above (+Y, glTF's up) — with up +Y and fov_y 40° (or the config's `fov_y`,
//!    `projection`, `ortho_height`, `up`). The bounding sphere (centre c, radius r = half the
//!    box's diagonal) fits the frustum exactly: a pinhole at c + d·r / sin θ, θ the smaller of
//!    the vertical and horizontal half angles (a pyramid contains the circular cone of its
//!    smaller half angle); an orthographic camera at c + 2r·d with half height
//!    r / min(1, W/H). One info line says where it was put.
//!
//! The image size is always the config's (`[render] width`, `height`): `yfov` and `ymag` are
//! kept and the horizontal extent follows W/H, as glTF viewers do in a window of another
//! shape; a glTF `aspectRatio` (or `xmag/ymag`) that differs gets a warning.

use crate::error::ConfigError;
use crate::material::MaterialOverride;
use crate::scene::{CameraDesc, CameraProjection, Scene};
use flowlight_core::camera::{Camera, Projection};
use glam::Vec3;
use serde::de::{self, MapAccess, Visitor};
use serde::{Deserialize, Deserializer};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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

/// The optional `[camera]` table: which glTF camera, and the parts that replace its own
/// (module docs, "Cameras").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraOverride {
    /// Select the glTF camera whose camera or node has this name.
    pub name: Option<String>,
    /// Select glTF camera `cameras[index]`.
    pub index: Option<usize>,
    pub position: Option<Vec3>,
    pub look_at: Option<Vec3>,
    pub forward: Option<Vec3>,
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees (perspective).
    pub fov_y: Option<f32>,
    pub projection: Option<Projection>,
    /// Full height of the view in world units (orthographic).
    pub ortho_height: Option<f32>,
}

/// Vertical field of view of a camera that does not give one (the automatic camera, or a
/// config camera without `fov_y`).
pub const DEFAULT_FOV_Y_DEGREES: f32 = 40.0;
/// Azimuth of the automatic camera's direction from +Z towards +X, degrees.
pub const AUTO_AZIMUTH_DEGREES: f32 = 30.0;
/// Elevation of the automatic camera's direction above the XZ plane, degrees.
pub const AUTO_ELEVATION_DEGREES: f32 = 20.0;

/// Unit direction from the scene's centre towards the automatic camera (module docs).
pub fn auto_camera_direction() -> Vec3 {
    let (az, el) = (
        AUTO_AZIMUTH_DEGREES.to_radians(),
        AUTO_ELEVATION_DEGREES.to_radians(),
    );
    Vec3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos())
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
    pub plugin_search_paths: Vec<PathBuf>,
    pub material_overrides: BTreeMap<String, MaterialOverride>,
    /// `[environment]`, when the file has one.
    pub environment: Option<EnvironmentConfig>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    scene: String,
    #[serde(default)]
    render: RawRender,
    camera: Option<RawCamera>,
    integrator: RawIntegrator,
    #[serde(default)]
    output: RawOutput,
    #[serde(default)]
    plugins: RawPlugins,
    #[serde(default)]
    materials: BTreeMap<String, MaterialOverride>,
    environment: Option<RawEnvironment>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEnvironment {
    color: Option<[f32; 3]>,
    map: Option<String>,
    #[serde(default = "default_strength")]
    strength: f32,
    #[serde(default)]
    rotation_degrees: f32,
}

fn default_strength() -> f32 {
    1.0
}

fn default_size() -> u32 {
    512
}
fn default_tile() -> u32 {
    32
}
fn default_quality() -> String {
    "medium".into()
}
fn default_robust() -> bool {
    true
}
fn default_intersector() -> String {
    "auto".into()
}
fn default_auto() -> String {
    "auto".into()
}
fn default_precision() -> String {
    "exact".into()
}
fn default_cache_mib() -> f64 {
    DEFAULT_CACHE_MIB
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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRender {
    #[serde(default = "default_size")]
    width: u32,
    #[serde(default = "default_size")]
    height: u32,
    spp: Option<u32>,
    time: Option<f64>,
    #[serde(default)]
    seed: u64,
    #[serde(default)]
    threads: usize,
    #[serde(default = "default_tile")]
    tile_size: u32,
    #[serde(default = "default_intersector")]
    intersector: String,
    #[serde(default = "default_quality")]
    build_quality: String,
    #[serde(default = "default_robust")]
    robust: bool,
    #[serde(default = "default_auto")]
    accumulation: String,
    #[serde(default = "default_precision")]
    precision: String,
    #[serde(default = "default_cache_mib")]
    accumulation_cache_mib: f64,
    flange: Option<toml::Value>,
}

impl Default for RawRender {
    fn default() -> Self {
        RawRender {
            width: default_size(),
            height: default_size(),
            spp: None,
            time: None,
            seed: 0,
            threads: 0,
            tile_size: default_tile(),
            intersector: default_intersector(),
            build_quality: default_quality(),
            robust: default_robust(),
            accumulation: default_auto(),
            precision: default_precision(),
            accumulation_cache_mib: default_cache_mib(),
            flange: None,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    name: Option<String>,
    index: Option<usize>,
    projection: Option<String>,
    ortho_height: Option<f32>,
    position: Option<[f32; 3]>,
    look_at: Option<[f32; 3]>,
    forward: Option<[f32; 3]>,
    up: Option<[f32; 3]>,
    fov_y: Option<f32>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    exr: Option<String>,
    png: Option<String>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawPlugins {
    #[serde(default)]
    search_paths: Vec<String>,
}

/// `[integrator]`: `plugin` plus free parameters, kept in file order (the toml crate's map is
/// sorted, so the order is recovered from each key's position in the file).
struct RawIntegrator {
    plugin: String,
    params: Vec<(String, toml::Value)>,
}

impl<'de> Deserialize<'de> for RawIntegrator {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = RawIntegrator;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an [integrator] table with a `plugin` key")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<RawIntegrator, A::Error> {
                let mut plugin = None;
                let mut params: Vec<(usize, String, toml::Value)> = Vec::new();
                while let Some(key) = map.next_key::<toml::Spanned<String>>()? {
                    let at = key.span().start;
                    let key = key.into_inner();
                    if key == "plugin" {
                        plugin = Some(map.next_value::<String>()?);
                    } else {
                        params.push((at, key, map.next_value::<toml::Value>()?));
                    }
                }
                params.sort_by_key(|p| p.0);
                Ok(RawIntegrator {
                    plugin: plugin.ok_or_else(|| de::Error::missing_field("plugin"))?,
                    params: params.into_iter().map(|(_, k, v)| (k, v)).collect(),
                })
            }
        }
        d.deserialize_map(V)
    }
}

/// Line (1-based) and dotted key that a toml error's span points at.
fn locate(text: &str, err: &toml::de::Error) -> (usize, String) {
    let msg = err.message();
    let quoted = |prefix: &str| {
        msg.find(prefix).and_then(|i| {
            let rest = &msg[i + prefix.len()..];
            rest.find('`').map(|j| rest[..j].to_string())
        })
    };
    let Some(span) = err.span() else {
        return (0, quoted("field `").unwrap_or_default());
    };
    let start = span.start.min(text.len());
    let line_no = text[..start].matches('\n').count() + 1;
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next().unwrap_or("").trim();
    let header_of = |l: &str| -> Option<String> {
        let l = l.trim();
        l.strip_prefix('[')
            .and_then(|h| h.split(']').next())
            .map(|h| h.trim_matches('[').trim().to_string())
    };
    let join = |t: Option<String>, k: String| match t {
        Some(t) if t == k || t.ends_with(&format!(".{k}")) => t,
        Some(t) => format!("{t}.{k}"),
        None => k,
    };
    let whole_document = span.start == 0 && span.end >= text.trim_end().len();
    let key = if let Some(header) = header_of(line) {
        // The error is about a table: the table itself, or a key missing from it.
        match (quoted("unknown field `"), quoted("missing field `")) {
            (Some(k), _) => join(Some(header), k),
            (None, Some(k)) if whole_document => k,
            (None, Some(k)) => join(Some(header), k),
            (None, None) => header,
        }
    } else {
        let table = text[..line_start].lines().filter_map(header_of).next_back();
        let own = quoted("unknown field `")
            .or_else(|| quoted("missing field `"))
            .or_else(|| {
                line.split_once('=')
                    .map(|(k, _)| k.trim().trim_matches('"').to_string())
            })
            .unwrap_or_default();
        join(table, own)
    };
    (line_no, key)
}

/// The toml crate's message on one line (its `Display` adds a multi-line excerpt of the
/// file; the line number is already in [`ConfigError::Parse`]).
fn one_line(msg: &str) -> String {
    msg.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Parses `text` as the config at `path` (used for messages and to resolve relative paths).
pub fn parse_config(path: &Path, text: &str) -> Result<RenderConfig, ConfigError> {
    let file = path.to_path_buf();
    let raw: RawConfig = toml::from_str(text).map_err(|e| {
        let (line, key) = locate(text, &e);
        ConfigError::Parse {
            file: file.clone(),
            line,
            key,
            message: one_line(e.message()),
        }
    })?;
    let invalid = |key: &str, reason: String| ConfigError::Invalid {
        file: file.clone(),
        key: key.into(),
        reason,
    };
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let base_dir = abs.parent().map(Path::to_path_buf).unwrap_or_default();
    let resolve = |p: &str| base_dir.join(p);

    let r = &raw.render;
    if r.width == 0 {
        return Err(invalid("render.width", "must be > 0".into()));
    }
    if r.height == 0 {
        return Err(invalid("render.height", "must be > 0".into()));
    }
    if r.tile_size == 0 {
        return Err(invalid("render.tile_size", "must be > 0".into()));
    }
    let budget = match (r.spp, r.time) {
        (Some(_), Some(_)) => {
            return Err(invalid(
                "render.spp",
                "give either `spp` or `time`, not both".into(),
            ))
        }
        (Some(0), None) => return Err(invalid("render.spp", "must be > 0".into())),
        (Some(s), None) => SampleBudget::Spp(s),
        (None, Some(t)) if !(t > 0.0 && t.is_finite()) => {
            return Err(invalid(
                "render.time",
                format!("must be a positive number of seconds, got {t}"),
            ))
        }
        (None, Some(t)) => SampleBudget::Time(t),
        (None, None) => SampleBudget::Spp(16),
    };
    let intersector = match r.intersector.as_str() {
        "bvh" => Intersector::Bvh,
        "embree" => Intersector::Embree,
        "auto" => Intersector::Auto,
        other => {
            return Err(invalid(
                "render.intersector",
                format!("\"{other}\" is not one of \"bvh\", \"embree\", \"auto\""),
            ))
        }
    };
    if !matches!(r.build_quality.as_str(), "low" | "medium" | "high") {
        return Err(invalid(
            "render.build_quality",
            format!(
                "\"{}\" is not one of \"low\", \"medium\", \"high\"",
                r.build_quality
            ),
        ));
    }
    let accumulation =
        parse_accumulation(&r.accumulation).map_err(|e| invalid("render.accumulation", e))?;
    let precision = parse_precision(&r.precision).map_err(|e| invalid("render.precision", e))?;
    let accumulation_cache_mib = parse_cache_mib(r.accumulation_cache_mib)
        .map_err(|e| invalid("render.accumulation_cache_mib", e))?;
    let flange = r
        .flange
        .as_ref()
        .map(parse_flange)
        .transpose()
        .map_err(|e| invalid("render.flange", e))?;
    let camera_override = match &raw.camera {
        None => None,
        Some(c) => {
            for (key, v) in [
                ("camera.position", c.position),
                ("camera.look_at", c.look_at),
                ("camera.forward", c.forward),
                ("camera.up", c.up),
            ] {
                if v.is_some_and(|v| !v.iter().all(|x| x.is_finite())) {
                    return Err(invalid(key, "must be finite".into()));
                }
            }
            if c.look_at.is_some() && c.forward.is_some() {
                return Err(invalid(
                    "camera.forward",
                    "give either `look_at` or `forward`, not both".into(),
                ));
            }
            // In f64: the squared length of [0, 0, 1e-30] underflows f32 to 0.
            if c.forward
                .is_some_and(|f| Vec3::from_array(f).as_dvec3().length_squared() == 0.0)
            {
                return Err(invalid("camera.forward", "must not be zero".into()));
            }
            if c.up
                .is_some_and(|u| Vec3::from_array(u).length_squared() == 0.0)
            {
                return Err(invalid("camera.up", "must not be zero".into()));
            }
            if let Some(f) = c.fov_y {
                if !(f > 0.0 && f < 180.0) {
                    return Err(invalid(
                        "camera.fov_y",
                        format!("{f} is not in (0, 180) degrees"),
                    ));
                }
            }
            if c.name.is_some() && c.index.is_some() {
                return Err(invalid(
                    "camera.index",
                    "give either `name` or `index`, not both".into(),
                ));
            }
            let projection = match c.projection.as_deref() {
                None => None,
                Some("perspective") => Some(Projection::Perspective),
                Some("orthographic") => Some(Projection::Orthographic),
                Some(other) => {
                    return Err(invalid(
                        "camera.projection",
                        format!("\"{other}\" is not one of \"perspective\", \"orthographic\""),
                    ))
                }
            };
            if let Some(h) = c.ortho_height {
                if !(h > 0.0 && h.is_finite()) {
                    return Err(invalid(
                        "camera.ortho_height",
                        format!("{h} is not a positive height in world units"),
                    ));
                }
            }
            match projection {
                Some(Projection::Orthographic) if c.fov_y.is_some() => {
                    return Err(invalid(
                        "camera.fov_y",
                        "is for perspective cameras; an orthographic one takes `ortho_height`"
                            .into(),
                    ))
                }
                Some(Projection::Perspective) if c.ortho_height.is_some() => {
                    return Err(invalid(
                        "camera.ortho_height",
                        "is for orthographic cameras; a perspective one takes `fov_y`".into(),
                    ))
                }
                _ => {}
            }
            Some(CameraOverride {
                name: c.name.clone(),
                index: c.index,
                projection,
                ortho_height: c.ortho_height,
                position: c.position.map(Vec3::from_array),
                look_at: c.look_at.map(Vec3::from_array),
                forward: c.forward.map(Vec3::from_array),
                up: c.up.map(Vec3::from_array),
                fov_y: c.fov_y,
            })
        }
    };
    if raw.integrator.plugin.trim().is_empty() {
        return Err(invalid("integrator.plugin", "must not be empty".into()));
    }
    for (name, o) in &raw.materials {
        o.validate()
            .map_err(|e| invalid(&format!("materials.{name}"), e))?;
    }
    let environment = match &raw.environment {
        None => None,
        Some(e) => {
            if !(e.strength >= 0.0 && e.strength.is_finite()) {
                return Err(invalid(
                    "environment.strength",
                    format!("must be a finite number ≥ 0, got {}", e.strength),
                ));
            }
            if !e.rotation_degrees.is_finite() {
                return Err(invalid(
                    "environment.rotation_degrees",
                    "must be finite".into(),
                ));
            }
            match (&e.color, &e.map) {
                (Some(_), Some(_)) => {
                    return Err(invalid(
                        "environment.map",
                        "give either `color` or `map`, not both".into(),
                    ))
                }
                (None, None) => {
                    return Err(invalid(
                        "environment",
                        "needs `color = [r, g, b]` or `map = \"file.exr\"`".into(),
                    ))
                }
                (Some(c), None) if !c.iter().all(|x| *x >= 0.0 && x.is_finite()) => {
                    return Err(invalid(
                        "environment.color",
                        format!("{c:?} must be finite and non-negative"),
                    ))
                }
                (None, Some(m)) => {
                    let ext = Path::new(m)
                        .extension()
                        .map(|x| x.to_string_lossy().to_ascii_lowercase());
                    if !matches!(ext.as_deref(), Some("exr" | "hdr")) {
                        return Err(invalid(
                            "environment.map",
                            format!("\"{m}\" is neither an .exr nor an .hdr file"),
                        ));
                    }
                }
                _ => {}
            }
            Some(EnvironmentConfig {
                color: e.color,
                map: e.map.as_deref().map(resolve),
                strength: e.strength,
                rotation_degrees: e.rotation_degrees,
            })
        }
    };
    let stem = path
        .file_stem()
        .map_or_else(|| "render".into(), |s| s.to_string_lossy().into_owned());
    let output_exr = resolve(raw.output.exr.as_deref().unwrap_or(&format!("{stem}.exr")));
    Ok(RenderConfig {
        path: abs.clone(),
        scene: resolve(&raw.scene),
        width: r.width,
        height: r.height,
        budget,
        seed: r.seed,
        threads: r.threads,
        tile_size: r.tile_size,
        intersector,
        build_quality: r.build_quality.clone(),
        robust: r.robust,
        accumulation,
        precision,
        accumulation_cache_mib,
        flange,
        camera_override,
        integrator_plugin: raw.integrator.plugin,
        integrator_params: raw.integrator.params,
        output_exr,
        output_png: raw.output.png.as_deref().map(resolve),
        plugin_search_paths: raw
            .plugins
            .search_paths
            .iter()
            .map(|p| resolve(p))
            .collect(),
        material_overrides: raw.materials,
        environment,
        base_dir,
    })
}

/// Reads and validates the config file at `path`.
pub fn load_config(path: &Path) -> Result<RenderConfig, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
        file: path.to_path_buf(),
        source,
    })?;
    parse_config(path, &text)
}

impl RenderConfig {
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

    /// The camera at this config's resolution (module docs, "Cameras"): the selected glTF
    /// camera with the `[camera]` keys replacing its parts, else the config's camera, else an
    /// automatic one framing the scene.
    pub fn camera(&self, scene: &Scene) -> Result<Camera, ConfigError> {
        let o = self.camera_override.clone().unwrap_or_default();
        let invalid = |key: &str, reason: String| ConfigError::Invalid {
            file: self.path.clone(),
            key: format!("camera.{key}"),
            reason,
        };
        let g = self.select_camera(scene, &o)?;
        let places = o.position.is_some() || o.look_at.is_some() || o.forward.is_some();
        if g.is_none() && !places {
            return Ok(self.auto_camera(scene, &o));
        }
        let missing = |key: &str| {
            invalid(
                key,
                "required: the scene has no camera to take it from".into(),
            )
        };
        let position = o
            .position
            .or(g.map(|g| g.position))
            .ok_or_else(|| missing("position"))?;
        let (forward, key) = match (o.look_at, o.forward) {
            (Some(l), _) => (l.as_dvec3() - position.as_dvec3(), "look_at"),
            (None, Some(f)) => (f.as_dvec3(), "forward"),
            (None, None) => (
                g.map(|g| g.forward)
                    .ok_or_else(|| missing("look_at"))?
                    .as_dvec3(),
                "look_at",
            ),
        };
        let up = o.up.or(g.map(|g| g.up)).unwrap_or(Vec3::Y);
        // Normalised in f64: a direction such as [0, 0, 1e30] overflows f32's squared length.
        let f = forward.normalize_or_zero().as_vec3();
        if f == Vec3::ZERO {
            return Err(invalid(
                key,
                if key == "forward" {
                    "has no direction (too short)".into()
                } else {
                    "the camera looks at its own position".into()
                },
            ));
        }
        if f.cross(up.normalize_or_zero()).length_squared() < 1e-12 {
            return Err(invalid("up", "is parallel to the viewing direction".into()));
        }
        let from_file = g.map(|g| g.projection);
        let projection = o.projection.unwrap_or(match from_file {
            Some(CameraProjection::Orthographic { .. }) => Projection::Orthographic,
            _ => Projection::Perspective,
        });
        if let Some(a) = g.and_then(|g| g.aspect) {
            let ours = self.width as f32 / self.height as f32;
            if (a - ours).abs() > 1e-3 * ours {
                tracing::warn!(file = %self.path.display(), "the glTF camera's aspect ratio {a} differs from the image's {ours}; the image's is used (the vertical extent is kept)");
            }
        }
        match projection {
            Projection::Perspective => {
                if o.ortho_height.is_some() {
                    return Err(invalid(
                        "ortho_height",
                        "the camera is perspective: give `projection = \"orthographic\"` too, or use `fov_y`".into(),
                    ));
                }
                let fov = o
                    .fov_y
                    .or(match from_file {
                        Some(CameraProjection::Perspective { fov_y_degrees }) => {
                            Some(fov_y_degrees)
                        }
                        _ => None,
                    })
                    .unwrap_or(DEFAULT_FOV_Y_DEGREES);
                Ok(Camera::look_along(
                    position,
                    f,
                    up,
                    fov,
                    self.width,
                    self.height,
                ))
            }
            Projection::Orthographic => {
                if o.fov_y.is_some() {
                    return Err(invalid(
                        "fov_y",
                        "the camera is orthographic: use `ortho_height`".into(),
                    ));
                }
                let half_height = match (o.ortho_height, from_file) {
                    (Some(h), _) => 0.5 * h,
                    (None, Some(CameraProjection::Orthographic { half_height })) => half_height,
                    _ => {
                        return Err(invalid(
                            "ortho_height",
                            "required for an orthographic camera that the file does not give"
                                .into(),
                        ))
                    }
                };
                Ok(Camera::orthographic(
                    position,
                    f,
                    up,
                    half_height,
                    self.width,
                    self.height,
                ))
            }
        }
    }

    /// The glTF camera that `[camera] name` / `index` selects, else the first camera node.
    fn select_camera<'s>(
        &self,
        scene: &'s Scene,
        o: &CameraOverride,
    ) -> Result<Option<&'s CameraDesc>, ConfigError> {
        let not_found = |key: &str, what: String| ConfigError::Invalid {
            file: self.path.clone(),
            key: format!("camera.{key}"),
            reason: format!("{what}; {}", list_cameras(&scene.cameras)),
        };
        if let Some(name) = &o.name {
            let found = scene.cameras.iter().find(|c| {
                c.name.as_deref() == Some(name.as_str())
                    || c.node_name.as_deref() == Some(name.as_str())
            });
            return found.map(Some).ok_or_else(|| {
                not_found(
                    "name",
                    format!("no camera or camera node is named \"{name}\""),
                )
            });
        }
        if let Some(index) = o.index {
            let found = scene.cameras.iter().find(|c| c.index == index);
            return found.map(Some).ok_or_else(|| {
                not_found(
                    "index",
                    format!("no node of the scene places cameras[{index}]"),
                )
            });
        }
        Ok(scene.cameras.first())
    }

    /// The automatic camera (module docs), with the config's projection keys and `up`.
    fn auto_camera(&self, scene: &Scene, o: &CameraOverride) -> Camera {
        let (centre, radius) = match scene.bounds() {
            Some((lo, hi)) => (0.5 * (lo + hi), 0.5 * (hi - lo).length()),
            None => (Vec3::ZERO, 1.0),
        };
        let radius = if radius > 0.0 && radius.is_finite() {
            radius
        } else {
            1.0
        };
        let d = auto_camera_direction();
        let up = o.up.unwrap_or(Vec3::Y);
        let aspect = self.width as f32 / self.height as f32;
        let cam = match o.projection.unwrap_or(Projection::Perspective) {
            Projection::Perspective => {
                let fov = o.fov_y.unwrap_or(DEFAULT_FOV_Y_DEGREES);
                let tan_y = (0.5 * fov.to_radians()).tan();
                let half_angle = tan_y.atan().min((aspect * tan_y).atan());
                let position = centre + d * (radius / half_angle.sin());
                Camera::look_along(position, -d, up, fov, self.width, self.height)
            }
            Projection::Orthographic => {
                let half_height = o.ortho_height.map_or(radius / aspect.min(1.0), |h| 0.5 * h);
                let position = centre + d * (2.0 * radius);
                Camera::orthographic(position, -d, up, half_height, self.width, self.height)
            }
        };
        let p = cam.position;
        tracing::info!(
            file = %self.path.display(),
            "no camera in the scene or the config: an automatic {} camera at ({:.4}, {:.4}, {:.4}) looks at the bounding box centre ({:.4}, {:.4}, {:.4}) from the front-right-above and frames its bounding sphere (radius {:.4})",
            cam.kind().name(),
            p.x, p.y, p.z, centre.x, centre.y, centre.z, radius
        );
        cam
    }
}

/// `the scene's cameras: 0 "Main" (node 2 "Cam", perspective), …` for error messages.
fn list_cameras(cameras: &[CameraDesc]) -> String {
    if cameras.is_empty() {
        return "the scene has no cameras".into();
    }
    let all: Vec<String> = cameras.iter().map(CameraDesc::label).collect();
    format!("the scene's cameras: {}", all.join(", "))
}
