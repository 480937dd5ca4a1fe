"""Render LIGGGHTS input decks from the templates in `liggghts_templates/`: format a plan.

Every value of a deck is decided by the planner (`plan.py`); this module only writes it as text.

The templates are package data (`pbmdem/data/liggghts_templates/`, the same files as the
project's `liggghts_templates/`), so an installed pbmdem renders decks from any directory.

A LIGGGHTS input script can run shell commands (`shell ...`), so nothing from a config file is
pasted into a deck as text. Every substituted value passes through `number()` (a finite float or
int, formatted by Python; its range was checked where the setting entered) or `known_name()` (a
member of a fixed set or a plain identifier), and the template is filled with
`string.Template.substitute`, which fails on any placeholder left unfilled.
"""

from __future__ import annotations

import math
import re
import string
from importlib import resources
from pathlib import Path

from .plan import BedPlan, DemPlan

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
    """The shipped template `name` (the workflow hashes the granulator deck's to rerun the DEM jobs when it changes)."""
    return template_dir() / name


def number(name: str, value, *, integer: bool = False) -> str:
    """`value` as text for a deck: a finite number (an integer if `integer`), or DeckValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DeckValueError(f"{name} = {value!r}: a number is required, got {type(value).__name__}")
    if not math.isfinite(value):
        raise DeckValueError(f"{name} = {value!r}: a finite number is required")
    if integer and float(value) != int(value):
        raise DeckValueError(f"{name} = {value!r}: an integer is required")
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
    return render(GRANULATOR_TEMPLATE, granulator_values(plan, ranks), "from_bed" if from_bed else "fresh")


def render_bed(bed: BedPlan, ranks: int) -> str:
    """The deck that inserts and settles the bed `bed` and writes it to bed.restart."""
    return render(GRANULATOR_TEMPLATE, bed_values(bed, ranks), "bed")
