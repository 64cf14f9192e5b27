//! Why a rendered pixel differs from a reference image (POV-Ray, or any
//! image rendered from the same scene): the causes that are not errors,
//! found from the frame's own G-buffer and exact ray queries.
//!
//! A pixel is explained when one of its samples lies
//! * at an **edge**: within ε_edge of an edge of its visible triangle, or
//!   next to a sample that sees another object or the background (a
//!   silhouette, where another renderer's intersection test may decide the
//!   other way);
//! * on a **depth tie**: a second surface lies within the depth tolerance
//!   along its primary ray (coincident surfaces, which each renderer breaks
//!   its own way);
//! * on a **shadow boundary**: an 8-neighbour has another shadow bit (each
//!   renderer's shadow-ray epsilon moves the boundary by a fraction of a
//!   sample), or the sample is flagged as a shading discontinuity;
//! * **before the near plane**: its primary ray meets geometry nearer than
//!   `near`, which the backends ignore and POV-Ray renders;
//! * **in the ray tree**: its visible surface reflects or transmits and the
//!   primary sample is none of the above, so the difference arises along a
//!   secondary ray (which meets edges, shadow boundaries and critical angles
//!   at positions no sample grid controls). Counted apart: a comparison can
//!   bound it;
//! * under a **Blinn bump**: its visible surface has a bump map with
//!   `method = "blinn"`, which POV-Ray (whose `bump_map` is the other
//!   method, DESIGN.md §3) does not compute; counted apart for the same
//!   reason.
//!
//! Anything else is unexplained.

use serde::Serialize;

use super::oracle::Oracle;
use crate::accel::Accel;
use crate::frame::{BACKGROUND, Frame};
use crate::math::Ray64;
use crate::shade::FLAG_DISCONTINUITY;
use crate::tri_scene::Prim;

/// Why a pixel differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum Explanation {
    /// Geometry nearer than the near plane.
    NearPlane,
    /// A surface bump-mapped by Blinn's method, which POV-Ray does not
    /// have (ranked before the causes below: no pixel of it can match).
    BlinnBump,
    /// Coincident surfaces.
    DepthTie,
    /// A triangle edge or silhouette.
    Edge,
    /// A shadow boundary or shading discontinuity.
    ShadowOrGate,
    /// Along a secondary ray of a reflecting or transmitting surface.
    RayTree,
    /// Nothing above.
    Unexplained,
}

/// Counts of the explanations of the differing pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Explained {
    /// Pixels that differ by more than the threshold.
    pub differing: u64,
    /// At the near plane.
    pub near_plane: u64,
    /// Depth ties.
    pub depth_tie: u64,
    /// Edges and silhouettes.
    pub edge: u64,
    /// Shadow boundaries and gates.
    pub shadow_or_gate: u64,
    /// Secondary rays of reflecting or transmitting surfaces.
    pub ray_tree: u64,
    /// Surfaces bump-mapped by Blinn's method.
    pub blinn_bump: u64,
    /// The rest.
    pub unexplained: u64,
}

/// Explains one pixel of `frame`.
#[must_use]
pub(crate) fn explain_pixel(
    frame: &Frame,
    accel: &Accel<'_>,
    oracle: &Oracle<'_>,
    x: u32,
    y: u32,
) -> Explanation {
    let scene = accel.scene();
    let cam = &scene.camera;
    let n = frame.samples;
    let (sw, sh) = (frame.sample_width(), frame.sample_height());
    let mut best = Explanation::Unexplained;
    for b in 0..n {
        for a in 0..n {
            let (sx, sy) = (x * n + a, y * n + b);
            let i = (sy * sw + sx) as usize;
            let id = frame.id[i];
            let (px, py) = cam.sample_point(sx, sy);
            let ray = cam.primary_ray64(px, py);
            // Before the near plane: any hit between the eye and near.
            let before = Ray64 {
                t_min: 0.0,
                t_max: ray.t_min,
                ..ray
            };
            if accel.intersect(&before).is_some() {
                return Explanation::NearPlane;
            }
            if id != BACKGROUND {
                let prim = scene.prim(id);
                let is_triangle = matches!(prim, Prim::Triangle(_));
                let material_id = match prim {
                    Prim::Triangle(t) => scene.tri_material.get(t as usize).copied(),
                    Prim::Analytic(k) => scene.analytic.get(k).map(|s| s.material),
                };
                let material = material_id.and_then(|m| scene.materials.get(usize::from(m)));
                if material.is_some_and(crate::shade::Material::spawns_rays) && scene.max_depth > 1
                {
                    best = best.min(Explanation::RayTree);
                }
                if material.is_some_and(|m| {
                    m.bump
                        .as_ref()
                        .is_some_and(|b| b.method == crate::shade::BumpMethod::Blinn)
                }) {
                    best = best.min(Explanation::BlinnBump);
                }
                // Coincident surfaces along the ray, and triangle edges
                // (an analytic shape has neither edges nor a footprint:
                // only its outline, found from the neighbours below).
                let f = is_triangle.then(|| oracle.footprint(id, px, py));
                if let Some(f) = &f
                    && let Some(t) = f.t
                {
                    // The verdict calls two surfaces tied when their
                    // depths differ by at most δ_a + δ_b (`Oracle::classify`);
                    // the other surface is not known here, so its δ is taken
                    // equal to this one's (the window is ±2·tol). The query
                    // ray is the same f64 camera ray the oracle evaluates.
                    let tol = oracle.depth_tolerance(f);
                    let mut tie = false;
                    let window = Ray64 {
                        t_min: (t - 2.0 * tol).max(0.0),
                        t_max: t + 2.0 * tol,
                        ..ray
                    };
                    accel.for_each_triangle_hit(&window, |other, _| {
                        tie = other != id;
                        tie
                    });
                    if tie {
                        best = best.min(Explanation::DepthTie);
                    }
                }
                if f.is_some_and(|f| {
                    f.edge_dist
                        <= crate::compare::Oracle::edge_tolerance(Some(&f), None)
                            .min(crate::compare::oracle::EDGE_TIE_MAX_PX)
                }) {
                    best = best.min(Explanation::Edge);
                }
            }
            // Neighbours that see another surface, or another shadow bit.
            let here = frame.flags[i];
            if here & FLAG_DISCONTINUITY != 0 {
                best = best.min(Explanation::ShadowOrGate);
            }
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (i64::from(sx) + dx, i64::from(sy) + dy);
                    if nx < 0 || ny < 0 || nx >= i64::from(sw) || ny >= i64::from(sh) {
                        continue;
                    }
                    #[expect(
                        clippy::cast_sign_loss,
                        clippy::cast_possible_truncation,
                        reason = "checked inside the u32 sample grid"
                    )]
                    let j = (ny as usize) * (sw as usize) + nx as usize;
                    // A silhouette: the neighbour sees another object or
                    // the background (inside one mesh, the exact distance
                    // test above decides).
                    let obj = |t: u32| {
                        if t == BACKGROUND {
                            None
                        } else {
                            scene.object_of(t)
                        }
                    };
                    if obj(frame.id[j]) != obj(id) {
                        best = best.min(Explanation::Edge);
                    }
                    if (frame.flags[j] ^ here) & !FLAG_DISCONTINUITY != 0 {
                        best = best.min(Explanation::ShadowOrGate);
                    }
                }
            }
        }
    }
    best
}

/// Explains every pixel of `frame` whose largest 8-bit sRGB channel
/// differs from `reference` by more than `max8`.
#[must_use]
pub fn explain(
    frame: &Frame,
    reference: &[crate::color::Rgb],
    accel: &Accel<'_>,
    oracle: &Oracle<'_>,
    max8: u8,
) -> (Explained, Vec<(u32, u32, Explanation)>) {
    use crate::color::to_srgb8;
    let mut counts = Explained::default();
    let mut list = Vec::new();
    for y in 0..frame.height {
        for x in 0..frame.width {
            let i = (y * frame.width + x) as usize;
            let (p, q) = (frame.color[i], reference[i]);
            let d = [(p.r, q.r), (p.g, q.g), (p.b, q.b)]
                .iter()
                .map(|(a, b)| to_srgb8(*a).abs_diff(to_srgb8(*b)))
                .max()
                .unwrap_or(0);
            if d <= max8 {
                continue;
            }
            counts.differing += 1;
            let e = explain_pixel(frame, accel, oracle, x, y);
            match e {
                Explanation::NearPlane => counts.near_plane += 1,
                Explanation::DepthTie => counts.depth_tie += 1,
                Explanation::Edge => counts.edge += 1,
                Explanation::ShadowOrGate => counts.shadow_or_gate += 1,
                Explanation::RayTree => counts.ray_tree += 1,
                Explanation::BlinnBump => counts.blinn_bump += 1,
                Explanation::Unexplained => counts.unexplained += 1,
            }
            list.push((x, y, e));
        }
    }
    (counts, list)
}
