//! `#[derive(Component)]`'s compile errors: each case in `tests/ui/` must fail with exactly the
//! message in its `.stderr` file (which names the field and says what is taken), and the
//! passing case, every role and option at once, must compile.
//!
//! Regenerate the `.stderr` files after changing a message with
//! `TRYBUILD=overwrite cargo test -p ndds-runtime --test derive_errors`, then read them.

#[test]
fn derive_component_compile_errors_name_the_field() {
    let cases = trybuild::TestCases::new();
    cases.compile_fail("tests/ui/fail_*.rs");
    cases.pass("tests/ui/pass.rs");
}
