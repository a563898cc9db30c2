//! Scene loading for Flowlight: glTF 2.0 meshes, materials, textures, lights and camera
//! ([`load_gltf`]), and the TOML render configuration ([`load_config`]).
//!
//! One file per concept:
//! - [`scene`]: the loaded, world-space [`Scene`] and its hit reconstruction;
//! - [`gltf_loader`]: walking a glTF document into a [`Scene`];
//! - [`instancing`]: `EXT_mesh_gpu_instancing` placements;
//! - [`source`]: reading `.gltf`/`.glb` files and their buffers (external files, data URIs);
//! - [`accessor`]: validated reading of glTF accessors;
//! - [`compression`]: `EXT_meshopt_compression` buffer views;
//! - [`extensions`]: the glTF extensions the loader knows, and the check of a file's list;
//! - [`material`]: glTF materials to [`flowlight_core::material::Material`], overrides;
//! - [`spec_gloss`], [`unlit`]: `KHR_materials_pbrSpecularGlossiness` and
//!   `KHR_materials_unlit` converted to the metallic-roughness material;
//! - [`texture`]: image decoding into compact texel storage, and samplers;
//! - [`lights`]: punctual lights, the emission integral of emitters, the environment and the
//!   power CDF over all lights;
//! - [`config`]: the TOML render configuration;
//! - [`load_options`]: what the config says about loading (missing textures, multiscatter);
//! - [`error`]: the error types.

pub mod accessor;
pub mod compression;
pub mod config;
pub mod error;
pub mod extensions;
pub mod files;
pub mod gltf_loader;
pub mod instancing;
pub mod lights;
pub mod load_options;
pub mod material;
pub mod material_layers;
pub mod memory;
pub mod scene;
pub mod source;
pub mod spec_gloss;
pub mod texture;
pub mod unlit;

pub use config::{
    load_config, parse_config, CameraOverride, EnvironmentConfig, Intersector, RenderConfig,
    SampleBudget,
};
pub use error::{ConfigError, SceneError};
pub use gltf_loader::{load_gltf, load_gltf_with};
pub use load_options::{LoadOptions, MissingTextures};
pub use material::{DiffuseChoice, MaterialOverride};
pub use scene::{
    CameraDesc, CameraProjection, LoadStats, MeshInstance, MeshRange, NamedNode, Scene,
};
pub use texture::{ImageData, Sampler, Texels, TextureData};
