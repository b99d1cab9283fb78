//! The realtime module's checks of what it reads from shared memory, played from arbitrary
//! bytes on the mock HAL: a real streamed plan (the trident at lab set 1, segment records and
//! VPOp path blocks) with bytes of its slots and arena values changed as the input says, then
//! played with hold, abort and resume toggled by the input. Any panic of the module is a
//! finding (it must fault and hold instead); so is a position that is not a finite number, and
//! a fault after which the position moves. Shared by the fuzz target `channel` (fuzz/) and the
//! regression tests of its findings (`channel_findings.rs`), which run on stable.
#![allow(dead_code)] // each includer uses a different subset

use std::sync::OnceLock;
use std::time::{Duration, Instant};

use nurbs_hal::channel::{Slot, SEGMENT_SLOTS};
use nurbs_hal::mock::{self, Value};
use nurbs_hal::module::{rtapi_app_exit, rtapi_app_main};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::presets::named;
use nurbs_motion::readers::read_toolpath;
use nurbs_planner::feed::{block_plan, plan_groups, vpop_plan, BlockPlan, SegmentGroup, Source, Streamer};
use nurbs_planner::hal_user::Component;

pub struct Plans {
    toolpath: Toolpath,
    groups: Vec<SegmentGroup>,
    blocks: BlockPlan,
}

/// The plans every input starts from, made once.
pub fn plans() -> &'static Plans {
    static PLANS: OnceLock<Plans> = OnceLock::new();
    PLANS.get_or_init(|| {
        let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/trident.json"));
        let toolpath = read_toolpath(path).unwrap();
        let limits = named("lab1").on(2);
        let groups = plan_groups(&toolpath, &limits, None).unwrap();
        let vpop = vpop_plan(&toolpath, &limits, None).unwrap();
        let blocks = block_plan(&toolpath, (&vpop.points, &vpop.limits), None, 1.0).unwrap();
        Plans {
            toolpath,
            groups,
            blocks,
        }
    })
}

fn bit(name: &str) -> bool {
    matches!(mock::pin(name), Some(Value::Bit(true)))
}

fn position() -> [f64; 3] {
    let f = |n: &str| match mock::pin(n) {
        Some(Value::Float(v)) => v,
        _ => 0.0,
    };
    [
        f("nurbs_interp.pos-cmd-x"),
        f("nurbs_interp.pos-cmd-y"),
        f("nurbs_interp.pos-cmd-z"),
    ]
}

/// Plays one input; panics on a finding.
pub fn play(data: &[u8]) {
    let Some((&mode, edits)) = data.split_first() else {
        return;
    };
    let p = plans();
    mock::reset();
    // SAFETY: the mock HAL stands in for rtapi_app; one module per process, one input at a time.
    assert_eq!(unsafe { rtapi_app_main() }, 0);
    let comp = Component::new("fuzz").unwrap();
    let channel = comp.attach_channel(Duration::ZERO).unwrap();
    mock::set_pin("nurbs_interp.enable", Value::Bit(true));
    let source = if mode & 1 == 0 {
        Source::groups(p.groups.clone(), p.blocks.period)
    } else {
        Source::blocks(p.blocks.clone())
    };
    let mut streamer = Streamer::new(channel, p.toolpath.tip_dim(), source, 0, f64::INFINITY, Instant::now()).unwrap();
    streamer.fill().unwrap();
    // The edits, 5 bytes each: where (slot, descriptor or arena value) and what to xor in.
    let mut queued: Vec<Slot> = Vec::new();
    while let Ok(Some(s)) = channel.segments.consumer().pop() {
        queued.push(s);
    }
    for e in edits.chunks_exact(5) {
        let (target, at, x) = (e[0], u16::from_le_bytes([e[1], e[2]]) as usize, [e[3], e[4]]);
        match target % 3 {
            0 if !queued.is_empty() => {
                let k = at % queued.len();
                // SAFETY: Slot is plain data; any bytes are a valid slot (the module checks it).
                let bytes = unsafe {
                    std::slice::from_raw_parts_mut(&mut queued[k] as *mut Slot as *mut u8, std::mem::size_of::<Slot>())
                };
                let i = (usize::from(e[0]) * 7 + at) % bytes.len();
                bytes[i] ^= x[0];
            }
            1 => {
                let values = channel.geometry.values();
                let i = at % 256;
                let v = values[i].to_bits() ^ (u64::from(x[0]) << (8 * (x[1] % 8)));
                channel.geometry.write_values(i, &[f64::from_bits(v)]).unwrap();
            }
            _ => {}
        }
    }
    for s in queued.iter().take(SEGMENT_SLOTS) {
        channel.segments.producer().push(s).unwrap();
    }
    let update = mock::funct("nurbs_interp.update").unwrap();
    let mut faulted_at: Option<[f64; 3]> = None;
    for k in 0..4500usize {
        let control = edits.get(k / 64).copied().unwrap_or(0);
        mock::set_pin("nurbs_interp.hold", Value::Bit(mode & 2 != 0 && control & 1 != 0));
        mock::set_pin("nurbs_interp.abort", Value::Bit(mode & 4 != 0 && control & 2 != 0));
        mock::set_pin("nurbs_interp.resume", Value::Bit(control & 4 != 0));
        // SAFETY: the exported function with its instance, as a servo thread calls it.
        unsafe { mock::call(update, 250_000) };
        let here = position();
        assert!(
            here.iter().all(|x| x.is_finite()),
            "a position that is not a number: {here:?}"
        );
        if let Some(held) = faulted_at {
            assert_eq!(here, held, "the position moved after a fault");
        } else if bit("nurbs_interp.fault") {
            faulted_at = Some(position());
        }
        if bit("nurbs_interp.done") {
            break;
        }
    }
    drop(streamer);
    drop(comp);
    // SAFETY: loaded above.
    unsafe { rtapi_app_exit() };
}
