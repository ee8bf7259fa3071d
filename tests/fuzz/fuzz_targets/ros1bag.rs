//! Opening a ROS 1 `.bag` (format 2.0) from memory, listing its topics and reading (and
//! decoding) every message, through the index and, for an unindexed bag, in file order.
#![no_main]
perturb_fuzz::capped_allocator!();

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    perturb_fuzz::read_bag("fuzz.bag", data);
});
