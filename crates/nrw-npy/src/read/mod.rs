//! The published code's VGG16 weights, `vgg16.npy` (machrisaa/tensorflow-vgg), read as users
//! have it: a NumPy `.npy` file holding a 0-d object array whose one element is a pickled dict
//! `{'conv1_1': [W, b], …}` with W as (3, 3, in, out) float32 and b as (out,) float32.
//!
//! Pickle is a program, not a format: `pickle.load` calls whatever globals it names. This
//! reader never calls anything. It interprets the opcodes that NumPy's pickles use into plain
//! values, allows exactly the globals that rebuild an ndarray and its dtype (refusing any other
//! by name), and checks every length against the bytes that are left before it allocates.

use std::collections::BTreeMap;

mod array;
mod pickle;

pub use array::{F32Array, NpyError};
use pickle::{Obj, Vm};

/// Read a `vgg16.npy`: layer name → (W, b) float32 arrays, in the file's layout.
pub fn read_layers(bytes: &[u8]) -> Result<BTreeMap<String, Vec<F32Array>>, NpyError> {
    let body = npy_object_body(bytes)?;
    let mut vm = Vm::new(bytes, body);
    let top = vm.run()?;
    // np.save of a dict: a 0-d object ndarray whose state holds the list [dict].
    let dict = vm.object_array_item(top)?;
    let Obj::Dict(items) = vm.objs[dict].clone() else {
        return Err(format!(
            "the array's element is {}, not the dict of layers {{'conv1_1': [W, b], …}} that tensorflow-vgg writes",
            vm.kind(dict)
        ));
    };
    let mut out = BTreeMap::new();
    for (k, v) in items {
        let name = vm.text(k).ok_or_else(|| {
            format!(
                "a key of the dict is {}, not a layer name such as 'conv1_1'",
                vm.kind(k)
            )
        })?;
        let parts = match &vm.objs[v] {
            Obj::List(p) | Obj::Tuple(p) => p.clone(),
            _ => return Err(format!("layer '{name}' is {}, not [W, b]", vm.kind(v))),
        };
        let arrays = parts
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                vm.f32_array(p)
                    .map_err(|e| format!("layer '{name}', item {i}: {e}"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        out.insert(name, arrays);
    }
    Ok(out)
}

/// The pickle bytes of a `.npy` file whose header says a 0-d object array.
fn npy_object_body(b: &[u8]) -> Result<std::ops::Range<usize>, NpyError> {
    if b.len() < 10 || &b[..6] != b"\x93NUMPY" {
        return Err("not a NumPy .npy file (no \\x93NUMPY magic)".into());
    }
    let (len, start): (usize, usize) = match b[6] {
        1 => (u16::from_le_bytes([b[8], b[9]]) as usize, 10),
        2 | 3 if b.len() >= 12 => (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12),
        v => return Err(format!(".npy format version {v} is not one NumPy writes")),
    };
    let header = b
        .get(start..start.saturating_add(len))
        .ok_or("the .npy header runs past the end of the file")?;
    let header = String::from_utf8_lossy(header);
    let compact: String = header.chars().filter(|c| !c.is_whitespace()).collect();
    if !compact.contains("'descr':'|O'") || !compact.contains("'shape':()") {
        return Err(format!(
            "the .npy header is {}: tensorflow-vgg's vgg16.npy is a 0-d object array ('descr': '|O', 'shape': ()) holding a dict of layers",
            header.trim()
        ));
    }
    Ok(start + len..b.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Python 2 protocol-2 pickle, as tensorflow-vgg's file was written: BINSTRING keys
    /// and data, `numpy.core.multiarray` globals by GLOBAL, BINPUT/BINGET memo.
    fn py2_file() -> Vec<u8> {
        let mut p = vec![0x80, 2];
        let global = |p: &mut Vec<u8>, m: &str, n: &str| {
            p.push(b'c');
            p.extend(format!("{m}\n{n}\n").bytes());
        };
        let array = |p: &mut Vec<u8>, shape: &[u8], data: &[f32], name: &str| {
            global(p, "numpy.core.multiarray", "_reconstruct");
            global(p, "numpy", "ndarray");
            p.extend([b'K', 0, 0x85, b'U', 1, b'b', 0x87, b'R']);
            p.extend([b'(', b'K', 1, b'(']);
            for &d in shape {
                p.extend([b'K', d]);
            }
            p.push(b't');
            global(p, "numpy", "dtype");
            p.extend([b'U', 2]);
            p.extend(name.bytes());
            p.extend([b'K', 0, b'K', 1, 0x87, b'R']);
            p.extend([b'(', b'K', 3, b'U', 1, b'<', b'N', b'N', b'N', b'J']);
            p.extend((-1i32).to_le_bytes());
            p.push(b'J');
            p.extend((-1i32).to_le_bytes());
            p.extend([b'K', 0, b't', b'b', 0x89, b'T']);
            p.extend(((data.len() * 4) as u32).to_le_bytes());
            p.extend(data.iter().flat_map(|v| v.to_le_bytes()));
            p.extend([b't', b'b']);
        };
        global(&mut p, "numpy.core.multiarray", "_reconstruct");
        p.extend([b'q', 0]);
        global(&mut p, "numpy", "ndarray");
        p.extend([b'K', 0, 0x85, b'U', 1, b'b', 0x87, b'R']);
        p.extend([b'(', b'K', 1, b')']);
        global(&mut p, "numpy", "dtype");
        p.extend([b'U', 2, b'O', b'8', b'K', 0, b'K', 1, 0x87, b'R']);
        p.extend([b'(', b'K', 3, b'U', 1, b'|', b'N', b'N', b'N', b'J']);
        p.extend((-1i32).to_le_bytes());
        p.push(b'J');
        p.extend((-1i32).to_le_bytes());
        p.extend([b'K', 63, b't', b'b', 0x89, b']', b'(', b'}', b'(']);
        p.extend([b'U', 7]);
        p.extend(b"conv1_1");
        p.push(b']');
        p.push(b'(');
        array(&mut p, &[1, 1, 2, 1], &[1.5, -2.0], "f4");
        array(&mut p, &[1], &[0.25], "f4");
        p.extend([b'e', b'u', b'e', b't', b'b', b'.']);
        npy(&p)
    }

    fn npy(pickle: &[u8]) -> Vec<u8> {
        let mut h = "{'descr': '|O', 'fortran_order': False, 'shape': (), }".to_string();
        while !(10 + h.len() + 1).is_multiple_of(64) {
            h.push(' ');
        }
        h.push('\n');
        let mut f = b"\x93NUMPY\x01\x00".to_vec();
        f.extend((h.len() as u16).to_le_bytes());
        f.extend(h.bytes());
        f.extend(pickle);
        f
    }

    #[test]
    fn a_python2_pickle_reads_as_numpy_reads_it() {
        let layers = read_layers(&py2_file()).unwrap();
        let l = &layers["conv1_1"];
        assert_eq!(l[0].shape, vec![1, 1, 2, 1]);
        assert_eq!(l[0].data, vec![1.5, -2.0]);
        assert_eq!(l[1].data, vec![0.25]);
    }

    #[test]
    fn other_globals_are_refused_by_name_and_never_run() {
        let mut g = py2_file();
        let at = g.windows(12).position(|w| w == b"numpy\ndtype\n").unwrap();
        g.splice(at..at + 12, b"os\nsystem\n".iter().copied());
        let e = read_layers(&g).unwrap_err();
        assert!(e.contains("`os.system`") && e.contains("refused"), "{e}");
    }

    #[test]
    fn truncated_and_hostile_lengths_are_errors_not_allocations() {
        let f = py2_file();
        for cut in [11, 80, 200, f.len() - 2] {
            assert!(read_layers(&f[..cut]).is_err(), "cut at {cut}");
        }
        let mut g = f.clone();
        let at = g.iter().rposition(|&c| c == b'T').unwrap();
        g[at + 1..at + 5].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = read_layers(&g).unwrap_err();
        assert!(e.contains("runs past the end"), "{e}");
        let e = read_layers(b"\x93NUMPY\x01\x00\x10\x00{'descr': '<f4'}").unwrap_err();
        assert!(e.contains("object array") || e.contains("header"), "{e}");
        assert!(read_layers(b"PK\x03\x04 a zip")
            .unwrap_err()
            .contains("magic"));
    }
}
