//! Hidden-line drawing: the visible edges of the scene's triangles, by
//! Appel's quantitative invisibility (1967, [`hidden_lines`], below) or,
//! for scenes made of convex polyhedra, by Roberts' algorithm (1963,
//! [`roberts_lines`]: back-face culling and each edge's parameter interval
//! clipped against every other polyhedron; see its module). Both give the
//! same [`Drawing`] of [`Segment`]s for the same writers.
//!
//! Appel's method:
//!
//! 1. **Edges** of the triangle mesh (positions welded as the tessellator
//!    shares them): *boundaries* (one triangle, or more than two),
//!    *silhouettes* (one adjacent triangle faces the eye, the other away)
//!    and *creases* (the normals differ by more than the crease angle).
//!    Edges between coplanar triangles (polygon diagonals, flat faces) are
//!    not drawn.
//! 2. **Occluders**: the triangles that hide what lies behind them — the
//!    front faces, and both faces of open objects (a back face of a closed
//!    object is always behind a front face of the same object). The
//!    *quantitative invisibility* (QI) of a point is the number of occluders
//!    between it and the eye; a point is visible when its QI is 0.
//! 3. **Contours**: the boundaries and silhouettes are where the occluder
//!    count of the screen changes, so the QI of a point moving along an
//!    edge changes only where the edge passes behind a contour edge — by
//!    the number of occluding triangles at that contour, up where the edge
//!    enters the side they cover, down where it leaves it.
//! 4. **Walk**: per drawn edge, its QI at the start is counted by a ray
//!    from the eye (the only ray cast per edge); the crossings with nearer
//!    contour edges, found through a screen grid and ordered along the
//!    edge, update it. The pieces with QI 0 are the visible segments.
//!
//! Verification (`LinesOptions::verify`) recounts the QI of every piece by
//! a ray through its midpoint and counts disagreements; the tests check
//! the drawing against the z-buffer's triangle ids.

#![warn(missing_docs, missing_debug_implementations)]

mod convex;
mod roberts;

pub use convex::NotConvex;
pub use roberts::roberts_lines;

use std::collections::HashMap;
use std::fmt::Write as _;

use rayon::prelude::*;

use rendiff_accel::Accel;
use rendiff_core::camera::{Camera, Projection};
use rendiff_core::math::{DVec3, Ray64, to_f64};
use rendiff_core::tri_scene::TriScene;

/// What to draw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinesOptions {
    /// Edges whose adjacent normals differ by more than this (degrees) are creases.
    pub crease_deg: f64,
    /// Keep the hidden pieces too (drawn dashed).
    pub hidden: bool,
    /// Recount the QI of every piece by ray casting and count disagreements.
    pub verify: bool,
}

impl Default for LinesOptions {
    fn default() -> Self {
        LinesOptions {
            crease_deg: 30.0,
            hidden: false,
            verify: false,
        }
    }
}

/// Why an edge is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EdgeKind {
    /// One adjacent triangle (or more than two).
    Boundary,
    /// One adjacent triangle faces the eye, the other away.
    Silhouette,
    /// The adjacent normals differ by more than the crease angle.
    Crease,
}

impl EdgeKind {
    /// The name used in the SVG's class attribute.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            EdgeKind::Boundary => "boundary",
            EdgeKind::Silhouette => "silhouette",
            EdgeKind::Crease => "crease",
        }
    }
}

/// A piece of an edge with one QI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Start, in pixels.
    pub a: (f64, f64),
    /// End, in pixels.
    pub b: (f64, f64),
    /// Edge parameters of the start and end (0 … 1 along the edge).
    pub s: (f64, f64),
    /// The 3-D start and end.
    pub p: [DVec3; 2],
    /// Why its edge is drawn.
    pub kind: EdgeKind,
    /// Occluders in front of it (0: visible).
    pub qi: u32,
    /// The edge's own triangles (the second is `u32::MAX` for a boundary).
    pub tris: [u32; 2],
}

/// Counters of one drawing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinesStats {
    /// Mesh edges.
    pub edges: usize,
    /// Edges drawn (boundaries, silhouettes, creases in front of the near plane).
    pub drawn_edges: usize,
    /// Contour edges (boundaries and silhouettes).
    pub contours: usize,
    /// Crossings where an edge passes behind a contour (QI changes).
    pub qi_changes: u64,
    /// Rays cast for the QI at edge starts (more than one where a ray ties).
    pub start_rays: u64,
    /// Visible pieces.
    pub visible: usize,
    /// Hidden pieces.
    pub hidden: usize,
    /// With `verify`: pieces whose recounted QI differs from Appel's.
    pub mismatches: usize,
    /// With `verify`: pieces recounted (those at least 0.05 px long whose
    /// ray does not tie).
    pub verified: usize,
    /// Roberts: objects (each a convex polyhedron).
    pub objects: usize,
    /// Roberts: edges culled with their back faces (both triangles face away).
    pub culled: usize,
    /// Roberts: front faces kept after back-face culling.
    pub faces: usize,
    /// Roberts: silhouette planes (one per silhouette edge of each object).
    pub silhouette_planes: usize,
    /// Roberts: edge–polyhedron pairs considered (the edge's own object aside).
    pub pairs: u64,
    /// Roberts: pairs rejected by their bounding boxes (screen and depth).
    pub box_rejected: u64,
    /// Roberts: clips of an edge's parameter interval against one plane.
    pub plane_tests: u64,
    /// Roberts: pairs where the polyhedron hides part of the edge.
    pub hidden_intervals: u64,
}

/// A hidden-line drawing.
#[derive(Clone, Debug, PartialEq)]
pub struct Drawing {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The pieces: every visible one, and the hidden ones if asked for.
    pub segments: Vec<Segment>,
    /// What it took.
    pub stats: LinesStats,
}

/// An edge to walk: its 3-D endpoints (clipped to the near plane), the
/// projected ones, and its triangles.
#[derive(Clone, Copy, Debug)]
struct Edge {
    p: [DVec3; 2],
    /// Pixels.
    q: [(f64, f64); 2],
    kind: EdgeKind,
    tris: [u32; 2],
    /// Position indices of the endpoints (shared endpoints meet, they do
    /// not cross).
    v: [u32; 2],
    /// For a contour: which side (sign of the 2-D cross product) its
    /// occluding triangles cover, and how many they are.
    cover: f64,
    occluders: u32,
}

/// A mesh edge: its position indices, up to two triangles, and how many
/// triangles use it.
type EdgeEntry = ((u32, u32), [u32; 2], u32);

/// A segment clipped to the near plane: its 3-D and screen endpoints.
type Clipped = ([DVec3; 2], [(f64, f64); 2]);

/// Triangle facing: `true` when its counter-clockwise side faces the eye.
fn front_facing(scene: &TriScene, cam: &Camera, t: u32) -> bool {
    let v = scene.triangle_f64(t);
    let n = (v[1] - v[0]).cross(v[2] - v[0]);
    match cam.projection() {
        Projection::Perspective { .. } => n.dot(cam.eye() - v[0]) > 0.0,
        Projection::Orthographic { .. } => n.dot(-cam.forward()) > 0.0,
    }
}

/// Draws the visible edges of a scene.
#[must_use]
pub fn hidden_lines(scene: &TriScene, accel: &Accel<'_>, opts: &LinesOptions) -> Drawing {
    let ctx = Ctx {
        b: Base::new(scene, opts),
        accel,
    };
    let cam = ctx.b.cam;

    // 1. The mesh edges and their triangles.
    let keys = mesh_edges(scene);
    let mut stats = LinesStats {
        edges: keys.len(),
        ..LinesStats::default()
    };
    let edges = ctx.b.drawn_edges(&keys);
    stats.drawn_edges = edges.len();
    let contours = contour_indices(&edges);
    stats.contours = contours.len();

    // 2. A screen grid of the contours.
    let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
    let grid = Grid::new(w, h, &edges, &contours);

    // 3. Walk every edge.
    let results: Vec<(Vec<Segment>, LinesStats)> = (0..edges.len())
        .into_par_iter()
        .map(|i| ctx.walk_edge(i, &edges, &grid))
        .collect();
    let segments = gather(results, &mut stats);
    Drawing {
        width: cam.width(),
        height: cam.height(),
        segments,
        stats,
    }
}

/// The mesh edges (position indices, the smaller first) with up to two of
/// their triangles and how many triangles use them, ordered by the
/// position indices.
fn mesh_edges(scene: &TriScene) -> Vec<EdgeEntry> {
    let mut map: HashMap<(u32, u32), ([u32; 2], u32)> = HashMap::with_capacity(scene.len() * 3 / 2);
    for (t, tri) in scene.tris.iter().enumerate() {
        let t = u32::try_from(t).unwrap_or(u32::MAX);
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            let e = map.entry(key).or_insert(([u32::MAX; 2], 0));
            if e.1 < 2 {
                e.0[e.1 as usize] = t;
            }
            e.1 += 1;
        }
    }
    let mut keys: Vec<EdgeEntry> = map.iter().map(|(k, v)| (*k, v.0, v.1)).collect();
    keys.sort_unstable_by_key(|k| k.0);
    keys
}

/// The indices of the contours that change the QI of what passes behind
/// them: the boundaries and silhouettes with occluding triangles on one
/// definite side.
fn contour_indices(edges: &[Edge]) -> Vec<u32> {
    edges
        .iter()
        .enumerate()
        .filter(|(_, e)| e.kind != EdgeKind::Crease && e.occluders > 0 && e.cover != 0.0)
        .map(|(i, _)| u32::try_from(i).unwrap_or(u32::MAX))
        .collect()
}

/// Concatenates the pieces of every edge, in edge order, and adds the
/// counters of the walks to `stats`.
fn gather(results: Vec<(Vec<Segment>, LinesStats)>, stats: &mut LinesStats) -> Vec<Segment> {
    let mut segments = Vec::new();
    for (segs, st) in results {
        segments.extend(segs);
        stats.qi_changes += st.qi_changes;
        stats.start_rays += st.start_rays;
        stats.visible += st.visible;
        stats.hidden += st.hidden;
        stats.mismatches += st.mismatches;
        stats.verified += st.verified;
    }
    segments
}

/// What the steps of one drawing share, by either method: the scene and
/// its camera, the options, and what decides which triangles occlude.
struct Base<'a> {
    scene: &'a TriScene,
    cam: &'a Camera,
    opts: &'a LinesOptions,
    /// Per triangle: whether it faces the eye.
    facing: Vec<bool>,
    /// Per object: whether its mesh is closed.
    closed: Vec<bool>,
    /// The cosine of the crease angle.
    cos_crease: f64,
}

impl<'a> Base<'a> {
    /// Finds the facing of every triangle (in parallel) and which objects
    /// are closed.
    fn new(scene: &'a TriScene, opts: &'a LinesOptions) -> Self {
        let cam = &scene.camera;
        let facing: Vec<bool> = (0..scene.len())
            .into_par_iter()
            .map(|t| front_facing(scene, cam, u32::try_from(t).unwrap_or(0)))
            .collect();
        let closed: Vec<bool> = scene.objects.iter().map(|o| o.closed).collect();
        Base {
            scene,
            cam,
            opts,
            facing,
            closed,
            cos_crease: opts.crease_deg.to_radians().cos(),
        }
    }

    /// Whether triangle `t` hides what is behind it: a front face, or any
    /// face of an open object.
    fn occluder(&self, t: u32) -> bool {
        self.facing[t as usize] || !self.closed[self.scene.tri_object[t as usize] as usize]
    }

    /// The edges to draw, in the order of `keys`: the boundaries,
    /// silhouettes and creases, clipped to the near plane and projected.
    fn drawn_edges(&self, keys: &[EdgeEntry]) -> Vec<Edge> {
        keys.iter()
            .filter_map(|&entry| self.drawn_edge(entry))
            .collect()
    }

    /// One mesh edge as an edge to draw, or `None` where it is not drawn
    /// (neither boundary, silhouette nor crease) or lies wholly behind the
    /// near plane.
    fn drawn_edge(&self, ((va, vb), tris, count): EdgeEntry) -> Option<Edge> {
        let kind = self.classify(tris, count)?;
        let tris = if count == 2 {
            tris
        } else {
            [tris[0], u32::MAX]
        };
        let p = [
            to_f64(self.scene.positions[va as usize]),
            to_f64(self.scene.positions[vb as usize]),
        ];
        let (p, q) = clip_and_project(self.cam, p)?;
        let (cover, occluders) = self.cover(kind, tris, [va, vb], q);
        Some(Edge {
            p,
            q,
            kind,
            tris,
            v: [va, vb],
            cover,
            occluders,
        })
    }

    /// Why an edge with triangles `tris` (`count` of them) is drawn: a
    /// boundary, a silhouette, a crease, or `None` for an edge between
    /// triangles that face the same way and meet at a shallow angle.
    fn classify(&self, tris: [u32; 2], count: u32) -> Option<EdgeKind> {
        if count != 2 {
            Some(EdgeKind::Boundary)
        } else if self.facing[tris[0] as usize] != self.facing[tris[1] as usize] {
            Some(EdgeKind::Silhouette)
        } else {
            let n0 = to_f64(self.scene.geometric_normal(tris[0]));
            let n1 = to_f64(self.scene.geometric_normal(tris[1]));
            (n0.dot(n1) < self.cos_crease).then_some(EdgeKind::Crease)
        }
    }

    /// For a contour between positions `v` projected to `q`: which side
    /// (sign of the 2-D cross product) its occluding triangles cover, and
    /// how many they are; `(0.0, 0)` for a crease.
    fn cover(&self, kind: EdgeKind, tris: [u32; 2], v: [u32; 2], q: [(f64, f64); 2]) -> (f64, u32) {
        let (mut cover, mut occluders) = (0.0, 0);
        if kind == EdgeKind::Crease {
            return (cover, occluders);
        }
        for &t in tris.iter().filter(|&&t| t != u32::MAX) {
            if !self.occluder(t) {
                continue;
            }
            let third = self.scene.tris[t as usize]
                .into_iter()
                .find(|&x| x != v[0] && x != v[1])
                .map(|x| to_f64(self.scene.positions[x as usize]));
            if let Some(side) = third
                .and_then(|x| self.cam.project(x))
                .map(|(x, y, _)| cross2(q[0], q[1], (x, y)))
            {
                cover = side;
                occluders += 1;
            }
        }
        (cover, occluders)
    }

    /// The pieces of `e` between consecutive `bounds` with QIs `qis`
    /// (recounted by a ray through `accel` with `verify`), counted in
    /// `st`: the visible ones, and the hidden ones too if asked for.
    fn pieces(
        &self,
        accel: Option<&Accel<'_>>,
        e: &Edge,
        bounds: &[f64],
        qis: &[i64],
        st: &mut LinesStats,
    ) -> Vec<Segment> {
        let cam = self.cam;
        let mut out = Vec::new();
        for (j, &qi) in qis.iter().enumerate() {
            let (s_a, s_b) = (bounds[j], bounds[j + 1]);
            if s_b - s_a <= 1e-12 {
                continue;
            }
            let mut qi = u32::try_from(qi.max(0)).unwrap_or(0);
            // A piece much shorter than a pixel lies between crossings
            // so close that a ray through its middle grazes both
            // contours: too short to recount reliably.
            // A recount that ties (its ray runs exactly along a contour)
            // cannot tell, and is not used.
            if let Some(accel) = accel.filter(|_| self.opts.verify)
                && screen_length(cam, e, s_a, s_b) >= 0.05
            {
                let mid = lerp3(e.p, 0.5 * (s_a + s_b));
                let (recount, tie) = self.count_occluders(accel, mid, e.tris);
                if !tie {
                    st.verified += 1;
                    if recount != qi {
                        st.mismatches += 1;
                        qi = recount;
                    }
                }
            }
            if qi == 0 {
                st.visible += 1;
            } else {
                st.hidden += 1;
            }
            if qi == 0 || self.opts.hidden {
                out.push(Segment {
                    a: project2(cam, lerp3(e.p, s_a), e.q[0]),
                    b: project2(cam, lerp3(e.p, s_b), e.q[1]),
                    s: (s_a, s_b),
                    p: [lerp3(e.p, s_a), lerp3(e.p, s_b)],
                    kind: e.kind,
                    qi,
                    tris: e.tris,
                });
            }
        }
        out
    }

    /// The occluders between the eye and `point`, not counting the
    /// triangles `own`, by one ray; and whether the count is a *tie*: the
    /// ray met a counted triangle within [`GRAZE`] (barycentric) of its
    /// boundary. Where that boundary is a contour seen exactly along its
    /// plane (a face edge on: the eye in its plane) the watertight test
    /// gives the hit to one side, as it must for a mesh, but whether the
    /// point is behind the surface is then a matter of that choice.
    fn count_occluders(&self, accel: &Accel<'_>, point: DVec3, own: [u32; 2]) -> (u32, bool) {
        let cam = self.cam;
        let origin = match cam.projection() {
            Projection::Perspective { .. } => cam.eye(),
            Projection::Orthographic { .. } => point - cam.forward() * cam.view_depth(point),
        };
        let d = point - origin;
        let len = d.length();
        if len == 0.0 || !len.is_finite() {
            return (0, false);
        }
        let ray = Ray64 {
            origin,
            dir: d / len,
            t_min: 0.0,
            t_max: len * (1.0 - 1e-6),
        };
        let mut hits: Vec<f32> = Vec::new();
        let mut tie = false;
        accel.for_each_triangle_hit(&ray, |t, hit| {
            if !own.contains(&t) && self.occluder(t) {
                hits.push(hit.t);
                tie |= hit.b.iter().any(|&b| b.abs() < GRAZE);
            }
            false
        });
        // A ray through a shared edge may hit both triangles: count a
        // distance once.
        hits.sort_by(f32::total_cmp);
        hits.dedup_by(|a, b| (*a - *b).abs() <= 1e-6 * b.abs().max(1e-12));
        (u32::try_from(hits.len()).unwrap_or(u32::MAX), tie)
    }
}

/// A ray that meets a triangle this close to its boundary (in barycentric
/// weight, f32 from the watertight test: about 8 ulps of 1 above its
/// rounding) may be passing along a contour exactly; its count is a tie.
const GRAZE: f32 = 1e-6;

/// The points where Appel's walk may count the QI of an edge: in the
/// pieces from the longest down, at these fractions of each.
const START_FRACTIONS: [f64; 3] = [0.5, 0.25, 0.75];

/// At most this many start rays per edge before the first count is used
/// even if it is a tie.
const MAX_START_RAYS: u64 = 8;

/// Appel's walk: the shared steps and the BVH that counts and pierces.
struct Ctx<'a, 's> {
    b: Base<'a>,
    accel: &'a Accel<'s>,
}

impl Ctx<'_, '_> {
    /// Walks edge `i`: its pieces between QI changes, with their QIs,
    /// merged where consecutive ones agree, and the counters of the walk.
    fn walk_edge(&self, i: usize, edges: &[Edge], grid: &Grid) -> (Vec<Segment>, LinesStats) {
        let e = &edges[i];
        let mut st = LinesStats::default();
        let events = self.qi_events(i, edges, grid);
        st.qi_changes = events.len() as u64;
        let mut bounds = Vec::with_capacity(events.len() + 2);
        bounds.push(0.0);
        bounds.extend(events.iter().map(|e| e.0));
        bounds.push(1.0);
        let (qis, rays) = self.piece_qis(e, &bounds, &events);
        st.start_rays = rays;
        let out = self.b.pieces(Some(self.accel), e, &bounds, &qis, &mut st);
        (merge(out), st)
    }

    /// The QI changes along edge `i`, at 3-D edge parameters λ, in order:
    /// where it passes behind a nearer contour, and where it pierces an
    /// occluding triangle.
    fn qi_events(&self, i: usize, edges: &[Edge], grid: &Grid) -> Vec<(f64, i32)> {
        let e = &edges[i];
        let mut events: Vec<(f64, i32)> = Vec::new();
        grid.for_each_near(e, |c| {
            if c as usize == i {
                return;
            }
            if let Some(event) = self.crossing(e, &edges[c as usize]) {
                events.push(event);
            }
        });
        // Where the edge pierces an occluding triangle (surfaces that
        // pass through each other): behind it from there on if the
        // edge goes away from the eye, in front of it if toward.
        self.pierce(e, &mut events);
        events.sort_by(|a, b| a.0.total_cmp(&b.0));
        events
    }

    /// Where edge `e` passes behind contour `ce` on the screen: the edge
    /// parameter λ of the crossing and the QI change there (up by the
    /// contour's occluders where `e` enters the side they cover, down
    /// where it leaves it); `None` where they share an endpoint, do not
    /// cross, or the contour is not nearer.
    fn crossing(&self, e: &Edge, ce: &Edge) -> Option<(f64, i32)> {
        let cam = self.b.cam;
        if ce.v.iter().any(|v| e.v.contains(v)) {
            return None;
        }
        let (s, u) = intersect2(e.q, ce.q)?;
        // Depths at the crossing, on each edge's own 3-D segment.
        let (Some(le), Some(lc)) = (param_at(cam, e, s), param_at(cam, ce, u)) else {
            return None;
        };
        let ze = cam.view_depth(lerp3(e.p, le));
        let zc = cam.view_depth(lerp3(ce.p, lc));
        if zc >= ze * (1.0 - 1e-9) {
            return None;
        }
        let dir = cross2(
            ce.q[0],
            ce.q[1],
            (
                ce.q[0].0 + e.q[1].0 - e.q[0].0,
                ce.q[0].1 + e.q[1].1 - e.q[0].1,
            ),
        );
        let entering = dir.signum() == ce.cover.signum();
        let change = i32::try_from(ce.occluders).unwrap_or(0);
        Some((le, if entering { change } else { -change }))
    }

    /// Adds to `events` where edge `e` pierces an occluding triangle other
    /// than its own and those at its endpoints: +1 where it goes behind
    /// the triangle, −1 where it comes out in front.
    fn pierce(&self, e: &Edge, events: &mut Vec<(f64, i32)>) {
        let d = e.p[1] - e.p[0];
        let len = d.length();
        if len == 0.0 || !len.is_finite() {
            return;
        }
        let ray = Ray64 {
            origin: e.p[0],
            dir: d / len,
            t_min: len * 1e-6,
            t_max: len * (1.0 - 1e-6),
        };
        self.accel.for_each_triangle_hit(&ray, |t, hit| {
            let tri = self.b.scene.tris[t as usize];
            if e.tris.contains(&t)
                || tri.contains(&e.v[0])
                || tri.contains(&e.v[1])
                || !self.b.occluder(t)
            {
                return false;
            }
            // The start on the eye's side: the edge goes behind it.
            let change = if self.eye_side(t, e.p[0]) > 0.0 {
                1
            } else {
                -1
            };
            events.push((hit.t64 / len, change));
            false
        });
    }

    /// Whether point `p` lies on the eye's side of triangle `t`'s plane:
    /// 1 if so, −1 if not (the sign of a product of plane distances).
    fn eye_side(&self, t: u32, p: DVec3) -> f64 {
        let v = self.b.scene.triangle_f64(t);
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let toward = match self.b.cam.projection() {
            Projection::Perspective { .. } => self.b.cam.eye() - v[0],
            Projection::Orthographic { .. } => -self.b.cam.forward(),
        };
        (n.dot(p - v[0]) * n.dot(toward)).signum()
    }

    /// The QI of each piece of `e` between consecutive `bounds`, and the
    /// rays cast. One ray counts the QI of the longest piece (at its
    /// middle: away from the vertices and the crossings, where nearby
    /// surfaces make a count ambiguous), and the `events` carry it to the
    /// others. Where that count is a tie (the ray runs exactly along a
    /// contour), other points are tried — a quarter and three quarters
    /// along, then the next longest pieces — up to [`MAX_START_RAYS`];
    /// if every one ties, the first count stands.
    fn piece_qis(&self, e: &Edge, bounds: &[f64], events: &[(f64, i32)]) -> (Vec<i64>, u64) {
        let n = bounds.len() - 1;
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| {
            (bounds[b + 1] - bounds[b])
                .total_cmp(&(bounds[a + 1] - bounds[a]))
                .then(a.cmp(&b))
        });
        let mut first = None;
        let mut rays = 0u64;
        let mut start = None;
        'pieces: for &k in &order {
            for f in START_FRACTIONS {
                if rays >= MAX_START_RAYS {
                    break 'pieces;
                }
                let s = bounds[k] + f * (bounds[k + 1] - bounds[k]);
                let (qi, tie) = self.b.count_occluders(self.accel, lerp3(e.p, s), e.tris);
                rays += 1;
                first.get_or_insert((k, qi));
                if !tie {
                    start = Some((k, qi));
                    break 'pieces;
                }
            }
        }
        let (k, qi) = start.or(first).unwrap_or((0, 0));
        let mut qis = vec![0i64; n];
        qis[k] = i64::from(qi);
        for j in k + 1..qis.len() {
            qis[j] = qis[j - 1] + i64::from(events[j - 1].1);
        }
        for j in (0..k).rev() {
            qis[j] = qis[j + 1] - i64::from(events[j].1);
        }
        (qis, rays)
    }
}

/// The screen length of the piece of `e` between edge parameters `s_a`
/// and `s_b`.
fn screen_length(cam: &Camera, e: &Edge, s_a: f64, s_b: f64) -> f64 {
    let (a, b) = (
        project2(cam, lerp3(e.p, s_a), e.q[0]),
        project2(cam, lerp3(e.p, s_b), e.q[1]),
    );
    (b.0 - a.0).hypot(b.1 - a.1)
}

/// Joins consecutive pieces of one edge with the same QI.
fn merge(segs: Vec<Segment>) -> Vec<Segment> {
    let mut out: Vec<Segment> = Vec::with_capacity(segs.len());
    for s in segs {
        if let Some(last) = out.last_mut()
            && last.qi == s.qi
            && last.s.1 == s.s.0
        {
            last.b = s.b;
            last.s.1 = s.s.1;
            last.p[1] = s.p[1];
            continue;
        }
        out.push(s);
    }
    out
}

fn lerp3(p: [DVec3; 2], s: f64) -> DVec3 {
    p[0] + (p[1] - p[0]) * s
}

/// The screen point of a 3-D point on an edge (clipped to the near plane,
/// so it projects; `fallback` otherwise).
fn project2(cam: &Camera, p: DVec3, fallback: (f64, f64)) -> (f64, f64) {
    cam.project(p).map_or(fallback, |(x, y, _)| (x, y))
}

/// Clips a segment to the near plane and projects it.
fn clip_and_project(cam: &Camera, p: [DVec3; 2]) -> Option<Clipped> {
    let near = cam.near();
    let z = [cam.view_depth(p[0]), cam.view_depth(p[1])];
    let p = match (z[0] >= near, z[1] >= near) {
        (true, true) => p,
        (false, false) => return None,
        (a_in, _) => {
            let t = (near - z[0]) / (z[1] - z[0]);
            let m = p[0] + (p[1] - p[0]) * t;
            if a_in { [p[0], m] } else { [m, p[1]] }
        }
    };
    let a = cam.project(p[0])?;
    let b = cam.project(p[1])?;
    if ![a.0, a.1, b.0, b.1].iter().all(|v| v.is_finite()) {
        return None;
    }
    Some((p, [(a.0, a.1), (b.0, b.1)]))
}

/// `(b − a) × (c − a)` in 2-D.
fn cross2(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> f64 {
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// The crossing of two screen segments strictly inside both: the
/// parameters along each.
fn intersect2(e: [(f64, f64); 2], c: [(f64, f64); 2]) -> Option<(f64, f64)> {
    let r = (e[1].0 - e[0].0, e[1].1 - e[0].1);
    let q = (c[1].0 - c[0].0, c[1].1 - c[0].1);
    let den = r.0 * q.1 - r.1 * q.0;
    let scale = (r.0.abs() + r.1.abs()) * (q.0.abs() + q.1.abs());
    if den.abs() <= 1e-12 * scale || scale == 0.0 {
        return None;
    }
    let w = (c[0].0 - e[0].0, c[0].1 - e[0].1);
    let s = (w.0 * q.1 - w.1 * q.0) / den;
    let u = (w.0 * r.1 - w.1 * r.0) / den;
    let eps = 1e-9;
    (s > eps && s < 1.0 - eps && u > eps && u < 1.0 - eps).then_some((s, u))
}

/// The 3-D parameter λ (along `e.p`) of the point that projects to the
/// screen point at parameter `s` of the projected segment (perspective
/// projection is not linear along the 3-D segment).
fn param_at(cam: &Camera, e: &Edge, s: f64) -> Option<f64> {
    match cam.projection() {
        Projection::Orthographic { .. } => Some(s),
        Projection::Perspective { .. } => {
            // Screen coordinates are X/z: along the 3-D segment X and z are
            // linear in λ, so λ solves X(λ) − x·z(λ) = 0 (in the coordinate
            // that moves most).
            let (x, y) = (
                e.q[0].0 + (e.q[1].0 - e.q[0].0) * s,
                e.q[0].1 + (e.q[1].1 - e.q[0].1) * s,
            );
            let z = [cam.view_depth(e.p[0]), cam.view_depth(e.p[1])];
            let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
            let ndc = |(px, py): (f64, f64)| (px / w * 2.0 - 1.0, 1.0 - py / h * 2.0);
            let (nx, ny) = ndc((x, y));
            let (a0, b0) = ndc(e.q[0]);
            let (a1, b1) = ndc(e.q[1]);
            // X_i = ndc_i · z_i (up to a constant factor).
            let (x0, x1, y0, y1) = (a0 * z[0], a1 * z[1], b0 * z[0], b1 * z[1]);
            let dx = (x1 - x0) - nx * (z[1] - z[0]);
            let dy = (y1 - y0) - ny * (z[1] - z[0]);
            let lambda = if dx.abs() >= dy.abs() {
                (nx * z[0] - x0) / dx
            } else {
                (ny * z[0] - y0) / dy
            };
            lambda.is_finite().then(|| lambda.clamp(0.0, 1.0))
        }
    }
}

/// A uniform screen grid of contour edges (16-pixel cells).
struct Grid {
    cell: f64,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<u32>>,
}

impl Grid {
    const CELL: f64 = 16.0;

    fn new(w: f64, h: f64, edges: &[Edge], contours: &[u32]) -> Grid {
        let cell = Self::CELL;
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "image sides are below 2^14"
        )]
        let (nx, ny) = (
            (w / cell).ceil().max(1.0) as usize,
            (h / cell).ceil().max(1.0) as usize,
        );
        let mut g = Grid {
            cell,
            nx,
            ny,
            cells: vec![Vec::new(); nx * ny],
        };
        for &c in contours {
            let e = &edges[c as usize];
            let mut ks = Vec::new();
            g.visit_cells(e.q, |k| ks.push(k));
            for k in ks {
                g.cells[k].push(c);
            }
        }
        g
    }

    /// Calls `f` for every cell index the segment's bounding box covers
    /// (clamped to the screen).
    fn visit_cells(&self, q: [(f64, f64); 2], mut f: impl FnMut(usize)) {
        let clamp = |v: f64, n: usize| {
            #[expect(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                clippy::cast_precision_loss,
                reason = "clamped to the grid (at most a few thousand cells: exact in f64)"
            )]
            let k = (v / self.cell).floor().clamp(0.0, (n - 1) as f64) as usize;
            k
        };
        let (x0, x1) = (
            clamp(q[0].0.min(q[1].0), self.nx),
            clamp(q[0].0.max(q[1].0), self.nx),
        );
        let (y0, y1) = (
            clamp(q[0].1.min(q[1].1), self.ny),
            clamp(q[0].1.max(q[1].1), self.ny),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                f(y * self.nx + x);
            }
        }
    }

    /// Calls `f` once for every contour that may cross `e`.
    fn for_each_near(&self, e: &Edge, mut f: impl FnMut(u32)) {
        let mut seen: Vec<u32> = Vec::new();
        self.visit_cells(e.q, |k| seen.extend_from_slice(&self.cells[k]));
        seen.sort_unstable();
        seen.dedup();
        for c in seen {
            f(c);
        }
    }
}

/// The drawing as SVG: visible pieces solid, hidden ones (if kept) dashed
/// and grey; silhouettes and boundaries heavier than creases.
#[must_use]
pub fn to_svg(d: &Drawing) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">"#,
        w = d.width,
        h = d.height
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<g fill="none" stroke-linecap="round"><style>.silhouette,.boundary{{stroke:#111;stroke-width:1.4}} .crease{{stroke:#333;stroke-width:0.9}} .hidden{{stroke:#999;stroke-width:0.7;stroke-dasharray:3 2}}</style>"#
    );
    for seg in &d.segments {
        let class = if seg.qi == 0 {
            seg.kind.name()
        } else {
            "hidden"
        };
        let _ = writeln!(
            s,
            r#"<line class="{class}" x1="{:.3}" y1="{:.3}" x2="{:.3}" y2="{:.3}"/>"#,
            seg.a.0, seg.a.1, seg.b.0, seg.b.1
        );
    }
    s.push_str("</g>\n</svg>\n");
    s
}

/// The drawing as 8-bit RGBA pixels drawn with tiny-skia's anti-aliased
/// strokes.
#[must_use]
pub fn to_rgba(d: &Drawing) -> Vec<u8> {
    let Some(mut pm) = tiny_skia::Pixmap::new(d.width.max(1), d.height.max(1)) else {
        return vec![255; (d.width as usize) * (d.height as usize) * 4];
    };
    pm.fill(tiny_skia::Color::WHITE);
    for seg in &d.segments {
        let mut pb = tiny_skia::PathBuilder::new();
        #[expect(clippy::cast_possible_truncation, reason = "pixel coordinates")]
        {
            pb.move_to(seg.a.0 as f32, seg.a.1 as f32);
            pb.line_to(seg.b.0 as f32, seg.b.1 as f32);
        }
        let Some(path) = pb.finish() else { continue };
        let mut paint = tiny_skia::Paint {
            anti_alias: true,
            ..tiny_skia::Paint::default()
        };
        let mut stroke = tiny_skia::Stroke {
            line_cap: tiny_skia::LineCap::Round,
            ..tiny_skia::Stroke::default()
        };
        if seg.qi == 0 {
            paint.set_color_rgba8(17, 17, 17, 255);
            stroke.width = if seg.kind == EdgeKind::Crease {
                0.9
            } else {
                1.4
            };
        } else {
            paint.set_color_rgba8(150, 150, 150, 255);
            stroke.width = 0.7;
            stroke.dash = tiny_skia::StrokeDash::new(vec![3.0, 2.0], 0.0);
        }
        pm.stroke_path(
            &path,
            &paint,
            &stroke,
            tiny_skia::Transform::identity(),
            None,
        );
    }
    pm.data().to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_cross_only_inside() {
        let e = [(0.0, 0.0), (10.0, 0.0)];
        let c = [(5.0, -5.0), (5.0, 5.0)];
        let (s, u) = intersect2(e, c).unwrap();
        assert!((s - 0.5).abs() < 1e-12 && (u - 0.5).abs() < 1e-12);
        // Touching at an end is not a crossing.
        assert!(intersect2(e, [(10.0, -1.0), (10.0, 1.0)]).is_none());
        // Parallel.
        assert!(intersect2(e, [(0.0, 1.0), (10.0, 1.0)]).is_none());
    }
}
