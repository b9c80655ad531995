use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn snell() -> Command {
    Command::new(env!("CARGO_BIN_EXE_snell"))
}

pub fn run(args: &[&str], dir: &Path) -> Output {
    snell().args(args).current_dir(dir).output().expect("failed to start snell")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The shared test data, from `SNELL_SCENES`. `None` (with a note) when the variable is not
/// set; a panic when it is set but the file is missing, so CI fails loudly. A relative path
/// is relative to the workspace root.
pub fn shared_scene(rel: &str) -> Option<PathBuf> {
    let Ok(root) = std::env::var("SNELL_SCENES") else {
        eprintln!("SNELL_SCENES is not set: skipping the test that needs {rel}");
        return None;
    };
    // A relative path is taken from the workspace root, where `cargo test` is run (the test
    // process itself runs in the crate's directory).
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(root);
    let p = root.join(rel);
    assert!(p.is_file(), "SNELL_SCENES is set but {} is missing", p.display());
    Some(p)
}

/// A little-endian colour PFM, rows given top first (the file stores them bottom up).
pub fn pfm(w: usize, h: usize, rows_top_first: &[[f32; 3]]) -> Vec<u8> {
    let mut v = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for y in (0..h).rev() {
        for x in 0..w {
            for c in rows_top_first[y * w + x] {
                v.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    v
}

/// Path of a file in `crates/cli/tests/data`.
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

/// Path of a scene in the repository's `scenes/` directory.
pub fn repo_scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name)
}

/// An icosphere of 1,280 triangles with each vertex moved out by up to 30 % (`rng`'s numbers,
/// one a vertex): a closed mesh that is not convex, so that rays leaving it may meet it again.
pub fn bumpy_ball(rng: &mut snell_core::sampling::Pcg32) -> snell_core::shape::Mesh {
    let mut ball = snell_core::shape::Mesh::icosphere(3);
    for p in ball.positions.iter_mut() {
        *p *= 1.0 + 0.3 * rng.next_f32();
    }
    ball
}
