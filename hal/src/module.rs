//! The realtime module `nurbs_interp`: `loadrt nurbs_interp`, then
//! `addf nurbs_interp.update servo-thread`.
//!
//! `rtapi_app_main` creates the component, its pins (all instance state lives in `hal_malloc`'d
//! memory, as in C components), the shared-memory [`Channel`] the planner writes to, and exports
//! `nurbs_interp.update`. [`Instance::update`] runs every servo period: it reads the input pins,
//! takes records from the channel, writes the output pins and nothing else. It never allocates,
//! locks, calls the OS or panics; failures are pins (fault, underruns), not errors.
//!
//! Pins (spike set; the README documents the final list):
//!
//! | pin | type | dir | meaning |
//! | --- | --- | --- | --- |
//! | `nurbs_interp.enable` | bit | in | run; when false the outputs hold |
//! | `nurbs_interp.pos-cmd-x`, `-y`, `-z` | float | out | axis position commands (mm) |
//! | `nurbs_interp.active` | bit | out | a record was executed this period |
//! | `nurbs_interp.fault` | bit | out | malformed channel or record sequence; latched |
//! | `nurbs_interp.seq` | u32 | out | sequence number of the last record taken |
//! | `nurbs_interp.records` | u32 | out | records taken so far |
//! | `nurbs_interp.underruns` | u32 | out | enabled periods that found no data |

use core::ffi::{c_int, c_long, c_void, CStr};
use core::ptr::{self, addr_of_mut};
use core::sync::atomic::{AtomicI32, Ordering};

use crate::channel::{Channel, ChannelError, CHANNEL_KEY};
use crate::pins::Pin;
use crate::record::SegmentRecord;
use crate::sys;

/// Component name: must equal the module's file name (`loadrt` dlopens `NAME.so`).
pub const NAME: &CStr = c"nurbs_interp";

/// Component id and channel id, for `rtapi_app_exit` (set once in `rtapi_app_main`).
static COMP_ID: AtomicI32 = AtomicI32::new(-1);
static SHMEM_ID: AtomicI32 = AtomicI32::new(-1);

const EINVAL: c_int = 22;
const ENOMEM: c_int = 12;

/// The component's pins, in HAL shared memory.
#[repr(C)]
pub struct Pins {
    pub enable: Pin<bool>,
    pub pos_cmd_x: Pin<f64>,
    pub pos_cmd_y: Pin<f64>,
    pub pos_cmd_z: Pin<f64>,
    pub active: Pin<bool>,
    pub fault: Pin<bool>,
    pub seq: Pin<u32>,
    pub records: Pin<u32>,
    pub underruns: Pin<u32>,
}

/// Everything the update function touches: pins, the channel and plain-data state.
#[repr(C)]
pub struct Instance {
    pub pins: Pins,
    channel: *const Channel,
    /// Sequence number the next record must carry.
    next_seq: u32,
    records: u32,
    underruns: u32,
    fault: bool,
    // INTEGRATION POINT: the `nurbs_rtcore` interpolator state (plain data, fixed capacity)
    // goes here, initialised in `create`.
}

impl Instance {
    /// One servo period. `period_ns` is the thread's period.
    pub fn update(&mut self, _period_ns: i64) {
        if !self.pins.enable.get() || self.fault {
            self.pins.active.set(false);
            self.pins.fault.set(self.fault);
            return;
        }
        // SAFETY: the channel block stays mapped until rtapi_app_exit, after the last period.
        let channel = unsafe { &*self.channel };
        // INTEGRATION POINT: the interpolator asks for the next record only when the current
        // segment ends, and every period evaluates the S-curve, advances u (RK2-PC) and the NURBS.
        // The spike takes one record per period and shows its fields on the position pins.
        match channel.segments.pop() {
            Ok(Some(record)) => self.execute(&record),
            Ok(None) => {
                self.underruns = self.underruns.wrapping_add(1);
                self.pins.active.set(false);
            }
            Err(
                ChannelError::NotInitialised
                | ChannelError::Layout
                | ChannelError::Corrupt
                | ChannelError::Full,
            ) => {
                self.fault = true;
                self.pins.active.set(false);
            }
        }
        self.pins.fault.set(self.fault);
        self.pins.records.set(self.records);
        self.pins.underruns.set(self.underruns);
    }

    fn execute(&mut self, record: &SegmentRecord) {
        let pins = &self.pins;
        if record.seq != self.next_seq {
            self.fault = true;
            pins.active.set(false);
            return;
        }
        self.next_seq = record.seq.wrapping_add(1);
        self.records = self.records.wrapping_add(1);
        pins.seq.set(record.seq);
        pins.pos_cmd_x.set(record.s_start);
        pins.pos_cmd_y.set(record.u_start);
        pins.pos_cmd_z.set(record.feed_start);
        pins.active.set(true);
    }
}

/// The exported HAL function `nurbs_interp.update`.
unsafe extern "C" fn update(arg: *mut c_void, period: c_long) {
    // SAFETY: `arg` is the Instance exported with this function; HAL calls a non-reentrant
    // function from one thread at a time.
    let instance = &mut *(arg as *mut Instance);
    #[allow(clippy::useless_conversion)] // c_long is i32 on some targets
    instance.update(i64::from(period));
}

fn error(msg: &CStr) {
    sys::print_msg(sys::RTAPI_MSG_ERR, msg);
}

/// Create pins, channel and function on an initialised component. Returns 0 or -errno.
unsafe fn create(comp_id: c_int) -> c_int {
    let inst = sys::hal_malloc(core::mem::size_of::<Instance>() as c_long) as *mut Instance;
    if inst.is_null() {
        error(c"nurbs_interp: hal_malloc failed");
        return -ENOMEM;
    }
    let p = addr_of_mut!((*inst).pins);
    let in_ = sys::HAL_IN;
    let out = sys::HAL_OUT;
    let results = [
        Pin::create(
            addr_of_mut!((*p).enable),
            c"nurbs_interp.enable",
            in_,
            comp_id,
        ),
        Pin::create(
            addr_of_mut!((*p).pos_cmd_x),
            c"nurbs_interp.pos-cmd-x",
            out,
            comp_id,
        ),
        Pin::create(
            addr_of_mut!((*p).pos_cmd_y),
            c"nurbs_interp.pos-cmd-y",
            out,
            comp_id,
        ),
        Pin::create(
            addr_of_mut!((*p).pos_cmd_z),
            c"nurbs_interp.pos-cmd-z",
            out,
            comp_id,
        ),
        Pin::create(
            addr_of_mut!((*p).active),
            c"nurbs_interp.active",
            out,
            comp_id,
        ),
        Pin::create(
            addr_of_mut!((*p).fault),
            c"nurbs_interp.fault",
            out,
            comp_id,
        ),
        Pin::create(addr_of_mut!((*p).seq), c"nurbs_interp.seq", out, comp_id),
        Pin::create(
            addr_of_mut!((*p).records),
            c"nurbs_interp.records",
            out,
            comp_id,
        ),
        Pin::create(
            addr_of_mut!((*p).underruns),
            c"nurbs_interp.underruns",
            out,
            comp_id,
        ),
    ];
    if let Some(&rc) = results.iter().find(|&&rc| rc < 0) {
        error(c"nurbs_interp: pin export failed");
        return rc;
    }

    let shmem_id = sys::rtapi_shmem_new(CHANNEL_KEY, comp_id, Channel::SIZE as _);
    if shmem_id < 0 {
        error(c"nurbs_interp: rtapi_shmem_new failed");
        return shmem_id;
    }
    SHMEM_ID.store(shmem_id, Ordering::Relaxed);
    let mut block: *mut c_void = ptr::null_mut();
    let rc = sys::rtapi_shmem_getptr(shmem_id, &mut block);
    if rc < 0 || block.is_null() || (block as usize) & 63 != 0 {
        error(c"nurbs_interp: rtapi_shmem_getptr failed");
        return if rc < 0 { rc } else { -EINVAL };
    }
    // A block left by a previous instance (same key) is re-initialised: no planner is attached
    // before hal_ready.
    ptr::write_bytes(block as *mut u8, 0, Channel::SIZE);
    let channel = Channel::init(block as *mut u8);

    addr_of_mut!((*inst).channel).write(channel);
    addr_of_mut!((*inst).next_seq).write(0);
    addr_of_mut!((*inst).records).write(0);
    addr_of_mut!((*inst).underruns).write(0);
    addr_of_mut!((*inst).fault).write(false);

    let rc = sys::hal_export_funct(
        c"nurbs_interp.update".as_ptr(),
        Some(update),
        inst as *mut c_void,
        1,
        0,
        comp_id,
    );
    if rc < 0 {
        error(c"nurbs_interp: hal_export_funct failed");
        return rc;
    }
    0
}

/// RTAPI entry point, called by `loadrt nurbs_interp`.
///
/// # Safety
/// Called by rtapi_app once, from its main thread.
#[no_mangle]
pub unsafe extern "C" fn rtapi_app_main() -> c_int {
    let comp_id = sys::hal_init(NAME.as_ptr());
    if comp_id < 0 {
        error(c"nurbs_interp: hal_init failed");
        return comp_id;
    }
    COMP_ID.store(comp_id, Ordering::Relaxed);
    let rc = create(comp_id);
    if rc < 0 {
        rtapi_app_exit();
        return rc;
    }
    sys::hal_ready(comp_id)
}

/// RTAPI exit point, called by `unload nurbs_interp` after the function left every thread.
///
/// # Safety
/// Called by rtapi_app once, after `rtapi_app_main`.
#[no_mangle]
pub unsafe extern "C" fn rtapi_app_exit() {
    let comp_id = COMP_ID.swap(-1, Ordering::Relaxed);
    let shmem_id = SHMEM_ID.swap(-1, Ordering::Relaxed);
    if comp_id < 0 {
        return;
    }
    if shmem_id >= 0 {
        sys::rtapi_shmem_delete(shmem_id, comp_id);
    }
    sys::hal_exit(comp_id);
}
