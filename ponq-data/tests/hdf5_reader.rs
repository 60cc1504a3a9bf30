//! The reader of the authors' HDF5 files, on a small file the test writes.

use hdf5_pure::FileBuilder;
use ponq_data::hdf5::read_authors_h5;

#[test]
fn reads_and_rescales_an_authors_file() {
    let dir = std::env::temp_dir().join(format!("ponq-h5-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let n = 50usize;
    let pc: Vec<f32> = (0..3 * n)
        .map(|i| ((i * 37) % 101) as f32 / 101.0 - 0.5)
        .collect();
    let nr: Vec<f32> = (0..3 * n)
        .map(|i| if i % 3 == 2 { 1.0 } else { 0.0 })
        .collect();
    let sdf: Vec<f32> = (0..17 * 17 * 17).map(|i| i as f32 * 1e-4 - 0.2).collect();
    let mut b = FileBuilder::new();
    b.create_dataset("pointcloud")
        .with_f32_data(&pc)
        .with_shape(&[n as u64, 3]);
    b.create_dataset("normals")
        .with_f32_data(&nr)
        .with_shape(&[n as u64, 3]);
    b.create_dataset("16_sdf")
        .with_f32_data(&sdf)
        .with_shape(&[17, 17, 17]);
    let path = dir.join("00000001.h5");
    std::fs::write(&path, b.finish().unwrap()).unwrap();

    let r = read_authors_h5(&path).unwrap();
    assert_eq!(r.samples.len(), n);
    for (i, p) in r.samples.iter().enumerate() {
        for k in 0..3 {
            assert_eq!(p[k], 2.0 * pc[3 * i + k], "positions are doubled exactly");
        }
    }
    assert_eq!(r.normals[0], [0.0, 0.0, 1.0]);
    let g = &r.sdf[&16];
    assert_eq!(g.len(), 17 * 17 * 17);
    assert!(g.iter().zip(&sdf).all(|(a, b)| *a == 2.0 * b));
    assert!(r.occupancy[&16].iter().filter(|&&o| o).count() > 0);

    // Missing datasets and non-HDF5 files are errors naming what is wrong.
    let mut b = FileBuilder::new();
    b.create_dataset("pointcloud")
        .with_f32_data(&pc)
        .with_shape(&[n as u64, 3]);
    let bad = dir.join("bad.h5");
    std::fs::write(&bad, b.finish().unwrap()).unwrap();
    let e = read_authors_h5(&bad).unwrap_err().to_string();
    assert!(e.contains("normals"), "{e}");
    std::fs::write(&bad, b"not hdf5").unwrap();
    assert!(read_authors_h5(&bad).is_err());
    std::fs::remove_dir_all(&dir).ok();
}
