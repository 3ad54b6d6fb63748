//! The vision library's evaluation kit, for its tests and benchmarks only: [`fixtures`] loads the shared real-data
//! fixtures and their ground truth and scores faces against it; [`evaluation`] runs the pipeline on still frames
//! and builds the synthetic scenes (a face pasted into a background) that time a face coming into view.
//!
//! It lives outside `agent-vision` so that the server, which links the library, ships none of it.

pub mod evaluation;
pub mod fixtures;
pub mod talking;
