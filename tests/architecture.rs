//! ARCHITECTURE.md is checked where it names code: its crate table lists exactly the workspace's
//! packages, every file it names exists, and every `crate::item` it names is a module, function or
//! type of that crate.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// ARCHITECTURE.md without its fenced blocks (drawings, whose backticks are not code spans).
fn architecture() -> String {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut fenced = false;
    let mut prose = String::new();
    for line in text.lines() {
        if line.starts_with("```") {
            fenced = !fenced;
        } else if !fenced {
            prose.push_str(line);
            prose.push('\n');
        }
    }
    prose
}

/// Every file of the repository (no build output, no git, no vendored or installed packages).
fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.')
            || ["target", "node_modules", "vendor", "__pycache__"].contains(&name.as_str())
        {
            continue;
        }
        if path.is_dir() {
            files(&path, out);
        } else {
            out.push(path);
        }
    }
}

/// The backticked spans of `text`.
fn spans(text: &str) -> impl Iterator<Item = &str> {
    text.split('`').skip(1).step_by(2)
}

/// The workspace's members: (directory, package name).
fn members() -> Vec<(String, String)> {
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).expect("Cargo.toml");
    let list = manifest.split("members = [").nth(1).and_then(|m| m.split(']').next()).expect("members");
    list.split('"')
        .skip(1)
        .step_by(2)
        .map(|dir| {
            let cargo =
                std::fs::read_to_string(root().join(dir).join("Cargo.toml")).expect("a member's Cargo.toml");
            let name = cargo.lines().find_map(|l| l.strip_prefix("name = \"")).expect("a package name");
            (dir.to_string(), name.trim_end_matches('"').to_string())
        })
        .collect()
}

#[test]
fn the_crate_table_lists_exactly_the_workspace_packages() {
    let text = architecture();
    let table: BTreeSet<String> = text
        .lines()
        .filter(|l| l.starts_with("| `"))
        .filter_map(|l| spans(l).next().map(str::to_string))
        .collect();
    let packages: BTreeSet<String> = members().into_iter().map(|(_, name)| name).collect();
    assert_eq!(table, packages, "ARCHITECTURE.md's crate table and the workspace's members differ");
}

#[test]
fn every_file_the_architecture_names_exists() {
    let mut all = Vec::new();
    files(&root(), &mut all);
    let root = root();
    let relative: Vec<String> = all
        .iter()
        .filter_map(|p| p.strip_prefix(&root).ok())
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let text = architecture();
    let named: BTreeSet<&str> = spans(&text)
        .filter(|s| !s.contains(char::is_whitespace))
        .filter(|s| [".rs", ".js", ".py", ".json", ".toml", ".html", ".onnx"].iter().any(|e| s.ends_with(e)))
        .collect();
    assert!(named.len() > 40, "the file names were found ({})", named.len());
    let missing: Vec<&&str> = named
        .iter()
        .filter(|name| !relative.iter().any(|f| f == *name || f.ends_with(&format!("/{name}"))))
        .collect();
    assert!(missing.is_empty(), "ARCHITECTURE.md names files that do not exist: {missing:?}");
}

/// Whether `code` defines `name` (an item, a module, an enum variant or a field).
fn defines(code: &str, name: &str) -> bool {
    let item = ["mod ", "fn ", "struct ", "enum ", "trait ", "type ", "const ", "static "]
        .iter()
        .any(|k| code.contains(&format!("{k}{name}")));
    let variant = code.lines().map(str::trim_start).any(|l| {
        l.strip_prefix(name)
            .is_some_and(|rest| rest.starts_with('(') || rest.starts_with(" {") || rest.starts_with(','))
    });
    let field = code.lines().map(str::trim_start).any(|l| {
        l.strip_prefix("pub ").unwrap_or(l).strip_prefix(name).is_some_and(|rest| rest.starts_with(':'))
    });
    item || variant || field
}

#[test]
fn every_item_the_architecture_names_exists() {
    let crates: Vec<(String, String)> =
        members().into_iter().map(|(dir, name)| (dir, name.replace('-', "_"))).collect();
    let sources_of = |dirs: &[&str]| {
        let mut sources = Vec::new();
        for dir in dirs {
            files(&root().join(dir).join("src"), &mut sources);
        }
        sources.retain(|p| p.extension().is_some_and(|e| e == "rs"));
        sources.into_iter().map(|p| (std::fs::read_to_string(&p).unwrap_or_default(), p)).collect::<Vec<_>>()
    };
    let all_dirs: Vec<&str> = crates.iter().map(|(dir, _)| dir.as_str()).collect();
    let everything = sources_of(&all_dirs);
    let names_a_file = |sources: &[(String, PathBuf)], name: &str| {
        sources.iter().any(|(_, p)| {
            p.file_stem().is_some_and(|s| s == name)
                || p.parent().and_then(Path::file_name).is_some_and(|d| d == name)
        })
    };
    let text = architecture();
    let (mut checked, mut missing) = (0, Vec::new());
    for span in spans(&text).filter(|s| s.contains("::") && !s.contains(char::is_whitespace)) {
        let parts: Vec<&str> = span.split("::").map(|p| p.trim_end_matches("()")).collect();
        let (first, rest) = (parts[0], &parts[1..]);
        // Which sources the rest is looked up in: a crate of the workspace, or all of it when the
        // first part is one of its types or modules; anything else (tokio's `watch`) is not ours.
        let sources = match crates.iter().find(|(_, name)| name == first) {
            Some((dir, _)) => sources_of(&[dir.as_str()]),
            None if defines_any(&everything, first) || names_a_file(&everything, first) => everything.clone(),
            None => continue,
        };
        checked += 1;
        let found = rest
            .iter()
            .all(|name| names_a_file(&sources, name) || sources.iter().any(|(code, _)| defines(code, name)));
        if !found {
            missing.push(span.to_string());
        }
    }
    assert!(checked > 50, "the code names were found ({checked})");
    assert!(missing.is_empty(), "ARCHITECTURE.md names code that does not exist: {missing:?}");
}

fn defines_any(sources: &[(String, PathBuf)], name: &str) -> bool {
    name.chars().next().is_some_and(char::is_uppercase) && sources.iter().any(|(code, _)| defines(code, name))
}
