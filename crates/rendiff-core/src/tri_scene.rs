//! `TriScene`: the one triangulated scene every backend sees (DESIGN.md §1).
//!
//! Flat arrays in world space, after transforms: a position pool with three
//! indices per triangle; normals and uvs per triangle corner (pools with
//! their own indices, [`NO_INDEX`] for a flat triangle or one without uv);
//! a material and an object per triangle; per-object bounds and closedness.
//! [`TriScene::surface_at`] is the only place a hit becomes shading inputs.

use std::ops::Range;

use crate::analytic::{AnalyticKind, Placed};
use crate::camera::Camera;
use crate::color::Rgb;
use crate::math::{
    Aabb, Bary, DVec3, F32_EPS, PlaneFromOrigin, Vec2, Vec3, f32_at_least, gamma64,
    plane_barycentrics, to_f32, to_f64,
};
use crate::shade::{Light, Material, ShadeContext, SurfacePoint};

/// "No normal" / "no uv" in a corner index triple.
pub const NO_INDEX: u32 = u32::MAX;

/// Per-object facts the plan, the backends and the exporter need.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectInfo {
    /// `objects[i] (kind)`.
    pub label: String,
    /// The shape kind.
    pub kind: &'static str,
    /// The object's triangles (contiguous ids).
    pub tris: Range<u32>,
    /// World-space bounds of its triangles.
    pub bounds: Aabb,
    /// Manifold and consistently oriented after welding equal positions
    /// (DESIGN.md §7); then its counter-clockwise side faces out.
    pub closed: bool,
    /// Casts no shadows.
    pub no_shadow: bool,
    /// Material index: the object's material, or, for an object whose
    /// triangles have materials of their own (an OBJ's, `material =
    /// "obj"`), the one whose `ior` is its inside; the triangles' are in
    /// [`TriScene::tri_material`] ([`TriScene::object_materials`]).
    pub material: u16,
    /// Uses interpolated vertex normals.
    pub smooth: bool,
    /// Segments around the equator (spheres, superellipsoids).
    pub segments: Option<u32>,
}

/// A shape kept analytic for `--geometry analytic`: a sphere, box or
/// superellipsoid under its affine transform (the ray tracer intersects it
/// in its own space, `crate::analytic`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalyticShape {
    /// The object it stands for.
    pub object: u32,
    /// The shape and its transform.
    pub placed: Placed,
    /// World bounds (conservative).
    pub bounds: (DVec3, DVec3),
    /// A sphere under a similarity transform: its world centre and radius
    /// (intersected in world space, without the transform's rounding).
    pub world_sphere: Option<(DVec3, f64)>,
    /// Material.
    pub material: u16,
    /// Compute the spherical uv map at hits (spheres; the plan turns it off
    /// where the material reads no uvs).
    pub uv: bool,
}

/// The triangulated scene.
#[derive(Clone, Debug)]
pub struct TriScene {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Position indices per triangle.
    pub tris: Vec<[u32; 3]>,
    /// Unit normals.
    pub normals: Vec<Vec3>,
    /// Normal indices per triangle corner ([`NO_INDEX`]: flat triangle).
    pub tri_normals: Vec<[u32; 3]>,
    /// Texture coordinates.
    pub uvs: Vec<Vec2>,
    /// uv indices per triangle corner ([`NO_INDEX`]: no uv).
    pub tri_uvs: Vec<[u32; 3]>,
    /// Material per triangle.
    pub tri_material: Vec<u16>,
    /// Object per triangle.
    pub tri_object: Vec<u32>,
    /// Objects.
    pub objects: Vec<ObjectInfo>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Lights.
    pub lights: Vec<Light>,
    /// The camera (with its final image size and `far`).
    pub camera: Camera,
    /// Background colour.
    pub background: Rgb,
    /// `ambient_light`.
    pub ambient_light: Rgb,
    /// `max_depth`.
    pub max_depth: u32,
    /// Analytic shapes (used only with `--geometry analytic`).
    pub analytic: Vec<AnalyticShape>,
    /// Bounds of every triangle.
    pub bounds: Aabb,
    /// Messages for the user (e.g. a segment count capped).
    pub warnings: Vec<String>,
}

/// A primitive id decoded: a triangle, or the `k`-th analytic shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Prim {
    /// Triangle id.
    Triangle(u32),
    /// Index into [`TriScene::analytic`].
    Analytic(usize),
}

impl TriScene {
    /// The materials object `object`'s triangles use, each once, in index
    /// order (an OBJ mesh with `material = "obj"` has several; every other
    /// object one, [`ObjectInfo::material`]).
    #[must_use]
    pub fn object_materials(&self, object: usize) -> Vec<u16> {
        let info = &self.objects[object];
        let mut m: Vec<u16> = self
            .tri_material
            .get(info.tris.start as usize..info.tris.end as usize)
            .unwrap_or_default()
            .to_vec();
        m.push(info.material);
        m.sort_unstable();
        m.dedup();
        m
    }

    /// The shading context of this scene's materials and lights, with the
    /// gate half-width `gate_eps` and shadow rays on or off.
    #[must_use]
    pub fn shade_context(&self, gate_eps: f32, shadows: bool) -> ShadeContext<'_> {
        ShadeContext {
            materials: &self.materials,
            lights: &self.lights,
            ambient_light: self.ambient_light,
            gate_eps,
            shadows,
        }
    }

    /// A scene of flat triangles with one default material, no lights and
    /// a black background, as one object (closed if the triangles are): for
    /// tests, benchmarks and experiments that build geometry directly.
    #[must_use]
    pub fn from_triangles(camera: Camera, triangles: &[[Vec3; 3]]) -> TriScene {
        let positions: Vec<Vec3> = triangles.iter().flatten().copied().collect();
        let n = u32::try_from(triangles.len()).unwrap_or(u32::MAX);
        let tris: Vec<[u32; 3]> = (0..n).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
        let bounds = Aabb::from_points(positions.iter().copied());
        TriScene {
            positions,
            tris,
            normals: Vec::new(),
            tri_normals: vec![[NO_INDEX; 3]; triangles.len()],
            uvs: Vec::new(),
            tri_uvs: vec![[NO_INDEX; 3]; triangles.len()],
            tri_material: vec![0; triangles.len()],
            tri_object: vec![0; triangles.len()],
            objects: vec![ObjectInfo {
                label: "objects[0] (triangles)".into(),
                kind: "mesh",
                tris: 0..n,
                bounds,
                closed: false,
                no_shadow: false,
                material: 0,
                smooth: false,
                segments: None,
            }],
            materials: vec![Material::default()],
            lights: Vec::new(),
            camera,
            background: Rgb::BLACK,
            ambient_light: Rgb::WHITE,
            max_depth: 1,
            analytic: Vec::new(),
            bounds,
            warnings: Vec::new(),
        }
    }

    /// The same scene with every triangle split into four at its edge
    /// midpoints, `levels` times (4^levels as many triangles, the same
    /// surface): for scaling benchmarks. Normals and uvs are interpolated;
    /// objects keep their closedness (midpoints are shared between the two
    /// triangles of an edge).
    #[must_use]
    pub fn subdivided(&self, levels: u32) -> TriScene {
        let mut s = self.clone();
        for _ in 0..levels {
            s = s.subdivide_once();
        }
        s.order_vertices_by_first_use();
        s
    }

    /// Renumbers the position pool in the order the triangles first use
    /// each vertex, so walking the triangles walks the pool almost
    /// sequentially (a per-vertex array then stays in cache); unused
    /// positions are dropped.
    pub fn order_vertices_by_first_use(&mut self) {
        fn reorder<T: Copy>(pool: &mut Vec<T>, corners: &mut [[u32; 3]]) {
            let mut remap = vec![NO_INDEX; pool.len()];
            let mut out = Vec::with_capacity(pool.len());
            for v in corners.iter_mut().flatten().filter(|v| **v != NO_INDEX) {
                let slot = &mut remap[*v as usize];
                if *slot == NO_INDEX {
                    *slot = u32::try_from(out.len()).unwrap_or(NO_INDEX);
                    out.push(pool[*v as usize]);
                }
                *v = *slot;
            }
            *pool = out;
        }
        reorder(&mut self.positions, &mut self.tris);
        reorder(&mut self.normals, &mut self.tri_normals);
        reorder(&mut self.uvs, &mut self.tri_uvs);
    }

    fn subdivide_once(&self) -> TriScene {
        use std::collections::HashMap;
        let mut out = self.clone();
        out.tris.clear();
        out.tri_normals.clear();
        out.tri_uvs.clear();
        out.tri_material.clear();
        out.tri_object.clear();
        let mut mids: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |pool: &mut Vec<Vec3>, a: u32, b: u32| {
            *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let m = (pool[a as usize] + pool[b as usize]) * 0.5;
                pool.push(m);
                u32::try_from(pool.len() - 1).unwrap_or(u32::MAX)
            })
        };
        let push_attr = |pool: &mut Vec<Vec3>, a: u32, b: u32| {
            let m = (pool[a as usize] + pool[b as usize]).normalize_or_zero();
            pool.push(m);
            u32::try_from(pool.len() - 1).unwrap_or(u32::MAX)
        };
        for (k, t) in self.tris.iter().enumerate() {
            let [a, b, c] = *t;
            let (ab, bc, ca) = (
                mid(&mut out.positions, a, b),
                mid(&mut out.positions, b, c),
                mid(&mut out.positions, c, a),
            );
            let n = self.tri_normals[k];
            let nn = if n[0] == NO_INDEX {
                [[NO_INDEX; 3]; 4]
            } else {
                let (nab, nbc, nca) = (
                    push_attr(&mut out.normals, n[0], n[1]),
                    push_attr(&mut out.normals, n[1], n[2]),
                    push_attr(&mut out.normals, n[2], n[0]),
                );
                [
                    [n[0], nab, nca],
                    [nab, n[1], nbc],
                    [nca, nbc, n[2]],
                    [nab, nbc, nca],
                ]
            };
            let u = self.tri_uvs[k];
            let uu = if u[0] == NO_INDEX {
                [[NO_INDEX; 3]; 4]
            } else {
                let mut push_uv = |a: u32, b: u32| {
                    let m = (out.uvs[a as usize] + out.uvs[b as usize]) * 0.5;
                    out.uvs.push(m);
                    u32::try_from(out.uvs.len() - 1).unwrap_or(u32::MAX)
                };
                let (uab, ubc, uca) = (
                    push_uv(u[0], u[1]),
                    push_uv(u[1], u[2]),
                    push_uv(u[2], u[0]),
                );
                [
                    [u[0], uab, uca],
                    [uab, u[1], ubc],
                    [uca, ubc, u[2]],
                    [uab, ubc, uca],
                ]
            };
            let pt = [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]];
            for q in 0..4 {
                out.tris.push(pt[q]);
                out.tri_normals.push(nn[q]);
                out.tri_uvs.push(uu[q]);
                out.tri_material.push(self.tri_material[k]);
                out.tri_object.push(self.tri_object[k]);
            }
        }
        for o in &mut out.objects {
            o.tris = o.tris.start * 4..o.tris.end * 4;
        }
        out
    }

    /// Number of triangles.
    #[must_use]
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// `true` when there are no triangles.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The three vertex positions of a triangle.
    #[must_use]
    #[inline]
    pub fn triangle(&self, tri: u32) -> [Vec3; 3] {
        let t = self.tris[tri as usize];
        [
            self.positions[t[0] as usize],
            self.positions[t[1] as usize],
            self.positions[t[2] as usize],
        ]
    }

    /// The triangle's vertices in `f64` (exact widening).
    #[must_use]
    pub fn triangle_f64(&self, tri: u32) -> [DVec3; 3] {
        self.triangle(tri).map(to_f64)
    }

    /// Unit geometric normal `(v1 − v0) × (v2 − v0)` (zero for a degenerate triangle).
    #[must_use]
    #[inline]
    pub fn geometric_normal(&self, tri: u32) -> Vec3 {
        unit_normal(self.triangle(tri))
    }

    /// The weights a camera ray `(o, d)` (the `f64` primary ray of a
    /// sample) meets triangle `tri` at, as both backends shade them, and
    /// the `f64` point they give (for the frame's depth).
    ///
    /// The rasterizer (for each visible sample) and the ray tracer (for
    /// each primary hit) both call this, so a sample that sees the same
    /// triangle in both is shaded from bit-identical inputs. Where the ray
    /// is parallel to the triangle's plane (it cannot be seen there, but
    /// snapping can leave a sliver) the centroid stands in.
    #[must_use]
    pub fn view_weights(&self, tri: u32, o: DVec3, d: DVec3) -> (Bary, DVec3) {
        view_weights_of(self.triangle(tri), o, d)
    }

    /// [`TriScene::view_weights`] and [`TriScene::surface_at`] at them, with
    /// the triangle's vertices read once: the shading inputs of a camera
    /// ray's hit (or any ray's) and the `f64` point, bit for bit the two
    /// calls'.
    #[must_use]
    // Inlined into its callers with the chain under it (`view_weights_of`,
    // `surface_on`, `plane_point`; `view_surface_after` too): as calls,
    // the 940 k bunny's raster frame took 1.2× as long for 1.07× the
    // instructions (ARCHITECTURE.md, "The per-sample chain inlined").
    #[inline(always)]
    pub fn view_surface(&self, tri: u32, o: DVec3, d: DVec3) -> (SurfacePoint, DVec3) {
        let v = self.triangle(tri);
        let (b, p) = view_weights_of(v, o, d);
        (self.surface_on(tri, v, b), p)
    }

    /// Shading inputs of triangle `tri` at barycentric weights `b`.
    ///
    /// Both backends call this. If the raster and ray images differ on a
    /// sample, the cause is which triangle and which `b` they found there,
    /// never how the point was shaded.
    ///
    /// The point is formed in `f64` with the weights divided by their sum
    /// (so it lies on the triangle's plane up to `f64` rounding) and
    /// rounded to `f32` once: its distance from the plane is at most half
    /// an `f32` step of its own coordinates plus ~10⁻¹⁶ of the vertices,
    /// which is what `p_error` bounds (the offset of rays leaving it).
    #[must_use]
    pub fn surface_at(&self, tri: u32, b: Bary) -> SurfacePoint {
        self.surface_on(tri, self.triangle(tri), b)
    }

    /// [`TriScene::surface_at`] given the triangle's vertices `v`.
    ///
    /// Written out rather than as `tri_consts(tri, v).surface(b)`, which
    /// computes the same values with more instructions where a triangle is
    /// seen once (1.6 % of the 940 k bunny's raster frame when it took
    /// this path; the rasterizer now keeps the parts of every sample's
    /// triangle, and the ray tracer's secondary hits come here); the two
    /// must stay the same operations in the same order, and
    /// `kept_triangle_parts_give_the_same_shading_inputs` compares their
    /// bits on every bundled scene.
    #[inline(always)]
    fn surface_on(&self, tri: u32, v: [Vec3; 3], b: Bary) -> SurfacePoint {
        let i = tri as usize;
        let (p, p_error) = plane_point(v, b);
        let mut ng = unit_normal(v);
        let n_idx = self.tri_normals[i];
        let mut ns = if n_idx[0] == NO_INDEX {
            ng
        } else {
            let n = b.interpolate(n_idx.map(|k| self.normals[k as usize]));
            n.try_normalize().unwrap_or(ng)
        };
        if ng == Vec3::ZERO {
            // A degenerate triangle: take the shading normal, or any unit vector.
            ng = if ns == Vec3::ZERO { Vec3::Y } else { ns };
            if ns == Vec3::ZERO {
                ns = ng;
            }
        }
        let material = self.tri_material[i];
        let uv_idx = self.tri_uvs[i];
        let (uv, dpdu, dpdv) = if uv_idx[0] == NO_INDEX {
            (None, Vec3::ZERO, Vec3::ZERO)
        } else {
            let t = uv_idx.map(|k| self.uvs[k as usize]);
            let uv = b.interpolate2(t);
            let (dpdu, dpdv) = if self.materials[usize::from(material)].bump.is_some() {
                uv_derivatives(v, t)
            } else {
                (Vec3::ZERO, Vec3::ZERO)
            };
            (Some(uv), dpdu, dpdv)
        };
        SurfacePoint {
            p,
            p_error,
            ng,
            ns,
            uv,
            dpdu,
            dpdv,
            material,
            object: self.tri_object[i],
            prim: tri,
        }
    }

    /// What [`TriScene::surface_at`] reads or derives from triangle `tri`
    /// (vertices `v`) alone, whatever the weights.
    #[inline]
    fn tri_consts(&self, tri: u32, v: [Vec3; 3]) -> TriConsts {
        let i = tri as usize;
        let n_idx = self.tri_normals[i];
        let normals = (n_idx[0] != NO_INDEX).then(|| n_idx.map(|k| self.normals[k as usize]));
        let material = self.tri_material[i];
        let uv_idx = self.tri_uvs[i];
        let uvs = (uv_idx[0] != NO_INDEX).then(|| uv_idx.map(|k| self.uvs[k as usize]));
        let (dpdu, dpdv) = match uvs {
            Some(t) if self.materials[usize::from(material)].bump.is_some() => uv_derivatives(v, t),
            _ => (Vec3::ZERO, Vec3::ZERO),
        };
        TriConsts {
            tri,
            v,
            ng: unit_normal(v),
            normals,
            uvs,
            dpdu,
            dpdv,
            material,
            object: self.tri_object[i],
            from_origin: None,
            again: false,
        }
    }

    /// [`TriScene::view_surface`] for a run of samples that often see the
    /// same triangle one after another (a row of the rasterizer's): what
    /// depends on the triangle alone is kept in `last` and formed again
    /// only when `tri` changes. The same operations on the same values, so
    /// the same bits as `view_surface`.
    #[must_use]
    #[inline(always)]
    pub fn view_surface_after(
        &self,
        last: &mut Option<TriConsts>,
        tri: u32,
        o: DVec3,
        d: DVec3,
    ) -> (SurfacePoint, DVec3) {
        let c = match last {
            Some(c) if c.tri == tri => c,
            _ => last.insert(self.tri_consts(tri, self.triangle(tri))),
        };
        let (b, p) = c.view_weights(o, d);
        (c.surface(b), p)
    }

    /// Checks, in debug builds, the invariants every renderer indexes by
    /// without checking: one material, object, normal and uv triple per
    /// triangle; every position index within the pool; every normal and uv
    /// index within its pool or [`NO_INDEX`]; every material and object
    /// index within its table.
    pub fn debug_check(&self) {
        let n = self.tris.len();
        debug_assert!(
            self.tri_material.len() == n
                && self.tri_object.len() == n
                && self.tri_normals.len() == n
                && self.tri_uvs.len() == n,
            "one material, object, normal and uv triple per triangle"
        );
        debug_assert!(
            self.tris
                .iter()
                .flatten()
                .all(|&i| (i as usize) < self.positions.len()),
            "position indices within the pool"
        );
        debug_assert!(
            self.tri_normals
                .iter()
                .flatten()
                .all(|&i| i == NO_INDEX || (i as usize) < self.normals.len())
                && self
                    .tri_uvs
                    .iter()
                    .flatten()
                    .all(|&i| i == NO_INDEX || (i as usize) < self.uvs.len()),
            "normal and uv indices within their pools"
        );
        debug_assert!(
            self.tri_material
                .iter()
                .all(|&m| usize::from(m) < self.materials.len())
                && self
                    .tri_object
                    .iter()
                    .all(|&o| (o as usize) < self.objects.len()),
            "material and object indices within their tables"
        );
    }

    /// Id of analytic shape `k` (above every triangle id).
    #[must_use]
    pub fn analytic_id(&self, k: usize) -> u32 {
        u32::try_from(self.tris.len() + k).unwrap_or(u32::MAX)
    }

    /// What a primitive id names: triangle ids come first, then one id per
    /// analytic shape ([`TriScene::analytic_id`]).
    #[must_use]
    pub fn prim(&self, id: u32) -> Prim {
        let i = id as usize;
        if i < self.tris.len() {
            Prim::Triangle(id)
        } else {
            Prim::Analytic(i - self.tris.len())
        }
    }

    /// Shading inputs of analytic shape `k` at world point `p` on it.
    #[must_use]
    pub fn analytic_surface_at(&self, k: usize, p: DVec3) -> SurfacePoint {
        let s = &self.analytic[k];
        let n = match s.world_sphere {
            Some((center, radius)) => ((p - center) / radius).normalize_or_zero(),
            None => s.placed.world_normal(p),
        };
        let uv = match s.placed.kind {
            AnalyticKind::Sphere { center, .. } if s.uv => Some(sphere_uv(
                (s.placed.to_object.transform_point3(p) - center).normalize_or_zero(),
            )),
            _ => None,
        };
        let p32 = to_f32(p);
        // The hit point comes from a root refined in f64 (the stable
        // quadratic, slabs, or bisection to the last bits) and, under a
        // transform, one affine map: its error is a few ulps of the largest
        // coordinate involved, far below the f32 point's own rounding.
        let (lo, hi) = s.bounds;
        let scale = p.abs().max(lo.abs()).max(hi.abs());
        let p_error = to_f32(scale * 8.0 * f64::from(f32::EPSILON));
        let ns = to_f32(n);
        SurfacePoint {
            p: p32,
            p_error,
            ng: ns,
            ns,
            uv,
            dpdu: Vec3::ZERO,
            dpdv: Vec3::ZERO,
            material: s.material,
            object: s.object,
            prim: self.analytic_id(k),
        }
    }

    /// The object of a primitive id (triangle or analytic shape).
    #[must_use]
    pub fn object_of(&self, prim: u32) -> Option<u32> {
        let i = prim as usize;
        if i < self.tris.len() {
            Some(self.tri_object[i])
        } else {
            self.analytic.get(i - self.tris.len()).map(|s| s.object)
        }
    }

    /// Bytes held by the geometry arrays (for the resource report).
    #[must_use]
    pub fn geometry_bytes(&self) -> usize {
        use std::mem::size_of;
        self.positions.len() * size_of::<Vec3>()
            + self.tris.len() * size_of::<[u32; 3]>()
            + self.normals.len() * size_of::<Vec3>()
            + self.tri_normals.len() * size_of::<[u32; 3]>()
            + self.uvs.len() * size_of::<Vec2>()
            + self.tri_uvs.len() * size_of::<[u32; 3]>()
            + self.tri_material.len() * size_of::<u16>()
            + self.tri_object.len() * size_of::<u32>()
    }
}

/// What a triangle's shading inputs take from the triangle alone
/// ([`TriScene::view_surface_after`] keeps it from sample to sample).
#[derive(Clone, Copy, Debug)]
pub struct TriConsts {
    tri: u32,
    v: [Vec3; 3],
    /// `unit_normal(v)`: zero for a degenerate triangle.
    ng: Vec3,
    normals: Option<[Vec3; 3]>,
    uvs: Option<[Vec2; 3]>,
    dpdu: Vec3,
    dpdv: Vec3,
    material: u16,
    object: u32,
    /// The parts of the view weights' plane test that depend on the
    /// triangle and the ray's origin alone, for the origin they were formed
    /// with (a perspective camera's rays all leave the eye).
    from_origin: Option<FromOrigin>,
    /// A sample has taken the view weights already: the next forms
    /// `from_origin` (a triangle one ray sees, as most of a dense mesh's,
    /// never pays for it).
    again: bool,
}

/// [`PlaneFromOrigin`] for one origin (its bits, the key), with the `f64`
/// corners it was formed from.
#[derive(Clone, Copy, Debug)]
struct FromOrigin {
    o: [u64; 3],
    v: [DVec3; 3],
    plane: PlaneFromOrigin,
}

impl TriConsts {
    /// [`view_weights_of`] for this triangle, with the part that depends
    /// on the origin alone ([`PlaneFromOrigin`]) kept while the origin
    /// stays the same: the same operations on the same values, so the
    /// same bits.
    #[inline]
    fn view_weights(&mut self, o: DVec3, d: DVec3) -> (Bary, DVec3) {
        if !self.again {
            self.again = true;
            return view_weights_of(self.v, o, d);
        }
        let key = o.to_array().map(f64::to_bits);
        let m = match &mut self.from_origin {
            Some(m) if m.o == key => m,
            slot => {
                let v = self.v.map(to_f64);
                slot.insert(FromOrigin {
                    o: key,
                    v,
                    plane: PlaneFromOrigin::new(o, v),
                })
            }
        };
        weights_and_point(m.v, m.plane.at(d))
    }

    /// The triangle it belongs to.
    #[must_use]
    pub fn tri(&self) -> u32 {
        self.tri
    }

    /// The shading inputs at weights `b` (see [`TriScene::surface_at`]).
    #[inline]
    fn surface(&self, b: Bary) -> SurfacePoint {
        let (p, p_error) = plane_point(self.v, b);
        let mut ng = self.ng;
        let mut ns = match self.normals {
            None => ng,
            Some(n) => b.interpolate(n).try_normalize().unwrap_or(ng),
        };
        if ng == Vec3::ZERO {
            // A degenerate triangle: take the shading normal, or any unit vector.
            ng = if ns == Vec3::ZERO { Vec3::Y } else { ns };
            if ns == Vec3::ZERO {
                ns = ng;
            }
        }
        SurfacePoint {
            p,
            p_error,
            ng,
            ns,
            uv: self.uvs.map(|t| b.interpolate2(t)),
            dpdu: self.dpdu,
            dpdv: self.dpdv,
            material: self.material,
            object: self.object,
            prim: self.tri,
        }
    }
}

/// The point `Σ b_i v_i / Σ b_i`, formed in `f64` and rounded to `f32`
/// once, and a bound per axis on its distance from the exact point of the
/// triangle's plane with those weights: the final rounding (2⁻²⁴ of each
/// coordinate) plus the `f64` arithmetic (γ₈ of `Σ|b_i v_i|`), rounded up.
/// Unit geometric normal `(v1 − v0) × (v2 − v0)` of a triangle (zero for a
/// degenerate one).
#[inline]
fn unit_normal([a, b, c]: [Vec3; 3]) -> Vec3 {
    let n = (b - a).cross(c - a);
    if n.is_finite() {
        n.normalize_or_zero()
    } else {
        // Edges so long their products overflow f32: take it in f64.
        to_f32(to_f64(b - a).cross(to_f64(c - a)).normalize_or_zero())
    }
}

/// The weights the ray `(o, d)` meets triangle `v`'s plane at, rounded for
/// shading, and the `f64` point they give (see [`TriScene::view_weights`]).
#[inline(always)]
fn view_weights_of(v: [Vec3; 3], o: DVec3, d: DVec3) -> (Bary, DVec3) {
    let v = v.map(to_f64);
    weights_and_point(v, plane_barycentrics(o, d, v))
}

/// The shading weights and the `f64` point of a plane test's answer on the
/// triangle `v` (the centroid where the line is parallel to the plane).
#[inline]
fn weights_and_point(v: [DVec3; 3], hit: Option<([f64; 3], f64)>) -> (Bary, DVec3) {
    let w = hit.map_or([1.0 / 3.0; 3], |(w, _)| w);
    let b = Bary::from_f64(w);
    let s = w[0] + w[1] + w[2];
    let p = (v[0] * w[0] + v[1] * w[1] + v[2] * w[2]) / s;
    (b, p)
}

#[inline(always)]
fn plane_point(v: [Vec3; 3], b: Bary) -> (Vec3, Vec3) {
    let w = b.0.map(f64::from);
    let sum = w[0] + w[1] + w[2];
    let s = if sum != 0.0 && sum.is_finite() {
        sum
    } else {
        1.0
    };
    let v64 = v.map(to_f64);
    let p64 = (v64[0] * w[0] + v64[1] * w[1] + v64[2] * w[2]) / s;
    let p = to_f32(p64);
    let spread = (v64[0] * w[0]).abs() + (v64[1] * w[1]).abs() + (v64[2] * w[2]).abs();
    let err = to_f64(p).abs() * f64::from(F32_EPS) + spread * (gamma64(8) / s.abs());
    // Rounded up (without a branch), so the f32 bound never falls below
    // the f64 one.
    (
        p,
        Vec3::new(
            f32_at_least(err.x),
            f32_at_least(err.y),
            f32_at_least(err.z),
        ),
    )
}

/// POV-Ray's spherical map (POVRAY.md §9.1) of a unit direction in the
/// sphere's own frame: `u = atan2(z, x)/2π` in [0, 1), `v = 0.5 + asin(y)/π`.
#[must_use]
pub(crate) fn sphere_uv(q: DVec3) -> Vec2 {
    // At the poles u = 0 (POVRAY.md §9.1).
    let mut u = if q.x == 0.0 && q.z == 0.0 {
        0.0
    } else {
        q.z.atan2(q.x) / std::f64::consts::TAU
    };
    if u < 0.0 {
        u += 1.0;
    }
    if u >= 1.0 {
        u -= 1.0;
    }
    let v = 0.5 + q.y.clamp(-1.0, 1.0).asin() / std::f64::consts::PI;
    #[expect(clippy::cast_possible_truncation, reason = "uv rounded to f32 once")]
    Vec2::new(u as f32, v as f32)
}

/// ∂P/∂u and ∂P/∂v of a triangle from its positions and uvs (zero when the
/// uv triangle is degenerate): solves `[P1 − P0, P2 − P0] = [P_u P_v]·[[Δu1, Δu2], [Δv1, Δv2]]`.
#[must_use]
pub(crate) fn uv_derivatives(p: [Vec3; 3], t: [Vec2; 3]) -> (Vec3, Vec3) {
    let (dp1, dp2) = (to_f64(p[1] - p[0]), to_f64(p[2] - p[0]));
    let du1 = f64::from(t[1].x - t[0].x);
    let dv1 = f64::from(t[1].y - t[0].y);
    let du2 = f64::from(t[2].x - t[0].x);
    let dv2 = f64::from(t[2].y - t[0].y);
    let det = du1 * dv2 - du2 * dv1;
    if det == 0.0 || !det.is_finite() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    let pu = (dp1 * dv2 - dp2 * dv1) / det;
    let pv = (dp2 * du1 - dp1 * du2) / det;
    (to_f32(pu), to_f32(pv))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uv_derivatives_of_a_unit_square_triangle() {
        let p = [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
        ];
        let t = [Vec2::ZERO, Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0)];
        let (pu, pv) = uv_derivatives(p, t);
        assert_eq!(pu, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(pv, Vec3::new(0.0, 3.0, 0.0));
    }

    #[test]
    fn sphere_uv_follows_povray() {
        // u = 0 on +x, 0.25 on +z, 0.5 on -x; v = 1 at the +y pole.
        let close = |a: Vec2, b: Vec2| (a - b).length() < 1e-6;
        assert!(close(sphere_uv(DVec3::X), Vec2::new(0.0, 0.5)));
        assert!(close(sphere_uv(DVec3::Z), Vec2::new(0.25, 0.5)));
        assert!(close(sphere_uv(-DVec3::X), Vec2::new(0.5, 0.5)));
        assert!(close(sphere_uv(DVec3::Y), Vec2::new(0.0, 1.0)));
        assert!(close(sphere_uv(-DVec3::Y), Vec2::new(0.0, 0.0)));
    }
}
