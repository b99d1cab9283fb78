//! The userspace side of the NURBS interpolator for LinuxCNC.
//!
//! `nurbs-planner` (`loadusr`) plans a toolpath with `nurbs_motion` and streams it into the
//! realtime module's shared-memory channel (`nurbs_hal::channel`) while the motion runs:
//! [`feed`] turns a plan into ring slots in groups that end at a checked stop and keeps the
//! module supplied ([`feed::Streamer`]), [`shared_path`] reads the toolpath once for all the plans of a motion, [`writer`] streams the curves into the channel's
//! geometry ring and reuses what the module has passed, [`hal_user`] is the HAL userspace API
//! (component, pins, signals, sampler streams). Nothing here runs on the servo thread.

pub mod cut;
pub mod feed;
pub mod hal_user;
pub mod hold_stops;
pub mod log;
pub mod shared_path;
pub mod writer;
