//! Python values as TOML values: a config given as a dict has the keys and values of the TOML
//! file (so it is parsed by the same code and refused with the same messages), and a render's
//! `set={...}` holds what `--set KEY=VALUE` would.

use crate::errors;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

/// `value` as TOML: bool, int, float, str (or an `os.PathLike`), list/tuple, dict with str
/// keys. `at` names the key in errors.
pub fn to_toml(value: &Bound<'_, PyAny>, at: &str) -> PyResult<toml::Value> {
    if value.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(value.extract()?));
    }
    if value.is_instance_of::<PyInt>() {
        let n: i64 = value
            .extract()
            .map_err(|_| errors::config(format!("{at}: integer {value} is out of TOML's range")))?;
        return Ok(toml::Value::Integer(n));
    }
    if value.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(value.extract()?));
    }
    if value.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(value.extract()?));
    }
    if let Ok(d) = value.cast::<PyDict>() {
        return Ok(toml::Value::Table(to_table(d, at)?));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items = value
            .try_iter()?
            .enumerate()
            .map(|(i, v)| to_toml(&v?, &format!("{at}[{i}]")))
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(toml::Value::Array(items));
    }
    // A path (pathlib.Path and other os.PathLike) as its text.
    if let Ok(p) = value.py().import("os")?.call_method1("fspath", (value,)) {
        if let Ok(s) = p.extract::<String>() {
            return Ok(toml::Value::String(s));
        }
    }
    // numpy scalars and other numbers.
    if let Ok(f) = value.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    Err(errors::config(format!(
        "{at}: a value of type {} has no TOML form",
        value.get_type().name()?
    )))
}

/// A dict with str keys as a TOML table; `at` prefixes the keys in errors.
pub fn to_table(d: &Bound<'_, PyDict>, at: &str) -> PyResult<toml::Table> {
    let mut t = toml::Table::new();
    for (k, v) in d.iter() {
        let key: String = k
            .extract()
            .map_err(|_| errors::config(format!("{at}: the key {k} is not a string")))?;
        let path = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        t.insert(key, to_toml(&v, &path)?);
    }
    Ok(t)
}

/// A render's `set={...}` as `--set` pairs, in the dict's order.
pub fn sets(d: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, toml::Value)>> {
    let Some(d) = d else {
        return Ok(Vec::new());
    };
    d.iter()
        .map(|(k, v)| {
            let key: String = k
                .extract()
                .map_err(|_| errors::config(format!("set: the key {k} is not a string")))?;
            let value = to_toml(&v, &format!("set {key}"))?;
            Ok((key, value))
        })
        .collect()
}
