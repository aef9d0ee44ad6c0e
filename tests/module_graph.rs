//! Issue 28: the engine's modules form no import cycle. Each source file is a module; every path
//! it names (`use` trees and inline paths through `crate::`, `super::`, `self::` or a child
//! module) is resolved, through re-exports, to the file that defines the item, and the graph of
//! those file-to-file edges must be acyclic. A facade (`scene/mod.rs`, the crate root) that only
//! re-exports does not count as the home of what it re-exports. Test code is left out.
//!
//! The parser is deliberately small (it knows `use` trees, item keywords, comments and strings);
//! it errs towards missing an edge, never towards inventing one, so a reported cycle is real.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Module = Vec<String>;

/// One source file: its module path, the items it defines and the paths it names.
struct File {
    defs: BTreeSet<String>,
    /// `use` paths (absolute or relative as written, `*` for globs).
    uses: Vec<Vec<String>>,
    /// Paths written inline in the code.
    inline: Vec<Vec<String>>,
}

fn module_of(rel: &Path) -> Module {
    let mut parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts
}

/// Removes comments, string and char literals (keeping the code's tokens apart).
fn strip(text: &str) -> String {
    let b: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            '/' if b.get(i + 1) == Some(&'/') => {
                while i < b.len() && b[i] != '\n' {
                    i += 1;
                }
            }
            '/' if b.get(i + 1) == Some(&'*') => {
                let mut depth = 0;
                while i < b.len() {
                    if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                        depth += 1;
                        i += 2;
                    } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                        depth -= 1;
                        i += 2;
                        if depth == 0 {
                            break;
                        }
                    } else {
                        i += 1;
                    }
                }
            }
            'r' if matches!(b.get(i + 1), Some('"') | Some('#'))
                && (i == 0 || !(b[i - 1].is_alphanumeric() || b[i - 1] == '_')) =>
            {
                let mut j = i + 1;
                let mut hashes = 0;
                while b.get(j) == Some(&'#') {
                    hashes += 1;
                    j += 1;
                }
                if b.get(j) != Some(&'"') {
                    out.push('r');
                    i += 1;
                    continue;
                }
                j += 1;
                loop {
                    if j >= b.len() {
                        break;
                    }
                    if b[j] == '"' && (0..hashes).all(|k| b.get(j + 1 + k) == Some(&'#')) {
                        j += 1 + hashes;
                        break;
                    }
                    j += 1;
                }
                out.push_str("\"\"");
                i = j;
            }
            '"' => {
                i += 1;
                while i < b.len() && b[i] != '"' {
                    if b[i] == '\\' {
                        i += 1;
                    }
                    i += 1;
                }
                i += 1;
                out.push_str("\"\"");
            }
            '\'' if b.get(i + 2) == Some(&'\'') || b.get(i + 1) == Some(&'\\') => {
                // A char literal ('a', '\n', '\u{..}'); lifetimes ('a) have no closing quote.
                i += 1;
                while i < b.len() && b[i] != '\'' {
                    if b[i] == '\\' {
                        i += 1;
                    }
                    i += 1;
                }
                i += 1;
                out.push_str("' '");
            }
            c => {
                out.push(c);
                i += 1;
            }
        }
    }
    out
}

/// Identifiers, `::` and single punctuation characters.
fn tokens(text: &str) -> Vec<String> {
    let b: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_alphanumeric() || c == '_' {
            let s = i;
            while i < b.len() && (b[i].is_alphanumeric() || b[i] == '_') {
                i += 1;
            }
            out.push(b[s..i].iter().collect());
        } else if c == ':' && b.get(i + 1) == Some(&':') {
            out.push("::".into());
            i += 2;
        } else if c.is_whitespace() {
            i += 1;
        } else {
            out.push(c.to_string());
            i += 1;
        }
    }
    out
}

/// Drops `#[cfg(test)]` items (a module block or declaration, or the next item's braces).
fn without_tests(t: Vec<String>, test_mods: &mut Vec<String>) -> Vec<String> {
    let mut out = Vec::with_capacity(t.len());
    let mut i = 0;
    while i < t.len() {
        let is_cfg_test = t[i] == "#"
            && t.get(i + 1).is_some_and(|s| s == "[")
            && t.get(i + 2).is_some_and(|s| s == "cfg")
            && t.get(i + 3).is_some_and(|s| s == "(")
            && t.get(i + 4).is_some_and(|s| s == "test")
            && t.get(i + 5).is_some_and(|s| s == ")");
        if !is_cfg_test {
            out.push(t[i].clone());
            i += 1;
            continue;
        }
        i += 7;
        if t.get(i).is_some_and(|s| s == "mod") && t.get(i + 2).is_some_and(|s| s == ";") {
            test_mods.push(t[i + 1].clone());
            i += 3;
            continue;
        }
        // Skip to the end of the item: its first `;` at depth 0 or its closing brace.
        let mut depth = 0usize;
        while i < t.len() {
            match t[i].as_str() {
                "{" => depth += 1,
                "}" => {
                    depth -= 1;
                    if depth == 0 {
                        i += 1;
                        break;
                    }
                }
                ";" if depth == 0 => {
                    i += 1;
                    break;
                }
                _ => {}
            }
            i += 1;
        }
    }
    out
}

/// Expands one `use` tree (tokens between `use` and `;`) into its leaf paths.
fn use_paths(t: &[String], prefix: &[String], out: &mut Vec<Vec<String>>) {
    if t.len() == 1 && t[0] == "self" {
        out.push(prefix.to_vec());
        return;
    }
    let mut path = prefix.to_vec();
    let mut i = 0;
    while i < t.len() {
        match t[i].as_str() {
            "::" => i += 1,
            "{" => {
                // Split the group at depth-0 commas.
                let mut depth = 0;
                let mut start = i + 1;
                let mut j = i + 1;
                while j < t.len() {
                    match t[j].as_str() {
                        "{" => depth += 1,
                        "}" if depth == 0 => break,
                        "}" => depth -= 1,
                        "," if depth == 0 => {
                            use_paths(&t[start..j], &path, out);
                            start = j + 1;
                        }
                        _ => {}
                    }
                    j += 1;
                }
                use_paths(&t[start..j], &path, out);
                return;
            }
            "as" => break,
            s => {
                path.push(s.to_string());
                i += 1;
            }
        }
    }
    if path.len() > prefix.len() {
        out.push(path);
    }
}

const ITEM_KEYWORDS: [&str; 8] = [
    "struct", "enum", "trait", "fn", "type", "const", "static", "union",
];

fn parse(text: &str, test_mods: &mut Vec<String>) -> File {
    let t = without_tests(tokens(&strip(text)), test_mods);
    let mut defs = BTreeSet::new();
    let mut uses = Vec::new();
    let mut inline = Vec::new();
    let mut i = 0;
    while i < t.len() {
        let tok = t[i].as_str();
        if ITEM_KEYWORDS.contains(&tok) {
            if let Some(name) = t.get(i + 1) {
                defs.insert(name.clone());
            }
        } else if tok == "macro_rules" && t.get(i + 1).is_some_and(|s| s == "!") {
            if let Some(name) = t.get(i + 2) {
                defs.insert(name.clone());
            }
        }
        if tok == "use" {
            let end = (i..t.len()).find(|&j| t[j] == ";").unwrap_or(t.len());
            let tree = &t[i + 1..end];
            let tree = if tree.first().is_some_and(|s| s == "::") {
                &tree[1..]
            } else {
                tree
            };
            use_paths(tree, &[], &mut uses);
            i = end + 1;
            continue;
        }
        // An inline path: ident (:: ident)+, not itself the tail of a path.
        let starts_path = tok
            .chars()
            .next()
            .is_some_and(|c| c.is_alphabetic() || c == '_')
            && t.get(i + 1).is_some_and(|s| s == "::")
            && (i == 0 || t[i - 1] != "::");
        if starts_path {
            let mut path = vec![tok.to_string()];
            let mut j = i + 1;
            while t.get(j).is_some_and(|s| s == "::")
                && t.get(j + 1).is_some_and(|s| {
                    s.chars()
                        .next()
                        .is_some_and(|c| c.is_alphabetic() || c == '_')
                })
            {
                path.push(t[j + 1].clone());
                j += 2;
            }
            inline.push(path);
            i = j;
            continue;
        }
        i += 1;
    }
    File { defs, uses, inline }
}

struct Crate {
    files: BTreeMap<Module, File>,
}

impl Crate {
    fn load(src: &Path) -> Self {
        let mut paths = Vec::new();
        let mut stack = vec![src.to_path_buf()];
        while let Some(dir) = stack.pop() {
            for e in std::fs::read_dir(&dir).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    paths.push(p);
                }
            }
        }
        paths.sort();
        let mut files = BTreeMap::new();
        let mut test_files: BTreeSet<Module> = BTreeSet::new();
        for p in &paths {
            let module = module_of(p.strip_prefix(src).unwrap());
            let mut test_mods = Vec::new();
            let file = parse(&std::fs::read_to_string(p).unwrap(), &mut test_mods);
            for m in test_mods {
                let mut child = module.clone();
                child.push(m);
                test_files.insert(child);
            }
            files.insert(module, file);
        }
        files.retain(|m, _| !test_files.iter().any(|t| m.starts_with(t)));
        Self { files }
    }

    /// `path` as written in `module`, made absolute (None for external crates and std).
    fn absolute(&self, module: &Module, path: &[String]) -> Option<Vec<String>> {
        let first = path.first()?;
        match first.as_str() {
            "crate" => Some(path[1..].to_vec()),
            "super" => {
                let mut base = module.clone();
                let mut rest = path;
                while rest.first().is_some_and(|s| s == "super") {
                    base.pop();
                    rest = &rest[1..];
                }
                base.extend(rest.iter().cloned());
                Some(base)
            }
            "self" => {
                let mut base = module.clone();
                base.extend(path[1..].iter().cloned());
                Some(base)
            }
            child => {
                let mut m = module.clone();
                m.push(child.to_string());
                self.files.contains_key(&m).then(|| {
                    let mut base = module.clone();
                    base.extend(path.iter().cloned());
                    base
                })
            }
        }
    }

    /// The file that defines what `path` (absolute) names: the longest module prefix, then
    /// through that module's re-exports to the defining one.
    fn resolve(&self, path: &[String], depth: usize) -> Option<Module> {
        if depth > 16 {
            return None;
        }
        for k in (0..=path.len()).rev() {
            let module: Module = path[..k].to_vec();
            let Some(file) = self.files.get(&module) else {
                continue;
            };
            let rest = &path[k..];
            let Some(name) = rest.first().filter(|n| *n != "*") else {
                return Some(module);
            };
            if file.defs.contains(name) {
                return Some(module);
            }
            for u in &file.uses {
                let last = u.last().map(String::as_str);
                if last != Some(name.as_str()) && last != Some("*") {
                    continue;
                }
                let Some(mut target) = self.absolute(&module, u) else {
                    continue;
                };
                if last == Some("*") {
                    target.pop();
                    target.push(name.clone());
                }
                if let Some(found) = self.resolve(&target, depth + 1) {
                    return Some(found);
                }
            }
            return Some(module);
        }
        None
    }

    fn edges(&self) -> BTreeMap<Module, BTreeSet<Module>> {
        let mut edges = BTreeMap::new();
        for (module, file) in &self.files {
            let mut to = BTreeSet::new();
            for path in file.uses.iter().chain(&file.inline) {
                let Some(abs) = self.absolute(module, path) else {
                    continue;
                };
                if let Some(target) = self.resolve(&abs, 0) {
                    if &target != module && !target.is_empty() {
                        to.insert(target);
                    }
                }
            }
            edges.insert(module.clone(), to);
        }
        edges
    }
}

/// The strongly connected components with more than one module (Tarjan).
fn cycles(edges: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    struct State<'a> {
        edges: &'a BTreeMap<Module, BTreeSet<Module>>,
        index: BTreeMap<&'a Module, usize>,
        low: BTreeMap<&'a Module, usize>,
        stack: Vec<&'a Module>,
        on: BTreeSet<&'a Module>,
        out: Vec<Vec<Module>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a Module) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on.insert(v);
        for w in &s.edges[v] {
            if !s.edges.contains_key(w) {
                continue;
            }
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low[v];
                s.low.insert(v, lv.min(lw));
            } else if s.on.contains(w) {
                let iw = s.index[w];
                let lv = s.low[v];
                s.low.insert(v, lv.min(iw));
            }
        }
        if s.low[v] == s.index[v] {
            let mut scc = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on.remove(w);
                scc.push(w.clone());
                if w == v {
                    break;
                }
            }
            if scc.len() > 1 {
                scc.sort();
                s.out.push(scc);
            }
        }
    }
    let mut s = State {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    s.out
}

fn name(m: &Module) -> String {
    if m.is_empty() {
        "(root)".into()
    } else {
        m.join("::")
    }
}

fn report(src: &str) -> (usize, Vec<String>) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(src);
    let krate = Crate::load(&root);
    let edges = krate.edges();
    let n_edges = edges.values().map(BTreeSet::len).sum();
    let mut lines = Vec::new();
    for scc in cycles(&edges) {
        lines.push(format!(
            "cycle: {}",
            scc.iter().map(name).collect::<Vec<_>>().join(", ")
        ));
        for a in &scc {
            for b in &edges[a] {
                if scc.contains(b) {
                    lines.push(format!("  {} -> {}", name(a), name(b)));
                }
            }
        }
    }
    (n_edges, lines)
}

/// The crates whose module graphs are layered; the umbrella crate (the CLI) still has cycles
/// between a parent module and its helpers (ARCHITECTURE.md).
const LAYERED: [(&str, usize); 9] = [
    ("engine/src", 100),
    ("plugins/fem/src", 40),
    ("plugins/pbd/src", 30),
    ("plugins/render/src", 15),
    ("plugins/robots/src", 40),
    ("plugins/tasks/src", 20),
    ("learn/src", 50),
    ("dataset/src", 10),
    ("python/src", 1),
];

#[test]
fn the_engine_and_plugin_modules_form_no_import_cycle() {
    let mut all = Vec::new();
    for (src, at_least) in LAYERED {
        let (edges, cycles) = report(src);
        println!(
            "{src}: {edges} module edges, {} cycle lines (want 0)",
            cycles.len()
        );
        for l in &cycles {
            println!("{l}");
        }
        // The parser must see the graph at all.
        assert!(
            edges >= at_least,
            "{src}: only {edges} edges found (expected at least {at_least}): the parser is broken"
        );
        all.extend(cycles.into_iter().map(|l| format!("{src}: {l}")));
    }
    assert!(all.is_empty(), "import cycles:\n{}", all.join("\n"));
}

/// The checker finds a cycle when there is one (two modules importing each other, through a
/// re-exporting facade) and none in the same modules layered.
#[test]
fn the_cycle_check_finds_a_planted_cycle() {
    let dir = std::env::temp_dir().join(format!("modesuite-modgraph-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("scene")).unwrap();
    let write = |p: &str, t: &str| std::fs::write(dir.join(p), t).unwrap();
    write(
        "lib.rs",
        "pub mod app;\npub mod scene;\npub use app::App;\n",
    );
    write("scene/mod.rs", "mod desc;\npub use desc::Desc;\n");
    write(
        "scene/desc.rs",
        "// crate::app::App in a comment is no edge\npub struct Desc(u32);\nconst S: &str = \"crate::app::App\";\n",
    );
    write(
        "app.rs",
        "use crate::scene::Desc;\npub struct App(Desc);\n#[cfg(test)]\nmod tests { use crate::scene::*; }\n",
    );
    let krate = Crate::load(&dir);
    let layered = cycles(&krate.edges());
    println!("layered: {layered:?} (want none)");
    assert!(layered.is_empty());
    write(
        "scene/desc.rs",
        "pub struct Desc(u32);\nfn f() -> usize { std::mem::size_of::<crate::App>() }\n",
    );
    let krate = Crate::load(&dir);
    let found = cycles(&krate.edges());
    println!("planted: {found:?} (want app <-> scene::desc)");
    assert_eq!(
        found,
        vec![vec![
            vec!["app".to_string()],
            vec!["scene".to_string(), "desc".to_string()]
        ]]
    );
    let _ = std::fs::remove_dir_all(&dir);
}
