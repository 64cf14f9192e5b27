//! Bad input gets a clear error and exit status 2, never a panic.
//!
//! Every scene in `tests/data/bad/` is broken in one way, said by the
//! comment on its first line. The place the message must name is written
//! in the corpus itself:
//!
//! - the line that holds `# <- error` is the line the message must name
//!   (in the scene, or in the OBJ file the error is in);
//! - `# error in: PATH` (relative to the scene, optionally `PATH:LINE`)
//!   says the error is in that mesh or image, not in the scene.
//!
//! Scene errors must read `error: SCENE:LINE:COL: …`, mesh errors
//! `error: FILE.obj:LINE: …` (or `error: FILE.obj: …` for the file as a
//! whole), image errors `error: FILE.png: …`. The message texts are
//! snapshotted, one snapshot per file.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rendiff::scene::Scene;
use rendiff::{Overrides, Prepared};

/// The corpus, relative to the crate root.
const CORPUS: &str = "tests/data/bad";

/// The corpus may grow but never shrink below this.
const MIN_FILES: usize = 35;

/// The marker of the line an error must name.
const MARKER: &str = "# <- error";

fn crate_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Runs the real binary from the crate root, with backtraces on so that a
/// panic would show one.
fn rendiff(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(crate_root())
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("could not run the rendiff binary")
}

/// The corpus scenes as paths relative to the crate root, in name order.
fn corpus() -> Vec<String> {
    let mut files: Vec<String> = std::fs::read_dir(crate_root().join(CORPUS))
        .expect("tests/data/bad exists")
        .map(|e| e.expect("readable directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| format!("{CORPUS}/{}", p.file_name().unwrap().to_string_lossy()))
        .collect();
    files.sort();
    files
}

/// Where an error must be reported.
#[derive(Debug)]
struct Place {
    /// The file, as the message must print it (relative to the crate root).
    file: String,
    /// The line it must name, if any.
    line: Option<usize>,
    /// `true` for the scene file itself (then the message has `:LINE:COL:`).
    in_scene: bool,
}

/// The line holding the marker, if the text has one.
fn marked_line(text: &str) -> Option<usize> {
    text.lines().position(|l| l.contains(MARKER)).map(|i| i + 1)
}

fn expected_place(rel: &str) -> Place {
    let bytes = std::fs::read(crate_root().join(rel)).expect("corpus file is readable");
    let text = String::from_utf8_lossy(&bytes);
    let other = text
        .lines()
        .find_map(|l| l.strip_prefix("# error in: "))
        .map(str::trim);
    match other {
        None => Place {
            file: rel.to_string(),
            line: Some(
                marked_line(&text)
                    .unwrap_or_else(|| panic!("{rel}: no `{MARKER}` line and no `# error in:`")),
            ),
            in_scene: true,
        },
        Some(spec) => {
            let (path, line) = match spec.rsplit_once(':') {
                Some((p, l)) if l.parse::<usize>().is_ok() => (p, l.parse().ok()),
                _ => (spec, None),
            };
            let file = format!("{CORPUS}/{path}");
            let line = line.or_else(|| {
                std::fs::read(crate_root().join(&file))
                    .ok()
                    .and_then(|b| marked_line(&String::from_utf8_lossy(&b)))
            });
            Place {
                file,
                line,
                in_scene: false,
            }
        }
    }
}

/// Checks the message of one failed run against the place the corpus names.
fn check_message(rel: &str, out: &Output) -> String {
    let stderr = String::from_utf8(out.stderr.clone()).expect("stderr is UTF-8");
    assert_eq!(
        out.status.code(),
        Some(2),
        "{rel}: expected exit status 2; stderr:\n{stderr}"
    );
    assert!(
        !stderr.contains("panicked") && !stderr.to_lowercase().contains("backtrace"),
        "{rel}: a panic or a backtrace:\n{stderr}"
    );
    assert!(
        stderr.ends_with('\n') && stderr.lines().count() == 1,
        "{rel}: expected one line on stderr, got:\n{stderr}"
    );
    assert!(
        out.stdout.is_empty(),
        "{rel}: nothing on stdout expected, got:\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let place = expected_place(rel);
    let prefix = match (place.in_scene, place.line) {
        (true, Some(line)) => format!("error: {}:{line}:", place.file),
        (false, Some(line)) => format!("error: {}:{line}: ", place.file),
        (_, None) => format!("error: {}: ", place.file),
    };
    assert!(
        stderr.starts_with(&prefix),
        "{rel}: expected the message to start with `{prefix}`, got:\n{stderr}"
    );
    if place.in_scene {
        // `SCENE:LINE:COL: ` — the column is a number too.
        let rest = &stderr[prefix.len()..];
        let col = rest.split(':').next().unwrap_or("");
        assert!(
            !col.is_empty() && col.parse::<usize>().is_ok() && rest[col.len()..].starts_with(": "),
            "{rel}: expected `{prefix}COL: `, got:\n{stderr}"
        );
    }
    stderr.trim_end().to_string()
}

/// (a) `rendiff plan` on every corpus file: exit status 2, one line naming
/// the file and place, no panic; the message text is snapshotted.
#[test]
fn plan_reports_every_bad_scene() {
    insta::glob!("../data/bad", "*.toml", |path| {
        let rel = format!("{CORPUS}/{}", path.file_name().unwrap().to_string_lossy());
        let out = rendiff(&["plan", &rel]);
        let message = check_message(&rel, &out);
        insta::assert_snapshot!(message);
    });
}

/// (b) The library gives the same error: `Scene::load` fails, and its
/// message is the CLI's without `error: `. A refracting material on an
/// open mesh and the scenes f32 cannot represent are the errors found only
/// after tessellation (closedness and extent are decided on the welded,
/// transformed triangles, DESIGN.md §4 and §8), so there `Prepared::load`
/// is the library call that fails.
#[test]
fn library_gives_the_same_errors() {
    const AFTER_TESSELLATION: &[&str] = &[
        "65_refraction_on_open_mesh.toml",
        // The extent of the transformed geometry.
        "73_scene_too_small.toml",
        "74_scene_too_far.toml",
        // uvs against their texture's size, per object.
        "80_uv_beyond_texture_precision.toml",
        // An object's own extent in f32 steps.
        "81_object_too_far.toml",
    ];
    for rel in corpus() {
        let cli = rendiff(&["plan", &rel]);
        let cli = String::from_utf8_lossy(&cli.stderr);
        let cli = cli
            .trim_end()
            .strip_prefix("error: ")
            .unwrap_or_else(|| panic!("{rel}: no `error: ` prefix: {cli}"));
        let path = PathBuf::from(&rel);
        let name = rel.rsplit('/').next().unwrap();
        let message = match Scene::load(&path) {
            Err(e) => {
                assert!(
                    !AFTER_TESSELLATION.contains(&name),
                    "{rel}: now fails in Scene::load; update AFTER_TESSELLATION"
                );
                chain(&e)
            }
            Ok(_) => {
                assert!(
                    AFTER_TESSELLATION.contains(&name),
                    "{rel}: Scene::load accepted a bad scene"
                );
                chain(
                    &Prepared::load(&path, &Overrides::default())
                        .expect_err("Prepared::load must reject it"),
                )
            }
        };
        assert_eq!(message, cli, "{rel}: library and CLI messages differ");
    }
}

/// An error and its sources joined by ": ", as a program prints it (an
/// error's Display never repeats its source).
fn chain(e: &dyn std::error::Error) -> String {
    let mut parts = vec![e.to_string()];
    let mut cause = e.source();
    while let Some(c) = cause {
        parts.push(c.to_string());
        cause = c.source();
    }
    parts.join(": ")
}

/// (c) The corpus cannot silently shrink.
#[test]
fn corpus_has_enough_files() {
    let files = corpus();
    assert!(
        files.len() >= MIN_FILES,
        "the bad-input corpus has {} scene files, expected at least {MIN_FILES}",
        files.len()
    );
    for rel in &files {
        let name = rel.rsplit('/').next().unwrap();
        let (nn, rest) = name.split_at(2);
        assert!(
            nn.bytes().all(|b| b.is_ascii_digit()) && rest.starts_with('_'),
            "{rel}: corpus files are named NN_short_name.toml"
        );
        let bytes = std::fs::read(crate_root().join(rel)).unwrap();
        assert!(
            bytes.starts_with(b"# "),
            "{rel}: the first line must be a comment saying what the file tests"
        );
    }
}

/// A scene file that does not exist (no file in the corpus, by design).
#[test]
fn missing_scene_file() {
    let rel = format!("{CORPUS}/no_such_scene.toml");
    assert!(!crate_root().join(&rel).exists());
    let out = rendiff(&["plan", &rel]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    let message = stderr.trim_end();
    let lib = Scene::load(Path::new(&rel)).expect_err("a missing file is an error");
    // The library's error and its source, as the binary prints them.
    assert_eq!(message.strip_prefix("error: "), Some(chain(&lib).as_str()));
    // The OS's wording differs between systems; the start is ours.
    assert!(
        message.starts_with(&format!("error: {rel}: could not read the file: ")),
        "{message}"
    );
}

/// `render` stops at the same errors before writing anything: no output
/// file, and no temporary file beside it.
#[test]
fn render_writes_nothing_for_bad_scenes() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bad_input_render");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for name in [
        "01_toml_syntax_error.toml",
        "20_radius_zero.toml",
        "26_obj_bad_number.toml",
        "34_png_garbage.toml",
        "42_empty_scene.toml",
        "65_refraction_on_open_mesh.toml",
        "71_not_utf8.toml",
    ] {
        let rel = format!("{CORPUS}/{name}");
        let png = dir.join(name.replace(".toml", ".png"));
        let out = rendiff(&["render", &rel, "-o", png.to_str().unwrap()]);
        let plan = rendiff(&["plan", &rel]);
        check_message(&rel, &out);
        assert_eq!(
            out.stderr, plan.stderr,
            "{rel}: render and plan report differently"
        );
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert!(left.is_empty(), "{rel}: render left files: {left:?}");
    }
}

/// Every subcommand that reads a scene stops at the same error on every
/// corpus file, before writing anything: exit status 2, the message
/// `plan` gives (naming the file and the place), no panic, no backtrace,
/// no file left in the output folder.
#[test]
fn every_subcommand_reports_every_bad_scene() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bad_input_all");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = |name: &str| dir.join(name).to_string_lossy().into_owned();
    let (png, pov, svg, bench, golden, diff) = (
        out("x.png"),
        out("x.pov"),
        out("x.svg"),
        out("bench"),
        out("golden"),
        out("diff"),
    );
    for rel in corpus() {
        let plan = rendiff(&["plan", &rel]);
        let runs: [(&str, Vec<&str>); 6] = [
            ("render", vec!["render", &rel, "-o", &png]),
            ("diff", vec!["diff", &rel, "--out", &diff]),
            ("pov", vec!["pov", &rel, "-o", &pov]),
            (
                "golden",
                vec!["golden", &rel, "--update", "--golden", &golden],
            ),
            ("bench", vec!["bench", &rel, "--quick", "--out", &bench]),
            ("lines", vec!["lines", &rel, "-o", &svg]),
        ];
        for (cmd, args) in runs {
            let o = rendiff(&args);
            eprintln!("{rel}: {cmd}");
            check_message(&rel, &o);
            assert_eq!(
                o.stderr, plan.stderr,
                "{rel}: {cmd} and plan report differently"
            );
            let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
            assert!(left.is_empty(), "{rel}: {cmd} left files: {left:?}");
        }
    }
}

/// A mesh too big for the memory budget is refused while it is read, at
/// the line reached and with the figure, not once it is all in memory;
/// the reader counts a triangle as tessellation does.
#[test]
fn a_mesh_over_the_budget_is_refused_at_the_line_reached() {
    assert_eq!(
        rendiff::scene::obj::BYTES_PER_TRIANGLE_TO_BE,
        rendiff::tessellate::BYTES_PER_TRIANGLE
    );
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bad_input_budget");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // 2 M faces (16 MB of text) would be 400 MB of triangles.
    let mut obj = String::from("v 0 0 0\nv 1 0 0\nv 0 1 0\n");
    obj += &"f 1 2 3\n".repeat(2 << 20);
    std::fs::write(dir.join("big.obj"), obj).unwrap();
    let scene = std::fs::read_to_string(
        crate_root()
            .join(CORPUS)
            .join("31_obj_two_corner_face.toml"),
    )
    .unwrap()
    .replace("assets/two_corner_face.obj", "big.obj");
    std::fs::write(dir.join("big.toml"), scene).unwrap();
    let budget = rendiff::budget::Budget::new(64 << 20);
    let err = Scene::load_within(&dir.join("big.toml"), &budget).expect_err("over the budget");
    let rendiff::scene::LoadError::Mesh {
        line: Some(line),
        message,
        ..
    } = &err
    else {
        panic!("{err}")
    };
    // 64 MiB less the 16 MB file, at 200 B per triangle: about 250 000.
    assert!((200_000..300_000).contains(line), "{err}");
    assert!(
        message.starts_with(&format!("the mesh up to line {line} ("))
            && message.contains("triangles to be)")
            && message.contains("over the memory budget of 64.0 MiB"),
        "{err}"
    );
}
