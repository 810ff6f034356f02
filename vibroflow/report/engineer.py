"""What the report's engineer's sections show, as the template takes it: the E limit and the
verdict in words beside every E (verdict.py), the velocity difference maps (flow_maps.py), the
line profiles (profiles.py), the bed's state (bed_state.py: Gamma, turnover time, kinetic
energy) and the binned mu(I) scatter (mu_i_bins.py).  Table cells are dicts of the template's
`td` (text, cls, value, stderr, attrs: the full number in data-value), images inline data
URIs (markupsafe.Markup: base64 text, safe in an attribute as it is)."""
from __future__ import annotations

import base64
import math

import numpy as np
from markupsafe import Markup

from vibroflow.analysis.compare import batches_stderr, rms_difference
from vibroflow.calibration.tub_rheology import DENSE_SOLID_FRACTION
from vibroflow.errors import InputError
from vibroflow.report import bed_state, flow_maps, mu_i_bins, profiles, verdict
from vibroflow.report.cell_tables import batches_note, method_tables
from vibroflow.rounding import plus_minus
from vibroflow.tub.motion import TubMotion


def image(png: bytes, alt: str) -> dict:
    return {"alt": alt, "src": Markup("data:image/png;base64,"
                                      + base64.b64encode(png).decode("ascii"))}


def cell(x, se=None, fmt: str = ".4g", cls: str = "", **attrs) -> dict:
    """A table cell of a number 'x ± se' (n/a when missing), or of text when x is a str."""
    tags = tuple((k.replace("_", "-"), str(v)) for k, v in attrs.items())
    if isinstance(x, str):
        return {"text": x, "cls": cls, "value": None, "stderr": None, "attrs": tags}
    if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x):
        return {"text": "n/a", "cls": cls, "value": "nan", "stderr": None, "attrs": tags}
    has_se = isinstance(se, (int, float)) and math.isfinite(se)
    return {"text": plus_minus(x, se, fmt) if has_se else format(x, fmt), "cls": cls,
            "value": repr(float(x)), "stderr": repr(float(se)) if has_se else None,
            "attrs": tags}


class Engineer:
    """The sections of one study (report.data.StudyData); the cell tables read once."""

    def __init__(self, data):
        self.data = data
        self.tables = method_tables(data)
        self.judged = verdict.e_rows(data, self.tables)

    def limit_cells(self, name: str) -> list[dict]:
        """The cells beside a continuum method's E: the limit and the verdict in words."""
        lim = self.judged["limit"]
        row = self.judged["rows"].get(name)
        if row is None:
            return [cell("reference"), cell("")]
        return [cell(lim.limit if lim else float("nan"), None, ".3f", data_method=name,
                     data_q="E_limit"),
                cell(row["words"], cls=("l " + row["cls"]).strip(), data_method=name,
                     data_q="E_verdict")]

    def limit_note(self) -> dict:
        lim = self.judged["limit"]
        out = {"note": self.judged["note"], "seeds": self.judged["seeds"],
               "known": lim is not None}
        if lim is not None:
            out.update(e_seed=f"{lim.e_seed:.3f}", stderr=(f"{lim.stderr:.3f}" if lim.stderr
                                                           is not None else None),
                       limit=f"{lim.limit:.3f}", source=lim.source, caveat=lim.caveat)
        return out

    def differences(self) -> dict:
        data = self.data
        if not data.continuum_methods:
            return {"img": None}
        dm = flow_maps.difference_maps(data, self.tables)
        rows = []
        msf = data.min_solid_fraction
        for name, m in dm.maps.items():
            ok = np.isfinite(m["dspeed"])
            a, b = self.tables[name], self.tables["dem"]
            try:
                rms = rms_difference(a, b, msf)
            except InputError:
                rms = float("nan")
            rms_se = batches_stderr(a, b, lambda s, t: rms_difference(s, t, msf))
            rows.append([cell(name, cls="l"), cell(int(ok.sum())),
                         cell(rms, rms_se, ".3g", data_method=name, data_q="rms_dv"),
                         cell(float(np.max(m["dspeed"][ok])) if ok.any() else float("nan"),
                              None, ".3g", data_method=name, data_q="max_dv")])
        return {"img": image(flow_maps.figure(data, dm), "velocity difference maps"),
                "rows": rows, "min_solid_fraction": f"{data.min_solid_fraction:g}"}

    def profiles(self) -> dict:
        try:
            p = profiles.profiles(self.tables, self.data.min_solid_fraction)
        except ValueError as exc:  # no bed cell at x = 0 in the DEM
            return {"img": None, "why": str(exc)}
        return {"img": image(profiles.figure(p), "velocity profiles"),
                "z_mid": f"{p.z_mid:.3f}",
                "with_errors": [n for n, ln in p.lines.items()
                                if np.isfinite(ln["vx_stderr"]).any()],
                "without_errors": [
                    {"name": n, "why": ("its bulk_velocity_batches.csv is unreadable: see "
                                        "Missing pieces" if batches_note(n) in self.data.notes
                                        else "no batches: no snapshots, or no "
                                        "bulk_velocity_batches.csv beside its "
                                        "bulk_velocity.csv")}
                    for n, ln in p.lines.items() if not np.isfinite(ln["vx_stderr"]).any()]}

    def bed(self) -> dict:
        data = self.data
        sc = data.scenario
        g = float(np.linalg.norm(np.asarray(sc.gravity, dtype=float)))
        motion = TubMotion.of_scenario(sc)
        gam = bed_state.gamma(motion, g)
        rows = []
        for name in data.methods:
            t = bed_state.turnover_time(self.tables[name], data.min_solid_fraction)
            rows.append([cell(name, cls="l"),
                         cell(t.time_s, t.stderr_s, ".3g", data_method=name,
                              data_q="turnover_s"),
                         cell(t.mean_vorticity_1_s, t.mean_vorticity_stderr_1_s, ".3g",
                              data_method=name, data_q="core_vorticity_1_s"),
                         cell(t.cells)])
        ke = bed_state.dem_kinetic_energy(data.out / "dem" / "dem.h5", sc)
        out = {"gamma": cell(gam["vertical"], None, ".3g", data_q="gamma"),
               "gamma_text": f"{gam['vertical']:.3g}",
               "gamma_x": f"{gam['horizontal']:.3g}", "gamma_u": f"{gam['bottom_of_u']:.3g}",
               "amplitude_z_mm": f"{1e3 * motion.amplitude_z:.3g}",
               "frequency": f"{motion.frequency:g}", "g": f"{g:.4g}",
               "turnover_rows": rows, "core": f"{bed_state.CORE:g}", "ke": None}
        if ke is not None:
            (m1, s1), (m2, s2) = ke.halves
            out["ke"] = {"img": image(bed_state.kinetic_energy_figure(ke),
                                      "kinetic energy against time"),
                         "steady": ke.steady, "mean": cell(ke.mean, ke.stderr, ".4g"),
                         "first": cell(m1, s1, ".4g"), "second": cell(m2, s2, ".4g"),
                         "rel": f"{100 * bed_state.STEADY_REL:g}"}
        return out

    def rheology_bins(self) -> dict:
        data = self.data
        got = mu_i_bins.dem_bins(data.dem_fields)
        if got is None:
            return {"img": None, "why": data.notes.get("dem_fields", "no DEM fields")}
        sc, bins = got
        fit = None
        if data.calibration is not None:
            r = data.calibration.rheology
            if all(math.isfinite(getattr(r, k)) for k in ("mu_s", "mu_2", "I_0")):
                fit = {"mu_s": r.mu_s, "mu_2": r.mu_2, "I_0": r.I_0}
        rows = [[cell(f"{lo:.3g} - {hi:.3g}", cls="l"), cell(mi, None, ".3g"),
                 cell(m, se, ".3f", data_q="mu_bin"), cell(int(n))]
                for lo, hi, mi, m, se, n in zip(bins.lo, bins.hi, bins.mean_I, bins.mean_mu,
                                                bins.stderr_mu, bins.count)]
        return {"img": image(mu_i_bins.figure(sc, bins, fit), "binned mu(I) scatter"),
                "rows": rows, "per_decade": mu_i_bins.BINS_PER_DECADE,
                "min_per_bin": mu_i_bins.MIN_PER_BIN, "dense": f"{DENSE_SOLID_FRACTION:g}"}
