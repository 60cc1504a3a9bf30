//! One inserting thread ([`Worker`]): its free slots, the locks it holds and its scratch
//! space, and why an insertion backs off ([`Fail`]).

use std::sync::atomic::Ordering::{Acquire, Relaxed, Release};

use super::order::SplitMix;
use super::store::Shared;

/// Cavities whose boundary has at most this many vertices are linked by
/// [`Worker::link_small`] (a Delaunay cavity in 3D has about 16 on average).
pub(super) const SMALL_CAVITY: usize = 32;

/// A slot of a worker's directed-edge table (see [`Worker::link_hashed`]).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct EdgeSlot {
    pub(super) key: u64,
    pub(super) tet: u32,
    pub(super) generation: u32,
}

/// Why an insertion backed off (nothing was changed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Fail {
    /// A tet it needed is held by another worker.
    Busy,
    /// The worker ran out of free tet slots.
    NoSpace,
}

/// Slots a worker takes from the shared pool at a time.
pub(super) const POOL_BLOCK: usize = 2048;

/// One inserting thread: its free slots and scratch space. With `PAR = false` it is the only
/// thread and takes no locks.
pub(super) struct Worker {
    /// Lock id (>= 1).
    pub(super) id: u32,
    /// Free tet slots owned by this worker.
    pub(super) free: Vec<u32>,
    /// Never-used slots reserved for this worker (`fresh.0..fresh.1`).
    pub(super) fresh: (u32, u32),
    /// A tet made by the last insertion (the start of the next walk).
    pub(super) last: u32,
    /// Vertices this worker backed off from.
    pub(super) deferred: Vec<u32>,
    /// Chunks this worker took from other workers' queues.
    pub(super) stolen: usize,
    /// First attempts of this worker that backed off.
    pub(super) backed_off: usize,
    /// Insertions linked by [`Worker::link_hashed`].
    pub(super) large_cavities: usize,
    /// Testing aid: every `n`-th lock attempt fails (0: never).
    pub(super) fail_every: u32,
    /// Insert with [`Worker::insert_avx2`] (only set where the CPU has AVX2).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(super) avx2: bool,
    pub(super) lock_attempts: u32,
    pub(super) rng: SplitMix,
    /// Cavity tets still to look around, each with the face it was entered through.
    pub(super) stack: Vec<(u32, u8)>,
    /// Faces of cavity tets whose neighbour was waiting for its conflict test (queued from
    /// another cavity tet): boundary faces if that neighbour turns out not in conflict.
    pub(super) later: Vec<(u32, u8, u32)>,
    pub(super) cavity: Vec<u32>,
    /// Slots locked by the current insertion (parallel phase).
    pub(super) held: Vec<u32>,
    pub(super) boundary: Vec<(u32, u8, u32, u8)>,
    pub(super) new_tets: Vec<([u32; 4], u32, u8)>,
    /// Slots taken from `free` / `fresh` for the current insertion.
    pub(super) taken: Vec<u32>,
    /// Open-addressing table directed edge -> new tet for linking the new tets. An entry
    /// belongs to the current insertion only if its generation is `generation`, so the table
    /// is never cleared (but when the generation wraps around).
    pub(super) table: Vec<EdgeSlot>,
    pub(super) generation: u32,
    /// The first slot of each vertex of the cavity boundary (see [`Worker::link_small`]),
    /// indexed by vertex; only the entries of the current boundary mean anything.
    pub(super) local_id: Vec<u8>,
    /// `edge_map[x * SMALL_CAVITY + y]`: the new tet with the directed edge `x -> y`.
    pub(super) edge_map: Box<[u32; SMALL_CAVITY * SMALL_CAVITY]>,
}

impl Worker {
    pub(super) fn new(id: u32, seed: u64) -> Self {
        Self {
            id,
            free: Vec::new(),
            fresh: (0, 0),
            last: 0,
            deferred: Vec::new(),
            stolen: 0,
            backed_off: 0,
            large_cavities: 0,
            fail_every: 0,
            avx2: false,
            lock_attempts: 0,
            rng: SplitMix(seed),
            stack: Vec::new(),
            later: Vec::new(),
            cavity: Vec::new(),
            held: Vec::new(),
            boundary: Vec::new(),
            new_tets: Vec::new(),
            taken: Vec::new(),
            table: vec![EdgeSlot::default(); 256],
            generation: 0,
            local_id: Vec::new(),
            edge_map: Box::new([0; SMALL_CAVITY * SMALL_CAVITY]),
        }
    }

    /// Takes a block of never-used slots from the shared pool (parallel phase only).
    pub(super) fn refill(&mut self, sh: &Shared) -> bool {
        let Some(pool) = sh.pool else {
            return false;
        };
        let start = pool.fetch_add(POOL_BLOCK, Relaxed);
        let end = (start + POOL_BLOCK).min(sh.tets.len());
        if start >= end {
            return false;
        }
        self.fresh = (start as u32, end as u32);
        true
    }

    /// Makes sure this worker holds the lock of slot `t`: `true` if it did already or takes
    /// it now, `false` if another worker holds it (nothing waits).
    #[inline]
    pub(super) fn try_lock<const PAR: bool>(&mut self, sh: &Shared, t: u32) -> bool {
        if !PAR {
            return true;
        }
        let lock = &sh.locks[t as usize];
        // Only this worker writes its own id: reading it means the slot is ours.
        if lock.load(Relaxed) == self.id {
            return true;
        }
        if self.fail_every > 0 {
            self.lock_attempts += 1;
            if self.lock_attempts.is_multiple_of(self.fail_every) {
                return false;
            }
        }
        let ok = lock.compare_exchange(0, self.id, Acquire, Relaxed).is_ok();
        if ok {
            self.held.push(t);
        }
        ok
    }

    /// Lets go of every slot this worker holds.
    #[inline]
    pub(super) fn unlock_all<const PAR: bool>(&mut self, sh: &Shared) {
        if PAR {
            for &t in &self.held {
                sh.locks[t as usize].store(0, Release);
            }
        }
        self.held.clear();
    }
}
