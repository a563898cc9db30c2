//! Plugin parameters: declared by the plugin, validated by the host, read by the plugin.

use crate::abi::{ParamSpec, ParamValue, StrRef};

/// Type of a parameter value.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    Int = 0,
    Float = 1,
    Bool = 2,
    String = 3,
    /// `[[integrator.mutations]]`: an array of tables, each naming a mutation plugin, its
    /// `weight` and its parameters. The host loads those plugins and hands them to `create`.
    MutationList = 4,
}

impl ParamKind {
    pub fn name(self) -> &'static str {
        match self {
            ParamKind::Int => "integer",
            ParamKind::Float => "float",
            ParamKind::Bool => "boolean",
            ParamKind::String => "string",
            ParamKind::MutationList => "mutation list",
        }
    }
}

/// Declares a parameter in a plugin's `PARAMS` list.
pub const fn param(
    name: &'static str,
    kind: ParamKind,
    default: &'static str,
    doc: &'static str,
) -> ParamSpec {
    ParamSpec {
        name: StrRef::new(name),
        kind,
        default: StrRef::new(default),
        doc: StrRef::new(doc),
    }
}

/// The parameter values a plugin instance was created with (only those the config set).
pub struct Params<'a> {
    values: &'a [ParamValue],
}

impl<'a> Params<'a> {
    /// # Safety
    /// `values` must point to `count` valid entries whose strings outlive `'a`.
    pub unsafe fn from_raw(values: *const ParamValue, count: usize) -> Params<'a> {
        // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
        // ABI rules in `abi.rs` for the C entry points).
        unsafe {
            let values = if values.is_null() || count == 0 {
                &[][..]
            } else {
                std::slice::from_raw_parts(values, count)
            };
            Params { values }
        }
    }

    pub fn from_slice(values: &'a [ParamValue]) -> Params<'a> {
        Params { values }
    }

    fn find(&self, name: &str) -> Option<&'a ParamValue> {
        // SAFETY: names are valid for 'a by construction.
        self.values
            .iter()
            .find(|v| unsafe { v.name.as_str() } == name)
    }

    /// Integer parameter, or `default` when absent. A float given for an int is an error.
    pub fn int(&self, name: &str, default: i64) -> Result<i64, String> {
        match self.find(name) {
            None => Ok(default),
            Some(v) if v.kind == ParamKind::Int => Ok(v.int),
            Some(v) => Err(format!(
                "parameter '{name}' must be an integer, got a {}",
                v.kind.name()
            )),
        }
    }

    /// Float parameter; integers are accepted and converted.
    pub fn float(&self, name: &str, default: f64) -> Result<f64, String> {
        match self.find(name) {
            None => Ok(default),
            Some(v) if v.kind == ParamKind::Float => Ok(v.float),
            Some(v) if v.kind == ParamKind::Int => Ok(v.int as f64),
            Some(v) => Err(format!(
                "parameter '{name}' must be a number, got a {}",
                v.kind.name()
            )),
        }
    }

    pub fn boolean(&self, name: &str, default: bool) -> Result<bool, String> {
        match self.find(name) {
            None => Ok(default),
            Some(v) if v.kind == ParamKind::Bool => Ok(v.boolean != 0),
            Some(v) => Err(format!(
                "parameter '{name}' must be a boolean, got a {}",
                v.kind.name()
            )),
        }
    }

    pub fn string(&self, name: &str, default: &'a str) -> Result<&'a str, String> {
        match self.find(name) {
            None => Ok(default),
            // SAFETY: strings are valid for 'a by construction.
            Some(v) if v.kind == ParamKind::String => Ok(unsafe { v.string.as_str() }),
            Some(v) => Err(format!(
                "parameter '{name}' must be a string, got a {}",
                v.kind.name()
            )),
        }
    }

    /// A string parameter that must be one of `choices`.
    pub fn choice(
        &self,
        name: &str,
        default: &'a str,
        choices: &[&str],
    ) -> Result<&'a str, String> {
        let s = self.string(name, default)?;
        if choices.contains(&s) {
            Ok(s)
        } else {
            Err(format!(
                "parameter '{name}' must be one of {choices:?}, got \"{s}\""
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value(name: &'static str, kind: ParamKind) -> ParamValue {
        ParamValue {
            name: StrRef::new(name),
            kind,
            int: 0,
            float: 0.0,
            boolean: 0,
            string: StrRef::EMPTY,
        }
    }

    fn values() -> Vec<ParamValue> {
        vec![
            ParamValue {
                int: -3,
                ..value("depth", ParamKind::Int)
            },
            ParamValue {
                float: 0.25,
                ..value("scale", ParamKind::Float)
            },
            ParamValue {
                boolean: 1,
                ..value("layers", ParamKind::Bool)
            },
            ParamValue {
                string: StrRef::new("wide"),
                ..value("width", ParamKind::String)
            },
        ]
    }

    #[test]
    fn set_values_are_read_and_absent_ones_default() {
        let v = values();
        let p = Params::from_slice(&v);
        assert_eq!(p.int("depth", 8), Ok(-3));
        assert_eq!(p.float("scale", 1.0), Ok(0.25));
        assert_eq!(p.boolean("layers", false), Ok(true));
        assert_eq!(p.string("width", "narrow"), Ok("wide"));
        assert_eq!(p.int("absent", 8), Ok(8));
        assert_eq!(p.float("absent", 1.5), Ok(1.5));
        assert_eq!(p.boolean("absent", true), Ok(true));
        assert_eq!(p.string("absent", "d"), Ok("d"));
        // An integer where a float is asked for converts exactly.
        assert_eq!(p.float("depth", 0.0), Ok(-3.0));
        // SAFETY: a null list of length 0 is the empty list.
        let none = unsafe { Params::from_raw(std::ptr::null(), 0) };
        assert_eq!(none.int("depth", 8), Ok(8));
    }

    #[test]
    fn wrong_kinds_and_choices_are_errors_naming_the_parameter() {
        let v = values();
        let p = Params::from_slice(&v);
        assert_eq!(
            p.int("scale", 0),
            Err("parameter 'scale' must be an integer, got a float".into())
        );
        assert_eq!(
            p.float("width", 0.0),
            Err("parameter 'width' must be a number, got a string".into())
        );
        assert_eq!(
            p.boolean("depth", false),
            Err("parameter 'depth' must be a boolean, got a integer".into())
        );
        assert_eq!(
            p.string("layers", ""),
            Err("parameter 'layers' must be a string, got a boolean".into())
        );
        assert_eq!(p.choice("width", "narrow", &["narrow", "wide"]), Ok("wide"));
        assert_eq!(
            p.choice("width", "narrow", &["narrow", "medium"]),
            Err("parameter 'width' must be one of [\"narrow\", \"medium\"], got \"wide\"".into())
        );
        assert_eq!(p.choice("absent", "narrow", &["narrow"]), Ok("narrow"));
    }
}
