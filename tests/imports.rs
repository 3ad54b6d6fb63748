//! The import rules, checked over every crate the manifests name (no hand-written list of folders):
//!
//! - no import cycles between files: in every crate, a file never imports (by `use`, or by a `super::` /
//!   `crate::` / child-module path in its code) a file that imports it back, directly or through others. A leaf
//!   never imports the file that wires it (ARCHITECTURE.md);
//! - no import runs back up between floors: `crates/` (base libraries) <- `hub/` <- `agent/` <- `satellites/`; a
//!   package depends only on packages of its own floor or of the floors above it. `tests/`, `bench/` and `fuzz/`
//!   stand over everything and may use anything.

// Shared by both guards, each using only part of it.
#[allow(dead_code)]
#[path = "guards/workspace.rs"]
mod workspace;

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

/// Cycles known and not yet broken, as the sorted files of each; the test fails if one disappears (so that the
/// list only shrinks) or a new one appears. None is left.
const KNOWN: &[&[&str]] = &[];

/// The floors, top to bottom: a package may depend on its own floor and the ones above it.
const FLOORS: &[&str] = &["crates", "hub", "agent", "satellites"];

/// The top-level folders over every floor: their packages may depend on anything.
const OVER_EVERYTHING: &[&str] = &["tests", "bench", "fuzz"];

/// The code of a file without comments and without its unit-test module.
fn code(text: &str) -> String {
    let body = text.split("#[cfg(test)]\nmod tests").next().unwrap_or(text);
    workspace::without_comments(body)
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

/// Every crate of every package, as its module tree (module path -> file).
fn crates() -> Vec<BTreeMap<Vec<String>, PathBuf>> {
    let root = workspace::root();
    let mut out = Vec::new();
    for package in workspace::packages() {
        let dir = root.join(&package);
        assert!(
            dir.join("Cargo.toml").is_file(),
            "the workspace names {package}, which has no Cargo.toml"
        );
        for crate_root in workspace::crate_roots(&dir) {
            out.push(workspace::module_tree(&crate_root));
        }
    }
    out
}

fn edges() -> BTreeMap<PathBuf, BTreeSet<PathBuf>> {
    let mut edges: BTreeMap<PathBuf, BTreeSet<PathBuf>> = BTreeMap::new();
    for files in crates() {
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
                let mut names: Vec<String> = comp.iter().map(|p| workspace::relative(p)).collect();
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

/// The floor of a package folder: its index in [`FLOORS`], or one past the last for the folders over everything.
fn floor(folder: &str) -> Result<usize, String> {
    let top = folder.split('/').next().unwrap_or(folder);
    if let Some(i) = FLOORS.iter().position(|f| *f == top) {
        Ok(i)
    } else if OVER_EVERYTHING.contains(&top) {
        Ok(FLOORS.len())
    } else {
        Err(format!(
            "{folder} lies on no floor: put it under one of {FLOORS:?} or {OVER_EVERYTHING:?}, or give its top \
             folder a floor in tests/imports.rs"
        ))
    }
}

#[test]
fn no_package_depends_on_a_floor_below_its_own() {
    let root = workspace::root();
    let mut wrong = Vec::new();
    let mut seen = 0;
    let packages = workspace::packages();
    for package in &packages {
        let own = match floor(package) {
            Ok(f) => f,
            Err(e) => {
                wrong.push(e);
                continue;
            }
        };
        for dep in workspace::path_dependencies(&root.join(package)) {
            seen += 1;
            match floor(&dep.folder) {
                Ok(theirs) if theirs > own => wrong.push(format!(
                    "{package} (floor `{}`) depends on {} ({}, floor `{}`), a floor below its own",
                    FLOORS.get(own).copied().unwrap_or("over everything"),
                    dep.name,
                    dep.folder,
                    FLOORS.get(theirs).copied().unwrap_or("over everything"),
                )),
                Ok(_) => {}
                Err(e) => wrong.push(format!("{package} depends on {}: {e}", dep.name)),
            }
        }
    }
    assert!(
        packages.len() > 10,
        "only {} packages found",
        packages.len()
    );
    assert!(seen > 20, "only {seen} dependencies between packages found");
    assert!(
        wrong.is_empty(),
        "imports that run back up between floors (top to bottom: {}):\n{}",
        FLOORS.join(" <- "),
        wrong.join("\n")
    );
}

#[test]
fn every_rust_file_is_in_a_crate_the_guards_read() {
    let root = workspace::root();
    let read: BTreeSet<PathBuf> = crates().into_iter().flat_map(|c| c.into_values()).collect();
    let mut unread = Vec::new();
    for package in workspace::packages() {
        for file in workspace::rust_files(&root.join(&package)) {
            if !read.contains(&file) {
                unread.push(workspace::relative(&file));
            }
        }
    }
    assert!(
        unread.is_empty(),
        "files no crate root reaches through `mod` declarations (dead, or a crate the guards do not know):\n{}",
        unread.join("\n")
    );
}

#[test]
fn the_module_finder_sees_visibility_and_path_attributes() {
    let code = "pub mod a;\npub(crate) mod b;\n#[path = \"x/c.rs\"]\n#[cfg(test)]\nmod c;\nmod d {\nuse e;";
    assert_eq!(
        workspace::declared_modules(code),
        vec![
            ("a".to_string(), None),
            ("b".to_string(), None),
            ("c".to_string(), Some("x/c.rs".to_string())),
        ]
    );
}

#[test]
fn floors_run_from_the_base_libraries_down_to_the_satellites() {
    assert_eq!(floor("crates/flow"), Ok(0));
    assert_eq!(floor("hub"), Ok(1));
    assert!(floor("agent/server") < floor("satellites/python"));
    assert_eq!(floor("bench"), Ok(FLOORS.len()));
    assert!(floor("server").is_err());
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
