//! Where outputs may go: never over an input, folders replaced as a whole
//! set, folder names for several scenes that stay inside `--out`.
//!
//! * [`refuse_inputs`]: an output that is one of the request's inputs (the
//!   same file by device and inode, whatever the spelling or link) is
//!   refused, as is an output folder that holds one.
//! * [`OutputDir`]: a set of files (a diff's pictures, report and page) is
//!   written into a fresh folder beside the target and swapped in at once
//!   (`renameat2(RENAME_EXCHANGE)` on Linux), so the folder holds either
//!   the whole old set or the whole new one, never a mix — also when two
//!   runs write it at the same time, or the disk fills half-way.
//! * [`scene_folders`]: one folder name per scene, from its path relative
//!   to the scenes' common folder, sanitised and de-duplicated.

use std::os::unix::fs::MetadataExt;
use std::path::{Component, Path, PathBuf};

use crate::image_io::ImageIoError;

/// The file marking a folder as a rendiff output set (replaceable as a
/// whole).
pub const MARKER: &str = ".rendiff-output";

fn refused(path: &Path, message: impl Into<String>) -> ImageIoError {
    ImageIoError::Refused {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn io(path: &Path, source: std::io::Error) -> ImageIoError {
    ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Removes the folders `made` (deepest first) while they are empty; one
/// already gone is passed over, one that holds something stops it (so do
/// the folders around it).
fn remove_empty(made: &[PathBuf]) {
    for dir in made {
        match std::fs::remove_dir(dir) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(_) => break,
        }
    }
}

/// Refuses an output file that is one of `inputs` (the same file: device
/// and inode, through any link or spelling), or an output folder that is
/// or holds one.
///
/// # Errors
///
/// [`ImageIoError::Refused`] naming the input.
pub fn refuse_inputs(out: &Path, inputs: &[PathBuf]) -> Result<(), ImageIoError> {
    let Ok(meta) = std::fs::metadata(out) else {
        // Nothing there yet: it is no input (inputs exist).
        return Ok(());
    };
    let id = (meta.dev(), meta.ino());
    for input in inputs {
        let Ok(m) = std::fs::metadata(input) else {
            continue;
        };
        if (m.dev(), m.ino()) == id {
            return Err(refused(
                out,
                format!(
                    "is an input of this request ({}); rendiff does not write over its inputs",
                    input.display()
                ),
            ));
        }
        if meta.is_dir()
            && let (Ok(dir), Ok(file)) = (std::fs::canonicalize(out), std::fs::canonicalize(input))
            && file.starts_with(&dir)
        {
            return Err(refused(
                out,
                format!(
                    "holds an input of this request ({}); an output folder is replaced as a whole, so it must not hold inputs",
                    input.display()
                ),
            ));
        }
    }
    Ok(())
}

/// An output folder being written: files go into a fresh folder beside
/// it, which [`OutputDir::commit`] swaps in as a whole.
#[derive(Debug)]
pub struct OutputDir {
    target: PathBuf,
    fresh: Option<tempfile::TempDir>,
    /// The folders of the target's path that [`OutputDir::begin`] made,
    /// deepest first: removed again (where still empty) unless the set is
    /// committed, so a run that fails leaves nothing behind.
    made: Vec<PathBuf>,
    _guard: crate::cleanup::TempGuard,
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        // The fresh folder first (its parent is among `made`).
        drop(self.fresh.take());
        // Only an empty folder goes: never what someone put there.
        remove_empty(&self.made);
    }
}

impl OutputDir {
    /// Starts writing the set for `target`, which must be a new path, an
    /// empty folder, or a folder rendiff wrote (it holds [`MARKER`]);
    /// `inputs` may not be inside it.
    ///
    /// # Errors
    ///
    /// [`ImageIoError::Refused`] for a folder of other files, a file, or one
    /// that holds an input; the I/O error of creating the fresh folder.
    pub fn begin(target: &Path, inputs: &[PathBuf]) -> Result<OutputDir, ImageIoError> {
        if let Ok(m) = std::fs::symlink_metadata(target) {
            if m.file_type().is_symlink() {
                return Err(refused(
                    target,
                    "is a symbolic link; name the output folder itself",
                ));
            }
            if !m.is_dir() {
                return Err(refused(target, "exists and is not a folder"));
            }
            refuse_inputs(target, inputs)?;
            let empty = std::fs::read_dir(target)
                .map_err(|e| io(target, e))?
                .next()
                .is_none();
            if !empty && !target.join(MARKER).is_file() {
                return Err(refused(
                    target,
                    format!(
                        "holds files rendiff did not write (no {MARKER}); an output folder is replaced as a whole: name a new or empty folder"
                    ),
                ));
            }
        }
        let parent = target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        // The folders of the path the user named are made as `mkdir -p`
        // would (a fresh checkout has no `out/`); a file in their way is
        // refused by name.
        let mut made = Vec::new();
        if !parent.is_dir() {
            if let Some(file) = parent.ancestors().find(|p| p.is_file()) {
                return Err(refused(
                    target,
                    format!("{} is a file, not a folder", file.display()),
                ));
            }
            // Each missing level made here, outermost first; only the
            // ones this call made are recorded (a level that turns out
            // to exist, such as `a/..`, or that another process made
            // meanwhile, is not), deepest first.
            let missing: Vec<&Path> = parent
                .ancestors()
                .take_while(|p| !p.as_os_str().is_empty() && !p.is_dir())
                .collect();
            for dir in missing.into_iter().rev() {
                match std::fs::create_dir(dir) {
                    Ok(()) => made.insert(0, dir.to_path_buf()),
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && dir.is_dir() => {}
                    Err(e) => {
                        remove_empty(&made);
                        return Err(io(dir, e));
                    }
                }
            }
        }
        let name = target
            .file_name()
            .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
        let prefix = format!(".{name}.");
        let fresh = match tempfile::Builder::new()
            .prefix(&prefix)
            .suffix(".tmp")
            .tempdir_in(parent)
        {
            Ok(f) => f,
            Err(e) => {
                remove_empty(&made);
                return Err(io(target, e));
            }
        };
        let guard = crate::cleanup::TempGuard::new(fresh.path());
        Ok(OutputDir {
            target: target.to_path_buf(),
            fresh: Some(fresh),
            made,
            _guard: guard,
        })
    }

    /// The folder to write the set into now.
    #[must_use]
    pub fn path(&self) -> &Path {
        self.fresh.as_ref().map_or(&self.target, |f| f.path())
    }

    /// Names the target, not the fresh folder, in an error met while
    /// writing the set: `d/a.png` rather than `./.d.3qV5Nd.tmp/a.png`.
    #[must_use]
    pub fn relabel(&self, e: ImageIoError) -> ImageIoError {
        let Some(fresh) = self.fresh.as_ref().map(tempfile::TempDir::path) else {
            return e;
        };
        let rename = |path: PathBuf| match path.strip_prefix(fresh) {
            Ok(rest) => self.target.join(rest),
            Err(_) => path,
        };
        match e {
            ImageIoError::Io { path, source } => ImageIoError::Io {
                path: rename(path),
                source,
            },
            ImageIoError::Png { path, message } => ImageIoError::Png {
                path: rename(path),
                message,
            },
            ImageIoError::Refused { path, message } => ImageIoError::Refused {
                path: rename(path),
                message,
            },
        }
    }

    /// Swaps the written set in as the target folder (what was there is
    /// removed after the swap).
    ///
    /// # Errors
    ///
    /// The I/O error; the target then holds its old set.
    pub fn commit(mut self) -> Result<(), ImageIoError> {
        let swapped = self.swap_in();
        if swapped.is_ok() {
            // The folders made for it now hold the set.
            self.made.clear();
        }
        swapped
    }

    /// [`OutputDir::commit`]'s swap.
    fn swap_in(&mut self) -> Result<(), ImageIoError> {
        let Some(fresh) = self.fresh.take() else {
            return Ok(());
        };
        let marker = fresh.path().join(MARKER);
        crate::image_io::write_atomic(&marker, |f| {
            f.write_all(b"written by rendiff: this folder is replaced as a whole by the next run\n")
        })?;
        let from = fresh.keep();
        let target = &self.target;
        match std::fs::rename(&from, target) {
            Ok(()) => return Ok(()),
            Err(e)
                if !matches!(
                    rustix::io::Errno::from_io_error(&e),
                    Some(rustix::io::Errno::NOTEMPTY | rustix::io::Errno::EXIST)
                ) =>
            {
                let _ = std::fs::remove_dir_all(&from);
                return Err(io(target, e));
            }
            Err(_) => {}
        }
        // The target holds a set: exchange the two at once.
        let exchanged = rustix::fs::renameat_with(
            rustix::fs::CWD,
            &from,
            rustix::fs::CWD,
            target,
            rustix::fs::RenameFlags::EXCHANGE,
        );
        match exchanged {
            Ok(()) => {
                // `from` now holds the old set.
                let _ = std::fs::remove_dir_all(&from);
                Ok(())
            }
            Err(_) => {
                // No exchange on this file system: set the old one aside
                // (a moment without the folder, never a mixed one).
                let aside = from.with_extension("old");
                let moved =
                    std::fs::rename(target, &aside).and_then(|()| std::fs::rename(&from, target));
                match moved {
                    Ok(()) => {
                        let _ = std::fs::remove_dir_all(&aside);
                        Ok(())
                    }
                    Err(e) => {
                        if aside.exists() && !target.exists() {
                            let _ = std::fs::rename(&aside, target);
                        }
                        let _ = std::fs::remove_dir_all(&from);
                        Err(io(target, e))
                    }
                }
            }
        }
    }
}

/// A folder name for each scene: its path relative to the scenes' common
/// folder, without `.toml`, every component sanitised (only letters,
/// digits, `-`, `_` and `.`; a leading dot, `.` and `..` made harmless)
/// and joined by `__`; a name already taken gets `-2`, `-3`…. The names
/// never leave the output folder and never collide.
#[must_use]
pub fn scene_folders(scenes: &[PathBuf]) -> Vec<String> {
    let absolute: Vec<PathBuf> = scenes
        .iter()
        .map(|p| std::fs::canonicalize(p).unwrap_or_else(|_| p.clone()))
        .collect();
    let parents: Vec<&Path> = absolute
        .iter()
        .map(|p| p.parent().unwrap_or(Path::new("")))
        .collect();
    let common = parents.iter().skip(1).fold(
        parents.first().map(|p| p.to_path_buf()).unwrap_or_default(),
        |acc, p| {
            acc.components()
                .zip(p.components())
                .take_while(|(a, b)| a == b)
                .map(|(a, _)| a)
                .collect()
        },
    );
    let mut taken: Vec<String> = Vec::new();
    absolute
        .iter()
        .map(|p| {
            let rel = p.strip_prefix(&common).unwrap_or(p);
            let parts: Vec<String> = rel
                .components()
                .filter_map(|c| match c {
                    Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
                    _ => None,
                })
                .collect();
            let n = parts.len();
            let mut name = parts
                .iter()
                .enumerate()
                .map(|(k, s)| {
                    let s = if k + 1 == n {
                        s.strip_suffix(".toml").unwrap_or(s).to_string()
                    } else {
                        s.clone()
                    };
                    sanitise(&s)
                })
                .collect::<Vec<_>>()
                .join("__");
            if name.is_empty() {
                name = "scene".into();
            }
            let base = name.clone();
            let mut k = 2;
            while taken.contains(&name) {
                name = format!("{base}-{k}");
                k += 1;
            }
            taken.push(name.clone());
            name
        })
        .collect()
}

/// A path component as a safe folder name.
fn sanitise(s: &str) -> String {
    let mut out: String = s
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    if out.is_empty() || out.starts_with('.') {
        out.insert(0, '_');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The folders `begin` makes for a new target's path are gone again
    /// when the set is not committed (a run that fails writes nothing),
    /// stay when it is, and a folder that was there is never removed, nor
    /// one that something else wrote into meanwhile.
    #[test]
    fn an_uncommitted_set_leaves_no_folders_behind() {
        let write = |p: &Path| {
            crate::image_io::write_atomic(p, |f| std::io::Write::write_all(f, b"x")).unwrap();
        };
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("a/b/c/out");
        let set = OutputDir::begin(&target, &[]).unwrap();
        write(&set.path().join("x.png"));
        assert!(root.path().join("a/b/c").is_dir());
        drop(set);
        assert!(!root.path().join("a").exists(), "the made folders are gone");
        assert!(root.path().is_dir(), "the folder that was there stays");

        let set = OutputDir::begin(&target, &[]).unwrap();
        write(&set.path().join("x.png"));
        set.commit().unwrap();
        assert!(target.join("x.png").is_file() && target.join(MARKER).is_file());

        // A path through `..` names a folder that was there: it stays,
        // and the folders made on the way are gone.
        let existing = root.path().join("existing");
        std::fs::create_dir(&existing).unwrap();
        let set = OutputDir::begin(&root.path().join("new/../existing/x/out"), &[]).unwrap();
        drop(set);
        assert!(
            existing.is_dir(),
            "a folder that was there is never removed"
        );
        assert!(!existing.join("x").exists() && !root.path().join("new").exists());
        // A level that cannot be made (a name too long) fails the call, and
        // the levels made before it are gone.
        let long = "n".repeat(300);
        let e = OutputDir::begin(&root.path().join(format!("p/q/{long}/out")), &[]);
        assert!(e.is_err());
        assert!(
            !root.path().join("p").exists(),
            "left behind after a failed begin"
        );

        // Something else writes beside the set: that folder stays.
        let other = root.path().join("d/e/out");
        let set = OutputDir::begin(&other, &[]).unwrap();
        write(&root.path().join("d/theirs.txt"));
        drop(set);
        assert!(!root.path().join("d/e").exists());
        assert!(root.path().join("d/theirs.txt").is_file());
    }

    #[test]
    fn scene_folders_stay_inside_and_apart() {
        let names = scene_folders(&[
            PathBuf::from("/s/a/x.toml"),
            PathBuf::from("/s/b/x.toml"),
            PathBuf::from("/s/a/...toml"),
            PathBuf::from("/s/a/..toml"),
            PathBuf::from("/s/a/x y\u{1b}].toml"),
            PathBuf::from("/s/a/x.toml"),
        ]);
        assert_eq!(
            names,
            ["a__x", "b__x", "a___..", "a___.", "a__x_y__", "a__x-2"]
        );
        for n in &names {
            assert!(!n.contains('/') && !n.starts_with('.') && n != ".." && n != ".");
        }
    }
}
