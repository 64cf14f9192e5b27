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
pub fn command_line(pov: &str, png: &str, (w, h): (u32, u32)) -> String {
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
        && tri
            .objects
            .iter()
            .any(|o| tri.materials[usize::from(o.material)].spawns_rays())
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
            );
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

/// Renders a reference with POV-Ray in `work` (a scratch folder), from the
/// scene's folder, and returns it averaged to the scene's size.
///
/// # Errors
///
/// [`GoldenError`] if POV-Ray is missing or fails, or files cannot be written.
pub fn render(scene: &Scene, r: &Reference, work: &Path) -> Result<LinearImage, GoldenError> {
    let name = scene.name();
    let pov = work.join(format!("{name}{}.pov", r.variant.suffix()));
    let png = work.join(format!("{name}{}.raw.png", r.variant.suffix()));
    image_io::write_atomic(&pov, |f| {
        std::io::Write::write_all(f, r.export.text.as_bytes())
    })?;
    for img in &r.export.images {
        img.materialise(work)?;
    }
    let (w, h) = r.export.render_size;
    let scene_dir = scene
        .path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let out = Command::new(POVRAY)
        .current_dir(&scene_dir)
        .arg(format!("+I{}", pov.display()))
        .arg(format!("+O{}", png.display()))
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
        .arg(format!("+L{}", work.display()))
        .output()
        .map_err(|_| GoldenError::NoPovray)?;
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
    let img = image_io::read_png_linear(&png)?;
    Ok(average_blocks(&img, r.export.samples))
}

/// Averages n×n blocks (the n×n samples of each pixel).
#[must_use]
pub fn average_blocks(img: &LinearImage, n: u32) -> LinearImage {
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

/// The metadata text of a scene's references.
#[must_use]
pub fn metadata(scene: &Scene, version: &str, refs: &[Reference]) -> String {
    use std::fmt::Write as _;
    let name = scene.name();
    let mut o = String::new();
    let _ = writeln!(
        o,
        "# POV-Ray references of {name}.toml, written by `rendiff golden --update`."
    );
    let _ = writeln!(
        o,
        "# A reference whose hashes no longer match its scene's export is stale."
    );
    let _ = writeln!(o, "povray = \"{version}\"");
    let _ = writeln!(o, "scene = \"{name}.toml\"");
    for r in refs {
        let _ = writeln!(o, "\n[[reference]]");
        let _ = writeln!(o, "file = \"{name}{}.png\"", r.variant.suffix());
        let _ = writeln!(o, "variant = \"{}\"", r.variant.name());
        let _ = writeln!(o, "max_depth = {}", r.max_depth);
        let _ = writeln!(o, "samples = {}", r.export.samples);
        let _ = writeln!(
            o,
            "render_size = [{}, {}]",
            r.export.render_size.0, r.export.render_size.1
        );
        let _ = writeln!(
            o,
            "command = \"{}\"",
            command_line(
                &format!("{name}{}.pov", r.variant.suffix()),
                "out.png",
                r.export.render_size
            )
        );
        let _ = writeln!(o, "pov_fnv1a = \"{:016x}\"", r.pov_hash);
        let imgs: Vec<String> = r
            .image_hashes
            .iter()
            .map(|(n, h)| format!("{{ file = \"{n}\", fnv1a = \"{h:016x}\" }}"))
            .collect();
        let _ = writeln!(o, "images = [{}]", imgs.join(", "));
    }
    o
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

/// Renders every reference of a scene into `work` and returns them with
/// their final paths (nothing in the golden folder is touched).
///
/// # Errors
///
/// [`GoldenError`].
pub fn render_all(
    scene: &Scene,
    tri: &TriScene,
    golden_dir: &Path,
    work: &Path,
) -> Result<Vec<(Reference, LinearImage, PathBuf)>, GoldenError> {
    references(scene, tri)?
        .into_iter()
        .map(|r| {
            let img = render(scene, &r, work)?;
            let path = reference_path(golden_dir, scene, r.variant);
            Ok((r, img, path))
        })
        .collect()
}

/// Writes rendered references and their metadata: every file is first
/// written in full to a temporary name in the golden folder, then the set
/// is swapped in by renames that are undone if one fails, so a failure at
/// any point leaves the old set intact.
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
    std::fs::create_dir_all(golden_dir).map_err(|source| image_io::ImageIoError::Io {
        path: golden_dir.to_path_buf(),
        source,
    })?;
    let mut staged = Vec::new();
    let result = (|| -> Result<(), GoldenError> {
        for (_, img, path) in rendered {
            let tmp = path.with_extension("png.staged");
            image_io::write_png(
                &tmp,
                img.width,
                img.height,
                &img.pixels,
                PngEncoding::Linear16,
            )?;
            staged.push((tmp, path.clone()));
        }
        let refs: Vec<Reference> = rendered.iter().map(|(r, _, _)| r.clone()).collect();
        let meta = metadata_path(golden_dir, scene);
        let tmp = meta.with_extension("toml.staged");
        let text = metadata(scene, version, &refs);
        image_io::write_atomic(&tmp, |f| std::io::Write::write_all(f, text.as_bytes()))?;
        staged.push((tmp, meta));
        Ok(())
    })();
    if let Err(e) = result {
        for (tmp, _) in &staged {
            let _ = std::fs::remove_file(tmp);
        }
        return Err(e);
    }
    commit(&staged)
}

/// Moves staged files into place as one set: every old file is first set
/// aside (renamed to `*.previous`), then the new ones are renamed in; if
/// any rename fails, what was moved is moved back, so the folder holds
/// either the whole old set or the whole new one.
fn commit(staged: &[(PathBuf, PathBuf)]) -> Result<(), GoldenError> {
    let aside = |p: &Path| {
        p.with_extension(format!(
            "{}.previous",
            p.extension().and_then(|e| e.to_str()).unwrap_or("")
        ))
    };
    let mut moved_aside: Vec<(PathBuf, PathBuf)> = Vec::new();
    let mut placed: Vec<PathBuf> = Vec::new();
    let mut step = || -> Result<(), (PathBuf, std::io::Error)> {
        for (_, path) in staged {
            if path.exists() {
                let a = aside(path);
                std::fs::rename(path, &a).map_err(|e| (path.clone(), e))?;
                moved_aside.push((a, path.clone()));
            }
        }
        for (tmp, path) in staged {
            std::fs::rename(tmp, path).map_err(|e| (path.clone(), e))?;
            placed.push(path.clone());
        }
        Ok(())
    };
    match step() {
        Ok(()) => {
            for (a, _) in &moved_aside {
                let _ = std::fs::remove_file(a);
            }
            Ok(())
        }
        Err((path, source)) => {
            for p in &placed {
                let _ = std::fs::remove_file(p);
            }
            for (a, p) in &moved_aside {
                let _ = std::fs::rename(a, p);
            }
            for (tmp, _) in staged {
                let _ = std::fs::remove_file(tmp);
            }
            Err(image_io::ImageIoError::Io { path, source }.into())
        }
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
