//! The workspace as its manifests describe it: the packages (the root `Cargo.toml`'s members, plus the crates
//! that are workspaces of their own, like `fuzz/`), each crate's root files as Cargo finds them, the module tree
//! under each root as the `mod` declarations build it, and the dependencies between packages. The `imports` and
//! `tidy` guards read everything from here, so that neither keeps a hand-written list that could fall behind.

use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

/// The repository root.
pub fn root() -> PathBuf {
    normalize(&Path::new(env!("CARGO_MANIFEST_DIR")).join(".."))
}

/// `path` without `.` and `..` components (the tree has no symbolic links to follow).
pub fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// `path` relative to the repository root, with `/` separators, as the documentation spells paths.
pub fn relative(path: &Path) -> String {
    let Ok(rel) = path.strip_prefix(root()) else {
        return path.display().to_string();
    };
    rel.components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join("/")
}

/// A manifest, parsed; a manifest that does not parse fails the guard that reads it, naming the file.
pub fn manifest(dir: &Path) -> toml::Table {
    let file = dir.join("Cargo.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", file.display()));
    text.parse::<toml::Table>()
        .unwrap_or_else(|e| panic!("{} does not parse: {e}", file.display()))
}

/// Directories a walk of the tree never enters: build output, installed packages, virtual environments, and the
/// git-ignored data the tools download (models, recordings).
fn skipped(dir: &Path) -> bool {
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned());
    match name.as_deref() {
        None => true,
        Some(n) => {
            n.starts_with('.')
                || matches!(
                    n,
                    "target" | "node_modules" | "vendor" | "__pycache__" | "corpus" | "artifacts"
                )
                || (dir.parent() == Some(root().as_path()) && matches!(n, "data" | "models"))
        }
    }
}

/// The workspace members, as the root manifest lists them (a trailing `/*` stands for every package below).
pub fn members() -> Vec<String> {
    let root = root();
    let table = manifest(&root);
    let listed: Vec<String> = table
        .get("workspace")
        .and_then(|w| w.get("members"))
        .and_then(toml::Value::as_array)
        .expect("the root Cargo.toml has [workspace] members")
        .iter()
        .filter_map(|m| m.as_str().map(str::to_string))
        .collect();
    let mut out = Vec::new();
    for m in listed {
        match m.strip_suffix("/*") {
            Some(parent) => {
                let mut found: Vec<String> = std::fs::read_dir(root.join(parent))
                    .into_iter()
                    .flatten()
                    .flatten()
                    .filter(|e| e.path().join("Cargo.toml").is_file())
                    .map(|e| format!("{parent}/{}", e.file_name().to_string_lossy()))
                    .collect();
                found.sort();
                out.extend(found);
            }
            None => out.push(m),
        }
    }
    out
}

/// Every `Cargo.toml` of the tree but the root's, as the folders that hold them (relative to the root).
pub fn manifests() -> Vec<String> {
    fn walk(dir: &Path, out: &mut Vec<String>) {
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let p = entry.path();
            if p.is_dir() && !skipped(&p) {
                if p.join("Cargo.toml").is_file() {
                    out.push(relative(&p));
                }
                walk(&p, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(&root(), &mut out);
    out.sort();
    out
}

/// The packages the guards read: the workspace members, then every other package of the tree that is a
/// workspace of its own (`fuzz/`, which needs its own flags and profile).
pub fn packages() -> Vec<String> {
    let mut out = members();
    for dir in manifests() {
        if !out.contains(&dir) && manifest(&root().join(&dir)).contains_key("workspace") {
            out.push(dir);
        }
    }
    out
}

/// Every `.rs` file under `dir`, not entering skipped folders nor the folders of other packages.
pub fn rust_files(dir: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let p = entry.path();
            if p.is_dir() {
                if !skipped(&p) && !p.join("Cargo.toml").is_file() {
                    walk(&p, out);
                }
            } else if p.extension().is_some_and(|e| e == "rs") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, &mut out);
    out.sort();
    out
}

/// The `.rs` files directly in `dir` (`tests/*.rs`) or, given `in_each_folder`, that file in each folder of
/// `dir` (`src/bin/*/main.rs`).
fn discovered(dir: &Path, in_each_folder: Option<&str>) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter_map(|p| match in_each_folder {
            None => (p.is_file() && p.extension().is_some_and(|e| e == "rs")).then_some(p),
            Some(name) => Some(p.join(name)).filter(|f| p.is_dir() && f.is_file()),
        })
        .collect();
    out.sort();
    out
}

/// The root file of every crate of the package in `dir`: the targets its manifest names by path, and those Cargo
/// finds by itself (`src/lib.rs`, `src/main.rs`, `src/bin/`, `tests/`, `examples/`, `benches/`, `build.rs`).
pub fn crate_roots(dir: &Path) -> Vec<PathBuf> {
    let table = manifest(dir);
    let mut out = Vec::new();
    let lib = table
        .get("lib")
        .and_then(|l| l.get("path"))
        .and_then(toml::Value::as_str);
    out.push(dir.join(lib.unwrap_or("src/lib.rs")));
    for kind in ["bin", "test", "example", "bench"] {
        for target in table
            .get(kind)
            .and_then(toml::Value::as_array)
            .into_iter()
            .flatten()
        {
            if let Some(path) = target.get("path").and_then(toml::Value::as_str) {
                out.push(dir.join(path));
            }
        }
    }
    let build = table
        .get("package")
        .and_then(|p| p.get("build"))
        .and_then(toml::Value::as_str);
    out.push(dir.join(build.unwrap_or("build.rs")));
    out.push(dir.join("src/main.rs"));
    for auto in ["src/bin", "tests", "examples", "benches"] {
        out.extend(discovered(&dir.join(auto), None));
        out.extend(discovered(&dir.join(auto), Some("main.rs")));
    }
    let mut out: Vec<PathBuf> = out
        .iter()
        .map(|p| normalize(p))
        .filter(|p| p.is_file())
        .collect();
    out.sort();
    out.dedup();
    out
}

/// The code of a file without its comments (a `//` inside a string literal cuts the line short, which no
/// declaration or path the guards read contains).
pub fn without_comments(text: &str) -> String {
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The out-of-line modules a file declares (`mod name;`, any visibility), each with its `#[path]` if it has one.
pub fn declared_modules(code: &str) -> Vec<(String, Option<String>)> {
    let mut out = Vec::new();
    let mut path: Option<String> = None;
    for line in code.lines().map(str::trim) {
        if let Some(rest) = line.strip_prefix("#[path") {
            path = rest.split('"').nth(1).map(str::to_string);
            continue;
        }
        if line.starts_with("#[") || line.is_empty() {
            continue;
        }
        let mut rest = line;
        if let Some(r) = rest.strip_prefix("pub") {
            rest = r.trim_start();
            if rest.starts_with('(') {
                rest = rest.split_once(')').map_or("", |(_, r)| r.trim_start());
            }
        }
        if let Some(r) = rest.strip_prefix("mod ")
            && let Some(name) = r.trim().strip_suffix(';')
            && !name.is_empty()
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            out.push((name.to_string(), path.take()));
        }
        path = None;
    }
    out
}

/// The files of the crate whose root is `root_file`, by module path (`[]` for the root, `[a, b]` for `a::b`),
/// following its `mod` declarations as the compiler does. Modules declared inside inline modules are not
/// followed (the workspace has none).
pub fn module_tree(root_file: &Path) -> BTreeMap<Vec<String>, PathBuf> {
    fn visit(
        file: &Path,
        at: Vec<String>,
        owns_its_folder: bool,
        out: &mut BTreeMap<Vec<String>, PathBuf>,
    ) {
        if out.values().any(|f| f == file) {
            return;
        }
        out.insert(at.clone(), file.to_path_buf());
        let folder = file.parent().map(Path::to_path_buf).unwrap_or_default();
        // A crate root, a `mod.rs` or a file loaded by `#[path]` keeps its modules beside it; `a.rs` keeps them
        // in `a/`.
        let children = if owns_its_folder {
            folder.clone()
        } else {
            folder.join(file.file_stem().unwrap_or_default())
        };
        let code = without_comments(&std::fs::read_to_string(file).unwrap_or_default());
        for (name, path) in declared_modules(&code) {
            let mut sub = at.clone();
            sub.push(name.clone());
            let (target, owns) = match path {
                Some(p) => (normalize(&folder.join(p)), true),
                None => {
                    let flat = children.join(format!("{name}.rs"));
                    if flat.is_file() {
                        (flat, false)
                    } else {
                        (children.join(&name).join("mod.rs"), true)
                    }
                }
            };
            if target.is_file() {
                visit(&target, sub, owns, out);
            }
        }
    }
    let mut out = BTreeMap::new();
    visit(&normalize(root_file), Vec::new(), true, &mut out);
    out
}

/// A dependency of a package on another package of the tree.
#[derive(Debug)]
pub struct PathDependency {
    /// The name the manifest gives it.
    pub name: String,
    /// The folder of the package it points to, relative to the root.
    pub folder: String,
}

/// The dependencies of the package in `dir` (normal, dev and build, target-specific ones too) that are packages
/// of the tree: a `path`, or `workspace = true` where the root's `[workspace.dependencies]` entry has a `path`.
pub fn path_dependencies(dir: &Path) -> Vec<PathDependency> {
    let root = root();
    let workspace = manifest(&root);
    let shared = workspace
        .get("workspace")
        .and_then(|w| w.get("dependencies"))
        .and_then(toml::Value::as_table);
    let table = manifest(dir);
    let mut tables: Vec<&toml::Table> = Vec::new();
    let kinds = ["dependencies", "dev-dependencies", "build-dependencies"];
    for kind in kinds {
        tables.extend(table.get(kind).and_then(toml::Value::as_table));
    }
    for target in table
        .get("target")
        .and_then(toml::Value::as_table)
        .into_iter()
        .flatten()
    {
        for kind in kinds {
            tables.extend(target.1.get(kind).and_then(toml::Value::as_table));
        }
    }
    let mut out = Vec::new();
    for (name, spec) in tables.into_iter().flatten() {
        let own = spec.get("path").and_then(toml::Value::as_str);
        let inherited = spec.get("workspace").and_then(toml::Value::as_bool) == Some(true);
        let folder = match (own, inherited) {
            (Some(p), _) => Some(dir.join(p)),
            (None, true) => shared
                .and_then(|s| s.get(name))
                .and_then(|s| s.get("path"))
                .and_then(toml::Value::as_str)
                .map(|p| root.join(p)),
            (None, false) => None,
        };
        if let Some(folder) = folder {
            out.push(PathDependency {
                name: name.clone(),
                folder: relative(&normalize(&folder)),
            });
        }
    }
    out
}
