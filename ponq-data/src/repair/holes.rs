//! Holes: the loops of boundary edges of an oriented surface, each closed by a fan of
//! triangles around its centroid (three edges: one triangle), oriented to continue the
//! surface's orientation.

use std::collections::HashMap;

use super::edges::{EdgeUse, by_edge};

/// What [`fill_holes`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct HoleStats {
    /// Loops closed.
    pub filled: usize,
    /// Triangles added.
    pub faces_added: usize,
    /// Boundary edges of the longest loop closed.
    pub longest_loop: usize,
    /// Boundary edges left open (chains that do not close into a loop, loops longer than
    /// the limit).
    pub left_open: usize,
}

/// Closes every loop of boundary edges (edges of exactly one face) of at most `max_edges`
/// edges whose faces are all of one part (`comp`: a hole in a surface; a loop through the
/// edges of several parts, such as fins standing on the edges of one face, is not a hole):
/// the loop runs each boundary edge against its face's direction, and its patch
/// triangles run it that way too, so the patched surface stays consistently oriented. A loop
/// of three edges becomes one triangle; a longer one a fan around a new vertex at the mean of
/// its vertices. Where a vertex starts several boundary edges (holes touching at a vertex) the
/// loops are split there in the order the edges come.
pub(crate) fn fill_holes(
    vertices: &mut Vec<[f64; 3]>,
    faces: &mut Vec<[u32; 3]>,
    uses: &[EdgeUse],
    comp: &[u32],
    max_edges: usize,
) -> HoleStats {
    // Loop edges `b -> a` for each boundary half-edge `a -> b`, by start vertex, with the part
    // of the face.
    let mut out: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut part: HashMap<(u32, u32), u32> = HashMap::new();
    let mut edges = 0usize;
    for g in by_edge(uses) {
        if g.len() == 1 {
            let u = g[0];
            let (a, b) = if u.forward {
                (u.lo, u.hi)
            } else {
                (u.hi, u.lo)
            };
            out.entry(b).or_default().push(a);
            part.insert((b, a), comp[u.face as usize]);
            edges += 1;
        }
    }
    let mut stats = HoleStats::default();
    let mut starts: Vec<u32> = out.keys().copied().collect();
    starts.sort_unstable();
    let mut used = 0usize;
    for s in starts {
        while let Some(first) = out.get_mut(&s).and_then(|l| l.pop()) {
            // Walk from `s` until back at `s` (or stuck: a chain that does not close).
            let mut lp = vec![s, first];
            let mut cur = first;
            let closed = loop {
                if cur == s {
                    break true;
                }
                match out.get_mut(&cur).and_then(|l| l.pop()) {
                    Some(next) => {
                        lp.push(next);
                        cur = next;
                    }
                    None => break false,
                }
                if lp.len() > edges + 1 {
                    break false;
                }
            };
            let n = lp.len() - 1;
            used += n;
            let one_part = lp
                .windows(2)
                .all(|w| part.get(&(w[0], w[1])) == part.get(&(lp[0], lp[1])));
            if !closed || n > max_edges || n < 3 || !one_part {
                stats.left_open += n;
                continue;
            }
            let ring = &lp[..n];
            if n == 3 {
                faces.push([ring[0], ring[1], ring[2]]);
                stats.faces_added += 1;
            } else {
                let mut c = [0.0f64; 3];
                for &v in ring {
                    for k in 0..3 {
                        c[k] += vertices[v as usize][k];
                    }
                }
                let c = c.map(|x| x / n as f64);
                let ci = vertices.len() as u32;
                vertices.push(c);
                for i in 0..n {
                    faces.push([ring[i], ring[(i + 1) % n], ci]);
                }
                stats.faces_added += n;
            }
            stats.filled += 1;
            stats.longest_loop = stats.longest_loop.max(n);
        }
    }
    stats.left_open += edges.saturating_sub(used);
    stats
}

#[cfg(test)]
mod tests {
    use super::super::edges::{count_edges, edge_uses};
    use super::*;

    /// An open box (a cube without its top: a square hole) is closed, consistently.
    #[test]
    fn a_square_hole_is_closed_consistently() {
        let mut v: Vec<[f64; 3]> = (0..8)
            .map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64])
            .collect();
        // The six faces of the unit cube, counter-clockwise from outside; the top (z = 1)
        // left out.
        let mut f = vec![
            [0, 2, 1],
            [1, 2, 3],
            [0, 1, 5],
            [0, 5, 4],
            [1, 3, 7],
            [1, 7, 5],
            [3, 2, 6],
            [3, 6, 7],
            [2, 0, 4],
            [2, 4, 6],
        ];
        let uses = edge_uses(&f);
        let comp = vec![0; f.len()];
        let s = fill_holes(&mut v, &mut f, &uses, &comp, usize::MAX);
        assert_eq!(
            (s.filled, s.faces_added, s.longest_loop, s.left_open),
            (1, 4, 4, 0)
        );
        assert_eq!(count_edges(&f), Default::default());
        assert_eq!(v[8], [0.5, 0.5, 1.0]);
        // A limit shorter than the loop leaves it open.
        let mut f2 = f[..10].to_vec();
        let uses = edge_uses(&f2);
        let s = fill_holes(&mut v, &mut f2, &uses, &comp, 3);
        assert_eq!((s.filled, s.left_open), (0, 4));
    }
}
