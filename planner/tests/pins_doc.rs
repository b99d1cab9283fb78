//! The module's pins are declared once (`nurbs_hal::module::PINS`, which also makes them): the
//! pin table of `docs/integration.md` and the man page `docs/man/nurbs_interp.9` are rendered
//! from that table, and this test fails when either file differs from its rendering.
//! `make man` (`UPDATE_DOCS=1` here) writes them anew.

use nurbs_hal::module::PINS;
use nurbs_hal::pins::{PinDir, PinSpec};
use std::path::Path;

const BEGIN: &str = "<!-- pins: rendered from nurbs_hal::module::PINS by `make man` -->";
const END: &str = "<!-- /pins -->";

fn dir(p: &PinSpec) -> &'static str {
    match p.dir {
        PinDir::In => "in",
        PinDir::Out => "out",
    }
}

/// The markdown table between the markers of `docs/integration.md`.
fn markdown() -> String {
    let mut out = String::from("| pin | type | dir | unit | meaning |\n| --- | --- | --- | --- | --- |\n");
    for p in PINS {
        out += &format!(
            "| `nurbs_interp.{}` | {} | {} | {} | {} |\n",
            p.name,
            p.kind,
            dir(p),
            p.unit,
            p.doc
        );
    }
    out
}

/// roff text: backquoted names in bold, hyphens as such.
fn roff(text: &str) -> String {
    let mut out = String::new();
    for (k, part) in text.replace('\\', "\\\\").split('`').enumerate() {
        if k % 2 == 1 {
            out += &format!("\\fB{}\\fR", part.replace('-', "\\-"));
        } else {
            out += part;
        }
    }
    out
}

/// The man page nurbs_interp(9).
fn man_page() -> String {
    let mut out = String::from(
        ".TH NURBS_INTERP 9 \"\" \"nurbs-motion\" \"HAL Component\"\n\
         .SH NAME\n\
         nurbs_interp \\- jerk-limited NURBS toolpath interpolation on the servo thread\n\
         .SH SYNOPSIS\n\
         .B loadrt nurbs_interp\n\
         .br\n\
         .B addf nurbs_interp.update servo-thread\n\
         .br\n\
         .B loadusr \\-W nurbs-planner TOOLPATH \\-\\-ini MACHINE.ini\n\
         .SH DESCRIPTION\n\
         Runs the segment records and path blocks that \\fBnurbs-planner\\fR(1) plans and streams \
         through shared memory: every servo period one position on the toolpath, checked by the \
         planner by finite differences against the axis velocity, acceleration and jerk limits. \
         Every stop (hold, abort, a planner that falls behind) is a stop the planner made and \
         checked. The function never allocates, locks, calls the operating system or panics.\n\
         .SH FUNCTIONS\n\
         .TP\n\
         .B nurbs_interp.update\n\
         One servo period: follow the geometry stream, take records, interpolate, write the pins.\n\
         .SH PINS\n",
    );
    for p in PINS {
        let unit = if p.unit.is_empty() {
            String::new()
        } else {
            format!(" ({})", p.unit)
        };
        out += &format!(
            ".TP\n.B nurbs_interp.{} \\fR{} {}{}\n{}\n",
            p.name.replace('-', "\\-"),
            p.kind,
            dir(p),
            unit,
            roff(p.doc)
        );
    }
    out += ".SH SEE ALSO\n\\fBnurbs-planner\\fR(1), \\fBnurbs-plan\\fR(1); docs/integration.md of nurbs-motion \
            (stops, resume, fault codes, the channel).\n";
    out
}

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// `file` as it should be: `render` applied to its current text.
fn check(file: &str, render: impl Fn(&str) -> String) {
    let path = root().join(file);
    let now = std::fs::read_to_string(&path).unwrap_or_default();
    let want = render(&now);
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &want).unwrap();
    } else {
        assert!(now == want, "{file} is not rendered from the pin table: run `make man`");
    }
}

#[test]
fn the_pin_table_in_the_docs_is_the_modules() {
    check("docs/integration.md", |text| {
        let (Some(a), Some(b)) = (text.find(BEGIN), text.find(END)) else {
            panic!("docs/integration.md has no {BEGIN} ... {END} markers");
        };
        format!("{}{BEGIN}\n{}{}", &text[..a], markdown(), &text[b..])
    });
}

#[test]
fn the_man_page_is_the_modules() {
    check("docs/man/nurbs_interp.9", |_| man_page());
}

#[test]
fn every_pin_has_a_unique_name_and_a_meaning() {
    for (k, p) in PINS.iter().enumerate() {
        assert!(!p.doc.is_empty(), "{} has no meaning", p.name);
        assert!(PINS[..k].iter().all(|q| q.name != p.name), "{} twice", p.name);
    }
}
