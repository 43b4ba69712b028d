//! Short excerpts of what a file holds, for messages: an error quotes at most a few hundred
//! characters of a line, a cell or a header however long it is (a 64 MB header line gives a
//! message of a few hundred bytes, not 64 MB), with control characters escaped (a NUL byte shows
//! as `\0`, not as a raw byte on the terminal).

/// Longest cell a message quotes [characters].
pub const CELL_CHARS: usize = 60;
/// Longest header or list a message quotes [characters].
pub const HEADER_CHARS: usize = 1000;

/// At most `max_chars` characters of `bytes` (invalid UTF-8 replaced, control characters
/// escaped, NUL as `\0`), followed by `... (N bytes in all)` when cut.
pub fn excerpt(bytes: &[u8], max_chars: usize) -> String {
    let (mut out, cut) = head(bytes, max_chars);
    if cut {
        out.push_str(&format!("... ({} bytes in all)", bytes.len()));
    }
    out
}

/// [`excerpt`] of the first bytes of something longer (a line read in part): `...` when cut,
/// without a total.
pub fn excerpt_start(bytes: &[u8], max_chars: usize) -> String {
    let (mut out, cut) = head(bytes, max_chars);
    if cut {
        out.push_str("...");
    }
    out
}

/// The first `max_chars` characters of `bytes`, escaped, and whether that cut them.
fn head(bytes: &[u8], max_chars: usize) -> (String, bool) {
    // Decode no more than needed: 4 bytes per character at most.
    let head = &bytes[..bytes
        .len()
        .min(max_chars.saturating_mul(4).saturating_add(4))];
    let text = String::from_utf8_lossy(head);
    let mut out = String::new();
    let mut cut = head.len() < bytes.len();
    for (chars, c) in text.chars().enumerate() {
        if chars >= max_chars {
            cut = true;
            break;
        }
        match c {
            '\0' => out.push_str("\\0"),
            c if c.is_control() => out.extend(c.escape_default()),
            c => out.push(c),
        }
    }
    (out, cut)
}

/// [`excerpt`] of a text.
pub fn excerpt_str(text: &str, max_chars: usize) -> String {
    excerpt(text.as_bytes(), max_chars)
}

/// The items of `items` joined by `sep`, quoted up to `max_chars` characters ([`excerpt`]);
/// the join stops early so that a million items are not joined to be cut.
pub fn join_excerpt<S: AsRef<str>>(items: &[S], sep: &str, max_chars: usize) -> String {
    let mut joined = String::new();
    let mut total = 0usize;
    for (i, s) in items.iter().enumerate() {
        let s = s.as_ref();
        total += s.len() + if i > 0 { sep.len() } else { 0 };
        if joined.len() <= max_chars.saturating_mul(4) {
            if i > 0 {
                joined.push_str(sep);
            }
            joined.push_str(s);
        }
    }
    if total <= joined.len() {
        return excerpt_str(&joined, max_chars);
    }
    let cut = excerpt_str(&joined, max_chars);
    let cut = cut.split("... (").next().unwrap_or("").to_string();
    format!("{cut}... ({} items, {total} bytes in all)", items.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn excerpts_are_short_and_escaped() {
        assert_eq!(excerpt(b"abc", 10), "abc");
        assert_eq!(excerpt(b"a\0b\x1b", 10), "a\\0b\\u{1b}");
        assert_eq!(excerpt_start(b"abcdef", 3), "abc...");
        let big = vec![b'x'; 1 << 20];
        let e = excerpt(&big, 20);
        assert!(e.starts_with(&"x".repeat(20)) && e.ends_with("(1048576 bytes in all)"));
        assert!(e.len() < 60, "{e}");
        let many: Vec<String> = (0..100_000).map(|k| format!("c{k}")).collect();
        let j = join_excerpt(&many, ",", 30);
        assert!(
            j.starts_with("c0,c1,c2") && j.contains("100000 items"),
            "{j}"
        );
        assert!(j.len() < 100, "{j}");
        assert_eq!(join_excerpt(&["a", "b"], ",", 30), "a,b");
        // A cut never splits a character.
        let e = excerpt("ééééé".as_bytes(), 2);
        assert!(e.starts_with("éé..."), "{e}");
    }
}
