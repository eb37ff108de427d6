//! The house rules of docs/conventions.md §11, checked on the repository's own `.rs`
//! files (`src/`, `tests/`, `bench/`, `fuzz/fuzz_targets/`), in plain Rust:
//!
//! - no file longer than [`MAX_FILE_LINES`] lines;
//! - no function longer than [`MAX_FN_LINES`] lines, counted from its `fn` line to the
//!   line of its closing brace (test functions too), except those in
//!   [`LONG_FUNCTIONS`], each named with its reason in docs/conventions.md §11;
//! - no import circle between the files of `src/`.
//!
//! The source is read with comments, string literals (raw and byte strings too) and
//! char literals blanked out, so braces and `fn` inside them do not count.
//!
//! The import graph has one node per file of `src/` and an edge from a file to every
//! file whose items its code names: `use` trees (groups expanded), and paths in code
//! that start with `crate::`, `super::`, `self::`, the name of a child module, or a
//! name the file imported. A path resolves to the longest module prefix that is a
//! file; a name that file imports itself (`use`, `pub use`) is followed to where it
//! comes from, so a parent's re-export leads to the child that defines the item. The
//! rule: a child may use its parent's items (an edge to a file's own ancestor module,
//! `mod.rs` or `lib.rs`, is left out); a parent may use its children; two sibling
//! files, or files in different folders, must not use each other, directly or
//! through a longer cycle. Code compiled only for tests (a module under
//! `#[cfg(test)]`, inline or in its own file) is left out of the graph. The
//! strongly connected components with more than one file are the circles reported.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::Path;

/// The longest a `.rs` file may be.
const MAX_FILE_LINES: usize = 900;
/// The longest a function may be, from its `fn` line to its closing brace.
const MAX_FN_LINES: usize = 120;
/// Functions allowed to be longer than [`MAX_FN_LINES`], as (file, function name);
/// the same list, with the reason for each, is in docs/conventions.md §11.
const LONG_FUNCTIONS: &[(&str, &str)] = &[
    ("bench/ffz_write.rs", "main"),
    ("bench/perf_rays.rs", "main"),
    ("src/solve/shooting.rs", "run"),
    (
        "tests/it/consumers.rs",
        "udales_reading_loop_reads_the_exported_city_with_its_count_and_values",
    ),
    ("tests/it/ffz_golden.rs", "dump_file"),
    ("tests/it/ffz_tools.rs", "info_verify_export_outputs"),
    (
        "tests/it/stress_ranges.rs",
        "every_numeric_option_at_the_ends_of_its_range_neither_panics_nor_hangs",
    ),
];
/// One `.rs` file: its path from the repository root (with `/`) and its text.
struct Source {
    path: String,
    text: String,
}

/// Every `.rs` file under the given folders of the repository, sorted by path.
fn sources(dirs: &[&str]) -> Vec<Source> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut out = Vec::new();
    for d in dirs {
        let dir = root.join(d);
        if dir.is_dir() {
            walk(root, &dir, &mut out);
        }
    }
    out.sort_by(|a, b| a.path.cmp(&b.path));
    out
}

fn walk(root: &Path, dir: &Path, out: &mut Vec<Source>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        if p.is_dir() {
            if name != "target" && !name.starts_with('.') {
                walk(root, &p, out);
            }
        } else if name.ends_with(".rs") {
            let text = fs::read_to_string(&p)
                .unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()));
            let rel = p
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            out.push(Source { path: rel, text });
        }
    }
}

/// All the folders the size rules cover.
const ALL_DIRS: &[&str] = &["src", "tests", "bench", "fuzz/fuzz_targets"];

// ---------------------------------------------------------------------------------
// Reading the code: comments and literals blanked out.
// ---------------------------------------------------------------------------------

/// The text with comments, string and char literals replaced by spaces (newlines
/// kept, so line numbers stay), as a vector of chars.
fn code_of(text: &str) -> Vec<char> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::with_capacity(c.len());
    let mut i = 0;
    while i < c.len() {
        let end = literal_or_comment_end(&c, i);
        if end > i {
            out.extend(
                c[i..end]
                    .iter()
                    .map(|&x| if x == '\n' { '\n' } else { ' ' }),
            );
            i = end;
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

fn is_ident(ch: char) -> bool {
    ch.is_alphanumeric() || ch == '_'
}

/// Where the comment or literal starting at `i` ends (one past it), or `i` when none
/// starts there.
fn literal_or_comment_end(c: &[char], i: usize) -> usize {
    let at = |k: usize| c.get(k).copied().unwrap_or('\0');
    match (at(i), at(i + 1)) {
        ('/', '/') => (i..c.len()).find(|&k| c[k] == '\n').unwrap_or(c.len()),
        ('/', '*') => block_comment_end(c, i),
        ('"', _) => string_end(c, i + 1),
        ('\'', '\\') => (i + 3..c.len())
            .find(|&k| c[k] == '\'')
            .map_or(c.len(), |k| k + 1),
        ('\'', _) if at(i + 2) == '\'' => i + 3,
        ('r' | 'b', _) if i == 0 || !is_ident(c[i - 1]) => raw_string_end(c, i).unwrap_or(i),
        _ => i,
    }
}

fn block_comment_end(c: &[char], mut i: usize) -> usize {
    let mut depth = 0usize;
    while i + 1 < c.len() {
        if c[i] == '/' && c[i + 1] == '*' {
            depth += 1;
            i += 2;
        } else if c[i] == '*' && c[i + 1] == '/' {
            depth -= 1;
            i += 2;
            if depth == 0 {
                return i;
            }
        } else {
            i += 1;
        }
    }
    c.len()
}

/// One past the closing quote of a string whose contents start at `i`.
fn string_end(c: &[char], mut i: usize) -> usize {
    while i < c.len() {
        match c[i] {
            '\\' => i += 2,
            '"' => return i + 1,
            _ => i += 1,
        }
    }
    c.len()
}

/// One past a raw string (`r"…"`, `r#"…"#`, `br"…"`) starting at `i`, if one does.
fn raw_string_end(c: &[char], i: usize) -> Option<usize> {
    let mut j = i;
    if c.get(j) == Some(&'b') {
        j += 1;
    }
    if c.get(j) != Some(&'r') {
        return None;
    }
    j += 1;
    let hashes = c[j..].iter().take_while(|&&x| x == '#').count();
    j += hashes;
    if c.get(j) != Some(&'"') {
        return None;
    }
    let mut k = j + 1;
    while k < c.len() {
        if c[k] == '"'
            && c[k + 1..]
                .iter()
                .take(hashes)
                .filter(|&&x| x == '#')
                .count()
                == hashes
        {
            return Some(k + 1 + hashes);
        }
        k += 1;
    }
    Some(c.len())
}

/// A token of code: an identifier (or keyword), `::`, or one punctuation char; with
/// its line (1-based).
#[derive(Clone, Debug)]
struct Tok {
    text: String,
    line: usize,
}

fn tokens(code: &[char]) -> Vec<Tok> {
    let mut out = Vec::new();
    let mut line = 1;
    let mut i = 0;
    while i < code.len() {
        let ch = code[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if is_ident(ch) || ch == '$' {
            let start = i;
            i += 1;
            while i < code.len() && is_ident(code[i]) {
                i += 1;
            }
            out.push(Tok {
                text: code[start..i].iter().collect(),
                line,
            });
        } else if ch == ':' && code.get(i + 1) == Some(&':') {
            out.push(Tok {
                text: "::".into(),
                line,
            });
            i += 2;
        } else {
            out.push(Tok {
                text: ch.to_string(),
                line,
            });
            i += 1;
        }
    }
    out
}

// ---------------------------------------------------------------------------------
// Sizes.
// ---------------------------------------------------------------------------------

/// A function: its name, the line of its `fn` and its length in lines.
struct Func {
    name: String,
    line: usize,
    lines: usize,
}

/// Every function with a body in the tokens, nested ones too.
fn functions(toks: &[Tok]) -> Vec<Func> {
    let mut out = Vec::new();
    for (i, t) in toks.iter().enumerate() {
        let Some(name) = toks.get(i + 1) else { break };
        if t.text != "fn"
            || !name
                .text
                .starts_with(|c: char| c.is_alphabetic() || c == '_')
        {
            continue;
        }
        // The body is the first `{` outside parentheses and brackets; a `;` there first
        // means a declaration without one.
        let mut depth = 0i32;
        let mut open = None;
        for (k, u) in toks.iter().enumerate().skip(i + 2) {
            match u.text.as_str() {
                "(" | "[" => depth += 1,
                ")" | "]" => depth -= 1,
                ";" if depth == 0 => break,
                "{" if depth == 0 => {
                    open = Some(k);
                    break;
                }
                _ => {}
            }
        }
        let Some(open) = open else { continue };
        let close = matching_brace(toks, open);
        out.push(Func {
            name: name.text.clone(),
            line: t.line,
            lines: toks[close].line - t.line + 1,
        });
    }
    out
}

/// The index of the `}` that closes the `{` at `open` (the last token if none does).
fn matching_brace(toks: &[Tok], open: usize) -> usize {
    let mut depth = 0usize;
    for (k, u) in toks.iter().enumerate().skip(open) {
        match u.text.as_str() {
            "{" => depth += 1,
            "}" => {
                depth -= 1;
                if depth == 0 {
                    return k;
                }
            }
            _ => {}
        }
    }
    toks.len() - 1
}

#[test]
fn no_source_file_is_longer_than_900_lines() {
    let long: Vec<String> = sources(ALL_DIRS)
        .iter()
        .filter(|s| s.text.lines().count() > MAX_FILE_LINES)
        .map(|s| {
            format!(
                "{}:{}: {} lines",
                s.path,
                MAX_FILE_LINES + 1,
                s.text.lines().count()
            )
        })
        .collect();
    assert!(
        long.is_empty(),
        "files over {MAX_FILE_LINES} lines (docs/conventions.md §11):\n{}",
        long.join("\n")
    );
}

#[test]
fn no_function_is_longer_than_120_lines() {
    let mut long = Vec::new();
    let mut excepted_seen = BTreeSet::new();
    for s in sources(ALL_DIRS) {
        for f in functions(&tokens(&code_of(&s.text))) {
            if f.lines <= MAX_FN_LINES {
                continue;
            }
            if LONG_FUNCTIONS.contains(&(s.path.as_str(), f.name.as_str())) {
                excepted_seen.insert((s.path.clone(), f.name.clone()));
            } else {
                long.push(format!(
                    "{}:{}: fn {} is {} lines",
                    s.path, f.line, f.name, f.lines
                ));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over {MAX_FN_LINES} lines (split them, or name them with the reason in \
         docs/conventions.md §11 and in LONG_FUNCTIONS):\n{}",
        long.join("\n")
    );
    let stale: Vec<_> = LONG_FUNCTIONS
        .iter()
        .filter(|(p, n)| !excepted_seen.contains(&(p.to_string(), n.to_string())))
        .collect();
    assert!(
        stale.is_empty(),
        "LONG_FUNCTIONS names functions that are no longer over {MAX_FN_LINES} lines (or \
         no longer exist); take them out of the list and of docs/conventions.md §11: \
         {stale:?}"
    );
}

#[test]
fn the_function_reader_sees_through_comments_and_literals() {
    let text = "fn a() {\n  let s = \"}\"; let c = '}'; // }\n  let r = r#\"}\"#; /* } */\n\
                let l: &'static str = s;\n}\nfn b(x: [u8; 2]) -> u8 { x[0] }\n";
    let f = functions(&tokens(&code_of(text)));
    let got: Vec<_> = f
        .iter()
        .map(|f| (f.name.as_str(), f.line, f.lines))
        .collect();
    assert_eq!(got, [("a", 1, 5), ("b", 6, 1)]);
}

// ---------------------------------------------------------------------------------
// The import graph of `src/`.
// ---------------------------------------------------------------------------------

/// A module path from the crate root (`["ffz", "writer"]`).
type ModPath = Vec<String>;

/// The module path of a file of `src/` (`src/lib.rs` and `src/main.rs` are the root).
fn module_of(path: &str) -> ModPath {
    let rel = path.strip_prefix("src/").expect("a file of src/");
    let rel = rel.strip_suffix(".rs").expect("a .rs file");
    let mut segs: ModPath = rel.split('/').map(String::from).collect();
    if matches!(
        segs.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        segs.pop();
    }
    segs
}

/// A path named in one file's code: where it was named and its segments.
struct Named {
    line: usize,
    /// The module the path was written in (the file's, with inline modules).
    module: ModPath,
    segs: Vec<String>,
    /// From a `use` declaration: the name it binds (`None` for a glob).
    binds: Option<String>,
}

/// What one file names: its `use` declarations and the other paths of its code; and
/// the modules it declares under `#[cfg(test)]` (as module paths).
struct FileRefs {
    uses: Vec<Named>,
    paths: Vec<Named>,
    test_mods: Vec<ModPath>,
}

/// Whether the tokens at `i` are the attribute `#[cfg(test)]`.
fn is_cfg_test(toks: &[Tok], i: usize) -> bool {
    let want = ["#", "[", "cfg", "(", "test", ")", "]"];
    toks.len() >= i + want.len() && want.iter().enumerate().all(|(k, w)| toks[i + k].text == *w)
}

/// Reads the paths a file names, keeping track of inline modules.
fn file_refs(module: &ModPath, toks: &[Tok]) -> FileRefs {
    let mut refs = FileRefs {
        uses: Vec::new(),
        paths: Vec::new(),
        test_mods: Vec::new(),
    };
    // Inline modules open at this point: (name, brace depth inside it, test-only).
    let mut inline: Vec<(String, usize, bool)> = Vec::new();
    let mut depth = 0usize;
    let mut cfg_test = false;
    let mut i = 0;
    while i < toks.len() {
        let t = toks[i].text.as_str();
        let mut here = module.clone();
        here.extend(inline.iter().map(|m| m.0.clone()));
        let skipping = inline.iter().any(|m| m.2);
        match t {
            "#" if is_cfg_test(toks, i) => {
                cfg_test = true;
                i += 7;
                continue;
            }
            "{" => depth += 1,
            "}" => {
                if inline.last().is_some_and(|m| m.1 == depth) {
                    inline.pop();
                }
                depth = depth.saturating_sub(1);
                cfg_test = false;
            }
            ";" => cfg_test = false,
            "mod" if toks.get(i + 1).is_some() => {
                let name = toks[i + 1].text.clone();
                match toks.get(i + 2).map(|t| t.text.as_str()) {
                    Some("{") => {
                        inline.push((name, depth + 1, cfg_test || skipping));
                        depth += 1;
                        cfg_test = false;
                        i += 3;
                        continue;
                    }
                    Some(";") if cfg_test || skipping => {
                        let mut m = here.clone();
                        m.push(name);
                        refs.test_mods.push(m);
                    }
                    _ => {}
                }
            }
            "use" if !skipping => {
                let end = (i..toks.len())
                    .find(|&k| toks[k].text == ";")
                    .unwrap_or(toks.len());
                let mut trees = Vec::new();
                use_tree(&toks[i + 1..end], &mut Vec::new(), &mut trees);
                for (segs, binds) in trees {
                    refs.uses.push(Named {
                        line: toks[i].line,
                        module: here.clone(),
                        segs,
                        binds,
                    });
                }
                i = end;
                continue;
            }
            _ if !skipping && is_path_start(toks, i) => {
                let mut segs = vec![t.to_string()];
                let mut k = i + 1;
                while k + 1 < toks.len() && toks[k].text == "::" && is_word(&toks[k + 1].text) {
                    segs.push(toks[k + 1].text.clone());
                    k += 2;
                }
                let line = toks[i].line;
                refs.paths.push(Named {
                    line,
                    module: here,
                    segs,
                    binds: None,
                });
                i = k;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    refs
}

fn is_word(s: &str) -> bool {
    s.starts_with(|c: char| is_ident(c) || c == '$')
}

/// Whether a path `a::b…` starts at token `i` (a word followed by `::`, not preceded
/// by `::`).
fn is_path_start(toks: &[Tok], i: usize) -> bool {
    is_word(&toks[i].text)
        && toks.get(i + 1).is_some_and(|t| t.text == "::")
        && (i == 0 || toks[i - 1].text != "::")
}

/// Expands a `use` tree (the tokens between `use` and `;`) into full paths with the
/// name each binds (`None` for a glob).
fn use_tree(toks: &[Tok], prefix: &mut Vec<String>, out: &mut Vec<(Vec<String>, Option<String>)>) {
    let n = prefix.len();
    let mut i = 0;
    while i < toks.len() {
        let t = toks[i].text.as_str();
        match t {
            "::" => {}
            "*" => out.push((prefix.clone(), None)),
            "{" => {
                let close = matching_brace(toks, i);
                // Each comma-separated subtree at this level.
                let mut start = i + 1;
                let mut level = 0i32;
                for k in i + 1..=close {
                    match toks[k].text.as_str() {
                        "{" => level += 1,
                        "}" if level > 0 => level -= 1,
                        "," | "}" if level == 0 => {
                            use_tree(&toks[start..k], prefix, out);
                            start = k + 1;
                        }
                        _ => {}
                    }
                }
                i = close;
            }
            "as" => {
                let alias = toks.get(i + 1).map(|t| t.text.clone());
                if let Some(last) = out.last_mut().filter(|o| o.0 == *prefix) {
                    last.1 = alias;
                }
                i += 1;
            }
            "self" if i == 0 && n > 0 => {
                out.push((prefix.clone(), prefix.last().cloned()));
            }
            _ if is_word(t) => {
                prefix.push(t.to_string());
                let next = toks.get(i + 1).map(|t| t.text.as_str());
                if next != Some("::") {
                    out.push((prefix.clone(), Some(t.to_string())));
                }
            }
            _ => {}
        }
        i += 1;
    }
    prefix.truncate(n);
}

/// The files of `src/` by module path, with what each names.
struct Crate {
    /// Module path → file (the root is `src/lib.rs`).
    files: BTreeMap<ModPath, String>,
    /// File → its module path, for every file (`src/main.rs` too).
    module: BTreeMap<String, ModPath>,
    refs: BTreeMap<String, FileRefs>,
}

impl Crate {
    fn read() -> Crate {
        let mut c = Crate {
            files: BTreeMap::new(),
            module: BTreeMap::new(),
            refs: BTreeMap::new(),
        };
        for s in sources(&["src"]) {
            let m = module_of(&s.path);
            if s.path != "src/main.rs" {
                c.files.insert(m.clone(), s.path.clone());
            }
            let refs = file_refs(&m, &tokens(&code_of(&s.text)));
            c.module.insert(s.path.clone(), m);
            c.refs.insert(s.path, refs);
        }
        // Files declared under `#[cfg(test)]` are left out (and whatever is under them).
        let tests: Vec<ModPath> = c.refs.values().flat_map(|r| r.test_mods.clone()).collect();
        c.module
            .retain(|_, m| !tests.iter().any(|t| m.starts_with(t)));
        c.refs.retain(|f, _| c.module.contains_key(f));
        c
    }

    /// The absolute module path a path names, or `None` for one outside the crate.
    fn absolute(&self, file: &str, n: &Named, imports: bool) -> Option<ModPath> {
        let first = n.segs[0].as_str();
        let mut base = n.module.clone();
        let rest: &[String] = match first {
            "crate" | "$crate" | "ffstream" => {
                base.clear();
                &n.segs[1..]
            }
            "self" => &n.segs[1..],
            "super" => {
                let ups = n.segs.iter().take_while(|s| *s == "super").count();
                base.truncate(base.len().saturating_sub(ups));
                &n.segs[ups..]
            }
            _ => {
                let mut child = n.module.clone();
                child.push(first.to_string());
                if self.files.contains_key(&child) {
                    &n.segs
                } else if let Some(target) = imports.then(|| self.import(file, first)).flatten() {
                    base = target;
                    &n.segs[1..]
                } else {
                    return None;
                }
            }
        };
        base.extend(rest.iter().cloned());
        Some(base)
    }

    /// Where the name `name` imported by `file` comes from.
    fn import(&self, file: &str, name: &str) -> Option<ModPath> {
        let u = self.refs[file]
            .uses
            .iter()
            .find(|u| u.binds.as_deref() == Some(name))?;
        self.absolute(file, u, false)
    }

    /// The file an absolute path leads to: the longest module prefix that is a file,
    /// following that file's own imports of the next name. `None` when the path names
    /// a module itself (what is used of it is counted where it is used).
    fn target(&self, abs: &ModPath, hops: usize) -> Option<String> {
        let k = (0..=abs.len())
            .rev()
            .find(|&k| self.files.contains_key(&abs[..k]))?;
        let file = &self.files[&abs[..k]];
        if k == abs.len() {
            return None;
        }
        if hops < 8 && self.refs.contains_key(file) {
            if let Some(via) = self.import(file, &abs[k]) {
                let mut next = via;
                next.extend(abs[k + 1..].iter().cloned());
                if let Some(t) = self.target(&next, hops + 1) {
                    return Some(t);
                }
            }
        }
        Some(file.clone())
    }

    /// Whether `anc` is the module file of an ancestor of `file`'s module.
    fn is_ancestor(&self, anc: &str, file: &str) -> bool {
        let (Some(a), Some(f)) = (self.module.get(anc), self.module.get(file)) else {
            return false;
        };
        (anc.ends_with("/mod.rs") || anc == "src/lib.rs") && f.len() > a.len() && f.starts_with(a)
    }

    /// The edges file → file, each with the first place that makes it (line, path).
    fn edges(&self) -> BTreeMap<(String, String), (usize, String)> {
        let mut edges = BTreeMap::new();
        for (file, refs) in &self.refs {
            for n in refs.uses.iter().chain(&refs.paths) {
                let Some(abs) = self.absolute(file, n, true) else {
                    continue;
                };
                let Some(to) = self.target(&abs, 0) else {
                    continue;
                };
                if to == *file || self.is_ancestor(&to, file) {
                    continue;
                }
                edges
                    .entry((file.clone(), to))
                    .or_insert((n.line, n.segs.join("::")));
            }
        }
        edges
    }
}

/// The strongly connected components of a directed graph (Tarjan), each sorted.
fn components(nodes: &[String], edges: &BTreeSet<(String, String)>) -> Vec<Vec<String>> {
    struct St<'a> {
        next: BTreeMap<&'a str, Vec<&'a str>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut St<'a>, v: &'a str) {
        let i = s.index.len();
        s.index.insert(v, i);
        s.low.insert(v, i);
        s.stack.push(v);
        s.on.insert(v);
        for w in s.next.get(v).cloned().unwrap_or_default() {
            if !s.index.contains_key(w) {
                visit(s, w);
                let l = s.low[v].min(s.low[w]);
                s.low.insert(v, l);
            } else if s.on.contains(w) {
                let l = s.low[v].min(s.index[w]);
                s.low.insert(v, l);
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            comp.sort();
            s.out.push(comp);
        }
    }
    let mut s = St {
        next: BTreeMap::new(),
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: Vec::new(),
    };
    for (a, b) in edges {
        s.next.entry(a.as_str()).or_default().push(b.as_str());
    }
    for v in nodes {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out
}

#[test]
fn no_two_files_of_src_use_each_other() {
    let c = Crate::read();
    let edges = c.edges();
    let set: BTreeSet<_> = edges.keys().cloned().collect();
    let nodes: Vec<String> = c.refs.keys().cloned().collect();
    let mut report = Vec::new();
    let circles: Vec<_> = components(&nodes, &set)
        .into_iter()
        .filter(|c| c.len() > 1)
        .collect();
    for comp in circles {
        report.push(format!("circle: {}", comp.join(" ↔ ")));
        for ((a, b), (line, path)) in &edges {
            if comp.contains(a) && comp.contains(b) {
                report.push(format!("  {a}:{line}: uses {b} ({path})"));
            }
        }
    }
    assert!(
        report.is_empty(),
        "import circles between files of src/ (docs/conventions.md §11: move the shared \
         item to the lower layer):\n{}",
        report.join("\n")
    );
}
