//! Backend B: the ray caster/tracer.
//!
//! 1. Primary rays through the sample points of DESIGN.md §2, starting where
//!    they cross the near plane.
//! 2. The closest hit from the [`Accel`] (watertight triangles, ties to the
//!    lower id; analytic spheres, boxes and superellipsoids with `--geometry
//!    analytic`).
//! 3. Barycentrics refined in `f64` on the hit triangle (for primary rays
//!    with the `f64` camera ray), so they agree with the rasterizer's
//!    perspective-correct ones to ~1e-12 before the one rounding to `f32`.
//! 4. `TriScene::surface_at` → `shade::shade`, with hard shadows through
//!    [`ShadowRays`].
//! 5. The ray tree with POV-Ray's semantics: additive reflection,
//!    refraction by the ray's list of refracting objects it is inside,
//!    total internal reflection added unfiltered, nothing at the depth limit.
//!
//! Parallel over bands of 16 sample rows ([`Frame::par_bands`]), each traced in
//! 16×16-sample tiles; every sample is computed independently, so the
//! output is bit-identical for any thread count.

#![warn(missing_docs, missing_debug_implementations)]

use rendiff_accel::{Accel, Hit, ShadowBatch, ShadowRays};
use rendiff_core::camera::SampleRays;
use rendiff_core::color::Rgb;
use rendiff_core::frame::{Frame, Sample};
use rendiff_core::math::{DVec3, Ray, Ray64, Vec3, to_f64};
use rendiff_core::shade::{self, ShadeContext, Shaded, SurfacePoint};
use rendiff_core::tri_scene::{Prim, TriConsts, TriScene};

/// Options of the ray tracer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayOptions {
    /// `max_depth` (POV-Ray's `max_trace_level`; 1 = no ray tree).
    pub max_depth: u32,
    /// Cast shadow rays (the plan turns them off where nothing can shadow).
    pub shadows: bool,
    /// Half-width of the band flagged as a discontinuity (ε_g).
    pub gate_eps: f32,
}

/// Tile side in samples.
const TILE: u32 = 16;
/// A packet of primary rays: 4×2 samples of a tile.
const BLOCK_W: u32 = 4;
/// See [`BLOCK_W`].
const BLOCK_H: u32 = 2;
/// Rays in a packet.
const BLOCK: usize = (BLOCK_W * BLOCK_H) as usize;

/// A primary hit ready to shade ([`Tracer::prepare`]).
type Prepared = (SurfacePoint, DVec3, Vec3, u32);

/// Straight continuations through `ior = 1` surfaces do not use up depth
/// (POV-Ray); this bounds them per path so no scene can recurse without end.
const MAX_STRAIGHT: u32 = 64;

/// What a render cast: the work the plan can save, and the denominators
/// of the ray rates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    /// Primary rays (one per sample).
    pub primary: u64,
    /// Shadow rays.
    pub shadow: u64,
    /// Reflected, refracted and straight-through rays.
    pub secondary: u64,
    /// Reflected and refracted rays by trace level: `by_level[k]` counts
    /// the rays of level `k + 2` (level 1 is the primary rays; the last
    /// entry also holds every deeper level). The seed's ray tree allows
    /// at most `N·2^(k−1)` rays at level `k`.
    pub by_level: [u64; LEVELS],
    /// Straight continuations through `ior = 1` surfaces (they keep their
    /// level, POV-Ray's rule, so they are outside the binary ray tree).
    pub straight: u64,
}

/// Trace levels counted apiece in [`RayStats::by_level`].
pub const LEVELS: usize = 32;

/// Which faces of the triangles the rays of the ray tree can hit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Faces {
    /// Both sides of every triangle: the ray tracer (DESIGN.md §7: it
    /// never culls, since the rays of the ray tree come from behind).
    #[default]
    Both,
    /// Only triangles whose geometric normal `(v1 − v0) × (v2 − v0)` faces
    /// against the ray: back-face culling forced on, to show what it
    /// loses. Shadow rays and analytic shapes are not culled.
    Front,
}

/// What the rays of the ray tree met on back faces (a triangle whose
/// geometric normal faces along the ray: `n·d ≥ 0`), counted by
/// [`render_faces`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CullStats {
    /// Rays (primary, reflected, refracted) whose nearest triangle is a
    /// back face: hit with [`Faces::Both`], lost with [`Faces::Front`]
    /// (the ray goes on to the nearest front face, or the background).
    pub back_faces: u64,
    /// Of those, back faces of closed objects: with outward normals, a ray
    /// meets one first only from inside — the exit surfaces.
    pub exits: u64,
    /// Rays refracted into a closed object, through its surface
    /// (`T·n_g < 0`; at a silhouette a flipped shading normal can bend the
    /// refracted ray straight back out): each must leave it through an exit
    /// surface, unless it meets another object inside.
    pub entries: u64,
}

impl std::ops::Add for CullStats {
    type Output = CullStats;
    fn add(self, o: CullStats) -> CullStats {
        CullStats {
            back_faces: self.back_faces + o.back_faces,
            exits: self.exits + o.exits,
            entries: self.entries + o.entries,
        }
    }
}

impl std::ops::Add for RayStats {
    type Output = RayStats;
    fn add(self, o: RayStats) -> RayStats {
        RayStats {
            primary: self.primary + o.primary,
            shadow: self.shadow + o.shadow,
            secondary: self.secondary + o.secondary,
            by_level: std::array::from_fn(|k| self.by_level[k] + o.by_level[k]),
            straight: self.straight + o.straight,
        }
    }
}

/// Where a ray is in the ray tree: its trace level (POV-Ray's trace level:
/// 1 for primary rays) and how many straight continuations through
/// `ior = 1` surfaces led to it.
#[derive(Clone, Copy, Debug)]
struct Depth {
    level: u32,
    straight: u32,
}

impl Depth {
    const PRIMARY: Depth = Depth {
        level: 1,
        straight: 0,
    };

    /// A reflected or refracted child.
    fn deeper(self) -> Depth {
        Depth {
            level: self.level + 1,
            ..self
        }
    }

    /// A straight continuation: the level is not used up.
    fn straight_on(self) -> Depth {
        Depth {
            straight: self.straight + 1,
            ..self
        }
    }
}

/// One worker's view: the shadow rays it casts and its counters.
struct Worker<'a, 's> {
    vis: ShadowRays<'a, 's>,
    /// What the last triangle a primary ray hit gives every primary hit
    /// on it ([`TriScene::view_surface_after`]; secondary hits, which
    /// rarely repeat a triangle, take the direct path).
    last: Option<TriConsts>,
    secondary: u64,
    by_level: [u64; LEVELS],
    straight: u64,
    cull: CullStats,
}

impl Worker<'_, '_> {
    /// Counts a reflected or refracted ray of `depth`'s level.
    fn count_level(&mut self, depth: Depth) {
        let k = (depth.level as usize).saturating_sub(2).min(LEVELS - 1);
        self.by_level[k] += 1;
    }
}

struct Tracer<'a, 's> {
    accel: &'a Accel<'s>,
    scene: &'s TriScene,
    ctx: ShadeContext<'s>,
    max_depth: u32,
    /// Refracting objects that contain the eye (outermost first).
    eye_inside: Vec<u32>,
    /// Back faces counted (and culled with [`Faces::Front`]); `None`: the
    /// plain path, nothing counted.
    faces: Option<Faces>,
    /// The camera's primary rays.
    rays: SampleRays,
}

/// Renders a scene with the given accelerator.
#[must_use]
pub fn render(accel: &Accel<'_>, opts: &RayOptions) -> Frame {
    render_counted(accel, opts).0
}

/// Renders a scene and counts the rays cast.
#[must_use]
pub fn render_counted(accel: &Accel<'_>, opts: &RayOptions) -> (Frame, RayStats) {
    let mut frame = Frame::new(0, 0, 1, accel.scene().background);
    let stats = render_into(accel, opts, &mut frame);
    (frame, stats)
}

/// [`render_counted`] into `frame` (made the scene's size), in the memory
/// it holds from an earlier frame where that is large enough: the same
/// frame bit for bit, without the fresh memory a frame costs. For a
/// caller that renders frame after frame.
pub fn render_into(accel: &Accel<'_>, opts: &RayOptions, frame: &mut Frame) -> RayStats {
    render_with(accel, opts, None, frame).0
}

/// Renders a scene hitting the given faces, and counts the rays cast and
/// the back faces the ray tree met (hit, or lost to culling).
#[must_use]
pub fn render_faces(
    accel: &Accel<'_>,
    opts: &RayOptions,
    faces: Faces,
) -> (Frame, RayStats, CullStats) {
    let mut frame = Frame::new(0, 0, 1, accel.scene().background);
    let (stats, cull) = render_with(accel, opts, Some(faces), &mut frame);
    (frame, stats, cull)
}

fn render_with(
    accel: &Accel<'_>,
    opts: &RayOptions,
    faces: Option<Faces>,
    frame: &mut Frame,
) -> (RayStats, CullStats) {
    let scene = accel.scene();
    let cam = &scene.camera;
    let ctx = scene.shade_context(opts.gate_eps, opts.shadows);
    let eye = cam.eye_f32();
    // Which refracting objects contain the eye: only needed by the ray tree.
    let spawns = opts.max_depth > 1;
    let mut eye_inside: Vec<u32> = (0..u32::try_from(scene.objects.len()).unwrap_or(0))
        .filter(|_| spawns)
        .filter(|&o| {
            let info = &scene.objects[o as usize];
            let m = &scene.materials[usize::from(info.material)];
            m.is_transparent() && m.ior != 1.0 && accel.contains(o, eye)
        })
        .collect();
    // Outermost first: the larger bounds contain the smaller.
    eye_inside.sort_by(|&a, &b| {
        let va = scene.objects[a as usize].bounds.half_area();
        let vb = scene.objects[b as usize].bounds.half_area();
        vb.total_cmp(&va).then(a.cmp(&b))
    });
    let tracer = Tracer {
        accel,
        scene,
        ctx,
        max_depth: opts.max_depth.max(1),
        eye_inside,
        faces,
        rays: SampleRays::new(cam),
    };
    let sw = cam.sample_width();
    // Bands of TILE sample rows (fewer on many threads: `band_rows`), each
    // traced in tiles TILE samples wide (coherent rays), written straight
    // into the frame's rows.
    frame.reset(cam.width(), cam.height(), cam.samples(), scene.background);
    let rows = rendiff_core::frame::band_rows(cam.sample_height(), TILE, 4, BLOCK_H);
    let stats = frame
        .par_bands(rows, |band| {
            let mut w = Worker {
                vis: ShadowRays::new(accel),
                last: None,
                secondary: 0,
                by_level: [0; LEVELS],
                straight: 0,
                cull: CullStats::default(),
            };
            let mut primary = 0u64;
            // Within a tile, the primary rays of each 4×2 block are traced
            // as one packet (the hits are the single-ray ones bit for bit);
            // rays that count back faces go one by one.
            let unset = Ray64 {
                origin: DVec3::ZERO,
                dir: DVec3::Z,
                t_min: 0.0,
                t_max: 0.0,
            };
            let mut rays = [unset; BLOCK];
            let mut at = [(0u32, 0u32); BLOCK];
            let mut hits = [None; BLOCK];
            let mut prepared: [Option<(Prepared, Vec3)>; BLOCK] = [None; BLOCK];
            let mut batch = ShadowBatch::default();
            for tx in (0..sw).step_by(TILE as usize) {
                let tx1 = (tx + TILE).min(sw);
                for dy in (0..band.rows).step_by(BLOCK_H as usize) {
                    for bx in (tx..tx1).step_by(BLOCK_W as usize) {
                        let mut n = 0;
                        for y in dy..(dy + BLOCK_H).min(band.rows) {
                            for sx in bx..(bx + BLOCK_W).min(tx1) {
                                at[n] = (sx, y);
                                rays[n] = tracer.rays.ray(sx, band.y0 + y);
                                n += 1;
                            }
                        }
                        if tracer.faces.is_none() {
                            accel.intersect_packets(&rays[..n], &mut hits[..n]);
                        } else {
                            for (h, r) in hits[..n].iter_mut().zip(&rays[..n]) {
                                *h = tracer.intersect(r, &mut w);
                            }
                        }
                        // The block's primary shadow queries answered
                        // together (packets per light), then each sample
                        // shaded with its answers and its ray tree traced.
                        batch.clear();
                        for k in 0..n {
                            prepared[k] = hits[k].map(|hit| {
                                let p = tracer.prepare(&rays[k], hit, &mut w.last);
                                let n = batch.add_with(&tracer.ctx, &p.0, p.2, &w.vis);
                                (p, n)
                            });
                            if prepared[k].is_none() {
                                // Keeps the batch's samples numbered as the block's.
                                batch.add_none();
                            }
                        }
                        batch.answer(&w.vis);
                        for k in 0..n {
                            let (sx, y) = at[k];
                            let s = match &prepared[k] {
                                None => Sample::background(scene.background),
                                Some((p, n)) => {
                                    let answered = batch.answered(k, &w.vis);
                                    let shaded = shade::shade_with_normal(
                                        &tracer.ctx,
                                        &p.0,
                                        p.2,
                                        *n,
                                        &answered,
                                    );
                                    tracer.finish(p, &shaded, &mut w)
                                }
                            };
                            band.set(sx, y, s);
                        }
                        primary += n as u64;
                    }
                }
            }
            let stats = RayStats {
                primary,
                shadow: w.vis.cast(),
                secondary: w.secondary,
                by_level: w.by_level,
                straight: w.straight,
            };
            (stats, w.cull)
        })
        .into_iter()
        .fold((RayStats::default(), CullStats::default()), |a, b| {
            (a.0 + b.0, a.1 + b.1)
        });
    frame.resolve();
    stats
}

impl Tracer<'_, '_> {
    /// What shading a primary hit needs: the surface point, the `f64` hit
    /// point, the view direction (the `f32` rounding of the ray's) and the
    /// primitive.
    fn prepare(&self, ray64: &Ray64, hit: Hit, last: &mut Option<TriConsts>) -> Prepared {
        // `Camera::primary_ray` is this ray rounded to f32 (one rounding
        // of each part): derived here rather than computed again.
        let ray = ray64.to_f32();
        let (sp, p64) = self.surface(&hit, ray64.origin, ray64.dir, Some(last));
        (sp, p64, ray.dir, hit.prim)
    }

    /// The sample of a primary hit shaded as `shaded`: its local colour
    /// and its ray tree.
    fn finish(&self, p: &Prepared, shaded: &Shaded, w: &mut Worker<'_, '_>) -> Sample {
        let (sp, p64, dir, prim) = p;
        let mut inside = self.eye_inside.clone();
        let color = shaded.local + self.children(w, sp, shaded, *dir, Depth::PRIMARY, &mut inside);
        Sample::hit(
            color,
            self.scene.camera.frame_depth(*p64),
            *prim,
            shaded.flags,
        )
    }

    /// The nearest hit of a ray of the ray tree on the faces it may hit,
    /// counting the back faces it meets when asked to.
    fn intersect(&self, ray: &Ray64, w: &mut Worker<'_, '_>) -> Option<Hit> {
        let Some(faces) = self.faces else {
            return self.accel.intersect(ray);
        };
        let nearest = self.accel.intersect(ray);
        if let Some(h) = nearest
            && let Prim::Triangle(id) = self.scene.prim(h.prim)
            && self.accel.faces_along(id, ray.dir)
        {
            w.cull.back_faces += 1;
            let object = self.scene.tri_object[id as usize] as usize;
            if self.scene.objects[object].closed {
                w.cull.exits += 1;
            }
            if faces == Faces::Front {
                return self.accel.intersect_front(ray);
            }
        }
        nearest
    }

    /// Shading inputs and the f64 hit point of a hit of the ray `(o, d)`
    /// (the `f64` ray the hit was found on); `last`, where given, keeps
    /// what the last triangle hit gives every hit on it.
    fn surface(
        &self,
        hit: &Hit,
        o: DVec3,
        d: DVec3,
        last: Option<&mut Option<TriConsts>>,
    ) -> (SurfacePoint, DVec3) {
        let scene = self.scene;
        match (scene.prim(hit.prim), last) {
            (Prim::Triangle(id), Some(last)) => scene.view_surface_after(last, id, o, d),
            (Prim::Triangle(id), None) => scene.view_surface(id, o, d),
            (Prim::Analytic(k), _) => {
                let p64 = o + d * hit.t64;
                (scene.analytic_surface_at(k, p64), p64)
            }
        }
    }

    /// Colour along a secondary ray.
    fn trace(&self, w: &mut Worker<'_, '_>, ray: &Ray, depth: Depth, inside: &mut Vec<u32>) -> Rgb {
        w.secondary += 1;
        let Some(hit) = self.intersect(&Ray64::from(ray), w) else {
            return self.scene.background;
        };
        // (Secondary hits rarely repeat a triangle: no kept part.)
        let (sp, _) = self.surface(&hit, to_f64(ray.origin), to_f64(ray.dir), None);
        let shaded = shade::shade(&self.ctx, &sp, ray.dir, &w.vis);
        shaded.local + self.children(w, &sp, &shaded, ray.dir, depth, inside)
    }

    fn spawn(sp: &SurfacePoint, dir: Vec3) -> Ray {
        Ray {
            origin: shade::offset_origin(sp.p, sp.p_error, sp.ng, dir),
            dir,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    /// Reflection and transmission at a hit at `depth`.
    fn children(
        &self,
        w: &mut Worker<'_, '_>,
        sp: &SurfacePoint,
        shaded: &Shaded,
        d: Vec3,
        depth: Depth,
        inside: &mut Vec<u32>,
    ) -> Rgb {
        if depth.level >= self.max_depth {
            return Rgb::BLACK;
        }
        let m = &self.scene.materials[usize::from(sp.material)];
        let mut c = Rgb::BLACK;
        let mut total_internal = false;
        if !shaded.transmit.is_black() {
            if m.ior == 1.0 {
                // POV-Ray: through an ior-1 surface the ray goes on straight
                // and the trace level is not used up.
                if depth.straight < MAX_STRAIGHT {
                    let ray = Self::spawn(sp, d);
                    w.straight += 1;
                    c += shaded.transmit * self.trace(w, &ray, depth.straight_on(), inside);
                }
            } else {
                let obj = sp.object;
                let ior_of = |o: u32| {
                    let info = &self.scene.objects[o as usize];
                    self.scene.materials[usize::from(info.material)].ior
                };
                let current = inside.last().map_or(1.0, |&o| ior_of(o));
                let leaving = inside.contains(&obj);
                let next = if leaving {
                    inside
                        .iter()
                        .rev()
                        .find(|&&o| o != obj)
                        .map_or(1.0, |&o| ior_of(o))
                } else {
                    m.ior
                };
                let eta = current / next;
                match shade::refract(d, shaded.normal, eta) {
                    Some(t) => {
                        let mut child_inside = inside.clone();
                        if leaving {
                            child_inside.retain(|&o| o != obj);
                        } else {
                            child_inside.push(obj);
                            // Through the surface into a closed object (at a
                            // silhouette a flipped shading normal can bend the
                            // refracted ray straight back out).
                            if self.faces.is_some()
                                && self.scene.objects[obj as usize].closed
                                && t.dot(sp.ng) < 0.0
                            {
                                w.cull.entries += 1;
                            }
                        }
                        let ray = Self::spawn(sp, t);
                        w.count_level(depth.deeper());
                        c += shaded.transmit
                            * self.trace(w, &ray, depth.deeper(), &mut child_inside);
                    }
                    None => {
                        // Total internal reflection: the mirror ray, added
                        // unfiltered, staying inside; no `reflection` here.
                        total_internal = true;
                        let dir = shade::reflect_bumped(d, shaded.normal, shaded.raw_normal);
                        let ray = Self::spawn(sp, dir);
                        w.count_level(depth.deeper());
                        c += self.trace(w, &ray, depth.deeper(), inside);
                    }
                }
            }
        }
        if shaded.reflection > 0.0 && !total_internal {
            let dir = shade::reflect_bumped(d, shaded.normal, shaded.raw_normal);
            let ray = Self::spawn(sp, dir);
            w.count_level(depth.deeper());
            c += self.trace(w, &ray, depth.deeper(), inside) * shaded.reflection;
        }
        c
    }
}

#[cfg(test)]
mod tests {
    //! The ray tree's counting rules on scenes where every ray's path is
    //! known: POV-Ray's trace level, the straight continuations that do
    //! not use it up, and their bound.
    use super::*;
    use rendiff_accel::AccelOptions;
    use rendiff_core::camera::{Camera, Projection};
    use rendiff_core::frame::BACKGROUND;
    use rendiff_core::math::{DVec3, Vec3};

    /// Square sheets parallel to z = 0 at the given heights, each two
    /// triangles wider than the view.
    fn sheets(zs: &[f32]) -> Vec<[Vec3; 3]> {
        let mut out = Vec::new();
        for &z in zs {
            let (a, b, c, d) = (
                Vec3::new(-4.0, -4.0, z),
                Vec3::new(4.0, -4.0, z),
                Vec3::new(4.0, 4.0, z),
                Vec3::new(-4.0, 4.0, z),
            );
            out.push([a, b, c]);
            out.push([a, c, d]);
        }
        out
    }

    /// A 4×4 orthographic view from z = `eye_z` down the −z axis.
    fn camera(eye_z: f64) -> Camera {
        Camera::new(
            DVec3::new(0.0, 0.0, eye_z),
            DVec3::new(0.0, 0.0, eye_z - 1.0),
            DVec3::Y,
            Projection::Orthographic { view_height: 1.0 },
            4,
            4,
            1,
            1e-3,
            100.0,
        )
        .unwrap()
    }

    fn render(scene: &TriScene, max_depth: u32) -> (Frame, RayStats) {
        let accel = Accel::new(scene, AccelOptions::default());
        let opts = RayOptions {
            max_depth,
            shadows: false,
            gate_eps: 0.0,
        };
        render_counted(&accel, &opts)
    }

    #[test]
    fn two_facing_mirrors_stop_at_the_trace_level() {
        // The eye between mirrors at z = 0 and z = 2: every primary ray
        // bounces until its level reaches max_depth, so each of the 16
        // samples adds max_depth − 1 secondary rays (the seed's 2ⁿ − 1
        // tree with one branch per node).
        let mut scene = TriScene::from_triangles(camera(1.0), &sheets(&[0.0, 2.0]));
        scene.materials[0].reflection = 1.0;
        for max_depth in [1, 2, 5, 9] {
            let (frame, stats) = render(&scene, max_depth);
            assert_eq!(stats.primary, 16);
            assert_eq!(
                stats.secondary,
                16 * u64::from(max_depth - 1),
                "max_depth {max_depth}"
            );
            // One ray per level: the one branch of each sample's tree.
            for (k, &n) in stats.by_level.iter().enumerate() {
                let level = u32::try_from(k).unwrap() + 2;
                assert_eq!(n, if level <= max_depth { 16 } else { 0 }, "level {level}");
            }
            assert_eq!(stats.straight, 0);
            assert!(frame.id.iter().all(|&id| id != BACKGROUND));
        }
    }

    #[test]
    fn straight_continuations_keep_the_level_and_are_bounded() {
        // Clear ior-1 sheets: a ray goes on straight through each without
        // using up its level. Through 10 sheets a primary ray spawns 10
        // continuations (the last meets the background); through 100 it
        // stops after MAX_STRAIGHT.
        for (n, per_sample) in [(10u16, 10u64), (100, u64::from(MAX_STRAIGHT))] {
            let zs: Vec<f32> = (0..n).map(|k| -f32::from(k) * 0.01).collect();
            let mut scene = TriScene::from_triangles(camera(1.0), &sheets(&zs));
            scene.materials[0].transmit = 1.0;
            scene.materials[0].ior = 1.0;
            let (_, stats) = render(&scene, 2);
            assert_eq!(stats.secondary, 16 * per_sample, "{n} sheets");
            // All of them straight: no level is used up.
            assert_eq!(stats.straight, 16 * per_sample);
            assert!(stats.by_level.iter().all(|&n| n == 0));
            // With max_depth 1 there is no ray tree at all.
            let (_, flat) = render(&scene, 1);
            assert_eq!(flat.secondary, 0);
        }
    }

    #[test]
    fn a_missed_sample_is_the_background() {
        let mut scene = TriScene::from_triangles(camera(1.0), &sheets(&[5.0]));
        scene.background = Rgb::new(0.25, 0.5, 0.75);
        let (frame, stats) = render(&scene, 5);
        assert_eq!(stats.secondary, 0);
        for i in 0..frame.id.len() {
            assert_eq!(frame.id[i], BACKGROUND);
            assert_eq!(frame.depth[i], f32::INFINITY);
            assert_eq!(frame.sample_colors()[i], scene.background);
        }
    }
}
