//! A mesh as the input of inference: repaired (`ponq_data::repair`: any triangle soup in, the
//! surface of the solid it describes out; a clean mesh is used as it is), normalised into the
//! `[-1,1]` frame (bounding-box centre at the origin, diagonal 2), its exact signed distance
//! grid computed as `ponq-prep sdf` does (`ponq_data::sdf`), and the transform that maps
//! results back to its coordinates.

use anyhow::{Context, Result, bail};
use ponq_data::normalize::Normalization;
use ponq_data::repair::{DefectReport, RepairOptions, repair_with_solid};
use ponq_data::sdf::MeshSdf;
use ponq_mesh::TriMesh;
use ponq_mesh::io::npy::Grid3;

/// Smallest and largest accepted number of cells per side.
pub const RES_RANGE: std::ops::RangeInclusive<usize> = 2..=1024;

/// The SDF grid of a mesh and how to map results back.
#[derive(Debug, Clone)]
pub struct MeshGrid {
    /// `(res+1)^3` nodes over `[-1,1]^3`, negative inside (C order, `z` fastest).
    pub grid: Grid3,
    /// Input coordinates -> the grid's `[-1,1]` frame.
    pub normalization: Normalization,
    /// The mesh (after the repair) is not a closed, consistently oriented surface: the sign
    /// follows the generalised winding number node by node.
    pub open: bool,
    /// What the repair found and did (`None` without the repair).
    pub report: Option<DefectReport>,
}

/// How [`mesh_grid`] treats the mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshInput {
    /// The output is an open surface (`--open`): an open mesh is welcome, and its repair
    /// closes nothing and removes nothing.
    pub open_surface: bool,
    /// Repair the mesh first (the default). Without it a mesh that is not closed and
    /// consistently oriented is an error unless `open_surface` (the behaviour before the
    /// repair existed).
    pub repair: bool,
}

impl Default for MeshInput {
    fn default() -> Self {
        Self {
            open_surface: false,
            repair: true,
        }
    }
}

/// Repairs (see [`MeshInput`]) and normalises `mesh`, then computes its exact SDF grid with
/// `res` cells per side. `progress(nodes_done)` reports the distance computation.
///
/// # Errors
/// `res` outside [`RES_RANGE`]; a mesh without faces, with non-finite coordinates or nothing
/// left to reconstruct after the repair; without the repair, an open mesh unless
/// `open_surface`.
pub fn mesh_grid(
    mesh: &TriMesh,
    res: usize,
    input: MeshInput,
    progress: impl Fn(usize) + Sync,
) -> Result<MeshGrid> {
    if !RES_RANGE.contains(&res) {
        bail!(
            "the resolution must be in {}..={} cells per side, got {res}",
            RES_RANGE.start(),
            RES_RANGE.end()
        );
    }
    if mesh.faces.is_empty() {
        bail!("the input mesh has no triangle: nothing to reconstruct");
    }
    let opts = if input.open_surface {
        RepairOptions::open_surface()
    } else {
        RepairOptions::default()
    };
    let (g, normalization, mut report) = if input.repair {
        let r = repair_with_solid(mesh, &opts).context("repairing the input mesh")?;
        let normalization = Normalization::of(&r.mesh).context("normalising the input mesh")?;
        let g = r
            .grid(|m| normalization.apply_mesh(m), res, progress)
            .context("computing the SDF grid")?;
        (g, normalization, Some(r.report))
    } else {
        let normalization = Normalization::of(mesh).context("normalising the input mesh")?;
        let m = normalization.apply_mesh(mesh);
        let sdf = MeshSdf::new(&m).context("preparing the input mesh's distance queries")?;
        if sdf.is_open() && !input.open_surface {
            let report = ponq_mesh::validity::check_topology(&m);
            bail!(
                "the input mesh is not a closed, consistently oriented surface ({report}): its \
                 inside is undefined. Repair it (the default, without --no-repair), or \
                 reconstruct it as an open surface with --open"
            );
        }
        let g = sdf.grid(res, progress).context("computing the SDF grid")?;
        (g, normalization, None)
    };
    if let Some(r) = &mut report
        && g.open
    {
        r.ambiguous_node_share = Some(g.ambiguous_nodes as f64 / g.values.len() as f64);
    }
    Ok(MeshGrid {
        grid: g.to_grid3(),
        normalization,
        open: g.open,
        report,
    })
}
