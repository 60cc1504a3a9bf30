//! Mesh validity: closed, oriented, manifold, free of self-intersections (exact).
//!
//! [`check`] inspects a [`TriMesh`] and returns a [`ValidityReport`]; [`check_topology`] does
//! the same without the (more expensive) geometric self-intersection test.
//!
//! Every geometric decision is exact: degenerate faces and self-intersections are decided with
//! exact orientation tests ([`crate::predicates::orient3d`]: a semi-static filter, then
//! Shewchuk's adaptive predicate, and `robust::orient2d` on an axis projection that is
//! injective on the relevant plane or line) evaluated on the `f64` coordinates, with no
//! epsilon. A mesh that passes [`ValidityReport::is_valid`] is therefore a
//! closed, consistently oriented 2-manifold whose faces meet exactly along their shared
//! edges and vertices (its triangles, taken as closed sets, touch nowhere else).
//!
//! Rules of the self-intersection test for a pair of distinct faces (see [`faces_intersect`]):
//! * no shared vertex index: they intersect iff the closed triangles share a point (touching
//!   counts);
//! * exactly one shared vertex index: they intersect iff they share a point other than that
//!   vertex;
//! * two shared indices (a shared edge): they intersect iff they are coplanar and their
//!   opposite vertices lie on the same side of the shared edge (folded onto each other);
//! * the same three indices: duplicate faces, always an intersection.
//!
//! Pairs that share a vertex index and involve a degenerate face (repeated index or collinear
//! corners) are not tested: the degenerate face is already reported in
//! [`ValidityReport::degenerate_faces`].
//!
//! Pairs that share one vertex or one edge are mostly decided at once by a certificate of the
//! shared vertex's fan ([`crate::fan`]: the fan projects one-to-one onto an axis plane, so its
//! faces meet only at the vertex and along shared edges); the others go through the rules.

use std::fmt;

use rayon::prelude::*;

use crate::bvh::{Aabb, Bvh};
use crate::cover_grid::CoverGrid;
use crate::fan::{VertexFans, graph_fans, vertex_fans};
use crate::predicates::{o2, proj};
use crate::trimesh::TriMesh;
use robust::Coord;

/// Outcome of [`check`] / [`check_topology`].
///
/// Edges are undirected pairs of distinct vertex indices used by faces (edges of faces with a
/// repeated index that join a vertex to itself are ignored).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ValidityReport {
    /// Every edge has exactly two incident faces.
    pub closed: bool,
    /// Every directed edge `a -> b` appears in exactly one face and its twin `b -> a` in
    /// exactly one face (implies `closed`).
    pub oriented: bool,
    /// `closed`, and the faces around every vertex form a single edge-connected fan (a cycle).
    pub manifold: bool,
    /// Edges with exactly one incident face.
    pub boundary_edges: usize,
    /// Edges with three or more incident faces.
    pub nonmanifold_edges: usize,
    /// Referenced vertices whose incident faces form two or more fans, fans being connected
    /// through the edges incident to the vertex (faces around a non-manifold edge count as
    /// connected).
    pub nonmanifold_vertices: usize,
    /// Faces with a repeated vertex index or exactly collinear corners (exact test).
    pub degenerate_faces: usize,
    /// Vertices no face refers to (reported, not a defect for [`ValidityReport::is_valid`]).
    pub unreferenced_vertices: usize,
    /// Number of intersecting face pairs (rules in the [module docs](self)); `0` when not
    /// checked.
    pub self_intersections: usize,
    /// Referenced vertices sharing their exact position with at least one other referenced
    /// vertex of a different index (a group of `k` coincident vertices counts `k`).
    pub coincident_vertices: usize,
    /// Whether `self_intersections` was computed ([`check`]) or skipped ([`check_topology`]).
    pub self_intersections_checked: bool,
}

impl ValidityReport {
    /// True for a closed, oriented, manifold mesh without degenerate faces, self-intersections
    /// or coincident vertices. For a report of [`check_topology`] self-intersections are not
    /// known and are assumed absent.
    pub fn is_valid(&self) -> bool {
        self.closed
            && self.oriented
            && self.manifold
            && self.degenerate_faces == 0
            && self.self_intersections == 0
            && self.coincident_vertices == 0
    }

    /// Same as [`ValidityReport::is_valid`].
    pub fn is_watertight(&self) -> bool {
        self.is_valid()
    }

    /// True for a valid open surface (the programs' `--open` outputs): boundary edges are
    /// expected, but no edge has three faces or more, every vertex's faces form one fan, and
    /// no two faces cross (for a report of [`check_topology`], assumed).
    pub fn is_valid_open_surface(&self) -> bool {
        self.self_intersections == 0
            && self.nonmanifold_edges == 0
            && self.nonmanifold_vertices == 0
    }
}

impl fmt::Display for ValidityReport {
    /// One line, e.g. `valid (closed, oriented, manifold, no self-intersection)` or
    /// `invalid: 3 boundary edges, not oriented, not manifold`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let plural =
            |n: usize, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
        if self.is_valid() {
            if self.self_intersections_checked {
                write!(
                    f,
                    "valid (closed, oriented, manifold, no self-intersection)"
                )?;
            } else {
                write!(
                    f,
                    "valid topology (closed, oriented, manifold; self-intersections not checked)"
                )?;
            }
        } else {
            let mut d: Vec<String> = Vec::new();
            if self.boundary_edges > 0 {
                d.push(plural(
                    self.boundary_edges,
                    "boundary edge",
                    "boundary edges",
                ));
            }
            if self.nonmanifold_edges > 0 {
                d.push(plural(
                    self.nonmanifold_edges,
                    "non-manifold edge",
                    "non-manifold edges",
                ));
            }
            if self.nonmanifold_vertices > 0 {
                d.push(plural(
                    self.nonmanifold_vertices,
                    "non-manifold vertex",
                    "non-manifold vertices",
                ));
            }
            if self.closed && !self.oriented {
                // (An open mesh is never `oriented`; its boundary edges already say so.)
                d.push("not oriented".into());
            }
            if self.degenerate_faces > 0 {
                d.push(plural(
                    self.degenerate_faces,
                    "degenerate face",
                    "degenerate faces",
                ));
            }
            if self.coincident_vertices > 0 {
                d.push(plural(
                    self.coincident_vertices,
                    "coincident vertex",
                    "coincident vertices",
                ));
            }
            if self.self_intersections > 0 {
                d.push(plural(
                    self.self_intersections,
                    "self-intersecting face pair",
                    "self-intersecting face pairs",
                ));
            } else if !self.self_intersections_checked {
                d.push("self-intersections not checked".into());
            }
            write!(f, "invalid: {}", d.join(", "))?;
        }
        if self.unreferenced_vertices > 0 {
            write!(
                f,
                "; {}",
                plural(
                    self.unreferenced_vertices,
                    "unreferenced vertex",
                    "unreferenced vertices"
                )
            )?;
        }
        Ok(())
    }
}

/// Full check: topology, degenerate faces, coincident vertices and exact self-intersections.
/// An empty mesh (no face) is valid.
pub fn check(mesh: &TriMesh) -> ValidityReport {
    // One pass over every vertex's corners gives both the fast path of the topology and the
    // fan certificates of the pair test.
    let (mut r, fans) = topology(mesh, true);
    r.self_intersections =
        prepare(mesh, Some(fans.certified)).map_or(0, |prep| count_with(mesh, &prep));
    r.self_intersections_checked = true;
    r
}

/// Cheap check: everything of [`check`] except the geometric self-intersection test
/// (`self_intersections` is `0` and `self_intersections_checked` is `false`).
pub fn check_topology(mesh: &TriMesh) -> ValidityReport {
    topology(mesh, false).0
}

/// The topology report and the vertices' fans ([`vertex_fans`], certified if `certify`).
///
/// Fast path: when the corners of every vertex form a single cycle, the mesh is a closed,
/// oriented 2-manifold ([`VertexFans::single_cycles`]), and the edge counts would all be zero;
/// only otherwise are the edges and fans counted (a test compares both on 400 meshes with and
/// without defects).
fn topology(mesh: &TriMesh, certify: bool) -> (ValidityReport, VertexFans) {
    let (fans, mut r) = rayon::join(
        || vertex_fans(&mesh.vertices, &mesh.faces, certify),
        || vertex_report(mesh),
    );
    if fans.single_cycles {
        r.closed = true;
        r.oriented = true;
        r.manifold = true;
    } else {
        edge_report(mesh, &mut r);
    }
    (r, fans)
}

/// The parts of the topology report that do not look at edges (unreferenced vertices,
/// degenerate faces, coincident vertices); the edge parts are left at zero / `false`.
fn vertex_report(mesh: &TriMesh) -> ValidityReport {
    let nv = mesh.vertices.len();
    let faces = &mesh.faces;

    let mut used = vec![false; nv];
    for f in faces {
        for &v in f {
            used[v as usize] = true;
        }
    }
    let unreferenced_vertices = used.iter().filter(|&&u| !u).count();

    let degenerate_faces = faces
        .par_iter()
        .filter(|f| face_is_degenerate(mesh, f))
        .count();

    let coincident_vertices = count_coincident(mesh, &used);
    ValidityReport {
        closed: false,
        oriented: false,
        manifold: false,
        boundary_edges: 0,
        nonmanifold_edges: 0,
        nonmanifold_vertices: 0,
        degenerate_faces,
        unreferenced_vertices,
        self_intersections: 0,
        coincident_vertices,
        self_intersections_checked: false,
    }
}

/// Counts the boundary and non-manifold edges and the non-manifold vertices, and sets
/// `closed`, `oriented` and `manifold`, in `r`.
fn edge_report(mesh: &TriMesh, r: &mut ValidityReport) {
    let nv = mesh.vertices.len();
    let faces = &mesh.faces;
    // ----- edges -----
    // Counting sort of the face edges by their smaller endpoint, then a tiny sort of each
    // bucket by the larger endpoint: O(V + F) and cache friendly. An entry is
    // (larger endpoint, slot = 3 * face + local edge); its direction is read from the face.
    let slot_count = 3 * faces.len();
    assert!(slot_count < u32::MAX as usize, "too many faces");
    let mut start = vec![0u32; nv + 1];
    for f in faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if a != b {
                start[a.min(b) as usize + 1] += 1;
            }
        }
    }
    for v in 0..nv {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut recs = vec![(0u32, 0u32); start[nv] as usize];
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if a != b {
                let lo = a.min(b) as usize;
                recs[fill[lo] as usize] = (a.max(b), (3 * fi + k) as u32);
                fill[lo] += 1;
            }
        }
    }
    drop(fill);
    let is_forward = |slot: u32| {
        let (f, k) = (slot as usize / 3, slot as usize % 3);
        faces[f][k] < faces[f][(k + 1) % 3]
    };

    let mut edge_of_slot = vec![u32::MAX; slot_count];
    // (smaller, larger) endpoint of each edge.
    let mut edges: Vec<(u32, u32)> = Vec::new();
    let mut boundary_edges = 0;
    let mut nonmanifold_edges = 0;
    let mut oriented = true;
    for lo in 0..nv {
        let bucket = &mut recs[start[lo] as usize..start[lo + 1] as usize];
        bucket.sort_unstable();
        let mut s = 0;
        while s < bucket.len() {
            let hi = bucket[s].0;
            let mut e = s + 1;
            while e < bucket.len() && bucket[e].0 == hi {
                e += 1;
            }
            let n = e - s;
            let fwd = bucket[s..e].iter().filter(|r| is_forward(r.1)).count();
            if n == 1 {
                boundary_edges += 1;
            } else if n > 2 {
                nonmanifold_edges += 1;
            }
            if !(fwd == 1 && n - fwd == 1) {
                oriented = false;
            }
            let id = edges.len() as u32;
            edges.push((lo as u32, hi));
            for r in &bucket[s..e] {
                edge_of_slot[r.1 as usize] = id;
            }
            s = e;
        }
    }
    drop(recs);
    drop(start);

    // ----- vertex fans -----
    // Node 2e (resp. 2e + 1) is edge e seen from its smaller (resp. larger) endpoint. A corner
    // at v joins the nodes of its two edges seen from v; the fans of v are the components of
    // v's nodes.
    let node = |e: u32, v: u32| -> usize { 2 * e as usize + usize::from(v == edges[e as usize].1) };
    let mut uf = UnionFind::new(2 * edges.len());
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let e_out = edge_of_slot[3 * fi + k];
            let e_in = edge_of_slot[3 * fi + (k + 2) % 3];
            if e_out != u32::MAX && e_in != u32::MAX {
                let v = f[k];
                uf.union(node(e_out, v), node(e_in, v));
            }
        }
    }
    let mut fans = vec![0u32; nv];
    for n in 0..2 * edges.len() {
        if uf.find(n) == n {
            let (lo, hi) = edges[n / 2];
            fans[if n % 2 == 1 { hi } else { lo } as usize] += 1;
        }
    }
    let nonmanifold_vertices = fans.iter().filter(|&&c| c > 1).count();

    let closed = boundary_edges == 0 && nonmanifold_edges == 0;
    r.closed = closed;
    r.oriented = oriented && closed;
    r.manifold = closed && nonmanifold_vertices == 0;
    r.boundary_edges = boundary_edges;
    r.nonmanifold_edges = nonmanifold_edges;
    r.nonmanifold_vertices = nonmanifold_vertices;
}

/// Number of intersecting face pairs (see the [module docs](self) for the rules).
///
/// Candidate pairs come from a [`Bvh`] over the face boxes (exact closed-box overlap, so no
/// candidate is missed); each candidate is decided exactly, in parallel. A candidate that
/// shares one vertex, or one edge, with a vertex whose fan is certified
/// ([`crate::fan::graph_fans`], exact) is decided by the certificate: on the mesher's outputs
/// that is most candidates (1.3 million of 1.43 million at 217k faces).
pub fn count_self_intersections(mesh: &TriMesh) -> usize {
    prepare(mesh, None).map_or(0, |prep| count_with(mesh, &prep))
}

fn count_with(mesh: &TriMesh, prep: &Prepared) -> usize {
    fold_intersecting(mesh, prep, || 0usize, |c, _, _| *c += 1, |a, b| a + b)
}

/// All intersecting face pairs `(i, j)`, `i < j`, sorted.
pub fn intersecting_face_pairs(mesh: &TriMesh) -> Vec<(usize, usize)> {
    let Some(prep) = prepare(mesh, None) else {
        return Vec::new();
    };
    let mut v = fold_intersecting(
        mesh,
        &prep,
        Vec::new,
        |v: &mut Vec<(usize, usize)>, i, j| v.push((i, j)),
        |mut a, mut b| {
            a.append(&mut b);
            a
        },
    );
    v.sort_unstable();
    v
}

/// Parallel fold over the intersecting face pairs `(i, j)`, `i < j` (each once, in no
/// particular order), as [`Bvh::par_fold_overlapping_pairs`] folds its pairs.
fn fold_intersecting<A: Send>(
    mesh: &TriMesh,
    prep: &Prepared,
    init: impl Fn() -> A + Sync,
    visit: impl Fn(&mut A, usize, usize) + Sync,
    reduce: impl Fn(A, A) -> A + Sync,
) -> A {
    // The faces as the pair test reads them, in the hierarchy's leaf order: a pair's two
    // records are near in memory (most pairs are neighbours on the surface), where the faces,
    // their info and the certificates by vertex would be three scattered reads each.
    let faces: Vec<LeafFace> = prep
        .bvh
        .items()
        .par_iter()
        .map(|&f| {
            let v = mesh.faces[f as usize];
            let certified = (0..3).fold(0u8, |m, k| m | ((prep.fans[v[k] as usize] as u8) << k));
            LeafFace {
                v,
                face: f,
                certified,
                info: prep.info[f as usize],
            }
        })
        .collect();
    prep.bvh.par_fold_overlapping_leaf_pairs(
        init,
        |acc, a, b| {
            let (x, y) = (&faces[a], &faces[b]);
            // In face order.
            let (x, y) = if x.face < y.face { (x, y) } else { (y, x) };
            if pair_intersects(mesh, x, y) {
                visit(acc, x.face as usize, y.face as usize);
            }
        },
        reduce,
    )
}

/// A face as [`fold_intersecting`] keeps it: its vertices, its index, which of its vertices
/// have certified fans (bit `k` for `v[k]`) and its [`face_info`].
#[derive(Debug, Clone, Copy)]
struct LeafFace {
    v: [u32; 3],
    face: u32,
    certified: u8,
    info: u8,
}

/// Whether two faces intersect beyond what they share. One or two shared vertex indices, one
/// of them with a certified fan: the faces meet only at the shared vertex or edge
/// (`crate::fan`). Three shared indices (a repeated face) never come with a certified fan, but
/// are left to the rule all the same. Otherwise [`pair_rule`].
#[inline]
fn pair_intersects(mesh: &TriMesh, x: &LeafFace, y: &LeafFace) -> bool {
    let shared = (0..3).fold(0u8, |m, k| m | ((y.v.contains(&x.v[k]) as u8) << k));
    let count = shared.count_ones();
    if (count == 1 || count == 2) && shared & x.certified != 0 {
        return false;
    }
    pair_rule(
        x.v,
        mesh.triangle(x.face as usize),
        x.info,
        y.v,
        mesh.triangle(y.face as usize),
        y.info,
    )
}

/// The intersecting face pairs `(i, j)`, `i < j`, sorted, that involve at least one face of
/// `faces`: the pairs of [`intersecting_face_pairs`] with `i` or `j` in `faces`, found by
/// testing every face against a bounding-volume hierarchy of `faces` only (cheap when
/// `faces` is a small part of the mesh, e.g. the faces a local edit changed).
///
/// # Panics
/// If an index of `faces` is out of range.
pub fn intersecting_face_pairs_among(mesh: &TriMesh, faces: &[usize]) -> Vec<(usize, usize)> {
    if faces.is_empty() || mesh.faces.len() < 2 {
        return Vec::new();
    }
    let boxes: Vec<Aabb> = faces
        .iter()
        .map(|&f| Aabb::from_points(&mesh.triangle(f)))
        .collect();
    let info: Vec<u8> = faces.iter().map(|&f| face_info(mesh, f)).collect();
    let bvh = Bvh::build(&boxes);
    // Most faces are far from all of `faces`: one bit of a grid of the cells they cover
    // rejects them without a descent of the hierarchy (exact, see `cover_grid`). With finite
    // vertices, from the vertices' keys (their cells, computed once), not from the faces'
    // boxes: three 8-byte reads per face instead of three 24-byte ones.
    let grid = CoverGrid::new(&boxes, 1 << 20);
    let keys: Option<Vec<u64>> = grid.as_ref().filter(|g| g.has_point_keys()).and_then(|g| {
        mesh.vertices
            .par_iter()
            .map(|&p| p.iter().all(|x| x.is_finite()).then(|| g.point_key(p)))
            .collect()
    });
    let mut v: Vec<(usize, usize)> = (0..mesh.faces.len())
        .into_par_iter()
        .fold(Vec::new, |mut acc, f| {
            if let (Some(g), Some(keys)) = (&grid, &keys)
                && !g.may_overlap_points(mesh.faces[f].map(|v| keys[v as usize]))
            {
                return acc;
            }
            let b = Aabb::from_points(&mesh.triangle(f));
            if keys.is_none() && grid.as_ref().is_some_and(|g| !g.may_overlap(&b)) {
                return acc;
            }
            let mut fi = None;
            bvh.query_overlaps(&b, |k| {
                let g = faces[k];
                if g == f {
                    return;
                }
                let fi = *fi.get_or_insert_with(|| face_info(mesh, f));
                if pair_rule(
                    mesh.faces[f],
                    mesh.triangle(f),
                    fi,
                    mesh.faces[g],
                    mesh.triangle(g),
                    info[k],
                ) {
                    acc.push((f.min(g), f.max(g)));
                }
            });
            acc
        })
        .reduce(Vec::new, |mut a, mut b| {
            a.append(&mut b);
            a
        });
    v.sort_unstable();
    v.dedup();
    v
}

/// Whether faces `i != j` of `mesh` intersect under the rules of the [module docs](self)
/// (which take shared vertex indices into account). Exact.
///
/// # Panics
/// If `i == j` or either index is out of range.
pub fn faces_intersect(mesh: &TriMesh, i: usize, j: usize) -> bool {
    assert_ne!(i, j, "a face is not tested against itself");
    let info = [face_info(mesh, i), face_info(mesh, j)];
    pair_rule(
        mesh.faces[i],
        mesh.triangle(i),
        info[0],
        mesh.faces[j],
        mesh.triangle(j),
        info[1],
    )
}

/// Exact test of whether two closed triangles (possibly degenerate: segments or points)
/// share at least one point. Touching at a single point counts. Ignores any notion of shared
/// vertices; see [`faces_intersect`] for mesh faces.
pub fn triangles_intersect(t1: &[[f64; 3]; 3], t2: &[[f64; 3]; 3]) -> bool {
    tri_tri(t1, proj_axis(t1), t2, proj_axis(t2))
}

// ---------------------------------------------------------------------------------------------
// internals
// ---------------------------------------------------------------------------------------------

/// `info` value of a degenerate face (repeated index or collinear corners).
const DEGENERATE: u8 = 3;

fn face_is_degenerate(mesh: &TriMesh, f: &[u32; 3]) -> bool {
    f[0] == f[1]
        || f[1] == f[2]
        || f[2] == f[0]
        || proj_axis(&[
            mesh.vertices[f[0] as usize],
            mesh.vertices[f[1] as usize],
            mesh.vertices[f[2] as usize],
        ])
        .is_none()
}

/// Per-face info: projection axis (0..3) or [`DEGENERATE`].
fn face_info(mesh: &TriMesh, f: usize) -> u8 {
    let idx = mesh.faces[f];
    if idx[0] == idx[1] || idx[1] == idx[2] || idx[2] == idx[0] {
        return DEGENERATE;
    }
    proj_axis(&mesh.triangle(f)).unwrap_or(DEGENERATE)
}

/// What the whole-mesh pair tests need: the face hierarchy, each face's [`face_info`] and the
/// vertices whose fans are certified ([`crate::fan`]): a pair of faces that shares one vertex
/// or one edge with such a vertex needs no test.
struct Prepared {
    bvh: Bvh,
    info: Vec<u8>,
    fans: Vec<bool>,
}

/// With `fans` given (from [`graph_fans`]) only the hierarchy and the face info are built.
fn prepare(mesh: &TriMesh, fans: Option<Vec<bool>>) -> Option<Prepared> {
    if mesh.faces.len() < 2 {
        return None;
    }
    let ((bvh, info), fans) = rayon::join(
        || {
            let boxes: Vec<Aabb> = (0..mesh.faces.len())
                .into_par_iter()
                .map(|f| Aabb::from_points(&mesh.triangle(f)))
                .collect();
            let info: Vec<u8> = (0..mesh.faces.len())
                .into_par_iter()
                .map(|f| face_info(mesh, f))
                .collect();
            (Bvh::build_morton(&boxes), info)
        },
        || fans.unwrap_or_else(|| graph_fans(&mesh.vertices, &mesh.faces)),
    );
    Some(Prepared { bvh, info, fans })
}

/// The face-pair rules of the module docs.
fn pair_rule(
    fi: [u32; 3],
    ti: [[f64; 3]; 3],
    ii: u8,
    fj: [u32; 3],
    tj: [[f64; 3]; 3],
    ij: u8,
) -> bool {
    let shared_i: [bool; 3] = std::array::from_fn(|k| fj.contains(&fi[k]));
    let k = shared_i.iter().filter(|&&s| s).count();
    let axis = |x: u8| (x != DEGENERATE).then_some(x);
    if k == 0 {
        return tri_tri(&ti, axis(ii), &tj, axis(ij));
    }
    if ii == DEGENERATE || ij == DEGENERATE {
        // Reported as degenerate faces instead.
        return false;
    }
    // Both faces have three distinct indices here.
    match k {
        3 => true,
        1 => {
            // Opposite edges against the other triangle (see `shared_vertex_rule` proof).
            let a = shared_i.iter().position(|&s| s).unwrap();
            let b = fj.iter().position(|&v| v == fi[a]).unwrap();
            let (ea0, ea1) = (ti[(a + 1) % 3], ti[(a + 2) % 3]);
            let (eb0, eb1) = (tj[(b + 1) % 3], tj[(b + 2) % 3]);
            // Fast exit (most adjacent pairs): if the opposite edge of one triangle lies
            // strictly on one side of the other's plane, that triangle meets the plane only
            // at the shared vertex, so the intersection is that vertex alone.
            let side = |t: &[[f64; 3]; 3], p: &[f64; 3]| o3(&t[0], &t[1], &t[2], p);
            let (sa0, sa1) = (side(&tj, &ea0), side(&tj, &ea1));
            if sa0 * sa1 > 0 || side(&ti, &eb0) * side(&ti, &eb1) > 0 {
                return false;
            }
            if sa0 == 0 && sa1 == 0 {
                // Coplanar (flat regions of CAD parts: ~18% of the pairs on a 217k-face
                // mesh): the wedges at the shared vertex decide, a few 2D orientations
                // instead of two coplanar segment-triangle tests.
                return coplanar_wedges_overlap(&ti[a], &ea0, &ea1, &eb0, &eb1, ii);
            }
            seg_tri(&ea0, &ea1, &tj, axis(ij)) || seg_tri(&eb0, &eb1, &ti, axis(ii))
        }
        _ => {
            // Shared edge: folded iff coplanar and the opposite vertices are on the same side.
            let oi = shared_i.iter().position(|&s| !s).unwrap();
            let oj = (0..3).find(|&m| !fi.contains(&fj[m])).unwrap();
            let (u, w, a, b) = (ti[(oi + 1) % 3], ti[(oi + 2) % 3], ti[oi], tj[oj]);
            if o3(&u, &w, &a, &b) != 0 {
                return false;
            }
            let ax = ii;
            let sa = o2(proj(&u, ax), proj(&w, ax), proj(&a, ax));
            let sb = o2(proj(&u, ax), proj(&w, ax), proj(&b, ax));
            sa == sb
        }
    }
}

// Correctness of the one-shared-vertex rule: let T1 = (v, a, b), T2 = (v, c, d) be
// non-degenerate and K = T1 ∩ T2 ∋ v. If K ≠ {v}, the compact convex set K has an extreme
// point X ≠ v. X is a vertex of T1 or T2 lying in the other triangle (a or b lie on edge ab,
// c or d on cd), or a crossing of an edge of T1 with an edge of T2 (non-coplanar case: X is an
// endpoint of T1 ∩ L or T2 ∩ L with L the line of the two planes, and L ∩ T1 = [v, Y], Y ∈ ab).
// Two edges both starting at v can only share X ≠ v when collinear on the same ray, and then
// the nearer of their far endpoints (a vertex among a, b, c, d) lies in both triangles. Hence
// K ≠ {v} iff ab meets T2 or cd meets T1 (neither edge contains v).

// The coplanar case of that rule: for non-degenerate coplanar T1 = (v, a, b), T2 = (v, c, d),
// each triangle coincides near v with its closed wedge W1 = v + cone(a - v, b - v) (W2 alike),
// and lies inside it. So K = T1 ∩ T2 contains a point other than v iff W1 ∩ W2 does (K is
// convex: a point X ≠ v in K brings the segment [v, X], whose points near v are in W1 ∩ W2;
// conversely K ⊂ W1 ∩ W2). Both wedges span less than a half-turn, so W1 ∩ W2 ≠ {v} iff
// their angular intervals overlap, iff an end of one interval lies in the other: a bounding
// ray of one wedge lies in the other (closed) wedge.

/// Whether the coplanar, non-degenerate triangles `(v, a, b)` and `(v, c, d)` share more than
/// `v` (see the proof above); `ax` is an injective projection axis of their plane.
fn coplanar_wedges_overlap(
    v: &[f64; 3],
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
    ax: u8,
) -> bool {
    let [v, a, b, c, d] = [v, a, b, c, d].map(|p| proj(p, ax));
    // The ray from v through r lies in the closed wedge spanned by the rays through x and y
    // (less than a half-turn, orientation s != 0): r is on x's side of the ray through y and on
    // y's side of the ray through x, zeros allowed (a ray opposite to x or y fails one test).
    let in_wedge = |x: Coord<f64>, y: Coord<f64>, s: i8, r: Coord<f64>| {
        s * o2(v, x, r) >= 0 && s * o2(v, r, y) >= 0
    };
    let (s1, s2) = (o2(v, a, b), o2(v, c, d));
    in_wedge(a, b, s1, c) || in_wedge(a, b, s1, d) || in_wedge(c, d, s2, a) || in_wedge(c, d, s2, b)
}

/// Exact sign of `robust::orient3d(a, b, c, d)` (`det[a-d, b-d, c-d]`), through
/// [`crate::predicates::orient3d`] (its semi-static filter decides most calls inline; the
/// rest go to the same adaptive predicate), whose convention is the opposite sign.
#[inline]
fn o3(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3]) -> i8 {
    -(crate::predicates::orient3d(a, b, c, d) as i8)
}

/// An axis whose projection keeps the triangle non-degenerate (hence is injective on its
/// plane); `None` iff the corners are collinear (or coincide).
fn proj_axis(t: &[[f64; 3]; 3]) -> Option<u8> {
    [2u8, 0, 1]
        .into_iter()
        .find(|&ax| o2(proj(&t[0], ax), proj(&t[1], ax), proj(&t[2], ax)) != 0)
}

/// Closed triangle vs closed triangle; `axis` is `proj_axis` of each (None: degenerate).
///
/// Two closed convex sets meet iff an extreme point of their intersection exists; such a
/// point lies on the boundary of one of them, i.e. on an edge of one triangle (a degenerate
/// triangle is the union of its edges). So testing the six edges against the other triangle
/// is exact and complete.
fn tri_tri(t1: &[[f64; 3]; 3], a1: Option<u8>, t2: &[[f64; 3]; 3], a2: Option<u8>) -> bool {
    if a1.is_some() && strictly_one_side(t1, t2) {
        return false;
    }
    if a2.is_some() && strictly_one_side(t2, t1) {
        return false;
    }
    (0..3).any(|k| seg_tri(&t1[k], &t1[(k + 1) % 3], t2, a2))
        || (0..3).any(|k| seg_tri(&t2[k], &t2[(k + 1) % 3], t1, a1))
}

/// All corners of `q` strictly on the same side of the plane of the non-degenerate `t`.
fn strictly_one_side(t: &[[f64; 3]; 3], q: &[[f64; 3]; 3]) -> bool {
    let s0 = o3(&t[0], &t[1], &t[2], &q[0]);
    if s0 == 0 {
        return false;
    }
    s0 == o3(&t[0], &t[1], &t[2], &q[1]) && s0 == o3(&t[0], &t[1], &t[2], &q[2])
}

/// Closed segment `[s0, s1]` (possibly a point) vs closed triangle `t` with projection axis
/// `axis` (`None`: `t` is degenerate and handled as the union of its edges).
fn seg_tri(s0: &[f64; 3], s1: &[f64; 3], t: &[[f64; 3]; 3], axis: Option<u8>) -> bool {
    let Some(ax) = axis else {
        return (0..3).any(|k| seg_seg_3d(s0, s1, &t[k], &t[(k + 1) % 3]));
    };
    let d0 = o3(&t[0], &t[1], &t[2], s0);
    let d1 = o3(&t[0], &t[1], &t[2], s1);
    if d0 * d1 > 0 {
        return false;
    }
    if d0 == 0 && d1 == 0 {
        // Coplanar: exact in the injective projection.
        let (p0, p1) = (proj(s0, ax), proj(s1, ax));
        let [a, b, c] = [proj(&t[0], ax), proj(&t[1], ax), proj(&t[2], ax)];
        return point_in_tri_2d(p0, a, b, c)
            || point_in_tri_2d(p1, a, b, c)
            || seg_seg_2d(p0, p1, a, b)
            || seg_seg_2d(p0, p1, b, c)
            || seg_seg_2d(p0, p1, c, a);
    }
    // The segment crosses (or touches at one endpoint) the plane at a single point X; the
    // line s0 s1 is transverse, and X lies in the closed triangle iff the line passes on the
    // same side of the three edge lines (Plücker signs, zeros allowed).
    let e = [
        o3(s0, s1, &t[0], &t[1]),
        o3(s0, s1, &t[1], &t[2]),
        o3(s0, s1, &t[2], &t[0]),
    ];
    !(e.contains(&1) && e.contains(&-1))
}

/// Closed point-in-triangle for a non-degenerate 2D triangle.
fn point_in_tri_2d(p: Coord<f64>, a: Coord<f64>, b: Coord<f64>, c: Coord<f64>) -> bool {
    let s = [o2(a, b, p), o2(b, c, p), o2(c, a, p)];
    !(s.contains(&1) && s.contains(&-1))
}

/// Closed 2D segments (possibly points) share a point.
fn seg_seg_2d(p0: Coord<f64>, p1: Coord<f64>, q0: Coord<f64>, q1: Coord<f64>) -> bool {
    let d1 = o2(p0, p1, q0);
    let d2 = o2(p0, p1, q1);
    if d1 * d2 > 0 {
        return false;
    }
    let d3 = o2(q0, q1, p0);
    let d4 = o2(q0, q1, p1);
    if d3 * d4 > 0 {
        return false;
    }
    if d1 == 0 && d2 == 0 && d3 == 0 && d4 == 0 {
        // All on one line (or points): overlap on both coordinates.
        let ov = |a0: f64, a1: f64, b0: f64, b1: f64| {
            a0.min(a1).max(b0.min(b1)) <= a0.max(a1).min(b0.max(b1))
        };
        return ov(p0.x, p1.x, q0.x, q1.x) && ov(p0.y, p1.y, q0.y, q1.y);
    }
    true
}

/// Closed 3D segments (possibly points) share a point. Coplanar segments meet iff their
/// projections meet on all three axis projections (one of them is injective on their affine
/// hull, and any meeting survives every projection).
fn seg_seg_3d(p0: &[f64; 3], p1: &[f64; 3], q0: &[f64; 3], q1: &[f64; 3]) -> bool {
    if o3(p0, p1, q0, q1) != 0 {
        return false;
    }
    (0..3u8).all(|ax| seg_seg_2d(proj(p0, ax), proj(p1, ax), proj(q0, ax), proj(q1, ax)))
}

/// Referenced vertices sharing an exact position with another referenced vertex (vertices
/// with a NaN coordinate never coincide).
fn count_coincident(mesh: &TriMesh, used: &[bool]) -> usize {
    // `+ 0.0` maps -0.0 to +0.0, so equal positions have equal bit patterns.
    let mut keys: Vec<[u64; 3]> = mesh
        .vertices
        .iter()
        .zip(used)
        .filter(|(p, u)| **u && !p.iter().any(|x| x.is_nan()))
        .map(|(p, _)| p.map(|x| (x + 0.0).to_bits()))
        .collect();
    keys.par_sort_unstable();
    let mut count = 0;
    let mut s = 0;
    while s < keys.len() {
        let mut e = s + 1;
        while e < keys.len() && keys[e] == keys[s] {
            e += 1;
        }
        if e - s > 1 {
            count += e - s;
        }
        s = e;
    }
    count
}

/// Union-find with path halving and union by size.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }
    fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] as usize != x {
            let p = self.parent[x] as usize;
            self.parent[x] = self.parent[p];
            x = self.parent[x] as usize;
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a] < self.size[b] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b] = a as u32;
        self.size[a] += self.size[b];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fan::tests::{SECOND_TURN_THROUGH_A_RAY, circle, fan};

    /// The uncertified fans of `fan`'s tests do have crossing faces: certifying them would hide
    /// these pairs. Seven faces going round twice (each sector less than a half-turn, all
    /// turning the same way, the projections overlapping) and a second turn through the ray of
    /// the first corner.
    #[test]
    fn fans_the_certificate_refuses_do_cross() {
        let (v, f) = fan(&circle(7, 2, |i| 0.1 * i as f64));
        let m = TriMesh::new(v, f).unwrap();
        let n = m.faces.len();
        let want: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .filter(|&(i, j)| faces_intersect(&m, i, j))
            .collect();
        assert!(!want.is_empty());
        assert_eq!(intersecting_face_pairs(&m), want);
        let (v, f) = fan(&SECOND_TURN_THROUGH_A_RAY);
        let m = TriMesh::new(v, f).unwrap();
        assert!(check(&m).self_intersections > 0);
    }

    fn c(x: f64, y: f64) -> Coord<f64> {
        Coord { x, y }
    }

    /// The topology report with the edges always counted (no fast path).
    fn counted_topology(m: &TriMesh) -> ValidityReport {
        let mut r = vertex_report(m);
        edge_report(m, &mut r);
        r
    }

    /// A closed torus of `nu * nv` quads, each split along a random diagonal.
    fn torus(nu: usize, nv: usize, rng: &mut impl rand::Rng) -> TriMesh {
        let mut vertices = Vec::new();
        for i in 0..nu {
            let u = i as f64 / nu as f64 * std::f64::consts::TAU;
            for j in 0..nv {
                let v = j as f64 / nv as f64 * std::f64::consts::TAU;
                let rr = 2.0 + 0.8 * v.cos();
                vertices.push([rr * u.cos(), rr * u.sin(), 0.8 * v.sin()]);
            }
        }
        let id = |i: usize, j: usize| ((i % nu) * nv + j % nv) as u32;
        let mut faces = Vec::new();
        for i in 0..nu {
            for j in 0..nv {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if rng.random_bool(0.5) {
                    faces.extend([[a, b, c], [a, c, d]]);
                } else {
                    faces.extend([[a, b, d], [b, c, d]]);
                }
            }
        }
        TriMesh::new(vertices, faces).unwrap()
    }

    #[test]
    fn the_fast_topology_path_reports_what_the_edge_counts_do() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let mut fast_valid = 0;
        for case in 0..400 {
            let mut m = torus(rng.random_range(3..7), rng.random_range(3..6), &mut rng);
            let nf = m.faces.len();
            let nv = m.vertices.len() as u32;
            // 0 to 2 defects of these kinds (none: a valid torus, which takes the fast path).
            for _ in 0..case % 3 {
                let f = rng.random_range(0..m.faces.len());
                match rng.random_range(0..8) {
                    0 => {
                        m.faces.swap_remove(f);
                    }
                    1 => m.faces.push(m.faces[f]),
                    2 => m.faces[f].swap(0, 1),
                    3 => m.faces[f][1] = m.faces[f][0],
                    4 => {
                        // Two vertices made one (a pinch, or a repeated index).
                        let (a, b) = (rng.random_range(0..nv), rng.random_range(0..nv));
                        for face in &mut m.faces {
                            face.iter_mut().filter(|x| **x == b).for_each(|x| *x = a);
                        }
                    }
                    5 => {
                        // A third face on an edge.
                        let g = m.faces[f];
                        m.faces.push([g[1], g[0], rng.random_range(0..nv)]);
                    }
                    6 => {
                        // The two faces of a "pillow" on a fresh pair of vertices.
                        let (a, b) = (m.faces[f][0], m.faces[f][1]);
                        m.vertices.push([9.0, 9.0, 9.0]);
                        let c = m.vertices.len() as u32 - 1;
                        m.faces.extend([[a, b, c], [b, a, c]]);
                    }
                    _ => m.vertices.push([0.0, 0.0, 0.0]),
                }
            }
            let fast = check_topology(&m);
            assert_eq!(
                fast,
                counted_topology(&m),
                "case {case} ({nf} faces before)"
            );
            fast_valid += fast.manifold as usize;
        }
        // Both paths were taken.
        assert!(fast_valid > 50 && fast_valid < 350, "{fast_valid}");
    }

    #[test]
    fn seg_seg_2d_cases() {
        // Proper crossing, touching at an endpoint, T-junction, parallel, collinear.
        assert!(seg_seg_2d(c(0., 0.), c(2., 2.), c(0., 2.), c(2., 0.)));
        assert!(seg_seg_2d(c(0., 0.), c(1., 0.), c(1., 0.), c(2., 5.)));
        assert!(seg_seg_2d(c(0., 0.), c(2., 0.), c(1., 0.), c(1., 3.)));
        assert!(!seg_seg_2d(c(0., 0.), c(2., 0.), c(1., 1e-15), c(1., 3.)));
        assert!(!seg_seg_2d(c(0., 0.), c(2., 0.), c(0., 1.), c(2., 1.)));
        assert!(seg_seg_2d(c(0., 0.), c(2., 0.), c(2., 0.), c(3., 0.)));
        assert!(!seg_seg_2d(
            c(0., 0.),
            c(2., 0.),
            c(2.000000000000001, 0.),
            c(3., 0.)
        ));
        assert!(seg_seg_2d(c(0., 0.), c(0., 2.), c(0., 1.), c(0., 3.)));
        // Points.
        assert!(seg_seg_2d(c(1., 1.), c(1., 1.), c(0., 0.), c(2., 2.)));
        assert!(!seg_seg_2d(c(3., 3.), c(3., 3.), c(0., 0.), c(2., 2.)));
        assert!(seg_seg_2d(c(3., 3.), c(3., 3.), c(3., 3.), c(3., 3.)));
        assert!(!seg_seg_2d(c(3., 3.), c(3., 3.), c(3., 4.), c(3., 4.)));
    }

    #[test]
    fn seg_seg_3d_cases() {
        let o = [0.0; 3];
        assert!(seg_seg_3d(&o, &[2., 2., 2.], &[0., 2., 0.], &[2., 0., 2.]));
        assert!(!seg_seg_3d(
            &o,
            &[2., 2., 2.],
            &[0., 2., 0.],
            &[2., 0., 2.0000000000000004]
        ));
        // Collinear along the z axis (two projections collapse to a point).
        assert!(seg_seg_3d(&o, &[0., 0., 1.], &[0., 0., 1.], &[0., 0., 3.]));
        assert!(!seg_seg_3d(
            &o,
            &[0., 0., 1.],
            &[0., 0., 1.5],
            &[0., 0., 3.]
        ));
        // Parallel, in a plane parallel to the z axis.
        assert!(!seg_seg_3d(&o, &[1., 1., 0.], &[0., 0., 1.], &[1., 1., 1.]));
    }

    #[test]
    fn degenerate_triangles() {
        let tri = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]];
        assert_eq!(proj_axis(&tri), Some(2));
        let seg = [[0.2, 0.2, -1.], [0.2, 0.2, 1.], [0.2, 0.2, 0.5]];
        assert_eq!(proj_axis(&seg), None);
        assert!(triangles_intersect(&tri, &seg));
        assert!(triangles_intersect(&seg, &tri));
        let seg_off = [[0.8, 0.8, -1.], [0.8, 0.8, 1.], [0.8, 0.8, 0.5]];
        assert!(!triangles_intersect(&tri, &seg_off));
        let point = [[0.25, 0.5, 0.]; 3];
        assert!(triangles_intersect(&tri, &point));
        assert!(triangles_intersect(&point, &point));
        let point_off = [[0.25, 0.5, 1e-15]; 3];
        assert!(!triangles_intersect(&tri, &point_off));
        assert!(!triangles_intersect(&point, &point_off));
        // Two crossing degenerate triangles (segments).
        let s2 = [[0.2, 0.0, 0.0], [0.2, 0.4, 0.0], [0.2, 0.1, 0.0]];
        let s3 = [[0.0, 0.2, 0.0], [0.4, 0.2, 0.0], [0.0, 0.2, 0.0]];
        assert!(triangles_intersect(&s2, &s3));
    }

    fn mesh(vertices: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> TriMesh {
        TriMesh::new(vertices, faces).unwrap()
    }

    #[test]
    fn shared_edge_rule() {
        let v = vec![
            [0., 0., 0.],
            [1., 0., 0.],
            [0., 1., 0.],
            [0.3, 0.3, 0.],  // same side as 2, coplanar
            [0.3, -0.3, 0.], // other side, coplanar
            [0.3, 0.3, 1.],  // not coplanar
        ];
        let m = mesh(v, vec![[0, 1, 2], [1, 0, 3], [1, 0, 4], [1, 0, 5]]);
        assert!(faces_intersect(&m, 0, 1), "folded");
        assert!(!faces_intersect(&m, 0, 2), "flat neighbour");
        assert!(!faces_intersect(&m, 0, 3), "dihedral angle");
        assert!(!faces_intersect(&m, 2, 3));
    }

    #[test]
    fn shared_vertex_rule() {
        let v = vec![
            [0., 0., 0.],    // 0: shared
            [2., 0., 0.],    // 1
            [0., 2., 0.],    // 2
            [0.5, 0.5, -1.], // 3
            [0.5, 0.5, 1.],  // 4: 0,3,4 pierces 0,1,2 along a segment from 0
            [-1., 0., 1.],   // 5
            [0., -1., 1.],   // 6: 0,5,6 only touches at 0
            [-1., 0., 0.],   // 7
            [0., -1., 0.],   // 8: 0,7,8 coplanar, opposite sector
            [1., 1., 0.],    // 9: 0,9,1 coplanar, overlapping sector
            [1., -1., 0.],   // 10: 0,1,10 coplanar, sharing the ray 0->1 only
        ];
        let m = mesh(
            v,
            vec![
                [0, 1, 2],
                [0, 3, 4],
                [0, 5, 6],
                [0, 7, 8],
                [0, 9, 1],
                [0, 10, 1],
                [0, 1, 10],
            ],
        );
        assert!(faces_intersect(&m, 0, 1));
        assert!(faces_intersect(&m, 1, 0));
        assert!(!faces_intersect(&m, 0, 2));
        assert!(!faces_intersect(&m, 0, 3));
        assert!(
            faces_intersect(&m, 0, 4),
            "coplanar overlap, shared edge 0-1 folded"
        );
        assert!(
            !faces_intersect(&m, 0, 5),
            "coplanar, opposite sides of shared edge"
        );
        // Same three indices: duplicate.
        let d = mesh(
            vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]],
            vec![[0, 1, 2], [2, 1, 0]],
        );
        assert!(faces_intersect(&d, 0, 1));
        // One shared index, coplanar, sectors overlap along the ray 0 -> (1,0,0).
        let r = mesh(
            vec![
                [0., 0., 0.],
                [2., 0., 0.],
                [0., 2., 0.],
                [1., 0., 0.],
                [1., -1., 0.],
            ],
            vec![[0, 1, 2], [0, 4, 3]],
        );
        assert!(faces_intersect(&r, 0, 1));
    }

    /// The one-shared-vertex fast exit of `pair_rule` (an opposite edge strictly on one side
    /// of the other plane) never changes the answer of the full rule (both opposite edges
    /// against the other triangle), on small integer coordinates full of coplanar and
    /// collinear cases.
    #[test]
    fn shared_vertex_fast_exit_agrees_with_the_full_rule() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let mut coord = || rng.random_range(-2i32..=2) as f64;
        let (mut tested, mut touching, mut crossing) = (0, 0, 0);
        for _ in 0..40_000 {
            let mut p = || [coord(), coord(), coord()];
            let (v, a, b, c, d) = (p(), p(), p(), p(), p());
            let (ti, tj) = ([v, a, b], [v, c, d]);
            let (Some(ii), Some(ij)) = (proj_axis(&ti), proj_axis(&tj)) else {
                continue;
            };
            tested += 1;
            let fast = pair_rule([0, 1, 2], ti, ii, [0, 3, 4], tj, ij);
            let full = seg_tri(&a, &b, &tj, Some(ij)) || seg_tri(&c, &d, &ti, Some(ii));
            assert_eq!(fast, full, "v {v:?} a {a:?} b {b:?} c {c:?} d {d:?}");
            if full {
                crossing += 1;
            } else {
                touching += 1;
            }
        }
        assert!(tested > 20_000 && touching > 1_000 && crossing > 1_000);
    }

    /// The coplanar wedge rule of `pair_rule` gives the full rule's answer (both opposite
    /// edges against the other triangle) on coplanar pairs sharing one vertex: small integer
    /// combinations of two integer directions, on axis-aligned and tilted planes, full of
    /// shared rays, touching corners and collinear edges.
    #[test]
    fn coplanar_shared_vertex_wedges_agree_with_the_full_rule() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
        let (mut tested, mut touching, mut overlapping) = (0, 0, 0);
        for _ in 0..60_000 {
            let mut int = |r: i32| rng.random_range(-r..=r) as f64;
            let (e1, e2) = ([int(2), int(2), int(2)], [int(2), int(2), int(2)]);
            let o = [int(3), int(3), int(3)];
            let mut p = || {
                let (i, j) = (int(3), int(3));
                std::array::from_fn(|k| o[k] + i * e1[k] + j * e2[k])
            };
            let (v, a, b, c, d): ([f64; 3], _, _, _, _) = (p(), p(), p(), p(), p());
            let (ti, tj) = ([v, a, b], [v, c, d]);
            let (Some(ii), Some(ij)) = (proj_axis(&ti), proj_axis(&tj)) else {
                continue;
            };
            // Exactly coplanar by construction; the rule's coplanar branch is the one taken.
            assert!(o3(&v, &a, &b, &c) == 0 && o3(&v, &a, &b, &d) == 0);
            tested += 1;
            let rule = pair_rule([0, 1, 2], ti, ii, [0, 3, 4], tj, ij);
            let full = seg_tri(&a, &b, &tj, Some(ij)) || seg_tri(&c, &d, &ti, Some(ii));
            assert_eq!(rule, full, "v {v:?} a {a:?} b {b:?} c {c:?} d {d:?}");
            if full {
                overlapping += 1;
            } else {
                touching += 1;
            }
        }
        assert!(
            tested > 20_000 && touching > 2_000 && overlapping > 2_000,
            "{tested} {touching} {overlapping}"
        );
    }

    #[test]
    fn degenerate_faces_sharing_vertices_are_not_tested() {
        let m = mesh(
            vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [2., 0., 0.]],
            vec![[0, 1, 2], [0, 1, 3], [0, 0, 2]],
        );
        assert!(!faces_intersect(&m, 0, 1));
        assert!(!faces_intersect(&m, 0, 2));
        assert_eq!(face_info(&m, 1), DEGENERATE);
        assert_eq!(face_info(&m, 2), DEGENERATE);
        let r = check(&m);
        assert_eq!(r.degenerate_faces, 2);
    }

    #[test]
    fn union_find_basics() {
        let mut uf = UnionFind::new(5);
        uf.union(0, 1);
        uf.union(3, 4);
        uf.union(1, 4);
        assert_eq!(uf.find(0), uf.find(3));
        assert_ne!(uf.find(0), uf.find(2));
    }
}
