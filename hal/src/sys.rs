//! The one place that chooses between LinuxCNC's C functions and the mock.
//!
//! Everything else in the crate calls HAL and RTAPI through this module. A normal build re-exports
//! the committed bindgen declarations; `cargo test` (or the `mock-hal` feature) re-exports the
//! Rust functions of the same names and signatures from [`crate::mock`].

use core::ffi::CStr;

pub use crate::bindings::{
    hal_pin_dir_t, hal_pin_dir_t_HAL_IN as HAL_IN, hal_pin_dir_t_HAL_IO as HAL_IO, hal_pin_dir_t_HAL_OUT as HAL_OUT,
    hal_stream_data, hal_stream_t, hal_type_t, hal_type_t_HAL_BIT as HAL_BIT, hal_type_t_HAL_FLOAT as HAL_FLOAT,
    hal_type_t_HAL_S32 as HAL_S32, hal_type_t_HAL_U32 as HAL_U32, msg_level_t,
    msg_level_t_RTAPI_MSG_ERR as RTAPI_MSG_ERR, msg_level_t_RTAPI_MSG_INFO as RTAPI_MSG_INFO,
    msg_level_t_RTAPI_MSG_WARN as RTAPI_MSG_WARN, real_t, HAL_NAME_LEN, HAL_STREAM_MAX_PINS,
};

#[cfg(not(any(test, feature = "mock-hal")))]
pub use crate::bindings::{
    hal_exit, hal_export_funct, hal_init, hal_malloc, hal_pin_bit_new, hal_pin_float_new, hal_pin_s32_new,
    hal_pin_u32_new, hal_ready, hal_stream_attach, hal_stream_detach, hal_stream_element_count,
    hal_stream_element_type, hal_stream_read, hal_stream_readable, rtapi_shmem_delete, rtapi_shmem_getptr,
    rtapi_shmem_new,
};

#[cfg(any(test, feature = "mock-hal"))]
pub use crate::mock::{
    hal_exit, hal_export_funct, hal_init, hal_malloc, hal_pin_bit_new, hal_pin_float_new, hal_pin_s32_new,
    hal_pin_u32_new, hal_ready, hal_stream_attach, hal_stream_detach, hal_stream_element_count,
    hal_stream_element_type, hal_stream_read, hal_stream_readable, rtapi_shmem_delete, rtapi_shmem_getptr,
    rtapi_shmem_new,
};

/// `rtapi_print_msg(level, "%s\n", msg)`. Not for the realtime path: it formats and writes.
pub fn print_msg(level: msg_level_t, msg: &CStr) {
    const FMT: &CStr = c"%s\n";
    #[cfg(not(any(test, feature = "mock-hal")))]
    // SAFETY: a constant format string with one `%s` and a NUL-terminated argument.
    unsafe {
        crate::bindings::rtapi_print_msg(level, FMT.as_ptr(), msg.as_ptr() as *const core::ffi::c_char)
    };
    #[cfg(any(test, feature = "mock-hal"))]
    crate::mock::print_msg(level, FMT, msg);
}
