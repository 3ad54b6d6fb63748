//! No import cycles between files: in every crate of the workspace, a file never imports (by `use`, or by a
//! `super::` / `crate::` / child-module path in its code) a file that imports it back, directly or through
//! others. A leaf never imports the file that wires it (ARCHITECTURE.md).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The source roots of the workspace's crates.
const ROOTS: &[&str] = &[
    "contract/src",
    "hub/src",
    "server/src",
    "server/vision/src",
    "server/voice/src",
    "server/brain/src",
    "satellites/flow/src",
    "satellites/flowctl/src",
    "satellites/whisper-sat/src",
    "tests/support",
    "bench/src",
];

/// Cycles known and not yet broken, as the sorted files of each; the test fails if one disappears (so that the
/// list only shrinks) or a new one appears. None is left.
const KNOWN: &[&[&str]] = &[];

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = entry.path();
        if p.is_dir() {
            walk(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// A file's module path inside its crate (`a/b.rs` and `a/b/mod.rs` are `[a, b]`; `lib.rs` and `main.rs` are `[]`).
fn module_path(root: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(root).unwrap_or(file).with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// The code of a file without comments and without its unit-test module.
fn code(text: &str) -> String {
    let body = text.split("#[cfg(test)]\nmod tests").next().unwrap_or(text);
    body.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Every path in `code` that starts with `start` (`super`, `crate` or a child module's name) at a word boundary,
/// as its `::`-separated segments; `use a::{b, c}` gives `[a]` and the braces' first names.
fn paths_from(code: &str, start: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let bytes: Vec<char> = code.chars().collect();
    let needle: Vec<char> = format!("{start}::").chars().collect();
    let mut i = 0;
    while i + needle.len() <= bytes.len() {
        let boundary = i == 0 || !(is_ident(bytes[i - 1]) || bytes[i - 1] == ':');
        if boundary && bytes[i..i + needle.len()] == needle[..] {
            let mut segs = vec![start.to_string()];
            let mut j = i + needle.len();
            loop {
                while j < bytes.len() && bytes[j].is_whitespace() {
                    j += 1;
                }
                if j < bytes.len() && bytes[j] == '{' {
                    j += 1;
                    continue;
                }
                let s = j;
                while j < bytes.len() && is_ident(bytes[j]) {
                    j += 1;
                }
                if s == j {
                    break;
                }
                segs.push(bytes[s..j].iter().collect());
                if bytes.get(j) == Some(&':') && bytes.get(j + 1) == Some(&':') {
                    j += 2;
                } else {
                    break;
                }
            }
            out.push(segs);
            i = j.max(i + 1);
        } else {
            i += 1;
        }
    }
    out
}

/// The file a path from the file at module path `at` names: the longest prefix that is a file of the crate.
fn resolve(
    at: &[String],
    path: &[String],
    files: &BTreeMap<Vec<String>, PathBuf>,
) -> Option<PathBuf> {
    let mut base: Vec<String> = match path.first().map(String::as_str) {
        Some("crate") => Vec::new(),
        Some("super") => at.to_vec(),
        _ => at.to_vec(),
    };
    let mut rest = path;
    match path.first().map(String::as_str) {
        Some("crate") => rest = &path[1..],
        Some("super") => {
            while rest.first().map(String::as_str) == Some("super") {
                base.pop();
                rest = &rest[1..];
            }
        }
        _ => {}
    }
    (0..=rest.len()).rev().find_map(|n| {
        let mut cand = base.clone();
        cand.extend(rest[..n].iter().cloned());
        files.get(&cand).cloned()
    })
}

fn edges() -> BTreeMap<PathBuf, BTreeSet<PathBuf>> {
    let mut edges: BTreeMap<PathBuf, BTreeSet<PathBuf>> = BTreeMap::new();
    for root in ROOTS {
        let root = workspace().join(root);
        assert!(root.is_dir(), "{} is not a directory", root.display());
        let mut list = Vec::new();
        walk(&root, &mut list);
        let files: BTreeMap<Vec<String>, PathBuf> = list
            .iter()
            .map(|f| (module_path(&root, f), f.clone()))
            .collect();
        for (at, file) in &files {
            let text = code(&std::fs::read_to_string(file).unwrap_or_default());
            let children: Vec<String> = files
                .keys()
                .filter(|k| k.len() == at.len() + 1 && k[..at.len()] == at[..])
                .filter_map(|k| k.last().cloned())
                .collect();
            let mut paths = paths_from(&text, "crate");
            paths.extend(paths_from(&text, "super"));
            for child in &children {
                paths.extend(paths_from(&text, child));
            }
            for p in paths {
                if let Some(target) = resolve(at, &p, &files)
                    && &target != file
                {
                    edges.entry(file.clone()).or_default().insert(target);
                }
            }
        }
    }
    edges
}

/// The strongly connected components with more than one file (Tarjan).
fn cycles(edges: &BTreeMap<PathBuf, BTreeSet<PathBuf>>) -> Vec<Vec<String>> {
    #[derive(Default)]
    struct T {
        index: BTreeMap<PathBuf, usize>,
        low: BTreeMap<PathBuf, usize>,
        stack: Vec<PathBuf>,
        on: BTreeSet<PathBuf>,
        out: Vec<Vec<String>>,
        next: usize,
    }
    fn visit(v: &PathBuf, e: &BTreeMap<PathBuf, BTreeSet<PathBuf>>, t: &mut T) {
        t.index.insert(v.clone(), t.next);
        t.low.insert(v.clone(), t.next);
        t.next += 1;
        t.stack.push(v.clone());
        t.on.insert(v.clone());
        for w in e.get(v).into_iter().flatten() {
            if !t.index.contains_key(w) {
                visit(w, e, t);
                let lw = t.low[w];
                let lv = t.low.get_mut(v).expect("visited");
                *lv = (*lv).min(lw);
            } else if t.on.contains(w) {
                let iw = t.index[w];
                let lv = t.low.get_mut(v).expect("visited");
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on.remove(&w);
                let done = &w == v;
                comp.push(w);
                if done {
                    break;
                }
            }
            if comp.len() > 1 {
                let root = workspace();
                let mut names: Vec<String> = comp
                    .iter()
                    .map(|p| {
                        let rel = p.strip_prefix(&root).unwrap_or(p);
                        rel.to_string_lossy().trim_start_matches("./").to_string()
                    })
                    .collect();
                names.sort();
                t.out.push(names);
            }
        }
    }
    let mut t = T::default();
    for v in edges.keys() {
        if !t.index.contains_key(v) {
            visit(v, edges, &mut t);
        }
    }
    t.out.sort();
    t.out
}

#[test]
fn no_file_imports_a_file_that_imports_it_back() {
    let edges = edges();
    assert!(edges.len() > 50, "only {} files import others", edges.len());
    let found = cycles(&edges);
    let known: Vec<Vec<String>> = KNOWN
        .iter()
        .map(|c| c.iter().map(|s| (*s).to_string()).collect())
        .collect();
    assert_eq!(
        found, known,
        "import cycles between files (each line: the files of one cycle)"
    );
}

#[test]
fn the_path_finder_sees_use_lists_inline_paths_and_child_modules() {
    let code = "use super::{state::Shared, lock};\nfn f() { crate::hub::x(); routes::router(); }";
    assert_eq!(
        paths_from(code, "super"),
        vec![vec!["super".to_string(), "state".into(), "Shared".into()]]
    );
    assert_eq!(
        paths_from(code, "crate"),
        vec![vec!["crate".to_string(), "hub".into(), "x".into()]]
    );
    assert_eq!(paths_from(code, "routes").len(), 1);
    assert!(paths_from("my_routes::x", "routes").is_empty());
}
