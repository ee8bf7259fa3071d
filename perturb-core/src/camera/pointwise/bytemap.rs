//! [`ByteMap`]: a 256-entry table run as exact integer arithmetic where a line or a staircase
//! reproduces it, and [`fit_fixed`] for 16.16 fixed-point tables.

use super::avx2;
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
    /// (input, output) pairs that replace the form's output where it differs from the table.
    patches: Vec<(u8, u8)>,
}

#[derive(Clone, Debug, PartialEq)]
enum Form {
    /// A lookup per byte.
    Table,
    /// `min(255, max(0, floor(v mul / 256) + add - sub) >> 7)` in 16-bit lanes (a slope of
    /// `mul / 2^15`, results with 7 fractional bits).
    Line { mul: u16, add: u16, sub: u16 },
    /// `min(255, floor(v levels / 255) scale)`: the posterize staircase.
    Steps { levels: u16, scale: u16 },
    /// `v & and`: a staircase of power-of-two steps.
    Mask { and: u8 },
    /// `table[v >> 4]`: a map that depends on the high half of the byte only.
    Nibble { table: [u8; 16] },
}

impl ByteMap {
    /// A map computed by table lookup, or by one AND or one 16-entry lookup where that gives the
    /// table's bytes (with at most 8 patched inputs).
    pub fn table(lut: [u8; 256]) -> Self {
        Self::cheapest(lut).unwrap_or(ByteMap {
            lut,
            form: Form::Table,
            patches: Vec::new(),
        })
    }

    /// A map that is about `slope v + offset` clamped to 0..=255 (rounded), `0 <= slope < 2`:
    /// computed by a line in fixed point when one gives the table's bytes (with at most 8 patched
    /// inputs), else as [`ByteMap::table`].
    pub fn line(lut: [u8; 256], slope: f64, offset: f64) -> Self {
        match fit_line(&lut, slope, offset) {
            Some((form, patches)) => ByteMap { lut, form, patches },
            None => Self::table(lut),
        }
    }

    /// A map that is the staircase `min(255, floor(v levels / 255) scale)`: computed as
    /// [`ByteMap::table`] does where an AND or a 16-entry lookup fits, else as the staircase in
    /// 16-bit arithmetic where the table is exactly that, else by lookup.
    pub fn steps(lut: [u8; 256], levels: u32, scale: u32) -> Self {
        if let Some(cheap) = Self::cheapest(lut) {
            return cheap;
        }
        let form = match (u16::try_from(levels), u16::try_from(scale)) {
            (Ok(levels), Ok(scale)) if levels <= 256 && levels as u32 * scale as u32 <= 65535 => {
                Form::Steps { levels, scale }
            }
            _ => Form::Table,
        };
        let form = if misses(&lut, &form).is_empty() {
            form
        } else {
            Form::Table
        };
        ByteMap {
            lut,
            form,
            patches: Vec::new(),
        }
    }

    /// The table as one AND or one 16-entry lookup with the fewest patches, if at most
    /// [`MAX_PATCHES`].
    fn cheapest(lut: [u8; 256]) -> Option<Self> {
        let nibble = std::array::from_fn(|h| most_common(&lut[16 * h..16 * h + 16]));
        let candidates = (0..=255u8)
            .map(|and| Form::Mask { and })
            .chain([Form::Nibble { table: nibble }]);
        let (form, patches) = candidates
            .map(|form| {
                let patches = misses(&lut, &form);
                (form, patches)
            })
            .min_by_key(|(_, patches)| patches.len())?;
        (patches.len() <= MAX_PATCHES).then_some(ByteMap { lut, form, patches })
    }

    /// The table.
    pub fn lut(&self) -> &[u8; 256] {
        &self.lut
    }

    /// True when the map runs as arithmetic rather than as a lookup per byte.
    pub fn is_arithmetic(&self) -> bool {
        self.form != Form::Table
    }

    /// Maps every byte of `src` into `dst` (same length; alpha is not special here).
    pub fn row(&self, src: &[u8], dst: &mut [u8]) {
        let kernel = match self.form {
            Form::Table => return table_bytes(&self.lut, src, dst),
            Form::Steps { levels, scale } => {
                let done = avx2::steps(src, dst, levels, scale);
                return steps_bytes(&src[done..], levels, scale, &mut dst[done..]);
            }
            Form::Line { mul, add, sub } => avx2::Kernel::Line { mul, add, sub },
            Form::Mask { and } => avx2::Kernel::Mask { and },
            Form::Nibble { table } => avx2::Kernel::Nibble { table },
        };
        let done = patched(src, dst, kernel, &self.patches);
        let (src, dst) = (&src[done..], &mut dst[done..]);
        match kernel {
            avx2::Kernel::Line { mul, add, sub } => line_bytes(src, mul, add, sub, dst),
            avx2::Kernel::Mask { and } => mask_bytes(src, and, dst),
            avx2::Kernel::Nibble { table } => nibble_bytes(src, &table, dst),
        }
        patch(&self.patches, src, dst);
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

/// The value that occurs most often in `values` (the smallest of those tied).
fn most_common(values: &[u8]) -> u8 {
    let mut counts = [0u16; 256];
    for &v in values {
        counts[v as usize] += 1;
    }
    (0..=255u8)
        .max_by_key(|&v| (counts[v as usize], std::cmp::Reverse(v)))
        .unwrap_or(0)
}

/// The output of `form` for input `v` (the scalar definition of each kernel).
fn eval(form: &Form, lut: &[u8; 256], v: u8) -> u8 {
    match *form {
        Form::Table => lut[v as usize],
        Form::Line { mul, add, sub } => line(v, mul, add, sub),
        Form::Steps { levels, scale } => step(v, levels, scale),
        Form::Mask { and } => v & and,
        Form::Nibble { table } => table[(v >> 4) as usize],
    }
}

/// The (input, table output) pairs where `form` differs from the table.
fn misses(lut: &[u8; 256], form: &Form) -> Vec<(u8, u8)> {
    (0..=255u8)
        .filter(|&v| eval(form, lut, v) != lut[v as usize])
        .map(|v| (v, lut[v as usize]))
        .collect()
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
/// the one that misses the fewest inputs (with those inputs), if it misses at most
/// [`MAX_PATCHES`].
fn fit_line(lut: &[u8; 256], slope: f64, offset: f64) -> Option<(Form, Vec<(u8, u8)>)> {
    let m0 = (slope * 32768.0).round() as i64;
    let o0 = ((offset + 0.5) * 128.0).round() as i64;
    let mut best: Option<(Form, Vec<(u8, u8)>)> = None;
    for mul in (m0 - 2).max(0)..=(m0 + 2).min(65535) {
        for off in o0 - 16..=o0 + 16 {
            let (add, sub) = (off.max(0), (-off).max(0));
            if add > 65535 || sub > 65535 {
                continue;
            }
            let form = Form::Line {
                mul: mul as u16,
                add: add as u16,
                sub: sub as u16,
            };
            let patches = misses(lut, &form);
            if best.as_ref().is_none_or(|(_, b)| patches.len() < b.len()) {
                best = Some((form, patches));
            }
        }
    }
    best.filter(|(_, patches)| patches.len() <= MAX_PATCHES)
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

/// `kernel` and the patches over the whole 32-byte blocks of `src` in one AVX2 pass, where the
/// CPU has it; returns the bytes written (0 without AVX2).
fn patched(src: &[u8], dst: &mut [u8], kernel: avx2::Kernel, patches: &[(u8, u8)]) -> usize {
    fn fixed<const N: usize>(
        src: &[u8],
        dst: &mut [u8],
        kernel: avx2::Kernel,
        patches: &[(u8, u8)],
    ) -> usize {
        let keys = std::array::from_fn(|i| patches[i].0);
        let outs = std::array::from_fn(|i| patches[i].1);
        avx2::patched::<N>(src, dst, kernel, keys, outs)
    }
    match patches.len() {
        0 => fixed::<0>(src, dst, kernel, patches),
        1 => fixed::<1>(src, dst, kernel, patches),
        2 => fixed::<2>(src, dst, kernel, patches),
        3 => fixed::<3>(src, dst, kernel, patches),
        4 => fixed::<4>(src, dst, kernel, patches),
        5 => fixed::<5>(src, dst, kernel, patches),
        6 => fixed::<6>(src, dst, kernel, patches),
        7 => fixed::<7>(src, dst, kernel, patches),
        _ => fixed::<MAX_PATCHES>(src, dst, kernel, patches),
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
    /// `v & and` on every byte ([`Form::Mask`]).
    fn mask_bytes(src: &[u8], and: u8, dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = s & and;
        }
    }
}

wide_fn! {
    /// `table[v >> 4]` on every byte ([`Form::Nibble`]).
    fn nibble_bytes(src: &[u8], table: &[u8; 16], dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = table[(s >> 4) as usize];
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
