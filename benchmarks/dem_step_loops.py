"""What the DEM step's two parallel loops save against three, in one process.

    python benchmarks/dem_step_loops.py [--rounds 20] [--steps 400] [--threads 2]

vibroflow.dem.step.advance makes a step in two parallel loops over the blocks of balls (the
pairs; the ball pass, which also makes the next step's first half kick and drift).  Its twin
here, `three_loops`, is made of the same kernels with the first half kick and drift in a loop
of their own before the pairs (each step's kick and drift as `step._kick_drift`, the ball pass
without them): the numbers of both are the same bit for bit (tests/test_dem_fused_step.py),
only the loops differ.  tub47-quick's balls fall from the closed-up fill lattice into the
vibrating tub for 2 500 untimed steps, then `--rounds` rounds each time `--steps` steps of both,
in turn (the order swapped every round), on the same evolving bed through run_steps, so that
a shared machine's load falls on both alike.  Printed: each one's median wall and CPU
microseconds a step, and the median of the rounds' ratios (two loops over three).
"""
from __future__ import annotations

import argparse
import os
import statistics
import time


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=20)
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args(argv)
    os.environ["NUMBA_NUM_THREADS"] = str(a.threads)
    import numba as nb

    from vibroflow.dem import fill as F
    from vibroflow.dem import simulate as S
    from vibroflow.dem import step as K
    from vibroflow.dem.contact_rows import pack, unpack
    from vibroflow.dem.walls import TUB_LENGTH, TUB_PERIODIC, TUB_PRESENT
    from vibroflow.scenario.io import load_scenario

    @nb.njit
    def three_loops(step0, nsteps, time_origin_step, motion, record_impacts, balls, pairs,
                    slots, walls, params, work, prt):
        """step.advance's steps, the first half kick and drift a loop of their own."""
        dt, hs2 = params.dt, params.half_skin * params.half_skin
        diag, pose, moved = work.diag, work.pose, work.moved
        tub = params.tub
        periodic_length = tub[TUB_LENGTH] if (tub[TUB_PRESENT] > 0.0 and
                                              tub[TUB_PERIODIC] > 0.0) else 0.0
        pack(pairs, slots, work)
        for k in range(nsteps):
            K._kick_drift(balls, params)
            t = (step0 + k + 1 - time_origin_step) * dt
            K._pose_array(motion, pose[6], pose[7], t, pose)
            K._pair_pass(t, dt, periodic_length, record_impacts, balls, pairs, slots, params,
                         work)
            K._ball_pass(t, dt, True, False, record_impacts, balls, pairs, slots, walls,
                         params, work, prt)
            for c in range(diag.shape[0]):
                if diag[c, K.D_NAN] >= 0.0 or diag[c, K.D_LOST] >= 0.0:
                    unpack(pairs, slots)
                    return k + 1, K.BLOWUP
                if moved[c] > hs2:
                    unpack(pairs, slots)
                    return k + 1, K.REBUILD
        unpack(pairs, slots)
        return nsteps, K.DONE

    sc = load_scenario("tub47-quick", ["fill.lattice_spacing=1.01", "fill.insert_above=0.0"])
    system = S.make_system(sc)
    state = F.fill_state(system, sc)
    state.vibrating = True
    S.run_steps(system, state, 2500)
    two = K.advance
    loops = {"two loops": two, "three loops": three_loops}
    times = {name: [] for name in loops}
    try:
        K.advance = three_loops
        S.run_steps(system, state, 10)  # compiles the twin
        for r in range(a.rounds):
            for name in (list(loops) if r % 2 == 0 else list(loops)[::-1]):
                K.advance = loops[name]
                t0, c0 = time.perf_counter(), time.process_time()
                S.run_steps(system, state, a.steps)
                times[name].append((1e6 * (time.perf_counter() - t0) / a.steps,
                                    1e6 * (time.process_time() - c0) / a.steps))
    finally:
        K.advance = two
    print(f"tub47-quick, {state.n} balls, {nb.get_num_threads()} thread(s), {a.rounds} rounds "
          f"of {a.steps} steps (load {os.getloadavg()[0]:.1f})")
    for name, v in times.items():
        print(f"  {name}: {statistics.median(x[0] for x in v):7.1f} us/step wall, "
              f"{statistics.median(x[1] for x in v):7.1f} CPU (medians)")
    for i, what in ((0, "wall"), (1, "CPU")):
        ratios = [x[i] / y[i] for x, y in zip(times["two loops"], times["three loops"])]
        print(f"  two / three loops, {what}: median of the rounds {statistics.median(ratios):.3f} "
              f"({min(ratios):.2f} - {max(ratios):.2f})")


if __name__ == "__main__":
    main()
