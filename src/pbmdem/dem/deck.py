"""Format a plan (`plan.py`, which decides every value) as a LIGGGHTS deck from the shipped
template `pbmdem/data/liggghts_templates/granulator.in`; every value passes `number()` or
`known_name()` first, so no config text reaches a deck (docs/dem.md, "One settled bed for every speed").
"""

from __future__ import annotations

import math
import re
import string
from importlib import resources
from pathlib import Path

from pbmdem.config.typed import NAME_PATTERN

from .plan import BedPlan, DemPlan

#: the sections of granulator.in (lines "#=== section <name>") that make each kind of deck: a
#: fresh run settles its own bed; a bed run settles one and writes it to bed.restart; a run from
#: a bed reads it and goes on with the spin-up (docs/dem.md, "One settled bed for every speed")
DECKS = {
    "fresh": ("header", "box", "model", "settle", "sample"),
    "bed": ("header", "box", "model", "settle", "write_bed"),
    "from_bed": ("header", "restart", "model", "sample"),
}
_SECTION = re.compile(r"^#=== section (\w+)\n", re.MULTILINE)
_IDENTIFIER = re.compile(NAME_PATTERN)


class DeckValueError(ValueError):
    """A value meant for a LIGGGHTS deck is not an allowed number or name."""


def template_path() -> Path:
    """The shipped granulator template (the workflow hashes it to rerun the DEM jobs when it changes)."""
    return Path(str(resources.files("pbmdem") / "data" / "liggghts_templates" / "granulator.in"))


def number(name: str, value, *, integer: bool = False) -> str:
    """`value` as text for a deck: a finite number (an integer if `integer`), or DeckValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DeckValueError(f"{name} = {value!r}: a number is required, got {type(value).__name__}")
    if not math.isfinite(value):
        raise DeckValueError(f"{name} = {value!r}: a finite number is required")
    if integer and float(value) != int(value):
        raise DeckValueError(f"{name} = {value!r}: an integer is required")
    return str(int(value)) if integer else repr(float(value))


def known_name(name: str, value) -> str:
    """`value` if it is a plain identifier, else DeckValueError naming it."""
    if not isinstance(value, str) or not _IDENTIFIER.match(value):
        raise DeckValueError(
            f"{name} = {value!r}: a name must start with a letter and contain only letters, digits, "
            "'_' or '-' (at most 64 characters)"
        )
    return value


def render(values: dict[str, str], kind: str) -> str:
    """The sections of deck `kind` (DECKS) of the template filled with `values`, text from
    `number` or `known_name` (or built only from them); a value with a line break or a LIGGGHTS
    comment or variable character is refused as a last line of defence."""
    for key, text in values.items():
        if not isinstance(text, str):
            raise DeckValueError(f"deck value {key} is not text; validate it with deck.number()")
        if not key.endswith("_block") and any(ch in text for ch in "\n\r#$&;\"'`"):
            raise DeckValueError(f"deck value {key} = {text!r} contains a character not allowed in a deck")
    parts = _SECTION.split(template_path().read_text())
    sections = dict(zip(parts[1::2], parts[2::2]))
    try:
        return string.Template("".join(sections[name] for name in DECKS[kind])).substitute(values)
    except KeyError as exc:
        raise DeckValueError(f"template granulator.in needs a value for {exc.args[0]}") from None


#: the plan's fields that fill the placeholders of the same name: numbers, integers, and the run's integers
BED_NUMBERS = ("timestep", "rayleigh_limit", "fill_radius", "fill_zlo", "fill_zhi")
BED_INTEGERS = ("thermo_every", "vtk_every", "settle_steps")
RUN_INTEGERS = ("spinup_steps", "sampling_steps", "spinup_pre_steps", "record_steps", "position_interval",
                "collision_interval")  # fmt: skip


def _matrix(value: float, n: int) -> str:
    return " ".join([number("matrix", value)] * (n * n))


def bed_values(bed: BedPlan, ranks: int) -> dict[str, str]:
    """Text for the speed-independent placeholders of liggghts_templates/granulator.in (box,
    material, insertion and settling) of the settled bed `bed` on `ranks` MPI ranks."""
    num, mat, n = number, bed.material, len(bed.diameters)
    templates = [
        f"fix             pts{k + 1} all particletemplate/sphere {num('seed', seed, integer=True)} "
        f"atom_type {k + 1} density constant {num('density', mat.density)} "
        f"radius constant {num(f'diameters[{k}]', 0.5 * d)}"
        for k, (seed, d) in enumerate(zip(bed.template_seeds, bed.diameters))
    ]
    # one distribution of one template and one insertion fix per class: exactly its planned count
    insert, unfix = [], []
    for k, count in enumerate(bed.counts):
        if count == 0:
            continue  # LIGGGHTS refuses an insertion of no particles
        c = k + 1
        insert += [
            f"fix             psd{c} all particledistribution/discrete/numberbased "
            f"{num('seed', bed.distribution_seeds[k], integer=True)} 1 pts{c} 1.0",
            f"fix             ins{c} all insert/rate/region seed {num('seed', bed.insertion_seeds[k], integer=True)} "
            f"distributiontemplate psd{c} nparticles {num(f'counts[{k}]', count, integer=True)} &\n"
            f"                particlerate {num(f'insert_rates[{k}]', bed.insert_rates[k])} "
            f"insert_every {num('insert_every', bed.insert_every, integer=True)} "
            f"start {num(f'insert_starts[{k}]', bed.insert_starts[k], integer=True)} overlapcheck yes "
            f"maxattempt {num('insert_attempts', bed.insert_attempts, integer=True)} all_in yes &\n"
            "                vel constant 0.0 0.0 -0.5 region fill",
        ]
        unfix.append(f"unfix           ins{c}")
    box = dict(zip(("box_xlo", "box_xhi", "box_ylo", "box_yhi", "box_zlo", "box_zhi"), bed.box))
    return {
        "point_id": known_name("point_id", bed.bed_id.replace(".", "p")),
        "processors": f"{num('mpi_ranks', ranks, integer=True)} 1 1",
        **{key: num(key, value) for key, value in box.items()},
        "n_types": num("n_classes", n, integer=True),
        "neighbor_skin": num("neighbor_skin", bed.settle_skin),
        "youngs_list": " ".join([num("youngs_modulus", mat.youngs_modulus)] * n),
        "poisson_list": " ".join([num("poisson_ratio", mat.poisson_ratio)] * n),
        "restitution_matrix": _matrix(mat.restitution, n),
        "friction_matrix": _matrix(mat.friction, n),
        "rolling_matrix": _matrix(mat.rolling_friction, n),
        "bowl_stl": "bowl.stl",
        "impeller_stl": "impeller.stl",
        "post_dir": "post",
        "check_every": num("check_every", bed.thermo_every, integer=True),
        "particle_templates_block": "\n".join(templates),
        "insertion_block": "\n".join(insert),
        "unfix_insertion_block": "\n".join(unfix),
        # the plan's fields of the same name
        **{key: num(key, getattr(bed, key)) for key in BED_NUMBERS},
        **{key: num(key, getattr(bed, key), integer=True) for key in BED_INTEGERS},
    }


def granulator_values(plan: DemPlan, ranks: int) -> dict[str, str]:
    """Text for every placeholder of liggghts_templates/granulator.in: the run `plan` on `ranks`
    MPI ranks."""
    num = number
    return bed_values(plan, ranks) | {
        "point_id": known_name("point_id", plan.point_id.replace(".", "p")),
        **{key: num(key, getattr(plan, key)) for key in ("neighbor_skin", "rotation_period")},
        **{key: num(key, getattr(plan, key), integer=True) for key in RUN_INTEGERS},
    }


def render_granulator(plan: DemPlan, ranks: int, *, from_bed: bool = False) -> str:
    """The granulator deck of a run (raises DeckValueError before any I/O): a fresh run that
    settles its own bed, or (`from_bed`) one that starts from bed.restart."""
    return render(granulator_values(plan, ranks), "from_bed" if from_bed else "fresh")


def render_bed(bed: BedPlan, ranks: int) -> str:
    """The deck that inserts and settles the bed `bed` and writes it to bed.restart."""
    return render(bed_values(bed, ranks), "bed")
