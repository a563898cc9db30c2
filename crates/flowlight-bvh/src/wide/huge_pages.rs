//! The arrays of a large tree on 2 MiB pages: [`HugeArray`].
//!
//! An incoherent ray through a 1M-triangle tree (57k nodes, 14 MiB; 263k packs, 42 MiB)
//! loads a few dozen node and pack lines scattered over 56 MiB. With 4 KiB pages that is
//! 14,000 pages, several times what a core's second-level TLB holds, so most of those
//! loads also miss the TLB and wait for a page walk before their cache miss even starts.
//! With 2 MiB pages the same arrays are 28 pages, and the TLB misses go away.
//!
//! Linux backs an anonymous mapping with transparent huge pages at its first touch when it
//! is advised `MADV_HUGEPAGE` (the setting `transparent_hugepage=madvise`, the usual
//! default, gives them only to such mappings; Embree advises its BVH memory the same way).
//! So an array of at least [`HUGE_PAGE`] bytes is its own mapping, starting at a 2 MiB
//! boundary, advised before it is filled; the fill (in parallel) then faults it in as huge
//! pages. Its length is only rounded up to the base page size (as Embree's mappings of sizes
//! that are not whole huge pages): a last, partial huge page stays on small pages rather
//! than taking up to 2 MiB of memory the array does not use. Smaller arrays, other systems, and a failed `mmap` use the ordinary heap.
//! The advice is a hint: where the kernel gives no huge pages, the array works as before.
//! Only where the memory lies changes, never its contents, so hits are unchanged.

use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ptr::NonNull;

/// The huge page size of x86-64 and aarch64 Linux (with 4 KiB base pages).
const HUGE_PAGE: usize = 2 << 20;

/// Elements filled at a time by one rayon task (below this, the fill is sequential).
const FILL_CHUNK: usize = 4096;

/// A fixed-length array of plain data (`Copy`), on huge pages where it is large enough and
/// the system offers them (see the module documentation). Reads as a slice.
pub(crate) struct HugeArray<T: Copy> {
    ptr: NonNull<T>,
    len: usize,
    /// Where the memory came from, for `drop`.
    owner: Owner,
}

/// The allocation behind a [`HugeArray`].
#[derive(Clone, Copy, Debug)]
enum Owner {
    /// Nothing allocated (no elements, or zero-sized ones).
    None,
    /// The global allocator, with `Layout::array::<T>(len)`.
    Heap,
    /// An `mmap`ed range of this many bytes (whole base pages).
    #[cfg(target_os = "linux")]
    Mapped(usize),
}

// SAFETY: a `HugeArray` owns its elements as a `Vec<T>` does.
unsafe impl<T: Copy + Send> Send for HugeArray<T> {}
// SAFETY: shared access only reads the elements, as for `&[T]`.
unsafe impl<T: Copy + Sync> Sync for HugeArray<T> {}

impl<T: Copy + Send + Sync> HugeArray<T> {
    /// The array `[f(0), f(1), …, f(len − 1)]`, filled in parallel when large.
    pub(crate) fn from_fn(len: usize, f: impl Fn(usize) -> T + Sync) -> HugeArray<T> {
        HugeArray::filled(len, true, f)
    }

    /// A copy of `items` on the heap, whatever its size (to compare against).
    #[cfg(test)]
    pub(crate) fn on_heap(items: &[T]) -> HugeArray<T> {
        HugeArray::filled(items.len(), false, |i| items[i])
    }

    /// `from_fn`, on its own huge-page mapping only if `huge` allows.
    fn filled(len: usize, huge: bool, f: impl Fn(usize) -> T + Sync) -> HugeArray<T> {
        let (ptr, owner) = allocate::<T>(len, huge);
        // SAFETY: `allocate` returned room for `len` elements of `T` (or a dangling, aligned
        // pointer when no room is needed), not yet initialised and owned by nobody else.
        let slots = unsafe { std::slice::from_raw_parts_mut(ptr.as_ptr().cast(), len) };
        fill(slots, &f);
        HugeArray { ptr, len, owner }
    }

    /// A copy of `items`.
    pub(crate) fn from_slice(items: &[T]) -> HugeArray<T> {
        HugeArray::from_fn(items.len(), |i| items[i])
    }

    /// Whether the array lies in its own mapping advised for huge pages (the kernel may
    /// still have backed parts of it with small pages).
    #[cfg(test)]
    pub(crate) fn advised(&self) -> bool {
        #[cfg(target_os = "linux")]
        if let Owner::Mapped(_) = self.owner {
            return true;
        }
        false
    }
}

/// Writes `f(i)` into every slot, in parallel chunks when there are many.
fn fill<T: Send>(slots: &mut [MaybeUninit<T>], f: &(impl Fn(usize) -> T + Sync)) {
    if slots.len() <= FILL_CHUNK {
        for (i, s) in slots.iter_mut().enumerate() {
            s.write(f(i));
        }
        return;
    }
    slots
        .par_chunks_mut(FILL_CHUNK)
        .enumerate()
        .for_each(|(c, chunk)| {
            for (i, s) in chunk.iter_mut().enumerate() {
                s.write(f(c * FILL_CHUNK + i));
            }
        });
}

/// Room for `len` elements of `T`: a mapping advised for huge pages when `huge` allows and it
/// is at least one huge page, else the heap.
fn allocate<T>(len: usize, huge: bool) -> (NonNull<T>, Owner) {
    let layout = std::alloc::Layout::array::<T>(len).expect("HugeArray too large");
    if layout.size() == 0 {
        return (NonNull::dangling(), Owner::None);
    }
    #[cfg(target_os = "linux")]
    if huge && layout.size() >= HUGE_PAGE && std::mem::align_of::<T>() <= HUGE_PAGE {
        if let Some((ptr, bytes)) = map_huge(layout.size()) {
            return (ptr.cast(), Owner::Mapped(bytes));
        }
    }
    // SAFETY: the layout has a non-zero size.
    let ptr = unsafe { std::alloc::alloc(layout) };
    match NonNull::new(ptr) {
        Some(p) => (p.cast(), Owner::Heap),
        None => std::alloc::handle_alloc_error(layout),
    }
}

/// A fresh anonymous mapping of `size` bytes rounded up to whole base pages, starting at a
/// huge-page boundary (so that every whole huge page of it can be one), advised
/// `MADV_HUGEPAGE`; `None` when the system refuses the mapping.
#[cfg(target_os = "linux")]
fn map_huge(size: usize) -> Option<(NonNull<u8>, usize)> {
    // SAFETY: `sysconf` only reads a system setting.
    let page = match unsafe { libc::sysconf(libc::_SC_PAGESIZE) } {
        p if p > 0 && HUGE_PAGE.is_multiple_of(p as usize) => p as usize,
        _ => return None,
    };
    let bytes = size.checked_next_multiple_of(page)?;
    // One huge page more than needed, so that an aligned start lies inside.
    let span = bytes.checked_add(HUGE_PAGE)?;
    // SAFETY: a new private anonymous mapping; it aliases nothing.
    let base = unsafe {
        libc::mmap(
            std::ptr::null_mut(),
            span,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
            -1,
            0,
        )
    };
    if base == libc::MAP_FAILED {
        return None;
    }
    let head = (base as usize).next_multiple_of(HUGE_PAGE) - base as usize;
    let start = base.cast::<u8>().wrapping_add(head);
    let tail = span - head - bytes;
    // SAFETY: the head and tail lie inside the mapping just made and are not used; `start`
    // and `bytes` are page aligned. A failed unmap or advice only leaves memory mapped or
    // on small pages, so their results are not needed.
    unsafe {
        if head > 0 {
            libc::munmap(base, head);
        }
        if tail > 0 {
            libc::munmap(start.wrapping_add(bytes).cast(), tail);
        }
        libc::madvise(start.cast(), bytes, libc::MADV_HUGEPAGE);
    }
    NonNull::new(start).map(|p| (p, bytes))
}

impl<T: Copy> Drop for HugeArray<T> {
    fn drop(&mut self) {
        match self.owner {
            Owner::None => {}
            Owner::Heap => {
                let layout = std::alloc::Layout::array::<T>(self.len).expect("allocated");
                // SAFETY: allocated by `allocate` with this layout; `T: Copy` needs no drop.
                unsafe { std::alloc::dealloc(self.ptr.as_ptr().cast(), layout) };
            }
            #[cfg(target_os = "linux")]
            Owner::Mapped(bytes) => {
                // SAFETY: the mapping `map_huge` made, `bytes` long, unmapped once.
                unsafe { libc::munmap(self.ptr.as_ptr().cast(), bytes) };
            }
        }
    }
}

impl<T: Copy> std::ops::Deref for HugeArray<T> {
    type Target = [T];

    #[inline(always)]
    fn deref(&self) -> &[T] {
        // SAFETY: `ptr` holds `len` initialised elements (`from_fn`), alive while `self` is.
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> std::ops::DerefMut for HugeArray<T> {
    #[inline(always)]
    fn deref_mut(&mut self) -> &mut [T] {
        // SAFETY: as for `deref`, and `&mut self` makes the access exclusive.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy + Send + Sync> Clone for HugeArray<T> {
    fn clone(&self) -> Self {
        HugeArray::from_slice(self)
    }
}

impl<T: Copy + std::fmt::Debug> std::fmt::Debug for HugeArray<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (**self).fmt(f)
    }
}

impl<T: Copy + PartialEq> PartialEq for HugeArray<T> {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_and_large_arrays_hold_what_they_were_filled_with() {
        for len in [0, 1, 5, FILL_CHUNK + 3, HUGE_PAGE / 4 + 1000] {
            let a = HugeArray::from_fn(len, |i| i as u32 * 3);
            assert_eq!(a.len(), len);
            assert!(a.iter().enumerate().all(|(i, &v)| v == i as u32 * 3));
            let b = a.clone();
            assert!(a == b && b.len() == len);
            // At least a huge page of u32s is mapped on its own (on Linux), less is not.
            assert_eq!(
                a.advised(),
                cfg!(target_os = "linux") && len * 4 >= HUGE_PAGE
            );
        }
    }

    #[test]
    fn a_mapped_array_is_aligned_to_a_huge_page_and_writable() {
        let mut a = HugeArray::from_fn(HUGE_PAGE + 8, |_| 1u8);
        if a.advised() {
            assert_eq!(a.as_ptr() as usize % HUGE_PAGE, 0);
        }
        let last = a.len() - 1;
        a[last] = 7;
        a[0] = 5;
        assert_eq!((a[0], a[1], a[last]), (5, 1, 7));
        assert_eq!(
            a.iter().map(|&v| v as usize).sum::<usize>(),
            HUGE_PAGE + 8 - 2 + 5 + 7
        );
    }

    #[test]
    fn zero_sized_elements_need_no_memory() {
        let a = HugeArray::from_fn(1000, |_| ());
        assert_eq!(a.len(), 1000);
        assert!(!a.advised());
    }
}
