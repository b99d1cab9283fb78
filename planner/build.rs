//! Link the userspace binaries against LinuxCNC's HAL library (with the `linuxcnc` feature,
//! unless the mock HAL replaces it). Only the binaries: the realtime module, built from
//! another crate, resolves `hal_*` from `hal_lib.so` and `rtapi_*` from `rtapi_app` when
//! rtapi_app dlopens it and must carry no link to liblinuxcnchal.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var_os("CARGO_FEATURE_LINUXCNC").is_some() && std::env::var_os("CARGO_FEATURE_MOCK_HAL").is_none() {
        println!("cargo:rustc-link-arg-bins=-llinuxcnchal");
    }
}
