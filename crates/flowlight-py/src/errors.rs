//! The exceptions: `flowlight.Error` and one subclass per kind of failure. Each carries the
//! command line's message, the text after `error: ` that `flowlight render` prints, made the
//! same way (anyhow's `{:#}` of the error and its sources).

use flowlight_host::HostError;
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _native,
    Error,
    PyException,
    "Every error Flowlight raises; the message is the command line's one line."
);
create_exception!(
    _native,
    ConfigError,
    Error,
    "A config (file or dict) or a `set` key is wrong."
);
create_exception!(
    _native,
    SceneError,
    Error,
    "The scene, its lights or its intersector could not be loaded."
);
create_exception!(
    _native,
    PluginError,
    Error,
    "A plugin was not found, was refused, or refused its parameters."
);
create_exception!(
    _native,
    RenderError,
    Error,
    "A plugin failed during a render."
);
create_exception!(
    _native,
    OutputError,
    Error,
    "An image could not be read or written."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("Error", py.get_type::<Error>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("PluginError", py.get_type::<PluginError>())?;
    m.add("RenderError", py.get_type::<RenderError>())?;
    m.add("OutputError", py.get_type::<OutputError>())?;
    Ok(())
}

/// `e` as the exception of its kind, with the command line's text.
pub fn host_error(e: HostError) -> PyErr {
    let kind = match &e {
        HostError::Scene(_) | HostError::Lights { .. } | HostError::Intersector { .. } => 1,
        HostError::Plugin { .. } => 2,
        HostError::Render(_) => 3,
        HostError::OutNotExr { .. }
        | HostError::OutputIsInput { .. }
        | HostError::WrongExtension { .. }
        | HostError::SameOutput { .. }
        | HostError::Output { .. }
        | HostError::PartFile(_) => 4,
        _ => 0,
    };
    let text = format!("{:#}", anyhow::Error::new(e));
    match kind {
        1 => SceneError::new_err(text),
        2 => PluginError::new_err(text),
        3 => RenderError::new_err(text),
        4 => OutputError::new_err(text),
        _ => ConfigError::new_err(text),
    }
}

/// A configuration mistake found here (an argument of a call), as `ConfigError`.
pub fn config(text: impl Into<String>) -> PyErr {
    ConfigError::new_err(text.into())
}

/// A file that could not be read or written, as `OutputError`.
pub fn output(text: impl std::fmt::Display) -> PyErr {
    OutputError::new_err(text.to_string())
}
