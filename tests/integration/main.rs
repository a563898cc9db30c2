//! The root package's integration tests, one binary: each file of this folder is a module
//! (`cargo test --test integration cli::` runs one of them), `common` holds the functions
//! they share. One binary instead of one per file, because each binary links the whole
//! workspace again after any change to a crate below the host.
//!
//! The plugins must have been built first (`cargo build --workspace`): the host loads them
//! from `target/<profile>/`. Tests share one process and run on parallel threads, so none may
//! change process-wide state (environment variables, the working directory, signal
//! handlers, the global allocator); `tests/accumulation_memory.rs` counts every byte the
//! process allocates and is therefore a binary of its own.

mod common;

mod accumulation;
mod alpha;
mod aovs;
mod bench;
mod bidir;
mod cli;
mod cornell;
mod depths;
mod distributed;
mod elf_mutations;
mod embree;
mod erpt;
mod erpt_auto;
mod erpt_bdpt_seeds;
mod erpt_perturbations;
mod erpt_seeds;
mod erpt_stability;
mod furnace;
mod gltf_corpus;
mod gltf_material;
mod hardening;
mod instancing;
mod lights;
mod live_preview;
mod mmlt;
mod multiscatter_furnace;
mod orthographic;
mod outsider;
mod plugins;
mod pssmlt;
mod ray_batches;
mod sampler;
mod stability;
mod thin_lens;
