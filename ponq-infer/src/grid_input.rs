//! A grid file as the input: read twice, plane by plane, never whole: a first pass measures
//! what the values are (`ponq_data::condition::FieldScan`), the second stores the distances
//! near the surface ([`BandGrid`]), conditioned as the first pass decided. A true signed
//! distance in the grid's frame is read exactly as before conditioning existed (the same
//! band, bit for bit).

use anyhow::{Context, Result};
use ponq_data::condition::{Conditioning, FieldScan};
use ponq_mesh::band::BandGrid;
use ponq_mesh::io::npy;

use crate::frame::Frame;
use crate::reconstruct::{InferOptions, band_memory_limit, band_parameters};

/// The largest grid re-distanced whole (`ponq_data::condition::Kind::Redistanced`): 2^25
/// nodes, 257 MB of values.
const WHOLE_GRID_NODES: usize = 1 << 25;

/// A grid read near its surface, and how its values were read.
pub struct GridInput {
    /// The distances near the surface, in the normalised frame.
    pub band: BandGrid,
    /// How the values were conditioned.
    pub conditioning: Conditioning,
}

/// Reads the `.npy` grid `path` for inference with a network of `encoder_layers`, conditioned
/// as `opts.condition` says. `progress(stage, done, total)` counts planes of the two passes
/// (`"scan"`, `"read"`).
///
/// # Errors
/// A file that is not a rank-3 float grid, a grid the frame rejects, a field without a sign
/// change or whose inside cannot be told, a band past the memory there is.
pub fn read_grid(
    path: &std::path::Path,
    encoder_layers: usize,
    opts: &InferOptions,
    mut progress: impl FnMut(&str, usize, usize),
) -> Result<GridInput> {
    let context = || format!("cannot read the SDF grid {}", path.display());
    // Pass 1: what the values are.
    let mut scan: Option<FieldScan> = None;
    let (dims, _) = npy::for_each_npy_plane(path, |stored, _, p, plane| {
        let s = scan.get_or_insert_with(|| FieldScan::new(stored, &opts.condition));
        s.push_plane(plane)
            .map_err(|e| ponq_mesh::Error::format(path, e.to_string()))?;
        progress("scan", p + 1, stored[0]);
        Ok(())
    })
    .with_context(context)?;
    let scan = scan.with_context(|| format!("the grid {} has no plane", path.display()))?;
    let frame = Frame::of_dims(dims, opts.bounds).with_context(context)?;
    let mut c = scan.finish(frame.scale()).with_context(context)?;
    if c.needs_whole_grid() {
        let nodes = dims.iter().product::<usize>();
        if nodes <= WHOLE_GRID_NODES {
            // Re-distanced: the whole grid, once (a grid this size fits).
            let g = npy::read_npy_grid(path).with_context(context)?;
            let values = c.condition_dense(&g.data, g.dims).with_context(context)?;
            let (t, reach) = band_parameters(frame.n, encoder_layers, opts);
            let band =
                BandGrid::from_dense(g.dims, &values, 1.0, t, reach).with_context(context)?;
            return Ok(GridInput {
                band,
                conditioning: c,
            });
        }
        c.notes.push(format!(
            "a grid of {nodes} nodes is too large to re-distance: read value by value"
        ));
    }
    // Pass 2: the distances near the surface. The band may take half of what is free; the
    // rest is for the network and the meshing (checked again before the network runs).
    let (t, reach) = band_parameters(frame.n, encoder_layers, opts);
    let limit = band_memory_limit()?;
    let band = if c.is_identity() {
        npy::read_npy_band_mapped(
            path,
            |_| Ok((frame.scale(), t, reach, limit)),
            None,
            |done, total| progress("read", done, total),
        )
    } else {
        let map = |v: f64| c.apply(v);
        npy::read_npy_band_mapped(
            path,
            |_| Ok((1.0, t, reach, limit)),
            Some(&map),
            |done, total| progress("read", done, total),
        )
    }
    .with_context(context)?;
    Ok(GridInput {
        band,
        conditioning: c,
    })
}
