//! `llm-sat`: the language-model satellite's command line.

fn main() {}
