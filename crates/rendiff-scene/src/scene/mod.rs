//! The scene file (DESIGN.md §4): parsing, validation, and the validated
//! [`Scene`] that tessellation turns into a `TriScene`.
//!
//! Loading is strict: unknown keys, missing required keys, values of the
//! wrong type, NaN or infinite numbers, values outside their rule, unknown
//! material names, unreadable or malformed meshes and images are all
//! errors that name the file, the line and column (or the mesh line) and
//! what was expected. A [`Scene`] that exists is valid; nothing after this
//! module re-checks what is checked here.

mod error;
pub mod mtl;
pub mod obj;
mod reader;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rendiff_core::budget::Budget;

pub use error::{LoadError, Loc};
pub use obj::{MeshData, MeshTri};

use reader::{At, Source, Table, num};
use toml::de::{DeTable, DeValue};

use crate::polygon::{self, PointRef, PolygonError, PolygonOptions};
use rendiff_core::camera::{Camera, Projection};
use rendiff_core::color::Rgb;
use rendiff_core::math::{DVec3, Transform, TransformStep, to_f32};
use rendiff_core::options::{BvhMode, DepthFormat, Geometry, ShadowMode};
use rendiff_core::shade::{Bump, BumpMethod, Light, LightKind, Material, Pigment};
use rendiff_core::texture::Texture;

/// Largest image side (DESIGN.md §4).
pub const MAX_IMAGE_SIDE: u32 = rendiff_core::options::MAX_SIDE;

/// `[image]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageSettings {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Background colour.
    pub background: Rgb,
    /// Samples per pixel side (1, 2, 4, 8 or 16).
    pub samples: u32,
}

/// The projection as written in the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProjectionDesc {
    /// Perspective with a vertical field of view in degrees.
    Perspective {
        /// `fov_y` in degrees.
        fov_y_deg: f64,
    },
    /// Orthographic with the view height in world units.
    Orthographic {
        /// `view_height`.
        view_height: f64,
    },
}

/// `[camera]`.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraSettings {
    /// Projection.
    pub projection: ProjectionDesc,
    /// Eye position.
    pub eye: DVec3,
    /// Target.
    pub look_at: DVec3,
    /// Up hint.
    pub up: DVec3,
    /// Near distance.
    pub near: f64,
    /// Far distance (`None`: from the scene bounds).
    pub far: Option<f64>,
}

/// `[render]`.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// `ambient_light`.
    pub ambient_light: Rgb,
    /// `max_depth` (POV-Ray's `max_trace_level`).
    pub max_depth: u32,
    /// Tessellation error in pixels.
    pub tessellation_error: f64,
}

/// `[raster]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RasterSettings {
    /// Depth buffer format.
    pub depth: DepthFormat,
    /// Shadow mode.
    pub shadows: ShadowMode,
}

/// `[ray]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RaySettings {
    /// BVH use.
    pub bvh: BvhMode,
    /// Geometry.
    pub geometry: Geometry,
}

/// A number from the scene file with its position (for errors raised
/// later, such as a tolerance looser than the derived one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    /// The value.
    pub value: f64,
    /// Where it was written.
    pub loc: Loc,
}

/// `[tolerance]`: may only tighten the derived tolerances.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ToleranceSettings {
    /// `shading_max`.
    pub shading_max: Option<Located>,
    /// `pov_max8`.
    pub pov_max8: Option<Located>,
    /// `pov_fraction`.
    pub pov_fraction: Option<Located>,
    /// `fuzzy = { max_diff, pixels }`: the user's own rule for image
    /// comparisons, as reftest's `fuzzy(maxDiff, pixelCount)`.
    pub fuzzy: Option<FuzzySetting>,
}

/// `[tolerance] fuzzy`: at most `pixels` pixels may differ (beyond the
/// images' rounding), none by more than `max_diff` 8-bit codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FuzzySetting {
    /// Largest 8-bit channel difference of a differing pixel.
    pub max_diff: u8,
    /// Largest number of differing pixels.
    pub pixels: u64,
    /// Where it was written.
    pub loc: Loc,
}

/// A polygon: outline and holes, validated and triangulated.
#[derive(Clone, Debug, PartialEq)]
pub struct PolygonShape {
    /// All points, outline first, then each hole.
    pub points: Vec<DVec3>,
    /// Number of points of the outline and of each hole.
    pub ring_sizes: Vec<usize>,
    /// One uv per point, if given.
    pub uv: Option<Vec<[f64; 2]>>,
    /// Triangles (indices into `points`), counter-clockwise around `normal`.
    pub triangles: Vec<[u32; 3]>,
    /// Unit Newell normal.
    pub normal: DVec3,
}

/// The geometry of an object, in its own space.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A triangle mesh from an OBJ file.
    Mesh {
        /// The loaded mesh (shared between objects using the same file).
        data: Arc<MeshData>,
        /// Interpolate vertex normals.
        smooth: bool,
        /// With `material = "obj"`: the material (an index into
        /// [`Scene::materials`]) of each of the mesh's triangles, from its
        /// face's `usemtl`; `None`: the object's `material` for all.
        face_materials: Option<Arc<[u16]>>,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: DVec3,
        /// Radius.
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Lower corner.
        min: DVec3,
        /// Upper corner.
        max: DVec3,
    },
    /// A planar polygon with holes.
    Polygon(Arc<PolygonShape>),
    /// POV-Ray's superellipsoid `<e, n>` in [−1, 1]³.
    Superellipsoid {
        /// East-west exponent (x-y plane).
        e: f64,
        /// North-south exponent (z).
        n: f64,
    },
}

impl Shape {
    /// The kind as written in the scene file.
    #[must_use]
    pub fn kind(&self) -> &'static str {
        match self {
            Shape::Mesh { .. } => "mesh",
            Shape::Sphere { .. } => "sphere",
            Shape::Box { .. } => "box",
            Shape::Polygon(_) => "polygon",
            Shape::Superellipsoid { .. } => "superellipsoid",
        }
    }
}

/// One `[[objects]]` entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// Index in the scene's object list.
    pub index: usize,
    /// Where the entry starts in the scene file.
    pub loc: Loc,
    /// The geometry.
    pub shape: Shape,
    /// Material index: the object's material; for a mesh with per-face
    /// materials (`material = "obj"`), the one whose `ior` is its inside
    /// (its first refracting material, else its first face's).
    pub material: u16,
    /// The transform steps as written.
    pub steps: Vec<TransformStep>,
    /// Their composition.
    pub transform: Transform,
    /// Casts no shadows.
    pub no_shadow: bool,
    /// Fixed segment count (spheres, superellipsoids).
    pub tessellation: Option<u32>,
}

impl Object {
    /// `objects[i] (kind)`, for messages.
    #[must_use]
    pub fn label(&self) -> String {
        format!("objects[{}] ({})", self.index, self.shape.kind())
    }
}

/// A scene as the loader made it: every value checked against the ranges
/// of DESIGN.md §4 and every reference (material, texture, mesh) resolved.
///
/// The fields are public so that a program can build or edit a scene
/// (`rendiff bench` varies them; [`Scene::scaled`] moves one). The
/// loader's checks do not follow such an edit: what the renderers rely on
/// is checked again where it is used ([`Scene::build_camera`] refuses a
/// degenerate camera, bad samples or an unrepresentable resolution; the
/// tessellation refuses non-finite or oversized geometry, and
/// `TriScene::debug_check` asserts the rest in debug builds), while a
/// value outside its documented range that passes those (a phong size of
/// 1e9, say) renders as the arithmetic says, not as an error.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The scene file.
    pub path: PathBuf,
    /// `[image]`.
    pub image: ImageSettings,
    /// `[camera]`.
    pub camera: CameraSettings,
    /// `[render]`.
    pub render: RenderSettings,
    /// `[[lights]]`.
    pub lights: Vec<Light>,
    /// `[materials]`, in name order, then the materials read from OBJ
    /// libraries (`material = "obj"`) in order of first use.
    pub materials: Vec<Material>,
    /// `[[objects]]`.
    pub objects: Vec<Object>,
    /// `[raster]`.
    pub raster: RasterSettings,
    /// `[ray]`.
    pub ray: RaySettings,
    /// `[tolerance]`.
    pub tolerance: ToleranceSettings,
    /// What loading noticed and let pass (statements of a material library
    /// that the finish model has no place for).
    pub warnings: Vec<String>,
}

/// The `material` value that selects an OBJ mesh's own materials (its
/// `.mtl` libraries, per `usemtl` group); no `[materials]` entry may have
/// this name.
pub const OBJ_MATERIALS: &str = "obj";

/// Why [`Scene::scaled`] cannot scale a scene.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "scaling by {scale} and moving by {offset:?}: {}",
    match .object {
        None => "expected a finite scale above 0 and a finite offset".to_string(),
        Some(k) => format!("objects[{k}]'s transform would not be invertible"),
    }
)]
pub struct ScaleError {
    /// The scale asked for.
    pub scale: f64,
    /// The offset asked for.
    pub offset: DVec3,
    /// The object whose transform fails, if one does.
    pub object: Option<usize>,
}

impl Scene {
    /// The camera of this scene at the image size and samples given, or
    /// the scene's own where `None` (`far` is the scene's, or `2·near`
    /// until the tessellation knows the bounds).
    ///
    /// # Errors
    ///
    /// [`LoadError::Scene`] naming the camera key when the frame is
    /// degenerate, the samples are not in {1, 2, 4, 8, 16}, or the
    /// resolution cannot be represented (DESIGN.md §4).
    pub fn build_camera(
        &self,
        size: Option<(u32, u32)>,
        samples: Option<u32>,
    ) -> Result<Camera, LoadError> {
        let (w, h) = size.unwrap_or((self.image.width, self.image.height));
        let samples = samples.unwrap_or(self.image.samples);
        let c = &self.camera;
        let projection = match c.projection {
            ProjectionDesc::Perspective { fov_y_deg } => Projection::Perspective {
                tan_half_fov: (fov_y_deg.to_radians() / 2.0).tan(),
            },
            ProjectionDesc::Orthographic { view_height } => {
                Projection::Orthographic { view_height }
            }
        };
        let camera = Camera::new(
            c.eye,
            c.look_at,
            c.up,
            projection,
            w,
            h,
            samples,
            c.near,
            c.far.unwrap_or(2.0 * c.near),
        )
        .map_err(|e| LoadError::Scene {
            path: self.path.clone(),
            message: format!("camera: {e}"),
        })?;
        if let Some((key, message)) = rendiff_core::camera::resolution_problem(
            camera.projection(),
            camera.eye().abs().max_element(),
            camera.width(),
            camera.height(),
        ) {
            return Err(LoadError::Scene {
                path: self.path.clone(),
                message: format!("camera.{key}: {message}"),
            });
        }
        Ok(camera)
    }

    /// The scene's name: the file stem.
    #[must_use]
    pub fn name(&self) -> String {
        self.path
            .file_stem()
            .map_or_else(|| "scene".to_string(), |s| s.to_string_lossy().into_owned())
    }

    /// The same scene with every length scaled by `scale` and everything
    /// moved by `offset`: camera (eye, target, near, far), lights (with
    /// their fade distances) and objects. Images look the same at any
    /// scale, which is what the numerical-stability tests check.
    ///
    /// # Errors
    ///
    /// [`ScaleError`] when `scale` is not finite and positive, `offset` is
    /// not finite, or an object's transform would no longer be invertible
    /// (it is never silently kept).
    pub fn scaled(&self, scale: f64, offset: DVec3) -> Result<Scene, ScaleError> {
        if !(scale.is_finite() && scale > 0.0 && offset.is_finite()) {
            return Err(ScaleError {
                scale,
                offset,
                object: None,
            });
        }
        let mut s = self.clone();
        let map = |p: DVec3| p * scale + offset;
        s.camera.eye = map(s.camera.eye);
        s.camera.look_at = map(s.camera.look_at);
        s.camera.near *= scale;
        s.camera.far = s.camera.far.map(|f| f * scale);
        if let ProjectionDesc::Orthographic { view_height } = &mut s.camera.projection {
            *view_height *= scale;
        }
        #[expect(clippy::cast_possible_truncation, reason = "light data is f32")]
        for l in &mut s.lights {
            if let LightKind::Point { position } = &mut l.kind {
                *position = to_f32(map(rendiff_core::math::to_f64(*position)));
            }
            if let Some((d, _)) = &mut l.fade {
                *d = (f64::from(*d) * scale) as f32;
            }
        }
        for (k, o) in s.objects.iter_mut().enumerate() {
            o.steps.push(TransformStep::Scale(DVec3::splat(scale)));
            o.steps.push(TransformStep::Translate(offset));
            o.transform = Transform::from_steps(&o.steps).ok_or(ScaleError {
                scale,
                offset,
                object: Some(k),
            })?;
        }
        Ok(s)
    }

    /// Every file the scene reads: the scene file, its meshes and its
    /// images (each once). A command refuses to write over any of them.
    #[must_use]
    pub fn input_files(&self) -> Vec<PathBuf> {
        let mut files = vec![self.path.clone()];
        let mut add = |p: &Path| {
            if !files.iter().any(|f| f == p) {
                files.push(p.to_path_buf());
            }
        };
        for o in &self.objects {
            if let Shape::Mesh { data, .. } = &o.shape {
                add(&data.path);
            }
        }
        for m in &self.materials {
            if let rendiff_core::shade::Pigment::Image(t) = &m.pigment {
                add(t.path());
            }
            if let Some(b) = &m.bump {
                add(b.texture.path());
            }
        }
        files
    }

    /// Bytes its loaded data holds: every distinct mesh and texture.
    #[must_use]
    pub fn data_bytes(&self) -> u64 {
        let mut seen: Vec<*const ()> = Vec::new();
        let mut total = 0u64;
        let mut once = |p: *const (), bytes: u64| {
            if !seen.contains(&p) {
                seen.push(p);
                total += bytes;
            }
        };
        for o in &self.objects {
            if let Shape::Mesh { data, .. } = &o.shape {
                once(Arc::as_ptr(data).cast(), obj::mesh_bytes(data));
            }
        }
        for m in &self.materials {
            let texels = |t: &Arc<Texture>| {
                u64::from(t.width()) * u64::from(t.height()) * Texture::BYTES_PER_TEXEL
            };
            if let rendiff_core::shade::Pigment::Image(t) = &m.pigment {
                once(Arc::as_ptr(t).cast(), texels(t));
            }
            if let Some(b) = &m.bump {
                once(Arc::as_ptr(&b.texture).cast(), texels(&b.texture));
            }
        }
        total
    }

    /// Loads and validates a scene file (within the default memory budget).
    ///
    /// # Errors
    ///
    /// [`LoadError`] naming the file, the place and what was expected.
    pub fn load(path: &Path) -> Result<Scene, LoadError> {
        Scene::load_within(path, &Budget::default())
    }

    /// Loads and validates a scene file, reserving what it reads (its text
    /// while parsed, its meshes and textures) in `budget` first.
    ///
    /// # Errors
    ///
    /// [`LoadError`] naming the file, the place and what was expected, or
    /// the figure that does not fit the budget.
    pub fn load_within(path: &Path, budget: &Budget) -> Result<Scene, LoadError> {
        // Parsing holds the text's tree: up to TOML_BYTES_PER_BYTE times
        // the file, reserved before the file is read.
        let size = std::fs::metadata(path).map_or(0, |m| m.len());
        let parse = size.saturating_mul(TOML_BYTES_PER_BYTE);
        budget
            .reserve(parse, || {
                format!(
                    "parsing the {} scene file",
                    rendiff_core::budget::human(size)
                )
            })
            .map_err(|e| LoadError::Scene {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
        let result = Scene::read_and_parse(path, budget);
        budget.release(parse);
        result
    }

    fn read_and_parse(path: &Path, budget: &Budget) -> Result<Scene, LoadError> {
        let bytes = rendiff_core::input::read_file(path).map_err(|source| LoadError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let text = match String::from_utf8(bytes) {
            Ok(text) => text,
            Err(e) => {
                // Locate the first bad byte in the valid text before it.
                let bytes = e.as_bytes();
                let at = e.utf8_error().valid_up_to();
                let valid = std::str::from_utf8(&bytes[..at]).unwrap_or_default();
                let src = Source { path, text: valid };
                return Err(LoadError::Syntax {
                    path: path.to_path_buf(),
                    loc: src.loc(at),
                    message: format!(
                        "the file is not valid UTF-8 (byte 0x{:02X} at offset {at}); a TOML file must be UTF-8 text",
                        bytes[at]
                    ),
                });
            }
        };
        Scene::from_str_within(path, &text, budget)
    }

    /// Parses and validates scene text; `path` locates relative files and
    /// names the scene in errors.
    ///
    /// # Errors
    ///
    /// [`LoadError`] naming the place and what was expected.
    pub fn from_str(path: &Path, text: &str) -> Result<Scene, LoadError> {
        Scene::from_str_within(path, text, &Budget::default())
    }

    /// [`Scene::from_str`], reserving the meshes and textures it loads in
    /// `budget`.
    ///
    /// # Errors
    ///
    /// As [`Scene::from_str`], or the figure that does not fit the budget.
    pub fn from_str_within(path: &Path, text: &str, budget: &Budget) -> Result<Scene, LoadError> {
        // A byte-order mark is not TOML; skip it rather than report it.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let src = Source { path, text };
        let doc = DeTable::parse(text).map_err(|e| {
            let mut message = e.message().trim().to_string();
            // toml names neither the key nor the table; the span is the key.
            if message == "duplicate key"
                && let Some(key) = e.span().and_then(|s| text.get(s)).filter(|k| !k.is_empty())
            {
                message = format!("duplicate key `{key}`: it is already defined in this table");
            }
            if message.starts_with("carriage return") && text.contains('\r') && !text.contains('\n') {
                message = "the lines end in a carriage return alone (classic Mac OS line endings), which TOML does not allow; convert them to LF or CRLF".into();
            }
            let mut at = e.span().map(|s| s.start);
            if at.is_none()
                && let Some(deep) = reader::deep_nesting(text)
            {
                at = Some(deep);
                message = format!(
                    "nested too deep: TOML keys of {} dotted parts, or arrays and inline tables {} deep, are beyond the parser's limit",
                    reader::NESTING_LIMIT,
                    reader::NESTING_LIMIT
                );
            }
            LoadError::Syntax {
                path: path.to_path_buf(),
                loc: src.loc(at.unwrap_or(0)),
                message,
            }
        })?;
        let span = doc.span();
        let root = Table::new(&src, String::new(), doc.get_ref(), span);
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Loader {
            base,
            textures: HashMap::new(),
            meshes: HashMap::new(),
            budget,
            libraries: HashMap::new(),
            library_materials: HashMap::new(),
            default_obj_material: None,
            warnings: Vec::new(),
        }
        .scene(&root)
    }
}

/// Bytes the TOML parser holds per byte of scene text, at most: its
/// document tree with spans and owned strings. Measured: 100 MB of text
/// took 7.5 GB before the first error (75 B per byte); 80 leaves a margin.
pub(crate) const TOML_BYTES_PER_BYTE: u64 = 80;

struct Loader<'b> {
    base: PathBuf,
    /// Textures by their canonical path (the same image named two ways is
    /// loaded once).
    textures: HashMap<PathBuf, Arc<Texture>>,
    meshes: HashMap<PathBuf, Arc<MeshData>>,
    budget: &'b Budget,
    /// Material libraries by canonical path.
    libraries: HashMap<PathBuf, Arc<mtl::MtlLibrary>>,
    /// Library materials already mapped: (canonical library, name) → index.
    library_materials: HashMap<(PathBuf, String), u16>,
    /// The material of faces no `usemtl` names, once made.
    default_obj_material: Option<u16>,
    warnings: Vec<String>,
}

/// Why an input file could not be read within the budget.
enum ReadError {
    Io(std::io::Error),
    Budget(rendiff_core::budget::OverBudget),
}

impl Loader<'_> {
    /// Reads a regular file after reserving its size in the budget (the
    /// caller releases it once the bytes are no longer held).
    fn read_within(&self, path: &Path, what: &str) -> Result<Vec<u8>, ReadError> {
        let size = rendiff_core::input::regular_file_size(path).map_err(ReadError::Io)?;
        self.budget
            .reserve(size, || {
                format!(
                    "reading the {} {what} file",
                    rendiff_core::budget::human(size)
                )
            })
            .map_err(ReadError::Budget)?;
        rendiff_core::input::read_file(path).map_err(|e| {
            self.budget.release(size);
            ReadError::Io(e)
        })
    }
}

fn rgb_of(v: DVec3) -> Rgb {
    let c = to_f32(v);
    Rgb::new(c.x, c.y, c.z)
}

fn check_nonneg_rgb(t: &Table<'_, '_>, key: &'static str, v: &At<DVec3>) -> Result<(), LoadError> {
    if v.value.min_element() < 0.0 {
        return Err(t.err(&v.span, key, "expected a colour with every channel ≥ 0"));
    }
    if v.value.max_element() > f64::from(f32::MAX) {
        return Err(t.err(&v.span, key, "colour channel exceeds the f32 range"));
    }
    Ok(())
}

/// The largest coordinate a scene may use (positions after transforms, the
/// eye, lights): the watertight ray-triangle test forms, in f32, distances
/// as products of three coordinate differences (up to 2·MAX each, with
/// factors of the shear ≤ √3 and three terms: about 336·MAX³), which must
/// stay below f32::MAX = 3.4e38 (DESIGN.md §8).
pub const MAX_COORDINATE: f64 = 1e12;

/// Texture coordinates must lie within ±1e6: f32 resolves 1e6 to 1/16, so
/// beyond it neighbouring texture lookups would be a sixteenth of a whole
/// repeat apart (every texel of a 16×16 image at once); an image pigment
/// cannot be rendered meaningfully there.
pub(crate) const MAX_UV: f64 = 1e6;

/// `bump.size` must lie within ±1e6: a one-code height step (1/255) then
/// tilts the normal by at most 4000 times its own length, still a
/// direction f32 can carry next to the unit normal; POV-Ray's `bump_size`
/// is rarely beyond 10.
pub(crate) const MAX_BUMP_SIZE: f64 = 1e6;

fn check_coord(t: &Table<'_, '_>, key: &'static str, v: &At<DVec3>) -> Result<(), LoadError> {
    if v.value.abs().max_element() > MAX_COORDINATE {
        return Err(t.err(
            &v.span,
            key,
            format!(
                "coordinates must be within ±{MAX_COORDINATE:e} (f32 arithmetic would overflow)"
            ),
        ));
    }
    Ok(())
}

/// The finish keys a material gives: where each was written and its value
/// as written (before it is stored in f32), for messages.
type Written = HashMap<&'static str, (reader::Span, f64)>;

impl Loader<'_> {
    fn resolve(&self, file: &str) -> PathBuf {
        let p = Path::new(file);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base.join(p)
        }
    }

    fn texture(
        &mut self,
        t: &Table<'_, '_>,
        key: &'static str,
        file: &At<String>,
    ) -> Result<Arc<Texture>, LoadError> {
        let path = self.resolve(&file.value);
        let read_err = |e: std::io::Error| {
            t.err(
                &file.span,
                key,
                format!("could not read image {}: {e}", path.display()),
            )
        };
        let decode_err = |message: String| LoadError::Image {
            path: path.clone(),
            message,
        };
        self.texture_at(&path, &read_err, &decode_err)
    }

    /// The texture at `path` (PNG or JPEG), loaded once per canonical path
    /// within the budget; `read_err` words a file that cannot be read,
    /// `decode_err` one that cannot be decoded or does not fit.
    fn texture_at(
        &mut self,
        path: &Path,
        read_err: &dyn Fn(std::io::Error) -> LoadError,
        decode_err: &dyn Fn(String) -> LoadError,
    ) -> Result<Arc<Texture>, LoadError> {
        // One image named two ways (`a.png`, `./a.png`, a link) is one
        // texture: the cache key is its canonical path.
        let canonical = std::fs::canonicalize(path).map_err(read_err)?;
        if let Some(tex) = self.textures.get(&canonical) {
            return Ok(tex.clone());
        }
        let bytes = self.read_within(path, "image").map_err(|e| match e {
            ReadError::Io(e) => read_err(e),
            ReadError::Budget(e) => decode_err(e.to_string()),
        })?;
        let tex = Texture::from_bytes_within(path, &bytes, self.budget)
            .map_err(|e| decode_err(e.message))?;
        // The file's bytes are freed once decoded.
        self.budget.release(bytes.len() as u64);
        let tex = Arc::new(tex);
        self.textures.insert(canonical, tex.clone());
        Ok(tex)
    }

    /// A material library named by an OBJ's `mtllib` (relative to the
    /// OBJ's folder, [`mtl::asset_path`]), read once per canonical path.
    fn library(&mut self, obj: &Path, lib: &obj::Named) -> Result<Arc<mtl::MtlLibrary>, LoadError> {
        let at = |message: String| LoadError::Mesh {
            path: obj.to_path_buf(),
            line: Some(lib.line as usize),
            message,
        };
        let base = obj.parent().unwrap_or(Path::new(""));
        // `mtllib a.mtl b.mtl` names two libraries, but a name with spaces
        // is one: the whole name is taken where such a file exists.
        let path = mtl::asset_path(base, &lib.name).map_err(|m| at(format!("mtllib: {m}")))?;
        let read_err = |e: std::io::Error| {
            at(format!(
                "could not read the material library {}: {e}",
                path.display()
            ))
        };
        let canonical = std::fs::canonicalize(&path).map_err(read_err)?;
        if let Some(l) = self.libraries.get(&canonical) {
            return Ok(l.clone());
        }
        let bytes = self
            .read_within(&path, "material library")
            .map_err(|e| match e {
                ReadError::Io(e) => read_err(e),
                ReadError::Budget(e) => at(e.to_string()),
            })?;
        let parsed = mtl::parse(&path, &bytes);
        self.budget.release(bytes.len() as u64);
        let parsed = Arc::new(parsed?);
        if !parsed.ignored.is_empty() {
            let list: Vec<String> = parsed
                .ignored
                .iter()
                .take(8)
                .map(|s| format!("{} (line {})", s.value, s.line))
                .collect();
            self.warnings.push(format!(
                "{}: {} statement(s) that rendiff does not model were ignored: {}{}",
                path.display(),
                parsed.ignored.len(),
                list.join(", "),
                if parsed.ignored.len() > 8 {
                    ", …"
                } else {
                    ""
                }
            ));
        }
        self.libraries.insert(canonical, parsed.clone());
        Ok(parsed)
    }

    /// The libraries an OBJ names: each `mtllib` (a line naming several
    /// files that do not exist as one name is split at its spaces).
    fn libraries_of(&mut self, data: &MeshData) -> Result<Vec<Arc<mtl::MtlLibrary>>, LoadError> {
        let base = data.path.parent().unwrap_or(Path::new(""));
        let mut out: Vec<Arc<mtl::MtlLibrary>> = Vec::new();
        for lib in &data.mtllibs {
            let whole = mtl::asset_path(base, &lib.name).is_ok_and(|p| p.is_file());
            let names: Vec<obj::Named> = if whole || !lib.name.contains(char::is_whitespace) {
                vec![lib.clone()]
            } else {
                lib.name
                    .split_whitespace()
                    .map(|n| obj::Named {
                        name: n.to_string(),
                        line: lib.line,
                    })
                    .collect()
            };
            for n in &names {
                let l = self.library(&data.path, n)?;
                if !out.iter().any(|o| Arc::ptr_eq(o, &l)) {
                    out.push(l);
                }
            }
        }
        Ok(out)
    }

    /// `material = "obj"`: the mesh's own materials. Reads the OBJ's
    /// libraries, maps every material a `usemtl` names
    /// ([`mtl::to_material`], each once per library and name, appended to
    /// `materials`), gives faces before any `usemtl` the default
    /// ([`mtl::default_material`]), and checks what the scene's own
    /// materials are checked for: uvs on the faces whose material reads an
    /// image, one index of refraction per object. Returns each triangle's
    /// material and the object's primary one ([`Object::material`]).
    fn obj_materials(
        &mut self,
        t: &Table<'_, '_>,
        mat_name: &At<String>,
        data: &MeshData,
        materials: &mut Vec<Material>,
    ) -> Result<(Arc<[u16]>, u16), LoadError> {
        if data.mtllibs.is_empty() {
            return Err(t.err(
                &mat_name.span,
                "material",
                format!(
                    "material = \"{OBJ_MATERIALS}\" uses the mesh's own materials, but {} has no `mtllib` statement naming a material library",
                    data.path.display()
                ),
            ));
        }
        let libs = self.libraries_of(data)?;
        // Each name once across the libraries.
        let mut defined: HashMap<&str, (usize, usize)> = HashMap::new();
        for (li, l) in libs.iter().enumerate() {
            for (mi, m) in l.materials.iter().enumerate() {
                if let Some(&(lj, mj)) = defined.get(m.name.as_str()) {
                    let first = &libs[lj];
                    return Err(LoadError::Mesh {
                        path: l.path.clone(),
                        line: Some(m.line as usize),
                        message: format!(
                            "material `{}` is also defined in {}:{}; the libraries of one OBJ must name each material once",
                            obj::shown(&m.name),
                            first.path.display(),
                            first.materials[mj].line
                        ),
                    });
                }
                defined.insert(&m.name, (li, mi));
            }
        }
        let mut used: Vec<u16> = Vec::with_capacity(data.usemtl.len());
        for u in &data.usemtl {
            let Some(&(li, mi)) = defined.get(u.name.as_str()) else {
                let mut names: Vec<String> = libs
                    .iter()
                    .flat_map(|l| {
                        l.materials
                            .iter()
                            .map(|m| format!("`{}`", obj::shown(&m.name)))
                    })
                    .collect();
                if names.is_empty() {
                    names.push("none".into());
                }
                let files: Vec<String> = libs
                    .iter()
                    .map(|l| {
                        l.path
                            .file_name()
                            .map_or_else(String::new, |f| f.to_string_lossy().into_owned())
                    })
                    .collect();
                return Err(LoadError::Mesh {
                    path: data.path.clone(),
                    line: Some(u.line as usize),
                    message: format!(
                        "usemtl `{}`: no material of that name in {} (defined: {})",
                        obj::shown(&u.name),
                        files.join(", "),
                        names.join(", ")
                    ),
                });
            };
            used.push(self.library_material(&libs[li], mi, materials)?);
        }
        let needs_default = data.tri_usemtl.is_empty() || data.tri_usemtl.contains(&obj::NO_USEMTL);
        let default = if needs_default {
            Some(match self.default_obj_material {
                Some(d) => d,
                None => {
                    let d = Self::push_material(
                        materials,
                        mtl::default_material("obj: no usemtl".to_string()),
                        t,
                    )?;
                    self.default_obj_material = Some(d);
                    d
                }
            })
        } else {
            None
        };
        let faces: Vec<u16> = if data.tri_usemtl.is_empty() {
            vec![default.unwrap_or(0); data.triangles.len()]
        } else {
            data.tri_usemtl
                .iter()
                .map(|&u| {
                    if u == obj::NO_USEMTL {
                        default.unwrap_or(0)
                    } else {
                        used[u as usize]
                    }
                })
                .collect()
        };
        // An image needs uvs on every face of its material.
        for ((tri, &m), &line) in data.triangles.iter().zip(&faces).zip(&data.lines) {
            let mat = &materials[usize::from(m)];
            if tri.t.is_none() && mat.needs_uv() {
                return Err(LoadError::Mesh {
                    path: data.path.clone(),
                    line: Some(line as usize),
                    message: format!(
                        "this face has no uv (vt) on every corner, but its material \"{}\" uses an image (map_Kd or bump)",
                        mat.name
                    ),
                });
            }
        }
        // One inside per object (as POV-Ray's `interior`): where one of
        // its transparent materials refracts, all of them refract alike.
        let mut distinct: Vec<u16> = faces.clone();
        distinct.sort_unstable();
        distinct.dedup();
        let transparent: Vec<u16> = distinct
            .iter()
            .copied()
            .filter(|&m| materials[usize::from(m)].is_transparent())
            .collect();
        let refracting = transparent
            .iter()
            .copied()
            .find(|&m| materials[usize::from(m)].ior != 1.0);
        if let Some(r) = refracting
            && let Some(other) = transparent
                .iter()
                .find(|&&m| materials[usize::from(m)].ior != materials[usize::from(r)].ior)
        {
            let (a, b) = (&materials[usize::from(r)], &materials[usize::from(*other)]);
            return Err(t.err(
                &mat_name.span,
                "material",
                format!(
                    "the mesh's transparent materials \"{}\" (ior {}) and \"{}\" (ior {}) differ in their index of refraction; an object has one inside, so its transparent materials share one (illum 6 or 7 and Ni on all, or on none)",
                    a.name, a.ior, b.name, b.ior
                ),
            ));
        }
        let primary = refracting.unwrap_or(faces[0]);
        Ok((faces.into(), primary))
    }

    /// Appends a material, refusing more than u16 can index.
    fn push_material(
        materials: &mut Vec<Material>,
        m: Material,
        t: &Table<'_, '_>,
    ) -> Result<u16, LoadError> {
        let k = u16::try_from(materials.len())
            .ok()
            .filter(|&k| k < u16::MAX)
            .ok_or_else(|| t.err_here("material", "too many materials (at most 65535, the scene's and the OBJ libraries' together)"))?;
        materials.push(m);
        Ok(k)
    }

    /// The scene material of material `mi` of library `lib`: mapped once,
    /// with its textures (relative to the library's folder) loaded.
    fn library_material(
        &mut self,
        lib: &Arc<mtl::MtlLibrary>,
        mi: usize,
        materials: &mut Vec<Material>,
    ) -> Result<u16, LoadError> {
        let m = &lib.materials[mi];
        let key = (lib.path.clone(), m.name.clone());
        if let Some(&k) = self.library_materials.get(&key) {
            return Ok(k);
        }
        let base = lib.path.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut load = |s: &mtl::TexStatement, kw: &str| -> Result<Arc<Texture>, LoadError> {
            let at = |message: String| LoadError::Mesh {
                path: lib.path.clone(),
                line: Some(s.line as usize),
                message,
            };
            let path = mtl::asset_path(&base, &s.file).map_err(|m| at(format!("{kw}: {m}")))?;
            let read_err = |e: std::io::Error| {
                at(format!(
                    "{kw}: could not read image {}: {e}",
                    path.display()
                ))
            };
            let decode_err = |e: String| at(format!("{kw}: image {}: {e}", path.display()));
            self.texture_at(&path, &read_err, &decode_err)
        };
        let tex = mtl::Textures {
            map_kd: m.map_kd.as_ref().map(|s| load(s, "map_Kd")).transpose()?,
            bump: m.bump.as_ref().map(|s| load(s, "bump")).transpose()?,
        };
        let file = lib
            .path
            .file_name()
            .map_or_else(String::new, |f| f.to_string_lossy().into_owned());
        let name = format!("{file}:{}", m.name);
        let mapped = mtl::to_material(lib, m, name, &tex, self.budget)?;
        let k = u16::try_from(materials.len())
            .ok()
            .filter(|&k| k < u16::MAX)
            .ok_or_else(|| LoadError::Mesh {
                path: lib.path.clone(),
                line: Some(m.line as usize),
                message: "too many materials (at most 65535, the scene's and the OBJ libraries' together)".into(),
            })?;
        materials.push(mapped);
        self.library_materials.insert(key, k);
        Ok(k)
    }

    fn scene(mut self, root: &Table<'_, '_>) -> Result<Scene, LoadError> {
        let path = root.path().to_path_buf();
        let image = self.image(root)?;
        let camera = self.camera(root, &image)?;
        let render = self.render(root)?;
        let lights = self.lights(root)?;
        let (mut materials, names) = self.materials(root)?;
        let objects = self.objects(root, &mut materials, &names)?;
        let raster = self.raster(root)?;
        let ray = self.ray(root)?;
        let tolerance = self.tolerance(root)?;
        root.finish()?;
        // Checked after the unknown keys, so that a misspelt `[[object]]`
        // is reported as such. The place is the empty `objects = []`, or
        // the top level, where every missing table is reported.
        if objects.is_empty() {
            let message = "the scene has no objects; add at least one [[objects]] entry";
            return Err(match root.span_of("objects") {
                Some(span) => root.err(&span, "objects", message),
                None => root.err_here("objects", message),
            });
        }
        Ok(Scene {
            path,
            image,
            camera,
            render,
            lights,
            materials,
            objects,
            raster,
            ray,
            tolerance,
            warnings: self.warnings,
        })
    }

    fn image(&mut self, root: &Table<'_, '_>) -> Result<ImageSettings, LoadError> {
        let t = root.table("image")?.ok_or_else(|| root.missing("image"))?;
        let side = |key: &'static str| -> Result<u32, LoadError> {
            let v = t.int(key)?.ok_or_else(|| t.missing(key))?;
            u32::try_from(v.value)
                .ok()
                .filter(|s| (1..=MAX_IMAGE_SIDE).contains(s))
                .ok_or_else(|| {
                    t.err(
                        &v.span,
                        key,
                        format!("expected 1 … {MAX_IMAGE_SIDE}, got {}", v.value),
                    )
                })
        };
        let width = side("width")?;
        let height = side("height")?;
        let background = match t.vec3("background")? {
            Some(v) => {
                check_nonneg_rgb(&t, "background", &v)?;
                rgb_of(v.value)
            }
            None => Rgb::BLACK,
        };
        let samples = match t.int("samples")? {
            Some(v) => u32::try_from(v.value)
                .ok()
                .filter(|s| rendiff_core::coverage::SAMPLES_PER_SIDE.contains(s))
                .ok_or_else(|| {
                    t.err(
                        &v.span,
                        "samples",
                        format!("expected 1, 2, 4, 8 or 16, got {}", v.value),
                    )
                })?,
            None => 1,
        };
        t.finish()?;
        Ok(ImageSettings {
            width,
            height,
            background,
            samples,
        })
    }

    /// `[camera]`: the projection, the view (eye, look_at, up) and the
    /// near and far distances, read and checked in that order.
    fn camera(
        &mut self,
        root: &Table<'_, '_>,
        image: &ImageSettings,
    ) -> Result<CameraSettings, LoadError> {
        let t = root
            .table("camera")?
            .ok_or_else(|| root.missing("camera"))?;
        let perspective = Self::is_perspective(&t)?;
        let eye = t.req_vec3("eye")?;
        check_coord(&t, "eye", &eye)?;
        let look_at = t.req_vec3("look_at")?;
        check_coord(&t, "look_at", &look_at)?;
        let up = t.req_vec3("up")?;
        let fov = t.f64("fov_y")?;
        let vh = t.f64("view_height")?;
        let eye_extent = eye.value.abs().max_element();
        let projection = if perspective {
            Self::perspective(&t, fov.as_ref(), vh.as_ref(), eye_extent, image)?
        } else {
            Self::orthographic(&t, fov.as_ref(), vh.as_ref(), eye_extent, image)?
        };
        Self::check_view(&t, &eye, &look_at, &up)?;
        let (near, far) = Self::near_far(&t)?;
        t.finish()?;
        Ok(CameraSettings {
            projection,
            eye: eye.value,
            look_at: look_at.value,
            up: up.value,
            near,
            far,
        })
    }

    /// `camera.projection`: `true` for "perspective" (the default), `false`
    /// for "orthographic".
    fn is_perspective(t: &Table<'_, '_>) -> Result<bool, LoadError> {
        match t.string("projection")? {
            None => Ok(true),
            Some(p) if p.value == "perspective" => Ok(true),
            Some(p) if p.value == "orthographic" => Ok(false),
            Some(p) => Err(t.err(
                &p.span,
                "projection",
                format!(
                    "expected \"perspective\" or \"orthographic\", got \"{}\"",
                    p.value
                ),
            )),
        }
    }

    /// A perspective projection from `fov_y` (required, `view_height`
    /// refused), checked against the image resolution at the eye's
    /// largest coordinate `eye_extent`.
    fn perspective(
        t: &Table<'_, '_>,
        fov: Option<&At<f64>>,
        vh: Option<&At<f64>>,
        eye_extent: f64,
        image: &ImageSettings,
    ) -> Result<ProjectionDesc, LoadError> {
        if let Some(v) = vh {
            return Err(t.err(
                &v.span,
                "view_height",
                "view_height is only for projection = \"orthographic\"; a perspective camera uses fov_y",
            ));
        }
        let fov = fov.ok_or_else(|| t.missing("fov_y"))?;
        if !(fov.value > 0.0 && fov.value < 180.0) {
            return Err(t.err(
                &fov.span,
                "fov_y",
                format!("expected 0 < fov_y < 180 (degrees), got {}", num(fov.value)),
            ));
        }
        let tan_half_fov = (fov.value.to_radians() / 2.0).tan();
        if let Some((_, m)) = rendiff_core::camera::resolution_problem(
            rendiff_core::camera::Projection::Perspective { tan_half_fov },
            eye_extent,
            image.width,
            image.height,
        ) {
            return Err(t.err(&fov.span, "fov_y", m));
        }
        Ok(ProjectionDesc::Perspective {
            fov_y_deg: fov.value,
        })
    }

    /// An orthographic projection from `view_height` (required, `fov_y`
    /// refused), checked against the image resolution at the eye's
    /// largest coordinate `eye_extent`.
    fn orthographic(
        t: &Table<'_, '_>,
        fov: Option<&At<f64>>,
        vh: Option<&At<f64>>,
        eye_extent: f64,
        image: &ImageSettings,
    ) -> Result<ProjectionDesc, LoadError> {
        if let Some(v) = fov {
            return Err(t.err(
                &v.span,
                "fov_y",
                "fov_y is only for projection = \"perspective\"; an orthographic camera uses view_height",
            ));
        }
        let vh = vh.ok_or_else(|| t.missing("view_height"))?;
        if vh.value <= 0.0 {
            return Err(t.err(
                &vh.span,
                "view_height",
                format!("expected > 0, got {}", num(vh.value)),
            ));
        }
        if let Some((_, m)) = rendiff_core::camera::resolution_problem(
            rendiff_core::camera::Projection::Orthographic {
                view_height: vh.value,
            },
            eye_extent,
            image.width,
            image.height,
        ) {
            return Err(t.err(&vh.span, "view_height", m));
        }
        Ok(ProjectionDesc::Orthographic {
            view_height: vh.value,
        })
    }

    /// The view is defined: `look_at` is away from `eye`, and `up` is
    /// neither zero nor parallel to the view direction.
    fn check_view(
        t: &Table<'_, '_>,
        eye: &At<DVec3>,
        look_at: &At<DVec3>,
        up: &At<DVec3>,
    ) -> Result<(), LoadError> {
        let Some(f) = (look_at.value - eye.value).try_normalize() else {
            let why = if look_at.value == eye.value {
                "look_at equals eye"
            } else {
                "look_at is too close to eye"
            };
            return Err(t.err(
                &look_at.span,
                "look_at",
                format!("{why}; the view direction is undefined"),
            ));
        };
        // Scaled to its largest component: `[0, 1e308, 1e308]` is a
        // direction (its length would overflow).
        let big = up.value.abs().max_element();
        let up_dir = if big > 0.0 { up.value / big } else { up.value };
        if big == 0.0 || f.cross(up_dir).length() <= 1e-9 * up_dir.length() {
            return Err(t.err(
                &up.span,
                "up",
                "up is zero or parallel to the view direction (look_at − eye)",
            ));
        }
        Ok(())
    }

    /// `camera.near` (default 0.01) and `camera.far` (default `None`: from
    /// the scene bounds).
    fn near_far(t: &Table<'_, '_>) -> Result<(f64, Option<f64>), LoadError> {
        // near is a distance in the scene: bounded like coordinates, so
        // the default far (at least 2·near) stays finite.
        let near = match t.f64("near")? {
            Some(n) if n.value > 0.0 && n.value <= MAX_COORDINATE => n.value,
            Some(n) => {
                return Err(t.err(
                    &n.span,
                    "near",
                    format!(
                        "expected 0 < near ≤ {MAX_COORDINATE:e}, got {}",
                        num(n.value)
                    ),
                ));
            }
            None => 0.01,
        };
        let far = match t.f64("far")? {
            Some(f) if f.value > near => Some(f.value),
            Some(f) => {
                return Err(t.err(
                    &f.span,
                    "far",
                    format!("expected far > near ({}), got {}", num(near), num(f.value)),
                ));
            }
            None => None,
        };
        Ok((near, far))
    }

    fn render(&mut self, root: &Table<'_, '_>) -> Result<RenderSettings, LoadError> {
        let mut r = RenderSettings {
            ambient_light: Rgb::WHITE,
            max_depth: 5,
            tessellation_error: 0.25,
        };
        let Some(t) = root.table("render")? else {
            return Ok(r);
        };
        if let Some(v) = t.vec3("ambient_light")? {
            check_nonneg_rgb(&t, "ambient_light", &v)?;
            r.ambient_light = rgb_of(v.value);
        }
        if let Some(v) = t.int("max_depth")? {
            r.max_depth = u32::try_from(v.value)
                .ok()
                .filter(|d| (1..=64).contains(d))
                .ok_or_else(|| {
                    t.err(
                        &v.span,
                        "max_depth",
                        format!("expected 1 … 64, got {}", v.value),
                    )
                })?;
        }
        if let Some(v) = t.f64("tessellation_error")? {
            if v.value <= 0.0 {
                return Err(t.err(
                    &v.span,
                    "tessellation_error",
                    format!("expected > 0 (pixels), got {}", num(v.value)),
                ));
            }
            r.tessellation_error = v.value;
        }
        t.finish()?;
        Ok(r)
    }

    /// `[[lights]]`: at most 31.
    fn lights(&mut self, root: &Table<'_, '_>) -> Result<Vec<Light>, LoadError> {
        let Some((arr, _)) = root.array("lights")? else {
            return Ok(Vec::new());
        };
        let mut lights = Vec::new();
        for (i, item) in arr.iter().enumerate() {
            let DeValue::Table(tt) = item.get_ref() else {
                return Err(root.err(
                    &item.span(),
                    &format!("lights[{i}]"),
                    "expected a table ([[lights]])",
                ));
            };
            let t = Table::new(root.source(), format!("lights[{i}]"), tt, item.span());
            let kind = t.req_string("kind")?;
            let color = t.req_vec3("color")?;
            check_nonneg_rgb(&t, "color", &color)?;
            let shadowless = t.bool("shadowless")?.is_some_and(|b| b.value);
            let fd = t.f64("fade_distance")?;
            let fp = t.f64("fade_power")?;
            let kind = Self::light_kind(&t, &kind, fd.as_ref(), fp.as_ref())?;
            let fade = Self::fade(&t, fd, fp)?;
            t.finish()?;
            lights.push(Light {
                kind,
                color: rgb_of(color.value),
                shadowless,
                fade,
            });
        }
        if lights.len() > 31 {
            return Err(root.err_here("lights", format!("at most 31 lights are supported (the shading flags have 31 shadow bits), got {}", lights.len())));
        }
        Ok(lights)
    }

    /// A light's `kind`: a point light's `position` or a parallel light's
    /// `direction` (which refuses the fade keys `fd` and `fp`).
    fn light_kind(
        t: &Table<'_, '_>,
        kind: &At<String>,
        fd: Option<&At<f64>>,
        fp: Option<&At<f64>>,
    ) -> Result<LightKind, LoadError> {
        match kind.value.as_str() {
            "point" => {
                let p = t.req_vec3("position")?;
                check_coord(t, "position", &p)?;
                Ok(LightKind::Point {
                    position: to_f32(p.value),
                })
            }
            "parallel" => {
                let d = t.req_vec3("direction")?;
                if d.value.length() == 0.0 {
                    return Err(t.err(&d.span, "direction", "the direction must be non-zero"));
                }
                if let Some(f) = fd.or(fp) {
                    return Err(t.err(
                        &f.span,
                        if fd.is_some() {
                            "fade_distance"
                        } else {
                            "fade_power"
                        },
                        "fade_distance and fade_power are only for point lights; this light is parallel",
                    ));
                }
                Ok(LightKind::Parallel {
                    direction: to_f32(d.value.normalize()),
                })
            }
            other => Err(t.err(
                &kind.span,
                "kind",
                format!("expected \"point\" or \"parallel\", got \"{other}\""),
            )),
        }
    }

    /// A light's fade: `fade_distance` and `fade_power` both given (each
    /// above 0), or neither.
    fn fade(
        t: &Table<'_, '_>,
        fd: Option<At<f64>>,
        fp: Option<At<f64>>,
    ) -> Result<Option<(f32, f32)>, LoadError> {
        match (fd, fp) {
            (None, None) => Ok(None),
            (Some(d), Some(p)) => {
                for (v, key) in [(&d, "fade_distance"), (&p, "fade_power")] {
                    if v.value <= 0.0 {
                        return Err(t.err(
                            &v.span,
                            key,
                            format!("expected > 0, got {}", num(v.value)),
                        ));
                    }
                }
                #[expect(
                    clippy::cast_possible_truncation,
                    reason = "validated finite light parameters"
                )]
                Ok(Some((d.value as f32, p.value as f32)))
            }
            (Some(v), None) => Err(t.err(
                &v.span,
                "fade_distance",
                "fade_distance is given without fade_power; give both or neither",
            )),
            (None, Some(v)) => Err(t.err(
                &v.span,
                "fade_power",
                "fade_power is given without fade_distance; give both or neither",
            )),
        }
    }

    fn materials(
        &mut self,
        root: &Table<'_, '_>,
    ) -> Result<(Vec<Material>, Vec<String>), LoadError> {
        let Some(t) = root.table("materials")? else {
            return Ok((Vec::new(), Vec::new()));
        };
        let mut out = Vec::new();
        let mut names = Vec::new();
        for (key, value) in t.entries() {
            let name: &str = key.get_ref().as_ref();
            let DeValue::Table(mt) = value.get_ref() else {
                return Err(LoadError::key(
                    root.path(),
                    root.loc(&value.span()),
                    format!("materials.{name}"),
                    "expected a table of finish keys",
                ));
            };
            let m = Table::new(root.source(), format!("materials.{name}"), mt, value.span());
            if name == OBJ_MATERIALS {
                return Err(LoadError::key(
                    root.path(),
                    root.loc(&key.span()),
                    format!("materials.{name}"),
                    format!(
                        "the name \"{OBJ_MATERIALS}\" is reserved: `material = \"{OBJ_MATERIALS}\"` gives a mesh its OBJ file's own materials; rename this material"
                    ),
                ));
            }
            out.push(self.material(&m, name)?);
            names.push(name.to_string());
        }
        if out.len() > usize::from(u16::MAX) {
            return Err(root.err_here("materials", "too many materials (at most 65535)"));
        }
        Ok((out, names))
    }

    /// `[materials.NAME]`: the pigment, the finish numbers (then their
    /// joint checks) and the bump map, read in that order.
    fn material(&mut self, t: &Table<'_, '_>, name: &str) -> Result<Material, LoadError> {
        let mut m = Material {
            name: name.to_string(),
            ..Material::default()
        };
        if let Some(pigment) = self.pigment(t)? {
            m.pigment = pigment;
        }
        let written = Self::finish_values(t, &mut m)?;
        Self::check_finish(t, &m, &written)?;
        if let Some(bt) = t.table("bump")? {
            m.bump = Some(self.bump(&bt)?);
        }
        t.finish()?;
        Ok(m)
    }

    /// `pigment`: a colour `[r, g, b]` or `{ image = "file.png" }`; `None`
    /// when it is not given (the default pigment stays).
    fn pigment(&mut self, t: &Table<'_, '_>) -> Result<Option<Pigment>, LoadError> {
        if !t.has("pigment") {
            return Ok(None);
        }
        let span = t.span_of("pigment").unwrap_or_default();
        if let Some(pt) = t.table("pigment").ok().flatten() {
            let file = pt.req_string("image")?;
            pt.finish()?;
            return Ok(Some(Pigment::Image(self.texture(&pt, "image", &file)?)));
        }
        let v = t.vec3("pigment").map_err(|_| {
            t.err(
                &span,
                "pigment",
                "expected a colour [r, g, b] or { image = \"file.png\" }",
            )
        })?;
        let Some(v) = v else {
            return Ok(None);
        };
        check_nonneg_rgb(t, "pigment", &v)?;
        Ok(Some(Pigment::Color(rgb_of(v.value))))
    }

    /// The finish numbers (`ambient` … `emission`), each ≥ 0 and within
    /// f32, stored into `m`; returns where each given one was written and
    /// its value as written.
    fn finish_values(t: &Table<'_, '_>, m: &mut Material) -> Result<Written, LoadError> {
        let mut spans = HashMap::new();
        let mut set = |key: &'static str, slot: &mut f32| -> Result<(), LoadError> {
            if let Some(v) = t.f64(key)? {
                if v.value < 0.0 {
                    return Err(t.err(&v.span, key, format!("expected ≥ 0, got {}", num(v.value))));
                }
                if v.value > f64::from(f32::MAX) {
                    return Err(t.err(&v.span, key, "exceeds the f32 range"));
                }
                #[expect(
                    clippy::cast_possible_truncation,
                    reason = "checked to be within f32 range"
                )]
                {
                    *slot = v.value as f32;
                }
                spans.insert(key, (v.span, v.value));
            }
            Ok(())
        };
        set("ambient", &mut m.ambient)?;
        set("diffuse", &mut m.diffuse)?;
        set("brilliance", &mut m.brilliance)?;
        set("phong", &mut m.phong)?;
        set("phong_size", &mut m.phong_size)?;
        set("specular", &mut m.specular)?;
        set("roughness", &mut m.roughness)?;
        set("metallic", &mut m.metallic)?;
        set("reflection", &mut m.reflection)?;
        set("filter", &mut m.filter)?;
        set("transmit", &mut m.transmit)?;
        set("ior", &mut m.ior)?;
        set("emission", &mut m.emission)?;
        Ok(spans)
    }

    /// The checks across finish numbers: roughness and ior above 0,
    /// filter + transmit ≤ 1, and no filter/transmit with an image pigment
    /// that has an alpha channel. `spans` is what
    /// `finish_values` returned.
    fn check_finish(t: &Table<'_, '_>, m: &Material, spans: &Written) -> Result<(), LoadError> {
        let here = |key: &str| spans.get(key).map(|s| s.0.clone()).unwrap_or_default();
        let written = |key: &str, default: f32| spans.get(key).map_or(f64::from(default), |s| s.1);
        // A positive value that is 0 once stored in f32 must not read "got 1e-50".
        let shown = |key: &str, stored: f32| {
            let w = written(key, stored);
            if w > 0.0 && stored == 0.0 {
                format!("{}, which is 0 in f32", num(w))
            } else {
                num(w)
            }
        };
        if m.roughness <= 0.0 {
            return Err(t.err(
                &here("roughness"),
                "roughness",
                format!(
                    "expected > 0 (the specular exponent is 1/roughness), got {}",
                    shown("roughness", m.roughness)
                ),
            ));
        }
        if m.ior <= 0.0 {
            return Err(t.err(
                &here("ior"),
                "ior",
                format!("expected > 0, got {}", shown("ior", m.ior)),
            ));
        }
        if m.filter + m.transmit > 1.0 {
            let key = if spans.contains_key("transmit") {
                "transmit"
            } else {
                "filter"
            };
            return Err(t.err(
                &here(key),
                key,
                format!(
                    "expected filter + transmit ≤ 1, got {} + {}",
                    num(written("filter", m.filter)),
                    num(written("transmit", m.transmit))
                ),
            ));
        }
        if let Pigment::Image(tex) = &m.pigment
            && tex.has_alpha()
            && m.filter + m.transmit > 0.0
        {
            let key = if spans.contains_key("transmit") {
                "transmit"
            } else {
                "filter"
            };
            return Err(t.err(&here(key), key, "an image pigment with an alpha channel sets transmit = 1 − alpha itself; remove filter/transmit or the alpha channel"));
        }
        Ok(())
    }

    /// `bump = { image, size, method }`: its keys are checked before the
    /// image is loaded.
    fn bump(&mut self, bt: &Table<'_, '_>) -> Result<Bump, LoadError> {
        let file = bt.req_string("image")?;
        let size = match bt.f64("size")? {
            Some(s) => {
                if s.value.abs() > MAX_BUMP_SIZE {
                    return Err(bt.err(
                        &s.span,
                        "size",
                        format!(
                            "expected a bump size within ±{MAX_BUMP_SIZE:e}, got {}",
                            num(s.value)
                        ),
                    ));
                }
                #[expect(clippy::cast_possible_truncation, reason = "bounded bump size")]
                let v = s.value as f32;
                v
            }
            None => 1.0,
        };
        let method = match bt.string("method")? {
            None => BumpMethod::Blinn,
            Some(s) if s.value == "blinn" => BumpMethod::Blinn,
            Some(s) if s.value == "pov" => BumpMethod::Pov,
            Some(s) => {
                return Err(bt.err(
                    &s.span,
                    "method",
                    format!("expected \"blinn\" or \"pov\", got \"{}\"", s.value),
                ));
            }
        };
        bt.finish()?;
        let texture = self.texture(bt, "image", &file)?;
        Ok(Bump {
            texture,
            size,
            method,
        })
    }

    fn objects(
        &mut self,
        root: &Table<'_, '_>,
        materials: &mut Vec<Material>,
        names: &[String],
    ) -> Result<Vec<Object>, LoadError> {
        let Some((arr, _)) = root.array("objects")? else {
            return Ok(Vec::new());
        };
        let mut out = Vec::new();
        for (i, item) in arr.iter().enumerate() {
            let DeValue::Table(tt) = item.get_ref() else {
                return Err(root.err(
                    &item.span(),
                    &format!("objects[{i}]"),
                    "expected a table ([[objects]])",
                ));
            };
            let t = Table::new(root.source(), format!("objects[{i}]"), tt, item.span());
            out.push(self.object(&t, i, materials, names)?);
        }
        Ok(out)
    }

    fn transform(
        &mut self,
        t: &Table<'_, '_>,
    ) -> Result<(Vec<TransformStep>, Transform), LoadError> {
        let Some((arr, span)) = t.array("transform")? else {
            return Ok((Vec::new(), Transform::IDENTITY));
        };
        let mut steps = Vec::new();
        for (k, item) in arr.iter().enumerate() {
            let DeValue::Table(st) = item.get_ref() else {
                return Err(t.err(
                    &item.span(),
                    &format!("transform[{k}]"),
                    "expected { scale = [x,y,z] }, { rotate = [x,y,z] } or { translate = [x,y,z] }",
                ));
            };
            let s = Table::new(
                t.source(),
                t.key_name(&format!("transform[{k}]")),
                st,
                item.span(),
            );
            let scale = s.vec3("scale")?;
            let rotate = s.vec3("rotate")?;
            let translate = s.vec3("translate")?;
            s.finish()?;
            let step = match (scale, rotate, translate) {
                (Some(v), None, None) => TransformStep::Scale(v.value),
                (None, Some(v), None) => TransformStep::Rotate(v.value),
                (None, None, Some(v)) => {
                    check_coord(&s, "translate", &v)?;
                    TransformStep::Translate(v.value)
                }
                _ => {
                    return Err(t.err(
                        &item.span(),
                        &format!("transform[{k}]"),
                        "each entry needs exactly one of scale, rotate or translate",
                    ));
                }
            };
            steps.push(step);
        }
        let tr = Transform::from_steps(&steps).ok_or_else(|| {
            t.err(
                &span,
                "transform",
                "the transform is singular (a zero or vanishing scale); it must be invertible",
            )
        })?;
        Ok((steps, tr))
    }

    /// One `[[objects]]` entry: kind, material, transform and flags, then
    /// the shape of that kind, its tessellation, and the checks that the
    /// material suits the shape.
    fn object(
        &mut self,
        t: &Table<'_, '_>,
        index: usize,
        materials: &mut Vec<Material>,
        names: &[String],
    ) -> Result<Object, LoadError> {
        let kind = t.req_string("kind")?;
        let mat_name = t.req_string("material")?;
        let own = mat_name.value == OBJ_MATERIALS;
        let material = if own {
            0
        } else {
            Self::material_index(t, &mat_name, names)?
        };
        let (steps, transform) = self.transform(t)?;
        let no_shadow = t.bool("no_shadow")?.is_some_and(|b| b.value);
        let tess = t.int("tessellation")?;
        let mut shape = self.shape(t, &kind)?;
        let tessellation = Self::tessellation(t, tess, &shape)?;
        t.finish()?;
        let material = if own {
            let Shape::Mesh {
                data,
                face_materials,
                ..
            } = &mut shape
            else {
                return Err(t.err(
                    &mat_name.span,
                    "material",
                    format!(
                        "material = \"{OBJ_MATERIALS}\" gives a mesh its OBJ file's own materials; this object is a {}",
                        shape.kind()
                    ),
                ));
            };
            let (faces, primary) = self.obj_materials(t, &mat_name, data, materials)?;
            *face_materials = Some(faces);
            usize::from(primary)
        } else {
            Self::check_material_fits(t, &materials[material], &mat_name, &shape)?;
            material
        };
        let loc = t.start();
        #[expect(
            clippy::cast_possible_truncation,
            reason = "material count is checked ≤ u16::MAX"
        )]
        let material = material as u16;
        Ok(Object {
            index,
            loc,
            shape,
            material,
            steps,
            transform,
            no_shadow,
            tessellation,
        })
    }

    /// The index of the material `mat_name` among `names`, or an error
    /// listing the defined ones.
    fn material_index(
        t: &Table<'_, '_>,
        mat_name: &At<String>,
        names: &[String],
    ) -> Result<usize, LoadError> {
        names
            .iter()
            .position(|n| *n == mat_name.value)
            .ok_or_else(|| {
                let known = if names.is_empty() {
                    "none are defined".to_string()
                } else {
                    names.join(", ")
                };
                t.err(
                    &mat_name.span,
                    "material",
                    format!("unknown material \"{}\" (defined: {known})", mat_name.value),
                )
            })
    }

    /// The shape of an object, read by its `kind`.
    fn shape(&mut self, t: &Table<'_, '_>, kind: &At<String>) -> Result<Shape, LoadError> {
        match kind.value.as_str() {
            "mesh" => self.mesh(t),
            "sphere" => Self::sphere(t),
            "box" => Self::box_shape(t),
            "polygon" => self.polygon(t),
            "superellipsoid" => Self::superellipsoid(t),
            other => Err(t.err(
                &kind.span,
                "kind",
                format!("expected mesh, sphere, box, polygon or superellipsoid, got \"{other}\""),
            )),
        }
    }

    /// `kind = "mesh"`: `file` (loaded once per canonical path, within the
    /// budget) and `smooth`.
    fn mesh(&mut self, t: &Table<'_, '_>) -> Result<Shape, LoadError> {
        let file = t.req_string("file")?;
        let smooth = t.bool("smooth")?.is_some_and(|b| b.value);
        let path = self.resolve(&file.value);
        let read_err = |e: std::io::Error| {
            t.err(
                &file.span,
                "file",
                format!("could not read mesh {}: {e}", path.display()),
            )
        };
        let canonical = std::fs::canonicalize(&path).map_err(read_err)?;
        let data = if let Some(d) = self.meshes.get(&canonical) {
            d.clone()
        } else {
            let bytes = self.read_within(&path, "mesh").map_err(|e| match e {
                ReadError::Io(e) => read_err(e),
                ReadError::Budget(e) => LoadError::Mesh {
                    path: path.clone(),
                    line: None,
                    message: e.to_string(),
                },
            })?;
            let d = Arc::new(obj::load_obj_within(&path, &bytes, self.budget)?);
            self.budget.release(bytes.len() as u64);
            self.meshes.insert(canonical, d.clone());
            d
        };
        Ok(Shape::Mesh {
            data,
            smooth,
            face_materials: None,
        })
    }

    /// `kind = "sphere"`: `center` and `radius`.
    fn sphere(t: &Table<'_, '_>) -> Result<Shape, LoadError> {
        let c = t.req_vec3("center")?;
        check_coord(t, "center", &c)?;
        let r = t.req_f64("radius")?;
        if r.value <= 0.0 || r.value > MAX_COORDINATE {
            return Err(t.err(
                &r.span,
                "radius",
                format!(
                    "expected 0 < radius ≤ {MAX_COORDINATE:e}, got {}",
                    num(r.value)
                ),
            ));
        }
        Ok(Shape::Sphere {
            center: c.value,
            radius: r.value,
        })
    }

    /// `kind = "box"`: `min` and `max`, with min < max on every axis.
    fn box_shape(t: &Table<'_, '_>) -> Result<Shape, LoadError> {
        let lo = t.req_vec3("min")?;
        let hi = t.req_vec3("max")?;
        check_coord(t, "min", &lo)?;
        check_coord(t, "max", &hi)?;
        if let Some(axis) = (0..3).find(|&k| lo.value[k] >= hi.value[k]) {
            return Err(t.err(
                &hi.span,
                "max",
                format!(
                    "expected min < max on every axis (a box needs a positive size), but on {} min = {} and max = {}",
                    ["x", "y", "z"][axis],
                    num(lo.value[axis]),
                    num(hi.value[axis])
                ),
            ));
        }
        Ok(Shape::Box {
            min: lo.value,
            max: hi.value,
        })
    }

    /// `kind = "superellipsoid"`: `exponents = [e, n]`, each in (0, 4].
    fn superellipsoid(t: &Table<'_, '_>) -> Result<Shape, LoadError> {
        let ex = t
            .floats::<2>("exponents")?
            .ok_or_else(|| t.missing("exponents"))?;
        let [e, n] = ex.value;
        if !(e > 0.0 && e <= 4.0 && n > 0.0 && n <= 4.0) {
            return Err(t.err(
                &ex.span,
                "exponents",
                format!("expected 0 < e, n ≤ 4, got [{}, {}]", num(e), num(n)),
            ));
        }
        Ok(Shape::Superellipsoid { e, n })
    }

    /// `tessellation` (read before the shape): only for spheres and
    /// superellipsoids, 3 … 4096 segments.
    fn tessellation(
        t: &Table<'_, '_>,
        tess: Option<At<i64>>,
        shape: &Shape,
    ) -> Result<Option<u32>, LoadError> {
        let Some(v) = tess else {
            return Ok(None);
        };
        if !matches!(shape, Shape::Sphere { .. } | Shape::Superellipsoid { .. }) {
            return Err(t.err(
                &v.span,
                "tessellation",
                format!(
                    "only spheres and superellipsoids are tessellated; remove it from this {}",
                    shape.kind()
                ),
            ));
        }
        let n = u32::try_from(v.value)
            .ok()
            .filter(|n| (3..=4096).contains(n))
            .ok_or_else(|| {
                t.err(
                    &v.span,
                    "tessellation",
                    format!("expected 3 … 4096 segments, got {}", v.value),
                )
            })?;
        Ok(Some(n))
    }

    /// The material `mat` suits the shape: an image (pigment or bump)
    /// needs uv coordinates, and refraction needs a closed shape (not a
    /// polygon). Errors point at `material`.
    fn check_material_fits(
        t: &Table<'_, '_>,
        mat: &Material,
        mat_name: &At<String>,
        shape: &Shape,
    ) -> Result<(), LoadError> {
        let has_uv = match shape {
            Shape::Mesh { data, .. } => data.has_uv(),
            Shape::Sphere { .. } => true,
            Shape::Polygon(p) => p.uv.is_some(),
            Shape::Box { .. } | Shape::Superellipsoid { .. } => false,
        };
        if mat.needs_uv() && !has_uv {
            let why = match shape {
                Shape::Mesh { data, .. } => format!(
                    "the mesh {} has no uv (vt) on every face{}",
                    data.path.display(),
                    data.first_face_without_uv()
                        .map(|l| format!(" (first face without: line {l})"))
                        .unwrap_or_default()
                ),
                Shape::Polygon(_) => "the polygon has no `uv`".to_string(),
                s => format!("a {} has no uv coordinates", s.kind()),
            };
            return Err(t.err(
                &mat_name.span,
                "material",
                format!(
                    "material \"{}\" uses an image (pigment or bump) but {why}",
                    mat.name
                ),
            ));
        }
        let refracts = mat.ior != 1.0 && mat.is_transparent();
        if refracts && matches!(shape, Shape::Polygon(_)) {
            return Err(t.err(&mat_name.span, "material", format!("material \"{}\" refracts (ior ≠ 1 with filter/transmit) but a polygon is not closed; refraction needs an inside", mat.name)));
        }
        Ok(())
    }

    /// The points of a ring, with the span of each.
    fn points(
        &self,
        t: &Table<'_, '_>,
        key: &str,
        v: &toml::Spanned<DeValue<'_>>,
    ) -> Result<(Vec<DVec3>, Vec<reader::Span>), LoadError> {
        let DeValue::Array(items) = v.get_ref() else {
            return Err(t.err(&v.span(), key, "expected an array of [x, y, z] points"));
        };
        let mut out = Vec::with_capacity(items.len());
        let mut spans = Vec::with_capacity(items.len());
        for (k, item) in items.iter().enumerate() {
            let here = format!("{key}[{k}]");
            let p = reader::floats_of::<3>(item).map_err(|m| t.err(&item.span(), &here, m))?;
            let p = DVec3::from_array(p);
            if p.abs().max_element() > MAX_COORDINATE {
                return Err(t.err(
                    &item.span(),
                    &here,
                    format!("coordinates must be within ±{MAX_COORDINATE:e}"),
                ));
            }
            out.push(p);
            spans.push(item.span());
        }
        Ok((out, spans))
    }

    /// A polygon's `uv`: one `[u, v]` pair per point, each within ±MAX_UV;
    /// `None` when not given.
    fn polygon_uv(t: &Table<'_, '_>) -> Result<Option<Vec<[f64; 2]>>, LoadError> {
        let Some((uarr, _)) = t.array("uv")? else {
            return Ok(None);
        };
        let mut uv = Vec::new();
        for (k, item) in uarr.iter().enumerate() {
            let pair = reader::floats_of::<2>(item)
                .map_err(|m| t.err(&item.span(), &format!("uv[{k}]"), m))?;
            if pair.iter().any(|c| c.abs() > MAX_UV) {
                return Err(t.err(
                    &item.span(),
                    &format!("uv[{k}]"),
                    format!(
                        "texture coordinates must lie within ±{MAX_UV:e} (f32 resolves larger ones to a sixteenth of a repeat or worse), got [{}, {}]",
                        num(pair[0]),
                        num(pair[1])
                    ),
                ));
            }
            uv.push(pair);
        }
        Ok(Some(uv))
    }

    fn polygon(&mut self, t: &Table<'_, '_>) -> Result<Shape, LoadError> {
        let (pts_arr, pts_span) = t.array("points")?.ok_or_else(|| t.missing("points"))?;
        let pts_value = toml::Spanned::new(pts_span.clone(), DeValue::Array(pts_arr.clone()));
        let (outline, outline_spans) = self.points(t, "points", &pts_value)?;
        let mut holes = Vec::new();
        // Per hole: the span of the hole and of each of its points.
        let mut hole_spans = Vec::new();
        if let Some((harr, _)) = t.array("holes")? {
            for (k, h) in harr.iter().enumerate() {
                let (pts, spans) = self.points(t, &format!("holes[{k}]"), h)?;
                holes.push(pts);
                hole_spans.push((h.span(), spans));
            }
        }
        let uv = Self::polygon_uv(t)?;
        let tri =
            polygon::triangulate(
                &outline,
                &holes,
                PolygonOptions {
                    check_planarity: true,
                },
            )
            .map_err(|e| {
                // Point at the ring or the point the problem is about.
                let ring = |hole: Option<usize>| match hole {
                    None => ("points".to_string(), pts_span.clone()),
                    Some(h) => (format!("holes[{h}]"), hole_spans[h].0.clone()),
                };
                let point = |p: PointRef| match p.hole {
                    None => (
                        format!("points[{}]", p.index),
                        outline_spans[p.index].clone(),
                    ),
                    Some(h) => (
                        format!("holes[{h}][{}]", p.index),
                        hole_spans[h].1[p.index].clone(),
                    ),
                };
                let (key, span) =
                    match &e {
                        PolygonError::NotFinite { point: p }
                        | PolygonError::NotPlanar { point: p, .. } => point(*p),
                        PolygonError::SelfIntersecting { b, .. } => point(b.start()),
                        PolygonError::TooFewPoints { hole, .. }
                        | PolygonError::Spike { hole, .. } => ring(*hole),
                        PolygonError::HoleOutside { hole }
                        | PolygonError::HoleInHole { hole, .. } => ring(Some(*hole)),
                        _ => ring(None),
                    };
                t.err(&span, &key, format!("invalid polygon: {e}"))
            })?;
        let mut points = outline.clone();
        let mut ring_sizes = vec![outline.len()];
        for h in &holes {
            points.extend_from_slice(h);
            ring_sizes.push(h.len());
        }
        if let Some(uv) = &uv {
            let span = t.span_of("uv").unwrap_or_default();
            polygon::check_uv_affine(&points, uv, tri.normal)
                .map_err(|e| t.err(&span, "uv", e.to_string()))?;
        }
        Ok(Shape::Polygon(Arc::new(PolygonShape {
            points,
            ring_sizes,
            uv,
            triangles: tri.triangles,
            normal: tri.normal,
        })))
    }

    fn raster(&mut self, root: &Table<'_, '_>) -> Result<RasterSettings, LoadError> {
        let mut r = RasterSettings::default();
        let Some(t) = root.table("raster")? else {
            return Ok(r);
        };
        if let Some(v) = t.option("depth")? {
            r.depth = v;
        }
        if let Some(v) = t.option("shadows")? {
            r.shadows = v;
        }
        t.finish()?;
        Ok(r)
    }

    fn ray(&mut self, root: &Table<'_, '_>) -> Result<RaySettings, LoadError> {
        let mut r = RaySettings::default();
        let Some(t) = root.table("ray")? else {
            return Ok(r);
        };
        if let Some(v) = t.option("bvh")? {
            r.bvh = v;
        }
        if let Some(v) = t.option("geometry")? {
            r.geometry = v;
        }
        t.finish()?;
        Ok(r)
    }

    fn tolerance(&mut self, root: &Table<'_, '_>) -> Result<ToleranceSettings, LoadError> {
        let mut r = ToleranceSettings::default();
        let Some(t) = root.table("tolerance")? else {
            return Ok(r);
        };
        let get = |key: &'static str| -> Result<Option<Located>, LoadError> {
            Ok(match t.f64(key)? {
                Some(v) if v.value >= 0.0 => Some(Located {
                    value: v.value,
                    loc: t.loc(&v.span),
                }),
                Some(v) => {
                    return Err(t.err(&v.span, key, format!("expected ≥ 0, got {}", num(v.value))));
                }
                None => None,
            })
        };
        r.shading_max = get("shading_max")?;
        r.pov_max8 = get("pov_max8")?;
        r.pov_fraction = get("pov_fraction")?;
        if let Some(f) = t.table("fuzzy")? {
            let int = |key: &'static str, max: i64| -> Result<i64, LoadError> {
                let v = f.int(key)?.ok_or_else(|| f.missing(key))?;
                if !(0..=max).contains(&v.value) {
                    return Err(f.err(
                        &v.span,
                        key,
                        format!("expected an integer in 0 … {max}, got {}", v.value),
                    ));
                }
                Ok(v.value)
            };
            r.fuzzy = Some(FuzzySetting {
                max_diff: u8::try_from(int("max_diff", 255)?).unwrap_or(u8::MAX),
                pixels: u64::try_from(int("pixels", i64::MAX)?).unwrap_or(u64::MAX),
                loc: f.start(),
            });
            f.finish()?;
        }
        t.finish()?;
        Ok(r)
    }
}
