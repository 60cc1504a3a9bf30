//! GFLOP/s of each fast CPU kernel on the layer shapes of the paper's network (32^3 cells,
//! width 128) and of `configs/cpu.toml`'s (8 crops of 16^3 cells, width 32).
//! The five decoders fused ([`ponq_model::fast::decoders`]) against their layers one at a
//! time. `cargo bench -p ponq-model --bench kernel_bench`; `train_bench` (ponq-train) gives the
//! whole network and the GEMM ceiling.

use std::time::Instant;

use ponq_model::fast::kernels::*;

fn best(mut f: impl FnMut(), n: usize) -> f64 {
    let mut b = f64::MAX;
    for _ in 0..n {
        let t = Instant::now();
        f();
        b = b.min(t.elapsed().as_secs_f64());
    }
    b
}

fn values(n: usize, m: usize) -> Vec<f32> {
    (0..n).map(|i| (i % m) as f32 * 0.1 - 0.3).collect()
}

fn main() {
    println!("| layer | shape | kernel | ms | GFLOP/s |\n|---|---|---|---:|---:|");
    let mut precisions = vec![Precision::F32];
    if ponq_model::fast::bf16::available() {
        precisions.push(Precision::Bf16);
    } else {
        println!("(no AVX-512 BF16 on this CPU: f32 only)");
    }
    // The paper's network (32^3 cells, width 128), the shipped model's (8 crops of 16^3 cells,
    // width 48) and configs/cpu.toml's (width 32).
    for (d, c, batch) in [(32usize, 128usize, 1usize), (16, 48, 8), (16, 32, 8)] {
        for &prec in &precisions {
            let p = if prec == Precision::Bf16 { "bf16 " } else { "" };
            let s = ConvShape {
                batch,
                dims: [d; 3],
                cin: c,
                cout: c,
                k: 3,
                pad: 1,
            };
            let name = format!("{batch} x {d}^3, {c} channels");
            let x = values(s.in_rows() * c, 7);
            let w: Vec<f32> = values(c * c * 27, 5).iter().map(|v| v * 0.1).collect();
            let b = vec![0.1f32; c];
            let gz = values(s.out_rows() * c, 3);
            let flops = 2.0 * (s.out_rows() * 27 * c * c) as f64;
            let packed = pack_weight(&w, &s, false);
            let row = |kernel: &str, t: f64, f: f64| {
                println!(
                    "| k3 conv | {name} | {p}{kernel} | {:.2} | {:.0} |",
                    t * 1e3,
                    f / t / 1e9
                )
            };
            let t = best(
                || {
                    std::hint::black_box(conv_forward(
                        &x,
                        &s,
                        &packed,
                        Some(&b),
                        Act::Leaky(0.01),
                        prec,
                    ));
                },
                3,
            );
            row("forward", t, flops);
            let t = best(
                || drop(std::hint::black_box(conv_input_grad(&s, &w, &gz, prec))),
                3,
            );
            row("input gradient", t, flops);
            let t = best(
                || drop(std::hint::black_box(conv_weight_grad(&x, &s, &gz, prec))),
                3,
            );
            row("weight gradient", t, flops);
            if prec == Precision::F32 {
                // The Winograd form (used from ponq_model::fast::winograd::MIN_CHANNELS
                // channels); GFLOP/s counted as the direct form's work, so comparable.
                use ponq_model::fast::winograd;
                let t = best(
                    || {
                        std::hint::black_box(winograd::conv_forward(
                            &x,
                            &s,
                            &w,
                            Some(&b),
                            Act::Leaky(0.01),
                        ));
                    },
                    3,
                );
                row("Winograd forward", t, flops);
                let t = best(
                    || drop(std::hint::black_box(winograd::conv_input_grad(&s, &w, &gz))),
                    3,
                );
                row("Winograd input gradient", t, flops);
                let t = best(
                    || {
                        drop(std::hint::black_box(winograd::conv_weight_grad(
                            &x, &s, &gz,
                        )))
                    },
                    3,
                );
                row("Winograd weight gradient", t, flops);
            }
            let rows = s.out_rows();
            let wl: Vec<f32> = values(c * c, 5).iter().map(|v| v * 0.1).collect();
            let lf = 2.0 * (rows * c * c) as f64;
            let xl = &x[..rows * c];
            let t = best(
                || {
                    std::hint::black_box(linear_forward(
                        xl,
                        c,
                        &wl,
                        &b,
                        Some(&gz),
                        Act::Leaky(0.01),
                        prec,
                    ));
                },
                5,
            );
            println!(
                "| 1x1x1 + residual | {name} | {p}forward | {:.2} | {:.0} |",
                t * 1e3,
                lf / t / 1e9
            );
            // Before: dZ, (dX, dW) and db in three passes (f32); now: one fused pass per row tile.
            let yl = &gz[..rows * c];
            if prec == Precision::F32 {
                let t = best(
                    || {
                        let g = activation_grad(yl, yl, Act::Leaky(0.01));
                        drop(std::hint::black_box(linear_backward(
                            xl, c, &wl, &g, c, true, true,
                        )));
                        drop(std::hint::black_box(column_sums(&g, c)));
                    },
                    5,
                );
                println!(
                    "| 1x1x1 | {name} | {p}backward (dZ, dX, dW, db), three passes | {:.2} | {:.0} |",
                    t * 1e3,
                    2.0 * lf / t / 1e9
                );
            }
            let all = LinearNeeds {
                x: true,
                w: true,
                b: true,
                z: false,
            };
            let t = best(
                || {
                    drop(std::hint::black_box(linear_grads(
                        xl,
                        c,
                        &wl,
                        yl,
                        yl,
                        Act::Leaky(0.01),
                        c,
                        all,
                        prec,
                    )))
                },
                5,
            );
            println!(
                "| 1x1x1 | {name} | {p}backward (dZ, dX, dW, db), fused | {:.2} | {:.0} |",
                t * 1e3,
                2.0 * lf / t / 1e9
            );
            // The five decoders (3 blocks, P = 4 heads) fused per row tile, against their 35
            // layers one at a time (forward).
            let ds = ponq_model::fast::decoders::DecoderShape {
                width: c,
                blocks: 3,
                outputs: [12, 12, 24, 12, 1],
            };
            let theta: Vec<f32> = values(ds.params(), 11).iter().map(|v| v * 0.05).collect();
            let df = 2.0 * (rows * (ds.params() - 3 * 5 * 2 * c - 61)) as f64;
            let t = best(
                || {
                    let mut outs = Vec::new();
                    for d in 0..5 {
                        let mut h = xl.to_vec();
                        for _ in 0..3 {
                            let a = linear_forward(&h, c, &wl, &b, None, Act::Leaky(0.01), prec);
                            h = linear_forward(&a, c, &wl, &b, Some(&h), Act::Leaky(0.01), prec);
                        }
                        let o = ds.outputs[d];
                        outs.push(linear_forward(
                            &h,
                            c,
                            &wl[..o * c],
                            &b[..o],
                            None,
                            Act::Identity,
                            prec,
                        ));
                    }
                    std::hint::black_box(outs);
                },
                3,
            );
            println!(
                "| five decoders | {name} | {p}forward, 35 layers one by one | {:.2} | {:.0} |",
                t * 1e3,
                df / t / 1e9
            );
            let t = best(
                || {
                    drop(std::hint::black_box(ponq_model::fast::decoders::forward(
                        xl, &ds, &theta, prec,
                    )))
                },
                3,
            );
            println!(
                "| five decoders | {name} | {p}forward, fused | {:.2} | {:.0} |",
                t * 1e3,
                df / t / 1e9
            );
            let gout = values(rows * ds.total_outputs(), 13);
            let t = best(
                || {
                    drop(std::hint::black_box(ponq_model::fast::decoders::backward(
                        xl, &ds, &theta, &gout, true, true, prec,
                    )))
                },
                3,
            );
            println!(
                "| five decoders | {name} | {p}backward, fused (recomputes the forward) | {:.2} | {:.0} |",
                t * 1e3,
                3.0 * df / t / 1e9
            );
        }
    }
}
