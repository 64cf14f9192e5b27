//! Hidden lines: Appel's incremental quantitative invisibility agrees with
//! a ray count on every piece, and the drawing agrees with the z-buffer's
//! triangle ids — points along a visible piece see the edge's own
//! triangles, points along a hidden one do not — away from the ends of
//! the pieces, where a crossing or a vertex makes the answer ambiguous.

use rendiff::accel::{Accel, AccelOptions};
use rendiff::lines::{Drawing, LinesOptions, hidden_lines};
use rendiff::raster;
use rendiff::{Overrides, Prepared};

use crate::util::load;

/// Scenes with several overlapping objects, open and closed meshes,
/// curved and flat shapes, perspective and orthographic cameras.
const SCENES: [&str; 6] = [
    "menagerie",
    "spheres",
    "superellipsoids",
    "painter_cycle",
    "polygons",
    "teapot",
];

fn drawing(job: &Prepared, hidden: bool, verify: bool) -> Drawing {
    let accel = Accel::new(&job.tri, AccelOptions::default());
    hidden_lines(
        &job.tri,
        &accel,
        &LinesOptions {
            hidden,
            verify,
            ..LinesOptions::default()
        },
    )
}

/// Checks a drawing against the z-buffer: at points along each piece
/// (every 0.5 px, skipping 1.5 px at each end, where a crossing or a
/// vertex lies), the 3×3 samples around the point either all see
/// something nearer than the edge (the point is hidden) or not (it shows
/// through somewhere nearby). Where they are mixed — the point lies
/// within a sample of an occluder's outline, the PARTIAL band — the
/// z-buffer cannot tell and the point is skipped; elsewhere a visible
/// piece must not be hidden and a hidden piece must not show.
/// Returns (points checked, points skipped, disagreements, examples).
fn zbuffer_check(job: &Prepared, d: &Drawing) -> (usize, usize, usize, Vec<String>) {
    let (frame, _) = raster::render(&job.tri, &job.raster_options());
    let cam = &job.tri.camera;
    let n = f64::from(cam.samples());
    let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
    let (sw, sh) = (
        i64::from(cam.sample_width()),
        i64::from(cam.sample_height()),
    );
    let (mut checked, mut skipped, mut bad) = (0usize, 0usize, 0usize);
    let mut examples = Vec::new();
    for seg in &d.segments {
        let len = (seg.b.0 - seg.a.0).hypot(seg.b.1 - seg.a.1);
        let steps = (2.0 * len).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let u = k as f64 / steps as f64;
            let p = seg.p[0] + (seg.p[1] - seg.p[0]) * u;
            let Some((x, y, _)) = cam.project(p) else {
                continue;
            };
            let (da, db) = (
                (x - seg.a.0).hypot(y - seg.a.1),
                (x - seg.b.0).hypot(y - seg.b.1),
            );
            if da < 1.5 || db < 1.5 || x < 1.0 || y < 1.0 || x > w - 1.0 || y > h - 1.0 {
                continue;
            }
            // The edge point's depth, and how much nearer a sample must be
            // to count as in front (the relative error of the f32 depths).
            let t = cam.frame_depth(p);
            let tol = 1e-4 * t;
            let (cx, cy) = ((x * n).floor() as i64, (y * n).floor() as i64);
            let (mut front, mut total) = (0, 0);
            for oy in -1..=1 {
                for ox in -1..=1 {
                    let (sx, sy) = (cx + ox, cy + oy);
                    if sx < 0 || sy < 0 || sx >= sw || sy >= sh {
                        continue;
                    }
                    let i = (sy * sw + sx) as usize;
                    total += 1;
                    if !seg.tris.contains(&frame.id[i]) && f64::from(frame.depth[i]) < t - tol {
                        front += 1;
                    }
                }
            }
            let hidden_here = front == total;
            let shown_here = front == 0;
            if !hidden_here && !shown_here {
                skipped += 1;
                continue;
            }
            checked += 1;
            if hidden_here != (seg.qi > 0) {
                bad += 1;
                if examples.len() < 5 {
                    examples.push(format!("{:?} qi {} at ({x:.1}, {y:.1})", seg.kind, seg.qi));
                }
            }
        }
    }
    (checked, skipped, bad, examples)
}

#[test]
fn appel_qi_agrees_with_ray_counts() {
    let mut report = String::new();
    for name in SCENES {
        let job = load(name, &Overrides::default());
        let d = drawing(&job, true, true);
        let s = d.stats;
        report.push_str(&format!(
            "{name:16} {} edges, {} drawn, {} contours, {} QI changes, {} pieces verified, {} mismatches\n",
            s.edges, s.drawn_edges, s.contours, s.qi_changes, s.verified, s.mismatches
        ));
        assert!(s.verified > 0);
        assert_eq!(s.mismatches, 0, "{name}: {s:?}");
    }
    eprint!("{report}");
}

#[test]
fn visible_lines_are_visible_in_the_zbuffer() {
    let mut report = String::new();
    for name in SCENES {
        let job = load(name, &Overrides::default());
        let d = drawing(&job, true, false);
        let (checked, skipped, bad, examples) = zbuffer_check(&job, &d);
        report.push_str(&format!(
            "{name:16} {checked} points checked, {skipped} in the partial band, {bad} disagree {examples:?}\n"
        ));
        assert!(checked > 100, "{name}: {checked} points");
        assert_eq!(bad, 0, "{name}: {examples:?}");
    }
    eprint!("{report}");
}

/// The check can fail: the same drawing with visible and hidden swapped
/// disagrees with the z-buffer nearly everywhere it is checked.
#[test]
fn the_zbuffer_check_catches_a_wrong_drawing() {
    let job = load("menagerie", &Overrides::default());
    let mut d = drawing(&job, true, false);
    for s in &mut d.segments {
        s.qi = u32::from(s.qi == 0);
    }
    let (checked, _, bad, _) = zbuffer_check(&job, &d);
    assert!(bad * 10 >= checked * 9, "{bad} of {checked} disagree");
}
