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

use anyhow::{Result, bail};
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

/// The band of a field `eval` (signed distances in the units of `opts.bounds`, negative
/// inside; called with batches of at most `batch` points, returns one value per point) on a
/// grid of `res` cells per side over `opts.bounds` (node `(i, j, k)` at `lo + h (i, j, k)`,
/// `h = (hi - lo) / res`), as [`crate::predict_band`] reads it for `encoder_layers`;
/// `lipschitz` bounds how fast the field changes (1 for a true distance; more for a neural
/// field that is not quite one). `progress(points_done)` after each batch.
///
/// # Errors
/// Bounds that do not make cubic cells, `res` below 1, a batch of 0, a `lipschitz` that is
/// not positive, `eval`'s errors, a result of the wrong length or with a non-finite value.
#[allow(clippy::too_many_arguments)]
pub fn field_band(
    res: usize,
    encoder_layers: usize,
    opts: &InferOptions,
    lipschitz: f64,
    batch: usize,
    mut eval: impl FnMut(&[[f64; 3]]) -> Result<Vec<f64>>,
    mut progress: impl FnMut(usize),
) -> Result<(BandGrid, FieldStats)> {
    if res == 0 || batch == 0 {
        bail!("a field needs at least 1 cell per side and a batch of at least 1 point");
    }
    if !(lipschitz > 0.0 && lipschitz.is_finite()) {
        bail!("lipschitz must be positive and finite, got {lipschitz}");
    }
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
    let t_user = t / s;
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
        let values = call(&centres, &mut stats)?;
        let mut next = Vec::new();
        for ((b, (l, u)), v) in blocks.iter().zip(&boxes).zip(values) {
            let a = node(l[0], l[1], l[2]);
            let c = node(u[0], u[1], u[2]);
            let r = 0.5
                * (0..3)
                    .map(|k| (c[k] - a[k]) * (c[k] - a[k]))
                    .sum::<f64>()
                    .sqrt();
            if v.abs() > (lipschitz * r + t_user) * (1.0 + 1e-9) {
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
    stats.stored_bricks = list.len();
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
        let values = call(&pts, &mut stats)?;
        let mut block = vec![0.0; group.len() * b3];
        for (slot, v) in slots.into_iter().zip(values) {
            block[slot] = v * s;
        }
        for (g, &b) in group.iter().enumerate() {
            bricks.push((b, block[g * b3..(g + 1) * b3].to_vec()));
        }
    }
    let grid = BandGrid::from_bricks(dims, t, reach, bricks, |b| negative[b])?;
    Ok((grid, stats))
}
