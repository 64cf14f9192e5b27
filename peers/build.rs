//! Links the system's Embree 3 (Debian: `libembree-dev`), and compiles the
//! llvmpipe peer (`llvmpipe/frame.c`, EGL + OpenGL; Debian: `libegl-dev
//! libgl1-mesa-dev libgl1-mesa-dri`) with the system C compiler into a
//! program of its own. When that fails the rest still builds: the
//! `llvmpipe` subcommand then reports why (`RENDIFF_LLVMPIPE_ERROR`).
use std::path::PathBuf;
use std::process::Command;

fn main() {
    println!("cargo:rustc-link-lib=embree3");
    println!("cargo:rerun-if-changed=llvmpipe/frame.c");
    println!("cargo:rerun-if-env-changed=CC");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let exe = out.join("llvmpipe-frame");
    let src = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"))
        .join("llvmpipe/frame.c");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let result = Command::new(&cc)
        .args(["-O2", "-std=c11", "-Wall", "-Wextra", "-o"])
        .arg(&exe)
        .arg(&src)
        .args(["-lEGL", "-lGL"])
        .output();
    match result {
        Ok(o) if o.status.success() => {
            println!("cargo:rustc-env=RENDIFF_LLVMPIPE_FRAME={}", exe.display());
        }
        Ok(o) => {
            let text = String::from_utf8_lossy(&o.stderr);
            let status = o.status.to_string();
            let mut first: Vec<&str> = text.lines().filter(|l| !l.is_empty()).take(3).collect();
            if first.is_empty() {
                first.push(&status);
            }
            println!(
                "cargo:warning=the llvmpipe peer was not built ({cc} failed): {}",
                first.join(" | ")
            );
            println!(
                "cargo:rustc-env=RENDIFF_LLVMPIPE_ERROR={cc} could not compile peers/llvmpipe/frame.c (needs libegl-dev and libgl1-mesa-dev): {}",
                first.join(" | ")
            );
        }
        Err(e) => {
            println!("cargo:warning=the llvmpipe peer was not built: cannot run {cc}: {e}");
            println!("cargo:rustc-env=RENDIFF_LLVMPIPE_ERROR=cannot run the C compiler {cc}: {e}");
        }
    }
}
