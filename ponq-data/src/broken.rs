//! Broken copies of a mesh, one class of defect at a time, seeded: the inputs the repair
//! ([`crate::repair`]) is tested and measured on (`ponq-prep break`, `ponq-eval broken`).
//!
//! The classes are those real collections are full of (Zhou and Jacobson 2016, Thingi10K):
//! triangle soups, cracks, flipped faces and parts, duplicated faces, small holes, internal
//! shells, overlapping copies and fins. Each copy describes the same solid as the input (but
//! [`Defect::Overlap`]: the union of the two copies, see [`union_surface`]), so a reconstruction
//! of the copy is compared with the clean input.
//!
//! ```
//! use ponq_data::broken::{Defect, break_mesh};
//! let v = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
//! let f = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]];
//! let tet = ponq_mesh::TriMesh::new(v, f).unwrap();
//! let soup = break_mesh(&tet, Defect::Soup, 1, 0.1).unwrap();
//! assert_eq!(soup.vertices.len(), 12);
//! ```

use std::fmt;
use std::str::FromStr;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{DataError, Result};
use crate::sdf::MeshSdf;
use ponq_mesh::TriMesh;
use ponq_mesh::vec3::{cross, dot, sub};

/// A class of defect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Defect {
    /// Every face with vertices of its own, at exactly the same positions.
    Soup,
    /// A soup whose vertices are moved apart by up to 1e-5 of the bounding-box diagonal (not
    /// welded by exact comparison).
    Cracks,
    /// 10% of the faces flipped.
    Flip10,
    /// 50% of the faces flipped.
    Flip50,
    /// The largest part flipped whole (the whole mesh, for one part).
    FlipPart,
    /// 5% of the faces duplicated with the opposite orientation.
    Duplicates,
    /// Holes up to one grid cell wide: faces no longer than a cell removed, one per hole.
    Holes,
    /// A closed sphere facing outward, inside the solid where it is deepest.
    NestedShell,
    /// A second copy, moved by a quarter of the bounding box along its longest side.
    Overlap,
    /// Fins: triangles half a cell tall standing on edges, outside the solid (non-manifold
    /// edges).
    Fins,
    /// A soup whose corners are moved apart by up to 1e-3 of the bounding-box diagonal (10x
    /// the repair's weld: patches whose borders do not meet).
    Gaps3,
    /// The same, by up to 1e-2 of the diagonal.
    Gaps2,
    /// T-junctions: a third of the edges split at their middle on one side only (the face on
    /// the other side keeps the long edge), as B-rep tessellators write them between faces.
    TJunctions,
    /// Every class at once: fins, 10% of the faces flipped, 5% duplicated the other way,
    /// T-junctions, then a soup with gaps of up to 1e-3 of the diagonal.
    Mixed,
}

impl Defect {
    /// Every class, in the order of the reports.
    pub const ALL: [Defect; 14] = [
        Defect::Soup,
        Defect::Cracks,
        Defect::Flip10,
        Defect::Flip50,
        Defect::FlipPart,
        Defect::Duplicates,
        Defect::Holes,
        Defect::NestedShell,
        Defect::Overlap,
        Defect::Fins,
        Defect::Gaps3,
        Defect::Gaps2,
        Defect::TJunctions,
        Defect::Mixed,
    ];

    /// The name the programs take and print.
    pub fn name(self) -> &'static str {
        match self {
            Defect::Soup => "soup",
            Defect::Cracks => "cracks",
            Defect::Flip10 => "flip10",
            Defect::Flip50 => "flip50",
            Defect::FlipPart => "flip-part",
            Defect::Duplicates => "duplicates",
            Defect::Holes => "holes",
            Defect::NestedShell => "nested-shell",
            Defect::Overlap => "overlap",
            Defect::Fins => "fins",
            Defect::Gaps3 => "gaps1e-3",
            Defect::Gaps2 => "gaps1e-2",
            Defect::TJunctions => "t-junctions",
            Defect::Mixed => "mixed",
        }
    }
}

impl fmt::Display for Defect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Defect {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Defect::ALL
            .into_iter()
            .find(|d| d.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown defect class '{s}' (one of: {})",
                    Defect::ALL.map(Defect::name).join(", ")
                )
            })
    }
}

fn diagonal(mesh: &TriMesh) -> Result<f64> {
    let (lo, hi) = mesh
        .bounding_box()
        .ok_or_else(|| DataError::Invalid("the mesh has no vertex".into()))?;
    Ok((0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt())
}

/// The mesh as a soup whose every vertex is moved uniformly in the ball of radius `r`.
fn jittered_soup(mesh: &TriMesh, r: f64, rng: &mut ChaCha8Rng) -> TriMesh {
    let mut m = soup(mesh);
    for p in &mut m.vertices {
        let d = loop {
            let d = [0; 3].map(|_| rng.random_range(-1.0..1.0));
            if dot(d, d) <= 1.0 {
                break d;
            }
        };
        for k in 0..3 {
            p[k] += r * d[k];
        }
    }
    m
}

/// T-junctions: about a third of the edges of two faces get a vertex at their middle, and one
/// of their two faces (chosen at random) is split there in two; the other keeps the long
/// edge. A face is split at most once.
fn t_junctions(mesh: &TriMesh, rng: &mut ChaCha8Rng) -> TriMesh {
    use std::collections::HashMap;
    let mut m = mesh.clone();
    let mut faces_of: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (f, t) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            faces_of.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let mut edges: Vec<((u32, u32), Vec<usize>)> = faces_of
        .into_iter()
        .filter(|(_, fs)| fs.len() == 2)
        .collect();
    edges.sort_unstable_by_key(|(e, _)| *e);
    let mut split = vec![false; mesh.faces.len()];
    let mut out: Vec<[u32; 3]> = Vec::with_capacity(mesh.faces.len() * 2);
    for ((a, b), fs) in edges {
        if !rng.random_bool(1.0 / 3.0) {
            continue;
        }
        let f = fs[usize::from(rng.random_bool(0.5))];
        if split[f] {
            continue;
        }
        split[f] = true;
        let mid = m.vertices.len() as u32;
        let (pa, pb) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
        m.vertices.push([0, 1, 2].map(|k| 0.5 * (pa[k] + pb[k])));
        // The face with its edge (a, b) in its own order: (u, v, w) with u -> v the edge.
        let t = mesh.faces[f];
        let k = (0..3)
            .find(|&k| {
                let (u, v) = (t[k], t[(k + 1) % 3]);
                (u, v) == (a, b) || (u, v) == (b, a)
            })
            .unwrap_or(0);
        let (u, v, w) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
        out.push([u, mid, w]);
        out.push([mid, v, w]);
    }
    for (f, t) in mesh.faces.iter().enumerate() {
        if !split[f] {
            out.push(*t);
        }
    }
    m.faces = out;
    m
}

/// The mesh as a soup: three vertices of its own per face.
fn soup(mesh: &TriMesh) -> TriMesh {
    let mut vertices = Vec::with_capacity(3 * mesh.faces.len());
    let mut faces = Vec::with_capacity(mesh.faces.len());
    for f in &mesh.faces {
        let b = vertices.len() as u32;
        vertices.extend(f.map(|v| mesh.vertices[v as usize]));
        faces.push([b, b + 1, b + 2]);
    }
    TriMesh { vertices, faces }
}

/// A unit-radius icosphere (an icosahedron subdivided twice: 162 vertices, 320 faces),
/// counter-clockwise from outside.
fn icosphere() -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let unit = |p: [f64; 3]| {
        let l = dot(p, p).sqrt();
        p.map(|x| x / l)
    };
    for p in &mut v {
        *p = unit(*p);
    }
    for _ in 0..2 {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::with_capacity(4 * f.len());
        for t in &f {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                m[k] = *mid.entry((a, b)).or_insert_with(|| {
                    let (p, q) = (v[a as usize], v[b as usize]);
                    v.push(unit([0, 1, 2].map(|i| 0.5 * (p[i] + q[i]))));
                    (v.len() - 1) as u32
                });
            }
            next.push([t[0], m[0], m[2]]);
            next.push([t[1], m[1], m[0]]);
            next.push([t[2], m[2], m[1]]);
            next.push(m);
        }
        f = next;
    }
    TriMesh {
        vertices: v,
        faces: f,
    }
}

/// A broken copy of `mesh` (a closed, oriented solid) with defects of class `defect`, from
/// `seed`; `cell` is a grid cell in the mesh's units (the diagonal over the cells per side the
/// copy will be sampled at: the size of the holes and fins).
///
/// # Errors
/// A mesh without faces or vertices; for [`Defect::NestedShell`], a mesh with no inside.
pub fn break_mesh(mesh: &TriMesh, defect: Defect, seed: u64, cell: f64) -> Result<TriMesh> {
    if mesh.faces.is_empty() {
        return Err(DataError::Invalid("the mesh has no face".into()));
    }
    let diag = diagonal(mesh)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0B20_4E11);
    let mut m = mesh.clone();
    match defect {
        Defect::Soup => m = soup(mesh),
        Defect::Cracks => m = jittered_soup(mesh, 1e-5 * diag, &mut rng),
        Defect::Gaps3 => m = jittered_soup(mesh, 1e-3 * diag, &mut rng),
        Defect::Gaps2 => m = jittered_soup(mesh, 1e-2 * diag, &mut rng),
        Defect::TJunctions => m = t_junctions(mesh, &mut rng),
        Defect::Mixed => {
            // Fins first: they stand along their face's normal, outside while it faces out.
            m = break_mesh(&m, Defect::Fins, seed ^ 2, cell)?;
            m = break_mesh(&m, Defect::Flip10, seed ^ 3, cell)?;
            m = break_mesh(&m, Defect::Duplicates, seed ^ 1, cell)?;
            m = t_junctions(&m, &mut rng);
            m = jittered_soup(&m, 1e-3 * diag, &mut rng);
        }
        Defect::Flip10 | Defect::Flip50 => {
            let share = if defect == Defect::Flip10 { 0.1 } else { 0.5 };
            for f in &mut m.faces {
                if rng.random_bool(share) {
                    f.swap(1, 2);
                }
            }
        }
        Defect::FlipPart => {
            let (map, _) = crate::repair::exact_weld_map(&mesh.vertices);
            let faces: Vec<[u32; 3]> = mesh
                .faces
                .iter()
                .map(|f| f.map(|v| map[v as usize]))
                .collect();
            let (comp, parts) = crate::repair::parts_of(&faces);
            let mut area = vec![0.0; parts];
            for (f, t) in mesh.faces.iter().enumerate() {
                let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
                let n = cross(sub(b, a), sub(c, a));
                area[comp[f] as usize] += dot(n, n).sqrt();
            }
            let big = (0..parts)
                .max_by(|&a, &b| area[a].total_cmp(&area[b]))
                .unwrap_or(0) as u32;
            for (f, t) in m.faces.iter_mut().enumerate() {
                if comp[f] == big {
                    t.swap(1, 2);
                }
            }
        }
        Defect::Duplicates => {
            let n = mesh.faces.len();
            for f in 0..n {
                if rng.random_bool(0.05) {
                    let t = mesh.faces[f];
                    m.faces.push([t[0], t[2], t[1]]);
                }
            }
        }
        Defect::Holes => {
            let longest = |t: &[u32; 3]| {
                (0..3)
                    .map(|k| {
                        let d = sub(
                            mesh.vertices[t[k] as usize],
                            mesh.vertices[t[(k + 1) % 3] as usize],
                        );
                        dot(d, d).sqrt()
                    })
                    .fold(0.0, f64::max)
            };
            let mut small: Vec<usize> = (0..mesh.faces.len())
                .filter(|&f| longest(&mesh.faces[f]) <= cell)
                .collect();
            if small.is_empty() {
                // No face fits in a cell: the smallest one.
                let f = (0..mesh.faces.len())
                    .min_by(|&a, &b| longest(&mesh.faces[a]).total_cmp(&longest(&mesh.faces[b])))
                    .unwrap_or(0);
                small.push(f);
            }
            // Shuffle, then take faces that share no vertex with one taken: one face per hole.
            for i in (1..small.len()).rev() {
                small.swap(i, rng.random_range(0..=i));
            }
            let want = (mesh.faces.len() / 200).clamp(1, 20);
            let mut used = std::collections::HashSet::new();
            let mut drop = vec![false; mesh.faces.len()];
            let mut taken = 0;
            for f in small {
                if taken == want {
                    break;
                }
                let t = mesh.faces[f];
                if t.iter().any(|v| used.contains(v)) {
                    continue;
                }
                used.extend(t);
                drop[f] = true;
                taken += 1;
            }
            m.faces = mesh
                .faces
                .iter()
                .zip(&drop)
                .filter(|&(_, &d)| !d)
                .map(|(t, _)| *t)
                .collect();
        }
        Defect::NestedShell => {
            let sdf = MeshSdf::new(mesh)?;
            let (lo, hi) = mesh.bounding_box().unwrap_or(([0.0; 3], [0.0; 3]));
            let n = 24;
            let pts: Vec<[f64; 3]> = (0..n * n * n)
                .map(|i| {
                    let ijk = [i / (n * n), (i / n) % n, i % n];
                    [0, 1, 2].map(|k| lo[k] + (hi[k] - lo[k]) * (ijk[k] as f64 + 0.5) / n as f64)
                })
                .collect();
            let d = sdf.signed_distances(&pts);
            let (best, depth) = d
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .map(|(i, &v)| (i, -v))
                .unwrap_or((0, 0.0));
            if !(depth > 0.0) {
                return Err(DataError::Invalid(
                    "the mesh has no inside for a nested shell".into(),
                ));
            }
            let c = pts[best];
            let s = icosphere();
            let base = m.vertices.len() as u32;
            m.vertices.extend(
                s.vertices
                    .iter()
                    .map(|p| [0, 1, 2].map(|k| c[k] + 0.5 * depth * p[k])),
            );
            m.faces.extend(s.faces.iter().map(|f| f.map(|v| v + base)));
        }
        Defect::Overlap => {
            let shift = overlap_shift(mesh);
            let base = m.vertices.len() as u32;
            m.vertices.extend(
                mesh.vertices
                    .iter()
                    .map(|p| [0, 1, 2].map(|k| p[k] + shift[k])),
            );
            m.faces
                .extend(mesh.faces.iter().map(|f| f.map(|v| v + base)));
        }
        Defect::Fins => {
            let want = (mesh.faces.len() / 100).clamp(1, 50);
            for _ in 0..want {
                let f = rng.random_range(0..mesh.faces.len());
                let t = mesh.faces[f];
                let k = rng.random_range(0..3usize);
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let [p, q, r] = t.map(|i| mesh.vertices[i as usize]);
                let n = cross(sub(q, p), sub(r, p));
                let l = dot(n, n).sqrt();
                if !(l > 0.0) {
                    continue;
                }
                let (pa, pb) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
                let tip = [0, 1, 2].map(|i| 0.5 * (pa[i] + pb[i]) + 0.5 * cell * n[i] / l);
                m.vertices.push(tip);
                m.faces.push([a, b, (m.vertices.len() - 1) as u32]);
            }
        }
    }
    Ok(m)
}

/// The translation of the second copy of [`Defect::Overlap`]: a quarter of the bounding box
/// along its longest side.
pub fn overlap_shift(mesh: &TriMesh) -> [f64; 3] {
    let (lo, hi) = mesh.bounding_box().unwrap_or(([0.0; 3], [0.0; 3]));
    let ext = [0, 1, 2].map(|k| hi[k] - lo[k]);
    let axis = (0..3)
        .max_by(|&a, &b| ext[a].total_cmp(&ext[b]))
        .unwrap_or(0);
    let mut s = [0.0; 3];
    s[axis] = 0.25 * ext[axis];
    s
}

/// The surface of the union of `mesh` and its [`Defect::Overlap`] copy, for comparisons: each
/// face of either copy, split into pieces no longer than `piece` (pieces need not match their
/// neighbours': the result is sampled, not meshed), kept where the piece's centroid is outside
/// the other copy.
///
/// # Errors
/// As [`MeshSdf::new`].
pub fn union_surface(mesh: &TriMesh, piece: f64) -> Result<TriMesh> {
    let shift = overlap_shift(mesh);
    let moved = TriMesh {
        vertices: mesh
            .vertices
            .iter()
            .map(|p| [0, 1, 2].map(|k| p[k] + shift[k]))
            .collect(),
        faces: mesh.faces.clone(),
    };
    let (a, b) = (MeshSdf::new(mesh)?, MeshSdf::new(&moved)?);
    let mut out = TriMesh::default();
    for (src, other) in [(mesh, &b), (&moved, &a)] {
        for f in &src.faces {
            let mut stack = vec![f.map(|v| src.vertices[v as usize])];
            while let Some(t) = stack.pop() {
                let longest = (0..3)
                    .map(|k| {
                        let d = sub(t[k], t[(k + 1) % 3]);
                        dot(d, d)
                    })
                    .enumerate()
                    .max_by(|x, y| x.1.total_cmp(&y.1))
                    .unwrap_or((0, 0.0));
                if longest.1.sqrt() > piece {
                    // Split the longest edge at its midpoint.
                    let k = longest.0;
                    let (p, q, r) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                    let m = [0, 1, 2].map(|i| 0.5 * (p[i] + q[i]));
                    stack.push([p, m, r]);
                    stack.push([m, q, r]);
                    continue;
                }
                let g = [0, 1, 2].map(|i| (t[0][i] + t[1][i] + t[2][i]) / 3.0);
                if other.winding_number(g).abs() <= 0.5 {
                    let base = out.vertices.len() as u32;
                    out.vertices.extend(t);
                    out.faces.push([base, base + 1, base + 2]);
                }
            }
        }
    }
    Ok(out)
}
