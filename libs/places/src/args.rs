//! Command-line values the agents (and `iwsim`'s own commands) read the same way: lists of
//! comma-separated numbers such as a pose `X,Y,DIR` or powers `LEFT,RIGHT`. The errors are
//! clap's `value_parser` errors: a sentence naming the form expected and what was given.

use sim_model::PoseDeg;

/// Parses `spec` as `min` to `max` comma-separated finite numbers; `form` names the form in
/// errors (`"X,Y,DIR"`).
///
/// ```
/// assert_eq!(places::args::numbers("1, 2.5", "X,Y[,R]", 2, 3), Ok(vec![1.0, 2.5]));
/// assert!(places::args::numbers("1,x", "X,Y", 2, 2).unwrap_err().contains("X,Y"));
/// ```
pub fn numbers(spec: &str, form: &str, min: usize, max: usize) -> Result<Vec<f64>, String> {
    let v: Vec<f64> = spec
        .split(',')
        .map(|t| t.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("{spec:?} is not {form}: expected comma-separated finite numbers"))?;
    if !(min..=max).contains(&v.len()) {
        let want = if min == max { format!("{min}") } else { format!("{min} to {max}") };
        return Err(format!("{spec:?} is not {form}: expected {want} numbers, got {}", v.len()));
    }
    Ok(v)
}

/// Parses exactly `N` numbers, or `N − 1` followed by `last_default` when given.
pub fn fixed<const N: usize>(spec: &str, form: &str, last_default: Option<f64>) -> Result<[f64; N], String> {
    let min = if last_default.is_some() { N - 1 } else { N };
    let v = numbers(spec, form, min, N)?;
    let mut out = [last_default.unwrap_or(0.0); N];
    out[..v.len()].copy_from_slice(&v);
    Ok(out)
}

/// A pose `X,Y,DIR` in its wire form `[x m, y m, heading °]`, exactly as typed: registrations
/// carry it so, and `sim_model::Pose::from_wire_deg` turns it into a pose for those who compute
/// with it (converting here would round the degrees a registration forwards).
pub fn pose(spec: &str) -> Result<PoseDeg, String> {
    fixed::<3>(spec, "a pose X,Y,DIR", None)
}

/// Motor powers `LEFT,RIGHT`.
pub fn powers(spec: &str) -> Result<[f64; 2], String> {
    fixed::<2>(spec, "powers LEFT,RIGHT", None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_of_numbers_read_and_junk_is_named() {
        assert_eq!(pose("10, 6.1,-90"), Ok([10.0, 6.1, -90.0]));
        assert_eq!(powers("-1,1"), Ok([-1.0, 1.0]));
        assert_eq!(fixed::<3>("1,2", "X,Y[,R]", Some(0.5)), Ok([1.0, 2.0, 0.5]));
        assert_eq!(fixed::<3>("1,2,3", "X,Y[,R]", Some(0.5)), Ok([1.0, 2.0, 3.0]));
        for (bad, says) in [
            ("1,2", "expected 3 numbers, got 2"),
            ("1,2,3,4", "got 4"),
            ("1,NaN,3", "finite"),
            ("1,,3", "comma-separated"),
            ("a pose", "X,Y,DIR"),
        ] {
            let e = pose(bad).expect_err(bad);
            assert!(e.contains(says) && e.contains(&format!("{bad:?}")), "{bad}: {e}");
        }
        assert!(fixed::<3>("1", "X,Y[,R]", Some(0.5)).expect_err("one").contains("2 to 3"));
    }
}
