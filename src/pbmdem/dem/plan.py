"""The plan of one DEM run: every decision about it in one frozen object, `plan_bed` the part of
a settled bed (speed-independent), `plan_point` the rest at a speed (docs/dem.md, "A run").
`deck.py` only formats a plan; `to_dict` is its record (plan.json, bed.json) without the fields
marked `DECK`, which the deck derives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from pbmdem.config import ConfigError, DemPoint, SizeDistribution
from pbmdem.config.dem import DemLimits
from pbmdem.config.granulator import Granulator, Material

#: contact snapshots per Hertz contact time t_c of two of the smallest particles meeting at the
#: tip speed, the shortest contact of a run (docs/dem.md, "Cost of a run": one against two)
SNAPSHOTS_PER_CONTACT = 1
#: replicate r runs with insertion seeds derived from dem.seed + r x this prime
REPLICATE_SEED_STRIDE = 7919
#: random positions an insertion fix tries for a particle (LIGGGHTS' maxattempt; its default is 50)
INSERT_ATTEMPTS = 1000
#: impact speed (m/s) below which the contact time is not evaluated (an impeller at rest)
MIN_CONTACT_SPEED = 0.1
#: steps between neighbour-list rebuilds that the skin allows a granule moving at the blade tip
#: speed (LIGGGHTS rebuilds the lists when a granule has moved half the skin)
SKIN_STEPS_AT_TIP_SPEED = 22
#: LIGGGHTS' warning limit of dt / Rayleigh time; a plan above it warns 2 % above its own fraction
RAYLEIGH_WARNING_FRACTION = 0.2
#: a thermo line every this many particle-steps (~0.3-1 s of wall time at 2-4 M particle-steps/s),
#: so that the progress moves between its 10 s log lines even for large beds
THERMO_PARTICLE_STEPS = 1_000_000
#: a field of the deck only (derived from the recorded fields and the settings), not in `to_dict`
DECK = {"deck": True}


def rayleigh_time(radius: float, density: float, youngs: float, poisson: float) -> float:
    """Rayleigh wave time of a sphere: pi R sqrt(rho/G) / (0.1631 nu + 0.8766)."""
    shear = youngs / (2.0 * (1.0 + poisson))
    return math.pi * radius * math.sqrt(density / shear) / (0.1631 * poisson + 0.8766)


def hertz_contact_time(radius: float, density: float, youngs: float, poisson: float, speed: float) -> float:
    """Duration of an elastic Hertz impact of two equal spheres at relative speed `speed`."""
    mass = density * 4.0 / 3.0 * math.pi * radius**3
    m_eff, r_eff = mass / 2.0, radius / 2.0
    e_eff = youngs / (2.0 * (1.0 - poisson**2))
    return 2.87 * (m_eff**2 / (r_eff * e_eff**2 * speed)) ** 0.2


def neighbor_skin(diameters, timestep: float, tip_speed: float = 0.0) -> float:
    """The neighbour-list skin at the tip speed `tip_speed`: the travel of 2 x SKIN_STEPS_AT_TIP_SPEED
    steps, between half the smallest and half the largest diameter (docs/dem.md, "Cost of a run")."""
    travel = 2 * SKIN_STEPS_AT_TIP_SPEED * tip_speed * timestep
    return min(max(0.5 * min(diameters), travel), 0.5 * max(diameters))


def next_prime(n: int) -> int:
    """Smallest prime >= max(n, 10007) (LIGGGHTS wants prime seeds above 10000)."""
    n = max(int(n), 10007)
    while True:
        if n % 2 and all(n % k for k in range(3, int(n**0.5) + 1, 2)):
            return n
        n += 1


@dataclass(frozen=True)
class BedPlan:
    """The speed-independent part of a run: the bed that is inserted and settled at rest."""

    distribution: str
    diameters: list[float]
    number_fractions: list[float]
    counts: list[int]
    n_particles: int
    timestep: float
    rayleigh_time: float
    settle_steps: int
    vtk_every: int
    replicate: int
    seed: int
    # what the deck is made of (DECK: derived, not recorded)
    material: Material = field(metadata=DECK)
    granulator: Granulator = field(metadata=DECK)
    #: LIGGGHTS' prime seeds, one per class each: its particle template, its particle distribution
    #: (of that one template) and its insertion fix
    template_seeds: tuple[int, ...] = field(metadata=DECK)
    distribution_seeds: tuple[int, ...] = field(metadata=DECK)
    insertion_seeds: tuple[int, ...] = field(metadata=DECK)
    #: simulation box (xlo, xhi, ylo, yhi, zlo, zhi) and the insertion cylinder (radius, zlo, zhi), m
    box: tuple[float, ...] = field(metadata=DECK)
    fill_radius: float = field(metadata=DECK)
    fill_zlo: float = field(metadata=DECK)
    fill_zhi: float = field(metadata=DECK)
    #: one insertion fix per class that inserts exactly its `counts` (a class with none has no
    #: fix): its particles per second, every `insert_every` steps from its first step `insert_starts`
    insert_rates: tuple[float, ...] = field(metadata=DECK)
    insert_every: int = field(metadata=DECK)
    insert_starts: tuple[int, ...] = field(metadata=DECK)
    #: random positions a fix tries for a particle before it gives up until its next step
    insert_attempts: int = field(metadata=DECK)
    #: steps between thermo lines (and the time-step check, which thermo reads)
    thermo_every: int = field(metadata=DECK)
    #: neighbour skin (m) of the settling, the impeller at rest
    settle_skin: float = field(metadata=DECK)
    rayleigh_limit: float = field(metadata=DECK)

    @property
    def bed_id(self) -> str:
        """`<distribution>_rep<k>`: the bed's name in paths and decks."""
        return f"{self.distribution}_rep{self.replicate}"

    def to_dict(self) -> dict:
        """The record of the plan (plan.json, bed.json): every field but the deck's."""
        record = {f.name: getattr(self, f.name) for f in fields(self) if not f.metadata.get("deck")}
        return {k: list(v) if isinstance(v, list) else v for k, v in record.items()}


@dataclass(frozen=True)
class DemPlan(BedPlan):
    """One run: its settled bed (the fields of `BedPlan`) and what follows at its speed."""

    point_id: str
    rpm: float
    contact_time: float
    collision_interval: int
    spinup_steps: int
    sampling_steps: int
    tip_speed: float
    history_steps: int
    position_interval: int
    encounter_gap_fraction: float
    omega: float
    #: neighbour skin (m) at this speed, one impeller revolution (s), and whether the contact and
    #: position dumps are kept after the tables are made
    neighbor_skin: float = field(metadata=DECK)
    rotation_period: float = field(metadata=DECK)
    keep_contact_dumps: bool = field(metadata=DECK)
    #: spin-up steps before the position history (recorded before the window) starts, and the
    #: steps with dumps: the position history, then the sampling window
    spinup_pre_steps: int = field(metadata=DECK)
    record_steps: int = field(metadata=DECK)

    @property
    def dumps(self) -> dict[str, tuple[int, int]]:
        """What is dumped (liggghts_templates/granulator.in): the frames and last step of each
        dump of a finished run, one at the start of the recording (`dump_modify first yes`, the
        position history before the sampling window), then one at every multiple of its interval
        up to the end."""
        start, end = self.window_start_step - self.history_steps, self.window_start_step + self.sampling_steps

        def frames_and_last(every: int) -> tuple[int, int]:
            multiples = end // every - (start + every - 1) // every + 1
            return multiples + (1 if start % every else 0), (end // every * every if multiples > 0 else start)

        contacts = frames_and_last(self.collision_interval)
        return {
            "post/pairs.dump": contacts,
            "post/walls.dump": contacts,
            "post/positions.bin": frames_and_last(self.position_interval),
        }

    @property
    def sampling_time(self) -> float:
        return self.sampling_steps * self.timestep

    @property
    def window_start_step(self) -> int:
        """Step at which the sampling window opens (end of the spin-up)."""
        return self.settle_steps + self.spinup_steps

    @property
    def total_steps(self) -> int:
        return self.settle_steps + self.spinup_steps + self.sampling_steps

    @property
    def particle_steps(self) -> float:
        return float(self.n_particles) * self.total_steps

    @property
    def run_steps(self) -> int:
        """Steps after the settling: what a run from a settled bed simulates."""
        return self.spinup_steps + self.sampling_steps

    @property
    def bed(self) -> BedPlan:
        """The settled bed this run starts from (the same for every speed)."""
        return BedPlan(**{f: getattr(self, f) for f in BedPlan.__dataclass_fields__})

    def to_dict(self) -> dict:
        return super().to_dict() | {"sampling_time": self.sampling_time}


def class_counts(n_particles: int, fractions) -> list[int]:
    """Expected numbers per class for `n_particles` (largest-remainder rounding)."""
    raw = np.asarray(fractions, float) * n_particles
    counts = np.floor(raw).astype(int)
    counts[np.argsort(-(raw - counts))[: n_particles - counts.sum()]] += 1
    return counts.tolist()


def bed_particle_count(bed_solid_volume: float, sizes: SizeDistribution) -> int:
    """Particles that hold the bed's solid volume with this size distribution."""
    return int(round(bed_solid_volume / sizes.mean_particle_volume))


def plan_bed(point: DemPoint, *, replicate: int = 0, counts: list[int] | None = None, where: str = "") -> BedPlan:
    """Plan the settled bed of `point`: particles, time step, settling and seeds. `replicate`
    selects the insertion seeds (replicates of one point differ only by them). `counts`
    (particles per class) replaces the count derived from the bed's solid volume: the coupled
    PBM-DEM loop hands its own sample this way. `where` names the bed in errors."""
    sizes, mat, dem, granulator = point.sizes, point.material, point.dem, point.granulator
    where = where or f"distribution {point.distribution}"
    counts = None if counts is None else [int(c) for c in counts]
    n_particles = bed_particle_count(granulator.bed_solid_volume, sizes) if counts is None else sum(counts)
    if n_particles > dem.max_particles:
        raise ConfigError(f"{where} needs {n_particles} particles, more than dem.max_particles = {dem.max_particles}")
    if n_particles < 2:
        raise ConfigError(f"{where}: the bed holds {n_particles} particles; raise dem.bed_height")
    counts = class_counts(n_particles, sizes.number_fractions) if counts is None else counts
    t_r = rayleigh_time(0.5 * min(sizes.diameters), mat.density, mat.youngs_modulus, mat.poisson_ratio)
    dt = dem.timestep_fraction * t_r
    settle_steps, vtk_every = _steps(dem.settle_time, dt), _steps(dem.vtk_interval, dt)
    seed = dem.seed + REPLICATE_SEED_STRIDE * int(replicate)
    primes, prime = [], next_prime(seed)
    for _ in range(3 * len(sizes.diameters)):  # template, distribution and insertion seeds
        prime = next_prime(prime + 1)
        primes.append(prime)
    n_classes = len(sizes.diameters)
    bowl, d_max = granulator.bowl, max(sizes.diameters)
    margin, half = 0.05 * bowl.diameter, bowl.radius + 0.05 * bowl.diameter
    # one insertion fix per class, in small batches over the first 60 % of the settling, the classes
    # on different steps, the largest first (docs/dem.md, "A run": insertion)
    insert_time = 0.6 * settle_steps * dt
    insert_every = max(1, int(0.002 / dt))
    largest_first = np.argsort(-np.asarray(sizes.diameters, float), kind="stable")
    offsets = np.empty(n_classes, int)
    offsets[largest_first] = 1 + np.arange(n_classes) * (insert_every // n_classes)
    return BedPlan(
        distribution=point.distribution,
        diameters=list(sizes.diameters),
        number_fractions=list(sizes.number_fractions),
        counts=counts,
        n_particles=n_particles,
        timestep=dt,
        rayleigh_time=t_r,
        settle_steps=settle_steps,
        vtk_every=vtk_every,
        replicate=int(replicate),
        seed=seed,
        material=mat,
        granulator=granulator,
        template_seeds=tuple(primes[:n_classes]),
        distribution_seeds=tuple(primes[n_classes : 2 * n_classes]),
        insertion_seeds=tuple(primes[2 * n_classes :]),
        box=(-half, half, -half, half, -margin, bowl.height + margin),
        fill_radius=bowl.radius - d_max,
        fill_zlo=granulator.impeller.top + d_max,
        fill_zhi=bowl.height - d_max,
        insert_rates=tuple(c / insert_time for c in counts),
        insert_every=insert_every,
        insert_starts=tuple(int(k) for k in offsets),
        insert_attempts=INSERT_ATTEMPTS,
        # thermo reads fix check/timestep/gran, so both run at the same interval (LIGGGHTS requires it)
        thermo_every=max(1, min(vtk_every, THERMO_PARTICLE_STEPS // n_particles)),
        settle_skin=neighbor_skin(sizes.diameters, dt),
        rayleigh_limit=max(RAYLEIGH_WARNING_FRACTION, 1.02 * dt / t_r),
    )


def _steps(seconds: float, dt: float) -> int:
    return max(1, int(math.ceil(seconds / dt)))


def _whole(steps: int, every: int) -> int:
    return int(math.ceil(steps / every) * every)


def plan_point(point: DemPoint, rpm: float, *, replicate: int = 0, counts: list[int] | None = None) -> DemPlan:
    """Plan one run of `point` at `rpm`: its bed (`plan_bed`, same `replicate` and `counts`), then
    the spin-up and the sampling window at this speed."""
    # rpm was checked where it entered (the config's Rpm type, or check_rpm on a command line)
    speed = point.at(rpm)
    rpm, pid, tip_speed = speed.rpm, speed.point_id, speed.tip_speed
    bed = plan_bed(point, replicate=replicate, counts=counts, where=f"operating point {pid}")
    mat, dem, dt = point.material, point.dem, bed.timestep
    t_c = hertz_contact_time(
        0.5 * min(bed.diameters), mat.density, mat.youngs_modulus, mat.poisson_ratio, max(tip_speed, MIN_CONTACT_SPEED)
    )
    interval = dem.collision_interval
    if interval == "auto":
        interval = max(1, int(t_c / (SNAPSHOTS_PER_CONTACT * dt)))
    position_interval = dem.position_every * interval
    spinup_steps = _steps(speed.spinup_time, dt)
    # the window and the position history before it: whole position intervals
    sampling_steps = _whole(_steps(speed.sampling_time, dt), position_interval)
    history_steps = _whole(_steps(dem.history_time, dt), position_interval)
    if history_steps >= spinup_steps:
        raise ConfigError(
            f"dem.history_time = {dem.history_time} s: the position history before the sampling "
            f"window must be shorter than the spin-up ({spinup_steps * dt:.4g} s at {rpm:g} rpm)"
        )
    return DemPlan(
        **{f: getattr(bed, f) for f in BedPlan.__dataclass_fields__},
        point_id=pid,
        rpm=rpm,
        contact_time=t_c,
        collision_interval=int(interval),
        spinup_steps=spinup_steps,
        sampling_steps=sampling_steps,
        tip_speed=tip_speed,
        history_steps=history_steps,
        position_interval=int(position_interval),
        encounter_gap_fraction=dem.encounter_gap_fraction,
        omega=speed.omega,
        neighbor_skin=neighbor_skin(bed.diameters, dt, tip_speed),
        rotation_period=speed.rotation_period,
        keep_contact_dumps=dem.keep_contact_dumps,
        spinup_pre_steps=spinup_steps - history_steps,
        record_steps=history_steps + sampling_steps,
    )


def limit_problems(plan: DemPlan, limits: DemLimits) -> list[str]:
    """What in `plan` exceeds `limits` (dem.limits): one sentence, naming the point, each bound
    exceeded (key, the plan's value, the bound) and what the plan is made of; empty if none."""
    values = {
        "max_steps": (plan.total_steps, "time steps"),
        "max_simulated_time": (plan.total_steps * plan.timestep, "s simulated"),
        "max_particle_steps": (plan.particle_steps, "particle-steps"),
    }
    over = [
        f"{value:.4g} {what}, more than dem.limits.{key} = {getattr(limits, key):g}"
        for key, (value, what) in values.items()
        if value > getattr(limits, key)
    ]
    if not over:
        return []
    return [
        f"operating point {plan.point_id}: the plan needs " + "; ".join(over) + f" (settling {plan.settle_steps}, "
        f"spin-up {plan.spinup_steps} and sampling {plan.sampling_steps} steps of {plan.timestep:.3g} s, "
        f"{plan.n_particles} particles, {plan.rpm:g} rpm); check the speed and the phase settings, or raise the bound"
    ]


def check_limits(plan: DemPlan, limits: DemLimits) -> DemPlan:
    """`plan` if it stays within `limits` (dem.limits), else ConfigError naming each bound exceeded."""
    if problems := limit_problems(plan, limits):
        raise ConfigError("\n".join(problems))
    return plan


def check_workflow_plans(cfg) -> None:
    """Plan every DEM run the workflow of `cfg` (a pbmdem.config.Config) would start: each grid
    point (replicates differ only by their seeds) and each validation speed's coupled-loop call
    (with the bed of its feed; a loop's samples hold at most dem.max_particles). ConfigError listing
    every point beyond dem.limits (or that cannot be planned), before Snakemake builds its DAG."""
    limits = cfg.dem_execution.limits
    problems: list[str] = []
    runs = [("grid", cfg.dem_point(dist), rpm, None) for rpm, dist in cfg.grid.points()]
    loop = cfg.coupled_loop().dem_point()
    largest = class_counts(cfg.dem.max_particles, loop.sizes.number_fractions)
    runs += [("validation.rpm (a coupled loop's DEM call)", loop, rpm, largest) for rpm in cfg.validation.rpm]
    for where, point, rpm, counts in runs:
        try:
            problems += [f"{where}: {p}" for p in limit_problems(plan_point(point, rpm, counts=counts), limits)]
        except ConfigError as exc:
            problems.append(f"{where}: {exc}")
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
