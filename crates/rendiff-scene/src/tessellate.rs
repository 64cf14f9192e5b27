//! Scene → `TriScene`: every object becomes triangles in world space.
//!
//! * spheres: a latitude-longitude grid (poles on the object's y axis, as
//!   POV-Ray's spherical map has them), `N` segments around and `N/2` rings,
//!   exact vertex normals and the spherical uv map at the vertices;
//! * superellipsoids: the same grid of directions (poles on z, POV-Ray's
//!   north-south axis) pushed radially onto the surface, with the surface's
//!   gradient as vertex normal;
//! * boxes: 12 flat triangles on 8 shared corners;
//! * polygons and OBJ faces: the constrained Delaunay triangulation made at
//!   load time.
//!
//! Curved shapes get the smallest segment count whose chord error, measured
//! on the tessellation itself, is within `tessellation_error` pixels at the
//! shape's nearest view depth (DESIGN.md §4), or the object's fixed
//! `tessellation`. Closed shapes share their vertices (no T-junctions), and
//! every object is checked for closedness after welding equal positions;
//! a closed object with negative signed volume has its winding reversed so
//! its counter-clockwise side faces out (DESIGN.md §7).

use crate::scene::{LoadError, MAX_COORDINATE, Object, Scene, Shape};
use rendiff_core::analytic::{AnalyticKind, Placed, superellipsoid_f, superellipsoid_gradient};
use rendiff_core::camera::Camera;
use rendiff_core::math::{Aabb, DMat3, DVec3, Vec2, Vec3, to_f32, to_f64};
use rendiff_core::tri_scene::{AnalyticShape, NO_INDEX, ObjectInfo, TriScene};

/// Samples per triangle side when measuring a superellipsoid's chord error
/// (28 points per triangle).
const SUPERELLIPSOID_SAMPLES: u32 = 6;

/// The sampled maximum of the chord error underestimates the continuous
/// one: on the exponents of the tests (<1,1>, <0.3,0.6>, <2,0.5>, <1,2.5>,
/// <0.25,0.25>), sampling with 16 steps per side (153 points per triangle)
/// and 20 000 radial rays found at most 3.3 % more than 6 steps per side.
/// Segments are chosen for 0.9 × the tolerance, three times that
/// underestimate; the tessellation test checks the ratio stays below 1/0.9.
const SUPERELLIPSOID_MARGIN: f64 = 0.9;

/// Largest segment count (DESIGN.md §4).
pub(crate) const MAX_SEGMENTS: u32 = 4096;

/// Overrides of the scene's image settings (the command line's `--size`
/// and `--samples`); tessellation is computed at the final size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TessOptions {
    /// Final image size.
    pub size: Option<(u32, u32)>,
    /// Final samples per pixel side.
    pub samples: Option<u32>,
    /// Memory budget in bytes (`None`: [`DEFAULT_MEMORY_BUDGET`]).
    pub memory_budget: Option<u64>,
}

/// Bytes a render holds per triangle, at most: the triangle scene (60 B
/// measured on meshes), its BVH (58 B), and the rasterizer's transformed
/// vertices and setup records or the BVH build's references (≈ 70 B);
/// `tests/it/resources.rs` checks the measured parts against it.
pub const BYTES_PER_TRIANGLE: u64 = 200;

/// Bytes per sample: the frame's colour, depth, id and flags (24 B) and
/// the rasterizer's depth key, id and barycentrics (20 B), rounded up.
pub const BYTES_PER_SAMPLE: u64 = 48;

/// Bytes per pixel beyond the samples: the resolved colour (12 B) and the
/// PNG encoder's buffers (≤ 8 B), rounded up.
pub(crate) const BYTES_PER_PIXEL: u64 = 24;

pub use rendiff_core::budget::DEFAULT_MEMORY_BUDGET;

/// The memory a scene's triangles and frames will need, counted before
/// anything large is allocated, into the request's budget.
struct Budget<'b> {
    shared: &'b rendiff_core::budget::Budget,
    samples: u64,
    triangles: u64,
}

impl Budget<'_> {
    /// Reserves `bytes` for the frames of the image.
    fn image(&mut self, bytes: u64, scene: &Scene, what: &str) -> Result<(), LoadError> {
        self.shared
            .reserve(bytes, || what.to_string())
            .map_err(|e| LoadError::Scene {
                path: scene.path.clone(),
                message: format!("{e} (lower the image size or the samples)"),
            })
    }

    /// Adds `tris` triangles, or says why they do not fit.
    fn add(&mut self, tris: u64, scene: &Scene, what: &str) -> Result<(), LoadError> {
        self.triangles = self.triangles.saturating_add(tris);
        let (triangles, samples) = (self.triangles, self.samples);
        self.shared
            .reserve(tris.saturating_mul(BYTES_PER_TRIANGLE), || {
                format!(
                    "{what} ({triangles} triangles in all at {BYTES_PER_TRIANGLE} B, beside {samples} samples at {BYTES_PER_SAMPLE} B)"
                )
            })
            .map_err(|e| LoadError::Scene {
                path: scene.path.clone(),
                message: format!("{e} (lower the tessellation, the image size or the samples)"),
            })
    }
}

/// One object's geometry in object space before it joins the scene.
#[derive(Default)]
struct Piece {
    positions: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
    normals: Vec<DVec3>,
    tri_normals: Vec<[u32; 3]>,
    uvs: Vec<Vec2>,
    tri_uvs: Vec<[u32; 3]>,
    smooth: bool,
    segments: Option<u32>,
    /// Per triangle, its material (a mesh with `material = "obj"`); `None`:
    /// the object's material for all.
    tri_materials: Option<std::sync::Arc<[u16]>>,
}

/// Largest singular value of a 3×3 matrix (power iteration on MᵀM).
fn max_stretch(m: DMat3) -> f64 {
    let a = m.transpose() * m;
    let mut v = DVec3::new(0.577, 0.577, 0.578);
    let mut lambda = 0.0;
    for _ in 0..64 {
        let w = a * v;
        let len = w.length();
        if len == 0.0 {
            return 0.0;
        }
        lambda = len;
        v = w / len;
    }
    lambda.sqrt()
}

/// Upper bound of the distance from a sphere of radius `r` to its
/// lat-long tessellation with `n` segments: over the faces of one column,
/// `r − distance(centre, face plane)`.
#[must_use]
pub(crate) fn sphere_chord_error(r: f64, n: u32) -> f64 {
    let (verts, tris) = sphere_grid(n);
    let mut worst: f64 = 0.0;
    for t in tris
        .iter()
        .filter(|t| t.iter().all(|&i| verts[i as usize].1 <= 1))
    {
        let [a, b, c] = t.map(|i| verts[i as usize].0 * r);
        let nrm = (b - a).cross(c - a);
        if nrm.length() == 0.0 {
            continue;
        }
        let d = a.dot(nrm.normalize()).abs();
        worst = worst.max(r - d);
    }
    worst
}

/// Unit-sphere lat-long grid: (direction, column index) per vertex, and
/// triangles wound counter-clockwise seen from outside. Poles on +y / −y.
fn sphere_grid(n: u32) -> (Vec<(DVec3, u32)>, Vec<[u32; 3]>) {
    let n = n.max(3);
    let rings = (n / 2).max(2);
    let mut verts = vec![(DVec3::Y, 0)];
    for i in 1..rings {
        let theta = std::f64::consts::PI * f64::from(i) / f64::from(rings);
        for j in 0..n {
            let phi = std::f64::consts::TAU * f64::from(j) / f64::from(n);
            verts.push((
                DVec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                ),
                j,
            ));
        }
    }
    verts.push((-DVec3::Y, 0));
    let south = u32::try_from(verts.len() - 1).unwrap_or(u32::MAX);
    let ring = |i: u32, j: u32| 1 + (i - 1) * n + (j % n);
    let mut tris = Vec::new();
    for j in 0..n {
        // Seen from outside (+y above), azimuth grows from +x toward +z,
        // which is clockwise seen from above: wind (pole, j+1, j).
        tris.push([0, ring(1, j + 1), ring(1, j)]);
    }
    for i in 1..rings - 1 {
        for j in 0..n {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            tris.push([a, b, d]);
            tris.push([a, d, c]);
        }
    }
    for j in 0..n {
        tris.push([south, ring(rings - 1, j), ring(rings - 1, j + 1)]);
    }
    (verts, tris)
}

fn sphere_piece(center: DVec3, radius: f64, n: u32) -> Piece {
    let (verts, tris) = sphere_grid(n);
    let n = n.max(3);
    let rings = (n / 2).max(2);
    let mut p = Piece {
        smooth: true,
        segments: Some(n),
        ..Piece::default()
    };
    for (d, _) in &verts {
        p.positions.push(center + *d * radius);
        p.normals.push(*d);
    }
    // uv grid with a seam column: (rings + 1) × (n + 1); the pole corners
    // take the middle of their triangle's column.
    let uv_index = |i: u32, j: u32| i * (n + 1) + j;
    for i in 0..=rings {
        for j in 0..=n {
            let u = f64::from(j) / f64::from(n);
            let v = 1.0 - f64::from(i) / f64::from(rings);
            #[expect(clippy::cast_possible_truncation, reason = "uv in [0, 1]")]
            p.uvs.push(Vec2::new(u as f32, v as f32));
        }
    }
    let pole_uv_base = u32::try_from(p.uvs.len()).unwrap_or(u32::MAX);
    for j in 0..n {
        let u = (f64::from(j) + 0.5) / f64::from(n);
        #[expect(clippy::cast_possible_truncation, reason = "uv in [0, 1]")]
        {
            p.uvs.push(Vec2::new(u as f32, 1.0));
            p.uvs.push(Vec2::new(u as f32, 0.0));
        }
    }
    let south = u32::try_from(verts.len() - 1).unwrap_or(u32::MAX);
    let col_of = |v: u32| verts[v as usize].1;
    let ring_of = |v: u32| {
        if v == 0 {
            0
        } else if v == south {
            rings
        } else {
            1 + (v - 1) / n
        }
    };
    for t in tris {
        // The column of the triangle is its smallest column index on a
        // ring, except across the seam (columns n−1 and 0): there the
        // column-0 vertices take the seam copy u = 1.
        let ring_cols: Vec<u32> = t
            .iter()
            .filter(|&&v| v != 0 && v != south)
            .map(|&v| col_of(v))
            .collect();
        let spans_seam = ring_cols.contains(&0) && ring_cols.contains(&(n - 1));
        let first_col = ring_cols
            .iter()
            .copied()
            .filter(|&c| !(spans_seam && c == 0))
            .min()
            .unwrap_or(0);
        let uvt = t.map(|v| {
            if v == 0 {
                pole_uv_base + 2 * first_col
            } else if v == south {
                pole_uv_base + 2 * first_col + 1
            } else {
                let c = col_of(v);
                let c = if spans_seam && c == 0 { n } else { c };
                uv_index(ring_of(v), c)
            }
        });
        p.tris.push(t);
        p.tri_normals.push(t);
        p.tri_uvs.push(uvt);
    }
    p
}

/// The surface point along direction `d`. F is evaluated on `d` scaled to
/// a largest component of 1 (F is homogeneous of degree 2/n, so
/// `F(d) = m^(2/n)·F(d/m)`): there F ≥ 1, where on the unit direction the
/// powers 2/e and 2/n of components below 1 underflow together for small
/// exponents (e = 0.001: 0.7^2000 = 0) and F = 0 put the point at
/// infinity.
fn superellipsoid_point(e: f64, n: f64, d: DVec3) -> DVec3 {
    let m = d.abs().max_element();
    if m == 0.0 || !m.is_finite() {
        return DVec3::ZERO;
    }
    let u = d / m;
    u * superellipsoid_f(u, e, n).powf(-n / 2.0)
}

/// Unit gradient of F at `p` (`None` where it is not finite: a cusp).
fn superellipsoid_normal(e: f64, n: f64, p: DVec3) -> Option<DVec3> {
    let g = superellipsoid_gradient(p, e, n);
    // 0·∞ and ∞/∞ give NaN; a zero component times a finite factor is fine.
    let g = DVec3::new(
        if p.x == 0.0 { 0.0 } else { g.x },
        if p.y == 0.0 { 0.0 } else { g.y },
        if p.z == 0.0 { 0.0 } else { g.z },
    );
    g.is_finite().then(|| g.try_normalize()).flatten()
}

/// `sign(v)·|v|^p`.
fn signed_pow(v: f64, p: f64) -> f64 {
    v.abs().powf(p).copysign(v)
}

/// Points of a superellipsoid on the sphere grid's topology, poles on ±z
/// (POV-Ray's north-south axis), by the classic superquadric
/// parameterisation: latitude η, longitude ω,
/// `x = cos(η)^n cos(ω)^e, y = cos(η)^n sin(ω)^e, z = sin(η)^n` (signed
/// powers). It places samples by curvature: few on flat faces, many at the
/// rounded edges of boxy shapes and at the cusps of pinched ones (e or
/// n > 2), where a uniform grid of directions would need far more segments.
fn superellipsoid_grid(e: f64, n: f64, segments: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let (verts, tris) = sphere_grid(segments);
    let pts = verts
        .iter()
        .map(|(d, _)| {
            // The sphere grid's direction (x, y, z) with the pole on y; on
            // the superellipsoid the pole is z: (x, y, z) -> (x, -z, y) is a
            // rotation, so the winding stays outward.
            let q = DVec3::new(d.x, -d.z, d.y);
            let eta = q.z.clamp(-1.0, 1.0).asin();
            let omega = q.y.atan2(q.x);
            let (ce, se) = (eta.cos(), eta.sin());
            let r = signed_pow(ce, n);
            DVec3::new(
                r * signed_pow(omega.cos(), e),
                r * signed_pow(omega.sin(), e),
                signed_pow(se, n),
            )
        })
        .collect();
    (pts, tris)
}

/// Measured chord error of a superellipsoid tessellation: for every
/// triangle, the radial distance between the surface and the triangle on a
/// barycentric grid of `samples_per_side` steps, maximised.
#[must_use]
pub fn superellipsoid_chord_error(e: f64, n: f64, segments: u32, samples_per_side: u32) -> f64 {
    use rayon::prelude::*;
    let (pts, tris) = superellipsoid_grid(e, n, segments);
    let k = f64::from(samples_per_side.max(2));
    tris.par_iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| pts[i as usize]);
            let mut worst: f64 = 0.0;
            for i in 0..=samples_per_side {
                for j in 0..=(samples_per_side - i) {
                    let (u, v) = (f64::from(i) / k, f64::from(j) / k);
                    let m = a + (b - a) * u + (c - a) * v;
                    let len = m.length();
                    if len == 0.0 {
                        continue;
                    }
                    let s = superellipsoid_point(e, n, m / len);
                    worst = worst.max((s.length() - len).abs());
                }
            }
            worst
        })
        .reduce(|| 0.0, f64::max)
}

fn superellipsoid_piece(e: f64, n: f64, segments: u32) -> Piece {
    let (pts, tris) = superellipsoid_grid(e, n, segments);
    let mut p = Piece {
        smooth: true,
        segments: Some(segments.max(3)),
        ..Piece::default()
    };
    p.positions = pts;
    // Gradient normals; at cusps (e or n > 2 on an axis) the area-weighted
    // normal of the vertex's triangles instead.
    let mut fallback = vec![DVec3::ZERO; p.positions.len()];
    for t in &tris {
        let [a, b, c] = t.map(|i| p.positions[i as usize]);
        let w = (b - a).cross(c - a);
        for &i in t {
            fallback[i as usize] += w;
        }
    }
    p.normals = p
        .positions
        .iter()
        .zip(&fallback)
        .map(|(q, f)| superellipsoid_normal(e, n, *q).unwrap_or_else(|| f.normalize_or_zero()))
        .collect();
    p.tri_normals.clone_from(&tris);
    p.tri_uvs = vec![[NO_INDEX; 3]; tris.len()];
    p.tris = tris;
    p
}

fn box_piece(lo: DVec3, hi: DVec3) -> Piece {
    let corner = |i: u32| {
        DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let mut p = Piece {
        positions: (0..8).map(corner).collect(),
        ..Piece::default()
    };
    let center = (lo + hi) / 2.0;
    // Each face as a quad of corner indices; orient each triangle outward.
    let faces: [[u32; 4]; 6] = [
        [0, 2, 6, 4], // -x
        [1, 3, 7, 5], // +x
        [0, 1, 5, 4], // -y
        [2, 3, 7, 6], // +y
        [0, 1, 3, 2], // -z
        [4, 5, 7, 6], // +z
    ];
    for f in faces {
        for t in [[f[0], f[1], f[2]], [f[0], f[2], f[3]]] {
            let [a, b, c] = t.map(|i| p.positions[i as usize]);
            let out = (b - a).cross(c - a).dot((a + b + c) / 3.0 - center) > 0.0;
            p.tris.push(if out { t } else { [t[0], t[2], t[1]] });
        }
    }
    p.tri_normals = vec![[NO_INDEX; 3]; 12];
    p.tri_uvs = vec![[NO_INDEX; 3]; 12];
    p
}

fn mesh_piece(data: &crate::scene::MeshData, smooth: bool) -> Piece {
    let mut p = Piece {
        smooth,
        ..Piece::default()
    };
    p.positions = data.positions.iter().map(|v| to_f64(*v)).collect();
    p.tris = data.triangles.iter().map(|t| t.v).collect();
    p.uvs.clone_from(&data.uvs);
    p.tri_uvs = data
        .triangles
        .iter()
        .map(|t| t.t.unwrap_or([NO_INDEX; 3]))
        .collect();
    // File normals where a face has them (smooth only); the others get
    // computed normals after welding (marked with NO_INDEX - 1 for now).
    if smooth {
        p.normals = data.normals.iter().map(|v| to_f64(*v)).collect();
        p.tri_normals = data
            .triangles
            .iter()
            .map(|t| t.n.unwrap_or([COMPUTE_NORMAL; 3]))
            .collect();
    } else {
        p.tri_normals = vec![[NO_INDEX; 3]; p.tris.len()];
    }
    p
}

/// Marker: this corner's normal is computed (area-weighted, welded).
const COMPUTE_NORMAL: u32 = NO_INDEX - 1;

fn polygon_piece(poly: &crate::scene::PolygonShape) -> Piece {
    let mut p = Piece::default();
    p.positions.clone_from(&poly.points);
    p.tris.clone_from(&poly.triangles);
    p.tri_normals = vec![[NO_INDEX; 3]; p.tris.len()];
    if let Some(uv) = &poly.uv {
        #[expect(clippy::cast_possible_truncation, reason = "uv rounded to f32 once")]
        {
            p.uvs = uv
                .iter()
                .map(|q| Vec2::new(q[0] as f32, q[1] as f32))
                .collect();
        }
        p.tri_uvs.clone_from(&p.tris);
    } else {
        p.tri_uvs = vec![[NO_INDEX; 3]; p.tris.len()];
    }
    p
}

/// The most segments a superellipsoid's search measures: a grid of 512
/// segments (262 000 triangles) meets the default half-pixel error of
/// every exponent pair that converges (<0.1, 4> at 64×48 needs 68; the
/// count grows as the square root of the image size, so about 520 at
/// 3840×2160 only for that pinched shape).
pub(crate) const SUPERELLIPSOID_MAX_SEGMENTS: u32 = 512;

/// Triangles the superellipsoid searches of one scene may measure in all
/// (each at 28 samples, about 80 ns a sample on one core here, so about
/// 5 s of work at most): past it a search keeps the count it has (one
/// that meets the bound, if it found one), which costs minimality, never
/// the bound.
pub(crate) const SEARCH_WORK_TRIANGLES: u64 = 1 << 21;

/// Why a segment search stopped short of the error bound.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Shortfall {
    /// The error at the count chosen.
    error: f64,
    /// Why the search stopped.
    why: &'static str,
}

/// The search for a curved object's segment count.
struct Search<'w> {
    /// The largest count measured.
    max: u32,
    /// Triangles still to measure (shared by a scene's searches).
    work: &'w mut u64,
    /// Whether the error is measured on the grid (cost n² triangles), or
    /// known in closed form (free).
    measured: bool,
}

/// Segment count for a curved object: fixed, or the smallest meeting the
/// error bound (doubling, then bisection). A doubling that does not halve
/// the error twice in a row is no longer converging (the error then lies
/// in an edge or cusp the parameterisation does not resolve), and the
/// search stops there, as at `search.max` or the end of its work; it then
/// keeps the count with the least error and says why.
fn choose_segments(
    fixed: Option<u32>,
    tolerance: f64,
    search: &mut Search<'_>,
    error: impl Fn(u32) -> f64,
) -> (u32, Option<Shortfall>) {
    if let Some(n) = fixed {
        return (n, None);
    }
    let measured = search.measured;
    let work = |n: u32, w: &mut u64| -> bool {
        let cost = if measured {
            u64::from(n) * u64::from(n)
        } else {
            0
        };
        if cost > *w {
            return false;
        }
        *w -= cost;
        true
    };
    let mut hi = 8u32.min(search.max);
    let mut best = (hi, f64::INFINITY);
    let mut slow = 0;
    loop {
        if !work(hi, search.work) {
            return (
                best.0,
                Some(Shortfall {
                    error: best.1,
                    why: "the scene's segment searches reached their work bound",
                }),
            );
        }
        let e = error(hi);
        if e <= tolerance {
            break;
        }
        slow = if e > 0.5 * best.1 { slow + 1 } else { 0 };
        if e < best.1 {
            best = (hi, e);
        }
        if slow >= 2 {
            return (
                best.0,
                Some(Shortfall {
                    error: best.1,
                    why: "doubling the segments no longer halves the error",
                }),
            );
        }
        if hi >= search.max {
            return (
                best.0,
                Some(Shortfall {
                    error: best.1,
                    why: "the most segments the search measures",
                }),
            );
        }
        hi = (hi * 2).min(search.max);
    }
    let mut lo = (hi / 2).max(3);
    if work(lo, search.work) && error(lo) <= tolerance {
        return (lo, None);
    }
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if !work(mid, search.work) {
            break;
        }
        if error(mid) <= tolerance {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    (hi, None)
}

/// Tessellates a scene into the `TriScene` every backend renders.
///
/// # Errors
///
/// [`LoadError`] for a degenerate camera, coordinates that leave the
/// supported range after transforms, or a refracting material on an
/// object that is not closed.
pub fn tessellate(scene: &Scene, opts: &TessOptions) -> Result<TriScene, LoadError> {
    let budget =
        rendiff_core::budget::Budget::new(opts.memory_budget.unwrap_or(DEFAULT_MEMORY_BUDGET));
    tessellate_within(scene, opts, &budget)
}

/// [`tessellate`] counting into a request's budget (what its scene,
/// meshes and textures already hold is in it).
///
/// # Errors
///
/// As [`tessellate`].
pub fn tessellate_within(
    scene: &Scene,
    opts: &TessOptions,
    shared: &rendiff_core::budget::Budget,
) -> Result<TriScene, LoadError> {
    let camera = scene.build_camera(opts.size, opts.samples)?;
    let err_px = scene.render.tessellation_error;
    let mut out = TriScene {
        positions: Vec::new(),
        tris: Vec::new(),
        normals: Vec::new(),
        tri_normals: Vec::new(),
        uvs: Vec::new(),
        tri_uvs: Vec::new(),
        tri_material: Vec::new(),
        tri_object: Vec::new(),
        objects: Vec::new(),
        materials: scene.materials.clone(),
        lights: scene.lights.clone(),
        camera,
        background: scene.image.background,
        ambient_light: scene.render.ambient_light,
        max_depth: scene.render.max_depth,
        analytic: Vec::new(),
        bounds: Aabb::EMPTY,
        warnings: Vec::new(),
    };
    out.warnings.extend(scene.warnings.iter().cloned());
    if scene.lights.is_empty() {
        out.warnings.push(format!(
            "{}: no lights: only ambient and emission light the scene",
            scene.path.display()
        ));
    }
    let (w, h, n) = (
        u64::from(camera.width()),
        u64::from(camera.height()),
        u64::from(camera.samples()),
    );
    let samples = w * h * n * n;
    let mut budget = Budget {
        shared,
        samples,
        triangles: 0,
    };
    budget.image(
        samples
            .saturating_mul(BYTES_PER_SAMPLE)
            .saturating_add(w * h * BYTES_PER_PIXEL),
        scene,
        &format!(
            "a {w}x{h} image with {n}x{n} samples ({samples} samples at {BYTES_PER_SAMPLE} B)"
        ),
    )?;
    let mut work = SEARCH_WORK_TRIANGLES;
    for obj in &scene.objects {
        let piece = object_piece(
            scene,
            obj,
            &camera,
            err_px,
            &mut out.warnings,
            &mut budget,
            &mut work,
        )?;
        check_uv_precision(scene, obj, &piece, &mut out.warnings)?;
        append(scene, obj, piece, &mut out)?;
    }
    check_precision(scene, &mut out, &camera)?;
    // far: just beyond the farthest corner of the bounds (DESIGN.md §2).
    let far = match scene.camera.far {
        Some(f) => f,
        None => {
            let b = out.bounds;
            let deepest = b
                .corners()
                .iter()
                .map(|c| camera.view_depth(to_f64(*c)))
                .fold(f64::NEG_INFINITY, f64::max);
            (1.001 * deepest).max(2.0 * camera.near())
        }
    };
    out.camera = camera.with_far(far).map_err(|e| LoadError::Scene {
        path: scene.path.clone(),
        message: format!("camera: {e}"),
    })?;
    out.debug_check();
    Ok(out)
}

/// The smallest scene extent (the diagonal of its bounds) that the f32
/// ray-triangle test resolves: its edge functions and distances are
/// products of two and three coordinate differences, which must stay far
/// above f32's smallest normal number (1.2e-38): (1e-10)³ = 1e-30.
pub const MIN_EXTENT: f64 = 1e-10;

/// The least number of f32 steps (at the largest coordinate of the scene's
/// geometry) that the scene must span: below 2¹¹ the rounding of the
/// stored positions moves vertices by more than 1/2048 of the scene.
pub const MIN_EXTENT_STEPS: f64 = 2048.0;

/// The most an f32 rounding of a texture coordinate may move a lookup, in
/// texels, before a warning (1/64: a one-code difference at a full-contrast
/// texel edge) and before the object is refused (1/4: a quarter of a texel,
/// where the picture visibly shifts against POV-Ray's f64 lookups).
pub(crate) const UV_WARN_TEXELS: f64 = 1.0 / 64.0;
/// See [`UV_WARN_TEXELS`].
pub(crate) const UV_REFUSE_TEXELS: f64 = 0.25;

/// Half an f32 step at `x`.
fn half_ulp32(x: f64) -> f64 {
    #[expect(
        clippy::cast_possible_truncation,
        reason = "the f32 whose step is wanted"
    )]
    let f = x.abs() as f32;
    f64::from(f.next_up() - f) * 0.5
}

/// Refuses (or warns about) uvs so large that their f32 rounding moves an
/// image lookup by a sizeable part of a texel of the object's texture.
fn check_uv_precision(
    scene: &Scene,
    obj: &Object,
    piece: &Piece,
    warnings: &mut Vec<String>,
) -> Result<(), LoadError> {
    // The largest texture of the object's materials (and that material).
    let mut side = 0u32;
    let mut m = &scene.materials[usize::from(obj.material)];
    for k in object_materials(obj, piece) {
        let mat = &scene.materials[usize::from(k)];
        let mut s = 0u32;
        if let rendiff_core::shade::Pigment::Image(t) = &mat.pigment {
            s = s.max(t.width()).max(t.height());
        }
        if let Some(b) = &mat.bump {
            s = s.max(b.texture.width()).max(b.texture.height());
        }
        if s > side {
            (side, m) = (s, mat);
        }
    }
    if side == 0 {
        return Ok(());
    }
    let reach = piece
        .uvs
        .iter()
        .map(|uv| f64::from(uv.abs().max_element()))
        .fold(0.0f64, f64::max);
    let texels = half_ulp32(reach) * f64::from(side);
    let msg = format!(
        "{}: its texture coordinates reach {reach:.6e}, where f32 rounds them by {texels:.3} of a texel of the {side}-texel image of material \"{}\"",
        obj.label(),
        m.name
    );
    if texels > UV_REFUSE_TEXELS {
        return Err(LoadError::Key {
            path: scene.path.clone(),
            loc: obj.loc,
            key: format!("objects[{}]", obj.index),
            message: format!(
                "{msg}, more than {UV_REFUSE_TEXELS}; keep the uvs near 0 (subtract whole repeats)"
            ),
        });
    }
    if texels > UV_WARN_TEXELS {
        warnings.push(format!(
            "{msg}: lookups differ from exact ones by up to that much"
        ));
    }
    Ok(())
}

/// The least number of f32 steps an object must span at its own position
/// (refused below; warned below [`MIN_EXTENT_STEPS`]): below 2⁸ rounding
/// moves its vertices by more than 1/256 of its size, a 2.5-unit object
/// at 10⁶ (40 steps) is a pile of f32 grid points.
pub(crate) const MIN_OBJECT_STEPS: f64 = 256.0;

/// Rejects scenes whose geometry f32 arithmetic cannot represent
/// (DESIGN.md §8): too small an extent for the products the ray-triangle
/// test forms, or too small for its distance from the origin. (Too large
/// coordinates are refused where they are read and after transforms:
/// [`MAX_COORDINATE`].)
fn check_precision(
    scene: &Scene,
    out: &mut TriScene,
    camera: &rendiff_core::camera::Camera,
) -> Result<(), LoadError> {
    let b = out.bounds;
    if b.is_empty() {
        return Ok(());
    }
    let (lo, hi) = (to_f64(b.min), to_f64(b.max));
    let extent = (hi - lo).length();
    // The geometry's own precision: the eye is f64 everywhere (the camera
    // rays, the projection, the oracle), so its distance does not matter.
    let _ = camera;
    let largest = lo.abs().max(hi.abs()).max_element();
    let step = largest * f64::from(f32::EPSILON);
    let fail = |message: String| LoadError::Scene {
        path: scene.path.clone(),
        message,
    };
    if extent < MIN_EXTENT {
        return Err(fail(format!(
            "the scene spans {extent:.3e} units, below the {MIN_EXTENT:e} that f32 ray-triangle arithmetic resolves (its products of three coordinates would underflow); scale it up"
        )));
    }
    if extent < MIN_EXTENT_STEPS * step {
        return Err(fail(format!(
            "the scene spans {extent:.3e} units at {largest:.3e} from the origin: only {:.0} f32 steps, fewer than the {MIN_EXTENT_STEPS} needed to keep its vertices in place; move it nearer the origin",
            extent / step
        )));
    }
    // The same for every object at its own position: a small object far
    // out is crushed onto the f32 grid there, however large the rest of
    // the scene (a far marker widens the scene's bounds, not its steps).
    // Below MIN_OBJECT_STEPS it is refused; below MIN_EXTENT_STEPS warned.
    let mut warnings = Vec::new();
    for o in &out.objects {
        if o.bounds.is_empty() {
            continue;
        }
        let (lo, hi) = (to_f64(o.bounds.min), to_f64(o.bounds.max));
        let extent = (hi - lo).length();
        let largest = lo.abs().max(hi.abs()).max_element();
        let step = largest * f64::from(f32::EPSILON);
        if extent < MIN_OBJECT_STEPS * step {
            return Err(fail(format!(
                "{} spans {extent:.3e} units at {largest:.3e} from the origin: only {:.0} f32 steps, fewer than the {MIN_OBJECT_STEPS} needed to keep its shape (rounding moves its vertices by more than 1/{MIN_OBJECT_STEPS} of it); move it nearer the origin or enlarge it",
                o.label,
                extent / step
            )));
        }
        if extent < MIN_EXTENT_STEPS * step {
            warnings.push(format!(
                "{} spans only {:.0} f32 steps at {largest:.3e} from the origin (fewer than {MIN_EXTENT_STEPS}): its vertices are rounded by up to 1/{:.0} of its size, which may show in its shading",
                o.label,
                extent / step,
                extent / step
            ));
        }
    }
    out.warnings.extend(warnings);
    Ok(())
}

fn object_piece(
    scene: &Scene,
    obj: &Object,
    camera: &Camera,
    err_px: f64,
    warnings: &mut Vec<String>,
    budget: &mut Budget<'_>,
    work: &mut u64,
) -> Result<Piece, LoadError> {
    // A grid of n segments around and n/2 rings has n² triangles (less the
    // poles): counted before it is built.
    let grid = |n: u32, budget: &mut Budget<'_>| {
        budget.add(
            u64::from(n) * u64::from(n),
            scene,
            &format!("{} with {n} segments", obj.label()),
        )
    };
    let stretch = max_stretch(DMat3::from_mat4(obj.transform.matrix()));
    // World tolerance at the shape's nearest view depth, back in object space.
    let object_tolerance = |c_obj: DVec3, r_obj: f64| {
        let c = obj.transform.point(c_obj);
        let r = r_obj * stretch;
        let z = (camera.view_depth(c) - r).max(camera.near());
        err_px / camera.max_pixels_per_unit(z) / stretch
    };
    let label = obj.label();
    let mut shortfall = |short: Option<Shortfall>, n: u32, tol: f64| {
        if let Some(Shortfall { error, why }) = short {
            warnings.push(format!(
                "{label}: the tessellation error stays at {:.3} px (tessellation_error is {err_px} px) with {n} segments: {why}; set `tessellation` to choose the count",
                error / tol * err_px
            ));
        }
    };
    Ok(match &obj.shape {
        Shape::Sphere { center, radius } => {
            let tol = object_tolerance(*center, *radius);
            let mut search = Search {
                max: MAX_SEGMENTS,
                work,
                measured: false,
            };
            let (n, short) = choose_segments(obj.tessellation, tol, &mut search, |n| {
                sphere_chord_error(*radius, n)
            });
            shortfall(short, n, tol);
            grid(n, budget)?;
            sphere_piece(*center, *radius, n)
        }
        Shape::Superellipsoid { e, n: ns } => {
            let tol = SUPERELLIPSOID_MARGIN * object_tolerance(DVec3::ZERO, 3f64.sqrt());
            let mut search = Search {
                max: SUPERELLIPSOID_MAX_SEGMENTS,
                work,
                measured: true,
            };
            let (n, short) = choose_segments(obj.tessellation, tol, &mut search, |k| {
                superellipsoid_chord_error(*e, *ns, k, SUPERELLIPSOID_SAMPLES)
            });
            shortfall(short, n, tol);
            grid(n, budget)?;
            superellipsoid_piece(*e, *ns, n)
        }
        Shape::Box { min, max } => {
            budget.add(12, scene, &obj.label())?;
            box_piece(*min, *max)
        }
        Shape::Polygon(poly) => {
            let piece = polygon_piece(poly);
            budget.add(piece.tris.len() as u64, scene, &obj.label())?;
            piece
        }
        Shape::Mesh {
            data,
            smooth,
            face_materials,
        } => {
            budget.add(data.triangles.len() as u64, scene, &obj.label())?;
            let mut p = mesh_piece(data, *smooth);
            p.tri_materials.clone_from(face_materials);
            p
        }
    })
}

/// Exact-equality welding key of an f32 position.
fn weld_key(p: Vec3) -> [u32; 3] {
    // +0.0 and -0.0 are the same position.
    let canon = |v: f32| if v == 0.0 { 0u32 } else { v.to_bits() };
    [canon(p.x), canon(p.y), canon(p.z)]
}

/// A necessary condition of [`is_closed`] in one pass and no memory: in a
/// closed mesh reversing an edge maps the directed edges one to one onto
/// themselves, so a sum of a hash of each directed edge equals the same
/// sum over the reversed edges. An open mesh (a scan with holes, a
/// sheet) almost always fails it, and then is known open without the
/// buckets; a mesh that passes (every closed one, or an open one whose
/// sums happen to cancel) is checked in full. `dense.toml`'s two open
/// meshes (48 731 triangles): `is_closed` was 1.2 % of a whole
/// `rendiff render` (perf).
fn edges_balance(tris: &[[u32; 3]]) -> bool {
    // A multiply and a fold: the product alone is linear, and its sum
    // over a triangle's three edges less their reverses is zero whatever
    // the mesh (the key's difference is (a − b)(2³² − 1)); the fold (an
    // exclusive or of the halves) is not linear, so an unpaired edge leaves
    // a sum that is zero only by chance.
    let mix = |a: u32, b: u32| {
        let z = (u64::from(a) << 32 | u64::from(b)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z ^ (z >> 32)
    };
    let mut sum = 0u64;
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            sum = sum.wrapping_add(mix(a, b)).wrapping_sub(mix(b, a));
        }
    }
    sum == 0
}

/// `true` when every undirected edge is used by exactly two triangles, in
/// opposite directions, and no triangle repeats a vertex.
///
/// Equivalently: no directed edge occurs twice and every directed edge's
/// reverse occurs. The directed edges are bucketed by their first vertex
/// (a counting sort, linear in the triangles) and each bucket sorted, so a
/// reverse is a binary search in a small list: O(n log d) for maximum
/// vertex degree d, about 0.1 µs a triangle where a hash map of edges took
/// 0.5 µs (10 M triangles: 5.3 s before).
#[must_use]
pub fn is_closed(tris: &[[u32; 3]]) -> bool {
    if tris.is_empty()
        || tris
            .iter()
            .any(|t| t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
    {
        return false;
    }
    if !edges_balance(tris) {
        return false;
    }
    let n_verts = tris.iter().flatten().max().map_or(0, |&m| m as usize + 1);
    if n_verts > 3 * tris.len() {
        // Sparse indices (never from the tessellator, which welds them
        // dense): renumber the used ones so the buckets stay O(n).
        let mut used: Vec<u32> = tris.iter().flatten().copied().collect();
        used.sort_unstable();
        used.dedup();
        let dense = |i: u32| u32::try_from(used.binary_search(&i).unwrap_or(0)).unwrap_or(0);
        let renumbered: Vec<[u32; 3]> = tris.iter().map(|t| t.map(dense)).collect();
        return is_closed(&renumbered);
    }
    // start[a]..start[a + 1]: the heads of the directed edges leaving a.
    let mut start = vec![0usize; n_verts + 1];
    for t in tris {
        for &a in t {
            start[a as usize + 1] += 1;
        }
    }
    for a in 0..n_verts {
        start[a + 1] += start[a];
    }
    let mut fill = start.clone();
    let mut heads = vec![0u32; 3 * tris.len()];
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3]);
            heads[fill[a]] = b;
            fill[a] += 1;
        }
    }
    for a in 0..n_verts {
        let out = &mut heads[start[a]..start[a + 1]];
        out.sort_unstable();
        if out.windows(2).any(|w| w[0] == w[1]) {
            return false;
        }
    }
    (0..n_verts).all(|a| {
        heads[start[a]..start[a + 1]].iter().all(|&b| {
            let back = &heads[start[b as usize]..start[b as usize + 1]];
            back.binary_search(&u32::try_from(a).unwrap_or(u32::MAX))
                .is_ok()
        })
    })
}

/// Transforms a piece's positions to world space and welds exactly equal
/// ones, returning the welded positions and the triangles re-indexed into
/// them. Fails if a vertex lands outside the allowed coordinate range.
fn weld_positions(
    scene: &Scene,
    obj: &Object,
    piece: &Piece,
) -> Result<(Vec<Vec3>, Vec<[u32; 3]>), LoadError> {
    let tr = &obj.transform;
    let mut world: Vec<Vec3> = Vec::with_capacity(piece.positions.len());
    for (k, p) in piece.positions.iter().enumerate() {
        let w = tr.point(*p);
        if !w.is_finite() || w.abs().max_element() > MAX_COORDINATE {
            return Err(LoadError::Key {
                path: scene.path.clone(),
                loc: obj.loc,
                key: format!("objects[{}]", obj.index),
                message: format!(
                    "vertex {k} lands at {w} after the transform; coordinates must be finite and within ±{MAX_COORDINATE:e}"
                ),
            });
        }
        world.push(to_f32(w));
    }
    // Equal positions found by sorting (key, index) pairs: streaming and
    // cache-friendly where a hash map's probes miss at every vertex, and
    // with no input that degrades it. Each welded position keeps its first
    // occurrence's place, so the result is what a first-come numbering
    // gives.
    // Each pair packed into one `u128` (key words high to low, then the
    // index): the same order as the tuples' lexicographic one, compared in
    // two 64-bit halves instead of four words (the sort was half of
    // tessellating `dense.toml`).
    let mut order: Vec<u128> = world
        .iter()
        .zip(0u32..)
        .map(|(w, k)| {
            let [a, b, c] = weld_key(*w);
            u128::from(a) << 96 | u128::from(b) << 64 | u128::from(c) << 32 | u128::from(k)
        })
        .collect();
    order.sort_unstable();
    // first[k]: the first vertex with vertex k's position.
    #[expect(
        clippy::cast_possible_truncation,
        reason = "the low 32 bits: the index"
    )]
    let index = |e: u128| e as u32;
    let mut first: Vec<u32> = vec![0; world.len()];
    for group in order.chunk_by(|a, b| a >> 32 == b >> 32) {
        let lead = index(group[0]);
        for &e in group {
            first[index(e) as usize] = lead;
        }
    }
    let mut welded: Vec<Vec3> = Vec::with_capacity(world.len());
    let mut remap: Vec<u32> = Vec::with_capacity(world.len());
    for (k, w) in world.iter().enumerate() {
        let lead = first[k] as usize;
        if lead == k {
            remap.push(u32::try_from(welded.len()).unwrap_or(u32::MAX));
            welded.push(*w);
        } else {
            remap.push(remap[lead]);
        }
    }
    let tris: Vec<[u32; 3]> = piece
        .tris
        .iter()
        .map(|t| t.map(|i| remap[i as usize]))
        .collect();
    Ok((welded, tris))
}

/// Makes a closed mesh face out: reverses the winding of every triangle
/// (with its normal and uv corners) if the signed volume is negative.
fn orient_outward(welded: &[Vec3], tris: &mut [[u32; 3]], piece: &mut Piece) {
    let volume: f64 = tris
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| to_f64(welded[i as usize]));
            a.dot(b.cross(c))
        })
        .sum();
    if volume < 0.0 {
        for ((t, n), uv) in tris
            .iter_mut()
            .zip(&mut piece.tri_normals)
            .zip(&mut piece.tri_uvs)
        {
            t.swap(1, 2);
            n.swap(1, 2);
            uv.swap(1, 2);
        }
    }
}

/// The materials an object's piece uses, each once: its triangles' (a
/// mesh with per-face materials), else the object's.
fn object_materials(obj: &Object, piece: &Piece) -> Vec<u16> {
    match &piece.tri_materials {
        Some(m) => {
            let mut v = m.to_vec();
            v.sort_unstable();
            v.dedup();
            v
        }
        None => vec![obj.material],
    }
}

/// Rejects a refracting material on an object that is not closed, since
/// refraction needs an inside.
fn check_refraction_needs_closed(
    scene: &Scene,
    obj: &Object,
    piece: &Piece,
    closed: bool,
) -> Result<(), LoadError> {
    let refracting = object_materials(obj, piece).into_iter().find(|&k| {
        let m = &scene.materials[usize::from(k)];
        m.ior != 1.0 && m.is_transparent()
    });
    if let Some(k) = refracting
        && !closed
    {
        let material = &scene.materials[usize::from(k)];
        return Err(LoadError::Key {
            path: scene.path.clone(),
            loc: obj.loc,
            key: format!("objects[{}].material", obj.index),
            message: format!(
                "material \"{}\" refracts (ior ≠ 1 with filter/transmit) but {} is not closed (manifold and consistently oriented after welding); refraction needs an inside",
                material.name,
                obj.label()
            ),
        });
    }
    Ok(())
}

/// Where a piece's indices start in the scene's shared arrays.
struct Bases {
    /// First of the piece's welded positions.
    pos: u32,
    /// First of the piece's uvs.
    uv: u32,
    /// First of the piece's given (transformed) normals.
    normal: u32,
    /// First of the piece's computed per-position normals (0 if none).
    computed: u32,
}

/// Appends a smooth piece's normals to `out`: the given ones transformed
/// by the inverse transpose, then, if any corner asks for one, normals
/// computed area-weighted over the welded world-space positions. Returns
/// the bases of the given and the computed normals.
fn push_normals(
    obj: &Object,
    piece: &Piece,
    welded: &[Vec3],
    tris: &[[u32; 3]],
    out: &mut TriScene,
) -> (u32, u32) {
    let tr = &obj.transform;
    let normal_base = u32::try_from(out.normals.len()).unwrap_or(u32::MAX);
    let needs_computed = piece.tri_normals.iter().any(|t| t[0] == COMPUTE_NORMAL);
    let mut computed_base = 0u32;
    if piece.smooth {
        for n in &piece.normals {
            let w = tr.normal(*n).normalize_or_zero();
            out.normals.push(to_f32(w));
        }
        if needs_computed {
            computed_base = u32::try_from(out.normals.len()).unwrap_or(u32::MAX);
            let mut acc = vec![DVec3::ZERO; welded.len()];
            for t in tris {
                let [a, b, c] = t.map(|i| to_f64(welded[i as usize]));
                let w = (b - a).cross(c - a);
                for &i in t {
                    acc[i as usize] += w;
                }
            }
            out.normals
                .extend(acc.iter().map(|n| to_f32(n.normalize_or_zero())));
        }
    }
    (normal_base, computed_base)
}

/// The scene-wide normal indices of triangle `t`'s corners, given its
/// piece-local normal indices `tn`: none for flat pieces or corners without
/// normals, otherwise each corner's given or computed normal.
fn tri_normal_indices(tn: [u32; 3], t: [u32; 3], smooth: bool, bases: &Bases) -> [u32; 3] {
    if tn[0] == NO_INDEX || !smooth {
        [NO_INDEX; 3]
    } else {
        let mut r = [0u32; 3];
        for c in 0..3 {
            r[c] = if tn[c] == COMPUTE_NORMAL {
                bases.computed + t[c]
            } else {
                bases.normal + tn[c]
            };
        }
        r
    }
}

/// Appends the piece's triangles with their normal and uv indices,
/// material and object id to `out`, returning the triangles' bounds.
fn push_triangles(
    obj: &Object,
    piece: &Piece,
    welded: &[Vec3],
    tris: &[[u32; 3]],
    bases: &Bases,
    object_id: u32,
    out: &mut TriScene,
) -> Aabb {
    let mut bounds = Aabb::EMPTY;
    for (k, t) in tris.iter().enumerate() {
        out.tris.push(t.map(|i| i + bases.pos));
        for &i in t {
            bounds = bounds.grow(welded[i as usize]);
        }
        let tn = tri_normal_indices(piece.tri_normals[k], *t, piece.smooth, bases);
        out.tri_normals.push(tn);
        let tu = piece.tri_uvs[k];
        out.tri_uvs.push(if tu[0] == NO_INDEX {
            tu
        } else {
            tu.map(|i| i + bases.uv)
        });
        out.tri_material
            .push(piece.tri_materials.as_ref().map_or(obj.material, |m| m[k]));
        out.tri_object.push(object_id);
    }
    bounds
}

/// Appends the analytic version of curved shapes and boxes (`--geometry
/// analytic`) to `out`. Boxes and superellipsoids whose material reads uvs
/// keep their triangles: their uv maps are those of the tessellation.
fn push_analytic(scene: &Scene, obj: &Object, object_id: u32, out: &mut TriScene) {
    let tr = &obj.transform;
    let needs_uv = scene.materials[usize::from(obj.material)].needs_uv();
    let kind = match obj.shape {
        Shape::Sphere { center, radius } => Some(AnalyticKind::Sphere { center, radius }),
        Shape::Box { min, max } if !needs_uv => Some(AnalyticKind::Box { min, max }),
        Shape::Superellipsoid { e, n } if !needs_uv => Some(AnalyticKind::Superellipsoid { e, n }),
        _ => None,
    };
    if let Some(kind) = kind {
        let placed = Placed::new(kind, tr.matrix(), tr.normal_matrix());
        let world_sphere = match (kind, tr.uniform_scale()) {
            (AnalyticKind::Sphere { center, radius }, Some(s)) => {
                Some((tr.point(center), radius * s))
            }
            _ => None,
        };
        out.analytic.push(AnalyticShape {
            object: object_id,
            placed,
            bounds: placed.world_bounds(),
            world_sphere,
            material: obj.material,
            uv: matches!(kind, AnalyticKind::Sphere { .. }),
        });
    }
}

/// Adds one object's piece to `out`: welds and orients its mesh in world
/// space, checks its material, and appends its normals, positions, uvs,
/// triangles, analytic shape and object record.
fn append(
    scene: &Scene,
    obj: &Object,
    mut piece: Piece,
    out: &mut TriScene,
) -> Result<(), LoadError> {
    let (welded, mut tris) = weld_positions(scene, obj, &piece)?;
    let closed = is_closed(&tris);
    if closed {
        orient_outward(&welded, &mut tris, &mut piece);
    }
    check_refraction_needs_closed(scene, obj, &piece, closed)?;

    let (normal_base, computed_base) = push_normals(obj, &piece, &welded, &tris, out);
    let bases = Bases {
        pos: u32::try_from(out.positions.len()).unwrap_or(u32::MAX),
        uv: u32::try_from(out.uvs.len()).unwrap_or(u32::MAX),
        normal: normal_base,
        computed: computed_base,
    };
    out.positions.extend_from_slice(&welded);
    out.uvs.extend_from_slice(&piece.uvs);
    let object_id = u32::try_from(out.objects.len()).unwrap_or(u32::MAX);
    let first = u32::try_from(out.tris.len()).unwrap_or(u32::MAX);
    let bounds = push_triangles(obj, &piece, &welded, &tris, &bases, object_id, out);
    let last = u32::try_from(out.tris.len()).unwrap_or(u32::MAX);
    out.bounds = out.bounds.union(bounds);
    push_analytic(scene, obj, object_id, out);
    out.objects.push(ObjectInfo {
        label: obj.label(),
        kind: obj.shape.kind(),
        tris: first..last,
        bounds,
        closed,
        no_shadow: obj.no_shadow,
        material: obj.material,
        smooth: piece.smooth,
        segments: piece.segments,
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    #[test]
    fn sphere_grid_is_closed_and_outward() {
        for n in [3, 4, 7, 16, 33] {
            let (verts, tris) = sphere_grid(n);
            assert!(is_closed(&tris), "n = {n}");
            let vol: f64 = tris
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| verts[i as usize].0);
                    a.dot(b.cross(c))
                })
                .sum();
            assert!(
                vol > 0.0,
                "n = {n}: the counter-clockwise side must face out"
            );
        }
    }

    /// The definition, directly: a map from each undirected edge to its
    /// use count and the sum of its directions.
    fn is_closed_by_definition(tris: &[[u32; 3]]) -> bool {
        let mut edges: HashMap<(u32, u32), (u32, i32)> = HashMap::new();
        for t in tris {
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                return false;
            }
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let e = edges.entry((a.min(b), a.max(b))).or_insert((0, 0));
                e.0 += 1;
                e.1 += if a < b { 1 } else { -1 };
            }
        }
        !tris.is_empty() && edges.values().all(|&(count, dir)| count == 2 && dir == 0)
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(512))]
        /// Closed meshes (sphere grids, boxes, both together) broken by one
        /// edit — a triangle flipped, removed, repeated, given a repeated
        /// corner, or a corner moved to another vertex — or left whole.
        #[test]
        fn is_closed_matches_its_definition(
            n in 3u32..12,
            with_box in proptest::bool::ANY,
            edit in 0u8..7,
            which in 0usize..10_000,
            corner in 0usize..3,
            target in 0u32..10_000,
        ) {
            let (verts, mut tris) = sphere_grid(n);
            if with_box {
                let b = box_piece(DVec3::splat(-1.0), DVec3::ONE);
                let off = u32::try_from(verts.len()).unwrap();
                tris.extend(b.tris.iter().map(|t| t.map(|i| i + off)));
            }
            let nv = tris.iter().flatten().max().unwrap() + 1;
            let i = which % tris.len();
            match edit {
                0 => tris[i].swap(0, 1),
                1 => {
                    tris.remove(i);
                }
                2 => tris.push(tris[i]),
                3 => tris[i][corner] = tris[i][(corner + 1) % 3],
                4 => tris[i][corner] = target % nv,
                5 => {
                    let t = tris[i];
                    tris.push([t[0], t[2], t[1]]);
                    tris.push(t);
                }
                _ => {}
            }
            let expected = is_closed_by_definition(&tris);
            proptest::prop_assert_eq!(is_closed(&tris), expected);
            // The same mesh with sparse indices (spread over u32).
            let spread: Vec<[u32; 3]> = tris
                .iter()
                .map(|t| {
                    // A bijection modulo the prime 2^32 - 5.
                    t.map(|i| u32::try_from(u64::from(i) * 40_000_003 % 4_294_967_291).unwrap())
                })
                .collect();
            proptest::prop_assert_eq!(is_closed(&spread), expected);
            if edit == 6 {
                proptest::prop_assert!(expected);
            }
        }
    }

    proptest::proptest! {
        /// Arbitrary triangle soups over a few vertices.
        #[test]
        fn is_closed_matches_its_definition_on_soups(
            tris in proptest::collection::vec(proptest::array::uniform3(0u32..6), 0..12),
        ) {
            proptest::prop_assert_eq!(is_closed(&tris), is_closed_by_definition(&tris));
        }
    }

    /// The one-pass check answers an open mesh by itself and never turns
    /// a closed one away; a mesh whose edges balance without being closed
    /// (a triangle beside its reverse, twice) is left to the full check.
    #[test]
    fn edge_balance_is_a_quick_no_for_open_meshes() {
        let (_, sphere) = sphere_grid(8);
        assert!(edges_balance(&sphere) && is_closed(&sphere));
        let mut open = sphere.clone();
        open.pop();
        assert!(!edges_balance(&open) && !is_closed(&open));
        assert!(!edges_balance(&[[0, 1, 2], [1, 3, 2]]));
        let doubled = [[0, 1, 2], [0, 2, 1], [0, 1, 2], [0, 2, 1]];
        assert!(edges_balance(&doubled) && !is_closed(&doubled));
    }

    #[test]
    fn box_is_closed_and_outward() {
        let p = box_piece(DVec3::splat(-1.0), DVec3::new(2.0, 1.0, 3.0));
        assert!(is_closed(&p.tris));
        for t in &p.tris {
            let [a, b, c] = t.map(|i| p.positions[i as usize]);
            let centroid = (a + b + c) / 3.0;
            assert!(
                (b - a)
                    .cross(c - a)
                    .dot(centroid - DVec3::new(0.5, 0.0, 1.0))
                    > 0.0
            );
        }
    }

    #[test]
    fn superellipsoid_unit_exponents_is_a_sphere() {
        let p = superellipsoid_point(1.0, 1.0, DVec3::new(1.0, 2.0, 2.0).normalize());
        assert!((p.length() - 1.0).abs() < 1e-12);
        let q = superellipsoid_point(0.3, 0.7, DVec3::new(0.2, -0.5, 0.8).normalize());
        assert!((superellipsoid_f(q, 0.3, 0.7) - 1.0).abs() < 1e-12);
        let nrm = superellipsoid_normal(1.0, 1.0, p).unwrap();
        assert!((nrm - p).length() < 1e-12);
    }

    #[test]
    fn segment_choice_is_minimal() {
        let tol = 1e-3;
        let mut work = SEARCH_WORK_TRIANGLES;
        let mut search = Search {
            max: MAX_SEGMENTS,
            work: &mut work,
            measured: false,
        };
        let (n, short) = choose_segments(None, tol, &mut search, |n| sphere_chord_error(1.0, n));
        assert_eq!(short, None);
        assert!(sphere_chord_error(1.0, n) <= tol);
        assert!(sphere_chord_error(1.0, n - 1) > tol);
    }
}
