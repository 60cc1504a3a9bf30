//! The SDF grids of generated shapes agree with their exact surface (the one their samples
//! come from), on many seeds: the sign of every node is the exact inside test's; within three
//! cells of the 65^3 grid of the surface, |sdf| exceeds the distance to the nearest of 300,000
//! independent exact boundary samples by at most 2% of such a cell, and no boundary point lies
//! within |sdf| minus 2% of a cell (random points of that ball all share the node's inside
//! test); farther away, by at most 30% of a cell.

use ponq_data::prep::{PrepOptions, prepare_synth};
use ponq_data::synth::{SynthOptions, generate};
use ponq_mesh::nn::PointIndex;
use rand::{Rng, SeedableRng};

#[test]
fn synth_grids_agree_with_the_exact_surface() {
    let res = 32;
    let cell65 = 2.0 / 64.0;
    let opts = SynthOptions {
        samples: 300_000,
        ..Default::default()
    };
    let prep = PrepOptions {
        resolutions: vec![res],
        samples: 300_000,
        seed: 0,
        ..Default::default()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut checked_balls = 0;
    for seed in 200..206u64 {
        let shape = generate(seed, &opts).unwrap();
        let rec = prepare_synth(&shape, seed, &prep).unwrap().record;
        let grid = &rec.sdf[&res];
        // Independent exact samples: the shape's own (a different random stream).
        let index = PointIndex::new(&shape.samples).unwrap();
        let m = res + 1;
        let c = |t: usize| -1.0 + 2.0 * t as f64 / res as f64;
        for i in 0..m {
            for j in 0..m {
                for k in 0..m {
                    let p = [c(i), c(j), c(k)];
                    let v = f64::from(grid[(i * m + j) * m + k]);
                    let bound = index.nearest(&p).1.sqrt();
                    let slack = if v.abs() <= 3.0 * cell65 { 0.02 } else { 0.3 } * cell65;
                    assert!(
                        v.abs() <= bound + slack,
                        "seed {seed} node {p:?}: |sdf| {v} exceeds the distance {bound} to an exact sample"
                    );
                    assert_eq!(
                        v < 0.0,
                        shape.inside(p) && v != 0.0,
                        "seed {seed} node {p:?}: sign"
                    );
                    // Ball check on some nodes within two 33^3 cells of the surface.
                    let r = v.abs() - 0.02 * cell65;
                    if v.abs() <= 3.0 * cell65 && r > 0.0 && (i + 2 * j + 3 * k) % 3 == 0 {
                        checked_balls += 1;
                        let centre = shape.inside(p);
                        for _ in 0..200 {
                            let u: [f64; 3] =
                                std::array::from_fn(|_| rng.random::<f64>() * 2.0 - 1.0);
                            let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
                            if l > 1.0 {
                                continue;
                            }
                            let q = std::array::from_fn(|a| p[a] + r * u[a]);
                            assert_eq!(
                                shape.inside(q),
                                centre,
                                "seed {seed} node {p:?}: a boundary point within |sdf| {v} minus 2% of a cell"
                            );
                        }
                    }
                }
            }
        }
    }
    assert!(checked_balls > 300, "{checked_balls} balls checked");
}
