"""What a tub scenario gives its LIGGGHTS deck: the atom types' materials, the per-type-pair
contact law (the `fix property/global` tables, `pair_style gran` and the wall fix's model), the
random seeds and the vibration steps of the snapshots."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.dem.sampling import sample_steps
from vibroflow.errors import InputError
from vibroflow.liggghts.template import _SLOT, _Deck, _fmt, _table
from vibroflow.scenario.laws import damping_ratio
from vibroflow.scenario.checks import find_contact


def next_prime(n: int) -> int:
    """Smallest prime >= n."""
    n = max(int(n), 2)
    while not _is_prime(n):
        n += 1
    return n


def _is_prime(n: int) -> bool:
    if n < 2:
        return False
    if n % 2 == 0:
        return n == 2
    return all(n % p for p in range(3, math.isqrt(n) + 1, 2))


def seed_primes(seed: int, count: int = 3) -> list[int]:
    """`count` distinct primes > 10000 (what LIGGGHTS' random seeds must be) derived from a
    scenario seed: the first prime at or above 1 000 003 + 10 000 (seed mod 200 000) + 1000 k
    for k = 0 .. count-1 (prime gaps there are far below 1000, so they are distinct, and the
    result stays below 2^31)."""
    base = 1_000_003 + 10_000 * (int(seed) % 200_000)
    return [next_prime(base + 1000 * k) for k in range(count)]


def _check_exportable(scenario) -> None:
    if scenario.explicit or scenario.tub is None or scenario.fill is None:
        raise InputError("scenario.particles: the LIGGGHTS export handles tub scenarios only "
                         "(no explicit particles or walls)")
    if scenario.walls:
        raise InputError("scenario.walls: the LIGGGHTS export handles tub scenarios only")


def type_materials(scenario) -> list[str]:
    """Material of atom types 1, 2, 3: the balls, the tub wall, the partitions; then one type
    per part of [[parts]] (4, 5, ...), in the scenario's order, each its own part's material."""
    return [scenario.fill.material, scenario.tub.wall_material,
            scenario.tub.partition_material, *(p.material for p in scenario.parts or [])]


def ball_mass(scenario) -> float:
    r = 0.5 * scenario.fill.diameter
    return 4.0 / 3.0 * math.pi * r**3 * scenario.materials[scenario.fill.material].density


@dataclass(frozen=True)
class PairTables:
    """Per-type-pair property tables (n x n, symmetric; n = 3 + the number of parts) for
    `fix property/global`."""

    model: str                  # "hooke/stiffness" or "hertz"
    rolling: str                # "cdt", "epsd2" or "none"
    kn: np.ndarray              # N/m
    kt: np.ndarray              # N/m
    gamman_abs: np.ndarray      # N s/m
    gammat_abs: np.ndarray      # N s/m (zero: no tangential damping)
    restitution: np.ndarray
    friction: np.ndarray
    rolling_friction: np.ndarray


def pair_tables(scenario) -> PairTables:
    """LIGGGHTS per-type-pair tables of a tub scenario (types: ball, tub wall, partition, then
    each part).

    Ball-ball pairs use m_eff = m/2, ball-wall and ball-part pairs m_eff = m (a wall or a fixed
    part is infinitely heavy), so gamman_abs = 2 zeta sqrt(m_eff k_n) (models.md).  Pairs that
    never touch (wall-wall, wall-part) copy the ball-ball entry, since LIGGGHTS wants every
    entry to be valid.
    """
    _check_exportable(scenario)
    mats = type_materials(scenario)
    m = ball_mass(scenario)
    n_types = len(mats)
    needed = {(0, 0): 0.5 * m, **{(0, t): m for t in range(1, n_types)}}
    shape = (n_types, n_types)
    kn, kt, gn, gt = (np.zeros(shape) for _ in range(4))
    e, mu, mur = (np.zeros(shape) for _ in range(3))
    models, rolls = set(), set()
    for (i, j), m_eff in needed.items():
        pair = find_contact(scenario, mats[i], mats[j])
        if pair is None:
            raise InputError(f"contacts: no contact law for the pair ({mats[i]}, {mats[j]}), "
                             "which the LIGGGHTS deck needs")
        models.add(pair.model)
        rolls.add(pair.rolling_model)
        for a, b in ((i, j), (j, i)):
            if pair.model == "linear":
                kn[a, b] = pair.k_n
                kt[a, b] = pair.k_t_over_k_n * pair.k_n
                gn[a, b] = 2.0 * damping_ratio(pair.restitution) * math.sqrt(m_eff * pair.k_n)
            e[a, b] = pair.restitution
            mu[a, b] = pair.friction
            mur[a, b] = pair.rolling_friction
    if len(models) > 1:
        raise InputError(f"contacts.model = {sorted(models)}: LIGGGHTS uses one normal model for "
                         "all pairs; make them all linear or all hertz")
    if len(rolls) > 1:
        raise InputError(f"contacts.rolling_model = {sorted(rolls)}: LIGGGHTS uses one rolling "
                         "model for all pairs; make them equal")
    for i in range(n_types):
        for j in range(n_types):
            if (min(i, j), max(i, j)) not in needed:
                for arr in (kn, kt, gn, e, mu, mur):
                    arr[i, j] = arr[0, 0]
    model = "hooke/stiffness" if models == {"linear"} else "hertz"
    rolling = {"cdt": "cdt", "cdt_liggghts": "cdt", "epsd": "epsd2",
               "none": "none"}[rolls.pop()]
    return PairTables(model, rolling, kn, kt, gn, gt, e, mu, mur)


def model_arguments(tables: PairTables) -> tuple[str, str]:
    """The model part and the keyword part of `pair_style gran` / `fix wall/gran`."""
    rolling = "" if tables.rolling == "none" else f" rolling_friction {tables.rolling}"
    if tables.model == "hooke/stiffness":
        return (f"model hooke/stiffness tangential history{rolling}",
                "absolute_damping on tangential_damping off limitForce off")
    return (f"model hertz tangential history{rolling}", "tangential_damping off limitForce off")


def _contact_law_deck(scenario, tables: PairTables | None = None) -> _Deck:
    """The deck lines of `contact_law_lines`, as a _Deck."""
    tables = tables or pair_tables(scenario)
    mats = type_materials(scenario)
    deck = _Deck()
    for fix, field in (("youngsModulus", "youngs_modulus"), ("poissonsRatio", "poisson_ratio")):
        deck.add(f"fix {fix} all property/global {fix} peratomtype "
                 + " ".join([_SLOT] * len(mats)),
                 *(_fmt(getattr(scenario.materials[mt], field)) for mt in mats))
    _table(deck, "coefficientRestitution", tables.restitution)
    _table(deck, "coefficientFriction", tables.friction)
    _table(deck, "coefficientRollingFriction", tables.rolling_friction)
    if tables.model == "hooke/stiffness":
        deck.add("# k_n (N/m); k_t = k_t_over_k_n k_n (N/m); gamma_n = 2 zeta sqrt(m_eff k_n) "
                 "(N s/m),")
        deck.add("# m_eff = m/2 ball-ball, m ball-wall, m = {} kg; no tangential damping",
                 ball_mass(scenario))
        _table(deck, "kn", tables.kn)
        _table(deck, "kt", tables.kt)
        _table(deck, "gamman_abs", tables.gamman_abs)
        _table(deck, "gammat_abs", tables.gammat_abs)
    model_args, model_kw = model_arguments(tables)
    deck.add()
    deck.add(f"pair_style      gran {model_args} {model_kw}")
    deck.add("pair_coeff      * *")
    return deck


def contact_law_lines(scenario, tables: PairTables | None = None) -> list[str]:
    """Deck lines that define the materials and the contact law: the `fix property/global`
    tables (types 1 = balls, 2 = tub wall, 3 = partitions, 4 and up the parts), `pair_style gran` and
    `pair_coeff`.  The wall fix uses the same model (`model_arguments`)."""
    return _contact_law_deck(scenario, tables).lines()


def dump_vibration_steps(scenario) -> np.ndarray:
    """Vibration steps (from the start of vibration) of the snapshots: the same instants as
    vibroflow's own DEM (vibroflow.dem.sampling.sample_steps)."""
    steps, _, _ = sample_steps(scenario, scenario.run.dt)
    return np.asarray(steps, dtype=np.int64)
