//! Winograd F(2x2x2, 3x3x3) convolutions: the encoder's 3x3x3 layers (stride 1, padding 1)
//! with 64 multiplications per 2x2x2 output block where the direct (im2col) form takes 216.
//!
//! Each 4x4x4 input block `d` (blocks overlap by two nodes) and each 3x3x3 filter `g` are
//! transformed along every axis (`V = B^T d B`, `U = G g G^T`); the product of the two is
//! then, for each of the 64 transformed positions ("frequencies") `f`, one GEMM over the
//! blocks: `M[f] = V[f] U[f]` (`[blocks, cin] x [cin, cout]`); the output block is
//! `Y = A^T M A`. With the transforms linear, the input gradient is the same computation on
//! the output gradient with the flipped filters, and the weight gradient is one GEMM per
//! frequency, `dU[f] = V[f]^T dM[f]` with `dM = A dY A^T`, mapped back by `G^T dU G`. So all
//! three passes of a training step take 64 / 216 of the direct form's GEMM work (1 / 3.4),
//! plus the transforms (linear in the data).
//!
//! Matrices (Lavin and Gray 2016, interpolation points 0, 1, -1): `B^T = [[1, 0, -1, 0], [0,
//! 1, 1, 0], [0, -1, 1, 0], [0, 1, 0, -1]]`, `G = [[1, 0, 0], [1/2, 1/2, 1/2], [1/2, -1/2,
//! 1/2], [0, 0, 1]]`, `A^T = [[1, 1, 1, 0], [0, 1, -1, -1]]`: every coefficient is 0, +-1 or
//! +-1/2, so the transforms round no more than sums do (the results match the direct form to
//! float accuracy: tested against an f64 reference).
//!
//! Written here because no crate does 3D Winograd convolutions on channels-last data (the
//! GEMMs are the `gemm` crate's, as everywhere in [`super`]). f32 only: with bf16 the direct
//! form's GEMMs are already twice as fast and the transforms would round the inputs again.

use std::cell::RefCell;
use std::ops::Range;

use rayon::prelude::*;

use super::kernels::{Act, ConvShape, Precision, mm, parts};

/// Smallest channel count (input and output) for which the Winograd form is used (the
/// transforms' memory traffic grows relative to the GEMMs as channels shrink). `kernel_bench`
/// measures it 1.6-2.2x faster than the direct form at 32, 48 and 128 channels in all three
/// passes; narrower layers keep the direct form (not measured).
pub const MIN_CHANNELS: usize = 32;

/// Blocks per GEMM (at most): the transformed blocks of a group (`64 x BLOCKS x channels`)
/// are built, multiplied and transformed back in one go.
const BLOCKS: usize = 256;

/// Transformed positions per block (4^3).
const F: usize = 64;

/// Distance between two positions' `[BLOCKS, c]` matrices in the group buffers: one cache
/// line more than their size, so that a block's 64 positions (read or written together) do
/// not all fall in the same cache set (`BLOCKS c` floats is a power of two for the usual
/// widths). A precaution: no change measured at width 128 on this machine.
fn fstride(c: usize) -> usize {
    BLOCKS * c + 16
}

/// Whether [`conv_forward`], [`conv_input_grad`] and [`conv_weight_grad`] serve the
/// convolution `s` in precision `prec`: 3x3x3 kernels with padding 1 in f32 (what runs on
/// this CPU), at least [`MIN_CHANNELS`] channels in and out.
pub fn applies(s: &ConvShape, prec: Precision) -> bool {
    s.k == 3
        && s.pad == 1
        && prec.effective() == Precision::F32
        && s.cin >= MIN_CHANNELS
        && s.cout >= MIN_CHANNELS
}

/// The 2x2x2 output blocks of a grid: `n[a] = ceil(o[a] / 2)` per axis. Blocks are grouped
/// in slabs (one batch item, one block row along the first axis), whose output rows are
/// contiguous: the unit of parallel work.
#[derive(Clone, Copy, Debug)]
struct Blocks {
    batch: usize,
    /// Grid size per axis (input = output for 3x3x3 with padding 1).
    o: [usize; 3],
    n: [usize; 3],
}

impl Blocks {
    fn new(s: &ConvShape) -> Self {
        let o = s.dims;
        Self {
            batch: s.batch,
            o,
            n: o.map(|v| v.div_ceil(2)),
        }
    }

    fn slabs(&self) -> usize {
        self.batch * self.n[0]
    }

    fn slab_blocks(&self) -> usize {
        self.n[1] * self.n[2]
    }

    /// Output rows of slab `slab`.
    fn slab_rows(&self, slab: usize) -> Range<usize> {
        let (b, t) = (slab / self.n[0], slab % self.n[0]);
        let plane = self.o[1] * self.o[2];
        let i0 = b * self.o[0] + 2 * t;
        let i1 = b * self.o[0] + (2 * t + 2).min(self.o[0]);
        i0 * plane..i1 * plane
    }

    /// `V = B^T d B` of the 4x4x4 input block `q` of slab `slab` (zeros outside the grid),
    /// position `f` written to `v[f fs + off ..]`; `d` (`[64, c]`) is scratch, `zero` `c`
    /// zeros. The gather is fused with the first axis' transform, the last axis' with the
    /// write.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn transform_input(
        &self,
        x: &[f32],
        c: usize,
        (slab, q): (usize, usize),
        zero: &[f32],
        d: &mut [f32],
        v: &mut [f32],
        (off, fs): (usize, usize),
    ) {
        let (b, t1) = (slab / self.n[0], slab % self.n[0]);
        let (t2, t3) = (q / self.n[2], q % self.n[2]);
        let [o0, o1, o2] = self.o;
        let zero = &zero[..c];
        for a in 0..4 {
            let i = (2 * t1 + a) as isize - 1;
            for bb in 0..4 {
                let j = (2 * t2 + bb) as isize - 1;
                let [o0_, o1_, o2_, o3_] = four(d, (a * 4 + bb) * 4 * c, c, c);
                if i < 0 || i >= o0 as isize || j < 0 || j >= o1 as isize {
                    for v in [o0_, o1_, o2_, o3_] {
                        v.fill(0.0);
                    }
                    continue;
                }
                let line = ((b * o0 + i as usize) * o1 + j as usize) * o2;
                let node = |e: usize| {
                    let l = (2 * t3 + e) as isize - 1;
                    if l < 0 || l >= o2 as isize {
                        zero
                    } else {
                        &x[(line + l as usize) * c..(line + l as usize + 1) * c]
                    }
                };
                bt_line(node(0), node(1), node(2), node(3), o0_, o1_, o2_, o3_);
            }
        }
        bt_middle(d, c);
        for be in 0..16 {
            let src = |a: usize| &d[(a * 16 + be) * c..(a * 16 + be + 1) * c];
            let [v0, v1, v2, v3] = four(v, off + be * fs, 16 * fs, c);
            bt_line(src(0), src(1), src(2), src(3), v0, v1, v2, v3);
        }
    }

    /// The output rows (relative to the slab's first row) of block `q`'s eight nodes, `None`
    /// for nodes outside the grid; in the order `(a, b, c)` of [`output_transform`].
    fn block_rows(&self, q: usize) -> [Option<usize>; 8] {
        let (t2, t3) = (q / self.n[2], q % self.n[2]);
        let mut r = [None; 8];
        for a in 0..2 {
            for b in 0..2 {
                for c in 0..2 {
                    let (j, l) = (2 * t2 + b, 2 * t3 + c);
                    if j < self.o[1] && l < self.o[2] {
                        r[(a * 2 + b) * 2 + c] = Some((a * self.o[1] + j) * self.o[2] + l);
                    }
                }
            }
        }
        r
    }
}

/// Four channel vectors `v[s0 + i stride .. + c]`, `i < 4`, as disjoint mutable slices.
#[inline(always)]
fn four(v: &mut [f32], s0: usize, stride: usize, c: usize) -> [&mut [f32]; 4] {
    let (_, rest) = v.split_at_mut(s0);
    let (a, rest) = rest.split_at_mut(stride);
    let (b, rest) = rest.split_at_mut(stride);
    let (cc, rest) = rest.split_at_mut(stride);
    [&mut a[..c], &mut b[..c], &mut cc[..c], &mut rest[..c]]
}

/// One line of `B^T` from `d` into `o`: `(d0 - d2, d1 + d2, d2 - d1, d1 - d3)`.
/// (Each slice a parameter of its own: Rust marks those as not aliasing, which lets the
/// loop vectorize; slices inside an array argument lose that.)
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn bt_line(
    d0: &[f32],
    d1: &[f32],
    d2: &[f32],
    d3: &[f32],
    o0: &mut [f32],
    o1: &mut [f32],
    o2: &mut [f32],
    o3: &mut [f32],
) {
    let n = o0.len();
    let (d0, d1, d2, d3) = (&d0[..n], &d1[..n], &d2[..n], &d3[..n]);
    let (o1, o2, o3) = (&mut o1[..n], &mut o2[..n], &mut o3[..n]);
    for i in 0..n {
        let (a, b, e, f) = (d0[i], d1[i], d2[i], d3[i]);
        o0[i] = a - e;
        o1[i] = b + e;
        o2[i] = e - b;
        o3[i] = b - f;
    }
}

/// `B^T` in place along the middle axis (stride 4c) of a `[4, 4, 4, c]` block.
#[inline(always)]
fn bt_middle(d: &mut [f32], c: usize) {
    for a in 0..4 {
        for e in 0..4 {
            let [d0, d1, d2, d3] = four(d, (a * 16 + e) * c, 4 * c, c);
            bt_in_place(d0, d1, d2, d3);
        }
    }
}

/// [`bt_line`] in place (the middle pass: out of place it would need a second block buffer,
/// and the two would no longer fit in L1 together at 128 channels).
#[inline(always)]
fn bt_in_place(d0: &mut [f32], d1: &mut [f32], d2: &mut [f32], d3: &mut [f32]) {
    let n = d0.len();
    let (d1, d2, d3) = (&mut d1[..n], &mut d2[..n], &mut d3[..n]);
    for i in 0..n {
        let (p, q, r, t) = (d0[i], d1[i], d2[i], d3[i]);
        d0[i] = p - r;
        d1[i] = q + r;
        d2[i] = r - q;
        d3[i] = q - t;
    }
}

/// One line of `A^T`: `y0 = m0 + m1 + m2`, `y1 = m1 - m2 - m3`.
#[inline(always)]
fn at_line(m0: &[f32], m1: &[f32], m2: &[f32], m3: &[f32], y0: &mut [f32], y1: &mut [f32]) {
    let n = y0.len();
    let (m0, m1, m2, m3, y1) = (&m0[..n], &m1[..n], &m2[..n], &m3[..n], &mut y1[..n]);
    for i in 0..n {
        y0[i] = m0[i] + m1[i] + m2[i];
        y1[i] = m1[i] - m2[i] - m3[i];
    }
}

/// One line of `A`: `m0 = g0`, `m1 = g0 + g1`, `m2 = g0 - g1`, `m3 = -g1`.
#[inline(always)]
fn a_line(g0: &[f32], g1: &[f32], m0: &mut [f32], m1: &mut [f32], m2: &mut [f32], m3: &mut [f32]) {
    let n = m0.len();
    let (g0, g1) = (&g0[..n], &g1[..n]);
    let (m1, m2, m3) = (&mut m1[..n], &mut m2[..n], &mut m3[..n]);
    for i in 0..n {
        let (a, b) = (g0[i], g1[i]);
        m0[i] = a;
        m1[i] = a + b;
        m2[i] = a - b;
        m3[i] = -b;
    }
}

/// `A^T m A` of a `[4, 4, 4, c]` block whose position `f` is at `m[f fs + off ..]` (the
/// block's column of the group's GEMM products) into `y` (`[2, 2, 2, c]`); `t1` (`[4, 4, 2,
/// c]`) and `t2` (`[4, 2, 2, c]`) are scratch.
#[inline(always)]
fn output_transform(
    m: &[f32],
    (off, fs): (usize, usize),
    c: usize,
    t1: &mut [f32],
    t2: &mut [f32],
    y: &mut [f32],
) {
    let at = |f: usize| &m[off + f * fs..off + f * fs + c];
    // Along the last axis: 16 lines of 4 -> 2.
    for line in 0..16 {
        let (y0, y1) = t1[line * 2 * c..(line + 1) * 2 * c].split_at_mut(c);
        let f = line * 4;
        at_line(at(f), at(f + 1), at(f + 2), at(f + 3), y0, y1);
    }
    // Middle axis: for each (a, e): 4 -> 2, stride 2c in t1.
    for a in 0..4 {
        for e in 0..2 {
            let at = |b: usize| &t1[(a * 8 + b * 2 + e) * c..(a * 8 + b * 2 + e + 1) * c];
            let (o0, o1) = ((a * 4 + e) * c, (a * 4 + 2 + e) * c);
            let (lo, hi) = t2.split_at_mut(o1);
            at_line(
                at(0),
                at(1),
                at(2),
                at(3),
                &mut lo[o0..o0 + c],
                &mut hi[..c],
            );
        }
    }
    // First axis: for each of the 4 (b, e): 4 -> 2, stride 4c in t2.
    for be in 0..4 {
        let at = |a: usize| &t2[(a * 4 + be) * c..(a * 4 + be + 1) * c];
        let (lo, hi) = y.split_at_mut(4 * c);
        at_line(
            at(0),
            at(1),
            at(2),
            at(3),
            &mut lo[be * c..(be + 1) * c],
            &mut hi[be * c..(be + 1) * c],
        );
    }
}

/// `dM = A dY A^T` of a `[2, 2, 2, c]` output-gradient block, position `f` written to
/// `dm[f fs + off ..]`; `t1` (`[2, 2, 4, c]`) and `t2` (`[2, 4, 4, c]`) are scratch. The
/// adjoint of [`output_transform`].
#[inline(always)]
fn output_transform_adjoint(
    g: &[f32],
    c: usize,
    t1: &mut [f32],
    t2: &mut [f32],
    dm: &mut [f32],
    (off, fs): (usize, usize),
) {
    // Last axis: 4 lines of 2 -> 4.
    for line in 0..4 {
        let (g0, g1) = g[line * 2 * c..(line + 1) * 2 * c].split_at(c);
        let [m0, m1, m2, m3] = four(&mut t1[line * 4 * c..(line + 1) * 4 * c], 0, c, c);
        a_line(g0, g1, m0, m1, m2, m3);
    }
    // Middle axis: for each (a, e), 2 -> 4 (stride 4c in t1, 4c in t2).
    for a in 0..2 {
        for e in 0..4 {
            let g0 = &t1[(a * 8 + e) * c..(a * 8 + e) * c + c];
            let g1 = &t1[(a * 8 + 4 + e) * c..(a * 8 + 4 + e) * c + c];
            let [m0, m1, m2, m3] = four(t2, (a * 16 + e) * c, 4 * c, c);
            a_line(g0, g1, m0, m1, m2, m3);
        }
    }
    // First axis: for each of the 16 (b, e), 2 -> 4 (positions be + 16 a).
    for be in 0..16 {
        let g0 = &t2[be * c..be * c + c];
        let g1 = &t2[(16 + be) * c..(16 + be) * c + c];
        let [m0, m1, m2, m3] = four(dm, off + be * fs, 16 * fs, c);
        a_line(g0, g1, m0, m1, m2, m3);
    }
}

/// `G` applied to a 3-vector.
fn g3(v: [f64; 3]) -> [f64; 4] {
    [
        v[0],
        0.5 * (v[0] + v[1] + v[2]),
        0.5 * (v[0] - v[1] + v[2]),
        v[2],
    ]
}

/// `G^T` applied to a 4-vector (the adjoint of [`g3`]).
fn gt4(u: [f64; 4]) -> [f64; 3] {
    [
        u[0] + 0.5 * (u[1] + u[2]),
        0.5 * (u[1] - u[2]),
        0.5 * (u[1] + u[2]) + u[3],
    ]
}

/// `U[f] = G g G^T` of every filter of a `[cout, cin, 3, 3, 3]` weight, as `[64, cin, cout]`
/// (the right-hand sides of the 64 GEMMs).
fn weight_transform(w: &[f32], cin: usize, cout: usize) -> Vec<f32> {
    assert_eq!(w.len(), cout * cin * 27);
    let mut u = vec![0.0f32; F * cin * cout];
    // Output channels innermost: the 64 writes of consecutive filters share cache lines.
    for ci in 0..cin {
        for co in 0..cout {
            let g = &w[(co * cin + ci) * 27..(co * cin + ci + 1) * 27];
            // Last axis, then middle, then first (f64: the factors 1/2 are exact anyway).
            let mut t1 = [[[0.0f64; 4]; 3]; 3];
            for a in 0..3 {
                for b in 0..3 {
                    let k = (a * 3 + b) * 3;
                    t1[a][b] = g3([g[k], g[k + 1], g[k + 2]].map(f64::from));
                }
            }
            let mut t2 = [[[0.0f64; 4]; 4]; 3];
            for a in 0..3 {
                for e in 0..4 {
                    let v = g3([t1[a][0][e], t1[a][1][e], t1[a][2][e]]);
                    for b in 0..4 {
                        t2[a][b][e] = v[b];
                    }
                }
            }
            for b in 0..4 {
                for e in 0..4 {
                    let v = g3([t2[0][b][e], t2[1][b][e], t2[2][b][e]]);
                    for a in 0..4 {
                        u[(((a * 4 + b) * 4 + e) * cin + ci) * cout + co] = v[a] as f32;
                    }
                }
            }
        }
    }
    u
}

/// `dW = G^T dU G` of `[64, cin, cout]` (f64) as a `[cout, cin, 3, 3, 3]` weight gradient.
fn weight_transform_adjoint(du: &[f64], cin: usize, cout: usize) -> Vec<f32> {
    let mut w = vec![0.0f32; cout * cin * 27];
    // Output channels innermost: the 64 reads of consecutive filters share cache lines.
    for ci in 0..cin {
        for co in 0..cout {
            let at = |f: usize| du[(f * cin + ci) * cout + co];
            let mut t1 = [[[0.0f64; 3]; 4]; 4];
            for a in 0..4 {
                for b in 0..4 {
                    let k = (a * 4 + b) * 4;
                    t1[a][b] = gt4([at(k), at(k + 1), at(k + 2), at(k + 3)]);
                }
            }
            let mut t2 = [[[0.0f64; 3]; 3]; 4];
            for a in 0..4 {
                for e in 0..3 {
                    let v = gt4([t1[a][0][e], t1[a][1][e], t1[a][2][e], t1[a][3][e]]);
                    for b in 0..3 {
                        t2[a][b][e] = v[b];
                    }
                }
            }
            for b in 0..3 {
                for e in 0..3 {
                    let v = gt4([t2[0][b][e], t2[1][b][e], t2[2][b][e], t2[3][b][e]]);
                    for a in 0..3 {
                        w[(co * cin + ci) * 27 + (a * 3 + b) * 3 + e] = v[a] as f32;
                    }
                }
            }
        }
    }
    w
}

/// A thread's buffers for a group of blocks.
#[derive(Default)]
struct Scratch {
    /// Transformed inputs `[64, BLOCKS, cin]` (position stride [`fstride`]).
    v: Vec<f32>,
    /// GEMM products (or transformed output gradients) `[64, BLOCKS, cout]` (the same).
    m: Vec<f32>,
    /// One block, `[64, max(cin, cout)]`, the transforms' scratch and a zero vector.
    d: Vec<f32>,
    t1: Vec<f32>,
    t2: Vec<f32>,
    y: Vec<f32>,
    zero: Vec<f32>,
}

impl Scratch {
    /// Grows the buffers to `cin` / `cout` channels (never shrinks them).
    fn ensure(&mut self, cin: usize, cout: usize) {
        let c = cin.max(cout);
        for (buf, n) in [
            (&mut self.v, F * fstride(cin)),
            (&mut self.m, F * fstride(cout)),
            (&mut self.d, F * c),
            (&mut self.t1, 32 * c),
            (&mut self.t2, 32 * c),
            (&mut self.y, 8 * c),
            (&mut self.zero, c),
        ] {
            if buf.len() < n {
                buf.resize(n, 0.0);
            }
        }
    }
}

/// Defines `$name(args)` that runs `$body(args)` compiled for AVX-512 where the CPU has it
/// (runtime detection; the portable build targets baseline x86-64, whose SSE2 code runs the
/// transforms' channel loops at a quarter of the width) and as portable code elsewhere.
macro_rules! multiversion {
    ($(#[$m:meta])* fn $name:ident => $body:ident ($($arg:ident : $ty:ty),* $(,)?)) => {
        $(#[$m])*
        fn $name($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx512f") {
                #[target_feature(enable = "avx512f")]
                fn avx512($($arg: $ty),*) {
                    $body($($arg),*)
                }
                // SAFETY: the CPU has AVX-512F (checked above).
                return unsafe { avx512($($arg),*) };
            }
            $body($($arg),*)
        }
    };
}

multiversion! {
    /// Transforms the input blocks `qs` of `slab` into `scr.v` (`[64, BLOCKS, cin]`).
    fn transform_inputs => transform_inputs_body(
        scr: &mut Scratch,
        bl: &Blocks,
        x: &[f32],
        cin: usize,
        slab: usize,
        qs: Range<usize>,
    )
}

#[inline(always)]
fn transform_inputs_body(
    scr: &mut Scratch,
    bl: &Blocks,
    x: &[f32],
    cin: usize,
    slab: usize,
    qs: Range<usize>,
) {
    for (i, q) in qs.enumerate() {
        bl.transform_input(
            x,
            cin,
            (slab, q),
            &scr.zero,
            &mut scr.d,
            &mut scr.v,
            (i * cin, fstride(cin)),
        );
    }
}

multiversion! {
    /// `Y = act(A^T M A + b)` of the blocks `qs` of a slab from `scr.m`, written to the rows
    /// of `ys` (the slab's `slab_len` rows) inside the grid.
    #[allow(clippy::too_many_arguments)]
    fn transform_outputs => transform_outputs_body(
        scr: &mut Scratch,
        bl: &Blocks,
        qs: Range<usize>,
        cout: usize,
        bias: &[f32],
        act: Act,
        ys: &mut [f32],
        slab_len: usize,
    )
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn transform_outputs_body(
    scr: &mut Scratch,
    bl: &Blocks,
    qs: Range<usize>,
    cout: usize,
    bias: &[f32],
    act: Act,
    ys: &mut [f32],
    slab_len: usize,
) {
    let bias = &bias[..cout];
    for (i, q) in qs.enumerate() {
        output_transform(
            &scr.m,
            (i * cout, fstride(cout)),
            cout,
            &mut scr.t1,
            &mut scr.t2,
            &mut scr.y,
        );
        for (k, r) in bl.block_rows(q).into_iter().enumerate() {
            if let Some(r) = r
                && r < slab_len
            {
                let src = &scr.y[k * cout..(k + 1) * cout];
                let dst = &mut ys[r * cout..(r + 1) * cout];
                match act {
                    Act::Identity => {
                        for c in 0..cout {
                            dst[c] = src[c] + bias[c];
                        }
                    }
                    Act::Leaky(slope) => {
                        for c in 0..cout {
                            let z = src[c] + bias[c];
                            dst[c] = if z > 0.0 { z } else { z * slope };
                        }
                    }
                }
            }
        }
    }
}

multiversion! {
    /// `dM = A dY A^T` of the blocks `qs` of a slab into `scr.m`, from `g` (the slab's rows
    /// of the output gradient; zeros outside the grid).
    fn transform_output_grads => transform_output_grads_body(
        scr: &mut Scratch,
        bl: &Blocks,
        qs: Range<usize>,
        cout: usize,
        g: &[f32],
    )
}

#[inline(always)]
fn transform_output_grads_body(
    scr: &mut Scratch,
    bl: &Blocks,
    qs: Range<usize>,
    cout: usize,
    g: &[f32],
) {
    for (i, q) in qs.enumerate() {
        let yb = &mut scr.y[..8 * cout];
        for (k, r) in bl.block_rows(q).into_iter().enumerate() {
            let dst = &mut yb[k * cout..(k + 1) * cout];
            match r {
                Some(r) if r * cout < g.len() => dst.copy_from_slice(&g[r * cout..(r + 1) * cout]),
                _ => dst.fill(0.0),
            }
        }
        output_transform_adjoint(
            yb,
            cout,
            &mut scr.t1,
            &mut scr.t2,
            &mut scr.m,
            (i * cout, fstride(cout)),
        );
    }
}

thread_local! {
    /// Each thread's [`Scratch`], kept from call to call (2 x 64 x BLOCKS x channels floats:
    /// 16 MB per thread at 128 channels): fresh zeroed buffers cost ~10% of a call.
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// Runs `f` with this thread's [`Scratch`], grown for `cin` / `cout` channels. `f` must not
/// call back into this module (it does not: the GEMMs run on the calling thread).
fn with_scratch<R>(cin: usize, cout: usize, f: impl FnOnce(&mut Scratch) -> R) -> R {
    SCRATCH.with(|cell| {
        let mut scr = cell.borrow_mut();
        scr.ensure(cin, cout);
        f(&mut scr)
    })
}

/// `Y = act(conv(X, W) + b)` for a 3x3x3, padding-1 convolution ([`applies`]): `x` is `[B,
/// D1, D2, D3, cin]`, `w` the `[cout, cin, 3, 3, 3]` weight (not packed); returns `[B, D1, D2,
/// D3, cout]`, as [`super::kernels::conv_forward`] does.
pub fn conv_forward(
    x: &[f32],
    s: &ConvShape,
    w: &[f32],
    bias: Option<&[f32]>,
    act: Act,
) -> Vec<f32> {
    assert!(s.k == 3 && s.pad == 1, "winograd: {s:?}");
    let (cin, cout) = (s.cin, s.cout);
    assert_eq!(x.len(), s.in_rows() * cin);
    let rows = s.out_rows();
    let mut y = vec![0.0f32; rows * cout];
    if rows == 0 || cout == 0 {
        return y;
    }
    let u = weight_transform(w, cin, cout);
    let zero = vec![0.0f32; cout];
    let bias = bias.unwrap_or(&zero);
    let bl = Blocks::new(s);
    // Fixed parts of the slabs (contiguous output rows), one task each.
    let ranges = parts(bl.slabs(), 1);
    let mut chunks: Vec<((usize, usize), &mut [f32])> = Vec::with_capacity(ranges.len());
    let mut rest: &mut [f32] = &mut y;
    for &(a, b) in &ranges {
        let len = (bl.slab_rows(b - 1).end - bl.slab_rows(a).start) * cout;
        let (head, tail) = std::mem::take(&mut rest).split_at_mut(len);
        chunks.push(((a, b), head));
        rest = tail;
    }
    debug_assert!(rest.is_empty());
    chunks.into_par_iter().for_each(|((a, b), yp)| {
        with_scratch(cin, cout, |scr| {
            let base = bl.slab_rows(a).start;
            for slab in a..b {
                let r0 = bl.slab_rows(slab).start - base;
                let ys = &mut yp[r0 * cout..];
                let slab_len = bl.slab_rows(slab).len();
                let nb = bl.slab_blocks();
                for g0 in (0..nb).step_by(BLOCKS) {
                    let qs = g0..(g0 + BLOCKS).min(nb);
                    let n = qs.len();
                    transform_inputs(scr, &bl, x, cin, slab, qs.clone());
                    for f in 0..F {
                        // SAFETY: V[f] is [n, cin] (row stride cin), U[f] [cin, cout], M[f]
                        // [n, cout]: inside the buffers, sized for BLOCKS >= n blocks.
                        unsafe {
                            mm(
                                n,
                                cout,
                                cin,
                                &mut scr.m[f * fstride(cout)..],
                                cout,
                                false,
                                &scr.v[f * fstride(cin)..],
                                (cin, 1),
                                &u[f * cin * cout..],
                                (cout, 1),
                                Precision::F32,
                            )
                        };
                    }
                    transform_outputs(scr, &bl, qs, cout, bias, act, ys, slab_len);
                }
            }
        })
    });
    y
}

/// Input gradient of a 3x3x3, padding-1 convolution: the same convolution of `dZ` (`[B, D1,
/// D2, D3, cout]`) with the flipped, transposed filters; `w` is the `[cout, cin, 3, 3, 3]`
/// weight. As [`super::kernels::conv_input_grad`].
pub fn conv_input_grad(s: &ConvShape, w: &[f32], gz: &[f32]) -> Vec<f32> {
    let wt = flip_filters(w, s.cin, s.cout);
    conv_forward(gz, &s.transposed(), &wt, None, Act::Identity)
}

/// The filters of the transposed convolution: `[cout, cin, 3, 3, 3]` -> `[cin, cout, 3, 3,
/// 3]` with the offsets reversed.
fn flip_filters(w: &[f32], cin: usize, cout: usize) -> Vec<f32> {
    assert_eq!(w.len(), cout * cin * 27);
    let mut wt = vec![0.0f32; w.len()];
    for co in 0..cout {
        for ci in 0..cin {
            for o in 0..27 {
                wt[(ci * cout + co) * 27 + 26 - o] = w[(co * cin + ci) * 27 + o];
            }
        }
    }
    wt
}

/// Weight gradient of a 3x3x3, padding-1 convolution, `[cout, cin, 3, 3, 3]`, as
/// [`super::kernels::conv_weight_grad`]: per fixed part of the slabs (the sums' order does not
/// depend on the thread count) `dU[f] += V[f]^T dM[f]`, the parts summed in f64.
pub fn conv_weight_grad(x: &[f32], s: &ConvShape, gz: &[f32]) -> Vec<f32> {
    assert!(s.k == 3 && s.pad == 1, "winograd: {s:?}");
    let (cin, cout) = (s.cin, s.cout);
    assert_eq!(x.len(), s.in_rows() * cin);
    assert_eq!(gz.len(), s.out_rows() * cout);
    let bl = Blocks::new(s);
    let partials: Vec<Vec<f32>> = parts(bl.slabs(), 1)
        .into_par_iter()
        .map(|(a, b)| {
            let mut du = vec![0.0f32; F * cin * cout];
            with_scratch(cin, cout, |scr| {
                let mut first = true;
                for slab in a..b {
                    let g = &gz[bl.slab_rows(slab).start * cout..bl.slab_rows(slab).end * cout];
                    let nb = bl.slab_blocks();
                    for g0 in (0..nb).step_by(BLOCKS) {
                        let qs = g0..(g0 + BLOCKS).min(nb);
                        let n = qs.len();
                        transform_inputs(scr, &bl, x, cin, slab, qs.clone());
                        transform_output_grads(scr, &bl, qs, cout, g);
                        for f in 0..F {
                            // SAFETY: V[f]^T is [cin, n] (row stride 1, column stride cin),
                            // dM[f] [n, cout], dU[f] [cin, cout]: inside the buffers.
                            unsafe {
                                mm(
                                    cin,
                                    cout,
                                    n,
                                    &mut du[f * cin * cout..(f + 1) * cin * cout],
                                    cout,
                                    !first,
                                    &scr.v[f * fstride(cin)..],
                                    (1, cin),
                                    &scr.m[f * fstride(cout)..],
                                    (cout, 1),
                                    Precision::F32,
                                )
                            };
                        }
                        first = false;
                    }
                }
            });
            du
        })
        .collect();
    let mut total = vec![0.0f64; F * cin * cout];
    for p in &partials {
        total
            .iter_mut()
            .zip(p)
            .for_each(|(t, v)| *t += f64::from(*v));
    }
    weight_transform_adjoint(&total, cin, cout)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fast::kernels::tests::conv_naive;
    use crate::fast::testing::{lcg, on_threads};

    /// The direct convolution of [`super::super::kernels`]' tests (f64 sums), no bias.
    fn conv_ref(x: &[f32], s: &ConvShape, w: &[f32]) -> Vec<f64> {
        conv_naive(x, s, w, &vec![0.0; s.cout])
            .into_iter()
            .map(f64::from)
            .collect()
    }

    fn shape(batch: usize, dims: [usize; 3], cin: usize, cout: usize) -> ConvShape {
        ConvShape {
            batch,
            dims,
            cin,
            cout,
            k: 3,
            pad: 1,
        }
    }

    /// Max |a - b| over max |b| (relative to the result's scale).
    fn rel(a: &[f32], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        let scale = b.iter().fold(1e-30f64, |m, v| m.max(v.abs()));
        a.iter()
            .zip(b)
            .map(|(x, y)| (f64::from(*x) - y).abs())
            .fold(0.0, f64::max)
            / scale
    }

    #[test]
    fn winograd_matches_the_direct_convolution_forward_and_backward() {
        // Odd and even sizes, a grid of 1, batch > 1, different channel counts in and out.
        for (k, (batch, dims, cin, cout)) in [
            (1, [4, 4, 4], 3, 5),
            (2, [5, 3, 7], 4, 6),
            (1, [1, 2, 3], 2, 2),
            (3, [6, 5, 2], 5, 3),
        ]
        .into_iter()
        .enumerate()
        {
            let s = shape(batch, dims, cin, cout);
            let seed = 10 * k as u64;
            let x = lcg(seed, s.in_rows() * cin);
            let w = lcg(seed + 1, cout * cin * 27);
            let gz = lcg(seed + 2, s.out_rows() * cout);
            let b = lcg(seed + 3, cout);
            // Forward (with bias and activation).
            let y = conv_forward(&x, &s, &w, Some(&b), Act::Leaky(0.1));
            let want: Vec<f64> = conv_ref(&x, &s, &w)
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    let z = v + f64::from(b[i % cout]);
                    if z > 0.0 { z } else { 0.1 * z }
                })
                .collect();
            assert!(rel(&y, &want) < 1e-5, "{s:?}: forward {}", rel(&y, &want));
            // Weight gradient dW[co, ci, o] = sum_p dZ[p, co] X[p + o - 1, ci] and input
            // gradient dX[p + o - 1, ci] = sum dZ[p, co] W[co, ci, o], straight from the
            // definition (y[p] reads x[p + o - 1] through offset o).
            let gw = conv_weight_grad(&x, &s, &gz);
            let gx = conv_input_grad(&s, &w, &gz);
            let o = s.dims;
            let mut want = vec![0.0f64; w.len()];
            let mut want_x = vec![0.0f64; x.len()];
            for bb in 0..batch {
                for i in 0..o[0] {
                    for j in 0..o[1] {
                        for l in 0..o[2] {
                            let row = ((bb * o[0] + i) * o[1] + j) * o[2] + l;
                            for off in 0..27 {
                                let (a, c, e) = (off / 9, (off / 3) % 3, off % 3);
                                let p = [i + a, j + c, l + e].map(|v| v as isize - 1);
                                if (0..3).any(|ax| p[ax] < 0 || p[ax] >= o[ax] as isize) {
                                    continue;
                                }
                                let xr = ((bb * o[0] + p[0] as usize) * o[1] + p[1] as usize)
                                    * o[2]
                                    + p[2] as usize;
                                for co in 0..cout {
                                    for ci in 0..cin {
                                        let g = f64::from(gz[row * cout + co]);
                                        want[(co * cin + ci) * 27 + off] +=
                                            g * f64::from(x[xr * cin + ci]);
                                        want_x[xr * cin + ci] +=
                                            g * f64::from(w[(co * cin + ci) * 27 + off]);
                                    }
                                }
                            }
                        }
                    }
                }
            }
            assert!(
                rel(&gw, &want) < 1e-5,
                "{s:?}: weight grad {}",
                rel(&gw, &want)
            );
            assert!(
                rel(&gx, &want_x) < 1e-5,
                "{s:?}: input grad {}",
                rel(&gx, &want_x)
            );
        }
    }

    #[test]
    fn winograd_groups_of_blocks_and_thread_counts_do_not_change_the_result() {
        // A slab of 17 x 17 blocks spans two groups of BLOCKS; batch 2, 3 slabs each.
        let s = shape(2, [5, 34, 33], 4, 3);
        let x = lcg(7, s.in_rows() * 4);
        let w = lcg(8, 3 * 4 * 27);
        let gz = lcg(9, s.out_rows() * 3);
        let run = |threads: usize| {
            on_threads(threads, || {
                (
                    conv_forward(&x, &s, &w, None, Act::Identity),
                    conv_weight_grad(&x, &s, &gz),
                )
            })
        };
        let (y1, g1) = run(1);
        let (y3, g3) = run(3);
        assert_eq!(y1, y3);
        assert_eq!(g1, g3);
        let want = conv_ref(&x, &s, &w);
        assert!(rel(&y1, &want) < 1e-5, "{}", rel(&y1, &want));
    }
}
