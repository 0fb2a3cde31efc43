//! Names in messages: lists of known names and the "did you mean".

/// Names a message lists at most.
const LISTED: usize = 12;
/// Above this many known names, no "did you mean" (each would cost a comparison with all).
const SUGGESTED_FROM: usize = 256;

/// `"a", "b" or "c"` for messages (at most [`LISTED`] names, then how many more).
pub(crate) fn list<S: AsRef<str>>(items: &[S]) -> String {
    let quoted: Vec<String> = items
        .iter()
        .take(LISTED)
        .map(|s| format!("`{}`", s.as_ref()))
        .collect();
    let text = match quoted.len() {
        0 => "nothing".to_owned(),
        1 => quoted[0].clone(),
        n => format!("{} or {}", quoted[..n - 1].join(", "), quoted[n - 1]),
    };
    match items.len().saturating_sub(LISTED) {
        0 => text,
        more => format!("{text} ({more} more)"),
    }
}

/// ` (did you mean `x`?)` when a known name is close to `name` (the closest, by
/// [`ndds_core::suggest`]'s rule, which the command line uses too).
pub(crate) fn suggest<S: AsRef<str>>(name: &str, known: &[S]) -> String {
    if known.len() > SUGGESTED_FROM {
        return String::new();
    }
    ndds_core::suggest::suggest(name, known)
        .first()
        .map(|k| format!(" (did you mean `{k}`?)"))
        .unwrap_or_default()
}
