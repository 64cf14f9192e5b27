//! Raster against ray on every bundled scene: zero real visibility
//! mismatches, shading within the derived bound; and two negative
//! controls showing the classifier is neither blind nor trigger-happy.

use rendiff::compare::report::Report;
use rendiff::compare::{VisibilityCounts, compare_frames, derive_tolerances};
use rendiff::coverage::FillRule;
use rendiff::diff::{self, Side};
use rendiff::raster::{self, Perturb};
use rendiff::{Backend, Overrides};

use crate::util::{bundled_scenes, load};

/// Raster against ray on one bundled scene: no real mismatch, shading
/// within the bound, classes summing to the samples, no false pass, and
/// the stable summary as a snapshot.
fn bundled_scene_agrees(name: &str) {
    let job = load(name, &Overrides::default());
    let r = diff::diff(
        &job,
        name,
        &Side::Backend(Backend::Raster),
        &Side::Backend(Backend::Ray),
    )
    .unwrap();
    let v = r.report.visibility.expect("two frames");
    assert_eq!(
        v.real,
        0,
        "{name}: real visibility mismatches\n{}",
        r.report.summary()
    );
    assert_eq!(
        r.report.shading.over_threshold,
        0,
        "{name}: shading outside the bound\n{}",
        r.report.summary()
    );
    assert!(r.report.shading.max <= r.report.tolerance.shading_max);
    assert_eq!(
        v.total(),
        r.report.samples,
        "{name}: classes must sum to the samples"
    );
    assert_no_false_pass(name, &r);
    insta::assert_snapshot!(format!("raster_vs_ray__{name}"), r.report.stable_summary());
}

/// One test per bundled scene (`cargo test teapot` runs one; a failing
/// scene hides no other), and a check that the list is every scene.
macro_rules! every_bundled_scene {
    ($($scene:ident),* $(,)?) => {
        mod bundled {
            $(
                #[test]
                fn $scene() {
                    super::bundled_scene_agrees(stringify!($scene));
                }
            )*
        }

        #[test]
        fn every_bundled_scene_has_its_test() {
            let listed = [$(stringify!($scene)),*];
            assert_eq!(bundled_scenes(), listed, "add the new scene to every_bundled_scene!");
        }
    };
}

every_bundled_scene!(
    bumps,
    bunny,
    dense,
    glass,
    grazing,
    inside,
    menagerie,
    near_plane,
    painter_cycle,
    painter_floor,
    polygons,
    spheres,
    spider,
    superellipsoids,
    teapot,
    textured,
);

/// No false pass: a passing verdict between two frames allows at most
/// 0.5 % of the pixels to differ beyond 2/255 (8-bit sRGB), plus one pixel
/// per depth-tie sample (coplanar surfaces, which either may show).
pub fn assert_no_false_pass(name: &str, r: &diff::DiffResult) {
    if !r.report.passed() {
        return;
    }
    let (Some(a), Some(b)) = (frame_of(&r.a), frame_of(&r.b)) else {
        return;
    };
    let beyond = a
        .color
        .iter()
        .zip(&b.color)
        .filter(|(p, q)| {
            let d =
                |x: f32, y: f32| rendiff::color::to_srgb8(x).abs_diff(rendiff::color::to_srgb8(y));
            d(p.r, q.r).max(d(p.g, q.g)).max(d(p.b, q.b)) > 2
        })
        .count() as u64;
    let v = r.report.visibility.expect("two frames");
    let pixels = u64::from(a.width) * u64::from(a.height);
    assert!(
        beyond * 200 <= pixels + 200 * v.depth_tie,
        "{name}: a pass with {beyond} of {pixels} pixels beyond 2/255 ({} depth-tie samples)\n{}",
        v.depth_tie,
        r.report.summary()
    );
}

fn frame_of(o: &diff::Output) -> Option<&rendiff::frame::Frame> {
    o.frame()
}

/// Renders a scene's raster frame with a perturbation and classifies it
/// against the ray tracer.
fn perturbed(name: &str, perturb: Perturb) -> VisibilityCounts {
    let job = load(name, &Overrides::default());
    let mut opts = job.raster_options();
    opts.perturb = perturb;
    let (fr, _) = raster::render(&job.tri, &opts);
    let fy = job.render_with_depth(Backend::Ray, 1).unwrap().frame;
    let tol = derive_tolerances(&job.tri);
    compare_frames(&job.tri, &fr, &fy, &tol, job.settings.depth)
        .visibility
        .unwrap()
}

const CONTROL_SCENES: [&str; 4] = ["spheres", "bunny", "polygons", "menagerie"];

/// Moving the rasterizer's camera by 1/32 pixel (ten times the edge
/// tolerance) must produce real mismatches: the classifier is not blind.
#[test]
fn a_shifted_camera_is_caught() {
    let mut text = String::new();
    for name in CONTROL_SCENES {
        let v = perturbed(
            name,
            Perturb {
                offset_px: 1.0 / 32.0,
                fill_rule: FillRule::TopLeft,
            },
        );
        assert!(v.real > 0, "{name}: a 1/32 px shift went unnoticed: {v:?}");
        text.push_str(&format!("{name}: {v:?}\n"));
    }
    insta::assert_snapshot!("negative_control_shifted_camera", text);
}

/// Flipping the fill rule changes which triangle owns the samples exactly
/// on shared edges: every difference must be an edge tie, none real.
#[test]
fn a_flipped_fill_rule_gives_edge_ties_only() {
    let mut text = String::new();
    for name in CONTROL_SCENES {
        let base = perturbed(name, Perturb::default());
        let v = perturbed(
            name,
            Perturb {
                offset_px: 0.0,
                fill_rule: FillRule::BottomRight,
            },
        );
        assert_eq!(
            v.real, 0,
            "{name}: the flipped fill rule made real mismatches: {v:?}"
        );
        assert_eq!(
            (v.depth_tie, v.near_tie),
            (base.depth_tie, base.near_tie),
            "{name}"
        );
        text.push_str(&format!("{name}: {v:?}\n"));
    }
    insta::assert_snapshot!("negative_control_flipped_fill_rule", text);
}

/// The JSON verdict has the fields of DESIGN.md §5.
#[test]
fn json_verdict_has_the_documented_fields() {
    let job = load("spheres", &Overrides::default());
    let r: Report = diff::diff(
        &job,
        "scenes/spheres.toml",
        &Side::Backend(Backend::Raster),
        &Side::Backend(Backend::Ray),
    )
    .unwrap()
    .report;
    let v: serde_json::Value = serde_json::to_value(&r).unwrap();
    for key in [
        "scene",
        "width",
        "height",
        "a",
        "b",
        "samples",
        "max_depth",
        "visibility",
        "shading",
        "image",
        "tolerance",
        "time_ms",
        "verdict",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    for key in [
        "agree",
        "edge_tie",
        "depth_tie",
        "near_tie",
        "unjudgeable",
        "real",
    ] {
        assert!(
            v["visibility"].get(key).is_some(),
            "missing visibility.{key}"
        );
    }
    for key in [
        "max",
        "mean",
        "rmse",
        "psnr",
        "over_threshold",
        "ties",
        "tie_max",
    ] {
        assert!(v["shading"].get(key).is_some(), "missing shading.{key}");
    }
    for key in ["max_channel_8bit", "differing_pixels", "ssim"] {
        assert!(v["image"].get(key).is_some(), "missing image.{key}");
    }
    for key in [
        "edge_px",
        "edge_px_p99",
        "depth_rel",
        "depth_rel_p99",
        "near_eps",
        "near_eps_p99",
        "judged",
        "limits",
        "gate_eps",
        "shading_max",
    ] {
        assert!(v["tolerance"].get(key).is_some(), "missing tolerance.{key}");
    }
    // Every tolerance is finite and within its limit.
    let t = &v["tolerance"];
    let edge = t["edge_px"].as_f64().expect("a number");
    assert!(edge.is_finite() && edge <= t["limits"]["edge_px"].as_f64().unwrap());
    assert!(t["depth_rel"].as_f64().unwrap().is_finite());
    assert_eq!(v["verdict"], "pass");
    assert_eq!(v["samples"], 320 * 240);
}

/// A scene's `[tolerance]` table may tighten the derived tolerances, never
/// loosen them: a looser value is an error naming the key.
#[test]
fn tolerance_table_may_only_tighten() {
    let base = std::fs::read_to_string(crate::util::scene_path("spheres")).unwrap();
    let path = crate::util::scene_path("inline");
    let load = |extra: &str| {
        let scene =
            rendiff::scene::Scene::from_str(&path, &format!("{base}\n[tolerance]\n{extra}\n"))
                .unwrap();
        let job = rendiff::Prepared::from_scene(scene, &Overrides::default()).unwrap();
        diff::tolerances(&job).map(|(t, i)| (t.shading_max, i.pov_max8))
    };
    // Shading is bit-identical where both see the same triangle: the
    // derived bound is 0, and the table can only restate it.
    let derived = load("").unwrap();
    assert_eq!(derived.0, 0.0);
    assert_eq!(load("shading_max = 0").unwrap().0, 0.0);
    assert_eq!(load("pov_max8 = 1").unwrap().1, 1.0);
    let e = load("shading_max = 1e-9").unwrap_err().to_string();
    assert!(
        e.contains("tolerance.shading_max") && e.contains("looser"),
        "{e}"
    );
    assert!(e.contains(&format!("{}:", path.display())), "{e}");
    assert!(load("pov_fraction = 0.5").is_err());
}

/// Where both backends see the same triangle they shade it bit for bit:
/// both take the sample's weights from the one function
/// (`TriScene::view_weights`) and shade them with the same ray direction
/// and the same shadow rays. Checked where the weights are most fragile:
/// a 170° field of view (rays at 85° to the view axis), 8×8 samples per
/// pixel, and the scene moved 10⁴ from the origin, on the scenes with
/// textures, bump maps and smooth meshes.
#[test]
fn shading_is_bit_identical_where_both_see_the_same_triangle() {
    use rendiff::math::DVec3;
    use rendiff::scene::ProjectionDesc;
    let mut text = String::new();
    for name in ["textured", "bumps", "bunny"] {
        let base = crate::util::load(name, &Overrides::default()).scene;
        let wide = {
            let mut s = base.clone();
            s.camera.projection = ProjectionDesc::Perspective { fov_y_deg: 170.0 };
            s
        };
        let moved = base.scaled(1.0, DVec3::new(1e4, -1e4, 1e4)).unwrap();
        for (what, scene, samples, size) in [
            ("fov 170", wide, None, Some((160, 120))),
            ("8x8 samples", base.clone(), Some(8), Some((80, 60))),
            ("moved 1e4", moved, None, None),
        ] {
            let job = rendiff::Prepared::from_scene(
                scene,
                &Overrides {
                    samples,
                    size,
                    ..Overrides::default()
                },
            )
            .unwrap();
            let r = diff::diff(
                &job,
                name,
                &Side::Backend(Backend::Raster),
                &Side::Backend(Backend::Ray),
            )
            .unwrap();
            let v = r.report.visibility.unwrap();
            assert_eq!(
                (
                    r.report.shading.max,
                    r.report.shading.over_threshold,
                    v.real,
                    v.unjudgeable
                ),
                (0.0, 0, 0, 0),
                "{name}, {what}:\n{}",
                r.report.summary()
            );
            // Bit for bit: every agreeing sample that is not a shading tie.
            let (Some(a), Some(b)) = (frame_of(&r.a), frame_of(&r.b)) else {
                unreachable!("two frames");
            };
            let mut same = 0u64;
            for i in 0..a.id.len() {
                if a.id[i] == b.id[i] && !r.comparison.ties[i] {
                    assert_eq!(
                        a.sample_colors()[i].to_array().map(f32::to_bits),
                        b.sample_colors()[i].to_array().map(f32::to_bits),
                        "{name}, {what}: sample {i}"
                    );
                    same += 1;
                }
            }
            text.push_str(&format!("{name}, {what}: {same} samples bit-identical\n"));
        }
    }
    eprintln!("{text}");
}

/// Controls written against the verdict from outside (each once passed
/// with a visibly wrong image): what the rasterizer gets wrong through its
/// chosen approximation must fail the verdict, not pass as ties.
#[test]
fn approximations_that_lose_surfaces_or_shadows_fail() {
    use rendiff::options::{DepthFormat, ShadowMode};
    let path = |n: &str| crate::util::root().join(format!("tests/data/controls/{n}.toml"));
    let verdict = |name: &str, ov: Overrides| {
        let job = rendiff::Prepared::load(&path(name), &ov).unwrap();
        diff::diff(
            &job,
            name,
            &Side::Backend(Backend::Raster),
            &Side::Backend(Backend::Ray),
        )
        .unwrap()
        .report
    };
    // Shadow rays: the fence's shadow is the same in both.
    assert!(verdict("thin_fence", Overrides::default()).passed());
    // A 256² shadow map loses most slats: 10 % of the pixels. (It passed as
    // 8 044 shadow-boundary ties when one frame's boundary was enough.)
    let r = verdict(
        "thin_fence",
        Overrides {
            shadows: Some(ShadowMode::Map(256)),
            ..Overrides::default()
        },
    );
    assert!(
        !r.passed() && r.shading.over_threshold > 1000,
        "{}",
        r.summary()
    );
    // f32 depth resolves the picture in front of the wall.
    assert!(verdict("walls_gap", Overrides::default()).passed());
    // 16-bit depth cannot: the picture vanishes behind the wall. Not a depth
    // tie (the two are a fifth of their depth apart): unjudgeable.
    let r = verdict(
        "walls_gap",
        Overrides {
            depth: Some(DepthFormat::U16),
            ..Overrides::default()
        },
    );
    let v = r.visibility.unwrap();
    assert!(
        !r.passed() && v.unjudgeable > 1000 && v.depth_tie == 0,
        "{}",
        r.summary()
    );
}
