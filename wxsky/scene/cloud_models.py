"""Cloud models as data: Wang's artist boxes per cloud type, and the choice of a layer's model.

Each model (cumulus humilis, stratus, ...) says how a block's cells hold clouds and lists boxes,
each placed relative to the cloud and filled with sprites, as the artists of "Let There Be
Clouds!" built them in 3DS Max. Units inside a model: box x and y in cloud widths from the
cloud's axis, z in cloud heights above its base, sprite sizes in cloud widths; a cloud's width
is a share of its cell and its height a share of the layer thickness. The files that hold the
models, `wxsky/scene/clouds/*.toml`, are read by `cloud_model_files`; the generator takes these
dataclasses and never reads a file.

A layer's model is the one of its type with the largest `min_thickness_m` not above the layer's
thickness, so cumulus is humilis below 1000 m, mediocris to 2500 m and congestus above
(towering cumulus; METAR TCU layers are 4000 m thick). Within `SUBTYPE_BLEND_FRAC` of a
boundary both models are drawn, the outgoing one's clouds dissipating as the incoming one's
form (`blend_for_layer`), so a layer that deepens through a boundary does not swap every cloud
at once.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

from wxsky.weather.state import CloudType

SUBTYPE_BLEND_FRAC = 0.1  # half-width of the cross-fade band, share of the boundary thickness


@dataclass(frozen=True)
class BoxTemplate:
    """One artist box: where it sits in the cloud, how big it is, what sprites fill it."""

    centre: tuple[float, float, float]  # x, y in cloud widths from the axis; z in cloud heights
    width: tuple[float, float]  # x extent in cloud widths, drawn per cloud in [lo, hi]
    depth: tuple[float, float]  # y extent in cloud widths
    height: tuple[float, float]  # z extent in cloud heights
    sprites: int  # random sprite centres in the box before culling; 0 with a grid
    grid: tuple[int, int]  # (nx, ny) sprites on a lattice over the box; (0, 0) for random
    grid_jitter: float  # lattice jitter, share of the lattice spacing
    sprite_size: tuple[float, float]  # sprite edge in cloud widths
    rotation_deg: tuple[float, float]
    textures: tuple[int, ...]  # sheet slots of the box's texture categories
    shading_group: int  # 0: by octant around the cloud's centre; n: boxes numbered n shade as one
    # Hangs under the layer's base (scud, fractus): its sprites are not kept inside the layer
    # and, under a slab, are shaded as a small cloud in the deck's light, not as the deck.
    under_base: bool = False

    @property
    def count(self) -> int:
        return self.sprites or self.grid[0] * self.grid[1]


@dataclass(frozen=True)
class CloudModel:
    name: str  # the file's stem
    type: CloudType
    min_thickness_m: float  # serves layers at least this thick (cumulus subtypes)
    cell_m: float  # the block is cut into cells of about this size, one cloud each
    width_frac: tuple[float, float]  # cloud width as a share of the cell
    height_frac: tuple[float, float]  # cloud height as a share of the layer thickness
    jitter_frac: float  # cloud centre offset from its cell's centre, share of the cell
    cull_frac: float  # Wang's cull distance over the sprite size: 1/3 typical, 1/5 dense
    opacity: float
    darkness: float  # 0..1, how grey the base is
    flat: bool  # horizontal quads (cirrus family) instead of camera-facing sprites
    slab: bool  # stratiform: shaded as a plane-parallel slab (Bouthors), not particle by particle
    grows_up: bool  # heaped: the core is the cloud's low middle, so it forms from the base up
    formation_spread_oktas: float  # cover change over which one cloud forms
    # Every sprite of the cloud is cut at the layer's base: the flat condensation level.
    flat_base: bool
    boxes: tuple[BoxTemplate, ...]


@dataclass(frozen=True)
class CloudModels:
    """Every model, by type, thinnest first."""

    by_type: dict[CloudType, tuple[CloudModel, ...]]
    source: str  # the directory they came from

    def for_layer(self, cloud_type: CloudType, thickness_m: float) -> CloudModel:
        models = self.by_type.get(cloud_type) or self.by_type[CloudType.CUMULUS]
        chosen = models[0]
        for model in models:
            if model.min_thickness_m <= thickness_m:
                chosen = model
        return chosen

    def blend_for_layer(
        self, cloud_type: CloudType, thickness_m: float
    ) -> tuple[tuple[CloudModel, float], ...]:
        """The layer's model with weight 1, or near a subtype boundary the two models on
        either side with weights that sum to 1 and slide smoothly across the band."""
        models = self.by_type.get(cloud_type) or self.by_type[CloudType.CUMULUS]
        for below, above in itertools.pairwise(models):
            edge = above.min_thickness_m
            half = SUBTYPE_BLEND_FRAC * edge
            if edge - half < thickness_m < edge + half:
                t = (thickness_m - (edge - half)) / (2.0 * half)
                share = t * t * (3.0 - 2.0 * t)
                return ((below, 1.0 - share), (above, share))
        return ((self.for_layer(cloud_type, thickness_m), 1.0),)
