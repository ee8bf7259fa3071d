//! The daemon's and the bridge's TOML configurations (parse and validate; the first byte picks
//! which). Validation of a bridge file opens nothing (no bag, no DDS participant).
#![no_main]
perturb_fuzz::capped_allocator!();

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&which, text)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(text) else {
        return;
    };
    if which % 2 == 0 {
        let _ = perturbd::Config::parse(text);
    } else {
        let _ = perturb_bridge::config::Config::parse(text, "fuzz.toml");
    }
});
