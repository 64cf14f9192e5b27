//! The one shading model every backend uses: POV-Ray 3.7's finish model as
//! measured in POVRAY.md §4–§6 and §9.
//!
//! A backend finds a surface point (which triangle, which barycentrics),
//! builds a [`SurfacePoint`] with `TriScene::surface_at`, and calls
//! [`shade`] with the direction of the ray that hit it and a [`Visibility`]
//! that answers shadow rays. [`shade`] returns the local colour, the
//! weights and directions of the ray-tree children (reflection; the
//! transmitted weight, for the tracer to refract), and the shading flags of
//! DESIGN.md §3 that the verdict uses to recognise samples on a
//! discontinuity.
//!
//! ```text
//! C = (1 − f − t)·(ambient·A_g·P + emission·P + Σ diffuse) + Σ highlights
//!   + r·C_reflected + (f·P + t)·C_behind
//! ```

use std::sync::Arc;

use crate::color::Rgb;
use crate::math::{Vec2, Vec3};
use crate::texture::Texture;

/// The pigment of a material.
#[derive(Clone, Debug, PartialEq)]
pub enum Pigment {
    /// A constant colour.
    Color(Rgb),
    /// An image mapped by the surface's uv.
    Image(Arc<Texture>),
}

/// How a bump map perturbs the normal (DESIGN.md §3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BumpMethod {
    /// Blinn's method on the triangle's uv parameterisation.
    Blinn,
    /// POV-Ray's own `bump_map` (three height samples, a frame on world +y).
    Pov,
}

/// A bump map.
#[derive(Clone, Debug, PartialEq)]
pub struct Bump {
    /// The height image (grey = 0.297 R + 0.589 G + 0.114 B).
    pub texture: Arc<Texture>,
    /// POV-Ray's `bump_size`.
    pub size: f32,
    /// The method.
    pub method: BumpMethod,
}

/// A material: POV-Ray's pigment + finish (+ interior ior), with POV-Ray's
/// names and defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name in the scene file.
    pub name: String,
    /// Pigment.
    pub pigment: Pigment,
    /// `ambient` (0.1).
    pub ambient: f32,
    /// `diffuse` (0.6).
    pub diffuse: f32,
    /// `brilliance` (1).
    pub brilliance: f32,
    /// `phong` (0).
    pub phong: f32,
    /// `phong_size` (40).
    pub phong_size: f32,
    /// `specular` (0).
    pub specular: f32,
    /// `roughness` (0.05).
    pub roughness: f32,
    /// `metallic` (0).
    pub metallic: f32,
    /// `reflection` (0).
    pub reflection: f32,
    /// `filter` (0).
    pub filter: f32,
    /// `transmit` (0).
    pub transmit: f32,
    /// `ior` (1).
    pub ior: f32,
    /// `emission` (0).
    pub emission: f32,
    /// Bump map.
    pub bump: Option<Bump>,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: String::new(),
            pigment: Pigment::Color(Rgb::WHITE),
            ambient: 0.1,
            diffuse: 0.6,
            brilliance: 1.0,
            phong: 0.0,
            phong_size: 40.0,
            specular: 0.0,
            roughness: 0.05,
            metallic: 0.0,
            reflection: 0.0,
            filter: 0.0,
            transmit: 0.0,
            ior: 1.0,
            emission: 0.0,
            bump: None,
        }
    }
}

impl Material {
    /// `true` when the pigment or bump map reads uv.
    #[must_use]
    pub fn needs_uv(&self) -> bool {
        matches!(self.pigment, Pigment::Image(_)) || self.bump.is_some()
    }

    /// `true` when light can pass through (filter, transmit or an alpha channel).
    #[must_use]
    pub fn is_transparent(&self) -> bool {
        self.filter + self.transmit > 0.0
            || matches!(&self.pigment, Pigment::Image(t) if t.has_alpha())
    }

    /// `true` when a highlight term is on.
    #[must_use]
    pub fn has_highlight(&self) -> bool {
        self.phong > 0.0 || self.specular > 0.0
    }

    /// `true` when the material spawns ray-tree children.
    #[must_use]
    pub fn spawns_rays(&self) -> bool {
        self.reflection > 0.0 || self.is_transparent()
    }

    /// Pigment colour and its (filter, transmit) at `uv`.
    ///
    /// An image's alpha `a` becomes transmit `1 − a` with filter 0
    /// (POVRAY.md §9.11).
    #[must_use]
    pub fn pigment_at(&self, uv: Option<Vec2>) -> (Rgb, f32, f32) {
        match &self.pigment {
            Pigment::Color(c) => (*c, self.filter, self.transmit),
            Pigment::Image(tex) => {
                let s = tex.sample(uv.unwrap_or(Vec2::ZERO));
                if tex.has_alpha() {
                    (s.rgb, 0.0, 1.0 - s.alpha)
                } else {
                    (s.rgb, self.filter, self.transmit)
                }
            }
        }
    }
}

/// What kind of light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// A point light at a position.
    Point {
        /// Position.
        position: Vec3,
    },
    /// A parallel light travelling along a unit direction.
    Parallel {
        /// The unit direction the light travels (L = −direction).
        direction: Vec3,
    },
}

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Kind and geometry.
    pub kind: LightKind,
    /// Colour (may exceed 1).
    pub color: Rgb,
    /// A fill light: diffuse only, no shadows, no highlights.
    pub shadowless: bool,
    /// `(fade_distance, fade_power)`: attenuation `2/(1 + (d/fd)^fp)`.
    pub fade: Option<(f32, f32)>,
}

impl Light {
    /// Unit vector toward the light and the distance to it (∞ for parallel).
    #[must_use]
    pub fn toward(&self, p: Vec3) -> (Vec3, f32) {
        match self.kind {
            LightKind::Point { position } => {
                let v = position - p;
                let d = v.length();
                if d > 0.0 {
                    (v / d, d)
                } else {
                    (Vec3::ZERO, 0.0)
                }
            }
            LightKind::Parallel { direction } => (-direction, f32::INFINITY),
        }
    }

    /// Distance attenuation.
    #[must_use]
    pub fn attenuation(&self, dist: f32) -> f32 {
        match self.fade {
            Some((fd, fp)) if dist.is_finite() => 2.0 / (1.0 + (dist / fd).powf(fp)),
            _ => 1.0,
        }
    }
}

/// Shading inputs at a surface point: the seam between "find the surface"
/// and "shade it". Built only by `TriScene::surface_at` (and its analytic
/// twin), used by every backend.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// Position.
    pub p: Vec3,
    /// Conservative bound on the absolute error of `p` per axis.
    pub p_error: Vec3,
    /// Unit geometric normal (winding normal; not flipped).
    pub ng: Vec3,
    /// Unit shading normal (interpolated or geometric; not flipped).
    pub ns: Vec3,
    /// Surface uv, if the surface has one.
    pub uv: Option<Vec2>,
    /// ∂P/∂u and ∂P/∂v of the triangle (zero where uv is absent or degenerate).
    pub dpdu: Vec3,
    /// See `dpdu`.
    pub dpdv: Vec3,
    /// Material index.
    pub material: u16,
    /// Object index.
    pub object: u32,
    /// Primitive id (triangle id, or an analytic id above the triangles).
    pub prim: u32,
}

/// Answers shadow rays: the RGB fraction of light that reaches the end of a
/// segment. Opaque occluders give black; transparent ones multiply by
/// `f·P + t` at every crossing, in order of increasing t (ties: lower id).
pub trait Visibility: Sync {
    /// Transmittance of a shadow segment.
    fn transmittance(&self, q: &ShadowQuery) -> Rgb;

    /// Transmittance of the next shadow query [`shade`] makes, toward
    /// light `light`, which `query` forms. The default forms it and asks
    /// [`Visibility::transmittance`]; a visibility that answered the
    /// queries before ([`Answered`]) serves the answer without forming it.
    fn transmittance_of(&self, light: usize, query: &dyn Fn() -> ShadowQuery) -> Rgb {
        let _ = light;
        self.transmittance(&query())
    }
}

/// A shadow ray: the segment `origin + t·dir`, `0 < t ≤ t_max`, toward light
/// `light` (for a point light, `dir` and `t_max` aim at the light from
/// `origin`), from a surface whose geometric normal is `normal` (a shadow
/// map scales its depth bias with the angle between the two; rays ignore
/// it). An occluder whose plane passes through the light within the
/// rounding of the plane's evaluation does not count (the light-plane rule,
/// applied where the crossings are found: the accel crate's `ShadowRays`).
///
/// `leaves` is the primitive the ray leaves ([`SurfacePoint::prim`]). The
/// ray queries leave that triangle untested where the origin lies strictly
/// on one side of its plane (or exactly on it) and the direction points
/// strictly away from it, both signs certain in `f64`: its exact test
/// could only reject it then (the accel crate's
/// `Accel::skips_its_own_triangle`). Not wherever the ray leaves it: the
/// origin's side is chosen in `f32` ([`offset_origin`]) from the light's
/// direction as shading saw it, and a light within about 10⁻⁷ of the
/// plane can lie on the other side. A curved analytic surface can be met
/// again (from inside a sphere) and is always tested.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowQuery {
    /// Index of the light.
    pub light: usize,
    /// Origin, already moved off the surface.
    pub origin: Vec3,
    /// Unit direction toward the light.
    pub dir: Vec3,
    /// End of the segment (∞ for a parallel light).
    pub t_max: f32,
    /// Unit geometric normal of the surface the ray leaves.
    pub normal: Vec3,
    /// The primitive the ray leaves ([`SurfacePoint::prim`]; `u32::MAX`:
    /// none): a triangle with this id is not tested where the ray
    /// certainly moves away from its plane.
    pub leaves: u32,
}

/// A visibility that never blocks (for shadowless renders and tests).
#[derive(Clone, Copy, Debug, Default)]
pub struct Unoccluded;

impl Visibility for Unoccluded {
    fn transmittance(&self, _q: &ShadowQuery) -> Rgb {
        Rgb::WHITE
    }
}

/// Moves a point off its surface along ±`ng`, toward the side `dir` leaves
/// on, by more than the point's floating-point error (pbrt-v4's
/// `OffsetRayOrigin`): a ray spawned there cannot re-hit the surface it
/// left, at any scene scale. (Inlined: its result feeds the shadow ray's
/// direction at once, and as a call it cost the shadowed bundled scenes
/// 2–5 % of their render.)
#[must_use]
#[inline(always)]
pub fn offset_origin(p: Vec3, p_error: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    let d = ng.abs().dot(p_error);
    let mut offset = ng * d;
    if dir.dot(ng) < 0.0 {
        offset = -offset;
    }
    let po = p + offset;
    // Round away from p so the offset is never lost to rounding.
    let bump = |v: f32, o: f32| {
        if o > 0.0 {
            v.next_up()
        } else if o < 0.0 {
            v.next_down()
        } else {
            v
        }
    };
    Vec3::new(
        bump(po.x, offset.x),
        bump(po.y, offset.y),
        bump(po.z, offset.z),
    )
}

/// Half-width of the band around a shading discontinuity that the verdict
/// treats as a tie (ε_g, DESIGN.md §6).
///
/// Both backends reach the same barycentrics to ~1e-12 and round them to
/// f32 once, so their weights differ by at most one ulp (2⁻²⁴ absolute);
/// the interpolated normal then moves by ≤ 2·2⁻²⁴ per unit of normal
/// spread (≤ 2), and N·L, N·D by ≤ 2⁻²¹ plus ~10 f32 operations of
/// rounding (10·2⁻²⁴): about 1.1e-6. The light vector moves with the hit
/// point by |ΔP|/distance ≤ 2⁻²³ for lights farther than the triangle's
/// size. ε_g = 1e-4 is 90× that bound: the margin covers a bump map's
/// normal perturbation, whose height samples move with the uv by the
/// same one ulp but are multiplied by the map's size and resolution.
pub const GATE_EPS: f32 = 1e-4;

/// Bit 0 of the shading flags: the sample lies on a discontinuity.
pub const FLAG_DISCONTINUITY: u32 = 1;

/// The flag bit of light `i` (lights 0–30): its shadow ray was blocked.
#[must_use]
pub(crate) fn shadow_flag(light: usize) -> u32 {
    if light < 31 { 1 << (light + 1) } else { 0 }
}

/// Scene-wide shading inputs.
#[derive(Clone, Copy, Debug)]
pub struct ShadeContext<'a> {
    /// Materials, indexed by `SurfacePoint::material`.
    pub materials: &'a [Material],
    /// Lights.
    pub lights: &'a [Light],
    /// `ambient_light` (A_g).
    pub ambient_light: Rgb,
    /// Half-width of the band around a discontinuity that is flagged (ε_g).
    pub gate_eps: f32,
    /// `false` turns every shadow ray off (the render plan's decision).
    pub shadows: bool,
}

/// The result of shading one surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shaded {
    /// Local colour: opacity-weighted ambient, emission and diffuse, plus
    /// the highlights.
    pub local: Rgb,
    /// The shading normal used (perturbed, flipped toward the viewer).
    pub normal: Vec3,
    /// The shading normal before any bump map (flipped toward the viewer):
    /// POV-Ray's raw normal, which keeps reflected rays on the viewer's
    /// side ([`reflect_bumped`]).
    pub raw_normal: Vec3,
    /// Reflection weight `r` (the tracer adds `r·C(mirror ray)`).
    pub reflection: f32,
    /// Transmission weight `f·P + t` (the tracer adds it times `C_behind`).
    pub transmit: Rgb,
    /// Shading flags: [`FLAG_DISCONTINUITY`] and `shadow_flag` bits.
    pub flags: u32,
}

/// `n`, or `−n` when it faces away from a viewer looking along `d`.
fn flipped_toward(n: Vec3, d: Vec3) -> Vec3 {
    if n.dot(d) > 0.0 { -n } else { n }
}

/// The bump-perturbed shading normal, flipped toward the viewer first.
#[must_use]
#[inline(always)]
pub(crate) fn shading_normal(m: &Material, sp: &SurfacePoint, d: Vec3) -> Vec3 {
    let mut n = sp.ns;
    if n.dot(d) > 0.0 {
        n = -n;
    }
    match (&m.bump, sp.uv) {
        (Some(bump), Some(uv)) => match bump.method {
            BumpMethod::Pov => bump_pov(bump, n, uv),
            BumpMethod::Blinn => bump_blinn(bump, n, uv, sp.dpdu, sp.dpdv),
        },
        _ => n,
    }
}

fn height(tex: &Texture, x: f64, y: f64) -> f32 {
    let t = tex.bilinear(x, y);
    Rgb::new(t[0], t[1], t[2]).pov_grey()
}

/// POV-Ray's `bump_map` (POVRAY.md §9.2).
fn bump_pov(bump: &Bump, n: Vec3, uv: Vec2) -> Vec3 {
    let tex = &bump.texture;
    let x = f64::from(uv.x) * f64::from(tex.width());
    let y = (1.0 - f64::from(uv.y)) * f64::from(tex.height());
    let h1 = height(tex, x, y);
    let h2 = height(tex, x - 1.0, y + 1.0);
    let h3 = height(tex, x + 1.0, y + 1.0);
    let s = bump.size;
    let b = Vec3::new(-s * (h3 - h2), 2.0, s * (2.0 * h1 - h2 - h3)).normalize();
    let c = n.cross(Vec3::Y);
    let (t, nn, bb) = if c.length() < 1e-10 {
        let nn = if n.y >= 0.0 { Vec3::Y } else { -Vec3::Y };
        let t = Vec3::X;
        (t, nn, t.cross(nn))
    } else {
        let t = c.normalize();
        (t, n, t.cross(n).normalize())
    };
    (t * b.x + nn * b.y - bb * b.z).normalize()
}

/// Blinn's bump mapping on the triangle's uv parameterisation (DESIGN.md §3).
fn bump_blinn(bump: &Bump, ns: Vec3, uv: Vec2, pu: Vec3, pv: Vec3) -> Vec3 {
    let tex = &bump.texture;
    let cross = pu.cross(pv);
    let len = cross.length();
    if len == 0.0 || !len.is_finite() {
        return ns;
    }
    let n_hat = cross / len;
    #[expect(
        clippy::cast_precision_loss,
        reason = "texture sides are at most 16384, exact in f32"
    )]
    let (w, h) = (tex.width() as f32, tex.height() as f32);
    let hh = |u: f32, v: f32| tex.sample(Vec2::new(u, v)).rgb.pov_grey();
    let bu = bump.size * (hh(uv.x + 1.0 / w, uv.y) - hh(uv.x - 1.0 / w, uv.y)) * w / 2.0;
    let bv = bump.size * (hh(uv.x, uv.y + 1.0 / h) - hh(uv.x, uv.y - 1.0 / h)) * h / 2.0;
    let perturbed = ns + (n_hat.cross(pv) * bu - n_hat.cross(pu) * bv) / len;
    perturbed.try_normalize().unwrap_or(ns)
}

/// POV-Ray's metallic Fresnel-like factor of the highlight colour
/// (POVRAY.md §4), with `x = acos(N·L)/(π/2)`.
fn metallic_tint(metallic: f32, pigment: Rgb, n_dot_l: f32) -> Rgb {
    if metallic <= 0.0 {
        return Rgb::WHITE;
    }
    let x = n_dot_l.clamp(-1.0, 1.0).acos() / std::f32::consts::FRAC_PI_2;
    let f = (0.014_567_225 / ((x - 1.12) * (x - 1.12)) - 0.011_612_903).clamp(0.0, 1.0);
    Rgb::splat(1.0) + (pigment - Rgb::WHITE) * (metallic * (1.0 - f))
}

/// The shadow ray of light `i` (toward it along unit `l`, at distance
/// `dist`) from `sp`: a point light's segment from the offset origin to
/// the light itself (its end within rounding of the light), a parallel
/// light's direction without end.
fn shadow_query(i: usize, light: &Light, sp: &SurfacePoint, l: Vec3, dist: f32) -> ShadowQuery {
    let origin = offset_origin(sp.p, sp.p_error, sp.ng, l);
    let (dir, t_max) = match light.kind {
        LightKind::Point { position } => {
            let v = position - origin;
            let len = v.length();
            if len > 0.0 && len.is_finite() {
                (v / len, len)
            } else {
                (l, dist)
            }
        }
        LightKind::Parallel { .. } => (l, f32::INFINITY),
    };
    ShadowQuery {
        light: i,
        origin,
        dir,
        t_max,
        normal: sp.ng,
        leaves: sp.prim,
    }
}

/// Calls `query` with each shadow query [`shade`] makes at `sp` seen
/// along `d`, in the order it makes them (light order), so that a caller
/// can answer a batch of samples' queries together and then shade them
/// with the answers ([`Answered`], [`shade_with_normal`]). Returns the
/// shading normal.
pub fn shadow_queries(
    ctx: &ShadeContext<'_>,
    sp: &SurfacePoint,
    d: Vec3,
    mut query: impl FnMut(ShadowQuery),
) -> Vec3 {
    shadow_queries_pending(ctx, sp, d, |p| query(p.form()))
}

/// [`shadow_queries`] offering each query before it is formed: `pending`
/// sees the light it goes to and forms it ([`PendingQuery::form`]) only
/// where it needs the ray (a caller that can answer a query from the
/// surface point alone skips the ray's setup). The same queries, in the
/// same order; returns the shading normal.
#[inline(always)]
pub fn shadow_queries_pending(
    ctx: &ShadeContext<'_>,
    sp: &SurfacePoint,
    d: Vec3,
    mut pending: impl FnMut(PendingQuery<'_>),
) -> Vec3 {
    let m = &ctx.materials[usize::from(sp.material)];
    let n = shading_normal(m, sp, d);
    if !ctx.shadows {
        return n;
    }
    for (i, light) in ctx.lights.iter().enumerate() {
        let (l, dist) = light.toward(sp.p);
        if n.dot(l) <= 0.0 || dist == 0.0 || light.shadowless {
            continue;
        }
        pending(PendingQuery {
            index: i,
            light,
            sp,
            l,
            dist,
        });
    }
    n
}

/// A shadow query [`shadow_queries_pending`] makes, not formed yet.
#[derive(Clone, Copy, Debug)]
pub struct PendingQuery<'a> {
    /// The light's index.
    pub index: usize,
    light: &'a Light,
    sp: &'a SurfacePoint,
    /// Unit vector toward the light from `sp.p`, and the distance
    /// ([`Light::toward`]).
    l: Vec3,
    dist: f32,
}

impl PendingQuery<'_> {
    /// The query, exactly as [`shadow_queries`] gives it.
    #[must_use]
    #[inline(always)]
    pub fn form(&self) -> ShadowQuery {
        shadow_query(self.index, self.light, self.sp, self.l, self.dist)
    }

    /// The query for a tracer that follows a point light's shadow ray as
    /// the segment from its origin to the light's position, whenever the
    /// two differ (as `rendiff-accel` does, in `f64`): `origin`, `normal`
    /// and `leaves` are [`PendingQuery::form`]'s, but `dir` and `t_max`
    /// are the direction and distance from the surface point
    /// ([`Light::toward`]) instead of from the origin. Such a tracer
    /// reads them only where the origin is the light's position, and
    /// there `form` gives these same values (its `f32` segment is empty);
    /// toward a parallel light the query is `form`'s. The answers are
    /// `form`'s without its normalisation, a square root and a division
    /// on each query's path. (Its own literal rather than a helper shared
    /// with `shadow_query`: routing `shadow_query` through one changed its
    /// code and cost `many_lights` 5 % wall time; ARCHITECTURE.md.)
    #[must_use]
    #[inline(always)]
    pub fn form_segment(&self) -> ShadowQuery {
        ShadowQuery {
            light: self.index,
            origin: offset_origin(self.sp.p, self.sp.p_error, self.sp.ng, self.l),
            dir: self.l,
            t_max: match self.light.kind {
                LightKind::Point { .. } => self.dist,
                LightKind::Parallel { .. } => f32::INFINITY,
            },
            normal: self.sp.ng,
            leaves: self.sp.prim,
        }
    }
}

/// A [`Visibility`] that answers from a list of queries answered before
/// (in the order [`shadow_queries`] gave them, which is the order
/// [`shade`] asks them in): the `k`-th query [`shade`] makes takes the
/// `k`-th answer when it is toward the same light, without being formed
/// again ([`Visibility::transmittance_of`]); any other query goes to
/// `fallback`.
pub struct Answered<'a> {
    /// Each query's light and its transmittance, in query order.
    pub answers: &'a [(usize, Rgb)],
    /// For a query not in `answers`.
    pub fallback: &'a dyn Visibility,
    /// The next answer expected.
    pub next: std::sync::atomic::AtomicUsize,
}

impl std::fmt::Debug for Answered<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Answered")
            .field("answers", &self.answers)
            .field("next", &self.next)
            .finish_non_exhaustive()
    }
}

impl Visibility for Answered<'_> {
    fn transmittance(&self, q: &ShadowQuery) -> Rgb {
        self.transmittance_of(q.light, &|| *q)
    }

    fn transmittance_of(&self, light: usize, query: &dyn Fn() -> ShadowQuery) -> Rgb {
        let k = self.next.load(std::sync::atomic::Ordering::Relaxed);
        if let Some(&(l, tr)) = self.answers.get(k)
            && l == light
        {
            self.next.store(k + 1, std::sync::atomic::Ordering::Relaxed);
            return tr;
        }
        self.fallback.transmittance(&query())
    }
}

/// Shades a surface point hit by a ray with unit direction `d`.
///
/// Shadows are asked of `vis` with one ray per light that has `N·L > 0`
/// and is not shadowless, from `sp.p` moved off the surface by its error
/// bound ([`offset_origin`]).
#[must_use]
pub fn shade(ctx: &ShadeContext<'_>, sp: &SurfacePoint, d: Vec3, vis: &dyn Visibility) -> Shaded {
    let m = &ctx.materials[usize::from(sp.material)];
    shade_with_normal(ctx, sp, d, shading_normal(m, sp, d), vis)
}

/// [`shade`] given the shading normal [`shadow_queries`] returned for the
/// same `sp` and `d` (the same result, bit for bit, without forming the
/// normal again).
#[must_use]
pub fn shade_with_normal(
    ctx: &ShadeContext<'_>,
    sp: &SurfacePoint,
    d: Vec3,
    n: Vec3,
    vis: &dyn Visibility,
) -> Shaded {
    shade_with_normal_inlined(ctx, sp, d, n, vis)
}

/// [`shade_with_normal`] inlined into its caller: for the rasterizer's
/// batches of shadowed samples, where the call cost 2–6 % of a bundled
/// scene's render. Not the default: inlined everywhere, it made the loop
/// of the shadowless 940 k bunny's raster frame 7 % slower
/// (ARCHITECTURE.md, "A batch's shading inlined").
#[must_use]
#[inline(always)]
pub fn shade_with_normal_inlined(
    ctx: &ShadeContext<'_>,
    sp: &SurfacePoint,
    d: Vec3,
    n: Vec3,
    vis: &dyn Visibility,
) -> Shaded {
    let m = &ctx.materials[usize::from(sp.material)];
    let (pig, f, t) = m.pigment_at(sp.uv);
    let opacity = 1.0 - f - t;
    let mut flags = 0u32;

    // N·D = 0 is where the flip toward the viewer switches the normal.
    if sp.ns.dot(d).abs() < ctx.gate_eps {
        flags |= FLAG_DISCONTINUITY;
    }

    let mut diffuse_sum = pig * (m.ambient * ctx.ambient_light) + pig * m.emission;
    let mut highlights = Rgb::BLACK;
    let reflected_view = d - n * (2.0 * d.dot(n));

    for (i, light) in ctx.lights.iter().enumerate() {
        let (l, dist) = light.toward(sp.p);
        let n_dot_l = n.dot(l);
        let highlight_on = !light.shadowless && m.has_highlight();
        if highlight_on && n_dot_l.abs() < ctx.gate_eps {
            flags |= FLAG_DISCONTINUITY;
        }
        if n_dot_l <= 0.0 || dist == 0.0 {
            continue;
        }
        let mut lc = light.color * light.attenuation(dist);
        if !light.shadowless && ctx.shadows {
            let tr = vis.transmittance_of(i, &|| shadow_query(i, light, sp, l, dist));
            if tr != Rgb::WHITE {
                flags |= shadow_flag(i);
            }
            if tr.is_black() {
                continue;
            }
            lc *= tr;
        }
        let lambert = if m.brilliance == 1.0 {
            n_dot_l
        } else {
            n_dot_l.powf(m.brilliance)
        };
        diffuse_sum += pig * lc * (m.diffuse * lambert);
        if light.shadowless {
            continue;
        }
        let cs = lc * metallic_tint(m.metallic, pig, n_dot_l);
        if m.phong > 0.0 {
            let c = reflected_view.dot(l);
            if c > 0.0 {
                highlights += cs * (m.phong * c.powf(m.phong_size));
            }
        }
        if m.specular > 0.0
            && let Some(h) = (l - d).try_normalize()
        {
            let c = h.dot(n);
            if c > 0.0 {
                highlights += cs * (m.specular * c.powf(1.0 / m.roughness));
            }
        }
    }

    Shaded {
        local: diffuse_sum * opacity + highlights,
        normal: n,
        raw_normal: flipped_toward(sp.ns, d),
        reflection: m.reflection,
        transmit: pig * f + Rgb::splat(t),
        flags,
    }
}

/// Snell refraction of unit `d` through a surface with unit normal `n`
/// (any orientation: it is flipped against the ray) and relative index
/// `eta = n_from / n_to` (POVRAY.md §9.9). `None` on total internal
/// reflection.
#[must_use]
pub fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let n = if n.dot(d) > 0.0 { -n } else { n };
    let c = -d.dot(n);
    let q = 1.0 + eta * eta * (c * c - 1.0);
    if q < 0.0 {
        return None;
    }
    Some((d * eta + n * (eta * c - q.sqrt())).normalize())
}

/// The reflected direction at a bump-mapped surface, as POV-Ray 3.7 makes
/// it (its "reflection bugfix" of 1998, `Trace::ComputeReflection`): the
/// mirror of `d` about the perturbed normal `n`, unless that turns into
/// the surface (against the raw normal `raw`): then the mirror about `raw`
/// where the ray also goes against `n`, else the perturbed mirror
/// reflected once more about `raw`. Without bumps (`n == raw`) it is the
/// plain mirror. (A bump can tilt the normal so far that the plain mirror
/// of a grazing ray points below the surface; it would then see what lies
/// under the floor.)
#[must_use]
pub fn reflect_bumped(d: Vec3, n: Vec3, raw: Vec3) -> Vec3 {
    let r = d - n * (2.0 * d.dot(n));
    let k = r.dot(raw);
    if k >= 0.0 {
        return r;
    }
    let fixed = if r.dot(n) < 0.0 {
        d - raw * (2.0 * d.dot(raw))
    } else {
        r - raw * (2.0 * k)
    };
    fixed.normalize_or_zero()
}

/// The mirror direction of unit `d` about unit `n`.
#[must_use]
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - n * (2.0 * d.dot(n))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sp(ns: Vec3) -> SurfacePoint {
        SurfacePoint {
            p: Vec3::ZERO,
            p_error: Vec3::ZERO,
            ng: ns,
            ns,
            uv: None,
            dpdu: Vec3::ZERO,
            dpdv: Vec3::ZERO,
            material: 0,
            object: 0,
            prim: 0,
        }
    }

    fn point_light(p: Vec3) -> Light {
        Light {
            kind: LightKind::Point { position: p },
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        }
    }

    fn ctx<'a>(m: &'a [Material], l: &'a [Light]) -> ShadeContext<'a> {
        ShadeContext {
            materials: m,
            lights: l,
            ambient_light: Rgb::WHITE,
            gate_eps: 1e-4,
            shadows: true,
        }
    }

    fn close(a: Rgb, b: Rgb) -> bool {
        a.max_abs_diff(b) < 1e-6
    }

    /// Blocks every shadow ray.
    struct Wall;
    impl Visibility for Wall {
        fn transmittance(&self, _: &ShadowQuery) -> Rgb {
            Rgb::BLACK
        }
    }

    #[test]
    fn ambient_and_lambert_by_hand() {
        let mat = Material {
            pigment: Pigment::Color(Rgb::new(0.8, 0.5, 0.2)),
            ..Material::default()
        };
        let light = point_light(Vec3::new(0.0, 10.0, 10.0));
        let mats = [mat];
        let lights = [light];
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), -Vec3::Y, &Unoccluded);
        // N·L = cos 45°; C = P·0.1 + P·0.6·cos45.
        let k = 0.1 + 0.6 * std::f32::consts::FRAC_1_SQRT_2;
        assert!(
            close(s.local, Rgb::new(0.8 * k, 0.5 * k, 0.2 * k)),
            "{:?}",
            s.local
        );
    }

    #[test]
    fn normal_is_flipped_toward_the_viewer() {
        let mats = [Material::default()];
        let lights = [point_light(Vec3::new(0.0, 5.0, 0.0))];
        // Normal points down, viewer looks down from above: flipped to +y, lit.
        let s = shade(&ctx(&mats, &lights), &sp(-Vec3::Y), -Vec3::Y, &Unoccluded);
        assert_eq!(s.normal, Vec3::Y);
        assert!(close(s.local, Rgb::splat(0.7)));
    }

    #[test]
    fn no_light_and_no_highlight_behind_the_gate() {
        // Light below the surface: N·L < 0 even though R·L > 0 for a grazing view.
        let mats = [Material {
            phong: 1.0,
            specular: 1.0,
            ..Material::default()
        }];
        let lights = [point_light(Vec3::new(5.0, -0.1, 0.0))];
        let d = Vec3::new(1.0, -0.01, 0.0).normalize();
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), d, &Unoccluded);
        assert!(close(s.local, Rgb::splat(0.1)), "{:?}", s.local);
    }

    #[test]
    fn phong_uses_reflected_view_and_is_not_tinted() {
        let mats = [Material {
            pigment: Pigment::Color(Rgb::new(1.0, 0.0, 0.0)),
            ambient: 0.0,
            diffuse: 0.0,
            phong: 0.5,
            phong_size: 10.0,
            ..Material::default()
        }];
        let l = Vec3::new(1.0, 1.0, 0.0).normalize();
        let lights = [point_light(l * 100.0)];
        let d = Vec3::new(0.6, -0.8, 0.0);
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), d, &Unoccluded);
        let rv = Vec3::new(0.6, 0.8, 0.0);
        let l_exact = (l * 100.0).normalize();
        let want = 0.5 * rv.dot(l_exact).powf(10.0);
        assert!(close(s.local, Rgb::splat(want)), "{:?} vs {want}", s.local);
    }

    #[test]
    fn specular_uses_blinn_half_vector() {
        let mats = [Material {
            ambient: 0.0,
            diffuse: 0.0,
            specular: 0.7,
            roughness: 0.05,
            ..Material::default()
        }];
        let lights = [point_light(Vec3::new(0.0, 100.0, 100.0))];
        let d = Vec3::new(0.0, -1.0, 0.0);
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), d, &Unoccluded);
        let l = Vec3::new(0.0, 1.0, 1.0).normalize();
        let h = (l - d).normalize();
        let want = 0.7 * h.dot(Vec3::Y).powf(20.0);
        assert!(close(s.local, Rgb::splat(want)));
    }

    #[test]
    fn metallic_tints_highlight_with_n_dot_l() {
        let pig = Rgb::new(0.9, 0.6, 0.2);
        let mats = [Material {
            pigment: Pigment::Color(pig),
            ambient: 0.0,
            diffuse: 0.0,
            phong: 1.0,
            phong_size: 1.0,
            metallic: 1.0,
            ..Material::default()
        }];
        let lights = [point_light(Vec3::new(0.0, 100.0, 0.0))];
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), -Vec3::Y, &Unoccluded);
        // N·L = 1: x = 0, F = 0.014567225/1.2544 − 0.011612903 ≈ 0; Cs ≈ P.
        let f = (0.014_567_225f32 / (1.12 * 1.12) - 0.011_612_903).clamp(0.0, 1.0);
        let want = Rgb::WHITE + (pig - Rgb::WHITE) * (1.0 - f);
        assert!(close(s.local, want), "{:?} vs {want:?}", s.local);
    }

    #[test]
    fn shadowless_light_is_diffuse_only_and_unshadowed() {
        let mats = [Material {
            ambient: 0.0,
            phong: 1.0,
            ..Material::default()
        }];
        let mut l = point_light(Vec3::new(0.0, 1.0, 0.0));
        l.shadowless = true;
        let lights = [l];
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), -Vec3::Y, &Wall);
        assert!(close(s.local, Rgb::splat(0.6)));
        assert_eq!(s.flags, 0);
    }

    #[test]
    fn shadow_blocks_diffuse_and_highlight_but_not_ambient() {
        let mats = [Material {
            phong: 1.0,
            emission: 0.2,
            ..Material::default()
        }];
        let lights = [point_light(Vec3::new(0.0, 1.0, 0.0))];
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), -Vec3::Y, &Wall);
        assert!(close(s.local, Rgb::splat(0.3)));
        assert_eq!(s.flags, shadow_flag(0));
    }

    #[test]
    fn fade_attenuates() {
        let mut l = point_light(Vec3::new(0.0, 3.0, 0.0));
        l.fade = Some((3.0, 2.0));
        assert!((l.attenuation(3.0) - 1.0).abs() < 1e-7);
        assert!((l.attenuation(6.0) - 2.0 / 5.0).abs() < 1e-7);
    }

    #[test]
    fn transparency_scales_local_terms_but_not_highlights() {
        let pig = Rgb::new(0.9, 0.5, 0.2);
        let mats = [Material {
            pigment: Pigment::Color(pig),
            ambient: 0.2,
            diffuse: 0.0,
            phong: 0.5,
            phong_size: 1.0,
            filter: 0.4,
            transmit: 0.3,
            ..Material::default()
        }];
        let lights = [point_light(Vec3::new(0.0, 100.0, 0.0))];
        let s = shade(&ctx(&mats, &lights), &sp(Vec3::Y), -Vec3::Y, &Unoccluded);
        let want = pig * (0.2 * 0.3) + Rgb::splat(0.5);
        assert!(close(s.local, want), "{:?}", s.local);
        assert!(close(s.transmit, pig * 0.4 + Rgb::splat(0.3)));
    }

    #[test]
    fn refraction_obeys_snell_and_reports_tir() {
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        let t = refract(d, Vec3::Y, 1.0 / 1.5).unwrap();
        let sin_in = (45f32).to_radians().sin();
        assert!((t.x - sin_in / 1.5).abs() < 1e-6);
        // Leaving glass at 45°: sin θt = 1.5·0.707 > 1 → TIR.
        assert!(refract(d, Vec3::Y, 1.5).is_none());
    }

    #[test]
    fn offset_origin_leaves_the_plane_on_the_ray_side() {
        let p = Vec3::new(1e4, 1.0, 0.0);
        // Half an f32 step of the point's coordinates.
        let err = p.abs() * crate::math::F32_EPS;
        let o = offset_origin(p, err, Vec3::Y, Vec3::Y);
        assert!(o.y > p.y);
        let o = offset_origin(p, err, Vec3::Y, -Vec3::Y);
        assert!(o.y < p.y);
    }
}
