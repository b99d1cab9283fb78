/work/main/hal/module/target/release/deps/nurbs_interp-3858f39a720abc22.d: src/lib.rs Cargo.toml

/work/main/hal/module/target/release/deps/libnurbs_interp-3858f39a720abc22.rmeta: src/lib.rs Cargo.toml

src/lib.rs:
Cargo.toml:

# env-dep:CLIPPY_ARGS=-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__
# env-dep:CLIPPY_CONF_DIR
