//! A pattern: the target sites particles are assembled into. From a TOML file of `[[site]]`
//! entries (`x_um`, `y_um`, an optional `tolerance_nm`), or from a generator of the usual
//! shapes (a line, a grid, a ring, letters) placed with its centre at a point of the stage.
//!
//! ```toml
//! name = "a square"          # optional
//! radius_nm = 500            # optional: the particles it wants (within a factor of 1.5)
//! tolerance_nm = 50          # optional: each site's, unless the site gives its own
//!
//! [[site]]
//! x_um = 40.0
//! y_um = 40.0
//! tolerance_nm = 30          # optional
//! ```
//!
//! Generators, as `nanopush assemble --pattern` takes them (`key=value` lengths in µm, angles
//! in degrees; the centre is `--at-um X,Y`):
//! - `line:n=5,spacing_um=4[,angle_deg=0]`
//! - `grid:rows=3,cols=3,spacing_um=4[,angle_deg=0]`
//! - `ring:n=8,radius_um=6[,angle_deg=0]`
//! - `text:NP,pitch_um=3` (upper-case letters and digits on a 5 × 7 dot font)

use serde::Deserialize;

use super::letters::glyph;

/// The largest number of sites a pattern may have.
pub const MAX_SITES: usize = 400;

/// One target site (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Site {
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// How close a particle's centre must be to fill it (m), when the site sets its own.
    pub tolerance: Option<f64>,
}

/// A pattern of sites (SI).
#[derive(Debug, Clone, PartialEq)]
pub struct Pattern {
    /// A name for reports.
    pub name: String,
    /// The sites, in the order the pattern gives them.
    pub sites: Vec<Site>,
    /// The particles it wants (m): only particles within a factor of [`RADIUS_MATCH`] of it
    /// are sent; `None` takes any.
    pub radius: Option<f64>,
}

/// How far a particle's radius may be from the pattern's `radius_nm`, as a factor either way.
pub const RADIUS_MATCH: f64 = 1.5;

/// Why a pattern was refused, naming what was wrong and what is allowed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PatternError {
    /// The file could not be read or parsed.
    #[error("{origin}: {message}")]
    File {
        /// The file.
        origin: String,
        /// What the reader or parser said.
        message: String,
    },
    /// A number out of its range.
    #[error("{origin}: {field} = {value} is out of range; allowed: {allowed}")]
    OutOfRange {
        /// The file or the generator.
        origin: String,
        /// Which number.
        field: String,
        /// Its value.
        value: f64,
        /// The allowed range.
        allowed: String,
    },
    /// A generator's text that is not one.
    #[error("pattern {spec:?}: {message}")]
    Spec {
        /// The text.
        spec: String,
        /// What is wrong, and what is allowed.
        message: String,
    },
}

/// The TOML file's form.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PatternFile {
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    radius_nm: Option<f64>,
    #[serde(default)]
    tolerance_nm: Option<f64>,
    #[serde(default)]
    site: Vec<SiteFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SiteFile {
    x_um: f64,
    y_um: f64,
    #[serde(default)]
    tolerance_nm: Option<f64>,
}

/// A tolerance's range (nm), as a push's.
fn tolerance_range() -> (f64, f64) {
    nanopush_proto::push::TOLERANCE_RANGE_NM
}

fn check(origin: &str, field: String, v: f64, lo: f64, hi: f64, unit: &str) -> Result<f64, PatternError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(v)
    } else {
        Err(PatternError::OutOfRange {
            origin: origin.into(),
            field,
            value: v,
            allowed: format!("[{lo}, {hi}] {unit}"),
        })
    }
}

impl Pattern {
    /// A pattern from the text of a TOML file named `origin`.
    pub fn parse(origin: &str, text: &str) -> Result<Pattern, PatternError> {
        let file: PatternFile = toml::from_str(text).map_err(|e| PatternError::File {
            origin: origin.into(),
            message: e.message().to_string(),
        })?;
        let (tlo, thi) = tolerance_range();
        let default_tol = file
            .tolerance_nm
            .map(|t| check(origin, "tolerance_nm".into(), t, tlo, thi, "nm"))
            .transpose()?;
        let radius = file
            .radius_nm
            .map(|r| check(origin, "radius_nm".into(), r, 2.0, 10_000.0, "nm"))
            .transpose()?;
        if file.site.is_empty() || file.site.len() > MAX_SITES {
            return Err(PatternError::OutOfRange {
                origin: origin.into(),
                field: "[[site]] entries".into(),
                value: file.site.len() as f64,
                allowed: format!("[1, {MAX_SITES}]"),
            });
        }
        let mut sites = Vec::with_capacity(file.site.len());
        for (i, s) in file.site.iter().enumerate() {
            let x = check(origin, format!("site[{i}].x_um"), s.x_um, -1e6, 1e6, "µm")?;
            let y = check(origin, format!("site[{i}].y_um"), s.y_um, -1e6, 1e6, "µm")?;
            let tol = s
                .tolerance_nm
                .map(|t| check(origin, format!("site[{i}].tolerance_nm"), t, tlo, thi, "nm"))
                .transpose()?
                .or(default_tol);
            sites.push(Site {
                x: x / 1e6,
                y: y / 1e6,
                tolerance: tol.map(|t| t / 1e9),
            });
        }
        Ok(Pattern {
            name: file.name.unwrap_or_else(|| origin.to_string()),
            sites,
            radius: radius.map(|r| r / 1e9),
        })
    }

    /// A pattern from a file (`.toml`).
    pub fn from_path(path: &std::path::Path) -> Result<Pattern, PatternError> {
        let origin = path.display().to_string();
        let meta = std::fs::metadata(path).map_err(|e| PatternError::File {
            origin: origin.clone(),
            message: e.to_string(),
        })?;
        if meta.len() > 1 << 20 {
            return Err(PatternError::File {
                origin,
                message: format!("{} bytes; allowed: at most 1 MiB", meta.len()),
            });
        }
        let text = std::fs::read_to_string(path).map_err(|e| PatternError::File {
            origin: origin.clone(),
            message: e.to_string(),
        })?;
        Pattern::parse(&origin, &text)
    }

    /// A generated pattern (`line:…`, `grid:…`, `ring:…`, `text:…`) centred at `at` (m).
    pub fn generate(spec: &str, at: (f64, f64)) -> Result<Pattern, PatternError> {
        let bad = |message: String| PatternError::Spec {
            spec: spec.to_string(),
            message,
        };
        let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
        let args = Args::parse(spec, rest, kind)?;
        let angle = args.get("angle_deg", 0.0, -360.0, 360.0, "degrees")?.to_radians();
        let local: Vec<(f64, f64)> = match kind {
            "line" => {
                let n = args.count("n", 2, MAX_SITES)?;
                let d = args.length("spacing_um")?;
                (0..n).map(|k| ((k as f64 - (n - 1) as f64 / 2.0) * d, 0.0)).collect()
            }
            "grid" => {
                let rows = args.count("rows", 1, MAX_SITES)?;
                let cols = args.count("cols", 1, MAX_SITES)?;
                if rows * cols > MAX_SITES || rows * cols < 2 {
                    return Err(bad(format!(
                        "rows × cols = {}; allowed: [2, {MAX_SITES}] sites",
                        rows * cols
                    )));
                }
                let d = args.length("spacing_um")?;
                let mut v = Vec::new();
                for r in 0..rows {
                    for c in 0..cols {
                        v.push((
                            (c as f64 - (cols - 1) as f64 / 2.0) * d,
                            ((rows - 1) as f64 / 2.0 - r as f64) * d,
                        ));
                    }
                }
                v
            }
            "ring" => {
                let n = args.count("n", 3, MAX_SITES)?;
                let r = args.length("radius_um")?;
                (0..n)
                    .map(|k| {
                        let a = std::f64::consts::TAU * k as f64 / n as f64;
                        (r * a.cos(), r * a.sin())
                    })
                    .collect()
            }
            "text" => {
                let pitch = args.length("pitch_um")?;
                let text = args.word.as_deref().unwrap_or("");
                text_dots(text, pitch).map_err(bad)?
            }
            other => {
                return Err(bad(format!("unknown shape {other:?}; allowed: line, grid, ring, text")));
            }
        };
        args.all_used()?;
        if local.len() > MAX_SITES {
            return Err(bad(format!("{} sites; allowed: at most {MAX_SITES}", local.len())));
        }
        let (s, c) = angle.sin_cos();
        let tolerance = args.tolerance()?;
        Ok(Pattern {
            name: spec.to_string(),
            sites: local
                .into_iter()
                .map(|(x, y)| Site {
                    x: at.0 + x * c - y * s,
                    y: at.1 + x * s + y * c,
                    tolerance,
                })
                .collect(),
            radius: args.radius()?,
        })
    }

    /// The same sites moved by `d` (m).
    pub fn shifted(&self, d: (f64, f64)) -> Pattern {
        Pattern {
            sites: self
                .sites
                .iter()
                .map(|s| Site {
                    x: s.x + d.0,
                    y: s.y + d.1,
                    ..*s
                })
                .collect(),
            ..self.clone()
        }
    }

    /// The mean of the sites (m).
    pub fn centre(&self) -> (f64, f64) {
        let n = self.sites.len().max(1) as f64;
        let (x, y) = self.sites.iter().fold((0.0, 0.0), |a, s| (a.0 + s.x, a.1 + s.y));
        (x / n, y / n)
    }
}

/// A generator's `key=value` arguments, each of which must be used.
struct Args {
    spec: String,
    kind: String,
    pairs: Vec<(String, String, std::cell::Cell<bool>)>,
    /// The text of `text:WORD,…`.
    word: Option<String>,
}

impl Args {
    fn parse(spec: &str, rest: &str, kind: &str) -> Result<Args, PatternError> {
        let mut pairs = Vec::new();
        let mut word = None;
        for (k, part) in rest.split(',').map(str::trim).filter(|p| !p.is_empty()).enumerate() {
            match part.split_once('=') {
                Some((key, value)) => pairs.push((key.trim().to_string(), value.trim().to_string(), false.into())),
                None if k == 0 && kind == "text" => word = Some(part.to_string()),
                None => {
                    return Err(PatternError::Spec {
                        spec: spec.into(),
                        message: format!("{part:?} is not key=value"),
                    });
                }
            }
        }
        Ok(Args {
            spec: spec.into(),
            kind: kind.into(),
            pairs,
            word,
        })
    }

    fn raw(&self, key: &str) -> Option<&str> {
        self.pairs.iter().find(|p| p.0 == key).map(|p| {
            p.2.set(true);
            p.1.as_str()
        })
    }

    fn number(&self, key: &str) -> Result<Option<f64>, PatternError> {
        match self.raw(key) {
            None => Ok(None),
            Some(v) => v.parse::<f64>().map(Some).map_err(|_| PatternError::Spec {
                spec: self.spec.clone(),
                message: format!("{key}={v:?} is not a number"),
            }),
        }
    }

    fn get(&self, key: &str, default: f64, lo: f64, hi: f64, unit: &str) -> Result<f64, PatternError> {
        let v = self.number(key)?.unwrap_or(default);
        check(&format!("pattern {:?}", self.spec), key.into(), v, lo, hi, unit)
    }

    fn required(&self, key: &str) -> Result<f64, PatternError> {
        self.number(key)?.ok_or_else(|| PatternError::Spec {
            spec: self.spec.clone(),
            message: format!("{} needs {key}=…", self.kind),
        })
    }

    /// A whole number of sites, rows or columns in `[lo, hi]`.
    fn count(&self, key: &str, lo: usize, hi: usize) -> Result<usize, PatternError> {
        let v = self.required(key)?;
        if v.fract() != 0.0 || v < lo as f64 || v > hi as f64 {
            return Err(PatternError::OutOfRange {
                origin: format!("pattern {:?}", self.spec),
                field: key.into(),
                value: v,
                allowed: format!("a whole number in [{lo}, {hi}]"),
            });
        }
        Ok(v as usize)
    }

    /// A length in µm, in (0, 1000], returned in m.
    fn length(&self, key: &str) -> Result<f64, PatternError> {
        let v = self.required(key)?;
        if !(v.is_finite() && v > 0.0 && v <= 1000.0) {
            return Err(PatternError::OutOfRange {
                origin: format!("pattern {:?}", self.spec),
                field: key.into(),
                value: v,
                allowed: "(0, 1000] µm".into(),
            });
        }
        Ok(v / 1e6)
    }

    fn tolerance(&self) -> Result<Option<f64>, PatternError> {
        let (lo, hi) = tolerance_range();
        match self.number("tolerance_nm")? {
            None => Ok(None),
            Some(t) => check(
                &format!("pattern {:?}", self.spec),
                "tolerance_nm".into(),
                t,
                lo,
                hi,
                "nm",
            )
            .map(|t| Some(t / 1e9)),
        }
    }

    fn radius(&self) -> Result<Option<f64>, PatternError> {
        match self.number("radius_nm")? {
            None => Ok(None),
            Some(r) => check(
                &format!("pattern {:?}", self.spec),
                "radius_nm".into(),
                r,
                2.0,
                10_000.0,
                "nm",
            )
            .map(|r| Some(r / 1e9)),
        }
    }

    fn all_used(&self) -> Result<(), PatternError> {
        // The options every shape takes are read before this.
        let _ = (self.raw("tolerance_nm"), self.raw("radius_nm"));
        match self.pairs.iter().find(|p| !p.2.get()) {
            None => Ok(()),
            Some(p) => Err(PatternError::Spec {
                spec: self.spec.clone(),
                message: format!(
                    "{} takes no {:?}; allowed: {}",
                    self.kind,
                    p.0,
                    match self.kind.as_str() {
                        "line" => "n, spacing_um, angle_deg, tolerance_nm, radius_nm",
                        "grid" => "rows, cols, spacing_um, angle_deg, tolerance_nm, radius_nm",
                        "ring" => "n, radius_um, angle_deg, tolerance_nm, radius_nm",
                        _ => "pitch_um, angle_deg, tolerance_nm, radius_nm",
                    }
                ),
            }),
        }
    }
}

/// The dots of `text` in the 5 × 7 font, `pitch` (m) apart, a blank column between letters,
/// centred on the origin.
fn text_dots(text: &str, pitch: f64) -> Result<Vec<(f64, f64)>, String> {
    if text.is_empty() || text.chars().count() > 12 {
        return Err(format!(
            "text needs 1 to 12 letters or digits first (text:NP,pitch_um=3); got {}",
            text.chars().count()
        ));
    }
    let mut dots = Vec::new();
    for (k, ch) in text.chars().enumerate() {
        let rows = glyph(ch).ok_or_else(|| format!("{ch:?} is not in the font; allowed: A-Z, 0-9 and space"))?;
        for (r, row) in rows.iter().enumerate() {
            for c in 0..5 {
                if row & (0b10000 >> c) != 0 {
                    dots.push(((k * 6 + c) as f64, -(r as f64)));
                }
            }
        }
    }
    let width = (text.chars().count() * 6 - 1) as f64;
    Ok(dots
        .into_iter()
        .map(|(x, y)| ((x - (width - 1.0) / 2.0) * pitch, (y + 3.0) * pitch))
        .collect())
}

#[cfg(test)]
mod tests;
