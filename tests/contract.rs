//! The contract holds: no Rust or Python file outside `contract/` spells a channel name as a string literal (they
//! come from `agent_contract::channels`, and in Python from `flow.agent`, which reads them from it), and the page's
//! test vectors still match the contract's types.

use std::path::{Path, PathBuf};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every `.rs` and `.py` file under `dir`, skipping build outputs and virtual environments.
fn source_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if path.is_dir() {
            if !matches!(
                name.as_ref(),
                "target" | "node_modules" | ".git" | "contract" | ".venv" | "venv" | "bench-venv"
            ) {
                source_files(&path, out);
            }
        } else if name.ends_with(".rs") || name.ends_with(".py") {
            out.push(path);
        }
    }
}

/// The string literals (`"..."`, escapes aside) in `text` that are an `Agent.` channel name or prefix.
fn channel_literals(text: &str) -> Vec<String> {
    // The needle is built from pieces for the same reason as the test below: this file is scanned too.
    let needle = format!("\"{}.", "Agent");
    let mut found = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find(&needle) {
        let tail = &rest[at + 1..];
        let end = tail
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '.' || c == '_' || c == '-'))
            .unwrap_or(tail.len());
        if tail[end..].starts_with('"') {
            found.push(tail[..end].to_string());
        }
        rest = &tail[end..];
    }
    found
}

#[test]
fn no_channel_name_is_spelt_outside_the_contract() {
    let mut files = Vec::new();
    source_files(&workspace(), &mut files);
    assert!(
        files.len() > 50,
        "the walk found only {} files",
        files.len()
    );
    let mut stray = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap_or_default();
        for name in channel_literals(&text) {
            stray.push(format!("{}: \"{name}\"", f.display()));
        }
    }
    assert!(
        stray.is_empty(),
        "channel names belong in crates/contract/src/channels.rs:\n{}",
        stray.join("\n")
    );
}

#[test]
fn the_literal_finder_sees_quoted_names_and_not_prose() {
    // Built from pieces, so that this file does not trip its own check.
    let audio = ["Agent", "audio"].join(".");
    let grey = ["Agent", "video", "y"].join(".");
    let text = format!(
        "subscribe(\"{audio}\"); let h = r#\"{{\"source\":\"{grey}\"}}\"#; warn!(\"bad message on {audio}: x\");"
    );
    assert_eq!(channel_literals(&text), vec![audio, grey]);
}

#[test]
fn every_contract_channel_is_unique_and_documented() {
    for c in agent_contract::channels::ALL {
        assert!(!c.doc.is_empty(), "{} has no doc", c.name);
    }
}
