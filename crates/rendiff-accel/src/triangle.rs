//! Watertight ray/triangle intersection (Woop, Benthin & Wald, "Watertight
//! Ray/Triangle Intersection", JCGT 2(1), 2013), decided in `f64` behind a
//! certified `f32` filter.
//!
//! The ray is translated to the origin, the axes permuted so the ray runs
//! along +z, and the triangle sheared so the ray becomes the z axis; the
//! hit is then a 2-D inside test of three edge functions that are exact
//! negatives of each other across a shared edge (the same products in the
//! same order), so no ray slips between two triangles and none hits both
//! except exactly on the shared edge.
//!
//! **Two stages.** [`candidates`] runs the edge functions of four
//! triangles at once in `f32` and drops a triangle only when two of its
//! edge functions have opposite signs *beyond their rounding error*
//! (`EDGE_PRODUCTS`): the exact edge functions then have those signs too.
//! Every other triangle goes to [`intersect`], which decides in `f64`
//! (translation, shear, edge functions, distance): its error is about
//! 2⁻⁵³ of the coordinates, against 2⁻²⁴ for an `f32` test. That matters
//! where the vertices are far from the ray origin compared with the hit:
//! an eye a millimetre above a floor two kilometres across sees the floor
//! at a few millimetres, where an `f32` test misplaces the floor's edges
//! by degrees and its distance by more than the distance itself.
//!
//! **No hit is rejected for being near the origin** except within the
//! `f64` test's own error bound of `t` (pbrt-v4's δt, with `f64`
//! rounding): about 10⁻¹⁵ of the triangle's extent in ray space. Rays
//! that start on a surface start off it by the hit point's error bound
//! (`shade::offset_origin`), so the surface they leave lies behind them by
//! more than that; primary rays start at the near plane.
//!
//! Both stages use only the ray and the vertices, the same operations for
//! every triangle that shares an edge, so the two triangles of an edge
//! take the same stage for it and reach opposite signs: the test stays
//! watertight.

use glam::{DVec3, Vec4};

use rendiff_core::math::{
    F32_EPS, Ray, Ray64, Vec3, f32_at_least, f32_at_most, gamma64, to_f32, to_f64,
};

/// Rounding bounds of the `f32` edge functions of [`candidates`].
///
/// With u = 2⁻²⁴ and γₙ = nu/(1 − nu), per vertex: the translated
/// coordinates `X, Y, Z` (one rounding each) and `m = |X| + |Y| + |Z|`
/// (≥ the exact sum × (1 − γ₂)); the shear constant `S = d_x/d_z`
/// (|S| ≤ 1, the dominant axis) carries one rounding, and differs from the
/// `f64` ray's by ≤ 3u more (its direction rounded to `f32`), so a sheared
/// coordinate `x = X − S·Z` lies within `e = γ₁₀·m + 2·Δo` of the `f64`
/// ray's, where `Δo` is the distance between the two origins
/// (`RayPrecomp::m_shift` adds `2Δo/γ₁₀` to every `m`). With
/// `n = |x| + |y|` (computed), the edge function `c_x·b_y − c_y·b_x` is
/// then within `γ₂(|P| + |Q|)(1 + γ₁) + e_c(n_b + e_b) + e_b(n_c + e_c)`
/// of the `f64` ray's (`P`, `Q` the two computed products). The
/// constants below are those coefficients rounded up by a factor of 2,
/// which covers the rounding of the bound's own few operations and leaves
/// the margin that keeps a certified sign clear of the `f64` test's own
/// error (2⁻⁵³ relative): a certified edge has the same sign in `f64`.
const EDGE_PRODUCTS: f32 = 2.0 * 2.0 * F32_EPS / (1.0 - 2.0 * F32_EPS);
/// See [`EDGE_PRODUCTS`]: the coefficient of `m_c n_b + m_b n_c`.
const EDGE_COORDS: f32 = 2.0 * GAMMA_10;
/// See [`EDGE_PRODUCTS`]: the coefficient of `m_b m_c`, relative to
/// [`EDGE_COORDS`] (`2γ₁₀²·2 / (2γ₁₀)` = 2γ₁₀).
const EDGE_SECOND: f32 = 2.0 * GAMMA_10;
/// γ₁₀ for `f32`.
const GAMMA_10: f32 = 10.0 * F32_EPS / (1.0 - 10.0 * F32_EPS);

/// Below this a bound is not trusted (its products may be subnormal, where
/// relative error bounds do not hold): such edges always go to `f64`.
const MIN_TRUSTED: f32 = 1e-30;

/// The `f32` ray that walks the BVH for an `f64` ray, and how far the two
/// stray apart: all a ray needs until it reaches a leaf. The triangle
/// test's constants ([`RayPrecomp`]) are derived from it only then, so a
/// ray that meets no leaf (most primary rays of a frame with background)
/// never computes them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WalkRay {
    /// The `f32` ray nearest to the `f64` one (`t_min` rounded down,
    /// `t_max` up).
    pub ray: Ray,
    /// How far the `f32` ray strays from the `f64` one up to the
    /// farthest `t` that matters (boxes are inflated by this).
    pub inflate: f32,
    /// What [`WalkRay::inflate`] lacks where the slab test replaces a
    /// direction component ([`slab_dir`]): the replaced direction strays
    /// from the `f64` one by under 2.1·10⁻³⁰ per unit t (the replacement
    /// and the component are each below 10⁻³⁰ and 1 ulp), so by this much
    /// up to the farthest `t` that matters.
    pub replaced: f32,
    /// The distance between the two origins (largest coordinate).
    dorigin: f64,
}

impl WalkRay {
    /// The `f32` ray of `ray`; `t_bound` is the farthest `t` at which the
    /// ray can still meet anything (it bounds the drift between the `f64`
    /// ray and its `f32` copy).
    #[must_use]
    #[inline(always)]
    pub(crate) fn new(ray: &Ray64, t_bound: f64) -> WalkRay {
        let d = to_f32(ray.dir);
        let o = to_f32(ray.origin);
        // The two rays apart: origins by `do`, directions by `dd` per unit
        // t (largest components by `max`, which has no branch; `dd·t` is
        // NaN only for 0·∞, which the last `max` turns into 0).
        let largest = |v: DVec3| v.x.max(v.y).max(v.z);
        let dorigin = largest((to_f64(o) - ray.origin).abs());
        // (Against the `f32` direction; where the slab test replaces a
        // component, `replaced` adds that one's drift: without it, a ray
        // lying in a box's face with a zero component there left the box
        // at t = 0 and missed what the `f64` test meets on that face, an
        // edge of a triangle whose box ends there. It is added in
        // `Slab::new`, which finds the replaced components anyway: a test
        // here cost every ray about 1 %.)
        let ddir = largest((to_f64(d) - ray.dir).abs());
        let t_reach = t_bound.min(ray.t_max).max(0.0);
        let reach = (ddir * t_reach).max(0.0);
        WalkRay {
            ray: Ray {
                origin: o,
                dir: d,
                t_min: f32_at_most(ray.t_min),
                t_max: f32_at_least(ray.t_max),
            },
            inflate: f32_at_least((dorigin + reach) * (1.0 + 1e-6)),
            replaced: f32_at_least((2.1e-30 * t_reach).max(0.0) * (1.0 + 1e-6)),
            dorigin,
        }
    }
}

/// The direction the slab test walks for the `f32` direction `d`: each
/// component below 10⁻³⁰ in magnitude replaced by 10⁻³⁰ of its sign (a
/// zero component would give 0·∞ = NaN in the slab test). [`WalkRay`]
/// counts the change in its drift, so the boxes are inflated by it.
#[inline(always)]
pub(crate) fn slab_dir(d: Vec3) -> Vec3 {
    let tiny = Vec3::splat(1e-30);
    Vec3::select(d.abs().cmplt(tiny), tiny.copysign(d), d)
}

/// Per-ray constants of the watertight test: the `f64` ray that decides,
/// and the shear of the nearest `f32` ray ([`WalkRay`]) that filters.
/// The `f64` shear (three divisions, [`RayPrecomp::shear64`]) is formed by
/// a leaf's first `f64` test: most rays that reach a leaf, and most shadow
/// rays (which skip the triangle they leave), never make one. (Kept
/// beside the constants rather than in them: a write into them made the
/// walk reload them around every triangle test, +14 % instructions on a
/// flat loop.)
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayPrecomp {
    /// Axis permutation: the dominant axis of the direction is `kz`.
    pub k: [usize; 3],
    /// The `f64` ray.
    origin64: DVec3,
    dir64: DVec3,
    /// The `f32` origin's coordinates, each in four lanes (for [`candidates`]).
    o4: [Vec4; 3],
    /// The `f32` `Sx` and `Sy` in four lanes.
    s4: [Vec4; 2],
    /// Added to every vertex's `m` in [`candidates`]: `2Δo/γ₁₀`.
    m_shift: Vec4,
    /// The distance bounds of `candidates::<true>` (see [`RayPrecomp::of`]):
    /// a triangle whose least translated `Z` is above `z_above`, or whose
    /// greatest is below `z_below`, lies wholly behind the `f64` origin or
    /// wholly past the `f64` ray's `t_max` (which of the two depends on
    /// the sign of the direction's dominant component). A closest-hit
    /// walk's are ±∞, never read.
    z_above: f32,
    z_below: f32,
}

impl RayPrecomp {
    /// Precomputes the permutation and shear of a ray; `t_bound` is the
    /// farthest `t` at which the ray can still meet anything (see
    /// [`WalkRay::new`]).
    #[cfg(test)]
    #[must_use]
    pub(crate) fn new(ray: &Ray64, t_bound: f64) -> RayPrecomp {
        RayPrecomp::of::<true>(ray, &WalkRay::new(ray, t_bound))
    }

    /// The permutation and shear of `ray`, whose `f32` copy is `walk`;
    /// with `SEGMENT`, the distance bounds of `candidates::<true>` too
    /// (a closest-hit walk's filter never reads them, and skips their
    /// arithmetic).
    #[must_use]
    pub(crate) fn of<const SEGMENT: bool>(ray: &Ray64, walk: &WalkRay) -> RayPrecomp {
        let d = walk.ray.dir;
        let o = walk.ray.origin;
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
        // Components by position in an array (glam's `Index` is a chain of
        // branches per access).
        let da = d.to_array();
        // Keep the winding: swap when the dominant component is negative.
        if da[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let s = Vec3::new(da[kx] / da[kz], da[ky] / da[kz], 1.0 / da[kz]);
        let m_shift = f32_at_least(2.0 * walk.dorigin / f64::from(GAMMA_10));
        // The distance bounds of [`candidates`] (derived there): `Δo`, and
        // `t_max·|d_z|` enlarged by γ₁₆ for the `f64` test's rounding of
        // `t`, plus `Δo`; each enlarged by 10⁻⁶ (> the `f32` rounding of
        // a translated coordinate, 2⁻²⁴ relative) and rounded up.
        let (z_above, z_below) = if SEGMENT {
            let dz64 = ray.dir.to_array()[kz];
            let z_behind = f32_at_least(walk.dorigin * (1.0 + 1e-6));
            let beyond =
                (ray.t_max * dz64.abs() * (1.0 + gamma64(16)) + walk.dorigin) * (1.0 + 1e-6);
            let z_beyond = if beyond.is_nan() {
                f32::INFINITY
            } else {
                f32_at_least(beyond)
            };
            // Along +z: behind is `Z < −z_behind`, past the end `Z > z_beyond`;
            // along −z the two swap sides. The side is the `f64` direction's
            // (its `f32` copy can round to −0 or +0 where it is below 10⁻⁴⁵).
            if dz64 < 0.0 {
                (z_behind, -z_beyond)
            } else {
                (z_beyond, -z_behind)
            }
        } else {
            (f32::INFINITY, f32::NEG_INFINITY)
        };
        RayPrecomp {
            k: [kx, ky, kz],
            origin64: ray.origin,
            dir64: ray.dir,
            o4: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            s4: [Vec4::splat(s.x), Vec4::splat(s.y)],
            m_shift: Vec4::splat(m_shift),
            z_above,
            z_below,
        }
    }

    /// The shear constants of the `f64` direction (permuted by `k`), for
    /// [`intersect`].
    #[inline(always)]
    pub(crate) fn shear64(&self) -> [f64; 3] {
        let [kx, ky, kz] = self.k;
        let d = self.dir64.to_array();
        [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]]
    }
}

/// Four triangles as structure of arrays: `v[corner][axis]` holds that
/// coordinate of the four triangles, one per lane. Leaves of the BVH are
/// runs of packs; `lanes` says how many lanes are triangles and `last`
/// whether the leaf ends here. Plain old data (no padding, every bit
/// pattern a value), so that the build's pack array can live in memory
/// advised for huge pages (`huge::Big`).
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub(crate) struct TriPack {
    /// Corner coordinates, `v[corner][axis]`, a triangle per lane.
    pub v: [[Vec4; 3]; 3],
    /// Lanes in use (1 … 4).
    pub lanes: u32,
    /// 1 for the last pack of its leaf, else 0 (see [`TriPack::ends_leaf`]).
    pub last: u32,
    /// (The pack's size is a multiple of its vectors' 16 bytes.)
    pad: [u32; 2],
}

impl TriPack {
    /// An empty pack (no lanes), which the tests fill lane by lane.
    #[cfg(test)]
    pub(crate) const EMPTY: TriPack = TriPack {
        v: [[Vec4::ZERO; 3]; 3],
        lanes: 0,
        last: 1,
        pad: [0; 2],
    };

    /// A pack of `lanes` triangles, not the last of its leaf.
    pub(crate) fn new(v: [[Vec4; 3]; 3], lanes: u32) -> TriPack {
        TriPack {
            v,
            lanes,
            last: 0,
            pad: [0; 2],
        }
    }

    /// The last pack of its leaf.
    #[inline(always)]
    pub(crate) fn ends_leaf(&self) -> bool {
        self.last != 0
    }

    /// Puts a triangle in `lane`.
    #[cfg(test)]
    pub(crate) fn set(&mut self, lane: usize, tri: [Vec3; 3]) {
        for (corner, p) in tri.iter().enumerate() {
            self.v[corner][0][lane] = p.x;
            self.v[corner][1][lane] = p.y;
            self.v[corner][2][lane] = p.z;
        }
    }
}

/// The lanes of `pack` that [`intersect`] could accept, as a bit mask (a
/// superset). A lane is dropped only when one of its `f32` edge functions
/// is below `−bound` and another above `+bound` (`EDGE_PRODUCTS`): the
/// exact edge functions, and so the `f64` ones of [`intersect`], then have
/// those signs as well, and the ray passes outside. Everything else —
/// the hits, and the rays within rounding of an edge — is decided by
/// [`intersect`].
///
/// With `SEGMENT`, a lane is also dropped when the triangle lies wholly
/// behind the origin or wholly past the ray's own `t_max` along the
/// ray's dominant axis (for queries whose `t_max` never shrinks: any-hit
/// and every-hit), by comparing the least and greatest translated `Z`
/// with two per-ray bounds. The argument, with `s` the sign of `d_z` and `ε` the
/// `f32` unit roundoff: a computed `Z = fl(v_z − o32_z)` has the sign of
/// the exact difference and `|Z| ≤ (1 + ε)` of it, and the `f64` origin
/// is within `Δo` of the `f32` one, so `Z·s < −Δo(1 + 10⁻⁶)` at every
/// corner puts every corner strictly behind the `f64` origin. The `f64`
/// test's translated `Z` then have that sign too (rounding keeps a sign),
/// its `t` is a sum of products of one sign over a `det` of the other,
/// so `t ≤ 0 ≤ δt`, which it rejects. Past the end: `Z·s` above
/// `(t_max·|d_z|(1 + γ₁₆) + Δo)(1 + 10⁻⁶)` at every corner puts every
/// corner's exact `f64` distance along the axis above `t_max·|d_z|(1 +
/// γ₁₆)`; the `f64` `t` is a weighted mean of the corners' `sz·Z` (the
/// weights `u, v, w / det` of one sign) computed with about ten roundings
/// (three in `sz·Z`, three in the sum, two in `det`, two in `1/det` and
/// the product), so it is at least `(1 − γ₁₀)` of the least corner's and
/// exceeds `t_max`, which the test rejects. (As every error bound of the
/// `f64` test, this one assumes no product underflows: edge functions
/// below 10⁻³⁰⁰, which coordinates that come from `f32` scenes never
/// reach.)
#[must_use]
#[inline(always)]
pub(crate) fn candidates<const SEGMENT: bool>(pre: &RayPrecomp, pack: &TriPack) -> u32 {
    let [kx, ky, kz] = pre.k;
    let [sx, sy] = pre.s4;
    let o = &pre.o4;
    let shear = |c: &[Vec4; 3]| {
        let x = c[kx] - o[kx];
        let y = c[ky] - o[ky];
        let z = c[kz] - o[kz];
        let m = x.abs() + y.abs() + z.abs() + pre.m_shift;
        let (xs, ys) = (x - sx * z, y - sy * z);
        (xs, ys, m, xs.abs() + ys.abs(), z)
    };
    let (ax, ay, am, an, az) = shear(&pack.v[0]);
    let (bx, by, bm, bn, bz) = shear(&pack.v[1]);
    let (cx, cy, cm, cn, cz) = shear(&pack.v[2]);
    let g1 = Vec4::splat(EDGE_PRODUCTS);
    let g2 = Vec4::splat(EDGE_COORDS);
    let g3 = Vec4::splat(EDGE_SECOND);
    let tiny = Vec4::splat(MIN_TRUSTED);
    // The edge function of an edge from `s` to `e`, and its bound; a bound
    // too small to trust is raised to +∞ (never certified).
    let edge = |ex: Vec4, ey: Vec4, em: Vec4, en: Vec4, sx: Vec4, sy: Vec4, sm: Vec4, sn: Vec4| {
        let p = ex * sy;
        let q = ey * sx;
        let bound = g1 * (p.abs() + q.abs()) + g2 * (em * sn + sm * en + g3 * (sm * em));
        let bound = Vec4::select(bound.cmplt(tiny), Vec4::INFINITY, bound);
        (p - q, bound)
    };
    let (u, eu) = edge(cx, cy, cm, cn, bx, by, bm, bn);
    let (v, ev) = edge(ax, ay, am, an, cx, cy, cm, cn);
    let (w, ew) = edge(bx, by, bm, bn, ax, ay, am, an);
    let neg = u.cmplt(-eu) | v.cmplt(-ev) | w.cmplt(-ew);
    let pos = u.cmpgt(eu) | v.cmpgt(ev) | w.cmpgt(ew);
    let kept = !(neg & pos).bitmask() & ((1u32 << pack.lanes) - 1);
    // The distance test only where a lane passed the edges (most packs a
    // ray meets have none: a branch instead of the test).
    if SEGMENT && kept != 0 {
        let above = az.min(bz).min(cz).cmpgt(Vec4::splat(pre.z_above));
        let below = az.max(bz).max(cz).cmplt(Vec4::splat(pre.z_below));
        return kept & !(above | below).bitmask();
    }
    kept
}

/// [`candidates`] of two rays with the same axis permutation (`k`) on one
/// pack at once, eight lanes wide (lanes 0–3 ray `a`, 4–7 ray `b`):
/// written lane by lane for the vectoriser, each lane the same IEEE
/// operations on the same operands as [`candidates`] (`min`/`max` as
/// `minps`/`maxps`, no fused multiply-add), so each mask is exactly that
/// ray's [`candidates`] (the distance test, which [`candidates`] skips
/// when the edges drop every lane, only clears lanes the edges keep).
#[must_use]
#[inline(always)]
pub(crate) fn candidates2<const SEGMENT: bool>(
    a: &RayPrecomp,
    b: &RayPrecomp,
    pack: &TriPack,
) -> (u32, u32) {
    debug_assert_eq!(a.k, b.k, "one axis permutation");
    let [kx, ky, kz] = a.k;
    let two = |p: Vec4, q: Vec4| -> [f32; 8] {
        let (p, q) = (p.to_array(), q.to_array());
        [p[0], p[1], p[2], p[3], q[0], q[1], q[2], q[3]]
    };
    let (ox, oy, oz) = (
        two(a.o4[kx], b.o4[kx]),
        two(a.o4[ky], b.o4[ky]),
        two(a.o4[kz], b.o4[kz]),
    );
    let (sx, sy) = (two(a.s4[0], b.s4[0]), two(a.s4[1], b.s4[1]));
    let shift = two(a.m_shift, b.m_shift);
    // The translated and sheared corners (a function, not a closure: a
    // closure called three times is compiled out of line, without the
    // instruction set of its caller).
    #[inline(always)]
    fn shear(
        c: [[f32; 8]; 3],
        [ox, oy, oz]: &[[f32; 8]; 3],
        [sx, sy, shift]: &[[f32; 8]; 3],
    ) -> [[f32; 8]; 5] {
        let [cx, cy, cz] = c;
        let mut out = [[0.0f32; 8]; 5];
        for l in 0..8 {
            let x = cx[l] - ox[l];
            let y = cy[l] - oy[l];
            let z = cz[l] - oz[l];
            let m = x.abs() + y.abs() + z.abs() + shift[l];
            let (xs, ys) = (x - sx[l] * z, y - sy[l] * z);
            out[0][l] = xs;
            out[1][l] = ys;
            out[2][l] = m;
            out[3][l] = xs.abs() + ys.abs();
            out[4][l] = z;
        }
        out
    }
    let (o, k) = ([ox, oy, oz], [sx, sy, shift]);
    let rows = |c: &[Vec4; 3]| [two(c[kx], c[kx]), two(c[ky], c[ky]), two(c[kz], c[kz])];
    let [ax, ay, am, an, az] = shear(rows(&pack.v[0]), &o, &k);
    let [bx, by, bm, bn, bz] = shear(rows(&pack.v[1]), &o, &k);
    let [cx, cy, cm, cn, cz] = shear(rows(&pack.v[2]), &o, &k);
    let (za, zb) = if SEGMENT {
        (
            [
                a.z_above, a.z_above, a.z_above, a.z_above, b.z_above, b.z_above, b.z_above,
                b.z_above,
            ],
            [
                a.z_below, a.z_below, a.z_below, a.z_below, b.z_below, b.z_below, b.z_below,
                b.z_below,
            ],
        )
    } else {
        ([f32::INFINITY; 8], [f32::NEG_INFINITY; 8])
    };
    let lane_min = |p: f32, q: f32| if p < q { p } else { q };
    let lane_max = |p: f32, q: f32| if p > q { p } else { q };
    // The edge function and its bound, as in [`candidates`].
    #[inline(always)]
    #[expect(clippy::too_many_arguments, reason = "two corners' four values")]
    fn edge(ex: f32, ey: f32, em: f32, en: f32, sx: f32, sy: f32, sm: f32, sn: f32) -> (f32, f32) {
        let p = ex * sy;
        let q = ey * sx;
        let bound = EDGE_PRODUCTS * (p.abs() + q.abs())
            + EDGE_COORDS * (em * sn + sm * en + EDGE_SECOND * (sm * em));
        let bound = if bound < MIN_TRUSTED {
            f32::INFINITY
        } else {
            bound
        };
        (p - q, bound)
    }
    // −1 where the lane is dropped, +1 where kept (read by sign).
    let mut verdict = [0.0f32; 8];
    for l in 0..8 {
        let (u, eu) = edge(cx[l], cy[l], cm[l], cn[l], bx[l], by[l], bm[l], bn[l]);
        let (v, ev) = edge(ax[l], ay[l], am[l], an[l], cx[l], cy[l], cm[l], cn[l]);
        let (w, ew) = edge(bx[l], by[l], bm[l], bn[l], ax[l], ay[l], am[l], an[l]);
        let neg = (u < -eu) | (v < -ev) | (w < -ew);
        let pos = (u > eu) | (v > ev) | (w > ew);
        let mut drop = neg & pos;
        if SEGMENT {
            let above = lane_min(lane_min(az[l], bz[l]), cz[l]) > za[l];
            let below = lane_max(lane_max(az[l], bz[l]), cz[l]) < zb[l];
            drop |= above | below;
        }
        verdict[l] = if drop { -1.0 } else { 1.0 };
    }
    let dropped = Vec4::from_slice(&verdict[..4]).is_negative_bitmask()
        | Vec4::from_slice(&verdict[4..]).is_negative_bitmask() << 4;
    let lanes = (1u32 << pack.lanes) - 1;
    let kept = !dropped;
    (kept & lanes, (kept >> 4) & lanes)
}

/// A hit: distance and the barycentric weights (of v0, v1, v2) as the
/// watertight test computes them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriHit {
    /// Ray parameter, rounded to `f32` from [`TriHit::t64`].
    pub t: f32,
    /// Ray parameter in `f64`, as decided.
    pub t64: f64,
    /// Barycentric weights, rounded to `f32`.
    pub b: [f32; 3],
}

/// Intersects a ray with a triangle in `f64`, accepting
/// `t_min ≤ t ≤ t_max` (inclusive at `t_max`, so a caller that orders
/// equal distances by triangle id sees every tie) and `t` beyond the
/// test's own rounding error of `t`. (The walks test a pack's lane,
/// [`intersect_lane`]; this form is the tests' and [`meets`]'.)
#[must_use]
#[inline(always)]
pub(crate) fn intersect(
    pre: &RayPrecomp,
    shear: [f64; 3],
    v: &[Vec3; 3],
    t_min: f64,
    t_max: f64,
) -> Option<TriHit> {
    let [kx, ky, kz] = pre.k;
    let corner = |p: &Vec3| {
        let p = p.to_array();
        [p[kx], p[ky], p[kz]]
    };
    intersect_permuted(pre, shear, v.each_ref().map(corner), t_min, t_max)
}

/// The walks' test of one triangle, given by its corners, for `ray` alone
/// over its own `[t_min, t_max]`: [`intersect`] with the constants a walk
/// forms for the ray ([`RayPrecomp::of`]; the `f64` test reads only its
/// axis permutation, from the `f32` direction, and the `f64` ray), so the
/// answer of [`intersect_lane`] on a pack holding those corners, bit for
/// bit.
#[must_use]
#[inline(always)]
pub(crate) fn meets(ray: &Ray64, v: &[Vec3; 3]) -> Option<TriHit> {
    let pre = RayPrecomp::of::<false>(ray, &WalkRay::new(ray, ray.t_max));
    intersect(&pre, pre.shear64(), v, ray.t_min, ray.t_max)
}

/// [`intersect`] of the triangle in `lane` of `pack`, read from the pack
/// directly: the same operations on the same values (each corner's
/// coordinates taken by the ray's axis permutation), without forming the
/// triangle's `Vec3` corners and indexing them by axis (glam's `Index`
/// is a chain of branches per access).
#[must_use]
#[inline(always)]
pub(crate) fn intersect_lane(
    pre: &RayPrecomp,
    shear: [f64; 3],
    pack: &TriPack,
    lane: usize,
    t_min: f64,
    t_max: f64,
) -> Option<TriHit> {
    let [kx, ky, kz] = pre.k;
    let lane = lane & 3;
    let corner = |c: &[Vec4; 3]| {
        let at = |axis: usize| -> f32 { AsRef::<[f32; 4]>::as_ref(&c[axis])[lane] };
        [at(kx), at(ky), at(kz)]
    };
    intersect_permuted(pre, shear, pack.v.each_ref().map(corner), t_min, t_max)
}

/// [`intersect`] of a triangle whose corners are given permuted by the
/// ray's axes (`[p[kx], p[ky], p[kz]]` of each corner `p`).
#[must_use]
#[inline(always)]
#[expect(clippy::similar_names, reason = "the paper's names")]
fn intersect_permuted(
    pre: &RayPrecomp,
    [sx, sy, sz]: [f64; 3],
    v: [[f32; 3]; 3],
    t_min: f64,
    t_max: f64,
) -> Option<TriHit> {
    let [kx, ky, kz] = pre.k;
    let o = pre.origin64.to_array();
    let (ox, oy, oz) = (o[kx], o[ky], o[kz]);
    // Per axis `f64(p) − o` (the `f64` translation), then the shear.
    let shear = |[px, py, pz]: [f32; 3]| {
        let (x, y, z) = (f64::from(px) - ox, f64::from(py) - oy, f64::from(pz) - oz);
        (x - sx * z, y - sy * z, z)
    };
    let (ax, ay, az) = shear(v[0]);
    let (bx, by, bz) = shear(v[1]);
    let (cx, cy, cz) = shear(v[2]);
    let u = cx * by - cy * bx;
    let vv = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0 || vv < 0.0 || w < 0.0) && (u > 0.0 || vv > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + vv + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let (az, bz, cz) = (sz * az, sz * bz, sz * cz);
    let t_scaled = u * az + vv * bz + w * cz;
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t >= t_min && t <= t_max) {
        return None;
    }
    // pbrt-v4's bound on the rounding error of t, with f64's γ: hits
    // within it of 0 cannot be told from the surface the ray leaves.
    let max_zt = az.abs().max(bz.abs()).max(cz.abs());
    let max_xt = ax.abs().max(bx.abs()).max(cx.abs());
    let max_yt = ay.abs().max(by.abs()).max(cy.abs());
    let delta_z = gamma64(3) * max_zt;
    let delta_x = gamma64(5) * (max_xt + max_zt);
    let delta_y = gamma64(5) * (max_yt + max_zt);
    let delta_e = 2.0 * (gamma64(2) * max_xt * max_yt + delta_y * max_xt + delta_x * max_yt);
    let max_e = u.abs().max(vv.abs()).max(w.abs());
    let delta_t =
        3.0 * (gamma64(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e) * inv.abs();
    if t <= delta_t {
        return None;
    }
    #[expect(
        clippy::cast_possible_truncation,
        reason = "the f32 copies of the f64 result"
    )]
    Some(TriHit {
        t: t as f32,
        t64: t,
        b: [(u * inv) as f32, (vv * inv) as f32, (w * inv) as f32],
    })
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: small generated counts and indices, where a wrong cast fails the test"
)]
mod tests {
    use super::*;

    /// A deterministic stream of numbers in [0, 1) (SplitMix64, 53 bits),
    /// for the generated cases below.
    fn uniform(mut state: u64) -> impl FnMut() -> f64 {
        move || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            #[expect(clippy::cast_precision_loss, reason = "53 random bits")]
            let f = ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64;
            f
        }
    }

    /// A triangle of `f32` corners drawn by `next` (values in [0, 1)) in
    /// the cube of side `scale` centred on `c`.
    fn triangle_around(c: DVec3, scale: f64, next: &mut impl FnMut() -> f64) -> [Vec3; 3] {
        let mut corner = || {
            let (r, s, t) = (next(), next(), next());
            to_f32(c + DVec3::new(r - 0.5, s - 0.5, t - 0.5) * scale)
        };
        [corner(), corner(), corner()]
    }

    /// [`intersect`] with the ray's own `f64` shear.
    fn hit_of(pre: &RayPrecomp, v: &[Vec3; 3], t_min: f64, t_max: f64) -> Option<TriHit> {
        intersect(pre, pre.shear64(), v, t_min, t_max)
    }

    /// [`meets`], the test of a triangle given by its corners, is the
    /// walks' own test of the triangle in a pack's lane with the constants
    /// an any-hit walk forms ([`RayPrecomp::of`] with the segment filter's
    /// bounds, over the walk's own reach), bit for bit: the same hit or
    /// miss, `t` and weights, whichever lane holds it among other
    /// triangles. Rays in every octant, with components
    /// that tie in magnitude (so the permutation's tie rule decides), that
    /// are ±0 or too small for `f32`; segments that end before, at and past
    /// the triangle; triangles hit inside, on an edge and missed.
    /// (Shearing by the `f32` direction in `meets` fails it.)
    #[test]
    fn meets_is_the_walks_lane_test() {
        let mut next = uniform(0x005e_ed0f_3e75_u64);
        let (mut hits, mut misses) = (0u32, 0u32);
        for case in 0..200_000u32 {
            let pick = |x: f64| -> f64 {
                match case % 11 {
                    // Ties in magnitude, and components at or below f32's reach.
                    0 => 0.5f64.copysign(x - 0.5),
                    1 => 0.0,
                    2 => -0.0,
                    3 => 1e-50 * (x - 0.5),
                    _ => x - 0.5,
                }
            };
            let raw = DVec3::new(pick(next()), next() - 0.5, pick(next()));
            if raw.length() == 0.0 {
                continue;
            }
            // Directions as camera and shadow rays make them: normalised in
            // f64, a few with a component tied to another's magnitude.
            let mut dir = raw.normalize();
            if case % 13 == 0 && dir.x != 0.0 {
                dir.y = dir.x.abs().copysign(dir.y);
            }
            let scale = 10f64.powf(next() * 6.0 - 3.0);
            let c = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * scale * 4.0;
            let tri = triangle_around(c, scale, &mut next);
            let v = tri.map(to_f64);
            // A target inside, on an edge, or beside the triangle.
            let (a, b) = (next(), next());
            let target = match case % 3 {
                0 => v[0] + (v[1] - v[0]) * a * 0.5 + (v[2] - v[0]) * b * 0.5,
                1 => v[0] + (v[1] - v[0]) * a,
                _ => v[0] + (v[1] - v[0]) * (1.0 + a) + (v[2] - v[0]) * b,
            };
            let dist = scale * 10f64.powf(next() * 4.0 - 2.0);
            let t_max = match case % 4 {
                0 => f64::INFINITY,
                1 => dist,
                2 => dist * 0.5,
                _ => dist * 2.0,
            };
            let ray = Ray64 {
                origin: target - dir * dist,
                dir,
                t_min: 0.0,
                t_max,
            };
            // The constants as an any-hit walk forms them (its segment
            // filter's, over a bound of its own), and the triangle in any
            // lane of a pack with others beside it.
            let bound = [ray.t_max, dist * 8.0, f64::INFINITY][(case % 3) as usize];
            let pre = RayPrecomp::of::<true>(&ray, &WalkRay::new(&ray, bound));
            let lane = (case / 3 % 4) as usize;
            let mut pack = TriPack::EMPTY;
            pack.lanes = 4;
            for l in 0..4 {
                let shift = to_f32(DVec3::splat(scale * f64::from(l as u8 + 1)));
                pack.set(l, tri.map(|v| v + shift));
            }
            pack.set(lane, tri);
            let want = intersect_lane(&pre, pre.shear64(), &pack, lane, ray.t_min, ray.t_max);
            let got = meets(&ray, &tri);
            assert_eq!(
                got.map(|h| (h.t64.to_bits(), h.t.to_bits(), h.b.map(f32::to_bits))),
                want.map(|h| (h.t64.to_bits(), h.t.to_bits(), h.b.map(f32::to_bits))),
                "case {case}: {tri:?} {ray:?}"
            );
            if got.is_some() {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(
            hits > 20_000 && misses > 20_000,
            "{hits} hits, {misses} misses"
        );
    }

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
        let h = hit_of(
            &RayPrecomp::new(&Ray64::from(&r), f64::INFINITY),
            &tri,
            0.0,
            f64::INFINITY,
        )
        .unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!((h.b[1] - 0.25).abs() < 1e-6 && (h.b[2] - 0.25).abs() < 1e-6);
        let r = ray(Vec3::new(0.75, 0.75, 1.0), -Vec3::Z);
        assert!(
            hit_of(
                &RayPrecomp::new(&Ray64::from(&r), f64::INFINITY),
                &tri,
                0.0,
                f64::INFINITY
            )
            .is_none()
        );
        // Behind the origin: no hit.
        let r = ray(Vec3::new(0.25, 0.25, 1.0), Vec3::Z);
        assert!(
            hit_of(
                &RayPrecomp::new(&Ray64::from(&r), f64::INFINITY),
                &tri,
                0.0,
                f64::INFINITY
            )
            .is_none()
        );
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
            let pre = RayPrecomp::new(&Ray64::from(&r), f64::INFINITY);
            let hit = hit_of(&pre, &t1, 0.0, f64::INFINITY).is_some()
                || hit_of(&pre, &t2, 0.0, f64::INFINITY).is_some();
            assert!(hit, "ray {k} slipped through the shared edge");
        }
    }

    /// The filter never drops a triangle the `f64` test accepts: rays
    /// through points near edges and vertices of triangles at every scale
    /// and distance, with `f64` directions whose `f32` rounding differs.
    #[test]
    fn the_filter_keeps_every_hit() {
        let mut next = uniform(0x1234_5678_9abc_def0_u64);
        let mut kept = 0u32;
        for case in 0..200_000u32 {
            let scale = 10f64.powf(next() * 9.0 - 3.0);
            let offset = 10f64.powf(next() * 6.0) * (next() - 0.5);
            let c = DVec3::new(offset, offset * 0.3, -offset * 0.7);
            let tri = triangle_around(c, scale, &mut next);
            // A target on an edge or at a vertex, nudged by a few ulps.
            let v = tri.map(to_f64);
            let (i, j) = ((case % 3) as usize, ((case + 1) % 3) as usize);
            let s = next();
            let target = v[i]
                + (v[j] - v[i]) * if case % 7 == 0 { 0.0 } else { s }
                + DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * scale * 1e-7;
            let dist = 10f64.powf(next() * 8.0 - 4.0) * scale;
            let dir = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            let origin = target - dir * dist;
            let ray = Ray64 {
                origin: if case % 2 == 0 {
                    rendiff_core::math::to_f64(to_f32(origin))
                } else {
                    origin
                },
                dir,
                t_min: 0.0,
                t_max: f64::INFINITY,
            };
            let pre = RayPrecomp::new(&ray, dist * 4.0 + scale * 4.0);
            let mut pack = TriPack::EMPTY;
            pack.lanes = 1;
            pack.set(0, tri);
            let accepted = hit_of(&pre, &tri, 0.0, f64::INFINITY).is_some();
            let lanes = candidates::<false>(&pre, &pack);
            assert!(
                !accepted || lanes & 1 == 1,
                "case {case}: the filter dropped a hit: {tri:?} {ray:?}"
            );
            kept += lanes & 1;
        }
        assert!(kept > 0);
    }

    /// The segment filter (`candidates::<true>`) never drops a triangle
    /// the `f64` test accepts within `[0, t_max]`, where its distance
    /// bounds are tightest: `t_max` within a few ulps of the hit either
    /// way, triangles square to the ray, and triangles whose three corners
    /// share one `f32` coordinate on the ray's dominant axis (every corner
    /// at the hit's distance along it, so only the bounds' margins keep
    /// them), with targets inside, on edges and next to corners, and
    /// origins from 10⁻⁹ to 10⁴ of the triangle's size away on either side
    /// of it, in `f32` (no drift) or off it. It also drops every triangle
    /// that lies clearly behind the origin or past `t_max`.
    ///
    /// It holds the drift term of the far bound (it fails without it). The
    /// relative margins (10⁻⁶, γ₁₆) guard roundings that random cases do
    /// not reach: the bound is rounded up to an `f32` and the corners' `Z`
    /// to the nearest, so they matter only where a corner's exact `Z` lies
    /// within about 10⁻¹⁵ above an `f32` step; and the near bound's drift
    /// term guards the `f32` rounding of the subtraction alone, since the
    /// `f32` origin's own coordinate on the axis cannot pass an `f32`
    /// corner coordinate that the `f64` origin has not.
    #[test]
    fn the_segment_filter_keeps_every_hit_on_the_segment() {
        let mut next = uniform(0x0bad_cafe_f00d_d00d_u64);
        let one_pack = |tri: [Vec3; 3]| {
            let mut pack = TriPack::EMPTY;
            pack.lanes = 1;
            pack.set(0, tri);
            pack
        };
        let (mut hits, mut at_the_end, mut dropped) = (0u32, 0u32, 0u32);
        for case in 0..300_000u32 {
            let scale = 10f64.powf(next() * 8.0 - 3.0);
            let offset = 10f64.powf(next() * 6.0) * (next() - 0.5);
            let c = DVec3::new(offset, -offset * 0.6, offset * 0.2);
            let dir = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            let kz = dir.abs().max_position();
            let tri = if case % 3 == 2 {
                // Square to the dominant axis: one shared f32 coordinate.
                let z = to_f32(c)[kz];
                let mut corner = || {
                    let mut p =
                        to_f32(c + DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * scale);
                    p[kz] = z;
                    p
                };
                [corner(), corner(), corner()]
            } else {
                // Square to the ray, up to a tilt that is zero in half the cases.
                let a = dir.any_orthonormal_vector();
                let b = dir.cross(a);
                let tilt = if case % 3 == 0 {
                    0.0
                } else {
                    10f64.powf(-next() * 7.0)
                };
                let mut corner = || {
                    let (r, s) = (next() - 0.5, next() - 0.5);
                    to_f32(c + (a * r + b * s + dir * (tilt * (r + s))) * scale)
                };
                [corner(), corner(), corner()]
            };
            let v = tri.map(to_f64);
            // A target inside, on an edge, or within 10⁻⁶ of a corner.
            let (w0, w1) = (next(), next());
            let w = match case % 5 {
                0 => [w0, 1.0 - w0, 0.0],
                1 => [1.0, w0 * 1e-6, w1 * 1e-6],
                _ => [w0, w1, next()],
            };
            let target = (v[0] * w[0] + v[1] * w[1] + v[2] * w[2]) / (w[0] + w[1] + w[2]);
            // From either side: a negative distance puts the origin past
            // the triangle (which then lies behind the ray).
            let side = if case % 4 == 1 { -1.0 } else { 1.0 };
            let dist = 10f64.powf(next() * 13.0 - 9.0) * scale * side;
            let origin = target - dir * dist;
            let origin = if case % 2 == 0 {
                to_f64(to_f32(origin))
            } else {
                origin
            };
            let probe = Ray64 {
                origin,
                dir,
                t_min: 0.0,
                t_max: f64::INFINITY,
            };
            let bound = dist.abs() * 4.0 + scale * 4.0;
            let pack = one_pack(tri);
            // Where the corners lie along the dominant axis, in units of t,
            // and a margin far above every rounding the bounds cover.
            let along = v.map(|p| (p[kz] - origin[kz]) / dir[kz]);
            let (near, far) = (
                along.iter().copied().fold(f64::INFINITY, f64::min),
                along.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            );
            // (The bounds carry the drift of the origin's largest
            // coordinate, on any axis.)
            let largest = v.iter().fold(origin.abs().max_element(), |m, p| {
                m.max(p.abs().max_element())
            });
            let clear = 1e-4 * largest / dir[kz].abs();
            if far < -clear {
                let pre = RayPrecomp::new(
                    &Ray64 {
                        t_max: 1.0,
                        ..probe
                    },
                    bound,
                );
                assert_eq!(
                    candidates::<true>(&pre, &pack),
                    0,
                    "case {case}: kept a triangle behind the origin"
                );
                dropped += 1;
            }
            let Some(h) = hit_of(&RayPrecomp::new(&probe, bound), &tri, 0.0, f64::INFINITY) else {
                continue;
            };
            // The segment ends a few ulps of t either side of the hit.
            let ulps = f64::from(case % 9) - 4.0;
            let t_max = h.t64 * (1.0 + ulps * f64::EPSILON);
            let ray = Ray64 { t_max, ..probe };
            let pre = RayPrecomp::new(&ray, bound);
            let accepted = hit_of(&pre, &tri, 0.0, t_max).is_some();
            assert!(
                !accepted || candidates::<true>(&pre, &pack) & 1 == 1,
                "case {case}: the segment filter dropped a hit: {tri:?} {ray:?}"
            );
            hits += u32::from(accepted);
            at_the_end += u32::from(accepted && (near - h.t64).abs() <= 1e-6 * h.t64);
            // A segment that ends clearly before the triangle drops it.
            let short = Ray64 {
                t_max: (near - clear) * 0.5,
                ..probe
            };
            if short.t_max > 0.0 {
                let pre = RayPrecomp::new(&short, bound);
                assert_eq!(
                    candidates::<true>(&pre, &pack),
                    0,
                    "case {case}: kept a triangle past t_max"
                );
                dropped += 1;
            }
        }
        assert!(
            hits > 50_000 && at_the_end > 10_000 && dropped > 10_000,
            "{hits} hits, {at_the_end} at the segment's end, {dropped} dropped"
        );
    }

    /// [`candidates2`] gives each ray exactly its own [`candidates`]
    /// mask, with and without the segment bounds: pairs of nearby rays
    /// (the same axis permutation) against packs of one to four
    /// triangles at every scale, aimed at the first triangle's edges and
    /// corners so both verdicts occur.
    #[test]
    fn the_paired_filter_is_each_rays_own() {
        let mut next = uniform(0x005e_ed0f_9a12_u64);
        let (mut pairs, mut kept, mut dropped) = (0u32, 0u32, 0u32);
        for case in 0..40_000u32 {
            let scale = 10f64.powf(next() * 8.0 - 3.0);
            let offset = 10f64.powf(next() * 5.0) * (next() - 0.5);
            let c = DVec3::new(offset, -offset * 0.4, offset * 0.9);
            let mut pack = TriPack::EMPTY;
            pack.lanes = 1 + case % 4;
            let mut tris = Vec::new();
            for lane in 0..pack.lanes as usize {
                let mut p =
                    || to_f32(c + DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * scale);
                let tri = [p(), p(), p()];
                pack.set(lane, tri);
                tris.push(tri);
            }
            let v = tris[0].map(to_f64);
            let target = v[0] + (v[1] - v[0]) * next() + (v[2] - v[0]) * (next() * 0.1);
            let dir = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
            let dist = 10f64.powf(next() * 6.0 - 3.0) * scale;
            let ray = |d: DVec3, o: DVec3, t_max: f64| Ray64 {
                origin: o,
                dir: d,
                t_min: 0.0,
                t_max,
            };
            let a = ray(dir, target - dir * dist, dist * (0.5 + next()));
            let d2 =
                (dir + DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 0.05).normalize();
            let o2 = a.origin + DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * scale * 0.1;
            let b = ray(
                d2,
                o2,
                if case % 5 == 0 {
                    f64::INFINITY
                } else {
                    dist * 2.0
                },
            );
            let bound = dist * 4.0 + scale * 4.0;
            let (pa, pb) = (RayPrecomp::new(&a, bound), RayPrecomp::new(&b, bound));
            let (qa, qb) = (
                RayPrecomp::of::<false>(&a, &WalkRay::new(&a, bound)),
                RayPrecomp::of::<false>(&b, &WalkRay::new(&b, bound)),
            );
            if pa.k != pb.k {
                continue;
            }
            pairs += 1;
            let want = (
                candidates::<true>(&pa, &pack),
                candidates::<true>(&pb, &pack),
            );
            assert_eq!(candidates2::<true>(&pa, &pb, &pack), want, "case {case}");
            let want_open = (
                candidates::<false>(&qa, &pack),
                candidates::<false>(&qb, &pack),
            );
            assert_eq!(
                candidates2::<false>(&qa, &qb, &pack),
                want_open,
                "case {case}"
            );
            kept += (want.0 & 1) + (want.1 & 1);
            dropped += u32::from(want.0 & 1 == 0) + u32::from(want.1 & 1 == 0);
        }
        assert!(
            pairs > 20_000 && kept > 1_000 && dropped > 1_000,
            "{pairs} pairs, {kept} kept, {dropped} dropped"
        );
    }

    #[test]
    fn plane_barycentrics_match() {
        use glam::DVec3;
        let v = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let (b, t) =
            rendiff_core::math::plane_barycentrics(DVec3::new(0.2, 0.3, 2.0), -DVec3::Z, v)
                .unwrap();
        assert!(
            (b[0] - 0.5).abs() < 1e-15 && (b[1] - 0.2).abs() < 1e-15 && (b[2] - 0.3).abs() < 1e-15
        );
        assert!((t - 2.0).abs() < 1e-15);
    }
}
