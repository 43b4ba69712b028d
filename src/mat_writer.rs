//! A small MAT-file Level 5 writer for the tests: synthetic files (Scope structures, cells,
//! opaque objects, compressed or not) read by `tests/mat.rs` and the fuzz seeds of
//! `tests/fuzz.rs`.

use std::io::Write;

/// One element: tag, data, padding to 8 bytes.
pub fn element(ty: u32, data: &[u8]) -> Vec<u8> {
    let mut v = Vec::new();
    if data.len() <= 4 && ty != 14 && ty != 15 {
        // Small data element format (the struct field-name length uses it in MATLAB's files).
        v.extend_from_slice(&(ty | ((data.len() as u32) << 16)).to_le_bytes());
        let mut d = data.to_vec();
        d.resize(4, 0);
        v.extend_from_slice(&d);
        return v;
    }
    v.extend_from_slice(&ty.to_le_bytes());
    v.extend_from_slice(&(data.len() as u32).to_le_bytes());
    v.extend_from_slice(data);
    while v.len() % 8 != 0 {
        v.push(0);
    }
    v
}

/// A miMATRIX element: flags, dimensions, name, then `parts`.
pub fn matrix(class: u32, dims: &[i32], name: &str, parts: &[Vec<u8>]) -> Vec<u8> {
    let mut body = element(6, &[class.to_le_bytes(), 0u32.to_le_bytes()].concat());
    if class != 17 {
        let d: Vec<u8> = dims.iter().flat_map(|x| x.to_le_bytes()).collect();
        body.extend(element(5, &d));
    }
    body.extend(element(1, name.as_bytes()));
    for p in parts {
        body.extend_from_slice(p);
    }
    element(14, &body)
}

pub fn doubles(name: &str, rows: usize, cols: usize, v: &[f64]) -> Vec<u8> {
    let d: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    matrix(6, &[rows as i32, cols as i32], name, &[element(9, &d)])
}

pub fn text(name: &str, s: &str) -> Vec<u8> {
    let d: Vec<u8> = s.encode_utf16().flat_map(|c| c.to_le_bytes()).collect();
    matrix(4, &[1, s.len() as i32], name, &[element(4, &d)])
}

/// A struct array of `n` elements (`values[e][f]`).
pub fn structure(name: &str, fields: &[&str], values: &[Vec<Vec<u8>>]) -> Vec<u8> {
    let len = 32usize;
    let mut names = Vec::new();
    for f in fields {
        let mut b = f.as_bytes().to_vec();
        b.resize(len, 0);
        names.extend(b);
    }
    let mut parts = vec![element(5, &(len as i32).to_le_bytes()), element(1, &names)];
    for e in values {
        parts.extend(e.iter().cloned());
    }
    matrix(2, &[1, values.len() as i32], name, &parts)
}

/// A Simulink Scope "structure with time": `time` and one signal per (columns, label).
pub fn scope(name: &str, time: &[f64], signals: &[(Vec<Vec<f64>>, &str)]) -> Vec<u8> {
    let n = time.len();
    let sig: Vec<Vec<Vec<u8>>> = signals
        .iter()
        .map(|(cols, label)| {
            let flat: Vec<f64> = cols.iter().flatten().copied().collect();
            vec![
                doubles("", n, cols.len(), &flat),
                doubles("", 1, 1, &[cols.len() as f64]),
                text("", label),
            ]
        })
        .collect();
    structure(
        name,
        &["time", "signals", "blockName"],
        &[vec![
            doubles("", n, 1, time),
            structure("", &["values", "dimensions", "label"], &sig),
            text("", "model/Scope"),
        ]],
    )
}

pub fn compress(el: &[u8]) -> Vec<u8> {
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    z.write_all(el).unwrap();
    let c = z.finish().unwrap();
    let mut v = 15u32.to_le_bytes().to_vec();
    v.extend_from_slice(&(c.len() as u32).to_le_bytes());
    v.extend(c);
    v
}

pub fn mat_file(elements: &[Vec<u8>], compressed: bool) -> Vec<u8> {
    let mut h = b"MATLAB 5.0 MAT-file, Platform: servo test, Created on: today".to_vec();
    h.resize(116, b' ');
    h.extend_from_slice(&[0; 8]);
    h.extend_from_slice(&0x0100u16.to_le_bytes());
    h.extend_from_slice(b"IM");
    for e in elements {
        h.extend(if compressed { compress(e) } else { e.clone() });
    }
    h
}
