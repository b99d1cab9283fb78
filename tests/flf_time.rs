// Development probe (not a test of behaviour): time to traverse each curve at its FLF.
use nurbs_motion::geometry::ArcLengthTable;
use nurbs_motion::planner::flf::flf;
use nurbs_motion::planner::Limits;
use nurbs_motion::readers::read_toolpath;
use std::path::Path;

#[test]
#[ignore]
fn flf_traversal_time() {
    for (name, l) in [
        ("butterfly.json", Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, 0.00025)),
        (
            "trident.json",
            Limits {
                feed: 166.667,
                velocity: vec![500.0, 500.0],
                acceleration: vec![2500.0, 3000.0],
                jerk: vec![5000.0, 5000.0],
                chord_tolerance: 0.02,
                period: 0.006,
            },
        ),
    ] {
        let tp = read_toolpath(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples").join(name)).unwrap();
        let c = &tp.elements[0].curve;
        let v = c.view();
        let n = 200000;
        let (mut t, mut t_noj) = (0.0, 0.0);
        let table = ArcLengthTable::new(c);
        let _ = table;
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            let ds = c.speed(u) / n as f64;
            let f = flf(&v, 2, &l, u);
            t += ds / f.value();
            t_noj += ds / f.feed.min(f.chord).min(f.accel);
        }
        eprintln!("{name}: FLF time {t:.4} s, without jerk cap {t_noj:.4} s");
    }
}

#[test]
#[ignore]
fn flf_dump() {
    let l = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, 0.00025);
    let tp = read_toolpath(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/butterfly.json")).unwrap();
    let v = tp.elements[0].curve.view();
    let mut out = String::new();
    for i in 0..=20000 {
        let u = i as f64 / 20000.0;
        let f = flf(&v, 2, &l, u);
        out += &format!("{u},{},{},{}\n", f.value(), f.accel, f.jerk);
    }
    std::fs::write("out/flf.csv", out).unwrap();
}
