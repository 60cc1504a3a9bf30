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
use ponq_mesh::band::BandGrid;
use ponq_mesh::io::npy::Grid3;

use crate::frame::Frame;
use crate::reconstruct::{InferOptions, band_parameters};

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

/// A mesh prepared for its grid: repaired (or checked) and normalised.
struct Prepared {
    repaired: Option<ponq_data::repair::Repaired>,
    /// The normalised mesh, without the repair.
    plain: Option<MeshSdf>,
    normalization: Normalization,
}

fn prepare(mesh: &TriMesh, res: usize, input: MeshInput) -> Result<Prepared> {
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
    if input.repair {
        let r = repair_with_solid(mesh, &opts).context("repairing the input mesh")?;
        let normalization = Normalization::of(&r.mesh).context("normalising the input mesh")?;
        Ok(Prepared {
            repaired: Some(r),
            plain: None,
            normalization,
        })
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
        Ok(Prepared {
            repaired: None,
            plain: Some(sdf),
            normalization,
        })
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
    let p = prepare(mesh, res, input)?;
    let normalization = p.normalization;
    let (g, mut report) = match (p.repaired, p.plain) {
        (Some(r), _) => {
            let g = r
                .grid(|m| normalization.apply_mesh(m), res, progress)
                .context("computing the SDF grid")?;
            (g, Some(r.report))
        }
        (None, Some(sdf)) => (
            sdf.grid(res, progress).context("computing the SDF grid")?,
            None,
        ),
        (None, None) => bail!("internal: a mesh prepared without its distances"),
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

/// The band of a mesh's grid that inference reads, and how to map results back.
#[derive(Debug, Clone)]
pub struct MeshBand {
    /// `(res+1)^3` nodes over `[-1,1]^3` in the normalised frame of inference, stored near
    /// the surface (`ponq_infer::band_parameters`).
    pub grid: BandGrid,
    /// Input coordinates -> the grid's `[-1,1]` frame.
    pub normalization: Normalization,
    /// As [`MeshGrid::open`].
    pub open: bool,
    /// What the repair found and did (`None` without the repair).
    pub report: Option<DefectReport>,
}

/// [`mesh_grid`] near the surface only, as inference reads it: exact distances in the band
/// of [`band_parameters`](crate::band_parameters) for `encoder_layers` and `opts`, the sign
/// elsewhere (`ponq_data::sdf::MeshSdf::band_signed_by`); the values where the band stores
/// them are those of [`mesh_grid`] in the normalised frame, so inference gives the same mesh.
/// `progress(done, total)` counts bricks of 8^3 nodes.
///
/// # Errors
/// As [`mesh_grid`].
pub fn mesh_band(
    mesh: &TriMesh,
    res: usize,
    input: MeshInput,
    encoder_layers: usize,
    opts: &InferOptions,
    progress: impl Fn(usize, usize) + Sync,
) -> Result<MeshBand> {
    let p = prepare(mesh, res, input)?;
    let normalization = p.normalization;
    let frame = Frame::of_dims([res + 1; 3], opts.bounds)?;
    let (t, reach) = band_parameters(frame.n, encoder_layers, opts);
    let s = frame.scale();
    let (b, mut report) = match (p.repaired, p.plain) {
        (Some(r), _) => {
            let b = r
                .band(|m| normalization.apply_mesh(m), res, s, t, reach, progress)
                .context("computing the SDF near the surface")?;
            (b, Some(r.report))
        }
        (None, Some(sdf)) => (
            sdf.band_signed_by(&sdf, res, s, t, reach, progress)
                .context("computing the SDF near the surface")?,
            None,
        ),
        (None, None) => bail!("internal: a mesh prepared without its distances"),
    };
    if let Some(r) = &mut report
        && b.open
    {
        r.ambiguous_node_share = Some(b.ambiguous_nodes as f64 / b.signed_nodes.max(1) as f64);
    }
    Ok(MeshBand {
        grid: b.grid,
        normalization,
        open: b.open,
        report,
    })
}
