//! Opening an MCAP bag from memory, listing its topics and reading (and decoding) every message.
#![no_main]
perturb_fuzz::capped_allocator!();

use std::ops::ControlFlow;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Ok(bag) = perturb_bag::Bag::from_bytes("fuzz.mcap".as_ref(), data.to_vec()) else {
        return;
    };
    let _ = bag.topics();
    let _ = bag.for_each(&perturb_bag::Filter::default(), |m| {
        if let Some(Ok(msg)) = m.decode() {
            match msg {
                perturb_bag::SensorMessage::Image(i) => {
                    let _ = i.view();
                }
                perturb_bag::SensorMessage::Cloud(c) => {
                    let _ = c.view();
                }
                perturb_bag::SensorMessage::Compressed(_) => {}
            }
        }
        Ok(ControlFlow::Continue(()))
    });
});
