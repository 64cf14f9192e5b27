//! POV-Ray 3.7 export: a scene as POV-Ray SDL that renders the same picture
//! (POVRAY.md §1–§9).
//!
//! Two geometries:
//! * `mesh`: every object as the very triangles the backends see (`mesh2`
//!   with per-corner normals and uvs), so a comparison tests visibility and
//!   shading only;
//! * `analytic`: spheres, boxes and superellipsoids as POV-Ray's own
//!   primitives with an explicit `matrix`, so a comparison also measures
//!   the tessellation error; polygons and meshes stay triangles.
//!
//! Every parameter is written explicitly (POVRAY.md §7b), floats in their
//! shortest round-trip form (an `f32` is widened to `f64` exactly first),
//! the camera as explicit vectors (no `look_at`, no `angle`). Image paths
//! are written as in the scene file, relative to the scene's folder:
//! POV-Ray must run from there (`rendiff golden` does). [`export_to`]
//! writes them relative to the .pov file's own folder instead (or
//! absolute), with the exact command that renders it on its first comment
//! line: what `rendiff pov -o FILE` writes.

pub mod golden;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::camera::Projection;
use crate::color::Rgb;
use crate::math::{DVec3, Vec3, to_f64};
use crate::options::Geometry;
use crate::scene::{Object, Scene, Shape};
use crate::shade::{LightKind, Material, Pigment};
use crate::tri_scene::{NO_INDEX, TriScene};

/// What to export.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExportOptions {
    /// Triangles only, or POV-Ray primitives for the curved shapes and boxes.
    pub geometry: Geometry,
    /// POV-Ray's `max_trace_level`.
    pub max_depth: u32,
    /// Replace the numbers of large arrays by their count and a hash (for
    /// snapshots of the export text).
    pub abridged: bool,
}

/// An image the exported SDL reads.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageRef {
    /// The name written in the SDL.
    pub name: String,
    /// The file it comes from.
    pub source: PathBuf,
    /// The file at `name` is a copy rendiff writes before rendering
    /// ([`ImageRef::materialise`]): the RGB copy of an 8-bit greyscale
    /// PNG, which POV-Ray 3.7 misreads (POVRAY.md §9.2), or a PNG of the
    /// texels below.
    pub rgb_copy: bool,
    /// Texels POV-Ray must see exactly as rendiff does, written as a
    /// 16-bit PNG at `name`: a JPEG decoded (POV-Ray's libjpeg would
    /// decode it to other values), or an image tinted by an OBJ material's
    /// Kd. `None` for a file POV-Ray reads itself.
    pub texels: Option<std::sync::Arc<crate::texture::Texture>>,
}

impl ImageRef {
    /// Writes the RGB copy of a greyscale image into `dir` (where `name`
    /// resolves); nothing for other images.
    ///
    /// # Errors
    ///
    /// I/O or PNG errors.
    pub fn materialise(&self, dir: &std::path::Path) -> Result<(), crate::image_io::ImageIoError> {
        if !self.rgb_copy {
            return Ok(());
        }
        if let Some(tex) = &self.texels {
            // v/255 and v/65535 texels are exact in 16 bits (v·257); a
            // tinted texel is off by at most half a 16-bit code.
            let channels = if tex.has_alpha() { 4 } else { 3 };
            let words: Vec<u16> = tex
                .texels()
                .iter()
                .flat_map(|t| t[..channels].iter().map(|&v| crate::color::to_linear16(v)))
                .collect();
            return crate::image_io::write_png16(
                &dir.join(&self.name),
                tex.width(),
                tex.height(),
                tex.has_alpha(),
                &words,
            );
        }
        let tex = crate::texture::Texture::load(&self.source).map_err(|e| {
            crate::image_io::ImageIoError::Png {
                path: self.source.clone(),
                message: e.message,
            }
        })?;
        let px: Vec<u8> = tex
            .texels()
            .iter()
            .flat_map(|t| {
                #[expect(
                    clippy::cast_possible_truncation,
                    clippy::cast_sign_loss,
                    reason = "8-bit texels, exact"
                )]
                let v = (t[0] * 255.0).round() as u8;
                [v, v, v, 255]
            })
            .collect();
        crate::image_io::write_png_rgba8(&dir.join(&self.name), tex.width(), tex.height(), &px)
    }
}

/// An exported scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Export {
    /// The SDL text.
    pub text: String,
    /// The image files the SDL reads: names relative to the scene's folder
    /// (RGB copies of greyscale images relative to the render folder).
    pub images: Vec<ImageRef>,
    /// The size POV-Ray must render: n·W × n·H for `samples = n`.
    pub render_size: (u32, u32),
    /// Samples per pixel side (the reference averages n×n blocks).
    pub samples: u32,
}

/// A float in its shortest round-trip decimal form.
fn num(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    format!("{v}")
}

fn f(v: f32) -> String {
    num(f64::from(v))
}

fn vec3(v: DVec3) -> String {
    format!("<{},{},{}>", num(v.x), num(v.y), num(v.z))
}

fn vec3f(v: Vec3) -> String {
    vec3(to_f64(v))
}

fn rgb(c: Rgb) -> String {
    format!("<{},{},{}>", f(c.r), f(c.g), f(c.b))
}

/// FNV-1a (64 bit) of bytes: a stable, dependency-free content hash.
#[must_use]
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// An SDL array: `name { count, item, item, … }`, or abridged to its count
/// and hash.
fn array(out: &mut String, name: &str, items: &[String], abridged: bool) {
    if abridged {
        let joined = items.join(",");
        let _ = writeln!(
            out,
            "  {name} {{ {}, /* {} items, fnv1a {:016x} */ }}",
            items.len(),
            items.len(),
            fnv1a(joined.as_bytes())
        );
        return;
    }
    let _ = write!(out, "  {name} {{ {}", items.len());
    for (k, it) in items.iter().enumerate() {
        out.push_str(if k % 4 == 0 { ",\n    " } else { ", " });
        out.push_str(it);
    }
    out.push_str("\n  }\n");
}

/// Whether a scene object is written as a POV-Ray primitive.
fn is_primitive(o: &Object, geometry: Geometry) -> bool {
    geometry == Geometry::Analytic
        && matches!(
            o.shape,
            Shape::Sphere { .. } | Shape::Box { .. } | Shape::Superellipsoid { .. }
        )
}

/// Why a scene cannot be written as SDL: a file it reads has a name
/// POV-Ray cannot open (see [`crate::escape::sdl_file_name`]).
#[derive(Debug, thiserror::Error)]
#[error("{}: `materials.{material}.{key}`: {message}", crate::escape::message(&.path.display().to_string()))]
pub struct ExportError {
    /// The scene file.
    pub path: PathBuf,
    /// The material.
    pub material: String,
    /// The key naming the file (`pigment.image`, `bump.image`).
    pub key: &'static str,
    /// What is wrong.
    pub message: String,
}

/// Exports a scene (its `TriScene` must come from the same scene).
///
/// Every string from the scene reaches the SDL through
/// [`crate::escape`]: file names as escaped literals, names and labels in
/// comments with everything but printable ASCII replaced.
///
/// # Errors
///
/// [`ExportError`] for an image whose name POV-Ray cannot open.
pub fn export(scene: &Scene, tri: &TriScene, opts: &ExportOptions) -> Result<Export, ExportError> {
    export_with(scene, tri, opts, None)
}

/// Where an exported file goes, for [`export_to`].
#[derive(Clone, Copy, Debug)]
pub struct Destination<'a> {
    /// The .pov file that will be written (its folder need not be the
    /// scene's): POV-Ray runs in its folder, writing the PNG of the same
    /// stem there.
    pub pov: &'a Path,
    /// Name the images by absolute paths instead of relative to the .pov
    /// file's folder.
    pub absolute_paths: bool,
}

/// Exports a scene to be written at `dest.pov`: as [`export`], but image
/// names are relative to that file's folder (or absolute), and the first
/// comment line is the exact `povray` command that renders it there (the
/// PNG beside it, of the same stem). Greyscale RGB copies
/// ([`ImageRef::rgb_copy`]) belong in that folder.
///
/// # Errors
///
/// [`ExportError`] for an image whose name POV-Ray cannot open.
pub fn export_to(
    scene: &Scene,
    tri: &TriScene,
    opts: &ExportOptions,
    dest: Destination<'_>,
) -> Result<Export, ExportError> {
    export_with(scene, tri, opts, Some(dest))
}

fn export_with(
    scene: &Scene,
    tri: &TriScene,
    opts: &ExportOptions,
    dest: Option<Destination<'_>>,
) -> Result<Export, ExportError> {
    let mut o = String::new();
    let cam = &tri.camera;
    let n = cam.samples();
    let render_size = (cam.width() * n, cam.height() * n);
    match dest {
        None => write_header(&mut o, scene, tri, opts, render_size),
        Some(d) => write_header_for(&mut o, scene, tri, opts, render_size, d.pov),
    }
    write_camera(&mut o, cam);
    write_lights(&mut o, tri);
    let mut images: Vec<ImageRef> = Vec::new();
    let names = match dest {
        None => ImageNames::SceneRelative,
        Some(d) if d.absolute_paths => ImageNames::Absolute,
        Some(d) => ImageNames::RelativeTo(absolute(
            d.pov
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new(".")),
        )),
    };
    write_objects(&mut o, scene, tri, opts, &names, &mut images)?;
    Ok(Export {
        text: o,
        images,
        render_size,
        samples: n,
    })
}

/// The `#version` line, the comment naming the scene and the POV-Ray
/// command line, and the global settings and background.
fn write_header(
    o: &mut String,
    scene: &Scene,
    tri: &TriScene,
    opts: &ExportOptions,
    render_size: (u32, u32),
) {
    let n = tri.camera.samples();
    let _ = writeln!(o, "#version 3.7;");
    let _ = writeln!(
        o,
        "// Exported by rendiff from {}: render {}x{} from the scene's folder with",
        crate::escape::sdl_comment(
            &scene
                .path
                .file_name()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
        ),
        render_size.0,
        render_size.1
    );
    let _ = writeln!(
        o,
        "// {}",
        golden::command_line("scene.pov", "out.png", render_size)
    );
    if n > 1 {
        let _ = writeln!(
            o,
            "// and average {n}x{n} blocks (the n×n samples of each pixel, each clamped to [0, 1] first, as the PNG stores them)."
        );
    }
    write_settings(o, tri, opts);
}

/// As [`write_header`], for a file written at `pov`: the first comment
/// line is the command that renders it in its folder.
fn write_header_for(
    o: &mut String,
    scene: &Scene,
    tri: &TriScene,
    opts: &ExportOptions,
    render_size: (u32, u32),
    pov: &Path,
) {
    let n = tri.camera.samples();
    let file = pov.file_name().map_or_else(
        || "scene.pov".to_string(),
        |s| s.to_string_lossy().into_owned(),
    );
    let png = Path::new(&file)
        .with_extension("png")
        .to_string_lossy()
        .into_owned();
    let _ = writeln!(o, "#version 3.7;");
    let _ = writeln!(
        o,
        "// {}",
        crate::escape::sdl_comment(&golden::command_line(
            &shell_word(&file),
            &shell_word(&png),
            render_size
        ))
    );
    let _ = writeln!(
        o,
        "// Exported by rendiff from {}: run the command above in this file's folder ({}x{}).",
        crate::escape::sdl_comment(
            &scene
                .path
                .file_name()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
        ),
        render_size.0,
        render_size.1
    );
    if n > 1 {
        let _ = writeln!(
            o,
            "// Then average {n}x{n} blocks (the n×n samples of each pixel, each clamped to [0, 1] first, as the PNG stores them)."
        );
    }
    write_settings(o, tri, opts);
}

/// The global settings and background every export starts with.
fn write_settings(o: &mut String, tri: &TriScene, opts: &ExportOptions) {
    let _ = writeln!(
        o,
        "global_settings {{ assumed_gamma 1.0 ambient_light rgb {} max_trace_level {} adc_bailout 0 }}",
        rgb(tri.ambient_light),
        opts.max_depth
    );
    let _ = writeln!(o, "background {{ rgb {} }}", rgb(tri.background));
}

/// A word a POSIX shell reads as it is: bare when it is made of safe
/// characters, single-quoted otherwise.
fn shell_word(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "._-+/=,:".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// A path made absolute: resolved through links where it exists (so a
/// relative path between two of them is right), else joined to the
/// current folder.
fn absolute(p: &Path) -> PathBuf {
    std::fs::canonicalize(p)
        .or_else(|_| std::path::absolute(p))
        .unwrap_or_else(|_| p.to_path_buf())
}

/// `to` relative to the folder `from` (both absolute): `..` for each of
/// `from`'s components not shared, then the rest of `to`.
fn relative_to(to: &Path, from: &Path) -> PathBuf {
    let (t, f): (Vec<_>, Vec<_>) = (to.components().collect(), from.components().collect());
    let common = t.iter().zip(&f).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..f.len() {
        out.push("..");
    }
    for c in &t[common..] {
        out.push(c);
    }
    out
}

/// How image files are named in the SDL.
enum ImageNames {
    /// As the scene file wrote them (relative to the scene's folder).
    SceneRelative,
    /// Relative to this (absolute) folder, where the .pov will be.
    RelativeTo(PathBuf),
    /// Absolute.
    Absolute,
}

impl ImageNames {
    fn name(&self, scene: &Scene, path: &Path) -> String {
        match self {
            ImageNames::SceneRelative => image_name(scene, path),
            ImageNames::RelativeTo(dir) => relative_to(&absolute(path), dir)
                .to_string_lossy()
                .into_owned(),
            ImageNames::Absolute => absolute(path).to_string_lossy().into_owned(),
        }
    }
}

/// The camera (POVRAY.md §2, §9.6): explicit vectors, the right-handed
/// basis as is.
fn write_camera(o: &mut String, cam: &crate::camera::Camera) {
    let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
    match cam.projection() {
        Projection::Perspective { tan_half_fov: t } => {
            let _ = writeln!(
                o,
                "camera {{ perspective location {} direction {} right {} up {} }}",
                vec3(cam.eye()),
                vec3(cam.forward()),
                vec3(cam.right() * (2.0 * t * w / h)),
                vec3(cam.up() * (2.0 * t))
            );
        }
        Projection::Orthographic { view_height } => {
            let _ = writeln!(
                o,
                "camera {{ orthographic location {} direction {} right {} up {} }}",
                vec3(cam.eye()),
                vec3(cam.forward()),
                vec3(cam.right() * (view_height * w / h)),
                vec3(cam.up() * view_height)
            );
        }
    }
}

/// The lights. A parallel light sits beyond the scene's bounding sphere,
/// because POV-Ray stops its shadow rays at the plane through it (§9.7).
fn write_lights(o: &mut String, tri: &TriScene) {
    let (c, r) = tri.bounds.bounding_sphere();
    let (c, r) = (to_f64(c), f64::from(r));
    for l in &tri.lights {
        let mut extra = String::new();
        if l.shadowless {
            extra.push_str(" shadowless");
        }
        if let Some((fd, fp)) = l.fade {
            let _ = write!(extra, " fade_distance {} fade_power {}", f(fd), f(fp));
        }
        match l.kind {
            LightKind::Point { position } => {
                let _ = writeln!(
                    o,
                    "light_source {{ {} color rgb {}{extra} }}",
                    vec3f(position),
                    rgb(l.color)
                );
            }
            LightKind::Parallel { direction } => {
                let d = to_f64(direction).normalize();
                let at = c - d * (r + 1.0);
                let _ = writeln!(
                    o,
                    "light_source {{ {} color rgb {} parallel point_at {}{extra} }}",
                    vec3(at),
                    rgb(l.color),
                    vec3(c)
                );
            }
        }
    }
}

/// Every object with its texture. The far plane clips what the camera
/// sees (DESIGN.md §2), not what casts shadows or is reflected: an object
/// it cuts is written twice, clipped for the camera only and whole for
/// everything else.
fn write_objects(
    o: &mut String,
    scene: &Scene,
    tri: &TriScene,
    opts: &ExportOptions,
    names: &ImageNames,
    images: &mut Vec<ImageRef>,
) -> Result<(), ExportError> {
    let cam = &tri.camera;
    let (f_dir, eye) = (cam.forward(), cam.eye());
    let far_plane = format!(
        "clipped_by {{ plane {{ {}, {} }} }}",
        vec3(f_dir),
        num(cam.far() + f_dir.dot(eye))
    );
    for (k, obj) in scene.objects.iter().enumerate() {
        let m = &tri.materials[usize::from(obj.material)];
        let info = &tri.objects[k];
        let mut body = String::new();
        let per_face = matches!(
            &obj.shape,
            Shape::Mesh {
                face_materials: Some(_),
                ..
            }
        );
        if per_face {
            // Each face its own texture (an OBJ's materials): a
            // texture_list in the mesh2, one object with one inside.
            let list = tri.object_materials(k);
            let mut textures = Vec::with_capacity(list.len());
            for &mk in &list {
                let mut t = String::new();
                let mat = &tri.materials[usize::from(mk)];
                write_texture(&mut t, scene, mat, mat.needs_uv(), names, images)?;
                textures.push(t);
            }
            write_mesh2_textured(&mut body, tri, k, &list, &textures, opts.abridged);
        } else {
            let uv = if is_primitive(obj, opts.geometry) {
                write_primitive(&mut body, obj);
                matches!(obj.shape, Shape::Sphere { .. })
            } else {
                write_mesh2(&mut body, tri, k, opts.abridged)
            };
            write_texture(&mut body, scene, m, uv, names, images)?;
        }
        if m.is_transparent() && m.ior != 1.0 {
            let _ = writeln!(body, "  interior {{ ior {} }}", f(m.ior));
        }
        if obj.no_shadow {
            let _ = writeln!(body, "  no_shadow");
        }
        let depths: Vec<f64> = info
            .bounds
            .corners()
            .iter()
            .map(|c| cam.view_depth(to_f64(*c)))
            .collect();
        let deepest = depths.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let nearest = depths.iter().copied().fold(f64::INFINITY, f64::min);
        let label = crate::escape::sdl_comment(&info.label);
        let _ = writeln!(o, "// {label}");
        if deepest <= cam.far() {
            let _ = writeln!(o, "{body}}}");
            continue;
        }
        if nearest <= cam.far() {
            let _ = writeln!(
                o,
                "{body}  {far_plane}\n  no_shadow no_reflection\n}}\n// {label} beyond the far plane: shadows and reflections only"
            );
        } else {
            let _ = writeln!(
                o,
                "// (wholly beyond the far plane: shadows and reflections only)"
            );
        }
        let _ = writeln!(o, "{body}  no_image\n}}");
    }
    Ok(())
}

fn write_primitive(o: &mut String, obj: &Object) {
    let m = obj.transform.matrix();
    let matrix = format!(
        "matrix <{},{},{}, {},{},{}, {},{},{}, {},{},{}>",
        num(m.x_axis.x),
        num(m.x_axis.y),
        num(m.x_axis.z),
        num(m.y_axis.x),
        num(m.y_axis.y),
        num(m.y_axis.z),
        num(m.z_axis.x),
        num(m.z_axis.y),
        num(m.z_axis.z),
        num(m.w_axis.x),
        num(m.w_axis.y),
        num(m.w_axis.z)
    );
    match &obj.shape {
        Shape::Sphere { center, radius } => {
            let _ = writeln!(
                o,
                "sphere {{ {}, {}\n  {matrix}",
                vec3(*center),
                num(*radius)
            );
        }
        Shape::Box { min, max } => {
            let _ = writeln!(o, "box {{ {}, {}\n  {matrix}", vec3(*min), vec3(*max));
        }
        Shape::Superellipsoid { e, n } => {
            let _ = writeln!(
                o,
                "superellipsoid {{ <{}, {}>\n  {matrix}",
                num(*e),
                num(*n)
            );
        }
        Shape::Mesh { .. } | Shape::Polygon(_) => {}
    }
}

/// Writes an object's triangles as `mesh2` (opening brace included);
/// returns whether it has uvs.
fn write_mesh2(o: &mut String, tri: &TriScene, object: usize, abridged: bool) -> bool {
    write_mesh2_with(o, tri, object, None, abridged)
}

/// Writes an object whose faces have materials of their own as `mesh2`
/// with a `texture_list` (`textures[i]`, the finish lines of material
/// `list[i]`) and each face's index into it (opening brace included).
fn write_mesh2_textured(
    o: &mut String,
    tri: &TriScene,
    object: usize,
    list: &[u16],
    textures: &[String],
    abridged: bool,
) {
    write_mesh2_with(o, tri, object, Some((list, textures)), abridged);
}

/// [`write_mesh2`], with a texture list where `textured` is given: uvs
/// are then written where any face's material reads them, and a face whose
/// material reads none points at uv 0 (POV-Ray wants an index on every
/// face; that texture never reads it).
fn write_mesh2_with(
    o: &mut String,
    tri: &TriScene,
    object: usize,
    textured: Option<(&[u16], &[String])>,
    abridged: bool,
) -> bool {
    let info = &tri.objects[object];
    let range = info.tris.start as usize..info.tris.end as usize;
    // Pools restricted to this object, in first-use order.
    let mut vmap = std::collections::HashMap::new();
    let mut verts = Vec::new();
    let mut faces = Vec::new();
    for t in range.clone() {
        let idx = tri.tris[t].map(|v| {
            let next = verts.len();
            *vmap.entry(v).or_insert_with(|| {
                verts.push(tri.positions[v as usize]);
                next
            })
        });
        faces.push(idx);
    }
    let smooth = range.clone().any(|t| tri.tri_normals[t][0] != NO_INDEX);
    // uvs only where the material reads them (the same rule as the plan),
    // so the export does not depend on whether the plan dropped them.
    let reads_uv = |t: usize| tri.materials[usize::from(tri.tri_material[t])].needs_uv();
    let has_uv = match textured {
        None => {
            range.clone().all(|t| tri.tri_uvs[t][0] != NO_INDEX)
                && !range.is_empty()
                && tri.materials[usize::from(info.material)].needs_uv()
        }
        Some(_) => range
            .clone()
            .any(|t| reads_uv(t) && tri.tri_uvs[t][0] != NO_INDEX),
    };
    let _ = writeln!(o, "mesh2 {{");
    array(
        o,
        "vertex_vectors",
        &verts.iter().map(|v| vec3f(*v)).collect::<Vec<_>>(),
        abridged,
    );
    let mut normals = Vec::new();
    let mut nfaces = Vec::new();
    if smooth {
        let mut nmap = std::collections::HashMap::new();
        for t in range.clone() {
            let ni = tri.tri_normals[t];
            let idx: [usize; 3] = if ni[0] == NO_INDEX {
                // A flat triangle among smooth ones: its geometric normal at
                // all three corners interpolates to itself.
                let g = tri.geometric_normal(u32::try_from(t).unwrap_or(0));
                normals.push(g);
                [normals.len() - 1; 3]
            } else {
                ni.map(|n| {
                    let next = normals.len();
                    *nmap.entry(n).or_insert_with(|| {
                        normals.push(tri.normals[n as usize]);
                        next
                    })
                })
            };
            nfaces.push(idx);
        }
        array(
            o,
            "normal_vectors",
            &normals.iter().map(|v| vec3f(*v)).collect::<Vec<_>>(),
            abridged,
        );
    }
    let mut uvs = Vec::new();
    let mut ufaces = Vec::new();
    if has_uv {
        let mut umap = std::collections::HashMap::new();
        for t in range.clone() {
            if textured.is_some() && !(reads_uv(t) && tri.tri_uvs[t][0] != NO_INDEX) {
                ufaces.push([0; 3]);
                continue;
            }
            ufaces.push(tri.tri_uvs[t].map(|u| {
                let next = uvs.len();
                *umap.entry(u).or_insert_with(|| {
                    uvs.push(tri.uvs[u as usize]);
                    next
                })
            }));
        }
        array(
            o,
            "uv_vectors",
            &uvs.iter()
                .map(|q| format!("<{},{}>", f(q.x), f(q.y)))
                .collect::<Vec<_>>(),
            abridged,
        );
    }
    let tri3 = |t: &[usize; 3]| format!("<{},{},{}>", t[0], t[1], t[2]);
    match textured {
        None => array(
            o,
            "face_indices",
            &faces.iter().map(tri3).collect::<Vec<_>>(),
            abridged,
        ),
        Some((list, textures)) => {
            let _ = writeln!(o, "  texture_list {{ {}", textures.len());
            for (k, t) in textures.iter().enumerate() {
                let _ = writeln!(
                    o,
                    "    {}texture {{ // {}",
                    if k > 0 { "," } else { "" },
                    crate::escape::sdl_comment(&tri.materials[usize::from(list[k])].name)
                );
                for line in t.lines() {
                    let _ = writeln!(o, "    {line}");
                }
                let _ = writeln!(o, "    }}");
            }
            let _ = writeln!(o, "  }}");
            let items: Vec<String> = faces
                .iter()
                .zip(range.clone())
                .map(|(f, t)| {
                    let m = list.binary_search(&tri.tri_material[t]).unwrap_or_default();
                    format!("{}, {m}", tri3(f))
                })
                .collect();
            array(o, "face_indices", &items, abridged);
        }
    }
    if smooth {
        array(
            o,
            "normal_indices",
            &nfaces.iter().map(tri3).collect::<Vec<_>>(),
            abridged,
        );
    }
    if has_uv {
        array(
            o,
            "uv_indices",
            &ufaces.iter().map(tri3).collect::<Vec<_>>(),
            abridged,
        );
    }
    if info.closed {
        // Makes the mesh a solid for the eye's inside test (POVRAY.md §9.9).
        let _ = writeln!(o, "  inside_vector <0,0,1>");
    }
    has_uv
}

/// The path of an image as the scene file wrote it (relative to the
/// scene's folder where possible). A backslash is kept: on Unix it is a
/// character of the name, not a separator, and rewriting it would make
/// POV-Ray open another file ([`crate::escape::sdl_file_name`] refuses it).
fn image_name(scene: &Scene, path: &std::path::Path) -> String {
    let base = scene.path.parent().unwrap_or(std::path::Path::new(""));
    path.strip_prefix(base)
        .unwrap_or(path)
        .to_string_lossy()
        .into_owned()
}

fn write_texture(
    o: &mut String,
    scene: &Scene,
    m: &Material,
    uv: bool,
    names: &ImageNames,
    images: &mut Vec<ImageRef>,
) -> Result<(), ExportError> {
    let mut note = |tex: &std::sync::Arc<crate::texture::Texture>, key: &'static str| {
        // Texels POV-Ray cannot read from the file as rendiff does.
        let own = tex.format() == crate::texture::ImageFormat::Jpeg || tex.tint().is_some();
        if own {
            let stem: String = tex
                .path()
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || c == '-' {
                        c
                    } else {
                        '_'
                    }
                })
                .collect();
            let same = |i: &ImageRef| {
                i.source == tex.path() && i.texels.as_ref().is_some_and(|t| t.tint() == tex.tint())
            };
            if let Some(i) = images.iter().find(|i| same(i)) {
                return Ok(format!("\"{}\"", i.name));
            }
            let taken = |n: &str| images.iter().any(|i| i.name == n);
            let mut name = format!("rendiff_tex_{stem}.png");
            let mut k = 2;
            while taken(&name) {
                name = format!("rendiff_tex_{stem}_{k}.png");
                k += 1;
            }
            let literal = crate::escape::sdl_file_name(&name).map_err(|message| ExportError {
                path: scene.path.clone(),
                material: m.name.clone(),
                key,
                message,
            })?;
            images.push(ImageRef {
                name,
                source: tex.path().to_path_buf(),
                rgb_copy: true,
                texels: Some(tex.clone()),
            });
            return Ok(literal);
        }
        let rgb_copy = tex.is_grey() && tex.bit_depth() == 8;
        let name = if rgb_copy {
            // Written by the renderer into its folder, found by +L.
            let stem = tex
                .path()
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            format!("rendiff_rgb_{stem}.png")
        } else {
            names.name(scene, tex.path())
        };
        let literal = crate::escape::sdl_file_name(&name).map_err(|message| ExportError {
            path: scene.path.clone(),
            material: m.name.clone(),
            key,
            message,
        })?;
        if !images.iter().any(|i| i.name == name) {
            images.push(ImageRef {
                name,
                source: tex.path().to_path_buf(),
                rgb_copy,
                texels: None,
            });
        }
        Ok(literal)
    };
    if uv && (m.needs_uv()) {
        let _ = writeln!(o, "  uv_mapping");
    }
    match &m.pigment {
        Pigment::Color(c) => {
            let _ = writeln!(
                o,
                "  pigment {{ rgbft <{},{},{},{},{}> }}",
                f(c.r),
                f(c.g),
                f(c.b),
                f(m.filter),
                f(m.transmit)
            );
        }
        Pigment::Image(tex) => {
            let name = note(tex, "pigment.image")?;
            copy_note(o, tex, &name);
            let mut ft = String::new();
            if !tex.has_alpha() && m.filter + m.transmit > 0.0 {
                let _ = write!(
                    ft,
                    " filter all {} transmit all {}",
                    f(m.filter),
                    f(m.transmit)
                );
            }
            let _ = writeln!(
                o,
                "  pigment {{ image_map {{ png {name} gamma 1.0 interpolate 2{ft} }} }}"
            );
        }
    }
    if let Some(b) = &m.bump {
        let name = note(&b.texture, "bump.image")?;
        copy_note(o, &b.texture, &name);
        let _ = writeln!(
            o,
            "  normal {{ bump_map {{ png {name} gamma 1.0 bump_size {} interpolate 2 }} }}",
            f(b.size)
        );
    }
    let _ = writeln!(
        o,
        "  finish {{ ambient {} emission {} diffuse {} brilliance {} phong {} phong_size {} specular {} roughness {} metallic {} reflection {{ {} }} }}",
        f(m.ambient),
        f(m.emission),
        f(m.diffuse),
        f(m.brilliance),
        f(m.phong),
        f(m.phong_size),
        f(m.specular),
        f(m.roughness),
        f(m.metallic),
        f(m.reflection)
    );
    Ok(())
}

/// For an image rendiff writes itself ([`ImageRef::texels`]), a comment
/// naming its source and tint, so that the export's text (and its hash in
/// the golden metadata) changes with them.
fn copy_note(o: &mut String, tex: &crate::texture::Texture, literal: &str) {
    let own = tex.format() == crate::texture::ImageFormat::Jpeg || tex.tint().is_some();
    if !own {
        return;
    }
    let source = tex
        .path()
        .file_name()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let tint = tex
        .tint()
        .map(|t| format!(" times {}", rgb(t)))
        .unwrap_or_default();
    let _ = writeln!(
        o,
        "  // {}",
        crate::escape::sdl_comment(&format!(
            "{}: the texels of {source} as rendiff reads them{tint}, written as a 16-bit PNG",
            literal.trim_matches('"')
        ))
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths_climb_to_the_common_folder() {
        let r = |to: &str, from: &str| relative_to(Path::new(to), Path::new(from));
        assert_eq!(r("/a/b/t.png", "/a/b"), PathBuf::from("t.png"));
        assert_eq!(r("/a/b/t.png", "/a/c/d"), PathBuf::from("../../b/t.png"));
        assert_eq!(r("/a/t.png", "/"), PathBuf::from("a/t.png"));
        assert_eq!(r("/x/t.png", "/a"), PathBuf::from("../x/t.png"));
    }

    #[test]
    fn shell_words_are_quoted_only_when_needed() {
        assert_eq!(shell_word("s.pov"), "s.pov");
        assert_eq!(shell_word("my scene.pov"), "'my scene.pov'");
        assert_eq!(shell_word("it's.pov"), "'it'\\''s.pov'");
        assert_eq!(shell_word(""), "''");
    }
}
