//! [`FieldScan`]: one pass over a grid's planes that collects what the conditioning decides
//! from, then decides ([`FieldScan::finish`]).

use std::collections::BinaryHeap;
use std::time::Instant;

use rayon::prelude::*;

use super::{
    ConditionOptions, Conditioning, FieldKind, Inside, Kind, crossings, fit_linear, fit_monotone,
    pairs,
};
use crate::error::{DataError, Result};

/// Grids of at most this many nodes are kept whole for the analysis (16 MB of `f32`).
const WHOLE_NODES: usize = 1 << 22;
/// Side of the windows sampled from larger grids, in nodes.
const WINDOW: usize = 32;
/// Most windows with a crossing kept from a larger grid.
const MAX_WINDOWS: usize = 48;
/// Fewest pairs to measure a field from; below, it is taken as a distance (with a note).
const MIN_PAIRS: usize = 100;
/// Nodes tried for pairs per analysis at most (strided down to about this many); a first
/// look at fewer decides a distance.
const MAX_TRIED: usize = 200_000;
const QUICK_TRIED: usize = 16_000;
/// Pairs reach this many cells from the zero set.
const PAIR_CELLS: f64 = 6.0;

/// A window being filled plane by plane, and its place in the lattice.
struct Open {
    origin: [usize; 3],
    dims: [usize; 3],
    data: Vec<f32>,
    id: u64,
}

/// One pass over a grid's planes (C order, or the reversed axes of a Fortran-order file: the
/// analysis does not depend on the axes' order) collecting the boundary's signs, the extreme
/// values and windows of nodes around the zero set; [`FieldScan::finish`] decides the
/// [`Conditioning`].
pub struct FieldScan {
    dims: [usize; 3],
    opts: ConditionOptions,
    /// Candidate levels: the one given, or 0 and 0.5.
    levels: Vec<f64>,
    /// Per candidate level: boundary nodes above and below it.
    boundary: Vec<(u64, u64)>,
    min: f64,
    max: f64,
    n_min: u64,
    n_max: u64,
    /// Values within 0.05 of 0 or of 1 (a saturated occupancy has most of them).
    near_0_or_1: u64,
    planes: usize,
    whole: Option<Vec<f32>>,
    open: Vec<Open>,
    /// Windows with a crossing, by priority (a hash of their place: the set kept does not
    /// depend on the order they come in).
    kept: BinaryHeap<(u64, usize)>,
    windows: Vec<Option<Window>>,
    started: Instant,
}

impl FieldScan {
    /// A scan of a grid of `dims` nodes.
    pub fn new(dims: [usize; 3], opts: &ConditionOptions) -> Self {
        let levels = match opts.level {
            Some(l) => vec![l],
            None => vec![0.0, 0.5],
        };
        let nodes = dims.iter().product::<usize>();
        Self {
            dims,
            opts: *opts,
            boundary: vec![(0, 0); levels.len()],
            levels,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            n_min: 0,
            n_max: 0,
            near_0_or_1: 0,
            planes: 0,
            whole: (nodes <= WHOLE_NODES).then(|| Vec::with_capacity(nodes)),
            open: Vec::new(),
            kept: BinaryHeap::new(),
            windows: Vec::new(),
            started: Instant::now(),
        }
    }

    /// Adds the next plane (`dims[1] * dims[2]` values).
    ///
    /// # Errors
    /// A plane of another size, past the last one, or with a non-finite value.
    pub fn push_plane(&mut self, plane: &[f64]) -> Result<()> {
        let [d0, d1, d2] = self.dims;
        if self.dims.contains(&0) {
            return Err(DataError::Invalid(format!(
                "an empty grid: {:?} nodes",
                self.dims
            )));
        }
        if plane.len() != d1 * d2 || self.planes >= d0 {
            return Err(DataError::Invalid(format!(
                "field scan: plane {} of {} values for a grid of {:?} nodes",
                self.planes,
                plane.len(),
                self.dims
            )));
        }
        let i = self.planes;
        if let Some(p) = plane.iter().position(|v| !v.is_finite()) {
            return Err(DataError::Invalid(format!(
                "grid value at [{i}, {}, {}] is {}",
                p / d2,
                p % d2,
                plane[p]
            )));
        }
        for &v in plane {
            if v < self.min {
                self.min = v;
                self.n_min = 0;
            }
            if v == self.min {
                self.n_min += 1;
            }
            if v > self.max {
                self.max = v;
                self.n_max = 0;
            }
            if v == self.max {
                self.n_max += 1;
            }
            if v.abs() <= 0.05 || (v - 1.0).abs() <= 0.05 {
                self.near_0_or_1 += 1;
            }
        }
        // The boundary: whole first and last planes, the border rows and columns of the others.
        let mut count = |v: f64| {
            for (l, b) in self.levels.iter().zip(self.boundary.iter_mut()) {
                if v > *l {
                    b.0 += 1;
                } else if v < *l {
                    b.1 += 1;
                }
            }
        };
        if i == 0 || i + 1 == d0 {
            plane.iter().for_each(|&v| count(v));
        } else {
            for j in 0..d1 {
                if j == 0 || j + 1 == d1 {
                    plane[j * d2..(j + 1) * d2].iter().for_each(|&v| count(v));
                } else {
                    count(plane[j * d2]);
                    count(plane[j * d2 + d2 - 1]);
                }
            }
        }
        match &mut self.whole {
            Some(w) => w.extend(plane.iter().map(|&v| v as f32)),
            None => self.window_plane(i, plane),
        }
        self.planes += 1;
        Ok(())
    }

    /// Feeds plane `i` to the lattice windows.
    fn window_plane(&mut self, i: usize, plane: &[f64]) {
        let [d0, d1, d2] = self.dims;
        // The lattice: windows of WINDOW nodes every `stride` nodes along each axis, so that a
        // layer of windows holds a bounded number of values.
        let stride = WINDOW.max(d1.max(d2).div_ceil(12));
        if i.is_multiple_of(stride) && i + 1 < d0 {
            for j in (0..d1.saturating_sub(1)).step_by(stride) {
                for k in (0..d2.saturating_sub(1)).step_by(stride) {
                    let dims = [WINDOW.min(d0 - i), WINDOW.min(d1 - j), WINDOW.min(d2 - k)];
                    let origin = [i, j, k];
                    let id = fnv(&origin);
                    self.open.push(Open {
                        origin,
                        dims,
                        data: Vec::with_capacity(dims.iter().product()),
                        id,
                    });
                }
            }
        }
        let levels = self.levels.clone();
        let mut done = Vec::new();
        for (n, w) in self.open.iter_mut().enumerate() {
            if i < w.origin[0] || i >= w.origin[0] + w.dims[0] {
                continue;
            }
            for j in w.origin[1]..w.origin[1] + w.dims[1] {
                let row = &plane[j * d2 + w.origin[2]..j * d2 + w.origin[2] + w.dims[2]];
                w.data.extend(row.iter().map(|&v| v as f32));
            }
            if i + 1 == w.origin[0] + w.dims[0] {
                done.push(n);
            }
        }
        for n in done.into_iter().rev() {
            let w = self.open.swap_remove(n);
            let crossing = levels.iter().any(|&l| {
                let (lo, hi) = w
                    .data
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |a, &v| {
                        (a.0.min(v), a.1.max(v))
                    });
                f64::from(lo) < l && f64::from(hi) > l
            });
            if !crossing {
                continue;
            }
            self.windows.push(Some(Window {
                dims: w.dims,
                data: w.data,
            }));
            self.kept.push((w.id, self.windows.len() - 1));
            if self.kept.len() > MAX_WINDOWS
                && let Some((_, drop)) = self.kept.pop()
            {
                self.windows[drop] = None;
            }
        }
    }

    /// The level and the sign the scan decides, and the notes that say so: the first half of
    /// [`FieldScan::finish`].
    ///
    /// # Errors
    /// As [`FieldScan::finish`].
    pub fn level_and_sign(&self) -> Result<(f64, bool, Vec<String>)> {
        if self.planes != self.dims[0] {
            return Err(DataError::Invalid(format!(
                "field scan: {} planes of {}",
                self.planes, self.dims[0]
            )));
        }
        let mut notes = Vec::new();
        let crosses = |l: f64| self.min < l && self.max > l;
        let (level, li) = match self.opts.level {
            Some(l) if crosses(l) => (l, 0),
            Some(l) => {
                return Err(DataError::Invalid(format!(
                    "no sign change: the field's values lie in [{}, {}], all on one side of the \
                     level {l}; give the field's iso-level with --level (level= in Python)",
                    self.min, self.max
                )));
            }
            None if crosses(0.0) => (0.0, 0),
            // An occupancy: values in [0, 1], most of them saturated near 0 or 1.
            None if self.min >= 0.0
                && self.max <= 1.0
                && crosses(0.5)
                && self.near_0_or_1 * 2 >= self.dims.iter().product::<usize>() as u64 =>
            {
                notes.push(
                    "its values lie in [0, 1], most of them near 0 or 1, without a sign change \
                     at 0: meshed at level 0.5 (an occupancy; --level sets another)"
                        .to_string(),
                );
                (0.5, 1)
            }
            None => {
                return Err(DataError::Invalid(format!(
                    "no sign change: the field's values lie in [{}, {}], all on one side of \
                     0; give the field's iso-level with --level (level= in Python)",
                    self.min, self.max
                )));
            }
        };
        let (above, below) = self.boundary[li];
        let flip = match self.opts.inside {
            Inside::Negative => false,
            Inside::Positive => true,
            Inside::Auto => {
                let total = (above + below).max(1) as f64;
                let share_below = below as f64 / total;
                if share_below <= 0.05 {
                    false
                } else if share_below >= 0.95 {
                    notes.push(
                        "inside is above the level (the grid's boundary lies below it): sign \
                         flipped (--inside negative keeps it)"
                            .to_string(),
                    );
                    true
                } else {
                    return Err(DataError::Invalid(format!(
                        "the grid's boundary lies on both sides of the level ({:.0}% of its \
                         nodes below, {:.0}% above): which side is inside cannot be told; give \
                         --inside negative (signed distances) or --inside positive \
                         (occupancies, densities)",
                        100.0 * share_below,
                        100.0 * above as f64 / total
                    )));
                }
            }
        };
        Ok((level, flip, notes))
    }

    /// The extreme values seen, how often each, and the nodes scanned.
    pub fn value_range(&self) -> ValueRange {
        ValueRange {
            min: self.min,
            max: self.max,
            n_min: self.n_min,
            n_max: self.n_max,
            nodes: self.dims.iter().product::<usize>() as u64,
        }
    }

    /// Decides the conditioning; `frame_scale` is the grid frame's normalised units per unit
    /// of its bounds.
    ///
    /// # Errors
    /// Fewer planes than the grid has; no sign change at the level (given, or 0; 0.5 for a
    /// saturated field in `[0, 1]`): the message gives the values' range and what to try; a
    /// boundary split between both sides when the sign is to be found.
    pub fn finish(mut self, frame_scale: f64) -> Result<Conditioning> {
        let (level, flip, notes) = self.level_and_sign()?;
        let cells = self.dims.iter().max().copied().unwrap_or(2).max(2) - 1;
        let windows: Vec<Window> = match self.whole.take() {
            Some(data) => vec![Window {
                dims: self.dims,
                data,
            }],
            None => self.windows.drain(..).flatten().collect(),
        };
        let mut c = Conditioning {
            level,
            flip,
            kind: Kind::Distance,
            frame_scale,
            slope: f64::NAN,
            time: Default::default(),
            cells,
            clamped: (None, None),
            notes,
        };
        match self.opts.field {
            FieldKind::Auto => classify(&mut c, &windows, &self.value_range()),
            FieldKind::Distance => {}
            FieldKind::Redistance => {
                c.kind = Kind::Redistanced {
                    why: "asked (--field redistance)".into(),
                    factor: frame_scale,
                }
            }
        }
        c.time = self.started.elapsed();
        Ok(c)
    }
}

/// The extreme values of a field and how often each occurs (a truncated field holds many of
/// them), over `nodes` nodes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueRange {
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Nodes at the smallest value.
    pub n_min: u64,
    /// Nodes at the largest value.
    pub n_max: u64,
    /// Nodes.
    pub nodes: u64,
}

/// A block of a field's nodes for [`classify`]: `dims` nodes in C order at the grid's spacing.
pub struct Window {
    /// Nodes per axis.
    pub dims: [usize; 3],
    /// The field's values.
    pub data: Vec<f32>,
}

/// Measures what kind of field `windows` (blocks of nodes around its zero set, at the grid's
/// spacing, `c.cells` cells along its longest axis) hold, after `c`'s level and sign, and sets
/// `c.kind` and `c.slope` ([`Kind`]); `range` holds the field's extremes (clamped values of a
/// truncated field give no pair).
pub fn classify(c: &mut Conditioning, windows: &[Window], range: &ValueRange) {
    let (level, flip, frame_scale) = (c.level, c.flip, c.frame_scale);
    let h = 2.0 / c.cells.max(1) as f64;
    let sign = if flip { -1.0 } else { 1.0 };
    let u_of = |v: f32| sign * (f64::from(v) - level);
    // Clamped values of a truncated field hold no distance (compared as stored, f32).
    let many = range.nodes / 100;
    let (lo_clamp, hi_clamp) = (
        (range.n_min > many).then_some(range.min as f32),
        (range.n_max > many).then_some(range.max as f32),
    );
    let clamped = |v: f32| Some(v) == lo_clamp || Some(v) == hi_clamp;
    // Clamped values are far: read as such whatever the map says of them.
    c.clamped = (
        (range.n_min > many).then_some(range.min),
        (range.n_max > many).then_some(range.max),
    );
    let analyse = |map: &(dyn Fn(f64) -> f64 + Sync), tried: usize| -> Vec<(f64, f64)> {
        let per_window = tried.div_ceil(windows.len().max(1));
        windows
            .par_iter()
            .flat_map_iter(|w| {
                let u: Vec<f64> = w.data.iter().map(|&v| u_of(v)).collect();
                let mapped: Vec<f64> = u.iter().map(|&x| map(x)).collect();
                let zero = crossings(&mapped, &u, w.dims, h);
                let values: Vec<f64> = w
                    .data
                    .iter()
                    .zip(&u)
                    .map(|(&v, &x)| if clamped(v) { f64::NAN } else { x })
                    .collect();
                pairs(
                    &values,
                    &u,
                    w.dims,
                    h,
                    &zero,
                    PAIR_CELLS,
                    per_window,
                    f64::is_nan,
                )
            })
            .collect()
    };
    // A few nodes tell a distance (the common case, and it must stay cheap); a field that is
    // not one gets all of them.
    let mut first = analyse(&|u| u, QUICK_TRIED);
    if !fit_linear(&first, h).is_some_and(|(_, linear)| linear) || first.len() < MIN_PAIRS {
        first = analyse(&|u| u, MAX_TRIED);
    }
    let Some((slope, linear)) = fit_linear(&first, h) else {
        // Too few flat pieces (a small or thin shape): the field's slope across the edges
        // that cross its zero set (a distance changes by a cell along edges normal to the
        // surface, and by less along the others: their upper tenth).
        let Some((edge, top)) = edge_slope(windows, h, &u_of) else {
            c.notes.push(
                "too few nodes near the surface to measure the field: taken as a signed \
                 distance"
                    .to_string(),
            );
            return;
        };
        c.slope = top * frame_scale;
        // Noise widens the edges' slopes: only a clear difference (a quarter) rescales, by
        // the steepest edges (those normal to the surface, exact for a scaled distance).
        if (edge * frame_scale - 1.0).abs() > 0.25 {
            c.kind = Kind::Scaled { factor: 1.0 / top };
            check_distance_like(
                c,
                windows,
                h,
                &u_of,
                &clamped,
                "a field measured on too few flat pieces of its surface",
            );
        }
        return;
    };
    c.slope = slope * frame_scale;
    let residual_linear = {
        let mut e: Vec<f64> = first.iter().map(|&(u, d)| (u / slope - d).abs()).collect();
        median(&mut e) / h
    };
    // The field's extremes after level and sign are the asymptotes of a saturating field
    // (tanh, an occupancy): a side counts as saturated when a fifth of its nodes analysed lie
    // within 0.5% of the range from its extreme (the deepest nodes of a thin part alone do not
    // make one).
    let (ulo, uhi) = if flip {
        (level - range.max, level - range.min)
    } else {
        (range.min - level, range.max - level)
    };
    let margin = 0.005 * (uhi - ulo);
    let (mut near_lo, mut near_hi, mut below, mut above) = (0usize, 0usize, 0usize, 0usize);
    for w in windows {
        for &v in &w.data {
            let u = u_of(v);
            if u < 0.0 {
                below += 1;
                near_lo += usize::from(u <= ulo + margin);
            } else {
                above += 1;
                near_hi += usize::from(u >= uhi - margin);
            }
        }
    }
    let sat_lo = near_lo * 5 >= below && below > 0;
    let sat_hi = near_hi * 5 >= above && above > 0;
    // A field that saturates on one side and stays within that value's magnitude on the
    // other (tanh, an occupancy: inside a part too thin to reach its own asymptote) is taken
    // to saturate symmetrically.
    let extremes = match (sat_lo, sat_hi) {
        (true, true) => (ulo, uhi),
        (false, true) if -ulo <= uhi => (-uhi, uhi),
        (true, false) if uhi <= -ulo => (ulo, -ulo),
        (true, false) => (ulo, f64::NAN),
        (false, true) => (f64::NAN, uhi),
        (false, false) => (f64::NAN, f64::NAN),
    };
    let monotone = fit_monotone(&first, extremes, h);
    let nonlinear = !linear
        && residual_linear > 0.05
        && monotone
            .as_ref()
            .is_some_and(|(_, e)| *e / h < 0.5 * residual_linear);
    if first.len() < MIN_PAIRS || !nonlinear {
        if (slope * frame_scale - 1.0).abs() > 0.03 {
            c.kind = Kind::Scaled {
                factor: 1.0 / slope,
            };
            check_distance_like(
                c,
                windows,
                h,
                &u_of,
                &clamped,
                "a field that is not a distance up to a unit",
            );
        }
        return;
    }
    // A monotone function of the distance: refit twice on the zero set of the mapped field
    // (its crossings placed by nearly linear values).
    let Some((mut map, mut err)) = monotone else {
        return;
    };
    let mut count = first.len();
    for _ in 0..2 {
        let m = map.clone();
        let again = analyse(&|u| m.eval(u), MAX_TRIED);
        match fit_monotone(&again, extremes, h) {
            Some((m2, e2)) if again.len() >= MIN_PAIRS => {
                map = m2;
                err = e2;
                count = again.len();
            }
            _ => break,
        }
    }
    if err / h > 0.15 {
        c.notes.push(format!(
            "the field is not one function of the distance everywhere (the map's median error \
             is {:.2} cells): expect a surface near marching cubes'",
            err / h
        ));
    }
    if map.power() > 1.0 {
        // A field whose slope vanishes at its surface (d |d|): its zero set falls between
        // nodes where no reading of its values places it; the map still reads its values far
        // from it, but the surface is marching cubes' either way.
        c.kind = Kind::Redistanced {
            why: format!(
                "a field whose slope vanishes at its surface (it grows as the distance to the \
                 power {:.1})",
                map.power()
            ),
            factor: 1.0 / slope,
        };
        return;
    }
    c.kind = Kind::Mapped {
        map,
        residual_cells: err / h,
        pairs: count,
    };
    check_distance_like(
        c,
        windows,
        h,
        &u_of,
        &clamped,
        "a field no monotone map explains",
    );
}

/// The 90th and 99th percentiles of `|u(b) - u(a)| / h` over the grid edges that cross the
/// zero set: a distance's slope times the field's (edges normal to the surface change by a
/// cell); `None` without 20 such edges.
fn edge_slope(windows: &[Window], h: f64, u_of: &dyn Fn(f32) -> f64) -> Option<(f64, f64)> {
    let mut slopes = Vec::new();
    for w in windows {
        let [d0, d1, d2] = w.dims;
        let at = |i: usize, j: usize, k: usize| u_of(w.data[(i * d1 + j) * d2 + k]);
        for i in 0..d0 {
            for j in 0..d1 {
                for k in 0..d2 {
                    let a = at(i, j, k);
                    for (x, y, z) in [(i + 1, j, k), (i, j + 1, k), (i, j, k + 1)] {
                        if x >= d0 || y >= d1 || z >= d2 {
                            continue;
                        }
                        let b = at(x, y, z);
                        if (a < 0.0) != (b < 0.0) {
                            slopes.push((b - a).abs() / h);
                        }
                    }
                }
            }
        }
    }
    if slopes.len() < 20 {
        return None;
    }
    let n = slopes.len();
    let v90 = *slopes.select_nth_unstable_by(n * 9 / 10, f64::total_cmp).1;
    let v99 = *slopes
        .select_nth_unstable_by(n * 99 / 100, f64::total_cmp)
        .1;
    (v90 > 0.0 && v99.is_finite()).then_some((v90, v99))
}

/// Checks that `c`'s reading of the windows is a distance where it matters: between one and
/// three cells from the surface, the steepest descent towards the surface over each node's
/// 5^3 block falls at a median rate within 25% of one, and at 40% of the nodes within 25%;
/// across the surface, the distances of the two nodes of an edge that crosses it add up to a
/// cell (within 20%, the upper twentieth of the edges: those normal to the surface). A reading
/// that fails is no distance the network can use: the field is re-distanced instead
/// ([`Kind::Redistanced`], `why` says what it was).
fn check_distance_like(
    c: &mut Conditioning,
    windows: &[Window],
    h: f64,
    u_of: &dyn Fn(f32) -> f64,
    clamped: &dyn Fn(f32) -> bool,
    why: &str,
) {
    let mut rates: Vec<f64> = Vec::new();
    for w in windows {
        let [d0, d1, d2] = w.dims;
        let v: Vec<f64> = w.data.iter().map(|&x| c.apply_u(u_of(x))).collect();
        let at = |i: usize, j: usize, k: usize| (i * d1 + j) * d2 + k;
        for i in 2..d0.saturating_sub(2) {
            for j in 2..d1.saturating_sub(2) {
                for k in 2..d2.saturating_sub(2) {
                    let f = at(i, j, k);
                    let x = v[f];
                    if !(x.abs() > h && x.abs() < 3.0 * h) || clamped(w.data[f]) {
                        continue;
                    }
                    let mut best = f64::NEG_INFINITY;
                    for a in 0..5 {
                        for b in 0..5 {
                            for e in 0..5 {
                                if (a, b, e) == (2, 2, 2) {
                                    continue;
                                }
                                let y = v[at(i + a - 2, j + b - 2, k + e - 2)];
                                let len = ((a as f64 - 2.0).powi(2)
                                    + (b as f64 - 2.0).powi(2)
                                    + (e as f64 - 2.0).powi(2))
                                .sqrt()
                                    * h;
                                best = best.max(x.signum() * (x - y) / len);
                            }
                        }
                    }
                    rates.push(best);
                }
            }
        }
    }
    // Across the zero set: the nodes of an edge that crosses it are a cell apart along the
    // edge, so their distances add up to at most a cell, and to a cell on edges normal to the
    // surface (the upper twentieth of them).
    let mut spans: Vec<f64> = Vec::new();
    for w in windows {
        let [d0, d1, d2] = w.dims;
        let v = |i: usize, j: usize, k: usize| c.apply_u(u_of(w.data[(i * d1 + j) * d2 + k]));
        for i in 0..d0 {
            for j in 0..d1 {
                for k in 0..d2 {
                    let a = v(i, j, k);
                    for (x, y, z) in [(i + 1, j, k), (i, j + 1, k), (i, j, k + 1)] {
                        if x < d0 && y < d1 && z < d2 {
                            let b = v(x, y, z);
                            if (a < 0.0) != (b < 0.0) {
                                spans.push((a.abs() + b.abs()) / h);
                            }
                        }
                    }
                }
            }
        }
    }
    let span = if spans.len() >= 20 {
        let n = spans.len();
        *spans.select_nth_unstable_by(n * 19 / 20, f64::total_cmp).1
    } else {
        1.0
    };
    let near_one = rates.iter().filter(|r| (**r - 1.0).abs() <= 0.25).count();
    // Too few nodes between one and three cells (a binary occupancy, a field clamped within a
    // cell or two) tell nothing: no pass.
    let m = if rates.len() >= 20 {
        median(&mut rates)
    } else {
        f64::NAN
    };
    // Loose enough for a learned field (slopes of 0.8 to 1.2 are common), tight enough to
    // catch a reading that squeezes or stretches the distances near the surface by a quarter.
    if (m - 1.0).abs() <= 0.25 && near_one * 5 >= rates.len() * 2 && (span - 1.0).abs() <= 0.2 {
        return;
    }
    let factor = match &c.kind {
        Kind::Scaled { factor } => *factor,
        _ if c.slope.is_finite() && c.slope > 0.0 => c.frame_scale / c.slope,
        _ => c.frame_scale,
    };
    c.notes.push(format!(
        "read value by value its distances would fall at a median rate of {m:.2} and span \
         {span:.2} cells across its zero set's edges (a distance: 1 and 1)"
    ));
    c.kind = Kind::Redistanced {
        why: why.to_string(),
        factor,
    };
}

/// The median (upper middle); `NaN` for an empty slice.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let n = v.len() / 2;
    *v.select_nth_unstable_by(n, f64::total_cmp).1
}

/// 64-bit FNV-1a of a window's place.
fn fnv(origin: &[usize; 3]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &x in origin {
        for b in (x as u64).to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}
