//! How far the SDF grids of generated shapes are from their exact surface: for each node near
//! the surface, |sdf| minus the distance to the nearest of 2,000,000 exact surface samples (a
//! positive value is an error of at least that size), in cells of the grid.
//! `cargo run --release -p ponq-data --example gt_consistency -- RES SEED...`
use ponq_data::sdf::MeshSdf;
use ponq_data::synth::{SynthOptions, generate};
use ponq_mesh::nn::PointIndex;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let res: usize = args.first().map(|s| s.parse()).transpose()?.unwrap_or(64);
    let seeds: Vec<u64> = args
        .iter()
        .skip(1)
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let seeds = if seeds.is_empty() {
        (1000..1012).collect()
    } else {
        seeds
    };
    let cell = 2.0 / res as f64;
    for seed in seeds {
        let mesh_res: usize = std::env::var("MESH_RES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(96);
        let mut mix = ponq_data::synth::SynthMix::default();
        match std::env::var("FAMILY").as_deref() {
            Ok("filleted") => (mix.csg, mix.filleted) = (0.0, 1.0),
            Ok("lathe") => (mix.csg, mix.lathe) = (0.0, 1.0),
            Ok("freeform") => (mix.csg, mix.freeform) = (0.0, 1.0),
            _ => {}
        }
        let opts = SynthOptions {
            samples: 2_000_000,
            mesh_resolution: mesh_res,
            mix,
            ..Default::default()
        };
        let t0 = std::time::Instant::now();
        let s = generate(seed, &opts)?;
        eprintln!(
            "{:?} in {} attempts, {:.2} s: {}",
            s.family,
            s.attempts,
            t0.elapsed().as_secs_f64(),
            s.primitive_kinds().join(" ")
        );
        let exact = std::env::var("EXACT").is_ok();
        let grid = MeshSdf::new(&s.mesh)?.grid(res, |_| {})?;
        let t = std::time::Instant::now();
        let ed = ponq_data::synth::distance::ExactDistance::new(&s.solid, &s.mesh, 1_000_000, seed)
            .expect("samples");
        eprintln!("samples: {:.2} s", t.elapsed().as_secs_f64());
        let exact_grid = ed.grid(res);
        eprintln!("exact grid: {:.2} s", t.elapsed().as_secs_f64());
        let index = PointIndex::new(&s.samples).expect("samples");
        let mut worst: f64 = 0.0;
        let mut worst_under: f64 = 0.0;
        let mut n = 0;
        let mut at = ([0.0; 3], [0.0; 3], 0.0);
        let m = res + 1;
        for i in 0..m {
            for j in 0..m {
                for k in 0..m {
                    let v = if exact {
                        f64::from(exact_grid[grid.index(i, j, k)])
                    } else {
                        f64::from(grid.get(i, j, k))
                    };
                    let band: f64 = std::env::var("BAND")
                        .ok()
                        .and_then(|b| b.parse().ok())
                        .unwrap_or(2.0);
                    if v.abs() > band * cell {
                        continue;
                    }
                    let p = grid.node_position(i, j, k);
                    let (_, d2) = index.nearest(&p);
                    let d = d2.sqrt();
                    if v.abs() - d > worst {
                        worst = v.abs() - d;
                        at = (p, s.samples[index.nearest(&p).0 as usize], v);
                    }
                    worst_under = worst_under.max(d - v.abs());
                    n += 1;
                    // Sign against the exact inside test.
                    if (v < 0.0) != s.inside(p) && v.abs() > 1e-9 {
                        worst = worst.max(v.abs());
                    }
                }
            }
        }
        println!(
            "seed {seed}: {n} nodes within 2 cells; |sdf| - d_sample max {:.4} cells ({:.5}); d_sample - |sdf| max {:.4} cells",
            worst / cell,
            worst,
            worst_under / cell
        );
        println!(
            "   worst at node {:?} (sdf {:.5}), nearest sample {:?}",
            at.0, at.2, at.1
        );
    }
    Ok(())
}
