"""The LIGGGHTS round trip: write a LIGGGHTS 3.8 deck for a tub scenario, read its dumps back.

    export_deck(scenario, DIR)      DIR/in.tub, tub_u.stl, partitions.stl, scenario.toml,
                                    README.txt, post/ (where LIGGGHTS writes)
    mpirun -np 2 liggghts -in in.tub    (in DIR; see README.txt and docs/liggghts.md)
    import_run(DIR/post, scenario, OUT) OUT/dem.h5 (vibroflow's DEM layout, source "liggghts"),
                                    OUT/summary.json, OUT/bulk_velocity.csv

What the deck does, and why (details and the deviations from vibroflow's own DEM in
docs/liggghts.md):

* Contact law.  vibroflow's linear spring-dashpot is LIGGGHTS' `hooke/stiffness` with
  `absolute_damping on` (so the damping coefficients are in N s/m, not per unit mass) and
  `tangential_damping off`, per type pair: kn = k_n, kt = k_t_over_k_n k_n,
  gamman_abs = 2 zeta sqrt(m_eff k_n) with zeta = -ln e / sqrt(pi^2 + ln^2 e) and m_eff = m/2
  for ball-ball, m for ball-wall (models.md), gammat_abs = 0; Coulomb friction and the CDT rolling
  resistance from the pair's mu and mu_r.  A scenario whose contacts are all Hertz gets LIGGGHTS'
  `hertz` (moduli from the materials, restitution through LIGGGHTS' own damping formula).
* Atom types: 1 = the balls' material, 2 = the tub wall's, 3 = the partitions'.
* Walls: the U and the partitions as STL meshes (vibroflow.io.stl; the U's facets joined into
  one smooth surface by `curvature`, so contact histories cross their creases), moved rigidly
  with the tub by two superposed `fix move/mesh` per mesh: `linear/variable` (the translation) then
  `rotate/variable` about the pivot (whose origin rides with the translation).  Their velocity
  variables are the exact derivatives of s(a, phi, t) = a [sin(omega t + phi) - sin(phi)], and
  LIGGGHTS integrates them once a step with the step counter already advanced, so the variables
  are evaluated at the middle of the step, t = (step - n0 - 1/2) dt: the midpoint rule, which
  reproduces X(t), Z(t), theta(t) with every phase to O(dt^2) (measured: 1e-8 m).
* Fill: `fix insert/rate/region` (random, no overlaps) in the U above insert_above, in events
  0.05 s apart, repeated until all N balls are in; then settling with the tub at rest for
  fill.settle_time and, like vibroflow, on in 0.01 s chunks until the kinetic energy per ball
  is below fill.settle_kinetic_energy or fill.max_settle_time has passed.  Seeds are primes
  derived from run.seed (`seed_primes`).
* Vibration for run.duration from step n0 (written to post/vibration_start_step.txt), snapshots
  (`dump custom`, post/balls.dump), ball-wall contacts (`compute wall/gran/local`,
  post/wall.dump) and ball-ball contacts (`compute pair/gran/local id force`, post/pairs.dump)
  at exactly the vibration steps vibroflow samples (vibroflow.dem.run.sample_steps:
  phases_per_cycle instants a cycle over the whole cycles of the last average_last seconds,
  each rounded to the nearest step) through `dump_modify every v_...` with a file-style
  variable; the kinetic energy every run.series_every steps (post/series.txt).

Bad input writes nothing.  The deck is a program (a newline starts a command, and `shell` runs
anything), so it is built from this module's template lines with slots, every user-derived value
one token of a safe set (names through `safe_name`, numbers finite), and each written line is
checked against its template (`_Deck`).  The importer refuses any dump that is not whole, in
one line naming the file and the line (`read_dump`).  Both write under the folder's lock
(vibroflow.io.folder_lock) and put their files in place only once everything is checked.

The importer recomputes the tub pose of every snapshot from the scenario (the pose is a known
function of time), so no pose file is needed.  It maps the pair dump's atom ids to the sorted
snapshot, orders each pair i < j (negating the force when it swaps them: the dumped force is
the one on the first id, PAIR_FORCE_SIGN) and checks on every import that the contacts touch
and push on the whole (PairCheck).
"""
from __future__ import annotations

import contextlib
import math
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroflow.tub.geometry import geometry_of
from vibroflow.scenario.laws import damping_ratio
from vibroflow.dem.walls import WALL_PARTITION_HI, WALL_PARTITION_LO, WALL_U
from vibroflow.errors import InputError
from vibroflow.io.atomic import TMP_PREFIX, write_json_atomic, write_text_atomic
from vibroflow.io.folder_lock import check_writable_dir, folder_lock
from vibroflow.scenario.model import find_contact
from vibroflow.io.stl import DEFAULT_MAX_SAGITTA, arc_segments, sagitta, write_tub_meshes
from vibroflow.tub.motion import TubMotion, lab_to_tub_np, pose_np

#: names the LIGGGHTS executable goes by (Debian: liggghts; source builds: lmp_auto)
BINARY_NAMES = ("liggghts", "lmp_auto", "lmp_fedora", "lmp_ubuntu", "lmp")

DECK_NAME = "in.tub"
POST_DIR = "post"
BALL_DUMP = "balls.dump"
WALL_DUMP = "wall.dump"
PAIR_DUMP = "pairs.dump"
SERIES_FILE = "series.txt"
START_FILE = "vibration_start_step.txt"
FILL_FILE = "fill_done.txt"
SETTLE_FILE = "settle_done.txt"

#: seconds between insertion events of the fill
FILL_EVENT_INTERVAL = 0.05
#: fraction of the insertion region's volume one event tries to fill
FILL_EVENT_FRACTION = 0.15
#: settling chunk after settle_time (s), as vibroflow.dem.fill.settle
SETTLE_CHUNK = 0.01

#: relative tolerance of |F_t| = mu |F_n| that marks a wall contact as sliding
SLIDING_TOLERANCE = 1.0e-4


# ----------------------------------------------------------------------------------------------
# Running LIGGGHTS

def find_liggghts() -> str | None:
    """Path of the LIGGGHTS executable, or None.  $LIGGGHTS overrides the search."""
    env = os.environ.get("LIGGGHTS")
    if env:
        return shutil.which(env) or (env if os.access(env, os.X_OK) else None)
    for name in BINARY_NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


def mpirun_command(nprocs: int = 2, binary: str | None = None,
                   deck: str = DECK_NAME) -> list[str]:
    """The command line that runs a deck on `nprocs` MPI ranks (Open MPI's mpirun; as root it
    needs --allow-run-as-root, and --oversubscribe lets 2 ranks run on a 1-core machine)."""
    binary = binary or find_liggghts()
    if binary is None:
        raise RuntimeError("LIGGGHTS not found (install the Debian package: apt-get install -y "
                           "liggghts; or set $LIGGGHTS)")
    cmd = [binary, "-in", deck]
    if nprocs <= 1:
        return cmd
    mpirun = shutil.which("mpirun") or shutil.which("mpiexec")
    if mpirun is None:
        raise RuntimeError("mpirun not found (apt-get install -y openmpi-bin)")
    extra = ["--oversubscribe"]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        extra.insert(0, "--allow-run-as-root")
    return [mpirun, *extra, "-np", str(nprocs), *cmd]


def run_deck(deck_dir, nprocs: int = 2, binary: str | None = None, timeout: float | None = None,
             log_name: str = "log.liggghts") -> subprocess.CompletedProcess:
    """Run DIR/in.tub in DIR on `nprocs` ranks; stdout+stderr go to DIR/screen.txt.  Raises
    RuntimeError (with the tail of the output) when LIGGGHTS fails."""
    deck_dir = Path(deck_dir)
    cmd = mpirun_command(nprocs, binary)
    cmd += ["-log", log_name]
    env = dict(os.environ)
    env.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")  # containers
    env.setdefault("OMP_NUM_THREADS", "1")
    with open(deck_dir / "screen.txt", "w") as out:
        proc = subprocess.run(cmd, cwd=deck_dir, stdout=out, stderr=subprocess.STDOUT,
                              timeout=timeout, env=env)
    text = (deck_dir / "screen.txt").read_text(errors="replace")
    if proc.returncode != 0 or "ERROR" in text:
        tail = "\n".join(text.splitlines()[-25:])
        raise RuntimeError(f"LIGGGHTS failed (exit {proc.returncode}) in {deck_dir}:\n{tail}")
    return proc


@dataclass(frozen=True)
class LoopTime:
    """One "Loop time of T on P procs for S steps with N atoms" line of a LIGGGHTS log."""

    seconds: float
    procs: int
    steps: int
    atoms: int

    @property
    def particle_steps_per_s(self) -> float:
        return self.atoms * self.steps / self.seconds if self.seconds > 0 else float("nan")


_LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs? for (\d+) steps with (\d+) atoms")


def loop_times(log_path) -> list[LoopTime]:
    """Every run's loop time in a LIGGGHTS log (or screen output), in order."""
    text = Path(log_path).read_text(errors="replace")
    return [LoopTime(float(a), int(b), int(c), int(d)) for a, b, c, d in _LOOP.findall(text)]


# ----------------------------------------------------------------------------------------------
# Parameters

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
    """Material of atom types 1, 2, 3: the balls, the tub wall, the partitions."""
    return [scenario.fill.material, scenario.tub.wall_material, scenario.tub.partition_material]


def ball_mass(scenario) -> float:
    r = 0.5 * scenario.fill.diameter
    return 4.0 / 3.0 * math.pi * r**3 * scenario.materials[scenario.fill.material].density


@dataclass(frozen=True)
class PairTables:
    """Per-type-pair property tables (3 x 3, symmetric) for `fix property/global`."""

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
    """LIGGGHTS per-type-pair tables of a tub scenario (types: ball, tub wall, partition).

    Ball-ball pairs use m_eff = m/2, ball-wall pairs m_eff = m (a wall is infinitely heavy), so
    gamman_abs = 2 zeta sqrt(m_eff k_n) (models.md).  Pairs that never touch (wall-wall) copy the
    ball-ball entry, since LIGGGHTS wants every entry to be valid.
    """
    _check_exportable(scenario)
    mats = type_materials(scenario)
    m = ball_mass(scenario)
    needed = {(0, 0): 0.5 * m, (0, 1): m, (0, 2): m}
    shape = (3, 3)
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
    for i in range(3):
        for j in range(3):
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
        deck.add(f"fix {fix} all property/global {fix} peratomtype {_SLOT} {_SLOT} {_SLOT}",
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
    tables (types 1 = balls, 2 = tub wall, 3 = partitions), `pair_style gran` and
    `pair_coeff`.  The wall fix uses the same model (`model_arguments`)."""
    return _contact_law_deck(scenario, tables).lines()


def dump_vibration_steps(scenario) -> np.ndarray:
    """Vibration steps (from the start of vibration) of the snapshots: the same instants as
    vibroflow's own DEM (vibroflow.dem.run.sample_steps)."""
    run, f, dt = scenario.run, scenario.motion.frequency, scenario.run.dt
    try:
        from vibroflow.dem.run import sample_steps
    except ImportError:  # pragma: no cover - dem package absent
        sample_steps = None
    if sample_steps is not None:
        steps, _, _ = sample_steps(scenario, dt)
        return np.asarray(steps, dtype=np.int64)
    n_cycles = int(math.floor(run.average_last * f + 1e-9))
    t0 = run.duration - n_cycles / f
    k = np.arange(n_cycles * run.phases_per_cycle)
    return np.round((t0 + k / (f * run.phases_per_cycle)) / dt).astype(np.int64)


# ----------------------------------------------------------------------------------------------
# What user input may put into a deck
#
# A LIGGGHTS deck is a program: a newline in a value starts a new command (and `shell` runs
# anything), `&` at a line's end joins the next line, `#` starts a comment, `$` substitutes a
# variable, quotes group words.  So the deck is built from lines whose text is a literal of
# this module (a template) with slots ("{}") for values, and every value is rendered as one
# token of a small safe set: a number (_fmt), a whole number, or a name of SAFE_NAME's
# characters.  A scenario can then fill a slot but never add a word, a line, a comment, a
# variable or a quoted string the template did not have; the written text is checked line by
# line against the templates (`_Deck.render`) before anything goes to disk.

#: the names a deck or its README may carry (case, materials, file names): the scenario's own
#: rule for names
SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")
SAFE_NAME_RULE = ("1 to 64 characters of A-Z a-z 0-9 _ . + -, the first a letter or a digit "
                  "(it is written into the LIGGGHTS deck)")
#: one value of a deck line: a number, a whole number, a safe name, or a lone * (LIGGGHTS'
#: "any", in `processors`)
_TOKEN = r"(?:[A-Za-z0-9_.+-]+|\*)"
_TOKEN_RE = re.compile(_TOKEN)
#: a slot of a template
_SLOT = "{}"
#: the `processors` grid: three counts, each a whole number or *
_PROCESSORS = re.compile(r"(?:\*|[1-9][0-9]{0,5})(?: (?:\*|[1-9][0-9]{0,5})){2}")


def _short(value, limit: int = 80) -> str:
    """repr(value), cut to `limit` characters (one line: repr escapes newlines)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def safe_name(field: str, value) -> str:
    """`value` if it is a name a deck may carry (SAFE_NAME), else a one-line InputError naming
    `field`.  The guard of every user-derived string of the deck and its README."""
    if not isinstance(value, str) or SAFE_NAME.fullmatch(value) is None:
        raise InputError(f"{field} = {_short(value)}: must be {SAFE_NAME_RULE}")
    return value


def _whole(field: str, value, minimum: int = 0) -> int:
    """A user-derived whole number for the deck, at least `minimum`; InputError otherwise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < minimum:
        raise InputError(f"{field} = {_short(value)}: must be a whole number >= {minimum}")
    return int(value)


def _fmt(x) -> str:
    """A real number as a deck token (10 significant digits); InputError unless finite."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise InputError(f"LIGGGHTS deck number = {_short(x)}: must be a real number") from None
    if not math.isfinite(v):
        raise InputError(f"LIGGGHTS deck number = {v!r}: must be finite (a scenario value is "
                         "nan or inf, or a quantity made from them overflows)")
    return f"{v:.10g}"


def _token(value, template: str) -> str:
    """One slot's value as deck text: int -> decimal, float -> _fmt, str -> as is; each must
    be a single _TOKEN."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        text = str(int(value))
    elif isinstance(value, (float, np.floating)):
        text = _fmt(value)
    elif isinstance(value, str):
        text = value
    else:
        text = None
    if text is None or _TOKEN_RE.fullmatch(text) is None:
        raise InputError(f"LIGGGHTS deck value = {_short(value)} (in {template!r}): must be a "
                         "number or a name of A-Z a-z 0-9 _ . + -, nothing LIGGGHTS or a shell "
                         "reads specially")
    return text


class _Deck:
    """Lines of a deck (or of its README), each a template and the values of its slots.

    A template is text of this module: a literal, or literals joined by code; it holds no
    newline and no user input, which goes into the slots only (rendered by `_token`)."""

    def __init__(self) -> None:
        self._lines: list[tuple[str, tuple]] = []

    def add(self, template: str = "", *values) -> None:
        if "\n" in template or "\r" in template or template.count(_SLOT) != len(values):
            raise ValueError(f"deck template {template!r}: one line with {len(values)} slots "
                             "expected (a bug in vibroflow.io.liggghts)")
        self._lines.append((template, values))

    def add_block(self, template: str, *values) -> None:
        """The lines of a multi-line template, the values shared out to their slots in order."""
        values = list(values)
        for line in template.split("\n"):
            k = line.count(_SLOT)
            self.add(line, *values[:k])
            values = values[k:]
        if values:
            raise ValueError(f"deck template: {len(values)} values left over")

    def extend(self, other: _Deck) -> None:
        self._lines.extend(other._lines)

    def lines(self) -> list[str]:
        return [_fill(template, values) for template, values in self._lines]

    def render(self, name: str) -> str:
        """The text, "\\n" after every line, checked: it has exactly one line per template,
        each line printable ASCII and matched by its template with one _TOKEN per slot."""
        text = "".join(line + "\n" for line in self.lines())
        written = text.split("\n")[:-1]
        if len(written) != len(self._lines):
            raise InputError(f"{name}: {len(written)} lines written for {len(self._lines)} "
                             "template lines (a value held a newline)")
        for k, ((template, _), line) in enumerate(zip(self._lines, written), 1):
            pattern = _TOKEN.join(re.escape(part) for part in template.split(_SLOT))
            if not line.isascii() or not line.isprintable() or \
                    re.fullmatch(pattern, line) is None:
                raise InputError(f"{name} line {k} = {_short(line)}: not the line its template "
                                 f"{template!r} allows")
        return text


def _fill(template: str, values) -> str:
    parts = template.split(_SLOT)
    out = [parts[0]]
    for value, part in zip(values, parts[1:]):
        out += [_token(value, template), part]
    return "".join(out)


def _table(deck: _Deck, name: str, arr: np.ndarray) -> None:
    deck.add(f"fix {name} all property/global {name} peratomtypepair 3 "
             + " ".join([_SLOT] * 9), *(_fmt(v) for v in np.asarray(arr).ravel()))


def _check_names(scenario) -> None:
    """Every name of the scenario that reaches the deck or its README passes `safe_name`, and
    the materials named are defined."""
    safe_name("case", scenario.case)
    materials = scenario.materials if isinstance(scenario.materials, dict) else {}
    for field, name in (("fill.material", scenario.fill.material),
                        ("tub.wall_material", scenario.tub.wall_material),
                        ("tub.partition_material", scenario.tub.partition_material)):
        safe_name(field, name)
        if name not in materials:
            raise InputError(f"{field} = {name!r}: not one of the scenario's materials "
                             f"{sorted(map(str, materials))}")


# ----------------------------------------------------------------------------------------------
# The deck

def _scenario_toml(scenario) -> str:
    try:
        from vibroflow.scenario.io import dump_scenario
    except ImportError:  # pragma: no cover
        dump_scenario = None
    if dump_scenario is not None:
        return dump_scenario(scenario)
    import tomli_w
    return tomli_w.dumps(scenario.model_dump(mode="json", exclude_none=True))


@dataclass(frozen=True)
class DeckInfo:
    """What export_deck wrote and the numbers it chose."""

    directory: Path
    deck: Path
    n_particles: int
    dt: float
    vibration_steps: int
    dump_steps: np.ndarray       # vibration steps of the snapshots
    arc_segments: int
    max_sagitta: float
    seeds: list[int]
    fill_per_event: int
    fill_event_steps: int
    settle_steps: int
    tables: PairTables


#: the meshes' files, as vibroflow.io.stl.write_tub_meshes names them
U_MESH_FILE = "tub_u.stl"
PARTITION_MESH_FILE = "partitions.stl"


def export_deck(scenario, out_dir, *, wall_contacts: bool = True, pair_contacts: bool = True,
                max_sagitta: float = DEFAULT_MAX_SAGITTA, thermo_every: int | None = None,
                processors: str = "* 1 1", mesh_curvature_deg: float | None = None) -> DeckInfo:
    """Write a LIGGGHTS 3.8 deck for a tub scenario into out_dir (see the module docstring).

    wall_contacts: dump the ball-wall contacts at the snapshots (compute wall/gran/local).
    pair_contacts: dump the ball-ball contacts (the two ids and the contact force) at the
    snapshots (compute pair/gran/local), for the contact stress of the calibration.
    processors: LIGGGHTS processor grid; the default splits the tub across x only, which
    balances a symmetric bed.
    mesh_curvature_deg: `curvature` of the U's fix mesh/surface, the largest angle between two
    facets that LIGGGHTS treats as one smooth surface (carrying a contact's tangential history
    across their common edge, no edge contact).  Default: twice the angle between neighbouring
    arc facets (5.9 degrees for tub47), so the faceted circle acts as one surface like the
    analytic one; 0 keeps LIGGGHTS' default (0.26 degrees: every crease is an edge).
    Returns a DeckInfo.

    Every file is made and checked in memory first (names through `safe_name`, the deck and
    README line by line against their templates, `_Deck`), so bad input writes nothing; then
    they are written atomically under out_dir's folder lock.
    """
    _check_exportable(scenario)
    _check_names(scenario)
    if not isinstance(processors, str) or _PROCESSORS.fullmatch(processors) is None:
        raise InputError(f"processors = {_short(processors)}: must be three counts, each a "
                         "whole number >= 1 or *, such as '* 1 1'")
    out_dir = Path(out_dir)
    run, fill, tub = scenario.run, scenario.fill, scenario.tub
    count = _whole("fill.count", fill.count, 1)
    ke_every = _whole("run.series_every", run.series_every, 1)
    geom = geometry_of(scenario)
    motion = TubMotion.of_scenario(scenario)
    tables = pair_tables(scenario)
    dt = run.dt
    d = fill.diameter
    r = 0.5 * d
    skin = run.skin * d
    R, rim, L = tub.radius, tub.rim_height, tub.length
    periodic = tub.periodic
    mats = type_materials(scenario)
    seeds = seed_primes(run.seed, 3)

    n_arc = arc_segments(R, max_sagitta)
    if mesh_curvature_deg is None:
        mesh_curvature_deg = min(10.0, 2.0 * 180.0 / n_arc)

    # simulation box: the tub plus room for its motion (translation <= 2 A, rotation about the
    # pivot) and for balls thrown above the rim
    reach = 2.0 * max(motion.amplitude_x, motion.amplitude_z)
    lever = math.hypot(R + abs(motion.pivot_x), rim - motion.pivot_z)
    swing = 2.0 * motion.amplitude_theta * lever
    pad = reach + swing + 4.0 * d
    x_lo, x_hi = -R - pad, R + pad
    z_lo, z_hi = -pad, rim + max(0.2, 10.0 * d) + pad
    if periodic:
        y_lo, y_hi = 0.0, L
    else:
        y_lo, y_hi = -4.0 * d, L + 4.0 * d

    # insertion region: ball centres at least r + skin/2 from every wall (LIGGGHTS' rule for
    # mesh walls), above insert_above (ball bottoms) and below the rim
    margin = r + 0.5 * skin
    ins_z_lo = max(fill.insert_above + r, margin)
    ins_z_hi = rim - margin
    if periodic:
        iy_lo, iy_hi = 0.0, L
    else:
        iy_lo, iy_hi = margin, L - margin
    if iy_hi - iy_lo <= 0 or ins_z_hi <= ins_z_lo or R - margin <= 0:
        raise InputError(f"tub.length = {L}: too short to insert balls of diameter {d} with "
                         f"a skin of {skin:.3g} m away from the partitions")
    # volume of the insertion region (centres), cross-section of the shrunk U above ins_z_lo
    area = _shrunk_u_area(R, margin, ins_z_lo, ins_z_hi)
    v_region = area * (iy_hi - iy_lo)
    v_ball = 4.0 / 3.0 * math.pi * r**3
    per_event = int(max(1, min(count, math.floor(FILL_EVENT_FRACTION * v_region / v_ball))))
    event_steps = max(1, int(round(FILL_EVENT_INTERVAL / dt)))
    rate = per_event / (event_steps * dt)
    max_passes = 4 * math.ceil(count / per_event) + 20

    settle_steps = int(round(fill.settle_time / dt))
    chunk_steps = max(1, int(round(SETTLE_CHUNK / dt)))
    extra_settle = max(0.0, fill.max_settle_time - fill.settle_time)
    max_chunks = int(math.ceil(extra_settle / (chunk_steps * dt) - 1e-9))

    vib_steps = int(round(run.duration / dt))
    dsteps = dump_vibration_steps(scenario)
    dsteps = dsteps[(dsteps >= 0) & (dsteps <= vib_steps)]
    thermo_every = _whole("thermo_every", thermo_every, 1) if thermo_every else \
        max(1, int(round(0.01 / dt)))

    w = motion.omega
    # dump steps relative to the vibration start; a sentinel far beyond the run ends the list
    first_now = dsteps.size and dsteps[0] == 0
    rest = dsteps[1:] if first_now else dsteps
    step_lines = "".join(f"{int(s)}\n" for s in rest)
    # two sentinels: LIGGGHTS reads one line ahead of what next() returns
    step_lines += f"{vib_steps + 10**9}\n{vib_steps + 10**9 + 1}\n"

    model_args, model_kw = model_arguments(tables)
    first = " first yes" if first_now else ""
    S = _SLOT

    deck = _Deck()
    add = deck.add
    add("# LIGGGHTS 3.8 deck written by vibroflow.io.liggghts for case '{}'", scenario.case)
    add("# Run in this folder:  mpirun -np 2 liggghts -in in.tub   (see README.txt)")
    add("# SI units.  Atom types: 1 = balls ({}), 2 = tub wall ({}), 3 = partitions ({}).", *mats)
    add()
    add("atom_style      granular")
    add("atom_modify     map array sort 0 0")
    add(f"boundary        f {'p' if periodic else 'f'} f")
    add("newton          off")
    add("communicate     single vel yes")
    add("units           si")
    add("hard_particles  yes")
    add("processors      {} {} {}", *processors.split())
    add()
    add("region          domain block {} {} {} {} {} {} units box",
        *(_fmt(v) for v in (x_lo, x_hi, y_lo, y_hi, z_lo, z_hi)))
    add("create_box      3 domain")
    add("neighbor        {} bin", _fmt(skin))
    add("neigh_modify    delay 0")
    add()
    add("# ---- materials and contact law (per type pair; see docs/liggghts.md)")
    deck.extend(_contact_law_deck(scenario, tables))
    add("timestep        {}", _fmt(dt))
    g = np.asarray(scenario.gravity, dtype=float)
    gn = float(np.linalg.norm(g))
    if gn > 0:
        gv = g / gn
        add("fix gravi all gravity {} vector {} {} {}", *(_fmt(v) for v in (gn, *gv)))
    add("fix integr all nve/sphere")
    add()
    add("# ---- walls: the U ({} arcs on the half circle, sagitta {} mm) and the partitions, "
        "moving with the tub", n_arc, f"{sagitta(R, n_arc) * 1e3:.4f}")
    u_file = safe_name("U mesh file", U_MESH_FILE)
    if mesh_curvature_deg > 0:
        add("fix tub all mesh/surface file {} type 2 curvature {}", u_file,
            _fmt(mesh_curvature_deg))
    else:
        add("fix tub all mesh/surface file {} type 2", u_file)
    if not periodic:
        add("fix parts all mesh/surface file {} type 3",
            safe_name("partition mesh file", PARTITION_MESH_FILE))
    add(f"fix walls all wall/gran {model_args} mesh n_meshes "
        + ("1 meshes tub " if periodic else "2 meshes tub parts ") + model_kw)
    add()
    add("# ---- output between runs")
    add("compute ke all ke")
    add("compute rke all erotate/sphere")
    add("variable ekin equal c_ke+c_rke")
    add("variable natoms equal atoms")
    add("variable keball equal (c_ke+c_rke)/(atoms+1.0e-300)")
    if wall_contacts:
        # (LIGGGHTS wants this compute defined before the first run)
        add("compute wallc all wall/gran/local id force_normal force_tangential")
    if pair_contacts:
        # id: the two atom ids and a periodic-image flag; force: the contact force on the
        # first of them (checked at import, _pair_rows)
        add("compute pairc all pair/gran/local id force")
    add("thermo_style    custom step atoms c_ke c_rke cpu")
    add("thermo          {}", thermo_every)
    add("thermo_modify   lost error norm no")
    add()
    add("# ---- fill: {} balls, d = {} m, in events of {} every {} steps, until all are in",
        count, _fmt(d), per_event, event_steps)
    add("fix pts1 all particletemplate/sphere {} atom_type 1 density constant {} radius "
        "constant {}", seeds[0], _fmt(scenario.materials[fill.material].density), _fmt(r))
    add("fix pdd1 all particledistribution/discrete {} 1 pts1 1.0", seeds[1])
    add("region ucyl cylinder y 0 {} {} {} {} units box",
        *(_fmt(v) for v in (R, R - margin, iy_lo, iy_hi)))
    add("region ublk block {} {} {} {} {} {} units box",
        *(_fmt(v) for v in (-R + margin, R - margin, iy_lo, iy_hi, R, ins_z_hi)))
    add("region uin union 2 ucyl ublk")
    add("region zcut block INF INF INF INF {} {} units box", _fmt(ins_z_lo), _fmt(ins_z_hi))
    add("region ins intersect 2 uin zcut")
    add("fix ins all insert/rate/region seed {} distributiontemplate pdd1 nparticles {} "
        "particlerate {} insert_every {} overlapcheck yes all_in no maxattempt 200 vel "
        "constant 0. 0. 0. region ins ntry_mc 200000", seeds[2], count, _fmt(rate),
        event_steps)
    add("variable fillpass loop {}", max_passes)
    add("label fill_loop")
    add("run {}", event_steps)
    add('if "${natoms} >= {}" then "jump SELF fill_done"', count)
    add("next fillpass")
    add("jump SELF fill_loop")
    add("label fill_done")
    add("variable fillpass delete")
    add("unfix ins")
    add("variable stepnow equal step")
    add(f'print "${{stepnow}} ${{natoms}}" file {POST_DIR}/{FILL_FILE}')
    add('if "${natoms} < {}" then "print \'vibroflow: the fill inserted only ${natoms} of {} '
        'balls\'"', count, count)
    add()
    add("# ---- settle with the tub at rest: {} s, then on in {} s chunks until the kinetic "
        "energy per ball < {} J (at most {} s)", _fmt(fill.settle_time),
        _fmt(chunk_steps * dt), _fmt(fill.settle_kinetic_energy), _fmt(fill.max_settle_time))
    if settle_steps > 0:
        add("run {}", settle_steps)
    if max_chunks > 0:
        add("variable settlepass loop {}", max_chunks)
        add("label settle_loop")
        add('if "${keball} < {}" then "jump SELF settle_done"',
            _fmt(fill.settle_kinetic_energy))
        add("run {}", chunk_steps)
        add("next settlepass")
        add("jump SELF settle_loop")
        add("label settle_done")
        add("variable settlepass delete")
    add(f'print "${{stepnow}} ${{keball}}" file {POST_DIR}/{SETTLE_FILE}')
    add()
    add("# ---- vibration: t = (step - n0) dt")
    add("variable n0 equal ${stepnow}")
    add(f'print "${{n0}}" file {POST_DIR}/{START_FILE}')
    add("# tub velocity = d/dt of s(a, phi, t) = a [sin(w t + phi) - sin(phi)], evaluated at the")
    add("# middle of each step (LIGGGHTS advances the step counter before moving the mesh), so")
    add("# the integrated pose is exact to O(dt^2) with every phase")
    add("variable tmid equal (step-${n0}-0.5)*{}", _fmt(dt))
    add("variable vX equal {}*cos({}*v_tmid+{})", _fmt(motion.amplitude_x * w), _fmt(w),
        _fmt(motion.phase_x))
    add("variable vY equal 0.0")
    add("variable vZ equal {}*cos({}*v_tmid+{})", _fmt(motion.amplitude_z * w), _fmt(w),
        _fmt(motion.phase_z))
    add("# theta > 0 turns x towards z: a turn about -y")
    add("variable wT equal {}*cos({}*v_tmid+{})", _fmt(motion.amplitude_theta * w), _fmt(w),
        _fmt(motion.phase_theta))
    for mesh in (["tub"] if periodic else ["tub", "parts"]):
        add(f"fix move_{mesh}_t all move/mesh mesh {mesh} linear/variable v_vX v_vY v_vZ")
        add(f"fix move_{mesh}_r all move/mesh mesh {mesh} rotate/variable origin {S} 0. {S} "
            "axis 0. -1. 0. omega v_wT", _fmt(motion.pivot_x), _fmt(motion.pivot_z))
    add()
    add(f"# snapshots at {S} vibration steps ({POST_DIR}/dump_steps.txt, relative to n0)",
        dsteps.size)
    add(f"variable dfile file {POST_DIR}/dump_steps.txt")
    add("variable dnext equal ${n0}+next(dfile)")
    add(f"dump dballs all custom 1 {POST_DIR}/{BALL_DUMP} id type x y z vx vy vz "
        "omegax omegay omegaz radius")
    add('dump_modify dballs every v_dnext sort id format "%d %d ' + " ".join(["%.10g"] * 10)
        + '"' + first)
    if wall_contacts:
        add(f"variable wfile file {POST_DIR}/dump_steps.txt")
        add("variable wnext equal ${n0}+next(wfile)")
        add(f"dump dwall all local 1 {POST_DIR}/{WALL_DUMP} "
            + " ".join(f"c_wallc[{k}]" for k in range(1, 10)))
        add("dump_modify dwall every v_wnext" + first)
    if pair_contacts:
        # its own file variable: each next() advances the variable it is called on
        add(f"variable pfile file {POST_DIR}/dump_steps.txt")
        add("variable pnext equal ${n0}+next(pfile)")
        add(f"dump dpairs all local 1 {POST_DIR}/{PAIR_DUMP} "
            + " ".join(f"c_pairc[{k}]" for k in range(1, 7)))
        # 10 digits: the default %g would round the ids above 999999 and the forces to 6 digits
        add('dump_modify dpairs every v_pnext format "' + " ".join(["%.10g"] * 6) + '"' + first)
    add("variable tvib equal (step-${n0})*{}", _fmt(dt))
    add(f'fix series all print {S} "${{tvib}} ${{ekin}}" file {POST_DIR}/{SERIES_FILE} '
        'screen no title "# t_vibration_s kinetic_energy_J"', ke_every)
    add("run {}", vib_steps)
    add('print "vibroflow: vibration of {} steps done"', vib_steps)

    # everything is made and checked before anything is written
    deck_text = deck.render(DECK_NAME)
    readme_text = _readme(scenario, vib_steps, dsteps.size, wall_contacts,
                          pair_contacts).render("README.txt")
    toml_text = _scenario_toml(scenario)

    with folder_lock(out_dir, "vibroflow export liggghts", field="DIR"):
        check_writable_dir(out_dir / POST_DIR, field="DIR")
        meshes = write_tub_meshes(geom, out_dir, max_sagitta)
        names = {k: p.name for k, p in meshes.items()}
        if names != {"u": U_MESH_FILE, **({} if periodic else
                                          {"partitions": PARTITION_MESH_FILE})}:
            raise RuntimeError(f"vibroflow.io.stl wrote {names}, the deck names "
                               f"{U_MESH_FILE}, {PARTITION_MESH_FILE}")
        write_text_atomic(out_dir / POST_DIR / "dump_steps.txt", step_lines)
        deck_path = write_text_atomic(out_dir / DECK_NAME, deck_text)
        write_text_atomic(out_dir / "scenario.toml", toml_text)
        write_text_atomic(out_dir / "README.txt", readme_text)
    return DeckInfo(out_dir, deck_path, count, dt, vib_steps, dsteps, n_arc,
                    sagitta(R, n_arc), seeds, per_event, event_steps, settle_steps, tables)


def _shrunk_u_area(R: float, margin: float, z_lo: float, z_hi: float) -> float:
    """Area (m^2) of the U shrunk by `margin` (circle of radius R - margin centred at (0, R),
    walls at x = +-(R - margin)) between heights z_lo and z_hi."""
    rr = R - margin
    zs = np.linspace(z_lo, z_hi, 4001)
    half = np.where(zs >= R, rr, np.sqrt(np.clip(rr**2 - (zs - R) ** 2, 0.0, None)))
    return float(np.trapezoid(2.0 * half, zs) if hasattr(np, "trapezoid")
                 else np.trapz(2.0 * half, zs))


_README = """LIGGGHTS deck for the vibroflow scenario '{}' (SI units)
=====================================================================

Files: in.tub (the deck), tub_u.stl (the U-shaped tub wall), partitions.stl (the glass
partitions at y = 0 and y = L_y), scenario.toml (the scenario it was written from), post/ (where
LIGGGHTS writes its output; post/dump_steps.txt lists the snapshot steps).

Run it in this folder with LIGGGHTS 3.8 on 2 MPI ranks:

    mpirun -np 2 liggghts -in in.tub

(as root Open MPI also wants --allow-run-as-root, and --oversubscribe on a machine with fewer
cores than ranks; the Debian package's executable is `liggghts`, a source build's `lmp_auto`).

What it does: inserts {} balls at random in the tub, lets them settle with the
tub at rest, then vibrates the tub for {} s ({} steps of
{} s) and writes WRITTEN (all at the same
steps), and the kinetic energy every {} steps to post/SERIES.

Then convert the results into vibroflow's format (dem.h5, summary.json, bulk_velocity.csv):

    vibroflow import liggghts post --out results

(the scenario is read from scenario.toml next to post/).  The tub's pose is not written by
LIGGGHTS: it is a known function of time, recomputed from the scenario by the importer.
"""


def _readme(scenario, vib_steps: int, n_snap: int, wall_contacts: bool,
            pair_contacts: bool = True) -> _Deck:
    """README.txt of a deck folder, as checked template lines (`_Deck`)."""
    outputs = [f"{_SLOT} snapshots of the balls to post/{BALL_DUMP}"]
    if wall_contacts:
        outputs.append(f"the ball-wall contacts to post/{WALL_DUMP}")
    if pair_contacts:
        outputs.append(f"the ball-ball contacts (ids, force) to post/{PAIR_DUMP}")
    written = ", ".join(outputs[:-1]) + (" and " if len(outputs) > 1 else "") + outputs[-1]
    template = _README.replace("WRITTEN", written).replace("SERIES", SERIES_FILE)
    if template.endswith("\n"):
        template = template[:-1]
    run = scenario.run
    text = _Deck()
    text.add_block(template, safe_name("case", scenario.case),
                   _whole("fill.count", scenario.fill.count, 1), _fmt(run.duration), vib_steps,
                   _fmt(run.dt), n_snap, _whole("run.series_every", run.series_every, 1))
    return text


# ----------------------------------------------------------------------------------------------
# Reading LIGGGHTS dumps

#: the longest line a dump may have (bytes): a ball row is about 150, a header a few hundred;
#: a longer "line" is no dump's (a binary file without newlines)
MAX_DUMP_LINE = 1 << 16


@dataclass(frozen=True)
class DumpSnapshot:
    """One snapshot of a dump: its step, column names, data (rows, columns) and where it is
    in the file (line numbers from 1: its ITEM: TIMESTEP and its first row)."""

    step: int
    columns: list[str]
    data: np.ndarray
    line: int
    first_row: int


def _decode(raw: bytes, path, line: int) -> str:
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: line {line}: byte {raw[exc.start]:#04x} at column "
                         f"{exc.start + 1} is not text; a LIGGGHTS text dump is ASCII (a binary "
                         "or compressed file?)") from None


class _Lines:
    """The lines of an open binary dump, counted, each at most MAX_DUMP_LINE bytes."""

    def __init__(self, f, path):
        self.f, self.path, self.n = f, path, 0
        self.cut = False  # the last line read ends the file without a newline

    def raw(self) -> bytes:
        """The next line as bytes (with its newline), b"" at the end of the file."""
        raw = self.f.readline(MAX_DUMP_LINE + 1)
        if raw:
            self.n += 1
        self.cut = bool(raw) and not raw.endswith(b"\n")
        if len(raw) > MAX_DUMP_LINE:
            raise InputError(f"{self.path}: line {self.n}: longer than {MAX_DUMP_LINE} bytes; "
                             "not a LIGGGHTS text dump (a binary file?)")
        return raw

    def text(self) -> str | None:
        raw = self.raw()
        return _decode(raw, self.path, self.n).rstrip("\r\n") if raw else None

    def required(self, what: str) -> str:
        text = self.text()
        if text is None:
            raise InputError(f"{self.path}: the file ends after line {self.n}, where {what} "
                             "belongs (a truncated dump)")
        return text

    def misplaced(self, text: str, expected: str, why: str) -> InputError:
        """The error of the line just read, `text`, where `expected` belongs."""
        if self.cut:
            why = "the file ends within this line: a truncated dump"
        return InputError(f"{self.path}: line {self.n}: {_short(text)} where {expected} belongs "
                          f"({why})")

    def whole(self, what: str) -> int:
        text = self.required(what)
        words = text.split()
        if len(words) != 1 or not words[0].isdigit():
            raise InputError(f"{self.path}: line {self.n}: {what} = {_short(text.strip())}: "
                             "must be a whole number >= 0")
        return int(words[0])


def read_dump(path):
    """Snapshots of a LIGGGHTS/LAMMPS text dump (custom or local), as DumpSnapshot.

    Anything but whole snapshots is refused with a one-line InputError naming the file, the
    line, what is there and what belongs there: text that is not ASCII, a header out of place,
    a count that is not a whole number, more rows claimed than the rest of the file can hold
    (checked before anything is read or allocated), a snapshot cut short, a row with too few
    or too many values, a value that is not a number, and nan or inf (not data: a run that
    blew up).  Blank lines between snapshots are allowed."""
    path = Path(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({(exc.strerror or str(exc)).lower()})") \
            from None
    with f:
        size = os.fstat(f.fileno()).st_size
        src = _Lines(f, path)
        while True:
            text = src.text()
            if text is None:
                return
            if not text.strip():
                continue
            if text.strip() != "ITEM: TIMESTEP":
                raise src.misplaced(text, "'ITEM: TIMESTEP' of the next snapshot",
                                    "more rows than the last ITEM: NUMBER OF says, or not a "
                                    "LIGGGHTS dump")
            at = src.n
            step = src.whole("the timestep")
            text = src.required("'ITEM: NUMBER OF ATOMS' (or ENTRIES)")
            if not text.startswith("ITEM: NUMBER OF "):
                raise src.misplaced(text, "'ITEM: NUMBER OF ATOMS' (or ENTRIES)", f"step {step}")
            what = text[len("ITEM: "):].strip()
            n = src.whole(what)
            count_line = src.n
            text = src.required("'ITEM: ATOMS' (or ENTRIES) and the column names")
            if text.startswith("ITEM: BOX BOUNDS"):
                for _ in range(3):
                    src.required("a line of the box bounds")
                text = src.required("'ITEM: ATOMS' (or ENTRIES) and the column names")
            cols = text.split()[2:]
            if not (text.startswith("ITEM: ATOMS ") or text.startswith("ITEM: ENTRIES ")) \
                    or not cols:
                raise src.misplaced(text, "'ITEM: ATOMS' (or ENTRIES) and the column names",
                                    f"step {step}")
            if len(set(cols)) != len(cols):
                raise InputError(f"{path}: line {src.n}: column names {cols}: each must appear "
                                 "once")
            k = len(cols)
            # every row is at least k one-character values and k - 1 blanks and a newline
            left = size - f.tell()
            if n and n * 2 * k - 1 > left:
                raise InputError(f"{path}: line {count_line}: {what} = {n} (step {step}), but the "
                                 f"{left} bytes left in the file hold at most "
                                 f"{(left + 1) // (2 * k)} rows of {k} values (a truncated or "
                                 "corrupt dump)")
            first = src.n + 1
            rows = []
            for i in range(n):
                raw = src.raw()
                if not raw:
                    raise InputError(f"{path}: the file ends after {i} of the {n} rows of step "
                                     f"{step} ({what} at line {count_line}; a truncated "
                                     "dump)")
                rows.append(raw)
            data = _parse_rows(path, rows, first, cols, what)
            yield DumpSnapshot(step, cols, data, at, first)


def _parse_rows(path, rows: list[bytes], first: int, cols: list[str], what: str) -> np.ndarray:
    """The rows of a snapshot as a float64 array (rows, columns); a one-line InputError at the
    first bad row (`first`: the line number of rows[0])."""
    n, k = len(rows), len(cols)
    if n == 0:
        return np.zeros((0, k))
    try:  # fast: all at once
        words = [row.split() for row in rows]
        if all(len(w) == k for w in words):
            data = np.array([x for w in words for x in w], dtype=float).reshape(n, k)
            if np.isfinite(data).all():
                return data
    except (UnicodeDecodeError, ValueError):
        pass
    # slow: row by row, to say where and what
    data = np.empty((n, k))
    for i, raw in enumerate(rows):
        line = first + i
        text = _decode(raw, path, line).strip()
        if text.startswith("ITEM:"):
            raise InputError(f"{path}: line {line}: {_short(text)} after {i} of the {n} rows "
                             f"that {what} promises (a truncated snapshot)")
        values = text.split()
        if len(values) != k:
            raise InputError(f"{path}: line {line}: {len(values)} values, expected {k} "
                             f"({' '.join(cols)}) (a cut-off line?)")
        for j, (word, col) in enumerate(zip(values, cols)):
            try:
                v = float(word)
            except ValueError:
                raise InputError(f"{path}: line {line}: {col} = {_short(word)}: not a "
                                 "number") from None
            if not math.isfinite(v):
                raise InputError(f"{path}: line {line}: {col} = {word}: must be a finite "
                                 "number (nan or inf is no data: did the run blow up?)")
            data[i, j] = v
    return data


def iter_dump(path):
    """Snapshots of a LIGGGHTS/LAMMPS text dump (custom or local): yields (step, columns, data)
    with data a float64 array (rows, columns).  Bad files: see read_dump."""
    for snap in read_dump(path):
        yield snap.step, snap.columns, snap.data


def _resolve_dump_dir(dump_dir: Path) -> Path:
    dump_dir = Path(dump_dir)
    for cand in (dump_dir, dump_dir / POST_DIR):
        if (cand / BALL_DUMP).is_file():
            return cand
    raise InputError(f"{dump_dir}: no LIGGGHTS dump {BALL_DUMP} here or in {dump_dir / POST_DIR}; "
                     "give the post/ folder (or the deck folder) of a LIGGGHTS run of an "
                     "exported deck")


def _scenario_for(dump_dir: Path, scenario):
    if scenario is not None:
        return scenario
    from vibroflow.scenario.io import load_scenario
    for folder in (dump_dir, dump_dir.parent):
        if (folder / "scenario.toml").is_file():
            return load_scenario(folder / "scenario.toml")
    raise InputError(f"{dump_dir}: no scenario given and no scenario.toml next to the dumps")


def _arc_of(tx, tz, R):
    """Arc coordinate (m, from the bottom, positive towards +x) of the point of the U nearest
    to tub-frame points (tx, tz) (as vibroflow.tub.geometry.u_wall_nearest)."""
    tx = np.asarray(tx, dtype=float)
    tz = np.asarray(tz, dtype=float)
    quarter = 0.5 * math.pi * R
    on_circle = tz <= R
    s_circle = R * np.arctan2(tx, -(tz - R))
    s_side = np.sign(np.where(tx >= 0, 1.0, -1.0)) * (quarter + (tz - R))
    return np.where(on_circle, s_circle, s_side)


def _wall_rows(snap, snap_index, ids, pos_lab, pose, motion, scenario, geom, path):
    """vibroflow wall_contacts rows from one snapshot of the wall/gran/local dump.

    Columns (compute wall/gran/local id force_normal force_tangential): mesh id (0 = the U,
    1 = the partitions), triangle id, particle id, F_n (3), F_t (3) on the ball, lab frame.
    LIGGGHTS-PUBLIC 3.8 does not fill contactPoint (it dumps zeros), so the contact point is
    taken as vibroflow does: the point of the analytic wall nearest to the ball's centre (tub
    frame); it differs from the facet's by at most the facets' sagitta.  F_n is |F_n| signed by
    the analytic wall normal (positive pushing the ball into the tub), F_t is |F_t|, and a
    contact slides when |F_t| >= mu |F_n| (LIGGGHTS truncates the tangential spring there).
    Raises InputError for another number of columns or indices that are not whole numbers.
    """
    data = snap.data
    if data.shape[1] != WALL_COLUMNS:
        raise InputError(f"{path}: line {snap.first_row - 1} (step {snap.step}): "
                         f"{data.shape[1]} columns, expected {WALL_COLUMNS} (compute "
                         "wall/gran/local id force_normal force_tangential)")
    if data.shape[0] == 0:
        return None
    mesh, tri, pid = (_whole_column(path, snap, j) for j in range(3))
    fnv = data[:, 3:6]
    ftv = data[:, 6:9]
    k = np.clip(np.searchsorted(ids, pid), 0, ids.size - 1)
    good = ids[k] == pid
    mesh, tri, k, fnv, ftv = mesh[good], tri[good], k[good], fnv[good], ftv[good]
    if scenario.tub.periodic:
        wall = np.zeros(mesh.shape, np.int8)
    else:
        # partitions.stl: triangles 0, 1 at y = 0, triangles 2, 3 at y = L_y
        wall = np.where(mesh == 0, WALL_U,
                        np.where(tri < 2, WALL_PARTITION_LO, WALL_PARTITION_HI)).astype(np.int8)
    X, Z, th = pose[0], pose[1], pose[2]
    piv = (motion.pivot_x, motion.pivot_z)
    ball = lab_to_tub_np(pos_lab[k], X, Z, th, piv)
    R = geom.radius
    # analytic nearest point and inward normal (tub frame)
    tx, ty, tz = ball[:, 0], ball[:, 1], ball[:, 2]
    rho = np.hypot(tx, tz - R)
    rho = np.where(rho > 0, rho, 1.0)
    on_circle = tz <= R
    ux, uz = tx / rho, (tz - R) / rho
    cx = np.where(on_circle, R * ux, np.where(tx >= 0, R, -R))
    cz = np.where(on_circle, R + R * uz, tz)
    nx = np.where(on_circle, -ux, np.where(tx >= 0, -1.0, 1.0))
    nz = np.where(on_circle, -uz, 0.0)
    ny = np.zeros_like(nx)
    cy = ty.copy()
    lo = wall == WALL_PARTITION_LO
    hi = wall == WALL_PARTITION_HI
    part = lo | hi
    cx = np.where(part, tx, cx)
    cz = np.where(part, tz, cz)
    cy = np.where(lo, 0.0, np.where(hi, geom.length, cy))
    nx = np.where(part, 0.0, nx)
    nz = np.where(part, 0.0, nz)
    ny = np.where(lo, 1.0, np.where(hi, -1.0, ny))
    # normal in lab axes (the rotation turns x towards z)
    c, s = math.cos(th), math.sin(th)
    n_lab = np.stack([c * nx - s * nz, ny, s * nx + c * nz], axis=1)
    # |F_n| as LIGGGHTS splits the force (along the line from the contact point to the centre,
    # the facet's normal), its sign from the analytic wall normal (negative: the damping pulls)
    fn = np.linalg.norm(fnv, axis=1) * np.where(np.einsum("ij,ij->i", fnv, n_lab) < 0, -1.0, 1.0)
    ft = np.linalg.norm(ftv, axis=1)
    arc = np.where(wall == WALL_U, _arc_of(tx, tz, R), np.nan)
    mats = type_materials(scenario)
    mu_u = find_contact(scenario, mats[0], mats[1]).friction
    mu_p = mu_u if scenario.tub.periodic else find_contact(scenario, mats[0], mats[2]).friction
    mu = np.where(wall == WALL_U, mu_u, mu_p)
    # at the limit the ratio is mu to the dump's 6 significant digits
    sliding = (ft > 0) & (ft >= mu * np.abs(fn) * (1.0 - SLIDING_TOLERANCE))
    pos_tub = np.stack([cx, cy, cz], axis=1)
    return {"snapshot": np.full(k.shape, snap_index, np.int32), "particle": k.astype(np.int32),
            "wall": wall, "position_tub": pos_tub.astype(np.float32),
            "arc": arc.astype(np.float32), "fn": fn.astype(np.float32),
            "ft": ft.astype(np.float32), "sliding": sliding,
            "force_lab": (fnv + ftv).astype(np.float32)}


#: columns of the wall/gran/local dump: mesh, triangle and atom id, F_n (3), F_t (3)
WALL_COLUMNS = 9
#: columns of the pair/gran/local dump: id (id1, id2, periodic-image flag), force (3)
PAIR_COLUMNS = 6
#: the `force` of compute pair/gran/local is the force on the first particle of its `id` pair
#: (+1) or on the second (-1).  Established with LIGGGHTS 3.8.0 (Debian), 300 balls settled in
#: a small tub (docs/liggghts.md): 99.97 % of the dumped contacts have F . (r_id1 - r_id2) > 0,
#: and adding F to id1 and -F to id2, plus the wall forces and the weight, gives LIGGGHTS' own
#: per-atom force to 1e-3 m g (tests/test_liggghts_io.py); the source agrees (add_pair(i, j, F)
#: with F what pair gran adds to f[i]).  Checked again on every import (PairCheck).
PAIR_FORCE_SIGN = 1.0
#: the dumped contacts must touch: |r_i - r_j| <= (r_i + r_j)(1 + this) (10-digit positions;
#: a wrong id mapping puts the partners a diameter or more apart)
PAIR_TOUCH_TOLERANCE = 1.0e-3
#: the smallest sum f_on_i . (r_i - r_j) / sum |f| |r_i - r_j| over an import's contacts
#: accepted as repulsive: a bed's contact forces are mostly normal and pushing (+0.95 to +0.99
#: measured, at rest and vibrated); the opposite convention gives the negative of that, ids
#: mapped to the wrong balls about 0
PAIR_MIN_REPULSION = 0.5


@dataclass
class PairCheck:
    """What the pair rows of an import add up to, for the sign check (`verdict`)."""

    contacts: int = 0
    virial: float = 0.0          # sum f_on_i . (r_i - r_j) (J)
    magnitude: float = 0.0       # sum |f| |r_i - r_j| (J)
    repulsive: int = 0           # contacts with f_on_i . (r_i - r_j) > 0

    def add(self, force: np.ndarray, branch: np.ndarray) -> None:
        w = np.einsum("ij,ij->i", force, branch)
        self.contacts += int(w.size)
        self.virial += float(w.sum())
        self.magnitude += float(np.sum(np.linalg.norm(force, axis=1)
                                       * np.linalg.norm(branch, axis=1)))
        self.repulsive += int(np.count_nonzero(w > 0))

    @property
    def repulsion(self) -> float:
        """sum f . b / sum |f| |b|: +1 all pushing along the line of centres, -1 all pulling."""
        return self.virial / self.magnitude if self.magnitude > 0 else float("nan")

    def verdict(self, path) -> None:
        """Raise InputError unless the contacts push on the whole."""
        if self.contacts and not self.repulsion > PAIR_MIN_REPULSION:
            raise InputError(
                f"{path}: the ball-ball contact forces pull the balls together on the whole "
                f"(sum f.(r_i - r_j) / sum |f||r_i - r_j| = {self.repulsion:.3g} over "
                f"{self.contacts} contacts, a bed gives > {PAIR_MIN_REPULSION}): the force "
                "column is not the force on the first id (another LIGGGHTS version or compute "
                "layout?)")


def _pair_rows(snap, snap_index, ids, pos_lab, radius, period, path, check: PairCheck):
    """vibroflow ball_contacts rows from one snapshot of the pair/gran/local dump.

    Columns (compute pair/gran/local id force): id1, id2, periodic-image flag, F (3, lab axes)
    with F the force on id1 by id2 (PAIR_FORCE_SIGN).  ids are mapped to the indices of the
    sorted snapshot (`ids`), each pair ordered i < j (F negated when swapped: Newton's third
    law), the rows sorted by (i, j) so the result does not depend on LIGGGHTS' rank order.
    The branch r_i - r_j is the minimum image along y when the tub is periodic (period > 0),
    as the calibration takes it; a pair across the periodic boundary (flag 1) is then as close
    as any other, which the touch check verifies.  Rows with an exactly zero force carry no
    stress and are dropped (a LIGGGHTS build whose compute also lists near pairs within a
    contact distance factor may write untouching pairs so; 3.8.0 wrote none in our runs):
    vibroflow stores touching pairs only.
    Raises InputError for another number of columns, ids that are not whole numbers, an id
    not in the snapshot, a pair twice, or partners apart.
    """
    data = snap.data
    if data.shape[1] != PAIR_COLUMNS:
        raise InputError(f"{path}: line {snap.first_row - 1} (step {snap.step}): "
                         f"{data.shape[1]} columns, expected {PAIR_COLUMNS} (compute "
                         "pair/gran/local id force)")
    force = PAIR_FORCE_SIGN * data[:, 3:6]
    keep = np.any(force != 0.0, axis=1)
    id1 = _whole_column(path, snap, 0)[keep]
    id2 = _whole_column(path, snap, 1)[keep]
    force = force[keep]
    a = np.clip(np.searchsorted(ids, id1), 0, ids.size - 1)
    b = np.clip(np.searchsorted(ids, id2), 0, ids.size - 1)
    bad = (ids[a] != id1) | (ids[b] != id2) | (id1 == id2)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(f"{path}: snapshot {snap_index}: contact of ids {id1[k]}, {id2[k]}, "
                         "not two balls of the snapshot")
    swap = a > b
    i = np.where(swap, b, a)
    j = np.where(swap, a, b)
    force = np.where(swap[:, None], -force, force)
    order = np.lexsort((j, i))
    i, j, force = i[order], j[order], force[order]
    if i.size > 1 and np.any((i[1:] == i[:-1]) & (j[1:] == j[:-1])):
        k = int(np.argmax((i[1:] == i[:-1]) & (j[1:] == j[:-1])))
        raise InputError(f"{path}: snapshot {snap_index}: the contact of ids {ids[i[k]]}, "
                         f"{ids[j[k]]} appears twice (would count its force twice)")
    branch = pos_lab[i] - pos_lab[j]
    if period > 0.0:
        branch[:, 1] -= period * np.round(branch[:, 1] / period)
    dist = np.linalg.norm(branch, axis=1)
    apart = dist > (radius[i] + radius[j]) * (1.0 + PAIR_TOUCH_TOLERANCE)
    if np.any(apart):
        k = int(np.argmax(apart))
        raise InputError(f"{path}: snapshot {snap_index}: balls {ids[i[k]]} and {ids[j[k]]} "
                         f"are {dist[k]:.6g} m apart, more than their radii "
                         f"{radius[i[k]] + radius[j[k]]:.6g} m, yet in contact (ids not "
                         "those of the ball dump?)")
    check.add(force, branch)
    return {"snapshot": np.full(i.shape, snap_index, np.int32), "i": i.astype(np.int32),
            "j": j.astype(np.int32), "force_lab": force.astype(np.float32)}


class _StepReader:
    """A local dump read in step with the ball dump: `at(step)` returns the entries of that
    step, or None when the dump has none (skipping the dump's earlier steps)."""

    def __init__(self, path: Path):
        self.path = path
        self._it = read_dump(path)
        self._pending = None

    def at(self, step: int):
        while True:
            if self._pending is None:
                self._pending = next(self._it, None)
            if self._pending is None or self._pending.step > step:
                return None
            found = self._pending
            self._pending = None
            if found.step == step:
                return found


def _whole_column(path, snap: DumpSnapshot, j: int) -> np.ndarray:
    """Column j of a snapshot as int64; InputError unless every value is a whole number
    (an atom id, a mesh or triangle index)."""
    col = snap.data[:, j]
    bad = (col != np.round(col)) | (np.abs(col) >= 2.0**53)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(f"{path}: line {snap.first_row + k}: {snap.columns[j]} = "
                         f"{float(col[k])!r}: must be a whole number")
    return col.astype(np.int64)


def _read_text(path: Path) -> str:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({(exc.strerror or str(exc)).lower()})") \
            from None
    text = raw.decode("ascii", errors="replace")
    if "\ufffd" in text:
        line = text[:text.index("\ufffd")].count("\n") + 1
        raise InputError(f"{path}: line {line}: not text; LIGGGHTS writes this file as ASCII "
                         "(a binary file?)")
    return text


def _read_start_step(post: Path) -> int:
    p = post / START_FILE
    if not p.is_file():
        raise InputError(f"{post}: no {START_FILE} (did the LIGGGHTS run reach the vibration?)")
    words = _read_text(p).split()
    try:
        n0 = float(words[0]) if words else math.nan
    except ValueError:
        n0 = math.nan
    if not (math.isfinite(n0) and n0 >= 0 and n0 == round(n0) and n0 < 2.0**53):
        raise InputError(f"{p}: line 1 = {_short(words[0] if words else '')}: must be the step "
                         "at which the vibration starts, a whole number >= 0")
    return int(n0)


def _read_series(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and kinetic energy (J) of LIGGGHTS' series file: '#' comment lines, then rows
    of at least two finite numbers."""
    t, e = [], []
    for k, line in enumerate(_read_text(path).split("\n"), 1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        try:
            a, b = float(words[0]), float(words[1])
        except (ValueError, IndexError):
            raise InputError(f"{path}: line {k}: {_short(line.strip())}: must be two numbers, "
                             "t_vibration_s kinetic_energy_J") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise InputError(f"{path}: line {k}: {_short(line.strip())}: must be finite numbers "
                             "(nan or inf is no data: did the run blow up?)")
        t.append(a)
        e.append(b)
    if not t:
        raise InputError(f"{path}: no rows of t_vibration_s kinetic_energy_J (did the LIGGGHTS "
                         "run reach the vibration?)")
    return np.asarray(t), np.asarray(e)


#: the ball dump's columns the import reads (the deck's `dump custom`)
BALL_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz", "radius")
BULK_CSV = "bulk_velocity.csv"
#: what an import writes into its out folder, in the order they are moved into place
IMPORT_FILES = ("dem.h5", BULK_CSV, "summary.json")
#: dem.h5 stores positions and velocities as float32: larger magnitudes would be inf there
FLOAT32_MAX = float(np.finfo(np.float32).max)


def import_run(dump_dir, scenario=None, out_dir=None) -> dict:
    """Convert a LIGGGHTS run of an exported deck into vibroflow results.

    dump_dir: the deck's post/ folder (or the deck folder).  scenario: the Scenario run (default:
    scenario.toml next to the dumps).  out_dir: where dem.h5, summary.json and bulk_velocity.csv
    go (default: dump_dir).  Returns the summary dict.

    Bad dumps (see read_dump; also missing columns, ids that are not whole, unique and the same
    in every snapshot, steps that do not increase) raise a one-line InputError.  out_dir is
    written under its folder lock, and only at the end: the three files are made in a temporary
    folder inside it and moved into place once all of them are whole, so a failed import leaves
    out_dir as it was.
    """
    post = _resolve_dump_dir(Path(dump_dir))
    scenario = _scenario_for(post, scenario)
    _check_exportable(scenario)
    out_dir = Path(out_dir) if out_dir is not None else post
    n0 = _read_start_step(post)
    for name in IMPORT_FILES:
        if (out_dir / name).is_dir():
            raise InputError(f"--out = {str(out_dir)!r}: {name} there is a folder; the import "
                             "writes a file of that name")
    made = not out_dir.exists()
    try:
        with folder_lock(out_dir, "vibroflow import liggghts"):
            tmp_dir = Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}liggghts-import-",
                                            dir=out_dir))
            try:
                summary = _import(post, scenario, n0, tmp_dir)
                summary["bulk_velocity_csv"] = os.fspath(out_dir / BULK_CSV)
                write_json_atomic(tmp_dir / "summary.json", _json_safe(summary))
                for name in IMPORT_FILES:  # summary.json last: it says the import is done
                    os.replace(tmp_dir / name, out_dir / name)
            finally:
                shutil.rmtree(tmp_dir, ignore_errors=True)
    except BaseException:
        if made:  # a folder made for a failed import goes again (if still empty)
            with contextlib.suppress(OSError):
                out_dir.rmdir()
        raise
    return summary


def _import(post: Path, scenario, n0: int, tmp_dir: Path) -> dict:
    """The import proper: dem.h5 and bulk_velocity.csv into tmp_dir; returns the summary."""
    from vibroflow.dem.output import ResultWriter

    run = scenario.run
    dt = run.dt
    f = scenario.motion.frequency
    motion = TubMotion.of_scenario(scenario)
    geom = geometry_of(scenario)
    rho = scenario.materials[scenario.fill.material].density

    ball_path = post / BALL_DUMP
    wall_path = post / WALL_DUMP
    walls = _StepReader(wall_path) if wall_path.is_file() else None
    # ball-ball contacts: absent from decks written before they were dumped; then dem.h5 has
    # an empty ball_contacts group, which the calibration reads as "no ball contacts"
    pair_path = post / PAIR_DUMP
    pairs = _StepReader(pair_path) if pair_path.is_file() else None
    pair_check = PairCheck()
    period = float(scenario.tub.length) if scenario.tub.periodic else 0.0

    writer = None
    ids = radius = None
    ke_t, ke_v = [], []
    n_snap = 0
    last = None
    try:
        for snap in read_dump(ball_path):
            step, cols, data = snap.step, snap.columns, snap.data
            c = {name: i for i, name in enumerate(cols)}
            missing = [name for name in BALL_COLUMNS if name not in c]
            if missing:
                raise InputError(f"{ball_path}: line {snap.first_row - 1} (step {step}): no "
                                 f"column {' '.join(missing)} (found: {' '.join(cols)}); the "
                                 f"import needs {' '.join(BALL_COLUMNS)}")
            if last is not None and step <= last:
                raise InputError(f"{ball_path}: line {snap.line + 1}: step {step} after step "
                                 f"{last}: the steps of the snapshots must increase")
            if step < n0:
                raise InputError(f"{ball_path}: line {snap.line + 1}: step {step} is before the "
                                 f"vibration's start, step {n0} ({START_FILE}): the dump and "
                                 "that file are not of one run")
            last = step
            if data.shape[0] == 0:
                raise InputError(f"{ball_path}: line {snap.line + 3}: step {step} holds no "
                                 "balls; every snapshot must hold the bed")
            stored = [c[name] for name in BALL_COLUMNS[1:10]]
            big = np.abs(data[:, stored]) > FLOAT32_MAX
            if np.any(big):
                i, j = np.unravel_index(int(np.argmax(big)), big.shape)
                raise InputError(f"{ball_path}: line {snap.first_row + i}: "
                                 f"{cols[stored[j]]} = {data[i, stored[j]]:.6g}: must be at most "
                                 f"{FLOAT32_MAX:.6g} in magnitude (dem.h5 stores float32; did "
                                 "the run blow up?)")
            these_raw = _whole_column(ball_path, snap, c["id"])
            order = np.argsort(these_raw, kind="stable")
            data = data[order]
            these = these_raw[order]
            dup = these[1:] == these[:-1]
            if np.any(dup) or these[0] < 1:
                what = (f"id {these[int(np.argmax(dup))]} appears twice" if np.any(dup)
                        else f"id {these[0]}")
                raise InputError(f"{ball_path}: step {step} (line {snap.line}): {what}; the ids "
                                 "must be whole numbers >= 1, each once")
            if ids is None:
                ids = these
                radius = data[:, c["radius"]].astype(np.float64)
                if np.any(radius <= 0):
                    k = int(np.argmax(radius <= 0))
                    raise InputError(f"{ball_path}: step {step}: radius of id {ids[k]} = "
                                     f"{radius[k]!r} m: must be > 0")
                n = ids.size
                attrs = {"case": scenario.case, "n_particles": int(n), "dt": float(dt),
                         "frequency": float(f), "scenario_toml": _scenario_toml(scenario),
                         "source": "liggghts"}
                writer = ResultWriter(tmp_dir, n, attrs, radius)
            elif these.size != ids.size or np.any(these != ids):
                gone = np.setdiff1d(ids, these)
                new = np.setdiff1d(these, ids)
                which = ", ".join(([f"id {gone[0]} missing"] if gone.size else [])
                                  + ([f"id {new[0]} new"] if new.size else []))
                what = (f"holds {these.size} balls, not the {ids.size} of the first snapshot"
                        if these.size != ids.size else "holds other ids than the first snapshot")
                raise InputError(f"{ball_path}: step {step} (line {snap.line}) {what} ({which}; "
                                 "balls lost?); every snapshot must hold the same balls")
            t = (step - n0) * dt
            p = pose_np(motion, t)
            pose = np.array([p["X"], p["Z"], p["theta"], p["Xdot"], p["Zdot"], p["thetadot"]],
                            dtype=float)
            pos = data[:, [c["x"], c["y"], c["z"]]]
            if scenario.tub.periodic:  # LIGGGHTS wraps only when it re-neighbours
                pos[:, 1] = np.mod(pos[:, 1], scenario.tub.length)
            vel = data[:, [c["vx"], c["vy"], c["vz"]]]
            omg = data[:, [c["omegax"], c["omegay"], c["omegaz"]]]
            writer.append("snapshots", time=[t], step=[step - n0], phase=[(t * f) % 1.0],
                          tub_pose=pose[None], position=pos[None].astype(np.float32),
                          velocity=vel[None].astype(np.float32),
                          angular_velocity=omg[None].astype(np.float32))
            mass = 4.0 / 3.0 * math.pi * radius**3 * rho
            ke = 0.5 * np.sum(mass * np.sum(vel**2, axis=1)) + 0.5 * np.sum(
                0.4 * mass * radius**2 * np.sum(omg**2, axis=1))
            ke_t.append(t)
            ke_v.append(ke)
            # wall contacts of this step
            wsnap = walls.at(step) if walls is not None else None
            if wsnap is not None:
                rows = _wall_rows(wsnap, n_snap, ids, pos, pose, motion, scenario, geom,
                                  wall_path)
                if rows is not None:
                    writer.append("wall_contacts", **rows)
            # ball-ball contacts of this step: every snapshot must have its entry (a missing
            # one would read as a snapshot without contacts and bias the contact stress)
            if pairs is not None:
                psnap = pairs.at(step)
                if psnap is None:
                    raise InputError(f"{pair_path}: no entry for step {step} of {BALL_DUMP} "
                                     "(truncated dump?)")
                writer.append("ball_contacts", **_pair_rows(psnap, n_snap, ids, pos, radius,
                                                            period, pair_path, pair_check))
            n_snap += 1
        if writer is None:
            raise InputError(f"{ball_path}: no snapshot (no 'ITEM: TIMESTEP'); a LIGGGHTS run "
                             "writes one at every dump step")
        pair_check.verdict(pair_path)
        # time series: LIGGGHTS' own every series_every steps, else from the snapshots
        series = post / SERIES_FILE
        if series.is_file():
            st, sv = _read_series(series)
        else:
            st, sv = np.asarray(ke_t), np.asarray(ke_v)
        nan = np.full(st.shape, np.nan)
        writer.append("series", time=st, kinetic_energy=sv, max_overlap_ball=nan,
                      max_overlap_wall=nan)
        h5 = writer.finish()
        writer = None
    finally:
        if writer is not None:
            writer.close()

    summary = {"case": scenario.case, "source": "liggghts", "n_particles": int(ids.size),
               "dt": float(dt), "snapshots": n_snap}
    steps = int(round(run.duration / dt))
    summary["steps"] = steps
    summary["simulated_time_s"] = steps * dt
    log = _find_log(post)
    if log is not None:
        lt = loop_times(log)
        if lt:
            vib = lt[-1]
            summary["wall_time_s"] = sum(x.seconds for x in lt)
            summary["vibration_wall_time_s"] = vib.seconds
            summary["mpi_ranks"] = vib.procs
            summary["particle_steps_per_s"] = vib.particle_steps_per_s
    summary["balls_lost"] = int(scenario.fill.count - ids.size)
    summary["wall_contacts_available"] = wall_path.is_file()
    summary["ball_contacts_available"] = pairs is not None
    if pairs is not None:
        summary["ball_contacts"] = pair_check.contacts
        summary["ball_contacts_repulsive_fraction"] = (
            pair_check.repulsive / pair_check.contacts if pair_check.contacts else float("nan"))
    summary["impacts_available"] = False
    from vibroflow.measure.summary import tub_summary
    summary.update(tub_summary(h5, scenario, bulk_csv=tmp_dir / BULK_CSV))
    return summary


def _find_log(post: Path) -> Path | None:
    for folder in (post, post.parent):
        for name in ("log.liggghts", "log.lammps", "screen.txt"):
            if (folder / name).is_file():
                return folder / name
    return None


def _json_safe(obj):
    try:
        from vibroflow.measure.summary import json_safe
        return json_safe(obj)
    except ImportError:  # pragma: no cover
        return obj
