//! The verdict (DESIGN.md §5–§6): compare two frames sample by sample, or
//! a frame with an image, and explain every disagreement.
//!
//! `compare` renders nothing. Where two frames report different triangles
//! it evaluates those two triangles in `f64` ([`oracle`]) to classify the
//! sample as an edge tie, a depth tie, a near tie, or a real mismatch.
//! Where they agree, the colour difference is the shading error; samples
//! whose shading flags say they sit on a discontinuity are shading ties.

pub mod explain;
pub mod maps;
pub mod metrics;
pub mod oracle;
pub mod report;

use serde::Serialize;

use crate::color::Rgb;
use crate::frame::{BACKGROUND, Frame};
use crate::options::DepthFormat;
use crate::shade::FLAG_DISCONTINUITY;
use crate::tri_scene::TriScene;
pub use metrics::ImageStats;
pub use oracle::{Class, Oracle};

/// The derived tolerances of a comparison (DESIGN.md §6; derivations in
/// ARCHITECTURE.md).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerances {
    /// ε_edge in pixels.
    pub edge_px: f64,
    /// δ_near in view-depth units.
    pub near_eps: f64,
    /// ε_g.
    pub gate_eps: f64,
    /// Largest shading error on agreeing samples.
    pub shading_max: f64,
}

/// Tolerances of image comparisons with POV-Ray or a regression image.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImageTolerances {
    /// Largest accepted 8-bit channel difference on most pixels.
    pub pov_max8: f64,
    /// Fraction of pixels that must be within `pov_max8`.
    pub pov_fraction: f64,
}

impl Default for ImageTolerances {
    fn default() -> Self {
        ImageTolerances {
            pov_max8: 2.0,
            pov_fraction: 0.999,
        }
    }
}

/// Visibility classes counted over all samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct VisibilityCounts {
    /// Same triangle (or both background).
    pub agree: u64,
    /// Edge ties.
    pub edge_tie: u64,
    /// Depth ties.
    pub depth_tie: u64,
    /// Near ties.
    pub near_tie: u64,
    /// Real mismatches.
    pub real: u64,
}

impl VisibilityCounts {
    fn add(&mut self, c: Class) {
        match c {
            Class::Agree => self.agree += 1,
            Class::EdgeTie => self.edge_tie += 1,
            Class::DepthTie => self.depth_tie += 1,
            Class::NearTie => self.near_tie += 1,
            Class::Real => self.real += 1,
        }
    }

    /// All classes.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.agree + self.edge_tie + self.depth_tie + self.near_tie + self.real
    }
}

/// Shading statistics on agreeing samples (or on all pixels for images).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ShadingStats {
    /// Largest per-sample error (largest channel difference, linear, clamped to [0, 1]).
    pub max: f64,
    /// Mean per-sample error.
    pub mean: f64,
    /// Root mean square over all channels.
    pub rmse: f64,
    /// PSNR in dB for a peak of 1 (null when identical).
    pub psnr: f64,
    /// Samples whose error exceeds the tolerance.
    pub over_threshold: u64,
    /// Shading ties (frames only).
    pub ties: Option<u64>,
    /// Largest error on a shading tie (frames only).
    pub tie_max: Option<f64>,
}

/// The result of comparing two frames (or a frame and an image).
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// Visibility counts (`None` when one side is an image).
    pub visibility: Option<VisibilityCounts>,
    /// Shading statistics.
    pub shading: ShadingStats,
    /// Image statistics of the pixel colours.
    pub image: ImageStats,
    /// Class per sample (frames only; empty otherwise).
    pub classes: Vec<Class>,
    /// Shading error per sample (frames) or per pixel (images); NaN where not compared.
    pub errors: Vec<f32>,
    /// Shading tie per sample.
    pub ties: Vec<bool>,
    /// Sample grid size.
    pub grid: (u32, u32),
    /// Samples per pixel side.
    pub samples: u32,
    /// Passed.
    pub pass: bool,
}

fn sample_error(a: Rgb, b: Rgb) -> f32 {
    a.clamp01().max_abs_diff(b.clamp01())
}

/// Derives the tolerances of a raster-vs-ray comparison for a scene.
///
/// * ε_edge = the snapping bound √2·2⁻⁹ px + the ray tracer's own error:
///   γ(16) radians of direction (mapped to pixels with the camera's largest
///   magnification) and γ(16)·(|eye|∞ + |bounds|∞) of position (the f32 ray
///   origin and vertices), in pixels at the nearest view depth of the bounds.
/// * δ_near = γ(16)·(|eye|∞ + |bounds|∞ + near): the absolute error of the
///   ray parameter near the eye.
/// * ε_g = [`crate::shade::GATE_EPS`].
/// * shading_max = 2⁻²² · K + 2⁻¹⁸, with K a bound on |∂C/∂b| (see
///   [`shading_lipschitz`]) and 2⁻¹⁸ the rounding of the shading arithmetic.
#[must_use]
pub fn derive_tolerances(scene: &TriScene) -> Tolerances {
    use crate::camera::Projection;
    let cam = &scene.camera;
    let h = f64::from(cam.height());
    // The ray tracer works in f32.
    let g = f64::from(crate::math::gamma(16));
    let b = scene.bounds;
    let extent = f64::from(b.min.abs().max(b.max.abs()).max_element());
    let eye = cam.eye().abs().max_element();
    // The ray tracer's positions are f32: the eye (ray origin) and every
    // vertex relative to it carry γ(16)·(|eye|∞ + |bounds|∞) of absolute
    // error, which the screen magnifies most at the nearest view depth.
    let position_error = g * (extent + eye);
    let z_min = b
        .corners()
        .iter()
        .map(|c| cam.view_depth(crate::math::to_f64(*c)))
        .fold(f64::INFINITY, f64::min)
        .max(cam.near());
    let proj = match cam.projection() {
        Projection::Perspective { tan_half_fov: t } => {
            // Its directions carry γ(16) radians of error besides.
            let a = cam.aspect();
            let px_per_rad = h / (2.0 * t) * (1.0 + t * t * (1.0 + a * a));
            g * px_per_rad + position_error * cam.max_pixels_per_unit(z_min)
        }
        Projection::Orthographic { view_height } => position_error * h / view_height,
    };
    Tolerances {
        edge_px: crate::coverage::SNAP_BOUND_PX + proj,
        near_eps: g * (eye + extent + cam.near()),
        gate_eps: f64::from(crate::shade::GATE_EPS),
        shading_max: (-22f64).exp2() * shading_lipschitz(scene) + (-18f64).exp2(),
    }
}

/// A bound K on |∂C/∂b_i| over the scene: the change of a sample's colour
/// per unit change of a barycentric weight, for colours clamped to [0, 1].
///
/// Per material: the normal moves by at most `2/|Σ b n|` per unit of `b`
/// (≤ 2·4 for the vertex normals of our meshes, taken as 8), which moves
/// N·L and R·L by as much; the light terms then change by
/// `Σ|Lc| (diffuse·max(1, brilliance) + phong·phong_size + specular/roughness)`
/// per unit; a texture adds `max texel step (1) × size × |Δuv|max` per unit
/// times the terms the pigment multiplies; the hit point moves by the
/// triangle's edge length, which changes L by `|edge|/distance` (bounded by
/// the same light factor).
#[must_use]
pub fn shading_lipschitz(scene: &TriScene) -> f64 {
    let light_sum: f64 = scene
        .lights
        .iter()
        .map(|l| f64::from(l.color.max_channel()))
        .sum::<f64>()
        .max(0.0);
    let mut k: f64 = 0.0;
    for (mi, m) in scene.materials.iter().enumerate() {
        let terms = f64::from(m.diffuse) * f64::from(m.brilliance.max(1.0))
            + f64::from(m.phong) * f64::from(m.phong_size)
            + f64::from(m.specular) / f64::from(m.roughness);
        let normal = 8.0 * light_sum * terms;
        let tex = match &m.pigment {
            crate::shade::Pigment::Image(t) => {
                let uv = uv_spread(scene, mi);
                f64::from(t.width().max(t.height()))
                    * uv
                    * (f64::from(m.ambient)
                        + f64::from(m.emission)
                        + f64::from(m.diffuse) * light_sum
                        + 1.0)
            }
            crate::shade::Pigment::Color(_) => 0.0,
        };
        let bump = m.bump.as_ref().map_or(0.0, |bm| {
            let uv = uv_spread(scene, mi);
            f64::from(bm.texture.width().max(bm.texture.height())).powi(2)
                * uv
                * f64::from(bm.size.abs())
                * light_sum
                * terms
        });
        k = k.max(normal + tex + bump);
    }
    k
}

/// Largest |Δuv| along a triangle edge among the triangles of material `m`.
fn uv_spread(scene: &TriScene, m: usize) -> f64 {
    let mut spread: f64 = 0.0;
    for (t, uvi) in scene.tri_uvs.iter().enumerate() {
        if usize::from(scene.tri_material[t]) != m || uvi[0] == crate::tri_scene::NO_INDEX {
            continue;
        }
        let uv = uvi.map(|i| scene.uvs[i as usize]);
        for (a, b) in [(0, 1), (1, 2), (2, 0)] {
            spread = spread.max(f64::from((uv[a] - uv[b]).abs().max_element()));
        }
    }
    // Analytic spheres map the whole [0, 1] range.
    if scene.analytic.iter().any(|s| usize::from(s.material) == m) {
        spread = spread.max(1.0);
    }
    spread
}

/// `true` when bit `mask` differs between a sample and one of its 8
/// neighbours in frame `f`.
fn on_boundary(f: &Frame, x: u32, y: u32, mask: u32) -> bool {
    let (w, h) = (f.sample_width(), f.sample_height());
    let here = f.flags[(y as usize) * (w as usize) + x as usize] & mask;
    for dy in -1i64..=1 {
        for dx in -1i64..=1 {
            let (nx, ny) = (i64::from(x) + dx, i64::from(y) + dy);
            if (dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= i64::from(w) || ny >= i64::from(h)
            {
                continue;
            }
            #[expect(clippy::cast_sign_loss, reason = "checked non-negative")]
            let i = (ny as usize) * (w as usize) + nx as usize;
            if f.flags[i] & mask != here {
                return true;
            }
        }
    }
    false
}

/// Compares two frames of the same scene, sample by sample.
///
/// # Panics
///
/// If the frames have different sizes or sample counts.
#[must_use]
pub fn compare_frames(
    scene: &TriScene,
    a: &Frame,
    b: &Frame,
    tol: &Tolerances,
    depth: DepthFormat,
) -> Comparison {
    use rayon::prelude::*;
    assert_eq!(
        (a.width, a.height, a.samples),
        (b.width, b.height, b.samples),
        "frames differ in size"
    );
    let oracle = Oracle::new(scene, tol.edge_px, tol.near_eps, depth);
    let (sw, sh) = (a.sample_width(), a.sample_height());
    let cam = &scene.camera;
    let per_row: Vec<Vec<(Class, f32, bool)>> = (0..sh)
        .into_par_iter()
        .map(|sy| {
            (0..sw)
                .map(|sx| {
                    let i = (sy as usize) * (sw as usize) + sx as usize;
                    let (ia, ib) = (a.id[i], b.id[i]);
                    let opt = |id: u32| (id != BACKGROUND).then_some(id);
                    let class = if ia == ib {
                        Class::Agree
                    } else {
                        let (x, y) = cam.sample_point(sx, sy);
                        oracle.classify(x, y, opt(ia), opt(ib))
                    };
                    if class != Class::Agree {
                        return (class, f32::NAN, false);
                    }
                    let err = sample_error(a.sample_colors()[i], b.sample_colors()[i]);
                    let (fa, fb) = (a.flags[i], b.flags[i]);
                    let mut tie = (fa | fb) & FLAG_DISCONTINUITY != 0;
                    let shadow_diff = (fa ^ fb) & !FLAG_DISCONTINUITY;
                    if !tie && shadow_diff != 0 {
                        tie = (0..31).filter(|k| shadow_diff & (2 << k) != 0).all(|k| {
                            let mask = 2u32 << k;
                            on_boundary(a, sx, sy, mask) || on_boundary(b, sx, sy, mask)
                        });
                    }
                    (class, err, tie)
                })
                .collect()
        })
        .collect();
    let mut vis = VisibilityCounts::default();
    let mut classes = Vec::with_capacity((sw as usize) * (sh as usize));
    let mut errors = Vec::with_capacity(classes.capacity());
    let mut ties = Vec::with_capacity(classes.capacity());
    let (mut n, mut sum, mut sq, mut max, mut over) = (0u64, 0.0f64, 0.0f64, 0.0f64, 0u64);
    let (mut n_ties, mut tie_max) = (0u64, 0.0f64);
    for row in per_row {
        for (class, err, tie) in row {
            vis.add(class);
            classes.push(class);
            errors.push(err);
            ties.push(tie);
            if class != Class::Agree {
                continue;
            }
            let e = f64::from(err);
            if tie {
                n_ties += 1;
                tie_max = tie_max.max(e);
                continue;
            }
            n += 1;
            sum += e;
            max = max.max(e);
            if e > tol.shading_max {
                over += 1;
            }
        }
    }
    // RMSE over all channels of the agreeing, non-tie samples.
    for (i, (&c, &t)) in classes.iter().zip(&ties).enumerate() {
        if c == Class::Agree && !t {
            let (p, q) = (
                a.sample_colors()[i].clamp01(),
                b.sample_colors()[i].clamp01(),
            );
            for (x, y) in p.to_array().iter().zip(q.to_array()) {
                sq += f64::from(x - y).powi(2);
            }
        }
    }
    #[expect(clippy::cast_precision_loss, reason = "sample counts below 2^52")]
    let (mean, rmse) = if n == 0 {
        (0.0, 0.0)
    } else {
        (sum / n as f64, (sq / (3 * n) as f64).sqrt())
    };
    let shading = ShadingStats {
        max,
        mean,
        rmse,
        psnr: metrics::psnr(rmse),
        over_threshold: over,
        ties: Some(n_ties),
        tie_max: Some(tie_max),
    };
    let image = metrics::image_stats(a.width, a.height, &a.color, &b.color);
    let pass = vis.real == 0 && over == 0;
    Comparison {
        visibility: Some(vis),
        shading,
        image,
        classes,
        errors,
        ties,
        grid: (sw, sh),
        samples: a.samples,
        pass,
    }
}

/// Compares pixel colours with an image (a POV-Ray reference or a
/// regression golden): visibility is unknown, every pixel is a shading sample.
///
/// # Panics
///
/// If the sizes differ.
#[must_use]
pub fn compare_images(
    w: u32,
    h: u32,
    a: &[Rgb],
    b: &[Rgb],
    tol: &ImageTolerances,
    shading_max: f64,
) -> Comparison {
    assert_eq!(a.len(), b.len(), "images differ in size");
    let mut errors = Vec::with_capacity(a.len());
    let (mut sum, mut sq, mut max, mut over) = (0.0f64, 0.0f64, 0.0f64, 0u64);
    for (p, q) in a.iter().zip(b) {
        let e = sample_error(*p, *q);
        errors.push(e);
        let e = f64::from(e);
        sum += e;
        max = max.max(e);
        if e > shading_max {
            over += 1;
        }
        for (x, y) in p.clamp01().to_array().iter().zip(q.clamp01().to_array()) {
            sq += f64::from(x - y).powi(2);
        }
    }
    #[expect(clippy::cast_precision_loss, reason = "pixel counts below 2^52")]
    let n = a.len().max(1) as f64;
    let rmse = (sq / (3.0 * n)).sqrt();
    let image = metrics::image_stats(w, h, a, b);
    // The fuzzy verdict: enough pixels within pov_max8 (8-bit sRGB).
    let within = a
        .iter()
        .zip(b)
        .filter(|(p, q)| {
            let d = [
                crate::color::to_srgb8(p.r).abs_diff(crate::color::to_srgb8(q.r)),
                crate::color::to_srgb8(p.g).abs_diff(crate::color::to_srgb8(q.g)),
                crate::color::to_srgb8(p.b).abs_diff(crate::color::to_srgb8(q.b)),
            ];
            f64::from(*d.iter().max().unwrap_or(&0)) <= tol.pov_max8
        })
        .count();
    #[expect(clippy::cast_precision_loss, reason = "pixel counts below 2^52")]
    let pass = within as f64 >= tol.pov_fraction * n;
    Comparison {
        visibility: None,
        shading: ShadingStats {
            max,
            mean: sum / n,
            rmse,
            psnr: metrics::psnr(rmse),
            over_threshold: over,
            ties: None,
            tie_max: None,
        },
        image,
        classes: Vec::new(),
        errors,
        ties: Vec::new(),
        grid: (w, h),
        samples: 1,
        pass,
    }
}
