//! The walk: a stochastic visibility walk from the last new tet to the tet that holds the next
//! vertex, checked under lock in the parallel phase ([`Worker::locate`]).

use super::store::{DEAD, Shared};
use super::triangulation::NONE;
use super::worker::{Fail, Worker};
#[cfg(target_arch = "x86_64")]
use crate::predicates::orient3d_faces_avx2;

impl Worker {
    /// A live tet to start a walk from: the last one made, or (in parallel, when another
    /// worker has removed it) one of the slots before it, which this worker filled recently.
    /// In parallel the tet is not locked, so it may be gone by the time the walk reads it;
    /// the walk's end is checked under lock.
    pub(super) fn start<const PAR: bool>(&self, sh: &Shared) -> Option<u32> {
        let len = sh.tets.len() as u32;
        let tries = if PAR { 256 } else { 1 };
        (0..tries)
            .map(|i| (self.last + len - i % len) % len)
            .find(|&t| sh.tets[t as usize].mark() != DEAD)
    }

    /// Stochastic visibility walk from `t` towards `p`; returns the tet where no face sees
    /// `p` from behind. In parallel the tets are read without locks: another worker may be
    /// changing them, so the result is only a candidate (see [`Worker::locate`]).
    pub(super) fn walk<const PAR: bool>(
        &mut self,
        sh: &Shared,
        t: u32,
        p: &[f64; 3],
    ) -> Option<u32> {
        #[cfg(target_arch = "x86_64")]
        {
            if self.avx2 {
                // SAFETY: the CPU has AVX2 (`avx2` is only set when it does).
                return unsafe { self.walk_avx2::<PAR>(sh, t, p) };
            }
        }
        self.walk_body::<PAR, false>(sh, t, p)
    }

    /// [`Worker::walk`] with AVX2: the four faces of a tet are tested together
    /// ([`orient3d_faces_avx2`]), then the first face in the walk's random order that sees
    /// `p` from behind is taken without a branch per face (each face's sign goes either way
    /// about as often). Where the static bound decides every open face, the same face is
    /// chosen as one by one; where it does not, a decided face that sees `p` goes first (see
    /// the body), so the walk may differ there, and ends in a tet containing `p` all the same.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) fn walk_avx2<const PAR: bool>(
        &mut self,
        sh: &Shared,
        t: u32,
        p: &[f64; 3],
    ) -> Option<u32> {
        self.walk_body::<PAR, true>(sh, t, p)
    }

    #[inline(always)]
    pub(super) fn walk_body<const PAR: bool, const AVX2: bool>(
        &mut self,
        sh: &Shared,
        mut t: u32,
        p: &[f64; 3],
    ) -> Option<u32> {
        let mut prev = NONE;
        let max_steps = if PAR {
            (64 + 4 * sh.tets.len()).min(1 << 16)
        } else {
            64 + 4 * sh.tets.len()
        };
        for step in 0..max_steps {
            let tet = &sh.tets[t as usize];
            let (tv, tn) = (tet.verts(), tet.nbrs());
            // An infinite tet (rare; with AVX2 it is found where its faces are undecided, off
            // the common path): entered through its hull face, which sees `p` from behind, it
            // is in conflict with `p` (strictly beyond the face), the walk's end; at the
            // start, the walk goes on from the finite tet across that face.
            macro_rules! infinite_tet {
                () => {
                    if step > 0 {
                        return Some(t);
                    }
                    let f = tn[sh.inf_at(tv)];
                    if f == NONE {
                        return None;
                    }
                    t = f;
                    continue;
                };
            }
            let r = (self.rng.next() & 3) as usize;
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                // The faces the walk may cross: not the hull, not back.
                let open = (0..4).fold(0u32, |m, k| {
                    m | (((tn[k] != NONE) & (tn[k] != prev)) as u32) << k
                });
                let eps = sh.orient_eps(tv);
                // SAFETY: `AVX2` is set only by `walk_avx2`, which runs only where the CPU
                // has AVX2.
                let (negative, undecided) =
                    unsafe { orient3d_faces_avx2(tv.map(|x| sh.p(x)), p, eps) };
                let mut seen = negative & open;
                // The open faces the static bound leaves undecided (ties, near-flat tets, the
                // hull; on a CAD PoNQ's v*, points coplanar with faces of flat regions: 30% of
                // the steps on the mesher's 109k v*) get the exact test only where no decided
                // face sees `p` from behind: the walk goes through a face that does, decided
                // or not, so it is a visibility walk (which ends in a Delaunay
                // triangulation), and it ends only where no face does, exactly. (Exact tests
                // of every undecided face, to take the first face of the random order as one
                // by one: 1.8 per insertion on those v*; this way 0.6, and 3% fewer steps.)
                let pending = undecided & open;
                if pending != 0 && seen == 0 {
                    // An infinite tet's bound is infinite: every face undecided.
                    if !sh.real(tv) {
                        infinite_tet!();
                    }
                    for k in 0..4 {
                        if (pending >> k) & 1 == 1 && sh.face_sees(tv, k, p) < 0 {
                            seen |= 1 << k;
                        }
                    }
                }
                // The faces in the order r, r + 1, ...: bit j is face (r + j) & 3.
                let rotated = ((seen >> r) | (seen << (4 - r))) & 0xF;
                if rotated == 0 {
                    debug_assert!(
                        PAR || (0..4).all(|k| sh.face_sees(tv, k, p) >= 0),
                        "the walk ended outside tet {t}"
                    );
                    return Some(t);
                }
                prev = t;
                t = tn[(r + rotated.trailing_zeros() as usize) & 3];
                continue;
            }
            if !sh.real(tv) {
                infinite_tet!();
            }
            let mut next = NONE;
            for j in 0..4 {
                let k = (r + j) & 3;
                let nb = tn[k];
                if nb == NONE || nb == prev {
                    continue;
                }
                if sh.face_sees(tv, k, p) < 0 {
                    next = nb;
                    break;
                }
            }
            if next == NONE {
                // `prev` was skipped: p is strictly in front of the face we came through.
                debug_assert!(
                    PAR || (0..4).all(|k| sh.face_sees(tv, k, p) >= 0),
                    "the walk ended outside tet {t}"
                );
                return Some(t);
            }
            prev = t;
            t = next;
        }
        None
    }

    /// A tet containing vertex `v`, returned locked. In parallel, the walk's end is locked and
    /// then checked (live, `v` on no face's negative side); a tet that changed under the walk
    /// makes it walk on from there.
    pub(super) fn locate<const PAR: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
    ) -> std::result::Result<u32, Fail> {
        let p = sh.pos[v as usize];
        let mut t = self.start::<PAR>(sh).ok_or(Fail::Busy)?;
        if !PAR {
            if let Some(end) = self.walk::<PAR>(sh, t, &p) {
                return Ok(end);
            }
            // Safety net (never expected): scan for a tet that holds `p`.
            return Ok((0..sh.tets.len() as u32)
                .find(|&t| {
                    let tet = &sh.tets[t as usize];
                    tet.mark() != DEAD && sh.holds(tet.verts(), &p)
                })
                .unwrap_or(t));
        }
        for _ in 0..4 {
            t = self.walk::<PAR>(sh, t, &p).ok_or(Fail::Busy)?;
            if !self.try_lock::<PAR>(sh, t) {
                // Keep the progress: the next walk starts here.
                self.last = t;
                return Err(Fail::Busy);
            }
            let tet = &sh.tets[t as usize];
            if tet.mark() != DEAD && sh.holds(tet.verts(), &p) {
                return Ok(t);
            }
            self.unlock_all::<PAR>(sh);
        }
        Err(Fail::Busy)
    }
}
