//! The pages that say what the code does stay readable and current: every row of README's
//! table and of docs/status.md is at most 400 characters (details go to the page it links),
//! status.md names no issue (an issue's state changes without the page), and every link to a
//! section of status.md finds its heading.

use std::path::Path;

/// The longest table row a reader takes in at a glance.
const MAX_ROW: usize = 400;

fn page(rel: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    std::fs::read_to_string(root.join(rel)).unwrap()
}

/// GitHub's anchor of a heading: lower case, spaces to hyphens, punctuation but hyphens gone.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// The anchors `link_prefix` + `#…` links in `text` name.
fn anchors<'a>(text: &'a str, link_prefix: &str) -> Vec<&'a str> {
    let pattern = format!("({link_prefix}#");
    text.match_indices(&pattern)
        .map(|(at, _)| {
            let rest = &text[at + pattern.len()..];
            &rest[..rest.find(')').unwrap_or(rest.len())]
        })
        .collect()
}

#[test]
fn status_tables_keep_short_rows_name_no_issue_and_link_to_headings_that_exist() {
    let (readme, status) = (page("README.md"), page("docs/status.md"));
    for (name, text) in [("README.md", &readme), ("docs/status.md", &status)] {
        for (i, line) in text.lines().enumerate() {
            let n = line.chars().count();
            assert!(
                !line.starts_with('|') || n <= MAX_ROW,
                "{name}:{}: a table row of {n} characters (at most {MAX_ROW}; details go to the linked page)",
                i + 1
            );
        }
    }
    let lower = status.to_lowercase();
    for (at, _) in lower.match_indices("issue ") {
        let next = lower[at + 6..].chars().next();
        assert!(
            !next.is_some_and(|c| c.is_ascii_digit()),
            "docs/status.md names an issue: …{}…",
            &status[at..(at + 20).min(status.len())]
        );
    }
    let headings: Vec<String> = status
        .lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| slug(l.trim_start_matches('#')))
        .collect();
    let links = [anchors(&status, ""), anchors(&readme, "docs/status.md")].concat();
    assert!(links.len() >= 9, "{links:?}");
    for a in links {
        assert!(
            headings.iter().any(|h| h == a),
            "a link to docs/status.md#{a}, which has no such heading ({headings:?})"
        );
    }
}

#[test]
fn a_heading_slug_is_githubs() {
    assert_eq!(
        slug(" undistortion, NeRF-W, nerfstudio"),
        "undistortion-nerf-w-nerfstudio"
    );
    assert_eq!(slug("trainer layouts"), "trainer-layouts");
}
