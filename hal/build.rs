//! Link the userspace binaries (never the realtime module) against LinuxCNC's HAL library.
//!
//! The realtime module resolves `hal_*` from `hal_lib.so` and `rtapi_*` from `rtapi_app` when
//! rtapi_app dlopens it, so the staticlib must carry no link to liblinuxcnchal: hence
//! `rustc-link-arg-bins` and not `rustc-link-lib`.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var_os("CARGO_FEATURE_LINUXCNC").is_some() && std::env::var_os("CARGO_FEATURE_MOCK_HAL").is_none() {
        println!("cargo:rustc-link-arg-bins=-llinuxcnchal");
    }
}
