//! Analytic primitives: an exact inside test, the exact surface area and exact area-uniform
//! surface sampling with true outward normals (side walls and caps included).
//!
//! Every primitive lives in its local frame (axis `z`, centred at the origin) and is placed by
//! a rigid [`Frame`].

use std::f64::consts::{PI, TAU};
use std::fmt;

use rand::Rng;

use super::geom::{Frame, V3, sub};
use super::smooth;

/// The shape of a primitive in its local frame (axis `z`, centre at the origin). Heights are
/// half heights along `z`.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind {
    /// `|x| <= half[0]`, `|y| <= half[1]`, `|z| <= half[2]`.
    Box {
        /// Half extents.
        half: V3,
    },
    /// Circular cylinder of axis `z`.
    Cylinder {
        /// Radius.
        radius: f64,
        /// Half height.
        half_height: f64,
    },
    /// Cone frustum of axis `z`: radius `r_bottom` at `z = -half_height`, `r_top` at
    /// `z = +half_height` (either may be 0: a full cone).
    Cone {
        /// Radius at the bottom.
        r_bottom: f64,
        /// Radius at the top.
        r_top: f64,
        /// Half height.
        half_height: f64,
    },
    /// Ball.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// Torus of axis `z`: tube of radius `minor` around the circle of radius `major`.
    Torus {
        /// Radius of the centre circle.
        major: f64,
        /// Radius of the tube (`< major`).
        minor: f64,
    },
    /// Extrusion along `z` of a convex polygon (counter-clockwise, at least 3 corners).
    Prism {
        /// Corners of the polygon in the `xy` plane.
        polygon: Vec<[f64; 2]>,
        /// Half height.
        half_height: f64,
    },
    /// A box whose 12 edges are rounded by a fillet of radius `radius` (`< min(half)`): six
    /// faces, twelve quarter cylinders, eight sphere corners, tangent-continuous.
    RoundedBox {
        /// Half extents.
        half: V3,
        /// Fillet radius.
        radius: f64,
    },
    /// A cylinder of axis `z` whose two rims are rounded by a fillet of radius `fillet`
    /// (`< min(radius, half_height)`): side, caps and two quarter tori.
    RoundedCylinder {
        /// Radius.
        radius: f64,
        /// Half height.
        half_height: f64,
        /// Fillet radius of the rims.
        fillet: f64,
    },
    /// An ellipsoid of semi-axes `radii` along the local axes (free-form: no edge, varying
    /// curvature).
    Ellipsoid {
        /// Semi-axes.
        radii: V3,
    },
    /// Extrusion along `z` of a stadium: the points of the `xy` plane within `radius` of the
    /// segment from `(-half_length, 0)` to `(half_length, 0)`.
    Slot {
        /// Half the distance between the two round ends' centres.
        half_length: f64,
        /// Radius of the round ends (half the width).
        radius: f64,
        /// Half height.
        half_height: f64,
    },
}

impl Kind {
    /// The name of the kind (`"box"`, `"cylinder"`, `"cone"`, `"sphere"`, `"torus"`, `"prism"`,
    /// `"slot"`, `"rounded box"`, `"rounded cylinder"`, `"ellipsoid"`).
    pub fn name(&self) -> &'static str {
        match self {
            Kind::RoundedBox { .. } => "rounded box",
            Kind::RoundedCylinder { .. } => "rounded cylinder",
            Kind::Ellipsoid { .. } => "ellipsoid",
            Kind::Box { .. } => "box",
            Kind::Cylinder { .. } => "cylinder",
            Kind::Cone { .. } => "cone",
            Kind::Sphere { .. } => "sphere",
            Kind::Torus { .. } => "torus",
            Kind::Prism { .. } => "prism",
            Kind::Slot { .. } => "slot",
        }
    }

    /// The same kind with every length multiplied by `s > 0`.
    pub(crate) fn scaled(&self, s: f64) -> Kind {
        match self {
            Kind::RoundedBox { half, radius } => Kind::RoundedBox {
                half: half.map(|x| x * s),
                radius: radius * s,
            },
            Kind::RoundedCylinder {
                radius,
                half_height,
                fillet,
            } => Kind::RoundedCylinder {
                radius: radius * s,
                half_height: half_height * s,
                fillet: fillet * s,
            },
            Kind::Ellipsoid { radii } => Kind::Ellipsoid {
                radii: radii.map(|x| x * s),
            },
            Kind::Box { half } => Kind::Box {
                half: half.map(|x| x * s),
            },
            Kind::Cylinder {
                radius,
                half_height,
            } => Kind::Cylinder {
                radius: radius * s,
                half_height: half_height * s,
            },
            Kind::Cone {
                r_bottom,
                r_top,
                half_height,
            } => Kind::Cone {
                r_bottom: r_bottom * s,
                r_top: r_top * s,
                half_height: half_height * s,
            },
            Kind::Sphere { radius } => Kind::Sphere { radius: radius * s },
            Kind::Torus { major, minor } => Kind::Torus {
                major: major * s,
                minor: minor * s,
            },
            Kind::Prism {
                polygon,
                half_height,
            } => Kind::Prism {
                polygon: polygon.iter().map(|v| [v[0] * s, v[1] * s]).collect(),
                half_height: half_height * s,
            },
            Kind::Slot {
                half_length,
                radius,
                half_height,
            } => Kind::Slot {
                half_length: half_length * s,
                radius: radius * s,
                half_height: half_height * s,
            },
        }
    }

    /// Exact inside test (closed set) of a local point.
    pub fn inside_local(&self, q: V3) -> bool {
        let [x, y, z] = q;
        match self {
            Kind::RoundedBox { half, radius } => smooth::rounded_box_inside(*half, *radius, q),
            Kind::RoundedCylinder {
                radius,
                half_height,
                fillet,
            } => smooth::rounded_cylinder_inside(*radius, *half_height, *fillet, q),
            Kind::Ellipsoid { radii } => smooth::ellipsoid_inside(*radii, q),
            Kind::Box { half } => x.abs() <= half[0] && y.abs() <= half[1] && z.abs() <= half[2],
            Kind::Cylinder {
                radius,
                half_height,
            } => z.abs() <= *half_height && x * x + y * y <= radius * radius,
            Kind::Cone {
                r_bottom,
                r_top,
                half_height,
            } => {
                if z.abs() > *half_height {
                    return false;
                }
                let t = (z + half_height) / (2.0 * half_height);
                let r = r_bottom + (r_top - r_bottom) * t;
                x * x + y * y <= r * r
            }
            Kind::Sphere { radius } => x * x + y * y + z * z <= radius * radius,
            Kind::Torus { major, minor } => {
                let d = (x * x + y * y).sqrt() - major;
                d * d + z * z <= minor * minor
            }
            Kind::Prism {
                polygon,
                half_height,
            } => {
                if z.abs() > *half_height {
                    return false;
                }
                let n = polygon.len();
                (0..n).all(|k| {
                    let a = polygon[k];
                    let b = polygon[(k + 1) % n];
                    (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]) >= 0.0
                })
            }
            Kind::Slot {
                half_length,
                radius,
                half_height,
            } => {
                if z.abs() > *half_height {
                    return false;
                }
                let dx = x - x.clamp(-half_length, *half_length);
                dx * dx + y * y <= radius * radius
            }
        }
    }

    /// Local axis-aligned bounding box `(min, max)`.
    pub(crate) fn local_box(&self) -> (V3, V3) {
        let h = match self {
            Kind::RoundedBox { half, .. } => *half,
            Kind::RoundedCylinder {
                radius,
                half_height,
                ..
            } => [*radius, *radius, *half_height],
            Kind::Ellipsoid { radii } => *radii,
            Kind::Box { half } => *half,
            Kind::Cylinder {
                radius,
                half_height,
            } => [*radius, *radius, *half_height],
            Kind::Cone {
                r_bottom,
                r_top,
                half_height,
            } => {
                let r = r_bottom.max(*r_top);
                [r, r, *half_height]
            }
            Kind::Sphere { radius } => [*radius; 3],
            Kind::Torus { major, minor } => [major + minor, major + minor, *minor],
            Kind::Prism {
                polygon,
                half_height,
            } => {
                let mut lo = [f64::INFINITY; 2];
                let mut hi = [f64::NEG_INFINITY; 2];
                for v in polygon {
                    for k in 0..2 {
                        lo[k] = lo[k].min(v[k]);
                        hi[k] = hi[k].max(v[k]);
                    }
                }
                return ([lo[0], lo[1], -half_height], [hi[0], hi[1], *half_height]);
            }
            Kind::Slot {
                half_length,
                radius,
                half_height,
            } => [half_length + radius, *radius, *half_height],
        };
        ([-h[0], -h[1], -h[2]], h)
    }

    /// Areas of the surface parts, in the order [`Kind::sample_part`] uses, restricted to the
    /// local box `clip` where that is simple: faces and caps outside it get area 0 and side
    /// walls keep only their slab `clip.lo[2] <= z <= clip.hi[2]` (the box also clips its
    /// faces in the other two directions). The restricted parts cover every point of the
    /// surface inside `clip`.
    pub(crate) fn part_areas(&self, clip: &Clip) -> Vec<f64> {
        let zr = |h: f64| clip.z_range(h);
        let cap = |z: f64, a: f64| if clip.has_z(z) { a } else { 0.0 };
        match self {
            // Fillets and free-form surfaces: whole parts (clipping only saves samples).
            Kind::RoundedBox { half, radius } => smooth::rounded_box_areas(*half, *radius),
            Kind::RoundedCylinder {
                radius,
                half_height,
                fillet,
            } => smooth::rounded_cylinder_areas(*radius, *half_height, *fillet),
            Kind::Ellipsoid { radii } => vec![smooth::ellipsoid_area(*radii)],
            Kind::Box { half } => (0..6)
                .map(|part| {
                    let (a, sign) = (part / 2, if part % 2 == 0 { 1.0 } else { -1.0 });
                    if !clip.has(a, sign * half[a]) {
                        return 0.0;
                    }
                    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                    let (rb, rc) = (clip.range(b, half[b]), clip.range(c, half[c]));
                    (rb.1 - rb.0).max(0.0) * (rc.1 - rc.0).max(0.0)
                })
                .collect(),
            Kind::Cylinder {
                radius: r,
                half_height: h,
            } => {
                let (z0, z1) = zr(*h);
                let disk = PI * r * r;
                vec![TAU * r * (z1 - z0).max(0.0), cap(*h, disk), cap(-h, disk)]
            }
            Kind::Cone {
                r_bottom: r0,
                r_top: r1,
                half_height: h,
            } => {
                let (z0, z1) = zr(*h);
                let side = if z1 > z0 {
                    let (a, b) = (cone_radius(*r0, *r1, *h, z0), cone_radius(*r0, *r1, *h, z1));
                    PI * (a + b) * ((b - a).powi(2) + (z1 - z0).powi(2)).sqrt()
                } else {
                    0.0
                };
                vec![side, cap(*h, PI * r1 * r1), cap(-h, PI * r0 * r0)]
            }
            Kind::Sphere { radius: r } => {
                let (z0, z1) = zr(*r);
                vec![TAU * r * (z1 - z0).max(0.0)]
            }
            Kind::Torus { major, minor } => vec![4.0 * PI * PI * major * minor],
            Kind::Prism {
                polygon,
                half_height: h,
            } => {
                let a = polygon_area(polygon);
                let (z0, z1) = zr(*h);
                let n = polygon.len();
                let mut v = vec![cap(*h, a), cap(-h, a)];
                for k in 0..n {
                    let (p, q) = (polygon[k], polygon[(k + 1) % n]);
                    v.push((q[0] - p[0]).hypot(q[1] - p[1]) * (z1 - z0).max(0.0));
                }
                v
            }
            Kind::Slot {
                half_length: l,
                radius: r,
                half_height: h,
            } => {
                let (z0, z1) = zr(*h);
                let len = (z1 - z0).max(0.0);
                let c = 4.0 * l * r + PI * r * r;
                vec![
                    cap(*h, c),
                    cap(-h, c),
                    2.0 * l * len,
                    2.0 * l * len,
                    TAU * r * len,
                ]
            }
        }
    }

    /// A uniform sample of surface part `part` (restricted to `clip` as in
    /// [`Kind::part_areas`]) with its outward unit normal (local frame).
    pub(crate) fn sample_part(&self, part: usize, clip: &Clip, rng: &mut impl Rng) -> (V3, V3) {
        let uz = |rng: &mut _, h: f64| {
            let (z0, z1) = clip.z_range(h);
            z0 + (z1 - z0) * u(rng)
        };
        match self {
            Kind::RoundedBox { half, radius } => {
                smooth::rounded_box_sample(*half, *radius, part, rng)
            }
            Kind::RoundedCylinder {
                radius,
                half_height,
                fillet,
            } => smooth::rounded_cylinder_sample(*radius, *half_height, *fillet, part, rng),
            Kind::Ellipsoid { radii } => smooth::ellipsoid_sample(*radii, rng),
            Kind::Box { half } => {
                let axis = part / 2;
                let sign = if part.is_multiple_of(2) { 1.0 } else { -1.0 };
                let mut q = [0.0; 3];
                for k in 0..3 {
                    let (lo, hi) = clip.range(k, half[k]);
                    q[k] = lo + (hi - lo) * u(rng);
                }
                q[axis] = sign * half[axis];
                let mut n = [0.0; 3];
                n[axis] = sign;
                (q, n)
            }
            Kind::Cylinder {
                radius: r,
                half_height: h,
            } => {
                let th = TAU * u(rng);
                let (s, c) = th.sin_cos();
                match part {
                    0 => ([r * c, r * s, uz(rng, *h)], [c, s, 0.0]),
                    _ => {
                        let rho = r * u(rng).sqrt();
                        let sign = if part == 1 { 1.0 } else { -1.0 };
                        ([rho * c, rho * s, sign * h], [0.0, 0.0, sign])
                    }
                }
            }
            Kind::Cone {
                r_bottom: r0,
                r_top: r1,
                half_height: h,
            } => {
                let th = TAU * u(rng);
                let (s, c) = th.sin_cos();
                match part {
                    0 => {
                        // The density of the radius is proportional to the radius: r^2 uniform
                        // between the radii at the ends of the clipped slab.
                        let (z0, z1) = clip.z_range(*h);
                        let (a, b) = (cone_radius(*r0, *r1, *h, z0), cone_radius(*r0, *r1, *h, z1));
                        let (v, w) = (u(rng), u(rng));
                        let (rho, t) = if (b - a).abs() > 1e-12 * a.max(b) {
                            let rho = (a * a + v * (b * b - a * a)).max(0.0).sqrt();
                            (rho, ((rho - a) / (b - a)).clamp(0.0, 1.0))
                        } else {
                            (a, w)
                        };
                        let sl = ((r1 - r0).powi(2) + 4.0 * h * h).sqrt();
                        (
                            [rho * c, rho * s, z0 + (z1 - z0) * t],
                            [2.0 * h * c / sl, 2.0 * h * s / sl, (r0 - r1) / sl],
                        )
                    }
                    _ => {
                        let (r, sign) = if part == 1 { (*r1, 1.0) } else { (*r0, -1.0) };
                        let rho = r * u(rng).sqrt();
                        ([rho * c, rho * s, sign * h], [0.0, 0.0, sign])
                    }
                }
            }
            Kind::Sphere { radius: r } => {
                // Archimedes: z uniform on the clipped range of [-r, r].
                let z = uz(rng, *r);
                let th = TAU * u(rng);
                let rho = (r * r - z * z).max(0.0).sqrt();
                let q = [rho * th.cos(), rho * th.sin(), z];
                (q, q.map(|x| x / r))
            }
            Kind::Torus { major, minor } => {
                let th = TAU * u(rng);
                // Tube angle with density proportional to major + minor cos(phi) (rejection).
                let phi = loop {
                    let phi = TAU * u(rng);
                    if u(rng) * (major + minor) <= major + minor * phi.cos() {
                        break phi;
                    }
                };
                let (st, ct) = th.sin_cos();
                let (sp, cp) = phi.sin_cos();
                let rr = major + minor * cp;
                ([rr * ct, rr * st, minor * sp], [cp * ct, cp * st, sp])
            }
            Kind::Prism {
                polygon,
                half_height: h,
            } => {
                let n = polygon.len();
                if part < 2 {
                    let sign = if part == 0 { 1.0 } else { -1.0 };
                    // Fan triangles from corner 0, picked by area.
                    let areas: Vec<f64> = (1..n - 1)
                        .map(|k| tri_area(polygon[0], polygon[k], polygon[k + 1]))
                        .collect();
                    let k = 1 + pick(&areas, u(rng));
                    let (a, b, c) = (polygon[0], polygon[k], polygon[k + 1]);
                    let (mut s, mut t) = (u(rng), u(rng));
                    if s + t > 1.0 {
                        s = 1.0 - s;
                        t = 1.0 - t;
                    }
                    let x = a[0] + s * (b[0] - a[0]) + t * (c[0] - a[0]);
                    let y = a[1] + s * (b[1] - a[1]) + t * (c[1] - a[1]);
                    ([x, y, sign * h], [0.0, 0.0, sign])
                } else {
                    let k = part - 2;
                    let (a, b) = (polygon[k], polygon[(k + 1) % n]);
                    let t = u(rng);
                    let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
                    let l = ex.hypot(ey);
                    (
                        [a[0] + t * ex, a[1] + t * ey, uz(rng, *h)],
                        [ey / l, -ex / l, 0.0],
                    )
                }
            }
            Kind::Slot {
                half_length: l,
                radius: r,
                half_height: h,
            } => match part {
                0 | 1 => {
                    let sign = if part == 0 { 1.0 } else { -1.0 };
                    let rect = 4.0 * l * r;
                    let disk = PI * r * r;
                    let (x, y) = if u(rng) * (rect + disk) < rect {
                        (l * (2.0 * u(rng) - 1.0), r * (2.0 * u(rng) - 1.0))
                    } else {
                        let rho = r * u(rng).sqrt();
                        let (s, c) = (TAU * u(rng)).sin_cos();
                        let cx = if c >= 0.0 { *l } else { -l };
                        (cx + rho * c, rho * s)
                    };
                    ([x, y, sign * h], [0.0, 0.0, sign])
                }
                2 | 3 => {
                    let sign = if part == 2 { 1.0 } else { -1.0 };
                    (
                        [l * (2.0 * u(rng) - 1.0), sign * r, uz(rng, *h)],
                        [0.0, sign, 0.0],
                    )
                }
                _ => {
                    let (s, c) = (TAU * u(rng)).sin_cos();
                    let cx = if c >= 0.0 { *l } else { -l };
                    ([cx + r * c, r * s, uz(rng, *h)], [c, s, 0.0])
                }
            },
        }
    }
}

impl Kind {
    /// The singular points of surface part `part` (the apex of a pointed cone), local frame,
    /// with the axis direction.
    pub(crate) fn part_apexes(&self, part: usize) -> Vec<(V3, V3)> {
        match self {
            Kind::RoundedBox { .. } | Kind::RoundedCylinder { .. } | Kind::Ellipsoid { .. } => {
                Vec::new()
            }
            Kind::Cone {
                r_bottom,
                r_top,
                half_height,
            } if part == 0 => {
                let mut v = Vec::new();
                if *r_bottom == 0.0 {
                    v.push(([0.0, 0.0, -half_height], [0.0, 0.0, 1.0]));
                }
                if *r_top == 0.0 {
                    v.push(([0.0, 0.0, *half_height], [0.0, 0.0, 1.0]));
                }
                v
            }
            _ => Vec::new(),
        }
    }

    /// Whether the function of [`Kind::patch`] for part `part` is the distance to its whole
    /// surface (all but the ellipsoid's).
    pub(crate) fn part_is_distance(&self, _part: usize) -> bool {
        !matches!(self, Kind::Ellipsoid { .. })
    }

    /// Whether surface part `part` lies on a plane (faces and caps).
    pub(crate) fn part_is_planar(&self, part: usize) -> bool {
        match self {
            Kind::RoundedBox { .. } => part < 6,
            Kind::RoundedCylinder { .. } => part == 1 || part == 2,
            Kind::Ellipsoid { .. } => false,
            Kind::Box { .. } | Kind::Prism { .. } => true,
            Kind::Cylinder { .. } | Kind::Cone { .. } => part > 0,
            Kind::Sphere { .. } | Kind::Torus { .. } => false,
            Kind::Slot { .. } => part < 4,
        }
    }

    /// The smooth surface that carries surface part `part` ([`Kind::sample_part`]'s numbering;
    /// `side` picks the round end of a slot's part 4 by the sign of `x`), as a distance-like
    /// function of a local point: `(g, grad g)` with `g = 0` on the surface, `g > 0` on its
    /// outer side and `|grad g| = 1` (exact distance to the whole plane, sphere, cylinder,
    /// torus or the cone's slanted line; planes for faces and caps).
    pub(crate) fn patch(&self, part: usize, side: i8, q: V3) -> (f64, V3) {
        let [x, y, z] = q;
        let plane = |n: V3, c: f64| (n[0] * x + n[1] * y + n[2] * z - c, n);
        let cap = |sign: f64, h: f64| plane([0.0, 0.0, sign], h);
        let radial = |cx: f64, r: f64| {
            let (dx, dy) = (x - cx, y);
            let rho = dx.hypot(dy);
            if rho > 1e-300 {
                (rho - r, [dx / rho, dy / rho, 0.0])
            } else {
                (-r, [1.0, 0.0, 0.0])
            }
        };
        match self {
            Kind::RoundedBox { half, radius } => smooth::rounded_box_patch(*half, *radius, part, q),
            Kind::RoundedCylinder {
                radius,
                half_height,
                fillet,
            } => smooth::rounded_cylinder_patch(*radius, *half_height, *fillet, part, q),
            Kind::Ellipsoid { radii } => smooth::ellipsoid_patch(*radii, q),
            Kind::Box { half } => {
                let (a, sign) = (part / 2, if part.is_multiple_of(2) { 1.0 } else { -1.0 });
                let mut n = [0.0; 3];
                n[a] = sign;
                plane(n, half[a])
            }
            Kind::Cylinder {
                radius,
                half_height,
            } => match part {
                0 => radial(0.0, *radius),
                1 => cap(1.0, *half_height),
                _ => cap(-1.0, *half_height),
            },
            Kind::Cone {
                r_bottom: r0,
                r_top: r1,
                half_height: h,
            } => match part {
                0 => {
                    // Distance to the line through (r0, -h) and (r1, h) in the (rho, z)
                    // half-plane, positive away from the axis.
                    let sl = ((r1 - r0).powi(2) + 4.0 * h * h).sqrt();
                    let rho = x.hypot(y);
                    let (cx, cy) = if rho > 1e-300 {
                        (x / rho, y / rho)
                    } else {
                        (1.0, 0.0)
                    };
                    let g = ((rho - r0) * 2.0 * h - (z + h) * (r1 - r0)) / sl;
                    (g, [2.0 * h * cx / sl, 2.0 * h * cy / sl, -(r1 - r0) / sl])
                }
                1 => cap(1.0, *h),
                _ => cap(-1.0, *h),
            },
            Kind::Sphere { radius } => {
                let l = (x * x + y * y + z * z).sqrt();
                if l > 1e-300 {
                    (l - radius, [x / l, y / l, z / l])
                } else {
                    (-radius, [0.0, 0.0, 1.0])
                }
            }
            Kind::Torus { major, minor } => {
                let rho = x.hypot(y);
                let (cx, cy) = if rho > 1e-300 {
                    (x / rho, y / rho)
                } else {
                    (1.0, 0.0)
                };
                let (a, b) = (rho - major, z);
                let t = a.hypot(b);
                if t > 1e-300 {
                    (t - minor, [a / t * cx, a / t * cy, b / t])
                } else {
                    (-minor, [cx, cy, 0.0])
                }
            }
            Kind::Prism {
                polygon,
                half_height,
            } => match part {
                0 => cap(1.0, *half_height),
                1 => cap(-1.0, *half_height),
                k => {
                    let n = polygon.len();
                    let (a, b) = (polygon[(k - 2) % n], polygon[(k - 1) % n]);
                    let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
                    let l = ex.hypot(ey);
                    let nn = [ey / l, -ex / l, 0.0];
                    plane(nn, nn[0] * a[0] + nn[1] * a[1])
                }
            },
            Kind::Slot {
                half_length,
                radius,
                half_height,
            } => match part {
                0 => cap(1.0, *half_height),
                1 => cap(-1.0, *half_height),
                2 => plane([0.0, 1.0, 0.0], *radius),
                3 => plane([0.0, -1.0, 0.0], *radius),
                _ => radial(
                    if side >= 0 {
                        *half_length
                    } else {
                        -half_length
                    },
                    *radius,
                ),
            },
        }
    }
}

/// Radius of a cone frustum at height `z`.
fn cone_radius(r0: f64, r1: f64, h: f64, z: f64) -> f64 {
    (r0 + (r1 - r0) * (z + h) / (2.0 * h)).max(0.0)
}

/// A local axis-aligned box that restricts sampling (see [`Kind::part_areas`]); unbounded by
/// default.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Clip {
    /// Lower corner.
    pub lo: V3,
    /// Upper corner.
    pub hi: V3,
}

impl Default for Clip {
    fn default() -> Self {
        Self {
            lo: [f64::NEG_INFINITY; 3],
            hi: [f64::INFINITY; 3],
        }
    }
}

impl Clip {
    /// `[-h, h]` intersected with the clip's range along axis `k`.
    fn range(&self, k: usize, h: f64) -> (f64, f64) {
        (self.lo[k].max(-h), self.hi[k].min(h))
    }
    fn z_range(&self, h: f64) -> (f64, f64) {
        self.range(2, h)
    }
    fn has(&self, k: usize, x: f64) -> bool {
        self.lo[k] <= x && x <= self.hi[k]
    }
    fn has_z(&self, z: f64) -> bool {
        self.has(2, z)
    }
}

/// Uniform in `[0, 1)`.
#[inline]
fn u<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    rng.random::<f64>()
}

/// Area of a counter-clockwise polygon (shoelace).
pub(crate) fn polygon_area(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    0.5 * (0..n)
        .map(|k| {
            let (a, b) = (p[k], p[(k + 1) % n]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum::<f64>()
}

fn tri_area(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])).abs()
}

/// Index `i` with probability `w[i] / sum(w)`, for `r` uniform in `[0, 1)`.
pub(crate) fn pick(w: &[f64], r: f64) -> usize {
    let total: f64 = w.iter().sum();
    let mut x = r * total;
    for (i, &wi) in w.iter().enumerate() {
        if x < wi {
            return i;
        }
        x -= wi;
    }
    // Rounding: the last part with a positive weight.
    w.iter().rposition(|&wi| wi > 0.0).unwrap_or(0)
}

/// A placed primitive: a [`Kind`] and the rigid [`Frame`] that puts it in the world, with its
/// world bounding box and the areas of its (possibly clipped) surface parts cached.
#[derive(Debug, Clone, PartialEq)]
pub struct Primitive {
    kind: Kind,
    frame: Frame,
    lo: V3,
    hi: V3,
    clip: Clip,
    parts: Vec<f64>,
    area: f64,
}

/// Corners of the box `lo..hi` mapped by `f`, and their bounding box.
fn map_box(lo: V3, hi: V3, f: impl Fn(V3) -> V3) -> (V3, V3) {
    let mut a = [f64::INFINITY; 3];
    let mut b = [f64::NEG_INFINITY; 3];
    for c in 0..8 {
        let q = [
            if c & 1 == 0 { lo[0] } else { hi[0] },
            if c & 2 == 0 { lo[1] } else { hi[1] },
            if c & 4 == 0 { lo[2] } else { hi[2] },
        ];
        let p = f(q);
        for k in 0..3 {
            a[k] = a[k].min(p[k]);
            b[k] = b[k].max(p[k]);
        }
    }
    (a, b)
}

impl Primitive {
    /// The primitive `kind` placed by `frame`.
    pub fn new(kind: Kind, frame: Frame) -> Self {
        let (llo, lhi) = kind.local_box();
        let (lo, hi) = map_box(llo, lhi, |q| frame.world_point(q));
        // A hair of slack so that rounding in the frame never rejects a boundary point.
        let pad = 1e-9 * (0..3).map(|k| hi[k] - lo[k]).fold(1.0, f64::max);
        let clip = Clip::default();
        let parts = kind.part_areas(&clip);
        let area = parts.iter().sum();
        Self {
            kind,
            frame,
            lo: lo.map(|x| x - pad),
            hi: hi.map(|x| x + pad),
            clip,
            parts,
            area,
        }
    }

    /// The same primitive whose sampling is restricted to (a superset of) its surface inside
    /// the world box `lo..hi`: [`Primitive::area`] and [`Primitive::sample`] then cover every
    /// surface point in the box and fewer outside it. The inside test is unchanged. An empty
    /// box (`lo > hi` somewhere) leaves nothing to sample.
    pub fn clipped(&self, lo: V3, hi: V3) -> Self {
        let mut out = Self::new(self.kind.clone(), self.frame);
        if (0..3).any(|k| !(lo[k] <= hi[k])) {
            out.parts.iter_mut().for_each(|a| *a = 0.0);
            out.area = 0.0;
            return out;
        }
        let (clo, chi) = map_box(lo, hi, |p| self.frame.local_point(p));
        let pad = 1e-9 * (0..3).map(|k| chi[k] - clo[k]).fold(1.0, f64::max);
        out.clip = Clip {
            lo: clo.map(|x| x - pad),
            hi: chi.map(|x| x + pad),
        };
        let (klo, khi) = self.kind.local_box();
        out.parts = if (0..3).any(|k| klo[k] > out.clip.hi[k] || khi[k] < out.clip.lo[k]) {
            vec![0.0; out.parts.len()]
        } else {
            self.kind.part_areas(&out.clip)
        };
        out.area = out.parts.iter().sum();
        out
    }

    /// The shape in the local frame.
    pub fn kind(&self) -> &Kind {
        &self.kind
    }

    /// The placement.
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// Surface area (of the clipped parts after [`Primitive::clipped`]).
    pub fn area(&self) -> f64 {
        self.area
    }

    /// World bounding box `(min, max)` (slightly padded).
    pub fn bounding_box(&self) -> (V3, V3) {
        (self.lo, self.hi)
    }

    /// Exact inside test (closed set) of a world point.
    #[inline]
    pub fn inside(&self, p: V3) -> bool {
        if (0..3).any(|k| p[k] < self.lo[k] || p[k] > self.hi[k]) {
            return false;
        }
        self.kind.inside_local(self.frame.local_point(p))
    }

    /// An area-uniform sample of the (clipped) surface with its outward unit normal (world
    /// frame). The area must be positive.
    pub fn sample(&self, rng: &mut impl Rng) -> (V3, V3) {
        let part = pick(&self.parts, rng.random::<f64>());
        let (q, n) = self.kind.sample_part(part, &self.clip, rng);
        (self.frame.world_point(q), self.frame.world_dir(n))
    }

    /// Like [`Primitive::sample`], with the surface part the sample lies on and, for the round
    /// ends of a slot, which end (the sign of the local `x`): the arguments of
    /// [`Primitive::patch`].
    pub(crate) fn sample_tagged(&self, rng: &mut impl Rng) -> (V3, V3, u8, i8) {
        let part = pick(&self.parts, rng.random::<f64>());
        let (q, n) = self.kind.sample_part(part, &self.clip, rng);
        let side = if q[0] >= 0.0 { 1 } else { -1 };
        (
            self.frame.world_point(q),
            self.frame.world_dir(n),
            part as u8,
            side,
        )
    }

    /// The singular points of a part (a pointed cone's apex) with the axis, world frame.
    pub(crate) fn apexes(&self, part: u8) -> Vec<(V3, V3)> {
        self.kind
            .part_apexes(part as usize)
            .into_iter()
            .map(|(q, a)| (self.frame.world_point(q), self.frame.world_dir(a)))
            .collect()
    }

    /// The smooth surface carrying a part of this primitive at a world point: `(g, grad g)`
    /// in world coordinates (see [`Kind::patch`]; the frame is rigid, so distances agree).
    pub(crate) fn patch(&self, part: u8, side: i8, p: V3) -> (f64, V3) {
        let (g, n) = self
            .kind
            .patch(part as usize, side, self.frame.local_point(p));
        (g, self.frame.world_dir(n))
    }

    /// The primitive under the similarity `p -> (p - centre) * s` (`s > 0`).
    pub(crate) fn similar(&self, centre: V3, s: f64) -> Self {
        let origin = sub(self.frame.origin, centre).map(|x| x * s);
        Primitive::new(self.kind.scaled(s), Frame::new(self.frame.rot, origin))
    }

    /// The primitive with its frame composed with the rotation `rot` about the world origin.
    pub(crate) fn rotated(&self, rot: &super::geom::M3) -> Self {
        let r = super::geom::mul_mm(rot, &self.frame.rot);
        let o = super::geom::mul_mv(rot, self.frame.origin);
        Primitive::new(self.kind.clone(), Frame::new(r, o))
    }
}

fn fmt3(v: V3) -> String {
    format!("[{:.4}, {:.4}, {:.4}]", v[0], v[1], v[2])
}

impl fmt::Display for Primitive {
    /// E.g. `cylinder(radius=0.1000, half_height=0.2000) at [..] axis z=[..] x=[..]`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.kind {
            Kind::RoundedBox { half, radius } => {
                write!(f, "rounded_box(half={}, radius={radius:.4})", fmt3(*half))?
            }
            Kind::RoundedCylinder {
                radius,
                half_height,
                fillet,
            } => write!(
                f,
                "rounded_cylinder(radius={radius:.4}, half_height={half_height:.4}, fillet={fillet:.4})"
            )?,
            Kind::Ellipsoid { radii } => write!(f, "ellipsoid(radii={})", fmt3(*radii))?,
            Kind::Box { half } => write!(f, "box(half={})", fmt3(*half))?,
            Kind::Cylinder {
                radius,
                half_height,
            } => write!(
                f,
                "cylinder(radius={radius:.4}, half_height={half_height:.4})"
            )?,
            Kind::Cone {
                r_bottom,
                r_top,
                half_height,
            } => write!(
                f,
                "cone(r_bottom={r_bottom:.4}, r_top={r_top:.4}, half_height={half_height:.4})"
            )?,
            Kind::Sphere { radius } => write!(f, "sphere(radius={radius:.4})")?,
            Kind::Torus { major, minor } => write!(f, "torus(major={major:.4}, minor={minor:.4})")?,
            Kind::Prism {
                polygon,
                half_height,
            } => {
                let p: Vec<String> = polygon
                    .iter()
                    .map(|v| format!("({:.4}, {:.4})", v[0], v[1]))
                    .collect();
                write!(
                    f,
                    "prism(polygon=[{}], half_height={half_height:.4})",
                    p.join(", ")
                )?
            }
            Kind::Slot {
                half_length,
                radius,
                half_height,
            } => write!(
                f,
                "slot(half_length={half_length:.4}, radius={radius:.4}, half_height={half_height:.4})"
            )?,
        }
        write!(
            f,
            " at {} z={} x={}",
            fmt3(self.frame.origin),
            fmt3(self.frame.axis()),
            fmt3(super::geom::column(&self.frame.rot, 0))
        )
    }
}

/// Checks used by the unit tests: the local point is on the surface (within `tol`).
#[cfg(test)]
pub(crate) fn on_surface(kind: &Kind, q: V3, n: V3, tol: f64) -> bool {
    use super::geom::add;
    let out = add(q, n.map(|x| x * tol));
    let inn = sub(q, n.map(|x| x * tol));
    kind.inside_local(inn) && !kind.inside_local(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::geom::{IDENTITY, add, norm, random_rotation};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn kinds() -> Vec<Kind> {
        vec![
            Kind::Box {
                half: [0.3, 0.2, 0.1],
            },
            Kind::Cylinder {
                radius: 0.3,
                half_height: 0.2,
            },
            Kind::Cone {
                r_bottom: 0.4,
                r_top: 0.1,
                half_height: 0.3,
            },
            Kind::Cone {
                r_bottom: 0.0,
                r_top: 0.3,
                half_height: 0.2,
            },
            Kind::Sphere { radius: 0.4 },
            Kind::Torus {
                major: 0.4,
                minor: 0.1,
            },
            Kind::Prism {
                polygon: vec![[0.3, 0.0], [0.0, 0.4], [-0.3, -0.1], [0.1, -0.3]],
                half_height: 0.15,
            },
            Kind::Slot {
                half_length: 0.3,
                radius: 0.1,
                half_height: 0.05,
            },
            Kind::RoundedBox {
                half: [0.3, 0.2, 0.15],
                radius: 0.05,
            },
            Kind::RoundedCylinder {
                radius: 0.3,
                half_height: 0.2,
                fillet: 0.06,
            },
            Kind::Ellipsoid {
                radii: [0.4, 0.25, 0.15],
            },
        ]
    }

    /// The ellipsoid's area against the closed form of a prolate spheroid, and its sampling
    /// against the spheroid's exact area share above half its height.
    #[test]
    fn ellipsoid_area_and_sampling() {
        let (a, c) = (0.2f64, 0.5f64);
        let e = (1.0 - a * a / (c * c)).sqrt();
        let want = 2.0 * PI * a * a * (1.0 + c / (a * e) * e.asin());
        let got = smooth::ellipsoid_area([a, a, c]);
        assert!((got - want).abs() < 2e-5 * want, "{got} vs {want}");
        // Area of the cap z > c/2: 2 pi a/c int_{c/2}^{c} sqrt(c^2 - e^2 z^2) dz.
        let f =
            |z: f64| 0.5 * (z * (c * c - e * e * z * z).sqrt() + c * c / e * (e * z / c).asin());
        let cap = 2.0 * PI * a / c * (f(c) - f(0.5 * c));
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        let n = 200_000;
        let hits = (0..n)
            .filter(|_| smooth::ellipsoid_sample([a, a, c], &mut rng).0[2] > 0.5 * c)
            .count() as f64
            / n as f64;
        assert!(
            (hits - cap / want).abs() < 0.004,
            "{hits} vs {}",
            cap / want
        );
    }

    #[test]
    fn samples_lie_on_the_surface_with_outward_normals() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for kind in kinds() {
            for _ in 0..2000 {
                let clip = Clip::default();
                let part = pick(&kind.part_areas(&clip), rng.random());
                let (q, n) = kind.sample_part(part, &clip, &mut rng);
                assert!((norm(n) - 1.0).abs() < 1e-12, "{kind:?}");
                assert!(on_surface(&kind, q, n, 1e-7), "{kind:?} {q:?} {n:?}");
            }
        }
    }

    /// The fraction of samples in a slab against the slab's share of the exact area.
    #[test]
    fn sampling_is_area_uniform() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // Sphere: every z-slab of equal height has the same area (Archimedes).
        // Cone side: area below the middle height is (3 r0 + r1) / (4 (r0 + r1)) of the side.
        let cone = Kind::Cone {
            r_bottom: 0.4,
            r_top: 0.1,
            half_height: 0.3,
        };
        let n = 200_000;
        let below = (0..n)
            .filter(|_| cone.sample_part(0, &Clip::default(), &mut rng).0[2] < 0.0)
            .count() as f64
            / n as f64;
        let want = (3.0 * 0.4 + 0.1) / (4.0 * 0.5);
        assert!((below - want).abs() < 0.005, "{below} vs {want}");
        // Torus: the outer half (cos phi > 0) has area share 1/2 + minor / (pi major).
        let torus = Kind::Torus {
            major: 0.4,
            minor: 0.1,
        };
        let outer = (0..n)
            .filter(|_| {
                let (q, _) = torus.sample_part(0, &Clip::default(), &mut rng);
                q[0].hypot(q[1]) > 0.4
            })
            .count() as f64
            / n as f64;
        let want = 0.5 + 0.1 / (PI * 0.4);
        assert!((outer - want).abs() < 0.005, "{outer} vs {want}");
    }

    /// Clipped sampling covers the surface inside the box with the same density.
    #[test]
    fn clipped_sampling_keeps_the_density_inside_the_box() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 40_000;
        for kind in kinds() {
            let frame = Frame::new(random_rotation(&mut rng), [0.05, -0.02, 0.03]);
            let full = Primitive::new(kind.clone(), frame);
            let (lo, hi) = ([-0.1, -0.3, -0.15], [0.35, 0.2, 0.1]);
            let clipped = full.clipped(lo, hi);
            assert!(clipped.area() <= full.area() * (1.0 + 1e-12));
            let inside_box = |p: V3| (0..3).all(|k| lo[k] <= p[k] && p[k] <= hi[k]);
            let mut density = [0.0; 2];
            for (j, prim) in [&full, &clipped].into_iter().enumerate() {
                let hits = (0..n)
                    .filter(|_| {
                        let (x, nn) = prim.sample(&mut rng);
                        assert!(prim.inside(sub(x, nn.map(|c| c * 1e-7))));
                        assert!(!prim.inside(add(x, nn.map(|c| c * 1e-7))));
                        inside_box(x)
                    })
                    .count();
                // Area of the surface inside the box, estimated.
                density[j] = prim.area() * hits as f64 / n as f64;
            }
            let tol = 0.05 * density[0] + 2e-3;
            assert!(
                (density[0] - density[1]).abs() < tol,
                "{kind:?} {density:?}"
            );
        }
    }

    #[test]
    fn placed_primitives_agree_with_their_local_shape() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for kind in kinds() {
            let frame = Frame::new(random_rotation(&mut rng), [0.1, -0.2, 0.3]);
            let p = Primitive::new(kind.clone(), frame);
            for _ in 0..500 {
                let (x, n) = p.sample(&mut rng);
                assert!(p.inside(sub(x, n.map(|c| c * 1e-7))));
                assert!(!p.inside(add(x, n.map(|c| c * 1e-7))));
            }
            let q = Primitive::new(kind, Frame::new(IDENTITY, [0.0; 3])).similar([1.0; 3], 2.0);
            assert!((q.area() - 4.0 * p.area()).abs() < 1e-9 * p.area());
        }
    }
}
