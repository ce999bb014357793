"""The ADALM-Pluto through pyadi-iio on libiio: the AD9361's numbers, what libiio sees of the
board, and the driver."""

from hil.pluto.driver import Pluto
from hil.pluto.iio_access import find_plutos

__all__ = [
    "Pluto",
    "find_plutos",
]
