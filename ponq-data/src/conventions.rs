//! The conventions people's grids come in, made from an exact signed distance grid: to test and
//! measure the conditioning (`crate::condition`) on the project's own copies, as
//! [`crate::broken`] does for meshes. `ponq-prep field GRID --convention NAME` writes one.
//!
//! ```
//! use ponq_data::conventions::Convention;
//! let c: Convention = "tsdf:3".parse().unwrap();
//! let h = 2.0 / 32.0;
//! // A normalised TSDF over 3 cells: 1 cell out is 1/3, 5 cells out is clamped to 1.
//! assert!((c.apply(&[h, 5.0 * h], h, 0)[0] - 1.0 / 3.0).abs() < 1e-12);
//! assert_eq!(c.apply(&[h, 5.0 * h], h, 0)[1], 1.0);
//! assert_eq!(c.level(), None);
//! ```

use rand::SeedableRng;
use rand_distr_free::normal;

/// One convention: how a distance `d` (negative inside, in the grid's frame, cell `h`)
/// becomes the values a user's grid holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Convention {
    /// `d` itself.
    Exact,
    /// `d * factor`: another unit (millimetres, a grid not normalised).
    Scale(f64),
    /// `d / h`: voxel units (`scipy.ndimage.distance_transform_edt`, OpenVDB index space).
    Voxel,
    /// `clamp(d / (n h), -1, 1)`: a TSDF normalised over `n` cells (KinectFusion, Open3D).
    Tsdf(f64),
    /// `clamp(d, -n h, n h)`: a TSDF truncated at `n` cells, in the grid's units.
    TsdfWorld(f64),
    /// `tanh(d / h)`: a field that saturates.
    Tanh,
    /// `1 / (1 + exp(d / h))`: an occupancy probability (inside near 1), its surface at 0.5.
    Sigmoid,
    /// `-d`: inside positive (trimesh and several SDF libraries).
    InsidePositive,
    /// `d |d|`: a field whose slope vanishes at its surface.
    Squared,
    /// `d + N(0, (sigma h)^2)`: noise of `sigma` cells (seeded).
    Noise(f64),
    /// `d + level`: the surface at another iso-level.
    Offset(f64),
}

impl Convention {
    /// Every convention of the benchmark in `docs/fields.md`, in its order.
    pub const BENCHMARK: [Convention; 17] = [
        Convention::Exact,
        Convention::Scale(0.5),
        Convention::Scale(2.0),
        Convention::Scale(0.25),
        Convention::Scale(4.0),
        Convention::Scale(50.0),
        Convention::Voxel,
        Convention::Tsdf(3.0),
        Convention::Tsdf(4.0),
        Convention::Tsdf(8.0),
        Convention::TsdfWorld(3.0),
        Convention::InsidePositive,
        Convention::Offset(0.05),
        Convention::Tanh,
        Convention::Sigmoid,
        Convention::Squared,
        Convention::Noise(0.1),
    ];

    /// The values of the distances `d` (cell `h`); `seed` for the noise.
    pub fn apply(&self, d: &[f64], h: f64, seed: u64) -> Vec<f64> {
        match *self {
            Self::Exact => d.to_vec(),
            Self::Scale(f) => d.iter().map(|x| x * f).collect(),
            Self::Voxel => d.iter().map(|x| x / h).collect(),
            Self::Tsdf(n) => d.iter().map(|x| (x / (n * h)).clamp(-1.0, 1.0)).collect(),
            Self::TsdfWorld(n) => d.iter().map(|x| x.clamp(-n * h, n * h)).collect(),
            Self::Tanh => d.iter().map(|x| (x / h).tanh()).collect(),
            Self::Sigmoid => d.iter().map(|x| 1.0 / (1.0 + (x / h).exp())).collect(),
            Self::InsidePositive => d.iter().map(|x| -x).collect(),
            Self::Squared => d.iter().map(|x| x * x.abs()).collect(),
            Self::Noise(sigma) => {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                d.iter().map(|x| x + sigma * h * normal(&mut rng)).collect()
            }
            Self::Offset(l) => d.iter().map(|x| x + l).collect(),
        }
    }

    /// The iso-level a user must give for this convention (`--level`), where the program
    /// cannot tell it: an offset surface.
    pub fn level(&self) -> Option<f64> {
        match *self {
            Self::Offset(l) => Some(l),
            _ => None,
        }
    }

    /// Where the surface is and which side is inside, as marching cubes needs it: the level,
    /// and whether inside is above it.
    pub fn surface(&self) -> (f64, bool) {
        match *self {
            Self::Sigmoid => (0.5, true),
            Self::InsidePositive => (0.0, true),
            Self::Offset(l) => (l, false),
            _ => (0.0, false),
        }
    }

    /// Whether the values are a distance up to a unit, a sign and a level (the benchmark's
    /// target is then the exact grid's F1 within 0.01).
    pub fn is_distance_up_to_scale(&self) -> bool {
        matches!(
            self,
            Self::Exact
                | Self::Scale(_)
                | Self::Voxel
                | Self::Tsdf(_)
                | Self::TsdfWorld(_)
                | Self::InsidePositive
                | Self::Offset(_)
        )
    }
}

impl std::fmt::Display for Convention {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Exact => write!(f, "exact"),
            Self::Scale(x) => write!(f, "scale:{x}"),
            Self::Voxel => write!(f, "voxel"),
            Self::Tsdf(n) => write!(f, "tsdf:{n}"),
            Self::TsdfWorld(n) => write!(f, "tsdf-world:{n}"),
            Self::Tanh => write!(f, "tanh"),
            Self::Sigmoid => write!(f, "sigmoid"),
            Self::InsidePositive => write!(f, "inside-positive"),
            Self::Squared => write!(f, "squared"),
            Self::Noise(s) => write!(f, "noise:{s}"),
            Self::Offset(l) => write!(f, "offset:{l}"),
        }
    }
}

impl std::str::FromStr for Convention {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, arg) = match s.split_once(':') {
            Some((n, a)) => (n, Some(a)),
            None => (s, None),
        };
        let num = |what: &str| -> Result<f64, String> {
            let a = arg.ok_or_else(|| format!("{name} takes a number: {name}:{what}"))?;
            let v: f64 = a
                .parse()
                .map_err(|_| format!("{name}:{a}: {a:?} is not a number"))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(format!("{name}:{a}: not finite"))
            }
        };
        let positive = |what: &str| -> Result<f64, String> {
            let v = num(what)?;
            if v > 0.0 {
                Ok(v)
            } else {
                Err(format!("{name}:{v}: must be positive"))
            }
        };
        let c = match name {
            "exact" => Self::Exact,
            "scale" => Self::Scale(positive("FACTOR")?),
            "voxel" => Self::Voxel,
            "tsdf" => Self::Tsdf(positive("CELLS")?),
            "tsdf-world" => Self::TsdfWorld(positive("CELLS")?),
            "tanh" => Self::Tanh,
            "sigmoid" => Self::Sigmoid,
            "inside-positive" => Self::InsidePositive,
            "squared" => Self::Squared,
            "noise" => Self::Noise(positive("CELLS")?),
            "offset" => Self::Offset(num("LEVEL")?),
            _ => {
                return Err(format!(
                    "unknown convention {s:?}: exact, scale:F, voxel, tsdf:N, tsdf-world:N, \
                     tanh, sigmoid, inside-positive, squared, noise:S, offset:L"
                ));
            }
        };
        if arg.is_some()
            && matches!(
                name,
                "exact" | "voxel" | "tanh" | "sigmoid" | "inside-positive" | "squared"
            )
        {
            return Err(format!("{name} takes no number: {s:?}"));
        }
        Ok(c)
    }
}

/// A standard normal draw (Box-Muller; the `rand` crate of this workspace carries no
/// distributions, and one function does not warrant a dependency).
mod rand_distr_free {
    use rand::Rng;

    pub fn normal(rng: &mut impl Rng) -> f64 {
        let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
        let u2: f64 = rng.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_errors() {
        for c in Convention::BENCHMARK {
            assert_eq!(c.to_string().parse::<Convention>().unwrap(), c);
        }
        assert_eq!(
            "offset:-0.3".parse::<Convention>().unwrap(),
            Convention::Offset(-0.3)
        );
        for bad in [
            "scale",
            "scale:0",
            "scale:x",
            "tsdf:-1",
            "tanh:2",
            "blur",
            "noise:nan",
        ] {
            assert!(bad.parse::<Convention>().is_err(), "{bad}");
        }
    }

    #[test]
    fn conventions_keep_the_zero_set_and_the_sides() {
        let h = 0.0625;
        let d: Vec<f64> = (-40..=40).map(|i| f64::from(i) * 0.01).collect();
        for c in Convention::BENCHMARK {
            let v = c.apply(&d, h, 3);
            let (level, inside_above) = c.surface();
            for (x, y) in d.iter().zip(&v) {
                if x.abs() < 0.02 || matches!(c, Convention::Noise(_)) {
                    continue;
                }
                let inside = if inside_above { *y > level } else { *y < level };
                assert_eq!(inside, *x < 0.0, "{c}: {x} -> {y}");
            }
        }
    }
}
