//! The geometry stream on the mock HAL: curves checked a slice per period, refused when bad,
//! and a program longer than the descriptor ring and the arena run through both, reused as
//! the module passes them.

mod common;

use std::time::Instant;

use common::test_paths::{g1_zigzag, long_spline};
use common::*;
use nurbs_hal::channel::{CurveDesc, GeometryHeader, CURVE_SLOTS};
use nurbs_hal::module::{FaultCode, VALIDATION_VALUES_PER_PERIOD};
use nurbs_planner::feed::{Source, Streamer};
use nurbs_planner::writer::{GeometryWriter, Release, WriteError};

/// Many small curves (a 150-line G1 program, 299 elements) and one curve larger than a
/// period's slice: the module checks at most [`VALIDATION_VALUES_PER_PERIOD`] values per
/// period, so the motion starts only once the curves of its first group are checked: as many
/// periods later as their values need.
#[test]
fn curves_are_checked_a_slice_per_period() {
    let _guard = lock_module();
    for (name, job) in [
        ("zigzag", job_of(g1_zigzag(150))),
        ("long spline", job_of(long_spline(3000))),
    ] {
        let l = load();
        let mut w = GeometryWriter::begin(l.channel, 0, job.toolpath.tip_dim(), PERIOD).unwrap();
        let mut values = 0;
        for e in &job.toolpath.elements {
            let c = &e.curve;
            w.publish_curve(c.degree(), c.dim(), c.knots(), c.points(), c.weights())
                .unwrap();
            // Knots, coordinates and weights once, interior knots once more.
            values += c.knots().len() + c.points().len() + 2 * c.weights().len() - c.degree() - 1;
        }
        let slots: Vec<_> = job.groups.iter().flat_map(|g| g.slots.clone()).collect();
        for s in &slots {
            l.channel
                .segments
                .producer()
                .push(&nurbs_hal::channel::Slot::segment(s))
                .unwrap();
        }
        let needed = slots[0].curve_needed as usize;
        let first_values: usize = job.toolpath.elements[..=needed]
            .iter()
            .map(|e| {
                let c = &e.curve;
                c.knots().len() + c.points().len() + 2 * c.weights().len() - c.degree() - 1
            })
            .sum();
        let mut waited = 0;
        while !bit("nurbs_interp.active") && waited < 10_000 {
            period();
            waited += 1;
        }
        let expected = first_values.div_ceil(VALIDATION_VALUES_PER_PERIOD);
        println!("{name}: {values} values in all; moving in period {waited} ({first_values} values before)");
        assert!(
            waited >= expected && waited <= expected + 1,
            "{name}: {waited} periods, expected {expected}"
        );
        assert!(!bit("nurbs_interp.fault"));
    }
}

/// A curve that does not check (a negative weight) faults the module (geometry) when it is
/// reached, before anything moves on it; a header the module cannot run is refused on both
/// sides; a new stream during the motion faults (geometry changed).
#[test]
fn bad_curves_and_streams_are_refused() {
    let _guard = lock_module();
    let job = job("trident.json");
    let l = load();
    let w = GeometryWriter::begin(l.channel, 0, 2, PERIOD).unwrap();
    let c = &job.toolpath.elements[0].curve;
    let mut weights = c.weights().to_vec();
    weights[2] = -1.0;
    assert!(matches!(
        GeometryWriter::begin(l.channel, 0, 2, PERIOD).unwrap().publish_curve(
            c.degree(),
            c.dim(),
            c.knots(),
            c.points(),
            &weights
        ),
        Err(WriteError::Refused(_))
    ));
    drop(w);
    // The same curve past the writer's check, straight into the stream.
    let w = GeometryWriter::begin(l.channel, 0, 2, PERIOD).unwrap();
    let data: Vec<f64> = c.knots().iter().chain(c.points()).chain(&weights).copied().collect();
    l.channel.geometry.write_values(0, &data).unwrap();
    let (k, p) = (c.knots().len() as u32, c.points().len() as u32);
    let desc = CurveDesc {
        index: 0,
        degree: c.degree() as u32,
        dim: 2,
        knots_offset: 0,
        knots_len: k,
        points_offset: k,
        points_len: p,
        weights_offset: k + p,
        weights_len: weights.len() as u32,
        reserved: 0,
    };
    l.channel.geometry.publish_unchecked(&desc);
    for s in &job.groups[0].slots {
        l.channel
            .segments
            .producer()
            .push(&nurbs_hal::channel::Slot::segment(s))
            .unwrap();
    }
    for _ in 0..10 {
        period();
    }
    assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::Geometry as u32);
    assert_eq!(u32_pin("nurbs_interp.records"), 0);
    drop(w);
    drop(l);
    // Four tip axes, or joints: refused by the stream itself.
    let l = load();
    for header in [
        GeometryHeader {
            tip_axes: 4,
            ..GeometryHeader::default()
        },
        GeometryHeader {
            tip_axes: 3,
            joints: 5,
            ..GeometryHeader::default()
        },
    ] {
        assert!(l.channel.geometry.begin(&header).is_err());
    }
    // A new stream in the middle of a motion.
    let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
    run(&mut s, 100, &mut |_| {}, &mut |_| false);
    assert!(bit("nurbs_interp.active"));
    let _w = GeometryWriter::begin(l.channel, 0, 2, PERIOD).unwrap();
    period();
    assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::GeometryChanged as u32);
}

/// A plan states the servo period it was made for; on a thread of another period the module
/// refuses the whole stream (fault "period", no record taken, the position held) rather than
/// play its samples faster or slower than planned. The period rounded to whole nanoseconds
/// still runs.
#[test]
fn a_plan_for_another_servo_period_is_refused() {
    let _guard = lock_module();
    let job = job("trident.json");
    for (planned, refused) in [(4.0 * PERIOD, true), (PERIOD * (1.0 + 1e-10), false)] {
        let l = load();
        let mut s = Streamer::new(
            l.channel,
            job.toolpath.tip_dim(),
            Source::groups(job.groups.clone(), planned),
            0,
            0.25,
            Instant::now(),
        )
        .unwrap();
        let got = run(&mut s, 200, &mut |_| {}, &mut |_| false);
        if refused {
            assert_eq!(u32_pin("nurbs_interp.fault-code"), FaultCode::Period as u32);
            assert_eq!(u32_pin("nurbs_interp.records"), 0);
            assert!(got.is_empty(), "no sample of the refused plan is played");
        } else {
            assert!(
                !bit("nurbs_interp.fault"),
                "fault {}",
                u32_pin("nurbs_interp.fault-code")
            );
            assert!(u32_pin("nurbs_interp.records") > 0);
        }
    }
}

/// A G1 program longer than what the writer may use (here limited to 64 descriptors in flight
/// and 6,000 arena values: as a program longer than the channel runs through
/// [`CURVE_SLOTS`] and the whole arena): the curves go in as the records need them and reuse
/// slots and values the module has passed; the module plays the offline streamed setpoints bit
/// for bit.
/// The arena is written round and round: values go after the last ones written, or at its
/// start, never over values the module may still read. Written round to exactly the oldest
/// value held, it is full (a writer that compared the two positions took that for empty and
/// wrote over a curve in use: garbage positions on a long G1 program through a small arena).
#[test]
fn an_arena_written_round_to_its_oldest_value_is_full() {
    let _guard = lock_module();
    let l = load();
    let mut w = GeometryWriter::begin(l.channel, 0, 2, PERIOD).unwrap();
    w.limit(100, 64);
    let kept = Release::Slot(1_000_000);
    assert_eq!(w.put(&[1.0; 30], Release::Slot(0)), Ok(0));
    assert_eq!(w.put(&[2.0; 70], kept), Ok(30));
    // The first 30 are released once the module has taken slot 2.
    w.reclaim(2);
    assert_eq!(w.put(&[3.0; 30], kept), Ok(0));
    // 30..100 and 0..30 are held: nothing fits anywhere, not even one value.
    assert_eq!(w.put(&[4.0; 10], kept), Err(WriteError::Full));
    assert_eq!(w.put(&[4.0; 1], kept), Err(WriteError::Full));
    // Nothing was written over.
    let read = &l.channel.geometry.values()[..100];
    assert!(read[..30].iter().all(|&v| v == 3.0) && read[30..].iter().all(|&v| v == 2.0));
}

#[test]
fn a_program_longer_than_the_channel_reuses_it() {
    let _guard = lock_module();
    let job = job_of(g1_zigzag(400));
    assert!(job.toolpath.elements.len() > 64 * 10);
    let l = load();
    let mut s = Streamer::new(
        l.channel,
        job.toolpath.tip_dim(),
        Source::groups(job.groups.clone(), PERIOD),
        0,
        0.2,
        Instant::now(),
    )
    .unwrap();
    // An arena far smaller than the machine's, but one that holds the group running and the
    // next one, each with its curves and stored hold stops (up to 7 curves a group here): with
    // less, the next group waits for the running one to end, and the module underruns there.
    s.writer().limit(6000, 64);
    let got = run(&mut s, job.samples.len() + 100, &mut |_| {}, &mut |_| {
        bit("nurbs_interp.done") || bit("nurbs_interp.fault") || bit("nurbs_interp.held")
    });
    assert_exact("zigzag 400", &got, &job.samples, 2);
    assert_eq!(u32_pin("nurbs_interp.underruns"), 0);
    println!(
        "{} elements through 64 descriptor slots and 6,000 arena values ({} of {CURVE_SLOTS} slots and the whole arena on the machine)",
        job.toolpath.elements.len(),
        64
    );
}

/// Every path element the readers accept fits the channel's arena with its knots and weights,
/// at the most coordinates a curve has (tool tip and top) and the highest degree: a stream
/// never meets an element it cannot carry.
#[test]
fn every_element_a_reader_accepts_fits_the_arena() {
    let points = nurbs_motion::readers::MAX_CONTROL_POINTS;
    let knots = points + nurbs_rtcore::MAX_DEGREE + 1;
    let values = knots + points * nurbs_rtcore::MAX_DIM + points;
    assert!(
        values <= nurbs_hal::channel::ARENA_VALUES,
        "{values} values against an arena of {}",
        nurbs_hal::channel::ARENA_VALUES
    );
}
