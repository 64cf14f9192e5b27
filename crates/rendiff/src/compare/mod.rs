//! The verdict (DESIGN.md §5–§6): compare two frames sample by sample, or
//! a frame with an image, and explain every disagreement.
//!
//! `compare` renders nothing. Where two frames report different triangles
//! it evaluates those two triangles in `f64` ([`oracle`]) to classify the
//! sample as an edge tie, a depth tie, a near tie, or a real mismatch.
//! Where they agree, the colour difference is the shading error; samples
//! whose shading flags say they sit on a discontinuity are shading ties.

pub mod clusters;
pub mod explain;
pub mod flip;
pub mod maps;
pub mod metrics;
pub mod oracle;
pub mod page;
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
/// ARCHITECTURE.md). The visibility tolerances are local (each sample's own,
/// from its two triangles, in [`oracle`]); these are the limits a tie's
/// tolerance may not exceed, and the scene-wide shading bound.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerances {
    /// The widest edge tie, in pixels (`oracle::EDGE_TIE_MAX_PX`).
    pub edge_px_limit: f64,
    /// The largest depth difference of a depth tie, relative to the depth
    /// (`oracle::DEPTH_TIE_MAX_REL`).
    pub depth_rel_limit: f64,
    /// The largest error part of a depth tie, relative to the depth
    /// (`oracle::DEPTH_ERROR_MAX_REL`).
    pub depth_error_limit: f64,
    /// The largest clip-plane error, relative to the plane's distance
    /// (`oracle::CLIP_ERROR_MAX_REL`).
    pub near_rel_limit: f64,
    /// ε_g.
    pub gate_eps: f64,
    /// Largest shading error on agreeing samples: 0, because both backends
    /// shade a sample that sees the same triangle from bit-identical inputs
    /// (the same weights from `TriScene::view_weights`, the same ray
    /// direction, the same shadow queries) through one function.
    pub shading_max: f64,
    /// How each frame's colours were stored: exact for a backend's frame,
    /// a PNG's code for another renderer's G-buffer (whose colour
    /// differences then count only beyond that rounding).
    pub quantisation: [Quantisation; 2],
}

/// A distribution of per-sample tolerances: its largest value and 99th
/// percentile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Spread {
    /// Largest value.
    pub max: f64,
    /// 99th percentile (nearest rank).
    pub p99: f64,
}

impl Spread {
    fn of(mut v: Vec<f64>, empty: f64) -> Spread {
        if v.is_empty() {
            return Spread {
                max: empty,
                p99: empty,
            };
        }
        v.sort_by(f64::total_cmp);
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss,
            reason = "a rank below the length"
        )]
        let rank = ((0.99 * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
        Spread {
            max: v[v.len() - 1],
            p99: v[rank],
        }
    }
}

/// The tolerances the oracle gave the samples it judged (every sample where
/// the two frames saw different surfaces). With none judged, each spread is
/// its smallest possible value (the snapping bound; 0).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct JudgedTolerances {
    /// Samples judged.
    pub judged: u64,
    /// ε_edge (px).
    pub edge_px: Spread,
    /// δ_t relative to the depth (where both triangles were inside).
    pub depth_rel: Spread,
    /// δ_near (view-depth units).
    pub near_eps: Spread,
}

/// Tolerances of image comparisons with POV-Ray or a regression image.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImageTolerances {
    /// Largest accepted 8-bit channel difference on most pixels.
    pub pov_max8: f64,
    /// Fraction of pixels that must be within `pov_max8`.
    pub pov_fraction: f64,
    /// The user's own rule (`[tolerance] fuzzy` or `--fuzzy`), which
    /// replaces the derived one and may be looser.
    pub fuzzy: Option<Fuzzy>,
    /// The derived rule, for when `fuzzy` is `None`.
    pub rule: ImageRule,
}

impl Default for ImageTolerances {
    fn default() -> Self {
        ImageTolerances {
            pov_max8: 2.0,
            pov_fraction: 0.999,
            fuzzy: None,
            rule: ImageRule::Renderer,
        }
    }
}

/// A user-stated threshold for image comparisons, as reftest's
/// `fuzzy(maxDiff, pixelCount)`: at most `pixels` pixels may differ beyond
/// the images' rounding, none by more than `max_diff` 8-bit codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Fuzzy {
    /// Largest 8-bit channel difference of a differing pixel.
    pub max_diff: u8,
    /// Largest number of differing pixels.
    pub pixels: u64,
}

/// Which rule decides an image comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ImageRule {
    /// Another renderer (POV-Ray): `pov_fraction` of the pixels within
    /// `pov_max8` codes (DESIGN.md §6).
    Renderer,
    /// An image of the same frame (a stored render, a golden): no pixel
    /// may differ beyond the images' rounding.
    SameFrame,
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
    /// Near ties (at the near or far clip plane).
    pub near_tie: u64,
    /// Samples that would be ties only with a tolerance wider than a tie
    /// can be: not judged, and the verdict fails.
    pub unjudgeable: u64,
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
            Class::Unjudgeable => self.unjudgeable += 1,
            Class::Real => self.real += 1,
        }
    }

    /// All classes.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.agree + self.edge_tie + self.depth_tie + self.near_tie + self.unjudgeable + self.real
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
    /// The tolerances the judged samples were given (frames only).
    pub judged: Option<JudgedTolerances>,
    /// Passed.
    pub pass: bool,
    /// The FLIP error per pixel (a's against b's colours), or empty.
    pub flip: Vec<f32>,
}

/// One sample's class, shading error, shading tie and (where the frames
/// saw different surfaces) the tolerances it was judged with.
type SampleVerdict = (Class, f32, bool, Option<oracle::Judged>);

fn sample_error(a: Rgb, b: Rgb) -> f32 {
    a.clamp01().max_abs_diff(b.clamp01())
}

/// The tolerances of a raster-vs-ray comparison (DESIGN.md §6): the limits
/// of the local tolerances and the shading bound. The scene is not needed
/// to derive them: nothing here depends on its bounds.
#[must_use]
pub fn derive_tolerances(_scene: &TriScene) -> Tolerances {
    image_tolerances()
}

/// The derived tolerances where no scene is known (two images): the
/// visibility limits are the oracle's constants, unused without frames.
#[must_use]
pub fn image_tolerances() -> Tolerances {
    Tolerances {
        edge_px_limit: oracle::EDGE_TIE_MAX_PX,
        depth_rel_limit: oracle::DEPTH_TIE_MAX_REL,
        depth_error_limit: oracle::DEPTH_ERROR_MAX_REL,
        near_rel_limit: oracle::CLIP_ERROR_MAX_REL,
        gate_eps: f64::from(crate::shade::GATE_EPS),
        shading_max: 0.0,
        quantisation: [Quantisation::Exact; 2],
    }
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
            #[expect(
                clippy::cast_sign_loss,
                clippy::cast_possible_truncation,
                reason = "checked inside the u32 sample grid"
            )]
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
    let oracle = Oracle::new(scene, depth);
    let (sw, sh) = (a.sample_width(), a.sample_height());
    let per_row: Vec<Vec<SampleVerdict>> = (0..sh)
        .into_par_iter()
        .map(|sy| {
            (0..sw)
                .map(|sx| judge_sample(&oracle, (a, b), tol.quantisation, sx, sy))
                .collect()
        })
        .collect();
    let mut vis = VisibilityCounts::default();
    let mut classes = Vec::with_capacity((sw as usize) * (sh as usize));
    let mut errors = Vec::with_capacity(classes.capacity());
    let mut ties = Vec::with_capacity(classes.capacity());
    let (mut edges, mut depths, mut nears) = (Vec::new(), Vec::new(), Vec::new());
    for (class, err, tie, judged) in per_row.into_iter().flatten() {
        if let Some(j) = judged {
            edges.push(j.edge_px);
            nears.push(j.clip);
            depths.extend(j.depth_rel);
        }
        vis.add(class);
        classes.push(class);
        errors.push(err);
        ties.push(tie);
    }
    let shading = shading_stats(a, b, &classes, &errors, &ties, tol);
    let over = shading.over_threshold;
    let (image, flip) = metrics::image_stats(a.width, a.height, &a.color, &b.color);
    let pass = vis.real == 0 && vis.unjudgeable == 0 && over == 0;
    let judged = JudgedTolerances {
        judged: edges.len() as u64,
        edge_px: Spread::of(edges, crate::coverage::SNAP_BOUND_PX),
        depth_rel: Spread::of(depths, 0.0),
        near_eps: Spread::of(nears, 0.0),
    };
    Comparison {
        flip,
        visibility: Some(vis),
        shading,
        image,
        classes,
        errors,
        ties,
        grid: (sw, sh),
        samples: a.samples,
        judged: Some(judged),
        pass,
    }
}

/// One sample of two frames: where the ids differ, the oracle's verdict;
/// where they agree, the colour error and whether the sample is a tie (a
/// discontinuity, or a shadow edge both frames place within a sample).
fn judge_sample(
    oracle: &Oracle<'_>,
    (a, b): (&Frame, &Frame),
    quant: [Quantisation; 2],
    sx: u32,
    sy: u32,
) -> SampleVerdict {
    let i = (sy as usize) * (a.sample_width() as usize) + sx as usize;
    let (ia, ib) = (a.id[i], b.id[i]);
    let opt = |id: u32| (id != BACKGROUND).then_some(id);
    if ia != ib {
        let (x, y) = oracle.camera().sample_point(sx, sy);
        let j = oracle.judge(x, y, opt(ia), opt(ib));
        return (j.class, f32::NAN, false, Some(j));
    }
    let (ca, cb) = (a.sample_colors()[i], b.sample_colors()[i]);
    let err = if quant == [Quantisation::Exact; 2] {
        sample_error(ca, cb)
    } else {
        quantised_error(ca, cb, quant)
    };
    let (fa, fb) = (a.flags[i], b.flags[i]);
    let mut tie = (fa | fb) & FLAG_DISCONTINUITY != 0;
    let shadow_diff = (fa ^ fb) & !FLAG_DISCONTINUITY;
    if !tie && shadow_diff != 0 {
        // A shadow edge each frame places differently by a sample: both
        // frames show an edge of that light's shadow here. (Where only one
        // does, a shadow is missing or added — a shadow map that loses
        // thin occluders — and the sample is compared as usual.)
        tie = (0..31).filter(|k| shadow_diff & (2 << k) != 0).all(|k| {
            let mask = 2u32 << k;
            on_boundary(a, sx, sy, mask) && on_boundary(b, sx, sy, mask)
        });
    }
    (Class::Agree, err, tie, None)
}

/// The shading statistics over the agreeing samples: ties apart (their
/// count and largest error), the rest against `tol.shading_max`.
fn shading_stats(
    a: &Frame,
    b: &Frame,
    classes: &[Class],
    errors: &[f32],
    ties: &[bool],
    tol: &Tolerances,
) -> ShadingStats {
    let (mut n, mut sum, mut sq, mut max, mut over) = (0u64, 0.0f64, 0.0f64, 0.0f64, 0u64);
    let (mut n_ties, mut tie_max) = (0u64, 0.0f64);
    for (i, ((&class, &err), &tie)) in classes.iter().zip(errors).zip(ties).enumerate() {
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
        // RMSE over all channels of the agreeing, non-tie samples.
        let (p, q) = (
            a.sample_colors()[i].clamp01(),
            b.sample_colors()[i].clamp01(),
        );
        for (x, y) in p.to_array().iter().zip(q.to_array()) {
            sq += f64::from(x - y).powi(2);
        }
    }
    #[expect(clippy::cast_precision_loss, reason = "sample counts below 2^52")]
    let (mean, rmse) = if n == 0 {
        (0.0, 0.0)
    } else {
        (sum / n as f64, (sq / (3 * n) as f64).sqrt())
    };
    ShadingStats {
        max,
        mean,
        rmse,
        psnr: metrics::psnr(rmse),
        over_threshold: over,
        ties: Some(n_ties),
        tie_max: Some(tie_max),
    }
}

/// How a side's colours were stored: what a value read back can have
/// been before it was rounded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantisation {
    /// Rendered now: the value is exact.
    Exact,
    /// An 8-bit sRGB PNG: a code `c` stands for every linear value whose
    /// sRGB encoding lies in `[(c − ½)/255, (c + ½)/255]`.
    Srgb8,
    /// A 16-bit linear PNG: a code `c` stands for `[(c − ½), (c + ½)]/65535`.
    Linear16,
}

impl Quantisation {
    /// The interval of linear values (clamped to [0, 1]) that `v`, as read
    /// back, can stand for.
    fn interval(self, v: f32) -> (f32, f32) {
        let v = v.clamp(0.0, 1.0);
        match self {
            Quantisation::Exact => (v, v),
            Quantisation::Srgb8 => {
                let c = f32::from(crate::color::to_srgb8(v));
                let lin = |e: f32| crate::color::srgb_decode(e.clamp(0.0, 1.0));
                (lin((c - 0.5) / 255.0), lin((c + 0.5) / 255.0))
            }
            Quantisation::Linear16 => {
                let c = f32::from(crate::color::to_linear16(v));
                (
                    ((c - 0.5) / 65535.0).max(0.0),
                    ((c + 0.5) / 65535.0).min(1.0),
                )
            }
        }
    }

    /// The stored code of `v` (`None` when exact).
    fn code(self, v: f32) -> Option<u16> {
        match self {
            Quantisation::Exact => None,
            Quantisation::Srgb8 => Some(u16::from(crate::color::to_srgb8(v))),
            Quantisation::Linear16 => Some(crate::color::to_linear16(v)),
        }
    }
}

/// The colour difference beyond both sides' storage rounding, the largest
/// channel's: 0 where both values store as the same code of the coarser
/// side's format (decided on the codes, so that no f32 rounding of an
/// interval end counts a boundary value as over); two images of one
/// format whose codes differ differ by their decoded values (one code is
/// a change); otherwise (an exact value against a code, or two formats)
/// the gap between the intervals of values the two stand for.
fn quantised_error(p: Rgb, q: Rgb, quant: [Quantisation; 2]) -> f32 {
    let common = match quant {
        [Quantisation::Exact, q] | [q, Quantisation::Exact] => Some(q),
        [a, b] if a == b => Some(a),
        _ => None,
    };
    p.to_array()
        .iter()
        .zip(q.to_array())
        .map(|(&x, y)| {
            match common {
                // Two float images: the stored values, unclamped (HDR).
                Some(Quantisation::Exact) => return (x - y).abs(),
                Some(c) if c.code(x) == c.code(y) => return 0.0,
                // Two images of one format with different codes: a change
                // of at least one code, whatever their intervals.
                Some(c) if quant == [c, c] => return (x - y).abs(),
                _ => {}
            }
            let (xl, xh) = quant[0].interval(x);
            let (yl, yh) = quant[1].interval(y);
            (xl - yh).max(yl - xh).max(0.0)
        })
        .fold(0.0, f32::max)
}

/// The largest 8-bit sRGB code difference of a pixel's channels.
fn max8_diff(p: Rgb, q: Rgb) -> u8 {
    let c = crate::color::to_srgb8;
    c(p.r)
        .abs_diff(c(q.r))
        .max(c(p.g).abs_diff(c(q.g)))
        .max(c(p.b).abs_diff(c(q.b)))
}

/// Compares pixel colours with an image (a POV-Ray reference, a
/// regression golden, another renderer's picture): visibility is unknown,
/// every pixel is a shading sample. A pixel is over the shading bound when
/// its difference *beyond the storage rounding of each side*
/// ([`Quantisation`]) exceeds `shading_max`: an 8-bit image's half-code
/// rounding is never counted, yet one code of change anywhere (0.00015 in
/// linear at the dark end, 0.0044 at the bright end) is. The per-pixel
/// errors (the heat map) are those differences beyond rounding.
///
/// # Panics
///
/// If the sizes differ.
#[must_use]
pub(crate) fn compare_images(
    w: u32,
    h: u32,
    (a, b): (&[Rgb], &[Rgb]),
    quant: [Quantisation; 2],
    tol: &ImageTolerances,
    shading_max: f64,
) -> Comparison {
    assert_eq!(a.len(), b.len(), "images differ in size");
    let mut errors = Vec::with_capacity(a.len());
    let (mut sum, mut sq, mut max, mut over) = (0.0f64, 0.0f64, 0.0f64, 0u64);
    let mut over_max8 = 0u8;
    for (p, q) in a.iter().zip(b) {
        let e = f64::from(sample_error(*p, *q));
        sum += e;
        max = max.max(e);
        let beyond = quantised_error(*p, *q, quant);
        errors.push(beyond);
        if f64::from(beyond) > shading_max {
            over += 1;
            over_max8 = over_max8.max(max8_diff(*p, *q));
        }
        for (x, y) in p.clamp01().to_array().iter().zip(q.clamp01().to_array()) {
            sq += f64::from(x - y).powi(2);
        }
    }
    #[expect(clippy::cast_precision_loss, reason = "pixel counts below 2^52")]
    let n = a.len().max(1) as f64;
    let rmse = (sq / (3.0 * n)).sqrt();
    let (image, flip) = metrics::image_stats(w, h, a, b);
    let pass = match (tol.fuzzy, tol.rule) {
        (Some(f), _) => over <= f.pixels && over_max8 <= f.max_diff,
        (None, ImageRule::SameFrame) => over == 0,
        (None, ImageRule::Renderer) => {
            // Enough pixels within pov_max8 (8-bit sRGB).
            let within = a
                .iter()
                .zip(b)
                .filter(|(p, q)| f64::from(max8_diff(**p, **q)) <= tol.pov_max8)
                .count();
            #[expect(clippy::cast_precision_loss, reason = "pixel counts below 2^52")]
            let enough = within as f64 >= tol.pov_fraction * n;
            enough
        }
    };
    Comparison {
        flip,
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
        judged: None,
        pass,
    }
}
