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

use spade::{ConstrainedDelaunayTriangulation, HasPosition, Point2, Triangulation};

use crate::math::DVec3;

/// Points farther than `PLANARITY_TOLERANCE × diameter` from the polygon's
/// Newell plane make a polygon non-planar (DESIGN.md §4).
pub const PLANARITY_TOLERANCE: f64 = 1e-5;

/// uv coordinates whose residual from the best affine fit in position
/// exceeds `UV_AFFINE_TOLERANCE × (uv extent + 1)` are not affine.
pub const UV_AFFINE_TOLERANCE: f64 = 1e-5;

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

/// Newell normal (not normalised) of a ring of 3-D points.
#[must_use]
pub fn newell_normal(points: &[DVec3]) -> DVec3 {
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
    let mut out = Vec::new();
    let mut stack: Vec<V2> = Vec::new();
    for v in pts {
        if let Some(pos) = stack.iter().position(|s| s.p == v.p) {
            let loop_part: Vec<V2> = stack.drain(pos + 1..).collect();
            let mut ring = vec![stack[pos]];
            ring.extend(loop_part);
            out.push(ring);
        } else {
            stack.push(v);
        }
    }
    out.push(stack);
    out
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
    let all: Vec<DVec3> = outline
        .iter()
        .chain(holes.iter().flatten())
        .copied()
        .collect();
    // Flat index (outline, then holes) → the point in its own ring.
    let ring_sizes: Vec<usize> = std::iter::once(outline.len())
        .chain(holes.iter().map(Vec::len))
        .collect();
    let point_ref = |flat: usize| -> PointRef {
        let mut k = flat;
        for (r, &n) in ring_sizes.iter().enumerate() {
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
    };
    if let Some(index) = all.iter().position(|p| !p.is_finite()) {
        return Err(PolygonError::NotFinite {
            point: point_ref(index),
        });
    }
    let n = newell_normal(outline);
    let diameter = {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for p in &all {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        (hi - lo).length()
    };
    let distinct = |r: &[DVec3]| {
        let mut v: Vec<[u64; 3]> = r.iter().map(|p| p.to_array().map(f64::to_bits)).collect();
        v.sort_unstable();
        v.dedup();
        v.len()
    };
    if distinct(outline) < 3 {
        return Err(PolygonError::TooFewPoints {
            hole: None,
            distinct: distinct(outline),
        });
    }
    for (k, h) in holes.iter().enumerate() {
        if distinct(h) < 3 {
            return Err(PolygonError::TooFewPoints {
                hole: Some(k),
                distinct: distinct(h),
            });
        }
    }
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
    let normal = n.normalize();
    let centroid = outline.iter().copied().sum::<DVec3>() / outline.len() as f64;
    if opts.check_planarity {
        let limit = PLANARITY_TOLERANCE * diameter;
        // Report the point farthest from the plane (the first of equals).
        let mut worst = (0usize, 0.0f64);
        for (index, p) in all.iter().enumerate() {
            let distance = (*p - centroid).dot(normal).abs();
            if distance > worst.1 {
                worst = (index, distance);
            }
        }
        if worst.1 > limit {
            return Err(PolygonError::NotPlanar {
                point: point_ref(worst.0),
                distance: worst.1,
                tolerance: PLANARITY_TOLERANCE,
                diameter,
                limit,
            });
        }
    }
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
    let outline_rings = clean_ring(&to_ring(outline));
    let hole_rings: Vec<Vec<Vec<V2>>> = holes.iter().map(|h| clean_ring(&to_ring(h))).collect();

    // Every ring (after splitting) must still enclose an area: a part
    // of two points is a spike, out and straight back.
    let hole_of = |ring_id: usize| -> Option<usize> {
        if ring_id < outline_rings.len() {
            return None;
        }
        let mut k = ring_id - outline_rings.len();
        for (h, parts) in hole_rings.iter().enumerate() {
            if k < parts.len() {
                return Some(h);
            }
            k -= parts.len();
        }
        None
    };
    let rings: Vec<&Vec<V2>> = outline_rings
        .iter()
        .chain(hole_rings.iter().flatten())
        .collect();
    for (id, r) in rings.iter().enumerate() {
        if r.len() < 3 {
            let from = r.first().map_or(0, |v| point_ref(v.index).index);
            let to = r.get(1).map_or(from, |v| point_ref(v.index).index);
            return Err(PolygonError::Spike {
                hole: hole_of(id),
                from,
                to,
            });
        }
    }

    // Edges: (ring id, edge index in ring, a, b).
    struct Edge {
        ring: usize,
        k: usize,
        from: usize,
        to: usize,
        a: Point2<f64>,
        b: Point2<f64>,
        xmin: f64,
        xmax: f64,
    }
    let mut edges: Vec<Edge> = Vec::new();
    for (ring, r) in rings.iter().enumerate() {
        for k in 0..r.len() {
            let a = r[k].p;
            let b = r[(k + 1) % r.len()].p;
            edges.push(Edge {
                ring,
                k,
                from: r[k].index,
                to: r[(k + 1) % r.len()].index,
                a,
                b,
                xmin: a.x.min(b.x),
                xmax: a.x.max(b.x),
            });
        }
    }
    edges.sort_by(|x, y| x.xmin.total_cmp(&y.xmin));
    let n_outline_rings = outline_rings.len();
    for i in 0..edges.len() {
        for j in i + 1..edges.len() {
            if edges[j].xmin > edges[i].xmax {
                break;
            }
            let (e, f) = (&edges[i], &edges[j]);
            let same_ring = e.ring == f.ring;
            let len = rings[e.ring].len();
            let adjacent = same_ring && ((e.k + 1) % len == f.k || (f.k + 1) % len == e.k);
            if adjacent {
                // Adjacent edges share one endpoint; they may not overlap.
                let shared = if (e.k + 1) % len == f.k { e.b } else { e.a };
                let (eo, fo) = (
                    if e.a == shared { e.b } else { e.a },
                    if f.a == shared { f.b } else { f.a },
                );
                let folds_back = on_segment(shared, eo, fo) || on_segment(shared, fo, eo);
                if !folds_back {
                    continue;
                }
            } else if !segments_touch(e.a, e.b, f.a, f.b) {
                continue;
            } else if !same_ring && e.ring < n_outline_rings && f.ring < n_outline_rings {
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
                    continue;
                }
            }
            // Any other touch (non-adjacent edges of one ring, a hole and
            // another ring) breaks "simple and disjoint".
            let edge_ref = |x: &Edge| EdgeRef {
                hole: hole_of(x.ring),
                from: point_ref(x.from).index,
                to: point_ref(x.to).index,
            };
            let (mut a, mut b) = (edge_ref(e), edge_ref(f));
            let order = |x: &EdgeRef| (x.hole.map_or(0, |h| h + 1), x.from);
            if order(&b) < order(&a) {
                std::mem::swap(&mut a, &mut b);
            }
            return Err(PolygonError::SelfIntersecting { a, b });
        }
    }

    // Holes must lie inside the outline region and outside the other holes.
    for (h, parts) in hole_rings.iter().enumerate() {
        for part in parts {
            let p = part[0].p;
            let mut in_outline = false;
            for r in &outline_rings {
                if inside_ring(r, p) == Some(true) {
                    in_outline = !in_outline;
                }
            }
            if !in_outline {
                return Err(PolygonError::HoleOutside { hole: h });
            }
            for (g, other) in hole_rings.iter().enumerate() {
                if g != h && other.iter().any(|r| inside_ring(r, p) == Some(true)) {
                    return Err(PolygonError::HoleInHole { hole: h, other: g });
                }
            }
        }
    }

    // Constrained Delaunay triangulation with every ring edge a constraint.
    let mut cdt: ConstrainedDelaunayTriangulation<V2> = ConstrainedDelaunayTriangulation::new();
    for r in &rings {
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

    // Even-odd flood fill from the outside: the faces along the convex hull
    // are inside exactly when their hull edge is a constraint; crossing a
    // constraint edge toggles inside/outside.
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
    Ok(Triangulated { normal, triangles })
}

/// Checks that `uv` (one per input point) is an affine function of
/// position within [`UV_AFFINE_TOLERANCE`].
///
/// # Errors
///
/// [`PolygonError::Uv`] when it is not.
pub fn check_uv_affine(
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
mod tests {
    use super::*;

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
