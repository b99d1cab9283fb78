/work/main/hal/module/target/release/deps/nurbs_hal-0a58edc537546dd0.d: /work/main/hal/src/lib.rs /work/main/hal/src/channel.rs /work/main/hal/src/module/mod.rs /work/main/hal/src/module/blocks.rs /work/main/hal/src/module/geometry.rs /work/main/hal/src/module/segments.rs /work/main/hal/src/pins.rs /work/main/hal/src/slot.rs /work/main/hal/src/sys.rs /work/main/hal/src/bindings.rs

/work/main/hal/module/target/release/deps/libnurbs_hal-0a58edc537546dd0.rmeta: /work/main/hal/src/lib.rs /work/main/hal/src/channel.rs /work/main/hal/src/module/mod.rs /work/main/hal/src/module/blocks.rs /work/main/hal/src/module/geometry.rs /work/main/hal/src/module/segments.rs /work/main/hal/src/pins.rs /work/main/hal/src/slot.rs /work/main/hal/src/sys.rs /work/main/hal/src/bindings.rs

/work/main/hal/src/lib.rs:
/work/main/hal/src/channel.rs:
/work/main/hal/src/module/mod.rs:
/work/main/hal/src/module/blocks.rs:
/work/main/hal/src/module/geometry.rs:
/work/main/hal/src/module/segments.rs:
/work/main/hal/src/pins.rs:
/work/main/hal/src/slot.rs:
/work/main/hal/src/sys.rs:
/work/main/hal/src/bindings.rs:
