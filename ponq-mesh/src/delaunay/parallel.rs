//! Parallel insertion ([`Builder::run`]): after the first BRIO rounds, each worker thread takes
//! one stretch of every later round's Hilbert order in chunks, takes the others' chunks from
//! the back of their queues once its own are done, and leaves the vertices it backed off from
//! twice to a final one-thread pass.

use std::sync::atomic::Ordering::Relaxed;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize};

use super::builder::{Builder, FIRST_TET};
use super::store::DEAD;
use super::triangulation::{Delaunay, DelaunayOptions, DelaunayStats};
use super::worker::{POOL_BLOCK, Worker};

/// Whether the insertion runs [`Worker::insert_avx2`]: on x86-64 CPUs with AVX2, unless
/// `opts.portable`.
pub(super) fn avx2_insertion(opts: &DelaunayOptions) -> bool {
    !opts.portable && crate::cpu::has_avx2()
}

/// Inputs smaller than this are triangulated by one thread.
pub(super) const PARALLEL_MIN_POINTS: usize = 8192;

/// Whether `n` distinct points are inserted by `threads` workers (see [`Builder::run`]).
pub(super) fn in_parallel(threads: usize, n: usize) -> bool {
    threads.clamp(1, 64) > 1 && n >= PARALLEL_MIN_POINTS
}

/// Vertices a worker claims at a time in the parallel phase (see [`Builder::run`]).
pub(super) const CHUNK: usize = 256;

/// The workers stop claiming chunks once at least [`STOP_MIN_ATTEMPTS`] insertions have been
/// tried and more than one in `STOP_BACKOFF_RATIO` backed off: two workers whose cavities keep
/// overlapping are slower than one (20k points on a flat paraboloid cap: 2.5x slower, with
/// 7,283 vertices backed off twice), and the rest is then inserted by one thread. On the
/// mesher's inputs about one insertion in 1,000 backs off.
pub(super) const STOP_BACKOFF_RATIO: usize = 8;
/// See [`STOP_BACKOFF_RATIO`].
pub(super) const STOP_MIN_ATTEMPTS: usize = 1024;

impl Builder {
    /// Inserts every vertex: the first BRIO rounds by one thread, the later (large) rounds by
    /// `threads` workers, each owning one stretch of every round's Hilbert order in chunks
    /// (and taking other workers' chunks once its own are done), then the vertices the
    /// workers backed off from by one thread.
    ///
    /// The first four vertices are in the first tet already ([`Builder::new`]); with no tet
    /// (the vertices span no volume) nothing is inserted.
    pub(super) fn run(mut self, rounds: &[usize], opts: &DelaunayOptions) -> Delaunay {
        let n = self.n_real as usize;
        let mut main = Worker::new(1, 12345);
        main.avx2 = avx2_insertion(opts);
        let threads = opts.threads.clamp(1, 64);
        if self.used == 0 {
            return self.finish(DelaunayStats {
                workers: 1,
                ..Default::default()
            });
        }
        if !in_parallel(threads, n) {
            self.insert_sequential(&mut main, FIRST_TET..self.n_real);
            return self.finish(DelaunayStats {
                workers: 1,
                large_cavities: main.large_cavities,
                ..Default::default()
            });
        }
        // Sequential prefix: enough points that the workers' regions hardly interact.
        // It ends at a round boundary (a prefix of a round covers only part of the domain),
        // and leaves at least half of the points to the workers.
        // (A smaller prefix, 64 points per worker at least, measured 6% faster at 10k points
        // than 512 per worker: the other threads wait less; the same at 100k.)
        let prefix_min = (n / 64).max(64 * threads);
        let split = match rounds.iter().copied().find(|&r| r >= prefix_min) {
            Some(r) if r <= n / 2 => r,
            _ => rounds
                .iter()
                .copied()
                .filter(|&r| r <= n / 2)
                .max()
                .unwrap_or(0),
        }
        // The first tet's vertices are in already: the workers' stretches start after them.
        .max(FIRST_TET as usize);
        self.insert_sequential(&mut main, FIRST_TET..split as u32);
        // Per-round stretches, cut into chunks of consecutive vertices; alternate directions so
        // that neighbouring workers never start a round where the other one ends the previous
        // one. `queues[i]`: the chunks of worker i, in its order of work.
        let mut queues: Vec<Vec<(u32, u32, bool)>> = vec![Vec::new(); threads];
        for (r, w) in rounds.windows(2).enumerate() {
            let (a, b) = (w[0].max(split), w[1]);
            if a >= b {
                continue;
            }
            let len = b - a;
            for (i, queue) in queues.iter_mut().enumerate() {
                let (s, e) = (a + len * i / threads, a + len * (i + 1) / threads);
                let chunks = (s..e)
                    .step_by(CHUNK)
                    .map(|c| (c as u32, (c + CHUNK).min(e) as u32));
                if r % 2 == 0 {
                    queue.extend(chunks.map(|(c, d)| (c, d, false)));
                } else {
                    queue.extend(chunks.rev().map(|(c, d)| (c, d, true)));
                }
            }
        }
        let parallel_insertions: usize =
            queues.iter().flatten().map(|c| (c.1 - c.0) as usize).sum();
        let mut workers: Vec<Worker> = (0..threads)
            .map(|i| Worker::new(i as u32 + 2, 0x9E37 + i as u64))
            .collect();
        for (w, queue) in workers.iter_mut().zip(&queues) {
            w.fail_every = opts.fail_every_nth_lock;
            w.avx2 = main.avx2;
            // Start each worker in its own region: at the tet holding its first vertex.
            w.last = main.last;
            if let Some(&(c, d, rev)) = queue.first() {
                let first = if rev { d - 1 } else { c };
                let sh = self.shared();
                if let Ok(t) = main.locate::<false>(&sh, first) {
                    w.last = t;
                }
            }
        }
        workers[0].free = std::mem::take(&mut main.free);
        // The slots of the parallel phase come from one pool, in blocks, so that a worker
        // that does more than its share never runs out; slots past the last block handed out
        // are never touched.
        let pool_start = self.used;
        self.reserve((15 * parallel_insertions / 2).max(POOL_BLOCK * threads) + 4096);
        let pool = AtomicUsize::new(pool_start);
        // The locks apart from the tets: 36-byte tets instead of 40 made one-thread insertion
        // ~10% faster and the parallel phase ~8%, side by side. Tried: one lock per 4 to 64
        // consecutive slots (a cavity and its neighbours sit in few such blocks): fewer
        // compare-exchanges but more back-offs, no faster; the marks apart too (32-byte tets,
        // a mark array beside them): no faster either (the cavity search reads both).
        // Zeroed pages: the locks of slots never used cost nothing.
        let locks: Vec<AtomicU32> = bytemuck::allocation::zeroed_vec(self.used);
        let (left, parallel_stopped) = {
            use rayon::prelude::*;
            let mut sh = self.shared();
            sh.pool = Some(&pool);
            sh.locks = &locks;
            // Each chunk is inserted by the one worker that claims it: its owner, going
            // forward through its queue, or (once a worker's own queue is done) a worker
            // taking the others' chunks from the back, far from where their owners are.
            let claimed: Vec<Vec<AtomicBool>> = queues
                .iter()
                .map(|q| q.iter().map(|_| AtomicBool::new(false)).collect())
                .collect();
            // First attempts and back-offs so far, all workers; `stop` once too many back off.
            let (attempts, backoffs, stop) = (
                AtomicUsize::new(0),
                AtomicUsize::new(0),
                AtomicBool::new(false),
            );
            workers.par_iter_mut().enumerate().for_each(|(i, w)| {
                // A vertex backed off from is tried again after the rest of its chunk (the
                // other worker has usually moved on by then), and only then deferred.
                let insert_chunk = |w: &mut Worker, (c, d, rev): (u32, u32, bool)| {
                    let mut retry = Vec::new();
                    let mut one = |v: u32| {
                        if w.insert::<true>(&sh, v).is_err() {
                            retry.push(v);
                        }
                    };
                    if rev {
                        (c..d).rev().for_each(&mut one);
                    } else {
                        (c..d).for_each(&mut one);
                    }
                    w.backed_off += retry.len();
                    let tried = attempts.fetch_add((d - c) as usize, Relaxed) + (d - c) as usize;
                    let failed = backoffs.fetch_add(retry.len(), Relaxed) + retry.len();
                    if tried >= STOP_MIN_ATTEMPTS && failed * STOP_BACKOFF_RATIO > tried {
                        stop.store(true, Relaxed);
                    }
                    for v in retry {
                        if w.insert::<true>(&sh, v).is_err() {
                            w.deferred.push(v);
                        }
                    }
                };
                for (j, &chunk) in queues[i].iter().enumerate() {
                    if stop.load(Relaxed) {
                        return;
                    }
                    if !claimed[i][j].swap(true, Relaxed) {
                        insert_chunk(w, chunk);
                    }
                }
                for other in (1..threads).map(|k| (i + k) % threads) {
                    // Owners claim from the front and thieves from the back, so the first
                    // claimed chunk from the back ends the search.
                    for (j, &chunk) in queues[other].iter().enumerate().rev() {
                        if stop.load(Relaxed) || claimed[other][j].swap(true, Relaxed) {
                            break;
                        }
                        w.stolen += 1;
                        insert_chunk(w, chunk);
                    }
                }
            });
            // The chunks no worker claimed (the workers stopped) go to the one-thread pass.
            let mut left: Vec<u32> = Vec::new();
            for (queue, claimed) in queues.iter().zip(&claimed) {
                for (&(c, d, _), taken) in queue.iter().zip(claimed) {
                    if !taken.load(Relaxed) {
                        left.extend(c..d);
                    }
                }
            }
            (left, stop.load(Relaxed))
        };
        self.used = pool.load(Relaxed).min(self.used);
        // Gather the slots and the deferred vertices; finish with one thread.
        let parallel_insertions = parallel_insertions - left.len();
        let mut deferred = left;
        for w in &mut workers {
            main.free.append(&mut w.free);
            main.free.extend(w.fresh.0..w.fresh.1);
            deferred.append(&mut w.deferred);
            if self.tets[w.last as usize].mark() != DEAD {
                main.last = w.last;
            }
        }
        if self.tets[main.last as usize].mark() == DEAD {
            main.last = (0..self.used as u32)
                .find(|&t| self.tets[t as usize].mark() != DEAD)
                .unwrap_or(0);
        }
        deferred.sort_unstable();
        let mut stats = DelaunayStats {
            workers: threads,
            parallel_insertions,
            deferred: deferred.len(),
            stolen_chunks: workers.iter().map(|w| w.stolen).sum(),
            backed_off: workers.iter().map(|w| w.backed_off).sum(),
            parallel_stopped,
            ..Default::default()
        };
        self.insert_sequential(&mut main, deferred);
        stats.large_cavities =
            main.large_cavities + workers.iter().map(|w| w.large_cavities).sum::<usize>();
        self.finish(stats)
    }
}
