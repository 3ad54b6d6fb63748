//! Build script: compiles the small C++ face of dlib (`cpp/dlib_face.cpp`) against Debian's `libdlib-dev` and
//! links dlib with the BLAS and LAPACK its headers call into.
//!
//! The shape predictor and the network's layers are templates instantiated in this file, so it is always built
//! with optimisation, also in the debug profile: at `-O0` the descriptor takes seconds per face.

fn main() {
    println!("cargo:rerun-if-changed=cpp/dlib_face.cpp");
    println!("cargo:rerun-if-changed=build.rs");
    cc::Build::new()
        .cpp(true)
        .file("cpp/dlib_face.cpp")
        .std("c++17")
        .opt_level(3)
        .debug(false)
        .warnings(false)
        .compile("agent_face_dlib");
    for lib in ["dlib", "blas", "lapack"] {
        println!("cargo:rustc-link-lib={lib}");
    }
}
