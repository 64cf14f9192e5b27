//! The render plan (DESIGN.md §7): before rendering, decide what work this
//! scene cannot need, and say why.
//!
//! Every decision switches work off only where it cannot change a pixel;
//! `--no-plan` forces everything on, and the invariant tests render every
//! scene both ways and require bit-identical output.

use std::fmt;

use rendiff_core::math::{DVec3, to_f64};
use rendiff_core::options::{BvhBuild, BvhMode};
use rendiff_core::tri_scene::{NO_INDEX, TriScene};

/// Scenes with at most this many triangles use a flat loop instead of a
/// BVH when `bvh = "auto"`. Measured with `cargo bench --bench render --
/// flat_loop_vs_bvh` (a 256×256 frame of primary rays, build included;
/// medians): 16 triangles 2.20 ms flat / 2.68 ms BVH, 32 triangles
/// 3.74 / 3.83 ms, 64 triangles 7.25 / 5.12 ms. That layout is one cluster;
/// scenes of separate objects favour the BVH sooner: `scenes/grazing.toml`
/// (26 triangles: a floor and two small boxes) renders 8–10 % faster with
/// one (`rendiff bench --sweep plan`, fastest runs). Up to 8 triangles the
/// SAH itself makes one leaf, so both are the same loop there.
pub const FLAT_LOOP_MAX_TRIANGLES: usize = 16;

/// One decision of the plan.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decision {
    /// What is decided.
    pub what: &'static str,
    /// On or off.
    pub on: bool,
    /// Why.
    pub why: String,
}

/// What a render of a scene needs.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Cast shadow rays.
    pub shadows: bool,
    /// Trace the ray tree (reflection / transmission).
    pub ray_tree: bool,
    /// Use a BVH (else a flat loop).
    pub bvh: bool,
    /// How the ray tracer's BVH is built (the rasterizer decides its
    /// shadow BVH's by the same rule once it has counted the visible
    /// samples).
    pub bvh_build: BvhBuild,
    /// Per object: can be culled from primary visibility (outside the frustum).
    pub frustum_cull: Vec<bool>,
    /// Per object: back faces can be culled by the rasterizer's primary visibility.
    pub backface_cull: Vec<bool>,
    /// Per material: its uvs are needed (an image pigment or a bump map).
    pub uv: Vec<bool>,
    /// The decisions, for `rendiff plan`.
    pub decisions: Vec<Decision>,
}

impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for d in &self.decisions {
            writeln!(
                f,
                "  {:<22} {:<3}  {}",
                d.what,
                if d.on { "on" } else { "off" },
                d.why
            )?;
        }
        Ok(())
    }
}

impl Plan {
    /// Everything on (`--no-plan`).
    #[must_use]
    pub fn everything(scene: &TriScene, bvh: BvhMode) -> Plan {
        let n = scene.objects.len();
        Plan {
            shadows: true,
            ray_tree: true,
            bvh: bvh != BvhMode::Off,
            bvh_build: BvhBuild::Sah,
            frustum_cull: vec![false; n],
            backface_cull: vec![false; n],
            uv: vec![true; scene.materials.len()],
            decisions: vec![Decision {
                what: "everything",
                on: true,
                why: "--no-plan".into(),
            }],
        }
    }

    /// The plan for a scene.
    #[must_use]
    pub fn for_scene(scene: &TriScene, bvh_mode: BvhMode, max_depth: u32) -> Plan {
        let (shadows, shadow_decision) = decide_shadows(scene);
        let (ray_tree, ray_tree_decision) = decide_ray_tree(scene, max_depth);
        let (uv, uv_decision) = decide_uv(scene);
        let smooth_decision = decide_smooth_normals(scene);
        let (bvh, bvh_decision) = decide_bvh(scene, bvh_mode);
        let (bvh_build, build_decision) = decide_bvh_build(scene, bvh, shadows);
        let (frustum_cull, frustum_decision) = decide_frustum_cull(scene);
        let (backface_cull, backface_decision) = decide_backface_cull(scene);
        let light_buffer_decision = decide_light_buffer(scene, shadows);
        Plan {
            shadows,
            ray_tree,
            bvh,
            bvh_build,
            frustum_cull,
            backface_cull,
            uv,
            decisions: vec![
                shadow_decision,
                ray_tree_decision,
                uv_decision,
                smooth_decision,
                bvh_decision,
                build_decision,
                frustum_decision,
                backface_decision,
                light_buffer_decision,
            ],
        }
    }

    /// Applies the decisions that change the triangle scene itself: drops
    /// the uvs of triangles (and analytic spheres) whose material reads
    /// none. Returns how many primitives lost their uvs.
    pub fn apply(&self, scene: &mut TriScene) -> usize {
        let mut dropped = 0;
        for (t, m) in scene.tri_uvs.iter_mut().zip(&scene.tri_material) {
            if t[0] != NO_INDEX && !self.uv.get(usize::from(*m)).copied().unwrap_or(true) {
                *t = [NO_INDEX; 3];
                dropped += 1;
            }
        }
        if scene.tri_uvs.iter().all(|t| t[0] == NO_INDEX) {
            scene.uvs = Vec::new();
        }
        for s in &mut scene.analytic {
            if s.uv
                && !self
                    .uv
                    .get(usize::from(s.material))
                    .copied()
                    .unwrap_or(true)
            {
                s.uv = false;
                dropped += 1;
            }
        }
        dropped
    }
}

/// Shadow rays: only lights that are not shadowless cast them, and only
/// objects without `no_shadow` can block them.
fn decide_shadows(scene: &TriScene) -> (bool, Decision) {
    let shadow_lights = scene.lights.iter().filter(|l| !l.shadowless).count();
    let casters = scene.objects.iter().filter(|o| !o.no_shadow).count();
    let shadows = shadow_lights > 0 && casters > 0;
    let decision = Decision {
        what: "shadow rays",
        on: shadows,
        why: if shadow_lights == 0 {
            "no light casts shadows (all shadowless, or none)".into()
        } else if casters == 0 {
            "every object has no_shadow".into()
        } else {
            format!("{shadow_lights} shadow-casting light(s), {casters} casting object(s)")
        },
    };
    (shadows, decision)
}

/// The ray tree: needed only where a visible material reflects or
/// transmits, and only when `max_depth` allows a second bounce.
fn decide_ray_tree(scene: &TriScene, max_depth: u32) -> (bool, Decision) {
    let spawning: Vec<&str> = scene
        .materials
        .iter()
        .enumerate()
        .filter(|(i, m)| {
            m.spawns_rays()
                && (0..scene.objects.len()).any(|o| {
                    scene
                        .object_materials(o)
                        .contains(&u16::try_from(*i).unwrap_or(u16::MAX))
                })
        })
        .map(|(_, m)| m.name.as_str())
        .collect();
    let ray_tree = !spawning.is_empty() && max_depth > 1;
    let decision = Decision {
        what: "ray tree",
        on: ray_tree,
        why: if max_depth <= 1 {
            "max_depth = 1".into()
        } else if spawning.is_empty() {
            "no material reflects or transmits".into()
        } else {
            format!("reflecting/transmitting: {}", spawning.join(", "))
        },
    };
    (ray_tree, decision)
}

/// uv and texture work: only materials with an image pigment or a bump map
/// read uvs; the other triangles drop theirs (`apply`). Returns the
/// per-material flags.
fn decide_uv(scene: &TriScene) -> (Vec<bool>, Decision) {
    let uv: Vec<bool> = scene.materials.iter().map(|m| m.needs_uv()).collect();
    let with_uv = scene
        .tri_uvs
        .iter()
        .zip(&scene.tri_material)
        .filter(|(t, _)| t[0] != NO_INDEX)
        .count();
    let kept = scene
        .tri_uvs
        .iter()
        .zip(&scene.tri_material)
        .filter(|(t, m)| t[0] != NO_INDEX && uv[usize::from(**m)])
        .count();
    let textured: Vec<&str> = scene
        .materials
        .iter()
        .zip(&uv)
        .filter(|(_, u)| **u)
        .map(|(m, _)| m.name.as_str())
        .collect();
    let decision = Decision {
        what: "uv and textures",
        on: !textured.is_empty(),
        why: if textured.is_empty() {
            format!(
                "no material has an image pigment or a bump map; uvs of {with_uv} triangle(s) dropped"
            )
        } else {
            format!(
                "textured: {}; uvs kept on {kept} of {with_uv} triangle(s)",
                textured.join(", ")
            )
        },
    };
    (uv, decision)
}

/// Smooth normals: interpolated only on triangles that carry corner normals
/// (smooth = true meshes and curved shapes); smooth = false meshes were
/// tessellated without them. Reported only; nothing is switched.
fn decide_smooth_normals(scene: &TriScene) -> Decision {
    let smooth = scene
        .tri_normals
        .iter()
        .filter(|t| t[0] != NO_INDEX)
        .count();
    let flat_meshes = scene.objects.iter().filter(|o| !o.smooth).count();
    Decision {
        what: "smooth normals",
        on: smooth > 0,
        why: format!(
            "interpolated on {smooth} of {} triangle(s); {flat_meshes} object(s) flat",
            scene.len()
        ),
    }
}

/// BVH or flat loop: as `bvh` says, or with `auto` a BVH only above
/// [`FLAT_LOOP_MAX_TRIANGLES`] triangles.
fn decide_bvh(scene: &TriScene, bvh_mode: BvhMode) -> (bool, Decision) {
    let bvh = match bvh_mode {
        BvhMode::On => true,
        BvhMode::Off => false,
        BvhMode::Auto => scene.len() > FLAT_LOOP_MAX_TRIANGLES,
    };
    let decision = Decision {
        what: "BVH",
        on: bvh,
        why: match bvh_mode {
            BvhMode::On => "bvh = \"on\"".into(),
            BvhMode::Off => "bvh = \"off\"".into(),
            BvhMode::Auto => format!(
                "{} triangles ({} a flat loop is faster up to {FLAT_LOOP_MAX_TRIANGLES})",
                scene.len(),
                if bvh { "above" } else { "at or below" }
            ),
        },
    };
    (bvh, decision)
}

/// The ray tracer's BVH build: in Morton order where its primary rays and
/// one shadow ray per sample and shadow-casting light (the rays every
/// frame casts; the ray tree's come on top) are fewer than
/// [`BvhBuild::MORTON_BELOW_RAYS_PER_TRIANGLE`] per triangle, else by the
/// SAH.
fn decide_bvh_build(scene: &TriScene, bvh: bool, shadows: bool) -> (BvhBuild, Decision) {
    let cam = &scene.camera;
    let samples = u64::from(cam.sample_width()) * u64::from(cam.sample_height());
    let lights = if shadows {
        scene.lights.iter().filter(|l| !l.shadowless).count()
    } else {
        0
    };
    let rays = samples.saturating_mul(1 + u64::try_from(lights).unwrap_or(u64::MAX));
    let build = if bvh {
        BvhBuild::for_rays(rays, scene.len())
    } else {
        BvhBuild::Sah
    };
    let per = BvhBuild::MORTON_BELOW_RAYS_PER_TRIANGLE;
    let decision = Decision {
        what: "Morton-order BVH",
        on: build == BvhBuild::Morton,
        why: if bvh {
            format!(
                "{rays} primary and shadow rays for {} triangles ({} {per} per triangle: {})",
                scene.len(),
                if build == BvhBuild::Morton {
                    "below"
                } else {
                    "at or above"
                },
                if build == BvhBuild::Morton {
                    "the faster build"
                } else {
                    "the SAH's faster walk"
                }
            )
        } else {
            "no BVH".into()
        },
    };
    (build, decision)
}

/// The ray tracer's light buffers (built by `Accel::new` by the rule
/// of [`rendiff_core::options::light_buffer_pays`] for one shadow ray per
/// camera sample and light, and only where every caster is a triangle:
/// with analytic shapes that cast, `--geometry analytic` has none). The
/// rasterizer applies the rule to its visible samples.
fn decide_light_buffer(scene: &TriScene, shadows: bool) -> Decision {
    let cam = &scene.camera;
    let rays = u64::from(cam.sample_width()) * u64::from(cam.sample_height());
    let casters = scene
        .tri_object
        .iter()
        .filter(|&&o| !scene.objects[o as usize].no_shadow)
        .count() as u64;
    let per = rendiff_core::options::LIGHT_BUFFER_RAYS_PER_TRIANGLE;
    let on = shadows && rendiff_core::options::light_buffer_pays(rays, casters);
    Decision {
        what: "light buffer",
        on,
        why: if shadows {
            format!(
                "{rays} camera samples per light for {casters} casting triangles ({} {per} per triangle: {})",
                if on { "at or above" } else { "below" },
                if on {
                    "a grid of the triangles seen from each light answers most shadow rays without a walk; a light whose grid is crowded is dropped after its build"
                } else {
                    "its build would cost more than it saves"
                }
            )
        } else {
            "no shadow rays".into()
        },
    }
}

/// Frustum culling: per object, whether it lies entirely outside the view
/// (primary visibility only).
fn decide_frustum_cull(scene: &TriScene) -> (Vec<bool>, Decision) {
    let frustum_cull = scene
        .objects
        .iter()
        .map(|o| outside_frustum(scene, o.bounds))
        .collect::<Vec<_>>();
    let culled = frustum_cull.iter().filter(|c| **c).count();
    let decision = Decision {
        what: "frustum culling",
        on: culled > 0,
        why: format!(
            "{culled} of {} object(s) entirely outside the view (primary visibility only)",
            scene.objects.len()
        ),
    };
    (frustum_cull, decision)
}

/// Back-face culling: per object, whether it is closed, opaque and seen
/// only from outside (the near rectangle does not touch it), so the
/// rasterizer's primary visibility may drop its back faces.
fn decide_backface_cull(scene: &TriScene) -> (Vec<bool>, Decision) {
    let backface_cull: Vec<bool> = scene
        .objects
        .iter()
        .enumerate()
        .map(|(k, o)| {
            let opaque = scene
                .object_materials(k)
                .iter()
                .all(|&m| !scene.materials[usize::from(m)].is_transparent());
            o.closed && opaque && !near_rect_touches(scene, o.bounds)
        })
        .collect();
    let bf = backface_cull.iter().filter(|c| **c).count();
    let decision = Decision {
        what: "back-face culling",
        on: bf > 0,
        why: format!(
            "{bf} of {} object(s) closed, opaque and seen from outside (raster primary visibility)",
            scene.objects.len()
        ),
    };
    (backface_cull, decision)
}

/// `true` when a box lies entirely outside one plane of the view frustum
/// (near, far, or a side), tested conservatively in `f64`.
fn outside_frustum(scene: &TriScene, b: rendiff_core::math::Aabb) -> bool {
    if b.is_empty() {
        return true;
    }
    let cam = &scene.camera;
    let corners: Vec<DVec3> = b.corners().iter().map(|c| to_f64(*c)).collect();
    let view: Vec<DVec3> = corners.iter().map(|c| cam.to_view(*c)).collect();
    let z: Vec<f64> = view.iter().map(|v| v.z).collect();
    if z.iter().all(|&z| z < cam.near()) || z.iter().all(|&z| z > cam.far()) {
        return true;
    }
    let aspect = cam.aspect();
    let (sx, sy) = match cam.projection() {
        rendiff_core::camera::Projection::Perspective { tan_half_fov: t } => (t * aspect, t),
        rendiff_core::camera::Projection::Orthographic { .. } => {
            return outside_ortho(scene, &view);
        }
    };
    // Side planes: |x| ≤ sx·z, |y| ≤ sy·z (with a relative margin).
    let margin = 1e-6;
    let xs: Vec<f64> = view.iter().map(|v| v.x).collect();
    let ys: Vec<f64> = view.iter().map(|v| v.y).collect();
    let all = |pred: &dyn Fn(usize) -> bool| (0..8).all(pred);
    all(&|k| xs[k] > sx * z[k] * (1.0 + margin) + margin)
        || all(&|k| -xs[k] > sx * z[k] * (1.0 + margin) + margin)
        || all(&|k| ys[k] > sy * z[k] * (1.0 + margin) + margin)
        || all(&|k| -ys[k] > sy * z[k] * (1.0 + margin) + margin)
}

fn outside_ortho(scene: &TriScene, view: &[DVec3]) -> bool {
    let cam = &scene.camera;
    let rendiff_core::camera::Projection::Orthographic { view_height: h } = cam.projection() else {
        return false;
    };
    let (hw, hh) = (h * cam.aspect() / 2.0, h / 2.0);
    let margin = 1e-6 * h;
    let xs: Vec<f64> = view.iter().map(|v| v.x).collect();
    let ys: Vec<f64> = view.iter().map(|v| v.y).collect();
    xs.iter().all(|&x| x > hw + margin)
        || xs.iter().all(|&x| x < -hw - margin)
        || ys.iter().all(|&y| y > hh + margin)
        || ys.iter().all(|&y| y < -hh - margin)
}

/// `true` when the camera's near rectangle (the part of the near plane the
/// view sees) touches the box: then the eye may see the object's inside
/// and back faces must stay (DESIGN.md §7).
fn near_rect_touches(scene: &TriScene, b: rendiff_core::math::Aabb) -> bool {
    let cam = &scene.camera;
    let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
    // The four near-rectangle corners and its centre; the box is tested
    // against the rectangle's bounding box, slightly enlarged (conservative).
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for (x, y) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
        let (o, d) = cam.primary_ray_f64(x, y);
        let p = o + d * cam.near_t(d);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    // The eye itself (perspective) lies behind the near rectangle; include
    // it so a box containing the eye always counts.
    lo = lo.min(cam.eye());
    hi = hi.max(cam.eye());
    let pad = (hi - lo).length() * 1e-6 + 1e-12;
    let (bl, bh) = (to_f64(b.min), to_f64(b.max));
    !(bh.x < lo.x - pad
        || bl.x > hi.x + pad
        || bh.y < lo.y - pad
        || bl.y > hi.y + pad
        || bh.z < lo.z - pad
        || bl.z > hi.z + pad)
}
