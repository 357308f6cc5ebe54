//! A library's modules keep to the layers its crate doc (`src/lib.rs`, "Layers") gives them:
//! every module of the crate is in one layer, and outside tests each module uses (by a `crate::`
//! path, or a `super::` path that leaves it) only modules of lower layers. A use from a lower
//! layer to a higher one would be the start of a circle. `tests/e2e/layers.rs` checks the
//! instrument and the server with [`check`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The layer of each top-level module, from the crate doc's table (`//! | N | `a`, `b` | … |`).
pub fn layers(lib: &str) -> BTreeMap<String, u32> {
    let mut out = BTreeMap::new();
    for line in lib.lines() {
        let Some(row) = line.strip_prefix("//! |") else {
            continue;
        };
        let mut cells = row.split('|').map(str::trim);
        let Some(Ok(layer)) = cells.next().map(str::parse::<u32>) else {
            continue;
        };
        for name in cells.next().unwrap_or("").split(',') {
            let name = name.trim().trim_matches('`');
            assert!(
                out.insert(name.to_string(), layer).is_none(),
                "`{name}` is in two layers of the crate doc"
            );
        }
    }
    out
}

/// The top-level modules `lib.rs` declares.
pub fn declared(lib: &str) -> Vec<String> {
    lib.lines()
        .filter_map(|l| {
            let l = l.trim_start_matches("pub ");
            l.strip_prefix("mod ")?.strip_suffix(';').map(str::to_string)
        })
        .collect()
}

/// The source with comments, string and character literals blanked out (each replaced by a
/// space), so that what is left is code: paths, braces, attributes.
pub fn code_only(src: &str) -> String {
    let c: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < c.len() {
        let rest = |k: usize| c.get(i + k).copied().unwrap_or('\0');
        if c[i] == '/' && rest(1) == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if c[i] == '/' && rest(1) == '*' {
            i += 2;
            while i + 1 < c.len() && !(c[i] == '*' && c[i + 1] == '/') {
                i += 1;
            }
            i += 2;
            out.push(' ');
        } else if c[i] == 'r' && (rest(1) == '"' || (rest(1) == '#' && (rest(2) == '"' || rest(2) == '#'))) {
            // A raw string: r"…", r#"…"#.
            let mut hashes = 0;
            i += 1;
            while i < c.len() && c[i] == '#' {
                hashes += 1;
                i += 1;
            }
            i += 1;
            while i < c.len() && !(c[i] == '"' && (0..hashes).all(|h| c.get(i + 1 + h) == Some(&'#'))) {
                i += 1;
            }
            i += 1 + hashes;
            out.push(' ');
        } else if c[i] == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
            out.push(' ');
        } else if c[i] == '\'' && (rest(1) == '\\' || rest(2) == '\'') {
            // A character literal ('x', '\n', '\''); a lifetime ('a) is code.
            i += if rest(1) == '\\' { 3 } else { 2 };
            while i < c.len() && c[i] != '\'' {
                i += 1;
            }
            i += 1;
            out.push(' ');
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

/// `code` without its `#[cfg(test)]` items (a `mod tests { … }`, a test helper, `mod tests;`).
pub fn without_tests(code: &str) -> String {
    let mut out = String::new();
    let mut rest = code;
    while let Some(at) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..at]);
        let item = &rest[at + "#[cfg(test)]".len()..];
        // The item ends at a `;` before any brace, or at the brace that closes its first one.
        let mut depth = 0usize;
        let mut end = item.len();
        for (k, ch) in item.char_indices() {
            match ch {
                ';' if depth == 0 => {
                    end = k + 1;
                    break;
                }
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = k + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        rest = &item[end..];
    }
    out.push_str(rest);
    out
}

/// The files a `#[cfg(test)] mod NAME;` of `code` (in `file`) declares.
pub fn test_files(file: &Path, code: &str) -> Vec<PathBuf> {
    let dir = if file.file_name().is_some_and(|n| n == "mod.rs" || n == "lib.rs") {
        file.parent().unwrap().to_path_buf()
    } else {
        file.with_extension("")
    };
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find("#[cfg(test)]") {
        rest = &rest[at + "#[cfg(test)]".len()..];
        let item = rest.trim_start();
        let item = item.strip_prefix("pub(crate) ").unwrap_or(item);
        if let Some(name) = item
            .strip_prefix("mod ")
            .and_then(|m| m.split_once(';'))
            .map(|(n, _)| n.trim())
        {
            if !name.contains('{') {
                out.push(dir.join(format!("{name}.rs")));
                out.push(dir.join(name).join("mod.rs"));
            }
        }
    }
    out
}

/// The module path of a source file under `src` (`session/commands/mod.rs` is
/// `["session", "commands"]`).
pub fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts
}

/// The top-level modules the paths of `code` (in module `module`) lead to.
pub fn uses(module: &[String], code: &str) -> Vec<String> {
    let ident = |s: &str| -> String { s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect() };
    let mut out = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        if code[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let path = &code[at + "crate::".len()..];
        if let Some(group) = path.strip_prefix('{') {
            let group = &group[..group.find('}').unwrap_or(group.len())];
            out.extend(group.split(',').map(|p| ident(p.trim())).filter(|p| !p.is_empty()));
        } else {
            out.push(ident(path));
        }
    }
    for (at, _) in code.match_indices("super::") {
        if code[..at].ends_with("super::") || code[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let mut path = &code[at..];
        let mut up = 0;
        while let Some(p) = path.strip_prefix("super::") {
            up += 1;
            path = p;
        }
        // From a module `m` (not its children), `super::` is `m`'s parent.
        if up >= module.len() {
            out.push(ident(path));
        }
    }
    out.retain(|m| !m.is_empty() && m != "self" && m != "super");
    out
}

/// Every `.rs` file under `dir`, into `out`.
pub fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            sources(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The modules of the library whose sources are in `src` against its crate doc's layers:
/// `Err` lists each module outside the table or a table entry with no module, and each use
/// against the layers (file, module, layer, used module, its layer).
pub fn check(src: &Path) -> Result<usize, String> {
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    let layer = layers(&lib);
    let mut declared = declared(&lib);
    declared.sort();
    let placed: Vec<String> = layer.keys().cloned().collect();
    if declared != placed {
        return Err(format!(
            "each module of lib.rs in one layer of its doc, and no other: declared {declared:?}, placed {placed:?}"
        ));
    }

    let mut files = Vec::new();
    sources(src, &mut files);
    let mut tests = Vec::new();
    let mut code = BTreeMap::new();
    for f in &files {
        let text = code_only(&std::fs::read_to_string(f).unwrap());
        tests.extend(test_files(f, &text));
        code.insert(f.clone(), text);
    }
    let mut wrong = Vec::new();
    let mut checked = 0;
    for (f, text) in code.iter().filter(|(f, _)| !tests.contains(f)) {
        let module = module_of(src, f);
        let Some(top) = module.first() else { continue };
        for used in uses(&module, &without_tests(text)) {
            if used == *top {
                continue;
            }
            checked += 1;
            match (layer.get(top), layer.get(&used)) {
                (Some(a), Some(b)) if b < a => {}
                (a, b) => wrong.push(format!(
                    "{}: `{top}` (layer {a:?}) uses `{used}` (layer {b:?})",
                    f.strip_prefix(src).unwrap().display()
                )),
            }
        }
    }
    if wrong.is_empty() {
        Ok(checked)
    } else {
        Err(format!("uses against the layers:\n{}", wrong.join("\n")))
    }
}
