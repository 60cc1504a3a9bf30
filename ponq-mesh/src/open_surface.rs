//! Open surfaces: after meshing, drop the triangles that close the holes (SPEC section 6).
//!
//! Boundary samples with rotated normals make the quadrics of boundary points elongated
//! ("cigars", anisotropy `lambda2/lambda1` close to 1), while points on the surface are flat
//! ("pancakes", close to 0). A triangle is kept only if one of its vertices has anisotropy
//! at most the threshold.
//!
//! Culling can leave two fans of triangles touching at one vertex (a non-manifold vertex: the
//! surface pinches there); the smaller fans at such a vertex are dropped too, so the output is
//! a valid open surface: every vertex's triangles form one fan.

use crate::corners::corner_rows;
use crate::trimesh::TriMesh;

/// Default anisotropy threshold.
pub const DEFAULT_OPEN_THRESHOLD: f64 = 0.35;

/// Culls in place the triangles whose three vertices all have `anisotropy > threshold` (and
/// the smaller fans at a vertex where several are left, see the module docs), removes unused
/// vertices, and returns for each remaining vertex its index before culling.
pub fn cull_open(mesh: &mut TriMesh, anisotropy: &[f64], threshold: f64) -> Vec<u32> {
    mesh.faces
        .retain(|f| f.iter().any(|&v| anisotropy[v as usize] <= threshold));
    one_fan_per_vertex(&mut mesh.faces, mesh.vertices.len());
    mesh.remove_unreferenced_vertices()
}

/// Drops the triangles of all but the largest fan (the most triangles; the first on a tie) at
/// every vertex whose triangles form several fans (joined across the edges at the vertex),
/// until none does. Returns the number of triangles dropped.
pub fn one_fan_per_vertex(faces: &mut Vec<[u32; 3]>, n_vertices: usize) -> usize {
    let mut dropped = 0;
    // Each round only removes triangles; a handful of rounds settles any input.
    for _ in 0..16 {
        let (start, rows) = corner_rows(faces, n_vertices, |fi, f, k| {
            (fi as u32, f[(k + 1) % 3], f[(k + 2) % 3])
        });
        let mut drop = vec![false; faces.len()];
        let mut any = false;
        for v in 0..n_vertices {
            let c = &rows[start[v] as usize..start[v + 1] as usize];
            if c.len() < 2 {
                continue;
            }
            // Fans: corners joined when their triangles share an edge at `v`.
            let mut fan: Vec<usize> = (0..c.len()).collect();
            fn root(f: &mut [usize], mut x: usize) -> usize {
                while f[x] != x {
                    f[x] = f[f[x]];
                    x = f[x];
                }
                x
            }
            for i in 0..c.len() {
                for j in i + 1..c.len() {
                    let (a, b) = (c[i], c[j]);
                    if a.1 == b.1 || a.1 == b.2 || a.2 == b.1 || a.2 == b.2 {
                        let (ri, rj) = (root(&mut fan, i), root(&mut fan, j));
                        fan[ri.max(rj)] = ri.min(rj);
                    }
                }
            }
            let roots: Vec<usize> = (0..c.len()).map(|i| root(&mut fan, i)).collect();
            let mut size = vec![0usize; c.len()];
            for &r in &roots {
                size[r] += 1;
            }
            let fans = size.iter().filter(|&&s| s > 0).count();
            if fans < 2 {
                continue;
            }
            let keep = (0..c.len())
                .max_by_key(|&r| (size[r], std::cmp::Reverse(r)))
                .unwrap_or(0);
            for (i, &r) in roots.iter().enumerate() {
                if r != keep {
                    drop[c[i].0 as usize] = true;
                    any = true;
                }
            }
        }
        if !any {
            break;
        }
        let before = faces.len();
        let mut i = 0;
        faces.retain(|_| {
            i += 1;
            !drop[i - 1]
        });
        dropped += before - faces.len();
    }
    dropped
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles touching at one vertex: the pinch goes (the first, on a tie, stays); a
    /// fan of two next to one triangle keeps the fan.
    #[test]
    fn a_pinched_vertex_keeps_its_largest_fan() {
        let mut f = vec![[0, 1, 2], [0, 3, 4]];
        assert_eq!(one_fan_per_vertex(&mut f, 5), 1);
        assert_eq!(f, vec![[0, 1, 2]]);
        let mut f = vec![[0, 1, 2], [0, 2, 5], [0, 3, 4]];
        assert_eq!(one_fan_per_vertex(&mut f, 6), 1);
        assert_eq!(f, vec![[0, 1, 2], [0, 2, 5]]);
        let mut f = vec![[0, 1, 2], [0, 2, 3], [0, 3, 1]];
        assert_eq!(one_fan_per_vertex(&mut f, 4), 0);
    }
}
