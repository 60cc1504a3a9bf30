//! Beyond the paper: relabel tets until the inside/outside boundary is a strict 2-manifold.
//!
//! The boundary of a union of tets is closed and embedded, but inside tets that touch only
//! along an edge or at a vertex make non-manifold edges and vertices. Around a vertex `v`, the
//! tets of its star tile a sphere (its link, closed by a virtual "exterior" tet on the hull);
//! the surface is a manifold disc at `v` exactly when the inside tets of the star form one
//! face-connected group and the outside tets one group (a non-manifold edge `vw` also splits
//! the groups of `v`). Where there are more groups, the group whose flip raises the cut energy
//! the least is flipped to the other label, and the neighbourhood is checked again.
//!
//! Termination: a tet is flipped at most once by the cost-driven rule; when every candidate
//! group holds an already-flipped tet, an inside group is flipped outside (monotone fallback),
//! so the inside set can only shrink from then on. Protective tets never become inside.

use crate::complex::{Label, TetComplex};
use crate::delaunay::NONE;
use crate::extract::boundary_faces;
use crate::halfedge::{HalfEdges, outgoing_rows};
use crate::score::face_scores;

/// What the repair did.
#[derive(Debug, Clone, Copy, Default)]
pub struct ManifoldStats {
    /// Vertices found non-manifold (counted each time one is repaired).
    pub repairs: usize,
    /// Tets whose label changed.
    pub flipped_tets: usize,
    /// Repairs that needed the monotone fallback.
    pub fallbacks: usize,
}

/// Groups of the star of `v`: `(label, tets)`; the exterior (hull) joins an outside group,
/// marked by `has_exterior`.
struct Group {
    label: Label,
    tets: Vec<u32>,
    has_exterior: bool,
}

fn star_groups(cx: &TetComplex, labels: &[Label], v: u32) -> Vec<Group> {
    let inc = cx.incident(v);
    let n = inc.len();
    // Local union-find over inc + exterior (index n).
    let mut parent: Vec<usize> = (0..=n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    let local = |t: u32| inc.binary_search(&t).ok();
    let mut exterior_used = false;
    for (i, &t) in inc.iter().enumerate() {
        let tv = cx.dt.tets[t as usize];
        let lt = labels[t as usize];
        for k in 0..4 {
            if tv[k] == v {
                continue; // face opposite v does not contain v
            }
            let nb = cx.neighbor(t, k);
            let (j, lj) = if nb == NONE {
                exterior_used = true;
                (n, Label::Outside)
            } else {
                match local(nb) {
                    Some(j) => (j, labels[nb as usize]),
                    None => continue,
                }
            };
            if lj == lt {
                let (a, b) = (find(&mut parent, i), find(&mut parent, j));
                if a != b {
                    parent[a] = b;
                }
            }
        }
    }
    let mut groups: Vec<Group> = Vec::new();
    let mut root_group: Vec<usize> = vec![usize::MAX; n + 1];
    for i in 0..=n {
        if i == n && !exterior_used {
            continue;
        }
        let r = find(&mut parent, i);
        if root_group[r] == usize::MAX {
            root_group[r] = groups.len();
            groups.push(Group {
                label: if i == n {
                    Label::Outside
                } else {
                    labels[inc[i] as usize]
                },
                tets: Vec::new(),
                has_exterior: false,
            });
        }
        let g = &mut groups[root_group[r]];
        if i == n {
            g.has_exterior = true;
        } else {
            g.tets.push(inc[i]);
        }
    }
    groups
}

/// Change of the cut energy when every tet of `set` (all with label `from`) takes the other
/// label.
fn flip_cost(cx: &TetComplex, labels: &[Label], set: &[u32], from: Label) -> f64 {
    let mut delta = 0.0;
    for &t in set {
        for k in 0..4 {
            let nb = cx.neighbor(t, k);
            if nb != NONE && set.contains(&nb) {
                continue;
            }
            let nl = if nb == NONE {
                Label::Outside
            } else {
                labels[nb as usize]
            };
            let (out_of_t, into_t) = face_scores(cx, t, k);
            // Cost of the face now and after the flip.
            let cost = |lt: Label| match (lt, nl) {
                (Label::Inside, Label::Outside) => out_of_t,
                (Label::Outside, Label::Inside) => into_t,
                _ => 0.0,
            };
            let to = if from == Label::Inside {
                Label::Outside
            } else {
                Label::Inside
            };
            delta += cost(to) - cost(from);
        }
    }
    delta
}

/// Vertices where the current inside/outside boundary is not a single disc: their boundary
/// triangles' opposite edges (the vertex's link in the surface) do not form one simple cycle.
/// A cheap O(#faces) scan that seeds the repair.
pub fn nonmanifold_surface_vertices(cx: &TetComplex, labels: &[Label]) -> Vec<u32> {
    nonmanifold_vertices_of(&boundary_faces(cx, labels), cx.dt.vertices.len(), false).0
}

/// [`nonmanifold_surface_vertices`] of the boundary `faces` over `nv` vertices: the link of
/// `v` in face `(v, b, c)` is the edge `b -> c`, the corner of `v` ([`crate::corners::one_cycle`]
/// on the corners grouped by vertex, in parallel); with `half_edges`, also the half-edges of
/// the faces when there is none ([`HalfEdges::checking_links`]).
fn nonmanifold_vertices_of(
    faces: &[[u32; 3]],
    nv: usize,
    half_edges: bool,
) -> (Vec<u32>, Option<HalfEdges>) {
    let (start, rows) = outgoing_rows(faces, nv);
    HalfEdges::checking_links(&start, &rows, half_edges)
}

/// The boundary faces when the repair changed nothing (see [`make_manifold_keeping_faces`]).
#[derive(Debug, Clone)]
pub struct KeptSurface {
    /// The boundary faces ([`boundary_faces`]).
    pub faces: Vec<[u32; 3]>,
    /// Their half-edges over the Delaunay vertices, when asked for: every vertex's link is one
    /// cycle, so they exist (the crease flips take them instead of building them again).
    pub half_edges: Option<HalfEdges>,
}

/// Relabels tets until every vertex of the inside/outside boundary is a manifold vertex.
/// `labels` must hold no [`Label::Unknown`].
pub fn make_manifold(cx: &TetComplex, labels: &mut [Label]) -> ManifoldStats {
    make_manifold_keeping_faces(cx, labels, false).0
}

/// [`make_manifold`], also returning the boundary faces ([`boundary_faces`]) when no tet
/// changed its label (the usual case): the faces the extraction would compute again, and, if
/// `half_edges`, their [`HalfEdges`] from the corners the check grouped by vertex.
pub fn make_manifold_keeping_faces(
    cx: &TetComplex,
    labels: &mut [Label],
    half_edges: bool,
) -> (ManifoldStats, Option<KeptSurface>) {
    let mut stats = ManifoldStats::default();
    let nv = cx.dt.vertices.len();
    let faces = boundary_faces(cx, labels);
    let (mut work, half_edges) = nonmanifold_vertices_of(&faces, nv, half_edges);
    if work.is_empty() {
        return (stats, Some(KeptSurface { faces, half_edges }));
    }
    drop(faces);
    let mut flipped = vec![false; labels.len()];
    let mut queued = vec![false; nv];
    for &v in &work {
        queued[v as usize] = true;
    }
    while let Some(v) = work.pop() {
        queued[v as usize] = false;
        let groups = star_groups(cx, labels, v);
        let n_in = groups.iter().filter(|g| g.label == Label::Inside).count();
        if n_in == 0 || groups.len() <= 2 {
            continue;
        }
        stats.repairs += 1;
        let mut best: Option<(f64, usize)> = None;
        for (gi, g) in groups.iter().enumerate() {
            if g.tets.iter().any(|&t| flipped[t as usize]) {
                continue;
            }
            if g.label == Label::Outside
                && (g.has_exterior || g.tets.iter().any(|&t| cx.touches_protective(t)))
            {
                continue;
            }
            let c = flip_cost(cx, labels, &g.tets, g.label);
            if best.is_none_or(|(bc, _)| c < bc) {
                best = Some((c, gi));
            }
        }
        let chosen = match best {
            Some((_, gi)) => gi,
            None => {
                stats.fallbacks += 1;
                // Monotone fallback: the cheapest inside group goes outside.
                let mut fb: Option<(f64, usize)> = None;
                for (gi, g) in groups.iter().enumerate() {
                    if g.label == Label::Inside {
                        let c = flip_cost(cx, labels, &g.tets, Label::Inside);
                        if fb.is_none_or(|(bc, _)| c < bc) {
                            fb = Some((c, gi));
                        }
                    }
                }
                match fb {
                    Some((_, gi)) => gi,
                    None => continue,
                }
            }
        };
        let g = &groups[chosen];
        let to = if g.label == Label::Inside {
            Label::Outside
        } else {
            Label::Inside
        };
        for &t in &g.tets {
            labels[t as usize] = to;
            flipped[t as usize] = true;
            stats.flipped_tets += 1;
            for &w in &cx.dt.tets[t as usize] {
                if !queued[w as usize] {
                    queued[w as usize] = true;
                    work.push(w);
                }
            }
        }
        if !queued[v as usize] {
            queued[v as usize] = true;
            work.push(v);
        }
    }
    (stats, None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::delaunay::Delaunay;
    use crate::quadric::Quadric;
    use std::collections::HashMap;

    /// Random points in the unit cube inside the 8 corners of a larger box (protective), and
    /// random labels: inside with probability `p_in` (never a tet of a corner).
    fn random_complex(seed: u64, n: usize, p_in: f64) -> (TetComplex, Vec<Label>) {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut r = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut points: Vec<[f64; 3]> = (0..n).map(|_| [r(), r(), r()]).collect();
        for k in 0..8 {
            points.push([0, 1, 2].map(|a| if k >> a & 1 == 1 { 3.0 } else { -2.0 }));
        }
        let dt = Delaunay::new(&points).expect("finite points");
        let nv = dt.vertices.len();
        let protective: Vec<bool> = (0..nv).map(|v| v >= n).collect();
        let cx = TetComplex::new(
            dt,
            vec![[0.0, 0.0, 1.0]; nv],
            vec![[0.0, 0.0, 1.0]; nv],
            vec![Quadric::zero(); nv],
            protective,
            0.1,
            1.0,
        );
        let labels = (0..cx.n_tets() as u32)
            .map(|t| {
                if !cx.touches_protective(t) && r() < p_in {
                    Label::Inside
                } else {
                    Label::Outside
                }
            })
            .collect();
        (cx, labels)
    }

    /// Non-manifold surface vertices by a plain reference: the link of each vertex as a map
    /// from start to end, followed from one edge.
    fn reference(cx: &TetComplex, labels: &[Label]) -> Vec<u32> {
        let mut links: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
        for [a, b, c] in boundary_faces(cx, labels) {
            links.entry(a).or_default().push((b, c));
            links.entry(b).or_default().push((c, a));
            links.entry(c).or_default().push((a, b));
        }
        let mut bad: Vec<u32> = links
            .into_iter()
            .filter(|(_, e)| {
                let next: HashMap<u32, u32> = e.iter().copied().collect();
                if next.len() != e.len() {
                    return true;
                }
                let (mut x, mut steps) = (e[0].1, 1);
                while x != e[0].0 {
                    match next.get(&x) {
                        Some(&y) if steps < e.len() => (x, steps) = (y, steps + 1),
                        _ => return true,
                    }
                }
                steps != e.len()
            })
            .map(|(v, _)| v)
            .collect();
        bad.sort_unstable();
        bad
    }

    #[test]
    fn scan_finds_the_reference_vertices_and_the_repair_leaves_none() {
        let mut repaired = 0;
        for seed in 0..12 {
            let (cx, mut labels) = random_complex(seed, 150, [0.1, 0.3, 0.6][seed as usize % 3]);
            let found = nonmanifold_surface_vertices(&cx, &labels);
            assert_eq!(found, reference(&cx, &labels), "seed {seed}");
            let before = labels.clone();
            let want_half_edges = seed % 2 == 0;
            let (stats, kept) = make_manifold_keeping_faces(&cx, &mut labels, want_half_edges);
            match kept {
                // Kept only when nothing changed: then they are the boundary's, and their
                // half-edges (when asked for) are those `HalfEdges::new` finds.
                Some(k) => {
                    assert!(found.is_empty() && labels == before);
                    assert_eq!(k.faces, boundary_faces(&cx, &labels));
                    if want_half_edges {
                        let he = HalfEdges::new(&k.faces, cx.dt.vertices.len());
                        assert!(he.is_some() && k.half_edges == he, "seed {seed}");
                    } else {
                        assert!(k.half_edges.is_none());
                    }
                }
                None => assert!(!found.is_empty()),
            }
            repaired += (stats.flipped_tets > 0) as usize;
            assert!(
                nonmanifold_surface_vertices(&cx, &labels).is_empty(),
                "seed {seed}"
            );
        }
        // Random labels make non-manifold boundaries: the repair was exercised.
        assert!(repaired >= 6, "{repaired}");
        // One inside tet: a manifold boundary, its four faces kept for the extraction.
        let (cx, mut labels) = random_complex(99, 50, 0.0);
        let t = (0..cx.n_tets() as u32)
            .find(|&t| !cx.touches_protective(t))
            .unwrap();
        labels[t as usize] = Label::Inside;
        let (stats, kept) = make_manifold_keeping_faces(&cx, &mut labels, true);
        assert_eq!(stats.flipped_tets, 0);
        let kept = kept.expect("a manifold boundary");
        assert_eq!(kept.faces.len(), 4);
        let he = HalfEdges::new(&kept.faces, cx.dt.vertices.len());
        assert!(he.is_some() && kept.half_edges == he);
    }
}
