//! Sides: whether each face separates the inside of the solid (`|w| > 1/2`, the generalised
//! winding number of the whole mesh) from the outside, seen from two points just in front of
//! and just behind it. A face with the inside in front is inverted; one with the same side in
//! front and behind separates nothing: an internal face, a nested shell's, a fin's, or the part
//! of an overlapping copy that lies inside the other.

use rayon::prelude::*;

use crate::sdf::{MeshSdf, solid_angle};
use ponq_mesh::vec3::{cross, dot, sub};

/// What a face separates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Side {
    /// Inside behind, outside in front (or a degenerate face, left as it is).
    Boundary,
    /// Inside in front, outside behind: the face is flipped.
    Inverted,
    /// The same on both sides.
    Internal,
}

/// The side of each face `f` with `test[f]` (the others are [`Side::Boundary`]). `sdf` holds
/// the whole mesh; the two points are the face's centroid moved by `eps` (at most, see the
/// body) along its unit normal each way.
pub(crate) fn classify(
    sdf: &MeshSdf,
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    test: &[bool],
    eps: f64,
) -> Vec<Side> {
    let inside = |p: [f64; 3]| sdf.winding_number(p).abs() > 0.5;
    faces
        .par_iter()
        .zip(test)
        .with_min_len(64)
        .map(|(t, &want)| {
            if !want {
                return Side::Boundary;
            }
            let [a, b, c] = t.map(|i| vertices[i as usize]);
            let n = cross(sub(b, a), sub(c, a));
            let len = dot(n, n).sqrt();
            if !(len > 0.0 && len.is_finite()) {
                return Side::Boundary;
            }
            // Small next to the face, so that the points stay in front of it and not past a
            // neighbouring surface.
            let e = eps.min(0.05 * (0.5 * len).sqrt());
            let g = [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0);
            let front = [0, 1, 2].map(|k| g[k] + e * n[k] / len);
            let back = [0, 1, 2].map(|k| g[k] - e * n[k] / len);
            match (inside(back), inside(front)) {
                (true, false) => Side::Boundary,
                (false, true) => Side::Inverted,
                _ => Side::Internal,
            }
        })
        .collect()
}

/// Winding number at `p` of the faces of part `part` alone (`comp[f]` the part of face `f`),
/// summed face by face.
pub(crate) fn part_winding(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    comp: &[u32],
    part: u32,
    p: [f64; 3],
) -> f64 {
    let s: f64 = faces
        .iter()
        .zip(comp)
        .filter(|&(_, &c)| c == part)
        .map(|(t, _)| {
            let [a, b, c] = t.map(|i| vertices[i as usize]);
            solid_angle(p, a, b, c)
        })
        .sum();
    s / (4.0 * std::f64::consts::PI)
}
