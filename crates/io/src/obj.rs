//! Wavefront OBJ meshes: `v`, `vn`, `vt` and `f` (polygons are fan-triangulated; negative,
//! relative indices are supported), and `mtllib` / `usemtl` for [`read_groups`] (one mesh per
//! material, see `mtl.rs`). Groups and smoothing groups are ignored. Vertices are
//! deduplicated by their `(v, vt, vn)` index triple.

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};
use snell_core::shape::Mesh;

use crate::{Error, Location};

/// Reads an OBJ file.
pub fn read(path: &Path) -> Result<Mesh, Error> {
    let bytes = crate::read_file(path)?;
    if bytes.is_empty() {
        return Err(Error::new(path, "the file is empty"));
    }
    let text = String::from_utf8_lossy(&bytes);
    parse(&text).map_err(|(line, msg)| Error::at(path, Location::Line(line), msg))
}

fn floats<const N: usize>(it: &mut std::str::SplitWhitespace, what: &str) -> Result<[f32; N], String> {
    let mut out = [0.0; N];
    for (i, o) in out.iter_mut().enumerate() {
        let tok = it.next().ok_or_else(|| format!("{what} needs {N} numbers, found {i}"))?;
        *o = tok.parse::<f32>().map_err(|_| format!("{what}: '{tok}' is not a number"))?;
        if !o.is_finite() {
            return Err(format!("{what}: '{tok}' is not a finite number"));
        }
    }
    Ok(out)
}

/// Parses OBJ text; errors carry the 1-based line number.
pub fn parse(text: &str) -> Result<Mesh, (usize, String)> {
    let parsed = parse_groups(text)?;
    Ok(parsed.mesh(None))
}

/// An OBJ file's faces with the material each was assigned (`usemtl`) and its `mtllib`s.
pub struct ObjFile {
    v: Vec<Vec3>,
    vn: Vec<Vec3>,
    vt: Vec<Vec2>,
    corners: Vec<[Option<usize>; 3]>,
    /// (first corner, count, material index into `materials`, or usize::MAX for none)
    faces: Vec<(usize, usize, usize)>,
    /// Material names in order of first `usemtl`.
    pub materials: Vec<String>,
    /// `mtllib` file names with their line.
    pub libraries: Vec<(String, usize)>,
}

impl ObjFile {
    /// Whether any face has a material.
    pub fn has_materials(&self) -> bool {
        self.faces.iter().any(|f| f.2 != usize::MAX)
    }

    /// The mesh of the faces with material `material` (an index into `materials`), or of all
    /// faces (`None`).
    pub fn mesh(&self, material: Option<usize>) -> Mesh {
        let faces: Vec<&(usize, usize, usize)> =
            self.faces.iter().filter(|f| material.is_none_or(|m| f.2 == m)).collect();
        let (v, vn, vt, corners) = (&self.v, &self.vn, &self.vt, &self.corners);
        let used = || faces.iter().flat_map(|&&(s, n, _)| &corners[s..s + n]);
        let all_vt = used().all(|c| c[1].is_some()) && !vt.is_empty();
        let all_vn = used().all(|c| c[2].is_some()) && !vn.is_empty();
        let mut mesh = Mesh::default();
        let mut map: HashMap<(usize, usize, usize), u32> = HashMap::new();
        let mut vertex = |c: [Option<usize>; 3], mesh: &mut Mesh| -> u32 {
            let key = (
                c[0].unwrap_or(0),
                if all_vt { c[1].unwrap_or(0) } else { 0 },
                if all_vn { c[2].unwrap_or(0) } else { 0 },
            );
            *map.entry(key).or_insert_with(|| {
                mesh.positions.push(v[key.0]);
                if all_vt {
                    mesh.uvs.get_or_insert_with(Vec::new).push(vt[key.1]);
                }
                if all_vn {
                    mesh.normals.get_or_insert_with(Vec::new).push(vn[key.2]);
                }
                (mesh.positions.len() - 1) as u32
            })
        };
        for &&(start, n, _) in &faces {
            let first = vertex(corners[start], &mut mesh);
            for k in 1..n - 1 {
                let b = vertex(corners[start + k], &mut mesh);
                let c = vertex(corners[start + k + 1], &mut mesh);
                mesh.indices.push([first, b, c]);
            }
        }
        mesh
    }
}

/// Reads an OBJ file keeping each face's material.
pub fn read_groups(path: &Path) -> Result<ObjFile, Error> {
    let bytes = crate::read_file(path)?;
    if bytes.is_empty() {
        return Err(Error::new(path, "the file is empty"));
    }
    parse_groups(&String::from_utf8_lossy(&bytes)).map_err(|(line, msg)| Error::at(path, Location::Line(line), msg))
}

/// Parses OBJ text keeping each face's material; errors carry the 1-based line number.
pub fn parse_groups(text: &str) -> Result<ObjFile, (usize, String)> {
    let mut materials: Vec<String> = Vec::new();
    let mut libraries: Vec<(String, usize)> = Vec::new();
    let mut current = usize::MAX;
    let mut v: Vec<Vec3> = Vec::new();
    let mut vn: Vec<Vec3> = Vec::new();
    let mut vt: Vec<Vec2> = Vec::new();
    // Face corners as (v, vt, vn) 0-based indices, with the line of each face.
    let mut corners: Vec<[Option<usize>; 3]> = Vec::new();
    let mut faces: Vec<(usize, usize, usize)> = Vec::new(); // (first corner, count, material)
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let l = raw.split('#').next().unwrap_or("").trim();
        let mut it = l.split_whitespace();
        match it.next() {
            Some("v") => v.push(Vec3::from(floats::<3>(&mut it, "vertex").map_err(|e| (line, e))?)),
            Some("vn") => vn.push(Vec3::from(floats::<3>(&mut it, "normal").map_err(|e| (line, e))?)),
            Some("vt") => {
                let uv = floats::<1>(&mut it, "texture coordinate").map_err(|e| (line, e))?;
                let vv = it.next().and_then(|t| t.parse::<f32>().ok()).filter(|x| x.is_finite()).unwrap_or(0.0);
                vt.push(Vec2::new(uv[0], vv));
            }
            Some("f") => {
                let start = corners.len();
                for tok in it {
                    let mut parts = tok.split('/');
                    let mut idx = [None; 3];
                    let counts = [v.len(), vt.len(), vn.len()];
                    let names = ["vertex", "texture coordinate", "normal"];
                    for k in 0..3 {
                        let Some(p) = parts.next() else { break };
                        if p.is_empty() {
                            if k == 0 {
                                return Err((line, format!("face corner '{tok}' has no vertex index")));
                            }
                            continue;
                        }
                        let n: i64 = p.parse().map_err(|_| (line, format!("face index '{p}' is not an integer")))?;
                        let resolved = if n > 0 { n - 1 } else { counts[k] as i64 + n };
                        if n == 0 || resolved < 0 || resolved >= counts[k] as i64 {
                            return Err((
                                line,
                                format!("face {} index {n} is out of range ({} defined so far)", names[k], counts[k]),
                            ));
                        }
                        idx[k] = Some(resolved as usize);
                    }
                    corners.push(idx);
                }
                let n = corners.len() - start;
                if n < 3 {
                    return Err((line, format!("a face needs at least 3 vertices, found {n}")));
                }
                faces.push((start, n, current));
            }
            Some("usemtl") => {
                let name = it.collect::<Vec<_>>().join(" ");
                current = match materials.iter().position(|m| *m == name) {
                    Some(i) => i,
                    None => {
                        materials.push(name);
                        materials.len() - 1
                    }
                };
            }
            Some("mtllib") => libraries.extend(it.map(|f| (f.to_string(), line))),
            _ => {}
        }
    }
    if faces.is_empty() {
        return Err((text.lines().count().max(1), "no faces in the file".to_string()));
    }
    Ok(ObjFile { v, vn, vt, corners, faces, materials, libraries })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_are_fan_triangulated_and_negative_indices_work() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n").unwrap();
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn normals_and_uvs_are_unified() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvn 0 0 1\nf 1/1/1 2/2/1 3/1/1\n").unwrap();
        assert_eq!(m.positions.len(), 3);
        assert_eq!(m.normals.as_ref().unwrap().len(), 3);
        assert_eq!(m.uvs.as_ref().unwrap()[1], Vec2::new(1.0, 0.0));
    }

    #[test]
    fn errors_name_the_line() {
        assert_eq!(parse("v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap_err().0, 3);
        assert_eq!(parse("v 0 0 0\nv nan 0 0\n").unwrap_err().0, 2);
        assert_eq!(parse("v 0 0 inf\n").unwrap_err().0, 1);
        assert!(parse("# nothing\n").is_err());
        assert!(parse("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 x\n").unwrap_err().1.contains("not an integer"));
    }
}
