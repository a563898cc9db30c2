//! Plugin parameters: declared by the plugin, validated by the host, read by the plugin.
//!
//! A plugin declares each parameter once ([`crate::declare`]) and reads it through its
//! declaration; [`Params`] is the raw list of values the config set, which the declarations'
//! getters read. Every value read is recorded as resolved (the default when the config left
//! it out), and the SDK's glue hands the record to the host for the output's metadata.

use crate::abi::{ParamRole, ParamSpec, ParamValue, ResolvedList, ResolvedParam, StrRef};
use std::cell::RefCell;

/// Type of a parameter value.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    /// A TOML integer (`i64`).
    Int = 0,
    /// A TOML float; an integer is accepted and converted.
    Float = 1,
    /// A TOML boolean.
    Bool = 2,
    /// A TOML string.
    String = 3,
    /// `[[integrator.mutations]]`: an array of tables, each naming a mutation plugin, its
    /// `weight` and its parameters. The host loads those plugins and hands them to `create`.
    MutationList = 4,
}

impl ParamKind {
    /// The type's name in messages and tables (`integer`, `float`, …).
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

/// An untyped entry of a plugin's `PARAMS` list: name, type, default text and doc, no range
/// and no role. The default text is not checked against what `create` reads; prefer a
/// typed declaration ([`crate::declare`]), whose `spec()` and getters share one default.
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
        range: StrRef::EMPTY,
        doc: StrRef::new(doc),
        role: ParamRole::None,
    }
}

/// The parameter values a plugin instance was created with (only those the config set), and
/// the record of the values read from it (resolved: the default when the config left it out).
pub struct Params<'a> {
    values: &'a [ParamValue],
    resolved: RefCell<Vec<(String, String)>>,
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
            Params::from_slice(values)
        }
    }

    /// The values of a list built in Rust (tests, hosts written in Rust).
    pub fn from_slice(values: &'a [ParamValue]) -> Params<'a> {
        Params {
            values,
            resolved: RefCell::new(Vec::new()),
        }
    }

    /// Whether the config set parameter `name`.
    pub fn is_set(&self, name: &str) -> bool {
        self.find(name).is_some()
    }

    /// Whether the mutation list `name` the integrator was handed is the default its spec
    /// declares ([`crate::declare::mutation_list_or`]): the config gave no list, and the host
    /// marked the defaults it created with a [`ParamKind::MutationList`] value (ABI 7).
    pub fn mutation_list_defaulted(&self, name: &str) -> bool {
        self.find(name)
            .is_some_and(|v| v.kind == ParamKind::MutationList)
    }

    /// Records `value` (TOML text) as the resolved value of `name`, replacing an earlier
    /// record of the same name (a later read decides).
    pub fn record(&self, name: &str, value: String) {
        let mut r = self.resolved.borrow_mut();
        match r.iter_mut().find(|(n, _)| n == name) {
            Some(entry) => entry.1 = value,
            None => r.push((name.to_string(), value)),
        }
    }

    /// The resolved values read so far, in the order first read: `(name, TOML text)`.
    pub fn resolved(&self) -> Vec<(String, String)> {
        self.resolved.borrow().clone()
    }

    fn find(&self, name: &str) -> Option<&'a ParamValue> {
        // SAFETY: names are valid for 'a by construction.
        self.values
            .iter()
            .find(|v| unsafe { v.name.as_str() } == name)
    }

    /// Integer parameter, or `default` when absent. A float given for an int is an error.
    pub fn int(&self, name: &str, default: i64) -> Result<i64, String> {
        let v = self.raw_int(name, default)?;
        self.record(name, v.to_string());
        Ok(v)
    }

    /// [`Params::int`] without recording (the declarations record after their range check).
    pub(crate) fn raw_int(&self, name: &str, default: i64) -> Result<i64, String> {
        Ok(match self.find(name) {
            None => default,
            Some(v) if v.kind == ParamKind::Int => v.int,
            Some(v) => {
                return Err(format!(
                    "parameter '{name}' must be an integer, got a {}",
                    v.kind.name()
                ))
            }
        })
    }

    /// Float parameter; integers are accepted and converted.
    pub fn float(&self, name: &str, default: f64) -> Result<f64, String> {
        let v = self.raw_float(name, default)?;
        self.record(name, toml_float(v));
        Ok(v)
    }

    /// [`Params::float`] without recording.
    pub(crate) fn raw_float(&self, name: &str, default: f64) -> Result<f64, String> {
        Ok(match self.find(name) {
            None => default,
            Some(v) if v.kind == ParamKind::Float => v.float,
            Some(v) if v.kind == ParamKind::Int => v.int as f64,
            Some(v) => {
                return Err(format!(
                    "parameter '{name}' must be a number, got a {}",
                    v.kind.name()
                ))
            }
        })
    }

    /// Boolean parameter, or `default` when absent.
    pub fn boolean(&self, name: &str, default: bool) -> Result<bool, String> {
        let v = match self.find(name) {
            None => default,
            Some(v) if v.kind == ParamKind::Bool => v.boolean != 0,
            Some(v) => {
                return Err(format!(
                    "parameter '{name}' must be a boolean, got a {}",
                    v.kind.name()
                ))
            }
        };
        self.record(name, v.to_string());
        Ok(v)
    }

    /// String parameter, or `default` when absent.
    pub fn string(&self, name: &str, default: &'a str) -> Result<&'a str, String> {
        let v = self.raw_string(name, default)?;
        self.record(name, format!("{v:?}"));
        Ok(v)
    }

    /// [`Params::string`] without recording.
    pub(crate) fn raw_string(&self, name: &str, default: &'a str) -> Result<&'a str, String> {
        Ok(match self.find(name) {
            None => default,
            // SAFETY: strings are valid for 'a by construction.
            Some(v) if v.kind == ParamKind::String => unsafe { v.string.as_str() },
            Some(v) => {
                return Err(format!(
                    "parameter '{name}' must be a string, got a {}",
                    v.kind.name()
                ))
            }
        })
    }

    /// A string parameter that must be one of `choices`.
    pub fn choice(
        &self,
        name: &str,
        default: &'a str,
        choices: &[&str],
    ) -> Result<&'a str, String> {
        let s = self.raw_string(name, default)?;
        if choices.contains(&s) {
            self.record(name, format!("{s:?}"));
            Ok(s)
        } else {
            Err(format!(
                "parameter '{name}' must be one of {choices:?}, got \"{s}\""
            ))
        }
    }
}

/// The resolved values of an instance as the C ABI hands them over: the strings are boxed
/// and never move while the table lives (the SDK's glue keeps it in the instance).
#[derive(Debug)]
pub(crate) struct ResolvedTable {
    _strings: Vec<(Box<str>, Box<str>)>,
    entries: Vec<ResolvedParam>,
}

impl ResolvedTable {
    pub(crate) fn new(values: Vec<(String, String)>) -> ResolvedTable {
        let strings: Vec<(Box<str>, Box<str>)> = values
            .into_iter()
            .map(|(n, v)| (n.into_boxed_str(), v.into_boxed_str()))
            .collect();
        let entries = strings
            .iter()
            .map(|(n, v)| ResolvedParam {
                name: StrRef::new(n),
                value: StrRef::new(v),
            })
            .collect();
        ResolvedTable {
            _strings: strings,
            entries,
        }
    }

    /// This table with `decided`'s values: each replaces the entry of its name, or is
    /// appended.
    pub(crate) fn with(&self, decided: Vec<(String, String)>) -> ResolvedTable {
        let mut values: Vec<(String, String)> = self
            ._strings
            .iter()
            .map(|(n, v)| (n.to_string(), v.to_string()))
            .collect();
        for (name, value) in decided {
            match values.iter_mut().find(|(n, _)| *n == name) {
                Some(entry) => entry.1 = value,
                None => values.push((name, value)),
            }
        }
        ResolvedTable::new(values)
    }

    /// The list the host reads until `destroy`.
    pub(crate) fn list(&self) -> ResolvedList {
        ResolvedList {
            entries: if self.entries.is_empty() {
                std::ptr::null()
            } else {
                self.entries.as_ptr()
            },
            count: self.entries.len(),
        }
    }
}

/// `x` as TOML writes a float: `8.0`, `0.95`, `1e-5`, `nan`, `inf`.
pub(crate) fn toml_float(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else {
        // Debug prints the shortest text that reads back exactly, with a `.0` on integers.
        format!("{x:?}")
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
