//! `rendiff-peers scaling [--threads 1,2,4,8,16] [--repeats N]`: every
//! parallel part of rendiff timed on 1, 2, 4, … threads beside Embree on
//! the same rays and thread counts, with the parallel efficiency and a
//! check that every image is bit-identical at every count.
//!
//! The work: the 940 k-triangle bunny at 1080p (`benches/scenes/bunny_1m.toml`
//! split 4 times) — the SAH and Morton builds against Embree's (its TBB
//! pool limited by `threads=N`), primary rays one at a time against
//! `rtcIntersect1`, 4×2 packets against `rtcIntersect8`, shadow rays
//! against `rtcOccluded1`, the rasterizer's and the ray tracer's shaded
//! frames with the light shadowless (BVH prebuilt) and with shadows; the
//! builds at ten million triangles (`benches/scenes/ten_million.toml`);
//! every bundled scene rendered by each backend (the sum of the medians);
//! and the whole `rendiff render` process of `scenes/dense.toml` when
//! `target/release/rendiff` is there. Efficiency at n threads is
//! t(1) / (n · t(n)).
//!
//! Thread invariance: every frame (the bunny's four and each bundled
//! scene's two) is hashed, every bit of colour, depth, primitive id and
//! flags, and the primary hit and shadow blocked counts are kept; any
//! count whose hashes differ from the first count's is reported and the
//! command fails.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use anyhow::{Result, bail};
use rendiff::accel::{Accel, AccelOptions, BvhBuild, ShadowRays};
use rendiff::frame::Frame;
use rendiff::{Backend, Overrides, Prepared, raster};

use crate::{
    camera_rays, embree, embree_blocked, embree_packets, embree_primary, median, ours_blocked,
    ours_packets, ours_primary, pool, shadow_rays, time_ms,
};

/// FNV-1a over every bit a frame stores.
fn frame_hash(f: &Frame) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |w: u32| {
        for b in w.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for c in f.color.iter().chain(&f.sample_color) {
        eat(c.r.to_bits());
        eat(c.g.to_bits());
        eat(c.b.to_bits());
    }
    for d in &f.depth {
        eat(d.to_bits());
    }
    for &i in f.id.iter().chain(&f.flags) {
        eat(i);
    }
    h
}

/// One measured row: its name and the median ms at each thread count.
struct Row {
    name: String,
    ms: Vec<f64>,
}

/// Runs the measures at each thread count and prints them with the
/// efficiency; fails if any result differs between thread counts.
pub fn scaling(threads: &[usize], repeats: usize) -> Result<()> {
    let load = Instant::now();
    let job = Prepared::load(
        Path::new("benches/scenes/bunny_1m.toml"),
        &Overrides::default(),
    )?;
    let tri = job.tri.subdivided(4);
    let mut shadowless = tri.clone();
    for l in &mut shadowless.lights {
        l.shadowless = true;
    }
    let (rays, blocks) = camera_rays(&tri.camera);
    let positions: Vec<[f32; 3]> = tri.positions.iter().map(|p| p.to_array()).collect();
    let shadow = {
        let accel = Accel::new(&tri, AccelOptions::default());
        shadow_rays(&tri, &accel)
    };
    let ten = Prepared::load(
        Path::new("benches/scenes/ten_million.toml"),
        &Overrides::default(),
    )?;
    let bundled: Vec<Prepared> = crate::bundled_scenes()?
        .iter()
        .map(|p| Prepared::load(p, &Overrides::default()).map_err(anyhow::Error::from))
        .collect::<Result<_>>()?;
    let exe = Path::new("target/release/rendiff");
    println!(
        "{} triangles at {}x{}: {} primary rays, {} shadow rays; {} triangles at ten million; {} bundled scenes; loaded in {:.1} s; threads {threads:?}, medians of {repeats}",
        tri.len(),
        tri.camera.width(),
        tri.camera.height(),
        rays.len(),
        shadow.len(),
        ten.tri.len(),
        bundled.len(),
        load.elapsed().as_secs_f64()
    );

    let names = [
        "build, SAH, 940 k",
        "build, Morton, 940 k",
        "build, Embree, 940 k",
        "primary rays, ours one at a time",
        "primary rays, Embree rtcIntersect1",
        "4x2 packets, ours",
        "4x2 packets, Embree rtcIntersect8",
        "shadow rays, ours",
        "shadow rays, Embree rtcOccluded1",
        "raster frame, shadowless",
        "ray frame, shadowless, BVH prebuilt",
        "raster frame, shadows",
        "ray frame, shadows, BVH prebuilt",
        "build, SAH, 10 M",
        "build, Morton, 10 M",
        "build, Embree, 10 M",
        "bundled scenes, raster (sum)",
        "bundled scenes, ray (sum)",
        "whole process, dense.toml, raster",
    ];
    let mut rows: Vec<Row> = names
        .iter()
        .map(|n| Row {
            name: (*n).to_string(),
            ms: Vec::new(),
        })
        .collect();
    // (thread count, the hashes and counts it produced)
    let mut results: Vec<(usize, Vec<u64>)> = Vec::new();
    let ten_positions: Vec<[f32; 3]> = ten.tri.positions.iter().map(|p| p.to_array()).collect();
    let raster_opts = job.raster_options();
    let mut shadowless_opts = job.raster_options();
    shadowless_opts.shadows_needed = false;

    for &n in threads {
        let p = pool(n)?;
        let config = format!("threads={n}");
        let started = Instant::now();
        let mut ms = Vec::new();
        let mut seen = Vec::new();
        let sah = AccelOptions::default();
        let morton = AccelOptions {
            build: BvhBuild::Morton,
            ..AccelOptions::default()
        };
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(Accel::new(&tri, sah));
        }));
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(Accel::new(&tri, morton));
        }));
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(embree::EmbreeScene::new(&positions, &tri.tris, &config).ok());
        }));
        let accel = p.install(|| Accel::new(&tri, sah));
        let emb = embree::EmbreeScene::new(&positions, &tri.tris, &config)?;
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(ours_primary(&accel, &rays));
        }));
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(embree_primary(&emb, &rays));
        }));
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(ours_packets(&accel, &blocks));
        }));
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(embree_packets(&emb, &blocks));
        }));
        let vis = ShadowRays::new(&accel);
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(ours_blocked(&vis, &shadow));
        }));
        ms.push(time_ms(&p, repeats, &|| {
            std::hint::black_box(embree_blocked(&emb, &shadow));
        }));
        seen.push(p.install(|| ours_primary(&accel, &rays)) as u64);
        seen.push(p.install(|| ours_packets(&accel, &blocks)) as u64);
        seen.push(p.install(|| ours_blocked(&vis, &shadow)) as u64);
        drop(emb);

        // The shaded frames, each drawn frame after frame into the same
        // memory after one untimed frame, as `summary`'s frames row.
        for (scene, opts, shadows) in [
            (&shadowless, &shadowless_opts, false),
            (&tri, &raster_opts, true),
        ] {
            let frame = std::sync::Mutex::new(Frame::new(0, 0, 1, scene.background));
            let buffers = std::sync::Mutex::new(raster::RasterBuffers::default());
            let raster_frame = || {
                let (mut frame, mut buffers) = (frame.lock().unwrap(), buffers.lock().unwrap());
                std::hint::black_box(raster::render_into(scene, opts, &mut buffers, &mut frame));
            };
            p.install(raster_frame);
            seen.push(frame_hash(&frame.lock().unwrap()));
            let t_raster = time_ms(&p, repeats, &raster_frame);
            let accel = p.install(|| Accel::new(scene, sah));
            let ray_opts = rendiff::ray::RayOptions {
                max_depth: 1,
                shadows,
                gate_eps: rendiff::GATE_EPS,
            };
            let ray_frame = || {
                let mut frame = frame.lock().unwrap();
                std::hint::black_box(rendiff::ray::render_into(&accel, &ray_opts, &mut frame));
            };
            p.install(ray_frame);
            seen.push(frame_hash(&frame.lock().unwrap()));
            let t_ray = time_ms(&p, repeats, &ray_frame);
            ms.push(t_raster);
            ms.push(t_ray);
        }

        let few = repeats.clamp(1, 3);
        for build in [sah, morton] {
            ms.push(time_ms(&p, few, &|| {
                std::hint::black_box(Accel::new(&ten.tri, build));
            }));
        }
        ms.push(time_ms(&p, few, &|| {
            std::hint::black_box(
                embree::EmbreeScene::new(&ten_positions, &ten.tri.tris, &config).ok(),
            );
        }));

        for backend in [Backend::Raster, Backend::Ray] {
            let mut total = 0.0;
            for job in &bundled {
                let frame = p.install(|| job.render(backend))?.frame;
                seen.push(frame_hash(&frame));
                let times: Vec<f64> = (0..repeats)
                    .map(|_| p.install(|| job.render(backend).map(|r| r.time_ms)))
                    .collect::<Result<_, _>>()?;
                total += median(times);
            }
            ms.push(total);
        }

        if exe.exists() {
            let out =
                std::env::temp_dir().join(format!("rendiff-scaling-{}.png", std::process::id()));
            let mut times = Vec::new();
            for _ in 0..repeats {
                let t = Instant::now();
                let status = Command::new(exe)
                    .args(["render", "--backend", "raster", "--threads"])
                    .arg(n.to_string())
                    .arg("-o")
                    .arg(&out)
                    .arg("scenes/dense.toml")
                    .output()?;
                if !status.status.success() {
                    bail!("{} render failed", exe.display());
                }
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
            ms.push(median(times));
            let _ = std::fs::remove_file(&out);
        } else {
            ms.push(f64::NAN);
        }

        for (row, v) in rows.iter_mut().zip(&ms) {
            row.ms.push(*v);
        }
        println!(
            "{n} thread(s) measured in {:.1} s: {}",
            started.elapsed().as_secs_f64(),
            rows.iter()
                .map(|r| format!(
                    "{} {:.1} ms",
                    r.name,
                    r.ms.last().copied().unwrap_or(f64::NAN)
                ))
                .collect::<Vec<_>>()
                .join("; ")
        );
        results.push((n, seen));
    }

    // The table: ms at each count, then speed-up and efficiency against
    // the first count (1 thread when the list starts there).
    let first = threads[0];
    println!();
    println!(
        "| measure | {} |",
        threads
            .iter()
            .map(|n| format!("{n} thr ms (speed-up, efficiency)"))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!("|---|{}", "---|".repeat(threads.len()));
    for row in &rows {
        let cells: Vec<String> = threads
            .iter()
            .zip(&row.ms)
            .map(|(&n, &t)| {
                let s = row.ms[0] / t;
                let scale = n as f64 / first as f64;
                format!("{t:.1} ({s:.2}×, {:.0} %)", s / scale * 100.0)
            })
            .collect();
        println!("| {} | {} |", row.name, cells.join(" | "));
    }

    let (n0, base) = &results[0];
    let mut differ = Vec::new();
    for (n, seen) in &results[1..] {
        let k = seen.iter().zip(base).filter(|(a, b)| a != b).count();
        if k > 0 || seen.len() != base.len() {
            differ.push(format!("{n} threads: {k} of {} results differ", seen.len()));
        }
    }
    if differ.is_empty() {
        println!(
            "thread invariance: all {} results (hit and blocked counts, {} frame hashes) are identical at {threads:?} threads",
            base.len(),
            base.len() - 3
        );
        Ok(())
    } else {
        bail!(
            "thread invariance broken against {n0} thread(s): {}",
            differ.join("; ")
        )
    }
}
