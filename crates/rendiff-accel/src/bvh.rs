//! An 8-wide bounding volume hierarchy over triangles.
//!
//! Build: a binary tree by binned SAH (Wald 2007: 16 bins per axis over the
//! centroid bounds, 8 below 65 primitives, a sample of at least 16 384
//! above 32 768; object-median splits where every centroid coincides),
//! split in parallel with `rayon::join` above 4096 primitives, then
//! collapsed into 8-wide nodes (each node adopts the grandchildren of its
//! largest inner children) with their child boxes stored as structure of
//! arrays, so one node visit tests eight boxes in one 256-bit step per
//! operation on x86-64-v3 (two SSE steps on the baseline).
//!
//! The queries are compiled twice through `pulp` (the walk and the triangle
//! tests inlined into each copy): for the target's baseline (SSE2) and for
//! x86-64-v3 (AVX2), chosen at run time; both give the same hits bit for bit.
//!
//! Packets ([`Bvh::intersect_packet`]) walk up to eight rays together and
//! give each exactly its single-ray hit.
//!
//! Traversal: ordered (nearest child first) with a precomputed inverse
//! direction; `t_far` of every box is enlarged by `1 + 2γ(3)` (Ize 2013,
//! pbrt-v4), so rounding never culls a box the ray really enters: the BVH
//! finds exactly the hits a linear scan finds.

use glam::Vec4;
use pulp::WithSimd;
use rayon::prelude::*;

use super::SimdPath;
#[cfg(test)]
use super::triangle::intersect;
use super::triangle::slab_dir;
use super::triangle::{
    RayPrecomp, TriHit, TriPack, WalkRay, candidates, candidates2, intersect_lane,
};
use rendiff_core::huge::Big;
use rendiff_core::math::{Aabb, DVec3, Ray64, Vec3, f32_at_least, gamma, to_f64};

/// Child slot encoding: the high bit marks a leaf.
const LEAF: u32 = 1 << 31;
/// An empty child slot.
const EMPTY: u32 = u32::MAX;

/// Largest number of triangles in a leaf.
pub(crate) const MAX_LEAF: usize = 8;
/// Bins per axis of the SAH build.
const BINS: usize = 16;
/// Relative cost of a node visit against a triangle test.
const TRAVERSAL_COST: f32 = 1.0;
/// The least sample a large node's SAH binning takes (see [`best_split`]).
const SAMPLED: usize = 16_384;
/// The sparsest sample: every 8th primitive (one 64-byte line in four).
const MAX_STRIDE: usize = 8;
/// Subtrees larger than this are built in parallel.
const PARALLEL_THRESHOLD: usize = 4096;

/// Children of a node.
const WIDTH: usize = 8;
/// Rays in a packet ([`Bvh::intersect_packet`]): one bit each in a `u32` mask.
pub(crate) const PACKET: usize = 8;
/// The `skip` of a walk that tests every triangle (no triangle has this id).
pub(crate) const NO_SKIP: u32 = u32::MAX;
/// A packet's rays that enter an inner node finish its subtree one by one
/// when they are this many or fewer. Measured: 3 ahead of 1 and of 5 while
/// a packet tested a node ray by ray; 1 ahead of 2 and 3 since it tests
/// the node against the packet first ([`PacketSlab`]).
const SOLO: u32 = 1;
/// The packet walks test a node against the whole packet first
/// ([`PacketSlab`]) in trees at least this deep. In a tree of one or two
/// levels of nodes (a scene of a few dozen triangles) the packet's bounds
/// keep nearly every child and their setup per packet is the only cost:
/// callgrind, one render with the rasterizer, `painter_floor` (depth 2)
/// 95.1 M instructions with ray-by-ray node tests, 96.2 M with the
/// packet's; `big_tiny` at 480×270 (depth 1) 401.1 against 406.7 M.
const PACKET_TEST_DEPTH: u32 = 3;

/// A node of `WIDTH` children, their boxes as structure of arrays (one
/// 256-bit vector per plane coordinate on x86-64-v3, two SSE vectors on
/// the baseline).
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
pub(crate) struct Node {
    min_x: [f32; WIDTH],
    max_x: [f32; WIDTH],
    min_y: [f32; WIDTH],
    max_y: [f32; WIDTH],
    min_z: [f32; WIDTH],
    max_z: [f32; WIDTH],
    /// Inner node index, `LEAF | first pack` or `EMPTY`.
    child: [u32; WIDTH],
    /// Bit k set when child k exists: an empty slot's box (all +∞) would
    /// pass the slab test for a ray with positive direction components
    /// and no far bound.
    used: u32,
    /// (Plain old data for `huge::Big`: the node's 256 bytes without
    /// implicit padding.)
    pad: [u32; 7],
}

#[cfg_attr(
    not(target_arch = "x86_64"),
    allow(dead_code, reason = "read by `Slab::test_v3`")
)]
impl Node {
    /// The six plane arrays in their order (`min_x`, `max_x`, `min_y`,
    /// `max_y`, `min_z`, `max_z`), then `child` and `used` with `pad`, as
    /// bits.
    #[inline(always)]
    fn planes(&self) -> &[[f32; WIDTH]; 8] {
        bytemuck::cast_ref(self)
    }
}

/// The BVH: nodes and triangle data in leaf order.
#[derive(Clone, Debug, Default)]
pub(crate) struct Bvh {
    nodes: Big<Node>,
    /// The root: an inner node index or a leaf encoding.
    root: u32,
    root_count: u32,
    /// The triangles in leaf order, four to a pack; a leaf is a run of
    /// packs.
    packs: Big<TriPack>,
    /// Triangle id (in the `TriScene`) of each lane: `ids[4·pack + lane]`.
    ids: Big<u32>,
    /// Triangles.
    triangles: usize,
    bounds: Aabb,
    /// The bounds' bounding sphere (centre in `f64`, radius with the
    /// margin of [`Bvh::reach`]), computed once.
    sphere: (DVec3, f64),
    depth: u32,
    /// The instruction set the queries run with (see [`SimdPath`]).
    arch: pulp::Arch,
}

/// Statistics of a built BVH.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhStats {
    /// Triangles.
    pub triangles: usize,
    /// 8-wide nodes.
    pub nodes: usize,
    /// Leaves.
    pub leaves: usize,
    /// Depth in 8-wide nodes.
    pub depth: u32,
    /// Bytes held (nodes + triangle copies + ids).
    pub bytes: usize,
}

/// A closest hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhHit {
    /// Ray parameter (rounded from `t64`).
    pub t: f32,
    /// Ray parameter in `f64`.
    pub t64: f64,
    /// Triangle id.
    pub id: u32,
    /// Barycentrics from the watertight test.
    pub b: [f32; 3],
}

/// A primitive reference for the build: its box as two SSE vectors, the
/// reference index kept in the `w` lane of `lo` (32 bytes, moved in place
/// by the partitions, so the build streams through memory), as the bits
/// of a normal float (see [`INDEX_BIAS`]).
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
struct PrimRef {
    lo: Vec4,
    hi: Vec4,
}

/// Added to a primitive's index to form the bits of its `w` lane: the
/// bits of 1.0, so that every index below 2³⁰ is a normal float in
/// [1, 2¹²⁸) and never a subnormal one. The lane rides along in every
/// vector operation on the box (the centroid `lo + hi`, the bins'
/// arithmetic, the bounds' differences), and with the index's own bits
/// (a subnormal float below 2²³) those operations took the processor's
/// slow path for subnormal operands and results on every primitive of
/// every level: the 940 k bunny's SAH build took 490 ms against 325 ms
/// (ARCHITECTURE.md, "Subnormal lanes"), while callgrind, which counts
/// instructions and not their cycles, saw no difference. The tree is the
/// same bit for bit: no result reads the `w` lane but [`PrimRef::index`].
const INDEX_BIAS: u32 = 0x3F80_0000;

impl PrimRef {
    fn index(&self) -> u32 {
        self.lo.w.to_bits().wrapping_sub(INDEX_BIAS)
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
        /// `bounds.half_area()`, which [`gather`] compares: formed once.
        area: f32,
        children: Box<[BNode; 2]>,
        /// What the subtree becomes as the root of an 8-wide node: see
        /// [`Tally`]; its nodes and packs as `u32` (each below the
        /// triangles' count, whose ids are `u32`), so that a `BNode`, area
        /// and all, stays 48 bytes.
        tally: [u32; 2],
    },
}

/// The 8-wide nodes and the packs a binary subtree becomes when it is
/// the root of an 8-wide node: a node of its own and, for each child that
/// [`gather`] gives it, that child's (a leaf child: its packs). Counted as
/// the binary tree is built (each inner node from the counts its
/// gathered descendants already hold), so that [`collapse`] knows
/// where every subtree's nodes and packs go before it writes them, and
/// writes them in parallel.
#[derive(Clone, Copy, Debug, Default)]
struct Tally {
    nodes: usize,
    packs: usize,
}

impl BNode {
    fn bounds(&self) -> Aabb {
        match self {
            BNode::Leaf { bounds, .. } | BNode::Inner { bounds, .. } => *bounds,
        }
    }

    /// An inner node over two subtrees, with its [`Tally`].
    fn inner(bounds: Aabb, children: [BNode; 2]) -> BNode {
        let mut node = BNode::Inner {
            bounds,
            area: bounds.half_area(),
            children: Box::new(children),
            tally: [0; 2],
        };
        let (kids, len) = gather(&node);
        let t = kids[..len]
            .iter()
            .fold(Tally { nodes: 1, packs: 0 }, |t, k| {
                let k = k.tally();
                Tally {
                    nodes: t.nodes + k.nodes,
                    packs: t.packs + k.packs,
                }
            });
        if let BNode::Inner { tally, .. } = &mut node {
            let to_u32 = |k: usize| u32::try_from(k).unwrap_or(u32::MAX);
            *tally = [to_u32(t.nodes), to_u32(t.packs)];
        }
        node
    }

    /// The subtree's [`Tally`] (a leaf: its packs and no node).
    fn tally(&self) -> Tally {
        match self {
            BNode::Leaf { count, .. } => Tally {
                nodes: 0,
                packs: count.div_ceil(4),
            },
            BNode::Inner {
                tally: [nodes, packs],
                ..
            } => Tally {
                nodes: *nodes as usize,
                packs: *packs as usize,
            },
        }
    }
}

/// Drops a binary tree, its large subtrees in parallel (freeing a
/// million boxes one by one was a serial tail of the build).
fn drop_tree(node: BNode) {
    let packs = node.tally().packs;
    if let BNode::Inner { children, .. } = node {
        let [l, r] = *children;
        if packs > PARALLEL_THRESHOLD / 4 {
            rayon::join(|| drop_tree(l), || drop_tree(r));
        } else {
            drop(l);
            drop(r);
        }
    }
}

/// What leaf emission needs: the ids in leaf order and the vertices.
struct Leaves<'a, F> {
    order: &'a [u32],
    tri: &'a F,
}

/// Binary depth beyond which splits are object medians, whatever the SAH
/// says: it bounds the tree depth (and the traversal stack) for any input.
const SAH_DEPTH_LIMIT: u32 = 40;

/// The bounds of a set of primitives and of their (doubled) centroids.
fn bounds_of(prims: &[PrimRef]) -> (Box4, Box4) {
    if prims.len() > PARALLEL_THRESHOLD {
        return par_bounds(prims.len(), |k| prims[k]);
    }
    let mut bounds = Box4::EMPTY;
    let mut cbounds = Box4::EMPTY;
    for p in prims {
        bounds.grow(p.lo, p.hi);
        let c = p.centroid2();
        cbounds.grow(c, c);
    }
    (bounds, cbounds)
}

/// The bounds of `n` primitives `get(k)` and of their (doubled)
/// centroids, in parallel: fixed runs of [`PARALLEL_THRESHOLD`] each
/// bounded in turn, the runs' bounds joined in order, so the result is
/// the same at any thread count.
fn par_bounds(n: usize, get: impl Fn(usize) -> PrimRef + Sync) -> (Box4, Box4) {
    let runs: Vec<(Box4, Box4)> = (0..n.div_ceil(PARALLEL_THRESHOLD))
        .into_par_iter()
        .map(|r| {
            let mut b = (Box4::EMPTY, Box4::EMPTY);
            for k in r * PARALLEL_THRESHOLD..((r + 1) * PARALLEL_THRESHOLD).min(n) {
                let p = get(k);
                b.0.grow(p.lo, p.hi);
                let c = p.centroid2();
                b.1.grow(c, c);
            }
            b
        })
        .collect();
    runs.iter()
        .fold((Box4::EMPTY, Box4::EMPTY), |(mut b, mut c), (rb, rc)| {
            b.grow(rb.lo, rb.hi);
            c.grow(rc.lo, rc.hi);
            (b, c)
        })
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
    // At most one pack: a split (one more node visit, and at least one
    // pack on each side) never costs less, so the SAH would make a leaf.
    if n <= 4 {
        return leaf;
    }
    let extent = cbounds.hi - cbounds.lo;
    // Small nodes use half the bins (the sweep, not the binning, dominates
    // there), in arrays of that size: setting up the bins of a node is a
    // fixed cost, and most nodes are small.
    let (nb, scale, best) = if n > 64 {
        best_split::<BINS, 2>(prims, (bounds, cbounds), extent)
    } else {
        best_split::<{ BINS / 2 }, 1>(prims, (bounds, cbounds), extent)
    };
    let leaf_cost = pack_cost(u32::try_from(n).unwrap_or(u32::MAX));
    let best = if depth >= SAH_DEPTH_LIMIT && n > MAX_LEAF {
        None
    } else {
        best
    };
    let (mid, lb, rb) = match best {
        Some((axis, split, cost)) if cost < leaf_cost || n > MAX_LEAF => {
            let left = |p: &PrimRef| bins_of(p.centroid2(), cbounds.lo, scale, nb)[axis] < split;
            // Both leave the same order; one thread takes the one pass.
            // (Their bounds can differ only in the sign of a zero, which
            // `unsigned_zeros` removes: the same tree at any thread count.)
            let (mid, l, r) = if n > 4 * PARTITION_BLOCK && rayon::current_num_threads() > 1 {
                par_partition(prims, left)
            } else {
                partition(prims, left)
            };
            (mid, unsigned_zeros(l), unsigned_zeros(r))
        }
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
    BNode::inner(bounds.aabb(), [l, r])
}

/// The SAH cost of `k` triangles in a leaf: they are tested four at a
/// time, so a leaf costs its packs.
fn pack_cost(k: u32) -> f32 {
    #[expect(clippy::cast_precision_loss, reason = "pack counts below 2^24")]
    let packs = k.div_ceil(4) as f32;
    packs
}

/// The binned SAH split of a node: `NB` bins per axis over the centroid
/// bounds, all three axes in one pass over the primitives. Returns `NB`,
/// the bins' scale per axis and the best (axis, split bin, cost), `None`
/// when no axis has two non-empty sides.
fn best_split<const NB: usize, const SETS: usize>(
    prims: &[PrimRef],
    (bounds, cbounds): (Box4, Box4),
    extent: Vec4,
) -> (usize, Vec4, Option<(usize, usize, f32)>) {
    #[expect(clippy::cast_precision_loss, reason = "NB ≤ 16")]
    let nbf = NB as f32;
    let scale = Vec4::new(
        if extent.x > 0.0 { nbf / extent.x } else { 0.0 },
        if extent.y > 0.0 { nbf / extent.y } else { 0.0 },
        if extent.z > 0.0 { nbf / extent.z } else { 0.0 },
        0.0,
    );
    // `SETS` sets of bins, primitive k in set k mod SETS, merged
    // afterwards: neighbours often fall in the same bin, and one set
    // chains every update to the previous one through memory. Small nodes
    // take one set: their setting up and merging cost more than the chain.
    let mut bin_bounds = [[[Box4::EMPTY; NB]; 3]; SETS];
    let mut bin_count = [[[0u32; NB]; 3]; SETS];
    // Large nodes are binned from every `stride`-th primitive (at least
    // SAMPLED of them): a sample this large places the split as well, and
    // the partition that follows is over all of them.
    let stride = (prims.len() / SAMPLED).clamp(1, MAX_STRIDE);
    for (k, p) in prims.iter().step_by(stride).enumerate() {
        let set = k % SETS;
        let bp = bins_of(p.centroid2(), cbounds.lo, scale, NB);
        for axis in 0..3 {
            bin_bounds[set][axis][bp[axis]].grow(p.lo, p.hi);
            bin_count[set][axis][bp[axis]] += 1;
        }
    }
    let stride = u32::try_from(stride).unwrap_or(1);
    let (first, others) = bin_bounds.split_at_mut(1);
    let (first_count, other_counts) = bin_count.split_at_mut(1);
    let (bin_bounds, bin_count) = (&mut first[0], &mut first_count[0]);
    for (set, counts) in others.iter().zip(other_counts.iter()) {
        for axis in 0..3 {
            for b in 0..NB {
                let o = set[axis][b];
                bin_bounds[axis][b].grow(o.lo, o.hi);
                bin_count[axis][b] += counts[axis][b];
            }
        }
    }
    let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
    let mut best: Option<(usize, usize, f32)> = None; // axis, split bin, cost
    for axis in 0..3 {
        if extent[axis] <= 0.0 || !extent[axis].is_finite() {
            continue;
        }
        // Sweep from the right, then from the left.
        let mut right_area = [0.0f32; NB];
        let mut right_count = [0u32; NB];
        let mut acc = Box4::EMPTY;
        let mut cnt = 0;
        for b in (1..NB).rev() {
            acc.grow(bin_bounds[axis][b].lo, bin_bounds[axis][b].hi);
            cnt += bin_count[axis][b];
            right_area[b] = acc.half_area();
            right_count[b] = cnt;
        }
        let mut acc = Box4::EMPTY;
        let mut cnt = 0;
        for b in 1..NB {
            acc.grow(bin_bounds[axis][b - 1].lo, bin_bounds[axis][b - 1].hi);
            cnt += bin_count[axis][b - 1];
            if cnt == 0 || right_count[b] == 0 {
                continue;
            }
            let cost = TRAVERSAL_COST
                + (acc.half_area() * pack_cost(cnt.saturating_mul(stride))
                    + right_area[b] * pack_cost(right_count[b].saturating_mul(stride)))
                    / parent_area;
            if best.is_none_or(|(_, _, c)| cost < c) {
                best = Some((axis, b, cost));
            }
        }
    }
    (NB, scale, best)
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
///
/// Two cursors from the ends (Hoare): only the misplaced pairs are
/// swapped, so after the splits above (which leave a node's primitives
/// roughly in space order) most elements are read once and never written;
/// the one-cursor form wrote every element of the left side.
fn partition(
    prims: &mut [PrimRef],
    pred: impl Fn(&PrimRef) -> bool,
) -> (usize, (Box4, Box4), (Box4, Box4)) {
    let mut left = (Box4::EMPTY, Box4::EMPTY);
    let mut right = (Box4::EMPTY, Box4::EMPTY);
    let add = |side: &mut (Box4, Box4), p: &PrimRef| {
        side.0.grow(p.lo, p.hi);
        let c = p.centroid2();
        side.1.grow(c, c);
    };
    let (mut i, mut j) = (0, prims.len());
    loop {
        while i < j && pred(&prims[i]) {
            add(&mut left, &prims[i]);
            i += 1;
        }
        while i < j && !pred(&prims[j - 1]) {
            add(&mut right, &prims[j - 1]);
            j -= 1;
        }
        if i >= j {
            break;
        }
        // prims[i] belongs right and prims[j − 1] left.
        prims.swap(i, j - 1);
        add(&mut left, &prims[i]);
        add(&mut right, &prims[j - 1]);
        i += 1;
        j -= 1;
    }
    if i == 0 || i == prims.len() {
        let mid = prims.len() / 2;
        let (l, r) = prims.split_at(mid);
        return (mid, bounds_of(l), bounds_of(r));
    }
    (i, left, right)
}

/// Bounds with every −0 made +0: the minima and maxima of a set of
/// numbers are the same in any order but for the sign of a zero (the
/// minimum of −0 and +0 is whichever came second), so bounds taken in
/// different orders agree bit for bit once zeros are unsigned.
fn unsigned_zeros((b, c): (Box4, Box4)) -> (Box4, Box4) {
    let fix = |v: Vec4| v + Vec4::ZERO;
    (
        Box4 {
            lo: fix(b.lo),
            hi: fix(b.hi),
        },
        Box4 {
            lo: fix(c.lo),
            hi: fix(c.hi),
        },
    )
}

/// Primitives per block of [`par_partition`], and the least node it
/// partitions (below, [`partition`]'s one pass is the cheaper).
const PARTITION_BLOCK: usize = 1 << 14;

/// [`partition`] of a large node in parallel, with the same result: the
/// two-cursor pass swaps the k-th element from the left that belongs
/// right (among the first `mid`, `mid` the count that belong left) with
/// the k-th element from the right that belongs left (among the rest),
/// for every k, and touches nothing else. Here the first `mid` are cut
/// into fixed blocks; each block's misplaced elements are a run of k, so
/// their partners lie in a run of the right side that no other block's
/// do, and the blocks swap with their runs in parallel. The bounds of
/// each side are those of the elements that belong to it, taken in the
/// counting pass.
fn par_partition(
    prims: &mut [PrimRef],
    pred: impl Fn(&PrimRef) -> bool + Sync,
) -> (usize, (Box4, Box4), (Box4, Box4)) {
    let n = prims.len();
    // The two sides are the elements that belong to each, wherever they
    // lie: their counts and bounds in one pass, block by block, the
    // blocks joined in order.
    let sides: Vec<(usize, [(Box4, Box4); 2])> = prims
        .par_chunks(PARTITION_BLOCK)
        .map(|b| {
            let mut count = 0;
            let (mut l, mut lc, mut r, mut rc) =
                (Box4::EMPTY, Box4::EMPTY, Box4::EMPTY, Box4::EMPTY);
            for p in b {
                let c = p.centroid2();
                if pred(p) {
                    count += 1;
                    l.grow(p.lo, p.hi);
                    lc.grow(c, c);
                } else {
                    r.grow(p.lo, p.hi);
                    rc.grow(c, c);
                }
            }
            (count, [(l, lc), (r, rc)])
        })
        .collect();
    let mut mid = 0;
    let mut bounds = [(Box4::EMPTY, Box4::EMPTY); 2];
    for (count, side) in &sides {
        mid += count;
        for (b, s) in bounds.iter_mut().zip(side) {
            b.0.grow(s.0.lo, s.0.hi);
            b.1.grow(s.1.lo, s.1.hi);
        }
    }
    if mid == 0 || mid == n {
        let mid = n / 2;
        let (l, r) = prims.split_at(mid);
        return (mid, bounds_of(l), bounds_of(r));
    }
    let (left, right) = prims.split_at_mut(mid);
    // Per block of the left side, its misplaced elements; their runs of k.
    let wrong: Vec<usize> = left
        .par_chunks(PARTITION_BLOCK)
        .map(|b| b.iter().filter(|p| !pred(p)).count())
        .collect();
    let mut first_k = Vec::with_capacity(wrong.len() + 1);
    let mut k = 0;
    for w in &wrong {
        first_k.push(k);
        k += w;
    }
    let misplaced = k;
    // The right side's misplaced elements counted per block from its end.
    let right_len = right.len();
    let from_end: Vec<usize> = right
        .par_rchunks(PARTITION_BLOCK)
        .map(|b| b.iter().filter(|p| pred(p)).count())
        .collect();
    let mut before = Vec::with_capacity(from_end.len());
    let mut k = 0;
    for c in &from_end {
        before.push(k);
        k += c;
    }
    // Where the right side's run of block i ends: just after its k-th
    // misplaced element from the end (k = the block's first), the end
    // itself for k = 0; the last run reaches the start.
    let right_ref: &[PrimRef] = right;
    let cut = |k: usize| -> usize {
        if k == 0 {
            return right_len;
        }
        if k >= misplaced {
            return 0;
        }
        // The block (from the end) holding it, then its place there.
        let q = before.partition_point(|&b| b <= k) - 1;
        let hi = right_len - q * PARTITION_BLOCK;
        let lo = hi.saturating_sub(PARTITION_BLOCK);
        let mut seen = before[q];
        for at in (lo..hi).rev() {
            if pred(&right_ref[at]) {
                if seen == k {
                    return at + 1;
                }
                seen += 1;
            }
        }
        lo
    };
    let ends: Vec<usize> = first_k.par_iter().map(|&k| cut(k)).collect();
    // The runs, block 0's at the right end, each the next to the left.
    let mut runs: Vec<&mut [PrimRef]> = Vec::with_capacity(ends.len());
    let mut rest: &mut [PrimRef] = right;
    for (i, &end) in ends.iter().enumerate() {
        let start = ends.get(i + 1).copied().unwrap_or(0);
        let whole = std::mem::take(&mut rest);
        let (keep, run) = whole[..end].split_at_mut(start);
        runs.push(run);
        rest = keep;
    }
    left.par_chunks_mut(PARTITION_BLOCK)
        .zip(runs)
        .for_each(|(block, run)| {
            let mut r = run.len();
            for x in block.iter_mut() {
                if !pred(x) {
                    // (The run holds exactly as many that belong left.)
                    while r > 0 {
                        r -= 1;
                        if pred(&run[r]) {
                            std::mem::swap(x, &mut run[r]);
                            break;
                        }
                    }
                }
            }
        });
    (mid, bounds[0], bounds[1])
}

/// How the binary tree under the 8-wide nodes is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tree {
    /// One leaf of every triangle (the flat loop that is faster for tiny
    /// scenes).
    Flat,
    /// Binned SAH ([`build_binary`]): the tree that traces fastest.
    Sah,
    /// Morton order ([`build_morton`]): built an order of magnitude
    /// faster, traced somewhat slower; for frames that cast fewer rays than
    /// the scene has triangles.
    Morton,
}

/// Bits of a Morton code per axis.
const MORTON_BITS: u32 = 10;

/// `x`'s low 10 bits spread to every third bit.
fn spread3(x: u32) -> u32 {
    let x = (x | (x << 16)) & 0x0300_00FF;
    let x = (x | (x << 8)) & 0x0300_F00F;
    let x = (x | (x << 4)) & 0x030C_30C3;
    (x | (x << 2)) & 0x0924_9249
}

/// Sorts `keys` by their upper 32 bits (a 30-bit Morton code; the lower
/// half is the primitive's index, so equal codes keep index order and the
/// order is the same on every run): three passes of a least significant
/// digit radix sort, ten bits each.
fn radix_sort_codes(keys: &mut Big<u64>) {
    if keys.len() > SORT_RUN && rayon::current_num_threads() >= 4 {
        par_sort_codes(keys);
        return;
    }
    let mut tmp = Big::zeroed(keys.len());
    for pass in 0..3 {
        let shift = 32 + 10 * pass;
        // The slices taken once: each index through a `Big` checks its
        // form and casts the map's bytes (4 % of a Morton build's
        // instructions when the scatter below wrote through `tmp`).
        let (from, to): (&[u64], &mut [u64]) = (keys, &mut tmp);
        let mut count = [0usize; 1025];
        for &k in from {
            count[((k >> shift) & 1023) as usize + 1] += 1;
        }
        for d in 0..1024 {
            count[d + 1] += count[d];
        }
        for &k in from {
            let d = ((k >> shift) & 1023) as usize;
            to[count[d]] = k;
            count[d] += 1;
        }
        std::mem::swap(keys, &mut tmp);
    }
}

/// Keys per run of [`par_sort_codes`].
const SORT_RUN: usize = 1 << 16;

/// [`radix_sort_codes`] on many threads: the keys are unique (each holds
/// its primitive's index), so any sort orders them alike, and this one
/// runs in parallel. Each run of [`SORT_RUN`] keys is sorted by its top
/// ten code bits (a counting sort); each of the 1 024 digits then gathers
/// its keys from run after run into its own part of the output and sorts
/// them there.
fn par_sort_codes(keys: &mut [u64]) {
    const DIGITS: usize = 1024;
    let digit = |k: u64| ((k >> 52) & 1023) as usize;
    let runs: Vec<(Vec<u64>, Vec<usize>)> = keys
        .par_chunks(SORT_RUN)
        .map(|run| {
            let mut start = vec![0usize; DIGITS + 1];
            for &k in run {
                start[digit(k) + 1] += 1;
            }
            for d in 0..DIGITS {
                start[d + 1] += start[d];
            }
            let mut fill = start.clone();
            let mut sorted = vec![0u64; run.len()];
            for &k in run {
                let d = digit(k);
                sorted[fill[d]] = k;
                fill[d] += 1;
            }
            (sorted, start)
        })
        .collect();
    let mut parts: Vec<&mut [u64]> = Vec::with_capacity(DIGITS);
    let mut rest = keys;
    for d in 0..DIGITS {
        let n: usize = runs.iter().map(|(_, s)| s[d + 1] - s[d]).sum();
        parts.push(take_front(&mut rest, n));
    }
    parts.into_par_iter().enumerate().for_each(|(d, part)| {
        let mut at = 0;
        for (sorted, start) in &runs {
            let from = &sorted[start[d]..start[d + 1]];
            part[at..at + from.len()].copy_from_slice(from);
            at += from.len();
        }
        part.sort_unstable();
    });
}

/// The children of an 8-wide node over the binary `node`: up to [`WIDTH`]
/// of them, found by opening the inner child of largest surface area
/// until there are `WIDTH` or none is inner; and how many.
fn gather(node: &BNode) -> ([&BNode; WIDTH], usize) {
    // Each child's surface area, read once when it joins (a leaf's is
    // −∞: never opened): the scan for the largest had formed every inner
    // child's area again at each opening, some 27 areas a node, and each
    // node's area again in the gather of every ancestor that reaches it.
    let area = |k: &BNode| match k {
        BNode::Inner { area, .. } => *area,
        BNode::Leaf { .. } => f32::NEG_INFINITY,
    };
    let mut kids: [&BNode; WIDTH] = [node; WIDTH];
    let mut areas = [f32::NEG_INFINITY; WIDTH];
    let mut len = match node {
        BNode::Inner { children, .. } => {
            kids[0] = &children[0];
            kids[1] = &children[1];
            areas[0] = area(kids[0]);
            areas[1] = area(kids[1]);
            2
        }
        BNode::Leaf { .. } => 1,
    };
    while len < WIDTH {
        // The first inner child of the largest area (a leaf's −∞ is never
        // above the best, so a leaf is never opened).
        let mut open = None;
        let mut best_area = f32::NEG_INFINITY;
        for (i, &a) in areas[..len].iter().enumerate() {
            if a > best_area {
                best_area = a;
                open = Some(i);
            }
        }
        let Some(i) = open else { break };
        let BNode::Inner { children, .. } = kids[i] else {
            break;
        };
        kids[i] = &children[0];
        kids[len] = &children[1];
        areas[i] = area(kids[i]);
        areas[len] = area(kids[len]);
        len += 1;
    }
    (kids, len)
}

/// The binary tree of `prims` in Morton order (a linear BVH, Lauterbach et
/// al. 2009): each primitive's centroid quantised to a 1024³ grid over the
/// centroid bounds, its three coordinates' bits interleaved, the
/// primitives sorted by that code (radix), and each range split where
/// the highest bit in which its first and last codes differ changes (a
/// binary search: the range is sorted and shares every higher bit), at
/// the middle where they are equal; ranges of four or fewer are leaves.
/// The boxes are the union of what they hold, so the tree is as exact as
/// the SAH's: only the grouping, and so the speed of a walk, differ.
///
/// It holds no array of boxes: a triangle's box is formed from its
/// vertices where needed (its centroid for its code, then the leaves'
/// bounds), which at ten million triangles spares 327 MB of memory that
/// this machine's page faults made the slowest part of the build.
fn build_morton<F: Fn(u32) -> [Vec3; 3] + Sync>(ids: &[u32], tri: &F) -> (BNode, Big<u64>) {
    let boxes = TriBoxes { ids, tri };
    let (_, cbounds) = par_bounds(ids.len(), |k| boxes.get(k));
    let extent = cbounds.hi - cbounds.lo;
    #[expect(clippy::cast_precision_loss, reason = "1024 is exact")]
    let cells = (1u32 << MORTON_BITS) as f32;
    let scale = Vec4::new(
        if extent.x > 0.0 {
            cells / extent.x
        } else {
            0.0
        },
        if extent.y > 0.0 {
            cells / extent.y
        } else {
            0.0
        },
        if extent.z > 0.0 {
            cells / extent.z
        } else {
            0.0
        },
        0.0,
    );
    let n_cells = 1usize << MORTON_BITS;
    let mut keys = Big::from_fn(ids.len(), |k| {
        let p = boxes.get(k);
        // (Clamped again: a centroid whose doubled sum overflowed is a
        // NaN or an infinity here, and any cell is as right for it,
        // since the boxes, not the codes, bound the tree.)
        let cell = |b: usize| u32::try_from(b.min(n_cells - 1)).unwrap_or(0);
        let [x, y, z] = bins_of(p.centroid2(), cbounds.lo, scale, n_cells).map(cell);
        let code = (spread3(x) << 2) | (spread3(y) << 1) | spread3(z);
        (u64::from(code) << 32) | k as u64
    });
    radix_sort_codes(&mut keys);
    // The sorted keys carry the triangles' indices; only the leaves read
    // their boxes.
    let tree = morton_range(&boxes, &keys, 0, None);
    (tree, keys)
}

/// The boxes of a build's triangles, formed from their vertices on
/// demand (as `PrimRef`s: the same box, with `w` zero in both corners:
/// no pass of the Morton build reads a primitive's index from its box,
/// which the keys carry, and forming it cost 2 % of the build).
struct TriBoxes<'a, F> {
    ids: &'a [u32],
    tri: &'a F,
}

impl<F: Fn(u32) -> [Vec3; 3]> TriBoxes<'_, F> {
    #[inline]
    fn get(&self, k: usize) -> PrimRef {
        let b = Aabb::from_points((self.tri)(self.ids[k]));
        PrimRef {
            lo: b.min.extend(0.0),
            hi: b.max.extend(0.0),
        }
    }
}

/// The reference of triangle `tri`, the `k`-th of a build: its box, and
/// `k` in the `w` lane (biased by [`INDEX_BIAS`]).
#[inline]
fn prim_ref(k: usize, tri: [Vec3; 3]) -> PrimRef {
    let b = Aabb::from_points(tri);
    let index = f32::from_bits(
        u32::try_from(k)
            .unwrap_or(u32::MAX)
            .wrapping_add(INDEX_BIAS),
    );
    PrimRef {
        lo: b.min.extend(index),
        hi: b.max.extend(0.0),
    }
}

/// The primitive index of a Morton key (its lower half).
#[inline]
fn key_index(k: u64) -> usize {
    (k & 0xFFFF_FFFF) as usize
}

/// The bounds of the triangles of a run of Morton keys.
fn keys_bounds<F: Fn(u32) -> [Vec3; 3]>(boxes: &TriBoxes<'_, F>, keys: &[u64]) -> Box4 {
    let mut b = Box4::EMPTY;
    for &k in keys {
        let p = boxes.get(key_index(k));
        b.grow(p.lo, p.hi);
    }
    b
}

/// The subtree of a Morton-sorted range (see [`build_morton`]). A range
/// of up to [`MAX_LEAF`] is a leaf where the SAH says so: its packs cost
/// no more than a node visit plus its two halves' packs weighted by
/// their areas. `known` is the range's bounds where the caller formed
/// them (a half of such a range): a triangle's box is then formed once
/// below `MAX_LEAF`, not again for its leaf. (The union of the halves'
/// bounds is the bounds of the whole bit for bit: `min` and `max` keep
/// the later of two equal values, so a fold over the whole and the
/// union of the folds over its halves both keep the last triangle's
/// value among those equal to the extreme.)
fn morton_range<F: Fn(u32) -> [Vec3; 3] + Sync>(
    boxes: &TriBoxes<'_, F>,
    keys: &[u64],
    offset: usize,
    known: Option<Box4>,
) -> BNode {
    let n = keys.len();
    let leaf = |bounds: Option<Box4>| {
        let own = || keys_bounds(boxes, keys).aabb();
        debug_assert!(
            bounds.is_none_or(|b| {
                let (a, o) = (b.aabb(), own());
                a.min.to_array().map(f32::to_bits) == o.min.to_array().map(f32::to_bits)
                    && a.max.to_array().map(f32::to_bits) == o.max.to_array().map(f32::to_bits)
            }),
            "the halves' bounds are the range's, bit for bit"
        );
        BNode::Leaf {
            bounds: bounds.map_or_else(own, |b| b.aabb()),
            start: offset,
            count: n,
        }
    };
    if n <= 4 {
        return leaf(known);
    }
    // The codes are the keys' upper halves: the first bit in which the
    // range's first and last codes differ is the first in which the keys
    // differ above bit 32.
    let (first, last) = (keys[0] >> 32, keys[n - 1] >> 32);
    let mid = if first == last {
        n / 2
    } else {
        let bit = 1u64 << (63 - (first ^ last).leading_zeros() + 32);
        keys.partition_point(|k| k & bit == 0)
    };
    let (lk, rk) = keys.split_at(mid);
    let mut halves = (None, None);
    if n <= MAX_LEAF {
        let (lb, rb) = (keys_bounds(boxes, lk), keys_bounds(boxes, rk));
        let mut all = lb;
        all.grow(rb.lo, rb.hi);
        let to_u32 = |k: usize| u32::try_from(k).unwrap_or(u32::MAX);
        let split = TRAVERSAL_COST
            + (lb.half_area() * pack_cost(to_u32(mid))
                + rb.half_area() * pack_cost(to_u32(n - mid)))
                / all.half_area().max(f32::MIN_POSITIVE);
        if pack_cost(to_u32(n)) <= split {
            return leaf(Some(all));
        }
        halves = (Some(lb), Some(rb));
    }
    let (l, r) = if n > PARALLEL_THRESHOLD {
        rayon::join(
            || morton_range(boxes, lk, offset, halves.0),
            || morton_range(boxes, rk, offset + mid, halves.1),
        )
    } else {
        (
            morton_range(boxes, lk, offset, halves.0),
            morton_range(boxes, rk, offset + mid, halves.1),
        )
    };
    BNode::inner(l.bounds().union(r.bounds()), [l, r])
}

/// Where [`collapse`] writes one 8-wide node's subtree: the node itself,
/// the nodes below it (its [`Tally`]'s count less one, starting at node
/// `below_at`), and its packs with their triangle ids (starting at pack
/// `packs_at`). The layout is depth-first: a node's inner children in
/// consecutive slots, then each child's own subtree in turn; a node's
/// leaf children's packs, then each inner child's packs in turn.
struct Out<'a> {
    root: &'a mut Node,
    below: &'a mut [Node],
    below_at: usize,
    packs: &'a mut [TriPack],
    ids: &'a mut [u32],
    packs_at: usize,
}

/// Splits the first `n` elements off the front of `rest`.
fn take_front<'a, T>(rest: &mut &'a mut [T], n: usize) -> &'a mut [T] {
    let (front, back) = std::mem::take(rest).split_at_mut(n);
    *rest = back;
    front
}

/// Fills `out` from the binary subtree `node` (its leaves become packs);
/// returns the depth in 8-wide nodes. The children of a subtree of more
/// than [`PARALLEL_THRESHOLD`] triangles' packs are filled in parallel:
/// every place is fixed by the tallies, so the arrays are the same at any
/// thread count.
fn collapse<F: Fn(u32) -> [Vec3; 3] + Sync>(
    node: &BNode,
    out: Out<'_>,
    leaves: &Leaves<'_, F>,
) -> u32 {
    let (kids, len) = gather(node);
    let inner = kids[..len]
        .iter()
        .filter(|k| matches!(k, BNode::Inner { .. }))
        .count();
    let direct: usize = kids[..len]
        .iter()
        .filter(|k| matches!(k, BNode::Leaf { .. }))
        .map(|k| k.tally().packs)
        .sum();
    let (roots, mut below) = out.below.split_at_mut(inner);
    let mut roots = roots.iter_mut();
    let mut root_at = out.below_at;
    let mut below_at = out.below_at + inner;
    let (mut packs, mut kid_packs) = out.packs.split_at_mut(direct);
    let (mut ids, mut kid_ids) = out.ids.split_at_mut(4 * direct);
    let mut packs_at = out.packs_at;
    let mut kid_packs_at = out.packs_at + direct;
    // Emits a leaf's packs (`ids` in that order) at the front of the
    // node's own packs; the index of the first.
    let mut emit = |order: &[u32]| -> u32 {
        let k = order.len().div_ceil(4);
        emit_into(
            order,
            leaves.tri,
            take_front(&mut packs, k),
            take_front(&mut ids, 4 * k),
        );
        let first = u32::try_from(packs_at).unwrap_or(u32::MAX);
        packs_at += k;
        first
    };
    let mut n = empty_node();
    let mut jobs: [Option<(&BNode, Out<'_>)>; WIDTH] = [const { None }; WIDTH];
    // Lanes the children leave free: a leaf of several packs takes one
    // lane per pack while they last, each with the box of its own
    // triangles, so the node's one slab test culls pack by pack.
    let mut free = WIDTH - len;
    let mut lane = 0;
    for kid in &kids[..len] {
        match kid {
            BNode::Leaf {
                bounds,
                start,
                count,
            } if *count > 4 && count.div_ceil(4) - 1 <= free => {
                // The leaf's triangles in the order of their centroids
                // along its longest side (ties by id), so that each
                // pack's box is small. (At most 4·(WIDTH − 1) of them:
                // the node has two children or more, and this leaf's
                // packs take its own lane and free ones.)
                let e = bounds.extent();
                let axis = if e.x >= e.y && e.x >= e.z {
                    0
                } else if e.y >= e.z {
                    1
                } else {
                    2
                };
                // Keys: the centroid's coordinate (thrice) in an
                // order-preserving integer form, then the id.
                let mut keyed = [0u64; 4 * WIDTH];
                let keyed = &mut keyed[..*count];
                for (k, &id) in keyed.iter_mut().zip(&leaves.order[*start..start + count]) {
                    let t = (leaves.tri)(id);
                    let c = (t[0][axis] + t[1][axis] + t[2][axis]).to_bits();
                    let ordered = if c >> 31 == 1 { !c } else { c | 1 << 31 };
                    *k = u64::from(ordered) << 32 | u64::from(id);
                }
                keyed.sort_unstable();
                // (The lower half of a key: the id.)
                let mut sorted = [0u32; 4 * WIDTH];
                for (i, &k) in sorted.iter_mut().zip(keyed.iter()) {
                    *i = (k & 0xFFFF_FFFF) as u32;
                }
                let sorted = &sorted[..*count];
                let mut boxes = [Aabb::EMPTY; WIDTH];
                for (b, pack) in boxes.iter_mut().zip(sorted.chunks(4)) {
                    for &id in pack {
                        for p in (leaves.tri)(id) {
                            *b = b.grow(p);
                        }
                    }
                }
                let k = count.div_ceil(4);
                if split_pays(bounds, &boxes[..k]) {
                    free -= k - 1;
                    for (b, pack) in boxes.iter().zip(sorted.chunks(4)) {
                        set_lane(&mut n, lane, *b);
                        n.child[lane] = LEAF | emit(pack);
                        lane += 1;
                    }
                } else {
                    // One lane, the sorted packs behind the leaf's box.
                    set_lane(&mut n, lane, kid.bounds());
                    n.child[lane] = LEAF | emit(sorted);
                    lane += 1;
                }
            }
            BNode::Leaf { start, count, .. } => {
                set_lane(&mut n, lane, kid.bounds());
                n.child[lane] = LEAF | emit(&leaves.order[*start..start + count]);
                lane += 1;
            }
            BNode::Inner { .. } => {
                set_lane(&mut n, lane, kid.bounds());
                let t = kid.tally();
                // (There are as many roots as inner children, and a lane
                // for each child.)
                let (Some(root), Some(job)) = (roots.next(), jobs.get_mut(lane)) else {
                    break;
                };
                n.child[lane] = u32::try_from(root_at).unwrap_or(EMPTY);
                root_at += 1;
                *job = Some((
                    kid,
                    Out {
                        root,
                        below: take_front(&mut below, t.nodes - 1),
                        below_at,
                        packs: take_front(&mut kid_packs, t.packs),
                        ids: take_front(&mut kid_ids, 4 * t.packs),
                        packs_at: kid_packs_at,
                    },
                ));
                below_at += t.nodes - 1;
                kid_packs_at += t.packs;
                lane += 1;
            }
        }
    }
    n.used = (1 << lane) - 1;
    *out.root = n;
    // The tallies place every node and pack: the node's own share is
    // used up exactly.
    debug_assert!(
        packs.is_empty() && ids.is_empty(),
        "the leaf children's packs fill their places"
    );
    debug_assert!(
        below.is_empty() && kid_packs.is_empty() && kid_ids.is_empty() && roots.next().is_none(),
        "the inner children's subtrees fill theirs"
    );
    let run = |job: &mut Option<(&BNode, Out<'_>)>| {
        job.take()
            .map_or(0, |(kid, out)| collapse(kid, out, leaves))
    };
    let depth = if node.tally().packs > PARALLEL_THRESHOLD / 4 {
        jobs.par_iter_mut().map(run).max()
    } else {
        jobs.iter_mut().map(run).max()
    };
    depth.unwrap_or(0) + 1
}

/// Writes the packs of a leaf of the triangles `order` (in that order)
/// into `packs` (exactly enough of them) and their ids into `ids`, four
/// lanes per pack; the last pack is marked so.
fn emit_into<F: Fn(u32) -> [Vec3; 3]>(
    order: &[u32],
    tri: &F,
    packs: &mut [TriPack],
    ids: &mut [u32],
) {
    for ((chunk, pack), lanes) in order.chunks(4).zip(packs.iter_mut()).zip(ids.chunks_mut(4)) {
        let (p, i) = pack_of(chunk, tri);
        *pack = p;
        lanes.copy_from_slice(&i);
    }
    if let Some(p) = packs.last_mut() {
        p.last = 1;
    }
}

/// The pack of up to four triangles and its lanes' ids (`u32::MAX` for an
/// unused lane, whose coordinates stay zero).
fn pack_of<F: Fn(u32) -> [Vec3; 3]>(chunk: &[u32], tri: &F) -> (TriPack, [u32; 4]) {
    // The coordinates gathered in plain arrays (lane by lane stores into
    // `Vec4`s are bounds-checked and branchy).
    let mut v = [[[0.0f32; 4]; 3]; 3];
    let mut ids = [u32::MAX; 4];
    for (lane, (&id, slot)) in chunk.iter().zip(&mut ids).enumerate() {
        *slot = id;
        for (corner, p) in tri(id).iter().enumerate() {
            v[corner][0][lane] = p.x;
            v[corner][1][lane] = p.y;
            v[corner][2][lane] = p.z;
        }
    }
    let pack = TriPack::new(
        v.map(|c| c.map(Vec4::from_array)),
        u32::try_from(chunk.len()).unwrap_or(4),
    );
    (pack, ids)
}

impl Bvh {
    /// Builds a BVH over the triangles `ids` whose vertices `tri(id)` gives,
    /// its binary tree by `tree` (see [`Tree`]).
    #[must_use]
    pub(crate) fn build(ids: &[u32], tri: impl Fn(u32) -> [Vec3; 3] + Sync, tree: Tree) -> Bvh {
        let mut bvh = Bvh::default();
        if ids.is_empty() {
            bvh.root = EMPTY;
            return bvh;
        }
        // The SAH and the flat leaf partition an array of the boxes; the
        // Morton build forms them from the vertices where it needs them.
        // (Every pass over all the triangles runs in parallel: rayon's
        // indexed collects and min/max reductions give the same array and
        // bounds at every thread count.)
        let mut prims: Big<PrimRef> = if tree == Tree::Morton {
            Big::default()
        } else {
            Big::from_fn(ids.len(), |k| prim_ref(k, tri(ids[k])))
        };
        // The triangle ids in leaf order: the primitives' own order after
        // the SAH's partitions, the sorted keys' for Morton order.
        let mut morton_keys = None;
        let tree = match tree {
            Tree::Flat => BNode::Leaf {
                bounds: bounds_of(&prims).0.aabb(),
                start: 0,
                count: ids.len(),
            },
            Tree::Sah => {
                let b = bounds_of(&prims);
                build_binary(&mut prims, 0, 0, b)
            }
            Tree::Morton => {
                let (tree, keys) = build_morton(ids, &tri);
                morton_keys = Some(keys);
                tree
            }
        };
        bvh.bounds = tree.bounds();
        let (c, r) = bvh.bounds.bounding_sphere();
        bvh.sphere = (to_f64(c), f64::from(r) * (1.0 + 1e-6));
        bvh.triangles = ids.len();
        let order: Big<u32> = match morton_keys.as_deref() {
            Some(keys) => Big::from_fn(ids.len(), |k| ids[key_index(keys[k])]),
            None => {
                let prims: &[PrimRef] = &prims;
                Big::from_fn(ids.len(), |k| ids[prims[k].index() as usize])
            }
        };
        drop(morton_keys);
        drop(prims);
        let leaves = Leaves {
            order: &order,
            tri: &tri,
        };
        // Every node and pack has its place before any is written (the
        // tree's tallies), so the arrays are allocated once, without
        // growth or copies (at ten million triangles the node array's
        // doublings were a third of the Morton build), and filled in
        // parallel. Every slot is written exactly once below (the tallies
        // count them, and `collapse` checks that each share is used up),
        // so the arrays start as untouched zero pages: filling them with
        // empty nodes and packs first wrote the 10 M build's 680 MB twice.
        let Tally { nodes, packs } = tree.tally();
        bvh.nodes = Big::zeroed(nodes);
        bvh.packs = Big::zeroed(packs);
        bvh.ids = Big::zeroed(4 * packs);
        match &tree {
            BNode::Leaf { start, count, .. } => {
                let order = &leaves.order[*start..start + count];
                emit_into(order, leaves.tri, &mut bvh.packs, &mut bvh.ids);
                bvh.root = LEAF;
                bvh.root_count = u32::try_from(*count).unwrap_or(0);
                bvh.depth = 0;
            }
            BNode::Inner { .. } => {
                bvh.root = 0;
                let (root, below) = bvh.nodes.split_at_mut(1);
                bvh.depth = collapse(
                    &tree,
                    Out {
                        root: &mut root[0],
                        below,
                        below_at: 1,
                        packs: &mut bvh.packs,
                        ids: &mut bvh.ids,
                        packs_at: 0,
                    },
                    &leaves,
                );
            }
        }
        drop_tree(tree);
        bvh
    }

    /// Appends the packs of a leaf of the triangles `ids`, in that order;
    /// returns the index of its first pack.
    pub(crate) fn emit_ids<F: Fn(u32) -> [Vec3; 3]>(&mut self, ids: &[u32], tri: &F) -> u32 {
        let first = u32::try_from(self.packs.len()).unwrap_or(u32::MAX);
        for chunk in ids.chunks(4) {
            let (pack, lanes) = pack_of(chunk, tri);
            self.ids.extend_from_slice(&lanes);
            self.packs.push(pack);
        }
        if let Some(p) = self.packs.last_mut() {
            p.last = 1;
        }
        first
    }

    /// The packs and their ids as slices, which a query takes once: each
    /// access through a [`Big`] checks which form it has and casts the
    /// map's bytes (callgrind: +5 % instructions on the shadow rays with
    /// the leaf tests reaching through it).
    #[inline(always)]
    fn leaf_arrays(&self) -> LeafArrays<'_> {
        (&self.packs, &self.ids)
    }

    /// Statistics.
    #[must_use]
    pub(crate) fn stats(&self) -> BvhStats {
        let leaves = self
            .nodes
            .iter()
            .flat_map(|n| n.child.iter())
            .filter(|&&c| c != EMPTY && c & LEAF != 0)
            .count()
            + usize::from(self.nodes.is_empty() && self.root != EMPTY);
        BvhStats {
            triangles: self.triangles,
            nodes: self.nodes.len(),
            leaves,
            depth: self.depth,
            bytes: self.nodes.len() * std::mem::size_of::<Node>()
                + self.packs.len() * std::mem::size_of::<TriPack>()
                + self.ids.len() * 4,
        }
    }

    /// The farthest `t` at which `ray` can meet a triangle of the tree: a
    /// bound on the distance to the far side of the bounds' bounding
    /// sphere (the L1 norm of the offset from its centre is never below
    /// the Euclidean one, and needs no square root). A distance is a `t`
    /// for a unit direction, which every `Ray64` has (its contract): the
    /// boxes' inflation ([`WalkRay`]) rests on it.
    #[inline(always)]
    fn reach(&self, ray: &Ray64) -> f64 {
        let (c, r) = self.sphere;
        (ray.origin - c).abs().element_sum() + r
    }

    /// The closest hit with `t` in `[ray.t_min, ray.t_max]`; equal `t`
    /// (in `f64`, as the triangle test decides it) goes to the lower
    /// triangle id.
    #[must_use]
    pub(crate) fn intersect(&self, ray: &Ray64) -> Option<BvhHit> {
        self.arch.dispatch(Closest { bvh: self, ray })
    }

    /// Calls `visit(id, hit)` for every triangle hit with `t` in
    /// `[ray.t_min, ray.t_max]` but triangle `skip` (which is not tested:
    /// [`NO_SKIP`] skips none), in no particular order; stops when `visit`
    /// returns `true`.
    pub(crate) fn for_each_hit(
        &self,
        ray: &Ray64,
        skip: u32,
        visit: impl FnMut(u32, TriHit) -> bool,
    ) {
        self.arch.dispatch(EachHit {
            bvh: self,
            ray,
            skip,
            visit,
        });
    }

    /// The instruction set the queries run with.
    pub(crate) fn set_simd(&mut self, path: SimdPath) {
        self.arch = match path {
            SimdPath::Auto => pulp::Arch::new(),
            SimdPath::Baseline => pulp::Arch::Scalar,
        };
    }

    /// The instruction set the queries run with: `"x86-64-v3"` (AVX2,
    /// found at run time) or `"baseline"` (the target's own, SSE2 on x86-64).
    pub(crate) fn simd_name(&self) -> &'static str {
        match self.arch {
            pulp::Arch::Scalar => "baseline",
            #[cfg(target_arch = "x86_64")]
            pulp::Arch::V3(_) => "x86-64-v3",
            // `pulp::Arch` is non-exhaustive, and its variants differ by target.
            _ => "other",
        }
    }

    /// [`Bvh::intersect`], compiled into each instruction set's copy.
    #[inline(always)]
    fn closest(&self, boxes: Boxes, ray: &Ray64) -> Option<BvhHit> {
        let walk = WalkRay::new(ray, self.reach(ray));
        let mut t_prune = walk.ray.t_max;
        let mut leaf = ClosestLeaf {
            ray,
            walk: &walk,
            pre: None,
            best: None,
            best_t: ray.t_max,
        };
        self.traverse(boxes, &walk, &mut t_prune, true, &mut leaf);
        leaf.best
    }

    /// [`Bvh::for_each_hit`], compiled into each instruction set's copy.
    #[inline(always)]
    fn each_hit(
        &self,
        boxes: Boxes,
        ray: &Ray64,
        skip: u32,
        visit: impl FnMut(u32, TriHit) -> bool,
    ) {
        let walk = WalkRay::new(ray, self.reach(ray));
        let mut t_prune = walk.ray.t_max;
        let mut leaf = EachLeaf {
            ray,
            walk: &walk,
            pre: None,
            t_max: ray.t_max,
            skip,
            visit,
        };
        self.traverse(boxes, &walk, &mut t_prune, false, &mut leaf);
    }

    /// Tests the leaf starting at pack `first`: four triangles at a time
    /// for the edge test ([`candidates`]), then the survivors but triangle
    /// `skip` one by one in `f64`; `hit(id, hit, t_max)` may shrink `t_max`
    /// and returns `true` to stop. `SEGMENT` also drops triangles wholly
    /// behind the origin or past the ray's `t_max` in the filter: only for
    /// walks whose `t_max` stays the ray's own (any hit, every hit).
    #[inline(always)]
    fn leaf_hits<const SEGMENT: bool>(
        (packs, ids): LeafArrays<'_>,
        (pre, shear): (&RayPrecomp, &mut Option<[f64; 3]>),
        first: usize,
        (t_min, skip): (f64, u32),
        t_max: &mut f64,
        mut hit: impl FnMut(u32, TriHit, &mut f64) -> bool,
    ) -> bool {
        // The segment bounds of the filter were formed from this `t_max`.
        let t_fixed = *t_max;
        let mut p = first;
        loop {
            let pack = &packs[p];
            let mut lanes = candidates::<SEGMENT>(pre, pack);
            while lanes != 0 {
                let lane = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                let id = ids[4 * p + lane];
                if id == skip {
                    continue;
                }
                let s = *shear.get_or_insert_with(|| pre.shear64());
                if let Some(h) = intersect_lane(pre, s, pack, lane, t_min, *t_max) {
                    let stop = hit(id, h, t_max);
                    debug_assert!(
                        !SEGMENT || t_max.to_bits() == t_fixed.to_bits(),
                        "a segment walk's t_max must stay the ray's own"
                    );
                    if stop {
                        return true;
                    }
                }
            }
            if pack.ends_leaf() {
                return false;
            }
            p += 1;
        }
    }

    /// Whether a triangle of the leaf starting at pack `first`, but
    /// `skip`, meets `ray` and is accepted: the any-hit walk's test of one
    /// leaf (the same filter and `f64` test, so the same triangles meet
    /// the ray), for the light buffer's cells, whose leaves are packs of
    /// a tree without nodes.
    /// (`accept(id, hit)`: the hit as `for_each_hit` gives it.)
    pub(crate) fn leaf_any(
        &self,
        ray: &Ray64,
        skip: u32,
        first: u32,
        mut accept: impl FnMut(u32, TriHit) -> bool,
    ) -> bool {
        let walk = WalkRay::new(ray, ray.t_max);
        let pre = RayPrecomp::of::<true>(ray, &walk);
        let mut t_max = ray.t_max;
        Bvh::leaf_hits::<true>(
            self.leaf_arrays(),
            (&pre, &mut None),
            first as usize,
            (ray.t_min, skip),
            &mut t_max,
            |id, h, _| accept(id, h),
        )
    }

    /// [`Bvh::leaf_hits`] (`SEGMENT`) of two rays with the same axis
    /// permutation at once: each pack's edge and distance filter for both
    /// in one pass ([`candidates2`], each ray's mask exactly its own
    /// [`candidates`]), then each ray's survivors but its `skip` in `f64`
    /// on its own fixed `t_max`; `hit(i, id, hit)` (ray `i` of the two)
    /// returns `true` to stop that ray. Returns which rays stopped. (Each
    /// ray's lane loop is `leaf_hits`' written out again: shared through
    /// one `#[inline(always)]` helper, callgrind gave `near_plane` and
    /// `spheres` with the rasterizer +0.9 % and +1.0 %, and the closest-hit
    /// pair's the 940 k bunny's ray frame +0.53 %.)
    #[inline(always)]
    fn leaf_hits_pair(
        (packs, ids): LeafArrays<'_>,
        mut pres: [(&RayPrecomp, &mut Option<[f64; 3]>); 2],
        first: usize,
        rays: [(&Ray64, u32); 2],
        mut hit: impl FnMut(usize, u32, TriHit) -> bool,
    ) -> [bool; 2] {
        let mut stopped = [false; 2];
        let mut p = first;
        loop {
            let pack = &packs[p];
            let (ma, mb) = candidates2::<true>(pres[0].0, pres[1].0, pack);
            for (i, mut lanes) in [ma, mb].into_iter().enumerate() {
                if stopped[i] {
                    continue;
                }
                let (pre, shear) = &mut pres[i];
                let (ray, skip) = rays[i];
                while lanes != 0 {
                    let lane = lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    let id = ids[4 * p + lane];
                    if id == skip {
                        continue;
                    }
                    let s = *shear.get_or_insert_with(|| pre.shear64());
                    if let Some(h) = intersect_lane(pre, s, pack, lane, ray.t_min, ray.t_max)
                        && hit(i, id, h)
                    {
                        stopped[i] = true;
                        break;
                    }
                }
            }
            if pack.ends_leaf() || stopped == [true; 2] {
                return stopped;
            }
            p += 1;
        }
    }

    /// Walks the tree; `leaf.visit(arrays, first_pack, t_max)` tests a leaf
    /// (of the tree's [`Bvh::leaf_arrays`], taken once) and may shrink
    /// `t_max`; returning `true` stops the walk. With `ordered`,
    /// children are visited nearest first (closest hit); without, in any
    /// order (any hit, all hits).
    #[inline(always)]
    fn traverse(
        &self,
        boxes: Boxes,
        walk: &WalkRay,
        t_max: &mut f32,
        ordered: bool,
        leaf: &mut impl Leaf,
    ) {
        if self.root == EMPTY {
            return;
        }
        if self.root & LEAF != 0 {
            leaf.visit(self.leaf_arrays(), (self.root & !LEAF) as usize, t_max);
            return;
        }
        self.traverse_from(
            (&self.nodes, self.leaf_arrays()),
            self.root,
            (boxes, &Slab::new(walk)),
            t_max,
            ordered,
            leaf,
        );
    }

    /// The stack a walk below a node needs: a visit pops one entry and
    /// pushes at most WIDTH − 1 (the nearest child is descended into
    /// directly), so (WIDTH − 1)·depth + 1 entries.
    #[inline(always)]
    fn stack_need(&self) -> usize {
        (WIDTH - 1) * self.depth as usize + 1
    }

    /// [`Bvh::traverse`] below the inner node `start`, on the tree's
    /// nodes and leaf arrays as its caller took them (once per walk or
    /// packet: each `Big` deref checks its form and casts).
    #[inline(always)]
    fn traverse_from(
        &self,
        (nodes, arrays): (&[Node], LeafArrays<'_>),
        start: u32,
        (boxes, slab): (Boxes, &Slab),
        t_max: &mut f32,
        ordered: bool,
        leaf: &mut impl Leaf,
    ) {
        let grow = Slab::GROW;
        debug_assert!(start & LEAF == 0, "the walk starts at an inner node");
        // The start node first: a ray that enters none of its children
        // (most camera rays of a small object) sets up no stack.
        let planes = Planes::of(slab);
        let n = &nodes[start as usize];
        let (mask, tn) = slab.test((boxes, &planes), n, *t_max);
        if mask == 0 {
            return;
        }
        // The stack holds (t_near bits << 32 | child).
        let mut stack = Stack::<u64>::default();
        let stack = stack.slice(self.stack_need());
        let mut sp = 0usize;
        let mut node = descend(n, mask, &tn, ordered, (stack, &mut sp));
        loop {
            if node & LEAF != 0 {
                if leaf.visit(arrays, (node & !LEAF) as usize, t_max) {
                    return;
                }
            } else {
                let n = &nodes[node as usize];
                let (mask, tn) = slab.test((boxes, &planes), n, *t_max);
                if mask != 0 {
                    node = descend(n, mask, &tn, ordered, (stack, &mut sp));
                    continue;
                }
            }
            // Pop the next box that can still hold a hit. Its t_near
            // carries rounding error too: compare it with t_max enlarged
            // like t_far, so a box holding a hit at exactly t_max (a tie,
            // decided by id) is still visited.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let e = stack[sp];
                #[expect(clippy::cast_possible_truncation, reason = "unpacking the two halves")]
                let (t_near, child) = (f32::from_bits((e >> 32) as u32), e as u32);
                if t_near <= *t_max * grow {
                    node = child;
                    break;
                }
            }
        }
    }

    /// Fills the walking rays, slab constants and `f32` bounds of a
    /// packet's first `n` rays, whose first ray's are in lane 0 already
    /// (the lanes past `n` repeat the last ray and are never entered).
    /// Written in place, ray by ray: `array::from_fn` built each array
    /// through its generic fallible path, and the arrays returned as a
    /// tuple were copied out by `memcpy` calls; together 17 % of a primary
    /// packet's instructions.
    #[inline(always)]
    fn packet_rays(&self, rays: &[Ray64], n: usize, (walks, slabs, t_prune): PacketRaysMut<'_>) {
        for i in 1..PACKET {
            let r = &rays[i.min(n - 1)];
            let w = WalkRay::new(r, self.reach(r));
            walks[i] = w;
            slabs[i] = Slab::new(&w);
            t_prune[i] = w.ray.t_max;
        }
    }

    /// The walking ray of `ray` (its reach bounded by the tree's bounds).
    #[inline(always)]
    fn walk_ray(&self, ray: &Ray64) -> WalkRay {
        WalkRay::new(ray, self.reach(ray))
    }

    /// The closest hits of `rays` into `out` (the same length), each
    /// exactly [`Bvh::intersect`] of its ray, traced [`PACKET`] at a time
    /// (see [`Bvh::closest_packet`]).
    pub(crate) fn intersect_packet(&self, rays: &[Ray64], out: &mut [Option<BvhHit>]) {
        debug_assert_eq!(rays.len(), out.len(), "one hit slot per ray");
        for (rays, out) in rays.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            self.arch.dispatch(ClosestPacket {
                bvh: self,
                rays,
                out,
            });
        }
    }

    /// The closest hits of a packet of up to [`PACKET`] rays (a 4×2 block
    /// of camera rays): the rays walk the tree together while more than
    /// [`SOLO`] of them enter the same inner node, one node fetch and one
    /// stack for all, their slab tests independent of each other (the
    /// processor overlaps them); below a node that `SOLO` or fewer enter,
    /// each of them finishes the subtree on the single-ray walk.
    ///
    /// Each ray's hit is exactly its single-ray one: a ray leaves a child
    /// only on its own slab test against its own bound, which never culls
    /// a box holding a hit at or before the best so far, and its best is
    /// the least (distance, id) over the triangles it tested, whatever the
    /// order it tested them in.
    #[inline(always)]
    fn closest_packet(&self, boxes: Boxes, rays: &[Ray64], out: &mut [Option<BvhHit>]) {
        let n = rays.len().min(out.len()).min(PACKET);
        if n <= 1 || self.root == EMPTY || self.root & LEAF != 0 {
            for (o, r) in out.iter_mut().zip(rays) {
                *o = self.closest(boxes, r);
            }
            return;
        }
        let ray_of = |i: usize| &rays[i.min(n - 1)];
        let first = self.walk_ray(&rays[0]);
        let mut walks = [first; PACKET];
        let mut slabs = [Slab::new(&first); PACKET];
        let mut t_prune = [first.ray.t_max; PACKET];
        self.packet_rays(rays, n, (&mut walks, &mut slabs, &mut t_prune));
        let nodes: &[Node] = &self.nodes;
        // Taken at the first leaf or lone ray: most packets of a small
        // object's frame meet none (two `Big` derefs saved).
        let mut arrays: Option<LeafArrays<'_>> = None;
        // (An `if`, not `bool::then`: its closure was compiled out of
        // line, without the instruction set, once the walk grew.)
        let mut wide = if self.depth >= PACKET_TEST_DEPTH {
            Some(PacketSlab::new(&slabs, &t_prune))
        } else {
            None
        };
        let mut leaves: [ClosestLeaf<'_>; PACKET] = std::array::from_fn(|i| ClosestLeaf {
            ray: ray_of(i),
            walk: &walks[i],
            pre: None,
            best: None,
            best_t: ray_of(i).t_max,
        });
        let grow = Slab::GROW;
        // Entries: (child, its rays as a bit mask, the least t_near of
        // those rays).
        let mut stack = Stack::<(u32, u32, f32)>::default();
        let stack = stack.slice(self.stack_need());
        let mut sp = 0usize;
        let mut node = self.root;
        let mut active: u32 = (1 << n) - 1;
        'walk: loop {
            if node & LEAF == 0 && active.count_ones() <= SOLO {
                let arrays = *arrays.get_or_insert_with(|| self.leaf_arrays());
                let mut m = active;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    self.traverse_from(
                        (nodes, arrays),
                        node,
                        (boxes, &slabs[r]),
                        &mut t_prune[r],
                        true,
                        &mut leaves[r],
                    );
                }
            } else if node & LEAF != 0 {
                let first = (node & !LEAF) as usize;
                let arrays = *arrays.get_or_insert_with(|| self.leaf_arrays());
                let mut m = active;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    // Two rays with the same axes filter the leaf
                    // together, eight lanes wide ([`ClosestLeaf::visit_pair`]).
                    if m != 0 {
                        let r2 = m.trailing_zeros() as usize;
                        if let Ok([a, b]) = leaves.get_disjoint_mut([r, r2])
                            && a.precomp().k == b.precomp().k
                        {
                            m &= m - 1;
                            ClosestLeaf::visit_pair([a, b], arrays, first);
                            t_prune[r] = f32_at_least(a.best_t);
                            t_prune[r2] = f32_at_least(b.best_t);
                            continue;
                        }
                    }
                    leaves[r].visit(arrays, first, &mut t_prune[r]);
                }
            } else {
                let nd = &nodes[node as usize];
                // As the any-hit packet walk: the packet's bounds, then
                // each child they leave against every ray; a child's key
                // is the least `t_near` of the rays that enter it.
                let mut rays_of = [0u32; WIDTH];
                let mut key = [f32::INFINITY; WIDTH];
                let mut mask = 0u32;
                if let Some(wide) = &mut wide {
                    wide.set_bounds(&t_prune);
                    let mut c = wide.children_of(boxes, nd);
                    while c != 0 {
                        let k = c.trailing_zeros() as usize;
                        c &= c - 1;
                        let (entered, tn) = wide.rays_in(boxes, nd, k);
                        let r = entered & active;
                        rays_of[k] = r;
                        mask |= u32::from(r != 0) << k;
                        let mut m = r;
                        while m != 0 {
                            let i = m.trailing_zeros() as usize;
                            m &= m - 1;
                            key[k] = lane_min(key[k], tn[i]);
                        }
                    }
                } else {
                    let mut by_ray = 0u64;
                    let mut m = active;
                    while m != 0 {
                        let r = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let (ray_mask, tn) = slabs[r].test_lanes(boxes, nd, t_prune[r]);
                        by_ray |= u64::from(ray_mask) << (8 * r);
                        for k in 0..WIDTH {
                            let hit = (ray_mask >> k) & 1;
                            key[k] = if hit != 0 {
                                lane_min(key[k], tn[k])
                            } else {
                                key[k]
                            };
                        }
                    }
                    (mask, rays_of) = rays_by_child(by_ray);
                }
                if mask != 0 {
                    let near = push_children(
                        mask,
                        &key,
                        true,
                        (stack, &mut sp),
                        |k| (nd.child[k], rays_of[k], key[k]),
                        |e| e.2,
                    );
                    node = nd.child[near];
                    active = rays_of[near];
                    continue;
                }
            }
            // Pop the next box that one of its rays can still hit (the
            // rays' least t_near against each one's enlarged bound, as in
            // the single-ray walk).
            loop {
                if sp == 0 {
                    break 'walk;
                }
                sp -= 1;
                let (child, rays_in, t_near) = stack[sp];
                let mut live = 0;
                let mut m = rays_in;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    live |= u32::from(t_near <= t_prune[r] * grow) << r;
                }
                if live != 0 {
                    node = child;
                    active = live;
                    break;
                }
            }
        }
        for (o, l) in out[..n].iter_mut().zip(&leaves) {
            *o = l.best;
        }
    }

    /// For each ray of `rays`, whether `accept(ray index, triangle, hit)`
    /// holds for some triangle it hits in `[t_min, t_max]` other than its
    /// entry of `skips` (into `out`, both the same length): the answer of
    /// [`Bvh::for_each_hit`] stopped at the first accepted hit, traced
    /// [`PACKET`] rays at a time (see [`Bvh::any_packet8`]). `accept` must
    /// depend on its arguments only.
    pub(crate) fn any_packet(
        &self,
        rays: &[Ray64],
        skips: &[u32],
        mut accept: impl FnMut(usize, u32, TriHit) -> bool,
        out: &mut [bool],
    ) {
        debug_assert_eq!(rays.len(), out.len(), "one answer per ray");
        debug_assert_eq!(rays.len(), skips.len(), "one skipped triangle per ray");
        for (c, ((rays, skips), out)) in rays
            .chunks(PACKET)
            .zip(skips.chunks(PACKET))
            .zip(out.chunks_mut(PACKET))
            .enumerate()
        {
            let base = c * PACKET;
            self.arch.dispatch(AnyPacket {
                bvh: self,
                rays,
                skips,
                out,
                accept: |r: usize, id: u32, h: TriHit| accept(base + r, id, h),
            });
        }
    }

    /// [`Bvh::any_packet`] of up to [`PACKET`] rays: the packet walk of
    /// [`Bvh::closest_packet`] in any order, a ray leaving the packet at its
    /// first accepted hit. The answers are the single-ray ones: a ray is
    /// culled from a child only by its own slab test, so it meets every
    /// triangle it would meet alone until it stops, and whether some hit
    /// is accepted does not depend on the order the hits come in.
    #[inline(always)]
    fn any_packet8(
        &self,
        boxes: Boxes,
        rays: &[Ray64],
        skips: &[u32],
        out: &mut [bool],
        mut accept: impl FnMut(usize, u32, TriHit) -> bool,
    ) {
        let n = rays.len().min(out.len()).min(skips.len()).min(PACKET);
        if n <= 1 || self.root == EMPTY || self.root & LEAF != 0 {
            for (r, (o, ray)) in out.iter_mut().zip(rays).enumerate() {
                let mut hit = false;
                self.each_hit(boxes, ray, skips[r], |id, h| {
                    hit = accept(r, id, h);
                    hit
                });
                *o = hit;
            }
            return;
        }
        let ray_of = |i: usize| &rays[i.min(n - 1)];
        let first = self.walk_ray(&rays[0]);
        let mut walks = [first; PACKET];
        let mut slabs = [Slab::new(&first); PACKET];
        let mut t_prune = [first.ray.t_max; PACKET];
        self.packet_rays(rays, n, (&mut walks, &mut slabs, &mut t_prune));
        let nodes: &[Node] = &self.nodes;
        let arrays = self.leaf_arrays();
        // (An any-hit walk's bounds stay the rays' own.)
        let wide = if self.depth >= PACKET_TEST_DEPTH {
            Some(PacketSlab::new(&slabs, &t_prune))
        } else {
            None
        };
        let mut pres: [Option<Precomp>; PACKET] = [None; PACKET];
        // Entries: (child, the mask of its rays).
        let mut stack = Stack::<(u32, u32)>::default();
        let stack = stack.slice(self.stack_need());
        let mut sp = 0usize;
        let mut node = self.root;
        // The rays not yet stopped, and those in the current node.
        let mut alive: u32 = (1 << n) - 1;
        let mut active = alive;
        'walk: loop {
            if node & LEAF == 0 && active.count_ones() <= SOLO {
                let mut m = active;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let mut stopped = false;
                    let mut leaf = EachLeaf {
                        ray: ray_of(r),
                        walk: &walks[r],
                        pre: pres[r].take(),
                        t_max: ray_of(r).t_max,
                        skip: skips[r.min(n - 1)],
                        visit: |id, h| {
                            stopped = accept(r, id, h);
                            stopped
                        },
                    };
                    self.traverse_from(
                        (nodes, arrays),
                        node,
                        (boxes, &slabs[r]),
                        &mut t_prune[r],
                        false,
                        &mut leaf,
                    );
                    pres[r] = leaf.pre;
                    if stopped {
                        alive &= !(1 << r);
                    }
                }
            } else if node & LEAF != 0 {
                let first = (node & !LEAF) as usize;
                let mut m = active;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let ray = ray_of(r);
                    pres[r].get_or_insert_with(|| (RayPrecomp::of::<true>(ray, &walks[r]), None));
                    // Two rays with the same axes test the leaf together,
                    // eight lanes wide ([`candidates2`]).
                    if m != 0 {
                        let r2 = m.trailing_zeros() as usize;
                        pres[r2].get_or_insert_with(|| {
                            (RayPrecomp::of::<true>(ray_of(r2), &walks[r2]), None)
                        });
                        if let Ok([Some((pa, sa)), Some((pb, sb))]) = pres.get_disjoint_mut([r, r2])
                            && pa.k == pb.k
                        {
                            m &= m - 1;
                            let stopped = Bvh::leaf_hits_pair(
                                arrays,
                                [(pa, sa), (pb, sb)],
                                first,
                                [
                                    (ray_of(r), skips[r.min(n - 1)]),
                                    (ray_of(r2), skips[r2.min(n - 1)]),
                                ],
                                |i, id, h| accept(if i == 0 { r } else { r2 }, id, h),
                            );
                            if stopped[0] {
                                alive &= !(1 << r);
                            }
                            if stopped[1] {
                                alive &= !(1 << r2);
                            }
                            continue;
                        }
                    }
                    let Some((pre, shear)) = pres[r].as_mut() else {
                        continue;
                    };
                    let mut t_max = ray.t_max;
                    let skip = skips[r.min(n - 1)];
                    if Bvh::leaf_hits::<true>(
                        arrays,
                        (pre, shear),
                        first,
                        (ray.t_min, skip),
                        &mut t_max,
                        |id, h, _| accept(r, id, h),
                    ) {
                        alive &= !(1 << r);
                    }
                }
            } else {
                let nd = &nodes[node as usize];
                let (mut mask, rays_of) = if let Some(wide) = &wide {
                    // The packet's bounds first, then each child they
                    // leave against every ray at once: the masks of the
                    // rays' own slab tests.
                    let mut rays_of = [0u32; WIDTH];
                    let mut mask = 0u32;
                    let mut c = wide.children_of(boxes, nd);
                    while c != 0 {
                        let k = c.trailing_zeros() as usize;
                        c &= c - 1;
                        let r = wide.rays_in(boxes, nd, k).0 & active;
                        rays_of[k] = r;
                        mask |= u32::from(r != 0) << k;
                    }
                    (mask, rays_of)
                } else {
                    let mut by_ray = 0u64;
                    let mut m = active;
                    while m != 0 {
                        let r = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let (mask, _) = slabs[r].test_lanes(boxes, nd, t_prune[r]);
                        by_ray |= u64::from(mask) << (8 * r);
                    }
                    rays_by_child(by_ray)
                };
                if mask != 0 {
                    let near = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    while mask != 0 {
                        let k = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        stack[sp] = (nd.child[k], rays_of[k]);
                        sp += 1;
                    }
                    node = nd.child[near];
                    active = rays_of[near];
                    continue;
                }
            }
            loop {
                if sp == 0 || alive == 0 {
                    break 'walk;
                }
                sp -= 1;
                let (child, rays_in) = stack[sp];
                if rays_in & alive != 0 {
                    node = child;
                    active = rays_in & alive;
                    break;
                }
            }
        }
        for (r, o) in out[..n].iter_mut().enumerate() {
            *o = alive & (1 << r) == 0;
        }
    }
}

/// The children a packet's rays enter, from each ray's mask of children
/// (byte `r` of `by_ray`: bit `k` set when ray `r` enters child `k`): the
/// mask of children some ray enters, and each child's mask of rays. The
/// 8×8 bit matrix is transposed by three exchanges of its off-diagonal
/// blocks (2×2, 4×4, then 8×8 bits; Hacker's Delight §7-3) instead of a
/// loop over every ray and child, and the mask of children is the OR of
/// the rays' bytes.
#[inline(always)]
fn rays_by_child(by_ray: u64) -> (u32, [u32; WIDTH]) {
    const _: () = assert!(WIDTH == 8 && PACKET == 8, "an 8×8 bit matrix");
    // Some ray enters child k: bit k of some byte (an OR of the bytes).
    let mut any = by_ray | by_ray >> 32;
    any |= any >> 16;
    any |= any >> 8;
    #[expect(clippy::cast_possible_truncation, reason = "the lowest byte")]
    let mask = u32::from(any as u8);
    let mut x = by_ray;
    let t = (x ^ (x >> 7)) & 0x00AA_00AA_00AA_00AA;
    x ^= t ^ (t << 7);
    let t = (x ^ (x >> 14)) & 0x0000_CCCC_0000_CCCC;
    x ^= t ^ (t << 14);
    let t = (x ^ (x >> 28)) & 0x0000_0000_F0F0_F0F0;
    x ^= t ^ (t << 28);
    let rays = x.to_le_bytes().map(u32::from);
    (mask, rays)
}

/// A leaf test of a walk ([`Bvh::traverse`]). A trait with an
/// always-inlined method rather than a closure: a closure this large,
/// called from two places, is compiled out of line, and so without the
/// instruction set of the copy it is called from (it ran the triangle
/// tests of the x86-64-v3 walk on SSE2 code, 20 % of a primary ray).
trait Leaf {
    /// Tests the leaf starting at pack `first` of `arrays` (the tree's
    /// [`Bvh::leaf_arrays`], taken once per walk: each `Big` deref checks
    /// its form and casts, about 17 instructions); may shrink `t_max`;
    /// `true` stops the walk.
    fn visit(&mut self, arrays: LeafArrays<'_>, first: usize, t_max: &mut f32) -> bool;
}

/// A ray's triangle-test constants, formed at its first leaf, and its
/// `f64` shear, formed by its first `f64` test ([`RayPrecomp`]).
type Precomp = (RayPrecomp, Option<[f64; 3]>);

/// A tree's packs and their lanes' ids ([`Bvh::leaf_arrays`]).
type LeafArrays<'a> = (&'a [TriPack], &'a [u32]);

/// The leaf test of a closest-hit query: the best hit so far.
struct ClosestLeaf<'a> {
    ray: &'a Ray64,
    walk: &'a WalkRay,
    /// The triangle test's constants, formed at the first leaf.
    pre: Option<Precomp>,
    best: Option<BvhHit>,
    best_t: f64,
}

impl Leaf for ClosestLeaf<'_> {
    #[inline(always)]
    fn visit(&mut self, arrays: LeafArrays<'_>, first: usize, t_prune: &mut f32) -> bool {
        let (ray, walk) = (self.ray, self.walk);
        let (pre, shear) = self
            .pre
            .get_or_insert_with(|| (RayPrecomp::of::<false>(ray, walk), None));
        let best = &mut self.best;
        Bvh::leaf_hits::<false>(
            arrays,
            (pre, shear),
            first,
            (ray.t_min, NO_SKIP),
            &mut self.best_t,
            |id, h, best_t| {
                offer(best, best_t, id, h);
                false
            },
        );
        // Boxes are pruned in f32: never below the f64 distance.
        *t_prune = f32_at_least(self.best_t);
        false
    }
}

impl ClosestLeaf<'_> {
    /// The triangle test's constants, formed at the ray's first leaf.
    #[inline(always)]
    fn precomp(&mut self) -> &RayPrecomp {
        let (ray, walk) = (self.ray, self.walk);
        &self
            .pre
            .get_or_insert_with(|| (RayPrecomp::of::<false>(ray, walk), None))
            .0
    }

    /// [`ClosestLeaf::visit`] of two rays with the same axis permutation
    /// on the leaf starting at pack `first`: each pack's edge filter for
    /// both at once ([`candidates2`], each ray's mask exactly its own
    /// [`candidates`]; the closest-hit filter reads no `t_max`, so one
    /// mask per pack serves every test of it), then each ray's survivors
    /// in `f64` against its own best so far. Each ray tests the same
    /// triangles in the same order (pack by pack, lanes ascending) with
    /// the same `t_max` at each test as in [`Bvh::leaf_hits`]: the two
    /// rays share only the filter, and their tests change nothing of the
    /// other's (its `best`, `best_t`, shear). So each gets bit for bit the
    /// hit of its own [`ClosestLeaf::visit`] (whose `skip`, [`NO_SKIP`],
    /// is no triangle's id: there is no skip test here). The caller sets
    /// the rays' `f32` pruning bounds afterwards, as `visit` does.
    #[inline(always)]
    fn visit_pair(leaves: [&mut Self; 2], (packs, ids): LeafArrays<'_>, first: usize) {
        let [a, b] = leaves;
        let (ray_a, walk_a) = (a.ray, a.walk);
        let (ray_b, walk_b) = (b.ray, b.walk);
        let (pa, sa) = a
            .pre
            .get_or_insert_with(|| (RayPrecomp::of::<false>(ray_a, walk_a), None));
        let (pb, sb) = b
            .pre
            .get_or_insert_with(|| (RayPrecomp::of::<false>(ray_b, walk_b), None));
        let mut p = first;
        loop {
            let pack = &packs[p];
            let (ma, mb) = candidates2::<false>(pa, pb, pack);
            for (mut lanes, pre, shear, ray, best, best_t) in [
                (ma, &*pa, &mut *sa, ray_a, &mut a.best, &mut a.best_t),
                (mb, &*pb, &mut *sb, ray_b, &mut b.best, &mut b.best_t),
            ] {
                while lanes != 0 {
                    let lane = lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    let id = ids[4 * p + lane];
                    let s = *shear.get_or_insert_with(|| pre.shear64());
                    if let Some(h) = intersect_lane(pre, s, pack, lane, ray.t_min, *best_t) {
                        offer(best, best_t, id, h);
                    }
                }
            }
            if pack.ends_leaf() {
                return;
            }
            p += 1;
        }
    }
}

/// The leaf test of an every-hit query: the caller's visitor.
struct EachLeaf<'a, F> {
    ray: &'a Ray64,
    walk: &'a WalkRay,
    /// The triangle test's constants, formed at the first leaf.
    pre: Option<Precomp>,
    t_max: f64,
    /// The triangle not tested ([`NO_SKIP`]: none).
    skip: u32,
    visit: F,
}

impl<F: FnMut(u32, TriHit) -> bool> Leaf for EachLeaf<'_, F> {
    #[inline(always)]
    fn visit(&mut self, arrays: LeafArrays<'_>, first: usize, _: &mut f32) -> bool {
        let (ray, walk) = (self.ray, self.walk);
        let (pre, shear) = self
            .pre
            .get_or_insert_with(|| (RayPrecomp::of::<true>(ray, walk), None));
        let visit = &mut self.visit;
        Bvh::leaf_hits::<true>(
            arrays,
            (pre, shear),
            first,
            (ray.t_min, self.skip),
            &mut self.t_max,
            |id, h, _| visit(id, h),
        )
    }
}

/// A packet's walking rays, slab constants and `f32` bounds, to be
/// filled by [`Bvh::packet_rays`].
type PacketRaysMut<'a> = (
    &'a mut [WalkRay; PACKET],
    &'a mut [Slab; PACKET],
    &'a mut [f32; PACKET],
);

/// A walk's stack: a 64-entry array for the usual trees (cheap to set up
/// per ray; depth ≤ 9), a heap vector beyond.
struct Stack<T> {
    small: [T; 64],
    big: Vec<T>,
}

impl<T: Copy + Default> Default for Stack<T> {
    #[inline(always)]
    fn default() -> Self {
        Stack {
            small: [T::default(); 64],
            big: Vec::new(),
        }
    }
}

impl<T: Copy + Default> Stack<T> {
    /// Room for `need` entries.
    #[inline(always)]
    fn slice(&mut self, need: usize) -> &mut [T] {
        if need <= self.small.len() {
            &mut self.small
        } else {
            self.big.resize(need, T::default());
            &mut self.big
        }
    }
}

/// The single-ray walk's [`push_children`]: its entries are `t_near` bits
/// << 32 | child, and it returns the child entry descended into. (A
/// function, not a closure: a closure called from two places is compiled
/// out of line, without the instruction set of its caller.)
#[inline(always)]
fn descend(
    n: &Node,
    mask: u32,
    tn: &[f32; WIDTH],
    ordered: bool,
    stack: (&mut [u64], &mut usize),
) -> u32 {
    let entry = |k: usize| (u64::from(tn[k].to_bits()) << 32) | u64::from(n.child[k]);
    // The high half (a shift by 32 leaves 32 bits).
    let t_of = |e: u64| f32::from_bits((e >> 32) as u32);
    n.child[push_children(mask, tn, ordered, stack, entry, t_of)]
}

/// Pushes a node's hit children (`mask`, their `t_near` in `tn`) but the
/// one the walk descends into onto `stack` from `sp`, as the walk's
/// entries (`entry(k)` of child `k`, whose `t_near` `t_of` reads back),
/// and returns that one's lane. With `ordered` it is the nearest (the
/// first of the least) and the pushed entries are sorted far to near, so
/// that the nearest is popped first; without, it is the lowest lane and
/// the rest are pushed by lane. Written straight onto the stack (an array
/// of the rest, returned and copied, cost the single-ray walk about 15
/// instructions a node).
#[inline(always)]
fn push_children<E: Copy>(
    mut mask: u32,
    tn: &[f32; WIDTH],
    ordered: bool,
    (stack, sp): (&mut [E], &mut usize),
    entry: impl Fn(usize) -> E,
    t_of: impl Fn(E) -> f32,
) -> usize {
    let mut near = mask.trailing_zeros() as usize;
    mask &= mask - 1;
    let first = *sp;
    while mask != 0 {
        let k = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let pushed = if ordered && tn[k] < tn[near] {
            std::mem::replace(&mut near, k)
        } else {
            k
        };
        stack[*sp] = entry(pushed);
        *sp += 1;
    }
    if ordered {
        // Descending t_near: the nearest of the pushed is popped first.
        for a in first + 1..*sp {
            let mut b = a;
            while b > first && t_of(stack[b - 1]) < t_of(stack[b]) {
                stack.swap(b - 1, b);
                b -= 1;
            }
        }
    }
    near
}

/// A packet closest-hit query as a `pulp` operation (see [`Closest`]).
struct ClosestPacket<'a> {
    bvh: &'a Bvh,
    rays: &'a [Ray64],
    out: &'a mut [Option<BvhHit>],
}

impl WithSimd for ClosestPacket<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        self.bvh
            .closest_packet(Boxes::of(simd), self.rays, self.out);
    }
}

/// A packet any-hit query as a `pulp` operation (see [`Closest`]).
struct AnyPacket<'a, F> {
    bvh: &'a Bvh,
    rays: &'a [Ray64],
    skips: &'a [u32],
    out: &'a mut [bool],
    accept: F,
}

impl<F: FnMut(usize, u32, TriHit) -> bool> WithSimd for AnyPacket<'_, F> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        self.bvh.any_packet8(
            Boxes::of(simd),
            self.rays,
            self.skips,
            self.out,
            self.accept,
        );
    }
}

/// A closest-hit query as a `pulp` operation: the walk and the triangle
/// tests are inlined into it, so each instruction set gets its own copy.
struct Closest<'a> {
    bvh: &'a Bvh,
    ray: &'a Ray64,
}

impl WithSimd for Closest<'_> {
    type Output = Option<BvhHit>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) -> Self::Output {
        self.bvh.closest(Boxes::of(simd), self.ray)
    }
}

/// An every-hit query as a `pulp` operation (see [`Closest`]).
struct EachHit<'a, F> {
    bvh: &'a Bvh,
    ray: &'a Ray64,
    skip: u32,
    visit: F,
}

impl<F: FnMut(u32, TriHit) -> bool> WithSimd for EachHit<'_, F> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        self.bvh
            .each_hit(Boxes::of(simd), self.ray, self.skip, self.visit);
    }
}

/// The closest-hit rule of every query: a hit replaces the best when it is
/// nearer (in `f64`), or as near with a lower triangle id.
#[inline(always)]
fn offer(best: &mut Option<BvhHit>, best_t: &mut f64, id: u32, h: TriHit) {
    let better = match *best {
        None => true,
        Some(b) => h.t64 < b.t64 || (h.t64 == b.t64 && id < b.id),
    };
    if better {
        *best = Some(BvhHit {
            t: h.t,
            t64: h.t64,
            id,
            b: h.b,
        });
        *best_t = h.t64;
    }
}

/// One ray's constants of the slab test of a node's eight boxes.
///
/// A zero direction component would give 0·∞ = NaN in the slab test: it
/// is replaced by a tiny one ([`slab_dir`]; the triangle test uses the
/// true direction). Boxes are inflated by the drift between the ray the
/// slabs walk and the `f64` ray it stands for ([`WalkRay::inflate`], which
/// counts that replacement: without it, a ray lying in a box's face with
/// a zero component left the box at t = 0); zero when they are the same
/// ray. The lower planes are
/// met from the origin moved up by it, the upper planes from the origin
/// moved down, rounded outward.
#[derive(Clone, Copy, Debug)]
struct Slab {
    /// Origin against the lower planes, per axis.
    lo: [f32; 3],
    /// Origin against the upper planes.
    hi: [f32; 3],
    /// Inverse direction.
    inv: [f32; 3],
    t_min: f32,
}

/// A ray's planes for [`Slab::test_v3`], formed from its [`Slab`] once
/// per single-ray walk ([`Planes::of`]), not with the [`Slab`]: a
/// packet's rays mostly never walk alone, and its own tests are the
/// lane-by-lane ones.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(
    not(target_arch = "x86_64"),
    allow(dead_code, reason = "read by `Slab::test_v3`")
)]
struct Planes {
    /// Per axis, the plane array of a node ([`Node::planes`]) the ray
    /// enters each box through (its lower plane where the inverse
    /// direction is positive, else its upper), and the one it leaves
    /// through.
    near: [usize; 3],
    far: [usize; 3],
    /// Per axis, the origin met against the `near` plane (`lo` where that
    /// is a lower plane, else `hi`), and against the `far` plane.
    o_near: [f32; 3],
    o_far: [f32; 3],
}

impl Planes {
    #[inline(always)]
    fn of(slab: &Slab) -> Planes {
        let (lo, hi) = (slab.lo, slab.hi);
        // By the sign bit: `inv` is never zero or NaN (every component of
        // the direction it inverts is finite and at least 10⁻³⁰).
        let down = |a: usize| slab.inv[a].is_sign_negative();
        Planes {
            near: std::array::from_fn(|a| 2 * a + usize::from(down(a))),
            far: std::array::from_fn(|a| 2 * a + usize::from(!down(a))),
            o_near: std::array::from_fn(|a| if down(a) { hi[a] } else { lo[a] }),
            o_far: std::array::from_fn(|a| if down(a) { lo[a] } else { hi[a] }),
        }
    }
}

/// How [`Slab::test`] runs: eight lanes wide with x86-64-v3's own
/// instructions (one compare and one `vmovmskps` for the mask, only the
/// planes each axis enters and leaves through), or written lane by lane
/// for the vectoriser (the baseline). Formed from a query's `pulp` token
/// ([`Boxes::of`]), whose type is known where the query is compiled, so
/// each instruction set's copy holds one form. (Only pulp's `V3` token
/// selects the eight-wide form: were pulp's `x86-v4` feature switched on,
/// `pulp::Arch::new` would pick `V4` on AVX-512 machines and the queries
/// would run the lane form there, as would the tests.)
#[derive(Clone, Copy, Debug)]
struct Boxes(#[cfg(target_arch = "x86_64")] Option<pulp::x86::V3>);

impl Boxes {
    /// The form for the instruction set of `simd` (the eight-wide one only
    /// for x86-64-v3's token; its type is known at compile time, so the
    /// `downcast` folds away).
    #[inline(always)]
    fn of<S: pulp::Simd>(simd: S) -> Boxes {
        #[cfg(target_arch = "x86_64")]
        {
            Boxes(
                (&simd as &dyn std::any::Any)
                    .downcast_ref::<pulp::x86::V3>()
                    .copied(),
            )
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = simd;
            Boxes()
        }
    }

    /// Whether this is the eight-wide form.
    #[cfg(test)]
    fn is_wide(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return self.0.is_some();
        #[cfg(not(target_arch = "x86_64"))]
        false
    }

    /// `a[k] <= b[k]` lane by lane as a bit mask: one compare and one
    /// `vmovmskps` on x86-64-v3, two SSE halves otherwise (the vectoriser
    /// turned the eight lanes' bits into shuffles and ORs). Both compares
    /// are ordered: a NaN lane is clear either way.
    #[inline(always)]
    fn le_mask(self, a: [f32; WIDTH], b: [f32; WIDTH]) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = self.0 {
            use std::arch::x86_64::_CMP_LE_OQ;
            let avx = v3.avx;
            let le = avx._mm256_cmp_ps::<_CMP_LE_OQ>(bytemuck::cast(a), bytemuck::cast(b));
            #[expect(clippy::cast_sign_loss, reason = "eight mask bits")]
            return avx._mm256_movemask_ps(le) as u32;
        }
        let half = |a: &[f32], b: &[f32]| Vec4::from_slice(a).cmple(Vec4::from_slice(b)).bitmask();
        half(&a[..4], &b[..4]) | half(&a[4..], &b[4..]) << 4
    }
}

/// The least and greatest `t` over a packet of one plane array `p`, from
/// the packet's least and greatest origin on the axis (`(o_lo, o_hi)`:
/// the offsets `a0 = p − o_hi ≤ a1 = p − o_lo`) and its inverse
/// directions in `[i_lo, i_hi]` (see [`PacketSlab::children_of_v3`]). (A
/// function, not a closure: called twice, a closure was compiled out of
/// line without the instruction set, and the packet walks took 13–20 %
/// more instructions.)
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn plane_bounds(
    v3: pulp::x86::V3,
    p: std::arch::x86_64::__m256,
    (o_lo, o_hi): (f32, f32),
    (i_lo, i_hi): (f32, f32),
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    let avx = v3.avx;
    let a0 = avx._mm256_sub_ps(p, avx._mm256_set1_ps(o_hi));
    let a1 = avx._mm256_sub_ps(p, avx._mm256_set1_ps(o_lo));
    let (lo, hi) = (avx._mm256_set1_ps(i_lo), avx._mm256_set1_ps(i_hi));
    // The choices need `a0 ≤ a1` and `i_lo ≤ i_hi`: a range is empty,
    // `(+∞, −∞)`, where every ray of the packet holds a NaN there (the
    // ranges' folds skip NaN), and then takes all four products, as the
    // lane form does, whose mask stays a superset of the rays' own.
    let ordered = o_lo <= o_hi && i_lo <= i_hi;
    // `blendv(x, y, m)`: `y` where `m`'s sign bit is set, else `x`.
    if ordered && i_lo > 0.0 {
        (
            avx._mm256_blendv_ps(avx._mm256_mul_ps(a0, lo), avx._mm256_mul_ps(a0, hi), a0),
            avx._mm256_blendv_ps(avx._mm256_mul_ps(a1, hi), avx._mm256_mul_ps(a1, lo), a1),
        )
    } else if ordered && i_hi < 0.0 {
        (
            avx._mm256_blendv_ps(avx._mm256_mul_ps(a1, lo), avx._mm256_mul_ps(a1, hi), a1),
            avx._mm256_blendv_ps(avx._mm256_mul_ps(a0, hi), avx._mm256_mul_ps(a0, lo), a0),
        )
    } else {
        let (p, q) = (avx._mm256_mul_ps(a0, lo), avx._mm256_mul_ps(a0, hi));
        let (r, s) = (avx._mm256_mul_ps(a1, lo), avx._mm256_mul_ps(a1, hi));
        (
            avx._mm256_min_ps(avx._mm256_min_ps(p, q), avx._mm256_min_ps(r, s)),
            avx._mm256_max_ps(avx._mm256_max_ps(p, q), avx._mm256_max_ps(r, s)),
        )
    }
}

/// `a < b ? a : b`, the semantics of `minps` (the vectoriser emits it).
#[inline(always)]
fn lane_min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `a > b ? a : b`, the semantics of `maxps`.
#[inline(always)]
fn lane_max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

impl Slab {
    /// `t_far` (and `t_max`) are enlarged by this factor: the slab test's
    /// rounding never culls a box the ray enters (Ize 2013, pbrt-v4).
    const GROW: f32 = 1.0 + 2.0 * gamma(3);

    #[inline(always)]
    fn new(walk: &WalkRay) -> Slab {
        let ray = &walk.ray;
        let o = Vec4::new(ray.origin.x, ray.origin.y, ray.origin.z, 0.0);
        // `slab_dir`, four lanes wide.
        let d = Vec4::new(ray.dir.x, ray.dir.y, ray.dir.z, 1.0);
        let tiny = Vec4::splat(1e-30);
        let small = d.abs().cmplt(tiny);
        let d = Vec4::select(small, tiny.copysign(d), d);
        debug_assert_eq!(d.truncate(), slab_dir(ray.dir), "the direction replaced");
        let inv = Vec4::ONE / d;
        // The replaced components' drift (never w's, which is 1).
        let inflate = walk.inflate + if small.any() { walk.replaced } else { 0.0 };
        let (lo, hi) = if inflate == 0.0 {
            (o, o)
        } else {
            // Each coordinate moved by at least `inflate` whatever the
            // rounding of the move: `fl(o ± s)` is within half an ulp of
            // `|o| + s` of the exact sum, which the `2⁻²²·|o|` term and
            // the relative margin on `inflate` cover (and `MIN_POSITIVE`
            // the subnormal range).
            let s = Vec4::splat(inflate * (1.0 + 1.0 / 1_048_576.0))
                + o.abs() * (1.0 / 4_194_304.0)
                + Vec4::splat(f32::MIN_POSITIVE);
            (o + s, o - s)
        };
        let xyz = |v: Vec4| [v.x, v.y, v.z];
        Slab {
            lo: xyz(lo),
            hi: xyz(hi),
            inv: xyz(inv),
            t_min: ray.t_min,
        }
    }

    /// The children of `n` whose boxes the ray enters before `t_max` (a bit
    /// mask), and the `t_near` of each lane: [`Slab::test_v3`] where the
    /// query runs on x86-64-v3 (`boxes`), else [`Slab::test_lanes`]; the
    /// walk decides the same with either.
    #[inline(always)]
    fn test(&self, (boxes, planes): (Boxes, &Planes), n: &Node, t_max: f32) -> (u32, [f32; WIDTH]) {
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = boxes.0 {
            return self.test_v3(v3, planes, n, t_max);
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = planes;
        self.test_lanes(boxes, n, t_max)
    }

    /// [`Slab::test`] with x86-64-v3's instructions, eight lanes at once:
    /// each axis meets only the plane the ray enters through and the one
    /// it leaves through ([`Planes`]), not both planes
    /// and then their `min` and `max` as [`Slab::test_lanes`] does, and
    /// the mask is one compare and one `vmovmskps`.
    ///
    /// The walk decides the same: it reads `t_near` and `t_far` only
    /// through comparisons, and they compare as [`Slab::test_lanes`]'
    /// do. With `ix > 0`, `(min − lo)·ix ≤ (max − hi)·ix`, since `min ≤
    /// max` and `lo ≥ hi` order the exact differences and rounding a
    /// difference, and a product by a positive factor, keeps an order
    /// (it is monotone); with `ix < 0` the order flips. So the near
    /// plane's value is the `min` of the two (equal to it; where the two
    /// are equal zeros, `lane_min` may give the other zero's sign, which
    /// no comparison sees) and the far plane's the `max`. No lane of a
    /// used box makes a NaN that `min` or `max` would have dropped: its
    /// planes are finite (the loader keeps every vertex within ±10¹²,
    /// `MAX_COORDINATE`; only empty slots, which `used` masks, are +∞; a
    /// tree built on non-finite vertices is outside this argument)
    /// and the origins never NaN, so `plane − o` is never NaN (an
    /// infinitely inflated origin gives ±∞, in order), and `ix` is finite
    /// and non-zero, so neither is the product. The
    /// remaining steps are `test_lanes`' own, in its order: `maxps` and
    /// `minps` are its `lane_max` and `lane_min`. Test
    /// `both_node_tests_decide_alike`.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn test_v3(
        &self,
        v3: pulp::x86::V3,
        order: &Planes,
        n: &Node,
        t_max: f32,
    ) -> (u32, [f32; WIDTH]) {
        use std::arch::x86_64::__m256;
        let avx = v3.avx;
        let planes = n.planes();
        let splat = |x: f32| avx._mm256_set1_ps(x);
        // `(plane − o)·inv` of a plane array (`& 7`: one of the eight, so
        // no bounds check).
        let t = |plane: usize, o: f32, inv: f32| {
            let p: __m256 = bytemuck::cast(planes[plane & 7]);
            avx._mm256_mul_ps(avx._mm256_sub_ps(p, splat(o)), splat(inv))
        };
        let [ix, iy, iz] = self.inv;
        let [nx, ny, nz] = order.near;
        let [fx, fy, fz] = order.far;
        let [onx, ony, onz] = order.o_near;
        let [ofx, ofy, ofz] = order.o_far;
        let tn = avx._mm256_max_ps(
            avx._mm256_max_ps(
                avx._mm256_max_ps(t(nx, onx, ix), t(ny, ony, iy)),
                t(nz, onz, iz),
            ),
            splat(self.t_min),
        );
        let tf = avx._mm256_mul_ps(
            avx._mm256_min_ps(
                avx._mm256_min_ps(t(fx, ofx, ix), t(fy, ofy, iy)),
                t(fz, ofz, iz),
            ),
            splat(Slab::GROW),
        );
        let tf = avx._mm256_min_ps(tf, splat(t_max * Slab::GROW));
        let le = avx._mm256_cmp_ps::<{ std::arch::x86_64::_CMP_LE_OQ }>(tn, tf);
        #[expect(clippy::cast_sign_loss, reason = "eight mask bits")]
        let mask = avx._mm256_movemask_ps(le) as u32;
        (mask & n.used, bytemuck::cast(tn))
    }

    /// [`Slab::test`] lane by lane (the mask by [`Boxes::le_mask`]):
    /// written for the vectoriser, one 256-bit operation per step on
    /// x86-64-v3, two SSE ones on the baseline, the same IEEE operations
    /// in every lane either way (no fused multiply-add: Rust never
    /// contracts).
    #[inline(always)]
    fn test_lanes(&self, boxes: Boxes, n: &Node, t_max: f32) -> (u32, [f32; WIDTH]) {
        let [ox0, oy0, oz0] = self.lo;
        let [ox1, oy1, oz1] = self.hi;
        let [ix, iy, iz] = self.inv;
        let far = t_max * Slab::GROW;
        let mut t_near = [0.0; WIDTH];
        let mut t_far = [0.0; WIDTH];
        for k in 0..WIDTH {
            let tx0 = (n.min_x[k] - ox0) * ix;
            let tx1 = (n.max_x[k] - ox1) * ix;
            let ty0 = (n.min_y[k] - oy0) * iy;
            let ty1 = (n.max_y[k] - oy1) * iy;
            let tz0 = (n.min_z[k] - oz0) * iz;
            let tz1 = (n.max_z[k] - oz1) * iz;
            let tn = lane_max(
                lane_max(
                    lane_max(lane_min(tx0, tx1), lane_min(ty0, ty1)),
                    lane_min(tz0, tz1),
                ),
                self.t_min,
            );
            let tf = lane_min(
                lane_min(lane_max(tx0, tx1), lane_max(ty0, ty1)),
                lane_max(tz0, tz1),
            ) * Slab::GROW;
            let tf = lane_min(tf, far);
            t_near[k] = tn;
            t_far[k] = tf;
        }
        (boxes.le_mask(t_near, t_far) & n.used, t_near)
    }
}

/// A packet's slab constants lane by lane (lane `r`: ray `r`'s
/// [`Slab`] and `far`), for testing one child box against every ray at
/// once ([`PacketSlab::rays_in`]), and their ranges over the packet, for
/// testing every child box against the packet at once
/// ([`PacketSlab::children_of`]).
#[derive(Clone, Copy, Debug)]
struct PacketSlab {
    /// Per axis, each ray's origin against the lower planes ([`Slab`]).
    lo: [[f32; PACKET]; 3],
    /// Per axis, each ray's origin against the upper planes.
    hi: [[f32; PACKET]; 3],
    /// Per axis, each ray's inverse direction.
    inv: [[f32; PACKET]; 3],
    /// Each ray's `t_min`.
    t_min: [f32; PACKET],
    /// `t_max · GROW` of each ray (its walk's bound).
    far: [f32; PACKET],
    /// Per axis, the least and greatest `lo`, `hi` and `inv` over the rays.
    lo_range: [(f32, f32); 3],
    hi_range: [(f32, f32); 3],
    inv_range: [(f32, f32); 3],
    /// The least `t_min` and the greatest `far` over the rays.
    t_min_least: f32,
    far_most: f32,
}

impl PacketSlab {
    #[inline(always)]
    fn new(slabs: &[Slab; PACKET], t_max: &[f32; PACKET]) -> PacketSlab {
        let lo = std::array::from_fn(|a| std::array::from_fn(|r| slabs[r].lo[a]));
        let hi = std::array::from_fn(|a| std::array::from_fn(|r| slabs[r].hi[a]));
        let inv = std::array::from_fn(|a| std::array::from_fn(|r| slabs[r].inv[a]));
        let t_min = std::array::from_fn(|r| slabs[r].t_min);
        let far: [f32; PACKET] = std::array::from_fn(|r| t_max[r] * Slab::GROW);
        let range = |v: &[f32; PACKET]| {
            v.iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                })
        };
        PacketSlab {
            lo_range: lo.map(|v| range(&v)),
            hi_range: hi.map(|v| range(&v)),
            inv_range: inv.map(|v| range(&v)),
            t_min_least: range(&t_min).0,
            far_most: range(&far).1,
            lo,
            hi,
            inv,
            t_min,
            far,
        }
    }

    /// The children of `n` some ray of the packet may enter: a superset
    /// of the union of the rays' [`Slab::test`] masks. Interval
    /// arithmetic on the rounded operations: `fl(b − o)` falls as `o`
    /// grows, so over the rays it lies in `[fl(b − o_max), fl(b − o_min)]`;
    /// `fl(a·i)` is a rounding of a product that is bilinear in `(a, i)`,
    /// whose extremes over a box lie at its corners, and rounding keeps
    /// order, so every ray's `t` of a plane lies within the least and
    /// greatest of the four corner products. Each ray's `t_near` (a `max`
    /// of `min`s and its `t_min`) is then at least the same expression of
    /// the lower ends, and its `t_far` (a `min` of `max`es times `GROW`,
    /// and its `far`) at most that of the upper ends: a ray that enters
    /// (`t_near ≤ t_far`) makes the bounds pass. No operand is NaN in a
    /// used lane (finite boxes, finite inverse directions).
    #[inline(always)]
    fn children_of(&self, boxes: Boxes, n: &Node) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = boxes.0 {
            return self.children_of_v3(v3, n);
        }
        self.children_of_lanes(boxes, n)
    }

    /// [`PacketSlab::children_of`] in x86-64-v3's own instructions, with
    /// fewer products where the packet's inverse directions share a sign
    /// on an axis (as the rays of a coherent packet mostly do on all
    /// three). With `i > 0` throughout, `fl(a·i)` never decreases as `a`
    /// or `i` grows for `a ≥ 0`, and as `a` grows or `i` falls for `a < 0`
    /// (rounding keeps order), so the least of the four corner products
    /// is `a₀·i_lo` where `a₀ ≥ 0`, else `a₀·i_hi`, and the greatest is
    /// `a₁·i_hi` where `a₁ ≥ 0`, else `a₁·i_lo`; with `i < 0` throughout,
    /// the least is `a₁·i_lo` or `a₁·i_hi` and the greatest `a₀·i_hi` or
    /// `a₀·i_lo`, by the same signs. `blendv` chooses by the sign bit, so
    /// an offset of `−0` takes its negative branch, whose product is the
    /// same `−0`. The chosen product equals the `min` (or `max`) of the
    /// four, up to the sign of a zero, which no later `min`, `max`,
    /// product or comparison tells apart: the mask is the lane form's.
    /// Axes whose signs are mixed take all four products, as the lane form
    /// does. Test `both_children_forms_agree`.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn children_of_v3(&self, v3: pulp::x86::V3, n: &Node) -> u32 {
        use std::arch::x86_64::{__m256, _CMP_LE_OQ};
        let avx = v3.avx;
        let planes = n.planes();
        let mut lo_t = avx._mm256_setzero_ps();
        let mut hi_t = avx._mm256_setzero_ps();
        for axis in 0..3 {
            let min_p: __m256 = bytemuck::cast(planes[2 * axis]);
            let max_p: __m256 = bytemuck::cast(planes[2 * axis + 1]);
            let inv = self.inv_range[axis];
            let (t0_least, t0_most) = plane_bounds(v3, min_p, self.lo_range[axis], inv);
            let (t1_least, t1_most) = plane_bounds(v3, max_p, self.hi_range[axis], inv);
            let near = avx._mm256_min_ps(t0_least, t1_least);
            let far = avx._mm256_max_ps(t0_most, t1_most);
            if axis == 0 {
                lo_t = near;
                hi_t = far;
            } else {
                lo_t = avx._mm256_max_ps(lo_t, near);
                hi_t = avx._mm256_min_ps(hi_t, far);
            }
        }
        let tn = avx._mm256_max_ps(lo_t, avx._mm256_set1_ps(self.t_min_least));
        let tf = avx._mm256_min_ps(
            avx._mm256_mul_ps(hi_t, avx._mm256_set1_ps(Slab::GROW)),
            avx._mm256_set1_ps(self.far_most),
        );
        let le = avx._mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf);
        #[expect(clippy::cast_sign_loss, reason = "eight mask bits")]
        let mask = avx._mm256_movemask_ps(le) as u32;
        mask & n.used
    }

    /// [`PacketSlab::children_of`] lane by lane, for the vectoriser.
    #[inline(always)]
    fn children_of_lanes(&self, boxes: Boxes, n: &Node) -> u32 {
        let mut lo_t = [0.0f32; WIDTH];
        let mut hi_t = [0.0f32; WIDTH];
        let planes = [
            (&n.min_x, &n.max_x),
            (&n.min_y, &n.max_y),
            (&n.min_z, &n.max_z),
        ];
        for (axis, (min_p, max_p)) in planes.into_iter().enumerate() {
            let (o0_lo, o0_hi) = self.lo_range[axis];
            let (o1_lo, o1_hi) = self.hi_range[axis];
            let (i_lo, i_hi) = self.inv_range[axis];
            for k in 0..WIDTH {
                let (a0, a1) = (min_p[k] - o0_hi, min_p[k] - o0_lo);
                let (c0, c1) = (max_p[k] - o1_hi, max_p[k] - o1_lo);
                let (p, q, r, s) = (a0 * i_lo, a0 * i_hi, a1 * i_lo, a1 * i_hi);
                let t0_least = lane_min(lane_min(p, q), lane_min(r, s));
                let t0_most = lane_max(lane_max(p, q), lane_max(r, s));
                let (p, q, r, s) = (c0 * i_lo, c0 * i_hi, c1 * i_lo, c1 * i_hi);
                let t1_least = lane_min(lane_min(p, q), lane_min(r, s));
                let t1_most = lane_max(lane_max(p, q), lane_max(r, s));
                let near = lane_min(t0_least, t1_least);
                let far = lane_max(t0_most, t1_most);
                if axis == 0 {
                    lo_t[k] = near;
                    hi_t[k] = far;
                } else {
                    lo_t[k] = lane_max(lo_t[k], near);
                    hi_t[k] = lane_min(hi_t[k], far);
                }
            }
        }
        let mut tn = [0.0f32; WIDTH];
        let mut tf = [0.0f32; WIDTH];
        for k in 0..WIDTH {
            tn[k] = lane_max(lo_t[k], self.t_min_least);
            tf[k] = lane_min(hi_t[k] * Slab::GROW, self.far_most);
        }
        boxes.le_mask(tn, tf) & n.used
    }

    /// The rays (a bit each) that enter child `k` of `n`, and each ray's
    /// `t_near` of it: lane `r` is exactly ray `r`'s [`Slab::test_lanes`]
    /// of that child with its `far` (the same operations on the same
    /// operands).
    #[inline(always)]
    fn rays_in(&self, boxes: Boxes, n: &Node, k: usize) -> (u32, [f32; PACKET]) {
        let (bx0, bx1, by0, by1, bz0, bz1) = (
            n.min_x[k], n.max_x[k], n.min_y[k], n.max_y[k], n.min_z[k], n.max_z[k],
        );
        let mut tn = [0.0f32; PACKET];
        let mut tf = [0.0f32; PACKET];
        for r in 0..PACKET {
            let tx0 = (bx0 - self.lo[0][r]) * self.inv[0][r];
            let tx1 = (bx1 - self.hi[0][r]) * self.inv[0][r];
            let ty0 = (by0 - self.lo[1][r]) * self.inv[1][r];
            let ty1 = (by1 - self.hi[1][r]) * self.inv[1][r];
            let tz0 = (bz0 - self.lo[2][r]) * self.inv[2][r];
            let tz1 = (bz1 - self.hi[2][r]) * self.inv[2][r];
            tn[r] = lane_max(
                lane_max(
                    lane_max(lane_min(tx0, tx1), lane_min(ty0, ty1)),
                    lane_min(tz0, tz1),
                ),
                self.t_min[r],
            );
            let f = lane_min(
                lane_min(lane_max(tx0, tx1), lane_max(ty0, ty1)),
                lane_max(tz0, tz1),
            ) * Slab::GROW;
            tf[r] = lane_min(f, self.far[r]);
        }
        (boxes.le_mask(tn, tf), tn)
    }

    /// Takes the rays' current bounds (a closest-hit walk shrinks them).
    #[inline(always)]
    fn set_bounds(&mut self, t_max: &[f32; PACKET]) {
        for (f, t) in self.far.iter_mut().zip(t_max) {
            *f = t * Slab::GROW;
        }
        self.far_most = self.far.iter().fold(f32::NEG_INFINITY, |a, &f| a.max(f));
    }
}

/// Whether a leaf of several packs (its box `leaf`, its packs' boxes
/// `packs`) is better split into a lane per pack, by the surface-area
/// estimate of a ray's work once it reaches the node: whole, every ray
/// that enters the leaf's box tests every pack and pays one leaf visit;
/// split, a ray pays a pack test and a visit for each pack box it enters.
/// A visit (the lane's stack entry, the leaf's loop) is taken as a quarter
/// of a pack test (about 50 against 200 instructions in the shadow walk's
/// profile). Packs as large as the leaf (a scene's few huge triangles)
/// stay together: their boxes would cull nothing and cost a visit each.
fn split_pays(leaf: &Aabb, packs: &[Aabb]) -> bool {
    const VISIT: f32 = 0.25;
    let half_area = |b: &Aabb| {
        let e = b.extent();
        e.x * e.y + e.y * e.z + e.z * e.x
    };
    #[expect(clippy::cast_precision_loss, reason = "a few packs")]
    let whole = half_area(leaf) * (packs.len() as f32 + VISIT);
    let split: f32 = packs.iter().map(|b| half_area(b) * (1.0 + VISIT)).sum();
    split < whole
}

fn empty_node() -> Node {
    let inf = [f32::INFINITY; WIDTH];
    Node {
        min_x: inf,
        max_x: inf,
        min_y: inf,
        max_y: inf,
        min_z: inf,
        max_z: inf,
        child: [EMPTY; WIDTH],
        used: 0,
        pad: [0; 7],
    }
}

fn set_lane(n: &mut Node, k: usize, b: Aabb) {
    n.min_x[k] = b.min.x;
    n.max_x[k] = b.max.x;
    n.min_y[k] = b.min.y;
    n.max_y[k] = b.max.y;
    n.min_z[k] = b.min.z;
    n.max_z[k] = b.max.z;
}

#[cfg(test)]
mod tests {
    //! The tree's invariants on generated triangle soups, and its hits
    //! against a linear scan of the same triangle test: the contract the
    //! module comment states ("exactly the hits a linear scan finds").
    use super::*;
    use proptest::prelude::*;
    use rendiff_core::math::DVec3;

    /// A deterministic soup: `n` triangles of size ~`size` in a unit cube,
    /// with a few long thin ones and exact duplicates mixed in (ties).
    /// 40 rays in 4×2 blocks of a fan around `d` from `o` (spread
    /// `spread`), every 7th from a second origin, every 5th starting at
    /// t = 0.3 and every 3rd with a short bound: packets whose rays diverge
    /// and whose bounds differ.
    fn packet_fan(o: DVec3, d: DVec3, spread: f64) -> Vec<Ray64> {
        (0..40u32)
            .map(|k| {
                let jitter =
                    DVec3::new(f64::from(k % 4), f64::from(k / 4 % 2), f64::from(k / 8)) * spread;
                Ray64 {
                    origin: if k % 7 == 6 {
                        DVec3::new(o.y, o.z, o.x)
                    } else {
                        o
                    },
                    dir: (d + jitter).normalize(),
                    t_min: if k % 5 == 4 { 0.3 } else { 0.0 },
                    t_max: if k % 3 == 2 {
                        0.5 + f64::from(k) * 0.01
                    } else {
                        f64::INFINITY
                    },
                }
            })
            .collect()
    }

    /// One step of a xorshift64 stream (state non-zero).
    fn xorshift_step(s: &mut u64) -> u64 {
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        *s
    }

    /// A xorshift64 stream from `seed` (non-zero): the generated cases of
    /// the tests below.
    fn xorshift(mut s: u64) -> impl FnMut() -> u64 {
        move || xorshift_step(&mut s)
    }

    /// The draws of the node tests' generated cases, from two xorshift64
    /// streams.
    struct Draws {
        bits: u64,
        other: u64,
    }

    impl Draws {
        /// 24 random bits as a float in [0, 1).
        fn unit(&mut self) -> f32 {
            #[expect(clippy::cast_precision_loss, reason = "24 random bits: exact")]
            let u = (xorshift_step(&mut self.bits) >> 40) as f32 / (1u64 << 24) as f32;
            u
        }

        /// One of `n` choices.
        fn choice(&mut self, n: u64) -> u64 {
            (xorshift_step(&mut self.other) >> 32) % n
        }

        /// A point whose coordinates `coord` makes of a unit draw and one of
        /// eight choices.
        fn point(&mut self, coord: impl Fn(f32, u64) -> f32) -> Vec3 {
            let mut c = || {
                let u = self.unit();
                coord(u, self.choice(8))
            };
            Vec3::new(c(), c(), c())
        }

        /// A direction whose components are ±0, ±10⁻³¹ (replaced in a
        /// slab) or anywhere in [-1, 1).
        fn direction(&mut self) -> DVec3 {
            let mut c = || {
                let u = self.unit();
                f64::from(match self.choice(10) {
                    0 => 0.0,
                    1 => -0.0,
                    2 => 1e-31,
                    3 => -1e-31,
                    _ => u * 2.0 - 1.0,
                })
            };
            DVec3::new(c(), c(), c())
        }

        /// A node whose slots are boxes between two points of `coord`, 15 %
        /// of them empty, 20 % of the rest flat on axis `flat`.
        fn node(&mut self, coord: impl Fn(f32, u64) -> f32 + Copy, flat: usize) -> Node {
            let mut n = empty_node();
            for k in 0..WIDTH {
                if self.unit() < 0.15 {
                    continue;
                }
                let a = self.point(coord);
                let mut b = self.point(coord);
                if self.unit() < 0.2 {
                    b[flat] = a[flat];
                }
                set_lane(&mut n, k, Aabb::from_min_max(a.min(b), a.max(b)));
                n.used |= 1 << k;
            }
            n
        }
    }

    /// [`Boxes::le_mask`]'s two forms give the same mask on every kind of
    /// lane: equal values, ±0, ±∞, NaN on either side, subnormals and
    /// generated values (the packet tests compare each form only with
    /// itself, so a wrong predicate in one would cancel out there).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn both_mask_forms_agree() {
        let pulp::Arch::V3(v3) = pulp::Arch::new() else {
            return;
        };
        let (wide, lanes) = (Boxes::of(v3), Boxes::of(pulp::Scalar::new()));
        assert!(wide.is_wide() && !lanes.is_wide());
        let special = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::MIN_POSITIVE / 4.0,
            f32::MAX,
            1.0 + f32::EPSILON,
        ];
        let mut pick = xorshift(0x1234_5678_9ABC_DEF1);
        let mut seen = [0u32; 2];
        for case in 0..100_000u32 {
            let mut value = || {
                let r = pick();
                let k = usize::from((r % 16) as u8);
                #[expect(clippy::cast_precision_loss, reason = "a few random bits")]
                let v = ((r >> 40) % 5) as f32 - 2.0;
                if k < special.len() { special[k] } else { v }
            };
            let a: [f32; WIDTH] = std::array::from_fn(|_| value());
            let b: [f32; WIDTH] = std::array::from_fn(|_| value());
            let (m, l) = (wide.le_mask(a, b), lanes.le_mask(a, b));
            assert_eq!(m, l, "case {case}: {a:?} <= {b:?}");
            seen[0] |= m;
            seen[1] |= !m & 0xFF;
        }
        assert_eq!(seen, [0xFF, 0xFF], "every lane both set and clear");
    }

    /// `Slab::test_v3` (x86-64-v3, where this machine has it) against
    /// `Slab::test_lanes` on nodes and rays generated to hit their edge
    /// cases: boxes flat on an axis, boxes whose planes pass through the
    /// origin or sit on a ray's `t_min`, empty slots, direction components
    /// of ±0, below 10⁻³⁰ and of either sign, origins off the `f64` ray's
    /// (inflated slabs), bounds from 0 to +∞. The walk reads a test's
    /// `t_near` only through comparisons, so the two must give the same
    /// mask and, in its lanes, `t_near` equal as numbers.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn both_node_tests_decide_alike() {
        let pulp::Arch::V3(v3) = pulp::Arch::new() else {
            return;
        };
        let mut draw = Draws {
            bits: 0x2545_F491_4F6C_DD1D,
            other: 0x9E37_79B9_7F4A_7C15,
        };
        // A coordinate: mostly in [-2, 2), sometimes exactly 0, ±1.
        let coord = |u: f32, c: u64| match c {
            0 => 0.0,
            1 => 1.0,
            2 => -1.0,
            _ => u * 4.0 - 2.0,
        };
        let mut masks = 0u32;
        for case in 0..200_000u32 {
            let n = draw.node(coord, 1);
            let dir = draw.direction();
            let dir = if dir == DVec3::ZERO { DVec3::X } else { dir };
            // An origin that is not an `f32` point half the time (the
            // `f32` ray strays from it: inflated slabs).
            let jitter = if case % 2 == 0 { 1e-9 } else { 0.0 };
            let origin = to_f64(draw.point(coord)) + DVec3::new(jitter, 0.0, -jitter);
            let ray = Ray64 {
                origin,
                dir,
                t_min: if case % 3 == 0 {
                    f64::from(draw.unit())
                } else {
                    0.0
                },
                t_max: f64::INFINITY,
            };
            let walk = WalkRay::new(&ray, 10.0);
            let slab = Slab::new(&walk);
            let t_max = match case % 4 {
                0 => f32::INFINITY,
                1 => 0.0,
                _ => draw.unit() * 4.0,
            };
            let (lanes, lanes_tn) = slab.test_lanes(Boxes::of(pulp::Scalar::new()), &n, t_max);
            let (wide, wide_tn) = slab.test_v3(v3, &Planes::of(&slab), &n, t_max);
            assert_eq!(lanes, wide, "case {case}: masks differ");
            for k in (0..WIDTH).filter(|&k| lanes & 1 << k != 0) {
                assert!(
                    lanes_tn[k] == wide_tn[k],
                    "case {case}, lane {k}: t_near {} against {}",
                    lanes_tn[k],
                    wide_tn[k]
                );
            }
            masks |= lanes;
        }
        assert_eq!(masks, 0xFF, "every lane entered somewhere");
    }

    /// The packet node test in x86-64-v3's instructions
    /// (`PacketSlab::children_of_v3`, two products a plane where the
    /// packet's inverse directions share a sign on the axis) gives the
    /// lane form's mask: packets whose rays share every sign, share some,
    /// or none; directions with ±0 and sub-10⁻³⁰ components (replaced in
    /// the slab); origins and planes on one grid of values, so that
    /// offsets are exactly ±0; a packet's origins together or apart (a
    /// plane between them); origins off the `f32` grid (inflated
    /// slabs); packets whose rays all hold a NaN origin coordinate (empty
    /// ranges); flat boxes and empty slots;
    /// `t_min` above 0 and short walks. (Choosing the greatest by the wrong offset's sign, or
    /// swapping `i_lo` and `i_hi` in a branch, fails it. The least's
    /// choice differs only where an offset is negative, so both choices
    /// are negative, and `t_min`, never negative, hides them.)
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn both_children_forms_agree() {
        let pulp::Arch::V3(v3) = pulp::Arch::new() else {
            return;
        };
        let mut draw = Draws {
            bits: 0x51A7_C0DE_2026_1207,
            other: 0x0DDB_A11C_AFE5_EED5,
        };
        // A coordinate on a coarse grid (offsets of exactly ±0), or anywhere.
        let coord = |u: f32, c: u64| match c {
            0 => -1.0,
            1 => -0.5,
            2 => 0.0,
            3 => 0.5,
            _ => u * 4.0 - 2.0,
        };
        let (mut seen, mut one_sign, mut mixed) = (0u32, 0u32, 0u32);
        for case in 0..100_000u32 {
            let n = draw.node(coord, 2);
            // A packet: one base direction and origin; each ray strays from
            // them a little (coherent: the signs mostly shared), or is
            // drawn anew (the signs mixed).
            let base = draw.direction();
            let o = to_f64(draw.point(coord));
            let spread = [0.0, 1e-3, 0.1, 2.0][(case % 4) as usize];
            let slabs: [Slab; PACKET] = std::array::from_fn(|r| {
                let stray = DVec3::new(
                    f64::from(draw.unit() - 0.5),
                    f64::from(draw.unit() - 0.5),
                    f64::from(draw.unit() - 0.5),
                ) * spread;
                let dir = if r % 3 == 2 { base } else { base + stray };
                let dir = if dir == DVec3::ZERO { DVec3::Y } else { dir };
                let jitter = if case % 2 == 0 { 1e-9 } else { 0.0 };
                // Origins apart (as shadow rays' are), so that a plane can
                // lie between the packet's least and greatest origin.
                let apart = if case % 3 == 0 {
                    to_f64(draw.point(coord)) * 0.5
                } else {
                    DVec3::ZERO
                };
                let mut origin = o
                    + apart
                    + DVec3::new(jitter, 0.0, -jitter) * u32::try_from(r).map_or(0.0, f64::from);
                // Packets whose rays all hold a NaN origin coordinate (the
                // ranges' folds skip NaN: an empty range there). (Not a
                // NaN direction: `Slab::new` asserts against it.)
                if case % 89 == 0 {
                    origin.y = f64::NAN;
                }
                let ray = Ray64 {
                    origin,
                    dir,
                    t_min: if case % 5 == 0 {
                        f64::from(draw.unit())
                    } else {
                        0.0
                    },
                    t_max: f64::INFINITY,
                };
                Slab::new(&WalkRay::new(&ray, 10.0))
            });
            let t_max: [f32; PACKET] = std::array::from_fn(|_| match draw.choice(4) {
                0 => f32::INFINITY,
                1 => 0.0,
                _ => draw.unit() * 4.0,
            });
            let wide = PacketSlab::new(&slabs, &t_max);
            let lanes = wide.children_of_lanes(Boxes::of(pulp::Scalar::new()), &n);
            let v3_mask = wide.children_of_v3(v3, &n);
            assert_eq!(lanes, v3_mask, "case {case}: masks differ");
            for (lo, hi) in wide.inv_range {
                if lo > 0.0 || hi < 0.0 {
                    one_sign += 1;
                } else {
                    mixed += 1;
                }
            }
            seen |= lanes;
        }
        assert_eq!(seen, 0xFF, "every lane entered somewhere");
        assert!(
            one_sign > 50_000 && mixed > 50_000,
            "{one_sign} one-sign axes, {mixed} mixed"
        );
    }

    fn soup(n: usize, seed: u64, size: f32) -> Vec<[Vec3; 3]> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            #[expect(clippy::cast_precision_loss, reason = "24 random bits: exact in f32")]
            let v = (s >> 40) as f32 / (1u64 << 24) as f32;
            v
        };
        let mut out: Vec<[Vec3; 3]> = Vec::with_capacity(n);
        for k in 0..n {
            if k % 17 == 16 {
                let dup = out[k / 2];
                out.push(dup);
                continue;
            }
            let c = Vec3::new(next(), next(), next());
            let stretch = if k % 11 == 0 { 20.0 } else { 1.0 };
            let mut corner =
                || c + Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * size * stretch;
            out.push([corner(), corner(), corner()]);
        }
        out
    }

    /// Rays lying in the planes of box faces, with components exactly
    /// zero (of either sign): every walk meets exactly the triangles the
    /// `f64` test meets, as for any other ray. Triangles with corners on a
    /// unit lattice (so boxes end on lattice planes), in every
    /// orientation; rays from lattice points along the axes and the
    /// diagonals of the axis planes. Before `WalkRay` counted the slab
    /// direction's tiny components in its drift, a ray along +x at y = 0
    /// missed a triangle below it whose edge lies at y = 0 (its box ends
    /// there; the slab left it at t = 0), though the `f64` test meets that
    /// edge: the walks then disagreed with the flat loop.
    #[test]
    fn rays_in_box_faces_meet_what_the_test_meets() {
        let mut tris: Vec<[Vec3; 3]> = Vec::new();
        let p = |x: i16, y: i16, z: i16| Vec3::new(f32::from(x), f32::from(y), f32::from(z));
        for i in 0..4i16 {
            for j in 0..4i16 {
                let (x, y) = (2 * i - 3, 2 * j - 3);
                // Below, above and across the planes through the lattice.
                tris.push([p(x, y, 0), p(x + 1, y, 0), p(x, y - 1, 1)]);
                tris.push([p(x, y, 2), p(x, y + 1, 2), p(x - 1, y, 3)]);
                tris.push([p(x, 0, y), p(x + 1, 1, y), p(x, 1, y + 1)]);
                tris.push([p(0, x, y), p(1, x, y + 1), p(0, x + 1, y + 1)]);
            }
        }
        let zeros = [0.0, -0.0];
        let mut dirs = Vec::new();
        for a in [1.0f64, -1.0] {
            for z0 in zeros {
                for z1 in zeros {
                    dirs.push(DVec3::new(a, z0, z1));
                    dirs.push(DVec3::new(z0, a, z1));
                    dirs.push(DVec3::new(z0, z1, a));
                    for b in [1.0f64, -1.0] {
                        let h = std::f64::consts::FRAC_1_SQRT_2;
                        dirs.push(DVec3::new(a * h, b * h, z0));
                        dirs.push(DVec3::new(a * h, z0, b * h));
                        dirs.push(DVec3::new(z0, a * h, b * h));
                    }
                }
            }
        }
        let mut trees = [
            build(&tris, false),
            build_tree(&tris, Tree::Morton),
            build(&tris, true),
        ];
        let (mut rays, mut met) = (0, 0);
        // Every ray with its closest hit and whether it meets anything,
        // for the packet walks below.
        type Case = (Ray64, Option<(u32, f64)>, bool);
        let mut cases: Vec<Case> = Vec::new();
        for x in -5..=5 {
            for y in -5..=5 {
                for z in [-1, 0, 1, 2, 3] {
                    for &dir in &dirs {
                        let ray = Ray64 {
                            origin: DVec3::new(f64::from(x), f64::from(y), f64::from(z)),
                            dir,
                            t_min: 0.0,
                            t_max: f64::INFINITY,
                        };
                        let pre = RayPrecomp::new(&ray, f64::INFINITY);
                        let every: Vec<u32> = (0..u32::try_from(tris.len()).unwrap())
                            .filter(|&id| {
                                intersect(
                                    &pre,
                                    pre.shear64(),
                                    &tris[id as usize],
                                    0.0,
                                    f64::INFINITY,
                                )
                                .is_some()
                            })
                            .collect();
                        let want = linear(&tris, &ray, trees[0].reach(&ray));
                        for bvh in &trees {
                            let mut all = Vec::new();
                            bvh.for_each_hit(&ray, NO_SKIP, |id, _| {
                                all.push(id);
                                false
                            });
                            all.sort_unstable();
                            assert_eq!(all, every, "{ray:?}");
                            assert_eq!(bvh.intersect(&ray).map(|h| (h.id, h.t64)), want, "{ray:?}");
                        }
                        rays += 1;
                        met += usize::from(!every.is_empty());
                        cases.push((ray, want, !every.is_empty()));
                    }
                }
            }
        }
        // The packet walks, on both instruction sets: the same answers.
        for bvh in &mut trees {
            for path in [SimdPath::Auto, SimdPath::Baseline] {
                bvh.set_simd(path);
                for chunk in cases.chunks(PACKET) {
                    let rays: Vec<Ray64> = chunk.iter().map(|c| c.0).collect();
                    let mut hits = vec![None; rays.len()];
                    bvh.intersect_packet(&rays, &mut hits);
                    let mut any = vec![false; rays.len()];
                    bvh.any_packet(&rays, &vec![NO_SKIP; rays.len()], |_, _, _| true, &mut any);
                    for ((c, h), a) in chunk.iter().zip(&hits).zip(&any) {
                        assert_eq!(h.map(|h| (h.id, h.t64)), c.1, "{:?}", c.0);
                        assert_eq!(*a, c.2, "{:?}", c.0);
                    }
                }
            }
        }
        // Many rays meet an edge or a corner lying in a box's face.
        assert!(met > rays / 10, "{met} of {rays} rays meet something");
    }

    fn build(tris: &[[Vec3; 3]], flat: bool) -> Bvh {
        build_tree(tris, if flat { Tree::Flat } else { Tree::Sah })
    }

    /// The parallel partition leaves exactly the order (and the bounds)
    /// the two-cursor pass leaves, for predicates that split by position
    /// (as the SAH's do), at random, and with a few elements on one side;
    /// on 1 and 4 threads.
    #[test]
    fn the_parallel_partition_is_the_two_cursor_pass() {
        let tris = soup(200_000, 3, 0.01);
        let prims: Vec<PrimRef> = tris
            .iter()
            .enumerate()
            .map(|(k, t)| prim_ref(k, *t))
            .collect();
        let bits = |b: &(Box4, Box4)| {
            [b.0.lo, b.0.hi, b.1.lo, b.1.hi].map(|v| v.to_array().map(f32::to_bits))
        };
        let preds: [&(dyn Fn(&PrimRef) -> bool + Sync); 4] = [
            &|p| p.centroid2().x < 1.0,
            &|p| p.index().wrapping_mul(2_654_435_761) >> 31 == 0,
            &|p| p.index() % 50_000 == 7,
            &|p| p.index() % 50_000 != 7,
        ];
        // Bounds taken in two orders agree once their zeros are unsigned
        // (with SSE's `minps`, min(+0, −0) is −0 and min(−0, +0) is +0).
        let plus = prim_ref(0, [Vec3::new(0.0, 1.0, 1.0); 3]);
        let minus = prim_ref(1, [Vec3::new(-0.0, 1.0, 1.0); 3]);
        let (ab, ba) = (bounds_of(&[plus, minus]), bounds_of(&[minus, plus]));
        let (ab, ba) = (unsigned_zeros(ab), unsigned_zeros(ba));
        assert_eq!(bits(&ab), bits(&ba));
        assert_eq!(ab.0.lo.x.to_bits(), 0, "+0");
        for (i, pred) in preds.iter().enumerate() {
            let mut want = prims.clone();
            let (mid, l, r) = partition(&mut want, pred);
            for threads in [1, 4] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut got = prims.clone();
                let (m, gl, gr) = pool.install(|| par_partition(&mut got, pred));
                assert_eq!(m, mid, "predicate {i}, {threads} threads");
                let order = |v: &[PrimRef]| v.iter().map(PrimRef::index).collect::<Vec<_>>();
                assert!(
                    order(&got) == order(&want),
                    "predicate {i}, {threads} threads: order"
                );
                assert_eq!(
                    (bits(&gl), bits(&gr)),
                    (bits(&l), bits(&r)),
                    "predicate {i}"
                );
            }
        }
    }

    /// Every bit of a built tree: nodes, packs, ids, root and depth.
    fn tree_bits(bvh: &Bvh) -> Vec<u32> {
        let mut out = vec![bvh.root, bvh.root_count, bvh.depth];
        for n in &bvh.nodes {
            for a in [n.min_x, n.max_x, n.min_y, n.max_y, n.min_z, n.max_z] {
                out.extend(a.iter().map(|x| x.to_bits()));
            }
            out.extend_from_slice(&n.child);
            out.push(n.used);
        }
        for p in &bvh.packs {
            for c in &p.v {
                for axis in c {
                    out.extend(axis.to_array().iter().map(|x| x.to_bits()));
                }
            }
            out.push(p.lanes);
            out.push(p.last);
        }
        out.extend_from_slice(&bvh.ids);
        out
    }

    /// The build's parallel passes (the boxes and their bounds, the
    /// Morton codes, the partitions, the collapse into 8-wide nodes that
    /// fills its subtrees' places in parallel, the codes' sort) give the same tree, bit
    /// for bit, on 1, 2, 3 and 8 threads, for both builds: the images'
    /// thread invariance rests on it. 70 000 triangles put every parallel
    /// path to work (they start above 4 096 triangles or 1 024 packs; the
    /// Morton codes' parallel sort above 65 536 keys on 4 threads or more).
    #[test]
    fn the_tree_is_the_same_at_every_thread_count() {
        // A plain soup, and one with a third of its x coordinates exactly
        // +0 or −0 (a mesh on a plane through the origin, mirrored): the
        // bounds that the serial and the parallel passes take in different
        // orders may differ only in a zero's sign, which must not reach
        // the tree.
        let plain = soup(70_000, 7, 0.01);
        let mut zeros = soup(70_000, 9, 0.01);
        for (k, t) in zeros.iter_mut().enumerate() {
            for (c, v) in t.iter_mut().enumerate() {
                if (k + c) % 3 == 0 {
                    v.x = if (k + c) % 2 == 0 { 0.0 } else { -0.0 };
                }
            }
        }
        for (tris, tree) in [
            (&plain, Tree::Sah),
            (&plain, Tree::Morton),
            (&zeros, Tree::Sah),
            (&zeros, Tree::Morton),
        ] {
            let at = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| tree_bits(&build_tree(tris, tree)))
            };
            let one = at(1);
            assert!(one.len() > 100_000, "{tree:?}: a tree of many nodes");
            for threads in [2, 3, 8] {
                assert!(at(threads) == one, "{tree:?} differs on {threads} threads");
            }
        }
    }

    fn build_tree(tris: &[[Vec3; 3]], tree: Tree) -> Bvh {
        let ids: Vec<u32> = (0..u32::try_from(tris.len()).unwrap()).collect();
        Bvh::build(&ids, |id| tris[id as usize], tree)
    }

    /// The closest hit by testing every triangle (ties to the lower id).
    fn linear(tris: &[[Vec3; 3]], ray: &Ray64, reach: f64) -> Option<(u32, f64)> {
        let pre = RayPrecomp::new(ray, reach);
        let (t_min, t_max) = (ray.t_min, ray.t_max);
        let mut best: Option<(u32, f64)> = None;
        for (id, v) in tris.iter().enumerate() {
            if let Some(h) = intersect(&pre, pre.shear64(), v, t_min, t_max) {
                let id = u32::try_from(id).unwrap();
                if best.is_none_or(|(_, t)| h.t64 < t) {
                    best = Some((id, h.t64));
                }
            }
        }
        best
    }

    /// Every triangle sits in exactly one lane, every child box contains
    /// the triangles below it, and no leaf is longer than `MAX_LEAF`
    /// triangles.
    fn check_structure(bvh: &Bvh, tris: &[[Vec3; 3]]) {
        fn below(bvh: &Bvh, c: u32, leaf_ids: &dyn Fn(u32) -> Vec<u32>, out: &mut Vec<u32>) {
            if c & LEAF != 0 {
                out.extend(leaf_ids(c));
                return;
            }
            let n = &bvh.nodes[c as usize];
            for k in 0..WIDTH {
                if n.used & (1 << k) != 0 {
                    below(bvh, n.child[k], leaf_ids, out);
                }
            }
        }
        let mut seen = vec![0u32; tris.len()];
        for &id in bvh.ids.iter().filter(|&&id| id != u32::MAX) {
            seen[id as usize] += 1;
        }
        assert!(
            seen.iter().all(|&c| c == 1),
            "a triangle is missing or duplicated"
        );
        let leaf_ids = |first: u32| {
            let mut out = Vec::new();
            let mut p = (first & !LEAF) as usize;
            loop {
                let pack = &bvh.packs[p];
                for lane in 0..pack.lanes as usize {
                    out.push(bvh.ids[4 * p + lane]);
                }
                if pack.ends_leaf() {
                    return out;
                }
                p += 1;
            }
        };
        for n in &bvh.nodes {
            for k in 0..WIDTH {
                if n.used & (1 << k) == 0 {
                    assert_eq!(n.child[k], EMPTY, "an unused slot names a child");
                    continue;
                }
                let lo = Vec3::new(n.min_x[k], n.min_y[k], n.min_z[k]);
                let hi = Vec3::new(n.max_x[k], n.max_y[k], n.max_z[k]);
                if n.child[k] & LEAF != 0 {
                    let len = leaf_ids(n.child[k]).len();
                    assert!(len <= MAX_LEAF, "leaf too long");
                    // A leaf keeps several packs behind one box only where
                    // the node lacks the lanes to give each its own, or
                    // where its packs' boxes would not pay.
                    let free = WIDTH - n.used.count_ones() as usize;
                    let ids = leaf_ids(n.child[k]);
                    let boxes: Vec<Aabb> = ids
                        .chunks(4)
                        .map(|p| {
                            p.iter().fold(Aabb::EMPTY, |b, &id| {
                                b.union(Aabb::from_points(tris[id as usize]))
                            })
                        })
                        .collect();
                    let lane_box = Aabb::from_min_max(lo, hi);
                    assert!(
                        len <= 4 || len.div_ceil(4) - 1 > free || !split_pays(&lane_box, &boxes),
                        "a leaf of {len} triangles shares a box beside {free} free lanes"
                    );
                }
                let mut ids = Vec::new();
                below(bvh, n.child[k], &leaf_ids, &mut ids);
                for id in ids {
                    for p in tris[id as usize] {
                        assert!(
                            p.cmpge(lo).all() && p.cmple(hi).all(),
                            "box misses triangle {id}"
                        );
                    }
                }
            }
        }
    }

    /// A primitive's index rides in the `w` lane of its box as a normal
    /// float: the lane, the centroid's, and the difference of two
    /// neighbours' centroids (the smallest the bins' arithmetic forms) are
    /// never subnormal, whose operations take the processor's slow path
    /// (see `INDEX_BIAS`); and the index comes back exactly. With the
    /// index's own bits every index from 1 to 2²³ − 1 fails.
    #[test]
    fn primitive_indices_are_normal_floats() {
        let tri = [
            Vec3::new(-1.0, 0.0, 2.0),
            Vec3::new(3.0, -0.5, 2.0),
            Vec3::new(0.0, 4.0, -1.0),
        ];
        let not_subnormal = |v: f32| v == 0.0 || v.is_normal();
        for k in [
            0usize,
            1,
            2,
            7,
            1000,
            (1 << 23) - 1,
            1 << 23,
            10_000_000,
            (1 << 30) - 2,
        ] {
            let (p, q) = (prim_ref(k, tri), prim_ref(k + 1, tri));
            assert_eq!(p.index() as usize, k, "index {k} round trip");
            assert!(p.lo.w.is_normal(), "index {k}: lane {:e}", p.lo.w);
            let (c, d) = (p.centroid2(), q.centroid2());
            assert!(not_subnormal(c.w), "index {k}: centroid lane {:e}", c.w);
            let gap = d.w - c.w;
            assert!(gap.is_normal(), "index {k}: neighbours' gap {gap:e}");
            assert!(not_subnormal((p.hi - p.lo).w), "index {k}: extent lane");
        }
    }

    /// The radix sort orders by code, equal codes by index (the key's lower
    /// half), as a comparison sort of the keys does.
    #[test]
    fn radix_sort_orders_codes_then_indices() {
        let mut z = 0x2545_f491_4f6c_dd1du64;
        let keys: Vec<u64> = (0..5000u64)
            .map(|k| {
                z ^= z << 13;
                z ^= z >> 7;
                z ^= z << 17;
                // 30-bit codes, many repeated (a few distinct values).
                let code = (z >> 34) & 0x3FFF_FFFF & !0x3FFF_FF0F;
                (code << 32) | k
            })
            .collect();
        let mut want = keys.clone();
        want.sort_unstable();
        let mut sorted = Big::from_fn(keys.len(), |k| keys[k]);
        radix_sort_codes(&mut sorted);
        assert_eq!(&*sorted, &want[..]);
        // The parallel sort (four threads or more, more than one run):
        // 300 000 keys, codes over all 30 bits, some repeated.
        let mut keys: Vec<u64> = (0..300_000u64)
            .map(|k| {
                z ^= z << 13;
                z ^= z >> 7;
                z ^= z << 17;
                let code = (z >> 34) & 0x3FFF_FFFF & !(0xFF << (8 * (k % 4)));
                (code << 32) | k
            })
            .collect();
        keys.sort_unstable();
        // (2.4 MB of keys: the serial sort's arrays are mapped ones.)
        for threads in [1, 4] {
            let mut sorted = Big::from_fn(keys.len(), |k| keys[k]);
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| radix_sort_codes(&mut sorted));
            assert!(
                *sorted == keys[..],
                "{threads} threads: the sort orders as a comparison sort"
            );
        }
        assert_eq!(spread3(0b11_1111_1111), 0x0924_9249);
        assert_eq!(spread3(0b10_0000_0001), (1 << 27) | 1);
    }

    /// The transpose of the rays' child masks is the loop over every ray
    /// and child it replaces.
    /// Random packets of eight rays (origins spread over `spread`, some
    /// inflated, directions near one another or not, components near 0,
    /// some short bounds) and random nodes of eight boxes (some around the
    /// origins, some flat, some huge): a node against the whole packet
    /// ([`PacketSlab::children_of`]) keeps every child some ray's own slab
    /// test enters, and one child against every ray
    /// ([`PacketSlab::rays_in`]) is each ray's own test bit for bit.
    #[test]
    fn packet_tests_agree_with_each_rays_slab_test() {
        let lanes = Boxes::of(pulp::Scalar::new());
        let forms = match pulp::Arch::new() {
            #[cfg(target_arch = "x86_64")]
            pulp::Arch::V3(v3) => vec![lanes, Boxes::of(v3)],
            _ => vec![lanes],
        };
        let mut z = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            z ^= z << 13;
            z ^= z >> 7;
            z ^= z << 17;
            #[expect(clippy::cast_precision_loss, reason = "a uniform draw")]
            let u = (z >> 11) as f64 / (1u64 << 53) as f64;
            u
        };
        let mut entered = 0usize;
        let mut kept = 0usize;
        for case in 0..20_000 {
            let spread = [1e-6, 1e-3, 0.1, 10.0][case % 4];
            let base = DVec3::new(next() * 4.0 - 2.0, next() * 4.0 - 2.0, next() * 4.0 - 2.0);
            let dir0 = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            let rays: [Ray64; PACKET] = std::array::from_fn(|_| {
                let jitter = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
                let mut dir = dir0 + jitter * [1e-4, 0.05, 1.0, 3.0][case / 4 % 4];
                if case % 13 == 0 {
                    dir.x = 0.0;
                }
                if case % 17 == 0 {
                    dir.y *= 1e-9;
                }
                let dir = dir.try_normalize().unwrap_or(DVec3::X);
                let o = base + DVec3::new(next(), next(), next()) * spread;
                Ray64 {
                    origin: o,
                    dir,
                    t_min: if case % 5 == 4 { next() } else { 0.0 },
                    t_max: if case % 3 == 2 {
                        next() * 3.0
                    } else {
                        f64::INFINITY
                    },
                }
            });
            let reach = if case % 7 == 0 { 1e3 } else { 0.0 };
            let walks: [WalkRay; PACKET] = std::array::from_fn(|r| {
                WalkRay::new(
                    &rays[r],
                    if reach > 0.0 {
                        reach
                    } else {
                        rays[r].t_max.min(1e3)
                    },
                )
            });
            let slabs: [Slab; PACKET] = std::array::from_fn(|r| Slab::new(&walks[r]));
            let t_max: [f32; PACKET] = std::array::from_fn(|r| walks[r].ray.t_max);
            let wide = PacketSlab::new(&slabs, &t_max);
            let mut n = empty_node();
            #[expect(clippy::cast_possible_truncation, reason = "test boxes in f32")]
            for k in 0..WIDTH {
                let c = match k % 3 {
                    0 => rays[k].origin + rays[k].dir * (next() * 2.0),
                    1 => base + DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * spread * 4.0,
                    _ => DVec3::new(next() * 6.0 - 3.0, next() * 6.0 - 3.0, next() * 6.0 - 3.0),
                };
                let mut h = DVec3::new(next(), next(), next()) * [1e-5, 0.01, 0.5, 4.0][k % 4];
                if k == 5 {
                    h.y = 0.0;
                }
                let (lo, hi) = (c - h, c + h);
                set_lane(
                    &mut n,
                    k,
                    Aabb::from_min_max(
                        Vec3::new(lo.x as f32, lo.y as f32, lo.z as f32),
                        Vec3::new(hi.x as f32, hi.y as f32, hi.z as f32),
                    ),
                );
            }
            n.used = if case % 11 == 0 { 0b1011_0111 } else { 0xFF };
            // Each mask form ([`Boxes::le_mask`]) the machine has.
            for &boxes in &forms {
                let wanted =
                    (0..PACKET).fold(0u32, |m, r| m | slabs[r].test_lanes(boxes, &n, t_max[r]).0);
                let candidates = wide.children_of(boxes, &n);
                assert_eq!(
                    wanted & !candidates,
                    0,
                    "case {case}: a child a ray enters was left out"
                );
                if !boxes.is_wide() {
                    entered += wanted.count_ones() as usize;
                    kept += candidates.count_ones() as usize;
                }
                for k in 0..WIDTH {
                    let (mask, tn) = wide.rays_in(boxes, &n, k);
                    for r in 0..PACKET {
                        let (own, own_tn) = slabs[r].test_lanes(boxes, &n, t_max[r]);
                        if n.used & (1 << k) != 0 {
                            assert_eq!(
                                (mask >> r) & 1,
                                (own >> k) & 1,
                                "case {case}: ray {r}, child {k}"
                            );
                            assert_eq!(tn[r].to_bits(), own_tn[k].to_bits(), "case {case}: t_near");
                        }
                    }
                }
            }
        }
        // The cases are not all trivial: rays enter children, and the
        // packet's bounds leave some out.
        assert!(
            entered > 10_000 && kept < 8 * 20_000,
            "{entered} entered, {kept} kept"
        );
    }

    /// Packets whose rays pair up in the leaves
    /// ([`ClosestLeaf::visit_pair`]) get each ray's single-ray hit bit for
    /// bit (distance, id, barycentrics): a grid of quads split on their
    /// diagonals (rays through shared edges and corners), duplicated
    /// triangles before and after their originals in id order (hits at
    /// equal `t` decided by id), larger coplanar triangles over some
    /// quads (equal `t` on different triangles) and a tilted sheet
    /// through the grid (hits in front of and behind it, so a ray's
    /// `t_max` shrinks between its tests); from an origin where every ray
    /// has the same axis permutation and one where a packet's rays
    /// differ, in both kinds of tree, on both instruction sets.
    #[test]
    fn paired_closest_hits_are_each_rays_own() {
        let mut tris: Vec<[Vec3; 3]> = Vec::new();
        for q in 0..64u8 {
            let (x, y) = (f32::from(q % 8), f32::from(q / 8));
            let p = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, 1.0);
            let lower = [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)];
            let upper = [p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)];
            if q % 3 == 0 {
                tris.push(lower);
            }
            tris.push(lower);
            tris.push(upper);
            if q % 3 == 1 {
                tris.push(upper);
            }
            if q % 4 == 2 {
                tris.push([p(-0.5, -0.5), p(1.5, -0.5), p(0.5, 1.5)]);
            }
            if q % 5 == 0 {
                let s = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, 0.9 + 0.025 * (x + dx));
                tris.push([s(0.0, 0.0), s(1.0, 0.0), s(0.0, 1.0)]);
            }
        }
        let origins = [
            DVec3::new(4.1, 3.9, -3.0),
            DVec3::new(-3.0, 4.0, -3.0),
            DVec3::new(4.0, 4.0, -8.0),
        ];
        let mut hits = 0;
        let (mut differing_axes, mut same_axes) = (0, 0);
        for tree in [Tree::Sah, Tree::Morton] {
            let mut bvh = build_tree(&tris, tree);
            for o in origins {
                // 4×2 blocks of targets on a half-unit lattice: corners,
                // edge midpoints, diagonal midpoints.
                let mut rays = Vec::new();
                for by in (0..18u8).step_by(2) {
                    for bx in (0..20u8).step_by(4) {
                        for j in by..by + 2 {
                            for i in bx..bx + 4 {
                                let t = DVec3::new(f64::from(i) * 0.5, f64::from(j) * 0.5, 1.0);
                                rays.push(Ray64 {
                                    origin: o,
                                    dir: t - o,
                                    t_min: 0.0,
                                    t_max: f64::INFINITY,
                                });
                            }
                        }
                    }
                }
                for path in [SimdPath::Auto, SimdPath::Baseline] {
                    bvh.set_simd(path);
                    for chunk in rays.chunks(PACKET) {
                        let mut got = vec![None; chunk.len()];
                        bvh.intersect_packet(chunk, &mut got);
                        let want: Vec<Option<BvhHit>> =
                            chunk.iter().map(|r| bvh.intersect(r)).collect();
                        // Bit for bit: the `Debug` text tells −0.0 from +0.0,
                        // which `PartialEq` on the floats would not.
                        assert_eq!(
                            format!("{got:?}"),
                            format!("{want:?}"),
                            "{tree:?}, origin {o}"
                        );
                        hits += want.iter().flatten().count();
                        let k = |r: &Ray64| {
                            let walk = WalkRay::new(r, bvh.reach(r));
                            RayPrecomp::of::<false>(r, &walk).k
                        };
                        let mixed = chunk.iter().any(|r| k(r) != k(&chunk[0]));
                        differing_axes += usize::from(mixed);
                        same_axes += usize::from(!mixed && chunk.len() > 1);
                    }
                }
            }
        }
        assert!(hits > 1000, "{hits} hits");
        assert!(differing_axes > 10, "{differing_axes} mixed packets");
        // Packets whose rays can all pair up.
        assert!(same_axes > 100, "{same_axes} packets of one axis order");
    }

    #[test]
    fn rays_by_child_transposes_the_masks() {
        let mut z = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..10_000 {
            z = z
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            // Some rays with no child, some children with no ray.
            let by_ray = z & (z >> 3);
            let mut want = [0u32; WIDTH];
            for r in 0..PACKET {
                let mask = (by_ray >> (8 * r)) & 0xFF;
                for (k, w) in want.iter_mut().enumerate() {
                    *w |= u32::try_from((mask >> k) & 1).unwrap() << r;
                }
            }
            let want_mask = want
                .iter()
                .enumerate()
                .fold(0u32, |acc, (k, &r)| acc | (u32::from(r != 0) << k));
            assert_eq!(rays_by_child(by_ray), (want_mask, want), "{by_ray:#x}");
        }
    }

    #[test]
    fn an_empty_tree_hits_nothing() {
        let bvh = build(&[], false);
        let ray = Ray64 {
            origin: DVec3::ZERO,
            dir: DVec3::X,
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        assert_eq!(bvh.intersect(&ray), None);
        assert_eq!(bvh.stats().triangles, 0);
    }

    #[test]
    fn structure_holds_for_every_size() {
        for n in [1usize, 2, 3, 4, 5, 8, 9, 33, 257, 5000] {
            let tris = soup(n, n as u64, 0.05);
            let bvh = build(&tris, false);
            check_structure(&bvh, &tris);
            assert_eq!(bvh.stats().triangles, n);
            let morton = build_tree(&tris, Tree::Morton);
            check_structure(&morton, &tris);
            assert_eq!(morton.stats().triangles, n);
            // Near the top of the f32 range, where a doubled centroid
            // overflows, beside tiny triangles.
            let mut wide: Vec<[Vec3; 3]> = tris.iter().map(|t| t.map(|v| v * 3e38)).collect();
            wide.extend(tris.iter().take(7).map(|t| t.map(|v| v * 1e-30)));
            check_structure(&build_tree(&wide, Tree::Morton), &wide);
            check_structure(&build_tree(&wide, Tree::Sah), &wide);
            let flat = build(&tris, true);
            assert_eq!(flat.stats().nodes, 0, "the flat loop is one leaf");
        }
    }

    #[test]
    fn coincident_centroids_split_by_median() {
        // 100 copies of one triangle: SAH has no split, the object median
        // keeps the leaves short.
        let tris = vec![[Vec3::ZERO, Vec3::X, Vec3::Y]; 100];
        // (Every Morton code equal: split at the middle.)
        check_structure(&build_tree(&tris, Tree::Morton), &tris);
        let bvh = build(&tris, false);
        check_structure(&bvh, &tris);
        let ray = Ray64 {
            origin: DVec3::new(0.2, 0.2, 1.0),
            dir: -DVec3::Z,
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        let hit = bvh.intersect(&ray).expect("the ray meets the stack");
        assert_eq!(hit.id, 0, "a tie goes to the lowest id");
        let mut count = 0;
        bvh.for_each_hit(&ray, NO_SKIP, |_, _| {
            count += 1;
            false
        });
        assert_eq!(count, 100);
        // The skipped triangle alone is not visited.
        let mut ids = Vec::new();
        bvh.for_each_hit(&ray, 7, |id, _| {
            ids.push(id);
            false
        });
        ids.sort_unstable();
        assert_eq!(ids, (0..100).filter(|&id| id != 7).collect::<Vec<u32>>());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn closest_hit_equals_the_linear_scan(
            seed in 0u64..1000,
            n in 1usize..400,
            ox in -0.5f64..1.5, oy in -0.5f64..1.5, oz in -0.5f64..1.5,
            dx in -1.0f64..1.0, dy in -1.0f64..1.0, dz in -1.0f64..1.0,
        ) {
            let d = DVec3::new(dx, dy, dz);
            prop_assume!(d.length() > 1e-3);
            let tris = soup(n, seed, 0.2);
            let bvh = build(&tris, false);
            let flat = build(&tris, true);
            let morton = build_tree(&tris, Tree::Morton);
            // A fan of rays from one origin: most meet something, the
            // duplicated triangles make ties.
            for k in 0..32u32 {
                let jitter = DVec3::new(
                    f64::from(k % 4),
                    f64::from(k / 4 % 4),
                    f64::from(k / 16),
                ) * 0.07;
                let ray = Ray64 {
                    origin: DVec3::new(ox, oy, oz),
                    dir: (d + jitter).normalize(),
                    t_min: 0.0,
                    t_max: f64::INFINITY,
                };
                let want = linear(&tris, &ray, bvh.reach(&ray));
                let got = bvh.intersect(&ray).map(|h| (h.id, h.t64));
                prop_assert_eq!(got, want);
                prop_assert_eq!(flat.intersect(&ray).map(|h| (h.id, h.t64)), want);
                prop_assert_eq!(morton.intersect(&ray).map(|h| (h.id, h.t64)), want);
                let mut all = Vec::new();
                bvh.for_each_hit(&ray, NO_SKIP, |id, _| {
                    all.push(id);
                    false
                });
                all.sort_unstable();
                let mut all_morton = Vec::new();
                morton.for_each_hit(&ray, NO_SKIP, |id, _| {
                    all_morton.push(id);
                    false
                });
                all_morton.sort_unstable();
                prop_assert_eq!(&all_morton, &all);
                let pre = RayPrecomp::new(&ray, bvh.reach(&ray));
                let (t_min, t_max) = (ray.t_min, ray.t_max);
                let every: Vec<u32> = (0..u32::try_from(n).unwrap())
                    .filter(|&id| {
                        intersect(&pre, pre.shear64(), &tris[id as usize], t_min, t_max).is_some()
                    })
                    .collect();
                prop_assert_eq!(all, every);
            }
        }

        /// A packet's any-hit answers are the single-ray ones (the every-hit
        /// walk stopped at the first accepted hit), with an acceptance that
        /// rejects some triangles (so a ray may pass hits before the one
        /// that stops it) and a skipped triangle per ray (every other ray
        /// skips none), on both instruction sets, for every packet size.
        #[test]
        fn packet_any_hits_equal_single_ray_answers(
            seed in 0u64..1000,
            n in 1usize..600,
            ox in -0.5f64..1.5, oy in -0.5f64..1.5, oz in -0.5f64..1.5,
            dx in -1.0f64..1.0, dy in -1.0f64..1.0, dz in -1.0f64..1.0,
            spread in 0.001f64..0.3,
            size in 1usize..=8,
            reject in 1u32..5,
        ) {
            let d = DVec3::new(dx, dy, dz);
            prop_assume!(d.length() > 1e-3);
            let tris = soup(n, seed, 0.2);
            let mut bvh = build(&tris, false);
            let rays = packet_fan(DVec3::new(ox, oy, oz), d, spread);
            let accept = |r: usize, id: u32| !(id + u32::try_from(r).unwrap()).is_multiple_of(reject + 1);
            // The first triangle each ray hits (or none), skipped by the odd rays.
            let skips: Vec<u32> = rays
                .iter()
                .enumerate()
                .map(|(r, ray)| match bvh.intersect(ray) {
                    Some(h) if r % 2 == 1 => h.id,
                    _ => NO_SKIP,
                })
                .collect();
            for path in [SimdPath::Auto, SimdPath::Baseline] {
                bvh.set_simd(path);
                for (c, (chunk, skip)) in rays.chunks(size).zip(skips.chunks(size)).enumerate() {
                    let mut got = vec![false; chunk.len()];
                    bvh.any_packet(chunk, skip, |r, id, _| accept(c * size + r, id), &mut got);
                    let want: Vec<bool> = chunk
                        .iter()
                        .enumerate()
                        .map(|(r, ray)| {
                            let mut hit = false;
                            bvh.for_each_hit(ray, NO_SKIP, |id, _| {
                                hit = id != skip[r] && accept(c * size + r, id);
                                hit
                            });
                            hit
                        })
                        .collect();
                    prop_assert_eq!(got, want);
                }
            }
        }

        /// Packets in a tree deeper than the walks' 64-entry stacks (a
        /// geometric run of triangles, each split off its neighbours by
        /// the SAH one at a time), where both the packet walk and the
        /// single-ray finishes use their heap stacks.
        #[test]
        fn packets_in_a_deep_tree_equal_single_rays(
            dx in -0.2f64..0.2, dy in -0.2f64..0.2,
            size in 2usize..=8,
        ) {
            let tris: Vec<[Vec3; 3]> = (0..400)
                .map(|k: i32| {
                    let x = 1.06f32.powi(k);
                    let w = x * 0.02;
                    [
                        Vec3::new(x, -w, 1.0),
                        Vec3::new(x + w, w, 1.0),
                        Vec3::new(x - w, w, 1.02),
                    ]
                })
                .collect();
            let bvh = build(&tris, false);
            prop_assert!(bvh.depth >= 10, "depth {}", bvh.depth);
            let rays: Vec<Ray64> = (0..24u32)
                .map(|k| {
                    let x = 1.06f64.powi(i32::try_from(k * 16).unwrap());
                    Ray64 {
                        origin: DVec3::new(x + dx * x * 0.02, dy * x * 0.02, -1.0),
                        dir: DVec3::new(f64::from(k % 3) * 1e-4, 0.0, 1.0).normalize(),
                        t_min: 0.0,
                        t_max: f64::INFINITY,
                    }
                })
                .collect();
            for chunk in rays.chunks(size) {
                let mut got = vec![None; chunk.len()];
                bvh.intersect_packet(chunk, &mut got);
                let want: Vec<Option<BvhHit>> = chunk.iter().map(|r| bvh.intersect(r)).collect();
                prop_assert_eq!(got, want);
            }
        }

        /// A packet's hits are the single-ray hits bit for bit (distance,
        /// id, barycentrics), on both instruction sets, for packets of
        /// every size up to eight, rays that diverge (a fan with spread
        /// `spread`), rays with short bounds, and rays from two origins.
        #[test]
        fn packet_hits_equal_single_ray_hits(
            seed in 0u64..1000,
            n in 1usize..600,
            ox in -0.5f64..1.5, oy in -0.5f64..1.5, oz in -0.5f64..1.5,
            dx in -1.0f64..1.0, dy in -1.0f64..1.0, dz in -1.0f64..1.0,
            spread in 0.001f64..0.3,
            size in 1usize..=8,
        ) {
            let d = DVec3::new(dx, dy, dz);
            prop_assume!(d.length() > 1e-3);
            let tris = soup(n, seed, 0.2);
            let mut bvh = build(&tris, false);
            let rays = packet_fan(DVec3::new(ox, oy, oz), d, spread);
            for path in [SimdPath::Auto, SimdPath::Baseline] {
                bvh.set_simd(path);
                for chunk in rays.chunks(size) {
                    let mut got = vec![None; chunk.len()];
                    bvh.intersect_packet(chunk, &mut got);
                    let want: Vec<Option<BvhHit>> = chunk.iter().map(|r| bvh.intersect(r)).collect();
                    prop_assert_eq!(got, want);
                }
            }
        }
    }
}
