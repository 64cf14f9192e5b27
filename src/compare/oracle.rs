//! The f64 oracle of DESIGN.md §6: at a sample where two frames report
//! different triangles, evaluate both triangles exactly enough to say why.
//!
//! Each triangle is clipped at the near plane in `f64` on its unsnapped
//! vertices, projected with the camera, and asked: is the sample inside,
//! how far is it from the nearest original edge and from the near-clip
//! segment (screen pixels), and at what depth `t` does the sample's
//! primary ray meet the triangle's plane.

use crate::accel::triangle::plane_barycentrics;
use crate::camera::{Camera, Projection};
use crate::math::DVec3;
use crate::options::DepthFormat;
use crate::tri_scene::TriScene;

/// The classes of a visibility mismatch, in the order they are tried.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Class {
    /// Both frames see the same triangle (or both the background).
    Agree,
    /// The sample lies within ε_edge of an edge of either triangle.
    EdgeTie,
    /// Inside both, and their depths differ by at most δ_t.
    DepthTie,
    /// At the near-plane clip segment, or a surface at the near plane.
    NearTie,
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
            Class::Real => "real",
        }
    }
}

/// What the oracle finds for one triangle at one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// The sample lies inside the (near-clipped) projected triangle.
    pub inside: bool,
    /// Distance (px) to the nearest edge that is part of an original edge.
    pub edge_dist: f64,
    /// Distance (px) to the near-clip segment (∞ if not clipped).
    pub near_dist: f64,
    /// Ray parameter of the plane hit (along the unit primary ray).
    pub t: Option<f64>,
    /// View depth of the plane hit.
    pub z: Option<f64>,
    /// Largest screen gradient of `t` (per pixel).
    pub t_gradient: f64,
}

/// The oracle for one scene and camera.
#[derive(Debug)]
pub struct Oracle<'a> {
    scene: &'a TriScene,
    cam: Camera,
    /// ε_edge (pixels).
    pub edge_px: f64,
    /// δ_near (world units of view depth).
    pub near_eps: f64,
    depth: DepthFormat,
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

impl<'a> Oracle<'a> {
    /// An oracle with the given tolerances.
    #[must_use]
    pub fn new(scene: &'a TriScene, edge_px: f64, near_eps: f64, depth: DepthFormat) -> Oracle<'a> {
        Oracle {
            scene,
            cam: scene.camera,
            edge_px,
            near_eps,
            depth,
        }
    }

    /// Evaluates triangle `tri` at screen point `(x, y)`.
    #[must_use]
    pub fn footprint(&self, tri: u32, x: f64, y: f64) -> Footprint {
        let v = self.scene.triangle_f64(tri);
        let cam = &self.cam;
        let near = cam.near();
        // Clip at z = near in 3-D, marking the edges the clip creates.
        let z: Vec<f64> = v.iter().map(|p| cam.view_depth(*p)).collect();
        let mut poly: Vec<(DVec3, bool)> = Vec::with_capacity(4); // (point, edge from here is a clip edge)
        for i in 0..3 {
            let (a, b) = (v[i], v[(i + 1) % 3]);
            let (za, zb) = (z[i], z[(i + 1) % 3]);
            let a_in = za >= near;
            let b_in = zb >= near;
            if a_in {
                poly.push((a, false));
            }
            if a_in != b_in {
                let t = (near - za) / (zb - za);
                let p = a + (b - a) * t;
                // Leaving the inside: the next edge runs along the clip line.
                poly.push((p, a_in));
            }
        }
        let (o, d) = cam.primary_ray_f64(x, y);
        let hit = plane_barycentrics(o, d, v);
        let t = hit.map(|(_, t)| t);
        let zh = t.map(|t| cam.view_depth(o + d * t));
        let t_gradient = self.t_gradient(&v, x, y, t);
        if poly.len() < 3 {
            return Footprint {
                inside: false,
                edge_dist: f64::INFINITY,
                near_dist: f64::INFINITY,
                t,
                z: zh,
                t_gradient,
            };
        }
        let pts: Vec<Option<(f64, f64)>> = poly
            .iter()
            .map(|(p, _)| cam.project(*p).map(|(px, py, _)| (px, py)))
            .collect();
        let mut edge_dist = f64::INFINITY;
        let mut near_dist = f64::INFINITY;
        let mut sign = 0.0f64;
        let mut inside = true;
        for i in 0..poly.len() {
            let (Some(a), Some(b)) = (pts[i], pts[(i + 1) % poly.len()]) else {
                // A vertex exactly at the eye plane (ortho never): no screen edge.
                inside = false;
                continue;
            };
            let dist = dist_to_segment((x, y), a, b);
            if poly[i].1 {
                near_dist = near_dist.min(dist);
            } else {
                edge_dist = edge_dist.min(dist);
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
        Footprint {
            inside,
            edge_dist,
            near_dist,
            t,
            z: zh,
            t_gradient,
        }
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
                let bits = self.depth.bits().unwrap_or(24);
                let step = 1.0 / f64::from((1u32 << bits) - 1);
                let dz = if perspective {
                    step * z * z * (1.0 / near - 1.0 / far)
                } else {
                    step * (far - near)
                };
                dz * scale
            }
        }
    }

    /// δ_t of one triangle's footprint: format resolution + gradient ×
    /// snapping bound + interpolation drift + the ray's own error.
    #[must_use]
    pub fn depth_tolerance(&self, f: &Footprint) -> f64 {
        let (Some(t), Some(z)) = (f.t, f.z) else {
            return 0.0;
        };
        let snap = crate::coverage::SNAP_BOUND_PX;
        let drift = crate::coverage::DEPTH_DRIFT_REL * t.abs();
        let ray = f64::from(crate::math::gamma(16)) * t.abs();
        self.format_resolution(t, z) + f.t_gradient * snap + drift + ray
    }

    /// Classifies the sample at screen point `(x, y)` whose frames report
    /// `a` and `b` (`None`: background).
    #[must_use]
    pub fn classify(&self, x: f64, y: f64, a: Option<u32>, b: Option<u32>) -> Class {
        if a == b {
            return Class::Agree;
        }
        let fa = a.map(|t| self.footprint(t, x, y));
        let fb = b.map(|t| self.footprint(t, x, y));
        let near_edge =
            |f: &Option<Footprint>| f.as_ref().is_some_and(|f| f.edge_dist <= self.edge_px);
        if near_edge(&fa) || near_edge(&fb) {
            return Class::EdgeTie;
        }
        if let (Some(pa), Some(pb)) = (&fa, &fb)
            && pa.inside
            && pb.inside
            && let (Some(ta), Some(tb)) = (pa.t, pb.t)
        {
            let tol = self.depth_tolerance(pa) + self.depth_tolerance(pb);
            if (ta - tb).abs() <= tol {
                return Class::DepthTie;
            }
        }
        let at_near = |f: &Option<Footprint>| {
            f.as_ref().is_some_and(|f| {
                f.near_dist <= self.edge_px
                    || f.z
                        .is_some_and(|z| (z - self.cam.near()).abs() <= self.near_eps)
            })
        };
        if at_near(&fa) || at_near(&fb) {
            return Class::NearTie;
        }
        Class::Real
    }
}
