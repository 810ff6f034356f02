"""vibroflow.run_clock: a run's solver time leaves numba's compilation out, and only that."""
from __future__ import annotations

import time

import numba
import numpy as np
import pytest

from vibroflow.run_clock import RunClock


def _fresh_kernel():
    """A kernel numba has never seen (no cache), so its first call compiles."""
    @numba.njit(cache=False)
    def kernel(x):
        s = 0.0
        for i in range(x.shape[0]):
            s += np.sqrt(x[i]) * np.sin(x[i])
        return s
    return kernel


def test_compilation_is_counted_apart_and_sleeping_is_not():
    """A first call compiles (compile_s > 0); a second call and a 0.3 s sleep do not; the
    solver time is the elapsed time less the compilation, so it holds the sleep."""
    kernel = _fresh_kernel()
    with RunClock() as clock:
        kernel(np.ones(8))
        compiled = clock.compile_s()
        kernel(np.ones(16))   # same signature: no compilation
        time.sleep(0.3)
    assert compiled > 0.01
    assert clock.compile_s() == pytest.approx(compiled)
    assert clock.solver_s() == pytest.approx(clock.elapsed_s() - clock.compile_s(), abs=1e-9)
    assert 0.3 <= clock.solver_s() < 0.3 + 0.5 * clock.elapsed_s()


def test_warm_kernels_compile_nothing_and_a_resume_carries_the_time_before():
    kernel = _fresh_kernel()
    kernel(np.ones(4))        # compiled outside the clock
    with RunClock() as clock:
        clock.resume_from(12.5)
        kernel(np.ones(4))
        time.sleep(0.05)
    assert clock.compile_s() == 0.0
    assert clock.solver_s() == pytest.approx(12.5 + clock.elapsed_s())
    assert clock.elapsed_s() >= 0.05


def test_the_listener_goes_with_the_clock():
    """After the clock's exit a compilation is not counted (no listener left behind)."""
    with RunClock() as clock:
        pass
    _fresh_kernel()(np.ones(3))
    assert clock.compile_s() == 0.0
