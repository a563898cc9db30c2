//! Error types. Every message names the file it is about and the cause.

use std::path::PathBuf;

/// Why a glTF scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{}: cannot read file: {source}", file.display())]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: invalid or truncated .glb: {reason}", file.display())]
    Glb { file: PathBuf, reason: String },
    #[error("{}: invalid glTF JSON: {reason}", file.display())]
    Json { file: PathBuf, reason: String },
    #[error("{}: invalid glTF document: {reason}", file.display())]
    Validation { file: PathBuf, reason: String },
    #[error("{}: buffer {buffer}: cannot read {}: {source}", file.display(), missing.display())]
    MissingBuffer {
        file: PathBuf,
        buffer: usize,
        missing: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: bad buffer {buffer}: {reason}", file.display())]
    Buffer {
        file: PathBuf,
        buffer: usize,
        reason: String,
    },
    #[error("{}: bad accessor {accessor}: {reason}", file.display())]
    Accessor {
        file: PathBuf,
        accessor: usize,
        reason: String,
    },
    #[error("{}: {reason}", file.display())]
    Primitive { file: PathBuf, reason: String },
    #[error("{}: the glTF document has no scene", file.display())]
    NoScene { file: PathBuf },
    #[error("{}: the scene contains no (non-degenerate) triangles", file.display())]
    NoTriangles { file: PathBuf },
    #[error("{}: bad material '{material}': {reason}", file.display())]
    Material {
        file: PathBuf,
        material: String,
        reason: String,
    },
    #[error("{}: bad image {image}: {reason}", file.display())]
    Image {
        file: PathBuf,
        image: usize,
        reason: String,
    },
    #[error("{}: {reason}", file.display())]
    Camera { file: PathBuf, reason: String },
    #[error("{}: bad node {node}: {reason}", file.display())]
    Node {
        file: PathBuf,
        node: usize,
        reason: String,
    },
    #[error("{}: bad KHR_lights_punctual light {light}: {reason}", file.display())]
    Light {
        file: PathBuf,
        light: usize,
        reason: String,
    },
    /// A documented size limit (instances, instanced triangles, memory) is exceeded.
    #[error("{}: scene too large: {reason}", file.display())]
    Limit { file: PathBuf, reason: String },
    #[error("{}: internal error while loading (malformed input?): {reason}", file.display())]
    Internal { file: PathBuf, reason: String },
}

/// Why a TOML render configuration could not be loaded or used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{}: cannot read file: {source}", file.display())]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A TOML syntax, unknown-key or type error, on one line: `file:line: key `k`: message`.
    #[error("{}:{line}: key `{key}`: {message}", file.display())]
    Parse {
        file: PathBuf,
        line: usize,
        key: String,
        message: String,
    },
    #[error("{}: key `{key}`: {reason}", file.display())]
    Invalid {
        file: PathBuf,
        key: String,
        reason: String,
    },
}
