//! Time and rate arguments: parsed by clap, so bad values are usage errors before anything
//! connects.

use std::time::{Duration, Instant};

/// A non-negative number of seconds; `inf` (or anything too large) means "no limit".
pub fn parse(text: &str) -> Result<Duration, String> {
    let value: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("{text:?} is not a number of seconds"))?;
    if value.is_nan() || value < 0.0 {
        return Err(format!("{text} is not a non-negative number of seconds"));
    }
    Ok(Duration::try_from_secs_f64(value).unwrap_or(Duration::MAX))
}

/// A report interval: at least 10 ms.
pub fn parse_interval(text: &str) -> Result<Duration, String> {
    let interval = parse(text)?;
    if interval < Duration::from_millis(10) {
        return Err(format!("{text} s is shorter than the 0.01 s minimum"));
    }
    Ok(interval)
}

/// A positive, finite rate in Hz, returned as the period between samples.
pub fn parse_rate(text: &str) -> Result<Duration, String> {
    let hz: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("{text:?} is not a rate in Hz"))?;
    if !(hz.is_finite() && hz > 0.0) {
        return Err(format!("{text} is not a positive rate in Hz"));
    }
    Duration::try_from_secs_f64(1.0 / hz).map_err(|_| format!("{text} Hz is too slow"))
}

/// `now + after`, or `None` for "never" when that is beyond what `Instant` represents.
pub fn deadline(after: Duration) -> Option<Instant> {
    Instant::now().checked_add(after)
}

/// True once `deadline` (if any) has passed.
pub fn passed(deadline: Option<Instant>) -> bool {
    deadline.is_some_and(|at| Instant::now() >= at)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_and_rates() {
        assert_eq!(parse("1.5"), Ok(Duration::from_millis(1500)));
        assert_eq!(parse("inf"), Ok(Duration::MAX));
        assert_eq!(parse("1e300"), Ok(Duration::MAX));
        assert!(parse("-1").is_err() && parse("NaN").is_err() && parse("soon").is_err());
        assert!(parse_interval("0.001").is_err());
        assert_eq!(parse_rate("50"), Ok(Duration::from_millis(20)));
        assert!(parse_rate("0").is_err() && parse_rate("inf").is_err());
        assert!(deadline(Duration::MAX).is_none());
        assert!(!passed(None));
    }
}
