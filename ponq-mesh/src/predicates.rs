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

/// `max` without NaN handling (one `maxsd`); the filters fall back to the exact predicate when a
/// bound is not finite.
#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

#[inline(always)]
fn fmin(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

#[inline(always)]
fn c3(p: &[f64; 3]) -> Coord3D<f64> {
    Coord3D {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

/// Exact sign (-1, 0, 1) of `det[b-a, c-a, d-a]`.
///
/// A semi-static floating-point filter decides almost every call; the uncertain ones go to
/// Shewchuk's adaptive exact predicate.
#[inline]
pub fn orient3d(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3]) -> i32 {
    orient3d_bounded(a, b, c, d, f64::INFINITY)
}

/// [`orient3d`] with a static error bound tried first: `static_eps` must be at least
/// `8e-15 * D^3` where `D` bounds every coordinate difference of the four points (see
/// [`static_orient_bound`]); `f64::INFINITY` disables it.
#[inline]
pub fn orient3d_bounded(
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
    static_eps: f64,
) -> i32 {
    let (bx, by, bz) = (b[0] - a[0], b[1] - a[1], b[2] - a[2]);
    let (cx, cy, cz) = (c[0] - a[0], c[1] - a[1], c[2] - a[2]);
    let (dx, dy, dz) = (d[0] - a[0], d[1] - a[1], d[2] - a[2]);
    let det = bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx);
    // The decision as a value, so that a decided call costs no branch on its sign (the walk
    // and the validity checks see both signs about equally often).
    if (det > static_eps) | (det < -static_eps) {
        return sign(det);
    }
    let mx = fmax(fmax(bx.abs(), cx.abs()), dx.abs());
    let my = fmax(fmax(by.abs(), cy.abs()), dy.abs());
    let mz = fmax(fmax(bz.abs(), cz.abs()), dz.abs());
    let lo = fmin(fmin(mx, my), mz);
    let hi = fmax(fmax(mx, my), mz);
    // Error bound: each of the 6 expanded monomials is at most mx*my*mz and goes through at
    // most 8 roundings (difference 1, minor 3, outer product 2, sums 2), so
    // |error| <= 6 * gamma_8 * mx*my*mz < 5.4e-15 * mx*my*mz (u = 2^-53; CGAL's filter for
    // the same expression has 5.11e-15). 8e-15 leaves a margin.
    if lo > 1e-60 && hi < 1e60 {
        let eps = 8e-15 * mx * my * mz;
        if (det > eps) | (det < -eps) {
            return sign(det);
        }
    }
    orient3d_exact(a, b, c, d)
}

/// `1` for a positive, `-1` for a negative number (called on decided, non-zero values only),
/// without a branch.
#[inline(always)]
fn sign(x: f64) -> i32 {
    (x > 0.0) as i32 - (x < 0.0) as i32
}

/// The static bound of [`orient3d_bounded`] for points whose coordinate differences are at
/// most `extent`: the semi-static bound with every maximum replaced by `extent`.
/// `f64::INFINITY` (no static filter) outside the range where the error analysis holds
/// without underflow or overflow.
pub fn static_orient_bound(extent: f64) -> f64 {
    if extent > 1e-50 && extent < 1e60 {
        8e-15 * extent.powi(3)
    } else {
        f64::INFINITY
    }
}

#[cold]
#[inline(never)]
fn orient3d_exact(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3]) -> i32 {
    // Four points in one axis-aligned plane (common on CAD faces and PoNQ-lite lattices)
    // are exactly coplanar: no need for the adaptive evaluation.
    if (0..3).any(|k| a[k] == b[k] && a[k] == c[k] && a[k] == d[k]) {
        return 0;
    }
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
///
/// A semi-static floating-point filter decides almost every call; the uncertain ones go to
/// Shewchuk's adaptive exact predicate.
#[inline]
pub fn insphere(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3], e: &[f64; 3]) -> i32 {
    insphere_bounded(a, b, c, d, e, f64::INFINITY)
}

/// [`insphere`] with a static error bound tried first: `static_eps` must be at least
/// `2e-13 * D^5` where `D` bounds every coordinate difference of the five points (see
/// [`static_insphere_bound`]); `f64::INFINITY` disables it.
#[inline(always)]
pub fn insphere_bounded(
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
    e: &[f64; 3],
    static_eps: f64,
) -> i32 {
    let (ax, ay, az) = (a[0] - e[0], a[1] - e[1], a[2] - e[2]);
    let (bx, by, bz) = (b[0] - e[0], b[1] - e[1], b[2] - e[2]);
    let (cx, cy, cz) = (c[0] - e[0], c[1] - e[1], c[2] - e[2]);
    let (dx, dy, dz) = (d[0] - e[0], d[1] - e[1], d[2] - e[2]);
    let a2 = ax * ax + ay * ay + az * az;
    let b2 = bx * bx + by * by + bz * bz;
    let c2 = cx * cx + cy * cy + cz * cz;
    let d2 = dx * dx + dy * dy + dz * dz;
    // det | a-e, |a-e|^2 ; b-e ... ; d-e ... | by 2x2 minors of the xy columns.
    let ab = ax * by - bx * ay;
    let ac = ax * cy - cx * ay;
    let ad = ax * dy - dx * ay;
    let bc = bx * cy - cx * by;
    let bd = bx * dy - dx * by;
    let cd = cx * dy - dx * cy;
    let abc = az * bc - bz * ac + cz * ab;
    let abd = az * bd - bz * ad + dz * ab;
    let acd = az * cd - cz * ad + dz * ac;
    let bcd = bz * cd - cz * bd + dz * bc;
    // det[a-e, b-e, c-e, d-e with lifts] = -a2*bcd + b2*acd - c2*abd + d2*abc; it is
    // negative when e is inside the sphere of a positively oriented (a, b, c, d).
    let det = (d2 * abc - c2 * abd) + (b2 * acd - a2 * bcd);
    // As in `orient3d_bounded`: the sign as a value (inside and outside are about equally
    // frequent in a cavity search, so a branch on it would be mispredicted half the time).
    if (det > static_eps) | (det < -static_eps) {
        return -sign(det);
    }
    let mx = fmax(fmax(ax.abs(), bx.abs()), fmax(cx.abs(), dx.abs()));
    let my = fmax(fmax(ay.abs(), by.abs()), fmax(cy.abs(), dy.abs()));
    let mz = fmax(fmax(az.abs(), bz.abs()), fmax(cz.abs(), dz.abs()));
    let lo = fmin(fmin(mx, my), mz);
    let hi = fmax(fmax(mx, my), mz);
    // Error bound: expanded, the determinant is 72 monomials (24 Leibniz terms, the lift a
    // sum of 3 squares), each at most mx*my*mz*hi^2, and each goes through at most 16
    // roundings (differences 1+2, square 1, lift sums 2, 2x2 minor 2, 3x3 minor 3, lifted
    // products 1, final sums 2 ... counted along the longest path: gamma_16). So
    // |error| <= 72 * gamma_16 * mx*my*mz*hi^2 < 1.3e-13 * mx*my*mz*hi^2 (CGAL's filter for
    // this determinant: 1.25e-13). 2e-13 leaves a margin.
    if lo > 1e-40 && hi < 1e40 {
        let eps = 2e-13 * mx * my * mz * hi * hi;
        if (det > eps) | (det < -eps) {
            return -sign(det);
        }
    }
    insphere_exact(a, b, c, d, e)
}

#[cold]
#[inline(never)]
fn insphere_exact(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3], e: &[f64; 3]) -> i32 {
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

/// The static bound of [`insphere_bounded`] for points whose coordinate differences are at most
/// `extent` (the largest side of their bounding box): the semi-static bound below with every
/// maximum replaced by `extent`. `f64::INFINITY` (no static filter) outside the range where the
/// error analysis holds without underflow or overflow.
pub fn static_insphere_bound(extent: f64) -> f64 {
    if extent > 1e-50 && extent < 1e40 {
        2e-13 * extent.powi(5)
    } else {
        f64::INFINITY
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
    in_conflict_bounded(t, || (it, ie), e, f64::INFINITY)
}

/// [`in_conflict`] with the static filter of [`insphere_bounded`]; the global indices
/// (`ids() = (it, ie)`) are only asked for when the exact test is a tie.
#[inline(always)]
pub fn in_conflict_bounded(
    t: [&[f64; 3]; 4],
    ids: impl FnOnce() -> ([u32; 4], u32),
    e: &[f64; 3],
    static_eps: f64,
) -> bool {
    let s = insphere_bounded(t[0], t[1], t[2], t[3], e, static_eps);
    if s != 0 {
        return s > 0;
    }
    let (it, ie) = ids();
    perturbed_insphere_tie(t, it, e, ie)
}

#[cold]
fn perturbed_insphere_tie(t: [&[f64; 3]; 4], it: [u32; 4], e: &[f64; 3], ie: u32) -> bool {
    // Roles 0..4 are the tet's vertices, 4 is the query point; visit in decreasing index.
    let mut roles = [(it[0], 0usize), (it[1], 1), (it[2], 2), (it[3], 3), (ie, 4)];
    roles.sort_unstable_by_key(|r| std::cmp::Reverse(r.0));
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
    fn filters_agree_with_the_exact_predicates() {
        let mut seed = 7u64;
        let mut r = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for i in 0..60000 {
            let mut p: [[f64; 3]; 5] = std::array::from_fn(|_| [r(), r(), r()]);
            if i % 6 == 4 {
                // On a sphere up to rounding: the insphere determinant is a few ulps of its
                // terms, right at the filters' bounds.
                let c = [r() * 0.5, r() * 0.5, r() * 0.5];
                let rad = 0.2 + 0.3 * r().abs();
                for q in &mut p {
                    let d = [r(), r(), r()];
                    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-9);
                    *q = [0, 1, 2].map(|k| c[k] + rad * d[k] / l);
                }
            }
            if i % 6 == 5 {
                // On a plane up to rounding: orient3d of the first four is nearly zero.
                let (u, v, o) = ([r(), r(), r()], [r(), r(), r()], [r(), r(), r()]);
                for q in &mut p[..4] {
                    let (s, t) = (r(), r());
                    *q = [0, 1, 2].map(|k| o[k] + s * u[k] + t * v[k]);
                }
            }
            if i % 4 == 1 {
                // Nearly co-spherical / coplanar: e close to a's mirror or on a lattice.
                p[4] = [p[0][0] + 1e-17, p[0][1], p[0][2] * (1.0 + 1e-16)];
            }
            if i % 4 == 2 {
                for q in &mut p {
                    *q = q.map(|x| (x * 4.0).round() / 4.0);
                }
            }
            if i % 4 == 3 {
                for q in &mut p {
                    *q = q.map(|x| x * 1e-30 + 1.0);
                }
            }
            assert_eq!(
                orient3d(&p[0], &p[1], &p[2], &p[3]),
                orient3d_exact(&p[0], &p[1], &p[2], &p[3])
            );
            let exact = insphere_exact(&p[0], &p[1], &p[2], &p[3], &p[4]);
            assert_eq!(insphere(&p[0], &p[1], &p[2], &p[3], &p[4]), exact);
            // Every coordinate lies in [-1, 1] (or [1, 1 + 1e-30]): differences are at most 2.
            let bound = static_insphere_bound(2.0);
            assert_eq!(
                insphere_bounded(&p[0], &p[1], &p[2], &p[3], &p[4], bound),
                exact
            );
            assert_eq!(
                orient3d_bounded(&p[0], &p[1], &p[2], &p[3], static_orient_bound(2.0)),
                orient3d_exact(&p[0], &p[1], &p[2], &p[3])
            );
        }
    }

    /// The axis-aligned-plane shortcut of the exact orientation agrees with Shewchuk's
    /// predicate: zero when the four points share a coordinate, the adaptive answer otherwise.
    #[test]
    fn points_on_an_axis_plane_are_coplanar() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut r = || rng.random_range(-1.0..1.0);
        let robust_sign = |p: &[[f64; 3]; 4]| {
            let v = robust::orient3d(c3(&p[0]), c3(&p[1]), c3(&p[2]), c3(&p[3]));
            -(v.partial_cmp(&0.0).map_or(0, |o| o as i32))
        };
        for i in 0..20000 {
            let mut p: [[f64; 3]; 4] = std::array::from_fn(|_| [r(), r(), r()]);
            let (k, x) = (i % 3, r() * 1e3);
            // All four on the plane x_k = x, or only three of them (then not coplanar).
            for q in p.iter_mut().take(if i % 2 == 0 { 4 } else { 3 }) {
                q[k] = x;
            }
            let expected = robust_sign(&p);
            assert_eq!(orient3d(&p[0], &p[1], &p[2], &p[3]), expected);
            assert_eq!(orient3d_exact(&p[0], &p[1], &p[2], &p[3]), expected);
            if i % 2 == 0 {
                assert_eq!(expected, 0);
            }
        }
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
