//! The code's shape, as two resolved issues promised it, checked so that a later change that
//! undoes it fails here rather than in a reviewer's grep:
//! - effects are plug-ins (#11): a catalogue effect lives in its own file, so its name appears in
//!   at most 3 source files under `crates/*/src` (its own file, the registry, and one user);
//! - the CLI is thin (#13): a command file parses flags, calls the libraries and prints, so no
//!   file under `crates/servo-cli/src/cmd/` is longer than 400 lines;
//! - servo-core's modules form layers (#32): no import cycle between its top-level modules (the
//!   effects' fit hooks, the one plug-in seam, apart), and no two sibling source files of any
//!   crate import each other;
//! - a real-time test runs alone (stop 44's CI): every test outside tests/e2e/serial.rs holds
//!   the machine shared from its first statement (`servo_e2e::shared`), so a QEMU board test
//!   never runs beside one.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file under `dir`, recursively, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let entries = fs::read_dir(&d).unwrap_or_else(|e| panic!("reading {}: {e}", d.display()));
        for entry in entries {
            let path = entry
                .unwrap_or_else(|e| panic!("reading {}: {e}", d.display()))
                .path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The source files of every crate: `crates/*/src/**.rs`.
fn crate_sources() -> Vec<PathBuf> {
    let crates = workspace().join("crates");
    let mut out = Vec::new();
    for entry in fs::read_dir(&crates).expect("crates/ lists") {
        let src = entry.expect("crates/ entry").path().join("src");
        if src.is_dir() {
            out.extend(rust_files(&src));
        }
    }
    assert!(
        out.len() > 20,
        "found only {} source files under {}",
        out.len(),
        crates.display()
    );
    out
}

#[test]
fn each_catalogue_effect_name_appears_in_at_most_three_source_files() {
    let _machine = servo_e2e::shared();
    let sources: Vec<(PathBuf, String)> = crate_sources()
        .into_iter()
        .map(|p| {
            let text = fs::read_to_string(&p)
                .unwrap_or_else(|e| panic!("reading {}: {e}", p.display()))
                .to_lowercase();
            (p, text)
        })
        .collect();
    let mut failures = Vec::new();
    for word in ["imbalance", "cogging", "backlash", "stribeck", "deadzone"] {
        let files: Vec<String> = sources
            .iter()
            .filter(|(_, text)| text.contains(word))
            .map(|(p, _)| {
                p.strip_prefix(workspace())
                    .unwrap_or(p)
                    .display()
                    .to_string()
            })
            .collect();
        // Its own file at least: a name found nowhere means the scan is broken.
        assert!(!files.is_empty(), "`{word}` appears in no source file");
        if files.len() > 3 {
            failures.push(format!(
                "`{word}` in {} files: {}",
                files.len(),
                files.join(", ")
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "a catalogue effect's name should appear in at most 3 source files (its own file, the \
         registry, one user); name effects through the registry instead:\n{}",
        failures.join("\n")
    );
}

#[test]
fn no_command_file_is_longer_than_400_lines() {
    let _machine = servo_e2e::shared();
    let cmd = workspace().join("crates/servo-cli/src/cmd");
    let files = rust_files(&cmd);
    assert!(
        files.len() > 5,
        "found only {} files under {}",
        files.len(),
        cmd.display()
    );
    let long: Vec<String> = files
        .iter()
        .filter_map(|p| {
            let lines = fs::read_to_string(p).ok()?.lines().count();
            (lines > 400).then(|| format!("{} ({lines} lines)", p.display()))
        })
        .collect();
    assert!(
        long.is_empty(),
        "a command file parses flags, calls the libraries and prints; move computations into \
         servo-core/servo-io/servo-hw:\n{}",
        long.join("\n")
    );
}

/// `src` with its comments (line, block, doc) and the contents of its string literals blanked
/// to spaces, newlines kept: what is left is code (a path in a message or a doc is no import).
fn strip_comments(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                let end = b[i..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .map_or(b.len(), |k| i + k);
                blank(&mut out, i, end);
                i = end;
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let (mut depth, mut j) = (1, i + 2);
                while j < b.len() && depth > 0 {
                    if b[j] == b'/' && b.get(j + 1) == Some(&b'*') {
                        depth += 1;
                        j += 2;
                    } else if b[j] == b'*' && b.get(j + 1) == Some(&b'/') {
                        depth -= 1;
                        j += 2;
                    } else {
                        j += 1;
                    }
                }
                blank(&mut out, i, j);
                i = j;
            }
            b'r' if (b.get(i + 1) == Some(&b'"') || b.get(i + 1) == Some(&b'#'))
                && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_')) =>
            {
                // A raw string r"..." or r#"..."#.
                let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
                if b.get(i + 1 + hashes) != Some(&b'"') {
                    i += 1;
                    continue;
                }
                let close: Vec<u8> = std::iter::once(b'"')
                    .chain(std::iter::repeat_n(b'#', hashes))
                    .collect();
                let from = i + 2 + hashes;
                let end = b[from..]
                    .windows(close.len())
                    .position(|w| w == close.as_slice())
                    .map_or(b.len(), |k| from + k);
                blank(&mut out, from, end);
                i = (end + close.len()).min(b.len());
            }
            b'"' => {
                let mut j = i + 1;
                while j < b.len() && b[j] != b'"' {
                    j += if b[j] == b'\\' { 2 } else { 1 };
                }
                let end = j.min(b.len());
                blank(&mut out, i + 1, end);
                i = j + 1;
            }
            b'\'' => {
                // A character literal ('x', '\n', '\''); otherwise a lifetime.
                if b.get(i + 1) == Some(&b'\\') {
                    let end = b[i + 2..].iter().position(|&c| c == b'\'');
                    i = end.map_or(b.len(), |k| i + 2 + k + 1);
                } else if b.get(i + 2) == Some(&b'\'') {
                    i += 3;
                } else {
                    i += 1;
                }
            }
            _ => i += 1,
        }
    }
    String::from_utf8(out).unwrap_or_default()
}

/// The end (exclusive) of the block whose `{` is the first one at or after `from`, or of the
/// item when a `;` comes first.
fn item_end(text: &str, from: usize) -> usize {
    let b = text.as_bytes();
    let mut i = from;
    while i < b.len() && b[i] != b'{' && b[i] != b';' {
        i += 1;
    }
    if i >= b.len() || b[i] == b';' {
        return (i + 1).min(b.len());
    }
    let mut depth = 0usize;
    while i < b.len() {
        match b[i] {
            b'{' => depth += 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
        i += 1;
    }
    b.len()
}

/// Splits comment-free `text` into (the code outside, the code inside) the items that start
/// where `starts` matches (at the beginning of the item's first line) and end at their block's
/// closing brace.
fn split_items(text: &str, starts: &[&str]) -> (String, String) {
    let mut outside = text.to_string();
    let mut inside = String::new();
    for pat in starts {
        let mut from = 0;
        while let Some(k) = outside[from..].find(pat) {
            let at = from + k;
            let end = item_end(&outside, at);
            inside.push_str(&outside[at..end]);
            inside.push('\n');
            let blanked: String = outside[at..end]
                .chars()
                .map(|c| if c == '\n' { '\n' } else { ' ' })
                .collect();
            outside.replace_range(at..end, &blanked);
            from = end;
        }
    }
    (outside, inside)
}

/// Comment-free code of a source file without its `#[cfg(test)]` items (unit tests may use any
/// module as a fixture: the layers are the library's), and the names of the test modules it
/// declares in files of their own (`#[cfg(test)] mod tests;`).
fn library_code(src: &str) -> (String, Vec<String>) {
    let mut text = strip_comments(src);
    let mut test_files = Vec::new();
    while let Some(at) = text.find("#[cfg(test)]") {
        let after = at + "#[cfg(test)]".len();
        let end = item_end(&text, after);
        let item = text[after..end].trim();
        if let Some(name) = item
            .strip_prefix("mod ")
            .and_then(|r| r.strip_suffix(';'))
            .map(str::trim)
        {
            test_files.push(name.to_string());
        }
        let blanked: String = text[at..end]
            .chars()
            .map(|c| if c == '\n' { '\n' } else { ' ' })
            .collect();
        text.replace_range(at..end, &blanked);
    }
    (text, test_files)
}

/// The first path segment after each `crate::` in `code` (each member of a `crate::{a, b::c}`
/// group), with its line number.
fn crate_paths(code: &str) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    for (at, _) in code.match_indices("crate::") {
        // Not `$crate::` nor the tail of another identifier (`servo_crate::`).
        if at > 0 {
            let p = code.as_bytes()[at - 1];
            if p.is_ascii_alphanumeric() || p == b'_' || p == b'$' {
                continue;
            }
        }
        let line = code[..at].matches('\n').count() + 1;
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let (mut depth, mut member) = (0usize, String::new());
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        out.push((ident(&member), line));
                        member.clear();
                        continue;
                    }
                    _ => {}
                }
                if depth == 0 {
                    member.push(c);
                }
            }
            out.push((ident(&member), line));
        } else {
            out.push((ident(rest), line));
        }
    }
    out.retain(|(m, _)| !m.is_empty());
    out
}

/// An edge of the module graph: the module imported, and where (file:line) one import is.
type Graph = BTreeMap<String, BTreeMap<String, String>>;

/// The node of the effects' fit hooks (the plug-in seam, see
/// [`servo_core_modules_form_layers`]).
const HOOKS: &str = "effects (fit hooks)";

/// servo-core's top-level modules and what each imports of the others (`crate::<module>`
/// paths in library code), from the sources. The effects' fit hooks (the `FitHooks` trait, its
/// implementations and the `mod fit` of an effect file) form a node of their own.
fn core_module_graph() -> Graph {
    let src = workspace().join("crates/servo-core/src");
    let mut modules = BTreeSet::new();
    for entry in fs::read_dir(&src).expect("servo-core/src lists") {
        let path = entry.expect("servo-core/src entry").path();
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        if stem != "lib" && (path.is_dir() || path.extension().is_some_and(|x| x == "rs")) {
            modules.insert(stem.to_string());
        }
    }
    let mut graph = Graph::new();
    for module in &modules {
        graph.entry(module.clone()).or_default();
        let mut files = Vec::new();
        let file = src.join(format!("{module}.rs"));
        if file.is_file() {
            files.push(file);
        }
        if src.join(module).is_dir() {
            files.extend(rust_files(&src.join(module)));
        }
        // Test modules in files of their own, declared `#[cfg(test)] mod name;`.
        let mut test_files = BTreeSet::new();
        let mut code = Vec::new();
        for f in &files {
            let text =
                fs::read_to_string(f).unwrap_or_else(|e| panic!("reading {}: {e}", f.display()));
            let (lib, tests) = library_code(&text);
            // The folder of the file's child modules: its own for `mod.rs`, `x/` for `x.rs`.
            let dir = if f.file_name().is_some_and(|n| n == "mod.rs") {
                f.parent().map_or_else(|| src.clone(), Path::to_path_buf)
            } else {
                f.with_extension("")
            };
            for t in tests {
                test_files.insert(dir.join(format!("{t}.rs")));
                test_files.insert(dir.join(&t).join("mod.rs"));
            }
            code.push((f.clone(), lib));
        }
        for (f, lib) in code {
            if test_files.contains(&f) {
                continue;
            }
            let (own, hooks) = if module == "effects" {
                split_items(
                    &lib,
                    &[
                        "pub trait FitHooks",
                        "impl FitHooks for",
                        "impl super::FitHooks for",
                        "impl crate::effects::FitHooks for",
                        "mod fit {",
                    ],
                )
            } else {
                (lib, String::new())
            };
            let rel = f.strip_prefix(&src).unwrap_or(&f).display().to_string();
            for (node, text) in [(module.as_str(), own), (HOOKS, hooks)] {
                for (to, line) in crate_paths(&text) {
                    if modules.contains(&to) && to != *module {
                        graph
                            .entry(node.to_string())
                            .or_default()
                            .entry(to)
                            .or_insert_with(|| format!("{rel}:{line}"));
                    }
                }
            }
        }
    }
    graph
}

/// A cycle of `graph` as its nodes (the first repeated at the end), if there is one.
fn find_cycle(graph: &Graph) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        graph: &Graph,
        done: &mut BTreeSet<String>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        if let Some(k) = path.iter().position(|p| p == n) {
            let mut cycle = path[k..].to_vec();
            cycle.push(n.to_string());
            return Some(cycle);
        }
        if done.contains(n) {
            return None;
        }
        path.push(n.to_string());
        for to in graph.get(n).into_iter().flat_map(|e| e.keys()) {
            if let Some(c) = visit(to, graph, done, path) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(n.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|n| visit(n, graph, &mut done, &mut Vec::new()))
}

/// A cycle as "a -> b (where) -> c (where) -> a (where)".
fn describe(graph: &Graph, cycle: &[String]) -> String {
    let mut s = cycle[0].clone();
    for w in cycle.windows(2) {
        let at = graph
            .get(&w[0])
            .and_then(|e| e.get(&w[1]))
            .map_or("?", String::as_str);
        s.push_str(&format!(" -> {} ({at})", w[1]));
    }
    s
}

#[test]
fn the_cycle_finder_finds_a_cycle_and_only_a_cycle() {
    let _machine = servo_e2e::shared();
    let mut g = Graph::new();
    for (a, b) in [("a", "b"), ("b", "c"), ("a", "c"), ("d", "a")] {
        g.entry(a.into())
            .or_default()
            .insert(b.into(), format!("{a}.rs:1"));
    }
    assert_eq!(find_cycle(&g), None, "a DAG has no cycle");
    g.entry("c".into())
        .or_default()
        .insert("d".into(), "c.rs:7".into());
    let cycle = find_cycle(&g).expect("c -> d closes a cycle");
    assert_eq!(cycle.first(), cycle.last());
    assert_eq!(cycle.len(), 5, "{cycle:?}");
    assert!(
        describe(&g, &cycle).contains("-> d (c.rs:7)"),
        "{}",
        describe(&g, &cycle)
    );
    // The parser: groups, nested groups, `$crate::` and comments.
    let code = strip_comments(
        "use crate::{fit::{Dataset, oe}, plant::Plant};\n// crate::sim\nlet q = \"crate::x // y\"; let c = '\"'; $crate::math::ln; crate::signal::derivative(x); /* crate::z */",
    );
    let found: Vec<String> = crate_paths(&code).into_iter().map(|(m, _)| m).collect();
    assert_eq!(found, ["fit", "plant", "signal"]);
    let (lib, tests) = library_code(
        "use crate::a;\n#[cfg(test)]\nmod tests {\n use crate::b;\n}\n#[cfg(test)]\nmod more;\n",
    );
    assert_eq!(tests, ["more"]);
    assert!(
        lib.contains("crate::a") && !lib.contains("crate::b"),
        "{lib}"
    );
}

/// servo-core's modules form layers (#32): signal, params, math (and the thread helpers `par`)
/// at the bottom, then plant and effects, then sim and fit, the verdict types of a candidate,
/// compare and diagnose, then design and frf, and at the top `trend` (the statistics of a
/// parameter over many logs, on the identification's Student t). What the effects need of a diagnosis lives in
/// `verdict`, the thread helpers in `par`, the encoder quantum in `signal`.
///
/// One seam is allowed through the layers, and only one: an effect's fit hooks (the
/// [`FitHooks`] trait, its implementations and an effect file's `mod fit`) see the fit's data
/// and the model they refine, because one file per effect holds both its physics and its fit
/// (#11). They form a node of their own here, importing what they need; nothing imports them
/// but through the registry's trait objects. Outside those blocks an effect file imports no layer
/// above it, and no effect, hook or fit imports `diagnose`.
///
/// [`FitHooks`]: servo_core::effects::FitHooks
#[test]
fn servo_core_modules_form_layers() {
    let _machine = servo_e2e::shared();
    let graph = core_module_graph();
    let edges: usize = graph.values().map(BTreeMap::len).sum();
    assert!(
        graph.len() >= 18 && edges >= 40,
        "the module scan found only {} modules and {edges} imports: is it broken?",
        graph.len()
    );
    for (module, uses) in [
        ("sim", "effects"),
        ("fit", "effects"),
        ("diagnose", "fit"),
        ("compare", "sim"),
    ] {
        assert!(
            graph.get(module).is_some_and(|e| e.contains_key(uses)),
            "the scan misses `{module}` importing `{uses}`: {:?}",
            graph.get(module)
        );
    }
    assert!(
        graph.get(HOOKS).is_some_and(|e| e.contains_key("fit")),
        "the scan misses the effects' fit hooks importing `fit`: {:?}",
        graph.get(HOOKS)
    );
    if let Some(cycle) = find_cycle(&graph) {
        panic!(
            "an import cycle between servo-core's top-level modules (module -> module it \
             imports (where)): {}\nmove what the lower module needs below both (see verdict.rs, \
             par.rs), or import the other way round",
            describe(&graph, &cycle)
        );
    }
    for module in ["effects", HOOKS, "fit", "sim", "plant"] {
        if let Some(at) = graph.get(module).and_then(|e| e.get("diagnose")) {
            panic!("`{module}` imports `diagnose` ({at}): the lower layers never reach into the diagnosis");
        }
    }
}

/// Two sibling source files of a crate (children of one module: `a.rs` and `b.rs` in one
/// folder) that import each other (`super::b` / `crate::<module>::b`) are one thing in two
/// files: the circles servo-cli `cmd/identify` <-> `cmd/identify_ramp`, servo-core
/// `control/reference` <-> `control/reference_parse` and servo-hw `backend` <-> `serial` were
/// untied (#32); this keeps every crate free of them. (servo-core's top-level modules are
/// checked, through their whole folders, by [`servo_core_modules_form_layers`].)
#[test]
fn no_two_sibling_source_files_import_each_other() {
    let _machine = servo_e2e::shared();
    let crates = workspace().join("crates");
    let mut circles = Vec::new();
    let mut pairs_seen = 0usize;
    for entry in fs::read_dir(&crates).expect("crates/ lists") {
        let src = entry.expect("crates/ entry").path().join("src");
        if !src.is_dir() {
            continue;
        }
        let top = src.clone();
        let core = src.ends_with("servo-core/src");
        let mut dirs = vec![src];
        while let Some(dir) = dirs.pop() {
            // The module path of the folder's children, from the crate root.
            let module: Vec<String> = dir
                .strip_prefix(&top)
                .unwrap_or(&dir)
                .iter()
                .map(|s| s.to_string_lossy().into_owned())
                .collect();
            // servo-core's top-level modules: checked through their whole folders by
            // servo_core_modules_form_layers, with the effects' fit-hook seam.
            if core && dir == top {
                for e in fs::read_dir(&dir).expect("a source folder lists") {
                    let p = e.expect("a source folder entry").path();
                    if p.is_dir() {
                        dirs.push(p);
                    }
                }
                continue;
            }
            let mut kids: BTreeMap<String, PathBuf> = BTreeMap::new();
            for e in fs::read_dir(&dir).expect("a source folder lists") {
                let p = e.expect("a source folder entry").path();
                if p.is_dir() {
                    dirs.push(p.clone());
                    continue;
                }
                let stem = p
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or("")
                    .to_string();
                if p.extension().is_some_and(|x| x == "rs")
                    && !["mod", "lib", "main"].contains(&stem.as_str())
                {
                    kids.insert(stem, p);
                }
            }
            let mut uses: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
            for (name, path) in &kids {
                let text = fs::read_to_string(path)
                    .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
                let (code, _) = library_code(&text);
                let prefix = format!(
                    "crate::{}",
                    module.iter().map(|m| format!("{m}::")).collect::<String>()
                );
                for other in kids.keys().filter(|o| *o != name) {
                    let named = |head: &str| {
                        code.match_indices(head).any(|(at, _)| {
                            let rest = &code[at + head.len()..];
                            let word = |r: &str| {
                                r.starts_with(other.as_str())
                                    && !r[other.len()..].starts_with(|c: char| {
                                        c.is_ascii_alphanumeric() || c == '_'
                                    })
                            };
                            word(rest)
                                || rest.strip_prefix('{').is_some_and(|g| {
                                    g.split('}')
                                        .next()
                                        .unwrap_or("")
                                        .split(',')
                                        .any(|m| word(m.trim()))
                                })
                        })
                    };
                    if named("super::") || named(&prefix) {
                        uses.entry(name.as_str())
                            .or_default()
                            .insert(other.as_str());
                    }
                }
            }
            for (a, bs) in &uses {
                for b in bs {
                    pairs_seen += 1;
                    if a < b && uses.get(b).is_some_and(|x| x.contains(a)) {
                        let rel = dir
                            .strip_prefix(&crates)
                            .unwrap_or(&dir)
                            .display()
                            .to_string();
                        circles.push(format!("{rel}: {a}.rs <-> {b}.rs"));
                    }
                }
            }
        }
    }
    assert!(
        pairs_seen > 20,
        "found only {pairs_seen} imports between sibling files: is the scan broken?"
    );
    assert!(
        circles.is_empty(),
        "sibling source files importing each other (move what both need into one of them, or \
         below both):\n{}",
        circles.join("\n")
    );
}

/// The first statement of every `#[test]` function of `src`: `(line number, function line,
/// first statement)`, the statement trimmed (empty when the body is empty).
fn test_first_statements(src: &str) -> Vec<(usize, String, String)> {
    let lines: Vec<&str> = src.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim() != "#[test]" {
            i += 1;
            continue;
        }
        let mut j = i + 1;
        while j < lines.len() && !lines[j].trim_start().starts_with("fn ") {
            j += 1;
        }
        let mut open = j;
        while open < lines.len() && !lines[open].trim_end().ends_with('{') {
            open += 1;
        }
        let first = lines.get(open + 1).map_or("", |l| l.trim()).to_string();
        out.push((
            j + 1,
            lines.get(j).map_or("", |l| l.trim()).to_string(),
            first,
        ));
        i = open + 1;
    }
    out
}

#[test]
fn every_test_but_the_real_time_ones_holds_the_machine_shared_first() {
    let _machine = servo_e2e::shared();
    const HOLD: &str = "let _machine = servo_e2e::shared();";
    // The checker finds a test that does not hold the machine and only such a test.
    let sample = "#[test]\nfn a() {\n    let _machine = servo_e2e::shared();\n}\n\
                  #[test]\n#[ignore]\nfn b(\n    x: u8,\n) {\n    let x = 1;\n}\n";
    let found = test_first_statements(sample);
    assert_eq!(found.len(), 2, "{found:?}");
    assert_eq!(found[0].2, HOLD);
    assert_eq!((found[1].0, found[1].2.as_str()), (7, "let x = 1;"));

    let dir = workspace().join("tests/e2e");
    let mut tests = 0;
    let mut bare = Vec::new();
    for path in rust_files(&dir) {
        if path.file_name().is_some_and(|n| n == "serial.rs") {
            continue; // real-time: each holds the machine alone (servo_e2e::realtime)
        }
        let src = fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        for (line, func, first) in test_first_statements(&src) {
            tests += 1;
            if first != HOLD {
                bare.push(format!(
                    "{}:{line}: {func} starts with `{first}`",
                    path.display()
                ));
            }
        }
    }
    assert!(
        tests > 150,
        "found only {tests} tests under {}",
        dir.display()
    );
    assert!(
        bare.is_empty(),
        "these tests do not start with `{HOLD}` (a QEMU board test could run beside them and miss \
         its deadlines):\n{}",
        bare.join("\n")
    );
}
