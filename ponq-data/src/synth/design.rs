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
            let radius: f64 = rng.random_range(0.06..0.3);
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

/// Families of generated shapes (see [`super::SynthMix`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// CSG parts of sharp-edged primitives (`design`).
    Csg,
    /// The same features on a base whose edges are rounded by fillets (a rounded box or a
    /// rounded cylinder), with rounded bosses.
    Filleted,
    /// Turned parts: a stack of coaxial cylinders, cones and rounded cylinders, with grooves
    /// (subtracted tori), an axial bore and cross holes.
    Lathe,
    /// Free-form bodies without edges: an ellipsoid, alone or with a smooth rounded box, a bore
    /// or a second ellipsoid.
    Freeform,
}

impl Family {
    /// Name in descriptions.
    pub fn name(self) -> &'static str {
        match self {
            Family::Csg => "csg",
            Family::Filleted => "filleted",
            Family::Lathe => "lathe",
            Family::Freeform => "freeform",
        }
    }
}

fn new_builder(max: usize) -> Builder {
    Builder {
        prims: Vec::new(),
        tree: Csg::Union(Vec::new()),
        max: max.max(1),
        rounded: false,
        label: "",
        labels: Vec::new(),
    }
}

fn final_rotation(rng: &mut ChaCha8Rng) -> super::geom::M3 {
    match rng.random_range(0..3) {
        0 => IDENTITY,
        1 => random_axis_rotation(rng),
        _ => random_rotation(rng),
    }
}

/// A design of `family` with at most `max_primitives` primitives.
pub(crate) fn design_family(rng: &mut ChaCha8Rng, max_primitives: usize, family: Family) -> Solid {
    match family {
        Family::Csg => design(rng, max_primitives),
        Family::Filleted => filleted(rng, max_primitives),
        Family::Lathe => lathe(rng, max_primitives),
        Family::Freeform => freeform(rng, max_primitives),
    }
}

/// A rounded base (fillet radius 0.03 to 0.4 of its smallest half size) and CSG features.
fn filleted(rng: &mut ChaCha8Rng, max_primitives: usize) -> Solid {
    let mut b = new_builder(max_primitives);
    b.label = "base";
    let frame = Frame::new(IDENTITY, [0.0; 3]);
    let kind = if rng.random_bool(0.55) {
        let half = [
            rng.random_range(0.35..0.9),
            rng.random_range(0.25..0.8),
            rng.random_range(0.06..0.6),
        ];
        let m = half.iter().cloned().fold(f64::MAX, f64::min);
        Kind::RoundedBox {
            half,
            radius: m * rng.random_range(0.1..0.9),
        }
    } else {
        let radius = rng.random_range(0.3..0.85);
        let half_height = rng.random_range(0.06..0.7);
        Kind::RoundedCylinder {
            radius,
            half_height,
            fillet: radius.min(half_height) * rng.random_range(0.1..0.9),
        }
    };
    b.tree = b.push(kind, frame);
    let target = rng.random_range(1..=b.max.max(2) / 2 + 1).min(b.max);
    let mut tries = 0;
    while b.prims.len() < target && tries < 4 * b.max {
        tries += 1;
        let Some((p, n)) = b.surface_point(rng) else {
            break;
        };
        let r = rng.random_range(0.0..1.0);
        if r < 0.35 {
            // A rounded boss standing on the surface.
            let z = Builder::maybe_tilt(rng, n, 0.2);
            let radius: f64 = rng.random_range(0.06..0.3);
            let hh = 0.5 * rng.random_range(0.08..0.4);
            let fillet = radius.min(hh) * rng.random_range(0.2..0.8);
            b.label = "rounded boss";
            let node = b.push(
                Kind::RoundedCylinder {
                    radius,
                    half_height: hh,
                    fillet,
                },
                Frame::from_axis(add(p, scale(z, hh - 0.02)), z, 0.0),
            );
            b.union(node);
        } else if r < 0.7 {
            b.add_hole(rng, p, n);
        } else if r < 0.9 {
            b.add_pocket(rng, p, n);
        } else {
            b.add_boss(rng, p, n);
        }
    }
    let rot = final_rotation(rng);
    b.current().rotated(&rot)
}

/// A turned part along `z`: 2 to 4 coaxial sections, grooves, a bore, cross holes.
fn lathe(rng: &mut ChaCha8Rng, max_primitives: usize) -> Solid {
    let mut b = new_builder(max_primitives.max(4));
    let sections = rng.random_range(2..=4);
    let total = rng.random_range(1.2..1.9);
    let mut z = -0.5 * total;
    let mut radius: f64 = rng.random_range(0.2..0.6);
    let mut nodes = Vec::new();
    let mut widest: f64 = 0.0;
    for _ in 0..sections {
        let h = total / sections as f64 * rng.random_range(0.7..1.3);
        let hh = 0.5 * h;
        let frame = Frame::new(IDENTITY, [0.0, 0.0, z + hh]);
        let r = rng.random_range(0.0..1.0);
        b.label = "section";
        let kind = if r < 0.4 {
            Kind::Cylinder {
                radius,
                half_height: hh,
            }
        } else if r < 0.7 {
            let next = (radius * rng.random_range(0.5..1.5)).clamp(0.08, 0.8);
            let k = Kind::Cone {
                r_bottom: radius,
                r_top: next,
                half_height: hh,
            };
            radius = next;
            k
        } else {
            Kind::RoundedCylinder {
                radius,
                half_height: hh,
                fillet: radius.min(hh) * rng.random_range(0.15..0.8),
            }
        };
        widest = widest.max(radius);
        nodes.push(b.push(kind, frame));
        z += h;
        radius = (radius * rng.random_range(0.6..1.5)).clamp(0.08, 0.8);
    }
    b.tree = Csg::Union(nodes);
    // Grooves: tori cutting into a section's side.
    for _ in 0..rng.random_range(0..=2) {
        if b.remaining() == 0 {
            break;
        }
        let Some((p, _)) = b.surface_point(rng) else {
            break;
        };
        let rho = p[0].hypot(p[1]);
        if rho < 0.1 {
            continue;
        }
        let minor = rng.random_range(0.02..0.06);
        b.label = "groove";
        let node = b.push(
            Kind::Torus {
                major: rho + 0.3 * minor,
                minor,
            },
            Frame::new(IDENTITY, [0.0, 0.0, p[2]]),
        );
        b.subtract(node);
    }
    // An axial bore through the part, or a blind one from the top.
    if b.remaining() > 0 && rng.random_bool(0.6) {
        b.label = "bore";
        let r = rng.random_range(0.04..(0.6 * widest).max(0.05));
        let node = b.push(
            Kind::Cylinder {
                radius: r.min(0.3),
                half_height: if rng.random_bool(0.5) {
                    FAR
                } else {
                    0.5 * total
                },
            },
            Frame::new(
                IDENTITY,
                [
                    0.0,
                    0.0,
                    if rng.random_bool(0.5) {
                        0.0
                    } else {
                        0.5 * total
                    },
                ],
            ),
        );
        b.subtract(node);
    }
    // Cross holes.
    if b.remaining() > 0 && rng.random_bool(0.35) {
        b.label = "cross hole";
        let zc = rng.random_range(-0.4 * total..0.4 * total);
        let node = b.push(
            Kind::Cylinder {
                radius: rng.random_range(0.03..0.1),
                half_height: FAR,
            },
            Frame::from_axis([0.0, 0.0, zc], [1.0, 0.0, 0.0], 0.0),
        );
        b.subtract(node);
    }
    let rot = final_rotation(rng);
    b.current().rotated(&rot)
}

/// A free-form body: an ellipsoid (semi-axes 0.25 to 0.9), alone or with a second ellipsoid, a
/// smooth rounded box (fillet at least half its smallest half size) or a bore.
fn freeform(rng: &mut ChaCha8Rng, max_primitives: usize) -> Solid {
    let mut b = new_builder(max_primitives.max(3));
    let radii = [
        rng.random_range(0.45..0.9),
        rng.random_range(0.3..0.8),
        rng.random_range(0.25..0.7),
    ];
    b.label = "body";
    b.tree = b.push(
        Kind::Ellipsoid { radii },
        Frame::new(random_rotation(rng), [0.0; 3]),
    );
    let r = rng.random_range(0.0..1.0);
    if r < 0.45 {
        // Alone.
    } else if r < 0.65 {
        let Some((p, _)) = b.surface_point(rng) else {
            return b.current();
        };
        b.label = "lobe";
        let node = b.push(
            Kind::Ellipsoid {
                radii: [
                    rng.random_range(0.15..0.45),
                    rng.random_range(0.12..0.4),
                    rng.random_range(0.1..0.35),
                ],
            },
            Frame::new(random_rotation(rng), p),
        );
        b.union(node);
    } else if r < 0.85 {
        let half = [
            rng.random_range(0.2..0.5),
            rng.random_range(0.2..0.5),
            rng.random_range(0.15..0.4),
        ];
        let m = half.iter().cloned().fold(f64::MAX, f64::min);
        b.label = "rounded block";
        let Some((p, _)) = b.surface_point(rng) else {
            return b.current();
        };
        let node = b.push(
            Kind::RoundedBox {
                half,
                radius: m * rng.random_range(0.5..0.95),
            },
            Frame::new(random_rotation(rng), scale(p, 0.7)),
        );
        b.union(node);
    } else {
        b.label = "bore";
        let node = b.push(
            Kind::Cylinder {
                radius: rng.random_range(0.05..0.2),
                half_height: FAR,
            },
            Frame::new(random_rotation(rng), [0.0; 3]),
        );
        b.subtract(node);
    }
    b.current()
}
