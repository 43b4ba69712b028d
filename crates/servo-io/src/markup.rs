//! Markup escaped by construction: the HTML reports and the SVG charts servo writes.
//!
//! A report is a [`Markup`]: its tags come only from `&'static str` templates written in
//! servo's source ([`Markup::lit`], [`Markup::fill`] and the [`markup!`](crate::markup!) macro),
//! and every value placed into it goes through a [`Fragment`], which escapes it for the context
//! it lands in:
//!
//! * text between tags and double-quoted attribute values: any `&str`/`String` ([`text`]
//!   escaping: `& < > " '` as entities, characters that XML forbids (control characters other
//!   than tab, newline and carriage return, U+FFFE, U+FFFF) replaced by U+FFFD);
//! * an attribute value kept verbatim, white space included: [`Attr`];
//! * a link: [`Url`] (http, https or a relative reference; any other scheme, `javascript:`
//!   first, becomes `#`);
//! * text of an SVG chart drawn by a renderer that escapes XML's five characters itself:
//!   [`svg_text`];
//! * JSON in a `<script type="application/json">` element: [`json_for_script`].
//!
//! A user-controlled string (a file or column name, an effect name, a custom expression, model
//! metadata, a title built from them) therefore cannot open a tag, close an attribute or start
//! an event handler: it has no way into a [`Markup`] but through a [`Fragment`].
//!
//! ```
//! use servo_io::markup;
//! use servo_io::markup::Markup;
//! let mut h = Markup::new();
//! let name = "x\" onfocus=\"alert(1)";
//! markup!(h, "<div data-log=\"{}\">{}</div>", name, name);
//! assert_eq!(
//!     h.as_str(),
//!     "<div data-log=\"x&quot; onfocus=&quot;alert(1)\">x&quot; onfocus=&quot;alert(1)</div>"
//! );
//! ```

use std::borrow::Cow;

/// The Content-Security-Policy of every HTML report servo writes: nothing is loaded or run
/// (no script at all, no fetch, no form, no base URL), the report's own `<style>`
/// and `style` attributes apply, images only from `data:` URLs.
pub const REPORT_CSP: &str = "default-src 'none'; style-src 'unsafe-inline'; img-src data:; \
                              base-uri 'none'; form-action 'none'";

/// The `<meta>` element that sets [`REPORT_CSP`]: the first element of every report's `<head>`.
pub const CSP_META: &str = "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; style-src 'unsafe-inline'; img-src data:; base-uri 'none'; form-action 'none'\">";

/// The character that replaces one XML does not allow (U+FFFD).
const REPLACEMENT: char = '\u{FFFD}';

/// Whether XML 1.0 allows `c` in a document (the HTML reports hold inline SVG, and an SVG file
/// is XML): tab, newline, carriage return and every other character from U+0020 but U+FFFE and
/// U+FFFF. Other C0 controls (NUL, ESC, ...) make a standalone SVG unreadable.
fn xml_allowed(c: char) -> bool {
    matches!(c, '\t' | '\n' | '\r') || (c >= ' ' && c != '\u{FFFE}' && c != '\u{FFFF}')
}

/// Whether a character would be shown as something else or hidden: C1 controls and the
/// Unicode format controls that reorder text (bidirectional overrides and isolates), which a
/// file name could use to make a report read differently from what it holds.
fn hidden(c: char) -> bool {
    matches!(c, '\u{7F}'..='\u{9F}' | '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}')
}

/// `s` escaped for HTML/XML text and for a double- or single-quoted attribute value: `& < > " '`
/// as entities, a character XML forbids or a hidden control (C1, bidirectional overrides) as
/// U+FFFD. Borrowed when nothing needs escaping.
pub fn text(s: &str) -> Cow<'_, str> {
    if !s
        .chars()
        .any(|c| matches!(c, '&' | '<' | '>' | '"' | '\'') || !xml_allowed(c) || hidden(c))
    {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 16);
    push_text(&mut out, s);
    Cow::Owned(out)
}

fn push_text(out: &mut String, s: &str) {
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if !xml_allowed(c) || hidden(c) => out.push(REPLACEMENT),
            c => out.push(c),
        }
    }
}

/// `s` escaped for an attribute value (double- or single-quoted) that keeps its white space:
/// as [`text`], and tab, newline, carriage return and the backtick as character references.
pub fn attr(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        match c {
            '\t' => out.push_str("&#9;"),
            '\n' => out.push_str("&#10;"),
            '\r' => out.push_str("&#13;"),
            '`' => out.push_str("&#96;"),
            c => push_text(&mut out, c.encode_utf8(&mut [0; 4])),
        }
    }
    out
}

/// `s` made safe as the text of an SVG chart whose renderer escapes `& < > " '` itself (the
/// plotters SVG backend does): the characters XML forbids and hidden controls become U+FFFD,
/// so that the SVG stays a well-formed XML document. Borrowed when nothing changes.
pub fn svg_text(s: &str) -> Cow<'_, str> {
    if s.chars().all(|c| xml_allowed(c) && !hidden(c)) {
        return Cow::Borrowed(s);
    }
    Cow::Owned(
        s.chars()
            .map(|c| {
                if xml_allowed(c) && !hidden(c) {
                    c
                } else {
                    REPLACEMENT
                }
            })
            .collect(),
    )
}

/// `s` if it is a link a report may hold: an `http:` or `https:` URL or a relative reference
/// (a path, `?query`, `#fragment`); `None` for any other scheme (`javascript:`, `data:`,
/// `vbscript:`, `file:`, ...). The scheme is read as a browser reads it: leading white space
/// and control characters skipped, tab and newline inside it ignored, any letter case.
pub fn safe_url(s: &str) -> Option<&str> {
    let trimmed = s.trim_start_matches(|c: char| c <= ' ');
    let scheme_end = trimmed.find([':', '/', '?', '#']);
    match scheme_end {
        Some(i) if trimmed[i..].starts_with(':') => {
            let scheme: String = trimmed[..i]
                .chars()
                .filter(|c| !matches!(c, '\t' | '\n' | '\r'))
                .collect::<String>()
                .to_ascii_lowercase();
            if scheme == "http" || scheme == "https" {
                Some(s)
            } else {
                None
            }
        }
        _ => Some(s),
    }
}

/// JSON text safe inside `<script type="application/json">...</script>`: `<`, `>`, `&` and the
/// line separators U+2028/U+2029 written as `\u` escapes (the same JSON value), so that no
/// `</script>` or `<!--` can end or change the element.
pub fn json_for_script(value: &serde_json::Value) -> String {
    let s = value.to_string();
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        match c {
            '<' => out.push_str("\\u003c"),
            '>' => out.push_str("\\u003e"),
            '&' => out.push_str("\\u0026"),
            '\u{2028}' => out.push_str("\\u2028"),
            '\u{2029}' => out.push_str("\\u2029"),
            c => out.push(c),
        }
    }
    out
}

/// A value placed into [`Markup`], escaped for its context.
pub trait Fragment {
    /// Appends the escaped value.
    fn put(&self, out: &mut String);
}

impl Fragment for str {
    fn put(&self, out: &mut String) {
        push_text(out, self);
    }
}

impl Fragment for String {
    fn put(&self, out: &mut String) {
        push_text(out, self);
    }
}

impl Fragment for Cow<'_, str> {
    fn put(&self, out: &mut String) {
        push_text(out, self);
    }
}

impl<T: Fragment + ?Sized> Fragment for &T {
    fn put(&self, out: &mut String) {
        (**self).put(out);
    }
}

macro_rules! integer_fragment {
    ($($t:ty),*) => {$(
        impl Fragment for $t {
            fn put(&self, out: &mut String) {
                out.push_str(&self.to_string());
            }
        }
    )*};
}
integer_fragment!(u8, u16, u32, u64, usize, i8, i16, i32, i64, isize);

/// An attribute value kept verbatim, white space included (see [`attr`]).
pub struct Attr<'a>(pub &'a str);

impl Fragment for Attr<'_> {
    fn put(&self, out: &mut String) {
        out.push_str(&attr(self.0));
    }
}

/// A link for an `href`/`src` attribute: the URL escaped as an attribute value when
/// [`safe_url`] accepts it, else `#`.
pub struct Url<'a>(pub &'a str);

impl Fragment for Url<'_> {
    fn put(&self, out: &mut String) {
        match safe_url(self.0) {
            Some(u) => out.push_str(&attr(u)),
            None => out.push('#'),
        }
    }
}

/// HTML or SVG markup: tags from servo's own templates, every value escaped (see the module).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Markup(String);

impl Markup {
    /// Empty markup.
    pub fn new() -> Self {
        Markup(String::new())
    }

    /// Markup written in servo's source: a literal, never a value.
    pub fn lit(&mut self, template: &'static str) -> &mut Self {
        self.0.push_str(template);
        self
    }

    /// `s` as text (escaped, see [`text`]).
    pub fn text(&mut self, s: &str) -> &mut Self {
        push_text(&mut self.0, s);
        self
    }

    /// Other markup, as it is.
    pub fn push(&mut self, m: &Markup) -> &mut Self {
        self.0.push_str(&m.0);
        self
    }

    /// The literal `template` with each `{}` in turn replaced by the next of `args`, escaped
    /// for its context. Only `{}` is a placeholder; any other brace is the template's own (a
    /// style sheet's). A placeholder without an argument is left out, an argument without a
    /// placeholder appended (a mistake of the template that the report's tests see).
    pub fn fill(&mut self, template: &'static str, args: &[&dyn Fragment]) -> &mut Self {
        let mut args = args.iter();
        let mut rest = template;
        while let Some(i) = rest.find("{}") {
            self.0.push_str(&rest[..i]);
            if let Some(a) = args.next() {
                a.put(&mut self.0);
            }
            rest = &rest[i + 2..];
        }
        self.0.push_str(rest);
        for a in args {
            a.put(&mut self.0);
        }
        self
    }

    /// An SVG document from servo's chart renderer (`plot::line_chart_svg` of the CLI, over
    /// the plotters SVG backend, which escapes every text and attribute value it writes, its
    /// labels cleaned with [`svg_text`] first), without its XML declaration, to inline in a
    /// report. Never for a string built from input by hand.
    pub fn from_rendered_svg(svg: &str) -> Markup {
        let body = match svg.find("<svg") {
            Some(i) => &svg[i..],
            None => svg,
        };
        Markup(body.to_string())
    }

    /// The markup as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The markup as a `String`.
    pub fn into_string(self) -> String {
        self.0
    }
}

impl Fragment for Markup {
    fn put(&self, out: &mut String) {
        out.push_str(&self.0);
    }
}

impl std::fmt::Display for Markup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// Appends a literal template to a [`Markup`], each `{}` filled with the next argument escaped
/// for its context ([`Fragment`]): `markup!(h, "<td>{}</td>", name)`. The template must be a
/// string literal; an argument is a `&str`/`String` (text), an integer, an [`Attr`], a [`Url`]
/// or other [`Markup`].
#[macro_export]
macro_rules! markup {
    ($out:expr, $template:literal $(, $arg:expr)* $(,)?) => {
        $out.fill($template, &[$(&$arg as &dyn $crate::markup::Fragment),*])
    };
}

/// Elements of HTML that have no end tag.
const VOID: [&str; 8] = ["meta", "br", "img", "input", "link", "hr", "col", "wbr"];

/// What is wrong with `doc`, an HTML report or SVG document servo wrote, read by a small
/// tokenizer: a `<script>` element, an event-handler attribute (`on...=`), a `javascript:` (or
/// other non-http) link, a tag that does not close, an end tag without its start, an unquoted
/// or unterminated attribute value, a character XML forbids. Empty when none. For the tests
/// and the fuzz targets of the report writers; a report is written, never read, by servo.
pub fn problems(doc: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack: Vec<String> = Vec::new();
    if let Some(c) = doc.chars().find(|c| !xml_allowed(*c)) {
        out.push(format!("a character XML forbids: {c:?}"));
    }
    let b = doc.as_bytes();
    let mut i = 0;
    while let Some(k) = doc[i..].find('<') {
        let at = i + k;
        let rest = &doc[at..];
        if rest.starts_with("<!--") {
            match rest.find("-->") {
                Some(e) => i = at + e + 3,
                None => {
                    out.push(format!("an unterminated comment at byte {at}"));
                    break;
                }
            }
            continue;
        }
        if rest.starts_with("<!") || rest.starts_with("<?") {
            match rest.find('>') {
                Some(e) => i = at + e + 1,
                None => {
                    out.push(format!("an unterminated declaration at byte {at}"));
                    break;
                }
            }
            continue;
        }
        let closing = rest.starts_with("</");
        let name_start = at + if closing { 2 } else { 1 };
        let mut j = name_start;
        while j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'-' || b[j] == b':') {
            j += 1;
        }
        if j == name_start {
            // a '<' that starts no tag: text (an HTML parser reads it so), but servo escapes it
            out.push(format!("a bare '<' at byte {at}"));
            i = at + 1;
            continue;
        }
        let name = doc[name_start..j].to_ascii_lowercase();
        if name == "script" {
            out.push(format!("a <script> element at byte {at}"));
        }
        // attributes up to the tag's end
        let mut self_closing = false;
        loop {
            while j < b.len() && b[j].is_ascii_whitespace() {
                j += 1;
            }
            if j >= b.len() {
                out.push(format!("the tag <{name}> at byte {at} does not end"));
                return out;
            }
            if b[j] == b'>' {
                j += 1;
                break;
            }
            if doc[j..].starts_with("/>") {
                self_closing = true;
                j += 2;
                break;
            }
            let a0 = j;
            while j < b.len() && !b[j].is_ascii_whitespace() && !matches!(b[j], b'=' | b'>' | b'/')
            {
                j += 1;
            }
            let attr_name = doc[a0..j].to_ascii_lowercase();
            if attr_name.is_empty() {
                out.push(format!("a stray '/' in <{name}> at byte {at}"));
                j += 1;
                continue;
            }
            if closing {
                out.push(format!(
                    "an attribute in the end tag </{name}> at byte {at}"
                ));
            }
            if attr_name.starts_with("on") {
                out.push(format!(
                    "an event handler `{attr_name}` in <{name}> at byte {at}"
                ));
            }
            if attr_name.contains(['"', '\'', '<', '`']) {
                out.push(format!(
                    "a broken attribute name `{attr_name}` in <{name}> at byte {at}"
                ));
            }
            let mut value = "";
            if j < b.len() && b[j] == b'=' {
                j += 1;
                let q = b.get(j).copied();
                if q != Some(b'"') && q != Some(b'\'') {
                    out.push(format!(
                        "an unquoted value of `{attr_name}` in <{name}> at byte {at}"
                    ));
                    while j < b.len() && !b[j].is_ascii_whitespace() && b[j] != b'>' {
                        j += 1;
                    }
                    continue;
                }
                let q = q.unwrap_or(b'"') as char;
                match doc[j + 1..].find(q) {
                    Some(e) => {
                        value = &doc[j + 1..j + 1 + e];
                        j = j + 1 + e + 1;
                    }
                    None => {
                        out.push(format!(
                            "an unterminated value of `{attr_name}` at byte {at}"
                        ));
                        return out;
                    }
                }
                if value.contains('<') {
                    out.push(format!("a '<' in the value of `{attr_name}` at byte {at}"));
                }
            }
            if matches!(
                attr_name.as_str(),
                "href" | "src" | "xlink:href" | "action" | "formaction"
            ) && safe_url(&value.replace("&#9;", "\t").replace("&#10;", "\n")).is_none()
            {
                out.push(format!("a link `{value}` in <{name}> at byte {at}"));
            }
        }
        if closing {
            match stack.pop() {
                Some(open) if open == name => {}
                Some(open) => {
                    out.push(format!("</{name}> at byte {at} closes <{open}>"));
                    return out;
                }
                None => {
                    out.push(format!("</{name}> at byte {at} closes nothing"));
                    return out;
                }
            }
        } else if !self_closing && !VOID.contains(&name.as_str()) {
            if name == "style" {
                // raw text up to its end tag
                match doc[j..].find("</style>") {
                    Some(e) => j += e,
                    None => out.push(format!("a <style> at byte {at} that does not end")),
                }
            }
            stack.push(name);
        }
        i = j;
    }
    if !stack.is_empty() {
        out.push(format!("elements left open: {stack:?}"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_escapes_the_five_and_replaces_controls() {
        assert_eq!(text("plain name.csv"), Cow::Borrowed("plain name.csv"));
        assert_eq!(
            text("a&b<c>d\"e'f\u{1}g\u{1b}h\u{202e}i\nj"),
            "a&amp;b&lt;c&gt;d&quot;e&#39;f\u{FFFD}g\u{FFFD}h\u{FFFD}i\nj"
        );
    }

    #[test]
    fn attr_keeps_white_space_as_references() {
        assert_eq!(attr("a b\tc\nd`\"<"), "a b&#9;c&#10;d&#96;&quot;&lt;");
    }

    #[test]
    fn urls_other_than_http_and_relative_are_refused() {
        for ok in [
            "https://example.org/a?b#c",
            "HTTP://x",
            "run.mcap",
            "../logs/run%201.csv",
            "#top",
            "?q=1",
            "a/b:c",
        ] {
            assert_eq!(safe_url(ok), Some(ok), "{ok}");
        }
        for bad in [
            "javascript:alert(1)",
            "JaVaScRiPt:alert(1)",
            " \u{1}javascript:alert(1)",
            "java\tscript:alert(1)",
            "java\nscript:alert(1)",
            "data:text/html,<script>alert(1)</script>",
            "vbscript:x",
            "file:///etc/passwd",
        ] {
            assert_eq!(safe_url(bad), None, "{bad:?}");
        }
        let mut h = Markup::new();
        markup!(h, "<a href=\"{}\">{}</a>", Url("javascript:alert(1)"), "x");
        assert_eq!(h.as_str(), "<a href=\"#\">x</a>");
    }

    #[test]
    fn json_for_script_cannot_end_the_element() {
        let v = serde_json::json!({"name": "</script><script>alert(1)</script><!--&\u{2028}"});
        let s = json_for_script(&v);
        assert!(
            !s.contains('<') && !s.contains('>') && !s.contains('&'),
            "{s}"
        );
        let back: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(back, v);
    }

    #[test]
    fn fill_places_every_argument_escaped_and_nothing_else() {
        let mut h = Markup::new();
        let inner = {
            let mut m = Markup::new();
            m.lit("<b>").text("<i>").lit("</b>");
            m
        };
        markup!(
            h,
            "body{x:1}<p class=\"{}\">{} {} {}</p>",
            "a\"b",
            42usize,
            inner,
            "{}"
        );
        assert_eq!(
            h.as_str(),
            "body{x:1}<p class=\"a&quot;b\">42 <b>&lt;i&gt;</b> {}</p>"
        );
    }

    #[test]
    fn the_meta_element_sets_the_policy() {
        assert!(CSP_META.contains(&format!("content=\"{REPORT_CSP}\"")));
        assert!(!REPORT_CSP.contains("script-src") && REPORT_CSP.contains("default-src 'none'"));
    }

    #[test]
    fn the_checker_finds_what_an_injection_leaves() {
        assert!(problems("<!DOCTYPE html><html><head><meta charset=\"utf-8\"><style>a{b:c}</style></head><body><p a=\"1\">x &amp; y<br></p><svg><text x='1'/></svg></body></html>").is_empty());
        for bad in [
            "<div data-log=\"x\" onfocus=\"alert(1)\" y=\"\"></div>",
            "<p>x<script>alert(1)</script></p>",
            "<p>x<img src=x onerror=alert(1)></p>",
            "<a href=\"javascript:alert(1)\">x</a>",
            "<p><b>x</p></b>",
            "<p>x",
            "<p>a < b</p>",
            "<p>\u{1}</p>",
        ] {
            assert!(!problems(bad).is_empty(), "{bad}");
        }
    }

    #[test]
    fn svg_text_keeps_xml_well_formed() {
        assert_eq!(svg_text("a <b> & \"c\""), Cow::Borrowed("a <b> & \"c\""));
        assert_eq!(
            svg_text("a\u{0}b\u{FFFF}c\u{85}"),
            "a\u{FFFD}b\u{FFFD}c\u{FFFD}"
        );
    }
}
