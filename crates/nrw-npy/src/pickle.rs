//! Pickles numpy loads without this tool (protocol 3; numpy's own `ndarray.__reduce__` for
//! arrays, so numpy 1.x or 2.x rebuilds them): `dist_<name>.pckl`, the
//! `{'dist_matrix': float64 N × N}` the published pretraining (`pretrain_appearance.py`) loads
//! (protocol 4 past 4 GiB of data); MegaDepth's object arrays of dicts; and, through
//! [`Pickler`], the matcher trainers' index files (LoFTR's, RoMa's).

const PROTO: u8 = 0x80;
const EMPTY_DICT: u8 = b'}';
const BINUNICODE: u8 = b'X';
const GLOBAL: u8 = b'c';
const BININT: u8 = b'J';
const BININT1: u8 = b'K';
const MARK: u8 = b'(';
const TUPLE: u8 = b't';
const TUPLE1: u8 = 0x85;
const TUPLE2: u8 = 0x86;
const TUPLE3: u8 = 0x87;
const REDUCE: u8 = b'R';
const BUILD: u8 = b'b';
const NONE: u8 = b'N';
const NEWTRUE: u8 = 0x88;
const NEWFALSE: u8 = 0x89;
const SHORT_BINBYTES: u8 = b'C';
const BINBYTES: u8 = b'B';
const BINBYTES8: u8 = 0x8e;
const SETITEM: u8 = b's';
const SETITEMS: u8 = b'u';
const EMPTY_LIST: u8 = b']';
const EMPTY_TUPLE: u8 = b')';
const APPEND: u8 = b'a';
const APPENDS: u8 = b'e';
const BINFLOAT: u8 = b'G';
const LONG1: u8 = 0x8a;
const BINPUT: u8 = b'q';
const BINGET: u8 = b'h';
const STOP: u8 = b'.';

fn unicode(s: &str, out: &mut Vec<u8>) {
    out.push(BINUNICODE);
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

fn global(module: &str, name: &str, out: &mut Vec<u8>) {
    out.push(GLOBAL);
    out.extend_from_slice(format!("{module}\n{name}\n").as_bytes());
}

fn int(v: i32, out: &mut Vec<u8>) {
    if (0..256).contains(&v) {
        out.extend_from_slice(&[BININT1, v as u8]);
    } else {
        out.push(BININT);
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// `numpy.dtype('<f8')` as numpy pickles it.
fn dtype_f8(out: &mut Vec<u8>) {
    dtype("f8", "<", 0, out);
}

/// `numpy.dtype(name)` as numpy pickles it: byte order `endian` ("<", or "|" where it has
/// none) and numpy's flags (0 for numbers, 63 for objects).
fn dtype(name: &str, endian: &str, flags: i32, out: &mut Vec<u8>) {
    global("numpy", "dtype", out);
    unicode(name, out);
    out.extend_from_slice(&[NEWFALSE, NEWTRUE, TUPLE3, REDUCE, MARK]);
    int(3, out);
    unicode(endian, out);
    out.extend_from_slice(&[NONE, NONE, NONE]);
    int(-1, out);
    int(-1, out);
    int(flags, out);
    out.extend_from_slice(&[TUPLE, BUILD]);
}

/// An array's shape as the tuple of Python ints pickle writes.
fn shape_tuple(shape: &[usize], out: &mut Vec<u8>) {
    if shape.len() > 3 {
        out.push(MARK);
    }
    for d in shape {
        long(*d as u64, out);
    }
    out.push(match shape.len() {
        0 => EMPTY_TUPLE,
        1 => TUPLE1,
        2 => TUPLE2,
        3 => TUPLE3,
        _ => TUPLE,
    });
}

/// What `ndarray.__reduce__` pickles before the shape: the empty array
/// `numpy.core.multiarray._reconstruct(numpy.ndarray, (0,), b'b')`, then the opening of its
/// state `(1, ` (version), whose shape, dtype, order and data follow.
fn empty_ndarray(out: &mut Vec<u8>) {
    global("numpy.core.multiarray", "_reconstruct", out);
    global("numpy", "ndarray", out);
    int(0, out);
    out.push(TUPLE1);
    out.extend_from_slice(&[SHORT_BINBYTES, 1, b'b', TUPLE3, REDUCE]);
    out.push(MARK);
    int(1, out);
}

/// The pickle of `{key: n × n float64 array}` with `values` row-major (length n²).
pub fn matrix_dict(key: &str, n: usize, values: &[f64]) -> Vec<u8> {
    assert_eq!(values.len(), n * n, "an n × n matrix has n² values");
    let mut out = Vec::with_capacity(n * n * 8 + 512);
    let mut rows = |r: std::ops::Range<usize>| Ok(values[r.start * n..r.end * n].to_vec());
    write_matrix_dict(
        &mut out,
        key,
        n,
        n.max(1),
        &mut rows,
        &|e: std::io::Error| e,
    )
    .expect("writing into memory cannot fail");
    out
}

/// [`matrix_dict`] written to `w` block of `block` rows by block, as `rows` gives them:
/// memory holds one block, not the n² values.
/// `io` names the destination in a write error.
pub fn write_matrix_dict<E>(
    w: &mut dyn std::io::Write,
    key: &str,
    n: usize,
    block: usize,
    rows: &mut dyn FnMut(std::ops::Range<usize>) -> Result<Vec<f64>, E>,
    io: &dyn Fn(std::io::Error) -> E,
) -> Result<(), E> {
    let data_len = n * n * 8;
    let big = data_len > u32::MAX as usize;
    let mut out = Vec::with_capacity(512);
    out.extend_from_slice(&[PROTO, if big { 4 } else { 3 }, EMPTY_DICT]);
    unicode(key, &mut out);
    empty_ndarray(&mut out);
    // __setstate__((1, (n, n), dtype('<f8'), False, data))
    shape_tuple(&[n, n], &mut out);
    dtype_f8(&mut out);
    out.push(NEWFALSE);
    if big {
        out.push(BINBYTES8);
        out.extend_from_slice(&(data_len as u64).to_le_bytes());
    } else {
        out.push(BINBYTES);
        out.extend_from_slice(&(data_len as u32).to_le_bytes());
    }
    w.write_all(&out).map_err(io)?;
    for start in (0..n).step_by(block.max(1)) {
        let end = (start + block.max(1)).min(n);
        let values = rows(start..end)?;
        assert_eq!(
            values.len(),
            (end - start) * n,
            "a block of rows has n values a row"
        );
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        w.write_all(&bytes).map_err(io)?;
    }
    w.write_all(&[TUPLE, BUILD, SETITEM, STOP]).map_err(io)?;
    Ok(())
}

/// A value of one of MegaDepth's per-image dicts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DictValue {
    /// A Python list of two floats (`points3D_id_to_2D`'s `[x, y]`).
    Pair([f64; 2]),
    /// A `numpy.float64` scalar (`points3D_id_to_ndepth`'s values).
    Scalar(f64),
}

/// The pickle `np.save` writes for a 1-D object array whose items are `{int: value}` dicts
/// (protocol 3; the `numpy.core.multiarray` names numpy 1.x writes and 2.x still loads).
pub fn object_array_of_dicts(items: &[Vec<(u64, DictValue)>]) -> Vec<u8> {
    let mut out = vec![PROTO, 3];
    empty_ndarray(&mut out);
    // __setstate__((1, (n,), dtype('O'), False, [items]))
    shape_tuple(&[items.len()], &mut out);
    dtype("O8", "|", 63, &mut out);
    out.extend_from_slice(&[NEWFALSE, EMPTY_LIST]);
    let mut memo = false; // numpy's scalar constructor and dtype('f8') stored at 0 and 1
    if !items.is_empty() {
        out.push(MARK);
        for dict in items {
            out.push(EMPTY_DICT);
            if dict.is_empty() {
                continue;
            }
            out.push(MARK);
            for (k, v) in dict {
                long(*k, &mut out);
                value(*v, &mut memo, &mut out);
            }
            out.push(SETITEMS);
        }
        out.push(APPENDS);
    }
    out.extend_from_slice(&[TUPLE, BUILD, STOP]);
    out
}

/// An integer of any size up to 2⁶⁴ − 1 (LONG1 past BININT's range).
fn long(v: u64, out: &mut Vec<u8>) {
    if let Ok(small) = i32::try_from(v) {
        return int(small, out);
    }
    // Little-endian two's complement, with a zero byte when the top bit is set.
    let mut bytes = v.to_le_bytes().to_vec();
    while bytes.len() > 1 && bytes[bytes.len() - 1] == 0 && bytes[bytes.len() - 2] < 0x80 {
        bytes.pop();
    }
    if bytes[bytes.len() - 1] >= 0x80 {
        bytes.push(0);
    }
    out.extend_from_slice(&[LONG1, bytes.len() as u8]);
    out.extend_from_slice(&bytes);
}

/// One dict value; `memo` says whether the scalar constructor and dtype are memoised yet.
fn value(v: DictValue, memo: &mut bool, out: &mut Vec<u8>) {
    match v {
        DictValue::Pair(xy) => {
            out.extend_from_slice(&[EMPTY_LIST, MARK]);
            for x in xy {
                out.push(BINFLOAT);
                out.extend_from_slice(&x.to_be_bytes());
            }
            out.push(APPENDS);
        }
        DictValue::Scalar(x) => {
            if *memo {
                out.extend_from_slice(&[BINGET, 0, BINGET, 1]);
            } else {
                global("numpy.core.multiarray", "scalar", out);
                out.extend_from_slice(&[BINPUT, 0]);
                dtype_f8(out);
                out.extend_from_slice(&[BINPUT, 1]);
                *memo = true;
            }
            out.extend_from_slice(&[SHORT_BINBYTES, 8]);
            out.extend_from_slice(&x.to_le_bytes());
            out.extend_from_slice(&[TUPLE2, REDUCE]);
        }
    }
}

/// The element type of an ndarray a [`Pickler`] writes.
#[derive(Clone, Copy)]
pub enum Dtype {
    F8,
    I8,
}

/// A pickle written as it goes (protocol 3, numpy's own `ndarray.__reduce__` for arrays): what
/// the matcher trainers' index files hold — a dict of str keys whose values are lists of str,
/// float64 and int64 ndarrays (their data streamed), floats and tuples. The caller lays the
/// opcodes out in pickle's order: a value, then what combines it (`set_item`, `append`,
/// `tuple`).
pub struct Pickler<'w> {
    w: &'w mut dyn std::io::Write,
}

impl<'w> Pickler<'w> {
    /// Start a pickle on `w`.
    pub fn new(w: &'w mut dyn std::io::Write) -> std::io::Result<Self> {
        w.write_all(&[PROTO, 3])?;
        Ok(Pickler { w })
    }

    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.w.write_all(bytes)
    }

    /// An empty dict, which `set_item` fills.
    pub fn dict(&mut self) -> std::io::Result<()> {
        self.put(&[EMPTY_DICT])
    }

    /// A str (a dict key, or a value).
    pub fn str(&mut self, s: &str) -> std::io::Result<()> {
        let mut out = Vec::with_capacity(5 + s.len());
        unicode(s, &mut out);
        self.put(&out)
    }

    /// A Python float.
    pub fn float(&mut self, v: f64) -> std::io::Result<()> {
        let mut out = vec![BINFLOAT];
        out.extend_from_slice(&v.to_be_bytes());
        self.put(&out)
    }

    /// Store the last value under the key before it in the dict before that.
    pub fn set_item(&mut self) -> std::io::Result<()> {
        self.put(&[SETITEM])
    }

    /// An empty list, which `append` fills.
    pub fn list(&mut self) -> std::io::Result<()> {
        self.put(&[EMPTY_LIST])
    }

    /// Append the last value to the list before it.
    pub fn append(&mut self) -> std::io::Result<()> {
        self.put(&[APPEND])
    }

    /// The last three values as a tuple.
    pub fn tuple3(&mut self) -> std::io::Result<()> {
        self.put(&[TUPLE3])
    }

    /// A list of str.
    pub fn str_list(&mut self, items: &[String]) -> std::io::Result<()> {
        self.list()?;
        for s in items {
            self.str(s)?;
            self.append()?;
        }
        Ok(())
    }

    /// The opening of a C-order ndarray of `shape` whose `nbytes` bytes of little-endian data
    /// the caller writes next with `data`, then closes with `array_end`; refused past 4 GiB
    /// (protocol 3's bytes).
    pub fn array_begin(&mut self, dtype: Dtype, shape: &[usize]) -> std::io::Result<()> {
        let count: usize = shape.iter().product();
        let nbytes = u32::try_from(count * 8).map_err(|_| {
            std::io::Error::other("an array over 4 GiB in an index pickle is not written")
        })?;
        let mut out = Vec::with_capacity(256);
        empty_ndarray(&mut out);
        shape_tuple(shape, &mut out);
        match dtype {
            Dtype::F8 => self::dtype("f8", "<", 0, &mut out),
            Dtype::I8 => self::dtype("i8", "<", 0, &mut out),
        }
        out.push(NEWFALSE);
        out.push(BINBYTES);
        out.extend_from_slice(&nbytes.to_le_bytes());
        self.put(&out)
    }

    /// Data of the array `array_begin` opened.
    pub fn data(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.put(bytes)
    }

    /// Close the array `array_begin` opened.
    pub fn array_end(&mut self) -> std::io::Result<()> {
        self.put(&[TUPLE, BUILD])
    }

    /// A whole float64 ndarray.
    pub fn f8_array(&mut self, shape: &[usize], v: &[f64]) -> std::io::Result<()> {
        self.array_begin(Dtype::F8, shape)?;
        let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.data(&bytes)?;
        self.array_end()
    }

    /// A whole int64 ndarray.
    pub fn i8_array(&mut self, shape: &[usize], v: &[i64]) -> std::io::Result<()> {
        self.array_begin(Dtype::I8, shape)?;
        let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.data(&bytes)?;
        self.array_end()
    }

    /// The opening of a 0-d object ndarray (what `np.save` pickles for a dict): its one item
    /// comes next, then `object_scalar_end`.
    pub fn object_scalar_begin(&mut self) -> std::io::Result<()> {
        let mut out = Vec::with_capacity(160);
        empty_ndarray(&mut out);
        shape_tuple(&[], &mut out);
        dtype("O8", "|", 63, &mut out);
        out.extend_from_slice(&[NEWFALSE, EMPTY_LIST]);
        self.put(&out)
    }

    /// Close the 0-d object ndarray around the item just written.
    pub fn object_scalar_end(&mut self) -> std::io::Result<()> {
        self.put(&[APPEND, TUPLE, BUILD])
    }

    /// End the pickle.
    pub fn stop(&mut self) -> std::io::Result<()> {
        self.put(&[STOP])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_ids_are_encoded_as_python_pickles_them() {
        // pickle.dumps(v, 3)[2:-1] for each v.
        for (v, want) in [
            (7u64, vec![BININT1, 7]),
            (2u64.pow(31), vec![138, 5, 0, 0, 0, 128, 0]),
            (3_000_000_000, vec![138, 5, 0, 94, 208, 178, 0]),
            (2u64.pow(40) + 5, vec![138, 6, 5, 0, 0, 0, 0, 1]),
            (
                u64::MAX,
                vec![138, 9, 255, 255, 255, 255, 255, 255, 255, 255, 0],
            ),
        ] {
            let mut out = Vec::new();
            long(v, &mut out);
            assert_eq!(out, want, "{v}");
        }
    }

    #[test]
    fn the_matrix_bytes_are_in_the_pickle_row_major_little_endian() {
        let v = [0.0, 1.5, 1.5, 0.0];
        let p = matrix_dict("dist_matrix", 2, &v);
        assert_eq!(&p[..3], &[0x80, 3, b'}']);
        assert_eq!(*p.last().unwrap(), b'.');
        let raw: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        let at = p
            .windows(raw.len())
            .position(|w| w == raw.as_slice())
            .expect("data present");
        assert_eq!(p[at - 5], BINBYTES);
        assert_eq!(&p[at - 4..at], &32u32.to_le_bytes());
    }
}
