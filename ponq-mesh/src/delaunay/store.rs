//! The tet store: the arena's [`Tet`] slots (vertices, neighbours, the insertion stamp), the
//! marks and stamps a cavity search leaves on them, and [`Shared`], what every worker sees
//! (the points and the arena).

use std::sync::atomic::Ordering::Relaxed;
use std::sync::atomic::{AtomicU32, AtomicUsize};

/// A tet of the builder: vertices, neighbours and the insertion stamp, kept together so that
/// the cavity search touches one tet's 36 bytes at a time.
///
/// Worker threads share the tets; in the parallel phase a thread writes a tet, or reads it
/// for an insertion, only while it holds the slot's lock ([`Shared::locks`], apart from the
/// tets; no waiting: a busy lock makes the insertion back off). The fields are atomics so
/// that this needs no `unsafe`; relaxed accesses are plain loads and stores.
///
/// All-zero bytes are a free slot ([`DEAD`]). The parallel phase's arena is allocated zeroed:
/// fresh pages from the system cost nothing until a worker first uses them, and slots never
/// used are never touched (filling a 30 MB arena up front took 20-30 ms of one thread at 100k
/// points). One thread writes its free slots a block at a time instead ([`Builder::new`]).
#[derive(bytemuck::Zeroable)]
pub(super) struct Tet {
    pub(super) v: [AtomicU32; 4],
    pub(super) n: [AtomicU32; 4],
    /// [`DEAD`] for a free slot, else [`NO_STAMP`] or an insertion's stamp ([`Stamps`]).
    pub(super) mark: AtomicU32,
}

impl Tet {
    pub(super) fn dead() -> Self {
        bytemuck::Zeroable::zeroed()
    }
    #[inline]
    pub(super) fn verts(&self) -> [u32; 4] {
        [0, 1, 2, 3].map(|k| self.v[k].load(Relaxed))
    }
    #[inline]
    pub(super) fn nbrs(&self) -> [u32; 4] {
        [0, 1, 2, 3].map(|k| self.n[k].load(Relaxed))
    }
    #[inline]
    pub(super) fn mark(&self) -> u32 {
        self.mark.load(Relaxed)
    }
    #[inline]
    pub(super) fn set_mark(&self, m: u32) {
        self.mark.store(m, Relaxed);
    }
    #[inline]
    pub(super) fn set_nbr(&self, k: usize, t: u32) {
        self.n[k].store(t, Relaxed);
    }
}

/// The mark of a free slot (all-zero bytes, see [`Tet`]).
pub(super) const DEAD: u32 = 0;
/// The mark of a live tet that carries no stamp of the insertion holding it.
pub(super) const NO_STAMP: u32 = 1;

/// `APEX_FACE[k]`: the positions of the face opposite position `k`, ordered so that the
/// vertex at `k` is on the face's positive side (`(APEX_FACE[k], k)` is an even permutation of
/// `0..4`, so for a positively oriented tet `orient3d(face..., t[k]) > 0`).
pub(super) const APEX_FACE: [[usize; 3]; 4] = [[1, 3, 2], [0, 2, 3], [0, 3, 1], [0, 1, 2]];

/// The three directed edges `(i, j)` of a boundary face, as indices into its
/// [`APEX_FACE`] order, each with the index of the face's third vertex: a new tet shares with
/// the new tet across edge `(i, j)` its face opposite `APEX_FACE[k][third]`.
pub(super) const FACE_EDGES: [(usize, usize, usize); 3] = [(0, 1, 2), (1, 2, 0), (2, 0, 1)];

/// The stamps an insertion puts on the tets it looks at (see [`Tet::mark`]): distinct for
/// each vertex, and never [`DEAD`] or [`NO_STAMP`].
#[derive(Debug, Clone, Copy)]
pub(super) struct Stamps {
    /// In the cavity (in conflict with the new vertex).
    pub(super) in_cavity: u32,
    /// Next to the cavity and not in conflict.
    pub(super) outside: u32,
    /// Next to the cavity, its conflict test not yet done.
    pub(super) waiting: u32,
}

impl Stamps {
    /// The stamps of vertex `v` (`3v + 2`, `3v + 3`, `3v + 4`: there are fewer than
    /// [`MAX_POINTS`] vertices, so they fit in a `u32`).
    #[inline(always)]
    pub(super) fn of(v: u32) -> Self {
        Self {
            in_cavity: 3 * v + 2,
            outside: 3 * v + 3,
            waiting: 3 * v + 4,
        }
    }
}

/// The face of tet `nt` that looks back at its neighbour `c` (adjacency is symmetric).
#[inline(always)]
pub(super) fn back_face(nt: &Tet, c: u32) -> u8 {
    let nn = nt.nbrs();
    let j = (nn[1] == c) as u8 + 2 * (nn[2] == c) as u8 + 3 * (nn[3] == c) as u8;
    debug_assert_eq!(nn[j as usize], c, "adjacency is symmetric");
    j
}

/// The most points a triangulation takes: the tet arena starts at 8 slots per point (2^31 at
/// this limit, 77 GB) and grows by half when it must, and slot numbers stay below [`NONE`];
/// the stamps ([`Stamps::of`]) fit in a `u32` far beyond.
pub(super) const MAX_POINTS: usize = 1 << 28;

/// Makes room for `n` more items in `v` (for [`push_if_in_room`]).
#[inline(always)]
pub(super) fn make_room<T>(v: &mut Vec<T>, n: usize) {
    if v.capacity() - v.len() < n {
        v.reserve(n.max(64));
    }
}

/// Writes `x` after the last item of `v` and keeps it only if `keep`: a conditional push
/// without a branch on `keep`, and without a capacity check (measured: 2-3% of a one-thread
/// insertion against `Vec::push` and `Vec::truncate`).
///
/// # Safety
/// `v` must have room for one more item ([`make_room`]).
#[inline(always)]
pub(super) unsafe fn push_if_in_room<T: Copy>(v: &mut Vec<T>, x: T, keep: bool) {
    let len = v.len();
    debug_assert!(len < v.capacity());
    // SAFETY: `len < capacity` (this function's contract): the write is to the vector's own
    // spare room, and the length grows over it only once it is written.
    unsafe {
        v.as_mut_ptr().add(len).write(x);
        v.set_len(len + keep as usize);
    }
}

/// What the workers share: the points (numbered in insertion order) and the tet arena.
pub(super) struct Shared<'a> {
    pub(super) pos: &'a [[f64; 3]],
    /// Input number of each real vertex (the infinite vertex, numbered past them, is in no
    /// perturbed test: see [`Shared::infinite_conflict`]).
    pub(super) rank: &'a [u32],
    pub(super) tets: &'a [Tet],
    pub(super) n_real: u32,
    /// Static insphere bound for tets of real vertices only (their differences are bounded by
    /// the extent of the input).
    pub(super) static_eps: f64,
    /// Static orientation bound, likewise.
    pub(super) static_orient_eps: f64,
    /// Never-used slots for the parallel phase, handed out in blocks: the next one is
    /// `pool.load()`, the last one `tets.len() - 1`.
    pub(super) pool: Option<&'a AtomicUsize>,
    /// Parallel phase: the lock of each slot, 0 when free, else the id of the worker holding
    /// it (see [`Worker::try_lock`]).
    pub(super) locks: &'a [AtomicU32],
}

impl Shared<'_> {
    #[inline]
    pub(super) fn p(&self, v: u32) -> &[f64; 3] {
        &self.pos[v as usize]
    }

    /// Whether all four vertices are real: a finite tet, not an infinite one (whose
    /// infinite vertex is numbered `n_real`, see [`Builder::new`]).
    #[inline(always)]
    pub(super) fn real(&self, tv: [u32; 4]) -> bool {
        tv[0].max(tv[1]).max(tv[2].max(tv[3])) < self.n_real
    }

    /// The position of the infinite vertex in infinite tet `tv`.
    #[inline]
    pub(super) fn inf_at(&self, tv: [u32; 4]) -> usize {
        (0..4).find(|&k| tv[k] >= self.n_real).unwrap_or(3)
    }
}
