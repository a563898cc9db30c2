//! Plugin parameters as the docs show them, and as the outputs record them.
//!
//! Both come from the plugin's declarations, never from a hand-written copy:
//!
//! * [`markdown_table`]: the table `flowlight plugins --markdown` prints and the docs hold
//!   between the markers [`begin_marker`] and [`END_MARKER`] (`<!-- params:mcpt -->` …
//!   `<!-- /params -->`); the test house compares every marked table with the loaded
//!   plugin's, so a doc cannot drift from the code.
//! * [`metadata_entries`]: the values an integrator and its mutations resolved (after
//!   defaults), written into the EXR header as `flowlight.param.NAME` and
//!   `flowlight.mutations.I.plugin` / `.probability` / `.param.NAME`.

use crate::plugin::{IntegratorInstance, ParamInfo};
use flowlight_sdk::ParamRole;

/// The line that closes a generated parameter table in the docs.
pub const END_MARKER: &str = "<!-- /params -->";

/// The line that opens plugin `name`'s generated parameter table in the docs.
pub fn begin_marker(name: &str) -> String {
    format!("<!-- params:{name} -->")
}

/// One markdown table row per parameter: name, type, default, values accepted, role (when
/// it has one) and meaning. `|` in a cell is escaped.
pub fn markdown_table(params: &[ParamInfo]) -> String {
    let cell = |s: &str| s.replace('|', "\\|");
    let code = |s: &str| {
        if s.is_empty() {
            String::new()
        } else {
            format!("`{}`", cell(s))
        }
    };
    let mut out =
        String::from("| parameter | type | default | values | meaning |\n|---|---|---|---|---|\n");
    for p in params {
        let role = match p.role {
            ParamRole::None => String::new(),
            r => format!(" (role: {r:?})"),
        };
        let default = if p.default.starts_with('(') || p.default.starts_with("by ") {
            cell(&p.default)
        } else {
            code(&p.default)
        };
        out.push_str(&format!(
            "| `{}` | {} | {} | {} | {}{} |\n",
            p.name,
            p.kind.name(),
            default,
            code(&p.range),
            cell(&p.doc),
            role
        ));
    }
    out
}

/// Plugin `name`'s table between its markers, as the docs hold it.
pub fn marked_block(name: &str, params: &[ParamInfo]) -> String {
    format!(
        "{}\n{}{END_MARKER}\n",
        begin_marker(name),
        markdown_table(params)
    )
}

/// The text between plugin `name`'s markers in `doc` (the table, newline-terminated), or
/// `None` when `doc` has no such block.
pub fn docs_table<'a>(doc: &'a str, name: &str) -> Option<&'a str> {
    let begin = begin_marker(name);
    let start = doc.find(&format!("{begin}\n"))? + begin.len() + 1;
    let len = doc[start..].find(END_MARKER)?;
    Some(&doc[start..start + len])
}

/// The resolved parameters of `instance` and of its mutations, as EXR metadata entries.
pub fn metadata_entries(instance: &IntegratorInstance) -> Vec<(String, String)> {
    let mut entries: Vec<(String, String)> = instance
        .resolved_params()
        .into_iter()
        .map(|(k, v)| (format!("flowlight.param.{k}"), v))
        .collect();
    for (i, m) in instance.mutations().iter().enumerate() {
        let at = format!("flowlight.mutations.{i}");
        entries.push((format!("{at}.plugin"), m.plugin().name.clone()));
        entries.push((format!("{at}.probability"), m.weight().to_string()));
        entries.extend(
            m.resolved_params()
                .into_iter()
                .map(|(k, v)| (format!("{at}.param.{k}"), v)),
        );
    }
    entries
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_sdk::ParamKind;

    fn info(name: &str, default: &str, range: &str, doc: &str, role: ParamRole) -> ParamInfo {
        ParamInfo {
            name: name.into(),
            kind: ParamKind::Int,
            default: default.into(),
            range: range.into(),
            doc: doc.into(),
            role,
        }
    }

    #[test]
    fn a_table_has_one_row_per_parameter_and_escapes_bars() {
        let t = markdown_table(&[
            info("path_depth", "8", "1..=32", "depth N", ParamRole::PathDepth),
            info("x", "(required)", "", "a | b", ParamRole::None),
        ]);
        assert_eq!(
            t,
            "| parameter | type | default | values | meaning |\n|---|---|---|---|---|\n\
             | `path_depth` | integer | `8` | `1..=32` | depth N (role: PathDepth) |\n\
             | `x` | integer | (required) |  | a \\| b |\n"
        );
    }

    #[test]
    fn the_docs_table_is_found_between_its_markers() {
        let params = [info("a", "1", "", "one", ParamRole::None)];
        let doc = format!("intro\n\n{}\nafter\n", marked_block("p", &params));
        assert_eq!(
            docs_table(&doc, "p"),
            Some(markdown_table(&params).as_str())
        );
        assert_eq!(docs_table(&doc, "q"), None);
        assert_eq!(docs_table("<!-- params:p -->\nno end", "p"), None);
    }
}
