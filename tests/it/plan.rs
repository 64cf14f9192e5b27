//! The render plan (DESIGN.md §7): with and without it every bundled scene
//! renders bit-identically on both backends (the one counted exception:
//! cullable back faces at silhouettes, each an edge or depth tie), and
//! each skip fires on a scene built for it, as the backends' own counters
//! show.

use rendiff::compare::Oracle;
use rendiff::compare::oracle::Class;
use rendiff::frame::{BACKGROUND, Frame};
use rendiff::options::ShadowMode;
use rendiff::scene::Scene;
use rendiff::tri_scene::NO_INDEX;
use rendiff::{Backend, Overrides, Prepared, Work};

use crate::util::{bundled_scenes, load, root};

fn no_plan() -> Overrides {
    Overrides {
        no_plan: true,
        ..Overrides::default()
    }
}

/// Samples that differ between two frames of the same scene (colour,
/// depth, id or flags, bit for bit).
fn differing_samples(a: &Frame, b: &Frame) -> Vec<usize> {
    (0..a.id.len())
        .filter(|&i| {
            a.sample_colors()[i] != b.sample_colors()[i]
                || a.depth[i].to_bits() != b.depth[i].to_bits()
                || a.id[i] != b.id[i]
                || a.flags[i] != b.flags[i]
        })
        .collect()
}

/// Pixels whose colour differs although all their samples agree.
fn unexplained_pixels(a: &Frame, b: &Frame, differing: &[usize]) -> usize {
    let n = a.samples as usize;
    let sw = a.width as usize * n;
    let mut bad_pixel = vec![false; a.color.len()];
    for &i in differing {
        let (sx, sy) = (i % sw, i / sw);
        bad_pixel[(sy / n) * a.width as usize + sx / n] = true;
    }
    a.color
        .iter()
        .zip(&b.color)
        .zip(&bad_pixel)
        .filter(|((p, q), bad)| !**bad && p != q)
        .count()
}

#[test]
fn the_plan_never_changes_a_pixel() {
    let mut report = String::new();
    for name in bundled_scenes() {
        let planned = load(&name, &Overrides::default());
        let unplanned = load(&name, &no_plan());
        for backend in [Backend::Raster, Backend::Ray] {
            let a = planned.render(backend).unwrap().frame;
            let b = unplanned.render(backend).unwrap().frame;
            let diff = differing_samples(&a, &b);
            assert_eq!(
                unexplained_pixels(&a, &b, &diff),
                0,
                "{name} {backend}: pixel colours differ where every sample agrees"
            );
            if backend == Backend::Ray {
                assert!(diff.is_empty(), "{name} ray: {} samples differ", diff.len());
                continue;
            }
            // The one exception: the unplanned rasterizer shows a back face
            // that the plan culls. Each such sample is an edge or depth tie.
            let tri = &planned.tri;
            let oracle = Oracle::new(tri, planned.settings.depth);
            let cam = &tri.camera;
            let sw = cam.sample_width() as usize;
            let mut ties = 0;
            for &i in &diff {
                let shown = b.id[i];
                assert_ne!(shown, BACKGROUND, "{name}: the plan removed a surface");
                let obj = tri.tri_object[shown as usize] as usize;
                assert!(
                    planned.plan.backface_cull[obj],
                    "{name}: sample {i} differs on object {obj}, which the plan does not cull"
                );
                #[expect(clippy::cast_possible_truncation, reason = "sample index < 2^32")]
                let (x, y) = cam.sample_point((i % sw) as u32, (i / sw) as u32);
                let id = |v: u32| (v != BACKGROUND).then_some(v);
                let class = oracle.classify(x, y, id(a.id[i]), id(shown));
                assert!(
                    matches!(class, Class::EdgeTie | Class::DepthTie),
                    "{name}: sample {i}: culled back face {shown} vs {}: {class:?}",
                    a.id[i]
                );
                ties += 1;
            }
            report.push_str(&format!(
                "{name:16} raster: {ties} back-face tie sample(s)\n"
            ));
        }
    }
    eprint!("{report}");
}

/// A scene written inline, resolved as if it lay in `scenes/`.
fn inline(body: &str, ov: &Overrides) -> Prepared {
    let head = r#"
[image]
width = 96
height = 72
[camera]
eye = [0.0, 1.0, 6.0]
look_at = [0.0, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0
[materials.grey]
pigment = [0.7, 0.7, 0.7]
[materials.noise]
pigment = { image = "textures/noise.png" }
"#;
    let text = format!("{head}\n{body}");
    let scene = Scene::from_str(&root().join("scenes/plan_inline.toml"), &text)
        .unwrap_or_else(|e| panic!("{e}\n{text}"));
    Prepared::from_scene(scene, ov).unwrap()
}

const SPHERE_AND_FLOOR: &str = r#"
[[objects]]
kind = "sphere"
material = "grey"
center = [0.0, 0.8, 0.0]
radius = 0.8
[[objects]]
kind = "box"
material = "grey"
min = [-3.0, -0.2, -3.0]
max = [3.0, 0.0, 3.0]
"#;

fn raster_work(p: &Prepared) -> rendiff::raster::RasterStats {
    match p.render(Backend::Raster).unwrap().work {
        Work::Raster(s) => s,
        other => panic!("a raster render reported {other:?}"),
    }
}

fn ray_work(p: &Prepared) -> (rendiff::ray::RayStats, rendiff::accel::BvhStats) {
    match p.render(Backend::Ray).unwrap().work {
        Work::Ray { rays, bvh } => (rays, bvh),
        other => panic!("a ray render reported {other:?}"),
    }
}

fn same_frames(a: &Prepared, b: &Prepared, what: &str) {
    for backend in [Backend::Raster, Backend::Ray] {
        let fa = a.render(backend).unwrap().frame;
        let fb = b.render(backend).unwrap().frame;
        assert!(
            differing_samples(&fa, &fb).is_empty(),
            "{what}: {backend} differs with and without the plan"
        );
    }
}

#[test]
fn shadow_work_is_skipped_where_no_shadow_can_fall() {
    for (what, lights) in [
        (
            "shadowless lights only",
            "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\nshadowless = true\n",
        ),
        (
            "no object casts",
            "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n",
        ),
    ] {
        let mut body = format!("{lights}{SPHERE_AND_FLOOR}");
        if what == "no object casts" {
            body = body.replace(
                "material = \"grey\"\n",
                "material = \"grey\"\nno_shadow = true\n",
            );
        }
        let planned = inline(&body, &Overrides::default());
        let unplanned = inline(&body, &no_plan());
        assert!(!planned.plan.shadows, "{what}: {}", planned.plan);
        same_frames(&planned, &unplanned, what);
        // Rays: the rasterizer builds no BVH for them and casts none.
        let (p, u) = (raster_work(&planned), raster_work(&unplanned));
        assert!(!p.shadow_bvh && u.shadow_bvh, "{what}: {p:?} / {u:?}");
        assert_eq!(p.shadow_rays, 0);
        // Maps: none rendered.
        let maps = Overrides {
            shadows: Some(ShadowMode::Map(64)),
            ..Overrides::default()
        };
        let planned = inline(&body, &maps);
        let unplanned = inline(
            &body,
            &Overrides {
                no_plan: true,
                ..maps
            },
        );
        assert_eq!(raster_work(&planned).shadow_maps, 0, "{what}");
        // Without the plan a casting light renders its cube of six maps of
        // nothing; a shadowless light is skipped by the maps themselves.
        let expected = if what == "no object casts" { 6 } else { 0 };
        assert_eq!(raster_work(&unplanned).shadow_maps, expected, "{what}");
    }
    // The control: one light that casts, and shadows stay on.
    let body = format!(
        "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n{SPHERE_AND_FLOOR}"
    );
    let planned = inline(&body, &Overrides::default());
    assert!(planned.plan.shadows);
    assert!(raster_work(&planned).shadow_rays > 0);
    assert!(ray_work(&planned).0.shadow > 0);
}

#[test]
fn the_ray_tree_is_skipped_where_nothing_reflects_or_transmits() {
    let light =
        "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n";
    let matte = inline(&format!("{light}{SPHERE_AND_FLOOR}"), &Overrides::default());
    assert!(!matte.plan.ray_tree, "{}", matte.plan);
    assert_eq!(ray_work(&matte).0.secondary, 0);
    // A mirror: the ray tree is on and secondary rays are cast...
    let mirror = format!(
        "{light}[materials.mirror]\npigment = [0.1, 0.1, 0.1]\nreflection = 0.8\n{}",
        SPHERE_AND_FLOOR.replacen("material = \"grey\"", "material = \"mirror\"", 1)
    );
    let on = inline(&mirror, &Overrides::default());
    assert!(on.plan.ray_tree);
    assert!(ray_work(&on).0.secondary > 0);
    // ...unless max_depth = 1, where the plan turns it off.
    let depth1 = Overrides {
        max_depth: Some(1),
        ..Overrides::default()
    };
    let off = inline(&mirror, &depth1);
    assert!(!off.plan.ray_tree);
    assert_eq!(ray_work(&off).0.secondary, 0);
}

#[test]
fn uvs_are_dropped_where_no_material_reads_them() {
    let light =
        "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n";
    let body = format!("{light}{SPHERE_AND_FLOOR}");
    let planned = inline(&body, &Overrides::default());
    let unplanned = inline(&body, &no_plan());
    let with_uv = |p: &Prepared| p.tri.tri_uvs.iter().filter(|t| t[0] != NO_INDEX).count();
    assert!(with_uv(&unplanned) > 0, "spheres and boxes carry uvs");
    assert_eq!(with_uv(&planned), 0);
    assert!(planned.tri.uvs.is_empty());
    same_frames(&planned, &unplanned, "no texture");
    // A textured sphere keeps its uvs; the grey box does not.
    let textured = inline(
        &body.replacen("material = \"grey\"", "material = \"noise\"", 1),
        &Overrides::default(),
    );
    let sphere = &textured.tri.objects[0];
    let kept = sphere
        .tris
        .clone()
        .filter(|&t| textured.tri.tri_uvs[t as usize][0] != NO_INDEX);
    assert_eq!(kept.count(), sphere.tris.len());
    assert!(
        textured.tri.objects[1]
            .tris
            .clone()
            .all(|t| textured.tri.tri_uvs[t as usize][0] == NO_INDEX)
    );
}

#[test]
fn flat_meshes_carry_no_normals_to_interpolate() {
    let light =
        "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n";
    let mesh = |smooth: bool| {
        format!(
            "{light}[[objects]]\nkind = \"mesh\"\nmaterial = \"grey\"\nfile = \"meshes/bunny.obj\"\nsmooth = {smooth}\n"
        )
    };
    let flat = inline(&mesh(false), &Overrides::default());
    let smooth = inline(&mesh(true), &Overrides::default());
    let decision = |p: &Prepared| {
        p.plan
            .decisions
            .iter()
            .find(|d| d.what == "smooth normals")
            .map(|d| d.on)
    };
    assert_eq!(decision(&flat), Some(false));
    assert_eq!(decision(&smooth), Some(true));
    assert!(flat.tri.tri_normals.iter().all(|t| t[0] == NO_INDEX));
    assert!(smooth.tri.tri_normals.iter().all(|t| t[0] != NO_INDEX));
}

#[test]
fn tiny_scenes_use_a_flat_loop() {
    let light =
        "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n";
    // Four separate quads: 8 triangles, below the flat-loop threshold, far
    // enough apart that the SAH splits them (two packs in one leaf cost
    // more than a node over two one-pack leaves).
    let quad = |x: f32, z: f32| {
        format!(
            "[[objects]]\nkind = \"polygon\"\nmaterial = \"grey\"\npoints = [[{x}, 0.0, {z}], [{}, 0.0, {z}], [{}, 1.0, {z}], [{x}, 1.0, {z}]]\n",
            x + 0.5,
            x + 0.5
        )
    };
    let body = format!(
        "{light}{}{}{}{}",
        quad(-3.0, 0.0),
        quad(-1.0, -1.0),
        quad(1.0, -2.0),
        quad(2.5, 0.5)
    );
    let planned = inline(&body, &Overrides::default());
    let unplanned = inline(&body, &no_plan());
    assert!(!planned.plan.bvh);
    assert_eq!(ray_work(&planned).1.leaves, 1, "one leaf: the flat loop");
    assert!(
        ray_work(&unplanned).1.leaves > 1,
        "a real BVH without the plan"
    );
    same_frames(&planned, &unplanned, "flat loop");
}

#[test]
fn culling_removes_what_primary_visibility_cannot_see() {
    let light =
        "[[lights]]\nkind = \"point\"\nposition = [3.0, 5.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n";
    // A sphere behind the camera casts a shadow it cannot be seen casting.
    let behind = "[[objects]]\nkind = \"sphere\"\nmaterial = \"grey\"\ncenter = [0.0, 1.0, 9.0]\nradius = 0.5\n";
    let body = format!("{light}{SPHERE_AND_FLOOR}{behind}");
    let planned = inline(&body, &Overrides::default());
    let unplanned = inline(&body, &no_plan());
    let (p, u) = (raster_work(&planned), raster_work(&unplanned));
    let hidden = planned.tri.objects[2].tris.len();
    assert_eq!(p.culled.frustum, hidden, "{}", planned.plan);
    assert_eq!(u.culled.frustum, 0);
    // The closed sphere and box seen from outside lose their back faces.
    assert!(planned.plan.backface_cull[0] && planned.plan.backface_cull[1]);
    let sphere = planned.tri.objects[0].tris.len();
    assert!(
        p.culled.backface * 10 >= sphere * 4,
        "{} of the sphere's {sphere} triangles culled as back faces",
        p.culled.backface
    );
    assert_eq!(u.culled.backface, 0);
    assert!(p.records < u.records);
    same_frames(&planned, &unplanned, "culling");
    // From inside a closed object nothing may be culled.
    let inside = load("inside", &Overrides::default());
    let room = inside
        .tri
        .objects
        .iter()
        .position(|o| o.closed && o.bounds.contains(inside.tri.camera.eye_f32()))
        .expect("the camera is inside a closed object");
    assert!(!inside.plan.backface_cull[room]);
}

/// The seed's ray-count formula (p. 17) bounds what the ray tracer casts,
/// level by level, and `plan --count` sets the two side by side.
#[test]
fn rays_cast_stay_within_the_seeds_ray_tree_bound() {
    for name in ["glass", "menagerie", "spheres"] {
        let job = crate::util::load(name, &rendiff::Overrides::default());
        let rendered = job.render(rendiff::Backend::Ray).unwrap();
        let rendiff::Work::Ray { rays, .. } = rendered.work else {
            panic!("the ray tracer reports rays");
        };
        let cam = &job.tri.camera;
        let n = u64::from(cam.sample_width()) * u64::from(cam.sample_height());
        let depth = job.settings.max_depth;
        let m = job.tri.lights.len() as u64;
        assert_eq!(rays.primary, n);
        assert_eq!(
            rays.secondary,
            rays.by_level.iter().sum::<u64>() + rays.straight,
            "{name}: every secondary ray is on a level or straight"
        );
        for (k, &got) in rays.by_level.iter().enumerate() {
            let level = k as u32 + 2;
            if level > depth {
                assert_eq!(got, 0, "{name}: level {level} beyond max_depth {depth}");
            } else {
                assert!(got <= n << (level - 1), "{name}: level {level}: {got}");
            }
        }
        if rays.straight == 0 {
            assert!(
                rays.shadow <= n * m * ((1 << depth) - 1),
                "{name}: {}",
                rays.shadow
            );
        }
    }
    // Every bundled scene: the formula beside the counts, and the counts
    // within it (a tree row "X of at most Y" with X ≤ Y).
    let scenes = crate::util::bundled_scenes();
    assert!(scenes.len() >= 15);
    for scene in scenes {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .args(["plan", "--count"])
            .arg(format!("scenes/{scene}.toml"))
            .current_dir(crate::util::root())
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{scene}: {text}");
        let tree = text
            .lines()
            .find(|l| l.trim_start().starts_with("ray tree") && l.contains("of at most"))
            .unwrap_or_else(|| panic!("{scene}: no ray tree row:\n{text}"));
        assert!(tree.contains("N·(2ⁿ − 1)"), "{tree}");
        let nums: Vec<u64> = tree
            .split_whitespace()
            .filter_map(|w| w.parse().ok())
            .collect();
        assert!(nums.len() >= 2 && nums[0] <= nums[1], "{scene}: {tree}");
    }
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(["plan", "scenes/glass.toml", "--count"])
        .current_dir(crate::util::root())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("level 6"), "{text}");
}
