//! The dataset format round-trips exactly and rejects bad files with clear errors.

use ponq_data::dataset::{ShapeRecord, read_split, select};

fn record() -> ShapeRecord {
    let mut r = ShapeRecord::default();
    for i in 0..100 {
        let t = i as f32 * 0.1;
        r.samples.push([t.sin(), t.cos(), 0.5 * t - 2.5]);
        r.normals.push([t.cos(), -t.sin(), 0.0]);
    }
    for res in [4usize, 8] {
        r.sdf.insert(
            res,
            (0..(res + 1).pow(3))
                .map(|k| k as f32 * 0.01 - 1.0)
                .collect(),
        );
        r.occupancy
            .insert(res, (0..res.pow(3)).map(|k| k % 3 == 0).collect());
    }
    r
}

#[test]
fn roundtrip_is_exact() {
    let dir = std::env::temp_dir().join(format!("ponq-ds-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("shape_1.npz");
    let r = record();
    r.write(&p).unwrap();
    assert!(!dir.join("shape_1.npz.tmp").exists());
    assert_eq!(ShapeRecord::read(&p).unwrap(), r);
    // Splits select files and report missing ids.
    let split = dir.join("split.txt");
    std::fs::write(&split, "shape_1\n# comment\n\nshape_2\n").unwrap();
    let ids = read_split(&split).unwrap();
    assert_eq!(ids, vec!["shape_1".to_string(), "shape_2".to_string()]);
    let (found, missing) = select(&dir, &ids);
    assert_eq!(found, vec![p.clone()]);
    assert_eq!(missing, vec!["shape_2".to_string()]);
    // Bad files are errors, not panics.
    std::fs::write(dir.join("bad.npz"), b"garbage").unwrap();
    assert!(ShapeRecord::read(dir.join("bad.npz")).is_err());
    assert!(ShapeRecord::read(dir.join("none.npz")).is_err());
    let mut wrong = r.clone();
    wrong.sdf.insert(5, vec![0.0; 10]);
    assert!(wrong.write(dir.join("wrong.npz")).is_err());
    std::fs::remove_dir_all(&dir).ok();
}
