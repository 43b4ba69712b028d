//! Reading MATLAB MAT-files, Level 5 (`save -v6` and `save -v7`: zlib-compressed elements), into a
//! tree of values: numeric arrays, char arrays, cell arrays, structures and struct arrays
//! (Simulink Scope "structure with time" variables are 1x1 structs with `time` and a 1xN `signals`
//! struct array). Sparse arrays, function handles and opaque objects (MCOS `classdef` objects,
//! `string`, `table`, ...) are skipped, not fatal: they are listed as [`MatValue::Skipped`].
//!
//! Why not a crate: `matfile` 0.5 reads numeric arrays only (no structs or cells); `matrw` 0.1.4
//! reads structs and cells but unwraps the zlib stream (a corrupt file panics), decompresses
//! without a bound, panics with `unimplemented!` on some variables and does not read MCOS objects.
//! Here zlib is `flate2`'s (miniz_oxide), and the element walking is ours, written for hostile
//! input:
//!
//! * never panics on any bytes (fuzzed in tests over real and synthetic files);
//! * every allocation is bounded by bytes actually present: a count from a header (dimensions,
//!   number of fields) only drives a loop that consumes at least 8 bytes per step, and numeric
//!   vectors are sized by the data element's own length, checked against the buffer;
//! * decompressed data are limited to [`MAX_DECOMPRESSED_BYTES`] per file (zip bombs stop there),
//!   numbers to [`MAX_NUMBERS`] and arrays to [`MAX_ARRAYS`];
//! * nesting is limited to [`MAX_DEPTH`] levels.

use flate2::read::ZlibDecoder;
use std::io::Read;
use std::path::Path;

/// Largest total of decompressed bytes read from one file (256 MiB).
pub const MAX_DECOMPRESSED_BYTES: usize = 256 << 20;
/// Largest total of numbers read from one file (32 Mi values, 256 MiB as f64): a uint8 array
/// grows eightfold as f64.
pub const MAX_NUMBERS: usize = 32 << 20;
/// Largest number of arrays (cells, struct fields, variables) read from one file.
pub const MAX_ARRAYS: usize = 1 << 20;
/// Deepest nesting of cells and structs read.
pub const MAX_DEPTH: usize = 48;

/// Why a MAT-file could not be read. Offsets are byte offsets in the file, or in the decompressed
/// data of the compressed variable named by `variable`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MatError {
    #[error("reading {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("not a MAT-file: {0}")]
    NotMat(String),
    #[error("{context}at byte {offset}: {what}")]
    Corrupt {
        context: String,
        offset: usize,
        what: String,
    },
    #[error("the file holds more than {limit} {what}, more than servo reads from one MAT-file (a corrupt file or a zip bomb?)")]
    TooLarge { what: &'static str, limit: usize },
}

/// A numeric array (any MATLAB numeric or logical class), as f64, column-major.
#[derive(Debug, Clone, PartialEq)]
pub struct NumericArray {
    pub dims: Vec<usize>,
    /// MATLAB class name (`double`, `single`, `int16`, `logical`, ...).
    pub class: &'static str,
    pub real: Vec<f64>,
    pub imag: Option<Vec<f64>>,
}

/// A struct array (or an old-style object): `values[e * fields.len() + f]` is field `f` of
/// element `e` (elements column-major).
#[derive(Debug, Clone, PartialEq)]
pub struct StructArray {
    pub dims: Vec<usize>,
    /// Class name of an old-style object (`None` for a plain struct).
    pub class_name: Option<String>,
    pub fields: Vec<String>,
    pub values: Vec<MatValue>,
}

impl StructArray {
    /// Number of elements.
    pub fn len(&self) -> usize {
        numel(&self.dims)
    }
    /// True when the array has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Field `name` of element `e` (0-based).
    pub fn field(&self, e: usize, name: &str) -> Option<&MatValue> {
        let f = self.fields.iter().position(|x| x == name)?;
        self.values
            .get(e.checked_mul(self.fields.len())?.checked_add(f)?)
    }
}

/// One MATLAB value.
#[derive(Debug, Clone, PartialEq)]
pub enum MatValue {
    Numeric(NumericArray),
    /// A char array; `rows` holds its rows (one for a 1xN string).
    Char {
        dims: Vec<usize>,
        rows: Vec<String>,
    },
    Cell {
        dims: Vec<usize>,
        items: Vec<MatValue>,
    },
    Struct(StructArray),
    /// A value servo does not read (sparse, function handle, opaque object), with its class.
    Skipped {
        class: String,
        dims: Vec<usize>,
    },
}

impl MatValue {
    /// Dimensions (`[]` when unknown, e.g. an opaque object).
    pub fn dims(&self) -> &[usize] {
        match self {
            MatValue::Numeric(a) => &a.dims,
            MatValue::Char { dims, .. } | MatValue::Cell { dims, .. } => dims,
            MatValue::Struct(s) => &s.dims,
            MatValue::Skipped { dims, .. } => dims,
        }
    }
    /// MATLAB class name.
    pub fn class(&self) -> String {
        match self {
            MatValue::Numeric(a) => a.class.to_string(),
            MatValue::Char { .. } => "char".into(),
            MatValue::Cell { .. } => "cell".into(),
            MatValue::Struct(s) => s.class_name.clone().unwrap_or_else(|| "struct".into()),
            MatValue::Skipped { class, .. } => class.clone(),
        }
    }
    /// The text of a 1-row char array.
    pub fn as_text(&self) -> Option<String> {
        match self {
            MatValue::Char { rows, .. } => Some(rows.join("\n")),
            _ => None,
        }
    }
}

/// `2x3`-style size text.
pub fn dims_text(dims: &[usize]) -> String {
    if dims.is_empty() {
        return "?".into();
    }
    dims.iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join("x")
}

/// Number of elements of an array of `dims` (saturating: counts only drive bounded loops).
pub fn numel(dims: &[usize]) -> usize {
    dims.iter().fold(1usize, |a, &d| a.saturating_mul(d))
}

/// A named top-level variable.
#[derive(Debug, Clone, PartialEq)]
pub struct MatVariable {
    pub name: String,
    pub value: MatValue,
}

/// A MAT-file's variables, in file order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MatFile {
    /// The descriptive text of the header (`MATLAB 5.0 MAT-file, Platform: ..., Created on: ...`).
    pub header_text: String,
    pub variables: Vec<MatVariable>,
    /// Elements that are not variables and were skipped (subsystem data, unknown types).
    pub skipped: Vec<String>,
}

impl MatFile {
    /// The variable `name`.
    pub fn get(&self, name: &str) -> Option<&MatValue> {
        self.variables
            .iter()
            .find(|v| v.name == name)
            .map(|v| &v.value)
    }
}

/// Largest MAT-file servo reads [bytes]: 1 GiB (its numbers are limited to [`MAX_NUMBERS`],
/// 256 MB of doubles, and its inflated data to [`MAX_DECOMPRESSED_BYTES`]).
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Reads the MAT-file at `path`: its header is checked before the rest is read (a large file
/// that is not a MAT-file is refused after its first bytes), a file beyond
/// [`MAX_FILE_BYTES`] is refused before it is read.
pub fn read_mat_file(path: &Path) -> Result<MatFile, MatError> {
    use std::io::Read;
    let io = |source| MatError::Io {
        path: path.display().to_string(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let mut head = Vec::new();
    (&file).take(520).read_to_end(&mut head).map_err(io)?;
    let header_ok = head.len() >= 128
        && matches!(&head[126..128], b"IM" | b"MI")
        && !head.starts_with(b"\x89HDF")
        && head.get(512..516) != Some(b"\x89HDF");
    if !header_ok {
        return parse_mat(&head);
    }
    let size = file.metadata().map_err(io)?.len();
    if size > MAX_FILE_BYTES {
        return Err(MatError::TooLarge {
            what: "bytes",
            limit: MAX_FILE_BYTES as usize,
        });
    }
    let mut bytes = head;
    (&file)
        .take(MAX_FILE_BYTES)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    parse_mat(&bytes)
}

// Data types of the element tags.
const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
const MI_UTF8: u32 = 16;
const MI_UTF16: u32 = 17;
const MI_UTF32: u32 = 18;

/// Parses a whole MAT-file held in memory.
pub fn parse_mat(bytes: &[u8]) -> Result<MatFile, MatError> {
    if bytes.starts_with(b"\x89HDF") || bytes.get(512..516) == Some(b"\x89HDF") {
        return Err(MatError::NotMat(
            "this is a MAT-file v7.3 (HDF5), which servo does not read; in MATLAB, save it again with `save(file, '-v7')`".into(),
        ));
    }
    if bytes.len() < 128 {
        return Err(MatError::NotMat(format!(
            "{} bytes, shorter than the 128-byte MAT-file header",
            bytes.len()
        )));
    }
    let text_end = bytes[..116]
        .iter()
        .rposition(|&b| b != 0 && b != b' ')
        .map_or(0, |p| p + 1);
    let header_text = String::from_utf8_lossy(&bytes[..text_end]).into_owned();
    let big_endian = match &bytes[126..128] {
        b"IM" => false,
        b"MI" => true,
        _ => {
            let hint = if bytes[..4].contains(&0) {
                " (a Level 4 MAT-file? save it again with `save(file, '-v7')`)"
            } else {
                ""
            };
            return Err(MatError::NotMat(format!(
                "no MAT-file Level 5 endian mark at bytes 126-127{hint}"
            )));
        }
    };
    if !header_text.starts_with("MATLAB") {
        return Err(MatError::NotMat(format!(
            "the header text starts `{}`, not `MATLAB 5.0 MAT-file`",
            header_text.chars().take(30).collect::<String>()
        )));
    }
    let mut p = Parser {
        big_endian,
        budget: MAX_DECOMPRESSED_BYTES,
        numbers: 0,
        arrays: 0,
        context: String::new(),
    };
    let mut file = MatFile {
        header_text,
        ..MatFile::default()
    };
    let mut cur = Cur {
        buf: bytes,
        pos: 128,
    };
    while cur.pos < bytes.len() {
        if bytes.len() - cur.pos < 8 {
            file.skipped
                .push(format!("{} trailing bytes", bytes.len() - cur.pos));
            break;
        }
        let start = cur.pos;
        p.context.clear();
        let (ty, data) = p.tag(&mut cur, true)?;
        let element = match ty {
            MI_COMPRESSED => {
                let inner = p.inflate(data, start)?;
                p.context = format!("in the compressed element at byte {start}, ");
                let mut ic = Cur {
                    buf: &inner,
                    pos: 0,
                };
                let (ity, idata) = p.tag(&mut ic, false)?;
                if ity != MI_MATRIX {
                    file.skipped.push(format!(
                        "a compressed element of type {ity} at byte {start}"
                    ));
                    continue;
                }
                p.matrix(idata, 0, 0)?
            }
            MI_MATRIX => p.matrix(data, start + 8, 0)?,
            other => {
                file.skipped
                    .push(format!("an element of type {other} at byte {start}"));
                continue;
            }
        };
        let (name, value) = element;
        if name.is_empty() {
            file.skipped.push(format!(
                "an unnamed {} {} at byte {start} (MATLAB's subsystem data for objects)",
                dims_text(value.dims()),
                value.class()
            ));
        } else {
            file.variables.push(MatVariable { name, value });
        }
    }
    Ok(file)
}

/// A position in a byte buffer.
struct Cur<'a> {
    buf: &'a [u8],
    pos: usize,
}

struct Parser {
    big_endian: bool,
    /// Decompressed bytes still allowed.
    budget: usize,
    /// Numbers and arrays read so far.
    numbers: usize,
    arrays: usize,
    /// Where we are, for messages.
    context: String,
}

impl Parser {
    fn corrupt(&self, offset: usize, what: impl Into<String>) -> MatError {
        MatError::Corrupt {
            context: self.context.clone(),
            offset,
            what: what.into(),
        }
    }

    fn u32_at(&self, b: &[u8]) -> u32 {
        let a = [b[0], b[1], b[2], b[3]];
        if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        }
    }

    /// Reads one element tag at `cur` and returns its type and data, moving past the element and
    /// its padding to 8 bytes (`top`: a compressed top-level element has no padding).
    fn tag<'a>(&self, cur: &mut Cur<'a>, top: bool) -> Result<(u32, &'a [u8]), MatError> {
        let at = cur.pos;
        let head = cur
            .buf
            .get(at..at.saturating_add(8))
            .filter(|h| h.len() == 8)
            .ok_or_else(|| self.corrupt(at, "an element tag is cut short"))?;
        let w0 = self.u32_at(&head[..4]);
        if w0 >> 16 != 0 {
            // Small data element: type and length in one word, data in the next 4 bytes.
            let (ty, n) = (w0 & 0xffff, (w0 >> 16) as usize);
            if n > 4 {
                return Err(
                    self.corrupt(at, format!("a small element claims {n} bytes (at most 4)"))
                );
            }
            cur.pos = at + 8;
            return Ok((ty, &head[4..4 + n]));
        }
        let n = self.u32_at(&head[4..]) as usize;
        let start = at + 8;
        let data = cur
            .buf
            .get(start..start.saturating_add(n))
            .filter(|d| d.len() == n)
            .ok_or_else(|| {
                self.corrupt(
                    at,
                    format!(
                        "an element of type {w0} claims {n} bytes, only {} remain",
                        cur.buf.len().saturating_sub(start)
                    ),
                )
            })?;
        let padded = if top && w0 == MI_COMPRESSED {
            n
        } else {
            n.div_ceil(8).saturating_mul(8)
        };
        cur.pos = start.saturating_add(padded).min(cur.buf.len());
        Ok((w0, data))
    }

    /// Decompresses a miCOMPRESSED element's data within the remaining budget.
    fn inflate(&mut self, data: &[u8], at: usize) -> Result<Vec<u8>, MatError> {
        let mut out = Vec::new();
        let limit = self.budget as u64 + 1;
        let mut dec = ZlibDecoder::new(data).take(limit);
        if let Err(e) = dec.read_to_end(&mut out) {
            // MATLAB writes complete streams; a broken one is a damaged file.
            return Err(self.corrupt(at, format!("the compressed data do not inflate: {e}")));
        }
        if out.len() > self.budget {
            return Err(MatError::TooLarge {
                what: "decompressed bytes",
                limit: MAX_DECOMPRESSED_BYTES,
            });
        }
        self.budget -= out.len();
        Ok(out)
    }

    /// Parses the body of a miMATRIX element (`base`: its offset, for messages). Returns the
    /// array's name and value.
    fn matrix(
        &mut self,
        body: &[u8],
        base: usize,
        depth: usize,
    ) -> Result<(String, MatValue), MatError> {
        if depth > MAX_DEPTH {
            return Err(self.corrupt(base, format!("nesting deeper than {MAX_DEPTH} levels")));
        }
        self.arrays += 1;
        if self.arrays > MAX_ARRAYS {
            return Err(MatError::TooLarge {
                what: "arrays",
                limit: MAX_ARRAYS,
            });
        }
        if body.is_empty() {
            // An empty matrix element: MATLAB's [] in a struct field or cell.
            return Ok((
                String::new(),
                MatValue::Numeric(NumericArray {
                    dims: vec![0, 0],
                    class: "double",
                    real: Vec::new(),
                    imag: None,
                }),
            ));
        }
        let mut cur = Cur { buf: body, pos: 0 };
        let (ty, flags) = self.tag(&mut cur, false)?;
        if ty != MI_UINT32 || flags.len() < 8 {
            return Err(self.corrupt(base, "a matrix does not start with its array flags"));
        }
        let w = self.u32_at(&flags[..4]);
        let class = w & 0xff;
        let complex = w & 0x0800 != 0;
        let logical = w & 0x0200 != 0;
        if class == 17 {
            // Opaque object (MCOS classdef, string, table, ...): name, type system, class name,
            // then data servo does not interpret.
            let name = self.text(&mut cur, base)?;
            let _system = self.text(&mut cur, base).unwrap_or_default();
            let class_name = self.text(&mut cur, base).unwrap_or_default();
            return Ok((
                name,
                MatValue::Skipped {
                    class: format!("opaque object {class_name}").trim().to_string(),
                    dims: Vec::new(),
                },
            ));
        }
        let (dty, draw) = self.tag(&mut cur, false)?;
        if dty != MI_INT32 || draw.len() < 4 {
            return Err(self.corrupt(base, "a matrix has no dimensions"));
        }
        let dims: Vec<usize> = draw
            .chunks_exact(4)
            .map(|c| self.u32_at(c) as i32)
            .map(|d| usize::try_from(d).unwrap_or(usize::MAX))
            .collect();
        if dims.contains(&usize::MAX) {
            return Err(self.corrupt(base, "a negative dimension"));
        }
        let n = numel(&dims);
        let name = self.text(&mut cur, base)?;
        let value = match class {
            6..=15 => {
                let real = self.numbers(&mut cur, base, n)?;
                let imag = if complex {
                    Some(self.numbers(&mut cur, base, n)?)
                } else {
                    None
                };
                MatValue::Numeric(NumericArray {
                    dims,
                    class: if logical {
                        "logical"
                    } else {
                        class_name(class)
                    },
                    real,
                    imag,
                })
            }
            4 => {
                let (ty, raw) = self.tag(&mut cur, false)?;
                let chars = self
                    .chars(ty, raw)
                    .ok_or_else(|| self.corrupt(base, format!("char data of unknown type {ty}")))?;
                let r = dims.first().copied().unwrap_or(0);
                let rows = if r <= 1 {
                    vec![chars.into_iter().collect()]
                } else if chars.len() == n {
                    // Column-major: row i is chars[i], chars[i + r], ...
                    let cols = n / r;
                    (0..r)
                        .map(|i| (0..cols).filter_map(|j| chars.get(j * r + i)).collect())
                        .collect()
                } else {
                    return Err(self.corrupt(
                        base,
                        format!(
                            "a {} char array holds {} characters",
                            dims_text(&dims),
                            chars.len()
                        ),
                    ));
                };
                MatValue::Char { dims, rows }
            }
            1 => {
                let mut items = Vec::new();
                for _ in 0..n {
                    items.push(self.child(&mut cur, base, depth)?);
                }
                MatValue::Cell { dims, items }
            }
            2 | 3 => {
                let class_name = if class == 3 {
                    Some(self.text(&mut cur, base)?)
                } else {
                    None
                };
                let (lt, lraw) = self.tag(&mut cur, false)?;
                if lt != MI_INT32 || lraw.len() < 4 {
                    return Err(self.corrupt(base, "a struct has no field-name length"));
                }
                let len = self.u32_at(lraw) as usize;
                let (_, names) = self.tag(&mut cur, false)?;
                let fields: Vec<String> = if len == 0 {
                    Vec::new()
                } else {
                    names
                        .chunks(len)
                        .map(|c| {
                            let end = c.iter().position(|&b| b == 0).unwrap_or(c.len());
                            String::from_utf8_lossy(&c[..end]).into_owned()
                        })
                        .collect()
                };
                let mut values = Vec::new();
                for _ in 0..n.saturating_mul(fields.len()) {
                    values.push(self.child(&mut cur, base, depth)?);
                }
                MatValue::Struct(StructArray {
                    dims,
                    class_name,
                    fields,
                    values,
                })
            }
            5 => MatValue::Skipped {
                class: "sparse".into(),
                dims,
            },
            16 => MatValue::Skipped {
                class: "function_handle".into(),
                dims,
            },
            other => MatValue::Skipped {
                class: format!("class {other}"),
                dims,
            },
        };
        Ok((name, value))
    }

    /// A nested miMATRIX (cell item or struct field value).
    fn child(&mut self, cur: &mut Cur, base: usize, depth: usize) -> Result<MatValue, MatError> {
        let at = base + cur.pos;
        let (ty, body) = self.tag(cur, false)?;
        if ty != MI_MATRIX {
            return Err(self.corrupt(
                at,
                format!("expected a matrix element (type 14), found type {ty}"),
            ));
        }
        Ok(self.matrix(body, at + 8, depth + 1)?.1)
    }

    /// An array name or class name (miINT8 text).
    fn text(&self, cur: &mut Cur, base: usize) -> Result<String, MatError> {
        let (ty, raw) = self.tag(cur, false)?;
        if !matches!(ty, MI_INT8 | MI_UINT8 | MI_UTF8) {
            return Err(self.corrupt(base, format!("expected a name (type 1), found type {ty}")));
        }
        let end = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
        Ok(String::from_utf8_lossy(&raw[..end]).into_owned())
    }

    /// The characters of a char array's data.
    fn chars(&self, ty: u32, raw: &[u8]) -> Option<Vec<char>> {
        Some(match ty {
            MI_INT8 | MI_UINT8 | MI_UTF8 => String::from_utf8_lossy(raw).chars().collect(),
            MI_UINT16 | MI_UTF16 | MI_INT16 => {
                let units: Vec<u16> = raw
                    .chunks_exact(2)
                    .map(|c| {
                        if self.big_endian {
                            u16::from_be_bytes([c[0], c[1]])
                        } else {
                            u16::from_le_bytes([c[0], c[1]])
                        }
                    })
                    .collect();
                char::decode_utf16(units)
                    .map(|r| r.unwrap_or(char::REPLACEMENT_CHARACTER))
                    .collect()
            }
            MI_UTF32 | MI_UINT32 | MI_INT32 => raw
                .chunks_exact(4)
                .map(|c| char::from_u32(self.u32_at(c)).unwrap_or(char::REPLACEMENT_CHARACTER))
                .collect(),
            _ => return None,
        })
    }

    /// A numeric data element holding `n` values of any storage type, as f64.
    fn numbers(&mut self, cur: &mut Cur, base: usize, n: usize) -> Result<Vec<f64>, MatError> {
        let at = base + cur.pos;
        let (ty, raw) = self.tag(cur, false)?;
        let size = match ty {
            MI_INT8 | MI_UINT8 => 1,
            MI_INT16 | MI_UINT16 => 2,
            MI_INT32 | MI_UINT32 | MI_SINGLE => 4,
            MI_DOUBLE | MI_INT64 | MI_UINT64 => 8,
            _ => return Err(self.corrupt(at, format!("numeric data of unknown type {ty}"))),
        };
        let count = raw.len() / size;
        if count != n {
            return Err(self.corrupt(
                at,
                format!("the dimensions say {n} values, the data hold {count}"),
            ));
        }
        self.numbers = self.numbers.saturating_add(count);
        if self.numbers > MAX_NUMBERS {
            return Err(MatError::TooLarge {
                what: "numbers",
                limit: MAX_NUMBERS,
            });
        }
        let be = self.big_endian;
        let b8 = |c: &[u8]| {
            let a = [c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]];
            if be {
                u64::from_be_bytes(a)
            } else {
                u64::from_le_bytes(a)
            }
        };
        let b2 = |c: &[u8]| {
            if be {
                u16::from_be_bytes([c[0], c[1]])
            } else {
                u16::from_le_bytes([c[0], c[1]])
            }
        };
        let it = raw.chunks_exact(size);
        Ok(match ty {
            MI_INT8 => it.map(|c| c[0] as i8 as f64).collect(),
            MI_UINT8 => it.map(|c| c[0] as f64).collect(),
            MI_INT16 => it.map(|c| b2(c) as i16 as f64).collect(),
            MI_UINT16 => it.map(|c| b2(c) as f64).collect(),
            MI_INT32 => it.map(|c| self.u32_at(c) as i32 as f64).collect(),
            MI_UINT32 => it.map(|c| self.u32_at(c) as f64).collect(),
            MI_SINGLE => it.map(|c| f32::from_bits(self.u32_at(c)) as f64).collect(),
            MI_DOUBLE => it.map(|c| f64::from_bits(b8(c))).collect(),
            MI_INT64 => it.map(|c| b8(c) as i64 as f64).collect(),
            _ => it.map(|c| b8(c) as f64).collect(),
        })
    }
}

fn class_name(class: u32) -> &'static str {
    match class {
        6 => "double",
        7 => "single",
        8 => "int8",
        9 => "uint8",
        10 => "int16",
        11 => "uint16",
        12 => "int32",
        13 => "uint32",
        14 => "int64",
        _ => "uint64",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A header with `mark` (`IM` little-endian, `MI` big-endian).
    fn header(mark: &[u8; 2]) -> Vec<u8> {
        let mut h = b"MATLAB 5.0 MAT-file, test".to_vec();
        h.resize(124, b' ');
        h.extend_from_slice(&[1, 0]);
        h.extend_from_slice(mark);
        h
    }

    #[test]
    fn big_endian_uncompressed_matrix() {
        // x = [1.5 -2], big-endian, its name in a small data element.
        let mut f = header(b"MI");
        let mut body = Vec::new();
        for w in [6u32, 8, 6, 0, 5, 8, 1, 2] {
            body.extend_from_slice(&w.to_be_bytes());
        }
        body.extend_from_slice(&((1u32 << 16) | 1).to_be_bytes()); // small element: 1 byte
        body.extend_from_slice(b"x\0\0\0");
        body.extend_from_slice(&9u32.to_be_bytes());
        body.extend_from_slice(&16u32.to_be_bytes());
        body.extend_from_slice(&1.5f64.to_be_bytes());
        body.extend_from_slice(&(-2.0f64).to_be_bytes());
        f.extend_from_slice(&14u32.to_be_bytes());
        f.extend_from_slice(&(body.len() as u32).to_be_bytes());
        f.extend(body);
        let m = parse_mat(&f).unwrap();
        match m.get("x") {
            Some(MatValue::Numeric(a)) => {
                assert_eq!(
                    (a.dims.as_slice(), a.real.as_slice()),
                    (&[1, 2][..], &[1.5, -2.0][..])
                )
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn clear_errors_for_other_files() {
        let e = parse_mat(b"\x89HDF\r\n\x1a\n").unwrap_err().to_string();
        assert!(e.contains("v7.3 (HDF5)") && e.contains("-v7"), "{e}");
        let e = parse_mat(b"time_s,u_V\n0,1\n").unwrap_err().to_string();
        assert!(e.contains("128-byte"), "{e}");
        let mut h = header(b"XX");
        h.extend_from_slice(&[0; 8]);
        assert!(parse_mat(&h).unwrap_err().to_string().contains("endian"));
        // A tag claiming more bytes than the file has.
        let mut h = header(b"IM");
        h.extend_from_slice(&14u32.to_le_bytes());
        h.extend_from_slice(&1000u32.to_le_bytes());
        let e = parse_mat(&h).unwrap_err().to_string();
        assert!(
            e.contains("at byte 128") && e.contains("claims 1000 bytes"),
            "{e}"
        );
        // A compressed element that is not zlib.
        let mut h = header(b"IM");
        h.extend_from_slice(&15u32.to_le_bytes());
        h.extend_from_slice(&4u32.to_le_bytes());
        h.extend_from_slice(b"junk");
        let e = parse_mat(&h).unwrap_err().to_string();
        assert!(e.contains("do not inflate"), "{e}");
        // An empty file body is an empty MAT-file.
        assert!(parse_mat(&header(b"IM")).unwrap().variables.is_empty());
    }
}
