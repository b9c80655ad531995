use std::fmt;
use std::path::{Path, PathBuf};

/// Where in a file something is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// 1-based line and column of a text file.
    LineCol(usize, usize),
    /// 1-based line of a text file.
    Line(usize),
    /// Byte offset into a binary file.
    Byte(u64),
}

/// An error reading or writing a file: which file, where in it, and what was wrong.
#[derive(Debug, thiserror::Error)]
pub struct Error {
    pub path: PathBuf,
    pub location: Option<Location>,
    pub message: String,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        match self.location {
            Some(Location::LineCol(l, c)) => write!(f, ":{l}:{c}")?,
            Some(Location::Line(l)) => write!(f, ":{l}")?,
            Some(Location::Byte(b)) => write!(f, ": at byte {b}")?,
            None => {}
        }
        write!(f, ": {}", self.message)
    }
}

impl Error {
    pub fn new(path: &Path, message: impl Into<String>) -> Error {
        Error { path: path.to_path_buf(), location: None, message: message.into() }
    }

    pub fn at(path: &Path, location: Location, message: impl Into<String>) -> Error {
        Error { path: path.to_path_buf(), location: Some(location), message: message.into() }
    }

    pub fn io(path: &Path, e: std::io::Error) -> Error {
        let message = match e.kind() {
            std::io::ErrorKind::NotFound => "no such file".to_string(),
            std::io::ErrorKind::PermissionDenied => "permission denied".to_string(),
            _ => e.to_string(),
        };
        Error::new(path, message)
    }
}
