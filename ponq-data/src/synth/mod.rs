//! Procedural CAD-like training shapes (SPEC section 4): seeded, reproducible, and every mesh
//! closed, oriented, manifold and free of self-intersections.
//!
//! A shape is a CSG tree (union, difference, intersection) of analytic primitives — boxes,
//! cylinders, cone frustums, spheres, tori, prisms (extruded convex polygons) and slots (stadium
//! extrusions) — placed by rigid frames (random, axis-aligned or identity rotations) with
//! independently drawn dimensions, so that parts have sharp edges of many dihedral angles, thin
//! walls (0.02 to 0.06 thick), drilled holes, pockets and handles (see [`design`] for the
//! recipe). Each primitive has an exact inside test and exact area-uniform surface sampling
//! with true normals; the samples of the solid are the primitive samples that lie on the
//! boundary of the CSG result ([`csg`]), with flipped normals on subtracted walls.
//!
//! The mesh comes from the project's own pipeline: the samples are clustered by the cells of a
//! `mesh_resolution^3` grid over the part (cells holding opposite-facing samples, like both
//! sides of a wall thinner than a cell, are split by normal), each cluster becomes a PoNQ point
//! (mean position, mean normal, mean plane quadric: its QEM v* recovers sharp edges and
//! corners, [`Ponq::from_clusters`]) and [`mesh_ponq`] meshes them with
//! `grid_scale = mesh_resolution`. A shape is kept only if its mesh is non-empty, a single
//! connected component, valid under the exact [`validity::check`], within
//! [`SynthOptions::volume_tolerance`] of a Monte-Carlo volume of the CSG and close to the
//! analytic samples (and they to it); otherwise the design is redrawn from the same random
//! stream (so the result stays a function of the seed).
//!
//! Everything emitted is in the `[-1,1]` convention of [`crate::normalize`]: the mesh's
//! bounding box is centred at the origin with diagonal 2, and the samples, normals, the
//! [`SynthShape::solid`] and its description are in the same frame.
//!
//! ```
//! use ponq_data::synth::{SynthOptions, generate};
//! let opts = SynthOptions { mesh_resolution: 32, samples: 2_000, ..Default::default() };
//! let shape = generate(7, &opts)?;
//! assert!(ponq_mesh::validity::check(&shape.mesh).is_valid());
//! assert_eq!(shape.samples.len(), 2_000);
//! // The same seed gives the same shape, bit for bit.
//! assert_eq!(generate(7, &opts)?.mesh, shape.mesh);
//! // The analytic solid answers inside queries in the mesh's frame.
//! let (p, n) = (shape.samples[0], shape.normals[0]);
//! assert!(shape.inside([p[0] - 1e-6 * n[0], p[1] - 1e-6 * n[1], p[2] - 1e-6 * n[2]]));
//! println!("{}", shape.description);
//! # Ok::<(), ponq_data::DataError>(())
//! ```

pub mod csg;
pub mod design;
pub mod distance;
pub mod geom;
pub mod primitive;
pub mod smooth;

use std::time::{Duration, Instant};

use ponq_mesh::bvh::{Aabb, Bvh};
use ponq_mesh::lite::cell_of;
use ponq_mesh::mesher::{MeshingOptions, mesh_ponq};
use ponq_mesh::nn::PointIndex;
use ponq_mesh::{Ponq, TriMesh, validity};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

pub use csg::{Csg, Patch, Solid};
pub use design::Family;
pub use geom::{Frame, V3};
pub use primitive::{Kind, Primitive};

use crate::error::{DataError, Result};
use crate::normalize::Normalization;
use geom::{dot, point_triangle_dist2, sub};

/// Options of [`generate`].
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    /// Grid resolution `N` of the clustering and of the mesher's `grid_scale` (96). The part
    /// fills a bounding-box diagonal of 1.9 of the `[-1,1]^3` grid while it is meshed.
    pub mesh_resolution: usize,
    /// Number of analytic surface samples (with normals) returned in [`SynthShape::samples`]
    /// (100,000).
    pub samples: usize,
    /// Upper bound on the number of primitives of a design (12); a design draws between a
    /// third of it and all of it.
    pub max_primitives: usize,
    /// Mean number of samples per occupied grid cell used for meshing (16); more samples than
    /// [`SynthOptions::samples`] are drawn when this needs them.
    pub samples_per_cell: f64,
    /// Uniform points of the Monte-Carlo volume estimate (100,000).
    pub volume_samples: usize,
    /// Largest relative difference between the mesh's volume and the Monte-Carlo volume of
    /// the CSG, on top of four standard errors of the estimate (0.04).
    pub volume_tolerance: f64,
    /// Distance, in grid cells, within which samples must lie from the mesh and mesh vertices
    /// from the samples (1.5); see [`SynthOptions::far_fraction`].
    pub surface_tolerance: f64,
    /// Largest fraction of checked samples (and of mesh vertices) farther than
    /// `surface_tolerance` (0.01).
    pub far_fraction: f64,
    /// Designs tried before giving up (30).
    pub max_attempts: u32,
    /// Run the exact [`validity::check`] (self-intersections included) on every mesh (true).
    pub validate: bool,
    /// Relative frequencies of the shape families (CSG parts only by default).
    pub mix: SynthMix,
}

/// Relative frequencies of the families of generated shapes ([`design::Family`]): each design
/// draws its family from these weights (from the seed's random stream). With only `csg`
/// positive (the default), no draw is made, so the shapes are those of earlier versions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthMix {
    /// Sharp-edged CSG parts.
    pub csg: f64,
    /// CSG features on a filleted base, rounded bosses.
    pub filleted: f64,
    /// Turned parts (coaxial sections, grooves, bores).
    pub lathe: f64,
    /// Free-form bodies without edges (ellipsoids, smooth blocks).
    pub freeform: f64,
}

impl Default for SynthMix {
    fn default() -> Self {
        Self {
            csg: 1.0,
            filleted: 0.0,
            lathe: 0.0,
            freeform: 0.0,
        }
    }
}

impl SynthMix {
    fn weights(&self) -> [f64; 4] {
        [self.csg, self.filleted, self.lathe, self.freeform]
    }

    /// Checks that the weights are finite, non-negative and not all zero.
    pub fn check(&self) -> Result<()> {
        let w = self.weights();
        if w.iter().any(|x| !(x.is_finite() && *x >= 0.0)) || !(w.iter().sum::<f64>() > 0.0) {
            return Err(DataError::Invalid(format!(
                "the family weights must be non-negative and not all zero, got {self:?}"
            )));
        }
        Ok(())
    }

    /// The family of a design: `csg` without a draw when it is the only one.
    fn draw(&self, rng: &mut ChaCha8Rng) -> design::Family {
        let w = self.weights();
        if w[1..].iter().all(|&x| x == 0.0) {
            return design::Family::Csg;
        }
        let x = rng.random::<f64>() * w.iter().sum::<f64>();
        let mut acc = 0.0;
        for (i, f) in [
            design::Family::Csg,
            design::Family::Filleted,
            design::Family::Lathe,
            design::Family::Freeform,
        ]
        .into_iter()
        .enumerate()
        {
            acc += w[i];
            if x < acc {
                return f;
            }
        }
        design::Family::Freeform
    }
}

impl Default for SynthOptions {
    fn default() -> Self {
        Self {
            mesh_resolution: 96,
            samples: 100_000,
            max_primitives: 12,
            samples_per_cell: 16.0,
            volume_samples: 100_000,
            volume_tolerance: 0.04,
            surface_tolerance: 1.5,
            far_fraction: 0.01,
            max_attempts: 30,
            validate: true,
            mix: SynthMix::default(),
        }
    }
}

/// Measurements of an accepted shape.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SynthStats {
    /// Volume of the mesh (`[-1,1]` frame).
    pub mesh_volume: f64,
    /// Monte-Carlo volume of the CSG (`[-1,1]` frame).
    pub csg_volume: f64,
    /// Area of the CSG surface estimated from the acceptance rate of primitive samples.
    pub csg_area: f64,
    /// Genus of the mesh (from its Euler characteristic).
    pub genus: i64,
    /// Samples clustered for meshing (the returned samples are the first of them).
    pub mesh_samples: usize,
    /// PoNQ points (clusters) meshed.
    pub ponq_points: usize,
    /// Fraction of checked samples farther than `surface_tolerance` from the mesh.
    pub far_samples: f64,
    /// Largest sample-to-mesh distance found, in grid cells.
    pub max_sample_distance: f64,
    /// Fraction of mesh vertices farther than `surface_tolerance` from every sample.
    pub far_vertices: f64,
    /// Time spent designing and sampling, meshing, and checking (accepted attempt only).
    pub times: [Duration; 3],
}

/// A generated shape, in the `[-1,1]` frame (bounding box of `mesh` centred, diagonal 2).
#[derive(Debug, Clone)]
pub struct SynthShape {
    /// Closed, oriented, manifold, self-intersection-free mesh.
    pub mesh: TriMesh,
    /// Exact, area-uniform samples of the CSG surface.
    pub samples: Vec<[f64; 3]>,
    /// Outward unit normals of the samples.
    pub normals: Vec<[f64; 3]>,
    /// The family of the design.
    pub family: design::Family,
    /// The CSG tree, one primitive per line (same frame).
    pub description: String,
    /// The analytic solid (same frame).
    pub solid: Solid,
    /// Designs drawn for this seed (1 when the first was accepted).
    pub attempts: u32,
    /// Why each earlier design of this seed was rejected.
    pub rejected: Vec<String>,
    /// Measurements.
    pub stats: SynthStats,
}

impl SynthShape {
    /// Exact inside test of the CSG solid (`[-1,1]` frame).
    pub fn inside(&self, p: [f64; 3]) -> bool {
        self.solid.inside(p)
    }

    /// Names of the primitive kinds used (with repetitions, in primitive order).
    pub fn primitive_kinds(&self) -> Vec<&'static str> {
        self.solid
            .primitives()
            .iter()
            .map(|p| p.kind().name())
            .collect()
    }
}

/// Part diagonal while meshing: a margin inside the `[-1,1]^3` box of the mesher.
const MESH_DIAGONAL: f64 = 1.9;
/// Two samples of one cell whose normals have a dot product below this go to different
/// clusters.
const SPLIT_DOT: f64 = -0.5;
/// At most this many clusters per cell.
const MAX_SPLIT: usize = 4;
/// Samples checked against the mesh.
const CHECKED_SAMPLES: usize = 4000;

/// Generates the shape of `seed`: the same seed and options give the same shape, bit for bit.
///
/// # Errors
/// [`DataError::Invalid`] for options out of range, or when `max_attempts` designs in a row
/// were rejected (the message gives the last reason).
pub fn generate(seed: u64, opts: &SynthOptions) -> Result<SynthShape> {
    if !(4..=1024).contains(&opts.mesh_resolution) {
        return Err(DataError::Invalid(format!(
            "mesh resolution must be between 4 and 1024, got {}",
            opts.mesh_resolution
        )));
    }
    if !(opts.samples_per_cell >= 1.0 && opts.samples_per_cell.is_finite()) {
        return Err(DataError::Invalid(format!(
            "samples per cell must be at least 1, got {}",
            opts.samples_per_cell
        )));
    }
    opts.mix.check()?;
    if opts.max_primitives == 0 || opts.max_attempts == 0 || opts.volume_samples < 1000 {
        return Err(DataError::Invalid(
            "max_primitives and max_attempts must be positive and volume_samples at least 1000"
                .into(),
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut rejected = Vec::new();
    for attempt in 1..=opts.max_attempts {
        match attempt_shape(&mut rng, opts) {
            Ok(mut s) => {
                s.attempts = attempt;
                s.rejected = rejected;
                return Ok(s);
            }
            Err(reason) => rejected.push(reason),
        }
    }
    Err(DataError::Invalid(format!(
        "seed {seed}: no valid shape in {} attempts (last: {})",
        opts.max_attempts,
        rejected.last().map_or("", String::as_str)
    )))
}

/// One design, sampled, meshed and checked; `Err(reason)` when rejected.
fn attempt_shape(rng: &mut ChaCha8Rng, opts: &SynthOptions) -> Result<SynthShape, String> {
    let t0 = Instant::now();
    let family = opts.mix.draw(rng);
    let solid = design::design_family(rng, opts.max_primitives, family);
    let keys: [u64; 3] = [rng.random(), rng.random(), rng.random()];
    let n_first = opts.samples.max(4096);
    let first = solid
        .sample_boundary(n_first, keys[0], 400)
        .ok_or("too few primitive samples lie on the boundary")?;
    let area = solid.total_area() * first.points.len() as f64 / first.drawn as f64;
    let (lo, hi) = bbox(&first.points);
    let diag = dot(sub(hi, lo), sub(hi, lo)).sqrt();
    if !(diag > 1e-6) {
        return Err("degenerate bounding box".into());
    }
    // Meshing frame: m = (p - c0) * s0.
    let c0: V3 = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let s0 = MESH_DIAGONAL / diag;
    let res = opts.mesh_resolution;
    let cell = 2.0 / res as f64;
    let need = (opts.samples_per_cell * 1.5 * area * s0 * s0 / (cell * cell)).ceil() as usize;
    let (mut points, mut normals) = (first.points, first.normals);
    if need > points.len() {
        let more = solid
            .sample_boundary(need - points.len(), keys[1], 400)
            .ok_or("too few primitive samples lie on the boundary")?;
        points.extend(more.points);
        normals.extend(more.normals);
    }
    let to_mesh = |p: &V3| -> V3 { std::array::from_fn(|k| (p[k] - c0[k]) * s0) };
    let pm: Vec<V3> = points.par_iter().map(to_mesh).collect();
    let t_sample = t0.elapsed();

    let t1 = Instant::now();
    let (cluster, n_clusters) = cluster_by_cell(&pm, &normals, res);
    let (ponq, _) =
        Ponq::from_clusters(&pm, &normals, &cluster, n_clusters).map_err(|e| e.to_string())?;
    let out = mesh_ponq(
        &ponq,
        &MeshingOptions {
            grid_scale: res as f64,
            ..Default::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let mesh_m = out.mesh;
    let t_mesh = t1.elapsed();

    let t2 = Instant::now();
    if mesh_m.faces.is_empty() {
        return Err(out.message.unwrap_or_else(|| "empty mesh".into()));
    }
    let components = components(&mesh_m);
    if components != 1 {
        return Err(format!("{components} connected components"));
    }
    // Volumes in the meshing frame.
    let mesh_volume = mesh_m.signed_volume();
    let (csg_volume, rel_sigma) = mc_volume(&solid, lo, hi, opts.volume_samples, keys[2]);
    let csg_volume = csg_volume * s0.powi(3);
    let tol = opts.volume_tolerance + 4.0 * rel_sigma;
    if !(csg_volume > 0.0) || !((mesh_volume - csg_volume).abs() <= tol * csg_volume) {
        return Err(format!(
            "mesh volume {mesh_volume:.5} vs CSG volume {csg_volume:.5} (tolerance {tol:.3})"
        ));
    }
    // Samples near the mesh, mesh vertices near the samples (distances in cells).
    let (far_samples, max_sample_distance) =
        samples_to_mesh(&mesh_m, &pm, opts.surface_tolerance * cell);
    let far_vertices = vertices_to_samples(&mesh_m, &pm, opts.surface_tolerance * cell);
    if far_samples > opts.far_fraction || far_vertices > opts.far_fraction {
        return Err(format!(
            "{:.2}% of samples and {:.2}% of mesh vertices farther than {} cells",
            100.0 * far_samples,
            100.0 * far_vertices,
            opts.surface_tolerance
        ));
    }
    if opts.validate {
        let report = validity::check(&mesh_m);
        if !report.is_valid() {
            return Err(format!("mesh {report}"));
        }
    }
    let chi = mesh_m.vertices.len() as i64 - (3 * mesh_m.faces.len() / 2) as i64
        + mesh_m.faces.len() as i64;
    let genus = (2 - chi) / 2;

    // The [-1,1] frame: f = (m - c2) * s2 = (p - c0 - c2 / s0) * s0 * s2.
    let norm = Normalization::of(&mesh_m).map_err(|e| e.to_string())?;
    let mesh = norm.apply_mesh(&mesh_m);
    let k = opts.samples;
    let samples: Vec<V3> = pm[..k].iter().map(|&m| norm.apply(m)).collect();
    let normals: Vec<V3> = normals[..k].to_vec();
    let centre: V3 = std::array::from_fn(|i| c0[i] + norm.centre[i] / s0);
    let solid = solid.similar(centre, s0 * norm.scale);
    let f3 = norm.scale.powi(3);
    let stats = SynthStats {
        mesh_volume: mesh_volume * f3,
        csg_volume: csg_volume * f3,
        csg_area: area * (s0 * norm.scale).powi(2),
        genus,
        mesh_samples: pm.len(),
        ponq_points: ponq.len(),
        far_samples,
        max_sample_distance: max_sample_distance / cell,
        far_vertices,
        times: [t_sample, t_mesh, t2.elapsed()],
    };
    Ok(SynthShape {
        mesh,
        samples,
        normals,
        family,
        description: solid.describe(),
        solid,
        attempts: 1,
        rejected: Vec::new(),
        stats,
    })
}

fn bbox(points: &[V3]) -> (V3, V3) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Cluster ids of the samples: one cluster per grid cell, split by normal where a cell holds
/// opposite-facing samples (both sides of a thin wall, a narrow slit). Ids follow cell order.
/// Returns the ids and their count.
fn cluster_by_cell(points: &[V3], normals: &[V3], res: usize) -> (Vec<u32>, usize) {
    let n = res as u64;
    let mut order: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = cell_of(*p, res, ([-1.0; 3], [1.0; 3]));
            (
                (u64::from(c[0]) * n + u64::from(c[1])) * n + u64::from(c[2]),
                i as u32,
            )
        })
        .collect();
    order.par_sort_unstable();
    let mut ids = vec![0u32; points.len()];
    let mut next = 0u32;
    let mut centres: Vec<V3> = Vec::with_capacity(MAX_SPLIT);
    for group in order.chunk_by(|a, b| a.0 == b.0) {
        let nrm = |j: usize| normals[group[j].1 as usize];
        centres.clear();
        // Two far-apart normals (two sweeps of farthest-point), then more while some sample
        // faces away from every centre.
        let argmin = |c: V3| {
            (0..group.len())
                .min_by(|&a, &b| dot(c, nrm(a)).total_cmp(&dot(c, nrm(b))))
                .unwrap_or(0)
        };
        let j1 = argmin(nrm(0));
        let j2 = argmin(nrm(j1));
        if dot(nrm(j1), nrm(j2)) < SPLIT_DOT {
            centres.push(nrm(j1));
            centres.push(nrm(j2));
            while centres.len() < MAX_SPLIT {
                let (j, best) = (0..group.len())
                    .map(|j| {
                        let b = centres
                            .iter()
                            .map(|&c| dot(c, nrm(j)))
                            .fold(f64::NEG_INFINITY, f64::max);
                        (j, b)
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .unwrap_or((0, 1.0));
                if best < SPLIT_DOT {
                    centres.push(nrm(j));
                } else {
                    break;
                }
            }
        }
        for (j, &(_, i)) in group.iter().enumerate() {
            let mut best = 0;
            for c in 1..centres.len() {
                if dot(centres[c], nrm(j)) > dot(centres[best], nrm(j)) {
                    best = c;
                }
            }
            ids[i as usize] = next + best as u32;
        }
        next += centres.len().max(1) as u32;
    }
    (ids, next as usize)
}

/// Connected components of the faces (through shared vertices).
fn components(mesh: &TriMesh) -> usize {
    let mut parent: Vec<u32> = (0..mesh.vertices.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    let mut used = vec![false; mesh.vertices.len()];
    for f in &mesh.faces {
        for &v in f {
            used[v as usize] = true;
        }
        let a = find(&mut parent, f[0]);
        for &v in &f[1..] {
            let b = find(&mut parent, v);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    (0..mesh.vertices.len() as u32)
        .filter(|&v| used[v as usize] && find(&mut parent, v) == v)
        .count()
}

/// Monte-Carlo volume of the solid in its bounding box `lo..hi` (padded by 1%), with the
/// relative standard error of the estimate.
fn mc_volume(solid: &Solid, lo: V3, hi: V3, n: usize, key: u64) -> (f64, f64) {
    let pad: V3 = std::array::from_fn(|k| 0.01 * (hi[k] - lo[k]) + 1e-9);
    let lo: V3 = std::array::from_fn(|k| lo[k] - pad[k]);
    let hi: V3 = std::array::from_fn(|k| hi[k] + pad[k]);
    const CH: usize = 8192;
    let hits: usize = (0..n.div_ceil(CH))
        .into_par_iter()
        .map(|c| {
            let mut rng = ChaCha8Rng::seed_from_u64(key);
            rng.set_stream(c as u64);
            (0..CH.min(n - c * CH))
                .filter(|_| {
                    let p: V3 =
                        std::array::from_fn(|k| lo[k] + (hi[k] - lo[k]) * rng.random::<f64>());
                    solid.inside(p)
                })
                .count()
        })
        .sum();
    let box_volume: f64 = (0..3).map(|k| hi[k] - lo[k]).product();
    let f = hits as f64 / n as f64;
    let rel = if hits > 0 {
        ((1.0 - f) / (f * n as f64)).sqrt()
    } else {
        f64::INFINITY
    };
    (f * box_volume, rel)
}

fn face_bvh(mesh: &TriMesh) -> Bvh {
    let boxes: Vec<Aabb> = (0..mesh.faces.len())
        .map(|f| Aabb::from_points(&mesh.triangle(f)))
        .collect();
    Bvh::build(&boxes)
}

/// Fraction of (up to [`CHECKED_SAMPLES`], evenly strided) samples farther than `tol` from the
/// mesh, and the largest distance found.
fn samples_to_mesh(mesh: &TriMesh, samples: &[V3], tol: f64) -> (f64, f64) {
    let bvh = face_bvh(mesh);
    let step = samples.len().div_ceil(CHECKED_SAMPLES).max(1);
    let picked: Vec<V3> = samples.iter().step_by(step).copied().collect();
    let d: Vec<f64> = picked
        .par_iter()
        .map(|&p| {
            bvh.nearest(p, |f| {
                let [a, b, c] = mesh.triangle(f);
                point_triangle_dist2(p, a, b, c)
            })
            .map_or(f64::INFINITY, |x| x.1.sqrt())
        })
        .collect();
    let far = d.iter().filter(|&&x| !(x <= tol)).count();
    let max = d.iter().copied().fold(0.0, f64::max);
    (far as f64 / d.len().max(1) as f64, max)
}

/// Fraction of mesh vertices farther than `tol` from every sample.
fn vertices_to_samples(mesh: &TriMesh, samples: &[V3], tol: f64) -> f64 {
    let Some(index) = PointIndex::new(samples) else {
        return 1.0;
    };
    let d = index.nearest_many(&mesh.vertices);
    let far = d.iter().filter(|x| !(x.1 <= tol * tol)).count();
    far as f64 / mesh.vertices.len().max(1) as f64
}
