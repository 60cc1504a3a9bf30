//! `ponq-infer DIR -o OUT`: every input of a folder into OUT/NAME.obj with one JSON record
//! each; `--shard I/N` splits the inputs so that the shards' union is the unsharded run, no
//! input twice; a bad input is an error record, not the end of the batch; a re-run skips
//! what is done.

use std::collections::BTreeMap;
use std::path::Path;

mod common;
use common::{repo, run as infer};

fn records(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn folders_shards_and_records() {
    let dir = std::env::temp_dir().join(format!("ponq-infer-batch-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let input = dir.join("in");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    std::fs::copy(repo("examples/csg_sdf_33.npy"), input.join("grid_a.npy")).unwrap();
    std::fs::copy(repo("examples/csg.obj"), input.join("sub/part_b.obj")).unwrap();
    std::fs::copy(repo("examples/example001.obj"), input.join("part_c.obj")).unwrap();
    std::fs::write(input.join("bad.obj"), "not a mesh\n").unwrap();
    let os = |p: &Path| p.as_os_str().to_owned();
    let whole = dir.join("whole");
    let (code, err) = infer(&[
        &os(&input),
        "-o".as_ref(),
        &os(&whole),
        "--res".as_ref(),
        "24".as_ref(),
        "-q".as_ref(),
    ]);
    assert_eq!(code, Some(2), "one input is bad: {err}");
    assert!(err.contains("1 input(s) failed"), "{err}");
    let log = records(&whole.join("log.jsonl"));
    assert_eq!(log.len(), 4);
    let bad: Vec<_> = log.iter().filter(|r| r["status"] == "error").collect();
    assert_eq!(bad.len(), 1);
    assert_eq!(bad[0]["name"], "bad");
    for r in log.iter().filter(|r| r["status"] == "done") {
        assert_eq!(r["valid"], true, "{r}");
        assert!(r["faces"].as_u64().unwrap() > 0);
        assert!(r["stages"]["network"].as_f64().is_some());
    }
    // The same mesh as one input at a time.
    let single = dir.join("single.obj");
    let (code, err) = infer(&[
        &os(&input.join("sub/part_b.obj")),
        "-o".as_ref(),
        &os(&single),
        "--res".as_ref(),
        "24".as_ref(),
        "-q".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(
        std::fs::read(&single).unwrap(),
        std::fs::read(whole.join("sub/part_b.obj")).unwrap()
    );
    // Three shards into one folder: the same outputs, each input in one shard's log.
    let sharded = dir.join("sharded");
    let mut names = Vec::new();
    for i in 0..3 {
        let shard = format!("{i}/3");
        infer(&[
            &os(&input),
            "-o".as_ref(),
            &os(&sharded),
            "--res".as_ref(),
            "24".as_ref(),
            "--shard".as_ref(),
            shard.as_ref(),
            "-q".as_ref(),
        ]);
        for r in records(&sharded.join(format!("log-shard-{i}-of-3.jsonl"))) {
            names.push(r["name"].as_str().unwrap().to_string());
        }
    }
    names.sort();
    assert_eq!(names, ["bad", "grid_a", "part_c", "sub/part_b"]);
    assert_eq!(outputs_below(&whole), outputs_below(&sharded));
    // A re-run redoes nothing that is done.
    infer(&[
        &os(&input),
        "-o".as_ref(),
        &os(&whole),
        "--res".as_ref(),
        "24".as_ref(),
        "-q".as_ref(),
    ]);
    let log = records(&whole.join("log.jsonl"));
    let rerun = &log[4..];
    assert_eq!(rerun.iter().filter(|r| r["status"] == "already").count(), 3);
    // A list file: paths relative to it, comments skipped.
    let list = input.join("list.txt");
    std::fs::write(&list, "# two of them\ngrid_a.npy\nsub/part_b.obj\n").unwrap();
    let listed = dir.join("listed");
    let (code, err) = infer(&[
        &os(&list),
        "-o".as_ref(),
        &os(&listed),
        "--res".as_ref(),
        "24".as_ref(),
        "-q".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let got = outputs_below(&listed);
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        ["grid_a.obj", "sub/part_b.obj"]
    );
    assert_eq!(
        got["sub/part_b.obj"],
        outputs_below(&whole)["sub/part_b.obj"]
    );
    // Flags of one input are refused with a folder.
    let (code, err) = infer(&[
        &os(&input),
        "-o".as_ref(),
        &os(&whole),
        "--json".as_ref(),
        "r.json".as_ref(),
    ]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--json"), "{err}");
    let (code, err) = infer(&[
        &os(&repo("examples/csg_sdf_33.npy")),
        "-o".as_ref(),
        &os(&dir.join("x.obj")),
        "--shard".as_ref(),
        "0/2".as_ref(),
    ]);
    assert_eq!(code, Some(2));
    assert!(err.contains("folder or list"), "{err}");
    // Two inputs that differ only by their extension would write one output: refused
    // before any work.
    let twins = dir.join("twins");
    std::fs::create_dir_all(twins.join("sub")).unwrap();
    std::fs::copy(repo("examples/csg.obj"), twins.join("sub/a.obj")).unwrap();
    std::fs::copy(repo("examples/csg_sdf_33.npy"), twins.join("sub/a.npy")).unwrap();
    let (code, err) = infer(&[&os(&twins), "-o".as_ref(), &os(&dir.join("twins-out"))]);
    assert_eq!(code, Some(2));
    assert!(err.contains("would both be written as \"sub/a\""), "{err}");
    assert!(!dir.join("twins-out").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// Every `.obj` under `d`, by its path below `d`.
fn outputs_below(d: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![d.to_path_buf()];
    while let Some(x) = stack.pop() {
        for e in std::fs::read_dir(&x).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|e| e == "obj") {
                let rel = p.strip_prefix(d).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// A dataset laid out as ShapeNet (`a/model.*`, `b/model.*`, `c/model.*`): three outputs
/// (`OUT/a/model.obj`, ...), the same under `--shard`; a cut output is redone on resume; a
/// folder whose every input fails exits 2.
#[test]
fn shapenet_layout_shards_and_resume() {
    let dir = common::tmp("shapenet");
    let input = dir.join("in");
    for (folder, src) in [
        ("a", "examples/csg_sdf_33.npy"),
        ("b", "examples/csg.obj"),
        ("c", "examples/example001.obj"),
    ] {
        std::fs::create_dir_all(input.join(folder)).unwrap();
        let ext = Path::new(src).extension().unwrap().to_str().unwrap();
        std::fs::copy(repo(src), input.join(folder).join(format!("model.{ext}"))).unwrap();
    }
    let os = |p: &Path| p.as_os_str().to_owned();
    let args = |out: &Path| -> Vec<std::ffi::OsString> {
        vec![
            os(&input),
            "-o".into(),
            os(out),
            "--res".into(),
            "24".into(),
            "-q".into(),
        ]
    };
    let whole = dir.join("whole");
    let a: Vec<std::ffi::OsString> = args(&whole);
    let (code, err) = infer(&a.iter().map(|x| x.as_os_str()).collect::<Vec<_>>());
    assert_eq!(code, Some(0), "{err}");
    let got = outputs_below(&whole);
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        ["a/model.obj", "b/model.obj", "c/model.obj"]
    );
    let v: Vec<&Vec<u8>> = got.values().collect();
    assert!(v[0] != v[1] && v[1] != v[2] && v[0] != v[2]);
    let sharded = dir.join("sharded");
    let mut names = Vec::new();
    for i in 0..3 {
        let mut a = args(&sharded);
        a.push("--shard".into());
        a.push(format!("{i}/3").into());
        let (code, err) = infer(&a.iter().map(|x| x.as_os_str()).collect::<Vec<_>>());
        assert_eq!(code, Some(0), "{err}");
        for r in records(&sharded.join(format!("log-shard-{i}-of-3.jsonl"))) {
            assert_eq!(r["shards"], 3);
            names.push(r["name"].as_str().unwrap().to_string());
        }
    }
    names.sort();
    assert_eq!(names, ["a/model", "b/model", "c/model"]);
    assert_eq!(outputs_below(&sharded), got);
    // A mesh cut in the middle (a machine that crashed while writing): redone on resume.
    let cut = whole.join("c/model.obj");
    let bytes = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let (code, err) = infer(&a.iter().map(|x| x.as_os_str()).collect::<Vec<_>>());
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(outputs_below(&whole), got);
    let log = records(&whole.join("log.jsonl"));
    let rerun = &log[3..];
    assert_eq!(rerun.iter().filter(|r| r["status"] == "already").count(), 2);
    let redone: Vec<_> = rerun.iter().filter(|r| r["status"] == "done").collect();
    assert_eq!(redone.len(), 1);
    assert_eq!(redone[0]["name"], "c/model");
    // Every input fails: exit 2, and the summary says so.
    let list = dir.join("missing.txt");
    std::fs::write(&list, "x.npy\ny.obj\n").unwrap();
    let (code, err) = infer(&[
        &os(&list),
        "-o".as_ref(),
        &os(&dir.join("none")),
        "--res".as_ref(),
        "24".as_ref(),
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("0 meshes written"), "{err}");
    assert!(err.contains("2 input(s) failed"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
