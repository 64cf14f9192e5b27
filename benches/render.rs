//! Performance of the pieces that dominate a frame, on the 940 544-triangle
//! bunny at 1920×1080 (`benches/scenes/bunny_1m.toml`, subdivided 4 times):
//! BVH build, primary and shadow rays, the rasterizer's visibility pass and
//! full frames, on one thread and on all threads; and loading and
//! tessellating the largest bundled meshes. See benches/README.md.

#![allow(
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test and bench fixtures: small generated counts, indices and rates, where a wrong cast fails the check instead of reaching a user"
)]
use std::path::Path;
use std::sync::OnceLock;

use divan::counter::ItemsCount;
use divan::{Bencher, black_box};
use rendiff::accel::{Accel, AccelOptions, ShadowRays};
use rendiff::math::Ray64;
use rendiff::raster;
use rendiff::shade::Visibility;
use rendiff::tri_scene::TriScene;
use rendiff::{Overrides, Prepared};

fn main() {
    divan::main();
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The 940k-triangle scene, built once.
fn bunny() -> &'static (Prepared, TriScene) {
    static S: OnceLock<(Prepared, TriScene)> = OnceLock::new();
    S.get_or_init(|| {
        let job = Prepared::load(
            &root().join("benches/scenes/bunny_1m.toml"),
            &Overrides::default(),
        )
        .unwrap();
        let t = job.tri.subdivided(4);
        (job, t)
    })
}

/// Threads: 1, and all of the machine's.
const THREADS: &[usize] = &[1, 0];

fn pool(threads: usize) -> rayon::ThreadPool {
    let mut b = rayon::ThreadPoolBuilder::new();
    if threads > 0 {
        b = b.num_threads(threads);
    }
    b.build().unwrap()
}

/// Loading and tessellating the scene with the two largest bundled meshes
/// (Snowden 37 629 and the dragon 11 102 triangles).
#[divan::bench(sample_count = 10)]
fn load_and_tessellate_dense() -> Prepared {
    Prepared::load(&root().join("scenes/dense.toml"), &Overrides::default()).unwrap()
}

#[divan::bench(args = THREADS, sample_count = 5)]
fn bvh_build_940k(bencher: Bencher, threads: usize) {
    let t = &bunny().1;
    let p = pool(threads);
    bencher
        .counter(ItemsCount::new(t.len()))
        .bench(|| p.install(|| black_box(Accel::new(t, AccelOptions::default()))));
}

/// One closest-hit query per pixel (1920×1080 primary rays), no shading.
#[divan::bench(args = THREADS, sample_count = 5)]
fn primary_rays_940k_1080p(bencher: Bencher, threads: usize) {
    use rayon::prelude::*;
    let t = &bunny().1;
    let accel = Accel::new(t, AccelOptions::default());
    let cam = &t.camera;
    let rays: Vec<Ray64> = (0..cam.sample_height())
        .flat_map(|y| (0..cam.sample_width()).map(move |x| (x, y)))
        .map(|(x, y)| cam.sample_ray64(x, y))
        .collect();
    let p = pool(threads);
    bencher.counter(ItemsCount::new(rays.len())).bench(|| {
        p.install(|| {
            rays.par_chunks(4096)
                .map(|c| c.iter().filter(|r| accel.intersect(r).is_some()).count())
                .sum::<usize>()
        })
    });
}

/// The same primary rays as [`primary_rays_940k_1080p`] in 4×2 blocks
/// (row-major within a block), one thread: each ray alone
/// (`Accel::intersect`) against eight at a time (`Accel::intersect_packets`,
/// the same hits bit for bit).
#[divan::bench(consts = [false, true], sample_count = 5)]
fn coherent_rays_940k_1080p<const PACKETS: bool>(bencher: Bencher) {
    let t = &bunny().1;
    let accel = Accel::new(t, AccelOptions::default());
    let cam = &t.camera;
    let (w, h) = (cam.sample_width(), cam.sample_height());
    let mut rays: Vec<Ray64> = Vec::new();
    for by in (0..h).step_by(2) {
        for bx in (0..w).step_by(4) {
            for y in by..(by + 2).min(h) {
                for x in bx..(bx + 4).min(w) {
                    rays.push(cam.sample_ray64(x, y));
                }
            }
        }
    }
    let p = pool(1);
    let mut hits = vec![None; rays.len()];
    bencher
        .counter(ItemsCount::new(rays.len()))
        .bench_local(|| {
            p.install(|| {
                if PACKETS {
                    accel.intersect_packets(&rays, &mut hits);
                } else {
                    for (o, r) in hits.iter_mut().zip(&rays) {
                        *o = accel.intersect(r);
                    }
                }
                black_box(hits.iter().filter(|h| h.is_some()).count())
            })
        });
}

/// The camera's f64 primary rays of a 1080p frame, one thread: each ray
/// formed from the camera alone (`Camera::sample_ray64`, four divisions on
/// its path) against the per-frame tables both backends use
/// (`SampleRays`, the same rays bit for bit), summed so none is skipped.
#[divan::bench(consts = [false, true], sample_count = 10)]
fn camera_rays_1080p<const TABLES: bool>(bencher: Bencher) {
    use rendiff::camera::SampleRays;
    let cam = bunny().1.camera;
    let (w, h) = (cam.sample_width(), cam.sample_height());
    bencher
        .counter(ItemsCount::new((w * h) as usize))
        .with_inputs(|| SampleRays::new(&cam))
        .bench_refs(|rays| {
            let mut acc = 0.0;
            for y in 0..h {
                for x in 0..w {
                    let r = if TABLES {
                        rays.ray(x, y)
                    } else {
                        cam.sample_ray64(x, y)
                    };
                    acc += r.dir.x + r.t_min;
                }
            }
            black_box(acc)
        });
}

/// One shadow ray toward the light from every visible point, one by one
/// (`Visibility::transmittance`; `shadow_packets_940k_1080p` sets packets
/// beside it).
#[divan::bench(args = THREADS, sample_count = 5)]
fn shadow_rays_940k_1080p(bencher: Bencher, threads: usize) {
    use rayon::prelude::*;
    let t = &bunny().1;
    let accel = Accel::new(t, AccelOptions::default());
    let queries = bunny_shadow_queries(&accel);
    let vis = ShadowRays::new(&accel);
    let p = pool(threads);
    bencher.counter(ItemsCount::new(queries.len())).bench(|| {
        p.install(|| {
            queries
                .par_chunks(4096)
                .map(|c| c.iter().filter(|q| vis.transmittance(q).is_black()).count())
                .sum::<usize>()
        })
    });
}

/// One shadow ray to the bunny's light from each visible sample's point,
/// in scanline order, as shading casts them.
fn bunny_shadow_queries(accel: &Accel<'_>) -> Vec<rendiff::shade::ShadowQuery> {
    let t = accel.scene();
    let cam = &t.camera;
    let light = match t.lights[0].kind {
        rendiff::shade::LightKind::Point { position } => position,
        rendiff::shade::LightKind::Parallel { .. } => unreachable!(),
    };
    (0..cam.sample_height())
        .flat_map(|y| (0..cam.sample_width()).map(move |x| (x, y)))
        .filter_map(|(x, y)| {
            let h = accel.intersect(&cam.sample_ray64(x, y))?;
            let sp = t.surface_at(h.prim, rendiff::math::Bary(h.b));
            let dir = (light - sp.p).normalize();
            let o = rendiff::shade::offset_origin(sp.p, sp.p_error, sp.ng, dir);
            let d = light - o;
            Some(rendiff::shade::ShadowQuery {
                light: 0,
                origin: o,
                dir: d.normalize(),
                t_max: d.length(),
                normal: d.normalize(),
                leaves: h.prim,
            })
        })
        .collect()
}

/// The rasterizer's visibility pass (setup, coverage, depth test) as the
/// render plan runs it: the bunny is closed and seen from outside, so its
/// back faces are culled.
/// The shadow rays of [`shadow_rays_940k_1080p`], one thread, one by one
/// (`Visibility::transmittance`) against eight at a time in scanline order
/// (`ShadowRays::transmittance_packets`, the same answers bit for bit).
#[divan::bench(consts = [false, true], sample_count = 5)]
fn shadow_packets_940k_1080p<const PACKETS: bool>(bencher: Bencher) {
    let t = &bunny().1;
    let accel = Accel::new(t, AccelOptions::default());
    let queries = bunny_shadow_queries(&accel);
    let vis = ShadowRays::new(&accel);
    let p = pool(1);
    let mut out = vec![rendiff::color::Rgb::WHITE; queries.len()];
    bencher
        .counter(ItemsCount::new(queries.len()))
        .bench_local(|| {
            p.install(|| {
                if PACKETS {
                    vis.transmittance_packets(&queries, &mut out);
                } else {
                    for (o, q) in out.iter_mut().zip(&queries) {
                        *o = vis.transmittance(q);
                    }
                }
                black_box(out.iter().filter(|o| o.is_black()).count())
            })
        });
}

#[divan::bench(args = THREADS, sample_count = 10)]
fn raster_visibility_940k_1080p(bencher: Bencher, threads: usize) {
    let (job, t) = bunny();
    let opts = job.raster_options();
    assert!(
        opts.backface_cull[0],
        "the plan culls the bunny's back faces"
    );
    let p = pool(threads);
    bencher
        .counter(ItemsCount::new(t.len()))
        .bench(|| p.install(|| black_box(raster::visibility(t, &opts))));
}

/// The same with every back face rasterized too (`--no-plan`).
#[divan::bench(sample_count = 5)]
fn raster_visibility_940k_1080p_no_culling(bencher: Bencher) {
    let (job, t) = bunny();
    let mut opts = job.raster_options();
    opts.backface_cull = vec![false; t.objects.len()];
    let p = pool(1);
    bencher
        .counter(ItemsCount::new(t.len()))
        .bench(|| p.install(|| black_box(raster::visibility(t, &opts))));
}

/// A full shaded frame with the light made shadowless (shadow rays cost the
/// same in both backends): rasterizer, as the plan runs it, frame after
/// frame into the same memory.
#[divan::bench(args = THREADS, sample_count = 5)]
fn raster_frame_shadowless_940k_1080p(bencher: Bencher, threads: usize) {
    let (job, t) = bunny();
    let mut t = t.clone();
    t.lights[0].shadowless = true;
    let mut opts = job.raster_options();
    opts.shadows_needed = false;
    let p = pool(threads);
    // Frame after frame into the same memory (`render_into`): the frame,
    // not the kernel zeroing fresh pages for it.
    let mut frame = rendiff::frame::Frame::new(0, 0, 1, t.background);
    let mut buffers = raster::RasterBuffers::default();
    bencher.bench_local(|| {
        p.install(|| black_box(raster::render_into(&t, &opts, &mut buffers, &mut frame)))
    });
}

fn shadowless_ray_options() -> rendiff::ray::RayOptions {
    rendiff::ray::RayOptions {
        max_depth: 1,
        shadows: false,
        gate_eps: rendiff::GATE_EPS,
    }
}

/// The same frame by the ray tracer: primary rays and shading, with the
/// BVH built beforehand, into the same memory each time.
#[divan::bench(args = THREADS, sample_count = 5)]
fn ray_frame_shadowless_940k_1080p(bencher: Bencher, threads: usize) {
    let (_, t) = bunny();
    let mut t = t.clone();
    t.lights[0].shadowless = true;
    let accel = Accel::new(&t, AccelOptions::default());
    let p = pool(threads);
    let mut frame = rendiff::frame::Frame::new(0, 0, 1, t.background);
    bencher.bench_local(|| {
        p.install(|| {
            black_box(rendiff::ray::render_into(
                &accel,
                &shadowless_ray_options(),
                &mut frame,
            ))
        })
    });
}

/// The ray tracer's whole render: BVH build, primary rays, shading.
#[divan::bench(sample_count = 5)]
fn ray_frame_shadowless_940k_1080p_with_build(bencher: Bencher) {
    let (_, t) = bunny();
    let mut t = t.clone();
    t.lights[0].shadowless = true;
    let p = pool(1);
    bencher.bench(|| {
        p.install(|| {
            let accel = Accel::new(&t, AccelOptions::default());
            black_box(rendiff::ray::render(&accel, &shadowless_ray_options()))
        })
    });
}

/// Memory of the geometry and of the BVH per triangle (printed once).
#[divan::bench(sample_count = 1)]
fn memory_per_triangle() {
    let (_, t) = bunny();
    let accel = Accel::new(t, AccelOptions::default());
    let s = accel.stats();
    #[allow(clippy::cast_precision_loss)]
    let per = |b: usize| b as f64 / t.len() as f64;
    eprintln!(
        "memory: TriScene {:.1} B/triangle, BVH {:.1} B/triangle ({} nodes, depth {}, {} leaves)",
        per(t.geometry_bytes()),
        per(s.bytes),
        s.nodes,
        s.depth,
        s.leaves
    );
}

/// Fill rate of the visibility pass: two triangles covering a 1920×1080
/// frame at 2×2 samples (8.3 M samples), one depth layer.
#[divan::bench(sample_count = 5)]
fn raster_fill_1080p_2x2(bencher: Bencher) {
    use rendiff::camera::{Camera, Projection};
    use rendiff::math::{DVec3, Vec3};
    let cam = Camera::new(
        DVec3::ZERO,
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::Y,
        Projection::Perspective { tan_half_fov: 0.5 },
        1920,
        1080,
        2,
        0.01,
        100.0,
    )
    .unwrap();
    let q = [
        Vec3::new(-20.0, -20.0, -5.0),
        Vec3::new(20.0, -20.0, -6.0),
        Vec3::new(20.0, 20.0, -7.0),
        Vec3::new(-20.0, 20.0, -6.0),
    ];
    let t = TriScene::from_triangles(cam, &[[q[0], q[1], q[2]], [q[0], q[2], q[3]]]);
    let opts = raster::RasterOptions {
        depth: rendiff::options::DepthFormat::F32,
        shadows: rendiff::options::ShadowMode::Rays,
        shadows_needed: false,
        gate_eps: rendiff::GATE_EPS,
        frustum_cull: vec![false],
        backface_cull: vec![false],
        perturb: raster::Perturb::default(),
    };
    let p = pool(1);
    bencher
        .counter(ItemsCount::new(
            cam.sample_width() as usize * cam.sample_height() as usize,
        ))
        .bench(|| p.install(|| black_box(raster::visibility(&t, &opts))));
}

/// Where a flat loop stops beating a BVH (`plan::FLAT_LOOP_MAX_TRIANGLES`):
/// `n` small triangles scattered in a unit cube, a 256×256 frame of
/// primary rays, structure build included (one frame's whole cost).
#[divan::bench(args = [2, 4, 8, 12, 16, 32, 64], consts = [false, true], sample_count = 20)]
fn flat_loop_vs_bvh<const BVH: bool>(bencher: Bencher, n: usize) {
    use rendiff::camera::{Camera, Projection};
    use rendiff::math::{DVec3, Vec3};
    let cam = Camera::new(
        DVec3::new(0.5, 0.5, 3.0),
        DVec3::new(0.5, 0.5, 0.5),
        DVec3::Y,
        Projection::Perspective { tan_half_fov: 0.25 },
        256,
        256,
        1,
        0.01,
        100.0,
    )
    .unwrap();
    // A fixed pseudo-random layout (SplitMix64).
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let tris: Vec<[Vec3; 3]> = (0..n)
        .map(|_| {
            let c = Vec3::new(next(), next(), next());
            let s = 0.15;
            [
                c,
                c + Vec3::new(s * next(), s * next(), 0.0),
                c + Vec3::new(-s * next(), s * next(), s * next()),
            ]
        })
        .collect();
    let scene = TriScene::from_triangles(cam, &tris);
    let rays: Vec<Ray64> = (0..256)
        .flat_map(|y| (0..256).map(move |x| (x, y)))
        .map(|(x, y)| cam.sample_ray64(x, y))
        .collect();
    bencher.counter(ItemsCount::new(rays.len())).bench(|| {
        let accel = Accel::new(
            &scene,
            AccelOptions {
                bvh: BVH,
                ..AccelOptions::default()
            },
        );
        rays.iter()
            .filter(|r| accel.intersect(black_box(r)).is_some())
            .count()
    });
}
