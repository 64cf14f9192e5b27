//! Watertight ray/triangle intersection (Woop, Benthin & Wald, "Watertight
//! Ray/Triangle Intersection", JCGT 2(1), 2013), with pbrt-v4's
//! conservative bound on `t` so a ray spawned on a surface never reports
//! a hit at a `t` indistinguishable from 0.
//!
//! The ray is translated to the origin, the axes permuted so the ray runs
//! along +z, and the triangle sheared so the ray becomes the z axis; the
//! hit is then a 2-D inside test of three edge functions that are exact
//! negatives of each other across a shared edge (the same products in the
//! same order), so no ray slips between two triangles and none hits both
//! except exactly on the shared edge. A zero edge function is recomputed in
//! `f64`, where the products of two `f32` values are exact.

use glam::Vec4;

use crate::math::{Ray, Vec3, gamma};

/// Per-ray constants of the watertight test.
#[derive(Clone, Copy, Debug)]
pub struct RayPrecomp {
    /// Origin.
    pub origin: Vec3,
    /// Axis permutation: the dominant axis of the direction is `kz`.
    pub k: [usize; 3],
    /// Shear constants `(Sx, Sy, Sz)`.
    pub s: Vec3,
    /// The origin's coordinates, each in four lanes (for [`candidates`]).
    o4: [Vec4; 3],
    /// `Sx` and `Sy` in four lanes.
    s4: [Vec4; 2],
}

impl RayPrecomp {
    /// Precomputes the permutation and shear of a ray.
    #[must_use]
    pub fn new(ray: &Ray) -> RayPrecomp {
        let d = ray.dir;
        let ad = d.abs();
        let kz = if ad.x > ad.y {
            if ad.x > ad.z { 0 } else { 2 }
        } else if ad.y > ad.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swap when the dominant component is negative.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let s = Vec3::new(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
        RayPrecomp {
            origin: ray.origin,
            k: [kx, ky, kz],
            s,
            o4: [
                Vec4::splat(ray.origin.x),
                Vec4::splat(ray.origin.y),
                Vec4::splat(ray.origin.z),
            ],
            s4: [Vec4::splat(s.x), Vec4::splat(s.y)],
        }
    }
}

/// Four triangles as structure of arrays: `v[corner][axis]` holds that
/// coordinate of the four triangles, one per lane. Leaves of the BVH are
/// runs of packs; `lanes` says how many lanes are triangles and `last`
/// whether the leaf ends here.
#[derive(Clone, Copy, Debug)]
pub struct TriPack {
    /// Corner coordinates, `v[corner][axis]`, a triangle per lane.
    pub v: [[Vec4; 3]; 3],
    /// Lanes in use (1 … 4).
    pub lanes: u32,
    /// The last pack of its leaf.
    pub last: bool,
}

impl TriPack {
    /// An empty pack (no lanes).
    pub const EMPTY: TriPack = TriPack {
        v: [[Vec4::ZERO; 3]; 3],
        lanes: 0,
        last: true,
    };

    /// The triangle in `lane`.
    #[must_use]
    #[inline]
    pub fn triangle(&self, lane: usize) -> [Vec3; 3] {
        self.v
            .map(|c| Vec3::new(c[0][lane], c[1][lane], c[2][lane]))
    }

    /// Puts a triangle in `lane`.
    pub fn set(&mut self, lane: usize, tri: [Vec3; 3]) {
        for (corner, p) in tri.iter().enumerate() {
            self.v[corner][0][lane] = p.x;
            self.v[corner][1][lane] = p.y;
            self.v[corner][2][lane] = p.z;
        }
    }
}

/// The lanes of `pack` that [`intersect`] could accept, as a bit mask (a
/// superset: the lanes whose sheared edge functions do not already show
/// the ray passing outside). The four edge tests run at once on SSE lanes
/// with exactly the scalar test's operations, so a lane is dropped only
/// where [`intersect`] would reject it; the survivors (the hits, and the
/// rare exact zeros that the scalar test re-evaluates in `f64`) are then
/// tested one by one, which keeps the results bit-identical.
#[must_use]
#[inline]
pub fn candidates(pre: &RayPrecomp, pack: &TriPack) -> u32 {
    let [kx, ky, kz] = pre.k;
    let [sx, sy] = pre.s4;
    let o = &pre.o4;
    let shear = |c: &[Vec4; 3]| {
        let x = c[kx] - o[kx];
        let y = c[ky] - o[ky];
        let z = c[kz] - o[kz];
        (x - sx * z, y - sy * z)
    };
    let (ax, ay) = shear(&pack.v[0]);
    let (bx, by) = shear(&pack.v[1]);
    let (cx, cy) = shear(&pack.v[2]);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let zero = Vec4::ZERO;
    let exact_zero = u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero);
    let neg = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
    let pos = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
    let outside = (neg & pos & !exact_zero).bitmask();
    !outside & ((1u32 << pack.lanes) - 1)
}

/// A hit: distance and the barycentric weights (of v0, v1, v2) as the
/// watertight test computes them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriHit {
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weights.
    pub b: [f32; 3],
}

/// Intersects a ray with a triangle, accepting `t_min ≤ t ≤ t_max`
/// (inclusive at `t_max`, so a caller that orders equal distances by
/// triangle id sees every tie).
#[must_use]
#[inline]
#[expect(clippy::similar_names, reason = "the paper's names")]
pub fn intersect(pre: &RayPrecomp, v: &[Vec3; 3], t_min: f32, t_max: f32) -> Option<TriHit> {
    let [kx, ky, kz] = pre.k;
    let a = v[0] - pre.origin;
    let b = v[1] - pre.origin;
    let c = v[2] - pre.origin;
    let (sx, sy, sz) = (pre.s.x, pre.s.y, pre.s.z);
    let ax = a[kx] - sx * a[kz];
    let ay = a[ky] - sy * a[kz];
    let bx = b[kx] - sx * b[kz];
    let by = b[ky] - sy * b[kz];
    let cx = c[kx] - sx * c[kz];
    let cy = c[ky] - sy * c[kz];
    let mut u = cx * by - cy * bx;
    let mut vv = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || vv == 0.0 || w == 0.0 {
        // Exact in f64: the product of two f32 values fits a double.
        let d = |p: f32, q: f32, r: f32, s: f32| {
            #[expect(clippy::cast_possible_truncation, reason = "sign-exact rounding back")]
            let x = (f64::from(p) * f64::from(q) - f64::from(r) * f64::from(s)) as f32;
            x
        };
        u = d(cx, by, cy, bx);
        vv = d(ax, cy, ay, cx);
        w = d(bx, ay, by, ax);
    }
    if (u < 0.0 || vv < 0.0 || w < 0.0) && (u > 0.0 || vv > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + vv + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let az = sz * a[kz];
    let bz = sz * b[kz];
    let cz = sz * c[kz];
    let t_scaled = u * az + vv * bz + w * cz;
    // Reject hits behind t_min without dividing (T and det must have the
    // same sign and |T| ≥ t_min·|det|); the far bound is compared after the
    // division, on the very value that is returned, so that a tie at
    // exactly t_max (equal t from another triangle) is always seen.
    if det > 0.0 {
        if t_scaled < t_min * det {
            return None;
        }
    } else if t_scaled > t_min * det {
        return None;
    }
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if t > t_max || t < t_min {
        return None;
    }

    // pbrt-v4: reject t within the rounding error of 0.
    let max_zt = az.abs().max(bz.abs()).max(cz.abs());
    let max_xt = ax.abs().max(bx.abs()).max(cx.abs());
    let max_yt = ay.abs().max(by.abs()).max(cy.abs());
    let delta_z = gamma(3) * max_zt;
    let delta_x = gamma(5) * (max_xt + max_zt);
    let delta_y = gamma(5) * (max_yt + max_zt);
    let delta_e = 2.0 * (gamma(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
    let max_e = u.abs().max(vv.abs()).max(w.abs());
    let delta_t =
        3.0 * (gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * inv.abs();
    if t <= delta_t {
        return None;
    }
    Some(TriHit {
        t,
        b: [u * inv, vv * inv, w * inv],
    })
}

/// Barycentric weights of the point where the line `o + t·d` meets the
/// triangle's plane, in `f64` (Möller–Trumbore without range tests).
///
/// Both backends derive the weights they shade with this accurately: the
/// rasterizer by perspective-correct interpolation in `f64`, the ray tracer
/// by this function on the hit triangle, so the two agree to ~1e-12.
#[must_use]
pub fn plane_barycentrics(
    o: glam::DVec3,
    d: glam::DVec3,
    v: [glam::DVec3; 3],
) -> Option<([f64; 3], f64)> {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let tv = o - v[0];
    let b1 = tv.dot(p) * inv;
    let q = tv.cross(e1);
    let b2 = d.dot(q) * inv;
    let t = e2.dot(q) * inv;
    Some(([1.0 - b1 - b2, b1, b2], t))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: Vec3, d: Vec3) -> Ray {
        Ray {
            origin: o,
            dir: d.normalize(),
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    #[test]
    fn hits_inside_misses_outside() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let r = ray(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z);
        let h = intersect(&RayPrecomp::new(&r), &tri, 0.0, f32::INFINITY).unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!((h.b[1] - 0.25).abs() < 1e-6 && (h.b[2] - 0.25).abs() < 1e-6);
        let r = ray(Vec3::new(0.75, 0.75, 1.0), -Vec3::Z);
        assert!(intersect(&RayPrecomp::new(&r), &tri, 0.0, f32::INFINITY).is_none());
        // Behind the origin: no hit.
        let r = ray(Vec3::new(0.25, 0.25, 1.0), Vec3::Z);
        assert!(intersect(&RayPrecomp::new(&r), &tri, 0.0, f32::INFINITY).is_none());
    }

    #[test]
    fn shared_edge_is_never_missed() {
        // Two triangles sharing the diagonal of a square; rays through
        // points on the diagonal must hit at least one of them.
        let t1 = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
        ];
        let t2 = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        for k in 0..1000 {
            let s = (k as f32 + 0.5) / 1000.0;
            let r = ray(Vec3::new(s, s, 3.0), Vec3::new(0.013, -0.007, -1.0));
            // Aim so the ray crosses the plane exactly on the diagonal.
            let target = Vec3::new(s, s, 0.0);
            let r = ray(r.origin, target - r.origin);
            let pre = RayPrecomp::new(&r);
            let hit = intersect(&pre, &t1, 0.0, f32::INFINITY).is_some()
                || intersect(&pre, &t2, 0.0, f32::INFINITY).is_some();
            assert!(hit, "ray {k} slipped through the shared edge");
        }
    }

    #[test]
    fn plane_barycentrics_match() {
        use glam::DVec3;
        let v = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let (b, t) = plane_barycentrics(DVec3::new(0.2, 0.3, 2.0), -DVec3::Z, v).unwrap();
        assert!(
            (b[0] - 0.5).abs() < 1e-15 && (b[1] - 0.2).abs() < 1e-15 && (b[2] - 0.3).abs() < 1e-15
        );
        assert!((t - 2.0).abs() < 1e-15);
    }
}
