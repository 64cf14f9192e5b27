//! Analytic shapes in their own space, and the inverse-affine ray
//! transform that puts them under any transform.
//!
//! A ray `o + t·d` in world space is mapped into the object's space by the
//! inverse of the object's affine transform: `o' + t·d'` with `o' = M⁻¹o`
//! and `d' = M⁻¹d` (not renormalised, so `t` is the same parameter in both
//! spaces). The shape is intersected untransformed there, and its normal
//! is mapped back by the inverse transpose of `M`'s linear part.
//!
//! * **Sphere**: the cancellation-free quadratic of [`sphere`].
//! * **Box**: the slab test.
//! * **Superellipsoid** `<e, n>` (POVRAY.md §9.5), `F(p) = (|x|^(2/e) +
//!   |y|^(2/e))^(e/n) + |z|^(2/n) − 1` in `[−1, 1]³`: roots bracketed by
//!   interval arithmetic. Along the ray each coordinate is linear in `t`,
//!   so on an interval of `t` its magnitude is bounded by the ends (or 0
//!   where it changes sign), and every power in `F` is increasing: the
//!   bounds of `F` over the interval follow exactly. An interval whose
//!   bounds exclude 0 holds no root and is dropped; the others are halved
//!   (nearest half first) down to a width of 1e-9 of the ray's span in the
//!   box, where a sign change is refined by bisection. No root is skipped
//!   however thin the shape is where the ray meets it (down to that
//!   width), which sampling `F` at fixed steps cannot promise.

pub mod sphere;

use glam::{DMat3, DMat4, DVec3};

use sphere::sphere_roots;

/// A shape in its own space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnalyticKind {
    /// A sphere.
    Sphere {
        /// Centre.
        center: DVec3,
        /// Radius.
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Lower corner.
        min: DVec3,
        /// Upper corner.
        max: DVec3,
    },
    /// POV-Ray's superellipsoid `<e, n>` in `[−1, 1]³` (n along z).
    Superellipsoid {
        /// East-west exponent.
        e: f64,
        /// North-south exponent.
        n: f64,
    },
}

impl AnalyticKind {
    /// The bounds in the shape's own space.
    #[must_use]
    pub fn local_bounds(&self) -> (DVec3, DVec3) {
        match *self {
            AnalyticKind::Sphere { center, radius } => {
                (center - DVec3::splat(radius), center + DVec3::splat(radius))
            }
            AnalyticKind::Box { min, max } => (min, max),
            AnalyticKind::Superellipsoid { .. } => (DVec3::splat(-1.0), DVec3::ONE),
        }
    }

    /// `true` when the point (own space) lies inside.
    #[must_use]
    pub fn contains(&self, p: DVec3) -> bool {
        match *self {
            AnalyticKind::Sphere { center, radius } => (p - center).length() < radius,
            AnalyticKind::Box { min, max } => p.cmpgt(min).all() && p.cmplt(max).all(),
            AnalyticKind::Superellipsoid { e, n } => {
                p.abs().max_element() < 1.0 && se_value(p, e, n) < 0.0
            }
        }
    }

    /// The outward unit normal at a point on the surface (own space).
    #[must_use]
    pub fn normal(&self, p: DVec3) -> DVec3 {
        match *self {
            AnalyticKind::Sphere { center, .. } => (p - center).normalize_or_zero(),
            AnalyticKind::Box { min, max } => {
                // The face the point is nearest, relative to the box's size.
                let size = (max - min).max(DVec3::splat(f64::MIN_POSITIVE));
                let lo = (p - min) / size;
                let hi = (max - p) / size;
                let mut best = (f64::INFINITY, DVec3::ZERO);
                for (axis, unit) in [DVec3::X, DVec3::Y, DVec3::Z].into_iter().enumerate() {
                    if lo[axis] < best.0 {
                        best = (lo[axis], -unit);
                    }
                    if hi[axis] < best.0 {
                        best = (hi[axis], unit);
                    }
                }
                best.1
            }
            AnalyticKind::Superellipsoid { e, n } => se_normal(p, e, n),
        }
    }

    /// Every crossing of `o + t·d` (own space) with the surface for `t` in
    /// `(t_min, t_max]`, in increasing order, appended to `out`.
    pub fn crossings(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64, out: &mut Vec<f64>) {
        match *self {
            AnalyticKind::Sphere { center, radius } => {
                let len = d.length();
                if len == 0.0 || !len.is_finite() {
                    return;
                }
                if let Some((t0, t1)) = sphere_roots(o, d / len, center, radius) {
                    for t in [t0 / len, t1 / len] {
                        if t > t_min && t <= t_max {
                            out.push(t);
                        }
                    }
                }
            }
            AnalyticKind::Box { min, max } => {
                if let Some((t0, t1)) = slabs(o, d, min, max) {
                    for t in [t0, t1] {
                        if t > t_min && t <= t_max {
                            out.push(t);
                        }
                    }
                }
            }
            AnalyticKind::Superellipsoid { e, n } => {
                let Some((a0, b0)) = slabs(o, d, DVec3::splat(-1.0), DVec3::ONE) else {
                    return;
                };
                let (mut a, b) = (a0.max(t_min), b0.min(t_max));
                let width = (b - a) * 1e-9;
                let start = out.len();
                // The surface lies inside its box and touches the box's
                // faces; with small exponents it is flat there to the
                // last bits (F = −1e-15 on a face, e = 0.1), so where the
                // ray meets the box on such a flat the box's own plane is
                // the crossing.
                let on_flat = |t: f64| se_value(o + d * t, e, n) <= 0.0;
                if a == a0 && a > t_min && a <= t_max && on_flat(a) {
                    out.push(a);
                    a += width.max(a.abs() * 1e-12);
                }
                while a < b {
                    match se_first_root(o, d, e, n, a, b, width) {
                        Some(t) => {
                            if t > t_min {
                                out.push(t);
                            }
                            // Continue past this root.
                            a = t + width.max(t.abs() * 1e-12);
                        }
                        None => break,
                    }
                }
                if b == b0 && b > t_min && on_flat(b) && (out.len() - start) % 2 == 1 {
                    out.push(b);
                }
            }
        }
    }

    /// The nearest crossing in `(t_min, t_max]`.
    #[must_use]
    pub fn first(&self, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<f64> {
        match *self {
            AnalyticKind::Superellipsoid { e, n } => {
                let (a0, b0) = slabs(o, d, DVec3::splat(-1.0), DVec3::ONE)?;
                let (a, b) = (a0.max(t_min), b0.min(t_max));
                if a >= b {
                    return None;
                }
                // Entering through a flat of the surface that coincides
                // with the box face (see `crossings`).
                if a == a0 && a > t_min && se_value(o + d * a, e, n) <= 0.0 {
                    return Some(a);
                }
                se_first_root(o, d, e, n, a, b, (b - a) * 1e-9).filter(|&t| t > t_min)
            }
            _ => {
                let mut v = Vec::with_capacity(2);
                self.crossings(o, d, t_min, t_max, &mut v);
                v.first().copied()
            }
        }
    }
}

/// An analytic object: its shape, its transform and what it is made of.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placed {
    /// The shape in its own space.
    pub kind: AnalyticKind,
    /// Own space → world.
    pub to_world: DMat4,
    /// World → own space.
    pub to_object: DMat4,
    /// Normals own space → world (inverse transpose of the linear part).
    pub normal_matrix: DMat3,
}

impl Placed {
    /// Places a shape by an affine transform.
    #[must_use]
    pub fn new(kind: AnalyticKind, to_world: DMat4, normal_matrix: DMat3) -> Placed {
        Placed {
            kind,
            to_world,
            to_object: to_world.inverse(),
            normal_matrix,
        }
    }

    /// World bounds: the transformed corners of the local bounds, enlarged
    /// by a relative 1e-9 (conservative for the slab prefilter).
    #[must_use]
    pub fn world_bounds(&self) -> (DVec3, DVec3) {
        let (lo, hi) = self.kind.local_bounds();
        let mut wlo = DVec3::splat(f64::INFINITY);
        let mut whi = DVec3::splat(f64::NEG_INFINITY);
        for k in 0..8 {
            let c = DVec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            let w = self.to_world.transform_point3(c);
            wlo = wlo.min(w);
            whi = whi.max(w);
        }
        let pad = (whi - wlo).max_element() * 1e-9 + 1e-12;
        (wlo - DVec3::splat(pad), whi + DVec3::splat(pad))
    }

    /// The ray in the shape's own space (same parameter `t`).
    #[must_use]
    pub fn to_local(&self, o: DVec3, d: DVec3) -> (DVec3, DVec3) {
        (
            self.to_object.transform_point3(o),
            self.to_object.transform_vector3(d),
        )
    }

    /// The world unit normal at world point `p` on the surface.
    #[must_use]
    pub fn world_normal(&self, p: DVec3) -> DVec3 {
        let local = self.to_object.transform_point3(p);
        (self.normal_matrix * self.kind.normal(local)).normalize_or_zero()
    }
}

/// The parameter interval where `o + t·d` is inside the box, if any
/// (finite ends only).
fn slabs(o: DVec3, d: DVec3, min: DVec3, max: DVec3) -> Option<(f64, f64)> {
    let (t0, t1) = slab_interval(o, d, min, max)?;
    (t0 <= t1 && t1.is_finite() && t0.is_finite()).then_some((t0, t1))
}

/// The slab test: the interval `(t0, t1)` of `o + t·d` between the box's
/// planes (empty when `t0 > t1`; unbounded ends stay infinite), or `None`
/// when the ray runs parallel to a slab outside it.
#[must_use]
pub fn slab_interval(o: DVec3, d: DVec3, min: DVec3, max: DVec3) -> Option<(f64, f64)> {
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    for axis in 0..3 {
        if d[axis] == 0.0 {
            if o[axis] < min[axis] || o[axis] > max[axis] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[axis];
        let (a, b) = ((min[axis] - o[axis]) * inv, (max[axis] - o[axis]) * inv);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    Some((t0, t1))
}

/// The superellipsoid's implicit function, POV-Ray's form with poles on
/// ±z: `F(p) = (|x|^(2/e) + |y|^(2/e))^(e/n) + |z|^(2/n)`, 1 on the
/// surface, below 1 inside; homogeneous of degree 2/n. The one definition
/// the tessellator (points along directions) and the analytic ray test
/// (roots along rays) both use.
#[must_use]
pub fn superellipsoid_f(p: DVec3, e: f64, n: f64) -> f64 {
    let a = p.x.abs().powf(2.0 / e) + p.y.abs().powf(2.0 / e);
    a.powf(e / n) + p.z.abs().powf(2.0 / n)
}

/// The gradient of [`superellipsoid_f`] divided by 2/n, as computed: a
/// component is infinite or NaN where a power with a negative exponent
/// meets a zero coordinate (the axes of a shape with e or n > 2: cusps).
/// Its callers handle those points as their use needs: the ray tracer
/// falls back to central differences (a hit needs a normal), the
/// tessellator zeroes the components of zero coordinates and gives a cusp
/// no normal (the mesh's face normals stand in).
#[must_use]
pub fn superellipsoid_gradient(p: DVec3, e: f64, n: f64) -> DVec3 {
    let a = p.x.abs().powf(2.0 / e) + p.y.abs().powf(2.0 / e);
    let k = a.powf(e / n - 1.0);
    DVec3::new(
        k * p.x.abs().powf(2.0 / e - 1.0) * p.x.signum(),
        k * p.y.abs().powf(2.0 / e - 1.0) * p.y.signum(),
        p.z.abs().powf(2.0 / n - 1.0) * p.z.signum(),
    )
}

/// `F(p) − 1`: negative inside, 0 on the surface.
#[must_use]
pub fn se_value(p: DVec3, e: f64, n: f64) -> f64 {
    superellipsoid_f(p, e, n) - 1.0
}

/// Bounds of `F` over `t ∈ [a, b]` along `o + t·d` (exact for this `F`:
/// each `|coordinate|` is bounded by its ends, or 0 where it changes sign,
/// and every power is increasing).
fn se_range(o: DVec3, d: DVec3, e: f64, n: f64, a: f64, b: f64) -> (f64, f64) {
    let pa = o + d * a;
    let pb = o + d * b;
    let range = |u: f64, v: f64| {
        let (lo, hi) = (u.abs().min(v.abs()), u.abs().max(v.abs()));
        if (u < 0.0) != (v < 0.0) {
            (0.0, hi)
        } else {
            (lo, hi)
        }
    };
    let (xl, xh) = range(pa.x, pb.x);
    let (yl, yh) = range(pa.y, pb.y);
    let (zl, zh) = range(pa.z, pb.z);
    let (pe, pn, en) = (2.0 / e, 2.0 / n, e / n);
    let lo = (xl.powf(pe) + yl.powf(pe)).powf(en) + zl.powf(pn) - 1.0;
    let hi = (xh.powf(pe) + yh.powf(pe)).powf(en) + zh.powf(pn) - 1.0;
    (lo, hi)
}

/// The first root of `F` along `o + t·d` in `[a, b]`, intervals narrower
/// than `width` refined by bisection on a sign change.
fn se_first_root(o: DVec3, d: DVec3, e: f64, n: f64, a: f64, b: f64, width: f64) -> Option<f64> {
    let f = |t: f64| se_value(o + d * t, e, n);
    let mut stack: Vec<(f64, f64)> = Vec::with_capacity(64);
    stack.push((a, b));
    while let Some((lo, hi)) = stack.pop() {
        let (fl, fh) = se_range(o, d, e, n, lo, hi);
        if fl > 0.0 || fh < 0.0 || fl.is_nan() || fh.is_nan() {
            continue;
        }
        if hi - lo <= width {
            let (mut l, mut h) = (lo, hi);
            let (fa, fb) = (f(l), f(h));
            if fa == 0.0 {
                return Some(l);
            }
            if fa.signum() == fb.signum() {
                // No sign change in so narrow an interval: a tangency.
                continue;
            }
            for _ in 0..64 {
                let m = 0.5 * (l + h);
                if m <= l || m >= h {
                    break;
                }
                if f(m).signum() == fa.signum() {
                    l = m;
                } else {
                    h = m;
                }
            }
            return Some(0.5 * (l + h));
        }
        let m = 0.5 * (lo + hi);
        // The nearer half is searched first.
        stack.push((m, hi));
        stack.push((lo, m));
    }
    None
}

/// The outward unit normal of the superellipsoid at `p`: its analytic
/// gradient, or central differences where a power with a negative
/// exponent makes it infinite (on the axes of a shape with e or n > 2).
fn se_normal(p: DVec3, e: f64, n: f64) -> DVec3 {
    let grad = superellipsoid_gradient(p, e, n);
    if grad.is_finite() && grad != DVec3::ZERO {
        return grad.normalize();
    }
    let h = 1e-7;
    let num = DVec3::new(
        se_value(p + DVec3::X * h, e, n) - se_value(p - DVec3::X * h, e, n),
        se_value(p + DVec3::Y * h, e, n) - se_value(p - DVec3::Y * h, e, n),
        se_value(p + DVec3::Z * h, e, n) - se_value(p - DVec3::Z * h, e, n),
    );
    num.try_normalize().unwrap_or(p.normalize_or_zero())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_unit_superellipsoid_is_the_unit_sphere() {
        let kind = AnalyticKind::Superellipsoid { e: 1.0, n: 1.0 };
        let o = DVec3::new(0.3, 0.2, -5.0);
        let t = kind.first(o, DVec3::Z, 0.0, f64::INFINITY).unwrap();
        let (ts, _) = sphere_roots(o, DVec3::Z, DVec3::ZERO, 1.0).unwrap();
        assert!((t - ts).abs() < 1e-12, "{t} vs {ts}");
        let p = o + DVec3::Z * t;
        assert!((kind.normal(p) - p.normalize()).length() < 1e-9);
    }

    #[test]
    fn grazing_hits_are_not_missed() {
        // A ray passing 1e-10 inside the rim of the unit superellipsoid
        // <1, 1> (the unit sphere): the chord is 2.8e-5 long in a span of
        // 2 through the box, so sampling F at a thousand steps would miss
        // it; the interval search finds both crossings.
        let kind = AnalyticKind::Superellipsoid { e: 1.0, n: 1.0 };
        let o = DVec3::new(-5.0, 1.0 - 1e-10, 0.0);
        let mut roots = Vec::new();
        kind.crossings(o, DVec3::X, 0.0, f64::INFINITY, &mut roots);
        let (t0, t1) = sphere_roots(o, DVec3::X, DVec3::ZERO, 1.0).unwrap();
        assert_eq!(roots.len(), 2, "{roots:?}");
        assert!(
            (roots[0] - t0).abs() < 1e-7 && (roots[1] - t1).abs() < 1e-7,
            "{roots:?} vs {t0}, {t1}"
        );
        // Just outside the rim: no crossing.
        roots.clear();
        kind.crossings(
            DVec3::new(-5.0, 1.0 + 1e-10, 0.0),
            DVec3::X,
            0.0,
            f64::INFINITY,
            &mut roots,
        );
        assert!(roots.is_empty(), "{roots:?}");
    }

    #[test]
    fn the_inverse_affine_transform_keeps_the_ray_parameter() {
        // A unit sphere scaled by (2, 1, 0.5) and moved: the world hit of a
        // ray along x through its centre lies at x = centre − 2.
        let m = DMat4::from_translation(DVec3::new(1.0, 2.0, 3.0))
            * DMat4::from_scale(DVec3::new(2.0, 1.0, 0.5));
        let normal = DMat3::from_mat4(m).inverse().transpose();
        let placed = Placed::new(
            AnalyticKind::Sphere {
                center: DVec3::ZERO,
                radius: 1.0,
            },
            m,
            normal,
        );
        let o = DVec3::new(-10.0, 2.0, 3.0);
        let (lo, ld) = placed.to_local(o, DVec3::X);
        let t = placed.kind.first(lo, ld, 0.0, f64::INFINITY).unwrap();
        assert!((o.x + t - (1.0 - 2.0)).abs() < 1e-12, "{t}");
        let n = placed.world_normal(o + DVec3::X * t);
        assert!((n - -DVec3::X).length() < 1e-12, "{n}");
    }

    #[test]
    fn boxes_give_entry_and_exit() {
        let kind = AnalyticKind::Box {
            min: DVec3::splat(-1.0),
            max: DVec3::ONE,
        };
        let mut v = Vec::new();
        kind.crossings(
            DVec3::new(0.2, 0.3, -4.0),
            DVec3::Z,
            0.0,
            f64::INFINITY,
            &mut v,
        );
        assert_eq!(v, vec![3.0, 5.0]);
        assert_eq!(kind.normal(DVec3::new(0.2, 0.3, -1.0)), -DVec3::Z);
    }
}
