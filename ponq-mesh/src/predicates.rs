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

use robust::{Coord, Coord3D, orient2d};

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

// Packed `f64` arithmetic of the AVX2 lanes below ([`orient3d_faces_avx2`],
// [`insphere_static4_avx2`]): macros rather than closures, which are not always inlined in
// AVX2 code (see `flips::error_at_avx2`). Each is one operation, so the lanes keep the scalar
// code's order.
#[cfg(target_arch = "x86_64")]
macro_rules! sub {
    ($x:expr, $y:expr) => {
        std::arch::x86_64::_mm256_sub_pd($x, $y)
    };
}
#[cfg(target_arch = "x86_64")]
macro_rules! mul {
    ($x:expr, $y:expr) => {
        std::arch::x86_64::_mm256_mul_pd($x, $y)
    };
}
#[cfg(target_arch = "x86_64")]
macro_rules! add {
    ($x:expr, $y:expr) => {
        std::arch::x86_64::_mm256_add_pd($x, $y)
    };
}

/// The static filter of [`orient3d_bounded`] for the four faces of tet `t` against point `p`,
/// one per lane, with AVX2: lane `k` is the orientation of `t` with its vertex `k` replaced by
/// `p` (what a visibility walk asks of each face). Returns two masks, bit `k` for lane `k`:
/// decided negative, and not decided (`|det| <= eps`: [`orient3d_bounded`] goes on from
/// there). Every lane does [`orient3d_bounded`]'s operations in its order (no fused
/// operations), so a decided lane is its answer (tested). Why by hand: one face after the
/// other, the walk branches on each sign, which goes either way about as often.
///
/// # Safety
/// The CPU must have AVX2. (Inlined into a function compiled for AVX2, the intrinsics become
/// single instructions; elsewhere each is a call.)
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn orient3d_faces_avx2(t: [&[f64; 3]; 4], p: &[f64; 3], eps: f64) -> (u32, u32) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's CPU has AVX2 (this function's contract).
    unsafe {
        // Coordinate `i` of the lanes' points `q0..q3`: `t`'s, with `p` in lane `k` of `qk`.
        macro_rules! lanes {
            ($q:expr, $i:expr) => {{
                let tq = _mm256_set1_pd(t[$q][$i]);
                let pq = _mm256_set1_pd(p[$i]);
                _mm256_blend_pd::<{ 1 << $q }>(tq, pq)
            }};
        }
        let (ax, ay, az) = (lanes!(0, 0), lanes!(0, 1), lanes!(0, 2));
        let (bx, by, bz) = (
            sub!(lanes!(1, 0), ax),
            sub!(lanes!(1, 1), ay),
            sub!(lanes!(1, 2), az),
        );
        let (cx, cy, cz) = (
            sub!(lanes!(2, 0), ax),
            sub!(lanes!(2, 1), ay),
            sub!(lanes!(2, 2), az),
        );
        let (dx, dy, dz) = (
            sub!(lanes!(3, 0), ax),
            sub!(lanes!(3, 1), ay),
            sub!(lanes!(3, 2), az),
        );
        // bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx)
        let m1 = sub!(mul!(cy, dz), mul!(cz, dy));
        let m2 = sub!(mul!(cx, dz), mul!(cz, dx));
        let m3 = sub!(mul!(cx, dy), mul!(cy, dx));
        let det = add!(sub!(mul!(bx, m1), mul!(by, m2)), mul!(bz, m3));
        let above = _mm256_cmp_pd::<_CMP_GT_OQ>(det, _mm256_set1_pd(eps));
        let below = _mm256_cmp_pd::<_CMP_LT_OQ>(det, _mm256_set1_pd(-eps));
        let decided = _mm256_movemask_pd(_mm256_or_pd(above, below)) as u32;
        // A decided lane's sign is its determinant's.
        let negative = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(det, _mm256_setzero_pd()));
        (negative as u32 & decided, !decided & 0xF)
    }
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

/// Whether `a`, `b` and `c` lie on one line (exactly: the three coordinate-plane projections
/// of the triangle all have zero signed area). Equal points are collinear.
pub fn collinear(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3]) -> bool {
    [(0, 1), (1, 2), (2, 0)].iter().all(|&(i, j)| {
        let q = |p: &[f64; 3]| robust::Coord { x: p[i], y: p[j] };
        robust::orient2d(q(a), q(b), q(c)) == 0.0
    })
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

/// The static filter of [`insphere_bounded`] for `L` tets against one point `e` at once, one
/// tet per lane of `[f64; L]` arrays (the compiler computes the lanes together in vector
/// registers, SSE2 pairs at least), with the local bound of `reach_decides` beside it: for
/// lane `l`, `-sign(det)` when `|det| > eps[l]` or that bound decides, else 0 (undecided:
/// [`in_conflict_past_static`] goes on from the lane's determinant, the second array). The
/// lanes compute [`insphere_bounded`]'s determinant by the same function (Rust never fuses a
/// multiply and an add, packed or not), so a decided lane is that function's answer
/// (tested).
#[inline(always)]
pub fn insphere_static_lanes<const L: usize>(
    t: &[[[f64; 3]; 4]; L],
    e: &[f64; 3],
    eps: &[f64; L],
) -> ([i32; L], [f64; L]) {
    let mut out = [0i32; L];
    let mut dets = [0.0f64; L];
    for l in 0..L {
        let [a, b, c, d] = &t[l];
        let (det, r2) = insphere_det_reach(a, b, c, d, e);
        let decided = (det > eps[l]) | (det < -eps[l]) | reach_decides(det, r2);
        out[l] = if decided { -sign(det) } else { 0 };
        dets[l] = det;
    }
    (out, dets)
}

/// [`insphere_static_lanes`] for four tets given by vertex numbers into `pos`, with AVX2:
/// the points go from `pos` straight into the lanes (x and y of a point by one 16-byte load,
/// two shuffles per register of four; z one by one), with no copy into an array of points
/// first, and the answers come from comparisons in the lanes. Every lane does the operations
/// of [`insphere_bounded`]'s determinant in their order (no fused operations), so the results
/// are [`insphere_static_lanes`]' to the bit (tested). Why by hand: the cavity search of the
/// Delaunay (`crate::delaunay`) runs this once per cavity tet, and the compiler built the
/// plain loop's lanes from scalars (a broadcast and a blend per coordinate) after a copy of
/// the points; a first version that took the answers lane by lane compiled to a branch per
/// lane on the sign, mispredicted half the time (insertion 12% slower than before it).
///
/// # Safety
/// The CPU must have AVX2. (Inlined into a function compiled for AVX2, the intrinsics become
/// single instructions; elsewhere each is a call.)
///
/// # Panics
/// If a vertex number is out of range of `pos`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn insphere_static4_avx2(
    pos: &[[f64; 3]],
    ids: &[[u32; 4]; 4],
    e: &[f64; 3],
    eps: &[f64; 4],
) -> ([i32; 4], [f64; 4]) {
    // SAFETY: the CPU has AVX2 (this function's contract); the loads read two of
    // the three coordinates of points of `pos` (bounds-checked), the store four `f64` into
    // `dets`.
    unsafe {
        use std::arch::x86_64::*;
        // Straight-line code and macros: closures in AVX2 code are not always inlined (see
        // `flips::error_at_avx2`).
        let (ex, ey, ez) = (
            _mm256_set1_pd(e[0]),
            _mm256_set1_pd(e[1]),
            _mm256_set1_pd(e[2]),
        );
        // Vertex `q` of the four lanes: x, y and z each in one register (lane l: tet l), minus `e`.
        macro_rules! vertex {
            ($q:expr) => {{
                let (p0, p1, p2, p3) = (
                    &pos[ids[0][$q] as usize],
                    &pos[ids[1][$q] as usize],
                    &pos[ids[2][$q] as usize],
                    &pos[ids[3][$q] as usize],
                );
                // Each pointer is to a `[f64; 3]`, of which the loads read the first two.
                let (xy0, xy1, xy2, xy3) = (
                    _mm_loadu_pd(p0.as_ptr()),
                    _mm_loadu_pd(p1.as_ptr()),
                    _mm_loadu_pd(p2.as_ptr()),
                    _mm_loadu_pd(p3.as_ptr()),
                );
                // [x0 y0 x2 y2] and [x1 y1 x3 y3], then the x and the y of all four.
                let lo = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(xy0), xy2);
                let hi = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(xy1), xy3);
                let z = _mm256_set_pd(p3[2], p2[2], p1[2], p0[2]);
                (
                    _mm256_sub_pd(_mm256_unpacklo_pd(lo, hi), ex),
                    _mm256_sub_pd(_mm256_unpackhi_pd(lo, hi), ey),
                    _mm256_sub_pd(z, ez),
                )
            }};
        }
        // `(x * x + y * y) + z * z`, as `insphere_det`.
        macro_rules! norm2 {
            ($x:expr, $y:expr, $z:expr) => {
                add!(add!(mul!($x, $x), mul!($y, $y)), mul!($z, $z))
            };
        }
        // `u * v - w * t`.
        macro_rules! minor {
            ($u:expr, $v:expr, $w:expr, $t:expr) => {
                sub!(mul!($u, $v), mul!($w, $t))
            };
        }
        let (ax, ay, az) = vertex!(0);
        let (bx, by, bz) = vertex!(1);
        let (cx, cy, cz) = vertex!(2);
        let (dx, dy, dz) = vertex!(3);
        let a2 = norm2!(ax, ay, az);
        let b2 = norm2!(bx, by, bz);
        let c2 = norm2!(cx, cy, cz);
        let d2 = norm2!(dx, dy, dz);
        let ab = minor!(ax, by, bx, ay);
        let ac = minor!(ax, cy, cx, ay);
        let ad = minor!(ax, dy, dx, ay);
        let bc = minor!(bx, cy, cx, by);
        let bd = minor!(bx, dy, dx, by);
        let cd = minor!(cx, dy, dx, cy);
        let abc = add!(minor!(az, bc, bz, ac), mul!(cz, ab));
        let abd = add!(minor!(az, bd, bz, ad), mul!(dz, ab));
        let acd = add!(minor!(az, cd, cz, ad), mul!(dz, ac));
        let bcd = add!(minor!(bz, cd, cz, bd), mul!(dz, bc));
        let det = add!(minor!(d2, abc, c2, abd), minor!(b2, acd, a2, bcd));
        let mut dets = [0.0f64; 4];
        // `dets` holds four `f64`; an unaligned store.
        _mm256_storeu_pd(dets.as_mut_ptr(), det);
        // The answers as `insphere_static_lanes` gives them, from comparisons in the lanes (a
        // branch per lane on the sign would be mispredicted half the time).
        let eps = _mm256_loadu_pd(eps.as_ptr());
        let neg_eps = _mm256_xor_pd(eps, _mm256_set1_pd(-0.0));
        // `reach_decides` with the same operations in the same order.
        let r2 = _mm256_max_pd(_mm256_max_pd(a2, b2), _mm256_max_pd(c2, d2));
        let in_range = _mm256_and_pd(
            _mm256_cmp_pd::<_CMP_GT_OQ>(r2, _mm256_set1_pd(1e-40)),
            _mm256_cmp_pd::<_CMP_LT_OQ>(r2, _mm256_set1_pd(1e40)),
        );
        let sq = mul!(r2, r2);
        let r10 = mul!(mul!(sq, sq), r2);
        let reach = _mm256_and_pd(
            in_range,
            _mm256_cmp_pd::<_CMP_GT_OQ>(mul!(det, det), mul!(_mm256_set1_pd(4e-26), r10)),
        );
        let decided = _mm256_movemask_pd(_mm256_or_pd(
            reach,
            _mm256_or_pd(
                _mm256_cmp_pd::<_CMP_GT_OQ>(det, eps),
                _mm256_cmp_pd::<_CMP_LT_OQ>(det, neg_eps),
            ),
        ));
        let zero = _mm256_setzero_pd();
        let below = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(det, zero));
        let above = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(det, zero));
        let mut out = [0i32; 4];
        for (l, o) in out.iter_mut().enumerate() {
            // `-sign(det)` where decided, else 0.
            let bit = |m: i32| (m >> l) & 1;
            *o = (bit(below) - bit(above)) * bit(decided);
        }
        (out, dets)
    }
}

/// The determinant of [`insphere_bounded`] (negative when `e` is inside the sphere of a
/// positively oriented `(a, b, c, d)`), in floating point: one function, so that every caller
/// (the lanes of [`insphere_static_lanes`] too) computes the same bits.
#[inline(always)]
fn insphere_det(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3], e: &[f64; 3]) -> f64 {
    insphere_det_reach(a, b, c, d, e).0
}

/// [`insphere_det`] and the largest squared distance of `a`, `b`, `c` and `d` from `e` as
/// computed along the way (the lifts), for [`reach_decides`].
#[inline(always)]
fn insphere_det_reach(
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
    e: &[f64; 3],
) -> (f64, f64) {
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
    (det, fmax(fmax(a2, b2), fmax(c2, d2)))
}

/// Whether the sign of `det` is the exact sign of the insphere determinant, by a bound from
/// `r2` alone, the largest squared distance of the four points from the fifth (both from
/// [`insphere_det_reach`]). Unlike the static bound, which takes the extent of the whole
/// input, it is local: on a dense input (the v* of a 230^3 PoNQ, whose flat regions give many
/// nearly co-spherical tets) the static bound leaves one conflict test in ten undecided,
/// this one almost none. Cheaper than the semi-static bound of [`insphere_past_static`]
/// (no per-axis maxima), and looser by a small factor.
///
/// Error analysis: with `mx`, `my`, `mz` the largest absolute (computed) coordinate
/// differences and `hi` their maximum, [`insphere_past_static`] bounds the error of `det` by
/// `1.3e-13 * mx * my * mz * hi^2`. Each of them is at most `R`, the largest exact distance
/// of the computed differences, and the computed lifts (products and sums of non-negative
/// numbers, three roundings) are at least `R^2 (1 - u)^3`, so the error is below
/// `1.3e-13 * r2^2.5 * (1 + 8u)`. The test `det^2 > 4e-26 * r2^5` (six roundings on either
/// side) then means `|det| > 1.99e-13 * r2^2.5`, beyond the error. Range: with `r2` in
/// `(1e-40, 1e40)` nothing overflows (`det^2 < 1e210`), `4e-26 * r2^5 > 1e-226` is a normal
/// number, and an underflow inside the determinant (one axis with tiny differences) adds an
/// absolute error below `1e-250` (at most a hundred operations of `2^-1075` each, times
/// the later factors, below `3 R^3`), far below the bound (over `1e-113`). `det^2` itself
/// may underflow: then the test fails and nothing is decided.
#[inline(always)]
fn reach_decides(det: f64, r2: f64) -> bool {
    let in_range = (r2 > 1e-40) & (r2 < 1e40);
    let sq = r2 * r2;
    in_range & (det * det > 4e-26 * (sq * sq * r2))
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
    let det = insphere_det(a, b, c, d, e);
    // As in `orient3d_bounded`: the sign as a value (inside and outside are about equally
    // frequent in a cavity search, so a branch on it would be mispredicted half the time).
    if (det > static_eps) | (det < -static_eps) {
        return -sign(det);
    }
    insphere_past_static(a, b, c, d, e, det)
}

/// The rest of [`insphere_bounded`] once its static bound has not decided: `det` must be the
/// determinant that function computes (bit for bit, as [`insphere_static_lanes`] gives it).
/// The semi-static bound from the actual coordinate differences, then the exact sign.
#[inline]
pub fn insphere_past_static(
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
    e: &[f64; 3],
    det: f64,
) -> i32 {
    let (ax, ay, az) = (a[0] - e[0], a[1] - e[1], a[2] - e[2]);
    let (bx, by, bz) = (b[0] - e[0], b[1] - e[1], b[2] - e[2]);
    let (cx, cy, cz) = (c[0] - e[0], c[1] - e[1], c[2] - e[2]);
    let (dx, dy, dz) = (d[0] - e[0], d[1] - e[1], d[2] - e[2]);
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
    let in_range = lo > 1e-40 && hi < 1e40;
    if in_range {
        let eps = 2e-13 * mx * my * mz * hi * hi;
        if (det > eps) | (det < -eps) {
            return -sign(det);
        }
    }
    insphere_exact(a, b, c, d, e, in_range)
}

/// The insphere sign when Shewchuk's first error bound decides it (`isperrboundA` times the
/// permanent of the same expression as [`insphere_bounded`]: the sum of the absolute values
/// of its monomials), else `None`. Valid without underflow or overflow.
#[inline(never)]
fn insphere_permanent_filter(
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
    e: &[f64; 3],
) -> Option<i32> {
    let df = |p: &[f64; 3]| [p[0] - e[0], p[1] - e[1], p[2] - e[2]];
    let (pa, pb, pc, pd) = (df(a), df(b), df(c), df(d));
    let lift = |p: [f64; 3]| p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
    // 2x2 minors of the xy columns and their permanents.
    let m = |p: [f64; 3], q: [f64; 3]| {
        (
            p[0] * q[1] - q[0] * p[1],
            (p[0] * q[1]).abs() + (q[0] * p[1]).abs(),
        )
    };
    let (ab, ac, ad, bc, bd, cd) = (
        m(pa, pb),
        m(pa, pc),
        m(pa, pd),
        m(pb, pc),
        m(pb, pd),
        m(pc, pd),
    );
    // 3x3 minors (z against the 2x2 minors) and their permanents.
    let t = |p: f64, x: (f64, f64), q: f64, y: (f64, f64), r: f64, z: (f64, f64)| {
        (
            p * x.0 - q * y.0 + r * z.0,
            p.abs() * x.1 + q.abs() * y.1 + r.abs() * z.1,
        )
    };
    let abc = t(pa[2], bc, pb[2], ac, pc[2], ab);
    let abd = t(pa[2], bd, pb[2], ad, pd[2], ab);
    let acd = t(pa[2], cd, pc[2], ad, pd[2], ac);
    let bcd = t(pb[2], cd, pc[2], bd, pd[2], bc);
    let (la, lb, lc, ld) = (lift(pa), lift(pb), lift(pc), lift(pd));
    let det = (ld * abc.0 - lc * abd.0) + (lb * acd.0 - la * bcd.0);
    let permanent = ld * abc.1 + lc * abd.1 + lb * acd.1 + la * bcd.1;
    // isperrboundA = (16 + 224 u) u with u = 2^-53 is 1.7764e-15 (Shewchuk, for this
    // evaluation order); 2e-15 leaves a margin.
    let bound = 2e-15 * permanent;
    if det > bound {
        Some(-1)
    } else if det < -bound {
        Some(1)
    } else {
        None
    }
}

#[cold]
#[inline(never)]
fn insphere_exact(
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
    e: &[f64; 3],
    in_range: bool,
) -> i32 {
    // Within the filters' range (no underflow or overflow): Shewchuk's permanent-based bound
    // first, tighter than the semi-static one and what `robust::insphere` tries first too;
    // what it leaves undecided is a near-tie. Points whose coordinates span few binary
    // orders of magnitude (every input of a normalised grid but those with coordinates very
    // near zero) are exact integers on a common scale: there the determinant is evaluated in
    // fixed-width integers, several times faster than `robust`'s adaptive stages and
    // expansion arithmetic on such near-ties (on lattices, where nearly every insphere test
    // is one, they took 85% of the time).
    if in_range {
        if let Some(s) = insphere_permanent_filter(a, b, c, d, e) {
            return s;
        }
        if let Some(s) = fixed::insphere_sign(a, b, c, d, e) {
            return s;
        }
    }
    insphere_adaptive(a, b, c, d, e)
}

/// Shewchuk's adaptive exact insphere (`robust`), the last resort of [`insphere_exact`]. Kept
/// out of line: its expansion arrays make a stack frame of tens of kilobytes, and inlined
/// into its caller every call of the caller probed those pages, whether it got this far or not
/// (on an exact lattice, where nearly every test is a tie the fixed-width path decides, the
/// insertion measured 5% slower that way: 6.5M extra first-level cache write misses).
#[cold]
#[inline(never)]
fn insphere_adaptive(a: &[f64; 3], b: &[f64; 3], c: &[f64; 3], d: &[f64; 3], e: &[f64; 3]) -> i32 {
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

/// [`in_conflict_bounded`] once its static bound has not decided, from the determinant
/// [`insphere_static_lanes`] computed (see [`insphere_past_static`]).
#[inline]
pub fn in_conflict_past_static(
    t: [&[f64; 3]; 4],
    ids: impl FnOnce() -> ([u32; 4], u32),
    e: &[f64; 3],
    det: f64,
) -> bool {
    let s = insphere_past_static(t[0], t[1], t[2], t[3], e, det);
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
    let (r, det) = circumcenter_unchecked(a, b, c, d);
    circumcenter_found(&r, det).then_some(r)
}

/// Whether [`circumcenter_unchecked`]'s `(r, det)` is a circumcentre (what [`circumcenter`]
/// returns): a non-zero, finite determinant and finite coordinates.
#[inline(always)]
pub fn circumcenter_found(r: &[f64; 3], det: f64) -> bool {
    det != 0.0 && det.is_finite() && r.iter().all(|x| x.is_finite())
}

/// [`circumcenter`]'s arithmetic without its checks: the centre and the determinant it
/// divides by (the centre is meaningful only when [`circumcenter_found`]). One function, so that the tagging's lanes
/// (`tagging::tag_lanes`) compute the same bits.
#[inline(always)]
pub fn circumcenter_unchecked(
    a: &[f64; 3],
    b: &[f64; 3],
    c: &[f64; 3],
    d: &[f64; 3],
) -> ([f64; 3], f64) {
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
    let (lu, lv, lw) = (dot(u), dot(v), dot(w));
    let s = 0.5 / det;
    let r = [
        a[0] + s * (lu * vw[0] + lv * wu[0] + lw * uv[0]),
        a[1] + s * (lu * vw[1] + lv * wu[1] + lw * uv[1]),
        a[2] + s * (lu * vw[2] + lv * wu[2] + lw * uv[2]),
    ];
    (r, det)
}

/// The exact insphere determinant in fixed-width integer arithmetic.
///
/// Every finite `f64` is `m 2^k` with an integer `m < 2^53`. When the 15 coordinates of the
/// five points span at most [`fixed::MAX_SPAN`] bits (from the lowest set bit of the smallest
/// exponent to the top bit of the largest number), they are integers below `2^99` on the
/// common scale `2^k_min`; their differences (below `2^100`) are exact, and the determinant
/// of [`insphere_bounded`] (degree 5 in them) is below `2^507`. Spans up to 61 bits (lattices
/// and points away from the coordinate planes) run in native `i64` / `i128`, with 3- and
/// 5-limb wrapping integers for the last two products; wider ones in 4-, 5- and 8-limb
/// wrapping integers, each stage in the width its values need. Why by hand: fixed-width
/// big-integer crates (`bnum`, `crypto-bigint`) would do, but one width for every stage (512
/// bits) costs several times the limb products of these graded widths; the few lines of
/// two's-complement limb arithmetic are tested against `robust` and against themselves
/// (native against limbs).
mod fixed {
    /// Largest span (bits) of the coordinates handled here: differences below `2^(span+1)`,
    /// the determinant below `2^(5 span + 13)` < `2^511`.
    pub const MAX_SPAN: i32 = 99;

    /// Largest span (bits) of the native-width path: differences below `2^62` (i64), their
    /// 2x2 minors and lifts below `2^126` (i128).
    const SMALL_SPAN: i32 = 61;

    /// Two's-complement integers of `N` 64-bit limbs, little-endian, wrapping: exact for
    /// values below `2^(64 N - 1)` in magnitude.
    pub(super) type Fixed<const N: usize> = [u64; N];

    pub(super) fn fixed_from_i128<const N: usize>(x: i128) -> Fixed<N> {
        let ext = if x < 0 { u64::MAX } else { 0 };
        std::array::from_fn(|i| match i {
            0 => x as u64,
            1 => (x >> 64) as u64,
            _ => ext,
        })
    }

    pub(super) fn fixed_add<const N: usize>(a: &Fixed<N>, b: &Fixed<N>) -> Fixed<N> {
        let mut out = [0u64; N];
        let mut carry = false;
        for i in 0..N {
            let (s1, c1) = a[i].overflowing_add(b[i]);
            let (s2, c2) = s1.overflowing_add(carry as u64);
            out[i] = s2;
            carry = c1 | c2;
        }
        out
    }

    pub(super) fn fixed_neg<const N: usize>(a: &Fixed<N>) -> Fixed<N> {
        let mut out = [0u64; N];
        let mut carry = true;
        for i in 0..N {
            let (s, c) = (!a[i]).overflowing_add(carry as u64);
            out[i] = s;
            carry = c;
        }
        out
    }

    pub(super) fn fixed_sub<const N: usize>(a: &Fixed<N>, b: &Fixed<N>) -> Fixed<N> {
        fixed_add(a, &fixed_neg(b))
    }

    /// The same value in `N >= M` limbs (sign-extended).
    pub(super) fn fixed_widen<const M: usize, const N: usize>(a: &Fixed<M>) -> Fixed<N> {
        let ext = if a[M - 1] >> 63 == 1 { u64::MAX } else { 0 };
        std::array::from_fn(|i| if i < M { a[i] } else { ext })
    }

    /// `a b` modulo `2^(64 N)` (schoolbook, only the limbs below `N`).
    pub(super) fn fixed_mul<const N: usize>(a: &Fixed<N>, b: &Fixed<N>) -> Fixed<N> {
        let mut out = [0u64; N];
        for i in 0..N {
            let mut carry = 0u128;
            for j in 0..N - i {
                let t = a[i] as u128 * b[j] as u128 + out[i + j] as u128 + carry;
                out[i + j] = t as u64;
                carry = t >> 64;
            }
        }
        out
    }

    pub(super) fn fixed_signum<const N: usize>(a: &Fixed<N>) -> i32 {
        if a[N - 1] >> 63 == 1 {
            -1
        } else if a.iter().any(|&x| x != 0) {
            1
        } else {
            0
        }
    }

    /// [`insphere_sign`] for integer points whose differences are below `2^62`: minors and
    /// lifts in i128, 3x3 minors (below `2^189`) in 3 limbs, the determinant (below `2^317`)
    /// in 5 limbs.
    pub(super) fn insphere_sign_small(q: &[[i128; 3]; 5]) -> i32 {
        let d: [[i64; 3]; 4] =
            std::array::from_fn(|i| std::array::from_fn(|k| (q[i][k] - q[4][k]) as i64));
        let m = |i: usize, j: usize| -> i128 {
            d[i][0] as i128 * d[j][1] as i128 - d[j][0] as i128 * d[i][1] as i128
        };
        let lift = |i: usize| -> i128 { d[i].iter().map(|&x| x as i128 * x as i128).sum::<i128>() };
        let (ab, ac, ad, bc, bd, cd) = (m(0, 1), m(0, 2), m(0, 3), m(1, 2), m(1, 3), m(2, 3));
        // z_i * minor, as 3 limbs.
        let zm = |i: usize, minor: i128| -> Fixed<3> {
            fixed_mul(
                &fixed_from_i128::<3>(d[i][2] as i128),
                &fixed_from_i128::<3>(minor),
            )
        };
        let tri =
            |p: Fixed<3>, n: Fixed<3>, r: Fixed<3>| fixed_add(&fixed_add(&p, &fixed_neg(&n)), &r);
        let abc = tri(zm(0, bc), zm(1, ac), zm(2, ab));
        let abd = tri(zm(0, bd), zm(1, ad), zm(3, ab));
        let acd = tri(zm(0, cd), zm(2, ad), zm(3, ac));
        let bcd = tri(zm(1, cd), zm(2, bd), zm(3, bc));
        let term =
            |l: i128, t: Fixed<3>| fixed_mul(&fixed_from_i128::<5>(l), &fixed_widen::<3, 5>(&t));
        let det = fixed_add(
            &fixed_sub(&term(lift(3), abc), &term(lift(2), abd)),
            &fixed_sub(&term(lift(1), acd), &term(lift(0), bcd)),
        );
        -fixed_signum(&det)
    }

    /// `x = m 2^k` with `m` an odd or zero integer below `2^53` in magnitude (sign in `m`);
    /// `None` for zero.
    fn split(x: f64) -> Option<(i64, i32)> {
        if x == 0.0 {
            return None;
        }
        let bits = x.to_bits();
        let exp = ((bits >> 52) & 0x7ff) as i32;
        let frac = bits & ((1u64 << 52) - 1);
        let (mut m, mut k) = if exp == 0 {
            (frac, -1074)
        } else {
            (frac | (1u64 << 52), exp - 1075)
        };
        let tz = m.trailing_zeros();
        m >>= tz;
        k += tz as i32;
        let m = m as i64;
        Some((if x < 0.0 { -m } else { m }, k))
    }

    /// The exact sign of [`super::insphere`] for points whose coordinates span at most
    /// [`MAX_SPAN`] bits; `None` otherwise (the caller falls back to expansion arithmetic).
    pub fn insphere_sign(
        a: &[f64; 3],
        b: &[f64; 3],
        c: &[f64; 3],
        d: &[f64; 3],
        e: &[f64; 3],
    ) -> Option<i32> {
        let pts = [a, b, c, d, e];
        let mut parts = [[None; 3]; 5];
        let (mut lo, mut hi) = (i32::MAX, i32::MIN);
        for (i, p) in pts.iter().enumerate() {
            for k in 0..3 {
                if !p[k].is_finite() {
                    return None;
                }
                if let Some((m, x)) = split(p[k]) {
                    lo = lo.min(x);
                    hi = hi.max(x + 64 - m.unsigned_abs().leading_zeros() as i32);
                    parts[i][k] = Some((m, x));
                }
            }
        }
        if lo == i32::MAX {
            // All coordinates zero: five equal points.
            return Some(0);
        }
        if hi - lo > MAX_SPAN {
            return None;
        }
        // Integers on the common scale 2^lo: below 2^MAX_SPAN, so they and their
        // differences fit in i128.
        let int = |v: Option<(i64, i32)>| -> i128 { v.map_or(0, |(m, x)| (m as i128) << (x - lo)) };
        let q: [[i128; 3]; 5] = std::array::from_fn(|i| std::array::from_fn(|k| int(parts[i][k])));
        Some(if hi - lo <= SMALL_SPAN {
            insphere_sign_small(&q)
        } else {
            insphere_sign_wide(&q)
        })
    }

    /// [`insphere_sign`] for integer points whose differences are below `2^100` (i128): 2x2
    /// minors and lifts (below `2^202`) in 4 limbs, 3x3 minors (below `2^303`) in 5, the
    /// determinant (below `2^507`) in 8.
    pub(super) fn insphere_sign_wide(q: &[[i128; 3]; 5]) -> i32 {
        let d: [[Fixed<4>; 3]; 4] =
            std::array::from_fn(|i| std::array::from_fn(|k| fixed_from_i128(q[i][k] - q[4][k])));
        let m = |i: usize, j: usize| -> Fixed<4> {
            fixed_sub(
                &fixed_mul(&d[i][0], &d[j][1]),
                &fixed_mul(&d[j][0], &d[i][1]),
            )
        };
        let lift = |i: usize| -> Fixed<8> {
            let [x, y, z] = d[i].map(|v| fixed_mul(&v, &v));
            fixed_widen(&fixed_add(&fixed_add(&x, &y), &z))
        };
        let (ab, ac, ad, bc, bd, cd) = (m(0, 1), m(0, 2), m(0, 3), m(1, 2), m(1, 3), m(2, 3));
        // z_i * minor, as 5 limbs.
        let zm = |i: usize, minor: Fixed<4>| -> Fixed<5> {
            fixed_mul(&fixed_widen(&d[i][2]), &fixed_widen(&minor))
        };
        let tri = |p: Fixed<5>, n: Fixed<5>, r: Fixed<5>| fixed_add(&fixed_sub(&p, &n), &r);
        let abc = tri(zm(0, bc), zm(1, ac), zm(2, ab));
        let abd = tri(zm(0, bd), zm(1, ad), zm(3, ab));
        let acd = tri(zm(0, cd), zm(2, ad), zm(3, ac));
        let bcd = tri(zm(1, cd), zm(2, bd), zm(3, bc));
        let term = |l: Fixed<8>, t: Fixed<5>| fixed_mul(&l, &fixed_widen(&t));
        let det = fixed_add(
            &fixed_sub(&term(lift(3), abc), &term(lift(2), abd)),
            &fixed_sub(&term(lift(1), acd), &term(lift(0), bcd)),
        );
        // Negative when e is inside: see `insphere_bounded`.
        -fixed_signum(&det)
    }
}

/// Exact sign of `orient2d(a, b, c)` (positive: counter-clockwise), for the 2D tests on an axis
/// projection ([`proj`]) of the validity check and the fan certificate.
#[inline]
pub(crate) fn o2(a: Coord<f64>, b: Coord<f64>, c: Coord<f64>) -> i8 {
    sign(orient2d(a, b, c)) as i8
}

/// Projection dropping coordinate `axis`.
#[inline]
pub(crate) fn proj(p: &[f64; 3], axis: u8) -> Coord<f64> {
    match axis {
        0 => Coord { x: p[1], y: p[2] },
        1 => Coord { x: p[2], y: p[0] },
        _ => Coord { x: p[0], y: p[1] },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const O: [f64; 3] = [0.0, 0.0, 0.0];
    const X: [f64; 3] = [1.0, 0.0, 0.0];
    const Y: [f64; 3] = [0.0, 1.0, 0.0];
    const Z: [f64; 3] = [0.0, 0.0, 1.0];

    #[test]
    fn collinear_is_exact() {
        let third = 1.0 / 3.0;
        assert!(collinear(&O, &X, &[2.0, 0.0, 0.0]));
        assert!(collinear(&O, &O, &Y));
        assert!(collinear(
            &[1.0, 2.0, 3.0],
            &[2.0, 4.0, 6.0],
            &[-0.5, -1.0, -1.5]
        ));
        assert!(!collinear(&O, &X, &Y));
        // One ulp off the line through the origin and (1, 1/3, 1/3).
        assert!(collinear(
            &O,
            &[1.0, third, third],
            &[2.0, 2.0 * third, 2.0 * third]
        ));
        let off = f64::from_bits((2.0 * third).to_bits() + 1);
        assert!(!collinear(
            &O,
            &[1.0, third, third],
            &[2.0, off, 2.0 * third]
        ));
    }

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

    /// Five-point sets on which the filters are hard: random, co-spherical and coplanar up
    /// to rounding, nearly coincident, on a lattice (exact ties), and far from the origin
    /// (tiny differences), with every coordinate difference at most 2.
    fn hard_cases(n: usize) -> impl Iterator<Item = [[f64; 3]; 5]> {
        let mut seed = 7u64;
        let mut r = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        (0..n).map(move |i| {
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
            p
        })
    }

    /// The lanes of [`insphere_static_lanes`] (8 and 4, and [`insphere_static4_avx2`]'s four
    /// where the CPU has AVX2) against the one-test functions on the hard cases, each
    /// translated so that its fifth point is the group's common one: the same determinant bits
    /// as [`insphere_det`], a decided lane has the exact sign, and an undecided one (ties, and
    /// lanes without a static bound) continues to the exact sign and to
    /// [`in_conflict_bounded`]'s answer.
    #[test]
    fn lanes_agree_with_the_one_test_filter() {
        use std::array::from_fn;
        let cases: Vec<[[f64; 3]; 5]> = hard_cases(24000).collect();
        let (mut decided, mut undecided) = (0, 0);
        for (g, group) in cases.chunks_exact(8).enumerate() {
            let e = group[0][4];
            let t: [[[f64; 3]; 4]; 8] =
                from_fn(|l| from_fn(|i| from_fn(|k| group[l][i][k] - group[l][4][k] + e[k])));
            // Coordinate differences stay below 2 plus roundings.
            let eps: [f64; 8] = from_fn(|l| {
                if (g + l) % 5 == 0 {
                    f64::INFINITY
                } else {
                    static_insphere_bound(4.0)
                }
            });
            let (s8, d8) = insphere_static_lanes(&t, &e, &eps);
            let (s4, d4) = insphere_static_lanes::<4>(&from_fn(|l| t[l]), &e, &from_fn(|l| eps[l]));
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // The same four tets read from a point array, in a shuffled order.
                let mut pos: Vec<[f64; 3]> = t[..4].iter().flatten().copied().collect();
                pos.reverse();
                let ids: [[u32; 4]; 4] = from_fn(|l| from_fn(|i| (15 - 4 * l - i) as u32));
                // SAFETY: the CPU has AVX2.
                let (sa, da) =
                    unsafe { insphere_static4_avx2(&pos, &ids, &e, &from_fn(|l| eps[l])) };
                assert_eq!(sa, s4);
                assert_eq!(da.map(f64::to_bits), d4.map(f64::to_bits));
            }
            for l in 0..8 {
                let [a, b, c, d] = &t[l];
                let det = insphere_det(a, b, c, d, &e);
                assert_eq!(d8[l].to_bits(), det.to_bits());
                if l < 4 {
                    assert_eq!((s4[l], d4[l].to_bits()), (s8[l], det.to_bits()));
                }
                let exact = robust_insphere([*a, *b, *c, *d, e]);
                // Decided exactly where the static bound decides `insphere_bounded`, or the
                // local one.
                let r2 = insphere_det_reach(a, b, c, d, &e).1;
                assert_eq!(s8[l] != 0, det.abs() > eps[l] || reach_decides(det, r2));
                if s8[l] != 0 {
                    decided += 1;
                    assert_eq!(s8[l], exact);
                    continue;
                }
                undecided += 1;
                assert_eq!(insphere_past_static(a, b, c, d, &e, det), exact);
                let pts = [a, b, c, d, &e];
                let distinct = (0..5).all(|i| (0..i).all(|j| pts[i] != pts[j]));
                if distinct && orient3d(a, b, c, d) > 0 {
                    let ids = || ([0, 1, 2, 3], 4);
                    assert_eq!(
                        in_conflict_past_static([a, b, c, d], ids, &e, det),
                        in_conflict_bounded([a, b, c, d], ids, &e, eps[l])
                    );
                }
            }
        }
        assert!(
            decided > 5_000 && undecided > 5_000,
            "{decided} / {undecided}"
        );
    }

    #[test]
    fn filters_agree_with_the_exact_predicates() {
        for p in hard_cases(60000) {
            assert_eq!(
                orient3d(&p[0], &p[1], &p[2], &p[3]),
                orient3d_exact(&p[0], &p[1], &p[2], &p[3])
            );
            // Shewchuk's expansion arithmetic alone is the reference; the exact stage with
            // and without its in-range steps (permanent filter, fixed-width integers) agrees.
            let exact = robust_insphere(p);
            for in_range in [false, true] {
                assert_eq!(
                    insphere_exact(&p[0], &p[1], &p[2], &p[3], &p[4], in_range),
                    exact
                );
            }
            if let Some(s) = insphere_permanent_filter(&p[0], &p[1], &p[2], &p[3], &p[4]) {
                assert_eq!(s, exact);
            }
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

    /// [`orient3d_faces_avx2`] against [`orient3d_bounded`] face by face, on the hard cases
    /// (the first four points a tet, the fifth the walk's point) with the static bound, a
    /// tight one, none, and one equal to a face's |det| (which tells one ulp apart): a lane
    /// is undecided exactly where the scalar filter is (the same determinant bits), and with
    /// a bound that holds a decided lane has the exact sign.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn face_lanes_agree_with_the_one_face_filter() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let (mut decided, mut undecided) = (0, 0);
        for (i, p) in hard_cases(12000).enumerate() {
            let t = [&p[0], &p[1], &p[2], &p[3]];
            let face_det = |k: usize| {
                let mut q = t;
                q[k] = &p[4];
                let [a, b, c, d] = q;
                let (bx, by, bz) = (b[0] - a[0], b[1] - a[1], b[2] - a[2]);
                let (cx, cy, cz) = (c[0] - a[0], c[1] - a[1], c[2] - a[2]);
                let (dx, dy, dz) = (d[0] - a[0], d[1] - a[1], d[2] - a[2]);
                bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx)
            };
            // The last: a bound equal to one face's |det|, undecided only if the lane has the
            // same bits. (By `i % 5`: the hard cases vary with `i % 4` and `i % 6`.)
            let eps = [
                static_orient_bound(2.0),
                1e-3,
                f64::INFINITY,
                face_det(i % 4).abs(),
                face_det((i + 1) % 4).abs(),
            ][i % 5];
            // SAFETY: the CPU has AVX2.
            let (negative, open) = unsafe { orient3d_faces_avx2(t, &p[4], eps) };
            for k in 0..4 {
                let mut q = t;
                q[k] = &p[4];
                let [a, b, c, d] = q;
                let det = face_det(k);
                let lane_open = (open >> k) & 1 == 1;
                assert_eq!(lane_open, !(det.abs() > eps), "case {i}, face {k}");
                if lane_open {
                    undecided += 1;
                    assert_eq!((negative >> k) & 1, 0);
                } else {
                    decided += 1;
                    assert_eq!((negative >> k) & 1 == 1, det < 0.0, "case {i}, face {k}");
                    if i % 5 < 3 {
                        // A bound that holds: the exact sign.
                        let exact = orient3d_exact(a, b, c, d);
                        assert_eq!(orient3d_bounded(a, b, c, d, eps), exact);
                        assert_eq!(det < 0.0, exact < 0, "case {i}, face {k}");
                    }
                }
            }
        }
        assert!(
            decided > 10_000 && undecided > 10_000,
            "{decided} / {undecided}"
        );
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

    /// The local bound of [`reach_decides`] on the hard cases at scales from 2^-80 to 2^80,
    /// and with the z differences squashed to 1e-200 (products that underflow): where it
    /// decides, the sign is the exact one; it decides most of the generic cases in its range
    /// and nothing outside it.
    #[test]
    fn reach_bound_decides_only_exact_signs() {
        let cases: Vec<[[f64; 3]; 5]> = hard_cases(12000).collect();
        for k in [-80, -60, -20, 0, 20, 60, 80] {
            for squash in [false, true] {
                let scale = 2f64.powi(k);
                let (mut decided, mut generic) = (0, 0);
                for (i, p) in cases.iter().enumerate() {
                    let p = p.map(|q| {
                        let z = if squash { q[2] * 1e-200 } else { q[2] };
                        [q[0] * scale, q[1] * scale, z * scale]
                    });
                    let [a, b, c, d, e] = &p;
                    let (det, r2) = insphere_det_reach(a, b, c, d, e);
                    // Random points, neither rounded nor moved (see `hard_cases`).
                    let is_generic = i % 6 < 2 && i % 4 == 0;
                    generic += is_generic as usize;
                    if reach_decides(det, r2) {
                        decided += is_generic as usize;
                        assert_eq!(-sign(det), robust_insphere(p), "case {i} at 2^{k} {squash}");
                    }
                }
                // Differences up to 2 * 2^k: r2 up to 12 * 4^k, and over 1e-3 * 4^k.
                let in_range = k.abs() < 70;
                if in_range && !squash {
                    assert!(decided > generic / 2, "2^{k}: {decided} of {generic}");
                } else if !in_range {
                    assert_eq!(decided, 0, "2^{k} {squash}");
                }
            }
        }
    }

    /// The sign of Shewchuk's exact insphere (`robust`) in this module's convention.
    fn robust_insphere(p: [[f64; 3]; 5]) -> i32 {
        let v = robust::insphere(c3(&p[0]), c3(&p[1]), c3(&p[2]), c3(&p[3]), c3(&p[4]));
        (v < 0.0) as i32 - (v > 0.0) as i32
    }

    /// The fixed-width integer evaluation gives the sign of the expansion arithmetic on
    /// generic points, exact ties (co-spherical integer and dyadic points, any scale), near
    /// ties (lattices of 0.1 steps, whose doubles are not co-spherical, and one-ulp moves of
    /// co-spherical points), and declines (None) only where the coordinates span too many
    /// binary orders of magnitude.
    #[test]
    fn fixed_width_insphere_matches_the_expansion_arithmetic() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut decided = [0usize; 3];
        let check = |p: [[f64; 3]; 5], must_decide: bool, decided: &mut [usize; 3]| {
            let want = robust_insphere(p);
            match fixed::insphere_sign(&p[0], &p[1], &p[2], &p[3], &p[4]) {
                Some(s) => {
                    assert_eq!(s, want, "points {p:?}");
                    decided[(s + 1) as usize] += 1;
                }
                None => assert!(!must_decide, "declined {p:?}"),
            }
            // The public predicate (filters, then this) agrees too.
            assert_eq!(
                insphere(&p[0], &p[1], &p[2], &p[3], &p[4]),
                want,
                "points {p:?}"
            );
        };
        // Generic points in the unit cube.
        for _ in 0..2000 {
            let p: [[f64; 3]; 5] =
                std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)));
            check(p, true, &mut decided);
        }
        // Five of the 27 points of a 3x3x3 block of a lattice with a random origin and a step
        // of 0.1, 1/3 or 2^-5: many co-spherical in the reals, near-ties in doubles.
        for t in 0..6000 {
            let step = [0.1, 1.0 / 3.0, 0.03125][t % 3];
            let o: [f64; 3] = std::array::from_fn(|_| (rng.random_range(0..40) as f64) * step);
            let p: [[f64; 3]; 5] = std::array::from_fn(|_| {
                std::array::from_fn(|k| o[k] + rng.random_range(0..3) as f64 * step)
            });
            // Repeated points make the determinant zero: fine for the comparison.
            check(p, true, &mut decided);
        }
        // Exactly co-spherical points: integer points on the sphere of radius 5 or 3 about
        // an integer centre, scaled by a power of two, and the same with one coordinate
        // moved by one ulp.
        let on5: Vec<[f64; 3]> = {
            let mut v = Vec::new();
            for x in -5i32..=5 {
                for y in -5i32..=5 {
                    for z in -5i32..=5 {
                        if x * x + y * y + z * z == 25 {
                            v.push([x as f64, y as f64, z as f64]);
                        }
                    }
                }
            }
            v
        };
        for t in 0..3000 {
            let scale = 2f64.powi(rng.random_range(-30..30));
            let c: [f64; 3] = std::array::from_fn(|_| rng.random_range(-20..20) as f64);
            let mut p: [[f64; 3]; 5] = std::array::from_fn(|_| {
                let q = on5[rng.random_range(0..on5.len())];
                std::array::from_fn(|k| (c[k] + q[k]) * scale)
            });
            if t % 2 == 1 {
                let (i, k) = (rng.random_range(0..5), rng.random_range(0..3));
                if p[i][k] == 0.0 {
                    // One ulp from zero is a subnormal: a span beyond the fixed width.
                    continue;
                }
                p[i][k] = if rng.random_bool(0.5) {
                    p[i][k].next_up()
                } else {
                    p[i][k].next_down()
                };
            }
            check(p, true, &mut decided);
        }
        assert!(decided.iter().all(|&n| n > 500), "signs seen: {decided:?}");
        // Spans beyond the fixed width are declined, and the fallback still decides.
        let tiny = [
            [1e-30, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.5, 0.5, 0.5],
        ];
        assert_eq!(
            fixed::insphere_sign(&tiny[0], &tiny[1], &tiny[2], &tiny[3], &tiny[4]),
            None
        );
        check(tiny, false, &mut decided);
    }

    /// The native-width path and the limb path agree on integer points whose
    /// differences fit both (up to 2^62), generic and co-spherical.
    #[test]
    fn native_and_wide_integer_paths_agree() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut signs = [0usize; 3];
        for t in 0..20000 {
            let bits = rng.random_range(1..61);
            let q: [[i128; 3]; 5] = if t % 2 == 0 {
                std::array::from_fn(|_| {
                    std::array::from_fn(|_| rng.random_range(0..(1i128 << bits)))
                })
            } else {
                // Corners and face centres of a box: many on one sphere.
                let s = 1i128 << rng.random_range(0..59);
                std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(0..3) * s))
            };
            let small = fixed::insphere_sign_small(&q);
            assert_eq!(small, fixed::insphere_sign_wide(&q), "{q:?}");
            signs[(small + 1) as usize] += 1;
        }
        assert!(signs.iter().all(|&n| n > 1000), "signs seen: {signs:?}");
    }

    /// The limb arithmetic against i128 on values that fit, and products that carry across
    /// limbs.
    #[test]
    fn wide_integers_add_subtract_and_multiply_exactly() {
        use fixed::{Fixed, fixed_add, fixed_mul, fixed_signum, fixed_sub};
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let w = fixed::fixed_from_i128::<8>;
        let sg = |x: Fixed<8>| fixed_signum(&x);
        for _ in 0..20000 {
            let bits = rng.random_range(1..62);
            let x: i128 = rng.random_range(-(1i128 << bits)..(1i128 << bits));
            let y: i128 = rng.random_range(-(1i128 << bits)..(1i128 << bits));
            assert_eq!(sg(fixed_add(&w(x), &w(y))), (x + y).signum() as i32);
            assert_eq!(sg(fixed_sub(&w(x), &w(y))), (x - y).signum() as i32);
            assert_eq!(sg(fixed_mul(&w(x), &w(y))), (x * y).signum() as i32);
            // (x y) - (x y) = 0 and x y + (-x) y = 0 through the wide path.
            let xy = fixed_mul(&w(x), &w(y));
            assert_eq!(sg(fixed_sub(&xy, &w(x * y))), 0);
            assert_eq!(sg(fixed_add(&xy, &fixed_mul(&w(-x), &w(y)))), 0);
        }
        // (2^100 - 1)^2 = 2^200 - 2^101 + 1: compare with the sum of its parts.
        let m = w((1i128 << 100) - 1);
        let sq = fixed_mul(&m, &m);
        let two100 = w(1i128 << 100);
        let parts = fixed_add(
            &fixed_sub(&fixed_mul(&two100, &two100), &fixed_mul(&two100, &w(2))),
            &w(1),
        );
        assert_eq!(sg(fixed_sub(&sq, &parts)), 0);
        assert_eq!(sg(fixed_sub(&sq, &fixed_add(&parts, &w(1)))), -1);
        // Negative products near the top of the width: -(2^250) * 2^250 = -2^500.
        let big = fixed_mul(&w(1i128 << 125), &w(1i128 << 125));
        let neg = fixed_mul(&fixed_sub(&w(0), &big), &big);
        assert_eq!(sg(neg), -1);
        assert_eq!(sg(fixed_add(&neg, &fixed_mul(&big, &big))), 0);
    }
}
