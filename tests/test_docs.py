"""The documents against the code: the user guide's scenario reference is the one the model
generates (so it cannot drift), and the README opens with the two commands, exactly as CI runs
the second, in under 200 lines."""
from __future__ import annotations

import re
from pathlib import Path

from vibroflow.scenario.reference import scenario_reference_markdown

REPO = Path(__file__).resolve().parents[1]
START = "<!-- scenario-reference:start -->"
END = "<!-- scenario-reference:end -->"

MAIN_JOB = ("python3 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/vibroflow run "
            "--out runs/tub47-quick")
TESTS = ("python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && .venv/bin/python -m "
         "pytest -q -n auto")


def test_the_user_guide_holds_the_scenario_reference_the_model_generates():
    text = (REPO / "docs" / "user-guide.md").read_text(encoding="utf-8")
    assert text.count(START) == 1 and text.count(END) == 1, "one pair of reference markers"
    held = text.split(START, 1)[1].split(END, 1)[0]
    generated = scenario_reference_markdown()
    assert held.strip() == generated.strip(), (
        "docs/user-guide.md's scenario reference differs from the model's; paste the output of "
        "`python -c 'from vibroflow.scenario.reference import scenario_reference_markdown as f; "
        "print(f())'` between the markers")


def test_the_scenario_reference_covers_every_field():
    from vibroflow.scenario.reference import TABLES

    text = scenario_reference_markdown()
    for _, record, _ in TABLES:
        for name in record.model_fields:
            assert f"| `{name}` |" in text, f"{record.__name__}.{name} missing"


def test_the_readme_is_short_and_opens_with_the_two_commands():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 200
    blocks = re.findall(r"^```sh\n(.*?)^```", text, flags=re.DOTALL | re.MULTILINE)
    assert len(blocks) >= 2
    assert blocks[0].strip() == MAIN_JOB
    assert blocks[1].strip() == TESTS
