//! Face scores of the minimum cut (SPEC section 6, step 3).
//!
//! `S(T) = h * S_Q(T) + (S_n(T) / 1.5)^2` with `S_Q = sum_{i != j} Q_i(v_j)` over the face's
//! vertices (normalised quadrics) and `S_n = sum_i arccos(n_T . n_i)` where `n_T` is the unit
//! normal of the face oriented from the tet that would be inside to the one that would be
//! outside. Low score = likely surface face.

use crate::complex::TetComplex;

/// Weight of the normal term: `(S_n / NORMAL_SCALE)^2`.
pub const NORMAL_SCALE: f64 = 1.5;

/// Scores of face `k` of tet `t`: `(out_of_t, into_t)`, i.e. the cost of the face being on the
/// surface with `t` inside (normal pointing out of `t`), and with `t` outside.
pub fn face_scores(cx: &TetComplex, t: u32, k: usize) -> (f64, f64) {
    let f = cx.outward_face(t, k);
    let [a, b, c] = f.map(|v| *cx.pos(v));
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let w = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let mut n = [
        u[1] * w[2] - u[2] * w[1],
        u[2] * w[0] - u[0] * w[2],
        u[0] * w[1] - u[1] * w[0],
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 {
        n = n.map(|x| x / len);
    }
    let mut sq = 0.0;
    for &i in &f {
        let q = &cx.quadrics[i as usize];
        for &j in &f {
            if i != j {
                sq += q.eval(*cx.pos(j)).max(0.0);
            }
        }
    }
    let mut sn_out = 0.0;
    let mut sn_in = 0.0;
    for &i in &f {
        let ni = &cx.normals[i as usize];
        let d = (n[0] * ni[0] + n[1] * ni[1] + n[2] * ni[2]).clamp(-1.0, 1.0);
        let ang = d.acos();
        sn_out += ang;
        sn_in += std::f64::consts::PI - ang;
    }
    let base = cx.h * sq;
    (
        base + (sn_out / NORMAL_SCALE).powi(2),
        base + (sn_in / NORMAL_SCALE).powi(2),
    )
}

/// Score of face `k` of `t` with `t` inside (normal pointing out of `t`).
#[inline]
pub fn score_out_of(cx: &TetComplex, t: u32, k: usize) -> f64 {
    face_scores(cx, t, k).0
}
