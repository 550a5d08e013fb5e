//! The JSON records blurset reads (meta.json, splits.json, dataset.json, …) from
//! arbitrary bytes: the first byte picks the record, the rest is its file. A value or an
//! error, never a panic, and a value it gives has the record's shape.
#![no_main]
use blurset_core::{check_shape, parse_record, Record};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else {
        return;
    };
    let record = Record::ALL[pick as usize % Record::ALL.len()];
    if let Ok(value) = parse_record(bytes, record) {
        assert!(check_shape(&value, record).is_ok());
    }
});
