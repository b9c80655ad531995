//! The `snell` binary's allocator: the system allocator, with large blocks backed by 2 MiB pages
//! where the kernel offers them.
//!
//! A mesh's acceleration structure and triangle blocks take tens of megabytes (the dragon's,
//! 46 MiB), which incoherent rays read all over. In 4 KiB pages that is more pages than the
//! TLB holds, and a walk pays for page-table look-ups as well as for cache misses. Embree asks
//! the kernel for transparent huge pages (`madvise(MADV_HUGEPAGE)`) for its large allocations;
//! this does the same. A block of at least [`HUGE`] bytes is aligned to [`HUGE`] and advised,
//! so that every whole 2 MiB of it can be one page (Linux, where transparent huge pages are
//! enabled as `always` or `madvise`; on other systems every block is placed as the system
//! allocator places it). Smaller blocks are the system allocator's, untouched. What it gains is
//! measured in MEASUREMENTS.md (twenty-first session).
//!
//! `SNELL_HUGE_PAGES=0` in the environment turns it off (for comparisons).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, Ordering};

/// The size of a huge page, and the smallest block that is advised to use them.
pub const HUGE: usize = 2 << 20;

/// Whether large blocks are aligned and advised: set once, at the start of `main`, before any
/// block of that size is made (a block must be freed with the layout it was made with).
static ENABLED: AtomicBool = AtomicBool::new(false);

/// Turns the advice on unless the environment says `SNELL_HUGE_PAGES=0`. Called first thing in
/// `main`.
pub fn init() {
    ENABLED.store(std::env::var_os("SNELL_HUGE_PAGES").is_none_or(|v| v != "0"), Ordering::Relaxed);
}

/// The allocator (see the module's documentation).
pub struct HugePages {
    /// Advise large blocks whatever [`init`] found (the tests' own instances); otherwise only
    /// where it turned the advice on.
    always: bool,
}

impl HugePages {
    /// The `snell` binary's global allocator, as [`init`] sets it.
    pub const GLOBAL: HugePages = HugePages { always: false };

    /// The layout a block is made with: `l` itself, or for a large block while enabled (on
    /// Linux, the one system here that takes the advice), `l` aligned to [`HUGE`].
    fn placed(&self, l: Layout) -> Layout {
        if cfg!(target_os = "linux") && l.size() >= HUGE && (self.always || ENABLED.load(Ordering::Relaxed)) {
            Layout::from_size_align(l.size(), HUGE.max(l.align())).unwrap_or(l)
        } else {
            l
        }
    }
}

/// Asks for huge pages over the whole 2 MiB pages of block `p` (made with layout `l`, as
/// [`HugePages::placed`] gives it). Returns whether the advice was given and taken. Never fails the
/// allocation: without the advice the block is ordinary memory.
fn advise(p: *mut u8, l: Layout) -> bool {
    if p.is_null() || l.align() < HUGE {
        return false;
    }
    #[cfg(target_os = "linux")]
    {
        // SAFETY: `p` starts a live block of `l.size()` bytes, aligned to a page; the range
        // advised lies inside it. The advice changes how the kernel backs the range, never its
        // contents.
        unsafe { libc::madvise(p.cast(), l.size() & !(HUGE - 1), libc::MADV_HUGEPAGE) == 0 }
    }
    #[cfg(not(target_os = "linux"))]
    false
}

// SAFETY: every block comes from `System` with the layout `placed` gives, and goes back to it
// with the same layout: `placed` depends only on the caller's layout, on `always` and on
// `ENABLED`, which `init` sets before any large block exists.
unsafe impl GlobalAlloc for HugePages {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let l = self.placed(l);
        let p = System.alloc(l);
        advise(p, l);
        p
    }

    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        let l = self.placed(l);
        let p = System.alloc_zeroed(l);
        advise(p, l);
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, self.placed(l))
    }

    unsafe fn realloc(&self, p: *mut u8, l: Layout, new_size: usize) -> *mut u8 {
        let new = Layout::from_size_align_unchecked(new_size, l.align());
        if self.placed(l) == l && self.placed(new) == new {
            // Small on both sides: the system's realloc, which may grow in place.
            return System.realloc(p, l, new_size);
        }
        let q = self.alloc(new);
        if !q.is_null() {
            std::ptr::copy_nonoverlapping(p, q, l.size().min(new_size));
            self.dealloc(p, l);
        }
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Large blocks come aligned to 2 MiB (advised, on Linux), small ones as the system places
    /// them, and contents survive growing and shrinking across the threshold either way.
    #[test]
    fn large_blocks_are_aligned_and_keep_their_contents() {
        // An instance of its own: the global one's setting is left alone, as blocks the
        // harness made under it must go back with the layout they were made with.
        let a = HugePages { always: true };
        unsafe {
            let l = Layout::from_size_align(3 * HUGE + 100, 8).unwrap();
            let p = a.alloc(l);
            assert!(!p.is_null());
            #[cfg(target_os = "linux")]
            {
                assert_eq!(p as usize % HUGE, 0, "a large block starts a huge page");
                // A kernel built without transparent huge pages refuses the advice (and has
                // no such directory); one with them takes it, whatever its setting.
                let thp = std::path::Path::new("/sys/kernel/mm/transparent_hugepage").exists();
                assert_eq!(advise(p, a.placed(l)), thp, "madvise(MADV_HUGEPAGE) refused or taken unexpectedly");
            }
            for i in 0..l.size() {
                *p.add(i) = (i % 251) as u8;
            }
            // Shrink below the threshold, then grow past it again.
            let q = a.realloc(p, l, 1000);
            assert!((0..1000).all(|i| *q.add(i) == (i % 251) as u8));
            let small = Layout::from_size_align(1000, 8).unwrap();
            let r = a.realloc(q, small, 5 * HUGE);
            #[cfg(target_os = "linux")]
            assert_eq!(r as usize % HUGE, 0);
            assert!((0..1000).all(|i| *r.add(i) == (i % 251) as u8));
            a.dealloc(r, Layout::from_size_align(5 * HUGE, 8).unwrap());

            let z = a.alloc_zeroed(Layout::from_size_align(HUGE, 4).unwrap());
            #[cfg(target_os = "linux")]
            assert_eq!(z as usize % HUGE, 0);
            assert!((0..HUGE).step_by(4093).all(|i| *z.add(i) == 0));
            a.dealloc(z, Layout::from_size_align(HUGE, 4).unwrap());

            let s = Layout::from_size_align(HUGE - 1, 16).unwrap();
            assert_eq!(a.placed(s), s, "blocks under 2 MiB are the system allocator's");
        }
    }
}
