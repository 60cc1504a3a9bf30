//! The output: [`Delaunay`] (tets, neighbours, vertices), how it was built
//! ([`DelaunayStats`], [`DelaunayTimes`]) and the options of a build ([`DelaunayOptions`]).

use std::time::Duration;

/// Marker for "no neighbour" (a face on the boundary of the triangulated region).
pub const NONE: u32 = u32::MAX;

/// A Delaunay tetrahedralisation.
///
/// Invariants: every tet `tets[t]` is positively oriented (`orient3d > 0`, never flat);
/// `neighbors[t][k]` is the tet sharing the face opposite `tets[t][k]`, or [`NONE`] on the
/// convex hull; adjacency is symmetric. The union of the tets is the convex hull of the
/// vertices (when they are not all in one plane), and every vertex is in a tet.
#[derive(Debug, Clone, Default)]
pub struct Delaunay {
    /// The distinct input points (exact duplicates merged; the first occurrence is kept).
    pub vertices: Vec<[f64; 3]>,
    /// For each input point, the index of its vertex in `vertices`.
    pub vertex_of_point: Vec<u32>,
    /// Tetrahedra as vertex indices, positively oriented.
    pub tets: Vec<[u32; 4]>,
    /// `neighbors[t][k]`: the tet across the face opposite vertex `k` of `t`, or [`NONE`].
    pub neighbors: Vec<[u32; 4]>,
    /// How the triangulation was built.
    pub stats: DelaunayStats,
}

/// How a [`Delaunay`] was built (for benchmarks and tests; the tets never depend on it).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DelaunayStats {
    /// Worker threads of the parallel phase (1: all insertions by one thread).
    pub workers: usize,
    /// Vertices inserted by the parallel phase.
    pub parallel_insertions: usize,
    /// Vertices inserted after the parallel phase by one thread: those a worker backed off
    /// from twice (a tet it needed was held by another worker), and those the workers left
    /// when they stopped early ([`DelaunayStats::parallel_stopped`]).
    pub deferred: usize,
    /// First attempts of the parallel phase that backed off (each vertex is tried again after
    /// the rest of its chunk).
    pub backed_off: usize,
    /// The workers stopped before the end of the parallel phase because more than one first
    /// attempt in 8 backed off (cavities so large that the workers' cavities keep overlapping, e.g. on
    /// points of a nearly flat convex surface); the rest went to the one-thread pass.
    pub parallel_stopped: bool,
    /// Chunks of the parallel phase inserted by a worker other than their owner (one that
    /// had finished its own share).
    pub stolen_chunks: usize,
    /// Insertions whose cavity boundary had too many vertices for the local-number map and
    /// whose new tets were linked through the directed-edge hash table instead.
    pub large_cavities: usize,
    /// Points merged into a vertex at another position ([`DelaunayOptions::merge_within`]).
    pub merged_near: usize,
    /// Points with a coordinate set to 0 because it was too small next to the largest
    /// coordinate for exact predicates (see [`Delaunay::with_options`]).
    pub snapped: usize,
    /// Wall-clock time of each stage.
    pub times: DelaunayTimes,
}

/// Wall-clock time of the stages of [`Delaunay::with_options`]; their sum is the whole call.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DelaunayTimes {
    /// Checking the input, merging duplicates and ordering the points for insertion (the
    /// Hilbert sort, the BRIO rounds).
    pub ordering: Duration,
    /// Inserting the points: the tet arena, the first tet, the walks and cavities.
    pub insertion: Duration,
    /// The output: the finite tets in canonical form and order with their neighbours, the
    /// input numbering restored.
    pub output: Duration,
}

/// Options of [`Delaunay::with_options`].
#[derive(Debug, Clone, Copy)]
pub struct DelaunayOptions {
    /// At most this many worker threads (of the current rayon pool); inputs under 8192
    /// points use one.
    pub threads: usize,
    /// Testing aid: make every `n`-th lock attempt of the parallel phase fail as if another
    /// worker held the tet, so that the back-off path runs (0: never).
    pub fail_every_nth_lock: u32,
    /// Testing aid: insert with the portable code even where the CPU has AVX2 (the same
    /// source compiled without it; the result is the same).
    pub portable: bool,
    /// Points within this (Euclidean) distance of the first point of their run in the
    /// sorted order (by Hilbert cell, then position) become one vertex, as exact duplicates
    /// do (0: exact duplicates only, the default). Best effort: points a rounding apart are
    /// nearly always next to each other in that order, but not always (a Hilbert cell's edge
    /// between them); the triangulation of the vertices is exact either way.
    pub merge_within: f64,
}

impl Default for DelaunayOptions {
    fn default() -> Self {
        Self {
            threads: rayon::current_num_threads(),
            fail_every_nth_lock: 0,
            portable: false,
            merge_within: 0.0,
        }
    }
}
