//! docs/gltf.md's table of known extensions agrees with `extensions::KNOWN`, row for row.

use flowlight_scene::extensions::{lookup, KNOWN};

#[test]
fn docs_extension_table_matches_the_loader_table() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/gltf.md");
    let doc = std::fs::read_to_string(path).unwrap();
    let start = doc
        .find("### Extensions the loader knows")
        .expect("docs/gltf.md has no '### Extensions the loader knows' section");
    let mut rows = Vec::new();
    let mut in_table = false;
    for line in doc[start..].lines().skip(1) {
        if line.starts_with('|') {
            in_table = true;
            let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
            if let Some(name) = cells[0].strip_prefix('`').and_then(|c| c.strip_suffix('`')) {
                rows.push((name.to_string(), cells[1].to_string()));
            }
        } else if in_table {
            break;
        }
    }
    for (name, status) in &rows {
        let e = lookup(name)
            .unwrap_or_else(|| panic!("docs/gltf.md lists {name}, the loader does not"));
        assert_eq!(
            status,
            e.status.doc_name(),
            "{name}: docs say {status}, the loader {:?}",
            e.status
        );
    }
    for e in KNOWN {
        assert!(
            rows.iter().any(|(n, _)| n == e.name),
            "{} is in extensions::KNOWN but not in docs/gltf.md",
            e.name
        );
    }
    assert_eq!(rows.len(), KNOWN.len(), "a row is listed twice");
}
