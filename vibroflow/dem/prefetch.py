"""A hint to the processor that a row of an array is read or written soon (LLVM's
llvm.prefetch: x86 PREFETCHT0 / PREFETCHW), from compiled code.

The pair pass touches a contact's history, its reverse place and its reverse slot at a few
scattered rows of arrays that, on a large bed, live in main memory, not in the caches (about
80 MB of list arrays for 140 000 balls).  Loaded one contact after the other, each waits a
memory latency; hinted for a whole tile of contacts first, the loads overlap
(vibroflow.dem.step._pair_block).  A hint changes no number: it moves no data the program
sees, and a hint for a row out of range faults nothing (the processor drops it).

A row of six float64 (48 bytes) starts at any multiple of 16 bytes of a 64-byte cache line, so
half of such rows span two lines: a hint names the row's first `width` elements, and both
their first and last element's lines are hinted (one instruction more; a second hint of the
same line costs nothing).
"""
from __future__ import annotations

from llvmlite import ir
from numba import njit
from numba.core import cgutils, types
from numba.extending import intrinsic

_I8P = ir.IntType(8).as_pointer()
_I32 = ir.IntType(32)
_FNTY = ir.FunctionType(ir.VoidType(), [_I8P, _I32, _I32, _I32])


def _hint(write: int):
    """The intrinsic for one access kind (0 read, 1 write), locality 3 (keep in all levels),
    data cache."""

    def typer(typingctx, arr, row, width):
        if not isinstance(arr, types.Array) or arr.ndim not in (1, 2) or arr.layout != "C":
            return None
        if not isinstance(row, types.Integer) or not isinstance(width, types.Integer):
            return None
        sig = types.void(arr, row, width)

        def codegen(context, builder, signature, args):
            a, r, w = args
            aryty, rowty, wty = signature.args
            ary = context.make_array(aryty)(context, builder, value=a)
            r = context.cast(builder, r, rowty, types.intp)
            fn = cgutils.get_or_insert_function(builder.module, _FNTY, "llvm.prefetch.p0i8")
            if aryty.ndim == 1:
                ends = [[r]]
            else:
                last = builder.sub(context.cast(builder, w, wty, types.intp),
                                   context.get_constant(types.intp, 1))
                ends = [[r, context.get_constant(types.intp, 0)], [r, last]]
            for idx in ends:
                # the element's address, computed without a bounds check or a load (as
                # block_queue._fetch_add finds its counter's)
                ptr = cgutils.get_item_pointer(context, builder, aryty, ary, idx)
                builder.call(fn, [builder.bitcast(ptr, _I8P), _I32(write), _I32(3), _I32(1)])
            return context.get_dummy_value()

        return sig, codegen

    typer.__name__ = typer.__qualname__ = ("hint_write" if write else "hint_read")
    return typer


_hint_read = intrinsic(_hint(0))
_hint_write = intrinsic(_hint(1))


@njit(inline="always")
def prefetch_read(arr, row, width=1):
    """arr[row] (a 1-d array) or arr[row, :width] (2-d) is read soon."""
    _hint_read(arr, row, width)


@njit(inline="always")
def prefetch_write(arr, row, width=1):
    """arr[row] (a 1-d array) or arr[row, :width] (2-d) is written soon."""
    _hint_write(arr, row, width)
