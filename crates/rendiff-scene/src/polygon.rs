//! Planar polygons with holes: validation and triangulation by spade's
//! constrained Delaunay triangulation (CDT).
//!
//! Used for `polygon` objects and for OBJ faces with more than three
//! corners. A fan is wrong for concave outlines; the CDT with every ring
//! edge as a constraint, followed by an even-odd flood fill from the outside
//! (the rule POV-Ray's `polygon` uses, POVRAY.md §9.8), is right for any
//! simple rings, holes included.
//!
//! Every geometric decision (do two edges cross or touch, is a point inside
//! a ring) uses exact orientation predicates (Shewchuk's, via the `robust`
//! crate) on the projected `f64` coordinates, so spade is never handed
//! crossing constraints, which it would reject.
//!
//! Everything before the triangulation is O(n log n) in the number of
//! points: the edges are checked by one sweep (Shamos and Hoey's), which
//! also tells which rings each hole lies in, and a ring is split where a
//! point repeats through a hash map. (Testing every pair of edges whose x
//! ranges overlap, and searching the ring for every point, took 76 s for
//! 200 000 corners; now 0.7–0.9 s, most of it spade's.)

use spade::{ConstrainedDelaunayTriangulation, HasPosition, Point2, Triangulation};

use rendiff_core::math::DVec3;

/// Points farther than `PLANARITY_TOLERANCE × diameter` from the polygon's
/// Newell plane make a polygon non-planar (DESIGN.md §4).
pub(crate) const PLANARITY_TOLERANCE: f64 = 1e-5;

/// uv coordinates whose residual from the best affine fit in position
/// exceeds `UV_AFFINE_TOLERANCE × (uv extent + 1)` are not affine.
pub(crate) const UV_AFFINE_TOLERANCE: f64 = 1e-5;

/// A point of a polygon, by its position in the scene's own lists.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointRef {
    /// `None` for the outline, `Some(k)` for hole k.
    pub hole: Option<usize>,
    /// Index of the point within its ring (from 0).
    pub index: usize,
}

impl std::fmt::Display for PointRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.hole {
            None => write!(f, "point {} of the outline", self.index),
            Some(h) => write!(f, "point {} of hole {h}", self.index),
        }
    }
}

/// An edge of a polygon ring, by the indices of its two end points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EdgeRef {
    /// `None` for the outline, `Some(k)` for hole k.
    pub hole: Option<usize>,
    /// Index of the first end point within its ring.
    pub from: usize,
    /// Index of the second end point within its ring.
    pub to: usize,
}

impl EdgeRef {
    /// The edge's first end point.
    #[must_use]
    pub fn start(&self) -> PointRef {
        PointRef {
            hole: self.hole,
            index: self.from,
        }
    }
}

impl std::fmt::Display for EdgeRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.hole {
            None => write!(
                f,
                "the outline's edge from point {} to point {}",
                self.from, self.to
            ),
            Some(h) => write!(
                f,
                "the edge of hole {h} from point {} to point {}",
                self.from, self.to
            ),
        }
    }
}

/// A length for a message, to 4 significant digits.
fn short(x: f64) -> String {
    let r: f64 = format!("{x:.3e}").parse().unwrap_or(x);
    if r == 0.0 || (1e-4..1e16).contains(&r.abs()) {
        format!("{r}")
    } else {
        format!("{r:e}")
    }
}

/// "the outline" or "hole k".
fn ring_name(hole: Option<usize>) -> String {
    hole.map_or_else(|| "the outline".to_string(), |h| format!("hole {h}"))
}

/// Why a polygon was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PolygonError {
    /// A coordinate is NaN or infinite.
    #[error("{point} is not finite")]
    NotFinite {
        /// The point.
        point: PointRef,
    },
    /// A ring has fewer than three distinct points.
    #[error(
        "{} has {distinct} distinct point{}; at least 3 are needed",
        ring_name(*.hole),
        if *.distinct == 1 { "" } else { "s" }
    )]
    TooFewPoints {
        /// `None` for the outline, `Some(k)` for hole k.
        hole: Option<usize>,
        /// Its number of distinct points.
        distinct: usize,
    },
    /// A ring runs out to a point and straight back: a part with no area.
    #[error(
        "{} runs from point {from} to point {to} and straight back along the same edge (a spike with no area)",
        ring_name(*.hole)
    )]
    Spike {
        /// `None` for the outline, `Some(k)` for hole k.
        hole: Option<usize>,
        /// Where the spike starts.
        from: usize,
        /// Its tip.
        to: usize,
    },
    /// All points of the outline lie on one line.
    #[error("the outline's points all lie on one line; a polygon needs an area")]
    Collinear,
    /// A point is too far from the plane.
    #[error(
        "not planar: {point} is {} from the polygon's plane (its Newell plane through the outline's centroid), more than the tolerance {tolerance:.0e} × the polygon's diameter {} = {}",
        short(*.distance),
        short(*.diameter),
        short(*.limit)
    )]
    NotPlanar {
        /// The point farthest from the plane.
        point: PointRef,
        /// Its distance from the plane.
        distance: f64,
        /// The relative tolerance.
        tolerance: f64,
        /// The polygon's diameter (of its bounding box).
        diameter: f64,
        /// The absolute limit.
        limit: f64,
    },
    /// Two edges cross or touch.
    #[error(
        "{a} and {b} cross, touch or overlap; the outline and the holes must be simple rings that do not touch each other"
    )]
    SelfIntersecting {
        /// One edge.
        a: EdgeRef,
        /// The other edge (the later one in the lists).
        b: EdgeRef,
    },
    /// A hole lies outside the outline.
    #[error("hole {hole} lies outside the outline; a hole must lie inside it")]
    HoleOutside {
        /// Hole index.
        hole: usize,
    },
    /// A hole lies inside another hole.
    #[error("hole {hole} lies inside hole {other}; holes must not overlap")]
    HoleInHole {
        /// Hole index.
        hole: usize,
        /// The hole it lies in.
        other: usize,
    },
    /// The triangulator refused the input.
    #[error("the triangulation failed: {0}")]
    Triangulation(String),
    /// uv has the wrong length or is not affine in position.
    #[error("{0}")]
    Uv(String),
}

#[derive(Clone, Copy, Debug)]
struct V2 {
    p: Point2<f64>,
    index: usize,
}

impl HasPosition for V2 {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

/// A triangulated polygon.
#[derive(Clone, Debug, PartialEq)]
pub struct Triangulated {
    /// Unit Newell normal of the outline (the triangles wind
    /// counter-clockwise around it).
    pub normal: DVec3,
    /// Triangles as indices into the flat input list (outline, then holes).
    pub triangles: Vec<[u32; 3]>,
}

/// Options for [`triangulate`].
#[derive(Clone, Copy, Debug)]
pub struct PolygonOptions {
    /// Reject points off the Newell plane (polygons: yes; OBJ faces: no,
    /// they are projected).
    pub check_planarity: bool,
}

fn orient(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>) -> f64 {
    robust::orient2d(
        robust::Coord { x: a.x, y: a.y },
        robust::Coord { x: b.x, y: b.y },
        robust::Coord { x: c.x, y: c.y },
    )
}

/// `true` when `p` lies on the closed segment `a b` (exact).
fn on_segment(a: Point2<f64>, b: Point2<f64>, p: Point2<f64>) -> bool {
    orient(a, b, p) == 0.0
        && p.x >= a.x.min(b.x)
        && p.x <= a.x.max(b.x)
        && p.y >= a.y.min(b.y)
        && p.y <= a.y.max(b.y)
}

/// `true` when the closed segments `a b` and `c d` share any point (exact).
fn segments_touch(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>, d: Point2<f64>) -> bool {
    let o1 = orient(a, b, c);
    let o2 = orient(a, b, d);
    let o3 = orient(c, d, a);
    let o4 = orient(c, d, b);
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    on_segment(a, b, c) || on_segment(a, b, d) || on_segment(c, d, a) || on_segment(c, d, b)
}

/// Newell normal (not normalised) of a ring of 3-D points.
#[must_use]
pub(crate) fn newell_normal(points: &[DVec3]) -> DVec3 {
    let mut n = DVec3::ZERO;
    for k in 0..points.len() {
        let a = points[k];
        let b = points[(k + 1) % points.len()];
        n.x += (a.y - b.y) * (a.z + b.z);
        n.y += (a.z - b.z) * (a.x + b.x);
        n.z += (a.x - b.x) * (a.y + b.y);
    }
    n
}

/// Normal of the best-spread triangle of a point set: the first point, the
/// farthest from it, and the farthest from their line.
fn best_triangle_normal(points: &[DVec3]) -> DVec3 {
    let p0 = points[0];
    let p1 = points
        .iter()
        .copied()
        .max_by(|a, b| (*a - p0).length().total_cmp(&(*b - p0).length()))
        .unwrap_or(p0);
    points
        .iter()
        .map(|p| (p1 - p0).cross(*p - p0))
        .max_by(|a, b| a.length().total_cmp(&b.length()))
        .unwrap_or(DVec3::ZERO)
}

/// Removes consecutive duplicates (and a closing copy of the first point),
/// then splits the ring where a point repeats (a ring touching itself at a
/// vertex becomes two rings).
fn clean_ring(ring: &[V2]) -> Vec<Vec<V2>> {
    let mut pts: Vec<V2> = Vec::with_capacity(ring.len());
    for v in ring {
        if pts.last().is_none_or(|l: &V2| l.p != v.p) {
            pts.push(*v);
        }
    }
    while pts.len() > 1 && pts[0].p == pts[pts.len() - 1].p {
        pts.pop();
    }
    // Where each point of the stack is, by its coordinates (`==` on f64:
    // -0 is 0, and the coordinates are finite).
    let key = |p: Point2<f64>| ((p.x + 0.0).to_bits(), (p.y + 0.0).to_bits());
    let mut at: std::collections::HashMap<(u64, u64), usize> =
        std::collections::HashMap::with_capacity(pts.len());
    let mut out = Vec::new();
    let mut stack: Vec<V2> = Vec::new();
    for v in pts {
        if let Some(&pos) = at.get(&key(v.p)) {
            for s in &stack[pos + 1..] {
                at.remove(&key(s.p));
            }
            let loop_part: Vec<V2> = stack.drain(pos + 1..).collect();
            let mut ring = vec![stack[pos]];
            ring.extend(loop_part);
            out.push(ring);
        } else {
            at.insert(key(v.p), stack.len());
            stack.push(v);
        }
    }
    out.push(stack);
    out
}

/// An edge of a ring, for the simplicity check.
struct Edge {
    /// Its ring (outline parts first, then hole parts).
    ring: usize,
    /// Its index in the ring (from point `k` to point `k + 1`).
    k: usize,
    /// Flat input index of its first point.
    from: usize,
    /// Flat input index of its second point.
    to: usize,
    a: Point2<f64>,
    b: Point2<f64>,
}

/// `true` when the two edges touch in a way the rings may not: anything
/// but adjacent edges of one ring meeting at their shared point, or parts
/// of a split outline meeting at a shared vertex (exact).
fn edges_conflict(e: &Edge, f: &Edge, ring_len: &[usize], n_outline_rings: usize) -> bool {
    let same_ring = e.ring == f.ring;
    let len = ring_len[e.ring];
    let adjacent = same_ring && ((e.k + 1) % len == f.k || (f.k + 1) % len == e.k);
    if adjacent {
        // Adjacent edges share one endpoint; they may not overlap.
        let shared = if (e.k + 1) % len == f.k { e.b } else { e.a };
        let (eo, fo) = (
            if e.a == shared { e.b } else { e.a },
            if f.a == shared { f.b } else { f.a },
        );
        return on_segment(shared, eo, fo) || on_segment(shared, fo, eo);
    }
    if !segments_touch(e.a, e.b, f.a, f.b) {
        return false;
    }
    if !same_ring && e.ring < n_outline_rings && f.ring < n_outline_rings {
        // Parts of a split outline may touch at the split vertex only.
        let shared_vertex = [e.a, e.b].iter().any(|p| *p == f.a || *p == f.b);
        let crossing = {
            let o1 = orient(e.a, e.b, f.a);
            let o2 = orient(e.a, e.b, f.b);
            let o3 = orient(f.a, f.b, e.a);
            let o4 = orient(f.a, f.b, e.b);
            o1 * o2 < 0.0 && o3 * o4 < 0.0
        };
        let inner = |a: Point2<f64>, b: Point2<f64>, p: Point2<f64>| {
            on_segment(a, b, p) && p != a && p != b
        };
        let collinear_overlap = inner(e.a, e.b, f.a)
            || inner(e.a, e.b, f.b)
            || inner(f.a, f.b, e.a)
            || inner(f.a, f.b, e.b)
            || (e.a == f.b && e.b == f.a)
            || (e.a == f.a && e.b == f.b);
        if shared_vertex && !crossing && !collinear_overlap {
            return false;
        }
    }
    // Any other touch (non-adjacent edges of one ring, a hole and another
    // ring) breaks "simple and disjoint".
    true
}

/// The pair of edges in conflict that the rings are reported by: the first
/// edge in the order of their smallest x (ties in ring order) that
/// conflicts with a later one, and the first of those, by testing the
/// pairs whose x ranges overlap; `None` when none is found within
/// `max_tests` tests (the sweep has found a conflict by then: this only
/// picks which one is reported, the same one as before the sweep; for a
/// star-shaped outline this is quadratic, hence the limit).
fn first_conflict_in_x_order(
    edges: &[Edge],
    ring_len: &[usize],
    n_outline_rings: usize,
    max_tests: usize,
) -> Option<(usize, usize)> {
    let xmin = |e: &Edge| e.a.x.min(e.b.x);
    let xmax = |e: &Edge| e.a.x.max(e.b.x);
    let mut order: Vec<usize> = (0..edges.len()).collect();
    order.sort_by(|&i, &j| xmin(&edges[i]).total_cmp(&xmin(&edges[j])));
    let mut tests = 0usize;
    for (n, &i) in order.iter().enumerate() {
        for &j in &order[n + 1..] {
            if xmin(&edges[j]) > xmax(&edges[i]) {
                break;
            }
            tests += 1;
            if tests > max_tests {
                return None;
            }
            if edges_conflict(&edges[i], &edges[j], ring_len, n_outline_rings) {
                return Some((i, j));
            }
        }
    }
    None
}

/// Pair tests [`first_conflict_in_x_order`] may spend on naming a conflict.
const MAX_NAMING_TESTS: usize = 1 << 22;

/// `true` when `p` comes before `q` in the sweep's order: by x, then by y
/// (a sweep line tilted infinitesimally, so no edge is vertical to it).
fn before(p: Point2<f64>, q: Point2<f64>) -> bool {
    p.x < q.x || (p.x == q.x && p.y < q.y)
}

const NIL: u32 = u32::MAX;

/// A node of the sweep's status: one edge crossing the sweep line.
#[derive(Clone, Copy)]
struct Node {
    left: u32,
    right: u32,
    up: u32,
    priority: u32,
    /// Outline edges in the subtree.
    outline: u32,
    /// Hole edges in the subtree.
    holes: u32,
}

/// The edges crossing the sweep line, bottom to top: a treap (random
/// priorities from the edge index) with parent links, so that an edge is
/// inserted after its neighbour and removed by its index without ever
/// comparing it, and with counts of outline and hole edges per subtree.
/// Node `i` is edge `i`.
struct Status {
    nodes: Vec<Node>,
    is_outline: Vec<bool>,
    root: u32,
}

impl Status {
    fn new(is_outline: Vec<bool>) -> Status {
        let nodes = (0..is_outline.len())
            .map(|i| {
                // SplitMix64 of the index: fixed, well-spread priorities.
                let mut z = (i as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                Node {
                    left: NIL,
                    right: NIL,
                    up: NIL,
                    priority: (z >> 32) as u32,
                    outline: 0,
                    holes: 0,
                }
            })
            .collect();
        Status {
            nodes,
            is_outline,
            root: NIL,
        }
    }

    fn n(&self, x: u32) -> &Node {
        &self.nodes[x as usize]
    }

    fn nm(&mut self, x: u32) -> &mut Node {
        &mut self.nodes[x as usize]
    }

    fn counts(&self, x: u32) -> (u32, u32) {
        if x == NIL {
            (0, 0)
        } else {
            (self.n(x).outline, self.n(x).holes)
        }
    }

    fn own(&self, x: u32) -> (u32, u32) {
        if self.is_outline[x as usize] {
            (1, 0)
        } else {
            (0, 1)
        }
    }

    fn update(&mut self, x: u32) {
        let (l, r) = (self.n(x).left, self.n(x).right);
        let (lo, lh) = self.counts(l);
        let (ro, rh) = self.counts(r);
        let (so, sh) = self.own(x);
        let node = self.nm(x);
        node.outline = lo + ro + so;
        node.holes = lh + rh + sh;
    }

    /// Rotates `x` above its parent.
    fn rotate_up(&mut self, x: u32) {
        let p = self.n(x).up;
        let g = self.n(p).up;
        if self.n(p).left == x {
            let b = self.n(x).right;
            self.nm(p).left = b;
            if b != NIL {
                self.nm(b).up = p;
            }
            self.nm(x).right = p;
        } else {
            let b = self.n(x).left;
            self.nm(p).right = b;
            if b != NIL {
                self.nm(b).up = p;
            }
            self.nm(x).left = p;
        }
        self.nm(p).up = x;
        self.nm(x).up = g;
        if g == NIL {
            self.root = x;
        } else if self.n(g).left == p {
            self.nm(g).left = x;
        } else {
            self.nm(g).right = x;
        }
        self.update(p);
        self.update(x);
    }

    fn leftmost(&self, mut x: u32) -> u32 {
        while self.n(x).left != NIL {
            x = self.n(x).left;
        }
        x
    }

    fn rightmost(&self, mut x: u32) -> u32 {
        while self.n(x).right != NIL {
            x = self.n(x).right;
        }
        x
    }

    /// The top edge, or `NIL`.
    fn last(&self) -> u32 {
        if self.root == NIL {
            NIL
        } else {
            self.rightmost(self.root)
        }
    }

    fn succ(&self, mut x: u32) -> u32 {
        if self.n(x).right != NIL {
            return self.leftmost(self.n(x).right);
        }
        while self.n(x).up != NIL && self.n(self.n(x).up).right == x {
            x = self.n(x).up;
        }
        self.n(x).up
    }

    fn pred(&self, mut x: u32) -> u32 {
        if self.n(x).left != NIL {
            return self.rightmost(self.n(x).left);
        }
        while self.n(x).up != NIL && self.n(self.n(x).up).left == x {
            x = self.n(x).up;
        }
        self.n(x).up
    }

    /// Inserts edge `x` just above `after` (at the bottom for `NIL`).
    fn insert_after(&mut self, after: u32, x: u32) {
        let (so, sh) = self.own(x);
        *self.nm(x) = Node {
            left: NIL,
            right: NIL,
            up: NIL,
            outline: so,
            holes: sh,
            ..*self.n(x)
        };
        if self.root == NIL {
            self.root = x;
            return;
        }
        let parent = if after == NIL {
            let p = self.leftmost(self.root);
            self.nm(p).left = x;
            p
        } else if self.n(after).right == NIL {
            self.nm(after).right = x;
            after
        } else {
            let p = self.leftmost(self.n(after).right);
            self.nm(p).left = x;
            p
        };
        self.nm(x).up = parent;
        let mut a = parent;
        while a != NIL {
            let node = self.nm(a);
            node.outline += so;
            node.holes += sh;
            a = node.up;
        }
        while self.n(x).up != NIL && self.n(x).priority > self.n(self.n(x).up).priority {
            self.rotate_up(x);
        }
    }

    /// Removes edge `x`.
    fn remove(&mut self, x: u32) {
        loop {
            let (l, r) = (self.n(x).left, self.n(x).right);
            let c = match (l, r) {
                (NIL, NIL) => break,
                (c, NIL) | (NIL, c) => c,
                _ if self.n(l).priority > self.n(r).priority => l,
                _ => r,
            };
            self.rotate_up(c);
        }
        let p = self.n(x).up;
        if p == NIL {
            self.root = NIL;
        } else {
            if self.n(p).left == x {
                self.nm(p).left = NIL;
            } else {
                self.nm(p).right = NIL;
            }
            let (so, sh) = self.own(x);
            let mut a = p;
            while a != NIL {
                let node = self.nm(a);
                node.outline -= so;
                node.holes -= sh;
                a = node.up;
            }
        }
        self.nm(x).up = NIL;
    }

    /// The lowest edge that `p` does not lie above (`side(edge) > 0` when
    /// `p` lies above it), or `NIL`.
    fn first_not_below(&self, side: impl Fn(u32) -> f64) -> u32 {
        let (mut x, mut best) = (self.root, NIL);
        while x != NIL {
            if side(x) > 0.0 {
                x = self.n(x).right;
            } else {
                best = x;
                x = self.n(x).left;
            }
        }
        best
    }

    /// Outline edges below `x`.
    fn outline_below(&self, mut x: u32) -> u32 {
        let mut count = self.counts(self.n(x).left).0;
        while self.n(x).up != NIL {
            let p = self.n(x).up;
            if self.n(p).right == x {
                count += self.counts(self.n(p).left).0 + self.own(p).0;
            }
            x = p;
        }
        count
    }

    /// The top hole edge in the subtree of `x`, or `NIL`.
    fn top_hole_in(&self, mut x: u32) -> u32 {
        while x != NIL && self.n(x).holes > 0 {
            let r = self.n(x).right;
            if self.counts(r).1 > 0 {
                x = r;
            } else if self.own(x).1 > 0 {
                return x;
            } else {
                x = self.n(x).left;
            }
        }
        NIL
    }

    /// The nearest hole edge below `x`, or `NIL`.
    fn hole_below(&self, mut x: u32) -> u32 {
        let found = self.top_hole_in(self.n(x).left);
        if found != NIL {
            return found;
        }
        while self.n(x).up != NIL {
            let p = self.n(x).up;
            if self.n(p).right == x {
                if self.own(p).1 > 0 {
                    return p;
                }
                let found = self.top_hole_in(self.n(p).left);
                if found != NIL {
                    return found;
                }
            }
            x = p;
        }
        NIL
    }
}

/// Where each ring lies, from the sweep (filled in for hole rings).
struct Nesting {
    /// Inside an odd number of outline rings.
    inside_outline: Vec<bool>,
    /// The innermost hole ring around it.
    parent: Vec<Option<usize>>,
}

/// `p` with each coordinate plus 0, which turns -0 into +0 (so that equal
/// points have equal bits and compare alike under `total_cmp`) and leaves
/// every other value as it is.
fn zero(p: Point2<f64>) -> Point2<f64> {
    Point2::new(p.x + 0.0, p.y + 0.0)
}

/// Each ring's first point in the sweep's order (least x, then least y,
/// after [`zero`]; the first of equal points), and whether the ring winds
/// counter-clockwise there (`orient` of the point's neighbours > 0; never
/// 0 for a simple ring).
fn ring_first_points(rings: &[&Vec<V2>]) -> Vec<(Point2<f64>, bool)> {
    rings
        .iter()
        .map(|r| {
            let n = r.len();
            let k = (0..n)
                .min_by(|&i, &j| {
                    let (p, q) = (zero(r[i].p), zero(r[j].p));
                    p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y))
                })
                .unwrap_or(0);
            let ccw = orient(r[(k + n - 1) % n].p, r[k].p, r[(k + 1) % n].p) > 0.0;
            (zero(r[k].p), ccw)
        })
        .collect()
}

/// The sweep's events, `(point, edge, starts here)`: each edge starts at
/// its first end and ends at its last (`ends`, in the sweep's order). They
/// are sorted by x, then y, then edge index, so all events at one point
/// are consecutive, in edge order.
fn sweep_events(ends: &[(Point2<f64>, Point2<f64>)]) -> Vec<(Point2<f64>, u32, bool)> {
    let mut events: Vec<(Point2<f64>, u32, bool)> = Vec::with_capacity(2 * ends.len());
    for (i, &(lo, hi)) in ends.iter().enumerate() {
        let i = u32::try_from(i).unwrap_or(NIL - 1);
        events.push((lo, i, true));
        events.push((hi, i, false));
    }
    events.sort_unstable_by(|a, b| {
        a.0.x
            .total_cmp(&b.0.x)
            .then(a.0.y.total_cmp(&b.0.y))
            .then(a.1.cmp(&b.1))
    });
    events
}

/// Clears `ending` and `starting`, then fills them, in event order, with
/// the edges of the events from `events[at]` on that share its point.
/// Returns the index of the first event at another point (or the length).
fn events_at(
    events: &[(Point2<f64>, u32, bool)],
    mut at: usize,
    ending: &mut Vec<u32>,
    starting: &mut Vec<u32>,
) -> usize {
    let p = events[at].0;
    ending.clear();
    starting.clear();
    while at < events.len() && events[at].0 == p {
        let (_, i, start) = events[at];
        if start {
            starting.push(i);
        } else {
            ending.push(i);
        }
        at += 1;
    }
    at
}

/// The simplicity check as one sweep over the edges (Shamos and Hoey's):
/// O(n log n) instead of testing every pair of edges whose x ranges
/// overlap, which is quadratic for a star-shaped polygon. Its fields are
/// the state of the sweep between two event points.
struct Sweep<'a> {
    /// The edges swept.
    edges: &'a [Edge],
    /// The number of points (and edges) of each ring.
    ring_len: &'a [usize],
    /// Rings below this index are parts of the outline; the rest are holes.
    n_outline_rings: usize,
    /// Each edge from its first to its last point in the sweep's order
    /// (after [`zero`]).
    ends: Vec<(Point2<f64>, Point2<f64>)>,
    /// [`ring_first_points`] of the rings.
    ring_first: Vec<(Point2<f64>, bool)>,
    /// The edges crossing the sweep line, bottom to top.
    status: Status,
    /// Where each hole ring lies: filled in when the sweep reaches the
    /// ring's first point.
    nesting: Nesting,
}

impl<'a> Sweep<'a> {
    /// A pair of edges that conflict ([`edges_conflict`]), or where each
    /// hole ring lies.
    ///
    /// Why every conflict is found: let `I` be the first point (in the
    /// sweep's order) where two edges conflict. Until the sweep reaches
    /// `I`, edges only meet at shared vertices without crossing, so the
    /// status stays in order. If `I` is a vertex, every edge through it is
    /// seen at its event: an edge with `I` inside it conflicts with any
    /// edge ending or starting there; two edges with `I` as an endpoint
    /// conflict only if one belongs to a hole and the other to another
    /// ring, or if they leave `I` in the same direction (sorting by
    /// direction makes those neighbours). Otherwise `I` is inside both
    /// edges; the edges between them in the status just after the last
    /// event before `I` must all pass through `I` (nothing ends on the way
    /// and nothing crosses them earlier), so two of the edges through `I`
    /// are neighbours there, and every pair that becomes neighbours is
    /// tested.
    fn run(
        edges: &'a [Edge],
        rings: &[&Vec<V2>],
        ring_len: &'a [usize],
        n_outline_rings: usize,
    ) -> Result<Nesting, (usize, usize)> {
        let mut sweep = Sweep::new(edges, rings, ring_len, n_outline_rings);
        let events = sweep_events(&sweep.ends);
        let (mut ending, mut starting): (Vec<u32>, Vec<u32>) = (Vec::new(), Vec::new());
        let mut at = 0;
        while at < events.len() {
            let p = events[at].0;
            at = events_at(&events, at, &mut ending, &mut starting);
            sweep.visit(p, &mut ending, &mut starting)?;
        }
        Ok(sweep.nesting)
    }

    /// The sweep before its first event: the edges' ends ordered, the
    /// rings' first points found, an empty status and no ring placed.
    fn new(
        edges: &'a [Edge],
        rings: &[&Vec<V2>],
        ring_len: &'a [usize],
        n_outline_rings: usize,
    ) -> Sweep<'a> {
        let ends: Vec<(Point2<f64>, Point2<f64>)> = edges
            .iter()
            .map(|e| {
                let (a, b) = (zero(e.a), zero(e.b));
                if before(a, b) { (a, b) } else { (b, a) }
            })
            .collect();
        Sweep {
            edges,
            ring_len,
            n_outline_rings,
            ends,
            ring_first: ring_first_points(rings),
            status: Status::new(edges.iter().map(|e| e.ring < n_outline_rings).collect()),
            nesting: Nesting {
                inside_outline: vec![false; rings.len()],
                parent: vec![None; rings.len()],
            },
        }
    }

    /// `true` when edges `i` and `j` conflict ([`edges_conflict`]).
    fn conflict(&self, i: u32, j: u32) -> bool {
        edges_conflict(
            &self.edges[i as usize],
            &self.edges[j as usize],
            self.ring_len,
            self.n_outline_rings,
        )
    }

    /// Which side of edge `i` (from its first to its last end) `p` lies on:
    /// > 0 above (to the left), < 0 below, 0 on its line (exact).
    fn side(&self, i: u32, p: Point2<f64>) -> f64 {
        let (lo, hi) = self.ends[i as usize];
        orient(lo, hi, p)
    }

    /// Handles the events at point `p`: the edges `ending` there leave the
    /// status and the edges `starting` there enter it (`starting` is left
    /// sorted bottom to top, `ending` by direction too), testing every pair
    /// that meets at `p` or becomes neighbours. Errs with the first pair
    /// found to conflict.
    fn visit(
        &mut self,
        p: Point2<f64>,
        ending: &mut [u32],
        starting: &mut [u32],
    ) -> Result<(), (usize, usize)> {
        let any = ending.first().or(starting.first()).copied().unwrap_or(NIL);
        for &i in ending.iter() {
            self.status.remove(i);
        }
        let (below, above) = self.neighbours_of(p, any)?;
        self.check_edges_meeting_at(p, ending, starting)?;
        if starting.is_empty() {
            if below != NIL && above != NIL && self.conflict(below, above) {
                return Err((below as usize, above as usize));
            }
            return Ok(());
        }
        self.insert_starting(p, below, above, starting)
    }

    /// With the edges ending at `p` already removed: the edge of the status
    /// just below `p` and the first edge above `p` (either may be `NIL`).
    /// An edge left in the status with `p` on it conflicts with every edge
    /// that ends or starts at `p`; each is tested against `any`, one of
    /// those, and the first such conflict is the error.
    fn neighbours_of(&self, p: Point2<f64>, any: u32) -> Result<(u32, u32), (usize, usize)> {
        let first = self.status.first_not_below(|i| self.side(i, p));
        let below = if first == NIL {
            self.status.last()
        } else {
            self.status.pred(first)
        };
        let mut above = first;
        while above != NIL && self.side(above, p) == 0.0 {
            if self.conflict(above, any) {
                return Err((above as usize, any as usize));
            }
            above = self.status.succ(above);
        }
        Ok((below, above))
    }

    /// Tests the edges with an end at `p`: a hole's edge against another
    /// ring's, and any two leaving `p` in the same direction (sorting
    /// `ending` and `starting` by direction, counter-clockwise, on the way).
    /// Errs with the first pair found to conflict.
    fn check_edges_meeting_at(
        &self,
        p: Point2<f64>,
        ending: &mut [u32],
        starting: &mut [u32],
    ) -> Result<(), (usize, usize)> {
        let ring = |i: u32| self.edges[i as usize].ring;
        let incident = || ending.iter().chain(starting.iter()).copied();
        if let Some(h) = incident().find(|&i| ring(i) >= self.n_outline_rings)
            && let Some(o) = incident().find(|&i| ring(i) != ring(h))
            && self.conflict(h, o)
        {
            return Err((h as usize, o as usize));
        }
        if let Some(pair) = self.sort_by_direction(p, |i| self.ends[i as usize].0, ending) {
            return Err(pair);
        }
        if let Some(pair) = self.sort_by_direction(p, |i| self.ends[i as usize].1, starting) {
            return Err(pair);
        }
        Ok(())
    }

    /// Sorts `list`, edges with one end at `p`, counter-clockwise by the
    /// direction from `p` to their other end `far(i)` (same direction: by
    /// index), and returns the first pair of neighbours in that order that
    /// leave `p` in the same direction and conflict.
    fn sort_by_direction(
        &self,
        p: Point2<f64>,
        far: impl Fn(u32) -> Point2<f64>,
        list: &mut [u32],
    ) -> Option<(usize, usize)> {
        list.sort_by(|&i, &j| {
            let o = orient(p, far(i), far(j));
            if o > 0.0 {
                std::cmp::Ordering::Less
            } else if o < 0.0 {
                std::cmp::Ordering::Greater
            } else {
                i.cmp(&j)
            }
        });
        list.windows(2)
            .find(|w| orient(p, far(w[0]), far(w[1])) == 0.0 && self.conflict(w[0], w[1]))
            .map(|w| (w[0] as usize, w[1] as usize))
    }

    /// Inserts the (non-empty) edges `starting` at `p`, sorted bottom to
    /// top, into the status just above `below`, tests the lowest against
    /// `below` and the highest against `above` (each unless `NIL`), and, if
    /// a hole ring starts at `p`, records where it lies. Errs with the
    /// first pair found to conflict.
    fn insert_starting(
        &mut self,
        p: Point2<f64>,
        below: u32,
        above: u32,
        starting: &[u32],
    ) -> Result<(), (usize, usize)> {
        // Bottom to top: the direction sort put them counter-clockwise.
        let mut after = below;
        for &i in starting {
            self.status.insert_after(after, i);
            after = i;
        }
        let (low, high) = (starting[0], after);
        if below != NIL && self.conflict(below, low) {
            return Err((below as usize, low as usize));
        }
        if above != NIL && self.conflict(high, above) {
            return Err((high as usize, above as usize));
        }
        let r = self.edges[low as usize].ring;
        if r >= self.n_outline_rings && self.ring_first[r].0 == p {
            self.place_hole(r, low);
        }
        Ok(())
    }

    /// Records where hole ring `r` lies, from the status just after its
    /// first edges were inserted (`low` the lowest of them): inside the
    /// outline when an odd number of outline edges lie below, and inside
    /// the ring of the nearest hole edge below when that ring's inside is
    /// above the edge (else inside whatever that ring lies in).
    fn place_hole(&mut self, r: usize, low: u32) {
        self.nesting.inside_outline[r] = self.status.outline_below(low) % 2 == 1;
        let h = self.status.hole_below(low);
        if h != NIL {
            let e = &self.edges[h as usize];
            let forward = before(zero(e.a), zero(e.b));
            // Counter-clockwise, an edge walked left to right has
            // the ring's inside above it.
            self.nesting.parent[r] = if forward == self.ring_first[e.ring].1 {
                Some(e.ring)
            } else {
                self.nesting.parent[e.ring]
            };
        }
    }
}

/// The input's points as one flat list (the outline's, then each hole's in
/// order), with the way back from a flat index to the point as written.
struct FlatPoints {
    /// Every point: the outline's, then each hole's.
    all: Vec<DVec3>,
    /// The number of points of each ring: the outline, then each hole.
    ring_sizes: Vec<usize>,
}

impl FlatPoints {
    /// Flattens the outline and holes (copies; checks nothing).
    fn new(outline: &[DVec3], holes: &[Vec<DVec3>]) -> FlatPoints {
        let all: Vec<DVec3> = outline
            .iter()
            .chain(holes.iter().flatten())
            .copied()
            .collect();
        let ring_sizes: Vec<usize> = std::iter::once(outline.len())
            .chain(holes.iter().map(Vec::len))
            .collect();
        FlatPoints { all, ring_sizes }
    }

    /// Flat index (outline, then holes) → the point in its own ring (an
    /// index past the end comes back as that index of the outline).
    fn point_ref(&self, flat: usize) -> PointRef {
        let mut k = flat;
        for (r, &n) in self.ring_sizes.iter().enumerate() {
            if k < n {
                return PointRef {
                    hole: r.checked_sub(1),
                    index: k,
                };
            }
            k -= n;
        }
        PointRef {
            hole: None,
            index: flat,
        }
    }

    /// Errs with [`PolygonError::NotFinite`] naming the first point (in
    /// flat order) with a NaN or infinite coordinate.
    fn check_finite(&self) -> Result<(), PolygonError> {
        if let Some(index) = self.all.iter().position(|p| !p.is_finite()) {
            return Err(PolygonError::NotFinite {
                point: self.point_ref(index),
            });
        }
        Ok(())
    }

    /// The length of the diagonal of the points' bounding box.
    fn diameter(&self) -> f64 {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for p in &self.all {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        (hi - lo).length()
    }

    /// Errs with [`PolygonError::NotPlanar`] when a point lies farther than
    /// [`PLANARITY_TOLERANCE`] × `diameter` from the plane through
    /// `centroid` with unit normal `normal`, naming the farthest point
    /// (the first of equals).
    fn check_planar(
        &self,
        normal: DVec3,
        centroid: DVec3,
        diameter: f64,
    ) -> Result<(), PolygonError> {
        let limit = PLANARITY_TOLERANCE * diameter;
        // Report the point farthest from the plane (the first of equals).
        let mut worst = (0usize, 0.0f64);
        for (index, p) in self.all.iter().enumerate() {
            let distance = (*p - centroid).dot(normal).abs();
            if distance > worst.1 {
                worst = (index, distance);
            }
        }
        if worst.1 > limit {
            return Err(PolygonError::NotPlanar {
                point: self.point_ref(worst.0),
                distance: worst.1,
                tolerance: PLANARITY_TOLERANCE,
                diameter,
                limit,
            });
        }
        Ok(())
    }
}

/// The number of distinct points of a ring (bitwise: -0 and 0 differ).
fn distinct_points(r: &[DVec3]) -> usize {
    let mut v: Vec<[u64; 3]> = r.iter().map(|p| p.to_array().map(f64::to_bits)).collect();
    v.sort_unstable();
    v.dedup();
    v.len()
}

/// Errs with [`PolygonError::TooFewPoints`] for the first ring (the
/// outline, then the holes in order) with fewer than three distinct points.
fn check_enough_points(outline: &[DVec3], holes: &[Vec<DVec3>]) -> Result<(), PolygonError> {
    if distinct_points(outline) < 3 {
        return Err(PolygonError::TooFewPoints {
            hole: None,
            distinct: distinct_points(outline),
        });
    }
    for (k, h) in holes.iter().enumerate() {
        if distinct_points(h) < 3 {
            return Err(PolygonError::TooFewPoints {
                hole: Some(k),
                distinct: distinct_points(h),
            });
        }
    }
    Ok(())
}

/// The polygon's unit normal: the outline's Newell normal, or, where that
/// vanishes (relative to `diameter`²), the normal of its best-spread
/// triangle. Errs with [`PolygonError::Collinear`] when both vanish. The
/// outline must have at least one point.
fn unit_normal(outline: &[DVec3], diameter: f64) -> Result<DVec3, PolygonError> {
    let n = newell_normal(outline);
    // A self-crossing outline (a figure eight) can have a vanishing Newell
    // normal; its plane is then the one of its best-spread triangle, and
    // the crossing is reported below.
    let n = if n.length() > 1e-12 * diameter * diameter {
        n
    } else {
        best_triangle_normal(outline)
    };
    if n.length() <= 1e-12 * diameter * diameter || n.length() == 0.0 {
        return Err(PolygonError::Collinear);
    }
    Ok(n.normalize())
}

/// The outline and holes projected onto the plane through `centroid` with
/// unit normal `normal`, each point tagged with its flat index. The 2-D
/// basis is right-handed with the normal, so counter-clockwise in 2-D is
/// counter-clockwise around it. Errs with [`PolygonError::Triangulation`]
/// when a projected coordinate is not finite.
fn project_rings(
    outline: &[DVec3],
    holes: &[Vec<DVec3>],
    normal: DVec3,
    centroid: DVec3,
) -> Result<(Vec<V2>, Vec<Vec<V2>>), PolygonError> {
    // A right-handed basis (t, b, normal): counter-clockwise in (t, b) is
    // counter-clockwise around the normal.
    let t = normal.any_orthonormal_vector();
    let b = normal.cross(t);
    let project = |p: DVec3| {
        let q = p - centroid;
        Point2::new(q.dot(t), q.dot(b))
    };
    let mut flat_index = 0usize;
    let mut to_ring = |r: &[DVec3]| {
        let ring: Vec<V2> = r
            .iter()
            .map(|p| {
                let v = V2 {
                    p: project(*p),
                    index: flat_index,
                };
                flat_index += 1;
                v
            })
            .collect();
        ring
    };
    let projected_outline = to_ring(outline);
    let projected_holes: Vec<Vec<V2>> = holes.iter().map(|h| to_ring(h)).collect();
    if projected_outline
        .iter()
        .chain(projected_holes.iter().flatten())
        .any(|v| !(v.p.x.is_finite() && v.p.y.is_finite()))
    {
        // Only beyond ~1e307, where spade would refuse the points anyway.
        return Err(PolygonError::Triangulation(
            "a point projected onto the polygon's plane is not finite".into(),
        ));
    }
    Ok((projected_outline, projected_holes))
}

/// The projected rings after [`clean_ring`]: the outline's parts, then each
/// hole's parts. A ring's id is its position in [`SplitRings::all`].
struct SplitRings {
    /// The parts of the outline.
    outline: Vec<Vec<V2>>,
    /// The parts of each hole.
    holes: Vec<Vec<Vec<V2>>>,
}

impl SplitRings {
    /// Cleans and splits the projected outline and each projected hole.
    fn new(outline: &[V2], holes: &[Vec<V2>]) -> SplitRings {
        SplitRings {
            outline: clean_ring(outline),
            holes: holes.iter().map(|h| clean_ring(h)).collect(),
        }
    }

    /// Every part, by ring id: the outline's, then each hole's.
    fn all(&self) -> Vec<&Vec<V2>> {
        self.outline
            .iter()
            .chain(self.holes.iter().flatten())
            .collect()
    }

    /// The hole a ring id belongs to; `None` for the outline's parts (and
    /// for an id past the end).
    fn hole_of(&self, ring_id: usize) -> Option<usize> {
        if ring_id < self.outline.len() {
            return None;
        }
        let mut k = ring_id - self.outline.len();
        for (h, parts) in self.holes.iter().enumerate() {
            if k < parts.len() {
                return Some(h);
            }
            k -= parts.len();
        }
        None
    }

    /// Every ring (after splitting) must still enclose an area: errs with
    /// [`PolygonError::Spike`] for the first of `rings` ([`Self::all`])
    /// with fewer than three points (out and straight back).
    fn check_no_spikes(&self, rings: &[&Vec<V2>], points: &FlatPoints) -> Result<(), PolygonError> {
        for (id, r) in rings.iter().enumerate() {
            if r.len() < 3 {
                let from = r.first().map_or(0, |v| points.point_ref(v.index).index);
                let to = r.get(1).map_or(from, |v| points.point_ref(v.index).index);
                return Err(PolygonError::Spike {
                    hole: self.hole_of(id),
                    from,
                    to,
                });
            }
        }
        Ok(())
    }

    /// Holes must lie inside the outline region and outside the other
    /// holes: errs, for the first hole part (in ring order) that does not,
    /// with [`PolygonError::HoleOutside`] or [`PolygonError::HoleInHole`]
    /// (naming the least other hole around it).
    ///
    /// Rings neither cross nor touch a hole, so a hole ring lies wholly
    /// inside or outside every other ring: the sweep's answer at its first
    /// point holds for all of it.
    fn check_hole_placement(&self, nesting: &Nesting) -> Result<(), PolygonError> {
        let mut ring_id = self.outline.len();
        for (h, parts) in self.holes.iter().enumerate() {
            for _ in parts {
                let id = ring_id;
                ring_id += 1;
                if !nesting.inside_outline[id] {
                    return Err(PolygonError::HoleOutside { hole: h });
                }
                let mut other = None;
                let mut up = nesting.parent[id];
                while let Some(r) = up {
                    if let Some(g) = self.hole_of(r).filter(|&g| g != h) {
                        other = Some(other.map_or(g, |o: usize| o.min(g)));
                    }
                    up = nesting.parent[r];
                }
                if let Some(g) = other {
                    return Err(PolygonError::HoleInHole { hole: h, other: g });
                }
            }
        }
        Ok(())
    }
}

/// Every edge of `rings`, ring by ring, each ring's from point `k` to point
/// `k + 1` in order (its closing edge last).
fn ring_edges(rings: &[&Vec<V2>]) -> Vec<Edge> {
    let mut edges: Vec<Edge> = Vec::new();
    for (ring, r) in rings.iter().enumerate() {
        for k in 0..r.len() {
            let (a, b) = (r[k], r[(k + 1) % r.len()]);
            edges.push(Edge {
                ring,
                k,
                from: a.index,
                to: b.index,
                a: a.p,
                b: b.p,
            });
        }
    }
    edges
}

/// Every pair of ring edges that touch must be allowed to (adjacent edges
/// of a ring, parts of a split outline at their shared vertex): checks it
/// by the sweep, which also tells which rings each hole lies in. Errs with
/// [`PolygonError::SelfIntersecting`] naming a conflicting pair (the one
/// [`first_conflict_in_x_order`] finds, else the sweep's), ordered by
/// ring (the outline, then the holes in order) and then by first point.
fn check_simple(
    edges: &[Edge],
    rings: &[&Vec<V2>],
    split: &SplitRings,
    points: &FlatPoints,
) -> Result<Nesting, PolygonError> {
    let ring_len: Vec<usize> = rings.iter().map(|r| r.len()).collect();
    let n_outline_rings = split.outline.len();
    let sweep = Sweep::run(edges, rings, &ring_len, n_outline_rings);
    match sweep {
        Ok(nesting) => Ok(nesting),
        Err(found) => {
            let (i, j) =
                first_conflict_in_x_order(edges, &ring_len, n_outline_rings, MAX_NAMING_TESTS)
                    .unwrap_or(found);
            let edge_ref = |x: &Edge| EdgeRef {
                hole: split.hole_of(x.ring),
                from: points.point_ref(x.from).index,
                to: points.point_ref(x.to).index,
            };
            let (mut a, mut b) = (edge_ref(&edges[i]), edge_ref(&edges[j]));
            let order = |x: &EdgeRef| (x.hole.map_or(0, |h| h + 1), x.from);
            if order(&b) < order(&a) {
                std::mem::swap(&mut a, &mut b);
            }
            Err(PolygonError::SelfIntersecting { a, b })
        }
    }
}

/// The triangulator used.
type Cdt = ConstrainedDelaunayTriangulation<V2>;

/// The constrained Delaunay triangulation of the rings' points, inserted
/// ring by ring, with every ring edge a constraint. Errs with
/// [`PolygonError::Triangulation`] when spade refuses a point or a
/// constraint would cross another.
fn constrained_triangulation(rings: &[&Vec<V2>]) -> Result<Cdt, PolygonError> {
    let mut cdt: Cdt = ConstrainedDelaunayTriangulation::new();
    for r in rings {
        let handles: Vec<_> = r
            .iter()
            .map(|v| {
                cdt.insert(*v)
                    .map_err(|e| PolygonError::Triangulation(format!("{e:?}")))
            })
            .collect::<Result<_, _>>()?;
        for k in 0..handles.len() {
            let (from, to) = (handles[k], handles[(k + 1) % handles.len()]);
            if from == to {
                continue;
            }
            if !cdt.can_add_constraint(from, to) {
                return Err(PolygonError::Triangulation(
                    "a ring edge crosses another (numerically)".into(),
                ));
            }
            cdt.add_constraint(from, to);
        }
    }
    Ok(cdt)
}

/// Even-odd flood fill from the outside, by face index: `Some(true)` for
/// the faces inside the polygon. The faces along the convex hull are
/// inside exactly when their hull edge is a constraint; crossing a
/// constraint edge toggles inside/outside. Faces not reached stay `None`.
fn face_parity(cdt: &Cdt) -> Vec<Option<bool>> {
    let mut parity: Vec<Option<bool>> = vec![None; cdt.num_all_faces()];
    let mut queue = std::collections::VecDeque::new();
    for hull_edge in cdt.convex_hull() {
        for e in [hull_edge, hull_edge.rev()] {
            if let Some(inner) = e.face().as_inner() {
                let slot = &mut parity[inner.fix().index()];
                if slot.is_none() {
                    *slot = Some(e.is_constraint_edge());
                    queue.push_back(inner.fix());
                }
            }
        }
    }
    while let Some(fh) = queue.pop_front() {
        let p = parity[fh.index()].unwrap_or(false);
        for e in cdt.face(fh).adjacent_edges() {
            if let Some(neighbour) = e.rev().face().as_inner() {
                let slot = &mut parity[neighbour.fix().index()];
                if slot.is_none() {
                    *slot = Some(p ^ e.is_constraint_edge());
                    queue.push_back(neighbour.fix());
                }
            }
        }
    }
    parity
}

/// The inside faces ([`face_parity`]) as triangles of flat input indices,
/// in spade's face order with spade's (counter-clockwise) vertex order.
/// Errs with [`PolygonError::Triangulation`] when there are none.
fn inside_triangles(cdt: &Cdt) -> Result<Vec<[u32; 3]>, PolygonError> {
    let parity = face_parity(cdt);
    let mut triangles = Vec::new();
    for face in cdt.inner_faces() {
        if parity[face.fix().index()] == Some(true) {
            let v = face.vertices();
            let idx = v.map(|h| u32::try_from(h.data().index).unwrap_or(u32::MAX));
            triangles.push(idx);
        }
    }
    if triangles.is_empty() {
        return Err(PolygonError::Triangulation(
            "no area inside the outline".into(),
        ));
    }
    Ok(triangles)
}

/// Validates and triangulates a polygon given as an outline and holes
/// (each a ring of 3-D points, closing edge implied).
///
/// # Errors
///
/// [`PolygonError`] naming the first problem found.
pub fn triangulate(
    outline: &[DVec3],
    holes: &[Vec<DVec3>],
    opts: PolygonOptions,
) -> Result<Triangulated, PolygonError> {
    let points = FlatPoints::new(outline, holes);
    points.check_finite()?;
    let diameter = points.diameter();
    check_enough_points(outline, holes)?;
    let normal = unit_normal(outline, diameter)?;
    #[expect(
        clippy::cast_precision_loss,
        reason = "a corner count is far below 2^53: exact in f64"
    )]
    let centroid = outline.iter().copied().sum::<DVec3>() / outline.len() as f64;
    if opts.check_planarity {
        points.check_planar(normal, centroid, diameter)?;
    }
    let (projected_outline, projected_holes) = project_rings(outline, holes, normal, centroid)?;
    let split = SplitRings::new(&projected_outline, &projected_holes);
    let rings = split.all();
    split.check_no_spikes(&rings, &points)?;
    let edges = ring_edges(&rings);
    let nesting = check_simple(&edges, &rings, &split, &points)?;
    split.check_hole_placement(&nesting)?;
    let cdt = constrained_triangulation(&rings)?;
    let triangles = inside_triangles(&cdt)?;
    Ok(Triangulated { normal, triangles })
}

/// Checks that `uv` (one per input point) is an affine function of
/// position within [`UV_AFFINE_TOLERANCE`].
///
/// # Errors
///
/// [`PolygonError::Uv`] when it is not.
pub(crate) fn check_uv_affine(
    points: &[DVec3],
    uv: &[[f64; 2]],
    normal: DVec3,
) -> Result<(), PolygonError> {
    if points.len() != uv.len() {
        return Err(PolygonError::Uv(format!(
            "uv has {} entries but the polygon has {} points (outline then holes)",
            uv.len(),
            points.len()
        )));
    }
    if let Some(k) = uv
        .iter()
        .position(|q| !q[0].is_finite() || !q[1].is_finite())
    {
        return Err(PolygonError::Uv(format!("uv {k} is not finite")));
    }
    let t = normal.any_orthonormal_vector();
    let b = normal.cross(t);
    let p2: Vec<[f64; 2]> = points.iter().map(|p| [p.dot(t), p.dot(b)]).collect();
    // The best-conditioned triple: the first point, the farthest from it,
    // and the farthest from their line.
    let i0 = 0;
    let dist = |a: [f64; 2], c: [f64; 2]| ((a[0] - c[0]).powi(2) + (a[1] - c[1]).powi(2)).sqrt();
    let i1 = (0..p2.len())
        .max_by(|&x, &y| dist(p2[x], p2[i0]).total_cmp(&dist(p2[y], p2[i0])))
        .unwrap_or(0);
    let area = |c: [f64; 2]| {
        ((p2[i1][0] - p2[i0][0]) * (c[1] - p2[i0][1])
            - (p2[i1][1] - p2[i0][1]) * (c[0] - p2[i0][0]))
            .abs()
    };
    let i2 = (0..p2.len())
        .max_by(|&x, &y| area(p2[x]).total_cmp(&area(p2[y])))
        .unwrap_or(0);
    // Solve uv = A·(p − p0) + uv0 from the two other points.
    let (e1, e2) = (
        [p2[i1][0] - p2[i0][0], p2[i1][1] - p2[i0][1]],
        [p2[i2][0] - p2[i0][0], p2[i2][1] - p2[i0][1]],
    );
    let det = e1[0] * e2[1] - e1[1] * e2[0];
    if det == 0.0 {
        return Err(PolygonError::Collinear);
    }
    let (uv0, uv1, uv2) = (uv[i0], uv[i1], uv[i2]);
    let mut extent: f64 = 0.0;
    for q in uv {
        extent = extent.max((q[0] - uv0[0]).abs()).max((q[1] - uv0[1]).abs());
    }
    let tol = UV_AFFINE_TOLERANCE * (extent + 1.0);
    for (k, (p, q)) in p2.iter().zip(uv).enumerate() {
        let d = [p[0] - p2[i0][0], p[1] - p2[i0][1]];
        // Barycentric-like coordinates of d in (e1, e2).
        let s = (d[0] * e2[1] - d[1] * e2[0]) / det;
        let r = (e1[0] * d[1] - e1[1] * d[0]) / det;
        for c in 0..2 {
            let pred = uv0[c] + s * (uv1[c] - uv0[c]) + r * (uv2[c] - uv0[c]);
            if (pred - q[c]).abs() > tol {
                return Err(PolygonError::Uv(format!(
                    "uv {k} is not an affine function of position (off by {:.3e}, tolerance {tol:.1e})",
                    (pred - q[c]).abs()
                )));
            }
        }
    }
    Ok(())
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

    /// Even-odd point-in-ring test; `None` when `p` lies on the ring (exact).
    fn inside_ring(ring: &[V2], p: Point2<f64>) -> Option<bool> {
        let mut inside = false;
        for k in 0..ring.len() {
            let a = ring[k].p;
            let b = ring[(k + 1) % ring.len()].p;
            if on_segment(a, b, p) {
                return None;
            }
            if (a.y > p.y) != (b.y > p.y) {
                // Does the edge cross the horizontal ray to the right of p?
                let o = orient(a, b, p);
                if (o > 0.0) == (b.y > a.y) {
                    inside = !inside;
                }
            }
        }
        Some(inside)
    }

    const OPTS: PolygonOptions = PolygonOptions {
        check_planarity: true,
    };

    fn xy(points: &[(f64, f64)]) -> Vec<DVec3> {
        points.iter().map(|&(x, y)| DVec3::new(x, y, 0.0)).collect()
    }

    fn area(tri: &Triangulated, pts: &[DVec3]) -> f64 {
        tri.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| pts[i as usize]);
                (b - a).cross(c - a).dot(tri.normal) / 2.0
            })
            .sum()
    }

    /// A regular 2n-gon, every other corner pulled in to `inner` (1: convex).
    fn star(corners: usize, inner: f64) -> Vec<DVec3> {
        (0..corners)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / corners as f64;
                let r = if k % 2 == 1 { inner } else { 1.0 };
                DVec3::new(r * a.cos(), r * a.sin(), 0.0)
            })
            .collect()
    }

    #[test]
    fn a_polygon_of_200_000_corners_is_quick() {
        // Was 76 s: the ring split searched its stack for every point, and
        // the edge check tested every pair of edges with overlapping x
        // ranges (quadratic for a star).
        for inner in [1.0, 0.5] {
            let pts = star(200_000, inner);
            let t = triangulate(&pts, &[], OPTS).unwrap();
            assert_eq!(t.triangles.len(), 200_000 - 2, "inner radius {inner}");
        }
    }

    #[test]
    fn twenty_thousand_holes_are_quick() {
        // Each hole was tested against every ring: O(holes × points).
        let outline = xy(&[(0.0, 0.0), (300.0, 0.0), (300.0, 300.0), (0.0, 300.0)]);
        let mut holes = Vec::new();
        for i in 0..140 {
            for j in 0..143 {
                let (x, y) = (1.0 + 2.0 * f64::from(i), 1.0 + 2.0 * f64::from(j));
                holes.push(xy(&[(x, y), (x + 1.0, y), (x, y + 1.0)]));
            }
        }
        let t = triangulate(&outline, &holes, OPTS).unwrap();
        assert_eq!(t.triangles.len(), 4 + 3 * holes.len() + 2 * holes.len() - 2);
        // One hole moved out, and one into another.
        holes[5000] = xy(&[(301.0, 1.0), (302.0, 1.0), (301.0, 2.0)]);
        assert_eq!(
            triangulate(&outline, &holes, OPTS),
            Err(PolygonError::HoleOutside { hole: 5000 })
        );
        holes[5000] = xy(&[(1.1, 1.1), (1.3, 1.1), (1.1, 1.3)]);
        assert_eq!(
            triangulate(&outline, &holes, OPTS),
            Err(PolygonError::HoleInHole {
                hole: 5000,
                other: 0
            })
        );
    }

    #[test]
    fn a_star_with_a_crossing_names_the_crossing_edges() {
        // One spike of a 20 000-corner star pushed across its neighbour.
        let mut pts = star(20_000, 0.5);
        pts[1001] = DVec3::new(pts[1003].x * 1.2, pts[1003].y * 1.2, 0.0);
        let e = triangulate(&pts, &[], OPTS).unwrap_err();
        let PolygonError::SelfIntersecting { a, b } = e else {
            panic!("{e}")
        };
        assert!(a.from >= 1000 && b.from <= 1003, "{a} / {b}");
    }

    struct Rng(u64);

    impl Rng {
        fn below(&mut self, n: u64) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0 % n
        }
    }

    /// A random ring: points on a small grid (collinear and repeated
    /// points, touching edges) or a star around (cx, cy).
    fn random_ring(rng: &mut Rng, cx: f64, cy: f64, scale: f64, star: bool) -> Vec<V2> {
        let n = 3 + rng.below(10) as usize;
        let pts: Vec<Point2<f64>> = if !star && rng.below(2) == 0 {
            (0..n)
                .map(|_| {
                    Point2::new(
                        cx + (rng.below(5) as f64 - 2.0) * scale,
                        cy + (rng.below(5) as f64 - 2.0) * scale,
                    )
                })
                .collect()
        } else {
            // Distinct directions, mostly.
            let mut a: Vec<u64> = (0..n).map(|_| rng.below(16)).collect();
            a.sort_unstable();
            if star {
                a.dedup();
            }
            a.iter()
                .map(|&k| {
                    let t = std::f64::consts::TAU * k as f64 / 16.0;
                    let r = (1 + rng.below(3)) as f64 * scale;
                    Point2::new(cx + r * t.cos(), cy + r * t.sin())
                })
                .collect()
        };
        pts.into_iter()
            .enumerate()
            .map(|(index, p)| V2 { p, index })
            .collect()
    }

    /// Random rings for the sweep test, as split by [`clean_ring`] and
    /// without parts of fewer than three points: the outline's parts (one
    /// or two random rings, sharing a vertex or not), then the parts of up
    /// to five holes (some stars nested around one point). Also returns
    /// the number of outline parts; `None` when the outline has none.
    fn random_rings(rng: &mut Rng) -> Option<(Vec<Vec<V2>>, usize)> {
        let star = rng.below(2) == 0;
        let mut outline: Vec<Vec<V2>> = clean_ring(&random_ring(rng, 0.0, 0.0, 2.0, star));
        if rng.below(3) == 0 {
            // Another part, sharing a vertex or not.
            let mut more = random_ring(rng, 1.0, 1.0, 1.0, false);
            if rng.below(2) == 0 {
                more[0].p = outline[0][0].p;
            }
            outline.extend(clean_ring(&more));
        }
        let mut rings: Vec<Vec<V2>> = outline.into_iter().filter(|r| r.len() >= 3).collect();
        if rings.is_empty() {
            return None;
        }
        let n_outline_rings = rings.len();
        let mut holes = Vec::new();
        for _ in 0..rng.below(3) {
            let (cx, cy) = (rng.below(7) as f64 - 3.0, rng.below(7) as f64 - 3.0);
            let scale = [0.1, 0.25, 0.5, 1.5][rng.below(4) as usize];
            holes.push(random_ring(rng, cx, cy, scale, false));
        }
        if rng.below(2) == 0 {
            // Stars nested around one point.
            let (cx, cy) = (rng.below(3) as f64 - 1.0, rng.below(3) as f64 - 1.0);
            for scale in [1.0, 0.3, 0.09].into_iter().take(1 + rng.below(3) as usize) {
                holes.push(random_ring(rng, cx, cy, scale, true));
            }
            let k = rng.below(holes.len() as u64) as usize;
            holes.rotate_left(k);
        }
        for h in &holes {
            rings.extend(clean_ring(h).into_iter().filter(|r| r.len() >= 3));
        }
        Some((rings, n_outline_rings))
    }

    /// Asserts that `nesting` places every hole ring of `rings` as even-odd
    /// point-in-ring tests at its first point do. Returns how many hole
    /// rings lie outside the outline and how many inside another hole.
    fn assert_nesting_as_tested(
        rings: &[Vec<V2>],
        n_outline_rings: usize,
        nesting: &Nesting,
    ) -> (usize, usize) {
        let (mut outside, mut nested) = (0, 0);
        for id in n_outline_rings..rings.len() {
            let p = rings[id][0].p;
            let inside = |r: &[V2]| inside_ring(r, p) == Some(true);
            let outlines = rings[..n_outline_rings]
                .iter()
                .filter(|r| inside(r))
                .count();
            assert_eq!(nesting.inside_outline[id], outlines % 2 == 1);
            outside += usize::from(outlines % 2 == 0);
            let mut expected: Vec<usize> = (n_outline_rings..rings.len())
                .filter(|&g| g != id && inside(&rings[g]))
                .collect();
            let mut chain = Vec::new();
            let mut up = nesting.parent[id];
            while let Some(g) = up {
                chain.push(g);
                up = nesting.parent[g];
            }
            chain.sort_unstable();
            expected.sort_unstable();
            assert_eq!(chain, expected, "{rings:?}");
            nested += usize::from(!chain.is_empty());
        }
        (outside, nested)
    }

    #[test]
    fn the_sweep_agrees_with_testing_every_pair() {
        // The sweep finds a conflict exactly when some pair of edges
        // conflicts; where there is none, it places every hole ring as
        // even-odd point-in-ring tests do.
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        let (mut conflicts, mut nested, mut outside) = (0, 0, 0);
        for _ in 0..20_000 {
            let Some((rings, n_outline_rings)) = random_rings(&mut rng) else {
                continue;
            };
            let ring_len: Vec<usize> = rings.iter().map(Vec::len).collect();
            let refs: Vec<&Vec<V2>> = rings.iter().collect();
            let edges = ring_edges(&refs);
            let brute = first_conflict_in_x_order(&edges, &ring_len, n_outline_rings, usize::MAX);
            match Sweep::run(&edges, &refs, &ring_len, n_outline_rings) {
                Err((i, j)) => {
                    conflicts += 1;
                    assert!(brute.is_some());
                    assert!(edges_conflict(
                        &edges[i],
                        &edges[j],
                        &ring_len,
                        n_outline_rings
                    ));
                }
                Ok(nesting) => {
                    assert_eq!(brute, None, "{rings:?}");
                    let (o, n) = assert_nesting_as_tested(&rings, n_outline_rings, &nesting);
                    outside += o;
                    nested += n;
                }
            }
        }
        // The cases exist.
        assert!(
            conflicts > 1000 && nested > 100 && outside > 100,
            "{conflicts} {nested} {outside}"
        );
    }

    #[test]
    fn concave_outline_is_not_fanned() {
        // An L shape: a fan from vertex 0 would cover the notch.
        let pts = xy(&[
            (0.0, 0.0),
            (2.0, 0.0),
            (2.0, 1.0),
            (1.0, 1.0),
            (1.0, 2.0),
            (0.0, 2.0),
        ]);
        let t = triangulate(&pts, &[], OPTS).unwrap();
        assert_eq!(t.triangles.len(), 4);
        assert!((area(&t, &pts) - 3.0).abs() < 1e-12);
        // Every triangle winds counter-clockwise around the normal.
        for tri in &t.triangles {
            let [a, b, c] = tri.map(|i| pts[i as usize]);
            assert!((b - a).cross(c - a).dot(t.normal) > 0.0);
        }
    }

    #[test]
    fn hole_is_removed() {
        let outline = xy(&[(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]);
        let hole = xy(&[(1.0, 1.0), (1.0, 3.0), (3.0, 3.0), (3.0, 1.0)]);
        let t = triangulate(&outline, std::slice::from_ref(&hole), OPTS).unwrap();
        let all: Vec<DVec3> = outline.iter().chain(&hole).copied().collect();
        assert!((area(&t, &all) - 12.0).abs() < 1e-12);
    }

    #[test]
    fn bow_tie_touching_at_a_vertex_splits_in_two() {
        // POVRAY.md §9.8's bow tie.
        let pts = xy(&[
            (5.5, 0.0),
            (7.0, 0.0),
            (6.25, 1.0),
            (7.0, 2.0),
            (5.5, 2.0),
            (6.25, 1.0),
        ]);
        let t = triangulate(&pts, &[], OPTS).unwrap();
        assert_eq!(t.triangles.len(), 2);
    }

    #[test]
    fn crossing_edges_are_an_error_not_a_panic() {
        let pts = xy(&[(0.0, 0.0), (2.0, 2.0), (2.0, 0.0), (0.0, 2.0)]);
        assert!(matches!(
            triangulate(&pts, &[], OPTS),
            Err(PolygonError::SelfIntersecting { .. })
        ));
    }

    #[test]
    fn non_planar_collinear_and_short_rings_are_errors() {
        let mut pts = xy(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        pts[2].z = 0.01;
        assert!(matches!(
            triangulate(&pts, &[], OPTS),
            Err(PolygonError::NotPlanar { .. })
        ));
        let line = xy(&[(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)]);
        assert_eq!(triangulate(&line, &[], OPTS), Err(PolygonError::Collinear));
        let two = xy(&[(0.0, 0.0), (1.0, 0.0), (1.0, 0.0), (0.0, 0.0)]);
        assert!(matches!(
            triangulate(&two, &[], OPTS),
            Err(PolygonError::TooFewPoints { .. })
        ));
    }

    #[test]
    fn hole_outside_or_touching_is_an_error() {
        let outline = xy(&[(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]);
        let outside = xy(&[(5.0, 1.0), (6.0, 1.0), (6.0, 2.0)]);
        assert!(matches!(
            triangulate(&outline, &[outside], OPTS),
            Err(PolygonError::HoleOutside { .. })
        ));
        let touching = xy(&[(0.0, 1.0), (2.0, 1.0), (2.0, 2.0)]);
        assert!(matches!(
            triangulate(&outline, &[touching], OPTS),
            Err(PolygonError::SelfIntersecting { .. })
        ));
    }

    #[test]
    fn errors_name_the_points_as_written() {
        // A figure eight: the edges 0–1 and 2–3 cross.
        let eight = xy(&[(0.0, 0.0), (2.0, 2.0), (2.0, 0.0), (0.0, 2.0)]);
        let e = triangulate(&eight, &[], OPTS).unwrap_err();
        assert_eq!(
            e,
            PolygonError::SelfIntersecting {
                a: EdgeRef {
                    hole: None,
                    from: 0,
                    to: 1
                },
                b: EdgeRef {
                    hole: None,
                    from: 2,
                    to: 3
                },
            }
        );
        assert!(
            e.to_string().starts_with(
                "the outline's edge from point 0 to point 1 and the outline's edge from point 2 to point 3 cross"
            ),
            "{e}"
        );
        // A spike out to point 3 and back to point 2.
        let spike = xy(&[
            (0.0, 0.0),
            (2.0, 0.0),
            (2.0, 2.0),
            (3.0, 3.0),
            (2.0, 2.0),
            (0.0, 2.0),
        ]);
        assert_eq!(
            triangulate(&spike, &[], OPTS),
            Err(PolygonError::Spike {
                hole: None,
                from: 2,
                to: 3
            })
        );
        // The point farthest from the plane is the one reported.
        let mut raised = xy(&[(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (1.0, 3.0), (0.0, 2.0)]);
        raised[3].z = 0.5;
        assert!(matches!(
            triangulate(&raised, &[], OPTS),
            Err(PolygonError::NotPlanar {
                point: PointRef {
                    hole: None,
                    index: 3
                },
                ..
            })
        ));
        // Hole points are numbered within their hole.
        let outline = xy(&[(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]);
        let hole = vec![
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(2.0, 1.0, f64::NAN),
            DVec3::new(2.0, 2.0, 0.0),
        ];
        assert_eq!(
            triangulate(&outline, &[hole], OPTS),
            Err(PolygonError::NotFinite {
                point: PointRef {
                    hole: Some(0),
                    index: 1
                }
            })
        );
    }

    #[test]
    fn hole_inside_another_hole_is_an_error() {
        let outline = xy(&[(0.0, 0.0), (8.0, 0.0), (8.0, 8.0), (0.0, 8.0)]);
        let big = xy(&[(1.0, 1.0), (7.0, 1.0), (7.0, 7.0), (1.0, 7.0)]);
        let small = xy(&[(3.0, 3.0), (4.0, 3.0), (4.0, 4.0)]);
        assert_eq!(
            triangulate(&outline, &[big, small], OPTS),
            Err(PolygonError::HoleInHole { hole: 1, other: 0 })
        );
    }

    #[test]
    fn uv_must_be_affine() {
        let pts = xy(&[(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (0.0, 1.0)]);
        let n = DVec3::Z;
        let good = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        check_uv_affine(&pts, &good, n).unwrap();
        let bad = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.2, 1.0]];
        assert!(check_uv_affine(&pts, &bad, n).is_err());
    }
}
