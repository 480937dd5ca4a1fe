"""The plan of one DEM run: particle numbers, time step, phases and snapshot intervals.

`plan_bed` turns the settings of an operating point (`pbmdem.config.DemPoint`) and its replicate
into a `BedPlan`, everything that does not depend on the impeller speed: particle numbers per class
(the bed's solid volume divided by the mean particle volume), the time step (a fraction of the
Rayleigh time of the smallest particle), the settling steps and the insertion seeds. One settled
bed serves every speed (docs/dem.md, "One settled bed for every speed"). `plan_point` adds the
speed: the spin-up and sampling steps and the contact-snapshot interval (a fraction of the Hertz
contact duration).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from pbmdem.config import ConfigError, DemPoint, SizeDistribution, point_id
from pbmdem.config.dem import DemLimits

# Hertz contact duration t_c = 2.87 (m*^2 / (R* E*^2 v))^(1/5) (Johnson 1985); contact snapshots
# are taken every t_c / SNAPSHOTS_PER_CONTACT, t_c of a head-on contact between two of the smallest
# particles at the impeller tip speed (the shortest contact of a run). One snapshot per contact
# time: over the 36 runs of the default grid, snapshots every t_c instead of t_c / 2 changed the
# encounters by -0.1 to -0.3 % (the raw new contacts, a diagnostic, by -0.6 to -1.5 %), and every
# run reports the change for twice its own interval (`encounter_change_when_interval_doubled`).
SNAPSHOTS_PER_CONTACT = 1
#: replicate r runs with insertion seeds derived from dem.seed + r x this prime
REPLICATE_SEED_STRIDE = 7919
#: impact speed (m/s) below which the contact time is not evaluated (an impeller at rest)
MIN_CONTACT_SPEED = 0.1


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

    @property
    def bed_id(self) -> str:
        """`<distribution>_rep<k>`: the bed's name in paths and decks."""
        return f"{self.distribution}_rep{self.replicate}"

    def to_dict(self) -> dict:
        return asdict(self)


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
        return asdict(self) | {"sampling_time": self.sampling_time}


def class_counts(n_particles: int, fractions) -> list[int]:
    """Expected numbers per class for `n_particles` (largest-remainder rounding)."""
    raw = np.asarray(fractions, float) * n_particles
    counts = np.floor(raw).astype(int)
    counts[np.argsort(-(raw - counts))[: n_particles - counts.sum()]] += 1
    return counts.tolist()


def bed_particle_count(bed_solid_volume: float, sizes: SizeDistribution) -> int:
    """Particles that hold the bed's solid volume with this size distribution."""
    return int(round(bed_solid_volume / sizes.mean_particle_volume))


def plan_bed(point: DemPoint, *, replicate: int = 0, counts: list[int] | None = None) -> BedPlan:
    """Plan the settled bed of `point`: particles, time step, settling and seeds. `replicate`
    selects the insertion seeds (replicates of one point differ only by them). `counts`
    (particles per class) replaces the count derived from the bed's solid volume: the coupled
    PBM-DEM loop hands its own sample this way."""
    sizes, mat, dem, granulator = point.sizes, point.material, point.dem, point.granulator
    where = f"distribution {point.distribution}"
    if counts is None:
        n_particles = bed_particle_count(granulator.bed_solid_volume, sizes)
    else:
        n_particles = int(sum(counts))
    if n_particles > dem.max_particles:
        raise ConfigError(f"{where} needs {n_particles} particles, more than dem.max_particles = {dem.max_particles}")
    if n_particles < 2:
        raise ConfigError(f"{where}: the bed holds {n_particles} particles; raise dem.bed_height")
    counts = class_counts(n_particles, sizes.number_fractions) if counts is None else [int(c) for c in counts]
    t_r = rayleigh_time(0.5 * min(sizes.diameters), mat.density, mat.youngs_modulus, mat.poisson_ratio)
    dt = dem.timestep_fraction * t_r
    return BedPlan(
        distribution=point.distribution,
        diameters=list(sizes.diameters),
        number_fractions=list(sizes.number_fractions),
        counts=counts,
        n_particles=int(sum(counts)),
        timestep=dt,
        rayleigh_time=t_r,
        settle_steps=_steps(dem.settle_time, dt),
        vtk_every=_steps(dem.vtk_interval, dt),
        replicate=int(replicate),
        seed=dem.seed + REPLICATE_SEED_STRIDE * int(replicate),
    )


def _steps(seconds: float, dt: float) -> int:
    return max(1, int(math.ceil(seconds / dt)))


def plan_point(point: DemPoint, rpm: float, *, replicate: int = 0, counts: list[int] | None = None) -> DemPlan:
    """Plan one run of `point` at `rpm`: its bed (`plan_bed`, same `replicate` and `counts`), then
    the spin-up and the sampling window at this speed."""
    rpm = float(rpm)  # checked where it entered (the config's Rpm type, or check_rpm on a command line)
    pid = point_id(rpm, point.distribution)
    try:
        bed = plan_bed(point, replicate=replicate, counts=counts)
    except ConfigError as exc:
        raise ConfigError(str(exc).replace(f"distribution {point.distribution}", f"operating point {pid}", 1)) from None
    mat, dem, granulator = point.material, point.dem, point.granulator
    dt = bed.timestep
    tip_speed = float(granulator.tip_speed(rpm))
    t_c = hertz_contact_time(
        0.5 * min(bed.diameters), mat.density, mat.youngs_modulus, mat.poisson_ratio, max(tip_speed, MIN_CONTACT_SPEED)
    )
    interval = dem.collision_interval
    if interval == "auto":
        interval = max(1, int(t_c / (SNAPSHOTS_PER_CONTACT * dt)))
    position_interval = dem.position_every * interval
    sampling_steps = int(math.ceil(_steps(dem.phase_time("sampling", rpm), dt) / position_interval) * position_interval)
    spinup_steps = _steps(dem.phase_time("spinup", rpm), dt)
    history_steps = int(math.ceil(_steps(dem.history_time, dt) / position_interval) * position_interval)
    if history_steps >= spinup_steps:
        raise ConfigError(
            f"dem.history_time = {dem.history_time} s: the position history before the sampling "
            f"window must be shorter than the spin-up ({spinup_steps * dt:.4g} s at {rpm:g} rpm)"
        )
    return DemPlan(
        **{f: getattr(bed, f) for f in BedPlan.__dataclass_fields__},
        point_id=pid,
        rpm=float(rpm),
        contact_time=t_c,
        collision_interval=int(interval),
        spinup_steps=spinup_steps,
        sampling_steps=sampling_steps,
        tip_speed=tip_speed,
        history_steps=history_steps,
        position_interval=int(position_interval),
        encounter_gap_fraction=dem.encounter_gap_fraction,
        omega=float(granulator.angular_speed(rpm)),
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
    problems = limit_problems(plan, limits)
    if problems:
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
