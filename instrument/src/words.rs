//! Numbers in messages: as the user wrote them, and a caught panic in words.

/// A number as an error message shows it: as written when short, else in scientific notation (a
/// 1e308 is not 309 digits, a 1e-320 not 330).
pub fn shown(v: f64) -> String {
    let plain = v.to_string();
    if plain.len() <= 16 { plain } else { format!("{v:e}") }
}

/// A length (m) in nm as the user gave it, for messages: to the picometre, trailing zeros
/// dropped (a 1.75 nm tolerance reads `1.75`, not `2`; 25e-9 reads `25`).
pub fn nm_text(v: f64) -> String {
    shown((v * 1e12).round() / 1e3)
}

/// The message of a caught panic's payload (`&str` or `String`), for reports that turn a
/// panic in one case, run or push into a row with its reason.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}
