"""A formulation's steps one by one with a callback between them, or all in one call."""
from __future__ import annotations


def run_steps(advance, system, state, n: int, callback=None) -> None:
    """n steps of the formulation's advance(system, state, n); callback(state) after each if
    given (else all in one compiled call)."""
    if callback is None:
        advance(system, state, n)
        return
    for _ in range(int(n)):
        advance(system, state, 1)
        callback(state)
