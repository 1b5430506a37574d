//! `report.html` beside every `report.md`: the same Markdown turned into one
//! self-contained HTML page, with the report's SVG figures embedded.
//!
//! The converter handles the subset of Markdown the reports are written in: `#` headings,
//! paragraphs, `|` tables (first row the header, second the `|---|` separator), `-`/`*`
//! and numbered lists, fenced code blocks, and inline code, `**strong**`, `*emphasis*`,
//! links and images. Everything taken from the text is HTML-escaped, so a channel name such
//! as `<b>` prints as written; a link whose target has a scheme other than `http(s)`, or an
//! image that is not an SVG file in the report's own folder, is shown as its text. An
//! image is embedded inline as SVG when its file holds nothing active (no `<script`, no
//! `on…=` handler, no `javascript:`), otherwise as a base64 `data:` image, which a browser
//! never runs.
//!
//! Owns: the Markdown-subset → HTML conversion and writing `report.md` + `report.html`
//! atomically. Never: deciding what a report says (each workflow writes its Markdown).
//! `discover`'s report module can call [`write_report`] the same way.

use std::fmt::Write as _;
use std::path::Path;

use crate::atomic::write_atomic;
use crate::error::Result;

/// Write `report.md` (the Markdown as given) and `report.html` (the same content, figures
/// referenced as `![caption](file.svg)` embedded from `dir`) into `dir`, each atomically.
pub fn write_report(dir: &Path, markdown: &str) -> Result<()> {
    write_atomic(&dir.join("report.md"), markdown.as_bytes())?;
    let html = markdown_to_html(markdown, &|src| read_local_svg(dir, src));
    write_atomic(&dir.join("report.html"), html.as_bytes())
}

/// A "Figures" section showing every `.svg` of `files` inline, in the given order, each
/// under a caption made from its file name (empty when there is none).
pub fn figures_section(files: &[String]) -> String {
    let svgs: Vec<&String> = files.iter().filter(|f| f.ends_with(".svg")).collect();
    if svgs.is_empty() {
        return String::new();
    }
    let mut s = String::from("\n## Figures\n\n");
    for f in svgs {
        let caption = f.trim_end_matches(".svg").replace('_', " ");
        let _ = write!(s, "![{caption}]({f})\n\n");
    }
    s
}

/// The text of `src` when it names an `.svg` file directly inside `dir` (no folders, no
/// `..`, no absolute path).
fn read_local_svg(dir: &Path, src: &str) -> Option<String> {
    let plain = !src.is_empty()
        && src.ends_with(".svg")
        && !src.contains(['/', '\\', ':'])
        && !src.starts_with('.');
    if !plain {
        return None;
    }
    std::fs::read_to_string(dir.join(src)).ok()
}

const STYLE: &str = "body{font-family:sans-serif;max-width:60rem;margin:2rem auto;padding:0 1rem;\
line-height:1.45;color:#222}table{border-collapse:collapse;margin:1rem 0}\
th,td{border:1px solid #bbb;padding:.25rem .5rem;text-align:left}th{background:#eee}\
code{background:#f3f3f3;padding:0 .2rem}pre{background:#f3f3f3;padding:.5rem;overflow-x:auto}\
figure{margin:1rem 0}figure svg,figure img{max-width:100%;height:auto}\
figcaption{font-size:.9rem;color:#555}";

/// Convert the Markdown subset (see the module docs) to a whole HTML page. `image`
/// returns the SVG text of an image source, or `None` to show the image's caption only.
pub fn markdown_to_html(markdown: &str, image: &dyn Fn(&str) -> Option<String>) -> String {
    let title = markdown
        .lines()
        .find_map(|l| l.strip_prefix("# "))
        .unwrap_or("report")
        .trim();
    // One string: the head, the body rendered straight after it, the end.
    let mut html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n",
        escape(&strip_inline(title))
    );
    render_blocks(markdown, image, &mut html);
    html.push_str("</body>\n</html>\n");
    html
}

/// `&`, `<`, `>`, `"` and `'` as entities.
pub fn escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            _ => s.push(c),
        }
    }
    s
}

/// A title without inline marks (`**`, backticks).
fn strip_inline(text: &str) -> String {
    text.replace("**", "").replace('`', "")
}

fn heading_level(line: &str) -> Option<(usize, &str)> {
    let hashes = line.bytes().take_while(|&b| b == b'#').count();
    if (1..=6).contains(&hashes) {
        line[hashes..].strip_prefix(' ').map(|rest| (hashes, rest))
    } else {
        None
    }
}

/// The item text of a list line and whether the list is numbered.
fn list_item(line: &str) -> Option<(bool, &str)> {
    if let Some(rest) = line.strip_prefix("- ").or_else(|| line.strip_prefix("* ")) {
        return Some((false, rest));
    }
    let digits = line.bytes().take_while(u8::is_ascii_digit).count();
    if digits > 0 {
        return line[digits..].strip_prefix(". ").map(|rest| (true, rest));
    }
    None
}

fn is_table_separator(line: &str) -> bool {
    let t = line.trim();
    t.starts_with('|') && t.contains('-') && t.chars().all(|c| matches!(c, '|' | '-' | ':' | ' '))
}

/// A lone image line: `![caption](src)` and nothing else.
fn lone_image(line: &str) -> Option<(&str, &str)> {
    let t = line.trim();
    let rest = t.strip_prefix("![")?;
    let (alt, rest) = rest.split_once("](")?;
    let src = rest.strip_suffix(')')?;
    (!src.contains(['(', ')', ' '])).then_some((alt, src))
}

fn render_blocks(md: &str, image: &dyn Fn(&str) -> Option<String>, out: &mut String) {
    let lines: Vec<&str> = md.lines().collect();
    let mut i = 0;
    let mut para: Vec<&str> = Vec::new();
    let flush = |para: &mut Vec<&str>, out: &mut String| {
        if !para.is_empty() {
            let text = para.join(" ");
            let _ = writeln!(out, "<p>{}</p>", inline(&text, image));
            para.clear();
        }
    };
    while i < lines.len() {
        let line = lines[i];
        let trimmed = line.trim_end();
        if trimmed.trim().is_empty() {
            flush(&mut para, out);
            i += 1;
        } else if trimmed.trim_start().starts_with("```") {
            flush(&mut para, out);
            i += 1;
            let mut code = String::new();
            while i < lines.len() && !lines[i].trim_start().starts_with("```") {
                code.push_str(lines[i]);
                code.push('\n');
                i += 1;
            }
            i += 1; // the closing fence (or the end)
            let _ = writeln!(out, "<pre><code>{}</code></pre>", escape(&code));
        } else if let Some((level, text)) = heading_level(trimmed) {
            flush(&mut para, out);
            let _ = writeln!(out, "<h{level}>{}</h{level}>", inline(text.trim(), image));
            i += 1;
        } else if trimmed.starts_with('|')
            && lines.get(i + 1).is_some_and(|l| is_table_separator(l))
        {
            flush(&mut para, out);
            let header = cells(trimmed);
            out.push_str("<table>\n<thead><tr>");
            for c in &header {
                let _ = write!(out, "<th>{}</th>", inline(c, image));
            }
            out.push_str("</tr></thead>\n<tbody>\n");
            i += 2;
            while i < lines.len() && lines[i].trim_start().starts_with('|') {
                out.push_str("<tr>");
                for c in cells(lines[i].trim()) {
                    let _ = write!(out, "<td>{}</td>", inline(&c, image));
                }
                out.push_str("</tr>\n");
                i += 1;
            }
            out.push_str("</tbody>\n</table>\n");
        } else if let Some((numbered, _)) = list_item(trimmed) {
            flush(&mut para, out);
            let tag = if numbered { "ol" } else { "ul" };
            let _ = writeln!(out, "<{tag}>");
            let mut items: Vec<String> = Vec::new();
            while i < lines.len() {
                let l = lines[i].trim_end();
                if let Some((n, text)) = list_item(l)
                    && n == numbered
                {
                    items.push(text.to_string());
                } else if !l.trim().is_empty()
                    && l.starts_with("  ")
                    && let Some(last) = items.last_mut()
                {
                    last.push(' ');
                    last.push_str(l.trim());
                } else {
                    break;
                }
                i += 1;
            }
            for item in items {
                let _ = writeln!(out, "<li>{}</li>", inline(&item, image));
            }
            let _ = writeln!(out, "</{tag}>");
        } else if let Some((alt, src)) = lone_image(trimmed) {
            flush(&mut para, out);
            let _ = writeln!(
                out,
                "<figure>{}<figcaption>{}</figcaption></figure>",
                embed(alt, src, image),
                escape(alt)
            );
            i += 1;
        } else if trimmed.trim() == "---" {
            flush(&mut para, out);
            out.push_str("<hr>\n");
            i += 1;
        } else {
            para.push(trimmed.trim());
            i += 1;
        }
    }
    flush(&mut para, out);
}

/// The cells of a table row: split on `|` outside backticks, `\|` kept as a bar.
fn cells(row: &str) -> Vec<String> {
    let inner = row.trim();
    let inner = inner.strip_prefix('|').unwrap_or(inner);
    let inner = inner.strip_suffix('|').unwrap_or(inner);
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut in_code = false;
    let mut chars = inner.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\\' if chars.peek() == Some(&'|') => {
                cur.push('|');
                chars.next();
            }
            '`' => {
                in_code = !in_code;
                cur.push(c);
            }
            '|' if !in_code => out.push(std::mem::take(&mut cur).trim().to_string()),
            _ => cur.push(c),
        }
    }
    out.push(cur.trim().to_string());
    out
}

/// Whether an SVG text is safe to put inline (nothing a browser would run).
fn svg_is_passive(svg: &str) -> bool {
    let lower = svg.to_ascii_lowercase();
    let head = lower.trim_start();
    let starts = head.starts_with("<svg") || head.starts_with("<?xml");
    let handler = lower.match_indices(" on").any(|(k, _)| {
        lower[k + 3..]
            .chars()
            .take_while(|c| c.is_ascii_alphabetic())
            .count()
            > 0
            && lower[k + 3..]
                .trim_start_matches(|c: char| c.is_ascii_alphabetic())
                .starts_with('=')
    });
    starts
        && !handler
        && !lower.contains("<script")
        && !lower.contains("javascript:")
        && !lower.contains("<foreignobject")
}

/// An image: its SVG inline, or as a `data:` image, or its caption when unavailable.
fn embed(alt: &str, src: &str, image: &dyn Fn(&str) -> Option<String>) -> String {
    match image(src) {
        Some(svg) if svg_is_passive(&svg) => {
            let start = svg.find("<svg").unwrap_or(0);
            let text = svg[start..].trim_end();
            // A title for screen readers, inside the root element.
            match text.find('>') {
                Some(end) => {
                    let title = format!("<title>{}</title>", escape(alt));
                    let mut s = String::with_capacity(text.len() + title.len());
                    s.push_str(&text[..=end]);
                    s.push_str(&title);
                    s.push_str(&text[end + 1..]);
                    s
                }
                None => text.to_string(),
            }
        }
        Some(svg) => format!(
            "<img alt=\"{}\" src=\"data:image/svg+xml;base64,{}\">",
            escape(alt),
            base64(svg.as_bytes())
        ),
        None => format!("<em>[figure {}: {}]</em>", escape(src), escape(alt)),
    }
}

fn base64(bytes: &[u8]) -> String {
    const TABLE: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                s.push(TABLE[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// Whether a link target may be a link: relative, `#…`, or `http(s)://`.
fn safe_href(href: &str) -> bool {
    let lower = href.trim().to_ascii_lowercase();
    match lower.find(':') {
        None => true,
        Some(colon) => {
            // A colon after a path separator or `#`/`?` is not a scheme.
            let before = &lower[..colon];
            before.contains(['/', '#', '?'])
                || lower.starts_with("http://")
                || lower.starts_with("https://")
        }
    }
}

/// Inline marks of one line of text, everything else escaped.
fn inline(text: &str, image: &dyn Fn(&str) -> Option<String>) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::new();
    let mut i = 0;
    let find = |from: usize, pat: &[char]| -> Option<usize> {
        (from..chars.len().saturating_sub(pat.len() - 1)).find(|&k| chars[k..].starts_with(pat))
    };
    let collect = |a: usize, b: usize| -> String { chars[a..b].iter().collect() };
    while i < chars.len() {
        let c = chars[i];
        if c == '\\' && i + 1 < chars.len() && chars[i + 1].is_ascii_punctuation() {
            out.push_str(&escape(&chars[i + 1].to_string()));
            i += 2;
        } else if c == '`'
            && let Some(end) = find(i + 1, &['`'])
        {
            let _ = write!(out, "<code>{}</code>", escape(&collect(i + 1, end)));
            i = end + 1;
        } else if c == '*'
            && chars.get(i + 1) == Some(&'*')
            && let Some(end) = find(i + 2, &['*', '*'])
            && end > i + 2
        {
            let _ = write!(
                out,
                "<strong>{}</strong>",
                inline(&collect(i + 2, end), image)
            );
            i = end + 2;
        } else if c == '*'
            && chars
                .get(i + 1)
                .is_some_and(|n| !n.is_whitespace() && *n != '*')
            && (i == 0 || !chars[i - 1].is_alphanumeric())
            && let Some(end) = find(i + 1, &['*'])
            && !chars[end - 1].is_whitespace()
        {
            let _ = write!(out, "<em>{}</em>", inline(&collect(i + 1, end), image));
            i = end + 1;
        } else if (c == '[' || (c == '!' && chars.get(i + 1) == Some(&'[')))
            && let Some((label, href, next)) = link_at(&chars, if c == '!' { i + 1 } else { i })
        {
            if c == '!' {
                out.push_str(&embed(&label, &href, image));
            } else if safe_href(&href) {
                let _ = write!(
                    out,
                    "<a href=\"{}\">{}</a>",
                    escape(href.trim()),
                    inline(&label, image)
                );
            } else {
                out.push_str(&inline(&label, image));
            }
            i = next;
        } else {
            out.push_str(&escape(&c.to_string()));
            i += 1;
        }
    }
    out
}

/// `[label](href)` starting at `open` (the `[`): label, target and the index after `)`.
fn link_at(chars: &[char], open: usize) -> Option<(String, String, usize)> {
    let close = (open + 1..chars.len()).find(|&k| chars[k] == ']')?;
    if chars.get(close + 1) != Some(&'(') {
        return None;
    }
    let end = (close + 2..chars.len()).find(|&k| chars[k] == ')')?;
    let href: String = chars[close + 2..end].iter().collect();
    if href.contains(char::is_whitespace) {
        return None;
    }
    Some((chars[open + 1..close].iter().collect(), href, end + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_images(_: &str) -> Option<String> {
        None
    }

    #[test]
    fn blocks_become_their_elements() {
        let md = "# Title *x*\n\nSome **bold** and `a<b` text\ncontinued.\n\n\
                  | a | b |\n|---|---|\n| 1 | `x|y` |\n| 2 | 3 |\n\n- one\n- two\n  more\n\n\
                  1. first\n2. second\n\n```\nlet a = b < c;\n```\n";
        let html = markdown_to_html(md, &no_images);
        for needle in [
            "<title>Title *x*</title>",
            "<h1>Title <em>x</em></h1>",
            "<p>Some <strong>bold</strong> and <code>a&lt;b</code> text continued.</p>",
            "<th>a</th><th>b</th>",
            "<td>1</td><td><code>x|y</code></td>",
            "<td>2</td><td>3</td>",
            "<ul>\n<li>one</li>\n<li>two more</li>\n</ul>",
            "<ol>\n<li>first</li>\n<li>second</li>\n</ol>",
            "<pre><code>let a = b &lt; c;\n</code></pre>",
        ] {
            assert!(html.contains(needle), "missing {needle:?} in\n{html}");
        }
        // Three body rows would be wrong: the separator is not a row.
        assert_eq!(html.matches("<tr>").count(), 3);
    }

    #[test]
    fn text_is_escaped_and_unsafe_links_are_text() {
        let md = "Name <script>alert('x')</script> & \"q\" [click](javascript:alert(1)) \
                  [ok](https://example.org/a?b=1&c=2) [rel](summary.json) 2*3*4 and a_b_c";
        let html = markdown_to_html(md, &no_images);
        assert!(!html.contains("<script>"));
        assert!(
            html.contains("&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; &quot;q&quot;")
        );
        assert!(!html.contains("javascript"));
        assert!(html.contains("<a href=\"https://example.org/a?b=1&amp;c=2\">ok</a>"));
        assert!(html.contains("<a href=\"summary.json\">rel</a>"));
        // `*` between digits and `_` inside names are not emphasis.
        assert!(html.contains("2*3*4 and a_b_c"), "{html}");
    }

    #[test]
    fn images_are_embedded_inline_or_as_data_or_named() {
        let svg = "<svg width=\"10\" height=\"10\" viewBox=\"0 0 10 10\"><circle r=\"1\"/></svg>";
        let bad = "<svg onload=\"alert(1)\"></svg>";
        let images = |src: &str| match src {
            "a.svg" => Some(svg.to_string()),
            "bad.svg" => Some(bad.to_string()),
            _ => None,
        };
        let html = markdown_to_html(
            "![fit of x](a.svg)\n\n![evil](bad.svg)\n\n![gone](missing.svg)\n",
            &images,
        );
        assert!(html.contains("<figure><svg width=\"10\" height=\"10\" viewBox=\"0 0 10 10\"><title>fit of x</title><circle r=\"1\"/></svg><figcaption>fit of x</figcaption></figure>"), "{html}");
        assert!(!html.contains("onload"));
        // base64 of the bad SVG, checked against a value computed by hand for its start.
        assert!(html.contains("src=\"data:image/svg+xml;base64,PHN2ZyBvbmxvYWQ9"));
        assert!(html.contains("[figure missing.svg: gone]"));
    }

    #[test]
    fn base64_matches_the_rfc_4648_test_vectors() {
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), coded);
        }
    }

    #[test]
    fn only_plain_svg_names_in_the_folder_are_read() {
        let dir = std::env::temp_dir().join(format!("mmenn-html-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("f.svg"), "<svg></svg>").unwrap();
        assert_eq!(
            read_local_svg(&dir, "f.svg").as_deref(),
            Some("<svg></svg>")
        );
        for bad in [
            "../f.svg",
            "/etc/f.svg",
            "sub/f.svg",
            ".f.svg",
            "f.txt",
            "c:f.svg",
        ] {
            assert_eq!(read_local_svg(&dir, bad), None, "{bad}");
        }
        write_report(&dir, "# R\n\n![f](f.svg)\n").unwrap();
        let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
        assert!(html.contains("<figure><svg><title>f</title></svg>"));
        assert_eq!(
            std::fs::read_to_string(dir.join("report.md")).unwrap(),
            "# R\n\n![f](f.svg)\n"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn figures_section_lists_svgs_only() {
        let s = figures_section(&["a.csv".into(), "d_v_vs_x.svg".into()]);
        assert_eq!(s, "\n## Figures\n\n![d v vs x](d_v_vs_x.svg)\n\n");
        assert_eq!(figures_section(&["a.csv".into()]), "");
    }
}
