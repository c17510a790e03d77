//! The user's documentation (README and the guide under docs/) read as a user reads it: every
//! link leads somewhere, every `#anchor` names a heading of its page, and no page talks of how
//! it was made. Every command the pages show is run by `runner::every_iwsim_command_in_the_
//! readme_and_the_docs_takes_the_options_it_shows`.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// README and every page of the user guide (docs/*.md): (path from the root, text).
pub(crate) fn user_docs() -> Vec<(String, String)> {
    let mut names = vec!["README.md".to_owned()];
    let mut pages: Vec<String> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .flatten()
        .filter_map(|e| e.file_name().to_str().filter(|n| n.ends_with(".md")).map(|n| format!("docs/{n}")))
        .collect();
    pages.sort();
    names.extend(pages);
    names
        .into_iter()
        .map(|n| {
            let text = std::fs::read_to_string(root().join(&n)).unwrap_or_else(|e| panic!("{n}: {e}"));
            (n, text)
        })
        .collect()
}

/// The lines of `text` outside code blocks, numbered from 1.
fn prose(text: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut in_block = false;
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if !in_block {
            out.push((n + 1, line));
        }
    }
    out
}

/// A heading's anchor as GitHub makes it: lower case, punctuation dropped, spaces as hyphens.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == '-' || *c == ' ' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a markdown page's headings.
fn anchors(text: &str) -> BTreeSet<String> {
    prose(text)
        .into_iter()
        .filter_map(|(_, l)| {
            let t = l.trim_start_matches('#');
            (t.len() < l.len() && l.len() - t.len() <= 6 && t.starts_with(' ')).then(|| slug(t))
        })
        .collect()
}

/// The targets of the inline links and images of a line: `[text](target)`.
fn links(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let Some(end) = after.find(')') else { break };
        let target = after[..end].split_whitespace().next().unwrap_or_default();
        // Inline code (`a](b)` in a command) is not a link.
        let before = &rest[..i];
        if before.matches('`').count().is_multiple_of(2) && !target.is_empty() {
            out.push(target.to_owned());
        }
        rest = &after[end..];
    }
    out
}

#[test]
fn a_link_is_read_in_a_line_and_its_anchor_as_github_makes_it() {
    assert_eq!(links("see [a](docs/a.md#x-y) and ![b](b.png) but `x[0](1)`"), ["docs/a.md#x-y", "b.png"]);
    assert_eq!(
        slug(" navigator — autonomous driving through checkpoints"),
        "navigator--autonomous-driving-through-checkpoints"
    );
    assert_eq!(slug("Agents on other machines (Zenoh)"), "agents-on-other-machines-zenoh");
}

#[test]
fn every_link_in_the_readme_and_the_docs_leads_to_a_file_and_a_heading_that_exist() {
    let docs = user_docs();
    assert!(docs.len() >= 10, "README and the guide's pages: {:?}", docs.iter().map(|d| &d.0).collect::<Vec<_>>());
    let mut broken = Vec::new();
    let mut checked = 0;
    for (name, text) in &docs {
        let dir = root().join(name).parent().expect("a folder").to_path_buf();
        for (n, line) in prose(text) {
            for target in links(line) {
                if target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                checked += 1;
                let (path, anchor) = target.split_once('#').unwrap_or((&target, ""));
                let file: PathBuf = if path.is_empty() { root().join(name) } else { dir.join(path) };
                if !file.exists() {
                    broken.push(format!("{name}:{n}: {target}: no such file"));
                    continue;
                }
                if !anchor.is_empty() {
                    let page = std::fs::read_to_string(&file).unwrap_or_default();
                    if !anchors(&page).contains(anchor) {
                        broken.push(format!("{name}:{n}: {target}: no such heading"));
                    }
                }
            }
        }
        // Every code block is closed, or the rest of the page renders as code.
        let fences = text.lines().filter(|l| l.trim_start().starts_with("```")).count();
        if !fences.is_multiple_of(2) {
            broken.push(format!("{name}: a code block is never closed"));
        }
    }
    assert!(checked >= 30, "only {checked} links checked");
    assert!(broken.is_empty(), "broken links:\n  {}", broken.join("\n  "));
}

#[test]
fn the_guide_has_a_page_per_part_and_the_readme_links_every_page() {
    let docs = user_docs();
    let readme = &docs[0].1;
    for part in ["scenarios", "agents", "python", "udp", "serial", "recordings", "viewer", "performance"] {
        assert!(docs.iter().any(|(n, _)| *n == format!("docs/{part}.md")), "docs/{part}.md is missing");
    }
    for (name, _) in &docs[1..] {
        assert!(readme.contains(&format!("]({name})")), "README does not link {name}");
    }
    assert!(readme.lines().count() < 300, "README is a front page, not the guide: {} lines", readme.lines().count());
}

#[test]
fn no_page_talks_of_how_it_was_made() {
    // A user's page says what the tool does and how to check it, not which ticket asked for it
    // or on which build machine someone once looked.
    let talk = ["issue", "this vm", "this session", "commit "];
    let mut found = Vec::new();
    for (name, text) in user_docs() {
        for (n, line) in prose(&text) {
            let lower = line.to_lowercase();
            for word in talk {
                if lower.contains(word) {
                    found.push(format!("{name}:{n}: {}", line.trim()));
                }
            }
        }
    }
    assert!(found.is_empty(), "pages that talk of their making:\n  {}", found.join("\n  "));
}

#[test]
fn the_user_guide_renders_with_mkdocs_in_strict_mode() {
    // A third-party renderer: MkDocs fails a strict build on a page left out of the guide, a
    // link to a missing page or a missing anchor (its own rules, beside ours above).
    let python = test_support::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
    let site = std::env::temp_dir().join(format!("iwsim-e2e-docs-site-{}", std::process::id()));
    let output = std::process::Command::new(&python)
        .current_dir(root())
        .args(["-m", "mkdocs", "build", "--strict", "--config-file", "mkdocs.yml", "--site-dir"])
        .arg(&site)
        .output()
        .expect("python runs");
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "mkdocs build --strict failed:\n{said}");
    for page in ["scenarios/index.html", "agents/index.html", "python/index.html", "performance/index.html"] {
        let html = std::fs::read_to_string(site.join(page)).unwrap_or_else(|e| panic!("{page}: {e}"));
        assert!(html.contains("<h1"), "{page} has no title:\n{said}");
    }
    let _ = std::fs::remove_dir_all(site);
}
