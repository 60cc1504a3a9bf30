//! Small 3-vector helpers on `[f64; 3]`, the point type of the whole crate (nalgebra is kept
//! for the 3x3 / 4x4 linear algebra of quadrics).
//!
//! ```
//! use ponq_mesh::vec3::{cross, dot, sub, unit};
//! let n = cross(sub([1.0, 0.0, 0.0], [0.0; 3]), sub([0.0, 1.0, 0.0], [0.0; 3]));
//! assert_eq!(n, [0.0, 0.0, 1.0]);
//! assert_eq!(dot(unit([0.0, 3.0, 4.0]), [0.0, 0.6, 0.8]), 1.0);
//! ```

/// `a - b`.
#[inline]
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
#[inline]
pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s a`.
#[inline]
pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a x b`.
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a . b`.
#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Euclidean length.
#[inline]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// `a` scaled to unit length; a zero vector is returned unchanged.
#[inline]
pub fn unit(a: [f64; 3]) -> [f64; 3] {
    let l = norm(a);
    if l > 0.0 { a.map(|x| x / l) } else { a }
}
