//! Row-parallel iteration over a frame and the deterministic per-row random streams.

use crate::image::{ImageView, ImageViewMut};
use crate::rng::Rng;
use rayon::prelude::*;

/// Rows handed to one rayon task; large enough that scheduling is negligible.
const ROWS_PER_TASK: usize = 8;

/// Calls `f(y, input_row, output_row)` for every row, in parallel on the current rayon pool.
pub fn par_rows<F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, f: F)
where
    F: Fn(usize, &[u8], &mut [u8]) + Send + Sync,
{
    let rows = output.rows_mut();
    rows.into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(y, out)| f(y, input.row(y), out));
}

/// [`par_rows`] with per-worker state: `init()` makes a worker's state (row buffers), which
/// `f(state, y, input_row, output_row)` reuses from row to row.
pub fn par_rows_with<T, I, F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, init: I, f: F)
where
    I: Fn() -> T + Send + Sync,
    F: Fn(&mut T, usize, &[u8], &mut [u8]) + Send + Sync,
{
    let rows = output.rows_mut();
    rows.into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each_init(init, |state, (y, out)| f(state, y, input.row(y), out));
}

/// A random stream for row `y` of frame `seq`: independent per row, so rows can run in any order
/// on any thread and give the same bytes.
#[inline]
pub fn row_rng(seed: u64, seq: u64, salt: u64, y: usize) -> Rng {
    Rng::from_key(crate::rng::hash(&[seed, seq, salt, y as u64]))
}

/// Fills `out` with `f` of successive 16-bit draws from `rng`, four per 64-bit output, low
/// quarter first (a fixed block of four per output, which the compiler keeps in registers).
#[inline]
pub fn fill_quarters<T: Copy>(rng: &mut Rng, out: &mut [T], f: impl Fn(u16) -> T) {
    let quarters = |bits: u64| [0, 1, 2, 3].map(|i| f((bits >> (16 * i)) as u16));
    let mut quads = out.chunks_exact_mut(4);
    for quad in &mut quads {
        quad.copy_from_slice(&quarters(rng.next_u64()));
    }
    let rest = quads.into_remainder();
    if !rest.is_empty() {
        let n = rest.len();
        rest.copy_from_slice(&quarters(rng.next_u64())[..n]);
    }
}
