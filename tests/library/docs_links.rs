//! Every relative link in the repository's Markdown resolves: the target file or directory exists
//! inside the repository, and a `#anchor` into a Markdown file names one of its headings (GitHub's
//! slug rules). Links with a scheme (`https:`, `mailto:`) are not followed.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Directories never scanned: build output, dependencies, version control.
const SKIP_DIRS: [&str; 3] = ["target", "node_modules", ".git"];

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `*.md` file under `dir`, skipping [`SKIP_DIRS`] and hidden directories.
fn markdown_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            if !name.starts_with('.') && !SKIP_DIRS.contains(&name.as_str()) {
                markdown_files(&path, out);
            }
        } else if name.ends_with(".md") {
            out.push(path);
        }
    }
}

/// The lines of a Markdown text outside fenced code blocks, numbered from 1.
fn prose_lines(text: &str) -> Vec<(usize, String)> {
    let mut in_fence = false;
    let mut lines = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("```") || trimmed.starts_with("~~~") {
            in_fence = !in_fence;
            continue;
        }
        if !in_fence {
            lines.push((n + 1, line.to_string()));
        }
    }
    lines
}

/// `line` without its inline code spans (`` `…` ``). A span may continue over the lines of a
/// paragraph: `in_code` carries that state from line to line and a blank line ends it.
fn strip_code_spans(line: &str, in_code: &mut bool) -> String {
    if line.trim().is_empty() {
        *in_code = false;
    }
    let mut out = String::with_capacity(line.len());
    for c in line.chars() {
        if c == '`' {
            *in_code = !*in_code;
        } else if !*in_code {
            out.push(c);
        }
    }
    out
}

/// The targets of the inline links `[text](target "title")` and images on one prose line.
fn inline_targets(line: &str) -> Vec<String> {
    let mut targets = Vec::new();
    let mut rest = line;
    while let Some(at) = rest.find("](") {
        let after = &rest[at + 2..];
        let mut depth = 1usize;
        let mut end = None;
        for (i, c) in after.char_indices() {
            match c {
                '(' => depth += 1,
                ')' => {
                    depth -= 1;
                    if depth == 0 {
                        end = Some(i);
                        break;
                    }
                }
                _ => {}
            }
        }
        let Some(end) = end else { break };
        targets.push(clean_target(&after[..end]));
        rest = &after[end..];
    }
    targets
}

/// The target of a reference definition `[label]: target`, if the line is one.
fn reference_target(line: &str) -> Option<String> {
    let t = line.trim_start();
    let rest = t.strip_prefix('[')?;
    let close = rest.find("]:")?;
    let target = rest[close + 2..].trim();
    (!target.is_empty()).then(|| clean_target(target))
}

/// A link destination without its optional title and angle brackets.
fn clean_target(raw: &str) -> String {
    let raw = raw.trim();
    let raw = raw.split_whitespace().next().unwrap_or("");
    raw.trim_start_matches('<')
        .trim_end_matches('>')
        .to_string()
}

/// GitHub's anchor for a heading: markup removed, lower case, every character but letters,
/// digits, `-` and `_` dropped, spaces turned into `-`.
fn slug(heading: &str) -> String {
    let text = link_texts(heading).replace(['*', '`'], "");
    let mut out = String::with_capacity(text.len());
    for c in text.trim().chars().flat_map(char::to_lowercase) {
        if c.is_alphanumeric() || c == '-' || c == '_' {
            out.push(c);
        } else if c == ' ' {
            out.push('-');
        }
    }
    out
}

/// `text` with each `[label](target)` replaced by its label.
fn link_texts(text: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(open) = rest.find('[') {
        let Some(mid) = rest[open..].find("](") else {
            break;
        };
        let Some(close) = rest[open + mid..].find(')') else {
            break;
        };
        out.push_str(&rest[..open]);
        out.push_str(&rest[open + 1..open + mid]);
        rest = &rest[open + mid + close + 1..];
    }
    out.push_str(rest);
    out
}

/// The anchors of a Markdown text's headings, duplicates numbered as GitHub numbers them
/// (`name`, `name-1`, `name-2`, …), plus explicit `<a name="…">` / `id="…"` anchors.
fn anchors(text: &str) -> HashSet<String> {
    let mut seen = HashSet::new();
    for (_, line) in prose_lines(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if (1..=6).contains(&hashes) && line[hashes..].starts_with(' ') {
            let base = slug(line[hashes..].trim().trim_end_matches('#'));
            let mut name = base.clone();
            let mut n = 0;
            while seen.contains(&name) {
                n += 1;
                name = format!("{base}-{n}");
            }
            seen.insert(name);
        }
        for key in ["name=\"", "id=\""] {
            let mut rest = line.as_str();
            while let Some(at) = rest.find(key) {
                let value = &rest[at + key.len()..];
                let end = value.find('"').unwrap_or(value.len());
                seen.insert(value[..end].to_string());
                rest = &value[end..];
            }
        }
    }
    seen
}

/// What is wrong with one link `target` found in `file`, or `None` when it resolves.
fn check_link(root: &Path, file: &Path, target: &str) -> Option<String> {
    if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
        return None;
    }
    let (path_part, anchor) = match target.split_once('#') {
        Some((p, a)) => (p, Some(a)),
        None => (target, None),
    };
    let resolved = if path_part.is_empty() {
        file.to_path_buf()
    } else if let Some(abs) = path_part.strip_prefix('/') {
        root.join(abs)
    } else {
        file.parent().unwrap_or(root).join(path_part)
    };
    let Ok(canonical) = resolved.canonicalize() else {
        return Some(format!("{target}: no such file or directory"));
    };
    let root = root.canonicalize().expect("the repository root exists");
    if !canonical.starts_with(&root) {
        return Some(format!("{target}: outside the repository"));
    }
    let anchor = anchor?;
    if canonical.extension().is_none_or(|e| e != "md") {
        return None;
    }
    let text = std::fs::read_to_string(&canonical).ok()?;
    (!anchors(&text).contains(anchor))
        .then(|| format!("{target}: no heading with anchor #{anchor}"))
}

/// Every broken link of the Markdown files under `root`, as `file: line: problem`.
fn broken_links(root: &Path) -> Vec<String> {
    let mut files = Vec::new();
    markdown_files(root, &mut files);
    files.sort();
    let mut problems = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).expect("readable Markdown");
        let shown = file
            .strip_prefix(root)
            .unwrap_or(file)
            .display()
            .to_string();
        let mut in_code = false;
        for (n, line) in prose_lines(&text) {
            let line = strip_code_spans(&line, &mut in_code);
            let mut targets = inline_targets(&line);
            targets.extend(reference_target(&line));
            for target in targets {
                if let Some(problem) = check_link(root, file, &target) {
                    problems.push(format!("{shown}:{n}: {problem}"));
                }
            }
        }
    }
    problems
}

#[test]
fn every_relative_link_in_the_markdown_resolves() {
    let root = repo_root();
    let mut files = Vec::new();
    markdown_files(&root, &mut files);
    assert!(
        files.iter().any(|f| f.ends_with("README.md")) && files.len() > 10,
        "the scan found the repository's Markdown: {files:?}"
    );
    let problems = broken_links(&root);
    assert!(
        problems.is_empty(),
        "broken links:\n{}",
        problems.join("\n")
    );
}

#[test]
fn slugs_follow_github_rules() {
    assert_eq!(
        slug("Speed against PoissonRecon"),
        "speed-against-poissonrecon"
    );
    assert_eq!(
        slug("Open borders: trim and peel"),
        "open-borders-trim-and-peel"
    );
    assert_eq!(slug("The seed paper's Table 1"), "the-seed-papers-table-1");
    assert_eq!(
        slug("`--max-handle-loop` and `snake_case`"),
        "--max-handle-loop-and-snake_case"
    );
    assert_eq!(
        slug("Open or closed (`--boundary auto`)"),
        "open-or-closed---boundary-auto"
    );
    assert_eq!(
        slug("See [the docs](docs/a.md) **now**"),
        "see-the-docs-now"
    );
    let found = anchors("# A\n\n```\n# not a heading\n```\n## A\n### B: c\n");
    let want: HashSet<String> = ["a", "a-1", "b-c"].map(String::from).into();
    assert_eq!(found, want);
}

#[test]
fn a_broken_link_or_anchor_is_reported() {
    let base = std::env::temp_dir().join(format!("rbfsurf-docs-links-{}", std::process::id()));
    let root = base.join("repo");
    std::fs::create_dir_all(root.join("docs")).unwrap();
    std::fs::write(base.join("outside.md"), "# Outside\n").unwrap();
    std::fs::write(root.join("docs/a.md"), "# Title\n\n## Part two\n").unwrap();
    let readme = "[ok](docs/a.md#part-two) [gone](docs/b.md) [anchor](docs/a.md#part-three)\n\
                  [out](../outside.md) `[code](docs/none.md)` [web](https://example.com/x)\n\
                  [self](#readme)\n\n# Readme\n";
    std::fs::write(root.join("README.md"), readme).unwrap();
    let problems = broken_links(&root);
    std::fs::remove_dir_all(&base).unwrap();
    assert_eq!(problems.len(), 3, "{problems:#?}");
    assert!(
        problems[0].contains("README.md:1: docs/b.md: no such file"),
        "{problems:#?}"
    );
    assert!(
        problems[1].contains("no heading with anchor #part-three"),
        "{problems:#?}"
    );
    assert!(
        problems[2].contains("README.md:2: ../outside.md: outside the repository"),
        "{problems:#?}"
    );
}
