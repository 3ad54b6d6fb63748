//! Tidy: the house rules that a reader would otherwise have to keep by hand, over every package the manifests
//! name (as rust-analyzer's tidy test does):
//!
//! - every Rust file starts with a `//!` line saying what it is for;
//! - every package of the tree is a workspace member or a workspace of its own;
//! - every repository path ARCHITECTURE.md names exists, and its code map names every workspace member and every
//!   folder of the page's `web/js/`;
//! - the page's `node --test` suites and every page module they reach (the pure ones) start with `// @ts-check`,
//!   so that `tsc -p web/tsconfig.json` checks them.
//!
//! How ARCHITECTURE.md names paths: a backticked token made of path characters is a path when it contains a `/`
//! or ends in a file extension. It is a repository path when its first segment is a top-level entry of the
//! repository (`hub/src/pulse.rs`, `web/js/avatar/`, `docs/protocol.md`). In the code map, a token may also be
//! relative to its section: the folder a `### \`folder\`` heading names, or the folder a bullet starts with
//! (`- \`agent/vision\`: ...`, also on the bullet's continuation lines); there it names the path it is a suffix
//! of inside that folder (`queue.rs`, `hub/mod.rs`, `cli/satellite/`). Outside the code map only repository paths
//! are checked. A `*` matches within one segment; a path under something `.gitignore` ignores from the root (the
//! generated `web/vendor/`, `data/`) is not looked for.

// Shared by both guards, each using only part of it.
#[allow(dead_code)]
#[path = "guards/workspace.rs"]
mod workspace;

use std::collections::BTreeSet;
use std::path::Path;

const ARCHITECTURE: &str = "ARCHITECTURE.md";

/// The extensions that make a backticked token without a `/` a file name.
const EXTENSIONS: &[&str] = &[
    "rs", "js", "mjs", "ts", "py", "pyi", "toml", "md", "json", "glb", "html", "css", "sh", "txt",
    "yaml", "yml", "lock",
];

#[test]
fn every_rust_file_starts_with_a_doc_line() {
    let root = workspace::root();
    let mut bare = Vec::new();
    for package in workspace::packages() {
        for file in workspace::rust_files(&root.join(&package)) {
            let text = std::fs::read_to_string(&file).unwrap_or_default();
            if !text.starts_with("//!") {
                bare.push(format!(
                    "{}: the first line is not a `//!` line saying what the file is for",
                    workspace::relative(&file)
                ));
            }
        }
    }
    assert!(bare.is_empty(), "{}", bare.join("\n"));
}

#[test]
fn every_package_of_the_tree_is_a_member_or_a_workspace_of_its_own() {
    let root = workspace::root();
    let members = workspace::members();
    let stray: Vec<String> = workspace::manifests()
        .into_iter()
        .filter(|dir| !members.contains(dir))
        .filter(|dir| !workspace::manifest(&root.join(dir)).contains_key("workspace"))
        .map(|dir| {
            format!("{dir}/Cargo.toml: neither a member of the root Cargo.toml's [workspace] nor a workspace")
        })
        .collect();
    assert!(stray.is_empty(), "{}", stray.join("\n"));
}

#[test]
fn every_path_architecture_names_exists() {
    let doc = Doc::read();
    let checked = doc.tokens.iter().filter(|t| t.checked).count();
    assert!(checked > 50, "only {checked} paths found in {ARCHITECTURE}");
    let mut missing = Vec::new();
    for token in &doc.tokens {
        if let Some(folder) = &token.heading_error {
            missing.push(format!(
                "{ARCHITECTURE}:{}: the heading names `{folder}`, which is no folder of the repository",
                token.line
            ));
        }
        if token.checked && token.found.is_empty() {
            let within = if token.contexts.is_empty() {
                String::new()
            } else {
                format!(" (nor inside {})", token.contexts.join(", "))
            };
            missing.push(format!(
                "{ARCHITECTURE}:{}: `{}` is not in the tree{within}",
                token.line, token.text
            ));
        }
    }
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

#[test]
fn the_code_map_names_every_member_and_every_page_folder() {
    let doc = Doc::read();
    let named: BTreeSet<&String> = doc
        .tokens
        .iter()
        .filter(|t| t.in_code_map)
        .flat_map(|t| &t.found)
        .collect();
    let root = workspace::root();
    let mut wanted = workspace::members();
    let mut page: Vec<String> = std::fs::read_dir(root.join("web/js"))
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.path().is_dir())
        .map(|e| format!("web/js/{}", e.file_name().to_string_lossy()))
        .collect();
    page.sort();
    wanted.extend(page);
    let unnamed: Vec<String> = wanted
        .into_iter()
        .filter(|w| !named.contains(w))
        .map(|w| format!("{ARCHITECTURE}: the code map does not name `{w}`"))
        .collect();
    assert!(unnamed.is_empty(), "{}", unnamed.join("\n"));
}

/// The relative imports of a JavaScript module (`from "./x.js"`, `import "./x.js"`), resolved against its folder.
fn js_imports(file: &Path) -> Vec<std::path::PathBuf> {
    let text = std::fs::read_to_string(file).unwrap_or_default();
    let folder = file.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for keyword in ["from \"", "import \""] {
        for piece in text.split(keyword).skip(1) {
            if let Some(target) = piece.split('"').next()
                && target.starts_with('.')
            {
                out.push(workspace::normalize(&folder.join(target)));
            }
        }
    }
    out
}

#[test]
fn the_page_tests_and_the_modules_they_reach_are_type_checked() {
    let root = workspace::root();
    let tests_of = |dir: &str| -> Vec<std::path::PathBuf> {
        let mut files: Vec<_> = std::fs::read_dir(root.join(dir))
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.to_string_lossy().ends_with(".test.mjs"))
            .collect();
        files.sort();
        files
    };
    let page_tests = tests_of("web/test");
    assert!(!page_tests.is_empty(), "no web/test/*.test.mjs");
    // The avatar generator's tests run the avatar's pure modules too; only what they reach of web/js is held.
    let mut queue: Vec<std::path::PathBuf> = page_tests.clone();
    queue.extend(tests_of("scripts/avatar-gen/tests"));
    let page = root.join("web/js");
    let mut seen = BTreeSet::new();
    let mut unchecked = Vec::new();
    while let Some(file) = queue.pop() {
        if !seen.insert(file.clone()) {
            continue;
        }
        let held = page_tests.contains(&file) || file.starts_with(&page);
        let text = std::fs::read_to_string(&file).unwrap_or_default();
        if held && !text.starts_with("// @ts-check") {
            unchecked.push(format!(
                "{}: does not start with `// @ts-check` (a node test reaches it, so tsc should check it)",
                workspace::relative(&file)
            ));
        }
        queue.extend(
            js_imports(&file)
                .into_iter()
                .filter(|f| f.starts_with(&page)),
        );
    }
    unchecked.sort();
    assert!(unchecked.is_empty(), "{}", unchecked.join("\n"));
}

#[test]
fn section_relative_names_are_suffixes_inside_the_section() {
    let tree: Vec<String> = [
        "hub",
        "hub/src",
        "hub/src/hub",
        "hub/src/hub/mod.rs",
        "hub/src/queue.rs",
    ]
    .map(String::from)
    .to_vec();
    let ignored: Vec<String> = Vec::new();
    let find = |t: &str, contexts: &[String]| resolve(t, contexts, &tree, &ignored);
    assert_eq!(
        find("hub/mod.rs", &["hub".into()]),
        vec!["hub/src/hub/mod.rs"]
    );
    assert_eq!(find("queue.rs", &["hub".into()]), vec!["hub/src/queue.rs"]);
    assert!(find("queue.rs", &["crates".into()]).is_empty());
    assert_eq!(find("hub/src/*.rs", &[]), vec!["hub/src/queue.rs"]);
    assert_eq!(find("hub/src/", &[]), vec!["hub/src"]);
    assert!(find("rub/src/queue.rs", &[]).is_empty());
}

#[test]
fn tokens_are_paths_only_when_they_look_like_paths() {
    assert!(is_path_like("crates/flow"));
    assert!(is_path_like("queue.rs"));
    assert!(is_path_like("web/js/avatar/"));
    // A channel name (built from pieces: tests/contract.rs scans this file for channel literals).
    assert!(!is_path_like(&format!("{}.video.y", "Agent")));
    assert!(!is_path_like("hub.io_threads"));
    assert!(!is_path_like("tcp://"));
    assert!(!is_path_like("/healthz"));
    assert!(!is_path_like("flow::Client"));
}

/// A backticked token of ARCHITECTURE.md and what it names.
#[derive(Debug, Default)]
struct Token {
    text: String,
    line: usize,
    in_code_map: bool,
    /// The section's folders it may be relative to.
    contexts: Vec<String>,
    /// Whether the rule above makes it a path to look for.
    checked: bool,
    /// The paths (relative to the root, without a trailing `/`) it names.
    found: Vec<String>,
    /// Set on a heading's token that names no folder.
    heading_error: Option<String>,
}

struct Doc {
    tokens: Vec<Token>,
}

impl Doc {
    fn read() -> Doc {
        let root = workspace::root();
        let text = std::fs::read_to_string(root.join(ARCHITECTURE))
            .unwrap_or_else(|e| panic!("cannot read {ARCHITECTURE}: {e}"));
        let tree = tree(&root);
        let ignored = ignored(&root);
        let top: BTreeSet<String> = std::fs::read_dir(&root)
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        let is_folder = |t: &str| {
            let t = t.trim_end_matches('/');
            !t.is_empty() && is_path_chars(t) && root.join(t).is_dir()
        };
        let mut tokens = Vec::new();
        let mut in_code_map = false;
        let mut in_fence = false;
        let mut heading: Option<String> = None;
        let mut bullet: Option<String> = None;
        for (n, line) in text.lines().enumerate() {
            let number = n + 1;
            if line.trim_start().starts_with("```") {
                in_fence = !in_fence;
                continue;
            }
            if in_fence {
                continue;
            }
            let spans: Vec<&str> = line.split('`').skip(1).step_by(2).collect();
            if let Some(title) = line.strip_prefix("## ") {
                in_code_map = title.trim() == "Code map";
                heading = None;
                bullet = None;
            } else if line.starts_with("### ") {
                heading = None;
                bullet = None;
                if in_code_map && let Some(first) = spans.first() {
                    let mut token = Token {
                        text: (*first).to_string(),
                        line: number,
                        in_code_map,
                        ..Token::default()
                    };
                    if is_folder(first) {
                        let folder = first.trim_end_matches('/').to_string();
                        token.found.push(folder.clone());
                        heading = Some(folder);
                    } else {
                        token.heading_error = Some((*first).to_string());
                    }
                    tokens.push(token);
                }
                continue;
            } else if line.trim_start().starts_with("- ") || line.trim().is_empty() {
                bullet = None;
                let opening = line
                    .trim_start()
                    .strip_prefix("- `")
                    .and_then(|r| r.split('`').next());
                if in_code_map
                    && let Some(first) = opening
                    && is_folder(first)
                {
                    bullet = Some(first.trim_end_matches('/').to_string());
                }
            }
            let contexts: Vec<String> = if in_code_map {
                bullet.iter().chain(heading.iter()).cloned().collect()
            } else {
                Vec::new()
            };
            for span in spans {
                let mut token = Token {
                    text: span.to_string(),
                    line: number,
                    in_code_map,
                    ..Token::default()
                };
                if bullet.as_deref() == Some(span.trim_end_matches('/')) {
                    token.found.push(span.trim_end_matches('/').to_string());
                } else if is_path_like(span) {
                    let first = span.split('/').next().unwrap_or_default();
                    let repository = span.contains('/') && top.contains(first);
                    token.checked = repository || !contexts.is_empty();
                    if repository {
                        token.found = resolve(span, &[], &tree, &ignored);
                    }
                    if !contexts.is_empty() {
                        token
                            .found
                            .extend(resolve(span, &contexts, &tree, &ignored));
                        token.contexts = contexts.clone();
                    }
                }
                tokens.push(token);
            }
        }
        Doc { tokens }
    }
}

fn is_path_chars(t: &str) -> bool {
    t.chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/' | '*'))
}

/// Whether a backticked token is a path by the rule above.
fn is_path_like(t: &str) -> bool {
    if t.is_empty() || t.starts_with('/') || !is_path_chars(t) || t.contains("//") {
        return false;
    }
    if t.contains('/') {
        return true;
    }
    t.rsplit_once('.')
        .is_some_and(|(stem, ext)| !stem.is_empty() && EXTENSIONS.contains(&ext))
}

/// Every file and folder of the tree, relative to the root, without the folders no walk enters.
fn tree(root: &Path) -> Vec<String> {
    fn walk(dir: &Path, out: &mut Vec<String>) {
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let p = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if p.is_dir() {
                if name.starts_with('.') && name != ".ci" && name != ".config"
                    || matches!(name.as_str(), "target" | "node_modules")
                {
                    continue;
                }
                out.push(workspace::relative(&p));
                walk(&p, out);
            } else {
                out.push(workspace::relative(&p));
            }
        }
    }
    let mut out = Vec::new();
    walk(root, &mut out);
    out.sort();
    out
}

/// The paths the root `.gitignore` ignores from the root (`/web/vendor`): generated, so not looked for.
fn ignored(root: &Path) -> Vec<String> {
    std::fs::read_to_string(root.join(".gitignore"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| l.trim().strip_prefix('/'))
        .map(|l| l.trim_end_matches('/').to_string())
        .filter(|l| !l.is_empty() && !l.contains('*'))
        .collect()
}

/// Whether `name` matches `pattern`, where a `*` stands for any run of characters.
fn glob(pattern: &str, name: &str) -> bool {
    match pattern.split_once('*') {
        None => pattern == name,
        Some((head, tail)) => {
            let Some(rest) = name.strip_prefix(head) else {
                return false;
            };
            (0..=rest.len())
                .filter(|i| rest.is_char_boundary(*i))
                .any(|i| glob(tail, &rest[i..]))
        }
    }
}

/// The paths of `tree` a token names: the repository path it spells, or with `contexts`, the paths inside a
/// context folder that it is a suffix of. A token under an ignored path names itself.
fn resolve(token: &str, contexts: &[String], tree: &[String], ignored: &[String]) -> Vec<String> {
    let want: Vec<&str> = token.trim_end_matches('/').split('/').collect();
    let spelled = want.join("/");
    if contexts.is_empty()
        && ignored
            .iter()
            .any(|i| spelled == *i || spelled.starts_with(&format!("{i}/")))
    {
        return vec![spelled];
    }
    let mut out = Vec::new();
    for path in tree {
        let segs: Vec<&str> = path.split('/').collect();
        let tail_matches = |segs: &[&str]| {
            segs.len() >= want.len()
                && segs[segs.len() - want.len()..]
                    .iter()
                    .zip(&want)
                    .all(|(s, w)| glob(w, s))
        };
        let hit = if contexts.is_empty() {
            segs.len() == want.len() && tail_matches(&segs)
        } else {
            contexts.iter().any(|c| {
                let inside = path.starts_with(&format!("{c}/"));
                let depth = c.split('/').count();
                inside && segs.len() >= depth + want.len() && tail_matches(&segs)
            })
        };
        if hit {
            out.push(path.clone());
        }
    }
    out
}
