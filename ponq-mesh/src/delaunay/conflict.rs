//! The geometric tests of the insertion on the tet store: whether a tet holds a point, sees
//! it across a face, or is in conflict with a vertex (its circumsphere contains it; CGAL's
//! rule for the infinite tets), on top of [`crate::predicates`].

use super::store::{APEX_FACE, Shared};
#[cfg(target_arch = "x86_64")]
use crate::predicates::insphere_static4_avx2;
use crate::predicates::{
    in_conflict_bounded, in_conflict_past_static, insphere_static_lanes, orient3d, orient3d_bounded,
};
use crate::vec3;

impl Shared<'_> {
    /// The orientation of infinite tet `tv` with its infinite vertex replaced by the real
    /// point `p`: positive where `p` is strictly beyond its finite face (the hull face).
    #[inline]
    pub(super) fn beyond_hull_face(&self, tv: [u32; 4], p: &[f64; 3]) -> i32 {
        let k = self.inf_at(tv);
        let q = [0, 1, 2, 3].map(|j| if j == k { p } else { self.p(tv[j]) });
        orient3d(q[0], q[1], q[2], q[3])
    }

    /// Whether tet `tv` holds the real point `p`: a finite tet, in its closed volume (no face
    /// sees `p` from behind); an infinite tet, strictly beyond its hull face (so that it is
    /// in conflict with `p`).
    pub(super) fn holds(&self, tv: [u32; 4], p: &[f64; 3]) -> bool {
        if self.real(tv) {
            (0..4).all(|k| self.face_sees(tv, k, p) >= 0)
        } else {
            self.beyond_hull_face(tv, p) > 0
        }
    }

    /// Whether infinite tet `tv` is in conflict with vertex `v` (CGAL's rule for its
    /// infinite vertex): `v` strictly beyond the tet's hull face; or on the face's plane and
    /// strictly inside its circumcircle, ties broken by the perturbation of the finite tets.
    /// On the plane this is the test of a finite tet through the face and any point `w` on
    /// the inner side: its circumsphere meets the plane in the face's circumcircle, and in
    /// the perturbation `w`'s term vanishes (`v` on the face's plane) while the others are
    /// orientations of planes that are the face's, so they depend on `w`'s side only (the
    /// finite tet across the face gives the same answer; this needs no look at it, so no
    /// lock).
    #[cold]
    #[inline(never)]
    pub(super) fn infinite_conflict(&self, tv: [u32; 4], v: u32) -> bool {
        let p = self.p(v);
        let o = self.beyond_hull_face(tv, p);
        if o != 0 {
            return o > 0;
        }
        let k = self.inf_at(tv);
        let f = APEX_FACE[k].map(|q| *self.p(tv[q]));
        // A point well inside: the face's first vertex moved along an axis by the face's size
        // plus the coordinate's magnitude (so that the coordinate does change, however far
        // from 0 the face is), the axis nearest the face's normal first (as computed; `w` has
        // the face's coordinates but one, which keeps the exact stages on their fast paths),
        // whichever way is exactly on the inner side (orientation negative with `w` in the
        // infinite vertex's place). Some axis is not parallel to the face, and one of its two
        // ways is inside.
        let (u, w) = (vec3::sub(f[1], f[0]), vec3::sub(f[2], f[0]));
        let n = vec3::cross(u, w);
        let size = (0..3)
            .map(|j| u[j].abs().max(w[j].abs()))
            .fold(0.0f64, f64::max);
        let mut axes = [0, 1, 2];
        axes.sort_by(|&x, &y| n[y].abs().total_cmp(&n[x].abs()));
        let inner = axes
            .iter()
            .flat_map(|&j| {
                let d = size + f[0][j].abs();
                [d, -d].map(|d| {
                    let mut w = f[0];
                    w[j] += d;
                    w
                })
            })
            .find(|w| {
                let q = [0, 1, 2, 3].map(|j| if j == k { w } else { self.p(tv[j]) });
                orient3d(q[0], q[1], q[2], q[3]) < 0
            });
        let Some(w) = inner else {
            // Only for a flat hull face, which the triangulation never has.
            unreachable!("no point inside the hull face of {tv:?}");
        };
        // The finite tet: `w` in the infinite vertex's place, two vertices swapped to make it
        // positive; `w` ranks after every vertex (its term vanishes either way).
        let mut ft = [0, 1, 2, 3].map(|j| if j == k { &w } else { self.p(tv[j]) });
        let rank = |x: u32| self.rank.get(x as usize).copied().unwrap_or(x);
        let mut ranks = [0, 1, 2, 3].map(|j| if j == k { u32::MAX } else { rank(tv[j]) });
        // The first two positions other than `k`.
        let (a, b) = if k <= 1 { (1 - k, 2) } else { (0, 1) };
        ft.swap(a, b);
        ranks.swap(a, b);
        in_conflict_bounded(ft, || (ranks, rank(v)), p, f64::INFINITY)
    }

    /// The orientation of tet `tv` with its vertex `k` replaced by the real point `p`.
    #[inline]
    pub(super) fn face_sees(&self, tv: [u32; 4], k: usize, p: &[f64; 3]) -> i32 {
        let mut q = [self.p(tv[0]), self.p(tv[1]), self.p(tv[2]), self.p(tv[3])];
        q[k] = p;
        orient3d_bounded(q[0], q[1], q[2], q[3], self.orient_eps(tv))
    }

    /// The static orientation bound for tet `tv` with one vertex replaced by a real point:
    /// [`Shared::static_orient_eps`] when all its vertices are real, else none.
    #[inline(always)]
    pub(super) fn orient_eps(&self, tv: [u32; 4]) -> f64 {
        if self.real(tv) {
            self.static_orient_eps
        } else {
            f64::INFINITY
        }
    }

    /// The static conflict tests of four tets (by their vertices) against vertex `v`, one per
    /// lane ([`insphere_static_lanes`]); with `AVX2` ([`insphere_static4_avx2`]) the points go
    /// from `pos` into the lanes with no copy in between. The same bits either way.
    #[inline(always)]
    pub(super) fn conflict_lanes<const AVX2: bool>(
        &self,
        ids: &[[u32; 4]; 4],
        v: u32,
        eps: &[f64; 4],
    ) -> ([i32; 4], [f64; 4]) {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: `AVX2` is set only by `Worker::insert_avx2`, which runs only where the
            // CPU has AVX2.
            return unsafe { insphere_static4_avx2(self.pos, ids, self.p(v), eps) };
        }
        let pts = ids.map(|tv| tv.map(|x| *self.p(x)));
        insphere_static_lanes(&pts, self.p(v), eps)
    }

    /// Whether tet `tv` is in conflict with vertex `v` (its circumsphere strictly contains
    /// `v`, ties broken symbolically), once the static bound of [`insphere_static_lanes`] has
    /// not decided, from the determinant it computed (rare: ties, and the infinite tets,
    /// whose bound is infinite: [`Shared::infinite_conflict`]).
    #[inline(never)]
    pub(super) fn conflicts_past_static(&self, tv: [u32; 4], v: u32, det: f64) -> bool {
        if !self.real(tv) {
            return self.infinite_conflict(tv, v);
        }
        // Ties are broken by the input numbering, not the insertion order, so that the
        // result does not depend on how the points are scheduled.
        let rank = |x: u32| self.rank.get(x as usize).copied().unwrap_or(x);
        in_conflict_past_static(
            [self.p(tv[0]), self.p(tv[1]), self.p(tv[2]), self.p(tv[3])],
            || (tv.map(rank), rank(v)),
            self.p(v),
            det,
        )
    }
}
