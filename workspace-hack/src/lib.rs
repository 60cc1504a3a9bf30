//! No code: this crate exists for its `Cargo.toml`, which gives the dependencies the
//! workspace's crates share the same features in every build (see the comment there).
