//! Errors a person can act on: every error names the file and the field.

use std::fmt;

/// What went wrong, for callers that branch on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// The file could not be read.
    Io,
    /// The file is not valid JSON.
    Json,
    /// A field that the format does not know.
    UnknownField,
    /// A required field is absent.
    MissingField,
    /// A field has the wrong type or is out of range.
    BadValue,
    /// A layer names a block that does not exist.
    UnknownBlock,
    /// A graph link names a node or endpoint that does not exist.
    DanglingLink,
    /// Two materials have the same name.
    Clash,
    /// A name that is not in the catalogue.
    UnknownMaterial,
}

/// A material-catalogue error: the file, the field inside it, what is wrong and what to do.
#[derive(Debug, Clone, PartialEq)]
pub struct Error {
    /// What went wrong.
    pub kind: ErrorKind,
    /// The material file (catalogue-relative for built-ins, a path for user files).
    pub file: String,
    /// The field, as a JSON path like `layers[0].colors[1]`; empty for whole-file errors.
    pub field: String,
    /// Lowercase description of the problem.
    pub message: String,
    /// What to do about it.
    pub hint: String,
}

impl Error {
    pub(crate) fn new(
        kind: ErrorKind,
        file: &str,
        field: &str,
        message: impl Into<String>,
        hint: impl Into<String>,
    ) -> Error {
        Error {
            kind,
            file: file.to_string(),
            field: field.to_string(),
            message: message.into(),
            hint: hint.into(),
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "material file `{}`: {}", self.file, self.message)?;
        } else {
            write!(
                f,
                "material file `{}`, field `{}`: {}",
                self.file, self.field, self.message
            )?;
        }
        write!(f, "\nhint: {}", self.hint)
    }
}

impl std::error::Error for Error {}
