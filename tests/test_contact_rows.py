"""The contact rows of the tub step (vibroflow.dem.contact_rows) on a contact that parts and
touches again many times within one call of `advance`: two equal balls between two plane walls,
without gravity, friction or damping (e = 1), the first thrown at the second.  Each ball-ball
contact swaps the balls' velocities (equal masses, e = 1), each wall turns the outer ball back,
so the pair rattles: fourteen contacts of the one list entry in the run, and no rebuild
(every ball stays within a fiftieth of a diameter of its start, the skin's half being 0.15).

Known answers: between contacts, the kinetic energy of the start (the linear spring stores and
gives back the energy, to the integrator's error at 50 steps a contact: 1e-4 measured) and no
motion off the walls' normal; and the run made in one call ends on the state of the run made
one step a call, bit for bit, though the long call gives the entry its row once and reuses it
at every contact.
"""
from __future__ import annotations

import numpy as np

from dem_helpers import D_STEEL, M_STEEL, Sim, ball, contact, linear_dt, one_thread, plane, scenario
from vibroflow.dem import simulate as S
from vibroflow.dem.walls import KIND_BALL_BALL

K_N = 1.0e5
GAP = 0.01 * D_STEEL   # each ball's play to its wall; twice that between the balls
V0 = 0.1               # m/s
DT = linear_dt(K_N, 0.5 * M_STEEL, 50)


def _rattle() -> Sim:
    half = 0.5 * D_STEEL + GAP
    walls = [plane(point=(-(2.0 * half), 0.0, 0.0), normal=(1.0, 0.0, 0.0)),
             plane(point=(2.0 * half, 0.0, 0.0), normal=(-1.0, 0.0, 0.0))]
    law = contact(model="linear", k_n=K_N, e=1.0, mu=0.0)
    return Sim(scenario([ball((-half, 0.0, 0.0), vel=(V0, 0.0, 0.0)), ball((half, 0.0, 0.0))],
                        [law], walls=walls, dt=DT))


def _free(sim: Sim) -> bool:
    """No ball touches the other or a wall."""
    st = sim.state
    return not (st.nl.flag.any() or st.wall_flag.any())


def test_a_rattling_contact_keeps_its_energy_and_the_numbers_of_one_step_a_call():
    steps = 9000
    whole = _rattle()
    builds = whole.state.nl.builds
    impacts = []
    with one_thread():
        S.run_steps(whole.system, whole.state, steps, record_impacts=True,
                    on_impacts=impacts.append)
    rows = np.concatenate(impacts)
    assert whole.state.nl.builds == builds          # one list, one call
    # the one entry's row is its block's first: it took the row once, not at every contact
    assert whole.state.nl.row.tolist() == [0]
    assert np.count_nonzero(rows[:, 1] == KIND_BALL_BALL) >= 12
    single = _rattle()
    for _ in range(steps):
        single.run(1)
    for name in ("pos", "vel", "omg", "force", "torque"):
        assert np.array_equal(getattr(whole.state, name), getattr(single.state, name)), name
    assert np.array_equal(whole.state.nl.hist, single.state.nl.hist)
    # between contacts: the energy of the start, no motion off the walls' normal
    while not _free(whole):
        whole.run(1)
    e0 = 0.5 * M_STEEL * V0 ** 2
    e = 0.5 * float(np.sum(whole.state.mass[:, None] * whole.state.vel ** 2))
    assert abs(e - e0) < 1e-3 * e0
    assert np.abs(whole.state.vel[:, 1:]).max() == 0.0
    assert np.abs(whole.state.omg).max() == 0.0
