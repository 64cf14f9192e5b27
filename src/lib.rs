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
//! scene.toml ─ scene::Scene::load ─▶ Scene ─ tessellate ─▶ TriScene ─▶ backends ─▶ Frame ─ compare ─▶ verdict
//! ```
//!
//! See `ARCHITECTURE.md` for the conventions, the module map and its
//! one-way dependencies.

#![warn(missing_docs, missing_debug_implementations)]

pub mod camera;
pub mod color;
pub mod frame;
pub mod image_io;
pub mod math;
pub mod options;
pub mod polygon;
pub mod scene;
pub mod shade;
pub mod tessellate;
pub mod texture;
pub mod tri_scene;
