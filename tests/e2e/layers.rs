//! The libraries keep to their layers (`nanopush_e2e::layers`): the instrument's and the
//! server's modules each use only modules of lower layers, as their crate docs' tables say.

use nanopush_e2e::layers::{check, code_only, test_files, uses, without_tests};
use nanopush_e2e::workspace;
use std::path::Path;

#[test]
fn the_instruments_modules_use_only_lower_layers() {
    let checked = check(&workspace().join("instrument/src")).unwrap_or_else(|e| panic!("{e}"));
    assert!(checked > 100, "the paths between modules were found ({checked})");
}

#[test]
fn the_servers_modules_use_only_lower_layers() {
    let checked = check(&workspace().join("server/src")).unwrap_or_else(|e| panic!("{e}"));
    assert!(checked > 50, "the paths between modules were found ({checked})");
}

#[test]
fn the_reader_finds_paths_in_code_and_not_in_comments_strings_or_tests() {
    let src = r##"
use crate::{app_state::AppState, records};
// crate::lifecycle in a comment
/* crate::app in a block comment */
fn f() { let s = "crate::session"; let r = r#"crate::telemetry"#; let c = '{'; let q = '\''; let l: &'static str = ""; }
fn g() -> super::super::push::X { crate::audit::x() }
#[cfg(test)]
fn helper() { crate::lifecycle::run(); }
#[cfg(test)]
mod tests { use crate::app; fn h() { {} } }
"##;
    let code = without_tests(&code_only(src));
    let mut used = uses(&["session".into(), "commands".into()], &code);
    used.sort();
    assert_eq!(used, ["app_state", "audit", "push", "records"]);
    assert_eq!(
        test_files(Path::new("src/session/mod.rs"), "#[cfg(test)]\npub(crate) mod tests;").len(),
        2
    );
}
