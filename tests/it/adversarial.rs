//! Adversarial geometry (DESIGN.md §8), with fixed seeds: every case
//! either renders — no panic, no NaN or infinite pixel, and the two
//! backends agree (no real mismatch) — or is refused at load with a clear
//! error. Where the line between the two lies is a stated threshold, and
//! both of its sides are tested.
//!
//! The thresholds (`scene::MAX_COORDINATE`, `tessellate::MIN_EXTENT`,
//! `tessellate::MIN_EXTENT_STEPS`): coordinates within ±1e12 (products of
//! three coordinate differences in the f32 ray-triangle test stay below
//! f32::MAX); a scene at least 1e-10 across (those products stay far above
//! f32's smallest normal); and at least 2048 f32 steps across at its
//! largest coordinate (rounding moves no vertex by more than 1/2048 of the
//! scene). NaN and infinite coordinates are refused where they are read
//! (`tests/data/bad/15`–`18`, `29`).

use rendiff::accel::{Accel, AccelOptions};
use rendiff::camera::{Camera, Projection};
use rendiff::compare::{compare_frames, derive_tolerances};
use rendiff::frame::Frame;
use rendiff::math::{DVec3, Vec3};
use rendiff::options::{DepthFormat, ShadowMode};
use rendiff::raster::{self, RasterOptions};
use rendiff::scene::Scene;
use rendiff::tessellate::{MIN_EXTENT, MIN_EXTENT_STEPS};
use rendiff::tri_scene::TriScene;
use rendiff::{Backend, GATE_EPS, Overrides, Prepared};

use crate::util::{Rng, scene_path};

fn finite(f: &Frame) -> bool {
    f.color.iter().all(|c| c.is_finite()) && f.depth.iter().all(|d| !d.is_nan())
}

/// Renders a prepared scene with both backends and checks the frames:
/// finite, and no real visibility mismatch. Returns the agreeing samples.
fn both_agree(job: &Prepared, what: &str) -> u64 {
    let a = job.render(Backend::Raster).unwrap().frame;
    let b = job.render(Backend::Ray).unwrap().frame;
    assert!(finite(&a) && finite(&b), "{what}: a non-finite pixel");
    let c = compare_frames(
        &job.tri,
        &a,
        &b,
        &derive_tolerances(&job.tri),
        job.settings.depth,
    );
    let v = c.visibility.expect("two frames");
    assert_eq!(v.real, 0, "{what}: {v:?}");
    v.agree
}

/// The same for a bare triangle scene.
fn both_agree_tri(tri: &TriScene, what: &str) {
    let opts = RasterOptions {
        depth: DepthFormat::F32,
        shadows: ShadowMode::Rays,
        shadows_needed: false,
        gate_eps: GATE_EPS,
        frustum_cull: vec![false; tri.objects.len()],
        backface_cull: vec![false; tri.objects.len()],
        perturb: raster::Perturb::default(),
    };
    let (a, _) = raster::render(tri, &opts);
    let accel = Accel::new(tri, AccelOptions::default());
    let b = rendiff::ray::render(
        &accel,
        &rendiff::ray::RayOptions {
            max_depth: 1,
            shadows: false,
            gate_eps: GATE_EPS,
        },
    );
    assert!(finite(&a) && finite(&b), "{what}: a non-finite pixel");
    let c = compare_frames(tri, &a, &b, &derive_tolerances(tri), DepthFormat::F32);
    let v = c.visibility.expect("two frames");
    assert_eq!(v.real, 0, "{what}: {v:?}");
}

fn small() -> Overrides {
    Overrides {
        size: Some((64, 48)),
        ..Overrides::default()
    }
}

/// The extent and the largest coordinate (eye included) of a prepared scene.
fn extent_and_largest(job: &Prepared) -> (f64, f64) {
    let b = job.tri.bounds;
    let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
    let largest = lo
        .abs()
        .max(hi.abs())
        .max(job.tri.camera.eye().abs())
        .max_element();
    ((hi - lo).length(), largest)
}

#[test]
fn scales_render_or_are_refused_at_the_stated_thresholds() {
    let base = Scene::load(&scene_path("spheres")).unwrap();
    let job = Prepared::from_scene(base.clone(), &small()).unwrap();
    let (extent, largest) = extent_and_largest(&job);
    let max_coordinate = rendiff::scene::MAX_COORDINATE;
    // Well inside, from 1e-9 to 1e10 times the scene.
    for scale in [1e-9, 1e-5, 1e-2, 1e3, 1e6, 1e10] {
        let job = Prepared::from_scene(base.scaled(scale, DVec3::ZERO).unwrap(), &small())
            .unwrap_or_else(|e| panic!("×{scale}: {e}"));
        assert!(both_agree(&job, &format!("×{scale}")) > 1000);
    }
    // Both sides of the smallest extent and of the largest coordinate.
    let s_small = MIN_EXTENT / extent;
    let s_large = max_coordinate / largest;
    for (scale, ok) in [
        (s_small * 1.5, true),
        (s_small * 0.5, false),
        (s_large * 0.5, true),
        (s_large * 2.0, false),
        (1e-30, false),
        (1e30, false),
    ] {
        match Prepared::from_scene(base.scaled(scale, DVec3::ZERO).unwrap(), &small()) {
            Ok(job) => {
                assert!(ok, "×{scale:e}: accepted beyond the threshold");
                both_agree(&job, &format!("×{scale:e}"));
            }
            Err(e) => {
                let m = e.to_string();
                assert!(!ok, "×{scale:e}: refused inside the threshold: {m}");
                assert!(
                    m.contains("1e-10") || m.contains("1e12"),
                    "×{scale:e}: the message names no threshold: {m}"
                );
            }
        }
    }
    // Both sides of the precision rule: the unit scene moved away from the
    // origin until it spans fewer than 2048 f32 steps.
    let d_max = extent / (MIN_EXTENT_STEPS * f64::from(f32::EPSILON));
    for (distance, ok) in [(d_max * 0.5, true), (d_max * 2.0, false)] {
        let offset = DVec3::new(distance, 0.0, 0.0);
        match Prepared::from_scene(base.scaled(1.0, offset).unwrap(), &small()) {
            Ok(job) => {
                assert!(ok, "moved {distance:e}: accepted");
                both_agree(&job, &format!("moved {distance:e}"));
            }
            Err(e) => {
                assert!(!ok, "moved {distance:e}: refused: {e}");
                assert!(e.to_string().contains("f32 steps"), "{e}");
            }
        }
    }
}

fn camera(rng: &mut Rng, w: u32, h: u32) -> Camera {
    let eye = DVec3::new(
        rng.range(-3.0, 3.0),
        rng.range(-3.0, 3.0),
        rng.range(3.0, 6.0),
    );
    let at = DVec3::new(
        rng.range(-0.5, 0.5),
        rng.range(-0.5, 0.5),
        rng.range(-0.5, 0.5),
    );
    let proj = if rng.below(4) == 0 {
        Projection::Orthographic {
            view_height: rng.range(2.0, 6.0),
        }
    } else {
        Projection::Perspective {
            tan_half_fov: rng.range(0.2, 1.2),
        }
    };
    Camera::new(
        eye,
        at,
        DVec3::Y,
        proj,
        w,
        h,
        1 + u32::from(rng.below(2) == 0),
        0.05,
        100.0,
    )
    .expect("a valid camera")
}

/// Zero-area triangles (repeated and collinear vertices), needles (one
/// side 1e-6 of the others), slivers, triangles through the eye plane and
/// ordinary ones, mixed, under random cameras.
#[test]
fn degenerate_and_needle_triangles_render_and_agree() {
    let mut rng = Rng(0x5EED_0009);
    for case in 0..60 {
        let cam = camera(&mut rng, 40, 30);
        let mut tris = Vec::new();
        let p = |rng: &mut Rng| {
            Vec3::new(
                rng.rangef(-2.0, 2.0),
                rng.rangef(-2.0, 2.0),
                rng.rangef(-2.0, 2.0),
            )
        };
        for _ in 0..40 {
            let (a, b, c) = (p(&mut rng), p(&mut rng), p(&mut rng));
            let t = match rng.below(6) {
                0 => [a, a, b],                                  // repeated vertex
                1 => [a, b, a + (b - a) * 0.37],                 // collinear
                2 => [a, a + (b - a) * 1e-6, c],                 // needle
                3 => [a, b, a + (b - a) * 0.5 + (c - a) * 1e-6], // sliver
                4 => [a, b, c + Vec3::new(0.0, 0.0, 8.0)],       // reaches behind the eye
                _ => [a, b, c],
            };
            tris.push(t);
        }
        let scene = TriScene::from_triangles(cam, &tris);
        both_agree_tri(&scene, &format!("case {case}"));
    }
}

/// A million triangles stacked in one pixel, at random depths and sizes
/// below a pixel: both render it, and agree.
#[test]
fn a_million_triangles_in_one_pixel() {
    let cam = Camera::new(
        DVec3::new(0.0, 0.0, 5.0),
        DVec3::ZERO,
        DVec3::Y,
        Projection::Perspective { tan_half_fov: 0.5 },
        16,
        12,
        1,
        0.05,
        100.0,
    )
    .unwrap();
    let mut rng = Rng(0x0001_0000_0000);
    // Pixel (8, 6) at view depth z covers about z·2·0.5/12 world units.
    let (o, d) = cam.primary_ray_f64(8.5, 6.5);
    let tris: Vec<[Vec3; 3]> = (0..1_000_000)
        .map(|_| {
            let z = rng.range(1.0, 4.0);
            let px = z / 12.0;
            let c = o + d * z;
            let j = |rng: &mut Rng| {
                DVec3::new(
                    rng.range(-0.4, 0.4),
                    rng.range(-0.4, 0.4),
                    rng.range(-0.1, 0.1),
                ) * px
            };
            let v = [c + j(&mut rng), c + j(&mut rng), c + j(&mut rng)];
            v.map(|p| p.as_vec3())
        })
        .collect();
    let scene = TriScene::from_triangles(cam, &tris);
    both_agree_tri(&scene, "a million in one pixel");
}

/// The camera inside a closed object, a light inside one, and a near
/// plane that cuts through the geometry.
#[test]
fn eyes_lights_and_near_planes_inside_geometry() {
    // The camera inside a closed room (bundled).
    let job = Prepared::load(&scene_path("inside"), &small()).unwrap();
    both_agree(&job, "inside");
    // A light inside the big sphere of spheres.toml: nothing outside the
    // sphere sees it.
    let mut scene = Scene::load(&scene_path("spheres")).unwrap();
    scene.lights.truncate(1);
    scene.lights[0].kind = rendiff::shade::LightKind::Point {
        position: Vec3::new(0.0, 0.8, -0.8),
    };
    let mut dark = scene.clone();
    dark.lights[0].color = rendiff::color::Rgb::BLACK;
    let job = Prepared::from_scene(scene, &small()).unwrap();
    both_agree(&job, "light inside a sphere");
    // Outside the sphere the light adds nothing: the frame equals the one
    // with the light switched off there.
    let dark = Prepared::from_scene(dark, &small()).unwrap();
    let inside = job
        .tri
        .objects
        .iter()
        .position(|o| o.closed && o.bounds.contains(Vec3::new(0.0, 0.8, -0.8)))
        .expect("the light is inside a closed sphere") as u32;
    for backend in [Backend::Raster, Backend::Ray] {
        let (f, g) = (
            job.render(backend).unwrap().frame,
            dark.render(backend).unwrap().frame,
        );
        let leaks = (0..f.id.len())
            .filter(|&i| {
                let id = f.id[i];
                id != rendiff::frame::BACKGROUND
                    && job.tri.object_of(id) != Some(inside)
                    && f.sample_colors()[i] != g.sample_colors()[i]
            })
            .count();
        assert_eq!(
            leaks, 0,
            "{backend}: {leaks} samples outside the sphere see its light"
        );
    }
    // Near planes through the spheres.
    for near in [1.5, 3.0, 4.2] {
        let mut scene = Scene::load(&scene_path("spheres")).unwrap();
        scene.camera.near = near;
        let job = Prepared::from_scene(scene, &small()).unwrap();
        both_agree(&job, &format!("near {near}"));
    }
}
