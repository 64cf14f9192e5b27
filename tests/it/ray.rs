//! The ray tracer: BVH against brute force, watertightness, no self-hits
//! at any scale, thread-count invariance, and shading against a
//! hand-written f64 reference on a lit sphere.

use rendiff::accel::{Accel, AccelOptions, ShadowRays};
use rendiff::camera::{Camera, Projection};
use rendiff::compare::{Class, Oracle};
use rendiff::frame::BACKGROUND;
use rendiff::math::{DVec3, Ray, Ray64, Vec3, to_f32, to_f64};
use rendiff::options::{DepthFormat, Geometry};
use rendiff::scene::Scene;
use rendiff::shade::Visibility;
use rendiff::tri_scene::TriScene;
use rendiff::{Backend, Overrides, Prepared};

use crate::util::{Rng, load, scene_path, with_threads};

fn camera() -> Camera {
    Camera::new(
        DVec3::new(0.0, 0.0, 5.0),
        DVec3::ZERO,
        DVec3::Y,
        Projection::Perspective { tan_half_fov: 0.5 },
        64,
        64,
        1,
        0.01,
        100.0,
    )
    .unwrap()
}

fn random_dir(rng: &mut Rng) -> Vec3 {
    loop {
        let d = Vec3::new(
            rng.rangef(-1.0, 1.0),
            rng.rangef(-1.0, 1.0),
            rng.rangef(-1.0, 1.0),
        );
        if d.length() > 0.05 && d.length() <= 1.0 {
            return d.normalize();
        }
    }
}

fn query(origin: Vec3, dir: Vec3, t_max: f32) -> rendiff::shade::ShadowQuery {
    rendiff::shade::ShadowQuery {
        light: 0,
        origin,
        dir,
        t_max,
        normal: dir,
        leaves: u32::MAX,
    }
}

/// Closest hits and shadow transmittance of a BVH equal those of a flat
/// loop over all triangles (the brute force): same triangle, same `t` bits.
fn assert_bvh_matches_brute_force(t: &TriScene, rays: usize, seed: u64) {
    let bvh = Accel::new(
        t,
        AccelOptions {
            geometry: Geometry::Mesh,
            bvh: true,
            ..AccelOptions::default()
        },
    );
    let flat = Accel::new(
        t,
        AccelOptions {
            geometry: Geometry::Mesh,
            bvh: false,
            ..AccelOptions::default()
        },
    );
    let (sb, sf) = (ShadowRays::new(&bvh), ShadowRays::new(&flat));
    let b = t.bounds;
    let (c, r) = b.bounding_sphere();
    let mut rng = Rng(seed);
    let mut hits = 0;
    for k in 0..rays {
        // Origins around and inside the bounds; half the rays aimed at a
        // random point of a random triangle, half at a random point of the bounds.
        let o = c + random_dir(&mut rng) * r * rng.rangef(0.0, 2.5);
        let target = if k % 2 == 0 {
            let v = t.triangle(rng.below(t.len() as u64) as u32);
            let (u, w) = (rng.rangef(0.0, 1.0), rng.rangef(0.0, 1.0));
            let (u, w) = if u + w > 1.0 {
                (1.0 - u, 1.0 - w)
            } else {
                (u, w)
            };
            v[0] + (v[1] - v[0]) * u + (v[2] - v[0]) * w
        } else {
            b.min
                + (b.max - b.min)
                    * Vec3::new(
                        rng.rangef(0.0, 1.0),
                        rng.rangef(0.0, 1.0),
                        rng.rangef(0.0, 1.0),
                    )
        };
        let Some(dir) = (target - o).try_normalize() else {
            continue;
        };
        let ray = Ray {
            origin: o,
            dir,
            t_min: 0.0,
            t_max: f32::INFINITY,
        };
        let (x, y) = (
            bvh.intersect(&Ray64::from(&ray)),
            flat.intersect(&Ray64::from(&ray)),
        );
        assert_eq!(
            x.map(|h| (h.prim, h.t.to_bits())),
            y.map(|h| (h.prim, h.t.to_bits())),
            "seed {seed}, ray {k}: {ray:?}"
        );
        hits += usize::from(x.is_some());
        let tmax = rng.rangef(0.0, 3.0) * r;
        assert_eq!(
            sb.transmittance(&query(o, dir, tmax)),
            sf.transmittance(&query(o, dir, tmax)),
            "seed {seed}, shadow ray {k}"
        );
    }
    assert!(
        hits > rays / 3,
        "only {hits} of {rays} rays hit: the test aims badly"
    );
}

#[test]
fn bvh_equals_brute_force_on_random_triangles() {
    let mut rng = Rng(7);
    let tris: Vec<[Vec3; 3]> = (0..3000)
        .map(|_| {
            let c = Vec3::new(
                rng.rangef(-2.0, 2.0),
                rng.rangef(-2.0, 2.0),
                rng.rangef(-2.0, 2.0),
            );
            let s = rng.rangef(0.01, 0.4);
            [
                c,
                c + random_dir(&mut rng) * s,
                c + random_dir(&mut rng) * s,
            ]
        })
        .collect();
    let t = TriScene::from_triangles(camera(), &tris);
    assert_bvh_matches_brute_force(&t, 20_000, 11);
}

#[test]
fn bvh_equals_brute_force_on_real_meshes() {
    for (name, seed) in [("bunny", 1), ("dense", 2), ("inside", 3)] {
        let job = load(name, &Overrides::default());
        assert_bvh_matches_brute_force(&job.tri, 4_000, seed);
    }
}

/// Closed meshes: tessellated spheres (several segment counts), a box, a
/// superellipsoid and the real closed meshes (cow, knot, elephant, bunny).
fn closed_meshes() -> Vec<TriScene> {
    let mut out = Vec::new();
    for (name, ..) in [
        ("inside", 0),
        ("menagerie", 0),
        ("bunny", 0),
        ("spheres", 0),
        ("superellipsoids", 0),
    ] {
        let job = load(name, &Overrides::default());
        for o in job.tri.objects.iter().filter(|o| o.closed) {
            let tris: Vec<[Vec3; 3]> = o.tris.clone().map(|k| job.tri.triangle(k)).collect();
            let mut t = TriScene::from_triangles(camera(), &tris);
            t.objects[0].closed = true;
            out.push(t);
        }
    }
    out
}

/// Number of surface crossings of the ray from `p` along `dir`, counted by
/// repeated closest-hit queries, each starting 8 ulps beyond the last hit
/// (the same triangle may report its hit again a few ulps further on).
fn crossings(accel: &Accel<'_>, p: Vec3, dir: Vec3) -> usize {
    let mut ray = Ray {
        origin: p,
        dir,
        t_min: 0.0,
        t_max: f32::INFINITY,
    };
    let mut n = 0;
    while let Some(h) = accel.intersect(&Ray64::from(&ray)) {
        n += 1;
        ray.t_min = h.t * (1.0 + 8.0 * f32::EPSILON) + f32::MIN_POSITIVE;
        assert!(n < 10_000, "runaway crossing count");
    }
    n
}

/// Points strictly inside a closed mesh: random points of its bounds whose
/// crossing count is odd along three different directions.
fn interior_points(accel: &Accel<'_>, t: &TriScene, rng: &mut Rng, want: usize) -> Vec<Vec3> {
    let b = t.bounds;
    let dirs = [
        Vec3::new(0.31, 0.84, 0.44).normalize(),
        Vec3::new(-0.72, 0.11, 0.68).normalize(),
        Vec3::new(0.05, -0.93, 0.36).normalize(),
    ];
    let mut out = Vec::new();
    for _ in 0..20_000 {
        let p = b.min
            + (b.max - b.min)
                * Vec3::new(
                    rng.rangef(0.02, 0.98),
                    rng.rangef(0.02, 0.98),
                    rng.rangef(0.02, 0.98),
                );
        if dirs.iter().all(|&d| crossings(accel, p, d) % 2 == 1) {
            out.push(p);
            if out.len() == want {
                break;
            }
        }
    }
    out
}

/// A ray from a point inside a closed mesh toward any point of its
/// surface reaches the surface at or before that point: aimed exactly at
/// vertices and along edges, where two or more triangles meet, it must
/// still hit (pbrt-v4's Triangle.Watertight, from inside real meshes too).
#[test]
fn watertight_rays_at_vertices_and_edges_never_miss() {
    let meshes = closed_meshes();
    assert!(meshes.len() >= 10, "{} closed meshes", meshes.len());
    let mut rng = Rng(99);
    let mut total = 0usize;
    let per_mesh = 1_000_000 / meshes.len() + 1;
    for (m, t) in meshes.iter().enumerate() {
        let accel = Accel::new(t, AccelOptions::default());
        let inside = interior_points(&accel, t, &mut rng, 16);
        assert!(!inside.is_empty(), "mesh {m}: no interior point found");
        let mut misses = 0usize;
        for k in 0..per_mesh {
            // Aim at a vertex (1/3 of the rays) or a point on an edge.
            let tri = t.triangle(rng.below(t.len() as u64) as u32);
            let e = rng.below(3) as usize;
            let target = if k % 3 == 0 {
                tri[e]
            } else {
                let s = rng.rangef(0.0, 1.0);
                tri[e] + (tri[(e + 1) % 3] - tri[e]) * s
            };
            let o = inside[k % inside.len()];
            let Some(dir) = (target - o).try_normalize() else {
                continue;
            };
            let ray = Ray {
                origin: o,
                dir,
                t_min: 0.0,
                t_max: f32::INFINITY,
            };
            if accel.intersect(&Ray64::from(&ray)).is_none() {
                misses += 1;
            }
            total += 1;
        }
        assert_eq!(
            misses, 0,
            "mesh {m}: {misses} of {per_mesh} rays slipped through"
        );
    }
    assert!(total >= 1_000_000, "{total} rays");
}

#[test]
fn rays_from_inside_a_closed_mesh_always_hit() {
    let job = load("superellipsoids", &Overrides::default());
    let mut rng = Rng(5);
    let accel = Accel::new(&job.tri, AccelOptions::default());
    for o in job
        .tri
        .objects
        .iter()
        .filter(|o| o.kind == "superellipsoid")
    {
        // The centre of a superellipsoid is inside it (star-shaped).
        let c = o.bounds.center();
        assert!(
            accel.contains(job.tri.tri_object[o.tris.start as usize], c),
            "{}: centre not inside",
            o.label
        );
        for _ in 0..50_000 {
            let ray = Ray {
                origin: c,
                dir: random_dir(&mut rng),
                t_min: 0.0,
                t_max: f32::INFINITY,
            };
            assert!(
                accel.intersect(&Ray64::from(&ray)).is_some(),
                "{}: a ray from inside escaped",
                o.label
            );
        }
    }
}

/// The visible surfaces do not change with the scale and position of a
/// scene: the id image of every scaled and moved copy equals the original
/// one except at ties (edge ties widened by the f32 rounding of the moved
/// vertices, which really moves them).
#[test]
fn visibility_is_the_same_at_any_scale() {
    for name in ["spheres", "glass", "inside"] {
        let base_scene = Scene::load(&scene_path(name)).unwrap();
        let base = Prepared::from_scene(base_scene.clone(), &Overrides::default()).unwrap();
        let fb = base.render(Backend::Ray).unwrap().frame;
        for (scale, offset) in [
            (1e-3, DVec3::ZERO),
            (1e5, DVec3::ZERO),
            (1.0, DVec3::new(1e4, -1e4, 1e4)),
            (1e3, DVec3::new(1e4, 0.0, -1e4)),
        ] {
            let job = Prepared::from_scene(
                base_scene.scaled(scale, offset).unwrap(),
                &Overrides::default(),
            )
            .unwrap();
            assert_eq!(
                job.tri.len(),
                base.tri.len(),
                "{name} ×{scale} +{offset}: tessellation changed"
            );
            let f = job.render(Backend::Ray).unwrap().frame;
            // Visibility: every differing id is explained (no real mismatch)
            // by the oracle of the scaled scene.
            let cam = &job.tri.camera;
            // Across scenes the triangles differ by the f32 rounding of the
            // scaled and moved vertices (≤ ½ ulp of the largest coordinate);
            // the base frame's triangle is evaluated in the scaled scene, so
            // that rounding, in pixels at the nearest depth, widens the edge band.
            let b = job.tri.bounds;
            let largest = f64::from(b.min.abs().max(b.max.abs()).max_element());
            let ulp = largest * f64::from(f32::EPSILON);
            let z_min = b
                .corners()
                .iter()
                .map(|c| cam.view_depth(to_f64(*c)))
                .fold(f64::INFINITY, f64::min)
                .max(cam.near());
            let quantization_px = ulp * cam.max_pixels_per_unit(z_min);
            let oracle = Oracle::new(&job.tri, DepthFormat::F32).with_vertex_error(quantization_px);
            let mut real = 0;
            let mut differ = 0;
            for (i, (&a, &b)) in fb.id.iter().zip(&f.id).enumerate() {
                if a != b {
                    differ += 1;
                    let (sx, sy) = (
                        (i as u32) % cam.sample_width(),
                        (i as u32) / cam.sample_width(),
                    );
                    let (x, y) = cam.sample_point(sx, sy);
                    let opt = |v: u32| (v != BACKGROUND).then_some(v);
                    if oracle.classify(x, y, opt(a), opt(b)) == Class::Real {
                        real += 1;
                    }
                }
            }
            assert_eq!(
                real, 0,
                "{name} ×{scale} +{offset}: {real} of {differ} differing samples are real"
            );
        }
    }
}

/// Every bit of a frame at 1, 2, 8 and 16 threads: the bands the passes
/// split a frame into grow thinner as threads are added (`band_rows`: 32
/// and 16 sample rows at 1 thread, 8 and 4 at 16), the BVH's and light
/// buffers' builds run their large parts in parallel, and none of it may
/// change a sample.
#[test]
fn output_does_not_depend_on_the_thread_count() {
    for name in ["spheres", "glass", "dense"] {
        let job = load(name, &Overrides::default());
        for backend in [Backend::Ray, Backend::Raster] {
            let one = with_threads(1, || job.render(backend).unwrap().frame);
            for n in [2, 8, 16] {
                let other = with_threads(n, || job.render(backend).unwrap().frame);
                assert!(
                    one == other,
                    "{name} {backend}: 1 thread and {n} threads differ"
                );
            }
        }
    }
}

// ---- Shading against an independent f64 reference ------------------------

struct Finish {
    pigment: [f64; 3],
    ambient: f64,
    diffuse: f64,
    brilliance: f64,
    phong: f64,
    phong_size: f64,
    specular: f64,
    roughness: f64,
    metallic: f64,
    reflection: f64,
    filter: f64,
    transmit: f64,
    emission: f64,
}

const BASE: Finish = Finish {
    pigment: [0.8, 0.5, 0.3],
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
    emission: 0.0,
};

/// POVRAY.md §4 in f64, for one analytic sphere lit by one point light,
/// seen against a uniform background (reflected and transmitted rays of a
/// convex sphere leave it and see the background; an ior-1 transmitted ray
/// crosses the far side, which is shaded too).
#[expect(
    clippy::too_many_arguments,
    reason = "the reference's scene, spelled out"
)]
fn reference(
    f: &Finish,
    p: DVec3,
    n_out: DVec3,
    d: DVec3,
    light: DVec3,
    lc: f64,
    amb: f64,
    bg: [f64; 3],
    far: Option<(DVec3, DVec3)>,
) -> [f64; 3] {
    let tw: [f64; 3] = std::array::from_fn(|k| f.filter * f.pigment[k] + f.transmit);
    let local = |p: DVec3, n_out: DVec3, d: DVec3| -> [f64; 3] {
        let n = if n_out.dot(d) > 0.0 { -n_out } else { n_out };
        let l = (light - p).normalize();
        let nl = n.dot(l);
        let opacity = 1.0 - f.filter - f.transmit;
        // A shadow ray that re-enters the (transparent) sphere crosses its
        // surface once more: the light is filtered by f·P + t.
        let shadow: [f64; 3] = if n_out.dot(l) < 0.0 { tw } else { [1.0; 3] };
        let mut c = [0.0; 3];
        let mut hl = 0.0;
        let mut metal = [1.0; 3];
        if nl > 0.0 {
            let x = nl.clamp(-1.0, 1.0).acos() / std::f64::consts::FRAC_PI_2;
            let fr = (0.014_567_225 / (x - 1.12).powi(2) - 0.011_612_903).clamp(0.0, 1.0);
            for (m, p) in metal.iter_mut().zip(f.pigment) {
                *m = 1.0 + f.metallic * (1.0 - fr) * (p - 1.0);
            }
            let rv = d - n * (2.0 * d.dot(n));
            if f.phong > 0.0 && rv.dot(l) > 0.0 {
                hl += f.phong * rv.dot(l).powf(f.phong_size);
            }
            let h = (l - d).normalize();
            if f.specular > 0.0 && h.dot(n) > 0.0 {
                hl += f.specular * h.dot(n).powf(1.0 / f.roughness);
            }
        }
        for k in 0..3 {
            let lk = lc * shadow[k];
            let diffuse = if nl > 0.0 {
                f.diffuse * nl.powf(f.brilliance) * lk
            } else {
                0.0
            };
            c[k] = opacity * f.pigment[k] * (f.ambient * amb + f.emission + diffuse)
                + hl * lk * metal[k];
        }
        c
    };
    let mut c = local(p, n_out, d);
    for k in 0..3 {
        c[k] += f.reflection * bg[k];
    }
    if f.filter + f.transmit > 0.0 {
        // ior 1: straight on, through the far side (shaded too), then the background.
        let (p2, n2) = far.expect("a far-side hit");
        let c2 = local(p2, n2, d);
        for k in 0..3 {
            c[k] += tw[k] * (c2[k] + f.reflection * bg[k] + tw[k] * bg[k]);
        }
    }
    c
}

#[test]
fn shading_matches_a_hand_computed_reference_for_each_finish_key() {
    let bg = [0.2, 0.3, 0.4];
    let light = DVec3::new(3.0, 4.0, 5.0);
    let amb = 0.7;
    let cases: Vec<(&str, Finish)> = vec![
        (
            "ambient",
            Finish {
                ambient: 0.4,
                ..BASE
            },
        ),
        (
            "diffuse",
            Finish {
                diffuse: 0.9,
                ..BASE
            },
        ),
        (
            "brilliance",
            Finish {
                brilliance: 3.0,
                ..BASE
            },
        ),
        ("phong", Finish { phong: 0.8, ..BASE }),
        (
            "phong_size",
            Finish {
                phong: 0.8,
                phong_size: 7.0,
                ..BASE
            },
        ),
        (
            "specular",
            Finish {
                specular: 0.7,
                ..BASE
            },
        ),
        (
            "roughness",
            Finish {
                specular: 0.7,
                roughness: 0.2,
                ..BASE
            },
        ),
        (
            "metallic",
            Finish {
                phong: 0.9,
                phong_size: 5.0,
                metallic: 0.8,
                ..BASE
            },
        ),
        (
            "reflection",
            Finish {
                reflection: 0.5,
                ..BASE
            },
        ),
        (
            "filter",
            Finish {
                filter: 0.6,
                phong: 0.5,
                ..BASE
            },
        ),
        (
            "transmit",
            Finish {
                transmit: 0.4,
                specular: 0.3,
                ..BASE
            },
        ),
        (
            "emission",
            Finish {
                emission: 0.3,
                ..BASE
            },
        ),
    ];
    for (key, f) in cases {
        let text = format!(
            r#"
[image]
width = 48
height = 48
background = [{}, {}, {}]
[camera]
eye = [0.0, 0.0, 4.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0
[render]
ambient_light = [{amb}, {amb}, {amb}]
max_depth = 3
[[lights]]
kind = "point"
position = [{}, {}, {}]
color = [1.0, 1.0, 1.0]
[materials.m]
pigment = [{}, {}, {}]
ambient = {}
diffuse = {}
brilliance = {}
phong = {}
phong_size = {}
specular = {}
roughness = {}
metallic = {}
reflection = {}
filter = {}
transmit = {}
emission = {}
[ray]
geometry = "analytic"
[[objects]]
kind = "sphere"
material = "m"
center = [0.0, 0.0, 0.0]
radius = 1.0
"#,
            bg[0],
            bg[1],
            bg[2],
            light.x,
            light.y,
            light.z,
            f.pigment[0],
            f.pigment[1],
            f.pigment[2],
            f.ambient,
            f.diffuse,
            f.brilliance,
            f.phong,
            f.phong_size,
            f.specular,
            f.roughness,
            f.metallic,
            f.reflection,
            f.filter,
            f.transmit,
            f.emission
        );
        let scene = Scene::from_str(&scene_path("inline"), &text).unwrap();
        let job = Prepared::from_scene(scene, &Overrides::default()).unwrap();
        let frame = job.render(Backend::Ray).unwrap().frame;
        let cam = &job.tri.camera;
        let mut checked = 0;
        // Error bound: every input carries an f32 rounding (≤ 2^-24
        // relative); the largest exponent here is 1/0.05 = 20 (40 for phong),
        // and a chain of ~30 f32 operations adds 30·2^-24. So
        // |Δ| ≤ (40·4 + 30)·2^-24·|C| ≤ 2e-5 for |C| ≤ 1.7.
        let bound = 2e-5;
        for sy in (2..48).step_by(5) {
            for sx in (2..48).step_by(5) {
                let i = (sy * 48 + sx) as usize;
                if frame.id[i] == BACKGROUND {
                    continue;
                }
                let (o, d) = cam.primary_ray_f64(f64::from(sx) + 0.5, f64::from(sy) + 0.5);
                let (t0, t1) =
                    rendiff::analytic::sphere::sphere_roots(o, d, DVec3::ZERO, 1.0).unwrap();
                let p = o + d * t0;
                // The renderer shades with the f32 direction; so does the reference.
                let d32 = to_f64(to_f32(d));
                let p2 = o + d * t1;
                let want = reference(
                    &f,
                    p,
                    p.normalize(),
                    d32,
                    light,
                    1.0,
                    amb,
                    bg,
                    Some((p2, p2.normalize())),
                );
                let got = frame.sample_colors()[i];
                let got = [f64::from(got.r), f64::from(got.g), f64::from(got.b)];
                for k in 0..3 {
                    assert!(
                        (got[k] - want[k]).abs() <= bound,
                        "{key}: sample ({sx}, {sy}) channel {k}: got {} want {} (Δ {:e})",
                        got[k],
                        want[k],
                        got[k] - want[k]
                    );
                }
                checked += 1;
            }
        }
        assert!(checked > 30, "{key}: only {checked} samples on the sphere");
    }
}

/// No acne at any scale: on a lone convex object, a shadow ray from a
/// point whose geometric normal faces the light cannot be blocked (the ray
/// leaves the convex hull), and a reflected ray cannot hit the object
/// again. Both are checked on every sample, for the scene scaled from 1e-3
/// to 1e5 and moved up to 1e4 away from the origin with everything in it.
#[test]
fn no_self_hits_at_any_scale() {
    let text = |reflection: f64| {
        format!(
            r#"
[image]
width = 96
height = 96
background = [0.25, 0.5, 0.75]
[camera]
eye = [0.4, 0.7, 3.5]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 45.0
[render]
max_depth = 2
tessellation_error = 1.5
[[lights]]
kind = "point"
position = [2.0, 3.0, 2.5]
color = [1.0, 1.0, 1.0]
[[lights]]
kind = "point"
position = [-3.0, 0.5, 1.0]
color = [0.5, 0.5, 0.5]
[materials.m]
pigment = [0.8, 0.7, 0.6]
phong = 0.5
reflection = {reflection}
[[objects]]
kind = "sphere"
material = "m"
center = [0.0, 0.0, 0.0]
radius = 1.0
"#
        )
    };
    let base = Scene::from_str(&scene_path("inline"), &text(0.5)).unwrap();
    let base0 = Scene::from_str(&scene_path("inline"), &text(0.0)).unwrap();
    let mut checked = 0u64;
    // Scaled about the origin from 1e-3 to 1e5, and moved 1e4 away at
    // scales 1 and 1e3. (A scene 1e-3 across moved 1e4 away spans a few
    // f32 ulps of its position: no geometry survives that rounding.)
    for (scale, offset) in [
        (1.0, DVec3::ZERO),
        (1e-3, DVec3::ZERO),
        (1e5, DVec3::ZERO),
        (1.0, DVec3::new(1e4, -1e4, 1e4)),
        (1e3, DVec3::new(-1e4, 1e4, 0.0)),
    ] {
        let job = Prepared::from_scene(base.scaled(scale, offset).unwrap(), &Overrides::default())
            .unwrap();
        let job0 =
            Prepared::from_scene(base0.scaled(scale, offset).unwrap(), &Overrides::default())
                .unwrap();
        let (f, f0) = (
            job.render(Backend::Ray).unwrap().frame,
            job0.render(Backend::Ray).unwrap().frame,
        );
        let (_, skips, met) = own_triangle_skips(&job);
        assert_eq!(
            met, 0,
            "×{scale} +{offset}: {met} of {skips} skipping shadow rays met their triangle"
        );
        let t = &job.tri;
        let mut shadow_acne = 0;
        let mut reflect_acne = 0;
        for i in 0..f.id.len() {
            let id = f.id[i];
            if id == BACKGROUND {
                continue;
            }
            assert_eq!(id, f0.id[i]);
            let ng = t.geometric_normal(id);
            let centroid = t.triangle(id).iter().copied().sum::<Vec3>() / 3.0;
            for (k, l) in t.lights.iter().enumerate() {
                let rendiff::shade::LightKind::Point { position } = l.kind else {
                    continue;
                };
                let to_light = (position - centroid).normalize();
                // Well inside the lit side of the facet's plane.
                if ng.dot(to_light) > 0.05 && f.flags[i] & (2 << k) != 0 {
                    shadow_acne += 1;
                }
            }
            // Where the view meets the facet at less than 60° from its
            // normal, the mirror ray about the smooth normal (within a few
            // degrees of the facet's) leaves the facet's plane outward and
            // cannot meet the convex object again: C(reflection 0.5) −
            // C(reflection 0) = 0.5·background, up to the f32 rounding of the
            // sum (≤ 2 ulps of values ≤ 2).
            let cam = &t.camera;
            let (sx, sy) = (
                (i as u32) % cam.sample_width(),
                (i as u32) / cam.sample_width(),
            );
            if cam.sample_ray(sx, sy).dir.dot(ng) > -0.5 {
                continue;
            }
            let (c, c0) = (f.sample_colors()[i], f0.sample_colors()[i]);
            let want = [0.125f32, 0.25, 0.375];
            for (got, w) in [c.r - c0.r, c.g - c0.g, c.b - c0.b].iter().zip(want) {
                if (got - w).abs() > 4.0 * f32::EPSILON * 2.0 {
                    reflect_acne += 1;
                }
            }
            checked += 1;
        }
        assert_eq!(shadow_acne, 0, "×{scale} +{offset}: shadow acne");
        assert_eq!(
            reflect_acne, 0,
            "×{scale} +{offset}: reflection rays hit their own surface"
        );
    }
    assert!(checked > 10_000, "{checked} samples");
}

/// Every bundled and hazard scene (at least twenty), loaded at 96×72, in
/// the order of their paths.
fn every_scene_small() -> Vec<(std::path::PathBuf, Prepared)> {
    let mut paths = Vec::new();
    for dir in ["scenes", "tests/data/hazards"] {
        for e in std::fs::read_dir(crate::util::root().join(dir)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                paths.push(p);
            }
        }
    }
    paths.sort();
    assert!(paths.len() >= 20, "the scenes are found");
    let ov = Overrides {
        size: Some((96, 72)),
        ..Overrides::default()
    };
    paths
        .into_iter()
        .map(|p| {
            let job = Prepared::load(&p, &ov).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, job)
        })
        .collect()
}

/// The ray tracer's frame of `job` through `accel`, with the plan's ray
/// tree and shadows.
fn ray_frame(job: &Prepared, accel: &Accel<'_>) -> rendiff::frame::Frame {
    let opts = rendiff::ray::RayOptions {
        max_depth: if job.plan.ray_tree {
            job.tri.max_depth.max(1)
        } else {
            1
        },
        shadows: job.plan.shadows,
        gate_eps: rendiff::GATE_EPS,
    };
    rendiff::ray::render(accel, &opts)
}

/// The shadow queries shading makes at every primary hit on a triangle
/// (the ray tracer's surface point and normal), each traced without
/// skipping anything: (queries, those the ray queries skip their own
/// triangle for, those of them that met it anyway). A query skips its
/// triangle (`Accel::skips_its_own_triangle`) only where its origin is
/// strictly on one side of the plane and its direction strictly away, so
/// the last count must be zero.
fn own_triangle_skips(job: &Prepared) -> (u64, u64, u64) {
    let t = &job.tri;
    let accel = Accel::new(t, AccelOptions::default());
    let ctx = t.shade_context(rendiff::GATE_EPS, true);
    let cam = &t.camera;
    let (mut queries, mut skipped, mut met) = (0u64, 0u64, 0u64);
    for sy in 0..cam.sample_height() {
        for sx in 0..cam.sample_width() {
            let ray = cam.sample_ray64(sx, sy);
            let Some(hit) = accel.intersect(&ray) else {
                continue;
            };
            if hit.prim as usize >= t.len() {
                continue;
            }
            let (b, _) = t.view_weights(hit.prim, ray.origin, ray.dir);
            let sp = t.surface_at(hit.prim, b);
            let _ = rendiff::shade::shadow_queries(&ctx, &sp, to_f32(ray.dir), |q| {
                queries += 1;
                assert_eq!(q.leaves, hit.prim);
                if !accel.skips_its_own_triangle(&q) {
                    return;
                }
                skipped += 1;
                accel.for_each_triangle_hit(&accel.shadow_segment(&q), |id, _| {
                    if id == q.leaves {
                        met += 1;
                    }
                    false
                });
            });
        }
    }
    (queries, skipped, met)
}

/// A shadow ray skips the triangle it leaves only where it cannot meet
/// it: on every bundled and hazard scene (the eye 10⁶ out, grazing views,
/// a light in a wall's plane, a 0.05° field of view), every shadow query
/// of every primary hit that skips its triangle, traced through every
/// triangle it crosses, never meets it; and nearly all of them skip it
/// (the saving is real).
#[test]
fn a_shadow_ray_skips_its_triangle_only_where_it_cannot_meet_it() {
    let (mut total, mut skipped) = (0, 0);
    for (path, job) in every_scene_small() {
        let (queries, skips, met) = own_triangle_skips(&job);
        assert_eq!(
            met,
            0,
            "{}: {met} of {skips} skipping shadow rays met their own triangle",
            path.display()
        );
        total += queries;
        skipped += skips;
    }
    assert!(total > 50_000, "{total} shadow queries");
    assert!(
        skipped * 100 > total * 95,
        "only {skipped} of {total} queries skip their triangle"
    );
}

/// Skipping a shadow ray's own triangle changes no answer where the
/// origin's side of the plane, chosen in `f32` from the light's direction
/// as shading saw it, is not the light's side (found by review: a point
/// light 10⁻⁷ off the plane made a self-shadowed point lit) or where the
/// triangle is so small that its `f32` normal underflows: random lights
/// near a random triangle's plane on both sides, at triangle sizes from
/// 10³ down to 10⁻¹³, every query answered with the skip (one by one and
/// in a packet) and without it (`leaves = u32::MAX`) alike.
#[test]
fn skipping_the_own_triangle_changes_no_shadow() {
    use rendiff::accel::ShadowRays;
    use rendiff::math::Bary;
    use rendiff::shade::{Light, LightKind, ShadowQuery};
    let cam = camera();
    let mut rng = Rng(0x5eed_0f0d_dba1_1000);
    // The reviewer's case: the light 10⁻⁷ off the triangle's plane.
    let mut cases: Vec<([Vec3; 3], Vec3, [f32; 3])> = vec![(
        [
            Vec3::new(32.2984, -34.524_387, 21.039_589),
            Vec3::new(-42.959_12, -9.527_147, -5.924_555_3),
            Vec3::new(41.259_872, 42.624_054, -8.743_754),
        ],
        Vec3::new(103.212_93, 106.999_81, -21.529_07),
        [0.350_064_37, 0.421_127_68, 0.228_807_94],
    )];
    let mut sign = 1.0;
    while cases.len() < 20_000 {
        sign = -sign;
        let scale = 10f64.powf(3.0 - 16.0 * rng.f64());
        let mut jitter = || {
            DVec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            )
        };
        let center = jitter() * scale * 10.0;
        let v: [Vec3; 3] = std::array::from_fn(|_| to_f32(center + jitter() * scale));
        let vd = v.map(to_f64);
        let Some(n) = (vd[1] - vd[0]).cross(vd[2] - vd[0]).try_normalize() else {
            continue;
        };
        let mut w = [rng.f64(), rng.f64(), rng.f64()];
        let sum = w[0] + w[1] + w[2];
        w = w.map(|x| x / sum);
        let p = vd[0] * w[0] + vd[1] * w[1] + vd[2] * w[2];
        // Heights off the plane from 1 down to 10⁻¹⁰ of the distance,
        // on either side.
        let height = 10f64.powf(-10.0 * rng.f64()) * sign;
        let dist = scale * 10f64.powf(3.0 * rng.f64());
        let light = to_f32(p + (n.any_orthonormal_vector() + n * height) * dist);
        #[expect(clippy::cast_possible_truncation, reason = "weights in [0, 1]")]
        cases.push((v, light, w.map(|x| x as f32)));
    }
    let (mut queries, mut differ) = (0, 0);
    for (v, light, w) in cases {
        let mut scene = TriScene::from_triangles(cam, &[v]);
        scene.lights.push(Light {
            kind: LightKind::Point { position: light },
            color: rendiff::color::Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
        let accel = Accel::new(&scene, AccelOptions::default());
        let rays = ShadowRays::new(&accel);
        let ctx = scene.shade_context(rendiff::GATE_EPS, true);
        let sp = scene.surface_at(0, Bary(w));
        for d in [sp.ng, -sp.ng] {
            let mut qs: Vec<ShadowQuery> = Vec::new();
            let _ = rendiff::shade::shadow_queries(&ctx, &sp, d, |q| qs.push(q));
            for q in qs {
                let every = ShadowQuery {
                    leaves: u32::MAX,
                    ..q
                };
                queries += 1;
                let (a, b) = (rays.transmittance(&q), rays.transmittance(&every));
                let mut packed = [rendiff::color::Rgb::WHITE];
                rays.transmittance_packets(&[q], &mut packed);
                if a != b || packed[0] != b {
                    differ += 1;
                }
            }
        }
    }
    assert!(queries > 15_000, "{queries} queries");
    assert_eq!(
        differ, 0,
        "{differ} of {queries} shadow answers changed by the skip"
    );
}

/// The shadow tests' triangles: the floor `y = 0` over ±4 (triangles 0
/// and 1, meeting on `x = z`), a large occluder at `y = 1` over ±1 moved
/// by `shift` along x (2 and 3), and a `cells × cells` grid of quads of
/// side `side` at `y = 2`, `pitch` apart from (0.5 − shift, −1.5).
fn floor_occluder_grid(shift: f32, cells: u8, pitch: f32, side: f32) -> Vec<[Vec3; 3]> {
    let quad = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| [[a, b, c], [a, c, d]];
    let mut tris: Vec<[Vec3; 3]> = Vec::new();
    tris.extend(quad(
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(-4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, -4.0),
    ));
    tris.extend(quad(
        Vec3::new(-1.0 + shift, 1.0, -1.0),
        Vec3::new(-1.0 + shift, 1.0, 1.0),
        Vec3::new(1.0 + shift, 1.0, 1.0),
        Vec3::new(1.0 + shift, 1.0, -1.0),
    ));
    for i in 0..cells {
        for j in 0..cells {
            let (x, z) = (
                0.5 + pitch * f32::from(i) - shift,
                -1.5 + pitch * f32::from(j),
            );
            tris.extend(quad(
                Vec3::new(x, 2.0, z),
                Vec3::new(x, 2.0, z + side),
                Vec3::new(x + side, 2.0, z + side),
                Vec3::new(x + side, 2.0, z),
            ));
        }
    }
    tris
}

/// The surface point of [`floor_occluder_grid`]'s floor at `(x, z)`.
fn floor_point(scene: &TriScene, x: f32, z: f32) -> rendiff::shade::SurfacePoint {
    use rendiff::math::Bary;
    let (tri, b) = if z >= x {
        (0, Bary([(4.0 - z) / 8.0, (z - x) / 8.0, (x + 4.0) / 8.0]))
    } else {
        (1, Bary([(4.0 - x) / 8.0, (z + 4.0) / 8.0, (x - z) / 8.0]))
    };
    scene.surface_at(tri, b)
}

/// The shadow cache of `transmittance_packets` (the triangle that stopped
/// a row's latest stopped ray, tried first and kept from call to call)
/// answers every query as the single-ray walk does: rows of floor samples
/// under a large occluder and a grid of small ones, toward two point
/// lights (one in the large occluder's plane, which that occluder does not
/// shadow) and along a parallel direction with segments that alternately
/// end before and beyond the occluders; passed in runs of 1 to 20 queries,
/// lights mixed within some runs, on one `ShadowRays` for the whole frame;
/// and rays straight up along the grid's edges, which lie in the planes
/// its boxes end on (the walk must reach what the cache's test meets).
#[test]
fn the_shadow_cache_answers_as_the_walk() {
    use rendiff::accel::ShadowRays;
    use rendiff::color::Rgb;
    use rendiff::shade::{Light, LightKind, ShadowQuery};
    // The floor (triangles 0 and 1), the large occluder at y = 1 (2, 3),
    // a 12 × 12 grid of small quads at y = 2 with gaps between them.
    let tris = floor_occluder_grid(0.0, 12, 0.25, 0.2);
    let mut scene = TriScene::from_triangles(camera(), &tris);
    for position in [Vec3::new(0.3, 5.0, 0.2), Vec3::new(-2.5, 1.0, 0.5)] {
        scene.lights.push(Light {
            kind: LightKind::Point { position },
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
    }
    let accel = Accel::new(&scene, AccelOptions::default());
    let rays = ShadowRays::new(&accel);
    let parallel = Vec3::new(0.15, 1.0, 0.1).normalize();
    let mut rows: Vec<ShadowQuery> = Vec::new();
    for zi in 0..40 {
        let z = -3.0 + 0.15 * zi as f32;
        for light in [0usize, 1, 7] {
            for xi in 0..64 {
                let x = -3.5 + 0.11 * xi as f32;
                let origin = Vec3::new(x, 1e-4, z);
                let leaves = u32::from(x + z > 0.0);
                let (dir, t_max) = match scene.lights.get(light).map(|l| l.kind) {
                    Some(LightKind::Point { position }) => (
                        (position - origin).normalize(),
                        (position - origin).length(),
                    ),
                    // No such light: the query's own direction and end,
                    // alternately short of the occluders and past them.
                    _ => (parallel, if xi % 2 == 0 { 0.9 } else { 5.0 }),
                };
                rows.push(ShadowQuery {
                    light,
                    origin,
                    dir,
                    t_max,
                    normal: Vec3::Y,
                    leaves,
                });
            }
        }
    }
    // Rays straight up through each quad of the grid: a few through the
    // inside of one of its triangles, then one along that triangle's edge
    // on the quad's side, in the plane a box may end on, with the zero
    // component's sign pointing out of it (the walk must reach what the
    // cache's test meets there).
    let up = |x: f32, z: f32, sx: f32| ShadowQuery {
        light: 7,
        origin: Vec3::new(x, 1.5, z),
        dir: Vec3::new(sx * 0.0, 1.0, 0.0),
        t_max: 10.0,
        normal: Vec3::Y,
        leaves: u32::MAX,
    };
    for i in 0..12 {
        for j in 0..12 {
            let (x0, z0) = (0.5 + 0.25 * i as f32, -1.5 + 0.25 * j as f32);
            for k in 0..6 {
                rows.push(up(x0 + 0.02, z0 + 0.08 + 0.015 * k as f32, 1.0));
            }
            rows.push(up(x0, z0 + 0.1, -1.0));
            for k in 0..6 {
                rows.push(up(x0 + 0.18, z0 + 0.04 + 0.015 * k as f32, 1.0));
            }
            rows.push(up(x0 + 0.2, z0 + 0.1, 1.0));
        }
    }
    // Some runs mix the lights: queries swapped with the next light's.
    let mut rng = crate::util::Rng(0x0cc1_0de5);
    let n = rows.len();
    for _ in 0..300 {
        // The same sample of the next light's row.
        let a = rng.below(n as u64) as usize;
        rows.swap(a, (a + 64).min(n - 1));
    }
    let mut start = 0;
    let (mut blocked, mut answers) = (0, 0);
    while start < rows.len() {
        let end = (start + 1 + rng.below(20) as usize).min(rows.len());
        let run = &rows[start..end];
        let mut got = vec![Rgb::WHITE; run.len()];
        rays.transmittance_packets(run, &mut got);
        for (q, g) in run.iter().zip(&got) {
            let want = rays.transmittance(q);
            assert_eq!(*g, want, "query {q:?}");
            blocked += usize::from(want == Rgb::BLACK);
            answers += 1;
        }
        start = end;
    }
    // Both answers are common, so runs fill, use and clear the cache.
    assert!(
        blocked > answers / 10 && blocked < answers * 9 / 10,
        "{blocked} of {answers}"
    );
}

// ---- Build invariance -------------------------------------------------------

/// Every bundled and hazard scene, ray traced through a BVH built by the
/// SAH and through one built in Morton order, gives the same frame bit for
/// bit (colour, depth, triangle id, flags): the grouping of a tree changes
/// how fast rays walk it, never what they meet. (The rasterizer's shadow
/// rays go through the tree its rule picks: `dense.toml`'s in Morton
/// order, held to its regression golden.)
#[test]
fn every_bvh_build_renders_every_scene_bit_for_bit() {
    use rendiff::accel::BvhBuild;
    for (path, job) in every_scene_small() {
        let frame = |build| {
            let accel = Accel::new(
                &job.tri,
                AccelOptions {
                    geometry: job.settings.geometry,
                    bvh: true,
                    build,
                    ..AccelOptions::default()
                },
            );
            ray_frame(&job, &accel)
        };
        assert!(
            frame(BvhBuild::Sah) == frame(BvhBuild::Morton),
            "{}: the builds' frames differ",
            path.display()
        );
    }
}

/// The rule that picks the build: Morton order below four rays per
/// triangle, the SAH at and above it; the plan applies it to the ray
/// tracer's primary and shadow rays, and the rasterizer to its shadow rays
/// once it has counted the visible samples (`scenes/dense.toml`: 42 638
/// visible samples and one light against 50 099 triangles).
#[test]
fn the_build_follows_the_rays_per_triangle() {
    use rendiff::accel::BvhBuild;
    assert_eq!(BvhBuild::for_rays(0, 1), BvhBuild::Morton);
    assert_eq!(BvhBuild::for_rays(399, 100), BvhBuild::Morton);
    assert_eq!(BvhBuild::for_rays(400, 100), BvhBuild::Sah);
    assert_eq!(BvhBuild::for_rays(u64::MAX, usize::MAX), BvhBuild::Sah);
    // 320×240 at 2×2 samples and one shadow-casting light: 614 400 rays.
    let dense = load("dense", &Overrides::default());
    assert_eq!(dense.plan.bvh_build, BvhBuild::Sah);
    // The same scene at 64×48: 24 576 rays for 50 099 triangles.
    let small = load(
        "dense",
        &Overrides {
            size: Some((64, 48)),
            ..Overrides::default()
        },
    );
    assert_eq!(small.plan.bvh_build, BvhBuild::Morton);
    assert!(
        small.plan.to_string().contains("Morton-order BVH       on"),
        "{}",
        small.plan
    );
}

// ---- Instruction-set invariance --------------------------------------------

/// Every bundled and hazard scene, ray traced with the ray queries on the
/// baseline instruction set (SSE2) and on the best one this processor has
/// (AVX2 where present, chosen at run time), gives the same frame bit for
/// bit: colour, depth, triangle id and flags of every sample. On a
/// processor without AVX2 both are the baseline and the test says so.
#[test]
fn every_simd_path_renders_every_scene_bit_for_bit() {
    use rendiff::accel::SimdPath;
    let mut names = std::collections::BTreeSet::new();
    for (path, job) in every_scene_small() {
        let mut frame = |simd| {
            let accel = Accel::new(
                &job.tri,
                AccelOptions {
                    geometry: job.settings.geometry,
                    bvh: job.plan.bvh,
                    simd,
                    ..AccelOptions::default()
                },
            );
            names.insert(accel.simd());
            ray_frame(&job, &accel)
        };
        let base = frame(SimdPath::Baseline);
        let auto = frame(SimdPath::Auto);
        assert!(
            base == auto,
            "{}: the instruction sets' frames differ",
            path.display()
        );
    }
    assert!(names.contains("baseline"));
    if std::is_x86_feature_detected!("avx2") {
        assert!(
            names.contains("x86-64-v3"),
            "AVX2 is present but was not used: {names:?}"
        );
    } else {
        eprintln!("no AVX2 here: only the baseline path was run");
    }
}

// ---- The light buffer ---------------------------------------------------------

/// The light buffer's answers are the walk's, bit for bit
/// (`Accel::new` with `shadow_rays_per_light` high enough builds one per
/// light): on scenes of boxes, a floor, a sloped sheet of small triangles
/// and long thin ones, with point lights above them, among them, just
/// off a triangle (nearer than the buffer's `η·S`, so tested on every
/// ray), in a wall's plane, far away, and parallel lights (the queries'
/// direction the light's own, or a different one, which the buffer must
/// leave to the walk); from origins on the surfaces (nudged off as
/// shading does, leaving their triangle), anywhere in and around the
/// scene, on the cube faces' diagonals from the light (where a ray's face
/// is a tie), and exactly below a triangle's corner; with every caster
/// opaque, and with every third triangle transparent (then the answer is
/// the product of the crossings, which the cell's list must hold all of).
#[test]
fn the_light_buffer_answers_as_the_walk() {
    use rendiff::color::Rgb;
    use rendiff::shade::{Light, LightKind, ShadowQuery};
    let mut rng = crate::util::Rng(0x11_6b7b_0ff3);
    let quad = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| [[a, b, c], [a, c, d]];
    let cube = |lo: Vec3, hi: Vec3| {
        let p = |x: bool, y: bool, z: bool| {
            Vec3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            )
        };
        let mut t = Vec::new();
        for (a, b, c, d) in [
            (
                p(false, false, false),
                p(false, true, false),
                p(true, true, false),
                p(true, false, false),
            ),
            (
                p(false, false, true),
                p(true, false, true),
                p(true, true, true),
                p(false, true, true),
            ),
            (
                p(false, false, false),
                p(false, false, true),
                p(false, true, true),
                p(false, true, false),
            ),
            (
                p(true, false, false),
                p(true, true, false),
                p(true, true, true),
                p(true, false, true),
            ),
            (
                p(false, true, false),
                p(false, true, true),
                p(true, true, true),
                p(true, true, false),
            ),
            (
                p(false, false, false),
                p(true, false, false),
                p(true, false, true),
                p(false, false, true),
            ),
        ] {
            t.extend(quad(a, b, c, d));
        }
        t
    };
    let mut tris: Vec<[Vec3; 3]> = Vec::new();
    tris.extend(quad(
        Vec3::new(-6.0, 0.0, -6.0),
        Vec3::new(-6.0, 0.0, 6.0),
        Vec3::new(6.0, 0.0, 6.0),
        Vec3::new(6.0, 0.0, -6.0),
    ));
    for k in 0..6 {
        let x = -3.0 + 1.1 * k as f32;
        let z = -2.0 + 0.7 * (k % 3) as f32;
        tris.extend(cube(
            Vec3::new(x, 0.0, z),
            Vec3::new(x + 0.5, 0.4 + 0.3 * k as f32, z + 0.6),
        ));
    }
    // A sloped sheet of small triangles (a crowded region of the buffer).
    for i in 0..24 {
        for j in 0..24 {
            let (x, z) = (-2.0 + 0.125 * i as f32, 2.0 + 0.125 * j as f32);
            let y = |x: f32, z: f32| 1.0 + 0.3 * x + 0.2 * z;
            tris.extend(quad(
                Vec3::new(x, y(x, z), z),
                Vec3::new(x, y(x, z + 0.1), z + 0.1),
                Vec3::new(x + 0.1, y(x + 0.1, z + 0.1), z + 0.1),
                Vec3::new(x + 0.1, y(x + 0.1, z), z),
            ));
        }
    }
    // Long thin triangles, and a wall at x = 5.
    for k in 0..8 {
        let z = -4.0 + k as f32;
        tris.push([
            Vec3::new(-5.0, 0.5 + 0.1 * k as f32, z),
            Vec3::new(5.0, 0.6, z + 0.01),
            Vec3::new(5.0, 0.6 + 0.002 * k as f32, z + 0.02),
        ]);
    }
    tris.extend(quad(
        Vec3::new(5.0, 0.0, -5.0),
        Vec3::new(5.0, 3.0, -5.0),
        Vec3::new(5.0, 3.0, 5.0),
        Vec3::new(5.0, 0.0, 5.0),
    ));
    let n_tris = tris.len();
    let mut scene = TriScene::from_triangles(camera(), &tris);
    let point = |position| Light {
        kind: LightKind::Point { position },
        color: Rgb::WHITE,
        shadowless: false,
        fade: None,
    };
    let points = [
        Vec3::new(0.5, 6.0, 0.3),
        Vec3::new(-1.0, 1.2, 0.1),
        // 10⁻⁵ above a box's top, and 10⁻¹² and 10⁻³⁰ above the floor
        // (nearer than η·S: tested on every ray).
        Vec3::new(-2.8, 0.4 + 1e-5, -1.7),
        Vec3::new(1.3, 1e-12, -4.1),
        Vec3::new(-4.5, 1e-30, 4.2),
        // In the wall's plane.
        Vec3::new(5.0, 2.0, 0.0),
        // Far away.
        Vec3::new(3e4, 2e4, -1e4),
        // On a box's corner's diagonals (ties between cube faces).
        Vec3::new(-1.9, 1.0, -1.3),
    ];
    for p in points {
        scene.lights.push(point(p));
    }
    let parallel = Vec3::new(-0.3, -1.0, 0.2).normalize();
    scene.lights.push(Light {
        kind: LightKind::Parallel {
            direction: parallel,
        },
        color: Rgb::WHITE,
        shadowless: false,
        fade: None,
    });
    let n_lights = scene.lights.len();
    let query = |light: usize, origin: Vec3, leaves: u32| {
        let (dir, t_max) = match scene.lights[light].kind {
            LightKind::Point { position } => {
                let v = position - origin;
                (v / v.length(), v.length())
            }
            LightKind::Parallel { direction } => (-direction, f32::INFINITY),
        };
        ShadowQuery {
            light,
            origin,
            dir,
            t_max,
            normal: Vec3::Y,
            leaves,
        }
    };
    let mut queries = Vec::new();
    for light in 0..n_lights {
        // Origins on the surfaces, nudged off toward the light.
        for _ in 0..3000 {
            let t = rng.below(n_tris as u64) as usize;
            let [a, b, c] = tris[t];
            let (u, v) = (rng.rangef(0.0, 1.0), rng.rangef(0.0, 1.0));
            let (u, v) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            let p = a + (b - a) * u + (c - a) * v;
            let n = (b - a).cross(c - a).normalize_or_zero();
            let q0 = query(light, p, t as u32);
            let side = if n.dot(q0.dir) >= 0.0 { 1.0 } else { -1.0 };
            let off = [0.0, 1e-6, 1e-4][rng.below(3) as usize];
            queries.push(query(light, p + n * side * off, t as u32));
        }
        // Anywhere in and around the scene.
        for _ in 0..1500 {
            let p = Vec3::new(
                rng.rangef(-7.0, 7.0),
                rng.rangef(-1.0, 4.0),
                rng.rangef(-7.0, 7.0),
            );
            queries.push(query(light, p, u32::MAX));
        }
        // Below corners, and on the diagonals of the light's cube.
        if let LightKind::Point { position } = scene.lights[light].kind {
            for _ in 0..300 {
                let s = rng.rangef(0.05, 6.0);
                let (sx, sz) = (
                    if rng.below(2) == 0 { -1.0 } else { 1.0 },
                    if rng.below(2) == 0 { -1.0 } else { 1.0 },
                );
                queries.push(query(
                    light,
                    position - Vec3::new(sx * s, s, sz * s),
                    u32::MAX,
                ));
                queries.push(query(light, position - Vec3::new(sx * s, s, 0.0), u32::MAX));
            }
        }
        for tri in &tris {
            for corner in tri {
                queries.push(query(light, *corner - Vec3::new(0.0, 0.25, 0.0), u32::MAX));
            }
        }
    }
    // The parallel light's queries along another direction: walked.
    for _ in 0..200 {
        let p = Vec3::new(rng.rangef(-5.0, 5.0), 0.01, rng.rangef(-5.0, 5.0));
        let mut q = query(n_lights - 1, p, 0);
        q.dir = Vec3::new(0.3, 1.0, 0.0).normalize();
        queries.push(q);
    }
    // Opaque casters only (answered in packets), then with every third
    // triangle transparent (answered one by one, the crossings' product).
    for transparent in [false, true] {
        let mut scene = scene.clone();
        if transparent {
            scene.materials.push(rendiff::shade::Material {
                filter: 0.3,
                transmit: 0.4,
                pigment: rendiff::shade::Pigment::Color(Rgb::new(0.9, 0.5, 0.2)),
                ..rendiff::shade::Material::default()
            });
            for (t, m) in scene.tri_material.iter_mut().enumerate() {
                if t % 3 == 0 {
                    *m = 1;
                }
            }
        }
        let (buffered, walked) = buffered_and_walked(&scene);
        // Every light keeps its buffer (none is crowded enough to be
        // dropped), so the answers below are the buffers'.
        assert!(
            (0..n_lights).all(|l| buffered.has_light_buffer(l)),
            "a light lost its buffer: this test would compare the walk with itself"
        );
        let (fast, slow) = (ShadowRays::new(&buffered), ShadowRays::new(&walked));
        let (mut blocked, mut lit, mut between) = (0usize, 0usize, 0usize);
        for run in queries.chunks(13) {
            let mut got = vec![Rgb::WHITE; run.len()];
            let mut want = vec![Rgb::WHITE; run.len()];
            fast.transmittance_packets(run, &mut got);
            slow.transmittance_packets(run, &mut want);
            for ((q, g), w) in run.iter().zip(&got).zip(&want) {
                assert_eq!(g, w, "query {q:?}");
                assert_eq!(*w, slow.transmittance(q), "query {q:?}");
                if *w == Rgb::BLACK {
                    blocked += 1;
                } else if *w == Rgb::WHITE {
                    lit += 1;
                } else {
                    between += 1;
                }
            }
        }
        assert!(blocked > 3000 && lit > 3000, "{blocked} blocked, {lit} lit");
        assert_eq!(
            between > 3000,
            transparent,
            "{between} through transparent triangles"
        );
    }
}

/// The plan says where the ray tracer builds light buffers: at 8 or more
/// camera samples per casting triangle (`painter_floor`: 76 800 for 50),
/// not below (`dense`: 307 200 for 50 099), and not without shadow rays.
#[test]
fn the_plan_shows_the_light_buffer_rule() {
    use rendiff::options::light_buffer_pays;
    assert!(light_buffer_pays(400, 50));
    assert!(!light_buffer_pays(399, 50));
    assert!(!light_buffer_pays(0, 0));
    assert!(!light_buffer_pays(u64::MAX - 1, u64::MAX));
    let line = |name: &str| {
        let job = load(name, &Overrides::default());
        job.plan
            .to_string()
            .lines()
            .find(|l| l.contains("light buffer"))
            .map(str::to_string)
            .unwrap_or_default()
    };
    assert!(
        line("painter_floor").contains(
            "light buffer           on   76800 camera samples per light for 50 casting triangles"
        ),
        "{}",
        line("painter_floor")
    );
    assert!(
        line("dense")
            .contains("light buffer           off  307200 camera samples per light for 50099"),
        "{}",
        line("dense")
    );
}

/// A point light over a stack of sheets deeper than a cell's list keeps
/// no light buffer (its rays would land in crowded cells and walk anyway,
/// with a lookup added: `many_lights`), and over two sheets it keeps one;
/// either way the answers are the walk's.
#[test]
fn a_light_over_a_deep_stack_keeps_no_buffer() {
    use rendiff::color::Rgb;
    use rendiff::shade::{Light, LightKind, ShadowQuery};
    let quad = |y: f32, h: f32| {
        let (a, b, c, d) = (
            Vec3::new(-h, y, -h),
            Vec3::new(-h, y, h),
            Vec3::new(h, y, h),
            Vec3::new(h, y, -h),
        );
        [[a, b, c], [a, c, d]]
    };
    let light = Vec3::new(0.0, 5.0, 0.0);
    for (sheets, kept) in [(12, false), (2, true)] {
        // Seen from the light (one cube face), the floor spans ±0.6 of
        // the face and each sheet ±0.45: more than half of the grid's
        // cells list the floor and every sheet (crowded), the rest the
        // floor alone.
        let mut tris: Vec<[Vec3; 3]> = quad(0.0, 3.0).to_vec();
        for k in 0..sheets {
            let y = 0.5 + 0.25 * k as f32;
            tris.extend(quad(y, 0.45 * (5.0 - y)));
        }
        let mut scene = TriScene::from_triangles(camera(), &tris);
        scene.lights.push(Light {
            kind: LightKind::Point { position: light },
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
        let (buffered, walked) = buffered_and_walked(&scene);
        assert_eq!(buffered.has_light_buffer(0), kept, "{sheets} sheets");
        assert!(!walked.has_light_buffer(0), "no buffer without the rays");
        let (fast, slow) = (ShadowRays::new(&buffered), ShadowRays::new(&walked));
        let queries: Vec<ShadowQuery> = (0..64)
            .map(|i| {
                let origin = Vec3::new(-2.9 + 0.09 * i as f32, 0.0, 2.9 - 0.09 * i as f32);
                let v = light - origin;
                ShadowQuery {
                    light: 0,
                    origin,
                    dir: v / v.length(),
                    t_max: v.length(),
                    normal: Vec3::Y,
                    leaves: 0,
                }
            })
            .collect();
        let mut a = vec![Rgb::BLACK; queries.len()];
        let mut b = vec![Rgb::BLACK; queries.len()];
        fast.transmittance_packets(&queries, &mut a);
        slow.transmittance_packets(&queries, &mut b);
        assert_eq!(a, b, "{sheets} sheets");
        // The floor under the sheets is in their shadow.
        assert_eq!(a[32], Rgb::BLACK, "{sheets} sheets");
    }
}

/// The structures of `scene` with a light buffer for every light (as
/// many rays as asked for) and without any.
fn buffered_and_walked(scene: &TriScene) -> (Accel<'_>, Accel<'_>) {
    let buffered = Accel::new(
        scene,
        AccelOptions {
            shadow_rays_per_light: u64::MAX,
            ..AccelOptions::default()
        },
    );
    (buffered, Accel::new(scene, AccelOptions::default()))
}

/// Every bundled and hazard scene, ray traced with light buffers and
/// without, gives the same frame bit for bit.
#[test]
fn the_light_buffer_renders_every_scene_bit_for_bit() {
    for (path, job) in every_scene_small() {
        let frame = |shadow_rays_per_light| {
            let accel = Accel::new(
                &job.tri,
                AccelOptions {
                    geometry: job.settings.geometry,
                    shadow_rays_per_light,
                    ..AccelOptions::default()
                },
            );
            ray_frame(&job, &accel)
        };
        assert!(
            frame(0) == frame(u64::MAX),
            "{}: the frames with and without light buffers differ",
            path.display()
        );
    }
}

/// A library caller's scene with a NaN or infinite corner does not make
/// the light buffer's build panic (point and parallel lights), and its
/// answers stay the walk's.
#[test]
fn the_light_buffer_survives_non_finite_corners() {
    use rendiff::color::Rgb;
    use rendiff::shade::{Light, LightKind, ShadowQuery};
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let tris = vec![
            [
                Vec3::new(-2.0, 0.0, -2.0),
                Vec3::new(-2.0, 0.0, 2.0),
                Vec3::new(2.0, 0.0, 2.0),
            ],
            [
                Vec3::new(-0.5, 1.0, -0.5),
                Vec3::new(-0.5, 1.0, 0.5),
                Vec3::new(0.5, 1.0, 0.5),
            ],
            [
                Vec3::new(0.0, 0.5, 0.0),
                Vec3::new(bad, 0.5, 1.0),
                Vec3::new(1.0, bad, 0.0),
            ],
        ];
        let mut scene = TriScene::from_triangles(camera(), &tris);
        scene.lights.push(Light {
            kind: LightKind::Point {
                position: Vec3::new(0.1, 3.0, 0.2),
            },
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
        let parallel = Vec3::new(-0.2, -1.0, 0.1).normalize();
        scene.lights.push(Light {
            kind: LightKind::Parallel {
                direction: parallel,
            },
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
        let (buffered, walked) = buffered_and_walked(&scene);
        let (fast, slow) = (ShadowRays::new(&buffered), ShadowRays::new(&walked));
        let queries: Vec<ShadowQuery> = (0..128)
            .map(|k| {
                let origin = Vec3::new(-1.5 + 0.05 * (k % 64) as f32, 1e-4, 0.3);
                let v = Vec3::new(0.1, 3.0, 0.2) - origin;
                let (light, dir, t_max) = if k < 64 {
                    (0, v / v.length(), v.length())
                } else {
                    (1, -parallel, f32::INFINITY)
                };
                ShadowQuery {
                    light,
                    origin,
                    dir,
                    t_max,
                    normal: Vec3::Y,
                    leaves: 0,
                }
            })
            .collect();
        let mut got = vec![Rgb::WHITE; queries.len()];
        let mut want = vec![Rgb::WHITE; queries.len()];
        fast.transmittance_packets(&queries, &mut got);
        slow.transmittance_packets(&queries, &mut want);
        assert_eq!(got, want, "corner {bad}");
    }
}

/// Barycentric weights of `p` in the triangle `v` (in its plane).
fn weights_in(v: [DVec3; 3], p: DVec3) -> [f64; 3] {
    let n = (v[1] - v[0]).cross(v[2] - v[0]);
    let area = n.length_squared();
    let a = (v[2] - v[1]).cross(p - v[1]).dot(n) / area;
    let b = (v[0] - v[2]).cross(p - v[2]).dot(n) / area;
    [a, b, 1.0 - a - b]
}

/// A query answered as it is added (`ShadowBatch::add_with`: the shadow
/// cache's triangle certainly stops it) gets the walk's answer. Each case
/// is an occluder and a large receiver through a point on the line from
/// the light through a corner of the occluder, a point on one of its
/// edges or inside it, before or behind it; scales from 10⁻³ to 10³, far
/// from the origin or near it; lights from 10⁻⁹ to 10³ of the occluder's
/// size off its plane. Before each sample, a batch of one sample on a
/// small triangle behind the occluder's centre puts the occluder in the
/// cache (and has its certifier made); then each sample,
/// nudged off the point by 10⁻¹³ to 10⁻¹ of the scale (across the
/// shadow's edges and the occluder's plane), with and without an error
/// bound on its position, is a batch of its own: its answer, certified or
/// traced, must be the single-ray walk's. Nearly every query well inside
/// the shadow must be certified.
#[test]
fn queries_answered_as_added_are_the_walks() {
    use rendiff::accel::ShadowBatch;
    use rendiff::color::Rgb;
    use rendiff::math::Bary;
    use rendiff::shade::{Light, LightKind, ShadowQuery};
    let mut rng = Rng(0x0000_ddc0_ffee_5eed);
    let (mut certified, mut inside, mut inside_certified) = (0usize, 0usize, 0usize);
    for case in 0..3000usize {
        let scale = 10f64.powf(rng.range(-3.0, 3.0));
        let center = random_dir(&mut rng).as_dvec3() * scale * rng.range(0.0, 40.0);
        let t: [DVec3; 3] = std::array::from_fn(|_| {
            to_f64(to_f32(center + random_dir(&mut rng).as_dvec3() * scale))
        });
        let Some(n) = (t[1] - t[0]).cross(t[2] - t[0]).try_normalize() else {
            continue;
        };
        let mid = (t[0] + t[1] + t[2]) / 3.0;
        let height = scale * 10f64.powf(rng.range(-9.0, 3.0));
        let light = to_f32(
            mid + n * height + random_dir(&mut rng).as_dvec3() * scale * rng.range(0.0, 3.0),
        );
        let l = to_f64(light);
        // A point of the occluder: a corner, on an edge, or inside.
        let w: [f64; 3] = match case % 3 {
            0 => {
                let mut w = [0.0; 3];
                w[case / 3 % 3] = 1.0;
                w
            }
            1 => {
                let a = rng.f64();
                let mut w = [a, 1.0 - a, 0.0];
                w.rotate_left(case / 3 % 3);
                w
            }
            _ => {
                let w = [rng.f64(), rng.f64(), rng.f64()];
                let s = w[0] + w[1] + w[2];
                w.map(|x| x / s)
            }
        };
        let x = t[0] * w[0] + t[1] * w[1] + t[2] * w[2];
        // Behind the occluder (or, one case in four, before it).
        let along = if case % 4 == 3 {
            rng.range(0.2, 1.0)
        } else {
            rng.range(1.0, 4.0)
        };
        let p0 = l + (x - l) * along;
        let rn = random_dir(&mut rng).as_dvec3();
        let u = rn.any_orthonormal_vector();
        let v = rn.cross(u);
        let big = scale * 100.0;
        let r = [
            p0 + u * big,
            p0 - u * big * 0.5 + v * big,
            p0 - u * big * 0.5 - v * big,
        ]
        .map(to_f32);
        let rd = r.map(to_f64);
        // A small triangle behind the occluder, across the line from the
        // light through its centre: where the priming sample lies.
        let axis = (mid - l).normalize();
        let (qa, qb) = (
            axis.any_orthonormal_vector(),
            axis.cross(axis.any_orthonormal_vector()),
        );
        let qc = l + (mid - l) * 2.0;
        let q = [
            qc + qa * scale,
            qc - qa * scale * 0.5 + qb * scale,
            qc - qa * scale * 0.5 - qb * scale,
        ]
        .map(to_f32);
        let mut scene = TriScene::from_triangles(camera(), &[r, t.map(to_f32), q]);
        scene.lights.push(Light {
            kind: LightKind::Point { position: light },
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
        let accel = Accel::new(&scene, AccelOptions::default());
        let rays = ShadowRays::new(&accel);
        let ctx = scene.shade_context(0.0, true);
        let at = |p: DVec3| {
            let b = weights_in(rd, p).map(|x| x as f32);
            scene.surface_at(0, Bary(b))
        };
        let prime = scene.surface_at(2, Bary([1.0 / 3.0; 3]));
        let mut batch = ShadowBatch::default();
        for k in 0..24 {
            // The occluder into the cache (and its certifier made).
            for d in [prime.ng, -prime.ng] {
                let _ = batch.add_with(&ctx, &prime, d, &rays);
            }
            batch.answer(&rays);
            batch.clear();
            let nudge = scale * 10f64.powf(rng.range(-13.0, -1.0));
            let p = p0 + (u * rng.range(-1.0, 1.0) + v * rng.range(-1.0, 1.0)) * nudge;
            let mut sp = at(p);
            if k % 2 == 1 {
                sp.p_error = Vec3::ZERO;
            }
            // Well inside the shadow: behind the occluder, the line from
            // the light more than a tenth of the occluder from its edges.
            let deep = case % 3 == 2
                && along > 1.5
                && w.iter().all(|&x| x > 0.1)
                && nudge < scale * 1e-3
                && height > scale * 0.1;
            for d in [sp.ng, -sp.ng] {
                let _ = batch.add_with(&ctx, &sp, d, &rays);
            }
            let answered_as_added = batch.answered_as_added();
            batch.answer(&rays);
            let mut queries: Vec<ShadowQuery> = Vec::new();
            for d in [sp.ng, -sp.ng] {
                let _ = rendiff::shade::shadow_queries(&ctx, &sp, d, |q| queries.push(q));
            }
            let mut answers = Vec::new();
            for k in 0..batch.len() {
                answers.extend(batch.answered(k, &rays).answers.iter().map(|a| a.1));
            }
            let walked: Vec<Rgb> = queries.iter().map(|q| rays.transmittance(q)).collect();
            assert_eq!(
                answers, walked,
                "case {case}, sample {k} ({answered_as_added} answered as added)"
            );
            certified += answered_as_added;
            if deep {
                inside += queries.len();
                inside_certified += answered_as_added;
            }
            batch.clear();
        }
    }
    assert!(certified > 12_000, "{certified} answered as added");
    assert!(
        inside_certified * 10 > inside * 9,
        "{inside_certified} of {inside} queries well inside the shadow answered as added"
    );
}

/// A batch filled by `add_with` answers every sample as one filled by
/// `add` does: the same answers in the same order, and the same count of
/// shadow rays cast. A floor under a large occluder (two triangles) and a
/// grid of small ones, toward a parallel light and two point lights (one
/// in the large occluder's plane, which it does not shadow), in batches
/// of 1 to 20 samples along rows (lit, shadowed and across shadows'
/// edges), on one `ShadowRays` each for the whole frame. (The parallel
/// light first: a sample's first query is formed before its second is
/// answered as added.) Many queries must be answered as they are added.
#[test]
fn batches_answer_alike_with_and_without_answers_as_added() {
    use rendiff::accel::ShadowBatch;
    use rendiff::color::Rgb;
    use rendiff::shade::{Light, LightKind};
    let tris = floor_occluder_grid(0.0, 12, 0.25, 0.2);
    let mut scene = TriScene::from_triangles(camera(), &tris);
    for kind in [
        LightKind::Parallel {
            direction: -Vec3::new(0.15, 1.0, 0.1).normalize(),
        },
        LightKind::Point {
            position: Vec3::new(0.3, 5.0, 0.2),
        },
        LightKind::Point {
            position: Vec3::new(-2.5, 1.0, 0.5),
        },
    ] {
        scene.lights.push(Light {
            kind,
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
    }
    let accel = Accel::new(&scene, AccelOptions::default());
    let (rays_a, rays_b) = (ShadowRays::new(&accel), ShadowRays::new(&accel));
    let ctx = scene.shade_context(0.0, true);
    let (mut with, mut plain) = (ShadowBatch::default(), ShadowBatch::default());
    let mut rng = Rng(0x00ba_7c4e_5a11_7e57);
    let (mut certified, mut queries, mut blocked) = (0usize, 0usize, 0usize);
    let down = Vec3::new(0.05, -1.0, 0.02).normalize();
    for zi in 0..48 {
        let z = -2.5 + 0.104 * zi as f32;
        let mut xi = 0;
        while xi < 96 {
            let n = 1 + rng.below(20) as usize;
            for _ in 0..n.min(96 - xi) {
                let x = -2.0 + 0.057 * xi as f32;
                let sp = floor_point(&scene, x, z);
                let na = with.add_with(&ctx, &sp, down, &rays_a);
                let nb = plain.add(&ctx, &sp, down);
                assert_eq!(
                    na.to_array().map(f32::to_bits),
                    nb.to_array().map(f32::to_bits)
                );
                xi += 1;
            }
            certified += with.answered_as_added();
            with.answer(&rays_a);
            plain.answer(&rays_b);
            assert_eq!(with.len(), plain.len());
            for k in 0..plain.len() {
                let (a, b) = (with.answered(k, &rays_a), plain.answered(k, &rays_b));
                assert_eq!(a.answers, b.answers, "row {zi}, sample {k}");
                queries += b.answers.len();
                blocked += b.answers.iter().filter(|t| t.1 == Rgb::BLACK).count();
            }
            with.clear();
            plain.clear();
        }
    }
    assert_eq!(rays_a.cast(), rays_b.cast());
    assert!(
        blocked > queries / 5 && blocked < queries * 4 / 5,
        "{blocked} of {queries} blocked"
    );
    assert!(
        certified * 8 > blocked,
        "{certified} of {blocked} blocked queries answered as added"
    );
}

/// A batch holds each query as `PendingQuery::form_segment` gives it
/// (the direction and distance from the surface point, not from the
/// offset origin: the tracer follows a point light's segment from the
/// origin to the light itself), and must answer it as the single-ray walk
/// answers the query `form` gives: the floor, a large occluder and a grid
/// of small ones; point lights above, 10⁻³⁰ and 10⁻⁹ above the floor,
/// in the occluder's plane and 10¹⁹ away, and one placed exactly at
/// the offset origin of a sample on a tilted triangle, with a blocker just
/// beyond it (there the segment is empty, the walk follows the query's own
/// direction and distance, and one that ran on would be black), and a
/// parallel light; samples on every triangle, seen from either side, in
/// batches of 1 to 20, with plain `add` and with `add_with`, through a
/// structure with light buffers and one without.
/// The two forms must agree bit for bit in all but a point light's
/// `dir` and `t_max`, and in those too where the origin is the light.
#[test]
fn segment_queries_answer_as_formed_ones() {
    use rendiff::accel::ShadowBatch;
    use rendiff::color::Rgb;
    use rendiff::math::Bary;
    use rendiff::shade::{Light, LightKind, ShadowQuery};
    let bits = |q: &ShadowQuery| {
        (
            q.light,
            q.origin.to_array().map(f32::to_bits),
            q.dir.to_array().map(f32::to_bits),
            q.t_max.to_bits(),
            q.normal.to_array().map(f32::to_bits),
            q.leaves,
        )
    };
    let mut tris = floor_occluder_grid(0.0, 6, 0.4, 0.3);
    // A tilted triangle, whose points' offset is not zero (the floor's
    // and the occluders' lie exactly in their planes).
    tris.push([
        Vec3::new(-3.5, 0.2, 3.0),
        Vec3::new(-2.0, 0.9, 3.5),
        Vec3::new(-2.8, 0.4, 2.2),
    ]);
    let tilted = (tris.len() - 1) as u32;
    let bary = Bary([0.31, 0.27, 0.42]);
    let mut scene = TriScene::from_triangles(camera(), &tris);
    let at = scene.surface_at(tilted, bary);
    // The offset origin of a sample on it toward a light along its
    // normal: a light placed there exactly.
    let mut origin = None;
    scene.lights.push(Light {
        kind: LightKind::Point {
            position: at.p + at.ng,
        },
        color: Rgb::WHITE,
        shadowless: false,
        fade: None,
    });
    let ctx = scene.shade_context(0.0, true);
    let _ = rendiff::shade::shadow_queries_pending(&ctx, &at, -at.ng, |p| {
        origin = Some(p.form().origin);
    });
    let origin = origin.expect("a query toward the light along the normal");
    // A blocker half a unit beyond that light, seen from the sample (the
    // origin's rounding, not the normal, sets the direction): a query
    // from the light itself that ran on past it would meet it.
    let l = (origin - at.p).normalize();
    let c = origin + 0.5 * l;
    let (u, v) = (
        l.any_orthonormal_vector(),
        l.cross(l.any_orthonormal_vector()),
    );
    tris.push([c - 0.2 * u - 0.2 * v, c + 0.3 * u, c + 0.3 * v]);
    let mut scene = TriScene::from_triangles(camera(), &tris);
    assert_eq!(scene.surface_at(tilted, bary), at);
    // The lights' indices: the one at the sample's origin, the parallel one.
    const AT_ORIGIN: usize = 5;
    const PARALLEL: usize = 6;
    for kind in [
        LightKind::Point {
            position: Vec3::new(0.3, 5.0, 0.2),
        },
        LightKind::Point {
            position: Vec3::new(-2.5, 1e-30, 0.5),
        },
        LightKind::Point {
            position: Vec3::new(2.2, 1e-9, -1.7),
        },
        LightKind::Point {
            position: Vec3::new(-3.0, 1.0, 0.4),
        },
        LightKind::Point {
            position: Vec3::new(4e18, 1e19, -3e18),
        },
        LightKind::Point { position: origin },
        LightKind::Parallel {
            direction: -Vec3::new(0.15, 1.0, 0.1).normalize(),
        },
    ] {
        scene.lights.push(Light {
            kind,
            color: Rgb::WHITE,
            shadowless: false,
            fade: None,
        });
    }
    // Batches through a structure with light buffers and one without;
    // the answers wanted are the walks' without.
    let (buffered, walked) = buffered_and_walked(&scene);
    let walks = ShadowRays::new(&walked);
    let ctx = scene.shade_context(0.0, true);
    let mut rng = Rng(0x5e97_e47f_0a11);
    let (mut with, mut plain) = (ShadowBatch::default(), ShadowBatch::default());
    let (mut queries, mut blocked, mut at_light) = (0usize, 0usize, 0usize);
    for round in 0..600 {
        let rays = ShadowRays::new(if round % 2 == 0 { &buffered } else { &walked });
        let n = 1 + rng.below(20) as usize;
        let mut samples = Vec::new();
        for _ in 0..n {
            let sp = match rng.below(4) {
                0 => at,
                1 => scene.surface_at(
                    rng.below(tris.len() as u64) as u32,
                    Bary({
                        let b = [
                            rng.rangef(0.0, 1.0),
                            rng.rangef(0.0, 1.0),
                            rng.rangef(0.0, 1.0),
                        ];
                        let s = b[0] + b[1] + b[2];
                        b.map(|x| x / s)
                    }),
                ),
                _ => floor_point(&scene, rng.rangef(-3.9, 3.9), rng.rangef(-3.9, 3.9)),
            };
            let d = match rng.below(8) {
                0 => sp.ng,
                _ => -sp.ng,
            };
            let _ = rendiff::shade::shadow_queries_pending(&ctx, &sp, d, |p| {
                let (formed, segment) = (p.form(), p.form_segment());
                let same_origin = formed.origin == origin && p.index == AT_ORIGIN;
                at_light += usize::from(same_origin);
                if p.index == PARALLEL || same_origin {
                    assert_eq!(bits(&formed), bits(&segment), "light {}", p.index);
                } else {
                    // All but `dir` and `t_max`.
                    let (f, s) = (bits(&formed), bits(&segment));
                    assert_eq!((f.0, f.1, f.4, f.5), (s.0, s.1, s.4, s.5));
                }
            });
            let _ = with.add_with(&ctx, &sp, d, &rays);
            let _ = plain.add(&ctx, &sp, d);
            samples.push((sp, d));
        }
        with.answer(&rays);
        plain.answer(&rays);
        let mut formed: Vec<ShadowQuery> = Vec::new();
        for (sp, d) in &samples {
            let _ = rendiff::shade::shadow_queries(&ctx, sp, *d, |q| formed.push(q));
        }
        let want: Vec<Rgb> = formed.iter().map(|q| walks.transmittance(q)).collect();
        for batch in [&with, &plain] {
            let mut got = Vec::new();
            for k in 0..batch.len() {
                got.extend(batch.answered(k, &rays).answers.iter().map(|a| a.1));
            }
            assert_eq!(got, want, "round {round}");
        }
        queries += want.len();
        blocked += want.iter().filter(|&&t| t == Rgb::BLACK).count();
        with.clear();
        plain.clear();
    }
    assert!(
        blocked * 10 > queries && blocked * 10 < queries * 9,
        "{blocked} of {queries} blocked"
    );
    assert!(at_light > 100, "{at_light} queries from the light itself");
}

/// A batch primed with `primes` (answered three times, so that the cache
/// holds its stopper and a certifier is made), then `tests` added with
/// `add_with`: their answers, and the single-ray walk's for the same
/// queries.
fn answers_as_added_and_walked(
    scene: &TriScene,
    primes: &[(rendiff::shade::SurfacePoint, Vec3)],
    tests: &[(rendiff::shade::SurfacePoint, Vec3)],
) -> (Vec<rendiff::color::Rgb>, Vec<rendiff::color::Rgb>) {
    use rendiff::accel::ShadowBatch;
    use rendiff::shade::ShadowQuery;
    let accel = Accel::new(scene, AccelOptions::default());
    let rays = ShadowRays::new(&accel);
    let ctx = scene.shade_context(0.0, true);
    let mut batch = ShadowBatch::default();
    for _ in 0..3 {
        for (sp, d) in primes {
            let _ = batch.add_with(&ctx, sp, *d, &rays);
        }
        batch.answer(&rays);
        batch.clear();
    }
    for (sp, d) in tests {
        let _ = batch.add_with(&ctx, sp, *d, &rays);
    }
    batch.answer(&rays);
    let mut with = Vec::new();
    for k in 0..batch.len() {
        with.extend(batch.answered(k, &rays).answers.iter().map(|a| a.1));
    }
    let mut queries: Vec<ShadowQuery> = Vec::new();
    for (sp, d) in tests {
        let _ = rendiff::shade::shadow_queries(&ctx, sp, *d, |q| queries.push(q));
    }
    (
        with,
        queries.iter().map(|q| rays.transmittance(q)).collect(),
    )
}

/// The review's case against the first form of the certifier: slivers
/// (aspect 10⁻⁷ to 10⁻⁶, no edge short) over a floor point at the origin
/// itself, where the ray's hit lies within the `f64` test's `δt` (which
/// grows as `1/det`): the test rejects it, and the first form, bounding
/// `δt` by `10⁻⁹·S`, answered black. Every answer must be the walk's.
#[test]
fn slivers_hit_within_their_delta_t_are_not_answered_as_added() {
    use rendiff::math::Bary;
    use rendiff::shade::{Light, LightKind};
    let (mut lit, mut cases) = (0, 0);
    for k in 3..8 {
        let a = 2f32.powi(-k);
        for w in [2e-6f32, 1e-6, 5e-7, 2e-7, 1e-7] {
            let e = 2f32.powi(-23);
            let sliver = [
                Vec3::new(-a, -a, -w / 2.0),
                Vec3::new(1.0, 1.0 + e, -w / 2.0),
                Vec3::new(0.0, 0.0, w / 2.0),
            ];
            let floor = [
                Vec3::new(-4.0, 0.0, -4.0),
                Vec3::new(-4.0, 0.0, 4.0),
                Vec3::new(4.0, 0.0, 0.0),
            ];
            let mut scene = TriScene::from_triangles(camera(), &[floor, sliver]);
            scene.lights.push(Light {
                kind: LightKind::Point {
                    position: Vec3::new(0.0, 1.0, 0.0),
                },
                color: rendiff::color::Rgb::WHITE,
                shadowless: false,
                fade: None,
            });
            let test = scene.surface_at(0, Bary([0.25, 0.25, 0.5]));
            let prime = scene.surface_at(0, Bary([0.218_75, 0.218_75, 0.5625]));
            let (with, walked) =
                answers_as_added_and_walked(&scene, &[(prime, -Vec3::Y)], &[(test, -Vec3::Y)]);
            assert_eq!(with, walked, "a = 2^-{k}, w = {w:e}");
            cases += 1;
            lit += walked
                .iter()
                .filter(|&&t| t == rendiff::color::Rgb::WHITE)
                .count();
        }
    }
    // The hazard is there: the walk finds most of these rays lit.
    assert!(lit * 3 > cases, "{lit} of {cases} lit");
}

/// One `ShadowBatch` used as a caller might: samples of two different
/// structures (scenes) in turn, eight lights (a parallel one and seven
/// point lights, so that lights share the cache's slots), samples with no
/// query (`add_none`), batches answered twice and cleared unanswered. Its
/// answers and the rays cast are those of a batch filled with `add`.
#[test]
fn a_reused_batch_answers_as_added_as_the_plain_one() {
    use rendiff::accel::ShadowBatch;
    use rendiff::color::Rgb;
    use rendiff::shade::{Light, LightKind};
    let make = |shift: f32| {
        let tris = floor_occluder_grid(shift, 6, 0.5, 0.4);
        let mut scene = TriScene::from_triangles(camera(), &tris);
        let mut kinds = vec![LightKind::Parallel {
            direction: -Vec3::new(0.15, 1.0, 0.1).normalize(),
        }];
        for k in 0..7 {
            let k = k as f32;
            kinds.push(LightKind::Point {
                position: Vec3::new(0.3 + 0.2 * k, 5.0 - 0.3 * k, 0.2 - 0.1 * k),
            });
        }
        for kind in kinds {
            scene.lights.push(Light {
                kind,
                color: Rgb::WHITE,
                shadowless: false,
                fade: None,
            });
        }
        scene
    };
    let scenes = [make(0.0), make(1.7)];
    let accels: Vec<Accel> = scenes
        .iter()
        .map(|s| Accel::new(s, AccelOptions::default()))
        .collect();
    let with_rays: Vec<ShadowRays> = accels.iter().map(ShadowRays::new).collect();
    let plain_rays: Vec<ShadowRays> = accels.iter().map(ShadowRays::new).collect();
    let ctxs: Vec<_> = scenes.iter().map(|s| s.shade_context(0.0, true)).collect();
    let (mut with, mut plain) = (ShadowBatch::default(), ShadowBatch::default());
    let mut rng = Rng(0x1234_5678);
    let (mut x, mut answered, mut certified) = (0usize, false, 0usize);
    let down = Vec3::new(0.05, -1.0, 0.02).normalize();
    for _ in 0..60_000 {
        let r = rng.below(100);
        if r < 60 {
            let (px, pz) = (rng.rangef(-3.0, 3.0), rng.rangef(-3.0, 3.0));
            let sp = floor_point(&scenes[x], px, pz);
            let _ = with.add_with(&ctxs[x], &sp, down, &with_rays[x]);
            let _ = plain.add(&ctxs[x], &sp, down);
            answered = false;
        } else if r < 66 {
            with.add_none();
            plain.add_none();
        } else if r < 90 || (r < 92 && answered) {
            // (Between 90 and 92: a batch answered again.)
            certified += with.answered_as_added();
            with.answer(&with_rays[x]);
            plain.answer(&plain_rays[x]);
            answered = true;
            assert_eq!(with.len(), plain.len());
            for k in 0..plain.len() {
                let (a, b) = (
                    with.answered(k, &with_rays[x]),
                    plain.answered(k, &plain_rays[x]),
                );
                assert_eq!(a.answers, b.answers, "sample {k}");
            }
        } else if r >= 92 {
            with.clear();
            plain.clear();
            if rng.below(3) == 0 {
                x = rng.below(2) as usize;
            }
        }
    }
    for (a, b) in with_rays.iter().zip(&plain_rays) {
        assert_eq!(a.cast(), b.cast());
    }
    assert!(certified > 1000, "{certified} answered as added");
}
