//! Reuse of finished frames' f32 buffers.

/// Finished frames' f32 buffers, kept for the next frames: a frame's intermediate images are
/// tens of megabytes, and memory fresh from the system costs a page fault and a zeroing per 4 KiB
/// page on every frame (measured: a k = 25 Gaussian at 2.3 MP takes 40 ms on fresh pages, 18 ms on
/// reused ones). At most [`SPARE_BUFFERS`] are kept.
static SPARE: std::sync::Mutex<Vec<Vec<f32>>> = std::sync::Mutex::new(Vec::new());

/// How many finished buffers [`frame_buffer`] keeps for reuse.
const SPARE_BUFFERS: usize = 8;

/// A zeroed buffer of `len` samples, reusing a finished frame's buffer when one is large enough.
pub fn frame_buffer(len: usize) -> Vec<f32> {
    let reused = SPARE.lock().ok().and_then(|mut spare| {
        let i = spare.iter().position(|b| b.capacity() >= len)?;
        Some(spare.swap_remove(i))
    });
    match reused {
        Some(mut b) => {
            b.clear();
            b.resize(len, 0.0);
            b
        }
        None => vec![0f32; len],
    }
}

/// A buffer of `len` samples for a caller that overwrites every one of them: a finished frame's
/// buffer is reused as it is (its old samples left in place), saving the zeroing of
/// [`frame_buffer`].
pub fn frame_buffer_overwritten(len: usize) -> Vec<f32> {
    let reused = SPARE.lock().ok().and_then(|mut spare| {
        let i = spare.iter().position(|b| b.capacity() >= len)?;
        Some(spare.swap_remove(i))
    });
    match reused {
        Some(mut b) => {
            b.truncate(len);
            b.resize(len, 0.0);
            b
        }
        None => vec![0f32; len],
    }
}

/// Hands a buffer back for [`frame_buffer`] to reuse (small ones are simply freed; when the spare
/// list is full the smallest buffer goes).
pub fn recycle(buffer: Vec<f32>) {
    if buffer.capacity() < 1 << 16 {
        return;
    }
    if let Ok(mut spare) = SPARE.lock() {
        spare.push(buffer);
        if spare.len() > SPARE_BUFFERS {
            let smallest = (0..spare.len())
                .min_by_key(|&i| spare[i].capacity())
                .unwrap_or(0);
            spare.swap_remove(smallest);
        }
    }
}
