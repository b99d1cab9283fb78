//! `nurbs_interp.so`'s contents: the realtime module of `nurbs-hal` (its exported
//! `rtapi_app_main` and `rtapi_app_exit`), built `no_std` without `alloc`. The Makefile links
//! this staticlib whole into the shared object that `loadrt nurbs_interp` dlopens.
#![no_std]

pub use nurbs_hal::module::{rtapi_app_exit, rtapi_app_main};

/// Nothing on the servo thread panics (no indexing that can fail, no unwrap); were it to, the
/// module ends rtapi_app rather than unwind into C.
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    extern "C" {
        fn abort() -> !;
    }
    // SAFETY: libc's abort takes no arguments and does not return.
    unsafe { abort() }
}
