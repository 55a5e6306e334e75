//! Checks that the layout tells the truth:
//!
//! * the crate graph written in `ARCHITECTURE.md` (the ```` ```crate-graph ```` block) is
//!   exactly the workspace's normal dependencies between its own crates, as
//!   `cargo metadata` reads them from the manifests;
//! * every crate directory has a `README.md`;
//! * no text file points outside the repository (the team's shared folder, absolute
//!   workspace paths, relative paths that climb above the clone, the team's design
//!   document): a clone is self-contained;
//! * no crate has a file-level import circle: file A imports file B when A names a
//!   `crate::…` or `super::…` path that resolves to B's module, and every strongly
//!   connected group (Tarjan) of two or more files is a circle. This is
//!   `scripts/import_cycles.py` in Rust, so CI needs no Python for it;
//! * the crates ARCHITECTURE.md keeps light stay light (`cargo tree`: no candle or
//!   wgpu in the baker and the exporters, no candle, baker or ground truth in the viewer).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

type Graph = BTreeMap<String, BTreeSet<String>>;

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read_text(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// `cargo metadata --no-deps` of the workspace.
fn metadata() -> Value {
    let manifest = repo_root().join("Cargo.toml");
    let out = Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
            "--manifest-path",
        ])
        .arg(&manifest)
        .output()
        .unwrap_or_else(|e| panic!("cannot run cargo metadata: {e}"));
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("cargo metadata printed no JSON: {e}"))
}

fn packages(meta: &Value) -> &[Value] {
    meta["packages"].as_array().map_or(&[], Vec::as_slice)
}

/// Each workspace crate and the workspace crates it depends on (normal dependencies,
/// on any target; dev and build dependencies left out).
fn metadata_graph(meta: &Value) -> Graph {
    let names: BTreeSet<&str> = packages(meta).iter().filter_map(|p| p["name"].as_str()).collect();
    let mut graph = Graph::new();
    for package in packages(meta) {
        let Some(name) = package["name"].as_str() else {
            continue;
        };
        let deps = graph.entry(name.to_string()).or_default();
        for dep in package["dependencies"].as_array().map_or(&[][..], Vec::as_slice) {
            let Some(dep_name) = dep["name"].as_str() else {
                continue;
            };
            if dep["kind"].is_null() && names.contains(dep_name) {
                deps.insert(dep_name.to_string());
            }
        }
    }
    graph
}

/// The ```` ```crate-graph ```` block of `ARCHITECTURE.md`: lines `crate: dep dep …`.
fn documented_graph(architecture: &str) -> Graph {
    let mut lines = architecture.lines().skip_while(|l| l.trim() != "```crate-graph");
    assert!(
        lines.next().is_some(),
        "ARCHITECTURE.md has no ```crate-graph block"
    );
    let mut graph = Graph::new();
    for line in lines.take_while(|l| l.trim() != "```") {
        if line.trim().is_empty() {
            continue;
        }
        let Some((name, deps)) = line.split_once(':') else {
            panic!("ARCHITECTURE.md crate-graph line without `crate:`: {line:?}")
        };
        let previous = graph.insert(
            name.trim().to_string(),
            deps.split_whitespace().map(str::to_string).collect(),
        );
        assert!(previous.is_none(), "ARCHITECTURE.md names {} twice", name.trim());
    }
    graph
}

/// What differs between the two graphs, one line per crate; empty when they agree.
fn graph_difference(actual: &Graph, documented: &Graph) -> String {
    let mut lines = Vec::new();
    let crates: BTreeSet<&String> = actual.keys().chain(documented.keys()).collect();
    for name in crates {
        match (actual.get(name), documented.get(name)) {
            (Some(_), None) => lines.push(format!("{name}: a workspace crate missing from ARCHITECTURE.md")),
            (None, Some(_)) => lines.push(format!("{name}: in ARCHITECTURE.md but not a workspace crate")),
            (Some(a), Some(d)) if a != d => {
                let undocumented: Vec<&String> = a.difference(d).collect();
                let not_real: Vec<&String> = d.difference(a).collect();
                let mut parts = Vec::new();
                if !undocumented.is_empty() {
                    parts.push(format!(
                        "depends on {undocumented:?}, not written in ARCHITECTURE.md"
                    ));
                }
                if !not_real.is_empty() {
                    parts.push(format!("ARCHITECTURE.md writes {not_real:?}, not a dependency"));
                }
                lines.push(format!("{name}: {}", parts.join("; ")));
            }
            _ => {}
        }
    }
    lines.join("\n")
}

#[test]
fn architecture_md_states_the_crate_graph() {
    let actual = metadata_graph(&metadata());
    let documented = documented_graph(&read_text(&repo_root().join("ARCHITECTURE.md")));
    let difference = graph_difference(&actual, &documented);
    assert!(
        difference.is_empty(),
        "ARCHITECTURE.md's crate graph differs from cargo metadata's:\n{difference}"
    );
}

#[test]
fn every_crate_has_a_readme() {
    let meta = metadata();
    let missing: Vec<String> = packages(&meta)
        .iter()
        .filter_map(|p| p["manifest_path"].as_str())
        .filter_map(|manifest| Path::new(manifest).parent().map(Path::to_path_buf))
        .filter(|dir| !dir.join("README.md").is_file())
        .map(|dir| dir.display().to_string())
        .collect();
    assert!(missing.is_empty(), "crates without a README.md: {missing:?}");
}

/// Folders never scanned: git's, build outputs, and the git-ignored ones.
const SKIPPED_DIRS: [&str; 7] = [
    ".git",
    "target",
    "out",
    "node_modules",
    "fuzz/target",
    "fuzz/corpus",
    "fuzz/artifacts",
];

/// Extensions of the text files scanned (everything under `scripts/` and `.ci/` too).
const TEXT_EXTENSIONS: [&str; 11] = [
    "md", "rs", "wgsl", "toml", "sh", "py", "mjs", "h", "c", "txt", "html",
];

/// The built page and generated reports are not written by hand; the built wasm and
/// its bindings are machine output.
const SKIPPED_FILES: [&str; 2] = ["web/dist", "docs/eval"];

fn text_files(root: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let entries =
            std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        for entry in entries {
            let path = entry
                .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
                .path();
            let rel = relative(root, &path);
            if SKIPPED_DIRS
                .iter()
                .any(|s| rel == *s || rel.ends_with(&format!("/{s}")))
                || SKIPPED_FILES.iter().any(|s| rel == *s)
            {
                continue;
            }
            if path.is_dir() {
                stack.push(path);
            } else {
                let in_script_dir = rel.starts_with("scripts/") || rel.starts_with(".ci/");
                let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
                if in_script_dir || TEXT_EXTENSIONS.contains(&ext) {
                    files.push(path);
                }
            }
        }
    }
    files.sort();
    files
}

fn relative(root: &Path, path: &Path) -> String {
    path.strip_prefix(root)
        .unwrap_or(path)
        .to_string_lossy()
        .replace('\\', "/")
}

fn is_path_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '/' | '.' | '_' | '-')
}

/// Relative paths in `line` that begin with `../` and, resolved from `dir` (the
/// file's folder, relative to the repository root), climb above the root.
fn escaping_paths(line: &str, dir: &[&str]) -> Vec<String> {
    let mut found = Vec::new();
    let mut start = 0;
    while let Some(offset) = line[start..].find("../") {
        let at = start + offset;
        start = at + 3;
        if line[..at].chars().next_back().is_some_and(is_path_char) {
            continue;
        }
        let token: String = line[at..].chars().take_while(|&c| is_path_char(c)).collect();
        start = at + token.len().max(3);
        let mut depth = dir.len();
        let escapes = token.split('/').any(|part| match part {
            ".." if depth == 0 => true,
            ".." => {
                depth -= 1;
                false
            }
            "" | "." => false,
            _ => {
                depth += 1;
                false
            }
        });
        if escapes {
            found.push(token);
        }
    }
    found
}

#[test]
fn no_file_points_outside_the_repository() {
    let root = repo_root();
    // Spelt in pieces so that this file does not name them itself.
    let forbidden = [
        ["..", "/shared"].concat(),
        ["shared", "/DESIGN"].concat(),
        ["shared", "/PLATFORM"].concat(),
        ["/work", "/"].concat(),
        // The team's design document: not in the repository (docs/CONVENTIONS.md is).
        ["DESIGN", ".md"].concat(),
    ];
    let mut problems = Vec::new();
    for path in text_files(&root) {
        let Ok(text) = std::fs::read_to_string(&path) else {
            continue;
        };
        let rel = relative(&root, &path);
        let dir: Vec<&str> = rel.split('/').collect();
        let dir = &dir[..dir.len() - 1];
        for (number, line) in text.lines().enumerate() {
            for needle in &forbidden {
                if line.contains(needle.as_str()) {
                    problems.push(format!("{rel}:{}: names {needle:?}", number + 1));
                }
            }
            for token in escaping_paths(line, dir) {
                problems.push(format!("{rel}:{}: {token:?} leaves the repository", number + 1));
            }
        }
    }
    assert!(
        problems.is_empty(),
        "{} reference(s) outside the repository:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

// ---- File-level import circles (scripts/import_cycles.py) ----

type Module = Vec<String>;

/// The module a source file defines: its path under `src/` without the extension,
/// `mod.rs`, `lib.rs` and `main.rs` standing for their folder.
fn module_of(src: &Path, path: &Path) -> Module {
    let rel = path.strip_prefix(src).unwrap_or(path).with_extension("");
    let mut parts: Module = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if parts
        .last()
        .is_some_and(|l| matches!(l.as_str(), "mod" | "lib" | "main"))
    {
        parts.pop();
    }
    parts
}

fn is_word_char(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Byte offsets where `crate` or `super` starts a word, with the keyword.
fn keywords(text: &str) -> impl Iterator<Item = (usize, &'static str)> + '_ {
    text.char_indices().filter_map(move |(at, _)| {
        let kind = ["crate", "super"]
            .into_iter()
            .find(|k| text[at..].starts_with(k))?;
        let boundary = !text[..at].chars().next_back().is_some_and(is_word_char);
        boundary.then_some((at, kind))
    })
}

/// `crate::a::b` / `super::a` paths, as (kind, segments) and the byte offset they end
/// at: the regular expression `\b(crate|super)((?:::[A-Za-z_][A-Za-z0-9_]*)+)`.
fn path_at(text: &str, at: usize, kind: &'static str) -> Option<(Vec<String>, usize)> {
    let mut end = at + kind.len();
    let mut parts = Vec::new();
    while text[end..].starts_with("::") {
        let ident_start = end + 2;
        let ident_len = text[ident_start..]
            .bytes()
            .enumerate()
            .take_while(|&(i, b)| b == b'_' || b.is_ascii_alphabetic() || (i > 0 && b.is_ascii_digit()))
            .count();
        if ident_len == 0 {
            break;
        }
        parts.push(text[ident_start..ident_start + ident_len].to_string());
        end = ident_start + ident_len;
    }
    (!parts.is_empty()).then_some((parts, end))
}

/// The module paths `text` names, as (kind, segments), found as the Python script's two
/// regular expressions find them, each scanning the whole text for non-overlapping
/// matches: `crate::a::b` / `super::a` paths, and the items of `crate::{a::b, c}`
/// groups (`\b(crate|super)::\{([^}]*)\}`) other than `self`.
fn module_references(text: &str) -> Vec<(&'static str, Vec<String>)> {
    let mut refs = Vec::new();
    let mut next_free = 0;
    for (at, kind) in keywords(text) {
        if at < next_free {
            continue;
        }
        if let Some((parts, end)) = path_at(text, at, kind) {
            refs.push((kind, parts));
            next_free = end;
        }
    }
    next_free = 0;
    for (at, kind) in keywords(text) {
        let open = at + kind.len();
        if at < next_free || !text[open..].starts_with("::{") {
            continue;
        }
        let Some(close) = text[open + 3..].find('}') else {
            continue;
        };
        for item in text[open + 3..open + 3 + close].split(',') {
            let item = item.trim();
            let first = item.split("::").next().unwrap_or("").trim();
            if !first.is_empty() && first != "self" {
                refs.push((kind, item.split("::").map(|p| p.trim().to_string()).collect()));
            }
        }
        next_free = open + 3 + close + 1;
    }
    refs
}

/// The modules (files) `module` imports, its ancestors left out.
fn imported_modules(module: &Module, text: &str, modules: &HashMap<Module, PathBuf>) -> BTreeSet<Module> {
    let mut found = BTreeSet::new();
    for (kind, parts) in module_references(text) {
        let mut full: Module = if kind == "crate" {
            Vec::new()
        } else {
            module[..module.len().saturating_sub(1)].to_vec()
        };
        full.extend(parts);
        for n in (1..=full.len()).rev() {
            let prefix = &full[..n];
            if modules.contains_key(prefix) {
                let is_ancestor_or_self = module.len() >= n && module[..n] == *prefix;
                if !is_ancestor_or_self {
                    found.insert(prefix.to_vec());
                }
                break;
            }
        }
    }
    found
}

/// Tarjan's strongly connected components of `graph`.
fn strongly_connected(graph: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    struct State<'a> {
        graph: &'a BTreeMap<Module, BTreeSet<Module>>,
        index: HashMap<&'a Module, usize>,
        low: HashMap<&'a Module, usize>,
        stack: Vec<&'a Module>,
        on_stack: BTreeSet<&'a Module>,
        components: Vec<Vec<Module>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a Module) {
        let next = s.index.len();
        s.index.insert(v, next);
        s.low.insert(v, next);
        s.stack.push(v);
        s.on_stack.insert(v);
        let graph = s.graph;
        for w in graph.get(v).into_iter().flatten() {
            if !s.index.contains_key(w) {
                visit(s, w);
                let low = s.low[v].min(s.low[w]);
                s.low.insert(v, low);
            } else if s.on_stack.contains(w) {
                let low = s.low[v].min(s.index[w]);
                s.low.insert(v, low);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                component.push(w.clone());
                if w == v {
                    break;
                }
            }
            s.components.push(component);
        }
    }
    let mut state = State {
        graph,
        index: HashMap::new(),
        low: HashMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        components: Vec::new(),
    };
    for v in graph.keys() {
        if !state.index.contains_key(v) {
            visit(&mut state, v);
        }
    }
    state.components
}

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let entries =
            std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        for entry in entries {
            let path = entry
                .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
                .path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Every file-level import circle of every crate, one line each:
/// `crate: a.rs <-> b.rs` (paths from the repository root, sorted).
fn import_circles(root: &Path) -> Vec<String> {
    let mut crate_dirs: Vec<(String, PathBuf)> = Vec::new();
    let entries = std::fs::read_dir(root).unwrap_or_else(|e| panic!("cannot list {}: {e}", root.display()));
    for entry in entries {
        let dir = entry
            .unwrap_or_else(|e| panic!("cannot list the root: {e}"))
            .path();
        if dir.join("Cargo.toml").is_file() && dir.join("src").is_dir() {
            let name = dir
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
            crate_dirs.push((name, dir.join("src")));
        }
    }
    crate_dirs.sort();
    crate_dirs.push(("nelf".to_string(), root.join("src")));

    let mut circles = Vec::new();
    for (name, src) in crate_dirs {
        let files: HashMap<Module, PathBuf> = rust_files(&src)
            .into_iter()
            .map(|p| (module_of(&src, &p), p))
            .collect();
        let mut graph = BTreeMap::new();
        for (module, path) in &files {
            let text: String = read_text(path)
                .lines()
                .map(|line| line.find("//").map_or(line, |at| &line[..at]))
                .collect::<Vec<_>>()
                .join("\n");
            // Tests inside a file (`#[cfg(test)] mod tests`) use their parent freely.
            let production = text.split("#[cfg(test)]").next().unwrap_or("");
            graph.insert(module.clone(), imported_modules(module, production, &files));
        }
        for component in strongly_connected(&graph) {
            if component.len() > 1 {
                let mut paths: Vec<String> = component.iter().map(|m| relative(root, &files[m])).collect();
                paths.sort();
                circles.push(format!("{name}: {}", paths.join(" <-> ")));
            }
        }
    }
    circles
}

#[test]
fn no_crate_has_a_file_level_import_circle() {
    let circles = import_circles(&repo_root());
    assert!(
        circles.is_empty(),
        "{} file-level import circle(s) (a child module using its parent's items while the \
         parent uses the child: put the shared items in a leaf module both use):\n{}",
        circles.len(),
        circles.join("\n")
    );
}

/// The normal dependencies (direct and indirect, on this host) of workspace crate
/// `package`, by name, as `cargo tree` resolves them from the lock file.
fn resolved_dependencies(package: &str) -> BTreeSet<String> {
    let manifest = repo_root().join("Cargo.toml");
    let out = Command::new(env!("CARGO"))
        .args([
            "tree",
            "--offline",
            "--edges",
            "normal",
            "--prefix",
            "none",
            "--format",
            "{p}",
            "--package",
            package,
            "--manifest-path",
        ])
        .arg(&manifest)
        .output()
        .unwrap_or_else(|e| panic!("cannot run cargo tree: {e}"));
    assert!(
        out.status.success(),
        "cargo tree failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|line| line.split_whitespace().next())
        .map(str::to_string)
        .collect()
}

/// ARCHITECTURE.md's promises about heavy dependencies: the baker and the exporters
/// never pull in the GPU stack or the network's tensor library, and the viewer never
/// pulls in the tensor library, the baker or the ground-truth crate.
#[test]
fn crates_stay_free_of_the_dependencies_architecture_md_rules_out() {
    let rules: [(&str, &[&str]); 3] = [
        ("nelf-bake", &["candle-core", "nelf-field", "wgpu"]),
        ("nelf-export", &["candle-core", "nelf-field", "wgpu"]),
        (
            "nelf-viewer",
            &["candle-core", "nelf-bake", "nelf-field", "nelf-scene"],
        ),
    ];
    let architecture = read_text(&repo_root().join("ARCHITECTURE.md"));
    for (crate_name, forbidden) in rules {
        assert!(
            architecture.contains(&format!("`{crate_name}`")),
            "ARCHITECTURE.md no longer names `{crate_name}`: update this test with it"
        );
        let found = resolved_dependencies(crate_name);
        assert!(
            found.contains(crate_name),
            "cargo tree listed nothing for {crate_name}: {found:?}"
        );
        let broken: Vec<_> = forbidden.iter().filter(|f| found.contains(**f)).collect();
        assert!(broken.is_empty(), "{crate_name} depends on {broken:?}");
    }
}
