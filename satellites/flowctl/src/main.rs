//! flowctl: the command-line client of the flow hub.

fn main() {}
