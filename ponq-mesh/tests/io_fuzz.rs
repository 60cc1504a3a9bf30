//! Property tests: every reader returns `Ok` or `Err` (never panics, never hangs) on
//! arbitrary bytes and on mutated or truncated valid files.

#[path = "io_common.rs"]
mod io_common;

use std::sync::OnceLock;

use io_common::*;
use ponq_mesh::io::{npy, npz, obj, off, ply, stl};
use proptest::prelude::*;

/// Runs every in-memory parser on `bytes`; the results are discarded, only panics matter.
fn parse_all(bytes: &[u8]) {
    let _ = obj::parse(bytes);
    let _ = ply::parse(bytes);
    let _ = off::parse(bytes);
    let _ = stl::parse(bytes);
    let _ = npz::parse_ponq(bytes);
    let _ = npy::parse(bytes);
}

/// Valid files of every format, each paired with its parser.
type Parser = fn(&[u8]) -> bool;

fn samples() -> &'static Vec<(Vec<u8>, Parser)> {
    static S: OnceLock<Vec<(Vec<u8>, Parser)>> = OnceLock::new();
    S.get_or_init(|| {
        let m = sample_mesh(9, 12, 16);
        let mut out: Vec<(Vec<u8>, Parser)> = Vec::new();
        let mut b = Vec::new();
        obj::write_to(&mut b, &m).unwrap();
        out.push((b, |x| obj::parse(x).is_ok()));
        let mut b = Vec::new();
        off::write_to(&mut b, &m).unwrap();
        out.push((b, |x| off::parse(x).is_ok()));
        let mut b = Vec::new();
        ply::write_to(&mut b, &m).unwrap();
        out.push((b, |x| ply::parse(x).is_ok()));
        let mut b = Vec::new();
        ply::write_ascii_to(&mut b, &m).unwrap();
        out.push((b, |x| ply::parse(x).is_ok()));
        out.push((
            std::fs::read(data("square_pyramid_ascii.ply")).unwrap(),
            |x| ply::parse(x).is_ok(),
        ));
        out.push((std::fs::read(data("square_pyramid.obj")).unwrap(), |x| {
            obj::parse(x).is_ok()
        }));
        out.push((std::fs::read(data("tetra_ascii.stl")).unwrap(), |x| {
            stl::parse(x).is_ok()
        }));
        let pyr = pyramid();
        let tris: Vec<[[f32; 3]; 3]> = pyr
            .faces
            .iter()
            .map(|f| f.map(|i| pyr.vertices[i as usize].map(|c| c as f32)))
            .collect();
        out.push((binary_stl(&tris, b"solid x"), |x| stl::parse(x).is_ok()));
        // npz and npy files go through the file system once.
        let dir = scratch("io_fuzz_samples");
        let p = dir.join("p.npz");
        npz::write_ponq(&p, &sample_ponq(3, 4, true)).unwrap();
        out.push((std::fs::read(&p).unwrap(), |x| npz::parse_ponq(x).is_ok()));
        let p = dir.join("f32.npz");
        write_npz(
            &p,
            &ponq_arrays(&sample_ponq(4, 3, false)),
            true,
            true,
            true,
        );
        out.push((std::fs::read(&p).unwrap(), |x| npz::parse_ponq(x).is_ok()));
        let p = dir.join("g.npy");
        let g = npy::Grid3::new([2, 3, 2], (0..12).map(f64::from).collect()).unwrap();
        npy::write_npy_grid_f32(&p, &g).unwrap();
        out.push((std::fs::read(&p).unwrap(), |x| npy::parse(x).is_ok()));
        for (k, (b, parse)) in out.iter().enumerate() {
            assert!(parse(b), "sample {k} does not parse");
        }
        out
    })
}

#[derive(Debug, Clone)]
enum Mutation {
    Set(usize, u8),
    Insert(usize, Vec<u8>),
    Remove(usize, usize),
    Truncate(usize),
    /// Replaces a decimal digit by a long run of 9s (huge counts in headers).
    Inflate(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Set(i, b)),
        1 => (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(i, v)| Mutation::Insert(i, v)),
        1 => (any::<usize>(), 1usize..16).prop_map(|(i, n)| Mutation::Remove(i, n)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
        1 => any::<usize>().prop_map(Mutation::Inflate),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    let n = bytes.len().max(1);
    match m {
        Mutation::Set(i, b) => {
            if !bytes.is_empty() {
                bytes[i % n] = *b;
            }
        }
        Mutation::Insert(i, v) => {
            let at = i % (bytes.len() + 1);
            bytes.splice(at..at, v.iter().copied());
        }
        Mutation::Remove(i, k) => {
            let at = i % n;
            let end = (at + k).min(bytes.len());
            if at < end {
                bytes.drain(at..end);
            }
        }
        Mutation::Truncate(i) => bytes.truncate(i % n),
        Mutation::Inflate(i) => {
            let digits: Vec<usize> = bytes
                .iter()
                .enumerate()
                .filter(|(_, b)| b.is_ascii_digit())
                .map(|(k, _)| k)
                .collect();
            if !digits.is_empty() {
                let at = digits[i % digits.len()];
                bytes.splice(at..=at, b"99999999999".iter().copied());
            }
        }
    }
}

fn fuzz_cases() -> u32 {
    std::env::var("IO_FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(256)
}

proptest! {
    // 256 cases by default; `IO_FUZZ_CASES=100000 cargo test --test io_fuzz` for a long run.
    #![proptest_config(ProptestConfig { cases: fuzz_cases(), ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        parse_all(&bytes);
    }

    #[test]
    fn arbitrary_text_never_panics(text in "(ply|OFF|solid |v |f |[0-9 .\\-/#\\n]|element |property |end_header\\n|format ascii 1.0\\n){0,64}") {
        parse_all(text.as_bytes());
    }

    #[test]
    fn mutated_valid_files_never_panic(
        which in any::<usize>(),
        muts in proptest::collection::vec(mutation(), 1..6),
    ) {
        let s = samples();
        let (orig, parse) = &s[which % s.len()];
        let mut b = orig.clone();
        for m in &muts {
            apply(&mut b, m);
        }
        let _ = parse(&b);
        parse_all(&b);
    }

    #[test]
    fn every_truncation_prefix_is_handled(which in any::<usize>(), cut in any::<usize>()) {
        let s = samples();
        let (orig, parse) = &s[which % s.len()];
        let b = &orig[..cut % (orig.len() + 1)];
        let _ = parse(b);
    }
}

/// All prefixes of the binary formats: a truncation is an error (or, at a record boundary
/// for formats without counts, a smaller valid file), never a panic.
#[test]
fn all_prefixes_of_binary_files() {
    for (orig, parse) in samples() {
        for cut in 0..orig.len() {
            let _ = parse(&orig[..cut]);
        }
    }
    // Binary PLY and npz have counts: every strict prefix is an error.
    let s = samples();
    for k in [2usize, 8] {
        let (orig, parse) = &s[k];
        for cut in 0..orig.len() {
            assert!(!parse(&orig[..cut]), "sample {k} prefix {cut} accepted");
        }
    }
}
