//! Each thread's spare activation buffers. A 512² photo's early activations are 67 MB each;
//! freshly allocated, every one costs tens of thousands of page faults (the allocator returns
//! such blocks to the system on free). The forward pass hands each activation's buffer back
//! here once the next layer has read it, and the next allocation of that thread reuses it.

use std::cell::RefCell;

/// Buffers kept per thread: a forward pass has at most two activations alive at once.
const KEEP: usize = 3;

thread_local! {
    static SPARE: RefCell<Vec<Vec<f32>>> = const { RefCell::new(Vec::new()) };
}

/// `n` zeros, in a spare buffer of this thread when one is large enough.
pub(crate) fn zeroed(n: usize) -> Vec<f32> {
    match take(n) {
        Some(mut v) => {
            v.clear();
            v.resize(n, 0.0);
            v
        }
        None => vec![0f32; n],
    }
}

/// The smallest spare buffer of this thread that holds `n` values, if any.
fn take(n: usize) -> Option<Vec<f32>> {
    SPARE.with_borrow_mut(|spare| {
        let best = spare
            .iter()
            .enumerate()
            .filter(|(_, v)| v.capacity() >= n)
            .min_by_key(|(_, v)| v.capacity())
            .map(|(i, _)| i);
        best.map(|i| spare.swap_remove(i))
    })
}

/// Give a buffer back for this thread's next [`zeroed`]; the smallest goes when full.
pub(crate) fn recycle(v: Vec<f32>) {
    if v.capacity() < 1 << 16 {
        return;
    }
    SPARE.with_borrow_mut(|spare| {
        spare.push(v);
        if spare.len() > KEEP {
            let smallest = (0..spare.len())
                .min_by_key(|&i| spare[i].capacity())
                .expect("not empty");
            spare.swap_remove(smallest);
        }
    });
}

/// `n` values the caller overwrites whole (stale from a reused buffer; NaN in debug builds).
pub(crate) fn overwritten(n: usize) -> Vec<f32> {
    let Some(mut v) = take(n) else {
        return vec![0f32; n];
    };
    v.truncate(n);
    v.resize(n, 0.0);
    if cfg!(debug_assertions) {
        v.fill(f32::NAN);
    }
    v
}

/// An (h + 2) × (w + 2) × c activation buffer whose one-pixel border is zero and whose
/// interior the caller must write whole: a reused buffer's interior keeps stale values
/// (filled with NaN in debug builds, so a pixel left unwritten fails the tests), which saves
/// zeroing 67 MB per layer at 512².
pub(crate) fn bordered(h: usize, w: usize, c: usize) -> Vec<f32> {
    let (pw, n) = (w + 2, (h + 2) * (w + 2) * c);
    let mut v = overwritten(n);
    let row = pw * c;
    v[..row].fill(0.0);
    v[(h + 1) * row..].fill(0.0);
    for y in 1..=h {
        v[y * row..y * row + c].fill(0.0);
        v[(y + 1) * row - c..(y + 1) * row].fill(0.0);
    }
    v
}
