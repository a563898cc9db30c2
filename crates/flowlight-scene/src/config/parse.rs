//! Reading the TOML file: serde's raw tables (unknown keys refused, the integrator's
//! parameters kept in file order), the toml error located to a line and a dotted key, then
//! every value checked and every relative path resolved against the config's folder.

use super::{
    parse_accumulation, parse_cache_mib, parse_flange, parse_precision, CameraOverride,
    EnvironmentConfig, Intersector, RenderConfig, SampleBudget, DEFAULT_CACHE_MIB,
};
use crate::error::ConfigError;
use crate::material::MaterialOverride;
use flowlight_core::camera::Projection;
use glam::Vec3;
use serde::de::{self, MapAccess, Visitor};
use serde::{Deserialize, Deserializer};
use std::collections::BTreeMap;
use std::path::Path;

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
    #[serde(default)]
    textures: RawTextures,
}

/// `[textures]`.
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawTextures {
    missing: Option<String>,
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
    #[serde(default)]
    multiscatter: bool,
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
            multiscatter: false,
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
    aperture_radius: Option<f32>,
    f_number: Option<f32>,
    sensor_height_mm: Option<f32>,
    focus_distance: Option<f32>,
    focus_on: Option<String>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    exr: Option<String>,
    png: Option<String>,
    #[serde(default)]
    aovs: Vec<String>,
    aov_spp: Option<u32>,
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
    let render = check_render(r, &invalid)?;
    let camera_override = raw
        .camera
        .as_ref()
        .map(|c| camera_override(c, &invalid))
        .transpose()?;
    if raw.integrator.plugin.trim().is_empty() {
        return Err(invalid("integrator.plugin", "must not be empty".into()));
    }
    for (name, o) in &raw.materials {
        o.validate()
            .map_err(|e| invalid(&format!("materials.{name}"), e))?;
    }
    let environment = raw
        .environment
        .as_ref()
        .map(|e| environment(e, &invalid, &resolve))
        .transpose()?;
    let missing_textures = match raw.textures.missing.as_deref() {
        None => crate::load_options::MissingTextures::Error,
        Some(v) => crate::load_options::MissingTextures::parse(v)
            .map_err(|e| invalid("textures.missing", e))?,
    };
    let stem = path
        .file_stem()
        .map_or_else(|| "render".into(), |s| s.to_string_lossy().into_owned());
    let aovs = super::aovs::parse_aovs(&raw.output.aovs).map_err(|e| invalid("output.aovs", e))?;
    let aov_spp = raw.output.aov_spp.unwrap_or(super::DEFAULT_AOV_SPP);
    if aov_spp == 0 {
        return Err(invalid("output.aov_spp", "must be at least 1".into()));
    }
    let output_exr = resolve(raw.output.exr.as_deref().unwrap_or(&format!("{stem}.exr")));
    Ok(RenderConfig {
        path: abs.clone(),
        scene: resolve(&raw.scene),
        width: r.width,
        height: r.height,
        budget: render.budget,
        seed: r.seed,
        threads: r.threads,
        tile_size: r.tile_size,
        intersector: render.intersector,
        build_quality: r.build_quality.clone(),
        robust: r.robust,
        accumulation: render.accumulation,
        precision: render.precision,
        accumulation_cache_mib: render.accumulation_cache_mib,
        flange: render.flange,
        camera_override,
        integrator_plugin: raw.integrator.plugin,
        integrator_params: raw.integrator.params,
        output_exr,
        output_png: raw.output.png.as_deref().map(resolve),
        aovs,
        aov_spp,
        plugin_search_paths: raw
            .plugins
            .search_paths
            .iter()
            .map(|p| resolve(p))
            .collect(),
        material_overrides: raw.materials,
        environment,
        missing_textures,
        multiscatter: r.multiscatter,
        base_dir,
    })
}

/// The `[render]` values that need more than a copy, checked.
struct RenderSettings {
    budget: SampleBudget,
    intersector: Intersector,
    accumulation: super::Accumulation,
    precision: super::FramePrecision,
    accumulation_cache_mib: f64,
    flange: Option<u32>,
}

/// Checks `[render]`: positive sizes, one budget (`spp` or `time`), known names.
fn check_render(
    r: &RawRender,
    invalid: &impl Fn(&str, String) -> ConfigError,
) -> Result<RenderSettings, ConfigError> {
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
    Ok(RenderSettings {
        budget,
        intersector,
        accumulation,
        precision,
        accumulation_cache_mib,
        flange,
    })
}

/// Checks `[camera]`: finite vectors, no zero direction, one of each exclusive pair
/// (`look_at`/`forward`, `name`/`index`), and the projection's own keys only.
fn camera_override(
    c: &RawCamera,
    invalid: &impl Fn(&str, String) -> ConfigError,
) -> Result<CameraOverride, ConfigError> {
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
    if c.forward
        // In f64: the squared length of [0, 0, 1e-30] underflows f32 to 0.
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
                "is for perspective cameras; an orthographic one takes `ortho_height`".into(),
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
    let lens = super::lens::lens_keys(
        super::lens::RawLens {
            aperture_radius: c.aperture_radius,
            f_number: c.f_number,
            sensor_height_mm: c.sensor_height_mm,
            focus_distance: c.focus_distance,
            focus_on: c.focus_on.clone(),
        },
        projection,
        invalid,
    )?;
    Ok(CameraOverride {
        lens,
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

/// Checks `[environment]`: a finite strength ≥ 0 and rotation, and either a non-negative
/// colour or an `.exr`/`.hdr` map (resolved against the config's folder).
fn environment(
    e: &RawEnvironment,
    invalid: &impl Fn(&str, String) -> ConfigError,
    resolve: &impl Fn(&str) -> std::path::PathBuf,
) -> Result<EnvironmentConfig, ConfigError> {
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
    Ok(EnvironmentConfig {
        color: e.color,
        map: e.map.as_deref().map(resolve),
        strength: e.strength,
        rotation_degrees: e.rotation_degrees,
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
