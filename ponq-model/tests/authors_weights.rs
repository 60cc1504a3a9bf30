//! Loading the authors' PyTorch state dict: the test writes a `.pt` file (PyTorch's zip
//! layout: `archive/data.pkl` pickled with protocol 2 as `torch.save` does, one raw storage
//! per tensor) with the key names and shapes of `CNN_3d_multiple_split`, loads it, and checks
//! every parameter landed in the right place.

use std::io::Write;

use burn::prelude::*;
use burn::store::ModuleSnapshot;
use ponq_model::{PonqNetConfig, backend, weights};

fn push_unicode(p: &mut Vec<u8>, s: &str) {
    p.push(b'X');
    p.extend_from_slice(&(s.len() as u32).to_le_bytes());
    p.extend_from_slice(s.as_bytes());
}

fn push_int(p: &mut Vec<u8>, v: i64) {
    p.push(b'J');
    p.extend_from_slice(&(v as i32).to_le_bytes());
}

fn push_global(p: &mut Vec<u8>, module: &str, name: &str) {
    p.push(b'c');
    p.extend_from_slice(format!("{module}\n{name}\n").as_bytes());
}

/// The authors' key names and shapes for the paper's config.
fn authors_keys(w: usize, p: usize) -> Vec<(String, Vec<usize>)> {
    let mut keys = vec![
        ("encoder.0.weight".to_string(), vec![w, 1, 2, 2, 2]),
        ("encoder.0.bias".to_string(), vec![w]),
    ];
    for k in 0..5 {
        keys.push((format!("encoder.{}.weight", 2 * k + 2), vec![w, w, 3, 3, 3]));
        keys.push((format!("encoder.{}.bias", 2 * k + 2), vec![w]));
    }
    for (dec, out) in [
        ("decoder_points", 3 * p),
        ("decoder_vstars", 3 * p),
        ("decoder_As", 6 * p),
        ("decoder_mean_normals", 3 * p),
        ("decoder_bools", 1),
    ] {
        for b in 0..3 {
            for c in ["conv_1", "conv_2"] {
                keys.push((format!("{dec}.decoder.{b}.{c}.weight"), vec![w, w, 1, 1, 1]));
                keys.push((format!("{dec}.decoder.{b}.{c}.bias"), vec![w]));
            }
        }
        keys.push((format!("{dec}.decoder.3.weight"), vec![out, w, 1, 1, 1]));
        keys.push((format!("{dec}.decoder.3.bias"), vec![out]));
    }
    keys
}

fn value(key_index: usize, i: usize) -> f32 {
    ((key_index * 7919 + i * 31) % 1009) as f32 * 1e-3 - 0.5
}

fn write_pt(path: &std::path::Path, keys: &[(String, Vec<usize>)]) {
    let mut p = vec![0x80, 2, b'}', b'('];
    for (ki, (key, shape)) in keys.iter().enumerate() {
        let numel: usize = shape.iter().product();
        push_unicode(&mut p, key);
        push_global(&mut p, "torch._utils", "_rebuild_tensor_v2");
        p.push(b'(');
        p.push(b'(');
        push_unicode(&mut p, "storage");
        push_global(&mut p, "torch", "FloatStorage");
        push_unicode(&mut p, &ki.to_string());
        push_unicode(&mut p, "cpu");
        push_int(&mut p, numel as i64);
        p.push(b't');
        p.push(b'Q');
        push_int(&mut p, 0);
        p.push(b'(');
        for &s in shape {
            push_int(&mut p, s as i64);
        }
        p.push(b't');
        p.push(b'(');
        let mut stride = 1;
        let mut strides = vec![0; shape.len()];
        for d in (0..shape.len()).rev() {
            strides[d] = stride;
            stride *= shape[d];
        }
        for s in strides {
            push_int(&mut p, s as i64);
        }
        p.push(b't');
        p.push(0x89);
        push_global(&mut p, "collections", "OrderedDict");
        p.push(b')');
        p.push(b'R');
        p.push(b't');
        p.push(b'R');
    }
    p.push(b'u');
    p.push(b'.');
    let f = std::fs::File::create(path).unwrap();
    let mut z = zip::ZipWriter::new(f);
    let o =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    z.start_file("archive/data.pkl", o).unwrap();
    z.write_all(&p).unwrap();
    for (ki, (_, shape)) in keys.iter().enumerate() {
        let numel: usize = shape.iter().product();
        z.start_file(format!("archive/data/{ki}"), o).unwrap();
        let bytes: Vec<u8> = (0..numel)
            .flat_map(|i| value(ki, i).to_le_bytes())
            .collect();
        z.write_all(&bytes).unwrap();
    }
    z.start_file("archive/version", o).unwrap();
    z.write_all(b"3\n").unwrap();
    z.start_file("archive/byteorder", o).unwrap();
    z.write_all(b"little").unwrap();
    z.finish().unwrap();
}

/// Our path of an authors' key.
fn our_path(key: &str) -> String {
    let mut s = key.to_string();
    for (from, to) in [
        ("decoder_As.", "decoder_cholesky."),
        ("decoder_mean_normals.", "decoder_normals."),
        ("decoder_bools.", "decoder_occupancy."),
    ] {
        if let Some(rest) = s.strip_prefix(from) {
            s = format!("{to}{rest}");
        }
    }
    if let Some(rest) = s.strip_prefix("encoder.") {
        let (idx, tail) = rest.split_once('.').unwrap();
        let i: usize = idx.parse().unwrap();
        return if i == 0 {
            format!("input.{tail}")
        } else {
            format!("encoder.{}.{tail}", i / 2 - 1)
        };
    }
    let (dec, rest) = s.split_once(".decoder.").unwrap();
    let (idx, tail) = rest.split_once('.').unwrap();
    if idx == "3" {
        format!("{dec}.head.{tail}")
    } else {
        format!("{dec}.blocks.{idx}.{tail}")
    }
}

#[test]
fn authors_state_dict_loads_every_parameter_in_place() {
    let dir = std::env::temp_dir().join(format!("ponq-authors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("pretrained_PoNQ_ABC.pt");
    let keys = authors_keys(128, 4);
    write_pt(&path, &keys);
    let cfg = PonqNetConfig::new();
    let dev = backend::cpu();
    let net = weights::load_authors_state_dict(&path, &cfg, &dev).expect("loads");
    let tensors = net.collect(None, None, false);
    assert_eq!(tensors.len(), keys.len());
    let mut by_path = std::collections::HashMap::new();
    for t in tensors {
        let (p, _, shape, _, bytes) = t.into_parts().unwrap();
        by_path.insert(p, (shape, bytes.to_vec()));
    }
    for (ki, (key, shape)) in keys.iter().enumerate() {
        let ours = our_path(key);
        let (s, bytes) = by_path
            .get(&ours)
            .unwrap_or_else(|| panic!("{key} -> {ours} missing"));
        assert_eq!(s.to_vec(), *shape, "{key}");
        let vals: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        for (i, v) in vals.iter().enumerate().step_by(97) {
            assert_eq!(*v, value(ki, i), "{key}[{i}]");
        }
    }
    // The loaded network runs the same on the fast CPU kernels and on the stock layers.
    let n = 6;
    let x = Tensor::<1>::from_data(
        TensorData::new(
            (0..(n + 1) * (n + 1) * (n + 1))
                .map(|i| ((i * 37) % 23) as f32 / 23.0 - 0.5)
                .collect::<Vec<f32>>(),
            [(n + 1) * (n + 1) * (n + 1)],
        ),
        &dev,
    )
    .reshape([1, 1, n + 1, n + 1, n + 1]);
    let mut frame = ponq_model::GridFrame::whole(n);
    frame.authors_cell_base = true;
    let fast = net.forward(x.clone(), &frame);
    let stock = net
        .clone()
        .with_kernels(ponq_model::Kernels::Stock)
        .forward(x, &frame);
    for (a, b) in [
        (fast.points, stock.points),
        (fast.normals, stock.normals),
        (fast.cholesky, stock.cholesky),
    ] {
        let a = a.into_data().try_to_vec::<f32>().unwrap();
        let b = b.into_data().try_to_vec::<f32>().unwrap();
        let scale = b.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max);
        assert!(worst <= 1e-5 * scale, "fast vs stock: {worst} of {scale}");
    }
    // A state dict with a missing tensor is refused with a message.
    let short = dir.join("short.pt");
    write_pt(&short, &keys[..keys.len() - 1]);
    let e = weights::load_authors_state_dict(&short, &cfg, &dev).expect_err("refused");
    assert!(
        e.to_string().contains("decoder_occupancy") || e.to_string().contains("missing"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
