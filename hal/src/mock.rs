//! In-process stand-in for LinuxCNC's HAL and RTAPI (`cargo test`, or the `mock-hal` feature).
//!
//! Same names and signatures as the bindgen declarations in [`crate::bindings`], selected by
//! [`crate::sys`], so the module code under test is the code that ships. The state is per thread:
//! each test thread is its own HAL, and a test that plays both the realtime module and the
//! planner does so from one thread (shared-memory blocks with the same key are shared, as in
//! RTAPI). Test helpers at the bottom read and write pins by name and call exported functions
//! the way a HAL thread does.
//!
//! The `unsafe extern "C"` functions have the safety contracts of the C functions they stand in
//! for (valid, NUL-terminated names; valid out-pointers).
#![allow(clippy::missing_safety_doc)]

use core::ffi::{c_char, c_int, c_long, c_uint, c_ulong, c_void, CStr};
use std::cell::RefCell;
use std::collections::VecDeque;

use crate::bindings::{hal_pin_dir_t, hal_stream_data, hal_stream_t, hal_type_t, msg_level_t, real_t};
use crate::sys::{HAL_BIT, HAL_FLOAT, HAL_S32, HAL_U32};

const EINVAL: c_int = 22;
const ENOENT: c_int = 2;
const EEXIST: c_int = 17;
const ENOSPC: c_int = 28;

type Funct = unsafe extern "C" fn(*mut c_void, c_long);

/// 64-byte aligned storage unit (RTAPI blocks are page aligned; our layouts want 64).
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Line([u8; 64]);

fn lines(size: usize) -> Box<[Line]> {
    vec![Line([0; 64]); size.div_ceil(64).max(1)].into_boxed_slice()
}

struct Comp {
    id: c_int,
    name: String,
    ready: bool,
}

struct MockPin {
    name: String,
    ty: hal_type_t,
    dir: hal_pin_dir_t,
    comp: c_int,
    /// The pin's own value (HAL's `dummysig`), 8 bytes, zero initially.
    value: Box<u64>,
}

struct Exported {
    name: String,
    funct: Funct,
    arg: *mut c_void,
    comp: c_int,
}

struct Block {
    key: c_int,
    size: usize,
    data: Box<[Line]>,
}

struct Stream {
    key: c_int,
    types: Vec<hal_type_t>,
    samples: VecDeque<(u32, Vec<hal_stream_data>)>,
    next_sample: u32,
}

#[derive(Default)]
struct State {
    next_id: c_int,
    comps: Vec<Comp>,
    pins: Vec<MockPin>,
    functs: Vec<Exported>,
    hal_memory: Vec<Box<[Line]>>,
    blocks: Vec<Block>,
    /// shmem id -> index into `blocks`
    shmem_ids: Vec<(c_int, usize)>,
    streams: Vec<Stream>,
    messages: Vec<(msg_level_t, String)>,
}

thread_local! {
    static STATE: RefCell<State> = RefCell::new(State { next_id: 1, ..State::default() });
}

fn with<R>(f: impl FnOnce(&mut State) -> R) -> R {
    STATE.with(|s| f(&mut s.borrow_mut()))
}

unsafe fn name_of(name: *const c_char) -> Option<String> {
    if name.is_null() {
        return None;
    }
    CStr::from_ptr(name).to_str().ok().map(str::to_owned)
}

pub unsafe extern "C" fn hal_init(name: *const c_char) -> c_int {
    let Some(name) = name_of(name) else {
        return -EINVAL;
    };
    with(|s| {
        if s.comps.iter().any(|c| c.name == name) {
            return -EEXIST;
        }
        let id = s.next_id;
        s.next_id += 1;
        s.comps.push(Comp { id, name, ready: false });
        id
    })
}

pub unsafe extern "C" fn hal_ready(comp_id: c_int) -> c_int {
    with(|s| match s.comps.iter_mut().find(|c| c.id == comp_id) {
        Some(c) => {
            c.ready = true;
            0
        }
        None => -EINVAL,
    })
}

pub unsafe extern "C" fn hal_exit(comp_id: c_int) -> c_int {
    with(|s| {
        let Some(i) = s.comps.iter().position(|c| c.id == comp_id) else {
            return -EINVAL;
        };
        s.comps.remove(i);
        s.pins.retain(|p| p.comp != comp_id);
        s.functs.retain(|f| f.comp != comp_id);
        0
    })
}

/// HAL memory is never freed while HAL runs (as in LinuxCNC); `reset` drops it.
pub unsafe extern "C" fn hal_malloc(size: c_long) -> *mut c_void {
    if size <= 0 {
        return core::ptr::null_mut();
    }
    with(|s| {
        let mut block = lines(size as usize);
        let p = block.as_mut_ptr() as *mut c_void;
        s.hal_memory.push(block);
        p
    })
}

unsafe fn pin_new(
    name: *const c_char,
    ty: hal_type_t,
    dir: hal_pin_dir_t,
    addr: *mut *mut c_void,
    comp: c_int,
) -> c_int {
    let Some(name) = name_of(name) else {
        return -EINVAL;
    };
    if addr.is_null() {
        return -EINVAL;
    }
    with(|s| {
        if !s.comps.iter().any(|c| c.id == comp && !c.ready) {
            return -EINVAL;
        }
        if s.pins.iter().any(|p| p.name == name) {
            return -EEXIST;
        }
        let mut value = Box::new(0u64);
        *addr = &mut *value as *mut u64 as *mut c_void;
        s.pins.push(MockPin {
            name,
            ty,
            dir,
            comp,
            value,
        });
        0
    })
}

pub unsafe extern "C" fn hal_pin_bit_new(
    name: *const c_char,
    dir: hal_pin_dir_t,
    addr: *mut *mut bool,
    comp: c_int,
) -> c_int {
    pin_new(name, HAL_BIT, dir, addr as *mut *mut c_void, comp)
}

pub unsafe extern "C" fn hal_pin_float_new(
    name: *const c_char,
    dir: hal_pin_dir_t,
    addr: *mut *mut real_t,
    comp: c_int,
) -> c_int {
    pin_new(name, HAL_FLOAT, dir, addr as *mut *mut c_void, comp)
}

pub unsafe extern "C" fn hal_pin_u32_new(
    name: *const c_char,
    dir: hal_pin_dir_t,
    addr: *mut *mut u32,
    comp: c_int,
) -> c_int {
    pin_new(name, HAL_U32, dir, addr as *mut *mut c_void, comp)
}

pub unsafe extern "C" fn hal_pin_s32_new(
    name: *const c_char,
    dir: hal_pin_dir_t,
    addr: *mut *mut i32,
    comp: c_int,
) -> c_int {
    pin_new(name, HAL_S32, dir, addr as *mut *mut c_void, comp)
}

pub unsafe extern "C" fn hal_export_funct(
    name: *const c_char,
    funct: Option<Funct>,
    arg: *mut c_void,
    _uses_fp: c_int,
    _reentrant: c_int,
    comp: c_int,
) -> c_int {
    let (Some(name), Some(funct)) = (name_of(name), funct) else {
        return -EINVAL;
    };
    with(|s| {
        if s.functs.iter().any(|f| f.name == name) {
            return -EEXIST;
        }
        s.functs.push(Exported { name, funct, arg, comp });
        0
    })
}

pub unsafe extern "C" fn rtapi_shmem_new(key: c_int, module_id: c_int, size: c_ulong) -> c_int {
    if key == 0 || size == 0 {
        return -EINVAL;
    }
    let size = size as usize;
    with(|s| {
        if !s.comps.iter().any(|c| c.id == module_id) {
            return -EINVAL;
        }
        let index = match s.blocks.iter().position(|b| b.key == key) {
            Some(i) if s.blocks.get(i).is_some_and(|b| b.size < size) => return -EINVAL,
            Some(i) => i,
            None => {
                s.blocks.push(Block {
                    key,
                    size,
                    data: lines(size),
                });
                s.blocks.len() - 1
            }
        };
        let id = s.next_id;
        s.next_id += 1;
        s.shmem_ids.push((id, index));
        id
    })
}

pub unsafe extern "C" fn rtapi_shmem_getptr(shmem_id: c_int, ptr: *mut *mut c_void) -> c_int {
    with(|s| {
        let Some(&(_, index)) = s.shmem_ids.iter().find(|(id, _)| *id == shmem_id) else {
            return -EINVAL;
        };
        match s.blocks.get_mut(index) {
            Some(b) if !ptr.is_null() => {
                *ptr = b.data.as_mut_ptr() as *mut c_void;
                0
            }
            _ => -EINVAL,
        }
    })
}

/// Releases the id; the block itself stays (so pointers held by other parties stay valid).
pub unsafe extern "C" fn rtapi_shmem_delete(shmem_id: c_int, _module_id: c_int) -> c_int {
    with(|s| match s.shmem_ids.iter().position(|(id, _)| *id == shmem_id) {
        Some(i) => {
            s.shmem_ids.remove(i);
            0
        }
        None => -EINVAL,
    })
}

/// `rtapi_print_msg(level, "%s\n", msg)` (the only form the crate uses).
pub fn print_msg(level: msg_level_t, _fmt: &CStr, msg: &CStr) {
    let text = msg.to_string_lossy().into_owned();
    with(|s| s.messages.push((level, text)));
}

// hal_stream: the mock streams are made by `stream_create` (a test playing e.g. `sampler`).
// `hal_stream_t::shmem_id` carries the key.

unsafe fn stream_key(stream: *mut hal_stream_t) -> Option<c_int> {
    stream.as_ref().map(|s| s.shmem_id)
}

pub unsafe extern "C" fn hal_stream_attach(
    stream: *mut hal_stream_t,
    comp: c_int,
    key: c_int,
    _types: *const c_char,
) -> c_int {
    let Some(out) = stream.as_mut() else {
        return -EINVAL;
    };
    with(|s| {
        if !s.streams.iter().any(|st| st.key == key) {
            return -ENOENT;
        }
        out.comp_id = comp;
        out.shmem_id = key;
        out.fifo = core::ptr::null_mut();
        0
    })
}

pub unsafe extern "C" fn hal_stream_detach(stream: *mut hal_stream_t) -> c_int {
    if stream.is_null() {
        -EINVAL
    } else {
        0
    }
}

pub unsafe extern "C" fn hal_stream_element_count(stream: *mut hal_stream_t) -> c_int {
    let key = stream_key(stream);
    with(|s| {
        s.streams
            .iter()
            .find(|st| Some(st.key) == key)
            .map_or(-EINVAL, |st| st.types.len() as c_int)
    })
}

pub unsafe extern "C" fn hal_stream_element_type(stream: *mut hal_stream_t, idx: c_int) -> hal_type_t {
    let key = stream_key(stream);
    with(|s| {
        s.streams
            .iter()
            .find(|st| Some(st.key) == key)
            .and_then(|st| st.types.get(idx as usize).copied())
            .unwrap_or(-1)
    })
}

pub unsafe extern "C" fn hal_stream_readable(stream: *mut hal_stream_t) -> bool {
    let key = stream_key(stream);
    with(|s| s.streams.iter().any(|st| Some(st.key) == key && !st.samples.is_empty()))
}

pub unsafe extern "C" fn hal_stream_read(
    stream: *mut hal_stream_t,
    buf: *mut hal_stream_data,
    sampleno: *mut c_uint,
) -> c_int {
    let key = stream_key(stream);
    with(|s| {
        let Some(st) = s.streams.iter_mut().find(|st| Some(st.key) == key) else {
            return -EINVAL;
        };
        let Some((n, values)) = st.samples.pop_front() else {
            return -ENOSPC;
        };
        for (i, v) in values.iter().enumerate() {
            *buf.add(i) = *v;
        }
        if !sampleno.is_null() {
            *sampleno = n;
        }
        0
    })
}

// ---- test helpers ----------------------------------------------------------------------------

/// A pin value as a test sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    Bit(bool),
    Float(f64),
    U32(u32),
    S32(i32),
}

/// Forget every component, pin, function, block and message of this thread's HAL.
pub fn reset() {
    with(|s| {
        *s = State {
            next_id: 1,
            ..State::default()
        }
    });
}

pub fn component_ready(name: &str) -> Option<bool> {
    with(|s| s.comps.iter().find(|c| c.name == name).map(|c| c.ready))
}

pub fn pin_names() -> Vec<String> {
    with(|s| s.pins.iter().map(|p| p.name.clone()).collect())
}

pub fn pin_dir(name: &str) -> Option<hal_pin_dir_t> {
    with(|s| s.pins.iter().find(|p| p.name == name).map(|p| p.dir))
}

/// Read a pin's value (its own storage: the mock has no signals).
pub fn pin(name: &str) -> Option<Value> {
    with(|s| {
        let p = s.pins.iter().find(|p| p.name == name)?;
        let ptr = &*p.value as *const u64;
        // SAFETY: 8 valid bytes owned by the pin.
        unsafe {
            Some(match p.ty {
                HAL_BIT => Value::Bit(*(ptr as *const u8) != 0),
                HAL_FLOAT => Value::Float(*(ptr as *const f64)),
                HAL_U32 => Value::U32(*(ptr as *const u32)),
                _ => Value::S32(*(ptr as *const i32)),
            })
        }
    })
}

/// Write a pin's value (as `setp` does); false if there is no such pin or the type differs.
pub fn set_pin(name: &str, value: Value) -> bool {
    with(|s| {
        let Some(p) = s.pins.iter_mut().find(|p| p.name == name) else {
            return false;
        };
        let ptr = &mut *p.value as *mut u64;
        // SAFETY: 8 valid bytes owned by the pin.
        unsafe {
            match (p.ty, value) {
                (HAL_BIT, Value::Bit(v)) => *(ptr as *mut u8) = v as u8,
                (HAL_FLOAT, Value::Float(v)) => *(ptr as *mut f64) = v,
                (HAL_U32, Value::U32(v)) => *(ptr as *mut u32) = v,
                (HAL_S32, Value::S32(v)) => *(ptr as *mut i32) = v,
                _ => return false,
            }
        }
        true
    })
}

/// The exported function `name`, to be called with [`call`] (looked up once, outside the loop,
/// so that the calls themselves allocate nothing).
pub fn funct(name: &str) -> Option<(Funct, *mut c_void)> {
    with(|s| s.functs.iter().find(|f| f.name == name).map(|f| (f.funct, f.arg)))
}

/// Run an exported function for one period, as a HAL thread does.
///
/// # Safety
/// `f` comes from [`funct`] and its component still exists.
pub unsafe fn call(f: (Funct, *mut c_void), period_ns: c_long) {
    (f.0)(f.1, period_ns)
}

pub fn messages() -> Vec<(msg_level_t, String)> {
    with(|s| s.messages.clone())
}

/// Create a stream as its realtime creator would (e.g. `sampler` with `cfg`).
pub fn stream_create(key: c_int, types: &[hal_type_t]) {
    with(|s| {
        s.streams.push(Stream {
            key,
            types: types.to_vec(),
            samples: VecDeque::new(),
            next_sample: 1,
        })
    });
}

/// Append one sample to a mock stream.
pub fn stream_write(key: c_int, values: &[hal_stream_data]) -> bool {
    with(|s| {
        let Some(st) = s.streams.iter_mut().find(|st| st.key == key) else {
            return false;
        };
        if values.len() != st.types.len() {
            return false;
        }
        st.samples.push_back((st.next_sample, values.to_vec()));
        st.next_sample = st.next_sample.wrapping_add(1);
        true
    })
}
