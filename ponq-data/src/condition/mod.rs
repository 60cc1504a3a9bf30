//! Any field in: the conditioning that turns a user's grid (or field) into what the network
//! and the refinement read, a signed distance in the grid's normalised frame (negative
//! inside, the cell `2 / N`).
//!
//! People's grids come in many conventions: distances in voxel units or millimetres, TSDFs
//! normalised to `[-1, 1]` over a few cells, occupancy probabilities at level 0.5, `tanh` or
//! sigmoid fields, inside-positive distances, learned fields far from unit slope. Marching cubes
//! only needs the zero set; the network needs the distance. [`FieldScan`] reads the grid once,
//! plane by plane, and decides ([`Conditioning`]):
//! - the **iso-level** (given, else 0; a field in `[0, 1]` without a sign change at 0 is taken
//!   at 0.5, an occupancy, with a note);
//! - the **sign**: the side the grid's boundary lies on is outside (or as given);
//! - the **kind** of field, from pairs (value, distance) measured where the distance is known
//!   exactly: at nodes next to flat pieces of the field's zero set ([`pairs`]), the distance to
//!   that plane. A field whose value is one factor times the distance at every distance is a
//!   distance up to a unit ([`Kind::Scaled`]; the factor 1 in the grid's frame:
//!   [`Kind::Distance`], used as it is, bit for bit); a field that is another monotone
//!   function of the distance is inverted by the map fitted to the pairs ([`Kind::Mapped`],
//!   [`fit`]), so sharp features keep their exact distances too.
//!
//! ```
//! use ponq_data::condition::{ConditionOptions, FieldScan, Kind};
//! // A sphere's distance on a 33^3 grid over [-1,1]^3, in voxel units (x 16).
//! let n = 33;
//! let h = 2.0 / 32.0;
//! let mut scan = FieldScan::new([n; 3], &ConditionOptions::default());
//! for i in 0..n {
//!     let plane: Vec<f64> = (0..n * n)
//!         .map(|jk| {
//!             let p = [i, jk / n, jk % n].map(|a| -1.0 + h * a as f64);
//!             ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.6) / h
//!         })
//!         .collect();
//!     scan.push_plane(&plane).unwrap();
//! }
//! let c = scan.finish(1.0).unwrap();
//! assert!(matches!(c.kind, Kind::Scaled { .. }));
//! assert!((c.apply(0.2 / h) - 0.2).abs() < 1e-3); // back in the grid's frame
//! ```

mod crossings;
mod fit;
mod redistance;
mod scan;

pub use crossings::{Crossing, crossings, pairs};
pub use fit::{MonotoneMap, fit_linear, fit_monotone};
pub use redistance::redistance;
pub use scan::{FieldScan, ValueRange, Window, classify};

use std::time::Duration;

/// Which side of the iso-level is inside.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Inside {
    /// The side the grid's boundary lies on is outside.
    #[default]
    Auto,
    /// Values below the level are inside (signed distances, the project's convention).
    Negative,
    /// Values above the level are inside (occupancies, densities, some SDF libraries).
    Positive,
}

impl std::str::FromStr for Inside {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "negative" => Ok(Self::Negative),
            "positive" => Ok(Self::Positive),
            _ => Err(format!("expected auto, negative or positive, got {s:?}")),
        }
    }
}

/// What the values are, when the user says ([`ConditionOptions::field`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum FieldKind {
    /// Measured ([`FieldScan`]).
    #[default]
    Auto,
    /// Signed distances in the units of the grid's bounds: used as they are (after the level
    /// and the sign).
    Distance,
    /// Any field: exact distances to its zero set ([`Kind::Redistanced`]).
    Redistance,
}

impl std::str::FromStr for FieldKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "distance" => Ok(Self::Distance),
            "redistance" => Ok(Self::Redistance),
            _ => Err(format!("expected auto, distance or redistance, got {s:?}")),
        }
    }
}

/// Options of the conditioning.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ConditionOptions {
    /// The iso-level; `None`: 0, or 0.5 for a field in `[0, 1]` without a sign change at 0.
    pub level: Option<f64>,
    /// Which side is inside.
    pub inside: Inside,
    /// What the values are.
    pub field: FieldKind,
}

/// What the conditioning found the field to be.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind {
    /// A signed distance in the grid's frame (its slope 1 within 3%): used as it is.
    Distance,
    /// A distance up to one factor (voxel units, another unit, a normalised TSDF): multiplied
    /// by `factor` into the grid's frame.
    Scaled {
        /// Normalised units per unit of the field.
        factor: f64,
    },
    /// A monotone function of the distance (occupancy, `tanh`, sigmoid, squared): mapped back
    /// by a fitted [`MonotoneMap`].
    Mapped {
        /// The map from the field's value (after level and sign) to the normalised distance.
        map: MonotoneMap,
        /// Median error of the map on the pairs it was fitted to, in cells.
        residual_cells: f64,
        /// Pairs it was fitted to.
        pairs: usize,
    },
    /// A field no map explains (or too few nodes could tell): exact distances to its zero
    /// set ([`redistance`]), which needs the whole grid ([`Conditioning::condition_dense`]);
    /// value by value ([`Conditioning::apply`]) it falls back to `factor`.
    Redistanced {
        /// Why no map explains it.
        why: String,
        /// The factor of a per-value reading (the slope at the zero set).
        factor: f64,
    },
}

/// How far from the zero set [`redistance`] computes exact distances, in cells (past what
/// inference reads).
pub const REDISTANCE_CELLS: f64 = 10.0;

/// How far clamped values of a truncated field are read at least, in cells (past the band
/// inference stores, 3 cells, so that a field clamped within it does not store the whole
/// grid; a TSDF clamped farther keeps its own reading).
pub const FAR_CELLS: f64 = 3.05;

/// The largest grid re-distanced whole (2^25 nodes, 256 MB of values); larger grids are read
/// value by value ([`Conditioning::fit_whole_grid`]).
pub const REDISTANCE_MAX_NODES: usize = 1 << 25;

/// The conditioning of one field: level, sign and kind, and how to apply them.
#[derive(Debug, Clone)]
pub struct Conditioning {
    /// The iso-level subtracted.
    pub level: f64,
    /// Whether the sign is flipped (inside positive).
    pub flip: bool,
    /// The kind of field.
    pub kind: Kind,
    /// Normalised units per unit of the grid's bounds (the frame's scale).
    pub frame_scale: f64,
    /// The field's median slope at its zero set, in its units per unit of the bounds
    /// (1 for a distance; `NaN` when not measured).
    pub slope: f64,
    /// Time of the scan and the fit.
    pub time: Duration,
    /// Cells along the grid's longest axis (the normalised cell is `2 / cells`).
    pub cells: usize,
    /// The field's extreme values where a truncated field clamps many nodes (below, above):
    /// read at least [`FAR_CELLS`] away.
    pub clamped: (Option<f64>, Option<f64>),
    /// What was decided that the user should hear (the level or the sign chosen, a fit
    /// that is loose, too few nodes to measure).
    pub notes: Vec<String>,
}

impl Conditioning {
    /// The field taken as a signed distance in the units of the bounds, as it is.
    pub fn identity(frame_scale: f64) -> Self {
        Self {
            level: 0.0,
            flip: false,
            kind: Kind::Distance,
            frame_scale,
            slope: f64::NAN,
            time: Duration::ZERO,
            cells: 0,
            clamped: (None, None),
            notes: Vec::new(),
        }
    }

    /// Whether [`Conditioning::apply`] is `v * frame_scale` (readers then take today's path,
    /// so that the grids of true distances give the same meshes bit for bit).
    pub fn is_identity(&self) -> bool {
        self.level == 0.0 && !self.flip && self.kind == Kind::Distance
    }

    /// A field value as a signed distance in the normalised frame.
    pub fn apply(&self, v: f64) -> f64 {
        let u = if self.flip {
            self.level - v
        } else {
            v - self.level
        };
        let d = self.apply_u(u);
        if !matches!(self.kind, Kind::Distance)
            && (Some(v) == self.clamped.0 || Some(v) == self.clamped.1)
        {
            // At least past the band inference stores (3 cells), so that a field clamped
            // within it does not store the whole grid.
            let far = FAR_CELLS * 2.0 / self.cells.max(1) as f64;
            return u.signum() * d.abs().max(far);
        }
        d
    }

    /// Keeps a re-distancing within what a grid of `nodes` nodes allows
    /// ([`REDISTANCE_MAX_NODES`]): past it, the field is read value by value
    /// ([`Kind::Scaled`] by the factor measured), with a note. Returns whether the kind
    /// changed.
    pub fn fit_whole_grid(&mut self, nodes: usize) -> bool {
        if let Kind::Redistanced { factor, .. } = self.kind
            && nodes > REDISTANCE_MAX_NODES
        {
            self.kind = Kind::Scaled { factor };
            self.notes.push(format!(
                "a grid of {nodes} nodes is too large to re-distance (at most \
                 {REDISTANCE_MAX_NODES}): read value by value"
            ));
            return true;
        }
        false
    }

    /// [`Conditioning::apply`] of a value after the level and the sign.
    pub fn apply_u(&self, u: f64) -> f64 {
        match &self.kind {
            Kind::Distance => u * self.frame_scale,
            Kind::Scaled { factor } | Kind::Redistanced { factor, .. } => u * factor,
            Kind::Mapped { map, .. } => map.eval(u),
        }
    }

    /// Whether the whole grid is needed ([`Conditioning::condition_dense`]): a field to
    /// re-distance.
    pub fn needs_whole_grid(&self) -> bool {
        matches!(self.kind, Kind::Redistanced { .. })
    }

    /// The conditioned values of a whole grid (`dims` nodes, C order): [`Conditioning::apply`]
    /// at every node, or the distances to its zero set ([`Kind::Redistanced`]).
    ///
    /// # Errors
    /// A grid of another size; the errors of [`redistance`].
    pub fn condition_dense(&self, raw: &[f64], dims: [usize; 3]) -> crate::Result<Vec<f64>> {
        if raw.len() != dims.iter().product::<usize>() {
            return Err(crate::DataError::Invalid(format!(
                "{} values for a grid of {dims:?} nodes",
                raw.len()
            )));
        }
        match &self.kind {
            Kind::Redistanced { .. } => {
                let u: Vec<f64> = raw
                    .iter()
                    .map(|&v| {
                        if self.flip {
                            self.level - v
                        } else {
                            v - self.level
                        }
                    })
                    .collect();
                redistance(&u, dims, 2.0 / self.cells.max(1) as f64, REDISTANCE_CELLS)
            }
            _ => Ok(raw.iter().map(|&v| self.apply(v)).collect()),
        }
    }

    /// Whether the conditioned values are close enough to exact distances for the refinement
    /// to fit against (`Some` for a mapped field: a map that fits its pairs within a tenth of
    /// a cell and a field whose slope does not vanish at its zero set; `None` otherwise: the
    /// distance check decides).
    pub fn mapped_refinable(&self) -> Option<bool> {
        match &self.kind {
            Kind::Mapped {
                map,
                residual_cells,
                ..
            } => {
                let h = 2.0 / self.cells.max(1) as f64;
                Some(*residual_cells <= 0.1 && map.has_slope_at_zero(h))
            }
            Kind::Redistanced { .. } => Some(false),
            _ => None,
        }
    }

    /// One line for the programs' summaries.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        if self.level != 0.0 {
            parts.push(format!("level {}", self.level));
        }
        if self.flip {
            parts.push("inside positive: sign flipped".to_string());
        }
        parts.push(match &self.kind {
            Kind::Distance => "a signed distance: used as it is".to_string(),
            Kind::Scaled { factor } => format!(
                "a distance in other units: rescaled by {:.6} (its slope {:.4} per unit)",
                factor / self.frame_scale,
                self.slope
            ),
            Kind::Mapped {
                residual_cells,
                pairs,
                ..
            } => format!(
                "not a distance (slope {:.4} per unit at the surface): mapped to distances by a \
                 monotone fit on {pairs} nodes (median error {residual_cells:.3} cells)",
                self.slope
            ),
            Kind::Redistanced { why, .. } => format!(
                "{why}: re-distanced (exact distances to its zero set as marching cubes places \
                 it)"
            ),
        });
        let mut s = format!(
            "field: {} ({:.1} ms)",
            parts.join(", "),
            self.time.as_secs_f64() * 1e3
        );
        for n in &self.notes {
            s.push_str("; ");
            s.push_str(n);
        }
        s
    }
}
