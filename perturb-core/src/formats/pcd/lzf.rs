//! LZF (liblzf's format), the compression of PCD's `binary_compressed` data.

use super::bad;
use crate::error::Result;

/// The most an LZF stream can expand: a 3-byte back reference copies at most 264 bytes.
pub(super) const LZF_MAX_RATIO: usize = 88;

/// Decompresses an LZF stream (liblzf format) of known output size.
pub fn lzf_decompress(input: &[u8], out_len: usize) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(out_len.min(input.len().saturating_mul(LZF_MAX_RATIO)));
    let mut i = 0;
    while i < input.len() {
        let ctrl = input[i] as usize;
        i += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            if i + len > input.len() || out.len() + len > out_len {
                return Err(bad(format!("LZF literal run at byte {} overflows", i - 1)));
            }
            out.extend_from_slice(&input[i..i + len]);
            i += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *input
                    .get(i)
                    .ok_or_else(|| bad("LZF stream ends inside a back reference"))?
                    as usize;
                i += 1;
            }
            let low = *input
                .get(i)
                .ok_or_else(|| bad("LZF stream ends inside a back reference"))?
                as usize;
            i += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            let len = len + 2;
            if back > out.len() || out.len() + len > out_len {
                return Err(bad(format!(
                    "LZF back reference at byte {} points outside the data",
                    i - 2
                )));
            }
            let start = out.len() - back;
            for k in 0..len {
                out.push(out[start + k]);
            }
        }
    }
    if out.len() != out_len {
        return Err(bad(format!(
            "LZF data decompresses to {} bytes, expected {out_len}",
            out.len()
        )));
    }
    Ok(out)
}

/// Compresses with LZF: a simple greedy matcher over a hash of 3-byte prefixes.
pub fn lzf_compress(input: &[u8]) -> Vec<u8> {
    const HSIZE: usize = 1 << 14;
    let mut table = vec![usize::MAX; HSIZE];
    let mut out = Vec::with_capacity(input.len() + input.len() / 32 + 8);
    let mut lit: Vec<u8> = Vec::with_capacity(32);
    let flush = |out: &mut Vec<u8>, lit: &mut Vec<u8>| {
        for chunk in lit.chunks(32) {
            out.push((chunk.len() - 1) as u8);
            out.extend_from_slice(chunk);
        }
        lit.clear();
    };
    let mut i = 0;
    while i < input.len() {
        if i + 2 < input.len() {
            let h =
                ((input[i] as usize) << 16 | (input[i + 1] as usize) << 8 | input[i + 2] as usize)
                    .wrapping_mul(2_654_435_761)
                    >> 8
                    & (HSIZE - 1);
            let cand = table[h];
            table[h] = i;
            if cand != usize::MAX && i - cand <= 8192 && input[cand..cand + 3] == input[i..i + 3] {
                let max = (input.len() - i).min(264);
                let mut len = 3;
                while len < max && input[cand + len] == input[i + len] {
                    len += 1;
                }
                flush(&mut out, &mut lit);
                let back = i - cand - 1;
                let l = len - 2;
                if l < 7 {
                    out.push(((l << 5) | (back >> 8)) as u8);
                } else {
                    out.push(((7 << 5) | (back >> 8)) as u8);
                    out.push((l - 7) as u8);
                }
                out.push((back & 0xff) as u8);
                i += len;
                continue;
            }
        }
        lit.push(input[i]);
        i += 1;
    }
    flush(&mut out, &mut lit);
    out
}
