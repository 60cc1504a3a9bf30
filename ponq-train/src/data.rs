//! Training data: shapes in memory ([`Shape`]), random crops with 90-degree rotations and
//! flips ([`Item`]), and the [`Batcher`] that stacks items into the network's input tensor.
//!
//! Every item is expressed in a crop-local frame: node `(0,0,0)` of the crop sits at
//! `(-1,-1,-1)` and the node spacing is `2/N` of the whole grid, so all items of a batch share
//! one [`GridFrame`] (a translation of samples and points changes no loss).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use burn::prelude::*;
use ponq_data::dataset::ShapeRecord;
use ponq_data::occupancy::close_threshold;
use ponq_model::{GridFrame, network_input_scale};
use rand::Rng;
use rand::seq::SliceRandom;

/// One training or validation shape: its SDF grid at the training resolution and surface
/// samples with unit normals, all in the `[-1,1]` convention.
///
/// Invariant: `sdf.len() == (res + 1)^3`, `normals.len() == samples.len()`.
#[derive(Debug, Clone)]
pub struct Shape {
    /// File stem.
    pub id: String,
    /// Cells per side.
    pub res: usize,
    /// `(res+1)^3` node values, C order.
    pub sdf: Vec<f32>,
    /// Surface samples.
    pub samples: Vec<[f32; 3]>,
    /// Their unit normals.
    pub normals: Vec<[f32; 3]>,
    /// Grids of the same shape at other resolutions (`data.extra_resolutions`), each
    /// `(res, (res+1)^3 values)`.
    pub extra: Vec<(usize, Vec<f32>)>,
}

impl Shape {
    /// The grid at resolution `res`: the main one or an extra one.
    pub fn grid(&self, res: usize) -> Option<&[f32]> {
        if res == self.res {
            return Some(&self.sdf);
        }
        self.extra
            .iter()
            .find(|g| g.0 == res)
            .map(|g| g.1.as_slice())
    }

    /// Takes the grid at `res` and at most `max_samples` samples (a deterministic subset) of
    /// a record.
    pub fn from_record(
        id: String,
        rec: ShapeRecord,
        res: usize,
        max_samples: usize,
    ) -> Result<Self> {
        let Some(sdf) = rec.sdf.get(&res) else {
            bail!(
                "shape {id} has no SDF grid at resolution {res} (it has {:?}); prepare it with `ponq-prep ... --res {res}`",
                rec.sdf.keys().collect::<Vec<_>>()
            );
        };
        if rec.samples.is_empty() {
            bail!("shape {id} has no surface samples");
        }
        let (mut samples, mut normals) = (rec.samples, rec.normals);
        if samples.len() > max_samples {
            let stride = samples.len() as f64 / max_samples as f64;
            let pick = |v: &[[f32; 3]]| -> Vec<[f32; 3]> {
                (0..max_samples)
                    .map(|i| v[(i as f64 * stride) as usize])
                    .collect()
            };
            samples = pick(&samples);
            normals = pick(&normals);
        }
        Ok(Self {
            id,
            res,
            sdf: sdf.clone(),
            samples,
            normals,
            extra: Vec::new(),
        })
    }
}

/// Shape files of `dir`, searched recursively (`.npz` records of `ponq-prep`, which writes
/// `OUT/a/model.npz` where file stems repeat, or the authors' `.hdf5` / `.h5`), sorted,
/// optionally restricted to the ids of a split file: a file's id is its path below `dir`
/// without the extension (`part_001`, `a/model`).
pub fn shape_files(dir: &Path, split: Option<&Path>) -> Result<Vec<PathBuf>> {
    let is_shape = |p: &Path| {
        matches!(
            p.extension().and_then(|e| e.to_str()),
            Some("npz" | "hdf5" | "h5")
        ) && !p
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with('.'))
    };
    if !dir.is_dir() {
        bail!(
            "cannot list the data folder {}: not a folder",
            dir.display()
        );
    }
    let mut files = ponq_data::prep::input_files(dir, is_shape)
        .with_context(|| format!("cannot list the data folder {}", dir.display()))?;
    files.sort();
    if let Some(split) = split {
        let ids = ponq_data::dataset::read_split(split)
            .with_context(|| format!("cannot read split {}", split.display()))?;
        let set: std::collections::HashSet<&str> = ids.iter().map(String::as_str).collect();
        files.retain(|p| {
            p.strip_prefix(dir)
                .ok()
                .map(|rel| rel.with_extension(""))
                .and_then(|rel| {
                    rel.to_str()
                        .map(|r| r.replace(std::path::MAIN_SEPARATOR, "/"))
                })
                .is_some_and(|id| set.contains(id.as_str()))
        });
    }
    Ok(files)
}

/// Reads one shape file: its grid at `res`, those at the resolutions `extra`, and at most
/// `max_samples` samples.
pub fn read_shape_with(
    path: &Path,
    res: usize,
    extra: &[usize],
    max_samples: usize,
) -> Result<Shape> {
    let id = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let rec = match path.extension().and_then(|e| e.to_str()) {
        Some("hdf5" | "h5") => ponq_data::hdf5::read_authors_h5(path),
        _ => ShapeRecord::read(path),
    }
    .with_context(|| format!("cannot read shape {}", path.display()))?;
    let mut grids = Vec::new();
    for &r in extra.iter().filter(|&&r| r != res) {
        let Some(g) = rec.sdf.get(&r) else {
            bail!(
                "shape {id} has no SDF grid at resolution {r} (it has {:?}); prepare it with `ponq-prep ... --res {r}`",
                rec.sdf.keys().collect::<Vec<_>>()
            );
        };
        grids.push((r, g.clone()));
    }
    let mut shape = Shape::from_record(id, rec, res, max_samples)?;
    shape.extra = grids;
    Ok(shape)
}

/// Reads one shape file.
pub fn read_shape(path: &Path, res: usize, max_samples: usize) -> Result<Shape> {
    read_shape_with(path, res, &[], max_samples)
}

/// A signed permutation of the axes: new coordinate `a` is `sign[a] * old[perm[a]]`.
/// It maps the `[-1,1]^3` grid onto itself (node `i` to `N - i` on flipped axes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AxisMap {
    /// Source axis of each new axis.
    pub perm: [usize; 3],
    /// Flip of each new axis.
    pub flip: [bool; 3],
}

impl AxisMap {
    /// The identity.
    pub const IDENTITY: Self = Self {
        perm: [0, 1, 2],
        flip: [false; 3],
    };

    /// One of the 48 symmetries of the cube, uniformly.
    pub fn random(rng: &mut impl Rng) -> Self {
        let mut perm = [0, 1, 2];
        perm.shuffle(rng);
        Self {
            perm,
            flip: [rng.random(), rng.random(), rng.random()],
        }
    }

    /// Maps a point or a normal.
    pub fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|a| {
            let v = p[self.perm[a]];
            if self.flip[a] { -v } else { v }
        })
    }

    /// Old node index (per old axis) of new node `i` of an `n`-cell grid.
    fn source_node(&self, i: [usize; 3], n: usize) -> [usize; 3] {
        let mut src = [0; 3];
        for a in 0..3 {
            src[self.perm[a]] = if self.flip[a] { n - i[a] } else { i[a] };
        }
        src
    }
}

/// One crop of one shape, ready for a step.
///
/// Invariants: `sdf.len() == (cells + 1)^3`; `occupied` and `close` have `cells^3` entries;
/// samples and normals have equal lengths and lie in the crop-local frame.
#[derive(Debug, Clone)]
pub struct Item {
    /// Cells per side of the crop.
    pub cells: usize,
    /// Network input (SDF times [`network_input_scale`]).
    pub sdf: Vec<f32>,
    /// Samples used by the losses (a random subset of those in the crop).
    pub samples: Vec<[f32; 3]>,
    /// Their normals.
    pub normals: Vec<[f32; 3]>,
    /// Ground-truth occupancy from all samples in the crop.
    pub occupied: Vec<bool>,
    /// Cells whose 8 corners are all within the close threshold.
    pub close: Vec<bool>,
}

/// How items are cut.
#[derive(Debug, Clone, Copy)]
pub struct ItemOptions {
    /// Cells per side of the crop (`0` or `>= res`: the whole grid).
    pub crop: usize,
    /// Samples per item.
    pub samples: usize,
    /// Random rotation / flip.
    pub augment: bool,
}

/// The frame shared by all items of a resolution-`res` grid (crop-local: node 0 at -1).
pub fn item_frame(res: usize) -> GridFrame {
    GridFrame::whole(res)
}

/// Cuts a random crop of `shape` (retrying until it holds surface, at most 32 times).
pub fn make_item(shape: &Shape, opts: &ItemOptions, rng: &mut impl Rng) -> Item {
    make_item_at(shape, shape.res, &shape.sdf, opts, rng)
}

/// [`make_item`] from the grid `sdf` of `shape` at resolution `res` (see [`Shape::grid`]).
pub fn make_item_at(
    shape: &Shape,
    res: usize,
    sdf: &[f32],
    opts: &ItemOptions,
    rng: &mut impl Rng,
) -> Item {
    let n = res;
    let c = if opts.crop == 0 || opts.crop >= n {
        n
    } else {
        opts.crop
    };
    let map = if opts.augment {
        AxisMap::random(rng)
    } else {
        AxisMap::IDENTITY
    };
    let cell = 2.0 / n as f32;
    // Samples in the mapped frame.
    let mapped: Vec<[f32; 3]> = shape.samples.iter().map(|&p| map.apply(p)).collect();
    let mut start = [0usize; 3];
    let mut inside: Vec<usize> = Vec::new();
    for attempt in 0..32 {
        start = std::array::from_fn(|_| {
            if c < n {
                rng.random_range(0..=n - c)
            } else {
                0
            }
        });
        let lo: [f32; 3] = start.map(|s| -1.0 + s as f32 * cell);
        let hi: [f32; 3] = std::array::from_fn(|a| lo[a] + c as f32 * cell);
        inside = (0..mapped.len())
            .filter(|&i| (0..3).all(|a| mapped[i][a] >= lo[a] && mapped[i][a] <= hi[a]))
            .collect();
        if !inside.is_empty() || c == n || attempt == 31 {
            break;
        }
    }
    let shift: [f32; 3] = start.map(|s| s as f32 * cell);
    let local = |p: [f32; 3]| -> [f32; 3] { std::array::from_fn(|a| p[a] - shift[a]) };
    // Ground-truth occupancy of the crop from all its samples.
    let mut occupied = vec![false; c * c * c];
    for &i in &inside {
        let q = local(mapped[i]);
        let idx: [usize; 3] = q.map(|x| {
            let k = ((x + 1.0) / cell).floor();
            if k <= 0.0 { 0 } else { (k as usize).min(c - 1) }
        });
        occupied[(idx[0] * c + idx[1]) * c + idx[2]] = true;
    }
    // The loss samples: a random subset.
    inside.shuffle(rng);
    inside.truncate(opts.samples);
    let samples = inside.iter().map(|&i| local(mapped[i])).collect();
    let normals = inside
        .iter()
        .map(|&i| map.apply(shape.normals[i]))
        .collect();
    // The crop of the mapped grid.
    let m = c + 1;
    let scale = network_input_scale(n);
    let mut raw = Vec::with_capacity(m * m * m);
    for i in 0..m {
        for j in 0..m {
            for k in 0..m {
                let s = map.source_node([start[0] + i, start[1] + j, start[2] + k], n);
                raw.push(sdf[(s[0] * (n + 1) + s[1]) * (n + 1) + s[2]]);
            }
        }
    }
    let thr = close_threshold(n) as f32;
    let mut close = vec![false; c * c * c];
    for i in 0..c {
        for j in 0..c {
            for k in 0..c {
                let mut all = true;
                for d in 0..8 {
                    let v = raw[((i + (d >> 2)) * m + j + ((d >> 1) & 1)) * m + k + (d & 1)];
                    all &= v.abs() < thr;
                }
                close[(i * c + j) * c + k] = all;
            }
        }
    }
    Item {
        cells: c,
        sdf: raw.iter().map(|v| v * scale).collect(),
        samples,
        normals,
        occupied,
        close,
    }
}

/// Stacks items (of one crop size) into the `[B, 1, c+1, c+1, c+1]` input tensor.
#[derive(Debug, Clone)]
pub struct Batcher {
    /// Device of the tensors.
    pub device: Device,
}

impl Batcher {
    /// The input tensor of `items`.
    pub fn batch(&self, items: &[Item]) -> Result<Tensor<5>> {
        let Some(first) = items.first() else {
            bail!("empty batch");
        };
        let c = first.cells;
        if items.iter().any(|it| it.cells != c) {
            bail!("items of one batch must have one crop size");
        }
        let m = c + 1;
        let data: Vec<f32> = items.iter().flat_map(|it| it.sdf.iter().copied()).collect();
        Ok(Tensor::<1>::from_data(
            TensorData::new(data, [items.len() * m * m * m]),
            &self.device,
        )
        .reshape([items.len(), 1, m, m, m]))
    }
}

/// An analytic test shape: a sphere of `radius` around `centre` on a `res`-cell grid with
/// `samples` Fibonacci-spiral surface samples (for tests and benchmarks).
pub fn sphere_shape(id: &str, res: usize, centre: [f32; 3], radius: f32, samples: usize) -> Shape {
    let m = res + 1;
    let node = |i: usize| -1.0 + 2.0 * i as f32 / res as f32;
    let mut sdf = Vec::with_capacity(m * m * m);
    for i in 0..m {
        for j in 0..m {
            for k in 0..m {
                let d = [
                    node(i) - centre[0],
                    node(j) - centre[1],
                    node(k) - centre[2],
                ];
                sdf.push((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - radius);
            }
        }
    }
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let mut pts = Vec::with_capacity(samples);
    let mut nrm = Vec::with_capacity(samples);
    for i in 0..samples {
        let z = 1.0 - 2.0 * (i as f32 + 0.5) / samples as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let t = golden * i as f32;
        let n = [r * t.cos(), r * t.sin(), z];
        nrm.push(n);
        pts.push(std::array::from_fn(|a| centre[a] + radius * n[a]));
    }
    Shape {
        extra: Vec::new(),
        id: id.to_string(),
        res,
        sdf,
        samples: pts,
        normals: nrm,
    }
}
