//! The pickle interpreter behind `vgg16.npy`: the opcodes NumPy's pickles use, interpreted
//! into plain values over an arena, with exactly the globals that rebuild an ndarray and its
//! dtype allowed (any other refused by name) and every length checked against the bytes left
//! before anything is allocated. Nothing is ever called.

use std::collections::BTreeMap;

use super::array::{F32Array, NpyError};

/// What a pickled value is, once interpreted without calling anything.
#[derive(Debug, Clone)]
pub(super) enum Obj {
    None,
    Bool(bool),
    Int(i64),
    Float,
    /// Text: Python 3 `str`, or a Python 2 `str` read as Latin-1 (as `np.load(encoding='latin1')`).
    Str(String),
    /// A byte payload, as a range of the file (no copy).
    Bytes(std::ops::Range<usize>),
    Tuple(Vec<usize>),
    List(Vec<usize>),
    Dict(Vec<(usize, usize)>),
    /// One of the allowed globals.
    Global(Allowed),
    /// `callable(*args)`, kept symbolic; `state` is what a later BUILD gave it.
    Call {
        callable: Allowed,
        args: usize,
        state: Option<usize>,
    },
    Mark,
}

/// The only globals a NumPy array's pickle needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Allowed {
    Reconstruct,
    Ndarray,
    Dtype,
    FromBuffer,
}

fn allowed(module: &str, name: &str) -> Option<Allowed> {
    let numpy_core = matches!(module, "numpy.core.multiarray" | "numpy._core.multiarray");
    let numeric = matches!(module, "numpy.core.numeric" | "numpy._core.numeric");
    match (module, name) {
        (_, "_reconstruct") if numpy_core => Some(Allowed::Reconstruct),
        (_, "_frombuffer") if numeric => Some(Allowed::FromBuffer),
        ("numpy", "ndarray") => Some(Allowed::Ndarray),
        ("numpy", "dtype") => Some(Allowed::Dtype),
        _ => None,
    }
}

/// Largest number of opcodes interpreted: far above a VGG's few hundred, a bound on a hostile file.
const MAX_OPS: usize = 10_000_000;

/// A pickle interpreter over an arena of [`Obj`]s: the stack and the memo hold indices, so a
/// BUILD or SETITEMS on a memoised object is seen by every later reference to it.
pub(super) struct Vm<'a> {
    b: &'a [u8],
    at: usize,
    end: usize,
    pub(super) objs: Vec<Obj>,
    stack: Vec<usize>,
    memo: BTreeMap<u32, usize>,
}

impl<'a> Vm<'a> {
    pub(super) fn new(b: &'a [u8], body: std::ops::Range<usize>) -> Vm<'a> {
        Vm {
            b,
            at: body.start,
            end: body.end,
            objs: Vec::new(),
            stack: Vec::new(),
            memo: BTreeMap::new(),
        }
    }

    fn take(&mut self, n: usize) -> Result<std::ops::Range<usize>, NpyError> {
        if n > self.end - self.at {
            return Err(format!(
                "pickle at byte {}: a length of {n} runs past the end of the file",
                self.at
            ));
        }
        let r = self.at..self.at + n;
        self.at += n;
        Ok(r)
    }

    fn u8(&mut self) -> Result<u8, NpyError> {
        Ok(self.b[self.take(1)?.start])
    }

    fn le<const N: usize>(&mut self) -> Result<[u8; N], NpyError> {
        let r = self.take(N)?;
        Ok(self.b[r].try_into().expect("N bytes"))
    }

    fn line(&mut self) -> Result<String, NpyError> {
        let rest = &self.b[self.at..self.end];
        let n = rest
            .iter()
            .position(|&c| c == b'\n')
            .ok_or("pickle: a GLOBAL's name has no end of line")?;
        let s = String::from_utf8_lossy(&rest[..n]).into_owned();
        self.at += n + 1;
        Ok(s)
    }

    fn push(&mut self, o: Obj) {
        self.objs.push(o);
        self.stack.push(self.objs.len() - 1);
    }

    fn pop(&mut self) -> Result<usize, NpyError> {
        self.stack
            .pop()
            .ok_or_else(|| format!("pickle at byte {}: the stack is empty", self.at))
    }

    fn top(&self) -> Result<usize, NpyError> {
        self.stack
            .last()
            .copied()
            .ok_or_else(|| format!("pickle at byte {}: the stack is empty", self.at))
    }

    /// Everything above the last MARK, which is removed.
    fn pop_mark(&mut self) -> Result<Vec<usize>, NpyError> {
        let m = self
            .stack
            .iter()
            .rposition(|&i| matches!(self.objs[i], Obj::Mark))
            .ok_or_else(|| format!("pickle at byte {}: no MARK to pop to", self.at))?;
        let items = self.stack.split_off(m + 1);
        self.stack.pop();
        Ok(items)
    }

    fn bytes(&mut self, n: usize) -> Result<(), NpyError> {
        let r = self.take(n)?;
        self.push(Obj::Bytes(r));
        Ok(())
    }

    fn unicode(&mut self, n: usize) -> Result<(), NpyError> {
        let r = self.take(n)?;
        let s = std::str::from_utf8(&self.b[r])
            .map_err(|_| format!("pickle at byte {}: a string is not UTF-8", self.at))?;
        self.push(Obj::Str(s.into()));
        Ok(())
    }

    fn global(&mut self, module: &str, name: &str) -> Result<(), NpyError> {
        let g = allowed(module, name).ok_or_else(|| {
            format!(
                "the pickle names `{module}.{name}`; a weights file needs only NumPy's array globals, so it is refused (nothing in it was run)"
            )
        })?;
        self.push(Obj::Global(g));
        Ok(())
    }

    fn len_u32(&mut self) -> Result<usize, NpyError> {
        Ok(u32::from_le_bytes(self.le()?) as usize)
    }

    fn len_u64(&mut self) -> Result<usize, NpyError> {
        usize::try_from(u64::from_le_bytes(self.le()?))
            .map_err(|_| "pickle: a length does not fit in memory".into())
    }

    /// Interpret up to STOP; the value left on the stack.
    pub(super) fn run(&mut self) -> Result<usize, NpyError> {
        for _ in 0..MAX_OPS {
            let at = self.at;
            let op = self.u8()?;
            if op == b'.' {
                return self.pop();
            }
            let known = self.value(op, at)?
                || self.text_op(op, at)?
                || self.container(op, at)?
                || self.memo_or_call(op, at)?;
            if !known {
                return Err(format!(
                    "pickle at byte {at}: opcode 0x{op:02x} is not one NumPy's array pickles use"
                ));
            }
        }
        Err(format!("pickle: more than {MAX_OPS} opcodes"))
    }

    /// Protocol, frame, constants, integers and floats; whether `op` is one of them.
    fn value(&mut self, op: u8, at: usize) -> Result<bool, NpyError> {
        match op {
            0x80 => {
                self.u8()?; // PROTO
            }
            0x95 => {
                self.le::<8>()?; // FRAME: a hint only
            }
            b'(' => self.push(Obj::Mark),
            b'N' => self.push(Obj::None),
            0x88 => self.push(Obj::Bool(true)),
            0x89 => self.push(Obj::Bool(false)),
            b'K' => {
                let v = self.u8()?;
                self.push(Obj::Int(v as i64))
            }
            b'M' => {
                let v = u16::from_le_bytes(self.le()?);
                self.push(Obj::Int(v as i64))
            }
            b'J' => {
                let v = i32::from_le_bytes(self.le()?);
                self.push(Obj::Int(v as i64))
            }
            0x8a => {
                let n = self.u8()? as usize;
                let r = self.take(n)?;
                if n > 8 {
                    return Err(format!("pickle at byte {at}: an integer of {n} bytes"));
                }
                let mut v: i64 = 0;
                for (i, &c) in self.b[r.clone()].iter().enumerate() {
                    v |= (c as i64) << (8 * i);
                }
                if n > 0 && n < 8 && self.b[r.end - 1] & 0x80 != 0 {
                    v -= 1i64 << (8 * n);
                }
                self.push(Obj::Int(v))
            }
            b'G' => {
                self.le::<8>()?; // a float: no weights file needs its value
                self.push(Obj::Float)
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// Strings, bytes and globals; whether `op` is one of them.
    fn text_op(&mut self, op: u8, at: usize) -> Result<bool, NpyError> {
        match op {
            // Python 2 `str` (SHORT_BINSTRING, BINSTRING) and bytes: payloads.
            b'U' | b'C' => {
                let n = self.u8()? as usize;
                self.bytes(n)?
            }
            b'T' | b'B' => {
                let n = self.len_u32()?;
                self.bytes(n)?
            }
            0x8e | 0x96 => {
                let n = self.len_u64()?;
                self.bytes(n)?
            }
            0x8c => {
                let n = self.u8()? as usize;
                self.unicode(n)?
            }
            b'X' => {
                let n = self.len_u32()?;
                self.unicode(n)?
            }
            0x8d => {
                let n = self.len_u64()?;
                self.unicode(n)?
            }
            b'c' => {
                let (m, n) = (self.line()?, self.line()?);
                self.global(&m, &n)?
            }
            0x93 => {
                let (n, m) = (self.pop()?, self.pop()?);
                let (Some(m), Some(n)) = (self.text(m), self.text(n)) else {
                    return Err(format!("pickle at byte {at}: STACK_GLOBAL of non-text"));
                };
                self.global(&m, &n)?
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// Tuples, lists and dicts, built and extended; whether `op` is one of them.
    fn container(&mut self, op: u8, at: usize) -> Result<bool, NpyError> {
        match op {
            b')' => self.push(Obj::Tuple(vec![])),
            b']' => self.push(Obj::List(vec![])),
            b'}' => self.push(Obj::Dict(vec![])),
            b't' => {
                let items = self.pop_mark()?;
                self.push(Obj::Tuple(items))
            }
            b'l' => {
                let items = self.pop_mark()?;
                self.push(Obj::List(items))
            }
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                if self.stack.len() < n {
                    return Err(format!("pickle at byte {at}: TUPLE{n} on a short stack"));
                }
                let items = self.stack.split_off(self.stack.len() - n);
                self.push(Obj::Tuple(items))
            }
            b'a' => {
                let v = self.pop()?;
                let l = self.top()?;
                self.list_mut(l, at)?.push(v)
            }
            b'e' => {
                let items = self.pop_mark()?;
                let l = self.top()?;
                self.list_mut(l, at)?.extend(items)
            }
            b'd' => {
                let items = self.pop_mark()?;
                let pairs = pairs(&items, at)?;
                self.push(Obj::Dict(pairs))
            }
            b's' => {
                let v = self.pop()?;
                let k = self.pop()?;
                let d = self.top()?;
                self.dict_mut(d, at)?.push((k, v))
            }
            b'u' => {
                let items = self.pop_mark()?;
                let p = pairs(&items, at)?;
                let d = self.top()?;
                self.dict_mut(d, at)?.extend(p)
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// The memo, calls and BUILD; whether `op` is one of them.
    fn memo_or_call(&mut self, op: u8, at: usize) -> Result<bool, NpyError> {
        match op {
            b'q' => {
                let k = self.u8()? as u32;
                self.memo.insert(k, self.top()?);
            }
            b'r' => {
                let k = u32::from_le_bytes(self.le()?);
                self.memo.insert(k, self.top()?);
            }
            0x94 => {
                let k = self.memo.len() as u32;
                self.memo.insert(k, self.top()?);
            }
            b'h' | b'j' => {
                let k = if op == b'h' {
                    self.u8()? as u32
                } else {
                    u32::from_le_bytes(self.le()?)
                };
                let i = *self
                    .memo
                    .get(&k)
                    .ok_or_else(|| format!("pickle at byte {at}: memo {k} was never stored"))?;
                self.stack.push(i)
            }
            b'R' | 0x81 => {
                let args = self.pop()?;
                let f = self.pop()?;
                let Obj::Global(callable) = self.objs[f] else {
                    return Err(format!("pickle at byte {at}: a call of {}", self.kind(f)));
                };
                self.push(Obj::Call {
                    callable,
                    args,
                    state: None,
                })
            }
            b'b' => {
                let s = self.pop()?;
                let o = self.top()?;
                match &mut self.objs[o] {
                    Obj::Call { state, .. } => *state = Some(s),
                    _ => return Err(format!("pickle at byte {at}: BUILD on a plain value")),
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    fn list_mut(&mut self, i: usize, at: usize) -> Result<&mut Vec<usize>, NpyError> {
        match &mut self.objs[i] {
            Obj::List(v) => Ok(v),
            _ => Err(format!("pickle at byte {at}: APPEND to a non-list")),
        }
    }

    fn dict_mut(&mut self, i: usize, at: usize) -> Result<&mut Vec<(usize, usize)>, NpyError> {
        match &mut self.objs[i] {
            Obj::Dict(v) => Ok(v),
            _ => Err(format!("pickle at byte {at}: SETITEM on a non-dict")),
        }
    }

    /// Text of a str, or of a Python 2 str (bytes) read as Latin-1.
    pub(super) fn text(&self, i: usize) -> Option<String> {
        match &self.objs[i] {
            Obj::Str(s) => Some(s.clone()),
            Obj::Bytes(r) => Some(self.b[r.clone()].iter().map(|&c| c as char).collect()),
            _ => None,
        }
    }

    pub(super) fn kind(&self, i: usize) -> &'static str {
        match &self.objs[i] {
            Obj::None => "None",
            Obj::Bool(_) => "a bool",
            Obj::Int(_) => "an int",
            Obj::Float => "a float",
            Obj::Str(_) => "a str",
            Obj::Bytes(_) => "bytes",
            Obj::Tuple(_) => "a tuple",
            Obj::List(_) => "a list",
            Obj::Dict(_) => "a dict",
            Obj::Global(_) => "a global",
            Obj::Call { .. } => "an object",
            Obj::Mark => "a MARK",
        }
    }

    fn tuple(&self, i: usize) -> Option<&[usize]> {
        match &self.objs[i] {
            Obj::Tuple(v) => Some(v),
            _ => None,
        }
    }

    fn int(&self, i: usize) -> Option<i64> {
        match self.objs[i] {
            Obj::Int(v) => Some(v),
            _ => None,
        }
    }

    /// (dtype string, byte order) of a `numpy.dtype(...)` object.
    fn dtype(&self, i: usize) -> Result<(String, String), NpyError> {
        let Obj::Call {
            callable: Allowed::Dtype,
            args,
            state,
        } = &self.objs[i]
        else {
            return Err(format!("its dtype is {}", self.kind(i)));
        };
        let name = self
            .tuple(*args)
            .and_then(|a| a.first())
            .and_then(|&a| self.text(a))
            .ok_or("its dtype has no name")?;
        let order = state
            .and_then(|s| self.tuple(s).map(|t| t.to_vec()))
            .and_then(|t| t.get(1).and_then(|&o| self.text(o)))
            .unwrap_or_else(|| "|".into());
        Ok((name, order))
    }

    /// (shape, dtype object, data object) of a `_reconstruct(ndarray, …)` after its BUILD.
    fn ndarray_state(&self, i: usize) -> Result<(Vec<usize>, usize, usize), NpyError> {
        let Obj::Call {
            callable: Allowed::Reconstruct,
            args,
            state: Some(state),
        } = &self.objs[i]
        else {
            return Err(format!("{} where an ndarray was expected", self.kind(i)));
        };
        let a = self.tuple(*args).unwrap_or(&[]);
        if !matches!(
            a.first().map(|&c| &self.objs[c]),
            Some(Obj::Global(Allowed::Ndarray))
        ) {
            return Err("an _reconstruct of something other than numpy.ndarray".into());
        }
        let s = self
            .tuple(*state)
            .ok_or("an ndarray state that is not a tuple")?;
        if s.len() != 5 {
            return Err(format!("an ndarray state of {} items, not 5", s.len()));
        }
        if matches!(self.objs[s[3]], Obj::Bool(true)) {
            return Err("a Fortran-ordered array (tensorflow-vgg writes C order)".into());
        }
        let shape = self
            .tuple(s[1])
            .ok_or("an ndarray shape that is not a tuple")?
            .iter()
            .map(|&d| {
                self.int(d)
                    .and_then(|v| usize::try_from(v).ok())
                    .ok_or("a negative or non-integer dimension")
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok((shape, s[2], s[4]))
    }

    /// The one element of a 0-d object array.
    pub(super) fn object_array_item(&self, i: usize) -> Result<usize, NpyError> {
        let (shape, dtype, data) = self.ndarray_state(i)?;
        let (name, _) = self.dtype(dtype)?;
        if !shape.is_empty() || name != "O8" && name != "O4" {
            return Err(format!(
                "the pickle holds a {name} array of shape {shape:?}, not the 0-d object array tensorflow-vgg writes"
            ));
        }
        match &self.objs[data] {
            Obj::List(v) if v.len() == 1 => Ok(v[0]),
            _ => Err("the object array holds no single element".into()),
        }
    }

    /// A float32 ndarray, by `_reconstruct` (protocols 2–4) or `_frombuffer` (protocol 5).
    pub(super) fn f32_array(&self, i: usize) -> Result<F32Array, NpyError> {
        let (shape, dtype, data) = match &self.objs[i] {
            Obj::Call {
                callable: Allowed::FromBuffer,
                args,
                ..
            } => {
                let a = self.tuple(*args).ok_or("a _frombuffer without arguments")?;
                let [buf, dt, shape, order] = a else {
                    return Err("a _frombuffer of other than 4 arguments".into());
                };
                if self.text(*order).as_deref() != Some("C") {
                    return Err("a Fortran-ordered array (tensorflow-vgg writes C order)".into());
                }
                let shape = self
                    .tuple(*shape)
                    .ok_or("a shape that is not a tuple")?
                    .iter()
                    .map(|&d| self.int(d).and_then(|v| usize::try_from(v).ok()))
                    .collect::<Option<Vec<_>>>()
                    .ok_or("a negative or non-integer dimension")?;
                (shape, *dt, *buf)
            }
            _ => self.ndarray_state(i)?,
        };
        let (name, order) = self.dtype(dtype)?;
        if name != "f4" || order == ">" {
            return Err(format!(
                "a {order}{name} array; tensorflow-vgg's weights are little-endian float32 (f4)"
            ));
        }
        let Obj::Bytes(r) = &self.objs[data] else {
            return Err(format!("array data is {}, not bytes", self.kind(data)));
        };
        let n = shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or("an array shape whose size overflows")?;
        if n.checked_mul(4) != Some(r.len()) {
            return Err(format!(
                "an array of shape {shape:?} with {} data bytes (expected {})",
                r.len(),
                n.saturating_mul(4)
            ));
        }
        let data = self.b[r.clone()]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok(F32Array { shape, data })
    }
}

fn pairs(items: &[usize], at: usize) -> Result<Vec<(usize, usize)>, NpyError> {
    if !items.len().is_multiple_of(2) {
        return Err(format!("pickle at byte {at}: an odd number of dict items"));
    }
    Ok(items.chunks_exact(2).map(|p| (p[0], p[1])).collect())
}
