//! The network over a grid of any size, in tiles whose margins (the encoder's reach) make the
//! result identical to one pass over the whole grid, so peak memory is bounded by the tile.

use anyhow::{Result, bail};
use burn::prelude::*;
use ponq_model::{GridFrame, PonqNet, Prediction};

use crate::frame::Frame;

/// Runs the network over `grid` (normalised values, already scaled for the network) in
/// tiles; returns the prediction over all cells and the number of tiles run.
///
/// With `needed` (one flag per cell, C order), only the needed cells get a prediction: a tile
/// whose kept core holds no needed cell is not run, and in the others the decoders run on
/// the needed cells only ([`PonqNet::forward_cells`]); the other cells keep a zero prediction
/// (occupancy 0), the needed ones get the values of one pass over the whole grid.
/// Inference passes the cells near the surface (the only ones it can keep).
// Grid, network, tiling and device are independent inputs; a struct would only rename them.
#[allow(clippy::too_many_arguments)]
pub fn predict_tiled(
    net: &PonqNet,
    input: &[f32],
    frame: &Frame,
    margin: usize,
    tile: usize,
    authors_cell_base: bool,
    needed: Option<&[bool]>,
    device: &Device,
    mut progress: impl FnMut(usize, usize),
) -> Result<(Prediction, usize)> {
    let cells = frame.cells;
    let nodes = cells.map(|c| c + 1);
    let tile = tile.max(1);
    if let Some(n) = needed {
        if n.len() != cells.iter().product::<usize>() {
            bail!(
                "the cell mask has {} flags for {} cells",
                n.len(),
                cells.iter().product::<usize>()
            );
        }
        let list: Vec<usize> = (0..n.len()).filter(|&c| n[c]).collect();
        let read = |lo: [usize; 3], hi: [usize; 3]| {
            let mut data = Vec::with_capacity((0..3).map(|a| hi[a] - lo[a] + 1).product());
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    let row = (i * nodes[1] + j) * nodes[2];
                    data.extend_from_slice(&input[row + lo[2]..=row + hi[2]]);
                }
            }
            data
        };
        let (part, total) = predict_cells(
            net,
            read,
            frame,
            margin,
            tile,
            authors_cell_base,
            &list,
            device,
            progress,
        )?;
        let mut pred = Prediction::zeros(cells, net.points_per_cell());
        pred.scatter(&part, &list)?;
        return Ok((pred, total));
    }
    let mut pred = Prediction::zeros(cells, net.points_per_cell());
    let starts = |n: usize| -> Vec<(usize, usize)> {
        (0..n)
            .step_by(tile)
            .map(|a| (a, (a + tile).min(n)))
            .collect()
    };
    let (sx, sy, sz) = (starts(cells[0]), starts(cells[1]), starts(cells[2]));
    let mut cores = Vec::new();
    for &(ax, bx) in &sx {
        for &(ay, by) in &sy {
            for &(az, bz) in &sz {
                cores.push([(ax, bx), (ay, by), (az, bz)]);
            }
        }
    }
    let total = cores.len();
    for (done, core) in cores.into_iter().enumerate() {
        let lo: [usize; 3] = std::array::from_fn(|a| core[a].0.saturating_sub(margin));
        let hi: [usize; 3] = std::array::from_fn(|a| (core[a].1 + margin).min(cells[a]));
        let m: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a] + 1);
        let mut data = Vec::with_capacity(m[0] * m[1] * m[2]);
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                let row = (i * nodes[1] + j) * nodes[2];
                data.extend_from_slice(&input[row + lo[2]..=row + hi[2]]);
            }
        }
        let x = Tensor::<1>::from_data(TensorData::new(data, [m[0] * m[1] * m[2]]), device)
            .reshape([1, 1, m[0], m[1], m[2]]);
        let mut gf = GridFrame::crop(frame.n, lo);
        gf.authors_cell_base = authors_cell_base;
        let out = net.forward(x, &gf);
        let t = Prediction::from_output(&out, 0)?;
        pred.paste(
            &t,
            std::array::from_fn(|a| core[a].0 - lo[a]),
            std::array::from_fn(|a| core[a].1 - lo[a]),
            lo,
        )?;
        progress(done + 1, total);
    }
    Ok((pred, total))
}

/// Runs the network on the cells `needed` (flat C-order indices over `frame.cells`,
/// ascending) only, tile by tile: a tile of `tile` cells per side (plus the encoder's
/// `margin`) runs when its core holds a needed cell, its input read by `read(lo, hi)` (the
/// node block `lo..=hi`, C order, values scaled for the network), the decoders on the
/// needed cells only ([`PonqNet::forward_cells`]). Returns the prediction over the list
/// (cell `r` of the result is `needed[r]`; the values of one pass over the whole grid) and
/// the number of tiles run. Nothing is allocated per cell of the grid: memory follows the
/// list and the tile.
///
/// # Errors
/// `needed` not ascending or outside the grid; the network's errors.
#[allow(clippy::too_many_arguments)]
pub fn predict_cells(
    net: &PonqNet,
    read: impl Fn([usize; 3], [usize; 3]) -> Vec<f32>,
    frame: &Frame,
    margin: usize,
    tile: usize,
    authors_cell_base: bool,
    needed: &[usize],
    device: &Device,
    mut progress: impl FnMut(usize, usize),
) -> Result<(Prediction, usize)> {
    let cells = frame.cells;
    let tile = tile.max(1);
    let total_cells = cells.iter().product::<usize>();
    if needed.windows(2).any(|w| w[0] >= w[1]) || needed.last().is_some_and(|&c| c >= total_cells) {
        bail!("the needed cells must be ascending indices below {total_cells}");
    }
    let tiles_per = cells.map(|c| c.div_ceil(tile));
    let coords = |c: usize| {
        [
            c / (cells[1] * cells[2]),
            (c / cells[2]) % cells[1],
            c % cells[2],
        ]
    };
    // (tile, position in `needed`), tiles in C order, cells in C order within each.
    let mut order: Vec<(usize, u32)> = needed
        .iter()
        .enumerate()
        .map(|(r, &c)| {
            let x = coords(c).map(|v| v / tile);
            ((x[0] * tiles_per[1] + x[1]) * tiles_per[2] + x[2], r as u32)
        })
        .collect();
    order.sort_unstable();
    let mut groups: Vec<&[(usize, u32)]> = order.chunk_by(|a, b| a.0 == b.0).collect();
    groups.retain(|g| !g.is_empty());
    let total = groups.len();
    let mut pred = Prediction::zeros([needed.len(), 1, 1], net.points_per_cell());
    for (done, group) in groups.into_iter().enumerate() {
        let t = group[0].0;
        let tc = [
            t / (tiles_per[1] * tiles_per[2]),
            (t / tiles_per[2]) % tiles_per[1],
            t % tiles_per[2],
        ];
        let core: [(usize, usize); 3] =
            std::array::from_fn(|a| (tc[a] * tile, (tc[a] * tile + tile).min(cells[a])));
        let lo: [usize; 3] = std::array::from_fn(|a| core[a].0.saturating_sub(margin));
        let hi: [usize; 3] = std::array::from_fn(|a| (core[a].1 + margin).min(cells[a]));
        let m: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a] + 1);
        let data = read(lo, hi);
        if data.len() != m[0] * m[1] * m[2] {
            bail!("a tile's input has {} values for {m:?} nodes", data.len());
        }
        let x = Tensor::<1>::from_data(TensorData::new(data, [m[0] * m[1] * m[2]]), device)
            .reshape([1, 1, m[0], m[1], m[2]]);
        let mut gf = GridFrame::crop(frame.n, lo);
        gf.authors_cell_base = authors_cell_base;
        // Decoders only on the needed cells of the core (the encoder runs near them).
        let tcells: [usize; 3] = std::array::from_fn(|a| m[a] - 1);
        let (mut local, mut rows) = (Vec::with_capacity(group.len()), Vec::new());
        for &(_, r) in group {
            let [i, j, k] = coords(needed[r as usize]);
            local.push(((i - lo[0]) * tcells[1] + (j - lo[1])) * tcells[2] + (k - lo[2]));
            rows.push(r as usize);
        }
        let out = net.forward_cells(x, &gf, &local)?;
        pred.scatter(&Prediction::from_output(&out, 0)?, &rows)?;
        progress(done + 1, total);
    }
    Ok((pred, total))
}
