//! The light buffer (Haines and Greenberg, "The Light Buffer: A
//! Shadow-Testing Accelerator", IEEE CG&A 6(9), 1986): for each light, a
//! grid over the directions from it, each cell listing the triangles seen
//! through it. Every shadow ray toward a point light runs along one
//! direction from the light, so only its cell's triangles can stop it: an
//! empty cell answers "lit" with no test at all, a short list is tested
//! as one leaf of the walks (the same `f32` filter and `f64` test), and a
//! crowded cell sends its rays to the BVH walk (a grid crowded over more
//! than a third of its listed cells is not kept: the light's rays walk).
//! To a parallel light, the grid lies in a plane across the light's
//! direction.
//!
//! **Why the answer is the walk's.** An any-hit answer is whether *some*
//! accepted triangle but the skipped one meets the ray by the walks' `f64`
//! test (`triangle::intersect`); the order does not matter. With
//! transparent casters it is the product over every crossing, sorted by
//! distance; the same test gives the same crossings. So a cell's list
//! gives the walk's answer when it holds every triangle whose test meets
//! a ray of that cell. A ray meets a triangle by that test only where
//! its `f64` line passes within the test's rounding of the triangle
//! (`Δ`, below); the cell of a ray is found from its origin, and the
//! triangles are entered in every cell their projection, widened by a
//! margin far above that rounding, touches:
//!
//! - *Point light at `L`.* The ray from `o` runs toward `L` and ends
//!   there; a point `q` of a triangle it meets lies (up to `Δ`) on the
//!   segment, so `q − L` points the way `o − L` does. The directions are
//!   the six faces of a cube (`u = w_a/w_k`, `v = w_b/w_k` on the face of
//!   the axis `k` where `|w_k|` is largest). Rounding displaces the
//!   segment by at most `Δ ≤ 2.2·10⁻¹⁴·S`, where `S` bounds every
//!   coordinate of the casters, the light and the origin (origins beyond
//!   `2S` are walked): the direction from `o` is rounded once in each
//!   operation of `shadow_ray` (about 5 ulp over a length under `6S`),
//!   and the `f64` test's translation, shear and edge functions err by
//!   about 20 ulp of the translated coordinates (under `6S`); 200 ulp of
//!   `S` covers both with room. A triangle at least `η·S` from the light
//!   (`η` = [`NEAR`]) is then seen from the light within
//!   `θ ≤ Δ/(ηS − Δ) ≈ 2.2·10⁻¹⁰` rad of the ray's direction, which moves
//!   `u` and `v` by under `5θ ≈ 1.1·10⁻⁹` (the face's `|w_k|` is at least
//!   `|w|/√3`); the margin is [`MARGIN`] = 10⁻⁶. A point of the triangle
//!   that a ray on a face meets has `w_k ≥ |w|(1/√3 − θ) > d/2`, where `d`
//!   is the triangle's least distance from the light, so the triangle is
//!   clipped to `w_k ≥ d/2` before its corners are projected (the
//!   projection of a convex polygon in front of the light is the convex
//!   polygon of its corners' projections, and its box bounds it). A
//!   triangle nearer than `η·S` (one the light almost touches, whose
//!   directions rounding can scatter) is tested on every ray.
//! - *Parallel light.* The ray `o + t·D` runs along the light's own
//!   direction `D` (the queries' `f32` direction, checked bit for bit),
//!   so a point it meets projects onto the plane across `D` where `o`
//!   does, up to `Δ`, the rounding of the projection (about 3 ulp of
//!   `S`), and `t` (under `6S`) times how far the computed axes of the
//!   plane are from square to `D`; the margin is `10⁻⁹·S` plus ten times
//!   the last.
//!
//! A cell is found by `floor((x − lo)·inv)` clamped to the grid, which
//! never decreases as `x` grows (each rounded operation is monotone), so
//! a ray whose coordinate lies in a triangle's widened box finds one of
//! that box's cells, wherever the box and the ray fall against the grid.
//!
//! As every argument that a box holds what the `f64` test meets (the BVH's
//! own, `Bvh::reach` and `WalkRay`), this one bounds the test's rounding
//! by the distance of the line from the triangle: it holds for the
//! triangles of any real mesh, not for a sliver whose shortest edge is
//! below the `f64` rounding of its coordinates (a corner one ulp from
//! another), whose edge function can take the wrong sign far beyond it.

use rayon::prelude::*;
use rendiff_core::math::{DVec3, Ray64, Vec3, to_f64};
use rendiff_core::shade::LightKind;
use rendiff_core::tri_scene::TriScene;

use super::TriPlane;
use super::bvh::Bvh;

/// A triangle nearer the light than `NEAR·S` is tested on every ray
/// toward it (see the module's argument).
const NEAR: f64 = 1e-4;
/// Casters per run of the build's parallel passes.
const RUN: usize = 1024;

/// How far a triangle's projected box is widened, in the cube faces'
/// `u, v` (see the module's argument: rounding moves them by under
/// `1.1·10⁻⁹`).
const MARGIN: f64 = 1e-6;

/// Cells listing more triangles than this send their rays to the walk:
/// beyond four packs, the tree's walk is the cheaper test.
pub(crate) const MAX_LIST: usize = 8;

/// The share of a grid's listed cells (those not empty) that may be
/// crowded ([`MAX_LIST`]) before the grid is dropped, as a fraction
/// (numerator, denominator): see `LightBuffer::new`.
const LB_CROWDED_SHARE: (usize, usize) = (1, 3);

/// Cells of a grid at least (a few large triangles, as a floor, would
/// otherwise set a grid too coarse for the small ones among them).
const MIN_CELLS: usize = 32 * 32;

/// Cells per side of a grid at most.
const MAX_RES: usize = 256;

/// A cell that lists no triangle: its rays are lit.
const EMPTY_CELL: u32 = u32::MAX;

/// A cell whose rays are walked.
const WALK_CELL: u32 = u32::MAX - 1;

/// What the light buffer says of a ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Cell {
    /// No triangle can stop it.
    Empty,
    /// Only the triangles of this leaf can.
    Leaf(u32),
    /// The buffer cannot tell: walk the tree.
    Walk,
}

/// A grid over two coordinates: cell `floor((x − lo)·inv)`, clamped.
#[derive(Clone, Copy, Debug)]
struct Grid {
    lo: [f64; 2],
    inv: [f64; 2],
    res: [usize; 2],
    /// `res − 1` as `f64` (the last cell).
    top: [f64; 2],
    /// Where the grid's cells start in [`LightBuffer::cells`].
    base: usize,
}

impl Grid {
    /// The grid over the box `[lo, hi]` with about `cells` cells.
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        clippy::cast_precision_loss,
        reason = "cell counts far below 2^52, a side clamped to 1 … MAX_RES"
    )]
    fn over(lo: [f64; 2], hi: [f64; 2], cells: usize, base: usize) -> Grid {
        let side = ((cells as f64).sqrt().ceil() as usize).clamp(1, MAX_RES);
        let mut inv = [0.0; 2];
        let mut res = [1; 2];
        for a in 0..2 {
            let span = hi[a] - lo[a];
            if span > 0.0 && span.is_finite() {
                res[a] = side;
                inv[a] = side as f64 / span;
            }
        }
        Grid {
            lo,
            inv,
            res,
            top: res.map(|r| (r - 1) as f64),
            base,
        }
    }

    /// The cell column (or row) of coordinate `x` on axis `a`: monotone in
    /// `x`, clamped to the grid.
    #[inline(always)]
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "a value clamped to 0 … res − 1 (at most MAX_RES), through i32 (one instruction)"
    )]
    fn index(&self, a: usize, x: f64) -> usize {
        let c = (x - self.lo[a]) * self.inv[a];
        // `max` first: a NaN (never from finite inputs) goes to cell 0;
        // the cast truncates what is then at least 0, as `floor` would
        // (without its call: SSE2 has no rounding instruction).
        c.max(0.0).min(self.top[a]) as i32 as usize
    }

    /// The cell of the point `(x, y)`.
    #[inline(always)]
    fn cell(&self, x: f64, y: f64) -> usize {
        self.base + self.index(1, y) * self.res[0] + self.index(0, x)
    }

    fn len(&self) -> usize {
        self.res[0] * self.res[1]
    }
}

/// How a light's rays map to the grid.
#[derive(Clone, Copy, Debug)]
enum Shape {
    /// A point light: six cube faces (grid `2k + (w_k < 0)`).
    Point { at: DVec3 },
    /// A parallel light whose queries run along `toward`: one plane,
    /// spanned by `a` and `b`.
    Parallel { toward: Vec3, a: DVec3, b: DVec3 },
}

/// One light's buffer.
#[derive(Debug)]
struct LightBuffer {
    shape: Shape,
    grids: Vec<Grid>,
    /// Per cell: its leaf (an index into `LightBuffers::leaf_info`),
    /// [`EMPTY_CELL`] or [`WALK_CELL`].
    cells: Vec<u32>,
    /// Origins with a coordinate beyond this are walked (`2S`).
    bound: f64,
}

/// The light buffers of a scene's lights, and the leaves their cells list.
#[derive(Debug, Default)]
pub(crate) struct LightBuffers {
    lights: Vec<Option<LightBuffer>>,
    /// The cells' leaves (packs and ids only; no nodes).
    leaves: Bvh,
    /// Per leaf: its first pack, and where its triangles' planes start in
    /// `planes` (they end where the next leaf's start).
    leaf_info: Vec<(u32, u32)>,
    /// The leaves' triangles and their planes, leaf after leaf.
    planes: Vec<CullPlane>,
}

/// One face's or plane's entry of a triangle: its widened box.
struct Entry {
    grid: u8,
    lo: [f64; 2],
    hi: [f64; 2],
    tri: u32,
}

impl LightBuffers {
    /// Buffers for the lights `build(light)` selects, over the triangles
    /// of `ids` (those the BVH holds) that `casts(light, id)` selects (those
    /// that could stop one of its rays).
    pub(crate) fn new(
        scene: &TriScene,
        ids: &[u32],
        build: impl Fn(usize) -> bool,
        casts: impl Fn(usize, u32) -> bool,
    ) -> LightBuffers {
        let mut out = LightBuffers::default();
        for (l, light) in scene.lights.iter().enumerate() {
            let buffer = build(l)
                .then(|| {
                    let casters: Vec<u32> =
                        ids.iter().copied().filter(|&id| casts(l, id)).collect();
                    LightBuffer::new(scene, light.kind, &casters, &mut out)
                })
                .flatten();
            out.lights.push(buffer);
        }
        out
    }

    /// `true` when light `light` has a buffer.
    pub(crate) fn has(&self, light: usize) -> bool {
        matches!(self.lights.get(light), Some(Some(_)))
    }

    /// `true` when no light has a buffer.
    pub(crate) fn is_empty(&self) -> bool {
        self.lights.iter().all(Option::is_none)
    }

    /// The leaves the cells list.
    pub(crate) fn leaves(&self) -> &Bvh {
        &self.leaves
    }

    /// The first pack of leaf `leaf` in [`LightBuffers::leaves`].
    #[inline(always)]
    pub(crate) fn first_pack(&self, leaf: u32) -> u32 {
        self.leaf_info[leaf as usize].0
    }

    /// `true` when `ray` keeps clear of the plane of every triangle of
    /// leaf `leaf` but `skip` ([`CullPlane::clear_of`]): the `f64` test
    /// rejects each, and the ray is lit.
    #[inline(always)]
    pub(crate) fn clear_of_all(&self, leaf: u32, ray: &Ray64, skip: u32) -> bool {
        let from = self.leaf_info[leaf as usize].1 as usize;
        let to = self
            .leaf_info
            .get(leaf as usize + 1)
            .map_or(self.planes.len(), |l| l.1 as usize);
        self.planes[from..to]
            .iter()
            .all(|p| p.id == skip || p.clear_of(ray))
    }

    /// What the buffer of `light` says of `ray`, a shadow ray toward it
    /// (`at`: the point light's position the ray ends at, as `shadow_ray`
    /// gave it; `dir`: the query's direction).
    #[inline(always)]
    pub(crate) fn cell(&self, light: usize, ray: &Ray64, at: Option<DVec3>, dir: Vec3) -> Cell {
        let Some(Some(b)) = self.lights.get(light) else {
            return Cell::Walk;
        };
        let o = ray.origin;
        let far = o.abs().max_element();
        // (A NaN origin is walked too.)
        if far.is_nan() || far > b.bound {
            return Cell::Walk;
        }
        let cell = match (b.shape, at) {
            (Shape::Point { at: l }, Some(at)) if at == l => {
                let w = o - l;
                let aw = w.abs();
                let k = if aw.x >= aw.y && aw.x >= aw.z {
                    0
                } else if aw.y >= aw.z {
                    1
                } else {
                    2
                };
                let w = w.to_array();
                let neg = w[k] < 0.0;
                let wk = w[k].abs();
                let (u, v) = (w[(k + 1) % 3] / wk, w[(k + 2) % 3] / wk);
                b.grids[2 * k + usize::from(neg)].cell(u, v)
            }
            (Shape::Parallel { toward, a, b: bb }, None)
                if toward.to_array().map(f32::to_bits) == dir.to_array().map(f32::to_bits) =>
            {
                b.grids[0].cell(a.dot(o), bb.dot(o))
            }
            _ => return Cell::Walk,
        };
        match b.cells[cell] {
            EMPTY_CELL => Cell::Empty,
            WALK_CELL => Cell::Walk,
            leaf => Cell::Leaf(leaf),
        }
    }
}

impl LightBuffer {
    /// The buffer of a light of kind `kind` over the casting triangles
    /// `ids`; `None` when it would send every ray to the walk.
    fn new(
        scene: &TriScene,
        kind: LightKind,
        ids: &[u32],
        store: &mut LightBuffers,
    ) -> Option<LightBuffer> {
        // S: every coordinate of the casters and the light. (The passes
        // over all the casters run in runs of `RUN`, in parallel, joined
        // in id order: the same S and entries at any thread count.)
        let mut s = ids
            .par_chunks(RUN)
            .map(|run| {
                let mut s = 0.0f64;
                for &id in run {
                    for p in scene.triangle(id) {
                        s = s.max(to_f64(p).abs().max_element());
                    }
                }
                s
            })
            .collect::<Vec<f64>>()
            .into_iter()
            .fold(0.0f64, f64::max);
        let (shape, ngrids) = match kind {
            LightKind::Point { position } => {
                let at = to_f64(position);
                s = s.max(at.abs().max_element());
                (Shape::Point { at }, 6)
            }
            LightKind::Parallel { direction } => {
                let toward = -direction;
                let d = to_f64(toward);
                if d.length().is_nan() || d.length() <= 0.5 {
                    return None;
                }
                // The plane's axes: square to D, from the axis D is least along.
                let ad = d.abs();
                let e = if ad.x <= ad.y && ad.x <= ad.z {
                    DVec3::X
                } else if ad.y <= ad.z {
                    DVec3::Y
                } else {
                    DVec3::Z
                };
                let a = d.cross(e).normalize();
                let b = d.cross(a).normalize();
                (Shape::Parallel { toward, a, b }, 1)
            }
        };
        if !(s.is_finite() && s > 0.0) {
            return None;
        }
        // A parallel light's margin (see the module's argument): 10⁻⁹·S,
        // and ten times `t` (under 6S) by how far the plane's computed
        // axes are from square to `D`.
        let margin = match shape {
            Shape::Parallel { toward, a, b } => {
                let d = to_f64(toward);
                1e-9 * s + 10.0 * 6.0 * s * (a.dot(d).abs() + b.dot(d).abs())
            }
            Shape::Point { .. } => 0.0,
        };
        // Each triangle's widened boxes, and the triangles every ray tests.
        let runs: Vec<(Vec<Entry>, Vec<u32>)> = ids
            .par_chunks(RUN)
            .map(|run| {
                let mut entries = Vec::with_capacity(run.len());
                let mut near = Vec::new();
                for &id in run {
                    entry(scene, id, shape, s, margin, &mut entries, &mut near);
                }
                (entries, near)
            })
            .collect();
        let mut entries = Vec::with_capacity(runs.iter().map(|r| r.0.len()).sum());
        let mut near = Vec::new();
        for (e, n) in runs {
            entries.extend(e);
            near.extend(n);
        }
        if near.len() > MAX_LIST {
            return None;
        }
        // The grids: each over its entries' boxes (a face's clamped to its
        // square), with about one cell per two entries (a triangle
        // mostly covers a few cells; four cells per entry cost `spheres`
        // 5 % more, in the build).
        let mut grids = Vec::with_capacity(ngrids);
        let mut base = 0;
        for g in 0..ngrids {
            let mut lo = [f64::INFINITY; 2];
            let mut hi = [f64::NEG_INFINITY; 2];
            let mut count = 0usize;
            for e in entries.iter().filter(|e| usize::from(e.grid) == g) {
                for a in 0..2 {
                    lo[a] = lo[a].min(e.lo[a]);
                    hi[a] = hi[a].max(e.hi[a]);
                }
                count += 1;
            }
            if matches!(shape, Shape::Point { .. }) {
                for a in 0..2 {
                    lo[a] = lo[a].max(-1.0);
                    hi[a] = hi[a].min(1.0);
                }
            }
            let grid = if count == 0 || !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
                Grid::over([0.0; 2], [0.0; 2], 1, base)
            } else {
                Grid::over(lo, hi, (count / 2).max(MIN_CELLS), base)
            };
            base += grid.len();
            grids.push(grid);
        }
        // Count, then list, each cell's triangles (in id order).
        let mut counts = vec![0u32; base];
        // An entry's cells: rows `y0..=y1` of its grid, columns `x0..=x1`
        // (`lo ≤ hi` and `index` is monotone, so `x0 ≤ x1`; loops over row
        // slices: an iterator of cells made `spheres`' build 47.6 M
        // instructions against 34.2 M).
        let rect = |e: &Entry| {
            let g = &grids[usize::from(e.grid)];
            let (x0, x1) = (g.index(0, e.lo[0]), g.index(0, e.hi[0]));
            let (y0, y1) = (g.index(1, e.lo[1]), g.index(1, e.hi[1]));
            (g.base + x0, x1 - x0 + 1, y0..=y1, g.res[0])
        };
        let cap = u32::try_from(MAX_LIST - near.len()).unwrap_or(0);
        for e in &entries {
            let (first, width, rows, stride) = rect(e);
            for y in rows {
                let row = first + y * stride;
                for c in &mut counts[row..row + width] {
                    *c = (*c + 1).min(cap + 1);
                }
            }
        }
        // A grid more than a third of whose listed cells are crowded sends
        // most rays to the walk with its lookup added (the rays leave the
        // casters, so they land where the casters are listed): dropped,
        // and every ray toward the light walks at once. The share is
        // measured (ARCHITECTURE.md, the light buffer's "Crowded
        // cells"): at most 0.21 in the scenes the buffer speeds up,
        // 0.43–0.67 in `many_lights` (eight lights 1.1 above a 16-unit
        // teapot), whose buffers cost 10.2 % more instructions than none.
        // Decided from the counts, before the lists and leaves are made: a
        // cell will be crowded (walked) where its count passes `cap`, and
        // listed where it counts a triangle or the near list is not empty.
        let (mut crowded, mut occupied) = (0usize, 0usize);
        for &n in &counts {
            crowded += usize::from(n > cap);
            occupied += usize::from(n > 0);
        }
        if !near.is_empty() {
            occupied = base;
        }
        if crowded * LB_CROWDED_SHARE.1 > occupied * LB_CROWDED_SHARE.0 {
            return None;
        }
        let mut start = Vec::with_capacity(base + 1);
        let mut total = 0usize;
        for &n in &counts {
            start.push(total);
            if n <= cap {
                total += n as usize;
            }
        }
        start.push(total);
        let mut listed = vec![0u32; total];
        let mut fill = start.clone();
        for e in &entries {
            let (first, width, rows, stride) = rect(e);
            for y in rows {
                let row = first + y * stride;
                for c in row..row + width {
                    if counts[c] <= cap {
                        listed[fill[c]] = e.tri;
                        fill[c] += 1;
                    }
                }
            }
        }
        let tri = |id: u32| scene.triangle(id);
        let at = match shape {
            Shape::Point { at } => Some(at),
            Shape::Parallel { .. } => None,
        };
        let mut cells = vec![EMPTY_CELL; base];
        let mut list = Vec::with_capacity(MAX_LIST);
        for g in &grids {
            for y in 0..g.res[1] {
                for x in 0..g.res[0] {
                    let c = g.base + y * g.res[0] + x;
                    if counts[c] > cap {
                        cells[c] = WALK_CELL;
                        continue;
                    }
                    let here = &listed[start[c]..start[c + 1]];
                    if here.is_empty() && near.is_empty() {
                        continue;
                    }
                    // Neighbours mostly list the same triangles: one leaf.
                    let same =
                        |n: usize| counts[n] <= cap && listed[start[n]..start[n + 1]] == *here;
                    if x > 0 && same(c - 1) {
                        cells[c] = cells[c - 1];
                        continue;
                    }
                    if y > 0 && same(c - g.res[0]) {
                        cells[c] = cells[c - g.res[0]];
                        continue;
                    }
                    list.clear();
                    list.extend_from_slice(here);
                    list.extend_from_slice(&near);
                    let leaf = u32::try_from(store.leaf_info.len()).ok()?;
                    let first = store.leaves.emit_ids(&list, &tri);
                    let planes = u32::try_from(store.planes.len()).ok()?;
                    store.leaf_info.push((first, planes));
                    store.planes.extend(
                        list.iter()
                            .map(|&id| CullPlane::new(scene, id, at, near.contains(&id), s)),
                    );
                    cells[c] = leaf;
                }
            }
        }
        Some(LightBuffer {
            shape,
            grids,
            cells,
            bound: 2.0 * s,
        })
    }
}

/// The entries of caster `id` for a light of shape `shape` (see
/// [`point_entries`]; a parallel light's one box in its plane, widened
/// by `margin`), or `id` in `near`.
fn entry(
    scene: &TriScene,
    id: u32,
    shape: Shape,
    s: f64,
    margin: f64,
    entries: &mut Vec<Entry>,
    near: &mut Vec<u32>,
) {
    let v = scene.triangle(id).map(to_f64);
    match shape {
        Shape::Point { at } => point_entries(id, v, at, s, entries, near),
        Shape::Parallel { a, b, .. } => {
            let x = v.map(|p| a.dot(p));
            let y = v.map(|p| b.dot(p));
            let lo = [
                x[0].min(x[1]).min(x[2]) - margin,
                y[0].min(y[1]).min(y[2]) - margin,
            ];
            let hi = [
                x[0].max(x[1]).max(x[2]) + margin,
                y[0].max(y[1]).max(y[2]) + margin,
            ];
            entries.push(Entry {
                grid: 0,
                lo,
                hi,
                tri: id,
            });
        }
    }
}

/// The entries of triangle `id` (corners `v`) on the cube faces around a
/// point light at `at`, or `id` in `near` (see the module's argument).
fn point_entries(
    id: u32,
    v: [DVec3; 3],
    at: DVec3,
    s: f64,
    entries: &mut Vec<Entry>,
    near: &mut Vec<u32>,
) {
    let w = v.map(|p| p - at);
    // The least distance from the light to the triangle's box.
    let lo = w[0].min(w[1]).min(w[2]);
    let hi = w[0].max(w[1]).max(w[2]);
    let gap = lo.max(-hi).max(DVec3::ZERO);
    let d = gap.length() * (1.0 - 1e-9);
    if d.is_nan() || d < NEAR * s {
        near.push(id);
        return;
    }
    let tau = d / 2.0;
    for k in 0..3 {
        for neg in [false, true] {
            let sign = if neg { -1.0 } else { 1.0 };
            let z = w.map(|p| sign * p.to_array()[k]);
            if z.iter().all(|&z| z < tau) {
                continue;
            }
            // Clip to z ≥ τ (Sutherland–Hodgman, one plane): at most four corners.
            let mut poly = [DVec3::ZERO; 4];
            let mut n = 0;
            for i in 0..3 {
                let j = (i + 1) % 3;
                if z[i] >= tau {
                    poly[n] = w[i];
                    n += 1;
                }
                if (z[i] >= tau) != (z[j] >= tau) {
                    let f = (tau - z[i]) / (z[j] - z[i]);
                    poly[n] = w[i] + (w[j] - w[i]) * f;
                    n += 1;
                }
            }
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            let mut lo = [f64::INFINITY; 2];
            let mut hi = [f64::NEG_INFINITY; 2];
            for p in &poly[..n] {
                let p = p.to_array();
                // (The clipped corner's `w_k` is τ up to rounding: never
                // below τ/2, so the quotient is finite.)
                let pk = (sign * p[k]).max(tau * 0.5);
                for (axis, c) in [a, b].into_iter().enumerate() {
                    let x = p[c] / pk;
                    let widen = MARGIN + 1e-12 * x.abs();
                    lo[axis] = lo[axis].min(x - widen);
                    hi[axis] = hi[axis].max(x + widen);
                }
            }
            if lo[0] > 1.0 || hi[0] < -1.0 || lo[1] > 1.0 || hi[1] < -1.0 {
                continue;
            }
            let clamp = |x: f64| x.clamp(-1.0 - MARGIN, 1.0 + MARGIN);
            #[expect(clippy::cast_possible_truncation, reason = "six faces")]
            entries.push(Entry {
                grid: (2 * k + usize::from(neg)) as u8,
                lo: lo.map(clamp),
                hi: hi.map(clamp),
                tri: id,
            });
        }
    }
}

/// A triangle of a leaf, and what tells cheaply that a ray toward the
/// leaf's light cannot meet it.
#[derive(Clone, Copy, Debug)]
struct CullPlane {
    id: u32,
    plane: TriPlane,
    /// The side of the plane the point light lies on, by more than
    /// `slack` beyond rounding (±1), or 0 (a parallel light; a light that
    /// near the plane; a triangle that near the light).
    light_side: f64,
    /// `|n|` times the test's rounding distance (see [`CullPlane::clear_of`]).
    slack: f64,
}

impl CullPlane {
    fn new(scene: &TriScene, id: u32, at: Option<DVec3>, near: bool, s: f64) -> CullPlane {
        let plane = TriPlane::of(scene, id);
        // Δ of the module's argument (2.2·10⁻¹⁴·S), with a factor of 45.
        let slack = plane.n.length() * 1e-12 * s;
        let light_side = match at {
            Some(at) if !near => {
                let (side, bound) = plane.dot(at - plane.v0);
                if side.abs() > bound + slack {
                    side.signum()
                } else {
                    0.0
                }
            }
            _ => 0.0,
        };
        CullPlane {
            id,
            plane,
            light_side,
            slack,
        }
    }

    /// `true` when the `f64` test cannot meet this triangle on `ray` (a
    /// shadow ray toward the leaf's light): either its origin lies on the
    /// light's side of the plane, farther from it than the test's rounding
    /// distance `Δ` as the light is (the segment between them then keeps
    /// farther than `Δ` from the plane: the cells' own argument), or the
    /// ray leaves the plane behind ([`TriPlane::left_behind`], the
    /// argument of the skipped triangle).
    #[inline(always)]
    fn clear_of(&self, ray: &Ray64) -> bool {
        let (side, bound) = self.plane.dot(ray.origin - self.plane.v0);
        side * self.light_side > bound + self.slack || self.plane.left_behind(ray)
    }
}
