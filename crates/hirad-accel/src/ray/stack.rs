//! The traversal stack of the ray queries: a fixed array on the machine stack, spilling to the
//! heap only for very deep or very wide trees.

use std::mem::MaybeUninit;

/// Traversal stack kept in a fixed array on the machine stack (not initialised), spilling to
/// the heap only for very deep or very wide trees.
pub(crate) struct Stack<T: Copy, const N: usize> {
    buf: [MaybeUninit<T>; N],
    len: usize,
    heap: Vec<T>,
    spilled: bool,
}

impl<T: Copy, const N: usize> Stack<T, N> {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            buf: [const { MaybeUninit::uninit() }; N],
            len: 0,
            heap: Vec::new(),
            spilled: false,
        }
    }

    #[inline(always)]
    pub(crate) fn push(&mut self, x: T) {
        if !self.spilled {
            if self.len < N {
                self.buf[self.len].write(x);
                self.len += 1;
                return;
            }
            self.heap.reserve(2 * N);
            // SAFETY: the first `len` entries were written by `push`.
            self.heap.extend(
                self.buf[..self.len]
                    .iter()
                    .map(|x| unsafe { x.assume_init() }),
            );
            self.spilled = true;
        }
        self.heap.push(x);
    }

    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<T> {
        if self.spilled {
            return self.heap.pop();
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: entries below the old `len` were written by `push`.
        Some(unsafe { self.buf[self.len].assume_init() })
    }

    /// Pop the top entry if there is one and `keep` accepts it.
    #[inline(always)]
    pub(crate) fn pop_if(&mut self, keep: impl Fn(&T) -> bool) -> Option<T> {
        let top = if self.spilled {
            self.heap.last().copied()
        } else if self.len > 0 {
            // SAFETY: entries below `len` were written by `push`.
            Some(unsafe { self.buf[self.len - 1].assume_init() })
        } else {
            None
        };
        let top = top.filter(keep)?;
        self.pop();
        Some(top)
    }

    #[inline(always)]
    pub(crate) fn size(&self) -> usize {
        if self.spilled {
            self.heap.len()
        } else {
            self.len
        }
    }

    /// The `k` topmost entries.
    #[inline(always)]
    pub(crate) fn top_mut(&mut self, k: usize) -> &mut [T] {
        if self.spilled {
            let l = self.heap.len();
            &mut self.heap[l - k..]
        } else {
            let s = &mut self.buf[self.len - k..self.len];
            // SAFETY: these entries were written by `push`; MaybeUninit<T> has T's layout.
            unsafe { &mut *(s as *mut [MaybeUninit<T>] as *mut [T]) }
        }
    }
}

impl<const N: usize> Stack<u32, N> {
    /// Push the lanes of `lanes` selected by the 8-bit `mask`, in lane order (the highest on
    /// top), without a branch per lane: every lane is stored at the top and the top moves up
    /// past the selected ones. Stores of single entries, so that a pop soon after reads from
    /// one store (a wider store would stall the load that forwards from it).
    #[inline(always)]
    pub(crate) fn push8(&mut self, lanes: &[u32; 8], mask: u32) {
        if !self.spilled && self.len + 8 <= N {
            let mut len = self.len;
            for (i, &c) in lanes.iter().enumerate() {
                // SAFETY: `len < self.len + 8 <= N`.
                unsafe { self.buf.get_unchecked_mut(len) }.write(c);
                len += (mask >> i & 1) as usize;
            }
            self.len = len;
            return;
        }
        let mut m = mask & 0xFF;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            self.push(lanes[i]);
            m &= m - 1;
        }
    }
}
