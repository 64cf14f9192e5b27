//! Every string that leaves rendiff for another reader goes through one of
//! these: POV-Ray SDL (string literals and comments), HTML (text,
//! attributes and links), and messages for a terminal. TOML metadata is
//! written by the `toml` serializer, which escapes its own strings.
//!
//! The rule is the same everywhere: a character the reader would take as
//! syntax is escaped, and one that cannot be escaped there is refused (in
//! SDL literals) or replaced visibly (in comments and messages), so text
//! from a scene file, a file name or a mesh never becomes a directive, a
//! link target or a terminal control sequence.

use std::borrow::Cow;
use std::fmt::Write as _;

/// A POV-Ray 3.7 string literal (quotes included) naming a file.
///
/// POV-Ray reads `\"` inside a literal as a quote, and looks the name up
/// as written: a backslash is not an escape it applies to file names (a
/// file `a\b.png` cannot be named), characters outside printable ASCII are
/// replaced by the parser, and control characters would end the line.
///
/// # Errors
///
/// Why the string cannot be written as a file name POV-Ray opens.
pub fn sdl_file_name(s: &str) -> Result<String, String> {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => {
                return Err(format!(
                    "{}: POV-Ray 3.7 cannot open a file whose name holds a backslash; rename the file",
                    message(s)
                ));
            }
            ' '..='~' => out.push(c),
            _ => {
                return Err(format!(
                    "{}: POV-Ray 3.7 reads only printable ASCII in file names (it replaces {}); rename the file",
                    message(s),
                    message(&c.to_string())
                ));
            }
        }
    }
    out.push('"');
    Ok(out)
}

/// Text for a POV-Ray `//` comment: printable ASCII as is, every other
/// character (a line break would end the comment and start a directive)
/// as `?`.
#[must_use]
pub fn sdl_comment(s: &str) -> Cow<'_, str> {
    if s.chars().all(|c| matches!(c, ' '..='~')) {
        return Cow::Borrowed(s);
    }
    Cow::Owned(
        s.chars()
            .map(|c| if matches!(c, ' '..='~') { c } else { '?' })
            .collect(),
    )
}

/// HTML text or a double-quoted attribute value.
#[must_use]
pub fn html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if c.is_control() => {
                let _ = write!(out, "&#xfffd;");
            }
            c => out.push(c),
        }
    }
    out
}

/// A relative link (`href` or `src`) to a file below the page: `./`
/// followed by the path with every byte outside `A-Z a-z 0-9 - . _ ~ /`
/// percent-encoded. With the leading `./` no value is read as a scheme
/// (`javascript:`), a host (`//x`) or an absolute path; `..` components
/// are dropped, so the link stays below the page.
#[must_use]
pub fn href(path: &str) -> String {
    let mut out = String::from("./");
    let parts: Vec<&str> = path
        .split('/')
        .filter(|p| !p.is_empty() && *p != "." && *p != "..")
        .collect();
    for (k, part) in parts.iter().enumerate() {
        if k > 0 {
            out.push('/');
        }
        for b in part.bytes() {
            if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~') {
                out.push(char::from(b));
            } else {
                let _ = write!(out, "%{b:02X}");
            }
        }
    }
    out
}

/// Text for a terminal: control characters (C0, DEL, C1 — the ones that
/// start escape sequences, ring the bell or move the cursor; also line
/// breaks and tabs) written as Rust escapes (`\u{1b}`), the rest as is.
#[must_use]
pub fn message(s: &str) -> Cow<'_, str> {
    if !s.chars().any(char::is_control) {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        push_printable(&mut out, c);
    }
    Cow::Owned(out)
}

/// As [`message`], but line breaks stay (for text of several lines).
#[must_use]
pub fn lines(s: &str) -> Cow<'_, str> {
    if !s.chars().any(|c| c.is_control() && c != '\n') {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        if c == '\n' {
            out.push(c);
        } else {
            push_printable(&mut out, c);
        }
    }
    Cow::Owned(out)
}

fn push_printable(out: &mut String, c: char) {
    match c {
        '\n' => out.push_str("\\n"),
        '\r' => out.push_str("\\r"),
        '\t' => out.push_str("\\t"),
        '\0' => out.push_str("\\0"),
        c if c.is_control() => {
            let _ = write!(out, "\\u{{{:x}}}", u32::from(c));
        }
        c => out.push(c),
    }
}

/// The most characters of a file's content quoted in a message.
pub const EXCERPT_CHARS: usize = 40;

/// A short quotation of file content for a message: at most
/// [`EXCERPT_CHARS`] characters (then `…`), bytes that are not UTF-8 as
/// `\xNN`, control characters escaped as in [`message`].
#[must_use]
pub fn excerpt(bytes: &[u8]) -> String {
    let mut out = String::new();
    let mut count = 0;
    for chunk in bytes.utf8_chunks() {
        for c in chunk.valid().chars() {
            if count == EXCERPT_CHARS {
                out.push('…');
                return out;
            }
            push_printable(&mut out, c);
            count += 1;
        }
        for b in chunk.invalid() {
            if count == EXCERPT_CHARS {
                out.push('…');
                return out;
            }
            let _ = write!(out, "\\x{b:02x}");
            count += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sdl_file_names_cannot_close_the_literal() {
        assert_eq!(sdl_file_name("a\"b.png").as_deref(), Ok("\"a\\\"b.png\""));
        assert_eq!(
            sdl_file_name("tex/x y.png").as_deref(),
            Ok("\"tex/x y.png\"")
        );
        for bad in ["a\\b.png", "a\nb.png", "\u{e9}.png", "a\u{0}b"] {
            assert!(sdl_file_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn sdl_comments_stay_on_their_line() {
        assert_eq!(
            sdl_comment("x\n#fopen F \"p\" write\r"),
            "x?#fopen F \"p\" write?"
        );
        assert_eq!(sdl_comment("plain"), "plain");
    }

    #[test]
    fn hrefs_stay_relative_and_below() {
        assert_eq!(href("javascript:alert(1)"), "./javascript%3Aalert%281%29");
        assert_eq!(href("//evil.example/x"), "./evil.example/x");
        assert_eq!(href("../../etc/passwd"), "./etc/passwd");
        assert_eq!(href("a b/\"c\".png"), "./a%20b/%22c%22.png");
        assert_eq!(href("sub/index.html"), "./sub/index.html");
    }

    #[test]
    fn html_escapes_markup_and_quotes() {
        assert_eq!(
            html("<a href='x'>\"&\u{1b}"),
            "&lt;a href=&#39;x&#39;&gt;&quot;&amp;&#xfffd;"
        );
    }

    #[test]
    fn messages_carry_no_control_characters() {
        let s = message("a\u{1b}]0;title\u{7}b\nc\u{9b}");
        assert_eq!(s, "a\\u{1b}]0;title\\u{7}b\\nc\\u{9b}");
        assert!(!s.chars().any(char::is_control));
        assert_eq!(lines("a\nb\u{1b}"), "a\nb\\u{1b}");
    }

    #[test]
    fn excerpts_are_short_and_printable() {
        let e = excerpt(&[0u8; 1 << 20]);
        assert!(e.len() < 400, "{}", e.len());
        assert!(e.ends_with('…'));
        assert_eq!(excerpt(b"v 1 2\xff"), "v 1 2\\xff");
        assert!(!excerpt(b"\x1b[2J").chars().any(char::is_control));
    }
}
