//! The hazard scenes of `tests/data/hazards` (a grazing eye over a huge
//! floor, a tiny field of view at distance, a huge wall with a light
//! behind it, a light in a wall's plane, crossing quads far from the
//! origin with an off-grid eye, `far` nearer than the objects, bright
//! supersampled highlights, POV-Ray's superel1 grid) and the ray-family
//! property test behind them.
//!
//! On every hazard scene: raster against ray has 0 real and 0 unjudgeable
//! samples, every tolerance within its limit, and both backends match the
//! stored POV-Ray reference (`tests/data/hazards/golden`) within 2/255 on
//! ≥ 99.9 % of the pixels with every pixel beyond explained.

use rayon::prelude::*;
use rendiff::accel::{Accel, AccelOptions};
use rendiff::diff::{self, Side};
use rendiff::math::{DVec3, Ray64, Vec3, to_f32, to_f64};
use rendiff::options::Geometry;
use rendiff::pov::golden;
use rendiff::tri_scene::TriScene;
use rendiff::{Backend, Overrides, Prepared};

use crate::util::{Rng, root};

/// The hazard scenes, sorted.
pub fn hazard_scenes() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(root().join("tests/data/hazards"))
        .expect("tests/data/hazards exists")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn hazard_path(name: &str) -> std::path::PathBuf {
    root()
        .join("tests/data/hazards")
        .join(format!("{name}.toml"))
}

fn golden_dir() -> std::path::PathBuf {
    root().join("tests/data/hazards/golden")
}

/// The geometry a scene is compared with POV-Ray in (superel1 is about
/// the analytic shapes).
fn geometry(name: &str) -> Geometry {
    if name == "superel1" {
        Geometry::Analytic
    } else {
        Geometry::Mesh
    }
}

#[test]
fn every_hazard_scene_has_no_real_and_no_unjudgeable_sample() {
    let scenes = hazard_scenes();
    assert!(scenes.len() >= 8, "{scenes:?}");
    let mut text = String::new();
    for name in &scenes {
        let job = Prepared::load(&hazard_path(name), &Overrides::default()).unwrap();
        let r = diff::diff(
            &job,
            name,
            &Side::Backend(Backend::Raster),
            &Side::Backend(Backend::Ray),
        )
        .unwrap();
        let v = r.report.visibility.expect("two frames");
        assert_eq!(
            (v.real, v.unjudgeable),
            (0, 0),
            "{name}: real or unjudgeable samples\n{}",
            r.report.summary()
        );
        assert!(r.report.passed(), "{name}\n{}", r.report.summary());
        let t = &r.report.tolerance;
        let edge = t.edge_px.expect("frames have judged tolerances");
        assert!(
            edge.is_finite() && edge <= t.limits.edge_px,
            "{name}: {t:?}"
        );
        assert!(t.depth_rel.unwrap().is_finite() && t.near_eps.unwrap().is_finite());
        crate::differential::assert_no_false_pass(name, &r);
        text.push_str(&format!(
            "{name}: {} agree, {} edge, {} depth, {} near, {} unjudgeable, {} real; edge ≤ {:.4} px (p99 {:.4}), depth ≤ {} of t\n",
            v.agree,
            v.edge_tie,
            v.depth_tie,
            v.near_tie,
            v.unjudgeable,
            v.real,
            edge,
            t.edge_px_p99.unwrap(),
            rendiff::compare::report::decade(t.depth_rel.unwrap()),
        ));
    }
    insta::assert_snapshot!("hazard_scenes_raster_vs_ray", text);
}

#[test]
fn hazard_references_exist_and_are_not_stale() {
    let mut problems = Vec::new();
    for name in hazard_scenes() {
        let job = Prepared::load(&hazard_path(&name), &Overrides::default()).unwrap();
        problems.extend(golden::stale(&job.scene, &job.tri, &golden_dir()).unwrap());
    }
    assert!(
        problems.is_empty(),
        "stale or missing POV-Ray references (rendiff golden tests/data/hazards/*.toml --golden tests/data/hazards/golden --update):\n{}",
        problems.join("\n")
    );
}

/// Both backends against POV-Ray's render of the same triangles (the ray
/// tracer against superel1's analytic render): the verdict against an
/// image is 2/255 on ≥ 99.9 % of the pixels, and nothing is unexplained.
#[test]
fn both_backends_match_povray_on_every_hazard_scene() {
    let mut text = String::new();
    for name in hazard_scenes() {
        for backend in [Backend::Ray, Backend::Raster] {
            let geometry = if backend == Backend::Ray {
                geometry(&name)
            } else {
                Geometry::Mesh
            };
            let job = Prepared::load(
                &hazard_path(&name),
                &Overrides {
                    geometry: Some(geometry),
                    ..Overrides::default()
                },
            )
            .unwrap();
            let pov = Side::Pov {
                golden_dir: golden_dir(),
                render: false,
            };
            let r = diff::diff(&job, &name, &Side::Backend(backend), &pov).unwrap();
            let e = r.report.explained.expect("a frame against an image");
            assert!(
                r.report.passed() && e.unexplained == 0,
                "{name} {backend} vs POV-Ray:\n{}",
                r.report.summary()
            );
            text.push_str(&format!(
                "{name} {backend}: max 8-bit {}, {} pixels beyond 2/255 ({} edges, {} depth ties, {} shadow/gate)\n",
                r.report.image.max_channel_8bit,
                e.differing,
                e.edge,
                e.depth_tie,
                e.shadow_or_gate
            ));
        }
    }
    insta::assert_snapshot!("hazard_scenes_against_povray", text);
}

/// `far` means one thing: with and without the plan (which culls objects
/// beyond far) both backends render the far-clipped scene bit for bit.
#[test]
fn far_is_the_same_with_and_without_the_plan() {
    let path = hazard_path("far_clip");
    let planned = Prepared::load(&path, &Overrides::default()).unwrap();
    let unplanned = Prepared::load(
        &path,
        &Overrides {
            no_plan: true,
            ..Overrides::default()
        },
    )
    .unwrap();
    assert!(
        planned.plan.frustum_cull.iter().any(|c| *c),
        "the sphere beyond far is culled"
    );
    for backend in [Backend::Raster, Backend::Ray] {
        let a = planned.render(backend).unwrap().frame;
        let b = unplanned.render(backend).unwrap().frame;
        assert_eq!(a.id, b.id, "{backend}");
        assert_eq!(a.color, b.color, "{backend}");
    }
}

// ---------------------------------------------------------------------
// Ray families: misses and leaks.

/// Rays per family; the four families together cast ≥ 10⁸ rays. Set
/// `RENDIFF_HAZARD_RAYS` to change the count per family.
fn rays_per_family() -> u64 {
    std::env::var("RENDIFF_HAZARD_RAYS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(25_000_000)
}

/// A log-uniform value in `[10^lo, 10^hi)`.
fn log_uniform(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    10f64.powf(rng.range(lo, hi))
}

fn sign(rng: &mut Rng) -> f64 {
    if rng.below(2) == 0 { 1.0 } else { -1.0 }
}

/// An offset of up to 10⁶ (none one time in four) that leaves a shape of
/// size `size` at least 4096 f32 steps across.
fn offset_for(rng: &mut Rng, size: f64) -> DVec3 {
    if rng.below(4) == 0 {
        return DVec3::ZERO;
    }
    let mag = log_uniform(rng, 0.0, 6.0).min(size / (4096.0 * f64::from(f32::EPSILON)));
    DVec3::new(
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
    ) * mag
}

/// A random rotation.
fn rotation(rng: &mut Rng) -> glam::DQuat {
    let axis = DVec3::new(
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
    )
    .try_normalize()
    .unwrap_or(DVec3::Y);
    glam::DQuat::from_axis_angle(axis, rng.range(0.0, std::f64::consts::TAU))
}

/// The f32 step at a shape of size `size` placed at `at`: what rounding
/// its vertices moved them by, at most.
fn step_at(at: DVec3, size: f64) -> f64 {
    (at.abs().max_element() + size) * f64::from(f32::EPSILON)
}

/// A scene of triangles (the accelerator needs only them).
fn scene_of(tris: &[[Vec3; 3]]) -> TriScene {
    let cam = rendiff::camera::Camera::new(
        DVec3::new(0.0, 0.0, 10.0),
        DVec3::ZERO,
        DVec3::Y,
        rendiff::camera::Projection::Perspective { tan_half_fov: 0.5 },
        4,
        4,
        1,
        0.01,
        100.0,
    )
    .unwrap();
    TriScene::from_triangles(cam, tris)
}

/// A placed shape: its triangles, centre, size and orientation.
struct Shape {
    scene: TriScene,
    centre: DVec3,
    size: f64,
    q: glam::DQuat,
}

/// Shapes built by `make(size, rotation, centre)`, sizes 10^lo … 10^hi,
/// offsets up to 10⁶, random rotations.
fn shapes(
    seed: u64,
    (lo, hi): (f64, f64),
    make: impl Fn(f64, glam::DQuat, DVec3) -> Vec<[Vec3; 3]>,
) -> Vec<Shape> {
    let mut rng = Rng(seed);
    (0..64)
        .map(|_| {
            let size = log_uniform(&mut rng, lo, hi);
            let q = rotation(&mut rng);
            let centre = offset_for(&mut rng, size);
            Shape {
                scene: scene_of(&make(size, q, centre)),
                centre,
                size,
                q,
            }
        })
        .collect()
}

/// A unit cube's 12 triangles (closed), placed.
fn cube(size: f64, q: glam::DQuat, centre: DVec3) -> Vec<[Vec3; 3]> {
    let c = |k: u32| {
        let p = DVec3::new(
            f64::from(k & 1),
            f64::from((k >> 1) & 1),
            f64::from((k >> 2) & 1),
        );
        to_f32(centre + q * ((p - DVec3::splat(0.5)) * size))
    };
    let v: Vec<Vec3> = (0..8).map(c).collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    quads
        .iter()
        .flat_map(|q| [[v[q[0]], v[q[1]], v[q[2]]], [v[q[0]], v[q[2]], v[q[3]]]])
        .collect()
}

/// A floor of 4×4 quads (32 triangles sharing their edges), `size`
/// across, centred, in the plane through `centre` normal to the local y
/// axis after `q`, which here only permutes the axes: the floor's
/// vertices are then exactly coplanar in f32 (a rotated floor's rounded
/// vertices fold along its edges, where a grazing ray may rightly touch
/// the surface without crossing it).
fn floor(size: f64, q: glam::DQuat, centre: DVec3) -> Vec<[Vec3; 3]> {
    let g = |i: usize, j: usize| {
        let p = DVec3::new(i as f64 / 4.0 - 0.5, 0.0, j as f64 / 4.0 - 0.5);
        to_f32(to_f64(to_f32(centre)) + q * (p * size))
    };
    let mut tris = Vec::new();
    for i in 0..4 {
        for j in 0..4 {
            let (a, b, c, d) = (g(i, j), g(i + 1, j), g(i + 1, j + 1), g(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    tris
}

/// The three axis permutations that put the local y axis on x, y or z.
fn axis_swap(k: u64) -> glam::DQuat {
    match k % 3 {
        0 => glam::DQuat::IDENTITY,
        1 => glam::DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
        _ => glam::DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2),
    }
}

/// Counts (rays, failures, a failing chunk's seed) of a family over `n`
/// rays in parallel chunks, each chunk with its own seed; `case` casts one
/// ray and says whether it behaved.
fn family(seed: u64, n: u64, case: impl Fn(&mut Rng) -> bool + Sync) -> (u64, u64, Option<u64>) {
    const CHUNK: u64 = 250_000;
    let chunks = n.div_ceil(CHUNK);
    let results: Vec<(u64, Option<u64>)> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let s = seed ^ c.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let mut rng = Rng(s);
            let count = CHUNK.min(n - c * CHUNK);
            let failed = (0..count).filter(|_| !case(&mut rng)).count() as u64;
            (failed, (failed > 0).then_some(s))
        })
        .collect();
    let failed = results.iter().map(|r| r.0).sum();
    (n, failed, results.iter().find_map(|r| r.1))
}

/// Random barycentric weights: inside, on an edge or at a vertex.
fn weights(rng: &mut Rng) -> [f64; 3] {
    let (a, b) = (rng.f64(), rng.f64());
    let (a, b) = if a + b > 1.0 {
        (1.0 - a, 1.0 - b)
    } else {
        (a, b)
    };
    match rng.below(8) {
        0 => [0.0, a, 1.0 - a],
        1 => [1.0, 0.0, 0.0],
        _ => [1.0 - a - b, a, b],
    }
}

/// ≥ 10⁸ rays in four families of the hazards that made the old test drop
/// genuine hits; each ray must meet the surface it is aimed through (no
/// miss, no leak). Targets are exact points of the f32 triangles (their
/// `f64` barycentric combinations), on edges and vertices too, so every
/// ray has a hit to find; eyes and origins stay clear of the surfaces by
/// more than the f32 rounding of the shapes (64 steps).
#[test]
fn no_ray_of_the_hazard_families_misses_or_leaks() {
    let n = rays_per_family();
    let floors: Vec<Shape> = {
        let mut rng = Rng(1);
        (0..64)
            .map(|k| {
                let size = log_uniform(&mut rng, -3.0, 6.0);
                let q = axis_swap(k);
                let centre = to_f64(to_f32(offset_for(&mut rng, size)));
                Shape {
                    scene: scene_of(&floor(size, q, centre)),
                    centre,
                    size,
                    q,
                }
            })
            .collect()
    };
    let floor_accels: Vec<Accel<'_>> = floors
        .iter()
        .map(|f| Accel::new(&f.scene, AccelOptions::default()))
        .collect();
    let cubes = shapes(2, (-3.0, 5.0), cube);
    let cube_accels: Vec<Accel<'_>> = cubes
        .iter()
        .map(|c| Accel::new(&c.scene, AccelOptions::default()))
        .collect();
    let walls = shapes(4, (1.3, 6.3), |size, q, c| {
        let w = |a: f64, b: f64| to_f32(c + q * (DVec3::new(a, b, 0.0) * (size * 0.5)));
        vec![
            [w(-1.0, -1.0), w(1.0, -1.0), w(1.0, 1.0)],
            [w(-1.0, -1.0), w(1.0, 1.0), w(-1.0, 1.0)],
        ]
    });
    let wall_accels: Vec<Accel<'_>> = walls
        .iter()
        .map(|w| Accel::new(&w.scene, AccelOptions::default()))
        .collect();
    let mut report = String::new();
    let mut total = 0;

    // 1. Grazing rays over huge floors (10⁻³ … 10⁶ across, the plane of
    // the rays' dominant axis): the eye 10⁻⁷ … 10⁻⁴ of the floor's size
    // above it (at least two f32 steps), aimed at points of its triangles
    // (edges and vertices too) near the eye's foot or anywhere.
    let (rays, failed, seed) = family(11, n, |rng| {
        let k = rng.below(floors.len() as u64) as usize;
        let (f, accel) = (&floors[k], &floor_accels[k]);
        let up = f.q * DVec3::Y;
        let tri = rng.below(32) as u32;
        let v = f.scene.triangle_f64(tri);
        let w = weights(rng);
        let target = v[0] * w[0] + v[1] * w[1] + v[2] * w[2];
        // Not on the floor's outline (a ray through its very edge may
        // round either way).
        let local = f.q.inverse() * (target - f.centre) / f.size;
        let margin = 64.0 * step_at(f.centre, f.size) / f.size;
        if local.x.abs().max(local.z.abs()) > 0.5 - margin {
            return true;
        }
        let h = (f.size * log_uniform(rng, -7.0, -4.0)).max(2.0 * step_at(f.centre, f.size));
        // The eye's foot: near the target (a few heights away) or anywhere.
        let run = if rng.below(2) == 0 {
            h * log_uniform(rng, 0.0, 4.0)
        } else {
            f.size * rng.f64() * 0.3
        };
        let side =
            f.q * DVec3::new(rng.range(-1.0, 1.0), 0.0, rng.range(-1.0, 1.0)).normalize_or_zero();
        let eye = to_f64(to_f32(target + side * run + up * h));
        let d = target - eye;
        let dist = d.length();
        let ray = Ray64 {
            origin: eye,
            dir: d / dist,
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        let ok = accel
            .intersect(&ray)
            .is_some_and(|hit| hit.t64 <= dist * (1.0 + 1e-9));
        if !ok && std::env::var("RENDIFF_DEBUG_HAZARDS").is_ok() {
            eprintln!(
                "miss: size {} centre {:?} h {h} run {run} target {target:?} eye {eye:?} w {w:?} tri {tri} hit {:?}",
                f.size,
                f.centre,
                accel.intersect(&ray)
            );
        }
        ok
    });
    report.push_str(&format!(
        "grazing floor: {rays} rays, {failed} misses (seed {seed:?})\n"
    ));
    total += rays;
    assert_eq!(failed, 0, "{report}");

    // 2. Tiny fields of view at distance: from an eye 10 … 10⁶ sizes away,
    // through points of a closed cube's inscribed sphere; each ray must
    // meet the cube before its target.
    let (rays, failed, seed) = family(12, n, |rng| {
        let k = rng.below(cubes.len() as u64) as usize;
        let (c, accel) = (&cubes[k], &cube_accels[k]);
        let dist = c.size * log_uniform(rng, 1.0, 6.0);
        let toward = DVec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        )
        .try_normalize()
        .unwrap_or(DVec3::X);
        let eye = to_f64(to_f32(c.centre - toward * dist));
        let p = DVec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        let target = c.centre + p.normalize_or_zero() * (0.45 * c.size * rng.f64().cbrt());
        let d = target - eye;
        let ray = Ray64 {
            origin: eye,
            dir: d.normalize(),
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        accel.intersect(&ray).is_some_and(|h| h.t64 <= d.length())
    });
    report.push_str(&format!(
        "tiny fov at distance: {rays} rays, {failed} misses (seed {seed:?})\n"
    ));
    total += rays;
    assert_eq!(failed, 0, "{report}");

    // 3. From inside a closed cube, in random, axis-aligned and grazing
    // directions (the dominant axis in a face's plane), from points up to
    // 64 f32 steps from a face: every ray leaves through the cube.
    let (rays, failed, seed) = family(13, n, |rng| {
        let k = rng.below(cubes.len() as u64) as usize;
        let (c, accel) = (&cubes[k], &cube_accels[k]);
        let margin = (64.0 * step_at(c.centre, c.size) / c.size).max(1e-7);
        let mut p = DVec3::new(
            rng.range(-0.45, 0.45),
            rng.range(-0.45, 0.45),
            rng.range(-0.45, 0.45),
        );
        if rng.below(2) == 0 {
            let axis = rng.below(3) as usize;
            p[axis] = (0.5 - margin * log_uniform(rng, 0.0, 3.0).min(0.4 / margin)) * sign(rng);
        }
        let local = match rng.below(3) {
            0 => DVec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ),
            1 => {
                let mut d = DVec3::ZERO;
                d[rng.below(3) as usize] = sign(rng);
                d
            }
            _ => {
                let mut d = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.0);
                d.z = log_uniform(rng, -9.0, -2.0) * sign(rng);
                d
            }
        };
        let Some(local) = local.try_normalize() else {
            return true;
        };
        let ray = Ray64 {
            origin: to_f64(to_f32(c.centre + c.q * (p * c.size))),
            dir: c.q * local,
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        accel.intersect(&ray).is_some()
    });
    report.push_str(&format!(
        "dominant axis in a face, from inside: {rays} rays, {failed} leaks (seed {seed:?})\n"
    ));
    total += rays;
    assert_eq!(failed, 0, "{report}");

    // 4. Shadow segments through a huge wall (2·10¹ … 4·10⁶ across): from
    // 10⁻⁷ … 10⁻¹ of its size in front (at least 64 f32 steps) to as far
    // behind, running mostly along it (their dominant axis in its plane).
    let (rays, failed, seed) = family(14, n, |rng| {
        let k = rng.below(walls.len() as u64) as usize;
        let (w, accel) = (&walls[k], &wall_accels[k]);
        let (u, v, normal) = (w.q * DVec3::X, w.q * DVec3::Y, w.q * DVec3::Z);
        let clear = 64.0 * step_at(w.centre, w.size);
        let at = w.centre + (u * rng.range(-0.4, 0.4) + v * rng.range(-0.4, 0.4)) * w.size;
        let front = (w.size * log_uniform(rng, -7.0, -1.0)).max(clear);
        let behind = (w.size * log_uniform(rng, -7.0, -1.0)).max(clear);
        let along = (u * rng.range(-1.0, 1.0) + v * rng.range(-1.0, 1.0)).normalize_or_zero()
            * (w.size * rng.range(0.01, 0.15));
        let from = to_f64(to_f32(at + normal * front - along * 0.5));
        let to = at - normal * behind + along * 0.5;
        let d = to - from;
        let len = d.length();
        let ray = Ray64 {
            origin: from,
            dir: d / len,
            t_min: 0.0,
            t_max: len,
        };
        let mut hit = false;
        accel.for_each_triangle_hit(&ray, |_, _| {
            hit = true;
            true
        });
        hit
    });
    report.push_str(&format!(
        "shadow segments through a huge wall: {rays} rays, {failed} leaks (seed {seed:?})\n"
    ));
    total += rays;
    assert_eq!(failed, 0, "{report}");
    eprintln!("{report}total: {total} rays");
    assert!(total >= 4 * rays_per_family());
}
