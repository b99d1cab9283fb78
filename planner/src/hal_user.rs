//! Userspace side: what `nurbs-planner` (and the test recorder) need from HAL.
//!
//! These run in ordinary processes (`loadusr`), so they may allocate, sleep and report errors as
//! strings; nothing here is called from a realtime thread.

use core::ffi::{c_int, c_void};
use core::ptr;
use std::ffi::CString;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nurbs_hal::channel::{Channel, CHANNEL_KEY};
use nurbs_hal::pins::{Pin, PinType};
use nurbs_hal::sys;

/// A HAL userspace component: `hal_init` on creation, `hal_exit` on drop (after releasing its
/// reference to the channel's shared memory, so that the block is removed with the module).
pub struct Component {
    id: c_int,
    name: String,
    /// The channel's RTAPI shared-memory id, once attached.
    shmem: std::cell::Cell<Option<c_int>>,
}

impl Component {
    pub fn new(name: &str) -> Result<Component, String> {
        let c_name = CString::new(name).map_err(|e| e.to_string())?;
        // SAFETY: NUL-terminated name.
        let id = unsafe { sys::hal_init(c_name.as_ptr()) };
        if id < 0 {
            return Err(format!("hal_init({name}) failed: {id}"));
        }
        Ok(Component {
            id,
            name: name.to_owned(),
            shmem: std::cell::Cell::new(None),
        })
    }

    pub fn id(&self) -> c_int {
        self.id
    }

    /// A pin `<component>.<suffix>` whose pointer lives in HAL shared memory.
    pub fn pin<T: PinType>(&self, suffix: &str, dir: sys::hal_pin_dir_t) -> Result<&'static Pin<T>, String> {
        let full = format!("{}.{}", self.name, suffix);
        let c_name = CString::new(full.as_str()).map_err(|e| e.to_string())?;
        // SAFETY: hal_malloc'd storage for one pointer; the pin is created before hal_ready.
        unsafe {
            let slot = sys::hal_malloc(core::mem::size_of::<Pin<T>>() as _) as *mut Pin<T>;
            if slot.is_null() {
                return Err(format!("hal_malloc for {full} failed"));
            }
            let rc = Pin::create(slot, &c_name, dir, self.id);
            if rc < 0 {
                return Err(format!("pin {full}: {rc}"));
            }
            // HAL memory outlives the component's use of it (released by hal_exit at the end).
            Ok(&*slot)
        }
    }

    pub fn ready(&self) -> Result<(), String> {
        // SAFETY: valid component id.
        let rc = unsafe { sys::hal_ready(self.id) };
        if rc < 0 {
            Err(format!("hal_ready failed: {rc}"))
        } else {
            Ok(())
        }
    }

    /// Attach to the realtime module's channel, waiting up to `timeout` for it to appear.
    pub fn attach_channel(&self, timeout: Duration) -> Result<&'static Channel, String> {
        let start = Instant::now();
        loop {
            // SAFETY: same key and size as the creator; the block stays mapped until the
            // reference is released (drop).
            let result = unsafe {
                let id = sys::rtapi_shmem_new(CHANNEL_KEY, self.id, Channel::SIZE as _);
                if id < 0 {
                    Err(format!("rtapi_shmem_new: {id} (is nurbs_interp loaded?)"))
                } else {
                    let mut p: *mut c_void = ptr::null_mut();
                    let rc = sys::rtapi_shmem_getptr(id, &mut p);
                    let attached = if rc < 0 || p.is_null() {
                        Err(format!("rtapi_shmem_getptr: {rc}"))
                    } else {
                        Channel::attach(p as *const u8).map_err(|e| format!("channel: {e:?}"))
                    };
                    match attached {
                        Ok(c) => {
                            self.shmem.set(Some(id));
                            Ok(c)
                        }
                        Err(e) => {
                            // Every rtapi_shmem_new counts a reference: give this one back.
                            sys::rtapi_shmem_delete(id, self.id);
                            Err(e)
                        }
                    }
                }
            };
            match result {
                Ok(c) => return Ok(c),
                Err(e) if start.elapsed() >= timeout => return Err(e),
                Err(_) => std::thread::sleep(Duration::from_millis(10)),
            }
        }
    }
}

impl Drop for Component {
    fn drop(&mut self) {
        // SAFETY: valid ids; the channel is not used after this (its users borrow the
        // component). hal_exit frees the pins.
        unsafe {
            if let Some(shmem) = self.shmem.take() {
                sys::rtapi_shmem_delete(shmem, self.id);
            }
            sys::hal_exit(self.id)
        };
    }
}

/// Set by SIGTERM/SIGINT; polled by the userspace main loops.
pub static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Route SIGTERM (what `halcmd unload` sends) and SIGINT to [`STOP`].
pub fn install_signal_handlers() {
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
    }
}

pub fn stopped() -> bool {
    STOP.load(Ordering::SeqCst)
}

/// One value of a `hal_stream` sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StreamValue {
    Float(f64),
    Bit(bool),
    U32(u32),
    S32(i32),
}

/// Reader of a `hal_stream` made by another component (e.g. LinuxCNC's `sampler`).
pub struct StreamReader {
    stream: sys::hal_stream_t,
    types: Vec<sys::hal_type_t>,
}

impl StreamReader {
    /// `hal_stream_attach(key)` accepting whatever element types the creator chose.
    pub fn attach(comp: &Component, key: c_int) -> Result<StreamReader, String> {
        // SAFETY: hal_stream_t is plain data that hal_stream_attach fills in.
        unsafe {
            let mut stream: sys::hal_stream_t = core::mem::zeroed();
            let rc = sys::hal_stream_attach(&mut stream, comp.id(), key, ptr::null());
            if rc < 0 {
                return Err(format!("hal_stream_attach({key:#x}): {rc}"));
            }
            let n = sys::hal_stream_element_count(&mut stream).max(0);
            let types = (0..n).map(|i| sys::hal_stream_element_type(&mut stream, i)).collect();
            Ok(StreamReader { stream, types })
        }
    }

    /// Next sample and its sample number, or None when the stream is empty.
    pub fn read(&mut self) -> Result<Option<(u32, Vec<StreamValue>)>, String> {
        // SAFETY: attached stream; the buffer holds one value per element.
        unsafe {
            if !sys::hal_stream_readable(&mut self.stream) {
                return Ok(None);
            }
            let mut buf: Vec<sys::hal_stream_data> = vec![sys::hal_stream_data { u: 0 }; self.types.len().max(1)];
            let mut sampleno: u32 = 0;
            let rc = sys::hal_stream_read(&mut self.stream, buf.as_mut_ptr(), &mut sampleno);
            if rc < 0 {
                return Err(format!("hal_stream_read: {rc}"));
            }
            let values = self
                .types
                .iter()
                .zip(&buf)
                .map(|(&t, v)| match t {
                    sys::HAL_FLOAT => StreamValue::Float(v.f),
                    sys::HAL_BIT => StreamValue::Bit(ptr::read(&v.u as *const u32 as *const u8) != 0),
                    sys::HAL_U32 => StreamValue::U32(v.u),
                    _ => StreamValue::S32(v.s),
                })
                .collect();
            Ok(Some((sampleno, values)))
        }
    }
}

impl Drop for StreamReader {
    fn drop(&mut self) {
        // SAFETY: attached stream.
        unsafe { sys::hal_stream_detach(&mut self.stream) };
    }
}

/// `CStr` helper for messages built at run time (userspace only).
pub fn c_message(s: &str) -> CString {
    CString::new(s.replace('\0', " ")).unwrap_or_default()
}
