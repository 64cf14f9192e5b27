//! # rendiff
//!
//! One scene, two renderers, one verdict. A scanline z-buffer rasterizer
//! and a BVH ray tracer render the same triangulated scene, and rendiff
//! checks, sample by sample, that they see the same surfaces and shade them
//! alike; POV-Ray 3.7 renders of the same scenes are the outside reference.
//!
//! The data flow (DESIGN.md §1):
//!
//! ```text
//! scene.toml ─ Scene::load ─▶ Scene ─ tessellate ─▶ TriScene ─ plan ─▶ backend ─▶ Frame ─ compare ─▶ verdict
//! ```
//!
//! ```no_run
//! use rendiff::{Backend, Overrides, Prepared};
//! let job = Prepared::load("scenes/spheres.toml".as_ref(), &Overrides::default())?;
//! let frame = job.render(Backend::Ray)?.frame;
//! frame.write_png("out.png".as_ref(), rendiff::image_io::PngEncoding::Srgb8)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! See `ARCHITECTURE.md` for the conventions, the module map and its
//! one-way dependencies.

#![warn(missing_docs, missing_debug_implementations)]

pub mod compare;
pub mod diff;
#[cfg(feature = "testing")]
pub mod fuzz;
pub mod pov;
pub mod snapshot;

// The floors below, re-exported so a user depends on `rendiff` alone and
// reaches every part by one path (`rendiff::scene::Scene`,
// `rendiff::raster::render`). Cargo holds their direction: each crate
// depends only on those below it, and the backends not on each other.
pub use rendiff_accel as accel;
pub use rendiff_core::{
    analytic, budget, camera, cleanup, color, coverage, escape, frame, image_io, input, math,
    options, output, shade, texture, tri_scene,
};
pub use rendiff_lines as lines;
pub use rendiff_raster as raster;
pub use rendiff_ray as ray;
pub use rendiff_scene::{plan, polygon, scene, tessellate};

use std::fmt;
use std::path::Path;
use std::str::FromStr;
use std::time::Instant;

use accel::{Accel, AccelOptions};
use frame::Frame;
use options::{BvhMode, DepthFormat, Geometry, PainterSort, ShadowMode};
use plan::Plan;
use scene::{LoadError, Scene};
use tessellate::TessOptions;
use tri_scene::TriScene;

/// The renderers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Backend {
    /// The scanline z-buffer rasterizer.
    Raster,
    /// The ray caster/tracer.
    Ray,
    /// List priority: the painter's algorithm on the rasterizer's sample grid.
    Painter,
    /// List priority that never fails: a BSP tree of the triangles (Fuchs,
    /// Kedem & Naylor), its pieces painted back to front on the
    /// rasterizer's sample grid.
    Bsp,
}

impl Backend {
    /// `true` for backends that shade locally (no ray tree).
    #[must_use]
    pub fn shades_locally(self) -> bool {
        matches!(self, Backend::Raster | Backend::Painter | Backend::Bsp)
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(match self {
            Backend::Raster => "raster",
            Backend::Ray => "ray",
            Backend::Painter => "painter",
            Backend::Bsp => "bsp",
        })
    }
}

impl FromStr for Backend {
    type Err = options::ParseOptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "raster" => Ok(Backend::Raster),
            "ray" => Ok(Backend::Ray),
            "painter" => Ok(Backend::Painter),
            "bsp" => Ok(Backend::Bsp),
            _ => Err(options::ParseOptionError::new(
                s,
                format!("unknown backend \"{s}\"; expected raster, ray, painter or bsp"),
            )),
        }
    }
}

/// Settings given on the command line; `None` keeps the scene's value.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overrides {
    /// `--size WxH`.
    pub size: Option<(u32, u32)>,
    /// `--samples N`.
    pub samples: Option<u32>,
    /// `--depth`.
    pub depth: Option<DepthFormat>,
    /// `--shadows`.
    pub shadows: Option<ShadowMode>,
    /// `--geometry`.
    pub geometry: Option<Geometry>,
    /// `--bvh` (scene key `ray.bvh`).
    pub bvh: Option<BvhMode>,
    /// `--max-depth`.
    pub max_depth: Option<u32>,
    /// `--sort` (painter).
    pub painter_sort: Option<PainterSort>,
    /// `--memory-budget`, in bytes.
    pub memory_budget: Option<u64>,
    /// `--no-plan`.
    pub no_plan: bool,
}

/// The resolved settings of one render.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Depth buffer format (raster).
    pub depth: DepthFormat,
    /// Shadow mode (raster).
    pub shadows: ShadowMode,
    /// Geometry (ray).
    pub geometry: Geometry,
    /// BVH mode (ray).
    pub bvh: BvhMode,
    /// `max_depth`.
    pub max_depth: u32,
    /// The painter's order.
    pub painter_sort: PainterSort,
    /// The plan is in effect.
    pub plan: bool,
}

/// Errors of the library facade.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The scene could not be loaded.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// An image could not be written or read.
    #[error(transparent)]
    Image(#[from] image_io::ImageIoError),
    /// A request that cannot be carried out as given.
    #[error("{0}")]
    Usage(String),
    /// A render would need more memory than its budget.
    #[error(transparent)]
    Budget(#[from] budget::OverBudget),
    /// A POV-Ray reference could not be read, rendered or checked.
    #[error(transparent)]
    Golden(#[from] pov::golden::GoldenError),
}

pub use shade::GATE_EPS;

/// A scene loaded, tessellated and planned: ready to render with any backend.
#[derive(Debug)]
pub struct Prepared {
    /// The scene as written.
    pub scene: Scene,
    /// Its triangles.
    pub tri: TriScene,
    /// The resolved settings.
    pub settings: Settings,
    /// The plan (or everything on).
    pub plan: Plan,
    /// The request's memory budget, with what loading and tessellating
    /// reserved (rendering reserves its own large buffers in it too).
    pub budget: std::sync::Arc<budget::Budget>,
}

/// A rendered frame and what it cost.
#[derive(Debug)]
pub struct Rendered {
    /// The frame.
    pub frame: Frame,
    /// Wall time of the render in milliseconds (build of acceleration
    /// structures included).
    pub time_ms: f64,
    /// The work done, as the backend counted it.
    pub work: Work,
}

/// The work a render did (what the plan can save).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Work {
    /// The rasterizer's counters.
    Raster(raster::RasterStats),
    /// The painter's counters: the rasterizer's, and its ordering.
    Painter {
        /// Scan conversion and shading.
        raster: raster::RasterStats,
        /// The drawing order.
        order: raster::painter::PainterStats,
    },
    /// The BSP backend's counters: the rasterizer's, and its tree.
    Bsp {
        /// Scan conversion and shading.
        raster: raster::RasterStats,
        /// The tree: pieces, splits, build cost.
        tree: raster::bsp::BspStats,
    },
    /// The ray tracer's counters and its acceleration structure.
    Ray {
        /// Rays cast.
        rays: ray::RayStats,
        /// The BVH (a single leaf when the plan chose the flat loop).
        bvh: accel::BvhStats,
    },
}

impl Prepared {
    /// Loads a scene file and applies the overrides.
    ///
    /// # Errors
    ///
    /// [`Error::Load`] for a bad scene, [`Error::Usage`] for bad overrides.
    pub fn load(path: &Path, ov: &Overrides) -> Result<Prepared, Error> {
        let budget = std::sync::Arc::new(budget::Budget::new(
            ov.memory_budget.unwrap_or(budget::DEFAULT_MEMORY_BUDGET),
        ));
        let scene = Scene::load_within(path, &budget)?;
        Prepared::from_scene_within(scene, ov, budget)
    }

    /// Prepares an already loaded scene (its meshes and textures counted
    /// into a fresh budget).
    ///
    /// # Errors
    ///
    /// As [`Prepared::load`].
    pub fn from_scene(scene: Scene, ov: &Overrides) -> Result<Prepared, Error> {
        let budget = std::sync::Arc::new(budget::Budget::new(
            ov.memory_budget.unwrap_or(budget::DEFAULT_MEMORY_BUDGET),
        ));
        budget.reserve(scene.data_bytes(), || {
            "the scene's meshes and textures".to_string()
        })?;
        Prepared::from_scene_within(scene, ov, budget)
    }

    /// Prepares a scene loaded within `budget`.
    ///
    /// # Errors
    ///
    /// As [`Prepared::load`].
    pub fn from_scene_within(
        scene: Scene,
        ov: &Overrides,
        budget: std::sync::Arc<budget::Budget>,
    ) -> Result<Prepared, Error> {
        if let Some((w, h)) = ov.size {
            let max = scene::MAX_IMAGE_SIDE;
            if w == 0 || h == 0 || w > max || h > max {
                return Err(Error::Usage(format!(
                    "--size {w}x{h}: each side must be 1 … {max}"
                )));
            }
        }
        if let Some(n) = ov.samples
            && !coverage::SAMPLES_PER_SIDE.contains(&n)
        {
            return Err(Error::Usage(format!(
                "--samples {n}: expected 1, 2, 4, 8 or 16"
            )));
        }
        if let Some(d) = ov.max_depth
            && !(1..=64).contains(&d)
        {
            return Err(Error::Usage(format!("--max-depth {d}: expected 1 … 64")));
        }
        let tri = tessellate::tessellate_within(
            &scene,
            &TessOptions {
                size: ov.size,
                samples: ov.samples,
                memory_budget: ov.memory_budget,
            },
            &budget,
        )?;
        let settings = Settings {
            depth: ov.depth.unwrap_or(scene.raster.depth),
            shadows: ov.shadows.unwrap_or(scene.raster.shadows),
            geometry: ov.geometry.unwrap_or(scene.ray.geometry),
            bvh: ov.bvh.unwrap_or(scene.ray.bvh),
            max_depth: ov.max_depth.unwrap_or(scene.render.max_depth),
            painter_sort: ov.painter_sort.unwrap_or_default(),
            plan: !ov.no_plan,
        };
        let mut tri = tri;
        let plan = if settings.plan {
            let plan = Plan::for_scene(&tri, settings.bvh, settings.max_depth);
            plan.apply(&mut tri);
            plan
        } else {
            Plan::everything(&tri, settings.bvh)
        };
        // Shadow maps: a cube of six f32 maps per point light, one map per
        // parallel light, RES² texels of 4 B each.
        if let ShadowMode::Map(res) = settings.shadows
            && plan.shadows
        {
            let maps: u64 = tri
                .lights
                .iter()
                .filter(|l| !l.shadowless)
                .map(|l| match l.kind {
                    shade::LightKind::Point { .. } => 6,
                    shade::LightKind::Parallel { .. } => 1,
                })
                .sum();
            let bytes = maps * u64::from(res) * u64::from(res) * 4;
            budget.reserve(bytes, || format!("{maps} shadow map(s) of {res}x{res}"))?;
        }
        Ok(Prepared {
            scene,
            tri,
            settings,
            plan,
            budget,
        })
    }

    /// The rasterizer's options under this plan.
    #[must_use]
    pub fn raster_options(&self) -> raster::RasterOptions {
        raster::RasterOptions {
            depth: self.settings.depth,
            shadows: self.settings.shadows,
            shadows_needed: self.plan.shadows,
            gate_eps: GATE_EPS,
            frustum_cull: self.plan.frustum_cull.clone(),
            backface_cull: self.plan.backface_cull.clone(),
            #[cfg(feature = "testing")]
            perturb: raster::Perturb::default(),
        }
    }

    /// Renders with a backend.
    ///
    /// # Errors
    ///
    /// [`Error::Budget`] when the render's own buffers (the painter's pair
    /// lists, the BSP tree) would not fit the budget.
    pub fn render(&self, backend: Backend) -> Result<Rendered, Error> {
        self.render_with_depth(backend, self.settings.max_depth)
    }

    /// Renders with a backend and a given ray-tree depth.
    ///
    /// # Errors
    ///
    /// As [`Prepared::render`].
    pub fn render_with_depth(&self, backend: Backend, max_depth: u32) -> Result<Rendered, Error> {
        let start = Instant::now();
        let (frame, work) = match backend {
            Backend::Raster => {
                let (frame, stats) = raster::render(&self.tri, &self.raster_options());
                (frame, Work::Raster(stats))
            }
            Backend::Painter => {
                let (frame, raster, order) = raster::painter::render(
                    &self.tri,
                    &self.raster_options(),
                    self.settings.painter_sort,
                    &self.budget,
                )?;
                (frame, Work::Painter { raster, order })
            }
            Backend::Bsp => {
                let (frame, raster, tree) =
                    raster::bsp::render(&self.tri, &self.raster_options(), &self.budget)?;
                (frame, Work::Bsp { raster, tree })
            }
            Backend::Ray => {
                let accel = Accel::new(
                    &self.tri,
                    AccelOptions {
                        geometry: self.settings.geometry,
                        bvh: self.plan.bvh,
                        build: self.plan.bvh_build,
                        // Each camera sample's hit asks a light at most
                        // once (its reflections and refractions more);
                        // none without shadow rays (the plan's "light
                        // buffer" line applies the same rule).
                        shadow_rays_per_light: if self.plan.shadows {
                            u64::from(self.tri.camera.sample_width())
                                * u64::from(self.tri.camera.sample_height())
                        } else {
                            0
                        },
                        ..AccelOptions::default()
                    },
                );
                let max_depth = if self.plan.ray_tree { max_depth } else { 1 };
                let (frame, rays) = ray::render_counted(
                    &accel,
                    &ray::RayOptions {
                        max_depth,
                        shadows: self.plan.shadows,
                        gate_eps: GATE_EPS,
                    },
                );
                (
                    frame,
                    Work::Ray {
                        rays,
                        bvh: accel.stats(),
                    },
                )
            }
        };
        Ok(Rendered {
            frame,
            time_ms: start.elapsed().as_secs_f64() * 1e3,
            work,
        })
    }
}
