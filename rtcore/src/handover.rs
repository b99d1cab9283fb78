//! The hand-over between LinuxCNC's motion controller and our interpolator, per joint, as a
//! pure state machine (the module wires it to pins).
//!
//! The pattern is LinuxCNC's own `moveoff` component: while engaged, the drive gets
//! `joint.N.motor-pos-cmd + offset` and motion gets the drive's feedback `- offset`, with
//! `offset = our position - joint.N.pos-cmd`. The two halves run on either side of motion in
//! the servo thread: [`Handover::motor_pos_fb`] before it (with the offset the drive's command
//! was made with, so that motion sees exactly its own last command when the drive tracks), and
//! [`Handover::step`] after it and after our interpolator. Motion stands still (a user M-code is running)
//! and keeps supervising the true tracking error (our command against the drive), homing and
//! soft limits stay its own, and after our path a plain move of motion to our end point (the
//! "catch-up move") takes the offset back to zero while the drive stands still. Released, both
//! outputs pass straight through, from the first period on.
//!
//! Engaging never jumps: only at rest (motion and our path), with our start within
//! [`ENGAGE_TOLERANCE`] of where motion stands. Releasing never jumps: only at rest too, with
//! every offset within that tolerance. Machine off while engaged releases at once: the drives are disabled
//! and motion takes over from their feedback (it re-syncs to feedback while disabled).

/// Joints the hand-over serves: X, Y and Z of a trivkins machine (joint N = axis N).
pub const JOINTS: usize = 3;

/// Largest distance (mm, per joint) between our start and motion's position at engagement, and
/// largest offset at release: a step of at most this size in the drive command (1 nm: far
/// below one period's change at any acceleration a machine has).
pub const ENGAGE_TOLERANCE: f64 = 1e-6;

/// Why an engage or release request is not carried out (the `handover-refused` pin).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    None = 0,
    /// Engage asked with the machine off.
    MachineOff = 1,
    /// Engage asked with no path loaded (no start position).
    NoPath = 2,
    /// Engage asked while motion's command or our path moves.
    NotAtRest = 3,
    /// Engage asked with our start more than [`ENGAGE_TOLERANCE`] from motion's position.
    StartMismatch = 4,
    /// Release asked with an offset larger than [`ENGAGE_TOLERANCE`] (the catch-up move has not
    /// brought motion to our position): stays engaged.
    OffsetLeft = 5,
}

/// What the hand-over reads in one period.
#[derive(Clone, Copy, Debug)]
pub struct Inputs {
    /// Hand-over requested (level).
    pub engage: bool,
    /// Motion is enabled (machine on).
    pub machine_on: bool,
    /// Our position, if one is known (a path is loaded or has run).
    pub ours: Option<[f64; JOINTS]>,
    /// Joints our path drives (the others pass through).
    pub driven: [bool; JOINTS],
    /// Our path is at rest (not started, stopped or finished).
    pub ours_at_rest: bool,
    /// Motion's `joint.N.pos-cmd`.
    pub pos_cmd: [f64; JOINTS],
    /// Motion's `joint.N.motor-pos-cmd`.
    pub motor_pos_cmd: [f64; JOINTS],
    /// The drive's position feedback (motor coordinates).
    pub drive_fb: [f64; JOINTS],
}

/// What the hand-over writes in one period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outputs {
    /// To the drive.
    pub drive_cmd: [f64; JOINTS],
    /// Our position minus motion's, per joint (0 when released).
    pub offset: [f64; JOINTS],
    pub engaged: bool,
    pub refused: Refusal,
    /// The machine was switched off while engaged, this period: the hand-over released and our
    /// motion must end where it stands.
    pub machine_off: bool,
}

/// The hand-over's state between periods.
#[derive(Clone, Copy, Debug, Default)]
pub struct Handover {
    engaged: bool,
    /// Released by the machine switched off: `engage` must go false before it counts again (an
    /// old request must not take the drives when the machine comes back).
    rearm: bool,
    offset: [f64; JOINTS],
    last_pos_cmd: Option<[f64; JOINTS]>,
}

impl Handover {
    pub const fn new() -> Handover {
        Handover {
            engaged: false,
            rearm: false,
            offset: [0.0; JOINTS],
            last_pos_cmd: None,
        }
    }

    /// Motion's `joint.N.motor-pos-fb` from the drive's feedback: less the offset the drive's
    /// last command was made with (run before motion, each period).
    pub fn motor_pos_fb(&self, drive_fb: &[f64; JOINTS]) -> [f64; JOINTS] {
        core::array::from_fn(|j| drive_fb[j] - self.offset[j])
    }

    /// One period: decides engagement and computes both outputs.
    pub fn step(&mut self, i: &Inputs) -> Outputs {
        let mut refused = Refusal::None;
        let mut machine_off = false;
        let motion_at_rest = self.last_pos_cmd == Some(i.pos_cmd);
        self.last_pos_cmd = Some(i.pos_cmd);
        if self.engaged && !i.machine_on {
            // Drives disabled: let motion take the drives' feedback (it re-syncs while disabled).
            self.engaged = false;
            self.offset = [0.0; JOINTS];
            self.rearm = true;
            machine_off = true;
            return Outputs {
                drive_cmd: i.drive_fb,
                offset: self.offset,
                engaged: false,
                refused,
                machine_off,
            };
        }
        if self.engaged {
            if let Some(ours) = i.ours {
                self.offset = offsets(&ours, &i.pos_cmd, &i.driven);
            }
            if !i.engage {
                // At rest too, as for engaging: released while motion still moves (a release
                // asked during the catch-up move), the drive would take up motion's velocity
                // in one period.
                if self.offset.iter().any(|o| o.abs() > ENGAGE_TOLERANCE) {
                    refused = Refusal::OffsetLeft;
                } else if !(motion_at_rest && i.ours_at_rest) {
                    refused = Refusal::NotAtRest;
                } else {
                    self.engaged = false;
                    self.offset = [0.0; JOINTS];
                }
            }
        } else if !i.engage {
            self.rearm = false;
        } else if self.rearm {
            refused = Refusal::MachineOff;
        } else {
            refused = match i.ours {
                _ if !i.machine_on => Refusal::MachineOff,
                None => Refusal::NoPath,
                Some(_) if !(motion_at_rest && i.ours_at_rest) => Refusal::NotAtRest,
                Some(ours) => {
                    let offset = offsets(&ours, &i.pos_cmd, &i.driven);
                    if offset.iter().all(|o| o.abs() <= ENGAGE_TOLERANCE) {
                        self.engaged = true;
                        self.offset = offset;
                        Refusal::None
                    } else {
                        Refusal::StartMismatch
                    }
                }
            };
        }
        Outputs {
            drive_cmd: core::array::from_fn(|j| i.motor_pos_cmd[j] + self.offset[j]),
            offset: self.offset,
            engaged: self.engaged,
            refused,
            machine_off,
        }
    }
}

/// Our position minus motion's on the joints our path drives (0 on the others); a difference
/// that is not a number counts as infinitely far.
fn offsets(ours: &[f64; JOINTS], pos_cmd: &[f64; JOINTS], driven: &[bool; JOINTS]) -> [f64; JOINTS] {
    core::array::from_fn(|j| {
        if !driven[j] {
            return 0.0;
        }
        let d = ours[j] - pos_cmd[j];
        if d.is_finite() {
            d
        } else {
            f64::INFINITY
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inputs(engage: bool, ours: [f64; 3], pos_cmd: [f64; 3]) -> Inputs {
        let motor_offset = [2.5, -1.0, 0.25];
        Inputs {
            engage,
            machine_on: true,
            ours: Some(ours),
            driven: [true; 3],
            ours_at_rest: true,
            pos_cmd,
            motor_pos_cmd: core::array::from_fn(|j| pos_cmd[j] + motor_offset[j]),
            drive_fb: core::array::from_fn(|j| pos_cmd[j] + motor_offset[j]),
        }
    }

    #[test]
    fn released_it_passes_through_from_the_first_period() {
        let mut h = Handover::new();
        let i = inputs(false, [0.0; 3], [1.0, 2.0, 3.0]);
        assert_eq!(h.motor_pos_fb(&i.drive_fb), i.drive_fb);
        let o = h.step(&i);
        assert_eq!((o.drive_cmd, o.engaged), (i.motor_pos_cmd, false));
    }

    #[test]
    fn engages_only_at_rest_and_at_the_start_then_the_drive_follows_our_path() {
        let mut h = Handover::new();
        let start = [10.0, 20.0, 5.0];
        // Motion still arriving: not at rest.
        assert_eq!(
            h.step(&inputs(true, start, [9.0, 20.0, 5.0])).refused,
            Refusal::NotAtRest
        );
        assert_eq!(h.step(&inputs(true, start, start)).refused, Refusal::NotAtRest);
        let o = h.step(&inputs(true, start, start));
        assert!(o.engaged && o.refused == Refusal::None);
        assert_eq!(o.drive_cmd, [12.5, 19.0, 5.25]);
        // Our path moves, motion stands: the drive follows us; the drive having tracked,
        // motion sees its own command (the feedback less the offset the command was made with).
        let i = inputs(true, [11.0, 20.5, 5.0], start);
        let o = h.step(&i);
        assert_eq!(o.drive_cmd, [13.5, 19.5, 5.25]);
        assert_eq!(o.offset, [1.0, 0.5, 0.0]);
        assert_eq!(h.motor_pos_fb(&o.drive_cmd), i.motor_pos_cmd);
    }

    #[test]
    fn refuses_a_start_elsewhere_no_path_and_machine_off() {
        let mut h = Handover::new();
        let here = [1.0, 1.0, 1.0];
        h.step(&inputs(false, here, here));
        let far = [1.0, 1.0 + 2.0 * ENGAGE_TOLERANCE, 1.0];
        assert_eq!(h.step(&inputs(true, far, here)).refused, Refusal::StartMismatch);
        let mut i = inputs(true, here, here);
        i.ours = None;
        assert_eq!(h.step(&i).refused, Refusal::NoPath);
        let mut i = inputs(true, here, here);
        i.machine_on = false;
        assert_eq!(h.step(&i).refused, Refusal::MachineOff);
        let mut i = inputs(true, [f64::NAN, 1.0, 1.0], here);
        i.ours_at_rest = true;
        assert_eq!(h.step(&i).refused, Refusal::StartMismatch);
        assert!(!h.step(&inputs(false, here, here)).engaged);
    }

    #[test]
    fn the_catch_up_move_keeps_the_drive_still_and_release_waits_for_zero_offset() {
        let mut h = Handover::new();
        let (start, end) = ([0.0; 3], [30.0, -4.0, 2.0]);
        h.step(&inputs(true, start, start));
        assert!(h.step(&inputs(true, start, start)).engaged);
        let drive_at_end = h.step(&inputs(true, end, start)).drive_cmd;
        // Release asked before the catch-up: refused, still engaged.
        let o = h.step(&inputs(false, end, start));
        assert!(o.engaged && o.refused == Refusal::OffsetLeft);
        // Motion moves to our end; the drive command does not move.
        for k in 1..=10 {
            let p: [f64; 3] = core::array::from_fn(|j| end[j] * k as f64 / 10.0);
            let o = h.step(&inputs(false, end, p));
            for j in 0..3 {
                assert!((o.drive_cmd[j] - drive_at_end[j]).abs() < 1e-12, "{k}: {o:?}");
            }
            // Arrived, but moving in this period: the release waits for motion to stand.
            assert!(o.engaged, "{k}");
        }
        let o = h.step(&inputs(false, end, end));
        assert!(!o.engaged && o.offset == [0.0; 3], "{o:?}");
    }

    #[test]
    fn machine_off_releases_at_once_to_the_drive_feedback() {
        let mut h = Handover::new();
        let start = [0.0; 3];
        h.step(&inputs(true, start, start));
        h.step(&inputs(true, start, start));
        let mut i = inputs(true, [3.0, 0.0, 0.0], start);
        i.machine_on = false;
        i.drive_fb = [5.4, -1.0, 0.25];
        let o = h.step(&i);
        assert!(o.machine_off && !o.engaged);
        assert_eq!((o.drive_cmd, h.motor_pos_fb(&i.drive_fb)), (i.drive_fb, i.drive_fb));
    }

    #[test]
    fn after_machine_off_an_old_request_does_not_engage_again() {
        let mut h = Handover::new();
        let start = [0.0; 3];
        h.step(&inputs(true, start, start));
        assert!(h.step(&inputs(true, start, start)).engaged);
        let mut off = inputs(true, start, start);
        off.machine_on = false;
        assert!(h.step(&off).machine_off);
        // On again, `engage` still high from before: refused until it has been low.
        for _ in 0..3 {
            let o = h.step(&inputs(true, start, start));
            assert!(!o.engaged && o.refused == Refusal::MachineOff);
        }
        h.step(&inputs(false, start, start));
        assert!(h.step(&inputs(true, start, start)).engaged);
    }

    #[test]
    fn an_undriven_joint_passes_through() {
        let mut h = Handover::new();
        let mut i = inputs(true, [1.0, 1.0, 99.0], [1.0, 1.0, 0.0]);
        i.driven = [true, true, false];
        h.step(&i);
        let o = h.step(&i);
        assert!(o.engaged);
        assert_eq!(o.offset[2], 0.0);
        assert_eq!(o.drive_cmd[2], i.motor_pos_cmd[2]);
    }
}
