//! `flowlight plugins`: the plugins on the search path, with versions and parameters; with
//! `--markdown`, each plugin's parameter table as the docs hold it (generated from the
//! plugin's declarations, [`flowlight_host::param_docs`]).

use anyhow::Result;
use flowlight_host::param_docs::marked_block;
use flowlight_host::plugin::{list_plugin_files, search_dirs, PluginLibrary};
use flowlight_sdk::ParamRole;
use std::path::PathBuf;

pub fn run(extra: &[PathBuf], markdown: bool) -> Result<()> {
    let dirs = search_dirs(extra);
    let files = list_plugin_files(&dirs);
    if markdown {
        for f in files {
            // A plugin without parameters has no table; a refused one neither (the plain
            // listing says why).
            match PluginLibrary::load(&f) {
                Ok(p) if !p.params().is_empty() => {
                    println!("{}", marked_block(&p.name, &p.params()))
                }
                _ => {}
            }
        }
        return Ok(());
    }
    println!(
        "search path: {}",
        dirs.iter()
            .map(|d| d.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    if files.is_empty() {
        println!("no plugins found (build them with `cargo build --release --workspace`)");
        return Ok(());
    }
    for f in files {
        match PluginLibrary::load(&f) {
            Ok(p) => {
                println!("\n{} ({:?}) — {}", p.name, p.kind, p.description);
                println!("  file   {}", p.path.display());
                println!("  sdk    {}, {}", p.sdk_version, p.rustc_version);
                for param in p.params() {
                    let range = if param.range.is_empty() {
                        String::new()
                    } else {
                        format!(" in {}", param.range)
                    };
                    let role = match param.role {
                        ParamRole::None => String::new(),
                        r => format!(" [role {r:?}]"),
                    };
                    println!(
                        "  {:<14} {:<8} default {:<12} {}{range}{role}",
                        param.name,
                        param.kind.name(),
                        param.default,
                        param.doc
                    );
                }
            }
            Err(e) => println!("\n{}: refused: {e}", f.display()),
        }
    }
    Ok(())
}
