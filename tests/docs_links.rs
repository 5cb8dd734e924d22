//! The README and the pages under docs/ hold together: every relative link and image in them
//! names a file or folder of the repository and, where it names a heading (`page.md#heading`
//! or `#heading`), a heading that page has under GitHub's anchor rules; the README stays short
//! enough to read in ten minutes.
//!
//! A small scanner, not a full Markdown parser: inline links `[text](dest)` and images
//! `![alt](dest)` outside fenced code blocks and inline code spans, an optional title after
//! the destination (`"…"`, `'…'`). Links to http(s) and mailto are not followed.

use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};

/// The README's length limit, in lines.
const README_MAX_LINES: usize = 300;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md and every `.md` under docs/, sorted, as paths relative to the repository root.
fn pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let mut entries: Vec<_> = fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
            .map(|e| e.expect("a directory entry").path())
            .collect();
        entries.sort();
        for path in entries {
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|x| x == "md") {
                out.push(path);
            }
        }
    }
    let root = root();
    let mut out = vec![root.join("README.md")];
    walk(&root.join("docs"), &mut out);
    out.iter()
        .map(|p| p.strip_prefix(&root).expect("under the root").to_path_buf())
        .collect()
}

/// The lines of a page outside fenced code blocks, with their 1-based numbers.
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut fence: Option<(char, usize)> = None;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let run = |c: char| trimmed.chars().take_while(|&x| x == c).count();
        match fence {
            Some((c, n)) => {
                if run(c) >= n && trimmed.trim_start_matches(c).trim().is_empty() {
                    fence = None;
                }
            }
            None => {
                let (bt, tl) = (run('`'), run('~'));
                if bt >= 3 {
                    fence = Some(('`', bt));
                } else if tl >= 3 {
                    fence = Some(('~', tl));
                } else {
                    out.push((i + 1, line));
                }
            }
        }
    }
    out
}

/// A line with its inline code spans (a run of n backticks up to the next run of exactly n)
/// blanked out, so that nothing inside them reads as a link.
fn without_code_spans(line: &str) -> String {
    let chars: Vec<char> = line.chars().collect();
    let mut out = String::with_capacity(line.len());
    let mut i = 0;
    while i < chars.len() {
        if chars[i] != '`' {
            out.push(chars[i]);
            i += 1;
            continue;
        }
        let open = chars[i..].iter().take_while(|&&c| c == '`').count();
        let mut j = i + open;
        let mut close = None;
        while j < chars.len() {
            if chars[j] == '`' {
                let n = chars[j..].iter().take_while(|&&c| c == '`').count();
                if n == open {
                    close = Some(j + n);
                    break;
                }
                j += n;
            } else {
                j += 1;
            }
        }
        match close {
            Some(end) => {
                out.extend(std::iter::repeat_n(' ', end - i));
                i = end;
            }
            None => {
                // An unmatched run is literal text.
                out.extend(std::iter::repeat_n('`', open));
                i += open;
            }
        }
    }
    out
}

/// The destinations of the inline links and images on one line (code spans already blanked):
/// the text inside `](…)` up to its balancing parenthesis, less a quoted title.
fn destinations(line: &str) -> Vec<String> {
    let chars: Vec<char> = line.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < chars.len() {
        if chars[i] != ']' || chars[i + 1] != '(' {
            i += 1;
            continue;
        }
        let start = i + 2;
        let mut depth = 1;
        let mut j = start;
        while j < chars.len() {
            match chars[j] {
                '(' => depth += 1,
                ')' => {
                    depth -= 1;
                    if depth == 0 {
                        break;
                    }
                }
                _ => {}
            }
            j += 1;
        }
        if depth != 0 {
            break;
        }
        let inner: String = chars[start..j].iter().collect();
        out.push(strip_title(inner.trim()).to_string());
        i = j + 1;
    }
    out
}

/// `dest "title"` or `dest 'title'` → `dest`; `<dest>` → `dest`.
fn strip_title(inner: &str) -> &str {
    let mut dest = inner;
    for q in ['"', '\''] {
        if dest.ends_with(q)
            && let Some(open) = dest[..dest.len() - 1].rfind(q)
            && dest[..open].ends_with(char::is_whitespace)
        {
            dest = dest[..open].trim_end();
            break;
        }
    }
    dest.strip_prefix('<')
        .and_then(|d| d.strip_suffix('>'))
        .unwrap_or(dest)
}

fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%'
            && i + 2 < bytes.len()
            && bytes[i + 1].is_ascii_hexdigit()
            && bytes[i + 2].is_ascii_hexdigit()
            && let Ok(b) = u8::from_str_radix(&s[i + 1..i + 3], 16)
        {
            out.push(b);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// A heading's anchor as GitHub makes it: the heading's text as rendered (code spans' and
/// links' text, no emphasis markers), lower-cased, every character that is not a letter, a
/// digit, `_`, `-` or a space dropped, and each space a `-`.
fn slug(heading: &str) -> String {
    let mut text = String::new();
    let chars: Vec<char> = heading.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        match chars[i] {
            '`' | '*' => {}
            // A link `[text](dest)` renders as its text.
            ']' if chars.get(i + 1) == Some(&'(') => {
                let mut depth = 0;
                while i < chars.len() {
                    match chars[i] {
                        '(' => depth += 1,
                        ')' => {
                            depth -= 1;
                            if depth == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                    i += 1;
                }
            }
            '[' => {}
            c => text.push(c),
        }
        i += 1;
    }
    text.trim()
        .to_lowercase()
        .chars()
        .filter(|&c| c.is_alphanumeric() || c == '_' || c == '-' || c == ' ')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// Every anchor a page's headings give, a repeated slug numbered `-1`, `-2`, … as GitHub does.
fn anchors(text: &str) -> Vec<String> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut out = Vec::new();
    for (_, line) in prose_lines(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if !(1..=6).contains(&hashes) || !line[hashes..].starts_with(' ') {
            continue;
        }
        let title = line[hashes..].trim().trim_end_matches('#').trim_end();
        let base = slug(title);
        let n = seen.entry(base.clone()).or_insert(0);
        out.push(if *n == 0 {
            base.clone()
        } else {
            format!("{base}-{n}")
        });
        *n += 1;
    }
    out
}

/// Every broken link of one page, as `page:line: what`.
fn broken_links(root: &Path, page: &Path) -> Vec<String> {
    let text = fs::read_to_string(root.join(page))
        .unwrap_or_else(|e| panic!("reading {}: {e}", page.display()));
    let dir = page.parent().unwrap_or(Path::new(""));
    let mut broken = Vec::new();
    for (number, line) in prose_lines(&text) {
        for dest in destinations(&without_code_spans(line)) {
            let at = format!("{}:{number}", page.display());
            if dest.starts_with("http://")
                || dest.starts_with("https://")
                || dest.starts_with("mailto:")
            {
                continue;
            }
            if dest.is_empty() {
                broken.push(format!("{at}: an empty link"));
                continue;
            }
            if dest.contains(char::is_whitespace) {
                broken.push(format!(
                    "{at}: `{dest}` has a space, so it is no link on GitHub (write %20 or rename the file)"
                ));
                continue;
            }
            let (path, anchor) = match dest.split_once('#') {
                Some((p, a)) => (p, Some(a)),
                None => (dest.as_str(), None),
            };
            let target = if path.is_empty() {
                page.to_path_buf()
            } else if let Some(from_root) = path.strip_prefix('/') {
                PathBuf::from(percent_decode(from_root))
            } else {
                dir.join(percent_decode(path))
            };
            let full = root.join(&target);
            if !full.exists() {
                broken.push(format!("{at}: `{dest}`: no file {}", target.display()));
                continue;
            }
            let Some(anchor) = anchor else { continue };
            if !full.is_file() || full.extension().is_none_or(|x| x != "md") {
                continue; // GitHub's line anchors (`file.rs#L10`) and the like: not checked
            }
            let target_text = fs::read_to_string(&full).expect("reading a linked page");
            let anchor = percent_decode(anchor).to_lowercase();
            if !anchors(&target_text).contains(&anchor) {
                broken.push(format!(
                    "{at}: `{dest}`: {} has no heading with the anchor #{anchor}",
                    target.display()
                ));
            }
        }
    }
    broken
}

#[test]
fn every_relative_link_and_image_in_the_readme_and_docs_resolves() {
    let root = root();
    let pages = pages();
    assert!(pages.len() > 1, "found no pages under docs/");
    let broken: Vec<String> = pages
        .iter()
        .flat_map(|page| broken_links(&root, page))
        .collect();
    assert!(
        broken.is_empty(),
        "{} broken links:\n{}",
        broken.len(),
        broken.join("\n")
    );
}

#[test]
fn the_readme_stays_short() {
    let text = fs::read_to_string(root().join("README.md")).expect("reading README.md");
    let lines = text.lines().count();
    assert!(
        lines <= README_MAX_LINES,
        "README.md has {lines} lines, more than {README_MAX_LINES}: move detail to a page under docs/"
    );
}

/// The scanner itself, on the cases the pages use.
#[test]
fn the_scanner_reads_links_titles_code_and_anchors_as_github_does() {
    assert_eq!(
        destinations(&without_code_spans(
            "see [a](b.md#c) and ![x](d (e).png) but not `[f](g)`, [h](<i j.png> \"t\")"
        )),
        ["b.md#c", "d (e).png", "i j.png"]
    );
    assert_eq!(
        slug("Miyazaki, Dobashi & Nishita's shadow-view slices (`--model miyazaki`)"),
        "miyazaki-dobashi--nishitas-shadow-view-slices---model-miyazaki"
    );
    assert_eq!(
        slug("Speed (`bench/max_cumulus_dawn.txt`, 2 cores, one run)"),
        "speed-benchmax_cumulus_dawntxt-2-cores-one-run"
    );
    assert_eq!(
        slug("Biri, Arquès & Michelin's analytic single scattering"),
        "biri-arquès--michelins-analytic-single-scattering"
    );
    assert_eq!(slug("See [the page](x.md) now"), "see-the-page-now");
    assert_eq!(
        anchors("# A\n```\n# not a heading\n```\n## A\n### B #\n"),
        ["a", "a-1", "b"]
    );
    assert_eq!(percent_decode("a%20b.png"), "a b.png");
}
