//! rendiff's rasterizer beside Mesa's llvmpipe on one shaded frame.
//!
//! The scene is the 940 k-triangle bunny (`benches/scenes/bunny_1m.toml`
//! split 4 times, as for `embree`) with its light shadowless, as in the
//! bench `raster_frame_shadowless_940k_1080p`. rendiff-peers writes the
//! mesh, the camera's world → clip matrix and the shading constants to a
//! file; `llvmpipe/frame.c` (compiled by `build.rs`) uploads them once to
//! an OpenGL 3.3 core context on llvmpipe (surfaceless EGL, an RGBA8 +
//! 24-bit depth framebuffer object of the camera's size) and times each
//! frame: `glClear`, one `glDrawElements` with depth test and back-face
//! culling, `glFinish`. One thread: `LP_NUM_THREADS=0` makes llvmpipe
//! rasterize on the calling thread (vertex processing runs there anyway).
//!
//! rendiff's frame is `raster::render_into` on a 1-thread rayon pool:
//! transform, setup, binning, visibility and deferred shading into a
//! `Frame` (colour, depth, id and flags per sample), frame after frame in
//! the same memory as llvmpipe's framebuffer object is (until 2026-12-03
//! each frame was a fresh `raster::render`, whose new memory the kernel
//! zeroes: 28 % of that frame on this machine).
//!
//! Both draw the same triangles: the covered-pixel counts, the share of
//! pixels where llvmpipe's `gl_PrimitiveID` is rendiff's triangle id, and
//! the share of pixels whose colours agree within 2/255 are printed.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rendiff::camera::{Camera, Projection};
use rendiff::color::Rgb;
use rendiff::frame::BACKGROUND;
use rendiff::math::Vec3;
use rendiff::raster;
use rendiff::shade::LightKind;
use rendiff::tri_scene::{NO_INDEX, TriScene};
use rendiff::{Overrides, Prepared};

use crate::{median, pool};

/// The scene of the comparison and its subdivision (as `embree`).
const SCENE: &str = "benches/scenes/bunny_1m.toml";
const SUBDIVIDE: u32 = 4;

/// Column-major `f32` world → clip matrix that gives OpenGL the pixels of
/// rendiff's camera: clip `x/w`, `y/w` are the camera's normalised screen
/// coordinates (`Camera::project`, y up; OpenGL's window rows then run
/// bottom to top), `w` the view depth, and depth maps `near..far` to
/// `-1..1` (both clip at near and far).
fn view_proj(cam: &Camera) -> [f32; 16] {
    let (n, f) = (cam.near(), cam.far());
    let a = cam.aspect();
    let (r, u, fw, e) = (cam.right(), cam.up(), cam.forward(), cam.eye());
    // View rows: right, up, -forward (OpenGL looks down -z), relative to
    // the eye.
    let view = [
        [r.x, r.y, r.z, -r.dot(e)],
        [u.x, u.y, u.z, -u.dot(e)],
        [-fw.x, -fw.y, -fw.z, fw.dot(e)],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let proj = match cam.projection() {
        Projection::Perspective { tan_half_fov: t } => [
            [1.0 / (t * a), 0.0, 0.0, 0.0],
            [0.0, 1.0 / t, 0.0, 0.0],
            [0.0, 0.0, -(f + n) / (f - n), -2.0 * f * n / (f - n)],
            [0.0, 0.0, -1.0, 0.0],
        ],
        Projection::Orthographic { view_height: h } => [
            [2.0 / (h * a), 0.0, 0.0, 0.0],
            [0.0, 2.0 / h, 0.0, 0.0],
            [0.0, 0.0, -2.0 / (f - n), -(f + n) / (f - n)],
            [0.0, 0.0, 0.0, 1.0],
        ],
    };
    let mut out = [0.0f32; 16];
    for col in 0..4 {
        for row in 0..4 {
            let v: f64 = (0..4).map(|k| proj[row][k] * view[k][col]).sum();
            #[expect(clippy::cast_possible_truncation, reason = "OpenGL takes f32")]
            let v = v as f32;
            out[col * 4 + row] = v;
        }
    }
    out
}

/// One OpenGL vertex per distinct (position, normal) corner; a flat
/// triangle's corners get its geometric normal. Triangles keep their
/// order, so `gl_PrimitiveID` is rendiff's triangle id.
fn gl_mesh(t: &TriScene) -> (Vec<[f32; 6]>, Vec<u32>) {
    let mut index = std::collections::HashMap::with_capacity(t.positions.len());
    let mut verts: Vec<[f32; 6]> = Vec::with_capacity(t.positions.len());
    let mut idx = Vec::with_capacity(3 * t.tris.len());
    let push = |verts: &mut Vec<[f32; 6]>, p: Vec3, n: Vec3| {
        let k = u32::try_from(verts.len()).expect("fewer than 2^32 vertices");
        verts.push([p.x, p.y, p.z, n.x, n.y, n.z]);
        k
    };
    for (tri, nrm) in t.tris.iter().zip(&t.tri_normals) {
        if nrm.contains(&NO_INDEX) {
            let p = tri.map(|i| t.positions[i as usize]);
            let ng = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            for q in p {
                idx.push(push(&mut verts, q, ng));
            }
        } else {
            for (&pi, &ni) in tri.iter().zip(nrm) {
                let k = *index.entry((pi, ni)).or_insert_with(|| {
                    push(&mut verts, t.positions[pi as usize], t.normals[ni as usize])
                });
                idx.push(k);
            }
        }
    }
    (verts, idx)
}

/// The input file of `frame.c`: see its header for the layout.
fn input_file(t: &TriScene) -> Result<Vec<u8>> {
    let cam = &t.camera;
    if t.lights.len() != 1 {
        bail!(
            "the llvmpipe peer shades one light; the scene has {}",
            t.lights.len()
        );
    }
    let light = &t.lights[0];
    let LightKind::Point { position } = light.kind else {
        bail!("the llvmpipe peer shades a point light");
    };
    let m = &t.materials[usize::from(t.tri_material[0])];
    if t.tri_material.iter().any(|&k| k != t.tri_material[0])
        || light.fade.is_some()
        || m.brilliance != 1.0
        || m.metallic != 0.0
        || m.specular != 0.0
        || m.bump.is_some()
        || m.needs_uv()
    {
        bail!(
            "the llvmpipe peer shades one plain material (no brilliance, metallic, specular, bump or image) under an unfaded light"
        );
    }
    let (pig, f, tr) = m.pigment_at(None);
    let opacity = 1.0 - f - tr;
    let ka = pig * (m.ambient * t.ambient_light) * opacity + pig * m.emission * opacity;
    let kd = pig * light.color * (m.diffuse * opacity);
    // rendiff gives a shadowless light no highlight.
    let ks = if light.shadowless {
        Rgb::BLACK
    } else {
        light.color * m.phong
    };
    let (verts, idx) = gl_mesh(t);
    let mut b = Vec::with_capacity(64 + verts.len() * 24 + idx.len() * 4);
    b.extend_from_slice(b"RDLLVMP1");
    for v in [
        cam.width(),
        cam.height(),
        u32::try_from(verts.len())?,
        u32::try_from(t.tris.len())?,
    ] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    let rgb = |c: Rgb| [c.r, c.g, c.b];
    let eye = t.camera.eye_f32();
    let floats = view_proj(cam)
        .into_iter()
        .chain(eye.to_array())
        .chain(position.to_array())
        .chain(rgb(ka))
        .chain(rgb(kd))
        .chain(rgb(ks))
        .chain([m.phong_size]);
    for x in floats {
        b.extend_from_slice(&x.to_le_bytes());
    }
    for x in verts.iter().flatten() {
        b.extend_from_slice(&x.to_le_bytes());
    }
    for i in idx {
        b.extend_from_slice(&i.to_le_bytes());
    }
    Ok(b)
}

/// What `frame.c` printed.
struct GlRun {
    renderer: String,
    threads: String,
    /// Per frame: wall and process CPU milliseconds.
    frames_ms: Vec<(f64, f64)>,
    covered: usize,
}

fn run_frame(exe: &Path, input: &Path, frames: usize, prefix: &Path) -> Result<GlRun> {
    let out = Command::new(exe)
        .arg(input)
        .arg(frames.to_string())
        .arg(prefix)
        .env("LIBGL_ALWAYS_SOFTWARE", "1")
        .env("GALLIUM_DRIVER", "llvmpipe")
        .env("LP_NUM_THREADS", "0")
        .output()
        .with_context(|| format!("could not run {}", exe.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        bail!(
            "the llvmpipe peer failed ({}): {}{}",
            out.status,
            stdout.trim(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let field = |key: &str| {
        stdout
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .map(str::trim)
    };
    let renderer = field("renderer:").unwrap_or_default().to_string();
    if !renderer.contains("llvmpipe") {
        bail!("the GL renderer is {renderer:?}, not llvmpipe: no figure reported");
    }
    let frames_ms = stdout
        .lines()
        .filter_map(|l| l.strip_prefix("frame_ms:"))
        .map(|s| {
            let mut v = s.split_whitespace().map(str::parse::<f64>);
            match (v.next(), v.next()) {
                (Some(Ok(wall)), Some(Ok(cpu))) => Ok((wall, cpu)),
                _ => Err(anyhow::anyhow!("bad frame line {s:?}")),
            }
        })
        .collect::<Result<Vec<_>>>()?;
    if frames_ms.len() != frames {
        bail!(
            "the llvmpipe peer printed {} frames of {frames}",
            frames_ms.len()
        );
    }
    Ok(GlRun {
        renderer,
        threads: field("threads:").unwrap_or("?").to_string(),
        frames_ms,
        covered: field("covered:").context("no covered count")?.parse()?,
    })
}

/// CPU time of the calling thread in milliseconds (Linux
/// `/proc/thread-self/schedstat`: nanoseconds on a CPU); `None` elsewhere.
fn thread_cpu_ms() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-6)
}

fn quantise(x: f32) -> u8 {
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "clamped to 0..=255 first"
    )]
    let q = (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    q
}

fn peer_exe() -> Result<PathBuf> {
    match option_env!("RENDIFF_LLVMPIPE_FRAME") {
        Some(p) => Ok(PathBuf::from(p)),
        None => bail!(
            "the llvmpipe peer was not built: {}",
            option_env!("RENDIFF_LLVMPIPE_ERROR").unwrap_or("unknown reason")
        ),
    }
}

/// Times llvmpipe's frame (median of `repeats` after one warm-up) and
/// rendiff's rasterizer frame of the same scene on one thread, prints the
/// comparison, and returns how many times faster rendiff is.
///
/// # Errors
///
/// When the peer was not built, the renderer is not llvmpipe, the scene
/// does not load, or the two frames do not cover the same pixels (within
/// 2 %).
pub fn compare(repeats: usize) -> Result<f64> {
    let exe = peer_exe()?;
    let repeats = repeats.max(1);
    let job = Prepared::load(Path::new(SCENE), &Overrides::default())
        .context("run from the repository root")?;
    let mut t = job.tri.subdivided(SUBDIVIDE);
    t.lights[0].shadowless = true;
    let cam = t.camera;
    let (w, h) = (cam.width() as usize, cam.height() as usize);
    if cam.samples() != 1 {
        bail!("the llvmpipe peer renders one sample per pixel");
    }

    let work = std::env::temp_dir().join(format!("rendiff-llvmpipe-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let input = work.join("input.bin");
    std::fs::write(&input, input_file(&t)?)?;
    let prefix = work.join("frame");
    let gl = run_frame(&exe, &input, repeats + 1, &prefix);
    let rgba = std::fs::read(prefix.with_extension("rgba"));
    let ids = std::fs::read(prefix.with_extension("id"));
    let _ = std::fs::remove_dir_all(&work);
    let (gl, rgba, ids) = (gl?, rgba?, ids?);
    if rgba.len() != 4 * w * h || ids.len() != 4 * w * h {
        bail!("the llvmpipe peer's read-back is not {w}x{h}");
    }
    let gl_ms = median(gl.frames_ms[1..].iter().map(|f| f.0).collect());
    let gl_cpu = median(gl.frames_ms[1..].iter().map(|f| f.1).collect());

    let mut opts = job.raster_options();
    opts.shadows_needed = false;
    let p = pool(1)?;
    // Frame after frame into the same memory, as llvmpipe draws into its
    // framebuffer object (`raster::render_into`); the first is untimed.
    let mut frame = rendiff::frame::Frame::new(0, 0, 1, t.background);
    let mut buffers = raster::RasterBuffers::default();
    let mut time = || {
        p.install(|| {
            let (start, cpu) = (Instant::now(), thread_cpu_ms());
            raster::render_into(&t, &opts, &mut buffers, &mut frame);
            let cpu = thread_cpu_ms().zip(cpu).map(|(b, a)| b - a);
            (start.elapsed().as_secs_f64() * 1e3, cpu)
        })
    };
    time();
    let runs: Vec<(f64, Option<f64>)> = (0..repeats).map(|_| time()).collect();
    let ours_ms = median(runs.iter().map(|r| r.0).collect());
    let ours_cpu = runs
        .iter()
        .map(|r| r.1)
        .collect::<Option<Vec<f64>>>()
        .map(median);

    // rendiff's rows run top to bottom, OpenGL's bottom to top.
    let ours_covered = frame.id.iter().filter(|&&id| id != BACKGROUND).count();
    let (mut same_id, mut both, mut close) = (0usize, 0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let g = 4 * ((h - 1 - y) * w + x);
            let gl_id = u32::from_le_bytes([ids[g], ids[g + 1], ids[g + 2], ids[g + 3]]);
            let ours_id = frame.id[i];
            if gl_id.wrapping_sub(1) == ours_id {
                same_id += 1;
            }
            if gl_id != 0 && ours_id != BACKGROUND {
                both += 1;
                let c = frame.color[i];
                let q = [quantise(c.r), quantise(c.g), quantise(c.b)];
                if (0..3).all(|k| q[k].abs_diff(rgba[g + k]) <= 2) {
                    close += 1;
                }
            }
        }
    }
    let ratio = gl_ms / ours_ms;
    let slower = if ratio < 1.0 {
        format!(" (llvmpipe is {:.2}x faster)", 1.0 / ratio)
    } else {
        String::new()
    };
    println!(
        "llvmpipe: 1 thread, {}x{}, {} triangles: llvmpipe {gl_ms:.1} ms (median of {repeats}), rendiff raster {ours_ms:.1} ms; rendiff is {ratio:.2}x faster{slower}",
        cam.width(),
        cam.height(),
        t.len()
    );
    let pct = |k: usize, of: usize| 100.0 * k as f64 / of.max(1) as f64;
    let mut note = String::new();
    if let Some(c) = ours_cpu {
        writeln!(
            note,
            "llvmpipe: CPU time (a shared machine's wall times include waiting): llvmpipe {gl_cpu:.1} ms, rendiff raster {c:.1} ms ({:.2}x)",
            gl_cpu / c
        )?;
    }
    write!(
        note,
        "llvmpipe: {}, its process's threads: {}; covered pixels llvmpipe {}, rendiff {} ({:+.3} %); same triangle at {:.3} % of pixels; colour within 2/255 at {:.3} % of the pixels both cover",
        gl.renderer,
        gl.threads,
        gl.covered,
        ours_covered,
        pct(gl.covered, ours_covered) - 100.0,
        pct(same_id, w * h),
        pct(close, both)
    )?;
    println!("{note}");
    if gl.covered.abs_diff(ours_covered) * 50 > ours_covered {
        bail!(
            "llvmpipe covers {} pixels and rendiff {ours_covered}: more than 2 % apart, the camera mapping is wrong",
            gl.covered
        );
    }
    Ok(ratio)
}
