//! Step 3 of the mesher: label the unknown tets with a minimum s-t cut of the dual graph.
//!
//! Nodes are the unknown tets; inside tets are merged into the source and outside tets (and
//! the hull) into the sink, so the graph only holds the undecided region. The capacity of the
//! arc `a -> b` is the score of their common face with `a` inside and `b` outside.

use crate::complex::{Label, TetComplex};
use crate::delaunay::NONE;
use crate::maxflow::{Graph, Segment};
use crate::score::face_scores;

/// Size of the cut problem.
#[derive(Debug, Clone, Copy, Default)]
pub struct CutStats {
    /// Graph nodes (unknown tets).
    pub nodes: usize,
    /// Arcs between unknown tets.
    pub edges: usize,
    /// Value of the minimum cut.
    pub flow: f64,
}

/// What one face of an unknown tet `t` adds to the cut's graph.
#[derive(Debug, Clone, Copy)]
enum Part {
    /// Nothing (a face shared with a smaller unknown tet, whose arc it is).
    Nothing,
    /// The arc to the unknown tet of this node number, with the capacities out of `t` and into
    /// it.
    Arc(u32, f64, f64),
    /// Capacity from the source (an inside neighbour).
    Source(f64),
    /// Capacity to the sink (an outside neighbour, or the hull).
    Sink(f64),
}

/// Replaces every [`Label::Unknown`] by [`Label::Inside`] or [`Label::Outside`].
pub fn min_cut(cx: &TetComplex, labels: &mut [Label]) -> CutStats {
    use rayon::prelude::*;
    let unknown: Vec<u32> = (0..labels.len() as u32)
        .filter(|&t| labels[t as usize] == Label::Unknown)
        .collect();
    if unknown.is_empty() {
        return CutStats::default();
    }
    let mut id = vec![u32::MAX; labels.len()];
    for (i, &t) in unknown.iter().enumerate() {
        id[t as usize] = i as u32;
    }
    // Each face's contribution to the graph, found in parallel (the neighbours, their labels
    // and the face scores are reads all over the tets), then added in the order of the tets
    // and faces (the sums of terminal capacities, in floating point, do not depend on the
    // thread count). A face between two unknown tets is scored from the smaller one only,
    // where its arc is added: the other side's score is never read (about 40% of the faces).
    let seen: &[Label] = labels;
    let id = &id;
    let parts: Vec<[Part; 4]> = unknown
        .par_iter()
        .map(|&t| {
            let mut parts = [Part::Nothing; 4];
            for (k, part) in parts.iter_mut().enumerate() {
                let nb = cx.neighbor(t, k);
                let label = if nb == NONE {
                    Label::Outside
                } else {
                    seen[nb as usize]
                };
                *part = match label {
                    Label::Unknown if nb < t => Part::Nothing,
                    Label::Unknown => {
                        let (out_of_t, into_t) = face_scores(cx, t, k);
                        Part::Arc(id[nb as usize], out_of_t, into_t)
                    }
                    // Cut when t is outside: the face is then seen from the inside neighbour.
                    Label::Inside => Part::Source(face_scores(cx, t, k).1),
                    // Cut when t is inside (the hull counts as outside).
                    Label::Outside => Part::Sink(face_scores(cx, t, k).0),
                };
            }
            parts
        })
        .collect();
    let mut g = Graph::new(unknown.len(), 2 * unknown.len());
    let mut edges = 0;
    for (i, parts) in parts.iter().enumerate() {
        for part in parts {
            match *part {
                Part::Nothing => {}
                Part::Arc(j, out_of_t, into_t) => {
                    g.add_edge(i, j as usize, out_of_t, into_t);
                    edges += 1;
                }
                Part::Source(c) => g.add_tweights(i, c, 0.0),
                Part::Sink(c) => g.add_tweights(i, 0.0, c),
            }
        }
    }
    let flow = g.maxflow();
    for (i, &t) in unknown.iter().enumerate() {
        labels[t as usize] = match g.segment(i) {
            Segment::Source => Label::Inside,
            Segment::Sink => Label::Outside,
        };
    }
    CutStats {
        nodes: unknown.len(),
        edges,
        flow,
    }
}
