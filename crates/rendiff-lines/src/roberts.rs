//! Roberts' hidden-line algorithm (1963) for scenes of convex polyhedra.
//!
//! 1. **Convexity**: every object must be a closed convex polyhedron
//!    ([`convex`](super::convex)); otherwise the drawing is refused, naming it.
//! 2. **Back-face culling**: per object, the triangles facing the eye.
//!    The edges drawn are Appel's (silhouettes and creases, the same
//!    classification and near-plane clipping), less those between two
//!    back faces: a convex object hides them itself.
//! 3. **The volume a polyhedron hides.** A point X is hidden by the convex
//!    polyhedron P when the segment from the eye to X passes through P.
//!    Those points form a convex volume, the polyhedron swept away from the
//!    eye, bounded by the planes of P's front faces (X lies behind each)
//!    and by the planes through the eye and each silhouette edge (front
//!    face on one side, back face on the other; X lies inside the cone
//!    they make). With an orthographic camera the silhouette planes
//!    contain the view direction instead. Every bounding plane is an
//!    affine function h with h < 0 inside, and along an edge
//!    X(s) = A + s(B − A) it is affine in s, so the hidden part of the
//!    edge is an interval of s found exactly by clipping s against each
//!    plane in turn (Cyrus–Beck): h(A) + s·(h(B) − h(A)) < −δ.
//! 4. **Per edge and polyhedron** (not the edge's own: a convex object
//!    hides none of its front edges): first a *bounding-box rejection* —
//!    the edge's screen box must meet the polyhedron's, and the edge's
//!    farthest point must lie beyond the polyhedron's nearest (a point
//!    hidden by P sees P in front of it) — then the silhouette planes,
//!    then the *relevant faces*: the front faces whose screen boxes meet
//!    the part of the edge left by the silhouette planes (the face a sight
//!    line enters P through contains the point's image, so the others
//!    cannot change the answer), looked up in a screen grid of P's front
//!    faces along that part.
//! 5. **Union**: the hidden intervals of all polyhedra, with how many
//!    polyhedra hide each piece (its QI: on a convex scene, the number of
//!    front faces in front of it, what Appel counts); the pieces with none
//!    are the visible segments, written as Appel's are.
//!
//! **Tolerance δ.** A point within rounding of a bounding plane counts as
//! not behind it, so edges lying in another object's face plane (touching
//! boxes, an edge ending on a face) or grazing a silhouette plane stay
//! visible. δ is the bound of [`convex`](super::convex) on the error rounding the
//! vertices to f32 puts into the plane at the point, ρ·(1 + Σ|barycentric
//! coordinates|) plus the f64 arithmetic, for the plane's own corners (the
//! eye and the view direction are exact); it is a convex function along
//! the edge, so its larger value at the two endpoints bounds it on the
//! whole edge.
//!
//! **Near plane.** As in Appel's counts, an occluder is not clipped at the
//! near plane (only the drawn edges are), and with an orthographic camera
//! a polyhedron straddling the eye plane hides as if it did not: the
//! renderers clip those parts, so scenes where it matters differ from the
//! z-buffer in both methods.

use rayon::prelude::*;

use rendiff_accel::{Accel, AccelOptions};
use rendiff_core::camera::{Camera, Projection};
use rendiff_core::math::{DVec3, gamma64, to_f64};
use rendiff_core::tri_scene::TriScene;

use super::convex::{
    NotConvex, centroid, check_convex, edges_by_object, largest_coordinate, object_vertices,
    vertex_rounding,
};
use super::{
    Base, Drawing, Edge, EdgeEntry, LinesOptions, LinesStats, Segment, lerp3, merge, mesh_edges,
};

/// Draws the visible edges of a scene of convex polyhedra by Roberts'
/// algorithm: the same edges, classification, segment type and writers as
/// [`hidden_lines`](super::hidden_lines). With `verify`, every piece's QI is recounted by
/// a ray (through a BVH built for the purpose), as for Appel's.
///
/// # Errors
///
/// [`NotConvex`] naming the first object that is not a closed convex
/// polyhedron.
pub fn roberts_lines(scene: &TriScene, opts: &LinesOptions) -> Result<Drawing, NotConvex> {
    let rho = vertex_rounding(largest_coordinate(scene));
    let keys = mesh_edges(scene);
    let per_object = edges_by_object(scene, &keys);
    let objects: Vec<u32> = (0..u32::try_from(scene.objects.len()).unwrap_or(u32::MAX)).collect();
    let checks: Vec<Result<(), NotConvex>> = objects
        .par_iter()
        .map(|&o| check_convex(scene, o, &per_object[o as usize], rho))
        .collect();
    checks.into_iter().collect::<Result<Vec<()>, NotConvex>>()?;

    let base = Base::new(scene, opts);
    let cam = base.cam;
    let mut stats = LinesStats {
        edges: keys.len(),
        objects: scene.objects.len(),
        ..LinesStats::default()
    };
    // Back-face culling: Appel's drawn edges less those with no front face.
    let (edges, culled): (Vec<Edge>, Vec<Edge>) =
        base.drawn_edges(&keys).into_iter().partition(|e| {
            e.tris
                .iter()
                .any(|&t| t != u32::MAX && base.facing[t as usize])
        });
    stats.culled = culled.len();
    stats.drawn_edges = edges.len();

    let polys: Vec<Poly> = objects
        .par_iter()
        .map(|&o| Poly::new(&base, o, &per_object[o as usize]))
        .collect();
    stats.faces = polys.iter().map(|p| p.faces.len()).sum();
    stats.silhouette_planes = polys.iter().map(|p| p.cone.len()).sum();

    let accel = opts
        .verify
        .then(|| Accel::new(scene, AccelOptions::default()));
    let r = Roberts {
        base: &base,
        polys: &polys,
        rho,
    };
    let results: Vec<(Vec<Segment>, LinesStats)> = edges
        .par_iter()
        .map(|e| r.edge(e, accel.as_ref()))
        .collect();
    let mut segments = Vec::new();
    for (segs, st) in results {
        segments.extend(segs);
        stats.pairs += st.pairs;
        stats.box_rejected += st.box_rejected;
        stats.plane_tests += st.plane_tests;
        stats.hidden_intervals += st.hidden_intervals;
        stats.visible += st.visible;
        stats.hidden += st.hidden;
        stats.mismatches += st.mismatches;
        stats.verified += st.verified;
    }
    Ok(Drawing {
        width: cam.width(),
        height: cam.height(),
        segments,
        stats,
    })
}

/// A screen rectangle in pixels, closed.
#[derive(Clone, Copy, Debug)]
struct Rect {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Rect {
    /// Margin added around a polyhedron's or face's box: the projection
    /// rounds at about 1e-13 px, so 1e-6 px never rejects a box that meets.
    const MARGIN: f64 = 1e-6;

    /// The box of the images of `points`, or `None` where one does not
    /// project (perspective: not in front of the eye plane).
    fn of_points(cam: &Camera, points: impl IntoIterator<Item = DVec3>) -> Option<Rect> {
        let mut r = Rect {
            x0: f64::INFINITY,
            y0: f64::INFINITY,
            x1: f64::NEG_INFINITY,
            y1: f64::NEG_INFINITY,
        };
        for p in points {
            let (x, y, _) = cam.project(p)?;
            r = r.with((x, y));
        }
        Some(r.grown(Self::MARGIN))
    }

    fn of_segment(a: (f64, f64), b: (f64, f64)) -> Rect {
        Rect {
            x0: a.0.min(b.0),
            y0: a.1.min(b.1),
            x1: a.0.max(b.0),
            y1: a.1.max(b.1),
        }
    }

    fn with(self, (x, y): (f64, f64)) -> Rect {
        Rect {
            x0: self.x0.min(x),
            y0: self.y0.min(y),
            x1: self.x1.max(x),
            y1: self.y1.max(y),
        }
    }

    fn grown(self, m: f64) -> Rect {
        Rect {
            x0: self.x0 - m,
            y0: self.y0 - m,
            x1: self.x1 + m,
            y1: self.y1 + m,
        }
    }

    fn meets(&self, o: &Rect) -> bool {
        self.x0 <= o.x1 && o.x0 <= self.x1 && self.y0 <= o.y1 && o.y0 <= self.y1
    }
}

/// How rounding errors of a plane's three defining points combine: the
/// plane's error at a point with barycentric coordinates (α, β, γ) on the
/// triangle `t` is at most ρ times this weight.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Corners {
    /// A face: three rounded vertices, |α| + |β| + |γ|.
    Face,
    /// A silhouette plane through the (exact) eye `t[0]` and two rounded
    /// vertices: |β| + |γ|.
    Eye,
    /// A silhouette plane through two rounded vertices `t[0]`, `t[1]` and
    /// `t[0]` moved along the (exact) view direction, which has the error
    /// of `t[0]`: |α + γ| + |β|.
    Direction,
}

/// A bounding plane of the volume a polyhedron hides: points X with
/// n·X − d < 0 lie on its inner side.
#[derive(Clone, Copy, Debug)]
struct Plane {
    /// Unit normal, pointing out of the hidden volume.
    n: DVec3,
    d: f64,
    /// The triangle that defines it (its normal is ±n), its sides from
    /// `t[0]`, their cross product over its squared length (for the
    /// barycentric coordinates of a point's projection) and how its
    /// corners' errors combine.
    t0: DVec3,
    e1: DVec3,
    e2: DVec3,
    m: DVec3,
    corners: Corners,
}

impl Plane {
    /// The plane of triangle `t` with `interior` on its inner side.
    fn through(t: [DVec3; 3], corners: Corners, interior: DVec3) -> Option<Plane> {
        let raw = (t[1] - t[0]).cross(t[2] - t[0]);
        let n = raw.try_normalize()?;
        // Swapping t1 and t2 flips the normal and keeps the weights.
        let (n, t) = if n.dot(interior - t[0]) > 0.0 {
            (-n, [t[0], t[2], t[1]])
        } else {
            (n, t)
        };
        let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
        let raw = e1.cross(e2);
        Some(Plane {
            n,
            d: n.dot(t[0]),
            t0: t[0],
            e1,
            e2,
            m: raw / raw.length_squared(),
            corners,
        })
    }

    fn eval(&self, x: DVec3) -> f64 {
        self.n.dot(x) - self.d
    }

    /// The rounding tolerance at `x`: the plane's error there (by its
    /// corners' weights), `x`'s own (ρ) and the arithmetic's (γ(8) of the
    /// magnitudes in n·x − d).
    fn tolerance(&self, x: DVec3, rho: f64) -> f64 {
        let r = x - self.t0;
        let b = r.cross(self.e2).dot(self.m);
        let c = self.e1.cross(r).dot(self.m);
        let a = 1.0 - b - c;
        let weight = match self.corners {
            Corners::Face => a.abs() + b.abs() + c.abs(),
            Corners::Eye => b.abs() + c.abs(),
            Corners::Direction => (a + c).abs() + b.abs(),
        };
        rho * (weight + 1.0) + gamma64(8) * (x.length() + self.d.abs())
    }
}

/// A front face: its plane and its screen box (`None`: a corner does not
/// project, so every edge may meet it).
#[derive(Clone, Copy, Debug)]
struct Face {
    plane: Plane,
    rect: Option<Rect>,
}

/// What one polyhedron hides: its front faces (and a screen grid of
/// them), its silhouette planes, its screen box (`None` where a vertex
/// does not project) and depth range.
#[derive(Debug)]
struct Poly {
    object: u32,
    faces: Vec<Face>,
    grid: Option<FaceGrid>,
    cone: Vec<Plane>,
    rect: Option<Rect>,
    zmin: f64,
    zmax: f64,
}

impl Poly {
    /// Culls the back faces of object `object` (mesh edges `edges`) and
    /// builds the planes of the volume it hides.
    fn new(base: &Base<'_>, object: u32, edges: &[EdgeEntry]) -> Poly {
        let scene = base.scene;
        let cam = base.cam;
        let info = &scene.objects[object as usize];
        let verts = object_vertices(scene, object);
        let pos = |i: u32| to_f64(scene.positions[i as usize]);
        let centroid = centroid(scene, object);
        let (mut zmin, mut zmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for &i in &verts {
            let z = cam.view_depth(pos(i));
            zmin = zmin.min(z);
            zmax = zmax.max(z);
        }
        let rect = Rect::of_points(cam, verts.iter().map(|&i| pos(i)));
        let faces: Vec<Face> = info
            .tris
            .clone()
            .filter(|&t| base.facing[t as usize])
            .filter_map(|t| {
                let v = scene.triangle_f64(t);
                Plane::through(v, Corners::Face, centroid).map(|plane| Face {
                    plane,
                    rect: Rect::of_points(cam, v),
                })
            })
            .collect();
        // The silhouette: edges between a front and a back face.
        let cone = edges
            .iter()
            .filter(|(_, t, count)| {
                *count == 2 && base.facing[t[0] as usize] != base.facing[t[1] as usize]
            })
            .filter_map(|&((a, b), _, _)| {
                let (va, vb) = (pos(a), pos(b));
                // A silhouette edge seen end on has no plane; its
                // neighbours' planes meet along its sight line.
                match cam.projection() {
                    Projection::Perspective { .. } => {
                        Plane::through([cam.eye(), va, vb], Corners::Eye, centroid)
                    }
                    Projection::Orthographic { .. } => {
                        Plane::through([va, vb, va + cam.forward()], Corners::Direction, centroid)
                    }
                }
            })
            .collect();
        let grid = rect.and_then(|r| FaceGrid::new(r, &faces));
        Poly {
            object,
            faces,
            grid,
            cone,
            rect,
            zmin,
            zmax,
        }
    }

    /// Calls `f` with the index of every front face whose screen box meets
    /// the box of the screen segment `a`–`b`, each once; with a grid, only
    /// of those listed in the cells along the segment.
    fn for_each_relevant_face(&self, a: (f64, f64), b: (f64, f64), mut f: impl FnMut(usize)) {
        let seg = Rect::of_segment(a, b);
        let mut visit = |k: usize| {
            if self.faces[k].rect.is_none_or(|r| r.meets(&seg)) {
                f(k);
            }
        };
        match &self.grid {
            None => (0..self.faces.len()).for_each(&mut visit),
            Some(grid) => {
                let mut found = grid.faces_along(a, b);
                found.sort_unstable();
                found.dedup();
                found.into_iter().for_each(|k| visit(k as usize));
            }
        }
    }
}

/// A uniform screen grid over a polyhedron's box, each cell listing the
/// front faces whose boxes meet it: the relevant faces of an edge are
/// found in the cells along it, not among all faces.
#[derive(Debug)]
struct FaceGrid {
    rect: Rect,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<u32>>,
    /// Faces without a screen box (a corner not in front of the eye):
    /// relevant everywhere.
    everywhere: Vec<u32>,
}

impl FaceGrid {
    /// About this many faces per cell, on a grid of at most 256 × 256.
    const PER_CELL: usize = 4;

    /// The grid of `faces` over `rect`; `None` for a handful of faces,
    /// where scanning them all is as quick.
    fn new(rect: Rect, faces: &[Face]) -> Option<FaceGrid> {
        if faces.len() < 4 * Self::PER_CELL {
            return None;
        }
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss,
            reason = "a face count's square root, clamped to 1 … 256"
        )]
        let side = ((faces.len() / Self::PER_CELL) as f64)
            .sqrt()
            .ceil()
            .clamp(1.0, 256.0) as usize;
        let mut g = FaceGrid {
            rect,
            nx: side,
            ny: side,
            cells: vec![Vec::new(); side * side],
            everywhere: Vec::new(),
        };
        for (k, face) in faces.iter().enumerate() {
            let k = u32::try_from(k).unwrap_or(u32::MAX);
            match face.rect {
                Some(r) => {
                    let (x0, y0) = g.cell_of(r.x0, r.y0);
                    let (x1, y1) = g.cell_of(r.x1, r.y1);
                    for y in y0..=y1 {
                        for x in x0..=x1 {
                            g.cells[y * g.nx + x].push(k);
                        }
                    }
                }
                None => g.everywhere.push(k),
            }
        }
        Some(g)
    }

    /// The cell of a screen point, clamped to the grid.
    fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        let clamp = |v: f64, lo: f64, hi: f64, n: usize| {
            let u = ((v - lo) / (hi - lo)).clamp(0.0, 1.0);
            #[expect(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                clippy::cast_precision_loss,
                reason = "clamped to the grid's 1 … 256 cells"
            )]
            let k = ((u * n as f64).floor() as usize).min(n - 1);
            k
        };
        (
            clamp(x, self.rect.x0, self.rect.x1, self.nx),
            clamp(y, self.rect.y0, self.rect.y1, self.ny),
        )
    }

    /// The faces (with repeats) listed in the cells the segment `a`–`b`
    /// passes through: it is cut into pieces no longer than a cell's
    /// smaller side, and each piece's box (within 2 × 2 cells) is taken
    /// whole — a superset of the cells it crosses.
    fn faces_along(&self, a: (f64, f64), b: (f64, f64)) -> Vec<u32> {
        let cw = (self.rect.x1 - self.rect.x0) / f64::from(u32::try_from(self.nx).unwrap_or(1));
        let ch = (self.rect.y1 - self.rect.y0) / f64::from(u32::try_from(self.ny).unwrap_or(1));
        let step = cw.min(ch).max(1e-9);
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "a segment's length in cells, clamped"
        )]
        let pieces = (len / step).ceil().clamp(1.0, 1e6) as u32;
        let mut out = self.everywhere.clone();
        let mut last = usize::MAX;
        for i in 0..pieces {
            let (u0, u1) = (
                f64::from(i) / f64::from(pieces),
                f64::from(i + 1) / f64::from(pieces),
            );
            let p = |u: f64| (a.0 + (b.0 - a.0) * u, a.1 + (b.1 - a.1) * u);
            let r = Rect::of_segment(p(u0), p(u1));
            let (x0, y0) = self.cell_of(r.x0, r.y0);
            let (x1, y1) = self.cell_of(r.x1, r.y1);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let c = y * self.nx + x;
                    // Consecutive pieces share cells: skip an immediate repeat.
                    if c != last {
                        out.extend_from_slice(&self.cells[c]);
                        last = c;
                    }
                }
            }
        }
        out
    }
}

/// The steps per edge.
struct Roberts<'a, 'b> {
    base: &'a Base<'b>,
    polys: &'a [Poly],
    rho: f64,
}

impl Roberts<'_, '_> {
    /// Edge `e` against every other polyhedron: its pieces with their QIs
    /// (merged where consecutive ones agree) and the counters.
    fn edge(&self, e: &Edge, accel: Option<&Accel<'_>>) -> (Vec<Segment>, LinesStats) {
        let cam = self.base.cam;
        let mut st = LinesStats::default();
        let own = self.base.scene.tri_object[e.tris[0] as usize];
        let rect = Rect::of_segment(e.q[0], e.q[1]);
        let zmax = cam.view_depth(e.p[0]).max(cam.view_depth(e.p[1]));
        let mut intervals: Vec<(f64, f64)> = Vec::new();
        for poly in self.polys {
            if poly.object == own || poly.faces.is_empty() {
                continue;
            }
            st.pairs += 1;
            // Bounding boxes: in depth (a hiding polyhedron lies in front of
            // the point, and in front of the eye) and on the screen.
            if zmax <= poly.zmin || poly.zmax <= 0.0 || poly.rect.is_some_and(|r| !r.meets(&rect)) {
                st.box_rejected += 1;
                continue;
            }
            if let Some(iv) = self.hidden_by(e, poly, &mut st) {
                st.hidden_intervals += 1;
                intervals.push(iv);
            }
        }
        let (bounds, qis) = pieces_of(&intervals);
        let out = self.base.pieces(accel, e, &bounds, &qis, &mut st);
        (merge(out), st)
    }

    /// The interval of edge parameters where `poly` hides `e`, if any.
    fn hidden_by(&self, e: &Edge, poly: &Poly, st: &mut LinesStats) -> Option<(f64, f64)> {
        let (mut lo, mut hi) = (0.0, 1.0);
        for plane in &poly.cone {
            st.plane_tests += 1;
            if !self.clip(e, plane, &mut lo, &mut hi) {
                return None;
            }
        }
        // The relevant faces: those whose screen box meets what is left.
        let cam = self.base.cam;
        let (a, b) = (
            project(cam, lerp3(e.p, lo), e.q[0]),
            project(cam, lerp3(e.p, hi), e.q[1]),
        );
        let mut alive = true;
        poly.for_each_relevant_face(a, b, |k| {
            if alive {
                st.plane_tests += 1;
                alive = self.clip(e, &poly.faces[k].plane, &mut lo, &mut hi);
            }
        });
        if !alive {
            return None;
        }
        Some((lo, hi))
    }

    /// Narrows `(lo, hi)` to where `e` lies more than the rounding
    /// tolerance behind `plane`; `false` once nothing is left.
    fn clip(&self, e: &Edge, plane: &Plane, lo: &mut f64, hi: &mut f64) -> bool {
        let (h0, h1) = (plane.eval(e.p[0]), plane.eval(e.p[1]));
        let delta = plane
            .tolerance(e.p[0], self.rho)
            .max(plane.tolerance(e.p[1], self.rho));
        // h0 + s·(h1 − h0) < −δ.
        let slope = h1 - h0;
        let rhs = -delta - h0;
        if slope > 0.0 {
            *hi = hi.min(rhs / slope);
        } else if slope < 0.0 {
            *lo = lo.max(rhs / slope);
        } else if rhs <= 0.0 {
            return false;
        }
        *lo < *hi
    }
}

/// The pieces of an edge between the ends of the hidden `intervals` (open,
/// within [0, 1]): their bounds, from 0 to 1, and how many intervals
/// cover each.
fn pieces_of(intervals: &[(f64, f64)]) -> (Vec<f64>, Vec<i64>) {
    let mut events: Vec<(f64, i64)> = intervals
        .iter()
        .flat_map(|&(a, b)| [(a, 1), (b, -1)])
        .collect();
    events.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut bounds = vec![0.0];
    let mut qis = Vec::new();
    let mut qi = 0;
    for (s, change) in events {
        if s > *bounds.last().unwrap_or(&0.0) {
            bounds.push(s);
            qis.push(qi);
        }
        qi += change;
    }
    if *bounds.last().unwrap_or(&0.0) < 1.0 {
        bounds.push(1.0);
        qis.push(qi);
    }
    (bounds, qis)
}

/// The image of a point of an edge (in front of the near plane, so it
/// projects; `fallback` otherwise).
fn project(cam: &Camera, p: DVec3, fallback: (f64, f64)) -> (f64, f64) {
    cam.project(p).map_or(fallback, |(x, y, _)| (x, y))
}

#[cfg(test)]
mod tests {
    use super::super::convex::tests::{camera, cuboid, scene};
    use super::super::{EdgeKind, hidden_lines};
    use super::*;
    use rendiff_core::math::Vec3;

    fn dump(d: &Drawing) -> String {
        d.segments
            .iter()
            .map(|s| {
                format!(
                    "{:?} qi {} {:?} {:.3} -> {:.3} s {:?}\n",
                    s.kind, s.qi, s.tris, s.p[0], s.p[1], s.s
                )
            })
            .collect()
    }

    /// A cube in front (z from 1 to 2) of a long bar (x from −3 to 3,
    /// top front edge at y = 0.2, z = 0), seen down −z from (0, 0, 10).
    fn cube_and_bar(ortho: bool) -> TriScene {
        scene(
            camera(ortho),
            &[
                cuboid([-1.0, -1.0, 1.0], [1.0, 1.0, 2.0]),
                cuboid([-3.0, -0.2, -1.0], [3.0, 0.2, 0.0]),
            ],
        )
    }

    /// The visible pieces of the bar's edge from (−3, 0.2, 0) to
    /// (3, 0.2, 0), in x.
    fn bar_top_front(d: &Drawing) -> Vec<(f64, f64)> {
        let mut v: Vec<(f64, f64)> = d
            .segments
            .iter()
            .filter(|s| {
                s.qi == 0
                    && s.p
                        .iter()
                        .all(|p| (p.y - 0.2).abs() < 1e-6 && p.z.abs() < 1e-6)
                    && (s.p[0].x - s.p[1].x).abs() > 1e-9
            })
            .map(|s| (s.p[0].x.min(s.p[1].x), s.p[0].x.max(s.p[1].x)))
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v
    }

    /// The hidden part of an edge is the interval where it lies inside the
    /// volume the cube hides, found exactly: |x| < 1 seen orthographically,
    /// |x| < 1.25 in perspective (the cube's front face at distance 8 from
    /// the eye, the edge at 10) — less the rounding tolerance δ at each
    /// end: δ ≤ ρ·(1 + 5) + … ≈ 2e-6 (ρ = √3·2⁻²⁴·3, the silhouette edge 2
    /// long seen from points up to 4 away along it) over a slope of 6 per
    /// unit of s, so the ends move by at most 1e-6 in x (checked: 2e-6).
    #[test]
    fn the_hidden_interval_is_exact() {
        for (ortho, x) in [(true, 1.0), (false, 1.25)] {
            let s = cube_and_bar(ortho);
            let d = roberts_lines(&s, &LinesOptions::default()).unwrap();
            let got = bar_top_front(&d);
            assert_eq!(got.len(), 2, "ortho {ortho}: {got:?} {}", dump(&d));
            assert!(
                (got[0].0 + 3.0).abs() < 1e-12 && (got[0].1 + x).abs() < 2e-6,
                "{got:?}"
            );
            assert!(
                (got[1].0 - x).abs() < 2e-6 && (got[1].1 - 3.0).abs() < 1e-12,
                "{got:?}"
            );
            assert_eq!(d.stats.objects, 2);
            assert!(d.stats.hidden_intervals >= 1);
        }
    }

    /// Back-face culling leaves the edges of front faces: of a box seen
    /// straight on (one face toward the eye, four edge on), the four edges
    /// of its front face, each visible whole.
    #[test]
    fn back_faces_are_culled() {
        let s = scene(camera(true), &[cuboid([-1.0; 3], [1.0; 3])]);
        let d = roberts_lines(&s, &LinesOptions::default()).unwrap();
        assert_eq!(d.stats.drawn_edges, 4, "{}", dump(&d));
        assert_eq!(d.segments.len(), 4);
        assert!(d.segments.iter().all(|s| s.qi == 0 && s.s == (0.0, 1.0)));
        assert!(d.segments.iter().all(|s| s.kind == EdgeKind::Silhouette));
        // Appel draws the side and back faces' edges too (seen end on or
        // lying behind the front face's, so its ray counts graze them).
        let accel = Accel::new(&s, AccelOptions::default());
        let a = hidden_lines(&s, &accel, &LinesOptions::default());
        assert_eq!(a.stats.drawn_edges, 12, "{}", dump(&a));
        for seg in &d.segments {
            assert!(
                a.segments
                    .iter()
                    .any(|x| x.tris == seg.tris && x.qi == 0 && x.s == seg.s)
            );
        }
    }

    /// With `hidden`, the hidden pieces are kept with the number of
    /// polyhedra in front of them as their QI, as Appel counts them, and
    /// the ray recount (`verify`) agrees.
    #[test]
    fn hidden_pieces_count_the_polyhedra_in_front() {
        let s = scene(
            camera(false),
            &[
                cuboid([-1.0, -1.0, 3.0], [1.0, 1.0, 4.0]),
                cuboid([-1.5, -1.5, 1.0], [1.5, 1.5, 2.0]),
                cuboid([-3.0, -0.2, -1.0], [3.0, 0.2, 0.0]),
            ],
        );
        let opts = LinesOptions {
            hidden: true,
            verify: true,
            ..LinesOptions::default()
        };
        let d = roberts_lines(&s, &opts).unwrap();
        assert!(d.stats.verified > 0);
        assert_eq!(d.stats.mismatches, 0, "{:?}", d.stats);
        let max_qi = d.segments.iter().map(|s| s.qi).max();
        assert_eq!(max_qi, Some(2), "the bar's middle is behind both cubes");
        let accel = Accel::new(&s, AccelOptions::default());
        let a = hidden_lines(&s, &accel, &opts);
        assert_eq!(a.stats.mismatches, 0);
        for seg in d.segments.iter().filter(|s| s.s.1 - s.s.0 > 1e-6) {
            let mid = 0.5 * (seg.s.0 + seg.s.1);
            let same = a
                .segments
                .iter()
                .find(|x| x.tris == seg.tris && x.s.0 <= mid && mid <= x.s.1)
                .map(|x| x.qi);
            assert_eq!(same, Some(seg.qi), "{seg:?}");
        }
    }

    /// A box standing on another and a box beside it sharing a face: the
    /// edges lying in the other box's face planes stay visible (the
    /// rounding tolerance), the ones behind are hidden.
    #[test]
    fn touching_boxes_do_not_hide_their_shared_edges() {
        let mut cam_eye = camera(false);
        cam_eye = Camera::new(
            DVec3::new(3.0, 4.0, 6.0),
            DVec3::new(0.5, 0.5, 0.0),
            DVec3::Y,
            cam_eye.projection(),
            400,
            400,
            1,
            0.01,
            100.0,
        )
        .unwrap();
        let s = scene(
            cam_eye,
            &[
                cuboid([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
                cuboid([1.0, 0.0, 0.0], [2.0, 1.0, 1.0]),
                cuboid([0.25, 1.0, 0.25], [0.75, 1.5, 0.75]),
            ],
        );
        let d = roberts_lines(
            &s,
            &LinesOptions {
                hidden: true,
                verify: true,
                ..LinesOptions::default()
            },
        )
        .unwrap();
        assert_eq!(d.stats.mismatches, 0, "{:?}", d.stats);
        // The front edge x = 1, z = 1 (both boxes' front faces meet there)
        // is visible whole.
        let shared: Vec<&Segment> = d
            .segments
            .iter()
            .filter(|s| {
                s.p.iter()
                    .all(|p| (p.x - 1.0).abs() < 1e-9 && (p.z - 1.0).abs() < 1e-9)
            })
            .collect();
        assert!(!shared.is_empty());
        assert!(shared.iter().all(|s| s.qi == 0), "{shared:?}");
        // The small box's bottom edges lie on the top face: visible where
        // drawn (the front ones).
        let bottom: Vec<&Segment> = d
            .segments
            .iter()
            .filter(|s| {
                s.p.iter()
                    .all(|p| (p.y - 1.0).abs() < 1e-9 && p.x > 0.2 && p.x < 0.8)
            })
            .collect();
        assert!(!bottom.is_empty());
        assert!(bottom.iter().all(|s| s.qi == 0), "{bottom:?}");
    }

    /// An object with no front face (the eye inside it) hides nothing.
    #[test]
    fn an_object_around_the_eye_hides_nothing() {
        let s = scene(
            camera(false),
            &[
                cuboid([-20.0, -20.0, 5.0], [20.0, 20.0, 20.0]),
                cuboid([-1.0; 3], [1.0; 3]),
            ],
        );
        let d = roberts_lines(&s, &LinesOptions::default()).unwrap();
        assert!(!d.segments.is_empty());
        assert!(d.segments.iter().all(|s| s.qi == 0));
    }

    #[test]
    fn pieces_count_the_covering_intervals() {
        let (b, q) = pieces_of(&[]);
        assert_eq!((b, q), (vec![0.0, 1.0], vec![0]));
        let (b, q) = pieces_of(&[(0.2, 0.6), (0.4, 1.0), (0.0, 0.1)]);
        assert_eq!(b, vec![0.0, 0.1, 0.2, 0.4, 0.6, 1.0]);
        assert_eq!(q, vec![1, 0, 1, 2, 1]);
    }

    /// A box turned by `angle` about the y axis through its centre: its
    /// corners (rounded to f32) and triangles.
    fn turned_box(c: [f64; 3], h: [f64; 3], angle: f64) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        #[expect(clippy::cast_possible_truncation, reason = "test sizes")]
        let (pos, tris) = cuboid(
            [-h[0] as f32, -h[1] as f32, -h[2] as f32],
            [h[0] as f32, h[1] as f32, h[2] as f32],
        );
        let (sin, cos) = angle.sin_cos();
        let pos = pos
            .iter()
            .map(|p| {
                let p = to_f64(*p);
                let q = DVec3::new(cos * p.x + sin * p.z, p.y, -sin * p.x + cos * p.z);
                rendiff_core::math::to_f32(q + DVec3::from(c))
            })
            .collect();
        (pos, tris)
    }

    /// A latitude-longitude sphere of `n` segments (n/2 rings) around `c`,
    /// counter-clockwise seen from outside: enough faces for the face grid.
    fn globe(c: [f64; 3], r: f64, n: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let rings = n / 2;
        let mut pos = vec![DVec3::new(0.0, r, 0.0)];
        for i in 1..rings {
            let th = std::f64::consts::PI * f64::from(i) / f64::from(rings);
            for j in 0..n {
                let ph = std::f64::consts::TAU * f64::from(j) / f64::from(n);
                pos.push(DVec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()) * r);
            }
        }
        pos.push(DVec3::new(0.0, -r, 0.0));
        let south = u32::try_from(pos.len() - 1).unwrap();
        let ring = |i: u32, j: u32| 1 + (i - 1) * n + j % n;
        let mut tris = Vec::new();
        for j in 0..n {
            tris.push([0, ring(1, j + 1), ring(1, j)]);
            tris.push([south, ring(rings - 1, j), ring(rings - 1, j + 1)]);
        }
        for i in 1..rings - 1 {
            for j in 0..n {
                let (a, b, cc, d) = (
                    ring(i, j),
                    ring(i, j + 1),
                    ring(i + 1, j),
                    ring(i + 1, j + 1),
                );
                tris.push([a, b, d]);
                tris.push([a, d, cc]);
            }
        }
        let pos = pos
            .iter()
            .map(|p| rendiff_core::math::to_f32(*p + DVec3::from(c)))
            .collect();
        (pos, tris)
    }

    /// Whether the segment from `a` to `b` passes through the inside of the
    /// closed convex mesh: the part of it behind every triangle's plane
    /// has positive length.
    fn through(mesh: &(Vec<Vec3>, Vec<[u32; 3]>), a: DVec3, b: DVec3) -> bool {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for t in &mesh.1 {
            let v = t.map(|i| to_f64(mesh.0[i as usize]));
            let n = (v[1] - v[0]).cross(v[2] - v[0]);
            let (ha, hb) = (n.dot(a - v[0]), n.dot(b - v[0]));
            if ha >= 0.0 && hb >= 0.0 {
                return false;
            }
            if ha >= 0.0 {
                t0 = t0.max(ha / (ha - hb));
            } else if hb >= 0.0 {
                t1 = t1.min(ha / (ha - hb));
            }
        }
        t1 - t0 > 1e-9
    }

    /// Whether the exact count may exceed the algorithm's at `x`, a point
    /// of edge `e`: some object that hides `x` exactly (`hiding`) has a
    /// bounding plane of its hidden volume with `x` on its inner side but
    /// within the rounding tolerance δ of it, where Roberts counts `x` as
    /// not behind it by design (h(x) ∈ [−δ, 0], 0 raised by the rounding
    /// of h's own evaluation). δ is the algorithm's own, the plane's
    /// tolerance at the edge's farther end. (A δ that is itself too large
    /// would excuse itself here; `the_hidden_interval_is_exact` holds δ to
    /// its derived size.)
    fn within_tolerance_of_a_hider(
        polys: &[Poly],
        hiding: &[bool],
        e: &Edge,
        x: DVec3,
        rho: f64,
    ) -> bool {
        polys.iter().filter(|p| hiding[p.object as usize]).any(|p| {
            p.cone
                .iter()
                .chain(p.faces.iter().map(|f| &f.plane))
                .any(|pl| {
                    let delta = pl.tolerance(e.p[0], rho).max(pl.tolerance(e.p[1], rho));
                    let h = pl.eval(x);
                    -delta <= h && h <= gamma64(8) * (x.length() + pl.d.abs())
                })
        })
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
        /// Roberts' QIs against brute force on random turned boxes and
        /// tessellated spheres (some overlapping, seen in perspective or
        /// orthographically; the spheres have enough faces for the face
        /// grid): at points along every piece, the number of other objects
        /// the sight segment passes through — by clipping the sight
        /// segment, not the edge, against all their planes — is the
        /// piece's QI, except that it may count fewer within the tolerance
        /// δ inside a bounding plane of a hiding object, where the point
        /// counts as not behind it by design (a
        /// fixed margin of 1e-4 in s at the pieces' ends was not enough:
        /// CI's seed d7a8e684 has a sphere face of δ = 5.6e-5 crossed at a
        /// slope of 0.42 per unit of s, which moves the end by 1.3e-4).
        #[test]
        fn qis_match_sight_segments_through_objects(
            objects in proptest::collection::vec(
                (
                    [-3.0f64..3.0, -2.0f64..2.0, -6.0f64..4.0],
                    [0.1f64..1.5, 0.1f64..1.5, 0.1f64..1.5],
                    0.0f64..3.2,
                    proptest::option::weighted(0.4, 12u32..40),
                ),
                2..6,
            ),
            ortho in proptest::bool::ANY,
            eye in [-4.0f64..4.0, -3.0f64..3.0],
        ) {
            let eye = DVec3::new(eye[0], eye[1], 10.0);
            let meshes: Vec<_> = objects
                .iter()
                .map(|(c, h, a, sphere)| match sphere {
                    Some(n) => globe(*c, h[0], *n),
                    None => turned_box(*c, *h, *a),
                })
                .collect();
            let inside = meshes.iter().any(|m| through(m, eye, eye + DVec3::splat(1e-9)));
            proptest::prop_assume!(!inside);
            let base = camera(ortho);
            let cam = Camera::new(eye, DVec3::ZERO, DVec3::Y, base.projection(), 400, 400, 1, 0.01, 100.0).unwrap();
            let s = scene(cam, &meshes);
            let d = roberts_lines(&s, &LinesOptions { hidden: true, ..LinesOptions::default() }).unwrap();
            // The drawn edges and the hiding volumes, to skip the points
            // within the tolerance band of a bounding plane.
            let opts = LinesOptions::default();
            let base_lines = Base::new(&s, &opts);
            let keys = mesh_edges(&s);
            let per_object = edges_by_object(&s, &keys);
            let polys: Vec<Poly> = (0..u32::try_from(meshes.len()).unwrap())
                .map(|o| Poly::new(&base_lines, o, &per_object[o as usize]))
                .collect();
            let edges = base_lines.drawn_edges(&keys);
            let rho = vertex_rounding(largest_coordinate(&s));
            let mut checked = 0;
            for seg in &d.segments {
                let own = s.tri_object[seg.tris[0] as usize];
                let e = edges.iter().find(|e| e.tris == seg.tris).unwrap();
                for k in 1..20 {
                    let u = f64::from(k) / 20.0;
                    let x = seg.p[0] + (seg.p[1] - seg.p[0]) * u;
                    let sight = if ortho { x - cam.forward() * cam.view_depth(x) } else { eye };
                    let hiding: Vec<bool> = meshes
                        .iter()
                        .enumerate()
                        .map(|(i, m)| i != own as usize && through(m, x, sight))
                        .collect();
                    let count = hiding.iter().filter(|&&h| h).count();
                    checked += 1;
                    // Roberts hides a point only more than δ inside every
                    // bounding plane, so it never counts more than the
                    // exact count, and fewer only within δ of a hider's
                    // plane.
                    proptest::prop_assert!(
                        count == seg.qi as usize
                            || (count > seg.qi as usize
                                && within_tolerance_of_a_hider(&polys, &hiding, e, x, rho)),
                        "piece {:?} at u {}: {} objects in front, QI {}", seg.s, u, count, seg.qi
                    );
                }
            }
            proptest::prop_assert!(checked > 0 || d.segments.is_empty());
        }
    }
}
