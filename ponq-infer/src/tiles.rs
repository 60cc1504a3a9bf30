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
    let mut pred = Prediction::zeros(cells, net.points_per_cell());
    let starts = |n: usize| -> Vec<(usize, usize)> {
        (0..n)
            .step_by(tile)
            .map(|a| (a, (a + tile).min(n)))
            .collect()
    };
    if let Some(n) = needed
        && n.len() != cells.iter().product::<usize>()
    {
        bail!(
            "the cell mask has {} flags for {} cells",
            n.len(),
            cells.iter().product::<usize>()
        );
    }
    let (sx, sy, sz) = (starts(cells[0]), starts(cells[1]), starts(cells[2]));
    let mut cores = Vec::new();
    for &(ax, bx) in &sx {
        for &(ay, by) in &sy {
            for &(az, bz) in &sz {
                let core = [(ax, bx), (ay, by), (az, bz)];
                let wanted = needed.is_none_or(|n| {
                    (ax..bx).any(|i| {
                        (ay..by).any(|j| {
                            let row = (i * cells[1] + j) * cells[2];
                            n[row + az..row + bz].iter().any(|&f| f)
                        })
                    })
                });
                if wanted {
                    cores.push(core);
                }
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
        if let Some(n) = needed {
            // Decoders only on the needed cells of the core (the encoder runs on the tile).
            let tc: [usize; 3] = std::array::from_fn(|a| m[a] - 1);
            let (mut local, mut global) = (Vec::new(), Vec::new());
            for i in core[0].0..core[0].1 {
                for j in core[1].0..core[1].1 {
                    for k in core[2].0..core[2].1 {
                        let g = (i * cells[1] + j) * cells[2] + k;
                        if n[g] {
                            local.push(((i - lo[0]) * tc[1] + (j - lo[1])) * tc[2] + (k - lo[2]));
                            global.push(g);
                        }
                    }
                }
            }
            let out = net.forward_cells(x, &gf, &local)?;
            pred.scatter(&Prediction::from_output(&out, 0)?, &global)?;
        } else {
            let out = net.forward(x, &gf);
            let t = Prediction::from_output(&out, 0)?;
            pred.paste(
                &t,
                std::array::from_fn(|a| core[a].0 - lo[a]),
                std::array::from_fn(|a| core[a].1 - lo[a]),
                lo,
            )?;
        }
        progress(done + 1, total);
    }
    Ok((pred, total))
}
