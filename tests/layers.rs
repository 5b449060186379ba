//! The layers, checked on the crate graph and on the modules' own import lines.
//!
//! - Crates (`cargo metadata`): `kac-core` (the mathematics) ← `kac-engine` (analyses, jobs, stores, search) ←
//!   `kac` (HTTP and the CLI). Neither the core nor the engine reaches an HTTP crate through its normal
//!   dependencies, and the core does not depend on the engine.
//! - Modules: within each directory of each crate, the import graph among its child modules (a child directory
//!   counts as one module) has no circle of more than three modules. An edge is a path in a `use` line or in code
//!   (`crate::a::b`, `super::x`) that names a module outside the file's own subtree.
//! - Files: no source file has more than 800 lines before its tests.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

const HTTP_CRATES: &[&str] = &["axum", "axum-core", "hyper", "hyper-util", "tower", "tower-http", "http", "http-body"];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The packages a package reaches through normal (not dev, not build) dependencies, by name.
fn normal_closure(metadata: &serde_json::Value, package: &str) -> BTreeSet<String> {
    let packages = metadata["packages"].as_array().unwrap();
    let name_of: HashMap<&str, &str> =
        packages.iter().map(|p| (p["id"].as_str().unwrap(), p["name"].as_str().unwrap())).collect();
    let nodes = metadata["resolve"]["nodes"].as_array().unwrap();
    let deps: HashMap<&str, Vec<&str>> = nodes
        .iter()
        .map(|n| {
            let normal = n["deps"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|d| d["dep_kinds"].as_array().unwrap().iter().any(|k| k["kind"].is_null()))
                .map(|d| d["pkg"].as_str().unwrap())
                .collect();
            (n["id"].as_str().unwrap(), normal)
        })
        .collect();
    let start = packages.iter().find(|p| p["name"] == package).unwrap_or_else(|| panic!("no package {package}"));
    let mut seen = BTreeSet::new();
    let mut todo = vec![start["id"].as_str().unwrap()];
    while let Some(id) = todo.pop() {
        for d in deps.get(id).into_iter().flatten() {
            if seen.insert(name_of[d].to_string()) {
                todo.push(d);
            }
        }
    }
    seen
}

#[test]
fn neither_the_core_nor_the_engine_reaches_an_http_crate() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // This machine's platform only: what builds here (another platform's crates need not be downloaded).
    let rustc = Command::new(std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into())).arg("-vV").output().unwrap();
    let version = String::from_utf8_lossy(&rustc.stdout).to_string();
    let host = version.lines().find_map(|l| l.strip_prefix("host: ")).expect("rustc -vV names the host").trim();
    let out = Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--offline", "--filter-platform", host])
        .current_dir(root())
        .output()
        .expect("cargo metadata runs");
    assert!(out.status.success(), "cargo metadata: {}", String::from_utf8_lossy(&out.stderr));
    let metadata: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let kac = normal_closure(&metadata, "kac");
    assert!(kac.contains("axum") && kac.contains("kac-engine"), "the binary's closure: {kac:?}");
    for package in ["kac-core", "kac-engine"] {
        let closure = normal_closure(&metadata, package);
        let http: Vec<_> = HTTP_CRATES.iter().filter(|c| closure.contains(**c)).collect();
        assert!(http.is_empty(), "{package} reaches {http:?}");
    }
    assert!(!normal_closure(&metadata, "kac-core").contains("kac-engine"), "the core depends on the engine");
    assert!(normal_closure(&metadata, "kac-engine").contains("kac-core"));
}

/// A crate's module files: module path (`["jobs", "runner"]`) → text before its tests.
fn modules(src: &Path) -> BTreeMap<Vec<String>, String> {
    fn walk(dir: &Path, prefix: &[String], out: &mut BTreeMap<Vec<String>, String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            let stem = p.file_stem().unwrap().to_string_lossy().to_string();
            if p.is_dir() {
                let mut m = prefix.to_vec();
                m.push(stem);
                walk(&p, &m, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let mut m = prefix.to_vec();
                if !matches!(stem.as_str(), "mod" | "lib" | "main") {
                    m.push(stem);
                }
                // The code before its tests: a test may reach anywhere.
                let text = std::fs::read_to_string(&p).unwrap();
                let text = text.split("\n#[cfg(test)]").next().unwrap_or("").to_string();
                out.entry(m).and_modify(|t| t.push_str(&text)).or_insert(text);
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(src, &[], &mut out);
    out
}

/// The paths a file names: `crate::…` and `super::…` chains, with `{…}` groups of `use` lines expanded one level.
fn paths(text: &str) -> Vec<Vec<String>> {
    let code: String = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .map(|l| l.split(" // ").next().unwrap_or(l))
        .collect::<Vec<_>>()
        .join("\n");
    let bytes: Vec<char> = code.chars().collect();
    let mut out = vec![];
    let mut i = 0;
    while i < bytes.len() {
        let at_word = i == 0 || !(bytes[i - 1].is_alphanumeric() || bytes[i - 1] == '_' || bytes[i - 1] == ':');
        let rest: String = bytes[i..bytes.len().min(i + 7)].iter().collect();
        if at_word && (rest.starts_with("crate::") || rest.starts_with("super::")) {
            let mut j = i;
            let mut segs = vec![];
            loop {
                let s = j;
                while j < bytes.len() && (bytes[j].is_alphanumeric() || bytes[j] == '_') {
                    j += 1;
                }
                segs.push(bytes[s..j].iter().collect::<String>());
                if j + 1 < bytes.len() && bytes[j] == ':' && bytes[j + 1] == ':' {
                    j += 2;
                    if j < bytes.len() && bytes[j] == '{' {
                        // `a::{b, c::d}`: each member's first segment.
                        let end = bytes[j..].iter().position(|&c| c == '}').map_or(bytes.len(), |p| j + p);
                        let group: String = bytes[j + 1..end].iter().collect();
                        for member in group.split(',') {
                            let first = member.trim().split("::").next().unwrap_or("").trim().to_string();
                            if !first.is_empty() && first != "self" {
                                let mut p = segs.clone();
                                p.push(first);
                                out.push(p);
                            }
                        }
                        segs.clear();
                        j = end;
                        break;
                    }
                    continue;
                }
                break;
            }
            if !segs.is_empty() {
                out.push(segs);
            }
            i = j.max(i + 1);
        } else {
            i += 1;
        }
    }
    out
}

/// The module a path names, absolute: the longest prefix that is a module of the crate.
fn resolve(from: &[String], path: &[String], known: &BTreeSet<Vec<String>>) -> Option<Vec<String>> {
    let mut base: Vec<String> = from.to_vec();
    let mut rest = path;
    match rest.first().map(String::as_str) {
        Some("crate") => {
            base.clear();
            rest = &rest[1..];
        }
        Some("super") => {
            while rest.first().map(String::as_str) == Some("super") {
                base.pop()?;
                rest = &rest[1..];
            }
        }
        _ => return None,
    }
    let mut best = None;
    for n in 0..=rest.len() {
        let mut m = base.clone();
        m.extend(rest[..n].iter().cloned());
        if known.contains(&m) {
            best = Some(m);
        }
    }
    best
}

/// Strongly connected components (Tarjan) of a graph over `0..n`.
fn components(n: usize, edges: &[BTreeSet<usize>]) -> Vec<Vec<usize>> {
    struct T<'a> {
        edges: &'a [BTreeSet<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(t: &mut T<'_>, v: usize) {
        t.index[v] = Some(t.next);
        t.low[v] = t.next;
        t.next += 1;
        t.stack.push(v);
        t.on[v] = true;
        for &w in t.edges[v].clone().iter() {
            if t.index[w].is_none() {
                visit(t, w);
                t.low[v] = t.low[v].min(t.low[w]);
            } else if t.on[w] {
                t.low[v] = t.low[v].min(t.index[w].unwrap());
            }
        }
        if Some(t.low[v]) == t.index[v] {
            let mut c = vec![];
            while let Some(w) = t.stack.pop() {
                t.on[w] = false;
                c.push(w);
                if w == v {
                    break;
                }
            }
            t.out.push(c);
        }
    }
    let mut t =
        T { edges, index: vec![None; n], low: vec![0; n], on: vec![false; n], stack: vec![], next: 0, out: vec![] };
    for v in 0..n {
        if t.index[v].is_none() {
            visit(&mut t, v);
        }
    }
    t.out
}

/// One directory's child modules and the imports among them.
type Graph = (Vec<String>, BTreeSet<(String, String)>);

/// The circles of more than three modules among the children of each directory of a crate.
fn circles(src: &Path) -> Vec<Vec<String>> {
    let mods = modules(src);
    let known: BTreeSet<Vec<String>> = mods.keys().cloned().collect();
    // Per directory (a module path), its children and the edges among them.
    let mut graphs: BTreeMap<Vec<String>, Graph> = BTreeMap::new();
    for m in &known {
        if let Some((last, parent)) = m.split_last() {
            graphs.entry(parent.to_vec()).or_default().0.push(last.clone());
        }
    }
    for (from, text) in &mods {
        for p in paths(text) {
            let Some(to) = resolve(from, &p, &known) else { continue };
            let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
            if common < from.len() && common < to.len() {
                let g = graphs.entry(from[..common].to_vec()).or_default();
                g.1.insert((from[common].clone(), to[common].clone()));
            }
        }
    }
    let mut found = vec![];
    for (dir, (children, edges)) in graphs {
        let mut names: Vec<String> = children;
        for (a, b) in &edges {
            names.push(a.clone());
            names.push(b.clone());
        }
        names.sort();
        names.dedup();
        let at = |s: &String| names.iter().position(|n| n == s).unwrap();
        let mut adj = vec![BTreeSet::new(); names.len()];
        for (a, b) in &edges {
            adj[at(a)].insert(at(b));
        }
        for c in components(names.len(), &adj) {
            if c.len() > 3 {
                let mut c: Vec<String> = c.iter().map(|&i| format!("{}::{}", dir.join("::"), names[i])).collect();
                c.sort();
                found.push(c);
            }
        }
    }
    found
}

const CRATES: &[&str] = &["src", "crates/kac-core/src", "crates/kac-engine/src"];

#[test]
fn no_import_circle_of_more_than_three_modules() {
    for src in CRATES {
        let found = circles(&root().join(src));
        assert!(found.is_empty(), "{src}: import circles of more than three modules: {found:#?}");
    }
}

/// The check itself finds a circle where there is one: four modules importing each other in a ring.
#[test]
fn the_circle_check_finds_a_ring() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path();
    std::fs::write(src.join("lib.rs"), "mod a; mod b; mod c; mod d;").unwrap();
    for (m, next) in [("a", "b"), ("b", "c"), ("c", "d"), ("d", "a")] {
        std::fs::create_dir_all(src.join(m)).unwrap();
        std::fs::write(src.join(m).join("mod.rs"), format!("use crate::{next}::{{X, Y}};\n")).unwrap();
    }
    assert_eq!(circles(src).len(), 1);
    std::fs::write(src.join("d").join("mod.rs"), "use super::c::Z;\n").unwrap();
    assert!(circles(src).is_empty());
}

#[test]
fn no_source_file_has_more_than_800_lines_before_its_tests() {
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
    let mut files = vec![];
    for src in CRATES {
        walk(&root().join(src), &mut files);
    }
    let mut long = vec![];
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        // A file that is a module of tests (`tests.rs`) is all tests.
        if f.file_stem().is_some_and(|s| s == "tests") {
            continue;
        }
        let before = text.lines().take_while(|l| !l.starts_with("#[cfg(test)]")).count();
        if before > 800 {
            long.push(format!("{} ({before})", f.strip_prefix(root()).unwrap().display()));
        }
    }
    assert!(long.is_empty(), "files with more than 800 lines before their tests: {long:?}");
}

#[test]
fn the_core_names_no_code_of_the_service() {
    // The core's errors are its own; the engine maps them to codes once (`kac_engine::code`).
    fn walk(dir: &Path, out: &mut Vec<(PathBuf, String)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push((p.clone(), std::fs::read_to_string(&p).unwrap()));
            }
        }
    }
    let mut files = vec![];
    walk(&root().join("crates/kac-core/src"), &mut files);
    for (path, text) in files {
        for code in ["\"output-too-large\"", "\"k-too-large\"", "\"queue-full\"", "\"internal-error\""] {
            assert!(!text.contains(code), "{} names the service's code {code}", path.display());
        }
    }
}
