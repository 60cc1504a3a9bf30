//! Quadric error metrics (QEM).
//!
//! A quadric measures a sum of squared distances to planes:
//! `Q(x) = x^T A x - 2 b^T x + c`, stored as the symmetric 4x4 matrix
//! `[[A, -b], [-b^T, c]]` so that `Q(x) = [x, 1]^T Q [x, 1]`.
//! For a single plane through `s` with unit normal `n`: `A = n n^T`, `b = A s`, `c = s^T A s`.

use nalgebra::{Matrix3, Matrix4, SymmetricEigen, Vector3};

/// Relative singular-value cut-off of the pseudo-inverse used to solve for v* (SPEC section 2).
pub const SVD_CUTOFF: f64 = 0.05;

/// A quadric error metric `Q(x) = x^T A x - 2 b^T x + c`.
///
/// Invariant: `a` is symmetric (it is positive semi-definite for quadrics built from planes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quadric {
    /// The 3x3 part `A`.
    pub a: Matrix3<f64>,
    /// The linear part `b` (`Q(x)` has the term `-2 b^T x`).
    pub b: Vector3<f64>,
    /// The constant part.
    pub c: f64,
}

impl Default for Quadric {
    fn default() -> Self {
        Self::zero()
    }
}

impl std::ops::Add for Quadric {
    type Output = Quadric;
    fn add(self, o: Quadric) -> Quadric {
        Quadric {
            a: self.a + o.a,
            b: self.b + o.b,
            c: self.c + o.c,
        }
    }
}

impl std::ops::AddAssign for Quadric {
    fn add_assign(&mut self, o: Quadric) {
        self.a += o.a;
        self.b += o.b;
        self.c += o.c;
    }
}

impl std::ops::Mul<f64> for Quadric {
    type Output = Quadric;
    fn mul(self, s: f64) -> Quadric {
        Quadric {
            a: self.a * s,
            b: self.b * s,
            c: self.c * s,
        }
    }
}

impl Quadric {
    /// The zero quadric.
    pub fn zero() -> Self {
        Self {
            a: Matrix3::zeros(),
            b: Vector3::zeros(),
            c: 0.0,
        }
    }

    /// `Q(x) = |x - centre|^2` (identity `A`), used for the protective corner points.
    pub fn identity_at(centre: [f64; 3]) -> Self {
        Self::from_a_vstar(Matrix3::identity(), centre)
    }

    /// Squared distance to the plane through `point` with normal `normal` (normalised here;
    /// a zero normal gives the zero quadric).
    pub fn from_plane(point: [f64; 3], normal: [f64; 3]) -> Self {
        let n = Vector3::from(normal);
        let len = n.norm();
        if len == 0.0 || !len.is_finite() {
            return Self::zero();
        }
        let n = n / len;
        let s = Vector3::from(point);
        let d = n.dot(&s);
        Self {
            a: n * n.transpose(),
            b: n * d,
            c: d * d,
        }
    }

    /// `Q(x) = (x - v*)^T A (x - v*)`: `b = A v*`, `c = v*^T A v*`.
    pub fn from_a_vstar(a: Matrix3<f64>, vstar: [f64; 3]) -> Self {
        let v = Vector3::from(vstar);
        let b = a * v;
        Self { a, b, c: v.dot(&b) }
    }

    /// `A = U U^T` from the 6 upper-triangular entries of `U` in the order
    /// (0,0), (0,1), (0,2), (1,1), (1,2), (2,2) (the network's Cholesky head).
    pub fn a_from_upper(u: [f64; 6]) -> Matrix3<f64> {
        let u = Matrix3::new(u[0], u[1], u[2], 0.0, u[3], u[4], 0.0, 0.0, u[5]);
        u * u.transpose()
    }

    /// From a 4x4 matrix `[[A, -b], [-b^T, c]]` (symmetrised).
    pub fn from_matrix4(m: &Matrix4<f64>) -> Self {
        let m = (m + m.transpose()) * 0.5;
        Self {
            a: m.fixed_view::<3, 3>(0, 0).into_owned(),
            b: -m.fixed_view::<3, 1>(0, 3).into_owned(),
            c: m[(3, 3)],
        }
    }

    /// The 4x4 matrix `[[A, -b], [-b^T, c]]`.
    pub fn to_matrix4(&self) -> Matrix4<f64> {
        let mut m = Matrix4::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.a);
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&(-self.b));
        m.fixed_view_mut::<1, 3>(3, 0)
            .copy_from(&(-self.b.transpose()));
        m[(3, 3)] = self.c;
        m
    }

    /// `Q(x)`.
    #[inline]
    pub fn eval(&self, x: [f64; 3]) -> f64 {
        let x = Vector3::from(x);
        x.dot(&(self.a * x)) - 2.0 * self.b.dot(&x) + self.c
    }

    /// Eigenvalues of `A` in decreasing order.
    pub fn eigenvalues(&self) -> [f64; 3] {
        let e = self.a.symmetric_eigenvalues();
        let mut v = [e[0], e[1], e[2]];
        v.sort_by(|x, y| y.total_cmp(x));
        v
    }

    /// Largest eigenvalue of `A` (0 for a zero quadric).
    pub fn largest_eigenvalue(&self) -> f64 {
        self.eigenvalues()[0]
    }

    /// The quadric divided by the largest eigenvalue of `A` (SPEC section 6, step 0).
    /// A quadric whose `A` has no positive eigenvalue is returned unchanged.
    pub fn normalized(&self) -> Self {
        self.scaled_by_largest(self.largest_eigenvalue())
    }

    /// Anisotropy `lambda_2 / lambda_1` of `A` (two largest eigenvalues): near 0 on flat
    /// regions ("pancakes") and open boundaries, near 1 at sharp edges and corners.
    /// A zero `A` gives 0.
    pub fn anisotropy(&self) -> f64 {
        let e = self.eigenvalues();
        if e[0] > 0.0 {
            (e[1] / e[0]).max(0.0)
        } else {
            0.0
        }
    }

    /// The QEM-optimal vertex: the minimiser of `Q` closest to `reference`, computed with the
    /// SVD pseudo-inverse of `A` keeping singular values with `sigma_i / sigma_1 > cutoff`,
    /// relative to `reference`: `v* = r + A^+ (b - A r)`. With `A = 0` this is `reference`.
    pub fn optimal_point(&self, reference: [f64; 3], cutoff: f64) -> [f64; 3] {
        self.optimal_point_and_scale(reference, cutoff).0
    }

    /// [`Quadric::optimal_point`] and [`Quadric::largest_eigenvalue`] from one
    /// eigen-decomposition of `A`.
    pub fn optimal_point_and_scale(&self, reference: [f64; 3], cutoff: f64) -> ([f64; 3], f64) {
        let solve = PseudoInverse::new(self, reference);
        (solve.point(cutoff), solve.eig.eigenvalues.max())
    }

    /// [`Quadric::optimal_point`] for several cut-offs from one eigen-decomposition of `A`.
    pub fn optimal_points<const N: usize>(
        &self,
        reference: [f64; 3],
        cutoffs: [f64; N],
    ) -> [[f64; 3]; N] {
        let solve = PseudoInverse::new(self, reference);
        cutoffs.map(|cutoff| solve.point(cutoff))
    }

    /// The quadric divided by `largest` (its largest eigenvalue, as from
    /// [`Quadric::optimal_point_and_scale`]); unchanged when `largest` is not positive.
    pub fn scaled_by_largest(&self, largest: f64) -> Self {
        if largest > 0.0 && largest.is_finite() {
            *self * (1.0 / largest)
        } else {
            *self
        }
    }
}

/// The eigen-decomposition of a quadric's `A` with the right-hand side around a reference
/// point: [`PseudoInverse::point`] is [`Quadric::optimal_point`] for any cut-off.
struct PseudoInverse {
    reference: [f64; 3],
    r: Vector3<f64>,
    rhs: Vector3<f64>,
    eig: SymmetricEigen<f64, nalgebra::U3>,
    /// The largest `|lambda|` (A is symmetric PSD: its SVD is its eigen-decomposition, with
    /// `|lambda|` as sigma).
    smax: f64,
}

impl PseudoInverse {
    fn new(q: &Quadric, reference: [f64; 3]) -> Self {
        let r = Vector3::from(reference);
        let eig = SymmetricEigen::new(q.a);
        let smax = eig.eigenvalues.iter().fold(0.0f64, |m, &l| m.max(l.abs()));
        Self {
            reference,
            r,
            rhs: q.b - q.a * r,
            eig,
            smax,
        }
    }

    /// `r + A^+ (b - A r)`, keeping the directions with `sigma_i / sigma_1 > cutoff`; the
    /// reference itself for `A = 0` or a non-finite result.
    fn point(&self, cutoff: f64) -> [f64; 3] {
        if !(self.smax > 0.0) || !self.smax.is_finite() {
            return self.reference;
        }
        let mut x = Vector3::zeros();
        for k in 0..3 {
            let l = self.eig.eigenvalues[k];
            if l.abs() / self.smax > cutoff {
                let u = self.eig.eigenvectors.column(k);
                x += u * (u.dot(&self.rhs) / l);
            }
        }
        let v = self.r + x;
        if v.iter().all(|c| c.is_finite()) {
            [v[0], v[1], v[2]]
        } else {
            self.reference
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_quadric_is_squared_distance() {
        let q = Quadric::from_plane([0.0, 0.0, 1.0], [0.0, 0.0, 2.0]);
        assert!((q.eval([3.0, -1.0, 4.0]) - 9.0).abs() < 1e-12);
        let m = Quadric::from_matrix4(&q.to_matrix4());
        assert_eq!(m, q);
    }

    #[test]
    fn optimal_points_match_one_cutoff_at_a_time() {
        let q = Quadric::from_plane([0.1, 0.2, 0.3], [0.0, 0.0, 1.0])
            + Quadric::from_plane([0.0, 0.0, 0.0], [0.0, 0.6, 0.8]) * 0.3
            + Quadric::from_plane([0.5, 0.0, 0.0], [1.0, 0.0, 0.0]) * 0.01;
        let r = [0.3, -0.2, 0.1];
        let cutoffs = [0.0, 0.05, 0.2, 1.0];
        let all = q.optimal_points(r, cutoffs);
        for (c, v) in cutoffs.iter().zip(all) {
            assert_eq!(v, q.optimal_point(r, *c), "cutoff {c}");
        }
        // The cut-offs give different points: the weakest plane is dropped at 0.05.
        assert_ne!(all[0], all[2]);
    }

    #[test]
    fn three_planes_give_their_corner() {
        let q = Quadric::from_plane([1.0, 0.0, 0.0], [1.0, 0.0, 0.0])
            + Quadric::from_plane([0.0, 2.0, 0.0], [0.0, 1.0, 0.0])
            + Quadric::from_plane([0.0, 0.0, -3.0], [0.0, 0.0, 1.0]);
        let v = q.optimal_point([0.0, 0.0, 0.0], SVD_CUTOFF);
        for (a, b) in v.iter().zip([1.0, 2.0, -3.0]) {
            assert!((a - b).abs() < 1e-12);
        }
        assert!((q.anisotropy() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn single_plane_projects_the_reference() {
        let q = Quadric::from_plane([0.0, 0.0, 0.5], [0.0, 0.0, 1.0]);
        let v = q.optimal_point([0.3, -0.2, 0.0], SVD_CUTOFF);
        assert!((v[0] - 0.3).abs() < 1e-12 && (v[1] + 0.2).abs() < 1e-12);
        assert!((v[2] - 0.5).abs() < 1e-12);
        assert!(q.anisotropy() < 1e-12);
    }

    #[test]
    fn one_decomposition_gives_the_point_and_the_scale() {
        let q = Quadric::from_a_vstar(
            Quadric::a_from_upper([1.5, 0.3, -0.2, 0.8, 0.1, 0.05]),
            [0.2, -0.4, 0.7],
        );
        let (v, largest) = q.optimal_point_and_scale([0.1, 0.1, 0.1], SVD_CUTOFF);
        assert_eq!(v, q.optimal_point([0.1, 0.1, 0.1], SVD_CUTOFF));
        assert!((largest - q.largest_eigenvalue()).abs() < 1e-12 * largest);
        let n = q.scaled_by_largest(largest);
        assert!((n.largest_eigenvalue() - 1.0).abs() < 1e-12);
        assert_eq!(Quadric::zero().scaled_by_largest(0.0), Quadric::zero());
    }

    #[test]
    fn cholesky_entries_and_normalisation() {
        let a = Quadric::a_from_upper([2.0, 0.0, 0.0, 1.0, 0.0, 0.5]);
        assert!((a[(0, 0)] - 4.0).abs() < 1e-12 && (a[(2, 2)] - 0.25).abs() < 1e-12);
        let q = Quadric::from_a_vstar(a, [0.1, 0.2, 0.3]).normalized();
        assert!((q.largest_eigenvalue() - 1.0).abs() < 1e-12);
        assert!(q.eval([0.1, 0.2, 0.3]).abs() < 1e-12);
    }
}
