//! The committed benchmark scenes are what `make-scenes` writes: edit
//! `crates/flowlight-testkit/src/scenes.rs` and run it, never the files.

use serde_json::Value;

/// `a` and `b` equal as JSON, numbers within a relative 1e-12 (the same values printed
/// another way), everything else exactly.
fn same(a: &Value, b: &Value, at: &str) -> Result<(), String> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            if (x - y).abs() <= 1e-12 * x.abs().max(y.abs()) {
                Ok(())
            } else {
                Err(format!("{at}: {x} vs {y}"))
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .try_for_each(|(i, (p, q))| same(p, q, &format!("{at}[{i}]"))),
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => {
            x.iter().try_for_each(|(k, v)| {
                let w = y.get(k).ok_or_else(|| format!("{at}.{k}: missing"))?;
                same(v, w, &format!("{at}.{k}"))
            })
        }
        _ if a == b => Ok(()),
        _ => Err(format!("{at}: {a} vs {b}")),
    }
}

#[test]
fn the_committed_scenes_are_what_make_scenes_writes() {
    let dir = flowlight_testkit::scenes_dir();
    for (name, gltf, toml, triangles) in flowlight_testkit::scenes::all() {
        let path = dir.join(name).join(format!("{name}.gltf"));
        let committed = std::fs::read_to_string(&path).unwrap();
        let parse = |t: &str| serde_json::from_str::<Value>(t).unwrap();
        same(&parse(&gltf), &parse(&committed), name)
            .unwrap_or_else(|e| panic!("{}: {e} (run make-scenes)", path.display()));
        let cfg = dir.join(name).join(format!("{name}.toml"));
        assert_eq!(
            toml,
            std::fs::read_to_string(&cfg).unwrap(),
            "{} (run make-scenes)",
            cfg.display()
        );
        assert!(triangles >= 20, "{name}: {triangles} triangles");
    }
}
