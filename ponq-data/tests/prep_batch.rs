//! The batch driver of `ponq-prep`: prepares shapes, skips bad ones with a reason, resumes.

use ponq_data::dataset::ShapeRecord;
use ponq_data::prep::{PrepOptions, SynthJob, mesh_inputs, mesh_jobs, run_batch};
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
    let jobs = mesh_jobs(files, &input).unwrap();
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

/// `ponq-prep meshes --shard I/N`: the union of the shards' outputs is the unsharded run's,
/// byte for byte, with no shape twice; each shard logs one JSON line per shape (the broken
/// file an error record), and a re-run logs every shape as already there.
#[test]
fn shards_cover_the_dataset_once_with_records() {
    use std::collections::BTreeMap;
    let dir = std::env::temp_dir().join(format!("ponq-shard-{}", std::process::id()));
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let part = std::fs::read_to_string(examples.join("example001.obj")).unwrap();
    for i in 0..7 {
        // Seven small copies (names spread over the shards).
        std::fs::write(input.join(format!("part_{i}.obj")), &part).unwrap();
    }
    std::fs::write(input.join("broken.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let prep = |out: &std::path::Path, shard: Option<&str>| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_ponq-prep"));
        c.args(["meshes", "-q", "--res", "8", "--samples", "2000", "-o"])
            .arg(out)
            .arg(&input);
        if let Some(s) = shard {
            c.args(["--shard", s]);
        }
        let o = c.output().unwrap();
        // A run that holds the broken file exits 2 (the others are written), others 0.
        let has_broken = shard.is_none_or(|s| {
            s.parse::<ponq_data::records::Shard>()
                .unwrap()
                .contains("broken")
        });
        assert_eq!(
            o.status.code(),
            Some(if has_broken { 2 } else { 0 }),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    let files = |d: &std::path::Path| -> BTreeMap<String, Vec<u8>> {
        std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "npz"))
            .map(|p| {
                (
                    p.file_name().unwrap().to_string_lossy().into_owned(),
                    std::fs::read(&p).unwrap(),
                )
            })
            .collect()
    };
    let whole = dir.join("whole");
    prep(&whole, None);
    let sharded = dir.join("sharded");
    let mut seen = 0;
    let mut lines = Vec::new();
    for i in 0..3 {
        prep(&sharded, Some(&format!("{i}/3")));
        let log =
            std::fs::read_to_string(sharded.join(format!("log-shard-{i}-of-3.jsonl"))).unwrap();
        for l in log.lines() {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            lines.push(v);
        }
        seen += log.lines().count();
    }
    // 8 inputs, each in exactly one shard's log.
    assert_eq!(seen, 8);
    let mut names: Vec<String> = lines
        .iter()
        .map(|v| v["name"].as_str().unwrap().to_string())
        .collect();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), 8);
    let errors: Vec<&serde_json::Value> = lines.iter().filter(|v| v["status"] == "error").collect();
    assert_eq!(errors.len(), 1);
    assert_eq!(errors[0]["name"], "broken");
    assert!(!errors[0]["error"].as_str().unwrap().is_empty());
    assert!(
        lines
            .iter()
            .filter(|v| v["status"] == "done")
            .all(|v| v["stages"]["sdf 8"].as_f64().is_some() && v["seconds"].as_f64() > Some(0.0))
    );
    assert_eq!(files(&whole), files(&sharded));
    // Re-running a shard redoes nothing and says so.
    prep(&sharded, Some("1/3"));
    let log = std::fs::read_to_string(sharded.join("log-shard-1-of-3.jsonl")).unwrap();
    let n = log.lines().count();
    let rerun: Vec<serde_json::Value> = log
        .lines()
        .skip(n / 2)
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(
        rerun
            .iter()
            .all(|v| v["status"] == "already" || v["status"] == "error")
    );
    std::fs::remove_dir_all(&dir).ok();
}
