//! "Did you mean …?" for names the user typed: topics, machines, configurations, stimuli.
//!
//! [`suggest`] picks the known names close to a mistyped one; [`did_you_mean`] words them:
//!
//! ```
//! use ndds_core::suggest;
//! let known = ["arm/angles", "arm/torques", "cs/status"];
//! let close = suggest::suggest("arm/angels", known);
//! assert_eq!(close, ["arm/angles"]);
//! assert_eq!(
//!     suggest::did_you_mean(&close).as_deref(),
//!     Some("did you mean `arm/angles`?")
//! );
//! ```
//!
//! A name is close when its edit distance (Levenshtein, ignoring case) is small for its length
//! (at most 2, or a third of the longer name, and not every character), or when one of the
//! two is the other's last `/`-separated segments (`angles` for `arm/angles`). The closest
//! come first, at most [`MAX_SUGGESTED`] of them.

/// At most this many names are suggested.
pub const MAX_SUGGESTED: usize = 3;

/// Names longer than this are not compared (the distance is quadratic in the length).
const MAX_COMPARED_LEN: usize = 256;

/// The known names close to `name`, closest first (ties in alphabetical order); empty when
/// none is close, or when `name` itself is known.
pub fn suggest<'a, I, S>(name: &str, candidates: I) -> Vec<&'a str>
where
    I: IntoIterator<Item = &'a S>,
    S: AsRef<str> + ?Sized + 'a,
{
    if name.is_empty() || name.len() > MAX_COMPARED_LEN {
        return Vec::new();
    }
    let wanted = name.to_lowercase();
    let mut close: Vec<(usize, &str)> = Vec::new();
    for candidate in candidates {
        let candidate = candidate.as_ref();
        if candidate == name {
            return Vec::new();
        }
        if let Some(distance) = closeness(&wanted, candidate) {
            close.push((distance, candidate));
        }
    }
    close.sort_unstable();
    close.dedup();
    close
        .into_iter()
        .take(MAX_SUGGESTED)
        .map(|(_, candidate)| candidate)
        .collect()
}

/// `did you mean `a`?`, `did you mean `a` or `b`?`, `did you mean `a`, `b` or `c`?`; `None`
/// for no names.
pub fn did_you_mean<S: AsRef<str>>(names: &[S]) -> Option<String> {
    let quoted: Vec<String> = names
        .iter()
        .map(|name| format!("`{}`", name.as_ref()))
        .collect();
    let list = match quoted.as_slice() {
        [] => return None,
        [one] => one.clone(),
        [first @ .., last] => format!("{} or {last}", first.join(", ")),
    };
    Some(format!("did you mean {list}?"))
}

/// How far `candidate` is from the lower-cased `wanted`, when it is close enough at all.
fn closeness(wanted: &str, candidate: &str) -> Option<usize> {
    if candidate.len() > MAX_COMPARED_LEN {
        return None;
    }
    let candidate = candidate.to_lowercase();
    let longer = wanted.chars().count().max(candidate.chars().count());
    let limit = 2.max(longer / 3);
    let length_gap = wanted.chars().count().abs_diff(candidate.chars().count());
    if length_gap <= limit {
        let distance = strsim::levenshtein(wanted, &candidate);
        if distance <= limit && distance < longer {
            return Some(distance);
        }
    }
    // `angles` for `arm/angles`, or `robot/arm/angles` for `arm/angles`: ranked after the
    // near spellings.
    let is_tail = |short: &str, long: &str| {
        long.strip_suffix(short)
            .is_some_and(|head| head.ends_with('/'))
    };
    (is_tail(wanted, &candidate) || is_tail(&candidate, wanted)).then_some(limit + length_gap)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOPICS: [&str; 6] = [
        "arm/angles",
        "arm/torques",
        "arm/angle_limits",
        "cs/status",
        "fsm/arm/state",
        "camera/image",
    ];

    #[test]
    fn a_misspelt_name_suggests_the_nearest_first() {
        assert_eq!(suggest("arm/angels", &TOPICS), ["arm/angles"]);
        assert_eq!(suggest("arm/torque", &TOPICS), ["arm/torques"]);
        assert_eq!(suggest("ARM/Angles", &TOPICS), ["arm/angles"]);
        assert_eq!(suggest("cs/stats", &TOPICS), ["cs/status"]);
    }

    #[test]
    fn a_last_segment_suggests_the_full_names_that_end_with_it() {
        assert_eq!(suggest("angles", &TOPICS), ["arm/angles"]);
        assert_eq!(suggest("robot/arm/angles", &TOPICS), ["arm/angles"]);
        assert_eq!(suggest("state", &TOPICS), ["fsm/arm/state"]);
    }

    #[test]
    fn nothing_is_suggested_for_a_far_name_a_known_name_or_an_empty_one() {
        assert!(suggest("lidar/points", &TOPICS).is_empty());
        assert!(suggest("arm/angles", &TOPICS).is_empty());
        assert!(suggest("", &TOPICS).is_empty());
        assert!(suggest(&"x".repeat(1000), &TOPICS).is_empty());
        assert!(suggest::<_, str>("arm/angles", []).is_empty());
        // Replacing every character is no near spelling, however short the name.
        assert!(suggest("z", &["x", "y"]).is_empty());
        assert_eq!(suggest("x", &["x1", "y"]), ["x1"]);
    }

    #[test]
    fn at_most_three_suggestions_closest_first_ties_alphabetical() {
        let known = ["ab1", "ab2", "ab3", "ab4", "abc"];
        assert_eq!(suggest("ab", &known), ["ab1", "ab2", "ab3"]);
        let owned: Vec<String> = vec!["Push".into(), "Pull".into(), "Pulse".into()];
        assert_eq!(suggest("Puls", &owned), ["Pull", "Pulse", "Push"]);
    }

    #[test]
    fn suggestions_are_worded_as_one_question() {
        assert_eq!(did_you_mean::<&str>(&[]), None);
        assert_eq!(
            did_you_mean(&["arm/angles"]).as_deref(),
            Some("did you mean `arm/angles`?")
        );
        assert_eq!(
            did_you_mean(&["a", "b"]).as_deref(),
            Some("did you mean `a` or `b`?")
        );
        assert_eq!(
            did_you_mean(&["a", "b", "c"]).as_deref(),
            Some("did you mean `a`, `b` or `c`?")
        );
    }
}
