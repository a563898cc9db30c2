//! `flowlight plugins`: the plugins on the search path, with versions and parameters.

use anyhow::Result;
use flowlight_host::plugin::{list_plugin_files, search_dirs, PluginLibrary};
use std::path::PathBuf;

pub fn run(extra: &[PathBuf]) -> Result<()> {
    let dirs = search_dirs(extra);
    let files = list_plugin_files(&dirs);
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
                    println!(
                        "  {:<14} {:<8} default {:<12} {}",
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
