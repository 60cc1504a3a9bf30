//! The five decoders (SPEC section 3) as one fused kernel over row tiles of the shared
//! encoder features.
//!
//! Run one 1x1x1 layer at a time, the 35 layers of the paper's decoders each read and write a
//! `[rows, W]` array in memory (16 MB at 32^3 cells, width 128): they are memory-bound, ~1.6x
//! slower inside a training step than their GEMMs in cache, and a training step keeps all 35
//! outputs for the backward pass. Here a tile of rows goes through all five decoders while
//! it is in cache:
//!
//! - the first layer of the five decoders is **one GEMM** over the shared features (`n = 5W`),
//!   and in the backward pass the features' gradient is one GEMM with `k = 5W`;
//! - the forward pass writes only the heads' outputs `[rows, T]`;
//! - the backward pass recomputes a tile's activations from the features (one more decoder
//!   forward, in cache) instead of storing them: a training step keeps no decoder activation.
//!
//! The parameters are one flat vector `theta` ([`DecoderShape`] gives its layout), so that the
//! Burn operation has two inputs; its gradient lands on the layers' parameters through the
//! concatenation that builds it. Reductions over rows are summed per fixed part of the rows,
//! the parts in order (eight parts, as in `kernels`): results do not depend on the thread count.

use rayon::prelude::*;

use super::kernels::{Act, Precision, Weights, epilogue, mm, parts, transpose};

/// Number of decoders of the PoNQ network.
pub const DECODERS: usize = 5;

/// Shape of the five decoders: each is `blocks` residual blocks of two `width x width` 1x1x1
/// layers (LeakyReLU) and a head of `outputs[d]` channels.
///
/// `theta` layout, decoder after decoder: for each block `conv_1.weight [W, W]`, `conv_1.bias
/// [W]`, `conv_2.weight [W, W]`, `conv_2.bias [W]`; then `head.weight [outputs[d], W]`,
/// `head.bias [outputs[d]]` (weights as `Conv3d` stores them: `[cout, cin]`, row-major).
/// The output `[rows, T]`, `T = sum(outputs)`, holds the heads side by side in decoder order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecoderShape {
    /// Feature channels `W` (> 0).
    pub width: usize,
    /// Residual blocks per decoder.
    pub blocks: usize,
    /// Output channels of each decoder's head.
    pub outputs: [usize; DECODERS],
}

/// Where one 1x1x1 layer's weight `[cout, cin]` and bias `[cout]` lie in `theta`.
#[derive(Debug, Clone, Copy)]
struct Layer {
    w: usize,
    b: usize,
    cout: usize,
    /// Index of the bias in the list of all biases (see [`DecoderShape::biases`]).
    bi: usize,
}

impl DecoderShape {
    fn decoder_params(&self, d: usize) -> usize {
        let w = self.width;
        self.blocks * 2 * (w * w + w) + self.outputs[d] * (w + 1)
    }

    fn decoder_start(&self, d: usize) -> usize {
        (0..d).map(|e| self.decoder_params(e)).sum()
    }

    /// Layer `l` of decoder `d`: `2 b` / `2 b + 1` are block `b`'s two layers, `2 blocks` the
    /// head.
    fn layer(&self, d: usize, l: usize) -> Layer {
        let w = self.width;
        let start = self.decoder_start(d) + l * (w * w + w);
        let cout = if l == 2 * self.blocks {
            self.outputs[d]
        } else {
            w
        };
        let bi = (0..d)
            .map(|e| 2 * self.blocks * w + self.outputs[e])
            .sum::<usize>()
            + l * w;
        Layer {
            w: start,
            b: start + cout * w,
            cout,
            bi,
        }
    }

    /// Number of bias entries.
    fn biases(&self) -> usize {
        (0..DECODERS)
            .map(|d| 2 * self.blocks * self.width + self.outputs[d])
            .sum()
    }

    /// Length of `theta`.
    pub fn params(&self) -> usize {
        self.decoder_start(DECODERS)
    }

    /// `T`: the output's channels.
    pub fn total_outputs(&self) -> usize {
        self.outputs.iter().sum()
    }

    /// First output channel of decoder `d`.
    pub fn output_offset(&self, d: usize) -> usize {
        self.outputs[..d].iter().sum()
    }

    /// Rows per tile (a fixed number: the parts of the reductions, hence the results, must
    /// not depend on the machine). Measured in training steps of the paper's network (width
    /// 128) and of the shipped one (width 48): 64 to 512 rows within a few percent, 256 best
    /// for both.
    fn tile(&self) -> usize {
        256
    }
}

/// The weight matrices in the orders the GEMMs read them (owned: built once per call).
struct Mats {
    /// `W^T [W, W]` of every block layer, `[d][l]` (empty for the fused first layers).
    fwd: Vec<Vec<Vec<f32>>>,
    /// The five first layers side by side, `[W, 5W]`.
    first: Vec<f32>,
    /// Their biases, `[5W]`.
    first_bias: Vec<f32>,
    /// The five first layers' weights stacked, `[5W, W]` (for the features' gradient).
    stack: Vec<f32>,
    /// `head.weight^T [W, outputs[d]]`.
    heads: Vec<Vec<f32>>,
}

impl Mats {
    fn new(s: &DecoderShape, theta: &[f32]) -> Self {
        let w = s.width;
        let weight = |l: Layer| &theta[l.w..l.w + l.cout * w];
        let fwd = (0..DECODERS)
            .map(|d| {
                (0..2 * s.blocks)
                    .map(|l| {
                        if l == 0 {
                            Vec::new()
                        } else {
                            transpose(weight(s.layer(d, l)), w, w)
                        }
                    })
                    .collect()
            })
            .collect();
        let (mut first, mut first_bias, mut stack) = (Vec::new(), Vec::new(), Vec::new());
        if s.blocks > 0 {
            first = vec![0.0f32; w * DECODERS * w];
            for d in 0..DECODERS {
                let l = s.layer(d, 0);
                let wt = weight(l);
                for j in 0..w {
                    for i in 0..w {
                        first[i * DECODERS * w + d * w + j] = wt[j * w + i];
                    }
                }
                stack.extend_from_slice(wt);
                first_bias.extend_from_slice(&theta[l.b..l.b + w]);
            }
        }
        let heads = (0..DECODERS)
            .map(|d| {
                let l = s.layer(d, 2 * s.blocks);
                transpose(weight(l), l.cout, w)
            })
            .collect();
        Self {
            fwd,
            first,
            first_bias,
            stack,
            heads,
        }
    }
}

/// Everything a tile needs: the shape, the parameters and the packed weights.
struct Plan<'a> {
    s: DecoderShape,
    theta: &'a [f32],
    mats: &'a Mats,
    act: Act,
    prec: Precision,
    fwd: Vec<Vec<Option<Weights<'a>>>>,
    first: Option<Weights<'a>>,
}

/// Per-thread buffers of one tile (`tile` rows).
struct Scratch {
    /// First layers' activations `[m, 5W]`.
    z: Vec<f32>,
    /// One decoder's activations: `acts[2b]` = block `b`'s inner activation (unused for
    /// `b = 0`, which lives in `z`), `acts[2b + 1]` = its output.
    acts: Vec<Vec<f32>>,
}

impl Scratch {
    fn new(s: &DecoderShape) -> Self {
        let (t, w) = (s.tile(), s.width);
        Self {
            z: vec![0.0; if s.blocks > 0 { t * DECODERS * w } else { 0 }],
            acts: (0..2 * s.blocks).map(|_| vec![0.0; t * w]).collect(),
        }
    }
}

impl<'a> Plan<'a> {
    fn new(s: DecoderShape, theta: &'a [f32], mats: &'a Mats, prec: Precision) -> Self {
        let w = s.width;
        let fwd = mats
            .fwd
            .iter()
            .map(|ls| {
                ls.iter()
                    .map(|m| (!m.is_empty()).then(|| Weights::new(m, w, w, prec)))
                    .collect()
            })
            .collect();
        let first = (s.blocks > 0).then(|| Weights::new(&mats.first, w, DECODERS * w, prec));
        Self {
            s,
            theta,
            mats,
            act: Act::Leaky(crate::activation::LEAKY_SLOPE as f32),
            prec,
            fwd,
            first,
        }
    }

    fn bias(&self, l: Layer) -> &'a [f32] {
        &self.theta[l.b..l.b + l.cout]
    }

    /// The first layers of all five decoders on `xt [m, W]` into `scr.z`.
    fn first_layers(&self, xt: &[f32], m: usize, scr: &mut Scratch) {
        if let Some(first) = &self.first {
            let n = DECODERS * self.s.width;
            let z = &mut scr.z[..m * n];
            first.mul(xt, self.s.width, z);
            epilogue(z, n, &self.mats.first_bias, None, self.act);
        }
    }

    /// Decoder `d`'s blocks on a tile whose first layers are in `scr.z`: fills `scr.acts`.
    fn blocks(&self, d: usize, xt: &[f32], m: usize, scr: &mut Scratch) {
        let (w, nz) = (self.s.width, DECODERS * self.s.width);
        for b in 0..self.s.blocks {
            if b > 0 {
                let mut a = std::mem::take(&mut scr.acts[2 * b]);
                let l = self.s.layer(d, 2 * b);
                let wts = self.fwd[d][2 * b].as_ref().expect("block layer weights");
                wts.mul(&scr.acts[2 * b - 1][..m * w], w, &mut a[..m * w]);
                epilogue(&mut a[..m * w], w, self.bias(l), None, self.act);
                scr.acts[2 * b] = a;
            }
            let mut h = std::mem::take(&mut scr.acts[2 * b + 1]);
            let l = self.s.layer(d, 2 * b + 1);
            let wts = self.fwd[d][2 * b + 1]
                .as_ref()
                .expect("block layer weights");
            if b == 0 {
                wts.mul(&scr.z[d * w..], nz, &mut h[..m * w]);
            } else {
                wts.mul(&scr.acts[2 * b][..m * w], w, &mut h[..m * w]);
            }
            let residual = if b == 0 {
                xt
            } else {
                &scr.acts[2 * b - 1][..m * w]
            };
            epilogue(&mut h[..m * w], w, self.bias(l), Some(residual), self.act);
            scr.acts[2 * b + 1] = h;
        }
    }

    /// The input of decoder `d`'s head: its last block's output (or the features).
    fn head_input<'s>(&self, xt: &'s [f32], m: usize, scr: &'s Scratch) -> &'s [f32] {
        match self.s.blocks {
            0 => xt,
            b => &scr.acts[2 * b - 1][..m * self.s.width],
        }
    }

    /// Decoder `d`'s head on the tile into the columns of `ot [m, T]`.
    fn head(&self, d: usize, xt: &[f32], m: usize, scr: &Scratch, ot: &mut [f32]) {
        let (w, t) = (self.s.width, self.s.total_outputs());
        let l = self.s.layer(d, 2 * self.s.blocks);
        let (off, od) = (self.s.output_offset(d), l.cout);
        if od == 0 {
            return;
        }
        let h = self.head_input(xt, m, scr);
        // SAFETY: h is [m, W], heads[d] is [W, od], the destination columns off..off + od of
        // the [m, T] tile (row stride T): in bounds.
        unsafe {
            mm(
                m,
                od,
                w,
                &mut ot[off..],
                t,
                false,
                h,
                (w, 1),
                &self.mats.heads[d],
                (od, 1),
                self.prec,
            )
        };
        let bias = self.bias(l);
        for row in ot.chunks_exact_mut(t) {
            for (v, b) in row[off..off + od].iter_mut().zip(bias) {
                *v += b;
            }
        }
    }
}

fn check(x: &[f32], s: &DecoderShape, theta: &[f32]) -> usize {
    assert!(
        s.width > 0 && x.len().is_multiple_of(s.width),
        "decoders: x"
    );
    assert_eq!(
        theta.len(),
        s.params(),
        "decoders: theta has the wrong length"
    );
    x.len() / s.width
}

/// The five decoders on feature rows `x [rows, W]`: `[rows, T]` (see [`DecoderShape`]), GEMMs
/// in `prec`. Equal to the layers run one by one ([`super::kernels::linear_forward`]) up to
/// float rounding.
pub fn forward(x: &[f32], s: &DecoderShape, theta: &[f32], prec: Precision) -> Vec<f32> {
    let rows = check(x, s, theta);
    let (w, t) = (s.width, s.total_outputs());
    let mut out = vec![0.0f32; rows * t];
    if rows == 0 || t == 0 {
        return out;
    }
    let mats = Mats::new(s, theta);
    let plan = Plan::new(*s, theta, &mats, prec);
    let tile = s.tile();
    out.par_chunks_mut(tile * t).enumerate().for_each_init(
        || Scratch::new(s),
        |scr, (i, ot)| {
            let m = ot.len() / t;
            let xt = &x[i * tile * w..(i * tile + m) * w];
            plan.first_layers(xt, m, scr);
            for d in 0..DECODERS {
                plan.blocks(d, xt, m, scr);
                plan.head(d, xt, m, scr, ot);
            }
        },
    );
    out
}

/// Which gradients [`backward`] computes, and the result.
#[derive(Debug, Default)]
pub struct DecoderGrads {
    /// `[rows, W]`: the features' gradient.
    pub x: Option<Vec<f32>>,
    /// `[params]`: the gradient of `theta`.
    pub theta: Option<Vec<f32>>,
}

/// `dZ = g * act'(y)` for `[m, W]` blocks with row strides `g_rs`, `y_rs`, `out_rs`.
#[allow(clippy::too_many_arguments)]
fn act_grad(
    m: usize,
    w: usize,
    g: &[f32],
    g_rs: usize,
    y: &[f32],
    y_rs: usize,
    act: Act,
    out: &mut [f32],
    out_rs: usize,
) {
    for r in 0..m {
        let (g, y) = (&g[r * g_rs..r * g_rs + w], &y[r * y_rs..r * y_rs + w]);
        for ((o, g), y) in out[r * out_rs..r * out_rs + w].iter_mut().zip(g).zip(y) {
            *o = g * act.slope_at_output(*y);
        }
    }
}

/// Adds the column sums of `[m, n]` at row stride `rs` to `acc`.
fn add_column_sums(acc: &mut [f64], g: &[f32], m: usize, n: usize, rs: usize) {
    for r in 0..m {
        for (a, v) in acc.iter_mut().zip(&g[r * rs..r * rs + n]) {
            *a += f64::from(*v);
        }
    }
}

/// Adds one tile's weight and bias gradients of layer `l` (`W [cout, W]`): `dW += dZ^T X`,
/// `db += sums(dZ)`, for `dZ [m, cout]` at row stride `dz_rs` and the layer's input `X [m,
/// W]` at row stride `x_rs`. `gw` is in `theta`'s layout, `gb` in [`Layer::bi`]'s.
#[allow(clippy::too_many_arguments)]
fn add_layer_grads(
    gw: &mut [f32],
    gb: &mut [f64],
    l: Layer,
    w: usize,
    m: usize,
    dz: (&[f32], usize),
    x: (&[f32], usize),
    prec: Precision,
) {
    let ((dz, dz_rs), (x, x_rs)) = (dz, x);
    // SAFETY: dZ^T is [cout, m] (row stride 1, column stride dz_rs), X [m, W] at row stride
    // x_rs, dst the layer's [cout, W] weight slot; the callers pass tiles of m rows.
    unsafe {
        mm(
            l.cout,
            w,
            m,
            &mut gw[l.w..l.w + l.cout * w],
            w,
            true,
            dz,
            (1, dz_rs),
            x,
            (x_rs, 1),
            prec,
        )
    };
    add_column_sums(&mut gb[l.bi..l.bi + l.cout], dz, m, l.cout, dz_rs);
}

/// `dst += src`, element by element.
fn add_into(dst: &mut [f32], src: &[f32]) {
    dst.iter_mut().zip(src).for_each(|(d, v)| *d += v);
}

/// Gradients of [`forward`] from the output's gradient `gout [rows, T]`: the features' (when
/// `need_x`) and `theta`'s (when `need_theta`). Each tile's activations are recomputed from
/// `x` (nothing of the forward pass is kept).
pub fn backward(
    x: &[f32],
    s: &DecoderShape,
    theta: &[f32],
    gout: &[f32],
    need_x: bool,
    need_theta: bool,
    prec: Precision,
) -> DecoderGrads {
    let rows = check(x, s, theta);
    let (w, t, blocks) = (s.width, s.total_outputs(), s.blocks);
    assert_eq!(gout.len(), rows * t, "decoders: gout");
    let nz = DECODERS * w;
    let mats = Mats::new(s, theta);
    let plan = Plan::new(*s, theta, &mats, prec);
    let tile = s.tile();
    // dX = dZ W for each block layer after the first ([cout, cin] as [k, n]), and for the
    // first layers all at once ([5W, W]).
    let bwd: Vec<Vec<Option<Weights>>> = (0..DECODERS)
        .map(|d| {
            (0..2 * blocks)
                .map(|l| {
                    (l > 0).then(|| {
                        let la = s.layer(d, l);
                        Weights::new(&theta[la.w..la.w + w * w], w, w, prec)
                    })
                })
                .collect()
        })
        .collect();
    let stack = (need_x && blocks > 0).then(|| Weights::new(&mats.stack, nz, w, prec));
    let ranges = parts(rows, tile);
    let part_rows = ranges.first().map_or(1, |&(a, b)| (b - a).max(1));
    let mut gx = need_x.then(|| vec![0.0f32; rows * w]);
    let mut gx_parts: Vec<Option<&mut [f32]>> = match &mut gx {
        Some(v) => v.chunks_mut(part_rows * w).map(Some).collect(),
        None => Vec::new(),
    };
    gx_parts.resize_with(ranges.len(), || None);
    let params = if need_theta { s.params() } else { 0 };
    // Per part: weight gradients (f32, GEMM-accumulated) and bias sums (f64) in `theta`'s
    // layout (weights' slots of the f64 vector and biases' of the f32 one stay unused).
    let partials: Vec<(Vec<f32>, Vec<f64>)> = ranges
        .par_iter()
        .zip(gx_parts)
        .map(|(&(a, b), mut gx_part)| {
            let mut gw = vec![0.0f32; params];
            let mut gb = vec![0.0f64; if need_theta { s.biases() } else { 0 }];
            let mut gfirst = vec![0.0f32; if need_theta { nz * w } else { 0 }];
            let mut scr = Scratch::new(s);
            let mut dz1_all = vec![0.0f32; tile * nz];
            let mut gres = vec![0.0f32; tile * w];
            let (mut gh, mut ga, mut dz2, mut dz1) = (
                vec![0.0f32; tile * w],
                vec![0.0f32; tile * w],
                vec![0.0f32; tile * w],
                vec![0.0f32; tile * w],
            );
            for r0 in (a..b).step_by(tile) {
                let m = tile.min(b - r0);
                let xt = &x[r0 * w..(r0 + m) * w];
                let gt = &gout[r0 * t..(r0 + m) * t];
                plan.first_layers(xt, m, &mut scr);
                gres[..m * w].fill(0.0);
                let mut gx_heads = false;
                for d in 0..DECODERS {
                    plan.blocks(d, xt, m, &mut scr);
                    // Head: dWh += go^T h, dbh += sums(go), dh = go Wh.
                    let lh = s.layer(d, 2 * blocks);
                    let (off, od) = (s.output_offset(d), lh.cout);
                    let h = plan.head_input(xt, m, &scr);
                    if need_theta && od > 0 {
                        // go: the head's columns of the [m, T] tile.
                        add_layer_grads(&mut gw, &mut gb, lh, w, m, (&gt[off..], t), (h, w), prec);
                    }
                    let gh_dst: &mut [f32] = if blocks == 0 {
                        // The head reads the features: its dX goes straight to the residual
                        // sum.
                        gx_heads = true;
                        &mut dz2[..m * w]
                    } else {
                        &mut gh[..m * w]
                    };
                    // SAFETY: go [m, od] at row stride T, Wh [od, W]; dst [m, W].
                    unsafe {
                        mm(
                            m,
                            w,
                            od,
                            gh_dst,
                            w,
                            false,
                            &gt[off..],
                            (t, 1),
                            &theta[lh.w..lh.w + od * w],
                            (w, 1),
                            prec,
                        )
                    };
                    if blocks == 0 {
                        add_into(&mut gres[..m * w], &dz2[..m * w]);
                    }
                    for bk in (0..blocks).rev() {
                        // Block output: h' = act(a W2^T + b2 + h).
                        let l2 = s.layer(d, 2 * bk + 1);
                        act_grad(
                            m,
                            w,
                            &gh,
                            w,
                            &scr.acts[2 * bk + 1],
                            w,
                            plan.act,
                            &mut dz2,
                            w,
                        );
                        let (a_in, a_rs): (&[f32], usize) = if bk == 0 {
                            (&scr.z[d * w..], nz)
                        } else {
                            (&scr.acts[2 * bk], w)
                        };
                        if need_theta {
                            add_layer_grads(
                                &mut gw,
                                &mut gb,
                                l2,
                                w,
                                m,
                                (&dz2, w),
                                (a_in, a_rs),
                                prec,
                            );
                        }
                        bwd[d][2 * bk + 1]
                            .as_ref()
                            .expect("block layer weights")
                            .mul(&dz2[..m * w], w, &mut ga[..m * w]);
                        // Inner activation: a = act(h W1^T + b1).
                        if bk == 0 {
                            act_grad(
                                m,
                                w,
                                &ga,
                                w,
                                a_in,
                                a_rs,
                                plan.act,
                                &mut dz1_all[d * w..],
                                nz,
                            );
                            add_into(&mut gres[..m * w], &dz2[..m * w]);
                        } else {
                            let l1 = s.layer(d, 2 * bk);
                            act_grad(m, w, &ga, w, a_in, a_rs, plan.act, &mut dz1, w);
                            let h_in = &scr.acts[2 * bk - 1][..m * w];
                            if need_theta {
                                add_layer_grads(
                                    &mut gw,
                                    &mut gb,
                                    l1,
                                    w,
                                    m,
                                    (&dz1, w),
                                    (h_in, w),
                                    prec,
                                );
                            }
                            // dh = dZ1 W1 + dZ2 (the residual).
                            bwd[d][2 * bk].as_ref().expect("block layer weights").mul(
                                &dz1[..m * w],
                                w,
                                &mut gh[..m * w],
                            );
                            add_into(&mut gh[..m * w], &dz2[..m * w]);
                        }
                    }
                }
                if blocks > 0 && need_theta {
                    // The five first layers at once: dW = dZ1_all^T X [5W, W], db = sums.
                    // SAFETY: dZ1_all^T [5W, m] (strides 1, 5W), X [m, W]; dst [5W, W].
                    unsafe {
                        mm(
                            nz,
                            w,
                            m,
                            &mut gfirst,
                            w,
                            true,
                            &dz1_all,
                            (1, nz),
                            xt,
                            (w, 1),
                            prec,
                        )
                    };
                    for d in 0..DECODERS {
                        let l = s.layer(d, 0);
                        add_column_sums(&mut gb[l.bi..l.bi + w], &dz1_all[d * w..], m, w, nz);
                    }
                }
                if let Some(p) = gx_part.as_deref_mut() {
                    let dst = &mut p[(r0 - a) * w..(r0 - a + m) * w];
                    match &stack {
                        // dX = dZ1_all [m, 5W] W1_all [5W, W] + the residuals' sum.
                        Some(st) => st.mul(&dz1_all[..m * nz], nz, dst),
                        None => dst.fill(0.0),
                    }
                    if blocks > 0 || gx_heads {
                        add_into(dst, &gres[..m * w]);
                    }
                }
            }
            if need_theta && blocks > 0 {
                for d in 0..DECODERS {
                    let l = s.layer(d, 0);
                    gw[l.w..l.w + w * w].copy_from_slice(&gfirst[d * w * w..(d + 1) * w * w]);
                }
            }
            (gw, gb)
        })
        .collect();
    let theta_grad = need_theta.then(|| {
        let mut gw = vec![0.0f32; params];
        let mut gb = vec![0.0f64; s.biases()];
        for (pw, pb) in partials {
            gw.iter_mut().zip(&pw).for_each(|(a, b)| *a += b);
            gb.iter_mut().zip(&pb).for_each(|(a, b)| *a += b);
        }
        // Bias slots take the f64 sums.
        for d in 0..DECODERS {
            for l in 0..=2 * blocks {
                let la = s.layer(d, l);
                for (g, v) in gw[la.b..la.b + la.cout]
                    .iter_mut()
                    .zip(&gb[la.bi..la.bi + la.cout])
                {
                    *g = *v as f32;
                }
            }
        }
        gw
    });
    DecoderGrads {
        x: gx,
        theta: theta_grad,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fast::testing::{lcg, on_threads};

    const SLOPE: f64 = crate::activation::LEAKY_SLOPE;

    fn lrelu(z: f64) -> f64 {
        if z > 0.0 { z } else { SLOPE * z }
    }

    fn slope(y: f64) -> f64 {
        if y > 0.0 { 1.0 } else { SLOPE }
    }

    /// `W v + b` in f64 for `W [cout, cin]` in `theta`.
    fn affine(theta: &[f32], l: Layer, cin: usize, v: &[f64]) -> Vec<f64> {
        (0..l.cout)
            .map(|o| {
                f64::from(theta[l.b + o])
                    + (0..cin)
                        .map(|i| f64::from(theta[l.w + o * cin + i]) * v[i])
                        .sum::<f64>()
            })
            .collect()
    }

    /// `W^T g` in f64.
    fn affine_t(theta: &[f32], l: Layer, cin: usize, g: &[f64]) -> Vec<f64> {
        (0..cin)
            .map(|i| {
                (0..l.cout)
                    .map(|o| f64::from(theta[l.w + o * cin + i]) * g[o])
                    .sum::<f64>()
            })
            .collect()
    }

    /// Row by row in f64, the layers one after the other: (output, dX, dtheta).
    fn reference(
        x: &[f32],
        s: &DecoderShape,
        theta: &[f32],
        gout: &[f32],
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (w, t, nb) = (s.width, s.total_outputs(), s.blocks);
        let rows = x.len() / w;
        let mut out = vec![0.0; rows * t];
        let mut gx = vec![0.0; rows * w];
        let mut gth = vec![0.0; s.params()];
        let outer = |gth: &mut [f64], l: Layer, g: &[f64], v: &[f64]| {
            for o in 0..l.cout {
                gth[l.b + o] += g[o];
                for i in 0..w {
                    gth[l.w + o * w + i] += g[o] * v[i];
                }
            }
        };
        for r in 0..rows {
            let x0: Vec<f64> = x[r * w..(r + 1) * w]
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            for d in 0..DECODERS {
                // hs[b] = block b's input, as[b] its inner activation.
                let (mut hs, mut acts) = (vec![x0.clone()], Vec::new());
                for b in 0..nb {
                    let a: Vec<f64> = affine(theta, s.layer(d, 2 * b), w, &hs[b])
                        .into_iter()
                        .map(lrelu)
                        .collect();
                    let z = affine(theta, s.layer(d, 2 * b + 1), w, &a);
                    hs.push(z.iter().zip(&hs[b]).map(|(z, h)| lrelu(z + h)).collect());
                    acts.push(a);
                }
                let lh = s.layer(d, 2 * nb);
                let off = s.output_offset(d);
                let o = affine(theta, lh, w, &hs[nb]);
                out[r * t + off..r * t + off + lh.cout].copy_from_slice(&o);
                let go: Vec<f64> = gout[r * t + off..r * t + off + lh.cout]
                    .iter()
                    .map(|&v| f64::from(v))
                    .collect();
                outer(&mut gth, lh, &go, &hs[nb]);
                let mut gh = affine_t(theta, lh, w, &go);
                for b in (0..nb).rev() {
                    let dz2: Vec<f64> = gh
                        .iter()
                        .zip(&hs[b + 1])
                        .map(|(g, y)| g * slope(*y))
                        .collect();
                    outer(&mut gth, s.layer(d, 2 * b + 1), &dz2, &acts[b]);
                    let ga = affine_t(theta, s.layer(d, 2 * b + 1), w, &dz2);
                    let dz1: Vec<f64> = ga
                        .iter()
                        .zip(&acts[b])
                        .map(|(g, y)| g * slope(*y))
                        .collect();
                    outer(&mut gth, s.layer(d, 2 * b), &dz1, &hs[b]);
                    gh = affine_t(theta, s.layer(d, 2 * b), w, &dz1)
                        .iter()
                        .zip(&dz2)
                        .map(|(a, b)| a + b)
                        .collect();
                }
                for (g, v) in gx[r * w..(r + 1) * w].iter_mut().zip(&gh) {
                    *g += v;
                }
            }
        }
        (out, gx, gth)
    }

    fn rel_err(a: &[f32], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        let num: f64 = a
            .iter()
            .zip(b)
            .map(|(a, b)| (f64::from(*a) - b).powi(2))
            .sum();
        let den: f64 = b.iter().map(|b| b * b).sum();
        (num / den.max(1e-300)).sqrt()
    }

    fn case(width: usize, blocks: usize, outputs: [usize; 5], rows: usize, seed: u64) {
        let s = DecoderShape {
            width,
            blocks,
            outputs,
        };
        let x = lcg(seed, rows * width);
        // Weights scaled like a default initialisation so that activations stay O(1).
        let scale = 1.0 / (width as f32).sqrt();
        let theta: Vec<f32> = lcg(seed + 1, s.params())
            .iter()
            .map(|v| v * scale)
            .collect();
        let gout = lcg(seed + 2, rows * s.total_outputs());
        let y = forward(&x, &s, &theta, Precision::F32);
        let g = backward(&x, &s, &theta, &gout, true, true, Precision::F32);
        let (ry, rgx, rgt) = reference(&x, &s, &theta, &gout);
        let tag = format!("{s:?}, {rows} rows");
        if rows > 0 {
            assert!(
                rel_err(&y, &ry) < 1e-5,
                "forward {tag}: {}",
                rel_err(&y, &ry)
            );
            let gx = g.x.expect("dX asked for");
            assert!(
                rel_err(&gx, &rgx) < 1e-5,
                "dX {tag}: {}",
                rel_err(&gx, &rgx)
            );
            let gt = g.theta.expect("dtheta asked for");
            assert!(
                rel_err(&gt, &rgt) < 1e-5,
                "dtheta {tag}: {}",
                rel_err(&gt, &rgt)
            );
        } else {
            assert!(y.is_empty() && g.x.is_some_and(|v| v.is_empty()));
            assert!(g.theta.is_some_and(|v| v.iter().all(|&v| v == 0.0)));
        }
    }

    #[test]
    fn fused_decoders_equal_the_layers_one_by_one() {
        // Several tiles and parts with a remainder; P = 4 heads.
        case(8, 3, [12, 12, 24, 12, 1], 600, 1);
        // An empty head, one block, a single row, a width below the SIMD width.
        case(5, 1, [3, 0, 6, 3, 1], 1, 2);
        case(5, 1, [3, 0, 6, 3, 1], 37, 3);
        // Heads straight on the features.
        case(6, 0, [2, 2, 2, 2, 2], 300, 4);
        // No rows.
        case(16, 2, [4, 4, 8, 4, 1], 0, 5);
    }

    #[test]
    fn fused_decoders_do_not_depend_on_threads_or_on_what_is_asked() {
        let s = DecoderShape {
            width: 16,
            blocks: 2,
            outputs: [12, 12, 24, 12, 1],
        };
        let rows = 3 * 256 + 17;
        let x = lcg(7, rows * s.width);
        let theta: Vec<f32> = lcg(8, s.params()).iter().map(|v| v * 0.25).collect();
        let gout = lcg(9, rows * s.total_outputs());
        let run = |threads: usize| {
            on_threads(threads, || {
                (
                    forward(&x, &s, &theta, Precision::F32),
                    backward(&x, &s, &theta, &gout, true, true, Precision::F32),
                )
            })
        };
        let (y1, g1) = run(1);
        let (y3, g3) = run(3);
        assert_eq!(y1, y3);
        assert_eq!(g1.x, g3.x);
        assert_eq!(g1.theta, g3.theta);
        let only_x = backward(&x, &s, &theta, &gout, true, false, Precision::F32);
        let only_theta = backward(&x, &s, &theta, &gout, false, true, Precision::F32);
        assert!(only_x.theta.is_none() && only_theta.x.is_none());
        assert_eq!(only_x.x, g1.x);
        assert_eq!(only_theta.theta, g1.theta);
    }

    #[test]
    fn bf16_decoders_follow_f32() {
        if !crate::fast::bf16::available() {
            return;
        }
        // Width 128: every GEMM reducing over >= 96 values runs in bf16.
        let s = DecoderShape {
            width: 128,
            blocks: 1,
            outputs: [12, 12, 24, 12, 1],
        };
        let rows = 300;
        let x = lcg(11, rows * s.width);
        let theta: Vec<f32> = lcg(12, s.params()).iter().map(|v| v * 0.09).collect();
        let gout = lcg(13, rows * s.total_outputs());
        let (ry, rgx, rgt) = reference(&x, &s, &theta, &gout);
        let y = forward(&x, &s, &theta, Precision::Bf16);
        let g = backward(&x, &s, &theta, &gout, true, true, Precision::Bf16);
        // bf16 keeps 8 bits: a few 1e-3 per GEMM; the gradients end chains of bf16 GEMMs with
        // cancellation (and LeakyReLU slopes that flip where rounding moves a pre-activation
        // across zero), so they drift further (about 1e-2 here).
        let (ey, ex, et) = (
            rel_err(&y, &ry),
            rel_err(&g.x.expect("dX"), &rgx),
            rel_err(&g.theta.expect("dtheta"), &rgt),
        );
        assert!(ey < 1e-2 && ex < 5e-2 && et < 5e-2, "{ey} {ex} {et}");
        assert!(ey > 1e-5, "bf16 did not run: {ey}");
    }
}
