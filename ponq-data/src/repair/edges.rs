//! The edges of a triangle soup: each undirected edge with the faces that use it and the
//! direction each one runs it, from one sort of the half-edges.

/// One use of an undirected edge `(lo, hi)` by face `face`; `forward` when the face runs it
/// from `lo` to `hi`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct EdgeUse {
    pub lo: u32,
    pub hi: u32,
    pub face: u32,
    pub forward: bool,
}

/// Every use of every edge of `faces`, grouped by edge (sorted by `(lo, hi)`, then face).
/// Faces with a repeated vertex give no use of the edge from a vertex to itself.
pub(crate) fn edge_uses(faces: &[[u32; 3]]) -> Vec<EdgeUse> {
    let mut uses = Vec::with_capacity(3 * faces.len());
    for (f, t) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a != b {
                uses.push(EdgeUse {
                    lo: a.min(b),
                    hi: a.max(b),
                    face: f as u32,
                    forward: a < b,
                });
            }
        }
    }
    uses.sort_unstable();
    uses
}

/// The groups of [`edge_uses`] that share one undirected edge.
pub(crate) fn by_edge(uses: &[EdgeUse]) -> impl Iterator<Item = &[EdgeUse]> {
    uses.chunk_by(|a, b| (a.lo, a.hi) == (b.lo, b.hi))
}

/// How the edges of a soup are used.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct EdgeCounts {
    /// Edges of one face.
    pub boundary: usize,
    /// Edges of three faces or more.
    pub nonmanifold: usize,
    /// Edges of two faces that run them the same way (one of the two is flipped).
    pub misoriented: usize,
}

/// Counts the boundary, non-manifold and misoriented edges of `faces`.
pub(crate) fn count_edges(faces: &[[u32; 3]]) -> EdgeCounts {
    let uses = edge_uses(faces);
    let mut c = EdgeCounts::default();
    for g in by_edge(&uses) {
        match g.len() {
            1 => c.boundary += 1,
            2 => c.misoriented += usize::from(g[0].forward == g[1].forward),
            _ => c.nonmanifold += 1,
        }
    }
    c
}

/// Connected components of faces joined across the edges that exactly two faces use
/// (non-manifold edges do not join): the component of each face, and the count.
pub(crate) fn manifold_components(faces: &[[u32; 3]], uses: &[EdgeUse]) -> (Vec<u32>, usize) {
    let mut parent: Vec<u32> = (0..faces.len() as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    for g in by_edge(uses) {
        if g.len() == 2 {
            let (a, b) = (find(&mut parent, g[0].face), find(&mut parent, g[1].face));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut id = vec![u32::MAX; faces.len()];
    let mut count = 0;
    let mut comp = vec![0u32; faces.len()];
    for f in 0..faces.len() {
        let r = find(&mut parent, f as u32) as usize;
        if id[r] == u32::MAX {
            id[r] = count;
            count += 1;
        }
        comp[f] = id[r];
    }
    (comp, count as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_components_of_a_tetrahedron_and_a_loose_face() {
        let mut faces = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]];
        assert_eq!(count_edges(&faces), EdgeCounts::default());
        faces.push([4, 5, 6]);
        let c = count_edges(&faces);
        assert_eq!(c.boundary, 3);
        faces[1] = [0, 3, 1];
        let c = count_edges(&faces);
        assert_eq!(c.misoriented, 3);
        let uses = edge_uses(&faces);
        let (comp, n) = manifold_components(&faces, &uses);
        assert_eq!(n, 2);
        assert_eq!(comp, vec![0, 0, 0, 0, 1]);
        // A fin: a third face on edge (0, 1) makes it non-manifold, and the fin its own part.
        faces.push([0, 1, 7]);
        let c = count_edges(&faces);
        assert_eq!(c.nonmanifold, 1);
        let (comp, n) = manifold_components(&faces, &edge_uses(&faces));
        assert_eq!(n, 3);
        assert_ne!(comp[5], comp[0]);
    }
}
