"""Feed override and feed hold: how fast the path being followed advances (LinuxCNC's feed).

The path's time is scaled by ``rate`` (0…1): each tick the move's phase advances
``rate`` rows, the desired position is interpolated between rows, and the desired
velocity (and with it the feed-forward) is ``rate`` times the path's. So position
and velocity stay continuous whatever the override. ``rate`` follows its target
(the override, or 0 while paused) no faster than the joints allow: along the path
the acceleration ``rate′·v`` stays within half of each joint's ``max_accel`` (the
other half is the path's own), so a pause decelerates along the path to a stop.

Reduced speed (``control/rt/speed_cap.py``): the rate is also capped, each tick, at the
fraction of the path's velocity the reduced limits allow at the current phase. A move
started in reduced speed is clamped to the cap from its first tick (the path starts at rest,
and the cap moves continuously along it, so the desired velocity stays continuous); a move
that is switched to reduced speed on its way decelerates to the cap as a pause does, then is
clamped to it.

Inputs: the operator's override and pause, the path's velocity per joint at the
current phase. Outputs: ``rate``; ``held_since``, since when the move has been held (a
pause, or the override at 0: the controller ends a move held longer than ``max_pause_s``);
and what the run records (``changes``: the override against the move's time; ``pauses``:
when and how long it was held).

What the run records grows with the move's time, not with how often the operator acts (a
slider dragged for ten minutes, a hold key hammered): a ``Timeline`` keeps its entries at
least ``spacing`` apart, and doubles the spacing whenever it holds ``MAX_ENTRIES``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hw.machine import Machine

SPACING_S = 0.05  # the feed timeline's resolution: changes closer than this are one
MAX_ENTRIES = 1_000  # a move's changes (or holds) kept at most; past it the spacing doubles


@dataclass
class Timeline:
    """One of a move's feed timelines, bounded: ``(t s, override)`` changes, or ``(t s,
    length s)`` holds when ``spans``. A change within ``spacing`` of the last one kept
    replaces that one's value (the override it came to, at the time it began); a hold that
    starts within ``spacing`` of the last one's end extends it. When ``entries`` reach
    ``MAX_ENTRIES`` the spacing doubles and they are thinned to it, so the whole move stays
    told, true to within the spacing, and ends on the override as last set."""

    entries: list[tuple[float, float]] = field(default_factory=list)
    spans: bool = False
    spacing: float = SPACING_S

    def add(self, t: float, value: float) -> None:
        self._coalesce(self.entries, (t, value))
        while len(self.entries) >= MAX_ENTRIES:
            self.spacing *= 2
            kept: list[tuple[float, float]] = []
            for entry in self.entries:
                self._coalesce(kept, entry)
            self.entries[:] = kept

    def _coalesce(self, entries: list[tuple[float, float]], new: tuple[float, float]) -> None:
        if entries:
            t, value = entries[-1]
            if new[0] - (t + value if self.spans else t) < self.spacing:
                entries[-1] = (t, round(new[0] + new[1] - t, 4) if self.spans else new[1])
                return
        entries.append(new)


class FeedRate:
    def __init__(self, machine: Machine, dt: float) -> None:
        self.dt = dt
        self.half_accel = [0.5 * j.max_accel for j in machine.joints]
        self.override = 1.0
        self.paused = False
        self.rate = 1.0
        self.changes = Timeline()  # the move's: (move time s, override) as set
        self.pauses = Timeline(spans=True)  # the move's: (move time s, length s)
        self.paused_at = 0.0
        self.stopped_at: float | None = None  # move time the override went to 0; None: it is not
        self.reduced = False  # reduced speed: the rate is capped (``advance``'s ``cap``)
        self.capping = False  # the rate has come down to the cap and is clamped to it

    @property
    def target(self) -> float:
        return 0.0 if self.paused else self.override

    @property
    def steady(self) -> bool:
        """Following the path at full speed, and meant to: the loop's fast path (an override
        or a hold set mid-move leaves it, to ramp the rate down; reduced speed never takes it)."""
        return self.rate == 1.0 and self.target == 1.0 and not self.reduced

    @property
    def held_since(self) -> float | None:
        """The move time since which the move has been held, by a pause or the override at 0
        (whichever came first), or None while it is not."""
        if self.paused and self.stopped_at is not None:
            return min(self.paused_at, self.stopped_at)
        return self.paused_at if self.paused else self.stopped_at

    @property
    def held_by(self) -> str:
        """What holds the move (``held_since``): the feed hold or the override at 0."""
        if self.paused and (self.stopped_at is None or self.paused_at <= self.stopped_at):
            return "feed hold"
        return "feed override 0 %"

    def start_move(self, changes: list[tuple[float, float]],
                   pauses: list[tuple[float, float]]) -> None:
        """A new move, recording into its ``changes`` and ``pauses``: not paused; it starts at
        the override (from rest, as every path), held from its start if that is 0."""
        self.paused = False
        self.rate = self.override
        self.capping = self.reduced
        self.changes, self.pauses = Timeline(changes), Timeline(pauses, spans=True)
        self.stopped_at = 0.0 if self.override == 0.0 else None
        if self.override != 1.0:
            self.changes.add(0.0, self.override)

    def end_move(self, t: float) -> None:
        """The move ended at its time ``t``: a hold still on is recorded up to then."""
        self.resume(t)
        self.changes, self.pauses = Timeline(), Timeline(spans=True)

    def set_override(self, value: float, t: float) -> None:
        if value != 0.0:
            self.stopped_at = None
        elif self.stopped_at is None:
            self.stopped_at = t
        self.override = value
        self.changes.add(round(t, 4), value)

    def pause(self, t: float) -> None:
        if not self.paused:
            self.paused, self.paused_at = True, t

    def resume(self, t: float) -> None:
        if self.paused:
            self.paused = False
            self.pauses.add(round(self.paused_at, 4), round(t - self.paused_at, 4))

    def reduce(self, on: bool) -> None:
        """Reduced speed on or off; switched on during a move, the rate comes down to the cap
        at the joints' acceleration before it is clamped to it."""
        self.reduced = on
        self.capping = False

    def advance(self, path_velocity: list[float], cap: float = 1.0) -> None:
        """Move ``rate`` toward its target, as fast as the path's velocity ``(J,)`` (units/s
        at rate 1, at the current phase) lets the joints decelerate or accelerate; in reduced
        speed never above ``cap`` once it has come down to it."""
        target, rate = self.target, self.rate
        if self.reduced:
            target = min(target, cap)
            if self.capping and rate > cap:
                rate = self.rate = cap
            elif rate <= cap:
                self.capping = True
        if rate == target:
            return
        step = 1.0
        for a, v in zip(self.half_accel, path_velocity, strict=True):
            if v != 0.0:
                step = min(step, a / abs(v) * self.dt)
        self.rate = min(rate + step, target) if target > rate else max(rate - step, target)
