//! Shared pieces of the fuzz targets: an allocator that refuses absurd allocations, so a decoder
//! that would ask for gigabytes because a length field says so is caught as a crash (instead of
//! passing on a machine with enough memory to grant the request).

use std::alloc::{GlobalAlloc, Layout, System};

/// The largest single allocation a decoder may make while fuzzing. The inputs are at most a few
/// megabytes (`-max_len`); a decoder that asks for more than this from them trusted a length it
/// should have checked.
pub const MAX_ALLOCATION: usize = 1 << 30;

/// [`System`], aborting with a message on any allocation above [`MAX_ALLOCATION`].
pub struct Capped;

// SAFETY: forwards to `System`, only refusing (aborting on) oversized requests first.
unsafe impl GlobalAlloc for Capped {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        check(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        check(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        check(new_size);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

fn check(size: usize) {
    if size > MAX_ALLOCATION {
        // No allocation in here: write the message straight to stderr.
        let msg = b"perturb-fuzz: a decoder asked for more than 1 GiB in one allocation\n";
        // SAFETY: writing a static buffer to fd 2.
        unsafe {
            libc_write(2, msg.as_ptr(), msg.len());
        }
        std::process::abort();
    }
}

unsafe extern "C" {
    #[link_name = "write"]
    fn libc_write(fd: i32, buf: *const u8, count: usize) -> isize;
}

/// Installs [`Capped`] as the global allocator of a fuzz target.
#[macro_export]
macro_rules! capped_allocator {
    () => {
        #[global_allocator]
        static ALLOC: $crate::Capped = $crate::Capped;
    };
}

/// Opens `data` as a bag (MCAP or ROS 1, told by its first bytes), lists its topics and reads
/// and decodes every message; errors and damage are expected, crashes and huge allocations are
/// not.
pub fn read_bag(name: &str, data: &[u8]) {
    use std::ops::ControlFlow;
    let Ok(bag) = perturb_bag::Bag::from_bytes(name.as_ref(), data.to_vec()) else {
        return;
    };
    let _ = bag.topics();
    let _ = bag.for_each(&perturb_bag::Filter::default(), |m| {
        let _ = m.header_seq();
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
}
