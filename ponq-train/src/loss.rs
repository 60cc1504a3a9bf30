//! The six PoNQ losses (SPEC section 5).
//!
//! Nearest-point assignments (each sample to its nearest predicted point among the points
//! of the ground-truth occupied cells, and each of those points to its nearest sample) are
//! kd-tree queries on host copies of the predicted points, outside the autodiff graph. The
//! differentiable parts then gather rows of the output tensors by those indices.
//!
//! Every term is a mean per shape, averaged over the shapes of the batch.

use anyhow::{Result, bail};
use burn::prelude::*;
use burn::tensor::activation::relu;
use ponq_mesh::nn::PointIndex;
use ponq_model::PonqOutput;

use crate::config::LossWeights;
use crate::data::Item;

/// Values of the terms of one step (unweighted) and the weighted total.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LossTerms {
    /// Weighted sum.
    pub total: f64,
    /// Squared Chamfer distance (both directions).
    pub cd: f64,
    /// Normal error.
    pub normals: f64,
    /// Quadric matrix error.
    pub a: f64,
    /// v* error along the sample normals.
    pub vstar: f64,
    /// v* regularisation.
    pub reg: f64,
    /// Occupancy error.
    pub occ: f64,
}

impl LossTerms {
    /// Names of the fields, in the order of [`LossTerms::values`].
    pub const NAMES: [&'static str; 7] = ["total", "cd", "normals", "a", "vstar", "reg", "occ"];

    /// The values in the order of [`LossTerms::NAMES`].
    pub fn values(&self) -> [f64; 7] {
        [
            self.total,
            self.cd,
            self.normals,
            self.a,
            self.vstar,
            self.reg,
            self.occ,
        ]
    }

    /// Running sum helper.
    pub fn add(&mut self, o: &LossTerms, w: f64) {
        self.total += w * o.total;
        self.cd += w * o.cd;
        self.normals += w * o.normals;
        self.a += w * o.a;
        self.vstar += w * o.vstar;
        self.reg += w * o.reg;
        self.occ += w * o.occ;
    }
}

/// The loss of a batch: the differentiable weighted total and the term values.
pub struct Loss {
    /// Weighted total (a one-element tensor).
    pub total: Tensor<1>,
    /// Term values.
    pub terms: LossTerms,
}

fn host(t: &Tensor<4>) -> Result<Vec<f32>> {
    t.clone()
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .map_err(|e| anyhow::anyhow!("reading predicted points: {e:?}"))
}

fn tensor1(v: Vec<f32>, device: &Device) -> Tensor<1> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn tensor2(v: Vec<[f32; 3]>, device: &Device) -> Tensor<2> {
    let n = v.len();
    let flat: Vec<f32> = v.into_iter().flatten().collect();
    Tensor::<1>::from_data(TensorData::new(flat, [n * 3]), device).reshape([n, 3])
}

fn index1(v: Vec<i64>, device: &Device) -> Tensor<1, Int> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn scalar(t: &Tensor<1>) -> f64 {
    f64::from(t.clone().into_scalar::<f32>())
}

/// Column `j` of an `[n, k]` tensor as `[n]`.
fn col(t: &Tensor<2>, j: usize) -> Tensor<1> {
    let n = t.dims()[0];
    t.clone().slice([0..n, j..j + 1]).reshape([n])
}

/// Computes the losses of `out` (a batch of network outputs) against `items` (same order).
pub fn compute(out: &PonqOutput, items: &[Item], w: &LossWeights) -> Result<Loss> {
    let [batch, cells, p, _] = out.points.dims();
    if items.len() != batch {
        bail!("{} items for a batch of {batch}", items.len());
    }
    let device = out.points.device();
    let pts = host(&out.points)?;
    let nb = batch as f32;

    // Assignments and the constant tensors of the gathers.
    let mut s_idx = Vec::new(); // per sample: flat index of its nearest point
    let mut s_pos = Vec::new();
    let mut s_nrm = Vec::new();
    let mut s_w = Vec::new();
    let mut q_idx = Vec::new(); // per point of an occupied cell: its flat index
    let mut q_near = Vec::new(); // its nearest sample
    let mut q_w = Vec::new();
    let mut o_gt = Vec::with_capacity(batch * cells);
    let mut o_w = Vec::with_capacity(batch * cells);
    for (b, it) in items.iter().enumerate() {
        if it.occupied.len() != cells || it.close.len() != cells {
            bail!(
                "item {b} has {} cells, the output {cells}",
                it.occupied.len()
            );
        }
        let close = it.close.iter().filter(|&&c| c).count();
        for c in 0..cells {
            o_gt.push(if it.occupied[c] { 1.0 } else { 0.0 });
            o_w.push(if it.close[c] {
                1.0 / (nb * close as f32)
            } else {
                0.0
            });
        }
        let cand: Vec<usize> = (0..cells)
            .filter(|&c| it.occupied[c])
            .flat_map(|c| (0..p).map(move |k| (b * cells + c) * p + k))
            .collect();
        if cand.is_empty() || it.samples.is_empty() {
            continue;
        }
        let cand_pos: Vec<[f64; 3]> = cand
            .iter()
            .map(|&g| std::array::from_fn(|a| f64::from(pts[3 * g + a])))
            .collect();
        let samples: Vec<[f64; 3]> = it.samples.iter().map(|s| s.map(f64::from)).collect();
        let (Some(cand_tree), Some(sample_tree)) =
            (PointIndex::new(&cand_pos), PointIndex::new(&samples))
        else {
            continue;
        };
        let ws = 1.0 / (nb * samples.len() as f32);
        for (i, (near, _)) in cand_tree.nearest_many(&samples).into_iter().enumerate() {
            s_idx.push(cand[near as usize] as i64);
            s_pos.push(it.samples[i]);
            s_nrm.push(it.normals[i]);
            s_w.push(ws);
        }
        let wq = 1.0 / (nb * cand.len() as f32);
        for (j, (near, _)) in sample_tree.nearest_many(&cand_pos).into_iter().enumerate() {
            q_idx.push(cand[j] as i64);
            q_near.push(it.samples[near as usize]);
            q_w.push(wq);
        }
    }

    let flat = batch * cells * p;
    let points = out.points.clone().reshape([flat, 3]);
    let vstars = out.vstars.clone().reshape([flat, 3]);
    let normals = out.normals.clone().reshape([flat, 3]);
    let chol = out.cholesky.clone().reshape([flat, 6]);

    // Occupancy over close cells.
    let occ_pred = out.occupancy.clone().reshape([batch * cells]);
    let err = occ_pred - tensor1(o_gt, &device);
    let occ = (relu((err.clone() * err).sub_scalar(w.occ_margin)) * tensor1(o_w, &device)).sum();

    let zero = || Tensor::<1>::zeros([1], &device);
    let (cd, ln, la, lv, reg) = if s_idx.is_empty() {
        (zero(), zero(), zero(), zero(), zero())
    } else {
        let ns = s_idx.len();
        let idx = index1(s_idx, &device);
        let sw = tensor1(s_w, &device);
        let s = tensor2(s_pos, &device);
        let n = tensor2(s_nrm, &device);
        // Samples -> nearest point.
        let d = points.clone().select(0, idx.clone()) - s.clone();
        let cd_s = ((d.clone() * d).sum_dim(1).reshape([ns]) * sw.clone()).sum();
        // Points -> nearest sample.
        let qi = index1(q_idx, &device);
        let qw = tensor1(q_w, &device);
        let nq = qw.dims()[0];
        let dq = points.clone().select(0, qi.clone()) - tensor2(q_near, &device);
        let cd_p = ((dq.clone() * dq).sum_dim(1).reshape([nq]) * qw.clone()).sum();
        // Normals.
        let dn = normals.select(0, idx.clone()) - n.clone();
        let ln = ((dn.clone() * dn).sum_dim(1).reshape([ns]) * sw.clone()).sum();
        // A = U U^T against n n^T (Frobenius).
        let u = chol.select(0, idx.clone());
        let (u0, u1, u2, u3, u4, u5) = (
            col(&u, 0),
            col(&u, 1),
            col(&u, 2),
            col(&u, 3),
            col(&u, 4),
            col(&u, 5),
        );
        let (n0, n1, n2) = (col(&n, 0), col(&n, 1), col(&n, 2));
        let a00 = u0.clone() * u0 + u1.clone() * u1.clone() + u2.clone() * u2.clone();
        let a01 = u1 * u3.clone() + u2.clone() * u4.clone();
        let a02 = u2 * u5.clone();
        let a11 = u3.clone() * u3 + u4.clone() * u4.clone();
        let a12 = u4 * u5.clone();
        let a22 = u5.clone() * u5;
        let sq = |t: Tensor<1>| t.clone() * t;
        let fro = sq(a00 - n0.clone() * n0.clone())
            + sq(a11 - n1.clone() * n1.clone())
            + sq(a22 - n2.clone() * n2.clone())
            + (sq(a01 - n0.clone() * n1.clone()) + sq(a02 - n0 * n2.clone()) + sq(a12 - n1 * n2))
                .mul_scalar(2.0);
        let la = (fro * sw.clone()).sum();
        // v* along the sample normal.
        let dv = vstars.clone().select(0, idx) - s;
        let along = (dv * n).sum_dim(1).reshape([ns]);
        let lv = (along.clone() * along * sw).sum();
        // v* regularisation over the points of occupied cells.
        let r = vstars.select(0, qi.clone()) - points.select(0, qi).detach();
        let reg = ((r.clone() * r).sum_dim(1).reshape([nq]) * qw).sum();
        (cd_s + cd_p, ln, la, lv, reg)
    };
    let total = cd.clone().mul_scalar(w.cd)
        + ln.clone().mul_scalar(w.normals)
        + la.clone().mul_scalar(w.a)
        + lv.clone().mul_scalar(w.vstar)
        + reg.clone().mul_scalar(w.reg)
        + occ.clone().mul_scalar(w.occ);
    let terms = LossTerms {
        total: scalar(&total),
        cd: scalar(&cd),
        normals: scalar(&ln),
        a: scalar(&la),
        vstar: scalar(&lv),
        reg: scalar(&reg),
        occ: scalar(&occ),
    };
    if !terms.total.is_finite() {
        bail!("the loss is not finite: {terms:?}");
    }
    Ok(Loss { total, terms })
}
