//! Linking a cavity's new tets to each other: by local vertex numbers for a small cavity
//! boundary ([`Worker::link_small`]), by a directed-edge hash table for any
//! ([`Worker::link_hashed`]).

use super::store::{APEX_FACE, FACE_EDGES, Shared};
use super::triangulation::NONE;
use super::worker::{EdgeSlot, SMALL_CAVITY, Worker};

/// The key of the directed edge `x -> y`.
#[inline(always)]
pub(super) fn edge_key(x: u32, y: u32) -> u64 {
    ((x as u64) << 32) | y as u64
}

impl Worker {
    /// Links the new tets of a cavity whose boundary has at most [`SMALL_CAVITY`] vertices
    /// (almost every cavity), as HXT does (Marot et al. 2019): the boundary vertices get local
    /// numbers, each directed edge `x -> y` of a boundary face enters its new tet at
    /// `map[x][y]`, then each tet reads its neighbour across `x -> y` at `map[y][x]`. No
    /// hashing, no probing and no branch on the data. Returns `false` (nothing changed) for a
    /// larger boundary.
    ///
    /// The local numbers follow the order of first visit. Numbering in one pass (read the
    /// vertex's number, give the next one if it has none) made every step wait for the
    /// store of an earlier step to the same vertex: this function held 10% of a one-thread
    /// insertion's samples. Here each vertex's first slot is found by stores alone, the
    /// count of first visits is a chain of one-cycle additions, and every other read is
    /// independent: 8% of the samples, the insertion stage 2-5% faster (measured side by
    /// side, `docs/meshing.md`).
    pub(super) fn link_small(&mut self, sh: &Shared) -> bool {
        const L: usize = SMALL_CAVITY;
        // A triangulated sphere with V vertices has 2V - 4 faces, so at most this many slots
        // (three per face), each below `u8::MAX`.
        const SLOTS: usize = 3 * (2 * L - 4);
        const { assert!(SLOTS < u8::MAX as usize) };
        let faces = self.new_tets.len();
        if faces > 2 * L - 4 {
            return false;
        }
        if self.local_id.len() < sh.pos.len() {
            self.local_id.resize(sh.pos.len(), 0);
        }
        let slots = 3 * faces;
        // Slot `3 f + q`: vertex `q` of new tet `f`'s boundary face, in `APEX_FACE` order.
        let mut xs = [0u32; SLOTS];
        for (f, &(tv, _, k)) in self.new_tets.iter().enumerate() {
            for (q, p) in APEX_FACE[k as usize].into_iter().enumerate() {
                xs[3 * f + q] = tv[p];
            }
        }
        let xs = &xs[..slots];
        // Each vertex's first slot: written from the last slot back, so the first one stays.
        let first_slot = &mut self.local_id[..];
        for (s, &x) in xs.iter().enumerate().rev() {
            first_slot[x as usize] = s as u8;
        }
        // `number[s]`: the local number of slot `s`'s vertex. A first slot gives the count of
        // first slots before it; any other reads its first slot's (written before it).
        // (256 entries: indexed by a `u8`, no bounds checks.)
        let mut number = [0u8; 256];
        let mut count = 0u8;
        for (s, &x) in xs.iter().enumerate() {
            let f = first_slot[x as usize];
            let fresh = f as usize == s;
            let seen = number[f as usize];
            number[s as u8 as usize] = if fresh { count } else { seen };
            count += fresh as u8;
        }
        if count as usize > L {
            return false;
        }
        let map = &mut self.edge_map;
        // The numbers are below `L`, so the mask changes no index: it spares the bounds checks.
        let at = |a: u8, b: u8| (a as usize * L + b as usize) & (L * L - 1);
        for (&(_, id, _), l) in self.new_tets.iter().zip(number.chunks_exact(3)) {
            for (i, j, _) in FACE_EDGES {
                map[at(l[i], l[j])] = id;
            }
        }
        for (&(_, id, k), l) in self.new_tets.iter().zip(number.chunks_exact(3)) {
            let tet = &sh.tets[id as usize];
            for (i, j, third) in FACE_EDGES {
                tet.set_nbr(APEX_FACE[k as usize][third], map[at(l[j], l[i])]);
            }
        }
        true
    }

    /// Links the new tets of any cavity: an open-addressing table of directed edges. Pass 1
    /// enters every directed edge, pass 2 looks up every reversed one (twice the probes of one
    /// "insert or find" pass, but the probes' branches are predictable).
    pub(super) fn link_hashed(&mut self, sh: &Shared) {
        let entries = 3 * self.new_tets.len();
        let bits = (4 * entries).next_power_of_two().max(256).trailing_zeros();
        if self.table.len() < 1 << bits {
            self.table = vec![EdgeSlot::default(); 1 << bits];
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.table.iter_mut().for_each(|e| e.generation = 0);
            self.generation = 1;
        }
        let generation = self.generation;
        // Hash into the first `1 << bits` slots only: the table may have grown for one big
        // cavity, and spreading small cavities over all of it would miss the cache.
        let mask = (1usize << bits) - 1;
        let slot_of = |key: u64| (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize;
        for &(tv, id, k) in &self.new_tets {
            let face = APEX_FACE[k as usize].map(|p| tv[p]);
            for (i, j, _) in FACE_EDGES {
                let key = edge_key(face[i], face[j]);
                let mut h = slot_of(key);
                while self.table[h].generation == generation {
                    h = (h + 1) & mask;
                }
                self.table[h] = EdgeSlot {
                    key,
                    tet: id,
                    generation,
                };
            }
        }
        for &(tv, id, k) in &self.new_tets {
            let tet = &sh.tets[id as usize];
            let face = APEX_FACE[k as usize].map(|p| tv[p]);
            for (i, j, third) in FACE_EDGES {
                let key = edge_key(face[j], face[i]);
                let mut h = slot_of(key);
                let mut other = NONE;
                loop {
                    let slot = self.table[h];
                    if slot.generation != generation {
                        break;
                    }
                    if slot.key == key {
                        other = slot.tet;
                        break;
                    }
                    h = (h + 1) & mask;
                }
                debug_assert_ne!(other, NONE, "the cavity boundary is closed");
                tet.set_nbr(APEX_FACE[k as usize][third], other);
            }
        }
    }
}
