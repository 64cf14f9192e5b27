//! Errors of scene loading: each names the file, the line (and column) or
//! key, and what was expected.

use std::fmt;
use std::path::{Path, PathBuf};

/// A position in a text file (1-based).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Loc {
    /// Line, from 1.
    pub line: usize,
    /// Column in characters, from 1.
    pub col: usize,
}

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.col)
    }
}

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    /// A file could not be read.
    #[error("{}: could not read the file", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The TOML is not well formed.
    #[error("{}:{loc}: TOML syntax error: {message}", .path.display())]
    Syntax {
        /// The scene file.
        path: PathBuf,
        /// Where.
        loc: Loc,
        /// The parser's message.
        message: String,
    },
    /// A key is unknown, missing, of the wrong type or breaks its rule.
    #[error("{}:{loc}: `{key}`: {message}", .path.display())]
    Key {
        /// The scene file.
        path: PathBuf,
        /// Where (the value; for a missing key, the near-miss key that is
        /// likely its typo, else the table it belongs to).
        loc: Loc,
        /// The dotted key, e.g. `materials.red.phong` or `objects[2].radius`.
        key: String,
        /// What was expected.
        message: String,
    },
    /// A mesh file is malformed.
    #[error("{}{}: {message}", .path.display(), .line.map(|l| format!(":{l}")).unwrap_or_default())]
    Mesh {
        /// The OBJ file.
        path: PathBuf,
        /// The line, when the problem has one.
        line: Option<usize>,
        /// What was wrong.
        message: String,
    },
    /// An image file is unreadable or malformed.
    #[error("{}: {message}", .path.display())]
    Image {
        /// The PNG file.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
    /// A problem with the scene as a whole.
    #[error("{}: {message}", .path.display())]
    Scene {
        /// The scene file.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
}

impl LoadError {
    /// A key error.
    pub(crate) fn key(
        path: &Path,
        loc: Loc,
        key: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        LoadError::Key {
            path: path.to_path_buf(),
            loc,
            key: key.into(),
            message: message.into(),
        }
    }
}
