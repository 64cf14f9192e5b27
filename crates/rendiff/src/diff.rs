//! `rendiff diff`: render a scene two ways (or once, against an image) and
//! deliver the verdict with its pictures.

use std::path::{Path, PathBuf};

use crate::color::Rgb;
use crate::compare::clusters;
use crate::compare::maps::{self, Picture};
use crate::compare::page::{PageImage, PageInput, scene_page};
use crate::compare::report::{Report, Times};
use crate::compare::{self, Comparison, ImageTolerances, Tolerances};
use crate::frame::Frame;
use crate::image_io::{self, PngEncoding};
use crate::scene::LoadError;
use crate::{Backend, Error, Prepared};

/// One side of a comparison.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Side {
    /// A backend renders it.
    Backend(Backend),
    /// A stored image (read as linear when 16-bit with gAMA 1.0, else sRGB).
    Image(PathBuf),
    /// Another renderer's G-buffer: a folder with `color.png` (the colour
    /// of every sample), `id.png` (rendiff's triangle id + 1 per sample as
    /// a little-endian u32 in RGBA8, 0 for the background) and `depth.pfm`
    /// (`t` along the unit primary ray, +∞ for the background), all at the
    /// scene's sample grid — the files `rendiff render --gbuffer` writes.
    /// Its disagreements are classified like a backend's.
    External(PathBuf),
    /// The POV-Ray reference: stored in the golden folder, or rendered now.
    Pov {
        /// The folder of the stored references (`golden/pov`).
        golden_dir: PathBuf,
        /// Render it with POV-Ray instead of reading the stored one.
        render: bool,
    },
}

impl Side {
    /// Parses `--a`/`--b`: a path when the text contains `.` or `/`.
    ///
    /// # Errors
    ///
    /// A message naming the accepted values.
    pub fn parse(s: &str) -> Result<Side, String> {
        if Path::new(s).is_dir() {
            return Ok(Side::External(PathBuf::from(s)));
        }
        if s.contains('.') || s.contains('/') {
            return Ok(Side::Image(PathBuf::from(s)));
        }
        if s == "pov" {
            return Ok(Side::Pov {
                golden_dir: PathBuf::from("golden/pov"),
                render: false,
            });
        }
        s.parse::<Backend>().map(Side::Backend).map_err(|_| {
            format!(
                "unknown side \"{s}\"; expected a backend (raster, ray, painter, bsp), pov, a PATH.png, or a G-buffer folder"
            )
        })
    }

    fn label(&self) -> String {
        match self {
            Side::Backend(b) => b.to_string(),
            Side::Image(p) | Side::External(p) => p.display().to_string(),
            Side::Pov { .. } => "pov".to_string(),
        }
    }

    fn traces_ray_tree(&self) -> bool {
        matches!(self, Side::Backend(Backend::Ray) | Side::Pov { .. })
    }
}

/// What one side produced.
#[derive(Debug)]
pub enum Output {
    /// A rendered frame and its time.
    Frame(Frame, f64),
    /// A stored image's pixels.
    Image {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
        /// Linear pixels.
        pixels: Vec<Rgb>,
        /// Read as 16-bit linear (else 8-bit sRGB).
        linear16: bool,
        /// Read from a float image (PFM): no rounding to allow for.
        float: bool,
        /// How long POV-Ray took, when it rendered the image just now.
        rendered_ms: Option<f64>,
    },
    /// Another renderer's G-buffer ([`Side::External`]) as a frame, and how
    /// its colours were stored.
    External(Frame, compare::Quantisation),
}

impl Output {
    fn pixels(&self) -> &[Rgb] {
        match self {
            Output::Frame(f, _) | Output::External(f, _) => &f.color,
            Output::Image { pixels, .. } => pixels,
        }
    }

    /// The frame of a side that has one (a backend's, another renderer's
    /// G-buffer).
    #[must_use]
    pub fn frame(&self) -> Option<&Frame> {
        match self {
            Output::Frame(f, _) | Output::External(f, _) => Some(f),
            Output::Image { .. } => None,
        }
    }

    fn quantisation(&self) -> compare::Quantisation {
        match self {
            Output::Frame(..) => compare::Quantisation::Exact,
            Output::External(_, q) => *q,
            Output::Image { float: true, .. } => compare::Quantisation::Exact,
            Output::Image { linear16: true, .. } => compare::Quantisation::Linear16,
            Output::Image { .. } => compare::Quantisation::Srgb8,
        }
    }

    fn width_height(&self) -> (u32, u32) {
        match self {
            Output::Frame(f, _) | Output::External(f, _) => (f.width, f.height),
            Output::Image { width, height, .. } => (*width, *height),
        }
    }

    fn time(&self) -> Option<f64> {
        match self {
            Output::Frame(_, t) => Some(*t),
            Output::External(..) => None,
            Output::Image { rendered_ms, .. } => *rendered_ms,
        }
    }
}

/// The full result of one scene's diff.
#[derive(Debug)]
pub struct DiffResult {
    /// The verdict.
    pub report: Report,
    /// The comparison behind it.
    pub comparison: Comparison,
    /// Side a.
    pub a: Output,
    /// Side b.
    pub b: Output,
    /// The tolerances used.
    pub tolerance: Tolerances,
}

/// The tolerances of a scene: derived, tightened by its `[tolerance]` table.
///
/// # Errors
///
/// [`Error::Load`] naming the key when the scene asks for a looser value
/// than the derived one.
pub fn tolerances(job: &Prepared) -> Result<(Tolerances, ImageTolerances), Error> {
    let mut t = compare::derive_tolerances(&job.tri);
    let mut it = ImageTolerances::default();
    let s = &job.scene.tolerance;
    let path = &job.scene.path;
    let looser = |key: &str, loc, value: f64, derived: f64, dir: &str| {
        Error::Load(LoadError::Key {
            path: path.clone(),
            loc,
            key: format!("tolerance.{key}"),
            message: format!(
                "{value} is looser than the derived {derived:.3e}; [tolerance] may only tighten ({dir})"
            ),
        })
    };
    if let Some(v) = s.shading_max {
        if v.value > t.shading_max {
            return Err(looser(
                "shading_max",
                v.loc,
                v.value,
                t.shading_max,
                "use a value ≤ the derived one",
            ));
        }
        t.shading_max = v.value;
    }
    if let Some(v) = s.pov_max8 {
        if v.value > it.pov_max8 {
            return Err(looser(
                "pov_max8",
                v.loc,
                v.value,
                it.pov_max8,
                "use a value ≤ the derived one",
            ));
        }
        it.pov_max8 = v.value;
    }
    if let Some(v) = s.pov_fraction {
        if v.value < it.pov_fraction || v.value > 1.0 {
            return Err(looser(
                "pov_fraction",
                v.loc,
                v.value,
                it.pov_fraction,
                "use a value between the derived one and 1",
            ));
        }
        it.pov_fraction = v.value;
    }
    // The user's own rule: may be looser than the derived one (it is
    // reported as theirs).
    it.fuzzy = s.fuzzy.map(|f| compare::Fuzzy {
        max_diff: f.max_diff,
        pixels: f.pixels,
    });
    Ok((t, it))
}

/// Renders or reads one side; a painter also says how its order went, a
/// BSP tree what it cut.
fn produce(job: &Prepared, side: &Side, max_depth: u32) -> Result<(Output, Option<String>), Error> {
    let out = match side {
        Side::Pov { golden_dir, render } => {
            use crate::pov::golden::{self, Variant};
            let variant = if job.settings.geometry == crate::options::Geometry::Analytic {
                // POV-Ray's own primitives (rendered at the scene's depth).
                Variant::Analytic
            } else if max_depth == 1 && job.tri.max_depth > 1 {
                Variant::Depth1
            } else {
                Variant::Main
            };
            let started = std::time::Instant::now();
            let mut stale_note = None;
            let img = if *render {
                golden::povray_version().map_err(Error::from)?;
                let refs = golden::references(&job.scene, &job.tri).map_err(Error::from)?;
                let r = refs
                    .iter()
                    .find(|r| r.variant == variant)
                    .or_else(|| refs.first())
                    .ok_or_else(|| Error::Usage("no POV-Ray reference for this scene".into()))?;
                golden::render(&job.scene, r).map_err(Error::from)?
            } else {
                let _lock = golden::GoldenLock::shared(golden_dir).map_err(Error::from)?;
                let path = golden::reference_path(golden_dir, &job.scene, variant);
                if !path.exists() {
                    return Err(Error::Usage(format!(
                        "{}: no stored POV-Ray reference; render one with `rendiff golden --update {}` or pass --render",
                        path.display(),
                        job.scene.path.display()
                    )));
                }
                // A reference rendered from another version of the scene
                // is not evidence about this one: say so before any count.
                let stale = golden::stale(&job.scene, &job.tri, golden_dir).map_err(Error::from)?;
                if !stale.is_empty() {
                    stale_note = Some(format!(
                        "the stored POV-Ray reference is stale ({}): it was rendered from another version of the scene, so its differences say nothing about this one; re-render it with `rendiff golden --update {}` or compare with --render",
                        stale.join("; "),
                        job.scene.path.display()
                    ));
                }
                let cam = &job.tri.camera;
                image_io::read_png_linear_within(
                    &path,
                    Some((cam.width(), cam.height())),
                    &job.budget,
                )?
            };
            return Ok((
                Output::Image {
                    width: img.width,
                    height: img.height,
                    pixels: img.pixels,
                    linear16: img.linear16,
                    float: false,
                    rendered_ms: render.then(|| started.elapsed().as_secs_f64() * 1e3),
                },
                stale_note,
            ));
        }
        Side::Backend(b) => {
            let r = job.render_with_depth(*b, max_depth)?;
            let note = match r.work {
                crate::Work::Painter { order: o, .. } => Some(format!(
                    "painter ({} sort): {} triangles drawn; {} overlapping pairs ordered: {} by depth ranges, {} by planes, {} coplanar; {} undecided (interpenetrating or cyclic), {} cycles broken; its real mismatches are samples it ordered wrongly",
                    job.settings.painter_sort,
                    o.drawn,
                    o.overlapping_pairs,
                    o.by_depth_range,
                    o.by_plane,
                    o.coplanar,
                    o.undecided,
                    o.cycles_broken
                )),
                crate::Work::Bsp { tree: t, .. } => Some(format!(
                    "bsp: {} triangles cut into {} pieces ({} splits) by a tree of {} nodes, {} deep, {} coplanar; built in {:.1} ms ({} classifications); a real mismatch would be a sample it ordered wrongly",
                    t.triangles,
                    t.pieces,
                    t.splits,
                    t.nodes,
                    t.depth,
                    t.coplanar,
                    t.build_ms,
                    t.classified
                )),
                _ => None,
            };
            return Ok((Output::Frame(r.frame, r.time_ms), note));
        }
        Side::External(dir) => {
            let (frame, q) = read_external(job, dir)?;
            Output::External(frame, q)
        }
        Side::Image(p) => {
            // The header's size is compared with the scene's before the
            // image is decoded (a PNG may claim 60000×60000 in 3 MB).
            let cam = &job.tri.camera;
            let img = image_io::read_png_linear_within(
                p,
                Some((cam.width(), cam.height())),
                &job.budget,
            )?;
            Output::Image {
                width: img.width,
                height: img.height,
                pixels: img.pixels,
                linear16: img.linear16,
                float: false,
                rendered_ms: None,
            }
        }
    };
    Ok((out, None))
}

/// Compares two images with no scene (`rendiff diff A.png B.png`): pixel
/// by pixel, beyond each image's rounding (8-bit sRGB or 16-bit linear);
/// the verdict passes when no pixel differs, or within the user's `fuzzy`
/// rule. Each image is refused before decoding when its header claims
/// more than `budget` allows, and `b` must have `a`'s size.
///
/// # Errors
///
/// [`Error::Image`] for an unreadable image or a size mismatch (naming
/// the file and both sizes).
pub fn diff_images(
    a: &Path,
    b: &Path,
    fuzzy: Option<compare::Fuzzy>,
    budget: &crate::budget::Budget,
) -> Result<DiffResult, Error> {
    let ext = |p: &Path, e: &str| p.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
    let is_pfm = |p: &Path| ext(p, "pfm") || ext(p, "exr");
    let read = |p: &Path, expect| -> Result<image_io::LinearImage, Error> {
        if ext(p, "exr") {
            read_exr(p, expect, budget)
        } else if ext(p, "pfm") {
            Ok(image_io::read_pfm_linear_within(p, expect, budget)?)
        } else {
            Ok(image_io::read_png_linear_within(p, expect, budget)?)
        }
    };
    let img_a = read(a, None)?;
    let img_b = read(b, Some((img_a.width, img_a.height)))?;
    let image = |img: image_io::LinearImage, float: bool| Output::Image {
        width: img.width,
        height: img.height,
        pixels: img.pixels,
        linear16: img.linear16,
        float,
        rendered_ms: None,
    };
    Ok(diff_outputs(
        (&a.display().to_string(), image(img_a, is_pfm(a))),
        (&b.display().to_string(), image(img_b, is_pfm(b))),
        fuzzy,
    ))
}

/// An OpenEXR image's first RGB(A) layer at its largest resolution, as
/// linear colour (alpha ignored, non-finite values 0); its header's size
/// is checked against `expect` and the budget before any pixel is read.
#[cfg(feature = "exr")]
fn read_exr(
    path: &Path,
    expect: Option<(u32, u32)>,
    budget: &crate::budget::Budget,
) -> Result<image_io::LinearImage, Error> {
    use exr::prelude::{ReadChannels, ReadLayers};
    let bad = |message: String| {
        Error::Image(image_io::ImageIoError::Png {
            path: path.to_path_buf(),
            message,
        })
    };
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| bad(format!("not a readable OpenEXR image: {e}")))?;
    let size = meta
        .headers
        .first()
        .map(|h| h.layer_size)
        .ok_or_else(|| bad("an OpenEXR image without layers".into()))?;
    let (w, h) = (
        u32::try_from(size.width()).map_err(|_| bad("too wide".into()))?,
        u32::try_from(size.height()).map_err(|_| bad("too tall".into()))?,
    );
    if let Some((ew, eh)) = expect
        && (w, h) != (ew, eh)
    {
        return Err(bad(format!(
            "the image is {w}x{h} but {ew}x{eh} is expected"
        )));
    }
    let need = u64::from(w) * u64::from(h) * 28;
    budget
        .reserve(need, || format!("decoding the {w}x{h} OpenEXR image"))
        .map_err(|e| bad(e.to_string()))?;
    budget.release(need);
    let width = size.width();
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            move |res, _| vec![Rgb::BLACK; res.width() * res.height()],
            move |px: &mut Vec<Rgb>, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * width + pos.x()] = Rgb::new(r, g, b);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| bad(format!("could not read the OpenEXR image: {e}")))?;
    let pixels = image.layer_data.channel_data.pixels;
    if let Some(k) = pixels.iter().position(|c| !c.is_finite()) {
        let (x, y) = (k % width, k / width);
        return Err(bad(format!(
            "pixel ({x}, {y}) is not finite: a colour must be"
        )));
    }
    if w == 0 || h == 0 {
        return Err(bad(format!("the image is {w}x{h}: it has no pixels")));
    }
    Ok(image_io::LinearImage {
        width: w,
        height: h,
        pixels,
        linear16: false,
    })
}

/// Without the `exr` feature an OpenEXR image is refused by name.
#[cfg(not(feature = "exr"))]
fn read_exr(
    path: &Path,
    _expect: Option<(u32, u32)>,
    _budget: &crate::budget::Budget,
) -> Result<image_io::LinearImage, Error> {
    Err(Error::Usage(format!(
        "{}: this build of rendiff reads no OpenEXR (enable the `exr` feature)",
        path.display()
    )))
}

/// As [`diff_images`], on images already read (or made: an image rounded
/// as its PNG would store it), each with its label.
///
/// # Panics
///
/// If the images differ in size.
#[must_use]
pub fn diff_image_data(
    (la, img_a): (&str, image_io::LinearImage),
    (lb, img_b): (&str, image_io::LinearImage),
    fuzzy: Option<compare::Fuzzy>,
) -> DiffResult {
    let image = |img: image_io::LinearImage| Output::Image {
        width: img.width,
        height: img.height,
        pixels: img.pixels,
        linear16: img.linear16,
        float: false,
        rendered_ms: None,
    };
    diff_outputs((la, image(img_a)), (lb, image(img_b)), fuzzy)
}

/// Two images as [`Output::Image`]s, compared.
fn diff_outputs(
    (la, out_a): (&str, Output),
    (lb, out_b): (&str, Output),
    fuzzy: Option<compare::Fuzzy>,
) -> DiffResult {
    let (width, height) = (out_a.width_height().0, out_a.width_height().1);
    let tol = compare::image_tolerances();
    let image_tol = ImageTolerances {
        fuzzy,
        rule: compare::ImageRule::SameFrame,
        ..ImageTolerances::default()
    };
    let comparison = compare::compare_images(
        width,
        height,
        (out_a.pixels(), out_b.pixels()),
        [out_a.quantisation(), out_b.quantisation()],
        &image_tol,
        tol.shading_max,
    );
    let notes: Vec<String> = fuzzy.map(fuzzy_note).into_iter().collect();
    let mut report = Report::new(
        "two images",
        (width, height),
        (la, lb),
        1,
        &comparison,
        &tol,
        Some(&image_tol),
        Times { a: None, b: None },
        notes,
    );
    report.clusters = clusters::of_image_mask(
        width,
        height,
        &over_mask(&comparison, tol.shading_max),
        None,
    );
    DiffResult {
        report,
        comparison,
        a: out_a,
        b: out_b,
        tolerance: tol,
    }
}

/// Reads another renderer's G-buffer folder ([`Side::External`]) as a
/// frame of this scene.
fn read_external(job: &Prepared, dir: &Path) -> Result<(Frame, compare::Quantisation), Error> {
    let cam = &job.tri.camera;
    let grid = (cam.sample_width(), cam.sample_height());
    let color = image_io::read_png_linear_within(&dir.join("color.png"), Some(grid), &job.budget)?;
    let id_path = dir.join("id.png");
    let ids = image_io::read_png_u32_within(&id_path, grid, &job.budget)?;
    let depth = image_io::read_pfm_within(&dir.join("depth.pfm"), grid, &job.budget)?;
    let n = u32::try_from(job.tri.len()).unwrap_or(u32::MAX);
    let mut frame = Frame::new(cam.width(), cam.height(), cam.samples(), job.tri.background);
    for (i, (&id, &d)) in ids.iter().zip(&depth).enumerate() {
        let sw = grid.0 as usize;
        if id > n {
            return Err(Error::Usage(format!(
                "{}: sample ({}, {}) names triangle {} but the scene has {n} triangles (ids are rendiff's, + 1; 0 is the background)",
                id_path.display(),
                i % sw,
                i / sw,
                id - 1
            )));
        }
        if !(d.is_finite() || d == f32::INFINITY)
            || (id != 0 && !(d.is_finite() && d > 0.0))
            || (id == 0 && d != f32::INFINITY)
        {
            return Err(Error::Usage(format!(
                "{}: sample ({}, {}) has depth {d}; expected a finite t > 0 for a surface, +inf for the background",
                dir.join("depth.pfm").display(),
                i % sw,
                i / sw
            )));
        }
    }
    frame.id = ids.iter().map(|&i| i.wrapping_sub(1)).collect();
    frame.depth = depth.into();
    let quantisation = if color.linear16 {
        compare::Quantisation::Linear16
    } else {
        compare::Quantisation::Srgb8
    };
    let finite = |c: crate::color::Rgb| {
        let f = |v: f32| if v.is_finite() { v } else { 0.0 };
        crate::color::Rgb::new(f(c.r), f(c.g), f(c.b))
    };
    if cam.samples() == 1 {
        frame.color = color.pixels.into_iter().map(finite).collect();
    } else {
        frame.sample_color = color.pixels.into_iter().map(finite).collect();
        frame.resolve();
    }
    Ok((frame, quantisation))
}

/// Renders (or reads) both sides and compares them.
///
/// # Errors
///
/// [`Error`] for a looser `[tolerance]`, an unreadable image or a size mismatch.
pub fn diff(job: &Prepared, scene_label: &str, a: &Side, b: &Side) -> Result<DiffResult, Error> {
    diff_with(job, scene_label, a, b, None)
}

/// As [`diff`], with the user's fuzzy rule for image comparisons
/// (`--fuzzy`), which replaces the scene's `[tolerance] fuzzy`.
///
/// # Errors
///
/// As [`diff`].
pub fn diff_with(
    job: &Prepared,
    scene_label: &str,
    a: &Side,
    b: &Side,
    fuzzy: Option<compare::Fuzzy>,
) -> Result<DiffResult, Error> {
    let (tol, mut image_tol) = tolerances(job)?;
    if fuzzy.is_some() {
        image_tol.fuzzy = fuzzy;
    }
    image_tol.rule = if matches!(a, Side::Pov { .. }) || matches!(b, Side::Pov { .. }) {
        compare::ImageRule::Renderer
    } else {
        compare::ImageRule::SameFrame
    };
    let mut notes = Vec::new();
    let max_depth = common_max_depth(job, a, b, &mut notes);
    let (out_a, note_a) = produce(job, a, max_depth)?;
    let (out_b, note_b) = produce(job, b, max_depth)?;
    notes.extend(note_a);
    notes.extend(note_b);
    let cam = &job.tri.camera;
    let (comparison, image_tol_used) = match (out_a.frame(), out_b.frame()) {
        (Some(fa), Some(fb)) => {
            let tol = Tolerances {
                quantisation: [out_a.quantisation(), out_b.quantisation()],
                ..tol
            };
            (
                compare::compare_frames(&job.tri, fa, fb, &tol, job.settings.depth),
                None,
            )
        }
        _ => {
            // Against a stored image the shading bound is the frames' (0:
            // the same inputs give the same colour) beyond each image's
            // own rounding, pixel by pixel.
            (
                compare::compare_images(
                    cam.width(),
                    cam.height(),
                    (out_a.pixels(), out_b.pixels()),
                    [out_a.quantisation(), out_b.quantisation()],
                    &image_tol,
                    tol.shading_max,
                ),
                Some(image_tol),
            )
        }
    };
    if let (Some(f), Some(_)) = (image_tol.fuzzy, &image_tol_used) {
        notes.push(fuzzy_note(f));
    }
    let mut report = Report::new(
        scene_label,
        (cam.width(), cam.height()),
        (&a.label(), &b.label()),
        max_depth,
        &comparison,
        &tol,
        image_tol_used.as_ref(),
        Times {
            a: out_a.time(),
            b: out_b.time(),
        },
        notes,
    );
    report.explained = explain_against_image(job, &out_a, &out_b, &image_tol);
    report.clusters = clusters_for(job, &comparison, (&out_a, &out_b), (&tol, &image_tol));
    Ok(DiffResult {
        report,
        comparison,
        a: out_a,
        b: out_b,
        tolerance: tol,
    })
}

/// The ray-tree depth both sides use: the scene's, or 1 when one side
/// renders and shades locally (with a note saying so).
fn common_max_depth(job: &Prepared, a: &Side, b: &Side, notes: &mut Vec<String>) -> u32 {
    let mut max_depth = job.settings.max_depth;
    // Sides that render (a backend, or POV-Ray's reference at either depth).
    let renderers = [a, b]
        .iter()
        .filter(|s| matches!(s, Side::Backend(_) | Side::Pov { .. }))
        .count();
    if renderers == 2
        && !(a.traces_ray_tree() && b.traces_ray_tree())
        && max_depth > 1
        && job.plan.ray_tree
    {
        let who = if a.traces_ray_tree() {
            b.label()
        } else {
            a.label()
        };
        notes.push(format!(
            "max_depth forced from {max_depth} to 1 on both sides: {who} shades locally and cannot trace the ray tree"
        ));
        max_depth = 1;
    }
    max_depth
}

/// A frame against an image: why the pixels beyond the 8-bit bound
/// differ, from the frame's side.
fn explain_against_image(
    job: &Prepared,
    out_a: &Output,
    out_b: &Output,
    image_tol: &ImageTolerances,
) -> Option<compare::explain::Explained> {
    let ((Some(frame), None) | (None, Some(frame))) = (out_a.frame(), out_b.frame()) else {
        return None;
    };
    let reference = if out_a.frame().is_some() {
        out_b.pixels()
    } else {
        out_a.pixels()
    };
    let accel = crate::accel::Accel::new(&job.tri, crate::accel::AccelOptions::default());
    let oracle = crate::compare::Oracle::new(&job.tri, job.settings.depth);
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "an 8-bit bound"
    )]
    let max8 = image_tol.pov_max8.clamp(0.0, 255.0) as u8;
    let (counts, _) = crate::compare::explain::explain(frame, reference, &accel, &oracle, max8);
    Some(counts)
}

/// Where the two sides differ, as clusters: between two frames by class;
/// against an image the pixels over its rule's bound.
fn clusters_for(
    job: &Prepared,
    comparison: &Comparison,
    (out_a, out_b): (&Output, &Output),
    (tol, image_tol): (&Tolerances, &ImageTolerances),
) -> clusters::Clusters {
    let cam = &job.tri.camera;
    match (out_a.frame(), out_b.frame()) {
        (Some(fa), Some(fb)) => clusters::of_frames(&job.tri, comparison, fa, fb, tol.shading_max),
        (fa, fb) => {
            #[expect(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                reason = "an 8-bit bound"
            )]
            let max8 = image_tol.pov_max8.clamp(0.0, 255.0) as u8;
            let frame = fa
                .map(|f| (&job.tri, f, true))
                .or(fb.map(|f| (&job.tri, f, false)));
            if image_tol.rule == compare::ImageRule::Renderer && image_tol.fuzzy.is_none() {
                clusters::of_images(
                    cam.width(),
                    cam.height(),
                    out_a.pixels(),
                    out_b.pixels(),
                    max8,
                    frame,
                )
            } else {
                // The same frame (or the user's rule): the pixels over the
                // bound beyond the images' rounding.
                let over = over_mask(comparison, tol.shading_max);
                clusters::of_image_mask(cam.width(), cam.height(), &over, frame)
            }
        }
    }
}

/// The note a user's fuzzy rule adds to a verdict.
fn fuzzy_note(f: compare::Fuzzy) -> String {
    format!(
        "the user's fuzzy rule decides: at most {} pixels may differ beyond the images' rounding, by at most {} codes (the derived rule allows none)",
        f.pixels, f.max_diff
    )
}

/// The pixels of an image comparison over the shading bound (beyond the
/// images' rounding).
fn over_mask(comparison: &Comparison, shading_max: f64) -> Vec<bool> {
    comparison
        .errors
        .iter()
        .map(|&e| f64::from(e) > shading_max)
        .collect()
}

fn picture(out: &Output, w: u32, h: u32) -> Picture {
    Picture::from_linear(w, h, out.pixels())
}

/// Writes a scene's pictures, `report.json` and the interactive
/// `index.html` (`compare::page`) into `dir`; `job` is the scene both
/// sides show.
///
/// # Errors
///
/// [`Error::Image`] on I/O failure.
pub fn write_outputs(
    r: &DiffResult,
    job: Option<&Prepared>,
    dir: &Path,
    encoding: PngEncoding,
) -> Result<(), Error> {
    std::fs::create_dir_all(dir).map_err(|source| {
        Error::Image(image_io::ImageIoError::Io {
            path: dir.to_path_buf(),
            source,
        })
    })?;
    let (w, h) = (r.report.width, r.report.height);
    image_io::write_png(&dir.join("a.png"), w, h, r.a.pixels(), encoding)?;
    image_io::write_png(&dir.join("b.png"), w, h, r.b.pixels(), encoding)?;
    let heat = maps::heat_map(&r.comparison, w, h, r.report.tolerance.shading_max);
    image_io::write_png_rgba8(&dir.join("heat.png"), w, h, &heat.rgba)?;
    let mut panels: Vec<(String, Picture)> = vec![
        (format!("A: {}", r.report.a), picture(&r.a, w, h)),
        (format!("B: {}", r.report.b), picture(&r.b, w, h)),
        ("SHADING ERROR".into(), heat),
    ];
    let image = |key, caption: &str, file: &str| PageImage {
        key,
        caption: caption.to_string(),
        file: file.to_string(),
    };
    let mut images = vec![
        image("a", &format!("A: {}", r.report.a), "a.png"),
        image("b", &format!("B: {}", r.report.b), "b.png"),
        image("heat", "shading error", "heat.png"),
    ];
    // The perceptual error map (FLIP's magma colours: black = no visible
    // difference, white = the largest).
    if let Some(p) = compare::flip::magma_picture(w, h, &r.comparison.flip) {
        image_io::write_png_rgba8(&dir.join("flip.png"), w, h, &p.rgba)?;
    }
    if r.comparison.visibility.is_some() {
        let vis = maps::visibility_map(&r.comparison, w, h);
        image_io::write_png_rgba8(&dir.join("visibility.png"), w, h, &vis.rgba)?;
        panels.push(("VISIBILITY".into(), vis));
        images.push(image("vis", "visibility classes", "visibility.png"));
    }
    let refs: Vec<(&str, &Picture)> = panels.iter().map(|(l, p)| (l.as_str(), p)).collect();
    if let Some(c) = maps::composite(&refs) {
        image_io::write_png_rgba8(&dir.join("composite.png"), c.width, c.height, &c.rgba)?;
        images.push(image("composite", "side by side", "composite.png"));
    }
    let json = serde_json::to_string_pretty(&r.report).unwrap_or_default();
    let write_text = |name: &str, text: &str| {
        image_io::write_atomic(&dir.join(name), |f| {
            std::io::Write::write_all(f, text.as_bytes())
        })
    };
    write_text("report.json", &json)?;
    let page = PageInput {
        scene: job.map(|j| &j.tri),
        cmp: &r.comparison,
        a: r.a.pixels(),
        b: r.b.pixels(),
        frame_a: r.a.frame(),
        frame_b: r.b.frame(),
        images,
    };
    write_text("index.html", &scene_page(&r.report, &page))?;
    Ok(())
}
