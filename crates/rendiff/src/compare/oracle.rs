//! The f64 oracle of DESIGN.md §6: at a sample where two frames report
//! different triangles, evaluate both triangles exactly enough to say why.
//!
//! Each triangle is clipped at the near and far planes in `f64` on its
//! unsnapped vertices, projected with the camera, and asked: is the sample
//! inside, how far is it from the nearest original edge and from the clip
//! segments (screen pixels), and at what depth `t` does the sample's
//! primary ray meet the triangle's plane.
//!
//! **Tolerances are local.** Every tolerance is derived at the sample from
//! the two triangles involved: the rasterizer's snapping (a constant), the
//! `f64` rounding of both backends' arithmetic on *these* vertices at
//! *this* depth, the depth format's resolution at *this* depth. Nothing is
//! derived from the scene's bounds, so a large floor elsewhere cannot widen
//! the tolerance here. A tie whose tolerance would have to exceed the
//! derived limits (`EDGE_TIE_MAX_PX`, `DEPTH_ERROR_MAX_REL`,
//! `CLIP_ERROR_MAX_REL`) is not a tie: the sample is *unjudgeable*, and
//! the verdict fails.

use crate::camera::{Camera, Projection};
use crate::math::{DVec3, gamma64, plane_barycentrics};
use crate::options::DepthFormat;
use crate::tri_scene::TriScene;

/// The widest edge tie (pixels). The finest sample grid is 1/16 px and
/// the verdict's negative control moves every edge by 1/32 px; a tie band
/// of at most 1/64 px keeps that control's mismatches real with a factor
/// of two to spare. The snapping bound alone is √2·2⁻⁹ ≈ 0.0028 px, so
/// 5.7× is left for the rounding of both backends (measured on every
/// bundled and hazard scene: below 10⁻⁶ px).
pub(crate) const EDGE_TIE_MAX_PX: f64 = 1.0 / 64.0;

/// The largest error part of a depth tie, relative to the depth (the depth
/// format's own resolution comes on top: it is what the format cannot
/// resolve, known exactly). Beyond a millimetre per metre two surfaces are
/// apart, whatever the rounding; the rounding itself is ~10⁻¹³.
pub(crate) const DEPTH_ERROR_MAX_REL: f64 = 1.0 / 1024.0;

/// The largest depth difference a depth tie may have in all, relative to
/// the depth, the depth format's resolution included. Surfaces a
/// thousandth of their distance apart are two surfaces: where a depth
/// format cannot resolve that (a 16-bit buffer beyond 64 times `near`, a
/// 24-bit one beyond 16 000 times), the rasterizer's choice between them
/// cannot be told from a bug, and the sample is unjudgeable.
pub(crate) const DEPTH_TIE_MAX_REL: f64 = 1.0 / 1024.0;

/// The largest error of a clip plane's position, relative to its distance
/// (`near` or `far`), for a clip tie; ~10⁻¹³ in practice.
pub(crate) const CLIP_ERROR_MAX_REL: f64 = 1.0 / 1024.0;

/// The classes of a visibility mismatch, in the order they are tried
/// (and, for the maps, from least to most serious).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Class {
    /// Both frames see the same triangle (or both the background).
    Agree,
    /// The sample lies within ε_edge of an edge of either triangle.
    EdgeTie,
    /// Inside both, and their depths differ by at most δ_t.
    DepthTie,
    /// At a clip segment (near or far), or a surface at a clip plane.
    NearTie,
    /// A tie only with a tolerance wider than a tie can be (or not
    /// finite): the verdict cannot tell a tie from a bug here.
    Unjudgeable,
    /// Anything else: a bug.
    Real,
}

impl Class {
    /// The name used in reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Class::Agree => "agree",
            Class::EdgeTie => "edge_tie",
            Class::DepthTie => "depth_tie",
            Class::NearTie => "near_tie",
            Class::Unjudgeable => "unjudgeable",
            Class::Real => "real",
        }
    }
}

/// What the oracle finds for one triangle at one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// The sample lies inside the (near- and far-clipped) projected triangle.
    pub inside: bool,
    /// Distance (px) to the nearest edge that is part of an original edge.
    pub edge_dist: f64,
    /// Distance (px) to the nearest clip segment (∞ if not clipped).
    pub clip_dist: f64,
    /// Ray parameter of the plane hit (along the unit primary ray).
    pub t: Option<f64>,
    /// View depth of the plane hit.
    pub z: Option<f64>,
    /// Largest screen gradient of `t` (per pixel).
    pub t_gradient: f64,
    /// Bound on the position error (px) of this triangle at this sample
    /// in either backend, beyond the snapping: the `f64` rounding of the
    /// rasterizer's projection and clipping, and of the ray tracer's
    /// watertight test on the camera ray.
    pub position_px: f64,
    /// Bound on the error of the ray tracer's `t` for this triangle.
    pub t_error: f64,
    /// Bound on the error of the clip planes' position (view depth) for
    /// this triangle, in either backend.
    pub clip_error: f64,
}

/// The tolerances one judged sample was given (for the distributions
/// reported beside the verdict).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Judged {
    /// The class.
    pub class: Class,
    /// ε_edge applied (px; within its limit).
    pub edge_px: f64,
    /// δ_t applied, relative to the depth, where both triangles were
    /// inside (within its limit).
    pub depth_rel: Option<f64>,
    /// δ_near applied (view-depth units; within its limit).
    pub clip: f64,
}

/// The oracle for one scene and camera.
#[derive(Debug)]
pub struct Oracle<'a> {
    scene: &'a TriScene,
    cam: Camera,
    depth: DepthFormat,
    /// A position error (px) added to every triangle's, for frames whose
    /// geometry differs from the scene's by a known rounding.
    extra_px: f64,
}

fn dist_to_segment(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (qx, qy) = (a.0 + t * dx - p.0, a.1 + t * dy - p.1);
    (qx * qx + qy * qy).sqrt()
}

/// Clips a polygon (points with "the edge from here is a clip edge" flags)
/// to the side of `keep(z)`, crossing at `z = plane`.
fn clip(
    poly: &[(DVec3, bool)],
    z: impl Fn(DVec3) -> f64,
    plane: f64,
    keep: impl Fn(f64) -> bool,
) -> Vec<(DVec3, bool)> {
    let mut out = Vec::with_capacity(poly.len() + 1);
    for i in 0..poly.len() {
        let (a, a_clip) = poly[i];
        let (b, _) = poly[(i + 1) % poly.len()];
        let (za, zb) = (z(a), z(b));
        let (a_in, b_in) = (keep(za), keep(zb));
        if a_in {
            out.push((a, a_clip));
        }
        if a_in != b_in {
            let t = (plane - za) / (zb - za);
            // Leaving the inside: the next edge runs along the clip line;
            // entering: the rest of a's edge is as it was.
            out.push((a + (b - a) * t, if a_in { true } else { a_clip }));
        }
    }
    out
}

impl<'a> Oracle<'a> {
    /// The oracle of a scene, for the rasterizer's depth format.
    #[must_use]
    pub fn new(scene: &'a TriScene, depth: DepthFormat) -> Oracle<'a> {
        Oracle {
            scene,
            cam: scene.camera,
            depth,
            extra_px: 0.0,
        }
    }

    /// The camera the oracle judges with (the scene's).
    pub(crate) fn camera(&self) -> &Camera {
        &self.cam
    }

    /// The same oracle for a frame rendered from vertices that differ from
    /// this scene's by up to `px` pixels (a scaled or moved copy of the
    /// scene, rounded to f32 anew): every triangle's position error grows
    /// by that much.
    #[must_use]
    pub fn with_vertex_error(mut self, px: f64) -> Oracle<'a> {
        self.extra_px = px;
        self
    }

    /// Pixels per radian of a direction change at the camera ray `d`
    /// (perspective; the local magnification, not the image's largest).
    fn px_per_radian(&self, d: DVec3) -> f64 {
        match self.cam.projection() {
            Projection::Perspective { tan_half_fov: t } => {
                let c = d.dot(self.cam.forward()).abs().max(1e-300);
                f64::from(self.cam.height()) / (2.0 * t) / (c * c)
            }
            Projection::Orthographic { .. } => 0.0,
        }
    }

    /// Evaluates triangle `tri` at screen point `(x, y)`.
    #[must_use]
    pub fn footprint(&self, tri: u32, x: f64, y: f64) -> Footprint {
        let v = self.scene.triangle_f64(tri);
        let cam = &self.cam;
        let (near, far) = (cam.near(), cam.far());
        let (o, d) = cam.primary_ray_f64(x, y);
        let hit = plane_barycentrics(o, d, v);
        let t = hit.map(|(_, t)| t);
        let zh = t.map(|t| cam.view_depth(o + d * t));
        let t_gradient = self.t_gradient(&v, x, y, t);

        // The rounding of both backends on these vertices (DESIGN.md §6):
        // every quantity is formed from coordinates relative to the eye,
        // of size ≤ m, by a few dozen f64 operations (γ₆₄ of 64 covers
        // them with room); a position error ε at depth t is an angle ε/t.
        let m = v
            .iter()
            .map(|p| (*p - o).abs().max_element())
            .fold(0.0f64, f64::max);
        let g = gamma64(64);
        let depth = t.unwrap_or(near).abs().max(near);
        let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
        let ray_px = match cam.projection() {
            Projection::Perspective { .. } => g * (m / depth) * self.px_per_radian(d),
            Projection::Orthographic { view_height } => {
                g * (m + o.abs().max_element()) * h / view_height
            }
        };
        let t_error = g * (m + depth);
        let clip_error = g * (m + o.abs().max_element() + far.min(m + depth));

        let poly = [(v[0], false), (v[1], false), (v[2], false)];
        let poly = clip(&poly, |p| cam.view_depth(p), near, |z| z >= near);
        let poly = clip(&poly, |p| cam.view_depth(p), far, |z| z <= far);
        let mut fp = Footprint {
            inside: false,
            edge_dist: f64::INFINITY,
            clip_dist: f64::INFINITY,
            t,
            z: zh,
            t_gradient,
            position_px: ray_px + g * (w + h) + self.extra_px,
            t_error,
            clip_error,
        };
        if poly.len() < 3 {
            return fp;
        }
        let pts: Vec<Option<(f64, f64)>> = poly
            .iter()
            .map(|(p, _)| cam.project(*p).map(|(px, py, _)| (px, py)))
            .collect();
        let mut sign = 0.0f64;
        let mut inside = true;
        let mut extent = 0.0f64;
        for i in 0..poly.len() {
            let (Some(a), Some(b)) = (pts[i], pts[(i + 1) % poly.len()]) else {
                // A vertex exactly at the eye plane (ortho never): no screen edge.
                inside = false;
                continue;
            };
            extent = extent.max(a.0.abs() + a.1.abs());
            let dist = dist_to_segment((x, y), a, b);
            if poly[i].1 {
                fp.clip_dist = fp.clip_dist.min(dist);
            } else {
                fp.edge_dist = fp.edge_dist.min(dist);
            }
            let cross = (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0);
            if cross != 0.0 {
                if sign == 0.0 {
                    sign = cross.signum();
                } else if cross.signum() != sign {
                    inside = false;
                }
            }
        }
        fp.inside = inside;
        // The rasterizer's projected vertices carry γ of their own size.
        fp.position_px = ray_px + g * (w + h + extent) + self.extra_px;
        fp
    }

    /// |∂t/∂x| + |∂t/∂y| (per pixel) of the triangle's plane at the sample,
    /// by central differences of the exact plane hit.
    fn t_gradient(&self, v: &[DVec3; 3], x: f64, y: f64, t: Option<f64>) -> f64 {
        let Some(t0) = t else { return 0.0 };
        let at = |x: f64, y: f64| {
            let (o, d) = self.cam.primary_ray_f64(x, y);
            plane_barycentrics(o, d, *v).map(|(_, t)| t)
        };
        let h = 0.5;
        let gx = match (at(x + h, y), at(x - h, y)) {
            (Some(a), Some(b)) => (a - b).abs() / (2.0 * h),
            _ => t0.abs(),
        };
        let gy = match (at(x, y + h), at(x, y - h)) {
            (Some(a), Some(b)) => (a - b).abs() / (2.0 * h),
            _ => t0.abs(),
        };
        gx + gy
    }

    /// The depth-format resolution (in `t`) at ray parameter `t` and view depth `z`.
    #[must_use]
    pub fn format_resolution(&self, t: f64, z: f64) -> f64 {
        let cam = &self.cam;
        let (near, far) = (cam.near(), cam.far());
        let scale = if z > 0.0 { t / z } else { 1.0 };
        let perspective = matches!(cam.projection(), Projection::Perspective { .. });
        match self.depth {
            // Reversed-Z f32: one ulp of near/z (≤ 2^-23 relative), both
            // roundings (stored and compared value).
            DepthFormat::F32 => {
                if perspective {
                    2.0 * t * f64::from(f32::EPSILON)
                } else {
                    2.0 * f64::from(f32::EPSILON) * (far - near) * scale
                }
            }
            // One quantisation step of q, mapped back to depth.
            DepthFormat::U24 | DepthFormat::U16 => {
                let step = 1.0 / self.depth.max_key().unwrap_or(f64::from(u32::MAX));
                let dz = if perspective {
                    step * z * z * (1.0 / near - 1.0 / far)
                } else {
                    step * (far - near)
                };
                dz * scale
            }
        }
    }

    /// The error part of one triangle's δ_t: the interpolation drift, the
    /// ray tracer's own error of `t`, and the depth change over the
    /// sample's position error.
    #[must_use]
    pub fn depth_error(&self, f: &Footprint) -> f64 {
        let Some(t) = f.t else {
            return f64::INFINITY;
        };
        let drift = crate::coverage::DEPTH_DRIFT_REL * t.abs();
        drift + f.t_error + f.t_gradient * f.position_px
    }

    /// δ_t of one triangle's footprint: the depth format's resolution plus
    /// [`Oracle::depth_error`].
    #[must_use]
    pub fn depth_tolerance(&self, f: &Footprint) -> f64 {
        let (Some(t), Some(z)) = (f.t, f.z) else {
            return f64::INFINITY;
        };
        self.format_resolution(t, z) + self.depth_error(f)
    }

    /// ε_edge at a sample whose two triangles have these footprints.
    #[must_use]
    pub fn edge_tolerance(fa: Option<&Footprint>, fb: Option<&Footprint>) -> f64 {
        let pos = [fa, fb]
            .iter()
            .flatten()
            .map(|f| f.position_px)
            .fold(0.0f64, f64::max);
        crate::coverage::SNAP_BOUND_PX + pos
    }

    /// Classifies the sample at screen point `(x, y)` whose frames report
    /// `a` and `b` (`None`: background).
    #[must_use]
    pub fn classify(&self, x: f64, y: f64, a: Option<u32>, b: Option<u32>) -> Class {
        self.judge(x, y, a, b).class
    }

    /// Classifies a sample and reports the tolerances it was judged with.
    #[must_use]
    pub fn judge(&self, x: f64, y: f64, a: Option<u32>, b: Option<u32>) -> Judged {
        if a == b {
            return Judged {
                class: Class::Agree,
                edge_px: 0.0,
                depth_rel: None,
                clip: 0.0,
            };
        }
        let fa = a.map(|t| self.footprint(t, x, y));
        let fb = b.map(|t| self.footprint(t, x, y));
        let (fa, fb) = (fa.as_ref(), fb.as_ref());
        let nan_to_inf = |v: f64| if v.is_nan() { f64::INFINITY } else { v };
        let edge = nan_to_inf(Self::edge_tolerance(fa, fb));
        let edge_ok = edge.min(EDGE_TIE_MAX_PX);
        let near_edge = |tol: f64| [fa, fb].iter().flatten().any(|f| f.edge_dist <= tol);

        // Depth: both inside, at finite depths.
        let depth = match (fa, fb) {
            (Some(pa), Some(pb)) if pa.inside && pb.inside => match (pa.t, pb.t, pa.z, pb.z) {
                (Some(ta), Some(tb), Some(za), Some(zb)) => {
                    let format = self.format_resolution(ta, za) + self.format_resolution(tb, zb);
                    let error = nan_to_inf(self.depth_error(pa) + self.depth_error(pb));
                    let t = ta.abs().max(tb.abs());
                    Some(((ta - tb).abs(), format, error, t))
                }
                _ => None,
            },
            _ => None,
        };
        let depth_tie = |capped: bool| {
            depth.is_some_and(|(diff, format, error, t)| {
                if capped {
                    let tol =
                        (format + error.min(DEPTH_ERROR_MAX_REL * t)).min(DEPTH_TIE_MAX_REL * t);
                    diff <= tol
                } else {
                    diff <= format + error
                }
            })
        };

        // Clip planes: the sample at a clip segment, or a surface at a plane.
        let cam = &self.cam;
        let clip = nan_to_inf(
            [fa, fb]
                .iter()
                .flatten()
                .map(|f| f.clip_error)
                .fold(0.0f64, f64::max),
        );
        let at_clip = |tol_px: f64, capped: bool| {
            let tol = |plane: f64| {
                if capped {
                    clip.min(CLIP_ERROR_MAX_REL * plane)
                } else {
                    clip
                }
            };
            [fa, fb].iter().flatten().any(|f| {
                f.clip_dist <= tol_px
                    || f.z.is_some_and(|z| {
                        (z - cam.near()).abs() <= tol(cam.near())
                            || (z - cam.far()).abs() <= tol(cam.far())
                    })
            })
        };

        // The tolerances as applied: each within its limit (a sample that
        // would need more is unjudgeable, and counted as such).
        let judged = |class: Class| Judged {
            class,
            edge_px: edge_ok,
            depth_rel: depth.map(|(_, format, error, t)| {
                let t = t.max(f64::MIN_POSITIVE);
                ((format + error.min(DEPTH_ERROR_MAX_REL * t)) / t).min(DEPTH_TIE_MAX_REL)
            }),
            clip: clip.min(CLIP_ERROR_MAX_REL * cam.near().max(cam.far())),
        };
        if near_edge(edge_ok) {
            return judged(Class::EdgeTie);
        }
        if depth_tie(true) {
            return judged(Class::DepthTie);
        }
        if at_clip(edge_ok, true) {
            return judged(Class::NearTie);
        }
        // A tie only with a tolerance beyond its limit: cannot be judged.
        if near_edge(edge) || depth_tie(false) || at_clip(edge, false) {
            return judged(Class::Unjudgeable);
        }
        judged(Class::Real)
    }
}
