//! Fits of the map from a field's value to the distance, on (value, distance) pairs.

/// A monotone non-decreasing map from a field's value `u` to the distance: piecewise linear
/// through its knots in the coordinate `s = S(u)`, continued past the outermost knots along
/// their segments' lines. `S` makes the field nearly linear in the distance, so that sparse
/// knots interpolate well: first `w = sign(u) |u|^(1/p)` for a field that grows as the
/// distance to the power `p` near its surface (`d |d|`: `p = 2`; 1 for the others), then, on a
/// side where the field saturates (`tanh`, an occupancy: it approaches a value `a` far from the
/// surface, exponentially in the distance), `-a' ln(1 - w / a')` (`a' = w(a)`), which is `w`
/// near 0 and linear in the distance near `a` (linear interpolation in `u` would put a value
/// between knots 1 and 2 cells out a fifth of a cell off).
///
/// Invariants: at least two knots, their `s` strictly increasing, distances non-decreasing.
#[derive(Debug, Clone, PartialEq)]
pub struct MonotoneMap {
    /// Knots: `S(u)` and the distance.
    s: Vec<f64>,
    d: Vec<f64>,
    /// The values the field saturates at below and above 0 (`NaN`: it does not).
    lo: f64,
    hi: f64,
    /// The field's power law near its surface (`p` above).
    power: f64,
}

impl MonotoneMap {
    /// `S(u)` ([`MonotoneMap`]).
    fn s_of(&self, u: f64) -> f64 {
        let pw = |x: f64| {
            if self.power == 1.0 {
                x
            } else {
                x.signum() * x.abs().powf(1.0 / self.power)
            }
        };
        let w = pw(u);
        let a = pw(if u > 0.0 { self.hi } else { self.lo });
        if !(a.is_finite() && a != 0.0 && (w / a) > 0.0) {
            return w;
        }
        -a * (1.0 - (w / a).min(1.0 - 1e-12)).ln()
    }

    /// The map at `u`.
    pub fn eval(&self, u: f64) -> f64 {
        let s = self.s_of(u);
        let (ss, ds) = (&self.s, &self.d);
        let n = ss.len();
        let seg = |a: usize, b: usize| (ds[b] - ds[a]) / (ss[b] - ss[a]);
        if s <= ss[0] {
            return ds[0] - (ss[0] - s) * seg(0, 1);
        }
        if s >= ss[n - 1] {
            return ds[n - 1] + (s - ss[n - 1]) * seg(n - 2, n - 1);
        }
        let i = ss.partition_point(|&x| x <= s).clamp(1, n - 1);
        ds[i - 1] + (s - ss[i - 1]) * seg(i - 1, i)
    }

    /// Whether the field's slope at its zero set is not far smaller than farther out: its
    /// value 2 cells out at most 6 times its value half a cell out, on both sides (4 for a
    /// distance, about 2 for `tanh`, 16 for `d |d|`). The zero set of a field whose slope
    /// vanishes there is placed poorly between nodes, and its distances are not worth
    /// refining against.
    pub fn has_slope_at_zero(&self, cells: f64) -> bool {
        [1.0, -1.0].iter().all(|&s| {
            let near = self.eval_d_to_u(s * 0.5 * cells);
            let far = self.eval_d_to_u(s * 2.0 * cells);
            let r = far / near;
            r.is_finite() && r > 0.0 && r <= 6.0
        })
    }

    /// The value `u` whose distance is `d` (the inverse, by bisection).
    fn eval_d_to_u(&self, d: f64) -> f64 {
        let (mut lo, mut hi) = (-1.0f64, 1.0f64);
        while self.eval(lo) > d && lo > -1e30 {
            lo *= 2.0;
        }
        while self.eval(hi) < d && hi < 1e30 {
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.eval(mid) < d {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// The power law near the surface the map undoes (1: none; [`MonotoneMap`]).
    pub fn power(&self) -> f64 {
        self.power
    }

    /// The knots (`S(value)`, distance).
    pub fn knots(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.s.iter().copied().zip(self.d.iter().copied())
    }
}

/// The factor `c` of `value = c * distance` (the median of `value / distance` over pairs
/// farther than a quarter cell), and whether the pairs follow it at every distance: the
/// median of `value / distance` in each band of distance (a quarter to 1, 1 to 2, 2 to 3, 3 to
/// 5 cells; bands of at least 20 pairs, at least two of them) within 3% of `c`. `None` without
/// enough pairs.
pub fn fit_linear(pairs: &[(f64, f64)], h: f64) -> Option<(f64, bool)> {
    let mut all: Vec<f64> = pairs
        .iter()
        .filter(|(_, d)| d.abs() >= 0.25 * h)
        .map(|(u, d)| u / d)
        .collect();
    if all.len() < 40 {
        return None;
    }
    let c = median(&mut all);
    if !(c > 0.0 && c.is_finite()) {
        return None;
    }
    let bands = [(0.25, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 5.0)];
    let mut counted = 0;
    let mut linear = true;
    for (lo, hi) in bands {
        let mut r: Vec<f64> = pairs
            .iter()
            .filter(|(_, d)| d.abs() >= lo * h && d.abs() < hi * h)
            .map(|(u, d)| u / d)
            .collect();
        if r.len() < 20 {
            continue;
        }
        counted += 1;
        let m = median(&mut r);
        if (m / c - 1.0).abs() > 0.03 {
            linear = false;
        }
    }
    Some((c, linear && counted >= 2))
}

/// The monotone map from value to distance: the pairs sorted by value in bins of equal counts
/// (at least 3 pairs, at most 256 bins), each bin's median value and median distance a knot,
/// the knot (0, 0) added, then made non-decreasing (pool-adjacent-violators). `extremes` are
/// the values the field saturates at below and above 0 (its asymptotes, [`MonotoneMap`];
/// `NaN` where it does not); `h` is the cell. Returns the map and its median absolute error on
/// the pairs. `None` without at least 100
/// pairs.
pub fn fit_monotone(
    pairs: &[(f64, f64)],
    extremes: (f64, f64),
    h: f64,
) -> Option<(MonotoneMap, f64)> {
    if pairs.len() < 100 {
        return None;
    }
    let mut p: Vec<(f64, f64)> = pairs.to_vec();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    let bins = (p.len() / 3).clamp(4, 256);
    let mut knots: Vec<(f64, f64, f64)> = Vec::with_capacity(bins + 1); // (u, d, weight)
    for b in 0..bins {
        let lo = b * p.len() / bins;
        let hi = (b + 1) * p.len() / bins;
        let mut us: Vec<f64> = p[lo..hi].iter().map(|x| x.0).collect();
        let mut ds: Vec<f64> = p[lo..hi].iter().map(|x| x.1).collect();
        knots.push((median(&mut us), median(&mut ds), (hi - lo) as f64));
    }
    // The zero set is where the value is zero: a knot of its own, weighted as a bin.
    let w0 = (p.len() / bins) as f64;
    knots.push((0.0, 0.0, w0));
    knots.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Pool adjacent violators: non-decreasing distances, weighted means of pooled knots.
    let mut pooled: Vec<(f64, f64, f64)> = Vec::new();
    for k in knots {
        pooled.push(k);
        while pooled.len() >= 2 {
            let n = pooled.len();
            let (a, b) = (pooled[n - 2], pooled[n - 1]);
            if a.1 <= b.1 {
                break;
            }
            let w = a.2 + b.2;
            pooled.truncate(n - 2);
            pooled.push(((a.0 * a.2 + b.0 * b.2) / w, (a.1 * a.2 + b.1 * b.2) / w, w));
        }
    }
    // Strictly increasing values (merge equal ones).
    let mut u: Vec<f64> = Vec::new();
    let mut d: Vec<f64> = Vec::new();
    for (ku, kd, _) in pooled {
        if u.last().is_some_and(|&l| ku <= l) {
            let l = d.len() - 1;
            d[l] = d[l].max(kd);
            continue;
        }
        u.push(ku);
        d.push(kd);
    }
    if u.len() < 2 {
        return None;
    }
    let mut map = MonotoneMap {
        s: Vec::new(),
        d,
        lo: extremes.0,
        hi: extremes.1,
        power: power_law(pairs, h),
    };
    map.s = u.iter().map(|&x| map.s_of(x)).collect();
    if map.s.windows(2).any(|w| w[1] <= w[0]) {
        return None;
    }
    let mut err: Vec<f64> = pairs
        .iter()
        .map(|&(u, d)| (map.eval(u) - d).abs())
        .collect();
    let e = median(&mut err);
    Some((map, e))
}

/// The power `p` of `|u| ~ |d|^p` of a field that grows faster than the distance: the
/// least-squares slope of `ln |u|` over `ln |d|` for the pairs from 1 to 4 cells out (`h` the
/// cell; nearer pairs carry the error of a zero set placed by linear interpolation, which such
/// a field makes large), when it is at least 1.4 (clamped to 4); else 1 (distances, and fields
/// that saturate: their slope there is below 1).
fn power_law(pairs: &[(f64, f64)], h: f64) -> f64 {
    let (xs, ys): (Vec<f64>, Vec<f64>) = pairs
        .iter()
        .filter(|(u, d)| *u != 0.0 && d.abs() >= h && d.abs() <= 4.0 * h)
        .map(|&(u, d)| (d.abs().ln(), u.abs().ln()))
        .unzip();
    if xs.len() < 30 {
        return 1.0;
    }
    let n = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    if !(sxx > 1e-6) {
        return 1.0;
    }
    let p = sxy / sxx;
    if p.is_finite() && p >= 1.4 {
        p.min(4.0)
    } else {
        1.0
    }
}

/// The median (upper middle) of `v`; `NaN` for an empty slice.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let n = v.len() / 2;
    *v.select_nth_unstable_by(n, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pairs_of(f: impl Fn(f64) -> f64, h: f64) -> Vec<(f64, f64)> {
        (0..2000)
            .map(|i| {
                let d = (i as f64 / 2000.0 - 0.5) * 10.0 * h;
                (f(d), d)
            })
            .collect()
    }

    #[test]
    fn linear_fields_are_found_with_their_factor() {
        let h = 0.0625;
        let (c, linear) = fit_linear(&pairs_of(|d| 16.0 * d, h), h).unwrap();
        assert!((c - 16.0).abs() < 1e-9 && linear);
        let (_, linear) = fit_linear(&pairs_of(|d| (d / h).tanh(), h), h).unwrap();
        assert!(!linear);
        let (_, linear) = fit_linear(&pairs_of(|d| d * d.abs(), h), h).unwrap();
        assert!(!linear);
    }

    #[test]
    fn monotone_fields_are_inverted() {
        let h = 0.0625;
        for (i, f) in [
            (|d: f64| (d / 0.0625).tanh()) as fn(f64) -> f64,
            |d| 1.0 / (1.0 + (-d / 0.0625).exp()) - 0.5,
            |d| d * d.abs(),
        ]
        .into_iter()
        .enumerate()
        {
            let p = pairs_of(f, h);
            // The saturating fields' asymptotes.
            let ext = if i < 2 {
                (f(-1.0), f(1.0))
            } else {
                (f64::NAN, f64::NAN)
            };
            let (map, err) = fit_monotone(&p, ext, h).unwrap();
            assert!(err < 0.05 * h, "{err}");
            for d in [-3.0 * h, -0.5 * h, 0.0, 0.7 * h, 2.5 * h] {
                assert!(
                    (map.eval(f(d)) - d).abs() < 0.1 * h,
                    "{d}: {}",
                    map.eval(f(d))
                );
            }
            // tanh and sigmoid have a slope at zero, d |d| has none.
            assert_eq!(map.has_slope_at_zero(h), i < 2, "{i}");
            // Saturating fields map their far values (past the pairs, 5 cells) far too.
            if i < 2 {
                assert!(
                    map.eval(f(8.0 * h)) > 6.0 * h,
                    "{i}: {}",
                    map.eval(f(8.0 * h)) / h
                );
                assert!(map.eval(f(-8.0 * h)) < -6.0 * h);
            }
            // Monotone everywhere, also past the knots.
            let mut last = f64::NEG_INFINITY;
            for i in -300..300 {
                let v = map.eval(f64::from(i) * 0.01);
                assert!(v >= last);
                last = v;
            }
        }
    }
}
