"""Scenarios: tub47 defaults against tub47.md, presets, TOML round trip, --set overrides,
cross-field validation and the command line's handling of bad input (one line, exit code 2, no
traceback, nothing written)."""
from __future__ import annotations

import math
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from pydantic import ValidationError

from vibroflow.errors import InputError
from vibroflow.scenario import dump_scenario, load_scenario, scenario_hash
from vibroflow.scenario.io import parse_scenario
from vibroflow.scenario.model import ContactPair, ParticleSpec, Run, Scenario, WallSpec

REPO = Path(__file__).resolve().parents[1]


def _contact(s: Scenario, a: str, b: str) -> ContactPair:
    [c] = [c for c in s.contacts if sorted(c.pair) == sorted((a, b))]
    return c


def _leaves(data, prefix=""):
    """{dotted path: value} of every scalar in nested dicts/lists."""
    if isinstance(data, dict):
        out = {}
        for k, v in data.items():
            out.update(_leaves(v, f"{prefix}{k}."))
        return out
    if isinstance(data, list):
        out = {}
        for i, v in enumerate(data):
            out.update(_leaves(v, f"{prefix}{i}."))
        return out
    return {prefix[:-1]: data}


# ---------------------------------------------------------------------------------------------
# Defaults: the literal numbers of shared/reference/tub47.md

def test_defaults_are_tub47_md():
    s = Scenario()
    assert s.case == "tub47"
    assert s.gravity == (0.0, 0.0, -9.81)
    # contact law table
    bb = _contact(s, "steel", "steel")
    assert bb.model == "linear" and bb.k_n == 1.0e5 and bb.restitution == 0.85
    assert bb.friction == 0.20 and bb.rolling_friction == 0.002
    assert bb.k_t_over_k_n == pytest.approx(2.0 / 7.0, rel=1e-15)
    wall = _contact(s, "steel", s.tub.wall_material)
    assert s.tub.wall_material == "polyurethane"
    assert wall.k_n == 5.0e4 and wall.restitution == 0.6 and wall.friction == 0.40
    part = _contact(s, "steel", s.tub.partition_material)
    assert s.tub.partition_material == "glass"
    assert part.k_n == 1.0e5 and part.restitution == 0.85 and part.friction == 0.15
    # media: 6.35 mm steel, 7800 kg/m^3, mass 1.046 g, N = 14 000
    assert s.fill.count == 14000 and s.fill.diameter == 0.00635 and s.fill.material == "steel"
    assert s.materials["steel"].density == 7800.0
    mass = s.materials["steel"].density * math.pi * s.fill.diameter**3 / 6
    assert mass == pytest.approx(1.046e-3, abs=0.0005e-3)
    # tub
    assert s.tub.radius == 0.15 and s.tub.rim_height == 0.40 and s.tub.length == 0.0635
    assert not s.tub.periodic
    # motion
    m = s.motion
    assert m.frequency == 47.0
    assert (m.amplitude_x, m.phase_x) == (1.0e-3, 0.0)
    assert m.amplitude_z == 1.5e-3 and m.phase_z == pytest.approx(math.pi / 2, rel=1e-15)
    assert (m.amplitude_theta, m.phase_theta) == (4.0e-3, 0.0)
    assert m.pivot == (0.0, -0.10) and m.amplitude_factor == 1.0
    # procedure
    assert s.run.dt == 1.0e-5 and s.run.duration == 3.0 and s.run.average_last == 2.0
    assert s.run.phases_per_cycle >= 8 and s.run.batches >= 4
    assert s.fill.settle_time == 0.5 and s.fill.insert_above == 0.01
    # measurement
    assert s.analysis.cell_size == 0.015 and s.analysis.min_solid_fraction == 0.3
    probes = {k: (p.x, p.z) for k, p in s.analysis.probes.items()}
    assert probes == {"P1": (-0.10, 0.15), "P2": (0.00, 0.15), "P3": (0.10, 0.15),
                      "P4": (0.00, 0.05), "P5": (0.00, 0.18)}
    assert not s.explicit and s.particles is None and s.walls is None


def test_peak_vertical_acceleration_is_about_13_g():
    # tub47.md: "Peak vertical acceleration of the tub about 13 g" (translation alone)
    m = Scenario().motion
    assert m.amplitude_z * (2 * math.pi * m.frequency) ** 2 / 9.81 == pytest.approx(13.3, abs=0.3)


def test_time_step_is_about_1_22_of_ball_ball_contact_time():
    # models.md: t_c = pi / sqrt(k/m_eff - (gamma/(2 m_eff))^2), gamma = 2 zeta sqrt(m_eff k)
    from vibroflow.scenario.checks import contact_times

    s = Scenario()
    m_eff = 7800.0 * math.pi * 0.00635**3 / 6 / 2
    zeta = -math.log(0.85) / math.sqrt(math.pi**2 + math.log(0.85) ** 2)
    gamma = 2 * zeta * math.sqrt(m_eff * 1.0e5)
    t_c = math.pi / math.sqrt(1.0e5 / m_eff - (gamma / (2 * m_eff)) ** 2)
    assert 21.5 < t_c / s.run.dt < 23.5  # tub47.md: "about 1/22"
    (tp, shortest), *_ = contact_times(s)
    assert tp.label == "steel-steel" and shortest == pytest.approx(t_c, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# Presets

def test_preset_tub47_is_the_default():
    assert load_scenario("tub47") == Scenario()


def test_tub47_quick_differs_exactly_as_specified():
    full = _leaves(load_scenario("tub47").model_dump(mode="json"))
    quick = _leaves(load_scenario("tub47-quick").model_dump(mode="json"))
    assert full.keys() == quick.keys()
    diff = {k: quick[k] for k in full if full[k] != quick[k]}
    assert diff == {"case": "tub47-quick", "tub.length": 0.01905, "fill.count": 4200,
                    "run.duration": 1.5, "run.average_last": 1.0}
    assert 0.01905 == pytest.approx(3 * 0.00635)  # L_y = 3 d


def test_preset_files_are_complete():
    # every field of the model is written out in the shipped presets (no hidden defaults)
    from vibroflow.scenario.io import read_preset_text

    for name in ("tub47", "tub47-quick"):
        raw = tomllib.loads(read_preset_text(name))
        written = set(_leaves(raw))
        expected = set(_leaves(Scenario().model_dump(mode="json", exclude_none=True)))
        assert written == expected, name


# ---------------------------------------------------------------------------------------------
# Round trip and hash

def _explicit() -> Scenario:
    return Scenario(
        case="two-balls",
        run=Run(dt=1e-6, duration=0.01, average_last=0.0),
        particles=[ParticleSpec(position=(0, 0, 0.01), velocity=(0, 0, -1.0)),
                   ParticleSpec(position=(0.02, 0, 0.01), diameter=0.004)],
        walls=[WallSpec(normal=(0, 0, 2.0), amplitude=(0, 0, 1e-3), frequency=47.0)],
    )


@pytest.mark.parametrize("make", [
    lambda: load_scenario("tub47"),
    lambda: load_scenario("tub47-quick", ["motion.amplitude_factor=0.75", "run.seed=3"]),
    _explicit,
    lambda: Scenario(contacts=[
        ContactPair(pair=("steel", "steel"), model="hertz", restitution=0.9),
        ContactPair(pair=("polyurethane", "steel"), restitution=0.6, k_n=5e4, friction=0.4),
        ContactPair(pair=("steel", "glass"), friction=0.15)],
        run=Run(dt=1e-6)),
], ids=["tub47", "quick-overridden", "explicit", "hertz"])
def test_dump_load_round_trip(make, tmp_path):
    s = make()
    text = dump_scenario(s)
    assert parse_scenario(tomllib.loads(text)) == s
    path = tmp_path / "s.toml"
    path.write_text(text)
    again = load_scenario(path)
    assert again == s and scenario_hash(again) == scenario_hash(s)


def test_explicit_mode_has_no_tub_and_no_fill(write_toml):
    s = _explicit()
    assert s.explicit and s.tub is None and s.fill is None
    path = write_toml('[[particles]]\nposition = [0.0, 0.0, 0.01]\n')
    s = load_scenario(path)
    assert s.explicit and s.tub is None and s.fill is None and s.case == "scenario"
    bad = write_toml('[[particles]]\nposition = [0.0, 0.0, 0.01]\n[tub]\nlength = 0.02\n')
    with pytest.raises(InputError, match=r"^tub: not allowed with particles"):
        load_scenario(bad)
    with pytest.raises(ValidationError, match="fill: not allowed"):
        Scenario(particles=[ParticleSpec(position=(0, 0, 0))], fill={"count": 3})


def test_hash():
    a = load_scenario("tub47-quick")
    assert re.fullmatch(r"[0-9a-f]{64}", scenario_hash(a))
    assert scenario_hash(a) == scenario_hash(load_scenario("tub47-quick"))
    b = load_scenario("tub47-quick", ["run.duration=1.2"])
    assert scenario_hash(a) != scenario_hash(b)
    fill_fields = ["fill", "tub", "materials", "contacts", "gravity", "run.seed", "run.dt"]
    assert scenario_hash(a, fill_fields) == scenario_hash(b, fill_fields)
    c = load_scenario("tub47-quick", ["run.seed=2"])
    assert scenario_hash(a, fill_fields) != scenario_hash(c, fill_fields)
    with pytest.raises(KeyError):
        scenario_hash(a, ["run.nonexistent"])


# ---------------------------------------------------------------------------------------------
# --set overrides

@pytest.mark.parametrize("key, text, expected", [
    ("run.dt", "5e-6", 5e-6),
    ("run.duration", "2.5", 2.5),
    ("run.average_last", "0.5", 0.5),
    ("run.seed", "7", 7),
    ("fill.count", "500", 500),
    ("fill.settle_time", "0.2", 0.2),
    ("tub.length", "0.02", 0.02),
    ("motion.frequency", "50", 50.0),
    ("motion.amplitude_factor", "1.5", 1.5),
    ("contacts.0.friction", "0.3", 0.3),
    ("gravity", "[0, 0, -9.81]", (0.0, 0.0, -9.81)),
    ("gravity", "[0,0,-1.62]", (0.0, 0.0, -1.62)),
    ("case", "my-run", "my-run"),
    ("case", '"quoted_run"', "quoted_run"),
    ("materials.steel.density", "8000", 8000.0),
])
def test_set_changes_exactly_one_field(key, text, expected):
    base = load_scenario("tub47-quick")
    s = load_scenario("tub47-quick", [f"{key}={text}"])
    node = s
    for part in key.split("."):
        if isinstance(node, dict):
            node = node[part]
        else:
            node = node[int(part)] if part.isdigit() else getattr(node, part)
    assert node == expected and type(node) is type(expected)
    before = _leaves(base.model_dump(mode="json"))
    after = _leaves(s.model_dump(mode="json"))
    changed = {k for k in before if before[k] != after[k]}
    assert changed <= {key} | {f"{key}.{i}" for i in range(3)}


def test_set_on_a_user_file_takes_missing_tables_from_the_defaults(write_toml):
    path = write_toml('case = "mine"\n[run]\nduration = 0.4\naverage_last = 0.2\n')
    s = load_scenario(path, ["materials.steel.density=8000", "contacts.1.friction=0.5"])
    assert s.case == "mine" and s.run.duration == 0.4 and s.run.dt == 1e-5
    assert s.materials["steel"].density == 8000.0 and "glass" in s.materials
    assert s.contacts[1].friction == 0.5 and s.contacts[1].k_n == 5e4


def test_apply_overrides_to_a_scenario():
    from vibroflow.scenario import apply_overrides

    base = load_scenario("tub47-quick")
    s = apply_overrides(base, ["motion.amplitude_factor=1.25", "run.seed=4"])
    assert isinstance(s, Scenario) and s.motion.amplitude_factor == 1.25 and s.run.seed == 4
    assert s.model_copy(update={"motion": base.motion, "run": base.run}) == base
    with pytest.raises(InputError, match=r"^run\.dt = 0\.001: must be at most"):
        apply_overrides(base, ["run.dt=1e-3"])


@pytest.mark.parametrize("override, message", [
    ("run.bogus=1", r"^run\.bogus: unknown key \(allowed: dt, duration, "),
    ("contacts.7.friction=0.3", r"^contacts\.7: no such entry"),
    ("noequals", r"^--set noequals: expected KEY=VALUE"),
    ("run.dt.x=1", r"^run\.dt\.x: run\.dt = 1e-05 is a value"),
    ("fill.count=many", r'^fill\.count = "many": must be an integer'),
])
def test_bad_set(override, message):
    with pytest.raises(InputError, match=message):
        load_scenario("tub47-quick", [override])


# ---------------------------------------------------------------------------------------------
# Cross-field validation in the model (so a Scenario built in code is checked too)

def test_model_checks_cross_fields():
    with pytest.raises(ValidationError, match=r"run\.dt = 0\.0001: must be at most 2\.27e-05 s"):
        Scenario(run=Run(dt=1e-4))
    with pytest.raises(ValidationError, match=r"run\.average_last = 3\.5: must be at most"):
        Scenario(run=Run(average_last=3.5))
    with pytest.raises(ValidationError, match=r'fill\.material = "tin": no such material'):
        Scenario(fill={"material": "tin"})
    dup = [*Scenario().contacts, ContactPair(pair=("glass", "steel"))]
    with pytest.raises(ValidationError, match=r"contacts\.3\.pair .*duplicate of contacts\.2"):
        Scenario(contacts=dup)
    with pytest.raises(ValidationError, match=r'contacts\.0\.pair .*no such material "tin"'):
        Scenario(contacts=[ContactPair(pair=("tin", "steel")), *Scenario().contacts])
    # the order of a pair does not matter
    flipped = [ContactPair(pair=tuple(reversed(c.pair)), k_n=c.k_n, restitution=c.restitution,
                           friction=c.friction) for c in Scenario().contacts]
    assert Scenario(contacts=flipped).contacts[1].pair == ("polyurethane", "steel")
    # a periodic tub has no partitions, so needs no ball-glass law
    Scenario(tub={"periodic": True}, contacts=Scenario().contacts[:2])
    with pytest.raises(ValidationError, match=r'tub\.partition_material = "glass": no contact law'):
        Scenario(contacts=Scenario().contacts[:2])


def test_mixed_sizes_use_the_smallest_balls():
    # m_eff and r_eff of the smallest pair: a 2 mm steel ball has t_c (linear) = (2/6.35)^1.5
    # of the 6.35 mm one's, so dt = 1e-5 fails only once it is present
    from vibroflow.scenario.checks import contact_times

    big = ParticleSpec(position=(0, 0, 0.01))
    big2 = ParticleSpec(position=(0, 0, 0.02))
    s = Scenario(particles=[big, big2], run=Run(duration=0.1, average_last=0.0))
    t_big = contact_times(s)[0][1]
    small = ParticleSpec(position=(0.02, 0, 0.01), diameter=0.002)
    s2 = Scenario(particles=[big, small], run=Run(dt=1e-6, duration=0.1, average_last=0.0))
    (tp, t_small), *_ = contact_times(s2)
    m_big = 7800 * math.pi * 0.00635**3 / 6
    m_small = 7800 * math.pi * 0.002**3 / 6
    ratio = math.sqrt((m_big * m_small / (m_big + m_small)) / (m_big / 2))
    assert t_small / t_big == pytest.approx(ratio, rel=1e-12)
    with pytest.raises(ValidationError, match=r"run\.dt = 1e-05: must be at most"):
        Scenario(particles=[big, small], run=Run(duration=0.1, average_last=0.0))


# ---------------------------------------------------------------------------------------------
# The command line

def test_cli_scenario_show_and_check(run_cli, tmp_path):
    r = run_cli("scenario", "show", "tub47-quick", "--set", "run.seed=9", "-s", "fill.count=300")
    assert r.returncode == 0, r.stderr
    s = parse_scenario(tomllib.loads(r.stdout))
    assert s == load_scenario("tub47-quick", ["run.seed=9", "fill.count=300"])
    path = tmp_path / "shown.toml"
    path.write_text(r.stdout)
    r = run_cli("scenario", "check", path, "--set", "tub.length=0.02")
    assert r.returncode == 0, r.stderr
    assert len(r.stdout.strip().splitlines()) == 1 and "ok" in r.stdout


_NEG_DIAMETER = """
[[particles]]
position = [0.0, 0.0, 0.01]
diameter = -0.001
"""
_RESTITUTION_0 = """
[[contacts]]
pair = ["steel", "steel"]
restitution = 0
[[contacts]]
pair = ["steel", "polyurethane"]
[[contacts]]
pair = ["steel", "glass"]
"""
_NO_CONTACT = """
[materials.rubber]
density = 1100.0
youngs_modulus = 1.0e7
poisson_ratio = 0.49
[materials.steel]
[materials.polyurethane]
[materials.glass]
[fill]
material = "rubber"
"""
_UNKNOWN_KEY = """
[run]
duration = 1.0
bogus = 3
"""
_MALFORMED = """
[run
duration = 1.0
"""


@pytest.mark.parametrize("toml, overrides, expected", [
    (_NEG_DIAMETER, [], ["particles.0.diameter = -0.001", "must be > 0"]),
    (None, ["contacts.0.restitution=1.2"], ["contacts.0.restitution = 1.2", "(0, 1]"]),
    (_RESTITUTION_0, [], ["contacts.0.restitution = 0", "(0, 1]"]),
    (None, ["run.dt=1e-4"], ["run.dt = 0.0001", "2.27e-05", "steel-steel"]),
    (_NO_CONTACT, [], ['fill.material = "rubber"', "rubber-rubber"]),
    (_UNKNOWN_KEY, [], ["run.bogus", "unknown key", "duration"]),
    (None, ["fill.bogus=1"], ["fill.bogus", "unknown key"]),
    (_MALFORMED, [], ["scenario.toml", "malformed TOML", "line 2"]),
    ("missing", [], ["no-such-file.toml", "no such scenario file or preset",
                     "tub47, tub47-quick"]),
], ids=["negative-diameter", "restitution-1.2", "restitution-0", "dt-too-large",
        "no-contact-pair", "unknown-key", "unknown-key-set", "malformed", "missing-file"])
def test_cli_bad_input(run_cli, tmp_path, toml, overrides, expected):
    if toml is None:
        source = "tub47-quick"
    elif toml == "missing":
        source = str(tmp_path / "no-such-file.toml")
    else:
        source = tmp_path / "scenario.toml"
        source.write_text(toml)
    out = tmp_path / "out"
    args = [a for o in overrides for a in ("--set", o)]
    for command in (["dem", source, "--out", out], ["scenario", "check", source]):
        r = run_cli(*command, *args)
        assert r.returncode == 2, (r.stdout, r.stderr)
        lines = r.stderr.splitlines()
        assert len(lines) == 1, r.stderr
        for text in expected:
            assert text in lines[0]
        assert "Traceback" not in r.stderr + r.stdout
        assert not out.exists()  # nothing written on bad input


def test_package_import_is_light():
    code = ("import sys, vibroflow, vibroflow.cli; "
            "assert 'numba' not in sys.modules, 'numba'; "
            "assert 'vibroflow.scenario.model' not in sys.modules; "
            "assert {'load', 'load_scenario', 'Scenario'} <= set(dir(vibroflow)); "
            "assert 'numba' not in sys.modules, 'numba after dir'; "
            "assert vibroflow.Scenario().case == 'tub47'; "
            "assert vibroflow.load_scenario('tub47-quick').fill.count == 4200; "
            "print(vibroflow.__version__)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert re.fullmatch(r"\d+\.\d+\.\d+\S*", r.stdout.strip())


# ---------------------------------------------------------------------------------------------
# The documents' examples are valid and the README's test command is what CI runs

def test_documented_scenario_examples_are_valid(tmp_path):
    """Every TOML example of the README and the user guide loads as a valid scenario."""
    text = "".join((REPO / name).read_text() for name in ("README.md", "docs/user-guide.md"))
    blocks = re.findall(r"```toml\n(.*?)```", text, re.S)
    assert len(blocks) >= 2
    for i, block in enumerate(blocks):
        path = tmp_path / f"example{i}.toml"
        path.write_text(block)
        load_scenario(path)
    assert any(load_scenario(tmp_path / f"example{i}.toml").explicit for i in range(len(blocks)))


def test_ci_runs_the_readme_test_command():
    readme = (REPO / "README.md").read_text()
    command = ("python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && "
               ".venv/bin/python -m pytest -q -n auto")
    assert command in readme
    assert command in (REPO / ".ci" / "run").read_text().splitlines()
