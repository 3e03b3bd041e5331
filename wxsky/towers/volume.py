"""One convective cell's cloud volume through time: the automaton run from the cell's birth, a
step every STEP_S of sim time, inside ellipsoids that stack up as the tower matures, and the
density at any moment interpolated between the two steps around it."""

from __future__ import annotations

import math
from dataclasses import dataclass

from wxsky.towers.automaton import (
    ANVIL_COLUMN_SHARE,
    BUBBLES,
    F32,
    Cells,
    Ellipsoid,
    Odds,
    cell_rng,
    density_between,
    ellipsoid_weight,
    flat_based,
    smoothed,
    step,
    tower_ellipsoids,
    tower_odds,
)

# How far up from the floor a tower stands straight on its flat base (`flat_based`): the
# bubbles' rounded floor spans about five rows of a congestus's 69 m (area at density 0.3,
# row by row up from the floor: 3 %, 38 %, 66 %, 79 %, 88 %, 95 % of the widest row there).
FLAT_BASE_M = 400.0
STEP_S = 10.0  # sim seconds per automaton step: a 30-minute tower is 180 steps
GRID = 64  # cells along each axis by default (128 is the option for big cells)
GRIDS = (64, 128)
# The grid's box around the tower: the ellipsoids fill about 0.6 of its width (radii 0.3 of
# it) and 0.9 of its height, so a tower as wide as its cloud's base and as tall as its layer
# has a box this much larger.
BOX_WIDTH_PER_TOWER = 1.0 / 0.6
BOX_HEIGHT_PER_TOWER = 1.0 / 0.9
# Extinction per metre at density 1: a congestus's cells (about 60 m) take the slice light's
# 0.35 a cell (towers.lighting.EXTINCTION_PER_CELL).
EXTINCTION_PER_M = 0.35 / 60.0
_TURRET_STREAM = 1  # the cell's stream for its shape (turret offsets), apart from the draws


@dataclass(frozen=True)
class TowerSpec:
    """What makes one tower: whose it is (seed, block, cell), its grid and box, its birth, how
    fast it matures, and the odds of the automaton (Dobashi's p_hum, p_act, and p_ext inside
    and outside its ellipsoids). `supplied_s`: sim seconds of the cell's life during which
    vapour is supplied; after it (the air clearing) nothing is supplied, and cloud vanishes
    with p_ext_clearing at the ellipsoids' centres, rising to p_ext_outside at their
    surfaces: edges first."""

    weather_seed: int
    block: tuple[int, int]
    cell: int
    grid: int = GRID
    # Where and how big (the box the grid fills), in the layer's drifting frame, z MSL; and
    # when it was born, in sim seconds from the moment its weather was set (negative: it was
    # already growing then).
    axis_m: tuple[float, float] = (0.0, 0.0)
    base_m: float = 0.0
    width_m: float = 2000.0
    height_m: float = 3000.0
    born_s: float = 0.0
    mature_s: float = 1800.0
    p_hum: float = 0.1
    p_act: float = 0.01
    p_ext_inside: float = 0.001
    p_ext_outside: float = 0.3
    p_ext_clearing: float = 0.03
    supplied_s: float = math.inf
    anvil: bool = False  # a cumulonimbus: a narrower column in a wider box, an anvil on top

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.grid, self.grid, self.grid)

    @property
    def box_size_m(self) -> tuple[float, float, float]:
        """East, north and up extent of the box the grid fills."""
        across = self.width_m * BOX_WIDTH_PER_TOWER / (ANVIL_COLUMN_SHARE if self.anvil else 1.0)
        return (across, across, self.height_m * BOX_HEIGHT_PER_TOWER)

    @property
    def box_centre_m(self) -> tuple[float, float, float]:
        """The box's middle, in the layer's drifting frame (z MSL): over the axis, its floor
        at the base."""
        return (self.axis_m[0], self.axis_m[1], self.base_m + 0.5 * self.box_size_m[2])

    @property
    def cell_m(self) -> float:
        """The mean edge of a grid cell."""
        return sum(self.box_size_m) / (3.0 * self.grid)

    @property
    def extinction_per_cell(self) -> float:
        """Light's extinction through a cell of density 1: cloud's extinction per metre
        (EXTINCTION_PER_M) over the cell's size, so a cumulonimbus's bigger cells (its box
        is kilometres wider and taller) shadow more than a congestus's do."""
        return EXTINCTION_PER_M * self.cell_m

    def age_s(self, since_set_s: float) -> float:
        """The tower's age `since_set_s` sim seconds after its weather was set (negative: not
        born yet)."""
        return since_set_s - self.born_s


class TowerVolume:
    """The automaton of one tower, stepped forward on demand. Asking for an earlier moment
    than the last one asked for starts again from the cell's birth, so any moment's volume is
    the same however it was reached."""

    def __init__(self, spec: TowerSpec) -> None:
        if spec.grid not in GRIDS:
            raise ValueError(f"tower grid must be one of {GRIDS}, got {spec.grid}")
        self.spec = spec
        shape_rng = cell_rng(spec.weather_seed, spec.block, spec.cell, _TURRET_STREAM)
        self._turrets = shape_rng.uniform(-1.0, 1.0, (BUBBLES, 4)).astype("float32")
        self._restart()

    def _restart(self) -> None:
        self._rng = cell_rng(self.spec.weather_seed, self.spec.block, self.spec.cell)
        self._cells = Cells.empty(self.spec.shape)
        self._previous = self._cells

    def ellipsoids_at(self, step_n: int) -> tuple[Ellipsoid, ...]:
        """The tower's ellipsoids at step `step_n`, as far as it has matured then."""
        s = self.spec
        age_s = step_n * STEP_S
        maturity = min(1.0, age_s / s.mature_s) if s.mature_s > 0.0 else 1.0
        return tower_ellipsoids(s.shape, maturity, self._turrets, s.anvil)

    def odds_at(self, step_n: int) -> Odds:
        """The odds of step `step_n`: the ellipsoids of the tower's maturity then, and no
        supply once `supplied_s` has passed."""
        s = self.spec
        weight = ellipsoid_weight(s.shape, self.ellipsoids_at(step_n))
        supplied = step_n * STEP_S < s.supplied_s
        return tower_odds(
            weight,
            hum=s.p_hum if supplied else 0.0,
            act=s.p_act if supplied else 0.0,
            ext_inside=s.p_ext_inside if supplied else s.p_ext_clearing,
            ext_outside=s.p_ext_outside,
        )

    def cells_at(self, step_n: int) -> Cells:
        """The automaton's state after `step_n` steps."""
        if step_n < 0:
            raise ValueError(f"step {step_n} is before the tower's birth")
        if step_n < self._previous.step:
            self._restart()
        if step_n == self._previous.step:
            return self._previous
        while self._cells.step < step_n:
            self._previous = self._cells
            self._cells = step(self._cells, self.odds_at(self._cells.step), self._rng)
        return self._cells

    @property
    def flat_base_rows(self) -> int:
        """The rows over the floor that stand straight on the base (`flat_based`)."""
        row_m = self.spec.box_size_m[2] / self.spec.grid
        return max(1, round(FLAT_BASE_M / row_m))

    def density_of_step(self, step_n: int) -> F32:
        """(grid, grid, grid) smoothed density after `step_n` steps, z up, flat based."""
        return flat_based(smoothed(self.cells_at(step_n).cld), self.flat_base_rows)

    def density_at(self, age_s: float) -> F32:
        """(grid, grid, grid) density 0..1, z up, `age_s` sim seconds after the cell's birth:
        between the two automaton states around that moment."""
        if not math.isfinite(age_s) or age_s < 0.0:
            raise ValueError(f"tower age {age_s} s is not a time since its birth")
        n = int(age_s // STEP_S)
        frac = age_s / STEP_S - n
        after = self.cells_at(n + 1)
        before = self._previous if self._previous.step == n else self.cells_at(n)
        return flat_based(density_between(before.cld, after.cld, frac), self.flat_base_rows)
