//! Primitives without sharp edges of their own: a box and a cylinder whose edges are rounded by
//! a fillet (tangent-continuous: faces, quarter cylinders or quarter tori, sphere corners), and
//! an ellipsoid (free-form, curvature varying over the surface). They teach the network where
//! a surface bends without a crease. Same contract as the other kinds of [`super::primitive`]:
//! exact inside test, exact part areas, exact area-uniform sampling with true normals, and the
//! smooth surface of every part as a function for the exact distances of
//! [`super::distance`].
//!
//! Part numbering:
//! - rounded box: faces `0..6` (axis `part / 2`, `+` side for even parts), then 12 edges
//!   `6 + 4 axis + 2 (b sign) + (c sign)` (the edge parallel to `axis`, `b, c` the two other
//!   axes in cyclic order), then 8 corners `18 + (x sign) + 2 (y sign) + 4 (z sign)`, a sign
//!   bit 1 meaning `-`;
//! - rounded cylinder: side `0`, caps `1` (top) and `2` (bottom), rims `3` (top) and `4`;
//! - ellipsoid: part `0`.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use rand::Rng;

use super::geom::V3;

#[inline]
fn u<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    rng.random::<f64>()
}

fn sign_of(bit: usize) -> f64 {
    if bit == 0 { 1.0 } else { -1.0 }
}

/// Inside test of a box of half extents `half` with edges rounded by `r`.
pub(crate) fn rounded_box_inside(half: V3, r: f64, q: V3) -> bool {
    let d: V3 = std::array::from_fn(|k| q[k].abs() - (half[k] - r));
    let out = d.iter().map(|x| x.max(0.0).powi(2)).sum::<f64>().sqrt();
    out + d[0].max(d[1]).max(d[2]).min(0.0) <= r
}

/// Areas of the 26 parts of a rounded box.
pub(crate) fn rounded_box_areas(half: V3, r: f64) -> Vec<f64> {
    let inner: V3 = half.map(|h| h - r);
    let mut v = Vec::with_capacity(26);
    for part in 0..6 {
        let a = part / 2;
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        v.push(4.0 * inner[b] * inner[c]);
    }
    for a in 0..3 {
        for _ in 0..4 {
            v.push(FRAC_PI_2 * r * 2.0 * inner[a]);
        }
    }
    for _ in 0..8 {
        v.push(0.5 * PI * r * r);
    }
    v
}

/// Centre of the fillet of edge or corner `part` of a rounded box (`None` for faces), and for an
/// edge its axis.
fn rounded_box_centre(half: V3, r: f64, part: usize) -> (V3, Option<usize>) {
    let inner: V3 = half.map(|h| h - r);
    if (6..18).contains(&part) {
        let e = part - 6;
        let a = e / 4;
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        let mut centre = [0.0; 3];
        centre[b] = sign_of((e >> 1) & 1) * inner[b];
        centre[c] = sign_of(e & 1) * inner[c];
        (centre, Some(a))
    } else {
        let k = part - 18;
        (
            std::array::from_fn(|i| sign_of((k >> i) & 1) * inner[i]),
            None,
        )
    }
}

/// A uniform sample of part `part` of a rounded box, with its outward normal.
pub(crate) fn rounded_box_sample(half: V3, r: f64, part: usize, rng: &mut impl Rng) -> (V3, V3) {
    let inner: V3 = half.map(|h| h - r);
    if part < 6 {
        let a = part / 2;
        let s = sign_of(part % 2);
        let mut q: V3 = std::array::from_fn(|k| inner[k] * (2.0 * u(rng) - 1.0));
        q[a] = s * half[a];
        let mut n = [0.0; 3];
        n[a] = s;
        return (q, n);
    }
    let (centre, axis) = rounded_box_centre(half, r, part);
    let n: V3 = match axis {
        Some(a) => {
            // Quarter circle in the (b, c) plane, towards the signs of the centre.
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let t = FRAC_PI_2 * u(rng);
            let mut n = [0.0; 3];
            n[b] = centre[b].signum() * t.cos();
            n[c] = centre[c].signum() * t.sin();
            n
        }
        None => {
            // Uniform direction of the octant of the centre's signs.
            let d = loop {
                let v: V3 = std::array::from_fn(|_| 2.0 * u(rng) - 1.0);
                let l2 = v.iter().map(|x| x * x).sum::<f64>();
                if l2 > 1e-12 && l2 <= 1.0 {
                    break v.map(|x| x / l2.sqrt());
                }
            };
            std::array::from_fn(|i| d[i].abs() * centre[i].signum())
        }
    };
    let mut q: V3 = std::array::from_fn(|i| centre[i] + r * n[i]);
    if let Some(a) = axis {
        q[a] = inner[a] * (2.0 * u(rng) - 1.0);
    }
    (q, n)
}

/// The smooth surface of part `part` of a rounded box: `(g, grad g)`, distance-like.
pub(crate) fn rounded_box_patch(half: V3, r: f64, part: usize, q: V3) -> (f64, V3) {
    if part < 6 {
        let a = part / 2;
        let s = sign_of(part % 2);
        let mut n = [0.0; 3];
        n[a] = s;
        return (s * q[a] - half[a], n);
    }
    let (centre, axis) = rounded_box_centre(half, r, part);
    let mut d: V3 = std::array::from_fn(|i| q[i] - centre[i]);
    if let Some(a) = axis {
        d[a] = 0.0;
    }
    let l = d.iter().map(|x| x * x).sum::<f64>().sqrt();
    if l > 1e-300 {
        (l - r, d.map(|x| x / l))
    } else {
        (-r, [1.0, 0.0, 0.0])
    }
}

/// Inside test of a cylinder of radius `rad` and half height `h` whose two rims are rounded by
/// `r`.
pub(crate) fn rounded_cylinder_inside(rad: f64, h: f64, r: f64, q: V3) -> bool {
    let d = [q[0].hypot(q[1]) - (rad - r), q[2].abs() - (h - r)];
    let out = d[0].max(0.0).hypot(d[1].max(0.0));
    out + d[0].max(d[1]).min(0.0) <= r
}

/// Areas of the 5 parts of a rounded cylinder.
pub(crate) fn rounded_cylinder_areas(rad: f64, h: f64, r: f64) -> Vec<f64> {
    let m = rad - r;
    let rim = TAU * r * (m * FRAC_PI_2 + r);
    vec![TAU * rad * 2.0 * (h - r), PI * m * m, PI * m * m, rim, rim]
}

/// A uniform sample of part `part` of a rounded cylinder, with its outward normal.
pub(crate) fn rounded_cylinder_sample(
    rad: f64,
    h: f64,
    r: f64,
    part: usize,
    rng: &mut impl Rng,
) -> (V3, V3) {
    let m = rad - r;
    let (s, c) = (TAU * u(rng)).sin_cos();
    match part {
        0 => (
            [rad * c, rad * s, (h - r) * (2.0 * u(rng) - 1.0)],
            [c, s, 0.0],
        ),
        1 | 2 => {
            let sign = if part == 1 { 1.0 } else { -1.0 };
            let rho = m * u(rng).sqrt();
            ([rho * c, rho * s, sign * h], [0.0, 0.0, sign])
        }
        _ => {
            let sign = if part == 3 { 1.0 } else { -1.0 };
            // Tube angle in [0, pi/2] with density proportional to m + r cos(phi).
            let phi = loop {
                let phi = FRAC_PI_2 * u(rng);
                if u(rng) * (m + r) <= m + r * phi.cos() {
                    break phi;
                }
            };
            let (sp, cp) = phi.sin_cos();
            let rho = m + r * cp;
            (
                [rho * c, rho * s, sign * ((h - r) + r * sp)],
                [cp * c, cp * s, sign * sp],
            )
        }
    }
}

/// The smooth surface of part `part` of a rounded cylinder: `(g, grad g)`, distance-like.
pub(crate) fn rounded_cylinder_patch(rad: f64, h: f64, r: f64, part: usize, q: V3) -> (f64, V3) {
    let rho = q[0].hypot(q[1]);
    let (cx, cy) = if rho > 1e-300 {
        (q[0] / rho, q[1] / rho)
    } else {
        (1.0, 0.0)
    };
    match part {
        0 => (rho - rad, [cx, cy, 0.0]),
        1 => (q[2] - h, [0.0, 0.0, 1.0]),
        2 => (-q[2] - h, [0.0, 0.0, -1.0]),
        _ => {
            let zc = if part == 3 { h - r } else { -(h - r) };
            let (a, b) = (rho - (rad - r), q[2] - zc);
            let t = a.hypot(b);
            if t > 1e-300 {
                (t - r, [a / t * cx, a / t * cy, b / t])
            } else {
                (-r, [cx, cy, 0.0])
            }
        }
    }
}

/// Inside test of the ellipsoid of semi-axes `radii`.
pub(crate) fn ellipsoid_inside(radii: V3, q: V3) -> bool {
    (0..3).map(|k| (q[k] / radii[k]).powi(2)).sum::<f64>() <= 1.0
}

/// Area element of the ellipsoid at the image of the unit vector `v`, relative to the unit
/// sphere's: `abc |v / radii|`.
fn ellipsoid_stretch(radii: V3, v: V3) -> f64 {
    let abc = radii[0] * radii[1] * radii[2];
    abc * (0..3)
        .map(|k| (v[k] / radii[k]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Area of the ellipsoid (midpoint quadrature over `cos(theta)` and the azimuth, 256 x 512
/// cells: relative error about 1e-5, which only weighs the ellipsoid against other primitives
/// when sampling).
pub(crate) fn ellipsoid_area(radii: V3) -> f64 {
    let (nz, na) = (256, 512);
    let mut sum = 0.0;
    for i in 0..nz {
        let z = -1.0 + (i as f64 + 0.5) * 2.0 / nz as f64;
        let rho = (1.0 - z * z).max(0.0).sqrt();
        for j in 0..na {
            let t = (j as f64 + 0.5) * TAU / na as f64;
            sum += ellipsoid_stretch(radii, [rho * t.cos(), rho * t.sin(), z]);
        }
    }
    sum * (2.0 / nz as f64) * (TAU / na as f64)
}

/// An area-uniform sample of the ellipsoid with its outward normal: a uniform direction of the
/// sphere, mapped, kept with probability proportional to the area element.
pub(crate) fn ellipsoid_sample(radii: V3, rng: &mut impl Rng) -> (V3, V3) {
    let max = ellipsoid_stretch(radii, [1.0, 0.0, 0.0])
        .max(ellipsoid_stretch(radii, [0.0, 1.0, 0.0]))
        .max(ellipsoid_stretch(radii, [0.0, 0.0, 1.0]));
    loop {
        let z = 2.0 * u(rng) - 1.0;
        let t = TAU * u(rng);
        let rho = (1.0 - z * z).max(0.0).sqrt();
        let v = [rho * t.cos(), rho * t.sin(), z];
        if u(rng) * max <= ellipsoid_stretch(radii, v) {
            let q: V3 = std::array::from_fn(|k| radii[k] * v[k]);
            let g: V3 = std::array::from_fn(|k| v[k] / radii[k]);
            let l = g.iter().map(|x| x * x).sum::<f64>().sqrt();
            return (q, g.map(|x| x / l));
        }
    }
}

/// The ellipsoid's surface as `(g, grad g)` with `g = min(radii) (|q / radii| - 1)`: zero on
/// the surface and never more than the distance to it in absolute value (the map
/// `q -> q / radii` shrinks distances by at most `1 / min(radii)`), so a valid lower bound;
/// not a distance itself (the exact distances use Newton on the closest-point conditions).
pub(crate) fn ellipsoid_patch(radii: V3, q: V3) -> (f64, V3) {
    let m = radii.iter().cloned().fold(f64::MAX, f64::min);
    let w: V3 = std::array::from_fn(|k| q[k] / radii[k]);
    let l = w.iter().map(|x| x * x).sum::<f64>().sqrt();
    if l < 1e-300 {
        return (-m, [0.0, 0.0, 1.0]);
    }
    (
        m * (l - 1.0),
        std::array::from_fn(|k| m * w[k] / (l * radii[k])),
    )
}
