//! `flowlight new-plugin --kind integrator|mutation NAME DIR`: writes a plugin crate that
//! builds outside this workspace.
//!
//! DIR gets `Cargo.toml` (a `cdylib` named `flowlight_<NAME with _>`, so the file is
//! `libflowlight_<NAME with _>.so`, with `flowlight-sdk` as its only dependency and an empty
//! `[workspace]` table so that it is a workspace of its own), `src/lib.rs` (a documented
//! skeleton that works as generated: a one-bounce direct-lighting integrator, or a symmetric
//! film-jitter mutation with a hard reconnection), unit tests inside it, a `README.md` and a
//! `.gitignore`, and runs `rustfmt` over `src/lib.rs` when it is installed. The SDK is referenced by the absolute path of this checkout's
//! `crates/flowlight-sdk` (default), another path (`--sdk-path`) or a registry version
//! (`--sdk-version`).
//!
//! A NAME is what configs write (`plugin = "NAME"`): 1–64 characters, lowercase ASCII
//! letters, digits and single `-` between them, starting with a letter. DIR must not exist
//! or be an empty folder. Templates live in `crates/cli/templates/`; `__NAME__`, `__TYPE__`
//! (NAME in CamelCase), `__CRATE__`, `__LIB__`, `__KIND__`, `__SDK_DEP__` and `__USAGE__` are
//! replaced.

use anyhow::{anyhow, Context, Result};
use std::path::{Path, PathBuf};

/// Which trait the generated plugin implements.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind {
    Integrator,
    Mutation,
}

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
    Ok(())
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

/// The files of the new crate: (path relative to DIR, contents).
pub fn render_files(kind: Kind, name: &str, sdk: &SdkSource) -> Result<Vec<(PathBuf, String)>> {
    check_name(name)?;
    let sdk_dep = match sdk {
        SdkSource::Path(p) => {
            let p = p.to_str().ok_or_else(|| {
                anyhow!(
                    "SDK path {} is not valid UTF-8: pass --sdk-path",
                    p.display()
                )
            })?;
            format!("flowlight-sdk = {{ path = {} }}", toml_string(p))
        }
        SdkSource::Version(v) => format!("flowlight-sdk = {}", toml_string(v)),
    };
    let (kind_word, lib_template, usage) = match kind {
        Kind::Integrator => (
            "integrator",
            include_str!("../templates/integrator.rs.tmpl"),
            format!(
                "and name it in the config:\n\n```toml\n[integrator]\nplugin = \"{name}\"\nlight_samples = 1\n```"
            ),
        ),
        Kind::Mutation => (
            "mutation",
            include_str!("../templates/mutation.rs.tmpl"),
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
            SdkSource::Path(std::fs::canonicalize(&p).with_context(|| p.display().to_string())?)
        }
        v => v,
    };
    let files = render_files(kind, name, &sdk)?;
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
    fn templates_are_filled_completely() {
        let sdk = SdkSource::Path("/x/flowlight-sdk".into());
        for kind in [Kind::Integrator, Kind::Mutation] {
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
