//! Step 2 of the mesher: tag the obvious inside / outside tets (SPEC section 6).
//!
//! A tet whose four vertices all see its circumcentre (and its barycentre) behind their
//! oriented plane is inside; in front of all four, outside; otherwise unknown. Tets touching a
//! protective corner are outside. Then every vertex that has a tagged tet but no inside (or no
//! outside) tet gets its smallest unknown tet tagged the missing way, if that tet is small.

use crate::complex::{Label, TetComplex};
use crate::predicates::circumcenter;

#[inline]
fn dot_diff(a: &[f64; 3], b: &[f64; 3], n: &[f64; 3]) -> f64 {
    (a[0] - b[0]) * n[0] + (a[1] - b[1]) * n[1] + (a[2] - b[2]) * n[2]
}

/// Circumcentre + barycentre tagging of one tet.
pub fn tag_tet(cx: &TetComplex, t: u32) -> Label {
    if cx.touches_protective(t) {
        return Label::Outside;
    }
    let tv = cx.dt.tets[t as usize];
    let p = |i: usize| cx.pos(tv[i]);
    let Some(cc) = circumcenter(p(0), p(1), p(2), p(3)) else {
        return Label::Unknown;
    };
    let count = tv
        .iter()
        .filter(|&&v| dot_diff(cx.pos(v), &cc, &cx.normals[v as usize]) > 0.0)
        .count();
    let label = match count {
        4 => Label::Inside,
        0 => Label::Outside,
        _ => return Label::Unknown,
    };
    let b = cx.barycenter(t);
    let bary: f64 = tv
        .iter()
        .map(|&v| dot_diff(&b, cx.pos(v), &cx.normals[v as usize]))
        .sum::<f64>()
        / 4.0;
    match label {
        Label::Outside if bary < 0.0 => Label::Unknown,
        Label::Inside if bary > 0.0 => Label::Unknown,
        l => l,
    }
}

/// Tags every tet, then applies the small-tet rule with threshold
/// `small_factor * cell_size^2` on the mean squared vertex-to-barycentre distance
/// (the authors use 3).
pub fn tag_all(cx: &TetComplex, small_factor: f64) -> Vec<Label> {
    use rayon::prelude::*;
    let mut labels: Vec<Label> = (0..cx.n_tets() as u32)
        .into_par_iter()
        .map(|t| tag_tet(cx, t))
        .collect();
    let threshold = small_factor * cx.cell_size * cx.cell_size;
    // The rule only ever turns unknown tets into inside / outside ones, so a vertex that has
    // both already keeps both: only the others need the (ordered, sequential) pass below.
    // Which labels each vertex has (bit 0: inside, bit 1: outside), from one pass over the tets.
    let nv = cx.dt.vertices.len();
    let has_labels: Vec<u8> = cx
        .dt
        .tets
        .par_chunks(1 << 15)
        .zip(labels.par_chunks(1 << 15))
        .fold(
            || vec![0u8; nv],
            |mut acc, (tets, labels)| {
                for (tv, l) in tets.iter().zip(labels) {
                    let bit = match l {
                        Label::Inside => 1,
                        Label::Outside => 2,
                        Label::Unknown => continue,
                    };
                    for &v in tv {
                        acc[v as usize] |= bit;
                    }
                }
                acc
            },
        )
        .reduce(
            || vec![0u8; nv],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x |= y);
                a
            },
        );
    // (A vertex with neither label now may get one from an earlier vertex of the pass.)
    let candidates: Vec<u32> = (0..nv as u32)
        .filter(|&v| !cx.protective[v as usize] && has_labels[v as usize] != 3)
        .collect();
    for v in candidates {
        let inc = cx.incident(v);
        let has = |l: Label, labels: &[Label]| inc.iter().any(|&t| labels[t as usize] == l);
        if !has(Label::Inside, &labels) && !has(Label::Outside, &labels) {
            continue;
        }
        for (missing, _) in [(Label::Outside, ()), (Label::Inside, ())] {
            if has(missing, &labels) {
                continue;
            }
            let smallest = inc
                .iter()
                .copied()
                .filter(|&t| labels[t as usize] == Label::Unknown)
                .map(|t| (cx.size(t), t))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((s, t)) = smallest
                && s < threshold
            {
                labels[t as usize] = missing;
            }
        }
    }
    labels
}
