//! No library crate's modules form a cycle: in each crate under crates/, every `crate::`, `super::` and `self::` path (in `use` lines and in code, grouped imports included) is an edge between modules, lifted to the two children of their nearest common module; each module's children must form an acyclic graph. Between crates, Cargo forbids cycles itself; the last test checks that only the binary's package takes clap.
//!
//! A module and its own submodules (a type's `impl` split over files) are one unit: edges
//! between a module and its ancestors or descendants are not counted. Comments and string
//! literals are left out, so a doc link is not an import. The binary (src/main.rs, src/cli/) is
//! its own crate and is not checked here; the top package's src/lib.rs only re-exports. Known limit: an item a parent re-exports from one
//! child and another child takes through `super::` is seen as an edge to the parent only.

use std::collections::{BTreeMap, BTreeSet};

use std::path::{Path, PathBuf};

type Module = Vec<String>;

/// Every library source file and its module path.
fn library_files(src: &Path) -> Vec<(PathBuf, Module)> {
    fn walk(dir: &Path, prefix: &Module, out: &mut Vec<(PathBuf, Module)>) {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .collect();
        entries.sort();
        for path in entries {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                let mut m = prefix.clone();
                m.push(name);
                walk(&path, &m, out);
            } else if let Some(stem) = name.strip_suffix(".rs") {
                let mut m = prefix.clone();
                if stem != "mod" && stem != "lib" {
                    m.push(stem.to_string());
                }
                out.push((path, m));
            }
        }
    }
    let mut out = Vec::new();
    walk(src, &Vec::new(), &mut out);
    out.retain(|(p, m)| !p.ends_with("main.rs") && m.first().map(String::as_str) != Some("cli"));
    out
}

/// The source with comments and the contents of string and char literals blanked (line
/// structure kept, so line numbers stay).
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            let mut depth = 0;
            while i < b.len() {
                if b[i..].starts_with(b"/*") {
                    depth += 1;
                    i += 2;
                } else if b[i..].starts_with(b"*/") {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if b[i] == b'\n' {
                        out.push(b'\n');
                    }
                    i += 1;
                }
            }
        } else if b[i] == b'r'
            && (b.get(i + 1) == Some(&b'"') || b.get(i + 1) == Some(&b'#'))
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
        {
            // Raw string r"…" or r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&b'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&b'"') {
                out.push(b[i]);
                i += 1;
                continue;
            }
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            j += 1;
            while j < b.len() && !b[j..].starts_with(&close) {
                if b[j] == b'\n' {
                    out.push(b'\n');
                }
                j += 1;
            }
            out.extend_from_slice(b"\"\"");
            i = (j + close.len()).min(b.len());
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                if b[i] == b'\\' {
                    i += 1;
                }
                if i < b.len() && b[i] == b'\n' {
                    out.push(b'\n');
                }
                i += 1;
            }
            out.extend_from_slice(b"\"\"");
            i += 1;
        } else if b[i] == b'\'' {
            // A char literal ('a', '\n', '\u{..}') or a lifetime ('a): skip a literal only.
            let lit_end = if b.get(i + 1) == Some(&b'\\') {
                b[i + 2..]
                    .iter()
                    .position(|&c| c == b'\'')
                    .map(|p| i + 2 + p)
            } else if b.get(i + 2) == Some(&b'\'') {
                Some(i + 2)
            } else {
                // A multi-byte char: find the closing quote within 5 bytes.
                b[i + 1..(i + 6).min(b.len())]
                    .iter()
                    .position(|&c| c == b'\'')
                    .map(|p| i + 1 + p)
                    .filter(|&e| e > i + 2 && !b[i + 1..e].iter().any(|c| c.is_ascii()))
            };
            match lit_end {
                Some(e) => {
                    out.extend_from_slice(b"' '");
                    i = e + 1;
                }
                None => {
                    out.push(b'\'');
                    i += 1;
                }
            }
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn is_ident_byte(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// Every path that starts with `crate`, `super` or `self` on a line: its segments (a grouped
/// import `super::{a::b, c}` gives one path per entry, with its first segment).
fn paths_in(line: &str) -> Vec<Vec<String>> {
    let b = line.as_bytes();
    let mut found = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts_word = i == 0 || !(is_ident_byte(b[i - 1]) || b[i - 1] == b':');
        let head = ["crate::", "super::", "self::"]
            .into_iter()
            .find(|h| b[i..].starts_with(h.as_bytes()));
        let (true, Some(_)) = (starts_word, head) else {
            i += 1;
            continue;
        };
        let mut segs = Vec::new();
        let mut j = i;
        loop {
            let s = j;
            while j < b.len() && is_ident_byte(b[j]) {
                j += 1;
            }
            if j == s {
                break;
            }
            segs.push(line[s..j].to_string());
            if b[j..].starts_with(b"::") {
                j += 2;
            } else {
                break;
            }
        }
        if b.get(j) == Some(&b'{') {
            // A group: each top-level entry's first segment.
            let mut depth = 0;
            let mut k = j;
            let mut entry_start = j + 1;
            while k < b.len() {
                match b[k] {
                    b'{' => depth += 1,
                    b'}' | b',' if depth == 1 => {
                        let entry = line[entry_start..k].trim();
                        let first: String = entry
                            .chars()
                            .take_while(|c| c.is_alphanumeric() || *c == '_')
                            .collect();
                        if !first.is_empty() {
                            let mut p = segs.clone();
                            p.push(first);
                            found.push(p);
                        }
                        entry_start = k + 1;
                        if b[k] == b'}' {
                            break;
                        }
                    }
                    b'}' => depth -= 1,
                    _ => {}
                }
                k += 1;
            }
            j = k;
        } else {
            found.push(segs);
        }
        i = j.max(i + 1);
    }
    found
}

/// The module a path names: the longest known module along it.
fn resolve(from: &Module, path: &[String], modules: &BTreeSet<Module>) -> Option<Module> {
    let mut m = from.clone();
    let mut rest = path;
    match path.first().map(String::as_str) {
        Some("crate") => {
            m.clear();
            rest = &path[1..];
        }
        Some("self") => rest = &path[1..],
        Some("super") => {
            while rest.first().map(String::as_str) == Some("super") {
                m.pop()?;
                rest = &rest[1..];
            }
        }
        _ => return None,
    }
    for seg in rest {
        let mut next = m.clone();
        next.push(seg.clone());
        if modules.contains(&next) {
            m = next;
        } else {
            break;
        }
    }
    Some(m)
}

/// The `src` folder of every library crate of the workspace.
fn library_crates() -> Vec<PathBuf> {
    let crates = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates");
    let mut out: Vec<PathBuf> = std::fs::read_dir(&crates)
        .unwrap()
        .flatten()
        .map(|e| e.path().join("src"))
        .filter(|src| src.join("lib.rs").is_file())
        .collect();
    out.sort();
    out
}

#[test]
fn no_library_crate_has_a_module_cycle() {
    let crates = library_crates();
    assert!(
        crates.len() >= 7,
        "crates/ lost its library crates: {crates:?}"
    );
    let mut cycles = Vec::new();
    let mut edge_count = 0;
    for src in &crates {
        let (edges, found) = module_cycles(src);
        edge_count += edges;
        cycles.extend(found);
    }
    assert!(
        edge_count > 50,
        "too few edges found: the path reader is broken"
    );
    assert!(
        cycles.is_empty(),
        "module cycles (each line: an edge and one place that makes it):\n{}",
        cycles.join("\n")
    );
}

/// The number of edges between sibling modules in one crate, and its cycles in words.
fn module_cycles(src: &Path) -> (usize, Vec<String>) {
    let crate_name = src
        .parent()
        .unwrap()
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    let files = library_files(src);
    let modules: BTreeSet<Module> = files.iter().map(|(_, m)| m.clone()).collect();
    // For each common module: edges between two of its children, with one place each shows.
    let mut graphs: BTreeMap<Module, BTreeMap<(String, String), String>> = BTreeMap::new();
    for (path, from) in &files {
        let text = std::fs::read_to_string(path).unwrap();
        let code = code_only(&text);
        for (n, line) in code.lines().enumerate() {
            for p in paths_in(line) {
                let Some(to) = resolve(from, &p, &modules) else {
                    continue;
                };
                let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
                if common == from.len() || common == to.len() {
                    continue; // the same module, an ancestor or a descendant
                }
                let parent = from[..common].to_vec();
                let edge = (from[common].clone(), to[common].clone());
                let place = format!(
                    "{}:{} ({})",
                    path.strip_prefix(src).unwrap().display(),
                    n + 1,
                    p.join("::")
                );
                graphs
                    .entry(parent)
                    .or_default()
                    .entry(edge)
                    .or_insert(place);
            }
        }
    }
    let mut cycles = Vec::new();
    for (parent, edges) in &graphs {
        for scc in strongly_connected(edges) {
            let key = parent.join("::");
            let inside: Vec<String> = edges
                .iter()
                .filter(|((a, b), _)| scc.contains(a) && scc.contains(b))
                .map(|((a, b), at)| format!("    {a} -> {b}: {at}"))
                .collect();
            cycles.push(format!(
                "in crates/{crate_name}, crate::{key}: {}\n{}",
                scc.iter().cloned().collect::<Vec<_>>().join(", "),
                inside.join("\n")
            ));
        }
    }
    (graphs.values().map(BTreeMap::len).sum::<usize>(), cycles)
}

/// Only the binary's package (the top Cargo.toml) names clap: the library crates speak in
/// types, and the command line's words live in src/cli/.
#[test]
fn only_the_binary_takes_clap() {
    for src in library_crates() {
        let manifest = src.parent().unwrap().join("Cargo.toml");
        let text = std::fs::read_to_string(&manifest).unwrap();
        let table: toml::Table = text.parse().unwrap();
        for section in ["dependencies", "dev-dependencies", "build-dependencies"] {
            if let Some(deps) = table.get(section).and_then(|d| d.as_table()) {
                assert!(
                    !deps.contains_key("clap"),
                    "{} takes clap in [{section}]",
                    manifest.display()
                );
            }
        }
        let mut files = Vec::new();
        collect_rs(&src, &mut files);
        for file in files {
            let code = code_only(&std::fs::read_to_string(&file).unwrap());
            assert!(!code.contains("clap::"), "{} names clap", file.display());
        }
    }
    let top: toml::Table =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml"))
            .unwrap()
            .parse()
            .unwrap();
    assert!(
        top["dependencies"].as_table().unwrap().contains_key("clap"),
        "the check reads the wrong manifest"
    );
}

fn collect_rs(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        if path.is_dir() {
            collect_rs(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The strongly connected components with more than one node (Tarjan).
fn strongly_connected(edges: &BTreeMap<(String, String), String>) -> Vec<BTreeSet<String>> {
    let mut nodes: BTreeSet<&String> = BTreeSet::new();
    let mut adj: BTreeMap<&String, Vec<&String>> = BTreeMap::new();
    for (a, b) in edges.keys() {
        nodes.insert(a);
        nodes.insert(b);
        adj.entry(a).or_default().push(b);
    }
    struct State<'a> {
        index: BTreeMap<&'a String, usize>,
        low: BTreeMap<&'a String, usize>,
        stack: Vec<&'a String>,
        on_stack: BTreeSet<&'a String>,
        next: usize,
        out: Vec<BTreeSet<String>>,
    }
    fn visit<'a>(v: &'a String, adj: &BTreeMap<&'a String, Vec<&'a String>>, s: &mut State<'a>) {
        s.index.insert(v, s.next);
        s.low.insert(v, s.next);
        s.next += 1;
        s.stack.push(v);
        s.on_stack.insert(v);
        for &w in adj.get(v).map(Vec::as_slice).unwrap_or(&[]) {
            if !s.index.contains_key(w) {
                visit(w, adj, s);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = BTreeSet::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                comp.insert(w.clone());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                s.out.push(comp);
            }
        }
    }
    let mut s = State {
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in nodes {
        if !s.index.contains_key(v) {
            visit(v, &adj, &mut s);
        }
    }
    s.out
}

#[test]
fn the_path_reader_finds_grouped_and_nested_paths() {
    let line =
        "use super::{gcode::{dist, lerp}, reach}; let x = crate::geom::Axis::Z; self::a::b();";
    let p = paths_in(line);
    assert!(p.contains(&vec!["super".into(), "gcode".into()]), "{p:?}");
    assert!(p.contains(&vec!["super".into(), "reach".into()]), "{p:?}");
    assert!(p.contains(&vec![
        "crate".into(),
        "geom".into(),
        "Axis".into(),
        "Z".into()
    ]));
    assert!(p.contains(&vec!["self".into(), "a".into(), "b".into()]));
    let code = code_only("let s = \"crate::x::y\"; // crate::z\n/// [`crate::w`]\nlet c = '\"';");
    assert!(paths_in(&code).is_empty(), "{code}");
    assert_eq!(code.lines().count(), 3);
}
