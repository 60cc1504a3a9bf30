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

/// `--band`: the distances within the band equal the dense grid's, the rest is the dense
/// grid truncated to the band's width with the same sign, for a closed part (sign by
/// components) and the same part without repair.
#[test]
fn band_writes_a_truncated_grid_equal_to_the_dense_one_near_the_surface() {
    for (res, cells) in [(48usize, 3.0f64), (64, 10.0)] {
        let dense = tmp(&format!("dense{res}.npy"));
        let band = tmp(&format!("band{res}.npy"));
        for (out, extra) in [(&dense, None), (&band, Some(cells.to_string()))] {
            let mut c = prep();
            c.args(["sdf", "-q", "--res", &res.to_string(), "-o"])
                .arg(out);
            if let Some(w) = &extra {
                c.args(["--band", w]);
            }
            assert!(c.arg(example("example001.obj")).status().unwrap().success());
        }
        let d = io::npy::read_npy_grid(&dense).unwrap();
        let b = io::npy::read_npy_grid(&band).unwrap();
        let t = cells * 2.0 / res as f64;
        let mut near = 0;
        for (x, y) in d.data.iter().zip(&b.data) {
            if x.abs() < t * 0.999 {
                assert_eq!(x, y);
                near += 1;
            } else {
                assert_eq!(*y, (x.clamp(-t, t) as f32) as f64, "{x} -> {y}");
            }
        }
        assert!(
            near > 0 && near < d.data.len() / 2,
            "{near} of {}",
            d.data.len()
        );
    }
    let e = prep()
        .args(["sdf", "-q", "--band", "0.5", "-o"])
        .arg(tmp("bad.npy"))
        .arg(example("example001.obj"))
        .output()
        .unwrap();
    assert_eq!(e.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&e.stderr).contains("--band"));
}
