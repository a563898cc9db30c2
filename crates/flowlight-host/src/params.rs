//! Converts config values into the C-ABI parameter list, checked against a plugin's specs.

use flowlight_sdk::abi::{ParamSpec, ParamValue, StrRef};
use flowlight_sdk::ParamKind;

/// Parameter values with the strings they point into; keep alive while the plugin reads them.
#[derive(Debug)]
pub struct ParamList {
    _names: Vec<String>,
    _strings: Vec<String>,
    values: Vec<ParamValue>,
}

impl ParamList {
    pub fn as_slice(&self) -> &[ParamValue] {
        &self.values
    }

    /// Adds the mark of a defaulted mutation list: a [`ParamKind::MutationList`] value under
    /// the list's name, `int` its number of entries (ABI 7; the config cannot set one,
    /// [`build_params`] refuses it).
    pub fn mark_defaulted_list(&mut self, name: &str, count: usize) {
        self._names.push(name.to_string());
        // The String's heap buffer does not move when the Vec grows: the StrRef stays valid.
        let name = self._names.last().expect("just pushed");
        self.values.push(ParamValue {
            name: StrRef::new(name),
            kind: ParamKind::MutationList,
            int: count as i64,
            float: 0.0,
            boolean: 0,
            string: StrRef::EMPTY,
        });
    }
}

/// Describes a TOML value's type for messages.
fn toml_type(v: &toml::Value) -> &'static str {
    match v {
        toml::Value::String(_) => "string",
        toml::Value::Integer(_) => "integer",
        toml::Value::Float(_) => "float",
        toml::Value::Boolean(_) => "boolean",
        toml::Value::Datetime(_) => "datetime",
        toml::Value::Array(_) => "array",
        toml::Value::Table(_) => "table",
    }
}

/// Checks `values` against `specs` (unknown names and wrong types are errors naming the
/// parameter) and builds the list a plugin's `create` receives. `owner` names the plugin in
/// messages.
pub fn build_params(
    owner: &str,
    specs: &[ParamSpec],
    values: &[(String, toml::Value)],
) -> Result<ParamList, String> {
    // SAFETY: specs come from a loaded plugin's static declaration.
    let spec_names: Vec<&str> = specs.iter().map(|s| unsafe { s.name.as_str() }).collect();
    let mut names = Vec::with_capacity(values.len());
    let mut strings = Vec::with_capacity(values.len());
    let mut kinds = Vec::with_capacity(values.len());
    for (key, value) in values {
        let Some(i) = spec_names.iter().position(|n| n == key) else {
            return Err(format!(
                "unknown parameter '{key}' for plugin '{owner}' (it accepts: {})",
                spec_names.join(", ")
            ));
        };
        let kind = specs[i].kind;
        if kind == ParamKind::MutationList {
            return Err(format!("parameter '{key}' of plugin '{owner}' is a list of mutation plugins, handled by the host"));
        }
        let ok = matches!(
            (kind, value),
            (ParamKind::Int, toml::Value::Integer(_))
                | (
                    ParamKind::Float,
                    toml::Value::Float(_) | toml::Value::Integer(_)
                )
                | (ParamKind::Bool, toml::Value::Boolean(_))
                | (ParamKind::String, toml::Value::String(_))
        );
        if !ok {
            return Err(format!(
                "parameter '{key}' of plugin '{owner}' must be a {}, got a {}",
                kind.name(),
                toml_type(value)
            ));
        }
        names.push(key.clone());
        strings.push(match value {
            toml::Value::String(s) => s.clone(),
            _ => String::new(),
        });
        kinds.push(kind);
    }
    // Build the values only now: the Strings no longer move, so their pointers stay valid.
    let values: Vec<ParamValue> = values
        .iter()
        .enumerate()
        .map(|(i, (_, v))| {
            let kind = match (kinds[i], v) {
                (ParamKind::Float, toml::Value::Integer(_)) => ParamKind::Int,
                (k, _) => k,
            };
            ParamValue {
                name: StrRef::new(&names[i]),
                kind,
                int: v.as_integer().unwrap_or(0),
                float: v.as_float().unwrap_or(0.0),
                boolean: v.as_bool().unwrap_or(false) as u32,
                string: StrRef::new(&strings[i]),
            }
        })
        .collect();
    Ok(ParamList {
        _names: names,
        _strings: strings,
        values,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_sdk::{param, Params};

    const SPECS: [ParamSpec; 3] = [
        param("depth", ParamKind::Int, "8", ""),
        param("scale", ParamKind::Float, "1.0", ""),
        param("mode", ParamKind::String, "\"a\"", ""),
    ];

    #[test]
    fn values_round_trip_through_the_abi() {
        let values = vec![
            ("depth".to_string(), toml::Value::Integer(5)),
            ("scale".to_string(), toml::Value::Integer(2)),
            ("mode".to_string(), toml::Value::String("b".into())),
        ];
        let list = build_params("t", &SPECS, &values).unwrap();
        let p = Params::from_slice(list.as_slice());
        assert_eq!(p.int("depth", 0).unwrap(), 5);
        assert_eq!(p.float("scale", 0.0).unwrap(), 2.0);
        assert_eq!(p.string("mode", "").unwrap(), "b");
        assert_eq!(p.int("missing", 7).unwrap(), 7);
    }

    #[test]
    fn unknown_and_mistyped_parameters_are_named() {
        let e =
            build_params("mcpt", &SPECS, &[("dpeth".into(), toml::Value::Integer(1))]).unwrap_err();
        assert!(
            e.contains("unknown parameter 'dpeth'") && e.contains("depth"),
            "{e}"
        );
        let e = build_params(
            "mcpt",
            &SPECS,
            &[("depth".into(), toml::Value::String("x".into()))],
        )
        .unwrap_err();
        assert!(
            e.contains("'depth'") && e.contains("integer") && e.contains("string"),
            "{e}"
        );
    }
}
