//! What the security layer reads: identity files (`security::Identity::parse`, read from a
//! path an operator gives), public keys in text, signed permissions documents
//! (`security::split_signed`, `verify_signed`), topic patterns against names, and `Signed`
//! datagrams from the network (`wire::signed::parse`, `verify`). The first byte picks which.
//! What parses is written again and must parse to the same thing; a pattern matches as a
//! plain backtracking matcher says; nothing forged verifies.

use ndds_core::security::{Identity, Pattern, PublicId, split_signed, verify_signed};
use ndds_core::wire::signed;

/// The textbook definition of `*` patterns as a table: `fits[i][j]` says whether the first
/// `i` bytes of the pattern match the first `j` bytes of the name.
fn reference(pattern: &[u8], name: &[u8]) -> bool {
    let mut fits = vec![vec![false; name.len() + 1]; pattern.len() + 1];
    fits[0][0] = true;
    for i in 1..=pattern.len() {
        for j in 0..=name.len() {
            fits[i][j] = if pattern[i - 1] == b'*' {
                fits[i - 1][j] || (j > 0 && fits[i][j - 1])
            } else {
                j > 0 && pattern[i - 1] == name[j - 1] && fits[i - 1][j - 1]
            };
        }
    }
    fits[pattern.len()][name.len()]
}

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Some((&which, data)) = data.split_first() else {
            return;
        };
        match which % 5 {
            0 => {
                let Ok(text) = std::str::from_utf8(data) else {
                    return;
                };
                if let Ok(identity) = Identity::parse(text) {
                    let again = Identity::parse(&identity.to_file_text()).expect("written, read");
                    assert_eq!(again.public(), identity.public());
                }
            }
            1 => {
                let Ok(text) = std::str::from_utf8(data) else {
                    return;
                };
                if let Ok(key) = text.parse::<PublicId>() {
                    assert_eq!(key.to_string().parse::<PublicId>(), Ok(key));
                }
            }
            2 => {
                let Ok(text) = std::str::from_utf8(data) else {
                    return;
                };
                if let Ok((body, _)) = split_signed(text) {
                    assert!(text.starts_with(body));
                }
                let admin = Identity::from_secret([7; 32]);
                let signed = ndds_core::security::sign(text, &admin);
                verify_signed(&signed, &admin.public()).expect("what was signed verifies");
            }
            3 => {
                let Ok(text) = std::str::from_utf8(data) else {
                    return;
                };
                let (pattern, name) = text.split_once('\n').unwrap_or((text, ""));
                if let Ok(compiled) = Pattern::new(pattern) {
                    assert_eq!(
                        compiled.matches(name),
                        reference(pattern.as_bytes(), name.as_bytes()),
                        "{pattern:?} against {name:?}"
                    );
                }
            }
            _ => {
                if let Ok(view) = signed::parse(data) {
                    let _ = view.verify();
                }
            }
        }
    });
}
