"""vibroflow.dem.prefetch: the hints reach the machine code as prefetch instructions and change
nothing a program computes, for rows in range and out of it."""
import numba
import numpy as np

from vibroflow.dem.prefetch import prefetch_read, prefetch_write


@numba.njit
def _scale_rows(a, rows, hinted):
    """a[rows] *= 2 (each row once), with every row hinted for reading and writing first when
    `hinted`, and a row far outside the array hinted as well; returns the sum of the rows."""
    s = 0.0
    if hinted:
        for r in rows:
            prefetch_read(a, r)
            prefetch_write(a, r, a.shape[1])
        prefetch_read(a, a.shape[0] + 10_000_000, a.shape[1])
        prefetch_write(a, -1)
    for r in rows:
        for c in range(a.shape[1]):
            a[r, c] *= 2.0
            s += a[r, c]
    return s


@numba.njit
def _sum_hinted(v, idx):
    s = 0.0
    for i in idx:
        prefetch_read(v, np.uint64(i))
    for i in idx:
        s += v[i]
    return s


def test_hints_change_no_number_in_or_out_of_range():
    rng = np.random.default_rng(7)
    a = rng.random((5000, 6))
    rows = rng.permutation(5000)[:700]
    plain, hinted = a.copy(), a.copy()
    s0 = _scale_rows(plain, rows, False)
    s1 = _scale_rows(hinted, rows, True)
    expected = a.copy()
    expected[rows] *= 2.0
    assert np.array_equal(plain, expected) and np.array_equal(hinted, expected)
    assert s0 == s1
    v = rng.random(1000)
    idx = rng.integers(0, 1000, 300)
    assert _sum_hinted(v, idx) == sum(float(v[i]) for i in idx)


def test_hints_are_prefetch_instructions():
    a = np.zeros((10, 3))
    _scale_rows(a, np.arange(3), True)
    asm = _scale_rows.inspect_asm(_scale_rows.signatures[0])
    assert "prefetch" in asm.lower() or "prfm" in asm.lower()  # x86, AArch64


@numba.njit
def _hint_row(a, r, width):
    prefetch_read(a, r, width)


def test_a_row_over_two_lines_is_hinted_at_both_ends():
    """A row of six float64 spans two 64-byte lines when it starts past a line's first 16
    bytes: the hint of its six elements is two prefetch instructions, of its first one."""
    a = np.zeros((4, 6))
    _hint_row(a, 1, 6)
    asm = _hint_row.inspect_asm(_hint_row.signatures[0]).lower()
    assert asm.count("prefetcht0") == 2 or asm.count("prfm") == 2
