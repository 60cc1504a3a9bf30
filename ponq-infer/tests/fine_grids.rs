//! Fine grids: inference reads a grid stored near its surface only (`ponq_mesh::band`), so its
//! cost follows the surface. These tests run the same code paths on small grids and check
//! that nothing is read outside the band: the band gives the same mesh, bit for bit, as the
//! whole grid stored (what inference did before), for a grid file read plane by plane and for
//! a mesh whose distances are computed near its surface only.

use ponq_infer::mesh_input::{MeshInput, mesh_band, mesh_grid};
use ponq_infer::{InferOptions, band_parameters, finish, predict, predict_band, shipped};
use ponq_mesh::band::BandGrid;
use ponq_mesh::{TriMesh, io, validity};

mod common;
use common::repo;

fn same_mesh(a: &TriMesh, b: &TriMesh) -> bool {
    a.faces == b.faces
        && a.vertices.len() == b.vertices.len()
        && a.vertices
            .iter()
            .zip(&b.vertices)
            .all(|(p, q)| (0..3).all(|k| p[k].to_bits() == q[k].to_bits()))
}

/// The shipped example grids: read plane by plane into the band, the band of the dense
/// grid, and the whole grid stored give one mesh.
#[test]
fn band_reading_gives_the_whole_grids_mesh() {
    let dev = ponq_model::backend::cpu();
    let (net, cfg) = shipped::load(&dev).unwrap();
    let opts = InferOptions::default();
    for name in ["examples/csg_sdf_33.npy", "examples/example001_sdf_65.npy"] {
        let path = repo(name);
        let dense = io::npy::read_npy_grid(&path).unwrap();
        let n = dense.dims[0] - 1;
        let (t, reach) = band_parameters(n, cfg.encoder_layers, &opts);
        let frame = ponq_infer::Frame::of(&dense, opts.bounds).unwrap();
        let whole =
            BandGrid::from_dense(dense.dims, &dense.data, frame.scale(), f64::INFINITY, reach)
                .unwrap();
        let streamed =
            io::npy::read_npy_band(&path, |_| Ok((frame.scale(), t, reach, None)), |_, _| {})
                .unwrap();
        assert!(
            streamed.stored_bricks() < whole.stored_bricks(),
            "{name}: the band stores {} of {} bricks",
            streamed.stored_bricks(),
            whole.stored_bricks()
        );
        let run = |g: BandGrid| {
            let p = predict_band(&net, cfg.encoder_layers, g, &opts, &dev, |_, _| {}).unwrap();
            finish(&p, &opts).unwrap()
        };
        let a = run(whole);
        let b = run(streamed);
        let c = finish(
            &predict(&net, cfg.encoder_layers, &dense, &opts, &dev, |_, _| {}).unwrap(),
            &opts,
        )
        .unwrap();
        assert!(a.refinement.ran, "{name}: the refinement should run");
        assert!(validity::check(&a.mesh).is_valid());
        assert!(same_mesh(&a.mesh, &b.mesh), "{name}: streamed band differs");
        assert!(same_mesh(&a.mesh, &c.mesh), "{name}: dense input differs");
    }
}

/// A mesh's distances computed near its surface only equal the dense grid's wherever the
/// dense grid's band stores them, for a closed part (signed by components) and an open
/// surface (signed node by node), and inference on them gives the same mesh.
#[test]
fn mesh_band_matches_the_dense_grid() {
    let dev = ponq_model::backend::cpu();
    let (net, cfg) = shipped::load(&dev).unwrap();
    let opts = InferOptions::default();
    let mut open_box = io::read_mesh(repo("examples/example001.obj")).unwrap();
    // An open copy: drop a tenth of the faces.
    open_box.faces.retain({
        let mut i = 0;
        move |_| {
            i += 1;
            i % 10 != 0
        }
    });
    let cases = [
        (
            io::read_mesh(repo("examples/example001.obj")).unwrap(),
            40,
            MeshInput::default(),
        ),
        (
            io::read_mesh(repo("examples/csg.obj")).unwrap(),
            33,
            MeshInput::default(),
        ),
        (
            open_box,
            24,
            MeshInput {
                open_surface: true,
                repair: false,
            },
        ),
    ];
    for (i, (mesh, res, input)) in cases.into_iter().enumerate() {
        let dense = mesh_grid(&mesh, res, input, |_| {}).unwrap();
        let band = mesh_band(&mesh, res, input, cfg.encoder_layers, &opts, |_, _| {}).unwrap();
        assert_eq!(dense.open, band.open, "case {i}");
        let frame = ponq_infer::Frame::of(&dense.grid, opts.bounds).unwrap();
        let (t, reach) = band_parameters(res, cfg.encoder_layers, &opts);
        let from_dense =
            BandGrid::from_dense(dense.grid.dims, &dense.grid.data, frame.scale(), t, reach)
                .unwrap();
        let d = band.grid.dims();
        let mut checked = 0;
        for x in 0..d[0] {
            for y in 0..d[1] {
                for z in 0..d[2] {
                    if from_dense.is_stored(x, y, z) {
                        assert!(band.grid.is_stored(x, y, z), "case {i}: ({x},{y},{z})");
                        assert_eq!(
                            band.grid.get(x, y, z).to_bits(),
                            from_dense.get(x, y, z).to_bits(),
                            "case {i}: ({x},{y},{z})"
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 0);
        if !input.open_surface {
            let a = finish(
                &predict_band(&net, cfg.encoder_layers, band.grid, &opts, &dev, |_, _| {}).unwrap(),
                &opts,
            )
            .unwrap();
            let b = finish(
                &predict(
                    &net,
                    cfg.encoder_layers,
                    &dense.grid,
                    &opts,
                    &dev,
                    |_, _| {},
                )
                .unwrap(),
                &opts,
            )
            .unwrap();
            assert!(validity::check(&a.mesh).is_valid());
            assert!(same_mesh(&a.mesh, &b.mesh), "case {i}: meshes differ");
        }
    }
}

/// A grid too narrow for what inference reads is refused with a clear error, not read
/// outside its band.
#[test]
fn a_narrow_band_is_refused() {
    let dev = ponq_model::backend::cpu();
    let (net, cfg) = shipped::load(&dev).unwrap();
    let opts = InferOptions::default();
    let dense = io::npy::read_npy_grid(repo("examples/csg_sdf_33.npy")).unwrap();
    let (t, reach) = band_parameters(32, cfg.encoder_layers, &opts);
    let narrow = BandGrid::from_dense(dense.dims, &dense.data, 1.0, t / 2.0, reach).unwrap();
    let e = predict_band(&net, cfg.encoder_layers, narrow, &opts, &dev, |_, _| {}).unwrap_err();
    assert!(e.to_string().contains("narrower"), "{e}");
}

/// Too little memory is a clear error before the work (exit 2, no output), at the reading
/// (the band itself) or before the network (the cells near the surface).
#[test]
fn too_little_memory_is_a_clear_error() {
    let out = std::env::temp_dir().join(format!("ponq-fine-mem-{}.obj", std::process::id()));
    for (limit, says) in [
        ("64K", "values near the surface"),
        ("8M", "not enough memory"),
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_ponq-infer"))
            .arg(repo("examples/example001_sdf_65.npy"))
            .arg("-o")
            .arg(&out)
            .env("PONQ_MEMORY_LIMIT", limit)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains(says), "{limit}: {err}");
        assert!(!out.exists());
    }
}

/// The memory a container (or Slurm job, or Ray worker) may take is its control group's
/// limit, not the machine's: a group with little room left is a clear error before the work
/// (a fake group's files through `PONQ_CGROUP_DIR`); one without a limit lets the run
/// through. A `PONQ_MEMORY_LIMIT` that is not a size is an error, not "no limit".
#[test]
fn container_limits_hold_and_bad_limits_are_errors() {
    let dir = std::env::temp_dir().join(format!("ponq-fine-cgroup-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out.obj");
    let run = |env: &[(&str, &std::ffi::OsStr)]| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_ponq-infer"));
        c.arg(repo("examples/example001_sdf_65.npy"))
            .arg("-o")
            .arg(&out)
            .env_remove("PONQ_MEMORY_LIMIT");
        for (k, v) in env {
            c.env(k, v);
        }
        let o = c.output().unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    // 12 MB left in the group (v2 files): the band fits in half of it, the cells near the
    // surface (about 30 MB for this grid) do not.
    std::fs::write(dir.join("memory.max"), "1012000000\n").unwrap();
    std::fs::write(dir.join("memory.current"), "1000000000\n").unwrap();
    let (code, err) = run(&[("PONQ_CGROUP_DIR", dir.as_os_str())]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("not enough memory"), "{err}");
    assert!(err.contains("cgroup"), "{err}");
    assert!(!out.exists());
    // The same group without a limit.
    std::fs::write(dir.join("memory.max"), "max\n").unwrap();
    let (code, err) = run(&[("PONQ_CGROUP_DIR", dir.as_os_str())]);
    assert_eq!(code, Some(0), "{err}");
    std::fs::remove_file(&out).unwrap();
    // Units people write parse; anything else is an error before the work.
    let (code, err) = run(&[("PONQ_MEMORY_LIMIT", "64GiB".as_ref())]);
    assert_eq!(code, Some(0), "{err}");
    std::fs::remove_file(&out).unwrap();
    let (code, err) = run(&[("PONQ_MEMORY_LIMIT", "8 GHz".as_ref())]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("PONQ_MEMORY_LIMIT=\"8 GHz\" is not a size"),
        "{err}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).ok();
}
