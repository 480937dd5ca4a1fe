"""Deck rendering: only validated numbers and names reach a LIGGGHTS script."""

import dataclasses
import math

import pytest

from pbmdem.dem import deck
from pbmdem.dem.deck import DeckValueError
from pbmdem.dem.plan import SKIN_STEPS_AT_TIP_SPEED, SNAPSHOTS_PER_CONTACT, neighbor_skin, next_prime, plan_point


@pytest.mark.parametrize("value", ["1\nshell rm -rf /", "0.1", None, True, math.nan, math.inf, [1]])
def test_number_rejects_anything_but_a_finite_number(value):
    with pytest.raises(DeckValueError, match="x ="):
        deck.number("x", value)


def test_number_and_integer():
    assert deck.number("n", 3, integer=True) == "3"
    assert float(deck.number("v", 2.5e-6)) == 2.5e-6
    with pytest.raises(DeckValueError, match="integer"):
        deck.number("n", 2.5, integer=True)


@pytest.mark.parametrize("value", ["fine\nshell ls", "a b", "${x}", "1abc", "", "x" * 65])
def test_names_must_be_plain(value):
    with pytest.raises(DeckValueError):
        deck.known_name("distribution", value)


def test_render_refuses_unvalidated_text():
    with pytest.raises(DeckValueError, match="not allowed"):
        deck.render({"timestep": "1e-5\nshell touch /tmp/x"}, "fresh")


def test_rendered_deck_is_complete_and_has_no_shell(tiny_config):
    point = tiny_config.dem_point("small")
    plan = plan_point(point, 600)
    text = deck.render_granulator(plan, ranks=1)
    assert "${" not in text
    assert "shell" not in text
    assert f"timestep        {plan.timestep!r}" in text
    assert "particledistribution/discrete/numberbased" in text
    assert "move/mesh mesh impeller rotate" in text
    # compute pair/gran/local is defined before the first run (LIGGGHTS 3.8 aborts otherwise)
    assert text.index("pair/gran/local") < text.index("\nrun ")


def test_injected_distribution_name_never_reaches_a_deck(tiny_config):
    # the schema refuses such a name (tests/test_config.py); the deck refuses it too
    evil = "small\nshell touch /tmp/pwned"
    point = tiny_config.dem_point("small").replace(distribution=evil)
    plan = plan_point(point, 600)
    with pytest.raises(DeckValueError, match="name must start"):
        deck.render_granulator(plan, ranks=1)


def test_timestep_from_rayleigh_time(tiny_config):
    plan = plan_point(tiny_config.dem_point("small"), 600)
    mat = tiny_config.material
    g = mat.youngs_modulus / (2 * (1 + mat.poisson_ratio))
    r = 0.001
    t_r = math.pi * r * math.sqrt(mat.density / g) / (0.1631 * mat.poisson_ratio + 0.8766)
    assert plan.rayleigh_time == pytest.approx(t_r)
    assert plan.timestep == pytest.approx(tiny_config.dem.timestep_fraction * t_r)
    # a snapshot at least once per Hertz contact of the smallest particles at tip speed (the
    # shortest contact), and not less than half a contact apart (the interval is the largest
    # whole number of steps within one contact time)
    assert plan.contact_time / 2 < plan.collision_interval * plan.timestep <= plan.contact_time / SNAPSHOTS_PER_CONTACT


def test_rayleigh_warning_limit_follows_a_planned_fraction_above_20_percent(tiny_config):
    """LIGGGHTS' time-step check warns above 20 % of the Rayleigh time, or just above the planned
    fraction where that is larger (a documented choice), so a run at the plan does not warn while a
    smaller particle than planned would."""
    small = tiny_config.dem_point("small")
    for fraction, limit in ((0.15, 0.2), (0.25, 0.255)):
        point = small.replace(dem=small.dem.replace(timestep_fraction=fraction))
        plan = plan_point(point, 600)
        assert plan.timestep / plan.rayleigh_time == pytest.approx(fraction)
        text = deck.render_granulator(plan, ranks=1)
        line = next(ln for ln in text.splitlines() if "check/timestep/gran" in ln)
        assert float(line.split()[-2]) == pytest.approx(limit) and line.split()[-1] == "0.2", line


def test_particle_count_fills_the_bed(default_config):
    for name in default_config.grid.size_distributions:
        plan = plan_point(default_config.dem_point(name), 600)
        d = plan.diameters
        solids = sum(c * math.pi / 6 * x**3 for c, x in zip(plan.counts, d))
        r = default_config.granulator.bowl.radius
        bed = solids / (default_config.granulator.bed.packing_fraction * math.pi * r * r)
        assert bed == pytest.approx(default_config.granulator.bed.height, rel=0.01)
        assert solids == pytest.approx(default_config.granulator.bed_solid_volume, rel=0.01)
        assert sum(plan.counts) == plan.n_particles


def test_neighbour_skin_follows_the_tip_speed_between_half_the_smallest_and_largest_diameter():
    d = (0.002, 0.003, 0.004)
    assert neighbor_skin(d, 1.0e-5) == 0.001  # impeller at rest: half the smallest
    travel = 2 * SKIN_STEPS_AT_TIP_SPEED * 3.0 * 1.0e-5
    assert 0.001 < travel < 0.002
    assert neighbor_skin(d, 1.0e-5, 3.0) == pytest.approx(travel)
    assert neighbor_skin(d, 1.0e-5, 50.0) == 0.002  # half the largest at most
    # no unit in it: millimetres and milliseconds give the same skin in millimetres
    assert neighbor_skin([x * 1e3 for x in d], 1.0e-2, 3.0) == pytest.approx(1e3 * travel)


def test_a_point_deck_sets_its_speed_s_skin_and_the_bed_deck_the_resting_one(default_config):
    point = default_config.dem_point("fine")
    slow, fast = plan_point(point, 150), plan_point(point, 1200)
    skin = {}
    for name, text in {
        "bed": deck.render_bed(slow.bed, 1),
        "slow": deck.render_granulator(slow, 1, from_bed=True),
        "fast": deck.render_granulator(fast, 1, from_bed=True),
    }.items():
        (line,) = [x for x in text.splitlines() if x.startswith("neighbor ")]
        skin[name] = float(line.split()[1])
    d_min, d_max = min(slow.bed.diameters), max(slow.bed.diameters)
    assert skin["bed"] == skin["slow"] == 0.5 * d_min
    assert 0.5 * d_min < skin["fast"] <= 0.5 * d_max
    assert skin["fast"] == pytest.approx(2 * SKIN_STEPS_AT_TIP_SPEED * fast.tip_speed * fast.timestep)


def test_the_deck_formats_the_plan_and_decides_nothing(tiny_config):
    """Every value of a deck is the plan's: change a decision in the plan and the deck follows."""
    plan = plan_point(tiny_config.dem_point("small"), 600)
    other = dataclasses.replace(
        plan, neighbor_skin=0.00123, thermo_every=17, insertion_seeds=(10037, 10039, 10061), rotation_period=0.25,
        rayleigh_limit=0.3, insert_starts=(1, 5, 9),
    )  # fmt: skip
    words = {
        line.split()[0] + (" " + line.split()[1 if "insert/" in line else 3] if line.startswith("fix") else ""): line
        for line in deck.render_granulator(other, 1).replace("&\n", "").splitlines()
        if line.strip() and not line.startswith("#")
    }
    words = {key: line.split() for key, line in words.items()}
    assert words["neighbor"][1] == "0.00123"
    assert words["thermo"][1] == "17"
    assert [words[f"fix ins{c}"][5] for c in (1, 2, 3)] == ["10037", "10039", "10061"]
    assert [words[f"fix ins{c}"][words[f"fix ins{c}"].index("start") + 1] for c in (1, 2, 3)] == ["1", "5", "9"]
    assert words["fix move/mesh"][-1] == "0.25"
    assert words["fix check/timestep/gran"][4:6] == ["17", "0.3"]
    # the plan's record (plan.json, bed.json) holds the fields a run is named by, not the deck's
    assert not {"neighbor_skin", "thermo_every", "insertion_seeds", "material"} & set(plan.to_dict())
    assert {"rpm", "seed", "timestep", "collision_interval", "sampling_time"} <= set(plan.to_dict())


def _insertions(text: str) -> dict[int, dict[str, str]]:
    """The insertion fixes of a deck by atom type: their keyword values (and the distribution's
    template), from the lines between the settling's region and its run."""
    text = text.replace("&\n", "")
    lines = [ln.split() for ln in text.splitlines() if ln.startswith("fix") and "/region" in ln]
    dists = {ln.split()[1]: ln.split() for ln in text.splitlines() if "particledistribution" in ln}
    found = {}
    for words in lines:
        keys = (
            "seed",
            "distributiontemplate",
            "nparticles",
            "maxattempt",
            "particlerate",
            "insert_every",
            "start",
            "overlapcheck",
            "region",
        )
        kv = {key: words[words.index(key) + 1] for key in keys}
        dist = dists[kv["distributiontemplate"]]
        assert dist[5:] == ["1", dist[6], "1.0"]  # one template, weight 1
        found[int(dist[6].removeprefix("pts"))] = kv | {"distribution_seed": dist[4]}
    return found


def test_every_class_is_inserted_by_its_own_fix_with_exactly_its_planned_count(default_config):
    """One fix over all classes drew each particle's class at random (the planned counts were
    missed by up to 25 %); each class now has its own fix with its count, its own prime seeds,
    the same region and insertion interval, on its own steps, and is unfixed after settling."""
    plan = plan_point(default_config.dem_point("dem_rpm900_i2"), 900)
    text = deck.render_bed(plan.bed, 1)
    fixes = _insertions(text)
    assert sorted(fixes) == [k + 1 for k, c in enumerate(plan.counts) if c > 0] == list(range(1, 6))
    assert [int(fixes[c]["nparticles"]) for c in sorted(fixes)] == plan.counts
    insert_time = 0.6 * plan.settle_steps * plan.timestep
    for c, kv in fixes.items():
        assert float(kv["particlerate"]) == pytest.approx(plan.counts[c - 1] / insert_time, rel=1e-12)
        assert kv["region"] == "fill" and kv["overlapcheck"] == "yes" and kv["insert_every"] == str(plan.insert_every)
        assert 1 <= int(kv["start"]) <= plan.insert_every
    assert len({kv["start"] for kv in fixes.values()}) == len(fixes)  # different steps
    # the largest class first in every insertion period, then by decreasing diameter
    by_start = sorted(fixes, key=lambda c: int(fixes[c]["start"]))
    assert [plan.diameters[c - 1] for c in by_start] == sorted(plan.diameters, reverse=True)
    assert {kv["maxattempt"] for kv in fixes.values()} == {str(plan.insert_attempts)}
    seeds = [int(kv[s]) for kv in fixes.values() for s in ("seed", "distribution_seed")] + list(plan.template_seeds)
    assert len(set(seeds)) == len(seeds) and all(s > 10000 and next_prime(s) == s for s in seeds)
    settle_run = text.index("\nrun ")
    for c in fixes:
        assert text.index(f"fix             ins{c} ") < settle_run < text.index(f"unfix           ins{c}\n")
    # a class the plan holds no particle of gets no fix (LIGGGHTS refuses nparticles 0)
    counts = [0, *plan.counts[1:]]
    empty = plan_point(default_config.dem_point("dem_rpm900_i2"), 900, counts=counts)
    assert sorted(_insertions(deck.render_bed(empty.bed, 1))) == [2, 3, 4, 5]
    assert "unfix           ins1\n" not in deck.render_bed(empty.bed, 1)
