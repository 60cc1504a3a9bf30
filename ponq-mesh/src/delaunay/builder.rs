//! The builder: the tet arena with the first tet and its infinite tets ([`Builder::new`]), and
//! insertion by one thread ([`Builder::insert_sequential`]).

use std::sync::atomic::Ordering::Relaxed;

use super::store::{APEX_FACE, NO_STAMP, Shared, Tet};
use super::triangulation::NONE;
use super::worker::Worker;
use crate::error::{Error, Result};
use crate::predicates::{orient3d, static_insphere_bound, static_orient_bound};

/// The vertices of the first tet ([`Builder::new`]): the first four of the insertion order
/// ([`independent_first`]), inserted before any other.
pub(super) const FIRST_TET: u32 = 4;

/// The free slots a one-thread insertion writes at a time when it runs out (147 KB: they are
/// filled by the next ~600 insertions while still in the cache; see [`Builder::new`]).
pub(super) const FRESH_BLOCK: usize = 4096;

pub(super) struct Builder {
    /// Real vertices (in insertion order) followed by an entry for the infinite vertex (NaN,
    /// see [`Builder::new`]).
    pub(super) pos: Vec<[f64; 3]>,
    /// Input number of each real vertex.
    pub(super) rank: Vec<u32>,
    pub(super) n_real: u32,
    pub(super) static_eps: f64,
    pub(super) static_orient_eps: f64,
    /// The tet arena: `tets[..used]` have been handed out, the slots after them are free
    /// ([`DEAD`]); room for more is reserved (see [`Builder::new`]).
    pub(super) tets: Vec<Tet>,
    pub(super) used: usize,
}

impl Builder {
    /// A builder with the first tet, on the first four vertices (affinely independent, see
    /// [`independent_first`]; `spans` says whether they are: otherwise no tet at all), and
    /// its four infinite tets, one per face: the face and the infinite vertex (numbered
    /// `pos.len()`, past the real ones), ordered as if that vertex were a point far beyond the
    /// face, so that the insertion makes and links infinite tets as any others. Room for
    /// `capacity` tets (more are added when needed).
    ///
    /// With `zeroed`, the arena's `capacity` slots are allocated zeroed (free) at once, as
    /// the parallel phase needs: its workers take slots from one pool and may look at any
    /// of them. Without it (one thread), only the room is reserved, and [`Builder::reserve`]
    /// writes the free slots a few thousand at a time, just before the insertions fill them.
    /// An allocator that serves the arena from memory freed before must clear it for a zeroed
    /// allocation: a pass over the whole arena (29 MB at 100k points) whose lines have left
    /// the caches again by the time they are filled.
    pub(super) fn new(
        mut pos: Vec<[f64; 3]>,
        rank: Vec<u32>,
        capacity: usize,
        zeroed: bool,
        spans: bool,
    ) -> Result<Self> {
        let n_real = pos.len() as u32;
        let (mut lo, mut hi) = ([0.0f64; 3], [0.0f64; 3]);
        if let Some(first) = pos.first() {
            lo = *first;
            hi = *first;
        }
        for p in &pos {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        let static_eps = static_insphere_bound(extent);
        let static_orient_eps = static_orient_bound(extent);
        // The infinite vertex's entry: NaN, so that every floating-point filter of a tet
        // with it is undecided (their comparisons are false for NaN), which sends the tet to
        // the tests made for infinite tets; no exact predicate reads it.
        pos.push([f64::NAN; 3]);
        let no_memory = || Error::InvalidInput(format!("no memory for {capacity} tetrahedra"));
        let mut tets: Vec<Tet> = if zeroed {
            bytemuck::allocation::try_zeroed_vec(capacity.max(5)).map_err(|_| no_memory())?
        } else {
            let mut tets = Vec::new();
            tets.try_reserve_exact(capacity.max(5))
                .map_err(|_| no_memory())?;
            tets
        };
        let mut used = 0;
        if spans {
            let inf = n_real;
            let mut first = [0, 1, 2, 3];
            if orient3d(&pos[0], &pos[1], &pos[2], &pos[3]) < 0 {
                first.swap(0, 1);
            }
            // Slot 0: the first tet; slot 1 + k: the infinite tet on its face k (the face's
            // first two vertices swapped, so that the far side is the positive one).
            let mut five = vec![first];
            for face in APEX_FACE {
                let f = face.map(|q| first[q]);
                five.push([f[1], f[0], f[2], inf]);
            }
            if !zeroed {
                tets.resize_with(5, Tet::dead);
            }
            for (t, tv) in five.iter().enumerate() {
                for k in 0..4 {
                    tets[t].v[k].store(tv[k], Relaxed);
                    // The tet across face k: the other of the five with the same three
                    // vertices.
                    let mut face: Vec<u32> = (0..4).filter(|&q| q != k).map(|q| tv[q]).collect();
                    face.sort_unstable();
                    let across = (0..5).find(|&u| {
                        u != t && {
                            let mut g: Vec<u32> = five[u].to_vec();
                            g.sort_unstable();
                            face.iter().all(|x| g.contains(x))
                        }
                    });
                    tets[t].set_nbr(k, across.map_or(NONE, |u| u as u32));
                }
                tets[t].set_mark(NO_STAMP);
            }
            used = 5;
        }
        Ok(Self {
            pos,
            rank,
            n_real,
            static_eps,
            static_orient_eps,
            tets,
            used,
        })
    }

    pub(super) fn shared(&self) -> Shared<'_> {
        Shared {
            pos: &self.pos,
            rank: &self.rank,
            tets: &self.tets[..self.used],
            n_real: self.n_real,
            static_eps: self.static_eps,
            static_orient_eps: self.static_orient_eps,
            pool: None,
            locks: &[],
        }
    }

    /// Hands out `count` never-used slots (written free here if they were not yet; the
    /// room grows by half when it is too small).
    pub(super) fn reserve(&mut self, count: usize) -> (u32, u32) {
        let end = self.used + count;
        if end > self.tets.len() {
            if end > self.tets.capacity() {
                let room = end.max(self.tets.capacity() + self.tets.capacity() / 2);
                self.tets.reserve_exact(room - self.tets.len());
            }
            self.tets.resize_with(end, Tet::dead);
        }
        let start = std::mem::replace(&mut self.used, end);
        (start as u32, end as u32)
    }

    /// Adds `count` free slots for `w`.
    pub(super) fn grow(&mut self, w: &mut Worker, count: usize) {
        if w.fresh.0 < w.fresh.1 {
            w.free.extend(w.fresh.0..w.fresh.1);
        }
        w.fresh = self.reserve(count);
    }

    /// Inserts `verts` one after the other with a single worker.
    pub(super) fn insert_sequential(
        &mut self,
        w: &mut Worker,
        verts: impl IntoIterator<Item = u32>,
    ) {
        for v in verts {
            loop {
                let result = {
                    let sh = self.shared();
                    w.insert::<false>(&sh, v)
                };
                match result {
                    Ok(()) => break,
                    Err(_) => {
                        // Half again as many slots within the slots already written free,
                        // else `FRESH_BLOCK` more (see `Builder::new`).
                        let room = self.tets.len() - self.used;
                        let count = (self.used / 2).max(1024).min(room.max(FRESH_BLOCK));
                        self.grow(w, count);
                    }
                }
            }
        }
    }
}
