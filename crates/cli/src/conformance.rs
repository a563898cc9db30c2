//! `flowlight conformance PLUGIN [--set NAME=VALUE]...`: runs the conformance kit
//! (`flowlight-testkit`) on a built mutation plugin, without Cargo.
//!
//! PLUGIN is a path to the library (`target/release/libflowlight_my_mutation.so`) or a
//! plugin name searched like the host searches; each `--set` is one of its parameters, the
//! value in TOML syntax or a bare string (`--set sigma=1.5`, `--set width=wide`). The kit
//! renders with the ERPT integrator, found like any plugin (`FLOWLIGHT_PLUGIN_PATH`, then
//! this executable's folder, where `cargo build --release` puts it), and reads the scenes of
//! the checkout this binary was built from.
//!
//! Prints the kit's report (the density checks per scene, then the furnace) and `conforms`;
//! a plugin that fails a check is an error naming the check, exit status 1.

use anyhow::{anyhow, Result};

/// The subcommand.
pub fn run(plugin: &str, sets: &[String]) -> Result<()> {
    let params = crate::parse_sets(sets)?;
    let params: Vec<(&str, toml::Value)> = params
        .iter()
        .map(|(k, v)| (k.as_str(), v.clone()))
        .collect();
    let report = flowlight_testkit::check_mutation(plugin, &params).map_err(|e| {
        anyhow!(
            "mutation {plugin} does not conform: {}",
            e.replace('\n', " ")
        )
    })?;
    println!("{report}");
    println!("conforms");
    Ok(())
}
