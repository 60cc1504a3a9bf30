//! Crease-aligned diagonals: edge flips on the extracted surface that lower the minimum cut's
//! own face score ([`crate::score`]), so that where two triangles form a quadrilateral the
//! diagonal follows the sharp edge the PoNQ quadrics describe.
//!
//! A CAD PoNQ is nearly a lattice: its Delaunay tetrahedralisation is not unique (co-spherical
//! points), and which diagonal a quadrilateral gets is then decided by the symbolic
//! perturbation, not by the geometry. Here, for two triangles `(u, v, a)` and `(v, u, b)`
//! sharing the edge `u v`, the flip to `(b, v, a)`, `(a, u, b)` is made when it lowers
//! `S(T1) + S(T2)` with `S(T) = h sum_{i != j} Q_i(v_j) + (sum_i angle(n_T, n_i) / 1.5)^2` (the
//! paper's face score: quadric error of the face's vertices under each other's quadrics, and
//! deviation of the face normal from the vertices' normals) and at least halves the quadric
//! error of the diagonal (the four vertices' quadrics at its midpoint): across a crease between
//! planes `P1` and `P2`, with `u` on `P1`, `v` on `P2` and `a`, `b` on the crease, the midpoint
//! of `a b` lies on both planes (error 0) and that of `u v` cuts the corner; on a flat region
//! both diagonals fit, and nothing is flipped. Errors below (1% of a cell)^2 are noise.
//!
//! Guarantees: a flip is made only when the new edge `a b` is not already an edge, `u` and `v`
//! keep at least three neighbours and the new triangles are not degenerate, so the surface stays
//! closed, oriented and a 2-manifold; afterwards the exact self-intersection test runs, and if
//! any flipped triangle intersects another one, all flips are undone and the pass is redone
//! without the quadrilaterals involved (and, as a last resort, the surface is left as it was).
//! The pass is sequential and deterministic.

use rustc_hash::{FxHashMap, FxHashSet};

use crate::TriMesh;
use crate::quadric::Quadric;
use crate::score::NORMAL_SCALE;
use crate::validity::intersecting_face_pairs_among;

/// What [`align_creases`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FlipStats {
    /// Flips kept.
    pub flips: usize,
    /// Passes over the edges in the last attempt.
    pub passes: usize,
    /// Attempts (1 unless flips had to be undone because of self-intersections).
    pub attempts: usize,
    /// Quadrilaterals excluded after a self-intersection.
    pub excluded: usize,
}

/// Relative gain of the whole score a flip must bring.
const MIN_GAIN: f64 = 1e-9;
/// A flip must bring the quadric error of the pair below this fraction of what it was: flat
/// regions (both diagonals fit the planes) are left alone, only diagonals across a crease are
/// flipped onto it.
const QUADRIC_FACTOR: f64 = 0.5;
/// Passes over all edges at most (each pass flips only improving pairs).
const MAX_PASSES: usize = 8;
/// Attempts before giving up on flips.
const MAX_ATTEMPTS: usize = 4;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The face score of the outward triangle `f` (see the [module docs](self)) as its quadric
/// term `h S_Q` and its normal term, or `None` when it is degenerate.
fn score(
    mesh: &TriMesh,
    quadrics: &[Quadric],
    normals: &[[f64; 3]],
    h: f64,
    f: [u32; 3],
) -> Option<(f64, f64)> {
    let p = f.map(|v| mesh.vertices[v as usize]);
    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let scale = [sub(p[1], p[0]), sub(p[2], p[1]), sub(p[0], p[2])]
        .iter()
        .map(|e| e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        .fold(0.0, f64::max);
    if !(len > 1e-12 * scale) || !len.is_finite() {
        return None;
    }
    let n = n.map(|x| x / len);
    let mut sq = 0.0;
    for a in 0..3 {
        for b in 0..3 {
            if a != b {
                sq += quadrics[f[a] as usize].eval(p[b]).max(0.0);
            }
        }
    }
    let sn: f64 = f
        .iter()
        .map(|&i| {
            let m = normals[i as usize];
            (n[0] * m[0] + n[1] * m[1] + n[2] * m[2])
                .clamp(-1.0, 1.0)
                .acos()
        })
        .sum();
    Some((h * sq, (sn / NORMAL_SCALE).powi(2)))
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// The faces of one undirected edge: the first two, and how many there are (two on a closed
/// manifold surface; any other count leaves the edge alone).
#[derive(Debug, Clone, Copy)]
struct EdgeFaces {
    faces: [u32; 2],
    count: u32,
}

/// Faces of every undirected edge. A fast (Fx) hash: the keys are vertex pairs of our own
/// mesh, not adversarial input, and the map is probed a few times per edge and pass.
fn edge_faces(mesh: &TriMesh) -> FxHashMap<(u32, u32), EdgeFaces> {
    let mut m: FxHashMap<(u32, u32), EdgeFaces> =
        FxHashMap::with_capacity_and_hasher(mesh.faces.len() * 3 / 2, Default::default());
    for (fi, f) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let e = m.entry(key(f[k], f[(k + 1) % 3])).or_insert(EdgeFaces {
                faces: [u32::MAX; 2],
                count: 0,
            });
            if e.count < 2 {
                e.faces[e.count as usize] = fi as u32;
            }
            e.count += 1;
        }
    }
    m
}

/// The face rotated so that it starts with `u` (it must contain `u`).
fn starting_at(f: [u32; 3], u: u32) -> [u32; 3] {
    if f[0] == u {
        f
    } else if f[1] == u {
        [f[1], f[2], f[0]]
    } else {
        [f[2], f[0], f[1]]
    }
}

/// One attempt: greedy improving flips, skipping the quadrilaterals (edges) in `banned`.
/// Returns the flipped face pairs.
fn flip_pass(
    mesh: &mut TriMesh,
    quadrics: &[Quadric],
    normals: &[[f64; 3]],
    h: f64,
    banned: &FxHashSet<(u32, u32)>,
    stats: &mut FlipStats,
) -> Vec<(u32, u32)> {
    let mut edges = edge_faces(mesh);
    let mut degree = vec![0u32; mesh.vertices.len()];
    for (&(a, b), fs) in &edges {
        if fs.count == 2 {
            degree[a as usize] += 1;
            degree[b as usize] += 1;
        }
    }
    let mut flipped = Vec::new();
    // Quadric errors below (1% of a cell)^2 per vertex are noise (the quadrics are normalised:
    // they measure squared distances).
    let noise = 4.0 * (0.01f64).powi(2) / h.max(1e-30);
    stats.passes = 0;
    for _ in 0..MAX_PASSES {
        stats.passes += 1;
        let mut changed = false;
        let mut keys: Vec<(u32, u32)> = edges.keys().copied().collect();
        keys.sort_unstable();
        for e in keys {
            if banned.contains(&e) {
                continue;
            }
            let Some(fs) = edges.get(&e) else { continue };
            if fs.count != 2 {
                continue;
            }
            let (fa, fb) = (fs.faces[0] as usize, fs.faces[1] as usize);
            let (u, v) = e;
            // f1 = (u, v, a) and f2 = (v, u, b), whichever face holds the directed edge u->v.
            let (mut f1, mut f2) = (
                starting_at(mesh.faces[fa], u),
                starting_at(mesh.faces[fb], v),
            );
            let (mut i1, mut i2) = (fa, fb);
            if f1[1] != v {
                f1 = starting_at(mesh.faces[fb], u);
                f2 = starting_at(mesh.faces[fa], v);
                (i1, i2) = (fb, fa);
            }
            if f1[1] != v || f2[1] != u {
                continue; // inconsistent orientation: leave it
            }
            let (a, b) = (f1[2], f2[2]);
            if a == b
                || edges.contains_key(&key(a, b))
                || degree[u as usize] <= 3
                || degree[v as usize] <= 3
            {
                continue;
            }
            let (g1, g2) = ([b, v, a], [a, u, b]);
            // A flip must at least halve the quadric error of the diagonal (the four vertices'
            // quadrics at its midpoint: zero on a crease line, positive on a diagonal that cuts
            // across it), by more than noise, and lower the whole face score. The quadric test
            // comes first: it is cheap and rejects almost every edge (flat regions), so the
            // face scores (three `acos` each) are computed for the few candidates only.
            let mid = |x: u32, y: u32| {
                let (p, q) = (mesh.vertices[x as usize], mesh.vertices[y as usize]);
                [
                    0.5 * (p[0] + q[0]),
                    0.5 * (p[1] + q[1]),
                    0.5 * (p[2] + q[2]),
                ]
            };
            let err = |m: [f64; 3]| -> f64 {
                [u, v, a, b]
                    .iter()
                    .map(|&w| quadrics[w as usize].eval(m).max(0.0))
                    .sum()
            };
            let (e_old, e_new) = (err(mid(u, v)), err(mid(a, b)));
            if !(e_new < QUADRIC_FACTOR * e_old && e_old > noise) {
                continue;
            }
            let (Some(s1), Some(s2)) = (
                score(mesh, quadrics, normals, h, f1),
                score(mesh, quadrics, normals, h, f2),
            ) else {
                continue;
            };
            let (Some(t1), Some(t2)) = (
                score(mesh, quadrics, normals, h, g1),
                score(mesh, quadrics, normals, h, g2),
            ) else {
                continue;
            };
            let (before, after) = (s1.0 + s2.0 + s1.1 + s2.1, t1.0 + t2.0 + t1.1 + t2.1);
            if !(after < before - MIN_GAIN * before.abs()) {
                continue;
            }
            // Flip: update faces, edge map and degrees.
            mesh.faces[i1] = g1;
            mesh.faces[i2] = g2;
            edges.remove(&e);
            edges.insert(
                key(a, b),
                EdgeFaces {
                    faces: [i1 as u32, i2 as u32],
                    count: 2,
                },
            );
            // The four outer edges change faces: v-a and b-v are in g1, a-u and u-b in g2.
            for (x, y, fnew) in [(v, a, i1), (b, v, i1), (a, u, i2), (u, b, i2)] {
                if let Some(list) = edges.get_mut(&key(x, y)) {
                    let n = (list.count as usize).min(2);
                    for f in list.faces[..n].iter_mut() {
                        if *f as usize == i1 || *f as usize == i2 {
                            *f = fnew as u32;
                        }
                    }
                }
            }
            degree[u as usize] -= 1;
            degree[v as usize] -= 1;
            degree[a as usize] += 1;
            degree[b as usize] += 1;
            flipped.push((i1 as u32, i2 as u32));
            changed = true;
        }
        if !changed {
            break;
        }
    }
    flipped
}

/// Flips the diagonals of quadrilaterals of the closed manifold surface `mesh` towards the
/// sharp edges described by the per-vertex (normalised) `quadrics` and unit `normals` (see the
/// [module docs](self)); `h` is the face-score weight (`grid_scale^2`). The result is as valid
/// as the input (closed, oriented, manifold, free of self-intersections).
pub fn align_creases(
    mesh: &mut TriMesh,
    quadrics: &[Quadric],
    normals: &[[f64; 3]],
    h: f64,
) -> FlipStats {
    let mut stats = FlipStats::default();
    if quadrics.len() != mesh.vertices.len() || normals.len() != mesh.vertices.len() {
        return stats;
    }
    let original = mesh.faces.clone();
    let mut banned = FxHashSet::default();
    for attempt in 1..=MAX_ATTEMPTS {
        stats.attempts = attempt;
        mesh.faces.clone_from(&original);
        let flipped = flip_pass(mesh, quadrics, normals, h, &banned, &mut stats);
        stats.flips = flipped.len();
        if flipped.is_empty() {
            return stats;
        }
        let touched: FxHashSet<u32> = flipped.iter().flat_map(|&(a, b)| [a, b]).collect();
        // The surface had no self-intersection before: only pairs with a flipped face can
        // intersect now, so only those are tested.
        let mut touched_list: Vec<usize> = touched.iter().map(|&f| f as usize).collect();
        touched_list.sort_unstable();
        let bad = intersecting_face_pairs_among(mesh, &touched_list);
        if bad.is_empty() {
            return stats;
        }
        // Exclude the original edges of the quadrilaterals whose new faces intersect.
        for (i, j) in bad {
            for f in [i, j] {
                if touched.contains(&(f as u32)) {
                    let g = original[f];
                    for k in 0..3 {
                        banned.insert(key(g[k], g[(k + 1) % 3]));
                    }
                }
            }
        }
        stats.excluded = banned.len();
    }
    mesh.faces = original;
    stats.flips = 0;
    stats
}
