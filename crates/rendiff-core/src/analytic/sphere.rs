//! Ray/sphere intersection in its cancellation-free form (Haines et al.,
//! "Precision Improvements for Ray/Sphere Intersection", Ray Tracing Gems
//! ch. 7), in `f64`.
//!
//! The textbook `t = −b ± √(b² − c)` loses every digit of the discriminant
//! when the sphere is far from the ray origin (b² and c are both ≈ |o − c|²)
//! and half of them at a grazing ray (the discriminant ≈ 0), and its near
//! root cancels when `b ≈ √disc`. Here the discriminant is
//! `r² − |f − (f·d)d|²` (the squared distance of the closest approach,
//! computed from a vector that is small exactly when it matters), written as
//! `(r − l)(r + l)`, and the two roots are `q` and `c/q` with
//! `q = −b − sign(b)·√disc`, so neither root subtracts nearly equal numbers.

use glam::DVec3;

/// The roots `t0 ≤ t1` of `|o + t·d − c| = r` for a unit `d`, or `None`
/// when the ray's line misses the sphere.
#[must_use]
pub fn sphere_roots(o: DVec3, d: DVec3, center: DVec3, r: f64) -> Option<(f64, f64)> {
    let f = o - center;
    let b = f.dot(d);
    let l = (f - d * b).length();
    let disc = (r - l) * (r + l);
    if disc < 0.0 || !disc.is_finite() {
        return None;
    }
    let fl = f.length();
    let c = (fl - r) * (fl + r);
    let q = if b >= 0.0 {
        -b - disc.sqrt()
    } else {
        -b + disc.sqrt()
    };
    if q == 0.0 {
        // The origin is on the sphere and the ray is tangent: one root at 0.
        return Some((0.0, 0.0));
    }
    let (t0, t1) = (c / q, q);
    Some(if t0 <= t1 { (t0, t1) } else { (t1, t0) })
}

#[cfg(test)]
/// The textbook form, kept for the test that shows what it loses.
#[must_use]
pub(crate) fn sphere_roots_textbook(
    o: DVec3,
    d: DVec3,
    center: DVec3,
    r: f64,
) -> Option<(f64, f64)> {
    let f = o - center;
    let b = f.dot(d);
    let c = f.dot(f) - r * r;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some((-b - s, -b + s))
}

#[cfg(test)]
/// The nearest root in `[t_min, t_max]`.
#[must_use]
pub(crate) fn intersect_sphere(
    o: DVec3,
    d: DVec3,
    center: DVec3,
    r: f64,
    t_min: f64,
    t_max: f64,
) -> Option<f64> {
    let (t0, t1) = sphere_roots(o, d, center, r)?;
    [t0, t1].into_iter().find(|t| *t >= t_min && *t <= t_max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn far_sphere_keeps_its_digits() {
        // A unit sphere 1e6 away, hit off-centre at height h: the exact
        // near root is 1e6 − √(1 − h²).
        for &h in &[0.3, 0.7, 0.9, 0.999] {
            let o = DVec3::new(0.0, h, -1e6);
            let exact = 1e6 - (1.0f64 - h * h).sqrt();
            let (t0, _) = sphere_roots(o, DVec3::Z, DVec3::ZERO, 1.0).unwrap();
            let (tb, _) = sphere_roots_textbook(o, DVec3::Z, DVec3::ZERO, 1.0).unwrap();
            // Stable: within a few ulps of 1e6 (1.2e-10 each).
            assert!((t0 - exact).abs() < 1e-9, "h = {h}: {t0} vs {exact}");
            // The textbook error is orders of magnitude larger here.
            assert!(
                (tb - exact).abs() > 100.0 * (t0 - exact).abs().max(1e-12),
                "h = {h}"
            );
        }
    }

    #[test]
    fn grazing_ray_discriminant() {
        // A ray passing at distance 1 − 1e-9 from the centre of a unit
        // sphere far away: the chord half-length is √(1 − l²) ≈ 4.47e-5.
        let l = 1.0 - 1e-9;
        let o = DVec3::new(0.0, l, -1e4);
        let (t0, t1) = sphere_roots(o, DVec3::Z, DVec3::ZERO, 1.0).unwrap();
        let half = ((1.0 - l) * (1.0 + l)).sqrt();
        assert!(
            ((t1 - t0) / 2.0 - half).abs() < 1e-9 * half * 1e3,
            "{} vs {half}",
            (t1 - t0) / 2.0
        );
        let tb = sphere_roots_textbook(o, DVec3::Z, DVec3::ZERO, 1.0);
        let err_b = tb.map_or(f64::INFINITY, |(a, b)| ((b - a) / 2.0 - half).abs());
        assert!(err_b > 1e3 * ((t1 - t0) / 2.0 - half).abs());
    }

    #[test]
    fn inside_origin_takes_the_far_root() {
        let t =
            intersect_sphere(DVec3::ZERO, DVec3::X, DVec3::ZERO, 2.0, 1e-9, f64::INFINITY).unwrap();
        assert!((t - 2.0).abs() < 1e-15);
    }
}
