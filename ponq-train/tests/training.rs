//! Data pipeline and training loop: crops and rotations keep samples on the zero level set,
//! the smoke run's loss falls, resume repeats the uninterrupted run, the CLI works.

use std::path::PathBuf;

use ponq_model::backend;
use ponq_train::config::TrainConfig;
use ponq_train::data::{ItemOptions, make_item, sphere_shape};
use ponq_train::train::{RunOptions, run_with_shapes};
use rand::SeedableRng;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ponq-train-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Trilinear interpolation of a `(c+1)^3` node grid over `[-1, -1 + c * cell]^3`.
fn interp(sdf: &[f32], c: usize, cell: f32, p: [f32; 3]) -> f32 {
    let m = c + 1;
    let mut idx = [0usize; 3];
    let mut f = [0f32; 3];
    for a in 0..3 {
        let t = (p[a] + 1.0) / cell;
        let i = (t.floor() as isize).clamp(0, c as isize - 1) as usize;
        idx[a] = i;
        f[a] = t - i as f32;
    }
    let mut v = 0.0;
    for d in 0..8 {
        let o = [(d >> 2) & 1, (d >> 1) & 1, d & 1];
        let w: f32 = (0..3)
            .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
            .product();
        v += w * sdf[((idx[0] + o[0]) * m + idx[1] + o[1]) * m + idx[2] + o[2]];
    }
    v
}

#[test]
fn crops_and_rotations_keep_samples_on_the_surface() {
    // An off-centre sphere, so that a wrong axis map would move the surface.
    let shape = sphere_shape("s", 16, [0.3, -0.2, 0.1], 0.5, 4000);
    let cell = 2.0 / 16.0;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    for _ in 0..40 {
        let it = make_item(
            &shape,
            &ItemOptions {
                crop: 8,
                samples: 500,
                augment: true,
            },
            &mut rng,
        );
        assert_eq!(it.sdf.len(), 9 * 9 * 9);
        assert!(!it.samples.is_empty(), "crops are chosen to hold surface");
        for (p, n) in it.samples.iter().zip(&it.normals) {
            // On the zero level set (trilinear error of a sphere at this resolution)...
            let v = interp(&it.sdf, 8, cell, *p);
            assert!(v.abs() < 0.02, "sdf {v} at sample {p:?}");
            // ... and the normal points outwards: the SDF grows along it.
            let q: [f32; 3] = std::array::from_fn(|a| p[a] + 0.05 * n[a]);
            if q.iter().all(|&x| (-1.0..=-1.0 + 8.0 * cell).contains(&x)) {
                assert!(interp(&it.sdf, 8, cell, q) > v);
            }
        }
        // Occupied cells are those holding samples; a cell with a sample is close.
        let occupied = it.occupied.iter().filter(|&&o| o).count();
        assert!(occupied > 0);
        for (o, c) in it.occupied.iter().zip(&it.close) {
            if *o {
                assert!(
                    *c,
                    "an occupied cell of a sphere at this resolution is close"
                );
            }
        }
    }
}

/// Options of a quiet run on `device` with the default kernels, writing to `out`.
fn opts(out: PathBuf, resume: bool, device: burn::prelude::Device) -> RunOptions {
    RunOptions {
        out,
        resume,
        device,
        quiet: true,
        kernels: ponq_model::Kernels::default(),
        extra_devices: Vec::new(),
    }
}

fn smoke_config() -> TrainConfig {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/smoke.toml");
    let mut cfg = TrainConfig::load(&path).expect("configs/smoke.toml parses");
    cfg.train.mesh_validate_every = 0;
    cfg
}

fn shapes() -> (Vec<ponq_train::data::Shape>, Vec<ponq_train::data::Shape>) {
    let train = vec![
        sphere_shape("a", 8, [0.1, 0.0, -0.1], 0.5, 3000),
        sphere_shape("b", 8, [-0.2, 0.1, 0.0], 0.6, 3000),
        sphere_shape("c", 8, [0.0, -0.15, 0.2], 0.45, 3000),
        sphere_shape("d", 8, [0.05, 0.05, 0.05], 0.65, 3000),
    ];
    let val = vec![sphere_shape("v", 8, [0.0, 0.1, 0.0], 0.55, 3000)];
    (train, val)
}

#[test]
fn smoke_training_loss_falls() {
    let mut cfg = smoke_config();
    cfg.train.epochs = 20;
    cfg.train.lr = 1e-2;
    let (train, val) = shapes();
    let out = tmp("falls");
    let opts = opts(out.clone(), false, backend::cpu());
    let s = run_with_shapes(&cfg, &train, &val, &opts).expect("training runs");
    assert_eq!(s.epochs_done, 20);
    let k = 4;
    let first: f64 = s.step_losses[..k].iter().sum::<f64>() / k as f64;
    let last: f64 = s.step_losses[s.step_losses.len() - k..].iter().sum::<f64>() / k as f64;
    assert!(last < 0.85 * first, "loss {first} -> {last}");
    let v = &s.validation;
    assert!(
        v.last().unwrap().1.total < v.first().unwrap().1.total,
        "{v:?}"
    );
    // Files of a run.
    for f in [
        "metrics.csv",
        "losses.png",
        "model.bpk",
        "model.json",
        "checkpoint/state.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 20);
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn resume_repeats_the_uninterrupted_run() {
    let mut cfg = smoke_config();
    cfg.train.epochs = 3;
    let (train, val) = shapes();
    let dev = backend::cpu();
    // Both runs start from the same saved weights (initialisation draws from a global RNG
    // that tests running in parallel share).
    let init = tmp("init");
    std::fs::create_dir_all(&init).unwrap();
    let init_file = init.join("init.bpk");
    let net = cfg.model.net();
    ponq_model::weights::save(&net.init(&dev), &net, &init_file).unwrap();
    cfg.train.init_from = Some(init_file);
    let a = tmp("whole");
    let whole = run_with_shapes(&cfg, &train, &val, &opts(a.clone(), false, dev.clone())).unwrap();
    // Interrupted after epoch 2, then resumed.
    let b = tmp("parts");
    cfg.train.epochs = 2;
    let first = run_with_shapes(&cfg, &train, &val, &opts(b.clone(), false, dev.clone())).unwrap();
    cfg.train.epochs = 3;
    let rest = run_with_shapes(&cfg, &train, &val, &opts(b.clone(), true, dev)).unwrap();
    assert_eq!(rest.epochs_done, 3);
    // Totals add up across the interrupted run and its continuation.
    assert_eq!(rest.total_steps, whole.total_steps);
    assert_eq!(first.total_steps + rest.step_losses.len(), rest.total_steps);
    assert!(rest.total_seconds > first.total_seconds);
    let steps = first.step_losses.len();
    assert_eq!(whole.step_losses.len(), steps + rest.step_losses.len());
    for (i, (x, y)) in whole.step_losses[..steps]
        .iter()
        .zip(&first.step_losses)
        .enumerate()
    {
        assert!((x - y).abs() <= 1e-5 * x.abs(), "step {i}: {x} vs {y}");
    }
    for (i, (x, y)) in whole.step_losses[steps..]
        .iter()
        .zip(&rest.step_losses)
        .enumerate()
    {
        assert!(
            (x - y).abs() <= 1e-4 * x.abs(),
            "resumed step {i}: {x} vs {y}"
        );
    }
    let csv = std::fs::read_to_string(b.join("metrics.csv")).unwrap();
    assert_eq!(
        csv.lines().count(),
        1 + 3,
        "one row per epoch across the resume"
    );
    std::fs::remove_dir_all(&a).ok();
    std::fs::remove_dir_all(&b).ok();
    std::fs::remove_dir_all(&init).ok();
}

#[test]
fn cli_trains_the_smoke_config_and_rejects_bad_input() {
    let exe = env!("CARGO_BIN_EXE_ponq-train");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let out = tmp("cli");
    let o = std::process::Command::new(exe)
        .current_dir(&root)
        .args([
            "--config",
            "configs/smoke.toml",
            "--epochs",
            "2",
            "-q",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("model.bpk").is_file());
    // A missing config, an unknown key, a bad backend: exit 2 with a message.
    let bad = out.join("bad.toml");
    std::fs::write(&bad, "[train]\nepochz = 3\n").unwrap();
    for args in [
        vec!["--config".to_string(), "no/such.toml".into()],
        vec!["--config".to_string(), bad.display().to_string()],
    ] {
        let o = std::process::Command::new(exe)
            .current_dir(&root)
            .args(&args)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(!o.stderr.is_empty());
    }
    let o = std::process::Command::new(exe)
        .current_dir(&root)
        .args(["--config", "configs/smoke.toml", "--backend", "tpu"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    // Device lists: several CPU devices, several wgpu devices, repeated or invalid indices,
    // more devices than shapes per batch, CUDA without the feature: exit 2, no panic.
    for (args, expect) in [
        (vec!["--devices", "0,1"], "--backend cuda"),
        (vec!["--devices", "0,0"], "twice"),
        (vec!["--devices", "zero"], "invalid device index"),
        (vec!["--backend", "wgpu", "--devices", "0,1"], "collective"),
        (
            vec!["--backend", "cuda", "--devices", "0,1,2"],
            "at least one",
        ),
        (vec!["--backend", "cuda"], "cuda"),
    ] {
        let o = std::process::Command::new(exe)
            .current_dir(&root)
            .args(["--config", "configs/smoke.toml", "-q", "--out"])
            .arg(out.join("devices"))
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(expect), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    std::fs::remove_dir_all(&out).ok();
}

/// The fast CPU kernels and Burn's stock layers train the same network the same way: from the
/// same initial weights, the loss curves of a short run agree within float tolerance.
#[test]
fn fast_and_stock_kernels_give_the_same_loss_curve() {
    let mut cfg = smoke_config();
    cfg.train.epochs = 4;
    let (train, val) = shapes();
    let dev = backend::cpu();
    let init = tmp("kernels-init");
    std::fs::create_dir_all(&init).unwrap();
    let init_file = init.join("init.bpk");
    let net = cfg.model.net();
    ponq_model::weights::save(&net.init(&dev), &net, &init_file).unwrap();
    cfg.train.init_from = Some(init_file);
    let run = |kernels: ponq_model::Kernels| {
        let out = tmp(&format!("kernels-{kernels}"));
        let s = run_with_shapes(
            &cfg,
            &train,
            &val,
            &RunOptions {
                out: out.clone(),
                resume: false,
                device: dev.clone(),
                quiet: true,
                kernels,
                extra_devices: Vec::new(),
            },
        )
        .unwrap();
        std::fs::remove_dir_all(&out).ok();
        s
    };
    let fast = run(ponq_model::Kernels::Fast);
    let stock = run(ponq_model::Kernels::Stock);
    assert_eq!(fast.step_losses.len(), stock.step_losses.len());
    assert!(fast.step_losses.len() >= 8);
    for (i, (x, y)) in fast.step_losses.iter().zip(&stock.step_losses).enumerate() {
        assert!(
            (x - y).abs() <= 1e-3 * y.abs(),
            "step {i}: fast {x} vs stock {y}"
        );
    }
    for ((_, a), (_, b)) in fast.validation.iter().zip(&stock.validation) {
        assert!(
            (a.total - b.total).abs() <= 1e-3 * b.total,
            "{a:?} vs {b:?}"
        );
    }
    std::fs::remove_dir_all(&init).ok();
}

/// Data parallelism's split: a batch cut into shards (3 shapes -> 2 + 1, the last batch of an
/// epoch 1 shape) whose losses are weighted by their share of the batch and whose gradients
/// are summed takes the same steps as the whole batch at once (the code path of several
/// devices, run as micro-batches on one): the loss curves and the final weights agree.
#[test]
fn micro_batches_take_the_whole_batch_step() {
    let mut cfg = smoke_config();
    cfg.train.epochs = 3;
    cfg.train.batch_size = 3;
    let (train, val) = shapes();
    let dev = backend::cpu();
    let init = tmp("micro-init");
    std::fs::create_dir_all(&init).unwrap();
    let init_file = init.join("init.bpk");
    let net = cfg.model.net();
    ponq_model::weights::save(&net.init(&dev), &net, &init_file).unwrap();
    cfg.train.init_from = Some(init_file);
    // All parameters, flattened.
    struct Flat(Vec<f32>);
    impl burn::module::ModuleVisitor for Flat {
        fn visit_float<const D: usize>(
            &mut self,
            param: &burn::module::Param<burn::prelude::Tensor<D>>,
        ) {
            self.0.extend(
                param
                    .val()
                    .into_data()
                    .convert::<f32>()
                    .try_to_vec::<f32>()
                    .unwrap(),
            );
        }
    }
    let params = |m: &ponq_model::PonqNet| {
        use burn::module::Module;
        let mut f = Flat(Vec::new());
        m.visit(&mut f);
        f.0
    };
    let run = |micro: usize| {
        let mut cfg = cfg.clone();
        cfg.train.micro_batches = micro;
        cfg.check().unwrap();
        let out = tmp(&format!("micro-{micro}"));
        let s =
            run_with_shapes(&cfg, &train, &val, &opts(out.clone(), false, dev.clone())).unwrap();
        let model = ponq_train::train::load_weights(&out.join("model.bpk"), &cfg, &dev).unwrap();
        let flat = params(&model);
        std::fs::remove_dir_all(&out).ok();
        (s, flat)
    };
    let (whole, m1) = run(1);
    let (split, m2) = run(2);
    assert_eq!(whole.step_losses.len(), 6);
    assert_eq!(whole.step_losses.len(), split.step_losses.len());
    for (i, (x, y)) in whole.step_losses.iter().zip(&split.step_losses).enumerate() {
        assert!((x - y).abs() <= 1e-4 * y.abs(), "step {i}: {x} vs {y}");
    }
    // The weights after six steps: the same within float rounding.
    let (a, b) = (m1, m2);
    assert_eq!(a.len(), b.len());
    let diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0f32, f32::max);
    assert!(diff < 1e-4, "weights differ by {diff}");
    // Invalid counts are config errors.
    let mut bad = cfg.clone();
    bad.train.micro_batches = 4;
    assert!(
        bad.check()
            .unwrap_err()
            .to_string()
            .contains("micro_batches")
    );
    std::fs::remove_dir_all(&init).ok();
}

/// A run whose data holds an id of its exclusion split stops before training, naming it.
#[test]
fn excluded_shapes_stop_the_run() {
    let mut cfg = smoke_config();
    cfg.train.epochs = 1;
    let (train, val) = shapes();
    let dir = tmp("exclude");
    std::fs::create_dir_all(&dir).unwrap();
    let run_opts = |out: &str| opts(dir.join(out), false, backend::cpu());
    // Shape "c" (training) and then "v" (validation) are excluded.
    for (list, id) in [("zz\nc\n", "c"), ("v\n", "v")] {
        std::fs::write(dir.join("never.txt"), list).unwrap();
        cfg.data.exclude = Some(dir.join("never.txt"));
        let err = run_with_shapes(&cfg, &train, &val, &run_opts("run"))
            .expect_err("an excluded shape stops the run")
            .to_string();
        assert!(err.contains(&format!("shape {id},")), "{err}");
        assert!(!dir.join("run/metrics.csv").exists(), "nothing was trained");
    }
    // Ids that are not in the data do not matter.
    std::fs::write(dir.join("never.txt"), "Advanced_GEB\nother\n").unwrap();
    let s = run_with_shapes(&cfg, &train, &val, &run_opts("ok")).expect("runs");
    assert_eq!(s.epochs_done, 1);
    // The shipped recipe excludes the 105 shared evaluation meshes.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let cpu = TrainConfig::load(&root.join("configs/cpu.toml")).unwrap();
    let ids = cpu.excluded_ids().unwrap();
    assert_eq!(ids.len(), 105);
    assert!(ids.contains("Advanced_GEB"));
    std::fs::remove_dir_all(&dir).ok();
}

/// Batches cut from extra resolutions: a run with `data.extra_resolutions` trains on the
/// extra grids of the shapes (and stops with a clear error naming a shape without one).
#[test]
fn extra_resolutions_are_trained_on() {
    let mut cfg = smoke_config();
    cfg.train.epochs = 3;
    cfg.data.extra_resolutions = vec![16];
    cfg.data.extra_weight = 1.0;
    let (train, val) = shapes();
    let dir = tmp("extra-res");
    std::fs::create_dir_all(&dir).unwrap();
    let opts = opts(dir.join("run"), false, backend::cpu());
    let err = run_with_shapes(&cfg, &train, &val, &opts)
        .expect_err("no shape has a 16^3 grid")
        .to_string();
    assert!(err.contains("has no grid at resolution 16"), "{err}");
    // Give every training shape its 16-cell grid: the run trains on it.
    let with_extra: Vec<_> = train
        .iter()
        .map(|s| {
            let fine = sphere_shape("x", 16, [0.0; 3], 0.5, 10);
            let mut s = s.clone();
            s.extra = vec![(16, fine.sdf)];
            s
        })
        .collect();
    let s = run_with_shapes(&cfg, &with_extra, &val, &opts).expect("trains");
    assert_eq!(s.epochs_done, 3);
    assert!(s.step_losses.iter().all(|l| l.is_finite()));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn init_from_a_narrower_network_widens_it() {
    let mut cfg = smoke_config();
    cfg.train.epochs = 1;
    let dev = backend::cpu();
    let dir = tmp("widen");
    std::fs::create_dir_all(&dir).unwrap();
    let init_file = dir.join("narrow.bpk");
    let narrow = cfg.model.net();
    let narrow_net = narrow.init(&dev);
    ponq_model::weights::save(&narrow_net, &narrow, &init_file).unwrap();
    cfg.train.init_from = Some(init_file.clone());
    cfg.model.width = narrow.width + 5;
    // The widened start computes what the saved network computes.
    let wide = ponq_train::train::init_weights(&init_file, &cfg, &dev, true).unwrap();
    assert_eq!(
        ponq_model::weights::load(&init_file, &dev).unwrap().1.width,
        narrow.width
    );
    let (train, val) = shapes();
    let x = ponq_train::data::Batcher {
        device: dev.clone(),
    }
    .batch(&[make_item(
        &train[0],
        &ItemOptions {
            crop: 0,
            samples: 100,
            augment: false,
        },
        &mut rand_chacha::ChaCha8Rng::seed_from_u64(1),
    )])
    .unwrap();
    let frame = ponq_train::data::item_frame(8);
    let a = narrow_net.forward(x.clone(), &frame).points;
    let b = wide.forward(x, &frame).points;
    let diff = (a.clone() - b).abs().max().into_scalar::<f32>();
    let scale = a.abs().max().into_scalar::<f32>();
    assert!(diff <= 1e-5 * scale, "{diff} vs {scale}");
    // A run starts from it and saves the wider network.
    let out = tmp("widen-run");
    run_with_shapes(&cfg, &train, &val, &opts(out.clone(), false, dev.clone())).unwrap();
    let (_, saved) = ponq_model::weights::load(&out.join("model.bpk"), &dev).unwrap();
    assert_eq!(saved.width, narrow.width + 5);
    // Anything but a wider width is refused, with the reason.
    cfg.model.width = narrow.width;
    cfg.model.points_per_cell = narrow.points_per_cell + 1;
    let e = ponq_train::train::init_weights(&init_file, &cfg, &dev, true).unwrap_err();
    assert!(format!("{e:#}").contains("only a wider network"), "{e:#}");
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_dir_all(&out).ok();
}
