//! Containment of panics in third-party decoders. The parquet crate asserts where a damaged
//! page should be an error ("Decoder for dict should have been set", found by fuzzing), so a
//! reader runs its decoding through [`contained`]: such a panic becomes an error naming the
//! file, and its message is not printed as a crash. Panics elsewhere are left as they are.

use std::cell::Cell;
use std::panic::AssertUnwindSafe;
use std::sync::Once;

thread_local! {
    static CONTAINED: Cell<bool> = const { Cell::new(false) };
}

/// Run `f`, turning a panic inside it into `Err(message)`.
pub fn contained<T>(f: impl FnOnce() -> T) -> std::result::Result<T, String> {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !CONTAINED.with(Cell::get) {
                previous(info);
            }
        }));
    });
    let was = CONTAINED.with(|c| c.replace(true));
    let r = std::panic::catch_unwind(AssertUnwindSafe(f));
    CONTAINED.with(|c| c.set(was));
    r.map_err(|p| {
        p.downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_inside_becomes_its_message_and_the_hook_stays_for_others() {
        assert_eq!(contained(|| 7), Ok(7));
        let e = contained(|| -> u8 { panic!("bad page {}", 3) }).unwrap_err();
        assert_eq!(e, "bad page 3");
        assert!(
            !CONTAINED.with(Cell::get),
            "the flag is reset after a panic"
        );
    }
}
