//! Survey of the procedural shapes (ignored by default): per-seed statistics, rejections and
//! timings, optionally writing each mesh and its CSG description to a folder.
//!
//! `cargo test --release -p ponq-data --test synth_survey -- --ignored --nocapture`
//!
//! Environment: `SYNTH_SEEDS` (40), `SYNTH_RES` (96), `SYNTH_SAMPLES` (100000), `SYNTH_SPC`
//! (samples per cell, 16), `SYNTH_VOL` (Monte-Carlo points, 100000), `SYNTH_OUT` (a folder
//! for `seed_N.obj` and `seed_N.txt`).

use ponq_data::synth::{SynthOptions, generate};

#[test]
#[ignore]
fn survey() {
    let env = |k: &str, d: usize| {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let n = env("SYNTH_SEEDS", 40) as u64;
    let res = env("SYNTH_RES", 96);
    let opts = SynthOptions {
        mesh_resolution: res,
        samples: env("SYNTH_SAMPLES", 100_000),
        samples_per_cell: env("SYNTH_SPC", 16) as f64,
        volume_samples: env("SYNTH_VOL", 100_000),
        max_attempts: 1000,
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let mut attempts = 0;
    for seed in 0..n {
        let t0 = std::time::Instant::now();
        let s = generate(seed, &opts).expect("shape");
        attempts += s.attempts;
        let st = &s.stats;
        println!(
            "seed {seed}: {:.3}s att {} F {} genus {} pts {} smp {} vol {:.4}/{:.4} far {:.4} {:.4} max {:.2} times {:?} kinds {:?}",
            t0.elapsed().as_secs_f64(),
            s.attempts,
            s.mesh.faces.len(),
            st.genus,
            st.ponq_points,
            st.mesh_samples,
            st.mesh_volume,
            st.csg_volume,
            st.far_samples,
            st.far_vertices,
            st.max_sample_distance,
            st.times.map(|d| (d.as_secs_f64() * 1000.0).round()),
            s.primitive_kinds()
        );
        if let Ok(dir) = std::env::var("SYNTH_OUT") {
            ponq_mesh::io::write_mesh(format!("{dir}/seed_{seed}.obj"), &s.mesh).unwrap();
            std::fs::write(format!("{dir}/seed_{seed}.txt"), &s.description).unwrap();
        }
        for r in &s.rejected {
            println!("   rejected: {r}");
        }
    }
    println!(
        "{n} shapes, {attempts} attempts, {:.2}s per shape",
        t.elapsed().as_secs_f64() / n as f64
    );
}
