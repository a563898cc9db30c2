//! The suite file (`docs/bench.md`): scenes, methods, budgets and seeds, validated with one
//! clear line per mistake.

use crate::run::Budget;
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSuite {
    bench: RawBench,
    #[serde(default)]
    reference: RawReference,
    #[serde(default)]
    scene: Vec<RawScene>,
    #[serde(default)]
    method: Vec<RawMethod>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBench {
    budgets: Vec<f64>,
    #[serde(default = "default_seeds")]
    seeds: Vec<u64>,
    #[serde(default)]
    threads: usize,
    width: Option<u32>,
    height: Option<u32>,
    #[serde(default = "default_out")]
    out: String,
    baseline: Option<String>,
    floor_ratio: Option<f64>,
}

fn default_seeds() -> Vec<u64> {
    vec![1, 2, 3]
}
fn default_out() -> String {
    "bench-results".into()
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawReference {
    spp: Option<u32>,
    time: Option<f64>,
    seed: Option<u64>,
    plugin: Option<String>,
    #[serde(default)]
    params: toml::Table,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: String,
    config: String,
    reference: Option<String>,
    reference_spp: Option<u32>,
    width: Option<u32>,
    height: Option<u32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMethod {
    label: String,
    plugin: Option<String>,
    #[serde(default)]
    params: toml::Table,
    scenes: Option<Vec<String>>,
    config: Option<String>,
}

/// A scene of a suite.
#[derive(Clone, Debug)]
pub struct SuiteScene {
    pub name: String,
    pub config: PathBuf,
    /// The suite's reference file: `reference` when given, else the cache
    /// `<out>/references/<name>.exr` (rendered when missing).
    pub reference: PathBuf,
    /// The committed reference `<config folder>/reference/<config stem>.exr`, used instead
    /// of [`SuiteScene::reference`] when it exists (`None` when the scene names its own).
    pub committed_reference: Option<PathBuf>,
    pub reference_budget: Budget,
    pub width: Option<u32>,
    pub height: Option<u32>,
}

/// A method: an integrator plugin with parameters, under a label.
#[derive(Clone, Debug)]
pub struct Method {
    pub label: String,
    pub plugin: Option<String>,
    pub params: Vec<(String, toml::Value)>,
    /// Scene names it runs on (`None`: all).
    pub scenes: Option<Vec<String>>,
    /// A config file name (`config = "erpt.toml"`): the method renders each scene's own
    /// config of that name, found beside the scene's config, with `params` over it; scenes
    /// without one are skipped. How a suite compares every scene's hand-tuned configuration
    /// in one row.
    pub config: Option<String>,
}

impl Method {
    /// Whether the method renders `scene`: named by `scenes` (or no list), and, for a
    /// method with a `config`, that scene has such a file.
    pub fn runs_on(&self, scene: &SuiteScene) -> bool {
        let named = self.scenes.as_ref().is_none_or(|s| s.contains(&scene.name));
        named && self.config_for(scene).is_none_or(|c| c.is_file())
    }

    /// The config the method renders `scene` with when it names its own
    /// ([`Method::config`]): that file beside the scene's config.
    pub fn config_for(&self, scene: &SuiteScene) -> Option<PathBuf> {
        let name = self.config.as_ref()?;
        Some(scene.config.with_file_name(name))
    }
}

/// A parsed suite file with absolute paths.
#[derive(Clone, Debug)]
pub struct Suite {
    pub path: PathBuf,
    pub budgets: Vec<f64>,
    pub seeds: Vec<u64>,
    pub threads: usize,
    pub out: PathBuf,
    pub baseline: String,
    /// The floor rule's bound: a reference floor above `floor_ratio` × the smallest relMSE
    /// reported against it refuses the comparison (default 0.1).
    pub floor_ratio: f64,
    pub reference_seed: u64,
    pub reference_plugin: Option<String>,
    pub reference_params: Vec<(String, toml::Value)>,
    pub scenes: Vec<SuiteScene>,
    pub methods: Vec<Method>,
}

fn table_pairs(t: toml::Table) -> Vec<(String, toml::Value)> {
    t.into_iter().collect()
}

/// Parses a suite file (see `docs/bench.md`). Relative paths are relative to its folder.
pub fn load_suite(path: &Path) -> Result<Suite, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    parse_suite(path, &text)
}

/// [`load_suite`] from text.
pub fn parse_suite(path: &Path, text: &str) -> Result<Suite, String> {
    let err = |m: String| format!("{}: {m}", path.display());
    let raw: RawSuite = toml::from_str(text).map_err(|e| err(e.to_string().trim().to_string()))?;
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let base = abs.parent().map(Path::to_path_buf).unwrap_or_default();
    let b = raw.bench;
    if b.budgets.is_empty() || b.budgets.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
        return Err(err(
            "bench.budgets must be a non-empty list of positive seconds".into(),
        ));
    }
    if b.seeds.is_empty() {
        return Err(err("bench.seeds must not be empty".into()));
    }
    if raw.scene.is_empty() || raw.method.is_empty() {
        return Err(err(
            "a suite needs at least one [[scene]] and one [[method]]".into(),
        ));
    }
    let out = base.join(&b.out);
    let ref_budget = match (raw.reference.spp, raw.reference.time) {
        (Some(_), Some(_)) => return Err(err("reference: give spp or time, not both".into())),
        (_, Some(t)) if t > 0.0 && t.is_finite() => Budget::Time(t),
        (_, Some(t)) => return Err(err(format!("reference.time must be positive, got {t}"))),
        (Some(n), None) => Budget::Spp(n),
        (None, None) => Budget::Spp(1024),
    };
    let mut names = std::collections::HashSet::new();
    let mut scenes = Vec::new();
    for s in raw.scene {
        if !names.insert(s.name.clone()) {
            return Err(err(format!("scene '{}' appears twice", s.name)));
        }
        if s.name.is_empty() || s.name.contains(['/', '\\', ',']) {
            return Err(err(format!(
                "scene name '{}' must be non-empty, without '/', '\\' or ','",
                s.name
            )));
        }
        let reference = match &s.reference {
            Some(r) => base.join(r),
            None => out.join("references").join(format!("{}.exr", s.name)),
        };
        let config = base.join(&s.config);
        let committed_reference = match &s.reference {
            Some(_) => None,
            None => config.parent().zip(config.file_stem()).map(|(dir, stem)| {
                dir.join("reference")
                    .join(format!("{}.exr", stem.to_string_lossy()))
            }),
        };
        scenes.push(SuiteScene {
            reference,
            committed_reference,
            config,
            reference_budget: s.reference_spp.map(Budget::Spp).unwrap_or(ref_budget),
            width: s.width.or(b.width),
            height: s.height.or(b.height),
            name: s.name,
        });
    }
    let mut labels = std::collections::HashSet::new();
    let mut methods = Vec::new();
    for m in raw.method {
        if !labels.insert(m.label.clone()) || m.label.is_empty() || m.label.contains(',') {
            return Err(err(format!(
                "method label '{}' is empty, has a ',' or appears twice",
                m.label
            )));
        }
        if let Some(list) = &m.scenes {
            if let Some(bad) = list.iter().find(|n| !names.contains(*n)) {
                return Err(err(format!(
                    "method '{}' names unknown scene '{bad}'",
                    m.label
                )));
            }
        }
        methods.push(Method {
            label: m.label,
            plugin: m.plugin,
            params: table_pairs(m.params),
            scenes: m.scenes,
            config: m.config,
        });
    }
    let baseline = match b.baseline {
        Some(l) if labels.contains(&l) => l,
        Some(l) => return Err(err(format!("bench.baseline '{l}' is not a method label"))),
        None => methods
            .iter()
            .find(|m| m.plugin.as_deref().unwrap_or("mcpt") == "mcpt")
            .unwrap_or(&methods[0])
            .label
            .clone(),
    };
    let floor_ratio = b.floor_ratio.unwrap_or(0.1);
    if !(floor_ratio > 0.0 && floor_ratio.is_finite()) {
        return Err(err(format!(
            "bench.floor_ratio must be a positive number, got {floor_ratio}"
        )));
    }
    // The reference's lighting layers are asked for when it renders, through the plugin's
    // parameter of role `Layers` (`run::ensure_reference`).
    let reference_params = table_pairs(raw.reference.params);
    Ok(Suite {
        path: abs,
        budgets: b.budgets,
        seeds: b.seeds,
        threads: b.threads,
        out,
        baseline,
        floor_ratio,
        reference_seed: raw.reference.seed.unwrap_or(1_000_000),
        reference_plugin: raw.reference.plugin,
        reference_params,
        scenes,
        methods,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suite_parses_and_validates() {
        let p = Path::new("/tmp/suite.toml");
        let text = r#"
[bench]
budgets = [0.5, 1.0]
seeds = [1, 2]
out = "out"
[reference]
spp = 64
[[scene]]
name = "a"
config = "a/a.toml"
[[scene]]
name = "b"
config = "b/b.toml"
reference = "b/ref.exr"
reference_spp = 16
[[method]]
label = "pt"
params = { variant = "entangled" }
[[method]]
label = "erpt"
plugin = "erpt"
params = { mutations = "lens" }
scenes = ["b"]
"#;
        let s = parse_suite(p, text).unwrap();
        assert_eq!(s.baseline, "pt");
        assert_eq!(
            s.scenes[0].reference,
            Path::new("/tmp/out/references/a.exr")
        );
        assert_eq!(s.scenes[0].reference_budget, Budget::Spp(64));
        assert_eq!(s.scenes[1].reference_budget, Budget::Spp(16));
        assert!(!s.methods[1].runs_on(&s.scenes[0]));
        assert_eq!(s.methods[1].plugin.as_deref(), Some("erpt"));
        for bad in [
            text.replace("budgets = [0.5, 1.0]", "budgets = []"),
            text.replace("scenes = [\"b\"]", "scenes = [\"c\"]"),
            text.replace("label = \"erpt\"", "label = \"pt\""),
            text.replace("[bench]", "[bench]\nbaseline = \"nope\""),
            text.replace("seeds = [1, 2]", "seedz = [1]"),
            text.replace("[bench]", "[bench]\nfloor_ratio = 0.0"),
        ] {
            assert!(parse_suite(p, &bad).is_err(), "accepted:\n{bad}");
        }
    }

    /// A method with `config` renders each scene's file of that name and skips the scenes
    /// that have none.
    #[test]
    fn method_config_is_found_beside_each_scene() {
        let dir = std::env::temp_dir().join(format!("flowlight-suite-{}", std::process::id()));
        for scene in ["a", "b"] {
            std::fs::create_dir_all(dir.join(scene)).unwrap();
        }
        std::fs::write(dir.join("b/tuned.toml"), "").unwrap();
        let text = r#"
[bench]
budgets = [1.0]
seeds = [1]
[[scene]]
name = "a"
config = "a/a.toml"
[[scene]]
name = "b"
config = "b/b.toml"
[[method]]
label = "pt"
[[method]]
label = "tuned"
config = "tuned.toml"
"#;
        let s = parse_suite(&dir.join("suite.toml"), text).unwrap();
        let tuned = &s.methods[1];
        assert!(!tuned.runs_on(&s.scenes[0]));
        assert!(tuned.runs_on(&s.scenes[1]));
        assert_eq!(
            tuned.config_for(&s.scenes[1]),
            Some(dir.join("b/tuned.toml"))
        );
        assert!(s.methods[0].runs_on(&s.scenes[0]));
        assert_eq!(s.methods[0].config_for(&s.scenes[0]), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
