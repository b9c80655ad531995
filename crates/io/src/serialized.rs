//! Mitsuba's `serialized` meshes: a `0x041C` header and version (3 or 4), then a zlib stream
//! with flags, (version 4) a name, vertex and triangle counts, positions, optional normals,
//! texture coordinates and colours, and triangle indices. A file may hold several meshes; a
//! table of their offsets and their count end the file, and `shape_index` picks one.

use std::io::Read;
use std::path::Path;

use glam::{Vec2, Vec3};
use snell_core::shape::Mesh;

use crate::{Error, Location};

const MAGIC: u16 = 0x041C;
const HAS_NORMALS: u32 = 0x0001;
const HAS_UVS: u32 = 0x0002;
const HAS_COLORS: u32 = 0x0008;
const FACE_NORMALS: u32 = 0x0010;
const SINGLE: u32 = 0x1000;
const DOUBLE: u32 = 0x2000;

/// Reads mesh `shape_index` of a serialized file.
pub fn read(path: &Path, shape_index: usize) -> Result<Mesh, Error> {
    let bytes = crate::read_file(path)?;
    let at = |offset: usize, m: String| Error::at(path, Location::Byte(offset as u64), m);
    let u16_at = |o: usize| bytes.get(o..o.checked_add(2)?).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let start = if shape_index == 0 {
        0
    } else {
        // The end of the file: the offsets of the meshes, then their count.
        let n = bytes.len();
        let count = bytes
            .get(n.saturating_sub(4)..)
            .filter(|b| b.len() == 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
            .ok_or_else(|| at(n, "too short for a table of meshes".into()))?;
        if shape_index >= count {
            return Err(at(n - 4, format!("shape_index {shape_index}, but the file holds {count} meshes")));
        }
        let version = u16_at(2).unwrap_or(0);
        let width = if version >= 4 { 8 } else { 4 };
        let pos =
            n.checked_sub(4 + width * (count - shape_index)).ok_or_else(|| at(n, "bad table of meshes".into()))?;
        let b = &bytes[pos..pos + width];
        if width == 8 {
            u64::from_le_bytes(b.try_into().unwrap_or([0; 8])) as usize
        } else {
            u32::from_le_bytes(b.try_into().unwrap_or([0; 4])) as usize
        }
    };
    match (u16_at(start), u16_at(start.saturating_add(2))) {
        (Some(MAGIC), Some(v @ (3 | 4))) => parse(&bytes[start + 4..], v, start + 4).map_err(|(o, m)| at(o, m)),
        (Some(MAGIC), Some(v)) => Err(at(start + 2, format!("serialized version {v} (expected 3 or 4)"))),
        _ => Err(at(start, "not a Mitsuba serialized mesh (no 0x041C header)".into())),
    }
}

/// Parses one compressed mesh; errors carry a byte offset (into the file for the header, into
/// the decompressed stream, after `base`, otherwise).
fn parse(compressed: &[u8], version: u16, base: usize) -> Result<Mesh, (usize, String)> {
    let mut data = Vec::new();
    flate2::read::ZlibDecoder::new(compressed)
        .read_to_end(&mut data)
        .map_err(|e| (base, format!("the compressed mesh data is damaged: {e}")))?;
    let mut r = Cursor { data: &data, pos: 0 };
    let flags = r.u32()?;
    if version >= 4 {
        while r.u8()? != 0 {}
    }
    let (nv, nt) = (r.u64()?, r.u64()?);
    let double = match (flags & SINGLE != 0, flags & DOUBLE != 0) {
        (true, false) => false,
        (false, true) => true,
        _ => return Err((0, format!("flags {flags:#x}: exactly one of single and double precision expected"))),
    };
    let width = if double { 8 } else { 4 };
    // Counts from the file bound the allocations only once they are known to fit the data.
    let fits = nv
        .checked_mul(3 * width)
        .and_then(|p| p.checked_add(nt.checked_mul(12)?))
        .is_some_and(|n| n <= data.len() as u64);
    if !fits {
        return Err((r.pos, format!("{nv} vertices and {nt} triangles do not fit in {} bytes", data.len())));
    }
    let (nv, nt) = (nv as usize, nt as usize);
    let vec3s = |r: &mut Cursor| -> Result<Vec<Vec3>, (usize, String)> {
        (0..nv).map(|_| Ok(Vec3::new(r.real(double)?, r.real(double)?, r.real(double)?))).collect()
    };
    let positions = vec3s(&mut r)?;
    let normals = if flags & HAS_NORMALS != 0 { Some(vec3s(&mut r)?) } else { None };
    let uvs = if flags & HAS_UVS != 0 {
        Some((0..nv).map(|_| Ok(Vec2::new(r.real(double)?, r.real(double)?))).collect::<Result<Vec<_>, _>>()?)
    } else {
        None
    };
    if flags & HAS_COLORS != 0 {
        r.pos += nv * 3 * width as usize;
    }
    let wide = nv > u32::MAX as usize;
    let mut indices = Vec::with_capacity(nt);
    for _ in 0..nt {
        let mut t = [0u32; 3];
        for i in &mut t {
            let v = if wide { r.u64()? } else { r.u32()? as u64 };
            *i = u32::try_from(v).map_err(|_| (r.pos, format!("vertex index {v} is too large")))?;
        }
        indices.push(t);
    }
    let normals = if flags & FACE_NORMALS != 0 { None } else { normals };
    Ok(Mesh { positions, normals, uvs, indices })
}

struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Cursor<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], (usize, String)> {
        let b =
            self.data.get(self.pos..self.pos + N).ok_or_else(|| (self.pos, "the mesh data ends early".to_string()))?;
        self.pos += N;
        Ok(b.try_into().unwrap_or([0; N]))
    }
    fn u8(&mut self) -> Result<u8, (usize, String)> {
        Ok(self.take::<1>()?[0])
    }
    fn u32(&mut self) -> Result<u32, (usize, String)> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    fn u64(&mut self) -> Result<u64, (usize, String)> {
        Ok(u64::from_le_bytes(self.take()?))
    }
    fn real(&mut self, double: bool) -> Result<f32, (usize, String)> {
        Ok(if double { f64::from_le_bytes(self.take()?) as f32 } else { f32::from_le_bytes(self.take()?) })
    }
}
