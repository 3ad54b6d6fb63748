//! Build script: links libsonic, which the espeak-ng static library built by `espeak-rs-sys` calls into.
//!
//! `espeak-rs-sys` configures espeak-ng with CMake, which enables its speed-up path when it finds the system
//! `libsonic` (Debian package `libsonic-dev`), but the crate does not tell rustc to link it, so every binary
//! that contains espeak-ng would fail with undefined `sonic*` symbols. Printing the directive from this
//! library's build script makes cargo add it to every binary that depends on `agent-voice`.

fn main() {
    println!("cargo:rustc-link-lib=sonic");
    println!("cargo:rerun-if-changed=build.rs");
}
