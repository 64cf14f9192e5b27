//! Backend D: list priority that never fails — a BSP tree of the triangles
//! (Fuchs, Kedem & Naylor 1980), painted back to front on the rasterizer's
//! sample grid.
//!
//! The painter orders whole triangles, and a cyclic overlap or two
//! triangles through each other defeat every such order. A BSP tree
//! splits each triangle by the planes of others until every piece lies on
//! one side of every plane above it; walking the tree from the side away
//! from the eye to the side of the eye then gives an order that is right
//! everywhere.
//!
//! **The space.** The tree is built in *screen-depth space*: `(X, Y, q)`
//! with `(X, Y)` the screen point in pixels and `q` the nearness, `1/z`
//! for a perspective camera (`z` the view depth) and `−z` for an
//! orthographic one. The map from view space is projective (affine for
//! orthographic), and every point it sees lies in front of the eye (the
//! triangles are clipped at the near plane first), so planes stay planes
//! and sides stay sides: the tree is a BSP tree of the view-space
//! triangles. Two things are simpler there: the eye is at `q = +∞` for
//! both projections, so the eye's side of a plane is always its nearer
//! side; and the plane of a triangle is `q = m·(X, Y, 1)`, the very depth
//! plane the z-buffer interpolates (`1/z` is linear on the screen), so
//! "in front of that plane" is the z-buffer's own depth test.
//!
//! **Pieces tile their triangle exactly.** A piece is never scan-converted
//! on its own: the triangle keeps its records (the same clipping,
//! snapping and coverage rule as the z-buffer), and each split of a piece
//! of triangle G by the plane of triangle P adds a node to G's *cut tree*:
//! the screen line `L(X, Y) = q_G(X, Y) − q_P(X, Y) = 0`, where G's and
//! P's depth planes cross, with the piece in front of P on the side
//! `L > 0` and the one behind on `L < 0` (on `L = 0` the depths are equal,
//! and the sample goes where the lower id wins, as in the z-buffer). A
//! sample the coverage rule gives to G descends G's cut tree, one
//! evaluation of one shared line per level, to exactly one leaf: the two
//! pieces of a cut share the cut
//! itself, computed once, so every sample of G lies in exactly one of its
//! pieces — no slivers, no cracks, no double hits, whatever the rounding.
//! The pieces keep G's id, so shading (barycentrics from the f64 camera
//! ray on G, as in the z-buffer) is G's, bit for bit.
//!
//! **Robustness.** The polygons the tree classifies are the triangles'
//! unsnapped clipped polygons in f64. A vertex is *on* a plane when its
//! signed nearness difference is within a bound of the rounding of both
//! (`on_plane_bound`, derived in ARCHITECTURE.md), so a triangle that
//! shares an edge with another, or lies in its plane, is not split by it;
//! triangles of one plane share a node and are drawn higher id first, so
//! the lower id ends on top, as the z-buffer breaks equal depths. A cut
//! point is computed once per polygon edge, from its endpoints in a
//! canonical order, and given to both halves.
//!
//! **Painting.** The walk gives every piece a rank (its place in the
//! back-to-front order); a sample shows the piece of highest rank among
//! those that cover it, which is the picture painting the pieces in rank
//! order would leave, computed per sample so that it does not depend on
//! the order the bands are scanned in.

use std::time::Instant;

use super::clip::HVert;
use super::{
    Clipped, RasterOptions, RasterStats, Rule, SetupCtx, clamped_screen, clip_triangle,
    homogeneous, primary_records, shade_pass, triangle_planes, visibility_with,
};
use rendiff_core::budget::{Budget, OverBudget};
use rendiff_core::camera::Projection;
use rendiff_core::coverage::SampleGrid;
use rendiff_core::frame::Frame;
use rendiff_core::math::{DVec3, to_f64};
use rendiff_core::tri_scene::TriScene;

/// No node, no piece, no triangle.
const NONE: u32 = u32::MAX;

/// Splitter candidates tried at each node, evenly spaced through its
/// fragments (and the largest fragment besides).
const CANDIDATES: usize = 8;

/// Fragments each candidate is tried against (evenly spaced).
const TRIAL: usize = 64;

/// What a split costs against imbalance when candidates are scored:
/// `SPLIT_WEIGHT · splits + |front − back|` over the trial fragments.
const SPLIT_WEIGHT: usize = 8;

/// The rounding of one coordinate of a point in screen-depth space, in
/// units of `f64::EPSILON` times the magnitude it is measured against:
/// world → view (a subtraction and three-term dot products: 4), the
/// projection (3), the near/far/guard clip's interpolation (3) and the
/// divide by `w` (1) make 11; rounded up.
const POINT_ULPS: f64 = 16.0;

/// Bytes the budget is asked for at a time while the tree grows.
const RESERVE_STEP: u64 = 1 << 20;

/// What the tree made.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BspStats {
    /// Triangles that entered the tree (those that cover a sample row,
    /// after the plan's culling).
    pub triangles: usize,
    /// Pieces drawn: the leaves of all cut trees (`triangles + splits`).
    pub pieces: usize,
    /// Fragments split in two.
    pub splits: usize,
    /// Nodes of the tree (one splitting plane each).
    pub nodes: usize,
    /// Fragments that lay in a node's plane besides its splitter (drawn
    /// at that node, higher id first).
    pub coplanar: usize,
    /// Depth of the deepest node (the root is 1).
    pub depth: usize,
    /// Fragment-against-plane classifications made (candidate trials
    /// included): the build's work, independent of the machine.
    pub classified: u64,
    /// Wall time of building the tree and ranking its pieces (ms).
    pub build_ms: f64,
}

/// A triangle in the tree: its depth plane in screen-depth space, and the
/// data of the bound on the rounding of everything computed from it.
///
/// The plane is the z-buffer's: `q(X, Y) = m0·(X − ax) + m1·(Y − ay) + m2`
/// with `q = Σ λ_j` (perspective, `λ_j = b_j/w` the 2-D homogeneous
/// barycentric planes of Olano & Greer) or `q = −Σ λ_j z_j`
/// (orthographic). Its vertices `h_j = (X_j w_j, Y_j w_j, w_j)` (and `z_j`)
/// were rounded; with `u` the plane's coefficients on `(X, Y, 1)`, a
/// perturbation `δh_j` moves the plane's value at a point by
/// `−Σ_j λ_j(X, Y)·(u·δh_j)` (plus `Σ_j λ_j δz_j` orthographic), to first
/// order — so the plane's error at a point is bounded by
/// `Σ_j |λ_j(X, Y)|·C_j` times the rounding unit, where `C_j` is vertex
/// j's rounding magnitude measured along `u` (`c`). Far from the triangle
/// the weights grow and the bound with them: a plane extrapolated far, or
/// of a sliver, is known only that well.
#[derive(Clone, Copy, Debug)]
struct Source {
    tri: u32,
    /// The nearness plane.
    m: [f64; 3],
    ax: f64,
    ay: f64,
    /// The barycentric planes `λ_j`, on the same anchor.
    lambda: [[f64; 3]; 3],
    /// `C_j`: `|u0|·Δxh_j + |u1|·Δyh_j + |u2|·Δw_j (+ Δz_j)`, the
    /// magnitudes each coordinate of vertex j was rounded against.
    c: [f64; 3],
    /// Bounds (without the rounding unit) on how far the rounding moved
    /// any point of the triangle's polygon in X, Y and q.
    e: [f64; 3],
}

impl Source {
    /// The nearness of the plane at `(x, y)`.
    fn q(&self, x: f64, y: f64) -> f64 {
        self.m[0] * (x - self.ax) + self.m[1] * (y - self.ay) + self.m[2]
    }
}

/// A fragment: a convex polygon of a source triangle, a leaf of its cut
/// tree.
#[derive(Clone, Copy, Debug)]
struct Frag {
    /// Index into the sources.
    src: u32,
    /// Its leaf in the cut arena.
    leaf: u32,
    /// Its vertices `(X, Y, q)` in the arena.
    start: u32,
    len: u32,
    /// How many splits made it (each interpolation adds its rounding).
    generation: u32,
    /// Screen area (px²), for the choice of splitters.
    area: f64,
}

/// A node of a cut tree: a leaf (a piece and its rank), or a line with
/// the pieces in front of the cutting plane (`L > 0`) and behind it
/// (`L < 0`); where `L = 0` the two depths are equal, and the sample goes
/// to the side that makes the lower triangle id win, as in the z-buffer.
#[derive(Clone, Copy, Debug)]
struct Cut {
    /// `L(X, Y) = l0·(X − ax) + l1·(Y − ay) + l2` on the triangle's anchor.
    l: [f64; 3],
    /// The child in front, or [`NONE`] for a leaf.
    front: u32,
    /// The child behind, or a leaf's rank.
    back: u32,
    /// `L = 0` goes in front (drawn after the cutting triangle, so it
    /// wins): the cut triangle's id is the lower.
    tie_front: bool,
}

/// The pieces of every triangle and their drawing ranks: what the
/// visibility pass asks for each covered sample.
#[derive(Debug)]
pub(crate) struct Pieces {
    /// Per scene triangle: its source index, or [`NONE`].
    source_of: Vec<u32>,
    /// Per source: the anchor of its lines and the root of its cut tree.
    roots: Vec<(f64, f64, u32)>,
    cuts: Vec<Cut>,
}

impl Pieces {
    /// The rank of the piece of triangle `tri` that holds the screen point
    /// `(x, y)` (a sample the coverage rule gives to `tri`); 0 for a
    /// triangle that is not in the tree (it covers nothing).
    pub(crate) fn rank_at(&self, tri: u32, x: f64, y: f64) -> u32 {
        let Some(&s) = self.source_of.get(tri as usize) else {
            return 0;
        };
        let Some(&(ax, ay, root)) = self.roots.get(s as usize) else {
            return 0;
        };
        let (dx, dy) = (x - ax, y - ay);
        let mut c = root;
        loop {
            let Some(cut) = self.cuts.get(c as usize) else {
                return 0;
            };
            if cut.front == NONE {
                return cut.back;
            }
            let l = cut.l[0] * dx + cut.l[1] * dy + cut.l[2];
            c = if l > 0.0 || (l == 0.0 && cut.tie_front) {
                cut.front
            } else {
                cut.back
            };
        }
    }
}

/// A node of the tree: the fragments in its plane (in drawing order) and
/// its subtrees.
#[derive(Clone, Debug, Default)]
struct Node {
    on: Vec<u32>,
    back: Option<u32>,
    front: Option<u32>,
}

/// Where a fragment lies against a plane.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    On,
    Front,
    Back,
    Spanning,
}

/// The memory the tree holds in the budget, asked for in steps.
struct Held<'b> {
    budget: &'b Budget,
    reserved: u64,
}

impl Held<'_> {
    /// Makes sure `bytes` in all are reserved.
    fn grow_to(&mut self, bytes: u64, pieces: usize) -> Result<(), OverBudget> {
        while self.reserved < bytes {
            self.budget.reserve(RESERVE_STEP, || {
                format!("the BSP tree ({pieces} pieces so far)")
            })?;
            self.reserved += RESERVE_STEP;
        }
        Ok(())
    }
}

impl Drop for Held<'_> {
    fn drop(&mut self) {
        self.budget.release(self.reserved);
    }
}

/// Approximate bytes per fragment (its record, about four vertices, its
/// leaf and a list entry) and per node.
const FRAG_BYTES: u64 = 40 + 4 * 24 + 32 + 8;
const NODE_BYTES: u64 = 64;

/// The tree under construction.
struct Builder {
    sources: Vec<Source>,
    frags: Vec<Frag>,
    verts: Vec<[f64; 3]>,
    cuts: Vec<Cut>,
    nodes: Vec<Node>,
    stats: BspStats,
}

/// The rounding magnitudes of one vertex's homogeneous coordinates
/// `(Δxh, Δyh, Δw, Δz)`, without the rounding unit: each coordinate is
/// computed from the view vector (rounded against its length `R`, the
/// world → view transform) through the projection.
fn vertex_magnitudes(view: DVec3, projection: Projection, size: (f64, f64)) -> [f64; 4] {
    let r = view.x.abs() + view.y.abs() + view.z.abs();
    let (w, h) = size;
    let aspect = w / h;
    match projection {
        Projection::Perspective { tan_half_fov: t } => [
            r * (1.0 / (t * aspect) + 1.0) * w / 2.0,
            r * (1.0 / t + 1.0) * h / 2.0,
            r,
            r,
        ],
        Projection::Orthographic { view_height: vh } => [
            (r * 2.0 / (vh * aspect) + 1.0) * w / 2.0,
            (r * 2.0 / vh + 1.0) * h / 2.0,
            0.0,
            r,
        ],
    }
}

/// The bound on `s = q_v − q_P(X_v, Y_v)` for a vertex `v` of a fragment of
/// `g` made by `generation` splits, against the plane of `p`, at
/// `(dx, dy) = (X_v − p.ax, Y_v − p.ay)`:
///
/// `2·[POINT_ULPS·ε·(Σ_j |λ_j| C_j + |m0| e_X + |m1| e_Y + e_q)
///   + 3·generation·ε·(|m0 X| + |m1 Y| + |q|) + 5ε·(|m0 dx| + |m1 dy| + |m2| + |q|)]`
///
/// — P's plane's rounding at the point (its vertices' rounding through the
/// barycentric weights, see [`Source`]), the point's own rounding through
/// the plane's slope (`e` of its triangle), the interpolations that made
/// it (three roundings each, relative to its coordinates), and the
/// evaluation of `s` itself (five operations). The factor 2 covers the
/// second-order terms and the inverse's own rounding, which is of the
/// order of the input rounding counted with it.
fn on_plane_bound(p: &Source, g: &Source, v: [f64; 3], generation: u32, dx: f64, dy: f64) -> f64 {
    let eps = f64::EPSILON;
    let lam = |r: &[f64; 3]| (r[0] * dx + r[1] * dy + r[2]).abs();
    let extrapolated =
        lam(&p.lambda[0]) * p.c[0] + lam(&p.lambda[1]) * p.c[1] + lam(&p.lambda[2]) * p.c[2];
    let own = p.m[0].abs() * g.e[0] + p.m[1].abs() * g.e[1] + g.e[2];
    let magnitude = (p.m[0] * v[0]).abs() + (p.m[1] * v[1]).abs() + v[2].abs();
    let evaluation = (p.m[0] * dx).abs() + (p.m[1] * dy).abs() + p.m[2].abs() + v[2].abs();
    2.0 * (POINT_ULPS * eps * (extrapolated + own)
        + 3.0 * f64::from(generation) * eps * magnitude
        + 5.0 * eps * evaluation)
}

/// Where vertex `v` lies against the plane of `p`: +1 in front (nearer),
/// −1 behind, 0 on it; with its signed nearness difference.
fn vertex_side(p: &Source, g: &Source, v: [f64; 3], generation: u32) -> (i8, f64) {
    let (dx, dy) = (v[0] - p.ax, v[1] - p.ay);
    let s = v[2] - (p.m[0] * dx + p.m[1] * dy + p.m[2]);
    let bound = on_plane_bound(p, g, v, generation, dx, dy);
    if s > bound {
        (1, s)
    } else if s < -bound {
        (-1, s)
    } else {
        (0, s)
    }
}

/// Twice the signed area of a polygon's screen projection.
fn doubled_area(poly: &[[f64; 3]]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum()
}

/// Splits a convex polygon by the signs of its vertices (none zero on
/// both sides at once: at least one +1 and one −1): the part in front and
/// the part behind. Each edge with endpoints strictly on both sides is cut
/// once, from its endpoints in a canonical order (so the same edge gives
/// the same point whichever polygon holds it), and the point goes to both.
fn split_polygon(
    poly: &[[f64; 3]],
    sides: &[(i8, f64)],
    front: &mut Vec<[f64; 3]>,
    back: &mut Vec<[f64; 3]>,
) {
    front.clear();
    back.clear();
    let n = poly.len();
    for i in 0..n {
        let j = (i + 1) % n;
        let (a, b) = (poly[i], poly[j]);
        let ((ca, sa), (cb, sb)) = (sides[i], sides[j]);
        if ca >= 0 {
            front.push(a);
        }
        if ca <= 0 {
            back.push(a);
        }
        if ca * cb < 0 {
            let key = |v: [f64; 3]| v.map(f64::to_bits);
            let ((p, sp), (q, sq)) = if key(a) <= key(b) {
                ((a, sa), (b, sb))
            } else {
                ((b, sb), (a, sa))
            };
            // sp and sq have opposite signs: no cancellation, t ∈ [0, 1].
            let t = sp / (sp - sq);
            let c = [0, 1, 2].map(|k| p[k] + (q[k] - p[k]) * t);
            front.push(c);
            back.push(c);
        }
    }
}

impl Builder {
    /// The vertices of fragment `f`.
    fn poly(&self, f: u32) -> &[[f64; 3]] {
        let fr = &self.frags[f as usize];
        &self.verts[fr.start as usize..(fr.start + fr.len) as usize]
    }

    /// Where fragment `f` lies against the plane of source `p`, with the
    /// side of each vertex.
    fn classify(&mut self, f: u32, p: u32, sides: &mut Vec<(i8, f64)>) -> Side {
        self.stats.classified += 1;
        let fr = self.frags[f as usize];
        sides.clear();
        if fr.src == p {
            return Side::On;
        }
        let (ps, gs) = (&self.sources[p as usize], &self.sources[fr.src as usize]);
        let (mut any_front, mut any_back) = (false, false);
        for &v in self.poly(f) {
            let (side, s) = vertex_side(ps, gs, v, fr.generation);
            any_front |= side > 0;
            any_back |= side < 0;
            sides.push((side, s));
        }
        match (any_front, any_back) {
            (false, false) => Side::On,
            (true, false) => Side::Front,
            (false, true) => Side::Back,
            (true, true) => Side::Spanning,
        }
    }

    /// Pushes a new fragment of source `src` with the given vertices, with
    /// a fresh leaf.
    fn push_frag(&mut self, src: u32, poly: &[[f64; 3]], generation: u32) -> u32 {
        let start = u32::try_from(self.verts.len()).unwrap_or(NONE);
        self.verts.extend_from_slice(poly);
        let leaf = u32::try_from(self.cuts.len()).unwrap_or(NONE);
        self.cuts.push(Cut {
            l: [0.0; 3],
            front: NONE,
            back: 0,
            tie_front: false,
        });
        let id = u32::try_from(self.frags.len()).unwrap_or(NONE);
        self.frags.push(Frag {
            src,
            leaf,
            start,
            len: u32::try_from(poly.len()).unwrap_or(0),
            generation,
            area: doubled_area(poly).abs() / 2.0,
        });
        id
    }

    /// Splits fragment `f` by the plane of source `p` (the vertex sides
    /// given): its leaf becomes the cut where the two depth planes cross;
    /// returns the fragments in front and behind.
    fn split(
        &mut self,
        f: u32,
        p: u32,
        sides: &[(i8, f64)],
        scratch: &mut (Vec<[f64; 3]>, Vec<[f64; 3]>),
    ) -> (u32, u32) {
        self.stats.splits += 1;
        let fr = self.frags[f as usize];
        let (front_poly, back_poly) = scratch;
        split_polygon(self.poly(f), sides, front_poly, back_poly);
        let front = self.push_frag(fr.src, front_poly, fr.generation + 1);
        let back = self.push_frag(fr.src, back_poly, fr.generation + 1);
        let (g, ps) = (&self.sources[fr.src as usize], &self.sources[p as usize]);
        // L = q_G − q_P on G's anchor: positive where G is nearer.
        let l = [
            g.m[0] - ps.m[0],
            g.m[1] - ps.m[1],
            g.m[2] - ps.q(g.ax, g.ay),
        ];
        self.cuts[fr.leaf as usize] = Cut {
            l,
            front: self.frags[front as usize].leaf,
            back: self.frags[back as usize].leaf,
            tie_front: g.tri < ps.tri,
        };
        (front, back)
    }

    /// The splitter of a node's fragments (an index into `list`): of a few
    /// candidates evenly spaced through the list, and the largest
    /// fragment, the one whose plane splits the fewest of a sample of the
    /// list, imbalance counted at 1/`SPLIT_WEIGHT` of a split.
    fn choose(&mut self, list: &[u32], sides: &mut Vec<(i8, f64)>) -> usize {
        let n = list.len();
        if n <= 2 {
            return 0;
        }
        let mut candidates: Vec<usize> = (0..CANDIDATES.min(n))
            .map(|k| k * n / CANDIDATES.min(n))
            .collect();
        let largest = (0..n)
            .max_by(|&a, &b| {
                let (fa, fb) = (&self.frags[list[a] as usize], &self.frags[list[b] as usize]);
                fa.area.total_cmp(&fb.area).then(b.cmp(&a))
            })
            .unwrap_or(0);
        if !candidates.contains(&largest) {
            candidates.push(largest);
        }
        let trials: Vec<usize> = (0..TRIAL.min(n)).map(|k| k * n / TRIAL.min(n)).collect();
        let mut best = (usize::MAX, 0usize);
        for &c in &candidates {
            let p = self.frags[list[c] as usize].src;
            let (mut splits, mut front, mut back) = (0usize, 0usize, 0usize);
            for &t in &trials {
                if t == c {
                    continue;
                }
                match self.classify(list[t], p, sides) {
                    Side::Spanning => splits += 1,
                    Side::Front => front += 1,
                    Side::Back => back += 1,
                    Side::On => {}
                }
            }
            let score = SPLIT_WEIGHT * splits + front.abs_diff(back);
            if score < best.0 {
                best = (score, c);
            }
        }
        best.1
    }

    /// Builds the tree over fragments `all`, growing the budget's share as
    /// it goes.
    fn build(&mut self, all: Vec<u32>, held: &mut Held<'_>) -> Result<(), OverBudget> {
        self.nodes.push(Node::default());
        let mut stack: Vec<(u32, Vec<u32>, usize)> = vec![(0, all, 1)];
        let mut sides = Vec::with_capacity(16);
        let mut scratch = (Vec::with_capacity(16), Vec::with_capacity(16));
        while let Some((node, list, depth)) = stack.pop() {
            self.stats.depth = self.stats.depth.max(depth);
            let chosen = self.choose(&list, &mut sides);
            let splitter = list[chosen];
            let p = self.frags[splitter as usize].src;
            let mut on = vec![splitter];
            let (mut front, mut back) = (Vec::new(), Vec::new());
            for (k, &f) in list.iter().enumerate() {
                if k == chosen {
                    continue;
                }
                match self.classify(f, p, &mut sides) {
                    Side::On => on.push(f),
                    Side::Front => front.push(f),
                    Side::Back => back.push(f),
                    Side::Spanning => {
                        let (a, b) = self.split(f, p, &sides, &mut scratch);
                        front.push(a);
                        back.push(b);
                    }
                }
            }
            drop(list);
            self.stats.coplanar += on.len() - 1;
            // Higher id first, so the lower id ends on top.
            let tri_of = |f: &u32| self.sources[self.frags[*f as usize].src as usize].tri;
            on.sort_by_key(|f| std::cmp::Reverse(tri_of(f)));
            self.nodes[node as usize].on = on;
            for (list, is_front) in [(back, false), (front, true)] {
                if list.is_empty() {
                    continue;
                }
                let child = u32::try_from(self.nodes.len()).unwrap_or(NONE);
                self.nodes.push(Node::default());
                if is_front {
                    self.nodes[node as usize].front = Some(child);
                } else {
                    self.nodes[node as usize].back = Some(child);
                }
                stack.push((child, list, depth + 1));
            }
            let bytes =
                (self.frags.len() as u64) * FRAG_BYTES + (self.nodes.len() as u64) * NODE_BYTES;
            held.grow_to(bytes, self.frags.len())?;
        }
        self.stats.nodes = self.nodes.len();
        Ok(())
    }

    /// Walks the tree back to front (the side away from the eye, the
    /// node's own plane, the eye's side) and ranks the leaves in that
    /// order.
    fn rank(&mut self) {
        let mut rank = 0u32;
        let mut stack: Vec<(u32, bool)> = vec![(0, false)];
        while let Some((n, expanded)) = stack.pop() {
            let node = &self.nodes[n as usize];
            if expanded {
                for &f in &node.on {
                    let leaf = self.frags[f as usize].leaf;
                    self.cuts[leaf as usize].back = rank;
                    rank = rank.saturating_add(1);
                }
                if let Some(front) = node.front {
                    stack.push((front, false));
                }
            } else {
                stack.push((n, true));
                if let Some(back) = node.back {
                    stack.push((back, false));
                }
            }
        }
    }
}

/// The source of triangle `tri` (its clipped polygon's first point as the
/// anchor) and its polygon in screen-depth space; `None` when its plane
/// passes through the eye (the z-buffer draws nothing of it either) or
/// nothing is left of it.
fn source(
    scene: &TriScene,
    hv: &[HVert],
    tri: u32,
    ctx: &SetupCtx<'_>,
    scratch: &mut (Vec<HVert>, Vec<HVert>),
) -> Option<(Source, Vec<[f64; 3]>)> {
    let cam = &scene.camera;
    let perspective = matches!(cam.projection(), Projection::Perspective { .. });
    let idx = scene.tris[tri as usize];
    let v = idx.map(|i| hv[i as usize]);
    let screen = v.map(|p| p.screen());
    let (poly, tmp) = scratch;
    let corners: Vec<HVert> = match clip_triangle(&v, &screen, ctx, poly, tmp) {
        Clipped::Whole => v.to_vec(),
        Clipped::Polygon => poly.clone(),
        Clipped::Nothing => return None,
    };
    let mut pts = Vec::with_capacity(corners.len());
    for c in &corners {
        let (x, y) = clamped_screen(c, ctx)?;
        pts.push((x, y, c));
    }
    let (ax, ay) = (pts[0].0, pts[0].1);
    let planes = triangle_planes(&v, perspective, ax, ay)?;
    let sign = if perspective { 1.0 } else { -1.0 };
    let m = planes.depth.map(|d| d * sign);
    let src_plane = |x: f64, y: f64| m[0] * (x - ax) + m[1] * (y - ay) + m[2];
    let polygon: Vec<[f64; 3]> = pts
        .iter()
        .map(|&(x, y, c)| {
            let q = if (x, y) == c.screen() {
                if perspective { 1.0 / c.w } else { -c.z }
            } else {
                // Clamped onto the guard band: back onto the plane there.
                src_plane(x, y)
            };
            [x, y, q]
        })
        .collect();
    // Rounding magnitudes of the three vertices, and of the polygon's points.
    let size = (f64::from(cam.width()), f64::from(cam.height()));
    let mags = idx.map(|i| {
        vertex_magnitudes(
            cam.to_view(to_f64(scene.positions[i as usize])),
            cam.projection(),
            size,
        )
    });
    let u = [m[0], m[1], m[2] - m[0] * ax - m[1] * ay];
    let c = mags.map(|d| {
        u[0].abs() * d[0]
            + u[1].abs() * d[1]
            + u[2].abs() * d[2]
            + if perspective { 0.0 } else { d[3] }
    });
    let dmax = |k: usize| mags.iter().map(|d| d[k]).fold(0.0f64, f64::max);
    let (dx, dy, dw, dz) = (dmax(0), dmax(1), dmax(2), dmax(3));
    let xm = polygon.iter().map(|p| p[0].abs()).fold(0.0f64, f64::max);
    let ym = polygon.iter().map(|p| p[1].abs()).fold(0.0f64, f64::max);
    let e = if perspective {
        let w_min = corners.iter().map(|c| c.w).fold(f64::INFINITY, f64::min);
        [
            (dx + xm * dw) / w_min,
            (dy + ym * dw) / w_min,
            dw / (w_min * w_min),
        ]
    } else {
        [dx, dy, dz]
    };
    let source = Source {
        tri,
        m,
        ax,
        ay,
        lambda: planes.lambda,
        c,
        e,
    };
    Some((source, polygon))
}

/// Builds the BSP tree of a scene's visible triangles and ranks its
/// pieces; the memory it holds stays reserved in `held` until that is
/// dropped.
fn tree<'b>(
    scene: &TriScene,
    opts: &RasterOptions,
    budget: &'b Budget,
) -> Result<(Pieces, BspStats, Held<'b>), OverBudget> {
    let started = Instant::now();
    let grid = SampleGrid::new(scene.camera.samples());
    let hv = homogeneous(scene, opts.perturbation());
    let recs = primary_records(scene, opts, &hv, &grid);
    let ctx = SetupCtx::new(scene, &grid, opts.perturbation().fill_rule);
    let mut held = Held {
        budget,
        reserved: 0,
    };
    let mut b = Builder {
        sources: Vec::new(),
        frags: Vec::new(),
        verts: Vec::new(),
        cuts: Vec::new(),
        nodes: Vec::new(),
        stats: BspStats::default(),
    };
    let mut source_of = vec![NONE; scene.len()];
    let mut scratch = (Vec::with_capacity(8), Vec::with_capacity(8));
    let mut last = NONE;
    for r in &recs {
        if r.tri == last {
            continue;
        }
        last = r.tri;
        let Some((src, poly)) = source(scene, &hv, r.tri, &ctx, &mut scratch) else {
            continue;
        };
        let s = u32::try_from(b.sources.len()).unwrap_or(NONE);
        source_of[r.tri as usize] = s;
        b.sources.push(src);
        b.push_frag(s, &poly, 0);
    }
    drop(recs);
    b.stats.triangles = b.sources.len();
    held.grow_to((b.frags.len() as u64) * FRAG_BYTES, b.frags.len())?;
    let all: Vec<u32> = (0..u32::try_from(b.frags.len()).unwrap_or(0)).collect();
    if !all.is_empty() {
        b.build(all, &mut held)?;
        b.rank();
    }
    b.stats.pieces = b.frags.len() - b.stats.splits;
    let roots = b
        .sources
        .iter()
        .enumerate()
        .map(|(k, s)| (s.ax, s.ay, b.frags[k].leaf))
        .collect();
    let mut stats = b.stats;
    stats.build_ms = started.elapsed().as_secs_f64() * 1e3;
    let pieces = Pieces {
        source_of,
        roots,
        cuts: b.cuts,
    };
    Ok((pieces, stats, held))
}

/// Renders with the BSP tree: the tree of the visible triangles, their
/// pieces painted back to front on the shared sample grid, and the
/// rasterizer's deferred shading.
///
/// # Errors
///
/// [`OverBudget`] when the tree (it can grow with the square of the
/// triangles) or its per-sample ranks would not fit `budget`.
pub fn render(
    scene: &TriScene,
    opts: &RasterOptions,
    budget: &Budget,
) -> Result<(Frame, RasterStats, BspStats), OverBudget> {
    let (pieces, bsp, mut held) = tree(scene, opts, budget)?;
    let cam = &scene.camera;
    let samples = u64::from(cam.sample_width()) * u64::from(cam.sample_height());
    held.grow_to(held.reserved + samples * 4, bsp.pieces)?;
    let vis = visibility_with(scene, opts, &Rule::Pieces(&pieces));
    let mut stats = vis.stats;
    let mut frame = Frame::new(0, 0, 1, scene.background);
    let (shadow_rays, shadow_maps) = shade_pass(scene, opts, &vis.id, &mut frame);
    stats.shadow_bvh =
        opts.shadows_needed && opts.shadows == rendiff_core::options::ShadowMode::Rays;
    stats.shadow_rays = shadow_rays;
    stats.shadow_maps = shadow_maps;
    Ok((frame, stats, bsp))
}

#[cfg(test)]
mod tests {
    //! The split's contract: the halves share their cut points bit for
    //! bit and together make the polygon; on-plane vertices go to both.
    use super::*;

    #[test]
    fn halves_share_the_cut_and_make_the_whole() {
        let square = [
            [0.0, 0.0, 1.0],
            [4.0, 0.0, 1.0],
            [4.0, 4.0, 2.0],
            [0.0, 4.0, 2.0],
        ];
        // A line through x = 1.3 (sides by x − 1.3).
        let sides: Vec<(i8, f64)> = square
            .iter()
            .map(|v| {
                let s = v[0] - 1.3;
                (if s > 0.0 { 1 } else { -1 }, s)
            })
            .collect();
        let (mut f, mut b) = (Vec::new(), Vec::new());
        split_polygon(&square, &sides, &mut f, &mut b);
        assert_eq!((f.len(), b.len()), (4, 4));
        let whole = doubled_area(&square);
        assert!((doubled_area(&f) + doubled_area(&b) - whole).abs() <= 1e-12 * whole);
        let shared: Vec<_> = f.iter().filter(|p| b.contains(p)).collect();
        assert_eq!(shared.len(), 2, "{f:?} {b:?}");
        // The reversed polygon cuts its edges at the very same points.
        let rev: Vec<[f64; 3]> = square.iter().rev().copied().collect();
        let rsides: Vec<(i8, f64)> = sides.iter().rev().copied().collect();
        let (mut rf, mut rb) = (Vec::new(), Vec::new());
        split_polygon(&rev, &rsides, &mut rf, &mut rb);
        for p in &shared {
            assert!(rf.contains(p) && rb.contains(p));
        }
    }

    #[test]
    fn a_vertex_on_the_plane_goes_to_both_halves() {
        let tri = [[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [1.0, 2.0, 1.0]];
        let sides = [(1, 1.0), (-1, -1.0), (0, 0.0)];
        let (mut f, mut b) = (Vec::new(), Vec::new());
        split_polygon(&tri, &sides, &mut f, &mut b);
        assert_eq!((f.len(), b.len()), (3, 3));
        assert!(f.contains(&tri[2]) && b.contains(&tri[2]));
    }
}
