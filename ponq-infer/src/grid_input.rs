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

/// A grid read near its surface, and how its values were read.
pub struct GridInput {
    /// The distances near the surface, in the normalised frame.
    pub band: BandGrid,
    /// How the values were conditioned.
    pub conditioning: Conditioning,
    /// A colour per node (C order), from an `.npz` with an `rgb` array.
    pub colours: Option<Vec<ponq_mesh::colour::Rgb>>,
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
    let mut checked = false;
    let (dims, _) = npy::for_each_npy_plane(path, |stored, fortran, p, plane| {
        if !checked {
            // The frame first: bad dims or bounds are an error before the file is read.
            let dims = if fortran {
                [stored[2], stored[1], stored[0]]
            } else {
                stored
            };
            Frame::of_dims(dims, opts.bounds)
                .map_err(|e| ponq_mesh::Error::InvalidInput(format!("{e:#}")))?;
            checked = true;
        }
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
    let nodes = dims.iter().product::<usize>();
    if opts.condition.field == ponq_data::condition::FieldKind::Redistance
        && nodes > ponq_data::condition::REDISTANCE_MAX_NODES
    {
        anyhow::bail!(
            "--field redistance: a grid of {nodes} nodes is too large to re-distance (at most \
             {})",
            ponq_data::condition::REDISTANCE_MAX_NODES
        );
    }
    c.fit_whole_grid(nodes);
    if c.needs_whole_grid() {
        // Re-distanced: the whole grid, once (two copies of it, and its marching cubes).
        ponq_mesh::memory::check(
            nodes as u64 * 24,
            "re-distancing the whole grid",
            "give the field's convention (--field distance) or mesh a coarser grid",
        )?;
        let g = npy::read_npy_grid(path).with_context(context)?;
        let values = c.condition_dense(&g.data, g.dims).with_context(context)?;
        let (t, reach) = band_parameters(frame.n, encoder_layers, opts);
        let band = BandGrid::from_dense(g.dims, &values, 1.0, t, reach).with_context(context)?;
        return Ok(GridInput {
            band,
            conditioning: c,
            colours: None,
        });
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
        colours: None,
    })
}

/// Reads an `.npz` grid: the array `sdf` (rank 3; the field, read as [`read_grid`] reads a
/// `.npy`), and the colours of its nodes when there is an array `rgb` of shape
/// `(nx, ny, nz, 3)` (floats in `[0, 1]`, or bytes) and `with_colours`. The archive is read
/// whole.
///
/// # Errors
/// No `sdf` array, arrays of other shapes, colours outside `[0, 1]` (floats) and
/// [`read_grid`]'s errors.
pub fn read_grid_npz(
    path: &std::path::Path,
    encoder_layers: usize,
    opts: &InferOptions,
    with_colours: bool,
) -> Result<GridInput> {
    let context = || format!("cannot read the grid {}", path.display());
    let arrays = ponq_mesh::io::npz::read_arrays(path).with_context(context)?;
    let names: Vec<&str> = arrays.iter().map(|(n, _)| n.as_str()).collect();
    let (_, sdf) = arrays.iter().find(|(n, _)| n == "sdf").with_context(|| {
        format!(
            "{}: no array 'sdf' (the archive holds: {})",
            path.display(),
            names.join(", ")
        )
    })?;
    if sdf.shape.len() != 3 {
        anyhow::bail!(
            "{}: 'sdf' must be a 3D grid, it has shape {:?}",
            path.display(),
            sdf.shape
        );
    }
    let dims = [sdf.shape[0], sdf.shape[1], sdf.shape[2]];
    let grid = ponq_mesh::io::npy::Grid3::new(dims, sdf.data.clone()).with_context(context)?;
    let colours = match arrays.iter().find(|(n, _)| with_colours && n == "rgb") {
        None => None,
        Some((_, rgb)) => {
            if rgb.shape != [dims[0], dims[1], dims[2], 3] {
                anyhow::bail!(
                    "{}: 'rgb' must have the grid's shape and 3 channels, {:?}; it has {:?}",
                    path.display(),
                    [dims[0], dims[1], dims[2], 3],
                    rgb.shape
                );
            }
            // The dtype decides: bytes are 0..=255, floats fractions in [0, 1] (as Python's
            // `ponq.infer(colours=)` reads them).
            let top = if rgb.was_bytes { 255.0 } else { 1.0 };
            if let Some(v) = rgb
                .data
                .iter()
                .find(|v| !(v.is_finite() && **v >= 0.0 && **v <= top))
            {
                anyhow::bail!(
                    "{}: 'rgb' holds {v}: colours are floats in [0, 1] or uint8",
                    path.display()
                );
            }
            let scale = 1.0 / top;
            Some(
                rgb.data
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]].map(|x| ((x * scale) as f32).clamp(0.0, 1.0)))
                    .collect(),
            )
        }
    };
    let (band, conditioning) =
        crate::reconstruct::conditioned_band(&grid, encoder_layers, opts).with_context(context)?;
    Ok(GridInput {
        band,
        conditioning,
        colours,
    })
}
