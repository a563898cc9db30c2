//! Scene loading (work in progress).
