//! The man pages `docs/man/nurbs-plan.1` and `docs/man/nurbs-planner.1` are rendered from the
//! command lines' own definitions (clap); this test fails when a file differs from its
//! rendering, and `make man` (`UPDATE_DOCS=1` here) writes them anew.

use clap::CommandFactory;
use std::path::Path;

fn check(file: &str, command: clap::Command) {
    let mut page = Vec::new();
    clap_mangen::Man::new(command).render(&mut page).unwrap();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(file);
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &page).unwrap();
    } else {
        let now = std::fs::read(&path).unwrap_or_default();
        assert!(
            now == page,
            "{file} is not rendered from the command line: run `make man`"
        );
    }
}

#[test]
fn the_man_page_of_nurbs_plan_is_its_command_line() {
    check("docs/man/nurbs-plan.1", nurbs_cli::Cli::command());
}

#[test]
fn the_man_page_of_nurbs_planner_is_its_command_line() {
    check("docs/man/nurbs-planner.1", nurbs_cli::PlannerArgs::command());
}
