//! Generates the Rust types of the vendored ROS 1 messages (`msgs/`) with roslibrust's code
//! generator; no ROS installation is read (ROS_PACKAGE_PATH is ignored).

use std::path::PathBuf;

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let msgs = root.join("msgs");
    let (tokens, inputs) =
        roslibrust_codegen::find_and_generate_ros_messages_without_ros_package_path(vec![
            msgs.clone(),
        ])
        .unwrap_or_else(|e| panic!("ROS message generation from {}: {e}", msgs.display()));
    for p in inputs {
        println!("cargo:rerun-if-changed={}", p.display());
    }
    println!("cargo:rerun-if-changed={}", msgs.display());
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets it")).join("messages.rs");
    std::fs::write(&out, tokens.to_string())
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", out.display()));
}
