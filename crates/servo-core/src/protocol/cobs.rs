//! Consistent Overhead Byte Stuffing (Cheshire & Baker, 1999): removes every 0x00 from a block so
//! that 0x00 can delimit frames. The encoded length is at most `n + n/254 + 1`.
//!
//! Both functions write into a caller buffer, never allocate and never panic: they return `None`
//! when the output does not fit or the input is not valid COBS.

/// Largest encoded size of `n` bytes.
pub const fn max_encoded_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// Encodes `src` into `dst` (without a delimiter); returns the encoded length.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    let mut code_idx = 0usize; // where the current block's code byte goes
    let mut out = 1usize; // next output index
    let mut code: u8 = 1;
    if dst.is_empty() {
        return None;
    }
    for &b in src {
        if b == 0 {
            *dst.get_mut(code_idx)? = code;
            code_idx = out;
            out += 1;
            code = 1;
            if code_idx >= dst.len() {
                return None;
            }
        } else {
            *dst.get_mut(out)? = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                *dst.get_mut(code_idx)? = code;
                code_idx = out;
                out += 1;
                code = 1;
                if code_idx >= dst.len() {
                    return None;
                }
            }
        }
    }
    *dst.get_mut(code_idx)? = code;
    Some(out)
}

/// Decodes one COBS block `src` (without its delimiter) into `dst`; returns the decoded length.
/// `None` if `src` contains 0x00, a code byte points past the end, or `dst` is too small.
pub fn decode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    let mut i = 0usize;
    let mut out = 0usize;
    while i < src.len() {
        let code = src[i];
        if code == 0 {
            return None;
        }
        i += 1;
        let run = code as usize - 1;
        let end = i.checked_add(run)?;
        if end > src.len() {
            return None;
        }
        for &b in &src[i..end] {
            if b == 0 {
                return None;
            }
            *dst.get_mut(out)? = b;
            out += 1;
        }
        i = end;
        if code != 0xFF && i < src.len() {
            *dst.get_mut(out)? = 0;
            out += 1;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(data: &[u8]) {
        let mut enc = [0u8; 1200];
        let n = encode(data, &mut enc).unwrap();
        assert!(n <= max_encoded_len(data.len()));
        assert!(!enc[..n].contains(&0), "encoded block contains 0x00");
        let mut dec = [0u8; 1200];
        let m = decode(&enc[..n], &mut dec).unwrap();
        assert_eq!(&dec[..m], data);
    }

    #[test]
    fn known_vectors() {
        // Vectors from the COBS paper / Wikipedia.
        let mut enc = [0u8; 16];
        let n = encode(&[0x00], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x01, 0x01]);
        let n = encode(&[0x00, 0x00], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x01, 0x01, 0x01]);
        let n = encode(&[0x11, 0x22, 0x00, 0x33], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        let n = encode(&[0x11, 0x00, 0x00, 0x00], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x02, 0x11, 0x01, 0x01, 0x01]);
    }

    #[test]
    fn roundtrips_including_long_runs() {
        roundtrip(&[]);
        roundtrip(&[1, 2, 3]);
        let long: [u8; 600] = core::array::from_fn(|i| (i % 255 + 1) as u8);
        roundtrip(&long);
        let mixed: [u8; 600] = core::array::from_fn(|i| (i % 7) as u8);
        roundtrip(&mixed);
        let exact: [u8; 254] = [7; 254];
        roundtrip(&exact);
    }

    #[test]
    fn rejects_bad_input_and_small_buffers() {
        let mut dst = [0u8; 8];
        assert_eq!(decode(&[0x05, 1, 2], &mut dst), None); // code past the end
        assert_eq!(decode(&[0x02, 0x00], &mut dst), None); // zero inside
        assert_eq!(encode(&[1, 2, 3, 4, 5, 6, 7, 8, 9], &mut dst), None);
        assert_eq!(encode(&[1], &mut []), None);
    }
}
