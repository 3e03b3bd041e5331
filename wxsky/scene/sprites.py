"""The sprite batch: every cloud sprite the scene hands on, as parallel arrays.

Split out of `clouds.py` (which re-exports it) so the generator, formation and the layout
stages share one type without importing each other.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
I32 = npt.NDArray[np.int32]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]


def _no_flags() -> B:
    return np.zeros(0, np.bool_)


def _no_slabs() -> F32:
    return np.zeros((0, 2), np.float32)


def _no_bases() -> F32:
    return np.zeros(0, np.float32)


def _no_drift() -> F32:
    return np.zeros((0, 2), np.float32)


@dataclass(frozen=True)
class SpriteBatch:
    """N cloud sprites as parallel arrays."""

    centre_m: F64  # (N, 3) ENU
    size_m: F32  # (N,) edge length of the square sprite
    rotation_rad: F32  # (N,) in-plane turn: on screen, or about the vertical for flat sprites
    texture: I32  # (N,) slot on the texture sheet
    height_frac: F32  # (N,) 0 at the cloud's base .. 1 at its top: picks the colour level
    light_dir: F32  # (N, 3) unit vector from the cloud centre to the sprite's shading group
    opacity: F32  # (N,) 0..1: formation/dissipation and type transparency
    darkness: F32  # (N,) 0..1: how grey the cloud type's base is (stratus, Cb)
    cloud_id: I64  # (N,) the sprite's cloud, the same in every frame and process
    # (N,) 0 core .. 1 edge: horizontal distance from the cloud's axis over its radius, or for
    # heaped clouds (cumulus, Cb) the larger of that and the height over the cloud's height.
    core_frac: F32
    # (N,) True: a horizontal quad in the layer (cirrus family), edge size_m, its texture's
    # u axis turned rotation_rad from east toward north; False: a camera-facing sprite.
    # Batches built without it (older callers) are all camera-facing.
    flat: B = field(default_factory=_no_flags)
    # (N, 2) base and top MSL of the stratiform layer whose slab shades the sprite (Bouthors),
    # NaN for sprites shaded as particles. Batches built without it have no slab sprites.
    slab_m: F32 = field(default_factory=_no_slabs)
    # (N,) MSL of the flat base the sprite is cut at (a heaped cloud's condensation level: no
    # texel of it shows below), NaN for none. Batches built without it cut nothing.
    base_m: F32 = field(default_factory=_no_bases)
    # (N, 2) east and north the wind has moved the sprite's layer (gather.Drift): what moves
    # with a deck, such as its base's relief, is fixed to centre - drift. Zero where unset.
    drift_m: F32 = field(default_factory=_no_drift)

    def __post_init__(self) -> None:
        n = int(self.size_m.shape[0])
        if self.flat.shape[0] != n:
            if self.flat.shape[0] != 0:
                raise ValueError(f"flat has {self.flat.shape[0]} entries for {n} sprites")
            object.__setattr__(self, "flat", np.zeros(n, np.bool_))
        if self.slab_m.shape[0] != n:
            if self.slab_m.shape[0] != 0:
                raise ValueError(f"slab_m has {self.slab_m.shape[0]} entries for {n} sprites")
            object.__setattr__(self, "slab_m", np.full((n, 2), np.nan, np.float32))
        if self.base_m.shape[0] != n:
            if self.base_m.shape[0] != 0:
                raise ValueError(f"base_m has {self.base_m.shape[0]} entries for {n} sprites")
            object.__setattr__(self, "base_m", np.full(n, np.nan, np.float32))
        if self.drift_m.shape[0] != n:
            if self.drift_m.shape[0] != 0:
                raise ValueError(f"drift_m has {self.drift_m.shape[0]} entries for {n} sprites")
            object.__setattr__(self, "drift_m", np.zeros((n, 2), np.float32))

    @functools.cached_property
    def slab(self) -> B:
        """(N,) True for sprites shaded as part of a stratiform slab (read-only: a frame asks
        a batch for it several times)."""
        out: B = ~np.isnan(self.slab_m[:, 0])
        out.flags.writeable = False
        return out

    def __len__(self) -> int:
        return int(self.size_m.shape[0])

    def take(self, index: npt.NDArray[np.intp] | B) -> SpriteBatch:
        """The sprites at `index` (indices, or a mask), in its order. Each field is cut when
        first read: a frame's drawn sprites are read for a few of their twelve fields (the
        renderer's, the shading's), and cutting every field was a sixth of the shading."""
        # ndarray.take along the rows: a fifth of the time of indexing (N, 3) arrays with an
        # index or a mask, for the same copy; a mask becomes its indices once for all fields.
        rows = np.flatnonzero(index) if index.dtype == np.bool_ else index
        own = self.__dict__
        out = object.__new__(SpriteBatch)
        fields = out.__dict__
        source = own.get("_taken")
        if source is None:
            fields["_taken"] = (self, rows)
        else:  # fields this batch has not cut yet come from its source at once
            fields["_taken"] = (source[0], source[1].take(rows))
            for name in _FIELD_NAMES:
                if name in own:
                    fields[name] = own[name].take(rows, axis=0)
        kept = own.get("slab")
        if kept is not None:  # this batch's kept slab mask, cut alike (cheaper than anew)
            taken = kept.take(rows)
            taken.flags.writeable = False
            fields["slab"] = taken
        return out

    if not TYPE_CHECKING:  # so that the type checker still catches a misspelt field

        def __getattr__(self, name):
            # Reached only for what __dict__ lacks: a field of a `take` not read yet.
            source = self.__dict__.get("_taken")
            if source is None or name not in _FIELD_NAMES:
                raise AttributeError(name)
            batch, rows = source
            value = getattr(batch, name).take(rows, axis=0)
            self.__dict__[name] = value
            return value

    def __getstate__(self) -> dict[str, object]:
        # Pickled (a ring built in the worker process) with every field, not its source.
        state = dict(self.__dict__)
        if state.pop("_taken", None) is not None:
            state.update((name, getattr(self, name)) for name in _FIELD_NAMES)
        return state

    def with_centres(self, centre_m: F64, drift_m: F32 | None = None) -> SpriteBatch:
        """These sprites at other centres ((N, 3), as many), and with `drift_m` ((N, 2)) the
        drift that moved them there: the other fields are this batch's own arrays, not
        checked again (a frame moves its near set by the drift this way;
        `dataclasses.replace` checking every field was 20 us of it)."""
        if centre_m.shape != self.centre_m.shape:
            raise ValueError(f"{centre_m.shape[0]} centres for {len(self)} sprites")
        out = object.__new__(SpriteBatch)
        out.__dict__.update(self.__dict__)
        out.__dict__["centre_m"] = centre_m
        if drift_m is not None:
            if drift_m.shape != (len(self), 2):
                raise ValueError(f"{drift_m.shape} drifts for {len(self)} sprites")
            out.__dict__["drift_m"] = drift_m
        return out

    def shifted(self, offset_m: tuple[float, float, float]) -> SpriteBatch:
        return dataclasses.replace(
            self,
            centre_m=self.centre_m + np.asarray(offset_m, dtype=np.float64),
            slab_m=(self.slab_m + np.float32(offset_m[2])).astype(np.float32),
            base_m=(self.base_m + np.float32(offset_m[2])).astype(np.float32),
            # Moved across with everything of its layer: the drift's way (layer_block).
            drift_m=(self.drift_m + np.asarray(offset_m[:2], np.float32)).astype(np.float32),
        )

    @staticmethod
    def empty() -> SpriteBatch:
        return SpriteBatch(
            centre_m=np.zeros((0, 3)),
            size_m=np.zeros(0, np.float32),
            rotation_rad=np.zeros(0, np.float32),
            texture=np.zeros(0, np.int32),
            height_frac=np.zeros(0, np.float32),
            light_dir=np.zeros((0, 3), np.float32),
            opacity=np.zeros(0, np.float32),
            darkness=np.zeros(0, np.float32),
            cloud_id=np.zeros(0, np.int64),
            core_frac=np.zeros(0, np.float32),
            flat=np.zeros(0, np.bool_),
            slab_m=np.zeros((0, 2), np.float32),
            base_m=np.zeros(0, np.float32),
            drift_m=np.zeros((0, 2), np.float32),
        )

    @staticmethod
    def concat(batches: list[SpriteBatch]) -> SpriteBatch:
        batches = [b for b in batches if len(b)]
        if not batches:
            return SpriteBatch.empty()
        if len(batches) == 1:
            return batches[0]
        return SpriteBatch(
            **{f.name: np.concatenate([getattr(b, f.name) for b in batches]) for f in _FIELDS}
        )


_FIELDS = dataclasses.fields(SpriteBatch)
_FIELD_NAMES = frozenset(f.name for f in _FIELDS)
