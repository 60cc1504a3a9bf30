//! The encoder at the cells near the surface only (inference on the CPU).
//!
//! Inference keeps the network's output at the cells near the surface, a small part of a grid
//! (a few percent at 129^3). A cell's features after the encoder depend on its neighbourhood
//! only: the `L` padded 3x3x3 layers reach `L` cells on each side, the unpadded 2x2x2 input
//! layer the cell's own eight nodes. So the encoder needs layer `l`'s output only on the
//! needed cells dilated `L - l` times ([`ActiveSets`]), and each layer here computes exactly
//! those rows: an im2col GEMM (the same packed weights, row layout and per-plane GEMMs as
//! [`super::kernels::conv_forward`]) whose im2col rows gather the neighbours' feature rows
//! through a cell -> row index, and put zeros where the dense layer reads its zero padding.
//!
//! Why by hand: this is a gather-GEMM on the dense layers' own packed weights; sparse
//! convolution crates target GPUs or other layouts, and Burn has no sparse convolution.
//!
//! Invariants (checked with `assert!`, programming errors, never user input): every in-grid
//! neighbour of a level's cell is in the level below ([`ActiveSets`] builds them so), and the
//! slices' lengths match the shapes.

use rayon::prelude::*;

use super::kernels::{Act, Precision, Weights, epilogue, tile_rows};

/// No row: the cell is not active at this level.
const ABSENT: u32 = u32::MAX;

/// The cells each encoder level is computed at, for one grid of `dims` cells.
///
/// Invariants: `levels.len() == layers + 1`; `levels[layers]` is the needed cells (sorted,
/// without repeats); `levels[l]` is `levels[l + 1]` dilated by one cell in each of the 26
/// directions (kept inside the grid), sorted, without repeats. `levels[0]` is where the input
/// layer runs, `levels[l]` for `l >= 1` where encoder layer `l` runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ActiveSets {
    /// Cells per axis.
    pub dims: [usize; 3],
    /// C-order cell indices per level, from the input layer's to the last layer's.
    pub levels: Vec<Vec<u32>>,
}

impl ActiveSets {
    /// The levels for `layers` padded 3x3x3 layers whose last output is needed at `needed`
    /// (C-order cell indices; any order, repeats allowed).
    ///
    /// # Panics
    /// A needed cell outside the grid, or a grid of `u32::MAX` cells or more (the caller
    /// checks both).
    pub fn new(dims: [usize; 3], needed: &[usize], layers: usize) -> Self {
        let total: usize = dims.iter().product();
        assert!(
            total < ABSENT as usize,
            "grid of {dims:?} cells is too large"
        );
        let mut mask = vec![false; total];
        for &c in needed {
            assert!(c < total, "cell {c} outside the grid of {dims:?} cells");
            mask[c] = true;
        }
        let list = |mask: &[bool]| -> Vec<u32> {
            (0..total as u32).filter(|&c| mask[c as usize]).collect()
        };
        let mut levels = vec![list(&mask)];
        for _ in 0..layers {
            let prev = levels.last().map(Vec::as_slice).unwrap_or_default();
            let mut grown = mask.clone();
            for &c in prev {
                let [i, j, k] = coords(c as usize, dims);
                for a in i.saturating_sub(1)..=(i + 1).min(dims[0] - 1) {
                    for b in j.saturating_sub(1)..=(j + 1).min(dims[1] - 1) {
                        let row = (a * dims[1] + b) * dims[2];
                        grown[row + k.saturating_sub(1)..=row + (k + 1).min(dims[2] - 1)]
                            .fill(true);
                    }
                }
            }
            mask = grown;
            levels.push(list(&mask));
        }
        levels.reverse();
        Self { dims, levels }
    }

    /// Cell -> row of `levels[level]` ([`ABSENT`] for cells not in it).
    fn index(&self, level: usize) -> Vec<u32> {
        let mut idx = vec![ABSENT; self.dims.iter().product()];
        for (r, &c) in self.levels[level].iter().enumerate() {
            idx[c as usize] = r as u32;
        }
        idx
    }

    /// Row of each of `cells` in the last level (`None` if one is not in it).
    pub fn rows_of(&self, cells: &[usize]) -> Option<Vec<usize>> {
        let last = self.levels.len() - 1;
        let idx = self.index(last);
        cells
            .iter()
            .map(|&c| {
                idx.get(c)
                    .copied()
                    .filter(|&r| r != ABSENT)
                    .map(|r| r as usize)
            })
            .collect()
    }
}

fn coords(c: usize, dims: [usize; 3]) -> [usize; 3] {
    [
        c / (dims[1] * dims[2]),
        (c / dims[2]) % dims[1],
        c % dims[2],
    ]
}

/// `act(im2col GEMM + bias)` at the `m = dst.len()` rows whose im2col rows `fill` writes
/// (`fill(cell, row)` with `row.len() == kd`), weights `packed: [kd, cout]`, summed one
/// kernel plane (`kd / planes` columns) at a time as the dense layers do
/// ([`super::kernels::conv_forward`]), so that both take the same precision per GEMM.
#[allow(clippy::too_many_arguments)]
fn gather_gemm(
    dst: &[u32],
    kd: usize,
    planes: usize,
    packed: &[f32],
    bias: &[f32],
    act: Act,
    prec: Precision,
    fill: impl Fn(usize, &mut [f32]) + Sync,
) -> Vec<f32> {
    let cout = bias.len();
    assert_eq!(packed.len(), kd * cout);
    let mut y = vec![0.0f32; dst.len() * cout];
    if y.is_empty() {
        return y;
    }
    let tile = tile_rows(kd);
    let pd = kd / planes;
    let weights: Vec<Weights> = (0..planes)
        .map(|p| Weights::new(&packed[p * pd * cout..(p + 1) * pd * cout], pd, cout, prec))
        .collect();
    y.par_chunks_mut(tile * cout).enumerate().for_each_init(
        || vec![0.0f32; tile * kd],
        |col, (t, yt)| {
            let m = yt.len() / cout;
            for (r, &c) in dst[t * tile..t * tile + m].iter().enumerate() {
                fill(c as usize, &mut col[r * kd..(r + 1) * kd]);
            }
            for (p, wp) in weights.iter().enumerate() {
                wp.mul_acc(&col[p * pd..m * kd], kd, yt, p > 0);
            }
            epilogue(yt, cout, bias, None, act);
        },
    );
    y
}

/// The encoder at the cells of `sets`: the unpadded 2x2x2 input layer on the node values
/// `nodes` (`(dims + 1)` per axis, one channel, C order) at `levels[0]`, then each padded
/// 3x3x3 layer `l` at `levels[l]`. `layers[0]` is the input layer; each entry is `(packed
/// weight, bias)` with the weight packed by [`super::kernels::pack_weight`] (not flipped) and
/// `bias.len()` output channels. Returns the features `[levels[L].len(), width]` of the last
/// level's cells, in its order. GEMMs in `prec`.
pub fn encode(
    nodes: &[f32],
    sets: &ActiveSets,
    layers: &[(Vec<f32>, Vec<f32>)],
    act: Act,
    prec: Precision,
) -> Vec<f32> {
    let dims = sets.dims;
    let n = dims.map(|d| d + 1);
    assert_eq!(nodes.len(), n.iter().product::<usize>());
    assert_eq!(layers.len(), sets.levels.len());
    // The input layer: the eight nodes of each cell, in the kernel's (a, b, c) order.
    let (w0, b0) = &layers[0];
    let mut x = gather_gemm(&sets.levels[0], 8, 2, w0, b0, act, prec, |cell, row| {
        let [i, j, k] = coords(cell, dims);
        for a in 0..2 {
            for b in 0..2 {
                let base = ((i + a) * n[1] + j + b) * n[2] + k;
                row[(a * 2 + b) * 2] = nodes[base];
                row[(a * 2 + b) * 2 + 1] = nodes[base + 1];
            }
        }
    });
    let mut cin = b0.len();
    for (l, (w, b)) in layers.iter().enumerate().skip(1) {
        let src = sets.index(l - 1);
        let input = &x;
        let kd = 27 * cin;
        let y = gather_gemm(&sets.levels[l], kd, 3, w, b, act, prec, |cell, row| {
            let [i, j, k] = coords(cell, dims);
            for a in 0..3 {
                for bb in 0..3 {
                    for c in 0..3 {
                        let seg = &mut row[((a * 3 + bb) * 3 + c) * cin..][..cin];
                        let (ii, jj, kk) = (i + a, j + bb, k + c);
                        // Padding: the neighbour (ii - 1, jj - 1, kk - 1) is outside the grid.
                        if ii == 0
                            || jj == 0
                            || kk == 0
                            || ii > dims[0]
                            || jj > dims[1]
                            || kk > dims[2]
                        {
                            seg.fill(0.0);
                            continue;
                        }
                        let nb = ((ii - 1) * dims[1] + jj - 1) * dims[2] + kk - 1;
                        let r = src[nb];
                        assert!(r != ABSENT, "sparse encoder: neighbour not computed");
                        let r = r as usize;
                        seg.copy_from_slice(&input[r * cin..(r + 1) * cin]);
                    }
                }
            }
        });
        cin = b.len();
        x = y;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::super::kernels::{ConvShape, conv_forward, pack_weight};
    use super::*;

    fn rand(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            })
            .collect()
    }

    /// The dense encoder (input layer, then `layers` padded 3x3x3 layers) on the whole grid.
    fn dense(
        nodes: &[f32],
        dims: [usize; 3],
        params: &[(Vec<f32>, Vec<f32>)],
        act: Act,
        prec: Precision,
    ) -> Vec<f32> {
        let n = dims.map(|d| d + 1);
        let s0 = ConvShape {
            batch: 1,
            dims: n,
            cin: 1,
            cout: params[0].1.len(),
            k: 2,
            pad: 0,
        };
        let mut x = conv_forward(
            nodes,
            &s0,
            &pack_weight(&params[0].0, &s0, false),
            Some(&params[0].1),
            act,
            prec,
        );
        let mut cin = s0.cout;
        for (w, b) in &params[1..] {
            let s = ConvShape {
                batch: 1,
                dims,
                cin,
                cout: b.len(),
                k: 3,
                pad: 1,
            };
            x = conv_forward(&x, &s, &pack_weight(w, &s, false), Some(b), act, prec);
            cin = b.len();
        }
        x
    }

    #[test]
    fn sparse_encoder_equals_the_dense_one_at_the_needed_cells() {
        let act = Act::Leaky(0.01);
        for (case, (dims, width, layers)) in [
            ([7, 5, 6], 8, 4),
            ([9, 9, 9], 16, 2),
            ([4, 11, 3], 5, 3),
            ([2, 2, 2], 4, 4),
        ]
        .into_iter()
        .enumerate()
        {
            let seed = case as u64 * 100;
            let n = dims.map(|d| d + 1);
            let nodes = rand(n.iter().product(), seed);
            let mut raw = vec![(rand(width * 8, seed + 1), rand(width, seed + 2))];
            for l in 0..layers {
                raw.push((
                    rand(width * width * 27, seed + 3 + l as u64),
                    rand(width, seed + 50 + l as u64),
                ));
            }
            for prec in [Precision::F32, Precision::Bf16] {
                let want = dense(&nodes, dims, &raw, act, prec);
                let total: usize = dims.iter().product();
                // Needed: a sparse, repeated, unordered subset incl. grid corners.
                let needed: Vec<usize> = (0..total)
                    .rev()
                    .filter(|c| c % 7 == 0 || c % 11 == 3)
                    .chain([0, total - 1, 0])
                    .collect();
                let sets = ActiveSets::new(dims, &needed, layers);
                assert_eq!(sets.levels.len(), layers + 1);
                for w in sets.levels.windows(2) {
                    assert!(
                        w[1].iter().all(|c| w[0].binary_search(c).is_ok()),
                        "levels nest"
                    );
                }
                let packed: Vec<(Vec<f32>, Vec<f32>)> = raw
                    .iter()
                    .enumerate()
                    .map(|(l, (w, b))| {
                        let (cin, k) = if l == 0 { (1, 2) } else { (width, 3) };
                        let s = ConvShape {
                            batch: 1,
                            dims,
                            cin,
                            cout: width,
                            k,
                            pad: 0,
                        };
                        (pack_weight(w, &s, false), b.clone())
                    })
                    .collect();
                let got = encode(&nodes, &sets, &packed, act, prec);
                let rows = sets
                    .rows_of(&needed)
                    .expect("needed cells are in the last level");
                for (&c, &r) in needed.iter().zip(&rows) {
                    for ch in 0..width {
                        let (g, w) = (got[r * width + ch], want[c * width + ch]);
                        assert!(
                            (g - w).abs() <= 1e-5 * (1.0 + w.abs()),
                            "case {case} {prec:?} cell {c} ch {ch}: {g} vs {w}"
                        );
                    }
                }
                // Fewer rows than the grid at the last level unless everything is needed.
                assert_eq!(sets.levels[layers].len(), {
                    let mut u = needed.clone();
                    u.sort_unstable();
                    u.dedup();
                    u.len()
                });
            }
        }
    }

    #[test]
    fn dilation_stays_in_the_grid_and_grows_by_one_cell() {
        let sets = ActiveSets::new([5, 5, 5], &[0], 2);
        // One dilation of the corner cell: 2x2x2 cells; two: 3x3x3.
        assert_eq!(sets.levels[2], vec![0]);
        assert_eq!(sets.levels[1].len(), 8);
        assert_eq!(sets.levels[0].len(), 27);
        assert!(sets.rows_of(&[1]).is_none(), "cell 1 is not needed");
    }
}
