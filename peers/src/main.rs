//! rendiff beside its peers.
//!
//! ```text
//! rendiff-peers summary [--repeats N]
//! rendiff-peers embree [SCENE.toml] [--subdivide K] [--morton] [--repeats N]
//! rendiff-peers povray [SCENE.toml ...] [--threads 1,2] [--repeats N]
//! rendiff-peers llvmpipe [--repeats N]
//! rendiff-peers objload [--repeats N]
//! rendiff-peers scaling [--threads 1,2,4,8,16] [--repeats N]
//! rendiff-peers trees [SCENE.toml] [--subdivide K] [--repeats N]
//! rendiff-peers profile SCENE.toml [--backend raster|ray] [--subdivide K] [--shadowless] [--reuse] [--build] [--repeats N]
//! ```
//!
//! `scaling`: the builds, rays and frames of the 940 k bunny, the builds
//! at ten million triangles, the bundled scenes and the whole process at
//! each thread count, beside Embree's, with the parallel efficiency and a
//! check that every result is bit-identical at every count (`scaling.rs`).
//!
//! `trees`: the BVH built by the SAH and in Morton order over the same
//! triangles (default: the 940 k bunny), each build timed, then the same
//! primary rays (scanline order and 4×2 packets) and shadow rays as
//! `embree` traced through both trees in alternation, one thread: the
//! build time against the walk's speed, medians and minima.
//!
//! `profile`: one scene rendered `--repeats` times in a row on one thread
//! (load once, render many), printing the median time: a target for
//! `perf record` that holds only the render phase POV-Ray is timed
//! against. `--subdivide K` splits every triangle K times into four and
//! `--shadowless` makes every light shadowless, as the summary's frames
//! of the 940 k bunny (the ray tracer then traces a BVH built once);
//! `--reuse` takes that path too (a BVH built once) and draws every frame
//! into the memory of the one before (`render_into`), as the summary's
//! frames do; `--build` times the BVH build alone. `--morton` (here and with
//! `embree`) builds our BVH in Morton order instead of by the SAH.
//!
//! `summary` (what `make peers` runs): every comparison below plus the
//! build at ten million triangles, the raster and ray frames, the whole
//! process against POV-Ray and OBJ loading, ending in one table of every
//! measure of issue 17 (see `summary.rs`).
//!
//! `embree`: the primary rays of a scene (default: the 940 k-triangle
//! bunny of `benches/scenes/bunny_1m.toml`, split 4 times) traced by
//! rendiff's BVH and by Embree 3's `rtcIntersect1` (the single-ray API)
//! in scanline order, and in 4×2 blocks (our packets, `Accel::intersect_packets`)
//! against `rtcIntersect8`; one
//! shadow ray from every visible point against `rtcOccluded1`; on one
//! thread and on all; the BVH builds timed too; the hits compared; on
//! one thread, the primary rays that hit and those that miss timed apart,
//! and the hitting rays again each four times in a row (caches and branch
//! predictors warm for the repeats: whether the gap is memory or work).
//!
//! `llvmpipe`: the rasterizer's shaded frame of the same bunny against
//! Mesa's llvmpipe on one thread (see `llvmpipe.rs`).
//!
//! `povray`: each scene rendered by POV-Ray 3.7 from `rendiff pov`'s
//! mesh export (the same triangles) and by both backends, at equal thread
//! counts; POV-Ray's render phase is its "Trace Time" (start-up, parsing
//! and bounding excluded); ours is the whole render (BVH build included).
//! The ray tracer is timed against POV-Ray's render of the scene as
//! written, the rasterizer against its `max_depth = 1` render (both
//! local-shading); equal error is shown by the share of pixels within
//! 2/255 of POV-Ray's stored reference.
//!
//! Run from the repository root: `make peers`.

mod embree;
mod llvmpipe;
mod scaling;
mod summary;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use rendiff::accel::{Accel, AccelOptions, BvhBuild, ShadowRays};
use rendiff::color::to_srgb8;
use rendiff::math::{Ray64, to_f32};
use rendiff::pov::golden::{self, Variant};
use rendiff::{Backend, Overrides, Prepared};

use summary::bundled as bundled_scenes;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn pool(n: usize) -> Result<rayon::ThreadPool> {
    Ok(rayon::ThreadPoolBuilder::new().num_threads(n).build()?)
}

fn all_threads() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
}

/// `--name value` from the arguments.
fn flag(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn positional(args: &[String]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut skip = false;
    for a in args {
        if skip {
            skip = false;
        } else if a.starts_with("--") {
            skip = true;
        } else {
            out.push(PathBuf::from(a));
        }
    }
    out
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(cmd) = args.first() else {
        bail!(
            "usage: rendiff-peers summary [--repeats N] | trees [SCENE] [--subdivide K] [--repeats N] | embree [SCENE] [--subdivide K] [--morton] [--repeats N] | povray [SCENE...] [--threads 1,2] [--repeats N] | llvmpipe [--repeats N] | objload [--repeats N] | scaling [--threads 1,2,4,8,16] [--repeats N] | rays [SCENE] [--subdivide K] [--repeats N] | profile SCENE [--backend raster|ray] [--subdivide K] [--shadowless] [--reuse] [--build] [--repeats N]"
        );
    };
    let rest = &args[1..];
    let repeats: usize = flag(rest, "--repeats").map_or(Ok(5), |s| s.parse())?;
    match cmd.as_str() {
        "embree" => {
            let (scene, k) = bench_scene(rest)?;
            embree_cmp(&scene, k, build_flag(rest), repeats).map(|_| ())
        }
        "povray" => {
            let mut scenes = positional(rest);
            if scenes.is_empty() {
                scenes = bundled_scenes()?;
            }
            let threads: Vec<usize> = flag(rest, "--threads").map_or_else(
                || Ok(vec![1, all_threads()]),
                |s| s.split(',').map(str::parse).collect(),
            )?;
            povray_cmp(&scenes, &threads, repeats).map(|_| ())
        }
        "summary" => summary::summary(repeats),
        "scaling" => {
            let threads: Vec<usize> = flag(rest, "--threads").map_or_else(
                || Ok(vec![1, 2, 4, 8, 16]),
                |s| s.split(',').map(str::parse).collect(),
            )?;
            anyhow::ensure!(!threads.is_empty(), "--threads needs at least one count");
            scaling::scaling(&threads, repeats)
        }
        "trees" => {
            let (scene, k) = bench_scene(rest)?;
            trees(&scene, k, repeats).map(|_| ())
        }
        "objload" => summary::obj_load(repeats).map(|_| ()),
        "rays" => {
            let (scene, k) = bench_scene(rest)?;
            rays(&scene, k, repeats)
        }
        "llvmpipe" => llvmpipe::compare(repeats).map(|_| ()),
        "profile" => {
            let scene = positional(rest)
                .first()
                .cloned()
                .context("profile needs a scene")?;
            let backend = match flag(rest, "--backend").as_deref() {
                None | Some("raster") => Backend::Raster,
                Some("ray") => Backend::Ray,
                Some(other) => bail!("unknown backend {other:?}: expected raster or ray"),
            };
            let k: u32 = flag(rest, "--subdivide").map_or(Ok(0), |s| s.parse())?;
            let shadowless = rest.iter().any(|a| a == "--shadowless");
            let build = build_flag(rest);
            if rest.iter().any(|a| a == "--build") {
                profile_build(&scene, k, build, repeats)
            } else {
                let reuse = rest.iter().any(|a| a == "--reuse");
                profile(&scene, backend, (k, build), (shadowless, reuse), repeats)
            }
        }
        other => bail!(
            "unknown command {other:?}: expected summary, scaling, embree, trees, povray, llvmpipe, objload, rays or profile"
        ),
    }
}

/// Renders one scene `repeats` times on one thread and prints the
/// median, minimum and maximum of the render phase. Plain, it times
/// `Prepared::render` (the ray tracer's BVH build included, as the
/// POV-Ray rows time it); split (`subdivide` > 0), shadowless or with
/// `reuse`, it times the frames of the summary (`raster::render`, or
/// `ray::render` on a BVH built once; with `reuse`, their `render_into`,
/// each frame in the memory of the one before).
fn profile(
    scene: &Path,
    backend: Backend,
    (subdivide, build): (u32, BvhBuild),
    (shadowless, reuse): (bool, bool),
    repeats: usize,
) -> Result<()> {
    let job = Prepared::load(scene, &Overrides::default())?;
    let p = pool(1)?;
    let times: Vec<f64> = if subdivide == 0 && !shadowless && !reuse {
        (0..repeats.max(1))
            .map(|_| p.install(|| job.render(backend).map(|r| r.time_ms)))
            .collect::<Result<_, _>>()?
    } else {
        let mut t = job.tri.subdivided(subdivide);
        let mut opts = job.raster_options();
        if shadowless {
            for l in &mut t.lights {
                l.shadowless = true;
            }
            opts.shadows_needed = false;
        }
        let accel = (backend == Backend::Ray).then(|| {
            Accel::new(
                &t,
                AccelOptions {
                    build,
                    ..AccelOptions::default()
                },
            )
        });
        let ray_opts = rendiff::ray::RayOptions {
            max_depth: job.settings.max_depth,
            shadows: !shadowless,
            gate_eps: rendiff::GATE_EPS,
        };
        let mut frame = rendiff::frame::Frame::new(0, 0, 1, t.background);
        let mut buffers = rendiff::raster::RasterBuffers::default();
        (0..repeats.max(1))
            .map(|_| {
                p.install(|| {
                    let start = Instant::now();
                    match (&accel, reuse) {
                        (Some(a), false) => {
                            std::hint::black_box(rendiff::ray::render(a, &ray_opts));
                        }
                        (Some(a), true) => {
                            std::hint::black_box(rendiff::ray::render_into(
                                a, &ray_opts, &mut frame,
                            ));
                        }
                        (None, false) => {
                            std::hint::black_box(rendiff::raster::render(&t, &opts));
                        }
                        (None, true) => {
                            std::hint::black_box(rendiff::raster::render_into(
                                &t,
                                &opts,
                                &mut buffers,
                                &mut frame,
                            ));
                        }
                    }
                    start.elapsed().as_secs_f64() * 1e3
                })
            })
            .collect()
    };
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    let max = times.iter().copied().fold(0.0, f64::max);
    println!(
        "{} {backend}, 1 thread, {} renders: median {:.2} ms (min {min:.2}, max {max:.2})",
        scene.display(),
        times.len(),
        median(times)
    );
    Ok(())
}

/// Times the rays of the `embree` row through our BVH alone, one thread:
/// the primary rays in 4×2 packets (`intersect_packets`), then the shadow
/// rays (one from every visible point to the first light, eight
/// neighbours at a time, `transmittance_packets`); medians of `repeats`
/// passes, with how many primary rays hit and how many shadow rays are
/// blocked (the same for every build of the BVH). For profiles of the
/// walks without Embree or the build in the way.
fn rays(scene: &Path, subdivide: u32, repeats: usize) -> Result<()> {
    let job = Prepared::load(scene, &Overrides::default())?;
    let tri = job.tri.subdivided(subdivide);
    let accel = Accel::new(&tri, AccelOptions::default());
    let (_, blocks) = camera_rays(&tri.camera);
    let primary: usize = blocks.iter().map(Vec::len).sum();
    let queries = shadow_rays(&tri, &accel);
    let vis = ShadowRays::new(&accel);
    // The rays of the `embree` row's packet and shadow measures, on this
    // pool's one thread.
    let hits = || ours_packets(&accel, &blocks);
    let blocked = || ours_blocked(&vis, &queries);
    let p = pool(1)?;
    let t_primary = time_ms(&p, repeats, &|| {
        std::hint::black_box(hits());
    });
    let t_shadow = time_ms(&p, repeats, &|| {
        std::hint::black_box(blocked());
    });
    println!(
        "{}, 1 thread: {primary} primary rays in 4x2 packets ({} hit): median {t_primary:.1} ms = {:.2} M rays/s; {} shadow rays ({} blocked): median {t_shadow:.1} ms = {:.2} M rays/s",
        scene.display(),
        hits(),
        primary as f64 / t_primary / 1e3,
        queries.len(),
        blocked(),
        queries.len() as f64 / t_shadow / 1e3
    );
    Ok(())
}

/// Builds the BVH of a scene (split `subdivide` times) `repeats` times on
/// one thread and prints the median, minimum and maximum.
fn profile_build(scene: &Path, subdivide: u32, build: BvhBuild, repeats: usize) -> Result<()> {
    let job = Prepared::load(scene, &Overrides::default())?;
    let t = job.tri.subdivided(subdivide);
    let p = pool(1)?;
    let times: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            p.install(|| {
                let start = Instant::now();
                std::hint::black_box(Accel::new(
                    &t,
                    AccelOptions {
                        build,
                        ..AccelOptions::default()
                    },
                ));
                start.elapsed().as_secs_f64() * 1e3
            })
        })
        .collect();
    let stats = Accel::new(
        &t,
        AccelOptions {
            build,
            ..AccelOptions::default()
        },
    )
    .stats();
    println!("{build:?} tree: {stats:?}");
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    let max = times.iter().copied().fold(0.0, f64::max);
    println!(
        "{} split {subdivide} times ({} triangles): BVH build, 1 thread, {} builds: median {:.1} ms (min {min:.1}, max {max:.1})",
        scene.display(),
        t.len(),
        times.len(),
        median(times)
    );
    Ok(())
}

/// Times `f` `repeats` times on a pool of `threads`; the median in ms.
fn time_ms(p: &rayon::ThreadPool, repeats: usize, f: &(dyn Fn() + Sync)) -> f64 {
    median(
        (0..repeats)
            .map(|_| {
                p.install(|| {
                    let t = Instant::now();
                    f();
                    t.elapsed().as_secs_f64() * 1e3
                })
            })
            .collect(),
    )
}

/// The figures of one `embree` comparison (1 thread), for the summary.
#[derive(Clone, Copy, Debug, Default)]
pub struct RayFigures {
    /// Primary rays, ours single rays / Embree `rtcIntersect1` (speed ratio, >1: ours faster).
    pub primary: f64,
    /// 4×2 blocks, our packets / Embree `rtcIntersect8`.
    pub coherent: f64,
    /// Our shadow rays, M rays/s.
    pub shadow_mrays: f64,
    /// Our shadow rays / Embree `rtcOccluded1`.
    pub shadow_vs_embree: f64,
    /// Build time, ours / Embree.
    pub build: f64,
    /// Embree's build, ms.
    pub embree_build_ms: f64,
}

#[expect(clippy::cast_possible_truncation, reason = "Embree takes f32 rays")]
fn embree_ray(r: &Ray64) -> embree::EmbreeRay {
    (
        to_f32(r.origin).to_array(),
        to_f32(r.dir).to_array(),
        r.t_min as f32,
        r.t_max as f32,
    )
}

/// The camera's primary rays in scanline order, and the same rays in
/// 4×2 blocks (row-major within each block), as the ray tracer casts them.
fn camera_rays(cam: &rendiff::camera::Camera) -> (Vec<Ray64>, Vec<Vec<Ray64>>) {
    let (w, h) = (cam.sample_width(), cam.sample_height());
    let rays: Vec<Ray64> = (0..h)
        .flat_map(|sy| (0..w).map(move |sx| (sx, sy)))
        .map(|(sx, sy)| cam.sample_ray64(sx, sy))
        .collect();
    let mut blocks = Vec::new();
    for by in (0..h).step_by(2) {
        for bx in (0..w).step_by(4) {
            let b: Vec<Ray64> = (by..(by + 2).min(h))
                .flat_map(|y| (bx..(bx + 4).min(w)).map(move |x| (x, y)))
                .map(|(x, y)| cam.sample_ray64(x, y))
                .collect();
            blocks.push(b);
        }
    }
    (rays, blocks)
}

/// What `trees` measured: the medians of the SAH's tree and of the Morton
/// order's, in ms.
pub struct TreeFigures {
    /// Builds (SAH, Morton).
    pub build: [f64; 2],
    /// Primary rays in scanline order.
    pub primary: [f64; 2],
    /// Primary rays in 4×2 packets.
    pub packets: [f64; 2],
    /// Shadow rays.
    pub shadow: [f64; 2],
}

/// The SAH and the Morton build of one scene's BVH: build times, then
/// primary, packet and shadow rays through each tree in alternation (one
/// thread; minima and medians of `repeats` rounds).
fn trees(scene: &Path, subdivide: u32, repeats: usize) -> Result<TreeFigures> {
    let job = Prepared::load(scene, &Overrides::default())?;
    let tri = job.tri.subdivided(subdivide);
    let (rays, blocks) = camera_rays(&tri.camera);
    let p = pool(1)?;
    let builds = [BvhBuild::Sah, BvhBuild::Morton];
    let opts = |build| AccelOptions {
        build,
        ..AccelOptions::default()
    };
    let mut build_ms = [Vec::new(), Vec::new()];
    for _ in 0..repeats.max(1) {
        for (k, &b) in builds.iter().enumerate() {
            build_ms[k].push(p.install(|| {
                let t = Instant::now();
                std::hint::black_box(Accel::new(&tri, opts(b)));
                t.elapsed().as_secs_f64() * 1e3
            }));
        }
    }
    let accels = builds.map(|b| Accel::new(&tri, opts(b)));
    let shadow = shadow_rays(&tri, &accels[0]);
    println!(
        "{}: {} triangles, {} primary rays, {} shadow rays, 1 thread",
        scene.display(),
        tri.len(),
        rays.len(),
        shadow.len()
    );
    // [tree][primary, packets, shadow] times.
    let mut ms = [[vec![], vec![], vec![]], [vec![], vec![], vec![]]];
    for _ in 0..repeats.max(1) {
        for (k, accel) in accels.iter().enumerate() {
            p.install(|| {
                let t = Instant::now();
                let hits = rays.iter().filter(|r| accel.intersect(r).is_some()).count();
                std::hint::black_box(hits);
                ms[k][0].push(t.elapsed().as_secs_f64() * 1e3);
                let t = Instant::now();
                let mut out = [None; 8];
                let hits: usize = blocks
                    .iter()
                    .map(|b| {
                        let out = &mut out[..b.len()];
                        accel.intersect_packets(b, out);
                        out.iter().filter(|h| h.is_some()).count()
                    })
                    .sum();
                std::hint::black_box(hits);
                ms[k][1].push(t.elapsed().as_secs_f64() * 1e3);
                let t = Instant::now();
                let vis = ShadowRays::new(accel);
                let mut out = vec![rendiff::color::Rgb::WHITE; shadow.len()];
                vis.transmittance_packets(&shadow, &mut out);
                std::hint::black_box(out.iter().filter(|t| t.is_black()).count());
                ms[k][2].push(t.elapsed().as_secs_f64() * 1e3);
            });
        }
    }
    let fig = |v: &Vec<f64>| {
        let min = v.iter().copied().fold(f64::INFINITY, f64::min);
        format!("{:.1} ms (min {min:.1})", median(v.clone()))
    };
    for (k, b) in builds.iter().enumerate() {
        println!(
            "{b:?}: build {}; primary {}; packets {}; shadow {}; {:?}",
            fig(&build_ms[k]),
            fig(&ms[k][0]),
            fig(&ms[k][1]),
            fig(&ms[k][2]),
            accels[k].stats()
        );
    }
    let med = |k: usize, i: usize| median(ms[k][i].clone());
    Ok(TreeFigures {
        build: [median(build_ms[0].clone()), median(build_ms[1].clone())],
        primary: [med(0, 0), med(1, 0)],
        packets: [med(0, 1), med(1, 1)],
        shadow: [med(0, 2), med(1, 2)],
    })
}

/// The scene of `embree` and `trees` (default: the 940 k-triangle bunny)
/// and how many times it is split (`--subdivide`, default 4).
fn bench_scene(args: &[String]) -> Result<(PathBuf, u32)> {
    let scene = positional(args)
        .first()
        .cloned()
        .unwrap_or_else(|| PathBuf::from("benches/scenes/bunny_1m.toml"));
    let k: u32 = flag(args, "--subdivide").map_or(Ok(4), |s| s.parse())?;
    Ok((scene, k))
}

/// The BVH build the arguments ask for: Morton order with `--morton`,
/// else the SAH.
fn build_flag(args: &[String]) -> BvhBuild {
    if args.iter().any(|a| a == "--morton") {
        BvhBuild::Morton
    } else {
        BvhBuild::Sah
    }
}

fn embree_cmp(scene: &Path, subdivide: u32, build: BvhBuild, repeats: usize) -> Result<RayFigures> {
    let opts = AccelOptions {
        build,
        ..AccelOptions::default()
    };
    let job = Prepared::load(scene, &Overrides::default())?;
    let tri = job.tri.subdivided(subdivide);
    let cam = &tri.camera;
    // The camera's f64 rays: ours decides on them, Embree gets their f32
    // rounding (the same rays, as each takes them).
    let (rays, blocks) = camera_rays(cam);
    println!(
        "{}: {} triangles, {}x{}, {} primary rays",
        scene.display(),
        tri.len(),
        cam.width(),
        cam.height(),
        rays.len()
    );
    let positions: Vec<[f32; 3]> = tri.positions.iter().map(|p| p.to_array()).collect();
    let all = all_threads();
    let mut figures = RayFigures::default();
    let mut thread_counts = vec![1];
    if all > 1 {
        thread_counts.push(all);
    }
    for threads in thread_counts {
        let p = pool(threads)?;
        let config = format!("threads={threads}");
        let ours_build = time_ms(&p, repeats, &|| {
            std::hint::black_box(Accel::new(&tri, opts));
        });
        let embree_build = time_ms(&p, repeats, &|| {
            std::hint::black_box(embree::EmbreeScene::new(&positions, &tri.tris, &config).ok());
        });
        let accel = Accel::new(&tri, opts);
        let emb = embree::EmbreeScene::new(&positions, &tri.tris, &config)?;
        let t_ours = time_ms(&p, repeats, &|| {
            std::hint::black_box(ours_primary(&accel, &rays));
        });
        let t_emb = time_ms(&p, repeats, &|| {
            std::hint::black_box(embree_primary(&emb, &rays));
        });
        // Coherent: 4×2 blocks, Embree's rtcIntersect8 against our packets
        // of the same eight rays (`Accel::intersect_packets`).
        let t_packet = time_ms(&p, repeats, &|| {
            std::hint::black_box(ours_packets(&accel, &blocks));
        });
        let t_emb8 = time_ms(&p, repeats, &|| {
            std::hint::black_box(embree_packets(&emb, &blocks));
        });
        // Shadow rays: from every visible point to the light, as shading
        // casts them (eight neighbours at a time, `transmittance_packets`).
        let shadow = shadow_rays(&tri, &accel);
        let vis = ShadowRays::new(&accel);
        let t_shadow = time_ms(&p, repeats, &|| {
            std::hint::black_box(ours_blocked(&vis, &shadow));
        });
        let t_emb_shadow = time_ms(&p, repeats, &|| {
            std::hint::black_box(embree_blocked(&emb, &shadow));
        });
        let mrays = |n: usize, ms: f64| n as f64 / ms / 1e3;
        println!(
            "{threads} thread(s): build ours {ours_build:.1} ms, Embree {embree_build:.1} ms (ours/Embree {:.2}x)",
            ours_build / embree_build
        );
        println!(
            "  primary rays (scanline order): ours {t_ours:.1} ms = {:.2} Mrays/s, Embree rtcIntersect1 {t_emb:.1} ms = {:.2} Mrays/s; ours is {:.2}x Embree's speed",
            mrays(rays.len(), t_ours),
            mrays(rays.len(), t_emb),
            t_emb / t_ours
        );
        println!(
            "  coherent 4x2 blocks: ours (packets of 8) {t_packet:.1} ms = {:.2} Mrays/s, Embree rtcIntersect8 {t_emb8:.1} ms = {:.2} Mrays/s; ours is {:.2}x Embree's speed",
            mrays(rays.len(), t_packet),
            mrays(rays.len(), t_emb8),
            t_emb8 / t_packet
        );
        println!(
            "  shadow rays ({} from the visible points): ours {t_shadow:.1} ms = {:.2} Mrays/s, Embree rtcOccluded1 {t_emb_shadow:.1} ms = {:.2} Mrays/s; ours is {:.2}x Embree's speed",
            shadow.len(),
            mrays(shadow.len(), t_shadow),
            mrays(shadow.len(), t_emb_shadow),
            t_emb_shadow / t_shadow
        );
        if threads == 1 {
            figures = RayFigures {
                primary: t_emb / t_ours,
                coherent: t_emb8 / t_packet,
                shadow_mrays: mrays(shadow.len(), t_shadow),
                shadow_vs_embree: t_emb_shadow / t_shadow,
                build: ours_build / embree_build,
                embree_build_ms: embree_build,
            };
            agreement(&rays, &accel, &emb);
            hits_and_misses(&p, repeats, &rays, &accel, &emb);
        }
    }
    Ok(figures)
}

/// The primary rays that hit and those that miss, timed apart (ours one
/// at a time against `rtcIntersect1`), and the hitting rays again with
/// each traced four times in a row, so that the repeats find the caches
/// and branch predictors warm: where the gap between the two lies, and
/// whether it is memory or work.
fn hits_and_misses(
    p: &rayon::ThreadPool,
    repeats: usize,
    rays: &[Ray64],
    accel: &Accel<'_>,
    emb: &embree::EmbreeScene,
) {
    let (hit, miss): (Vec<Ray64>, Vec<Ray64>) =
        rays.iter().partition(|r| accel.intersect(r).is_some());
    let warm: Vec<Ray64> = hit.iter().flat_map(|r| [*r; 4]).collect();
    for (what, set) in [
        ("that hit", &hit),
        ("that miss", &miss),
        ("that hit, each 4 times in a row", &warm),
    ] {
        if set.is_empty() {
            continue;
        }
        let ours = time_ms(p, repeats, &|| {
            std::hint::black_box(ours_primary(accel, set));
        });
        let theirs = time_ms(p, repeats, &|| {
            std::hint::black_box(embree_primary(emb, set));
        });
        let ns = |ms: f64| ms * 1e6 / set.len() as f64;
        println!(
            "  primary rays {what} ({}): ours {:.1} ns/ray, Embree {:.1} ns/ray; ours is {:.2}x Embree's speed",
            set.len(),
            ns(ours),
            ns(theirs),
            theirs / ours
        );
    }
}

/// Primary rays that hit, ours one at a time, in parallel runs (never
/// inlined: a symbol for callgrind's `--toggle-collect`, as the other
/// `ours_` and `embree_` passes).
#[inline(never)]
fn ours_primary(accel: &Accel<'_>, rays: &[Ray64]) -> usize {
    rays.par_chunks(4096)
        .map(|c| c.iter().filter(|r| accel.intersect(r).is_some()).count())
        .sum()
}

/// The same with Embree's `rtcIntersect1` (the rays rounded to f32).
#[inline(never)]
fn embree_primary(emb: &embree::EmbreeScene, rays: &[Ray64]) -> usize {
    rays.par_chunks(4096)
        .map(|c| {
            c.iter()
                .filter(|r| {
                    let (o, d, t0, t1) = embree_ray(r);
                    emb.intersect(o, d, t0, t1).is_some()
                })
                .count()
        })
        .sum()
}

/// Primary rays that hit, ours in packets of a 4×2 block each.
#[inline(never)]
fn ours_packets(accel: &Accel<'_>, blocks: &[Vec<Ray64>]) -> usize {
    blocks
        .par_chunks(512)
        .map(|c| {
            let mut out = [None; 8];
            c.iter()
                .map(|b| {
                    let out = &mut out[..b.len()];
                    accel.intersect_packets(b, out);
                    out.iter().filter(|h| h.is_some()).count()
                })
                .sum::<usize>()
        })
        .sum()
}

/// The same with Embree's `rtcIntersect8`.
fn embree_packets(emb: &embree::EmbreeScene, blocks: &[Vec<Ray64>]) -> usize {
    blocks
        .par_chunks(512)
        .map(|c| {
            c.iter()
                .map(|b| {
                    let r: Vec<embree::EmbreeRay> = b.iter().map(embree_ray).collect();
                    emb.intersect8(&r).iter().filter(|h| h.is_some()).count()
                })
                .sum::<usize>()
        })
        .sum()
}

/// Shadow queries blocked, ours (`transmittance_packets`, eight
/// neighbours at a time), in parallel runs.
#[inline(never)]
fn ours_blocked(vis: &ShadowRays<'_, '_>, shadow: &[rendiff::shade::ShadowQuery]) -> usize {
    shadow
        .par_chunks(4096)
        .map(|c| {
            let mut out = vec![rendiff::color::Rgb::WHITE; c.len()];
            vis.transmittance_packets(c, &mut out);
            out.iter().filter(|t| t.is_black()).count()
        })
        .sum()
}

/// The same with Embree's `rtcOccluded1`.
#[inline(never)]
fn embree_blocked(emb: &embree::EmbreeScene, shadow: &[rendiff::shade::ShadowQuery]) -> usize {
    shadow
        .par_chunks(4096)
        .map(|c| {
            c.iter()
                .filter(|q| emb.occluded(q.origin.to_array(), q.dir.to_array(), 0.0, q.t_max))
                .count()
        })
        .sum()
}

/// The shadow queries of a frame: one from every visible point of the
/// primary rays toward the scene's first light, started off the surface
/// as shading starts them.
fn shadow_rays(
    tri: &rendiff::tri_scene::TriScene,
    accel: &Accel<'_>,
) -> Vec<rendiff::shade::ShadowQuery> {
    let cam = &tri.camera;
    let light = match tri.lights.first().map(|l| l.kind) {
        Some(rendiff::shade::LightKind::Point { position }) => position,
        _ => return Vec::new(),
    };
    (0..cam.sample_height())
        .flat_map(|y| (0..cam.sample_width()).map(move |x| (x, y)))
        .filter_map(|(x, y)| {
            let h = accel.intersect(&cam.sample_ray64(x, y))?;
            let sp = tri.surface_at(h.prim, rendiff::math::Bary(h.b));
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

/// Ours against Embree, hit by hit.
fn agreement(rays: &[Ray64], accel: &Accel<'_>, emb: &embree::EmbreeScene) {
    let (mut same, mut both_miss, mut differ, mut close) = (0usize, 0usize, 0usize, 0usize);
    for r in rays {
        let (o, d, t0, t1) = embree_ray(r);
        match (
            accel.intersect(r).map(|h| (h.prim, h.t)),
            emb.intersect(o, d, t0, t1),
        ) {
            (None, None) => both_miss += 1,
            (Some(a), Some(b)) if a.0 == b.0 => same += 1,
            (Some(a), Some(b)) => {
                differ += 1;
                if (a.1 - b.1).abs() <= 1e-5 * a.1.max(b.1) {
                    close += 1;
                }
            }
            _ => differ += 1,
        }
    }
    println!(
        "  hits against Embree: {same} same triangle, {both_miss} both miss, {differ} differ ({close} of them at the same distance within 1e-5: shared edges and vertices)"
    );
}

/// POV-Ray's trace time in milliseconds from its statistics.
fn trace_ms(stderr: &str) -> Option<f64> {
    let line = stderr
        .lines()
        .find(|l| l.trim_start().starts_with("Trace Time:"))?;
    let open = line.rfind('(')?;
    let secs: f64 = line[open + 1..].split_whitespace().next()?.parse().ok()?;
    Some(secs * 1e3)
}

/// A reference written out for POV-Ray (its scene file and images in
/// `work`), ready to render with [`PovRun::trace_ms`].
struct PovRun<'a> {
    pov: PathBuf,
    dir: &'a Path,
    size: (u32, u32),
    threads: usize,
    work: &'a Path,
}

impl<'a> PovRun<'a> {
    /// Writes the reference `r` of `job` into `work`.
    fn new(
        job: &'a Prepared,
        r: &golden::Reference,
        threads: usize,
        work: &'a Path,
    ) -> Result<PovRun<'a>> {
        let pov = work.join(format!("{}{}.pov", job.scene.name(), r.variant.suffix()));
        std::fs::write(&pov, &r.export.text)?;
        for img in &r.export.images {
            img.materialise(work)?;
        }
        let dir = job
            .scene
            .path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        Ok(PovRun {
            pov,
            dir,
            size: r.export.render_size,
            threads,
            work,
        })
    }

    /// Renders it once; POV-Ray's trace time.
    fn trace_ms(&self) -> Result<f64> {
        let (w, h) = self.size;
        let out = std::process::Command::new("povray")
            .current_dir(self.dir)
            .arg(format!("+I{}", self.pov.display()))
            .arg(format!("+O{}", self.work.join("out.png").display()))
            .arg(format!("+W{w}"))
            .arg(format!("+H{h}"))
            .args(["-D", "-A", "+FN16", "File_Gamma=1.0", "+Q9"])
            .arg(format!("+WT{}", self.threads))
            .arg(format!("+L{}", self.work.display()))
            .output()
            .context("could not run povray (apt-get install povray)")?;
        let text = String::from_utf8_lossy(&out.stderr);
        trace_ms(&text).with_context(|| {
            format!(
                "no Trace Time in POV-Ray's output for {}",
                self.pov.display()
            )
        })
    }
}

/// Share of pixels within 2/255 of the stored reference, in percent.
fn within(job: &Prepared, frame: &rendiff::frame::Frame, variant: Variant) -> Option<f64> {
    let path = golden::reference_path(Path::new("golden/pov"), &job.scene, variant);
    let img = rendiff::image_io::read_png_linear(&path).ok()?;
    let ok = frame
        .color
        .iter()
        .zip(&img.pixels)
        .filter(|(p, q)| {
            [(p.r, q.r), (p.g, q.g), (p.b, q.b)]
                .iter()
                .all(|(x, y)| to_srgb8(*x).abs_diff(to_srgb8(*y)) <= 2)
        })
        .count();
    Some(ok as f64 / frame.color.len() as f64 * 100.0)
}

/// POV-Ray's render phase against the better backend, per thread count:
/// (threads, geometric mean, worst speed-up, the worst scene).
type PovFigures = Vec<(usize, f64, f64, String)>;

fn povray_cmp(scenes: &[PathBuf], threads: &[usize], repeats: usize) -> Result<PovFigures> {
    let work = std::env::temp_dir().join(format!("rendiff-peers-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    println!("scene,threads,backend,pov_variant,pov_trace_ms,ours_ms,speedup,within_2_255_pct");
    let mut ratios: Vec<(String, usize, f64)> = Vec::new();
    for path in scenes {
        let job = Prepared::load(path, &Overrides::default())?;
        let refs = golden::references(&job.scene, &job.tri)?;
        for &n in threads {
            let p = pool(n)?;
            let mut best: Option<f64> = None;
            for backend in [Backend::Raster, Backend::Ray] {
                let variant = if backend == Backend::Raster
                    && refs.iter().any(|r| r.variant == Variant::Depth1)
                {
                    Variant::Depth1
                } else {
                    Variant::Main
                };
                let Some(r) = refs.iter().find(|r| r.variant == variant) else {
                    continue;
                };
                let pov = PovRun::new(&job, r, n, &work)?;
                let frame =
                    p.install(|| job.render_with_depth(backend, r.max_depth).unwrap().frame);
                // POV-Ray's runs (at most three: each starts a process and
                // parses the scene) interleaved with ours, so that both
                // medians come from the same minutes of a shared host,
                // whose speed moves by a third within half an hour. After
                // each POV-Ray run one render is untimed: ours are timed
                // warm, as back to back (right after POV-Ray's process the
                // caches hold its data, not ours), and POV-Ray's trace
                // follows its own parse.
                let pov_runs = repeats.clamp(1, 3);
                let mut pov_times = Vec::with_capacity(pov_runs);
                let mut our_times = Vec::with_capacity(repeats);
                for i in 0..repeats.max(pov_runs) {
                    if i < pov_runs {
                        pov_times.push(pov.trace_ms()?);
                        p.install(|| job.render_with_depth(backend, r.max_depth).unwrap());
                    }
                    if i < repeats {
                        our_times.push(p.install(|| {
                            job.render_with_depth(backend, r.max_depth).unwrap().time_ms
                        }));
                    }
                }
                let pov_ms = median(pov_times);
                let ours = median(our_times);
                let pct = within(&job, &frame, variant)
                    .map_or_else(|| "n/a".into(), |v| format!("{v:.3}"));
                println!(
                    "{},{n},{backend},pov{},{pov_ms:.1},{ours:.2},{:.2},{pct}",
                    job.scene.name(),
                    variant.suffix(),
                    pov_ms / ours
                );
                best = Some(best.map_or(pov_ms / ours, |b: f64| b.max(pov_ms / ours)));
            }
            if let Some(b) = best {
                ratios.push((job.scene.name(), n, b));
            }
        }
    }
    let mut figures = Vec::new();
    for &n in threads {
        let r: Vec<&(String, usize, f64)> = ratios.iter().filter(|x| x.1 == n).collect();
        if let Some(worst) = r.iter().min_by(|a, b| a.2.total_cmp(&b.2)) {
            let geo = (r.iter().map(|x| x.2.ln()).sum::<f64>() / r.len() as f64).exp();
            println!(
                "# {n} thread(s): best backend per scene is {:.2}x ({}, the worst scene) … geometric mean {geo:.2}x faster than POV-Ray's render phase",
                worst.2, worst.0
            );
            figures.push((n, geo, worst.2, worst.0.clone()));
        }
    }
    let _ = std::fs::remove_dir_all(&work);
    Ok(figures)
}
