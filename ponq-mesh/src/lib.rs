//! # ponq-mesh
//!
//! Turns a PoNQ (points, normals, quadric error metrics) into a watertight, manifold,
//! self-intersection-free triangle mesh, following PoNQ (CVPR 2024), and holds the
//! geometry the rest of PoNQ-rs shares (mesh I/O, validity checks).
//!
//! The pipeline, one module per stage:
//! [`quadric`] (v* from Q) -> [`delaunay`] (exact 3D Delaunay of v* + protective corners) ->
//! [`tagging`] (inside / outside / unknown tets) -> [`score`] (face scores) ->
//! [`maxflow`] + [`cut`] (minimum s-t cut) -> [`extract`] (oriented boundary) ->
//! [`manifold`] (relabel tets until the boundary is a strict manifold) -> [`flips`] (quadrilateral
//! diagonals onto the sharp edges the quadrics describe; on [`halfedge`]s) -> [`caps`] (flat
//! caps, near-180-degree triangles whose normals are noise, flipped away).
//! [`mesher`] runs them all.
//!
//! ```no_run
//! use ponq_mesh::{io, mesher::{mesh_ponq, MeshingOptions}};
//! let ponq = io::npz::read_ponq("shape.npz")?;
//! let out = mesh_ponq(&ponq, &MeshingOptions { grid_scale: 32.0, ..Default::default() })?;
//! io::write_mesh("shape.obj", &out.mesh)?;
//! # Ok::<(), ponq_mesh::Error>(())
//! ```

pub mod band;
pub mod bvh;
pub mod caps;
pub mod cli;
pub mod colour;
pub mod complex;
pub mod corners;
pub mod cover_grid;
pub mod cpu;
pub mod cut;
pub mod delaunay;
pub mod error;
pub mod extract;
pub mod fan;
pub mod flips;
pub mod halfedge;
pub mod io;
pub mod lite;
pub mod manifold;
pub mod marching_cubes;
pub mod maxflow;
pub mod memory;
pub mod mesher;
pub mod metrics;
pub mod nn;
pub mod open_surface;
pub mod ponq;
pub mod predicates;
pub mod quadric;
pub mod sampling;
pub mod score;
pub mod tagging;
pub mod trimesh;
pub mod validity;
pub mod vec3;

pub use error::{Error, Result};
pub use ponq::Ponq;
pub use quadric::Quadric;
pub use trimesh::TriMesh;
