//! Scene errors and warnings.

/// Why a scene was rejected. Every variant names where the scene came from and what was wrong.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {error}")]
    Io {
        /// The path.
        path: String,
        /// The I/O error (in the message, not a `source`: printed once).
        error: std::io::Error,
    },
    /// Not valid TOML, a wrong type, an unknown key or a missing field (the message names it,
    /// with its line and column).
    #[error("scene {origin}: {message}")]
    Parse {
        /// File name or `<default scene>`.
        origin: String,
        /// The parser's message.
        message: String,
    },
    /// A number that is NaN or infinite.
    #[error("scene {origin}: {field} = {} is not a finite number; allowed: {allowed}", crate::words::shown(*.value))]
    NotFinite {
        /// File name.
        origin: String,
        /// Dotted field path, e.g. `particles[0].radius_nm`.
        field: String,
        /// The value as read.
        value: f64,
        /// The allowed range.
        allowed: String,
    },
    /// A number outside its allowed range.
    #[error("scene {origin}: {field} = {} is out of range; allowed: {allowed}", crate::words::shown(*.value))]
    OutOfRange {
        /// File name.
        origin: String,
        /// Dotted field path.
        field: String,
        /// The value as read.
        value: f64,
        /// The allowed range, with its unit.
        allowed: String,
    },
    /// Fields that are each valid but do not fit together.
    #[error("scene {origin}: {field}: {message}")]
    Inconsistent {
        /// File name.
        origin: String,
        /// Dotted field path.
        field: String,
        /// What is wrong.
        message: String,
    },
}

/// Something a valid scene does that will not work as the user probably expects.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneWarning(pub String);

impl std::fmt::Display for SceneWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}
