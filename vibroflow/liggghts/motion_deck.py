"""The tub's motion in a LIGGGHTS deck (vibroflow.liggghts.deck): the meshes moved rigidly with
the tub by two superposed `fix move/mesh` each, `linear/variable` (the translation) then
`rotate/variable` about the pivot (whose origin rides with the translation).  Their velocity
variables are the exact derivatives of s(a, phi, t) = a [sin(omega t + phi) - sin(phi)],
evaluated at the middle of the step, t = (step - n0 - 1/2) dt, because LIGGGHTS moves a mesh
once a step with the step counter already advanced: the midpoint rule, which reproduces X(t),
Z(t), theta(t) with every phase to O(dt^2) (docs/liggghts.md, "The tub's motion")."""
from __future__ import annotations

from vibroflow.liggghts.template import _SLOT, _Deck, _fmt
from vibroflow.tub.motion import TubMotion


def add_tub_motion(deck: _Deck, motion: TubMotion, dt: float, meshes: list[str]) -> None:
    """The velocity variables (from the deck's variable n0, the vibration's first step) and the
    two move/mesh fixes of each mesh id in `meshes`."""
    add, S, w = deck.add, _SLOT, motion.omega
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
    for mesh in meshes:
        add(f"fix move_{mesh}_t all move/mesh mesh {mesh} linear/variable v_vX v_vY v_vZ")
        add(f"fix move_{mesh}_r all move/mesh mesh {mesh} rotate/variable origin {S} 0. {S} "
            "axis 0. -1. 0. omega v_wT", _fmt(motion.pivot_x), _fmt(motion.pivot_z))
