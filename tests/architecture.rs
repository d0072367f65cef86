//! The module boundaries of `docs/architecture.md` (DESIGN section 4 as amended there),
//! checked on the source: every `crate::<module>` path and every external crate named in the
//! library's non-test code must be one its module may use. A test module (`#[cfg(test)]`,
//! inline or in a `tests.rs`) may use anything, so it is cut before the check.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// What each top-level module of `src/` may import from the crate (besides itself): exactly
/// what it does import (`every_allowed_import_is_used`). `rng`, `stats`, `cache`, `boxqp`
/// and `edit` are leaves; `sim` uses the box solver only.
const ALLOWED: &[(&str, &[&str])] = &[
    ("rng", &[]),
    ("stats", &[]),
    ("cache", &[]),
    ("boxqp", &[]),
    ("edit", &[]),
    ("sim", &["boxqp"]),
    ("observe", &["sim", "rng", "stats"]),
    ("learn", &["stats"]),
    ("cohort", &["sim", "observe", "rng"]),
    ("landmark", &["sim", "observe"]),
    ("io", &["sim", "observe", "landmark", "cache"]),
    (
        "dataset",
        &["sim", "observe", "io", "landmark", "report", "rng"],
    ),
    ("headneck", &["sim", "learn", "rng"]),
    (
        "spec",
        &[
            "sim", "observe", "learn", "cohort", "io", "dataset", "headneck",
        ],
    ),
    ("report", &["sim", "observe"]),
    ("judge", &["sim", "landmark", "report", "stats"]),
    (
        "run",
        &[
            "sim", "observe", "learn", "io", "dataset", "rng", "spec", "cache",
        ],
    ),
    (
        "transfer",
        &[
            "sim", "observe", "learn", "landmark", "io", "dataset", "headneck", "boxqp", "stats",
            "spec", "report", "judge", "run",
        ],
    ),
    (
        "experiments",
        &[
            "sim", "observe", "learn", "cohort", "io", "dataset", "headneck", "boxqp", "rng",
            "stats", "spec", "cache", "report", "judge", "run", "transfer",
        ],
    ),
    (
        "tools",
        &[
            "sim",
            "observe",
            "learn",
            "cohort",
            "landmark",
            "io",
            "headneck",
            "rng",
            "stats",
            "edit",
            "spec",
            "cache",
            "report",
            "judge",
            "transfer",
            "experiments",
        ],
    ),
];

/// Which modules may name each external crate directly.
const EXTERNAL: &[(&str, &[&str])] = &[
    ("toml", &["spec"]),
    ("plotters", &["report"]),
    ("gif", &["report"]),
    ("candle_core", &["learn", "landmark"]),
    ("candle_nn", &["learn"]),
    (
        "image",
        &["io", "report", "transfer", "experiments", "tools"],
    ),
    ("indicatif", &["run"]),
];

/// The first path segment after `crate::` of every path in `code`, including the members of
/// a grouped `use crate::{a::x, b::y}`.
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        let starts = path_starts(&rest[..at]);
        rest = &rest[at + "crate::".len()..];
        // `$crate::` and `facelab_crate::` are not this crate's paths.
        if !starts {
            continue;
        }
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 1;
            let end = group
                .char_indices()
                .find(|&(_, c)| {
                    depth += match c {
                        '{' => 1,
                        '}' => -1,
                        _ => 0,
                    };
                    depth == 0
                })
                .map_or(group.len(), |(i, _)| i);
            let mut depth = 0;
            let mut item = String::new();
            for c in group[..end].chars().chain([',']) {
                match c {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        found.insert(head(item.trim()));
                        item.clear();
                        continue;
                    }
                    _ => {}
                }
                item.push(c);
            }
        } else {
            found.insert(head(rest));
        }
    }
    found.remove("");
    found
}

fn head(path: &str) -> String {
    path.chars()
        .take_while(|c| c.is_alphanumeric() || *c == '_')
        .collect()
}

/// `text` without comments and without the `#[cfg(test)]` item that closes a file.
fn library_code(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod ") {
        Some(at) => &text[..at],
        None => text,
    };
    text.lines()
        .map(|line| match line.find("//") {
            Some(at) if !line[..at].contains('"') => &line[..at],
            _ => line,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// A library file of `src` (`lib.rs` and the binary, `bin/facelab/`: its `main.rs`, its clap
/// structs in `cli.rs` and one file per command in `commands/`, left out, which may use
/// anything of the library): its path under `src`, its top-level module,
/// and its code without comments and test module (`None` for a module's tests in their own
/// file, `#[cfg(test)] mod tests;`, which is test code).
struct LibraryFile {
    rel: PathBuf,
    module: String,
    code: Option<String>,
}

fn library_files(src: &Path) -> Vec<LibraryFile> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.sort();
    files
        .into_iter()
        .filter_map(|file| {
            let rel = file.strip_prefix(src).unwrap().to_path_buf();
            let module = rel
                .components()
                .next()
                .unwrap()
                .as_os_str()
                .to_string_lossy()
                .trim_end_matches(".rs")
                .to_string();
            if module == "lib" || module == "bin" {
                return None;
            }
            let code = file
                .file_name()
                .is_none_or(|n| n != "tests.rs")
                .then(|| library_code(&std::fs::read_to_string(&file).unwrap()));
            Some(LibraryFile { rel, module, code })
        })
        .collect()
}

/// Every module's imports from the crate and external crates in the source folder `src`
/// (test code left out), as `(module, target)` with external crates as `extern <name>`.
fn used(src: &Path) -> BTreeSet<(String, String)> {
    let mut edges = BTreeSet::new();
    for f in library_files(src) {
        let Some(code) = f.code else { continue };
        for target in crate_paths(&code) {
            if target != f.module {
                edges.insert((f.module.clone(), target));
            }
        }
        for (krate, _) in EXTERNAL {
            if names_crate(&code, krate) {
                edges.insert((f.module.clone(), format!("extern {krate}")));
            }
        }
    }
    edges
}

/// Whether a path segment right after `before` is the path's first: not the tail of a
/// longer name (`facelab_crate`, `$crate`) nor a later segment (`codecs::gif`).
fn path_starts(before: &str) -> bool {
    !before
        .chars()
        .next_back()
        .is_some_and(|c| c == '$' || c == ':' || c == '_' || c.is_alphanumeric())
}

/// Whether `code` names the external crate `krate` as a path's first segment (`gif::Frame`,
/// not `image::codecs::gif::GifDecoder`).
fn names_crate(code: &str, krate: &str) -> bool {
    code.match_indices(&format!("{krate}::"))
        .any(|(at, _)| path_starts(&code[..at]))
}

/// Every allowed import no code makes, as "module -> what": a rule the code does not need
/// lets drift pass unnoticed.
fn unused_rules(src: &Path) -> Vec<String> {
    let used = used(src);
    let mut found = Vec::new();
    for (module, may) in ALLOWED {
        for target in *may {
            if !used.contains(&(module.to_string(), target.to_string())) {
                found.push(format!("{module} -> {target}"));
            }
        }
    }
    for (krate, users) in EXTERNAL {
        for module in *users {
            if !used.contains(&(module.to_string(), format!("extern {krate}"))) {
                found.push(format!("{module} -> extern {krate}"));
            }
        }
    }
    found
}

/// Every forbidden import in the source folder `src`, as "file: module -> what".
fn violations(src: &Path) -> Vec<String> {
    let allowed: BTreeMap<&str, &[&str]> = ALLOWED.iter().copied().collect();
    let mut found = Vec::new();
    for LibraryFile { rel, module, code } in library_files(src) {
        let Some(may) = allowed.get(module.as_str()) else {
            found.push(format!(
                "{}: module `{module}` has no rule in tests/architecture.rs",
                rel.display()
            ));
            continue;
        };
        let Some(code) = code else { continue };
        for target in crate_paths(&code) {
            if target != module && !may.contains(&target.as_str()) {
                found.push(format!("{}: {module} -> {target}", rel.display()));
            }
        }
        for (krate, users) in EXTERNAL {
            let named = names_crate(&code, krate);
            if named && !users.contains(&module.as_str()) {
                found.push(format!("{}: {module} -> extern {krate}", rel.display()));
            }
        }
    }
    found
}

/// Whether the allowed imports form no cycle (a module graph that is a partial order).
fn cycle() -> Option<Vec<&'static str>> {
    let allowed: BTreeMap<&str, &[&str]> = ALLOWED.iter().copied().collect();
    fn visit(
        m: &'static str,
        allowed: &BTreeMap<&str, &'static [&'static str]>,
        path: &mut Vec<&'static str>,
        done: &mut BTreeSet<&'static str>,
    ) -> Option<Vec<&'static str>> {
        if let Some(at) = path.iter().position(|p| *p == m) {
            return Some(path[at..].to_vec());
        }
        if done.contains(m) {
            return None;
        }
        path.push(m);
        for next in allowed.get(m).copied().unwrap_or(&[]) {
            if let Some(c) = visit(next, allowed, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m);
        None
    }
    let mut done = BTreeSet::new();
    ALLOWED
        .iter()
        .find_map(|(m, _)| visit(m, &allowed, &mut Vec::new(), &mut done))
}

#[test]
fn the_source_keeps_the_module_boundaries() {
    let found = violations(&crate::root().join("src"));
    assert!(
        found.is_empty(),
        "imports that docs/architecture.md forbids:\n{}",
        found.join("\n")
    );
}

/// The rules are exact: every allowed import is one the code makes.
#[test]
fn every_allowed_import_is_used() {
    let found = unused_rules(&crate::root().join("src"));
    assert!(
        found.is_empty(),
        "allowed in tests/architecture.rs (and docs/architecture.md) but used nowhere:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_allowed_imports_have_no_cycle() {
    assert_eq!(cycle(), None);
}

/// The checks themselves can fail: a copy of `sim` that imports `observe` and `rng` is
/// caught, a grouped import is read member by member, and a rule no code uses is named.
#[test]
fn a_forbidden_import_is_caught() {
    let dir = crate::temp("architecture", "forbidden");
    std::fs::create_dir_all(dir.join("sim")).unwrap();
    std::fs::write(
        dir.join("sim/solver.rs"),
        "//! uses crate::report in a comment only\nuse crate::{sim::geom::V3, observe::Observer};\n\
         fn f() { let _ = crate::rng::stream(1, \"x\"); }\n\
         #[cfg(test)]\nmod tests { use crate::io::mesh; }\n",
    )
    .unwrap();
    std::fs::write(dir.join("stats.rs"), "fn g() { toml::from_str(\"\"); }\n").unwrap();
    let found = violations(&dir);
    assert_eq!(
        found,
        [
            "sim/solver.rs: sim -> observe".to_string(),
            "sim/solver.rs: sim -> rng".to_string(),
            "stats.rs: stats -> extern toml".to_string(),
        ]
    );
    // And a rule no code needs: this `sim` does not use the box solver it may.
    assert!(unused_rules(&dir).contains(&"sim -> boxqp".to_string()));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The harness's rules, each shown to catch its violation: an experiment that uses a
/// command-line tool, run machinery that names an experiment, and a transfer pipeline that
/// reaches up into the experiments it serves.
#[test]
fn the_harness_rules_catch_their_violations() {
    let dir = crate::temp("architecture", "harness");
    for (file, code) in [
        ("experiments/table1.rs", "use crate::tools::face::pose;\n"),
        ("run/mod.rs", "use crate::experiments::REGISTRY;\n"),
        (
            "transfer/mod.rs",
            "use crate::experiments::table2::RefFrame;\n",
        ),
        (
            "tools/face.rs",
            "use crate::experiments::table2::RefFrame;\n",
        ),
    ] {
        let path = dir.join(file);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, code).unwrap();
    }
    assert_eq!(
        violations(&dir),
        [
            "experiments/table1.rs: experiments -> tools".to_string(),
            "run/mod.rs: run -> experiments".to_string(),
            "transfer/mod.rs: transfer -> experiments".to_string(),
        ],
        "the tools may use the experiments; nothing else here may"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Files by concept: none of `src/` past 700 lines (STYLE: split past ~800; the structure
/// issue set 700).
#[test]
fn no_source_file_is_over_700_lines() {
    let mut files = Vec::new();
    rust_files(&crate::root().join("src"), &mut files);
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let n = std::fs::read_to_string(f).unwrap().lines().count();
            (n > 700).then(|| format!("{}: {n} lines", f.display()))
        })
        .collect();
    assert!(long.is_empty(), "{}", long.join("\n"));
}

/// The command line is a dispatcher: `main.rs` at most 150 lines, and every subcommand of
/// `cli.rs`'s `Command` handled by its own file in `commands/` (`Command::Render(args) =>
/// commands::render::run(args)`), so a command's code is found by its name.
#[test]
fn main_dispatches_each_command_to_its_own_file() {
    let bin = crate::root().join("src/bin/facelab");
    let main = std::fs::read_to_string(bin.join("main.rs")).unwrap();
    assert!(
        main.lines().count() <= 150,
        "main.rs has {} lines",
        main.lines().count()
    );
    let cli = std::fs::read_to_string(bin.join("cli.rs")).unwrap();
    let enum_body = cli
        .split("pub enum Command {")
        .nth(1)
        .and_then(|rest| rest.split("\n}\n").next())
        .expect("cli.rs defines `pub enum Command`");
    let variants: Vec<&str> = enum_body
        .lines()
        .filter_map(|l| {
            let l = l.strip_prefix("    ")?;
            let name: &str = l.split(['(', ' ', ',']).next()?;
            (name.starts_with(|c: char| c.is_ascii_uppercase())
                && name.chars().all(|c| c.is_ascii_alphanumeric()))
            .then_some(name)
        })
        .collect();
    assert!(variants.len() >= 10, "commands found: {variants:?}");
    let missing: Vec<String> = variants
        .iter()
        .filter_map(|v| {
            let file = v.to_lowercase();
            let dispatched = main.contains(&format!("commands::{file}::run("));
            let exists = bin.join("commands").join(format!("{file}.rs")).is_file();
            (!(dispatched && exists)).then(|| format!("{v} (commands/{file}.rs)"))
        })
        .collect();
    assert!(
        missing.is_empty(),
        "not dispatched to their own file: {missing:?}"
    );
}
