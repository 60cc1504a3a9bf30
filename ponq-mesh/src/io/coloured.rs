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
/// here). Textures that cannot be read are an error naming them.
///
/// # Errors
/// As [`read_mesh`]; an MTL file or texture named by the OBJ that cannot be read.
pub fn read_mesh_coloured(path: impl AsRef<Path>) -> Result<(TriMesh, Option<Colours>)> {
    let path = path.as_ref();
    match MeshFormat::from_path(path) {
        Some(MeshFormat::Ply) => {
            let bytes = read_file(path)?;
            ply::parse_with_colours(&bytes).map_err(|m| Error::format(path, m))
        }
        Some(MeshFormat::Obj) => {
            let bytes = read_file(path)?;
            let (mesh, x) = obj::parse_with_extras(&bytes).map_err(|m| Error::format(path, m))?;
            if let Some(c) = x.vertex_colours {
                return Ok((mesh, Some(Colours::Vertex(c))));
            }
            let colours = obj_materials(path, &mesh, &x)?;
            Ok((mesh, colours))
        }
        _ => Ok((read_mesh(path)?, None)),
    }
}

/// The material colours of an OBJ: `None` without `usemtl` or a library that defines them.
fn obj_materials(path: &Path, mesh: &TriMesh, x: &obj::ObjExtras) -> Result<Option<Colours>> {
    if x.material_names.is_empty() || x.mtllibs.is_empty() {
        return Ok(None);
    }
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut defined: Vec<(String, Rgb, Option<String>)> = Vec::new();
    for lib in &x.mtllibs {
        let p = dir.join(lib);
        let text = std::fs::read_to_string(&p).map_err(|e| Error::io(&p, e))?;
        defined.extend(parse_mtl(&text));
    }
    let mut materials = Vec::with_capacity(x.material_names.len() + 1);
    let mut any = false;
    for name in &x.material_names {
        match defined.iter().rev().find(|(n, _, _)| n == name) {
            Some((_, kd, map)) => {
                any = true;
                let texture = match map {
                    Some(m) => Some(read_texture(&dir.join(m))?),
                    None => None,
                };
                materials.push(Material {
                    diffuse: *kd,
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
        return Ok(None);
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
    Ok(t.fits(mesh.vertices.len(), mesh.faces.len()).then_some(t))
}

/// The materials of an MTL file: name, `Kd` (default white) and `map_Kd` (its last token,
/// the file; options before it are ignored).
fn parse_mtl(text: &str) -> Vec<(String, Rgb, Option<String>)> {
    let mut out: Vec<(String, Rgb, Option<String>)> = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        let mut toks = line.split_whitespace();
        match toks.next() {
            Some("newmtl") => {
                out.push((toks.collect::<Vec<_>>().join(" "), [1.0; 3], None));
            }
            Some("Kd") => {
                let v: Vec<f32> = toks.filter_map(|t| t.parse().ok()).collect();
                if let (Some(m), 3..) = (out.last_mut(), v.len()) {
                    m.1 = [v[0], v[1], v[2]].map(|c| c.clamp(0.0, 1.0));
                }
            }
            Some("map_Kd") => {
                if let (Some(m), Some(file)) = (out.last_mut(), toks.last()) {
                    m.2 = Some(file.to_string());
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
        // A missing texture is an error naming it.
        std::fs::remove_file(d.join("tex.png")).unwrap();
        let e = read_mesh_coloured(d.join("m.obj")).unwrap_err();
        assert!(e.to_string().contains("tex.png"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }
}
