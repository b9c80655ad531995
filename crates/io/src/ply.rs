//! PLY meshes: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! Reads the `vertex` element (`x y z`, optional `nx ny nz` and `u v` / `s t`) and the `face`
//! element (`vertex_indices` or `vertex_index` lists; polygons are fan-triangulated); other
//! elements and properties are skipped. The counts in the header are checked against the
//! size of the file before anything is allocated, so a header that declares 10^12 vertices
//! fails at once instead of exhausting memory.

use std::path::Path;

use glam::{Vec2, Vec3};
use snell_core::shape::Mesh;

use crate::{Error, Location};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> u64 {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug)]
struct Property {
    name: String,
    /// `Some(count type)` for list properties.
    list: Option<Scalar>,
    ty: Scalar,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Le,
    Be,
}

/// Reads a PLY file.
pub fn read(path: &Path) -> Result<Mesh, Error> {
    let bytes = crate::read_file(path)?;
    parse(&bytes).map_err(|(loc, msg)| match loc {
        Some(l) => Error::at(path, l, msg),
        None => Error::new(path, msg),
    })
}

type PErr = (Option<Location>, String);

fn header_err(line: usize, msg: impl Into<String>) -> PErr {
    (Some(Location::Line(line)), msg.into())
}

/// Parses PLY bytes.
pub fn parse(bytes: &[u8]) -> Result<Mesh, PErr> {
    if bytes.is_empty() {
        return Err((None, "the file is empty".into()));
    }
    // Header: lines up to "end_header".
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut ended = false;
    while pos < bytes.len() {
        let end = bytes[pos..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |e| pos + e);
        let line = String::from_utf8_lossy(&bytes[pos..end]).trim().to_string();
        pos = (end + 1).min(bytes.len());
        line_no += 1;
        let toks: Vec<&str> = line.split_whitespace().collect();
        if line_no == 1 {
            if line != "ply" {
                return Err(header_err(1, "not a PLY file (the first line must be 'ply')"));
            }
            continue;
        }
        match toks.first().copied() {
            Some("format") => {
                format = Some(match toks.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::Le,
                    Some("binary_big_endian") => Format::Be,
                    other => return Err(header_err(line_no, format!("unknown PLY format {other:?}"))),
                });
            }
            Some("element") => {
                let (Some(name), Some(count)) = (toks.get(1), toks.get(2)) else {
                    return Err(header_err(line_no, "'element' needs a name and a count"));
                };
                let count: u64 = count
                    .parse()
                    .map_err(|_| header_err(line_no, format!("element count '{count}' is not a count")))?;
                elements.push(Element { name: name.to_string(), count, props: Vec::new() });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(header_err(line_no, "'property' before any 'element'"));
                };
                let prop = if toks.get(1) == Some(&"list") {
                    let (Some(ct), Some(it), Some(name)) = (toks.get(2), toks.get(3), toks.get(4)) else {
                        return Err(header_err(line_no, "'property list' needs a count type, an item type and a name"));
                    };
                    let ct = Scalar::parse(ct).ok_or_else(|| header_err(line_no, format!("unknown type '{ct}'")))?;
                    if matches!(ct, Scalar::F32 | Scalar::F64) {
                        return Err(header_err(line_no, "a list count must have an integer type"));
                    }
                    let it = Scalar::parse(it).ok_or_else(|| header_err(line_no, format!("unknown type '{it}'")))?;
                    Property { name: name.to_string(), list: Some(ct), ty: it }
                } else {
                    let (Some(ty), Some(name)) = (toks.get(1), toks.get(2)) else {
                        return Err(header_err(line_no, "'property' needs a type and a name"));
                    };
                    let ty = Scalar::parse(ty).ok_or_else(|| header_err(line_no, format!("unknown type '{ty}'")))?;
                    Property { name: name.to_string(), list: None, ty }
                };
                el.props.push(prop);
            }
            Some("end_header") => {
                ended = true;
                break;
            }
            Some("comment") | Some("obj_info") | None => {}
            Some(other) => return Err(header_err(line_no, format!("unknown header keyword '{other}'"))),
        }
    }
    if !ended {
        return Err(header_err(line_no, "the header has no 'end_header'"));
    }
    let format = format.ok_or_else(|| header_err(line_no, "the header has no 'format' line"))?;

    // Fail fast: a lower bound on the body size from the declared counts.
    let body = bytes.len() as u64 - pos as u64;
    for el in &elements {
        let per = if format == Format::Ascii {
            // At least one digit and one separator per value.
            2 * el.props.len() as u64
        } else {
            el.props.iter().map(|p| p.list.map_or(p.ty.size(), |c| c.size())).sum()
        };
        let need = el.count.saturating_mul(per);
        if need > body {
            return Err((
                None,
                format!(
                    "the header declares {} '{}' elements, which need at least {} bytes, but only {} bytes follow the header",
                    el.count, el.name, need, body
                ),
            ));
        }
    }

    let mut reader: Box<dyn Values> = match format {
        Format::Ascii => Box::new(AsciiValues { text: &bytes[pos..], pos: 0, line: line_no + 1 }),
        Format::Le | Format::Be => Box::new(BinValues { data: bytes, pos, big: format == Format::Be }),
    };
    let mut mesh = Mesh::default();
    for el in &elements {
        match el.name.as_str() {
            "vertex" => read_vertices(el, reader.as_mut(), &mut mesh)?,
            "face" => read_faces(el, reader.as_mut(), &mut mesh)?,
            _ => {
                for _ in 0..el.count {
                    for p in &el.props {
                        skip_property(p, reader.as_mut())?;
                    }
                }
            }
        }
    }
    if mesh.indices.is_empty() {
        return Err((None, "the file has no faces".into()));
    }
    Ok(mesh)
}

trait Values {
    fn next(&mut self, ty: Scalar) -> Result<f64, PErr>;
    /// Where the next value starts.
    fn location(&mut self) -> Location;
}

struct BinValues<'a> {
    data: &'a [u8],
    pos: usize,
    big: bool,
}

impl Values for BinValues<'_> {
    fn next(&mut self, ty: Scalar) -> Result<f64, PErr> {
        let n = ty.size() as usize;
        let Some(b) = self.data.get(self.pos..self.pos + n) else {
            return Err((
                Some(Location::Byte(self.pos as u64)),
                "the file ends in the middle of the data (truncated)".into(),
            ));
        };
        self.pos += n;
        macro_rules! get {
            ($t:ty) => {{
                let a = b.try_into().map_err(|_| (None, "internal size mismatch".to_string()))?;
                (if self.big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        Ok(match ty {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16),
            Scalar::U16 => get!(u16),
            Scalar::I32 => get!(i32),
            Scalar::U32 => get!(u32),
            Scalar::F32 => get!(f32),
            Scalar::F64 => get!(f64),
        })
    }

    fn location(&mut self) -> Location {
        Location::Byte(self.pos as u64)
    }
}

struct AsciiValues<'a> {
    text: &'a [u8],
    pos: usize,
    line: usize,
}

impl AsciiValues<'_> {
    fn skip_space(&mut self) {
        while self.pos < self.text.len() && self.text[self.pos].is_ascii_whitespace() {
            if self.text[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
    }
}

impl Values for AsciiValues<'_> {
    fn next(&mut self, ty: Scalar) -> Result<f64, PErr> {
        self.skip_space();
        let start = self.pos;
        while self.pos < self.text.len() && !self.text[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos {
            return Err((
                Some(Location::Line(self.line)),
                "the file ends in the middle of the data (truncated)".into(),
            ));
        }
        let tok = String::from_utf8_lossy(&self.text[start..self.pos]);
        let v: f64 = tok.parse().map_err(|_| (Some(Location::Line(self.line)), format!("'{tok}' is not a number")))?;
        if !matches!(ty, Scalar::F32 | Scalar::F64) && v.fract() != 0.0 {
            return Err((Some(Location::Line(self.line)), format!("'{tok}' is not an integer")));
        }
        Ok(v)
    }

    fn location(&mut self) -> Location {
        self.skip_space();
        Location::Line(self.line)
    }
}

fn skip_property(p: &Property, r: &mut dyn Values) -> Result<(), PErr> {
    if let Some(ct) = p.list {
        let n = r.next(ct)?;
        for _ in 0..(n.max(0.0) as u64) {
            r.next(p.ty)?;
        }
    } else {
        r.next(p.ty)?;
    }
    Ok(())
}

fn read_vertices(el: &Element, r: &mut dyn Values, mesh: &mut Mesh) -> Result<(), PErr> {
    let find = |names: &[&str]| el.props.iter().position(|p| names.contains(&p.name.as_str()) && p.list.is_none());
    let (Some(x), Some(y), Some(z)) = (find(&["x"]), find(&["y"]), find(&["z"])) else {
        return Err((None, "the 'vertex' element has no x, y and z properties".into()));
    };
    let normal = (find(&["nx"]), find(&["ny"]), find(&["nz"]));
    let uv = (find(&["u", "s", "texture_u", "texture_s"]), find(&["v", "t", "texture_v", "texture_t"]));
    let has_n = normal.0.is_some() && normal.1.is_some() && normal.2.is_some();
    let has_uv = uv.0.is_some() && uv.1.is_some();
    let count = el.count as usize;
    mesh.positions.reserve(count);
    let mut normals = Vec::with_capacity(if has_n { count } else { 0 });
    let mut uvs = Vec::with_capacity(if has_uv { count } else { 0 });
    let mut vals = vec![0.0f64; el.props.len()];
    for i in 0..count {
        let loc = r.location();
        for (k, p) in el.props.iter().enumerate() {
            if p.list.is_some() {
                skip_property(p, r)?;
            } else {
                vals[k] = r.next(p.ty)?;
            }
        }
        let pos = Vec3::new(vals[x] as f32, vals[y] as f32, vals[z] as f32);
        if !pos.is_finite() {
            return Err((Some(loc), format!("vertex {i} has a NaN or infinite coordinate")));
        }
        mesh.positions.push(pos);
        if has_n {
            let (a, b, c) = (normal.0.unwrap_or(0), normal.1.unwrap_or(0), normal.2.unwrap_or(0));
            normals.push(Vec3::new(vals[a] as f32, vals[b] as f32, vals[c] as f32));
        }
        if has_uv {
            uvs.push(Vec2::new(vals[uv.0.unwrap_or(0)] as f32, vals[uv.1.unwrap_or(0)] as f32));
        }
    }
    if has_n {
        mesh.normals = Some(normals);
    }
    if has_uv {
        mesh.uvs = Some(uvs);
    }
    Ok(())
}

fn read_faces(el: &Element, r: &mut dyn Values, mesh: &mut Mesh) -> Result<(), PErr> {
    let Some(fi) =
        el.props.iter().position(|p| p.list.is_some() && (p.name == "vertex_indices" || p.name == "vertex_index"))
    else {
        return Err((None, "the 'face' element has no 'vertex_indices' list".into()));
    };
    mesh.indices.reserve(el.count as usize);
    let nverts = mesh.positions.len() as f64;
    let mut poly: Vec<u32> = Vec::with_capacity(8);
    for i in 0..el.count {
        for (k, p) in el.props.iter().enumerate() {
            if k != fi {
                skip_property(p, r)?;
                continue;
            }
            let loc = r.location();
            let n = r.next(p.list.unwrap_or(Scalar::U8))?;
            if n < 0.0 {
                return Err((Some(loc), format!("face {i} has a negative vertex count")));
            }
            poly.clear();
            for _ in 0..n as u64 {
                let loc = r.location();
                let v = r.next(p.ty)?;
                if v < 0.0 || v >= nverts {
                    return Err((
                        Some(loc),
                        format!("face {i} uses vertex index {v}, but the file has {} vertices", mesh.positions.len()),
                    ));
                }
                poly.push(v as u32);
            }
            if poly.len() >= 3 {
                for k in 1..poly.len() - 1 {
                    mesh.indices.push([poly[0], poly[k], poly[k + 1]]);
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn binary_tri(count_line: &str, truncate: usize) -> Vec<u8> {
        let mut b = format!(
            "ply\nformat binary_little_endian 1.0\n{count_line}\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        )
        .into_bytes();
        for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
            for c in v {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.push(3);
        for i in [0i32, 1, 2] {
            b.extend_from_slice(&i.to_le_bytes());
        }
        b.truncate(b.len() - truncate);
        b
    }

    #[test]
    fn reads_binary_and_ascii() {
        let m = parse(&binary_tri("element vertex 3", 0)).unwrap();
        assert_eq!(m.indices, vec![[0, 1, 2]]);
        assert_eq!(m.positions[1], Vec3::X);
        let a = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        let m = parse(a.as_bytes()).unwrap();
        assert_eq!(m.indices.len(), 2);
    }

    #[test]
    fn truncated_binary_reports_byte_offset() {
        let e = parse(&binary_tri("element vertex 3", 3)).unwrap_err();
        assert!(matches!(e.0, Some(Location::Byte(_))), "{e:?}");
        assert!(e.1.contains("truncated"));
    }

    #[test]
    fn absurd_counts_fail_fast() {
        let e = parse(&binary_tri("element vertex 1000000000000", 0)).unwrap_err();
        assert!(e.1.contains("1000000000000"), "{e:?}");
        let e = parse(&binary_tri("element vertex 18446744073709551615", 0)).unwrap_err();
        assert!(e.1.contains("bytes"), "{e:?}");
    }

    #[test]
    fn bad_headers() {
        assert!(parse(b"").is_err());
        assert!(parse(b"plx\n").is_err());
        assert!(parse(b"ply\nformat ascii 1.0\nelement vertex 1\n").unwrap_err().1.contains("end_header"));
        assert!(parse(b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n").is_err());
    }
}
