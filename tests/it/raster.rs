//! The rasterizer: exact coverage (every sample of a partition exactly
//! once, a Khronos-style FULL/NONE/PARTIAL oracle), bounded drift of the
//! incremental interpolation, depth formats, near-plane clipping.

use rendiff::camera::{Camera, Projection};
use rendiff::compare::{Class, compare_frames, derive_tolerances};
use rendiff::coverage::SNAP_BOUND_PX;
use rendiff::frame::BACKGROUND;
use rendiff::math::{DVec3, Vec3, to_f32, to_f64};
use rendiff::options::DepthFormat;
use rendiff::raster::{self, DEPTH_DRIFT_REL, Perturb, RasterOptions};
use rendiff::tri_scene::TriScene;

use crate::util::Rng;

fn camera(w: u32, h: u32, n: u32, near: f64) -> Camera {
    Camera::new(
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::Y,
        Projection::Perspective { tan_half_fov: 0.5 },
        w,
        h,
        n,
        near,
        1000.0,
    )
    .unwrap()
}

fn options(scene: &TriScene, depth: DepthFormat) -> RasterOptions {
    RasterOptions {
        depth,
        shadows: rendiff::options::ShadowMode::Rays,
        shadows_needed: false,
        gate_eps: 1e-4,
        frustum_cull: vec![false; scene.objects.len()],
        backface_cull: vec![false; scene.objects.len()],
        perturb: Perturb::default(),
    }
}

/// Signed distance (pixels) from a screen point to the boundary of a
/// convex polygon (positive inside).
fn inside_distance(poly: &[(f64, f64)], p: (f64, f64)) -> f64 {
    let n = poly.len();
    let area: f64 = (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum();
    let s = area.signum();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let len = (dx * dx + dy * dy).sqrt().max(1e-300);
            s * (dx * (p.1 - a.1) - dy * (p.0 - a.0)) / len
        })
        .fold(f64::INFINITY, f64::min)
}

/// A planar partition of a convex quadrilateral on a random plane: a grid
/// of jittered cells split into triangles, a fan around an inner point, or
/// a strip, with sub-pixel, needle and zero-area triangles among them.
fn partition(rng: &mut Rng, corners: [DVec3; 4]) -> Vec<[DVec3; 3]> {
    let lerp = |a: DVec3, b: DVec3, t: f64| a + (b - a) * t;
    let at = |u: f64, v: f64| {
        lerp(
            lerp(corners[0], corners[1], u),
            lerp(corners[3], corners[2], u),
            v,
        )
    };
    match rng.below(3) {
        0 => {
            // Grid: interior vertices jittered, boundary vertices kept on the edges.
            let (nu, nv) = (1 + rng.below(6) as usize, 1 + rng.below(6) as usize);
            let mut p = vec![vec![DVec3::ZERO; nv + 1]; nu + 1];
            for (i, row) in p.iter_mut().enumerate() {
                for (j, q) in row.iter_mut().enumerate() {
                    let mut u = i as f64 / nu as f64;
                    let mut v = j as f64 / nv as f64;
                    // ±0.2 of a cell keeps every cell convex (a corner
                    // must move 0.707 cells to cross the opposite diagonal),
                    // so either diagonal splits it into a partition.
                    if i > 0 && i < nu {
                        u += rng.range(-0.2, 0.2) / nu as f64;
                    }
                    if j > 0 && j < nv {
                        v += rng.range(-0.2, 0.2) / nv as f64;
                    }
                    *q = at(u, v);
                }
            }
            let mut t = Vec::new();
            for i in 0..nu {
                for j in 0..nv {
                    let (a, b, c, d) = (p[i][j], p[i + 1][j], p[i + 1][j + 1], p[i][j + 1]);
                    if rng.below(2) == 0 {
                        t.push([a, b, c]);
                        t.push([a, c, d]);
                    } else {
                        t.push([a, b, d]);
                        t.push([b, c, d]);
                    }
                }
            }
            t
        }
        1 => {
            // Fan around an inner point (sometimes on a boundary vertex: needles).
            let center = at(rng.range(0.05, 0.95), rng.range(0.05, 0.95));
            let mut ring = Vec::new();
            for k in 0..4 {
                let (a, b) = (corners[k], corners[(k + 1) % 4]);
                let m = 1 + rng.below(4) as usize;
                for s in 0..m {
                    ring.push(lerp(a, b, s as f64 / m as f64));
                }
            }
            (0..ring.len())
                .map(|k| [center, ring[k], ring[(k + 1) % ring.len()]])
                .collect()
        }
        _ => {
            // A strip across the quad with uneven spacing (some columns
            // repeated: zero-area triangles).
            let m = 2 + rng.below(8) as usize;
            let mut us: Vec<f64> = (0..=m).map(|i| i as f64 / m as f64).collect();
            for u in us.iter_mut().take(m).skip(1) {
                *u += rng.range(-0.4, 0.4) / m as f64;
            }
            if m > 3 {
                let k = 1 + rng.below((m - 2) as u64) as usize;
                us[k + 1] = us[k];
            }
            let mut t = Vec::new();
            for i in 0..m {
                let (a, b, c, d) = (
                    at(us[i], 0.0),
                    at(us[i + 1], 0.0),
                    at(us[i + 1], 1.0),
                    at(us[i], 1.0),
                );
                t.push([a, b, c]);
                t.push([a, c, d]);
            }
            t
        }
    }
}

/// Every sample of a planar partition is covered exactly once: counted
/// with the sign of each triangle's snapped orientation relative to the
/// partition's side, the coverage is 1 deeper than 1 px inside the
/// (near-clipped) outline, 0 outside, and never anything else. (A sliver
/// whose projected area is below the snapping resolution can flip its
/// orientation when snapped; it then covers its samples twice, once with
/// each sign, and the signed count stays exact — back-face culling is what
/// removes it from a real frame. Such double hits are counted, and they
/// occur only in cases with a flipped sliver.) Partitions of random
/// planes, some of which pass behind the eye and are clipped; random
/// samples per pixel; triangles from sub-pixel to far larger than the image.
#[test]
fn partitions_cover_every_sample_exactly_once() {
    let mut rng = Rng(2024);
    let mut triangles = 0usize;
    let mut cases = 0usize;
    let (mut double_hits, mut flipped_slivers) = (0usize, 0usize);
    while triangles < 100_000 {
        cases += 1;
        let n = [1, 2, 4, 16][rng.below(4) as usize];
        let (w, h) = (8 + rng.below(17) as u32, 8 + rng.below(17) as u32);
        let near = 0.05;
        let cam = camera(w, h, n, near);
        // A random plane; sizes from a hundredth of a pixel to 100× the view.
        let size = 10f64.powf(rng.range(-3.5, 1.5));
        let depth = rng.range(0.5, 6.0);
        let behind = rng.below(4) == 0;
        let c = DVec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), -depth)
            * if behind { 0.1 } else { 1.0 };
        let e1 = DVec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        )
        .normalize()
            * size;
        let e2 = DVec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        )
        .normalize()
            * size;
        let mut corners = [c - e1 - e2, c + e1 - e2, c + e1 + e2, c - e1 + e2];
        let px = size * f64::from(h) / (2.0 * 0.5 * depth);
        if rng.below(3) == 0 && px > 20.0 && !behind {
            // Corners exactly on pixel centres (the quad is large enough to
            // stay convex when they move there).
            // Each corner moves along its plane to where the ray through
            // the nearest pixel centre meets the plane: still coplanar.
            // Only when every corner is in front of the eye and the moved
            // quad stays convex (otherwise it is no partition any more).
            let normal = e1.cross(e2);
            let mut moved = corners;
            for q in &mut moved {
                if let Some((x, y, _)) = cam.project(*q) {
                    let (o, d) = cam.primary_ray_f64(x.floor() + 0.5, y.floor() + 0.5);
                    let t = (c - o).dot(normal) / d.dot(normal);
                    if t > 0.0 && t.is_finite() {
                        *q = o + d * t;
                    }
                }
            }
            let convex = (0..4).all(|k| {
                let (a, b, cc) = (moved[k], moved[(k + 1) % 4], moved[(k + 2) % 4]);
                (b - a).cross(cc - b).dot(normal) > 0.0
            });
            if convex && corners.iter().all(|q| cam.view_depth(*q) > near) {
                corners = moved;
            }
        }
        let tris = partition(&mut rng, corners);
        let tris32: Vec<[Vec3; 3]> = tris.iter().map(|t| t.map(to_f32)).collect();
        triangles += tris32.len();
        let scene = TriScene::from_triangles(cam, &tris32);
        let (sw, sh) = (cam.sample_width(), cam.sample_height());
        // The partition's side: its plane normal against the view of its centre.
        let facing = e1.cross(e2).dot(c - cam.eye()) < 0.0;
        let mut count = vec![0i32; (sw * sh) as usize];
        let mut unsigned = vec![0u32; (sw * sh) as usize];
        let mut flipped = 0usize;
        let mut flipped_tris = std::collections::HashSet::new();
        raster::cover(&scene, false, |tri, sx, sy, front| {
            let i = (sy * sw + sx) as usize;
            let agrees = front == facing;
            count[i] += if agrees { 1 } else { -1 };
            unsigned[i] += 1;
            if !agrees && flipped_tris.insert(tri) {
                flipped += 1;
            }
        });
        let doubles = unsigned.iter().filter(|&&u| u > 1).count();
        assert!(
            doubles == 0 || flipped > 0,
            "case {cases}: {doubles} double hits without a flipped sliver"
        );
        double_hits += doubles;
        flipped_slivers += flipped;
        // The outline clipped at z = near, projected (f32-rounded corners).
        let outline: Vec<DVec3> = corners.iter().map(|c| to_f64(to_f32(*c))).collect();
        let mut clipped = Vec::new();
        for i in 0..4 {
            let (a, b) = (outline[i], outline[(i + 1) % 4]);
            let (za, zb) = (cam.view_depth(a), cam.view_depth(b));
            if za >= near {
                clipped.push(a);
            }
            if (za >= near) != (zb >= near) {
                clipped.push(a + (b - a) * ((near - za) / (zb - za)));
            }
        }
        let screen: Vec<(f64, f64)> = clipped
            .iter()
            .filter_map(|p| cam.project(*p).map(|(x, y, _)| (x, y)))
            .collect();
        for sy in 0..sh {
            for sx in 0..sw {
                let c = count[(sy * sw + sx) as usize];
                assert!(
                    c == 0 || c == 1,
                    "case {cases}: sample ({sx}, {sy}) signed coverage {c}"
                );
                if screen.len() >= 3 && screen.len() == clipped.len() {
                    let d = inside_distance(&screen, cam.sample_point(sx, sy));
                    if d > 1.0 {
                        assert_eq!(
                            c, 1,
                            "case {cases}: sample ({sx}, {sy}) inside the partition ({d:.2} px) is missed"
                        );
                    } else if d < -1.0 {
                        assert_eq!(
                            c, 0,
                            "case {cases}: sample ({sx}, {sy}) outside the partition is covered"
                        );
                    }
                }
            }
        }
    }
    assert!(cases > 1000);
    eprintln!(
        "{cases} partitions, {triangles} triangles: {flipped_slivers} slivers flipped by snapping, {double_hits} samples hit twice by them"
    );
}

/// Closed meshes (tessellated spheres and boxes, seen from random
/// cameras, partly behind the eye): front faces minus back faces cover
/// every sample exactly zero times (each ray enters as often as it leaves),
/// and convex ones get every sample inside their silhouette from exactly
/// one front face.
#[test]
fn closed_meshes_have_zero_signed_coverage() {
    let mut rng = Rng(77);
    for case in 0..300 {
        let segs = 3 + rng.below(30) as u32;
        let text = format!(
            r#"
[image]
width = {}
height = {}
samples = {}
[camera]
eye = [{}, {}, {}]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = {}
near = {}
[materials.m]
[[objects]]
kind = "{}"
material = "m"
{}
"#,
            16 + rng.below(16),
            16 + rng.below(16),
            [1, 2, 4][rng.below(3) as usize],
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
            rng.range(0.5, 3.0),
            rng.range(20.0, 120.0),
            rng.range(0.01, 0.6),
            if case % 2 == 0 { "sphere" } else { "box" },
            if case % 2 == 0 {
                format!(
                    "center = [0.0, 0.0, 0.0]\nradius = {}\ntessellation = {segs}",
                    rng.range(0.3, 1.5)
                )
            } else {
                format!(
                    "min = [{}, -0.8, -0.6]\nmax = [0.7, {}, 0.9]",
                    rng.range(-1.5, -0.2),
                    rng.range(0.1, 1.2)
                )
            }
        );
        let Ok(scene) = rendiff::scene::Scene::from_str(&crate::util::scene_path("inline"), &text)
        else {
            continue;
        };
        let Ok(job) = rendiff::Prepared::from_scene(scene, &rendiff::Overrides::default()) else {
            continue;
        };
        let t = &job.tri;
        let cam = &t.camera;
        let (sw, sh) = (cam.sample_width(), cam.sample_height());
        let mut signed = vec![0i32; (sw * sh) as usize];
        let mut front = vec![0i32; (sw * sh) as usize];
        raster::cover(t, false, |_, sx, sy, is_front| {
            let i = (sy * sw + sx) as usize;
            signed[i] += if is_front { 1 } else { -1 };
            front[i] += i32::from(is_front);
        });
        let eye_inside = t.objects[0]
            .bounds
            .contains(rendiff::math::to_f32(cam.eye()));
        for i in 0..signed.len() {
            // The near plane cuts the mesh open when it passes through it;
            // then entries and exits need not balance. Check where it does not.
            if !eye_inside && !near_cuts(t) {
                assert_eq!(
                    signed[i], 0,
                    "case {case}: sample {i} signed coverage {}",
                    signed[i]
                );
                assert!(
                    front[i] <= 1,
                    "case {case}: sample {i} front coverage {}",
                    front[i]
                );
            }
        }
    }
}

/// `true` when some triangle has a vertex nearer than `near`.
fn near_cuts(t: &TriScene) -> bool {
    let cam = &t.camera;
    t.positions
        .iter()
        .any(|p| cam.view_depth(to_f64(*p)) < cam.near())
}

/// The coverage oracle of the Khronos conformance tests, per triangle and
/// sample: FULL (inside the unsnapped triangle, farther than the snapping
/// bound from every edge), NONE (outside, as far), PARTIAL otherwise. The
/// rasterizer never covers a NONE sample and never misses a FULL one.
#[test]
fn coverage_matches_the_full_none_partial_oracle() {
    let mut rng = Rng(31337);
    let (mut full, mut none, mut partial) = (0u64, 0u64, 0u64);
    for case in 0..20_000 {
        let n = [1, 2, 4, 8, 16][rng.below(5) as usize];
        let cam = camera(16, 16, n, 0.01);
        let depth = rng.range(1.0, 10.0);
        let size = 10f64.powf(rng.range(-2.5, 0.5)) * depth;
        let c = DVec3::new(
            rng.range(-0.6, 0.6) * depth,
            rng.range(-0.6, 0.6) * depth,
            -depth,
        );
        let tri: [DVec3; 3] = std::array::from_fn(|_| {
            to_f64(to_f32(
                c + DVec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-0.3, 0.3),
                ) * size,
            ))
        });
        if tri.iter().any(|p| cam.view_depth(*p) < 0.01) {
            continue;
        }
        let scene = TriScene::from_triangles(cam, &[tri.map(to_f32)]);
        let (sw, sh) = (cam.sample_width(), cam.sample_height());
        let mut covered = vec![false; (sw * sh) as usize];
        raster::cover(&scene, false, |_, sx, sy, _| {
            covered[(sy * sw + sx) as usize] = true
        });
        let screen: Vec<(f64, f64)> = tri
            .iter()
            .map(|p| {
                let (x, y, _) = cam.project(*p).unwrap();
                (x, y)
            })
            .collect();
        for sy in 0..sh {
            for sx in 0..sw {
                let d = inside_distance(&screen, cam.sample_point(sx, sy));
                let got = covered[(sy * sw + sx) as usize];
                if d > SNAP_BOUND_PX {
                    full += 1;
                    assert!(
                        got,
                        "case {case}: FULL sample ({sx}, {sy}) missed ({d:e} px inside)"
                    );
                } else if d < -SNAP_BOUND_PX {
                    none += 1;
                    assert!(
                        !got,
                        "case {case}: NONE sample ({sx}, {sy}) covered ({d:e} px outside)"
                    );
                } else {
                    partial += 1;
                }
            }
        }
    }
    assert!(
        full > 100_000 && none > 1_000_000 && partial > 0,
        "full {full}, none {none}, partial {partial}"
    );
}

/// Incremental depth and barycentrics stay within the derived bound of
/// direct evaluation on spans of 16384 pixels and edges of 16384 rows.
#[test]
fn drift_is_bounded_on_the_longest_spans_and_edges() {
    for (w, h) in [(16384u32, 2u32), (2, 16384)] {
        let cam = Camera::new(
            DVec3::ZERO,
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::Y,
            Projection::Perspective { tan_half_fov: 1.0 },
            w,
            h,
            1,
            0.01,
            1000.0,
        )
        .unwrap();
        // Triangles across the whole image, receding from 0.05 to 500
        // (strong perspective: 1/z changes 10⁴-fold along a span).
        let at = |x: f64, y: f64, depth: f64| {
            let (o, d) = cam.primary_ray_f64(x, y);
            to_f32(o + d * (depth / d.dot(cam.forward())))
        };
        let (fw, fh) = (f64::from(w), f64::from(h));
        let tri = [
            at(-0.3 * fw, -0.3 * fh, 0.05),
            at(1.3 * fw, 0.5 * fh, 500.0),
            at(0.2 * fw, 1.4 * fh, 200.0),
        ];
        let tri2 = [
            at(1.2 * fw, -0.2 * fh, 3.0),
            at(-0.4 * fw, 1.2 * fh, 0.02),
            at(1.3 * fw, 1.3 * fh, 50.0),
        ];
        let scene = TriScene::from_triangles(cam, &[tri, tri2]);
        let d = raster::measure_drift(&scene);
        assert!(d.samples > 10_000, "{w}x{h}: only {} samples", d.samples);
        assert!(
            f64::from(d.longest_span) >= 0.5 * f64::from(w.max(2)) || h > w,
            "{w}x{h}: longest span {}",
            d.longest_span
        );
        assert!(
            d.depth_rel <= DEPTH_DRIFT_REL,
            "{w}x{h}: depth drift {:e} > {:e}",
            d.depth_rel,
            DEPTH_DRIFT_REL
        );
        // b = λ_i/Σλ: two values each within DEPTH_DRIFT_REL relative.
        assert!(
            d.bary_abs <= 2.0 * DEPTH_DRIFT_REL,
            "{w}x{h}: barycentric drift {:e}",
            d.bary_abs
        );
        eprintln!(
            "{w}x{h}: {} samples, longest span {}, depth drift {:e}, barycentric drift {:e}",
            d.samples, d.longest_span, d.depth_rel, d.bary_abs
        );
    }
}

/// Resolution of a depth format (in view depth) at view depth z.
fn resolution(format: DepthFormat, z: f64, near: f64, far: f64) -> f64 {
    match format {
        DepthFormat::F32 => z * f64::from(f32::EPSILON),
        DepthFormat::U24 | DepthFormat::U16 => {
            let bits = format.bits().unwrap();
            z * z * (1.0 / near - 1.0 / far) / f64::from((1u32 << bits) - 1)
        }
    }
}

/// Two parallel planes δ apart: above the format's resolution at their
/// depth the front one wins every sample; far below it they fight, as the
/// theory says they must (16-bit especially).
#[test]
fn depth_formats_resolve_what_their_resolution_allows() {
    let (near, far) = (0.1, 100.0);
    for format in [DepthFormat::F32, DepthFormat::U24, DepthFormat::U16] {
        for z in [2.0f64, 20.0] {
            let r = resolution(format, z, near, far);
            for (factor, must_resolve) in [(4.0, true), (1.0 / 64.0, false)] {
                let delta = r * factor;
                let cam = Camera::new(
                    DVec3::ZERO,
                    DVec3::new(0.0, 0.0, -1.0),
                    DVec3::Y,
                    Projection::Perspective { tan_half_fov: 0.5 },
                    64,
                    64,
                    1,
                    near,
                    far,
                )
                .unwrap();
                let quad = |zz: f64| {
                    let s = zz; // covers the view
                    let p = |x: f64, y: f64| to_f32(DVec3::new(x * s, y * s, -zz));
                    [
                        [p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0)],
                        [p(-1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)],
                    ]
                };
                // The back plane gets the lower ids: on equal depth it wins,
                // so every sample the format cannot separate counts as a failure.
                let back = quad(z + delta);
                let front = quad(z);
                let scene = TriScene::from_triangles(cam, &[back[0], back[1], front[0], front[1]]);
                let vis = raster::visibility(&scene, &options(&scene, format));
                let fails = vis
                    .id
                    .iter()
                    .filter(|&&id| id < 2 || id == BACKGROUND)
                    .count();
                let rate = fails as f64 / vis.id.len() as f64;
                eprintln!(
                    "{format} z {z}: δ = {factor} × resolution ({delta:.3e}): {:.1} % wrong",
                    rate * 100.0
                );
                if must_resolve {
                    assert_eq!(
                        fails, 0,
                        "{format} at z {z}: δ = 4× resolution must resolve"
                    );
                } else if format == DepthFormat::U16 {
                    assert!(
                        rate > 0.5,
                        "{format} at z {z}: δ = resolution/64 must fight, {rate}"
                    );
                }
            }
        }
    }
}

/// A triangle through the eye plane renders exactly its part in front of
/// the near plane: the rasterizer's ids equal the ray tracer's except at
/// classified ties.
#[test]
fn triangles_through_the_near_plane_agree_with_the_ray_tracer() {
    let mut rng = Rng(4);
    for case in 0..40 {
        let cam = camera(48, 40, 1 + (case % 2) * 3, rng.range(0.05, 1.0));
        let tris: Vec<[Vec3; 3]> = (0..6)
            .map(|_| {
                std::array::from_fn(|_| {
                    to_f32(DVec3::new(
                        rng.range(-3.0, 3.0),
                        rng.range(-3.0, 3.0),
                        rng.range(-6.0, 2.0),
                    ))
                })
            })
            .collect();
        let scene = TriScene::from_triangles(cam, &tris);
        assert!(near_cuts(&scene) || case > 0);
        let opts = options(&scene, DepthFormat::F32);
        let (fr, _) = raster::render(&scene, &opts);
        let accel = rendiff::accel::Accel::new(&scene, rendiff::accel::AccelOptions::default());
        let fy = rendiff::ray::render(
            &accel,
            &rendiff::ray::RayOptions {
                max_depth: 1,
                shadows: false,
                gate_eps: 1e-4,
            },
        );
        let tol = derive_tolerances(&scene);
        let c = compare_frames(&scene, &fr, &fy, &tol, DepthFormat::F32);
        let v = c.visibility.unwrap();
        assert_eq!(v.real, 0, "case {case}: {v:?}");
        assert!(c.classes.iter().filter(|&&k| k == Class::Agree).count() > 0);
    }
}

/// Shadow maps are the rasterizer's own answer to shadows; their error
/// against shadow rays is measured here (not bounded): the fraction of
/// visible samples whose shadow decision differs, per resolution. It must
/// shrink as the resolution grows and stay small at 4096.
#[test]
fn shadow_map_error_against_shadow_rays_is_measured() {
    use rendiff::options::ShadowMode;
    let mut report = String::new();
    for name in ["spheres", "teapot", "bunny"] {
        let job = crate::util::load(name, &rendiff::Overrides::default());
        let rays = raster::render(&job.tri, &job.raster_options()).0;
        let mut last = f64::INFINITY;
        for res in [256u32, 1024, 4096] {
            let mut opts = job.raster_options();
            opts.shadows = ShadowMode::Map(res);
            let map = raster::render(&job.tri, &opts).0;
            let visible = rays.id.iter().filter(|&&i| i != BACKGROUND).count();
            let differ = rays
                .id
                .iter()
                .zip(&rays.flags)
                .zip(&map.flags)
                .filter(|((id, a), b)| **id != BACKGROUND && (**a ^ **b) & !1 != 0)
                .count();
            let rate = differ as f64 / visible as f64;
            report.push_str(&format!(
                "{name} map:{res}: {:.3} % of visible samples shadowed differently\n",
                rate * 100.0
            ));
            assert!(
                rate <= last * 1.5 + 1e-4,
                "{name}: the error grew from {last} to {rate} at {res}"
            );
            last = rate;
        }
        assert!(
            last < 0.02,
            "{name}: {:.2} % still differ at 4096",
            last * 100.0
        );
    }
    eprint!("{report}");
}

/// Frames drawn into reused memory (`raster::render_into` and
/// `ray::render_into`, holding the buffers and the frame of the scenes
/// rendered before: larger and smaller, wider and narrower, with and
/// without multisampling) are the fresh renders bit for bit, stats
/// included: nothing of an earlier frame survives into a later one.
#[test]
fn frames_in_reused_memory_are_the_fresh_frames() {
    use rendiff::accel::{Accel, AccelOptions};
    use rendiff::color::Rgb;
    use rendiff::frame::Frame;
    // Every field as bits, each led by its length.
    fn bits(f: &Frame) -> Vec<u32> {
        let rgb = |v: &[Rgb]| -> Vec<u32> {
            v.iter()
                .flat_map(|c| [c.r, c.g, c.b])
                .map(f32::to_bits)
                .collect()
        };
        let depth: Vec<u32> = f.depth.iter().map(|d| d.to_bits()).collect();
        let mut out = vec![f.width, f.height, f.samples];
        for part in [
            rgb(&f.color),
            rgb(&f.sample_color),
            depth,
            f.id.to_vec(),
            f.flags.to_vec(),
        ] {
            out.push(u32::try_from(part.len()).unwrap());
            out.extend(part);
        }
        out
    }
    let mut buffers = raster::RasterBuffers::default();
    let mut frame = Frame::new(0, 0, 1, Rgb::BLACK);
    let mut ray_frame = Frame::new(0, 0, 1, Rgb::BLACK);
    // 320×240 at 2×2 samples, then 160×120 at one, then 400×300 (wider
    // and taller) at one, then 320×240 at 2×2 again; the backgrounds differ.
    for (name, size) in [
        ("dense", None),
        ("polygons", Some((160, 120))),
        ("spheres", Some((400, 300))),
        ("dense", None),
    ] {
        let ov = rendiff::Overrides {
            size,
            ..rendiff::Overrides::default()
        };
        let job = crate::util::load(name, &ov);
        let opts = job.raster_options();
        let (fresh, fresh_stats) = raster::render(&job.tri, &opts);
        let stats = raster::render_into(&job.tri, &opts, &mut buffers, &mut frame);
        assert_eq!(stats, fresh_stats, "{name}: raster stats");
        assert!(
            bits(&frame) == bits(&fresh),
            "{name}: the raster frame differs"
        );
        let accel = Accel::new(&job.tri, AccelOptions::default());
        let ray_opts = rendiff::ray::RayOptions {
            max_depth: job.settings.max_depth,
            shadows: true,
            gate_eps: rendiff::GATE_EPS,
        };
        let (fresh, fresh_stats) = rendiff::ray::render_counted(&accel, &ray_opts);
        let stats = rendiff::ray::render_into(&accel, &ray_opts, &mut ray_frame);
        assert_eq!(stats, fresh_stats, "{name}: ray stats");
        assert!(
            bits(&ray_frame) == bits(&fresh),
            "{name}: the ray frame differs"
        );
    }
}

/// The shading inputs a row of samples takes with the triangle's own part
/// kept from one sample to the next (`view_surface_after`, as the
/// rasterizer's shading pass and the ray tracer call it) are those of
/// `view_surface` bit for bit, on every bundled scene's triangles (smooth
/// normals, uvs, bump maps, degenerate slivers): runs of one triangle,
/// switches, and returns to an earlier one, each at drawn rays.
#[test]
fn kept_triangle_parts_give_the_same_shading_inputs() {
    let mut rng = Rng(0x5eed_7a1e);
    for name in crate::util::bundled_scenes() {
        let job = crate::util::load(&name, &rendiff::Overrides::default());
        let tri = &job.tri;
        let n = u32::try_from(tri.len()).unwrap();
        let mut last = None;
        let mut prev = 0;
        for k in 0..3000u32 {
            // Runs of one triangle, a neighbour, a jump, and back.
            let id = match k % 7 {
                0 => rng.below(u64::from(n)) as u32,
                1 => prev,
                2 => (prev + 1) % n,
                _ => prev,
            };
            prev = id;
            let v = tri.triangle(id);
            let c = to_f64((v[0] + v[1] + v[2]) / 3.0);
            let o = c + DVec3::new(
                rng.range(-3.0, 3.0),
                rng.range(0.5, 3.0),
                rng.range(-3.0, 3.0),
            );
            let target = c + DVec3::new(
                rng.range(-0.1, 0.1),
                rng.range(-0.1, 0.1),
                rng.range(-0.1, 0.1),
            );
            let d = (target - o).normalize();
            let (a, pa) = tri.view_surface_after(&mut last, id, o, d);
            let (b, pb) = tri.view_surface(id, o, d);
            assert_eq!(
                format!("{a:?} {pa:?}"),
                format!("{b:?} {pb:?}"),
                "{name}: triangle {id}"
            );
        }
    }
}
