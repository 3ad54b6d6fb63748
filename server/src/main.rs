//! The robot-agent server binary.

fn main() {}
