//! Exact 3D Delaunay tetrahedralisation.
//!
//! Written here because no MIT/Apache crate does it well enough: the pure-Rust candidates
//! measured on this project's machine were either MPL-licensed and 7 s on a 27k-point lattice
//! (PoNQ-lite puts v* on lattices), aborted on lattices, emitted flat tets, or were 1000x slower;
//! TetGen is AGPL. This is the classic Bowyer-Watson insertion in a BRIO / Hilbert-curve order
//! with a stochastic visibility walk, on top of [`crate::predicates`]: exact orientation and
//! insphere tests with Devillers-Teillaud symbolic perturbation, so co-spherical and coplanar
//! inputs (lattices) give a valid triangulation with no flat tetrahedron and no jitter.
//!
//! ```
//! use ponq_mesh::delaunay::Delaunay;
//! let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]];
//! let dt = Delaunay::new(&pts).unwrap();
//! assert_eq!(dt.tets.len(), 2);
//! ```

use crate::error::{Error, Result};
use crate::predicates::{in_conflict_bounded, orient3d, static_insphere_bound};

/// Marker for "no neighbour" (a face on the boundary of the triangulated region).
pub const NONE: u32 = u32::MAX;

/// A Delaunay tetrahedralisation.
///
/// Invariants: every tet `tets[t]` is positively oriented (`orient3d > 0`, never flat);
/// `neighbors[t][k]` is the tet sharing the face opposite `tets[t][k]`, or [`NONE`] on the
/// boundary; adjacency is symmetric. The union of the tets is (up to slivers along the convex
/// hull) the convex hull of the vertices; the mesher always adds an enclosing box.
#[derive(Debug, Clone, Default)]
pub struct Delaunay {
    /// The distinct input points (exact duplicates merged; the first occurrence is kept).
    pub vertices: Vec<[f64; 3]>,
    /// For each input point, the index of its vertex in `vertices`.
    pub vertex_of_point: Vec<u32>,
    /// Tetrahedra as vertex indices, positively oriented.
    pub tets: Vec<[u32; 4]>,
    /// `neighbors[t][k]`: the tet across the face opposite vertex `k` of `t`, or [`NONE`].
    pub neighbors: Vec<[u32; 4]>,
}

/// SplitMix64: a tiny deterministic generator for the insertion order and walk.
struct SplitMix(u64);
impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// Index of a point on the 3D Hilbert curve of order `bits` (Skilling's transpose method).
fn hilbert_index(mut x: [u32; 3], bits: u32) -> u64 {
    let m = 1u32 << (bits - 1);
    let mut q = m;
    while q > 1 {
        let p = q - 1;
        for i in 0..3 {
            if x[i] & q != 0 {
                x[0] ^= p;
            } else {
                let t = (x[0] ^ x[i]) & p;
                x[0] ^= t;
                x[i] ^= t;
            }
        }
        q >>= 1;
    }
    for i in 1..3 {
        x[i] ^= x[i - 1];
    }
    let mut t = 0;
    let mut q = m;
    while q > 1 {
        if x[2] & q != 0 {
            t ^= q - 1;
        }
        q >>= 1;
    }
    for v in &mut x {
        *v ^= t;
    }
    let mut h = 0u64;
    for b in (0..bits).rev() {
        for v in &x {
            h = (h << 1) | ((v >> b) & 1) as u64;
        }
    }
    h
}

/// Biased randomised insertion order: rounds of doubling size, each sorted along a Hilbert curve.
fn brio_order(pts: &[[f64; 3]], lo: [f64; 3], hi: [f64; 3]) -> Vec<u32> {
    const BITS: u32 = 16;
    let scale: Vec<f64> = (0..3)
        .map(|k| {
            let e = hi[k] - lo[k];
            if e > 0.0 {
                ((1u32 << BITS) - 1) as f64 / e
            } else {
                0.0
            }
        })
        .collect();
    let key = |p: &[f64; 3]| {
        let c = |k: usize| (((p[k] - lo[k]) * scale[k]) as u32).min((1 << BITS) - 1);
        hilbert_index([c(0), c(1), c(2)], BITS)
    };
    let mut order: Vec<u32> = (0..pts.len() as u32).collect();
    let mut rng = SplitMix(0x005E_ED0F_D3A1);
    for i in (1..order.len()).rev() {
        let j = (rng.next() % (i as u64 + 1)) as usize;
        order.swap(i, j);
    }
    let mut end = order.len();
    while end > 0 {
        let start = if end <= 64 { 0 } else { end / 2 };
        order[start..end].sort_by_cached_key(|&i| key(&pts[i as usize]));
        end = start;
    }
    order
}

impl Delaunay {
    /// Triangulates `points`. Exact duplicates are merged (see [`Delaunay::vertex_of_point`]).
    /// Fewer than four affinely independent points give a triangulation without tets.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for a non-finite coordinate or more than 2^31 points.
    pub fn new(points: &[[f64; 3]]) -> Result<Self> {
        if points.len() >= (1usize << 31) - 8 {
            return Err(Error::InvalidInput(format!(
                "{} points is more than the triangulation supports",
                points.len()
            )));
        }
        if let Some(i) = points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(Error::InvalidInput(format!(
                "point {i} = {:?} is not finite",
                points[i]
            )));
        }
        // Merge exact duplicates.
        let mut idx: Vec<u32> = (0..points.len() as u32).collect();
        idx.sort_unstable_by(|&a, &b| {
            let (p, q) = (&points[a as usize], &points[b as usize]);
            p[0].total_cmp(&q[0])
                .then(p[1].total_cmp(&q[1]))
                .then(p[2].total_cmp(&q[2]))
                .then(a.cmp(&b))
        });
        let mut vertex_of_point = vec![0u32; points.len()];
        let mut first_of_group: Vec<u32> = Vec::with_capacity(points.len());
        let mut group_of_point = vec![0u32; points.len()];
        for (k, &i) in idx.iter().enumerate() {
            let same = k > 0 && {
                let (p, q) = (&points[idx[k - 1] as usize], &points[i as usize]);
                p[0] == q[0] && p[1] == q[1] && p[2] == q[2]
            };
            if !same {
                first_of_group.push(i);
            }
            group_of_point[i as usize] = first_of_group.len() as u32 - 1;
        }
        // Number vertices by the first occurrence of each position in input order.
        let mut group_vertex = vec![u32::MAX; first_of_group.len()];
        let mut vertices = Vec::with_capacity(first_of_group.len() + 4);
        for (i, p) in points.iter().enumerate() {
            let g = group_of_point[i] as usize;
            if group_vertex[g] == u32::MAX {
                group_vertex[g] = vertices.len() as u32;
                vertices.push(*p);
            }
            vertex_of_point[i] = group_vertex[g];
        }
        let mut dt = Builder::new(vertices).run();
        dt.vertex_of_point = vertex_of_point;
        Ok(dt)
    }

    /// For every vertex, one tet incident to it (or [`NONE`] for a vertex in no tet).
    pub fn vertex_to_tet(&self) -> Vec<u32> {
        let mut v2t = vec![NONE; self.vertices.len()];
        for (t, tet) in self.tets.iter().enumerate() {
            for &v in tet {
                v2t[v as usize] = t as u32;
            }
        }
        v2t
    }
}

/// A tet of the builder: vertices, neighbours and the insertion stamp, kept together so that
/// the cavity search touches one cache line per tet.
#[derive(Clone, Copy)]
struct Tet {
    v: [u32; 4],
    n: [u32; 4],
    /// Insertion stamp; [`DEAD`] for a free slot.
    mark: u32,
}

const DEAD: u32 = u32::MAX;

/// `OTHER_TWO[f][k]`: the two indices of `0..4` other than `f` and `k` (`f != k`).
const OTHER_TWO: [[[usize; 2]; 4]; 4] = {
    let mut t = [[[0usize; 2]; 4]; 4];
    let mut f = 0;
    while f < 4 {
        let mut k = 0;
        while k < 4 {
            let mut n = 0;
            let mut s = 0;
            while s < 4 {
                if s != f && s != k && n < 2 {
                    t[f][k][n] = s;
                    n += 1;
                }
                s += 1;
            }
            k += 1;
        }
        f += 1;
    }
    t
};

struct Builder {
    /// Real vertices followed by the 4 super-tetrahedron vertices.
    pos: Vec<[f64; 3]>,
    n_real: u32,
    /// Static insphere bound for tets of real vertices only (their differences are bounded by
    /// the extent of the input).
    static_eps: f64,
    tets: Vec<Tet>,
    free: Vec<u32>,
    rng: SplitMix,
    // Per-insertion scratch.
    stack: Vec<u32>,
    cavity: Vec<u32>,
    boundary: Vec<(u32, u8, u32, u8)>,
    new_tets: Vec<([u32; 4], u32, u8)>,
    /// Open-addressing table edge key -> (tet, face) for linking the new tets.
    table: Vec<(u64, u32, u8)>,
    used: Vec<usize>,
}

const EMPTY_KEY: u64 = u64::MAX;

impl Builder {
    fn new(mut pos: Vec<[f64; 3]>) -> Self {
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
        let c = [
            0.5 * (lo[0] + hi[0]),
            0.5 * (lo[1] + hi[1]),
            0.5 * (lo[2] + hi[2]),
        ];
        let r = (0..3)
            .map(|k| hi[k] - lo[k])
            .fold(0.0f64, f64::max)
            .max(1.0);
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        let static_eps = static_insphere_bound(extent);
        let s = 1000.0 * r;
        pos.push([c[0] - s, c[1] - s, c[2] - s]);
        pos.push([c[0] + 3.0 * s, c[1] - s, c[2] - s]);
        pos.push([c[0] - s, c[1] + 3.0 * s, c[2] - s]);
        pos.push([c[0] - s, c[1] - s, c[2] + 3.0 * s]);
        let n = n_real;
        let mut tet = [n, n + 1, n + 2, n + 3];
        if orient3d(
            &pos[tet[0] as usize],
            &pos[tet[1] as usize],
            &pos[tet[2] as usize],
            &pos[tet[3] as usize],
        ) < 0
        {
            tet.swap(0, 1);
        }
        let mut tets = Vec::with_capacity(7 * pos.len() + 16);
        tets.push(Tet {
            v: tet,
            n: [NONE; 4],
            mark: 0,
        });
        Self {
            pos,
            n_real,
            static_eps,
            tets,
            free: Vec::new(),
            rng: SplitMix(12345),
            stack: Vec::new(),
            cavity: Vec::new(),
            boundary: Vec::new(),
            new_tets: Vec::new(),
            table: vec![(EMPTY_KEY, 0, 0); 256],
            used: Vec::new(),
        }
    }

    #[inline]
    fn p(&self, v: u32) -> &[f64; 3] {
        &self.pos[v as usize]
    }

    fn run(mut self) -> Delaunay {
        let n = self.n_real as usize;
        let (mut lo, mut hi) = ([0.0f64; 3], [0.0f64; 3]);
        if n > 0 {
            lo = self.pos[0];
            hi = self.pos[0];
        }
        for p in &self.pos[..n] {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let order = brio_order(&self.pos[..n], lo, hi);
        let mut last = 0u32;
        for (it, &v) in order.iter().enumerate() {
            let t = self.locate(last, v);
            last = self.insert(v, t, it as u32);
        }
        self.finish()
    }

    #[inline]
    fn face_sees(&self, tv: [u32; 4], k: usize, p: &[f64; 3]) -> i32 {
        let mut q = [self.p(tv[0]), self.p(tv[1]), self.p(tv[2]), self.p(tv[3])];
        q[k] = p;
        orient3d(q[0], q[1], q[2], q[3])
    }

    /// Stochastic visibility walk from `start` to a tet containing point `v`.
    fn locate(&mut self, start: u32, v: u32) -> u32 {
        let p = self.pos[v as usize];
        let mut t = start;
        let mut prev = NONE;
        let max_steps = 64 + 4 * self.tets.len();
        for _ in 0..max_steps {
            let tet = self.tets[t as usize];
            let r = (self.rng.next() & 3) as usize;
            let mut moved = false;
            for j in 0..4 {
                let k = (r + j) & 3;
                let nb = tet.n[k];
                if nb == NONE || nb == prev {
                    continue;
                }
                if self.face_sees(tet.v, k, &p) < 0 {
                    prev = t;
                    t = nb;
                    moved = true;
                    break;
                }
            }
            if !moved {
                // `prev` was skipped: p is strictly in front of the face we came through.
                return t;
            }
        }
        // Safety net (never expected): scan for a containing tet.
        (0..self.tets.len() as u32)
            .find(|&t| {
                let tet = self.tets[t as usize];
                tet.mark != DEAD && (0..4).all(|k| self.face_sees(tet.v, k, &p) >= 0)
            })
            .unwrap_or(t)
    }

    #[inline]
    fn conflicts(&self, tv: [u32; 4], v: u32) -> bool {
        let n = self.n_real;
        let eps = if tv[0] < n && tv[1] < n && tv[2] < n && tv[3] < n {
            self.static_eps
        } else {
            f64::INFINITY
        };
        in_conflict_bounded(
            [self.p(tv[0]), self.p(tv[1]), self.p(tv[2]), self.p(tv[3])],
            tv,
            self.p(v),
            v,
            eps,
        )
    }

    /// Inserts vertex `v` located in tet `t`; returns one of the new tets.
    fn insert(&mut self, v: u32, t: u32, it: u32) -> u32 {
        let in_cav = 2 * it + 1;
        let not_cav = 2 * it + 2;
        self.cavity.clear();
        self.boundary.clear();
        self.stack.clear();
        self.stack.push(t);
        self.tets[t as usize].mark = in_cav;
        while let Some(c) = self.stack.pop() {
            self.cavity.push(c);
            let cn = self.tets[c as usize].n;
            for k in 0..4u8 {
                let nb = cn[k as usize];
                if nb == NONE {
                    self.boundary.push((c, k, NONE, 0));
                    continue;
                }
                let nt = self.tets[nb as usize];
                if nt.mark == in_cav {
                    continue;
                }
                if nt.mark != not_cav && self.conflicts(nt.v, v) {
                    self.tets[nb as usize].mark = in_cav;
                    self.stack.push(nb);
                } else {
                    self.tets[nb as usize].mark = not_cav;
                    let j =
                        nt.n.iter()
                            .position(|&x| x == c)
                            .expect("adjacency is symmetric") as u8;
                    self.boundary.push((c, k, nb, j));
                }
            }
        }
        // New tets: one per boundary face, the cavity tet's vertex k replaced by v. Read the
        // cavity tets' vertices before their slots are reused.
        self.new_tets.clear();
        for &(c, k, _, _) in &self.boundary {
            let mut tv = self.tets[c as usize].v;
            tv[k as usize] = v;
            self.new_tets.push((tv, 0, k));
        }
        let mut reuse = 0usize;
        for i in 0..self.new_tets.len() {
            let id = if reuse < self.cavity.len() {
                reuse += 1;
                self.cavity[reuse - 1]
            } else if let Some(f) = self.free.pop() {
                f
            } else {
                self.tets.push(Tet {
                    v: [0; 4],
                    n: [NONE; 4],
                    mark: 0,
                });
                (self.tets.len() - 1) as u32
            };
            self.new_tets[i].1 = id;
        }
        for i in reuse..self.cavity.len() {
            let c = self.cavity[i];
            self.tets[c as usize].mark = DEAD;
            self.free.push(c);
        }
        // Size the edge table (3 entries per new tet, load <= 1/2).
        let need = (6 * self.new_tets.len()).next_power_of_two().max(256);
        if self.table.len() < need {
            self.table = vec![(EMPTY_KEY, 0, 0); need];
        }
        let mask = self.table.len() - 1;
        let mut used_slots = std::mem::take(&mut self.used);
        used_slots.clear();
        for i in 0..self.new_tets.len() {
            let (tv, id, k) = self.new_tets[i];
            let (_, _, nb, j) = self.boundary[i];
            self.tets[id as usize] = Tet {
                v: tv,
                n: [NONE; 4],
                mark: 0,
            };
            self.tets[id as usize].n[k as usize] = nb;
            if nb != NONE {
                self.tets[nb as usize].n[j as usize] = id;
            }
            debug_assert!(
                orient3d(self.p(tv[0]), self.p(tv[1]), self.p(tv[2]), self.p(tv[3])) > 0,
                "flat or inverted tet created"
            );
            for f in 0..4u8 {
                if f == k {
                    continue;
                }
                // The face opposite f contains v and the two vertices other than f and k.
                let [i0, i1] = OTHER_TWO[f as usize][k as usize];
                let e = [tv[i0], tv[i1]];
                let key = ((e[0].min(e[1]) as u64) << 32) | e[0].max(e[1]) as u64;
                let mut h = (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as usize & mask;
                loop {
                    let slot = self.table[h];
                    if slot.0 == EMPTY_KEY {
                        self.table[h] = (key, id, f);
                        used_slots.push(h);
                        break;
                    }
                    if slot.0 == key {
                        let (_, a, fa) = slot;
                        self.tets[a as usize].n[fa as usize] = id;
                        self.tets[id as usize].n[f as usize] = a;
                        break;
                    }
                    h = (h + 1) & mask;
                }
            }
        }
        for &h in &used_slots {
            self.table[h].0 = EMPTY_KEY;
        }
        self.used = used_slots;
        self.new_tets[0].1
    }

    fn finish(self) -> Delaunay {
        let n = self.n_real;
        let mut remap = vec![NONE; self.tets.len()];
        let mut tets = Vec::new();
        for (t, tet) in self.tets.iter().enumerate() {
            if tet.mark != DEAD && tet.v.iter().all(|&v| v < n) {
                remap[t] = tets.len() as u32;
                tets.push(tet.v);
            }
        }
        let mut neighbors = Vec::with_capacity(tets.len());
        for (t, tet) in self.tets.iter().enumerate() {
            if remap[t] != NONE {
                neighbors.push(
                    tet.n
                        .map(|x| if x == NONE { NONE } else { remap[x as usize] }),
                );
            }
        }
        let mut vertices = self.pos;
        vertices.truncate(n as usize);
        Delaunay {
            vertices,
            vertex_of_point: Vec::new(),
            tets,
            neighbors,
        }
    }
}
