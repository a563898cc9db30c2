//! flowlight-scene's integration tests, one binary: each file of this folder is a module
//! (`cargo test -p flowlight-scene --test integration fuzz::` runs one of them), `common`
//! holds the glTF-building functions they share. Tests run on parallel threads of one
//! process, so none may change process-wide state (environment variables, the working
//! directory); each takes its own temporary directory from `common::temp_dir`.

mod common;

mod cameras;
mod config;
mod converted_materials;
mod extensions_doc;
mod fuzz;
mod geometry;
mod instancing;
mod lens;
mod lights;
mod malformed;
mod materials;
mod missing_textures;
mod normal_bend;
mod scenes;
mod textures;
