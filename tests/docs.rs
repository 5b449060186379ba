//! The README and the pages under docs/ stay readable and true to the binary: prose lines fit in 120 characters
//! (fenced code blocks and table rows aside), relative links reach files and headings that exist, every `kac`
//! subcommand has a heading in docs/cli.md and each of its long flags is named there, and every path of the
//! committed OpenAPI document is named in docs/service.md.

use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const MAX_PROSE_CHARS: usize = 120;

/// README.md and every Markdown page under docs/, as (path relative to the root, text).
fn pages() -> Vec<(String, String)> {
    let root = Path::new(ROOT);
    let mut paths: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/ exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    paths.sort();
    paths.insert(0, root.join("README.md"));
    paths
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p.strip_prefix(root).unwrap().display().to_string(), text)
        })
        .collect()
}

/// The lines outside fenced code blocks, with their 1-based numbers.
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut fenced = false;
    let mut out = vec![];
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            out.push((i + 1, line));
        }
    }
    out
}

/// The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a page's headings.
fn anchors(text: &str) -> Vec<String> {
    prose_lines(text)
        .into_iter()
        .filter(|(_, l)| l.starts_with('#'))
        .map(|(_, l)| slug(l.trim_start_matches('#')))
        .collect()
}

/// Whether `text` names `word` as a whole token: `--k` is not named by `--keep-degenerate`, nor `/v1/jobs` by
/// `/v1/jobs/{id}`.
fn names(text: &str, word: &str) -> bool {
    let part = |c: char| c.is_alphanumeric() || matches!(c, '-' | '_' | '/' | '{');
    text.match_indices(word).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + word.len()..].chars().next();
        !before.is_some_and(|c| c.is_alphanumeric() || c == '-') && !after.is_some_and(part)
    })
}

#[test]
fn prose_lines_fit_in_120_characters() {
    let mut long = vec![];
    for (page, text) in pages() {
        for (n, line) in prose_lines(&text) {
            let chars = line.chars().count();
            if chars > MAX_PROSE_CHARS && !line.trim_start().starts_with('|') {
                long.push(format!("{page}:{n}: {chars} characters: {}…", line.chars().take(60).collect::<String>()));
            }
        }
    }
    assert!(
        long.is_empty(),
        "prose lines over {MAX_PROSE_CHARS} characters (wrap them; a long heading becomes a short one with its \
         synopsis in a code block under it):\n{}",
        long.join("\n")
    );
}

#[test]
fn relative_links_reach_files_and_headings_that_exist() {
    let root = Path::new(ROOT);
    let mut broken = vec![];
    for (page, text) in pages() {
        let dir = root.join(&page).parent().unwrap().to_path_buf();
        for (n, line) in prose_lines(&text) {
            for (i, _) in line.match_indices("](") {
                let rest = &line[i + 2..];
                let Some(end) = rest.find(')') else { continue };
                let target = &rest[..end];
                if target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                let (file, anchor) = target.split_once('#').unwrap_or((target, ""));
                let path = if file.is_empty() { root.join(&page) } else { dir.join(file) };
                if !path.exists() {
                    broken.push(format!("{page}:{n}: {target}: no file {}", path.display()));
                    continue;
                }
                if !anchor.is_empty() && path.extension().is_some_and(|x| x == "md") {
                    let linked = std::fs::read_to_string(&path).unwrap();
                    if !anchors(&linked).iter().any(|a| a == anchor) {
                        broken.push(format!("{page}:{n}: {target}: no heading with the anchor #{anchor}"));
                    }
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken relative links:\n{}", broken.join("\n"));
}

/// `kac ARGS --help`, as text.
fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_kac")).args(args).arg("--help").output().unwrap();
    assert!(out.status.success(), "kac {} --help failed", args.join(" "));
    String::from_utf8(out.stdout).unwrap()
}

/// The names under a help text's `Commands:` heading.
fn subcommands() -> Vec<String> {
    let top = help(&[]);
    let list = top.split("Commands:").nth(1).expect("kac --help lists its commands");
    let list = list.split("\n\n").next().unwrap();
    list.lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_string)
        .collect()
}

/// The long flags a subcommand's help defines (the option lines, not flags its descriptions mention).
fn long_flags(sub: &str) -> Vec<String> {
    help(&[sub])
        .lines()
        .filter(|l| {
            let indent = l.len() - l.trim_start().len();
            (1..=6).contains(&indent) && l.trim_start().starts_with('-')
        })
        .filter_map(|l| l.split_whitespace().find(|w| w.starts_with("--")))
        .map(|w| w.trim_end_matches(',').to_string())
        .filter(|f| f != "--help" && f != "--version")
        .collect()
}

#[test]
fn every_subcommand_and_flag_is_in_the_cli_reference() {
    let cli = std::fs::read_to_string(Path::new(ROOT).join("docs/cli.md")).unwrap();
    let headings: Vec<String> = prose_lines(&cli)
        .into_iter()
        .filter(|(_, l)| l.starts_with('#'))
        .map(|(_, l)| l.trim_start_matches('#').replace('`', "").trim().to_string())
        .collect();
    let subs = subcommands();
    assert!(subs.len() > 20, "kac --help listed only {subs:?}");
    let mut missing = vec![];
    for sub in &subs {
        let title = format!("kac {sub}");
        if !headings.iter().any(|h| h == &title || h.starts_with(&format!("{title} "))) {
            missing.push(format!("no heading `{title}`"));
        }
        let flags = long_flags(sub);
        for flag in flags {
            if !names(&cli, &flag) {
                missing.push(format!("`kac {sub} {flag}` is not named"));
            }
        }
    }
    assert!(missing.is_empty(), "docs/cli.md is missing (read src/cli/ and document them):\n{}", missing.join("\n"));
}

/// Every analysis of the registry is a `kac` subcommand (hand-written, or derived from its request), is in the
/// README's table and has a request schema in the OpenAPI document: the places an analysis follows from.
#[test]
fn every_analysis_of_the_registry_is_everywhere_it_follows_to() {
    let out = Command::new(env!("CARGO_BIN_EXE_kac")).arg("analyses").output().unwrap();
    let table: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let names: Vec<String> =
        table["analyses"].as_array().unwrap().iter().map(|a| a["name"].as_str().unwrap().to_string()).collect();
    assert!(names.len() > 20, "{names:?}");
    let subs = subcommands();
    let readme = std::fs::read_to_string(Path::new(ROOT).join("README.md")).unwrap();
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(Path::new(ROOT).join("openapi/openapi.json")).unwrap()).unwrap();
    let mut missing = vec![];
    for n in &names {
        if !subs.contains(n) {
            missing.push(format!("{n}: no `kac {n}` subcommand"));
        }
        if !readme.contains(&format!("| `{n}` |")) {
            missing.push(format!("{n}: no row in the README's table (`kac analyses --markdown`)"));
        }
        let camel: String = n.split('-').map(|w| w[..1].to_uppercase() + &w[1..]).collect();
        if doc.pointer(&format!("/components/schemas/{camel}Analysis")).is_none() {
            missing.push(format!("{n}: no schema {camel}Analysis in openapi/openapi.json"));
        }
    }
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

#[test]
fn every_openapi_path_is_in_the_service_reference() {
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(Path::new(ROOT).join("openapi/openapi.json")).unwrap()).unwrap();
    let service = std::fs::read_to_string(Path::new(ROOT).join("docs/service.md")).unwrap();
    let paths: Vec<&String> = doc["paths"].as_object().expect("the document has paths").keys().collect();
    assert!(!paths.is_empty());
    let missing: Vec<&&String> = paths.iter().filter(|p| !names(&service, p)).collect();
    assert!(
        missing.is_empty(),
        "paths of openapi/openapi.json that docs/service.md does not name (add them to its routes table): {missing:?}"
    );
}

#[test]
fn names_matches_whole_tokens_only() {
    assert!(names("`--k K` and `--keep`", "--k"));
    assert!(!names("`--keep-degenerate`", "--k"));
    assert!(!names("`--solver-method`", "--method"));
    assert!(names("`GET /v1/jobs` (`?status=`)", "/v1/jobs"));
    assert!(!names("`GET /v1/jobs/{id}`", "/v1/jobs"));
    assert!(names("`POST /v1/analyze?wait=S`", "/v1/analyze"));
    assert_eq!(slug("The pair (L, M)"), "the-pair-l-m");
    assert_eq!(slug(" `kac spectrum`"), "kac-spectrum");
}

/// Every warning code the code can raise (`Warning::new("code", …)` anywhere under src/ and crates/) has its row in
/// the README's warnings table, and the table names no code the code never raises.
#[test]
fn every_warning_code_is_in_the_readme_table() {
    fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                sources(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let root = Path::new(ROOT);
    let mut files = vec![];
    sources(&root.join("src"), &mut files);
    sources(&root.join("crates"), &mut files);
    let mut raised = std::collections::BTreeSet::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for (i, _) in text.match_indices("Warning::new(") {
            let rest = text[i + "Warning::new(".len()..].trim_start();
            if let Some(code) = rest.strip_prefix('"').and_then(|r| r.split('"').next()) {
                raised.insert(code.to_string());
            }
        }
    }
    assert!(raised.len() >= 10, "the scan finds the codes: {raised:?}");
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let table = readme.split("## Warnings").nth(1).and_then(|s| s.split("\n## ").next()).expect("a Warnings section");
    let listed: std::collections::BTreeSet<String> =
        table.lines().filter_map(|l| l.strip_prefix("| `")?.split('`').next().map(str::to_string)).collect();
    assert_eq!(raised, listed, "codes raised (left) against the README's warnings table (right)");
}
