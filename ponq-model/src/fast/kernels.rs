//! Slice-level `f32` kernels of the fast CPU path (no Burn types): 3D convolutions and 1x1x1
//! layers on channels-last activations, forward and backward, with bias, LeakyReLU and the
//! residual add fused into the GEMM epilogue.
//!
//! Layouts: activations are `[rows, channels]` row-major, where the rows of a grid are its
//! nodes in C order (`[B, D1, D2, D3, C]`); weights keep Burn's `Conv3d` layout
//! `[Cout, Cin, k, k, k]` (so checkpoints are shared with the stock path) and are repacked per
//! call (cheap: at most 0.4 M values against tens of millions of activation values).
//!
//! GEMMs are the `gemm` crate's (the one Burn's `flex` backend uses): it picks its AVX-512,
//! AVX2+FMA or scalar micro-kernel at run time (`x86-v4` feature), so the build needs no
//! `target-cpu` flag. A convolution is an im2col GEMM over tiles of output rows: each tile's
//! im2col block stays in cache and the tiles run in parallel on rayon's threads (one GEMM
//! call per tile, no nested parallelism). The backward of a convolution is the same kernel
//! on the output gradient with the flipped, transposed weights (input gradient) and a
//! per-thread sum of `im2col(x)^T dZ` (weight gradient).
//!
//! Invariants the callers keep (checked with `assert!`, they are programming errors, never
//! user input): slice lengths match the shapes, `d + 2 pad >= k` on every axis.

use gemm::{Parallelism, gemm};
use rayon::prelude::*;

/// Activation fused after a layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Act {
    /// None (the decoder heads).
    Identity,
    /// LeakyReLU with this negative slope.
    Leaky(f32),
}

impl Act {
    #[inline]
    fn apply(self, z: f32) -> f32 {
        match self {
            Act::Identity => z,
            Act::Leaky(s) => {
                if z > 0.0 {
                    z
                } else {
                    s * z
                }
            }
        }
    }

    /// Derivative at the pre-activation whose activation is `y` (`y > 0` exactly when the
    /// pre-activation is: the slope is positive).
    #[inline]
    pub(super) fn slope_at_output(self, y: f32) -> f32 {
        match self {
            Act::Identity => 1.0,
            Act::Leaky(s) => {
                if y > 0.0 {
                    1.0
                } else {
                    s
                }
            }
        }
    }
}

/// The arithmetic of the kernels' GEMMs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    /// f32 products and sums (the `gemm` crate).
    #[default]
    F32,
    /// Inputs rounded to bf16, products summed in f32 ([`super::bf16`], AVX-512 BF16); where
    /// the CPU lacks it the f32 kernel runs instead (see [`Precision::effective`]).
    Bf16,
}

/// The shortest reduction (`k`) a bf16 GEMM is used for: below it the f32 kernel is faster
/// (`kernel_bench`: the width-32 / 48 networks' 1x1x1 layers, `k` = 32 / 48, run 10-20% slower
/// in bf16, where the k3 convolutions (`k` = 27 x width) and width-128 1x1x1 layers run
/// 1.5-2.5x faster): the inputs are converted per call and `k` is padded to 32 per tile.
pub const BF16_MIN_K: usize = 96;

impl Precision {
    /// What runs on this CPU: `Bf16` only where [`super::bf16::available`].
    pub fn effective(self) -> Precision {
        match self {
            Precision::Bf16 if super::bf16::available() => Precision::Bf16,
            _ => Precision::F32,
        }
    }

    /// What a GEMM with reduction length `k` runs in: [`Precision::effective`], and f32 where
    /// `k < BF16_MIN_K`.
    pub fn for_reduction(self, k: usize) -> Precision {
        if k < BF16_MIN_K {
            Precision::F32
        } else {
            self.effective()
        }
    }
}

/// `dst[m, n] (+)= lhs[m, k] * rhs[k, n]` with explicit row / column strides, on this thread.
///
/// # Safety
/// The strided extents must lie inside the slices; `dst` must not overlap the inputs.
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn mm(
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    dst_rs: usize,
    accumulate: bool,
    lhs: &[f32],
    (lhs_rs, lhs_cs): (usize, usize),
    rhs: &[f32],
    (rhs_rs, rhs_cs): (usize, usize),
    prec: Precision,
) {
    if prec.for_reduction(k) == Precision::Bf16 {
        // SAFETY: `effective` checked the CPU features; extents as the caller guarantees.
        unsafe {
            super::bf16::gemm(
                m,
                n,
                k,
                dst,
                dst_rs,
                accumulate,
                lhs,
                (lhs_rs, lhs_cs),
                rhs,
                (rhs_rs, rhs_cs),
            )
        };
        return;
    }
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            for r in 0..m {
                dst[r * dst_rs..r * dst_rs + n].fill(0.0);
            }
        }
        return;
    }
    debug_assert!((m - 1) * dst_rs + n <= dst.len());
    debug_assert!((m - 1) * lhs_rs + (k - 1) * lhs_cs < lhs.len());
    debug_assert!((k - 1) * rhs_rs + (n - 1) * rhs_cs < rhs.len());
    // SAFETY: the caller guarantees the strided extents are inside the slices (checked in
    // debug builds above); `dst` is a unique borrow, so it does not alias `lhs` / `rhs`.
    unsafe {
        gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            dst_rs as isize,
            accumulate,
            lhs.as_ptr(),
            lhs_cs as isize,
            lhs_rs as isize,
            rhs.as_ptr(),
            rhs_cs as isize,
            rhs_rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            Parallelism::None,
        )
    }
}

/// A GEMM's right-hand side `[k, n]` (row-major), shared by many row tiles (a layer's
/// weights): with [`Precision::Bf16`] it is packed once into bf16 pairs here instead of per
/// tile. Invariant: `bf16`, when present, packs `b`.
pub(super) struct Weights<'a> {
    b: &'a [f32],
    k: usize,
    n: usize,
    bf16: Option<super::bf16::PackedB>,
}

impl<'a> Weights<'a> {
    /// `b: [k, n]`; packed for bf16 when `prec` is effectively bf16.
    pub(super) fn new(b: &'a [f32], k: usize, n: usize, prec: Precision) -> Self {
        assert_eq!(b.len(), k * n);
        let bf16 = if prec.for_reduction(k) == Precision::Bf16 {
            super::bf16::PackedB::new(b, (n, 1), k, n)
        } else {
            None
        };
        Self { b, k, n, bf16 }
    }

    /// `dst[m, n] = lhs[m, k] B` for `lhs` with row stride `lhs_rs` (column stride 1) and
    /// `dst` `[m, n]`; on this thread.
    pub(super) fn mul(&self, lhs: &[f32], lhs_rs: usize, dst: &mut [f32]) {
        self.mul_acc(lhs, lhs_rs, dst, false);
    }

    /// [`Weights::mul`], adding to `dst` when `accumulate`.
    pub(super) fn mul_acc(&self, lhs: &[f32], lhs_rs: usize, dst: &mut [f32], accumulate: bool) {
        let (k, n) = (self.k, self.n);
        assert!(n > 0 && dst.len().is_multiple_of(n));
        let m = dst.len() / n;
        if m == 0 {
            return;
        }
        assert!(lhs_rs >= k && lhs.len() >= (m - 1) * lhs_rs + k);
        match &self.bf16 {
            // SAFETY: lhs is [m, k] at row stride lhs_rs, dst [m, n]: in bounds (asserted).
            Some(pb) => unsafe {
                super::bf16::gemm_packed(m, dst, n, accumulate, lhs, (lhs_rs, 1), pb)
            },
            // SAFETY: as above; B is [k, n] (asserted in `new`).
            None => unsafe {
                mm(
                    m,
                    n,
                    k,
                    dst,
                    n,
                    accumulate,
                    lhs,
                    (lhs_rs, 1),
                    self.b,
                    (n, 1),
                    Precision::F32,
                )
            },
        }
    }
}

/// Tiles per group in [`conv_forward`] (each kernel plane's weights serve the group's tiles
/// in turn).
const CONV_GROUP_TILES: usize = 8;

/// Rows per tile: 128 to 256, the im2col block at most about 1 MB (this CPU's L2 is 2 MB
/// per core); measured best for widths 32 and 128 (`benches/kernel_bench.rs`).
pub(super) fn tile_rows(kdim: usize) -> usize {
    ((1 << 17) / kdim.max(1)).clamp(128, 256)
}

/// Bias, residual and activation on a block of rows of `n` channels, in place.
pub(super) fn epilogue(y: &mut [f32], n: usize, bias: &[f32], residual: Option<&[f32]>, act: Act) {
    match residual {
        Some(r) => {
            for (row, rr) in y.chunks_exact_mut(n).zip(r.chunks_exact(n)) {
                for ((v, b), x) in row.iter_mut().zip(bias).zip(rr) {
                    *v = act.apply(*v + b + x);
                }
            }
        }
        None => {
            for row in y.chunks_exact_mut(n) {
                for (v, b) in row.iter_mut().zip(bias) {
                    *v = act.apply(*v + b);
                }
            }
        }
    }
}

/// `dZ = dY * act'(Y)` (a copy of `dY` for the identity).
pub fn activation_grad(y: &[f32], gy: &[f32], act: Act) -> Vec<f32> {
    assert_eq!(y.len(), gy.len());
    let mut gz = vec![0.0f32; gy.len()];
    gz.par_chunks_mut(1 << 14)
        .zip(gy.par_chunks(1 << 14).zip(y.par_chunks(1 << 14)))
        .for_each(|(z, (g, y))| {
            for ((z, g), y) in z.iter_mut().zip(g).zip(y) {
                *z = g * act.slope_at_output(*y);
            }
        });
    gz
}

/// Reductions over rows are split into this many parts, whatever the thread count, and the
/// parts are summed in order: results are the same on every machine and thread count (exact
/// resume of a training run depends on it).
const PARTS: usize = 8;

/// Row ranges of the [`PARTS`] parts of `rows` rows (in units of `unit` rows).
pub(super) fn parts(rows: usize, unit: usize) -> Vec<(usize, usize)> {
    let units = rows.div_ceil(unit.max(1));
    let per = units.div_ceil(PARTS).max(1);
    (0..units.div_ceil(per))
        .map(|p| (p * per * unit, ((p + 1) * per * unit).min(rows)))
        .collect()
}

/// Sum over rows of a `[rows, n]` block (the bias gradient).
pub fn column_sums(g: &[f32], n: usize) -> Vec<f32> {
    assert!(n > 0 && g.len().is_multiple_of(n));
    let partials: Vec<Vec<f64>> = parts(g.len() / n, 1)
        .into_par_iter()
        .map(|(a, b)| {
            let mut s = vec![0.0f64; n];
            for row in g[a * n..b * n].chunks_exact(n) {
                for (acc, v) in s.iter_mut().zip(row) {
                    *acc += f64::from(*v);
                }
            }
            s
        })
        .collect();
    let mut total = vec![0.0f64; n];
    for p in partials {
        total.iter_mut().zip(&p).for_each(|(a, b)| *a += b);
    }
    total.into_iter().map(|v| v as f32).collect()
}

// ---------------------------------------------------------------------------------------------
// 1x1x1 layers: plain GEMMs over [rows, channels]
// ---------------------------------------------------------------------------------------------

/// Rows per tile of the 1x1x1 layers.
const LINEAR_TILE: usize = 512;

/// `[r, c]` row-major -> `[c, r]` row-major.
pub(super) fn transpose(a: &[f32], r: usize, c: usize) -> Vec<f32> {
    let mut t = vec![0.0f32; a.len()];
    for i in 0..r {
        for j in 0..c {
            t[j * r + i] = a[i * c + j];
        }
    }
    t
}

/// `Y = act(X W^T + b (+ R))` for `X: [rows, cin]`, `W: [cout, cin]` (a 1x1x1 `Conv3d`
/// weight), `b: [cout]`, `R: [rows, cout]`.
pub fn linear_forward(
    x: &[f32],
    cin: usize,
    w: &[f32],
    bias: &[f32],
    residual: Option<&[f32]>,
    act: Act,
    prec: Precision,
) -> Vec<f32> {
    let cout = bias.len();
    assert!(cin > 0 && x.len().is_multiple_of(cin) && w.len() == cout * cin);
    let rows = x.len() / cin;
    if let Some(r) = residual {
        assert_eq!(r.len(), rows * cout);
    }
    let mut y = vec![0.0f32; rows * cout];
    if cout == 0 || rows == 0 {
        return y;
    }
    let wt = transpose(w, cout, cin);
    let tile = LINEAR_TILE;
    y.par_chunks_mut(tile * cout)
        .enumerate()
        .for_each(|(t, yt)| {
            let m = yt.len() / cout;
            let r0 = t * tile;
            let xt = &x[r0 * cin..(r0 + m) * cin];
            // SAFETY: xt is [m, cin], wt is W^T [cin, cout], yt is [m, cout]; all in bounds
            // by the asserts above.
            unsafe {
                mm(
                    m,
                    cout,
                    cin,
                    yt,
                    cout,
                    false,
                    xt,
                    (cin, 1),
                    &wt,
                    (cout, 1),
                    prec,
                )
            };
            let rt = residual.map(|r| &r[r0 * cout..(r0 + m) * cout]);
            epilogue(yt, cout, bias, rt, act);
        });
    y
}

/// Gradients of [`linear_forward`] from `dZ` (the gradient before the activation, see
/// [`activation_grad`]): `(dX, dW)`, each only when asked for.
pub fn linear_backward(
    x: &[f32],
    cin: usize,
    w: &[f32],
    gz: &[f32],
    cout: usize,
    need_x: bool,
    need_w: bool,
) -> (Option<Vec<f32>>, Option<Vec<f32>>) {
    assert!(cin > 0 && cout > 0 && x.len().is_multiple_of(cin) && w.len() == cout * cin);
    let rows = x.len() / cin;
    assert_eq!(gz.len(), rows * cout);
    let gx = need_x.then(|| {
        let mut gx = vec![0.0f32; rows * cin];
        let tile = LINEAR_TILE;
        gx.par_chunks_mut(tile * cin)
            .enumerate()
            .for_each(|(t, gxt)| {
                let m = gxt.len() / cin;
                let gzt = &gz[t * tile * cout..(t * tile + m) * cout];
                // SAFETY: dZ tile [m, cout] times W [cout, cin] into [m, cin].
                unsafe {
                    mm(
                        m,
                        cin,
                        cout,
                        gxt,
                        cin,
                        false,
                        gzt,
                        (cout, 1),
                        w,
                        (cin, 1),
                        Precision::F32,
                    )
                };
            });
        gx
    });
    let gw = need_w.then(|| {
        // dW = dZ^T X, summed over the row parts in order.
        let partials: Vec<Vec<f32>> = parts(rows, 1)
            .into_par_iter()
            .map(|(r0, r1)| {
                let m = r1 - r0;
                let mut p = vec![0.0f32; cout * cin];
                let gzt = &gz[r0 * cout..(r0 + m) * cout];
                let xt = &x[r0 * cin..(r0 + m) * cin];
                // SAFETY: dZ^T [cout, m] (row stride 1, column stride cout) times X [m, cin].
                unsafe {
                    mm(
                        cout,
                        cin,
                        m,
                        &mut p,
                        cin,
                        false,
                        gzt,
                        (1, cout),
                        xt,
                        (cin, 1),
                        Precision::F32,
                    )
                };
                p
            })
            .collect();
        sum_partials(partials, cout * cin)
    });
    (gx, gw)
}

/// Which gradients [`linear_grads`] computes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinearNeeds {
    /// `dX` (`[rows, cin]`).
    pub x: bool,
    /// `dW` (`[cout, cin]`).
    pub w: bool,
    /// `db` (`[cout]`).
    pub b: bool,
    /// `dZ` itself (`[rows, cout]`: the residual's gradient).
    pub z: bool,
}

/// The gradients of a 1x1x1 layer asked for by a [`LinearNeeds`]; `None` where not asked.
#[derive(Debug, Default)]
pub struct LinearGrads {
    /// `dZ = dY * act'(Y)`.
    pub z: Option<Vec<f32>>,
    /// `dX = dZ W`.
    pub x: Option<Vec<f32>>,
    /// `dW = dZ^T X`.
    pub w: Option<Vec<f32>>,
    /// `db`: the column sums of `dZ`.
    pub b: Option<Vec<f32>>,
}

/// All gradients of [`linear_forward`] from its output `y` and the output's gradient `gy`, in
/// one pass over row tiles: each tile's `dZ` is made in cache and used at once for `dX`, `dW`
/// and `db` (the same results as [`activation_grad`], [`linear_backward`] and [`column_sums`]
/// up to float rounding, without their three extra passes over `[rows, cout]` arrays).
/// Reductions are summed per fixed part of the rows, the parts in order, so results do not
/// depend on the thread count.
#[allow(clippy::too_many_arguments)]
pub fn linear_grads(
    x: &[f32],
    cin: usize,
    w: &[f32],
    y: &[f32],
    gy: &[f32],
    act: Act,
    cout: usize,
    need: LinearNeeds,
    prec: Precision,
) -> LinearGrads {
    assert!(cin > 0 && cout > 0 && x.len().is_multiple_of(cin) && w.len() == cout * cin);
    let rows = x.len() / cin;
    assert!(y.len() == rows * cout && gy.len() == rows * cout);
    let tile = LINEAR_TILE;
    let ranges = parts(rows, tile);
    let part_rows = ranges.first().map_or(1, |&(a, b)| (b - a).max(1));
    let mut gz = need.z.then(|| vec![0.0f32; rows * cout]);
    let mut gx = need.x.then(|| vec![0.0f32; rows * cin]);
    fn split(v: &mut Option<Vec<f32>>, chunk: usize, n: usize) -> Vec<Option<&mut [f32]>> {
        let mut out: Vec<Option<&mut [f32]>> = match v {
            Some(v) => v.chunks_mut(chunk.max(1)).map(Some).collect(),
            None => Vec::new(),
        };
        out.resize_with(n, || None);
        out
    }
    // W for dX, packed once (only when dX is asked for).
    let w_dx = need.x.then(|| Weights::new(w, cout, cin, prec));
    let gz_parts = split(&mut gz, part_rows * cout, ranges.len());
    let gx_parts = split(&mut gx, part_rows * cin, ranges.len());
    let reductions = need.w || need.b;
    let partials: Vec<(Vec<f32>, Vec<f64>)> = ranges
        .par_iter()
        .zip(gz_parts)
        .zip(gx_parts)
        .map(|((&(a, b), mut gz_part), mut gx_part)| {
            let mut gw = vec![0.0f32; if need.w { cout * cin } else { 0 }];
            let mut gb = vec![0.0f64; if need.b { cout } else { 0 }];
            let mut local = vec![0.0f32; if need.z { 0 } else { tile * cout }];
            let mut first = true;
            for r0 in (a..b).step_by(tile) {
                let m = tile.min(b - r0);
                let gzt: &mut [f32] = match gz_part.as_deref_mut() {
                    Some(p) => &mut p[(r0 - a) * cout..(r0 - a + m) * cout],
                    None => &mut local[..m * cout],
                };
                let (yt, gyt) = (
                    &y[r0 * cout..(r0 + m) * cout],
                    &gy[r0 * cout..(r0 + m) * cout],
                );
                for ((z, g), y) in gzt.iter_mut().zip(gyt).zip(yt) {
                    *z = g * act.slope_at_output(*y);
                }
                if need.b {
                    for row in gzt.chunks_exact(cout) {
                        for (acc, v) in gb.iter_mut().zip(row) {
                            *acc += f64::from(*v);
                        }
                    }
                }
                if let (Some(p), Some(w_dx)) = (gx_part.as_deref_mut(), &w_dx) {
                    // dZ tile [m, cout] times W [cout, cin] into [m, cin].
                    w_dx.mul(gzt, cout, &mut p[(r0 - a) * cin..(r0 - a + m) * cin]);
                }
                if need.w {
                    let xt = &x[r0 * cin..(r0 + m) * cin];
                    // SAFETY: dZ^T [cout, m] (row stride 1, column stride cout) times X
                    // [m, cin] into [cout, cin].
                    unsafe {
                        mm(
                            cout,
                            cin,
                            m,
                            &mut gw,
                            cin,
                            !first,
                            gzt,
                            (1, cout),
                            xt,
                            (cin, 1),
                            prec,
                        )
                    };
                }
                first = false;
            }
            (gw, gb)
        })
        .collect();
    let mut out = LinearGrads {
        z: gz,
        x: gx,
        ..Default::default()
    };
    if reductions {
        let (gws, gbs): (Vec<_>, Vec<_>) = partials.into_iter().unzip();
        if need.w {
            out.w = Some(sum_partials(gws, cout * cin));
        }
        if need.b {
            let mut total = vec![0.0f64; cout];
            for p in gbs {
                total.iter_mut().zip(&p).for_each(|(t, v)| *t += v);
            }
            out.b = Some(total.into_iter().map(|v| v as f32).collect());
        }
    }
    out
}

fn sum_partials(partials: Vec<Vec<f32>>, n: usize) -> Vec<f32> {
    let mut it = partials.into_iter();
    let mut acc = it.next().unwrap_or_else(|| vec![0.0; n]);
    for p in it {
        acc.iter_mut().zip(&p).for_each(|(a, b)| *a += b);
    }
    acc
}

// ---------------------------------------------------------------------------------------------
// k x k x k convolutions (stride 1, symmetric zero padding) on channels-last grids
// ---------------------------------------------------------------------------------------------

/// Shape of a channels-last convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvShape {
    /// Batch size.
    pub batch: usize,
    /// Input grid size per axis.
    pub dims: [usize; 3],
    /// Input channels.
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
    /// Kernel size per axis.
    pub k: usize,
    /// Zero padding on each side of each axis.
    pub pad: usize,
}

impl ConvShape {
    /// Output grid size per axis: `d + 2 pad - k + 1`.
    pub fn out_dims(&self) -> [usize; 3] {
        self.dims.map(|d| d + 2 * self.pad + 1 - self.k)
    }

    /// Output rows (batch times output nodes).
    pub fn out_rows(&self) -> usize {
        self.batch * self.out_dims().iter().product::<usize>()
    }

    /// Input rows.
    pub fn in_rows(&self) -> usize {
        self.batch * self.dims.iter().product::<usize>()
    }

    /// Length of an im2col row: `k^3 cin`.
    pub fn kdim(&self) -> usize {
        self.k * self.k * self.k * self.cin
    }

    /// The convolution whose forward is this one's input gradient: the output grid as input,
    /// channels swapped, padding `k - 1 - pad`.
    pub fn transposed(&self) -> ConvShape {
        ConvShape {
            batch: self.batch,
            dims: self.out_dims(),
            cin: self.cout,
            cout: self.cin,
            k: self.k,
            pad: self.k - 1 - self.pad,
        }
    }

    fn check(&self) {
        assert!(self.k >= 1 && self.pad < self.k, "{self:?}");
        assert!(
            self.dims.iter().all(|&d| d + 2 * self.pad >= self.k),
            "{self:?}"
        );
    }
}

/// The im2col rows of output rows `r0 .. r0 + m` (`[m, k^3 cin]`), restricted to the kernel
/// planes `planes` (first kernel axis): `col` is `[m, planes.len() k^2 cin]`, the columns
/// `planes.start k^2 cin ..` of the full rows.
fn im2col_planes(
    x: &[f32],
    s: &ConvShape,
    r0: usize,
    m: usize,
    planes: std::ops::Range<usize>,
    col: &mut [f32],
) {
    let [o1, o2, o3] = s.out_dims();
    let [d1, d2, d3] = s.dims;
    let (k, cin) = (s.k, s.cin);
    let pad = s.pad as isize;
    let kd = planes.len() * k * k * cin;
    for r in 0..m {
        let row = r0 + r;
        let l = row % o3;
        let j = (row / o3) % o2;
        let i = (row / (o3 * o2)) % o1;
        let b = row / (o1 * o2 * o3);
        let dst = &mut col[r * kd..(r + 1) * kd];
        for (pa, a) in planes.clone().enumerate() {
            let ii = i as isize + a as isize - pad;
            for c in 0..k {
                let jj = j as isize + c as isize - pad;
                let seg = &mut dst[(pa * k + c) * k * cin..(pa * k + c + 1) * k * cin];
                if ii < 0 || ii >= d1 as isize || jj < 0 || jj >= d2 as isize {
                    seg.fill(0.0);
                    continue;
                }
                let line = ((b * d1 + ii as usize) * d2 + jj as usize) * d3;
                let l0 = l as isize - pad;
                if l0 >= 0 && l0 as usize + k <= d3 {
                    let src = (line + l0 as usize) * cin;
                    seg.copy_from_slice(&x[src..src + k * cin]);
                } else {
                    for e in 0..k {
                        let ll = l0 + e as isize;
                        let part = &mut seg[e * cin..(e + 1) * cin];
                        if ll < 0 || ll >= d3 as isize {
                            part.fill(0.0);
                        } else {
                            let src = (line + ll as usize) * cin;
                            part.copy_from_slice(&x[src..src + cin]);
                        }
                    }
                }
            }
        }
    }
}

/// Packs a `[cout, cin, k, k, k]` weight as the `[k^3 cin, cout]` right-hand side of the
/// im2col GEMM (row `(offset, ci)`), or, `flipped`, as the `[k^3 cout, cin]` one of the input
/// gradient (offsets reversed, channels swapped).
pub fn pack_weight(w: &[f32], s: &ConvShape, flipped: bool) -> Vec<f32> {
    let k3 = s.k * s.k * s.k;
    let (cin, cout) = (s.cin, s.cout);
    assert_eq!(w.len(), cout * cin * k3);
    let mut p = vec![0.0f32; w.len()];
    for co in 0..cout {
        for ci in 0..cin {
            for o in 0..k3 {
                let v = w[(co * cin + ci) * k3 + o];
                if flipped {
                    p[((k3 - 1 - o) * cout + co) * cin + ci] = v;
                } else {
                    p[(o * cin + ci) * cout + co] = v;
                }
            }
        }
    }
    p
}

/// `Y = act(conv(X, W) + b)` for `X: [B, D1, D2, D3, cin]` (flattened), `packed` from
/// [`pack_weight`] (not flipped), `b: [cout]` (or none); returns `[B, O1, O2, O3, cout]`.
pub fn conv_forward(
    x: &[f32],
    s: &ConvShape,
    packed: &[f32],
    bias: Option<&[f32]>,
    act: Act,
    prec: Precision,
) -> Vec<f32> {
    s.check();
    assert_eq!(x.len(), s.in_rows() * s.cin);
    let (kd, cout) = (s.kdim(), s.cout);
    assert_eq!(packed.len(), kd * cout);
    let rows = s.out_rows();
    let mut y = vec![0.0f32; rows * cout];
    if rows == 0 || cout == 0 {
        return y;
    }
    let tile = tile_rows(kd);
    let zero = vec![0.0f32; cout];
    let bias = bias.unwrap_or(&zero);
    // One kernel plane (k^2 offsets, `pd` rows of the packed weights) at a time over a group
    // of tiles: the plane's weights stay in L2 across the group's tiles, and each tile's
    // im2col block is a third of the full one.
    let pd = kd / s.k;
    let planes: Vec<Weights> = (0..s.k)
        .map(|p| Weights::new(&packed[p * pd * cout..(p + 1) * pd * cout], pd, cout, prec))
        .collect();
    let group = tile * CONV_GROUP_TILES;
    y.par_chunks_mut(group * cout).enumerate().for_each_init(
        || vec![0.0f32; tile * pd],
        |col, (g, yg)| {
            for (p, wp) in planes.iter().enumerate() {
                for (t, yt) in yg.chunks_mut(tile * cout).enumerate() {
                    let m = yt.len() / cout;
                    im2col_planes(x, s, g * group + t * tile, m, p..p + 1, col);
                    wp.mul_acc(&col[..m * pd], pd, yt, p > 0);
                }
            }
            if bias.iter().any(|&b| b != 0.0) || act != Act::Identity {
                epilogue(yg, cout, bias, None, act);
            }
        },
    );
    y
}

/// Weight gradient of a convolution: `dW = im2col(X)^T dZ`, as `[cout, cin, k, k, k]`.
/// (With bf16 it is made as `dW^T = dZ^T im2col(X)`, whose large operand, the im2col block,
/// is the one the bf16 kernel packs fastest.)
pub fn conv_weight_grad(x: &[f32], s: &ConvShape, gz: &[f32], prec: Precision) -> Vec<f32> {
    s.check();
    let (kd, cout) = (s.kdim(), s.cout);
    let rows = s.out_rows();
    assert_eq!(gz.len(), rows * cout);
    assert_eq!(x.len(), s.in_rows() * s.cin);
    let tile = tile_rows(kd);
    let transposed = prec.for_reduction(tile_rows(kd)) == Precision::Bf16;
    // One kernel plane (k^2 offsets) at a time over all tiles of a part: that plane's slice of
    // the accumulator and of the im2col block stay in L2 from one tile to the next.
    let pd = kd / s.k;
    let partials: Vec<Vec<f32>> = parts(rows, tile)
        .into_par_iter()
        .map(|(a, b)| {
            let mut acc = vec![0.0f32; kd * cout];
            let mut col = vec![0.0f32; tile * pd];
            for plane in 0..s.k {
                let mut first = true;
                for r0 in (a..b).step_by(tile) {
                    let m = tile.min(b - r0);
                    im2col_planes(x, s, r0, m, plane..plane + 1, &mut col);
                    let gzt = &gz[r0 * cout..(r0 + m) * cout];
                    if transposed {
                        // SAFETY: dZ^T is [cout, m] (row stride 1, column stride cout), col
                        // [m, pd], the plane's columns of acc [cout, kd] (row stride kd).
                        unsafe {
                            mm(
                                cout,
                                pd,
                                m,
                                &mut acc[plane * pd..],
                                kd,
                                !first,
                                gzt,
                                (1, cout),
                                &col,
                                (pd, 1),
                                prec,
                            )
                        };
                    } else {
                        // SAFETY: col^T is [pd, m] (row stride 1, column stride pd), dZ tile
                        // [m, cout], the plane's rows of acc [kd, cout].
                        unsafe {
                            mm(
                                pd,
                                cout,
                                m,
                                &mut acc[plane * pd * cout..(plane + 1) * pd * cout],
                                cout,
                                !first,
                                &col,
                                (1, pd),
                                gzt,
                                (cout, 1),
                                prec,
                            )
                        };
                    }
                    first = false;
                }
            }
            acc
        })
        .collect();
    let g = sum_partials(partials, kd * cout);
    // [(offset, ci), co] (or [co, (offset, ci)]) -> [co, ci, offset]
    let k3 = s.k * s.k * s.k;
    let cin = s.cin;
    let mut out = vec![0.0f32; g.len()];
    for o in 0..k3 {
        for ci in 0..cin {
            for co in 0..cout {
                out[(co * cin + ci) * k3 + o] = if transposed {
                    g[co * kd + o * cin + ci]
                } else {
                    g[(o * cin + ci) * cout + co]
                };
            }
        }
    }
    out
}

/// Input gradient of a convolution: the transposed convolution of `dZ` (see
/// [`ConvShape::transposed`]); `w` is the `[cout, cin, k, k, k]` weight.
pub fn conv_input_grad(s: &ConvShape, w: &[f32], gz: &[f32], prec: Precision) -> Vec<f32> {
    let t = s.transposed();
    let packed = pack_weight(w, s, true);
    conv_forward(gz, &t, &packed, None, Act::Identity, prec)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::fast::testing::{lcg, on_threads};

    /// Direct (six nested loops) convolution on channels-last data.
    pub(in crate::fast) fn conv_naive(x: &[f32], s: &ConvShape, w: &[f32], b: &[f32]) -> Vec<f32> {
        let o = s.out_dims();
        let (k, cin, cout) = (s.k, s.cin, s.cout);
        let mut y = vec![0.0f32; s.out_rows() * cout];
        for bb in 0..s.batch {
            for i in 0..o[0] {
                for j in 0..o[1] {
                    for l in 0..o[2] {
                        let row = ((bb * o[0] + i) * o[1] + j) * o[2] + l;
                        for co in 0..cout {
                            let mut acc = f64::from(b[co]);
                            for a in 0..k {
                                for c in 0..k {
                                    for e in 0..k {
                                        let p = [i + a, j + c, l + e]
                                            .map(|v| v as isize - s.pad as isize);
                                        if (0..3)
                                            .any(|ax| p[ax] < 0 || p[ax] >= s.dims[ax] as isize)
                                        {
                                            continue;
                                        }
                                        let xr = ((bb * s.dims[0] + p[0] as usize) * s.dims[1]
                                            + p[1] as usize)
                                            * s.dims[2]
                                            + p[2] as usize;
                                        for ci in 0..cin {
                                            acc += f64::from(x[xr * cin + ci])
                                                * f64::from(
                                                    w[(co * cin + ci) * k * k * k
                                                        + (a * k + c) * k
                                                        + e],
                                                );
                                        }
                                    }
                                }
                            }
                            y[row * cout + co] = acc as f32;
                        }
                    }
                }
            }
        }
        y
    }

    fn close(a: &[f32], b: &[f32], tol: f32) {
        assert_eq!(a.len(), b.len());
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!((x - y).abs() <= tol * (1.0 + y.abs()), "[{i}] {x} vs {y}");
        }
    }

    #[test]
    fn conv_forward_matches_direct_loops() {
        for s in [
            ConvShape {
                batch: 2,
                dims: [4, 3, 5],
                cin: 3,
                cout: 4,
                k: 3,
                pad: 1,
            },
            ConvShape {
                batch: 1,
                dims: [5, 4, 3],
                cin: 1,
                cout: 5,
                k: 2,
                pad: 0,
            },
            ConvShape {
                batch: 1,
                dims: [3, 3, 3],
                cin: 2,
                cout: 3,
                k: 3,
                pad: 0,
            },
            ConvShape {
                batch: 1,
                dims: [2, 6, 1],
                cin: 2,
                cout: 2,
                k: 2,
                pad: 1,
            },
        ] {
            let x = lcg(1, s.in_rows() * s.cin);
            let w = lcg(2, s.cout * s.cin * s.k * s.k * s.k);
            let b = lcg(3, s.cout);
            let y = conv_forward(
                &x,
                &s,
                &pack_weight(&w, &s, false),
                Some(&b),
                Act::Identity,
                Precision::F32,
            );
            close(&y, &conv_naive(&x, &s, &w, &b), 1e-5);
        }
    }

    /// `<conv(x), g> = <x, conv^T(g)>` and `<conv(x), g> = <w, dW(x, g)>` on random data:
    /// the two backward kernels are the adjoints of the forward.
    #[test]
    fn backward_kernels_are_the_adjoints_of_the_forward() {
        for s in [
            ConvShape {
                batch: 2,
                dims: [4, 3, 5],
                cin: 3,
                cout: 4,
                k: 3,
                pad: 1,
            },
            ConvShape {
                batch: 1,
                dims: [5, 4, 3],
                cin: 1,
                cout: 5,
                k: 2,
                pad: 0,
            },
            ConvShape {
                batch: 1,
                dims: [2, 6, 1],
                cin: 2,
                cout: 2,
                k: 2,
                pad: 1,
            },
        ] {
            let x = lcg(4, s.in_rows() * s.cin);
            let w = lcg(5, s.cout * s.cin * s.k * s.k * s.k);
            let g = lcg(6, s.out_rows() * s.cout);
            let y = conv_forward(
                &x,
                &s,
                &pack_weight(&w, &s, false),
                None,
                Act::Identity,
                Precision::F32,
            );
            let dot = |a: &[f32], b: &[f32]| -> f64 {
                a.iter()
                    .zip(b)
                    .map(|(p, q)| f64::from(*p) * f64::from(*q))
                    .sum()
            };
            let lhs = dot(&y, &g);
            let gx = conv_input_grad(&s, &w, &g, Precision::F32);
            let gw = conv_weight_grad(&x, &s, &g, Precision::F32);
            assert!(
                (lhs - dot(&x, &gx)).abs() < 1e-4 * (1.0 + lhs.abs()),
                "{s:?}"
            );
            assert!(
                (lhs - dot(&w, &gw)).abs() < 1e-4 * (1.0 + lhs.abs()),
                "{s:?}"
            );
        }
    }

    #[test]
    fn linear_forward_and_backward_match_direct_sums() {
        let (rows, cin, cout) = (37, 5, 3);
        let x = lcg(7, rows * cin);
        let w = lcg(8, cout * cin);
        let b = lcg(9, cout);
        let r = lcg(10, rows * cout);
        let act = Act::Leaky(0.01);
        let y = linear_forward(&x, cin, &w, &b, Some(&r), act, Precision::F32);
        for i in 0..rows {
            for o in 0..cout {
                let z: f32 = (0..cin)
                    .map(|c| x[i * cin + c] * w[o * cin + c])
                    .sum::<f32>()
                    + b[o]
                    + r[i * cout + o];
                let want = if z > 0.0 { z } else { 0.01 * z };
                assert!((y[i * cout + o] - want).abs() < 1e-5);
            }
        }
        let gz = lcg(11, rows * cout);
        let (gx, gw) = linear_backward(&x, cin, &w, &gz, cout, true, true);
        let (gx, gw) = (gx.unwrap(), gw.unwrap());
        for i in 0..rows {
            for c in 0..cin {
                let want: f32 = (0..cout).map(|o| gz[i * cout + o] * w[o * cin + c]).sum();
                assert!((gx[i * cin + c] - want).abs() < 1e-5);
            }
        }
        for o in 0..cout {
            for c in 0..cin {
                let want: f32 = (0..rows).map(|i| gz[i * cout + o] * x[i * cin + c]).sum();
                assert!((gw[o * cin + c] - want).abs() < 1e-4);
            }
        }
        let sums = column_sums(&gz, cout);
        for o in 0..cout {
            let want: f32 = (0..rows).map(|i| gz[i * cout + o]).sum();
            assert!((sums[o] - want).abs() < 1e-5);
        }
    }

    #[test]
    fn fused_linear_grads_match_the_separate_kernels() {
        // Rows around the tile and part sizes (512-row tiles, 8 parts): one short tile, exact
        // tiles, parts with a short last tile.
        for (rows, cin, cout) in [(37, 5, 3), (512, 8, 8), (4096 + 77, 16, 4), (9000, 3, 7)] {
            let x = lcg(21, rows * cin);
            let w = lcg(22, cout * cin);
            let y = lcg(23, rows * cout);
            let gy = lcg(24, rows * cout);
            for act in [Act::Identity, Act::Leaky(0.01)] {
                let gz = activation_grad(&y, &gy, act);
                let (gx, gw) = linear_backward(&x, cin, &w, &gz, cout, true, true);
                let gb = column_sums(&gz, cout);
                let all = LinearNeeds {
                    x: true,
                    w: true,
                    b: true,
                    z: true,
                };
                let g = linear_grads(&x, cin, &w, &y, &gy, act, cout, all, Precision::F32);
                assert_eq!(g.z.as_deref(), Some(&gz[..]));
                close(g.x.as_deref().unwrap(), &gx.unwrap(), 1e-5);
                close(g.w.as_deref().unwrap(), &gw.unwrap(), 3e-4);
                close(g.b.as_deref().unwrap(), &gb, 1e-5);
                // Each gradient alone, and none: only what is asked for, the same values.
                let only_w = LinearNeeds {
                    w: true,
                    ..Default::default()
                };
                let h = linear_grads(&x, cin, &w, &y, &gy, act, cout, only_w, Precision::F32);
                assert!(h.x.is_none() && h.z.is_none() && h.b.is_none());
                assert_eq!(h.w, g.w);
                let only_x = LinearNeeds {
                    x: true,
                    ..Default::default()
                };
                assert_eq!(
                    linear_grads(&x, cin, &w, &y, &gy, act, cout, only_x, Precision::F32).x,
                    g.x
                );
                let none = linear_grads(
                    &x,
                    cin,
                    &w,
                    &y,
                    &gy,
                    act,
                    cout,
                    LinearNeeds::default(),
                    Precision::F32,
                );
                assert!(none.x.is_none() && none.w.is_none() && none.b.is_none());
            }
        }
    }

    /// Each bf16 kernel equals its f32 version fed with the bf16-rounded inputs (up to f32
    /// summation order), on shapes whose every GEMM reduces over at least [`BF16_MIN_K`]
    /// (every layout and packing path the layers use); below it the f32 kernel runs.
    #[test]
    fn bf16_kernels_equal_f32_on_rounded_inputs() {
        if !super::super::bf16::available() {
            return;
        }
        let r = |v: &[f32]| -> Vec<f32> {
            v.iter()
                .map(|&x| super::super::bf16::round_bf16(x))
                .collect()
        };
        let (f, b) = (Precision::F32, Precision::Bf16);
        // Rows a multiple of the tile (every weight-gradient call reduces over a whole tile).
        // Each kernel plane's GEMM reduces over k^2 cin values (9 cin >= 96 here).
        for (cin, cout) in [(11, 20), (16, 48)] {
            let s = ConvShape {
                batch: 2,
                dims: [8, 8, 8],
                cin,
                cout,
                k: 3,
                pad: 1,
            };
            assert!(9 * cin >= BF16_MIN_K && 9 * cout >= BF16_MIN_K);
            let x = lcg(31, s.in_rows() * cin);
            let w = lcg(32, cout * cin * 27);
            let g = lcg(33, s.out_rows() * cout);
            let pw = |w: &[f32]| pack_weight(w, &s, false);
            let y_b = conv_forward(&x, &s, &pw(&w), None, Act::Identity, b);
            let y_f = conv_forward(&r(&x), &s, &pw(&r(&w)), None, Act::Identity, f);
            close(&y_b, &y_f, 1e-5);
            let gw_b = conv_weight_grad(&x, &s, &g, b);
            close(&gw_b, &conv_weight_grad(&r(&x), &s, &r(&g), f), 1e-4);
            let gx_b = conv_input_grad(&s, &w, &g, b);
            close(&gx_b, &conv_input_grad(&s, &r(&w), &r(&g), f), 1e-5);
        }
        for (rows, cin, cout) in [(1024, 128, 128), (512, 96, 100)] {
            let x = lcg(41, rows * cin);
            let w = lcg(42, cout * cin);
            let bias = lcg(43, cout);
            let y = lcg(44, rows * cout);
            let gy = lcg(45, rows * cout);
            let act = Act::Leaky(0.1);
            close(
                &linear_forward(&x, cin, &w, &bias, Some(&y), act, b),
                &linear_forward(&r(&x), cin, &r(&w), &bias, Some(&y), act, f),
                1e-5,
            );
            let all = LinearNeeds {
                x: true,
                w: true,
                b: true,
                z: true,
            };
            let id = Act::Identity;
            let gb = linear_grads(&x, cin, &w, &y, &gy, id, cout, all, b);
            let gf = linear_grads(&r(&x), cin, &r(&w), &y, &r(&gy), id, cout, all, f);
            close(gb.x.as_deref().unwrap(), gf.x.as_deref().unwrap(), 1e-5);
            close(gb.w.as_deref().unwrap(), gf.w.as_deref().unwrap(), 1e-4);
            assert_eq!(gb.z, Some(gy.clone()), "dZ itself is not rounded");
        }
        // Below the threshold (k = 5, 3 and 37 rows): exactly the f32 results.
        let (rows, cin, cout) = (37, 5, 3);
        let (x, w, y) = (
            lcg(51, rows * cin),
            lcg(52, cout * cin),
            lcg(53, rows * cout),
        );
        let bias = vec![0.0; cout];
        let act = Act::Leaky(0.1);
        assert_eq!(
            linear_forward(&x, cin, &w, &bias, None, act, b),
            linear_forward(&x, cin, &w, &bias, None, act, f)
        );
        let all = LinearNeeds {
            x: true,
            w: true,
            b: true,
            z: false,
        };
        let gb = linear_grads(&x, cin, &w, &y, &y, act, cout, all, b);
        let gf = linear_grads(&x, cin, &w, &y, &y, act, cout, all, f);
        assert!(gb.x == gf.x && gb.w == gf.w && gb.b == gf.b);
    }

    /// Reductions give bit-identical results for any thread count (exact resume).
    #[test]
    fn gradients_do_not_depend_on_the_thread_count() {
        let s = ConvShape {
            batch: 2,
            dims: [9, 8, 7],
            cin: 5,
            cout: 6,
            k: 3,
            pad: 1,
        };
        let x = lcg(12, s.in_rows() * s.cin);
        let w = lcg(13, s.cout * s.cin * 27);
        let g = lcg(14, s.out_rows() * s.cout);
        let run = |threads: usize, prec: Precision| {
            on_threads(threads, || {
                let (gx, gw) =
                    linear_backward(&x[..s.out_rows() * 5], 5, &w[..30], &g, 6, true, true);
                let all = LinearNeeds {
                    x: true,
                    w: true,
                    b: true,
                    z: true,
                };
                let fused = linear_grads(
                    &x[..s.out_rows() * 5],
                    5,
                    &w[..30],
                    &g,
                    &g,
                    Act::Leaky(0.2),
                    6,
                    all,
                    prec,
                );
                (
                    conv_weight_grad(&x, &s, &g, prec),
                    conv_input_grad(&s, &w, &g, prec),
                    column_sums(&g, s.cout),
                    gx.unwrap(),
                    gw.unwrap(),
                    (fused.x, fused.w, fused.b, fused.z),
                )
            })
        };
        for prec in [Precision::F32, Precision::Bf16] {
            let one = run(1, prec);
            for t in [2, 3, 8] {
                assert!(run(t, prec) == one, "{t} threads, {prec:?}");
            }
        }
    }
}
