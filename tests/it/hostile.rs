//! The hostile corpus: inputs and file-system situations a careless or
//! malicious contributor can produce, one test per item of issue 14.
//! Every case runs the real binary. The big cases are generated here (no
//! large files in the repository) and run under an address-space limit
//! (`prlimit --as`), so a regression shows as a failed test, not as a
//! machine out of memory; each must end with exit status 2 (never 134 or
//! 137) within seconds, and the peak resident memory it reports
//! (`RENDIFF_PEAK_RSS`) must stay within its budget plus [`OVERHEAD`].
//!
//! The write cases check by content hash and file type that devices, link
//! targets, inputs and references are left as they were; the injection
//! cases check that the file an injected POV-Ray directive would create
//! never appears.

use std::ffi::OsStr;
use std::io::Write as _;
use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Resident memory a request holds beyond its budget: the binary and its
/// libraries, the thread stacks and the allocator's slack. A trivial
/// render measures 5–7 MB here; 64 MiB leaves room for allocator
/// fragmentation without letting an unbudgeted image (hundreds of MB in
/// every case below) through.
const OVERHEAD: u64 = 64 << 20;

/// The address space the big cases run in, beyond their budget: a normal
/// render needs under 128 MiB of it with two worker threads and two
/// allocator arenas (measured), so this limit only stops a case that
/// allocates what it should have refused.
const AS_SLACK: u64 = 512 << 20;

/// A folder of its own for each test.
fn temp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("hostile")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// What a run of the binary did.
#[derive(Debug)]
struct Run {
    code: Option<i32>,
    stdout: Vec<u8>,
    stderr: String,
    secs: f64,
    /// Peak resident memory in bytes, as the process reported it.
    peak: Option<u64>,
}

impl Run {
    fn refused(&self, what: &str) {
        assert_eq!(
            self.code,
            Some(2),
            "{what}: expected a refusal (exit 2), got {:?}\n{}",
            self.code,
            self.stderr
        );
        assert!(
            !self.stderr.contains("internal error") && !self.stderr.contains("panicked"),
            "{what}: {}",
            self.stderr
        );
    }

    fn within(&self, what: &str, budget: u64, secs: f64) {
        let peak = self.peak.expect("the peak is reported");
        eprintln!(
            "{what}: exit {:?} in {:.2} s, peak RSS {:.1} MiB (budget {:.1} MiB)",
            self.code,
            self.secs,
            peak as f64 / f64::from(1 << 20),
            budget as f64 / f64::from(1 << 20)
        );
        assert!(
            peak <= budget + OVERHEAD,
            "{what}: peak RSS {peak} B over the budget {budget} B + {OVERHEAD} B"
        );
        assert!(self.secs < secs, "{what}: took {:.1} s", self.secs);
    }
}

/// Runs the binary in `dir` with `args`, optionally under an address-space
/// limit, with two worker threads (so the limit does not depend on the
/// machine's cores) and the peak-memory report on.
fn run_in(dir: &Path, args: &[&OsStr], env: &[(&str, &OsStr)], limit: Option<u64>) -> Run {
    let bin = env!("CARGO_BIN_EXE_rendiff");
    let mut cmd = match limit {
        Some(bytes) => {
            let mut c = Command::new("prlimit");
            c.arg(format!("--as={bytes}")).arg("--").arg(bin);
            c
        }
        None => Command::new(bin),
    };
    cmd.args(args)
        .current_dir(dir)
        .env("RENDIFF_PEAK_RSS", "1")
        .env("RAYON_NUM_THREADS", "2")
        .env("MALLOC_ARENA_MAX", "2")
        .stdin(Stdio::null());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let start = Instant::now();
    let out = cmd.output().expect("run the binary");
    let secs = start.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let peak = stderr
        .lines()
        .find_map(|l| l.strip_prefix("peak RSS: "))
        .and_then(|v| v.trim_end_matches(" kB").trim().parse::<u64>().ok())
        .map(|kb| kb * 1024);
    Run {
        code: out.status.code(),
        stdout: out.stdout,
        stderr,
        secs,
        peak,
    }
}

fn run(dir: &Path, args: &[&str]) -> Run {
    let args: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
    run_in(dir, &args, &[], None)
}

fn run_limited(dir: &Path, args: &[&str], budget: u64) -> Run {
    let args: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
    run_in(dir, &args, &[], Some(budget + AS_SLACK))
}

/// A small scene: a floor and a sphere under one point light, with
/// `extra` appended (more materials, objects, settings).
fn scene(width: u32, height: u32, extra: &str) -> String {
    format!(
        r#"[image]
width = {width}
height = {height}
background = [0.1, 0.1, 0.15]

[camera]
eye = [0.0, 1.5, 4.0]
look_at = [0.0, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0

[[lights]]
kind = "point"
position = [3.0, 5.0, 3.0]
color = [1.0, 1.0, 1.0]

[materials.floor]
pigment = [0.7, 0.7, 0.7]

[materials.red]
pigment = [0.8, 0.2, 0.1]
phong = 0.5

[[objects]]
kind = "box"
material = "floor"
min = [-2.0, -0.2, -2.0]
max = [2.0, 0.0, 2.0]

[[objects]]
kind = "sphere"
material = "red"
center = [0.0, 0.6, 0.0]
radius = 0.6
{extra}"#
    )
}

/// FNV-1a of a file's bytes and its type, to see that it was not touched.
fn fingerprint(p: &Path) -> (u64, String) {
    let meta = std::fs::symlink_metadata(p).unwrap();
    let t = meta.file_type();
    let kind = if t.is_symlink() {
        format!("link to {}", std::fs::read_link(p).unwrap().display())
    } else if t.is_char_device() {
        "char device".into()
    } else if t.is_dir() {
        "folder".into()
    } else {
        "file".into()
    };
    let bytes = if t.is_file() {
        std::fs::read(p).unwrap()
    } else {
        Vec::new()
    };
    (rendiff::pov::fnv1a(&bytes), kind)
}

/// Every file below `dir` with its fingerprint.
fn tree(dir: &Path) -> Vec<(PathBuf, (u64, String))> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().filter_map(Result::ok) {
            let p = e.path();
            let meta = std::fs::symlink_metadata(&p).unwrap();
            if meta.is_dir() {
                stack.push(p.clone());
            }
            out.push((p.clone(), fingerprint(&p)));
        }
    }
    out.sort();
    out
}

// ---------------------------------------------------------------- PNG

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                (c >> 1) ^ 0xedb8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&u32::try_from(data.len()).unwrap().to_be_bytes());
    let mut body = kind.to_vec();
    body.extend_from_slice(data);
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32(&body).to_be_bytes());
}

fn zlib(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

/// An 8-bit RGB PNG of `w`×`h` grey pixels, with an optional chunk before
/// the image data.
fn png(w: u32, h: u32, extra: Option<(&[u8; 4], &[u8])>) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    if let Some((kind, data)) = extra {
        chunk(&mut out, kind, data);
    }
    let row = 1 + 3 * w as usize;
    let mut raw = vec![128u8; row * h as usize];
    for y in 0..h as usize {
        raw[y * row] = 0;
    }
    chunk(&mut out, b"IDAT", &zlib(&raw));
    chunk(&mut out, b"IEND", &[]);
    out
}

/// A PNG whose header claims `w`×`h` with a few KB of image data: what a
/// decoder that trusts the header would allocate for.
fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &zlib(&vec![0u8; 1 << 20]));
    chunk(&mut out, b"IEND", &[]);
    out
}

// ---------------------------------------------------------------- memory

#[test]
fn an_image_claiming_60000_squared_is_refused_from_its_header() {
    let dir = temp("png_bomb");
    std::fs::write(dir.join("s.toml"), scene(32, 24, "")).unwrap();
    std::fs::write(dir.join("bomb.png"), png_claiming(60000, 60000)).unwrap();
    let budget = rendiff::budget::DEFAULT_MEMORY_BUDGET;
    let r = run_limited(&dir, &["diff", "s.toml", "--b", "bomb.png"], budget);
    r.refused("a 60000x60000 --b image");
    assert!(r.stderr.contains("60000x60000"), "{}", r.stderr);
    r.within("60000² PNG as --b", budget, 5.0);
    // As a texture: refused from its header too, against the budget.
    let extra = "[materials.t]\npigment = { image = \"bomb.png\" }\n[[objects]]\nkind = \"sphere\"\nmaterial = \"t\"\ncenter = [1.0, 0.5, 0.0]\nradius = 0.3\n";
    std::fs::write(dir.join("t.toml"), scene(32, 24, extra)).unwrap();
    let r = run_limited(&dir, &["render", "t.toml", "-o", "t.png"], budget);
    r.refused("a 60000x60000 texture");
    r.within("60000² PNG as a texture", budget, 5.0);
    assert!(!dir.join("t.png").exists());
}

#[test]
fn shadow_maps_are_budgeted_before_they_are_allocated() {
    let dir = temp("shadow_maps");
    let lights: String = (0..8)
        .map(|k| {
            format!(
                "[[lights]]\nkind = \"point\"\nposition = [{}.0, 4.0, 2.0]\ncolor = [0.1, 0.1, 0.1]\n",
                k - 4
            )
        })
        .collect();
    let text = scene(64, 48, &lights);
    std::fs::write(dir.join("s.toml"), &text).unwrap();
    let budget = rendiff::budget::DEFAULT_MEMORY_BUDGET;
    let r = run_limited(
        &dir,
        &[
            "render",
            "s.toml",
            "--backend",
            "raster",
            "--shadows",
            "map:16384",
            "-o",
            "out.png",
        ],
        budget,
    );
    r.refused("8 lights with 16384² shadow maps");
    assert!(r.stderr.contains("GiB"), "names the figure: {}", r.stderr);
    r.within("8 shadow maps of 16384²", budget, 5.0);
    // One light is 6.4 GB of cube map: refused at the default budget too.
    std::fs::write(dir.join("one.toml"), scene(64, 48, "")).unwrap();
    let r = run_limited(
        &dir,
        &[
            "render",
            "one.toml",
            "--backend",
            "raster",
            "--shadows",
            "map:16384",
            "-o",
            "out.png",
        ],
        budget,
    );
    r.refused("one 16384² shadow map");
    r.within("one shadow map of 16384²", budget, 5.0);
    assert!(!dir.join("out.png").exists());
}

#[test]
fn one_texture_named_three_ways_is_held_once() {
    let dir = temp("texture_names");
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    // 2048² texels at 16 B each: 64 MiB held; three copies would be 192.
    std::fs::write(dir.join("t.png"), png(2048, 2048, None)).unwrap();
    std::os::unix::fs::symlink(dir.join("t.png"), dir.join("link.png")).unwrap();
    let mut extra = String::new();
    for (k, name) in ["t.png", "./sub/../t.png", "link.png"].iter().enumerate() {
        extra.push_str(&format!(
            "[materials.t{k}]\npigment = {{ image = \"{name}\" }}\n[[objects]]\nkind = \"sphere\"\nmaterial = \"t{k}\"\ncenter = [{}.0, 0.5, 1.0]\nradius = 0.3\n",
            k as i32 - 1
        ));
    }
    std::fs::write(dir.join("s.toml"), scene(32, 24, &extra)).unwrap();
    let budget: u64 = 128 << 20;
    let r = run_limited(
        &dir,
        &[
            "render",
            "s.toml",
            "--memory-budget",
            "0.125",
            "-o",
            "out.png",
        ],
        budget,
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    r.within("one 2048² texture named three ways", budget, 10.0);
    // A fourth, really different texture of the same size does not fit.
    std::fs::write(dir.join("u.png"), png(2048, 2047, None)).unwrap();
    extra.push_str("[materials.u]\npigment = { image = \"u.png\" }\n[[objects]]\nkind = \"sphere\"\nmaterial = \"u\"\ncenter = [0.0, 1.5, 0.0]\nradius = 0.3\n");
    std::fs::write(dir.join("s2.toml"), scene(32, 24, &extra)).unwrap();
    let r = run_limited(
        &dir,
        &[
            "render",
            "s2.toml",
            "--memory-budget",
            "0.125",
            "-o",
            "out2.png",
        ],
        budget,
    );
    r.refused("two different 2048² textures in 128 MiB");
    r.within("two 2048² textures", budget, 10.0);
}

#[test]
fn an_icc_profile_bomb_is_never_inflated() {
    let dir = temp("icc_bomb");
    // A profile of 512 MiB of zeros, compressed to about 0.5 MB.
    let mut iccp = b"bomb\0\0".to_vec();
    iccp.extend_from_slice(&zlib(&vec![0u8; 512 << 20]));
    std::fs::write(dir.join("t.png"), png(16, 16, Some((b"iCCP", &iccp)))).unwrap();
    let extra = "[materials.t]\npigment = { image = \"t.png\" }\n[[objects]]\nkind = \"sphere\"\nmaterial = \"t\"\ncenter = [1.0, 0.5, 0.0]\nradius = 0.3\n";
    std::fs::write(dir.join("s.toml"), scene(32, 24, extra)).unwrap();
    let budget: u64 = 100 << 20;
    let r = run_limited(
        &dir,
        &[
            "render",
            "s.toml",
            "--memory-budget",
            "0.09765625",
            "-o",
            "o.png",
        ],
        budget,
    );
    // The profile is skipped, never inflated: the texture renders.
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    r.within("ICC bomb texture", budget, 10.0);
    // As the --b image of a diff.
    std::fs::write(dir.join("p.toml"), scene(16, 16, "")).unwrap();
    let r = run_limited(
        &dir,
        &[
            "diff",
            "p.toml",
            "--b",
            "t.png",
            "--memory-budget",
            "0.09765625",
        ],
        budget,
    );
    // A verdict (pass or fail), not an error.
    assert!(matches!(r.code, Some(0 | 1)), "{}", r.stderr);
    r.within("ICC bomb --b", budget, 10.0);
}

/// An OBJ mesh object for [`scene`].
fn mesh_object(file: &str) -> String {
    format!(
        "[[objects]]\nkind = \"mesh\"\nfile = \"{file}\"\nmaterial = \"red\"\ntransform = [ {{ translate = [0.0, 0.5, 0.0] }} ]\n"
    )
}

#[test]
fn obj_faces_and_vertices_are_counted_while_streaming() {
    let dir = temp("obj_counts");
    // 4 M faces over three vertices (36 MB of text): refused in 64 MiB
    // while the faces stream in, long before they are all read.
    let mut text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n".to_vec();
    for _ in 0..4_000_000 {
        text.extend_from_slice(b"f 1 2 3\n");
    }
    std::fs::write(dir.join("faces.obj"), &text).unwrap();
    // 4 M vertices and one face.
    let mut text = Vec::new();
    for k in 0..4_000_000u32 {
        writeln!(text, "v {} 0 0", k % 7).unwrap();
    }
    text.extend_from_slice(b"f 1 2 3\n");
    std::fs::write(dir.join("verts.obj"), &text).unwrap();
    let budget: u64 = 64 << 20;
    for file in ["faces.obj", "verts.obj"] {
        std::fs::write(dir.join("s.toml"), scene(32, 24, &mesh_object(file))).unwrap();
        let r = run_limited(
            &dir,
            &["plan", "s.toml", "--memory-budget", "0.0625"],
            budget,
        );
        r.refused(file);
        assert!(r.stderr.contains(file), "names the file: {}", r.stderr);
        r.within(file, budget, 10.0);
    }
}

#[test]
fn a_file_of_nuls_gets_a_short_message() {
    let dir = temp("nuls");
    std::fs::write(dir.join("nul.obj"), vec![0u8; 16 << 20]).unwrap();
    std::fs::write(dir.join("s.toml"), scene(32, 24, &mesh_object("nul.obj"))).unwrap();
    let r = run_limited(
        &dir,
        &["plan", "s.toml"],
        rendiff::budget::DEFAULT_MEMORY_BUDGET,
    );
    r.refused("16 MB of NULs as an OBJ");
    assert!(r.stderr.len() < 1024, "{} bytes of message", r.stderr.len());
    assert!(!r.stderr.contains('\0'));
    // The same as scene text.
    std::fs::write(dir.join("nul.toml"), vec![0u8; 16 << 20]).unwrap();
    let r = run(&dir, &["plan", "nul.toml"]);
    r.refused("16 MB of NULs as a scene");
    assert!(r.stderr.len() < 1024, "{} bytes of message", r.stderr.len());
}

#[test]
fn a_huge_scene_text_is_refused_before_it_is_parsed() {
    let dir = temp("huge_toml");
    // 8 MB of scene (a long comment, then an unknown key): 640 MB by the
    // parser's 80 B per byte, refused in 128 MiB before parsing.
    let mut text = scene(32, 24, "");
    text.push_str(&"# padding padding padding padding padding padding padding\n".repeat(140_000));
    text.push_str("nonsense = 1\n");
    std::fs::write(dir.join("s.toml"), &text).unwrap();
    let budget: u64 = 128 << 20;
    let r = run_limited(
        &dir,
        &[
            "render",
            "s.toml",
            "--memory-budget",
            "0.125",
            "-o",
            "o.png",
        ],
        budget,
    );
    r.refused("8 MB of scene text in 128 MiB");
    assert!(r.stderr.contains("s.toml"), "{}", r.stderr);
    r.within("8 MB scene text", budget, 5.0);
}

#[test]
fn the_painters_pair_work_is_budgeted() {
    let dir = temp("painter_pairs");
    // 16 000 triangles stacked over one another: every pair overlaps.
    let mut text = Vec::new();
    for k in 0..16_000u32 {
        let z = f64::from(k) * 1e-4;
        writeln!(text, "v -1 -1 {z}\nv 1 -1 {z}\nv 0 1 {z}").unwrap();
        writeln!(text, "f {} {} {}", 3 * k + 1, 3 * k + 2, 3 * k + 3).unwrap();
    }
    std::fs::write(dir.join("stack.obj"), &text).unwrap();
    std::fs::write(dir.join("s.toml"), scene(64, 48, &mesh_object("stack.obj"))).unwrap();
    let budget: u64 = 512 << 20;
    let r = run_limited(
        &dir,
        &[
            "render",
            "s.toml",
            "--backend",
            "painter",
            "--memory-budget",
            "0.5",
            "-o",
            "o.png",
        ],
        budget,
    );
    assert!(
        matches!(r.code, Some(0 | 2)),
        "a render or a refusal: {:?} {}",
        r.code,
        r.stderr
    );
    r.within("16 000 overlapping triangles, painter", budget, 60.0);
}

#[test]
fn work_bounds_hold_for_corners_exponents_threads_and_fields_of_view() {
    let dir = temp("time_bombs");
    // A polygon of 200 000 corners (a star) and an OBJ face of as many.
    let n = 200_000;
    let corners: Vec<String> = (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * f64::from(k) / f64::from(n);
            let r = if k % 2 == 0 { 1.0 } else { 0.6 };
            format!("[{:.9}, 0.01, {:.9}]", r * a.cos(), r * a.sin())
        })
        .collect();
    let poly = format!(
        "[[objects]]\nkind = \"polygon\"\nmaterial = \"red\"\npoints = [{}]\n",
        corners.join(", ")
    );
    std::fs::write(dir.join("poly.toml"), scene(32, 24, &poly)).unwrap();
    let r = run(&dir, &["plan", "poly.toml"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    r.within(
        "a polygon of 200 000 corners",
        rendiff::budget::DEFAULT_MEMORY_BUDGET,
        10.0,
    );
    let mut obj = String::new();
    for k in 0..n {
        let a = std::f64::consts::TAU * f64::from(k) / f64::from(n);
        let r = if k % 2 == 0 { 1.0 } else { 0.6 };
        obj.push_str(&format!("v {:.9} {:.9} 0\n", r * a.cos(), r * a.sin()));
    }
    obj.push('f');
    for k in 1..=n {
        obj.push_str(&format!(" {k}"));
    }
    obj.push('\n');
    std::fs::write(dir.join("face.obj"), obj).unwrap();
    std::fs::write(
        dir.join("face.toml"),
        scene(32, 24, &mesh_object("face.obj")),
    )
    .unwrap();
    let r = run(&dir, &["plan", "face.toml"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    r.within(
        "an OBJ face of 200 000 corners",
        rendiff::budget::DEFAULT_MEMORY_BUDGET,
        10.0,
    );
    // Superellipsoid exponents at the edge of the range.
    for (e, m) in [
        (0.001, 0.001),
        (0.001, 1.0),
        (0.02, 4.0),
        (4.0, 0.001),
        (4.0, 4.0),
    ] {
        let obj = format!(
            "[[objects]]\nkind = \"superellipsoid\"\nexponents = [{e}, {m}]\nmaterial = \"red\"\n"
        );
        std::fs::write(dir.join("se.toml"), scene(64, 48, &obj)).unwrap();
        let r = run(&dir, &["render", "se.toml", "-o", "se.png"]);
        assert_eq!(r.code, Some(0), "<{e}, {m}>: {}", r.stderr);
        r.within(
            &format!("superellipsoid <{e}, {m}>"),
            rendiff::budget::DEFAULT_MEMORY_BUDGET,
            10.0,
        );
    }
    // Threads: capped at a stated multiple of the cores.
    std::fs::write(dir.join("s.toml"), scene(32, 24, "")).unwrap();
    let r = run(
        &dir,
        &["render", "s.toml", "--threads", "100000", "-o", "t.png"],
    );
    r.refused("--threads 100000");
    assert!(r.stderr.contains("at most"), "{}", r.stderr);
    assert!(r.secs < 2.0);
    // A degenerate field of view: refused at load, at once.
    let text = scene(32, 24, "").replace("fov_y = 40.0", "fov_y = 1e-300");
    std::fs::write(dir.join("fov.toml"), text).unwrap();
    let r = run(&dir, &["render", "fov.toml", "-o", "f.png"]);
    r.refused("fov_y = 1e-300");
    assert!(
        r.stderr.contains("fov.toml:") && r.stderr.contains("fov_y"),
        "{}",
        r.stderr
    );
    assert!(r.secs < 2.0);
}

// ---------------------------------------------------------------- writes

#[test]
fn devices_and_links_named_as_outputs_stay_what_they_are() {
    let dir = temp("devices");
    std::fs::write(dir.join("s.toml"), scene(16, 12, "")).unwrap();
    let null = Path::new("/dev/null");
    let before = std::fs::metadata(null).unwrap();
    let r = run(&dir, &["render", "s.toml", "-o", "/dev/null"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let after = std::fs::metadata(null).unwrap();
    assert!(after.file_type().is_char_device(), "/dev/null was replaced");
    assert_eq!(
        std::os::unix::fs::MetadataExt::rdev(&before),
        std::os::unix::fs::MetadataExt::rdev(&after)
    );
    // A FIFO: written into, left a FIFO.
    let fifo = dir.join("fifo");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let reader = std::thread::spawn({
        let fifo = fifo.clone();
        move || std::fs::read(fifo).unwrap()
    });
    let r = run(&dir, &["pov", "s.toml", "-o", "fifo"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let sdl = reader.join().unwrap();
    assert!(sdl.starts_with(b"#version 3.7;"));
    assert!(
        std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo()
    );
    // A link to a file: the file is replaced, the link stays a link.
    std::fs::write(dir.join("real.png"), b"old").unwrap();
    std::os::unix::fs::symlink("real.png", dir.join("link.png")).unwrap();
    let r = run(&dir, &["render", "s.toml", "-o", "link.png"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(
        std::fs::symlink_metadata(dir.join("link.png"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert!(
        std::fs::read(dir.join("real.png"))
            .unwrap()
            .starts_with(b"\x89PNG")
    );
    // A link to nowhere, a folder: refused, untouched.
    std::os::unix::fs::symlink("nowhere.png", dir.join("dangling.png")).unwrap();
    std::fs::create_dir(dir.join("folder.png")).unwrap();
    for target in ["dangling.png", "folder.png"] {
        let r = run(&dir, &["render", "s.toml", "-o", target]);
        r.refused(target);
    }
    assert!(!dir.join("nowhere.png").exists());
}

#[test]
fn a_planted_link_redirects_no_write() {
    let dir = temp("planted");
    std::fs::write(dir.join("s.toml"), scene(16, 12, "")).unwrap();
    std::fs::write(dir.join("victim"), b"precious").unwrap();
    // Links at the names an atomic writer with predictable temporaries
    // would use (`.NAME.PID.tmp`, `.NAME.tmp`, `NAME.tmp`): none is used.
    for name in [".out.png.tmp", "out.png.tmp", ".out.png.1.tmp"] {
        std::os::unix::fs::symlink(dir.join("victim"), dir.join(name)).unwrap();
    }
    for pid in 1..4096u32 {
        let _ =
            std::os::unix::fs::symlink(dir.join("victim"), dir.join(format!(".out.png.{pid}.tmp")));
    }
    let r = run(&dir, &["render", "s.toml", "-o", "out.png"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(std::fs::read(dir.join("victim")).unwrap(), b"precious");
    assert!(
        std::fs::read(dir.join("out.png"))
            .unwrap()
            .starts_with(b"\x89PNG")
    );
}

#[test]
fn no_output_replaces_an_input() {
    let dir = temp("inputs");
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    std::fs::write(dir.join("tex/a.png"), png(8, 8, None)).unwrap();
    std::fs::write(dir.join("mesh.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let extra = format!(
        "[materials.t]\npigment = {{ image = \"tex/a.png\" }}\n[[objects]]\nkind = \"sphere\"\nmaterial = \"t\"\ncenter = [1.0, 0.5, 0.0]\nradius = 0.3\n{}",
        mesh_object("mesh.obj")
    );
    std::fs::write(dir.join("s.toml"), scene(16, 12, &extra)).unwrap();
    std::os::unix::fs::symlink("s.toml", dir.join("alias.png")).unwrap();
    let before = tree(&dir);
    let cases: &[&[&str]] = &[
        &["render", "s.toml", "-o", "s.toml"],
        &["render", "s.toml", "-o", "./tex/../s.toml"],
        &["render", "s.toml", "-o", "alias.png"],
        &["render", "s.toml", "-o", "mesh.obj"],
        &["render", "s.toml", "-o", "tex/a.png"],
        &["pov", "s.toml", "-o", "s.toml"],
        &["pov", "s.toml", "-o", "mesh.obj"],
        &["lines", "s.toml", "-o", "tex/a.png"],
        &["diff", "s.toml", "--out", "."],
        &["diff", "s.toml", "--out", "tex"],
        &["diff", "s.toml", "--b", "tex/a.png", "--out", "tex"],
    ];
    for args in cases {
        let r = run(&dir, args);
        r.refused(&args.join(" "));
        assert!(
            r.stderr.contains("input") || r.stderr.contains("rendiff did not write"),
            "{}: {}",
            args.join(" "),
            r.stderr
        );
    }
    assert_eq!(tree(&dir), before, "an input changed");
}

#[test]
fn scene_folders_stay_inside_out_and_apart() {
    let dir = temp("folders");
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(scenes.join("sub")).unwrap();
    std::fs::create_dir_all(scenes.join("javascript:alert(1)")).unwrap();
    let names = [
        "...toml",
        "..toml",
        "x.toml",
        "sub/x.toml",
        "javascript:alert(1)/a b.toml",
    ];
    for n in names {
        std::fs::write(scenes.join(n), scene(12, 9, "")).unwrap();
    }
    let mut args: Vec<String> = vec!["diff".into()];
    args.extend(names.iter().map(|n| format!("scenes/{n}")));
    args.extend(["--out".into(), "scenes/out".into()]);
    let before: Vec<_> = tree(&dir);
    let r = run(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    // Nothing changed outside the out folder.
    let after: Vec<_> = tree(&dir)
        .into_iter()
        .filter(|(p, _)| !p.starts_with(scenes.join("out")))
        .collect();
    assert_eq!(after, before);
    let out = scenes.join("out");
    let folders: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| e.path().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(folders.len(), names.len(), "{folders:?}");
    for f in &folders {
        assert!(out.join(f).join("report.json").is_file(), "{f}");
    }
    let index = std::fs::read_to_string(out.join("index.html")).unwrap();
    for link in index
        .split("href=\"")
        .skip(1)
        .chain(index.split("src=\"").skip(1))
    {
        assert!(link.starts_with("./"), "{}", &link[..link.len().min(40)]);
    }
    // A scheme in a folder name stays text: every link above is relative.
    assert!(!index.contains("href=\"javascript:") && !index.contains("src=\"javascript:"));
}

#[test]
fn an_out_set_is_replaced_whole_or_not_at_all() {
    let dir = temp("sets");
    std::fs::write(dir.join("s.toml"), scene(64, 48, "")).unwrap();
    let r = run(&dir, &["diff", "s.toml", "--out", "d"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let old = tree(&dir.join("d"));
    // A write that fails part way (a file-size limit: EFBIG) leaves the
    // old set, and no temporary folder.
    let out = Command::new("prlimit")
        .args(["--fsize=20000", "--"])
        .arg(env!("CARGO_BIN_EXE_rendiff"))
        // 640×480: the first image is over 20 kB (the 64×48 set is 9 kB
        // at most per file).
        .args(["diff", "s.toml", "--size", "640x480", "--out", "d"])
        .current_dir(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    // The message names the file of the set, not the fresh folder.
    assert!(err.contains("d/a.png") && !err.contains(".tmp"), "{err}");
    assert_eq!(tree(&dir.join("d")), old, "the old set changed");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    // Concurrent runs of different sizes: the folder ends as one whole set.
    let sizes = ["16x12", "24x18", "32x24", "40x30", "48x36"];
    let children: Vec<_> = sizes
        .iter()
        .map(|size| {
            Command::new(env!("CARGO_BIN_EXE_rendiff"))
                .args(["diff", "s.toml", "--size", size, "--out", "d"])
                .current_dir(&dir)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for c in children {
        let o = c.wait_with_output().unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("d/report.json")).unwrap()).unwrap();
    let (w, h) = (
        report["width"].as_u64().unwrap(),
        report["height"].as_u64().unwrap(),
    );
    for name in ["a.png", "b.png", "heat.png"] {
        let img = rendiff::image_io::read_png_linear(&dir.join("d").join(name)).unwrap();
        assert_eq!(
            (u64::from(img.width), u64::from(img.height)),
            (w, h),
            "{name} is from another run than report.json"
        );
    }
    // A folder of other files is not replaced.
    std::fs::create_dir(dir.join("mine")).unwrap();
    std::fs::write(dir.join("mine/notes.txt"), "mine").unwrap();
    let r = run(&dir, &["diff", "s.toml", "--out", "mine"]);
    r.refused("--out over a folder of other files");
    assert_eq!(std::fs::read(dir.join("mine/notes.txt")).unwrap(), b"mine");
}

#[test]
fn standard_output_errors_are_errors_and_a_closed_pipe_keeps_the_verdict() {
    let dir = temp("stdout");
    std::fs::write(dir.join("s.toml"), scene(32, 24, "")).unwrap();
    // A full disk.
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(["pov", "s.toml"])
        .current_dir(&dir)
        .stdout(full)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("standard output"));
    // A file-size limit part way through.
    let f = std::fs::File::create(dir.join("part.pov")).unwrap();
    let o = Command::new("prlimit")
        .args(["--fsize=4096", "--"])
        .arg(env!("CARGO_BIN_EXE_rendiff"))
        .args(["pov", "s.toml"])
        .current_dir(&dir)
        .stdout(f)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // A failing verdict whose reader goes away: still exit 1.
    rendiff::image_io::write_png(
        &dir.join("black.png"),
        32,
        24,
        &vec![rendiff::color::Rgb::BLACK; 32 * 24],
        rendiff::image_io::PngEncoding::Srgb8,
    )
    .unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(["diff", "s.toml", "--b", "black.png"])
        .current_dir(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    assert_eq!(child.wait().unwrap().code(), Some(1));
}

// ------------------------------------------------------- golden and POV-Ray

/// The files of a golden folder, with their contents.
fn golden_set(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap_or_default(),
            )
        })
        .filter(|(n, _)| n != rendiff::pov::golden::LOCK_FILE)
        .collect();
    v.sort();
    v
}

#[test]
fn golden_updates_are_locked_and_a_killed_one_is_completed() {
    let dir = temp("golden_lock");
    std::fs::write(dir.join("s.toml"), scene(16, 12, "")).unwrap();
    let bin = env!("CARGO_BIN_EXE_rendiff");
    let update = |pause: &str| {
        Command::new(bin)
            .args(["golden", "--update", "--golden", "g", "s.toml"])
            .current_dir(&dir)
            .env("RENDIFF_TEST_PAUSE_IN_COMMIT_MS", pause)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let o = update("0").wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let complete = golden_set(&dir.join("g"));
    assert_eq!(complete.len(), 3, "png, analytic png, toml: {complete:?}");
    // Four overlapping updates, each slowed in the middle of its commit.
    let children: Vec<_> = (0..4).map(|_| update("150")).collect();
    for c in children {
        let o = c.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert_eq!(golden_set(&dir.join("g")), complete);
    // Killed between the renames of its commit: the journal is left.
    let mut child = update("60000");
    let journal = dir.join("g").join(rendiff::pov::golden::JOURNAL_FILE);
    let start = Instant::now();
    while !journal.exists() {
        assert!(start.elapsed() < Duration::from_secs(60), "no commit began");
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(50));
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(journal.exists());
    // The next run (a check) completes the commit and finds it whole.
    let r = run(&dir, &["golden", "--golden", "g", "s.toml"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(golden_set(&dir.join("g")), complete);
    // Killed while staging (before the journal): the old set stays, and
    // the next run removes what it staged.
    let mut child = update("0");
    std::thread::sleep(Duration::from_millis(30));
    child.kill().unwrap();
    child.wait().unwrap();
    let r = run(&dir, &["golden", "--golden", "g", "s.toml"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(golden_set(&dir.join("g")), complete);
}

#[test]
fn signals_remove_temporaries_and_stop_povray() {
    let dir = temp("signals");
    let tmp = dir.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    // Big enough that POV-Ray runs for a while.
    std::fs::write(dir.join("s.toml"), scene(640, 480, "")).unwrap();
    for sig in ["-TERM", "-INT"] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .args(["golden", "--update", "--golden", "g", "s.toml"])
            .current_dir(&dir)
            .env("TMPDIR", &tmp)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while std::fs::read_dir(&tmp).unwrap().next().is_none() {
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "POV-Ray never started"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_millis(200));
        assert!(
            Command::new("kill")
                .args([sig, &child.id().to_string()])
                .status()
                .unwrap()
                .success()
        );
        let status = child.wait().unwrap();
        assert!(!status.success());
        let left: Vec<_> = std::fs::read_dir(&tmp)
            .unwrap()
            .filter_map(Result::ok)
            .collect();
        assert!(left.is_empty(), "{sig}: left {left:?}");
        // No process still runs in a scratch folder below tmp.
        for p in std::fs::read_dir("/proc").unwrap().filter_map(Result::ok) {
            if let Ok(cwd) = std::fs::read_link(p.path().join("cwd")) {
                assert!(
                    !cwd.starts_with(&tmp),
                    "{sig}: process {:?} still runs",
                    p.file_name()
                );
            }
        }
        assert!(!dir.join("g").join("s.png").exists());
    }
}

// ---------------------------------------------------------------- injection

/// An SDL payload that creates `marker` if POV-Ray ever parses it as code:
/// written unescaped into `image_map { png "…" }` it names `t.png`, closes
/// the image map, the pigment and the object, and runs `#fopen` (checked
/// below: POV-Ray does create the marker from the raw SDL). The marker
/// lies under `/tmp`, where POV-Ray's default I/O restrictions allow
/// writes.
fn payload(marker: &Path) -> String {
    format!(
        "t.png\" }} }} }} #fopen F \"{}\" write #write(F, \"owned\") #fclose F #declare Q = {{ {{ {{ \"y",
        marker.display()
    )
}

/// A folder under `/tmp` (POV-Ray may write there) for an injection's
/// marker.
fn marker_dir() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("rendiff-inject-")
        .tempdir_in("/tmp")
        .unwrap()
}

fn povray_installed() -> bool {
    Command::new("povray")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok()
}

#[test]
fn a_quote_in_a_texture_path_injects_nothing() {
    let dir = temp("inject_texture");
    let markers = marker_dir();
    let marker = markers.path().join("pwned.txt");
    // The payload holds the marker's path, so the texture's name is a
    // path through folders named by the payload's pieces.
    let name = format!("{}.png", payload(&marker));
    let file = dir.join(&name);
    std::fs::create_dir_all(file.parent().unwrap()).unwrap();
    std::fs::write(&file, png(8, 8, None)).unwrap();
    std::fs::write(dir.join("t.png"), png(8, 8, None)).unwrap();
    let literal = name.replace('\\', "\\\\").replace('"', "\\\"");
    let extra = format!(
        "[materials.t]\npigment = {{ image = \"{literal}\" }}\n[[objects]]\nkind = \"sphere\"\nmaterial = \"t\"\ncenter = [1.0, 0.5, 0.0]\nradius = 0.3\n"
    );
    std::fs::write(dir.join("s.toml"), scene(16, 12, &extra)).unwrap();
    // The SDL names the file as one literal.
    let r = run(&dir, &["pov", "s.toml"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let sdl = String::from_utf8(r.stdout).unwrap();
    assert!(!sdl.lines().any(|l| l.trim_start().starts_with("#fopen")));
    let escaped = format!("\"{}\"", name.replace('"', "\\\""));
    assert!(
        sdl.contains(&escaped),
        "the name is not one escaped literal"
    );
    if povray_installed() {
        // The test can fail: the same SDL with the name unescaped does run
        // the payload.
        std::fs::write(
            dir.join("raw.pov"),
            sdl.replace(&escaped, &format!("\"{name}\"")),
        )
        .unwrap();
        let _ = Command::new("povray")
            .args(["+Iraw.pov", "+Oraw.png", "+W16", "+H12", "-D", "-V"])
            .current_dir(&dir)
            .output()
            .unwrap();
        assert!(marker.exists(), "the raw payload should have run");
        std::fs::remove_file(&marker).unwrap();
    }
    for args in [
        &["golden", "--update", "--golden", "g", "s.toml"][..],
        &["golden", "--golden", "g", "s.toml"],
        &["diff", "s.toml", "--b", "pov", "--render"],
        &["diff", "s.toml", "--b", "pov", "--golden", "g"],
    ] {
        let r = run(&dir, args);
        assert_eq!(r.code, Some(0), "{}: {}", args.join(" "), r.stderr);
        assert!(
            !marker.exists(),
            "{}: the injected directive ran",
            args.join(" ")
        );
    }
    // A name POV-Ray cannot open is refused, naming the key.
    std::fs::write(dir.join("back\\slash.png"), png(8, 8, None)).unwrap();
    let extra = "[materials.t]\npigment = { image = \"back\\\\slash.png\" }\n[[objects]]\nkind = \"sphere\"\nmaterial = \"t\"\ncenter = [1.0, 0.5, 0.0]\nradius = 0.3\n";
    std::fs::write(dir.join("b.toml"), scene(16, 12, extra)).unwrap();
    let r = run(&dir, &["pov", "b.toml"]);
    r.refused("a backslash in a texture name");
    assert!(
        r.stderr.contains("materials.t.pigment.image"),
        "{}",
        r.stderr
    );
}

#[test]
fn scene_names_and_folders_with_newlines_quotes_and_spaces_stay_data() {
    let dir = temp("inject_names");
    // A scene folder and a TMPDIR with spaces and quotes, a scene file
    // whose name carries a newline and a directive: were the name to
    // reach a line of SDL on its own, POV-Ray would stop at `#error` and
    // the runs below would fail.
    let folder = dir.join("my 'scenes' \"here\"");
    std::fs::create_dir_all(&folder).unwrap();
    let tmp = dir.join("t m p");
    std::fs::create_dir_all(&tmp).unwrap();
    let name = "a\n#error \"injected\"\n\"b.toml";
    std::fs::write(folder.join(name), scene(16, 12, "")).unwrap();
    let scene_arg = folder.join(name);
    let args = |a: &[&str]| -> Vec<std::ffi::OsString> {
        let mut v: Vec<std::ffi::OsString> = a.iter().map(Into::into).collect();
        v.push(scene_arg.clone().into_os_string());
        v
    };
    let env = [("TMPDIR", tmp.as_os_str())];
    for a in [
        args(&["golden", "--update", "--golden", "g"]),
        args(&["golden", "--golden", "g"]),
        args(&["diff", "--b", "pov", "--render"]),
    ] {
        let a: Vec<&OsStr> = a.iter().map(std::ffi::OsString::as_os_str).collect();
        let r = run_in(&dir, &a, &env, None);
        assert_eq!(r.code, Some(0), "{a:?}: {}", r.stderr);
    }
    // The metadata written for it parses back, and the SDL's comment lines
    // stay comments.
    let meta = std::fs::read_dir(dir.join("g"))
        .unwrap()
        .filter_map(Result::ok)
        .find(|e| e.file_name().to_string_lossy().ends_with(".toml"))
        .unwrap();
    let text = std::fs::read_to_string(meta.path()).unwrap();
    text.parse::<toml::Table>().expect("the metadata is TOML");
    let a: Vec<&OsStr> = vec![OsStr::new("pov"), scene_arg.as_os_str()];
    let r = run_in(&dir, &a, &[], None);
    let sdl = String::from_utf8(r.stdout).unwrap();
    for line in sdl.lines() {
        assert!(
            !line.starts_with('#') || line == "#version 3.7;",
            "a directive line: {line}"
        );
    }
    assert!(
        std::fs::read_dir(&tmp).unwrap().next().is_none(),
        "TMPDIR not cleaned"
    );
}

#[test]
fn control_characters_never_reach_the_terminal() {
    let dir = temp("controls");
    let cases: Vec<(String, String)> = vec![
        (
            "material".into(),
            scene(16, 12, "").replace(
                "[materials.red]",
                "[materials.\"red\\u001b]0;pwned\\u0007\"]",
            ),
        ),
        ("key".into(), scene(16, 12, "\"bad\\u001b[2Jkey\" = 1\n")),
        (
            "file name".into(),
            scene(16, 12, &mesh_object("m\\u001b]0;t\\u0007.obj")),
        ),
        ("OBJ token".into(), scene(16, 12, &mesh_object("tok.obj"))),
    ];
    std::fs::write(dir.join("tok.obj"), b"v 0 0 0\nq\x1b]0;pwned\x07 1 2\x00\n").unwrap();
    for (what, text) in cases {
        std::fs::write(dir.join("s.toml"), text).unwrap();
        let r = run(&dir, &["plan", "s.toml"]);
        r.refused(&what);
        let bad: Vec<char> = r
            .stderr
            .chars()
            .filter(|c| c.is_control() && *c != '\n')
            .collect();
        assert!(
            bad.is_empty(),
            "{what}: {bad:?} in {}",
            r.stderr.escape_debug()
        );
    }
}

#[test]
fn a_mesh_of_proc_self_environ_prints_no_environment() {
    let dir = temp("environ");
    std::fs::write(
        dir.join("s.toml"),
        scene(16, 12, &mesh_object("/proc/self/environ")),
    )
    .unwrap();
    let args = [OsStr::new("plan"), OsStr::new("s.toml")];
    let secret = OsStr::new("hunter2-hunter2-hunter2-hunter2-hunter2-hunter2");
    let r = run_in(&dir, &args, &[("RENDIFF_SECRET", secret)], None);
    r.refused("/proc/self/environ as a mesh");
    assert!(!r.stderr.contains("hunter2"), "{}", r.stderr);
    assert!(r.stderr.len() < 1024, "{}", r.stderr);
}

// ---------------------------------------------------------------- OBJ materials

/// A small valid JPEG (16x16, baseline), from the test data.
fn jpeg() -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/obj/mtl/tiles.jpg"))
        .unwrap()
}

/// The JPEG with its frame header (SOF0) claiming `w`×`h`.
fn jpeg_claiming(w: u16, h: u16) -> Vec<u8> {
    let mut b = jpeg();
    let at = b
        .windows(2)
        .position(|m| m == [0xFF, 0xC0])
        .expect("a baseline frame header");
    // FF C0, length (2), precision (1), height (2), width (2).
    b[at + 5..at + 7].copy_from_slice(&h.to_be_bytes());
    b[at + 7..at + 9].copy_from_slice(&w.to_be_bytes());
    b
}

/// A quad OBJ with uvs that names `mtl.mtl` and selects `usemtl` (line 8).
const QUAD_OBJ: &str = "mtllib mtl.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 1\nusemtl skin\nf 1/1 2/2 3/2 4/1\n";

/// A case: what it is, the files of its folder `m`, the message.
type MtlCase = (&'static str, Vec<(&'static str, Vec<u8>)>, &'static str);

/// Each case: the files of a folder beside the scene (which renders
/// `m/quad.obj` with `material = "obj"`), and the start of the message
/// after `error: `, naming the file and line.
#[test]
fn broken_material_libraries_and_textures_are_refused_by_file_and_line() {
    let lib = |body: &str| format!("newmtl skin\nKd 0.8 0.8 0.8\n{body}");
    let cases: Vec<MtlCase> = vec![
        (
            "missing library",
            vec![("quad.obj", QUAD_OBJ.replace("mtl.mtl", "gone.mtl").into())],
            "m/quad.obj:1: could not read the material library m/gone.mtl: ",
        ),
        (
            "library that is not text",
            vec![("quad.obj", QUAD_OBJ.into()), ("mtl.mtl", vec![0u8; 4096])],
            "m/mtl.mtl:1: unsupported MTL statement `\\0",
        ),
        (
            "malformed Kd",
            vec![
                ("quad.obj", QUAD_OBJ.into()),
                ("mtl.mtl", "newmtl skin\nKd 0.8 O.8 0.8\n".into()),
            ],
            "m/mtl.mtl:2: `O.8` is not a number",
        ),
        (
            "undefined usemtl",
            vec![
                (
                    "quad.obj",
                    QUAD_OBJ.replace("usemtl skin", "usemtl bone").into(),
                ),
                ("mtl.mtl", lib("").into()),
            ],
            "m/quad.obj:8: usemtl `bone`: no material of that name in mtl.mtl (defined: `skin`)",
        ),
        (
            "missing texture",
            vec![
                ("quad.obj", QUAD_OBJ.into()),
                ("mtl.mtl", lib("map_Kd .\\gone.jpg\n").into()),
            ],
            "m/mtl.mtl:3: map_Kd: could not read image m/gone.jpg: ",
        ),
        (
            "texture escaping the folder",
            vec![
                ("quad.obj", QUAD_OBJ.into()),
                ("mtl.mtl", lib("map_Kd ..\\t.jpg\n").into()),
            ],
            "m/mtl.mtl:3: map_Kd: `..\\t.jpg` climbs out of the folder m with `..`",
        ),
        (
            "absolute texture name",
            vec![
                ("quad.obj", QUAD_OBJ.into()),
                ("mtl.mtl", lib("bump /etc/passwd\n").into()),
            ],
            "m/mtl.mtl:3: bump: `/etc/passwd` is an absolute name",
        ),
        (
            "JPEG claiming 60000x60000",
            vec![
                ("quad.obj", QUAD_OBJ.into()),
                ("mtl.mtl", lib("map_Kd huge.jpg\n").into()),
                ("huge.jpg", jpeg_claiming(60000, 60000)),
            ],
            "m/mtl.mtl:3: map_Kd: image m/huge.jpg: image is 60000x60000; each side must be 1 … 16384",
        ),
        (
            "truncated JPEG",
            vec![
                ("quad.obj", QUAD_OBJ.into()),
                ("mtl.mtl", lib("map_Kd cut.jpg\n").into()),
                ("cut.jpg", {
                    let j = jpeg();
                    j[..j.len() * 2 / 3].to_vec()
                }),
            ],
            "m/mtl.mtl:3: map_Kd: image m/cut.jpg: not a readable JPEG: ",
        ),
        (
            "a texture on a face without uvs",
            vec![
                (
                    "quad.obj",
                    QUAD_OBJ.replace("f 1/1 2/2 3/2 4/1", "f 1 2 3 4").into(),
                ),
                ("mtl.mtl", lib("map_Kd t.jpg\n").into()),
                ("t.jpg", jpeg()),
            ],
            "m/quad.obj:9: this face has no uv (vt) on every corner, but its material \"mtl.mtl:skin\" uses an image",
        ),
    ];
    for (what, files, message) in cases {
        let dir = temp(&format!("mtl_{}", what.replace(' ', "_")));
        std::fs::create_dir_all(dir.join("m")).unwrap();
        for (name, bytes) in &files {
            std::fs::write(dir.join("m").join(name), bytes).unwrap();
        }
        let obj = "[[objects]]\nkind = \"mesh\"\nfile = \"m/quad.obj\"\nmaterial = \"obj\"\n";
        std::fs::write(dir.join("s.toml"), scene(32, 24, obj)).unwrap();
        let before = tree(&dir);
        let r = run(&dir, &["render", "s.toml", "-o", "out.png"]);
        r.refused(what);
        // One line, besides the peak-memory report.
        let lines: Vec<&str> = r
            .stderr
            .lines()
            .filter(|l| !l.starts_with("peak RSS: "))
            .collect();
        assert!(
            lines.len() == 1 && lines[0].starts_with(&format!("error: {message}")),
            "{what}: expected one line `error: {message}…`, got:\n{}",
            r.stderr
        );
        assert!(r.stdout.is_empty(), "{what}");
        assert_eq!(tree(&dir), before, "{what}: something was written");
    }
}

#[test]
fn jpeg_textures_of_a_scene_are_refused_by_their_header_and_when_cut_short() {
    let dir = temp("jpeg_scene");
    std::fs::write(dir.join("bomb.jpg"), jpeg_claiming(60000, 60000)).unwrap();
    let j = jpeg();
    std::fs::write(dir.join("cut.jpg"), &j[..j.len() / 2]).unwrap();
    // A JPEG's end-of-image marker cut off alone still decodes (every
    // scan is complete); its scans cut short do not.
    std::fs::write(dir.join("ok.jpg"), &j).unwrap();
    let sphere = |file: &str| {
        format!(
            "[materials.t]\npigment = {{ image = \"{file}\" }}\n[[objects]]\nkind = \"sphere\"\nmaterial = \"t\"\ncenter = [1.0, 0.5, 0.0]\nradius = 0.3\n"
        )
    };
    let budget = rendiff::budget::DEFAULT_MEMORY_BUDGET;
    for (file, message) in [
        (
            "bomb.jpg",
            "error: bomb.jpg: image is 60000x60000; each side must be 1 … 16384",
        ),
        ("cut.jpg", "error: cut.jpg: not a readable JPEG: "),
    ] {
        std::fs::write(dir.join("t.toml"), scene(32, 24, &sphere(file))).unwrap();
        let before = tree(&dir);
        let r = run_limited(&dir, &["render", "t.toml", "-o", "t.png"], budget);
        r.refused(file);
        assert!(
            r.stderr.lines().any(|l| l.starts_with(message)),
            "{file}: {}",
            r.stderr
        );
        r.within(file, budget, 5.0);
        assert_eq!(tree(&dir), before, "{file}: something was written");
    }
    std::fs::write(dir.join("t.toml"), scene(32, 24, &sphere("ok.jpg"))).unwrap();
    let r = run(&dir, &["render", "t.toml", "-o", "t.png"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(dir.join("t.png").exists());
}
