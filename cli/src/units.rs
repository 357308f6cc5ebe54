//! Engineering-unit formatting for the readable tables.

/// `value` with an SI prefix chosen so the mantissa is in [1, 1000), e.g. `1.427 kN/m`.
pub fn eng(value: f64, unit: &str) -> String {
    if !value.is_finite() {
        return format!("{value} {unit}");
    }
    if value == 0.0 {
        return format!("0 {unit}");
    }
    const PREFIXES: [(f64, &str); 11] = [
        (1e15, "P"),
        (1e12, "T"),
        (1e9, "G"),
        (1e6, "M"),
        (1e3, "k"),
        (1.0, ""),
        (1e-3, "m"),
        (1e-6, "µ"),
        (1e-9, "n"),
        (1e-12, "p"),
        (1e-15, "f"),
    ];
    let a = value.abs();
    let (scale, prefix) = PREFIXES
        .iter()
        .copied()
        .find(|(s, _)| a >= *s * 0.9995)
        .unwrap_or((1e-18, "a"));
    format!("{:.4} {prefix}{unit}", value / scale)
}

/// A `X_UM,Y_UM` argument of flag `flag` as two finite numbers (µm); `example` shows the form.
pub fn parse_point_um(flag: &str, s: &str, example: &str) -> anyhow::Result<(f64, f64)> {
    use anyhow::Context as _;
    let parsed = s.split_once(',').and_then(|(x, y)| {
        let (x, y) = (x.trim().parse::<f64>().ok()?, y.trim().parse::<f64>().ok()?);
        (x.is_finite() && y.is_finite()).then_some((x, y))
    });
    parsed.with_context(|| {
        format!(
            "{flag} {}: expected X_UM,Y_UM, two numbers in µm such as {example}",
            echo(s)
        )
    })
}

/// A user's text as an error message quotes it: at most 40 characters, so a 400 KB argument is
/// not echoed back whole.
pub fn echo(s: &str) -> String {
    if s.chars().count() <= 40 {
        format!("{s:?}")
    } else {
        let head: String = s.chars().take(40).collect();
        format!("{head:?}… ({} characters)", s.chars().count())
    }
}

/// A number as an error message shows it: as typed when short, else in scientific notation (a
/// 1e308 is not 309 digits).
pub fn num(v: f64) -> String {
    nanopush_instrument::shown(v)
}

/// `--method NAME` as an integration method, with the allowed names in the error.
pub fn parse_method(name: &str) -> anyhow::Result<nanopush_instrument::numerics::integrate::Method> {
    use anyhow::Context as _;
    nanopush_instrument::numerics::integrate::Method::parse(name)
        .with_context(|| format!("--method {name}: unknown; allowed: rodas4, rodas5p, trbdf2, implicit-euler"))
}

/// [`nanopush_instrument::files::write_atomic`] with the path in the error.
pub fn write_file(path: &std::path::Path, bytes: impl AsRef<[u8]>) -> anyhow::Result<()> {
    use anyhow::Context as _;
    nanopush_instrument::files::write_atomic(path, bytes.as_ref())
        .with_context(|| format!("writing {}", path.display()))
}

/// A whole-number argument: any integer is parsed (the command then checks its range and says
/// it), and what is not an integer is told the allowed range `allowed` too, not only the
/// parser's "invalid digit" (`--attempts 1.5`, `--random -1`).
fn whole<T: std::str::FromStr>(s: &str, allowed: &str) -> Result<T, String> {
    s.trim()
        .parse::<T>()
        .map_err(|_| format!("not a whole number in range; allowed: {allowed}"))
}

/// `push --attempts`: see [`whole`]; the range is checked by the command.
pub fn attempts_arg(s: &str) -> Result<i64, String> {
    whole(s, "[1, 10]")
}

/// `campaign --random`: see [`whole`].
pub fn scenes_arg(s: &str) -> Result<u64, String> {
    whole(s, "[1, 100000] scenes")
}

/// `campaign --seed`: see [`whole`].
pub fn seed_arg(s: &str) -> Result<u64, String> {
    whole(s, "[0, 18446744073709551615]")
}

/// A `--tolerance-nm` within [`TOLERANCE_RANGE_NM`](nanopush_proto::push::TOLERANCE_RANGE_NM),
/// or an error naming the flag and the range.
pub fn check_tolerance_nm(v: f64) -> anyhow::Result<()> {
    let (lo, hi) = nanopush_proto::push::TOLERANCE_RANGE_NM;
    if !(v.is_finite() && (lo..=hi).contains(&v)) {
        anyhow::bail!("--tolerance-nm {} is out of range; allowed: [{lo}, {hi}] nm", num(v));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::eng;

    #[test]
    fn long_inputs_and_huge_numbers_are_shortened_in_messages() {
        assert_eq!(super::num(1e308), "1e308");
        assert_eq!(super::num(-90.0), "-90");
        assert_eq!(super::num(0.5), "0.5");
        let long = "9".repeat(400_000);
        let e = super::echo(&long);
        assert!(e.len() < 80 && e.ends_with("(400000 characters)"), "{e}");
        let e = super::parse_point_um("--to-um", &long, "60,45")
            .unwrap_err()
            .to_string();
        assert!(e.len() < 200, "{} bytes", e.len());
    }

    #[test]
    fn prefixes() {
        assert_eq!(eng(1427.0, "N/m"), "1.4270 kN/m");
        assert_eq!(eng(0.2215e-9, "m"), "221.5000 pm");
        assert_eq!(eng(-904.8e-9, "N"), "-904.8000 nN");
        assert_eq!(eng(0.0, "m"), "0 m");
    }
}
