//! flowlight-bvh's integration tests, one binary: each file of this folder is a module
//! (`cargo test -p flowlight-bvh --test integration wide::` runs one of them), `common` holds
//! the reference intersector and the scene generators they share.

mod common;

mod agreement;
mod instanced;
mod robustness;
mod wide;
