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
            prefetch_write(a, r)
        prefetch_read(a, a.shape[0] + 10_000_000)
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
