"""LIGGGHTS 3.8 on a convex mesh: a ball resting on a crease of the bar's faceted cylinder.

LIGGGHTS computes no contact at an edge its `curvature` makes smooth (TriMesh's inactive
edges), and on a convex mesh the facets' faces do not cover a crease: a ball whose closest point
is the crease touches no face.  Known answers, a steel ball (m = 1.05 g, k_n = 1e5 N/m) set on
the bar's top crease (tub47-bar's 36 chords, creases every 10 degrees from +x, one at 90) with
the resting overlap m g / k_n = 0.10 um, 0.02 s under gravity:

* the deck's part line (the export's: LIGGGHTS' default `curvature`, the creases active edges):
  the edge holds it, within 1 um of where it starts;
* the same mesh with `curvature 20` (twice its crease angle): nothing holds it, and it falls
  freely into the bar, g t^2 / 2 = 1.96 mm (measured to 1e-12).
(docs/validation.md section 27; docs/liggghts.md, "Parts in the export".)
"""
from __future__ import annotations

import math
import shutil

import pytest

from vibroflow import liggghts as LG
from vibroflow.liggghts.part_meshes import part_triangles
from vibroflow.liggghts.stl import write_stl
from vibroflow.tub.parts import Part

pytestmark = pytest.mark.skipif(
    LG.find_liggghts() is None or shutil.which("mpirun") is None,
    reason="LIGGGHTS (apt-get install liggghts) or mpirun not installed")

K_N, G = 1.0e5, 9.81
BAR, R_BAR = (0.05, 0.0, 0.10), 0.0125   # m, tub47-bar's bar
LENGTH, D = 0.01905, 0.00635             # m, the short slice and the ball
DECK = """atom_style granular
atom_modify map array
boundary f f f
newton off
communicate single vel yes
units si
region domain block 0.0 0.1 -0.01 0.03 0.05 0.15 units box
create_box 2 domain
neighbor 0.001 bin
neigh_modify delay 0
fix m1 all property/global youngsModulus peratomtype 2e+11 2e+11
fix m2 all property/global poissonsRatio peratomtype 0.3 0.3
fix m3 all property/global coefficientRestitution peratomtypepair 2 0.85 0.85 0.85 0.85
fix m4 all property/global coefficientFriction peratomtypepair 2 0.2 0.2 0.2 0.2
fix kn all property/global kn peratomtypepair 2 {kn} {kn} {kn} {kn}
fix kt all property/global kt peratomtypepair 2 {kt} {kt} {kt} {kt}
fix gn all property/global gamman_abs peratomtypepair 2 1.0 1.0 1.0 1.0
fix gt all property/global gammat_abs peratomtypepair 2 0 0 0 0
pair_style gran model hooke/stiffness tangential history absolute_damping on tangential_damping off limitForce off
pair_coeff * *
timestep 1e-05
fix gravi all gravity {g} vector 0 0 -1
{mesh_line}
fix walls all wall/gran model hooke/stiffness tangential history mesh n_meshes 1 meshes pmesh1 absolute_damping on tangential_damping off limitForce off
create_atoms 1 single {x!r} {y!r} {z!r} units box
set atom 1 diameter {d!r} density 7800
fix integr all nve/sphere
run 2000
variable zend equal z[1]
print "${{zend}}" file z_end.txt
"""


def _z_end(tmp_path, name: str, curvature: str) -> tuple[float, float]:
    """(start, end) height of the ball's centre (m) on the bar's top crease."""
    bar = Part("bar", "cylinder", BAR, "steel", radius=R_BAR)
    m = 7800.0 * math.pi / 6.0 * D ** 3
    z0 = BAR[2] + R_BAR + 0.5 * D - m * G / K_N
    deck = tmp_path / name
    deck.mkdir()
    write_stl(deck / "part_bar.stl", part_triangles(bar, LENGTH), "bar")
    (deck / "in.tub").write_text(DECK.format(
        kn=K_N, kt=K_N * 2 / 7, g=G, x=BAR[0], y=0.5 * LENGTH, z=z0, d=D,
        mesh_line=f"fix pmesh1 all mesh/surface file part_bar.stl type 2{curvature}"))
    LG.run_deck(deck, nprocs=1, timeout=120)
    return z0, float((deck / "z_end.txt").read_text().split()[0])


def test_the_exports_bar_holds_a_ball_on_its_crease(tmp_path):
    z0, z1 = _z_end(tmp_path, "default", "")
    assert abs(z1 - z0) < 1e-6


def test_a_bar_with_its_creases_made_smooth_lets_the_ball_through(tmp_path):
    z0, z1 = _z_end(tmp_path, "smooth", " curvature 20")
    assert z0 - z1 == pytest.approx(0.5 * G * 0.02 ** 2, rel=1e-3)
