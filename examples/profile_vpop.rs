use nurbs_motion::planner::vpop::{plan_tip, SearchOptions};
use nurbs_motion::planner::Limits;
use nurbs_motion::readers::read_toolpath;
fn main() {
    let name = std::env::args().nth(1).unwrap_or("trident".into());
    let tp = read_toolpath(std::path::Path::new(&format!("examples/{name}.json"))).unwrap();
    let limits = Limits::uniform(2, 2500.0, 1e4, 6e4, 0.001, 0.00025);
    let p = plan_tip(&tp, &limits, SearchOptions::default()).unwrap();
    println!(
        "{name}: motion {:.4} s plan {:.1} ms {:?}",
        p.motion_time,
        p.plan_time * 1e3,
        p.stats
    );
}
