//! Small vector helpers, rigid frames and the point-triangle distance used by the generator.

use std::f64::consts::TAU;

use rand::Rng;

/// A 3D vector / point.
pub type V3 = [f64; 3];

#[inline]
pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub(crate) fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
#[inline]
pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline]
pub(crate) fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
/// `a / |a|`; `fallback` for a zero vector.
#[inline]
pub(crate) fn normalize_or(a: V3, fallback: V3) -> V3 {
    let l = norm(a);
    if l > 0.0 && l.is_finite() {
        scale(a, 1.0 / l)
    } else {
        fallback
    }
}

/// A unit vector perpendicular to the unit vector `n`.
pub(crate) fn any_perpendicular(n: V3) -> V3 {
    let a = if n[0].abs() < 0.6 {
        [1.0, 0.0, 0.0]
    } else if n[1].abs() < 0.6 {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    normalize_or(cross(n, a), [0.0, 0.0, 1.0])
}

/// A 3x3 rotation matrix, row major.
pub type M3 = [[f64; 3]; 3];

/// The identity matrix.
pub(crate) const IDENTITY: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

#[inline]
pub(crate) fn mul_mv(m: &M3, v: V3) -> V3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}
#[inline]
pub(crate) fn mul_mtv(m: &M3, v: V3) -> V3 {
    [
        m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
        m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
        m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2],
    ]
}
pub(crate) fn mul_mm(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// The rotation whose columns are the (orthonormal, right-handed) axes `x`, `y`, `z`.
pub(crate) fn from_columns(x: V3, y: V3, z: V3) -> M3 {
    [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]
}

/// Column `k` of `m` (the image of the local axis `k`).
pub(crate) fn column(m: &M3, k: usize) -> V3 {
    [m[0][k], m[1][k], m[2][k]]
}

/// A uniformly random rotation (Shoemake's uniform quaternion).
pub(crate) fn random_rotation(rng: &mut impl Rng) -> M3 {
    let (u1, u2, u3): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    let (x, y, z, w) = (
        a * (TAU * u2).sin(),
        a * (TAU * u2).cos(),
        b * (TAU * u3).sin(),
        b * (TAU * u3).cos(),
    );
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// One of the 24 rotations that map the coordinate axes onto coordinate axes, at random.
pub(crate) fn random_axis_rotation(rng: &mut impl Rng) -> M3 {
    let perms = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let p = perms[rng.random_range(0..6)];
    let mut m = [[0.0; 3]; 3];
    for (col, &row) in p.iter().enumerate() {
        m[row][col] = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    }
    // Make it a proper rotation (determinant +1).
    let det = dot(column(&m, 0), cross(column(&m, 1), column(&m, 2)));
    if det < 0.0 {
        for row in &mut m {
            row[2] = -row[2];
        }
    }
    m
}

/// A rigid frame: `world = rot * local + origin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Rotation (row major); its columns are the local axes in world coordinates.
    pub rot: M3,
    /// The local origin in world coordinates.
    pub origin: V3,
}

impl Frame {
    /// The frame at `origin` with rotation `rot`.
    pub(crate) fn new(rot: M3, origin: V3) -> Self {
        Self { rot, origin }
    }

    /// The frame at `origin` whose local z axis is the unit vector `z`, turned by `spin` radians
    /// about it.
    pub(crate) fn from_axis(origin: V3, z: V3, spin: f64) -> Self {
        let x0 = any_perpendicular(z);
        let y0 = cross(z, x0);
        let (s, c) = spin.sin_cos();
        let x = add(scale(x0, c), scale(y0, s));
        let y = cross(z, x);
        Self::new(from_columns(x, y, z), origin)
    }

    /// Local point to world.
    #[inline]
    pub(crate) fn world_point(&self, q: V3) -> V3 {
        add(mul_mv(&self.rot, q), self.origin)
    }
    /// Local direction to world.
    #[inline]
    pub(crate) fn world_dir(&self, v: V3) -> V3 {
        mul_mv(&self.rot, v)
    }
    /// World point to local.
    #[inline]
    pub(crate) fn local_point(&self, p: V3) -> V3 {
        mul_mtv(&self.rot, sub(p, self.origin))
    }
    /// The local z axis in world coordinates.
    pub(crate) fn axis(&self) -> V3 {
        column(&self.rot, 2)
    }
}

/// Squared distance from `p` to the closed triangle `(a, b, c)` (Ericson, Real-Time Collision
/// Detection, 5.1.5).
pub fn point_triangle_dist2(p: V3, a: V3, b: V3, c: V3) -> f64 {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    let closest = if d1 <= 0.0 && d2 <= 0.0 {
        a
    } else {
        let bp = sub(p, b);
        let d3 = dot(ab, bp);
        let d4 = dot(ac, bp);
        if d3 >= 0.0 && d4 <= d3 {
            b
        } else {
            let vc = d1 * d4 - d3 * d2;
            if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
                add(a, scale(ab, d1 / (d1 - d3)))
            } else {
                let cp = sub(p, c);
                let d5 = dot(ab, cp);
                let d6 = dot(ac, cp);
                if d6 >= 0.0 && d5 <= d6 {
                    c
                } else {
                    let vb = d5 * d2 - d1 * d6;
                    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
                        add(a, scale(ac, d2 / (d2 - d6)))
                    } else {
                        let va = d3 * d6 - d5 * d4;
                        if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
                            add(b, scale(sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))))
                        } else {
                            let denom = 1.0 / (va + vb + vc);
                            add(a, add(scale(ab, vb * denom), scale(ac, vc * denom)))
                        }
                    }
                }
            }
        }
    };
    let d = sub(p, closest);
    dot(d, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn is_rotation(m: &M3) -> bool {
        let mtm = mul_mm(
            &[
                [m[0][0], m[1][0], m[2][0]],
                [m[0][1], m[1][1], m[2][1]],
                [m[0][2], m[1][2], m[2][2]],
            ],
            m,
        );
        let det = dot(column(m, 0), cross(column(m, 1), column(m, 2)));
        (0..3).all(|i| (0..3).all(|j| (mtm[i][j] - IDENTITY[i][j]).abs() < 1e-12))
            && (det - 1.0).abs() < 1e-12
    }

    #[test]
    fn rotations_are_proper() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..50 {
            assert!(is_rotation(&random_rotation(&mut rng)));
            assert!(is_rotation(&random_axis_rotation(&mut rng)));
        }
        let f = Frame::from_axis(
            [1.0, 2.0, 3.0],
            normalize_or([1.0, -2.0, 0.5], [0.0; 3]),
            0.7,
        );
        assert!(is_rotation(&f.rot));
        let q = [0.3, -0.2, 0.9];
        let back = f.local_point(f.world_point(q));
        assert!(norm(sub(back, q)) < 1e-12);
    }

    #[test]
    fn point_triangle_distance() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        assert!((point_triangle_dist2([0.2, 0.2, 0.5], a, b, c) - 0.25).abs() < 1e-15);
        assert!((point_triangle_dist2([-1.0, -1.0, 0.0], a, b, c) - 2.0).abs() < 1e-15);
        assert!((point_triangle_dist2([1.0, 1.0, 0.0], a, b, c) - 0.5).abs() < 1e-15);
        assert!((point_triangle_dist2([2.0, 0.0, 1.0], a, b, c) - 2.0).abs() < 1e-15);
    }
}
