//! Errors in scene files, located by file, line, column and field path.
//!
//! Field paths use the scene's own spelling: `body[0].region.radius`,
//! `material[1].E`. Parse errors (syntax, unknown keys, wrong types) come
//! from the TOML deserializer with a byte span; semantic errors (negative E,
//! points outside the grid) name a field path, which is looked up in the
//! spanned TOML document to find its line.

use std::fmt;
use std::ops::Range;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

/// A mistake in a scene file.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneError {
    pub file: String,
    /// 1-based line (0 when the file could not be read at all).
    pub line: usize,
    /// 1-based column.
    pub column: usize,
    /// Dotted path of the offending field, e.g. `material[0].nu`.
    pub field: String,
    pub message: String,
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}: {}", self.file, self.field, self.message)
        } else {
            write!(
                f,
                "{}:{}:{}: field `{}`: {}",
                self.file, self.line, self.column, self.field, self.message
            )
        }
    }
}

impl std::error::Error for SceneError {}

/// A field path and a message, before it is located in the file.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldError {
    pub field: String,
    pub message: String,
}

impl FieldError {
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        FieldError {
            field: field.into(),
            message: message.into(),
        }
    }
}

/// 1-based line and column of a byte offset.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before.rfind('\n').map_or(offset, |k| offset - k - 1) + 1;
    (line, column)
}

enum Seg<'a> {
    Key(&'a str),
    Index(usize),
}

fn segments(path: &str) -> Vec<Seg<'_>> {
    let mut out = Vec::new();
    for part in path.split('.') {
        let (key, rest) = part.split_once('[').map_or((part, ""), |(k, r)| (k, r));
        if !key.is_empty() {
            out.push(Seg::Key(key));
        }
        for idx in rest.split('[') {
            if let Ok(i) = idx.trim_end_matches(']').parse() {
                out.push(Seg::Index(i));
            }
        }
    }
    out
}

/// The spanned document of a scene file, for locating fields.
pub struct Locator<'a> {
    text: &'a str,
    root: Option<Spanned<DeTable<'a>>>,
}

impl<'a> Locator<'a> {
    pub fn new(text: &'a str) -> Self {
        Locator {
            text,
            root: Some(DeTable::parse_recoverable(text).0),
        }
    }

    /// Span of the deepest existing prefix of `path` (the key, for a
    /// missing leaf, falls back to its table).
    pub fn span(&self, path: &str) -> Range<usize> {
        let Some(root) = &self.root else { return 0..0 };
        let mut span = 0..0;
        let mut table: Option<&DeTable<'_>> = Some(root.get_ref());
        let mut array: Option<&[Spanned<DeValue<'_>>]> = None;
        for seg in segments(path) {
            let value = match seg {
                Seg::Key(k) => table
                    .and_then(|t| t.iter().find(|(key, _)| key.get_ref() == k))
                    .map(|(key, v)| {
                        span = key.span();
                        v
                    }),
                Seg::Index(i) => array.and_then(|a| a.get(i)).inspect(|v| span = v.span()),
            };
            let Some(value) = value else { break };
            table = value.get_ref().as_table();
            array = value.get_ref().as_array().map(|a| &a[..]);
        }
        span
    }

    pub fn error(&self, file: &str, e: FieldError) -> SceneError {
        let (line, column) = line_column(self.text, self.span(&e.field).start);
        SceneError {
            file: file.to_string(),
            line,
            column,
            field: e.field,
            message: e.message,
        }
    }

    /// The dotted path of the innermost field whose key or value covers
    /// `offset`. Tables opened by a `[header]` span only their header, so
    /// every child is searched, not just those whose parent covers `offset`.
    pub fn path_at(&self, offset: usize) -> String {
        let Some(root) = &self.root else { return String::new() };
        find_in_table(root.get_ref(), "", offset).unwrap_or_default()
    }

    /// The value at a field path.
    fn value(&self, path: &str) -> Option<&Spanned<DeValue<'a>>> {
        let root = self.root.as_ref()?;
        let mut table: Option<&DeTable<'a>> = Some(root.get_ref());
        let mut array: Option<&[Spanned<DeValue<'a>>]> = None;
        let mut value = None;
        for seg in segments(path) {
            let v = match seg {
                Seg::Key(k) => table
                    .and_then(|t| t.iter().find(|(key, _)| key.get_ref() == k))
                    .map(|(_, v)| v),
                Seg::Index(i) => array.and_then(|a| a.get(i)),
            }?;
            table = v.get_ref().as_table();
            array = v.get_ref().as_array().map(|a| &a[..]);
            value = Some(v);
        }
        value
    }

    /// For an error reported at the table `path`: the one field below it
    /// that the message describes (`unknown field `x``, `invalid type:
    /// string "a"`, `invalid length 3`, `unknown variant `v``), with the
    /// offset of its key or value.
    pub fn refine(&self, path: &str, message: &str) -> Option<(String, usize)> {
        let table = self.value(path)?.get_ref().as_table()?;
        // The table itself may be what the message describes.
        if message.starts_with("invalid type: map") {
            return None;
        }
        if let Some(key) = message
            .strip_prefix("unknown field `")
            .and_then(|r| r.split_once('`'))
            .map(|(k, _)| k)
        {
            let (k, _) = table.iter().find(|(k, _)| k.get_ref() == key)?;
            return Some((join(path, key), k.span().start));
        }
        let described = message
            .strip_prefix("invalid type: ")
            .or_else(|| message.strip_prefix("invalid value: "))
            .map(|r| r.split(", expected").next().unwrap_or(r).to_string())
            .or_else(|| {
                message
                    .strip_prefix("unknown variant `")
                    .and_then(|r| r.split_once('`'))
                    .map(|(v, _)| format!("string \"{v}\""))
            })
            .or_else(|| {
                message
                    .strip_prefix("invalid length ")
                    .and_then(|r| r.split(',').next())
                    .map(|n| format!("length {n}"))
            })?;
        let mut found = Vec::new();
        matching(table, path, &described, &mut found);
        match found.as_slice() {
            [(p, at)] => Some((p.clone(), *at)),
            _ => None,
        }
    }

    /// Every real number in the document must be finite, and zero or of a
    /// magnitude in `[MIN_MAGNITUDE, MAX_MAGNITUDE]`: the first that is not,
    /// with its field path.
    pub fn check_numbers(&self) -> Result<(), FieldError> {
        let Some(root) = &self.root else { return Ok(()) };
        numbers_in_table(root.get_ref(), "")
    }
}

/// Largest magnitude of a real number in a scene.
pub const MAX_MAGNITUDE: f64 = 1e30;
/// Smallest non-zero magnitude of a real number in a scene.
pub const MIN_MAGNITUDE: f64 = 1e-30;

/// A number for a message: plain when short, `1.2346e-300` otherwise.
pub fn number(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || ((1e-4..1e9).contains(&a) && format!("{x}").len() <= 20) {
        format!("{x}")
    } else {
        format!("{x:.4e}")
    }
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

fn find_in_table(t: &DeTable<'_>, path: &str, offset: usize) -> Option<String> {
    for (k, v) in t.iter() {
        let p = join(path, k.get_ref());
        if let Some(deeper) = find_in_value(v.get_ref(), &p, offset) {
            return Some(deeper);
        }
        if k.span().contains(&offset) || v.span().contains(&offset) || k.span().end == offset {
            return Some(p);
        }
    }
    None
}

fn find_in_value(v: &DeValue<'_>, path: &str, offset: usize) -> Option<String> {
    if let Some(t) = v.as_table() {
        return find_in_table(t, path, offset);
    }
    for (i, e) in v.as_array()?.iter().enumerate() {
        let p = format!("{path}[{i}]");
        if let Some(deeper) = find_in_value(e.get_ref(), &p, offset) {
            return Some(deeper);
        }
        if e.span().contains(&offset) {
            return Some(p);
        }
    }
    None
}

/// Fields below `table` whose value fits a serde description such as
/// `string "a"`, `integer `3``, `floating point `1.5``, `boolean `true``,
/// `sequence`, `map` or `length 3`.
fn matching(table: &DeTable<'_>, path: &str, described: &str, out: &mut Vec<(String, usize)>) {
    for (k, v) in table.iter() {
        let p = join(path, k.get_ref());
        let x = v.get_ref();
        let arg = |prefix: &str| described.strip_prefix(prefix).map(|r| r.trim_matches('`').to_string());
        let fits = if let Some(s) = arg("string ") {
            x.as_str().is_some_and(|v| format!("{v:?}") == s)
        } else if let Some(i) = arg("integer ") {
            x.as_integer().is_some_and(|v| v.as_str().replace('_', "") == i)
        } else if let Some(f) = arg("floating point ") {
            x.as_float()
                .is_some_and(|v| v.as_str().replace('_', "").parse::<f64>().ok() == f.parse::<f64>().ok())
        } else if let Some(b) = arg("boolean ") {
            x.as_bool().is_some_and(|v| v.to_string() == b)
        } else if let Some(n) = arg("length ") {
            x.as_array().is_some_and(|a| a.len().to_string() == n)
        } else {
            match described {
                "sequence" => x.is_array(),
                "map" => x.is_table(),
                _ => false,
            }
        };
        if fits {
            out.push((p.clone(), k.span().start));
        }
        if let Some(t) = x.as_table() {
            matching(t, &p, described, out);
        }
    }
}

/// Keys whose values are points or 2-vectors `[x, y]`, alone or in a list.
const PAIRS: &[&str] = &[
    "origin",
    "size",
    "min",
    "max",
    "center",
    "about",
    "anchor",
    "velocity",
    "velocity_centre",
    "velocity_gradient",
    "at",
    "force",
    "gravity",
    "displacement",
    "lattice",
    "value",
    "points",
    "vertices",
    "close_via",
    "node",
];

/// A list of numbers given for a pair must have two (serde takes the
/// first two of a longer list silently).
fn check_pairs(path: &str, key: &str, v: &DeValue<'_>) -> Result<(), FieldError> {
    if !PAIRS.contains(&key) {
        return Ok(());
    }
    let Some(a) = v.as_array() else { return Ok(()) };
    let numeric = |x: &DeValue<'_>| x.is_float() || x.is_integer();
    if !a.is_empty() && a.iter().all(|x| numeric(x.get_ref())) && a.len() != 2 {
        return Err(FieldError::new(
            path,
            format!("expected a pair of numbers [a, b], got {} numbers", a.len()),
        ));
    }
    for (i, x) in a.iter().enumerate() {
        if let Some(inner) = x.get_ref().as_array() {
            if !inner.is_empty() && inner.iter().all(|y| numeric(y.get_ref())) && inner.len() != 2 {
                return Err(FieldError::new(
                    format!("{path}[{i}]"),
                    format!("expected a pair of numbers [a, b], got {} numbers", inner.len()),
                ));
            }
        }
    }
    Ok(())
}

fn check_number(path: &str, v: &DeValue<'_>) -> Result<(), FieldError> {
    let Some(f) = v.as_float() else { return Ok(()) };
    let x: f64 = f.as_str().replace('_', "").parse().unwrap_or(f64::NAN);
    if !x.is_finite() {
        return Err(FieldError::new(
            path,
            format!("must be a finite number, got {}", f.as_str()),
        ));
    }
    let a = x.abs();
    if a > MAX_MAGNITUDE || (x != 0.0 && a < MIN_MAGNITUDE) {
        return Err(FieldError::new(
            path,
            format!(
                "{} is out of range: numbers in a scene are zero or of magnitude between {} and {}",
                number(x),
                number(MIN_MAGNITUDE),
                number(MAX_MAGNITUDE)
            ),
        ));
    }
    Ok(())
}

fn numbers_in_table(t: &DeTable<'_>, path: &str) -> Result<(), FieldError> {
    for (k, v) in t.iter() {
        let p = join(path, k.get_ref());
        check_pairs(&p, k.get_ref(), v.get_ref())?;
        numbers_in_value(v.get_ref(), &p)?;
    }
    Ok(())
}

fn numbers_in_value(v: &DeValue<'_>, path: &str) -> Result<(), FieldError> {
    if let Some(t) = v.as_table() {
        return numbers_in_table(t, path);
    }
    if let Some(a) = v.as_array() {
        for (i, e) in a.iter().enumerate() {
            numbers_in_value(e.get_ref(), &format!("{path}[{i}]"))?;
        }
        return Ok(());
    }
    check_number(path, v)
}

/// The field a line of TOML text sets, from its headers and its key: the
/// fallback for text the TOML parser cannot make into a document.
pub fn path_of_line(text: &str, line: usize) -> String {
    let mut counts: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    let mut table = String::new();
    // Resolve a dotted header against the arrays of tables seen so far.
    let resolve = |name: &str, counts: &std::collections::HashMap<String, usize>| {
        let mut out = String::new();
        let mut prefix = String::new();
        for part in name.split('.') {
            let part = part.trim().trim_matches('"');
            prefix = join(&prefix, part);
            out = join(&out, part);
            if let Some(n) = counts.get(&prefix) {
                out.push_str(&format!("[{}]", n.saturating_sub(1)));
            }
        }
        out
    };
    let is_name = |n: &str| {
        let n = n.trim();
        !n.is_empty()
            && n.chars().all(|c| c.is_alphanumeric() || "_-.\"' ".contains(c))
            && !n.starts_with(|c: char| c.is_ascii_digit())
    };
    for (i, l) in text.lines().enumerate() {
        let t = l.trim();
        let header = t
            .strip_prefix('[')
            .map(|r| r.trim_start_matches('[').split(']').next().unwrap_or(r));
        if !header.is_some_and(is_name) {
            if i + 1 == line {
                let key = t.split_once('=').map(|(k, _)| k.trim()).filter(|k| is_name(k));
                if let Some(k) = key {
                    let k: String = k
                        .split('.')
                        .map(|s| s.trim().trim_matches('"'))
                        .collect::<Vec<_>>()
                        .join(".");
                    return join(&table, &k);
                }
                return table;
            }
        } else if let Some(name) = t.strip_prefix("[[") {
            let name = name.split("]]").next().unwrap_or(name);
            let name: String = name
                .split('.')
                .map(|s| s.trim().trim_matches('"'))
                .collect::<Vec<_>>()
                .join(".");
            *counts.entry(name.clone()).or_insert(0) += 1;
            table = resolve(&name, &counts);
        } else if let Some(rest) = t.strip_prefix('[') {
            // `[name]`, or an unclosed `[name` on the line of the error.
            let name = rest.split(']').next().unwrap_or(rest).trim();
            table = resolve(name, &counts);
        }
        if i + 1 == line {
            return table;
        }
    }
    table
}

/// Turn a TOML deserialization error into a located scene error: the
/// innermost field at the error, the missing field for `missing field`
/// errors, or the key of the offending line when the text is no document.
pub fn from_toml(file: &str, text: &str, e: &toml::de::Error) -> SceneError {
    let offset = e.span().map_or(0, |s| s.start);
    let (mut line, mut column) = line_column(text, offset);
    let message = e.message().trim().to_string();
    let locator = Locator::new(text);
    let mut field = locator.path_at(offset);
    if DeTable::parse(text).is_err() {
        // Not a TOML document: the tree recovered from it may be skewed,
        // so the line's own table and key decide, unless the tree names a
        // field inside that same table.
        let trusted = !field.is_empty() && locator.span(&field).start <= offset;
        if !trusted {
            field = path_of_line(text, line);
        }
    } else if let Some((deeper, at)) = locator.refine(&field, &message) {
        // Errors inside tagged tables (regions, tractions, exact solutions)
        // come with the table's span: find the field the message is about.
        field = deeper;
        (line, column) = line_column(text, at);
    }
    if let Some(missing) = message
        .strip_prefix("missing field `")
        .and_then(|r| r.split_once('`'))
        .map(|(m, _)| m)
    {
        if !field.ends_with(missing) {
            field = join(&field, missing);
        }
    }
    SceneError {
        file: file.to_string(),
        line,
        column,
        field: if field.is_empty() { "(top level)".into() } else { field },
        message,
    }
}
