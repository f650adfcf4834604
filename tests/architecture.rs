//! The house rules of `docs/ARCHITECTURE.md`, checked on the source text: no import circle between
//! files, no import from a lower layer to a higher one (between the top-level modules, and between
//! the stages of `pipeline`), and no file of the project over 600 lines without its reason written
//! at its top.
//!
//! An *import* is any path through `crate::…` (a `use` or an inline path), `super::…` or
//! `self::…` in a file's code outside its `#[cfg(test)]` tests, resolved to the file of the
//! longest module prefix it names. A module's `mod.rs` declaring and re-exporting its own children
//! (`pub mod x; pub use x::Y;`) is its table of contents, not an import; a child using its parent
//! is.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Module path (`["pipeline", "input", "frames"]`) → file.
type Modules = BTreeMap<Vec<String>, PathBuf>;
/// Module → the modules it imports.
type Graph = BTreeMap<Vec<String>, BTreeSet<Vec<String>>>;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

fn modules() -> Modules {
    let src = root().join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut m = Modules::new();
    for f in files {
        let rel = f.strip_prefix(&src).unwrap().with_extension("");
        let mut path: Vec<String> = rel.iter().map(|s| s.to_string_lossy().into_owned()).collect();
        if path == ["main"] {
            continue;
        }
        if path.last().is_some_and(|l| l == "mod" || l == "lib") {
            path.pop();
        }
        m.insert(path, f);
    }
    m
}

/// The code of a file without comments and without its `#[cfg(test)]` module.
fn code(text: &str) -> String {
    let tests = ["#[cfg(test)]\nmod tests", "#[cfg(test)]\npub(crate) mod tests"];
    let text = match tests.iter().filter_map(|t| text.find(t)).min() {
        Some(i) => &text[..i],
        None => text,
    };
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let line = match line.find("//") {
            // A `//` inside a string literal ("http://") is rare in this code base; the paths
            // after it are then missed, never invented.
            Some(i) => &line[..i],
            None => line,
        };
        out.push_str(line);
        out.push('\n');
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Splits `a, b::{c, d}, e` at its top-level commas.
fn split_top(s: &str) -> Vec<&str> {
    let (mut parts, mut depth, mut start) = (Vec::new(), 0i32, 0);
    for (i, c) in s.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(s[start..i].trim());
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(s[start..].trim());
    parts.into_iter().filter(|p| !p.is_empty()).collect()
}

/// The paths a `use` tree names: `a::{b, c::d}` → `a::b`, `a::c::d`.
fn expand(tree: &str) -> Vec<Vec<String>> {
    let tree = tree.split(" as ").next().unwrap().trim();
    if let Some(open) = tree.find('{') {
        let prefix: Vec<String> = tree[..open].split("::").filter(|s| !s.is_empty()).map(str::to_string).collect();
        let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
        return split_top(inner)
            .into_iter()
            .flat_map(expand)
            .map(|rest| prefix.iter().cloned().chain(rest).collect())
            .collect();
    }
    vec![tree.split("::").map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect()]
}

/// Every path in `code` that starts with `anchor::` (`crate`, `super` or `self`), with the anchor
/// dropped; `use anchor::{…}` trees expanded.
fn anchored_paths(code: &str, anchor: &str) -> Vec<Vec<String>> {
    let pat = format!("{anchor}::");
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(i) = code[from..].find(&pat) {
        let at = from + i;
        from = at + pat.len();
        if code[..at].chars().next_back().is_some_and(|c| is_ident(c) || c == ':') {
            continue; // part of a longer path (`x::super::`) or a name (`my_crate::`)
        }
        let rest = &code[from..];
        // The path: identifiers and `::`, then maybe a `{…}` group.
        let mut end = 0;
        let bytes: Vec<char> = rest.chars().collect();
        while end < bytes.len() && (is_ident(bytes[end]) || bytes[end] == ':') {
            end += 1;
        }
        let head: String = bytes[..end].iter().collect();
        if end < bytes.len() && bytes[end] == '{' && head.ends_with("::") || head.is_empty() && rest.starts_with('{') {
            let mut depth = 0;
            let mut close = end;
            for (k, c) in bytes.iter().enumerate().skip(end) {
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            close = k;
                            break;
                        }
                    }
                    _ => {}
                }
            }
            let tree: String = bytes[..=close].iter().collect();
            out.extend(expand(&tree));
        } else {
            out.push(head.split("::").filter(|s| !s.is_empty()).map(str::to_string).collect());
        }
    }
    out
}

/// The module of the longest prefix of `path` that is one.
fn resolve(mods: &Modules, path: &[String]) -> Option<Vec<String>> {
    (1..=path.len()).rev().map(|k| path[..k].to_vec()).find(|p| mods.contains_key(p))
}

fn graph(mods: &Modules) -> Graph {
    let mut g = Graph::new();
    for (m, file) in mods {
        let text = code(&std::fs::read_to_string(file).unwrap());
        let is_dir_module = file.file_name().is_some_and(|n| n == "mod.rs" || n == "lib.rs");
        // `self::` and `super::` are relative to the module (a `mod.rs` is its folder's module).
        let parent: Vec<String> = m[..m.len().saturating_sub(1)].to_vec();
        let mut targets = BTreeSet::new();
        let mut add = |p: Vec<String>| {
            if let Some(t) = resolve(mods, &p) {
                // A directory module naming its own children: its table of contents.
                let own_child = is_dir_module && t.len() > m.len() && t.starts_with(m);
                if &t != m && !own_child && !t.is_empty() {
                    targets.insert(t);
                }
            }
        };
        for p in anchored_paths(&text, "crate") {
            add(p);
        }
        for p in anchored_paths(&text, "super") {
            let mut base = parent.clone();
            let mut p = p;
            while p.first().is_some_and(|s| s == "super") {
                base.pop();
                p.remove(0);
            }
            add(base.into_iter().chain(p).collect());
        }
        for p in anchored_paths(&text, "self") {
            add(m.iter().cloned().chain(p).collect());
        }
        g.insert(m.clone(), targets);
    }
    g
}

/// Strongly connected components of more than one module (Tarjan).
fn circles(g: &Graph) -> Vec<Vec<Vec<String>>> {
    struct T<'a> {
        g: &'a Graph,
        index: BTreeMap<&'a Vec<String>, usize>,
        low: BTreeMap<&'a Vec<String>, usize>,
        stack: Vec<&'a Vec<String>>,
        on: BTreeSet<&'a Vec<String>>,
        out: Vec<Vec<Vec<String>>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a Vec<String>) {
        let i = t.index.len();
        t.index.insert(v, i);
        t.low.insert(v, i);
        t.stack.push(v);
        t.on.insert(v);
        for w in t.g.get(v).into_iter().flatten() {
            let Some((w, _)) = t.g.get_key_value(w) else { continue };
            if !t.index.contains_key(w) {
                visit(t, w);
                let lw = t.low[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if t.on.contains(w) {
                let iw = t.index[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on.remove(w);
                comp.push(w.clone());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.out.push(comp);
            }
        }
    }
    let mut t = T { g, index: BTreeMap::new(), low: BTreeMap::new(), stack: vec![], on: BTreeSet::new(), out: vec![] };
    for v in g.keys() {
        if !t.index.contains_key(v) {
            visit(&mut t, v);
        }
    }
    t.out
}

fn name(m: &[String]) -> String {
    if m.is_empty() {
        "crate".into()
    } else {
        m.join("::")
    }
}

/// The layers of `docs/ARCHITECTURE.md`: a module may import its own top-level module and those of
/// lower layers only. Modules of one layer are peers and import none of each other.
const LAYERS: &[(&str, u32)] = &[
    ("model", 0),
    ("io", 1),
    ("kinematics", 2),
    ("solve", 3),
    ("pipeline", 4),
    ("archive", 5),
    ("body", 6),
    ("retarget", 6),
    ("render", 7),
    ("eval", 7),
    ("cli", 8),
];

/// The stages inside `pipeline`, in the same sense.
const STAGES: &[(&str, u32)] =
    &[("context", 0), ("stats", 0), ("input", 1), ("calibration", 2), ("running", 3), ("results", 4), ("session", 5)];

fn rank(table: &[(&str, u32)], name: &str) -> Option<u32> {
    table.iter().find(|(n, _)| *n == name).map(|&(_, r)| r)
}

#[test]
fn no_import_circle_between_files() {
    let g = graph(&modules());
    let found = circles(&g);
    let mut text = String::new();
    for c in &found {
        let members: BTreeSet<&Vec<String>> = c.iter().collect();
        text.push_str(&format!("circle: {}\n", c.iter().map(|m| name(m)).collect::<Vec<_>>().join(", ")));
        for a in c {
            for b in &g[a] {
                if members.contains(b) {
                    text.push_str(&format!("    {} -> {}\n", name(a), name(b)));
                }
            }
        }
    }
    assert!(found.is_empty(), "import circles between files (move what both sides need down):\n{text}");
}

#[test]
fn the_circle_check_sees_a_circle() {
    // The check itself: two files importing each other through `super::` and `crate::` paths.
    let text_a = "use super::b::Thing;\npub struct A;\n";
    let text_b = "use crate::x::{a::A, c};\n";
    let dir = std::env::temp_dir().join(format!("smocap-arch-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (fa, fb, fc) = (dir.join("a.rs"), dir.join("b.rs"), dir.join("c.rs"));
    std::fs::write(&fa, text_a).unwrap();
    std::fs::write(&fb, text_b).unwrap();
    std::fs::write(&fc, "").unwrap();
    let mut mods = Modules::new();
    let p = |s: &[&str]| s.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    mods.insert(p(&["x", "a"]), fa);
    mods.insert(p(&["x", "b"]), fb);
    mods.insert(p(&["x", "c"]), fc);
    let g = graph(&mods);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(circles(&g), vec![vec![p(&["x", "a"]), p(&["x", "b"])]]);
    assert!(g[&p(&["x", "b"])].contains(&p(&["x", "c"])));
}

#[test]
fn no_import_from_a_lower_layer_to_a_higher_one() {
    let mods = modules();
    let g = graph(&mods);
    let mut bad = Vec::new();
    for (a, targets) in &g {
        let Some(top_a) = a.first() else { continue };
        for b in targets {
            let Some(top_b) = b.first() else { continue };
            if top_a != top_b {
                let (ra, rb) = (rank(LAYERS, top_a), rank(LAYERS, top_b));
                match (ra, rb) {
                    (Some(ra), Some(rb)) if rb < ra => {}
                    (Some(_), Some(_)) => bad.push(format!("{} -> {}", name(a), name(b))),
                    _ => bad.push(format!("{} -> {}: a top-level module missing from LAYERS", name(a), name(b))),
                }
            } else if top_a == "pipeline" && a.len() > 1 && b.len() > 1 && a[1] != b[1] {
                match (rank(STAGES, &a[1]), rank(STAGES, &b[1])) {
                    (Some(ra), Some(rb)) if rb < ra => {}
                    (Some(_), Some(_)) => bad.push(format!("{} -> {}", name(a), name(b))),
                    _ => bad.push(format!("{} -> {}: a pipeline stage missing from STAGES", name(a), name(b))),
                }
            }
        }
    }
    assert!(bad.is_empty(), "imports against the layers of docs/ARCHITECTURE.md:\n{}", bad.join("\n"));
}

/// Files of the project a person reads: source, tests, benches, scripts, shaders.
fn project_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let skip = ["target", ".git", "node_modules", "fuzz/target"];
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    entries.sort();
    for p in entries {
        let n = p.file_name().unwrap().to_string_lossy().into_owned();
        if p.is_dir() {
            if !skip.contains(&n.as_str()) && !n.starts_with('.') {
                project_files(&p, out);
            }
        } else if ["rs", "py", "wgsl", "sh", "mjs", "pyi"].iter().any(|e| p.extension().is_some_and(|x| x == *e)) {
            out.push(p);
        }
    }
}

/// The first lines of a long file must say why it is long: a comment containing
/// `Over 600 lines:` followed by the reason.
#[test]
fn no_file_over_600_lines_without_its_reason() {
    let root = root();
    let mut files = Vec::new();
    for d in ["src", "tests", "benches", "python", "scripts", "shaders", "examples", "fuzz"] {
        if root.join(d).is_dir() {
            project_files(&root.join(d), &mut files);
        }
    }
    let mut bad = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap_or_default();
        let lines = text.lines().count();
        let head: String = text.lines().take(15).collect::<Vec<_>>().join("\n");
        if lines > 600 && !head.contains("Over 600 lines:") {
            bad.push(format!("{} ({lines} lines)", f.strip_prefix(&root).unwrap().display()));
        }
    }
    assert!(
        bad.is_empty(),
        "files over 600 lines with no `Over 600 lines: <reason>` at their top:\n{}",
        bad.join("\n")
    );
}
