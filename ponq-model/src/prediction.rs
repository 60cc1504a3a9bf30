//! A network prediction copied off the device, and its conversion to a `ponq-mesh` [`Ponq`].

use ponq_mesh::Ponq;
use ponq_mesh::quadric::Quadric;

use crate::error::{ModelError, Result};
use crate::model::PonqOutput;

/// Per-cell outputs of one grid, in C order over `cells`.
///
/// Invariants: with `C = cells[0] * cells[1] * cells[2]` and `P = points_per_cell`,
/// `points`, `vstars`, `normals` have `C * P * 3` values, `cholesky` has `C * P * 6` and
/// `occupancy` has `C`.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Cells per axis.
    pub cells: [usize; 3],
    /// Points per cell `P`.
    pub points_per_cell: usize,
    /// Absolute point positions.
    pub points: Vec<f32>,
    /// Absolute v*.
    pub vstars: Vec<f32>,
    /// Raw normals.
    pub normals: Vec<f32>,
    /// Upper-triangular entries of `U` (`A = U U^T`).
    pub cholesky: Vec<f32>,
    /// Occupancy probabilities.
    pub occupancy: Vec<f32>,
}

fn to_vec<const D: usize>(t: burn::Tensor<D>) -> Result<Vec<f32>> {
    t.into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .map_err(|e| ModelError::Tensor(format!("{e:?}")))
}

impl Prediction {
    /// An all-zero prediction over `cells` (to be filled tile by tile).
    pub fn zeros(cells: [usize; 3], points_per_cell: usize) -> Self {
        let c = cells.iter().product::<usize>();
        let p = points_per_cell;
        Self {
            cells,
            points_per_cell: p,
            points: vec![0.0; c * p * 3],
            vstars: vec![0.0; c * p * 3],
            normals: vec![0.0; c * p * 3],
            cholesky: vec![0.0; c * p * 6],
            occupancy: vec![0.0; c],
        }
    }

    /// Copies grid `b` of a batch output to the host.
    pub fn from_output(out: &PonqOutput, b: usize) -> Result<Self> {
        let [batch, c, p, _] = out.points.dims();
        if b >= batch {
            return Err(ModelError::Invalid(format!(
                "batch index {b} >= batch size {batch}"
            )));
        }
        let take4 = |t: &burn::Tensor<4>| to_vec(t.clone().narrow(0, b, 1));
        let pred = Self {
            cells: out.cells,
            points_per_cell: p,
            points: take4(&out.points)?,
            vstars: take4(&out.vstars)?,
            normals: take4(&out.normals)?,
            cholesky: take4(&out.cholesky)?,
            occupancy: to_vec(out.occupancy.clone().narrow(0, b, 1))?,
        };
        debug_assert_eq!(pred.occupancy.len(), c);
        Ok(pred)
    }

    /// Number of cells.
    pub fn num_cells(&self) -> usize {
        self.cells.iter().product()
    }

    /// Cell coordinates of C-order index `c`.
    pub fn cell_coords(&self, c: usize) -> [u32; 3] {
        let [_, n2, n3] = self.cells;
        [
            (c / (n2 * n3)) as u32,
            ((c / n3) % n2) as u32,
            (c % n3) as u32,
        ]
    }

    /// Copies the cells of `tile` (a prediction over a sub-block) whose tile coordinates lie
    /// in `keep_lo..keep_hi` to this prediction, at tile position + `offset`.
    pub fn paste(
        &mut self,
        tile: &Prediction,
        keep_lo: [usize; 3],
        keep_hi: [usize; 3],
        offset: [usize; 3],
    ) -> Result<()> {
        if tile.points_per_cell != self.points_per_cell {
            return Err(ModelError::Invalid("tile with another P".into()));
        }
        for i in keep_lo[0]..keep_hi[0] {
            for j in keep_lo[1]..keep_hi[1] {
                for k in keep_lo[2]..keep_hi[2] {
                    let (gi, gj, gk) = (i + offset[0], j + offset[1], k + offset[2]);
                    if gi >= self.cells[0] || gj >= self.cells[1] || gk >= self.cells[2] {
                        return Err(ModelError::Invalid(format!(
                            "tile cell ({gi},{gj},{gk}) outside the grid {:?}",
                            self.cells
                        )));
                    }
                    let src = (i * tile.cells[1] + j) * tile.cells[2] + k;
                    let dst = (gi * self.cells[1] + gj) * self.cells[2] + gk;
                    self.copy_cell(tile, src, dst);
                }
            }
        }
        Ok(())
    }

    /// Copies cell `i` of `part` (a prediction over a list of cells, e.g. from
    /// [`crate::PonqNet::forward_cells`]) to cell `dst[i]` (C order) of this prediction.
    ///
    /// # Errors
    /// Another `P`, `dst` not one index per cell of `part`, or an index outside the grid.
    pub fn scatter(&mut self, part: &Prediction, dst: &[usize]) -> Result<()> {
        if part.points_per_cell != self.points_per_cell {
            return Err(ModelError::Invalid("part with another P".into()));
        }
        if dst.len() != part.num_cells() {
            return Err(ModelError::Invalid(format!(
                "{} destinations for {} cells",
                dst.len(),
                part.num_cells()
            )));
        }
        let n = self.num_cells();
        if let Some(&d) = dst.iter().find(|&&d| d >= n) {
            return Err(ModelError::Invalid(format!(
                "cell {d} outside the grid {:?}",
                self.cells
            )));
        }
        for (src, &dst) in dst.iter().enumerate() {
            self.copy_cell(part, src, dst);
        }
        Ok(())
    }

    /// Copies every output of cell `src` of `from` (same `P`) to cell `dst` of this one.
    fn copy_cell(&mut self, from: &Prediction, src: usize, dst: usize) {
        let p = self.points_per_cell;
        let copy = |d: &mut Vec<f32>, s: &Vec<f32>, w: usize| {
            d[dst * w..(dst + 1) * w].copy_from_slice(&s[src * w..(src + 1) * w]);
        };
        copy(&mut self.points, &from.points, 3 * p);
        copy(&mut self.vstars, &from.vstars, 3 * p);
        copy(&mut self.normals, &from.normals, 3 * p);
        copy(&mut self.cholesky, &from.cholesky, 6 * p);
        copy(&mut self.occupancy, &from.occupancy, 1);
    }

    /// Cells kept for meshing: occupancy above `threshold` and, when given, `close[c]`.
    pub fn kept_cells(&self, threshold: f32, close: Option<&[bool]>) -> Result<Vec<usize>> {
        if let Some(m) = close
            && m.len() != self.num_cells()
        {
            return Err(ModelError::Invalid(format!(
                "close mask has {} cells, prediction {}",
                m.len(),
                self.num_cells()
            )));
        }
        Ok((0..self.num_cells())
            .filter(|&c| self.occupancy[c] > threshold && close.is_none_or(|m| m[c]))
            .collect())
    }

    /// The PoNQ of the given cells (all `P` points of each), with the cell of every point
    /// (for PoNQ-lite / coarsening). Quadrics are `Q(x) = (x - v*)^T U U^T (x - v*)`.
    pub fn to_ponq(&self, cells: &[usize]) -> Result<(Ponq, Vec<[u32; 3]>)> {
        let p = self.points_per_cell;
        let n = cells.len() * p;
        let mut points = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        let mut quadrics = Vec::with_capacity(n);
        let mut vstars = Vec::with_capacity(n);
        let mut cell_of = Vec::with_capacity(n);
        let v3 = |v: &[f32], i: usize| [v[3 * i] as f64, v[3 * i + 1] as f64, v[3 * i + 2] as f64];
        for &c in cells {
            if c >= self.num_cells() {
                return Err(ModelError::Invalid(format!("cell {c} out of range")));
            }
            for k in 0..p {
                let i = c * p + k;
                let u: [f64; 6] = std::array::from_fn(|t| self.cholesky[6 * i + t] as f64);
                let vs = v3(&self.vstars, i);
                points.push(v3(&self.points, i));
                normals.push(v3(&self.normals, i));
                vstars.push(vs);
                quadrics.push(Quadric::from_a_vstar(Quadric::a_from_upper(u), vs));
                cell_of.push(self.cell_coords(c));
            }
        }
        let ponq = Ponq::new(points, normals, quadrics, Some(vstars))
            .map_err(|e| ModelError::Invalid(format!("network output: {e}")))?;
        Ok((ponq, cell_of))
    }
}
