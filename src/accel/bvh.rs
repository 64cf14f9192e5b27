//! A 4-wide bounding volume hierarchy over triangles.
//!
//! Build: a binary tree by binned SAH (Wald 2007: 16 bins per axis over the
//! centroid bounds, object-median splits where every centroid coincides),
//! split in parallel with `rayon::join` above 4096 primitives, then
//! collapsed into 4-wide nodes (each node adopts the grandchildren of its
//! largest inner children) with their child boxes stored as structure-of-
//! arrays `Vec4`s, so one node visit tests four boxes with SSE.
//!
//! Traversal: ordered (nearest child first) with a precomputed inverse
//! direction; `t_far` of every box is enlarged by `1 + 2γ(3)` (Ize 2013,
//! pbrt-v4), so rounding never culls a box the ray really enters: the BVH
//! finds exactly the hits a linear scan finds.

use glam::Vec4;

use super::triangle::{RayPrecomp, TriHit, intersect};
use crate::math::{Aabb, Ray, Vec3, gamma};

/// Child slot encoding: the high bit marks a leaf.
const LEAF: u32 = 1 << 31;
/// An empty child slot.
const EMPTY: u32 = u32::MAX;

/// Largest number of triangles in a leaf.
pub const MAX_LEAF: usize = 8;
/// Bins per axis of the SAH build.
const BINS: usize = 16;
/// Relative cost of a node visit against a triangle test.
const TRAVERSAL_COST: f32 = 1.0;
/// Subtrees larger than this are built in parallel.
const PARALLEL_THRESHOLD: usize = 4096;

/// A 4-wide node.
#[derive(Clone, Copy, Debug)]
pub struct Node4 {
    min_x: Vec4,
    max_x: Vec4,
    min_y: Vec4,
    max_y: Vec4,
    min_z: Vec4,
    max_z: Vec4,
    /// Inner node index, `LEAF | first` or `EMPTY`.
    child: [u32; 4],
    /// Triangle count of leaf children.
    count: [u32; 4],
}

/// The BVH: nodes and triangle data in leaf order.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node4>,
    /// The root: an inner node index or a leaf encoding.
    root: u32,
    root_count: u32,
    /// Vertices of each triangle, in leaf order.
    verts: Vec<[Vec3; 3]>,
    /// Triangle id (in the `TriScene`) of each leaf-order triangle.
    ids: Vec<u32>,
    bounds: Aabb,
    depth: u32,
}

/// Statistics of a built BVH.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Triangles.
    pub triangles: usize,
    /// 4-wide nodes.
    pub nodes: usize,
    /// Leaves.
    pub leaves: usize,
    /// Depth in 4-wide nodes.
    pub depth: u32,
    /// Bytes held (nodes + triangle copies + ids).
    pub bytes: usize,
}

/// A closest hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhHit {
    /// Ray parameter.
    pub t: f32,
    /// Triangle id.
    pub id: u32,
    /// Barycentrics from the watertight test.
    pub b: [f32; 3],
}

/// A primitive reference for the build: its box as two SSE vectors, the
/// reference index kept in the `w` lane of `lo` (32 bytes, moved in place
/// by the partitions, so the build streams through memory).
#[derive(Clone, Copy, Debug)]
struct PrimRef {
    lo: Vec4,
    hi: Vec4,
}

impl PrimRef {
    fn index(&self) -> u32 {
        self.lo.w.to_bits()
    }

    /// Twice the centroid (the factor 2 cancels in the binning).
    fn centroid2(&self) -> Vec4 {
        self.lo + self.hi
    }
}

/// A box as two SSE vectors (w lanes unused).
#[derive(Clone, Copy, Debug)]
struct Box4 {
    lo: Vec4,
    hi: Vec4,
}

impl Box4 {
    const EMPTY: Box4 = Box4 {
        lo: Vec4::splat(f32::INFINITY),
        hi: Vec4::splat(f32::NEG_INFINITY),
    };

    fn grow(&mut self, lo: Vec4, hi: Vec4) {
        self.lo = self.lo.min(lo);
        self.hi = self.hi.max(hi);
    }

    fn half_area(&self) -> f32 {
        let e = (self.hi - self.lo).max(Vec4::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }

    fn aabb(&self) -> Aabb {
        Aabb::from_min_max(self.lo.truncate(), self.hi.truncate())
    }
}

enum BNode {
    Leaf {
        bounds: Aabb,
        start: usize,
        count: usize,
    },
    Inner {
        bounds: Aabb,
        children: Box<[BNode; 2]>,
    },
}

impl BNode {
    fn bounds(&self) -> Aabb {
        match self {
            BNode::Leaf { bounds, .. } | BNode::Inner { bounds, .. } => *bounds,
        }
    }
}

/// Binary depth beyond which splits are object medians, whatever the SAH
/// says: it bounds the tree depth (and the traversal stack) for any input.
const SAH_DEPTH_LIMIT: u32 = 40;

/// The bounds of a set of primitives and of their (doubled) centroids.
fn bounds_of(prims: &[PrimRef]) -> (Box4, Box4) {
    let mut bounds = Box4::EMPTY;
    let mut cbounds = Box4::EMPTY;
    for p in prims {
        bounds.grow(p.lo, p.hi);
        let c = p.centroid2();
        cbounds.grow(c, c);
    }
    (bounds, cbounds)
}

/// Builds the subtree of `prims`, whose bounds and centroid bounds the
/// caller has computed (the partition of the parent produces them).
fn build_binary(
    prims: &mut [PrimRef],
    offset: usize,
    depth: u32,
    (bounds, cbounds): (Box4, Box4),
) -> BNode {
    let n = prims.len();
    let leaf = BNode::Leaf {
        bounds: bounds.aabb(),
        start: offset,
        count: n,
    };
    if n <= 2 {
        return leaf;
    }
    let extent = cbounds.hi - cbounds.lo;
    // Binned SAH over the three axes at once: one pass over the primitives.
    // Small nodes use half the bins (the sweep, not the binning, dominates there).
    let nb = if n > 64 { BINS } else { BINS / 2 };
    #[expect(clippy::cast_precision_loss, reason = "nb ≤ 16")]
    let nbf = nb as f32;
    let scale = Vec4::new(
        if extent.x > 0.0 { nbf / extent.x } else { 0.0 },
        if extent.y > 0.0 { nbf / extent.y } else { 0.0 },
        if extent.z > 0.0 { nbf / extent.z } else { 0.0 },
        0.0,
    );
    let mut bin_bounds = [[Box4::EMPTY; BINS]; 3];
    let mut bin_count = [[0u32; BINS]; 3];
    for p in prims.iter() {
        let b = bins_of(p.centroid2(), cbounds.lo, scale, nb);
        for axis in 0..3 {
            bin_bounds[axis][b[axis]].grow(p.lo, p.hi);
            bin_count[axis][b[axis]] += 1;
        }
    }
    #[expect(
        clippy::cast_precision_loss,
        reason = "counts are far below 2^24 per bin evaluation"
    )]
    let leaf_cost = n as f32;
    let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
    let mut best: Option<(usize, usize, f32)> = None; // axis, split bin, cost
    for axis in 0..3 {
        if extent[axis] <= 0.0 || !extent[axis].is_finite() {
            continue;
        }
        // Sweep from the right, then from the left.
        let mut right_area = [0.0f32; BINS];
        let mut right_count = [0u32; BINS];
        let mut acc = Box4::EMPTY;
        let mut cnt = 0;
        for b in (1..nb).rev() {
            acc.grow(bin_bounds[axis][b].lo, bin_bounds[axis][b].hi);
            cnt += bin_count[axis][b];
            right_area[b] = acc.half_area();
            right_count[b] = cnt;
        }
        let mut acc = Box4::EMPTY;
        let mut cnt = 0;
        for b in 1..nb {
            acc.grow(bin_bounds[axis][b - 1].lo, bin_bounds[axis][b - 1].hi);
            cnt += bin_count[axis][b - 1];
            if cnt == 0 || right_count[b] == 0 {
                continue;
            }
            #[expect(clippy::cast_precision_loss, reason = "counts below 2^24")]
            let cost = TRAVERSAL_COST
                + (acc.half_area() * cnt as f32 + right_area[b] * right_count[b] as f32)
                    / parent_area;
            if best.is_none_or(|(_, _, c)| cost < c) {
                best = Some((axis, b, cost));
            }
        }
    }
    let best = if depth >= SAH_DEPTH_LIMIT && n > MAX_LEAF {
        None
    } else {
        best
    };
    let (mid, lb, rb) = match best {
        Some((axis, split, cost)) if cost < leaf_cost || n > MAX_LEAF => partition(prims, |p| {
            bins_of(p.centroid2(), cbounds.lo, scale, nb)[axis] < split
        }),
        Some(_) => return leaf,
        None if n <= MAX_LEAF => return leaf,
        None => {
            // Every centroid coincides, or the depth limit is reached: split
            // by count along the widest centroid axis to bound the depth.
            let axis = (0..3)
                .max_by(|&a, &b| extent[a].total_cmp(&extent[b]))
                .unwrap_or(0);
            prims.sort_unstable_by(|a, b| a.centroid2()[axis].total_cmp(&b.centroid2()[axis]));
            let (l, r) = prims.split_at(n / 2);
            (n / 2, bounds_of(l), bounds_of(r))
        }
    };
    let (left, right) = prims.split_at_mut(mid);
    let (l, r) = if n > PARALLEL_THRESHOLD {
        rayon::join(
            || build_binary(left, offset, depth + 1, lb),
            || build_binary(right, offset + mid, depth + 1, rb),
        )
    } else {
        (
            build_binary(left, offset, depth + 1, lb),
            build_binary(right, offset + mid, depth + 1, rb),
        )
    };
    BNode::Inner {
        bounds: bounds.aabb(),
        children: Box::new([l, r]),
    }
}

/// The bin of a (doubled) centroid on each axis, below `nb`.
#[inline]
fn bins_of(c2: Vec4, lo: Vec4, scale: Vec4, nb: usize) -> [usize; 3] {
    // Round by the float trick: adding 2^23 to a value in [-0.5, 2^23)
    // leaves the nearest integer in the low mantissa bits (SIMD adds, no
    // saturating float-to-int conversions); subtracting 0.5 first makes it
    // the floor except at exact integers, which is as good a bin boundary.
    #[expect(clippy::cast_precision_loss, reason = "nb ≤ 16")]
    let top = (nb - 1) as f32;
    let b = ((c2 - lo) * scale - Vec4::splat(0.5))
        .min(Vec4::splat(top))
        .max(Vec4::ZERO)
        + Vec4::splat(8_388_608.0);
    let mask = 0x7F_FFFF;
    [
        (b.x.to_bits() & mask) as usize,
        (b.y.to_bits() & mask) as usize,
        (b.z.to_bits() & mask) as usize,
    ]
}

/// In-place partition: the elements for which `pred` holds come first.
/// Returns their count and the bounds (and centroid bounds) of both sides,
/// gathered in the same pass. An empty side (every element on one side,
/// which the SAH sweep never picks) is split by count instead.
fn partition(
    prims: &mut [PrimRef],
    pred: impl Fn(&PrimRef) -> bool,
) -> (usize, (Box4, Box4), (Box4, Box4)) {
    let (mut lb, mut lc, mut rb, mut rc) = (Box4::EMPTY, Box4::EMPTY, Box4::EMPTY, Box4::EMPTY);
    let mut i = 0;
    for j in 0..prims.len() {
        let p = prims[j];
        let c = p.centroid2();
        if pred(&p) {
            lb.grow(p.lo, p.hi);
            lc.grow(c, c);
            prims.swap(i, j);
            i += 1;
        } else {
            rb.grow(p.lo, p.hi);
            rc.grow(c, c);
        }
    }
    if i == 0 || i == prims.len() {
        let mid = prims.len() / 2;
        let (l, r) = prims.split_at(mid);
        return (mid, bounds_of(l), bounds_of(r));
    }
    (i, (lb, lc), (rb, rc))
}

impl Bvh {
    /// Builds a BVH over the triangles `ids` whose vertices `tri(id)` gives.
    /// With `flat = true` the whole set is one leaf (the flat loop that is
    /// faster for tiny scenes).
    #[must_use]
    pub fn build(ids: &[u32], tri: impl Fn(u32) -> [Vec3; 3] + Sync, flat: bool) -> Bvh {
        let mut prims: Vec<PrimRef> = ids
            .iter()
            .enumerate()
            .map(|(k, &id)| {
                let b = Aabb::from_points(tri(id));
                let index = f32::from_bits(u32::try_from(k).unwrap_or(u32::MAX));
                PrimRef {
                    lo: b.min.extend(index),
                    hi: b.max.extend(0.0),
                }
            })
            .collect();
        let mut bvh = Bvh::default();
        if ids.is_empty() {
            bvh.root = EMPTY;
            return bvh;
        }
        let tree = if flat {
            let mut b = Box4::EMPTY;
            for p in &prims {
                b.grow(p.lo, p.hi);
            }
            BNode::Leaf {
                bounds: b.aabb(),
                start: 0,
                count: ids.len(),
            }
        } else {
            let b = bounds_of(&prims);
            build_binary(&mut prims, 0, 0, b)
        };
        bvh.bounds = tree.bounds();
        bvh.ids = prims.iter().map(|p| ids[p.index() as usize]).collect();
        bvh.verts = bvh.ids.iter().map(|&id| tri(id)).collect();
        match &tree {
            BNode::Leaf { start, count, .. } => {
                bvh.root = LEAF | u32::try_from(*start).unwrap_or(0);
                bvh.root_count = u32::try_from(*count).unwrap_or(0);
                bvh.depth = 0;
            }
            BNode::Inner { .. } => {
                bvh.root = 0;
                bvh.nodes.push(empty_node());
                bvh.depth = bvh.collapse(&tree, 0);
            }
        }
        bvh
    }

    /// Fills node `slot` from the binary subtree `node`; returns the depth.
    fn collapse(&mut self, node: &BNode, slot: usize) -> u32 {
        // Gather up to four children by opening the largest inner child.
        let mut kids: [&BNode; 4] = [node; 4];
        let mut len = match node {
            BNode::Inner { children, .. } => {
                kids[0] = &children[0];
                kids[1] = &children[1];
                2
            }
            BNode::Leaf { .. } => 1,
        };
        while len < 4 {
            let mut open = None;
            let mut best_area = f32::NEG_INFINITY;
            for (i, k) in kids[..len].iter().enumerate() {
                if let BNode::Inner { bounds, .. } = k {
                    let a = bounds.half_area();
                    if a > best_area {
                        best_area = a;
                        open = Some(i);
                    }
                }
            }
            let Some(i) = open else { break };
            let BNode::Inner { children, .. } = kids[i] else {
                break;
            };
            kids[i] = &children[0];
            kids[len] = &children[1];
            len += 1;
        }
        let mut n = empty_node();
        let mut depth = 0;
        let mut pending: [(usize, usize); 4] = [(0, 0); 4];
        let mut np = 0;
        for (k, kid) in kids[..len].iter().enumerate() {
            let b = kid.bounds();
            set_lane(&mut n, k, b);
            match kid {
                BNode::Leaf { start, count, .. } => {
                    n.child[k] = LEAF | u32::try_from(*start).unwrap_or(0);
                    n.count[k] = u32::try_from(*count).unwrap_or(0);
                }
                BNode::Inner { .. } => {
                    let idx = self.nodes.len();
                    self.nodes.push(empty_node());
                    n.child[k] = u32::try_from(idx).unwrap_or(EMPTY);
                    pending[np] = (k, idx);
                    np += 1;
                }
            }
        }
        self.nodes[slot] = n;
        for &(k, idx) in &pending[..np] {
            depth = depth.max(self.collapse(kids[k], idx));
        }
        depth + 1
    }

    /// Bounds of all triangles.
    #[must_use]
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Statistics.
    #[must_use]
    pub fn stats(&self) -> BvhStats {
        let leaves = self
            .nodes
            .iter()
            .flat_map(|n| n.child.iter())
            .filter(|&&c| c != EMPTY && c & LEAF != 0)
            .count()
            + usize::from(self.nodes.is_empty() && self.root != EMPTY);
        BvhStats {
            triangles: self.ids.len(),
            nodes: self.nodes.len(),
            leaves,
            depth: self.depth,
            bytes: self.nodes.len() * std::mem::size_of::<Node4>()
                + self.verts.len() * std::mem::size_of::<[Vec3; 3]>()
                + self.ids.len() * 4,
        }
    }

    /// The closest hit with `t` in `[ray.t_min, ray.t_max]`; equal `t`
    /// goes to the lower triangle id.
    #[must_use]
    pub fn intersect(&self, ray: &Ray) -> Option<BvhHit> {
        let pre = RayPrecomp::new(ray);
        let mut best: Option<BvhHit> = None;
        let mut t_best = ray.t_max;
        self.traverse(ray, &mut t_best, true, |first, count, t_best| {
            for i in first..first + count {
                if let Some(TriHit { t, b }) = intersect(&pre, &self.verts[i], ray.t_min, *t_best) {
                    let id = self.ids[i];
                    let better = match best {
                        None => true,
                        Some(h) => t < h.t || (t == h.t && id < h.id),
                    };
                    if better {
                        best = Some(BvhHit { t, id, b });
                        *t_best = t;
                    }
                }
            }
            false
        });
        best
    }

    /// Calls `visit(id, hit)` for every triangle hit with `t` in
    /// `[ray.t_min, ray.t_max]`, in no particular order; stops when `visit`
    /// returns `true`.
    pub fn for_each_hit(&self, ray: &Ray, mut visit: impl FnMut(u32, TriHit) -> bool) {
        let pre = RayPrecomp::new(ray);
        let mut t_max = ray.t_max;
        self.traverse(ray, &mut t_max, false, |first, count, t_max| {
            for i in first..first + count {
                if let Some(h) = intersect(&pre, &self.verts[i], ray.t_min, *t_max)
                    && visit(self.ids[i], h)
                {
                    return true;
                }
            }
            false
        });
    }

    /// Walks the tree; `leaf(first, count, t_max)` tests a leaf and may
    /// shrink `t_max`; returning `true` stops the walk.
    #[inline]
    fn traverse(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        ordered: bool,
        mut leaf: impl FnMut(usize, usize, &mut f32) -> bool,
    ) {
        if self.root == EMPTY {
            return;
        }
        if self.root & LEAF != 0 {
            leaf(
                (self.root & !LEAF) as usize,
                self.root_count as usize,
                t_max,
            );
            return;
        }
        // A zero direction component would give 0·∞ = NaN in the slab test:
        // replace it by a tiny one (the box test stays conservative because
        // t_far is enlarged and the triangle test uses the true direction).
        let safe = |d: f32| {
            if d.abs() < 1e-30 {
                1e-30f32.copysign(d)
            } else {
                d
            }
        };
        let inv = Vec3::new(
            1.0 / safe(ray.dir.x),
            1.0 / safe(ray.dir.y),
            1.0 / safe(ray.dir.z),
        );
        let (ox, oy, oz) = (
            Vec4::splat(ray.origin.x),
            Vec4::splat(ray.origin.y),
            Vec4::splat(ray.origin.z),
        );
        let (ix, iy, iz) = (Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z));
        let grow = 1.0 + 2.0 * gamma(3);
        let t_min4 = Vec4::splat(ray.t_min);
        // Stack of (child encoding, count, t_near). The build bounds the
        // binary depth by SAH_DEPTH_LIMIT + log2(n) ≤ 64 for n < 2^24, and a
        // visit pushes at most 3 more entries than it pops.
        let mut stack: [(u32, u32, f32); 256] = [(0, 0, 0.0); 256];
        let mut sp = 0usize;
        stack[0] = (self.root, 0, ray.t_min);
        sp += 1;
        while sp > 0 {
            sp -= 1;
            let (child, count, t_near) = stack[sp];
            // t_near carries rounding error too: compare it with t_max
            // enlarged like t_far, so a box holding a hit at exactly t_max
            // (a tie, decided by id) is still visited.
            if t_near > *t_max * grow {
                continue;
            }
            if child & LEAF != 0 {
                if leaf((child & !LEAF) as usize, count as usize, t_max) {
                    return;
                }
                continue;
            }
            let n = &self.nodes[child as usize];
            let tx0 = (n.min_x - ox) * ix;
            let tx1 = (n.max_x - ox) * ix;
            let ty0 = (n.min_y - oy) * iy;
            let ty1 = (n.max_y - oy) * iy;
            let tz0 = (n.min_z - oz) * iz;
            let tz1 = (n.max_z - oz) * iz;
            let tn = tx0.min(tx1).max(ty0.min(ty1)).max(tz0.min(tz1)).max(t_min4);
            let tf = tx0.max(tx1).min(ty0.max(ty1)).min(tz0.max(tz1)) * grow;
            let tf = tf.min(Vec4::splat(*t_max * grow));
            let mask = tn.cmple(tf).bitmask();
            if mask == 0 {
                continue;
            }
            let tn = tn.to_array();
            // Push hit children far to near so the nearest is popped first.
            let mut order: [(f32, usize); 4] = [(0.0, 0); 4];
            let mut m = 0;
            for (k, &t) in tn.iter().enumerate() {
                if mask & (1 << k) != 0 {
                    order[m] = (t, k);
                    m += 1;
                }
            }
            if ordered {
                // Insertion sort, descending t_near.
                for a in 1..m {
                    let mut b = a;
                    while b > 0 && order[b - 1].0 < order[b].0 {
                        order.swap(b - 1, b);
                        b -= 1;
                    }
                }
            }
            for &(t, k) in &order[..m] {
                stack[sp] = (n.child[k], n.count[k], t);
                sp += 1;
            }
        }
    }
}

fn empty_node() -> Node4 {
    let inf = Vec4::splat(f32::INFINITY);
    Node4 {
        min_x: inf,
        max_x: inf,
        min_y: inf,
        max_y: inf,
        min_z: inf,
        max_z: inf,
        child: [EMPTY; 4],
        count: [0; 4],
    }
}

fn set_lane(n: &mut Node4, k: usize, b: Aabb) {
    n.min_x[k] = b.min.x;
    n.max_x[k] = b.max.x;
    n.min_y[k] = b.min.y;
    n.max_y[k] = b.max.y;
    n.min_z[k] = b.min.z;
    n.max_z[k] = b.max.z;
}
