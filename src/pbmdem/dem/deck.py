"""Render LIGGGHTS input decks from the templates in `liggghts_templates/`.

The templates are package data (`pbmdem/data/liggghts_templates/`, the same files as the
project's `liggghts_templates/`), so an installed pbmdem renders decks from any directory.

A LIGGGHTS input script can run shell commands (`shell ...`), so nothing from a config file is
pasted into a deck as text. Every substituted value passes through `number()` (a finite float or
int within a stated range, formatted by Python) or `known_name()` (a member of a fixed set or a
plain identifier), and the template is filled with `string.Template.substitute`, which fails on
any placeholder left unfilled.
"""

from __future__ import annotations

import math
import re
import string
from importlib import resources
from pathlib import Path

from pbmdem.config import DemPoint

from .plan import BedPlan, DemPlan, next_prime
from .progress import thermo_interval

#: the deck of a granulator run
GRANULATOR_TEMPLATE = "granulator.in"
#: the sections of granulator.in (lines "#=== section <name>") that make each kind of deck: a
#: fresh run settles its own bed; a bed run settles one and writes it to bed.restart; a run from
#: a bed reads it and goes on with the spin-up (docs/dem.md, "One settled bed for every speed")
DECKS = {
    "fresh": ("header", "box", "model", "settle", "sample"),
    "bed": ("header", "box", "model", "settle", "write_bed"),
    "from_bed": ("header", "restart", "model", "sample"),
}
_SECTION = re.compile(r"^#=== section (\w+)\n", re.MULTILINE)

_IDENTIFIER = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")


class DeckValueError(ValueError):
    """A value meant for a LIGGGHTS deck is not an allowed number or name."""


def template_dir() -> Path:
    """The folder of the LIGGGHTS templates shipped with the package."""
    return Path(str(resources.files("pbmdem") / "data" / "liggghts_templates"))


def template_path(name: str = GRANULATOR_TEMPLATE) -> Path:
    return template_dir() / name


def number(
    name: str,
    value,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    integer: bool = False,
    exclusive_minimum: bool = False,
) -> str:
    """Validate `value` as a finite number in range and return its text for a deck."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DeckValueError(f"{name} = {value!r}: a number is required, got {type(value).__name__}")
    if not math.isfinite(value):
        raise DeckValueError(f"{name} = {value!r}: a finite number is required")
    if integer and float(value) != int(value):
        raise DeckValueError(f"{name} = {value!r}: an integer is required")
    if minimum is not None:
        if exclusive_minimum and not value > minimum:
            raise DeckValueError(f"{name} = {value!r}: must be greater than {minimum}")
        if not exclusive_minimum and value < minimum:
            raise DeckValueError(f"{name} = {value!r}: must be at least {minimum}")
    if maximum is not None and value > maximum:
        raise DeckValueError(f"{name} = {value!r}: must be at most {maximum}")
    return str(int(value)) if integer else repr(float(value))


def known_name(name: str, value, allowed: set[str] | None = None) -> str:
    """Validate a name: a member of `allowed` if given, otherwise a plain identifier."""
    if not isinstance(value, str):
        raise DeckValueError(f"{name} = {value!r}: a name (string) is required")
    if allowed is not None:
        if value not in allowed:
            raise DeckValueError(f"{name} = {value!r}: allowed names are {sorted(allowed)}")
        return value
    if not _IDENTIFIER.match(value):
        raise DeckValueError(
            f"{name} = {value!r}: a name must start with a letter and contain only letters, digits, "
            "'_' or '-' (at most 64 characters)"
        )
    return value


def numbers(name: str, values, **limits) -> str:
    """Validate a sequence of numbers; return them space-separated."""
    return " ".join(number(f"{name}[{k}]", v, **limits) for k, v in enumerate(values))


def sections(template_name: str) -> dict[str, str]:
    """The sections of a template, by name (a template without section lines is one section, "all")."""
    text = (template_dir() / template_name).read_text()
    parts = _SECTION.split(text)
    if len(parts) == 1:
        return {"all": text}
    return dict(zip(parts[1::2], parts[2::2]))


def render(template_name: str, values: dict[str, str], kind: str | None = None) -> str:
    """Fill `liggghts_templates/<template_name>` (only the sections of deck `kind` of DECKS, if
    given) with already-validated text values.

    Values must come from `number`, `numbers` or `known_name` (or be built only from them);
    a value containing a line break or a LIGGGHTS comment/variable character is refused as a
    last line of defence.
    """
    for key, text in values.items():
        if not isinstance(text, str):
            raise DeckValueError(f"deck value {key} is not text; validate it with deck.number()")
        if key.endswith("_block"):
            continue  # multi-line blocks are assembled from validated numbers by the caller
        if any(ch in text for ch in "\n\r#$&;\"'`"):
            raise DeckValueError(f"deck value {key} = {text!r} contains a character not allowed in a deck")
    if kind is None:
        text = "".join(sections(template_name).values())
    else:
        parts = sections(template_name)
        text = "".join(parts[name] for name in DECKS[known_name("deck kind", kind, set(DECKS))])
    try:
        return string.Template(text).substitute(values)
    except KeyError as exc:
        raise DeckValueError(f"template {template_name} needs a value for {exc.args[0]}") from None


def _matrix(name: str, value: float, n: int) -> str:
    return " ".join([number(name, value, minimum=0.0)] * (n * n))


def bed_values(point: DemPoint, bed: BedPlan, ranks: int, name: str | None = None) -> dict[str, str]:
    """Validated text for the speed-independent placeholders of liggghts_templates/granulator.in
    (box, material, insertion and settling): the settled bed `bed` of `point` on `ranks` MPI
    ranks. `name` (default: the bed's id) heads the deck."""
    num = number
    mat = point.material
    bowl, imp = point.granulator.bowl, point.granulator.impeller
    n = len(bed.diameters)
    d_max = max(bed.diameters)
    margin = 0.05 * bowl.diameter
    templates = []
    seed = next_prime(bed.seed)
    for k, d in enumerate(bed.diameters):
        seed = next_prime(seed + 1)
        templates.append(
            f"fix             pts{k + 1} all particletemplate/sphere {num('seed', seed, integer=True)} "
            f"atom_type {k + 1} density constant {num('material.density', mat.density, minimum=1.0)} "
            f"radius constant {num(f'diameters[{k}]', 0.5 * d, exclusive_minimum=True, minimum=0.0)}"
        )
    weights = " ".join(
        f"pts{k + 1} {num(f'number_fractions[{k}]', w, minimum=0.0, maximum=1.0)}"
        for k, w in enumerate(bed.number_fractions)
    )
    fill_zlo = imp.top + d_max
    fill_zhi = bowl.height - d_max
    # insert in small batches over the first 60 % of the settling phase, so that the fill region
    # never saturates (a saturated region inserts the large templates first and skews the PSD)
    insert_time = 0.6 * bed.settle_steps * bed.timestep
    insert_every = max(1, int(0.002 / bed.timestep))
    every = thermo_interval(bed.n_particles, bed.vtk_every)
    return {
        "point_id": known_name("point_id", (name or bed.bed_id).replace(".", "p")),
        "processors": f"{num('mpi_ranks', ranks, integer=True, minimum=1)} 1 1",
        "box_xlo": num("box", -bowl.radius - margin),
        "box_xhi": num("box", bowl.radius + margin),
        "box_ylo": num("box", -bowl.radius - margin),
        "box_yhi": num("box", bowl.radius + margin),
        "box_zlo": num("box", -margin),
        "box_zhi": num("box", bowl.height + margin),
        "n_types": num("n_classes", n, integer=True, minimum=1),
        "neighbor_skin": num(
            "neighbor_skin", neighbor_skin(bed.diameters, bed.timestep), exclusive_minimum=True, minimum=0.0
        ),
        "youngs_list": " ".join(
            [num("material.youngs_modulus", mat.youngs_modulus, exclusive_minimum=True, minimum=0.0)] * n
        ),
        "poisson_list": " ".join([num("material.poisson_ratio", mat.poisson_ratio, minimum=0.0, maximum=0.5)] * n),
        "restitution_matrix": _matrix("material.restitution", mat.restitution, n),
        "friction_matrix": _matrix("material.friction", mat.friction, n),
        "rolling_matrix": _matrix("material.rolling_friction", mat.rolling_friction, n),
        "timestep": num("timestep", bed.timestep, exclusive_minimum=True, minimum=0.0),
        "bowl_stl": "bowl.stl",
        "impeller_stl": "impeller.stl",
        "post_dir": "post",
        # thermo reads fix check/timestep/gran, so both run at the same interval (LIGGGHTS requires it)
        "check_every": num("check_every", every, integer=True, minimum=1),
        "rayleigh_limit": num("rayleigh_limit", rayleigh_limit(bed), exclusive_minimum=True, minimum=0.0),
        "particle_templates_block": "\n".join(templates),
        "seed_dist": num("seed", next_prime(seed + 1), integer=True),
        "distribution_weights": weights,
        "fill_radius": num("fill_radius", bowl.radius - d_max, exclusive_minimum=True, minimum=0.0),
        "fill_zlo": num("fill_zlo", fill_zlo, minimum=0.0),
        "fill_zhi": num("fill_zhi", fill_zhi, exclusive_minimum=True, minimum=fill_zlo),
        "seed_insert": num("seed", next_prime(seed + 100), integer=True),
        "n_particles": num("n_particles", bed.n_particles, integer=True, minimum=1),
        "insert_rate": num("insert_rate", bed.n_particles / insert_time, exclusive_minimum=True, minimum=0.0),
        "insert_every": num("insert_every", insert_every, integer=True, minimum=1),
        "thermo_every": num("thermo_every", every, integer=True, minimum=1),
        "vtk_every": num("vtk_every", bed.vtk_every, integer=True, minimum=1),
        "settle_steps": num("settle_steps", bed.settle_steps, integer=True, minimum=1),
    }


#: steps between neighbour-list rebuilds that the skin allows a granule moving at the blade tip
#: speed (LIGGGHTS rebuilds the lists when a granule has moved half the skin)
SKIN_STEPS_AT_TIP_SPEED = 22


def neighbor_skin(diameters, timestep: float, tip_speed: float = 0.0) -> float:
    """The neighbour-list skin of a bed of granules of `diameters` at the impeller tip speed
    `tip_speed`: the distance a granule at the tip speed travels in 2 x SKIN_STEPS_AT_TIP_SPEED
    steps, between half the smallest and half the largest diameter.

    Every skin gives the same contacts (the lists are checked every step); it only trades list
    rebuilds (a small skin at a high speed) against pair checks (a large skin around small
    granules). Measured on the default grid (docs/dem.md, "Cost of a run"): half the largest
    diameter, the old skin, cost the fine bed 12 % at 600 rpm and the coupled loops' wide samples
    18-29 %; half the smallest cost the fine bed 24 % at 1200 rpm."""
    travel = 2 * SKIN_STEPS_AT_TIP_SPEED * tip_speed * timestep
    return min(max(0.5 * min(diameters), travel), 0.5 * max(diameters))


def granulator_values(point: DemPoint, plan: DemPlan, ranks: int) -> dict[str, str]:
    """Validated text for every placeholder of liggghts_templates/granulator.in: the run `plan` of
    `point` on `ranks` MPI ranks."""
    num = number
    skin = neighbor_skin(plan.bed.diameters, plan.timestep, plan.tip_speed)
    return bed_values(point, plan.bed, ranks, name=plan.point_id) | {
        "neighbor_skin": num("neighbor_skin", skin, exclusive_minimum=True, minimum=0.0),
        "spinup_steps": num("spinup_steps", plan.spinup_steps, integer=True, minimum=1),
        "sampling_steps": num("sampling_steps", plan.sampling_steps, integer=True, minimum=1),
        "spinup_pre_steps": num("spinup_pre_steps", plan.spinup_steps - plan.history_steps, integer=True, minimum=1),
        "record_steps": num("record_steps", plan.history_steps + plan.sampling_steps, integer=True, minimum=1),
        "position_interval": num("position_interval", plan.position_interval, integer=True, minimum=1),
        "rotation_period": num("rotation_period", 60.0 / plan.rpm, exclusive_minimum=True, minimum=0.0),
        "collision_interval": num("collision_interval", plan.collision_interval, integer=True, minimum=1),
    }


#: LIGGGHTS' warning limit of dt over the Rayleigh time when the plan's fraction is below it
RAYLEIGH_WARNING_FRACTION = 0.2


def rayleigh_limit(bed: BedPlan) -> float:
    """The fraction of the Rayleigh time above which fix check/timestep/gran warns: 20 %, or 2 %
    above the planned fraction dt / t_R where that is larger (the fraction is a documented choice,
    docs/dem.md "Cost of a run"; a particle smaller than planned still makes it warn)."""
    return max(RAYLEIGH_WARNING_FRACTION, 1.02 * bed.timestep / bed.rayleigh_time)


def render_granulator(point: DemPoint, plan: DemPlan, ranks: int, *, from_bed: bool = False) -> str:
    """The granulator deck of a run, every value validated (raises DeckValueError before any I/O):
    a fresh run that settles its own bed, or (`from_bed`) one that starts from bed.restart."""
    return render(GRANULATOR_TEMPLATE, granulator_values(point, plan, ranks), "from_bed" if from_bed else "fresh")


def render_bed(point: DemPoint, bed: BedPlan, ranks: int) -> str:
    """The deck that inserts and settles the bed `bed` and writes it to bed.restart."""
    return render(GRANULATOR_TEMPLATE, bed_values(point, bed, ranks), "bed")
