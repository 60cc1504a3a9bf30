//! Command-line flags the mesher's programs share (`ponq-infer`, `ponq-mesh`), as a clap
//! argument group to flatten into a program's own arguments, so that the flags, their help
//! and their meaning are one and the same in both.
//!
//! ```
//! use clap::Parser;
//! use ponq_mesh::cli::MesherFlags;
//! #[derive(Parser)]
//! struct Args {
//!     #[command(flatten)]
//!     mesher: MesherFlags,
//! }
//! let a = Args::parse_from(["prog", "--bounds", "-2,-2,-2,2,2,2", "--small-tets", "both"]);
//! assert_eq!(a.mesher.domain().unwrap(), ([-2.0; 3], [2.0; 3]));
//! assert_eq!(a.mesher.small_tet_rule(), ponq_mesh::tagging::SmallTetRule::BothWays);
//! ```

use crate::error::Result;
use crate::mesher::MeshingOptions;
use crate::tagging::SmallTetRule;

/// The domain box and the mesher's choices of the tagging and the flips.
#[derive(clap::Args, Debug, Clone)]
pub struct MesherFlags {
    /// Box spanned by the grid nodes (the domain): xmin,ymin,zmin,xmax,ymax,zmax [default:
    /// -1,-1,-1,1,1,1].
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "X0,Y0,Z0,X1,Y1,Z1"
    )]
    pub bounds: Option<Vec<f64>>,
    /// Keep the triangles of the minimum cut as they are: no flips of quadrilateral diagonals
    /// onto the sharp edges the quadrics describe, and none of the flat caps (near-180-degree
    /// triangles on flat parts) away.
    #[arg(long)]
    pub no_crease_flips: bool,
    /// The small-tet rule of the tagging: `inside` (default: a vertex with an outside tet but no
    /// inside tet gets its smallest unknown tet tagged inside, if small; the authors' intent),
    /// `authors` (their code to the letter: the smallest of all the vertex's tets, whatever its
    /// label, flags read once), `both` (the paper's text: inside and outside tets; the rule
    /// before 2026-12-03). See docs/meshing.md.
    #[arg(long, value_name = "RULE", default_value = "inside")]
    pub small_tets: SmallTetRule,
    /// Same as `--small-tets both` (kept for earlier scripts).
    #[arg(long, conflicts_with = "small_tets")]
    pub small_tets_both_ways: bool,
}

impl MesherFlags {
    /// The domain box: `--bounds` checked ([`MeshingOptions::domain_from`]), or `[-1, 1]^3`.
    ///
    /// # Errors
    /// As [`MeshingOptions::domain_from`].
    pub fn domain(&self) -> Result<([f64; 3], [f64; 3])> {
        match &self.bounds {
            None => Ok(([-1.0; 3], [1.0; 3])),
            Some(b) => MeshingOptions::domain_from(b),
        }
    }

    /// The small-tet rule: `--small-tets`, or `both` with `--small-tets-both-ways`.
    pub fn small_tet_rule(&self) -> SmallTetRule {
        if self.small_tets_both_ways {
            SmallTetRule::BothWays
        } else {
            self.small_tets
        }
    }
}
