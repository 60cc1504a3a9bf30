//! The cavity: one Bowyer-Watson insertion ([`Worker::insert`]): the walk's tet, the tets in
//! conflict with the new vertex found from it (conflict tests four at a time), the boundary's
//! faces joined to the vertex, the new tets linked; or a back-off that leaves nothing changed.

use std::sync::atomic::Ordering::Relaxed;

use super::store::{DEAD, NO_STAMP, Shared, Stamps, back_face, make_room, push_if_in_room};
use super::triangulation::NONE;
use super::worker::{Fail, Worker};
use crate::predicates::orient3d;

impl Worker {
    /// Undoes the stamps and locks of a failed insertion. Its stamps are on the tets of the
    /// cavity found so far, on those still to look around (the stack), on the tets next to
    /// them (the boundary) and on those waiting for their conflict test (`waiting`, the
    /// neighbour of each): a neighbour is stamped only after it is locked, and then waits for
    /// its test and goes to the stack or to the boundary. (A list of the stamped tets kept as
    /// they were stamped: a store per conflict test.)
    pub(super) fn back_off<const PAR: bool>(
        &mut self,
        sh: &Shared,
        waiting: &[(u32, u8, u32)],
        fail: Fail,
    ) -> Fail {
        let next_to = self.boundary.iter().map(|b| b.2).filter(|&t| t != NONE);
        let pending = self.stack.iter().map(|e| e.0);
        let waiting = waiting.iter().map(|w| w.2);
        for t in self
            .cavity
            .iter()
            .copied()
            .chain(pending)
            .chain(next_to)
            .chain(waiting)
        {
            sh.tets[t as usize].set_mark(NO_STAMP);
        }
        self.unlock_all::<PAR>(sh);
        fail
    }

    /// The conflict tests of the cavity search waiting in `lanes` (at most four; `ids` and
    /// `eps` hold their tets' vertices and static bounds in the same lanes, any tets in the
    /// lanes after them): a tet in conflict with `v` joins the cavity (the stack), any other
    /// gives a boundary face.
    #[inline(always)]
    pub(super) fn test_lanes<const AVX2: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
        stamps: Stamps,
        lanes: &[(u32, u8, u32)],
        ids: &[[u32; 4]; 4],
        eps: &[f64; 4],
    ) {
        let (signs, dets) = sh.conflict_lanes::<AVX2>(ids, v, eps);
        make_room(&mut self.stack, lanes.len());
        make_room(&mut self.boundary, lanes.len());
        for (r, &(c, k, nb)) in lanes.iter().enumerate() {
            let nt = &sh.tets[nb as usize];
            let conflict = if signs[r] != 0 {
                signs[r] > 0
            } else {
                sh.conflicts_past_static(ids[r], v, dets[r])
            };
            // From here on without a branch on `conflict` (in a cavity search it is true
            // about as often as false): the mark is a select, the tet goes to the stack
            // or to the boundary by a write after the last item that is kept or not.
            nt.set_mark(if conflict {
                stamps.in_cavity
            } else {
                stamps.outside
            });
            let j = back_face(nt, c);
            // SAFETY: room for one item per lane was made above.
            unsafe {
                push_if_in_room(&mut self.stack, (nb, j), conflict);
                push_if_in_room(&mut self.boundary, (c, k, nb, j), !conflict);
            }
        }
    }

    /// Inserts vertex `v`, or backs off leaving the triangulation unchanged. On x86-64 CPUs
    /// with AVX2 the insertion is compiled for it ([`Worker::insert_avx2`]); the same code
    /// otherwise.
    #[inline]
    pub(super) fn insert<const PAR: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
    ) -> std::result::Result<(), Fail> {
        #[cfg(target_arch = "x86_64")]
        {
            if self.avx2 {
                // SAFETY: the CPU has AVX2 (`avx2` is only set when it does).
                return unsafe { self.insert_avx2::<PAR>(sh, v) };
            }
        }
        self.insert_body::<PAR, false>(sh, v)
    }

    /// [`Worker::insert`] with AVX2: the cavity search's conflict tests
    /// ([`insphere_static_lanes`]) then run four to a register. Measured side by side with
    /// the build before the lanes (`delaunay_bench`, six alternating rounds, the mesher's 109k
    /// v*, insertion stage): one thread 2.44 -> 2.22 us per point, two threads 1.34 -> 1.28;
    /// in other rounds the lanes without AVX2 (SSE2 pairs) gave 2.47 -> 2.29 and 1.36 -> 1.35,
    /// AVX2 without the lanes 2.44 -> 2.35 and 1.34 -> 1.35. Same results (no fused
    /// operations). Since then the points go straight from `pos` into the lanes
    /// ([`insphere_static4_avx2`], see [`Shared::conflict_lanes`]): one thread 2-4% faster;
    /// and the lanes are filled four at a time from any cavity tets (they held the three
    /// other neighbours of one cavity tet, so a fourth of the work was idle): one thread
    /// 8-9% faster.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub(super) fn insert_avx2<const PAR: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
    ) -> std::result::Result<(), Fail> {
        self.insert_body::<PAR, true>(sh, v)
    }

    /// The insertion; `AVX2` only where the CPU has it (see [`Shared::conflict_lanes`]).
    #[inline(always)]
    pub(super) fn insert_body<const PAR: bool, const AVX2: bool>(
        &mut self,
        sh: &Shared,
        v: u32,
    ) -> std::result::Result<(), Fail> {
        let t = self.locate::<PAR>(sh, v)?;
        let stamps = Stamps::of(v);
        self.cavity.clear();
        self.boundary.clear();
        self.stack.clear();
        self.later.clear();
        // Each stack entry keeps the face it was entered through (4: none), which leads back
        // into the cavity and needs no look.
        self.stack.push((t, 4));
        sh.tets[t as usize].set_mark(stamps.in_cavity);
        // The conflict tests wait here until four are ready, then run together
        // ([`Shared::conflict_lanes`]): lane r tests neighbour `ids[r]` of cavity tet `c`
        // across its face `k` (`lanes[r] = (c, k, neighbour)`). The cavity search goes on
        // from the other cavity tets meanwhile; the cavity is the same in any order.
        let mut lanes = [(NONE, 0u8, NONE); 4];
        let mut ids = [[0u32; 4]; 4];
        let mut eps = [f64::INFINITY; 4];
        let mut ready = 0usize;
        loop {
            while let Some((c, entry)) = self.stack.pop() {
                self.cavity.push(c);
                let cn = sh.tets[c as usize].nbrs();
                // Touch the four neighbours together so that their cache misses overlap.
                let _touch =
                    cn.map(|nb| sh.tets.get(nb as usize).map_or(0, |t| t.mark.load(Relaxed)));
                // The other faces: three after the entry face, or all four of the first tet
                // (a count instead of a skip, which would be a branch on the data).
                let (first, count) = if entry == 4 { (0, 4) } else { (entry + 1, 3) };
                for r in 0..count {
                    let k = (first + r) & 3;
                    let nb = cn[k as usize];
                    if nb == NONE {
                        // Never: every face has a tet across it, infinite tets included.
                        self.boundary.push((c, k, NONE, 0));
                        continue;
                    }
                    // (One thread takes no locks: `try_lock::<false>` is `true`.)
                    if !self.try_lock::<PAR>(sh, nb) {
                        return Err(self.back_off::<PAR>(sh, &lanes[..ready], Fail::Busy));
                    }
                    let nt = &sh.tets[nb as usize];
                    let mark = nt.mark();
                    if mark == stamps.in_cavity {
                        continue;
                    }
                    if mark == stamps.outside {
                        self.boundary.push((c, k, nb, back_face(nt, c)));
                        continue;
                    }
                    if mark == stamps.waiting {
                        // Waiting for its test, from another cavity tet: a boundary face if
                        // it is not in conflict, known at the end.
                        self.later.push((c, k, nb));
                        continue;
                    }
                    nt.set_mark(stamps.waiting);
                    let tv = nt.verts();
                    lanes[ready] = (c, k, nb);
                    ids[ready] = tv;
                    eps[ready] = if sh.real(tv) {
                        sh.static_eps
                    } else {
                        f64::INFINITY
                    };
                    ready += 1;
                    if ready == 4 {
                        self.test_lanes::<AVX2>(sh, v, stamps, &lanes, &ids, &eps);
                        ready = 0;
                    }
                }
            }
            if ready == 0 {
                break;
            }
            // Fewer than four (the lanes after them hold earlier tests: computed, not read).
            self.test_lanes::<AVX2>(sh, v, stamps, &lanes[..ready], &ids, &eps);
            ready = 0;
        }
        for i in 0..self.later.len() {
            let (c, k, nb) = self.later[i];
            let nt = &sh.tets[nb as usize];
            if nt.mark() == stamps.outside {
                self.boundary.push((c, k, nb, back_face(nt, c)));
            }
        }
        // Slots: the cavity's, then free ones, then fresh ones; all taken before any change.
        let extra = self.boundary.len().saturating_sub(self.cavity.len());
        self.taken.clear();
        let mut skipped = 0usize;
        while self.taken.len() < extra {
            if self.free.len() > skipped {
                let i = self.free.len() - 1 - skipped;
                let f = self.free[i];
                // A walker of another worker may hold a free slot for a moment.
                if self.try_lock::<PAR>(sh, f) {
                    self.free.swap_remove(i);
                    self.taken.push(f);
                } else {
                    skipped += 1;
                }
            } else if self.fresh.0 < self.fresh.1 || self.refill(sh) {
                let f = self.fresh.0;
                // A never-used slot of this worker's: no walker reaches it before a tet is
                // written there, so nobody else locks it (no compare-exchange).
                if PAR {
                    sh.locks[f as usize].store(self.id, Relaxed);
                    self.held.push(f);
                }
                self.fresh.0 += 1;
                self.taken.push(f);
            } else {
                self.free.extend_from_slice(&self.taken);
                self.taken.clear();
                return Err(self.back_off::<PAR>(sh, &[], Fail::NoSpace));
            }
        }
        // New tets: one per boundary face, the cavity tet's vertex k replaced by v. Read the
        // cavity tets' vertices before their slots are reused.
        self.new_tets.clear();
        make_room(&mut self.new_tets, self.boundary.len());
        for &(c, k, _, _) in &self.boundary {
            let old = sh.tets[c as usize].verts();
            // A select per position rather than a store at position k: the array is written
            // whole, so reading it back does not stall on store forwarding (measured: the
            // store-then-load of `tv[k] = v` cost ~8% of the insertion).
            let tv = [0, 1, 2, 3].map(|q| if q == k as usize { v } else { old[q] });
            // SAFETY: room for one item per boundary face was made above.
            unsafe { push_if_in_room(&mut self.new_tets, (tv, 0, k), true) };
        }
        let ncav = self.cavity.len();
        for i in 0..self.new_tets.len() {
            self.new_tets[i].1 = if i < ncav {
                self.cavity[i]
            } else {
                self.taken[i - ncav]
            };
        }
        for i in self.new_tets.len()..ncav {
            let c = self.cavity[i];
            sh.tets[c as usize].set_mark(DEAD);
            self.free.push(c);
        }
        for i in 0..self.new_tets.len() {
            let (tv, id, k) = self.new_tets[i];
            let (_, _, nb, j) = self.boundary[i];
            let tet = &sh.tets[id as usize];
            for q in 0..4 {
                tet.v[q].store(tv[q], Relaxed);
            }
            tet.set_mark(NO_STAMP);
            tet.set_nbr(k as usize, nb);
            if nb != NONE {
                sh.tets[nb as usize].set_nbr(j as usize, id);
            }
            debug_assert!(
                !sh.real(tv) || orient3d(sh.p(tv[0]), sh.p(tv[1]), sh.p(tv[2]), sh.p(tv[3])) > 0,
                "flat or inverted tet created inserting {v}: {tv:?} cavity {} boundary {}",
                self.cavity.len(),
                self.boundary.len()
            );
        }
        // Link the new tets to each other. They all have `v` as apex over a boundary face,
        // and the faces (ordered by `APEX_FACE`, `v` on their positive side) orient the
        // cavity boundary consistently: two new tets are neighbours exactly where one face
        // has the directed edge (x, y) and the other (y, x).
        if !self.link_small(sh) {
            self.link_hashed(sh);
            self.large_cavities += 1;
        }
        self.last = self.new_tets[0].1;
        // Let go: the cavity slots (reused or dead), their neighbours, the new slots.
        self.unlock_all::<PAR>(sh);
        Ok(())
    }
}
