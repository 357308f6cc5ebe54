//! Checks of client commands: one JSON object per message, finite numbers, ranges, a target on
//! the stage. Each refusal is a typed
//! error naming the field, the value and the allowed range.

use nanopush_proto::ws::{Bounds, ClientMessage, ErrorCode};

use nanopush_instrument::control::MoveTarget;

/// A refused command.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// Why, as a code.
    pub code: ErrorCode,
    /// In words.
    pub message: String,
}

impl Refusal {
    /// A refusal.
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Refusal {
        Refusal {
            code,
            message: message.into(),
        }
    }
}

/// Checks `value` of `field` against `[lo, hi]` (or `(lo, hi]` when `lo_open`), with `unit`.
pub fn number(field: &str, value: f64, lo: f64, hi: f64, lo_open: bool, unit: &str) -> Result<f64, Refusal> {
    let range = format!("{}{lo}, {hi}] {unit}", if lo_open { "(" } else { "[" });
    if !value.is_finite() {
        return Err(Refusal::new(
            ErrorCode::NotFinite,
            format!(
                "{field} = {} is not a finite number; allowed: {range}",
                nanopush_instrument::shown(value)
            ),
        ));
    }
    let above_lo = if lo_open { value > lo } else { value >= lo };
    if !above_lo || value > hi {
        return Err(Refusal::new(
            ErrorCode::OutOfRange,
            format!(
                "{field} = {} is out of range; allowed: {range}",
                nanopush_instrument::shown(value)
            ),
        ));
    }
    Ok(value)
}

/// One command from one text message: exactly one JSON value, an object (an array, a number or
/// several values in one message are refused, though serde would read a tagged enum from an
/// array). The error carries the object's `id` when it has a readable one.
pub fn parse_command(text: &str) -> Result<ClientMessage, (Option<u32>, String)> {
    let value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| (None, format!("not one JSON value: {e}")))?;
    let serde_json::Value::Object(map) = &value else {
        return Err((
            None,
            "a command is one JSON object with a \"type\"; got something else".into(),
        ));
    };
    let id = map
        .get("id")
        .and_then(serde_json::Value::as_u64)
        .and_then(|v| u32::try_from(v).ok());
    // serde_json keeps the last of a key given twice: `{"type":"ping","type":"stop"}` would be a
    // stop. A key given twice is refused instead, naming the key.
    if let Err(e) = serde_json::from_str::<UniqueKeys>(text) {
        return Err((id, format!("not a valid command: {e}")));
    }
    serde_json::from_value(value).map_err(|e| (id, format!("not a valid command: {e}")))
}

/// A JSON value in which no object has a key twice (at any depth); deserializing one fails with
/// the key's name otherwise.
struct UniqueKeys;

impl<'de> serde::Deserialize<'de> for UniqueKeys {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(UniqueKeys)
    }
}

impl<'de> serde::de::Visitor<'de> for UniqueKeys {
    type Value = UniqueKeys;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_bool<E>(self, _: bool) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_i64<E>(self, _: i64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_u64<E>(self, _: u64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_f64<E>(self, _: f64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_str<E>(self, _: &str) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_unit<E>(self) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<UniqueKeys, A::Error> {
        while seq.next_element::<UniqueKeys>()?.is_some() {}
        Ok(UniqueKeys)
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<UniqueKeys, A::Error> {
        let mut seen = std::collections::HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            map.next_value::<UniqueKeys>()?;
            if !seen.insert(key.clone()) {
                return Err(serde::de::Error::custom(format_args!(
                    "the key \"{key}\" is given more than once; each key may appear once"
                )));
            }
        }
        Ok(UniqueKeys)
    }
}

/// A push's tolerance (m) from its `tolerance_nm`, as `welcome` states it
/// ([`Bounds::PUSH_TOLERANCE_NM`]): its default when left out, checked against its range.
pub fn push_tolerance(tolerance_nm: Option<f64>) -> Result<f64, Refusal> {
    let b = Bounds::PUSH_TOLERANCE_NM;
    let t = number(
        "tolerance_nm",
        tolerance_nm.unwrap_or(b.default),
        b.min,
        b.max,
        false,
        "nm",
    )?;
    Ok(t * 1e-9)
}

/// Whether a particle of radius `r` (m) can be pushed to `p` (m): its centre at least a radius
/// inside the stage's `[0, range]` square, so the particle stays on the stage and the tip, which
/// stays inside it, can reach behind it. Checked as the planner checks it
/// ([`nanopush_instrument::control::route::on_stage`]: in µm, the bounds rounded inward to the nanometre, as
/// the refusal prints them).
pub fn on_stage(p: (f64, f64), r: f64, range: f64) -> Result<(), Refusal> {
    if nanopush_instrument::control::route::on_stage(p, r, range) {
        return Ok(());
    }
    let (lo, hi) = nanopush_instrument::control::route::centre_bounds_um(r, range);
    Err(Refusal::new(
        ErrorCode::OutOfRange,
        format!(
            "target ({:.3}, {:.3}) µm is out of range for a particle {:.3} µm in radius; allowed: [{lo:.3}, {hi:.3}] µm in x and y",
            p.0 * 1e6,
            p.1 * 1e6,
            r * 1e6,
        ),
    ))
}

/// Checks a push's numbers; `range_um` is the stage range.
pub fn push_target(
    distance_um: Option<f64>,
    direction_deg: Option<f64>,
    to_x_um: Option<f64>,
    to_y_um: Option<f64>,
    range_um: f64,
) -> Result<MoveTarget, Refusal> {
    match (distance_um, to_x_um, to_y_um) {
        (Some(d), None, None) => {
            let d = number("distance_um", d, 0.0, range_um, true, "µm")?;
            // No default direction: a push along +x that the operator did not ask for moves a
            // particle the wrong way.
            let Some(deg) = direction_deg else {
                return Err(Refusal::new(
                    ErrorCode::Invalid,
                    "distance_um goes with direction_deg (degrees from +x, in [-360, 360]): give both",
                ));
            };
            let deg = number("direction_deg", deg, -360.0, 360.0, false, "degrees")?;
            let th = deg.to_radians();
            Ok(MoveTarget::Distance {
                distance: d * 1e-6,
                direction: (th.cos(), th.sin()),
            })
        }
        (None, Some(x), Some(y)) => {
            if direction_deg.is_some() {
                return Err(Refusal::new(
                    ErrorCode::Invalid,
                    "direction_deg goes with distance_um, not with a target point",
                ));
            }
            let x = number("to_x_um", x, 0.0, range_um, false, "µm")?;
            let y = number("to_y_um", y, 0.0, range_um, false, "µm")?;
            Ok(MoveTarget::Point((x * 1e-6, y * 1e-6)))
        }
        _ => Err(Refusal::new(
            ErrorCode::Invalid,
            "give either distance_um (with direction_deg) or both to_x_um and to_y_um",
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Commands are JSON objects, one per message: an array (which serde would read as the
    /// tagged enum) and several values are refused; a bad object's id is echoed.
    #[test]
    fn a_command_is_one_json_object() {
        assert!(matches!(
            parse_command(r#"{"type":"ping","id":4}"#),
            Ok(ClientMessage::Ping { id: Some(4) })
        ));
        for bad in [
            r#"["push",13,1,0.2,0]"#,
            r#"{"type":"ping"} {"type":"ping"}"#,
            "7",
            r#""ping""#,
            "",
        ] {
            let (id, why) = parse_command(bad).unwrap_err();
            assert_eq!(id, None, "{bad}");
            assert!(!why.is_empty());
        }
        let (id, why) = parse_command(r#"{"type":"push","id":9,"particle":"x"}"#).unwrap_err();
        assert_eq!(id, Some(9));
        assert!(why.contains("not a valid command"), "{why}");
    }

    /// A key given twice is refused naming the key, at any depth (serde would keep the last one:
    /// `{"type":"ping","type":"stop"}` would be a stop).
    #[test]
    fn a_key_given_twice_is_refused_naming_it() {
        for (text, key) in [
            (r#"{"type":"ping","type":"stop","id":2}"#, "type"),
            (r#"{"type":"subscribe","streams":[{"a":1,"a":2}]}"#, "a"),
        ] {
            let (_, why) = parse_command(text).unwrap_err();
            assert!(why.contains(&format!("\"{key}\" is given more than once")), "{why}");
        }
        assert_eq!(
            parse_command(r#"{"type":"ping","type":"stop","id":2}"#).unwrap_err().0,
            Some(2)
        );
        assert!(parse_command(r#"{"type":"subscribe","streams":["tip","scan"],"id":1}"#).is_ok());
    }

    /// A refusal does not echo `tolerance_nm: 1e-320` in 330 digits.
    #[test]
    fn a_refusal_shows_a_tiny_or_huge_number_in_scientific_notation() {
        let e = push_tolerance(Some(1e-320)).unwrap_err();
        assert_eq!(
            e.message,
            "tolerance_nm = 1e-320 is out of range; allowed: [1, 100000] nm"
        );
        let e = number("x", 1.2345e59, 0.0, 1.0, false, "µm").unwrap_err();
        assert_eq!(e.message, "x = 1.2345e59 is out of range; allowed: [0, 1] µm");
    }

    #[test]
    fn a_push_tolerance_has_a_default_and_is_checked() {
        assert_eq!(push_tolerance(None), Ok(25.0 * 1e-9));
        assert_eq!(push_tolerance(Some(1.0)), Ok(1.0 * 1e-9));
        let e = push_tolerance(Some(0.5)).unwrap_err();
        assert_eq!(e.code, ErrorCode::OutOfRange);
        assert!(
            e.message
                .contains("tolerance_nm = 0.5 is out of range; allowed: [1, 100000] nm"),
            "{}",
            e.message
        );
        assert_eq!(
            push_tolerance(Some(f64::INFINITY)).unwrap_err().code,
            ErrorCode::NotFinite
        );
    }

    #[test]
    fn numbers_are_checked_for_finiteness_and_range() {
        assert_eq!(number("d", 1.0, 0.0, 100.0, true, "µm"), Ok(1.0));
        let e = number("distance_um", f64::NAN, 0.0, 100.0, true, "µm").unwrap_err();
        assert_eq!(e.code, ErrorCode::NotFinite);
        assert!(e.message.contains("allowed: (0, 100] µm"), "{}", e.message);
        let e = number("distance_um", 0.0, 0.0, 100.0, true, "µm").unwrap_err();
        assert_eq!(e.code, ErrorCode::OutOfRange);
        let e = number("x", 101.0, 0.0, 100.0, false, "µm").unwrap_err();
        assert!(e.message.contains("x = 101 is out of range; allowed: [0, 100] µm"));
    }

    /// The bounds the message prints are the bounds checked: a closed end is allowed, an open
    /// one is not, and the next double past either end is refused (`> hi` is not `>= hi`).
    #[test]
    fn each_end_of_a_range_is_as_the_message_says() {
        assert_eq!(number("x", 100.0, 0.0, 100.0, false, "µm"), Ok(100.0));
        assert_eq!(number("x", 0.0, 0.0, 100.0, false, "µm"), Ok(0.0));
        assert_eq!(number("x", 100.0, 0.0, 100.0, true, "µm"), Ok(100.0));
        for (v, lo_open) in [
            (0.0, true),
            (100.0f64.next_up(), false),
            (100.0f64.next_up(), true),
            ((-0.0f64).next_down(), false),
        ] {
            assert_eq!(
                number("x", v, 0.0, 100.0, lo_open, "µm").unwrap_err().code,
                ErrorCode::OutOfRange,
                "{v}"
            );
        }
    }

    #[test]
    fn a_push_is_a_distance_or_a_point_never_both() {
        assert!(matches!(
            push_target(Some(2.0), Some(90.0), None, None, 100.0),
            Ok(MoveTarget::Distance { distance, direction }) if (distance - 2e-6).abs() < 1e-18 && direction.1 > 0.99
        ));
        // A point in µm becomes metres, to the bit.
        assert!(matches!(
            push_target(None, None, Some(5.0), Some(6.0), 100.0),
            Ok(MoveTarget::Point((x, y))) if x == 5.0 * 1e-6 && y == 6.0 * 1e-6
        ));
        for bad in [
            push_target(Some(1.0), None, Some(1.0), Some(1.0), 100.0),
            push_target(None, None, Some(1.0), None, 100.0),
            push_target(None, Some(3.0), Some(1.0), Some(1.0), 100.0),
            push_target(None, None, None, None, 100.0),
        ] {
            assert_eq!(bad.unwrap_err().code, ErrorCode::Invalid);
        }
        assert_eq!(
            push_target(Some(1.0), Some(f64::INFINITY), None, None, 100.0)
                .unwrap_err()
                .code,
            ErrorCode::NotFinite
        );
    }

    /// A distance without its direction is refused naming both and the direction's range, not
    /// pushed at 0° (the refusal text always said "distance_um (with direction_deg)").
    #[test]
    fn a_distance_without_its_direction_is_refused() {
        let e = push_target(Some(1.0), None, None, None, 100.0).unwrap_err();
        assert_eq!(
            e,
            Refusal::new(
                ErrorCode::Invalid,
                "distance_um goes with direction_deg (degrees from +x, in [-360, 360]): give both"
            )
        );
        assert!(push_target(Some(1.0), Some(0.0), None, None, 100.0).is_ok());
    }

    /// The edges the refusal states are accepted, in µm as sent; a nanometre past them is not.
    #[test]
    fn a_target_on_the_stated_edge_is_on_the_stage() {
        let (r, range) = (500.0 * 1e-9, 100.0 * 1e-6);
        for edge in [0.5, 99.5] {
            assert_eq!(on_stage((edge * 1e-6, 30.0 * 1e-6), r, range), Ok(()), "{edge}");
        }
        for past in [0.499, 99.501] {
            let e = on_stage((past * 1e-6, 30.0 * 1e-6), r, range).unwrap_err();
            assert!(e.message.contains("allowed: [0.500, 99.500] µm"), "{}", e.message);
        }
        // A radius between nanometres: the bounds are rounded inward, and the stated one holds.
        let e = on_stage((0.0, 0.0), 251.37e-9, range).unwrap_err();
        assert!(e.message.contains("allowed: [0.252, 99.748] µm"), "{}", e.message);
        assert_eq!(on_stage((0.252e-6, 99.748e-6), 251.37e-9, range), Ok(()));
    }
}
