//! The committed references of the project's suites (`scenes/<scene>/reference/`): each
//! loads, is the suite's size, carries the floor, spp, seeds and path depth it was made with in
//! its metadata, and a scene of another size or depth refuses it. No rendering: this reads
//! files only.

use flowlight_bench::{check_reference_matches, load_suite, read_reference};
use std::path::{Path, PathBuf};

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

#[test]
fn committed_references_load_with_their_recorded_floor_and_match_their_scenes() {
    let suite = load_suite(&scenes().join("experiments/suite-erpt.toml")).unwrap();
    assert!(suite.scenes.len() >= 6, "the five scenes and the ring");
    for s in &suite.scenes {
        let path = s.committed_reference.clone().unwrap();
        assert!(path.exists(), "{} is not committed", path.display());
        let r = read_reference(&path).unwrap();
        let get = |k: &str| {
            r.meta_value(k)
                .unwrap_or_else(|| panic!("{}: no {k}", path.display()))
                .to_string()
        };
        // The floor recomputed from the variance layer is the recorded one (6 digits).
        // (Read from the header itself: a loaded reference recomputes its floor.)
        let header = flowlight_host::output::read_exr_metadata(&path).unwrap();
        let recorded: f64 = header
            .get(flowlight_bench::reference::FLOOR_KEY)
            .unwrap()
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let floor = r.floor().unwrap();
        assert!(
            (floor / recorded - 1.0).abs() < 1e-4,
            "{}: floor {floor} vs recorded {recorded}",
            s.name
        );
        assert!(floor > 0.0 && floor < 0.05, "{}: floor {floor}", s.name);
        // The total spp is the two halves' (seeds 1000000 and 1000001).
        let halves = get("flowlight.reference.halves");
        let parts: Vec<f64> = halves
            .split('+')
            .map(|h| h.split_whitespace().next().unwrap().parse().unwrap())
            .collect();
        assert_eq!(parts.len(), 2, "{halves}");
        assert!(parts.iter().all(|&n| n >= 256.0), "{}: {halves}", s.name);
        assert!(
            (parts[0] + parts[1] - r.spp).abs() < 1e-6,
            "{}: {halves}",
            s.name
        );
        assert!(halves.contains("(seed 1000000)") && halves.contains("(seed 1000001)"));
        assert!(get("flowlight.seed").contains("1000000 and 1000001"));
        assert!(get("flowlight.reference.command").contains("reference"));
        // Lighting layers: the main image is their sum.
        let depth = r.path_depth().unwrap() as usize;
        assert_eq!(r.layers.len(), depth + 1, "{}", s.name);
        let sum: f64 = r
            .layers
            .iter()
            .flat_map(|(_, l)| l.iter())
            .map(|c| c.luminance() as f64)
            .sum();
        let main: f64 = r.image.iter().map(|c| c.luminance() as f64).sum();
        assert!(
            (sum / main - 1.0).abs() < 1e-3,
            "{}: {sum} vs {main}",
            s.name
        );

        // It matches its scene at the suite's size and depth ...
        let mut cfg = flowlight_scene::config::load_config(&s.config).unwrap();
        cfg.width = s.width.unwrap();
        cfg.height = s.height.unwrap();
        check_reference_matches(&r, &path, &s.name, &cfg).unwrap();
        // ... and is refused at another size, or for another path depth.
        let mut small = cfg.clone();
        small.width = 64;
        small.height = 64;
        let e = check_reference_matches(&r, &path, &s.name, &small).unwrap_err();
        assert!(e.contains("128x128") && e.contains("64x64"), "{e}");
        let mut deeper = cfg.clone();
        deeper.integrator_params.retain(|(k, _)| k != "path_depth");
        deeper
            .integrator_params
            .push(("path_depth".into(), toml::Value::Integer(depth as i64 + 3)));
        let e = check_reference_matches(&r, &path, &s.name, &deeper).unwrap_err();
        assert!(e.contains(&format!("path_depth {depth}")), "{e}");
    }
}

/// The bidirectional suite: the four research scenes and every scene of `scenes/suite.toml`,
/// each with its committed reference (a VCM one would be rendered for a scene without); every
/// config loads, and the methods are MCPT (the baseline), the three bidirectional plugins and
/// ERPT.
#[test]
fn the_bidirectional_suite_covers_every_suite_and_research_scene_with_committed_references() {
    let suite = load_suite(&scenes().join("experiments/suite-bidir.toml")).unwrap();
    assert_eq!(suite.reference_plugin.as_deref(), Some("vcm"));
    assert_eq!(suite.baseline, "mcpt-entangled-throughput");
    let names: Vec<&str> = suite.scenes.iter().map(|s| s.name.as_str()).collect();
    let main = load_suite(&scenes().join("suite.toml")).unwrap();
    let mut expected = vec!["veach-door", "water-pool", "veach-mis", "lamp-shade"];
    expected.extend(main.scenes.iter().map(|s| s.name.as_str()));
    let (mut sorted, mut want) = (names.clone(), expected.clone());
    sorted.sort_unstable();
    want.sort_unstable();
    assert_eq!(sorted, want);
    for s in &suite.scenes {
        flowlight_scene::config::load_config(&s.config)
            .unwrap_or_else(|e| panic!("{}: {e}", s.name));
        let committed = s.committed_reference.as_ref().is_some_and(|p| p.exists());
        assert!(committed, "{}: no committed reference", s.name);
    }
    let plugins: Vec<&str> = suite
        .methods
        .iter()
        .map(|m| m.plugin.as_deref().unwrap())
        .collect();
    assert_eq!(plugins, ["mcpt", "lighttrace", "bdpt", "vcm", "erpt"]);
}

/// The cross-family suite: every scene of the bidirectional suite plus the two caustic scenes
/// kept out of tuning, each with a committed reference that matches it at the suite's size
/// and depth; one method per family (and the hand-tuned ERPT configs, found beside the scenes
/// of `scenes/suite.toml` only).
#[test]
fn the_cross_family_suite_covers_every_scene_with_matching_references() {
    let suite = load_suite(&scenes().join("experiments/suite-mcmc.toml")).unwrap();
    let bidir = load_suite(&scenes().join("experiments/suite-bidir.toml")).unwrap();
    let main = load_suite(&scenes().join("suite.toml")).unwrap();
    let mut want: Vec<&str> = bidir.scenes.iter().map(|s| s.name.as_str()).collect();
    want.extend(["lens-spot", "glass-rod"]);
    let mut names: Vec<&str> = suite.scenes.iter().map(|s| s.name.as_str()).collect();
    want.sort_unstable();
    names.sort_unstable();
    assert_eq!(names, want);
    for s in &suite.scenes {
        let path = s.committed_reference.clone().unwrap();
        let r = read_reference(&path).unwrap_or_else(|e| panic!("{}: {e}", s.name));
        let mut cfg = flowlight_scene::config::load_config(&s.config).unwrap();
        cfg.width = s.width.unwrap();
        cfg.height = s.height.unwrap();
        check_reference_matches(&r, &path, &s.name, &cfg).unwrap();
        assert!(r.floor().is_some_and(|f| f > 0.0 && f < 0.05), "{}", s.name);
    }
    let plugins: Vec<&str> = suite
        .methods
        .iter()
        .filter_map(|m| m.plugin.as_deref())
        .collect();
    for family in ["mcpt", "bdpt", "vcm", "pssmlt", "mmlt", "erpt"] {
        assert!(plugins.contains(&family), "no {family} method");
    }
    let tuned = suite
        .methods
        .iter()
        .find(|m| m.label == "erpt-tuned")
        .unwrap();
    for s in &suite.scenes {
        let in_main = main.scenes.iter().any(|m| m.name == s.name);
        assert_eq!(tuned.runs_on(s), in_main, "{}: erpt.toml", s.name);
    }
}
