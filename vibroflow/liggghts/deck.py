"""A LIGGGHTS 3.8 deck for a tub scenario: DIR/in.tub, tub_u.stl, partitions.stl, scenario.toml,
README.txt and post/ (where LIGGGHTS writes; the names: vibroflow.liggghts.deck_files).

What the deck does, and why (details and the deviations from vibroflow's own DEM in
docs/liggghts.md):

* Contact law.  vibroflow's linear spring-dashpot is LIGGGHTS' `hooke/stiffness` with
  `absolute_damping on` (so the damping coefficients are in N s/m, not per unit mass) and
  `tangential_damping off`, per type pair: kn = k_n, kt = k_t_over_k_n k_n,
  gamman_abs = 2 zeta sqrt(m_eff k_n) with zeta = -ln e / sqrt(pi^2 + ln^2 e) and m_eff = m/2
  for ball-ball, m for ball-wall (models.md), gammat_abs = 0; Coulomb friction and the CDT rolling
  resistance from the pair's mu and mu_r.  A scenario whose contacts are all Hertz gets LIGGGHTS'
  `hertz` (moduli from the materials, restitution through LIGGGHTS' own damping formula).
* Atom types: 1 = the balls' material, 2 = the tub wall's, 3 = the partitions', 4 and up one
  per part of [[parts]] (its mesh, wall fix, motion and per-step dump:
  vibroflow.liggghts.part_deck).
* Walls: the U and the partitions as STL meshes (vibroflow.liggghts.stl; the U's facets joined
  into one smooth surface by `curvature`, so contact histories cross their creases), moved rigidly
  with the tub by two superposed `fix move/mesh` per mesh, whose velocities are the exact
  derivatives of the tub's motion at mid-step (vibroflow.liggghts.motion_deck; measured: the
  pose to 1e-8 m).
* Fill: `fix insert/rate/region` (random, no overlaps) in the U above insert_above, in events
  0.05 s apart, repeated until all N balls are in; then settling with the tub at rest for
  fill.settle_time and, like vibroflow, on in 0.01 s chunks until the kinetic energy per ball
  is below fill.settle_kinetic_energy or fill.max_settle_time has passed.  Seeds are primes
  derived from run.seed (`seed_primes`).  Or, with fill_from, the DEM's settled bed read from
  fill.data, briefly settled (vibroflow.liggghts.dem_fill; the fill's lines: fill_deck).
* Vibration for run.duration from step n0 (written to post/vibration_start_step.txt), snapshots
  (`dump custom`, post/balls.dump), ball-wall contacts (`compute wall/gran/local`,
  post/wall.dump) and ball-ball contacts (`compute pair/gran/local id force`, post/pairs.dump)
  at exactly the vibration steps vibroflow samples (vibroflow.dem.sampling.sample_steps:
  phases_per_cycle instants a cycle over the whole cycles of the last average_last seconds,
  each rounded to the nearest step) through `dump_modify every v_...` with a file-style
  variable; the kinetic energy every run.series_every steps (post/series.txt).

Bad input writes nothing.  The deck is a program (a newline starts a command, and `shell` runs
anything), so it is built from template lines with slots, every user-derived value one token of
a safe set (names through `safe_name`, numbers finite), and each written line is checked against
its template (vibroflow.liggghts.template).  The export writes under the folder's lock
(vibroflow.io.folder_lock) and puts its files in place only once everything is checked.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroflow.errors import InputError
from vibroflow.io.atomic import write_text_atomic
from vibroflow.io.folder_lock import check_writable_dir, folder_lock
from vibroflow.io.run_folder import folder_owner
from vibroflow.liggghts.dem_fill import (DATA_NAME, FROM_FILL_MAX_SAGITTA,
                                         FROM_FILL_MAX_SETTLE_TIME, FROM_FILL_SETTLE_TIME,
                                         DemFill, data_file_text)
from vibroflow.liggghts.deck_files import (BALL_DUMP, DECK_NAME, FILL_FILE, PAIR_DUMP,
                                           PARTITION_MESH_FILE, POST_DIR, SERIES_FILE,
                                           SETTLE_FILE, START_FILE, U_MESH_FILE, WALL_DUMP,
                                           readme)
from vibroflow.liggghts.fill_deck import add_fill_from_data, add_insertion
from vibroflow.liggghts.motion_deck import add_tub_motion
from vibroflow.liggghts.part_deck import (add_part_dump, add_part_meshes, check_part_names,
                                          moving_meshes, part_file, part_mesh_ids,
                                          write_part_meshes)
from vibroflow.liggghts.parameters import (PairTables, _check_exportable, _contact_law_deck,
                                           dump_vibration_steps, model_arguments, pair_tables,
                                           seed_primes, type_materials)
from vibroflow.liggghts.stl import DEFAULT_MAX_SAGITTA, arc_segments, sagitta, write_tub_meshes
from vibroflow.liggghts.template import _PROCESSORS, _SLOT, _Deck, _fmt, _short, _whole, safe_name
from vibroflow.scenario.io import dump_scenario
from vibroflow.tub.geometry import geometry_of
from vibroflow.tub.motion import TubMotion
from vibroflow.tub.parts import parts_of

#: seconds between insertion events of the fill
FILL_EVENT_INTERVAL = 0.05
#: fraction of the insertion region's volume one event tries to fill
FILL_EVENT_FRACTION = 0.15
#: settling chunk after settle_time (s), as vibroflow.dem.fill.settle
SETTLE_CHUNK = 0.01


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


def _scenario_toml(scenario) -> str:
    return dump_scenario(scenario)


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


def export_deck(scenario, out_dir, *, wall_contacts: bool = True, pair_contacts: bool = True,
                max_sagitta: float | None = None, thermo_every: int | None = None,
                processors: str = "* 1 1", mesh_curvature_deg: float | None = None,
                fill_from: DemFill | None = None) -> DeckInfo:
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
    max_sagitta: largest chord-to-circle deviation of the U's and the parts' facets (m);
    default DEFAULT_MAX_SAGITTA (0.05 mm), with fill_from FROM_FILL_MAX_SAGITTA (1 um).
    fill_from: a DEM run's settled bed (vibroflow.liggghts.dem_fill.dem_fill): the deck reads
    it from DIR/fill.data instead of inserting balls, and settles it only briefly.
    Returns a DeckInfo.

    Every file is made and checked in memory first (names through `safe_name`, the deck and
    README line by line against their templates, `_Deck`), so bad input writes nothing; then
    they are written atomically under out_dir's folder lock.
    """
    _check_exportable(scenario)
    if max_sagitta is None:
        max_sagitta = DEFAULT_MAX_SAGITTA if fill_from is None else FROM_FILL_MAX_SAGITTA
    _check_names(scenario)
    check_part_names(scenario)
    parts = parts_of(scenario)
    if not isinstance(processors, str) or _PROCESSORS.fullmatch(processors) is None:
        raise InputError(f"processors = {_short(processors)}: must be three counts, each a "
                         "whole number >= 1 or *, such as '* 1 1'")
    out_dir = Path(out_dir)
    run, fill, tub = scenario.run, scenario.fill, scenario.tub
    count = _whole("fill.count", fill.count, 1)
    if fill_from is not None and fill_from.n != count:
        raise InputError(f"--fill-from = {str(fill_from.source)!r}: {fill_from.n} balls, the "
                         f"scenario's fill.count is {count}")
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

    settle_time, max_settle_time = ((FROM_FILL_SETTLE_TIME, FROM_FILL_MAX_SETTLE_TIME) if fill_from
                                    else (fill.settle_time, fill.max_settle_time))
    settle_steps = int(round(settle_time / dt))
    chunk_steps = max(1, int(round(SETTLE_CHUNK / dt)))
    extra_settle = max(0.0, max_settle_time - settle_time)
    max_chunks = int(math.ceil(extra_settle / (chunk_steps * dt) - 1e-9))

    vib_steps = int(round(run.duration / dt))
    dsteps = dump_vibration_steps(scenario)
    dsteps = dsteps[(dsteps >= 0) & (dsteps <= vib_steps)]
    thermo_every = _whole("thermo_every", thermo_every, 1) if thermo_every else \
        max(1, int(round(0.01 / dt)))

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
    add(DECK_MARK + " for case '{}'", scenario.case)
    add("# Run in this folder:  mpirun -np 2 liggghts -in in.tub   (see README.txt)")
    add("# SI units.  Atom types: 1 = balls ({}), 2 = tub wall ({}), 3 = partitions ({}).",
        *mats[:3])
    for k, part in enumerate(parts):
        add("# Atom type {}: part {} ({})", k + 4, part.name, mats[k + 3])
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
    if fill_from is None:
        add("create_box      {} domain", len(mats))
    else:
        add(f"read_data       {DATA_NAME}")
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
    add_part_meshes(deck, parts)
    meshes = ["tub"] + ([] if periodic else ["parts"]) + part_mesh_ids(parts)
    add(f"fix walls all wall/gran {model_args} mesh n_meshes {len(meshes)} meshes "
        + " ".join(meshes) + " " + model_kw)
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
    if fill_from is not None:
        add_fill_from_data(deck, count, POST_DIR, FILL_FILE)
    else:
        add_insertion(deck, scenario, parts, count, per_event, event_steps, seeds, rate,
                      max_passes, margin, (iy_lo, iy_hi, ins_z_lo, ins_z_hi), max_sagitta,
                      POST_DIR, FILL_FILE)
    add()
    add("# ---- settle with the tub at rest: {} s, then on in {} s chunks until the kinetic "
        "energy per ball < {} J (at most {} s)", _fmt(settle_time),
        _fmt(chunk_steps * dt), _fmt(fill.settle_kinetic_energy), _fmt(max_settle_time))
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
    add_tub_motion(deck, motion, dt, (['tub'] if periodic else ['tub', 'parts'])
                   + moving_meshes(parts))
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
    if parts:
        add_part_dump(deck, parts, L, max_sagitta, d + skin + reach + swing,
                      int(round((run.duration - run.average_last) / dt)))
    add("variable tvib equal (step-${n0})*{}", _fmt(dt))
    add(f'fix series all print {S} "${{tvib}} ${{ekin}}" file {POST_DIR}/{SERIES_FILE} '
        'screen no title "# t_vibration_s kinetic_energy_J"', ke_every)
    add("run {}", vib_steps)
    add('print "vibroflow: vibration of {} steps done"', vib_steps)

    # everything is made and checked before anything is written
    deck_text = deck.render(DECK_NAME)
    data_text = None if fill_from is None else data_file_text(
        fill_from, (x_lo, x_hi, y_lo, y_hi, z_lo, z_hi), len(mats), L if periodic else None)
    readme_text = readme(scenario, vib_steps, dsteps.size, wall_contacts, pair_contacts,
                          fill_from is not None).render("README.txt")
    toml_text = _scenario_toml(scenario)

    written = [U_MESH_FILE, *([] if periodic else [PARTITION_MESH_FILE]),
               *([] if data_text is None else [DATA_NAME]),
               *(part_file(p.name) for p in parts)]
    with folder_lock(out_dir, "vibroflow export liggghts", field="DIR"):
        earlier = _claim_deck_folder(out_dir, [U_MESH_FILE, PARTITION_MESH_FILE, DECK_NAME,
                                               DATA_NAME, "scenario.toml", "README.txt",
                                               *(part_file(p.name) for p in parts)])
        if earlier:
            _remove_earlier_inputs(out_dir, written)
        check_writable_dir(out_dir / POST_DIR, field="DIR")
        meshes = write_tub_meshes(geom, out_dir, max_sagitta)
        names = {k: p.name for k, p in meshes.items()}
        if names != {"u": U_MESH_FILE, **({} if periodic else
                                          {"partitions": PARTITION_MESH_FILE})}:
            raise RuntimeError(f"vibroflow.liggghts.stl wrote {names}, the deck names "
                               f"{U_MESH_FILE}, {PARTITION_MESH_FILE}")
        write_part_meshes(out_dir, parts, L, max_sagitta)
        if data_text is not None:
            write_text_atomic(out_dir / DATA_NAME, data_text)
        write_text_atomic(out_dir / POST_DIR / "dump_steps.txt", step_lines)
        deck_path = write_text_atomic(out_dir / DECK_NAME, deck_text)
        write_text_atomic(out_dir / "scenario.toml", toml_text)
        write_text_atomic(out_dir / "README.txt", readme_text)
    return DeckInfo(out_dir, deck_path, count, dt, vib_steps, dsteps, n_arc,
                    sagitta(R, n_arc), seeds, per_event, event_steps, settle_steps, tables)


#: the first line of every deck export_deck writes: an earlier export's folder is the next's
DECK_MARK = "# LIGGGHTS 3.8 deck written by vibroflow.liggghts"


def _claim_deck_folder(out_dir: Path, names) -> bool:
    """InputError (one line) unless the deck's files may be written into out_dir: it holds no
    run's results (a study, a sweep, a summary.json: an import's included, whose results belong
    to the deck there) and none of `names`, or they are an earlier export's (its in.tub
    starts with DECK_MARK).  Returns whether out_dir holds an earlier export."""
    owner = folder_owner(out_dir) if out_dir.is_dir() else None
    if owner is not None:
        raise InputError(f"DIR = {str(out_dir)!r}: holds the results of {owner}; a deck goes "
                         "into a folder of its own: give another DIR")
    present = sorted(n for n in names if (out_dir / n).exists())
    deck = out_dir / DECK_NAME
    ours = deck.is_file() and deck.read_text(errors="replace").startswith(DECK_MARK)
    if present and not ours:
        raise InputError(f"DIR = {str(out_dir)!r}: holds {', '.join(present)}, which no "
                         "`vibroflow export liggghts` wrote there and the deck would replace; "
                         "give another DIR")
    return ours


def _remove_earlier_inputs(out_dir: Path, written) -> None:
    """Remove the input files of an earlier export in out_dir that this deck does not write
    (`written`: a part's STL, the partitions' mesh, the settled bed's data file), so that the
    folder holds one deck's inputs only."""
    earlier = [U_MESH_FILE, PARTITION_MESH_FILE, DATA_NAME,
               *(p.name for p in out_dir.glob(part_file("*")))]
    for name in sorted(set(earlier) - set(written)):
        (out_dir / name).unlink(missing_ok=True)


def _shrunk_u_area(R: float, margin: float, z_lo: float, z_hi: float) -> float:
    """Area (m^2) of the U shrunk by `margin` (circle of radius R - margin centred at (0, R),
    walls at x = +-(R - margin)) between heights z_lo and z_hi."""
    rr = R - margin
    zs = np.linspace(z_lo, z_hi, 4001)
    half = np.where(zs >= R, rr, np.sqrt(np.clip(rr**2 - (zs - R) ** 2, 0.0, None)))
    return float(np.trapezoid(2.0 * half, zs) if hasattr(np, "trapezoid")
                 else np.trapz(2.0 * half, zs))
