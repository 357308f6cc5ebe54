//! Range checks of a parsed scene: each rejected value gets one error naming the field, the
//! value and the allowed range. The ranges are tables ([`fields`]); [`validate`] walks them in
//! file order, with the checks that relate several fields between them.

mod clash;
mod fields;
mod validate;

pub(crate) use clash::first_clash;
pub use validate::validate;

use super::error::SceneError;

/// An allowed interval with its unit, e.g. `(0, 10000] nm`.
#[derive(Debug, Clone, Copy)]
pub struct Range {
    lo: f64,
    hi: f64,
    lo_open: bool,
    hi_open: bool,
    unit: &'static str,
}

impl Range {
    /// The upper bound.
    pub const fn hi(&self) -> f64 {
        self.hi
    }

    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64, unit: &'static str) -> Range {
        Range {
            lo,
            hi,
            lo_open: false,
            hi_open: false,
            unit,
        }
    }
    /// `(lo, hi]`.
    pub const fn open_closed(lo: f64, hi: f64, unit: &'static str) -> Range {
        Range {
            lo,
            hi,
            lo_open: true,
            hi_open: false,
            unit,
        }
    }
    /// `[lo, hi)`.
    pub const fn closed_open(lo: f64, hi: f64, unit: &'static str) -> Range {
        Range {
            lo,
            hi,
            lo_open: false,
            hi_open: true,
            unit,
        }
    }
    fn contains(&self, v: f64) -> bool {
        let lo_ok = if self.lo_open { v > self.lo } else { v >= self.lo };
        let hi_ok = if self.hi_open { v < self.hi } else { v <= self.hi };
        lo_ok && hi_ok
    }
}

impl std::fmt::Display for Range {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let l = if self.lo_open { '(' } else { '[' };
        let r = if self.hi_open { ')' } else { ']' };
        write!(f, "{l}{}, {}{r}", self.lo, self.hi)?;
        if !self.unit.is_empty() {
            write!(f, " {}", self.unit)?;
        }
        Ok(())
    }
}

/// Checks one number against its range.
fn check(origin: &str, field: &str, value: f64, range: Range) -> Result<(), SceneError> {
    if !value.is_finite() {
        return Err(SceneError::NotFinite {
            origin: origin.into(),
            field: field.into(),
            value,
            allowed: range.to_string(),
        });
    }
    if !range.contains(value) {
        return Err(SceneError::OutOfRange {
            origin: origin.into(),
            field: field.into(),
            value,
            allowed: range.to_string(),
        });
    }
    Ok(())
}

const MODULUS: Range = Range::closed(0.01, 1500.0, "GPa");
const POISSON: Range = Range::closed(0.0, 0.5, "");
const HAMAKER: Range = Range::closed(1.0, 1000.0, "zJ");
const MU: Range = Range::closed(0.0, 5.0, "");
/// `cantilever.stiffness_n_per_m` (the planner names no stiffness beyond it).
pub const STIFFNESS_N_PER_M: Range = Range::closed(0.01, 500.0, "N/m");
/// `sensor.gain_v_per_nm` (the planner asks for no larger gain).
pub const GAIN_V_PER_NM: Range = Range::closed(-10.0, 10.0, "V/nm");
/// `strategy.start_height_um` (the planner lifts no higher).
pub const START_HEIGHT_UM: Range = Range::open_closed(0.0, 50.0, "µm");

/// Largest image side (pixels) a scene may ask for.
pub const MAX_SCAN_PIXELS: u32 = 4096;

/// The most particles a scene may hold.
pub const MAX_PARTICLES: usize = 2000;

/// Smallest image side (pixels).
pub const MIN_SCAN_PIXELS: u32 = 8;

#[cfg(test)]
mod tests {
    use super::*;

    use crate::scene::Scene;
    use crate::scene::file::SceneFile;

    /// The default scene with `key` (`section.name`, or `particles[0].name`) set to `v` through
    /// its TOML, so that the table's reader is checked against serde's names, not its own.
    fn with_value(key: &str, v: f64) -> SceneFile {
        let mut t = toml::Value::try_from(&Scene::default_scene().file).unwrap();
        let (section, name) = key.split_once('.').unwrap();
        let item = match section.strip_suffix("[0]") {
            Some(list) => &mut t[list][0],
            None => &mut t[section],
        };
        item[name] = if key == "scan.pixels" {
            toml::Value::Integer(v as i64)
        } else {
            toml::Value::Float(v)
        };
        t.try_into().unwrap()
    }

    /// Each row of every table reads the field it names: a value written to that field is the
    /// one the row reads.
    #[test]
    fn every_table_row_reads_the_field_it_names() {
        use fields::*;
        let tables = [
            INSTRUMENT,
            CONTACT,
            SENSOR_LEVELS,
            SENSOR_READOUT,
            STRATEGY,
            SENSOR_PERTURBATION,
            SCAN,
            HAPTIC,
        ];
        let mut n = 0;
        for f in tables.iter().flat_map(|t| t.iter()) {
            assert_eq!((f.value)(&with_value(f.name, 777.0)), 777.0, "{}", f.name);
            n += 1;
        }
        for f in PARTICLE {
            let s = with_value(&format!("particles[0].{}", f.name), 777.0);
            assert_eq!((f.value)(&s.particles[0]), 777.0, "particles[0].{}", f.name);
            n += 1;
        }
        // Every number of the scene's file has its row, but the ids (any u32) and the seeds.
        let t = toml::Value::try_from(&Scene::default_scene().file).unwrap();
        let mut numbers = Vec::new();
        for (section, v) in t.as_table().unwrap() {
            let item = match v {
                toml::Value::Array(a) => &a[0],
                other => other,
            };
            for (name, x) in item.as_table().into_iter().flatten() {
                if x.is_float() || x.is_integer() {
                    numbers.push(format!("{section}.{name}"));
                }
            }
        }
        numbers.retain(|k| !k.ends_with("id") && !k.ends_with("seed"));
        assert_eq!(n, numbers.len(), "{numbers:?}");
    }

    #[test]
    fn range_display() {
        assert_eq!(Range::open_closed(0.0, 5.0, "nm").to_string(), "(0, 5] nm");
        assert_eq!(Range::closed_open(0.0, 1.0, "").to_string(), "[0, 1)");
    }
}
