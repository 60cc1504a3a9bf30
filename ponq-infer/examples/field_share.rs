//! The share of a grid that `ponq_infer::field::field_band` evaluates for analytic fields, per
//! resolution (the band inference reads; no network run):
//! `cargo run --release -p ponq-infer --example field_share -- 128 256 512 1024`.

use ponq_infer::InferOptions;
use ponq_infer::field::field_band;

/// Exact SDF of the union of a box (half size 0.45) and a sphere (radius 0.35 at x = 0.4),
/// the field of the Python tests.
fn box_sphere(p: [f64; 3]) -> f64 {
    let q = p.map(|x| x.abs() - 0.45);
    let out = q.map(|x| x.max(0.0));
    let boxd = (out[0] * out[0] + out[1] * out[1] + out[2] * out[2]).sqrt()
        + q[0].max(q[1]).max(q[2]).min(0.0);
    let s = [p[0] - 0.4, p[1], p[2]];
    let sphere = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt() - 0.35;
    boxd.min(sphere)
}

/// A sphere of radius 0.5.
fn sphere(p: [f64; 3]) -> f64 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.5
}

fn main() -> anyhow::Result<()> {
    let res: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse())
        .collect::<Result<_, _>>()?;
    let res = if res.is_empty() {
        vec![128, 256, 512, 1024]
    } else {
        res
    };
    let opts = InferOptions::default();
    println!("| field | cells per side | calls | points evaluated | share of the grid | seconds |");
    println!("|---|---:|---:|---:|---:|---:|");
    for (name, f) in [
        ("box and sphere", box_sphere as fn([f64; 3]) -> f64),
        ("sphere", sphere),
    ] {
        for &r in &res {
            let t = std::time::Instant::now();
            let (_, s) = field_band(
                r,
                4,
                &opts,
                1.0,
                65536,
                |pts| Ok(pts.iter().map(|&p| f(p)).collect()),
                |_| {},
            )?;
            println!(
                "| {name} | {r} | {} | {} | {:.2}% | {:.2} |",
                s.calls,
                s.points,
                100.0 * s.points as f64 / s.dense_points as f64,
                t.elapsed().as_secs_f64()
            );
        }
    }
    Ok(())
}
