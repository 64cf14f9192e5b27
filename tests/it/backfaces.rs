//! Why a ray tracer cannot cull back faces and a rasterizer can (DESIGN.md
//! §7: "the ray tracer never culls (rays of the ray tree come from
//! behind)"), shown rather than stated. With culling forced on, the ray
//! tracer's refracted rays lose the surfaces they leave their objects by:
//! every ray refracted into a closed object meets its next surface from
//! inside, a back face, and culling removes exactly those hits — the
//! picture changes. The camera's own rays, from outside every closed
//! object, meet front faces first, so primary visibility is the same
//! either way, in the ray tracer and in the rasterizer.

use rendiff::accel::{Accel, AccelOptions};
use rendiff::compare::Oracle;
use rendiff::compare::oracle::Class;
use rendiff::frame::BACKGROUND;
use rendiff::options::Geometry;
use rendiff::ray::{CullStats, Faces, RayOptions, render_counted, render_faces};
use rendiff::{GATE_EPS, Overrides, Prepared};

use crate::util::load;

/// The ray tracer on `job` at `max_depth`: (plain frame, unculled frame
/// and counts, culled frame and counts).
fn traced(
    job: &Prepared,
    max_depth: u32,
) -> (
    rendiff::frame::Frame,
    (rendiff::frame::Frame, CullStats),
    (rendiff::frame::Frame, CullStats),
) {
    let accel = Accel::new(
        &job.tri,
        AccelOptions {
            geometry: Geometry::Mesh,
            bvh: job.plan.bvh,
            ..AccelOptions::default()
        },
    );
    let opts = RayOptions {
        max_depth,
        shadows: job.plan.shadows,
        gate_eps: GATE_EPS,
    };
    let (plain, _) = render_counted(&accel, &opts);
    let (both, _, hit) = render_faces(&accel, &opts, Faces::Both);
    let (front, _, lost) = render_faces(&accel, &opts, Faces::Front);
    (plain, (both, hit), (front, lost))
}

#[test]
fn culling_loses_the_exit_surfaces_of_refracting_objects() {
    // glass: a glass sphere (ior 1.5) and an amber box (ior 1.33), both
    // closed, over an open mirror floor; the eye outside everything.
    let job = load("glass", &Overrides::default());
    let scene_depth = job.settings.max_depth;
    let mut report = String::new();
    let mut first_exits = 0;
    for max_depth in [2, scene_depth] {
        let (plain, (both, hit), (front, lost)) = traced(&job, max_depth);
        // Counting changes nothing.
        assert_eq!(plain.color, both.color, "max_depth {max_depth}");
        assert_eq!(plain.id, both.id);
        // The camera's rays meet front faces only: the same primary hits.
        assert_eq!(
            both.id, front.id,
            "max_depth {max_depth}: primary visibility"
        );
        assert!(hit.entries > 0 && hit.exits > 0, "{hit:?}");
        if max_depth == 2 {
            // Level 2 is the last: the rays refracted into the sphere and
            // the box at the camera's hits spawn nothing. Each leaves its
            // (convex, closed) object through a back face — the only back
            // faces any ray meets — and culling loses every one of those
            // hits and no other, since the trees agree up to them.
            assert_eq!(hit.exits, hit.entries, "{hit:?}");
            assert_eq!(hit.back_faces, hit.exits, "{hit:?}");
            assert_eq!(lost, hit, "culled {lost:?} against unculled {hit:?}");
            first_exits = hit.exits;
        } else {
            // Deeper, the culled trees differ after their first loss, but
            // up to it they are the same: every deeper tree loses at least
            // the exits of the rays refracted in at the camera's hits.
            assert!(lost.exits >= first_exits && first_exits > 0, "{lost:?}");
            assert!(hit.exits > first_exits, "{hit:?}");
        }
        let changed = plain
            .color
            .iter()
            .zip(&front.color)
            .filter(|(a, b)| a != b)
            .count();
        assert!(
            changed > 0,
            "max_depth {max_depth}: culling changed no pixel"
        );
        report.push_str(&format!(
            "max_depth {max_depth}: unculled {hit:?}; culled {lost:?}; {changed} of {} pixels changed\n",
            plain.color.len()
        ));
    }
    eprint!("{report}");
}

/// On scenes whose closed objects the camera is outside of, the
/// rasterizer's primary visibility with every closed object's back faces
/// culled is the unculled one, sample for sample, apart from samples on a
/// silhouette where a back face and a front face tie (each checked to be
/// an edge or depth tie by the oracle, and counted).
#[test]
fn the_rasterizer_sees_the_same_culled_or_not_on_closed_meshes() {
    let mut report = String::new();
    for name in ["glass", "spheres", "superellipsoids", "bunny", "menagerie"] {
        let job = load(
            name,
            &Overrides {
                no_plan: true,
                ..Overrides::default()
            },
        );
        let tri = &job.tri;
        let closed: Vec<bool> = tri.objects.iter().map(|o| o.closed).collect();
        assert!(closed.iter().any(|&c| c), "{name}: no closed object");
        let mut opts = job.raster_options();
        opts.backface_cull = vec![false; closed.len()];
        let unculled = rendiff::raster::visibility(tri, &opts);
        opts.backface_cull = closed.clone();
        let culled = rendiff::raster::visibility(tri, &opts);
        assert!(culled.stats.culled.backface > 0, "{name}: nothing culled");
        let oracle = Oracle::new(tri, job.settings.depth);
        let cam = &tri.camera;
        let sw = cam.sample_width() as usize;
        let mut ties = 0;
        for i in 0..culled.id.len() {
            let (a, b) = (culled.id[i], unculled.id[i]);
            if a == b {
                continue;
            }
            assert_ne!(b, BACKGROUND, "{name}: culling added a surface");
            assert!(
                closed[tri.tri_object[b as usize] as usize],
                "{name}: sample {i} lost a triangle of an open object"
            );
            let (x, y) = cam.sample_point((i % sw) as u32, (i / sw) as u32);
            let id = |v: u32| (v != BACKGROUND).then_some(v);
            let class = oracle.classify(x, y, id(a), id(b));
            assert!(
                matches!(class, Class::EdgeTie | Class::DepthTie),
                "{name}: sample {i}: culled shows {a}, unculled the back face {b}: {class:?}"
            );
            ties += 1;
        }
        report.push_str(&format!(
            "{name:16} {} back faces culled, {} samples, {ties} silhouette ties\n",
            culled.stats.culled.backface,
            culled.id.len()
        ));
    }
    eprint!("{report}");
}
