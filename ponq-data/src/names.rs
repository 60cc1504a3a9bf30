//! The output names of a batch's inputs: distinct by construction, stable, the same in every
//! batch entry point (`ponq-prep meshes`, `ponq-infer DIR`, `ponq.prepare_meshes`, the Ray
//! example) and the key of the shard hash ([`crate::records::Shard`]).
//!
//! A name is the input's path below the dataset's root folder, without its extension, with `/`
//! between folders: `part_001` for a file in the root, `a/model` and `b/model` for a dataset
//! laid out as ShapeNet and many others are (`a/model.obj`, `b/model.obj`; the output is
//! written into the same sub-folders of the output folder). The root is the folder given, or
//! the folder of a list file; an input outside it is named by its whole path. So a name
//! depends on its input and the root only: adding files to a dataset, or listing it at another
//! time, never renames another input (shards stay put), and a flat folder keeps the names it
//! always had (the stems). Inputs that would still share an output are refused, before any
//! work: two that differ only by their extension (`a/model.obj`, `a/model.ply`), one listed
//! twice, and two whose names differ only by letter case (one file on a case-insensitive
//! output folder, as macOS and Windows have).
//!
//! Invariant: the names of one call are distinct (also ignoring case), non-empty, use `/`
//! between folders, and hold no `.` / `..` component.
//!
//! ```
//! use std::path::{Path, PathBuf};
//! use ponq_data::names::output_names;
//! let inputs: Vec<PathBuf> =
//!     ["data/a/model.obj", "data/b/model.obj", "data/chair.obj"].map(PathBuf::from).into();
//! assert_eq!(
//!     output_names(&inputs, Path::new("data")).unwrap(),
//!     ["a/model", "b/model", "chair"]
//! );
//! ```

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

use crate::error::{DataError, Result};

/// The output name of every input ([module docs](self)) below `root`, in the order of
/// `inputs`.
///
/// # Errors
/// An input without a file name, one whose name is not UTF-8, or two inputs that map to one
/// name (ignoring case); the error names both files.
pub fn output_names(inputs: &[PathBuf], root: &Path) -> Result<Vec<String>> {
    let root = lexical(root);
    let mut names = Vec::with_capacity(inputs.len());
    for p in inputs {
        let normal = lexical(p);
        let rel = normal.strip_prefix(&root).unwrap_or(&normal);
        let stem = rel
            .file_stem()
            .ok_or_else(|| DataError::Invalid(format!("{} has no file name", p.display())))?;
        let mut parts: Vec<String> = Vec::new();
        if let Some(parent) = rel.parent() {
            for c in parent.components() {
                if let Component::Normal(s) = c {
                    parts.push(utf8(s, p)?);
                }
            }
        }
        parts.push(utf8(stem, p)?);
        names.push(parts.join("/"));
    }
    let mut seen: HashMap<String, usize> = HashMap::new();
    for (i, n) in names.iter().enumerate() {
        if let Some(&j) = seen.get(&n.to_lowercase()) {
            return Err(DataError::Invalid(format!(
                "{} and {} would both be written as {:?}{} (they differ only by their \
                 extension or letter case, or are one file twice); rename or drop one",
                inputs[j].display(),
                inputs[i].display(),
                names[j],
                if names[j] == *n {
                    String::new()
                } else {
                    format!(" / {n:?}")
                }
            )));
        }
        seen.insert(n.to_lowercase(), i);
    }
    Ok(names)
}

/// The root of a list of inputs given without one (a Python list): their deepest common
/// folder (empty when they share none). Give the dataset's folder instead when calling on
/// parts of a dataset, so that every part names its inputs alike.
pub fn common_folder(paths: &[PathBuf]) -> PathBuf {
    let normals: Vec<PathBuf> = paths.iter().map(|p| lexical(p)).collect();
    let mut root: Option<Vec<Component<'_>>> = None;
    for p in &normals {
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

/// The output file of `name` in `out` with extension `ext` (`out/a/model.npz`).
pub fn output_path(out: &Path, name: &str, ext: &str) -> PathBuf {
    out.join(format!("{name}.{ext}"))
}

fn utf8(s: &std::ffi::OsStr, p: &Path) -> Result<String> {
    s.to_str().map(str::to_string).ok_or_else(|| {
        DataError::Invalid(format!(
            "{} has a name that is not UTF-8: outputs and logs need one",
            p.display()
        ))
    })
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

    fn names(v: &[&str], root: &str) -> Result<Vec<String>> {
        output_names(
            &v.iter().map(PathBuf::from).collect::<Vec<_>>(),
            Path::new(root),
        )
    }

    #[test]
    fn a_flat_folder_keeps_its_stems() {
        assert_eq!(
            names(&["d/x.obj", "d/y.ply", "d/z.stl"], "d").unwrap(),
            ["x", "y", "z"]
        );
    }

    #[test]
    fn names_are_paths_below_the_root() {
        // ShapeNet: synset/id/model.obj, ids repeated across synsets.
        let got = names(
            &[
                "s/c0/a/model.obj",
                "s/c0/b/model.obj",
                "s/c1/a/model.obj",
                "s/c1/other.obj",
            ],
            "s",
        )
        .unwrap();
        assert_eq!(got, ["c0/a/model", "c0/b/model", "c1/a/model", "c1/other"]);
        // A name depends on its input and the root only, not on the other inputs.
        assert_eq!(names(&["s/c0/a/model.obj"], "s").unwrap(), ["c0/a/model"]);
        // `..` and `.` are resolved before names are taken; inputs outside the root are
        // named by their whole path.
        assert_eq!(
            names(&["l/x/../p/./m.obj", "/abs/q/m.obj"], "l").unwrap(),
            ["p/m", "abs/q/m"]
        );
        assert_eq!(
            common_folder(&["s/c0/a/m.obj", "s/c1/m.obj"].map(PathBuf::from)),
            PathBuf::from("s")
        );
    }

    #[test]
    fn inputs_that_would_share_an_output_are_refused() {
        let e = names(&["d/a/model.obj", "d/a/model.ply"], "d").unwrap_err();
        assert!(e.to_string().contains("would both be written"), "{e}");
        assert!(names(&["x.obj", "x.obj"], "").is_err());
        assert!(names(&["d/A/Model.obj", "d/a/model.obj"], "d").is_err());
        assert!(names(&[".."], "").is_err());
    }

    proptest::proptest! {
        /// Whatever the layout, names are distinct (or the call refuses), and each name is the
        /// input's path below the root without the extension.
        #[test]
        fn names_are_distinct_paths(
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
            match output_names(&unique, Path::new("root")) {
                Ok(n) => {
                    let mut s = n.clone();
                    s.sort();
                    s.dedup();
                    proptest::prop_assert_eq!(s.len(), n.len());
                    for (p, name) in unique.iter().zip(&n) {
                        let rel = p.strip_prefix("root").unwrap().with_extension("");
                        proptest::prop_assert_eq!(rel.to_string_lossy(), name.as_str());
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
