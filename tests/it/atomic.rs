//! Nothing half-written: a process killed (SIGKILL) while it writes its
//! output leaves the old file as it was; a golden update that fails part
//! way leaves the old set; and every file the library writes goes through
//! the one atomic writer.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use rendiff::image_io::{LinearImage, read_png_linear};
use rendiff::pov::golden;

use crate::util::{load, root};

fn temp(name: &str) -> std::path::PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("atomic")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The temporary files of the atomic writer in `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect()
}

#[test]
fn a_killed_render_leaves_the_old_file() {
    let dir = temp("kill");
    let target = dir.join("out.png");
    let old = b"the previous contents".to_vec();
    std::fs::write(&target, &old).unwrap();
    let args = [
        "render",
        "scenes/spheres.toml",
        "--size",
        "640x480",
        "--linear16",
        "-o",
        target.to_str().unwrap(),
    ];
    // The writer pauses between its complete temporary file and the
    // rename; the kill lands there, with the new file fully written.
    let mut child = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(root())
        .env("RENDIFF_TEST_PAUSE_BEFORE_RENAME_MS", "60000")
        .spawn()
        .unwrap();
    let start = Instant::now();
    while temporaries(&dir).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no temporary file appeared"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert_eq!(std::fs::read(&target).unwrap(), old, "the target changed");
    // Killed earlier, while rendering: nothing written at all.
    let mut child = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(root())
        .spawn()
        .unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(std::fs::read(&target).unwrap(), old, "the target changed");
    // Not killed: the complete new image.
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(root())
        .output()
        .unwrap();
    assert!(o.status.success());
    let img = read_png_linear(&target).unwrap();
    assert_eq!((img.width, img.height), (640, 480));
}

/// A golden update that fails while it swaps the files in (a folder is in
/// the way of the last reference, after the others were swapped in) puts
/// every old file back and leaves nothing of its own behind.
#[test]
fn a_failed_golden_update_keeps_the_old_set() {
    let dir = temp("golden");
    let job = load("spheres", &Default::default());
    let refs = golden::references(&job.scene, &job.tri).unwrap();
    assert!(
        refs.len() >= 2,
        "spheres has a mesh and an analytic reference"
    );
    let (w, h) = (job.tri.camera.width(), job.tri.camera.height());
    let fake = LinearImage {
        width: w,
        height: h,
        pixels: vec![rendiff::color::Rgb::splat(0.5); (w * h) as usize],
        linear16: true,
    };
    let rendered: Vec<_> = refs
        .into_iter()
        .map(|r| {
            let path = golden::reference_path(&dir, &job.scene, r.variant);
            (r, fake.clone(), path)
        })
        .collect();
    // The old set: the metadata and every reference but the last, which is
    // a folder that cannot be replaced by a file (swapped after the rest).
    let meta = golden::metadata_path(&dir, &job.scene);
    std::fs::write(&meta, "old metadata").unwrap();
    let (last, rest) = rendered.split_last().unwrap();
    for (_, _, p) in rest {
        std::fs::write(p, "old image").unwrap();
    }
    std::fs::create_dir_all(last.2.join("in the way")).unwrap();
    let err = golden::store(&job.scene, "test", &rendered, &dir);
    assert!(err.is_err(), "the update should fail");
    assert_eq!(std::fs::read_to_string(&meta).unwrap(), "old metadata");
    for (_, _, p) in rest {
        assert_eq!(
            std::fs::read_to_string(p).unwrap(),
            "old image",
            "{}",
            p.display()
        );
    }
    assert!(last.2.join("in the way").is_dir());
    let left: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".rendiff-staged") || n.contains("journal"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    // Without the obstacle the same update goes through whole.
    std::fs::remove_dir_all(&last.2).unwrap();
    golden::store(&job.scene, "test", &rendered, &dir).unwrap();
    assert_ne!(std::fs::read_to_string(&meta).unwrap(), "old metadata");
    for (_, _, p) in &rendered {
        assert_eq!(read_png_linear(p).unwrap().width, w);
    }
}

/// Every file the library writes goes through `image_io::write_atomic`:
/// no other `File::create` or `fs::write` in its sources.
#[test]
fn the_library_writes_only_through_the_atomic_writer() {
    let mut offenders = Vec::new();
    // The command line and every crate of the library.
    let mut stack = vec![root().join("src"), root().join("crates")];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().filter_map(Result::ok) {
            let p = e.path();
            if p.is_dir() {
                if p.file_name().is_none_or(|n| n != "target") {
                    stack.push(p);
                }
                continue;
            }
            if p.extension().is_none_or(|x| x != "rs") || p.ends_with("image_io.rs") {
                continue;
            }
            let text = std::fs::read_to_string(&p).unwrap();
            for (k, line) in text.lines().enumerate() {
                if line.contains("File::create(") || line.contains("fs::write(") {
                    offenders.push(format!("{}:{}", p.display(), k + 1));
                }
            }
        }
    }
    assert!(offenders.is_empty(), "direct writes: {offenders:?}");
}
