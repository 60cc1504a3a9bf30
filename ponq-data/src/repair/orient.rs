//! Orientation: the faces of each connected part run every edge they share in opposite
//! directions, as in a consistently oriented surface.

use super::edges::{EdgeUse, by_edge};
use ponq_mesh::vec3::{cross, dot, sub};

/// Area of a triangle (twice: the length of its normal).
fn double_area(v: &[[f64; 3]], f: [u32; 3]) -> f64 {
    let [a, b, c] = f.map(|i| v[i as usize]);
    let n = cross(sub(b, a), sub(c, a));
    dot(n, n).sqrt()
}

/// Flips faces so that, in every part of faces joined across edges of exactly two faces, the
/// two faces of each such edge run it in opposite directions; of the two ways to do that, each
/// part keeps the one that leaves the larger area of its faces as they were. `uses` are the
/// edge uses of `faces` ([`super::edges::edge_uses`]) and `comp` their parts
/// ([`super::edges::manifold_components`]). A part that cannot be oriented (a Moebius strip)
/// keeps the orientation its breadth-first visit gives. Returns the number of faces flipped.
pub(crate) fn orient_parts(
    vertices: &[[f64; 3]],
    faces: &mut [[u32; 3]],
    uses: &[EdgeUse],
    comp: &[u32],
    parts: usize,
) -> usize {
    let n = faces.len();
    // Neighbours across edges of two faces, with whether both run the edge the same way.
    let mut count = vec![0u32; n + 1];
    let pairs: Vec<(u32, u32, bool)> = by_edge(uses)
        .filter(|g| g.len() == 2 && g[0].face != g[1].face)
        .map(|g| (g[0].face, g[1].face, g[0].forward == g[1].forward))
        .collect();
    for &(a, b, _) in &pairs {
        count[a as usize + 1] += 1;
        count[b as usize + 1] += 1;
    }
    for i in 0..n {
        count[i + 1] += count[i];
    }
    let mut fill = count.clone();
    let mut adj = vec![(0u32, false); count[n] as usize];
    for &(a, b, same) in &pairs {
        adj[fill[a as usize] as usize] = (b, same);
        fill[a as usize] += 1;
        adj[fill[b as usize] as usize] = (a, same);
        fill[b as usize] += 1;
    }
    // 0: unvisited, 1: keep, 2: flip.
    let mut state = vec![0u8; n];
    let mut queue = Vec::new();
    for seed in 0..n {
        if state[seed] != 0 {
            continue;
        }
        state[seed] = 1;
        queue.push(seed as u32);
        while let Some(f) = queue.pop() {
            let s = state[f as usize];
            for &(g, same) in &adj[count[f as usize] as usize..count[f as usize + 1] as usize] {
                if state[g as usize] == 0 {
                    // Running the edge the same way: one of the two must flip.
                    state[g as usize] = if same { 3 - s } else { s };
                    queue.push(g);
                }
            }
        }
    }
    let mut flip_area = vec![0.0f64; parts];
    let mut keep_area = vec![0.0f64; parts];
    for f in 0..n {
        let a = double_area(vertices, faces[f]);
        if state[f] == 2 {
            flip_area[comp[f] as usize] += a;
        } else {
            keep_area[comp[f] as usize] += a;
        }
    }
    let mut flipped = 0;
    for f in 0..n {
        let c = comp[f] as usize;
        let invert = flip_area[c] > keep_area[c];
        if (state[f] == 2) != invert {
            faces[f].swap(1, 2);
            flipped += 1;
        }
    }
    flipped
}

/// Signed volume enclosed by each part (`comp`, `parts`), by the divergence theorem: positive
/// for a closed part whose faces are counter-clockwise seen from outside.
pub(crate) fn part_volumes(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    comp: &[u32],
    parts: usize,
) -> Vec<f64> {
    let mut vol = vec![0.0f64; parts];
    for (f, t) in faces.iter().enumerate() {
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        vol[comp[f] as usize] += dot(a, cross(b, c)) / 6.0;
    }
    vol
}

#[cfg(test)]
mod tests {
    use super::super::edges::{count_edges, edge_uses, manifold_components};
    use super::*;

    #[test]
    fn flipped_faces_of_a_tetrahedron_are_turned_back() {
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let good = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]];
        let mut f = good.clone();
        f[2].swap(1, 2);
        let uses = edge_uses(&f);
        let (comp, parts) = manifold_components(&f, &uses);
        assert_eq!(orient_parts(&v, &mut f, &uses, &comp, parts), 1);
        assert_eq!(count_edges(&f).misoriented, 0);
        assert_eq!(f, good);
        assert!(part_volumes(&v, &f, &comp, parts)[0] > 0.0);
        // Three of four flipped: the larger area (here the three) keeps its orientation, so
        // the result is the inverted tetrahedron.
        let mut f = good.clone();
        for t in &mut f[..3] {
            t.swap(1, 2);
        }
        let uses = edge_uses(&f);
        let (comp, parts) = manifold_components(&f, &uses);
        orient_parts(&v, &mut f, &uses, &comp, parts);
        assert_eq!(count_edges(&f).misoriented, 0);
        assert!(part_volumes(&v, &f, &comp, parts)[0] < 0.0);
    }
}
