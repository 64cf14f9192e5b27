//! Backend A: the scanline z-buffer rasterizer.
//!
//! 1. **Transform**: every vertex to homogeneous screen space `(X·w, Y·w, w)`
//!    in `f64`, with the ray tracer's camera.
//! 2. **Setup** (parallel over triangles, in id order): frustum and
//!    back-face culling where the plan allows it, homogeneous clipping
//!    against the near plane (and a guard band where needed), snapping to
//!    1/256 pixel ([`rendiff_core::coverage`]); every sub-triangle that covers a
//!    sample row becomes a compact record, binned to fixed bands of sample
//!    rows.
//! 3. **Visibility** (parallel over bands): per record, the coverage rule's
//!    exact integer DDA gives the covered span of every sample row; along
//!    the span the perspective-correct plane values `λ_i = b_i/w` of the
//!    *unsnapped* triangle and the depth plane are stepped incrementally
//!    in `f64`, re-anchored by direct evaluation at every span start. The
//!    depth test compares (depth key, triangle id), so equal depths go to
//!    the lower id whatever the drawing order.
//! 4. **Deferred shading** (parallel over rows): each visible sample is
//!    shaded once through `TriScene::surface_at` and `shade::shade` with
//!    the sample's primary-ray direction; shadows by the same shadow rays
//!    as the ray tracer, or a shadow map.
//!
//! Bands have a fixed height (independent of the thread count) and each
//! sample is written by one band only, so the output is bit-identical for
//! any number of threads.

#![warn(missing_docs, missing_debug_implementations)]

pub mod bsp;
mod clip;
pub mod painter;
mod shadow_map;

use rayon::prelude::*;

use clip::{HVert, clip_polygon, planes};
use rendiff_accel::{Accel, AccelOptions, BvhBuild, ShadowBatch, ShadowRays};
use rendiff_core::camera::{Projection, SampleRays};
use rendiff_core::coverage::{FillRule, SampleGrid, SnappedTri, Sub8, bbox_samples, doubled_area};
use rendiff_core::frame::{BACKGROUND, Frame, Sample, band_rows};
use rendiff_core::huge::Big;
use rendiff_core::math::{DVec3, to_f64};
use rendiff_core::options::{DepthFormat, ShadowMode};
use rendiff_core::shade::{self, Unoccluded, Visibility};
use rendiff_core::tri_scene::TriScene;

pub use rendiff_core::coverage::DEPTH_DRIFT_REL;

/// Sample rows per band of the visibility pass (fewer on many threads:
/// [`band_rows`]).
const BAND: u32 = 32;
/// Guard band around the screen (pixels); beyond it triangles are clipped.
/// With sides ≤ 16384 px every snapped coordinate stays below 2¹⁷ px,
/// far inside [`rendiff_core::coverage::MAX_SNAPPED`].
const GUARD_PX: f64 = 65_536.0;

/// The test hooks (feature `testing`): perturbations for the verdict's
/// negative controls, the coverage visitor and the drift measure. Without
/// the feature the rasterizer always runs unperturbed and none of them is
/// part of the API.
mod hooks {
    use rendiff_core::coverage::FillRule;

    /// Test-only perturbations for the verdict's negative controls.
    #[derive(Clone, Copy, Debug, Default, PartialEq)]
    pub struct Perturb {
        /// Shift every projected vertex by this many pixels in x and y.
        pub offset_px: f64,
        /// The fill rule (bottom-right flips the ownership of edge samples).
        pub fill_rule: FillRule,
    }
}
#[cfg(feature = "testing")]
pub use hooks::Perturb;
#[cfg(not(feature = "testing"))]
use hooks::Perturb;

/// Options of the rasterizer.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterOptions {
    /// Depth buffer format.
    pub depth: DepthFormat,
    /// Shadows by rays or a shadow map.
    pub shadows: ShadowMode,
    /// The plan allows shadows at all.
    pub shadows_needed: bool,
    /// ε_g for the shading flags.
    pub gate_eps: f32,
    /// Per object: skip for primary visibility (outside the frustum).
    pub frustum_cull: Vec<bool>,
    /// Per object: cull back faces.
    pub backface_cull: Vec<bool>,
    /// Test-only perturbation (feature `testing`).
    #[cfg(feature = "testing")]
    pub perturb: Perturb,
}

impl RasterOptions {
    /// The perturbation to apply: none without the `testing` feature.
    pub(crate) fn perturbation(&self) -> Perturb {
        #[cfg(feature = "testing")]
        {
            self.perturb
        }
        #[cfg(not(feature = "testing"))]
        {
            Perturb::default()
        }
    }
}

/// Counters of one render.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RasterStats {
    /// Triangles considered.
    pub triangles: usize,
    /// Sub-triangles that reached scan conversion.
    pub records: usize,
    /// Samples that passed the depth test (including overwritten ones).
    pub depth_writes: u64,
    /// Samples tested.
    pub fragments: u64,
    /// Triangles culled from primary visibility by the plan.
    pub culled: Culled,
    /// A BVH was built for shadow rays.
    pub shadow_bvh: bool,
    /// Shadow rays cast by the shading pass.
    pub shadow_rays: u64,
    /// Shadow maps built (one per parallel light, six per point light).
    pub shadow_maps: usize,
}

/// A record of a (sub-)triangle to scan: snapped vertices, its triangle
/// id and its sample-row range.
#[derive(Clone, Copy, Debug)]
struct Record {
    x: [i32; 3],
    y: [i32; 3],
    tri: u32,
    rows: (u32, u32),
    /// A back face (doubled signed area ≥ 0 before orientation).
    #[cfg_attr(
        not(any(test, feature = "testing")),
        expect(
            dead_code,
            reason = "read only by the testing hook `cover` and a unit test"
        )
    )]
    back: bool,
    /// The fill rule in effect.
    rule: FillRule,
}

impl Record {
    fn snapped(&self) -> Option<SnappedTri> {
        SnappedTri::from_snapped(
            [
                (i64::from(self.x[0]), i64::from(self.y[0])),
                (i64::from(self.x[1]), i64::from(self.y[1])),
                (i64::from(self.x[2]), i64::from(self.y[2])),
            ],
            self.rule,
        )
    }
}

/// A placeholder for the band lists before they are filled.
static EMPTY_RECORD: Record = Record {
    x: [0; 3],
    y: [0; 3],
    tri: 0,
    rows: (0, 0),
    back: false,
    rule: FillRule::TopLeft,
};

/// Interpolation planes of a triangle: `λ_i = b_i/w` and the depth plane,
/// each `m0·X + m1·Y + m2` relative to an anchor `(ax, ay)` (pixels).
#[derive(Clone, Copy, Debug)]
struct Planes {
    lambda: [[f64; 3]; 3],
    depth: [f64; 3],
    ax: f64,
    ay: f64,
}

impl Planes {
    fn eval(p: &[f64; 3], dx: f64, dy: f64) -> f64 {
        p[0] * dx + p[1] * dy + p[2]
    }
}

/// The visibility buffers of the sample grid.
#[derive(Clone, Debug)]
pub struct VisibilityBuffers {
    /// Depth key per sample (smaller is nearer; `u32::MAX` empty).
    pub key: Big<u32>,
    /// Triangle id per sample ([`BACKGROUND`] empty).
    pub id: Big<u32>,
    /// Counters.
    pub stats: RasterStats,
}

/// Maps the stepped depth value to the format's key (smaller = nearer).
#[derive(Clone, Copy, Debug)]
struct DepthMap {
    format: DepthFormat,
    perspective: bool,
    near: f64,
    far: f64,
}

impl DepthMap {
    /// `v` is 1/z (perspective) or z (orthographic).
    #[inline]
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "quantisation to the depth format, clamped to its range first"
    )]
    fn key(&self, v: f64) -> u32 {
        match self.format {
            DepthFormat::F32 => {
                // Reversed-Z: near/z (perspective), 1 − (z − near)/(far − near).
                let r = if self.perspective {
                    self.near * v
                } else {
                    1.0 - (v - self.near) / (self.far - self.near)
                };
                let f = r as f32;
                // Larger reversed value is nearer: order-preserving bits, inverted.
                let bits = f.to_bits();
                let ordered = if bits >> 31 == 1 {
                    !bits
                } else {
                    bits | 0x8000_0000
                };
                u32::MAX - 1 - ordered.min(u32::MAX - 1)
            }
            DepthFormat::U24 | DepthFormat::U16 => {
                let max = self.format.max_key().unwrap_or(f64::from(u32::MAX));
                let q = if self.perspective {
                    (1.0 / self.near - v) / (1.0 / self.near - 1.0 / self.far)
                } else {
                    (v - self.near) / (self.far - self.near)
                };
                let k = (q.max(0.0) * max).round().min(max - 1.0);
                k as u32
            }
        }
    }
}

/// Renders a scene.
#[must_use]
pub fn render(scene: &TriScene, opts: &RasterOptions) -> (Frame, RasterStats) {
    let mut frame = Frame::new(0, 0, 1, scene.background);
    let stats = render_into(scene, opts, &mut RasterBuffers::default(), &mut frame);
    (frame, stats)
}

/// The working buffers of the rasterizer that outlive a frame when the
/// caller keeps them ([`render_into`]): the projected vertices and the
/// visibility pass's depth keys and triangle ids.
#[derive(Debug, Default)]
pub struct RasterBuffers {
    projected: Projected,
    key: Big<u32>,
    id: Big<u32>,
}

/// Renders a scene into `frame` (made the scene's size), in the memory of
/// `frame` and `buffers` from an earlier call where it is large enough:
/// the frame [`render`] returns, bit for bit, without the fresh memory a
/// frame costs (ARCHITECTURE.md, "Frames into reused memory": a third of
/// a 1080p frame of a 58 k-triangle mesh on the machine measured). For a
/// caller that renders frame after frame.
pub fn render_into(
    scene: &TriScene,
    opts: &RasterOptions,
    buffers: &mut RasterBuffers,
    frame: &mut Frame,
) -> RasterStats {
    let mut stats = visibility_into(scene, opts, &Rule::ZBuffer, buffers);
    let (shadow_rays, shadow_maps) = shade_pass(scene, opts, &buffers.id, frame);
    stats.shadow_bvh = opts.shadows_needed && opts.shadows == ShadowMode::Rays;
    stats.shadow_rays = shadow_rays;
    stats.shadow_maps = shadow_maps;
    stats
}

/// The scene's vertices in homogeneous screen space, and the screen
/// position of each (`HVert::screen`, formed once per vertex: a mesh's
/// vertex is a corner of about six triangles, and the clip test and the
/// setup of each asked for its two divisions), and where no clip can touch
/// a triangle through it, its snapped position ([`SnapV`]). It derefs to
/// the homogeneous vertices, which the plane set-up and the BSP read alone.
#[derive(Debug, Default)]
struct Projected {
    hv: Vec<HVert>,
    screen: Vec<(f64, f64)>,
    snapped: Vec<SnapV>,
}

/// A vertex's screen position snapped to 1/256 pixel ([`Sub8::snap`]),
/// where the vertex passes `clip_triangle`'s test for a whole triangle
/// (between the near and far planes, inside the guard band); else
/// [`SnapV::CLIP`]. A triangle whose three corners all have one is the
/// whole triangle `clip_triangle` would pass on, and these are the values
/// `push_snapped` would snap from its screen corners: the test and the
/// snap are per vertex, so they are made once per vertex instead of at
/// each of its (about six) triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct SnapV {
    x: i32,
    y: i32,
}

impl SnapV {
    /// A vertex that some clip plane may cut.
    const CLIP: SnapV = SnapV {
        x: i32::MIN,
        y: i32::MIN,
    };

    /// The snapped position of the vertex `p` at `screen`, or
    /// [`SnapV::CLIP`] (NaN coordinates included: every comparison fails).
    fn of(p: &HVert, screen: (f64, f64), near: f64, far: f64) -> SnapV {
        if p.z >= near && p.z <= far && guard_ok(screen) {
            // Inside the guard band |x|, |y| < 2¹⁶ px: below 2²⁴ snapped.
            #[expect(
                clippy::cast_possible_truncation,
                reason = "inside the guard band a snapped coordinate is below 2^24"
            )]
            SnapV {
                x: Sub8::snap(screen.0).0 as i32,
                y: Sub8::snap(screen.1).0 as i32,
            }
        } else {
            SnapV::CLIP
        }
    }
}

/// Inside the guard band (where no guard plane clips).
fn guard_ok(p: (f64, f64)) -> bool {
    p.0.abs() < GUARD_PX && p.1.abs() < GUARD_PX
}

impl std::ops::Deref for Projected {
    type Target = [HVert];

    fn deref(&self) -> &[HVert] {
        &self.hv
    }
}

fn homogeneous(scene: &TriScene, perturb: Perturb) -> Projected {
    let mut p = Projected::default();
    p.fill(scene, perturb);
    p
}

impl Projected {
    /// The projection of `scene`'s vertices, in this one's memory.
    fn fill(&mut self, scene: &TriScene, perturb: Perturb) {
        self.hv.clear();
        self.hv.par_extend(homogeneous_vertices(scene, perturb));
        self.screen.clear();
        self.screen
            .par_extend(self.hv.par_iter().map(HVert::screen));
        let (near, far) = (scene.camera.near(), scene.camera.far());
        self.snapped.clear();
        self.snapped.par_extend(
            self.hv
                .par_iter()
                .zip(self.screen.par_iter())
                .map(|(p, s)| SnapV::of(p, *s, near, far)),
        );
    }
}

fn homogeneous_vertices(
    scene: &TriScene,
    perturb: Perturb,
) -> impl IndexedParallelIterator<Item = HVert> + '_ {
    let cam = &scene.camera;
    let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
    let a = cam.aspect();
    let off = perturb.offset_px;
    scene.positions.par_iter().map(move |p| {
        let DVec3 {
            x: xc,
            y: yc,
            z: zc,
        } = cam.to_view(to_f64(*p));
        match cam.projection() {
            Projection::Perspective { tan_half_fov: t } => HVert {
                xh: (xc / (t * a) + zc) * w / 2.0 + off * zc,
                yh: (zc - yc / t) * h / 2.0 + off * zc,
                w: zc,
                z: zc,
            },
            Projection::Orthographic { view_height: vh } => HVert {
                xh: (xc / (vh * a / 2.0) + 1.0) * w / 2.0 + off,
                yh: (1.0 - yc / (vh / 2.0)) * h / 2.0 + off,
                w: 1.0,
                z: zc,
            },
        }
    })
}

/// The visibility pass alone: depth keys, ids and barycentrics per sample.
#[must_use]
pub fn visibility(scene: &TriScene, opts: &RasterOptions) -> VisibilityBuffers {
    visibility_with(scene, opts, &Rule::ZBuffer)
}

/// How a sample chooses between the triangles that cover it.
#[derive(Clone, Debug)]
pub(crate) enum Rule<'a> {
    /// The nearest (depth key, then triangle id): the z-buffer.
    ZBuffer,
    /// The last drawn: triangles are drawn in order of their rank
    /// (`rank[tri]`, ascending), each overwriting what is there (list
    /// priority, the painter's algorithm).
    Painter(&'a [u32]),
    /// The last drawn of the pieces a BSP tree cut the triangles into: each
    /// covered sample belongs to exactly one piece of its triangle, and the
    /// piece drawn last (highest rank) wins.
    Pieces(&'a bsp::Pieces),
}

/// The visibility pass under a rule.
pub(crate) fn visibility_with(
    scene: &TriScene,
    opts: &RasterOptions,
    rule: &Rule<'_>,
) -> VisibilityBuffers {
    let mut buffers = RasterBuffers::default();
    let stats = visibility_into(scene, opts, rule, &mut buffers);
    VisibilityBuffers {
        key: buffers.key,
        id: buffers.id,
        stats,
    }
}

/// [`visibility_with`] into `buffers` (its keys and ids end there).
fn visibility_into(
    scene: &TriScene,
    opts: &RasterOptions,
    rule: &Rule<'_>,
    buffers: &mut RasterBuffers,
) -> RasterStats {
    let cam = &scene.camera;
    let n = cam.samples();
    let grid = SampleGrid::new(n);
    let (sw, sh) = (cam.sample_width(), cam.sample_height());
    buffers.projected.fill(scene, opts.perturbation());
    let hv = &buffers.projected;
    let perspective = matches!(cam.projection(), Projection::Perspective { .. });

    // Setup: per chunk of triangles, in id order: 4 096 of them, fewer
    // where that would leave under four chunks per thread (a scene of
    // 20 000 triangles made five chunks for 16 threads), down to 512.
    // (The chunks only divide the work: the records, in id order, are the
    // same.)
    let n_tris = scene.len();
    let chunk = (n_tris / (4 * rayon::current_num_threads()).max(1)).clamp(512, 4096);
    let chunks: Vec<(Vec<Record>, Culled)> = (0..n_tris.div_ceil(chunk))
        .into_par_iter()
        .map(|c| {
            records(
                scene,
                hv,
                c * chunk..((c + 1) * chunk).min(n_tris),
                &grid,
                opts.perturbation().fill_rule,
                |obj| {
                    (
                        opts.frustum_cull.get(obj).copied().unwrap_or(false),
                        opts.backface_cull.get(obj).copied().unwrap_or(false),
                    )
                },
            )
        })
        .collect();
    let culled = chunks.iter().fold(Culled::default(), |a, (_, c)| Culled {
        frustum: a.frustum + c.frustum,
        backface: a.backface + c.backface,
    });
    let n_records: usize = chunks.iter().map(|c| c.0.len()).sum();

    // Bin each run of records to bands (a counting sort per run, the runs
    // in parallel): a band then draws run after run its part of each, so
    // in drawing order. The runs: the setup's chunks (id order), or for
    // the painter's rule all the records sorted by rank (a triangle's
    // sub-triangles stay together: stable) and cut into runs.
    let band_h = band_rows(sh, BAND, 8, 1);
    let bands = sh.div_ceil(band_h) as usize;
    let binned: Vec<(Vec<&Record>, Vec<u32>)> = if let Rule::Painter(rank) = rule {
        let mut records: Vec<&Record> = chunks.iter().flat_map(|c| &c.0).collect();
        records.sort_by_key(|r| rank.get(r.tri as usize).copied().unwrap_or(u32::MAX));
        records
            .par_chunks(chunk)
            .map(|run| bin_to_bands(run.iter().copied(), band_h, bands))
            .collect()
    } else {
        chunks
            .par_iter()
            .map(|c| bin_to_bands(c.0.iter(), band_h, bands))
            .collect()
    };

    let total = (sw as usize) * (sh as usize);
    let (key, id) = (&mut buffers.key, &mut buffers.id);
    key.refill(total, u32::MAX);
    id.refill(total, BACKGROUND);
    let depth_map = DepthMap {
        format: opts.depth,
        perspective,
        near: cam.near(),
        far: cam.far(),
    };
    let walk = Walk {
        scene,
        hv,
        grid: &grid,
        sw,
        perspective,
    };
    let band_len = (band_h * sw) as usize;
    // The BSP's rank of the piece each sample shows (0: none yet).
    let mut ranks = match rule {
        Rule::Pieces(_) => vec![0u32; total],
        _ => Vec::new(),
    };
    let rank_bands: Vec<Option<&mut [u32]>> = if ranks.is_empty() {
        (0..bands).map(|_| None).collect()
    } else {
        ranks.chunks_mut(band_len).map(Some).collect()
    };
    let counters: Vec<(u64, u64)> = key
        .par_chunks_mut(band_len)
        .zip(id.par_chunks_mut(band_len))
        .zip(rank_bands)
        .enumerate()
        .map(|(b, ((key, id), rank))| {
            let row0 = u32::try_from(b).unwrap_or(0) * band_h;
            let rows = row0..(row0 + band_h).min(sh);
            let mut writes = 0u64;
            let mut frags = 0u64;
            // (A `Pieces` rule always has its rank bands.)
            let choose = match (rule, rank) {
                (Rule::Pieces(p), Some(rank)) => Choose::Piece(p, rank),
                (Rule::Painter(_), _) => Choose::Last,
                _ => Choose::Nearest,
            };
            let mut band = Band {
                key,
                id,
                row0,
                depth_map: &depth_map,
                choose,
            };
            for (lists, counts) in &binned {
                for r in &lists[counts[b] as usize..counts[b + 1] as usize] {
                    let (w, f) = scan_record(&walk, r, rows.clone(), &mut band);
                    writes += w;
                    frags += f;
                }
            }
            (writes, frags)
        })
        .collect();
    RasterStats {
        triangles: n_tris,
        records: n_records,
        depth_writes: counters.iter().map(|c| c.0).sum(),
        fragments: counters.iter().map(|c| c.1).sum(),
        culled,
        shadow_bvh: false,
        shadow_rays: 0,
        shadow_maps: 0,
    }
}

/// The records of one run listed band by band (rows of `band_h`; each
/// record in every band its rows meet, in the run's order), and where
/// each band's list starts (`bands + 1` offsets).
fn bin_to_bands<'a>(
    run: impl Iterator<Item = &'a Record> + Clone,
    band_h: u32,
    bands: usize,
) -> (Vec<&'a Record>, Vec<u32>) {
    let mut counts = vec![0u32; bands + 1];
    for r in run.clone() {
        for b in (r.rows.0 / band_h)..=((r.rows.1 - 1) / band_h) {
            counts[b as usize + 1] += 1;
        }
    }
    for b in 0..bands {
        counts[b + 1] += counts[b];
    }
    let mut lists: Vec<&Record> = vec![&EMPTY_RECORD; counts[bands] as usize];
    let mut fill = counts.clone();
    for r in run {
        for b in (r.rows.0 / band_h)..=((r.rows.1 - 1) / band_h) {
            lists[fill[b as usize] as usize] = r;
            fill[b as usize] += 1;
        }
    }
    (lists, counts)
}

/// What the near, far and guard planes leave of a triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Clipped {
    /// All of it, inside the guard band (the common case).
    Whole,
    /// The convex polygon left in `poly` (its screen points by
    /// [`clamped_screen`]).
    Polygon,
    /// Nothing.
    Nothing,
}

/// Clips triangle `v` (its vertices' screen positions `screen`) against the
/// near and far planes and, only where a vertex leaves it, the guard band;
/// the polygon is left in `poly`.
fn clip_triangle(
    v: &[HVert; 3],
    screen: &[(f64, f64); 3],
    ctx: &SetupCtx<'_>,
    poly: &mut Vec<HVert>,
    tmp: &mut Vec<HVert>,
) -> Clipped {
    let near = -ctx.clip_planes[0].c[4];
    let far = ctx.clip_planes[1].c[4];
    // The common case: between the near and far planes and inside the
    // guard band (the test `SnapV::of` makes per vertex).
    if v.iter().all(|p| p.z >= near && p.z <= far) && screen.iter().all(|p| guard_ok(*p)) {
        return Clipped::Whole;
    }
    if v.iter().all(|p| p.z < near) || v.iter().all(|p| p.z > far) {
        return Clipped::Nothing;
    }
    poly.clear();
    poly.extend_from_slice(v);
    for (k, plane) in ctx.clip_planes.iter().enumerate() {
        // Planes 0 and 1 are near and far; the guard band only where needed.
        if k > 1 && poly.iter().all(|p| guard_ok(p.screen())) {
            break;
        }
        clip_polygon(poly, plane, tmp);
        std::mem::swap(poly, tmp);
        if poly.len() < 3 {
            return Clipped::Nothing;
        }
    }
    Clipped::Polygon
}

/// The screen point of a vertex the clip made, clamped onto the guard
/// band; `None` when it is not a number.
///
/// A vertex the guard planes made lies on one of them, up to the rounding
/// of its interpolation; with an extreme dynamic range (a near plane of
/// 1e-39 against coordinates of 1e33) that rounding can put it far outside
/// (measured: 1e94 px). Clamping puts it back on the plane it belongs to;
/// the clip computed each shared point once in a canonical order, so
/// neighbours still share it bit for bit.
fn clamped_screen(p: &HVert, ctx: &SetupCtx<'_>) -> Option<(f64, f64)> {
    let (gx, gy) = (
        f64::from(ctx.size.0 / ctx.grid.n) + GUARD_PX,
        f64::from(ctx.size.1 / ctx.grid.n) + GUARD_PX,
    );
    let (x, y) = p.screen();
    if x.is_nan() || y.is_nan() {
        return None;
    }
    Some((x.clamp(-GUARD_PX, gx), y.clamp(-GUARD_PX, gy)))
}

fn setup_triangle(
    (v, screen): (&[HVert; 3], &[(f64, f64); 3]),
    tri: u32,
    cull_back: bool,
    ctx: &SetupCtx<'_>,
    poly: &mut Vec<HVert>,
    tmp: &mut Vec<HVert>,
    out: &mut Vec<Record>,
) -> bool {
    match clip_triangle(v, screen, ctx, poly, tmp) {
        Clipped::Whole => {
            return push_snapped(screen, tri, cull_back, ctx, out);
        }
        Clipped::Nothing => return false,
        Clipped::Polygon => {}
    }
    let mut pts = Vec::with_capacity(poly.len());
    for p in poly.iter() {
        let Some(s) = clamped_screen(p, ctx) else {
            return false;
        };
        pts.push(s);
    }
    let mut culled = false;
    for k in 1..pts.len() - 1 {
        culled |= push_snapped(&[pts[0], pts[k], pts[k + 1]], tri, cull_back, ctx, out);
    }
    culled
}

/// Snaps a screen triangle and records it if it can cover a sample.
fn push_snapped(
    p: &[(f64, f64); 3],
    tri: u32,
    cull_back: bool,
    ctx: &SetupCtx<'_>,
    out: &mut Vec<Record>,
) -> bool {
    let s = p.map(|(x, y)| (Sub8::snap(x).0, Sub8::snap(y).0));
    record_snapped(s, tri, cull_back, ctx, out)
}

/// Records a snapped triangle if it can cover a sample; true when it is a
/// back face culled. (Inlined, as `triangle_planes`: see ARCHITECTURE.md,
/// "The per-sample chain inlined".)
#[inline(always)]
fn record_snapped(
    s: [(i64, i64); 3],
    tri: u32,
    cull_back: bool,
    ctx: &SetupCtx<'_>,
    out: &mut Vec<Record>,
) -> bool {
    let area2 = doubled_area(&s);
    let back = area2 >= 0;
    if area2 == 0 {
        return false;
    }
    if cull_back && back {
        return true;
    }
    let (rows, cols) = bbox_samples(&s, ctx.grid, ctx.size);
    if rows.is_empty() || cols.is_empty() {
        return false;
    }
    #[expect(
        clippy::cast_possible_truncation,
        reason = "snapped coordinates are below 2^26"
    )]
    out.push(Record {
        x: s.map(|q| q.0 as i32),
        y: s.map(|q| q.1 as i32),
        tri,
        rows: (rows.start, rows.end),
        back,
        rule: ctx.rule,
    });
    false
}

/// The planes `λ_i = b_i/w` (2-D homogeneous rasterization, Olano & Greer
/// 1997) and the depth plane of triangle `tri`, relative to `(ax, ay)`;
/// `None` when the triangle's plane passes through the eye.
#[inline(always)]
fn triangle_planes(v: &[HVert; 3], perspective: bool, ax: f64, ay: f64) -> Option<Planes> {
    // Columns h_i = (X_i·w_i, Y_i·w_i, w_i); λ = M⁻¹·(X, Y, 1). The rows of
    // M⁻¹ are (h1 × h2, h2 × h0, h0 × h1) / det.
    let h = v.map(|p| DVec3::new(p.xh, p.yh, p.w));
    let rows = [h[1].cross(h[2]), h[2].cross(h[0]), h[0].cross(h[1])];
    let det = h[0].dot(rows[0]);
    // Singular relative to the columns' lengths: the plane passes through the eye.
    let scale2 = h[0].length_squared() * h[1].length_squared() * h[2].length_squared();
    if det == 0.0 || !det.is_finite() || det * det <= 1e-28 * scale2 {
        return None;
    }
    let inv_det = 1.0 / det;
    let mut lambda = [[0.0; 3]; 3];
    for (l, r) in lambda.iter_mut().zip(rows) {
        let r = r * inv_det;
        // Relative to the anchor: λ_i = r_x·dx + r_y·dy + λ_i(anchor).
        *l = [r.x, r.y, r.x * ax + r.y * ay + r.z];
    }
    // Depth plane: 1/z = Σλ (perspective); z = Σ λ_i z_i (orthographic, Σλ = 1).
    let weights = if perspective {
        [1.0; 3]
    } else {
        [v[0].z, v[1].z, v[2].z]
    };
    let mut depth = [0.0; 3];
    for (w, l) in weights.iter().zip(&lambda) {
        for c in 0..3 {
            depth[c] += w * l[c];
        }
    }
    Some(Planes {
        lambda,
        depth,
        ax,
        ay,
    })
}

/// What every record of one frame is walked against: the scene, its
/// projected vertices, the sample grid and its width, and the projection.
#[derive(Clone, Copy)]
struct Walk<'a> {
    scene: &'a TriScene,
    hv: &'a [HVert],
    grid: &'a SampleGrid,
    /// Samples per row.
    sw: u32,
    perspective: bool,
}

/// Walks the covered samples of one record over `rows`, stepping the
/// perspective-correct planes incrementally along each span (anchored by
/// direct evaluation at the span's first sample). `visit(row, col, λ, d)`
/// receives the stepped `λ_i = b_i/w` and depth-plane value of each sample.
fn walk_record(
    walk: &Walk<'_>,
    r: &Record,
    rows: std::ops::Range<u32>,
    mut visit: impl FnMut(u32, u32, &[f64; 3], f64, &Planes),
) {
    let Walk {
        scene,
        hv,
        grid,
        sw,
        perspective,
    } = *walk;
    let Some(st) = r.snapped() else {
        return;
    };
    let n = f64::from(grid.n);
    let dx = 1.0 / n;
    // The planes are set up on the first covered span only: most records
    // of a dense mesh cover no sample at all.
    let mut planes: Option<Option<(Planes, [f64; 3], f64)>> = None;
    st.for_each_span(grid, rows, 0..sw, |row, cols| {
        let setup = planes.get_or_insert_with(|| {
            let idx = scene.tris[r.tri as usize];
            let v = idx.map(|i| hv[i as usize]);
            let (ax, ay) = (f64::from(r.x[0]) / 256.0, f64::from(r.y[0]) / 256.0);
            triangle_planes(&v, perspective, ax, ay).map(|pl| {
                let step_l = [
                    pl.lambda[0][0] * dx,
                    pl.lambda[1][0] * dx,
                    pl.lambda[2][0] * dx,
                ];
                let step_d = pl.depth[0] * dx;
                (pl, step_l, step_d)
            })
        });
        let Some((pl, step_l, step_d)) = setup else {
            return;
        };
        // Anchor: direct evaluation at the span's first sample.
        let x0 = (f64::from(cols.start) + 0.5) * dx - pl.ax;
        let y = (f64::from(row) + 0.5) * dx - pl.ay;
        let mut l = [
            Planes::eval(&pl.lambda[0], x0, y),
            Planes::eval(&pl.lambda[1], x0, y),
            Planes::eval(&pl.lambda[2], x0, y),
        ];
        let mut d = Planes::eval(&pl.depth, x0, y);
        for col in cols {
            visit(row, col, &l, d, pl);
            l[0] += step_l[0];
            l[1] += step_l[1];
            l[2] += step_l[2];
            d += *step_d;
        }
    });
}

/// One band's depth keys and triangle ids, and how a fragment enters them.
struct Band<'b> {
    key: &'b mut [u32],
    id: &'b mut [u32],
    /// The band's first sample row.
    row0: u32,
    depth_map: &'b DepthMap,
    /// Which fragment a sample keeps.
    choose: Choose<'b>,
}

/// Which of the fragments that cover a sample it keeps.
enum Choose<'b> {
    /// The nearest (depth key, then triangle id): the z-buffer.
    Nearest,
    /// The last drawn (the painter: records come in drawing order).
    Last,
    /// The piece of highest rank, with the band's ranks (rank + 1 of the
    /// piece each sample shows, 0 for none).
    Piece(&'b bsp::Pieces, &'b mut [u32]),
}

/// Scans one record over `rows` (a band): each covered sample takes the
/// record's triangle if it passes the depth test (or always, with
/// `overwrite`: the painter); returns (writes, fragments).
fn scan_record(
    walk: &Walk<'_>,
    r: &Record,
    rows: std::ops::Range<u32>,
    band: &mut Band<'_>,
) -> (u64, u64) {
    let sw = walk.sw;
    let mut writes = 0u64;
    let mut frags = 0u64;
    let n = f64::from(walk.grid.n);
    walk_record(walk, r, rows, |row, col, _, d, _| {
        let i = ((row - band.row0) * sw + col) as usize;
        let k = band.depth_map.key(d);
        frags += 1;
        let wins = match &mut band.choose {
            Choose::Nearest => k < band.key[i] || (k == band.key[i] && r.tri < band.id[i]),
            Choose::Last => true,
            Choose::Piece(pieces, ranks) => {
                // The sample's position, as the coverage rule placed it.
                let (x, y) = ((f64::from(col) + 0.5) / n, (f64::from(row) + 0.5) / n);
                let rank = pieces.rank_at(r.tri, x, y).saturating_add(1);
                let wins = rank > ranks[i];
                if wins {
                    ranks[i] = rank;
                }
                wins
            }
        };
        if wins {
            band.key[i] = k;
            band.id[i] = r.tri;
            writes += 1;
        }
    });
    (writes, frags)
}

/// What triangle setup needs besides the triangle.
struct SetupCtx<'g> {
    clip_planes: [clip::Plane; 6],
    grid: &'g SampleGrid,
    /// Sample grid size.
    size: (u32, u32),
    rule: FillRule,
}

impl<'g> SetupCtx<'g> {
    /// The clip planes and sizes of a scene's camera.
    fn new(scene: &TriScene, grid: &'g SampleGrid, rule: FillRule) -> SetupCtx<'g> {
        let cam = &scene.camera;
        SetupCtx {
            clip_planes: planes(
                cam.near(),
                cam.far(),
                f64::from(cam.width()),
                f64::from(cam.height()),
                GUARD_PX,
            ),
            grid,
            size: (cam.sample_width(), cam.sample_height()),
            rule,
        }
    }
}

/// The records of the triangles in `range`, in id order; `cull(object)`
/// says whether to skip the object (frustum) and whether to cull its back
/// faces.
fn records(
    scene: &TriScene,
    hv: &Projected,
    range: std::ops::Range<usize>,
    grid: &SampleGrid,
    rule: FillRule,
    cull: impl Fn(usize) -> (bool, bool),
) -> (Vec<Record>, Culled) {
    let ctx = SetupCtx::new(scene, grid, rule);
    let mut out = Vec::with_capacity(range.len());
    let mut poly = Vec::with_capacity(8);
    let mut tmp = Vec::with_capacity(8);
    let mut culled = Culled::default();
    for t in range {
        let (skip, cull_back) = cull(scene.tri_object[t] as usize);
        if skip {
            culled.frustum += 1;
            continue;
        }
        let idx = scene.tris[t];
        let tri = u32::try_from(t).unwrap_or(u32::MAX);
        // Corners no clip can touch: the whole triangle, snapped already.
        let sv = idx.map(|i| hv.snapped[i as usize]);
        if sv.iter().all(|c| *c != SnapV::CLIP) {
            let s = sv.map(|c| (i64::from(c.x), i64::from(c.y)));
            if record_snapped(s, tri, cull_back, &ctx, &mut out) {
                culled.backface += 1;
            }
            continue;
        }
        let v = idx.map(|i| hv.hv[i as usize]);
        let screen = idx.map(|i| hv.screen[i as usize]);
        if setup_triangle(
            (&v, &screen),
            tri,
            cull_back,
            &ctx,
            &mut poly,
            &mut tmp,
            &mut out,
        ) {
            culled.backface += 1;
        }
    }
    (out, culled)
}

/// The records of every triangle `opts` does not cull, in id order (the
/// list-priority backends' input).
fn primary_records(
    scene: &TriScene,
    opts: &RasterOptions,
    hv: &Projected,
    grid: &SampleGrid,
) -> Vec<Record> {
    records(
        scene,
        hv,
        0..scene.len(),
        grid,
        opts.perturbation().fill_rule,
        |obj| {
            (
                opts.frustum_cull.get(obj).copied().unwrap_or(false),
                opts.backface_cull.get(obj).copied().unwrap_or(false),
            )
        },
    )
    .0
}

/// Triangles the plan's culling removed from primary visibility.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Culled {
    /// Triangles of objects entirely outside the view frustum.
    pub frustum: usize,
    /// Back faces of closed objects seen from outside.
    pub backface: usize,
}

#[cfg(feature = "testing")]
/// Calls `visit(tri, sx, sy, front)` for every sample the coverage rule
/// gives each triangle (after near/guard clipping), serially, triangle by
/// triangle in id order; `front` is false for a back face (doubled signed
/// area ≥ 0). With `backface_cull`, back faces are skipped.
pub fn cover(scene: &TriScene, backface_cull: bool, mut visit: impl FnMut(u32, u32, u32, bool)) {
    let cam = &scene.camera;
    let grid = SampleGrid::new(cam.samples());
    let hv = homogeneous(scene, Perturb::default());
    let (records, _) = records(scene, &hv, 0..scene.len(), &grid, FillRule::TopLeft, |_| {
        (false, backface_cull)
    });
    for r in records {
        let Some(st) = r.snapped() else { continue };
        st.for_each_span(
            &grid,
            r.rows.0..r.rows.1,
            0..cam.sample_width(),
            |row, cols| {
                for c in cols {
                    visit(r.tri, c, row, !r.back);
                }
            },
        );
    }
}

#[cfg(feature = "testing")]
/// Drift of the incremental interpolation against direct evaluation, over
/// every covered sample of a scene.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drift {
    /// Samples compared.
    pub samples: u64,
    /// Largest |stepped − direct| / |direct| of the depth plane.
    pub depth_rel: f64,
    /// Largest |stepped − direct| of a normalised barycentric weight.
    pub bary_abs: f64,
    /// Largest span length in samples.
    pub longest_span: u32,
}

#[cfg(feature = "testing")]
/// Measures the drift of the incremental depth and barycentrics (the same
/// walk the renderer uses) against direct evaluation of the planes.
#[must_use]
pub fn measure_drift(scene: &TriScene) -> Drift {
    let cam = &scene.camera;
    let grid = SampleGrid::new(cam.samples());
    let hv = homogeneous(scene, Perturb::default());
    let perspective = matches!(cam.projection(), Projection::Perspective { .. });
    let n = f64::from(grid.n);
    let mut drift = Drift::default();
    let (records, _) = records(scene, &hv, 0..scene.len(), &grid, FillRule::TopLeft, |_| {
        (false, false)
    });
    for r in records {
        let mut span_len = 0u32;
        let mut last_row = u32::MAX;
        let walk = Walk {
            scene,
            hv: &hv,
            grid: &grid,
            sw: cam.sample_width(),
            perspective,
        };
        walk_record(&walk, &r, r.rows.0..r.rows.1, |row, col, l, d, pl| {
            if row != last_row {
                last_row = row;
                span_len = 0;
            }
            span_len += 1;
            drift.longest_span = drift.longest_span.max(span_len);
            let x = (f64::from(col) + 0.5) / n - pl.ax;
            let y = (f64::from(row) + 0.5) / n - pl.ay;
            let direct = [
                Planes::eval(&pl.lambda[0], x, y),
                Planes::eval(&pl.lambda[1], x, y),
                Planes::eval(&pl.lambda[2], x, y),
            ];
            let dd = Planes::eval(&pl.depth, x, y);
            if dd != 0.0 {
                drift.depth_rel = drift.depth_rel.max(((d - dd) / dd).abs());
            }
            let sum_s = l[0] + l[1] + l[2];
            let sum_d = direct[0] + direct[1] + direct[2];
            for k in 0..3 {
                drift.bary_abs = drift.bary_abs.max((l[k] / sum_s - direct[k] / sum_d).abs());
            }
            drift.samples += 1;
        });
    }
    drift
}

/// The deferred shading pass: shades the visible samples (`ids`, the visibility pass's) into `frame`,
/// reset to the scene's empty frame first; returns the shadow rays cast
/// and the shadow maps made.
fn shade_pass(
    scene: &TriScene,
    opts: &RasterOptions,
    ids: &[u32],
    frame: &mut Frame,
) -> (u64, usize) {
    let cam = &scene.camera;
    let sw = cam.sample_width();
    let ctx = scene.shade_context(opts.gate_eps, opts.shadows_needed);
    // Shadows: nothing when the plan says no shadow can fall; else a BVH
    // for shadow rays (one `ShadowRays` per row, so its counter is never
    // shared), built by the rule of `BvhBuild::for_rays` for at most one
    // ray per visible sample and shadow-casting light; or the shadow maps.
    let accel = (opts.shadows_needed && opts.shadows == ShadowMode::Rays)
        .then(|| Accel::new(scene, shadow_accel_options(scene, ids)));
    let map = match (opts.shadows_needed, opts.shadows) {
        (true, ShadowMode::Map(res)) => Some(shadow_map::ShadowMaps::new(scene, res)),
        _ => None,
    };
    frame.reset(cam.width(), cam.height(), cam.samples(), scene.background);
    let cam_rays = SampleRays::new(cam);
    let w = sw as usize;
    let shadow_rays: u64 = frame
        .par_bands(1, |band| {
            let rays = accel.as_ref().map(ShadowRays::new);
            let visibility: &dyn Visibility = match (&rays, &map) {
                (Some(r), _) => r,
                (None, Some(m)) => m,
                (None, None) => &Unoccluded,
            };
            let sy = band.y0;
            // With shadow rays, the visible samples are shaded in batches
            // of sixteen: their shadow queries first, answered together
            // (packets per light: neighbours' rays toward one light share
            // their walk), then each sample with its answers.
            let mut batch = ShadeBatch::default();
            // Neighbours in a row mostly see the same triangle: what the
            // shading inputs take from it alone is kept from one to the next.
            let mut last = None;
            for sx in 0..sw {
                let i = (sy as usize) * w + sx as usize;
                let tri = ids[i];
                if tri == BACKGROUND {
                    continue;
                }
                // The weights the ray tracer shades with: the f64 camera
                // ray of this sample against the visible triangle.
                let ray64 = cam_rays.ray(sx, sy);
                // Every sample through the kept parts, even where its
                // triangle is its own alone (most of a mesh finer than the
                // samples): one inlined copy of the shading inputs instead
                // of two made the 940 k bunny's frame 4 % faster and the
                // bundled scenes' 5–12 % (ARCHITECTURE.md, "One path for the
                // raster's shading inputs").
                let (sp, p64) = scene.view_surface_after(&mut last, tri, ray64.origin, ray64.dir);
                let ray = ray64.to_f32();
                let depth = cam.frame_depth(p64);
                let Some(r) = &rays else {
                    let shaded = shade::shade(&ctx, &sp, ray.dir, visibility);
                    band.set(sx, 0, Sample::hit(shaded.local, depth, tri, shaded.flags));
                    continue;
                };
                batch.push(&ctx, sx, tri, sp, ray.dir, depth, r);
                if batch.is_full() {
                    batch.shade(&ctx, r, |sx, s| band.set(sx, 0, s));
                }
            }
            if let Some(r) = &rays {
                batch.shade(&ctx, r, |sx, s| band.set(sx, 0, s));
            }
            rays.as_ref().map_or(0, ShadowRays::cast)
        })
        .into_iter()
        .sum();
    frame.resolve();
    let maps = map.as_ref().map_or(0, shadow_map::ShadowMaps::count);
    (shadow_rays, maps)
}

/// The options of a shadow BVH for a frame whose samples show the
/// triangles `ids`: built as [`BvhBuild::for_rays`] decides for one shadow
/// ray per visible sample and shadow-casting light (an upper bound: only
/// lit sides cast them).
pub(crate) fn shadow_accel_options(scene: &TriScene, ids: &[u32]) -> AccelOptions {
    let visible = ids.iter().filter(|&&id| id != BACKGROUND).count();
    let lights = scene.lights.iter().filter(|l| !l.shadowless).count();
    let rays = u64::try_from(visible.saturating_mul(lights)).unwrap_or(u64::MAX);
    AccelOptions {
        build: BvhBuild::for_rays(rays, scene.len()),
        shadow_rays_per_light: u64::try_from(visible).unwrap_or(u64::MAX),
        ..AccelOptions::default()
    }
}

/// Visible samples of a row waiting to be shaded together (see
/// [`shade_pass`]), with their shadow queries.
#[derive(Default)]
struct ShadeBatch {
    /// (column, triangle, surface point, view direction, shading normal,
    /// frame depth).
    samples: Vec<(
        u32,
        u32,
        shade::SurfacePoint,
        rendiff_core::math::Vec3,
        rendiff_core::math::Vec3,
        f64,
    )>,
    shadows: ShadowBatch,
}

impl ShadeBatch {
    /// Samples per batch: two packets per light. (Each batch's answer
    /// groups its queries by light and calls the packet path once a
    /// light, which reads the light's kept occluder and sets up its
    /// arrays: batches of 16 instead of 8 made the bundled scenes' raster
    /// renders 0.5–1.75 % fewer instructions; 32 were within ±0.2 % of
    /// 16, either way.)
    const SIZE: usize = 16;

    /// Adds a visible sample: its shadow queries, those the shadow cache's
    /// triangle certainly stops answered at once
    /// ([`ShadowBatch::add_with`]).
    #[expect(
        clippy::too_many_arguments,
        reason = "one sample's values, as the band loop holds them"
    )]
    fn push(
        &mut self,
        ctx: &shade::ShadeContext<'_>,
        sx: u32,
        tri: u32,
        sp: shade::SurfacePoint,
        dir: rendiff_core::math::Vec3,
        depth: f64,
        rays: &ShadowRays<'_, '_>,
    ) {
        let n = self.shadows.add_with(ctx, &sp, dir, rays);
        self.samples.push((sx, tri, sp, dir, n, depth));
    }

    fn is_full(&self) -> bool {
        self.samples.len() >= Self::SIZE
    }

    /// Answers the queries together, shades every sample with its answers
    /// (exactly as `shade` with the shadow rays would) and hands each to
    /// `set`; empties the batch. (Out of the band loop: inlined there with
    /// the shading inlined into it, it slowed the loop's shadowless path
    /// by 7–9 %.)
    #[inline(never)]
    fn shade(
        &mut self,
        ctx: &shade::ShadeContext<'_>,
        rays: &ShadowRays<'_, '_>,
        mut set: impl FnMut(u32, Sample),
    ) {
        self.shadows.answer(rays);
        for (k, (sx, tri, sp, dir, n, depth)) in self.samples.iter().enumerate() {
            let answered = self.shadows.answered(k, rays);
            let shaded = shade::shade_with_normal_inlined(ctx, sp, *dir, *n, &answered);
            set(*sx, Sample::hit(shaded.local, *depth, *tri, shaded.flags));
        }
        self.samples.clear();
        self.shadows.clear();
    }
}

#[cfg(test)]
mod tests {
    //! The depth keys' contract: nearer is smaller in every format and
    //! projection, the key range is the format's, and depths outside
    //! [near, far] clamp instead of wrapping.
    use super::*;

    fn maps() -> Vec<DepthMap> {
        let mut out = Vec::new();
        for format in [DepthFormat::F32, DepthFormat::U24, DepthFormat::U16] {
            for perspective in [true, false] {
                out.push(DepthMap {
                    format,
                    perspective,
                    near: 0.1,
                    far: 100.0,
                });
            }
        }
        out
    }

    /// The stepped value the rasterizer interpolates at view depth `z`.
    fn stepped(m: &DepthMap, z: f64) -> f64 {
        if m.perspective { 1.0 / z } else { z }
    }

    /// The per-vertex snap (`SnapV`) is the clip's whole-triangle test and
    /// `push_snapped`'s snap, made once per vertex: for triangles whose
    /// corners sit on both sides of, and exactly on, the near and far
    /// planes and the guard band (and NaN), all three corners have a
    /// `SnapV` exactly where `clip_triangle` passes the triangle whole, and
    /// then they record what `setup_triangle` records.
    #[test]
    fn per_vertex_snaps_are_the_whole_triangle_setup() {
        let (near, far, w, h) = (0.25, 400.0, 320.0, 240.0);
        let grid = SampleGrid::new(2);
        let ctx = SetupCtx {
            clip_planes: planes(near, far, w, h, GUARD_PX),
            grid: &grid,
            size: (640, 480),
            rule: FillRule::TopLeft,
        };
        let zs = [
            near.next_down(),
            near,
            near.next_up(),
            1.0,
            37.5,
            far.next_down(),
            far,
            far.next_up(),
            f64::NAN,
        ];
        let xs = [
            -GUARD_PX,
            (-GUARD_PX).next_up(),
            -3.3,
            0.0,
            100.4,
            319.9,
            GUARD_PX.next_down(),
            GUARD_PX,
            f64::NAN,
        ];
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut pick = |n: usize| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            usize::try_from(state % n as u64).unwrap_or(0)
        };
        let (mut whole, mut clipped) = (0, 0);
        let (mut poly, mut tmp) = (Vec::new(), Vec::new());
        for _ in 0..60_000 {
            let corner = |pick: &mut dyn FnMut(usize) -> usize| {
                let z = zs[pick(zs.len())];
                // Screen positions from the grid of values, or anywhere
                // inside (with sub-pixel ties).
                let sx = if pick(2) == 0 {
                    xs[pick(xs.len())]
                } else {
                    f64::from(u32::try_from(pick(320 * 512)).unwrap_or(0)) / 512.0
                };
                let sy = if pick(2) == 0 {
                    xs[pick(xs.len())]
                } else {
                    f64::from(u32::try_from(pick(240 * 512)).unwrap_or(0)) / 512.0
                };
                (
                    HVert {
                        xh: sx * z,
                        yh: sy * z,
                        w: z,
                        z,
                    },
                    (sx, sy),
                )
            };
            let c = [corner(&mut pick), corner(&mut pick), corner(&mut pick)];
            let v = c.map(|(p, _)| p);
            let screen = c.map(|(_, s)| s);
            let sv = c.map(|(p, s)| SnapV::of(&p, s, near, far));
            let all = sv.iter().all(|x| *x != SnapV::CLIP);
            let is_whole = matches!(
                clip_triangle(&v, &screen, &ctx, &mut poly, &mut tmp),
                Clipped::Whole
            );
            assert_eq!(all, is_whole, "{v:?} {screen:?}");
            if all {
                whole += 1;
                let (mut a, mut b) = (Vec::new(), Vec::new());
                let s = sv.map(|x| (i64::from(x.x), i64::from(x.y)));
                let culled_a = record_snapped(s, 7, true, &ctx, &mut a);
                let culled_b =
                    setup_triangle((&v, &screen), 7, true, &ctx, &mut poly, &mut tmp, &mut b);
                assert_eq!(culled_a, culled_b);
                assert_eq!(a.len(), b.len());
                for (x, y) in a.iter().zip(&b) {
                    assert_eq!((x.x, x.y, x.rows, x.back), (y.x, y.y, y.rows, y.back));
                }
            } else {
                clipped += 1;
            }
        }
        assert!(
            whole > 5_000 && clipped > 5_000,
            "{whole} whole, {clipped} clipped"
        );
    }

    #[test]
    fn nearer_is_never_a_larger_key() {
        for m in maps() {
            let mut last = 0u32;
            for k in 0..=10_000 {
                let z = 0.1 + (100.0 - 0.1) * (f64::from(k) / 10_000.0).powi(3);
                let key = m.key(stepped(&m, z));
                assert!(key >= last, "{:?}: key falls at z = {z}", m.format);
                last = key;
            }
        }
    }

    #[test]
    fn keys_span_the_format_and_clamp() {
        for m in maps() {
            let near = m.key(stepped(&m, m.near));
            let far = m.key(stepped(&m, m.far));
            let before = m.key(stepped(&m, m.near * 0.5));
            let beyond = m.key(stepped(&m, m.far * 2.0));
            match m.format.max_key() {
                Some(max) => {
                    assert_eq!(near, 0, "{:?}", m.format);
                    // The largest key is kept free: max − 1 is the farthest.
                    assert_eq!(f64::from(far), max - 1.0, "{:?}", m.format);
                    assert_eq!(before, 0);
                    assert_eq!(beyond, far);
                }
                None => {
                    assert!(near < far && before <= near && beyond >= far);
                    assert!(beyond < u32::MAX, "u32::MAX stays the empty key");
                }
            }
        }
    }

    #[test]
    fn f32_keys_resolve_a_relative_step_of_a_few_ulps() {
        // Reversed-Z f32 keeps ~2^-23 relative resolution at every depth
        // in perspective: depths 4 ulps of f32 apart get different keys.
        let m = DepthMap {
            format: DepthFormat::F32,
            perspective: true,
            near: 0.1,
            far: 1e4,
        };
        for z in [0.2, 3.0, 70.0, 5000.0] {
            let dz = z * 4.0 * f64::from(f32::EPSILON);
            assert!(m.key(1.0 / z) < m.key(1.0 / (z + dz)), "z = {z}");
        }
    }
}
