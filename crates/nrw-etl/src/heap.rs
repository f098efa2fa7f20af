//! The process's heap, counted: the system allocator wrapped so that the bytes in use, their
//! high-water mark and the bytes ever allocated are known. tests/memory.rs reads them for one
//! step (`--heap-file`) to see what the step allocates itself, which the resident peak (code,
//! libraries, the allocator's own pages) blurs: an N × N matrix of 130 photos is 135 kB. The
//! mark sees what is held at once; the sum sees a matrix made and dropped below the mark.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// The system allocator, counting.
pub struct Counting;

static IN_USE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static ALLOCATED: AtomicU64 = AtomicU64::new(0);

/// Counts `bytes` more in use, raising the mark if they pass it.
fn held(bytes: usize) {
    let now = IN_USE.fetch_add(bytes, Ordering::Relaxed) + bytes;
    if now > PEAK.load(Ordering::Relaxed) {
        PEAK.fetch_max(now, Ordering::Relaxed);
    }
}

/// Counts a new block of `bytes`: held, and added to the sum.
fn grew(bytes: usize) {
    ALLOCATED.fetch_add(bytes as u64, Ordering::Relaxed);
    held(bytes);
}

// SAFETY: every call goes to `System` unchanged; the counters only observe sizes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if !p.is_null() {
            // The old block stays counted until the move is done: the mark holds both. The
            // sum counts only what a growth adds (a vector doubling to n bytes adds about n,
            // not 2n), so it reads as the bytes the step asked for.
            held(new_size);
            IN_USE.fetch_sub(layout.size(), Ordering::Relaxed);
            let added = new_size.saturating_sub(layout.size());
            ALLOCATED.fetch_add(added as u64, Ordering::Relaxed);
        }
        p
    }
}

/// The most heap bytes this process has held at once.
pub fn peak() -> usize {
    PEAK.load(Ordering::Relaxed)
}

/// Every heap byte this process has allocated, freed or not (a growth counts what it adds).
pub fn allocated() -> u64 {
    ALLOCATED.load(Ordering::Relaxed)
}

/// The counters as `--heap-file` writes them: `peak BYTES` and `allocated BYTES`, a line each.
pub fn report() -> String {
    format!("peak {}\nallocated {}\n", peak(), allocated())
}
