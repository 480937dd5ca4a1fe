"""Progress of a running LIGGGHTS job from the thermo lines of its log: log lines (at each phase
change and every `log_every` s) and a tqdm bar on a terminal (docs/dem.md, the paragraph "Progress")."""

from __future__ import annotations

import logging
import time
from pathlib import Path

from tqdm import tqdm

from .engine import thermo_columns

log = logging.getLogger(__name__)

LOG_EVERY_S = 10.0


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
        self._start = time.monotonic()
        self._last_log = self._start
        self._last_phase: str | None = None
        self._bar = tqdm(total=self.total, unit="step", desc=label, dynamic_ncols=True, leave=True) if bar else None

    def _read(self) -> None:
        """The last step (counted from `first_step`) and particles the log shows so far."""
        try:
            text = self.path.read_text(errors="replace")
        except FileNotFoundError:
            return
        columns = thermo_columns(text[: text.rfind("\n") + 1])  # an unfinished last line waits
        if columns.get("Step"):
            self.step = max(self.step, int(max(columns["Step"])) - self.first_step)
        if columns.get("Atoms"):
            self.atoms = int(columns["Atoms"][-1])

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
        self._read()
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
