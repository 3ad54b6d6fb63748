//! Example subscriber satellite.

fn main() {}
