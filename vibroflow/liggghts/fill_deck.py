"""The fill's lines of a LIGGGHTS deck (vibroflow.liggghts.deck): LIGGGHTS' own random insertion
(`add_insertion`), or the DEM's settled bed read from the data file (`add_fill_from_data`,
vibroflow.liggghts.dem_fill).  Both end with the step and the ball count in post/fill_done.txt
and the variable `stepnow` the settling and the vibration count from."""
from __future__ import annotations

from vibroflow.liggghts.part_deck import add_part_exclusions
from vibroflow.liggghts.template import _Deck, _fmt


def add_insertion(deck: _Deck, scenario, parts, count: int, per_event: int, event_steps: int,
                  seeds: list[int], rate: float, max_passes: int, margin: float,
                  region: tuple[float, float, float, float], max_sagitta: float,
                  post_dir: str, fill_file: str) -> None:
    """`fix insert/rate/region` (random, no overlaps) in the U above insert_above, in events of
    `per_event` balls every `event_steps` steps, repeated until all `count` balls are in (at most
    `max_passes` events); region = (y_lo, y_hi, z_lo, z_hi) of the centres (m), `margin` (m)
    from the walls, the parts left out (part_deck.add_part_exclusions)."""
    add = deck.add
    fill, tub = scenario.fill, scenario.tub
    R, L = tub.radius, tub.length
    iy_lo, iy_hi, ins_z_lo, ins_z_hi = region
    add("# ---- fill: {} balls, d = {} m, in events of {} every {} steps, until all are in",
        count, _fmt(fill.diameter), per_event, event_steps)
    add("fix pts1 all particletemplate/sphere {} atom_type 1 density constant {} radius "
        "constant {}", seeds[0], _fmt(scenario.materials[fill.material].density),
        _fmt(0.5 * fill.diameter))
    add("fix pdd1 all particledistribution/discrete {} 1 pts1 1.0", seeds[1])
    add("region ucyl cylinder y 0 {} {} {} {} units box",
        *(_fmt(v) for v in (R, R - margin, iy_lo, iy_hi)))
    add("region ublk block {} {} {} {} {} {} units box",
        *(_fmt(v) for v in (-R + margin, R - margin, iy_lo, iy_hi, R, ins_z_hi)))
    add("region uin union 2 ucyl ublk")
    add("region zcut block INF INF INF INF {} {} units box", _fmt(ins_z_lo), _fmt(ins_z_hi))
    outside = add_part_exclusions(deck, parts, L, max_sagitta, margin)
    add("region ins intersect {} uin zcut" + " {}" * len(outside), 2 + len(outside), *outside)
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
    add(f'print "${{stepnow}} ${{natoms}}" file {post_dir}/{fill_file}')
    add('if "${natoms} < {}" then "print \'vibroflow: the fill inserted only ${natoms} of {} '
        'balls\'"', count, count)


def add_fill_from_data(deck: _Deck, count: int, post_dir: str, fill_file: str) -> None:
    """The fill already read by `read_data` (the DEM's settled bed, at rest), no insertion;
    a count other than `count` is said on the screen, as a short insertion is."""
    add = deck.add
    add("# ---- fill: the DEM's settled bed of {} balls, read from the data file above, at rest",
        count)
    add("variable stepnow equal step")
    add(f'print "${{stepnow}} ${{natoms}}" file {post_dir}/{fill_file}')
    add('if "${natoms} != {}" then "print \'vibroflow: the data file holds ${natoms}, not {} '
        'balls\'"', count, count)
