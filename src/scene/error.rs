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
            root: DeTable::parse(text).ok(),
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

    /// The dotted path of the innermost field whose key or value covers `offset`.
    pub fn path_at(&self, offset: usize) -> String {
        let Some(root) = &self.root else { return String::new() };
        let mut path = String::new();
        let mut value: Option<&DeValue<'_>> = None;
        let mut table = Some(root.get_ref());
        loop {
            let mut next = None;
            if let Some(t) = table {
                for (k, v) in t.iter() {
                    if k.span().contains(&offset) || v.span().contains(&offset) || k.span().end == offset {
                        if !path.is_empty() {
                            path.push('.');
                        }
                        path.push_str(k.get_ref());
                        next = Some(v);
                        break;
                    }
                }
            } else if let Some(a) = value.and_then(|v| v.as_array()) {
                for (i, v) in a.iter().enumerate() {
                    if v.span().contains(&offset) {
                        path.push_str(&format!("[{i}]"));
                        next = Some(v);
                        break;
                    }
                }
            }
            let Some(v) = next else { break };
            value = Some(v.get_ref());
            table = v.get_ref().as_table();
        }
        path
    }
}

/// Turn a TOML deserialization error into a located scene error.
pub fn from_toml(file: &str, text: &str, e: &toml::de::Error) -> SceneError {
    let offset = e.span().map_or(0, |s| s.start);
    let (line, column) = line_column(text, offset);
    let field = Locator::new(text).path_at(offset);
    SceneError {
        file: file.to_string(),
        line,
        column,
        field: if field.is_empty() { "(document)".into() } else { field },
        message: e.message().trim().to_string(),
    }
}
