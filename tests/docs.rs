//! The documentation runs as written.
//!
//! README.md and every page of docs/guide/ are scanned for fenced code blocks. Blocks whose info
//! string is `sh run` are executed with `bash -euo pipefail`, every block of a page in order in
//! one scratch folder laid out like a checkout (`T/repo/` with links to the repository's files,
//! `T/shared` a link to the real `../shared`), with the directory of the `smocap` binary this
//! test was built with first on `PATH`: `smocap …` in the docs is the release binary. Plain
//! `sh` blocks are shown to readers, not run (users' own files, or minutes of work), but every
//! `smocap <command> --flag` they name must be a flag of that command. `python run` blocks are
//! run by `python/tests/test_docs.py`.
//!
//! docs/ARCHITECTURE.md, where it exists, names modules: every path it quotes below `src/`,
//! `shaders/`, `python/`, `scripts/`, `tests/` or `models/` must exist.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const REPO: &str = env!("CARGO_MANIFEST_DIR");

/// Top-level entries of the checkout that the scratch copy links to (outputs of the docs'
/// commands land beside them, never in the repository). `datasets.toml` is copied instead: its
/// relative paths resolve against its folder.
const LINKED: &[&str] = &[
    "models",
    "examples",
    "scripts",
    "docs",
    "proto",
    "shaders",
    "python",
    "src",
    "tests",
    "benches",
    "Cargo.toml",
    "Cargo.lock",
    "pyproject.toml",
    "README.md",
    "BENCHMARKS.md",
];
const COPIED: &[&str] = &["datasets.toml"];

/// One fenced code block: where it starts (1-based line of the opening fence), its info string
/// and its text.
struct Block {
    file: String,
    line: usize,
    info: String,
    text: String,
}

impl Block {
    fn is(&self, info: &str) -> bool {
        self.info.split_whitespace().eq(info.split_whitespace())
    }
}

/// The fenced blocks of a Markdown text (backtick fences; an unclosed block runs to the end).
fn blocks(file: &str, text: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut open: Option<(usize, String, usize, Vec<&str>)> = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        match &mut open {
            None => {
                if let Some(rest) = t.strip_prefix("```") {
                    let ticks = 3 + rest.chars().take_while(|&c| c == '`').count();
                    open = Some((i + 1, rest.trim_start_matches('`').trim().to_string(), ticks, Vec::new()));
                }
            }
            Some((start, info, ticks, body)) => {
                let n = t.chars().take_while(|&c| c == '`').count();
                if n >= *ticks && t[n..].trim().is_empty() {
                    out.push(Block {
                        file: file.to_string(),
                        line: *start,
                        info: info.clone(),
                        text: body.join("\n") + "\n",
                    });
                    open = None;
                } else {
                    body.push(line);
                }
            }
        }
    }
    if let Some((start, info, _, body)) = open {
        out.push(Block { file: file.to_string(), line: start, info, text: body.join("\n") + "\n" });
    }
    out
}

/// README.md, then docs/guide/*.md in name order, as (path relative to the repository, text).
fn pages() -> Vec<(String, String)> {
    let repo = Path::new(REPO);
    let mut names = vec!["README.md".to_string()];
    let mut guide: Vec<String> = std::fs::read_dir(repo.join("docs/guide"))
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".md"))
                .map(|n| format!("docs/guide/{n}"))
                .collect()
        })
        .unwrap_or_default();
    guide.sort();
    names.extend(guide);
    names
        .into_iter()
        .map(|n| (n.clone(), std::fs::read_to_string(repo.join(&n)).unwrap_or_else(|e| panic!("{n}: {e}"))))
        .collect()
}

fn shared_datasets() -> PathBuf {
    Path::new(REPO).join("../shared/datasets")
}

/// A scratch folder laid out like a checkout with `../shared` beside it.
fn scratch(page: &str) -> PathBuf {
    let stem: String = page.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    let t = std::env::temp_dir().join(format!("smocap-docs-{}-{stem}", std::process::id()));
    let _ = std::fs::remove_dir_all(&t);
    let repo = t.join("repo");
    std::fs::create_dir_all(&repo).unwrap();
    let src = Path::new(REPO);
    for name in LINKED {
        if src.join(name).exists() {
            std::os::unix::fs::symlink(src.join(name), repo.join(name)).unwrap();
        }
    }
    for name in COPIED {
        if src.join(name).exists() {
            std::fs::copy(src.join(name), repo.join(name)).unwrap();
        }
    }
    if let Ok(shared) = src.join("../shared").canonicalize() {
        std::os::unix::fs::symlink(shared, t.join("shared")).unwrap();
    }
    t
}

/// `PATH` with the directory of the smocap binary under test first.
fn path_with_smocap() -> String {
    let bin = Path::new(env!("CARGO_BIN_EXE_smocap")).parent().unwrap().to_path_buf();
    let rest = std::env::var("PATH").unwrap_or_default();
    format!("{}:{rest}", bin.display())
}

#[test]
fn every_runnable_command_in_the_docs_runs() {
    let have_shared = shared_datasets().is_dir();
    let path = path_with_smocap();
    let mut failures = Vec::new();
    let (mut ran, mut skipped) = (0, 0);
    let all = Instant::now();
    for (page, text) in pages() {
        let runnable: Vec<Block> = blocks(&page, &text).into_iter().filter(|b| b.is("sh run")).collect();
        if runnable.is_empty() {
            continue;
        }
        let t = scratch(&page);
        let page_start = Instant::now();
        for (i, b) in runnable.iter().enumerate() {
            if !have_shared && b.text.contains("../shared") {
                println!("docs: {}:{}: skipped, {} is not here", b.file, b.line, shared_datasets().display());
                skipped += 1;
                continue;
            }
            let script = t.join(format!("block-{i:02}.sh"));
            std::fs::write(&script, &b.text).unwrap();
            println!("docs: {}:{} …", b.file, b.line);
            let start = Instant::now();
            let o = Command::new("bash")
                .args(["-euo", "pipefail"])
                .arg(&script)
                .current_dir(t.join("repo"))
                .env("PATH", &path)
                .output()
                .expect("run bash");
            ran += 1;
            println!(
                "docs: {}:{}: exit {:?} in {:.1} s",
                b.file,
                b.line,
                o.status.code(),
                start.elapsed().as_secs_f64()
            );
            if !o.status.success() {
                failures.push(format!(
                    "{}:{}: exit {:?}\n--- block\n{}--- stdout\n{}--- stderr\n{}",
                    b.file,
                    b.line,
                    o.status.code(),
                    b.text,
                    String::from_utf8_lossy(&o.stdout),
                    String::from_utf8_lossy(&o.stderr)
                ));
            }
        }
        println!("docs: {page}: {:.1} s", page_start.elapsed().as_secs_f64());
        if failures.is_empty() {
            let _ = std::fs::remove_dir_all(&t);
        } else {
            println!("docs: {page}: scratch kept in {}", t.display());
        }
    }
    println!("docs: {ran} blocks ran, {skipped} skipped, {:.1} s", all.elapsed().as_secs_f64());
    assert!(ran + skipped > 0, "no `sh run` block in README.md or docs/guide/");
    assert!(failures.is_empty(), "{} block(s) failed:\n\n{}", failures.len(), failures.join("\n\n"));
}

/// The commands of a shell block with the `smocap` subcommand and the `--flags` each passes:
/// `smocap CMD …` or `cargo run --release -- CMD …`, continuation lines joined, comments dropped.
fn smocap_calls(text: &str) -> Vec<(String, Vec<String>)> {
    let joined = text.replace("\\\n", " ");
    let mut calls = Vec::new();
    for line in joined.lines() {
        let line = match line.find(" #") {
            Some(i) => &line[..i],
            None if line.trim_start().starts_with('#') => "",
            None => line,
        };
        // Split into simple commands at pipes, lists and command substitutions.
        let simple = line.split(['|', ';', '&', '(', ')', '`']);
        for cmd in simple {
            let words: Vec<&str> = cmd.split_whitespace().collect();
            let at = match words.iter().position(|w| *w == "smocap") {
                Some(i) => i + 1,
                None => match words.windows(3).position(|w| w == ["cargo", "run", "--release"]) {
                    Some(i) => match words[i..].iter().position(|w| *w == "--") {
                        Some(j) => i + j + 1,
                        None => continue,
                    },
                    None => continue,
                },
            };
            let Some(sub) = words.get(at) else { continue };
            if sub.starts_with('-') || sub.contains('/') || sub.contains('.') {
                continue;
            }
            let flags = words[at + 1..]
                .iter()
                .filter(|w| w.starts_with("--") && w.len() > 2)
                .map(|w| w.split('=').next().unwrap().trim_end_matches(['"', '\'', ',']).to_string())
                .collect();
            calls.push((sub.to_string(), flags));
        }
    }
    calls
}

#[test]
fn every_flag_the_docs_pass_to_smocap_exists() {
    let mut help: BTreeMap<String, String> = BTreeMap::new();
    let mut wrong = BTreeSet::new();
    for (page, text) in pages() {
        for b in blocks(&page, &text).into_iter().filter(|b| b.is("sh") || b.is("sh run")) {
            for (sub, flags) in smocap_calls(&b.text) {
                let h = help.entry(sub.clone()).or_insert_with(|| {
                    let o = Command::new(env!("CARGO_BIN_EXE_smocap")).args([sub.as_str(), "--help"]).output().unwrap();
                    if o.status.success() {
                        String::from_utf8_lossy(&o.stdout).into_owned()
                    } else {
                        String::new()
                    }
                });
                if h.is_empty() {
                    wrong.insert(format!("{}:{}: `smocap {sub}` is not a command", b.file, b.line));
                    continue;
                }
                for f in flags {
                    let known = h.split(|c: char| !(c.is_ascii_alphanumeric() || c == '-')).any(|w| w == f);
                    if !known {
                        wrong.insert(format!("{}:{}: `smocap {sub}` has no {f}", b.file, b.line));
                    }
                }
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "flags the docs use that smocap does not have:\n{}",
        wrong.into_iter().collect::<Vec<_>>().join("\n")
    );
}

/// Paths quoted in backticks in `text` below the repository's source folders that do not exist
/// under `root` (a trailing `/` asks for a directory; `:line`, `#anchor` and text after a space
/// are not part of the path; a quoted glob needs its folder).
fn missing_paths(text: &str, root: &Path) -> Vec<String> {
    const PREFIXES: &[&str] = &["src/", "shaders/", "python/", "scripts/", "tests/", "models/"];
    let mut missing = Vec::new();
    for (i, span) in text.split('`').enumerate() {
        if i % 2 == 0 {
            continue;
        }
        let p = span.split_whitespace().next().unwrap_or("");
        let p = p.split([':', '#']).next().unwrap();
        if !PREFIXES.iter().any(|pre| p.starts_with(pre)) {
            continue;
        }
        let (p, dir) = match p.find(['*', '{', '?']) {
            Some(k) => (&p[..p[..k].rfind('/').map_or(0, |j| j + 1)], true),
            None => (p, p.ends_with('/')),
        };
        let full = root.join(p.trim_end_matches('/'));
        let ok = if dir { full.is_dir() } else { full.exists() };
        if !ok {
            missing.push(span.to_string());
        }
    }
    missing
}

#[test]
fn architecture_names_only_modules_that_exist() {
    let path = Path::new(REPO).join("docs/ARCHITECTURE.md");
    let Ok(text) = std::fs::read_to_string(&path) else {
        println!("docs: {} is not here; nothing to check", path.display());
        return;
    };
    let missing = missing_paths(&text, Path::new(REPO));
    assert!(missing.is_empty(), "docs/ARCHITECTURE.md names paths that do not exist: {missing:?}");
}

#[test]
fn the_architecture_check_finds_a_path_that_does_not_exist() {
    let text = "`src/cli/` the command line; `src/cli/solve.rs:13` solve; `src/nowhere.rs` gone; \
                `shaders/*.wgsl` kernels; `models/fullbody.xml/` not a folder; `Cargo.toml` not checked";
    assert_eq!(missing_paths(text, Path::new(REPO)), vec!["src/nowhere.rs", "models/fullbody.xml/"]);
}

#[test]
fn runnable_blocks_are_found_with_their_lines() {
    let md = "# t\n\n```sh run\nsmocap demo --frames 10\n```\n\n```sh\nsmocap bench --figure x.svg\n```\n\n```python run\nimport smocap\n```\n";
    let b = blocks("x.md", md);
    assert_eq!(b.len(), 3);
    assert!(b[0].is("sh run") && b[0].line == 3 && b[0].text == "smocap demo --frames 10\n");
    assert!(b[1].is("sh") && !b[1].is("sh run") && b[1].line == 7);
    assert!(b[2].is("python run"));
    assert_eq!(
        smocap_calls("x=1; smocap solve a.trc --mot-dir out \\\n  --scaled-model=o.osim | head # --no"),
        vec![("solve".to_string(), vec!["--mot-dir".to_string(), "--scaled-model".to_string()])]
    );
}

/// Pages linked from the docs that another piece of work adds; a link to one of them is not
/// checked until it exists.
const PENDING: &[&str] = &[];

/// Relative Markdown links (`[text](target)`, `![alt](target)`) of `text` in `file` (a path
/// relative to the repository) whose target does not exist; `#anchors` are not checked.
fn broken_links(file: &str, text: &str, root: &Path) -> Vec<String> {
    let dir = Path::new(file).parent().unwrap_or(Path::new(""));
    let mut broken = Vec::new();
    for part in text.split("](").skip(1) {
        let Some(end) = part.find(')') else { continue };
        let target = part[..end].split_whitespace().next().unwrap_or("");
        if target.is_empty() || target.starts_with('#') || target.contains("://") || target.starts_with("mailto:") {
            continue;
        }
        let path = target.split('#').next().unwrap();
        let mut resolved = PathBuf::new();
        for c in dir.join(path).components() {
            match c {
                std::path::Component::ParentDir => {
                    resolved.pop();
                }
                std::path::Component::CurDir => {}
                c => resolved.push(c),
            }
        }
        let rel = resolved.to_string_lossy().replace('\\', "/");
        if !root.join(&resolved).exists() && !PENDING.contains(&rel.as_str()) {
            broken.push(format!("{file}: ({target})"));
        }
    }
    broken
}

#[test]
fn every_link_in_the_docs_points_at_a_file() {
    let root = Path::new(REPO);
    let broken: Vec<String> = pages().iter().flat_map(|(f, t)| broken_links(f, t, root)).collect();
    assert!(broken.is_empty(), "links to files that do not exist:\n{}", broken.join("\n"));
    assert_eq!(
        broken_links(
            "docs/guide/x.md",
            "[a](../preview.png) [b](../../README.md#x) [c](nope.md) [d](https://x.org/y)",
            root
        ),
        vec!["docs/guide/x.md: (nope.md)"]
    );
}
