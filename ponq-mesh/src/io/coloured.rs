//! Meshes with their colours ([`crate::colour::Colours`]): read from PLY (vertex or face
//! `red green blue`) and OBJ (`v x y z r g b`; materials of its MTL libraries, `Kd` and
//! `map_Kd` textures, PNG or JPEG, read with the `image` crate), written as PLY (`uchar red
//! green blue` per vertex) or OBJ (`v x y z r g b`).
//!
//! A file without colours reads as `None`, and a mesh written without colours is the plain
//! writer's file, byte for byte.

use std::path::Path;

use super::file::read_file;
use super::{MeshFormat, obj, off, ply, read_mesh, write_mesh};
use crate::colour::{Colours, Image, Material, Rgb, Textured};
use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// Reads a mesh and its colours (`None` when the file carries none; OFF and STL carry none
/// here). Colours never cost the geometry: what of them cannot be read (a missing MTL file
/// or texture, an image format other than PNG or JPEG) is left out; see
/// [`read_mesh_coloured_noted`] for notes that say what.
///
/// # Errors
/// As [`read_mesh`].
pub fn read_mesh_coloured(path: impl AsRef<Path>) -> Result<(TriMesh, Option<Colours>)> {
    read_mesh_coloured_noted(path).map(|(m, c, _)| (m, c))
}

/// [`read_mesh_coloured`], and one note for each colour source left out (a missing or
/// unreadable MTL file or texture: its material then takes its `Kd`), to tell the user.
///
/// # Errors
/// As [`read_mesh`].
pub fn read_mesh_coloured_noted(
    path: impl AsRef<Path>,
) -> Result<(TriMesh, Option<Colours>, Vec<String>)> {
    let path = path.as_ref();
    let mut notes = Vec::new();
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Ply) => {
            let bytes = read_file(path)?;
            let (m, c) = ply::parse_with_colours(&bytes).map_err(|m| Error::format(path, m))?;
            Ok((m, c, notes))
        }
        Some(MeshFormat::Obj) => {
            let bytes = read_file(path)?;
            let (mesh, x) = obj::parse_with_extras(&bytes).map_err(|m| Error::format(path, m))?;
            if let Some(c) = x.vertex_colours {
                return Ok((mesh, Some(Colours::Vertex(c)), notes));
            }
            let colours = obj_materials(path, &mesh, &x, &mut notes);
            Ok((mesh, colours, notes))
        }
        _ => Ok((read_mesh(path)?, None, notes)),
    }
}

/// The file a name in an OBJ or MTL statement refers to, relative to `dir`: the whole name
/// (which may hold spaces), else the name with its leading words dropped one by one (the
/// options before a `map_Kd` file: `-bm 1`, `-s 1 1 1`, ...); `\` read as `/`.
fn resolve(dir: &Path, name: &str) -> Option<std::path::PathBuf> {
    let name = name.trim().replace('\\', "/");
    let mut rest = name.as_str();
    loop {
        let p = dir.join(rest);
        if !rest.is_empty() && p.is_file() {
            return Some(p);
        }
        match rest.find(char::is_whitespace) {
            Some(i) => rest = rest[i..].trim_start(),
            None => return None,
        }
    }
}

/// The material colours of an OBJ: `None` without `usemtl` or a library that defines them.
/// Libraries and textures that cannot be read are left out, with a note in `notes`.
fn obj_materials(
    path: &Path,
    mesh: &TriMesh,
    x: &obj::ObjExtras,
    notes: &mut Vec<String>,
) -> Option<Colours> {
    if x.material_names.is_empty() || x.mtllibs.is_empty() {
        return None;
    }
    let dir = path.parent().unwrap_or(Path::new(""));
    // Each material with the folder of its library (textures are relative to it).
    let mut defined: Vec<(MtlEntry, std::path::PathBuf)> = Vec::new();
    for lib in &x.mtllibs {
        // `mtllib a.mtl b.mtl` names two files; `mtllib my model.mtl` one with a space.
        let files: Vec<std::path::PathBuf> = match resolve(dir, lib) {
            Some(p) if p.ends_with(lib.trim().replace('\\', "/")) => vec![p],
            _ => lib
                .split_whitespace()
                .filter_map(|n| {
                    let p = resolve(dir, n);
                    if p.is_none() {
                        notes.push(format!("the material library {n} was not found"));
                    }
                    p
                })
                .collect(),
        };
        for p in files {
            match std::fs::read(&p) {
                Ok(bytes) => {
                    let lib_dir = p.parent().unwrap_or(Path::new("")).to_path_buf();
                    defined.extend(
                        parse_mtl(&String::from_utf8_lossy(&bytes))
                            .into_iter()
                            .map(|m| (m, lib_dir.clone())),
                    );
                }
                Err(e) => notes.push(format!("cannot read {}: {e}", p.display())),
            }
        }
    }
    // One decoding per texture file, however many materials name it.
    let mut textures: Vec<(std::path::PathBuf, Option<std::sync::Arc<Image>>)> = Vec::new();
    let mut materials = Vec::with_capacity(x.material_names.len() + 1);
    let mut any = false;
    for name in &x.material_names {
        match defined.iter().rev().find(|(m, _)| m.name == *name) {
            Some((m, lib_dir)) => {
                any = true;
                let texture = m.map_kd.as_deref().and_then(|file| {
                    let Some(p) = resolve(lib_dir, file).or_else(|| resolve(dir, file)) else {
                        notes.push(format!(
                            "the texture {file} of material {name} was not found: its Kd is used"
                        ));
                        return None;
                    };
                    if let Some((_, t)) = textures.iter().find(|(q, _)| *q == p) {
                        return t.clone();
                    }
                    let t = match read_texture(&p) {
                        Ok(t) => Some(std::sync::Arc::new(t)),
                        Err(e) => {
                            notes.push(format!("{e}: the Kd of material {name} is used"));
                            None
                        }
                    };
                    textures.push((p, t.clone()));
                    t
                });
                materials.push(Material {
                    diffuse: m.kd,
                    texture,
                });
            }
            None => materials.push(Material {
                diffuse: [1.0; 3],
                texture: None,
            }),
        }
    }
    if !any {
        return None;
    }
    // Faces before any `usemtl`: white, as viewers draw them.
    let plain = materials.len() as u32;
    materials.push(Material {
        diffuse: [1.0; 3],
        texture: None,
    });
    let uv = x
        .face_texcoords
        .iter()
        .map(|t| {
            t.map(|i| {
                usize::try_from(i)
                    .ok()
                    .and_then(|i| x.texcoords.get(i))
                    .copied()
                    .unwrap_or([f32::NAN; 2])
            })
        })
        .collect();
    let material = x
        .face_material
        .iter()
        .map(|&m| u32::try_from(m).unwrap_or(plain))
        .collect();
    let t = Colours::Texture(Textured {
        uv,
        material,
        materials,
    });
    t.fits(mesh.vertices.len(), mesh.faces.len()).then_some(t)
}

/// One material of an MTL file.
struct MtlEntry {
    name: String,
    /// `Kd` (default white; non-finite values read as 0).
    kd: Rgb,
    /// `map_Kd`: the rest of its line (options, then the file; resolved by [`resolve`]).
    map_kd: Option<String>,
}

/// The materials of an MTL file.
fn parse_mtl(text: &str) -> Vec<MtlEntry> {
    let mut out: Vec<MtlEntry> = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        let mut toks = line.split_whitespace();
        match toks.next() {
            Some("newmtl") => out.push(MtlEntry {
                name: toks.collect::<Vec<_>>().join(" "),
                kd: [1.0; 3],
                map_kd: None,
            }),
            Some("Kd") => {
                let v: Vec<f32> = toks.filter_map(|t| t.parse().ok()).collect();
                if let (Some(m), 3..) = (out.last_mut(), v.len()) {
                    m.kd = [v[0], v[1], v[2]].map(|c| {
                        if c.is_finite() {
                            c.clamp(0.0, 1.0)
                        } else {
                            0.0
                        }
                    });
                }
            }
            Some("map_Kd") => {
                let rest = line["map_Kd".len()..].trim();
                if let (Some(m), false) = (out.last_mut(), rest.is_empty()) {
                    m.map_kd = Some(rest.to_string());
                }
            }
            _ => {}
        }
    }
    out
}

/// A texture image (PNG or JPEG) as linear `[0, 1]` RGB (the bytes / 255, as viewers map
/// them).
fn read_texture(path: &Path) -> Result<Image> {
    let img = image::open(path)
        .map_err(|e| Error::format(path, format!("cannot read the texture: {e}")))?
        .to_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let pixels = img
        .pixels()
        .map(|p| crate::colour::from_bytes(p.0))
        .collect();
    Image::new(w, h, pixels).ok_or_else(|| Error::format(path, "an empty texture"))
}

/// Writes a mesh with a colour per vertex (`None`: [`write_mesh`], the same bytes). PLY gets
/// `uchar red green blue`, OBJ `v x y z r g b`; OFF gets `COFF` lines.
///
/// # Errors
/// As [`write_mesh`]; colours of another count than the vertices.
pub fn write_mesh_coloured(
    path: impl AsRef<Path>,
    mesh: &TriMesh,
    colours: Option<&[Rgb]>,
) -> Result<()> {
    let path = path.as_ref();
    let Some(c) = colours else {
        return write_mesh(path, mesh);
    };
    if c.len() != mesh.vertices.len() {
        return Err(Error::InvalidInput(format!(
            "{} colours for {} vertices",
            c.len(),
            mesh.vertices.len()
        )));
    }
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Obj) => {
            super::file::write_with(path, |w| obj::write_coloured_to(w, mesh, c))
        }
        Some(MeshFormat::Ply) => {
            super::file::write_with(path, |w| ply::write_coloured_to(w, mesh, c))
        }
        Some(MeshFormat::Off) => {
            super::file::write_with(path, |w| off::write_coloured_to(w, mesh, c))
        }
        _ => write_mesh(path, mesh),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("ponq-coloured-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn quad() -> TriMesh {
        TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap()
    }

    #[test]
    fn round_trips_and_plain_files() {
        let d = tmp("rt");
        let m = quad();
        let c: Vec<Rgb> = vec![
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ];
        for ext in ["ply", "obj", "off"] {
            let p = d.join(format!("m.{ext}"));
            write_mesh_coloured(&p, &m, Some(&c)).unwrap();
            let (m2, c2) = read_mesh_coloured(&p).unwrap();
            assert_eq!(m2.faces, m.faces, "{ext}");
            match (ext, c2) {
                ("off", _) => {}
                (_, Some(Colours::Vertex(v))) => assert_eq!(v, c, "{ext}"),
                (_, other) => panic!("{ext}: {other:?}"),
            }
            // Without colours: the plain writer's bytes.
            let plain = d.join(format!("plain.{ext}"));
            write_mesh(&plain, &m).unwrap();
            let q = d.join(format!("q.{ext}"));
            write_mesh_coloured(&q, &m, None).unwrap();
            assert_eq!(std::fs::read(&plain).unwrap(), std::fs::read(&q).unwrap());
            assert!(read_mesh_coloured(&plain).unwrap().1.is_none());
        }
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn obj_materials_and_textures() {
        let d = tmp("mtl");
        // A 2 x 1 texture: left red, right blue.
        let img = image::RgbImage::from_fn(2, 1, |x, _| {
            if x == 0 {
                image::Rgb([255, 0, 0])
            } else {
                image::Rgb([0, 0, 255])
            }
        });
        img.save(d.join("tex.png")).unwrap();
        std::fs::write(
            d.join("m.mtl"),
            "newmtl green\nKd 0 1 0\nnewmtl textured\nKd 1 1 1\nmap_Kd -bm 1 tex.png\n",
        )
        .unwrap();
        std::fs::write(
            d.join("m.obj"),
            "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0.25 0.5\nvt 0.3 0.5\nvt 0.75 0.5\n\
             usemtl green\nf 1 2 3\nusemtl textured\nf 1/1 3/2 4/3\n",
        )
        .unwrap();
        let (m, c) = read_mesh_coloured(d.join("m.obj")).unwrap();
        let c = c.unwrap();
        assert_eq!(c.at(&m.faces, 0, [0.3, 0.3, 0.4]), [0.0, 1.0, 0.0]);
        // The first corner's texture coordinate: the left texel, red.
        assert_eq!(c.at(&m.faces, 1, [1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]);
        assert_eq!(c.at(&m.faces, 1, [0.0, 0.0, 1.0]), [0.0, 0.0, 1.0]);
        // A texture in the library's folder, named with a space, after options; the
        // library in a subfolder, named with a space too.
        std::fs::create_dir_all(d.join("mat")).unwrap();
        img.save(d.join("mat/my tex.png")).unwrap();
        std::fs::write(
            d.join("mat/my lib.mtl"),
            "newmtl green\nKd 0 1 0\nnewmtl textured\nKd 1 1 1\nmap_Kd -s 1 1 1 my tex.png\n",
        )
        .unwrap();
        let obj = std::fs::read_to_string(d.join("m.obj")).unwrap();
        std::fs::write(
            d.join("n.obj"),
            obj.replace("mtllib m.mtl", "mtllib mat\\my lib.mtl"),
        )
        .unwrap();
        let (m2, c2, notes) = read_mesh_coloured_noted(d.join("n.obj")).unwrap();
        assert!(notes.is_empty(), "{notes:?}");
        assert_eq!(
            c2.unwrap().at(&m2.faces, 1, [1.0, 0.0, 0.0]),
            [1.0, 0.0, 0.0]
        );
        // A missing texture costs only its colours: the material's Kd, with a note.
        std::fs::remove_file(d.join("tex.png")).unwrap();
        let (m, c, notes) = read_mesh_coloured_noted(d.join("m.obj")).unwrap();
        assert_eq!(m.faces.len(), 2);
        assert!(
            notes.len() == 1 && notes[0].contains("tex.png"),
            "{notes:?}"
        );
        assert_eq!(c.unwrap().at(&m.faces, 1, [1.0, 0.0, 0.0]), [1.0, 1.0, 1.0]);
        // So does a missing library, and an unreadable texture.
        std::fs::write(d.join("tex.png"), b"not a png").unwrap();
        let (_, c, notes) = read_mesh_coloured_noted(d.join("m.obj")).unwrap();
        assert!(c.is_some() && notes[0].contains("texture"), "{notes:?}");
        std::fs::remove_file(d.join("m.mtl")).unwrap();
        let (m, c, notes) = read_mesh_coloured_noted(d.join("m.obj")).unwrap();
        assert!(
            c.is_none() && m.faces.len() == 2 && notes[0].contains("m.mtl"),
            "{notes:?}"
        );
        std::fs::remove_dir_all(&d).ok();
    }
}
