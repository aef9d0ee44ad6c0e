//! Scene errors: every one names where (file:line:col, or object.field) and what would be valid.

use std::fmt;

/// An error in a scene file or scene description. Never a panic: the CLI prints it and exits 2.
#[derive(Debug, Clone, PartialEq)]
pub enum SceneError {
    /// RON syntax error, unknown field or wrong type, with its position in the file.
    Syntax {
        /// The file (or `<memory>` for text parsed from a string).
        file: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        col: usize,
        /// What is wrong and what is valid.
        message: String,
    },
    /// A value that parses but is not valid: `path = value: expected`.
    Semantic {
        /// The file, when the scene came from one.
        file: Option<String>,
        /// Where in the scene, e.g. `objects[2] "rod".shape.radius`.
        path: String,
        /// The offending value as written.
        value: String,
        /// What would be valid.
        expected: String,
    },
    /// The file could not be read.
    Io {
        /// The path that was tried.
        file: String,
        /// The OS error.
        message: String,
    },
}

impl SceneError {
    /// A semantic error without a file (the compiler adds the file).
    pub fn semantic(
        path: impl Into<String>,
        value: impl Into<String>,
        expected: impl Into<String>,
    ) -> Self {
        Self::Semantic {
            file: None,
            path: path.into(),
            value: value.into(),
            expected: expected.into(),
        }
    }

    /// Sets the file of a semantic error that has none.
    pub fn in_file(self, file: Option<&str>) -> Self {
        match self {
            Self::Semantic {
                file: None,
                path,
                value,
                expected,
            } => Self::Semantic {
                file: file.map(str::to_string),
                path,
                value,
                expected,
            },
            other => other,
        }
    }

    /// Converts a RON error to a syntax error; `hint` explains common mistakes.
    pub fn from_ron(file: &str, e: &ron::error::SpannedError) -> Self {
        let mut message = e.code.to_string();
        if e.code == ron::Error::ExpectedComma {
            message.push_str(" (hint: a float where an integer is expected, e.g. `4.0` for a count, also reads like this)");
        }
        Self::Syntax {
            file: file.to_string(),
            line: e.span.start.line,
            col: e.span.start.col,
            message,
        }
    }
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Syntax {
                file,
                line,
                col,
                message,
            } => write!(f, "{file}:{line}:{col}: {message}"),
            Self::Semantic {
                file,
                path,
                value,
                expected,
            } => {
                if let Some(file) = file {
                    write!(f, "{file}: ")?;
                }
                write!(f, "{path} = {value}: {expected}")
            }
            Self::Io { file, message } => write!(f, "{file}: cannot read: {message}"),
        }
    }
}

impl std::error::Error for SceneError {}
