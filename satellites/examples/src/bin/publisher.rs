//! Example publisher satellite.

fn main() {}
