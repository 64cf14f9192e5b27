//! Snapshot tests for your own crate, in the manner of cargo-insta: a test
//! renders a scene (or hands over its own image), the image is compared
//! with a stored golden beyond both images' rounding, and on a mismatch a
//! pending `NAME.new.png` is written beside the golden for `rendiff review`
//! to accept or reject.
//!
//! ```text
//! // tests/render.rs of your crate, with rendiff as a dev-dependency
//! // (examples/user-crate in this repository is such a crate):
//! #[test]
//! fn ball() {
//!     assert_golden!("scenes/ball.toml"); // the macro at rendiff's root
//! }
//! ```
//!
//! Goldens live under `tests/golden/` of the crate that runs the test
//! (`CARGO_MANIFEST_DIR`), named by the scene's path relative to the
//! crate: `scenes/ball.toml` rendered by the ray tracer is
//! `tests/golden/scenes/ball.ray.png`, so two scenes called `ball.toml` in
//! different folders never share a golden. A missing golden is a failure
//! too (with its pending file), so nothing passes unseen; set
//! `RENDIFF_ACCEPT=1` to write goldens directly instead (the first run of
//! a new suite, or an accepted change everywhere).
//!
//! The rule: a golden of the same renderer is the same frame, so no pixel
//! may differ beyond the PNG's rounding ([`crate::compare::Quantisation`]);
//! [`Snapshot::fuzzy`] states a looser rule of your own, as reftest's
//! `fuzzy(maxDiff, pixelCount)`.

use std::path::{Path, PathBuf};

use crate::color::Rgb;
use crate::compare::Fuzzy;
use crate::diff::{self, Side};
use crate::image_io::{self, PngEncoding};
use crate::{Backend, Error, Overrides, Prepared};

/// The suffix of a pending image: `NAME.new.png` beside `NAME.png`.
pub const PENDING_SUFFIX: &str = ".new.png";

/// Where goldens are kept and how they are judged.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// The folder scene paths are relative to (the crate's root).
    pub root: PathBuf,
    /// The golden folder (`root/tests/golden` by default).
    pub golden_dir: PathBuf,
    /// The user's own rule; `None`: no pixel beyond the images' rounding.
    pub fuzzy: Option<Fuzzy>,
    /// Write goldens instead of pending files (`RENDIFF_ACCEPT=1`).
    pub accept: bool,
}

/// What a snapshot check found, when it did not pass.
#[derive(Debug, thiserror::Error)]
pub enum Mismatch {
    /// No golden yet: the image was written as pending.
    #[error(
        "{name}: no golden yet; the image is pending at {pending}\n  review it with `rendiff review {dir}` (or set RENDIFF_ACCEPT=1 to accept it)",
        pending = .pending.display(), dir = .dir.display()
    )]
    New {
        /// The snapshot's name.
        name: String,
        /// The pending file written.
        pending: PathBuf,
        /// The golden folder.
        dir: PathBuf,
    },
    /// The image differs from its golden beyond the rule.
    #[error(
        "{name}: differs from its golden {golden}\n{summary}  the new image is pending at {pending}\n  review it with `rendiff review {dir}` (or set RENDIFF_ACCEPT=1 to accept it)",
        golden = .golden.display(), pending = .pending.display(), dir = .dir.display()
    )]
    Differs {
        /// The snapshot's name.
        name: String,
        /// The golden.
        golden: PathBuf,
        /// The pending file written.
        pending: PathBuf,
        /// The golden folder.
        dir: PathBuf,
        /// The verdict's summary (where and how much).
        summary: String,
    },
    /// Two backends disagree on a scene.
    #[error("{scene}: {a} and {b} disagree\n{summary}")]
    Disagree {
        /// The scene.
        scene: String,
        /// Side a.
        a: Backend,
        /// Side b.
        b: Backend,
        /// The verdict's summary.
        summary: String,
    },
    /// The check could not run (a bad scene, an unreadable golden).
    #[error(transparent)]
    Error(#[from] Error),
}

impl Snapshot {
    /// The settings for the crate at `root`: goldens in `root/tests/golden`,
    /// the derived rule, `accept` from `RENDIFF_ACCEPT` (`1`, `true` or
    /// `always`).
    #[must_use]
    pub fn for_crate(root: &Path) -> Snapshot {
        let accept = std::env::var("RENDIFF_ACCEPT")
            .is_ok_and(|v| matches!(v.as_str(), "1" | "true" | "always"));
        Snapshot {
            root: root.to_path_buf(),
            golden_dir: root.join("tests").join("golden"),
            fuzzy: None,
            accept,
        }
    }

    /// The same settings with a fuzzy rule of your own.
    #[must_use]
    pub fn fuzzy(mut self, max_diff: u8, pixels: u64) -> Snapshot {
        self.fuzzy = Some(Fuzzy { max_diff, pixels });
        self
    }

    /// The golden of snapshot `name` (`golden_dir/NAME.png`).
    #[must_use]
    pub fn golden_path(&self, name: &str) -> PathBuf {
        self.golden_dir.join(format!("{name}.png"))
    }

    /// The snapshot name of `scene` rendered by `backend`: its path
    /// relative to `root` without `.toml`, then `.BACKEND`.
    #[must_use]
    pub fn scene_name(&self, scene: &Path, backend: Backend) -> String {
        let rel = scene.strip_prefix(&self.root).unwrap_or(scene);
        let stem = rel.with_extension("");
        let parts: Vec<String> = stem
            .components()
            .filter_map(|c| match c {
                std::path::Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
                _ => None,
            })
            .collect();
        format!("{}.{backend}", parts.join("/"))
    }

    /// Renders `scene` (relative to `root`, or absolute) with `backend`
    /// and checks it against its golden.
    ///
    /// # Errors
    ///
    /// [`Mismatch`]: new, different, or the scene could not be rendered.
    pub fn check_scene(&self, scene: &Path, backend: Backend) -> Result<(), Mismatch> {
        let path = self.root.join(scene);
        let job = Prepared::load(&path, &Overrides::default())?;
        let frame = job.render(backend)?.frame;
        let name = self.scene_name(&path, backend);
        self.check_image(&name, frame.width, frame.height, &frame.color)
    }

    /// Checks an image of your own (linear RGB, row-major from the top)
    /// against the golden `name`.
    ///
    /// # Errors
    ///
    /// [`Mismatch`]: new, different, or the golden could not be read or
    /// the pending file written.
    pub fn check_image(
        &self,
        name: &str,
        width: u32,
        height: u32,
        pixels: &[Rgb],
    ) -> Result<(), Mismatch> {
        let golden = self.golden_path(name);
        let pending = self.golden_dir.join(format!("{name}{PENDING_SUFFIX}"));
        let write = |path: &Path| -> Result<(), Mismatch> {
            if let Some(dir) = path.parent() {
                std::fs::create_dir_all(dir).map_err(|source| {
                    Error::Image(image_io::ImageIoError::Io {
                        path: dir.to_path_buf(),
                        source,
                    })
                })?;
            }
            image_io::write_png(path, width, height, pixels, PngEncoding::Srgb8)
                .map_err(Error::from)?;
            Ok(())
        };
        let remove_pending = || {
            // A stale pending file of an earlier failure would be reviewed
            // against a golden it no longer differs from.
            let _ = std::fs::remove_file(&pending);
        };
        if !golden.exists() {
            if self.accept {
                write(&golden)?;
                remove_pending();
                return Ok(());
            }
            write(&pending)?;
            return Err(Mismatch::New {
                name: name.to_string(),
                pending,
                dir: self.golden_dir.clone(),
            });
        }
        // Compare as the stored file would be: the candidate rounded to
        // 8-bit sRGB exactly as a golden is written (and read back).
        let budget = crate::budget::Budget::new(crate::budget::DEFAULT_MEMORY_BUDGET);
        let stored =
            image_io::read_png_linear_within(&golden, None, &budget).map_err(Error::from)?;
        if (stored.width, stored.height) != (width, height) {
            return self.differs(
                name,
                &golden,
                &pending,
                format!(
                    "  the golden is {}x{}, the image {width}x{height}\n",
                    stored.width, stored.height
                ),
                &write,
            );
        }
        let round =
            |v: f32| crate::color::srgb_decode(f32::from(crate::color::to_srgb8(v)) / 255.0);
        let candidate = image_io::LinearImage {
            width,
            height,
            pixels: pixels
                .iter()
                .map(|c| Rgb::new(round(c.r), round(c.g), round(c.b)))
                .collect(),
            linear16: false,
        };
        let r = diff::diff_image_data(
            (&golden.display().to_string(), stored),
            (name, candidate),
            self.fuzzy,
        );
        if r.report.passed() {
            remove_pending();
            return Ok(());
        }
        self.differs(name, &golden, &pending, r.report.summary(), &write)
    }

    /// Writes the pending image (or, accepting, the golden) for a
    /// mismatch.
    fn differs(
        &self,
        name: &str,
        golden: &Path,
        pending: &Path,
        summary: String,
        write: &dyn Fn(&Path) -> Result<(), Mismatch>,
    ) -> Result<(), Mismatch> {
        if self.accept {
            write(golden)?;
            let _ = std::fs::remove_file(pending);
            return Ok(());
        }
        write(pending)?;
        Err(Mismatch::Differs {
            name: name.to_string(),
            golden: golden.to_path_buf(),
            pending: pending.to_path_buf(),
            dir: self.golden_dir.clone(),
            summary,
        })
    }

    /// Renders `scene` with both backends and checks the verdict.
    ///
    /// # Errors
    ///
    /// [`Mismatch::Disagree`] with the verdict's summary, or the scene's
    /// error.
    pub fn check_agree(&self, scene: &Path, a: Backend, b: Backend) -> Result<(), Mismatch> {
        let path = self.root.join(scene);
        let job = Prepared::load(&path, &Overrides::default())?;
        let label = scene.display().to_string();
        let r = diff::diff(&job, &label, &Side::Backend(a), &Side::Backend(b))?;
        if r.report.passed() {
            Ok(())
        } else {
            Err(Mismatch::Disagree {
                scene: label,
                a,
                b,
                summary: r.report.summary(),
            })
        }
    }
}

/// A pending image found by [`pending`]: the file and its golden.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pending {
    /// `NAME.new.png`.
    pub pending: PathBuf,
    /// `NAME.png` (it may not exist yet).
    pub golden: PathBuf,
}

impl Pending {
    /// Accepts it: the pending image becomes the golden (a rename, atomic
    /// on one file system).
    ///
    /// # Errors
    ///
    /// [`Error::Image`] when the rename fails.
    pub fn accept(&self) -> Result<(), Error> {
        std::fs::rename(&self.pending, &self.golden).map_err(|source| {
            Error::Image(image_io::ImageIoError::Io {
                path: self.golden.clone(),
                source,
            })
        })
    }

    /// Rejects it: the pending image is removed, the golden kept.
    ///
    /// # Errors
    ///
    /// [`Error::Image`] when the removal fails.
    pub fn reject(&self) -> Result<(), Error> {
        std::fs::remove_file(&self.pending).map_err(|source| {
            Error::Image(image_io::ImageIoError::Io {
                path: self.pending.clone(),
                source,
            })
        })
    }
}

/// Every pending image under `dir` (recursively, in path order; links are
/// not followed).
///
/// # Errors
///
/// [`Error::Image`] when `dir` cannot be read.
pub fn pending(dir: &Path) -> Result<Vec<Pending>, Error> {
    fn walk(dir: &Path, out: &mut Vec<Pending>) -> Result<(), Error> {
        let io = |source| {
            Error::Image(image_io::ImageIoError::Io {
                path: dir.to_path_buf(),
                source,
            })
        };
        let mut entries: Vec<_> = std::fs::read_dir(dir)
            .map_err(io)?
            .collect::<Result<_, _>>()
            .map_err(io)?;
        entries.sort_by_key(std::fs::DirEntry::path);
        for e in entries {
            let path = e.path();
            let kind = e.file_type().map_err(io)?;
            if kind.is_dir() {
                walk(&path, out)?;
            } else if kind.is_file() {
                let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
                if let Some(stem) = name.as_deref().and_then(|n| n.strip_suffix(PENDING_SUFFIX)) {
                    out.push(Pending {
                        golden: path.with_file_name(format!("{stem}.png")),
                        pending: path,
                    });
                }
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, &mut out)?;
    Ok(out)
}

/// What the `assert_golden!` macro runs: the check for the
/// crate at `root`, panicking with the mismatch.
///
/// # Panics
///
/// When the image does not match its golden (or the scene fails to load).
#[track_caller]
pub fn golden_or_panic(root: &str, scene: &str, backend: Backend) {
    if let Err(e) = Snapshot::for_crate(Path::new(root)).check_scene(Path::new(scene), backend) {
        panic!("{e}");
    }
}

/// What the `assert_image!` macro runs.
///
/// # Panics
///
/// When the image does not match its golden.
#[track_caller]
pub fn image_or_panic(root: &str, name: &str, width: u32, height: u32, pixels: &[Rgb]) {
    if let Err(e) = Snapshot::for_crate(Path::new(root)).check_image(name, width, height, pixels) {
        panic!("{e}");
    }
}

/// What the `assert_agree!` macro runs.
///
/// # Panics
///
/// When the backends disagree (or the scene fails to load).
#[track_caller]
pub fn agree_or_panic(root: &str, scene: &str, a: Backend, b: Backend) {
    if let Err(e) = Snapshot::for_crate(Path::new(root)).check_agree(Path::new(scene), a, b) {
        panic!("{e}");
    }
}

/// Checks a scene's image against its golden, in a test of your crate:
/// `assert_golden!("scenes/ball.toml")` (the ray tracer) or
/// `assert_golden!("scenes/ball.toml", Backend::Raster)`. Panics with the
/// verdict and the pending file's path when it does not match.
#[macro_export]
macro_rules! assert_golden {
    ($scene:expr) => {
        $crate::snapshot::golden_or_panic(env!("CARGO_MANIFEST_DIR"), $scene, $crate::Backend::Ray)
    };
    ($scene:expr, $backend:expr) => {
        $crate::snapshot::golden_or_panic(env!("CARGO_MANIFEST_DIR"), $scene, $backend)
    };
}

/// Checks an image of your own against its golden:
/// `assert_image!("name", width, height, &pixels)` with linear [`Rgb`]
/// pixels. Panics with the verdict and the pending file's path.
#[macro_export]
macro_rules! assert_image {
    ($name:expr, $width:expr, $height:expr, $pixels:expr) => {
        $crate::snapshot::image_or_panic(
            env!("CARGO_MANIFEST_DIR"),
            $name,
            $width,
            $height,
            $pixels,
        )
    };
}

/// Checks that two backends agree on a scene (the full verdict):
/// `assert_agree!("scenes/ball.toml")` (raster against ray) or with two
/// [`Backend`]s. Panics with the verdict's summary.
#[macro_export]
macro_rules! assert_agree {
    ($scene:expr) => {
        $crate::snapshot::agree_or_panic(
            env!("CARGO_MANIFEST_DIR"),
            $scene,
            $crate::Backend::Raster,
            $crate::Backend::Ray,
        )
    };
    ($scene:expr, $a:expr, $b:expr) => {
        $crate::snapshot::agree_or_panic(env!("CARGO_MANIFEST_DIR"), $scene, $a, $b)
    };
}
