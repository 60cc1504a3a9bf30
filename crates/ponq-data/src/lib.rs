//! # ponq-data
//!
//! Meshes to training shapes: normalisation, exact SDF grids, surface samples, datasets.
//! Not implemented yet (see the issue "ponq-data").
