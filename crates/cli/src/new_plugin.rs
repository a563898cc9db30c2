//! `flowlight new-plugin --kind integrator|mutation|raw-mutation NAME DIR`: writes a plugin
//! crate that builds outside this workspace.
//!
//! DIR gets `Cargo.toml` (a `cdylib` named `flowlight_<NAME with _>`, so the file is
//! `libflowlight_<NAME with _>.so`, with `flowlight-sdk` as its dependency — and
//! `flowlight-mcmc` for `mutation` — and an empty `[workspace]` table so that it is a
//! workspace of its own), `src/lib.rs` (a documented skeleton that works as generated: a
//! one-bounce direct-lighting integrator; a mutation made of a policy of `flowlight-mcmc`'s
//! regeneration engine, as the in-tree strategies are; or a hand-written symmetric
//! film-jitter mutation with a hard reconnection), unit tests inside it, a `README.md`, a
//! `.gitignore` and a copy of the SDK's workspace `Cargo.lock`, so that the crate's
//! dependencies resolve to the versions the host was built and tested with (without it,
//! Cargo picks the newest versions it can). It runs `rustfmt` over `src/lib.rs` when it is
//! installed. The SDK is referenced by the absolute path of this checkout's
//! `crates/flowlight-sdk` (default; `flowlight-mcmc` is its sibling), another path
//! (`--sdk-path`) or a registry version (`--sdk-version`).
//!
//! A NAME is what configs write (`plugin = "NAME"`): 1–64 characters, lowercase ASCII
//! letters, digits and single `-` between them, starting with a letter, and not a name whose
//! crate would not compile: a Rust keyword, a name whose CamelCase type clashes with the
//! standard prelude or an identifier the templates use (`scene` → `Scene`, `result` →
//! `Result`, `self` → `Self`), or the name of a Flowlight crate (`sdk` → `flowlight-sdk`).
//! DIR must not exist or be an empty folder. Templates live in `crates/cli/templates/`;
//! `__NAME__`, `__TYPE__` (NAME in CamelCase), `__CRATE__`, `__LIB__`, `__KIND__`,
//! `__SDK_DEP__` and `__USAGE__` are replaced.

use anyhow::{anyhow, Context, Result};
use std::path::{Path, PathBuf};

/// Which trait the generated plugin implements, and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind {
    /// An `Integrator` (one-bounce direct lighting).
    Integrator,
    /// A mutation on `flowlight-mcmc`'s regeneration engine (a `Strategy` and its policy).
    Mutation,
    /// A `Mutation` written by hand (film jitter with a hard reconnection).
    RawMutation,
}

/// The lib.rs templates: every identifier in them is one a generated type must not be named.
const TEMPLATES: [&str; 3] = [
    include_str!("../templates/integrator.rs.tmpl"),
    include_str!("../templates/mutation.rs.tmpl"),
    include_str!("../templates/raw-mutation.rs.tmpl"),
];

/// Rust's keywords, strict and reserved (2021 edition).
const KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut", "pub",
    "ref", "return", "self", "static", "struct", "super", "trait", "true", "type", "unsafe", "use",
    "where", "while", "abstract", "become", "box", "do", "final", "gen", "macro", "override",
    "priv", "try", "typeof", "unsized", "virtual", "yield", "union",
];

/// Types and traits of the standard prelude a generated type would shadow.
const PRELUDE: &[&str] = &[
    "Self",
    "Option",
    "Some",
    "None",
    "Result",
    "Ok",
    "Err",
    "String",
    "Vec",
    "Box",
    "ToString",
    "ToOwned",
    "Clone",
    "Copy",
    "Send",
    "Sync",
    "Sized",
    "Unpin",
    "Drop",
    "Fn",
    "FnMut",
    "FnOnce",
    "Iterator",
    "IntoIterator",
    "DoubleEndedIterator",
    "ExactSizeIterator",
    "Extend",
    "FromIterator",
    "Default",
    "Eq",
    "PartialEq",
    "Ord",
    "PartialOrd",
    "AsRef",
    "AsMut",
    "Into",
    "From",
    "TryFrom",
    "TryInto",
    "Debug",
    "Hash",
];

/// Crates of the Flowlight workspace: `flowlight-NAME` would collide with one of them in
/// the generated crate's dependency graph.
const WORKSPACE_CRATES: &[&str] = &[
    "core",
    "sdk",
    "bvh",
    "scene",
    "host",
    "pathtrace",
    "mcmc",
    "embree",
    "elf",
    "bench",
    "cli",
    "testkit",
];

/// Where the generated crate takes `flowlight-sdk` from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SdkSource {
    /// A path to the SDK crate (absolute in the generated Cargo.toml).
    Path(PathBuf),
    /// A version requirement on a registry.
    Version(String),
}

/// The SDK of the checkout this binary was built from.
pub fn default_sdk_path() -> PathBuf {
    // This crate is crates/cli; the SDK is its sibling.
    let sdk = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../flowlight-sdk");
    sdk.canonicalize().unwrap_or(sdk)
}

/// Checks a plugin name (module docs); the error is one line saying what is wrong.
pub fn check_name(name: &str) -> Result<()> {
    let bad = |why: &str| Err(anyhow!("plugin name {name:?} {why}"));
    if name.is_empty() || name.len() > 64 {
        return bad("must have 1 to 64 characters");
    }
    if !name.starts_with(|c: char| c.is_ascii_lowercase()) {
        return bad("must start with a lowercase letter (a-z)");
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '-'))
    {
        return bad(&format!(
            "contains {c:?}: use lowercase letters, digits and '-' (the library is flowlight_<name with _>)"
        ));
    }
    if name.ends_with('-') || name.contains("--") {
        return bad("must not end with '-' or contain \"--\"");
    }
    if KEYWORDS.contains(&name) {
        return bad("is a Rust keyword: the generated crate would not compile");
    }
    if WORKSPACE_CRATES.contains(&name) {
        return bad(&format!(
            "would make a crate flowlight-{name}, the name of one of Flowlight's own crates"
        ));
    }
    let ty = type_name(name);
    if PRELUDE.contains(&ty.as_str()) || template_identifiers().any(|w| w == ty) {
        return bad(&format!(
            "would name the plugin's type {ty}, which the generated code already uses: choose another name"
        ));
    }
    Ok(())
}

/// The words of the templates' code, comments left out (placeholders excluded): a type of
/// the same name would clash with what the code imports or names.
fn template_identifiers() -> impl Iterator<Item = &'static str> {
    TEMPLATES.iter().flat_map(|t| {
        t.lines()
            .map(|line| line.split("//").next().unwrap_or(""))
            .flat_map(|code| code.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')))
            .filter(|w| !w.is_empty() && !w.starts_with("__"))
    })
}

/// `my-ao` → `MyAo`: the Rust type the skeleton defines.
fn type_name(name: &str) -> String {
    name.split('-')
        .map(|part| {
            let mut c = part.chars();
            match c.next() {
                Some(first) => first.to_ascii_uppercase().to_string() + c.as_str(),
                None => String::new(),
            }
        })
        .collect()
}

/// Quotes a string for TOML (basic string).
fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// The regeneration engine's crate beside the SDK at `sdk` (both live in `crates/`).
fn mcmc_path(sdk: &Path) -> PathBuf {
    sdk.parent()
        .map(|p| p.join("flowlight-mcmc"))
        .unwrap_or_else(|| PathBuf::from("flowlight-mcmc"))
}

/// The `Cargo.lock` of the workspace the SDK at `sdk` belongs to (`crates/flowlight-sdk` →
/// the workspace root), if there is one.
fn workspace_lock(sdk: &Path) -> Option<PathBuf> {
    let lock = sdk.parent()?.parent()?.join("Cargo.lock");
    lock.is_file().then_some(lock)
}

/// The `[dependencies]` lines: the SDK, and the engine's crate for an engine-based mutation.
fn dependencies(kind: Kind, sdk: &SdkSource) -> Result<String> {
    let with_engine = kind == Kind::Mutation;
    Ok(match sdk {
        SdkSource::Path(p) => {
            let text = |p: &Path| {
                p.to_str().map(toml_string).ok_or_else(|| {
                    anyhow!(
                        "SDK path {} is not valid UTF-8: pass --sdk-path",
                        p.display()
                    )
                })
            };
            let mut deps = format!("flowlight-sdk = {{ path = {} }}", text(p)?);
            if with_engine {
                let mcmc = mcmc_path(p);
                deps += &format!("\nflowlight-mcmc = {{ path = {} }}", text(&mcmc)?);
            }
            deps
        }
        SdkSource::Version(v) => {
            let mut deps = format!("flowlight-sdk = {}", toml_string(v));
            if with_engine {
                deps += &format!("\nflowlight-mcmc = {}", toml_string(v));
            }
            deps
        }
    })
}

/// The files of the new crate: (path relative to DIR, contents).
pub fn render_files(kind: Kind, name: &str, sdk: &SdkSource) -> Result<Vec<(PathBuf, String)>> {
    check_name(name)?;
    let sdk_dep = dependencies(kind, sdk)?;
    let (kind_word, lib_template, usage) = match kind {
        Kind::Integrator => (
            "integrator",
            TEMPLATES[0],
            format!(
                "and name it in the config:\n\n```toml\n[integrator]\nplugin = \"{name}\"\nlight_samples = 1\n```"
            ),
        ),
        Kind::Mutation => (
            "mutation",
            TEMPLATES[1],
            format!(
                "and list it among an integrator's mutations:\n\n```toml\n[integrator]\nplugin = \"erpt\"\n\n[[integrator.mutations]]\nplugin = \"{name}\"\np_reconnect = 0.5\n```"
            ),
        ),
        Kind::RawMutation => (
            "raw-mutation",
            TEMPLATES[2],
            format!(
                "and list it among an integrator's mutations:\n\n```toml\n[integrator]\nplugin = \"erpt\"\n\n[[integrator.mutations]]\nplugin = \"{name}\"\nsize = 2.0\n```"
            ),
        ),
    };
    let lib = format!("flowlight_{}", name.replace('-', "_"));
    let fill = |t: &str| {
        t.replace("__NAME__", name)
            .replace("__TYPE__", &type_name(name))
            .replace("__CRATE__", &format!("flowlight-{name}"))
            .replace("__LIB__", &lib)
            .replace("__KIND__", kind_word)
            .replace("__SDK_DEP__", &sdk_dep)
            .replace("__USAGE__", &usage)
    };
    Ok(vec![
        (
            "Cargo.toml".into(),
            fill(include_str!("../templates/Cargo.toml.tmpl")),
        ),
        ("src/lib.rs".into(), fill(lib_template)),
        (
            "README.md".into(),
            fill(include_str!("../templates/README.md.tmpl")),
        ),
        (".gitignore".into(), "/target\n".into()),
    ])
}

/// The subcommand: checks NAME and DIR, then writes the crate.
pub fn run(kind: Kind, name: &str, dir: &Path, sdk: SdkSource) -> Result<()> {
    check_name(name)?;
    if dir.exists() {
        let mut entries = std::fs::read_dir(dir)
            .with_context(|| format!("{} exists and is not a readable folder", dir.display()))?;
        if entries.next().is_some() {
            return Err(anyhow!(
                "{} exists and is not empty: choose a new folder",
                dir.display()
            ));
        }
    }
    let sdk = match sdk {
        SdkSource::Path(p) => {
            if !p.join("Cargo.toml").is_file() {
                return Err(anyhow!(
                    "no flowlight-sdk crate at {} (pass --sdk-path DIR or --sdk-version VERSION)",
                    p.display()
                ));
            }
            let p = std::fs::canonicalize(&p).with_context(|| p.display().to_string())?;
            if kind == Kind::Mutation && !mcmc_path(&p).join("Cargo.toml").is_file() {
                return Err(anyhow!(
                    "no flowlight-mcmc crate at {} beside the SDK (an engine-based mutation needs it; --kind raw-mutation does not)",
                    mcmc_path(&p).display()
                ));
            }
            SdkSource::Path(p)
        }
        v => v,
    };
    let mut files = render_files(kind, name, &sdk)?;
    // The workspace's resolution, so that the plugin builds against the versions the host was
    // built with; Cargo drops the entries the plugin does not need on its first build.
    let lock = match &sdk {
        SdkSource::Path(p) => workspace_lock(p),
        SdkSource::Version(_) => workspace_lock(&default_sdk_path()),
    };
    if let Some(lock) = lock {
        let text = std::fs::read_to_string(&lock)
            .with_context(|| format!("cannot read {}", lock.display()))?;
        files.push(("Cargo.lock".into(), text));
    }
    for (rel, text) in &files {
        let path = dir.join(rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    // Line widths depend on the name: let rustfmt lay the skeleton out, when it is installed
    // (the code is valid either way).
    let _ = std::process::Command::new("rustfmt")
        .args(["--edition", "2021"])
        .arg(dir.join("src/lib.rs"))
        .stderr(std::process::Stdio::null())
        .status();
    let lib = format!(
        "{}flowlight_{}{}",
        std::env::consts::DLL_PREFIX,
        name.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    );
    println!("new {kind:?} plugin '{name}' in {}", dir.display());
    for (rel, _) in &files {
        println!("  wrote           {}", dir.join(rel).display());
    }
    println!(
        "  next            cd {} && cargo build --release   (gives target/release/{lib})",
        dir.display()
    );
    println!(
        "  load it with    FLOWLIGHT_PLUGIN_PATH={}/target/release, or [plugins] search_paths in the config",
        dir.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_library_rule() {
        for good in ["ao", "my-ao", "a2", "film-perturbation-2"] {
            check_name(good).unwrap();
        }
        for bad in ["", "Ao", "2d", "my_ao", "my--ao", "ao-", "a b", "é"] {
            let e = check_name(bad).unwrap_err().to_string();
            assert!(
                e.contains("plugin name") && !e.contains('\n'),
                "{bad:?}: {e}"
            );
        }
        assert_eq!(type_name("film-perturbation-2"), "FilmPerturbation2");
    }

    #[test]
    fn names_whose_crate_would_not_compile_are_refused() {
        // Each of these generated a crate that failed to build: `Self` is a keyword, the
        // others clash with the prelude or with what the templates import.
        let clashing = [
            "self",
            "scene",
            "film",
            "ray",
            "integrator",
            "mutation",
            "result",
            "string",
            "option",
            "tracer",
            "params",
            "proposal",
            "strategy",
            "policy",
            "rng",
            "path",
        ];
        for bad in clashing
            .iter()
            .chain(["fn", "type", "async", "sdk", "mcmc", "core"].iter())
        {
            let e = check_name(bad).unwrap_err().to_string();
            assert!(
                e.starts_with(&format!("plugin name {bad:?} ")) && !e.contains('\n'),
                "{bad:?}: {e}"
            );
        }
        // Words of the templates' comments are no identifiers.
        for good in ["markov", "rules", "my-scene", "scene-2", "film-grain"] {
            check_name(good).unwrap_or_else(|e| panic!("{good}: {e}"));
        }
    }

    #[test]
    fn templates_are_filled_completely() {
        let sdk = SdkSource::Path("/x/flowlight-sdk".into());
        for kind in [Kind::Integrator, Kind::Mutation, Kind::RawMutation] {
            let files = render_files(kind, "my-thing", &sdk).unwrap();
            for (rel, text) in &files {
                assert!(!text.contains("__"), "{}: placeholder left", rel.display());
            }
            let cargo = &files[0].1;
            let parsed: toml::Table = toml::from_str(cargo).unwrap();
            assert_eq!(parsed["lib"]["name"].as_str(), Some("flowlight_my_thing"));
            assert_eq!(
                parsed["package"]["name"].as_str(),
                Some("flowlight-my-thing")
            );
            assert_eq!(
                parsed["dependencies"]["flowlight-sdk"]["path"].as_str(),
                Some("/x/flowlight-sdk")
            );
            assert!(parsed["workspace"].as_table().unwrap().is_empty());
            assert!(files[1].1.contains("struct MyThing"));
            let engine = parsed["dependencies"].get("flowlight-mcmc");
            assert_eq!(
                engine.and_then(|d| d["path"].as_str()),
                (kind == Kind::Mutation).then_some("/x/flowlight-mcmc")
            );
        }
        let files = render_files(Kind::Mutation, "j", &SdkSource::Version("0.1".into())).unwrap();
        let parsed: toml::Table = toml::from_str(&files[0].1).unwrap();
        assert_eq!(
            parsed["dependencies"]["flowlight-sdk"].as_str(),
            Some("0.1")
        );
    }

    #[test]
    fn a_non_empty_folder_is_refused() {
        let dir = std::env::temp_dir().join(format!("flowlight-new-plugin-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("keep.txt"), "mine").unwrap();
        let e = run(
            Kind::Integrator,
            "x",
            &dir,
            SdkSource::Version("0.1".into()),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("not empty"), "{e}");
        assert_eq!(
            std::fs::read_to_string(dir.join("keep.txt")).unwrap(),
            "mine"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
