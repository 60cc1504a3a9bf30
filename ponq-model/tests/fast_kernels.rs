//! The fast CPU kernels against Burn's stock layers: the same network (same parameters) run
//! both ways gives the same outputs, the same gradient for every parameter and the same
//! gradient for the input, on random inputs of odd sizes, crops, batches, widths 8 / 32 / 128
//! and P = 1 / 4.

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::prelude::*;
use ponq_model::{GridFrame, Kernels, PonqNet, PonqNetConfig, PonqOutput, backend};

fn random(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

fn tensor<const D: usize>(v: Vec<f32>, shape: [usize; D], d: &Device) -> Tensor<D> {
    let n = v.len();
    Tensor::<1>::from_data(TensorData::new(v, [n]), d).reshape(shape)
}

fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32 tensor")
}

/// A scalar that depends on every output: a fixed random projection of each.
fn projection(out: &PonqOutput, seed: u64, d: &Device) -> Tensor<1> {
    let proj = |t: Tensor<4>, s: u64| {
        let dims = t.dims();
        let r = tensor(random(dims.iter().product(), s), dims, d);
        (t * r).sum()
    };
    let occ = out.occupancy.clone();
    let od = occ.dims();
    proj(out.points.clone(), seed)
        + proj(out.vstars.clone(), seed + 1)
        + proj(out.normals.clone(), seed + 2)
        + proj(out.cholesky.clone(), seed + 3)
        + (occ * tensor(random(od[0] * od[1], seed + 4), od, d)).sum()
}

struct Collect<'a> {
    grads: &'a GradientsParams,
    out: Vec<(ParamId, Vec<f32>)>,
}

impl ModuleVisitor for Collect<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let g = self
            .grads
            .get::<D>(param.id)
            .map(values)
            .unwrap_or_default();
        self.out.push((param.id, g));
    }
}

/// Outputs, parameter gradients and input gradient of a run.
type Run = (Vec<Vec<f32>>, Vec<(ParamId, Vec<f32>)>, Vec<f32>);

/// Outputs, parameter gradients and input gradient of `net` on `x`.
fn run(net: &PonqNet, x: &Tensor<5>, frame: &GridFrame, d: &Device) -> Run {
    let x = x.clone().require_grad();
    let out = net.forward(x.clone(), frame);
    let outs = vec![
        values(out.points.clone()),
        values(out.vstars.clone()),
        values(out.normals.clone()),
        values(out.cholesky.clone()),
        values(out.occupancy.clone()),
    ];
    let grads = projection(&out, 11, d).backward();
    let gx = values(x.grad(&grads).expect("input gradient"));
    let gp = GradientsParams::from_grads(grads, net);
    let mut c = Collect {
        grads: &gp,
        out: Vec::new(),
    };
    net.visit(&mut c);
    (outs, c.out, gx)
}

/// Largest difference relative to the largest magnitude.
fn rel_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
        / scale
}

#[allow(clippy::too_many_arguments)]
fn check(
    width: usize,
    p: usize,
    layers: usize,
    blocks: usize,
    batch: usize,
    nodes: [usize; 3],
    frame: GridFrame,
    seed: u64,
) {
    let d = backend::cpu().autodiff();
    let cfg = PonqNetConfig::new()
        .with_width(width)
        .with_points_per_cell(p)
        .with_encoder_layers(layers)
        .with_decoder_blocks(blocks);
    let fast = cfg.init(&d);
    assert_eq!(fast.kernels(), Kernels::Fast, "fast is the default");
    assert!(fast.uses_fast_kernels(&d));
    let stock = fast.clone().with_kernels(Kernels::Stock);
    assert!(!stock.uses_fast_kernels(&d));
    let n: usize = nodes.iter().product();
    let x = tensor(
        random(batch * n, seed),
        [batch, 1, nodes[0], nodes[1], nodes[2]],
        &d,
    );
    let (of, gf, xf) = run(&fast, &x, &frame, &d);
    let (os, gs, xs) = run(&stock, &x, &frame, &d);
    let case = format!("width {width}, P {p}, batch {batch}, nodes {nodes:?}");
    for (i, (a, b)) in of.iter().zip(&os).enumerate() {
        let e = rel_diff(a, b);
        assert!(e < 1e-5, "{case}: output {i} differs by {e}");
    }
    assert_eq!(gf.len(), gs.len());
    for ((ia, a), (ib, b)) in gf.iter().zip(&gs) {
        assert_eq!(ia, ib);
        assert!(!b.is_empty(), "{case}: stock gradient of {ia:?} missing");
        let e = rel_diff(a, b);
        assert!(e < 1e-4, "{case}: gradient of {ia:?} differs by {e}");
    }
    let e = rel_diff(&xf, &xs);
    assert!(e < 1e-4, "{case}: input gradient differs by {e}");
    // The gradients are not trivially zero.
    assert!(xs.iter().any(|v| *v != 0.0));
}

#[test]
fn fast_equals_stock_narrow_odd_sizes_and_batches() {
    check(8, 1, 2, 1, 1, [6, 5, 7], GridFrame::whole(6), 1);
    check(8, 4, 1, 2, 3, [5, 5, 5], GridFrame::crop(16, [3, 0, 5]), 2);
    check(32, 4, 2, 1, 2, [4, 6, 5], GridFrame::crop(9, [1, 2, 3]), 3);
}

#[test]
fn fast_equals_stock_paper_width() {
    check(128, 4, 1, 1, 1, [4, 5, 4], GridFrame::whole(4), 4);
    check(
        128,
        1,
        2,
        1,
        2,
        [3, 4, 3],
        GridFrame::crop(12, [2, 2, 2]),
        5,
    );
}

#[test]
fn inference_without_autodiff_equals_stock() {
    let d = backend::cpu();
    let net = PonqNetConfig::new()
        .with_width(16)
        .with_points_per_cell(4)
        .with_encoder_layers(3)
        .with_decoder_blocks(2)
        .init(&d);
    let x = tensor(random(2 * 9 * 8 * 7, 9), [2, 1, 9, 8, 7], &d);
    let frame = GridFrame::whole(8);
    let a = net.forward(x.clone(), &frame);
    let b = net
        .clone()
        .with_kernels(Kernels::Stock)
        .forward(x.clone(), &frame);
    for (x, y) in [
        (values(a.points), values(b.points)),
        (values(a.cholesky), values(b.cholesky)),
        (values(a.occupancy), values(b.occupancy)),
    ] {
        assert!(rel_diff(&x, &y) < 1e-5);
    }
    // The encoder features in the stock layout agree as well.
    let fe = values(net.encode(x.clone()));
    let se = values(net.with_kernels(Kernels::Stock).encode(x));
    assert!(rel_diff(&fe, &se) < 1e-5);
}

/// `forward_cells` (decoders on listed cells only; on the plain CPU device the encoder at
/// their neighbourhoods only) gives `forward`'s values at those cells, with the fast and the
/// stock layers and on an autodiff device, for cells in any order with repeats, on a crop; and
/// rejects a batch, an empty list and a cell outside the grid.
#[test]
fn forward_cells_equals_forward_at_those_cells() {
    let d = backend::cpu();
    let net = PonqNetConfig::new()
        .with_width(16)
        .with_points_per_cell(4)
        .with_encoder_layers(2)
        .with_decoder_blocks(2)
        .init(&d);
    let x = tensor(random(9 * 8 * 7, 11), [1, 1, 9, 8, 7], &d);
    let frame = GridFrame::crop(20, [3, 1, 4]);
    let cells: Vec<usize> = vec![0, 5, 17, 17, 100, 8 * 7 * 6 - 1, 33];
    for kernels in [Kernels::Fast, Kernels::Stock] {
        let net = net.clone().with_kernels(kernels);
        let full = net.forward(x.clone(), &frame);
        let part = net.forward_cells(x.clone(), &frame, &cells).unwrap();
        assert_eq!(part.cells, [cells.len(), 1, 1]);
        let [_, c, p, _] = full.points.dims();
        assert_eq!(c, 8 * 7 * 6);
        let pick = |t: Tensor<4>, w: usize| -> Vec<f32> {
            let v = values(t);
            cells
                .iter()
                .flat_map(|&c| v[c * p * w..(c + 1) * p * w].to_vec())
                .collect()
        };
        for (name, a, b) in [
            ("points", values(part.points), pick(full.points, 3)),
            ("vstars", values(part.vstars), pick(full.vstars, 3)),
            ("normals", values(part.normals), pick(full.normals, 3)),
            ("cholesky", values(part.cholesky), pick(full.cholesky, 6)),
        ] {
            assert!(rel_diff(&a, &b) < 1e-5, "{kernels:?} {name}");
        }
        let occ = values(full.occupancy);
        let want: Vec<f32> = cells.iter().map(|&c| occ[c]).collect();
        assert!(rel_diff(&values(part.occupancy), &want) < 1e-5);
    }
    // With autodiff the fast path keeps the dense encoder (the sparse one gives no
    // gradients): the same values.
    let ad = d.clone().autodiff();
    let net_ad = net.clone().to_device(&ad);
    let xa = x.clone().to_device(&ad);
    let full = net.forward(x.clone(), &frame);
    let part = net_ad.forward_cells(xa, &frame, &cells).unwrap();
    let occ = values(full.occupancy);
    let want: Vec<f32> = cells.iter().map(|&c| occ[c]).collect();
    assert!(rel_diff(&values(part.occupancy), &want) < 1e-5, "autodiff");
    let x2 = tensor(random(2 * 9 * 8 * 7, 12), [2, 1, 9, 8, 7], &d);
    assert!(net.forward_cells(x2, &frame, &[0]).is_err(), "batch of 2");
    assert!(
        net.forward_cells(x.clone(), &frame, &[]).is_err(),
        "no cell"
    );
    assert!(
        net.forward_cells(x, &frame, &[8 * 7 * 6]).is_err(),
        "cell outside"
    );
}

/// `|a - b| / |b|` (Euclidean norms).
fn norm_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    let d: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
    let n: f64 = b.iter().map(|y| f64::from(*y).powi(2)).sum();
    (d.sqrt() / n.sqrt().max(1e-30)) as f32
}

/// `fast-bf16` (bf16 GEMM inputs, f32 sums) follows the f32 fast path within bf16 rounding
/// (8 bits of mantissa: relative errors of a few 1e-3 per layer), outputs and every gradient,
/// and is not simply the f32 path (it rounds).
#[test]
fn bf16_kernels_follow_f32_within_bf16_rounding() {
    if !ponq_model::fast::bf16::available() {
        assert!(Kernels::FastBf16.unsupported_here().is_some());
        eprintln!("no bf16 engine on this CPU: fast-bf16 not tested");
        return;
    }
    assert!(Kernels::FastBf16.unsupported_here().is_none());
    assert_eq!("fast-bf16".parse::<Kernels>(), Ok(Kernels::FastBf16));
    assert_eq!(Kernels::FastBf16.to_string(), "fast-bf16");
    let d = backend::cpu().autodiff();
    // Width 12 at least: a k3 layer's GEMMs reduce over one kernel plane (9 W values) and
    // below 96 values they stay f32.
    for (width, p, batch, nodes, frame, seed) in [
        (12, 4, 2, [6, 5, 7], GridFrame::crop(16, [3, 0, 5]), 21),
        (48, 4, 1, [9, 8, 9], GridFrame::whole(8), 22),
        (128, 1, 1, [5, 4, 5], GridFrame::whole(4), 23),
    ] {
        d.seed(seed);
        let net = PonqNetConfig::new()
            .with_width(width)
            .with_points_per_cell(p)
            .with_encoder_layers(2)
            .with_decoder_blocks(2)
            .init(&d);
        let bf = net.clone().with_kernels(Kernels::FastBf16);
        assert!(bf.uses_fast_kernels(&d));
        let n: usize = nodes.iter().product();
        let x = tensor(
            random(batch * n, seed),
            [batch, 1, nodes[0], nodes[1], nodes[2]],
            &d,
        );
        let (of, gf, xf) = run(&net, &x, &frame, &d);
        let (ob, gb, xb) = run(&bf, &x, &frame, &d);
        let case = format!("width {width}, P {p}, batch {batch}");
        let mut largest = 0.0f32;
        for (i, (a, b)) in ob.iter().zip(&of).enumerate() {
            let e = norm_diff(a, b);
            assert!(e < 1e-2, "{case}: output {i} differs by {e}");
            largest = largest.max(e);
        }
        assert!(
            largest > 1e-7,
            "{case}: bf16 output equals f32: not rounded?"
        );
        // Gradients: sums over many cells with cancellation, so bf16's relative error grows
        // for the first layers' small parameter vectors; the whole gradient stays close (the
        // per-kernel exactness is tested in `fast::kernels`).
        let (mut all_b, mut all_f) = (vec![], vec![]);
        for ((ia, a), (ib, b)) in gb.iter().zip(&gf) {
            assert_eq!(ia, ib);
            let e = norm_diff(a, b);
            assert!(e < 0.25, "{case}: gradient of {ia:?} differs by {e}");
            all_b.extend_from_slice(a);
            all_f.extend_from_slice(b);
        }
        let e = norm_diff(&all_b, &all_f);
        assert!(e < 0.1, "{case}: the whole gradient differs by {e}");
        // The input gradient ends a chain of bf16 GEMMs through every layer (and LeakyReLU
        // slopes that flip where rounding moves a pre-activation across zero).
        let e = norm_diff(&xb, &xf);
        assert!(e < 0.15, "{case}: input gradient differs by {e}");
        // Inference (no autodiff, sparse encoder) follows too.
        let dc = backend::cpu();
        dc.seed(seed);
        let plain = PonqNetConfig::new()
            .with_width(width)
            .with_points_per_cell(p)
            .with_encoder_layers(2)
            .with_decoder_blocks(2)
            .init(&dc);
        let xc = tensor(random(n, seed), [1, 1, nodes[0], nodes[1], nodes[2]], &dc);
        let f32_out = values(plain.forward(xc.clone(), &frame).normals);
        let bf_out = values(
            plain
                .with_kernels(Kernels::FastBf16)
                .forward(xc, &frame)
                .normals,
        );
        let e = norm_diff(&bf_out, &f32_out);
        assert!(e < 1e-2, "{case}: inference normals differ by {e}");
    }
}
