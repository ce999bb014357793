"""Import Mitsuba safely: LLVM found first, and a global variant set so scoped switches restore."""

from __future__ import annotations

import phy

RGB_VARIANT = "llvm_ad_rgb"
RT_VARIANT = "llvm_ad_mono_polarized"  # sionna-rt's; keeping it global keeps sionna.rt working


def import_mitsuba():
    """``phy.require_llvm()`` then ``import mitsuba``; sets sionna-rt's variant when none is set.

    (``mi.util.scoped_set_variant`` cannot restore "no variant", and sionna.rt fails when the
    global variant is an RGB one, so renders switch to RGB only inside a scope.)
    """
    phy.require_llvm()
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant(RT_VARIANT, RGB_VARIANT)
    return mi
