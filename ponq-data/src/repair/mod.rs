//! Repair of broken meshes before their signed distance: any triangle soup in, a surface whose
//! exact signed distance is the one of the solid the input describes.
//!
//! Real meshes are rarely closed, oriented, manifold solids (Thingi10K: half are not solid, 45%
//! self-intersect, 22% are non-manifold; Zhou and Jacobson 2016). [`repair`] first looks:
//! after merging vertices at exactly the same position, a mesh that is closed, consistently
//! oriented and manifold, of one part (or of several parts that neither cross nor sit inside
//! each other the wrong way) is handed on unchanged, so clean inputs keep their results bit
//! for bit. Any other mesh goes through, in order:
//! 1. [`weld`]: vertices within `weld` of the bounding-box diagonal become one (cracks);
//! 2. faces with a repeated vertex are dropped, and of faces on the same three vertices
//!    (either orientation) the first is kept;
//! 3. [`orient`]: each part (faces joined across edges of two faces) is oriented consistently,
//!    keeping the orientation of the larger area;
//! 4. [`holes`]: every loop of boundary edges is closed by a fan;
//! 5. each outermost part (not inside another, by the winding number of the others) whose
//!    enclosed volume is negative is turned outward; parts inside others keep their
//!    orientation (a cavity faces inward);
//! 6. [`sides`]: on the parts that cross another, sit inside another, or are not closed, every
//!    face is tested with the generalised winding number of the whole mesh on both of its
//!    sides: a face with the solid on both sides or on neither (internal faces, nested
//!    shells, fins, the part of an overlapping copy inside the other) is removed, one with the
//!    solid in front is flipped.
//!
//! The result is the boundary of the solid `|w| > 1/2` (Jacobson et al. 2013), closed where the
//! input only had holes, so its exact distance is a true signed distance and the refinement
//! finds it. What was found and done is a [`DefectReport`]. For genuinely open surfaces
//! ([`RepairOptions::open_surface`]) steps 4-6 are skipped: nothing is closed or removed.
//!
//! ```
//! use ponq_data::repair::{RepairOptions, repair};
//! use ponq_mesh::TriMesh;
//! // A tetrahedron with one face flipped and one duplicated the other way round.
//! let v = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
//! let f = vec![[0, 2, 1], [0, 3, 1], [1, 2, 3], [2, 0, 3], [3, 2, 1]];
//! let (fixed, report) = repair(&TriMesh::new(v, f).unwrap(), &RepairOptions::default()).unwrap();
//! assert_eq!(report.duplicate_faces, 1);
//! assert!(ponq_mesh::validity::check(&fixed).is_valid());
//! assert!(fixed.signed_volume() > 0.0);
//! ```

mod edges;
mod holes;
mod orient;
mod report;
mod sides;
mod weld;

pub use report::DefectReport;

use std::collections::HashMap;

use ponq_mesh::TriMesh;
use ponq_mesh::validity::intersecting_face_pairs;

use crate::error::{DataError, Result};
use crate::sdf::MeshSdf;
use edges::{count_edges, edge_uses, manifold_components};
use sides::{Side, classify, part_winding};

/// How [`repair`] works.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RepairOptions {
    /// Vertices closer than this fraction of the bounding-box diagonal are merged (1e-4: far
    /// below a grid cell at any resolution the programs take, and above the gaps of vertices
    /// written with few digits).
    pub weld: f64,
    /// Close holes (steps 4-5 of the module docs).
    pub fill_holes: bool,
    /// Remove the faces that separate nothing and flip the inverted ones (step 6).
    pub remove_internal: bool,
    /// Leave open the loops of more boundary edges than this.
    pub max_hole_edges: usize,
}

impl Default for RepairOptions {
    /// For solids: every step.
    fn default() -> Self {
        Self {
            weld: 1e-4,
            fill_holes: true,
            remove_internal: true,
            max_hole_edges: usize::MAX,
        }
    }
}

impl RepairOptions {
    /// For open surfaces (cloth, a terrain): weld, drop degenerate and duplicate faces, orient
    /// consistently; close nothing and remove nothing.
    pub fn open_surface() -> Self {
        Self {
            fill_holes: false,
            remove_internal: false,
            ..Self::default()
        }
    }
}

/// Checks a mesh's data: at least one face, finite coordinates, indices in range, a bounding
/// box with some extent. Returns the bounding-box diagonal.
fn check_input(mesh: &TriMesh) -> Result<f64> {
    if mesh.faces.is_empty() {
        return Err(DataError::Invalid(
            "the mesh has no face: nothing to reconstruct".into(),
        ));
    }
    if let Some(i) = mesh
        .vertices
        .iter()
        .position(|v| v.iter().any(|x| !x.is_finite()))
    {
        return Err(DataError::Invalid(format!(
            "vertex {i} of the mesh has a non-finite coordinate {:?}",
            mesh.vertices[i]
        )));
    }
    let n = mesh.vertices.len();
    if let Some((i, f)) = mesh
        .faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v as usize >= n))
    {
        return Err(DataError::Invalid(format!(
            "face {i} = {f:?} refers to a vertex >= the vertex count {n}"
        )));
    }
    let (lo, hi) = mesh
        .bounding_box()
        .ok_or_else(|| DataError::Invalid("the mesh has no vertex".into()))?;
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    if !(diag > 0.0 && diag.is_finite()) {
        return Err(DataError::Invalid(
            "the mesh's vertices are all at one point: it has no volume".into(),
        ));
    }
    Ok(diag)
}

/// `faces` with `map` applied, without the faces that repeat a vertex and without repeats of
/// a face (the same three vertices, either orientation; the first is kept). Returns the faces
/// and the counts (degenerate, duplicates, of which opposite).
fn distinct_faces(faces: &[[u32; 3]], map: &[u32]) -> (Vec<[u32; 3]>, usize, usize, usize) {
    let mut out = Vec::with_capacity(faces.len());
    let mut seen: HashMap<[u32; 3], [u32; 3]> = HashMap::with_capacity(faces.len());
    let (mut degenerate, mut dups, mut opposite) = (0, 0, 0);
    for f in faces {
        let t = f.map(|v| map[v as usize]);
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            degenerate += 1;
            continue;
        }
        let mut key = t;
        key.sort_unstable();
        match seen.get(&key) {
            Some(first) => {
                dups += 1;
                // The same cyclic order or the reverse.
                let same = (0..3).any(|r| [0, 1, 2].map(|k| first[(k + r) % 3]) == t);
                opposite += usize::from(!same);
            }
            None => {
                seen.insert(key, t);
                out.push(t);
            }
        }
    }
    (out, degenerate, dups, opposite)
}

/// The largest face of each part (index of a face with the largest area), `u32::MAX` for none.
fn largest_face_per_part(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    comp: &[u32],
    parts: usize,
) -> Vec<u32> {
    use ponq_mesh::vec3::{cross, dot, sub};
    let mut best = vec![(f64::NEG_INFINITY, u32::MAX); parts];
    for (f, t) in faces.iter().enumerate() {
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        let n = cross(sub(b, a), sub(c, a));
        let area = dot(n, n);
        let e = &mut best[comp[f] as usize];
        if area > e.0 {
            *e = (area, f as u32);
        }
    }
    best.into_iter().map(|b| b.1).collect()
}

/// The parts that need each face tested (step 6): those with a face crossing a face of
/// another part or of itself (`pairs`), those whose largest face does not separate the solid
/// from the outside, and those flagged in `open_parts`.
fn parts_to_test(
    sdf: &MeshSdf,
    mesh: &TriMesh,
    comp: &[u32],
    parts: usize,
    pairs: &[(usize, usize)],
    open_parts: &[bool],
    eps: f64,
) -> Vec<bool> {
    let mut test = open_parts.to_vec();
    for &(i, j) in pairs {
        test[comp[i] as usize] = true;
        test[comp[j] as usize] = true;
    }
    let largest = largest_face_per_part(&mesh.vertices, &mesh.faces, comp, parts);
    let mut probe = vec![false; mesh.faces.len()];
    for (p, &f) in largest.iter().enumerate() {
        if !test[p] && f != u32::MAX {
            probe[f as usize] = true;
        }
    }
    let sides = classify(sdf, &mesh.vertices, &mesh.faces, &probe, eps);
    for (p, &f) in largest.iter().enumerate() {
        if f != u32::MAX && probe[f as usize] && sides[f as usize] != Side::Boundary {
            test[p] = true;
        }
    }
    test
}

/// The side of every face with `test` (the others: [`Side::Boundary`]), region by region: the
/// faces joined across edges of exactly two faces, neither crossing another face (`pairs`),
/// are on one side throughout (a side only changes across a surface), so the largest face of
/// each region is tested for all of it; faces that cross another are tested one by one. (Face
/// by face, the two winding numbers per face were most of the repair's time on overlapping
/// copies.)
fn classify_by_regions(
    solid: &MeshSdf,
    m: &TriMesh,
    uses: &[edges::EdgeUse],
    pairs: &[(usize, usize)],
    test: &[bool],
    eps: f64,
) -> Vec<Side> {
    let n = m.faces.len();
    let mut crossing = vec![false; n];
    for &(i, j) in pairs {
        crossing[i] = true;
        crossing[j] = true;
    }
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn root(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let joins = |f: u32| test[f as usize] && !crossing[f as usize];
    for g in edges::by_edge(uses) {
        if g.len() == 2 && joins(g[0].face) && joins(g[1].face) {
            let (a, b) = (root(&mut parent, g[0].face), root(&mut parent, g[1].face));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let area = |f: usize| {
        use ponq_mesh::vec3::{cross, dot, sub};
        let [a, b, c] = m.faces[f].map(|i| m.vertices[i as usize]);
        let x = cross(sub(b, a), sub(c, a));
        dot(x, x)
    };
    // The largest face of each region.
    let mut rep: HashMap<u32, (f64, usize)> = HashMap::new();
    for f in 0..n {
        if test[f] && !crossing[f] {
            let r = root(&mut parent, f as u32);
            let a = area(f);
            let e = rep.entry(r).or_insert((a, f));
            if a > e.0 {
                *e = (a, f);
            }
        }
    }
    let mut probe: Vec<bool> = (0..n).map(|f| test[f] && crossing[f]).collect();
    for &(_, f) in rep.values() {
        probe[f] = true;
    }
    let probed = classify(solid, &m.vertices, &m.faces, &probe, eps);
    (0..n)
        .map(|f| {
            if !test[f] {
                Side::Boundary
            } else if crossing[f] {
                probed[f]
            } else {
                probed[rep[&root(&mut parent, f as u32)].1]
            }
        })
        .collect()
}

/// Repairs `mesh` as the [module docs](self) say; returns the mesh to take the signed
/// distance of and the report. The output's vertices are the input's (merged), plus one per
/// hole of more than three edges.
///
/// # Errors
/// A mesh without faces, with non-finite coordinates, indices out of range, all its vertices
/// at one point, or with nothing left after the repair.
pub fn repair(mesh: &TriMesh, opts: &RepairOptions) -> Result<(TriMesh, DefectReport)> {
    repair_with_solid(mesh, opts).map(|r| (r.mesh, r.report))
}

/// A repaired mesh ([`repair_with_solid`]).
#[derive(Debug, Clone)]
pub struct Repaired {
    /// The surface to take distances to.
    pub mesh: TriMesh,
    /// When faces that separate nothing were removed (step 6): the closed, oriented surface
    /// they were removed from, whose winding number (`|w| > 1/2`) is the inside of `mesh`'s
    /// solid without the cracks the removal may leave where copies cross.
    pub solid: Option<TriMesh>,
    /// What was found and done.
    pub report: DefectReport,
    /// The sign is the fast winding number of [`Repaired::mesh`]'s faces as they are
    /// ([`MeshSdf::with_fast_winding`]): the topological repair could not prove a closed
    /// surface (the report's `winding_sign` says why).
    pub fast_sign: bool,
}

impl Repaired {
    /// The exact signed distance grid (`res` cells per side over `[-1,1]^3`) of the repaired
    /// mesh moved by `map` (the normalisation, or the identity): distances to
    /// [`Repaired::mesh`], the sign of [`Repaired::solid`] where there is one.
    ///
    /// # Errors
    /// As [`MeshSdf::grid`].
    pub fn grid(
        &self,
        map: impl Fn(&TriMesh) -> TriMesh,
        res: usize,
        progress: impl Fn(usize) + Sync,
    ) -> Result<crate::sdf::SdfGrid> {
        let sdf = self.distances(&map(&self.mesh))?;
        match &self.solid {
            Some(s) => sdf.grid_signed_by(&MeshSdf::new(&map(s))?, res, progress),
            None => sdf.grid(res, progress),
        }
    }
}

impl Repaired {
    /// The distance (and, without a solid, sign) structure of `mesh`, the repaired mesh
    /// moved: signed by the fast winding number when [`Repaired::fast_sign`].
    ///
    /// # Errors
    /// As [`MeshSdf::new`].
    pub fn distances(&self, mesh: &TriMesh) -> Result<MeshSdf> {
        if self.fast_sign {
            MeshSdf::with_fast_winding(mesh)
        } else {
            MeshSdf::new(mesh)
        }
    }

    /// [`Repaired::grid`] near the surface only ([`MeshSdf::band_signed_by`]).
    ///
    /// # Errors
    /// As [`MeshSdf::band_signed_by`].
    pub fn band(
        &self,
        map: impl Fn(&TriMesh) -> TriMesh,
        res: usize,
        scale: f64,
        threshold: f64,
        reach: usize,
        progress: impl Fn(usize, usize) + Sync,
    ) -> Result<crate::sdf::SdfBand> {
        let sdf = self.distances(&map(&self.mesh))?;
        match &self.solid {
            Some(s) => sdf.band_signed_by(
                &MeshSdf::new(&map(s))?,
                res,
                scale,
                threshold,
                reach,
                progress,
            ),
            None => sdf.band_signed_by(&sdf, res, scale, threshold, reach, progress),
        }
    }
}

/// [`repair`], with the closed surface that signs the result where faces were removed.
///
/// # Errors
/// As [`repair`].
pub fn repair_with_solid(mesh: &TriMesh, opts: &RepairOptions) -> Result<Repaired> {
    let diag = check_input(mesh)?;
    let eps = 1e-6 * diag;
    let mut report = DefectReport {
        input_vertices: mesh.vertices.len(),
        input_faces: mesh.faces.len(),
        ..Default::default()
    };
    // What the input is, after merging exact copies of vertices.
    let (exact, _) = weld::weld_map(&mesh.vertices, 0.0);
    let (faces0, degenerate, dups, opposite) = distinct_faces(&mesh.faces, &exact);
    let counts = count_edges(
        &mesh
            .faces
            .iter()
            .map(|f| f.map(|v| exact[v as usize]))
            .collect::<Vec<_>>(),
    );
    let uses0 = edge_uses(&faces0);
    let (comp0, parts0) = manifold_components(&faces0, &uses0);
    report.boundary_edges = counts.boundary;
    report.nonmanifold_edges = counts.nonmanifold;
    report.misoriented_edges = counts.misoriented;
    report.degenerate_faces = degenerate;
    report.duplicate_faces = dups;
    report.opposite_duplicates = opposite;
    report.components = parts0;
    let clean = counts.boundary == 0
        && counts.nonmanifold == 0
        && counts.misoriented == 0
        && degenerate == 0
        && dups == 0;
    if clean && (parts0 == 1 || !opts.remove_internal) {
        let mut out = mesh.clone();
        // A closed surface facing inward all over (its sign would still come out right, by
        // the winding number's absolute value): turned outward.
        if parts0 == 1 && opts.fill_holes && mesh.signed_volume() < 0.0 {
            for f in &mut out.faces {
                f.swap(1, 2);
            }
            report.repaired = true;
            report.flipped_parts = 1;
        }
        report.output_vertices = out.vertices.len();
        report.output_faces = out.faces.len();
        return Ok(Repaired {
            mesh: out,
            solid: None,
            report,
            fast_sign: false,
        });
    }
    if clean {
        // Several closed parts: unchanged unless two cross or one sits inside another the
        // wrong way (a nested shell facing out).
        let welded = TriMesh {
            vertices: mesh.vertices.clone(),
            faces: faces0.clone(),
        };
        let pairs: Vec<(usize, usize)> = intersecting_face_pairs(&welded)
            .into_iter()
            .filter(|&(i, j)| comp0[i] != comp0[j])
            .collect();
        report.self_intersecting_pairs = Some(pairs.len());
        let sdf = MeshSdf::new(&welded)?;
        let test = parts_to_test(
            &sdf,
            &welded,
            &comp0,
            parts0,
            &pairs,
            &vec![false; parts0],
            eps,
        );
        if !test.iter().any(|&t| t) {
            report.output_vertices = mesh.vertices.len();
            report.output_faces = mesh.faces.len();
            return Ok(Repaired {
                mesh: mesh.clone(),
                solid: None,
                report,
                fast_sign: false,
            });
        }
    }
    report.repaired = true;
    // 1-2: weld within the tolerance; drop degenerate and repeated faces.
    let (map, merged) = weld::weld_map(&mesh.vertices, opts.weld * diag);
    report.welded_vertices = merged;
    let (mut faces, degenerate, dups, opposite) = distinct_faces(&mesh.faces, &map);
    // The counts after the weld include the cracks' faces that it made degenerate or repeated.
    report.degenerate_faces = report.degenerate_faces.max(degenerate);
    report.duplicate_faces = report.duplicate_faces.max(dups);
    report.opposite_duplicates = report.opposite_duplicates.max(opposite);
    let mut vertices = mesh.vertices.clone();
    if faces.is_empty() {
        return Err(DataError::Invalid(
            "the mesh has no face left once degenerate and repeated faces are dropped: it has \
             no surface"
                .into(),
        ));
    }
    // Faces that do not meet their neighbours even after the weld (a soup whose patches have
    // gaps, T-junctions on most faces): no closed surface can be proved from them, and
    // closing every loop would only make slivers. The fast winding number of the faces as
    // read signs the grid; the distances are to those faces.
    if opts.fill_holes && opts.remove_internal {
        let loose = loose_share(&faces);
        if loose > 0.5 {
            let why = format!(
                "{:.0}% of the faces are in parts of one or two faces after welding within \
                 {:e} of the diagonal: patches whose borders do not meet",
                100.0 * loose,
                opts.weld
            );
            // Where the winding number sees no solid either, the topological path goes on
            // (and says what it finds).
            if let Ok(r) = winding_fallback(mesh, &faces0, report.clone(), why) {
                return Ok(r);
            }
        }
    }
    // 3: orient each part consistently.
    let uses = edge_uses(&faces);
    let (comp, parts) = manifold_components(&faces, &uses);
    report.flipped_faces = orient::orient_parts(&vertices, &mut faces, &uses, &comp, parts);
    if !opts.fill_holes && !opts.remove_internal {
        let (mesh, report) = finish(vertices, faces, report);
        return Ok(Repaired {
            mesh,
            solid: None,
            report,
            fast_sign: false,
        });
    }
    // 4: close the holes (the edge uses again: the orientation changed their directions).
    if opts.fill_holes {
        let uses = edge_uses(&faces);
        let h = holes::fill_holes(&mut vertices, &mut faces, &uses, &comp, opts.max_hole_edges);
        report.holes_filled = h.filled;
        report.hole_faces_added = h.faces_added;
        report.boundary_left = h.left_open;
    }
    // 5: outermost closed parts outward. A part with boundary edges left (a fin, a loop that
    // did not close) bounds no volume of its own and is not turned.
    let uses = edge_uses(&faces);
    let (comp, parts) = manifold_components(&faces, &uses);
    let mut boundary = vec![0usize; parts];
    let mut nonmanifold_parts = vec![false; parts];
    for g in edges::by_edge(&uses) {
        for u in g {
            let c = comp[u.face as usize] as usize;
            match g.len() {
                1 => boundary[c] += 1,
                2 => {}
                _ => nonmanifold_parts[c] = true,
            }
        }
    }
    let mut part_faces = vec![0usize; parts];
    for &c in &comp {
        part_faces[c as usize] += 1;
    }
    // Open parts: those with boundary edges left. A part with at most one boundary edge per
    // four faces (a surface with a hole the filling could not close) still bounds a solid
    // nearly everywhere and counts in it; a more open one (a fin, a loose sheet) bounds none:
    // its own half-turns of winding number next to it would decide its sides.
    let loose: Vec<bool> = (0..parts)
        .map(|p| boundary[p] > 0 && 4 * boundary[p] > part_faces[p])
        .collect();
    let open_parts: Vec<bool> = boundary.iter().map(|&b| b > 0).collect();
    let volumes = orient::part_volumes(&vertices, &faces, &comp, parts);
    let mut m = TriMesh { vertices, faces };
    let closed_only = |m: &TriMesh| -> Result<Option<MeshSdf>> {
        let faces: Vec<[u32; 3]> = m
            .faces
            .iter()
            .zip(&comp)
            .filter(|&(_, &c)| !loose[c as usize])
            .map(|(f, _)| *f)
            .collect();
        if faces.is_empty() {
            return Ok(None);
        }
        Ok(Some(MeshSdf::new(&TriMesh {
            vertices: m.vertices.clone(),
            faces,
        })?))
    };
    // The winding number of the closed parts: the solid. Open parts (fins, leftovers) would
    // add their half-turns next to themselves.
    let mut sdf = closed_only(&m)?;
    if let Some(solid) = &sdf {
        let largest = largest_face_per_part(&m.vertices, &m.faces, &comp, parts);
        let mut turn = vec![false; parts];
        for p in 0..parts {
            let f = largest[p];
            if volumes[p] >= 0.0 || f == u32::MAX || loose[p] {
                continue;
            }
            // A point on the part: the winding number of the other parts there says whether
            // the part is inside one of them.
            let [a, b, c] = m.faces[f as usize].map(|i| m.vertices[i as usize]);
            let g = [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0);
            let own = part_winding(&m.vertices, &m.faces, &comp, p as u32, g);
            let others = solid.winding_number(g) - own;
            if others.abs() < 0.5 {
                turn[p] = true;
            }
        }
        if turn.iter().any(|&t| t) {
            for (f, t) in m.faces.iter_mut().enumerate() {
                if turn[comp[f] as usize] {
                    t.swap(1, 2);
                }
            }
            report.flipped_parts = turn.iter().filter(|&&t| t).count();
            sdf = closed_only(&m)?;
        }
    }
    // 6: faces that separate nothing, and inverted faces.
    let mut solid_faces: Option<Vec<[u32; 3]>> = None;
    let pairs = intersecting_face_pairs(&m);
    report.self_intersecting_pairs = Some(pairs.len());
    if let (true, Some(solid)) = (opts.remove_internal, &sdf) {
        let flagged: Vec<bool> = (0..parts)
            .map(|p| open_parts[p] || nonmanifold_parts[p])
            .collect();
        let test_parts = parts_to_test(solid, &m, &comp, parts, &pairs, &flagged, eps);
        let test: Vec<bool> = comp.iter().map(|&c| test_parts[c as usize]).collect();
        let sides = classify_by_regions(solid, &m, &uses, &pairs, &test, eps);
        let mut kept = Vec::with_capacity(m.faces.len());
        for (t, s) in m.faces.iter().zip(&sides) {
            match s {
                Side::Boundary => kept.push(*t),
                Side::Inverted => {
                    kept.push([t[0], t[2], t[1]]);
                    report.inverted_faces_flipped += 1;
                }
                Side::Internal => report.internal_faces_removed += 1,
            }
        }
        if report.internal_faces_removed > 0 {
            let faces: Vec<[u32; 3]> = m
                .faces
                .iter()
                .zip(&comp)
                .filter(|&(_, &c)| !loose[c as usize])
                .map(|(f, _)| *f)
                .collect();
            solid_faces = Some(faces);
        }
        if kept.is_empty() {
            // Nothing the topology proves: the fast winding number of the faces as read may
            // still see a solid (patches whose borders do not meet).
            if let Ok(r) = winding_fallback(
                mesh,
                &faces0,
                report.clone(),
                "no face of the repaired mesh separates an inside from an outside".into(),
            ) {
                return Ok(r);
            }
            return Err(DataError::Invalid(
                "no face of the mesh separates an inside from an outside: it encloses no volume \
                 (a surface has no inside: reconstruct it as an open surface, --open in the \
                 programs, open=True in Python)"
                    .into(),
            ));
        }
        m.faces = kept;
    }
    // Loops the hole filling could not close, more than one per four faces left (edges split
    // on one side only, T-junctions, leave slits no fan closes, and removing what separates
    // nothing then eats the surface): the faces as read, signed by their winding number.
    if opts.fill_holes && opts.remove_internal && 4 * report.boundary_left > m.faces.len() {
        let why = format!(
            "the topological repair left {} boundary edges open for {} faces: T-junctions or \
             gaps",
            report.boundary_left,
            m.faces.len()
        );
        if let Ok(r) = winding_fallback(mesh, &faces0, report.clone(), why) {
            return Ok(r);
        }
    }
    let solid = solid_faces.map(|faces| {
        let mut s = TriMesh {
            vertices: m.vertices.clone(),
            faces,
        };
        s.remove_unreferenced_vertices();
        s
    });
    let (mesh, report) = finish(m.vertices, m.faces, report);
    Ok(Repaired {
        mesh,
        solid,
        report,
        fast_sign: false,
    })
}

/// The share of `faces` in parts of at most two faces (parts: faces joined across edges of
/// exactly two faces). A soup whose corners do not meet is all such parts; a mesh with holes,
/// however coarse, is not.
fn loose_share(faces: &[[u32; 3]]) -> f64 {
    let uses = edge_uses(faces);
    let (comp, parts) = manifold_components(faces, &uses);
    let mut count = vec![0usize; parts];
    for &c in &comp {
        count[c as usize] += 1;
    }
    let loose: usize = count.iter().filter(|&&n| n <= 2).sum();
    loose as f64 / faces.len().max(1) as f64
}

/// The input's faces as read (vertices merged at equal positions, degenerate and repeated
/// faces dropped: `faces0`), signed by their fast winding number, with `why` in the report.
/// An error when the winding number sees no solid (no point of a 16^3 lattice over the box
/// with `|w| > 3/4`).
fn winding_fallback(
    mesh: &TriMesh,
    faces0: &[[u32; 3]],
    mut report: DefectReport,
    why: String,
) -> Result<Repaired> {
    let no_volume = || {
        DataError::Invalid(
            "no face of the mesh separates an inside from an outside: it encloses no volume (a \
             surface has no inside: reconstruct it as an open surface, --open in the \
             programs, open=True in Python)"
                .into(),
        )
    };
    if faces0.is_empty() {
        return Err(no_volume());
    }
    // The faces as read, all of them: a face's own side test is unreliable within the gaps
    // (a neighbour moved across it adds half a turn), so nothing is removed or turned here.
    let kept: Vec<[u32; 3]> = faces0.to_vec();
    let fast = crate::fast_winding::FastWinding::of_mesh(&mesh.vertices, &kept);
    // The box of the faces' corners (stray vertices of the file left out).
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for &v in kept.iter().flatten() {
        let p = mesh.vertices[v as usize];
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let n = 16;
    let lattice: Vec<[f64; 3]> = (0..n * n * n)
        .map(|i| {
            let ijk = [i / (n * n), (i / n) % n, i % n];
            [0, 1, 2].map(|k| lo[k] + (hi[k] - lo[k]) * (ijk[k] as f64 + 0.5) / n as f64)
        })
        .collect();
    if !fast
        .winding_numbers(&lattice)
        .iter()
        .any(|w| w.abs() > 0.75)
    {
        return Err(no_volume());
    }
    report.repaired = true;
    report.winding_sign = Some(why);
    // Nothing of the topological steps is in the output: the faces as read.
    report.welded_vertices = 0;
    report.flipped_faces = 0;
    report.flipped_parts = 0;
    report.holes_filled = 0;
    report.hole_faces_added = 0;
    report.boundary_left = 0;
    report.internal_faces_removed = 0;
    report.inverted_faces_flipped = 0;
    let (out, report) = finish(mesh.vertices.clone(), kept, report);
    Ok(Repaired {
        mesh: out,
        solid: None,
        report,
        fast_sign: true,
    })
}

/// For each vertex, the first vertex at exactly its position (`-0.0` equals `0.0`), and the
/// number of vertices merged so.
pub(crate) fn exact_weld_map(vertices: &[[f64; 3]]) -> (Vec<u32>, usize) {
    weld::weld_map(vertices, 0.0)
}

/// The parts of `faces` (joined across edges of exactly two faces): the part of each face,
/// and the count.
pub(crate) fn parts_of(faces: &[[u32; 3]]) -> (Vec<u32>, usize) {
    manifold_components(faces, &edge_uses(faces))
}

/// The repaired mesh without unused vertices, and the report's output counts.
fn finish(
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    mut report: DefectReport,
) -> (TriMesh, DefectReport) {
    let mut m = TriMesh { vertices, faces };
    m.remove_unreferenced_vertices();
    report.output_vertices = m.vertices.len();
    report.output_faces = m.faces.len();
    (m, report)
}
