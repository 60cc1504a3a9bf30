//! `ponq-prep meshes` never loses or misreports a shape: a dataset laid out as ShapeNet
//! (`a/model.obj`, `b/model.obj`, ...) gives one output per mesh, sharded or not; the exit
//! code says when a shape failed; a cut output is redone on resume and the temporary files of
//! crashed runs are removed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ponq-names-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `examples/example001.obj` with its x and y swapped: another shape, another record.
fn swapped_example() -> String {
    std::fs::read_to_string(repo("examples/example001.obj"))
        .unwrap()
        .lines()
        .map(|l| {
            let t: Vec<&str> = l.split_whitespace().collect();
            if t.first() == Some(&"v") && t.len() >= 4 {
                format!("v {} {} {}\n", t[2], t[1], t[3])
            } else {
                format!("{l}\n")
            }
        })
        .collect()
}

/// Three meshes, each `model.obj` in its own folder.
fn shapenet(dir: &Path) -> PathBuf {
    let input = dir.join("in");
    for (folder, text) in [
        (
            "a",
            std::fs::read_to_string(repo("examples/csg.obj")).unwrap(),
        ),
        (
            "b",
            std::fs::read_to_string(repo("examples/example001.obj")).unwrap(),
        ),
        ("c", swapped_example()),
    ] {
        std::fs::create_dir_all(input.join(folder)).unwrap();
        std::fs::write(input.join(folder).join("model.obj"), text).unwrap();
    }
    input
}

/// Runs `ponq-prep meshes INPUT -o OUT` with small grids; (exit code, stdout + stderr).
fn prep(input: &Path, out: &Path, extra: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_ponq-prep"))
        .args(["meshes", "--res", "8", "--samples", "2000", "-o"])
        .arg(out)
        .arg(input)
        .args(extra)
        .output()
        .unwrap();
    (
        o.status.code(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        ),
    )
}

/// Every `.npz` under `d`, by its path below `d`.
fn records(d: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![d.to_path_buf()];
    while let Some(x) = stack.pop() {
        for e in std::fs::read_dir(&x).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|e| e == "npz") {
                let rel = p.strip_prefix(d).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

fn log_lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn shapenet_layout_gives_every_shape_its_output_sharded_or_not() {
    let dir = tmp("shapenet");
    let input = shapenet(&dir);
    let whole = dir.join("whole");
    let (code, text) = prep(&input, &whole, &[]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("3 shapes written"), "{text}");
    let got = records(&whole);
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        ["a/model.npz", "b/model.npz", "c/model.npz"]
    );
    // Three shapes, three different records (none written over another).
    let v: Vec<&Vec<u8>> = got.values().collect();
    assert!(v[0] != v[1] && v[1] != v[2] && v[0] != v[2]);
    let log = log_lines(&whole.join("log.jsonl"));
    let mut names: Vec<&str> = log.iter().map(|r| r["name"].as_str().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["a/model", "b/model", "c/model"]);
    for r in &log {
        assert_eq!(r["status"], "done");
        assert_eq!(r["shards"], 1);
        assert!(r["time"].as_str().unwrap().ends_with('Z'));
    }
    // Three shards into one folder: the same files, byte for byte, each shape in one log.
    let sharded = dir.join("sharded");
    let mut seen = Vec::new();
    for i in 0..3 {
        let (code, text) = prep(&input, &sharded, &["--shard", &format!("{i}/3"), "-q"]);
        assert_eq!(code, Some(0), "{text}");
        for r in log_lines(&sharded.join(format!("log-shard-{i}-of-3.jsonl"))) {
            assert_eq!(r["shards"], 3);
            seen.push(r["name"].as_str().unwrap().to_string());
        }
    }
    seen.sort();
    assert_eq!(seen, ["a/model", "b/model", "c/model"]);
    assert_eq!(records(&sharded), got);
    // A re-run finds every output whole and redoes nothing.
    let (code, text) = prep(&input, &whole, &[]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("3 already there"), "{text}");
    // Two files that differ only by their extension would share an output: refused before
    // any work.
    let twins = dir.join("twins");
    std::fs::create_dir_all(twins.join("x")).unwrap();
    std::fs::copy(repo("examples/csg.obj"), twins.join("x/model.obj")).unwrap();
    std::fs::copy(repo("examples/csg.obj"), twins.join("x/model.stl")).unwrap();
    let out = dir.join("twins-out");
    let (code, text) = prep(&twins, &out, &[]);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains("would both be written as \"x/model\""),
        "{text}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn exit_codes_say_when_shapes_failed() {
    let dir = tmp("exit");
    // Six paths that do not exist: every shape fails.
    let list = dir.join("list.txt");
    std::fs::write(
        &list,
        (0..6)
            .map(|i| format!("missing_{i}.obj\n"))
            .collect::<String>(),
    )
    .unwrap();
    let (code, text) = prep(&list, &dir.join("none"), &[]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("0 shapes written"), "{text}");
    assert!(text.contains("6 of 6 shapes failed"), "{text}");
    assert!(text.contains("log.jsonl"), "{text}");
    // One of two fails: the other is written, and the exit code still says so.
    let input = dir.join("in");
    std::fs::create_dir_all(&input).unwrap();
    std::fs::copy(repo("examples/example001.obj"), input.join("good.obj")).unwrap();
    std::fs::write(input.join("bad.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let out = dir.join("some");
    let (code, text) = prep(&input, &out, &[]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("1 of 2 shapes failed"), "{text}");
    assert!(text.contains("failed bad"), "{text}");
    assert!(out.join("good.npz").is_file());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_cut_output_is_redone_and_stale_partials_removed() {
    let dir = tmp("resume");
    let input = shapenet(&dir);
    let out = dir.join("out");
    let (code, text) = prep(&input, &out, &["-q"]);
    assert_eq!(code, Some(0), "{text}");
    let before = records(&out);
    // A machine that crashed mid-write under older rules: a record cut in half, and a
    // temporary file of a process that no longer runs.
    let cut = out.join("b/model.npz");
    let bytes = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| {
            h.trim()
                .chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
                .collect::<String>()
        })
        .unwrap_or_else(|_| "host".into());
    let stale = out.join(format!("c/.model.partial-{host}-4294967290.npz"));
    std::fs::write(&stale, b"half a record").unwrap();
    let (code, text) = prep(&input, &out, &[]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("1 shapes written, 2 already there"), "{text}");
    assert!(text.contains("removed 1 temporary file"), "{text}");
    assert!(!stale.exists());
    assert_eq!(
        records(&out),
        before,
        "the redone record equals the first one"
    );
    let log = log_lines(&out.join("log.jsonl"));
    let redone: Vec<_> = log[3..].iter().filter(|r| r["status"] == "done").collect();
    assert_eq!(redone.len(), 1);
    assert_eq!(redone[0]["name"], "b/model");
    assert!(
        redone[0]["warning"].as_str().unwrap().contains("cut"),
        "{}",
        redone[0]
    );
    std::fs::remove_dir_all(&dir).ok();
}
