//! A crate of a user's own (examples/user-crate) built against the library
//! as a user builds it (a path dependency, its own tests): its snapshot
//! test passes, fails with a pending file when its scene changes, and
//! passes again once `rendiff review --accept-all` accepts the change.

use std::path::Path;
use std::process::Command;

use crate::util::root;

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            if e.file_name() != "target" {
                copy_dir(&e.path(), &target);
            }
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// `cargo test` in the user's crate: (passed, output).
fn cargo_test(dir: &Path) -> (bool, String) {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let o = Command::new(cargo)
        .args(["test", "--offline", "--quiet"])
        .current_dir(dir)
        // One build for every run of this test, kept between runs.
        .env("CARGO_TARGET_DIR", root().join("target").join("user-crate"))
        .env_remove("RENDIFF_ACCEPT")
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    (o.status.success(), text)
}

#[test]
fn a_users_crate_keeps_its_scene_under_regression() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("user-crate");
    copy_dir(&root().join("examples/user-crate"), &dir);
    // The path dependency, absolute now that the crate moved.
    let manifest = dir.join("Cargo.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let lib = root().join("crates/rendiff");
    let text = text.replace(
        "\"../../crates/rendiff\"",
        &format!("{:?}", lib.display().to_string()),
    );
    std::fs::write(&manifest, text).unwrap();

    let (ok, out) = cargo_test(&dir);
    assert!(ok, "the example's tests pass as shipped:\n{out}");

    // A changed pigment: the golden test fails, says where the pending
    // image is and how to review it.
    let scene = dir.join("scenes/ball.toml");
    let text = std::fs::read_to_string(&scene).unwrap();
    std::fs::write(&scene, text.replace("[0.2, 0.4, 0.9]", "[0.9, 0.4, 0.2]")).unwrap();
    let (ok, out) = cargo_test(&dir);
    assert!(!ok, "a changed pigment fails:\n{out}");
    let pending = dir.join("tests/golden/scenes/ball.ray.new.png");
    assert!(pending.exists(), "{out}");
    assert!(
        out.contains("ball.ray.new.png") && out.contains("rendiff review"),
        "{out}"
    );

    // Review without a terminal and without a decision: still pending.
    let review = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .arg("review")
            .args(args)
            .current_dir(&dir)
            .output()
            .unwrap()
    };
    let o = review(&[]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("scenes/ball.ray.new.png"));
    assert!(pending.exists());
    // Accepted: the golden is the new image and the test passes again.
    let o = review(&["--accept-all"]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!pending.exists());
    let (ok, out) = cargo_test(&dir);
    assert!(ok, "after accepting:\n{out}");
    // `rendiff golden --accept` accepts as review --accept-all does.
    let edited = std::fs::read_to_string(&scene).unwrap();
    std::fs::write(&scene, edited.replace("phong = 0.5", "phong = 0.9")).unwrap();
    assert!(!cargo_test(&dir).0, "a changed phong fails");
    assert!(pending.exists());
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(["golden", "--accept"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!pending.exists());
    assert!(cargo_test(&dir).0, "after golden --accept");
    // Reverted and rejected: the golden stays, the pending file goes.
    std::fs::write(&scene, text).unwrap();
    let (ok, _) = cargo_test(&dir);
    assert!(!ok);
    let o = review(&["--reject-all"]);
    assert_eq!(o.status.code(), Some(0));
    assert!(!pending.exists());
    assert!(!cargo_test(&dir).0, "the rejected change still fails");
}
