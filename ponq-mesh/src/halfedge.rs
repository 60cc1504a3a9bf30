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

/// No half-edge.
pub const NONE: u32 = u32::MAX;

/// An outgoing half-edge `h` of a vertex, with the vertex it goes to and the vertex before
/// it in its face (the origin of the half-edge that ends where `h` starts).
#[derive(Debug, Clone, Copy, Default)]
struct Outgoing {
    h: u32,
    target: u32,
    before: u32,
}

/// Opposites and one outgoing half-edge per vertex of a closed, oriented 2-manifold.
///
/// Invariants (checked by [`HalfEdges::new`], kept by [`HalfEdges::flip`]):
/// `opposite(opposite(h)) == h`; `h` goes from `u` to `v` exactly when `opposite(h)` goes from
/// `v` to `u`; each vertex with faces has one fan, reached from its outgoing half-edge, of
/// `degree(v)` half-edges.
#[derive(Debug, Clone)]
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
        // The outgoing half-edges of each vertex with their targets and the vertices before
        // them in their faces (compressed rows).
        let (start, rows) = corner_rows(faces, n, |fi, f, k| Outgoing {
            h: (3 * fi + k) as u32,
            target: f[(k + 1) % 3],
            before: f[(k + 2) % 3],
        });
        debug_assert_eq!(rows.len(), nh);
        let row = |v: u32| &rows[start[v as usize] as usize..start[v as usize + 1] as usize];
        // The opposite of `h = u -> v` is the one half-edge `v -> u`; it is `prev(g)` for the
        // one outgoing `g` of `u` whose face has `v` before `u`. So each vertex's row alone
        // gives the opposites of its outgoing half-edges (a search of the target's row for
        // each half-edge missed the cache each time: 12.5 of the ~20 ms this function took on
        // a 217k-face mesh, now ~5).
        // A second `u -> v` needs no test of its own: if `v -> u` exists, `v`'s row finds two
        // half-edges before it, else `u -> v` finds no opposite.
        let opp_atomic: Vec<AtomicU32> = (0..nh).map(|_| AtomicU32::new(NONE)).collect();
        const RANGE: usize = 4096;
        let ok = (0..n.div_ceil(RANGE)).into_par_iter().all(|r| {
            (r * RANGE..((r + 1) * RANGE).min(n)).all(|u| {
                let out = row(u as u32);
                out.iter().all(|o| {
                    let mut found = NONE;
                    for g in out.iter().filter(|g| g.before == o.target) {
                        if found != NONE {
                            return false;
                        }
                        found = Self::prev(g.h);
                    }
                    opp_atomic[o.h as usize].store(found, Relaxed);
                    found != NONE
                })
            })
        });
        if !ok {
            return None;
        }
        let opp: Vec<u32> = opp_atomic.into_iter().map(AtomicU32::into_inner).collect();
        let degree: Vec<u32> = (0..n).map(|v| start[v + 1] - start[v]).collect();
        let out: Vec<u32> = (0..n as u32)
            .map(|v| row(v).first().map_or(NONE, |o| o.h))
            .collect();
        let he = Self { opp, out, degree };
        // One fan per vertex: walking around from its outgoing half-edge meets all of them.
        let one_fan = (0..n as u32).into_par_iter().all(|v| {
            let d = he.degree[v as usize] as usize;
            d == 0 || he.fan_len(faces, v, d) == d
        });
        one_fan.then_some(he)
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

    /// Length of `v`'s fan, counting at most `limit + 1` half-edges.
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

/// The corners of the faces grouped by vertex (compressed rows, a counting sort): the corners
/// of vertex `v` are `rows[start[v]..start[v + 1]]`, in face order, each made by
/// `corner(face index, face, k)` for the face's position `k` holding `v`. Every index of
/// `faces` must be below `n`.
pub(crate) fn corner_rows<T: Copy + Default>(
    faces: &[[u32; 3]],
    n: usize,
    corner: impl Fn(usize, &[u32; 3], usize) -> T,
) -> (Vec<u32>, Vec<T>) {
    let mut start = vec![0u32; n + 1];
    for f in faces {
        for &v in f {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut rows = vec![T::default(); start[n] as usize];
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let v = f[k] as usize;
            rows[fill[v] as usize] = corner(fi, f, k);
            fill[v] += 1;
        }
    }
    (start, rows)
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
