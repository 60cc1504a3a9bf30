//! Random CAD-like designs: a base body (plate, block, disk, prism, slotted plate, cone, ball or
//! ring) followed by features placed on its current surface: bosses, ribs, domes, handles
//! (union), drilled holes with drill points, countersinks and counterbores, pockets, through
//! slots, hole patterns, chamfer cuts (difference), and rounding by a ball or a cylinder
//! (intersection); finally a rotation of the whole part (none, one of the 24 axis-aligned
//! ones, or uniformly random).
//!
//! Lengths are in a design frame where the base spans a bounding-box diagonal of about 2;
//! thin parts (plates, ribs, ring tubes) are 0.02 to 0.06 thick in it.

use std::f64::consts::TAU;

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::csg::{Csg, Solid};
use super::geom::{
    Frame, IDENTITY, V3, add, any_perpendicular, cross, dot, normalize_or, random_axis_rotation,
    random_rotation, scale, sub,
};
use super::primitive::{Kind, Primitive};

/// Half size of the boxes that act as half-spaces (chamfer cuts) and of through cuts.
const FAR: f64 = 4.0;

/// A design under construction.
struct Builder {
    prims: Vec<Primitive>,
    tree: Csg,
    /// The budget of primitives.
    max: usize,
    rounded: bool,
    /// Role of the primitives pushed next (for the description).
    label: &'static str,
    labels: Vec<&'static str>,
}

fn thin(rng: &mut ChaCha8Rng) -> f64 {
    rng.random_range(0.02..0.06)
}

/// A random convex polygon (counter-clockwise) of `n` corners on an ellipse of half axes
/// `(rx, ry)`; regular with probability 0.4.
fn convex_polygon(rng: &mut ChaCha8Rng, n: usize, rx: f64, ry: f64) -> Vec<[f64; 2]> {
    let phase = rng.random_range(0.0..TAU);
    let gaps: Vec<f64> = if rng.random_bool(0.4) {
        vec![1.0; n]
    } else {
        (0..n).map(|_| rng.random_range(0.5..1.5)).collect()
    };
    let total: f64 = gaps.iter().sum();
    let mut a = phase;
    let mut out = Vec::with_capacity(n);
    for g in gaps {
        out.push([rx * a.cos(), ry * a.sin()]);
        a += TAU * g / total;
    }
    out
}

impl Builder {
    fn current(&self) -> Solid {
        Solid::new(self.prims.clone(), self.tree.clone()).with_labels(&self.labels)
    }

    fn remaining(&self) -> usize {
        self.max.saturating_sub(self.prims.len())
    }

    fn push(&mut self, kind: Kind, frame: Frame) -> Csg {
        self.prims.push(Primitive::new(kind, frame));
        self.labels.push(self.label);
        Csg::Prim(self.prims.len() - 1)
    }

    fn union(&mut self, node: Csg) {
        let t = std::mem::replace(&mut self.tree, Csg::Union(Vec::new()));
        self.tree = match t {
            Csg::Union(mut v) => {
                v.push(node);
                Csg::Union(v)
            }
            t => Csg::Union(vec![t, node]),
        };
    }

    fn subtract(&mut self, node: Csg) {
        let t = std::mem::replace(&mut self.tree, Csg::Union(Vec::new()));
        self.tree = match t {
            Csg::Difference(a, mut v) => {
                v.push(node);
                Csg::Difference(a, v)
            }
            t => Csg::Difference(Box::new(t), vec![node]),
        };
    }

    fn intersect(&mut self, node: Csg) {
        let t = std::mem::replace(&mut self.tree, Csg::Union(Vec::new()));
        self.tree = match t {
            Csg::Intersection(mut v) => {
                v.push(node);
                Csg::Intersection(v)
            }
            t => Csg::Intersection(vec![t, node]),
        };
    }

    /// Boundary samples of the current solid (sequential, from the design stream).
    fn surface_points(&self, rng: &mut ChaCha8Rng, n: usize) -> Vec<(V3, V3)> {
        let s = self.current();
        let w: Vec<f64> = s.primitives().iter().map(Primitive::area).collect();
        let mut out = Vec::with_capacity(n);
        if !(w.iter().sum::<f64>() > 0.0) {
            return out;
        }
        for _ in 0..200 * n {
            if out.len() == n {
                break;
            }
            if let Some((p, n, _)) = s.draw(&w, rng) {
                out.push((p, n));
            }
        }
        out
    }

    fn surface_point(&self, rng: &mut ChaCha8Rng) -> Option<(V3, V3)> {
        self.surface_points(rng, 1).pop()
    }

    /// The axis `n`, tilted by 10 to 35 degrees with probability `p`.
    fn maybe_tilt(rng: &mut ChaCha8Rng, n: V3, p: f64) -> V3 {
        if !rng.random_bool(p) {
            return n;
        }
        let t = any_perpendicular(n);
        let b = cross(n, t);
        let phi = rng.random_range(0.0..TAU);
        let dir = add(scale(t, phi.cos()), scale(b, phi.sin()));
        let a = rng.random_range(10.0f64..35.0).to_radians();
        normalize_or(add(scale(n, a.cos()), scale(dir, a.sin())), n)
    }

    fn base(&mut self, rng: &mut ChaCha8Rng) {
        let thin_p = 0.35;
        let frame = Frame::new(IDENTITY, [0.0; 3]);
        let r = rng.random_range(0.0..1.0);
        let kind = if r < 0.28 {
            let t = if rng.random_bool(thin_p) {
                0.5 * thin(rng)
            } else {
                rng.random_range(0.05..0.3)
            };
            Kind::Box {
                half: [rng.random_range(0.45..0.9), rng.random_range(0.3..0.8), t],
            }
        } else if r < 0.45 {
            Kind::Box {
                half: [
                    rng.random_range(0.25..0.7),
                    rng.random_range(0.25..0.7),
                    rng.random_range(0.25..0.7),
                ],
            }
        } else if r < 0.6 {
            let h = if rng.random_bool(thin_p * 0.7) {
                0.5 * thin(rng)
            } else {
                rng.random_range(0.08..0.7)
            };
            Kind::Cylinder {
                radius: rng.random_range(0.35..0.85),
                half_height: h,
            }
        } else if r < 0.74 {
            let n = rng.random_range(3..=8);
            let rx = rng.random_range(0.45..0.9);
            let ry = rx * rng.random_range(0.6..1.0);
            let h = if rng.random_bool(thin_p * 0.7) {
                0.5 * thin(rng)
            } else {
                rng.random_range(0.08..0.6)
            };
            Kind::Prism {
                polygon: convex_polygon(rng, n, rx, ry),
                half_height: h,
            }
        } else if r < 0.84 {
            let h = if rng.random_bool(thin_p) {
                0.5 * thin(rng)
            } else {
                rng.random_range(0.05..0.4)
            };
            Kind::Slot {
                half_length: rng.random_range(0.25..0.6),
                radius: rng.random_range(0.15..0.45),
                half_height: h,
            }
        } else if r < 0.91 {
            let r0 = rng.random_range(0.3..0.8);
            let r1 = if rng.random_bool(0.2) {
                0.0
            } else {
                r0 * rng.random_range(0.1..0.85)
            };
            Kind::Cone {
                r_bottom: r0,
                r_top: r1,
                half_height: rng.random_range(0.2..0.7),
            }
        } else if r < 0.96 {
            Kind::Sphere {
                radius: rng.random_range(0.5..0.9),
            }
        } else {
            let major = rng.random_range(0.45..0.7);
            Kind::Torus {
                major,
                minor: rng.random_range(0.12f64..0.3).min(0.6 * major),
            }
        };
        self.label = "base";
        let node = self.push(kind, frame);
        self.tree = node;
    }

    /// A union feature standing on the surface at `p` (outward normal `n`), sunk by `d`.
    fn add_boss(&mut self, rng: &mut ChaCha8Rng, p: V3, n: V3) {
        let z = Self::maybe_tilt(rng, n, 0.25);
        let spin = rng.random_range(0.0..TAU);
        let d = rng.random_range(0.01..0.05);
        let h = rng.random_range(0.06..0.45);
        // Centre of a prism of height h standing on the surface, sunk by d.
        let standing = |hh: f64| Frame::from_axis(add(p, scale(z, hh - d)), z, spin);
        let r = rng.random_range(0.0..1.0);
        self.label = "boss";
        let node = if r < 0.2 {
            let radius = rng.random_range(0.04..0.25);
            let hh = 0.5 * (h + d);
            self.push(
                Kind::Cylinder {
                    radius,
                    half_height: hh,
                },
                standing(hh),
            )
        } else if r < 0.38 {
            // A rib: a thin wall.
            self.label = "rib";
            let hh = 0.5 * (rng.random_range(0.06..0.35) + d);
            self.push(
                Kind::Box {
                    half: [rng.random_range(0.08..0.45), 0.5 * thin(rng), hh],
                },
                standing(hh),
            )
        } else if r < 0.5 {
            let hh = 0.5 * (h + d);
            self.push(
                Kind::Box {
                    half: [rng.random_range(0.04..0.3), rng.random_range(0.04..0.3), hh],
                },
                standing(hh),
            )
        } else if r < 0.62 {
            let hh = 0.5 * (h + d);
            let r0 = rng.random_range(0.06..0.3);
            let r1 = if rng.random_bool(0.2) {
                0.0
            } else {
                r0 * rng.random_range(0.2..0.9)
            };
            self.push(
                Kind::Cone {
                    r_bottom: r0,
                    r_top: r1,
                    half_height: hh,
                },
                standing(hh),
            )
        } else if r < 0.74 {
            let hh = 0.5 * (h + d);
            let n = rng.random_range(3..=8);
            let rx = rng.random_range(0.06..0.3);
            let ry = rx * rng.random_range(0.5..1.0);
            self.push(
                Kind::Prism {
                    polygon: convex_polygon(rng, n, rx, ry),
                    half_height: hh,
                },
                standing(hh),
            )
        } else if r < 0.82 {
            let radius = rng.random_range(0.06..0.3);
            let c = sub(p, scale(n, radius * rng.random_range(0.1..0.7)));
            self.label = "dome";
            self.push(Kind::Sphere { radius }, Frame::new(IDENTITY, c))
        } else if r < 0.92 {
            let major = rng.random_range(0.08..0.25);
            let minor = 0.5 * thin(rng) + rng.random_range(0.0..0.03);
            if rng.random_bool(0.5) {
                // A handle: the ring stands on the surface, half of it sunk.
                self.label = "handle";
                let t = any_perpendicular(n);
                let c = add(p, scale(n, major * rng.random_range(0.3..0.7)));
                self.push(Kind::Torus { major, minor }, Frame::from_axis(c, t, spin))
            } else {
                // A ring lying on the surface.
                self.label = "ring";
                let c = add(p, scale(n, minor * rng.random_range(-0.3..0.5)));
                self.push(Kind::Torus { major, minor }, Frame::from_axis(c, n, spin))
            }
        } else {
            let hh = 0.5 * (h + d);
            self.push(
                Kind::Slot {
                    half_length: rng.random_range(0.04..0.25),
                    radius: rng.random_range(0.03..0.15),
                    half_height: hh,
                },
                standing(hh),
            )
        };
        self.union(node);
    }

    /// A drilled hole at `p` along `-n`: through or blind (with a 118-degree drill point),
    /// sometimes with a countersink or a counterbore.
    fn add_hole(&mut self, rng: &mut ChaCha8Rng, p: V3, n: V3) {
        let z = Self::maybe_tilt(rng, n, 0.15);
        let radius = rng.random_range(0.03..0.15);
        let above = 0.3;
        let mut parts = Vec::new();
        self.label = "hole";
        let depth = if rng.random_bool(0.6) {
            parts.push(self.push(
                Kind::Cylinder {
                    radius,
                    half_height: FAR,
                },
                Frame::from_axis(p, z, 0.0),
            ));
            None
        } else {
            let depth = rng.random_range(0.05..0.4);
            let hh = 0.5 * (depth + above);
            parts.push(self.push(
                Kind::Cylinder {
                    radius,
                    half_height: hh,
                },
                Frame::from_axis(add(p, scale(z, 0.5 * (above - depth))), z, 0.0),
            ));
            Some(depth)
        };
        if let Some(depth) = depth
            && self.remaining() >= 1
            && rng.random_bool(0.6)
        {
            let tip = radius / (59.0f64).to_radians().tan();
            self.label = "drill point";
            parts.push(self.push(
                Kind::Cone {
                    r_bottom: 0.0,
                    r_top: radius,
                    half_height: 0.5 * tip,
                },
                Frame::from_axis(add(p, scale(z, -depth - 0.5 * tip)), z, 0.0),
            ));
        }
        if self.remaining() >= 1 && rng.random_bool(0.35) {
            if rng.random_bool(0.5) {
                // Countersink: a 90-degree cone.
                self.label = "countersink";
                let s = radius * rng.random_range(0.3..1.0);
                let hh = 0.5 * (s + above);
                parts.push(self.push(
                    Kind::Cone {
                        r_bottom: radius,
                        r_top: radius + s + above,
                        half_height: hh,
                    },
                    Frame::from_axis(add(p, scale(z, 0.5 * (above - s))), z, 0.0),
                ));
            } else {
                let depth = rng.random_range(0.02..0.12);
                let hh = 0.5 * (depth + above);
                self.label = "counterbore";
                parts.push(self.push(
                    Kind::Cylinder {
                        radius: radius * rng.random_range(1.4..2.0),
                        half_height: hh,
                    },
                    Frame::from_axis(add(p, scale(z, 0.5 * (above - depth))), z, 0.0),
                ));
            }
        }
        let node = if parts.len() == 1 {
            parts.pop().unwrap_or(Csg::Union(Vec::new()))
        } else {
            Csg::Union(parts)
        };
        self.subtract(node);
    }

    /// A pocket (box, slot, prism or cylinder) sunk into the surface at `p`, or a through slot.
    fn add_pocket(&mut self, rng: &mut ChaCha8Rng, p: V3, n: V3) {
        let z = Self::maybe_tilt(rng, n, 0.15);
        let spin = rng.random_range(0.0..TAU);
        let above = 0.3;
        let through = rng.random_bool(0.3);
        let depth = if through {
            2.0 * FAR
        } else {
            rng.random_range(0.02..0.25)
        };
        let hh = 0.5 * (depth + above);
        let frame = if through {
            Frame::from_axis(p, z, spin)
        } else {
            Frame::from_axis(add(p, scale(z, 0.5 * (above - depth))), z, spin)
        };
        let r = rng.random_range(0.0..1.0);
        let kind = if r < 0.3 {
            Kind::Box {
                half: [rng.random_range(0.04..0.3), rng.random_range(0.04..0.3), hh],
            }
        } else if r < 0.6 {
            Kind::Slot {
                half_length: rng.random_range(0.04..0.3),
                radius: rng.random_range(0.03..0.12),
                half_height: hh,
            }
        } else if r < 0.8 {
            let k = rng.random_range(3..=8);
            let rx = rng.random_range(0.06..0.3);
            let ry = rx * rng.random_range(0.5..1.0);
            Kind::Prism {
                polygon: convex_polygon(rng, k, rx, ry),
                half_height: hh,
            }
        } else {
            Kind::Cylinder {
                radius: rng.random_range(0.05..0.3),
                half_height: hh,
            }
        };
        self.label = if through { "through cut" } else { "pocket" };
        let node = self.push(kind, frame);
        self.subtract(node);
    }

    /// A plane cut (a half-space, as a big box) taking a slice off an edge or a corner:
    /// chamfers and bevels of many angles.
    fn add_chamfer(&mut self, rng: &mut ChaCha8Rng) {
        let pts = self.surface_points(rng, 256);
        if pts.is_empty() {
            return;
        }
        let r = rng.random_range(0.0..1.0);
        let u = if r < 0.45 {
            // An edge: two axes, at a random angle around 45 degrees.
            let (a, b) = match rng.random_range(0..3) {
                0 => (0, 1),
                1 => (0, 2),
                _ => (1, 2),
            };
            let t = rng.random_range(20.0f64..70.0).to_radians();
            let mut u = [0.0; 3];
            u[a] = t.cos() * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            u[b] = t.sin() * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            u
        } else if r < 0.75 {
            // A corner.
            std::array::from_fn(|_| {
                rng.random_range(0.5..1.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 }
            })
        } else {
            // Any direction.
            let m = random_rotation(rng);
            [m[0][2], m[1][2], m[2][2]]
        };
        let u = normalize_or(u, [0.0, 0.0, 1.0]);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (p, _) in &pts {
            let h = dot(*p, u);
            lo = lo.min(h);
            hi = hi.max(h);
        }
        let cut = (hi - lo) * rng.random_range(0.05..0.3);
        let c = scale(u, hi - cut + FAR);
        let spin = rng.random_range(0.0..TAU);
        self.label = "plane cut";
        let node = self.push(Kind::Box { half: [FAR; 3] }, Frame::from_axis(c, u, spin));
        self.subtract(node);
    }

    /// A pattern of through holes: on a circle about an axis of the design frame, or in a row
    /// on the surface at `p`.
    fn add_pattern(&mut self, rng: &mut ChaCha8Rng, p: V3, n: V3) {
        let count = rng.random_range(3..=8).min(self.remaining());
        if count < 2 {
            return;
        }
        let radius = rng.random_range(0.025..0.09);
        let mut holes = Vec::new();
        self.label = "hole pattern";
        if rng.random_bool(0.5) {
            let pts = self.surface_points(rng, 128);
            if pts.is_empty() {
                return;
            }
            let axis_k = rng.random_range(0..3);
            let mut axis = [0.0; 3];
            axis[axis_k] = 1.0;
            let (a, b) = ((axis_k + 1) % 3, (axis_k + 2) % 3);
            let rmax = pts
                .iter()
                .map(|(q, _)| q[a].hypot(q[b]))
                .fold(0.0f64, f64::max);
            let ring = rmax * rng.random_range(0.3..0.8);
            let phase = rng.random_range(0.0..TAU);
            for j in 0..count {
                let t = phase + TAU * j as f64 / count as f64;
                let mut c = [0.0; 3];
                c[a] = ring * t.cos();
                c[b] = ring * t.sin();
                holes.push(self.push(
                    Kind::Cylinder {
                        radius,
                        half_height: FAR,
                    },
                    Frame::from_axis(c, axis, 0.0),
                ));
            }
        } else {
            let dir = Frame::from_axis(p, n, rng.random_range(0.0..TAU)).rot;
            let dir = [dir[0][0], dir[1][0], dir[2][0]];
            let step = radius * rng.random_range(2.5..5.0);
            for j in 0..count {
                let off = (j as f64 - 0.5 * (count - 1) as f64) * step;
                holes.push(self.push(
                    Kind::Cylinder {
                        radius,
                        half_height: FAR,
                    },
                    Frame::from_axis(add(p, scale(dir, off)), n, 0.0),
                ));
            }
        }
        self.subtract(Csg::Union(holes));
    }

    /// Rounding: intersect with a ball about the centre, or a cylinder about an axis.
    fn add_rounding(&mut self, rng: &mut ChaCha8Rng) {
        let pts = self.surface_points(rng, 512);
        if pts.is_empty() {
            return;
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (p, _) in &pts {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let c: V3 = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        self.label = "rounding";
        let node = if rng.random_bool(0.5) {
            let rmax = pts
                .iter()
                .map(|(p, _)| super::geom::norm(sub(*p, c)))
                .fold(0.0, f64::max);
            let radius = rmax * rng.random_range(0.8..0.97);
            self.push(Kind::Sphere { radius }, Frame::new(IDENTITY, c))
        } else {
            let k = rng.random_range(0..3);
            let mut axis = [0.0; 3];
            axis[k] = 1.0;
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            let rmax = pts
                .iter()
                .map(|(p, _)| (p[a] - c[a]).hypot(p[b] - c[b]))
                .fold(0.0, f64::max);
            self.push(
                Kind::Cylinder {
                    radius: rmax * rng.random_range(0.8..0.97),
                    half_height: FAR,
                },
                Frame::from_axis(c, axis, 0.0),
            )
        };
        self.rounded = true;
        self.intersect(node);
    }
}

/// A random design with at most `max_primitives` primitives (at least 1).
pub(crate) fn design(rng: &mut ChaCha8Rng, max_primitives: usize) -> Solid {
    let max = max_primitives.max(1);
    let mut b = Builder {
        prims: Vec::new(),
        tree: Csg::Union(Vec::new()),
        max,
        rounded: false,
        label: "",
        labels: Vec::new(),
    };
    b.base(rng);
    let target = rng.random_range((max / 3).max(1)..=max);
    let mut tries = 0;
    while b.prims.len() < target && tries < 4 * max {
        tries += 1;
        let r = rng.random_range(0.0..1.0);
        if r < 0.1 {
            b.add_chamfer(rng);
            continue;
        }
        if r < 0.15 {
            if !b.rounded {
                b.add_rounding(rng);
            }
            continue;
        }
        let Some((p, n)) = b.surface_point(rng) else {
            break;
        };
        if r < 0.5 {
            b.add_boss(rng, p, n);
        } else if r < 0.75 {
            b.add_hole(rng, p, n);
        } else if r < 0.9 {
            b.add_pocket(rng, p, n);
        } else {
            b.add_pattern(rng, p, n);
        }
    }
    let rot = match rng.random_range(0..3) {
        0 => IDENTITY,
        1 => random_axis_rotation(rng),
        _ => random_rotation(rng),
    };
    b.current().rotated(&rot)
}
