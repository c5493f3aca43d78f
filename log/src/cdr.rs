//! CDR (XCDR1, as ROS 2 writes it): a 4-byte encapsulation header (`00 01 00 00` little endian,
//! `00 00 00 00` big endian), then the fields, each aligned to its size counted from the end of
//! the header; strings as u32 length (with the NUL) + bytes + NUL; sequences as u32 count +
//! elements; fixed arrays without a count.
//!
//! [`CdrReader`] and [`CdrWriter`] are the byte-level pieces used by the typed fast paths;
//! [`decode`] turns any message into a [`Value`] tree from its parsed [`MsgDefs`].

use super::msgdef::{Arity, FieldType, MsgDefs, Primitive};

/// Why a CDR payload could not be decoded; turned into [`crate::Error::Decode`] with the topic.
#[derive(Debug, Clone, PartialEq)]
pub struct CdrError {
    /// Byte offset in the message (encapsulation header included).
    pub offset: usize,
    /// What went wrong.
    pub message: String,
}

type CdrResult<T> = std::result::Result<T, CdrError>;

/// Reads primitives from a CDR payload.
pub struct CdrReader<'a> {
    buf: &'a [u8],
    pos: usize,
    little_endian: bool,
}

/// The aligned primitives, by size in bytes: `CdrReader::u32` reads one (in the message's
/// byte order), `CdrWriter::u32` writes one (little-endian), for every type named here.
macro_rules! primitives {
    ($($n:literal => $($t:ident),+;)+) => {
        impl CdrReader<'_> {
            $($(
                /// Reads one aligned value.
                #[inline]
                pub fn $t(&mut self) -> CdrResult<$t> {
                    let b = self.take_aligned($n, $n)?;
                    let arr: [u8; $n] = b.try_into().expect("take_aligned returns exactly n bytes");
                    Ok(if self.little_endian { <$t>::from_le_bytes(arr) } else { <$t>::from_be_bytes(arr) })
                }
            )+)+
        }

        impl CdrWriter {
            $($(
                /// Writes one value, aligned, little-endian.
                pub fn $t(&mut self, v: $t) {
                    self.align($n);
                    self.buf.extend_from_slice(&v.to_le_bytes());
                }
            )+)+
        }
    };
}

primitives! {
    2 => u16, i16;
    4 => u32, i32, f32;
    8 => u64, i64, f64;
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header and positions after it.
    pub fn new(buf: &'a [u8]) -> CdrResult<Self> {
        if buf.len() < 4 {
            return Err(CdrError {
                offset: 0,
                message: format!("message is {} bytes, shorter than the 4-byte CDR header", buf.len()),
            });
        }
        let little_endian = match (buf[0], buf[1]) {
            (0, 1) => true,
            (0, 0) => false,
            (a, b) => {
                return Err(CdrError {
                    offset: 0,
                    message: format!(
                        "encapsulation {a:02x} {b:02x} is not plain CDR (00 00 or 00 01); \
                         parameter-list (XCDR2/PL_CDR) messages are not supported"
                    ),
                });
            }
        };
        Ok(Self { buf, pos: 4, little_endian })
    }

    /// Byte offset in the message.
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Bytes left.
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    #[inline]
    fn align(&mut self, n: usize) {
        // Alignment is relative to the end of the 4-byte header.
        let rel = self.pos - 4;
        self.pos += (n - rel % n) % n;
    }

    #[inline]
    fn take_aligned(&mut self, align: usize, len: usize) -> CdrResult<&'a [u8]> {
        self.align(align);
        let end = self.pos.checked_add(len).filter(|&e| e <= self.buf.len());
        match end {
            Some(end) => {
                let s = &self.buf[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err(self.short(len)),
        }
    }

    fn short(&self, len: usize) -> CdrError {
        CdrError {
            offset: self.pos.min(self.buf.len()),
            message: format!(
                "message ends early: needed {len} bytes at offset {}, message has {}",
                self.pos,
                self.buf.len()
            ),
        }
    }

    /// One byte.
    #[inline]
    pub fn u8(&mut self) -> CdrResult<u8> {
        Ok(self.take_aligned(1, 1)?[0])
    }

    /// A sequence length, sanity-checked against the bytes left so a corrupt count cannot make
    /// us allocate gigabytes.
    #[inline]
    pub fn seq_len(&mut self, min_elem_size: usize) -> CdrResult<usize> {
        let at = self.pos;
        let n = self.u32()? as usize;
        if n.saturating_mul(min_elem_size) > self.remaining() {
            return Err(CdrError {
                offset: at,
                message: format!("sequence count {n} needs more bytes than the {} left", self.remaining()),
            });
        }
        Ok(n)
    }

    /// A string (u32 length including the NUL, bytes, NUL).
    pub fn string(&mut self) -> CdrResult<&'a str> {
        let at = self.pos;
        let n = self.seq_len(1)?;
        let bytes = self.take_aligned(1, n)?;
        // Length 0 is what some writers emit for an empty string.
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        std::str::from_utf8(text).map_err(|e| CdrError { offset: at, message: format!("string is not UTF-8: {e}") })
    }

    /// `n` f64 values (fixed array or sequence body).
    pub fn f64_array(&mut self, n: usize, out: &mut Vec<f64>) -> CdrResult<()> {
        out.clear();
        if n == 0 {
            return Ok(());
        }
        let bytes = self.take_aligned(8, n * 8)?;
        out.reserve(n);
        let le = self.little_endian;
        out.extend(bytes.chunks_exact(8).map(|c| {
            let a: [u8; 8] = c.try_into().expect("chunks_exact(8)");
            if le { f64::from_le_bytes(a) } else { f64::from_be_bytes(a) }
        }));
        Ok(())
    }

    /// A `float64[]` sequence.
    pub fn f64_seq(&mut self, out: &mut Vec<f64>) -> CdrResult<()> {
        let n = self.seq_len(8)?;
        self.f64_array(n, out)
    }

    /// A `uint8[]` sequence, borrowed.
    pub fn bytes(&mut self) -> CdrResult<&'a [u8]> {
        let n = self.seq_len(1)?;
        self.take_aligned(1, n)
    }

    /// A `float32[]` sequence.
    pub fn f32_seq(&mut self, out: &mut Vec<f32>) -> CdrResult<()> {
        let n = self.seq_len(4)?;
        out.clear();
        if n == 0 {
            return Ok(());
        }
        let bytes = self.take_aligned(4, n * 4)?;
        let le = self.little_endian;
        out.extend(bytes.chunks_exact(4).map(|c| {
            let a: [u8; 4] = c.try_into().expect("chunks_exact(4)");
            if le { f32::from_le_bytes(a) } else { f32::from_be_bytes(a) }
        }));
        Ok(())
    }

    /// A fixed `float64[N]`.
    pub fn f64_fixed<const N: usize>(&mut self) -> CdrResult<[f64; N]> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64()?;
        }
        Ok(out)
    }
}

/// Appends CDR (little endian) to a buffer that starts with the encapsulation header.
#[derive(Debug, Default, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl CdrWriter {
    /// A writer whose buffer holds the little-endian encapsulation header.
    pub fn new() -> Self {
        let mut w = Self { buf: Vec::with_capacity(256) };
        w.reset();
        w
    }

    /// Clears the buffer back to the header, keeping its capacity.
    pub fn reset(&mut self) {
        self.buf.clear();
        self.buf.extend_from_slice(&[0, 1, 0, 0]);
    }

    /// The encoded message.
    pub fn bytes(&self) -> &[u8] {
        &self.buf
    }

    #[inline]
    fn align(&mut self, n: usize) {
        let rel = self.buf.len() - 4;
        let pad = (n - rel % n) % n;
        self.buf.extend(std::iter::repeat_n(0u8, pad));
    }

    /// One byte.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    /// A fixed `uint8[N]` (no count).
    pub fn u8_fixed(&mut self, v: &[u8]) {
        self.buf.extend_from_slice(v);
    }
    /// A `uint8[]` (count, then the bytes).
    pub fn u8_seq(&mut self, v: &[u8]) {
        self.seq_len(v.len());
        self.buf.extend_from_slice(v);
    }
    /// A `float32[]`.
    pub fn f32_seq(&mut self, v: &[f32]) {
        self.seq_len(v.len());
        self.buf.reserve(v.len() * 4);
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    /// A string with its length (including the NUL) and NUL.
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    /// A sequence count.
    pub fn seq_len(&mut self, n: usize) {
        self.u32(n as u32);
    }
    /// A `float64[]`.
    pub fn f64_seq(&mut self, v: &[f64]) {
        self.seq_len(v.len());
        self.f64_fixed(v);
    }
    /// A `float64[]` of `n` values from an iterator (no intermediate vector).
    pub fn f64_seq_iter(&mut self, n: usize, values: impl IntoIterator<Item = f64>) {
        self.seq_len(n);
        if n == 0 {
            return;
        }
        self.align(8);
        self.buf.reserve(n * 8);
        let mut written = 0;
        for x in values.into_iter().take(n) {
            self.buf.extend_from_slice(&x.to_le_bytes());
            written += 1;
        }
        assert_eq!(written, n, "f64_seq_iter: the iterator gave fewer values than announced");
    }
    /// A fixed `float64[N]` (no count).
    pub fn f64_fixed(&mut self, v: &[f64]) {
        if v.is_empty() {
            return;
        }
        self.align(8);
        self.buf.reserve(v.len() * 8);
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    /// `builtin_interfaces/Time` from nanoseconds.
    pub fn time(&mut self, stamp_nanos: i64) {
        self.i32(stamp_nanos.div_euclid(1_000_000_000) as i32);
        self.u32(stamp_nanos.rem_euclid(1_000_000_000) as u32);
    }
    /// `std_msgs/Header`.
    pub fn header(&mut self, stamp_nanos: i64, frame_id: &str) {
        self.time(stamp_nanos);
        self.string(frame_id);
    }
}

/// A decoded message, generically.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// `bool`.
    Bool(bool),
    /// Signed integers.
    Int(i64),
    /// Unsigned integers.
    UInt(u64),
    /// `float32` / `float64`.
    Float(f64),
    /// `string`.
    String(String),
    /// `uint8[]` / `byte[]` / `uint8[N]`.
    Bytes(Vec<u8>),
    /// Any other array.
    Array(Vec<Value>),
    /// A message: field names and values in definition order.
    Struct(Vec<(String, Value)>),
}

impl Value {
    /// A field by dotted path (`header.stamp.sec`, `pose.pose.position.x`).
    pub fn get(&self, path: &str) -> Option<&Value> {
        let mut v = self;
        for part in path.split('.') {
            match v {
                Value::Struct(fields) => {
                    v = &fields.iter().find(|(n, _)| n == part)?.1;
                }
                Value::Array(items) => v = items.get(part.parse::<usize>().ok()?)?,
                _ => return None,
            }
        }
        Some(v)
    }

    /// Numeric value as f64.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Value::Float(f) => Some(f),
            Value::Int(i) => Some(i as f64),
            Value::UInt(u) => Some(u as f64),
            Value::Bool(b) => Some(f64::from(u8::from(b))),
            _ => None,
        }
    }

    /// Integer value.
    pub fn as_i64(&self) -> Option<i64> {
        match *self {
            Value::Int(i) => Some(i),
            Value::UInt(u) => i64::try_from(u).ok(),
            _ => None,
        }
    }

    /// String value.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(s) => Some(s),
            _ => None,
        }
    }

    /// Array of numbers as f64.
    pub fn as_f64_vec(&self) -> Option<Vec<f64>> {
        match self {
            Value::Array(items) => items.iter().map(Value::as_f64).collect(),
            Value::Bytes(b) => Some(b.iter().map(|&x| f64::from(x)).collect()),
            _ => None,
        }
    }
}

/// Decodes a whole message of the root type of `defs`.
///
/// # Errors
/// A [`CdrError`] with the byte offset when the payload is shorter than the definition needs
/// or holds an invalid string.
pub fn decode(defs: &MsgDefs, data: &[u8]) -> CdrResult<Value> {
    let mut r = CdrReader::new(data)?;
    decode_struct(defs, 0, &mut r)
}

fn decode_struct(defs: &MsgDefs, t: usize, r: &mut CdrReader) -> CdrResult<Value> {
    let ty = &defs.types[t];
    if ty.fields.is_empty() {
        // ROS 2 gives empty messages one `uint8 structure_needs_at_least_one_member`.
        r.u8()?;
        return Ok(Value::Struct(Vec::new()));
    }
    let mut out = Vec::with_capacity(ty.fields.len());
    for f in &ty.fields {
        let v = match f.arity {
            Arity::Single => decode_one(defs, &f.ty, r)?,
            Arity::Fixed(n) => decode_array(defs, &f.ty, n, r)?,
            Arity::Sequence { .. } => {
                let min = match f.ty {
                    FieldType::Primitive(p) => p.size().min(4),
                    FieldType::Message(_) => 1,
                };
                let n = r.seq_len(min.max(1))?;
                decode_array(defs, &f.ty, n, r)?
            }
        };
        out.push((f.name.clone(), v));
    }
    Ok(Value::Struct(out))
}

fn decode_array(defs: &MsgDefs, ty: &FieldType, n: usize, r: &mut CdrReader) -> CdrResult<Value> {
    if let FieldType::Primitive(Primitive::U8) = ty {
        let b = r.take_aligned(1, n)?;
        return Ok(Value::Bytes(b.to_vec()));
    }
    let mut items = Vec::with_capacity(n.min(r.remaining()));
    for _ in 0..n {
        items.push(decode_one(defs, ty, r)?);
    }
    Ok(Value::Array(items))
}

fn decode_one(defs: &MsgDefs, ty: &FieldType, r: &mut CdrReader) -> CdrResult<Value> {
    Ok(match ty {
        FieldType::Message(i) => decode_struct(defs, *i, r)?,
        FieldType::Primitive(p) => match p {
            Primitive::Bool => Value::Bool(r.u8()? != 0),
            Primitive::U8 => Value::UInt(u64::from(r.u8()?)),
            Primitive::I8 => Value::Int(i64::from(r.u8()? as i8)),
            Primitive::I16 => Value::Int(i64::from(r.i16()?)),
            Primitive::U16 => Value::UInt(u64::from(r.u16()?)),
            Primitive::I32 => Value::Int(i64::from(r.i32()?)),
            Primitive::U32 => Value::UInt(u64::from(r.u32()?)),
            Primitive::I64 => Value::Int(r.i64()?),
            Primitive::U64 => Value::UInt(r.u64()?),
            Primitive::F32 => Value::Float(f64::from(r.f32()?)),
            Primitive::F64 => Value::Float(r.f64()?),
            Primitive::String => Value::String(r.string()?.to_string()),
            Primitive::WString => {
                return Err(CdrError { offset: r.position(), message: "wstring fields are not supported".into() });
            }
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alignment_is_relative_to_the_header() {
        // uint8 a; float64 b -> b starts at payload offset 8 (file offset 12).
        let defs = MsgDefs::parse("p/T", "uint8 a\nfloat64 b\n").unwrap();
        let mut bytes = vec![0, 1, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0];
        bytes.extend_from_slice(&2.5f64.to_le_bytes());
        let v = decode(&defs, &bytes).unwrap();
        assert_eq!(v.get("a"), Some(&Value::UInt(7)));
        assert_eq!(v.get("b"), Some(&Value::Float(2.5)));
    }

    #[test]
    fn big_endian_and_fixed_arrays() {
        let defs = MsgDefs::parse("p/T", "int16[2] a\nstring s\nint32[] c\n").unwrap();
        let mut bytes = vec![0, 0, 0, 0];
        bytes.extend_from_slice(&(-2i16).to_be_bytes());
        bytes.extend_from_slice(&300i16.to_be_bytes());
        bytes.extend_from_slice(&3u32.to_be_bytes());
        bytes.extend_from_slice(b"hi\0");
        bytes.push(0); // pad to 4
        bytes.extend_from_slice(&1u32.to_be_bytes());
        bytes.extend_from_slice(&(-9i32).to_be_bytes());
        let v = decode(&defs, &bytes).unwrap();
        assert_eq!(v.get("a"), Some(&Value::Array(vec![Value::Int(-2), Value::Int(300)])));
        assert_eq!(v.get("s").and_then(Value::as_str), Some("hi"));
        assert_eq!(v.get("c.0"), Some(&Value::Int(-9)));
    }

    #[test]
    fn short_payload_reports_offset() {
        let defs = MsgDefs::parse("p/T", "float64 a\nfloat64 b\n").unwrap();
        let mut bytes = vec![0, 1, 0, 0];
        bytes.extend_from_slice(&1.0f64.to_le_bytes());
        let err = decode(&defs, &bytes).unwrap_err();
        assert_eq!(err.offset, 12);
    }

    #[test]
    fn huge_sequence_count_is_refused_without_allocating() {
        let defs = MsgDefs::parse("p/T", "float64[] a\n").unwrap();
        let bytes = [0, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f];
        assert!(decode(&defs, &bytes).is_err());
    }
}
