//! [`ByteMap`]: a 256-entry table run as exact integer arithmetic where a line or a staircase
//! reproduces it, and [`fit_fixed`] for 16.16 fixed-point tables.

use crate::camera::ops::{copy_alpha, par_rows, wide_fn};
use crate::image::{ImageView, ImageViewMut};

/// Inputs a line may miss and still be used: each costs one compare-and-select pass over a row.
const MAX_PATCHES: usize = 8;

/// A byte-to-byte map of every colour byte (alpha is copied), as a table plus the fastest exact
/// way to compute it found at configuration time.
#[derive(Clone, Debug)]
pub struct ByteMap {
    lut: [u8; 256],
    form: Form,
}

#[derive(Clone, Debug, PartialEq)]
enum Form {
    /// A lookup per byte.
    Table,
    /// `min(255, max(0, floor(v mul / 256) + add - sub) >> 7)` in 16-bit lanes (a slope of
    /// `mul / 2^15`, results with 7 fractional bits), then `patches` (input, output) replace the
    /// inputs where that differs from the table.
    Line {
        mul: u16,
        add: u16,
        sub: u16,
        patches: Vec<(u8, u8)>,
    },
    /// `min(255, floor(v levels / 255) scale)`: the posterize staircase.
    Steps { levels: u16, scale: u16 },
}

impl ByteMap {
    /// A map computed by table lookup.
    pub fn table(lut: [u8; 256]) -> Self {
        ByteMap {
            lut,
            form: Form::Table,
        }
    }

    /// A map that is about `slope v + offset` clamped to 0..=255 (rounded), `0 <= slope < 2`:
    /// computed by a line in fixed point when one gives the table's bytes (with at most 8 patched
    /// inputs), else by lookup.
    pub fn line(lut: [u8; 256], slope: f64, offset: f64) -> Self {
        let form = fit_line(&lut, slope, offset).unwrap_or(Form::Table);
        ByteMap { lut, form }
    }

    /// A map that is the staircase `min(255, floor(v levels / 255) scale)` where the table is
    /// exactly that (else by lookup).
    pub fn steps(lut: [u8; 256], levels: u32, scale: u32) -> Self {
        let form = match (u16::try_from(levels), u16::try_from(scale)) {
            (Ok(levels), Ok(scale)) if levels <= 256 && levels as u32 * scale as u32 <= 65535 => {
                Form::Steps { levels, scale }
            }
            _ => Form::Table,
        };
        let form = if agrees(&lut, &form) {
            form
        } else {
            Form::Table
        };
        ByteMap { lut, form }
    }

    /// The table.
    pub fn lut(&self) -> &[u8; 256] {
        &self.lut
    }

    /// True when the map runs as arithmetic rather than as a lookup.
    pub fn is_arithmetic(&self) -> bool {
        self.form != Form::Table
    }

    /// Maps every byte of `src` into `dst` (same length; alpha is not special here).
    pub fn row(&self, src: &[u8], dst: &mut [u8]) {
        match &self.form {
            Form::Table => table_bytes(&self.lut, src, dst),
            Form::Line {
                mul,
                add,
                sub,
                patches,
            } => {
                line_bytes(src, *mul, *add, *sub, dst);
                patch(patches, src, dst);
            }
            Form::Steps { levels, scale } => steps_bytes(src, *levels, *scale, dst),
        }
    }

    /// Maps every colour byte of `input` into `output`; alpha is copied.
    pub fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>) {
        let format = input.format;
        par_rows(input, output, |_, src, dst| {
            let n = src.len().min(dst.len());
            self.row(&src[..n], &mut dst[..n]);
            copy_alpha(format, src, dst);
        });
    }
}

/// The output of `form` for input `v` (the scalar definition of each kernel).
fn eval(form: &Form, lut: &[u8; 256], v: u8) -> u8 {
    match form {
        Form::Table => lut[v as usize],
        Form::Line {
            mul,
            add,
            sub,
            patches,
        } => match patches.iter().find(|p| p.0 == v) {
            Some(&(_, out)) => out,
            None => line(v, *mul, *add, *sub),
        },
        Form::Steps { levels, scale } => step(v, *levels, *scale),
    }
}

fn agrees(lut: &[u8; 256], form: &Form) -> bool {
    (0..=255u8).all(|v| eval(form, lut, v) == lut[v as usize])
}

#[inline(always)]
fn line(v: u8, mul: u16, add: u16, sub: u16) -> u8 {
    // floor(v mul / 256) with 16-bit products only: v (mul >> 8) + floor(v (mul & 255) / 256).
    let v = v as u16;
    let scaled = v * (mul >> 8) + ((v * (mul & 255)) >> 8);
    (scaled.saturating_add(add).saturating_sub(sub) >> 7).min(255) as u8
}

/// `floor(v levels / 255)` as `floor((v levels + 1) 257 / 2^16)` (exact for `v levels` up to
/// 65280), times `scale`, at most 255.
#[inline(always)]
fn step(v: u8, levels: u16, scale: u16) -> u8 {
    let t = v as u16 * levels + 1;
    let q = ((t as u32 * 257) >> 16) as u16;
    (q * scale).min(255) as u8
}

/// The line of [`Form::Line`] closest to the table: slopes and offsets around the nominal ones,
/// the one that misses the fewest inputs, if it misses at most [`MAX_PATCHES`].
fn fit_line(lut: &[u8; 256], slope: f64, offset: f64) -> Option<Form> {
    let m0 = (slope * 32768.0).round() as i64;
    let o0 = ((offset + 0.5) * 128.0).round() as i64;
    let mut best: Option<Form> = None;
    let mut best_misses = usize::MAX;
    for mul in (m0 - 2).max(0)..=(m0 + 2).min(65535) {
        for off in o0 - 16..=o0 + 16 {
            let (add, sub) = (off.max(0), (-off).max(0));
            if add > 65535 || sub > 65535 {
                continue;
            }
            let (mul, add, sub) = (mul as u16, add as u16, sub as u16);
            let misses: Vec<(u8, u8)> = (0..=255u8)
                .filter(|&v| line(v, mul, add, sub) != lut[v as usize])
                .map(|v| (v, lut[v as usize]))
                .collect();
            if misses.len() < best_misses {
                best_misses = misses.len();
                best = Some(Form::Line {
                    mul,
                    add,
                    sub,
                    patches: misses,
                });
            }
        }
    }
    best.filter(|_| best_misses <= MAX_PATCHES)
}

/// `(mul, add)` with `(v mul + add) >> 16 == table[v]` for every v in 0..=255 and no 32-bit
/// overflow, if there is one: a table of rounded products `round(c v)` in 16.16 fixed point. For
/// each slope around the table's mean slope the offsets that fit every entry form an interval,
/// computed directly.
pub fn fit_fixed(table: &[u32; 256]) -> Option<(u32, u32)> {
    fit_fixed_near(table, (table[255] as f64 - table[0] as f64) / 255.0)
}

/// [`fit_fixed`] starting from the slope `slope` (the search ends sooner when it is close).
pub fn fit_fixed_near(table: &[u32; 256], slope: f64) -> Option<(u32, u32)> {
    if !(0.0..65536.0).contains(&slope) {
        return None;
    }
    let m0 = (slope * 65536.0).round() as i64;
    // The rounding of each entry moves the best slope by at most 1/255 of a step either way.
    for d in 0..=(65536 / 255 + 2) {
        for mul in [m0 - d, m0 + d] {
            if mul < 0 || (d == 0 && mul != m0) {
                continue;
            }
            // table[v] << 16 <= v mul + add < (table[v] + 1) << 16
            let mut lo = i64::MIN;
            let mut hi = i64::MAX;
            for (v, &t) in table.iter().enumerate() {
                let base = v as i64 * mul;
                lo = lo.max(((t as i64) << 16) - base);
                hi = hi.min((((t as i64) + 1) << 16) - base - 1);
            }
            let add = lo.max(0);
            if add <= hi && 255 * mul + add <= u32::MAX as i64 {
                return Some((mul as u32, add as u32));
            }
        }
    }
    None
}

wide_fn! {
    /// `dst[i] = lut[src[i]]`.
    fn table_bytes(lut: &[u8; 256], src: &[u8], dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = lut[*s as usize];
        }
    }
}

wide_fn! {
    /// The line of [`Form::Line`] on every byte.
    fn line_bytes(src: &[u8], mul: u16, add: u16, sub: u16, dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = line(s, mul, add, sub);
        }
    }
}

/// `dst[i] = out` where `src[i] == v`, for every `(v, out)` of `patches`, in one pass.
fn patch(patches: &[(u8, u8)], src: &[u8], dst: &mut [u8]) {
    fn fixed<const N: usize>(patches: &[(u8, u8)], src: &[u8], dst: &mut [u8]) {
        let keys = std::array::from_fn(|i| patches[i].0);
        let outs = std::array::from_fn(|i| patches[i].1);
        patch_bytes::<N>(src, keys, outs, dst);
    }
    match patches.len() {
        0 => {}
        1 => fixed::<1>(patches, src, dst),
        2 => fixed::<2>(patches, src, dst),
        3 => fixed::<3>(patches, src, dst),
        4 => fixed::<4>(patches, src, dst),
        5 => fixed::<5>(patches, src, dst),
        6 => fixed::<6>(patches, src, dst),
        7 => fixed::<7>(patches, src, dst),
        _ => fixed::<MAX_PATCHES>(patches, src, dst),
    }
}

wide_fn! {
    /// `dst[i] = outs[j]` where `src[i] == keys[j]`.
    fn patch_bytes<const N: usize>(src: &[u8], keys: [u8; N], outs: [u8; N], dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            let mut o = *d;
            for j in 0..N {
                // A select, not a conditional store: it vectorises.
                o = if s == keys[j] { outs[j] } else { o };
            }
            *d = o;
        }
    }
}

wide_fn! {
    /// The staircase of [`Form::Steps`] on every byte.
    fn steps_bytes(src: &[u8], levels: u16, scale: u16, dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = step(s, levels, scale);
        }
    }
}
