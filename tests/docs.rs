//! Tables of the docs rendered from the code that defines them: the limit presets in
//! `docs/planners.md` (`nurbs_motion::planner::presets`). This test fails when the file differs
//! from its rendering; `make man` (`UPDATE_DOCS=1` here) writes it anew.

use nurbs_motion::planner::presets::markdown_table;
use std::path::Path;

const BEGIN: &str = "<!-- presets: rendered from nurbs_motion::planner::presets::PRESETS by `make man` -->";
const END: &str = "<!-- /presets -->";

#[test]
fn the_preset_table_in_the_docs_is_the_code_s() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/planners.md");
    let text = std::fs::read_to_string(&path).unwrap();
    let (Some(a), Some(b)) = (text.find(BEGIN), text.find(END)) else {
        panic!("docs/planners.md has no {BEGIN} ... {END} markers");
    };
    let want = format!("{}{BEGIN}\n{}{}", &text[..a], markdown_table(), &text[b..]);
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &want).unwrap();
    } else {
        assert!(
            text == want,
            "docs/planners.md is not rendered from the presets: run `make man`"
        );
    }
}
