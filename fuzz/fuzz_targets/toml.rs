#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    hirad_fuzz::fuzz_one(hirad_fuzz::Target::Toml, data);
});
