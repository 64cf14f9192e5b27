//! Backend C: list priority — the painter's algorithm.
//!
//! The triangles are projected and set up exactly as the z-buffer does it
//! (same clipping, snapping and coverage rule, same perspective-correct
//! barycentrics), but instead of a depth test each covered sample takes
//! the triangle drawn *last*: the triangles are drawn farthest first. The
//! triangle-id image is therefore comparable with the z-buffer's sample by
//! sample, and `rendiff diff --a painter --b raster` counts the samples the
//! order got wrong (both triangles cover the sample and the painter's is
//! farther by more than the depth tie).
//!
//! Two orders:
//! * **centroid**: by the view depth of the centroid. Long triangles (a
//!   floor under small objects) and cyclic overlaps defeat it.
//! * **Newell** (Newell, Newell & Sancha 1972): for every pair whose
//!   snapped projections overlap, decide which must be drawn first — the
//!   depth ranges are disjoint, or one lies entirely on the far side of the
//!   other's plane, or the other entirely on the eye's side of its plane —
//!   and draw in a topological order of those constraints, farthest first
//!   where free. Pairs no test can order (interpenetrating triangles, and
//!   the pairs of a cyclic overlap) are counted; they would need splitting
//!   along the other's plane, which this painter does not do, so their
//!   samples show up as wrongly ordered in the comparison.
//!
//! [`draw_smooth`] paints the same order with tiny-skia's anti-aliased
//! fills, one flat colour per triangle: the picture list priority makes
//! when it is not checked sample by sample.

use std::collections::BinaryHeap;

use rayon::prelude::*;

use super::{
    RasterOptions, RasterStats, Record, Rule, homogeneous, primary_records, shade_pass,
    visibility_with,
};
use rendiff_accel::{Accel, AccelOptions, ShadowRays};
use rendiff_core::budget::{Budget, OverBudget};
use rendiff_core::camera::Projection;
use rendiff_core::color::to_srgb8;
use rendiff_core::coverage::SampleGrid;
use rendiff_core::frame::Frame;
use rendiff_core::math::{Bary, DVec3, to_f64};
use rendiff_core::options::PainterSort;
use rendiff_core::shade::{self, Unoccluded, Visibility};
use rendiff_core::tri_scene::TriScene;

/// Bytes per entry of the painter's screen grid (a triangle index in a
/// cell's list, with the list's share of the map).
const CELL_ENTRY_BYTES: u64 = 8;

/// Bytes per candidate pair: its key (8 B), its decision (12 B), and the
/// sort's scratch (8 B).
const PAIR_BYTES: u64 = 28;

/// What ordering the triangles found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PainterStats {
    /// Triangles drawn (those that cover a sample row).
    pub drawn: usize,
    /// Pairs whose projections overlap (Newell only).
    pub overlapping_pairs: u64,
    /// Of those, ordered by disjoint depth ranges.
    pub by_depth_range: u64,
    /// Ordered by a plane test.
    pub by_plane: u64,
    /// Coplanar pairs (ordered by id, as the z-buffer breaks ties).
    pub coplanar: u64,
    /// Pairs no test could order (interpenetrating or cyclic); ordered by
    /// their centroid depths.
    pub undecided: u64,
    /// Cycles broken in the topological sort.
    pub cycles_broken: u64,
}

/// A triangle as the painter sees it.
struct Item<'r> {
    tri: u32,
    /// Its sub-triangles after clipping (snapped, as scan conversion sees them).
    records: Vec<&'r Record>,
    /// View-space vertices (x right, y up, z forward).
    view: [DVec3; 3],
    /// Depth range (view z).
    zmin: f64,
    zmax: f64,
    /// Snapped screen bounds (1/256 px).
    lo: (i64, i64),
    hi: (i64, i64),
}

/// The drawing rank of every triangle (`u32::MAX` for those that cover no
/// sample) and what the ordering found.
///
/// # Errors
///
/// [`OverBudget`] when Newell's pair lists would not fit `budget` (they
/// grow with the square of the triangles that overlap on screen).
pub fn order(
    scene: &TriScene,
    opts: &RasterOptions,
    sort: PainterSort,
    budget: &Budget,
) -> Result<(Vec<u32>, PainterStats), OverBudget> {
    order_records(scene, sort, &painter_records(scene, opts), budget)
}

/// The scan-conversion records of every triangle the options do not cull.
fn painter_records(scene: &TriScene, opts: &RasterOptions) -> Vec<Record> {
    let grid = SampleGrid::new(scene.camera.samples());
    let hv = homogeneous(scene, opts.perturbation());
    primary_records(scene, opts, &hv, &grid)
}

/// The drawing rank of the triangles of `recs` (see [`order`]).
fn order_records(
    scene: &TriScene,
    sort: PainterSort,
    recs: &[Record],
    budget: &Budget,
) -> Result<(Vec<u32>, PainterStats), OverBudget> {
    let cam = &scene.camera;
    let (w, h) = (i64::from(cam.width()) * 256, i64::from(cam.height()) * 256);
    let items = items(scene, recs, (w, h));
    let mut stats = PainterStats {
        drawn: items.len(),
        ..PainterStats::default()
    };
    let centroid = |it: &Item<'_>| (it.view[0].z + it.view[1].z + it.view[2].z) / 3.0;
    let centroid = &centroid;
    let sequence: Vec<usize> = match sort {
        PainterSort::Centroid => {
            let mut idx: Vec<usize> = (0..items.len()).collect();
            // Farthest first; equal depths draw the higher id first so the
            // lower id ends on top, as the z-buffer breaks ties.
            idx.sort_by(|&a, &b| {
                centroid(&items[b])
                    .total_cmp(&centroid(&items[a]))
                    .then(items[b].tri.cmp(&items[a].tri))
            });
            idx
        }
        PainterSort::Newell => newell(&items, cam.projection(), &mut stats, centroid, budget)?,
    };
    let mut rank = vec![u32::MAX; scene.len()];
    for (k, &i) in sequence.iter().enumerate() {
        rank[items[i].tri as usize] = u32::try_from(k).unwrap_or(u32::MAX);
    }
    Ok((rank, stats))
}

/// The painter's items: every triangle with at least one record.
/// `screen`: the image size in snapped units; bounds are clamped to it
/// (overlaps off the screen cover no sample).
fn items<'r>(scene: &TriScene, recs: &'r [Record], screen: (i64, i64)) -> Vec<Item<'r>> {
    let cam = &scene.camera;
    let mut out: Vec<Item<'r>> = Vec::new();
    for rec in recs {
        let lo = (
            i64::from(*rec.x.iter().min().unwrap_or(&0)).clamp(0, screen.0),
            i64::from(*rec.y.iter().min().unwrap_or(&0)).clamp(0, screen.1),
        );
        let hi = (
            i64::from(*rec.x.iter().max().unwrap_or(&0)).clamp(0, screen.0),
            i64::from(*rec.y.iter().max().unwrap_or(&0)).clamp(0, screen.1),
        );
        if let Some(last) = out.last_mut()
            && last.tri == rec.tri
        {
            last.records.push(rec);
            last.lo = (last.lo.0.min(lo.0), last.lo.1.min(lo.1));
            last.hi = (last.hi.0.max(hi.0), last.hi.1.max(hi.1));
            continue;
        }
        let view = scene.triangle(rec.tri).map(|p| cam.to_view(to_f64(p)));
        let zmin = view[0].z.min(view[1].z).min(view[2].z);
        let zmax = view[0].z.max(view[1].z).max(view[2].z);
        out.push(Item {
            tri: rec.tri,
            records: vec![rec],
            view,
            zmin,
            zmax,
            lo,
            hi,
        });
    }
    out
}

/// Do two snapped triangles share interior points? (Separating axes on
/// the six edge normals, exact in integers; touching counts as apart:
/// the coverage rule gives a sample on a shared boundary to one side.)
fn records_overlap(a: &Record, b: &Record) -> bool {
    let pa = [0, 1, 2].map(|k| (i64::from(a.x[k]), i64::from(a.y[k])));
    let pb = [0, 1, 2].map(|k| (i64::from(b.x[k]), i64::from(b.y[k])));
    for (p, _) in [(&pa, &pb), (&pb, &pa)] {
        for k in 0..3 {
            let (x0, y0) = p[k];
            let (x1, y1) = p[(k + 1) % 3];
            let n = (y1 - y0, x0 - x1);
            if n == (0, 0) {
                continue;
            }
            let proj = |q: &(i64, i64)| {
                i128::from(n.0) * i128::from(q.0) + i128::from(n.1) * i128::from(q.1)
            };
            let (amin, amax) = pa
                .iter()
                .map(proj)
                .fold((i128::MAX, i128::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
            let (bmin, bmax) = pb
                .iter()
                .map(proj)
                .fold((i128::MAX, i128::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
            if amax <= bmin || bmax <= amin {
                return false;
            }
        }
    }
    true
}

fn items_overlap(a: &Item<'_>, b: &Item<'_>) -> bool {
    if a.hi.0 <= b.lo.0 || b.hi.0 <= a.lo.0 || a.hi.1 <= b.lo.1 || b.hi.1 <= a.lo.1 {
        return false;
    }
    a.records
        .iter()
        .any(|ra| b.records.iter().any(|rb| records_overlap(ra, rb)))
}

/// Where the vertices of `q` lie against the plane of `p`: (all on the
/// eye's side or on it, all on the far side or on it).
fn sides(p: &[DVec3; 3], q: &[DVec3; 3], projection: Projection) -> (bool, bool) {
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    let d = n.dot(p[0]);
    // The eye's side: the eye at the view origin (perspective), or the
    // direction toward the viewer, −z (orthographic).
    let eye_sign = match projection {
        Projection::Perspective { .. } => -d,
        Projection::Orthographic { .. } => -n.z,
    };
    if eye_sign == 0.0 || !eye_sign.is_finite() {
        // Seen edge-on: the plane separates nothing the eye can tell apart.
        return (false, false);
    }
    let scale = p
        .iter()
        .chain(q.iter())
        .map(|v| v.abs().max_element())
        .fold(0.0f64, f64::max);
    let eps = 1e-9 * n.length() * scale;
    let mut front = true;
    let mut back = true;
    for v in q {
        let s = (n.dot(*v) - d) * eye_sign.signum();
        front &= s >= -eps;
        back &= s <= eps;
    }
    (front, back)
}

/// Newell's order: constraints between overlapping pairs, then a
/// topological sort with the farthest (largest `zmax`) free triangle first.
fn newell(
    items: &[Item<'_>],
    projection: Projection,
    stats: &mut PainterStats,
    centroid: &(dyn Fn(&Item<'_>) -> f64 + Sync),
    budget: &Budget,
) -> Result<Vec<usize>, OverBudget> {
    let (pairs, reserved) = candidate_pairs(items, budget)?;
    let decided = decide_pairs(items, &pairs, projection, centroid);
    let out = topological_order(items, &decided, stats);
    budget.release(reserved);
    Ok(out)
}

/// The candidate pairs (`a << 32 | b`, `a < b`, sorted, once each): items
/// whose bounding boxes share a cell of a screen grid, the cells sized for
/// about eight triangles each on average (4 … 64 px). The grid's lists and
/// the pair list grow with the overlap, up to the square of the triangles:
/// both are reserved in `budget` before they are made; the bytes reserved
/// are returned with the pairs, for the caller to give back.
fn candidate_pairs(items: &[Item<'_>], budget: &Budget) -> Result<(Vec<u64>, u64), OverBudget> {
    let n = items.len();
    #[expect(
        clippy::cast_precision_loss,
        reason = "spans of 1/256 px fixed point inside a 16 384 px image (< 2^23): exact"
    )]
    let area: f64 = items
        .iter()
        .map(|it| ((it.hi.0 - it.lo.0) as f64 / 256.0) * ((it.hi.1 - it.lo.1) as f64 / 256.0))
        .sum();
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_precision_loss,
        reason = "clamped to 4 … 64 px; the item count is exact in f64 below 2^53"
    )]
    let cell_px = (8.0 * area / n.max(1) as f64).sqrt().clamp(4.0, 64.0) as i64;
    let cell = cell_px * 256;
    let cells_of = |it: &Item<'_>| {
        let span = |lo: i64, hi: i64| {
            u64::try_from(hi.div_euclid(cell) - lo.div_euclid(cell) + 1).unwrap_or(u64::MAX)
        };
        span(it.lo.0, it.hi.0).saturating_mul(span(it.lo.1, it.hi.1))
    };
    let entries: u64 = items.iter().map(cells_of).fold(0, u64::saturating_add);
    let grid_bytes = entries.saturating_mul(CELL_ENTRY_BYTES);
    budget.reserve(grid_bytes, || {
        format!("the painter's screen grid ({entries} cell entries at {CELL_ENTRY_BYTES} B)")
    })?;
    let mut cells: std::collections::HashMap<(i64, i64), Vec<u32>> =
        std::collections::HashMap::new();
    for (i, it) in items.iter().enumerate() {
        let i = u32::try_from(i).unwrap_or(u32::MAX);
        for cy in it.lo.1.div_euclid(cell)..=it.hi.1.div_euclid(cell) {
            for cx in it.lo.0.div_euclid(cell)..=it.hi.0.div_euclid(cell) {
                cells.entry((cx, cy)).or_default().push(i);
            }
        }
    }
    let candidates: u64 = cells
        .values()
        .map(|l| (l.len() as u64).saturating_mul((l.len() as u64).saturating_sub(1)) / 2)
        .fold(0, u64::saturating_add);
    let pair_bytes = candidates.saturating_mul(PAIR_BYTES);
    if let Err(e) = budget.reserve(pair_bytes, || {
        format!("Newell's order of {n} triangles ({candidates} candidate pairs at {PAIR_BYTES} B)")
    }) {
        budget.release(grid_bytes);
        return Err(e);
    }
    let mut pairs: Vec<u64> = cells
        .values()
        .flat_map(|list| {
            list.iter().enumerate().flat_map(move |(k, &a)| {
                list[k + 1..]
                    .iter()
                    .map(move |&b| (u64::from(a.min(b)) << 32) | u64::from(a.max(b)))
            })
        })
        .collect();
    pairs.par_sort_unstable();
    pairs.dedup();
    Ok((pairs, grid_bytes.saturating_add(pair_bytes)))
}

/// Decides each candidate pair that overlaps on screen: `(first, second,
/// how)` with `how` 0 for disjoint depth ranges, 1 for a plane test, 2 for
/// coplanar triangles (the higher id first, so the lower ends on top), 3
/// for undecided (by centroid depth).
fn decide_pairs(
    items: &[Item<'_>],
    pairs: &[u64],
    projection: Projection,
    centroid: &(dyn Fn(&Item<'_>) -> f64 + Sync),
) -> Vec<(u32, u32, u8)> {
    pairs
        .par_iter()
        .filter_map(|&key| {
            let (a, b) = ((key >> 32) as usize, (key & 0xFFFF_FFFF) as usize);
            let (p, q) = (&items[a], &items[b]);
            if !items_overlap(p, q) {
                return None;
            }
            let (a32, b32) = (u32::try_from(a).unwrap_or(0), u32::try_from(b).unwrap_or(0));
            // 0: disjoint depth ranges; 1: plane test; 2: coplanar; 3: undecided.
            if q.zmin >= p.zmax {
                return Some((b32, a32, 0));
            }
            if p.zmin >= q.zmax {
                return Some((a32, b32, 0));
            }
            let (q_front_of_p, q_behind_p) = sides(&p.view, &q.view, projection);
            let (p_front_of_q, p_behind_q) = sides(&q.view, &p.view, projection);
            let p_first = q_front_of_p || p_behind_q;
            let q_first = p_front_of_q || q_behind_p;
            match (p_first, q_first) {
                (true, false) => Some((a32, b32, 1)),
                (false, true) => Some((b32, a32, 1)),
                (true, true) => {
                    // Coplanar: the higher id first, so the lower ends on top.
                    if p.tri > q.tri {
                        Some((a32, b32, 2))
                    } else {
                        Some((b32, a32, 2))
                    }
                }
                (false, false) => {
                    if centroid(p) >= centroid(q) {
                        Some((a32, b32, 3))
                    } else {
                        Some((b32, a32, 3))
                    }
                }
            }
        })
        .collect()
}

/// Kahn's algorithm over the decided pairs, the farthest free item first
/// (ties: higher id first); a cycle is broken by releasing the farthest
/// item still waiting (counted in `stats`).
fn topological_order(
    items: &[Item<'_>],
    decided: &[(u32, u32, u8)],
    stats: &mut PainterStats,
) -> Vec<usize> {
    let n = items.len();
    let mut after: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut indegree = vec![0u32; n];
    for &(first, second, how) in decided {
        stats.overlapping_pairs += 1;
        match how {
            0 => stats.by_depth_range += 1,
            1 => stats.by_plane += 1,
            2 => stats.coplanar += 1,
            _ => stats.undecided += 1,
        }
        after[first as usize].push(second);
        indegree[second as usize] += 1;
    }
    let key = |i: usize| (items[i].zmax.to_bits(), items[i].tri);
    let mut heap: BinaryHeap<((u64, u32), usize)> = (0..n)
        .filter(|&i| indegree[i] == 0)
        .map(|i| (key(i), i))
        .collect();
    let mut done = vec![false; n];
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let Some((_, i)) = heap.pop() else {
            // A cycle: release the farthest item still waiting.
            stats.cycles_broken += 1;
            let i = (0..n)
                .filter(|&i| !done[i])
                .max_by_key(|&i| key(i))
                .unwrap_or(0);
            indegree[i] = 0;
            heap.push((key(i), i));
            continue;
        };
        if done[i] {
            continue;
        }
        done[i] = true;
        out.push(i);
        for &j in &after[i] {
            let j = j as usize;
            if done[j] {
                continue;
            }
            indegree[j] = indegree[j].saturating_sub(1);
            if indegree[j] == 0 {
                heap.push((key(j), j));
            }
        }
    }
    out
}

/// Renders with the painter: the drawing order, list-priority visibility
/// on the shared sample grid, and the rasterizer's deferred shading.
///
/// # Errors
///
/// [`OverBudget`] as [`order`].
pub fn render(
    scene: &TriScene,
    opts: &RasterOptions,
    sort: PainterSort,
    budget: &Budget,
) -> Result<(Frame, RasterStats, PainterStats), OverBudget> {
    let (rank, pstats) = order(scene, opts, sort, budget)?;
    let vis = visibility_with(scene, opts, &Rule::Painter(&rank));
    let mut stats = vis.stats;
    let mut frame = Frame::new(0, 0, 1, scene.background);
    let (shadow_rays, shadow_maps) = shade_pass(scene, opts, &vis.id, &mut frame);
    stats.shadow_bvh =
        opts.shadows_needed && opts.shadows == rendiff_core::options::ShadowMode::Rays;
    stats.shadow_rays = shadow_rays;
    stats.shadow_maps = shadow_maps;
    Ok((frame, stats, pstats))
}

/// The painter's picture drawn with anti-aliased fills: every triangle (as
/// clipped and snapped for scan conversion) in drawing order, in one flat
/// colour shaded at its centroid (shadows by shadow rays when the options
/// ask for shadows). Returns 8-bit sRGB RGBA pixels, `width × height`.
///
/// # Errors
///
/// [`OverBudget`] as [`order`].
pub fn draw_smooth(
    scene: &TriScene,
    opts: &RasterOptions,
    sort: PainterSort,
    budget: &Budget,
) -> Result<Vec<u8>, OverBudget> {
    let cam = &scene.camera;
    let (w, h) = (cam.width(), cam.height());
    let mut recs = painter_records(scene, opts);
    let (rank, _) = order_records(scene, sort, &recs, budget)?;
    recs.sort_by_key(|r| rank.get(r.tri as usize).copied().unwrap_or(u32::MAX));
    let ctx = scene.shade_context(opts.gate_eps, opts.shadows_needed);
    let accel = opts
        .shadows_needed
        .then(|| Accel::new(scene, AccelOptions::default()));
    let rays = accel.as_ref().map(ShadowRays::new);
    let visibility: &dyn Visibility = match &rays {
        Some(r) => r,
        None => &Unoccluded,
    };
    let third = 1.0f32 / 3.0;
    let bg = scene.background;
    let Some(mut pixmap) = tiny_skia::Pixmap::new(w.max(1), h.max(1)) else {
        return Ok(vec![0; (w as usize) * (h as usize) * 4]);
    };
    pixmap.fill(tiny_skia::Color::from_rgba8(
        to_srgb8(bg.r),
        to_srgb8(bg.g),
        to_srgb8(bg.b),
        255,
    ));
    let mut last: Option<(u32, tiny_skia::Paint<'_>)> = None;
    for rec in &recs {
        let paint = match &last {
            Some((t, p)) if *t == rec.tri => p.clone(),
            _ => {
                let sp = scene.surface_at(rec.tri, Bary([third; 3]));
                let dir = match cam.projection() {
                    Projection::Perspective { .. } => {
                        (to_f64(sp.p) - cam.eye()).normalize_or_zero()
                    }
                    Projection::Orthographic { .. } => cam.forward(),
                };
                #[expect(clippy::cast_possible_truncation, reason = "an f32 view direction")]
                let d = glam::Vec3::new(dir.x as f32, dir.y as f32, dir.z as f32);
                let c = shade::shade(&ctx, &sp, d, visibility).local;
                let mut paint = tiny_skia::Paint::default();
                paint.set_color_rgba8(to_srgb8(c.r), to_srgb8(c.g), to_srgb8(c.b), 255);
                paint.anti_alias = true;
                last = Some((rec.tri, paint.clone()));
                paint
            }
        };
        // Snapped coordinates (1/256 pixel) to pixels.
        #[expect(
            clippy::cast_precision_loss,
            reason = "snapped coordinates are below 2^26"
        )]
        let px = |v: i32| v as f32 / 256.0;
        let mut pb = tiny_skia::PathBuilder::new();
        pb.move_to(px(rec.x[0]), px(rec.y[0]));
        pb.line_to(px(rec.x[1]), px(rec.y[1]));
        pb.line_to(px(rec.x[2]), px(rec.y[2]));
        pb.close();
        if let Some(path) = pb.finish() {
            pixmap.fill_path(
                &path,
                &paint,
                tiny_skia::FillRule::Winding,
                tiny_skia::Transform::identity(),
                None,
            );
        }
    }
    Ok(pixmap.data().to_vec())
}
