//! The house rules of issue 28 §1, read from the sources: each top-level module imports only
//! the layers below it (the table in [`LAYERS`], the order README's module map gives), and no
//! two files import each other, directly or round a longer cycle (the `vk/` files among
//! themselves excepted). An import is a `crate::…` or `super::…` path outside comments and
//! unit tests; it is resolved to the longest module prefix that is a file.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Each top-level module with the modules it may import (space-separated), bottom up.
const LAYERS: &[(&str, &str)] = &[
    ("files", ""),
    ("vk", "files"),
    ("data", "files"),
    ("samples", "data files"),
    ("recon", "data files samples"),
    ("gpu_types", "recon samples vk"),
    ("view", "data gpu_types"),
    ("field", "data files gpu_types recon samples view vk"),
    (
        "raycast",
        "data field files gpu_types recon samples view vk",
    ),
    ("splat", "data field files gpu_types recon samples view vk"),
    (
        "renderer",
        "data field files gpu_types raycast recon samples splat view vk",
    ),
    (
        "bricks",
        "data field files gpu_types raycast recon renderer samples splat view vk",
    ),
    (
        "distributed",
        "bricks data field files gpu_types raycast recon renderer samples splat view vk",
    ),
    (
        "scene",
        "data field files gpu_types raycast recon renderer samples splat view vk",
    ),
];

/// The command line's modules (cargo feature `cli`): they may import anything in the library.
const CLI: &[&str] = &["output", "bench", "check", "probe", "info"];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("src is readable") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            if path.file_name().is_some_and(|n| n != "bin") {
                rust_files(&path, out);
            }
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module path of a source file: `src/field/mod.rs` → [field], `src/field/gpu.rs` →
/// [field, gpu], `src/lib.rs` → [].
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file
        .strip_prefix(src)
        .expect("under src")
        .with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts
}

/// The code of a file without its unit tests and comments (doc links are not imports).
fn code(text: &str) -> String {
    let text = text.split("#[cfg(test)]").next().unwrap_or(text);
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The paths a file's code names: `crate::a::b…` and `super::…` (each brace item of a grouped
/// `use` as its own path), as absolute module paths.
fn named_paths(me: &[String], code: &str) -> Vec<Vec<String>> {
    let bytes = code.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let starts = (bytes[i..].starts_with(b"crate::") || bytes[i..].starts_with(b"super::"))
            && (i == 0 || !ident(bytes[i - 1]));
        if !starts {
            i += 1;
            continue;
        }
        // Read `seg::seg::…`, stopping at a brace group or anything else.
        let mut segments = Vec::new();
        let mut j = i;
        loop {
            let k = j + code[j..].bytes().take_while(|&c| ident(c)).count();
            if k == j {
                break;
            }
            segments.push(code[j..k].to_string());
            if code[k..].starts_with("::") {
                j = k + 2;
            } else {
                j = k;
                break;
            }
        }
        let mut base: Vec<String> = Vec::new();
        let mut rest = segments.as_slice();
        if rest.first().is_some_and(|s| s == "crate") {
            rest = &rest[1..];
        } else {
            base = me.to_vec();
            while rest.first().is_some_and(|s| s == "super") {
                base.pop();
                rest = &rest[1..];
            }
        }
        base.extend(rest.iter().cloned());
        if code[j..].starts_with('{') {
            let end = code[j..].find('}').map_or(code.len(), |e| j + e);
            for item in code[j + 1..end].split(',') {
                let first = item.trim().split("::").next().unwrap_or("").trim();
                if !first.is_empty() && first != "self" {
                    let mut path = base.clone();
                    path.push(first.to_string());
                    out.push(path);
                }
            }
            i = end;
        } else {
            out.push(base);
            i = j.max(i + 1);
        }
    }
    out
}

struct Graph {
    /// File → the files it imports.
    edges: BTreeMap<PathBuf, BTreeSet<PathBuf>>,
    modules: BTreeMap<PathBuf, Vec<String>>,
}

fn graph() -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let modules: BTreeMap<PathBuf, Vec<String>> = files
        .iter()
        .map(|f| (f.clone(), module_of(&src, f)))
        .collect();
    let by_module: BTreeMap<&[String], &PathBuf> =
        modules.iter().map(|(f, m)| (m.as_slice(), f)).collect();
    let mut edges = BTreeMap::new();
    for (file, me) in &modules {
        let text = std::fs::read_to_string(file).expect("source is readable");
        let mut to = BTreeSet::new();
        for path in named_paths(me, &code(&text)) {
            let target = (1..=path.len())
                .rev()
                .find_map(|k| by_module.get(&path[..k]));
            if let Some(&t) = target
                && t != file
            {
                to.insert(t.clone());
            }
        }
        edges.insert(file.clone(), to);
    }
    Graph { edges, modules }
}

#[test]
fn each_module_imports_only_the_layers_below_it() {
    let g = graph();
    let allowed: BTreeMap<&str, Vec<&str>> = LAYERS
        .iter()
        .map(|(m, may)| (*m, may.split_whitespace().collect()))
        .collect();
    let mut wrong = Vec::new();
    for (file, to) in &g.edges {
        let Some(from) = g.modules[file].first() else {
            continue;
        };
        if CLI.contains(&from.as_str()) {
            continue;
        }
        let Some(may) = allowed.get(from.as_str()) else {
            wrong.push(format!("{}: module `{from}` has no layer", file.display()));
            continue;
        };
        for t in to {
            let Some(target) = g.modules[t].first() else {
                continue;
            };
            if target != from && !may.contains(&target.as_str()) {
                wrong.push(format!("{} imports {}", file.display(), t.display()));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "imports against the layers:\n{}",
        wrong.join("\n")
    );
}

#[test]
fn no_two_files_import_each_other_outside_vk() {
    let g = graph();
    // Tarjan's strongly connected components; any of more than one file is a cycle.
    struct State<'a> {
        edges: &'a BTreeMap<PathBuf, BTreeSet<PathBuf>>,
        index: BTreeMap<&'a PathBuf, usize>,
        low: BTreeMap<&'a PathBuf, usize>,
        stack: Vec<&'a PathBuf>,
        cycles: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a PathBuf) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        for w in &s.edges[v] {
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(lw);
            } else if s.stack.contains(&w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                component.push(w.display().to_string());
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                s.cycles.push(component);
            }
        }
    }
    let mut s = State {
        edges: &g.edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        cycles: Vec::new(),
    };
    for v in g.edges.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    let cycles: Vec<_> = s
        .cycles
        .into_iter()
        .filter(|c| !c.iter().all(|f| f.contains("/src/vk/")))
        .collect();
    assert!(cycles.is_empty(), "import cycles: {cycles:#?}");
}

#[test]
fn the_checker_sees_an_import_and_a_cycle() {
    // The parser on a grouped `use` through `super`, so that a clean result above means
    // something: a file in field/ naming raycast and a sibling.
    let me = vec!["field".to_string(), "gpu".to_string()];
    let paths = named_paths(
        &me,
        "use super::{resample::grid, Field};\nlet x = crate::raycast::setup::RaySetup::new();",
    );
    assert!(paths.contains(&vec!["field".into(), "resample".into()]));
    assert!(paths.contains(&vec!["field".into(), "Field".into()]));
    assert!(paths.contains(&vec![
        "raycast".into(),
        "setup".into(),
        "RaySetup".into(),
        "new".into()
    ]));
    assert!(!code("// crate::splat::x\nfn f() {}").contains("crate::"));
}
