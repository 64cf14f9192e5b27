//! Both backends against the stored POV-Ray 3.7 references
//! (`golden/pov`), without POV-Ray: mesh mode to the 8-bit bound with
//! every pixel beyond it explained, analytic spheres exactly, the
//! tessellation error of curved shapes measured; stale references fail.

use rendiff::accel::{Accel, AccelOptions};
use rendiff::color::to_srgb8;
use rendiff::compare::Oracle;
use rendiff::compare::explain::{Explained, explain};
use rendiff::image_io::read_png_linear;
use rendiff::options::Geometry;
use rendiff::pov::golden::{self, Variant};
use rendiff::scene::Scene;
use rendiff::{Backend, Overrides, Prepared};

use crate::util::{bundled_scenes, load, root, scene_path};

/// The 8-bit sRGB bound and the fraction of pixels that must meet it
/// (the acceptance: 2/255 on ≥ 99.9 %). POVRAY.md measured the
/// numpy reference at 1/65535 of POV-Ray everywhere; 2/255 leaves room for
/// the f32 shading arithmetic and POV-Ray's f32 colours.
const MAX8: u8 = 2;
const FRACTION: f64 = 0.999;

/// A scene name, why it is excepted, and the count of its documented cause.
type Exception = (&'static str, &'static str, fn(&Explained) -> u64);

/// Scenes kept out of the tight group, why, and the one cause that their
/// extra differences must have: with those pixels set aside, the scene
/// still meets the bound on ≥ 99.9 % of its pixels.
const EXCEPTIONS: &[Exception] = &[
    (
        "near_plane",
        "geometry nearer than `near`, which POV-Ray does not clip",
        |e| e.near_plane,
    ),
    (
        "polygons",
        "a sticker coplanar with a wall: each renderer breaks the depth tie its own way",
        |e| e.depth_tie,
    ),
    (
        "bumps",
        "a sphere bump-mapped by Blinn's method, which POV-Ray does not have",
        |e| e.blinn_bump,
    ),
];

fn golden_dir() -> std::path::PathBuf {
    root().join("golden/pov")
}

/// Fraction of pixels within the 8-bit bound.
fn within(a: &[rendiff::color::Rgb], b: &[rendiff::color::Rgb]) -> (f64, u8) {
    let mut ok = 0usize;
    let mut max = 0u8;
    for (p, q) in a.iter().zip(b) {
        let d = [(p.r, q.r), (p.g, q.g), (p.b, q.b)]
            .iter()
            .map(|(x, y)| to_srgb8(*x).abs_diff(to_srgb8(*y)))
            .max()
            .unwrap_or(0);
        max = max.max(d);
        ok += usize::from(d <= MAX8);
    }
    (ok as f64 / a.len() as f64, max)
}

#[test]
fn references_exist_and_are_not_stale() {
    let mut problems = Vec::new();
    for name in bundled_scenes() {
        let job = load(&name, &Overrides::default());
        problems.extend(golden::stale(&job.scene, &job.tri, &golden_dir()).unwrap());
    }
    assert!(
        problems.is_empty(),
        "stale or missing POV-Ray references (run `make golden`):\n{}",
        problems.join("\n")
    );
}

#[test]
fn a_changed_scene_makes_its_reference_stale() {
    let job = load("spheres", &Overrides::default());
    let mut scene = job.scene.clone();
    scene.materials[0].diffuse += 0.01;
    let changed = Prepared::from_scene(scene, &Overrides::default()).unwrap();
    let problems = golden::stale(&changed.scene, &changed.tri, &golden_dir()).unwrap();
    assert!(problems.iter().any(|p| p.contains("stale")), "{problems:?}");
    // And a scene without references is reported missing.
    let text = std::fs::read_to_string(scene_path("spheres")).unwrap();
    let orphan = Scene::from_str(&root().join("scenes/no_such_scene.toml"), &text).unwrap();
    let job = Prepared::from_scene(orphan, &Overrides::default()).unwrap();
    let problems = golden::stale(&job.scene, &job.tri, &golden_dir()).unwrap();
    assert!(
        problems.iter().any(|p| p.contains("missing")),
        "{problems:?}"
    );
}

/// Compares a backend with a reference; returns (within fraction, max 8-bit, explanations).
fn against(
    job: &Prepared,
    backend: Backend,
    variant: Variant,
    geometry: Geometry,
) -> (f64, u8, Explained) {
    let depth = if variant == Variant::Depth1 {
        1
    } else {
        job.settings.max_depth
    };
    let reference =
        read_png_linear(&golden::reference_path(&golden_dir(), &job.scene, variant)).unwrap();
    let frame = match (backend, geometry) {
        (Backend::Ray, Geometry::Analytic) => {
            let accel = Accel::new(
                &job.tri,
                AccelOptions {
                    geometry,
                    bvh: true,
                    ..AccelOptions::default()
                },
            );
            rendiff::ray::render(
                &accel,
                &rendiff::ray::RayOptions {
                    max_depth: depth,
                    shadows: true,
                    gate_eps: rendiff::GATE_EPS,
                },
            )
        }
        _ => job.render_with_depth(backend, depth).unwrap().frame,
    };
    let (frac, max8) = within(&frame.color, &reference.pixels);
    let accel = Accel::new(&job.tri, AccelOptions::default());
    let oracle = Oracle::new(&job.tri, job.settings.depth);
    let (explained, _) = explain(&frame, &reference.pixels, &accel, &oracle, MAX8);
    (frac, max8, explained)
}

/// Mesh mode: the ray tracer against the scene's reference, the
/// rasterizer against the max_depth = 1 one, each within 2/255 on ≥ 99.9 %
/// of the pixels and every pixel beyond explained.
#[test]
fn both_backends_match_povray_in_mesh_mode() {
    let mut report = String::new();
    let mut checked = 0;
    for name in bundled_scenes() {
        let job = load(&name, &Overrides::default());
        let has_d1 = golden::reference_path(&golden_dir(), &job.scene, Variant::Depth1).exists();
        for (backend, variant) in [
            (Backend::Ray, Variant::Main),
            (
                Backend::Raster,
                if has_d1 {
                    Variant::Depth1
                } else {
                    Variant::Main
                },
            ),
        ] {
            let (frac, max8, e) = against(&job, backend, variant, Geometry::Mesh);
            report.push_str(&format!(
                "{name:16} {backend:6} vs {:7}: {:.4} % within 2/255, max {max8}/255; beyond: {} at edges, {} depth ties, {} shadow/gate, {} near plane, {} ray tree, {} Blinn bump, {} unexplained\n",
                format!("pov{}", variant.suffix()),
                frac * 100.0,
                e.edge,
                e.depth_tie,
                e.shadow_or_gate,
                e.near_plane,
                e.ray_tree,
                e.blinn_bump,
                e.unexplained
            ));
            if let Some((_, why, cause)) = EXCEPTIONS.iter().find(|(n, ..)| *n == name) {
                report.push_str(&format!("{:16} (out of the tight group: {why})\n", ""));
                // Still: every differing pixel is explained, and apart
                // from the documented cause the scene meets the bound.
                assert_eq!(e.unexplained, 0, "{name} {backend}: unexplained pixels");
                let pixels = f64::from(job.tri.camera.width() * job.tri.camera.height());
                let rest = frac + cause(&e) as f64 / pixels;
                assert!(
                    rest >= FRACTION,
                    "{name} {backend}: {:.3} % within 2/255 with the documented cause set aside",
                    rest * 100.0
                );
                continue;
            }
            assert!(
                frac >= FRACTION,
                "{name} {backend}: only {:.3} % within 2/255",
                frac * 100.0
            );
            assert_eq!(
                e.unexplained, 0,
                "{name} {backend}: {} pixels beyond 2/255 unexplained",
                e.unexplained
            );
            // Differences born along secondary rays stay rare: at most 1 in 10^4 pixels.
            assert!(
                e.ray_tree * 10_000 <= u64::from(job.tri.camera.width() * job.tri.camera.height()),
                "{name} {backend}: {} ray-tree differences",
                e.ray_tree
            );
            checked += 1;
        }
    }
    eprint!("{report}");
    assert!(checked >= 20, "{checked} comparisons in the tight group");
}

/// Analytic shapes: the ray tracer's exact spheres, boxes and
/// superellipsoids (any transform, by the inverse-affine ray transform)
/// against POV-Ray's own primitives, on every scene that has them: the
/// same bound as the mesh mode, every pixel beyond it explained (`bumps`:
/// apart from its Blinn-bumped sphere).
#[test]
fn analytic_shapes_match_povray() {
    let mut checked = 0;
    for name in bundled_scenes() {
        let job = load(&name, &Overrides::default());
        if !golden::reference_path(&golden_dir(), &job.scene, Variant::Analytic).exists() {
            continue;
        }
        let (frac, max8, e) = against(&job, Backend::Ray, Variant::Analytic, Geometry::Analytic);
        eprintln!(
            "{name:16} analytic: {:.4} % within 2/255, max {max8}/255; beyond: {} edges, {} shadow/gate, {} ray tree, {} near plane, {} Blinn bump, {} unexplained",
            frac * 100.0,
            e.edge,
            e.shadow_or_gate,
            e.ray_tree,
            e.near_plane,
            e.blinn_bump,
            e.unexplained
        );
        assert_eq!(e.unexplained, 0, "{name}");
        let pixels = f64::from(job.tri.camera.width() * job.tri.camera.height());
        let set_aside = EXCEPTIONS
            .iter()
            .find(|(n, ..)| *n == name)
            .map_or(0.0, |(_, _, cause)| cause(&e) as f64);
        assert!(
            frac + set_aside / pixels >= FRACTION,
            "{name}: {:.3} % within 2/255",
            frac * 100.0
        );
        checked += 1;
    }
    assert!(checked >= 10, "{checked} scenes with analytic references");
}

/// The tessellation error, measured: the mesh render of curved shapes at
/// several `tessellation_error` settings against POV-Ray's analytic
/// render. The error shrinks as the tessellation gets finer.
#[test]
fn tessellation_error_against_povray_analytic() {
    let mut table =
        String::from("scene            tess_err  triangles  >2/255 px  mean |Δ|   max 8-bit\n");
    for name in ["spheres", "superellipsoids"] {
        let base = Scene::load(&scene_path(name)).unwrap();
        let reference = read_png_linear(&golden::reference_path(
            &golden_dir(),
            &base,
            Variant::Analytic,
        ))
        .unwrap();
        let mut last = usize::MAX;
        for err in [2.0, 1.0, 0.5, 0.25, 0.1] {
            let mut scene = base.clone();
            scene.render.tessellation_error = err;
            let job = Prepared::from_scene(scene, &Overrides::default()).unwrap();
            let frame = job.render(Backend::Ray).unwrap().frame;
            let mut beyond = 0usize;
            let mut sum = 0.0f64;
            let mut max = 0u8;
            for (p, q) in frame.color.iter().zip(&reference.pixels) {
                let d = [(p.r, q.r), (p.g, q.g), (p.b, q.b)]
                    .iter()
                    .map(|(x, y)| to_srgb8(*x).abs_diff(to_srgb8(*y)))
                    .max()
                    .unwrap_or(0);
                beyond += usize::from(d > MAX8);
                max = max.max(d);
                sum += f64::from(p.max_abs_diff(*q));
            }
            table.push_str(&format!(
                "{name:16} {err:8}  {:9}  {beyond:9}  {:.2e}   {max}\n",
                job.tri.len(),
                sum / frame.color.len() as f64
            ));
            assert!(
                beyond <= last.saturating_add(last / 4 + 20),
                "{name}: the error grew at tessellation_error {err}"
            );
            last = beyond;
        }
        // The analytic shapes themselves: below every tessellation.
        let job = Prepared::from_scene(
            base.clone(),
            &Overrides {
                geometry: Some(Geometry::Analytic),
                ..Overrides::default()
            },
        )
        .unwrap();
        let frame = job.render(Backend::Ray).unwrap().frame;
        let (frac, max) = within(&frame.color, &reference.pixels);
        let beyond = ((1.0 - frac) * frame.color.len() as f64).round() as usize;
        table.push_str(&format!(
            "{name:16} analytic  {:>9}  {beyond:9}  {:>8}   {max}\n",
            "-", "-"
        ));
        assert!(
            beyond <= last,
            "{name}: analytic {beyond} > finest tessellation {last}"
        );
    }
    eprint!("{table}");
}

/// The export text of every bundled scene (large arrays abridged to their
/// count and hash), mesh and analytic.
#[test]
fn export_text_snapshots() {
    use rendiff::pov::{ExportOptions, export};
    for name in bundled_scenes() {
        let job = load(&name, &Overrides::default());
        for geometry in [Geometry::Mesh, Geometry::Analytic] {
            let e = export(
                &job.scene,
                &job.tri,
                &ExportOptions {
                    geometry,
                    max_depth: job.settings.max_depth,
                    abridged: true,
                },
            )
            .unwrap();
            insta::assert_snapshot!(format!("export_{name}_{geometry}"), e.text);
        }
    }
}
