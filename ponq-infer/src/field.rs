//! A signed distance given as a function (a neural field), evaluated near its surface only.
//!
//! People who mesh neural fields (NeuS, SDFStudio, Occupancy Networks' MISE) never build the
//! dense grid: at 1025^3 it is a billion evaluations of the network. [`field_band`] builds the
//! [`BandGrid`] inference reads by evaluating the field coarse to fine: an octree of blocks of
//! nodes, each tested at its centre; a block whose value is farther from zero than the field
//! can change over the block (its half-diagonal times `lipschitz`) plus the band's threshold
//! holds no node of the band and keeps only its sign; the others split down to bricks of
//! 8^3 nodes, and the bricks near the surface (and `reach` around them) are evaluated at every
//! node. For a field with that Lipschitz bound the stored values are the dense grid's, so the
//! mesh is the dense grid's.
//!
//! The field need not be a distance: its values are conditioned first, as a grid's are
//! (`ponq_data::condition`), from its first evaluations: a probe grid of at most 33^3 nodes
//! gives the iso-level and the sign, and windows of nodes at the full resolution around the
//! probe's zero set give the kind of field (a distance in other units, a monotone function of
//! one). The octree then tests the conditioned values, and the slopes seen in the evaluated
//! bricks check the Lipschitz bound: where they exceed it, the bound is widened and the field
//! evaluated again, rather than a piece dropped.

use anyhow::{Result, bail};
use ponq_data::condition::{Conditioning, FieldKind, FieldScan, Window, classify};
use ponq_mesh::band::{BRICK, BandGrid};

use crate::frame::Frame;
use crate::reconstruct::{InferOptions, band_parameters};

/// How many evaluations [`field_band`] made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FieldStats {
    /// Calls of the field (batches).
    pub calls: usize,
    /// Points evaluated.
    pub points: usize,
    /// Points of the dense grid.
    pub dense_points: usize,
    /// Bricks of 8^3 nodes evaluated at every node.
    pub stored_bricks: usize,
}

/// A field's band, how its values were conditioned, and the Lipschitz bound the octree used
/// in the end.
pub struct FieldBand {
    /// The conditioned values near the surface, in the normalised frame.
    pub band: BandGrid,
    /// What was evaluated (all passes).
    pub stats: FieldStats,
    /// How the values were read into distances.
    pub conditioning: Conditioning,
    /// The Lipschitz bound of the last pass (the one given, or wider: slopes seen beyond it).
    pub lipschitz: f64,
}

/// Cells per side of the probe grid that finds a field's level, sign and surface.
const PROBE: usize = 32;
/// Side, in nodes, of the windows evaluated at the full resolution for the conditioning.
const PROBE_WINDOW: usize = 24;
/// Windows at most.
const PROBE_WINDOWS: usize = 8;
/// Passes of the octree at most (each widens the Lipschitz bound the slopes exceeded).
const MAX_PASSES: usize = 4;

/// The band of a field `eval` (values in the units of `opts.bounds`; called with batches of
/// at most `batch` points, returns one value per point) on a grid of `res` cells per side over
/// `opts.bounds` (node `(i, j, k)` at `lo + h (i, j, k)`, `h = (hi - lo) / res`), as
/// [`crate::predict_band`] reads it for `encoder_layers`. The values are conditioned as
/// `opts.condition` says ([module docs](self)); `lipschitz` bounds how fast the conditioned
/// field changes (1 for a true distance), and is widened where evaluated bricks show faster
/// slopes. `progress(points_done)` after each batch.
///
/// # Errors
/// Bounds that do not make cubic cells, `res` below 1, a batch of 0, a `lipschitz` that is
/// not positive, `eval`'s errors, a result of the wrong length or with a non-finite value, a
/// field without a sign change or whose inside cannot be told.
#[allow(clippy::too_many_arguments)]
pub fn field_band_conditioned(
    res: usize,
    encoder_layers: usize,
    opts: &InferOptions,
    lipschitz: f64,
    batch: usize,
    mut eval: impl FnMut(&[[f64; 3]]) -> Result<Vec<f64>>,
    mut progress: impl FnMut(usize),
) -> Result<FieldBand> {
    if res == 0 || batch == 0 {
        bail!("a field needs at least 1 cell per side and a batch of at least 1 point");
    }
    if !(lipschitz > 0.0 && lipschitz.is_finite()) {
        bail!("lipschitz must be positive and finite, got {lipschitz}");
    }
    let started = std::time::Instant::now();
    let n1 = res + 1;
    let frame = Frame::of_dims([n1; 3], opts.bounds)?;
    let (lo, hi) = opts.bounds;
    let mut stats = FieldStats {
        dense_points: n1 * n1 * n1,
        ..Default::default()
    };
    let mut call = |pts: &[[f64; 3]], stats: &mut FieldStats| -> Result<Vec<f64>> {
        let mut out = Vec::with_capacity(pts.len());
        for chunk in pts.chunks(batch) {
            let v = eval(chunk)?;
            if v.len() != chunk.len() {
                bail!(
                    "the field returned {} values for {} points",
                    v.len(),
                    chunk.len()
                );
            }
            if let Some(p) = v.iter().position(|x| !x.is_finite()) {
                bail!("the field returned {} at the point {:?}", v[p], chunk[p]);
            }
            stats.calls += 1;
            stats.points += chunk.len();
            out.extend_from_slice(&v);
            progress(stats.points);
        }
        Ok(out)
    };
    // 1. The probe: level, sign, where the surface is.
    let pr = res.min(PROBE);
    let pn = pr + 1;
    let probe_at = |i: usize| -> [f64; 3] {
        let idx = [i / (pn * pn), (i / pn) % pn, i % pn];
        std::array::from_fn(|a| lo[a] + (hi[a] - lo[a]) * idx[a] as f64 / pr as f64)
    };
    let probe_pts: Vec<[f64; 3]> = (0..pn * pn * pn).map(probe_at).collect();
    let probe = call(&probe_pts, &mut stats)?;
    let mut scan = FieldScan::new([pn; 3], &opts.condition);
    for plane in probe.chunks(pn * pn) {
        scan.push_plane(plane)?;
    }
    let mut c = Conditioning::identity(frame.scale());
    c.cells = frame.n;
    let mut probed = true;
    match scan.level_and_sign() {
        Ok((level, flip, notes)) => {
            c.level = level;
            c.flip = flip;
            c.notes = notes;
        }
        Err(e) if e.to_string().contains("no sign change") => {
            // A surface smaller than the probe's cells: the octree (on the field as a
            // distance at the given level) still finds it; too little was seen to measure.
            probed = false;
            c.level = opts.condition.level.unwrap_or(0.0);
            c.flip = opts.condition.inside == ponq_data::condition::Inside::Positive;
            c.notes.push(
                "the probe grid saw no sign change: read as a signed distance at the level"
                    .to_string(),
            );
        }
        Err(e) => return Err(e.into()),
    }
    if opts.condition.field == FieldKind::Redistance {
        c.notes.push(
            "a field is not re-distanced (its grid is never built): read as a distance".to_string(),
        );
    }
    if opts.condition.field == FieldKind::Auto && probed {
        // 2. Windows at the full resolution around the probe's zero set, spread by a hash.
        let h: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]) / res as f64);
        let (level, flip) = (c.level, c.flip);
        let below = |v: f64| (v < level) != flip;
        let mut centres: Vec<(u64, [usize; 3])> = Vec::new();
        for i in 0..pr {
            for j in 0..pr {
                for k in 0..pr {
                    let at = |a: usize, b: usize, cc: usize| probe[(a * pn + b) * pn + cc];
                    let s0 = below(at(i, j, k));
                    if s0 == below(at(i + 1, j, k))
                        && s0 == below(at(i, j + 1, k))
                        && s0 == below(at(i, j, k + 1))
                    {
                        continue;
                    }
                    let centre =
                        [i, j, k].map(|x| ((x as f64 + 0.5) * res as f64 / pr as f64) as usize);
                    let key = (i as u64)
                        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
                        .wrapping_add((j as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f))
                        .wrapping_add((k as u64).wrapping_mul(0x1656_67b1_9e37_79f9))
                        .rotate_left(17);
                    centres.push((key, centre));
                }
            }
        }
        centres.sort_unstable();
        let w = PROBE_WINDOW.min(n1);
        let mut windows = Vec::new();
        for (_, centre) in centres.into_iter().take(PROBE_WINDOWS) {
            let origin = centre.map(|x| x.saturating_sub(w / 2).min(n1 - w));
            let pts: Vec<[f64; 3]> = (0..w * w * w)
                .map(|f| {
                    let idx = [f / (w * w), (f / w) % w, f % w];
                    std::array::from_fn(|a| lo[a] + h[a] * (origin[a] + idx[a]) as f64)
                })
                .collect();
            let v = call(&pts, &mut stats)?;
            windows.push(Window {
                dims: [w; 3],
                data: v.iter().map(|&x| x as f32).collect(),
            });
        }
        classify(&mut c, &windows, &scan.value_range());
        if c.needs_whole_grid() {
            c.notes.push(
                "a field is not re-distanced (its grid is never built): read value by value"
                    .to_string(),
            );
        }
    }
    c.time = started.elapsed();
    // 3. The octree on the conditioned values, widened while the slopes exceed its bound.
    let mut bound = lipschitz;
    for pass in 0..MAX_PASSES {
        let (band, seen) = octree_band(
            res,
            encoder_layers,
            opts,
            bound,
            batch,
            &|v| c.apply(v),
            &mut |pts, st| call(pts, st),
            &mut stats,
        )?;
        if seen <= bound * 1.5 || pass + 1 == MAX_PASSES {
            return Ok(FieldBand {
                band,
                stats,
                conditioning: c,
                lipschitz: bound,
            });
        }
        bound = seen * 1.25;
    }
    unreachable!("the loop returns on its last pass")
}

/// [`field_band_conditioned`]'s band and statistics.
///
/// # Errors
/// As [`field_band_conditioned`].
#[allow(clippy::too_many_arguments)]
pub fn field_band(
    res: usize,
    encoder_layers: usize,
    opts: &InferOptions,
    lipschitz: f64,
    batch: usize,
    eval: impl FnMut(&[[f64; 3]]) -> Result<Vec<f64>>,
    progress: impl FnMut(usize),
) -> Result<(BandGrid, FieldStats)> {
    let b = field_band_conditioned(res, encoder_layers, opts, lipschitz, batch, eval, progress)?;
    Ok((b.band, b.stats))
}

/// One pass of the octree over the field's conditioned values (`map` of the raw values):
/// the band, and the slope seen between neighbouring nodes of the evaluated bricks whose
/// values are within 4 cells of the surface (normalised units per normalised length; the
/// 99.9th percentile).
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn octree_band(
    res: usize,
    encoder_layers: usize,
    opts: &InferOptions,
    lipschitz: f64,
    batch: usize,
    map: &dyn Fn(f64) -> f64,
    call: &mut dyn FnMut(&[[f64; 3]], &mut FieldStats) -> Result<Vec<f64>>,
    stats: &mut FieldStats,
) -> Result<(BandGrid, f64)> {
    let n1 = res + 1;
    let dims = [n1; 3];
    let frame = Frame::of_dims(dims, opts.bounds)?;
    let (t, reach) = band_parameters(frame.n, encoder_layers, opts);
    let s = frame.scale();
    let (lo, _) = opts.bounds;
    let h: [f64; 3] = std::array::from_fn(|a| (opts.bounds.1[a] - lo[a]) / res as f64);
    let node = |i: usize, j: usize, k: usize| {
        [
            lo[0] + h[0] * i as f64,
            lo[1] + h[1] * j as f64,
            lo[2] + h[2] * k as f64,
        ]
    };
    let nb = BandGrid::brick_dims_of(dims)[0];
    // Octree over bricks: blocks of `size` bricks per side, from the coarsest that covers the
    // grid in a few blocks down to one brick.
    let mut size = 1usize;
    while size * 4 < nb {
        size *= 2;
    }
    // (brick coordinates of the block's corner, negative) of the far bricks' blocks.
    let mut far_blocks: Vec<([usize; 3], usize, bool)> = Vec::new();
    let mut blocks: Vec<[usize; 3]> = Vec::new();
    for x in (0..nb).step_by(size) {
        for y in (0..nb).step_by(size) {
            for z in (0..nb).step_by(size) {
                blocks.push([x, y, z]);
            }
        }
    }
    let mut near_bricks: Vec<[usize; 3]> = Vec::new();
    loop {
        // The node box of each block and its centre.
        let boxes: Vec<([usize; 3], [usize; 3])> = blocks
            .iter()
            .map(|b| {
                let l = b.map(|v| v * BRICK);
                let u = b.map(|v| ((v + size) * BRICK).min(n1) - 1);
                (l, u)
            })
            .collect();
        let centres: Vec<[f64; 3]> = boxes
            .iter()
            .map(|(l, u)| {
                let a = node(l[0], l[1], l[2]);
                let b = node(u[0], u[1], u[2]);
                std::array::from_fn(|k| 0.5 * (a[k] + b[k]))
            })
            .collect();
        let values: Vec<f64> = call(&centres, stats)?.into_iter().map(map).collect();
        let mut next = Vec::new();
        for ((b, (l, u)), v) in blocks.iter().zip(&boxes).zip(values) {
            let a = node(l[0], l[1], l[2]);
            let c = node(u[0], u[1], u[2]);
            let r = 0.5
                * (0..3)
                    .map(|k| (c[k] - a[k]) * (c[k] - a[k]))
                    .sum::<f64>()
                    .sqrt();
            // In the normalised frame: the conditioned value against the bound over the block.
            if v.abs() > (lipschitz * r * s + t) * (1.0 + 1e-9) {
                far_blocks.push((*b, size, v < 0.0));
            } else if size == 1 {
                near_bricks.push(*b);
            } else {
                let half = size / 2;
                for dx in [0, half] {
                    for dy in [0, half] {
                        for dz in [0, half] {
                            let q = [b[0] + dx, b[1] + dy, b[2] + dz];
                            if q.iter().all(|&v| v < nb) {
                                next.push(q);
                            }
                        }
                    }
                }
            }
        }
        if size == 1 || next.is_empty() {
            break;
        }
        size /= 2;
        blocks = next;
    }
    // The sign of every brick not near, from the block that settled it.
    let mut negative = vec![false; nb * nb * nb];
    for (b, size, neg) in &far_blocks {
        if !neg {
            continue;
        }
        for x in b[0]..(b[0] + size).min(nb) {
            for y in b[1]..(b[1] + size).min(nb) {
                for z in b[2]..(b[2] + size).min(nb) {
                    negative[(x * nb + y) * nb + z] = true;
                }
            }
        }
    }
    // Stored: the near bricks and those within `reach` nodes of one.
    let rb = reach.div_ceil(BRICK);
    let mut stored = vec![false; nb * nb * nb];
    for b in &near_bricks {
        for x in b[0].saturating_sub(rb)..=(b[0] + rb).min(nb - 1) {
            for y in b[1].saturating_sub(rb)..=(b[1] + rb).min(nb - 1) {
                for z in b[2].saturating_sub(rb)..=(b[2] + rb).min(nb - 1) {
                    stored[(x * nb + y) * nb + z] = true;
                }
            }
        }
    }
    let list: Vec<usize> = (0..stored.len()).filter(|&b| stored[b]).collect();
    let list_len = list.len();
    let b3 = BRICK * BRICK * BRICK;
    // Priced before the field runs on them: the bricks' values, held twice while the band
    // is assembled.
    let _reserved = ponq_mesh::memory::reserve(
        (list.len() * b3 * 16) as u64,
        &format!(
            "the field's values near its surface ({} bricks of 8^3 nodes at {n1}^3)",
            list.len()
        ),
        "take a coarser resolution",
    )?;
    let mut bricks = Vec::with_capacity(list.len());
    // Bricks in groups, so that a batch holds many bricks' nodes.
    let per_group = (batch / b3).clamp(1, 4096);
    for group in list.chunks(per_group) {
        let mut pts = Vec::with_capacity(group.len() * b3);
        let mut slots = Vec::with_capacity(group.len() * b3);
        for (g, &b) in group.iter().enumerate() {
            let base = [b / (nb * nb), (b / nb) % nb, b % nb].map(|v| v * BRICK);
            for x in 0..BRICK {
                for y in 0..BRICK {
                    for z in 0..BRICK {
                        let [i, j, k] = [base[0] + x, base[1] + y, base[2] + z];
                        if i < n1 && j < n1 && k < n1 {
                            pts.push(node(i, j, k));
                            slots.push(g * b3 + (x * BRICK + y) * BRICK + z);
                        }
                    }
                }
            }
        }
        let values = call(&pts, stats)?;
        let mut block = vec![0.0; group.len() * b3];
        for (slot, v) in slots.into_iter().zip(values) {
            block[slot] = map(v);
        }
        for (g, &b) in group.iter().enumerate() {
            bricks.push((b, block[g * b3..(g + 1) * b3].to_vec()));
        }
    }
    // The steepest slope between neighbours of the evaluated bricks near the surface.
    let cell = 2.0 / frame.n as f64;
    let near = 4.0 * cell;
    // A histogram of the slopes (hundredths up to 20; past that, the last bin), so that a few
    // spikes of a learned field do not widen the bound for all of it: the 99.9th percentile.
    const BINS: usize = 2001;
    let mut hist = vec![0u64; BINS];
    for (b, v) in &bricks {
        let base = [b / (nb * nb), (b / nb) % nb, b % nb].map(|c| c * BRICK);
        // Nodes of the brick inside the grid (the rest is padding).
        let lim = base.map(|c| (n1 - c).min(BRICK));
        for x in 0..lim[0] {
            for y in 0..lim[1] {
                for z in 0..lim[2] {
                    let a = v[(x * BRICK + y) * BRICK + z];
                    for (dx, dy, dz) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                        let (x2, y2, z2) = (x + dx, y + dy, z + dz);
                        if x2 >= lim[0] || y2 >= lim[1] || z2 >= lim[2] {
                            continue;
                        }
                        let b = v[(x2 * BRICK + y2) * BRICK + z2];
                        if a.abs() < near || b.abs() < near {
                            let slope = (a - b).abs() / cell;
                            hist[((slope * 100.0) as usize).min(BINS - 1)] += 1;
                        }
                    }
                }
            }
        }
    }
    let total: u64 = hist.iter().sum();
    let mut seen = 0.0;
    let mut acc = 0u64;
    for (i, &n) in hist.iter().enumerate() {
        acc += n;
        if acc * 1000 >= total * 999 {
            seen = (i + 1) as f64 / 100.0;
            break;
        }
    }
    let grid = BandGrid::from_bricks(dims, t, reach, bricks, |b| negative[b])?;
    stats.stored_bricks = list_len;
    Ok((grid, seen))
}
