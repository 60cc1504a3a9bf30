//! The defect report: what [`super::repair`] found in a mesh and what it did.

use std::fmt;

/// What was wrong with a mesh and what was done about it. Counts of the input are after
/// merging vertices at exactly the same position (a triangle soup of a closed surface has no
/// boundary edge).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DefectReport {
    /// Vertices and faces of the input.
    pub input_vertices: usize,
    pub input_faces: usize,
    /// Edges of one face only (holes, cracks, an open surface).
    pub boundary_edges: usize,
    /// Edges of three faces or more (fins, internal faces, touching parts).
    pub nonmanifold_edges: usize,
    /// Edges of two faces that run them the same way (flipped faces).
    pub misoriented_edges: usize,
    /// Faces with a repeated vertex.
    pub degenerate_faces: usize,
    /// Faces on the same three vertices as an earlier face, running them the same way or
    /// the opposite way.
    pub duplicate_faces: usize,
    pub opposite_duplicates: usize,
    /// Parts of faces joined across edges of exactly two faces.
    pub components: usize,
    /// Pairs of faces that cross each other (exact test), when it was run: on every mesh
    /// that needed a repair, and on closed meshes of several parts.
    pub self_intersecting_pairs: Option<usize>,
    /// Anything changed; `false`: the mesh is used as it is.
    pub repaired: bool,
    /// Vertices merged into another (at the same position, or within the weld tolerance).
    pub welded_vertices: usize,
    /// Faces flipped to agree with their neighbours.
    pub flipped_faces: usize,
    /// Whole outermost parts turned outward.
    pub flipped_parts: usize,
    /// Holes closed and the triangles that closed them.
    pub holes_filled: usize,
    pub hole_faces_added: usize,
    /// Boundary edges left open (loops that do not close, or longer than the limit).
    pub boundary_left: usize,
    /// Faces removed because the solid is on the same side of both their sides (internal
    /// faces, nested shells, fins, the part of an overlap inside the other copy).
    pub internal_faces_removed: usize,
    /// Faces flipped because the solid was in front of them.
    pub inverted_faces_flipped: usize,
    /// Vertices and faces handed on.
    pub output_vertices: usize,
    pub output_faces: usize,
    /// Share of the grid's nodes whose winding number was within 1/4 of the inside threshold
    /// 1/2 (a sign that is a guess), when the grid had to be signed node by node.
    pub ambiguous_node_share: Option<f64>,
    /// Why the sign is the fast winding number of the faces as read
    /// ([`crate::fast_winding`]) rather than the repaired surface's (`None`: the topological
    /// repair proved a closed surface, or the mesh was clean).
    pub winding_sign: Option<String>,
}

impl DefectReport {
    /// Whether the input had any defect this report counts.
    pub fn found_defects(&self) -> bool {
        self.boundary_edges > 0
            || self.nonmanifold_edges > 0
            || self.misoriented_edges > 0
            || self.degenerate_faces > 0
            || self.duplicate_faces > 0
            || self.self_intersecting_pairs.is_some_and(|n| n > 0)
            || self.repaired
    }

    /// The report as one JSON object (keys as the field names; `null` for a check not run;
    /// `sign`: `"topological"` or `"winding number"`, with `sign_reason`).
    pub fn to_json(&self) -> String {
        serde_json::json!({
            "input_vertices": self.input_vertices,
            "input_faces": self.input_faces,
            "boundary_edges": self.boundary_edges,
            "nonmanifold_edges": self.nonmanifold_edges,
            "misoriented_edges": self.misoriented_edges,
            "degenerate_faces": self.degenerate_faces,
            "duplicate_faces": self.duplicate_faces,
            "opposite_duplicates": self.opposite_duplicates,
            "components": self.components,
            "self_intersecting_pairs": self.self_intersecting_pairs,
            "repaired": self.repaired,
            "welded_vertices": self.welded_vertices,
            "flipped_faces": self.flipped_faces,
            "flipped_parts": self.flipped_parts,
            "holes_filled": self.holes_filled,
            "hole_faces_added": self.hole_faces_added,
            "boundary_left": self.boundary_left,
            "internal_faces_removed": self.internal_faces_removed,
            "inverted_faces_flipped": self.inverted_faces_flipped,
            "output_vertices": self.output_vertices,
            "output_faces": self.output_faces,
            "ambiguous_node_share": self.ambiguous_node_share.filter(|v| v.is_finite()),
            "sign": if self.winding_sign.is_some() { "winding number" } else { "topological" },
            "sign_reason": self.winding_sign,
        })
        .to_string()
    }
}

impl fmt::Display for DefectReport {
    /// Two lines: what was found, what was done.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut found = Vec::new();
        let mut say = |n: usize, what: &str| {
            if n > 0 {
                found.push(format!("{n} {what}"));
            }
        };
        say(self.boundary_edges, "boundary edges");
        say(self.nonmanifold_edges, "non-manifold edges");
        say(self.misoriented_edges, "edges between flipped faces");
        say(self.degenerate_faces, "degenerate faces");
        say(self.duplicate_faces, "duplicate faces");
        if let Some(n) = self.self_intersecting_pairs {
            say(n, "self-intersecting face pairs");
        }
        write!(
            f,
            "mesh: {} vertices, {} faces, {} part{}; ",
            self.input_vertices,
            self.input_faces,
            self.components,
            if self.components == 1 { "" } else { "s" }
        )?;
        if found.is_empty() {
            write!(f, "no defect found")?;
        } else {
            write!(f, "found {}", found.join(", "))?;
            if self.opposite_duplicates > 0 {
                write!(f, " ({} of opposite orientation)", self.opposite_duplicates)?;
            }
        }
        if let Some(s) = self.ambiguous_node_share {
            write!(
                f,
                "; {:.2}% of the grid's nodes have an ambiguous winding number",
                100.0 * s
            )?;
        }
        if let Some(why) = &self.winding_sign {
            write!(
                f,
                "\nsign: the fast winding number of the faces as read ({why}); distances to them"
            )?;
        }
        if !self.repaired {
            return write!(f, "\nrepair: nothing done, the mesh is used as it is");
        }
        let mut done = Vec::new();
        let mut did = |n: usize, what: &str| {
            if n > 0 {
                done.push(format!("{what} {n}"));
            }
        };
        did(self.welded_vertices, "welded vertices:");
        did(
            self.degenerate_faces + self.duplicate_faces,
            "dropped degenerate / duplicate faces:",
        );
        did(self.flipped_faces, "flipped faces:");
        did(self.flipped_parts, "turned parts outward:");
        did(self.holes_filled, "filled holes:");
        did(self.hole_faces_added, "patch faces:");
        did(self.internal_faces_removed, "removed internal faces:");
        did(self.inverted_faces_flipped, "flipped inverted faces:");
        did(self.boundary_left, "boundary edges left open:");
        write!(
            f,
            "\nrepair: {}; {} vertices, {} faces",
            if done.is_empty() {
                "nothing changed".to_string()
            } else {
                done.join(", ")
            },
            self.output_vertices,
            self.output_faces
        )
    }
}
