//! `rendiff-peers summary`: every measure of issue 17's table from one
//! run, each beside the figure it started from and its target.
//!
//! The rows: primary, coherent and shadow rays and the BVH build against
//! Embree 3 (the 940 k-triangle bunny at 1080p), the build at ten million
//! triangles, the rasterizer's shaded frame against the ray tracer's (BVH
//! prebuilt) and against Mesa llvmpipe, the render phase against POV-Ray
//! 3.7 over the bundled scenes and over the adversarial ones
//! (`benches/scenes/adversarial`), the whole process against POV-Ray's on
//! the largest bundled mesh scene (wall time, and each process's CPU
//! time beside it: POV-Ray 3.7 idles ~0.7 s a run), and loading a
//! 177 k-triangle OBJ. All on one thread, medians.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rendiff::accel::{Accel, AccelOptions};
use rendiff::pov::golden::{self, Variant};
use rendiff::{Overrides, Prepared, raster};

use crate::{median, pool, time_ms};

/// One row: the measure, where it stood when the issue was filed, the
/// figure now, and the target.
struct Row {
    measure: &'static str,
    before: &'static str,
    now: String,
    target: &'static str,
}

/// Runs every comparison and prints the table.
pub fn summary(repeats: usize) -> Result<()> {
    let mut rows = Vec::new();
    let bunny = Path::new("benches/scenes/bunny_1m.toml");
    let rays = crate::embree_cmp(bunny, 4, rendiff::accel::BvhBuild::Sah, repeats)?;
    rows.push(Row {
        measure: "primary rays, 940 k bunny 1080p, vs Embree rtcIntersect1 (speed ratio)",
        before: "0.65×",
        now: format!("{:.2}×", rays.primary),
        target: "≥ 1.0×",
    });
    rows.push(Row {
        measure: "coherent 4×2 blocks vs Embree rtcIntersect8 (ours: packets of 8)",
        before: "—",
        now: format!("{:.2}×", rays.coherent),
        target: "≥ 1.0×",
    });
    rows.push(Row {
        measure: "shadow rays, same scene (M rays/s; vs Embree rtcOccluded1)",
        before: "2.3 M rays/s",
        now: format!(
            "{:.2} M rays/s ({:.2}× Embree)",
            rays.shadow_mrays, rays.shadow_vs_embree
        ),
        target: "≥ 4.6 M rays/s",
    });
    rows.push(Row {
        measure: "BVH build 940 k, ours / Embree",
        before: "1.54×",
        now: format!("{:.2}×", rays.build),
        target: "≤ 1.0×",
    });
    let trees = crate::trees(bunny, 4, repeats.max(5))?;
    let embree_build = rays.embree_build_ms;
    rows.push(Row {
        measure: "BVH build 940 k in Morton order, ours / Embree (its walks against the SAH tree's: primary, packets, shadow)",
        before: "—",
        now: format!(
            "{:.2}× ({:.0} / {embree_build:.0} ms; walks {:.2}×, {:.2}×, {:.2}× the SAH's time)",
            trees.build[1] / embree_build,
            trees.build[1],
            trees.primary[1] / trees.primary[0],
            trees.packets[1] / trees.packets[0],
            trees.shadow[1] / trees.shadow[0],
        ),
        target: "≤ 1.0× at equal trace speed",
    });
    let (ours10, morton10, embree10) = build_10m(repeats.min(3))?;
    rows.push(Row {
        measure: "BVH build at 10 M triangles (µs per triangle: SAH; Morton order; Embree)",
        before: "0.5 µs",
        now: format!("{ours10:.3} µs; {morton10:.3} µs (Embree {embree10:.3} µs)"),
        target: "≤ 0.25 µs",
    });
    let (raster_ms, ray_ms) = frames(repeats)?;
    rows.push(Row {
        measure: "raster shaded frame vs ray frame, BVH prebuilt, shadowless (940 k, 1080p)",
        before: "2.4×",
        now: format!(
            "{:.2}× ({raster_ms:.1} / {ray_ms:.1} ms)",
            ray_ms / raster_ms
        ),
        target: "≥ 5×",
    });
    let llvm = match crate::llvmpipe::compare(repeats) {
        Ok(r) => format!("{r:.2}×"),
        Err(e) => format!("not measured: {e:#}"),
    };
    rows.push(Row {
        measure: "raster shaded frame vs Mesa llvmpipe (speed ratio)",
        before: "1.3–1.6× (not measured in the project)",
        now: llvm,
        target: "≥ 2×",
    });
    rows.push(pov_row(
        &crate::bundled_scenes()?,
        repeats,
        "render phase vs POV-Ray 3.7, geometric mean over bundled scenes (worst)",
        ("4.7× (worst 2.8×)", "≥ 10× (worst ≥ 5×)"),
    )?);
    rows.push(pov_row(
        &adversarial()?,
        repeats,
        "render phase vs POV-Ray 3.7, the adversarial scenes of benches/scenes/adversarial (worst)",
        ("—", "(the bundled scenes' row)"),
    )?);
    let dense = Path::new("scenes/dense.toml");
    let w = whole_process(dense, repeats.min(5))?;
    let cpu = match (w.ours_cpu, w.pov_cpu) {
        (Some(o), Some(p)) => format!("; CPU time {:.2}× ({o:.0} / {p:.0} ms)", p / o),
        _ => String::new(),
    };
    rows.push(Row {
        measure: "whole process vs POV-Ray (load, build, render, write), scenes/dense.toml",
        before: "4.4× (a 202 k dragon at 1280×720)",
        now: format!(
            "{:.2}× ({:.0} / {:.0} ms{cpu})",
            w.pov_ms / w.ours_ms,
            w.ours_ms,
            w.pov_ms
        ),
        target: "≥ 20×",
    });
    let (load_ms, mb, tris) = obj_load(repeats)?;
    rows.push(Row {
        measure: "OBJ load + tessellate",
        before: "~0.29 s (7 MB, 200 k)",
        now: format!("{:.3} s ({mb:.1} MB, {tris} triangles)", load_ms / 1e3),
        target: "≤ 0.1 s",
    });
    let mut out = String::from("\n| measure | when filed | now | target |\n|---|---|---|---|\n");
    for r in &rows {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} |",
            r.measure, r.before, r.now, r.target
        );
    }
    println!("{out}");
    Ok(())
}

/// The row of the render phase against POV-Ray over `scenes` (1 thread):
/// the better backend's geometric mean and the worst scene.
fn pov_row(
    scenes: &[PathBuf],
    repeats: usize,
    measure: &'static str,
    (before, target): (&'static str, &'static str),
) -> Result<Row> {
    let pov = crate::povray_cmp(scenes, &[1], repeats)?;
    let (_, geo, worst, worst_scene) = pov.first().context("no POV-Ray figures")?;
    Ok(Row {
        measure,
        before,
        now: format!("{geo:.2}× (worst {worst:.2}×, {worst_scene})"),
        target,
    })
}

/// BVH build time per triangle at ten million triangles
/// (`benches/scenes/ten_million.toml`), ours by the SAH and in Morton order
/// and Embree's, 1 thread, in µs.
fn build_10m(repeats: usize) -> Result<(f64, f64, f64)> {
    let job = Prepared::load(
        Path::new("benches/scenes/ten_million.toml"),
        &Overrides::default(),
    )?;
    let tri = &job.tri;
    let p = pool(1)?;
    let ours = time_ms(&p, repeats, &|| {
        std::hint::black_box(Accel::new(tri, AccelOptions::default()));
    });
    let morton = time_ms(&p, repeats, &|| {
        std::hint::black_box(Accel::new(
            tri,
            AccelOptions {
                build: rendiff::accel::BvhBuild::Morton,
                ..AccelOptions::default()
            },
        ));
    });
    let positions: Vec<[f32; 3]> = tri.positions.iter().map(|v| v.to_array()).collect();
    let embree = time_ms(&p, repeats, &|| {
        std::hint::black_box(
            crate::embree::EmbreeScene::new(&positions, &tri.tris, "threads=1").ok(),
        );
    });
    let n = tri.len() as f64;
    println!(
        "build at {} triangles, 1 thread: ours {ours:.0} ms (Morton order {morton:.0} ms), Embree {embree:.0} ms",
        tri.len()
    );
    Ok((ours * 1e3 / n, morton * 1e3 / n, embree * 1e3 / n))
}

/// The rasterizer's shaded frame and the ray tracer's (BVH built
/// beforehand) of the 940 k bunny with its light shadowless, 1 thread, ms;
/// each draws frame after frame into the same memory (`render_into`).
fn frames(repeats: usize) -> Result<(f64, f64)> {
    let job = Prepared::load(
        Path::new("benches/scenes/bunny_1m.toml"),
        &Overrides::default(),
    )?;
    let mut t = job.tri.subdivided(4);
    t.lights[0].shadowless = true;
    let mut opts = job.raster_options();
    opts.shadows_needed = false;
    let p = pool(1)?;
    // Each backend draws frame after frame into the same memory
    // (`render_into`), as the llvmpipe row's frames do.
    let frame = std::sync::Mutex::new(rendiff::frame::Frame::new(0, 0, 1, t.background));
    let buffers = std::sync::Mutex::new(raster::RasterBuffers::default());
    let raster = || {
        let (mut frame, mut buffers) = (frame.lock().unwrap(), buffers.lock().unwrap());
        std::hint::black_box(raster::render_into(&t, &opts, &mut buffers, &mut frame));
    };
    // One untimed frame first (its memory is fresh), as llvmpipe's.
    p.install(raster);
    let raster_ms = time_ms(&p, repeats, &raster);
    let accel = Accel::new(&t, AccelOptions::default());
    let ray_opts = rendiff::ray::RayOptions {
        max_depth: 1,
        shadows: false,
        gate_eps: rendiff::GATE_EPS,
    };
    let ray = || {
        let mut frame = frame.lock().unwrap();
        std::hint::black_box(rendiff::ray::render_into(&accel, &ray_opts, &mut frame));
    };
    p.install(ray);
    let ray_ms = time_ms(&p, repeats, &ray);
    println!(
        "frames, 940 k bunny 1080p, shadowless, 1 thread: raster {raster_ms:.1} ms, ray (BVH prebuilt) {ray_ms:.1} ms"
    );
    Ok((raster_ms, ray_ms))
}

/// The whole process, wall clock and each process's CPU time, 1
/// thread: `rendiff render` (load, tessellate, build, render, PNG) with
/// its faster backend at equal error (the ray tracer alone where the
/// scene has a ray tree), against `povray` on the scene's mesh export
/// (start-up, parse, bounding, trace, PNG). Needs
/// `target/release/rendiff` (`make peers` builds it). In ms.
fn whole_process(scene: &Path, repeats: usize) -> Result<Whole> {
    let exe = Path::new("target/release/rendiff");
    if !exe.exists() {
        bail!(
            "{} is missing: run `cargo build --release` first",
            exe.display()
        );
    }
    let job = Prepared::load(scene, &Overrides::default())?;
    let refs = golden::references(&job.scene, &job.tri)?;
    let main = refs
        .iter()
        .find(|r| r.variant == Variant::Main)
        .context("no POV-Ray export")?;
    let work = std::env::temp_dir().join(format!("rendiff-whole-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let pov = work.join("scene.pov");
    std::fs::write(&pov, &main.export.text)?;
    for img in &main.export.images {
        img.materialise(&work)?;
    }
    // (wall ms, CPU ms): the CPU time is the child's own, from the
    // rusage of the waited-for children before and after it.
    let wall = |cmd: &mut Command| -> Result<(f64, Option<f64>)> {
        let cpu0 = children_cpu_ms();
        let t = Instant::now();
        let out = cmd.output().context("could not run a peer")?;
        if !out.status.success() {
            bail!(
                "{cmd:?} failed: {}",
                String::from_utf8_lossy(&out.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            );
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        Ok((ms, cpu0.zip(children_cpu_ms()).map(|(a, b)| b - a)))
    };
    let (w, h) = main.export.render_size;
    let dir = scene.parent().filter(|p| !p.as_os_str().is_empty());
    let mut ours = Vec::new();
    let mut theirs = Vec::new();
    // The rasterizer shades locally: it is at equal error only where the
    // scene has no ray tree (no depth-1 reference is made for it then).
    let backends: &[&str] = if refs.iter().any(|r| r.variant == Variant::Depth1) {
        &["ray"]
    } else {
        &["raster", "ray"]
    };
    let mut ours_cpu = Vec::new();
    let mut theirs_cpu = Vec::new();
    for _ in 0..repeats.max(1) {
        let mut best = (f64::INFINITY, None);
        for backend in backends {
            let ms = wall(
                Command::new(exe)
                    .args(["render", "--threads", "1", "--backend", backend, "-o"])
                    .arg(work.join("ours.png"))
                    .arg(scene),
            )?;
            if ms.0 < best.0 {
                best = ms;
            }
        }
        ours.push(best.0);
        ours_cpu.extend(best.1);
        let pov_run = wall(
            Command::new("povray")
                .current_dir(dir.unwrap_or(Path::new(".")))
                .arg(format!("+I{}", pov.display()))
                .arg(format!("+O{}", work.join("pov.png").display()))
                .arg(format!("+W{w}"))
                .arg(format!("+H{h}"))
                .args(["-D", "-A", "+FN16", "File_Gamma=1.0", "+Q9", "+WT1"])
                .arg(format!("+L{}", work.display())),
        )?;
        theirs.push(pov_run.0);
        theirs_cpu.extend(pov_run.1);
    }
    let _ = std::fs::remove_dir_all(&work);
    let n = ours.len();
    let cpu_median = |v: Vec<f64>| (v.len() == n).then(|| median(v));
    let whole = Whole {
        ours_ms: median(ours),
        pov_ms: median(theirs),
        ours_cpu: cpu_median(ours_cpu),
        pov_cpu: cpu_median(theirs_cpu),
    };
    let cpu = match (whole.ours_cpu, whole.pov_cpu) {
        (Some(o), Some(p)) => format!("; CPU time rendiff {o:.0} ms, POV-Ray {p:.0} ms"),
        _ => String::new(),
    };
    println!(
        "whole process, {}, 1 thread: rendiff {:.0} ms (the faster backend), POV-Ray {:.0} ms{cpu}",
        scene.display(),
        whole.ours_ms,
        whole.pov_ms
    );
    Ok(whole)
}

/// The whole-process medians: wall time (what the row's ratio is), and
/// each process's own CPU time (user and system), which leaves out
/// the time a process waits, for the host's CPUs or idle by its own
/// design (`None` where the system does not report it).
struct Whole {
    ours_ms: f64,
    pov_ms: f64,
    ours_cpu: Option<f64>,
    pov_cpu: Option<f64>,
}

/// The CPU time (user and system) of every child process this process
/// has waited for, in ms: a child's own is the difference around its
/// run. `None` off Unix or on an error. (Through the `libc` crate, which
/// `memmap2` already brings in: its `rusage` has each target's layout.)
#[cfg(unix)]
fn children_cpu_ms() -> Option<f64> {
    // SAFETY: `rusage` is plain old data (integers and `timeval`s), for
    // which all-zero bytes are a value.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `getrusage` writes one `struct rusage` into the memory it
    // is given, which is ours and of that type.
    let rc = unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &raw mut u) };
    #[expect(
        clippy::cast_precision_loss,
        reason = "seconds and microseconds of a run"
    )]
    let ms = |tv: libc::timeval| tv.tv_sec as f64 * 1e3 + tv.tv_usec as f64 * 1e-3;
    (rc == 0).then(|| ms(u.ru_utime) + ms(u.ru_stime))
}

/// (No child CPU times off Unix.)
#[cfg(not(unix))]
fn children_cpu_ms() -> Option<f64> {
    None
}

/// Loading and tessellating a 177 k-triangle OBJ: the bundled dragon
/// (11 102 triangles) split twice into four, written as a plain `v`/`f`
/// file. Returns (ms, MB, triangles).
pub fn obj_load(repeats: usize) -> Result<(f64, f64, usize)> {
    let work = std::env::temp_dir().join(format!("rendiff-obj-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let toml = work.join("load.toml");
    let scene_text = |file: &str| {
        format!(
            "[image]\nwidth = 320\nheight = 240\n\n[camera]\neye = [0.0, 0.4, 3.0]\nlook_at = [0.0, 0.3, 0.0]\nup = [0.0, 1.0, 0.0]\nfov_y = 30.0\n\n\
             [[lights]]\nkind = \"point\"\nposition = [2.0, 4.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n\n\
             [materials.jade]\npigment = [0.35, 0.7, 0.45]\n\n\
             [[objects]]\nkind = \"mesh\"\nfile = \"{file}\"\nmaterial = \"jade\"\n"
        )
    };
    std::fs::copy(
        "scenes/meshes/stanford_dragon_res4.obj",
        work.join("dragon.obj"),
    )?;
    std::fs::write(&toml, scene_text("dragon.obj"))?;
    let one = Prepared::load(&toml, &Overrides::default())?.tri;
    let big = one.subdivided(2);
    let mut text = String::with_capacity(big.positions.len() * 40 + big.tris.len() * 30);
    for v in &big.positions {
        let _ = writeln!(text, "v {} {} {}", v.x, v.y, v.z);
    }
    for t in &big.tris {
        let _ = writeln!(text, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let obj = work.join("dragon177k.obj");
    std::fs::write(&obj, &text)?;
    std::fs::write(&toml, scene_text("dragon177k.obj"))?;
    let p = pool(1)?;
    let mut tris = 0;
    let ms = median(
        (0..repeats.max(1))
            .map(|_| {
                p.install(|| {
                    let t = Instant::now();
                    let job = Prepared::load(&toml, &Overrides::default());
                    let ms = t.elapsed().as_secs_f64() * 1e3;
                    tris = job.map_or(0, |j| j.tri.len());
                    ms
                })
            })
            .collect(),
    );
    let _ = std::fs::remove_dir_all(&work);
    if tris == 0 {
        bail!("the generated OBJ did not load");
    }
    println!(
        "OBJ load + tessellate, {:.1} MB, {tris} triangles, 1 thread: {ms:.1} ms",
        text.len() as f64 / 1e6
    );
    Ok((ms, text.len() as f64 / 1e6, tris))
}

/// The bundled scenes, sorted.
pub fn bundled() -> Result<Vec<PathBuf>> {
    scenes_in(Path::new("scenes"))
}

/// The adversarial scenes (`benches/scenes/adversarial`), sorted: written
/// to find where rendiff is slowest against POV-Ray, outside the bundled
/// set that the project's work was measured on.
pub fn adversarial() -> Result<Vec<PathBuf>> {
    scenes_in(Path::new("benches/scenes/adversarial"))
}

/// The scene files of a folder, sorted.
fn scenes_in(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: run from the repository root", dir.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    scenes.sort();
    Ok(scenes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A child that spends CPU shows in the difference of the children's
    /// CPU time around it, and never more than its wall time allows (one
    /// thread of it), plus one scheduler tick (10 ms at the coarsest
    /// kernel clock, 100 Hz), by which a kernel may account CPU time.
    #[cfg(unix)]
    #[test]
    fn a_childs_cpu_time_is_counted() {
        let before = children_cpu_ms().expect("getrusage answers on Unix");
        let t = Instant::now();
        let status = Command::new("sh")
            .args(["-c", "i=0; while [ $i -lt 300000 ]; do i=$((i+1)); done"])
            .status()
            .expect("sh runs");
        let wall = t.elapsed().as_secs_f64() * 1e3;
        assert!(status.success());
        let cpu = children_cpu_ms().expect("getrusage answers on Unix") - before;
        assert!(
            cpu > 10.0,
            "a busy loop of {wall:.0} ms spent {cpu:.1} ms of CPU"
        );
        assert!(
            cpu <= wall + 10.0,
            "{cpu:.1} ms of CPU in {wall:.1} ms of wall time"
        );
    }
}
