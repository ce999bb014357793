"""A Pluto's receive stream (:meth:`hil.Pluto.stream`): its receive buffer kept open from one
block to the next.

libiio 0.x reports no overruns of a Pluto: the stream's ``last_stats.device_shortfalls``
is -1 (unknown), and only what the host counts (its ring) is exact there. An emulated
Pluto counts the blocks a late reader lost (``hil.pluto.context.OVERRUN_ATTR``): the
board's ``emulated_rx_loss`` holds them after the stream, ``(overruns, lost_blocks,
lost_samples)`` (None on a real board).
"""

from __future__ import annotations

import time
from collections.abc import Generator
from typing import TYPE_CHECKING

import numpy as np

from hil.hackrf.stream import StreamStats
from hil.pluto.ad9361 import RX_FULL_SCALE
from hil.pluto.iio_access import (
    destroy_buffers,
    receive_error,
    release_frames,
    rx_overrun_counts,
)

if TYPE_CHECKING:
    from hil.pluto.driver import Pluto

PLUTO_BUFFER_SAMPLES = 1 << 18  # a Pluto's receive buffer at least (4 of them in the kernel)


def rx_stream(board: Pluto, block_samples: int) -> Generator[np.ndarray, None, None]:
    """``board``'s receive buffer of ``block_samples``, refilled without pause: ``[1,
    block_samples]`` complex64 blocks (full scale 1.0) until the generator is closed."""
    sdr = board._sdr
    delivered, asked = 0, time.monotonic()
    try:
        sdr.rx_destroy_buffer()
        sdr.rx_buffer_size = int(block_samples)
        while True:
            asked = time.monotonic()
            x = np.asarray(sdr.rx())  # [block_samples] complex128, ADC counts
            board._receiving = True  # the stream is live once a buffer arrived
            delivered += len(x)
            yield (x / RX_FULL_SCALE).astype(np.complex64)[None, :]
    except GeneratorExit:
        raise
    except Exception as e:  # noqa: BLE001 - libiio raises OSError, pyadi Exception
        release_frames(e)
        raise receive_error(e, time.monotonic() - asked, board.timeout_ms) from e
    finally:
        board._receiving = False
        destroy_buffers(sdr.rx_destroy_buffer)
        board.emulated_rx_loss = rx_overrun_counts(sdr)
        board.last_stats = StreamStats("rx", delivered)
