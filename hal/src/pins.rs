//! Typed HAL pins.
//!
//! A HAL pin is a pointer, kept in HAL shared memory, to the pin's value; `net` re-points it at
//! the signal's value while threads may be running. So the pointer lives in `hal_malloc`'d memory
//! (inside the component's instance struct), and every access reloads it: both loads are
//! volatile, as in C where the pin is `hal_float_t *` and the value `volatile double`.

// Reached from the update path: no unwrap, expect, panic or indexing that can fail.
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing)]

use core::cell::UnsafeCell;
use core::ffi::{c_int, CStr};
use core::ptr;

use crate::sys;

/// Pin types: the Rust value type and the `hal_pin_*_new` that makes the pin.
pub trait PinType: Copy {
    /// The C type HAL stores.
    type Raw: Copy;
    /// HAL's name of the type (`halcmd show pin`).
    const TYPE_NAME: &'static str;
    fn from_raw(raw: Self::Raw) -> Self;
    fn to_raw(self) -> Self::Raw;
    /// # Safety
    /// As `hal_pin_*_new`: `addr` in HAL shared memory, between `hal_init` and `hal_ready`.
    unsafe fn new_pin(name: &CStr, dir: sys::hal_pin_dir_t, addr: *mut *mut Self::Raw, comp_id: c_int) -> c_int;
}

impl PinType for f64 {
    type Raw = f64;
    const TYPE_NAME: &'static str = "float";
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
    const TYPE_NAME: &'static str = "bit";
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
    const TYPE_NAME: &'static str = "u32";
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
    const TYPE_NAME: &'static str = "s32";
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

/// Direction of a pin, as documented.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PinDir {
    In,
    Out,
}

impl PinDir {
    pub fn raw(self) -> sys::hal_pin_dir_t {
        match self {
            PinDir::In => sys::HAL_IN,
            PinDir::Out => sys::HAL_OUT,
        }
    }
}

/// A pin of a component as it is made and documented: the one source of its name (after the
/// component's prefix), HAL type, direction, unit and meaning.
#[derive(Clone, Copy, Debug)]
pub struct PinSpec {
    pub name: &'static str,
    pub kind: &'static str,
    pub dir: PinDir,
    pub unit: &'static str,
    pub doc: &'static str,
}

/// Declares a component's pins once: `struct $pins` with a typed [`Pin`] per field, the table
/// `$table` of [`PinSpec`]s (for the documentation and its tests) and `$pins::create`, which
/// makes every pin as `$prefix.name`. Each line: `field: type, In|Out, "name", "unit", "meaning";`.
#[macro_export]
macro_rules! declare_pins {
    ($prefix:literal, $pins:ident, $table:ident,
     $($field:ident: $ty:ty, $dir:ident, $name:literal, $unit:literal, $doc:literal;)*) => {
        /// The component's pins, in HAL shared memory ([`
        #[doc = stringify!($table)]
        /// `]).
        #[repr(C)]
        pub struct $pins {
            $(
                #[doc = $doc]
                pub $field: $crate::pins::Pin<$ty>,
            )*
        }

        /// Every pin of the component, in the order they are made.
        pub const $table: &[$crate::pins::PinSpec] = &[$(
            $crate::pins::PinSpec {
                name: $name,
                kind: <$ty as $crate::pins::PinType>::TYPE_NAME,
                dir: $crate::pins::PinDir::$dir,
                unit: $unit,
                doc: $doc,
            },
        )*];

        impl $pins {
            /// Makes every pin into `*this`; 0 or the first negative errno.
            ///
            /// # Safety
            /// `this` points into HAL shared memory (`hal_malloc`) and the call happens between
            /// `hal_init` and `hal_ready`.
            pub unsafe fn create(this: *mut $pins, comp_id: core::ffi::c_int) -> core::ffi::c_int {
                $(
                    // A name that is not a C string fails the build, not the module.
                    let name = const {
                        match core::ffi::CStr::from_bytes_with_nul(concat!($prefix, ".", $name, "\0").as_bytes()) {
                            Ok(name) => name,
                            Err(_) => panic!("a pin name holds a NUL"),
                        }
                    };
                    let rc = $crate::pins::Pin::create(
                        core::ptr::addr_of_mut!((*this).$field),
                        name,
                        $crate::pins::PinDir::$dir.raw(),
                        comp_id,
                    );
                    if rc < 0 {
                        return rc;
                    }
                )*
                0
            }
        }
    };
}
