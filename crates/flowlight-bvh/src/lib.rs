//! Pure-Rust BVH (work in progress).
