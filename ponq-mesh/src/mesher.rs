//! The whole PoNQ meshing pipeline: PoNQ -> Delaunay -> tags -> min cut -> manifold -> mesh.

use std::time::{Duration, Instant};

use crate::complex::{Label, TetComplex};
use crate::cut::{CutStats, min_cut};
use crate::delaunay::Delaunay;
use crate::error::{Error, Result};
use crate::extract::{extract_boundary, extract_faces};
use crate::halfedge::HalfEdges;
use crate::manifold::{KeptSurface, ManifoldStats, make_manifold_keeping_faces};
use crate::open_surface::cull_open;
use crate::ponq::Ponq;
use crate::quadric::{Quadric, SVD_CUTOFF};
use crate::tagging::{SmallTetRule, tag_all};
use crate::trimesh::TriMesh;

/// Options of [`mesh_ponq`].
#[derive(Debug, Clone)]
pub struct MeshingOptions {
    /// Grid resolution `N` the PoNQ comes from (cells per side of the domain): sets the
    /// face-score weight `h = N^2` and the small-tet threshold.
    pub grid_scale: f64,
    /// The domain box `(min, max)`; its corners are the protective points. Default `[-1,1]^3`.
    /// It is enlarged (by one cell) when some v* lies outside it.
    pub domain: ([f64; 3], [f64; 3]),
    /// Small-tet rule factor: threshold `factor * cell^2` (authors: 3).
    pub small_tet_factor: f64,
    /// Which labels the small-tet rule adds ([`SmallTetRule`]; default: inside only, as the
    /// authors' mesher).
    pub small_tet_rule: SmallTetRule,
    /// Relabel tets so that the output is a strict manifold (default true).
    pub manifold: bool,
    /// Open-surface culling: keep a triangle only if one of its vertices has anisotropy
    /// `lambda2/lambda1 <= t` (the paper uses 0.35 to 0.4). `None` keeps the closed mesh.
    pub open_threshold: Option<f64>,
    /// Flip quadrilateral diagonals onto the sharp edges the quadrics describe
    /// ([`crate::flips`]; default true, closed surfaces only). `false` keeps the triangles of
    /// the minimum cut as they are (the behaviour before this option).
    pub align_creases: bool,
    /// After the crease flips, flip the flat caps away: triangles with an angle above 150
    /// degrees in a flat part of the surface, whose normals are noise ([`crate::caps`];
    /// default true, closed surfaces only).
    pub flat_caps: bool,
    /// Weld tolerance, relative to the domain's largest side (default `1e-10`; 0: off). v*
    /// within this distance of each other (two v* a rounding apart: ponq-fit's PoNQs of CAD
    /// parts have some, where the quadrics of two cells meet at one corner) become one vertex,
    /// quadrics summed as for exact duplicates: the Delaunay merges them as it sorts the points
    /// ([`crate::delaunay::DelaunayOptions::merge_within`]), and if the surface still has an
    /// edge at most this long, the v* joined by Delaunay edges that short are merged and the
    /// PoNQ is meshed again. The output then has no such edge and none of the near-zero-area
    /// triangles next to it. The Delaunay stays exact either way.
    pub weld: f64,
}

impl Default for MeshingOptions {
    fn default() -> Self {
        Self {
            grid_scale: 32.0,
            domain: ([-1.0; 3], [1.0; 3]),
            small_tet_factor: 3.0,
            small_tet_rule: SmallTetRule::InsideOnly,
            manifold: true,
            open_threshold: None,
            align_creases: true,
            flat_caps: true,
            weld: DEFAULT_WELD,
        }
    }
}

/// Default [`MeshingOptions::weld`].
pub const DEFAULT_WELD: f64 = 1e-10;

/// The largest v* coordinate and domain size [`mesh_ponq`] takes. Beyond it the products
/// of the exact orientation tests (the crease flips' self-intersection test, the validity
/// check: degree 3 in the coordinates, no scaling of their own) could overflow; the Delaunay
/// itself takes any finite input ([`crate::delaunay::Delaunay::with_options`]).
pub const MAX_COORDINATE: f64 = 1e30;

/// The smallest domain size [`mesh_ponq`] takes (below it, those products could underflow).
pub const MIN_EXTENT: f64 = 1e-30;

impl MeshingOptions {
    /// The domain box from six numbers `xmin, ymin, zmin, xmax, ymax, zmax` (the form the
    /// command-line programs take), checked: six finite numbers, each max above its min.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] naming what is wrong.
    pub fn domain_from(bounds: &[f64]) -> Result<([f64; 3], [f64; 3])> {
        let [x0, y0, z0, x1, y1, z1] = bounds else {
            return Err(Error::InvalidInput(format!(
                "the box needs 6 comma-separated numbers xmin,ymin,zmin,xmax,ymax,zmax, got {bounds:?}"
            )));
        };
        let (lo, hi) = ([*x0, *y0, *z0], [*x1, *y1, *z1]);
        if (0..3).any(|k| !lo[k].is_finite() || !hi[k].is_finite() || !(hi[k] > lo[k])) {
            return Err(Error::InvalidInput(format!(
                "the box needs finite numbers with each max larger than its min, got {bounds:?}"
            )));
        }
        Ok((lo, hi))
    }

    /// Checks an open-surface threshold (see [`MeshingOptions::open_threshold`]): anisotropy
    /// `lambda2/lambda1` lies in `[0, 1]`, so must the threshold.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for a threshold outside `[0, 1]` or NaN.
    pub fn check_open_threshold(t: f64) -> Result<f64> {
        if (0.0..=1.0).contains(&t) {
            Ok(t)
        } else {
            Err(Error::InvalidInput(format!(
                "the open-surface threshold must be in [0, 1], got {t}"
            )))
        }
    }
}

/// Time spent in each stage.
#[derive(Debug, Clone, Copy, Default)]
pub struct StageTimes {
    /// v* solve and quadric normalisation.
    pub prepare: Duration,
    /// Delaunay tetrahedralisation.
    pub delaunay: Duration,
    /// Tagging (incidence lists included).
    pub tagging: Duration,
    /// Minimum cut (scores included).
    pub cut: Duration,
    /// Manifold repair.
    pub manifold: Duration,
    /// Boundary extraction (and open-surface culling).
    pub extraction: Duration,
    /// Flips of the extracted surface (crease-aligning and flat-cap flips).
    pub flips: Duration,
}

impl StageTimes {
    /// Sum of all stages.
    pub fn total(&self) -> Duration {
        self.prepare
            + self.delaunay
            + self.tagging
            + self.cut
            + self.manifold
            + self.extraction
            + self.flips
    }
}

/// Counts and timings of one meshing run.
#[derive(Debug, Clone, Default)]
pub struct MeshingStats {
    /// Input points.
    pub points: usize,
    /// Distinct Delaunay vertices (protective corners included).
    pub vertices: usize,
    /// Tetrahedra.
    pub tets: usize,
    /// Tets tagged inside / outside / unknown before the cut.
    pub tagged: [usize; 3],
    /// The cut problem.
    pub cut: CutStats,
    /// The manifold repair.
    pub manifold: ManifoldStats,
    /// The crease-aligning flips.
    pub flips: crate::flips::FlipStats,
    /// The flat-cap flips.
    pub caps: crate::caps::CapStats,
    /// Input points merged into a vertex at another position by the weld
    /// ([`MeshingOptions::weld`]).
    pub welded: usize,
    /// Whether the weld needed a second pass (points the Delaunay's own merge missed; the
    /// stage times are then those of both passes).
    pub meshed_twice: bool,
    /// Stage timings.
    pub times: StageTimes,
}

/// Result of [`mesh_ponq`].
#[derive(Debug, Clone)]
pub struct MeshingOutput {
    /// The mesh (empty when no tet is inside; see `message`).
    pub mesh: TriMesh,
    /// For each output vertex, the index of the input point it comes from.
    pub source_point: Vec<u32>,
    /// Counts and timings.
    pub stats: MeshingStats,
    /// A human-readable note when the result is empty or degenerate.
    pub message: Option<String>,
}

fn unit(n: [f64; 3]) -> [f64; 3] {
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if l > 0.0 && l.is_finite() {
        n.map(|x| x / l)
    } else {
        [0.0; 3]
    }
}

/// Meshes a PoNQ: the output is closed, oriented, free of self-intersections and (with
/// `manifold`) a strict 2-manifold, or empty with a `message`.
///
/// # Errors
/// [`Error::InvalidInput`] for a non-positive or non-finite `grid_scale`, a degenerate domain,
/// non-finite data, or a domain or v* beyond the range of the exact predicates
/// ([`MAX_COORDINATE`], [`MIN_EXTENT`]).
pub fn mesh_ponq(ponq: &Ponq, opts: &MeshingOptions) -> Result<MeshingOutput> {
    if !(opts.grid_scale > 0.0 && opts.grid_scale.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "grid scale must be a positive number, got {}",
            opts.grid_scale
        )));
    }
    if let Some(t) = opts.open_threshold {
        MeshingOptions::check_open_threshold(t)?;
    }
    let (dlo, dhi) = opts.domain;
    if (0..3).any(|k| !(dhi[k] > dlo[k]) || !dlo[k].is_finite() || !dhi[k].is_finite()) {
        return Err(Error::InvalidInput(format!(
            "domain box {dlo:?}..{dhi:?} is empty or not finite"
        )));
    }
    let extent = (0..3).map(|k| dhi[k] - dlo[k]).fold(0.0, f64::max);
    if !(MIN_EXTENT..=MAX_COORDINATE).contains(&extent)
        || dlo.iter().chain(&dhi).any(|c| c.abs() > MAX_COORDINATE)
    {
        return Err(Error::InvalidInput(format!(
            "domain box {dlo:?}..{dhi:?}: its size must be within {MIN_EXTENT:e}..{MAX_COORDINATE:e} \
             and its corners within +-{MAX_COORDINATE:e} (PoNQs live in [-1, 1]^3: rescale the input)"
        )));
    }
    let mut stats = MeshingStats {
        points: ponq.len(),
        ..Default::default()
    };
    let t0 = Instant::now();
    // v* (unless stored) and the scale of each quadric (largest eigenvalue of A, see
    // `Quadric::normalized`), from one eigen-decomposition each.
    let (vstars, scales): (Vec<[f64; 3]>, Vec<f64>) = {
        use rayon::prelude::*;
        match &ponq.vstars {
            Some(v) => (
                v.clone(),
                ponq.quadrics
                    .par_iter()
                    .map(Quadric::largest_eigenvalue)
                    .collect(),
            ),
            None => ponq
                .quadrics
                .par_iter()
                .zip(&ponq.points)
                .map(|(q, p)| q.optimal_point_and_scale(*p, SVD_CUTOFF))
                .unzip(),
        }
    };
    // One pass for both checks (NaN fails the comparison too).
    if let Some(i) = vstars
        .iter()
        .position(|p| p.iter().any(|c| !(c.abs() <= MAX_COORDINATE)))
    {
        return Err(Error::InvalidInput(
            if vstars[i].iter().any(|c| !c.is_finite()) {
                format!("v*[{i}] is not finite")
            } else {
                format!(
                    "v*[{i}] = {:?} is beyond +-{MAX_COORDINATE:e} (PoNQs live in [-1, 1]^3: \
                     rescale the input)",
                    vstars[i]
                )
            },
        ));
    }
    stats.times.prepare = t0.elapsed();
    let m = ponq.len();
    let weld_tol = opts.weld * extent;
    if !(opts.weld >= 0.0 && weld_tol.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "the weld tolerance must be a finite number >= 0, got {}",
            opts.weld
        )));
    }
    let mut points = vstars;
    let (mut rewelded, mut moved) = (false, 0);
    let (mesh, source_point) = loop {
        let Pass {
            cx,
            mut mesh,
            back,
            source,
            half_edges,
        } = mesh_pass(ponq, opts, &points, &scales, weld_tol, &mut stats)?;
        let t5 = Instant::now();
        let mut source_point: Vec<u32> = back.iter().map(|&v| source[v as usize]).collect();
        let mut flip_time = Duration::ZERO;
        if opts.align_creases && opts.open_threshold.is_none() && opts.manifold {
            let t = Instant::now();
            // The mesh vertices' data through `back`, not gathered into new arrays.
            stats.flips = crate::flips::align_creases_with(
                &mut mesh,
                &cx.quadrics,
                &cx.normals,
                &back,
                cx.h,
                half_edges,
            );
            flip_time = t.elapsed();
            stats.times.flips += flip_time;
        }
        if opts.flat_caps && opts.open_threshold.is_none() && opts.manifold {
            let t = Instant::now();
            let (lo, hi) = opts.domain;
            let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
            stats.caps = crate::caps::flatten_caps(&mut mesh, extent / opts.grid_scale);
            let cap_time = t.elapsed();
            flip_time += cap_time;
            stats.times.flips += cap_time;
        }
        if let Some(th) = opts.open_threshold {
            let aniso: Vec<f64> = back
                .iter()
                .map(|&v| cx.quadrics[v as usize].anisotropy())
                .collect();
            let keep = cull_open(&mut mesh, &aniso, th);
            source_point = keep.iter().map(|&i| source_point[i as usize]).collect();
        }
        stats.times.extraction += t5.elapsed() - flip_time;
        // One more pass at most: after the weld no two points are within the tolerance.
        if !rewelded && weld_tol > 0.0 && has_edge_within(&mesh, weld_tol) {
            let t = Instant::now();
            // Counted apart: the moved points are exact duplicates in the next pass.
            moved = weld(&cx.dt, m, &mut points, weld_tol);
            stats.times.prepare += t.elapsed();
            if moved > 0 {
                rewelded = true;
                stats.meshed_twice = true;
                continue;
            }
        }
        break (mesh, source_point);
    };
    stats.welded += moved;

    let message = if m == 0 {
        Some("the PoNQ has no point: empty mesh".to_string())
    } else if mesh.faces.is_empty() {
        Some(format!(
            "no tetrahedron was labelled inside ({} points, {} tets): empty mesh",
            m, stats.tets
        ))
    } else {
        None
    };
    Ok(MeshingOutput {
        mesh,
        source_point,
        stats,
        message,
    })
}

/// Whether some edge of `mesh` is at most `tol` long.
fn has_edge_within(mesh: &TriMesh, tol: f64) -> bool {
    use rayon::prelude::*;
    let tol2 = tol * tol;
    mesh.faces.par_iter().any(|f| {
        (0..3).any(|k| {
            let (a, b) = (
                mesh.vertices[f[k] as usize],
                mesh.vertices[f[(k + 1) % 3] as usize],
            );
            (0..3).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum::<f64>() <= tol2
        })
    })
}

/// Moves each v* (`vstars`, the first `m` points of `dt`) that is within `tol` of another
/// one onto it: the groups are the connected parts of the Delaunay edges at most `tol` long
/// (two points within `tol` are joined by such a path: the Delaunay graph contains the
/// Gabriel graph, and a point inside the ball on a short edge is nearer still), each moved
/// onto its point of lowest index. Protective corners (vertices of points `>= m`) stay out.
/// Returns how many points moved.
fn weld(dt: &Delaunay, m: usize, vstars: &mut [[f64; 3]], tol: f64) -> usize {
    use rayon::prelude::*;
    let nv = dt.vertices.len();
    // The first input point of each vertex (u32::MAX: a corner's).
    let mut first = vec![u32::MAX; nv];
    for (i, &v) in dt.vertex_of_point.iter().enumerate().take(m).rev() {
        first[v as usize] = i as u32;
    }
    let tol2 = tol * tol;
    const EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];
    let short: Vec<(u32, u32)> = dt
        .tets
        .par_iter()
        .flat_map_iter(|t| {
            EDGES.iter().filter_map(move |&(i, j)| {
                let (a, b) = (t[i], t[j]);
                let (p, q) = (dt.vertices[a as usize], dt.vertices[b as usize]);
                let d2: f64 = (0..3).map(|k| (p[k] - q[k]) * (p[k] - q[k])).sum();
                (d2 <= tol2).then_some((a, b))
            })
        })
        .collect();
    // Union-find, each set rooted at its vertex of lowest first point.
    let mut parent: Vec<u32> = (0..nv as u32).collect();
    fn root(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            parent[v as usize] = parent[parent[v as usize] as usize];
            v = parent[v as usize];
        }
        v
    }
    for (a, b) in short {
        if first[a as usize] == u32::MAX || first[b as usize] == u32::MAX {
            continue;
        }
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        if ra != rb {
            let (keep, other) = if first[ra as usize] < first[rb as usize] {
                (ra, rb)
            } else {
                (rb, ra)
            };
            parent[other as usize] = keep;
        }
    }
    let mut moved = 0;
    for (i, p) in vstars.iter_mut().enumerate() {
        let v = dt.vertex_of_point[i];
        let r = root(&mut parent, v);
        if r != v {
            *p = dt.vertices[r as usize];
            moved += 1;
        }
    }
    moved
}

/// The points the mesher triangulates for the v* `vstars`: the v*, then the eight corners of
/// the protective box (the domain of `opts`, enlarged by one cell, `extent / grid_scale`, on
/// each side where some v* reaches its boundary). The corners form the convex hull, so every
/// tet of the v* is inside the box. `delaunay_bench` times the Delaunay on these points.
///
/// ```
/// use ponq_mesh::mesher::{delaunay_points, MeshingOptions};
/// let pts = delaunay_points(&[[0.0, 0.5, 0.0], [0.25, 0.0, 1.0]], &MeshingOptions::default());
/// assert_eq!(pts.len(), 10);
/// assert_eq!(pts[2], [-1.0, -1.0, -1.0]);
/// // The second v* is on the domain's top face: the box grows by a cell (2 / 32) there.
/// assert_eq!(pts[9], [1.0, 1.0, 1.0625]);
/// ```
pub fn delaunay_points(vstars: &[[f64; 3]], opts: &MeshingOptions) -> Vec<[f64; 3]> {
    let (dlo, dhi) = opts.domain;
    let extent = (0..3).map(|k| dhi[k] - dlo[k]).fold(0.0, f64::max);
    let cell = extent / opts.grid_scale;
    // Protective box: the domain, enlarged by a cell where some v* leaves it.
    let (mut lo, mut hi) = (dlo, dhi);
    for p in vstars {
        for k in 0..3 {
            if p[k] <= lo[k] {
                lo[k] = p[k] - cell;
            }
            if p[k] >= hi[k] {
                hi[k] = p[k] + cell;
            }
        }
    }
    let mut points = Vec::with_capacity(vstars.len() + 8);
    points.extend_from_slice(vstars);
    for i in 0..8 {
        points.push([
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]);
    }
    points
}

/// What one pass of the mesher (Delaunay to extraction) gives.
struct Pass {
    cx: TetComplex,
    mesh: TriMesh,
    /// Complex vertex of each mesh vertex.
    back: Vec<u32>,
    /// First input point of each complex vertex (`u32::MAX`: a protective corner).
    source: Vec<u32>,
    /// The half-edges of `mesh` when the manifold repair changed nothing and the crease flips
    /// will run (from the corners the repair's check grouped, not grouped again).
    half_edges: Option<HalfEdges>,
}

/// Delaunay, tagging, cut, manifold repair and extraction of the points `vstars` (one per
/// input point of `ponq`; `scales`: their quadrics' largest eigenvalues); stage times and
/// counts are added to `stats`.
fn mesh_pass(
    ponq: &Ponq,
    opts: &MeshingOptions,
    vstars: &[[f64; 3]],
    scales: &[f64],
    weld_tol: f64,
    stats: &mut MeshingStats,
) -> Result<Pass> {
    let t0 = Instant::now();
    let points = delaunay_points(vstars, opts);
    let (dlo, dhi) = opts.domain;
    let extent = (0..3).map(|k| dhi[k] - dlo[k]).fold(0.0, f64::max);
    let cell = extent / opts.grid_scale;
    // The protective box's centre (its corners are the last eight points).
    let (lo, hi) = (points[vstars.len()], points[vstars.len() + 7]);
    let centre = [
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    ];
    stats.times.prepare += t0.elapsed();

    let t1 = Instant::now();
    // v* a rounding apart are nearly always merged here already (one pass); `mesh_ponq`'s
    // weld catches the rest.
    let dt = Delaunay::with_options(
        &points,
        &crate::delaunay::DelaunayOptions {
            merge_within: weld_tol,
            ..Default::default()
        },
    )?;
    stats.welded = dt.stats.merged_near;
    stats.times.delaunay += t1.elapsed();

    let t2 = Instant::now();
    // Per-vertex data; duplicates of one position are merged (quadrics summed, normals averaged).
    // Which points each vertex has (one pass over small arrays), then the data of each vertex
    // in parallel; a protective corner's own data replaces that of points at its position.
    let nv = dt.vertices.len();
    let m = ponq.len();
    // `corner[v]`: the point of the protective corner at vertex v (u32::MAX: none).
    let mut corner = vec![u32::MAX; nv];
    let mut source = vec![u32::MAX; nv];
    let mut sources = vec![0u32; nv];
    for (i, &v) in dt.vertex_of_point.iter().enumerate() {
        let v = v as usize;
        if i >= m {
            corner[v] = i as u32;
            source[v] = u32::MAX;
        } else {
            if source[v] == u32::MAX {
                source[v] = i as u32;
            }
            sources[v] += 1;
        }
    }
    // The points of merged vertices, by vertex, in input order.
    let mut merged: Vec<(u32, u32)> = (0..m)
        .filter(|&i| sources[dt.vertex_of_point[i] as usize] > 1)
        .map(|i| (dt.vertex_of_point[i], i as u32))
        .collect();
    merged.sort_by_key(|&(v, _)| v);
    // Each vertex's unit normal, its tagging normal (the unit normal at the length of the mean
    // of its points' raw normals: the barycentre test weighs by it, as the authors do) and its
    // quadric.
    #[allow(clippy::type_complexity)]
    let (normals, (tag_normals, quadrics)): (Vec<[f64; 3]>, (Vec<[f64; 3]>, Vec<Quadric>)) = {
        use rayon::prelude::*;
        (0..nv)
            .into_par_iter()
            .map(|v| {
                if corner[v] != u32::MAX {
                    let c = points[corner[v] as usize];
                    let n = unit([centre[0] - c[0], centre[1] - c[1], centre[2] - c[2]]);
                    return (n, (n, Quadric::identity_at(c)));
                }
                let (mut n, mut raw, mut q) = ([0.0; 3], [0.0; 3], Quadric::zero());
                let mut add = |i: usize| {
                    let ni = unit(ponq.normals[i]);
                    for k in 0..3 {
                        n[k] += ni[k];
                        raw[k] += ponq.normals[i][k];
                    }
                    q += ponq.quadrics[i].scaled_by_largest(scales[i]);
                };
                if sources[v] == 1 {
                    add(source[v] as usize);
                } else {
                    let at = merged.partition_point(|&(w, _)| (w as usize) < v);
                    for &(_, i) in merged[at..].iter().take_while(|&&(w, _)| w as usize == v) {
                        add(i as usize);
                    }
                }
                let len = (raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2]).sqrt()
                    / f64::from(sources[v].max(1));
                // A single normalised quadric is already normalised; a sum of several is not.
                let n = unit(n);
                let len = if len.is_finite() { len } else { 0.0 };
                (
                    n,
                    (
                        n.map(|x| x * len),
                        if sources[v] > 1 { q.normalized() } else { q },
                    ),
                )
            })
            .unzip()
    };
    stats.vertices = nv;
    stats.tets = dt.tets.len();
    let cx = TetComplex::new(
        dt,
        normals,
        tag_normals,
        quadrics,
        corner.iter().map(|&c| c != u32::MAX).collect(),
        cell,
        opts.grid_scale * opts.grid_scale,
    );
    let mut labels = tag_all(&cx, opts.small_tet_factor, opts.small_tet_rule);
    // Counted by comparisons the compiler vectorises: a `match` per label branched on random
    // labels (~1.1 ms at 686k tets).
    let count = |which: Label| labels.iter().map(|&l| (l == which) as usize).sum::<usize>();
    let (inside, outside) = (count(Label::Inside), count(Label::Outside));
    stats.tagged = [inside, outside, labels.len() - inside - outside];
    stats.times.tagging += t2.elapsed();

    let t3 = Instant::now();
    stats.cut = min_cut(&cx, &mut labels);
    stats.times.cut += t3.elapsed();

    let t4 = Instant::now();
    let mut kept = None;
    if opts.manifold {
        // The repair's boundary faces are the output's when it changed nothing, and their
        // half-edges are the crease flips'.
        let flips = opts.align_creases && opts.open_threshold.is_none();
        (stats.manifold, kept) = make_manifold_keeping_faces(&cx, &mut labels, flips);
    }
    stats.times.manifold += t4.elapsed();

    let t5 = Instant::now();
    let (mesh, back, half_edges) = match kept {
        Some(KeptSurface { faces, half_edges }) => {
            let (mesh, back) = extract_faces(&cx, faces);
            let half_edges = half_edges.map(|he| he.renumbered(&back));
            (mesh, back, half_edges)
        }
        None => {
            let (mesh, back) = extract_boundary(&cx, &labels);
            (mesh, back, None)
        }
    };
    stats.times.extraction += t5.elapsed();
    Ok(Pass {
        cx,
        mesh,
        back,
        source,
        half_edges,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flips::reference;
    use crate::flips::{
        FlipStats, VertexData, align_creases, align_creases_indexed, flip_pass, well_shaped,
    };
    use crate::vec3::{cross, dot};
    use rand::{Rng, SeedableRng};
    use rustc_hash::FxHashSet;

    #[test]
    fn boxes_and_thresholds_are_checked() {
        let ok = MeshingOptions::domain_from(&[-1.0, -2.0, -3.0, 1.0, 2.0, 3.0]);
        assert_eq!(ok.ok(), Some(([-1.0, -2.0, -3.0], [1.0, 2.0, 3.0])));
        for bad in [
            vec![],
            vec![0.0; 5],
            vec![0.0; 7],
            vec![0.0, 0.0, 0.0, 1.0, 1.0, 0.0],
            vec![0.0, 0.0, 0.0, 1.0, -1.0, 1.0],
            vec![0.0, 0.0, f64::NAN, 1.0, 1.0, 1.0],
            vec![0.0, 0.0, 0.0, 1.0, 1.0, f64::INFINITY],
        ] {
            assert!(
                matches!(
                    MeshingOptions::domain_from(&bad),
                    Err(Error::InvalidInput(_))
                ),
                "{bad:?}"
            );
        }
        for t in [0.0, 0.35, 1.0] {
            assert_eq!(MeshingOptions::check_open_threshold(t).ok(), Some(t));
        }
        for t in [-0.1, 1.5, f64::NAN] {
            assert!(MeshingOptions::check_open_threshold(t).is_err(), "{t}");
        }
        // The mesher refuses a bad threshold instead of culling everything or nothing.
        let opts = MeshingOptions {
            open_threshold: Some(2.0),
            ..Default::default()
        };
        assert!(matches!(
            mesh_ponq(&Ponq::default(), &opts),
            Err(Error::InvalidInput(_))
        ));
        // Domains beyond the exact predicates' range are refused, with a hint (the size is the
        // largest side: a thin box is fine).
        for (lo, hi) in [
            ([-1e31, 0.0, 0.0], [1.0; 3]),
            ([0.0; 3], [2e30, 1.0, 1.0]),
            ([0.0; 3], [1e-31; 3]),
        ] {
            let opts = MeshingOptions {
                domain: (lo, hi),
                ..Default::default()
            };
            match mesh_ponq(&Ponq::default(), &opts) {
                Err(Error::InvalidInput(m)) => assert!(m.contains("rescale"), "{m}"),
                other => panic!("{lo:?}..{hi:?}: {other:?}"),
            }
        }
        let small = MeshingOptions {
            domain: ([0.0; 3], [1e-20; 3]),
            ..Default::default()
        };
        assert!(mesh_ponq(&Ponq::default(), &small).is_ok());
    }

    // The crease flips on the mesher's own outputs (here rather than in `flips`, which the
    // mesher calls: the tests' meshes come from the mesher).

    /// Samples of the surface of a box rotated by `angle` about the axis (1, 1, 0)/sqrt(2):
    /// sharp edges at every angle to the grid.
    fn rotated_box(
        half: [f64; 3],
        angle: f64,
        n: usize,
        seed: u64,
    ) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (c, s) = (angle.cos(), angle.sin());
        let k = [
            std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
        ];
        // Rodrigues' rotation about the unit axis k.
        let rot = |v: [f64; 3]| -> [f64; 3] {
            let kv = dot(k, v);
            let x = cross(k, v);
            std::array::from_fn(|i| v[i] * c + x[i] * s + k[i] * kv * (1.0 - c))
        };
        let (mut pts, mut nrm) = (Vec::new(), Vec::new());
        for _ in 0..n {
            let axis = rng.random_range(0..3usize);
            let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let mut p: [f64; 3] = std::array::from_fn(|i| rng.random_range(-half[i]..half[i]));
            p[axis] = side * half[axis];
            let mut q = [0.0; 3];
            q[axis] = side;
            pts.push(rot(p));
            nrm.push(rot(q));
        }
        (pts, nrm)
    }

    /// A rotated box's PoNQ on a `grid`^3 grid, meshed without flips, with each mesh vertex's
    /// normalised quadric and unit normal (gathered from its source point).
    fn unflipped_box(
        grid: usize,
        angle: f64,
        samples: usize,
        seed: u64,
    ) -> (TriMesh, Vec<Quadric>, Vec<[f64; 3]>) {
        let (pts, nrm) = rotated_box([0.55, 0.4, 0.3], angle, samples, seed);
        let cell = |p: &[f64; 3]| {
            let c =
                |x: f64| (((x + 1.0) / 2.0 * grid as f64).floor().max(0.0) as usize).min(grid - 1);
            ((c(p[0]) * grid + c(p[1])) * grid + c(p[2])) as u32
        };
        let ids: Vec<u32> = pts.iter().map(cell).collect();
        let (ponq, _) = Ponq::from_clusters(&pts, &nrm, &ids, grid * grid * grid).unwrap();
        let opts = MeshingOptions {
            grid_scale: grid as f64,
            align_creases: false,
            ..Default::default()
        };
        let out = mesh_ponq(&ponq, &opts).unwrap();
        let q: Vec<Quadric> = out
            .source_point
            .iter()
            .map(|&s| ponq.quadrics[s as usize].normalized())
            .collect();
        let n: Vec<[f64; 3]> = out
            .source_point
            .iter()
            .map(|&s| {
                let m = ponq.normals[s as usize];
                let l = dot(m, m).sqrt().max(1e-30);
                m.map(|x| x / l)
            })
            .collect();
        (out.mesh, q, n)
    }

    /// The work-list pass flips exactly what plain sweeps over all edges flip (same faces,
    /// same flips in the same order, same pass count), with and without banned edges, on
    /// meshes of rotated boxes where flips happen over several passes.
    #[test]
    fn work_lists_flip_exactly_what_sweeps_flip() {
        let mut with_flips = 0;
        let mut multi_pass = 0;
        for (seed, grid, angle) in [
            (6u64, 36usize, 0.6),
            (8, 24, 0.7),
            (13, 36, 0.3),
            (9, 20, 0.7),
        ] {
            let (mesh, q, n) = unflipped_box(grid, angle, 40_000, seed);
            let h = (grid * grid) as f64;
            let mut banned_sets = vec![FxHashSet::default()];
            let every_7th: FxHashSet<(u32, u32)> = reference::edge_faces(&mesh)
                .keys()
                .copied()
                .filter(|e| (e.0 + 3 * e.1) % 7 == 0)
                .collect();
            banned_sets.push(every_7th);
            for banned in &banned_sets {
                let (mut m1, mut m2) = (mesh.clone(), mesh.clone());
                let (mut s1, mut s2) = (FlipStats::default(), FlipStats::default());
                let data = VertexData::new(&q, &n, None);
                // Half the runs on half-edges built beforehand (as the mesher passes them).
                let prebuilt = (seed % 2 == 0)
                    .then(|| HalfEdges::new(&mesh.faces, mesh.vertices.len()))
                    .flatten();
                let f1 = flip_pass(&mut m1, data, h, banned, prebuilt, &mut s1);
                let f2 = reference::flip_pass_sweeps(&mut m2, data, h, banned, &mut s2);
                assert_eq!(f1, f2, "seed {seed}: the flips differ");
                assert_eq!(m1.faces, m2.faces, "seed {seed}: the faces differ");
                assert_eq!(s1.passes, s2.passes, "seed {seed}");
                // Every face a flip made (its last state) has no angle above 150 degrees
                // (without the rule, seed 6 has one).
                for &(i, j) in &f1 {
                    for f in [i, j] {
                        assert!(
                            well_shaped(&m1, m1.faces[f as usize]),
                            "seed {seed}: a sliver"
                        );
                    }
                }
                if !f1.is_empty() {
                    with_flips += 1;
                }
                if s1.passes >= 3 {
                    multi_pass += 1;
                }
            }
        }
        eprintln!("cases with flips: {with_flips}, with >= 3 passes: {multi_pass}");
        assert!(with_flips >= 4, "only {with_flips} cases flipped anything");
        assert!(multi_pass >= 1, "no case needed a second flipping pass");
    }

    /// Reading the data through an index gives the same flips as gathering it first (here the
    /// index is a shuffled, padded layout of the same data); an index of the wrong length or
    /// out of range changes nothing.
    #[test]
    fn indexed_data_flips_like_gathered_data() {
        let grid = 36usize;
        let (mesh, q, n) = unflipped_box(grid, 0.6, 40_000, 6);
        let nv = mesh.vertices.len();
        // Vertex w's data at slot index[w] of arrays twice as long (the rest is junk).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mut slots: Vec<u32> = (0..2 * nv as u32).collect();
        for i in (1..slots.len()).rev() {
            slots.swap(i, rng.random_range(0..=i));
        }
        let index: Vec<u32> = slots[..nv].to_vec();
        let mut q2 = vec![Quadric::identity_at([0.3, 0.1, -0.2]); 2 * nv];
        let mut n2 = vec![[0.0, 0.0, 1.0]; 2 * nv];
        for (w, &i) in index.iter().enumerate() {
            q2[i as usize] = q[w];
            n2[i as usize] = n[w];
        }
        let h = (grid * grid) as f64;
        let (mut m1, mut m2) = (mesh.clone(), mesh.clone());
        let s1 = align_creases(&mut m1, &q, &n, h);
        let s2 = align_creases_indexed(&mut m2, &q2, &n2, &index, h);
        assert!(s1.flips > 10, "only {} flips", s1.flips);
        assert_eq!(s1, s2);
        assert_eq!(m1.faces, m2.faces);
        for bad in [&index[1..], &[u32::MAX; 1][..]] {
            let mut m3 = mesh.clone();
            let mut bad = bad.to_vec();
            bad.resize(if bad.len() == 1 { nv } else { bad.len() }, 0);
            let s3 = align_creases_indexed(&mut m3, &q2, &n2, &bad, h);
            assert_eq!(s3, FlipStats::default());
            assert_eq!(m3.faces, mesh.faces);
        }
    }
}
