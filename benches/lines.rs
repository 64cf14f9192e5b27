//! Hidden lines: Appel's quantitative invisibility against Roberts'
//! algorithm on the same scenes as the edges grow, on one thread: a k×k
//! grid of boxes (k = 2 … 32: the objects grow with the edges) and a 3×3
//! grid of superellipsoids ⟨0.5, 0.8⟩ at growing tessellation (nine
//! objects, more edges each). Appel's time includes its BVH, Roberts' its
//! convexity checks, as `rendiff lines` measures them. The scenes are
//! built before the timed closures; each setting prints its counts once
//! (edges drawn, Roberts' edge–object pairs and plane clips). See the
//! README's lines section for the table.

#![allow(
    clippy::cast_precision_loss,
    reason = "bench fixtures: small grid indices turned into coordinates"
)]

use std::path::Path;

use divan::{Bencher, black_box};
use rendiff::accel::{Accel, AccelOptions};
use rendiff::lines::{LinesOptions, hidden_lines, roberts_lines};
use rendiff::scene::Scene;
use rendiff::{Overrides, Prepared};

fn main() {
    divan::main();
}

const HEADER: &str = r#"
[image]
width = 640
height = 480

[[lights]]
kind = "point"
position = [4.0, 8.0, 6.0]
color = [1.0, 1.0, 1.0]

[materials.grey]
pigment = [0.7, 0.7, 0.7]
"#;

/// A k×k grid of boxes of varied heights and turns on a floor, seen from
/// above one corner so that the rows hide each other.
fn box_grid(k: u32) -> String {
    let kf = f64::from(k);
    let mut s = format!(
        "{HEADER}\n[camera]\neye = [{:.3}, {:.3}, {:.3}]\nlook_at = [0.0, 0.0, 0.0]\nup = [0.0, 1.0, 0.0]\nfov_y = 45.0\n",
        0.45 * kf + 1.0,
        0.55 * kf + 1.0,
        0.95 * kf + 2.0
    );
    s.push_str(&format!(
        "\n[[objects]]\nkind = \"box\"\nmaterial = \"grey\"\nmin = [{a:.3}, -0.2, {a:.3}]\nmax = [{b:.3}, 0.0, {b:.3}]\n",
        a = -0.5 * kf - 0.5,
        b = 0.5 * kf + 0.5
    ));
    for i in 0..k {
        for j in 0..k {
            let (x, z) = (
                f64::from(i) - 0.5 * (kf - 1.0),
                f64::from(j) - 0.5 * (kf - 1.0),
            );
            let h = 0.4 + 0.3 * f64::from((i * 7 + j * 3) % 5);
            let turn = f64::from((i * 13 + j * 29) % 40);
            s.push_str(&format!(
                "\n[[objects]]\nkind = \"box\"\nmaterial = \"grey\"\nmin = [-0.3, 0.0, -0.3]\nmax = [0.3, {h:.3}, 0.3]\ntransform = [ {{ rotate = [0.0, {turn:.1}, 0.0] }}, {{ translate = [{x:.3}, 0.0, {z:.3}] }} ]\n"
            ));
        }
    }
    s
}

/// A 3×3 grid of ⟨0.5, 0.8⟩ superellipsoids with `n` segments each, on a
/// floor, overlapping on the screen.
fn blob_grid(n: u32) -> String {
    let mut s = format!(
        "{HEADER}\n[camera]\neye = [2.2, 2.6, 5.2]\nlook_at = [0.0, 0.3, 0.0]\nup = [0.0, 1.0, 0.0]\nfov_y = 45.0\n\n[[objects]]\nkind = \"box\"\nmaterial = \"grey\"\nmin = [-2.5, -0.2, -2.5]\nmax = [2.5, 0.0, 2.5]\n"
    );
    for i in 0..3 {
        for j in 0..3 {
            let (x, z) = (f64::from(i) - 1.0, f64::from(j) - 1.0);
            s.push_str(&format!(
                "\n[[objects]]\nkind = \"superellipsoid\"\nmaterial = \"grey\"\nexponents = [0.5, 0.8]\ntessellation = {n}\ntransform = [ {{ scale = [0.42, 0.42, 0.42] }}, {{ rotate = [-90.0, {:.1}, 0.0] }}, {{ translate = [{x:.3}, 0.42, {z:.3}] }} ]\n",
                f64::from(i * 3 + j) * 11.0
            ));
        }
    }
    s
}

fn prepare(text: &str) -> Prepared {
    let scene = Scene::from_str(Path::new("bench.toml"), text).unwrap();
    Prepared::from_scene(scene, &Overrides::default()).unwrap()
}

fn one_thread() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
}

/// Prints the counts of one setting (once, before it is timed).
fn counts(label: &str, job: &Prepared) {
    let r = roberts_lines(&job.tri, &LinesOptions::default()).unwrap();
    let s = r.stats;
    eprintln!(
        "{label}: {} triangles, {} objects, {} edges drawn, {} pairs ({} box-rejected), {} plane clips, {} visible pieces",
        job.tri.len(),
        s.objects,
        s.drawn_edges,
        s.pairs,
        s.box_rejected,
        s.plane_tests,
        s.visible
    );
}

const GRID: &[u32] = &[2, 4, 8, 16, 32];
const SEGMENTS: &[u32] = &[16, 32, 64, 128, 256];

fn appel(bencher: Bencher, job: &Prepared) {
    let pool = one_thread();
    bencher.bench(|| {
        pool.install(|| {
            let accel = Accel::new(&job.tri, AccelOptions::default());
            black_box(hidden_lines(&job.tri, &accel, &LinesOptions::default()))
        })
    });
}

fn roberts(bencher: Bencher, job: &Prepared) {
    let pool = one_thread();
    bencher.bench(|| {
        pool.install(|| black_box(roberts_lines(&job.tri, &LinesOptions::default()).unwrap()))
    });
}

#[divan::bench(args = GRID, sample_count = 7)]
fn appel_boxes(bencher: Bencher, k: u32) {
    appel(bencher, &prepare(&box_grid(k)));
}

#[divan::bench(args = GRID, sample_count = 7)]
fn roberts_boxes(bencher: Bencher, k: u32) {
    let job = prepare(&box_grid(k));
    counts(&format!("boxes {k}x{k}"), &job);
    roberts(bencher, &job);
}

#[divan::bench(args = SEGMENTS, sample_count = 7)]
fn appel_superellipsoids(bencher: Bencher, n: u32) {
    appel(bencher, &prepare(&blob_grid(n)));
}

#[divan::bench(args = SEGMENTS, sample_count = 7)]
fn roberts_superellipsoids(bencher: Bencher, n: u32) {
    let job = prepare(&blob_grid(n));
    counts(&format!("superellipsoids n = {n}"), &job);
    roberts(bencher, &job);
}
