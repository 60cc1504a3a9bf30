//! A mesh as the input of inference: normalised into the `[-1,1]` frame (bounding-box centre
//! at the origin, diagonal 2), its exact signed distance grid computed as `ponq-prep sdf`
//! does (`ponq_data::sdf`), and the transform that maps results back to its coordinates.

use anyhow::{Context, Result, bail};
use ponq_data::normalize::Normalization;
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
    /// The mesh is not a closed, consistently oriented surface: the sign follows the
    /// generalised winding number.
    pub open: bool,
}

/// Normalises `mesh` and computes its exact SDF grid with `res` cells per side.
/// `progress(nodes_done)` reports the distance computation.
///
/// # Errors
/// `res` outside [`RES_RANGE`], a mesh without faces or with a degenerate bounding box, and
/// an open mesh unless `allow_open` (the open-surface path).
pub fn mesh_grid(
    mesh: &TriMesh,
    res: usize,
    allow_open: bool,
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
        bail!("the input mesh has no triangle");
    }
    let normalization = Normalization::of(mesh).context("normalising the input mesh")?;
    let m = normalization.apply_mesh(mesh);
    let sdf = MeshSdf::new(&m).context("preparing the input mesh's distance queries")?;
    if sdf.is_open() && !allow_open {
        let report = ponq_mesh::validity::check_topology(&m);
        bail!(
            "the input mesh is not a closed, consistently oriented surface ({report}): its inside \
             is undefined. Repair it, or reconstruct it as an open surface with --open"
        );
    }
    let g = sdf.grid(res, progress).context("computing the SDF grid")?;
    Ok(MeshGrid {
        grid: g.to_grid3(),
        normalization,
        open: g.open,
    })
}
