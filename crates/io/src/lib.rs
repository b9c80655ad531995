//! # snell-io
//!
//! Everything that touches files: Snell's native TOML scene format, Mitsuba 3 XML scenes, OBJ
//! and PLY meshes, and
//! PNG / EXR output. Every reader reports bad input as an [`Error`] naming the file and the
//! line and column (text) or byte offset (binary) and what was wrong; nothing here panics on
//! user input.

mod error;
pub mod gltf;
pub mod image_in;
pub mod image_out;
pub mod mitsuba;
pub mod mtl;
pub mod obj;
pub mod pbrt;
pub mod ply;
pub mod rays;
pub mod scene;
pub mod serialized;
mod shapes;
pub mod spectrum;

pub use error::{Error, Location};

use std::path::Path;

use snell_core::shape::Mesh;

/// Loads a scene file by its extension: Snell's TOML (`.toml`), Mitsuba 3 XML (`.xml`, with
/// `defines` for its `$name` defaults), pbrt-v4 (`.pbrt`), glTF (`.gltf`, `.glb`), or a bare
/// mesh (`.obj`, `.ply`) in [`scene::from_mesh`]'s scene around it.
pub fn load_scene(path: &Path, defines: &[(String, String)]) -> Result<scene::LoadedScene, Error> {
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("toml") => scene::load(path),
        Some("xml") => mitsuba::load(path, defines),
        Some("pbrt") => pbrt::load(path),
        Some("gltf") | Some("glb") => gltf::load(path),
        Some("obj") | Some("ply") => scene::from_mesh(path),
        _ => Err(Error::new(path, "unsupported scene format (expected .toml, .xml, .pbrt, .gltf, .glb, .obj or .ply)")),
    }
}

/// Reads a mesh by extension (`.obj` or `.ply`), validated and without degenerate-index faces.
pub fn read_mesh(path: &Path) -> Result<Mesh, Error> {
    let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    let mut mesh = match ext.as_deref() {
        Some("obj") => obj::read(path)?,
        Some("ply") => ply::read(path)?,
        _ => return Err(Error::new(path, "unsupported mesh format (expected .obj or .ply)")),
    };
    mesh.drop_degenerate_indices();
    mesh.validate().map_err(|e| Error::new(path, e.to_string()))?;
    if mesh.indices.is_empty() {
        return Err(Error::new(path, "the mesh has no triangles"));
    }
    Ok(mesh)
}

/// Reads a whole file, mapping I/O errors to [`Error`].
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, Error> {
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// Reads a whole text file; bytes that are not UTF-8 are an error at their line and column
/// (the column counted in bytes).
pub(crate) fn read_text(path: &Path) -> Result<String, Error> {
    String::from_utf8(read_file(path)?).map_err(|e| {
        let bytes = e.as_bytes();
        let bad = e.utf8_error().valid_up_to();
        let line = 1 + bytes[..bad].iter().filter(|&&b| b == b'\n').count();
        let col = 1 + bad - bytes[..bad].iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        Error::at(path, error::Location::LineCol(line, col), "the file is not valid UTF-8")
    })
}
