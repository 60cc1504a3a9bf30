//! Exact geometric predicates, kept in one place.
//!
//! Every decision that changes topology (orientation of a tetrahedron, whether a point lies in
//! a circumsphere) goes through these functions. They wrap Shewchuk's adaptive exact
//! predicates from the `robust` crate, so their sign is always the sign of the exact real
//! determinant of the `f64` inputs. Ties of the insphere test are broken by the symbolic
//! perturbation of Devillers & Teillaud ("Perturbations for Delaunay and weighted Delaunay 3D
//! triangulations", CGAL's scheme), which only evaluates further exact orientation tests:
//! no epsilon, no random jitter.
//!
//! Convention: `orient3d(a, b, c, d) > 0` when `det[b-a, c-a, d-a] > 0`, i.e. `d` lies on the
//! side of the plane `abc` that `(b-a) x (c-a)` points to. A tetrahedron `(a, b, c, d)` is
//! *positively oriented* when `orient3d(a, b, c, d) > 0`.

use robust::Coord3D;

#[inline(always)]
fn c3(p: &[f64; 3]) -> Coord3D<f64> {
    Coord3D {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

/// Exact sign (-1, 0, 1) of `det[b-a, c-a, d-a]`.
#[inline]
pub fn orient3d(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3]) -> i32 {
    // robust::orient3d(a, b, c, d) = det[a-d, b-d, c-d] = -det[b-a, c-a, d-a].
    let v = robust::orient3d(c3(a), c3(b), c3(c), c3(d));
    if v < 0.0 {
        1
    } else if v > 0.0 {
        -1
    } else {
        0
    }
}

/// Exact sign of the insphere determinant for a positively oriented tetrahedron `(a, b, c, d)`:
/// `1` if `e` is strictly inside its circumsphere, `-1` strictly outside, `0` on it.
#[inline]
pub fn insphere(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3], e: &[f64; 3]) -> i32 {
    // robust::insphere is positive for "inside" when robust::orient3d(a,b,c,d) > 0, which is
    // our negative orientation: flip the sign.
    let v = robust::insphere(c3(a), c3(b), c3(c), c3(d), c3(e));
    if v < 0.0 {
        1
    } else if v > 0.0 {
        -1
    } else {
        0
    }
}

/// Symbolically perturbed insphere test: is point `e` (with global index `ie`) in conflict with
/// (strictly inside the circumsphere of) the positively oriented tetrahedron with vertices
/// `t` (global indices `it`)?
///
/// Never undecided: when `e` is exactly on the sphere, the point of largest index among the
/// five decides, as if each point `i` were lifted by `-eps^i` on the paraboloid. All indices
/// must be distinct and the points pairwise distinct (deduplicate first).
#[inline]
pub fn in_conflict(t: [&[f64; 3]; 4], it: [u32; 4], e: &[f64; 3], ie: u32) -> bool {
    let s = insphere(t[0], t[1], t[2], t[3], e);
    if s != 0 {
        return s > 0;
    }
    perturbed_insphere_tie(t, it, e, ie)
}

#[cold]
fn perturbed_insphere_tie(t: [&[f64; 3]; 4], it: [u32; 4], e: &[f64; 3], ie: u32) -> bool {
    // Roles 0..4 are the tet's vertices, 4 is the query point; visit in decreasing index.
    let mut roles = [(it[0], 0usize), (it[1], 1), (it[2], 2), (it[3], 3), (ie, 4)];
    roles.sort_unstable_by(|a, b| b.0.cmp(&a.0));
    for &(_, role) in &roles {
        if role == 4 {
            // The coefficient is orient3d(t) > 0 with the sign of "outside".
            return false;
        }
        let mut q = t;
        q[role] = e;
        let o = orient3d(q[0], q[1], q[2], q[3]);
        if o != 0 {
            return o > 0;
        }
    }
    // Unreachable for distinct points and a non-degenerate tet (two orientations cannot both
    // vanish); "outside" keeps the cavity minimal if it ever happens.
    false
}

/// Circumcentre of a tetrahedron (floating point; used for tagging, not for topology).
/// Returns `None` for a flat tetrahedron.
pub fn circumcenter(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3]) -> Option<[f64; 3]> {
    let sub = |p: &[f64; 3]| [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
    let (u, v, w) = (sub(b), sub(c), sub(d));
    let dot = |p: [f64; 3]| p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
    let cross = |p: [f64; 3], q: [f64; 3]| {
        [
            p[1] * q[2] - p[2] * q[1],
            p[2] * q[0] - p[0] * q[2],
            p[0] * q[1] - p[1] * q[0],
        ]
    };
    let vw = cross(v, w);
    let wu = cross(w, u);
    let uv = cross(u, v);
    let det = u[0] * vw[0] + u[1] * vw[1] + u[2] * vw[2];
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let (lu, lv, lw) = (dot(u), dot(v), dot(w));
    let s = 0.5 / det;
    let r = [
        a[0] + s * (lu * vw[0] + lv * wu[0] + lw * uv[0]),
        a[1] + s * (lu * vw[1] + lv * wu[1] + lw * uv[1]),
        a[2] + s * (lu * vw[2] + lv * wu[2] + lw * uv[2]),
    ];
    r.iter().all(|x| x.is_finite()).then_some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    const O: [f64; 3] = [0.0, 0.0, 0.0];
    const X: [f64; 3] = [1.0, 0.0, 0.0];
    const Y: [f64; 3] = [0.0, 1.0, 0.0];
    const Z: [f64; 3] = [0.0, 0.0, 1.0];

    #[test]
    fn orientation_convention() {
        assert_eq!(orient3d(&O, &X, &Y, &Z), 1);
        assert_eq!(orient3d(&O, &Y, &X, &Z), -1);
        assert_eq!(orient3d(&O, &X, &Y, &[0.3, 0.4, 0.0]), 0);
    }

    #[test]
    fn insphere_convention() {
        assert_eq!(insphere(&O, &X, &Y, &Z, &[0.2, 0.2, 0.2]), 1);
        assert_eq!(insphere(&O, &X, &Y, &Z, &[2.0, 2.0, 2.0]), -1);
        // (1,1,1) lies on the circumsphere of the corner tet (centre (.5,.5,.5)).
        assert_eq!(insphere(&O, &X, &Y, &Z, &[1.0, 1.0, 1.0]), 0);
    }

    #[test]
    fn perturbation_is_decisive_and_antisymmetric_on_cube_corners() {
        // The 8 cube corners are co-spherical: every tie must be decided, and for two tets
        // sharing a face, a point on the common sphere conflicts with exactly one of them
        // when it lies on the other side... here we only check decisiveness and determinism.
        let p = [1.0, 1.0, 1.0];
        let a = in_conflict([&O, &X, &Y, &Z], [0, 1, 2, 3], &p, 7);
        let b = in_conflict([&O, &X, &Y, &Z], [0, 1, 2, 3], &p, 7);
        assert_eq!(a, b);
        // Largest index is the query point: outside.
        assert!(!a);
        // Largest index is the vertex O: decided by orient3d(p, X, Y, Z) which is negative
        // (p and O on opposite sides of the plane XYZ).
        assert!(!in_conflict([&O, &X, &Y, &Z], [9, 1, 2, 3], &p, 4));
        // Largest index is Z: orient3d(O, X, Y, p) > 0.
        assert!(in_conflict([&O, &X, &Y, &Z], [0, 1, 2, 9], &p, 4));
    }

    #[test]
    fn circumcenter_of_corner_tet() {
        let c = circumcenter(&O, &X, &Y, &Z).expect("non-degenerate");
        for k in c {
            assert!((k - 0.5).abs() < 1e-15);
        }
        assert!(circumcenter(&O, &X, &Y, &[1.0, 1.0, 0.0]).is_none());
    }
}
