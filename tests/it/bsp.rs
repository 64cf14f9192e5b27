//! List priority that never fails: the BSP tree's pieces, painted back to
//! front on the z-buffer's sample grid, see what the z-buffer sees — no
//! wrongly ordered sample on the cyclic overlap and the interpenetrating
//! teapot that defeat the painter, nor on any bundled scene; every sample
//! the z-buffer covers is covered (pieces tile their triangle), and the
//! shading is the z-buffer's bit for bit; likewise on the hazard scenes.
//! Then the cases that are hard for
//! a floating-point BSP: coplanar overlapping triangles, shared edges, a
//! triangle in a splitter's plane, long thin triangles, the eye in a
//! triangle's plane, three triangles through each other, random soups and
//! extreme scales.

use rendiff::camera::{Camera, Projection};
use rendiff::compare::{compare_frames, derive_tolerances};
use rendiff::frame::{BACKGROUND, Frame};
use rendiff::math::{DVec3, Vec3};
use rendiff::options::{DepthFormat, ShadowMode};
use rendiff::raster::bsp::BspStats;
use rendiff::raster::{self, RasterOptions};
use rendiff::scene::Scene;
use rendiff::tri_scene::TriScene;
use rendiff::{Backend, GATE_EPS, Overrides, Prepared, Work};

use crate::util::{Rng, bundled_scenes, load, scene_path};

/// What one comparison of the BSP with the z-buffer found.
#[derive(Debug)]
struct Against {
    /// Real mismatches: samples the tree ordered wrongly.
    real: u64,
    /// Samples neither a tie nor judgeable.
    unjudgeable: u64,
    /// Samples covered by one frame and not the other.
    coverage: usize,
    /// Samples showing different triangles (ties included).
    differ: usize,
    /// Largest shading difference where both show the same triangle.
    shading: f64,
    tree: BspStats,
}

fn against(
    tri: &TriScene,
    bsp: &Frame,
    zbuf: &Frame,
    depth: DepthFormat,
    tree: BspStats,
) -> Against {
    let c = compare_frames(tri, bsp, zbuf, &derive_tolerances(tri), depth);
    let v = c.visibility.expect("two frames");
    let coverage = bsp
        .id
        .iter()
        .zip(&zbuf.id)
        .filter(|(a, b)| (**a == BACKGROUND) != (**b == BACKGROUND))
        .count();
    let differ = bsp.id.iter().zip(&zbuf.id).filter(|(a, b)| a != b).count();
    Against {
        real: v.real,
        unjudgeable: v.unjudgeable,
        coverage,
        differ,
        shading: c.shading.max,
        tree,
    }
}

/// A prepared scene's BSP render against its z-buffer render.
fn job_against(job: &Prepared) -> Against {
    let bsp = job.render(Backend::Bsp).unwrap();
    let zbuf = job.render(Backend::Raster).unwrap();
    let Work::Bsp { tree, .. } = bsp.work else {
        panic!("a BSP render reported {:?}", bsp.work);
    };
    against(&job.tri, &bsp.frame, &zbuf.frame, job.settings.depth, tree)
}

/// Nothing culled, no shadows: the options for a bare triangle scene.
fn bare_options(tri: &TriScene) -> RasterOptions {
    RasterOptions {
        depth: DepthFormat::F32,
        shadows: ShadowMode::Rays,
        shadows_needed: false,
        gate_eps: GATE_EPS,
        frustum_cull: vec![false; tri.objects.len()],
        backface_cull: vec![false; tri.objects.len()],
        perturb: raster::Perturb::default(),
    }
}

/// A bare triangle scene's BSP render against its z-buffer render.
fn tri_against(tri: &TriScene) -> Against {
    let opts = bare_options(tri);
    let budget = rendiff::budget::Budget::new(1 << 30);
    let (bsp, _, tree) = raster::bsp::render(tri, &opts, &budget).unwrap();
    assert_eq!(budget.used(), 0, "the tree gave back what it reserved");
    let (zbuf, _) = raster::render(tri, &opts);
    against(tri, &bsp, &zbuf, DepthFormat::F32, tree)
}

/// The checks every case must pass: no wrongly ordered or unjudgeable
/// sample, exactly the z-buffer's coverage, its shading where the ids agree.
fn assert_sees_what_the_zbuffer_sees(a: &Against, what: &str) {
    assert_eq!(a.real, 0, "{what}: {a:?}");
    assert_eq!(a.unjudgeable, 0, "{what}: {a:?}");
    assert_eq!(
        a.coverage, 0,
        "{what}: pieces lost or added coverage: {a:?}"
    );
    assert_eq!(a.shading, 0.0, "{what}: {a:?}");
    assert_eq!(a.tree.pieces, a.tree.triangles + a.tree.splits, "{what}");
}

#[test]
fn the_tree_orders_what_defeats_the_painter() {
    for name in ["painter_cycle", "teapot"] {
        let job = load(name, &Overrides::default());
        let painter = job.render(Backend::Painter).unwrap();
        let zbuf = job.render(Backend::Raster).unwrap();
        let c = compare_frames(
            &job.tri,
            &painter.frame,
            &zbuf.frame,
            &derive_tolerances(&job.tri),
            job.settings.depth,
        );
        let painter_wrong = c.visibility.unwrap().real;
        assert!(
            painter_wrong > 50,
            "{name}: the painter got {painter_wrong} wrong"
        );
        let a = job_against(&job);
        assert_sees_what_the_zbuffer_sees(&a, name);
        // The cycle and the interpenetration are resolved by splitting.
        assert!(a.tree.splits > 0, "{name}: {a:?}");
        eprintln!(
            "{name}: painter {painter_wrong} wrongly ordered samples; bsp 0 ({} triangles, {} pieces)",
            a.tree.triangles, a.tree.pieces
        );
    }
}

/// Every bundled scene (at 160 px wide, to keep the suite fast): the BSP
/// sees what the z-buffer sees.
#[test]
fn every_bundled_scene_agrees_with_the_zbuffer() {
    let mut report = String::new();
    for name in bundled_scenes() {
        let path = scene_path(&name);
        let scene = Scene::load(&path).unwrap();
        let (w, h) = (scene.image.width, scene.image.height);
        let ov = Overrides {
            size: Some((160, (160 * h / w).max(1))),
            ..Overrides::default()
        };
        let job = Prepared::from_scene(scene, &ov).unwrap();
        let a = job_against(&job);
        assert_sees_what_the_zbuffer_sees(&a, &name);
        report.push_str(&format!(
            "{name:16} {:6} triangles {:6} pieces {:5} ties\n",
            a.tree.triangles, a.tree.pieces, a.differ
        ));
    }
    eprint!("{report}");
}

/// The hazard scenes (a grazing eye a millimetre above a floor two
/// kilometres wide, quads 10⁶ from the origin, a 0.05° view, far nearer
/// than the objects, …), as they are.
#[test]
fn the_hazard_scenes_agree_with_the_zbuffer() {
    let dir = crate::util::root().join("tests/data/hazards");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 9);
    for path in names {
        let job = Prepared::load(&path, &Overrides::default()).unwrap();
        let a = job_against(&job);
        assert_sees_what_the_zbuffer_sees(&a, &path.display().to_string());
    }
}

/// The camera of the synthetic cases: 96×72 from z = 6 towards the origin.
fn camera() -> Camera {
    Camera::new(
        DVec3::new(0.0, 0.0, 6.0),
        DVec3::ZERO,
        DVec3::Y,
        Projection::Perspective { tan_half_fov: 0.45 },
        96,
        72,
        1,
        0.01,
        100.0,
    )
    .unwrap()
}

fn v(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z)
}

#[test]
fn coplanar_overlapping_triangles_show_the_lower_id_as_the_zbuffer_does() {
    // Exactly coplanar in f32: z = 0, and a tilted plane x + y + z = 1
    // whose vertices are exact, so the depth planes differ by rounding only.
    let flat = [
        [v(-2.0, -1.5, 0.0), v(2.0, -1.0, 0.0), v(0.0, 2.0, 0.0)],
        [v(-1.5, 1.5, 0.0), v(-1.0, -2.0, 0.0), v(2.5, 0.5, 0.0)],
    ];
    let tilted = [
        [v(-1.0, -1.0, 3.0), v(2.0, -1.0, 0.0), v(-1.0, 2.0, 0.0)],
        [v(1.5, 1.0, -1.5), v(-1.5, 0.5, 2.0), v(0.5, -1.5, 2.0)],
    ];
    for (what, tris) in [("flat", flat), ("tilted", tilted)] {
        for order in [[0, 1], [1, 0]] {
            let t = [tris[order[0]], tris[order[1]]];
            let scene = TriScene::from_triangles(camera(), &t);
            let a = tri_against(&scene);
            assert_sees_what_the_zbuffer_sees(&a, what);
            // One node: the second triangle lies in the first one's plane.
            assert_eq!((a.tree.splits, a.tree.coplanar), (0, 1), "{what}: {a:?}");
        }
    }
    // Sample for sample the lower id, as the z-buffer's tie rule.
    let scene = TriScene::from_triangles(camera(), &flat);
    let budget = rendiff::budget::Budget::new(1 << 30);
    let opts = bare_options(&scene);
    let (bsp, _, _) = raster::bsp::render(&scene, &opts, &budget).unwrap();
    let (zbuf, _) = raster::render(&scene, &opts);
    assert_eq!(bsp.id, zbuf.id);
    assert!(bsp.id.contains(&0) && bsp.id.contains(&1));
}

#[test]
fn triangles_sharing_edges_are_not_split_by_each_other() {
    // A folded strip: each triangle shares an edge with the next, at a
    // crease, and the strip folds over itself so that they overlap on the
    // screen. Their shared vertices are on each other's planes.
    let mut tris = Vec::new();
    let pts: Vec<Vec3> = (0..8)
        .map(|k| {
            let x = -2.0 + 0.5 * k as f32;
            let (y, z) = if k % 2 == 0 { (-1.0, 0.0) } else { (1.0, 0.7) };
            v(x, y, z + 0.3 * (k as f32 * 1.3).sin())
        })
        .collect();
    for k in 0..pts.len() - 2 {
        tris.push([pts[k], pts[k + 1], pts[k + 2]]);
    }
    let a = tri_against(&TriScene::from_triangles(camera(), &tris));
    assert_sees_what_the_zbuffer_sees(&a, "strip");
    assert_eq!(a.tree.splits, 0, "{a:?}");
}

#[test]
fn a_triangle_in_a_splitters_plane_is_drawn_at_its_node() {
    // Two triangles of the plane z = 0 apart and a third, parallel, in
    // front of both: whichever is chosen first, one of the two lies in a
    // splitter's plane and goes to its node; nothing is split.
    let apart = [
        [v(-2.5, -1.0, 0.0), v(-0.5, -1.0, 0.0), v(-1.5, 1.0, 0.0)],
        [v(0.5, -1.0, 0.0), v(2.5, -1.0, 0.0), v(1.5, 1.0, 0.0)],
        [v(-2.0, -0.5, 0.5), v(2.0, -0.5, 0.5), v(0.0, 0.8, 0.5)],
    ];
    let a = tri_against(&TriScene::from_triangles(camera(), &apart));
    assert_sees_what_the_zbuffer_sees(&a, "in a plane");
    assert_eq!(
        (a.tree.triangles, a.tree.coplanar, a.tree.splits),
        (3, 1, 0),
        "{a:?}"
    );
    // A triangle touching the plane z = 0 at one vertex inside the first
    // (exactly on it, in f32) and standing in front of it; and one through
    // the plane along a line that runs through a vertex of the first.
    let touching = [
        apart[0],
        [v(-1.5, -0.2, 0.0), v(-0.2, 0.9, 0.7), v(-2.4, 0.6, 0.9)],
        [v(-0.5, -1.0, -0.8), v(-0.5, -1.0, 0.8), v(-2.8, 1.2, 0.1)],
    ];
    let a = tri_against(&TriScene::from_triangles(camera(), &touching));
    assert_sees_what_the_zbuffer_sees(&a, "touching");
}

#[test]
fn long_thin_triangles_tile_without_losing_coverage() {
    // Slivers across the whole view, a hundredth of a pixel to a pixel
    // wide, through each other at shallow angles.
    let mut tris = Vec::new();
    for k in 0..12 {
        let a = k as f32 * 0.27;
        let (c, s) = (a.cos(), a.sin());
        let w = 0.0005 * (k as f32 + 1.0).powi(2);
        let z0 = 0.8 * (k as f32 - 6.0) / 6.0;
        tris.push([
            v(-4.0 * c, -4.0 * s, z0),
            v(4.0 * c, 4.0 * s, -z0),
            v(4.0 * c - w * s, 4.0 * s + w * c, -z0 + 0.1),
        ]);
    }
    let a = tri_against(&TriScene::from_triangles(camera(), &tris));
    assert_sees_what_the_zbuffer_sees(&a, "slivers");
    assert!(a.tree.splits > 0, "{a:?}");
}

#[test]
fn a_triangle_whose_plane_holds_the_eye_is_harmless() {
    // The first triangle's plane x = 0 holds the eye at (0, 0, 6): seen
    // edge-on it covers nothing, in either backend; the others cross it.
    let tris = [
        [v(0.0, -1.0, 0.0), v(0.0, 1.0, 0.0), v(0.0, 0.0, 3.0)],
        [v(-1.5, -1.0, -0.5), v(1.5, -1.0, 0.5), v(0.0, 1.5, 0.0)],
        [v(-1.5, 1.0, 0.5), v(1.5, 1.0, -0.5), v(0.0, -1.5, 0.2)],
    ];
    let a = tri_against(&TriScene::from_triangles(camera(), &tris));
    assert_sees_what_the_zbuffer_sees(&a, "eye in a plane");
}

#[test]
fn three_mutually_piercing_triangles_are_ordered_by_splitting() {
    // Three blades, each passing through the other two: no order of whole
    // triangles is right, and every pair crosses on the screen.
    let mut tris = Vec::new();
    for k in 0..3 {
        let a = k as f32 * std::f32::consts::TAU / 3.0;
        let (c, s) = (a.cos(), a.sin());
        let rot = |x: f32, y: f32, z: f32| v(c * x - s * y, s * x + c * y, z);
        tris.push([
            rot(-0.3, -1.8, 0.9),
            rot(0.3, -1.8, 0.9),
            rot(0.0, 1.6, -0.9),
        ]);
    }
    let a = tri_against(&TriScene::from_triangles(camera(), &tris));
    assert_sees_what_the_zbuffer_sees(&a, "blades");
    assert!(a.tree.splits >= 2, "{a:?}");
}

#[test]
fn random_soups_see_what_the_zbuffer_sees() {
    for seed in 1..=12u64 {
        let mut rng = Rng(seed);
        let n = 10 + rng.below(60) as usize;
        let tris: Vec<[Vec3; 3]> = (0..n)
            .map(|_| {
                let c = v(
                    rng.rangef(-2.0, 2.0),
                    rng.rangef(-1.5, 1.5),
                    rng.rangef(-2.0, 2.0),
                );
                let r = rng.rangef(0.2, 2.0);
                [0, 1, 2].map(|_| c + v(rng.rangef(-r, r), rng.rangef(-r, r), rng.rangef(-r, r)))
            })
            .collect();
        let mut scene = TriScene::from_triangles(camera(), &tris);
        if seed % 3 == 0 {
            scene.camera = Camera::new(
                DVec3::new(0.3, 0.2, 6.0),
                DVec3::ZERO,
                DVec3::Y,
                Projection::Orthographic { view_height: 5.0 },
                96,
                72,
                2,
                0.01,
                100.0,
            )
            .unwrap();
        }
        let a = tri_against(&scene);
        assert_sees_what_the_zbuffer_sees(&a, &format!("seed {seed}"));
    }
}

#[test]
fn extreme_scales_keep_the_on_plane_bound_relative() {
    // The bound is derived from the coordinates' own magnitudes, so a
    // scene a billion times smaller or ten billion times larger (around
    // its own origin, the eye included) builds the same tree.
    let base = Scene::load(&scene_path("painter_cycle")).unwrap();
    let small = Overrides {
        size: Some((96, 72)),
        ..Overrides::default()
    };
    let reference = job_against(&Prepared::from_scene(base.clone(), &small).unwrap());
    assert_sees_what_the_zbuffer_sees(&reference, "×1");
    for scale in [1e-9, 1e10] {
        let job = Prepared::from_scene(base.scaled(scale, DVec3::ZERO).unwrap(), &small).unwrap();
        let a = job_against(&job);
        assert_sees_what_the_zbuffer_sees(&a, &format!("×{scale}"));
        assert_eq!(a.tree.triangles, reference.tree.triangles, "×{scale}");
        assert!(a.tree.splits > 0, "×{scale}: {a:?}");
    }
}

#[test]
fn the_tree_is_held_in_the_memory_budget() {
    // A soup whose tree outgrows 1 MiB: refused with the tree named, and
    // everything it had reserved given back; with room, it renders.
    let mut rng = Rng(7);
    let tris: Vec<[Vec3; 3]> = (0..3000)
        .map(|_| {
            let c = v(
                rng.rangef(-2.0, 2.0),
                rng.rangef(-1.5, 1.5),
                rng.rangef(-2.0, 2.0),
            );
            [0, 1, 2].map(|_| {
                c + v(
                    rng.rangef(-0.8, 0.8),
                    rng.rangef(-0.8, 0.8),
                    rng.rangef(-0.8, 0.8),
                )
            })
        })
        .collect();
    let scene = TriScene::from_triangles(camera(), &tris);
    let opts = bare_options(&scene);
    let tight = rendiff::budget::Budget::new(1 << 20);
    let e = raster::bsp::render(&scene, &opts, &tight).expect_err("a 1 MiB tree");
    assert!(e.to_string().contains("BSP tree"), "{e}");
    assert_eq!(tight.used(), 0);
    let roomy = rendiff::budget::Budget::new(1 << 30);
    let (_, _, tree) = raster::bsp::render(&scene, &opts, &roomy).unwrap();
    assert!(tree.pieces > 3000, "{tree:?}");
    assert_eq!(roomy.used(), 0);
}

#[test]
fn samples_where_two_triangles_cross_go_to_the_lower_id() {
    // Two planes through each other along x = 1/16, seen orthographically
    // so that a column of sample centres lies exactly on the line where
    // their depths are equal: the z-buffer gives those samples to the
    // lower id. A third triangle in the second one's plane (off to the
    // side) makes the second the splitter, so the first, of lower id, is
    // the one cut: its samples on the line must go to its front piece,
    // drawn after the splitter. (Found: with `L = 0` always behind, the
    // 23 samples of that column showed the splitter.)
    let a = [
        v(-2.0, -1.5, -1.03125),
        v(2.0, -1.5, 0.96875),
        v(0.0, 1.5, -0.03125),
    ];
    let b = [
        v(-2.0, -1.5, 1.03125),
        v(2.0, -1.5, -0.96875),
        v(0.0, 1.5, 0.03125),
    ];
    let c = [
        v(3.0, -1.5, -1.46875),
        v(5.0, -1.5, -2.46875),
        v(4.0, 1.5, -1.96875),
    ];
    let mut scene = TriScene::from_triangles(camera(), &[a, b, c]);
    scene.camera = Camera::new(
        DVec3::new(0.0, 0.0, 10.0),
        DVec3::ZERO,
        DVec3::Y,
        Projection::Orthographic { view_height: 6.0 },
        96,
        48,
        1,
        0.01,
        100.0,
    )
    .unwrap();
    let opts = bare_options(&scene);
    let budget = rendiff::budget::Budget::new(1 << 30);
    let (bsp, _, tree) = raster::bsp::render(&scene, &opts, &budget).unwrap();
    let (zbuf, _) = raster::render(&scene, &opts);
    assert_eq!((tree.splits, tree.coplanar), (1, 1), "{tree:?}");
    let differ = bsp.id.iter().zip(&zbuf.id).filter(|(p, q)| p != q).count();
    assert_eq!(differ, 0);
}
