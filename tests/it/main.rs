//! Integration tests (one binary). Each module says what it covers.

#![allow(
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test and bench fixtures: small generated counts, indices and rates, where a wrong cast fails the check instead of reaching a user"
)]
/// Adversarial geometry: extreme scales, degenerate triangles, a million
/// triangles in a pixel, eyes and lights inside objects.
mod adversarial;
/// The module map's one-way dependencies.
mod architecture;
/// Nothing half-written: killed writes, failed golden updates.
mod atomic;
/// Back faces: culling loses a ray tracer's exit surfaces, never the
/// rasterizer's primary visibility on closed meshes.
mod backfaces;
/// Bad input: every file of tests/data/bad gives exit 2 and a located message.
mod bad_input;
/// The BSP tree against the z-buffer: list priority that never fails.
mod bsp;
/// Bump mapping: both methods against each other and against POV-Ray.
mod bumps;
/// The command line: help, outputs, exit codes, the HTML report.
mod cli;
/// Raster against ray on every scene, and the classifier's negative controls.
mod differential;
/// Another renderer's G-buffer, classified like a backend's.
mod external;
/// The fuzz corpora and past crashes, replayed.
mod fuzz_corpus;
/// Regression images per backend (golden/raster, golden/ray).
mod golden;
/// The hazard scenes and the ray families behind them.
mod hazards;
/// The hostile corpus: inputs and file systems that must not hurt.
mod hostile;
/// Hidden lines: Appel's QI against ray counts and the z-buffer.
mod lines;
/// OBJ faces as exporters write them: keyhole faces load as rings.
mod obj_faces;
/// OBJ materials: a mesh's own .mtl per usemtl group, JPEG textures, their export.
mod obj_materials;
/// The painter's algorithm against the z-buffer.
mod painter;
/// The render plan: invariance with and without it, and each skip firing.
mod plan;
/// Both backends against the stored POV-Ray references.
mod povray;
/// Comparing with 8-bit and 16-bit PNGs: their rounding is not a difference.
mod quantised;
/// The rasterizer: exact coverage, drift, depth formats, near clipping.
mod raster;
/// The ray tracer: BVH, watertightness, self-hits, threads, shading.
mod ray;
/// The README's examples print what it shows.
mod readme;
/// The interactive HTML report driven in headless Chromium: toggle,
/// hover values, cluster zoom, legends.
mod report_browser;
/// Resource bounds: memory per triangle and per sample, the budget.
mod resources;
/// `--shard K/N` and `rendiff report`: suites split across machines.
mod shard;
/// A stale stored reference is named before any count.
mod stale;
/// Tessellation: chord error bounds and closedness.
mod tessellation;
/// A user's own crate under snapshot tests, reviewed with `rendiff review`.
mod user_crate;
/// Helpers shared by the modules.
mod util;
