//! `cargo xtask cycles`: import cycles between the files of each crate.
//!
//! Every file of `crates/*/src` and `xtask/src` is a module (`lib.rs`/`main.rs` the root,
//! `mod.rs` its folder; `bin/`, `tests.rs` files and `#[cfg(test)] mod … { … }` blocks are
//! left out). A file uses another when it names a path into it — `crate::a::b::X` or
//! `super::X`, in a `use` tree or inline — resolved to the deepest file module on the path.
//! A parent reaching its children by their bare names (`child::f`) is how Rust nests
//! modules and is not counted, so a parent and its private children are one unit; two
//! files that reach each other by `crate::`/`super::` paths are a cycle (strongly
//! connected components, Tarjan).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// A module by its path below the crate root (empty: the root).
type ModPath = Vec<String>;

/// Edges `from → to` with the paths that made each.
type Edges = BTreeMap<ModPath, BTreeMap<ModPath, BTreeSet<String>>>;

/// Print every cycle; fail when there is one.
#[allow(clippy::print_stdout)]
pub fn cycles(root: &Path) -> Result<()> {
    let mut sources = Vec::new();
    for entry in std::fs::read_dir(root.join("crates")).context("listing crates/")? {
        let src = entry?.path().join("src");
        if src.is_dir() {
            sources.push(src);
        }
    }
    sources.sort();
    sources.push(root.join("xtask/src"));
    let mut found = Vec::new();
    for src in &sources {
        let files = crate_files(src)?;
        let mut edges = Edges::new();
        for (module, path) in &files {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let toks = without_test_modules(&tokens(&text));
            for segs in paths(&toks) {
                if let Some(target) = resolve(module, &segs, &files)
                    && &target != module
                {
                    edges
                        .entry(module.clone())
                        .or_default()
                        .entry(target)
                        .or_default()
                        .insert(segs.join("::"));
                }
            }
        }
        let name = src.strip_prefix(root).unwrap_or(src).display().to_string();
        for component in components(files.keys(), &edges) {
            if component.len() > 1 {
                found.push(describe(&name, &component, &edges));
            }
        }
    }
    if found.is_empty() {
        println!("no import cycles between the files of a crate");
        return Ok(());
    }
    for f in &found {
        println!("{f}");
    }
    bail!("{} import cycle(s) between files of a crate", found.len())
}

fn describe(src: &str, component: &[ModPath], edges: &Edges) -> String {
    let show = |m: &ModPath| {
        if m.is_empty() {
            "<root>".to_string()
        } else {
            m.join("/")
        }
    };
    let members: BTreeSet<&ModPath> = component.iter().collect();
    let mut s = format!(
        "{src}: cycle {}",
        members
            .iter()
            .map(|m| show(m))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for from in &members {
        for (to, why) in edges.get(*from).into_iter().flatten() {
            if members.contains(to) {
                let why: Vec<&str> = why.iter().take(4).map(String::as_str).collect();
                s.push_str(&format!(
                    "\n  {} -> {}: {}",
                    show(from),
                    show(to),
                    why.join(", ")
                ));
            }
        }
    }
    s
}

/// The crate's file modules.
fn crate_files(src: &Path) -> Result<BTreeMap<ModPath, PathBuf>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in
            std::fs::read_dir(&dir).with_context(|| format!("listing {}", dir.display()))?
        {
            let path = entry?.path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            if path.extension().is_none_or(|e| e != "rs") {
                continue;
            }
            let rel = path.strip_prefix(src).unwrap_or(&path).with_extension("");
            let mut module: ModPath = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if module.first().is_some_and(|m| m == "bin") || module.iter().any(|m| m == "tests") {
                continue;
            }
            if module.len() == 1 && (module[0] == "lib" || module[0] == "main") {
                module.clear();
            } else if module.last().is_some_and(|m| m == "mod") {
                module.pop();
            }
            out.insert(module, path);
        }
    }
    Ok(out)
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Tok {
    Ident(String),
    /// `::`
    Path,
    Punct(char),
}

/// Identifiers, `::` and punctuation, without comments, literals and lifetimes.
fn tokens(text: &str) -> Vec<Tok> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    let skip_string = |mut i: usize| {
        // `c[i]` is the opening quote.
        i += 1;
        while i < c.len() && c[i] != '"' {
            i += if c[i] == '\\' { 2 } else { 1 };
        }
        i + 1
    };
    while i < c.len() {
        let ch = c[i];
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && c.get(i + 1) == Some(&'/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && c.get(i + 1) == Some(&'*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if ch == '"' {
            i = skip_string(i);
        } else if ch == '\'' {
            if c.get(i + 1) == Some(&'\\') {
                i += 2;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if c.get(i + 2) == Some(&'\'') {
                i += 3;
            } else {
                // A lifetime or label.
                i += 1;
                while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                    i += 1;
                }
            }
        } else if ch.is_alphabetic() || ch == '_' {
            let start = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            let word: String = c[start..i].iter().collect();
            let raw = matches!(word.as_str(), "r" | "br" | "cr");
            if raw && matches!(c.get(i), Some('"' | '#')) {
                let mut hashes = 0;
                while c.get(i) == Some(&'#') {
                    hashes += 1;
                    i += 1;
                }
                if c.get(i) != Some(&'"') {
                    continue; // `r#ident`
                }
                i += 1;
                loop {
                    if i >= c.len() {
                        break;
                    }
                    if c[i] == '"' && (1..=hashes).all(|h| c.get(i + h) == Some(&'#')) {
                        i += 1 + hashes;
                        break;
                    }
                    i += 1;
                }
            } else if matches!(word.as_str(), "b" | "c") && c.get(i) == Some(&'"') {
                i = skip_string(i);
            } else if word == "b" && c.get(i) == Some(&'\'') {
                // A byte literal: `b'x'` or `b'\x'`.
                i += 2;
                while i < c.len() && c[i] != '\'' {
                    i += if c[i] == '\\' { 2 } else { 1 };
                }
                i += 1;
            } else {
                out.push(Tok::Ident(word));
            }
        } else if ch.is_ascii_digit() {
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_' || c[i] == '.') {
                i += 1;
            }
        } else if ch == ':' && c.get(i + 1) == Some(&':') {
            out.push(Tok::Path);
            i += 2;
        } else {
            out.push(Tok::Punct(ch));
            i += 1;
        }
    }
    out
}

fn ident(t: Option<&Tok>, word: &str) -> bool {
    matches!(t, Some(Tok::Ident(w)) if w == word)
}

/// The tokens without `#[cfg(test)] mod name { … }` blocks.
fn without_test_modules(toks: &[Tok]) -> Vec<Tok> {
    let cfg_test = [
        Tok::Punct('#'),
        Tok::Punct('['),
        Tok::Ident("cfg".into()),
        Tok::Punct('('),
        Tok::Ident("test".into()),
        Tok::Punct(')'),
        Tok::Punct(']'),
    ];
    let mut out = Vec::with_capacity(toks.len());
    let mut i = 0;
    while i < toks.len() {
        if toks[i..].starts_with(&cfg_test) {
            // Skip further attributes, then look for `mod name {`.
            let mut j = i + cfg_test.len();
            while toks.get(j) == Some(&Tok::Punct('#')) {
                let mut depth = 0;
                j += 1;
                while j < toks.len() {
                    match toks[j] {
                        Tok::Punct('[') => depth += 1,
                        Tok::Punct(']') => {
                            depth -= 1;
                            if depth == 0 {
                                j += 1;
                                break;
                            }
                        }
                        _ => {}
                    }
                    j += 1;
                }
            }
            if ident(toks.get(j), "mod") && toks.get(j + 2) == Some(&Tok::Punct('{')) {
                let mut depth = 0;
                let mut k = j + 2;
                while k < toks.len() {
                    match toks[k] {
                        Tok::Punct('{') => depth += 1,
                        Tok::Punct('}') => {
                            depth -= 1;
                            if depth == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                    k += 1;
                }
                i = k + 1;
                continue;
            }
        }
        out.push(toks[i].clone());
        i += 1;
    }
    out
}

/// Every path starting with `crate` or `super`: `use` trees expanded, and inline paths.
fn paths(toks: &[Tok]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < toks.len() {
        if ident(toks.get(i), "use") {
            i += 1;
            use_tree(toks, &mut i, Vec::new(), &mut out);
            continue;
        }
        let starts = ident(toks.get(i), "crate") || ident(toks.get(i), "super");
        if starts && (i == 0 || toks[i - 1] != Tok::Path) && toks.get(i + 1) == Some(&Tok::Path) {
            let mut segs = Vec::new();
            while let Some(Tok::Ident(w)) = toks.get(i) {
                segs.push(w.clone());
                i += 1;
                if toks.get(i) != Some(&Tok::Path) {
                    break;
                }
                i += 1;
            }
            out.push(segs);
            continue;
        }
        i += 1;
    }
    out.retain(|s| matches!(s.first().map(String::as_str), Some("crate" | "super")));
    out
}

/// One `use` tree from `toks[*i]`, every leaf path pushed to `out`.
fn use_tree(toks: &[Tok], i: &mut usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut segs = prefix;
    loop {
        match toks.get(*i) {
            Some(Tok::Ident(w)) => {
                if w != "self" {
                    segs.push(w.clone());
                }
                *i += 1;
            }
            Some(Tok::Punct('{')) => {
                *i += 1;
                loop {
                    if toks.get(*i) == Some(&Tok::Punct('}')) {
                        *i += 1;
                        break;
                    }
                    use_tree(toks, i, segs.clone(), out);
                    match toks.get(*i) {
                        Some(Tok::Punct(',')) => *i += 1,
                        Some(Tok::Punct('}')) => {
                            *i += 1;
                            break;
                        }
                        _ => break,
                    }
                }
                return;
            }
            Some(Tok::Punct('*')) => {
                *i += 1;
                out.push(segs);
                return;
            }
            _ => break,
        }
        if toks.get(*i) == Some(&Tok::Path) {
            *i += 1;
            continue;
        }
        if ident(toks.get(*i), "as") {
            *i += 2;
        }
        break;
    }
    out.push(segs);
}

/// The deepest file module on the path, or `None` for paths leaving the crate.
fn resolve(
    module: &ModPath,
    segs: &[String],
    files: &BTreeMap<ModPath, PathBuf>,
) -> Option<ModPath> {
    let (mut base, rest): (ModPath, &[String]) = match segs.first().map(String::as_str) {
        Some("crate") => (Vec::new(), &segs[1..]),
        Some("super") => {
            let ups = segs.iter().take_while(|s| *s == "super").count();
            if ups > module.len() {
                return None;
            }
            (module[..module.len() - ups].to_vec(), &segs[ups..])
        }
        _ => return None,
    };
    let mut best = base.clone();
    for s in rest {
        base.push(s.clone());
        if files.contains_key(&base) {
            best = base.clone();
        } else {
            break;
        }
    }
    files.contains_key(&best).then_some(best)
}

/// Strongly connected components (Tarjan).
fn components<'a>(nodes: impl Iterator<Item = &'a ModPath>, edges: &Edges) -> Vec<Vec<ModPath>> {
    struct State<'e> {
        edges: &'e Edges,
        index: BTreeMap<ModPath, usize>,
        low: BTreeMap<ModPath, usize>,
        stack: Vec<ModPath>,
        on_stack: BTreeSet<ModPath>,
        out: Vec<Vec<ModPath>>,
    }
    fn visit(st: &mut State<'_>, v: &ModPath) {
        let n = st.index.len();
        st.index.insert(v.clone(), n);
        st.low.insert(v.clone(), n);
        st.stack.push(v.clone());
        st.on_stack.insert(v.clone());
        let next: Vec<ModPath> = st
            .edges
            .get(v)
            .map(|m| m.keys().cloned().collect())
            .unwrap_or_default();
        for w in &next {
            if !st.index.contains_key(w) {
                visit(st, w);
                let lw = st.low[w];
                let lv = st.low.get_mut(v).expect("visited");
                *lv = (*lv).min(lw);
            } else if st.on_stack.contains(w) {
                let iw = st.index[w];
                let lv = st.low.get_mut(v).expect("visited");
                *lv = (*lv).min(iw);
            }
        }
        if st.low[v] == st.index[v] {
            let mut component = Vec::new();
            while let Some(w) = st.stack.pop() {
                st.on_stack.remove(&w);
                let done = &w == v;
                component.push(w);
                if done {
                    break;
                }
            }
            st.out.push(component);
        }
    }
    let mut st = State {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in nodes {
        if !st.index.contains_key(v) {
            visit(&mut st, v);
        }
    }
    st.out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn files(mods: &[&str]) -> BTreeMap<ModPath, PathBuf> {
        mods.iter()
            .map(|m| {
                let p: ModPath = if m.is_empty() {
                    Vec::new()
                } else {
                    m.split('/').map(String::from).collect()
                };
                (p, PathBuf::new())
            })
            .collect()
    }

    fn m(s: &str) -> ModPath {
        s.split('/').map(String::from).collect()
    }

    #[test]
    fn use_trees_and_inline_paths_resolve_to_file_modules() {
        let text = r##"
            use crate::a::{X, b::{self, Y as Z}};
            use super::c::*; // crate::d::Ignored in a comment
            fn f<'a>(s: &'a str) -> char { let _ = "crate::d::InString"; let _ = r#"crate::d"#; crate::d::g(); 'x' }
            pub(crate) fn h() {}
            #[cfg(test)]
            mod tests { use crate::e::T; }
        "##;
        let toks = without_test_modules(&tokens(text));
        let fs = files(&["", "a", "a/b", "c", "d", "e", "k", "k/s"]);
        let got: BTreeSet<ModPath> = paths(&toks)
            .iter()
            .filter_map(|p| resolve(&m("k/s"), p, &fs))
            .collect();
        let want: BTreeSet<ModPath> = [m("a"), m("a/b"), m("k"), m("d")].into_iter().collect();
        assert_eq!(got, want);
    }

    #[test]
    fn two_siblings_using_each_other_are_one_component() {
        let mut edges = Edges::new();
        edges.entry(m("a")).or_default().entry(m("b")).or_default();
        edges.entry(m("b")).or_default().entry(m("a")).or_default();
        edges.entry(m("b")).or_default().entry(m("c")).or_default();
        let nodes = [m("a"), m("b"), m("c")];
        let mut big: Vec<Vec<ModPath>> = components(nodes.iter(), &edges)
            .into_iter()
            .filter(|c| c.len() > 1)
            .collect();
        assert_eq!(big.len(), 1);
        big[0].sort();
        assert_eq!(big[0], vec![m("a"), m("b")]);
    }
}
