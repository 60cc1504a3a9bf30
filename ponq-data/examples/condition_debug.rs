//! Prints what the conditioning measures on a grid: `cargo run --release -p ponq-data --example
//! condition_debug -- GRID.npy [LEVEL]`.
use ponq_data::condition::{
    ConditionOptions, FieldScan, crossings, fit_linear, fit_monotone, pairs,
};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let g = ponq_mesh::io::npy::read_npy_grid(&args[1]).expect("grid");
    let level: f64 = args.get(2).map_or(0.0, |s| s.parse().expect("level"));
    let flip = args.get(3).is_some();
    let n = g.dims[0] - 1;
    let h = 2.0 / n as f64;
    let u: Vec<f64> = g
        .data
        .iter()
        .map(|&v| if flip { level - v } else { v - level })
        .collect();
    let z = crossings(&u, &u, g.dims, h);
    let p = pairs(&u, &u, g.dims, h, &z, 6.0, usize::MAX, |_| false);
    println!("{} crossings, {} pairs", z.len(), p.len());
    let mut hist = [0usize; 8];
    for (_, d) in &p {
        hist[((d.abs() / h) as usize).min(7)] += 1;
    }
    println!("pairs by |d| cells: {hist:?}");
    println!("linear: {:?}", fit_linear(&p, h));
    if args.get(4).is_some_and(|f| f == "tanh") {
        pair_errors(&p, h);
    }
    if let Some((m, e)) = fit_monotone(&p, (f64::NAN, f64::NAN), h) {
        println!("monotone error {:.4} cells, power {}", e / h, m.power());
        let mapped: Vec<f64> = u.iter().map(|&x| m.eval(x)).collect();
        let z2 = crossings(&mapped, &u, g.dims, h);
        let p2 = pairs(&u, &u, g.dims, h, &z2, 6.0, usize::MAX, |_| false);
        println!("second pass: {} pairs", p2.len());
        if args.get(4).is_some_and(|f| f == "tanh") {
            pair_errors(&p2, h);
        }
        for (a, b) in m.knots().step_by(8) {
            println!("  {a:.5} -> {:.3} cells", b / h);
        }
    }
    let mut scan = FieldScan::new(g.dims, &ConditionOptions::default());
    let plane = g.dims[1] * g.dims[2];
    for c in g.data.chunks(plane) {
        scan.push_plane(c).expect("plane");
    }
    match scan.finish(1.0) {
        Ok(c) => {
            println!("{}", c.summary());
            // Against a known function of the distance, when given: tanh or sigmoid.
            if let Some(f) = args.get(4) {
                for k in -24..=24 {
                    let d = f64::from(k) / 4.0 * h;
                    let v = match f.as_str() {
                        "tanh" => (d / h).tanh(),
                        "sigmoid" => 1.0 / (1.0 + (d / h).exp()),
                        "dd" => d * d.abs(),
                        _ => d,
                    };
                    println!("  d {:+.2} cells -> {:+.3} cells", d / h, c.apply(v) / h);
                }
            }
        }
        Err(e) => println!("{e}"),
    }
}

/// Errors of the pairs of a tanh field against its exact inverse (for the debug only).
#[allow(dead_code)]
fn pair_errors(p: &[(f64, f64)], h: f64) {
    let mut e: Vec<(f64, f64, f64)> = p
        .iter()
        .map(|&(u, d)| {
            (
                d / h,
                u.clamp(-0.999999, 0.999999).atanh(),
                (d / h - u.clamp(-0.999999, 0.999999).atanh()),
            )
        })
        .collect();
    e.sort_by(|a, b| a.2.abs().total_cmp(&b.2.abs()));
    let n = e.len();
    println!(
        "pair errors (cells): median {:.3}, p90 {:.3}, max {:.3}",
        e[n / 2].2.abs(),
        e[n * 9 / 10].2.abs(),
        e[n - 1].2.abs()
    );
    for x in e.iter().rev().take(8) {
        println!("  pair d {:.3} true {:.3}", x.0, x.1);
    }
}
