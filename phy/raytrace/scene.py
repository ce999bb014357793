"""Resolve a sionna-rt scene (built-in name, scene file, or loaded ``sionna.rt.Scene``).

``phy.require_llvm()`` runs before ``sionna.rt`` is imported, so a machine without a usable
LLVM gets one clear error instead of a Dr.Jit crash.
"""

from __future__ import annotations

import os
from pathlib import Path

from phy._llvm import require_llvm


def import_rt():
    """Import ``sionna.rt`` after checking that Dr.Jit has an LLVM (RuntimeError if not)."""
    require_llvm()
    import sionna.rt as rt

    return rt


def builtin_scenes() -> list[str]:
    """Names of sionna-rt's built-in scenes (``"munich"``, ``"simple_street_canyon"``, ...)."""
    rt = import_rt()
    return sorted(
        name
        for name in dir(rt.scene)
        if not name.startswith("_")
        and isinstance(getattr(rt.scene, name), str)
        and getattr(rt.scene, name).endswith(".xml")
    )


def scene_key(scene) -> tuple:
    """A hashable identity for caching: the name, the file (with its mtime), or the object."""
    if isinstance(scene, str):
        if scene.endswith(".xml") or os.sep in scene:
            p = Path(scene).resolve()
            return ("file", str(p), p.stat().st_mtime_ns if p.exists() else 0)
        return ("builtin", scene)
    if isinstance(scene, Path):
        return scene_key(str(scene))
    return ("object", id(scene))


def load_scene(scene):
    """A ``sionna.rt.Scene`` from a built-in name, an XML file path, or a Scene (returned as is).

    Raises:
        KeyError: unknown built-in name (the message lists the known ones).
        FileNotFoundError: a path that does not exist.
        ValueError: anything else.
    """
    rt = import_rt()
    if isinstance(scene, rt.Scene):
        return scene
    if isinstance(scene, Path):
        scene = str(scene)
    if not isinstance(scene, str):
        raise ValueError(
            f"scene must be a built-in scene name, a scene .xml path or a sionna.rt.Scene, "
            f"got {type(scene).__name__}"
        )
    if scene.endswith(".xml") or os.sep in scene:
        if not Path(scene).is_file():
            raise FileNotFoundError(f"scene file {scene!r} does not exist")
        return rt.load_scene(str(scene))
    known = builtin_scenes()
    if scene not in known:
        raise KeyError(f"scene must be one of {known} or a .xml path, got {scene!r}")
    return rt.load_scene(getattr(rt.scene, scene))
