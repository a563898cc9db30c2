//! The plugin boundary: real plugins load from disk, mismatches and missing plugins are
//! refused with clear errors.

use crate::common;

use flowlight_host::error::HostError;
use flowlight_host::plugin::{
    find_plugin, plugin_file_name, search_dirs, PluginError, PluginLibrary,
};
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_sdk::abi::ABI_VERSION;
use flowlight_sdk::PluginKind;

#[test]
fn mcpt_plugin_loads_with_its_declaration() {
    let path = find_plugin("mcpt", &search_dirs(&[]))
        .expect("mcpt plugin built (run `cargo build --workspace`)");
    let p = PluginLibrary::load(&path).unwrap();
    assert_eq!(p.name, "mcpt");
    assert_eq!(p.kind, PluginKind::Integrator);
    assert_eq!(p.sdk_version, flowlight_sdk::abi::SDK_VERSION);
    let names: Vec<String> = p.params().into_iter().map(|p| p.name).collect();
    for expected in [
        "variant",
        "termination",
        "path_depth",
        "max_ray_depth",
        "layers",
    ] {
        assert!(
            names.iter().any(|n| n == expected),
            "missing parameter {expected} in {names:?}"
        );
    }
}

#[test]
fn plugin_with_wrong_abi_is_refused_by_name_and_versions() {
    let path = find_plugin("test-bad-abi", &search_dirs(&[])).expect("fixture plugin built");
    let err = match PluginLibrary::load(&path) {
        Ok(_) => panic!("a plugin with a wrong ABI version was accepted"),
        Err(e) => e,
    };
    assert!(
        matches!(
            err,
            PluginError::Mismatch {
                what: "ABI version",
                ..
            }
        ),
        "{err}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains(&plugin_file_name("test-bad-abi")),
        "message does not name the file: {msg}"
    );
    assert!(
        msg.contains(&format!(
            "(plugin has {}, host has {ABI_VERSION})",
            ABI_VERSION - 1
        )),
        "{msg}"
    );
}

#[test]
fn missing_plugin_is_a_clear_error() {
    let err = find_plugin("no-such-integrator", &search_dirs(&[])).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("no-such-integrator") && msg.contains("not found"),
        "{msg}"
    );
    assert!(
        msg.contains(&plugin_file_name("no-such-integrator")),
        "{msg}"
    );

    let dir = common::scratch("missing-plugin");
    std::fs::copy(
        common::scene_config("furnace/furnace.gltf"),
        dir.join("furnace.gltf"),
    )
    .unwrap();
    let cfg = dir.join("r.toml");
    std::fs::write(
        &cfg,
        "scene = \"furnace.gltf\"\n[integrator]\nplugin = \"no-such-integrator\"\n",
    )
    .unwrap();
    let err = Renderer::prepare(&cfg, &Overrides::default())
        .err()
        .expect("missing plugin accepted");
    let HostError::Plugin {
        file: Some(file),
        field: Some(field),
        error,
    } = &err
    else {
        panic!("not a plugin's error named in the config: {err:?}")
    };
    let PluginError::NotFound { name, .. } = error.as_ref() else {
        panic!("not a missing plugin: {err:?}")
    };
    assert_eq!(file, &cfg);
    assert_eq!(field, "integrator.plugin");
    assert_eq!(name, "no-such-integrator");
}

#[test]
fn a_non_plugin_library_is_refused() {
    let dir = common::scratch("not-a-plugin");
    let fake = dir.join(plugin_file_name("fake"));
    std::fs::write(&fake, b"this is not a shared library").unwrap();
    let err = PluginLibrary::load(&fake)
        .err()
        .expect("garbage accepted as a plugin");
    assert!(
        err.to_string().contains(&fake.display().to_string()),
        "{err}"
    );
}

#[test]
fn unknown_integrator_parameter_names_the_key() {
    let ov = Overrides {
        params: common::toml_params(&[("path_dpeth", toml::Value::Integer(3))]),
        ..Default::default()
    };
    let err = Renderer::prepare(&common::scene_config("furnace/furnace.toml"), &ov)
        .err()
        .expect("typo accepted");
    let err = common::plugin_refusal(&err, "mcpt");
    assert!(err.contains("path_dpeth"), "{err}");
    let ov = Overrides {
        params: common::toml_params(&[("variant", "sideways".into())]),
        ..Default::default()
    };
    let err = Renderer::prepare(&common::scene_config("furnace/furnace.toml"), &ov)
        .err()
        .expect("bad value accepted");
    let err = common::plugin_refusal(&err, "mcpt");
    assert!(err.contains("variant") && err.contains("sideways"), "{err}");
}

#[test]
fn the_real_plugin_renders_an_image() {
    let s = common::renderer("furnace/furnace.toml", 4, &[]);
    let out = common::render(&s);
    assert_eq!(out.stats.pixel_samples, 32 * 32 * 4);
    assert!(out.stats.closest_rays >= 32 * 32 * 4);
    assert!(out
        .frame
        .image()
        .iter()
        .all(|c| c.is_valid_radiance() && c.luminance() > 0.0));
}

#[test]
fn plugin_errors_and_panics_come_back_as_errors() {
    let ov = Overrides {
        params: common::toml_params(&[("fail_create", true.into())]),
        ..Default::default()
    };
    let mut cfg =
        flowlight_scene::config::load_config(&common::scene_config("furnace/furnace.toml"))
            .unwrap();
    cfg.integrator_plugin = "test-panic".into();
    cfg.integrator_params.clear();
    let err = Renderer::from_config(cfg.clone(), &ov)
        .err()
        .expect("create error ignored");
    let err = common::plugin_refusal(&err, "test-panic");
    assert!(err.contains("asked to fail in create"), "{err}");

    let ov = Overrides {
        spp: Some(1),
        threads: Some(2),
        ..Default::default()
    };
    let s = Renderer::from_config(cfg, &ov).unwrap();
    let out = s
        .render(&std::sync::atomic::AtomicBool::new(false), &|_| {})
        .unwrap();
    let err = out
        .error
        .expect("a panic in render was not reported")
        .to_string();
    assert!(
        err.contains("test-panic") && err.contains("panicked") && err.contains("deliberate panic"),
        "{err}"
    );
    assert!(out.stats.interrupted);
}

/// Where the out-of-tree fixture builds of [`plugins_from_another_sdk_or_rustc_are_refused`]
/// live: beside the test executable's profile folder (`target/version-fixtures`), kept
/// between runs so that only the first run compiles `flowlight-core` for them.
fn fixture_root() -> std::path::PathBuf {
    let exe = std::env::current_exe().unwrap();
    // target/<profile>/deps/plugins-HASH → target/
    let target = exe.ancestors().nth(3).unwrap().to_path_buf();
    target.join("version-fixtures")
}

/// A minimal integrator, as an outsider would write it.
const FIXTURE_PLUGIN: &str = r#"
use flowlight_sdk::{
    export_integrator, Film, Integrator, IntegratorInfo, MutationSet, ParamSpec, Params, Scene,
    Stats, StatsBuilder, Tracer, WorkUnit,
};

pub struct Fixture;

impl Integrator for Fixture {
    const NAME: &'static str = "fixture";
    const DESCRIPTION: &'static str = "version-check fixture";
    const PARAMS: &'static [ParamSpec] = &[];

    fn create(
        _: &Params,
        _: MutationSet<'static>,
        _: Scene<'static>,
        _: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        Ok((Fixture, IntegratorInfo::simple()))
    }

    fn render(&self, _: &WorkUnit, _: &Tracer, _: &mut Film, _: &mut Stats) -> Result<(), String> {
        Ok(())
    }
}

export_integrator!(Fixture);
"#;

/// Writes a one-plugin workspace at `dir` whose plugin depends on the SDK at `sdk`, builds it
/// into the shared fixture target folder with `rustc` as the compiler (None: the default),
/// and returns the built library.
fn build_fixture(
    dir: &std::path::Path,
    lib: &str,
    sdk: &std::path::Path,
    rustc: Option<&std::path::Path>,
) -> std::path::PathBuf {
    let plugin = dir.join("plugin");
    std::fs::create_dir_all(plugin.join("src")).unwrap();
    std::fs::write(
        dir.join("Cargo.toml"),
        "[workspace]\nmembers = [\"plugin\"]\nresolver = \"2\"\n",
    )
    .unwrap();
    // The workspace's lock file: the fixture resolves to the versions the host was built with.
    std::fs::copy(common::repo().join("Cargo.lock"), dir.join("Cargo.lock")).unwrap();
    std::fs::write(
        plugin.join("Cargo.toml"),
        format!(
            "[package]\nname = \"{}\"\nversion = \"0.1.0\"\nedition = \"2021\"\npublish = false\n\n[lib]\nname = \"{lib}\"\ncrate-type = [\"cdylib\"]\n\n[dependencies]\nflowlight-sdk = {{ path = {:?} }}\n",
            lib.replace('_', "-"),
            sdk.display().to_string()
        ),
    )
    .unwrap();
    std::fs::write(plugin.join("src/lib.rs"), FIXTURE_PLUGIN).unwrap();
    let target = fixture_root().join("target");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = std::process::Command::new(cargo);
    cmd.current_dir(dir)
        .args(["build", "--offline", "--quiet", "--target-dir"])
        .arg(&target)
        .env_remove("RUSTC_WRAPPER")
        .env_remove("RUSTC_WORKSPACE_WRAPPER")
        .env_remove("CARGO_BUILD_RUSTC")
        .env_remove("CARGO_TARGET_DIR");
    match rustc {
        Some(r) => cmd.env("RUSTC", r),
        None => cmd.env_remove("RUSTC"),
    };
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "building the fixture in {} failed:\n{}",
        dir.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    target.join("debug").join(format!(
        "{}{lib}{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ))
}

/// A copy of this repository's SDK crate at `dest`, with `version` in its manifest and, if
/// given, one text replacement in `abi.rs`; returns its folder.
fn copy_sdk(
    dest: &std::path::Path,
    version: &str,
    patch: Option<(&str, &str)>,
) -> std::path::PathBuf {
    let repo = common::repo();
    let real = repo.join("crates/flowlight-sdk");
    std::fs::create_dir_all(dest.join("src")).unwrap();
    std::fs::copy(real.join("build.rs"), dest.join("build.rs")).unwrap();
    for f in std::fs::read_dir(real.join("src")).unwrap() {
        let f = f.unwrap().path();
        let mut text = std::fs::read_to_string(&f).unwrap();
        if let (Some((from, to)), Some("abi.rs")) = (patch, f.file_name().and_then(|n| n.to_str()))
        {
            assert!(text.contains(from), "abi.rs no longer contains {from:?}");
            text = text.replace(from, to);
        }
        let out = dest.join("src").join(f.file_name().unwrap());
        // Unchanged files keep their timestamps, so reruns do not rebuild the copy.
        if std::fs::read_to_string(&out).ok().as_deref() != Some(text.as_str()) {
            std::fs::write(out, text).unwrap();
        }
    }
    let manifest = format!(
        "[package]\nname = \"flowlight-sdk\"\nversion = \"{version}\"\nedition = \"2021\"\nbuild = \"build.rs\"\n\n[dependencies]\nflowlight-core = {{ path = {:?} }}\nglam = \"0.34\"\n",
        repo.join("crates/flowlight-core").display().to_string()
    );
    if std::fs::read_to_string(dest.join("Cargo.toml")).ok() != Some(manifest.clone()) {
        std::fs::write(dest.join("Cargo.toml"), manifest).unwrap();
    }
    dest.to_path_buf()
}

/// A plugin built against another SDK version, and one built by another rustc, are refused
/// with the documented message (docs/architecture.md, "Versions"):
/// `plugin PATH was refused: WHAT mismatch (plugin has X, host has Y); rebuild the plugin
/// against this host's SDK`.
///
/// Both are real out-of-tree builds of the same small integrator, with `cargo build` in a
/// workspace of their own under `target/version-fixtures`:
/// - *another SDK*: against a copy of `crates/flowlight-sdk` whose manifest says version
///   `9.9.9-fixture`, otherwise the same sources (same ABI version and layout hash, so the
///   SDK version is the only difference the host can see);
/// - *another type layout*: against a copy of this SDK version with one crossing type
///   (`HitRecord`) enlarged, so that only the layout hash differs;
/// - a control, built against this SDK by this rustc, loads;
/// - *another rustc*: against this SDK, with `RUSTC` set to a script that answers
///   `rustc --version` (what the SDK's build script records) as `rustc 1.95.0-fixture
///   (another compiler)` and passes every other call, `-vV` included, to the real rustc.
///   Only one toolchain exists on the build machine; the script makes the SDK record a
///   different compiler through the same path a different toolchain would take.
#[cfg(unix)]
#[test]
fn plugins_from_another_sdk_or_rustc_are_refused() {
    use flowlight_sdk::abi::{RUSTC_VERSION, SDK_VERSION};
    let root = fixture_root();
    let repo = common::repo();
    let real_sdk = repo.join("crates/flowlight-sdk");

    // Control: the fixture built against this SDK by this rustc loads.
    let lib = build_fixture(
        &root.join("same"),
        "flowlight_fixture_same",
        &real_sdk,
        None,
    );
    let p = PluginLibrary::load(&lib).unwrap_or_else(|e| panic!("control fixture refused: {e}"));
    assert_eq!(
        (p.name.as_str(), p.kind),
        ("fixture", PluginKind::Integrator)
    );

    // Another SDK version: a copy of the SDK crate with another version in its manifest.
    let ws = root.join("other-sdk");
    let sdk = copy_sdk(&ws.join("sdk"), "9.9.9-fixture", None);
    let lib = build_fixture(&ws, "flowlight_fixture_other_sdk", &sdk, None);
    let err = PluginLibrary::load(&lib)
        .err()
        .expect("a plugin built against another SDK version was accepted");
    assert_eq!(
        err.to_string(),
        format!(
            "plugin {} was refused: SDK version mismatch (plugin has 9.9.9-fixture, host has {SDK_VERSION}); rebuild the plugin against this host's SDK",
            lib.display()
        )
    );

    // Another type layout: a copy of this SDK version whose hit record's flag is a u64 (one
    // crossing type changed without an ABI version bump).
    let ws = root.join("other-layout");
    let sdk = copy_sdk(
        &ws.join("sdk"),
        SDK_VERSION,
        Some(("pub hit: u32,", "pub hit: u64,")),
    );
    let lib = build_fixture(&ws, "flowlight_fixture_other_layout", &sdk, None);
    let err = PluginLibrary::load(&lib)
        .err()
        .expect("a plugin with another type layout was accepted");
    let msg = err.to_string();
    assert!(
        msg.starts_with(&format!(
            "plugin {} was refused: type layout mismatch (plugin has ",
            lib.display()
        )) && msg.ends_with(&format!(
            ", host has {:016x}); rebuild the plugin against this host's SDK",
            flowlight_sdk::abi::layout_hash()
        )),
        "{msg}"
    );

    // Another rustc: the same SDK, compiled by a "different" compiler.
    let ws = root.join("other-rustc");
    std::fs::create_dir_all(&ws).unwrap();
    let fake = ws.join("rustc-other");
    std::fs::write(
        &fake,
        "#!/bin/sh\n# Answers `rustc --version` as another compiler; everything else is the real rustc.\nif [ \"$1\" = \"--version\" ] || [ \"$1\" = \"-V\" ]; then\n  echo 'rustc 1.95.0-fixture (another compiler)'\n  exit 0\nfi\nexec rustc \"$@\"\n",
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    let lib = build_fixture(&ws, "flowlight_fixture_other_rustc", &real_sdk, Some(&fake));
    let err = PluginLibrary::load(&lib)
        .err()
        .expect("a plugin built by another rustc was accepted");
    assert_eq!(
        err.to_string(),
        format!(
            "plugin {} was refused: rustc version mismatch (plugin has rustc 1.95.0-fixture (another compiler), host has {RUSTC_VERSION}); rebuild the plugin against this host's SDK",
            lib.display()
        )
    );
}

/// `[[integrator.mutations]]` entries of (plugin, weight).
fn weighted(entries: &[(&str, toml::Value)]) -> toml::Value {
    toml::Value::Array(
        entries
            .iter()
            .map(|(plugin, weight)| {
                let mut t = toml::map::Map::new();
                t.insert("plugin".into(), toml::Value::String(plugin.to_string()));
                t.insert("weight".into(), weight.clone());
                toml::Value::Table(t)
            })
            .collect(),
    )
}

/// ERPT's counters, declared through the SDK's typed builder, reach the host merged over
/// units with the invariants of their definitions: one seed per pixel sample, N steps per
/// chain, every step a domain hit or miss and every hit an acceptance or rejection, the
/// strategies' steps adding up to the total, ratios formed from the totals.
#[test]
fn erpt_counters_arrive_merged_and_consistent() {
    let list = weighted(&[("drill", 1.into()), ("blow", 3.into())]);
    let s = common::renderer_at("cornell-box/erpt.toml", 16, 16, 2, &[("mutations", list)]);
    let weights: Vec<f64> = (0..2)
        .map(|i| s.instance.mutation_set().weight(i))
        .collect();
    assert_eq!(weights, [0.25, 0.75]);
    let out = common::render(&s);
    let c: std::collections::HashMap<&str, f64> = out
        .stats
        .integrator
        .iter()
        .map(|(k, v)| (k.as_str(), *v))
        .collect();
    assert_eq!(c["seeds"], 16.0 * 16.0 * 2.0);
    assert_eq!(c["image_pixels"], 256.0);
    let chains = c["chains"];
    assert!(chains > 0.0, "no chain ran");
    assert_eq!(c["chains_per_seed"], chains / c["seeds"]);
    assert_eq!(c["deposits_per_pixel"], c["deposits"] / 256.0);
    assert_eq!(c["mean_quantum"], c["quantum_sum"] / c["units"]);
    // chain_length = 16 in erpt.toml.
    assert_eq!(c["total.mutations"], 16.0 * chains);
    assert_eq!(
        c["drill.mutations"] + c["blow.mutations"],
        c["total.mutations"]
    );
    for g in ["total", "drill", "blow"] {
        let at = |k: &str| c[format!("{g}.{k}").as_str()];
        assert_eq!(at("domain_hit") + at("domain_miss"), at("mutations"), "{g}");
        assert_eq!(at("acceptance") + at("rejection"), at("domain_hit"), "{g}");
        assert_eq!(
            at("acceptance_strength"),
            at("acceptance") / at("mutations"),
            "{g}"
        );
        assert!(at("acceptance_streak_max") >= 1.0, "{g}");
    }
    // blow is chosen 3 times as often as drill: 0.75 of the steps, within 5 standard
    // deviations of a binomial draw.
    let n = c["total.mutations"];
    let sd = (n * 0.75 * 0.25).sqrt();
    assert!(
        (c["blow.mutations"] - 0.75 * n).abs() < 5.0 * sd,
        "blow took {} of {n} steps",
        c["blow.mutations"]
    );
}

/// The mutation list's weights are checked in one place, before any strategy loads; each
/// error is one line naming the entry.
#[test]
fn bad_mutation_weights_are_refused_naming_the_entry() {
    let config = common::scene_config("cornell-box/erpt.toml");
    // The list's error (`file` the config), as the CLI prints it.
    let prepare = |list: toml::Value| {
        let e = Renderer::prepare(
            &config,
            &Overrides {
                params: common::toml_params(&[("mutations", list)]),
                ..Default::default()
            },
        )
        .err()
        .expect("bad weights accepted");
        match &e {
            HostError::Mutations { file, .. } => assert_eq!(file, &config),
            e => panic!("not the mutation list's error: {e:?}"),
        }
        e.to_string()
    };
    let cfg = config.display().to_string();
    let e = prepare(weighted(&[("drill", 1.into()), ("blow", (-0.5).into())]));
    assert_eq!(
        e,
        format!("{cfg}: integrator.mutations[1] (plugin \"blow\"): `weight` must not be negative, got -0.5")
    );
    let e = prepare(weighted(&[("drill", f64::NAN.into())]));
    assert!(
        e.contains("integrator.mutations[0] (plugin \"drill\")") && e.contains("NaN"),
        "{e}"
    );
    let e = prepare(weighted(&[("drill", 0.into()), ("blow", 0.0.into())]));
    assert_eq!(e, format!("{cfg}: integrator.mutations: the weights sum to 0; give at least one entry a positive `weight`"));
    // Checked before loading: a missing plugin in a list with 9 entries reports the length.
    let nine: Vec<(&str, toml::Value)> = (0..9).map(|_| ("no-such-mutation", 1.into())).collect();
    let e = prepare(weighted(&nine));
    assert!(e.contains("9 entries") && e.contains("at most 8"), "{e}");
    assert!(!e.contains('\n'), "{e}");
}

/// An integrator with no mutation-list parameter is given no list: a `mutations` key is an
/// unknown parameter like any other.
#[test]
fn mutations_for_an_integrator_without_a_list_are_an_unknown_parameter() {
    let err = Renderer::prepare(
        &common::scene_config("furnace/furnace.toml"),
        &Overrides {
            params: common::toml_params(&[("mutations", weighted(&[("drill", 1.into())]))]),
            ..Default::default()
        },
    )
    .err()
    .expect("mutations accepted by mcpt");
    let err = common::plugin_refusal(&err, "mcpt");
    assert!(
        err.contains("unknown parameter 'mutations' for plugin 'mcpt'"),
        "{err}"
    );
}

/// The host reads a mutation list under the name of the parameter the integrator declares
/// as `ParamKind::MutationList` (`strategies` for the test-panic fixture), not a fixed key.
#[test]
fn the_mutation_list_is_read_under_the_declared_name() {
    let mut cfg =
        flowlight_scene::config::load_config(&common::scene_config("furnace/furnace.toml"))
            .unwrap();
    cfg.integrator_plugin = "test-panic".into();
    cfg.integrator_params = common::toml_params(&[(
        "strategies",
        weighted(&[("drill", 1.into()), ("blow", 1.into())]),
    )]);
    let s = Renderer::from_config(cfg.clone(), &Overrides::default()).unwrap();
    let names: Vec<&str> = s
        .instance
        .mutations()
        .iter()
        .map(|m| m.plugin().name.as_str())
        .collect();
    assert_eq!(names, ["drill", "blow"]);
    assert_eq!(s.instance.mutation_set().weight(1), 0.5);
    // `mutations` is not a parameter of this integrator.
    cfg.integrator_params = common::toml_params(&[("mutations", weighted(&[("drill", 1.into())]))]);
    let err = Renderer::from_config(cfg, &Overrides::default())
        .err()
        .expect("a list under an undeclared name was read");
    let err = common::plugin_refusal(&err, "test-panic");
    assert!(
        err.contains("unknown parameter 'mutations' for plugin 'test-panic'"),
        "{err}"
    );
}

/// The plugins whose parameters the docs list, and the doc holding each table.
const DOCUMENTED: [(&str, &str); 13] = [
    ("mcpt", "docs/mcpt.md"),
    ("erpt", "docs/erpt.md"),
    ("soft-reconnection", "docs/erpt.md"),
    ("blow", "docs/erpt.md"),
    ("drill", "docs/erpt.md"),
    ("lens-perturbation", "docs/erpt.md"),
    ("caustic-perturbation", "docs/erpt.md"),
    ("multichain-perturbation", "docs/erpt.md"),
    ("lighttrace", "docs/bdpt.md"),
    ("bdpt", "docs/bdpt.md"),
    ("vcm", "docs/bdpt.md"),
    ("mmlt", "docs/mmlt.md"),
    ("pssmlt", "docs/pssmlt.md"),
];

/// Every parameter table in the docs is the one `flowlight plugins --markdown` generates from
/// the plugin's declarations: a doc that drifts from the code fails here, naming the file and
/// printing the table to paste.
#[test]
fn docs_parameter_tables_are_the_generated_ones() {
    use flowlight_host::param_docs::{docs_table, markdown_table, marked_block};
    let mut stale = Vec::new();
    for (name, doc) in DOCUMENTED {
        let lib = PluginLibrary::load(&find_plugin(name, &search_dirs(&[])).unwrap()).unwrap();
        let params = lib.params();
        assert!(!params.is_empty(), "{name} declares no parameter");
        let text = std::fs::read_to_string(common::repo().join(doc)).unwrap();
        let expected = markdown_table(&params);
        match docs_table(&text, name) {
            Some(t) if t == expected => {}
            found => stale.push(format!(
                "{doc}: the table of '{name}' {} the declarations; paste:\n{}",
                if found.is_some() {
                    "differs from"
                } else {
                    "is missing, see"
                },
                marked_block(name, &params)
            )),
        }
    }
    assert!(stale.is_empty(), "{}", stale.join("\n"));
    // Every loaded plugin with parameters is documented (the fixtures excepted).
    for f in flowlight_host::plugin::list_plugin_files(&search_dirs(&[])) {
        let Ok(lib) = PluginLibrary::load(&f) else {
            continue;
        };
        if !lib.params().is_empty() && !lib.name.starts_with("test-") {
            assert!(
                DOCUMENTED.iter().any(|(n, _)| *n == lib.name),
                "plugin '{}' has parameters but no table in the docs",
                lib.name
            );
        }
    }
}

/// Each declaration carries its range and role across the ABI; the bench and the CLI read
/// them instead of names.
#[test]
fn declarations_cross_the_abi_with_ranges_and_roles() {
    use flowlight_sdk::ParamRole;
    let load = |n| PluginLibrary::load(&find_plugin(n, &search_dirs(&[])).unwrap()).unwrap();
    for (plugin, max_ray_depth) in [("mcpt", ("64", "1..=1024")), ("erpt", ("32", "1..=32"))] {
        let params = load(plugin).params();
        let by_role = |role| params.iter().find(|p| p.role == role).unwrap();
        let depth = by_role(ParamRole::PathDepth);
        assert_eq!(
            (
                depth.name.as_str(),
                depth.default.as_str(),
                depth.range.as_str()
            ),
            ("path_depth", "8", "1..=32"),
            "{plugin}"
        );
        let cap = by_role(ParamRole::MaxRayDepth);
        assert_eq!(
            (cap.default.as_str(), cap.range.as_str()),
            max_ray_depth,
            "{plugin}"
        );
        assert_eq!(by_role(ParamRole::Layers).name, "layers", "{plugin}");
    }
    let drill = load("drill").params();
    let width = drill.iter().find(|p| p.name == "width").unwrap();
    assert_eq!(width.range, "\"narrow\" | \"wide\"");
    assert_eq!(
        drill
            .iter()
            .find(|p| p.name == "cap_degrees")
            .unwrap()
            .default,
        "by width"
    );
}

/// A value outside its declared range is refused with the standard line, in an integrator
/// and in a mutation.
#[test]
fn values_outside_their_declared_range_are_refused() {
    let refused = |config: &str, params: &[(&str, toml::Value)]| {
        Renderer::prepare(
            &common::scene_config(config),
            &Overrides {
                params: common::toml_params(params),
                ..Default::default()
            },
        )
        .err()
        .expect("an out-of-range value was accepted")
    };
    let e = refused("cornell-box/cornell-box.toml", &[("path_depth", 40.into())]);
    let e = common::plugin_refusal(&e, "mcpt");
    assert!(
        e.contains("parameter 'path_depth' must be in 1..=32, got 40"),
        "{e}"
    );
    let e = refused(
        "cornell-box/cornell-box.toml",
        &[("wavefront", (-1).into())],
    );
    let e = common::plugin_refusal(&e, "mcpt");
    assert!(
        e.contains("parameter 'wavefront' must be in 0..=65536, got -1"),
        "{e}"
    );
    let e = refused("cornell-box/erpt.toml", &[("max_ray_depth", 33.into())]);
    let e = common::plugin_refusal(&e, "erpt");
    assert!(
        e.contains("parameter 'max_ray_depth' must be in 1..=32, got 33"),
        "{e}"
    );
    let list = common::mutations(&[("drill", &[("p_stop", 1.5.into())])]);
    let e = refused("cornell-box/erpt.toml", &[("mutations", list)]);
    let e = e.to_string();
    assert!(
        e.contains("parameter 'p_stop' must be in [0.0, 1.0], got 1.5"),
        "{e}"
    );
}

/// The values a render used, defaults included, are in its EXR header: the integrator's and
/// each mutation's, with the mutation's selection probability.
#[test]
fn resolved_parameters_are_written_into_the_exr_metadata() {
    let dir = common::scratch("resolved-params");
    let list = common::mutations(&[
        ("drill", &[("width", "wide".into()), ("weight", 1.into())]),
        ("lens-perturbation", &[("weight", 3.into())]),
    ]);
    let mut s = common::renderer_at(
        "cornell-box/erpt.toml",
        8,
        8,
        1,
        &[("path_depth", 3.into()), ("mutations", list)],
    );
    let exr = dir.join("resolved.exr");
    s.exr_path = Some(exr.clone());
    let out = common::render(&s);
    s.write_outputs(out.frame, &out.stats).unwrap();
    let meta = flowlight_host::output::read_exr_metadata(&exr).unwrap();
    let get = |k: &str| {
        meta.get(k)
            .unwrap_or_else(|| panic!("no {k} in {:?}", meta.entries))
    };
    // Given, and defaulted (ERPT's own default, not MCPT's).
    assert_eq!(get("flowlight.param.path_depth"), "3");
    assert_eq!(get("flowlight.param.max_ray_depth"), "32");
    assert_eq!(get("flowlight.param.seeds"), "\"untangled\"");
    assert_eq!(get("flowlight.param.sampler"), "\"independent\"");
    // Only what ERPT declares: MCPT's variant is not ERPT's parameter.
    assert!(meta.get("flowlight.param.variant").is_none());
    assert_eq!(get("flowlight.mutations.0.plugin"), "drill");
    assert_eq!(get("flowlight.mutations.0.probability"), "0.25");
    assert_eq!(get("flowlight.mutations.0.param.width"), "\"wide\"");
    // Drill's cap follows `width` when not given.
    assert_eq!(get("flowlight.mutations.0.param.cap_degrees"), "10.0");
    assert_eq!(get("flowlight.mutations.1.probability"), "0.75");
    assert_eq!(get("flowlight.mutations.1.param.r1"), "0.1");
    assert_eq!(get("flowlight.mutations.1.param.free_chains"), "true");
}
