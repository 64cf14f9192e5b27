//! Homogeneous clipping of a triangle against the near plane and, only
//! where a vertex leaves it, the guard band around the screen.
//!
//! A clipped edge's new vertex is computed from its two endpoints taken in
//! a canonical order (by their coordinates), so the two triangles that
//! share an edge clip it to the *same* point: the edge stays shared and
//! the coverage rule stays watertight across clipped triangles too.

/// A vertex in homogeneous screen space: `(X·w, Y·w, w)` with `(X, Y)` in
/// pixels, and its view depth `z` (perspective: `w = z`; orthographic: `w = 1`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HVert {
    /// `X·w`.
    pub xh: f64,
    /// `Y·w`.
    pub yh: f64,
    /// `w`.
    pub w: f64,
    /// View depth.
    pub z: f64,
}

impl HVert {
    /// Screen position (pixels).
    #[must_use]
    pub(crate) fn screen(&self) -> (f64, f64) {
        (self.xh / self.w, self.yh / self.w)
    }

    fn key(&self) -> [u64; 4] {
        [self.xh, self.yh, self.w, self.z].map(f64::to_bits)
    }

    fn lerp(a: &HVert, b: &HVert, t: f64) -> HVert {
        HVert {
            xh: a.xh + (b.xh - a.xh) * t,
            yh: a.yh + (b.yh - a.yh) * t,
            w: a.w + (b.w - a.w) * t,
            z: a.z + (b.z - a.z) * t,
        }
    }
}

/// A clip plane as a signed distance function (inside: ≥ 0).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Plane {
    /// Coefficients on (xh, yh, w, z) and a constant.
    pub c: [f64; 5],
}

impl Plane {
    fn dist(&self, v: &HVert) -> f64 {
        self.c[0] * v.xh + self.c[1] * v.yh + self.c[2] * v.w + self.c[3] * v.z + self.c[4]
    }
}

/// Clips a convex polygon against a plane (Sutherland–Hodgman).
pub(crate) fn clip_polygon(poly: &[HVert], plane: &Plane, out: &mut Vec<HVert>) {
    out.clear();
    let n = poly.len();
    for i in 0..n {
        let a = &poly[i];
        let b = &poly[(i + 1) % n];
        let da = plane.dist(a);
        let db = plane.dist(b);
        if da >= 0.0 {
            out.push(*a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            // Canonical order: the same point whichever way the edge runs.
            let (p, q, dp, dq) = if a.key() <= b.key() {
                (a, b, da, db)
            } else {
                (b, a, db, da)
            };
            let t = dp / (dp - dq);
            out.push(HVert::lerp(p, q, t));
        }
    }
}

/// The clip planes: the near plane `z ≥ near`, the far plane `z ≤ far`,
/// and the guard band `−g ≤ X ≤ width + g`, `−g ≤ Y ≤ height + g` (in
/// homogeneous form, valid once `w > 0`).
#[must_use]
pub(crate) fn planes(near: f64, far: f64, width: f64, height: f64, g: f64) -> [Plane; 6] {
    [
        Plane {
            c: [0.0, 0.0, 0.0, 1.0, -near],
        },
        Plane {
            c: [0.0, 0.0, 0.0, -1.0, far],
        },
        Plane {
            c: [1.0, 0.0, g, 0.0, 0.0],
        },
        Plane {
            c: [-1.0, 0.0, width + g, 0.0, 0.0],
        },
        Plane {
            c: [0.0, 1.0, g, 0.0, 0.0],
        },
        Plane {
            c: [0.0, -1.0, height + g, 0.0, 0.0],
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(xh: f64, z: f64) -> HVert {
        HVert {
            xh,
            yh: 0.0,
            w: z,
            z,
        }
    }

    #[test]
    fn shared_edge_clips_to_the_same_point_both_ways() {
        let near = Plane {
            c: [0.0, 0.0, 0.0, 1.0, -0.1],
        };
        let a = v(0.3, -1.0);
        let b = v(0.7, 2.0);
        let c = v(5.0, 3.0);
        let d = v(-5.0, 3.0);
        let mut o1 = Vec::new();
        let mut o2 = Vec::new();
        clip_polygon(&[a, b, c], &near, &mut o1);
        clip_polygon(&[b, a, d], &near, &mut o2);
        let p1 = o1
            .iter()
            .find(|p| p.z == 0.1 || (p.z - 0.1).abs() < 1e-15)
            .copied();
        let on_ab =
            |p: &HVert| (p.z - 0.1).abs() < 1e-12 && (p.xh - (0.3 + 0.4 * 1.1 / 3.0)).abs() < 1e-9;
        let x1: Vec<_> = o1.iter().filter(|p| on_ab(p)).collect();
        let x2: Vec<_> = o2.iter().filter(|p| on_ab(p)).collect();
        assert!(p1.is_some());
        assert_eq!(x1.len(), 1);
        assert_eq!(x2.len(), 1);
        assert_eq!(x1[0], x2[0], "bit-identical clip point");
    }
}
