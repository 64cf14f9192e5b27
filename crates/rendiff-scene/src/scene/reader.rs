//! A typed, strict reader over toml's spanned document tree.
//!
//! serde's derive would give "unknown field" errors, but a rule such as
//! "radius > 0" needs the value's position after deserialisation too, and
//! the messages would come from two places. This reader asks for each key
//! by name and type, so every error — syntax, unknown key, wrong type,
//! missing key, broken rule — carries the file, line, column and dotted key,
//! and the list of keys a table accepts is exactly the list of keys the
//! loader asks for.

use std::cell::RefCell;
use std::ops::Range;
use std::path::Path;

use toml::Spanned;
use toml::de::{DeArray, DeTable, DeValue};

use super::error::{LoadError, Loc};
use rendiff_core::math::DVec3;

/// The scene file's text and path, for locating spans.
pub(crate) struct Source<'a> {
    pub path: &'a Path,
    pub text: &'a str,
}

impl Source<'_> {
    /// Line and column (1-based, columns in characters) of a byte offset.
    pub fn loc(&self, offset: usize) -> Loc {
        let offset = offset.min(self.text.len());
        let before = &self.text[..floor_char_boundary(self.text, offset)];
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        let col = before[line_start..].chars().count() + 1;
        Loc { line, col }
    }
}

/// The known name closest to `name` by [`edit_distance`], if one is close
/// enough to be a typo of it: within 2 edits, and fewer edits than half the
/// longer name (so `ior` is not offered for `fov`). Ties go to the first
/// in `known`'s order.
pub(crate) fn suggestion<'k>(name: &str, known: &[&'k str]) -> Option<&'k str> {
    known
        .iter()
        .map(|k| (edit_distance(name, k), *k))
        .filter(|&(d, k)| {
            let longer = name.chars().count().max(k.chars().count());
            d <= 2 && 2 * d < longer
        })
        .min_by_key(|&(d, _)| d)
        .map(|(_, k)| k)
}

/// The optimal-string-alignment distance (Damerau–Levenshtein with each
/// substring edited once) between `a` and `b`, in characters: insertions,
/// deletions, substitutions and swaps of two neighbours count one each.
pub(crate) fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    // Three rows of the dynamic programme: two back, one back, this one.
    let mut two: Vec<usize> = vec![0; b.len() + 1];
    let mut one: Vec<usize> = (0..=b.len()).collect();
    let mut row: Vec<usize> = vec![0; b.len() + 1];
    for i in 1..=a.len() {
        row[0] = i;
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut d = (one[j] + 1).min(row[j - 1] + 1).min(one[j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                d = d.min(two[j - 2] + 1);
            }
            row[j] = d;
        }
        std::mem::swap(&mut two, &mut one);
        std::mem::swap(&mut one, &mut row);
    }
    one[b.len()]
}

fn floor_char_boundary(s: &str, mut i: usize) -> usize {
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

pub(crate) type Span = Range<usize>;

/// A table being read: every key asked for is remembered, and
/// [`Table::finish`] rejects the others.
pub(crate) struct Table<'s, 'i> {
    src: &'s Source<'s>,
    /// Dotted name of this table ("" for the root).
    pub name: String,
    table: &'s DeTable<'i>,
    span: Span,
    asked: RefCell<Vec<&'static str>>,
}

/// A value with its position.
pub(crate) struct At<T> {
    pub value: T,
    pub span: Span,
}

impl<'s, 'i> Table<'s, 'i> {
    pub fn new(src: &'s Source<'s>, name: String, table: &'s DeTable<'i>, span: Span) -> Self {
        Table {
            src,
            name,
            table,
            span,
            asked: RefCell::new(Vec::new()),
        }
    }

    /// The dotted key of `key` in this table.
    pub fn key_name(&self, key: &str) -> String {
        if self.name.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.name)
        }
    }

    pub fn loc(&self, span: &Span) -> Loc {
        self.src.loc(span.start)
    }

    /// Where this table starts (its `[header]`, or its inline `{`).
    pub fn start(&self) -> Loc {
        self.loc(&self.span)
    }

    pub fn path(&self) -> &Path {
        self.src.path
    }

    pub fn source(&self) -> &'s Source<'s> {
        self.src
    }

    /// An error at `span` about `key`.
    pub fn err(&self, span: &Span, key: &str, message: impl Into<String>) -> LoadError {
        LoadError::key(self.src.path, self.loc(span), self.key_name(key), message)
    }

    /// An error about this table as a whole (e.g. a missing key).
    pub fn err_here(&self, key: &str, message: impl Into<String>) -> LoadError {
        LoadError::key(
            self.src.path,
            self.loc(&self.span),
            self.key_name(key),
            message,
        )
    }

    fn raw(&self, key: &'static str) -> Option<&'s Spanned<DeValue<'i>>> {
        self.asked.borrow_mut().push(key);
        self.table
            .iter()
            .find(|(k, _)| k.get_ref().as_ref() == key)
            .map(|(_, v)| v)
    }

    /// `true` when the key is present (and marks it as known).
    pub fn has(&self, key: &'static str) -> bool {
        self.raw(key).is_some()
    }

    /// Span of a key's value, if present.
    pub fn span_of(&self, key: &'static str) -> Option<Span> {
        self.raw(key).map(Spanned::span)
    }

    /// A required key is absent. A key of this table that was never asked
    /// for and is close enough to be a typo of it ([`suggestion`]:
    /// `postion` for `position`, not `max` for `min`) is named, at its own
    /// place.
    pub fn missing(&self, key: &str) -> LoadError {
        let typo = {
            let asked = self.asked.borrow();
            let others: Vec<&str> = self
                .table
                .iter()
                .map(|(k, _)| -> &str { k.get_ref().as_ref() })
                .filter(|name| *name != key && !asked.contains(name))
                .collect();
            suggestion(key, &others).and_then(|name| {
                self.table
                    .iter()
                    .map(|(k, _)| k)
                    .find(|k| -> bool { k.get_ref().as_ref() == name })
            })
        };
        if self.name.is_empty() {
            // Every top-level key is a table.
            if let Some(k) = typo {
                return self.err(
                    &k.span(),
                    key,
                    format!(
                        "missing required table [{key}] (found [{}]: a typo?)",
                        k.get_ref()
                    ),
                );
            }
            return self.err_here(key, format!("missing required table [{key}]"));
        }
        if let Some(k) = typo {
            return self.err(
                &k.span(),
                key,
                format!(
                    "missing required key `{key}` {} (found `{}`: a typo?)",
                    self.display_name(),
                    k.get_ref()
                ),
            );
        }
        self.err_here(
            key,
            format!("missing required key `{key}` {}", self.display_name()),
        )
    }

    /// "in [image]", "in objects[2]" or "at the top level".
    fn display_name(&self) -> String {
        if self.name.is_empty() {
            "at the top level".to_string()
        } else if self.name.ends_with(']') {
            format!("in {}", self.name)
        } else {
            format!("in [{}]", self.name)
        }
    }

    /// Rejects keys that were never asked for.
    pub fn finish(&self) -> Result<(), LoadError> {
        let asked = self.asked.borrow();
        for (k, _) in self.table.iter() {
            let name: &str = k.get_ref().as_ref();
            if !asked.contains(&name) {
                let mut expected: Vec<&str> = asked.clone();
                expected.sort_unstable();
                expected.dedup();
                let list = expected
                    .iter()
                    .map(|e| format!("`{e}`"))
                    .collect::<Vec<_>>()
                    .join(", ");
                let hint = suggestion(name, &expected)
                    .map(|s| format!(" (did you mean `{s}`?)"))
                    .unwrap_or_default();
                return Err(self.err(
                    &k.span(),
                    name,
                    format!(
                        "unknown key {}{hint}; expected one of: {list}",
                        self.display_name()
                    ),
                ));
            }
        }
        Ok(())
    }

    // ---- typed getters ---------------------------------------------------

    pub fn f64(&self, key: &'static str) -> Result<Option<At<f64>>, LoadError> {
        let Some(v) = self.raw(key) else {
            return Ok(None);
        };
        let value = number(v.get_ref()).ok_or_else(|| {
            self.err(
                &v.span(),
                key,
                format!("expected a number, got {}", type_name(v.get_ref())),
            )
        })?;
        if !value.is_finite() {
            return Err(self.err(
                &v.span(),
                key,
                format!("expected a finite number, got {value}"),
            ));
        }
        Ok(Some(At {
            value,
            span: v.span(),
        }))
    }

    pub fn req_f64(&self, key: &'static str) -> Result<At<f64>, LoadError> {
        self.f64(key)?.ok_or_else(|| self.missing(key))
    }

    pub fn int(&self, key: &'static str) -> Result<Option<At<i64>>, LoadError> {
        let Some(v) = self.raw(key) else {
            return Ok(None);
        };
        match v.get_ref() {
            DeValue::Integer(i) => {
                let value = parse_int(i.as_str(), i.radix()).ok_or_else(|| {
                    self.err(
                        &v.span(),
                        key,
                        format!("integer {} is out of range", i.as_str()),
                    )
                })?;
                Ok(Some(At {
                    value,
                    span: v.span(),
                }))
            }
            other => Err(self.err(
                &v.span(),
                key,
                format!("expected an integer, got {}", type_name(other)),
            )),
        }
    }

    pub fn bool(&self, key: &'static str) -> Result<Option<At<bool>>, LoadError> {
        let Some(v) = self.raw(key) else {
            return Ok(None);
        };
        match v.get_ref() {
            DeValue::Boolean(b) => Ok(Some(At {
                value: *b,
                span: v.span(),
            })),
            other => Err(self.err(
                &v.span(),
                key,
                format!("expected true or false, got {}", type_name(other)),
            )),
        }
    }

    /// An option string (`depth = "u24"`) parsed by its `FromStr`, the
    /// parse error reported at the value with the key named.
    pub fn option<T>(&self, key: &'static str) -> Result<Option<T>, LoadError>
    where
        T: std::str::FromStr<Err = rendiff_core::options::ParseOptionError>,
    {
        let Some(s) = self.string(key)? else {
            return Ok(None);
        };
        s.value
            .parse()
            .map(Some)
            .map_err(|e: rendiff_core::options::ParseOptionError| self.err(&s.span, key, e.message))
    }

    pub fn string(&self, key: &'static str) -> Result<Option<At<String>>, LoadError> {
        let Some(v) = self.raw(key) else {
            return Ok(None);
        };
        match v.get_ref() {
            DeValue::String(s) => Ok(Some(At {
                value: s.to_string(),
                span: v.span(),
            })),
            other => Err(self.err(
                &v.span(),
                key,
                format!("expected a string, got {}", type_name(other)),
            )),
        }
    }

    pub fn req_string(&self, key: &'static str) -> Result<At<String>, LoadError> {
        self.string(key)?.ok_or_else(|| self.missing(key))
    }

    /// A vector of exactly `N` finite numbers.
    pub fn floats<const N: usize>(
        &self,
        key: &'static str,
    ) -> Result<Option<At<[f64; N]>>, LoadError> {
        let Some(v) = self.raw(key) else {
            return Ok(None);
        };
        let value = floats_of::<N>(v).map_err(|m| self.err(&v.span(), key, m))?;
        Ok(Some(At {
            value,
            span: v.span(),
        }))
    }

    pub fn vec3(&self, key: &'static str) -> Result<Option<At<DVec3>>, LoadError> {
        Ok(self.floats::<3>(key)?.map(|a| At {
            value: DVec3::from_array(a.value),
            span: a.span,
        }))
    }

    pub fn req_vec3(&self, key: &'static str) -> Result<At<DVec3>, LoadError> {
        self.vec3(key)?.ok_or_else(|| self.missing(key))
    }

    /// A sub-table (a `[a.b]` table or an inline table).
    pub fn table(&self, key: &'static str) -> Result<Option<Table<'s, 'i>>, LoadError> {
        let Some(v) = self.raw(key) else {
            return Ok(None);
        };
        match v.get_ref() {
            DeValue::Table(t) => Ok(Some(Table::new(self.src, self.key_name(key), t, v.span()))),
            other => Err(self.err(
                &v.span(),
                key,
                format!("expected a table, got {}", type_name(other)),
            )),
        }
    }

    /// An array value.
    pub fn array(&self, key: &'static str) -> Result<Option<(&'s DeArray<'i>, Span)>, LoadError> {
        let Some(v) = self.raw(key) else {
            return Ok(None);
        };
        match v.get_ref() {
            DeValue::Array(a) => Ok(Some((a, v.span()))),
            other => Err(self.err(
                &v.span(),
                key,
                format!("expected an array, got {}", type_name(other)),
            )),
        }
    }

    /// The entries of this table in key order (for `[materials]`).
    pub fn entries(
        &self,
    ) -> impl Iterator<
        Item = (
            &'s Spanned<std::borrow::Cow<'i, str>>,
            &'s Spanned<DeValue<'i>>,
        ),
    > {
        self.table.iter()
    }
}

/// A number for a message: Rust's shortest round-trip form, in exponent
/// form when very large or very small (so 1e300 is not 301 digits).
pub(crate) fn num(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || !a.is_finite() || (1e-4..1e16).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A number (integer or float) as `f64`.
pub(crate) fn number(v: &DeValue<'_>) -> Option<f64> {
    match v {
        #[expect(
            clippy::cast_precision_loss,
            reason = "integers are accepted where a float is expected (DESIGN.md §4)"
        )]
        DeValue::Integer(i) => parse_int(i.as_str(), i.radix())
            .map(|x| x as f64)
            .or_else(|| int_as_f64(i.as_str(), i.radix())),
        DeValue::Float(f) => {
            let s: String = f.as_str().chars().filter(|c| *c != '_').collect();
            let s = s.trim_start_matches('+');
            s.parse::<f64>().ok()
        }
        _ => None,
    }
}

fn parse_int(s: &str, radix: u32) -> Option<i64> {
    let s: String = s.chars().filter(|c| *c != '_').collect();
    let (neg, digits) = match s.strip_prefix('-') {
        Some(d) => (true, d.to_string()),
        None => (false, s.trim_start_matches('+').to_string()),
    };
    let digits = if radix == 10 {
        digits.as_str()
    } else {
        digits
            .get(2..)
            .filter(|_| digits.starts_with('0'))
            .unwrap_or(digits.as_str())
    };
    let v = i64::from_str_radix(digits, radix).ok()?;
    Some(if neg { -v } else { v })
}

/// An integer beyond i64 as the nearest f64 (or infinity), so where a
/// number is expected it meets the same range checks as a float of that
/// size instead of being "not a number".
fn int_as_f64(s: &str, radix: u32) -> Option<f64> {
    let s: String = s.chars().filter(|c| *c != '_').collect();
    let (neg, digits) = match s.strip_prefix('-') {
        Some(d) => (true, d),
        None => (false, s.trim_start_matches('+')),
    };
    if radix == 10 {
        let v = digits.parse::<f64>().ok()?;
        return Some(if neg { -v } else { v });
    }
    let digits = digits.get(2..).unwrap_or(digits);
    let mut v = 0.0f64;
    for c in digits.chars() {
        v = v * f64::from(radix) + f64::from(c.to_digit(radix)?);
    }
    Some(if neg { -v } else { v })
}

/// The parser's nesting limit (toml 1.2: dotted keys of 80 parts, arrays
/// and inline tables 80 deep), and where the text first reaches it —
/// the parser reports it without a position.
pub(crate) const NESTING_LIMIT: usize = 80;

/// The byte offset where `text` first nests [`NESTING_LIMIT`] deep: a key
/// (before `=`, or in a `[table]` header) of that many dotted parts, or
/// that many open arrays and inline tables. Strings and comments are
/// skipped.
pub(crate) fn deep_nesting(text: &str) -> Option<usize> {
    let b = text.as_bytes();
    let (mut i, mut depth, mut parts) = (0usize, 0usize, 1usize);
    // In a key: at the start of a line, in a header, or after `{` / `,`
    // inside an inline table, until `=` (or `]` of the header).
    let mut in_key = true;
    while i < b.len() {
        let c = b[i];
        match c {
            b'#' => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
                continue;
            }
            b'"' | b'\'' => {
                let triple = b[i..].starts_with(if c == b'"' { b"\"\"\"" } else { b"'''" });
                let q = c;
                i += if triple { 3 } else { 1 };
                while i < b.len() {
                    if q == b'"' && b[i] == b'\\' {
                        i += 2;
                        continue;
                    }
                    if triple {
                        if b[i..].starts_with(if q == b'"' { b"\"\"\"" } else { b"'''" }) {
                            i += 3;
                            break;
                        }
                    } else if b[i] == q || b[i] == b'\n' {
                        i += 1;
                        break;
                    }
                    i += 1;
                }
                continue;
            }
            b'\n' if depth == 0 => {
                in_key = true;
                parts = 1;
            }
            b'.' if in_key => {
                parts += 1;
                if parts >= NESTING_LIMIT {
                    return Some(i);
                }
            }
            b'=' => in_key = false,
            b'[' | b'{' if c == b'{' || !in_key || depth > 0 => {
                depth += 1;
                if depth >= NESTING_LIMIT {
                    return Some(i);
                }
                if c == b'{' {
                    in_key = true;
                    parts = 1;
                }
            }
            b']' | b'}' => {
                depth = depth.saturating_sub(1);
            }
            b',' if depth > 0 => {
                in_key = true;
                parts = 1;
            }
            _ => {}
        }
        i += 1;
    }
    None
}

pub(crate) fn type_name(v: &DeValue<'_>) -> &'static str {
    match v {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a float",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date-time",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

/// `N` finite numbers from an array value, or a message.
pub(crate) fn floats_of<const N: usize>(v: &Spanned<DeValue<'_>>) -> Result<[f64; N], String> {
    let DeValue::Array(items) = v.get_ref() else {
        return Err(format!(
            "expected an array of {N} numbers, got {}",
            type_name(v.get_ref())
        ));
    };
    if items.len() != N {
        return Err(format!(
            "expected an array of {N} numbers, got {} element{}",
            items.len(),
            if items.len() == 1 { "" } else { "s" }
        ));
    }
    let mut out = [0.0; N];
    for (k, item) in items.iter().enumerate() {
        let x = number(item.get_ref()).ok_or_else(|| {
            format!(
                "expected an array of {N} numbers, element {k} is {}",
                type_name(item.get_ref())
            )
        })?;
        if !x.is_finite() {
            return Err(format!("element {k} is {x}; expected a finite number"));
        }
        out[k] = x;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_in_every_radix() {
        assert_eq!(parse_int("1_000", 10), Some(1000));
        assert_eq!(parse_int("-42", 10), Some(-42));
        assert_eq!(parse_int("0xff", 16), Some(255));
        assert_eq!(parse_int("0o17", 8), Some(15));
        assert_eq!(parse_int("0b101", 2), Some(5));
        assert_eq!(parse_int("99999999999999999999", 10), None);
    }

    #[test]
    fn loc_counts_lines_and_characters() {
        let src = Source {
            path: Path::new("x.toml"),
            text: "a = 1\nbé = 2\n",
        };
        assert_eq!(src.loc(0), Loc { line: 1, col: 1 });
        let off = src.text.find('=').unwrap();
        assert_eq!(src.loc(off), Loc { line: 1, col: 3 });
        let off = src.text.rfind('=').unwrap();
        assert_eq!(src.loc(off), Loc { line: 2, col: 4 });
    }

    #[test]
    fn edit_distance_counts_swaps_as_one() {
        assert_eq!(edit_distance("position", "postion"), 1);
        assert_eq!(edit_distance("phong_size", "phong_sise"), 1);
        assert_eq!(edit_distance("radius", "raduis"), 1);
        assert_eq!(edit_distance("", "eye"), 3);
        assert_eq!(edit_distance("eye", "eye"), 0);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }

    #[test]
    fn suggestions_are_close_and_not_short_coincidences() {
        let known = ["phong", "phong_size", "ior", "ambient"];
        assert_eq!(suggestion("phong_sise", &known), Some("phong_size"));
        assert_eq!(suggestion("phongg", &known), Some("phong"));
        assert_eq!(suggestion("fov", &known), None);
        assert_eq!(suggestion("colour", &known), None);
    }
}
