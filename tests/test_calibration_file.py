"""calibration.toml as the typed record vibroflow.io.calibration_file.Calibration: a file read
and written again is the same file byte for byte, every key kept; a file that lacks a parameter
the continuum needs, or holds one of the wrong kind, is one line naming the file, the field, the
value and what is allowed."""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import pytest
from pydantic import ValidationError

from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration, read_calibration, write_calibration

DATA = Path(__file__).parent / "data"
FILES = [DATA / "tub47-quick-dem" / "calibration.toml", DATA / "tub47-dem" / "calibration.toml"]

MINIMAL = ("[rheology]\nmu_s = 0.3\nmu_2 = 0.55\nI_0 = 0.3\nphi_max = 0.61\nphi_min = 0.5\n"
           "[elastic]\nbulk_modulus_Pa = 2e6\nshear_modulus_Pa = 1e6\n"
           "[wall]\nfriction = 0.2\n"
           "[media]\ndiameter_m = 0.00635\nsolid_density_kg_m3 = 7800.0\n")


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.parent.name)
def test_a_calibration_read_and_written_again_is_the_same_file(path, tmp_path):
    cal = read_calibration(path)
    out = write_calibration(tmp_path / "calibration.toml", cal)
    assert out.read_bytes() == path.read_bytes()
    # a run folder holding one reads the same (NaN != NaN, so compared as JSON text)
    assert (json.dumps(read_calibration(tmp_path).to_toml_dict())
            == json.dumps(cal.to_toml_dict()))


def test_the_record_gives_the_files_values_by_attribute():
    cal = read_calibration(FILES[0])
    assert cal.rheology.mu_s == 0.27477660849384
    assert cal.rheology.mu_s_stderr == 0.006203069833516833
    assert math.isnan(cal.elastic.bulk_modulus_stderr_Pa)
    assert cal.wall.friction == 0.1857858537488243
    assert cal.partitions.friction == 0.1411598253760551
    assert cal.impacts.ball_ball.c1 == 2.714392988466361
    assert cal.impacts.bagnold_sqrtT_over_d_gamma_dot == 3.622660458786205
    assert cal.source.coarse_graining.kernel == "gaussian"
    assert cal.cyclic_shear.strain_amplitude[3] == cal.cyclic_shear.tub_strain_amplitude
    assert cal.dilatancy is None and cal.compaction is None
    # keys a table does not declare are kept, with their values
    assert cal.drucker_prager.dilatancy_K1 == 4.09
    assert cal.to_toml_dict()["impacts"]["ball_wall"]["a_maxwellian"] == 1.2533141373155001


def test_unknown_tables_and_keys_are_kept(tmp_path):
    text = MINIMAL + "[wall.extra]\nnote = \"kept\"\n[mystery]\nx = [1, 2]\n"
    (tmp_path / "calibration.toml").write_text(text)
    cal = read_calibration(tmp_path / "calibration.toml")
    assert cal.to_toml_dict()["mystery"] == {"x": [1, 2]}
    assert cal.wall.extra == {"note": "kept"}
    assert write_calibration(tmp_path / "again.toml", cal).read_text().endswith(
        "[mystery]\nx = [\n    1,\n    2,\n]\n")


def test_the_fingerprint_content_is_the_files_tables():
    """What the continuum's run fingerprint hashes (continuum.checkpoint.run_fingerprint) is the
    file's own tables."""
    for path in FILES:
        tables = tomllib.loads(path.read_text())
        cal = read_calibration(path)
        assert (json.dumps(cal.to_toml_dict(), sort_keys=True)
                == json.dumps(tables, sort_keys=True))


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("mu_s = 0.3\n", ""),
     "rheology.mu_s is missing: must be a finite number"),
    (lambda t: t.replace("mu_s = 0.3", "mu_s = nan\nstatus = \"fit failed\""),
     "rheology.mu_s = nan: must be a finite number (fit failed)"),
    (lambda t: t.replace("friction = 0.2", "friction = \"high\""),
     "wall.friction = 'high': must be a finite number"),
    (lambda t: t.replace("bulk_modulus_Pa = 2e6", "bulk_modulus_Pa = inf"),
     "elastic.bulk_modulus_Pa = inf: must be a finite number"),
    (lambda t: t.replace("solid_density_kg_m3 = 7800.0", "solid_density_kg_m3 = true"),
     "media.solid_density_kg_m3 = True: must be a finite number"),
    (lambda t: t.replace("[wall]\nfriction = 0.2\n", ""),
     "wall is missing: must be a table"),
    (lambda t: t + "[impacts.ball_ball]\nc1 = \"x\"\n",
     "impacts.ball_ball.c1 = 'x': must be a number (nan where it could not be estimated)"),
    (lambda t: t + "[partitions]\nspacing_m = 0.019\n",
     "partitions.friction is missing: must be a finite number"),
])
def test_a_bad_calibration_is_one_line_naming_file_field_value(tmp_path, edit, message):
    path = tmp_path / "calibration.toml"
    path.write_text(edit(MINIMAL))
    with pytest.raises(InputError) as e:
        read_calibration(path)
    assert e.value.message == f"{path}: {message}"


def test_a_missing_or_malformed_file_is_one_line(tmp_path):
    with pytest.raises(InputError, match=r"^calibration = '.*nothere': no such file"):
        read_calibration(tmp_path / "nothere")
    with pytest.raises(InputError, match=r"^calibration = '.*': a folder with no "
                                         r"calibration.toml \(give the file"):
        read_calibration(tmp_path)
    (tmp_path / "calibration.toml").write_text("[rheology\n")
    with pytest.raises(InputError, match=r"calibration.toml: malformed TOML"):
        read_calibration(tmp_path)


def test_the_record_is_frozen():
    cal = Calibration.from_dict({"rheology": {"mu_s": 0.3, "mu_2": 0.5, "I_0": 0.3,
                                              "phi_max": 0.6, "phi_min": 0.5},
                                 "elastic": {"bulk_modulus_Pa": 1e6, "shear_modulus_Pa": 1e5},
                                 "wall": {"friction": 0.2},
                                 "media": {"diameter_m": 0.006, "solid_density_kg_m3": 7800.0}})
    with pytest.raises(ValidationError, match="frozen"):
        cal.wall.friction = 0.5  # type: ignore[misc]
    assert cal.wall.friction == 0.2
