//! The command line: help texts, outputs, exit codes, the HTML report in
//! a headless browser.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::util::root;

fn rendiff(args: &[&str]) -> Output {
    rendiff_with_env(args, &[])
}

fn rendiff_with_env(args: &[&str], env: &[(&str, &Path)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    cmd.args(args)
        .current_dir(root())
        .env("RUST_BACKTRACE", "1");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("could not run rendiff")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn temp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("cli")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn help_texts() {
    for args in [
        &["--help"][..],
        &["render", "--help"],
        &["diff", "--help"],
        &["plan", "--help"],
        &["pov", "--help"],
        &["golden", "--help"],
        &["bench", "--help"],
        &["lines", "--help"],
        &["completions", "--help"],
        &["man", "--help"],
        &["review", "--help"],
        &["report", "--help"],
    ] {
        let o = rendiff(args);
        assert!(o.status.success(), "{args:?}");
        insta::assert_snapshot!(
            format!("help_{}", args.join("_").replace("--", "")),
            stdout(&o)
        );
    }
}

#[test]
fn render_writes_the_image_and_the_gbuffer() {
    let dir = temp("render");
    let out = dir.join("spheres.png");
    let gb = dir.join("gb");
    let o = rendiff(&[
        "render",
        "scenes/spheres.toml",
        "--backend",
        "raster",
        "--size",
        "64x48",
        "--samples",
        "2",
        "-o",
        out.to_str().unwrap(),
        "--gbuffer",
        gb.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = rendiff::image_io::read_png_linear(&out).unwrap();
    assert_eq!((img.width, img.height, img.linear16), (64, 48, false));
    // The G-buffer is at the sample resolution.
    let id = rendiff::image_io::read_png_linear(&gb.join("id.png")).unwrap();
    assert_eq!((id.width, id.height), (128, 96));
    let pfm = std::fs::read(gb.join("depth.pfm")).unwrap();
    assert!(pfm.starts_with(b"Pf\n128 96\n-1.0\n"));
    assert_eq!(pfm.len(), b"Pf\n128 96\n-1.0\n".len() + 128 * 96 * 4);
    assert!(gb.join("flags.png").exists());
    // 16-bit linear on request.
    let o = rendiff(&[
        "render",
        "scenes/spheres.toml",
        "--size",
        "32x24",
        "--linear16",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    assert!(rendiff::image_io::read_png_linear(&out).unwrap().linear16);
}

#[test]
fn diff_exit_status_follows_the_verdict() {
    let dir = temp("diff");
    // Raster against ray: within tolerance.
    let o = rendiff(&["diff", "scenes/spheres.toml", "--size", "80x60"]);
    assert_eq!(o.status.code(), Some(0), "{}{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("verdict: pass"));
    // The ray tracer against an image of another scene: outside tolerance.
    let other = dir.join("bunny.png");
    let o = rendiff(&[
        "render",
        "scenes/bunny.toml",
        "--size",
        "80x60",
        "--linear16",
        "-o",
        other.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    let o = rendiff(&[
        "diff",
        "scenes/spheres.toml",
        "--size",
        "80x60",
        "--a",
        "ray",
        "--b",
        other.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("verdict: fail"));
    // An image of the wrong size is bad input.
    let o = rendiff(&[
        "diff",
        "scenes/spheres.toml",
        "--size",
        "81x60",
        "--a",
        "ray",
        "--b",
        other.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("80x60"), "{}", stderr(&o));
}

#[test]
fn diff_json_is_one_object_or_an_array() {
    let o = rendiff(&["diff", "scenes/spheres.toml", "--size", "40x30", "--json"]);
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["verdict"], "pass");
    assert_eq!(v["samples"], 1200);
    let o = rendiff(&[
        "diff",
        "scenes/spheres.toml",
        "scenes/bunny.toml",
        "--size",
        "40x30",
        "--json",
    ]);
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v.as_array().map(Vec::len), Some(2));
}

#[test]
fn usage_errors_exit_with_2_and_say_what_was_expected() {
    let cases: &[(&[&str], &str)] = &[
        (
            &["render", "scenes/spheres.toml", "--backend", "gpu"],
            "[possible values: raster, ray, painter, bsp]",
        ),
        (
            &["diff", "scenes/spheres.toml", "--backend", "ray"],
            "diff compares two sides: use --a and --b",
        ),
        (
            &["render", "scenes/spheres.toml", "-o", "x.jpg"],
            "-o x.jpg: rendiff writes PNG; use a .png name",
        ),
        (
            &["pov", "scenes/spheres.toml", "-o", "x.txt"],
            "use a .pov name",
        ),
        (
            &["render", "scenes/spheres.toml", "--shadows", "map"],
            "expected \"rays\" or \"map:RES\"",
        ),
        (
            &["render", "scenes/spheres.toml", "--sort", "depth"],
            "[possible values: newell, centroid]",
        ),
        (
            &["render", "scenes/spheres.toml", "--geometry", "exact"],
            "[possible values: mesh, analytic]",
        ),
        (
            &["render", "scenes/spheres.toml", "--size", "0x10"],
            "each side must be 1",
        ),
        (
            &["render", "scenes/spheres.toml", "--samples", "3"],
            "expected 1, 2, 4, 8 or 16",
        ),
        (
            &["render", "scenes/spheres.toml", "--depth", "f16"],
            "--depth",
        ),
        (
            &["render", "scenes/spheres.toml", "--threads", "0"],
            "--threads",
        ),
        (
            &["render", "scenes/spheres.toml", "-o", "no/such/dir/x.png"],
            "does not exist",
        ),
        (
            &["diff", "scenes/spheres.toml", "--b", "nope"],
            "expected a backend (raster, ray, painter, bsp), pov, a PATH.png, or a G-buffer folder",
        ),
        (
            &[
                "render",
                "scenes/spheres.toml",
                "--backend",
                "raster",
                "--geometry",
                "analytic",
            ],
            "only the ray tracer",
        ),
        (
            &["diff", "scenes/spheres.toml", "--geometry", "analytic"],
            "--a is raster",
        ),
        (&["render", "scenes/nosuch.toml"], "could not read"),
    ];
    let mut text = String::new();
    for (args, want) in cases {
        let o = rendiff(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(e.contains(want), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{args:?}");
        text.push_str(&format!("$ rendiff {}\n{e}\n", args.join(" ")));
    }
    insta::assert_snapshot!("usage_errors", text);
}

/// Finds a headless browser: Debian's chromium.
fn chromium() -> Option<PathBuf> {
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .find_map(|name| {
            let o = Command::new("which").arg(name).output().ok()?;
            o.status
                .success()
                .then(|| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()))
        })
}

/// The HTML report of several scenes, opened in headless Chromium: the
/// index and every scene page load and show every image. (Runs where
/// Chromium is installed; `.ci/run` installs it and sets
/// RENDIFF_REQUIRE_CHROMIUM=1 so CI cannot skip it.)
#[test]
fn html_report_loads_in_a_headless_browser() {
    let Some(browser) = chromium() else {
        assert!(
            std::env::var("RENDIFF_REQUIRE_CHROMIUM").is_err(),
            "chromium is required but not installed"
        );
        eprintln!("skipped: chromium is not installed");
        return;
    };
    let dir = temp("report");
    let o = rendiff(&[
        "diff",
        "scenes/spheres.toml",
        "scenes/polygons.toml",
        "--size",
        "96x72",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let pages = [
        dir.join("index.html"),
        dir.join("spheres/index.html"),
        dir.join("polygons/index.html"),
    ];
    for page in &pages {
        assert!(page.exists(), "{}", page.display());
        let o = Command::new(&browser)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--no-first-run",
                "--allow-file-access-from-files",
                &format!("--user-data-dir={}", temp("chromium-profile").display()),
                "--virtual-time-budget=5000",
                "--dump-dom",
                &format!("file://{}", page.display()),
            ])
            .output()
            .expect("chromium runs");
        let dom = stdout(&o);
        let marker = dom
            .split("data-images=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
            .unwrap_or("");
        let (ok, all) = marker.split_once('/').unwrap_or(("0", "?"));
        assert!(
            all != "0" && ok == all,
            "{}: images loaded {marker:?}\n{}",
            page.display(),
            stderr(&o)
        );
    }
}

/// Without POV-Ray, every command that needs it says how to install it
/// and exits with status 2 (no output written); commands that only read
/// stored references keep working.
#[test]
fn missing_povray_is_a_clear_error() {
    let empty = temp("no-povray-path");
    let out = temp("no-povray-out");
    let path = [("PATH", empty.as_path())];
    for args in [
        &["golden", "scenes/spheres.toml"][..],
        &[
            "golden",
            "scenes/spheres.toml",
            "--update",
            "--golden",
            out.to_str().unwrap(),
        ],
        &["diff", "scenes/spheres.toml", "--b", "pov", "--render"],
    ] {
        let o = rendiff_with_env(args, &path);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(
            err.contains("POV-Ray is not installed") && err.contains("apt-get install -y povray"),
            "{args:?}: {err}"
        );
    }
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 0, "files written");
    // The stored reference needs no POV-Ray.
    let o = rendiff_with_env(
        &["diff", "scenes/spheres.toml", "--b", "pov", "--json"],
        &path,
    );
    assert!(
        o.status.code() == Some(0) || o.status.code() == Some(1),
        "{}",
        stderr(&o)
    );
}

fn povray_installed() -> bool {
    let found = Command::new("povray").arg("--version").output().is_ok();
    assert!(
        found || std::env::var("RENDIFF_REQUIRE_POVRAY").is_err(),
        "povray is required but not installed"
    );
    found
}

/// `rendiff golden` in check mode, with POV-Ray: a copy of the stored
/// references passes; a tampered scene hash is reported stale and a
/// tampered image as no longer reproduced, each with exit status 1.
/// (`.ci/run` installs POV-Ray and sets RENDIFF_REQUIRE_POVRAY=1.)
#[test]
fn golden_check_reports_stale_and_changed_references() {
    if !povray_installed() {
        eprintln!("skipped: povray is not installed");
        return;
    }
    let dir = temp("golden-check");
    for f in std::fs::read_dir(root().join("golden/pov")).unwrap() {
        let f = f.unwrap().path();
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        if name.starts_with("spheres.") {
            std::fs::copy(&f, dir.join(&name)).unwrap();
        }
    }
    let args = [
        "golden",
        "scenes/spheres.toml",
        "--golden",
        dir.to_str().unwrap(),
    ];
    let o = rendiff(&args);
    assert_eq!(o.status.code(), Some(0), "{}{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("reproduced exactly"), "{}", stdout(&o));

    // A scene edited since its reference was rendered: its hash no longer matches.
    let meta = dir.join("spheres.toml");
    let text = std::fs::read_to_string(&meta).unwrap();
    let tampered: String = text
        .lines()
        .map(|l| {
            if l.starts_with("pov_fnv1a") {
                "pov_fnv1a = \"0000000000000000\"".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(tampered, text, "no export hash in {}", meta.display());
    std::fs::write(&meta, &tampered).unwrap();
    let o = rendiff(&args);
    assert_eq!(o.status.code(), Some(1), "{}{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("stale"), "{}", stdout(&o));
    std::fs::write(&meta, &text).unwrap();

    // A reference image that POV-Ray no longer reproduces.
    let png = dir.join("spheres.png");
    let mut img = rendiff::image_io::read_png_linear(&png).unwrap();
    img.pixels[0].r = (img.pixels[0].r + 0.25).min(1.0);
    rendiff::image_io::write_png(
        &png,
        img.width,
        img.height,
        &img.pixels,
        rendiff::image_io::PngEncoding::Linear16,
    )
    .unwrap();
    let o = rendiff(&args);
    assert_eq!(o.status.code(), Some(1), "{}{}", stdout(&o), stderr(&o));
    assert!(
        stdout(&o).contains("renders it differently"),
        "{}",
        stdout(&o)
    );
}

/// `rendiff bench` on a small image: the CSV has a row per setting with
/// finite times and errors, the plots are SVG documents, and a bad sweep
/// name is a usage error.
#[test]
fn bench_writes_the_results_and_the_plots() {
    let dir = temp("bench");
    let o = rendiff(&[
        "bench",
        "scenes/spheres.toml",
        "scenes/glass.toml",
        "--quick",
        "--repeats",
        "1",
        "--size",
        "64x48",
        "--sweep",
        "plan",
        "--sweep",
        "shadows",
        "--sweep",
        "max_depth",
        "--threads",
        "1",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(rendiff_cli::bench::CSV_HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // spheres: plan 2×2, shadows 2 (raster); glass: plan 2×2, shadows 2,
    // max_depth 2 (ray).
    assert_eq!(rows.len(), 4 + 2 + 4 + 2 + 2, "{csv}");
    for r in &rows {
        assert_eq!(r.len(), 18, "{r:?}");
        let median: f64 = r[10].parse().unwrap();
        let mae: f64 = r[14].parse().unwrap();
        assert!(
            median > 0.0 && median.is_finite() && mae >= 0.0 && mae.is_finite(),
            "{r:?}"
        );
        // At 64x48 the stored 320x240 POV-Ray references do not apply: the
        // reference is a ray-traced render.
        assert!(r[13].starts_with("ray"), "{r:?}");
    }
    // The ray tracer measured against its own render at the scene's
    // settings has no error there.
    assert!(
        rows.iter()
            .any(|r| r[1] == "ray" && r[2] == "plan" && r[14] == "0.00000"),
        "{csv}"
    );
    for f in [
        "time_vs_error_spheres.svg",
        "time_vs_error_glass.svg",
        "plan_savings.svg",
    ] {
        let svg = std::fs::read_to_string(dir.join(f)).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
            "{f}"
        );
    }
    assert!(
        std::fs::read_to_string(dir.join("index.html"))
            .unwrap()
            .contains("plan_savings.svg")
    );
    assert!(stdout(&o).contains("plan saved"), "{}", stdout(&o));

    let o = rendiff(&[
        "bench",
        "scenes/spheres.toml",
        "--sweep",
        "nope",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("unknown sweep \"nope\""),
        "{}",
        stderr(&o)
    );
}

/// `rendiff lines` writes an SVG of line elements or a PNG; other
/// extensions and bad crease angles are usage errors.
#[test]
fn lines_writes_svg_and_png() {
    let dir = temp("lines");
    let svg = dir.join("m.svg");
    let o = rendiff(&[
        "lines",
        "scenes/menagerie.toml",
        "-o",
        svg.to_str().unwrap(),
        "--hidden",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.contains("<line class=\"silhouette\""));
    assert!(
        text.contains("class=\"hidden\""),
        "--hidden keeps the hidden pieces"
    );
    let png = dir.join("m.png");
    let o = rendiff(&["lines", "scenes/spheres.toml", "-o", png.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let img = rendiff::image_io::read_png_linear(&png).unwrap();
    assert_eq!((img.width, img.height), (320, 240));
    assert!(img.pixels.iter().any(|p| p.r < 0.2), "no line drawn");
    for (args, want) in [
        (
            vec!["lines", "scenes/spheres.toml", "-o", "x.jpg"],
            ".svg or .png",
        ),
        (
            vec![
                "lines",
                "scenes/spheres.toml",
                "-o",
                "x.svg",
                "--crease",
                "200",
            ],
            "--crease",
        ),
    ] {
        let o = rendiff(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(want), "{}", stderr(&o));
    }
    assert!(!root().join("x.svg").exists() && !root().join("x.jpg").exists());
}

/// The painter renders from the command line, sample-exact or smooth;
/// `--smooth` belongs to the painter only.
#[test]
fn painter_renders_exact_and_smooth() {
    let dir = temp("painter");
    for (extra, name) in [(None, "exact.png"), (Some("--smooth"), "smooth.png")] {
        let out = dir.join(name);
        let mut args = vec![
            "render",
            "scenes/painter_cycle.toml",
            "--backend",
            "painter",
            "--sort",
            "centroid",
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        let o = rendiff(&args);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        assert!(out.exists());
    }
    let o = rendiff(&[
        "render",
        "scenes/spheres.toml",
        "--smooth",
        "-o",
        dir.join("x.png").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--smooth"), "{}", stderr(&o));
    let o = rendiff(&[
        "render",
        "scenes/spheres.toml",
        "--backend",
        "painter",
        "--sort",
        "depth",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--sort"), "{}", stderr(&o));
}

/// `rendiff completions SHELL` prints a script naming every command;
/// `rendiff man` the roff page, every command in it.
#[test]
fn completions_and_man_page() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let o = rendiff(&["completions", shell]);
        assert!(o.status.success(), "{shell}: {}", stderr(&o));
        let text = stdout(&o);
        for cmd in ["render", "diff", "pov", "bench", "completions"] {
            assert!(text.contains(cmd), "{shell} script lacks {cmd}");
        }
    }
    let o = rendiff(&["completions", "tcsh"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("possible values"), "{}", stderr(&o));

    let o = rendiff(&["man"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let page = stdout(&o);
    assert!(
        page.starts_with(".ie") || page.contains(".TH rendiff"),
        "{page}"
    );
    for sub in [
        "RENDIFF RENDER",
        "RENDIFF DIFF",
        "RENDIFF POV",
        "RENDIFF BENCH",
    ] {
        assert!(page.contains(sub), "the page lacks {sub}");
    }
    assert!(
        page.contains("\\-\\-absolute\\-paths"),
        "the page lacks pov's options"
    );
    let dir = temp("man");
    let file = dir.join("rendiff.1");
    let o = rendiff(&["man", "-o", file.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&file).unwrap(), page);
    assert!(stdout(&o).is_empty());
}

/// A scene without lights renders, with a warning on standard error.
#[test]
fn a_scene_without_lights_is_warned_about() {
    let dir = temp("no_lights");
    let scene = dir.join("dark.toml");
    std::fs::write(
        &scene,
        r#"[image]
width = 16
height = 12

[camera]
eye = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 45.0

[materials.glow]
pigment = [0.8, 0.1, 0.1]
emission = 0.5

[[objects]]
kind = "sphere"
material = "glow"
center = [0.0, 0.0, 0.0]
radius = 1.0
"#,
    )
    .unwrap();
    let png = dir.join("dark.png");
    let o = rendiff(&[
        "render",
        scene.to_str().unwrap(),
        "--size",
        "16x12",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("no lights: only ambient and emission light the scene"),
        "{}",
        stderr(&o)
    );
    assert!(png.exists());
}

/// `rendiff pov S -o elsewhere/S.pov` names textures from that folder,
/// and its first comment line is the command that renders it there:
/// POV-Ray run in that folder finds every file.
#[test]
fn pov_export_renders_where_it_is_written() {
    for scene in ["textured", "bumps"] {
        let dir = temp(&format!("pov_elsewhere_{scene}"));
        let pov = dir.join(format!("{scene}.pov"));
        let o = rendiff(&[
            "pov",
            &format!("scenes/{scene}.toml"),
            "--size",
            "32x24",
            "-o",
            pov.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = std::fs::read_to_string(&pov).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("#version 3.7;"));
        let command = lines.next().unwrap().strip_prefix("// ").unwrap();
        let words: Vec<&str> = command.split_whitespace().collect();
        assert_eq!(words[0], "povray", "{command}");
        assert!(
            words.contains(&format!("+I{scene}.pov").as_str()),
            "{command}"
        );
        assert!(
            words.contains(&format!("+O{scene}.png").as_str()),
            "{command}"
        );
        assert!(
            text.contains("png \"../"),
            "relative names expected:\n{text}"
        );
        assert!(!text.contains(root().to_str().unwrap()));

        let abs = dir.join(format!("{scene}_abs.pov"));
        let o = rendiff(&[
            "pov",
            &format!("scenes/{scene}.toml"),
            "--size",
            "32x24",
            "--absolute-paths",
            "-o",
            abs.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let abs_text = std::fs::read_to_string(&abs).unwrap();
        assert!(abs_text.contains("png \"/"), "absolute names expected");

        if !povray_installed() {
            continue;
        }
        for (file, words) in [(&pov, words.clone()), (&abs, vec![])] {
            let words = if words.is_empty() {
                let t = std::fs::read_to_string(file).unwrap();
                let line = t
                    .lines()
                    .nth(1)
                    .unwrap()
                    .strip_prefix("// ")
                    .unwrap()
                    .to_string();
                line.split_whitespace()
                    .map(str::to_string)
                    .collect::<Vec<_>>()
            } else {
                words.iter().map(|w| (*w).to_string()).collect()
            };
            let o = Command::new(&words[0])
                .args(&words[1..])
                .current_dir(&dir)
                .output()
                .expect("povray runs");
            let err = stderr(&o);
            assert!(
                !err.contains("Cannot open file"),
                "{}: {err}",
                file.display()
            );
            assert!(o.status.success(), "{}: {err}", file.display());
            let png = file.with_extension("png");
            assert!(png.exists(), "{} not rendered", png.display());
        }
    }
}

/// `--threads 1` runs the command on the calling thread itself (no
/// worker is started); its images and G-buffers must be those of a
/// pool of several workers, byte for byte, on both backends.
#[test]
fn one_thread_renders_what_several_do() {
    let dir = temp("one_thread");
    for backend in ["raster", "ray"] {
        let mut files = Vec::new();
        for threads in ["1", "3"] {
            let out = dir.join(format!("{backend}-{threads}.png"));
            let gbuf = dir.join(format!("{backend}-{threads}-g"));
            let o = rendiff(&[
                "render",
                "scenes/dense.toml",
                "--size",
                "96x72",
                "--backend",
                backend,
                "--threads",
                threads,
                "-o",
                out.to_str().unwrap(),
                "--gbuffer",
                gbuf.to_str().unwrap(),
            ]);
            assert!(o.status.success(), "{}", stderr(&o));
            let mut bytes = vec![std::fs::read(&out).unwrap()];
            for f in rendiff::frame::GBUFFER_FILES {
                bytes.push(std::fs::read(gbuf.join(f)).unwrap());
            }
            files.push(bytes);
        }
        assert!(
            files[0] == files[1],
            "{backend}: --threads 1 differs from 3"
        );
    }
}
