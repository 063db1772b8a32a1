//! The crate's layout keeps what `src/lib.rs` promises: the command line (`src/bin/`) is a shell
//! over the library, and the library is a set of rooms without a cycle between them.
//!
//! * the library (every file under `src/` outside `src/bin/`) never uses clap: no `use clap`,
//!   no `clap::` path, no clap derive (`Parser`, `Args`, `Subcommand`, `ValueEnum`) and no clap
//!   attribute (`#[arg(`, `#[command(`, `#[value(`);
//! * the library never refers to the command line: no type the bin defines is named in it, and
//!   no `#[path]`, `include!` or `mod bin` reaches into `src/bin/`;
//! * the graph of references between the library's top-level modules (`crate::gap::...`, also
//!   grouped `crate::{gap, sim}` and `super::` chains that climb to the crate root) has no
//!   cycle. The test prints the graph and, on failure, the cycle.
//!
//! The check reads the text, comments included: a doc link is a reference too. It is this
//! project's tool for import cycles; run it alone with `cargo test -p host-tests --test
//! layout -- --nocapture` to see the graph.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every `.rs` file under `dir`, sorted.
fn rs_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// (path relative to `src/`, text) of every library file: all of `src/` but `src/bin/`.
fn library_files() -> Vec<(PathBuf, String)> {
    let src = src_dir();
    rs_files(&src)
        .into_iter()
        .map(|p| {
            let rel = p.strip_prefix(&src).unwrap().to_path_buf();
            let text = std::fs::read_to_string(&p).unwrap();
            (rel, text)
        })
        .filter(|(rel, _)| !rel.starts_with("bin"))
        .collect()
}

/// The module path of a library file: `gap/select.rs` -> `[gap, select]`, `gap/mod.rs` ->
/// `[gap]`, `util.rs` -> `[util]`, `lib.rs` -> `[]`.
fn module_path(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|l| l == "mod" || l == "lib") {
        parts.pop();
    }
    parts
}

fn is_ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The identifier starting at byte `at` of `s` (empty if none).
fn ident_at(s: &str, at: usize) -> &str {
    let rest = &s[at..];
    let end = rest.find(|c: char| !is_ident_char(c)).unwrap_or(rest.len());
    &rest[..end]
}

/// Every identifier of `text`, as a set of words.
fn words(text: &str) -> BTreeSet<&str> {
    text.split(|c: char| !is_ident_char(c))
        .filter(|w| !w.is_empty())
        .collect()
}

/// The first-level names of a `{...}` group starting at byte `open` (the `{`) of `s`.
fn group_names(s: &str, open: usize) -> Vec<&str> {
    let mut names = Vec::new();
    let mut depth = 0;
    let mut expect = true;
    let mut i = open;
    while i < s.len() {
        let c = s[i..].chars().next().unwrap_or(' ');
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            ',' if depth == 1 => expect = true,
            c if depth == 1 && expect && is_ident_char(c) => {
                let w = ident_at(s, i);
                names.push(w);
                expect = false;
                i += w.len();
                continue;
            }
            _ => {}
        }
        i += c.len_utf8();
    }
    names
}

/// The crate-root names `text` (of the module at `path`) refers to: `crate::NAME`,
/// `crate::{A, B::..}`, and `super::...::NAME` where the `super`s climb to the crate root.
fn root_refs<'a>(text: &'a str, path: &[String]) -> BTreeSet<&'a str> {
    let mut out = BTreeSet::new();
    let mut push_after = |at: usize| {
        if text[at..].starts_with('{') {
            out.extend(group_names(text, at));
        } else {
            let w = ident_at(text, at);
            if !w.is_empty() {
                out.insert(w);
            }
        }
    };
    for (at, _) in text.match_indices("crate::") {
        // `host_tests::crate::` cannot occur; a preceding identifier char means another word
        // (`my_crate::`).
        if text[..at].chars().next_back().is_some_and(is_ident_char) {
            continue;
        }
        push_after(at + "crate::".len());
    }
    for (at, _) in text.match_indices("super::") {
        let before = &text[..at];
        if before.ends_with("::") || before.chars().next_back().is_some_and(is_ident_char) {
            continue; // inside a chain, counted from its start
        }
        let mut ups = 0;
        let mut end = at;
        while text[end..].starts_with("super::") {
            ups += 1;
            end += "super::".len();
        }
        // A file's own module is `path`; `super` names its parent.
        if ups == path.len() {
            push_after(end);
        }
    }
    out
}

/// The top-level modules `lib.rs` declares.
fn declared_modules(lib: &str) -> Vec<String> {
    lib.lines()
        .map(str::trim)
        .filter_map(|l| {
            l.strip_prefix("pub mod ")
                .or_else(|| l.strip_prefix("mod "))
                .and_then(|r| r.strip_suffix(';'))
                .map(str::to_string)
        })
        .collect()
}

/// The graph of references between the library's top-level modules.
fn module_graph() -> BTreeMap<String, BTreeSet<String>> {
    let files = library_files();
    let lib = &files
        .iter()
        .find(|(rel, _)| rel == Path::new("lib.rs"))
        .expect("src/lib.rs")
        .1;
    let modules = declared_modules(lib);
    let mut graph: BTreeMap<String, BTreeSet<String>> = modules
        .iter()
        .map(|m| (m.clone(), BTreeSet::new()))
        .collect();
    for (rel, text) in &files {
        let path = module_path(rel);
        let Some(top) = path.first() else { continue };
        assert!(
            modules.contains(top),
            "{} belongs to no module lib.rs declares ({modules:?})",
            rel.display()
        );
        for name in root_refs(text, &path) {
            if name != top && modules.iter().any(|m| m == name) {
                graph.get_mut(top).unwrap().insert(name.to_string());
            }
        }
    }
    graph
}

/// A cycle of `graph` as `[a, b, ..., a]`, if there is one (depth-first search).
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        Open,
        Done,
    }
    fn visit(
        n: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        mark: &mut BTreeMap<String, Mark>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        mark.insert(n.to_string(), Mark::Open);
        stack.push(n.to_string());
        for m in graph.get(n).into_iter().flatten() {
            match mark.get(m).copied().unwrap_or(Mark::New) {
                Mark::Open => {
                    let from = stack.iter().position(|s| s == m).unwrap();
                    let mut cycle = stack[from..].to_vec();
                    cycle.push(m.clone());
                    return Some(cycle);
                }
                Mark::New => {
                    if let Some(c) = visit(m, graph, mark, stack) {
                        return Some(c);
                    }
                }
                Mark::Done => {}
            }
        }
        stack.pop();
        mark.insert(n.to_string(), Mark::Done);
        None
    }
    let mut mark: BTreeMap<String, Mark> = graph.keys().map(|k| (k.clone(), Mark::New)).collect();
    for n in graph.keys() {
        if mark[n] == Mark::New
            && let Some(c) = visit(n, graph, &mut mark, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

#[test]
fn the_library_never_uses_clap() {
    const DERIVES: [&str; 4] = ["Parser", "Args", "Subcommand", "ValueEnum"];
    let mut found = Vec::new();
    for (rel, text) in library_files() {
        for (n, line) in text.lines().enumerate() {
            let l = line.trim();
            let mut why = None;
            if l.starts_with("use clap") || line.contains("clap::") {
                why = Some("clap path");
            }
            if ["#[arg(", "#[command(", "#[value("]
                .iter()
                .any(|a| l.starts_with(a))
            {
                why = Some("clap attribute");
            }
            if let Some(why) = why {
                found.push(format!("src/{}:{}: {why}: {l}", rel.display(), n + 1));
            }
        }
        // Derive lists, also those rustfmt spreads over several lines.
        for (at, _) in text.match_indices("#[derive(") {
            let list = &text[at + "#[derive(".len()..];
            let list = &list[..list.find(")]").unwrap_or(list.len())];
            let derives_clap = list
                .split(',')
                .map(|d| d.trim().rsplit("::").next().unwrap_or(""))
                .any(|d| DERIVES.contains(&d));
            if derives_clap {
                let line = text[..at].lines().count() + 1;
                found.push(format!(
                    "src/{}:{line}: clap derive: #[derive({})]",
                    rel.display(),
                    list.split_whitespace().collect::<Vec<_>>().join(" ")
                ));
            }
        }
    }
    println!(
        "{} library files read; clap found in {} lines",
        library_files().len(),
        found.len()
    );
    assert!(
        found.is_empty(),
        "the library uses clap (it belongs in src/bin/):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_library_never_refers_to_the_command_line() {
    // The types the bin defines (its argument structs, value enums, the verb enum).
    let bin = src_dir().join("bin");
    let mut bin_types = BTreeSet::new();
    for p in rs_files(&bin) {
        let text = std::fs::read_to_string(&p).unwrap();
        for l in text.lines() {
            let l = l.trim_start().trim_start_matches("pub ");
            for kw in ["struct ", "enum ", "trait ", "type "] {
                if let Some(rest) = l.strip_prefix(kw) {
                    let name = ident_at(rest, 0);
                    if !name.is_empty() {
                        bin_types.insert(name.to_string());
                    }
                }
            }
        }
    }
    println!("types the bin defines: {bin_types:?}");
    assert!(!bin_types.is_empty(), "no types found in src/bin/");
    let mut found = Vec::new();
    for (rel, text) in library_files() {
        let w = words(&text);
        for t in &bin_types {
            if w.contains(t.as_str()) {
                found.push(format!("src/{} names the bin's type `{t}`", rel.display()));
            }
        }
        for (n, line) in text.lines().enumerate() {
            let l = line.trim();
            let reaches_bin = (l.starts_with("#[path") || l.contains("include!("))
                && l.contains("bin/")
                || l.contains("crate::bin")
                || l == "mod bin;"
                || l == "pub mod bin;";
            if reaches_bin {
                found.push(format!("src/{}:{}: {l}", rel.display(), n + 1));
            }
        }
    }
    assert!(
        found.is_empty(),
        "the library refers to the command line:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_library_modules_import_each_other_without_a_cycle() {
    let graph = module_graph();
    println!("references between the library's top-level modules:");
    for (m, to) in &graph {
        let to: Vec<&str> = to.iter().map(String::as_str).collect();
        println!(
            "  {m:<9} -> {}",
            if to.is_empty() {
                "(none)".to_string()
            } else {
                to.join(", ")
            }
        );
    }
    if let Some(cycle) = find_cycle(&graph) {
        panic!("import cycle: {}", cycle.join(" -> "));
    }
    println!("no cycle");
}

#[test]
fn the_cycle_finder_finds_a_cycle_and_the_parser_reads_groups_and_supers() {
    let g = |edges: &[(&str, &str)]| {
        let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in edges {
            g.entry(a.to_string()).or_default().insert(b.to_string());
            g.entry(b.to_string()).or_default();
        }
        g
    };
    assert_eq!(find_cycle(&g(&[("a", "b"), ("b", "c"), ("a", "c")])), None);
    let c = find_cycle(&g(&[("a", "b"), ("b", "c"), ("c", "a"), ("d", "a")])).unwrap();
    println!("cycle found: {}", c.join(" -> "));
    assert_eq!(c.first(), c.last());
    assert_eq!(c.len(), 4);
    let path = ["gap".to_string(), "select".to_string()];
    let text = "use crate::{io::csv::Record, sim};\nuse super::super::util::median;\n\
                use super::data::Data;\nfn f() { crate::oracle::lag::RefLag::new(); }";
    let refs: Vec<&str> = root_refs(text, &path).into_iter().collect();
    assert_eq!(refs, ["io", "oracle", "sim", "util"]);
}
