"""Teacher renders for distilling the feature renderer, streamed through a pool of bounded
size (:class:`TeacherPool`) with the low-resolution passes it can keep beside them."""

from __future__ import annotations

import torch
from torch import Tensor

from renderer.cameras import Intrinsics
from renderer.feature_renderer import LowResPass
from renderer.model import RadianceField, render_views

PASS_BATCH_VIEWS = 8
"""Views whose low-resolution passes :class:`TeacherPool` computes in one call."""


class TeacherPool:
    """Teacher renders (8-bit) of a list of cameras, at most ``capacity`` held at once:
    :meth:`render_next` renders the next ``count`` cameras, each replacing the oldest.

    With ``passes`` (``poses -> [LowResPass]``) the low-resolution pass of each held camera
    is kept beside its image while their total stays under ``pass_bytes``; the others are
    recomputed when drawn (:meth:`passes_of`)."""

    def __init__(
        self,
        model: RadianceField,
        poses: Tensor,
        intrinsics: Intrinsics,
        capacity: int,
        passes=None,
        pass_bytes: int = 0,
    ):
        self.model, self.poses, self.intrinsics = model, poses, intrinsics
        self.capacity = max(1, min(capacity, poses.shape[0]))
        self.images = torch.zeros(
            self.capacity, intrinsics.height, intrinsics.width, 3, dtype=torch.uint8
        )
        self.index = torch.zeros(self.capacity, dtype=torch.long)  # camera of each slot
        # each slot's last training error (mean squared); NaN until it is first drawn
        self.errors = torch.full((self.capacity,), float("nan"))
        self.rendered = 0  # cameras rendered so far
        self._passes_fn, self._pass_bytes = passes, pass_bytes
        self._passes: dict[int, LowResPass] = {}  # slot -> its camera's pass
        self._held_bytes = 0

    @property
    def held(self) -> int:
        return min(self.rendered, self.capacity)

    @property
    def remaining(self) -> int:
        return self.poses.shape[0] - self.rendered

    @torch.no_grad()
    def render_next(self, count: int) -> None:
        count = min(count, self.remaining)
        if count <= 0:
            return
        cams = torch.arange(self.rendered, self.rendered + count)
        rgb = render_views(self.model, self.poses[cams], self.intrinsics)["rgb"]
        slots = cams % self.capacity
        self.images[slots] = (rgb.clamp(0, 1) * 255).round().to(torch.uint8)
        self.index[slots] = cams
        self.errors[slots] = float("nan")
        self.rendered += count
        for slot in slots.tolist():
            old = self._passes.pop(slot, None)
            self._held_bytes -= 0 if old is None else old.nbytes
        # passes a few views at a time, none once the budget is full: a large batch of
        # new teachers neither holds all its passes at once nor computes discarded ones
        full = self._passes_fn is None
        for start in range(0, count, PASS_BATCH_VIEWS):
            if full or self._held_bytes >= self._pass_bytes:
                break
            chunk = slice(start, start + PASS_BATCH_VIEWS)
            for slot, p in zip(slots[chunk].tolist(), self._passes_fn(self.poses[cams[chunk]])):
                if self._held_bytes + p.nbytes > self._pass_bytes:
                    full = True
                    break
                self._passes[slot] = p
                self._held_bytes += p.nbytes

    def sample(self, count: int, generator: torch.Generator, focus: float = 0.0) -> Tensor:
        """``count`` slots [count] from the held teachers: ``round(count * focus)`` of them
        drawn in proportion to their last error (:meth:`record_errors`; a teacher not yet
        drawn counts as the largest error seen), the others uniformly."""
        focused = round(count * focus)
        uniform = torch.randint(self.held, (count - focused,), generator=generator)
        if focused == 0:
            return uniform
        err = self.errors[: self.held]
        seen = err[~err.isnan()]
        top = float(seen.max()) if seen.numel() else 1.0
        weights = torch.nan_to_num(err, nan=top).clamp_min(1e-12)
        drawn = torch.multinomial(weights, focused, replacement=True, generator=generator)
        return torch.cat([drawn, uniform])

    def record_errors(self, slots: Tensor, errors: Tensor) -> None:
        """Remember the training error [len(slots)] of each slot's teacher."""
        self.errors[slots] = errors.detach().float()

    def poses_of(self, slots: Tensor) -> Tensor:
        return self.poses[self.index[slots]]

    def images_of(self, slots: Tensor) -> Tensor:
        """[len(slots), height, width, 3] float in [0, 1]."""
        return self.images[slots].float() / 255.0

    def passes_of(self, slots: Tensor) -> list[LowResPass]:
        """The slots' low-resolution passes: kept ones, the rest computed together."""
        slots = slots.tolist()
        missing = [s for s in slots if s not in self._passes]
        fresh = {}
        if missing:
            computed = self._passes_fn(self.poses[self.index[torch.tensor(missing)]])
            fresh = dict(zip(missing, computed))
        return [self._passes[s] if s in self._passes else fresh[s] for s in slots]
