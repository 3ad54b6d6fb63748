//! The language-model satellite: the agent's chat turns (`Agent.chat`) answered by llama.cpp in-process or by an
//! OpenAI-compatible endpoint, spoken sentence by sentence as the reply streams (docs/llm.md).

pub mod endpoint;
pub mod engine;
pub mod generator;
pub mod grammar;
pub mod prompt;
pub mod satellite;
pub mod spoken;
pub mod turn;
