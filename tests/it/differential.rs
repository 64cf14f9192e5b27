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

#[test]
fn every_bundled_scene_agrees() {
    let scenes = bundled_scenes();
    assert!(scenes.len() >= 12, "{} bundled scenes", scenes.len());
    for name in &scenes {
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
        insta::assert_snapshot!(format!("raster_vs_ray__{name}"), r.report.stable_summary());
    }
}

/// Renders a scene's raster frame with a perturbation and classifies it
/// against the ray tracer.
fn perturbed(name: &str, perturb: Perturb) -> VisibilityCounts {
    let job = load(name, &Overrides::default());
    let mut opts = job.raster_options();
    opts.perturb = perturb;
    let (fr, _) = raster::render(&job.tri, &opts);
    let fy = job.render_with_depth(Backend::Ray, 1).frame;
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
