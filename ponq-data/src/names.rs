//! The output names of a batch's inputs: distinct by construction, the same in every batch
//! entry point (`ponq-prep meshes`, `ponq-infer DIR`, `ponq.prepare_meshes`, the Ray example)
//! and the key of the shard hash ([`crate::records::Shard`]).
//!
//! A name is the input's file stem. Where inputs share a stem (a dataset laid out as ShapeNet
//! and many others are: `a/model.obj`, `b/model.obj`), each of them is given its parent
//! folders, nearest first, until the names differ: `a/model` and `b/model` (the output is then
//! written into those sub-folders of the output folder). So a dataset whose stems are unique
//! keeps the names it always had, and no two inputs share an output. Two inputs that differ
//! only by their extension (`a.obj`, `a.ply` in one folder) cannot be told apart this way:
//! [`output_names`] refuses them, before any work.
//!
//! Invariant: the names of one call are distinct, non-empty, use `/` between folders, and hold
//! no `.` / `..` component.
//!
//! ```
//! use std::path::PathBuf;
//! use ponq_data::names::output_names;
//! let inputs: Vec<PathBuf> =
//!     ["data/a/model.obj", "data/b/model.obj", "data/c/chair.obj"].map(PathBuf::from).into();
//! assert_eq!(output_names(&inputs).unwrap(), ["a/model", "b/model", "chair"]);
//! ```

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

use crate::error::{DataError, Result};

/// The output name of every input ([module docs](self)), in the order of `inputs`.
///
/// # Errors
/// An input without a file name, one whose name is not UTF-8, or two inputs that map to one
/// name (the same path, or the same path but for the extension); the error names both files.
pub fn output_names(inputs: &[PathBuf]) -> Result<Vec<String>> {
    // Per input: its stem and parent folders below the inputs' common folder, nearest first.
    let normals: Vec<PathBuf> = inputs.iter().map(|p| lexical(p)).collect();
    let root = common_folder(&normals);
    let mut parts: Vec<Vec<String>> = Vec::with_capacity(inputs.len());
    for (p, normal) in inputs.iter().zip(&normals) {
        let normal = normal.strip_prefix(&root).unwrap_or(normal);
        let stem = normal
            .file_stem()
            .ok_or_else(|| DataError::Invalid(format!("{} has no file name", p.display())))?;
        let mut v = vec![utf8(stem, p)?];
        if let Some(parent) = normal.parent() {
            for c in parent.components().rev() {
                if let Component::Normal(s) = c {
                    v.push(utf8(s, p)?);
                }
            }
        }
        parts.push(v);
    }
    // Inputs that share a stem all take the fewest parent folders that tell them apart (the
    // same number for all of them: one layout per group, e.g. `synset/id/model`).
    let mut by_stem: HashMap<&str, Vec<usize>> = HashMap::new();
    for (i, p) in parts.iter().enumerate() {
        by_stem.entry(p[0].as_str()).or_default().push(i);
    }
    let mut names: Vec<String> = parts.iter().map(|p| p[0].clone()).collect();
    for members in by_stem.values().filter(|g| g.len() > 1) {
        let deepest = members.iter().map(|&i| parts[i].len()).max().unwrap_or(1);
        let mut depth = 2;
        loop {
            let group: Vec<String> = members.iter().map(|&i| join(&parts[i], depth)).collect();
            let mut sorted: Vec<&String> = group.iter().collect();
            sorted.sort_unstable();
            let twin = sorted
                .windows(2)
                .find(|w| w[0] == w[1])
                .map(|w| w[0].clone());
            match twin {
                None => {
                    for (&i, n) in members.iter().zip(group) {
                        names[i] = n;
                    }
                    break;
                }
                Some(name) if depth >= deepest => {
                    let same: Vec<&PathBuf> = members
                        .iter()
                        .filter(|&&i| join(&parts[i], depth) == name)
                        .map(|&i| &inputs[i])
                        .collect();
                    return Err(DataError::Invalid(format!(
                        "{} and {} would both be written as {name:?} (they differ only by \
                         their extension, or are one file twice); rename or drop one",
                        same[0].display(),
                        same[1].display(),
                    )));
                }
                Some(_) => depth += 1,
            }
        }
    }
    Ok(names)
}

/// The output file of `name` in `out` with extension `ext` (`out/a/model.npz`).
pub fn output_path(out: &Path, name: &str, ext: &str) -> PathBuf {
    out.join(format!("{name}.{ext}"))
}

/// The first `depth` components, outermost first, joined by `/`.
fn join(parts: &[String], depth: usize) -> String {
    let mut v: Vec<&str> = parts[..depth.min(parts.len())]
        .iter()
        .map(String::as_str)
        .collect();
    v.reverse();
    v.join("/")
}

fn utf8(s: &std::ffi::OsStr, p: &Path) -> Result<String> {
    s.to_str().map(str::to_string).ok_or_else(|| {
        DataError::Invalid(format!(
            "{} has a name that is not UTF-8: outputs and logs need one",
            p.display()
        ))
    })
}

/// The deepest folder that holds every path (empty when there is none).
fn common_folder(paths: &[PathBuf]) -> PathBuf {
    let mut root: Option<Vec<Component<'_>>> = None;
    for p in paths {
        let folders: Vec<Component<'_>> =
            p.parent().map_or(Vec::new(), |d| d.components().collect());
        root = Some(match root {
            None => folders,
            Some(r) => r
                .into_iter()
                .zip(folders)
                .take_while(|(a, b)| a == b)
                .map(|(a, _)| a)
                .collect(),
        });
    }
    root.unwrap_or_default().iter().collect()
}

/// `p` with `.` dropped and each `..` taking out the folder before it (no file system access:
/// the folders need not exist, links are not followed).
fn lexical(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Result<Vec<String>> {
        output_names(&v.iter().map(PathBuf::from).collect::<Vec<_>>())
    }

    #[test]
    fn unique_stems_keep_their_names() {
        assert_eq!(
            names(&["d/cad/x.obj", "d/free/y.ply", "z.stl"]).unwrap(),
            ["x", "y", "z"]
        );
    }

    #[test]
    fn shared_stems_take_their_folders_until_distinct() {
        // ShapeNet: synset/id/model.obj, ids repeated across synsets.
        let got = names(&[
            "s/c0/a/model.obj",
            "s/c0/b/model.obj",
            "s/c1/a/model.obj",
            "s/c1/other.obj",
        ])
        .unwrap();
        assert_eq!(got, ["c0/a/model", "c0/b/model", "c1/a/model", "other"]);
        // One file of a stem group may have fewer folders than the others need.
        assert_eq!(
            names(&["s/model.obj", "s/x/a/model.obj", "s/y/a/model.obj"]).unwrap(),
            ["model", "x/a/model", "y/a/model"]
        );
        // A file at the root beside a same-named one in a folder.
        assert_eq!(names(&["r/a.obj", "r/sub/a.npy"]).unwrap(), ["a", "sub/a"]);
        // `..` and `.` are resolved before names are taken.
        assert_eq!(
            names(&["l/x/../p/./m.obj", "l/q/m.obj"]).unwrap(),
            ["p/m", "q/m"]
        );
    }

    #[test]
    fn inputs_that_would_share_an_output_are_refused() {
        let e = names(&["d/a/model.obj", "d/a/model.ply"]).unwrap_err();
        assert!(e.to_string().contains("would both be written"), "{e}");
        assert!(names(&["x.obj", "x.obj"]).is_err());
        assert!(names(&[".."]).is_err());
    }

    proptest::proptest! {
        /// Whatever the layout, names are distinct (or the call refuses), and each name is a
        /// suffix of its input's path without the extension.
        #[test]
        fn names_are_distinct_suffixes(
            files in proptest::collection::vec(
                (proptest::collection::vec(0u8..3, 0..4), 0u8..3, 0u8..2), 1..30)
        ) {
            let paths: Vec<PathBuf> = files
                .iter()
                .map(|(dirs, stem, ext)| {
                    let mut p = PathBuf::from("root");
                    for d in dirs {
                        p.push(format!("d{d}"));
                    }
                    p.push(format!("s{stem}.{}", ["obj", "ply"][*ext as usize]));
                    p
                })
                .collect();
            let mut unique = paths.clone();
            unique.sort();
            unique.dedup();
            match output_names(&unique) {
                Ok(n) => {
                    let mut s = n.clone();
                    s.sort();
                    s.dedup();
                    proptest::prop_assert_eq!(s.len(), n.len());
                    for (p, name) in unique.iter().zip(&n) {
                        let full = p.with_extension("");
                        proptest::prop_assert!(full.to_string_lossy().ends_with(name.as_str()));
                    }
                }
                Err(_) => {
                    // Only when two files differ by their extension alone.
                    let mut stems: Vec<PathBuf> =
                        unique.iter().map(|p| p.with_extension("")).collect();
                    stems.sort();
                    let before = stems.len();
                    stems.dedup();
                    proptest::prop_assert!(stems.len() < before);
                }
            }
        }
    }
}
