//! The exact range: the input scaled by a power of two (exact, no predicate changes sign) so
//! that the exact predicates' expansions neither underflow nor overflow ([`ExactRange`]).

/// `x * 2^k`, exact wherever the result is a normal number or `x` is scaled up (in two
/// steps: `2^k` alone need not be a finite `f64`). `k` within `-1100..=1100`.
pub(super) fn times_pow2(x: f64, k: i32) -> f64 {
    let pow2 = |j: i32| f64::from_bits(((j + 1023) as u64) << 52);
    let h = k / 2;
    x * pow2(h) * pow2(k - h)
}

/// How the input is brought into the range where the exact predicates' expansions can
/// neither underflow nor overflow: scaled by `2^k` so that the largest coordinate magnitude
/// is in `[1, 2)` (`k = 0` when it is already within `[2^-10, 2^10]`), and every nonzero
/// coordinate below `2^-140` of that set to 0.
///
/// Why this suffices: a nonzero coordinate is then at least `2^-150` in magnitude, so an
/// integer multiple of `2^-202`; the insphere determinant is a polynomial of degree 5 in the
/// coordinates (orient3d: 3), so every product and rounding error in its exact evaluation is
/// a multiple of `2^-1010`, representable (subnormal floats are the multiples of `2^-1074`),
/// and every magnitude stays far below `2^1024`. Scaling by a power of two is exact and
/// multiplies each determinant by a positive power of two: no predicate changes sign, so the
/// triangulation of the scaled points is that of the input.
#[derive(Debug, Clone, Copy)]
pub(super) struct ExactRange {
    /// The points are multiplied by `2^k`.
    pub(super) k: i32,
    /// Nonzero coordinates below this (after scaling) are set to 0.
    pub(super) snap_below: f64,
}

impl ExactRange {
    pub(super) fn of(points: &[[f64; 3]]) -> Self {
        use rayon::prelude::*;
        // In parallel: the largest of finite numbers is the same in any grouping.
        let m = points
            .par_iter()
            .with_min_len(4096)
            .map(|p| p[0].abs().max(p[1].abs()).max(p[2].abs()))
            .reduce(|| 0.0f64, f64::max);
        if m == 0.0 {
            return Self {
                k: 0,
                snap_below: 0.0,
            };
        }
        let (lo, hi) = (2f64.powi(-10), 2f64.powi(10));
        if (lo..=hi).contains(&m) {
            return Self {
                k: 0,
                snap_below: m * 2f64.powi(-140),
            };
        }
        // floor(log2 m), also for a subnormal m.
        let bits = m.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as i32;
        let e = if biased == 0 {
            -1074 + 63 - (bits & ((1 << 52) - 1)).leading_zeros() as i32
        } else {
            biased - 1023
        };
        Self {
            k: -e,
            snap_below: 2f64.powi(-140),
        }
    }

    /// A length in input units, in the units of the scaled points.
    pub(super) fn scale(&self, x: f64) -> f64 {
        if self.k == 0 {
            x
        } else {
            times_pow2(x, self.k)
        }
    }

    /// The points as the predicates see them, and how many had a coordinate set to 0.
    /// Borrowed (no copy) when nothing changes: the usual case.
    pub(super) fn apply<'a>(
        &self,
        points: &'a [[f64; 3]],
    ) -> (std::borrow::Cow<'a, [[f64; 3]]>, usize) {
        use rayon::prelude::*;
        let tiny = |x: f64| x != 0.0 && x.abs() < self.snap_below;
        if self.k == 0 && !points.par_iter().any(|p| p.iter().any(|&x| tiny(x))) {
            return (std::borrow::Cow::Borrowed(points), 0);
        }
        let mut snapped = 0;
        let out = points
            .iter()
            .map(|p| {
                let q = p.map(|x| self.scale(x));
                if q.iter().any(|&x| tiny(x)) {
                    snapped += 1;
                    q.map(|x| if tiny(x) { 0.0 } else { x })
                } else {
                    q
                }
            })
            .collect();
        (std::borrow::Cow::Owned(out), snapped)
    }
}
