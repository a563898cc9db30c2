//! Every glTF 2.0 model of Debian's `assimp-testmodels` (fetched by `bash .ci/setup` into
//! `scenes/assimp-testmodels/glTF2/`) is rendered twice through the command line, as a user
//! would: once as it is, with no camera or light added, and once with a constant
//! `[environment]`. Each run either renders or fails with an error line; a render that comes
//! out black must have said why (the "no light" warning). The outcomes must be the ones listed
//! in docs/gltf.md's corpus table, so the table cannot drift from what the renderer does, and
//! every model of the corpus must be listed there.

use crate::common;

use flowlight_host::output::read_exr_rgb;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Outcome {
    /// Exit 0 and some pixel is not black.
    Renders,
    /// Exit 0, every pixel black, and a warning line that says the scene has no light.
    BlackWarned,
    /// A non-zero exit with a one-line error.
    Error,
}

impl Outcome {
    fn parse(s: &str) -> Option<Outcome> {
        match s {
            "renders" => Some(Outcome::Renders),
            "black, warned" => Some(Outcome::BlackWarned),
            "error" => Some(Outcome::Error),
            _ => None,
        }
    }
}

struct Documented {
    plain: Outcome,
    environment: Outcome,
    /// Text (in backticks in the table) that the error line must contain.
    error_names: Option<String>,
}

fn corpus_root() -> PathBuf {
    let root = common::repo().join("scenes/assimp-testmodels/glTF2");
    assert!(
        root.is_dir(),
        "{} is missing: run `bash .ci/setup` (it fetches Debian's assimp-testmodels)",
        root.display()
    );
    root
}

fn corpus_files(dir: &Path, root: &Path, out: &mut Vec<String>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().collect();
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let p = e.path();
        if p.is_dir() {
            corpus_files(&p, root, out);
        } else if matches!(
            p.extension().and_then(|x| x.to_str()),
            Some("gltf") | Some("glb")
        ) {
            out.push(
                p.strip_prefix(root)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/"),
            );
        }
    }
}

/// The rows of the table that follows the `<!-- corpus-table -->` marker in docs/gltf.md:
/// `| `file` | plain outcome | outcome with [environment] | detail |`.
fn documented() -> BTreeMap<String, Documented> {
    let doc = std::fs::read_to_string(common::repo().join("docs/gltf.md")).unwrap();
    let table = doc
        .split("<!-- corpus-table -->")
        .nth(1)
        .expect("docs/gltf.md has a <!-- corpus-table --> marker before the corpus table");
    let mut rows = BTreeMap::new();
    for line in table.lines().map(str::trim) {
        if line.is_empty() {
            if rows.is_empty() {
                continue;
            }
            break;
        }
        let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
        if cells.len() < 4 || cells[0].starts_with("---") || cells[0] == "file" {
            continue;
        }
        let file = cells[0].trim_matches('`').to_string();
        let parse = |s: &str| {
            Outcome::parse(s)
                .unwrap_or_else(|| panic!("docs/gltf.md corpus row {file}: unknown outcome '{s}'"))
        };
        let error_names = cells[3]
            .split('`')
            .nth(1)
            .filter(|s| !s.is_empty())
            .map(str::to_string);
        rows.insert(
            file.clone(),
            Documented {
                plain: parse(cells[1]),
                environment: parse(cells[2]),
                error_names,
            },
        );
    }
    rows
}

struct Run {
    outcome: Outcome,
    stderr: String,
}

fn render(model: &Path, environment: bool, scratch: &Path, tag: &str) -> Run {
    let exr = scratch.join(format!("{tag}.exr"));
    let _ = std::fs::remove_file(&exr);
    let env = if environment {
        "[environment]\ncolor = [1.0, 1.0, 1.0]\n"
    } else {
        ""
    };
    let config = scratch.join(format!("{tag}.toml"));
    std::fs::write(
        &config,
        format!(
            "scene = {:?}\n[render]\nwidth = 24\nheight = 24\nspp = 2\n[integrator]\nplugin = \"mcpt\"\n{env}[output]\nexr = {:?}\n",
            model.to_str().unwrap(),
            exr.to_str().unwrap()
        ),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_flowlight"))
        .args(["render", "-q"])
        .arg(&config)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    if !o.status.success() {
        return Run {
            outcome: Outcome::Error,
            stderr,
        };
    }
    let (_, _, layers) = read_exr_rgb(&exr)
        .unwrap_or_else(|e| panic!("{}: exit 0 but no readable EXR: {e}", model.display()));
    let lit = layers[0]
        .1
        .iter()
        .any(|c| c.r > 0.0 || c.g > 0.0 || c.b > 0.0);
    let outcome = if lit {
        Outcome::Renders
    } else {
        assert!(
            stderr.to_lowercase().contains("no light"),
            "{}: rendered black with exit 0 and no warning saying why:\n{stderr}",
            model.display()
        );
        Outcome::BlackWarned
    };
    Run { outcome, stderr }
}

#[test]
fn every_corpus_model_renders_or_names_what_it_lacks() {
    let root = corpus_root();
    let mut files = Vec::new();
    corpus_files(&root, &root, &mut files);
    assert!(files.len() >= 40, "only {} corpus files found", files.len());
    let docs = documented();
    let scratch = common::scratch("gltf-corpus");
    let mut problems = Vec::new();
    for (i, f) in files.iter().enumerate() {
        let Some(d) = docs.get(f) else {
            problems.push(format!("{f}: not listed in docs/gltf.md's corpus table"));
            continue;
        };
        let model = root.join(f);
        for (environment, expected) in [(false, d.plain), (true, d.environment)] {
            let run = render(
                &model,
                environment,
                &scratch,
                &format!("m{i}-{environment}"),
            );
            let what = if environment {
                "with [environment]"
            } else {
                "as it is"
            };
            if run.outcome != expected {
                problems.push(format!(
                    "{f} {what}: {:?}, docs/gltf.md says {expected:?}; stderr: {}",
                    run.outcome,
                    run.stderr.trim()
                ));
            }
            if run.outcome == Outcome::Error {
                let lines: Vec<&str> = run.stderr.trim().lines().collect();
                let error_lines: Vec<&&str> =
                    lines.iter().filter(|l| l.starts_with("error")).collect();
                if error_lines.len() != 1 {
                    problems.push(format!("{f} {what}: the error is not one line: {lines:?}"));
                }
                if let Some(name) = &d.error_names {
                    if !run.stderr.contains(name.as_str()) {
                        problems.push(format!(
                            "{f} {what}: the error does not name `{name}`: {}",
                            run.stderr.trim()
                        ));
                    }
                }
            }
        }
    }
    for f in docs.keys() {
        if !files.contains(f) {
            problems.push(format!(
                "docs/gltf.md lists {f}, which is not in the corpus"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
