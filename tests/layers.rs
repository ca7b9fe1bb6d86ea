//! Issue 68: the library's layers point down. Every `crate::NAME` a top-level module of `src/`
//! names (grouped `crate::{a, b}` imports included, comments skipped) is an edge; the graph
//! has no circle, and the low stages (`render`, `video`, `audio`, `model` and what they stand
//! on) reach nothing of the talker, its mouths, footage, synthesis or the codec, not even
//! through another module.
use crate::common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

type Graph = BTreeMap<String, BTreeSet<String>>;

/// `text` without `//` comments (doc comments included) and `/* */` blocks.
fn code_of(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while !rest.is_empty() {
        let line_comment = rest.find("//");
        let block_comment = rest.find("/*");
        match (line_comment, block_comment) {
            (Some(l), b) if b.is_none_or(|b| l < b) => {
                out.push_str(&rest[..l]);
                rest = rest[l..].find('\n').map_or("", |end| &rest[l + end..]);
            }
            (_, Some(b)) => {
                out.push_str(&rest[..b]);
                rest = rest[b..].find("*/").map_or("", |end| &rest[b + end + 2..]);
            }
            _ => {
                out.push_str(rest);
                rest = "";
            }
        }
    }
    out
}

/// The first path segment of each item a `crate::` path names: `crate::a::x` gives `a`,
/// `crate::{a::x, b}` gives `a` and `b`.
fn named_after_crate(code: &str) -> Vec<String> {
    let mut names = Vec::new();
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    for (at, _) in code.match_indices("crate::") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue; // `my_crate::`, not ours (a macro's `$crate::` is ours)
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // Top-level items of the group, up to its closing brace.
            let (mut depth, mut start) = (0usize, 0usize);
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => {
                        names.push(ident(&group[start..i]));
                        break;
                    }
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        names.push(ident(&group[start..i]));
                        start = i + 1;
                    }
                    _ => {}
                }
            }
        } else {
            names.push(ident(rest));
        }
    }
    names.retain(|n| !n.is_empty());
    names
}

fn sources(dir: &Path, found: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, found);
        } else if path.extension().is_some_and(|e| e == "rs") {
            found.push(path);
        }
    }
}

/// The top-level modules of `src/` and which others each names.
fn module_graph(src: &Path) -> Graph {
    let mut graph = Graph::new();
    for entry in std::fs::read_dir(src).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        if name == "lib" || name == "main" || !(path.is_dir() || name.len() + 3 == path.file_name().unwrap().len()) {
            continue;
        }
        let mut files = Vec::new();
        if path.is_dir() {
            sources(&path, &mut files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path.clone());
        } else {
            continue;
        }
        let named = graph.entry(name.clone()).or_default();
        for file in files {
            let code = code_of(&std::fs::read_to_string(&file).unwrap());
            named.extend(named_after_crate(&code).into_iter().filter(|n| *n != name));
        }
    }
    let modules: BTreeSet<String> = graph.keys().cloned().collect();
    for named in graph.values_mut() {
        named.retain(|n| modules.contains(n)); // `crate::Progress` and the like
    }
    graph
}

/// Every module `from` reaches.
fn reach(graph: &Graph, from: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![from.to_owned()];
    while let Some(m) = stack.pop() {
        for next in graph.get(&m).into_iter().flatten() {
            if seen.insert(next.clone()) {
                stack.push(next.clone());
            }
        }
    }
    seen
}

/// The modules on a circle, each with one way round it.
fn circles(graph: &Graph) -> Vec<String> {
    graph
        .keys()
        .filter(|m| reach(graph, m).contains(*m))
        .map(|m| {
            // A shortest way back, by breadth-first search.
            let mut back: BTreeMap<String, String> = BTreeMap::new();
            let mut queue = std::collections::VecDeque::from([m.clone()]);
            while let Some(at) = queue.pop_front() {
                for next in &graph[&at] {
                    if !back.contains_key(next) {
                        back.insert(next.clone(), at.clone());
                        queue.push_back(next.clone());
                    }
                }
            }
            let mut way = vec![m.clone()];
            let mut at = back[m].clone();
            while at != *m {
                way.push(at.clone());
                at = back[&at].clone();
            }
            way.push(m.clone());
            way.reverse();
            way.join(" → ")
        })
        .collect()
}

#[test]
fn the_reader_finds_grouped_and_plain_imports() {
    let code = code_of(
        "use crate::{a::{x, y}, b};\n// crate::c\nlet v = crate::d::f(); /* crate::e */ $crate::g",
    );
    assert_eq!(named_after_crate(&code), ["a", "b", "d", "g"]);
    let graph: Graph = [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")]
        .into_iter()
        .fold(Graph::new(), |mut g, (from, to)| {
            g.entry(from.into()).or_default().insert(to.into());
            g.entry(to.into()).or_default();
            g
        });
    assert_eq!(circles(&graph), ["a → b → c → a", "b → c → a → b", "c → a → b → c"]);
}

#[test]
fn the_layers_point_down() {
    let graph = module_graph(&common::root().join("src"));
    assert!(graph.len() > 30 && graph["talker"].contains("synth"), "{graph:?}");
    let found = circles(&graph);
    assert!(found.is_empty(), "import circles:\n{}", found.join("\n"));
    let high = ["talker", "mouths", "footage", "synth", "codec", "live", "sound_to_face"];
    for low in ["render", "video", "audio", "model", "mp4_file", "warp", "mesh", "npy", "manifest"] {
        let wrong: Vec<_> = reach(&graph, low).into_iter().filter(|m| high.contains(&m.as_str())).collect();
        assert!(wrong.is_empty(), "{low} reaches {wrong:?}");
    }
}
