//! The recorder's reader of LinuxCNC sampler streams, on the mock HAL.

use nurbs_hal::{mock, sys};
use nurbs_planner::hal_user::{Component, StreamReader, StreamValue};

#[test]
fn stream_reader_reads_a_sampler_like_stream() {
    mock::reset();
    let comp = Component::new("recorder").unwrap();
    let key = 0x4853_4130;
    mock::stream_create(key, &[sys::HAL_FLOAT, sys::HAL_BIT, sys::HAL_U32]);
    let mut reader = StreamReader::attach(&comp, key).unwrap();
    assert_eq!(reader.read(), Ok(None));
    let x = 1.0 / 3.0;
    assert!(mock::stream_write(
        key,
        &[
            sys::hal_stream_data { f: x },
            sys::hal_stream_data { u: 1 },
            sys::hal_stream_data { u: 7 }
        ]
    ));
    let (n, values) = reader.read().unwrap().unwrap();
    assert_eq!(n, 1);
    assert_eq!(
        values,
        vec![StreamValue::Float(x), StreamValue::Bit(true), StreamValue::U32(7)]
    );
}
