//! The batch driver of `ponq-prep`: prepares shapes, skips bad ones with a reason, resumes.

use ponq_data::dataset::ShapeRecord;
use ponq_data::prep::{MeshJob, PrepOptions, SynthJob, mesh_inputs, run_batch};
use ponq_data::synth::SynthOptions;

#[test]
fn batch_prepares_skips_and_resumes() {
    let dir = std::env::temp_dir().join(format!("ponq-prep-{}", std::process::id()));
    let input = dir.join("in");
    let out = dir.join("out");
    std::fs::create_dir_all(&input).unwrap();
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    std::fs::copy(examples.join("example001.obj"), input.join("part.obj")).unwrap();
    std::fs::write(input.join("broken.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let files = mesh_inputs(&input).unwrap();
    assert_eq!(files.len(), 2);
    let jobs: Vec<MeshJob> = files.into_iter().map(MeshJob).collect();
    let opts = PrepOptions {
        resolutions: vec![8, 16],
        samples: 5000,
        seed: 1,
        ..Default::default()
    };
    let s = run_batch(&jobs, &out, &opts, || {}).unwrap();
    assert_eq!(s.done, vec!["part".to_string()]);
    assert_eq!(s.skipped.len(), 1);
    assert_eq!(s.skipped[0].0, "broken");
    assert!(!s.skipped[0].1.is_empty());
    let r = ShapeRecord::read(out.join("part.npz")).unwrap();
    assert_eq!(r.samples.len(), 5000);
    assert_eq!(r.sdf[&16].len(), 17 * 17 * 17);
    // The part is a solid around its centre region: some nodes inside, the corners outside.
    assert!(r.sdf[&16].iter().any(|&d| d < 0.0));
    assert!(r.sdf[&16][0] > 0.0);
    assert!(r.occupancy[&8].iter().any(|&o| o));
    // A second run resumes: nothing is redone.
    let s2 = run_batch(&jobs, &out, &opts, || {}).unwrap();
    assert!(s2.done.is_empty());
    assert_eq!(s2.already, vec!["part".to_string()]);
    // Procedural shapes go through the same driver with their analytic samples.
    let synth = vec![SynthJob {
        seed: 3,
        synth: SynthOptions {
            mesh_resolution: 32,
            ..Default::default()
        },
    }];
    let s3 = run_batch(&synth, &out, &opts, || {}).unwrap();
    assert_eq!(
        s3.done,
        vec!["synth_00000003".to_string()],
        "{:?}",
        s3.skipped
    );
    std::fs::remove_dir_all(&dir).ok();
}
