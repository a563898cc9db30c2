//! The plugin boundary: real plugins load from disk, mismatches and missing plugins are
//! refused with clear errors.

mod common;

use flowlight_host::plugin::{
    find_plugin, plugin_file_name, search_dirs, PluginError, PluginLibrary,
};
use flowlight_host::session::{Overrides, Session};
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
        msg.contains(&(ABI_VERSION + 100).to_string()) && msg.contains(&ABI_VERSION.to_string()),
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
    let err = Session::prepare(&cfg, &Overrides::default())
        .err()
        .expect("missing plugin accepted");
    assert!(err.contains("no-such-integrator"), "{err}");
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
    let err = Session::prepare(&common::scene_config("furnace/furnace.toml"), &ov)
        .err()
        .expect("typo accepted");
    assert!(err.contains("path_dpeth") && err.contains("mcpt"), "{err}");
    let ov = Overrides {
        params: common::toml_params(&[("variant", "sideways".into())]),
        ..Default::default()
    };
    let err = Session::prepare(&common::scene_config("furnace/furnace.toml"), &ov)
        .err()
        .expect("bad value accepted");
    assert!(err.contains("variant") && err.contains("sideways"), "{err}");
}

#[test]
fn the_real_plugin_renders_an_image() {
    let s = common::session("furnace/furnace.toml", 4, &[]);
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
    let err = Session::from_config(cfg.clone(), &ov)
        .err()
        .expect("create error ignored");
    assert!(
        err.contains("test-panic") && err.contains("asked to fail in create"),
        "{err}"
    );

    let ov = Overrides {
        spp: Some(1),
        threads: Some(2),
        ..Default::default()
    };
    let s = Session::from_config(cfg, &ov).unwrap();
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
