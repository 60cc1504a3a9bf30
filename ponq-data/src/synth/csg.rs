//! CSG trees of analytic primitives: exact inside test and area-uniform sampling of the
//! boundary of the result.
//!
//! A sample of primitive `i`'s surface at `p` with outward normal `n` lies on the boundary of
//! the solid exactly when the solid's inside test differs at `p - eps n` and `p + eps n`; the
//! solid's outward normal there is `n` when the inner side is inside (a union or intersection
//! keeps the primitive's orientation) and `-n` otherwise (the wall of a subtracted primitive).
//! Sampling every primitive in proportion to its area and discarding the samples that fail the
//! test is therefore exactly area-uniform on the boundary of the solid.

use std::fmt::Write as _;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::geom::{V3, add, scale, sub};
use super::primitive::{Primitive, pick};

/// Offset (in the units of the solid) of the two probes of the boundary test.
const PROBE: f64 = 1e-9;

/// A CSG expression over the primitives of a [`Solid`].
#[derive(Debug, Clone, PartialEq)]
pub enum Csg {
    /// Primitive `i` of the solid.
    Prim(usize),
    /// Points inside any child.
    Union(Vec<Csg>),
    /// Points inside every child.
    Intersection(Vec<Csg>),
    /// Points inside the first operand and inside none of the others.
    Difference(Box<Csg>, Vec<Csg>),
}

/// A solid: primitives and the CSG expression that combines them.
#[derive(Debug, Clone, PartialEq)]
pub struct Solid {
    prims: Vec<Primitive>,
    tree: Csg,
    /// Role of each primitive in the design ("hole", "rib", ...), or empty.
    labels: Vec<String>,
}

/// The smooth surface piece a boundary sample lies on: surface part `part` of primitive
/// `prim` (and, for a slot's round ends, which end), see `Primitive::patch`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Patch {
    /// Primitive index in the solid.
    pub prim: u32,
    /// Surface part of the primitive.
    pub part: u8,
    /// Round end of a slot (sign of the local `x`); 1 otherwise.
    pub side: i8,
}

/// Oriented boundary samples of a [`Solid`] and how many primitive samples were drawn.
#[derive(Debug, Clone, Default)]
pub(crate) struct BoundarySamples {
    pub points: Vec<V3>,
    pub normals: Vec<V3>,
    /// The surface piece of each sample.
    pub patches: Vec<Patch>,
    /// Primitive samples drawn (accepted or not).
    pub drawn: u64,
}

/// Accepted samples per parallel chunk (each chunk has its own random stream).
const CHUNK: usize = 4096;

impl Solid {
    /// A solid from primitives and a tree over them. The primitives' sampling is restricted
    /// to a box that holds the whole solid ([`Primitive::clipped`]): long drills and the big
    /// boxes of plane cuts are then sampled only where they can meet the solid.
    ///
    /// # Panics
    /// If the tree refers to a primitive that does not exist.
    pub fn new(prims: Vec<Primitive>, tree: Csg) -> Self {
        fn check(t: &Csg, n: usize) {
            match t {
                Csg::Prim(i) => assert!(*i < n, "primitive {i} of {n}"),
                Csg::Union(v) | Csg::Intersection(v) => v.iter().for_each(|c| check(c, n)),
                Csg::Difference(a, v) => {
                    check(a, n);
                    v.iter().for_each(|c| check(c, n));
                }
            }
        }
        check(&tree, prims.len());
        let (lo, hi) = Self::tree_box(&prims, &tree);
        let prims: Vec<Primitive> = prims.iter().map(|p| p.clipped(lo, hi)).collect();
        let labels = vec![String::new(); prims.len()];
        Self {
            prims,
            tree,
            labels,
        }
    }

    /// The solid with a role for each primitive (shown by [`Solid::describe`]); missing
    /// labels stay empty.
    pub fn with_labels<S: AsRef<str>>(mut self, labels: &[S]) -> Self {
        for (l, s) in self.labels.iter_mut().zip(labels) {
            *l = s.as_ref().to_string();
        }
        self
    }

    /// The role of each primitive in the design (`"base"`, `"boss"`, `"rib"`, `"hole"`,
    /// `"plane cut"`, ...; empty when unknown).
    pub fn labels(&self) -> &[String] {
        &self.labels
    }

    /// A box that holds the solid of `t` (empty, `lo > hi`, when the solid obviously is).
    fn tree_box(prims: &[Primitive], t: &Csg) -> (V3, V3) {
        match t {
            Csg::Prim(i) => prims[*i].bounding_box(),
            Csg::Union(v) => v.iter().fold(
                ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
                |(lo, hi), c| {
                    let (a, b) = Self::tree_box(prims, c);
                    (
                        std::array::from_fn(|k| lo[k].min(a[k])),
                        std::array::from_fn(|k| hi[k].max(b[k])),
                    )
                },
            ),
            Csg::Intersection(v) => v.iter().fold(
                ([f64::NEG_INFINITY; 3], [f64::INFINITY; 3]),
                |(lo, hi), c| {
                    let (a, b) = Self::tree_box(prims, c);
                    (
                        std::array::from_fn(|k| lo[k].max(a[k])),
                        std::array::from_fn(|k| hi[k].min(b[k])),
                    )
                },
            ),
            Csg::Difference(a, _) => Self::tree_box(prims, a),
        }
    }

    /// The primitives.
    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }

    /// The CSG expression.
    pub fn tree(&self) -> &Csg {
        &self.tree
    }

    /// Exact inside test (closed primitives combined by the tree).
    pub fn inside(&self, p: V3) -> bool {
        self.eval(&self.tree, p)
    }

    fn eval(&self, t: &Csg, p: V3) -> bool {
        match t {
            Csg::Prim(i) => self.prims[*i].inside(p),
            Csg::Union(v) => v.iter().any(|c| self.eval(c, p)),
            Csg::Intersection(v) => v.iter().all(|c| self.eval(c, p)),
            Csg::Difference(a, v) => self.eval(a, p) && !v.iter().any(|c| self.eval(c, p)),
        }
    }

    /// Sum of the primitives' areas.
    pub(crate) fn total_area(&self) -> f64 {
        self.prims.iter().map(Primitive::area).sum()
    }

    /// One draw: a primitive picked by area, a uniform point on it, kept when it lies on the
    /// boundary of the solid (with the solid's outward normal).
    pub(crate) fn draw(&self, weights: &[f64], rng: &mut impl Rng) -> Option<(V3, V3, Patch)> {
        let i = pick(weights, rng.random::<f64>());
        let (p, n, part, side) = self.prims[i].sample_tagged(rng);
        let side = if matches!(self.prims[i].kind(), super::primitive::Kind::Slot { .. }) {
            side
        } else {
            1
        };
        let patch = Patch {
            prim: i as u32,
            part,
            side,
        };
        let inner = self.inside(sub(p, scale(n, PROBE)));
        let outer = self.inside(add(p, scale(n, PROBE)));
        match (inner, outer) {
            (true, false) => Some((p, n, patch)),
            (false, true) => Some((p, n.map(|x| -x), patch)),
            _ => None,
        }
    }

    /// The singular points of `patch` (a pointed cone's apex) with the cone's axis.
    pub(crate) fn patch_apexes(&self, patch: Patch) -> Vec<(V3, V3)> {
        self.prims[patch.prim as usize].apexes(patch.part)
    }

    /// Whether the function of `patch` is the distance to its whole surface.
    pub(crate) fn patch_is_distance(&self, patch: Patch) -> bool {
        self.prims[patch.prim as usize]
            .kind()
            .part_is_distance(patch.part as usize)
    }

    /// Whether the surface of `patch` is a plane.
    pub(crate) fn patch_is_planar(&self, patch: Patch) -> bool {
        self.prims[patch.prim as usize]
            .kind()
            .part_is_planar(patch.part as usize)
    }

    /// `(g, grad g)` of the smooth surface of `patch` at `p` (distance-like, see
    /// [`Primitive::patch`]).
    pub(crate) fn patch(&self, patch: Patch, p: V3) -> (f64, V3) {
        self.prims[patch.prim as usize].patch(patch.part, patch.side, p)
    }

    /// `n` area-uniform boundary samples, reproducible from `key` whatever the thread count
    /// (chunk `c` draws from stream `c` of `ChaCha8Rng::seed_from_u64(key)`). `None` when a
    /// chunk accepts fewer than one draw in `max_draws_per_sample`.
    pub(crate) fn sample_boundary(
        &self,
        n: usize,
        key: u64,
        max_draws_per_sample: u64,
    ) -> Option<BoundarySamples> {
        let weights: Vec<f64> = self.prims.iter().map(Primitive::area).collect();
        if !(weights.iter().sum::<f64>() > 0.0) {
            return None;
        }
        let chunks = n.div_ceil(CHUNK);
        let parts: Vec<Option<BoundarySamples>> = (0..chunks)
            .into_par_iter()
            .map(|c| {
                let quota = CHUNK.min(n - c * CHUNK);
                let mut rng = ChaCha8Rng::seed_from_u64(key);
                rng.set_stream(c as u64);
                let mut out = BoundarySamples {
                    points: Vec::with_capacity(quota),
                    normals: Vec::with_capacity(quota),
                    patches: Vec::with_capacity(quota),
                    drawn: 0,
                };
                let limit = max_draws_per_sample * quota as u64 + 1000;
                while out.points.len() < quota {
                    if out.drawn >= limit {
                        return None;
                    }
                    out.drawn += 1;
                    if let Some((p, nn, patch)) = self.draw(&weights, &mut rng) {
                        out.points.push(p);
                        out.normals.push(nn);
                        out.patches.push(patch);
                    }
                }
                Some(out)
            })
            .collect();
        let mut all = BoundarySamples {
            points: Vec::with_capacity(n),
            normals: Vec::with_capacity(n),
            patches: Vec::with_capacity(n),
            drawn: 0,
        };
        for p in parts {
            let p = p?;
            all.points.extend(p.points);
            all.normals.extend(p.normals);
            all.patches.extend(p.patches);
            all.drawn += p.drawn;
        }
        Some(all)
    }

    /// The solid under the similarity `p -> (p - centre) * s` (`s > 0`).
    pub(crate) fn similar(&self, centre: V3, s: f64) -> Self {
        Self::new(
            self.prims.iter().map(|p| p.similar(centre, s)).collect(),
            self.tree.clone(),
        )
        .with_labels(&self.labels)
    }

    /// The solid rotated by `rot` about the origin.
    pub(crate) fn rotated(&self, rot: &super::geom::M3) -> Self {
        Self::new(
            self.prims.iter().map(|p| p.rotated(rot)).collect(),
            self.tree.clone(),
        )
        .with_labels(&self.labels)
    }

    /// The CSG tree as indented text, one primitive per line.
    pub fn describe(&self) -> String {
        let mut s = String::new();
        self.describe_node(&self.tree, 0, &mut s);
        s
    }

    fn describe_node(&self, t: &Csg, depth: usize, s: &mut String) {
        let pad = "  ".repeat(depth);
        match t {
            Csg::Prim(i) => {
                let _ = write!(s, "{pad}{}", self.prims[*i]);
                if !self.labels[*i].is_empty() {
                    let _ = write!(s, "  # {}", self.labels[*i]);
                }
                s.push('\n');
            }
            Csg::Union(v) | Csg::Intersection(v) => {
                let name = if matches!(t, Csg::Union(_)) {
                    "union"
                } else {
                    "intersection"
                };
                let _ = writeln!(s, "{pad}{name}(");
                for c in v {
                    self.describe_node(c, depth + 1, s);
                }
                let _ = writeln!(s, "{pad})");
            }
            Csg::Difference(a, v) => {
                let _ = writeln!(s, "{pad}difference(");
                self.describe_node(a, depth + 1, s);
                let _ = writeln!(s, "{pad}  minus");
                for c in v {
                    self.describe_node(c, depth + 1, s);
                }
                let _ = writeln!(s, "{pad})");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::geom::{Frame, IDENTITY, dot};
    use crate::synth::primitive::Kind;

    /// A unit cube with a through hole of radius 0.25 along z: boundary area is known.
    fn drilled_cube() -> Solid {
        let cube = Primitive::new(Kind::Box { half: [0.5; 3] }, Frame::new(IDENTITY, [0.0; 3]));
        let hole = Primitive::new(
            Kind::Cylinder {
                radius: 0.25,
                half_height: 1.0,
            },
            Frame::new(IDENTITY, [0.0; 3]),
        );
        Solid::new(
            vec![cube, hole],
            Csg::Difference(Box::new(Csg::Prim(0)), vec![Csg::Prim(1)]),
        )
    }

    #[test]
    fn boundary_samples_of_a_drilled_cube() {
        let s = drilled_cube();
        let b = s.sample_boundary(50_000, 7, 100).unwrap();
        assert_eq!(b.points.len(), 50_000);
        let pi = std::f64::consts::PI;
        let area = 6.0 - 2.0 * pi * 0.0625 + 2.0 * pi * 0.25;
        let est = s.total_area() * b.points.len() as f64 / b.drawn as f64;
        assert!((est - area).abs() < 0.02 * area, "{est} vs {area}");
        // Hole wall samples point towards the axis; their share is the wall's area share.
        let mut wall = 0;
        for (p, n) in b.points.iter().zip(&b.normals) {
            assert!(s.inside(sub(*p, scale(*n, 1e-6))));
            assert!(!s.inside(add(*p, scale(*n, 1e-6))));
            let r = p[0].hypot(p[1]);
            if (r - 0.25).abs() < 1e-9 && p[2].abs() < 0.5 - 1e-9 {
                wall += 1;
                assert!(dot(*n, [p[0], p[1], 0.0]) < 0.0);
            }
        }
        let share = wall as f64 / b.points.len() as f64;
        let want = 2.0 * pi * 0.25 / area;
        assert!((share - want).abs() < 0.01, "{share} vs {want}");
        // Same key, same samples; the description names both primitives.
        let again = s.sample_boundary(50_000, 7, 100).unwrap();
        assert_eq!(again.points, b.points);
        let d = s.describe();
        assert!(d.contains("difference(") && d.contains("box(") && d.contains("cylinder("));
    }
}
