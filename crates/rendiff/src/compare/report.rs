//! The verdict as text, JSON (DESIGN.md §5) and HTML.

use std::fmt::Write as _;

use serde::Serialize;

use super::clusters::Clusters;
use super::{Comparison, ImageStats, ImageTolerances, ShadingStats, Tolerances, VisibilityCounts};

/// The limits a tie's local tolerance may not exceed (derived constants).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ToleranceLimits {
    /// Widest edge tie (px).
    pub edge_px: f64,
    /// Largest depth difference of a depth tie, relative to the depth.
    pub depth_rel: f64,
    /// Largest error part of a depth tie (beside the depth format's
    /// resolution), relative to the depth.
    pub depth_error_rel: f64,
    /// Largest clip-plane error, relative to the plane's distance.
    pub near_rel: f64,
}

/// The JSON `tolerance` object. The visibility tolerances are per sample
/// (DESIGN.md §6): their largest value and 99th percentile over the samples
/// the oracle judged (null when one side is an image), beside the limits.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ToleranceJson {
    /// ε_edge (px): the largest over the judged samples.
    pub edge_px: Option<f64>,
    /// ε_edge: 99th percentile.
    pub edge_px_p99: Option<f64>,
    /// δ_t relative to the depth: the largest.
    pub depth_rel: Option<f64>,
    /// δ_t relative to the depth: 99th percentile.
    pub depth_rel_p99: Option<f64>,
    /// δ_near (view-depth units): the largest.
    pub near_eps: Option<f64>,
    /// δ_near: 99th percentile.
    pub near_eps_p99: Option<f64>,
    /// Samples the oracle judged (the two sides saw different surfaces).
    pub judged: Option<u64>,
    /// The limits of the local tolerances.
    pub limits: ToleranceLimits,
    /// ε_g.
    pub gate_eps: f64,
    /// Shading bound.
    pub shading_max: f64,
    /// For image comparisons: the 8-bit bound.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pov_max8: Option<f64>,
    /// For image comparisons: the fraction of pixels that must meet it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pov_fraction: Option<f64>,
    /// For image comparisons: the user's fuzzy rule, when one decides.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fuzzy: Option<super::Fuzzy>,
    /// For image comparisons: the derived rule (`renderer`: POV-Ray's
    /// `pov_max8`/`pov_fraction`; `same_frame`: no pixel beyond the
    /// images' rounding).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image_rule: Option<super::ImageRule>,
}

/// Times of the two sides (ms; null for a stored image).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Times {
    /// Side a.
    pub a: Option<f64>,
    /// Side b.
    pub b: Option<f64>,
}

/// The version of the JSON report's layout: 2 added `schema_version` and
/// `clusters`.
pub const SCHEMA_VERSION: u32 = 2;

/// One scene's verdict, serialised as DESIGN.md §5's JSON object.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The scene file as given.
    pub scene: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Side a.
    pub a: String,
    /// Side b.
    pub b: String,
    /// Sample points compared (W·H·n², or W·H for images).
    pub samples: u64,
    /// The ray-tree depth both sides used.
    pub max_depth: u32,
    /// Visibility classes (null when a side is an image).
    pub visibility: Option<VisibilityCounts>,
    /// Shading statistics.
    pub shading: ShadingStats,
    /// Image statistics.
    pub image: ImageStats,
    /// Tolerances.
    pub tolerance: ToleranceJson,
    /// Times.
    pub time_ms: Times,
    /// "pass" or "fail".
    pub verdict: String,
    /// Remarks, e.g. a forced max_depth.
    pub notes: Vec<String>,
    /// For a frame against an image: why the pixels beyond the 8-bit bound differ.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub explained: Option<super::explain::Explained>,
    /// Where the sides disagree: the failing and notable pixels in
    /// connected clusters (`compare::clusters`).
    pub clusters: Clusters,
}

impl Report {
    /// Builds a report from a comparison.
    #[must_use]
    #[expect(clippy::too_many_arguments, reason = "one field each")]
    pub fn new(
        scene: &str,
        (width, height): (u32, u32),
        (a, b): (&str, &str),
        max_depth: u32,
        cmp: &Comparison,
        tol: &Tolerances,
        image_tol: Option<&ImageTolerances>,
        time_ms: Times,
        notes: Vec<String>,
    ) -> Report {
        Report {
            schema_version: SCHEMA_VERSION,
            scene: scene.to_string(),
            width,
            height,
            a: a.to_string(),
            b: b.to_string(),
            samples: u64::from(cmp.grid.0) * u64::from(cmp.grid.1),
            max_depth,
            visibility: cmp.visibility,
            shading: cmp.shading,
            image: cmp.image,
            tolerance: ToleranceJson {
                edge_px: cmp.judged.map(|j| j.edge_px.max),
                edge_px_p99: cmp.judged.map(|j| j.edge_px.p99),
                depth_rel: cmp.judged.map(|j| j.depth_rel.max),
                depth_rel_p99: cmp.judged.map(|j| j.depth_rel.p99),
                near_eps: cmp.judged.map(|j| j.near_eps.max),
                near_eps_p99: cmp.judged.map(|j| j.near_eps.p99),
                judged: cmp.judged.map(|j| j.judged),
                limits: ToleranceLimits {
                    edge_px: tol.edge_px_limit,
                    depth_rel: tol.depth_rel_limit,
                    depth_error_rel: tol.depth_error_limit,
                    near_rel: tol.near_rel_limit,
                },
                gate_eps: tol.gate_eps,
                shading_max: tol.shading_max,
                pov_max8: image_tol.map(|t| t.pov_max8),
                pov_fraction: image_tol.map(|t| t.pov_fraction),
                fuzzy: image_tol.and_then(|t| t.fuzzy),
                image_rule: image_tol.map(|t| t.rule),
            },
            time_ms,
            verdict: if cmp.pass { "pass" } else { "fail" }.to_string(),
            notes,
            explained: None,
            clusters: Clusters::default(),
        }
    }

    /// `true` when the verdict is pass.
    #[must_use]
    pub fn passed(&self) -> bool {
        self.verdict == "pass"
    }

    /// The short human summary.
    #[must_use]
    pub fn summary(&self) -> String {
        let mut o = String::new();
        let _ = writeln!(
            o,
            "{}: {} vs {}, {}x{}, {} samples, max_depth {}",
            self.scene, self.a, self.b, self.width, self.height, self.samples, self.max_depth
        );
        for n in &self.notes {
            let _ = writeln!(o, "  note: {n}");
        }
        if let Some(v) = &self.visibility {
            let _ = writeln!(
                o,
                "  visibility: {} agree, {} edge ties, {} depth ties, {} near ties, {} unjudgeable, {} real",
                v.agree, v.edge_tie, v.depth_tie, v.near_tie, v.unjudgeable, v.real
            );
        }
        let s = &self.shading;
        let _ = write!(
            o,
            "  shading: max {:.2e} (tolerance {:.2e}), mean {:.2e}, rmse {:.2e}, psnr {}, {} over",
            s.max,
            self.tolerance.shading_max,
            s.mean,
            s.rmse,
            if s.psnr.is_finite() {
                format!("{:.1} dB", s.psnr)
            } else {
                "inf".into()
            },
            s.over_threshold
        );
        if let (Some(t), Some(m)) = (s.ties, s.tie_max) {
            let _ = write!(o, ", {t} shading ties (max {m:.3})");
        }
        o.push('\n');
        let _ = writeln!(
            o,
            "  image: max 8-bit difference {}, {} pixels differ, SSIM {:.5}, FLIP mean {:.5} (max {:.3})",
            self.image.max_channel_8bit,
            self.image.differing_pixels,
            self.image.ssim,
            self.image.flip.mean,
            self.image.flip.max
        );
        if let Some(e) = &self.explained {
            let _ = writeln!(
                o,
                "  beyond the 8-bit bound: {} pixel(s): {} at edges, {} depth ties, {} shadow boundaries or gates, {} before the near plane, {} in the ray tree, {} under Blinn bumps, {} unexplained",
                e.differing,
                e.edge,
                e.depth_tie,
                e.shadow_or_gate,
                e.near_plane,
                e.ray_tree,
                e.blinn_bump,
                e.unexplained
            );
        }
        if let Some(c) = self.clusters.list.first() {
            let _ = writeln!(
                o,
                "  clusters: {} ({} listed); first: {} pixel(s) {} at x {}..={}, y {}..={}",
                self.clusters.total,
                self.clusters.list.len(),
                c.pixels,
                c.kind.name(),
                c.bbox.x0,
                c.bbox.x1,
                c.bbox.y0,
                c.bbox.y1
            );
        }
        let t = &self.tolerance;
        if let (Some(e), Some(d), Some(n), Some(j)) = (t.edge_px, t.depth_rel, t.near_eps, t.judged)
        {
            let _ = write!(
                o,
                "  tolerance ({j} samples judged): edge ≤ {e:.4} px (limit {:.4}), depth ≤ {d:.1e} of t (limit {:.1e}), near ≤ {n:.1e}, gate {:.1e}",
                t.limits.edge_px, t.limits.depth_rel, t.gate_eps
            );
        } else {
            let _ = write!(o, "  tolerance: gate {:.1e}", t.gate_eps);
        }
        match (t.fuzzy, t.image_rule, t.pov_max8, t.pov_fraction) {
            (Some(f), ..) => {
                let _ = write!(
                    o,
                    ", the user's fuzzy rule: ≤ {} pixels differ, by ≤ {} codes",
                    f.pixels, f.max_diff
                );
            }
            (None, Some(super::ImageRule::SameFrame), ..) => {
                o.push_str(", no pixel beyond the images' rounding");
            }
            (None, _, Some(m), Some(f)) => {
                let _ = write!(o, ", 8-bit ≤ {m} on ≥ {:.2}% of pixels", f * 100.0);
            }
            _ => {}
        }
        o.push('\n');
        let ms = |v: Option<f64>| v.map_or_else(|| "stored".to_string(), |v| format!("{v:.1} ms"));
        let _ = writeln!(
            o,
            "  time: {} {}, {} {}",
            self.a,
            ms(self.time_ms.a),
            self.b,
            ms(self.time_ms.b)
        );
        let _ = writeln!(o, "  verdict: {}", self.verdict);
        o
    }

    /// A summary that is stable across machines and runs: class counts
    /// exactly, errors rounded to one significant digit in log steps, no
    /// times. For insta snapshots.
    #[must_use]
    pub fn stable_summary(&self) -> String {
        let mut o = String::new();
        let _ = writeln!(
            o,
            "{} vs {}: {}x{}, {} samples, max_depth {}",
            self.a, self.b, self.width, self.height, self.samples, self.max_depth
        );
        if let Some(v) = &self.visibility {
            let _ = writeln!(
                o,
                "visibility: agree {}, edge_tie {}, depth_tie {}, near_tie {}, unjudgeable {}, real {}",
                v.agree, v.edge_tie, v.depth_tie, v.near_tie, v.unjudgeable, v.real
            );
        }
        let s = &self.shading;
        let _ = writeln!(
            o,
            "shading: max {}, over {}, ties {}",
            decade(s.max),
            s.over_threshold,
            s.ties.map_or_else(|| "-".into(), |t| t.to_string())
        );
        let _ = writeln!(o, "verdict: {}", self.verdict);
        o
    }
}

/// A value rounded to its decade: "0", "< 1e-6", "~1e-4" …
#[must_use]
pub fn decade(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v < 1e-6 {
        "< 1e-6".into()
    } else {
        format!("<= 1e{}", v.log10().ceil())
    }
}

use crate::escape::html as esc;

/// The index page of several scenes with their verdicts.
#[must_use]
pub fn index_html(entries: &[(Report, String)]) -> String {
    let mut o = String::new();
    let pass = entries.iter().filter(|(r, _)| r.passed()).count();
    let _ = write!(
        o,
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>rendiff report</title>\n{STYLE}{LOAD_CHECK}</head><body>\n<h1>rendiff: {pass} of {} scenes pass</h1>\n<table>\n<tr><th>scene</th><th>a / b</th><th>verdict</th><th>real</th><th>shading max</th><th>8-bit max</th><th>clusters</th><th>composite</th></tr>\n",
        entries.len()
    );
    for (r, dir) in entries {
        let real = r
            .visibility
            .map_or_else(|| "–".to_string(), |v| v.real.to_string());
        let _ = writeln!(
            o,
            "<tr><td><a href=\"{page}\">{}</a></td><td>{} / {}</td><td class=\"{}\">{}</td><td>{real}</td><td>{:.2e}</td><td>{}</td><td>{}</td><td><a href=\"{page}\"><img class=\"thumb\" src=\"{thumb}\" alt=\"composite of {}\"></a></td></tr>",
            esc(&r.scene),
            esc(&r.a),
            esc(&r.b),
            r.verdict,
            r.verdict.to_uppercase(),
            r.shading.max,
            r.image.max_channel_8bit,
            r.clusters.total,
            esc(&r.scene),
            page = esc(&crate::escape::href(&format!("{dir}/index.html"))),
            thumb = esc(&crate::escape::href(&format!("{dir}/composite.png")))
        );
    }
    o.push_str("</table>\n</body></html>\n");
    o
}

use super::page::LOAD_CHECK;

const STYLE: &str = "<style>body{font-family:sans-serif;background:#1e1e22;color:#ddd;margin:2em}\
h1{font-weight:normal}.pass{color:#5c5}.fail{color:#f55}figure{display:inline-block;margin:0 1em 1em 0}\
figcaption{font-size:90%;color:#aaa}img{image-rendering:pixelated;border:1px solid #444}\
figure.wide{display:block;margin-right:0}figure.wide img{max-width:100%;height:auto}img.thumb{height:60px}table{border-collapse:collapse}td,th{padding:4px 10px;border-bottom:1px solid #333;text-align:left}\
pre{background:#111;padding:1em;white-space:pre-wrap}a{color:#8af}</style>\n";
