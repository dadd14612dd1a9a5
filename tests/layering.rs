//! The layout is the architecture (DESIGN.md "Layout"): this guards its rules by reading the
//! crate's sources.
//! - No folder-level cycles: the top-level modules of `src/` (and the folders inside
//!   `src/rig/`) import each other along a DAG.
//! - The simulator is one backend among others: `twin`, `control`, `session`, `diagnose` and
//!   `rig::hw` never import `rig::sim` (nor `rig::device`, the emulator built on it).
//! - `config` is a leaf: it imports nothing of the crate.
//! - No file-level cycles inside a folder (two files of one folder importing each other).
//!
//! Imports are read from the source text: `crate::a::b` paths (in `use` trees, braces
//! expanded, and in expressions), `super::` paths resolved against the file's module, in code
//! and in doc links alike (a doc link is a dependency a reader follows too); line comments
//! are skipped.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A source file and its module path (`src/rig/hw/mod.rs` -> `["rig", "hw"]`).
struct Source {
    path: PathBuf,
    module: Vec<String>,
    text: String,
}

fn sources() -> Vec<Source> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    walk(&src, &mut files);
    files.sort();
    files
        .into_iter()
        .map(|path| {
            let rel = path.strip_prefix(&src).unwrap().with_extension("");
            let mut module: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if matches!(
                module.last().map(String::as_str),
                Some("mod" | "lib" | "main")
            ) {
                module.pop();
            }
            let text = std::fs::read_to_string(&path).unwrap();
            Source { path, module, text }
        })
        .collect()
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Expands the path or use tree starting at `s` (just after `crate::` or `super::`) into the
/// module paths it names (first segments only as far as they are identifiers).
fn expand(s: &str) -> Vec<Vec<String>> {
    fn tree(s: &[char], i: &mut usize) -> Vec<Vec<String>> {
        let mut prefix = Vec::new();
        loop {
            while *i < s.len() && s[*i].is_whitespace() {
                *i += 1;
            }
            if *i < s.len() && s[*i] == '{' {
                *i += 1;
                let mut out = Vec::new();
                loop {
                    while *i < s.len() && (s[*i].is_whitespace() || s[*i] == ',') {
                        *i += 1;
                    }
                    if *i >= s.len() || s[*i] == '}' {
                        *i += 1;
                        break;
                    }
                    let before = *i;
                    for mut p in tree(s, i) {
                        let mut full = prefix.clone();
                        full.append(&mut p);
                        out.push(full);
                    }
                    // Skip `as name` and anything else up to the next separator.
                    while *i < s.len() && s[*i] != ',' && s[*i] != '}' {
                        *i += 1;
                    }
                    if *i == before {
                        *i += 1;
                    }
                }
                return out;
            }
            let start = *i;
            while *i < s.len() && is_ident(s[*i]) {
                *i += 1;
            }
            if *i == start {
                return vec![prefix];
            }
            prefix.push(s[start..*i].iter().collect());
            if *i + 1 < s.len() && s[*i] == ':' && s[*i + 1] == ':' {
                *i += 2;
            } else {
                return vec![prefix];
            }
        }
    }
    let chars: Vec<char> = s.chars().take(4000).collect();
    let mut i = 0;
    tree(&chars, &mut i)
}

/// Every module path a file names, resolved to absolute paths from the crate root.
fn imports(src: &Source) -> BTreeSet<Vec<String>> {
    let mut out = BTreeSet::new();
    // The module `super` refers to: the parent of a file's module.
    let parent: Vec<String> = src.module[..src.module.len().saturating_sub(1)].to_vec();
    for (n, line) in src.text.lines().enumerate() {
        let code = line.trim_start();
        if code.starts_with("//") && !code.starts_with("///") && !code.starts_with("//!") {
            continue;
        }
        // The rest of the file from this line: use trees span lines.
        let rest: String = src
            .text
            .lines()
            .skip(n)
            .take(40)
            .collect::<Vec<_>>()
            .join("\n");
        let line_len = line.len();
        let mut from = 0;
        while let Some(pos) = rest[from..line_len.min(rest.len())].find("crate::") {
            let at = from + pos;
            let before = rest[..at].chars().last();
            if before.is_none_or(|c| !is_ident(c) && c != '$') {
                for p in expand(&rest[at + "crate::".len()..]) {
                    if !p.is_empty() {
                        out.insert(p);
                    }
                }
            }
            from = at + 1;
        }
        let mut from = 0;
        while let Some(pos) = rest[from..line_len.min(rest.len())].find("super::") {
            let at = from + pos;
            let before = rest[..at].chars().last();
            if before.is_none_or(|c| !is_ident(c) && c != ':') {
                // Count chained `super::super::`.
                let mut base = parent.clone();
                let mut k = at;
                while rest[k..].starts_with("super::") {
                    k += "super::".len();
                    if rest[k..].starts_with("super::") {
                        base.pop();
                    }
                }
                for p in expand(&rest[k..]) {
                    let mut full = base.clone();
                    full.extend(p);
                    if !full.is_empty() {
                        out.insert(full);
                    }
                }
            }
            from = at + 1;
        }
    }
    out
}

/// The layering unit of a module path: its top-level folder, or for `rig` the folder below
/// it (`rig::sim`, `rig::hw`, `rig::device`; `rig` for the trait and the shared types).
fn unit(module: &[String], folders: &BTreeSet<Vec<String>>) -> String {
    let Some(top) = module.first() else {
        return String::from("(root)");
    };
    if let Some(second) = module.get(1) {
        let sub = vec![top.clone(), second.clone()];
        if top == "rig" && folders.contains(&sub) {
            return format!("{top}::{second}");
        }
    }
    top.clone()
}

struct Graph {
    /// unit -> unit -> the files that make the edge.
    edges: BTreeMap<String, BTreeMap<String, BTreeSet<String>>>,
}

fn graph(srcs: &[Source]) -> Graph {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let folders: BTreeSet<Vec<String>> = srcs
        .iter()
        .filter(|s| s.path.file_name().is_some_and(|f| f == "mod.rs"))
        .map(|s| s.module.clone())
        .collect();
    let mut edges: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for s in srcs {
        if s.module.is_empty() {
            continue; // lib.rs / main.rs: the crate root declares every module
        }
        let from = unit(&s.module, &folders);
        for p in imports(s) {
            let to = unit(&p, &folders);
            if to != from && to != "(root)" {
                edges
                    .entry(from.clone())
                    .or_default()
                    .entry(to)
                    .or_default()
                    .insert(s.path.strip_prefix(&root).unwrap().display().to_string());
            }
        }
    }
    Graph { edges }
}

/// A cycle in `edges`, if any, as the list of its nodes.
fn find_cycle(edges: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(n.to_string(), 1);
        stack.push(n.to_string());
        for m in edges.get(n).into_iter().flatten() {
            match state.get(m.as_str()).copied().unwrap_or(0) {
                1 => {
                    let i = stack.iter().position(|x| x == m).unwrap();
                    let mut c = stack[i..].to_vec();
                    c.push(m.clone());
                    return Some(c);
                }
                0 => {
                    if let Some(c) = visit(m, edges, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(n.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in edges.keys() {
        if state.get(n.as_str()).copied().unwrap_or(0) == 0 {
            let mut stack = Vec::new();
            if let Some(c) = visit(n, edges, &mut state, &mut stack) {
                return Some(c);
            }
        }
    }
    None
}

#[test]
fn folders_import_each_other_along_a_dag() {
    let g = graph(&sources());
    let simple: BTreeMap<String, BTreeSet<String>> = g
        .edges
        .iter()
        .map(|(k, v)| (k.clone(), v.keys().cloned().collect()))
        .collect();
    if let Some(cycle) = find_cycle(&simple) {
        let why: Vec<String> = cycle
            .windows(2)
            .map(|w| format!("{} -> {}: {:?}", w[0], w[1], g.edges[&w[0]][&w[1]]))
            .collect();
        panic!(
            "folder-level import cycle {}:\n{}",
            cycle.join(" -> "),
            why.join("\n")
        );
    }
}

#[test]
fn only_the_simulated_backend_and_its_drivers_know_the_simulator() {
    let g = graph(&sources());
    let mut leaks = Vec::new();
    for from in ["twin", "control", "session", "diagnose", "rig::hw"] {
        for to in ["rig::sim", "rig::device"] {
            if let Some(files) = g.edges.get(from).and_then(|e| e.get(to)) {
                leaks.push(format!("{from} imports {to} in {files:?}"));
            }
        }
    }
    assert!(leaks.is_empty(), "{}", leaks.join("\n"));
}

#[test]
fn the_rig_description_is_a_leaf() {
    let g = graph(&sources());
    let deps = g.edges.get("config").cloned().unwrap_or_default();
    assert!(deps.is_empty(), "config imports {deps:?}");
}

#[test]
fn files_of_a_folder_import_each_other_along_a_dag() {
    let srcs = sources();
    // Per folder: file module -> sibling file modules it imports.
    let mut by_folder: BTreeMap<Vec<String>, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    let modules: BTreeSet<Vec<String>> = srcs.iter().map(|s| s.module.clone()).collect();
    for s in &srcs {
        let Some((_, folder)) = s.module.split_last() else {
            continue;
        };
        let entry = by_folder.entry(folder.to_vec()).or_default();
        let me = s.module.join("::");
        entry.entry(me.clone()).or_default();
        for p in imports(s) {
            // The sibling module (or the folder's own mod.rs) the path goes through.
            if p.len() > folder.len() && p[..folder.len()] == *folder {
                let sibling = p[..=folder.len()].to_vec();
                if modules.contains(&sibling) && sibling != s.module {
                    // A file inside a sub-folder counts as the sub-folder.
                    entry.get_mut(&me).unwrap().insert(sibling.join("::"));
                }
            }
        }
    }
    // Files deeper than the folder: fold them into their top sub-module.
    let mut cycles = Vec::new();
    for (folder, files) in &by_folder {
        let mut folded: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        let depth = folder.len() + 1;
        for (f, deps) in files {
            let key: Vec<&str> = f.split("::").take(depth).collect();
            let key = key.join("::");
            let e = folded.entry(key.clone()).or_default();
            for d in deps {
                if *d != key {
                    e.insert(d.clone());
                }
            }
        }
        if let Some(c) = find_cycle(&folded) {
            cycles.push(format!("{}: {}", folder.join("::"), c.join(" -> ")));
        }
    }
    assert!(
        cycles.is_empty(),
        "file-level import cycles:\n{}",
        cycles.join("\n")
    );
}

#[test]
fn the_import_reader_expands_use_trees() {
    let p = expand("rig::{sim::{A, b::C}, hw} ;");
    assert_eq!(
        p,
        vec![
            vec!["rig".to_string(), "sim".into(), "A".into()],
            vec!["rig".into(), "sim".into(), "b".into(), "C".into()],
            vec!["rig".into(), "hw".into()],
        ]
    );
    assert_eq!(
        expand("twin::Twin::new(x)"),
        vec![vec!["twin".to_string(), "Twin".into(), "new".into()]]
    );
}
