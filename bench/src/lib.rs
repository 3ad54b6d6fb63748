//! Shared benchmark plumbing.
