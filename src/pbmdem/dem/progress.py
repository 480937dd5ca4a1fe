"""Progress of a running LIGGGHTS job, read from its own thermo output.

LIGGGHTS writes a thermo line (`thermo_style custom step atoms ...`, flushed after each line by
`thermo_modify flush yes` in the deck) every `thermo_every` steps into `log.liggghts`.
`ThermoProgress` follows that file while the engine runs (`liggghts.run` calls `update()` about
once a second) and reports the phase (settling, spin-up, sampling), the step of the total, the
particles inserted so far, the elapsed and the estimated remaining wall time:

* as a log line (logger `pbmdem.progress`) at least every `log_every` seconds of wall time and
  at each phase change, so that Snakemake job logs and cluster logs show a run moving;
* as a tqdm bar on a terminal when `bar=True` (the `pbmdem dem` CLI on a TTY).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from tqdm import tqdm

log = logging.getLogger(__name__)

LOG_EVERY_S = 10.0
# a thermo line every this many particle-steps: ~0.3-1 s of wall time at the 2-4 M particle-steps/s
# measured here, so that progress moves between the 10 s log lines even for large beds
THERMO_PARTICLE_STEPS = 1_000_000


def thermo_interval(n_particles: int, vtk_every: int) -> int:
    """Steps between thermo lines: the VTK interval, or fewer for a bed large enough that a VTK
    interval would take more than about a second of wall time."""
    return max(1, min(int(vtk_every), THERMO_PARTICLE_STEPS // max(int(n_particles), 1)))


def _eta(seconds: float) -> str:
    if seconds != seconds or seconds == float("inf"):
        return "?"
    seconds = int(round(seconds))
    return (
        f"{seconds // 3600:d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"
        if seconds >= 3600
        else f"{seconds // 60:d}:{seconds % 60:02d}"
    )


class ThermoProgress:
    """Follow `log_path` (a LIGGGHTS log being written) for a run of `phases`, a list of
    (name, steps) in the order the deck runs them (steps accumulate across `run` commands);
    `first_step`: the step counter at the first phase's start (a run from a settled bed goes on
    counting from the bed's last step)."""

    def __init__(
        self,
        log_path: str | Path,
        phases: list[tuple[str, int]],
        *,
        label: str = "LIGGGHTS",
        bar: bool = False,
        log_every: float = LOG_EVERY_S,
        first_step: int = 0,
    ):
        self.path = Path(log_path)
        self.phases = [(str(n), int(s)) for n, s in phases]
        self.total = sum(s for _, s in self.phases)
        self.label = label
        self.log_every = float(log_every)
        self.first_step = int(first_step)
        self.step = 0
        self.atoms = 0
        self._offset = 0
        self._partial = b""
        self._header: list[str] | None = None
        self._start = time.monotonic()
        self._last_log = self._start
        self._last_phase: str | None = None
        self._bar = tqdm(total=self.total, unit="step", desc=label, dynamic_ncols=True, leave=True) if bar else None

    # -------------------------------------------------------------- reading
    def _read_new_lines(self) -> list[str]:
        try:
            with open(self.path, "rb") as fh:
                fh.seek(self._offset)
                chunk = fh.read()
        except FileNotFoundError:
            return []
        self._offset += len(chunk)
        data = self._partial + chunk
        lines = data.split(b"\n")
        self._partial = lines.pop()  # an unfinished last line waits for the next read
        return [line.decode(errors="replace") for line in lines]

    def _parse(self, lines: list[str]) -> None:
        for line in lines:
            words = line.split()
            if words[:1] == ["Step"]:
                self._header = [w.lower() for w in words]
                continue
            if self._header is None or len(words) != len(self._header):
                if line.startswith("Loop time"):
                    self._header = None
                continue
            try:
                step = int(float(words[0]))
            except ValueError:
                continue
            self.step = max(self.step, step - self.first_step)
            if "atoms" in self._header:
                try:
                    self.atoms = int(float(words[self._header.index("atoms")]))
                except ValueError:
                    pass

    # -------------------------------------------------------------- state
    def phase(self) -> str:
        edge = 0
        for name, steps in self.phases:
            edge += steps
            if self.step < edge:
                return name
        return self.phases[-1][0] if self.phases else "?"

    def elapsed(self) -> float:
        return time.monotonic() - self._start

    def remaining(self) -> float:
        if self.step <= 0:
            return float("nan")
        return self.elapsed() * (self.total - self.step) / self.step

    def status(self) -> str:
        return (
            f"{self.label}: {self.phase()}, step {self.step} of {self.total} "
            f"({100.0 * self.step / max(self.total, 1):.0f} %), {self.atoms} particles, "
            f"elapsed {_eta(self.elapsed())}, remaining ~{_eta(self.remaining())}"
        )

    # -------------------------------------------------------------- reporting
    def update(self) -> None:
        """Read what LIGGGHTS wrote since the last call; log and move the bar as due."""
        self._parse(self._read_new_lines())
        now = time.monotonic()
        phase = self.phase()
        if self._bar is not None:
            self._bar.set_postfix_str(f"{phase}, {self.atoms} particles", refresh=False)
            self._bar.update(self.step - self._bar.n)
        if phase != self._last_phase or now - self._last_log >= self.log_every:
            self._last_phase, self._last_log = phase, now
            log.info("%s", self.status())

    def close(self) -> None:
        self.update()
        if self._bar is not None:
            self._bar.close()
        log.info(
            "%s: engine stopped at step %d of %d after %s", self.label, self.step, self.total, _eta(self.elapsed())
        )
