//! The README and the pages under docs/ hold together: every relative link and image in them
//! names a file or folder of the repository and, where it names a heading (`page.md#heading`
//! or `#heading`), a heading that page has under GitHub's anchor rules; the README stays short
//! enough to read in ten minutes; and each measured figure is written once. A design page (the
//! README, a page directly under docs/ other than the dated logs, a page under docs/models/)
//! links the file that holds a measurement — a table or JSON a script writes beside itself under
//! docs/, bench/, or a dated entry of a log — instead of copying its figures: a figure with a
//! unit of measurement (a per cent, a time, a multiple of σ, a speed ratio) there must be one of
//! the few design figures listed below, each with why it is not a measurement.
//!
//! A small scanner, not a full Markdown parser: inline links `[text](dest)` and images
//! `![alt](dest)` outside fenced code blocks and inline code spans, an optional title after
//! the destination (`"…"`, `'…'`). Links to http(s) and mailto are not followed.

use std::collections::{HashMap, HashSet};
use std::fs;
use std::path::{Path, PathBuf};

/// The README's length limit, in lines.
const README_MAX_LINES: usize = 300;

/// The dated logs: where a measurement no script writes is kept as it was taken, with its date
/// and machine, and where the design pages link for it. `log.md` holds the renderers' and the
/// suite's, `accuracy.md` the bake's (code cites its sections by name).
const LOG_PAGES: &[&str] = &["docs/log.md", "docs/accuracy.md"];

/// The folder of hand-written pages under docs/ (one design page per render model); every other
/// folder's pages are tables the script beside them writes.
const DESIGN_FOLDER: &str = "docs/models";

/// The figures with a unit of measurement that a design page may state, because nobody
/// measured them: a definition, a rule, a setting or a test's tolerance set by design, a
/// constant, a cited paper's number. Each entry: the page (empty: every design page), the
/// phrases such a figure stands in on one line (a figure counts as listed only inside one of
/// them), and why. A phrase no page says any more fails the test, so the list stays short.
const DESIGN_FIGURES: &[(&str, &[&str], &str)] = &[
    (
        "",
        &["within 3σ", "1 − T_vol > 1 %", "±50 %"],
        "compare-render's definitions: differences within 3σ of the truth's noise count as 0, \
         the volume's pixels are those with 1 − T_vol > 1 %, an error map is full colour at ±50 %",
    ),
    (
        "",
        &["is within 10 %"],
        "--model auto's rule: the fastest model whose median |bias| is within 10 % \
         (runtime/render/src/auto.rs)",
    ),
    (
        "",
        &["within 4σ", "within 4.5σ", "within 5σ"],
        "tolerances the truth's, the GPU truth's and the sky's tests assert",
    ),
    (
        "docs/truth.md",
        &[
            "0.5 % where 3σ",
            "3σ under 0.3 %",
            "within 4σ and 0.5 %",
            "radiances to 2 %",
            "hold them to 2 %",
            "3σ is under 1.5 %",
            "asserts 2 % wherever 3σ",
            "within 2 % of DISORT",
            "stops at 1 %",
        ],
        "the DISORT slab tests' tolerances and stopping rules (runtime/render/tests/truth.rs), \
         and what `--noise 0.01` asks for",
    ),
    (
        "docs/testing.md",
        &["3σ < 0.3 %"],
        "the long slab run's stopping rule",
    ),
    (
        "docs/physics.md",
        &[
            "1.5× the minimum",
            "allows ± 10 %",
            "around it by 5 %",
            "central 80 %",
        ],
        "validate's criteria: the glory's enhancement, the corona ring's tolerance, snow's \
         featurelessness, a channel's angle tolerance (physics.md §4)",
    ),
    (
        "docs/physics.md",
        &["84 % of it"],
        "a constant: the share of the diffracted light in the Airy pattern's central lobe",
    ),
    (
        "docs/physics.md",
        &["30 % of the kept weight for R, 11 % for G"],
        "a property of fixed inputs (the CIE 1931 functions, the sRGB matrix, ASTM G173), \
         computed, not sampled; every manifest reports it",
    ),
    (
        "docs/commands.md",
        &["central 80 %", "(default 1 %)"],
        "validate's angle tolerance and phase's default --tolerance",
    ),
    (
        "docs/engines.md",
        &["(1 %), up to"],
        "export's default --max-loss",
    ),
    (
        "docs/scenes.md",
        &[
            "draft 3.5 %, standard 0.8 %",
            "draft 4.5 %",
            "standard 0.9 %, reference 0.35 %",
            "at most 4× the preset's",
            "8× for",
            "draft ≤ 5 %",
            "standard ≤ 1 %",
            "in 4 s (draft) and 40 s (standard)",
        ],
        "the presets' noise targets and size limits (tables/bake/src/plan.rs) and what they \
         promise",
    ),
    (
        "docs/models/biri.md",
        &["34.7–59 % for its stage 5"],
        "a cited paper's figure (Biri et al. 2006, Table 1)",
    ),
];

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

/// Whether a page (relative to the root) is a design page: the README, a page directly under
/// docs/ other than the logs, or a page under docs/models/.
fn is_design_page(page: &Path) -> bool {
    let Some(dir) = page.parent() else {
        return false;
    };
    page == Path::new("README.md")
        || (dir == Path::new("docs") && !LOG_PAGES.iter().any(|log| page == Path::new(log)))
        || dir == Path::new(DESIGN_FOLDER)
}

fn is_digit(c: char) -> bool {
    c.is_ascii_digit() || "⁰¹²³⁴⁵⁶⁷⁸⁹".contains(c)
}

fn is_space(c: char) -> bool {
    matches!(c, ' ' | '\u{a0}' | '\u{2009}' | '\u{202f}')
}

/// The figures with a unit of measurement on one line (code spans already blanked), as byte
/// ranges: a number, at most one space, then `%`; `σ` (not a symbol's `σ_tr`); `×` right after
/// the number and before no other number (a ratio, not `160 × 120`); or, after a space and a
/// number ending in an ASCII digit, `ms`, `s`, `min` or `h` as a word.
fn figures(line: &str) -> Vec<(usize, usize)> {
    let chars: Vec<char> = line.chars().collect();
    let bytes: Vec<usize> = line.char_indices().map(|(b, _)| b).collect();
    let at = |i: usize| chars.get(i).copied();
    let byte = |i: usize| bytes.get(i).copied().unwrap_or(line.len());
    let mut out = Vec::new();
    for (i, &c) in chars.iter().enumerate() {
        if !is_digit(c) || at(i + 1).is_some_and(is_digit) {
            continue;
        }
        let mut start = i;
        while start > 0
            && at(start - 1).is_some_and(|p| is_digit(p) || matches!(p, '.' | ',' | '·'))
        {
            start -= 1;
        }
        let spaced = at(i + 1).is_some_and(is_space);
        let k = if spaced { i + 2 } else { i + 1 };
        let Some(unit) = at(k) else {
            continue;
        };
        let end = match unit {
            '%' => Some(k + 1),
            'σ' if !at(k + 1).is_some_and(|n| n == '_' || n.is_alphabetic()) => Some(k + 1),
            '×' if !spaced => {
                let next = if at(k + 1).is_some_and(is_space) {
                    k + 2
                } else {
                    k + 1
                };
                (!at(next).is_some_and(is_digit)).then_some(k + 1)
            }
            _ if spaced && c.is_ascii_digit() => ["ms", "min", "s", "h"].iter().find_map(|word| {
                let n = word.chars().count();
                let here: String = chars.iter().skip(k).take(n).collect();
                let joined = at(k + n).is_some_and(|a| a.is_alphanumeric() || a == '_');
                (here == *word && !joined).then_some(k + n)
            }),
            _ => None,
        };
        if let Some(end) = end {
            out.push((byte(start), byte(end)));
        }
    }
    out
}

/// Every figure of one design page that DESIGN_FIGURES does not list, as `page:line: …`;
/// `used` collects the listed phrases (entry, phrase) the page says.
fn unlisted_figures(name: &str, text: &str, used: &mut HashSet<(usize, usize)>) -> Vec<String> {
    let mut out = Vec::new();
    for (number, raw) in prose_lines(text) {
        let line = without_code_spans(raw);
        let mut listed = Vec::new();
        for (e, (on, phrases, _)) in DESIGN_FIGURES.iter().enumerate() {
            if !on.is_empty() && *on != name {
                continue;
            }
            for (p, phrase) in phrases.iter().enumerate() {
                for (at, _) in line.match_indices(phrase) {
                    listed.push((at, at + phrase.len()));
                    used.insert((e, p));
                }
            }
        }
        for (start, end) in figures(&line) {
            if !listed.iter().any(|&(a, b)| a <= start && end <= b) {
                let figure = &line[start..end];
                out.push(format!(
                    "{name}:{number}: `{figure}` in \"{}\"",
                    line.trim()
                ));
            }
        }
    }
    out
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

#[test]
fn design_pages_link_measured_figures_instead_of_copying_them() {
    let root = root();
    let design: Vec<PathBuf> = pages().into_iter().filter(|p| is_design_page(p)).collect();
    assert!(design.len() > 5, "found few design pages: {design:?}");
    let mut used = HashSet::new();
    let mut found = Vec::new();
    for page in &design {
        let text = fs::read_to_string(root.join(page))
            .unwrap_or_else(|e| panic!("reading {}: {e}", page.display()));
        let name = page.to_string_lossy().replace('\\', "/");
        found.extend(unlisted_figures(&name, &text, &mut used));
    }
    for (e, (on, phrases, _)) in DESIGN_FIGURES.iter().enumerate() {
        for (p, phrase) in phrases.iter().enumerate() {
            if !used.contains(&(e, p)) {
                let on = if on.is_empty() { "any page" } else { *on };
                found.push(format!(
                    "DESIGN_FIGURES lists `{phrase}` ({on}), which no design page says any more: \
                     drop it"
                ));
            }
        }
    }
    assert!(
        found.is_empty(),
        "{} figures on design pages look measured. Link the file that holds each (a table or \
         JSON a script writes, bench/…, or the dated entry in docs/log.md or docs/accuracy.md; \
         move the sentence there with its date if none does), or, if it is a design figure (a \
         definition, a setting, a test's tolerance, a constant, a cited paper's), list it in \
         DESIGN_FIGURES with why:\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn every_page_in_a_docs_folder_is_written_by_the_script_beside_it() {
    let root = root();
    let mut orphans = Vec::new();
    for page in pages() {
        let Some(dir) = page.parent() else { continue };
        if !dir.starts_with("docs") || dir == Path::new("docs") || dir == Path::new(DESIGN_FOLDER) {
            continue;
        }
        if !["py", "sh"]
            .iter()
            .any(|x| root.join(page.with_extension(x)).is_file())
        {
            orphans.push(page.display().to_string());
        }
    }
    assert!(
        orphans.is_empty(),
        "pages in docs/ folders with no script of their name beside them (a hand-written page \
         belongs in docs/ or {DESIGN_FOLDER}/, where the figures check reads it):\n{}",
        orphans.join("\n")
    );
}

/// The figure scanner on the cases the pages use, and a page that copies a measured figure.
#[test]
fn a_design_page_that_copies_a_measured_figure_fails() {
    let found = |line: &str| -> Vec<String> {
        figures(line)
            .into_iter()
            .map(|(a, b)| line[a..b].to_string())
            .collect()
    };
    assert_eq!(
        found("frames 4.38 / 3.47 s, bias +6.6 %, 12.7× faster, worst 2.26σ, 96 ms"),
        ["3.47 s", "6.6 %", "12.7×", "2.26σ", "96 ms"]
    );
    assert_eq!(
        found("took 53–58 minutes, then 10.4 min and 1 h"),
        ["10.4 min", "1 h"]
    );
    assert!(
        found("160 × 120 pixels, 2.1× 3, 1/(3σ_tr), √(2h), x⁴ min(1, y), 5 spp, 10⁵ × bin 1")
            .is_empty()
    );
    let page = "The frame took 4.38 s, and\ndifferences within 3σ count as 0.\n```\n12 s in a \
                block\n```\n`9 %` in a code span\n";
    let mut used = HashSet::new();
    let unlisted = unlisted_figures("docs/rendering.md", page, &mut used);
    assert_eq!(unlisted.len(), 1, "{unlisted:?}");
    assert!(
        unlisted[0].starts_with("docs/rendering.md:1: `4.38 s`"),
        "{unlisted:?}"
    );
    assert!(
        used.contains(&(0, 0)),
        "`within 3σ` is listed for every page"
    );
}
