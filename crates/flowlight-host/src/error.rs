//! What can go wrong in a [`Renderer`](crate::renderer::Renderer): one typed error, so that
//! callers (tests, the bench, the conformance kit) match on what failed instead of on the
//! wording, while users keep reading the same one-line message.
//!
//! Each variant's `Display` is the message the host has always printed: the file at fault
//! first, then the field or plugin, then the cause. The variants keep the parts apart (the
//! config file, the key, the underlying [`ConfigError`], [`SceneError`], [`PluginError`] or
//! [`OutputError`]).
//!
//! No variant reports a [`source`](std::error::Error::source): every message already ends
//! with its cause, and the CLI prints errors with `{:#}` (anyhow's cause chain), which would
//! print the cause a second time.

use crate::output::OutputError;
use crate::plugin::PluginError;
use flowlight_scene::{ConfigError, SceneError};
use std::fmt;
use std::path::PathBuf;

/// Why a [`Renderer`](crate::renderer::Renderer) could not be prepared, configured, rendered or
/// written.
#[derive(Debug)]
pub enum HostError {
    /// The render config could not be read, or one of its values is wrong (the checks of
    /// `flowlight-scene`: syntax, types, ranges, the camera, the environment).
    Config(ConfigError),
    /// The glTF scene the config names could not be loaded.
    Scene(SceneError),
    /// A config value the host itself checks, `{file}: {field}: {msg}` (e.g.
    /// `render.build_quality`, an entry of `integrator.mutations`).
    Field {
        file: PathBuf,
        field: String,
        msg: String,
    },
    /// The integrator's mutation list (`{file}: {msg}`, the message naming
    /// `integrator.<list>` or its entry `integrator.<list>[i]`).
    Mutations { file: PathBuf, msg: String },
    /// The scene's lights cannot be rendered (`{file}: {msg}`: an emission beyond what an
    /// `f32` holds, named by the message).
    Lights { file: PathBuf, msg: String },
    /// `--set render.{key}` for a render key the command line cannot set.
    NotSettable { file: PathBuf, key: String },
    /// `--out` names something other than the EXR image.
    OutNotExr { out: PathBuf },
    /// The image buffers would not fit in memory or the address space; `file` is the config
    /// when the check ran while preparing, `None` when it ran at the start of the render.
    Memory { file: Option<PathBuf>, msg: String },
    /// The intersector named by the config could not be built.
    Intersector { file: PathBuf, msg: String },
    /// An environment variable the host reads has a bad value (`FLOWLIGHT_EMBREE_PACKETS`).
    Variable(String),
    /// A plugin could not be found, loaded or created; `file` and `field` say where the
    /// config named it, when the message gives them. Boxed: the other variants are small,
    /// and every `Result` of a `Renderer` carries the largest.
    Plugin {
        file: Option<PathBuf>,
        field: Option<String>,
        error: Box<PluginError>,
    },
    /// `--part`/`--samples` refused for this config.
    Part { file: PathBuf, refusal: PartRefusal },
    /// A distributed part's file could not be hashed, read or written (the message names the
    /// file).
    PartFile(String),
    /// An output path is one of the render's inputs.
    OutputIsInput {
        file: PathBuf,
        what: &'static str,
        output: PathBuf,
        input: &'static str,
    },
    /// An output's name does not end in its format's extension (`wanted`).
    WrongExtension {
        file: PathBuf,
        what: &'static str,
        output: PathBuf,
        wanted: &'static str,
    },
    /// Two outputs are one file.
    SameOutput {
        file: PathBuf,
        what: &'static str,
        other: &'static str,
        output: PathBuf,
    },
    /// An output cannot be written; `file` and `what` are given when the check ran before
    /// rendering (`{file}: {what}: {error}`).
    Output {
        file: Option<PathBuf>,
        what: Option<&'static str>,
        error: OutputError,
    },
    /// The render could not start (thread pool, accumulation settings).
    Render(String),
}

/// Why a config cannot be rendered in parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PartRefusal {
    /// Parts need a fixed number of samples.
    TimeBudget,
    /// Parts merge exact sums.
    NotExact,
}

impl fmt::Display for HostError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HostError::Config(e) => write!(f, "{e}"),
            HostError::Scene(e) => write!(f, "{e}"),
            HostError::Field { file, field, msg } => {
                write!(f, "{}: {field}: {msg}", file.display())
            }
            HostError::NotSettable { file, key } => write!(
                f,
                "{}: --set {key}: only render.accumulation, render.precision, render.accumulation_cache_mib and render.flange can be set from the command line",
                file.display()
            ),
            HostError::OutNotExr { out } => write!(
                f,
                "--out {}: --out names the EXR image (e.g. x.exr); the PNG preview is written beside it",
                out.display()
            ),
            HostError::Memory { file, msg } => {
                if let Some(file) = file {
                    write!(f, "{}: ", file.display())?;
                }
                write!(f, "{msg}")
            }
            HostError::Mutations { file, msg } | HostError::Intersector { file, msg } => {
                write!(f, "{}: {msg}", file.display())
            }
            HostError::Variable(msg) | HostError::PartFile(msg) | HostError::Render(msg) => {
                write!(f, "{msg}")
            }
            HostError::Plugin { file, field, error } => {
                if let Some(file) = file {
                    write!(f, "{}: ", file.display())?;
                }
                if let Some(field) = field {
                    write!(f, "{field}: ")?;
                }
                write!(f, "{error}")
            }
            HostError::Part { file, refusal } => {
                let why = match refusal {
                    PartRefusal::TimeBudget => {
                        "need a sample budget (render.spp or --spp), not a time budget"
                    }
                    PartRefusal::NotExact => {
                        "need render.precision = \"exact\": parts merge exact sums, and f32 sums would not add up to the full render"
                    }
                };
                write!(f, "{}: --part/--samples {why}", file.display())
            }
            HostError::Lights { file, msg } => write!(f, "{}: {msg}", file.display()),
            HostError::WrongExtension {
                file,
                what,
                output,
                wanted,
            } => write!(
                f,
                "{}: {what} {} must end in .{wanted}: the file is written in that format whatever its name",
                file.display(),
                output.display()
            ),
            HostError::OutputIsInput {
                file,
                what,
                output,
                input,
            } => write!(
                f,
                "{}: {what} {} is {input}; refusing to overwrite an input",
                file.display(),
                output.display()
            ),
            HostError::SameOutput {
                file,
                what,
                other,
                output,
            } => write!(
                f,
                "{}: {what} and {other} are the same file {}; give them different paths",
                file.display(),
                output.display()
            ),
            HostError::Output { file, what, error } => {
                if let Some(file) = file {
                    write!(f, "{}: ", file.display())?;
                }
                if let Some(what) = what {
                    write!(f, "{what}: ")?;
                }
                write!(f, "{error}")
            }
        }
    }
}

// No `source()`: see the module documentation.
impl std::error::Error for HostError {}

/// For callers that report errors as strings (the bench, the conformance kit): the message.
impl From<HostError> for String {
    fn from(e: HostError) -> String {
        e.to_string()
    }
}

impl From<ConfigError> for HostError {
    fn from(e: ConfigError) -> HostError {
        HostError::Config(e)
    }
}

impl From<SceneError> for HostError {
    fn from(e: SceneError) -> HostError {
        HostError::Scene(e)
    }
}

impl From<OutputError> for HostError {
    fn from(error: OutputError) -> HostError {
        HostError::Output {
            file: None,
            what: None,
            error,
        }
    }
}

impl From<PluginError> for HostError {
    fn from(error: PluginError) -> HostError {
        HostError::Plugin {
            file: None,
            field: None,
            error: Box::new(error),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The messages users read, byte for byte as the host printed them before the enum.
    #[test]
    fn messages_are_the_one_line_messages_of_the_cli() {
        let file = PathBuf::from("/s/a.toml");
        let cases: Vec<(HostError, &str)> = vec![
            (
                HostError::Field {
                    file: file.clone(),
                    field: "render.build_quality".into(),
                    msg: "\"best\": expected low, medium or high".into(),
                },
                "/s/a.toml: render.build_quality: \"best\": expected low, medium or high",
            ),
            (
                HostError::NotSettable {
                    file: file.clone(),
                    key: "render.width".into(),
                },
                "/s/a.toml: --set render.width: only render.accumulation, render.precision, render.accumulation_cache_mib and render.flange can be set from the command line",
            ),
            (
                HostError::Part {
                    file: file.clone(),
                    refusal: PartRefusal::TimeBudget,
                },
                "/s/a.toml: --part/--samples need a sample budget (render.spp or --spp), not a time budget",
            ),
            (
                HostError::Memory {
                    file: None,
                    msg: "too big".into(),
                },
                "too big",
            ),
            (
                HostError::Plugin {
                    file: Some(file.clone()),
                    field: Some("integrator.plugin".into()),
                    error: Box::new(PluginError::NotFound {
                        name: "x".into(),
                        file: "libx.so".into(),
                        searched: "/p".into(),
                    }),
                },
                "/s/a.toml: integrator.plugin: plugin 'x' not found (looked for libx.so in: /p)",
            ),
            (
                HostError::OutputIsInput {
                    file: file.clone(),
                    what: "the EXR output",
                    output: PathBuf::from("/s/a.toml"),
                    input: "the config",
                },
                "/s/a.toml: the EXR output /s/a.toml is the config; refusing to overwrite an input",
            ),
            (
                HostError::SameOutput {
                    file,
                    what: "the PNG preview",
                    other: "the EXR output",
                    output: PathBuf::from("/s/x"),
                },
                "/s/a.toml: the PNG preview and the EXR output are the same file /s/x; give them different paths",
            ),
        ];
        for (e, want) in cases {
            assert_eq!(e.to_string(), want, "{e:?}");
            assert!(std::error::Error::source(&e).is_none());
        }
    }
}
