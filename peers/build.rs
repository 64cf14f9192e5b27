//! Links the system's Embree 3 (Debian: `libembree-dev`).
fn main() {
    println!("cargo:rustc-link-lib=embree3");
}
