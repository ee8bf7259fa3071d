//! Opening an MCAP bag (rosbag2 or ROS 1 profile) from memory, listing its topics and reading
//! (and decoding) every message.
#![no_main]
perturb_fuzz::capped_allocator!();

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    perturb_fuzz::read_bag("fuzz.mcap", data);
});
