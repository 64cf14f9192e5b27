//! The camera of DESIGN.md §2: primary rays, the projection that inverts
//! them, the n×n sample points, near and far.
//!
//! Everything here is computed in `f64`; a backend receives the primary ray
//! of a sample as `f32` values rounded once from the same `f64` expression,
//! so the rasterizer (shading) and the ray tracer (casting) see bit-identical
//! rays.
//!
//! **One eye.** The ray tracer casts the `f64` camera rays themselves
//! ([`Camera::primary_ray64`]), the rays the rasterizer projects with and
//! the verdict's oracle evaluates, so both start at the one `f64` eye. (An
//! `f32` ray origin was a second eye, up to half an `f32` step away: at
//! 10⁶ that is 0.03 units, which moved crossing lines by several pixels;
//! rounding the eye onto the `f32` grid instead would move it onto a
//! floor it hovers a millionth above.)
//!
//! Screen coordinates run from (0, 0) at the top-left corner of the image to
//! (width, height); the sample grid has `n·width × n·height` cells and the
//! sample `(sx, sy)` of that grid sits at screen point
//! `((sx + 0.5)/n, (sy + 0.5)/n)`.

use crate::math::{DVec3, Ray, Ray64, Vec3, to_f32};

/// The two projections.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Perspective with `tan(fov_y / 2)`.
    Perspective {
        /// `tan(fov_y / 2)`.
        tan_half_fov: f64,
    },
    /// Orthographic with the height of the view in world units.
    Orthographic {
        /// Height of the view in world units.
        view_height: f64,
    },
}

/// The smallest angle a pixel may span (perspective), and the smallest
/// pixel size relative to the eye's distance from the origin
/// (orthographic): 2⁻³⁰. Below it the `f64` rounding of a camera ray
/// (γ₆₄(64) ≈ 7e-15 of the coordinates involved, over the few dozen
/// operations of the projection, the ray–triangle test and the oracle)
/// would exceed 1/64 px — the widest edge tie — for geometry 2¹⁰ times
/// farther from the eye than the surface it hides, and the verdict could
/// not be trusted; such a view is refused rather than judged.
pub const MIN_PIXEL_ANGLE: f64 = 1.0 / 1_073_741_824.0;

/// What is wrong with a view too narrow for `f64` camera rays
/// ([`MIN_PIXEL_ANGLE`]), as `(key, message)`; `None` when it is fine.
/// `eye` is the eye's largest coordinate in magnitude.
#[must_use]
pub fn resolution_problem(
    projection: Projection,
    eye: f64,
    width: u32,
    height: u32,
) -> Option<(&'static str, String)> {
    let (w, h) = (f64::from(width.max(1)), f64::from(height.max(1)));
    match projection {
        Projection::Perspective { tan_half_fov: t } => {
            // The smallest pixel angle is at the image corners.
            let a = w / h;
            let corner = 1.0 / (1.0 + t * t * (1.0 + a * a));
            let angle = 2.0 * t / h * corner;
            (angle.is_nan() || angle < MIN_PIXEL_ANGLE).then(|| {
                (
                    "fov_y",
                    format!(
                        "a field of view this narrow gives pixels {angle:.3e} rad wide at {width}x{height}, below the {MIN_PIXEL_ANGLE:.3e} rad that f64 camera rays resolve; widen it or render fewer pixels"
                    ),
                )
            })
        }
        Projection::Orthographic { view_height } => {
            let size = view_height / h;
            let reach = eye.abs() + view_height;
            (size.is_nan() || size < MIN_PIXEL_ANGLE * reach).then(|| {
                (
                    "view_height",
                    format!(
                        "a view {view_height:.3e} high at {eye:.3e} from the origin gives pixels {size:.3e} across at {width}x{height}, below the {MIN_PIXEL_ANGLE:.3e} of that distance that f64 camera rays resolve; enlarge it, move the scene nearer the origin or render fewer pixels"
                    ),
                )
            })
        }
    }
}

/// Errors in building a camera.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CameraError {
    /// `eye` equals `look_at`.
    #[error("eye and look_at are the same point")]
    EyeAtTarget,
    /// `up` is parallel to the view direction, zero, or not a number.
    #[error("up is parallel to the view direction (look_at - eye), zero, or not finite")]
    UpParallel,
    /// The eye is not a finite `f32` point.
    #[error("the eye is not a finite point in f32 (coordinates beyond ±3.4e38)")]
    EyeNotFinite,
    /// The image has no pixels.
    #[error("the image is {width}x{height}; each side must be at least 1")]
    EmptyImage {
        /// Pixels across.
        width: u32,
        /// Pixels down.
        height: u32,
    },
    /// Samples per pixel side not one of [`crate::coverage::SAMPLES_PER_SIDE`].
    #[error("{samples} samples per pixel side: expected 1, 2, 4, 8 or 16")]
    Samples {
        /// The samples asked for.
        samples: u32,
    },
    /// `near` and `far` are not `0 < near < far`.
    #[error("near ({near}) and far ({far}) must satisfy 0 < near < far")]
    NearFar {
        /// The near distance.
        near: f64,
        /// The far distance.
        far: f64,
    },
}

/// A validated camera.
///
/// # Guarantees
///
/// `f`, `r`, `u` are orthonormal (right-handed: `r = f × up`, `u = r × f`),
/// the eye is finite, `0 < near < far`, `width, height ≥ 1`,
/// `samples ∈ {1, 2, 4, 8, 16}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    eye: DVec3,
    f: DVec3,
    r: DVec3,
    u: DVec3,
    projection: Projection,
    width: u32,
    height: u32,
    samples: u32,
    near: f64,
    far: f64,
}

impl Camera {
    /// A camera looking from `eye` at `look_at`.
    ///
    /// # Errors
    ///
    /// [`CameraError`] when the frame is degenerate, `near`/`far` are out
    /// of order, the image is empty, or `samples` is not one of
    /// [`crate::coverage::SAMPLES_PER_SIDE`] (the guarantees above, which
    /// both backends rely on).
    #[expect(
        clippy::too_many_arguments,
        reason = "mirrors the [camera] table one to one"
    )]
    pub fn new(
        eye: DVec3,
        look_at: DVec3,
        up: DVec3,
        projection: Projection,
        width: u32,
        height: u32,
        samples: u32,
        near: f64,
        far: f64,
    ) -> Result<Camera, CameraError> {
        if !eye.is_finite() || !to_f32(eye).is_finite() {
            return Err(CameraError::EyeNotFinite);
        }
        let f = (look_at - eye)
            .try_normalize()
            .ok_or(CameraError::EyeAtTarget)?;
        // Scaled to its largest component first: `up = [0, 1e308, 1e308]`
        // is a direction, not an overflow.
        let big = up.abs().max_element();
        let up = if big > 0.0 && big.is_finite() {
            up / big
        } else {
            up
        };
        let r = f.cross(up);
        // up ∦ f: the cross product must not vanish relative to |up| (and
        // be a number: a NaN in `up` fails this too; found by the
        // orthonormality check below on a fuzz input).
        if !(r.length() > 1e-9 * up.length() && up.length() > 0.0) {
            return Err(CameraError::UpParallel);
        }
        // `f × up` is exact up to ε·|f||up| per component: relative to its
        // length s·|up| (s = sin of the angle, at least 1e-9 here) `r` is
        // perpendicular to `f` within about 4ε/s.
        let ortho_tol = 8.0 * f64::EPSILON * up.length() / r.length() + 8.0 * f64::EPSILON;
        let r = r.normalize();
        let u = r.cross(f);
        if !(near > 0.0 && far > near && far.is_finite()) {
            return Err(CameraError::NearFar { near, far });
        }
        if width == 0 || height == 0 {
            return Err(CameraError::EmptyImage { width, height });
        }
        if !crate::coverage::SAMPLES_PER_SIDE.contains(&samples) {
            return Err(CameraError::Samples { samples });
        }
        debug_assert!(
            f.dot(r).abs() <= ortho_tol
                && f.dot(u).abs() <= ortho_tol
                && (u.length() - 1.0).abs() <= ortho_tol,
            "the camera frame is orthonormal within its rounding"
        );
        Ok(Camera {
            eye,
            f,
            r,
            u,
            projection,
            width,
            height,
            samples,
            near,
            far,
        })
    }

    /// The same camera with another `far`.
    ///
    /// # Errors
    ///
    /// [`CameraError::NearFar`] if `far <= near`.
    pub fn with_far(mut self, far: f64) -> Result<Camera, CameraError> {
        if !(far > self.near && far.is_finite()) {
            return Err(CameraError::NearFar {
                near: self.near,
                far,
            });
        }
        self.far = far;
        Ok(self)
    }

    /// Eye position.
    #[must_use]
    pub fn eye(&self) -> DVec3 {
        self.eye
    }
    /// Unit view direction `f`.
    #[must_use]
    pub fn forward(&self) -> DVec3 {
        self.f
    }
    /// Unit right vector `r`.
    #[must_use]
    pub fn right(&self) -> DVec3 {
        self.r
    }
    /// Unit up vector `u` (perpendicular to `f`).
    #[must_use]
    pub fn up(&self) -> DVec3 {
        self.u
    }
    /// The projection.
    #[must_use]
    pub fn projection(&self) -> Projection {
        self.projection
    }
    /// Image width in pixels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Image height in pixels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }
    /// Samples per pixel side `n`.
    #[must_use]
    pub fn samples(&self) -> u32 {
        self.samples
    }
    /// Width of the sample grid, `n·width`.
    #[must_use]
    pub fn sample_width(&self) -> u32 {
        self.width * self.samples
    }
    /// Height of the sample grid, `n·height`.
    #[must_use]
    pub fn sample_height(&self) -> u32 {
        self.height * self.samples
    }
    /// Near distance (view depth).
    #[must_use]
    pub fn near(&self) -> f64 {
        self.near
    }
    /// Far distance (view depth).
    #[must_use]
    pub fn far(&self) -> f64 {
        self.far
    }
    /// `width / height`.
    #[must_use]
    pub fn aspect(&self) -> f64 {
        f64::from(self.width) / f64::from(self.height)
    }

    /// The screen point of sample `(sx, sy)` of the sample grid.
    #[must_use]
    pub fn sample_point(&self, sx: u32, sy: u32) -> (f64, f64) {
        let n = f64::from(self.samples);
        ((f64::from(sx) + 0.5) / n, (f64::from(sy) + 0.5) / n)
    }

    /// Normalised screen coordinates `(sx, sy)` in `[-1, 1]` (y up).
    #[must_use]
    pub fn ndc(&self, x: f64, y: f64) -> (f64, f64) {
        (
            2.0 * x / f64::from(self.width) - 1.0,
            1.0 - 2.0 * y / f64::from(self.height),
        )
    }

    /// Origin and unit direction of the primary ray through screen point
    /// `(x, y)`, in `f64`; the ray starts at the eye (perspective) or on the
    /// plane through the eye (orthographic).
    #[must_use]
    pub fn primary_ray_f64(&self, x: f64, y: f64) -> (DVec3, DVec3) {
        let (sx, sy) = self.ndc(x, y);
        match self.projection {
            Projection::Perspective { tan_half_fov: t } => {
                let d = self.f + self.r * (sx * t * self.aspect()) + self.u * (sy * t);
                (self.eye, d.normalize())
            }
            Projection::Orthographic { view_height: h } => {
                let o =
                    self.eye + self.r * (sx * h * self.aspect() / 2.0) + self.u * (sy * h / 2.0);
                (o, self.f)
            }
        }
    }

    /// Parameter `t` at which the primary ray with direction `dir` crosses
    /// the near plane.
    #[must_use]
    pub fn near_t(&self, dir: DVec3) -> f64 {
        match self.projection {
            Projection::Perspective { .. } => self.near / dir.dot(self.f),
            Projection::Orthographic { .. } => self.near,
        }
    }

    /// Parameter `t` at which the primary ray with direction `dir` crosses
    /// the far plane.
    #[must_use]
    pub fn far_t(&self, dir: DVec3) -> f64 {
        match self.projection {
            Projection::Perspective { .. } => self.far / dir.dot(self.f),
            Projection::Orthographic { .. } => self.far,
        }
    }

    /// The primary ray through screen point `(x, y)` as the `f32` ray every
    /// backend uses: unit direction, from the near plane to the far plane
    /// (DESIGN.md §2: surfaces beyond either are not seen).
    #[must_use]
    pub fn primary_ray(&self, x: f64, y: f64) -> Ray {
        self.primary_ray64(x, y).to_f32()
    }

    /// The primary ray through screen point `(x, y)` as the ray tracer casts
    /// it: the `f64` camera ray itself, from the near plane to the far
    /// plane (the rasterizer projects with the same ray; the `f32` ray of
    /// [`Camera::primary_ray`] is its rounding, for shading).
    #[must_use]
    pub fn primary_ray64(&self, x: f64, y: f64) -> Ray64 {
        let (o, d) = self.primary_ray_f64(x, y);
        Ray64 {
            origin: o,
            dir: d,
            t_min: self.near_t(d),
            t_max: self.far_t(d),
        }
    }

    /// The primary ray of sample `(sx, sy)` of the sample grid.
    #[must_use]
    pub fn sample_ray(&self, sx: u32, sy: u32) -> Ray {
        let (x, y) = self.sample_point(sx, sy);
        self.primary_ray(x, y)
    }

    /// The `f64` primary ray of sample `(sx, sy)` of the sample grid (as the
    /// ray tracer casts it).
    #[must_use]
    pub fn sample_ray64(&self, sx: u32, sy: u32) -> Ray64 {
        let (x, y) = self.sample_point(sx, sy);
        self.primary_ray64(x, y)
    }

    /// View depth `(p − eye)·f`.
    #[must_use]
    pub fn view_depth(&self, p: DVec3) -> f64 {
        (p - self.eye).dot(self.f)
    }

    /// Depth of a visible point as the frame stores it: `t` along the unit
    /// primary ray (perspective: distance from the eye; orthographic: view depth).
    #[must_use]
    pub fn frame_depth(&self, p: DVec3) -> f64 {
        match self.projection {
            Projection::Perspective { .. } => (p - self.eye).length(),
            Projection::Orthographic { .. } => self.view_depth(p),
        }
    }

    /// `p` in view coordinates: `(x, y, z)` along `right`, `up` and
    /// `forward`, relative to the eye. The one world → view transform: the
    /// rasterizer's homogeneous vertices, the painter's depth order, the
    /// plan's frustum test and [`Camera::project`] all start from it, so
    /// they round alike.
    #[must_use]
    pub fn to_view(&self, p: DVec3) -> DVec3 {
        let rel = p - self.eye;
        DVec3::new(rel.dot(self.r), rel.dot(self.u), rel.dot(self.f))
    }

    /// The screen point whose primary ray passes through `p`, and its view
    /// depth; `None` when `p` is not in front of the eye plane (perspective).
    #[must_use]
    pub fn project(&self, p: DVec3) -> Option<(f64, f64, f64)> {
        let DVec3 { x: a, y: b, z } = self.to_view(p);
        let (sx, sy) = match self.projection {
            Projection::Perspective { tan_half_fov: t } => {
                if z <= 0.0 {
                    return None;
                }
                (a / (z * t * self.aspect()), b / (z * t))
            }
            Projection::Orthographic { view_height: h } => {
                (a / (h * self.aspect() / 2.0), b / (h / 2.0))
            }
        };
        let x = (sx + 1.0) * f64::from(self.width) / 2.0;
        let y = (1.0 - sy) * f64::from(self.height) / 2.0;
        Some((x, y, z))
    }

    /// Pixels per world unit of a length perpendicular to the view at view
    /// depth `z`, at its largest over the image (perspective: toward the
    /// image corners the scale grows by `√(1 + t²(1 + aspect²))`).
    ///
    /// This is the conversion of DESIGN.md §4 for tessellation error.
    #[must_use]
    pub fn max_pixels_per_unit(&self, z: f64) -> f64 {
        let h = f64::from(self.height);
        match self.projection {
            Projection::Perspective { tan_half_fov: t } => {
                let a = self.aspect();
                h * (1.0 + t * t * (1.0 + a * a)).sqrt() / (2.0 * t * z.max(self.near))
            }
            Projection::Orthographic { view_height } => h / view_height,
        }
    }

    /// The f32 eye (for shading).
    #[must_use]
    pub fn eye_f32(&self) -> Vec3 {
        to_f32(self.eye)
    }
}

/// The primary rays of a camera's sample grid, with what depends on the
/// column alone and on the row alone computed once per frame.
///
/// [`SampleRays::ray`] is [`Camera::sample_ray64`] bit for bit: the same
/// operations in the same order, the column term (`f + r·(x·t·aspect)`,
/// or the eye's offset across) and the row term (`u·(y·t)`) read from
/// tables instead of being recomputed. What is left per sample is one sum,
/// the normalisation and the near and far distances: the sample point's
/// and the screen's divisions, four on the path of every primary ray, are
/// off it.
#[derive(Clone, Debug)]
pub struct SampleRays {
    cam: Camera,
    /// Per sample column: `f + r·(x·t·aspect)` (perspective) or
    /// `eye + r·(x·h·aspect/2)` (orthographic).
    cols: Vec<DVec3>,
    /// Per sample row: `u·(y·t)` or `u·(y·h/2)`.
    rows: Vec<DVec3>,
}

impl SampleRays {
    /// The tables of `cam`'s sample grid.
    #[must_use]
    pub fn new(cam: &Camera) -> SampleRays {
        let a = cam.aspect();
        let cols = (0..cam.sample_width())
            .map(|sx| {
                let (sx, _) = cam.ndc(cam.sample_point(sx, 0).0, 0.0);
                match cam.projection {
                    Projection::Perspective { tan_half_fov: t } => cam.f + cam.r * (sx * t * a),
                    Projection::Orthographic { view_height: h } => {
                        cam.eye + cam.r * (sx * h * a / 2.0)
                    }
                }
            })
            .collect();
        let rows = (0..cam.sample_height())
            .map(|sy| {
                let (_, sy) = cam.ndc(0.0, cam.sample_point(0, sy).1);
                match cam.projection {
                    Projection::Perspective { tan_half_fov: t } => cam.u * (sy * t),
                    Projection::Orthographic { view_height: h } => cam.u * (sy * h / 2.0),
                }
            })
            .collect();
        SampleRays {
            cam: *cam,
            cols,
            rows,
        }
    }

    /// The camera.
    #[must_use]
    pub fn camera(&self) -> &Camera {
        &self.cam
    }

    /// The `f64` primary ray of sample `(sx, sy)`: [`Camera::sample_ray64`]
    /// (computed directly for a sample outside the grid).
    #[must_use]
    #[inline]
    pub fn ray(&self, sx: u32, sy: u32) -> Ray64 {
        let cam = &self.cam;
        let (Some(&col), Some(&row)) = (self.cols.get(sx as usize), self.rows.get(sy as usize))
        else {
            return cam.sample_ray64(sx, sy);
        };
        match cam.projection {
            Projection::Perspective { .. } => {
                let d = (col + row).normalize();
                Ray64 {
                    origin: cam.eye,
                    dir: d,
                    t_min: cam.near_t(d),
                    t_max: cam.far_t(d),
                }
            }
            Projection::Orthographic { .. } => Ray64 {
                origin: col + row,
                dir: cam.f,
                t_min: cam.near,
                t_max: cam.far,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cam(proj: Projection, eye: DVec3, at: DVec3, up: DVec3) -> Camera {
        Camera::new(eye, at, up, proj, 320, 240, 2, 0.01, 100.0).unwrap()
    }

    #[test]
    fn pixel_centre_ray_of_centre_pixel_looks_forward() {
        let c = cam(
            Projection::Perspective { tan_half_fov: 0.5 },
            DVec3::ZERO,
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::Y,
        );
        let (_, d) = c.primary_ray_f64(160.0, 120.0);
        assert!((d - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-15);
        // Right of centre goes to +x (right-handed, y up, looking down -z).
        let (_, d) = c.primary_ray_f64(300.0, 120.0);
        assert!(d.x > 0.0);
        // Top of the image (small y) goes up.
        let (_, d) = c.primary_ray_f64(160.0, 10.0);
        assert!(d.y > 0.0);
    }

    /// The tables change where the work is done, not a bit of any ray: every
    /// sample of small grids (both projections, every sample count, odd
    /// sizes, tilted frames) and the samples just outside the grid.
    #[test]
    fn sample_rays_are_the_camera_rays_bit_for_bit() {
        let frames = [
            (
                DVec3::new(0.3, 1.7, 5.1),
                DVec3::new(-0.2, 0.1, 0.0),
                DVec3::Y,
            ),
            (
                DVec3::new(1e4, -3.0, 2.5),
                DVec3::new(1e4 + 1.0, -2.0, 2.0),
                DVec3::Z,
            ),
            (
                DVec3::new(-0.1, 0.0, 0.0),
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(0.3, 1.0, 0.2),
            ),
        ];
        for (eye, at, up) in frames {
            for proj in [
                Projection::Perspective { tan_half_fov: 0.41 },
                Projection::Perspective { tan_half_fov: 3.7 },
                Projection::Orthographic { view_height: 2.3 },
            ] {
                for (w, h, n) in [(7, 5, 1), (13, 3, 2), (4, 9, 4), (3, 2, 16)] {
                    let c = Camera::new(eye, at, up, proj, w, h, n, 0.013, 77.0).unwrap();
                    let rays = SampleRays::new(&c);
                    for sy in 0..=c.sample_height() {
                        for sx in 0..=c.sample_width() {
                            let (a, b) = (rays.ray(sx, sy), c.sample_ray64(sx, sy));
                            let bits = |r: Ray64| {
                                [
                                    r.origin.to_array(),
                                    r.dir.to_array(),
                                    [r.t_min, r.t_max, 0.0],
                                ]
                                .concat()
                                .iter()
                                .map(|v| v.to_bits())
                                .collect::<Vec<_>>()
                            };
                            assert_eq!(
                                bits(a),
                                bits(b),
                                "{proj:?} {w}x{h}x{n} sample ({sx}, {sy})"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn degenerate_frames_are_errors() {
        let p = Projection::Perspective { tan_half_fov: 0.5 };
        assert_eq!(
            Camera::new(DVec3::ONE, DVec3::ONE, DVec3::Y, p, 1, 1, 1, 0.01, 1.0),
            Err(CameraError::EyeAtTarget)
        );
        assert_eq!(
            Camera::new(DVec3::ZERO, DVec3::Y, DVec3::Y, p, 1, 1, 1, 0.01, 1.0),
            Err(CameraError::UpParallel)
        );
        // A NaN in `up` made a NaN frame (found by the fuzz corpus once the
        // frame's orthonormality was checked).
        let nan_up = DVec3::new(f64::NAN, f64::NAN, -1.0);
        assert_eq!(
            Camera::new(DVec3::ZERO, DVec3::Z, nan_up, p, 1, 1, 1, 0.01, 1.0),
            Err(CameraError::UpParallel)
        );
        // The guarantees the backends index by: samples and size.
        assert_eq!(
            Camera::new(DVec3::ZERO, DVec3::Z, DVec3::Y, p, 8, 6, 3, 0.01, 1.0),
            Err(CameraError::Samples { samples: 3 })
        );
        assert_eq!(
            Camera::new(DVec3::ZERO, DVec3::Z, DVec3::Y, p, 0, 6, 1, 0.01, 1.0),
            Err(CameraError::EmptyImage {
                width: 0,
                height: 6
            })
        );
    }

    #[test]
    fn sample_points_match_design() {
        let c = cam(
            Projection::Perspective { tan_half_fov: 0.5 },
            DVec3::ZERO,
            DVec3::Z,
            DVec3::Y,
        );
        // n = 2: pixel (3, 5), sub-sample (1, 0) -> (3 + 1.5/2, 5 + 0.5/2).
        assert_eq!(c.sample_point(7, 10), (3.75, 5.25));
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 2000, rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..ProptestConfig::default() })]

        /// project(ray(x, y).at(t)) == (x, y): the projection inverts the
        /// primary ray. Bound: the round trip is a handful of f64 operations
        /// on coordinates of size ≤ width, each with relative error 2^-53;
        /// amplified by at most 1/(D·f) ≤ 1/cos(fov/2) ≤ 12 for fov ≤ 170°
        /// and by the ratio t/z ≤ 1e4 of the sampled range. 1e-6 px is
        /// 100× above the resulting ~1e-9 px bound.
        #[test]
        fn project_inverts_primary_ray(
            ex in -50.0f64..50.0, ey in -50.0f64..50.0, ez in -50.0f64..50.0,
            dx in -1.0f64..1.0, dy in -1.0f64..1.0, dz in -1.0f64..1.0,
            ux in -1.0f64..1.0, uy in -1.0f64..1.0, uz in -1.0f64..1.0,
            fov in 1.0f64..170.0, ortho in any::<bool>(),
            x in 0.0f64..320.0, y in 0.0f64..240.0, t in 0.01f64..100.0,
        ) {
            let eye = DVec3::new(ex, ey, ez);
            let dir = DVec3::new(dx, dy, dz);
            let up = DVec3::new(ux, uy, uz);
            prop_assume!(dir.length() > 0.1 && up.length() > 0.1);
            prop_assume!(dir.normalize().cross(up.normalize()).length() > 0.05);
            let proj = if ortho {
                Projection::Orthographic { view_height: fov / 10.0 }
            } else {
                Projection::Perspective { tan_half_fov: (fov.to_radians() / 2.0).tan() }
            };
            let c = Camera::new(eye, eye + dir, up, proj, 320, 240, 1, 0.01, 1000.0).unwrap();
            let (o, d) = c.primary_ray_f64(x, y);
            let (px, py, _) = c.project(o + d * t).unwrap();
            prop_assert!((px - x).abs() < 1e-6 && (py - y).abs() < 1e-6,
                "({x}, {y}) -> ({px}, {py})");
        }
    }
}
