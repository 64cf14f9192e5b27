//! rendiff's ground floor: what both backends, the scene loader and the
//! verdict share. Math and colour, the render options, sample coverage and
//! the sample grid, the camera, the material and light model (`shade`), the
//! frame both backends fill, PNG/PFM input and output with safe writes,
//! textures, the analytic shapes, and [`tri_scene::TriScene`], the one
//! triangulated geometry every renderer sees.
//!
//! Inside this crate the modules keep the floors of ARCHITECTURE.md (L0:
//! math, color, options, coverage, analytic, input, budget, cleanup,
//! escape; L1: image_io, camera, texture; L2: shade, frame, output; L3:
//! tri_scene); `tests/it/architecture.rs` checks those, Cargo the crates.

#![warn(missing_docs, missing_debug_implementations)]

pub mod analytic;
pub mod budget;
pub mod camera;
pub mod cleanup;
pub mod color;
pub mod coverage;
pub mod escape;
pub mod frame;
pub mod huge;
pub mod image_io;
pub mod input;
pub mod math;
pub mod options;
pub mod output;
pub mod shade;
pub mod texture;
pub mod tri_scene;
