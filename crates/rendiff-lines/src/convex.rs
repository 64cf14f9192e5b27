//! Which objects are convex polyhedra, as Roberts' algorithm needs them.
//!
//! An object passes when
//!
//! 1. it is **closed** (the tessellator's test: manifold and consistently
//!    oriented after welding, its counter-clockwise side out);
//! 2. **no triangle is degenerate**: its normal is longer than the
//!    rounding of its corners could make it (otherwise its facing, and so
//!    the silhouette, is undetermined);
//! 3. **every edge is convex**: the far corner of each neighbouring
//!    triangle lies on the inner side of the other's plane, within the
//!    error that rounding the corners to f32 puts into that plane there;
//! 4. its **vertex centroid lies strictly inside every triangle's plane**
//!    (by more than that error), and
//! 5. the triangles **wind once around the centroid**: their solid angles
//!    seen from it sum to 4π (each is positive by 4, so the sum is 4π
//!    times the number of times the surface wraps around).
//!
//! 4 and 5 make the surface star-shaped from the centroid (every ray from
//! it crosses one triangle), and a star-shaped polyhedral surface whose
//! edges are all convex bounds a convex body: a plane through the centroid
//! and two points of the body, moved off the vertices, cuts it in a
//! star-shaped polygon whose corners lie on edges, so all its angles are
//! convex and the polygon is convex. The test is linear in the triangles,
//! where "every vertex inside every face plane" is quadratic.
//!
//! **Tolerance.** The positions are f32: each vertex lies within
//! ρ = √3·2⁻²⁴·R of the exact point of the shape, R the largest absolute
//! coordinate in the scene (half an ulp per coordinate). The plane of a
//! triangle through three such points is off, at a point whose projection
//! on the plane has barycentric coordinates (α, β, γ), by at most
//! (|α| + |β| + |γ|)·ρ (the error is affine on the plane, at most ρ at
//! each corner), and the tested point itself by ρ. A fold within
//! ρ·(1 + |α| + |β| + |γ|) of flat is rounding, not a concavity (the flat
//! faces of boxes and of boxy superellipsoids are many coplanar triangles
//! whose rounded corners fold by that much either way). The f64
//! arithmetic of the test adds γ(8)·|d − a| (Higham), far below it.

use std::fmt;

use rendiff_core::math::{DVec3, gamma64, to_f64};
use rendiff_core::tri_scene::TriScene;

use super::EdgeEntry;

/// An object Roberts' algorithm cannot take: which, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct NotConvex {
    /// Its index in the scene's objects.
    pub object: u32,
    /// Its label, `objects[i] (kind)`.
    pub label: String,
    /// What failed.
    pub reason: String,
}

impl fmt::Display for NotConvex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} is not a convex polyhedron: {}; Roberts' method takes closed convex objects only (--method appel draws any scene)",
            self.label, self.reason
        )
    }
}

impl std::error::Error for NotConvex {}

/// The bound ρ on how far an f32 vertex lies from the exact point it
/// rounds: √3 half-ulps of the largest coordinate `r_max`.
#[must_use]
pub(crate) fn vertex_rounding(r_max: f64) -> f64 {
    3f64.sqrt() * f64::from(f32::EPSILON) * 0.5 * r_max
}

/// The largest absolute coordinate of the scene's positions.
pub(crate) fn largest_coordinate(scene: &TriScene) -> f64 {
    scene
        .positions
        .iter()
        .map(|p| f64::from(p.abs().max_element()))
        .fold(0.0, f64::max)
}

/// `|α| + |β| + |γ|` for the projection of `x` on the plane of triangle
/// `v` (non-degenerate, normal `n` = (v1 − v0) × (v2 − v0)).
pub(crate) fn bary_sum(v: [DVec3; 3], n: DVec3, x: DVec3) -> f64 {
    let nn = n.length_squared();
    let b1 = (x - v[0]).cross(v[2] - v[0]).dot(n) / nn;
    let b2 = (v[1] - v[0]).cross(x - v[0]).dot(n) / nn;
    (1.0 - b1 - b2).abs() + b1.abs() + b2.abs()
}

/// The largest error rounding puts into the signed distance of `x` from
/// the plane of triangle `v` (normal `n`, not normalised): the plane's
/// error there, the point's own, and the f64 arithmetic's.
pub(crate) fn plane_tolerance(v: [DVec3; 3], n: DVec3, x: DVec3, rho: f64) -> f64 {
    rho * (1.0 + bary_sum(v, n, x)) + gamma64(8) * (x - v[0]).length()
}

/// Whether the normal `n` of the triangle with corners `v` is longer than
/// the rounding of its corners could make it: each corner moves by ρ, so
/// the cross product of the two sides from `v0` moves by at most
/// 2ρ·(|e1| + |e2|) + 4ρ² (and the arithmetic by γ(6)·|e1||e2|).
pub(crate) fn degenerate(v: [DVec3; 3], n: DVec3, rho: f64) -> bool {
    let (e1, e2) = ((v[1] - v[0]).length(), (v[2] - v[0]).length());
    n.length() <= 2.0 * rho * (e1 + e2) + 4.0 * rho * rho + gamma64(6) * e1 * e2
}

/// Checks that object `object`, whose mesh edges (with their triangles,
/// as [`mesh_edges`](super::mesh_edges) finds them) are `edges`, is a convex
/// polyhedron (the module's five conditions) with vertex rounding `rho`.
///
/// # Errors
///
/// [`NotConvex`] with the first condition that fails.
pub(crate) fn check_convex(
    scene: &TriScene,
    object: u32,
    edges: &[EdgeEntry],
    rho: f64,
) -> Result<(), NotConvex> {
    let info = &scene.objects[object as usize];
    let fail = |reason: String| NotConvex {
        object,
        label: info.label.clone(),
        reason,
    };
    if !info.closed {
        return Err(fail(
            "it is not closed (manifold and consistently oriented after welding equal positions)"
                .to_string(),
        ));
    }
    let tri = |t: u32| scene.triangle_f64(t);
    let normal = |v: [DVec3; 3]| (v[1] - v[0]).cross(v[2] - v[0]);
    for t in info.tris.clone() {
        let v = tri(t);
        if degenerate(v, normal(v), rho) {
            return Err(fail(format!(
                "triangle {} has no area within rounding (corners {}, {}, {})",
                t - info.tris.start,
                fmt_point(v[0]),
                fmt_point(v[1]),
                fmt_point(v[2])
            )));
        }
    }
    // 3. Every edge convex: the far corner of the second triangle inside
    // the first one's plane (outward normals: the object is closed).
    let pos = |i: u32| to_f64(scene.positions[i as usize]);
    let third = |t: u32, (a, b): (u32, u32)| {
        scene.tris[t as usize]
            .into_iter()
            .find(|&x| x != a && x != b)
            .unwrap_or(a)
    };
    for &((a, b), tris, count) in edges {
        let other = tris
            .iter()
            .map(|&t| scene.tri_object.get(t as usize).copied())
            .find(|&o| o != Some(object));
        if count != 2 || other.is_some() {
            return Err(fail(format!(
                "the edge from {} to {} has {count} triangles{}",
                fmt_point(pos(a)),
                fmt_point(pos(b)),
                match other {
                    Some(Some(o)) => format!(", one of objects[{o}]"),
                    _ => String::new(),
                }
            )));
        }
        let v = tri(tris[0]);
        let n = normal(v);
        let x = pos(third(tris[1], (a, b)));
        let fold = n.dot(x - v[0]) / n.length();
        let tol = plane_tolerance(v, n, x, rho);
        if fold > tol {
            return Err(fail(format!(
                "the edge from {} to {} folds inward (the next triangle's corner {} lies {fold:.3e} outside this one's plane, beyond the rounding tolerance {tol:.1e})",
                fmt_point(pos(a)),
                fmt_point(pos(b)),
                fmt_point(x)
            )));
        }
    }
    // 4. The centroid strictly inside every plane.
    let first = info.tris.start;
    let centroid = centroid(scene, object);
    for t in info.tris.clone() {
        let v = tri(t);
        let n = normal(v);
        let side = n.dot(centroid - v[0]) / n.length();
        let tol = plane_tolerance(v, n, centroid, rho);
        if side >= -tol {
            return Err(fail(format!(
                "its vertex centroid {} is not inside the plane of triangle {} (distance {side:.3e}, tolerance {tol:.1e})",
                fmt_point(centroid),
                t - first
            )));
        }
    }
    // 5. Winding once: Van Oosterom & Strackee's solid angle of each
    // triangle from the centroid.
    let total: f64 = info
        .tris
        .clone()
        .map(|t| {
            let [a, b, c] = tri(t).map(|p| p - centroid);
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let num = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
            2.0 * num.atan2(den)
        })
        .sum();
    let turns = total / (4.0 * std::f64::consts::PI);
    if (turns - 1.0).abs() >= 0.5 {
        return Err(fail(format!(
            "its surface wraps {turns:.2} times around its vertex centroid, not once"
        )));
    }
    Ok(())
}

/// The mean of the positions object `object`'s triangles use (each once).
pub(crate) fn centroid(scene: &TriScene, object: u32) -> DVec3 {
    let verts = object_vertices(scene, object);
    #[expect(
        clippy::cast_precision_loss,
        reason = "a vertex count, exact in f64 below 2^53"
    )]
    let n = verts.len().max(1) as f64;
    verts
        .iter()
        .map(|&i| to_f64(scene.positions[i as usize]))
        .sum::<DVec3>()
        / n
}

/// The mesh edges of each object, in the order of `edges` (an edge goes to
/// the object of its first triangle).
pub(crate) fn edges_by_object(scene: &TriScene, edges: &[EdgeEntry]) -> Vec<Vec<EdgeEntry>> {
    let mut out = vec![Vec::new(); scene.objects.len()];
    for &e in edges {
        if let Some(list) = scene
            .tri_object
            .get(e.1[0] as usize)
            .and_then(|&o| out.get_mut(o as usize))
        {
            list.push(e);
        }
    }
    out
}

/// The position indices object `object`'s triangles use, sorted, once each.
pub(crate) fn object_vertices(scene: &TriScene, object: u32) -> Vec<u32> {
    let range = scene.objects[object as usize].tris.clone();
    let mut v: Vec<u32> = scene.tris[range.start as usize..range.end as usize]
        .iter()
        .flatten()
        .copied()
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

fn fmt_point(p: DVec3) -> String {
    format!("({:.4}, {:.4}, {:.4})", p.x, p.y, p.z)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rendiff_core::camera::{Camera, Projection};
    use rendiff_core::math::{Aabb, Vec3};
    use rendiff_core::tri_scene::{NO_INDEX, ObjectInfo};

    /// A camera looking down −z from (0, 0, 10): orthographic (4 units
    /// high) or perspective (40°).
    pub(crate) fn camera(ortho: bool) -> Camera {
        let projection = if ortho {
            Projection::Orthographic { view_height: 4.0 }
        } else {
            Projection::Perspective {
                tan_half_fov: 20f64.to_radians().tan(),
            }
        };
        Camera::new(
            DVec3::new(0.0, 0.0, 10.0),
            DVec3::ZERO,
            DVec3::Y,
            projection,
            400,
            400,
            1,
            0.01,
            100.0,
        )
        .unwrap()
    }

    /// The box's 8 corners and 12 triangles, counter-clockwise seen from
    /// outside.
    pub(crate) fn cuboid(min: [f32; 3], max: [f32; 3]) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let c = |i: u32| {
            Vec3::new(
                if i & 1 == 0 { min[0] } else { max[0] },
                if i & 2 == 0 { min[1] } else { max[1] },
                if i & 4 == 0 { min[2] } else { max[2] },
            )
        };
        let quads = [
            [0, 2, 3, 1], // z = min
            [4, 5, 7, 6], // z = max
            [0, 1, 5, 4], // y = min
            [2, 6, 7, 3], // y = max
            [0, 4, 6, 2], // x = min
            [1, 3, 7, 5], // x = max
        ];
        let tris = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        ((0..8).map(c).collect(), tris)
    }

    /// A scene of closed objects given as (positions, triangles), each
    /// welded already; `closed` as the tessellator would decide it.
    pub(crate) fn scene(cam: Camera, objects: &[(Vec<Vec3>, Vec<[u32; 3]>)]) -> TriScene {
        let mut s = TriScene::from_triangles(cam, &[]);
        s.objects.clear();
        for (k, (pos, tris)) in objects.iter().enumerate() {
            let base = u32::try_from(s.positions.len()).unwrap();
            let first = u32::try_from(s.tris.len()).unwrap();
            s.positions.extend_from_slice(pos);
            for t in tris {
                s.tris.push(t.map(|i| i + base));
                s.tri_normals.push([NO_INDEX; 3]);
                s.tri_uvs.push([NO_INDEX; 3]);
                s.tri_material.push(0);
                s.tri_object.push(u32::try_from(k).unwrap());
            }
            let last = u32::try_from(s.tris.len()).unwrap();
            let closed = {
                // Every directed edge's reverse present, none twice.
                let mut set = std::collections::HashSet::new();
                tris.iter()
                    .all(|t| (0..3).all(|i| set.insert((t[i], t[(i + 1) % 3]))))
                    && tris
                        .iter()
                        .all(|t| (0..3).all(|i| set.contains(&(t[(i + 1) % 3], t[i]))))
            };
            s.objects.push(ObjectInfo {
                label: format!("objects[{k}] (test)"),
                kind: "mesh",
                tris: first..last,
                bounds: Aabb::from_points(pos.iter().copied()),
                closed,
                no_shadow: false,
                material: 0,
                smooth: false,
                segments: None,
            });
        }
        s
    }

    fn check(s: &TriScene) -> Result<(), NotConvex> {
        let rho = vertex_rounding(largest_coordinate(s));
        let edges = edges_by_object(s, &super::super::mesh_edges(s));
        (0..u32::try_from(s.objects.len()).unwrap())
            .try_for_each(|o| check_convex(s, o, &edges[o as usize], rho))
    }

    #[test]
    fn a_box_is_convex_and_a_dented_one_is_not() {
        let cube = cuboid([-1.0; 3], [1.0; 3]);
        assert_eq!(
            check(&scene(camera(false), std::slice::from_ref(&cube))),
            Ok(())
        );
        // Corner 7 (the +x +y +z one) pushed toward the centre: the three
        // faces around it fold inward at their diagonals.
        let mut dented = cube.clone();
        dented.0[7] = Vec3::splat(0.5);
        let err = check(&scene(camera(false), &[cube.clone(), dented])).unwrap_err();
        assert_eq!(err.object, 1);
        assert!(err.reason.contains("folds inward"), "{err}");
        assert!(
            err.to_string()
                .starts_with("objects[1] (test) is not a convex polyhedron")
        );
    }

    #[test]
    fn an_open_box_is_refused_as_not_closed() {
        let (pos, mut tris) = cuboid([-1.0; 3], [1.0; 3]);
        tris.truncate(10);
        let err = check(&scene(camera(false), &[(pos, tris)])).unwrap_err();
        assert!(err.reason.contains("not closed"), "{err}");
    }

    /// The tolerance is the rounding of the corners and no more: a face
    /// folded inward by a tenth of ρ passes, by ten times ρ it does not.
    #[test]
    fn the_fold_tolerance_is_the_rounding_of_the_corners() {
        let (pos, tris) = cuboid([-1.0; 3], [1.0; 3]);
        let rho = vertex_rounding(1.0);
        for (dent, ok) in [(0.0, true), (0.1 * rho, true), (10.0 * rho, false)] {
            // Corner 7 moved inward along z, normal to the z = max face:
            // that face folds at its diagonal 4–7 by about `dent`.
            let mut p = pos.clone();
            #[expect(clippy::cast_possible_truncation, reason = "a test offset")]
            let z = (1.0 - dent) as f32;
            p[7].z = z;
            let moved = f64::from(z);
            let got = check(&scene(camera(false), &[(p, tris.clone())]));
            assert_eq!(
                got.is_ok(),
                ok || moved == 1.0,
                "dent {dent:e} (z = {moved}): {got:?}"
            );
        }
    }

    #[test]
    fn a_flat_triangle_is_refused() {
        // A tetrahedron with a fourth corner on the plane of the other
        // three is flat: its triangles have area but the centroid lies in
        // every plane.
        let pos = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ];
        let tris = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        assert_eq!(
            check(&scene(camera(true), &[(pos.clone(), tris.clone())])),
            Ok(())
        );
        let mut flat = pos;
        flat[3] = Vec3::new(0.5, 0.5, 0.0);
        let err = check(&scene(camera(true), &[(flat, tris)])).unwrap_err();
        assert!(
            err.reason.contains("no area") || err.reason.contains("centroid"),
            "{err}"
        );
    }
}
