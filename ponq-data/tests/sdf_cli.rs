//! `ponq-prep sdf` end to end: the written `.npy` grid equals the library's, and bad inputs
//! give clear errors with exit status 2.

use std::path::{Path, PathBuf};
use std::process::Command;

use ponq_data::normalize::Normalization;
use ponq_data::sdf::signed_distance_grid;
use ponq_mesh::io;

fn prep() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ponq-prep"))
}

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ponq-prep-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

#[test]
fn sdf_writes_the_normalised_grid() {
    let out = tmp("csg_sdf.npy");
    let st = prep()
        .args(["sdf", "-q", "--res", "12", "-o"])
        .arg(&out)
        .arg(example("csg.obj"))
        .status()
        .unwrap();
    assert!(st.success());
    let g = io::npy::read_npy_grid(&out).unwrap();
    assert_eq!(g.dims, [13, 13, 13]);
    let m = io::read_mesh(example("csg.obj")).unwrap();
    let m = Normalization::of(&m).unwrap().apply_mesh(&m);
    let want = signed_distance_grid(&m, 12, |_| {}).unwrap();
    assert_eq!(g, want.to_grid3());
    assert!(g.data.iter().any(|&v| v < 0.0));

    // --no-normalize keeps the coordinates (the part is ~70 units wide).
    let st = prep()
        .args(["sdf", "-q", "--res", "4", "--no-normalize", "-o"])
        .arg(&out)
        .arg(example("csg.obj"))
        .status()
        .unwrap();
    assert!(st.success());
    let g = io::npy::read_npy_grid(&out).unwrap();
    let raw = io::read_mesh(example("csg.obj")).unwrap();
    assert_eq!(g, signed_distance_grid(&raw, 4, |_| {}).unwrap().to_grid3());
    assert!(g.data.iter().any(|&v| v.abs() > 2.0));
    std::fs::remove_file(&out).unwrap();
}

#[test]
fn sdf_errors_are_clear() {
    let out = tmp("never.npy");
    let run = |args: &[&str], mesh: &Path| {
        let o = prep()
            .args(args)
            .arg("-o")
            .arg(&out)
            .arg(mesh)
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (code, err) = run(&["sdf", "--res", "1"], &example("csg.obj"));
    assert_eq!(code, Some(2));
    assert!(err.contains("--res must be in 2..=1024"), "{err}");
    let (code, err) = run(&["sdf", "--res", "2000"], &example("csg.obj"));
    assert_eq!(code, Some(2));
    assert!(err.contains("2000"), "{err}");
    let (code, err) = run(&["sdf"], Path::new("/no/such/mesh.obj"));
    assert_eq!(code, Some(2));
    assert!(err.contains("does not exist"), "{err}");
    let bad = tmp("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nf 1 2 3\n").unwrap();
    let (code, err) = run(&["sdf"], &bad);
    assert_eq!(code, Some(2));
    assert!(err.contains("bad.obj"), "{err}");
    assert!(!out.exists());
    std::fs::remove_file(&bad).unwrap();
}
