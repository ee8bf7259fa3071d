//! TCPROS framing: connection headers (`u32` total length, then `u32 len | key=value` fields) and
//! messages (`u32` length, then the ROS 1 serialized message).

use std::collections::BTreeMap;
use std::io::{IoSlice, Read, Write};

/// Headers or messages announcing more than this are refused (roscpp's limit).
pub const MAX_LEN: usize = 1_000_000_000;

/// Encodes a connection header, its total length first.
pub fn encode_header(fields: &[(&str, &str)]) -> Vec<u8> {
    let mut body = Vec::with_capacity(256);
    for (k, v) in fields {
        body.extend_from_slice(&((k.len() + 1 + v.len()) as u32).to_le_bytes());
        body.extend_from_slice(k.as_bytes());
        body.push(b'=');
        body.extend_from_slice(v.as_bytes());
    }
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&body);
    out
}

/// Decodes a header's fields (without its total length).
pub fn decode_header(mut b: &[u8]) -> Result<BTreeMap<String, String>, String> {
    let mut out = BTreeMap::new();
    while !b.is_empty() {
        if b.len() < 4 {
            return Err(format!("{} stray bytes at the end of the header", b.len()));
        }
        let n = u32::from_le_bytes(b[..4].try_into().expect("4 bytes")) as usize;
        if n == 0 || n > b.len() - 4 {
            return Err(format!("a header field of {n} bytes does not fit"));
        }
        let f = &b[4..4 + n];
        let eq = f
            .iter()
            .position(|&c| c == b'=')
            .ok_or("a header field without `=`")?;
        out.insert(
            String::from_utf8_lossy(&f[..eq]).into_owned(),
            String::from_utf8_lossy(&f[eq + 1..]).into_owned(),
        );
        b = &b[4 + n..];
    }
    Ok(out)
}

/// Reads a `u32` length and checks it against [`MAX_LEN`].
pub fn read_len(r: &mut impl Read, what: &str) -> std::io::Result<usize> {
    let mut b = [0u8; 4];
    r.read_exact(&mut b)?;
    let n = u32::from_le_bytes(b) as usize;
    if n > MAX_LEN {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("a {what} of {n} bytes announced (the limit is {MAX_LEN})"),
        ));
    }
    Ok(n)
}

/// Reads one connection header.
pub fn read_header(r: &mut impl Read) -> std::io::Result<BTreeMap<String, String>> {
    let n = read_len(r, "connection header")?;
    let mut b = vec![0u8; n];
    r.read_exact(&mut b)?;
    decode_header(&b).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))
}

/// Reads one message into `buf` (resized to the message).
pub fn read_message(r: &mut impl Read, buf: &mut Vec<u8>) -> std::io::Result<()> {
    let n = read_len(r, "message")?;
    // A recycled buffer of the same size is reused as it is (no zeroing of megabytes per frame).
    buf.resize(n, 0);
    r.read_exact(buf)
}

/// Writes one message given as parts (its length prefix first), with vectored writes so the
/// large part goes to the socket from where it lies.
pub fn write_message(w: &mut impl Write, parts: &[&[u8]]) -> std::io::Result<()> {
    let len: usize = parts.iter().map(|p| p.len()).sum();
    let prefix = (len as u32).to_le_bytes();
    let mut bufs: Vec<&[u8]> = Vec::with_capacity(parts.len() + 1);
    bufs.push(&prefix);
    bufs.extend(parts.iter().copied().filter(|p| !p.is_empty()));
    write_all_vectored(w, &mut bufs)
}

fn write_all_vectored(w: &mut impl Write, bufs: &mut [&[u8]]) -> std::io::Result<()> {
    let mut first = 0;
    while first < bufs.len() {
        let slices: Vec<IoSlice<'_>> = bufs[first..].iter().map(|b| IoSlice::new(b)).collect();
        let mut n = match w.write_vectored(&slices) {
            Ok(0) => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::WriteZero,
                    "the peer takes no more bytes",
                ));
            }
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        while first < bufs.len() && n >= bufs[first].len() {
            n -= bufs[first].len();
            first += 1;
        }
        if first < bufs.len() {
            bufs[first] = &bufs[first][n..];
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_and_messages_frame_as_the_reference_says() {
        let h = encode_header(&[("topic", "/a"), ("message_definition", "x=1\ny")]);
        let mut r = &h[..];
        let f = read_header(&mut r).unwrap();
        assert_eq!(f["topic"], "/a");
        assert_eq!(
            f["message_definition"], "x=1\ny",
            "value is everything after the first ="
        );
        // std_msgs/String "abc" is `07 00 00 00 | 03 00 00 00 61 62 63`.
        let mut out = Vec::new();
        write_message(&mut out, &[&3u32.to_le_bytes(), b"ab", b"", b"c"]).unwrap();
        assert_eq!(out, [7, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', b'c']);
        let mut buf = Vec::new();
        read_message(&mut &out[..], &mut buf).unwrap();
        assert_eq!(buf, [3, 0, 0, 0, b'a', b'b', b'c']);
        assert!(
            decode_header(&[0, 0, 0, 0]).is_err(),
            "a zero-length field is an error"
        );
        let huge = (2_000_000_000u32).to_le_bytes();
        assert!(read_message(&mut &huge[..], &mut buf).is_err());
    }
}
