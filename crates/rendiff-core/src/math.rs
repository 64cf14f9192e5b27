//! Small geometric types shared by every layer: rays, boxes, barycentric
//! weights, affine transforms and floating-point error bounds.
//!
//! Geometry that reaches the renderers is `f32` (glam `Vec3`); anything
//! that builds it (scene transforms, the camera, the verdict's oracle) works
//! in `f64` and rounds once at the end, so the two backends receive bit-identical
//! inputs.

pub use glam::{DMat3, DMat4, DVec2, DVec3, Vec2, Vec3};

/// Machine epsilon of `f32` in the sense of Higham / pbrt: half an ulp of 1.
pub const F32_EPS: f32 = f32::EPSILON * 0.5;

/// Higham's γ(n) = nε/(1 − nε) for `f32`: a bound on the relative error of
/// `n` chained floating-point operations (pbrt-v4 `gamma`).
#[must_use]
pub const fn gamma(n: u32) -> f32 {
    #[expect(clippy::cast_precision_loss, reason = "n is a small operation count")]
    let ne = n as f32 * F32_EPS;
    ne / (1.0 - ne)
}

/// `f64` version of [`gamma`].
#[must_use]
pub const fn gamma64(n: u32) -> f64 {
    let ne = n as f64 * (f64::EPSILON * 0.5);
    ne / (1.0 - ne)
}

/// A ray: `origin + t * dir` for `t` in `[t_min, t_max]`.
///
/// `dir` has unit length for primary, shadow and secondary rays, so `t` is a
/// distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Direction (unit length).
    pub dir: Vec3,
    /// Smallest accepted parameter.
    pub t_min: f32,
    /// Largest accepted parameter.
    pub t_max: f32,
}

impl Ray {
    /// The point at parameter `t`.
    #[must_use]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// A ray in `f64`: `origin + t·dir` for `t` in `[t_min, t_max]`.
///
/// The ray queries (`accel`) decide every hit on this ray; the `f32`
/// [`Ray`] nearest to it walks the BVH, with boxes inflated by the
/// distance between the two rays, so nothing the `f64` ray meets is
/// missed. A primary ray is the camera's `f64` ray (the very ray the
/// rasterizer's projection and the verdict's oracle use); a shadow ray to
/// a point light ends at the light itself; a reflected or refracted ray,
/// which starts from an `f32` point with an `f32` direction, is that `f32`
/// ray widened exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray64 {
    /// Origin.
    pub origin: DVec3,
    /// Direction (unit length, up to `f64` rounding).
    pub dir: DVec3,
    /// Smallest accepted parameter.
    pub t_min: f64,
    /// Largest accepted parameter.
    pub t_max: f64,
}

impl From<&Ray> for Ray64 {
    fn from(r: &Ray) -> Ray64 {
        Ray64 {
            origin: to_f64(r.origin),
            dir: to_f64(r.dir),
            t_min: f64::from(r.t_min),
            t_max: f64::from(r.t_max),
        }
    }
}

impl Ray64 {
    /// The `f32` ray nearest to this one: each part rounded once (so the
    /// `f32` primary ray of a camera is its `f64` ray's rounding).
    #[must_use]
    pub fn to_f32(&self) -> Ray {
        #[expect(clippy::cast_possible_truncation, reason = "the one rounding to f32")]
        Ray {
            origin: to_f32(self.origin),
            dir: to_f32(self.dir),
            t_min: self.t_min as f32,
            t_max: self.t_max as f32,
        }
    }

    /// The point at parameter `t`.
    #[must_use]
    pub fn at(&self, t: f64) -> DVec3 {
        self.origin + self.dir * t
    }
}

/// Axis-aligned bounding box. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box (the identity of [`Aabb::union`]).
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The box spanned by two corners.
    #[must_use]
    pub fn from_min_max(min: Vec3, max: Vec3) -> Aabb {
        Aabb { min, max }
    }

    /// The smallest box containing every point.
    #[must_use]
    pub fn from_points<I: IntoIterator<Item = Vec3>>(points: I) -> Aabb {
        points.into_iter().fold(Aabb::EMPTY, Aabb::grow)
    }

    /// This box grown to contain `p`.
    #[must_use]
    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box containing both boxes.
    #[must_use]
    pub fn union(self, other: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// `true` when the box contains no point.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Edge lengths (zero for an empty box).
    #[must_use]
    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            self.max - self.min
        }
    }

    /// Centre point.
    #[must_use]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Half the surface area (the SAH only needs ratios).
    #[must_use]
    pub fn half_area(&self) -> f32 {
        let e = self.extent();
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    /// The eight corners.
    #[must_use]
    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }

    /// Bounding sphere (centre, radius) of the box.
    #[must_use]
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        (self.center(), self.extent().length() * 0.5)
    }

    /// `true` when `p` lies inside or on the box.
    #[must_use]
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }
}

/// Barycentric weights `[b0, b1, b2]` of the vertices `v0, v1, v2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bary(pub [f32; 3]);

impl Bary {
    /// Weights from `f64` values (any scale: they are divided by their
    /// sum), rounded once to `f32`. Every backend turns its `f64` weights
    /// into the `f32` weights it shades with by this one function.
    #[must_use]
    #[expect(
        clippy::cast_possible_truncation,
        reason = "deliberate rounding of the f64 weights to the f32 used for shading"
    )]
    pub fn from_f64(b: [f64; 3]) -> Bary {
        let s = b[0] + b[1] + b[2];
        let n = if s != 0.0 && s.is_finite() {
            [b[0] / s, b[1] / s, b[2] / s]
        } else {
            b
        };
        Bary([n[0] as f32, n[1] as f32, n[2] as f32])
    }

    /// `w0·a + w1·b + w2·c`.
    #[must_use]
    pub fn interpolate(&self, v: [Vec3; 3]) -> Vec3 {
        v[0] * self.0[0] + v[1] * self.0[1] + v[2] * self.0[2]
    }

    /// `w0·a + w1·b + w2·c` for 2-vectors.
    #[must_use]
    pub fn interpolate2(&self, v: [Vec2; 3]) -> Vec2 {
        v[0] * self.0[0] + v[1] * self.0[1] + v[2] * self.0[2]
    }
}

/// Barycentric weights of the point where the line `o + t·d` meets the
/// triangle's plane, and that `t`, in `f64` (Möller–Trumbore without range
/// tests); `None` when the line is parallel to the plane.
///
/// The verdict's oracle evaluates triangles with it, and both backends
/// take the weights they shade a camera-ray hit with from it
/// (`TriScene::view_weights`), so the weights agree bit for bit.
#[must_use]
#[inline]
pub fn plane_barycentrics(o: DVec3, d: DVec3, v: [DVec3; 3]) -> Option<([f64; 3], f64)> {
    PlaneFromOrigin::new(o, v).at(d)
}

/// The part of [`plane_barycentrics`] that depends on the triangle and the
/// line's origin alone (`e₁ = v₁ − v₀`, `e₂ = v₂ − v₀`, `o − v₀` and
/// `(o − v₀) × e₁`), so that lines from one origin (a perspective camera's
/// rays) can share it; [`PlaneFromOrigin::at`] is the rest, the same
/// operations on the same values either way.
#[derive(Clone, Copy, Debug)]
pub struct PlaneFromOrigin {
    e1: DVec3,
    e2: DVec3,
    tv: DVec3,
    q: DVec3,
}

impl PlaneFromOrigin {
    /// The origin-only part for origin `o` and triangle `v`.
    #[must_use]
    #[inline]
    pub fn new(o: DVec3, v: [DVec3; 3]) -> PlaneFromOrigin {
        let e1 = v[1] - v[0];
        let tv = o - v[0];
        PlaneFromOrigin {
            e1,
            e2: v[2] - v[0],
            tv,
            q: tv.cross(e1),
        }
    }

    /// [`plane_barycentrics`] of the line from this origin along `d`.
    #[must_use]
    #[inline]
    pub fn at(&self, d: DVec3) -> Option<([f64; 3], f64)> {
        let p = d.cross(self.e2);
        let det = self.e1.dot(p);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let b1 = self.tv.dot(p) * inv;
        let b2 = d.dot(self.q) * inv;
        let t = self.e2.dot(self.q) * inv;
        Some(([1.0 - b1 - b2, b1, b2], t))
    }
}

/// An affine transform of an object: `p_world = m · p_object`.
///
/// # Guarantees
///
/// The linear part is invertible (|det| > 0 and finite), so
/// [`Transform::normal_matrix`] exists.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    m: DMat4,
    normal: DMat3,
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

/// One entry of a scene's transform list.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TransformStep {
    /// Scale by the factors along x, y and z.
    Scale(DVec3),
    /// Rotate by the angles in degrees about x, then y, then z (right-hand rule).
    Rotate(DVec3),
    /// Translate by the vector.
    Translate(DVec3),
}

impl TransformStep {
    /// The step as a matrix.
    #[must_use]
    pub fn matrix(&self) -> DMat4 {
        match *self {
            TransformStep::Scale(s) => DMat4::from_scale(s),
            TransformStep::Rotate(deg) => {
                let rx = DMat4::from_rotation_x(deg.x.to_radians());
                let ry = DMat4::from_rotation_y(deg.y.to_radians());
                let rz = DMat4::from_rotation_z(deg.z.to_radians());
                rz * ry * rx
            }
            TransformStep::Translate(t) => DMat4::from_translation(t),
        }
    }
}

impl Transform {
    /// The identity.
    pub const IDENTITY: Transform = Transform {
        m: DMat4::IDENTITY,
        normal: DMat3::IDENTITY,
    };

    /// The composition of the steps, first entry applied first; `None` if
    /// the result is singular or not finite.
    #[must_use]
    pub fn from_steps(steps: &[TransformStep]) -> Option<Transform> {
        let m = steps
            .iter()
            .fold(DMat4::IDENTITY, |acc, s| s.matrix() * acc);
        Transform::from_matrix(m)
    }

    /// A transform from an affine matrix; `None` if singular or not finite.
    #[must_use]
    pub fn from_matrix(m: DMat4) -> Option<Transform> {
        let lin = DMat3::from_mat4(m);
        let det = lin.determinant();
        if !det.is_finite() || det == 0.0 || !m.is_finite() {
            return None;
        }
        // Singular relative to the largest axis: a transform that squashes
        // one axis by 1e-12 of another is singular for f32 geometry.
        let largest = lin
            .x_axis
            .length()
            .max(lin.y_axis.length())
            .max(lin.z_axis.length());
        if det.abs() <= 1e-12 * largest * largest * largest {
            return None;
        }
        Some(Transform {
            m,
            normal: lin.inverse().transpose(),
        })
    }

    /// The affine matrix.
    #[must_use]
    pub fn matrix(&self) -> DMat4 {
        self.m
    }

    /// The inverse transpose of the linear part (maps normals).
    #[must_use]
    pub fn normal_matrix(&self) -> DMat3 {
        self.normal
    }

    /// Transforms a point.
    #[must_use]
    pub fn point(&self, p: DVec3) -> DVec3 {
        self.m.transform_point3(p)
    }

    /// Transforms a direction (no translation).
    #[must_use]
    pub fn vector(&self, v: DVec3) -> DVec3 {
        self.m.transform_vector3(v)
    }

    /// Transforms a normal by the inverse transpose (not normalised).
    #[must_use]
    pub fn normal(&self, n: DVec3) -> DVec3 {
        self.normal * n
    }

    /// Determinant of the linear part (negative when the transform mirrors).
    #[must_use]
    pub fn determinant(&self) -> f64 {
        DMat3::from_mat4(self.m).determinant()
    }

    /// The uniform scale factor if the linear part is a rotation times a
    /// uniform scale (a similarity), within 1e-9 relative.
    #[must_use]
    pub fn uniform_scale(&self) -> Option<f64> {
        let lin = DMat3::from_mat4(self.m);
        let s = lin.x_axis.length();
        let ortho = lin.transpose() * lin;
        let expect = DMat3::from_diagonal(DVec3::splat(s * s));
        let err = (0..3)
            .map(|c| (ortho.col(c) - expect.col(c)).abs().max_element())
            .fold(0.0, f64::max);
        (err <= 1e-9 * s * s).then_some(s)
    }
}

/// Rounds an `f64` vector to `f32` once.
#[must_use]
#[expect(
    clippy::cast_possible_truncation,
    reason = "the one deliberate f64 -> f32 rounding of geometry"
)]
pub fn to_f32(v: DVec3) -> Vec3 {
    Vec3::new(v.x as f32, v.y as f32, v.z as f32)
}

/// Widens an `f32` vector to `f64` exactly.
#[must_use]
pub fn to_f64(v: Vec3) -> DVec3 {
    DVec3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

/// The smallest `f32` not below `t` (a traversal bound that never cuts off
/// a hit at `t`, an error bound that never falls below the `f64` one).
///
/// Without branches (a ray's bounds and inflation fall either way at
/// random, and a mispredicted branch costs more than the whole test): the
/// rounding `r` and its successor are both formed and one is selected.
/// The successor is one step of the bit pattern away from zero for
/// `r ≥ +0` and toward zero for `r < 0` (`r = −∞` steps to `−f32::MAX`);
/// it is chosen only when `r < t`, so never for `r = +∞`, NaN, or a `−0`
/// (which only a `t ≤ 0` rounds to). Exactly `r.next_up()` where chosen
/// (a unit test holds it to that).
#[must_use]
#[inline(always)]
pub fn f32_at_least(t: f64) -> f32 {
    #[expect(
        clippy::cast_possible_truncation,
        reason = "rounded, then corrected upward"
    )]
    let r = t as f32;
    let bits = r.to_bits();
    let up = f32::from_bits(if r.is_sign_negative() {
        bits.wrapping_sub(1)
    } else {
        bits.wrapping_add(1)
    });
    if f64::from(r) < t { up } else { r }
}

/// The largest `f32` not above `t` (branch-free as [`f32_at_least`]:
/// exactly `r.next_down()` where the rounding `r` lies above `t`).
#[must_use]
#[inline(always)]
pub fn f32_at_most(t: f64) -> f32 {
    #[expect(
        clippy::cast_possible_truncation,
        reason = "rounded, then corrected downward"
    )]
    let r = t as f32;
    let bits = r.to_bits();
    let down = f32::from_bits(if r.is_sign_negative() {
        bits.wrapping_add(1)
    } else {
        bits.wrapping_sub(1)
    });
    if f64::from(r) > t { down } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The branch-free roundings are exactly "round, then step with
    /// `next_up`/`next_down` where the rounding fell on the wrong side",
    /// at the edges of the format (zeros, subnormals, the largest finite,
    /// infinities, NaN) and on values between every pair of neighbours.
    #[test]
    fn directed_roundings_match_next_up_and_next_down() {
        #![allow(
            clippy::cast_possible_truncation,
            clippy::cast_precision_loss,
            clippy::cast_sign_loss,
            clippy::cast_possible_wrap
        )]
        let reference_up = |t: f64| {
            let r = t as f32;
            if f64::from(r) < t { r.next_up() } else { r }
        };
        let reference_down = |t: f64| {
            let r = t as f32;
            if f64::from(r) > t { r.next_down() } else { r }
        };
        let mut values = vec![
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::from(f32::MAX),
            -f64::from(f32::MAX),
            f64::from(f32::MAX) * (1.0 + 1e-9),
            -f64::from(f32::MAX) * (1.0 + 1e-9),
            f64::MAX,
            -f64::MAX,
            1e-300,
            -1e-300,
            f64::from(f32::MIN_POSITIVE),
            f64::from(f32::from_bits(1)),
            f64::from(f32::from_bits(1)) * 0.5,
            f64::from(f32::from_bits(1)) * 0.25,
            -f64::from(f32::from_bits(1)) * 0.25,
        ];
        let mut z = 0x1234_5678_9abc_def0u64;
        for _ in 0..20_000 {
            z = z
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let f = f32::from_bits((z >> 32) as u32);
            if f.is_finite() {
                let next = f.next_up();
                values.extend([f64::from(f), (f64::from(f) + f64::from(next)) / 2.0]);
                values.push(f64::from(f) + (f64::from(next) - f64::from(f)) * 1e-3);
            }
        }
        for t in values {
            let (up, down) = (f32_at_least(t), f32_at_most(t));
            assert_eq!(up.to_bits(), reference_up(t).to_bits(), "at least {t:e}");
            assert_eq!(down.to_bits(), reference_down(t).to_bits(), "at most {t:e}");
            if !t.is_nan() {
                assert!(f64::from(up) >= t && f64::from(down) <= t, "{t:e}");
            }
        }
    }

    #[test]
    fn transform_order_is_first_entry_first() {
        let t = Transform::from_steps(&[
            TransformStep::Scale(DVec3::splat(2.0)),
            TransformStep::Translate(DVec3::new(1.0, 0.0, 0.0)),
        ])
        .unwrap();
        // Scale first, then translate: (1,0,0) -> (2,0,0) -> (3,0,0).
        assert_eq!(t.point(DVec3::X), DVec3::new(3.0, 0.0, 0.0));
    }

    #[test]
    fn rotate_is_x_then_y_then_z_right_handed() {
        let t =
            Transform::from_steps(&[TransformStep::Rotate(DVec3::new(0.0, 0.0, 90.0))]).unwrap();
        // Right-hand rule about +z takes +x to +y.
        let p = t.point(DVec3::X);
        assert!((p - DVec3::Y).length() < 1e-12, "{p}");
        let t =
            Transform::from_steps(&[TransformStep::Rotate(DVec3::new(90.0, 90.0, 0.0))]).unwrap();
        // x first: +y -> +z; then y: +z -> +x.
        let p = t.point(DVec3::Y);
        assert!((p - DVec3::X).length() < 1e-12, "{p}");
    }

    #[test]
    fn singular_transform_is_rejected() {
        assert!(
            Transform::from_steps(&[TransformStep::Scale(DVec3::new(1.0, 0.0, 1.0))]).is_none()
        );
        assert!(
            Transform::from_steps(&[TransformStep::Scale(DVec3::new(1e-300, 1.0, 1.0))]).is_none()
        );
    }

    #[test]
    fn normals_use_the_inverse_transpose() {
        let t = Transform::from_steps(&[TransformStep::Scale(DVec3::new(2.0, 1.0, 1.0))]).unwrap();
        // The plane x + y = 0 has normal (1,1,0); after scaling x by 2 the
        // plane is x/2 + y = 0 with normal (1/2, 1, 0).
        let n = t.normal(DVec3::new(1.0, 1.0, 0.0));
        assert!((n - DVec3::new(0.5, 1.0, 0.0)).length() < 1e-12);
        assert!(t.uniform_scale().is_none());
        let s = Transform::from_steps(&[
            TransformStep::Rotate(DVec3::new(10.0, 20.0, 30.0)),
            TransformStep::Scale(DVec3::splat(3.0)),
        ])
        .unwrap();
        assert!((s.uniform_scale().unwrap() - 3.0).abs() < 1e-12);
    }
}
