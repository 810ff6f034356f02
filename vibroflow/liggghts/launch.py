"""Running LIGGGHTS: the executable, the mpirun command line, a deck run in its folder, and the
loop times of its log (the speed the benchmarks compare)."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from vibroflow.liggghts.deck_files import DECK_NAME

#: names the LIGGGHTS executable goes by (Debian: liggghts; source builds: lmp_auto)
BINARY_NAMES = ("liggghts", "lmp_auto", "lmp_fedora", "lmp_ubuntu", "lmp")


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
