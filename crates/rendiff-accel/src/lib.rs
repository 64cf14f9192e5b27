//! Ray queries over a `TriScene`: the BVH, the watertight triangle test,
//! the analytic shapes (spheres, boxes, superellipsoids), and the shadow
//! rays of the [`Visibility`] interface.
//!
//! This layer sits below both backends: the ray tracer casts every ray
//! through it, and the rasterizer answers shadow rays through the same
//! [`ShadowRays`] (the hybrid of DESIGN.md §3), so both see the same shadows.

#![warn(missing_docs, missing_debug_implementations)]

mod bvh;
mod light_buffer;
mod triangle;

use bvh::Bvh;
pub use bvh::{BvhHit, BvhStats};
use light_buffer::{Cell, LightBuffers};
use rayon::prelude::*;
use rendiff_core::analytic::sphere::sphere_roots;
use rendiff_core::color::Rgb;
use rendiff_core::math::{DVec3, Ray64, Vec3, to_f64};
pub use rendiff_core::options::BvhBuild;
use rendiff_core::options::Geometry;
use rendiff_core::shade::{Answered, ShadeContext, ShadowQuery, SurfacePoint, Visibility};
use rendiff_core::tri_scene::{Prim, TriScene};
pub use triangle::TriHit;

/// What an accelerator is built over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AccelOptions {
    /// Triangles only, or the analytic shapes (spheres, boxes,
    /// superellipsoids) in place of their triangles.
    pub geometry: Geometry,
    /// A BVH (`true`) or one flat leaf (`false`).
    pub bvh: bool,
    /// How the BVH is built.
    pub build: BvhBuild,
    /// The instruction set of the ray queries.
    pub simd: SimdPath,
    /// About how many shadow rays will be asked toward each light (0:
    /// unknown). A light gets a light buffer (a grid of the triangles
    /// seen from it, which answers most of its rays without a walk) where
    /// that is at least [`AccelOptions::LIGHT_BUFFER_RAYS_PER_TRIANGLE`]
    /// per triangle that casts a shadow: below that, its build (300 to
    /// 2 000 instructions per triangle and light on the bundled scenes)
    /// costs more than the walks it saves (ARCHITECTURE.md).
    pub shadow_rays_per_light: u64,
}

impl AccelOptions {
    /// Shadow rays per casting triangle from which a light buffer pays
    /// (see [`AccelOptions::shadow_rays_per_light`]; the rule is
    /// [`rendiff_core::options::light_buffer_pays`], which the plan shows).
    pub const LIGHT_BUFFER_RAYS_PER_TRIANGLE: u64 =
        rendiff_core::options::LIGHT_BUFFER_RAYS_PER_TRIANGLE;
}

impl Default for AccelOptions {
    fn default() -> Self {
        AccelOptions {
            geometry: Geometry::Mesh,
            bvh: true,
            build: BvhBuild::Sah,
            simd: SimdPath::Auto,
            shadow_rays_per_light: 0,
        }
    }
}

/// The instruction set the ray queries (the walk of the tree and the
/// triangle tests) run with. Every path gives the same hits, bit for bit:
/// the arithmetic is IEEE single and double precision either way, with
/// no fused multiply-adds (a test renders every scene on each path).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SimdPath {
    /// The best the processor has, found at run time: on x86-64 with
    /// AVX2 (x86-64-v3), code compiled for it; else the baseline.
    #[default]
    Auto,
    /// The target's baseline instruction set (SSE2 on x86-64).
    Baseline,
}

/// How a primitive acts on a shadow ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ShadowClass {
    /// Blocks the light.
    Opaque,
    /// Multiplies it by `f·P + t`.
    Transparent,
    /// Casts no shadow (`no_shadow`).
    None,
}

/// A closest hit on a triangle or an analytic shape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter.
    pub t: f32,
    /// Primitive id (a triangle id, or `TriScene::analytic_id` of an
    /// analytic shape).
    pub prim: u32,
    /// Barycentrics from the watertight test (zero for analytic shapes).
    pub b: [f32; 3],
    /// Exact-ish `t` for sphere hits (f64).
    pub t64: f64,
}

/// The ray-query structure of a scene.
#[derive(Debug)]
pub struct Accel<'s> {
    scene: &'s TriScene,
    bvh: Bvh,
    /// Analytic shapes in use (indices into `scene.analytic`).
    analytic: Vec<usize>,
    class: Vec<ShadowClass>,
    analytic_class: Vec<ShadowClass>,
    any_caster: bool,
    /// Every shadow caster is an opaque triangle (no transparent one, no
    /// analytic shape that casts): a shadow ray's answer is then whether
    /// it meets one, and rays can be answered in packets.
    opaque_triangles_only: bool,
    /// The lights' light buffers (where every caster is a triangle).
    light_buffers: LightBuffers,
    /// This structure's number, unique in the process: what a
    /// [`ShadowBatch`]'s certifiers were made for (an address could be a
    /// later structure's).
    id: u64,
}

/// The next [`Accel`]'s number.
static NEXT_ACCEL: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

impl<'s> Accel<'s> {
    /// Builds the structure for a scene.
    #[must_use]
    pub fn new(scene: &'s TriScene, opts: AccelOptions) -> Accel<'s> {
        let analytic: Vec<usize> = if opts.geometry == Geometry::Analytic {
            (0..scene.analytic.len()).collect()
        } else {
            Vec::new()
        };
        let mut analytic_object = vec![false; scene.objects.len()];
        for &k in &analytic {
            analytic_object[scene.analytic[k].object as usize] = true;
        }
        // (The passes over every triangle run in parallel; rayon's
        // collects keep the order.)
        let ids: Vec<u32> = (0..u32::try_from(scene.len()).unwrap_or(u32::MAX))
            .into_par_iter()
            .filter(|&t| !analytic_object[scene.tri_object[t as usize] as usize])
            .collect();
        let tree = match (opts.bvh, opts.build) {
            (false, _) => bvh::Tree::Flat,
            (true, BvhBuild::Sah) => bvh::Tree::Sah,
            (true, BvhBuild::Morton) => bvh::Tree::Morton,
        };
        let mut bvh = Bvh::build(&ids, |id| scene.triangle(id), tree);
        bvh.set_simd(opts.simd);
        let class_of = |object: u32, material: u16| {
            if scene.objects[object as usize].no_shadow {
                ShadowClass::None
            } else if scene.materials[usize::from(material)].is_transparent() {
                ShadowClass::Transparent
            } else {
                ShadowClass::Opaque
            }
        };
        let class: Vec<ShadowClass> = (0..scene.len())
            .into_par_iter()
            .map(|t| class_of(scene.tri_object[t], scene.tri_material[t]))
            .collect();
        let analytic_class: Vec<ShadowClass> = scene
            .analytic
            .iter()
            .map(|s| class_of(s.object, s.material))
            .collect();
        let any_caster = class
            .iter()
            .chain(&analytic_class)
            .any(|c| *c != ShadowClass::None);
        // Every caster a triangle (no analytic shape casts): a light
        // buffer's cell then lists every caster a ray of it can meet.
        let triangles_only = analytic
            .iter()
            .all(|&k| analytic_class[k] == ShadowClass::None);
        let opaque_triangles_only = triangles_only && !class.contains(&ShadowClass::Transparent);
        let light_buffers = if triangles_only && opts.shadow_rays_per_light > 0 {
            let casters = ids
                .iter()
                .filter(|&&id| class[id as usize] != ShadowClass::None)
                .count() as u64;
            let pays =
                rendiff_core::options::light_buffer_pays(opts.shadow_rays_per_light, casters);
            LightBuffers::new(
                scene,
                &ids,
                |l| pays && !scene.lights[l].shadowless,
                |l, id| {
                    // What `accept` takes: casting, and not in a plane
                    // through the point light.
                    class[id as usize] != ShadowClass::None
                        && match scene.lights[l].kind {
                            rendiff_core::shade::LightKind::Point { position } => {
                                !plane_through(scene, id, to_f64(position))
                            }
                            rendiff_core::shade::LightKind::Parallel { .. } => true,
                        }
                },
            )
        } else {
            LightBuffers::default()
        };
        Accel {
            scene,
            bvh,
            analytic,
            class,
            analytic_class,
            any_caster,
            opaque_triangles_only,
            light_buffers,
            id: NEXT_ACCEL.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        }
    }

    /// Whether the shadow rays toward light `light` are answered through
    /// a light buffer: one is built where
    /// [`AccelOptions::shadow_rays_per_light`] pays for it
    /// ([`rendiff_core::options::light_buffer_pays`]) and kept unless more
    /// than a third of its listed cells are crowded (its rays would then
    /// mostly walk, with a lookup added).
    #[must_use]
    pub fn has_light_buffer(&self, light: usize) -> bool {
        self.light_buffers.has(light)
    }

    /// The scene.
    #[must_use]
    pub fn scene(&self) -> &'s TriScene {
        self.scene
    }

    /// BVH statistics.
    #[must_use]
    pub fn stats(&self) -> BvhStats {
        self.bvh.stats()
    }

    /// The instruction set the ray queries run with: `"x86-64-v3"` or
    /// `"baseline"` (see [`SimdPath`]).
    #[must_use]
    pub fn simd(&self) -> &'static str {
        self.bvh.simd_name()
    }

    /// The closest hit in `[ray.t_min, ray.t_max]` (ties: lower id), on the
    /// `f64` ray (see [`Ray64`]).
    #[must_use]
    pub fn intersect(&self, ray: &Ray64) -> Option<Hit> {
        let best = self.bvh.intersect(ray).map(|h| Hit {
            t: h.t,
            prim: h.id,
            b: h.b,
            t64: h.t64,
        });
        self.nearer_analytic(ray, best)
    }

    /// [`Accel::intersect`] of each ray of `rays` into `out` (the same
    /// length), bit for bit, traced eight at a time as packets: the rays of
    /// a packet walk the tree together while they enter the same nodes
    /// (one node fetch, independent slab tests), which pays for coherent
    /// rays such as a 4×2 block of camera rays and costs little for
    /// others.
    ///
    /// # Panics
    ///
    /// When `out` and `rays` differ in length.
    pub fn intersect_packets(&self, rays: &[Ray64], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one hit slot per ray");
        let mut hits = [None; bvh::PACKET];
        for (rs, os) in rays.chunks(bvh::PACKET).zip(out.chunks_mut(bvh::PACKET)) {
            let hits = &mut hits[..rs.len()];
            self.bvh.intersect_packet(rs, hits);
            for ((o, h), r) in os.iter_mut().zip(hits.iter()).zip(rs) {
                let best = h.map(|h| Hit {
                    t: h.t,
                    prim: h.id,
                    b: h.b,
                    t64: h.t64,
                });
                *o = self.nearer_analytic(r, best);
            }
        }
    }

    /// `true` when triangle `tri`'s geometric normal `(v1 − v0) × (v2 − v0)`
    /// faces along `dir` (`n·dir ≥ 0`, in `f64`): a ray in direction `dir`
    /// meets its back face. Closed objects face out (DESIGN.md §7), so a ray
    /// meets a back face of one first only from inside it.
    #[must_use]
    pub fn faces_along(&self, tri: u32, dir: DVec3) -> bool {
        let v = self.scene.triangle_f64(tri);
        (v[1] - v[0]).cross(v[2] - v[0]).dot(dir) >= 0.0
    }

    /// The closest hit as [`Accel::intersect`], on the triangles whose
    /// front faces the ray (see [`Accel::faces_along`]) and the analytic
    /// shapes: back-face culling, which the ray tracer never does; this is
    /// here to show what it would lose. Every triangle hit along the ray
    /// is visited.
    #[must_use]
    pub fn intersect_front(&self, ray: &Ray64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        self.bvh.for_each_hit(ray, bvh::NO_SKIP, |id, h| {
            let nearer = best.is_none_or(|b| h.t64 < b.t64 || (h.t64 == b.t64 && id < b.prim));
            if nearer && !self.faces_along(id, ray.dir) {
                best = Some(Hit {
                    t: h.t,
                    prim: id,
                    b: h.b,
                    t64: h.t64,
                });
            }
            false
        });
        self.nearer_analytic(ray, best)
    }

    /// `best`, or the nearest analytic shape's hit where that is nearer
    /// (equal `t`: the lower id). Inlined for the test of whether there is
    /// any (a triangle scene's rays paid 28 instructions a ray for the call
    /// that passed the hit through).
    #[inline(always)]
    fn nearer_analytic(&self, ray: &Ray64, best: Option<Hit>) -> Option<Hit> {
        if self.analytic.is_empty() {
            best
        } else {
            self.nearer_analytic_shape(ray, best)
        }
    }

    /// [`Accel::nearer_analytic`] where the scene has analytic shapes.
    #[inline(never)]
    fn nearer_analytic_shape(&self, ray: &Ray64, mut best: Option<Hit>) -> Option<Hit> {
        let (o, d) = (ray.origin, ray.dir);
        for &k in &self.analytic {
            let t_max = best.map_or(ray.t_max, |h| h.t64);
            if let Some(t) = self.first_analytic(k, o, d, ray.t_min, t_max) {
                let prim = self.scene.analytic_id(k);
                #[expect(
                    clippy::cast_possible_truncation,
                    reason = "f32 copy of the f64 distance"
                )]
                let t32 = t as f32;
                let better = best.is_none_or(|h| t < h.t64 || (t == h.t64 && prim < h.prim));
                if better {
                    best = Some(Hit {
                        t: t32,
                        prim,
                        b: [0.0; 3],
                        t64: t,
                    });
                }
            }
        }
        best
    }

    /// Does the world ray `o + t·d` pass through the bounds of analytic
    /// shape `k` within `[t_min, t_max]`?
    fn analytic_bounds_hit(&self, k: usize, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> bool {
        let (lo, hi) = self.scene.analytic[k].bounds;
        rendiff_core::analytic::slab_interval(o, d, lo, hi)
            .is_some_and(|(t0, t1)| t0.max(t_min) <= t1.min(t_max))
    }

    /// The nearest crossing of the world ray with analytic shape `k` in
    /// `[t_min, t_max]`.
    fn first_analytic(&self, k: usize, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<f64> {
        if !self.analytic_bounds_hit(k, o, d, t_min, t_max) {
            return None;
        }
        let s = &self.scene.analytic[k];
        match s.world_sphere {
            Some((center, radius)) => {
                let (t0, t1) = sphere_roots(o, d, center, radius)?;
                [t0, t1].into_iter().find(|t| *t >= t_min && *t <= t_max)
            }
            None => {
                let (lo, ld) = s.placed.to_local(o, d);
                s.placed.kind.first(lo, ld, t_min, t_max)
            }
        }
    }

    /// Every crossing of the world ray with analytic shape `k` in
    /// `(t_min, t_max)`.
    fn analytic_crossings(&self, k: usize, o: DVec3, d: DVec3, t_max: f64, out: &mut Vec<f64>) {
        out.clear();
        if !self.analytic_bounds_hit(k, o, d, 0.0, t_max) {
            return;
        }
        let s = &self.scene.analytic[k];
        match s.world_sphere {
            Some((center, radius)) => {
                if let Some((t0, t1)) = sphere_roots(o, d, center, radius) {
                    out.extend([t0, t1].into_iter().filter(|t| *t > 0.0 && *t < t_max));
                }
            }
            None => {
                let (lo, ld) = s.placed.to_local(o, d);
                s.placed.kind.crossings(lo, ld, 0.0, t_max, out);
                out.retain(|t| *t < t_max);
            }
        }
    }

    /// Whether a shadow query leaves the triangle it starts on untested
    /// (its origin strictly on one side of that triangle's plane, its
    /// direction strictly away from it: the exact test could only reject
    /// the triangle). Exposed for the tests that hold it to that.
    #[must_use]
    pub fn skips_its_own_triangle(&self, q: &ShadowQuery) -> bool {
        let ray = shadow_ray(self.scene, q).0;
        leaves_behind(self.scene, q, &ray, &mut None) != bvh::NO_SKIP
    }

    /// The `f64` segment a shadow query is traced on: to a point light,
    /// from the query's origin to the light itself; to a parallel light,
    /// the query's ray widened.
    #[must_use]
    pub fn shadow_segment(&self, q: &ShadowQuery) -> Ray64 {
        shadow_ray(self.scene, q).0
    }

    /// Calls `visit(triangle, hit)` for every triangle hit in
    /// `[ray.t_min, ray.t_max]` (analytic shapes excluded), in no particular
    /// order; stops when `visit` returns `true`.
    pub fn for_each_triangle_hit(&self, ray: &Ray64, visit: impl FnMut(u32, TriHit) -> bool) {
        self.bvh.for_each_hit(ray, bvh::NO_SKIP, visit);
    }

    /// `true` when `p` lies inside the closed object `object` (parity of
    /// the crossings of a ray in a fixed generic direction).
    #[must_use]
    pub fn contains(&self, object: u32, p: Vec3) -> bool {
        if let Some(&k) = self
            .analytic
            .iter()
            .find(|&&k| self.scene.analytic[k].object == object)
        {
            let s = &self.scene.analytic[k];
            let local = s.placed.to_object.transform_point3(to_f64(p));
            return s.placed.kind.contains(local);
        }
        let info = &self.scene.objects[object as usize];
        if !info.closed || !info.bounds.contains(p) {
            return false;
        }
        let ray = Ray64 {
            origin: to_f64(p),
            dir: to_f64(Vec3::new(0.577_215_7, 0.291_3, 0.751_942_6).normalize()),
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        let mut crossings = 0u32;
        self.bvh.for_each_hit(&ray, bvh::NO_SKIP, |id, _| {
            if info.tris.contains(&id) {
                crossings += 1;
            }
            false
        });
        crossings % 2 == 1
    }
}

/// Shadow rays through an [`Accel`]: the [`Visibility`] both backends use.
///
/// It counts the rays it casts. Each worker makes its own instance (two
/// words), so the counter is never contended; the counts are summed.
#[derive(Debug)]
pub struct ShadowRays<'a, 's> {
    accel: &'a Accel<'s>,
    cast: std::sync::atomic::AtomicU64,
    /// The shadow cache of [`ShadowRays::transmittance_packets`], kept
    /// from call to call: per slot (light number mod [`OCCLUDER_SLOTS`]),
    /// the light in the high 30 bits, the entry's two acceptances
    /// ([`Occluder::casts`] and [`Occluder::casts_on_point`], bits 33 and
    /// 32: one word, so an entry is read whole) and, in the low word, the
    /// triangle that stopped its latest stopped ray; `u64::MAX` when there
    /// is none.
    /// (Atomics, for `Sync`; an instance is one worker's, never contended.)
    occluders: [std::sync::atomic::AtomicU64; OCCLUDER_SLOTS],
}

/// Lights whose last occluders a [`ShadowRays`] keeps at once.
const OCCLUDER_SLOTS: usize = 4;

/// Light numbers below this have their occluders kept (30 bits of an
/// entry, less the all-ones that `u64::MAX`, no entry, holds).
const KEPT_LIGHTS: usize = (1 << 30) - 1;

impl<'a, 's> ShadowRays<'a, 's> {
    /// Shadow rays against the given structure.
    #[must_use]
    pub fn new(accel: &'a Accel<'s>) -> ShadowRays<'a, 's> {
        ShadowRays {
            accel,
            cast: std::sync::atomic::AtomicU64::new(0),
            occluders: std::array::from_fn(|_| std::sync::atomic::AtomicU64::new(u64::MAX)),
        }
    }

    /// Shadow rays cast through this instance (queries answered without
    /// a ray, because nothing in the scene casts shadows, are not counted).
    #[must_use]
    pub fn cast(&self) -> u64 {
        self.cast.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// [`Visibility::transmittance`] of each query of `queries` into
    /// `out` (the same length), bit for bit, traced as packets of eight
    /// where every caster is an opaque triangle (then a ray's answer is
    /// whether it meets one, in any order), else one by one. Coherent
    /// queries (the samples of a row toward one light) share their walk.
    /// Inside a shadow, the triangle that stopped the packet's last ray is
    /// tried first on the next packet's rays toward the same light, up to
    /// the first it does not stop (the shadow cache of Haines and
    /// Greenberg's light buffer, kept per light from call to call); the
    /// rest walk. The answers are the same: any accepted hit stops a ray.
    ///
    /// # Panics
    ///
    /// When `out` and `queries` differ in length.
    pub fn transmittance_packets(&self, queries: &[ShadowQuery], out: &mut [Rgb]) {
        assert_eq!(queries.len(), out.len(), "one answer per query");
        let a = self.accel;
        if queries.is_empty() {
            return;
        }
        if !a.any_caster {
            out.fill(Rgb::WHITE);
            return;
        }
        if !a.opaque_triangles_only {
            for (o, q) in out.iter_mut().zip(queries) {
                *o = self.transmittance(q);
            }
            return;
        }
        self.cast
            .fetch_add(queries.len() as u64, std::sync::atomic::Ordering::Relaxed);
        let scene = a.scene;
        let mut rays = [shadow_ray(scene, &queries[0]).0; bvh::PACKET];
        let mut lights = [None; bvh::PACKET];
        let mut skips = [bvh::NO_SKIP; bvh::PACKET];
        let mut blocked = [false; bvh::PACKET];
        // The triangle that stopped each ray.
        let mut stopper = [bvh::NO_SKIP; bvh::PACKET];
        let mut plane = None;
        let mut cache = self.occluder(queries[0].light);
        let buffered = !a.light_buffers.is_empty();
        for (qs, os) in queries.chunks(bvh::PACKET).zip(out.chunks_mut(bvh::PACKET)) {
            for (k, q) in qs.iter().enumerate() {
                (rays[k], lights[k]) = shadow_ray(scene, q);
                skips[k] = leaves_behind(scene, q, &rays[k], &mut plane);
            }
            let m = qs.len();
            let accept = |k: usize, id: u32| {
                a.class[id as usize] != ShadowClass::None
                    && !lights[k].is_some_and(|l| plane_through(scene, id, l))
            };
            if buffered {
                by_buffer(
                    a,
                    (qs, &rays[..m], &lights[..m], &skips[..m]),
                    &accept,
                    &mut blocked,
                    &mut cache,
                );
                for (o, &b) in os.iter_mut().zip(&blocked[..m]) {
                    *o = if b { Rgb::BLACK } else { Rgb::WHITE };
                }
                continue;
            }
            // The rays the cached triangle stops (`Occluder::stops`: why
            // that is the walk's answer), then the walk of the rest.
            let cached = match &cache {
                Some(c) => c.stops(
                    qs,
                    (&rays[..m], &lights[..m], &skips[..m]),
                    &mut blocked,
                    &mut stopper,
                ),
                None => 0,
            };
            if cached == 0 {
                // The whole packet, walked in place.
                walk_some(
                    &a.bvh,
                    (&rays[..m], &skips[..m]),
                    &WHOLE_PACKET[..m],
                    &accept,
                    &mut blocked,
                    &mut stopper,
                );
            } else if cached < m {
                walk_rest(
                    &a.bvh,
                    (&rays[..m], &skips[..m]),
                    &accept,
                    &mut blocked,
                    &mut stopper,
                );
            }
            // The cache follows the row: the packet's last ray's triangle,
            // where it is stopped (inside a shadow; at its edge, the next
            // packet would mostly miss it).
            cache = if blocked[m - 1] {
                Occluder::after(cache, qs[m - 1].light, stopper[m - 1], a)
            } else {
                None
            };
            for (o, &b) in os.iter_mut().zip(&blocked[..m]) {
                *o = if b { Rgb::BLACK } else { Rgb::WHITE };
            }
        }
        self.keep_occluder(queries[queries.len() - 1].light, cache);
    }

    /// The kept occluder of `light` ([`ShadowRays::transmittance_packets`]).
    #[inline(always)]
    fn occluder(&self, light: usize) -> Option<Occluder> {
        let entry =
            self.occluders[light % OCCLUDER_SLOTS].load(std::sync::atomic::Ordering::Relaxed);
        (light < KEPT_LIGHTS && entry >> 34 == light as u64).then(|| self.kept(light, entry))
    }

    /// The entry `entry` of `light`, with its triangle's corners (its
    /// acceptances are kept in the entry: formed again here, at every
    /// call, they cost `near_plane`'s raster render 0.4 % more
    /// instructions).
    #[inline(never)]
    fn kept(&self, light: usize, entry: u64) -> Occluder {
        #[expect(clippy::cast_possible_truncation, reason = "the low word")]
        let id = entry as u32;
        Occluder {
            light,
            id,
            corners: self.accel.scene.triangle(id),
            casts: entry >> 33 & 1 == 1,
            casts_on_point: entry >> 32 & 1 == 1,
        }
    }

    /// Keeps `cache` as the occluder of its light, or, where it is `None`,
    /// forgets that of `light`. (A light number of [`KEPT_LIGHTS`] or more
    /// is never kept: its entry could not be told from none.)
    #[inline(always)]
    fn keep_occluder(&self, light: usize, cache: Option<Occluder>) {
        let (light, entry) = match cache {
            Some(c) if c.light < KEPT_LIGHTS => (
                c.light,
                (c.light as u64) << 34
                    | u64::from(c.casts) << 33
                    | u64::from(c.casts_on_point) << 32
                    | u64::from(c.id),
            ),
            Some(c) => (c.light, u64::MAX),
            None => (light, u64::MAX),
        };
        self.occluders[light % OCCLUDER_SLOTS].store(entry, std::sync::atomic::Ordering::Relaxed);
    }
}

/// The shadow cache's entry: the triangle that stopped the latest stopped
/// ray toward `light`, its corners, and what the packets' `accept` asks of
/// it, formed once.
#[derive(Clone, Copy, Debug)]
struct Occluder {
    light: usize,
    id: u32,
    corners: [Vec3; 3],
    /// `accept`'s answer for a ray that carries no point light's position
    /// (a parallel light's, or a point light's zero or non-finite segment):
    /// the triangle casts.
    casts: bool,
    /// `accept`'s answer for a ray that carries the point light's
    /// position: it casts and its plane does not pass through the light.
    casts_on_point: bool,
}

impl Occluder {
    /// The entry for `light` and triangle `id`. `accept`'s two answers are
    /// formed here, once, instead of at every ray the entry is tried on
    /// (`plane_through` was about 125 instructions a call, 2.6 % of
    /// `near_plane`'s raster render): a packet ray's `lights[k]` is either
    /// `None` or the position `shadow_ray` gives every segment toward
    /// `light`, `to_f64` of the light's own, so `accept(k, id)` is one of
    /// the two.
    fn new(a: &Accel<'_>, light: usize, id: u32) -> Occluder {
        let scene = a.scene;
        let casts = a.class[id as usize] != ShadowClass::None;
        let through = match scene.lights.get(light).map(|l| l.kind) {
            Some(rendiff_core::shade::LightKind::Point { position }) => {
                plane_through(scene, id, to_f64(position))
            }
            _ => false,
        };
        Occluder {
            light,
            id,
            corners: scene.triangle(id),
            casts,
            casts_on_point: casts && !through,
        }
    }

    /// The entry for `light` and triangle `id`: `cache` where it is that,
    /// else formed.
    #[inline(never)]
    fn after(cache: Option<Occluder>, light: usize, id: u32, a: &Accel<'_>) -> Option<Occluder> {
        match cache {
            Some(c) if (c.light, c.id) == (light, id) => Some(c),
            _ => Some(Occluder::new(a, light, id)),
        }
    }

    /// What `accept` answers for this entry's triangle and a ray toward
    /// its light whose point light's position is `point` (`lights[k]`).
    #[inline(always)]
    fn accepts(&self, point: Option<DVec3>) -> bool {
        if point.is_some() {
            self.casts_on_point
        } else {
            self.casts
        }
    }

    /// Marks in `blocked` (and `stopper`) the rays of a packet toward its
    /// light that the triangle stops, clearing the others; returns how
    /// many it stops. A ray is stopped when some triangle but its skip
    /// meets it and is accepted: this triangle, met by the walks' own
    /// test ([`triangle::meets`]), answers for a ray it stops as the walk
    /// would, since the walk reaches every triangle that test meets
    /// (`for_each_hit`'s set is that test's whole set: a property test for
    /// rays in general, `rays_in_box_faces_meet_what_the_test_meets` for
    /// rays lying in box faces) and any accepted one stops the ray
    /// ([`Occluder::accepts`]: `accept`'s answer, kept). (Out of line, as
    /// `walk_rest`: inlined, the two cost `grazing`, which has no stopped
    /// ray, 0.4 %.)
    #[inline(never)]
    fn stops(
        &self,
        queries: &[ShadowQuery],
        (rays, lights, skips): (&[Ray64], &[Option<DVec3>], &[u32]),
        blocked: &mut [bool; bvh::PACKET],
        stopper: &mut [u32; bvh::PACKET],
    ) -> usize {
        let mut count = 0;
        for (k, (((q, ray), &light), &skip)) in
            queries.iter().zip(rays).zip(lights).zip(skips).enumerate()
        {
            blocked[k] = q.light == self.light
                && skip != self.id
                && self.accepts(light)
                && triangle::meets(ray, &self.corners).is_some();
            if !blocked[k] {
                // Past the shadow's edge: the rest walk (from here on,
                // neighbours of a lit ray).
                for b in &mut blocked[k + 1..rays.len()] {
                    *b = false;
                }
                break;
            }
            stopper[k] = self.id;
            count += 1;
        }
        count
    }
}

/// What certifies, from a surface point alone, that a point light's
/// shadow ray from it is stopped by one triangle: the shadow cache's, for
/// [`ShadowBatch::add_with`]. Formed once per cache entry.
///
/// **Why its answer is the packets'.** A query's ray runs from the offset
/// origin `o` (`offset_origin`: within `δ` of the surface point `P` on
/// every axis, `δ` bounded from `P`'s error bound and normal, of any
/// sign or length) to the
/// light `L`, and any accepted triangle but its skipped one that the `f64`
/// test meets stops it. The triangle `T` here is accepted (the entry's
/// `casts_on_point`: it casts, and its plane does not pass through `L`)
/// and is not the sample's own (`sp.prim`), so never the skipped one; it
/// remains to show that the test meets it. Let `a_i = V_i − L` and, for
/// each edge `(i, j)` with opposite corner `k`, `n_ij = σ·a_i × a_j`, `σ`
/// the sign of `a_0 · (a_1 × a_2)` (so that `n_ij · a_k > 0`). A point
/// `o` with `n_ij · (o − L) > 0` for all three edges lies in the open cone
/// from `L` through `T`; if it also lies strictly on the far side of
/// `T`'s plane from `L`, the segment crosses that plane at a point `X`
/// strictly inside `T`, strictly between `o` and `L`.
///
/// The `f64` test errs by rounding: its edge functions, 2-D cross
/// products of the sheared corners, carry an error below about 20 ulp of
/// the translated coordinates squared (under `6S`, where `S` bounds every
/// coordinate of `o`, `L` and the corners: the same accounting as the
/// light buffer's, `light_buffer`), under `8·10⁻¹⁴·S²`. An edge function
/// is `|V_j' − V_i'|` times the distance of the ray's point from the
/// edge's line, both in the ray's projection. Along a direction at angle
/// `θ` from `T`'s normal the projection shrinks lengths in `T`'s plane by
/// at most `cos θ`, so the edge function is at least `|V_j − V_i| ·
/// cos²θ · dist(X, plane through L, V_i, V_j)` (the distance from `X` to
/// that plane is at most its distance from the edge's line). And
/// `dist(X, plane) = dist(o, plane)·|X − L|/|o − L|`, with `|X − L| ≥ h_L`
/// (the light's distance from `T`'s plane) and `cos θ = (h_L + h_o)/|o −
/// L| ≥ h_L/|o − L|`. So each edge function's sign is certain when
/// `dist(o, plane_ij)·h_L³·|V_j − V_i|/|o − L|³ > 10⁻¹¹·S²` (125 times the
/// error above); the three then agree, and `det`, their sum, is not zero.
/// The test's distance is `|X − o| ≥ h_o` and it ends `|L − X| ≥ h_L`
/// before `t_max = |L − o|`. The test accepts a hit beyond its own bound
/// `δt`, which is under `1.05·10⁻¹²·S³/det` (pbrt-v4's, with the sheared
/// coordinates under `4S` and `4S` and the scaled depths under `3.5S`),
/// and its computed `t` errs by up to `δt`; `det`, twice the triangle's
/// area in the ray's projection, is at least `|n_T|·cos θ ≥ |n_T|·h_L/|o −
/// L|`. So `h_o·h_L·|n_T| > 10⁻¹¹·S³·|o − L|` and `h_L²·|n_T| >
/// 10⁻¹¹·S³·|o − L|` put the hit beyond `2δt` and `2δt` before the end
/// (a sliver's small `det` makes `δt` large: a review found a sliver of
/// aspect 10⁻⁶ near the origin whose hit the test rejects, certified by
/// the first form, which bounded `δt` by `10⁻⁹·S` alone); both are also
/// kept above `10⁻⁹·S`. Every
/// quantity is bounded conservatively: `dist(o, ·)` by the value at `P`
/// less `δ` times the normal's 1-norm and `10⁻¹³` times the absolute
/// products (the `f64` rounding of these few operations is under
/// `10⁻¹⁵` of them), `|o − L|` by the 1-norm of `P − L` plus `3δ`, and
/// the per-triangle factors with a relative allowance far above their
/// rounding. A non-finite input fails a comparison and certifies nothing.
/// (As for the light buffer, this assumes a real mesh's triangles, not a
/// sliver whose edge is below the rounding of its coordinates.)
#[derive(Clone, Copy, Debug)]
struct Certifier {
    id: u32,
    light: DVec3,
    v0: DVec3,
    /// Per edge: `n_ij`, its absolute products (`|a_i| × |a_j|`, which
    /// bound `n_ij`'s and `n_ij · Δ`'s rounding), its 1-norm bound, and
    /// `h_L³·|V_j − V_i| / |n_ij|` rounded down.
    edges: [(DVec3, DVec3, f64, f64); 3],
    /// `T`'s normal pointing away from the light, its absolute products,
    /// 1-norm bound and length rounded up.
    normal: (DVec3, DVec3, f64, f64),
    /// The light's distance from `T`'s plane, rounded down.
    h_light: f64,
    /// The largest coordinate of the light and the corners.
    scale: f64,
}

/// The absolute products of `a × b`: `|a_y b_z| + |a_z b_y|`, and so on.
#[inline(always)]
fn abs_cross(a: DVec3, b: DVec3) -> DVec3 {
    let (a, b) = (a.abs(), b.abs());
    DVec3::new(
        a.y * b.z + a.z * b.y,
        a.z * b.x + a.x * b.z,
        a.x * b.y + a.y * b.x,
    )
}

/// The `10⁻¹³` relative allowance for the rounding of a few `f64`
/// operations (under `10⁻¹⁵`), see [`Certifier`].
const CERTIFY_ROUNDING: f64 = 1e-13;

impl Certifier {
    /// The certifier of the shadow cache's `entry` for `light` (see
    /// [`ShadowRays`]); `None` unless the light is a point light, the
    /// entry's triangle is accepted for rays toward it, and the light lies
    /// clearly off its plane and out of the planes of its edges.
    fn new(scene: &TriScene, light: usize, entry: u64) -> Option<Certifier> {
        #[expect(clippy::cast_possible_truncation, reason = "the low word")]
        let id = entry as u32;
        let casts_on_point = entry >> 32 & 1 == 1;
        let rendiff_core::shade::LightKind::Point { position } = scene.lights.get(light)?.kind
        else {
            return None;
        };
        if !casts_on_point || id as usize >= scene.len() {
            return None;
        }
        let l = to_f64(position);
        let v = scene.triangle(id).map(to_f64);
        let a = v.map(|x| x - l);
        let triple = a[0].dot(a[1].cross(a[2]));
        let triple_bound = CERTIFY_ROUNDING * a[0].abs().dot(abs_cross(a[1], a[2]));
        // (Written as tests that a NaN fails.)
        let oriented = triple.abs() > triple_bound;
        if !oriented {
            return None;
        }
        let sigma = triple.signum();
        let e1 = v[1] - v[0];
        let e2 = v[2] - v[0];
        let nt = e1.cross(e2);
        let nt_abs = abs_cross(e1, e2);
        let to_light = l - v[0];
        let g_light = nt.dot(to_light);
        let g_bound = CERTIFY_ROUNDING * nt_abs.dot(to_light.abs());
        let nt_len = nt.length() * (1.0 + CERTIFY_ROUNDING);
        let h_light = (g_light.abs() - g_bound) / nt_len * (1.0 - CERTIFY_ROUNDING);
        let off_plane = h_light > 0.0;
        if !off_plane {
            return None;
        }
        let slack = 1.0 + CERTIFY_ROUNDING;
        let edge = |i: usize, j: usize| {
            let n = a[i].cross(a[j]) * sigma;
            let n_abs = abs_cross(a[i], a[j]);
            let n_len = n.length() * slack;
            let side = (v[j] - v[i]).length() * (1.0 - CERTIFY_ROUNDING);
            let factor = h_light * h_light * h_light * side / n_len * (1.0 - CERTIFY_ROUNDING);
            (n, n_abs, (n_abs.x + n_abs.y + n_abs.z) * slack, factor)
        };
        let far = -g_light.signum();
        let scale = v
            .iter()
            .fold(l.abs().max_element(), |m, p| m.max(p.abs().max_element()));
        Some(Certifier {
            id,
            light: l,
            v0: v[0],
            edges: [edge(0, 1), edge(1, 2), edge(2, 0)],
            normal: (
                nt * far,
                nt_abs,
                (nt_abs.x + nt_abs.y + nt_abs.z) * slack,
                nt_len,
            ),
            h_light,
            scale,
        })
    }

    /// `true` when the shadow ray toward the light from `sp` (from its
    /// offset origin, as `shadow_query` forms it) is certainly stopped by
    /// the triangle (see [`Certifier`]).
    #[inline(always)]
    fn stops(&self, sp: &SurfacePoint) -> bool {
        if sp.prim == self.id {
            return false;
        }
        let p = to_f64(sp.p);
        let ng = to_f64(sp.ng).abs();
        // `offset_origin`'s `d` is this dot in `f32` (of either sign, if
        // an error bound were negative), and its offset `ng·d`.
        let spread = ng.dot(to_f64(sp.p_error)).abs() * ng.max_element().max(1.0);
        let p_max = p.abs().max_element();
        // |o − P| on every axis: the offset and its rounding and one-ulp
        // bump (each under 2⁻²³ of the coordinate, or 2⁻¹⁴⁹ among
        // subnormals), with room.
        let delta = 1.1 * spread + (p_max + spread) * (1.0 / f64::from(1u32 << 20)) + 1e-44;
        let s = p_max.max(self.scale) + delta;
        let d = p - self.light;
        let d_abs = d.abs();
        let reach = d_abs.x + d_abs.y + d_abs.z + 3.0 * delta;
        let need = 1e-11 * s * s * reach * reach * reach;
        for (n, n_abs, n1, factor) in &self.edges {
            let side = n.dot(d) - CERTIFY_ROUNDING * n_abs.dot(d_abs) - n1 * delta;
            let inside = side * factor > need;
            if !inside {
                return false;
            }
        }
        let (n, n_abs, n1, n_len) = &self.normal;
        let q = p - self.v0;
        // `|n|·h_o`, the origin's distance beyond the plane, bounded below.
        let beyond = n.dot(q) - CERTIFY_ROUNDING * n_abs.dot(q.abs()) - n1 * delta;
        let margin = 1e-9 * s;
        // The test's `δt` is under `1.05·10⁻¹²·S³/det` and `det ≥ |n|·cos θ
        // ≥ |n|·h_L/|o − L|`: the hit's `t` (at least `h_o`) and its
        // distance from the end (at least `h_L`) must both exceed twice
        // that (the computed `t` errs by up to `δt`), with room.
        let room = 1e-11 * s * s * s * reach;
        self.h_light > margin
            && beyond > margin * n_len
            && beyond * self.h_light > room
            && self.h_light * self.h_light * n_len > room
    }
}

/// Answers a packet's rays into `blocked` through the light buffers: a
/// ray whose cell is empty is lit, one whose cell lists a few triangles
/// is tested against them (the walks' leaf test), and the rest walk the
/// tree as a smaller packet. (See `light_buffer`: why these are the
/// walk's answers.)
#[inline(never)]
fn by_buffer(
    a: &Accel<'_>,
    (queries, rays, lights, skips): PacketRays<'_>,
    accept: &impl Fn(usize, u32) -> bool,
    blocked: &mut [bool; bvh::PACKET],
    cache: &mut Option<Occluder>,
) {
    let lb = &a.light_buffers;
    let mut of = [0usize; bvh::PACKET];
    let mut n = 0;
    // The shadow cache is tried first, as in the walk's path, from the
    // packet's first ray up to the first it does not stop: inside a
    // shadow, that answers a ray before its cell is looked up.
    let mut try_cache = true;
    for (k, ((q, ray), &light)) in queries.iter().zip(rays).zip(lights).enumerate() {
        if try_cache {
            if let Some(c) = cache
                && c.light == q.light
                && c.id != skips[k]
                && c.accepts(light)
                && triangle::meets(ray, &c.corners).is_some()
            {
                blocked[k] = true;
                continue;
            }
            try_cache = false;
        }
        let leaf = match lb.cell(q.light, ray, light, q.dir) {
            Cell::Empty => {
                blocked[k] = false;
                continue;
            }
            Cell::Leaf(leaf) => {
                // Lit without a test where the ray keeps clear of every
                // plane of the cell's triangles (`CullPlane::clear_of`), as
                // of the floor's other triangle from the floor.
                if lb.clear_of_all(leaf, ray, skips[k]) {
                    blocked[k] = false;
                    continue;
                }
                leaf
            }
            Cell::Walk => {
                of[n] = k;
                n += 1;
                continue;
            }
        };
        let mut stopper = bvh::NO_SKIP;
        blocked[k] = lb
            .leaves()
            .leaf_any(ray, skips[k], lb.first_pack(leaf), |id, _| {
                let stops = accept(k, id);
                if stops {
                    stopper = id;
                }
                stops
            });
        if blocked[k] {
            *cache = Occluder::after(*cache, q.light, stopper, a);
        }
    }
    if n > 0 {
        let mut stopper = [bvh::NO_SKIP; bvh::PACKET];
        walk_some(
            &a.bvh,
            (rays, skips),
            &of[..n],
            accept,
            blocked,
            &mut stopper,
        );
        // The cache follows the last walked ray's stopper, where it is
        // stopped.
        let last = of[n - 1];
        if blocked[last] {
            *cache = Occluder::after(*cache, queries[last].light, stopper[last], a);
        }
    }
    // As in the walk's path, a packet whose last ray is lit clears the
    // cache (at a shadow's edge, the next packet would mostly miss it).
    if !blocked[queries.len() - 1] {
        *cache = None;
    }
}

/// A packet's queries, their rays, their point lights' positions and
/// their skipped triangles.
type PacketRays<'p> = (
    &'p [ShadowQuery],
    &'p [Ray64],
    &'p [Option<DVec3>],
    &'p [u32],
);

/// The any-hit walk of the rays of a packet that `blocked` leaves
/// unmarked, as a smaller packet; marks those it stops (and `stopper`).
#[inline(never)]
fn walk_rest(
    bvh: &Bvh,
    rays: (&[Ray64], &[u32]),
    accept: &impl Fn(usize, u32) -> bool,
    blocked: &mut [bool; bvh::PACKET],
    stopper: &mut [u32; bvh::PACKET],
) {
    let mut of = [0usize; bvh::PACKET];
    let mut n = 0;
    for k in (0..rays.0.len()).filter(|&k| !blocked[k]) {
        of[n] = k;
        n += 1;
    }
    walk_some(bvh, rays, &of[..n], accept, blocked, stopper);
}

/// Every ray of a packet, as the `of` of [`walk_some`].
const WHOLE_PACKET: [usize; bvh::PACKET] = {
    let mut all = [0; bvh::PACKET];
    let mut k = 0;
    while k < bvh::PACKET {
        all[k] = k;
        k += 1;
    }
    all
};

/// The any-hit walk of the rays `of` of a packet (indices into `rays`,
/// increasing) as a smaller packet: sets their `blocked` (and `stopper`
/// where stopped). Where `of` is the whole packet (every ray's light
/// buffer cell crowded, or a packet the shadow cache stopped none of),
/// the packet's own arrays are walked: gathering
/// them cost `many_lights`, whose rays all land in crowded cells, 1.5 %
/// more instructions (ARCHITECTURE.md, "Crowded cells").
#[inline(always)]
fn walk_some(
    bvh: &Bvh,
    (rays, skips): (&[Ray64], &[u32]),
    of: &[usize],
    accept: &impl Fn(usize, u32) -> bool,
    blocked: &mut [bool; bvh::PACKET],
    stopper: &mut [u32; bvh::PACKET],
) {
    let n = of.len();
    if n == 0 {
        return;
    }
    if n == rays.len() {
        // Every ray of the packet: `of` (increasing, below `n`) is `0..n`,
        // so the packet is walked in place, without gathering a copy.
        debug_assert!(of.iter().enumerate().all(|(j, &k)| j == k), "of is 0..n");
        bvh.any_packet(
            rays,
            &skips[..n],
            |j, id, _| {
                let stops = accept(j, id);
                if stops {
                    stopper[j] = id;
                }
                stops
            },
            &mut blocked[..n],
        );
        return;
    }
    let rest_rays: [Ray64; bvh::PACKET] = std::array::from_fn(|j| rays[of[j.min(n - 1)]]);
    let rest_skips: [u32; bvh::PACKET] = std::array::from_fn(|j| skips[of[j.min(n - 1)]]);
    let mut walked = [false; bvh::PACKET];
    bvh.any_packet(
        &rest_rays[..n],
        &rest_skips[..n],
        |j, id, _| {
            let stops = accept(of[j], id);
            if stops {
                stopper[of[j]] = id;
            }
            stops
        },
        &mut walked[..n],
    );
    for (&k, &w) in of.iter().zip(&walked[..n]) {
        blocked[k] = w;
    }
}

/// The shadow queries of a batch of samples, answered together: each
/// sample's queries as `shade` makes them ([`ShadowBatch::add`]), traced
/// light by light as packets ([`ShadowRays::transmittance_packets`]), and
/// served back to `shade` sample by sample ([`ShadowBatch::answered`]).
/// Holds its buffers from batch to batch.
#[derive(Debug, Default)]
pub struct ShadowBatch {
    /// Where each sample's answers start in `answers`.
    starts: Vec<usize>,
    /// The queries formed (those not answered as they were added).
    queries: Vec<ShadowQuery>,
    /// Where each query's answer is in `answers`, once one query was
    /// answered as it was added.
    slots: Vec<usize>,
    /// Each query's light, and its answer once [`ShadowBatch::answer`] ran
    /// (or as it was added: [`ShadowBatch::add_with`]).
    answers: Vec<(usize, Rgb)>,
    /// Queries answered as they were added since the last clear (while
    /// none is, `slots` is empty: each query's answer has its index).
    certified: usize,
    /// Lights whose certifiers [`ShadowBatch::add_with`] tries (see
    /// [`ShadowBatch::arm`]): where none is, it is [`ShadowBatch::add`].
    armed: usize,
    /// Per light (below [`CERTIFIED_LIGHTS`]): the shadow cache's entry
    /// its certifier was made for (`u64::MAX`: none yet), and the
    /// certifier.
    certifiers: Vec<CertifierSlot>,
    order: Vec<usize>,
    group: Vec<ShadowQuery>,
    group_answers: Vec<Rgb>,
}

/// Lights whose queries [`ShadowBatch::add_with`] may answer as they are
/// added (a certifier each).
const CERTIFIED_LIGHTS: usize = 64;

/// Queries a light's certifier may fail to answer in one batch before the
/// rest of the batch's queries toward that light go straight to the
/// packets: outside the triangle's shadow it stops no ray, and each try
/// costs about a hundred instructions.
const CERTIFIER_MISSES: u8 = 1;

/// A light's [`Certifier`] in a [`ShadowBatch`]. A new shadow cache entry
/// gets its certifier at once while the light's certifiers answer
/// queries; once one answered none, only an entry that stayed the cache's
/// over two answers in a row does (a triangle whose shadow covers more
/// than a packet, as a box's face on a floor). Where the cache's triangle
/// changes from packet to packet (the small triangles of a tessellated
/// sphere's shadow, a mesh's self-shadowing), making a certifier at every
/// entry (about 400 instructions) cost more than it saved.
#[derive(Clone, Copy, Debug)]
struct CertifierSlot {
    /// The cache's entry at the last answer (`u64::MAX`: none).
    seen: u64,
    /// The entry the certifier was made for.
    made_for: u64,
    /// The structure ([`Accel`]'s number) the certifier was made with.
    accel: u64,
    /// Tries that failed in this batch.
    misses: u8,
    /// Queries the certifier answered (up to `u8::MAX`).
    answered: u8,
    /// Tried in this batch: the light's cache holds a triangle, and the
    /// certifier has misses left.
    live: bool,
    certifier: Option<Certifier>,
}

impl Default for CertifierSlot {
    fn default() -> Self {
        CertifierSlot {
            seen: u64::MAX,
            made_for: u64::MAX,
            accel: u64::MAX,
            misses: 0,
            answered: 0,
            live: false,
            certifier: None,
        }
    }
}

impl CertifierSlot {
    /// Whether the light's certifier answered a query (or it has none
    /// yet): then a new cache entry gets its certifier at once.
    fn productive(&self) -> bool {
        self.certifier.is_none() || self.answered != 0
    }
}

impl ShadowBatch {
    /// Adds a sample: the shadow queries `shade` makes at `sp` seen along
    /// `d` ([`rendiff_core::shade::shadow_queries`]); returns the shading
    /// normal for [`rendiff_core::shade::shade_with_normal`].
    pub fn add(&mut self, ctx: &ShadeContext<'_>, sp: &SurfacePoint, d: Vec3) -> Vec3 {
        self.starts.push(self.answers.len());
        rendiff_core::shade::shadow_queries_pending(ctx, sp, d, |p| {
            if self.certified != 0 {
                self.slots.push(self.answers.len());
            }
            self.answers.push((p.index, Rgb::WHITE));
            self.queries.push(p.form_segment());
        })
    }

    /// [`ShadowBatch::add`], answering at once, without forming its ray,
    /// a query toward a point light that a triangle the shadow cache of
    /// `rays` held certainly stops (the argument is the private
    /// `Certifier`'s): the answer the packets would give (any accepted
    /// triangle met stops the ray), from the surface point alone. Inside
    /// a large shadow that saves forming, preparing and testing the ray,
    /// about 640 instructions a query.
    /// Batches filled this way answer every query as with `add`, and
    /// count the same rays cast; answer each batch once
    /// ([`ShadowBatch::answer`]) before it is cleared.
    #[inline(always)]
    pub fn add_with(
        &mut self,
        ctx: &ShadeContext<'_>,
        sp: &SurfacePoint,
        d: Vec3,
        rays: &ShadowRays<'_, '_>,
    ) -> Vec3 {
        // Only where every caster is an opaque triangle (then an answer is
        // whether some accepted triangle meets the ray) and the cache held
        // a triangle after the last answer: else as `add`.
        if self.armed != 0 {
            self.add_armed(ctx, sp, d, rays)
        } else {
            self.add(ctx, sp, d)
        }
    }

    /// After `rays` answered a batch, which lights' certifiers
    /// [`ShadowBatch::add_with`] tries in the next: where every caster is
    /// an opaque triangle, each light whose shadow cache holds a triangle
    /// (inside a shadow: the cache is cleared where a packet's last ray is
    /// lit) and that has a certifier made with this structure. A light's
    /// certifier is made here, for the cache's entry, where the light's
    /// last certifier answered a query or the entry is the one of the last
    /// answer too ([`CertifierSlot`]); one that cannot certify leaves the
    /// light its last. (Which certifier is tried never changes an answer:
    /// each certifies only what its own triangle stops.)
    #[inline(always)]
    fn arm(&mut self, rays: &ShadowRays<'_, '_>) {
        self.armed = 0;
        for slot in &mut self.certifiers {
            slot.live = false;
        }
        if !rays.accel.opaque_triangles_only {
            return;
        }
        let accel = rays.accel.id;
        for o in &rays.occluders {
            let entry = o.load(std::sync::atomic::Ordering::Relaxed);
            // (`u64::MAX`, no entry, holds a light number far above.)
            let Ok(light) = usize::try_from(entry >> 34) else {
                continue;
            };
            if light >= CERTIFIED_LIGHTS {
                continue;
            }
            if self.certifiers.len() <= light {
                self.certifiers.resize(light + 1, CertifierSlot::default());
            }
            let slot = &mut self.certifiers[light];
            if (slot.made_for != entry || slot.accel != accel)
                && (slot.seen == entry || slot.productive())
            {
                // A new entry, worth a certifier: the last one answered a
                // query, or this entry stayed the cache's over two answers
                // (one that cannot certify keeps the light's last one).
                if let Some(c) = Certifier::new(rays.accel.scene, light, entry) {
                    slot.certifier = Some(c);
                    slot.accel = accel;
                    slot.answered = 0;
                }
                slot.made_for = entry;
            }
            slot.seen = entry;
            slot.misses = 0;
            slot.live = slot.certifier.is_some() && slot.accel == accel;
            self.armed += usize::from(slot.live);
        }
    }

    /// [`ShadowBatch::add_with`] where a light's certifier is live. (Out
    /// of line, as [`ShadowBatch::add`] is by the compiler's choice:
    /// inlined into the rasterizer's band loop it cost `polygons` 4 % more
    /// instructions.)
    #[inline(never)]
    fn add_armed(
        &mut self,
        ctx: &ShadeContext<'_>,
        sp: &SurfacePoint,
        d: Vec3,
        rays: &ShadowRays<'_, '_>,
    ) -> Vec3 {
        self.starts.push(self.answers.len());
        rendiff_core::shade::shadow_queries_pending(ctx, sp, d, |p| {
            if self.certifies(rays, p.index, sp) {
                if self.certified == 0 {
                    // Until now each query's answer had its own index.
                    self.slots.extend(0..self.queries.len());
                }
                self.answers.push((p.index, Rgb::BLACK));
                self.certified += 1;
                return;
            }
            if self.certified != 0 {
                self.slots.push(self.answers.len());
            }
            self.answers.push((p.index, Rgb::WHITE));
            self.queries.push(p.form_segment());
        })
    }

    /// `true` when the certifier of `light`, live in this batch and made
    /// with the structure of `rays`, says that its triangle stops the
    /// shadow ray from `sp`. A miss ends its tries in this batch
    /// ([`CERTIFIER_MISSES`]).
    #[inline(always)]
    fn certifies(&mut self, rays: &ShadowRays<'_, '_>, light: usize, sp: &SurfacePoint) -> bool {
        let Some(slot) = self.certifiers.get_mut(light) else {
            return false;
        };
        if !slot.live {
            return false;
        }
        if slot.accel == rays.accel.id && slot.certifier.as_ref().is_some_and(|c| c.stops(sp)) {
            slot.answered = slot.answered.saturating_add(1);
            return true;
        }
        slot.misses += 1;
        if slot.misses >= CERTIFIER_MISSES {
            // The rest of the batch as `add`, where no light is left.
            slot.live = false;
            self.armed -= 1;
        }
        false
    }

    /// Adds a sample that makes no shadow queries (a primary ray that
    /// missed), so that the batch's samples keep their callers' numbers.
    pub fn add_none(&mut self) {
        self.starts.push(self.answers.len());
    }

    /// Queries answered as they were added ([`ShadowBatch::add_with`])
    /// since the last [`ShadowBatch::clear`].
    #[must_use]
    pub fn answered_as_added(&self) -> usize {
        self.certified
    }

    /// Samples added since the last [`ShadowBatch::clear`].
    #[must_use]
    pub fn len(&self) -> usize {
        self.starts.len()
    }

    /// `true` when no sample was added since the last clear.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.starts.is_empty()
    }

    /// Answers every query added, through `rays`: grouped by light (stable,
    /// so a light's rays keep the samples' order, neighbours together) and
    /// traced in packets.
    pub fn answer(&mut self, rays: &ShadowRays<'_, '_>) {
        self.answer_queries(rays);
        self.arm(rays);
    }

    /// [`ShadowBatch::answer`]'s answers: each formed query's goes to its
    /// own index of `answers`, or, once a query was answered as it was
    /// added, to its slot.
    #[inline(always)]
    fn answer_queries(&mut self, rays: &ShadowRays<'_, '_>) {
        let slotted = self.certified != 0;
        if slotted {
            // The queries answered as they were added are shadow rays too.
            rays.cast.fetch_add(
                u64::try_from(self.certified).unwrap_or(u64::MAX),
                std::sync::atomic::Ordering::Relaxed,
            );
        }
        let (queries, answers, slots) = (&self.queries, &mut self.answers, &self.slots);
        debug_assert!(
            !slotted || queries.len() == slots.len(),
            "a slot per query formed"
        );
        let slot = |k: usize| if slotted { slots[k] } else { k };
        if queries.iter().all(|q| q.light == queries[0].light) {
            // One light (or none): no grouping.
            self.group_answers.clear();
            self.group_answers.resize(queries.len(), Rgb::WHITE);
            rays.transmittance_packets(queries, &mut self.group_answers);
            for (k, &t) in self.group_answers.iter().enumerate() {
                answers[slot(k)].1 = t;
            }
            return;
        }
        // Light by light in increasing order, each light's queries in the
        // samples' order (a stable sort by light, in one pass per light:
        // a batch holds a few lights, and a sort of its indices cost more).
        let mut light = queries.iter().map(|q| q.light).min();
        while let Some(l) = light {
            self.order.clear();
            self.group.clear();
            let mut next = None::<usize>;
            for (k, q) in queries.iter().enumerate() {
                if q.light == l {
                    self.order.push(k);
                    self.group.push(*q);
                } else if q.light > l && next.is_none_or(|n| q.light < n) {
                    next = Some(q.light);
                }
            }
            self.group_answers.clear();
            self.group_answers.resize(self.group.len(), Rgb::WHITE);
            rays.transmittance_packets(&self.group, &mut self.group_answers);
            for (&k, &t) in self.order.iter().zip(&self.group_answers) {
                answers[slot(k)].1 = t;
            }
            light = next;
        }
    }

    /// The visibility that serves sample `k`'s answers to `shade` (any
    /// other query goes to `fallback`).
    #[must_use]
    pub fn answered<'a>(&'a self, k: usize, fallback: &'a dyn Visibility) -> Answered<'a> {
        let end = self
            .starts
            .get(k + 1)
            .copied()
            .unwrap_or(self.answers.len());
        Answered {
            answers: &self.answers[self.starts[k]..end],
            fallback,
            next: std::sync::atomic::AtomicUsize::new(0),
        }
    }

    /// Empties the batch.
    pub fn clear(&mut self) {
        self.starts.clear();
        self.queries.clear();
        self.slots.clear();
        self.answers.clear();
        self.certified = 0;
    }
}

/// The shadow ray of a query: to a point light, the `f64` segment from the
/// origin to the light itself, and the light's position; to a parallel
/// light, the query's `f32` ray.
fn shadow_ray(scene: &TriScene, q: &ShadowQuery) -> (Ray64, Option<DVec3>) {
    let o = to_f64(q.origin);
    if let Some(light) = scene.lights.get(q.light)
        && let rendiff_core::shade::LightKind::Point { position } = light.kind
    {
        let at = to_f64(position);
        let v = at - o;
        let len = v.length();
        if len > 0.0 && len.is_finite() {
            let ray = Ray64 {
                origin: o,
                dir: v / len,
                t_min: 0.0,
                t_max: len,
            };
            return (ray, Some(at));
        }
    }
    let ray = Ray64 {
        origin: o,
        dir: to_f64(q.dir),
        t_min: 0.0,
        t_max: f64::from(q.t_max),
    };
    (ray, None)
}

/// `true` when triangle `tri`'s plane passes through `light` up to the
/// rounding of evaluating it: the shadow ray then meets the triangle at the
/// light itself, and the triangle does not shadow it (a point light lying
/// in a wall lights the floor, as in POV-Ray). The plane distance is
/// `n·(L − v0)` with `n = (v1 − v0) × (v2 − v0)`, in `f64`: each
/// component of `n` is within `γ₃(|e1_j e2_k| + |e1_k e2_j|)` and the dot
/// product adds `γ₃` of `Σ|n_i Δ_i|`; twice the sum of those is the test.
fn plane_through(scene: &TriScene, tri: u32, light: DVec3) -> bool {
    let plane = TriPlane::of(scene, tri);
    let (dist, bound) = plane.dot(light - plane.v0);
    dist.abs() <= bound
}

/// A triangle's plane in `f64` for sign tests: `n = (v1 − v0) × (v2 −
/// v0)` and what bounds the rounding of `n·Δ` ([`TriPlane::dot`]).
#[derive(Clone, Copy, Debug)]
struct TriPlane {
    v0: DVec3,
    n: DVec3,
    /// `|n| + spread`, `spread_i = |e1_j e2_k| + |e1_k e2_j|`.
    weight: DVec3,
}

impl TriPlane {
    fn of(scene: &TriScene, tri: u32) -> TriPlane {
        let v = scene.triangle_f64(tri);
        let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
        let n = e1.cross(e2);
        let spread = DVec3::new(
            (e1.y * e2.z).abs() + (e1.z * e2.y).abs(),
            (e1.z * e2.x).abs() + (e1.x * e2.z).abs(),
            (e1.x * e2.y).abs() + (e1.y * e2.x).abs(),
        );
        TriPlane {
            v0: v[0],
            n,
            weight: n.abs() + spread,
        }
    }

    /// `n·delta` and the bound on its rounding (see [`plane_through`]):
    /// beyond it, its sign is the exact one.
    #[inline(always)]
    fn dot(&self, delta: DVec3) -> (f64, f64) {
        let g = rendiff_core::math::gamma64(4);
        (self.n.dot(delta), 2.0 * g * self.weight.dot(delta.abs()))
    }

    /// `true` when `ray`'s origin lies strictly on one side of the plane
    /// (or exactly on it) and its direction points strictly away from it,
    /// each sign certain beyond its rounding: the `f64` test can then only
    /// reject the triangle (see [`leaves_behind`]).
    #[inline(always)]
    fn left_behind(&self, ray: &Ray64) -> bool {
        let (side, side_bound) = self.dot(ray.origin - self.v0);
        let (along, along_bound) = self.dot(ray.dir);
        // On the plane exactly (every term of `n·Δ` exact: a floor at y = 0,
        // whose points' error bound is zero and so their offset), the line
        // meets the plane at t = 0 itself, which the test rejects as well.
        let on_plane = side == 0.0 && side_bound == 0.0;
        let side_certain = side.abs() > side_bound;
        along.abs() > along_bound && (on_plane || side_certain && (side > 0.0) == (along > 0.0))
    }
}

/// The triangle a shadow ray leaves untested: the one it leaves
/// ([`ShadowQuery::leaves`]) where its origin lies strictly on one side of
/// that triangle's plane (or exactly on it) and its direction points
/// strictly away from it, each sign certain beyond its rounding
/// ([`TriPlane::dot`]); else none.
///
/// The exact line then meets the plane only at `t ≤ 0`, and the `f64`
/// test rejects every `t` within its own error bound of a `t ≤ 0`
/// (`triangle::intersect`, pbrt-v4's δt): the test could only reject the
/// triangle. The origin's own side is not enough: it is chosen in `f32`
/// from the light's direction as shading saw it, and a light within
/// about 10⁻⁷ of the plane, or a triangle so small that its `f32` normal
/// underflows, can put the segment's far end on the other side (then the
/// ray crosses its triangle, and is shadowed by it, as before).
fn leaves_behind(
    scene: &TriScene,
    q: &ShadowQuery,
    ray: &Ray64,
    last: &mut Option<(u32, TriPlane)>,
) -> u32 {
    let tri = q.leaves;
    if tri as usize >= scene.len() {
        return bvh::NO_SKIP;
    }
    // Neighbouring samples' rays leave the same triangle: its plane once.
    let plane = match last {
        Some((t, p)) if *t == tri => p,
        _ => &last.insert((tri, TriPlane::of(scene, tri))).1,
    };
    if plane.left_behind(ray) {
        tri
    } else {
        bvh::NO_SKIP
    }
}

/// `true` when a crossing of an analytic shape at `t` is the light itself:
/// within the crossing's own error bound `p_error` (and the ray's `f64`
/// rounding) of the segment's end.
fn analytic_at_light(ray: &Ray64, t: f64, p_error: Vec3) -> bool {
    ray.t_max.is_finite()
        && (ray.t_max - t).abs()
            <= to_f64(p_error).length() * 2.0 + rendiff_core::math::gamma64(16) * ray.t_max
}

impl Visibility for ShadowRays<'_, '_> {
    fn transmittance(&self, q: &ShadowQuery) -> Rgb {
        let a = self.accel;
        if !a.any_caster {
            return Rgb::WHITE;
        }
        self.cast.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let scene = a.scene;
        let (ray, light) = shadow_ray(scene, q);
        // Every crossing: (t, id, barycentrics); an opaque one ends it. A
        // surface through the light itself is not an occluder.
        let mut crossings: Vec<(f64, u32, [f32; 3])> = Vec::new();
        let mut blocked = false;
        let skip = leaves_behind(scene, q, &ray, &mut None);
        let mut visit = |id: u32, h: TriHit| {
            let class = a.class[id as usize];
            if class == ShadowClass::None || light.is_some_and(|l| plane_through(scene, id, l)) {
                return false;
            }
            if class == ShadowClass::Opaque {
                blocked = true;
                return true;
            }
            crossings.push((h.t64, id, h.b));
            false
        };
        // Through the light buffer where the light has one (every caster
        // is then a triangle, and a cell's list holds each one the walk
        // could meet, with the same hits: see `light_buffer`).
        let lb = &a.light_buffers;
        match lb.cell(q.light, &ray, light, q.dir) {
            Cell::Empty => return Rgb::WHITE,
            Cell::Leaf(leaf) if lb.clear_of_all(leaf, &ray, skip) => return Rgb::WHITE,
            Cell::Leaf(leaf) => {
                lb.leaves()
                    .leaf_any(&ray, skip, lb.first_pack(leaf), &mut visit);
            }
            Cell::Walk => a.bvh.for_each_hit(&ray, skip, &mut visit),
        }
        if blocked {
            return Rgb::BLACK;
        }
        let (o, d) = (ray.origin, ray.dir);
        let mut ts = Vec::new();
        for &k in &a.analytic {
            if a.analytic_class[k] == ShadowClass::None {
                continue;
            }
            a.analytic_crossings(k, o, d, ray.t_max, &mut ts);
            for &t in &ts {
                let p_error = scene.analytic_surface_at(k, o + d * t).p_error;
                if analytic_at_light(&ray, t, p_error) {
                    continue;
                }
                match a.analytic_class[k] {
                    ShadowClass::Opaque => return Rgb::BLACK,
                    ShadowClass::Transparent => {
                        crossings.push((t, a.scene.analytic_id(k), [0.0; 3]));
                    }
                    ShadowClass::None => {}
                }
            }
        }
        if crossings.is_empty() {
            return Rgb::WHITE;
        }
        // Multiply in order of increasing t (ties: lower id): the result
        // does not depend on the traversal order.
        crossings.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        let mut tr = Rgb::WHITE;
        for (t, id, b) in crossings {
            let sp = match scene.prim(id) {
                Prim::Triangle(id) => scene.surface_at(id, rendiff_core::math::Bary(b)),
                Prim::Analytic(k) => scene.analytic_surface_at(k, o + d * t),
            };
            let m = &scene.materials[usize::from(sp.material)];
            let (p, f, t) = m.pigment_at(sp.uv);
            tr *= p * f + Rgb::splat(t);
            if tr.is_black() {
                break;
            }
        }
        tr
    }
}
