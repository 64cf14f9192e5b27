//! rendiff's scene model: the strict TOML loader and its located errors
//! (`scene`), OBJ meshes read in one streaming pass, polygon triangulation
//! (`polygon`), tessellation of every shape into the shared
//! [`rendiff_core::tri_scene::TriScene`] (`tessellate`), and the render
//! plan that skips what a scene does not need (`plan`).

#![warn(missing_docs, missing_debug_implementations)]

pub mod plan;
pub mod polygon;
pub mod scene;
pub mod tessellate;
