//! Reading input files (scenes, meshes, images). Only regular files are
//! read: a path to a device or a pipe (`/dev/zero`, `/dev/stdin`, a FIFO)
//! would block or fill memory, so it is refused with an error instead.

use std::io;
use std::path::Path;

/// Reads a whole regular file.
///
/// # Errors
///
/// The I/O error, or one of kind [`io::ErrorKind::InvalidInput`] when
/// `path` is not a regular file (a directory, a device, a pipe). The
/// metadata is checked before the file is opened: opening a FIFO blocks
/// until a writer appears.
pub fn read_file(path: &Path) -> io::Result<Vec<u8>> {
    if !std::fs::metadata(path)?.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file (a directory, a device or a pipe)",
        ));
    }
    std::fs::read(path)
}

/// The size of a regular file, without opening it.
///
/// # Errors
///
/// As [`read_file`] for what is not a regular file.
pub fn regular_file_size(path: &Path) -> io::Result<u64> {
    let m = std::fs::metadata(path)?;
    if !m.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a regular file (a directory, a device or a pipe)",
        ));
    }
    Ok(m.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_what_is_not_a_regular_file() {
        let dir = std::env::temp_dir();
        let e = read_file(&dir).expect_err("a directory");
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        #[cfg(unix)]
        {
            let e = read_file(Path::new("/dev/zero")).expect_err("a device");
            assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        }
        let e = read_file(&dir.join("rendiff-no-such-file")).expect_err("missing");
        assert_eq!(e.kind(), io::ErrorKind::NotFound);
    }
}
