/work/main/hal/module/target/release/deps/nurbs_rtcore-a7d5d4141d728211.d: /work/main/rtcore/src/lib.rs /work/main/rtcore/src/block_stop.rs /work/main/rtcore/src/handover.rs /work/main/rtcore/src/interpolator.rs /work/main/rtcore/src/math.rs /work/main/rtcore/src/nurbs.rs /work/main/rtcore/src/records.rs /work/main/rtcore/src/scurve.rs /work/main/rtcore/src/span_cache.rs /work/main/rtcore/src/step_methods.rs

/work/main/hal/module/target/release/deps/libnurbs_rtcore-a7d5d4141d728211.rmeta: /work/main/rtcore/src/lib.rs /work/main/rtcore/src/block_stop.rs /work/main/rtcore/src/handover.rs /work/main/rtcore/src/interpolator.rs /work/main/rtcore/src/math.rs /work/main/rtcore/src/nurbs.rs /work/main/rtcore/src/records.rs /work/main/rtcore/src/scurve.rs /work/main/rtcore/src/span_cache.rs /work/main/rtcore/src/step_methods.rs

/work/main/rtcore/src/lib.rs:
/work/main/rtcore/src/block_stop.rs:
/work/main/rtcore/src/handover.rs:
/work/main/rtcore/src/interpolator.rs:
/work/main/rtcore/src/math.rs:
/work/main/rtcore/src/nurbs.rs:
/work/main/rtcore/src/records.rs:
/work/main/rtcore/src/scurve.rs:
/work/main/rtcore/src/span_cache.rs:
/work/main/rtcore/src/step_methods.rs:
