//! POV-Ray references (DESIGN.md §9): render them with the exact command
//! line of POVRAY.md §1, store them with the hashes that make staleness
//! detectable without POV-Ray, and check that the stored ones are still
//! what POV-Ray produces.
//!
//! Per scene `NAME`, in the golden folder (`golden/pov`):
//! * `NAME.png` — the scene as written (its `max_depth`), mesh geometry;
//! * `NAME.d1.png` — the same at `max_depth = 1`, for scenes whose
//!   materials reflect or transmit (what the rasterizer is compared with);
//! * `NAME.analytic.png` — spheres, boxes and superellipsoids as POV-Ray
//!   primitives, for scenes that have them (the tessellation error);
//! * `NAME.toml` — POV-Ray's version, the command lines, the hash of each
//!   exported `.pov` and of every image it reads.
//!
//! All PNGs are 16-bit linear (gAMA 1.0), at the scene's size: a scene with
//! n×n samples is rendered at n·W × n·H without antialiasing and averaged
//! over n×n blocks, which puts POV-Ray's rays on the same sample points;
//! each sample is clamped to [0, 1] before the mean (the PNG cannot store
//! more), exactly as `Frame::resolve` does.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::{Export, ExportOptions, export, fnv1a};
use crate::color::Rgb;
use crate::image_io::{self, LinearImage, PngEncoding};
use crate::options::Geometry;
use crate::scene::{Scene, Shape};
use crate::tri_scene::TriScene;

/// The POV-Ray executable.
pub const POVRAY: &str = "povray";

/// Why a golden operation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GoldenError {
    /// POV-Ray is not installed.
    #[error(
        "POV-Ray is not installed (no `povray` on PATH); install Debian's package with `sudo apt-get install -y povray` (POV-Ray 3.7)"
    )]
    NoPovray,
    /// POV-Ray failed on a scene.
    #[error("POV-Ray failed on {scene}: {message}")]
    Povray {
        /// The scene.
        scene: String,
        /// Its message.
        message: String,
    },
    /// A file could not be written or read.
    #[error(transparent)]
    Image(#[from] image_io::ImageIoError),
    /// The scene cannot be written as SDL.
    #[error(transparent)]
    Export(#[from] super::ExportError),
    /// The metadata file is malformed.
    #[error("{}: {message}", .path.display())]
    Metadata {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
}

/// The POV-Ray command line of POVRAY.md §1 (16-bit linear PNG, no
/// antialiasing, no display, one thread).
#[must_use]
pub(crate) fn command_line(pov: &str, png: &str, (w, h): (u32, u32)) -> String {
    format!("povray +I{pov} +O{png} +W{w} +H{h} -D -A +FN16 File_Gamma=1.0 +Q9 -GA -V +WT1")
}

/// Which reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Variant {
    /// The scene as written.
    Main,
    /// At `max_depth = 1`.
    Depth1,
    /// Analytic primitives.
    Analytic,
}

impl Variant {
    /// The file-name suffix.
    #[must_use]
    pub fn suffix(self) -> &'static str {
        match self {
            Variant::Main => "",
            Variant::Depth1 => ".d1",
            Variant::Analytic => ".analytic",
        }
    }

    /// The name used in the metadata.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Variant::Main => "mesh",
            Variant::Depth1 => "mesh, max_depth 1",
            Variant::Analytic => "analytic",
        }
    }
}

/// One reference of a scene: its export and what it depends on.
#[derive(Clone, Debug)]
pub struct Reference {
    /// Which.
    pub variant: Variant,
    /// Its `max_depth`.
    pub max_depth: u32,
    /// The SDL.
    pub export: Export,
    /// FNV-1a of the SDL text.
    pub pov_hash: u64,
    /// (name, FNV-1a) of every image it reads.
    pub image_hashes: Vec<(String, u64)>,
}

/// `true` when some material of the scene reflects or transmits (and
/// `max_depth` > 1): the scene then has a `NAME.d1.png` reference.
#[must_use]
pub fn has_ray_tree(tri: &TriScene) -> bool {
    tri.max_depth > 1
        && (0..tri.objects.len()).any(|o| {
            tri.object_materials(o)
                .iter()
                .any(|&m| tri.materials[usize::from(m)].spawns_rays())
        })
}

/// The references a scene has, exported.
///
/// # Errors
///
/// [`GoldenError::Image`] when an image the scene reads cannot be read.
pub fn references(scene: &Scene, tri: &TriScene) -> Result<Vec<Reference>, GoldenError> {
    let mut variants = vec![(Variant::Main, tri.max_depth, Geometry::Mesh)];
    if has_ray_tree(tri) {
        variants.push((Variant::Depth1, 1, Geometry::Mesh));
    }
    if scene.objects.iter().any(|o| {
        matches!(
            o.shape,
            Shape::Sphere { .. } | Shape::Box { .. } | Shape::Superellipsoid { .. }
        )
    }) {
        variants.push((Variant::Analytic, tri.max_depth, Geometry::Analytic));
    }
    variants
        .into_iter()
        .map(|(variant, max_depth, geometry)| {
            let e = export(
                scene,
                tri,
                &ExportOptions {
                    geometry,
                    max_depth,
                    abridged: false,
                },
            )?;
            let mut image_hashes = Vec::new();
            for img in &e.images {
                let bytes = crate::input::read_file(&img.source).map_err(|source| {
                    image_io::ImageIoError::Io {
                        path: img.source.clone(),
                        source,
                    }
                })?;
                image_hashes.push((img.name.clone(), fnv1a(&bytes)));
            }
            Ok(Reference {
                variant,
                max_depth,
                pov_hash: fnv1a(e.text.as_bytes()),
                export: e,
                image_hashes,
            })
        })
        .collect()
}

/// POV-Ray's version line, or [`GoldenError::NoPovray`].
///
/// # Errors
///
/// [`GoldenError::NoPovray`] when `povray` cannot be run.
pub fn povray_version() -> Result<String, GoldenError> {
    let out = Command::new(POVRAY)
        .arg("--version")
        .output()
        .map_err(|_| GoldenError::NoPovray)?;
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    text.lines()
        .find(|l| l.starts_with("POV-Ray "))
        .map(|l| l.trim().to_string())
        .ok_or(GoldenError::NoPovray)
}

/// The name of the scene's folder inside a render's scratch folder: a
/// link to it, POV-Ray's library path, so the image names of the SDL
/// (relative to the scene's folder) resolve without the folder's own path
/// ever reaching POV-Ray's option parser.
const SCENE_LINK: &str = "rendiff-scene-dir";

/// Renders a reference with POV-Ray and returns it averaged to the
/// scene's size.
///
/// POV-Ray runs in a fresh scratch folder (removed afterwards, and on
/// SIGINT/SIGTERM through [`crate::cleanup`], which also stops POV-Ray)
/// with an argument vector of fixed, simple names: `+Irendiff.pov
/// +Orendiff.png +Lrendiff-scene-dir`, where `rendiff-scene-dir` is a
/// link to the scene's folder. No path of the user's reaches POV-Ray's
/// command line, whose option parser splits values at spaces.
///
/// # Errors
///
/// [`GoldenError`] if POV-Ray is missing or fails, or files cannot be written.
pub fn render(scene: &Scene, r: &Reference) -> Result<LinearImage, GoldenError> {
    let io = |path: &Path, source| image_io::ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let work = tempfile::Builder::new()
        .prefix("rendiff-pov-")
        .tempdir()
        .map_err(|e| io(&std::env::temp_dir(), e))?;
    let _guard = crate::cleanup::TempGuard::new(work.path());
    let dir = work.path();
    let pov = dir.join("rendiff.pov");
    let png = dir.join("rendiff.png");
    image_io::write_atomic(&pov, |f| {
        std::io::Write::write_all(f, r.export.text.as_bytes())
    })?;
    for img in &r.export.images {
        img.materialise(dir)?;
    }
    let scene_dir = scene
        .path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let scene_dir = std::fs::canonicalize(scene_dir).map_err(|e| io(scene_dir, e))?;
    std::os::unix::fs::symlink(&scene_dir, dir.join(SCENE_LINK))
        .map_err(|e| io(&dir.join(SCENE_LINK), e))?;
    let (w, h) = r.export.render_size;
    let child = Command::new(POVRAY)
        .current_dir(dir)
        .args(["+Irendiff.pov", "+Orendiff.png"])
        .arg(format!("+W{w}"))
        .arg(format!("+H{h}"))
        .args([
            "-D",
            "-A",
            "+FN16",
            "File_Gamma=1.0",
            "+Q9",
            "-GA",
            "-V",
            "+WT1",
        ])
        .arg(format!("+L{SCENE_LINK}"))
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|_| GoldenError::NoPovray)?;
    let child_guard = crate::cleanup::ChildGuard::new(child.id());
    let out = child.wait_with_output().map_err(|e| io(&pov, e))?;
    drop(child_guard);
    if !out.status.success() || !png.exists() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err
            .lines()
            .filter(|l| !l.trim().is_empty())
            .rev()
            .take(6)
            .collect();
        return Err(GoldenError::Povray {
            scene: scene.path.display().to_string(),
            message: tail.into_iter().rev().collect::<Vec<_>>().join(" / "),
        });
    }
    let img =
        image_io::read_png_linear_within(&png, Some((w, h)), &crate::budget::Budget::default())?;
    Ok(average_blocks(&img, r.export.samples))
}

/// Averages n×n blocks (the n×n samples of each pixel).
#[must_use]
pub(crate) fn average_blocks(img: &LinearImage, n: u32) -> LinearImage {
    if n <= 1 {
        return img.clone();
    }
    let (w, h) = (img.width / n, img.height / n);
    #[expect(clippy::cast_precision_loss, reason = "n² ≤ 256")]
    let inv = 1.0 / (n * n) as f32;
    let mut pixels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let mut acc = Rgb::BLACK;
            for b in 0..n {
                for a in 0..n {
                    acc += img.pixels[((y * n + b) * img.width + x * n + a) as usize];
                }
            }
            pixels.push(acc * inv);
        }
    }
    LinearImage {
        width: w,
        height: h,
        pixels,
        linear16: true,
    }
}

/// The path of a stored reference.
#[must_use]
pub fn reference_path(golden_dir: &Path, scene: &Scene, variant: Variant) -> PathBuf {
    golden_dir.join(format!("{}{}.png", scene.name(), variant.suffix()))
}

/// The metadata path of a scene's references.
#[must_use]
pub fn metadata_path(golden_dir: &Path, scene: &Scene) -> PathBuf {
    golden_dir.join(format!("{}.toml", scene.name()))
}

/// The metadata text of a scene's references, written by the `toml`
/// serializer (which escapes every string; the scene's name reaches the
/// comment line only through [`crate::escape::sdl_comment`]'s printable
/// ASCII).
#[must_use]
pub fn metadata(scene: &Scene, version: &str, refs: &[Reference]) -> String {
    use toml::{Table, Value};
    let name = scene.name();
    let mut root = Table::new();
    root.insert("povray".into(), Value::String(version.to_string()));
    root.insert("scene".into(), Value::String(format!("{name}.toml")));
    let entries: Vec<Value> = refs
        .iter()
        .map(|r| {
            let mut t = Table::new();
            let file = format!("{name}{}.png", r.variant.suffix());
            t.insert("file".into(), Value::String(file));
            t.insert("variant".into(), Value::String(r.variant.name().into()));
            t.insert("max_depth".into(), Value::Integer(i64::from(r.max_depth)));
            t.insert(
                "samples".into(),
                Value::Integer(i64::from(r.export.samples)),
            );
            t.insert(
                "render_size".into(),
                Value::Array(vec![
                    Value::Integer(i64::from(r.export.render_size.0)),
                    Value::Integer(i64::from(r.export.render_size.1)),
                ]),
            );
            t.insert(
                "command".into(),
                Value::String(command_line(
                    &format!("{name}{}.pov", r.variant.suffix()),
                    "out.png",
                    r.export.render_size,
                )),
            );
            t.insert(
                "pov_fnv1a".into(),
                Value::String(format!("{:016x}", r.pov_hash)),
            );
            let images = r
                .image_hashes
                .iter()
                .map(|(n, h)| {
                    let mut i = Table::new();
                    i.insert("file".into(), Value::String(n.clone()));
                    i.insert("fnv1a".into(), Value::String(format!("{h:016x}")));
                    Value::Table(i)
                })
                .collect();
            t.insert("images".into(), Value::Array(images));
            Value::Table(t)
        })
        .collect();
    root.insert("reference".into(), Value::Array(entries));
    format!(
        "# POV-Ray references of {}.toml, written by `rendiff golden --update`.\n# A reference whose hashes no longer match its scene's export is stale.\n{}",
        crate::escape::sdl_comment(&name),
        toml::to_string(&root).unwrap_or_default()
    )
}

/// Problems of a scene's stored references that need no POV-Ray to see:
/// missing files, and hashes that no longer match the scene (stale).
///
/// # Errors
///
/// [`GoldenError`] when an image of the scene cannot be read or the
/// metadata file is malformed.
pub fn stale(scene: &Scene, tri: &TriScene, golden_dir: &Path) -> Result<Vec<String>, GoldenError> {
    let refs = references(scene, tri)?;
    let meta_path = metadata_path(golden_dir, scene);
    let Ok(text) = std::fs::read_to_string(&meta_path) else {
        return Ok(vec![format!(
            "{}: missing (render it with `rendiff golden --update`)",
            meta_path.display()
        )]);
    };
    let meta: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| GoldenError::Metadata {
            path: meta_path.clone(),
            message: e.message().to_string(),
        })?;
    let stored = meta
        .get("reference")
        .and_then(toml::Value::as_array)
        .cloned()
        .unwrap_or_default();
    let mut problems = Vec::new();
    for r in &refs {
        let file = format!("{}{}.png", scene.name(), r.variant.suffix());
        if !golden_dir.join(&file).exists() {
            problems.push(format!("{}: missing", golden_dir.join(&file).display()));
            continue;
        }
        let Some(entry) = stored
            .iter()
            .find(|e| e.get("file").and_then(toml::Value::as_str) == Some(&file))
        else {
            problems.push(format!("{}: no entry for {file}", meta_path.display()));
            continue;
        };
        let want = format!("{:016x}", r.pov_hash);
        if entry.get("pov_fnv1a").and_then(toml::Value::as_str) != Some(&want) {
            problems.push(format!(
                "{file}: stale: the scene now exports a different .pov (fnv1a {want})"
            ));
        }
        let images = entry
            .get("images")
            .and_then(toml::Value::as_array)
            .cloned()
            .unwrap_or_default();
        for (n, h) in &r.image_hashes {
            let want = format!("{h:016x}");
            let ok = images.iter().any(|i| {
                i.get("file").and_then(toml::Value::as_str) == Some(n)
                    && i.get("fnv1a").and_then(toml::Value::as_str) == Some(&want)
            });
            if !ok {
                problems.push(format!("{file}: stale: image {n} changed or is new"));
            }
        }
        if images.len() != r.image_hashes.len() {
            problems.push(format!(
                "{file}: stale: the scene reads other images than when it was rendered"
            ));
        }
    }
    if let Some(extra) = stored.iter().find_map(|e| {
        let f = e.get("file").and_then(toml::Value::as_str)?;
        (!refs
            .iter()
            .any(|r| format!("{}{}.png", scene.name(), r.variant.suffix()) == f))
        .then(|| f.to_string())
    }) {
        problems.push(format!(
            "{}: stale: lists {extra}, which the scene no longer needs",
            meta_path.display()
        ));
    }
    Ok(problems)
}

/// Renders every reference of a scene and returns them with their final
/// paths (nothing in the golden folder is touched).
///
/// # Errors
///
/// [`GoldenError`].
pub fn render_all(
    scene: &Scene,
    tri: &TriScene,
    golden_dir: &Path,
) -> Result<Vec<(Reference, LinearImage, PathBuf)>, GoldenError> {
    references(scene, tri)?
        .into_iter()
        .map(|r| {
            let img = render(scene, &r)?;
            let path = reference_path(golden_dir, scene, r.variant);
            Ok((r, img, path))
        })
        .collect()
}

/// The lock file of a golden folder: updates hold it exclusively, readers
/// shared, so a reader never sees a set half swapped in and two updates
/// never interleave.
pub const LOCK_FILE: &str = ".rendiff-golden.lock";

/// The journal of a commit in progress: which staged file becomes which
/// reference, and where each old file is set aside. While it exists the
/// commit is incomplete; the next run that takes the lock finishes it
/// (forward) or undoes it (rollback), as the journal says.
pub const JOURNAL_FILE: &str = ".rendiff-golden.journal";

/// The prefix of staged and set-aside files in a golden folder.
const STAGED_PREFIX: &str = ".rendiff-staged.";

/// A held lock on a golden folder (released on drop).
#[derive(Debug)]
pub struct GoldenLock {
    _file: Option<std::fs::File>,
}

impl GoldenLock {
    /// Takes the folder's lock exclusively (waiting for other holders),
    /// creating the folder if needed, and completes or undoes a commit an
    /// earlier run left incomplete (killed part way).
    ///
    /// # Errors
    ///
    /// [`GoldenError::Image`] when the folder or its lock cannot be
    /// created, or the recovery fails.
    pub fn exclusive(golden_dir: &Path) -> Result<GoldenLock, GoldenError> {
        std::fs::create_dir_all(golden_dir).map_err(|e| io_err(golden_dir, e))?;
        let file = open_lock(golden_dir).map_err(|e| io_err(&golden_dir.join(LOCK_FILE), e))?;
        file.lock()
            .map_err(|e| io_err(&golden_dir.join(LOCK_FILE), e))?;
        recover(golden_dir)?;
        Ok(GoldenLock { _file: Some(file) })
    }

    /// Takes the folder's lock shared, for reading its references. A
    /// folder that does not exist or cannot be written (a read-only
    /// checkout) is read without a lock: no update can be under way there.
    /// An incomplete commit is completed first (under the exclusive lock).
    ///
    /// # Errors
    ///
    /// [`GoldenError::Image`] when the lock cannot be taken, or an
    /// incomplete commit is found in a folder rendiff cannot write.
    pub fn shared(golden_dir: &Path) -> Result<GoldenLock, GoldenError> {
        if !golden_dir.is_dir() {
            return Ok(GoldenLock { _file: None });
        }
        let Ok(file) = open_lock(golden_dir) else {
            if golden_dir.join(JOURNAL_FILE).exists() {
                return Err(GoldenError::Metadata {
                    path: golden_dir.join(JOURNAL_FILE),
                    message: "an interrupted `golden --update` left this commit incomplete, and the folder cannot be written to complete it; run `rendiff golden --update` where it can".into(),
                });
            }
            return Ok(GoldenLock { _file: None });
        };
        file.lock_shared()
            .map_err(|e| io_err(&golden_dir.join(LOCK_FILE), e))?;
        if golden_dir.join(JOURNAL_FILE).exists() {
            drop(file);
            drop(GoldenLock::exclusive(golden_dir)?);
            return GoldenLock::shared(golden_dir);
        }
        Ok(GoldenLock { _file: Some(file) })
    }
}

fn open_lock(golden_dir: &Path) -> std::io::Result<std::fs::File> {
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(golden_dir.join(LOCK_FILE))
}

fn io_err(path: &Path, source: std::io::Error) -> GoldenError {
    image_io::ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    }
    .into()
}

/// One file of a commit (names relative to the golden folder).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct Entry {
    /// The complete new file.
    staged: String,
    /// The reference it becomes.
    target: String,
    /// Where the old reference is set aside (`None`: there was none).
    aside: Option<String>,
}

/// What the journal says to do with an incomplete commit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
enum Direction {
    /// Every staged file was complete: finish the commit.
    Forward,
    /// The commit failed: put the old files back.
    Rollback,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct Journal {
    direction: Direction,
    entries: Vec<Entry>,
}

fn write_journal(golden_dir: &Path, j: &Journal) -> Result<(), GoldenError> {
    let text = serde_json::to_string_pretty(j).map_err(|e| GoldenError::Metadata {
        path: golden_dir.join(JOURNAL_FILE),
        message: e.to_string(),
    })?;
    image_io::write_atomic(&golden_dir.join(JOURNAL_FILE), |f| {
        std::io::Write::write_all(f, text.as_bytes())
    })?;
    Ok(())
}

/// A name the journal gives must be a plain file name in the folder (the
/// journal is read back from disk: it may not point elsewhere).
fn plain(golden_dir: &Path, name: &str) -> Result<PathBuf, GoldenError> {
    let p = Path::new(name);
    let ok = p.components().count() == 1
        && matches!(p.components().next(), Some(std::path::Component::Normal(_)));
    if ok {
        Ok(golden_dir.join(p))
    } else {
        Err(GoldenError::Metadata {
            path: golden_dir.join(JOURNAL_FILE),
            message: format!(
                "names {}, which is not a file of this folder",
                crate::escape::message(name)
            ),
        })
    }
}

/// Completes or undoes an incomplete commit (the caller holds the
/// exclusive lock), then removes staged files no journal names (a run
/// killed while staging). Every step is idempotent, so a recovery killed
/// part way is finished by the next one.
fn recover(golden_dir: &Path) -> Result<(), GoldenError> {
    let journal = golden_dir.join(JOURNAL_FILE);
    if journal.exists() {
        let text = crate::input::read_file(&journal).map_err(|e| io_err(&journal, e))?;
        let j: Journal = serde_json::from_slice(&text).map_err(|e| GoldenError::Metadata {
            path: journal.clone(),
            message: format!(
                "unreadable commit journal ({e}); remove it and run `rendiff golden --update`"
            ),
        })?;
        apply(golden_dir, &j)?;
        std::fs::remove_file(&journal).map_err(|e| io_err(&journal, e))?;
    }
    let entries = std::fs::read_dir(golden_dir).map_err(|e| io_err(golden_dir, e))?;
    for e in entries.filter_map(Result::ok) {
        let name = e.file_name().to_string_lossy().into_owned();
        // Staged files, and the atomic writer's temporary of the journal.
        if name.starts_with(STAGED_PREFIX)
            || (name.starts_with(&format!(".{JOURNAL_FILE}.")) && name.ends_with(".tmp"))
        {
            let _ = std::fs::remove_file(e.path());
        }
    }
    Ok(())
}

/// Carries a journal out (see [`recover`]).
fn apply(golden_dir: &Path, j: &Journal) -> Result<(), GoldenError> {
    let exists = |p: &Path| std::fs::symlink_metadata(p).is_ok();
    let rename = |a: &Path, b: &Path| std::fs::rename(a, b).map_err(|e| io_err(b, e));
    for e in &j.entries {
        let staged = plain(golden_dir, &e.staged)?;
        let target = plain(golden_dir, &e.target)?;
        let aside = e
            .aside
            .as_deref()
            .map(|a| plain(golden_dir, a))
            .transpose()?;
        match j.direction {
            Direction::Forward => {
                if exists(&staged) {
                    rename(&staged, &target)?;
                }
                if let Some(a) = &aside {
                    let _ = std::fs::remove_file(a);
                }
            }
            Direction::Rollback => {
                let placed = !exists(&staged);
                let old_aside = !exists(&target) || placed;
                match &aside {
                    Some(a) if old_aside && exists(a) => rename(a, &target)?,
                    Some(a) => {
                        let _ = std::fs::remove_file(a);
                    }
                    None if placed => {
                        let _ = std::fs::remove_file(&target);
                    }
                    None => {}
                }
                let _ = std::fs::remove_file(&staged);
            }
        }
    }
    Ok(())
}

/// Writes rendered references and their metadata as one set, under the
/// folder's exclusive lock: every file is first written in full under a
/// fresh staged name, then a journal names what becomes what, then each
/// old file is set aside and its new one renamed in. A failure undoes the
/// commit; a kill at any point is completed by the next run that takes the
/// lock (see [`GoldenLock::exclusive`]), so the folder always ends with
/// the whole old set or the whole new one.
///
/// # Errors
///
/// [`GoldenError::Image`] on I/O failure (the old files are kept).
pub fn store(
    scene: &Scene,
    version: &str,
    rendered: &[(Reference, LinearImage, PathBuf)],
    golden_dir: &Path,
) -> Result<(), GoldenError> {
    let _lock = GoldenLock::exclusive(golden_dir)?;
    let mut files: Vec<(Vec<u8>, PathBuf)> = Vec::new();
    for (_, img, path) in rendered {
        let bytes =
            image_io::encode_png(img.width, img.height, &img.pixels, PngEncoding::Linear16)?;
        files.push((bytes, path.clone()));
    }
    let refs: Vec<Reference> = rendered.iter().map(|(r, _, _)| r.clone()).collect();
    files.push((
        metadata(scene, version, &refs).into_bytes(),
        metadata_path(golden_dir, scene),
    ));
    let mut entries = Vec::new();
    let staged = (|| -> Result<(), GoldenError> {
        for (bytes, target) in &files {
            let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
            let target_name = name(target).ok_or_else(|| GoldenError::Metadata {
                path: target.clone(),
                message: "not a file name".into(),
            })?;
            let staged = new_staged(golden_dir)?;
            {
                use std::io::Write as _;
                let mut f = staged.as_file();
                f.write_all(bytes)
                    .and_then(|()| f.sync_all())
                    .map_err(|e| io_err(staged.path(), e))?;
            }
            let aside = if std::fs::symlink_metadata(target).is_ok() {
                let a = new_staged(golden_dir)?;
                let (_, p) = a.keep().map_err(|e| io_err(golden_dir, e.error))?;
                name(&p)
            } else {
                None
            };
            let (_, p) = staged.keep().map_err(|e| io_err(golden_dir, e.error))?;
            entries.push(Entry {
                staged: name(&p).unwrap_or_default(),
                target: target_name,
                aside,
            });
        }
        Ok(())
    })();
    if let Err(e) = staged {
        let _ = recover(golden_dir);
        return Err(e);
    }
    let mut journal = Journal {
        direction: Direction::Forward,
        entries,
    };
    if let Err(e) = write_journal(golden_dir, &journal) {
        let _ = recover(golden_dir);
        return Err(e);
    }
    let swapped = (|| -> Result<(), GoldenError> {
        for (k, e) in journal.entries.iter().enumerate() {
            let target = golden_dir.join(&e.target);
            if let Some(a) = &e.aside {
                std::fs::rename(&target, golden_dir.join(a)).map_err(|err| io_err(&target, err))?;
            }
            std::fs::rename(golden_dir.join(&e.staged), &target)
                .map_err(|err| io_err(&target, err))?;
            if k == 0 {
                pause_in_commit();
            }
        }
        Ok(())
    })();
    match swapped {
        Ok(()) => {
            apply(golden_dir, &journal)?;
        }
        Err(e) => {
            journal.direction = Direction::Rollback;
            write_journal(golden_dir, &journal)?;
            apply(golden_dir, &journal)?;
            let _ = std::fs::remove_file(golden_dir.join(JOURNAL_FILE));
            return Err(e);
        }
    }
    std::fs::remove_file(golden_dir.join(JOURNAL_FILE))
        .map_err(|e| io_err(&golden_dir.join(JOURNAL_FILE), e))?;
    Ok(())
}

fn new_staged(golden_dir: &Path) -> Result<tempfile::NamedTempFile, GoldenError> {
    tempfile::Builder::new()
        .prefix(STAGED_PREFIX)
        .permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644))
        .tempfile_in(golden_dir)
        .map_err(|e| io_err(golden_dir, e))
}

/// The test hook of the killed-update test (`tests/it/atomic.rs`): with
/// `RENDIFF_TEST_PAUSE_IN_COMMIT_MS` set (and the feature `testing`), a
/// commit waits that long after
/// its first file is swapped in, so a SIGKILL lands in the middle.
fn pause_in_commit() {
    #[cfg(feature = "testing")]
    if let Some(ms) = std::env::var("RENDIFF_TEST_PAUSE_IN_COMMIT_MS")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
}

/// The largest difference, in 16-bit codes, between two images of one size.
#[must_use]
pub fn max_code_difference(a: &LinearImage, b: &LinearImage) -> Option<u16> {
    if (a.width, a.height) != (b.width, b.height) {
        return None;
    }
    Some(
        a.pixels
            .iter()
            .zip(&b.pixels)
            .flat_map(|(p, q)| {
                [(p.r, q.r), (p.g, q.g), (p.b, q.b)].map(|(x, y)| {
                    crate::color::to_linear16(x).abs_diff(crate::color::to_linear16(y))
                })
            })
            .max()
            .unwrap_or(0),
    )
}
