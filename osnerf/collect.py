"""The on-demand collector: a demand -> the views, masks and masked images worth sending.

A *demand* names objects of the scene with weights (``hydrant:2,tree:1``). A drone view is
sent only when at least one demanded object is *visible enough* in it: its visible
(occlusion-aware) area is at least ``min_visible_fraction`` of its silhouette and at least
``min_pixel_fraction`` of the image. Views that fail are never transmitted. What is sent of a
selected view is the masked image: the demanded objects over the known background colour.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common import InputError
from osnerf.scenes import SceneViews


@dataclass(frozen=True)
class Demand:
    """Objects a user wants, with weights normalised to sum to 1.

    Attributes:
        objects: object names, in the order given.
        weights: one weight per object (> 0), normalised to sum 1.
    """

    objects: tuple[str, ...]
    weights: tuple[float, ...]

    def __post_init__(self):
        if not self.objects:
            raise ValueError("demand must name at least one object")
        if len(self.weights) != len(self.objects):
            raise ValueError(
                f"demand has {len(self.objects)} objects but {len(self.weights)} weights"
            )
        if len(set(self.objects)) != len(self.objects):
            raise ValueError(f"demand names an object twice: {','.join(self.objects)}")
        if any(not np.isfinite(w) or w <= 0 for w in self.weights):
            raise ValueError(f"demand weights must be finite and > 0, got {self.weights}")
        s = float(sum(self.weights))
        object.__setattr__(self, "weights", tuple(float(w) / s for w in self.weights))

    @classmethod
    def parse(cls, text: str) -> Demand:
        """``"hydrant"``, ``"hydrant,tree"`` or ``"hydrant:2,tree:1"`` (weights default 1)."""
        objs, ws = [], []
        for item in str(text).split(","):
            item = item.strip()
            if not item:
                continue
            name, _, w = item.partition(":")
            try:
                weight = float(w) if w else 1.0
            except ValueError:
                raise ValueError(f"demand weight of {name!r} must be a number, got {w!r}") from None
            objs.append(name.strip())
            ws.append(weight)
        if not objs:
            raise ValueError(f"demand must be OBJECT[:WEIGHT][,OBJECT...], got {text!r}")
        return cls(tuple(objs), tuple(ws))

    def __str__(self) -> str:
        return ",".join(f"{o}:{w:.3g}" for o, w in zip(self.objects, self.weights))


@dataclass(frozen=True)
class CollectorConfig:
    """When a view is worth sending.

    Attributes:
        min_visible_fraction: visible area / silhouette area of a demanded object, in [0, 1].
        min_pixel_fraction: visible area / image area of a demanded object, in [0, 1].
    """

    min_visible_fraction: float = 0.8
    min_pixel_fraction: float = 0.01

    def __post_init__(self):
        for name in ("min_visible_fraction", "min_pixel_fraction"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {v!r}")


@dataclass
class Collection:
    """What the collector hands the encoder.

    Attributes:
        indices: [num_sent] int indices of the selected views in ``SceneViews``.
        images: [num_sent, height, width, 3] float32 masked images (objects over background).
        masks: [num_sent, height, width] float32 union of the demanded objects' masks.
        object_masks: [num_sent, num_objects, height, width] float32, one mask per
            demanded object (the encoder's feature routing input).
        candidates: indices of every view considered (the train split).
        reasons: view index -> why it was skipped (views not in ``indices``).
    """

    indices: np.ndarray
    images: np.ndarray
    masks: np.ndarray
    candidates: np.ndarray
    reasons: dict[int, str] = field(default_factory=dict)
    object_masks: np.ndarray | None = None

    def subset(self, keep: np.ndarray) -> Collection:
        """The selected views where ``keep`` [num_sent] bool is True."""
        om = None if self.object_masks is None else self.object_masks[keep]
        return Collection(
            self.indices[keep],
            self.images[keep],
            self.masks[keep],
            self.candidates,
            self.reasons,
            om,
        )

    @property
    def num_sent(self) -> int:
        return int(len(self.indices))


def visible_enough(
    views: SceneViews, demand: Demand, config: CollectorConfig, index: int
) -> tuple[bool, str]:
    """Whether view ``index`` shows a demanded object well enough, and why not."""
    why = []
    for obj in demand.objects:
        vf, pf = float(views.visible_fraction[obj][index]), float(views.pixel_fraction[obj][index])
        if vf >= config.min_visible_fraction and pf >= config.min_pixel_fraction:
            return True, ""
        why.append(f"{obj}: visible {vf:.2f} of silhouette, {pf:.3f} of image")
    return False, "; ".join(why)


def masked_images(images: np.ndarray, masks: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Composite: ``image * mask + background * (1 - mask)``.

    Args:
        images: [num_views, height, width, 3]; masks: [num_views, height, width] in [0, 1].
    Returns:
        [num_views, height, width, 3] float32.
    """
    m = masks[..., None]
    return (images * m + np.asarray(background, np.float32) * (1.0 - m)).astype(np.float32)


def collect(
    views: SceneViews, demand: Demand, config: CollectorConfig | None = None, split: str = "train"
) -> Collection:
    """Select the views of ``split`` worth sending for ``demand``.

    Raises:
        KeyError: a demanded object is not in the scene (lists the known ones).
        ValueError: no view shows any demanded object well enough.
    """
    config = config or CollectorConfig()
    for obj in demand.objects:
        if obj not in views.objects:
            raise KeyError(f"unknown object {obj!r}; known objects: {', '.join(views.objects)}")
    candidates = views.indices(split)
    keep, reasons = [], {}
    for i in candidates:
        ok, why = visible_enough(views, demand, config, int(i))
        if ok:
            keep.append(int(i))
        else:
            reasons[int(i)] = why
    if not keep:
        raise InputError(
            f"no drone camera sees the demanded object(s) {','.join(demand.objects)} well enough "
            f"(min_visible_fraction={config.min_visible_fraction}, "
            f"min_pixel_fraction={config.min_pixel_fraction})"
        )
    idx = np.asarray(keep, np.int64)
    per_obj = np.stack(
        [views.masks[o][idx] for o in demand.objects]
    )  # [num_objects, num_sent, h, w]
    union = per_obj.max(0)
    images = masked_images(views.images[idx], union, views.background)
    return Collection(
        idx,
        images,
        union.astype(np.float32),
        candidates,
        reasons,
        per_obj.transpose(1, 0, 2, 3).astype(np.float32),
    )
