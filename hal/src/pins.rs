//! Typed HAL pins.
//!
//! A HAL pin is a pointer, kept in HAL shared memory, to the pin's value; `net` re-points it at
//! the signal's value while threads may be running. So the pointer lives in `hal_malloc`'d memory
//! (inside the component's instance struct), and every access reloads it: both loads are
//! volatile, as in C where the pin is `hal_float_t *` and the value `volatile double`.

use core::cell::UnsafeCell;
use core::ffi::{c_int, CStr};
use core::ptr;

use crate::sys;

/// Pin types: the Rust value type and the `hal_pin_*_new` that makes the pin.
pub trait PinType: Copy {
    /// The C type HAL stores.
    type Raw: Copy;
    fn from_raw(raw: Self::Raw) -> Self;
    fn to_raw(self) -> Self::Raw;
    /// # Safety
    /// As `hal_pin_*_new`: `addr` in HAL shared memory, between `hal_init` and `hal_ready`.
    unsafe fn new_pin(name: &CStr, dir: sys::hal_pin_dir_t, addr: *mut *mut Self::Raw, comp_id: c_int) -> c_int;
}

impl PinType for f64 {
    type Raw = f64;
    fn from_raw(raw: f64) -> f64 {
        raw
    }
    fn to_raw(self) -> f64 {
        self
    }
    unsafe fn new_pin(name: &CStr, dir: sys::hal_pin_dir_t, addr: *mut *mut f64, comp_id: c_int) -> c_int {
        sys::hal_pin_float_new(name.as_ptr(), dir, addr, comp_id)
    }
}

/// HAL bits are C `bool`; read them as a byte so a stray value cannot make an invalid Rust bool.
impl PinType for bool {
    type Raw = u8;
    fn from_raw(raw: u8) -> bool {
        raw != 0
    }
    fn to_raw(self) -> u8 {
        self as u8
    }
    unsafe fn new_pin(name: &CStr, dir: sys::hal_pin_dir_t, addr: *mut *mut u8, comp_id: c_int) -> c_int {
        sys::hal_pin_bit_new(name.as_ptr(), dir, addr as *mut *mut bool, comp_id)
    }
}

impl PinType for u32 {
    type Raw = u32;
    fn from_raw(raw: u32) -> u32 {
        raw
    }
    fn to_raw(self) -> u32 {
        self
    }
    unsafe fn new_pin(name: &CStr, dir: sys::hal_pin_dir_t, addr: *mut *mut u32, comp_id: c_int) -> c_int {
        sys::hal_pin_u32_new(name.as_ptr(), dir, addr, comp_id)
    }
}

impl PinType for i32 {
    type Raw = i32;
    fn from_raw(raw: i32) -> i32 {
        raw
    }
    fn to_raw(self) -> i32 {
        self
    }
    unsafe fn new_pin(name: &CStr, dir: sys::hal_pin_dir_t, addr: *mut *mut i32, comp_id: c_int) -> c_int {
        sys::hal_pin_s32_new(name.as_ptr(), dir, addr, comp_id)
    }
}

/// One pin: the HAL-owned pointer to its value. Lives in `hal_malloc`'d memory.
#[repr(transparent)]
pub struct Pin<T: PinType> {
    value: UnsafeCell<*mut T::Raw>,
}

impl<T: PinType> Pin<T> {
    /// Create the pin `name` on component `comp_id`, writing its pointer into `*this`.
    ///
    /// # Safety
    /// `this` points into HAL shared memory (`hal_malloc`) and the call happens between
    /// `hal_init` and `hal_ready`.
    pub unsafe fn create(this: *mut Pin<T>, name: &CStr, dir: sys::hal_pin_dir_t, comp_id: c_int) -> c_int {
        T::new_pin(name, dir, this as *mut *mut T::Raw, comp_id)
    }

    /// Current value (reloads the pointer, then the value).
    #[inline]
    pub fn get(&self) -> T {
        // SAFETY: after a successful `create` HAL keeps the pointer valid while the component
        // exists; HAL itself may rewrite it (net/unlinkp), hence the volatile reloads.
        unsafe { T::from_raw(ptr::read_volatile(ptr::read_volatile(self.value.get()) as *const T::Raw)) }
    }

    #[inline]
    pub fn set(&self, v: T) {
        // SAFETY: as in `get`.
        unsafe { ptr::write_volatile(ptr::read_volatile(self.value.get()), v.to_raw()) }
    }
}
