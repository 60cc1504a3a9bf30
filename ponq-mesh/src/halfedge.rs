//! Half-edges of a closed, oriented 2-manifold triangle mesh: the opposite of every half-edge,
//! one outgoing half-edge per vertex, vertex fans, and edge flips in constant time.
//!
//! Half-edge `h = 3 f + k` of face `f = [v0, v1, v2]` goes from `v_k` to `v_(k+1 mod 3)`; the
//! faces stay the caller's `[[u32; 3]]` array (a [`TriMesh`](crate::TriMesh)'s `faces`), which
//! [`HalfEdges::flip`] rewrites in place, so nothing is converted in or out. Written here rather
//! than taken from a mesh crate because those keep their own mesh types (a conversion each way
//! per use) and the crease flips need exactly this: find an edge by its two vertices, walk a
//! vertex's fan, flip.
//!
//! ```
//! use ponq_mesh::halfedge::HalfEdges;
//! // A tetrahedron, faces counter-clockwise seen from outside.
//! let faces = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]];
//! let he = HalfEdges::new(&faces, 4).expect("closed and manifold");
//! let h = he.find(&faces, 0, 1).expect("an edge");
//! assert_eq!(HalfEdges::target(&faces, he.opposite(h)), 0);
//! assert_eq!(he.outgoing(&faces, 3).count(), 3);
//! ```

use std::sync::atomic::AtomicU32;
use std::sync::atomic::Ordering::Relaxed;

use rayon::prelude::*;

use crate::corners::{Link, PARALLEL_MIN_CORNERS, corner_rows, one_cycle_steps};

/// No half-edge.
pub const NONE: u32 = u32::MAX;

/// An outgoing half-edge `h` of a vertex, with the vertex it goes to and the vertex before
/// it in its face (the origin of the half-edge that ends where `h` starts).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Outgoing {
    h: u32,
    target: u32,
    before: u32,
}

impl Link for Outgoing {
    /// The edge of the origin's link this corner holds: from the target to the vertex before.
    #[inline(always)]
    fn link(&self) -> (u32, u32) {
        (self.target, self.before)
    }
}

/// The outgoing half-edges of each vertex of `faces` (every index below `n`) with their
/// targets and the vertices before them in their faces, grouped by vertex in face order
/// (compressed rows: vertex `v`'s are `rows[start[v]..start[v + 1]]`).
pub(crate) fn outgoing_rows(faces: &[[u32; 3]], n: usize) -> (Vec<u32>, Vec<Outgoing>) {
    corner_rows(faces, n, |fi, f, k| Outgoing {
        h: (3 * fi + k) as u32,
        target: f[(k + 1) % 3],
        before: f[(k + 2) % 3],
    })
}

/// Opposites and one outgoing half-edge per vertex of a closed, oriented 2-manifold.
///
/// Invariants (checked by [`HalfEdges::new`], kept by [`HalfEdges::flip`]):
/// `opposite(opposite(h)) == h`; `h` goes from `u` to `v` exactly when `opposite(h)` goes from
/// `v` to `u`; each vertex with faces has one fan, reached from its outgoing half-edge, of
/// `degree(v)` half-edges.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HalfEdges {
    opp: Vec<u32>,
    out: Vec<u32>,
    degree: Vec<u32>,
}

impl HalfEdges {
    /// The half-edges of `faces` over `n_vertices` vertices, or `None` unless every face has
    /// three distinct vertices `< n_vertices`, every edge belongs to exactly two faces that
    /// traverse it in opposite directions, and the faces around each vertex form one fan.
    pub fn new(faces: &[[u32; 3]], n_vertices: usize) -> Option<Self> {
        let n = n_vertices;
        let nh = faces.len() * 3;
        if nh >= NONE as usize
            || faces.iter().any(|f| {
                f.iter().any(|&v| v as usize >= n) || f[0] == f[1] || f[1] == f[2] || f[0] == f[2]
            })
        {
            return None;
        }
        let (start, rows) = outgoing_rows(faces, n);
        let (bad, he) = Self::checking_links(&start, &rows, true);
        debug_assert!(he.is_none() || bad.is_empty());
        he
    }

    /// The vertices (with faces) whose link in [`outgoing_rows`] `(start, rows)` is not one
    /// cycle ([`crate::corners::one_cycle`]) and, if `half_edges` and there are none, the
    /// half-edges. Every link one cycle is what [`HalfEdges::new`] asks (each edge in two
    /// faces that traverse it in opposite directions, one fan per vertex), and following the
    /// cycles gives the opposites: the opposite of `h = u -> v` is the one half-edge `v -> u`,
    /// `prev(g)` for the outgoing `g` of `u` whose face has `v` before `u`, the corner before
    /// `h`'s in `u`'s cycle. (A search of `v`'s row for each half-edge missed the cache each
    /// time; a search of `u`'s row, as a pass of its own after the manifold check, cost ~3 ms
    /// at 217k faces: the cycle test finds the same corners.)
    pub(crate) fn checking_links(
        start: &[u32],
        rows: &[Outgoing],
        half_edges: bool,
    ) -> (Vec<u32>, Option<Self>) {
        let n = start.len() - 1;
        let row = |v: u32| &rows[start[v as usize] as usize..start[v as usize + 1] as usize];
        // Written once per half-edge when every link is one cycle (else dropped).
        // In parallel only for large surfaces: a parallel call from outside the pool waits
        // for a worker to wake up, which smaller ones do not repay (see [`corner_rows`]).
        let large = rows.len() >= PARALLEL_MIN_CORNERS;
        let opp: Vec<AtomicU32> = if half_edges {
            collect_indexed(rows.len(), large, |_| AtomicU32::new(NONE))
        } else {
            Vec::new()
        };
        let bad: Vec<u32> = (0..n as u32)
            .into_par_iter()
            .with_min_len(1024)
            .filter(|&u| {
                let c = row(u);
                let one = one_cycle_steps(c, |i, j| {
                    if half_edges {
                        opp[c[j].h as usize].store(Self::prev(c[i].h), Relaxed);
                    }
                });
                !c.is_empty() && !one
            })
            .collect();
        if !half_edges || !bad.is_empty() {
            return (bad, None);
        }
        // In place (the same layout): no new array.
        let opp: Vec<u32> = opp.into_iter().map(AtomicU32::into_inner).collect();
        let degree = collect_indexed(n, large, |v| start[v + 1] - start[v]);
        let out = collect_indexed(n, large, |v| row(v as u32).first().map_or(NONE, |o| o.h));
        (bad, Some(Self { opp, out, degree }))
    }

    /// The same half-edges after the vertices were renumbered, the faces keeping their order:
    /// new vertex `i` is old vertex `old[i]` (old vertices in no face may be left out, as
    /// [`crate::TriMesh::remove_unreferenced_vertices`] does). Half-edge numbers do not
    /// change.
    ///
    /// # Panics
    /// If an index of `old` is out of range.
    pub(crate) fn renumbered(self, old: &[u32]) -> Self {
        Self {
            out: old.iter().map(|&v| self.out[v as usize]).collect(),
            degree: old.iter().map(|&v| self.degree[v as usize]).collect(),
            opp: self.opp,
        }
    }

    /// The vertex `h` starts at.
    #[inline]
    pub fn origin(faces: &[[u32; 3]], h: u32) -> u32 {
        faces[(h / 3) as usize][(h % 3) as usize]
    }

    /// The vertex `h` ends at.
    #[inline]
    pub fn target(faces: &[[u32; 3]], h: u32) -> u32 {
        faces[(h / 3) as usize][((h % 3 + 1) % 3) as usize]
    }

    /// The half-edge before `h` in its face (it ends where `h` starts).
    #[inline]
    pub fn prev(h: u32) -> u32 {
        h - h % 3 + (h % 3 + 2) % 3
    }

    /// The half-edge opposite `h`.
    #[inline]
    pub fn opposite(&self, h: u32) -> u32 {
        self.opp[h as usize]
    }

    /// The next outgoing half-edge of `origin(h)` around its fan.
    #[inline]
    fn rotate(&self, h: u32) -> u32 {
        self.opp[Self::prev(h) as usize]
    }

    /// Length of `v`'s fan, counting at most `limit + 1` half-edges (the tests' reference).
    #[cfg(test)]
    fn fan_len(&self, faces: &[[u32; 3]], v: u32, limit: usize) -> usize {
        let first = self.out[v as usize];
        let mut h = first;
        let mut len = 0;
        loop {
            if Self::origin(faces, h) != v {
                return usize::MAX;
            }
            len += 1;
            h = self.rotate(h);
            if h == first || len > limit {
                return len;
            }
        }
    }

    /// The outgoing half-edges of vertex `v` around its fan (none for a vertex without faces).
    pub fn outgoing<'a>(&'a self, faces: &'a [[u32; 3]], v: u32) -> impl Iterator<Item = u32> + 'a {
        let first = self.out[v as usize];
        let mut h = first;
        let mut done = first == NONE;
        std::iter::from_fn(move || {
            if done {
                return None;
            }
            let cur = h;
            h = self.rotate(h);
            done = h == first;
            debug_assert_eq!(Self::origin(faces, cur), v);
            Some(cur)
        })
    }

    /// The half-edge from `u` to `v`, if `u v` is an edge.
    pub fn find(&self, faces: &[[u32; 3]], u: u32, v: u32) -> Option<u32> {
        self.outgoing(faces, u)
            .find(|&h| Self::target(faces, h) == v)
    }

    /// Flips the edge of `h`: with `h` = `u -> v` in face `(u, v, a)` and its opposite in
    /// `(v, u, b)`, the faces become `[b, v, a]` (in `h`'s face) and `[a, u, b]` (in the
    /// opposite's face). The caller makes sure `a != b` and `a b` is not an edge yet (else the
    /// result is not a manifold). Returns `(u, v, a, b)`.
    pub fn flip(&mut self, faces: &mut [[u32; 3]], h: u32) -> [u32; 4] {
        let g = self.opp[h as usize];
        let (i1, i2) = ((h / 3) as usize, (g / 3) as usize);
        let next = |x: u32| x - x % 3 + (x % 3 + 1) % 3;
        let (u, v) = (Self::origin(faces, h), Self::target(faces, h));
        let a = Self::target(faces, next(h));
        let b = Self::target(faces, next(g));
        // The outer edges' opposites, before the faces change: v -> a, a -> u in h's face,
        // u -> b, b -> v in the other.
        let (o_va, o_au) = (self.opp[next(h) as usize], self.opp[Self::prev(h) as usize]);
        let (o_ub, o_bv) = (self.opp[next(g) as usize], self.opp[Self::prev(g) as usize]);
        faces[i1] = [b, v, a];
        faces[i2] = [a, u, b];
        let (f1, f2) = (3 * i1 as u32, 3 * i2 as u32);
        let mut link = |x: u32, y: u32| {
            self.opp[x as usize] = y;
            self.opp[y as usize] = x;
        };
        link(f1, o_bv); // b -> v
        link(f1 + 1, o_va); // v -> a
        link(f1 + 2, f2 + 2); // a -> b, b -> a
        link(f2, o_au); // a -> u
        link(f2 + 1, o_ub); // u -> b
        self.out[u as usize] = f2 + 1;
        self.out[v as usize] = f1 + 1;
        self.out[a as usize] = f1 + 2;
        self.out[b as usize] = f1;
        self.degree[u as usize] -= 1;
        self.degree[v as usize] -= 1;
        self.degree[a as usize] += 1;
        self.degree[b as usize] += 1;
        [u, v, a, b]
    }

    /// The undirected edges as their half-edges `u -> v` with `u < v`, sorted by `(u, v)`.
    pub fn sorted_edges(&self, faces: &[[u32; 3]]) -> Vec<u32> {
        const RANGE: u32 = 8192;
        let n = self.out.len() as u32;
        let parts: Vec<Vec<u32>> = (0..n.div_ceil(RANGE))
            .into_par_iter()
            .map(|r| {
                let mut part = Vec::with_capacity(3 * RANGE as usize);
                for u in r * RANGE..((r + 1) * RANGE).min(n) {
                    let s = part.len();
                    part.extend(
                        self.outgoing(faces, u)
                            .filter(|&h| Self::target(faces, h) > u),
                    );
                    part[s..].sort_unstable_by_key(|&h| Self::target(faces, h));
                }
                part
            })
            .collect();
        parts.concat()
    }

    /// The number of edges at vertex `v` (the length of its fan).
    #[inline]
    pub fn degree(&self, v: u32) -> u32 {
        self.degree[v as usize]
    }
}

/// `(0..len).map(f)` collected, in parallel when `parallel` (see [`PARALLEL_MIN_CORNERS`] for
/// why small surfaces stay on the calling thread).
fn collect_indexed<T: Send>(
    len: usize,
    parallel: bool,
    f: impl Fn(usize) -> T + Sync + Send,
) -> Vec<T> {
    if parallel {
        (0..len).into_par_iter().map(f).collect()
    } else {
        (0..len).map(f).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An octahedron (closed, oriented, every vertex of degree 4).
    fn octahedron() -> Vec<[u32; 3]> {
        // Vertices: 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z.
        vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ]
    }

    fn check_invariants(he: &HalfEdges, faces: &[[u32; 3]], n: usize) {
        for h in 0..faces.len() as u32 * 3 {
            let g = he.opposite(h);
            assert_eq!(he.opposite(g), h);
            assert_eq!(HalfEdges::origin(faces, h), HalfEdges::target(faces, g));
            assert_eq!(HalfEdges::target(faces, h), HalfEdges::origin(faces, g));
        }
        let rebuilt = HalfEdges::new(faces, n).expect("still a closed manifold");
        for v in 0..n as u32 {
            assert_eq!(he.degree(v), rebuilt.degree(v), "degree of {v}");
            let mut a: Vec<u32> = he.outgoing(faces, v).collect();
            let mut b: Vec<u32> = rebuilt.outgoing(faces, v).collect();
            a.sort_unstable();
            b.sort_unstable();
            assert_eq!(a, b, "fan of {v}");
        }
    }

    #[test]
    fn opposites_fans_and_edges_of_an_octahedron() {
        let faces = octahedron();
        let he = HalfEdges::new(&faces, 6).expect("closed manifold");
        check_invariants(&he, &faces, 6);
        assert!((0..6).all(|v| he.degree(v) == 4));
        let edges: Vec<(u32, u32)> = he
            .sorted_edges(&faces)
            .iter()
            .map(|&h| (HalfEdges::origin(&faces, h), HalfEdges::target(&faces, h)))
            .collect();
        assert_eq!(edges.len(), 12);
        assert!(edges.windows(2).all(|w| w[0] < w[1]));
        assert!(edges.iter().all(|&(u, v)| he.find(&faces, u, v).is_some()));
        assert!(
            he.find(&faces, 0, 1).is_none(),
            "opposite poles are not adjacent"
        );
    }

    #[test]
    fn flips_keep_the_structure_exact() {
        let mut faces = octahedron();
        let mut he = HalfEdges::new(&faces, 6).expect("closed manifold");
        // Flip 2 - 4 (faces [0, 2, 4] and [2, 1, 4]) to 0 - 1.
        let h = he.find(&faces, 2, 4).expect("edge");
        let [u, v, a, b] = he.flip(&mut faces, h);
        assert_eq!((u, v), (2, 4));
        assert_eq!(
            [a, b]
                .iter()
                .copied()
                .collect::<std::collections::BTreeSet<_>>(),
            [0, 1].into()
        );
        check_invariants(&he, &faces, 6);
        assert!(he.find(&faces, 0, 1).is_some() && he.find(&faces, 2, 4).is_none());
        let degrees: Vec<u32> = (0..6).map(|v| he.degree(v)).collect();
        assert_eq!(degrees, vec![5, 5, 3, 4, 3, 4]);
    }

    /// A torus of `n x m` quads, two triangles each, oriented consistently.
    fn torus(n: u32, m: u32) -> Vec<[u32; 3]> {
        let id = |i: u32, j: u32| (i % n) * m + j % m;
        (0..n)
            .flat_map(|i| {
                (0..m).flat_map(move |j| {
                    let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                    [[a, b, c], [a, c, d]]
                })
            })
            .collect()
    }

    #[test]
    fn opposites_are_the_reversed_half_edges() {
        let faces = torus(37, 23);
        let n = 37 * 23;
        let he = HalfEdges::new(&faces, n).expect("a torus is a closed manifold");
        check_invariants(&he, &faces, n);
        let by_edge: std::collections::HashMap<(u32, u32), u32> = (0..3 * faces.len() as u32)
            .map(|h| {
                (
                    (HalfEdges::origin(&faces, h), HalfEdges::target(&faces, h)),
                    h,
                )
            })
            .collect();
        for h in 0..3 * faces.len() as u32 {
            let (u, v) = (HalfEdges::origin(&faces, h), HalfEdges::target(&faces, h));
            assert_eq!(he.opposite(h), by_edge[&(v, u)], "opposite of {u} -> {v}");
        }
        assert!((0..n as u32).all(|v| he.degree(v) == 6));
        // One face turned over, or one missing, anywhere: refused.
        for f in [0, 500, faces.len() - 1] {
            let mut turned = faces.clone();
            turned[f].swap(1, 2);
            assert!(HalfEdges::new(&turned, n).is_none(), "face {f} turned over");
            let mut open = faces.clone();
            open.remove(f);
            assert!(HalfEdges::new(&open, n).is_none(), "face {f} removed");
        }
    }

    /// The half-edges made from the corner rows over scattered vertex numbers (with vertices in
    /// no face between them), then renumbered, are those of the renumbered faces.
    #[test]
    fn rows_and_renumbering_give_the_half_edges_of_new() {
        let faces = torus(19, 11);
        let n = 19 * 11;
        // New vertex i is old vertex old[i]: a scattered injection into 3n numbers.
        let old: Vec<u32> = (0..n as u32).map(|i| (i * 7919) % (3 * n as u32)).collect();
        assert_eq!(
            old.iter().collect::<std::collections::HashSet<_>>().len(),
            n
        );
        let old_faces: Vec<[u32; 3]> = faces.iter().map(|f| f.map(|v| old[v as usize])).collect();
        let (start, rows) = outgoing_rows(&old_faces, 3 * n);
        let (bad, he) = HalfEdges::checking_links(&start, &rows, true);
        let he = he.expect("a closed manifold");
        assert!(bad.is_empty());
        assert_eq!(Some(&he), HalfEdges::new(&old_faces, 3 * n).as_ref());
        let renumbered = he.renumbered(&old);
        assert_eq!(Some(renumbered), HalfEdges::new(&faces, n));
        // A hole: the three vertices of the removed face are reported, no half-edges.
        let (start, rows) = outgoing_rows(&old_faces[1..], 3 * n);
        let (mut bad, he) = HalfEdges::checking_links(&start, &rows, true);
        bad.sort_unstable();
        let mut hole = old_faces[0].to_vec();
        hole.sort_unstable();
        assert!(he.is_none() && bad == hole);
    }

    /// [`HalfEdges::new`] without the link cycles: the opposites from a map of the directed
    /// edges (each once, its reverse present), then a walk around each vertex's fan.
    fn reference_new(faces: &[[u32; 3]], n: usize) -> Option<HalfEdges> {
        use std::collections::HashMap;
        if faces.iter().any(|f| {
            f.iter().any(|&v| v as usize >= n) || f[0] == f[1] || f[1] == f[2] || f[0] == f[2]
        }) {
            return None;
        }
        let mut by_edge: HashMap<(u32, u32), u32> = HashMap::new();
        for h in 0..3 * faces.len() as u32 {
            let e = (HalfEdges::origin(faces, h), HalfEdges::target(faces, h));
            if by_edge.insert(e, h).is_some() {
                return None;
            }
        }
        let mut opp = vec![NONE; 3 * faces.len()];
        for (&(u, v), &h) in &by_edge {
            opp[h as usize] = *by_edge.get(&(v, u))?;
        }
        let (mut out, mut degree) = (vec![NONE; n], vec![0u32; n]);
        for h in (0..3 * faces.len() as u32).rev() {
            let u = HalfEdges::origin(faces, h) as usize;
            out[u] = h;
            degree[u] += 1;
        }
        let he = HalfEdges { opp, out, degree };
        (0..n as u32)
            .all(|v| {
                let d = he.degree(v) as usize;
                d == 0 || he.fan_len(faces, v, d) == d
            })
            .then_some(he)
    }

    /// On closed meshes and on broken ones (a face turned over, removed, repeated, two
    /// vertices glued, a high-degree vertex), `new` accepts and builds exactly what the
    /// reference does.
    #[test]
    fn new_agrees_with_the_reference_on_broken_meshes() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut r = |k: usize| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % k as u64) as usize
        };
        let (mut accepted, mut refused) = (0, 0);
        for case in 0..300 {
            let (a, b) = (3 + r(6) as u32, 3 + r(6) as u32);
            let mut faces = torus(a, b);
            let mut n = (a * b) as usize;
            match case % 6 {
                0 => {}
                1 => {
                    let f = r(faces.len());
                    faces[f].swap(1, 2);
                }
                2 => {
                    faces.remove(r(faces.len()));
                }
                3 => {
                    let f = faces[r(faces.len())];
                    faces.push(f);
                }
                4 => {
                    let (x, y) = (r(n) as u32, r(n) as u32);
                    for f in &mut faces {
                        for v in f.iter_mut() {
                            if *v == y {
                                *v = x;
                            }
                        }
                    }
                }
                _ => {
                    // A bipyramid over a ring of 33 to 40 vertices: two vertices above the
                    // sorted cycle test's threshold; every other one with a face turned over.
                    let m = 33 + r(8) as u32;
                    n = m as usize + 2;
                    faces = (0..m)
                        .flat_map(|k| [[m, k, (k + 1) % m], [m + 1, (k + 1) % m, k]])
                        .collect();
                    if case % 12 == 11 {
                        let f = r(faces.len());
                        faces[f].swap(0, 1);
                    }
                }
            }
            let expected = reference_new(&faces, n);
            assert_eq!(HalfEdges::new(&faces, n), expected, "case {case}");
            if expected.is_some() {
                accepted += 1;
            } else {
                refused += 1;
            }
        }
        assert!(accepted >= 50 && refused >= 150, "{accepted} / {refused}");
    }

    #[test]
    fn open_non_manifold_and_misoriented_inputs_are_refused() {
        let mut open = octahedron();
        open.pop();
        assert!(HalfEdges::new(&open, 6).is_none(), "a hole");
        let mut flipped = octahedron();
        flipped[0] = [0, 4, 2];
        assert!(
            HalfEdges::new(&flipped, 6).is_none(),
            "one face turned over"
        );
        let mut dup = octahedron();
        dup.push([0, 2, 4]);
        assert!(HalfEdges::new(&dup, 6).is_none(), "an edge in three faces");
        assert!(
            HalfEdges::new(&[[0, 0, 1]], 2).is_none(),
            "a degenerate face"
        );
        assert!(
            HalfEdges::new(&octahedron(), 5).is_none(),
            "an index out of range"
        );
        // Two octahedra sharing one vertex (5 of the first is 0 of the second): every edge
        // has two faces but the shared vertex has two fans.
        let mut two = octahedron();
        let map = |v: u32| if v == 0 { 5 } else { v + 5 };
        two.extend(octahedron().iter().map(|f| f.map(map)));
        assert!(HalfEdges::new(&two, 11).is_none(), "a vertex with two fans");
        // The same two, disjoint, are fine.
        let mut apart = octahedron();
        apart.extend(octahedron().iter().map(|f| f.map(|v| v + 6)));
        assert!(HalfEdges::new(&apart, 12).is_some());
    }
}
