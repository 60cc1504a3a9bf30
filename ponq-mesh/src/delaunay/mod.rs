//! Exact 3D Delaunay tetrahedralisation.
//!
//! Written here because no MIT/Apache crate does it well enough: the pure-Rust candidates
//! measured on this project's machine were either MPL-licensed and 7 s on a 27k-point lattice
//! (PoNQ-lite puts v* on lattices), aborted on lattices, emitted flat tets, or were 1000x slower;
//! TetGen is AGPL. This is the classic Bowyer-Watson insertion in a BRIO / Hilbert-curve order
//! with a stochastic visibility walk, on top of [`crate::predicates`]: exact orientation and
//! insphere tests with Devillers-Teillaud symbolic perturbation, so co-spherical and coplanar
//! inputs (lattices) give a valid triangulation with no flat tetrahedron and no jitter.
//! The triangulation covers all of space, as CGAL's does: every face of the convex hull has an
//! infinite tet, the face and one symbolic infinite vertex (no position). A point beyond a
//! hull face is in conflict with that face's infinite tet; a point on the face's plane is in
//! conflict with it where it is in conflict with the finite tet across the face (inside the
//! face's circumcircle, ties broken by the same perturbation). The insertion starts from four
//! affinely independent points, their tet and its four infinite tets. (Until 2026-12-05 it
//! started from a super-tetrahedron of four far real points, which left the filters undecided
//! along the hull and cut off the hull's flat tets, whose circumspheres reach far: the
//! triangulation was then built again with a larger one.)
//!
//! Parallel insertion: after the first BRIO rounds, each worker thread takes one stretch of
//! every later round's Hilbert order (so the workers are far apart in space), cut into chunks;
//! a worker that has finished its own chunks takes the others' from the back of their queues
//! (work stealing). It walks to each vertex without locks, then try-locks the tet it ends in
//! (checked to contain the vertex), the cavity and the cavity's neighbours. A worker that
//! finds a tet busy undoes its stamps and locks, tries the vertex again after its chunk, and
//! else leaves it for a final one-thread pass. The perturbed Delaunay triangulation is unique,
//! and the output is put in a canonical order, so the result is the same arrays for any
//! number of workers and any timing (tested, with injected lock failures and stealing too).
//!
//! ```
//! use ponq_mesh::delaunay::Delaunay;
//! let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]];
//! let dt = Delaunay::new(&pts).unwrap();
//! assert_eq!(dt.tets.len(), 2);
//! ```
//!
//! Measured against CGAL 5.5's `Delaunay_triangulation_3` and HXT on the same points in the
//! same minutes (`ponq-mesh/benches/cgal/side_by_side.sh`, `docs/meshing.md`): the whole call on
//! one thread is 1.7-2.1x faster than CGAL's on random and PoNQ points, 3.1x on lattices.
//!
//! The modules, bottom up: `triangulation` (the output types), `range` (the input scaled
//! into the exact predicates' range), `order` (Hilbert keys, the BRIO rounds), `distinct`
//! (duplicate merging), `store` (the tet arena, marks and stamps), `conflict` (the geometric
//! tests on it), `worker` (one inserting thread), `walk`, `link` (joining a cavity's new
//! tets), `cavity` (one insertion), `builder` (the arena and the first tet),
//! `canonical` (the output in a canonical order), `parallel` (the parallel phase); this
//! file puts them together ([`Delaunay::with_options`]).

mod builder;
mod canonical;
mod cavity;
mod conflict;
mod distinct;
mod link;
mod order;
mod parallel;
mod range;
mod store;
mod triangulation;
mod walk;
mod worker;

use std::time::Instant;

use builder::Builder;
use distinct::{Distinct, distinct_points};
use order::{brio_order, extremes_first, independent_first};
use parallel::in_parallel;
use range::{ExactRange, times_pow2};
use store::MAX_POINTS;

pub use triangulation::{Delaunay, DelaunayOptions, DelaunayStats, DelaunayTimes, NONE};

use crate::error::{Error, Result};

impl Delaunay {
    /// Triangulates `points`. Exact duplicates are merged (see [`Delaunay::vertex_of_point`]).
    /// Fewer than four affinely independent points give a triangulation without tets.
    ///
    /// Any finite coordinates work, tiny or huge: the predicates run on the points scaled by
    /// a power of two (exact, and no sign changes) where their products cannot underflow or
    /// overflow. A nonzero coordinate below 2^-140 of the largest coordinate magnitude (a
    /// subnormal next to 1, say) is set to 0 first (the point is then counted in
    /// [`DelaunayStats::snapped`], and may become a copy of another): its products would
    /// underflow. The vertices are the input points (with such coordinates at 0).
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for a non-finite coordinate or 2^28 points or more.
    pub fn new(points: &[[f64; 3]]) -> Result<Self> {
        Self::with_threads(points, rayon::current_num_threads())
    }

    /// [`Delaunay::new`] with at most `threads` worker threads (of the current rayon pool).
    /// The result does not depend on `threads`: the symbolically perturbed Delaunay
    /// triangulation is unique, so every insertion order gives the same tets.
    ///
    /// # Errors
    /// As [`Delaunay::new`].
    pub fn with_threads(points: &[[f64; 3]], threads: usize) -> Result<Self> {
        Self::with_options(
            points,
            &DelaunayOptions {
                threads,
                ..Default::default()
            },
        )
    }

    /// [`Delaunay::new`] with options.
    ///
    /// # Errors
    /// As [`Delaunay::new`].
    pub fn with_options(points: &[[f64; 3]], opts: &DelaunayOptions) -> Result<Self> {
        use rayon::prelude::*;
        let start = Instant::now();
        // Tet slots and the vertices' stamps are `u32` (see `MAX_POINTS`).
        if points.len() >= MAX_POINTS {
            return Err(Error::InvalidInput(format!(
                "{} points is more than the triangulation supports",
                points.len()
            )));
        }
        if let Some(i) = points
            .par_iter()
            .with_min_len(4096)
            .position_first(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(Error::InvalidInput(format!(
                "point {i} = {:?} is not finite",
                points[i]
            )));
        }
        let exact = ExactRange::of(points);
        let (points, snapped) = exact.apply(points);
        let Distinct {
            mut vertices,
            vertex_of_point,
            hilbert,
        } = distinct_points(&points, exact.scale(opts.merge_within.max(0.0)));
        // Number the vertices in insertion order inside the builder, so that consecutive
        // insertions touch neighbouring memory; `finish` maps the numbers back.
        let (mut order, mut rounds) = brio_order(&hilbert);
        extremes_first(&vertices, &mut order, &mut rounds);
        let spans = independent_first(&vertices, &mut order, &mut rounds);
        let capacity = 8 * vertices.len() + 4096 * (opts.threads.clamp(1, 64) + 1);
        let parallel = in_parallel(opts.threads, vertices.len());
        let mut times = DelaunayTimes {
            ordering: start.elapsed(),
            ..Default::default()
        };
        let t = Instant::now();
        // In parallel (a gather through the insertion order).
        let mut sorted: Vec<[f64; 3]> = Vec::with_capacity(order.len() + 1);
        order
            .par_iter()
            .map(|&i| vertices[i as usize])
            .collect_into_vec(&mut sorted);
        let mut dt = Builder::new(sorted, order, capacity, parallel, spans)?.run(&rounds, opts);
        // `finish` timed the output stage.
        times.output += dt.stats.times.output;
        times.insertion += t.elapsed() - dt.stats.times.output;
        let t = Instant::now();
        if opts.merge_within > 0.0 {
            dt.stats.merged_near = points
                .iter()
                .zip(&vertex_of_point)
                .filter(|&(p, &v)| {
                    let q = &vertices[v as usize];
                    p[0] != q[0] || p[1] != q[1] || p[2] != q[2]
                })
                .count();
        }
        dt.stats.snapped = snapped;
        if exact.k != 0 {
            vertices
                .par_iter_mut()
                .for_each(|p| *p = p.map(|x| times_pow2(x, -exact.k)));
        }
        dt.vertices = vertices;
        dt.vertex_of_point = vertex_of_point;
        times.output += t.elapsed();
        dt.stats.times = times;
        Ok(dt)
    }

    /// For every vertex, one tet incident to it (or [`NONE`] for a vertex in no tet).
    pub fn vertex_to_tet(&self) -> Vec<u32> {
        let mut v2t = vec![NONE; self.vertices.len()];
        for (t, tet) in self.tets.iter().enumerate() {
            for &v in tet {
                v2t[v as usize] = t as u32;
            }
        }
        v2t
    }
}
